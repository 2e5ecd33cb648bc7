"""The realistic body (scenes/makehuman.py), its scene (scenes/realistic.py) and `scan-synth --body makehuman`.

Each test checks a truth found independently of the code under test: brute-force integration,
the divergence theorem, analytic volumes, mirror symmetry, rigid arm turns, a plane's depth.
"""
import json

import numpy as np
import open3d as o3d
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from breastplan import read_ply
from breastplan.ingest.files import read_scan_file
from breastplan.scenes.makehuman import POSES, Body, BodyOptions, breast_region, make_body
from breastplan.meshes import positive_part_mean
from breastplan.scenes.realistic import CameraOptions, load_body_truth, make_body_scene
from breastplan.ingest.recording import read_recording

from clitools import run

SIDES = ("left", "right")
SMALL = "640x400"


@pytest.fixture(scope="module")
def default_body():
    return make_body(BodyOptions())


def divergence_volume_cc(vertices, faces) -> float:
    """Volume of a closed, outward-oriented mesh: (1/6) Σ v0 · (v1 × v2), in cc."""
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", v0, np.cross(v1, v2))) / 6.0 / 1000.0


# --- positive_part_mean ---------------------------------------------------------------------

def brute_positive_part_mean(P: np.ndarray, normal: np.ndarray, offset: float, n: int = 300) -> float:
    """Mean of max(x·normal − offset, 0) over the 3-D triangle P (3, 3): midpoint rule on the n²
    congruent sub-triangles of its regular subdivision."""
    i, j = np.mgrid[0:n, 0:n]
    up = (i + j <= n - 1)
    down = (i + j <= n - 2)
    ab = np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], 1), np.stack([i[down] + 2 / 3, j[down] + 2 / 3], 1)]) / n
    points = P[0] + ab[:, :1] * (P[1] - P[0]) + ab[:, 1:] * (P[2] - P[0])
    return float(np.mean(np.maximum(points @ normal - offset, 0.0)))


coordinate = st.floats(-100.0, 100.0, allow_nan=False)


@settings(max_examples=25, deadline=None)
@given(st.lists(coordinate, min_size=9, max_size=9), st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
       st.floats(-60.0, 60.0))
def test_positive_part_mean_matches_dense_sampling_of_a_triangle(corners, direction, offset):
    P = np.array(corners).reshape(3, 3)
    normal = np.array(direction)
    if np.linalg.norm(normal) < 1e-3:
        normal = np.array([1.0, 0.0, 0.0])
    normal /= np.linalg.norm(normal)
    f = P @ normal - offset                      # the signed distance to a plane, linear on the triangle
    exact = positive_part_mean(f[None])[0]
    scale = 1.0 + np.abs(f).max()
    assert exact == pytest.approx(brute_positive_part_mean(P, normal, offset), abs=1e-4 * scale)


def test_positive_part_mean_boundary_cases():
    f = np.array([[1.0, 2.0, 6.0],          # all positive: the mean
                  [-1.0, -2.0, -6.0],       # all negative: 0
                  [0.0, 0.0, 0.0],          # all zero: 0
                  [2.0, 0.0, 0.0],          # non-negative with zeros: the mean
                  [0.0, -1.0, -3.0],        # non-positive with a zero: 0
                  [1.0, 0.0, -1.0]])        # positive on the sub-triangle (1, 0) – (1/2, 1/2): area ½, mean ⅓ there
    assert positive_part_mean(f) == pytest.approx([3.0, 0.0, 0.0, 2.0 / 3.0, 0.0, 1.0 / 6.0], abs=1e-12)
    assert positive_part_mean(f[:, [2, 0, 1]]) == pytest.approx(positive_part_mean(f), abs=1e-12)  # vertex order


# --- half volumes --------------------------------------------------------------------------

def test_half_volumes_of_a_box_straddling_the_mid_plane():
    box = o3d.geometry.TriangleMesh.create_box(30.0, 20.0, 10.0).translate((-10.0, 0.0, 0.0))   # X from −10 to 20 mm
    body = Body(np.asarray(box.vertices), np.asarray(box.triangles), {}, BodyOptions())
    volumes = body.half_volumes_cc()
    assert volumes["left"] == pytest.approx(20 * 20 * 10 / 1000.0, rel=1e-12)
    assert volumes["right"] == pytest.approx(10 * 20 * 10 / 1000.0, rel=1e-12)


@pytest.mark.parametrize("options", [BodyOptions(), BodyOptions(cup=1.0, firmness=0.0, weight=0.8),
                                     BodyOptions(pose="arms-down", modifiers={"asymmetry": 0.7})])
def test_half_volumes_add_up_to_the_closed_body(options):
    body = make_body(options)
    volumes = body.half_volumes_cc()
    total = divergence_volume_cc(body.vertices, body.faces)
    assert volumes["left"] + volumes["right"] == pytest.approx(total, rel=1e-9)
    assert 30_000 < total < 120_000          # a woman's body: 30–120 litres


def test_default_body_is_mirror_symmetric(default_body):
    V = default_body.vertices
    gap, _ = cKDTree(V).query(V * [-1.0, 1.0, 1.0])
    assert gap.max() < 1e-6
    volumes = default_body.half_volumes_cc()
    assert volumes["left"] == pytest.approx(volumes["right"], rel=1e-3)


def test_a_bigger_cup_adds_the_same_volume_to_both_halves(default_body):
    bigger = make_body(BodyOptions(cup=1.0)).half_volumes_cc()
    base = default_body.half_volumes_cc()
    added = {side: bigger[side] - base[side] for side in SIDES}
    assert added["left"] > 100.0                                   # a cup size is hundreds of cc per breast
    assert added["left"] == pytest.approx(added["right"], rel=0.01)


def test_asymmetry_lowers_one_breast_and_changes_its_half_most(default_body):
    base = default_body.half_volumes_cc()
    for value, lower in ((1.0, "left"), (-1.0, "right")):
        body = make_body(BodyOptions(modifiers={"asymmetry": value}))
        other = "right" if lower == "left" else "left"
        nipples = body.nipples
        assert nipples[lower][1] < nipples[other][1] - 10.0
        for side in SIDES:                                          # a vertical shift: x and z stay
            assert nipples[side][[0, 2]] == pytest.approx(default_body.nipples[side][[0, 2]], abs=1.0)
        change = {side: abs(body.half_volumes_cc()[side] - base[side]) for side in SIDES}
        assert change[lower] > change[other]


# --- nipples -------------------------------------------------------------------------------

def test_nipples_are_mirror_images_in_front_of_the_chest(default_body):
    left, right = default_body.nipples["left"], default_body.nipples["right"]
    assert left[0] > 50.0 and right[0] == pytest.approx(-left[0], abs=1e-6)
    assert left[1:] == pytest.approx(right[1:], abs=1e-6)
    V = default_body.vertices
    sternum = V[(np.abs(V[:, 0]) < 15.0) & (np.abs(V[:, 1] - left[1]) < 20.0) & (V[:, 2] > 0.0)]
    assert len(sternum) and left[2] > sternum[:, 2].max()
    surface = o3d.t.geometry.RaycastingScene()
    surface.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(default_body.faces.astype(np.uint32)))
    assert surface.compute_distance(o3d.core.Tensor(np.float32([left, right]))).numpy().max() < 2.0   # on the skin


def test_soft_large_breasts_sag():
    soft, firm = (make_body(BodyOptions(cup=1.0, firmness=f)).nipples for f in (0.0, 1.0))
    for side in SIDES:
        assert soft[side][1] < firm[side][1] - 10.0


# --- poses ---------------------------------------------------------------------------------

def segment(body, side, a, b):
    return body.joints[f"{side}-{b}"] - body.joints[f"{side}-{a}"]


def frontal_angle_deg(u, v):
    """Angle between the projections of u and v on the frontal plane (XY)."""
    return float(np.degrees(abs(np.arctan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1]))))


@pytest.mark.parametrize("pose", [p for p in POSES if p != "a-pose"])
def test_a_pose_turns_the_arms_rigidly_and_leaves_the_body(default_body, pose):
    posed = make_body(BodyOptions(pose=pose))
    shoulder_deg, elbow_deg = POSES[pose]
    V0, V = default_body.vertices, posed.vertices
    for side in SIDES:
        for a, b in (("shoulder", "elbow"), ("elbow", "hand")):
            assert np.linalg.norm(segment(posed, side, a, b)) == pytest.approx(
                np.linalg.norm(segment(default_body, side, a, b)), rel=1e-9)
        assert posed.joints[f"{side}-shoulder"] == pytest.approx(default_body.joints[f"{side}-shoulder"], abs=1e-9)
        for a, b, turn in (("shoulder", "elbow", shoulder_deg), ("elbow", "hand", shoulder_deg + elbow_deg)):
            before, after = segment(default_body, side, a, b), segment(posed, side, a, b)
            assert frontal_angle_deg(before, after) == pytest.approx(abs(turn), abs=1e-6)   # a turn in the frontal
            assert after[2] == pytest.approx(before[2], abs=1e-9)                          # plane, about Z
        assert abs(posed.joints[f"{side}-hand"][0]) < abs(default_body.joints[f"{side}-hand"][0])   # towards the body
        assert posed.nipples[side] == pytest.approx(default_body.nipples[side], abs=1e-6)
        near = breast_region(side)[np.linalg.norm(V0[breast_region(side)] - default_body.nipples[side], axis=1) < 40]
        assert np.abs(V[near] - V0[near]).max() < 2.0              # the breast around the nipple stays
        if shoulder_deg == 0.0:                                     # an elbow turn leaves the whole breast
            assert np.array_equal(V[breast_region(side)], V0[breast_region(side)])
    legs = V0[:, 1] < 0.0
    assert np.array_equal(V[legs], V0[legs])


# --- the realistic scene -------------------------------------------------------------------

@pytest.mark.parametrize("yaw, pitch", [(0.0, 0.0), (15.0, 10.0), (-15.0, -5.0)])
def test_the_depth_at_each_nipple_is_its_distance(yaw, pitch):
    scene = make_body_scene(BodyOptions(), CameraOptions(resolution=SMALL, yaw_deg=yaw, pitch_deg=pitch))
    depth, ids = scene.render()
    K, (w, h) = scene.camera.K, scene.camera.size
    for side, p in scene.nipples_camera().items():
        u, v = p[0] / p[2] * K[0, 0] + K[0, 2], p[1] / p[2] * K[1, 1] + K[1, 2]
        assert 0 <= u < w and 0 <= v < h
        row, col = int(round(v)), int(round(u))
        assert ids[row, col] == 0 and depth[row, col] == pytest.approx(p[2], abs=3.0)
    if yaw == 0.0:
        nipples = scene.nipples_camera()
        assert nipples["left"][0] > 0 > nipples["right"][0]       # the patient's left on the image's right


def test_the_wall_closes_the_far_depths():
    body = BodyOptions()
    with_wall = make_body_scene(body, CameraOptions(distance_mm=650.0, resolution=SMALL, wall_mm=400.0))
    bare = make_body_scene(body, CameraOptions(distance_mm=650.0, resolution=SMALL, wall_mm=None))
    made = make_body(body)
    nipple_z = (made.nipples["left"][2] + made.nipples["right"][2]) / 2
    wall_depth = 650.0 + nipple_z - made.vertices[:, 2].min() + 400.0    # a plane square to the camera's axis
    depth, ids = with_wall.render()
    corners = depth[[0, 0, -1, -1], [0, -1, 0, -1]]
    assert corners == pytest.approx(np.full(4, wall_depth), abs=0.5) and (ids[[0, -1], [0, -1]] == 1).all()
    bare_depth, _ = bare.render()
    assert np.isnan(bare_depth[[0, 0, -1, -1], [0, -1, 0, -1]]).all()
    assert np.nanmax(bare_depth) < wall_depth - 300.0
    body_pixels = ids == 0
    assert np.array_equal(depth[body_pixels], bare_depth[body_pixels], equal_nan=True)   # the wall hides no body


# --- the command -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def recorded(cli, tmp_path_factory):
    folder = tmp_path_factory.mktemp("makehuman")
    res = run(cli, "scan-synth", "--body", "makehuman", "--out", folder / "rec.mcap", "--truth", folder / "truth.npz",
              "--frames", 2, "--resolution", SMALL, "--cup", 0.7, "--modifier", "breast_point=0.5", "--pitch", 10,
              "--scan-file", folder / "scan.ply", "--units", "m", "--up", "+z", "--json")
    assert res.returncode == 0, res.stderr
    return folder, json.loads(res.stdout)


def test_scan_synth_makehuman_records_frames_ingest_can_replay(recorded):
    folder, out = recorded
    assert out["frames"] == 2 and out["size"] == [640, 400]
    frames = read_recording(folder / "rec.mcap")
    assert frames.depth.shape == (2, 400, 640) and frames.depth.dtype == np.uint16
    assert frames.K == pytest.approx(CameraOptions(resolution=SMALL).K)
    assert 0.9 < np.mean(frames.depth > 0) <= 1.0                          # the wall fills the background


def test_scan_synth_makehuman_writes_the_truth(recorded):
    folder, out = recorded
    truth = load_body_truth(folder / "truth.npz")
    scene = make_body_scene(BodyOptions(cup=0.7, modifiers={"breast_point": 0.5}),
                            CameraOptions(resolution=SMALL, pitch_deg=10.0))
    for side in SIDES:
        assert truth[f"{side}_nipple_camera_mm"] == pytest.approx(scene.nipples_camera()[side], abs=1e-6)
        assert float(truth[f"{side}_half_volume_cc"]) == pytest.approx(out["half_volumes_cc"][side], abs=0.1)
    total = divergence_volume_cc(truth["vertices"].astype(float), truth["faces"])   # camera mm: rigid, same volume
    assert float(truth["left_half_volume_cc"] + truth["right_half_volume_cc"]) == pytest.approx(total, rel=1e-4)
    assert truth.meta["body"]["cup"] == 0.7 and truth.meta["camera"]["pitch_deg"] == 10.0


def test_scan_file_ply_in_metres_with_z_up(recorded):
    folder, _ = recorded
    assert not any("camera-opencv" in c for c in read_ply(folder / "scan.ply").comments)
    raw = read_ply(folder / "scan.ply").points
    cloud = read_scan_file(folder / "scan.ply", "m")
    np.testing.assert_allclose(cloud.points, raw * 1000.0, rtol=1e-12)
    assert 0.3 < np.ptp(raw, axis=0).max() < 3.0                       # metres
    scene = make_body_scene(BodyOptions(cup=0.7, modifiers={"breast_point": 0.5}),
                            CameraOptions(resolution=SMALL, pitch_deg=10.0))
    depth, ids = scene.render()                                        # back-projected here, independently
    K = scene.camera.K
    v, u = np.nonzero((ids == 0) & np.isfinite(depth))
    z = depth[v, u]
    camera = np.column_stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z])
    R, t = scene.camera_from_body[:3, :3], scene.camera_from_body[:3, 3]
    X, Y, Z = ((camera - t) @ R).T                                     # body frame: X left, Y up, Z front
    expected = np.column_stack([X, -Z, Y])                             # up +z: x left, y back, z up
    near, _ = cKDTree(cloud.points).query(expected)
    assert near.max() < 1e-3
    nipples = np.array([[n[0], -n[2], n[1]] for n in scene.body.nipples.values()])
    assert cKDTree(cloud.points).query(nipples)[0].max() < 3.0
    body_points = cloud.points[cKDTree(expected).query(cloud.points, distance_upper_bound=1.0)[0] < 1e-3]
    assert np.ptp(body_points, axis=0) == pytest.approx(np.ptp(expected, axis=0), abs=1e-3)


def test_scan_file_obj_lies_on_the_body(cli, tmp_path):
    res = run(cli, "scan-synth", "--body", "makehuman", "--truth", tmp_path / "truth.npz", "--resolution", SMALL,
              "--yaw", 20, "--no-wall", "--scan-file", tmp_path / "scan.obj", "--up", "-x", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["scan_faces"] > 1000 and "recording" not in out and not (tmp_path / "rec.mcap").exists()
    cloud = read_scan_file(tmp_path / "scan.obj", "mm")
    body = make_body(BodyOptions())
    X, Y, Z = body.vertices.T
    in_file = np.column_stack([-Y, X, Z]).astype(np.float32)            # up −x: x down, y left, z front
    surface = o3d.t.geometry.RaycastingScene()
    surface.add_triangles(o3d.core.Tensor(in_file), o3d.core.Tensor(body.faces.astype(np.uint32)))
    assert surface.compute_distance(o3d.core.Tensor(cloud.points.astype(np.float32))).numpy().max() < 0.01
    left = body.nipples["left"]
    assert cKDTree(cloud.points).query([-left[1], left[0], left[2]])[0] < 3.0   # the left nipple faces the camera
    assert cloud.normals is not None and np.mean(cloud.normals[:, 2]) > 0.3     # the front of the body


@pytest.mark.parametrize("args, option", [
    (["--body", "makehuman", "--out", "r.mcap", "--cup", "2"], "--cup"),
    (["--out", "r.mcap", "--cup", "0.3"], "--cup"),                              # chen takes no MakeHuman option
    (["--body", "makehuman", "--scan-file", "s.xyz"], "--scan-file"),
    (["--body", "makehuman", "--out", "r.mcap", "--modifier", "nose=1"], "--modifier"),
    (["--body", "makehuman", "--out", "r.mcap", "--wall", "300", "--no-wall"], "--wall"),
])
def test_scan_synth_makehuman_usage_errors_exit_2(cli, tmp_path, args, option):
    res = run(cli, "scan-synth", "--truth", tmp_path / "t.npz", *[tmp_path / a if a.endswith((".mcap", ".xyz")) else a
                                                                  for a in args])
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert option in res.stderr and "Traceback" not in res.stderr
    assert list(tmp_path.iterdir()) == []
