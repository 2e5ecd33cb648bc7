"""A case folder is one patient's, of one recording, and whole: another input is refused (or replaced
whole with --force), its sides are what its scans say, an earlier visit is only read, one side of a
plan is not planned alone over it, a damaged artefact is made again, and a failed plan leaves no folder.

Truths: the files on disk before and after each command (names and content), and the side each
scan.npz records.
"""
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

from clitools import assert_bad_input, run

from breastplan import write_ply
from breastplan.plan.job import sample_recording
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file


def _tree(folder):
    """Every file under `folder`, relative, with its content."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def planned(cli, tmp_path_factory):
    """The sample planned once (one change), and another woman's scan file."""
    tmp = tmp_path_factory.mktemp("one-patient")
    res = run(cli, "plan", "--deform", "ptosis:3", "--out", tmp / "case")
    assert res.returncode == 0, res.stderr[-2000:]
    other = tmp / "other.ply"
    write_scan_file(other, make_body_scene(BodyOptions(cup=0.8), CameraOptions(resolution="640x400")))
    return tmp / "case", other


@pytest.fixture
def case(planned, tmp_path):
    """A copy of the planned case, to change."""
    shutil.copytree(planned[0], tmp_path / "case")
    return tmp_path / "case"


def test_a_case_of_another_recording_is_refused_and_force_replaces_it_whole(cli, planned, case):
    before = _tree(case)
    res = run(cli, "plan", planned[1], "--side", "left", "--deform", "ptosis:3", "--out", case)
    assert_bad_input(res, case, case.parent)
    assert str(planned[1]) in res.stderr and "--force" in res.stderr
    assert _tree(case) == before
    res = run(cli, "plan", planned[1], "--side", "left", "--deform", "ptosis:3", "--out", case, "--force")
    assert res.returncode == 0, res.stderr[-2000:]
    assert not (case / "right").exists()                        # nothing of the other woman is kept
    record = json.loads((case / "plan.json").read_text())
    assert list(record["sides"]) == ["left"] and record["input"]["path"].endswith("other.ply")
    assert not any(after == before.get(name) for name, after in _tree(case).items())
    assert sorted(p.name for p in case.parent.iterdir()) == ["case"]       # no sibling left


def test_the_same_recording_plans_into_its_own_case(cli, case):
    res = run(cli, "plan", sample_recording(), "--deform", "ptosis:3", "--out", case)
    assert res.returncode == 0, res.stderr[-2000:]


def test_a_cases_sides_are_what_its_scans_say(cli, case):
    (case / "left").rename(case / "was-left")
    (case / "right").rename(case / "left")
    (case / "was-left").rename(case / "right")
    before = _tree(case)
    res = run(cli, "plan", case, "--out", case.parent / "out-case")
    assert_bad_input(res, case / "left", case.parent)
    assert "holds a scan of her right breast" in res.stderr
    assert _tree(case) == before and not (case.parent / "out-case").exists()


@pytest.mark.parametrize("args", [
    ("plan", "{rec}", "--wall-from", "{case}", "--out", "{case}/left"),
    ("plan", "{case}/left", "--wall-from", "{case}"),
    ("plan", "{rec}", "--wall-from", "{case}/left", "--out", "{case}"),
    ("fit", "{case}/left", "--wall-from", "{case}"),
])
def test_the_earlier_visit_is_only_read(cli, case, args):
    before = _tree(case)
    res = run(cli, *[a.format(rec=sample_recording(), case=case) for a in args])
    assert res.returncode == 2 and "--wall-from" in res.stderr and "only read" in " ".join(res.stderr.split())
    assert _tree(case) == before


@pytest.mark.parametrize("args", [("plan", "{case}/left"), ("plan", "{rec}", "--out", "{case}/right"),
                                  ("ingest", "{rec}", "--side", "left", "--out", "{case}/left")])
def test_one_side_of_a_plan_is_not_planned_alone_over_it(cli, case, args):
    before = _tree(case)
    res = run(cli, *[a.format(rec=sample_recording(), case=case) for a in args])
    assert res.returncode == 2 and "one side of the plan" in " ".join(res.stderr.split()), res.stderr
    assert _tree(case) == before
    record = json.loads((case / "plan.json").read_text())
    assert all((case / f).is_file() for s in record["sides"].values()
               for c in s["changes"] for f in c["files"].values())


@pytest.mark.parametrize("volume", [np.nan, -500.0])
def test_a_fit_of_an_impossible_volume_is_made_again(cli, case, volume):
    """fit.npz's volume set to NaN or −500 cc, its hashes intact: the plan fits the breast again."""
    npz = case / "left" / "fit.npz"
    with np.load(npz) as held:
        arrays = {k: held[k] for k in held.files}
    arrays["volume_cc_mesh"] = np.float64(volume)
    with open(npz, "wb") as fh:
        np.savez(fh, **arrays)
    res = run(cli, "plan", case, "--deform", "ptosis:3", "--json")
    assert res.returncode == 0, res.stderr[-2000:]
    with np.load(npz) as remade:
        assert 50.0 < float(remade["volume_cc_mesh"]) < 2000.0
    assert json.loads((case / "plan.json").read_text())["sides"]["left"]["reused"] == ["ingest"]


def test_a_damaged_scan_of_a_case_folder_says_how_to_recover(cli, case):
    npz = case / "right" / "scan.npz"
    with np.load(npz) as held:
        arrays = {k: held[k] for k in held.files}
    arrays["voxel_mm"] = np.float64(-1.0)
    with open(npz, "wb") as fh:
        np.savez(fh, **arrays)
    res = run(cli, "plan", case, "--out", case.parent / "out-case")
    assert_bad_input(res, npz, case.parent)
    assert "plan her recording or scan file again" in res.stderr
    assert not (case.parent / "out-case").exists()


def test_a_failed_plan_leaves_no_folder_it_made(cli, tmp_path):
    plate = tmp_path / "plate.ply"
    x, y = np.meshgrid(np.linspace(-200, 200, 120), np.linspace(-200, 200, 120))
    write_ply(plate, np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 700.0)]))
    res = run(cli, "plan", plate, "--out", tmp_path / "new" / "sub" / "case")
    assert_bad_input(res, plate, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plate.ply"]


def test_a_case_whose_plan_folder_leads_elsewhere_is_refused_and_what_it_leads_to_kept(cli, case, tmp_path):
    """A case's plan/ folder replaced by a link to another folder: planning the case in place wrote its plan there
    and removed the files of that folder it took for an earlier plan's."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    for name in ("keep.ply", "keep.npz"):
        (elsewhere / name).write_bytes(b"someone's")
    shutil.rmtree(case / "left" / "plan")
    (case / "left" / "plan").symlink_to(elsewhere, target_is_directory=True)
    before = _tree(case)
    res = run(cli, "plan", case, "--deform", "ptosis:2")
    assert_bad_input(res, case / "left" / "plan", case.parent)
    assert sorted(p.name for p in elsewhere.iterdir()) == ["keep.npz", "keep.ply"]
    assert _tree(case) == before


@pytest.mark.parametrize("where", ["elsewhere", "in place"])
def test_a_folder_where_a_case_file_belongs_is_named_and_nothing_written(cli, case, tmp_path, where):
    """A case whose fit.npz is a folder: planned into another folder, the refusal named that other folder's copy;
    it names the case's own fit.npz, and neither folder changes."""
    fit = case / "left" / "fit.npz"
    fit.unlink()
    fit.mkdir()
    before = _tree(case)
    res = run(cli, "plan", case, *(["--out", tmp_path / "elsewhere"] if where == "elsewhere" else []))
    assert_bad_input(res, fit, tmp_path)
    assert "is a folder" in res.stderr
    assert _tree(case) == before and not (tmp_path / "elsewhere").exists()


def test_a_fault_of_a_case_planned_elsewhere_names_the_cases_own_file(cli, case, tmp_path):
    """A case planned into another folder is copied there first: its faults named the hidden copy (already
    removed), or said "[Errno None] None", instead of the case's own file."""
    fit = case / "left" / "fit.npz"
    with np.load(fit, allow_pickle=False) as held:
        arrays = {k: held[k] for k in held.files}
    np.savez(fit, **{**arrays, "schema": np.str_("breastplan.fit/99")})
    res = run(cli, "plan", case, "--out", tmp_path / "elsewhere")
    assert_bad_input(res, fit, tmp_path)
    assert "newer" in res.stderr
    np.savez(fit, **arrays)
    fit.chmod(0)
    as_user = ["setpriv", "--inh-caps=-dac_override,-dac_read_search",        # root reads it whatever its mode
               "--bounding-set=-dac_override,-dac_read_search"] if os.geteuid() == 0 else []
    res = subprocess.run([*as_user, cli, "plan", str(case), "--out", str(tmp_path / "elsewhere")],
                         capture_output=True, text=True, timeout=600)
    assert_bad_input(res, fit, tmp_path)
    assert "cannot be read (Permission denied)" in res.stderr
