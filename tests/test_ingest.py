"""Ingest: depthai recordings, fusion, chest wall, the synthetic scanner and the whole pipeline.

Accuracy is measured against the synthetic scanner's truth: the recorded
frames go through depthai (RecordMessage → MCAP → ReplayMessage) as a clinic's would.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from breastplan import read_ply, to_mm, write_ply
from breastplan.chest_wall import ChestWall
from breastplan.scenes import synthetic
from breastplan.ingest.chest_wall import fit_chest_wall
from breastplan.ingest.depth import fuse
from breastplan.ingest.pipeline import ingest_frames
from breastplan.ingest.recording import read_recording, write_recording
from breastplan.case import Case, sha256
from breastplan.ingest.scan import ingest
from breastplan.options import IngestOptions


@pytest.fixture(scope="module")
def scanned(tmp_path_factory):
    """A 10-frame synthetic recording (seed 1, 10° tilt), its truth, and the replayed frames."""
    folder = tmp_path_factory.mktemp("scan")
    scene = synthetic.make_scene(1, tilt_deg=10.0)
    write_recording(folder / "rec.mcap", synthetic.depth_frames(scene, 10, 1), scene.K)
    synthetic.save_truth(folder / "truth.npz", scene, 10)
    return folder, scene, synthetic.load_truth(folder / "truth.npz"), read_recording(folder / "rec.mcap")


def errors_in_camera(result, truth, side):
    inv = np.linalg.inv(result.input_to_breast)
    points = result.points @ inv[:3, :3].T + inv[:3, 3]
    return synthetic.scan_errors(points, result.nipple_camera, inv[:3, 2], truth, side)


# --- recordings -------------------------------------------------------------------------
def test_recording_round_trip_keeps_every_frame_and_the_intrinsics(tmp_path):
    rng = np.random.default_rng(0)
    depth = rng.integers(0, 3000, (12, 40, 64), dtype=np.uint16)
    K = np.array([[450.5, 0, 31.5], [0, 449.0, 19.5], [0, 0, 1]])
    write_recording(tmp_path / "r.mcap", depth, K)
    back = read_recording(tmp_path / "r.mcap")
    assert back.depth.shape == depth.shape and (back.depth == depth).all()
    assert np.allclose(back.K, K)
    assert read_recording(tmp_path / "r.mcap", max_frames=3).depth.shape[0] == 3
    assert [p.name for p in tmp_path.iterdir()] == ["r.mcap"]  # no temporary file left behind


# --- fusion -----------------------------------------------------------------------------
def test_fusion_is_a_robust_average_of_valid_depths():
    stack = np.zeros((5, 1, 4), np.uint16)
    stack[:, 0, 0] = [600, 601, 602, 0, 700]   # 700 is an outlier, 0 no measurement
    stack[:, 0, 1] = [0, 0, 0, 0, 0]           # never measured
    stack[:, 0, 2] = [0, 0, 0, 0, 900]         # one frame of five: too few (< 5 // 3 = 1? no: kept)
    stack[:, 0, 3] = [800, 800, 800, 800, 800]
    fused = fuse(stack)
    assert fused[0, 0] == pytest.approx(601.0)
    assert fused[0, 1] == 0.0
    assert fused[0, 2] == pytest.approx(900.0)
    assert fused[0, 3] == pytest.approx(800.0)
    six = np.zeros((6, 1, 1), np.uint16)
    six[0, 0, 0] = 900                           # one of six frames: below the 6 // 3 = 2 needed
    assert fuse(six)[0, 0] == 0.0


@settings(max_examples=20, deadline=None)
@given(st.floats(450, 900), st.integers(5, 30))
def test_fusion_beats_single_frame_noise(depth_mm, n):
    rng = np.random.default_rng(int(depth_mm * 7 + n))
    sigma = (depth_mm / 600) ** 2
    frames = np.rint(depth_mm + sigma * rng.standard_normal((n, 32, 32))).astype(np.uint16)
    single = np.sqrt(np.mean((frames[0] - depth_mm) ** 2))
    fused = np.sqrt(np.mean((fuse(frames) - depth_mm) ** 2))
    assert fused < single / np.sqrt(n) * 1.6 + 0.05


# --- chest wall -------------------------------------------------------------------------
def test_chest_wall_recovers_a_quadric_under_mounds_and_outliers():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-200, 200, (6000, 2))
    true_z = 650 + 0.0012 * xy[:, 0] ** 2 + 0.0005 * xy[:, 1] ** 2 - 0.05 * xy[:, 1]
    r2 = np.sum((np.abs(xy) - [90, 0]) ** 2, axis=1)
    mound = 55 * np.sqrt(np.clip(1 - r2 / 65**2, 0, None))  # two half-ellipsoid breasts
    z = true_z - mound + rng.normal(0, 0.5, len(xy))
    z[:600] += rng.uniform(20, 80, 600)   # 10 % behind the surface (arms, background)
    wall = fit_chest_wall(np.column_stack([xy, z]), 2)
    grid = np.column_stack([np.linspace(-150, 150, 50), np.linspace(-100, 100, 50)])
    expect = 650 + 0.0012 * grid[:, 0] ** 2 + 0.0005 * grid[:, 1] ** 2 - 0.05 * grid[:, 1]
    assert np.abs(wall.z(grid) - expect).max() < 0.5
    assert wall.height(np.array([[90.0, 0.0, 650 + 0.0012 * 8100 - 55]]))[0] == pytest.approx(55, abs=0.6)


def _chest(xy):
    """A curved chest in a viewing frame (z away from the viewer, mm), not a quadric."""
    x, y = xy[..., 0], xy[..., 1]
    return 600.0 + np.square(x) / 600.0 + np.square(y) / 1800.0 + 1e-6 * x * np.square(y)


@pytest.mark.parametrize("centre", [(100.0, 40.0), (-90.0, -30.0)])
def test_the_wall_under_a_small_and_a_large_breast_is_the_chest_beneath_both(centre):
    """Truth: the chest is the same skin under a small and a large breast whose skirt fades into
    it (height H (1 − r²/R²)², no edge); the wall under the mound is that chest to 0.5 mm, and the
    same under both to 0.3 mm (a quadratic refitted on a ring around the mound rose 0.9–2.1 mm in
    front of it, more under the larger breast)."""
    from breastplan.ingest import breast as B

    grid = np.mgrid[-300:301:10.0, -250:251:10.0].reshape(2, -1).T
    under = np.mgrid[-40:41:10.0, -40:41:10.0].reshape(2, -1).T + centre
    walls = []
    for radius, height in ((70.0, 30.0), (110.0, 70.0)):
        r2 = np.sum(np.square(grid - centre), axis=1) / radius ** 2
        voxels = np.column_stack([grid, _chest(grid) - height * np.clip(1 - r2, 0, None) ** 2])
        first = fit_chest_wall(voxels, 2)
        mound = B.find_mounds(voxels, first, 0.0, 10.0)[0]
        walls.append(B.chest_wall_under(voxels, mound, first).z(under))
        assert np.abs(walls[-1] - _chest(under)).max() < 0.5
    assert np.abs(walls[1] - walls[0]).max() < 0.3


# --- synthetic scanner ------------------------------------------------------------------
def test_scanner_renders_the_true_nipple_at_its_pixel(scanned):
    _, scene, truth, frames = scanned
    for side in synthetic.SIDES:
        nipple = truth[f"{side}_nipple_camera_mm"]
        u, v, _ = scene.K @ (nipple / nipple[2])
        measured = frames.depth[:, int(round(v)), int(round(u))].astype(float)
        measured = measured[measured > 0]
        assert len(measured) >= 5
        assert np.median(measured) == pytest.approx(nipple[2], abs=2.5)  # σ ≈ 1 mm, pixel ≈ 1.3 mm wide


def test_scanner_noise_grows_with_distance_squared():
    scene = synthetic.make_scene(0, distance_mm=600.0, noise_mm=1.0)
    clean, ids = synthetic.render_depth(scene)
    wall = (ids == 3) & np.isfinite(clean)            # the flat wall behind the patient
    frames = synthetic.depth_frames(scene, 4, 0).astype(float)
    ok = wall & (frames > 0).all(axis=0)
    residual = (frames - clean)[:, ok]
    expected = np.sqrt(np.mean((clean[ok] / 600.0) ** 4) + 1 / 12)  # noise plus mm quantisation
    assert residual.std() == pytest.approx(expected, rel=0.1)


def test_breast_frame_of_the_scene_is_on_the_chest_wall():
    T = synthetic.body_from_breast("left")
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    o = T[:3, 3]
    assert o[2] == pytest.approx(synthetic.chest_z(o[0], o[1]))
    h = 1e-4  # z is the chest normal: orthogonal to the chest's tangents
    tangent_x = np.array([h, 0, synthetic.chest_z(o[0] + h, o[1]) - o[2]])
    assert abs(np.dot(tangent_x, T[:3, 2])) < 1e-9


def test_surface_distance_is_zero_on_the_nipple_and_the_offset_along_its_normal():
    scene = synthetic.make_scene(0)
    T = scene.camera_from_breast("right")
    tip = scene.breasts["right"].nipple_mm               # on the surface; its normal is the breast's z
    points = np.array([tip, tip + [0.0, 0.0, 5.0]]) @ T[:3, :3].T + T[:3, 3]
    assert np.allclose(scene.surface_distance("right", points), [0.0, 5.0], atol=0.05)


# --- the pipeline against the truth -----------------------------------------------------
@pytest.mark.parametrize("side", synthetic.SIDES)
def test_ingest_meets_the_accuracy_targets(scanned, side):
    _, _, truth, frames = scanned
    result = ingest_frames(frames, IngestOptions(side))
    e = errors_in_camera(result, truth, side)
    assert e["rms_mm"] <= 0.8
    assert e["nipple_mm"] <= 2.0
    assert e["z_axis_deg"] <= 3.0
    assert e["coverage"] >= 0.95
    assert result.side == side
    assert (result.points[:, 2] > 0).all()                         # above the chest wall
    assert np.mean(np.sum(result.normals * [0, 0, 1], axis=1) > 0) > 0.9  # outward (anterior)


def test_fusion_improves_on_one_frame(scanned):
    _, _, truth, frames = scanned
    one = type(frames)(frames.depth[:1], frames.K, frames.source)
    fused_rms = errors_in_camera(ingest_frames(frames, IngestOptions("left")), truth, "left")["rms_mm"]
    single_rms = errors_in_camera(ingest_frames(one, IngestOptions("left")), truth, "left")["rms_mm"]
    assert fused_rms < 0.7 * single_rms


def test_a_scan_file_in_metres_with_its_own_axes_gives_the_same_breast(scanned, tmp_path):
    folder, scene, truth, frames = scanned
    result = ingest_frames(frames, IngestOptions("right"))
    body_from_camera = np.linalg.inv(scene.camera_from_body)
    a = np.radians(15)  # the scanner's frame: y up, turned 15° about it, metres
    yaw = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    to_file = np.eye(4)
    to_file[:3, :3] = yaw @ body_from_camera[:3, :3]
    to_file[:3, 3] = yaw @ body_from_camera[:3, 3]
    torso_file = (result.torso_camera @ to_file[:3, :3].T + to_file[:3, 3]) / 1000.0
    write_ply(tmp_path / "torso.ply", torso_file)
    from_file = ingest(tmp_path / "torso.ply", IngestOptions("right"))
    assert from_file.source.kind == "file" and "units m" in from_file.source.description
    nipple_camera = np.linalg.solve(to_file[:3, :3], from_file.nipple_camera_mm - to_file[:3, 3])
    assert np.linalg.norm(nipple_camera - truth["right_nipple_camera_mm"]) <= 2.0


def test_manual_nipple_and_roi_override_the_automatic_choice(scanned):
    _, _, truth, frames = scanned
    nipple = truth["left_nipple_camera_mm"] + [1.0, -1.0, 0.5]
    result = ingest_frames(frames, IngestOptions("right", nipple_camera_mm=nipple))   # the nipple wins over --side
    assert result.side == "left" and np.allclose(result.nipple_camera, nipple)
    box = np.concatenate([truth["left_nipple_camera_mm"] - 120, truth["left_nipple_camera_mm"] + 120])
    assert ingest_frames(frames, IngestOptions("right", roi_camera_mm=box)).side == "left"


def test_case_folder_artefacts(scanned, tmp_path):
    folder, _, truth, _ = scanned
    result = ingest(folder / "rec.mcap", IngestOptions("left", voxel_mm=3.0))
    case = Case(tmp_path / "case")
    paths = case.save_scan(result)
    scan = case.load_scan()
    ply = read_ply(paths["scan.ply"])
    assert np.allclose(ply.points, result.points) and ply.normals is not None
    assert np.array_equal(scan.points, result.points) and np.array_equal(scan.normals, result.normals)
    assert scan.side == "left" and scan.source.frames == 10 and scan.voxel_mm == 3.0
    T = scan.input_to_breast
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    assert np.allclose(T[:3, :3] @ scan.nipple_camera_mm + T[:3, 3], scan.nipple_breast_mm)
    assert np.allclose(scan.source.K, truth["K"])
    camera = read_ply(paths["camera.ply"])
    assert any("camera-opencv" in c for c in camera.comments) and len(camera.points) > 10 * len(ply.points)
    assert len(result.points) < len(result.torso_camera) / 10
    # provenance: the recording's content hash and the options that made the scan
    assert scan.provenance.inputs == {"rec.mcap": sha256(folder / "rec.mcap")}
    assert scan.provenance.options["voxel_mm"] == 3.0 and scan.provenance.options["side"] == "left"


def test_an_up_axis_along_the_viewing_direction_is_bad_input():
    from breastplan import BadInputError
    from breastplan.ingest.pipeline import viewing_frame
    rng = np.random.default_rng(0)
    slab = np.column_stack([rng.uniform(-150, 150, 2000), rng.uniform(-250, 250, 2000), rng.normal(0, 5, 2000)])
    with pytest.raises(BadInputError, match="^its up axis"):       # stages name no file; commands do
        viewing_frame(slab, "+z")


def _rotation(yaw, pitch, roll):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("yxz", [yaw, pitch, roll], degrees=True).as_matrix()
    return T


@settings(max_examples=40, deadline=None)
@given(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4), st.floats(-20, 20), st.floats(-25, 25), st.floats(-180, 180))
def test_the_wall_beneath_a_frame_is_where_its_z_axis_meets_a_plane(p, q, yaw, pitch, roll):
    """Truth: for a plane z = 500 + p x + q y of the viewing frame, the line through (x, y, 0) of a
    turned and shifted frame along that frame's z axis meets it at a closed-form t."""
    wall = ChestWall(np.array([500.0, 100 * p, 100 * q]), 1, np.zeros(2), 0.0)
    view_from_frame = _rotation(yaw, pitch, roll) @ np.diag([1.0, -1.0, -1.0, 1.0])   # z towards the viewer
    view_from_frame[:3, 3] = [40.0, -30.0, 480.0]
    xy = np.mgrid[-80:81:40.0, -80:81:40.0].reshape(2, -1).T
    R, o = view_from_frame[:3, :3], view_from_frame[:3, 3]
    start, axis = xy @ R[:, :2].T + o, R[:, 2]
    n = np.array([p, q, -1.0])                                           # plane: n · v + 500 = 0
    t = -(start @ n + 500.0) / (axis @ n)
    assert np.allclose(wall.beneath(np.linalg.inv(view_from_frame), xy), t, atol=1e-6)


def test_a_chest_wall_survives_its_array():
    wall = ChestWall(np.arange(10.0), 3, np.array([5.0, -7.0]), 1.5)
    again = ChestWall.from_array(wall.as_array())
    xy = np.array([[10.0, 20.0], [-30.0, 5.0]])
    assert again.degree == 3 and again.scale_mm == 1.5 and np.allclose(again.z(xy), wall.z(xy))


def test_a_chen_breast_reaches_down_to_the_curved_chest_by_its_extruded_base():
    """Truth: the chest falls away from the base plane by about r²/(2 R) (R the chest's radii,
    420 mm across and 900 mm along the body), so the extruded base of a breast whose base is near
    a disc of radius a holds about π a⁴ (1/R_x + 1/R_y) / 8, and the whole breast more than its primitive."""
    breast = synthetic.make_scene(0).breasts["left"]
    a = float(to_mm(np.mean([getattr(breast.primitive, f"a{i}") for i in range(1, 5)])))
    lens = np.pi * a ** 4 * (1 / synthetic.CHEST_RX + 1 / synthetic.CHEST_RY) / 8 / 1000.0
    extra = breast.volume_on_chest_cc("left") - breast.primitive.volume_cc
    assert 0.7 * lens < extra < 1.3 * lens
