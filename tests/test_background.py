"""A wall behind the patient (ingest/background.py) against the planes it was built from.

Truths: the realistic scenes' wall is the plane Z = const of the body frame (so its normal is the
body's Z in the camera frame); planes drawn here have the normals they were drawn with.
"""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from breastplan import transform_points
from breastplan.ingest.background import FACING_DEG, WALL_AREA_MM2, plumb_wall
from breastplan.scenes.makehuman import BodyOptions
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import CameraOptions, file_from_body, make_body_scene, write_scan_file
from breastplan.ingest.recording import DepthFrames
from breastplan.ingest.scan import ingest
from breastplan.options import IngestOptions
from breastplan.plan.measures import find_landmarks

WALL_DEG = 0.5
"""The wall's normal against the truth: a flat wall measured over a square metre."""


def degrees(a, b):
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def plane(normal, side_mm, depth_mm=2000.0, noise_mm=1.0, seed=0):
    """Points on a square plane through (0, 0, depth) with unit `normal`, 10 mm apart, with noise."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    s = np.arange(-side_mm / 2, side_mm / 2, 10.0)
    a, b = (g.ravel() for g in np.meshgrid(s, s))
    rng = np.random.default_rng(seed)
    return [0.0, 0.0, depth_mm] + a[:, None] * u + b[:, None] * v + rng.normal(0, noise_mm, (len(a), 1)) * n


@settings(max_examples=20, deadline=None)
@given(st.floats(-30, 30), st.floats(-30, 30))
def test_a_wall_facing_the_viewer_gives_its_normal(pitch, yaw):
    p, y = np.radians(pitch), np.radians(yaw)
    normal = np.array([np.sin(y) * np.cos(p), np.sin(p), -np.cos(y) * np.cos(p)])   # towards the viewer
    found = plumb_wall(plane(normal, 1200.0))
    assert found is not None and degrees(found, normal) < WALL_DEG


def test_a_floor_a_small_board_and_nothing_are_no_wall():
    assert plumb_wall(plane([0.0, -1.0, -0.2], 2000.0)) is None                   # a floor seen at a slant
    assert FACING_DEG < 90 - np.degrees(np.arctan(0.2))
    small = np.sqrt(WALL_AREA_MM2) * 0.8
    assert plumb_wall(plane([0.0, 0.0, -1.0], small)) is None                       # under 0.25 m²
    assert plumb_wall(np.zeros((0, 3))) is None


def test_the_largest_plane_is_the_wall_among_clutter():
    wall = plane([0.0, 0.0, -1.0], 1500.0)
    rng = np.random.default_rng(3)
    clutter = rng.uniform([-700, -700, 1200], [700, 700, 1900], (3000, 3))
    found = plumb_wall(np.vstack([wall, clutter]))
    assert found is not None and degrees(found, [0.0, 0.0, -1.0]) < WALL_DEG
    assert np.array_equal(found, plumb_wall(np.vstack([wall, clutter])))           # the same points, the same wall


@pytest.mark.parametrize("wall_mm", [400.0, 100.0, None])
def test_ingest_finds_the_wall_behind_a_heavy_patient_and_her_up_axis_from_it(wall_mm):
    """A heavy body (weight 0.9) whose belly leans her midline profile: with a wall behind her (beyond
    the depth slab at 400 mm, inside it at 100 mm) the up axis is the body's Y to within the wall's
    fit; without one it comes from the profile."""
    scene = make_body_scene(BodyOptions(weight=0.9, cup=0.8),
                            CameraOptions(resolution="640x400", pitch_deg=12.0, yaw_deg=-8.0, wall_mm=wall_mm))
    frames = DepthFrames(scene.frames(3, seed=2), scene.camera.K, "synthetic")
    scans = {side: ingest_frames(frames, IngestOptions(side=side)) for side in ("left", "right")}
    R = scene.camera_from_body[:3, :3]
    plumb = scans["left"].plumb_camera
    found = find_landmarks(scans["left"].torso_camera, {s: scan.nipple_camera for s, scan in scans.items()},
                           scans["left"].input_to_view, plumb)
    if wall_mm is None:
        assert plumb is None and found.up_from == "midline profile"
        return
    assert degrees(plumb, R[:, 2]) < WALL_DEG                  # the wall faces the way she does
    assert found.up_from == "wall" and degrees(found.up_axis, R[:, 1]) < 1.0


def test_a_scan_file_with_a_wall_gives_its_normal_in_the_files_own_frame(tmp_path):
    """A scan file in metres with z up (`write_scan_file`: the body frame turned by `file_from_body`):
    the wall's normal and the up axis come back in the file's frame, as the body's Z and Y turned."""
    scene = make_body_scene(BodyOptions(weight=0.9, pose="arms-down"),
                            CameraOptions(resolution="640x400", pitch_deg=-10.0, yaw_deg=6.0, wall_mm=300.0))
    path = tmp_path / "patient.ply"
    write_scan_file(path, scene, units="m", up="+z")
    scans = {side: ingest(path, IngestOptions(side=side, up="+z")) for side in ("left", "right")}
    turn = file_from_body("+z", "m")[:3, :3] * 1000.0              # a rotation: the file is read in mm
    plumb = scans["left"].plumb_camera
    assert plumb is not None and degrees(plumb, turn[:, 2]) < WALL_DEG
    found = find_landmarks(scans["left"].torso_camera, {s: scan.nipple_camera_mm for s, scan in scans.items()},
                           scans["left"].input_to_view, plumb)
    assert found.up_from == "wall" and degrees(found.up_axis, turn[:, 1]) < 1.0


@pytest.mark.parametrize("up", ["+y", "auto"])
def test_a_scan_file_with_a_wall_is_read_from_her_front_not_the_walls_back(tmp_path, up):
    """A woman with her hands on her hips scanned in front of a wall at 640×400, as a scan file: seen from behind,
    the nearest surface as wide as a chest is one half of the wall (her body's shadow splits it), flat, and it had
    been taken for her, her front's trunk bulging a hair less along the file's tilted first axis: "no breast mound
    found". Both nipples are found within 5 mm of the truth, and she faces the viewer."""
    scene = make_body_scene(BodyOptions(cup=0.7, firmness=0.4, weight=0.6, pose="hands-on-hips"),
                            CameraOptions(resolution="640x400"))
    path = tmp_path / "patient.ply"
    write_scan_file(path, scene)
    to_file = file_from_body("+y", "mm")
    for side in ("left", "right"):
        scan = ingest(path, IngestOptions(side=side, up=up))
        truth = transform_points(to_file, scene.body.nipples[side][None])[0]
        assert np.linalg.norm(scan.nipple_camera_mm - truth) < 5.0, side
