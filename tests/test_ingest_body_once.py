"""`ingest_sides` finds the body once for both sides and gives each side exactly what a single-side
ingest gives (ingest/scan.py, ingest/pipeline.py), on a realistic MakeHuman recording and scan file."""
import numpy as np
import pytest

from breastplan.ingest import pipeline
from breastplan.ingest.files import read_scan_file
from breastplan.scenes.makehuman import BodyOptions
from breastplan.scenes.realistic import CameraOptions, make_body_scene, write_scan_file
from breastplan.ingest.recording import read_recording, write_recording
from breastplan.ingest.scan import ingest_sides
from breastplan.options import SIDES, IngestOptions


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    """A MakeHuman scene (arms down, a wall behind) as a 5-frame recording and as a PLY in metres, z up."""
    folder = tmp_path_factory.mktemp("body_once")
    scene = make_body_scene(BodyOptions(pose="arms-down"), CameraOptions(resolution="640x400", wall_mm=400.0))
    write_recording(folder / "her.mcap", scene.frames(5, 0), scene.camera.K)
    write_scan_file(folder / "her.ply", scene, units="m", up="+z")
    return folder


@pytest.fixture
def clusterings(monkeypatch):
    """A list that `pipeline.body_cluster` (the real one) appends to on every call."""
    calls = []
    real = pipeline.body_cluster

    def counted(points):
        calls.append(len(points))
        return real(points)
    monkeypatch.setattr(pipeline, "body_cluster", counted)
    return calls


@pytest.mark.parametrize("name", ["her.mcap", "her.ply"])
def test_both_sides_at_once_are_each_side_alone_with_the_body_clustered_once(sources, clusterings, name):
    path = sources / name
    options = [IngestOptions(side, units="m", up="+z") for side in SIDES]
    both = ingest_sides(path, options)
    at_once = len(clusterings)
    alone = []
    for opts in options:
        del clusterings[:]
        alone.append(pipeline.ingest_frames(read_recording(path), opts) if name.endswith(".mcap")
                     else pipeline.ingest_cloud(read_scan_file(path, "m"), opts))
        assert len(clusterings) == at_once          # one side alone clusters as often as both sides at once
    if name.endswith(".mcap"):
        assert at_once == 1                         # a file's viewing frame tries a few views, each clustered
    for scan, one in zip(both, alone):
        assert scan.side == one.side and scan.nipple_found == one.nipple_found
        for mine, theirs in [(scan.points, one.points), (scan.normals, one.normals),
                             (scan.torso_camera, one.torso_camera), (scan.input_to_breast, one.input_to_breast),
                             (scan.input_to_view, one.input_to_view), (scan.nipple_camera_mm, one.nipple_camera),
                             (scan.plumb_camera, one.plumb_camera),
                             (scan.mound_centre_view_mm, one.crop["mound_centre_view_mm"]),
                             (scan.mound_radius_mm, one.crop["mound_radius_mm"]),
                             (scan.chest_wall.coefficients, one.chest_wall.coefficients),
                             (scan.chest_wall.centre, one.chest_wall.centre),
                             (scan.chest_wall.scale_mm, one.chest_wall.scale_mm)]:
            assert np.array_equal(mine, theirs)
        assert set(scan.timings_ms) - {"replay (depthai)"} == set(one.timings_ms)
    assert both[0].plumb_camera is not None                   # the wall behind her was found, and shared
    assert not np.array_equal(both[0].points, both[1].points)
