"""A scan that wraps round her (a scanner's closed or 180° mesh, as Artec, 3dMD and Vectra export, or a phone app's
GLB) read as well as a frontal view of her: the front a camera would see is chosen from the scan itself, whatever
the file's axes, units or her turn in it, her up axis found from her body."""
import json

import numpy as np
import pytest

from breastplan import transform_points
from breastplan.ingest.scan import ingest_sides
from breastplan.options import IngestOptions
from breastplan.plan.compute import measure_scans
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.scenes.realistic import (CameraOptions, file_from_body, make_body_scene, turned, write_closed_scan,
                                        write_scan_file)

from clitools import run

WRAPPED = {   # her body, her turn about her vertical axis in the file (°, +: her left forward), its up, units, format
    "cup 0.8, her back to the file's +z (turned 180°)": (BodyOptions(cup=0.8), 180.0, "+y", "mm", ".obj"),
    "heavy, arms down, turned 35°, Z up, metres": (BodyOptions(cup=0.6, weight=0.8, pose="arms-down"), 35.0, "+z",
                                                    "m", ".ply"),
    "cup 0.9, soft, A-pose, turned −40°, −X up, a GLB in metres": (BodyOptions(cup=0.9, firmness=0.2), -40.0, "-x",
                                                                    "m", ".glb"),
}


def _read(path) -> dict:
    """Both breasts of a scan file, its up axis not given: found from her body."""
    return dict(zip(("left", "right"), ingest_sides(path, [IngestOptions(s) for s in ("left", "right")])))


@pytest.fixture(scope="module", params=list(WRAPPED), ids=list(WRAPPED))
def wrapped(request, tmp_path_factory):
    """(nipples found − truth (mm, each side), her volumes measured on the wrapped scan, on a frontal export)."""
    options, deg, up, units, suffix = WRAPPED[request.param]
    folder = tmp_path_factory.mktemp("wrapped")
    body = make_body(options)
    to_file = file_from_body(up, units) @ turned(deg)
    write_closed_scan(folder / f"closed{suffix}", body, units, up, turn_deg=deg)
    scans = _read(folder / f"closed{suffix}")
    assert f"up {up} (found: her head" in scans["left"].source.description
    mm = 1000.0 if units == "m" else 1.0
    errors = {s: float(np.linalg.norm(scan.nipple_camera_mm - mm * transform_points(to_file, body.nipples[s][None])[0]))
              for s, scan in scans.items()}
    frontal = make_body_scene(options, CameraOptions(680.0, 5.0, 0.0, wall_mm=None))
    write_scan_file(folder / "front.obj", frontal, "mm", "+y")
    return errors, measure_scans(scans).sides, measure_scans(_read(folder / "front.obj")).sides


def test_a_wrapped_scan_finds_her_nipples_on_her_front(wrapped):
    errors, _, _ = wrapped
    assert max(errors.values()) < 3.0, errors


def test_a_wrapped_scan_measures_her_breasts_within_the_frontal_ones_stated_range(wrapped):
    """A wrapped scan sees the outer sides of her breasts, which a camera in front of her sees at a grazing angle or
    not at all: it reads them within the frontal scan's ±, or above it by no more than what the frontal scan says
    may lie on her outer side, unseen."""
    _, volumes, front = wrapped
    for side in ("left", "right"):
        more = volumes[side].volume_cc - front[side].volume_cc
        assert -front[side].uncertainty_cc <= more <= front[side].uncertainty_cc + front[side].unseen_outer_cc, \
            (side, volumes[side].volume_cc, front[side].volume_cc, front[side].uncertainty_cc)


def test_a_wrapped_scan_leaves_less_of_her_outer_side_unseen_than_a_frontal_one(wrapped):
    _, volumes, front = wrapped
    for side in ("left", "right"):
        assert volumes[side].unseen_outer_cc < front[side].unseen_outer_cc, (side, volumes[side], front[side])


def test_scan_synth_writes_her_closed_body_and_ingest_reads_it_from_her_front_without_up(cli, tmp_path):
    """`scan-synth --closed`: her whole body as a 360° scanner exports it (here a PLY in metres, her up on −y); read
    with no --up, her nipple is found where the truth puts it in the file's frame."""
    res = run(cli, "scan-synth", "--body", "makehuman", "--cup", "0.7", "--pose", "hands-on-hips", "--scan-file",
              tmp_path / "her.ply", "--closed", "--units", "m", "--up", "-y", "--truth", tmp_path / "truth.npz", "--json")
    assert res.returncode == 0, res.stderr
    nipple = np.array(json.loads(res.stdout)["nipples_camera_mm"]["right"])
    with np.load(tmp_path / "truth.npz", allow_pickle=False) as truth:
        to_file = file_from_body("-y", "m") @ np.linalg.inv(truth["camera_from_body"])
    res = run(cli, "ingest", tmp_path / "her.ply", "--side", "right", "--out", tmp_path / "right", "--json")
    assert res.returncode == 0, res.stderr
    found = json.loads(res.stdout)
    assert "up -y (found" in found["source"]
    assert np.linalg.norm(np.array(found["nipple_camera_mm"]) - 1000.0 * transform_points(to_file, nipple[None])[0]) < 3.0
