"""Anthropometric breast measures and body landmarks (plan/measures.py) against independent truths.

Truths: closed-form volumes and pole ratios of half superellipsoid meshes; exact changes of the
measures under known motions of a breast; and, on realistic MakeHuman scenes run through the real
ingest and fit, the body frame the scene was posed with (its mid-sagittal plane is x = 0, its up +y),
MakeHuman's nipple rings and its jugular notch (`Body.sternal_notch`).
"""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from breastplan import BadInputError, Primitive, transform_points
from breastplan.case import Provenance, Source
from breastplan.fitting.breast_fit import fit_breast
from breastplan.scenes.makehuman import NOTCH_VERTICES, BodyOptions, make_body
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import CameraOptions, make_body_scene
from breastplan.ingest.recording import DepthFrames
from breastplan.ingest.scan import scan_record
from breastplan.options import FitOptions, IngestOptions
from breastplan.plan.measures import MEASURES, BodyLandmarks, asymmetry, base_ring, breast_measures, find_landmarks

SIDES = ("left", "right")
NOTCH_MM = 15.0
"""The suprasternal hollow is about 25 mm tall on the skin (from the sternum's slope into the
throat); a surgeon's fingertip finds the notch in it to about this."""
MIDLINE_MM = 5.0
"""Nipple-to-midline: the plane within this of the body's x = 0 at the nipples."""
UP_DEG = 5.0
"""The up axis: an upright body's sternum is vertical to a few degrees, the camera is pitched ±15°."""
PLANE_DEG = 3.0
"""The mid-sagittal plane's normal."""
LEVEL_MM = 4.0
"""Left/right difference of the nipples' heights (as tests/test_realistic.py accepts)."""
FRAMES = 3
SCENES = {
    "asymmetric (asymmetry 0.4), a-pose, pitch +15, yaw +10": (
        BodyOptions(cup=0.7, modifiers={"asymmetry": 0.4}),
        CameraOptions(resolution="640x400", pitch_deg=15.0, yaw_deg=10.0, wall_mm=None)),
    "sagging (cup 0.9, firmness 0), arms down, pitch -15, yaw -10, wall": (
        BodyOptions(cup=0.9, firmness=0.0, pose="arms-down"),
        CameraOptions(resolution="640x400", pitch_deg=-15.0, yaw_deg=-10.0, distance_mm=700.0, wall_mm=400.0)),
    "heavy (weight 0.9), hands on hips, pitch -15": (
        BodyOptions(weight=0.9, pose="hands-on-hips"),
        CameraOptions(resolution="640x400", pitch_deg=-15.0, distance_mm=800.0, wall_mm=None)),
}
ASYMMETRIC = next(iter(SCENES))


# --- realistic scenes through the real ingest and fit, built once --------------------------------
_built: dict = {}


def built(name):
    """(scene, {side: Scan}, landmarks from the scans) of a scene."""
    if name not in _built:
        scene = make_body_scene(*SCENES[name])
        frames = DepthFrames(scene.frames(FRAMES, seed=1), scene.camera.K, "synthetic")
        scans = {}
        for side in SIDES:
            options = IngestOptions(side=side)
            scans[side] = scan_record(ingest_frames(frames, options), Source("recording", name, FRAMES, scene.camera.K,
                                                                             np.array(scene.camera.size)),
                                      options, Provenance())
        landmarks = find_landmarks(scans["left"].torso_camera, {s: scans[s].nipple_camera_mm for s in SIDES},
                                   scans["left"].input_to_view, scans["left"].plumb_camera)
        _built[name] = scene, scans, landmarks
    return _built[name]


_fits: dict = {}


def fitted(name, side):
    """The case's Fit of one side (a short FFD: the measures tested here do not hang on its last mm)."""
    if (name, side) not in _fits:
        _, scans, _ = built(name)
        _fits[name, side] = fit_breast(scans[side].points, FitOptions(max_iterations=10)).artefact()
    return _fits[name, side]


def measured(name, side):
    """breast_measures of one side as the plan job calls it: the fitted mesh in the input frame."""
    _, scans, landmarks = built(name)
    scan, fit = scans[side], fitted(name, side)
    vertices = transform_points(np.linalg.inv(scan.input_to_breast), fit.vertices)
    return breast_measures(landmarks, scan.nipple_camera_mm, vertices, fit.faces)


def body_truth(scene):
    """The true landmarks in the camera frame: the notch, the body's left (normal of x = 0) and up."""
    R = scene.camera_from_body[:3, :3]
    notch = transform_points(scene.camera_from_body, scene.body.sternal_notch[None])[0]
    return notch, R[:, 0], R[:, 1]


def degrees(a, b):
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def test_the_notch_vertices_lie_on_the_midline_below_the_chin():
    for options in (BodyOptions(), BodyOptions(weight=0.9, cup=1.0), BodyOptions(weight=0.1, muscle=1.0)):
        V = make_body(options).vertices
        notch = V[list(NOTCH_VERTICES)]
        assert np.abs(notch[:, 0]).max() < 1e-6                          # on the mid-sagittal plane
        above = V[(np.abs(V[:, 0]) < 1.0) & (V[:, 1] > notch[:, 1].max()) & (V[:, 1] < notch[:, 1].max() + 40)]
        assert (above[:, 2].max() > notch[:, 2]).all()                    # the throat stands in front of it


@pytest.mark.parametrize("name", SCENES)
def test_landmarks_match_the_body_frame(name):
    scene, scans, found = built(name)
    notch, left, up = body_truth(scene)
    assert degrees(found.up_axis, up) < UP_DEG
    assert degrees(found.left_axis, left) < PLANE_DEG
    assert np.linalg.norm(found.sternal_notch - notch) < NOTCH_MM
    to_body = np.linalg.inv(scene.camera_from_body)
    for side, nipple in scene.nipples_camera().items():        # the true nipples, measured to the found plane
        true = abs(transform_points(to_body, nipple)[0])
        assert abs(abs((nipple - found.midline_point) @ found.left_axis) - true) < MIDLINE_MM, side
    nipples = scene.body.nipples                                   # body frame: y is up
    true_level = nipples["left"][1] - nipples["right"][1]
    found_level = (scans["left"].nipple_camera_mm - scans["right"].nipple_camera_mm) @ found.up_axis
    assert abs(found_level - true_level) < LEVEL_MM             # the ingested nipples, levelled by the found up


@pytest.mark.parametrize("name", list(SCENES)[:2])
def test_landmarks_follow_a_rigid_motion_of_the_input(name):
    """A scan file's frame: the same torso turned and moved, with its viewing frame given."""
    _, scans, found = built(name)
    scan = scans["left"]
    rng = np.random.default_rng(len(name))
    T = _rigid(rng.normal(size=4), rng.uniform(-800, 800, 3))
    moved = find_landmarks(transform_points(T, scan.torso_camera),
                           {s: transform_points(T, scans[s].nipple_camera_mm) for s in SIDES},
                           scan.input_to_view @ np.linalg.inv(T)).transformed(np.linalg.inv(T))
    # the 4 and 8 mm voxels and 5 mm bins do not turn with the body: a few mm of resampling
    assert np.linalg.norm(moved.sternal_notch - found.sternal_notch) < 3.0
    assert degrees(moved.up_axis, found.up_axis) < 1.5 and degrees(moved.left_axis, found.left_axis) < 1.5
    assert abs((moved.midline_point - found.midline_point) @ found.left_axis) < 1.5


@pytest.mark.parametrize("side", SIDES)
def test_one_nipple_is_enough_for_the_landmarks(side):
    """A patient with one breast: the plane starts from the torso's middle instead of the nipples."""
    name = list(SCENES)[2]
    scene, scans, _ = built(name)
    notch, left, up = body_truth(scene)
    found = find_landmarks(scans[side].torso_camera, {side: scans[side].nipple_camera_mm})
    assert degrees(found.up_axis, up) < UP_DEG and degrees(found.left_axis, left) < PLANE_DEG
    assert np.linalg.norm(found.sternal_notch - notch) < NOTCH_MM
    nipple = scene.nipples_camera()[side]
    true = abs(transform_points(np.linalg.inv(scene.camera_from_body), nipple)[0])
    assert abs(abs((nipple - found.midline_point) @ found.left_axis) - true) < MIDLINE_MM


def test_nipple_height_asymmetry_has_the_sign_and_size_of_the_truth():
    """MakeHuman's asymmetry +0.4 lowers the left breast: the measured drop below the notch is larger
    on the left, by the true difference of the nipples' heights."""
    scene, _, _ = built(ASYMMETRIC)
    nipples = scene.body.nipples                                   # body frame: y is up
    true = nipples["right"][1] - nipples["left"][1]
    assert true > 5.0                                              # the scene is asymmetric as meant
    measures = {side: measured(ASYMMETRIC, side) for side in SIDES}
    diff = asymmetry(measures)["nipple_below_notch_mm"]
    assert diff["left_minus_right"] > 0
    assert abs(diff["left_minus_right"] - true) < LEVEL_MM
    assert diff["abs_difference"] == abs(diff["left_minus_right"])
    for side in SIDES:
        m = measures[side]
        assert set(m) == set(MEASURES) and all(np.isfinite(v) for v in m.values())
        assert abs(m["upper_pole_cc"] + m["lower_pole_cc"] - m["volume_cc"]) < 1e-6 * m["volume_cc"]
        assert m["nipple_below_notch_mm"] <= m["notch_to_nipple_mm"]   # a height is no longer than the chord


def test_a_torso_without_a_neck_above_the_nipples_is_refused():
    _, scans, found = built(ASYMMETRIC)
    torso = scans["left"].torso_camera
    low = torso[(torso - scans["left"].nipple_camera_mm) @ found.up_axis < 20.0]
    with pytest.raises(BadInputError, match="sternal notch"):
        find_landmarks(low, {s: scans[s].nipple_camera_mm for s in SIDES})


# --- closed forms on half superellipsoids ------------------------------------------------------
A_MM, UP_MM, LOW_MM, C_MM = 60.0, 54.0, 42.0, 45.0     # lateral half-width, upper and lower extents, height
PLACE = np.array([100.0, 300.0, 50.0])                   # base centre in a frame x left, y up, z anterior
NOTCH = np.array([0.0, 500.0, 40.0])
BODY = BodyLandmarks(NOTCH, [0.0, 350.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def half_ellipsoid(a=A_MM, up=UP_MM, low=LOW_MM, c=C_MM, eps=(1.0, 1.0), grid=(120, 240)):
    """Closed mesh (mm) of a half superellipsoid on its base plane, placed at PLACE; its nipple."""
    p = Primitive(a / 6, a / 6, up / 6, low / 6, c / 6, *eps)
    V, F = p.mesh(*grid)
    return V * 6.0 + PLACE, F, PLACE + [0.0, 0.0, c]


def test_the_base_ring_is_the_first_latitude_ring():
    V, F, _ = half_ellipsoid(grid=(30, 48))
    assert np.array_equal(base_ring(F), np.arange(48))      # Primitive.mesh: ring u = 0 comes first


def test_half_ellipsoid_measures_match_closed_forms():
    V, F, nipple = half_ellipsoid()
    m = breast_measures(BODY, nipple, V, F)
    # an inscribed polyhedron misses (Δθ)²/6 of the volume per direction: under 3e-4 on this grid
    assert m["volume_cc"] == pytest.approx(np.pi / 3 * A_MM * C_MM * (UP_MM + LOW_MM) / 1000, rel=1e-3)
    assert m["upper_pole_cc"] == pytest.approx(np.pi / 3 * A_MM * C_MM * UP_MM / 1000, rel=1e-3)
    assert m["pole_ratio"] == pytest.approx(UP_MM / LOW_MM, rel=1e-9)   # the halves are scaled copies
    assert m["width_mm"] == pytest.approx(2 * A_MM, rel=1e-12)
    assert m["projection_mm"] == pytest.approx(C_MM, rel=1e-12)
    assert m["nipple_to_fold_mm"] == pytest.approx(np.hypot(LOW_MM, C_MM), rel=1e-12)
    assert m["nipple_to_midline_mm"] == pytest.approx(PLACE[0], rel=1e-12)
    assert m["notch_to_nipple_mm"] == pytest.approx(np.linalg.norm(nipple - NOTCH), rel=1e-12)
    assert m["nipple_below_notch_mm"] == pytest.approx(NOTCH[1] - PLACE[1], rel=1e-12)


def test_moving_and_scaling_a_breast_changes_its_measures_as_it_should():
    """What a plan does to a breast while the body's landmarks stay."""
    V, F, nipple = half_ellipsoid()
    before = breast_measures(BODY, nipple, V, F)
    drop = breast_measures(BODY, nipple - [0, 20, 0], V - [0, 20, 0], F)         # 20 mm lower
    assert drop["nipple_below_notch_mm"] == pytest.approx(before["nipple_below_notch_mm"] + 20)
    out = breast_measures(BODY, nipple + [15, 0, 0], V + [15, 0, 0], F)          # 15 mm lateral
    assert out["nipple_to_midline_mm"] == pytest.approx(before["nipple_to_midline_mm"] + 15)
    for moved in (drop, out):
        for name in ("volume_cc", "pole_ratio", "width_mm", "projection_mm", "nipple_to_fold_mm"):
            assert moved[name] == pytest.approx(before[name], rel=1e-9), name
    s = 1.2                                                                         # grown about its base centre
    grown = breast_measures(BODY, PLACE + s * (nipple - PLACE), PLACE + s * (V - PLACE), F)
    assert grown["volume_cc"] == pytest.approx(s**3 * before["volume_cc"], rel=1e-9)
    for name in ("width_mm", "projection_mm", "nipple_to_fold_mm"):
        assert grown[name] == pytest.approx(s * before[name], rel=1e-9), name
    assert grown["pole_ratio"] == pytest.approx(before["pole_ratio"], rel=1e-9)


def test_a_mesh_turned_inside_out_is_refused():
    V, F, nipple = half_ellipsoid(grid=(20, 32))
    with pytest.raises(BadInputError, match="encloses no volume"):
        breast_measures(BODY, nipple, V, F[:, ::-1])


def _rigid(q, t) -> np.ndarray:
    """(4, 4) rotation by the quaternion q (normalised) and translation t."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                 [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                 [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    T[:3, 3] = t
    return T


semi = st.floats(4.0, 14.0)
quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)
shifts = st.lists(st.floats(-1000, 1000), min_size=3, max_size=3)


@settings(max_examples=30, deadline=None)
@given(a=st.lists(semi, min_size=5, max_size=5), eps=st.tuples(st.floats(0.3, 1.5), st.floats(0.3, 1.5)),
       q=quaternions, t=shifts)
def test_pole_ratio_is_the_ratio_of_the_vertical_semi_axes(a, eps, q, t):
    """Above and below the nipple's horizontal plane a primitive's halves are the same shape scaled
    in height by a3 and a4 (and so is its mesh, whose grid is symmetric): the volume ratio is a3/a4,
    1 for a breast symmetric about that plane, wherever the body stands."""
    T = _rigid(q, t)
    p = Primitive(*a, *eps)
    V, F = p.mesh(24, 48)
    body = BODY.transformed(T)
    m = breast_measures(body, transform_points(T, [0.0, 0.0, a[4] * 6]), transform_points(T, V * 6.0), F)
    assert m["pole_ratio"] == pytest.approx(a[2] / a[3], rel=1e-6)
    assert m["upper_pole_cc"] + m["lower_pole_cc"] == pytest.approx(m["volume_cc"], rel=1e-9)
    symmetric = Primitive(a[0], a[1], a[2], a[2], a[4], *eps).mesh(24, 48)
    m = breast_measures(body, transform_points(T, [0.0, 0.0, a[4] * 6]), transform_points(T, symmetric[0] * 6.0), F)
    assert m["pole_ratio"] == pytest.approx(1.0, rel=1e-6)


@settings(max_examples=30, deadline=None)
@given(q=quaternions, t=shifts)
def test_measures_do_not_depend_on_the_frame(q, t):
    """Every input moved by one rigid motion: the same measures."""
    T = _rigid(q, t)
    V, F, nipple = half_ellipsoid(up=50.0, low=58.0, grid=(30, 64))
    V = V + 8.0 * np.sin(V[:, [1, 2, 0]] / 17.0)            # no longer a primitive: a lumpy breast
    before = breast_measures(BODY, nipple, V, F)
    after = breast_measures(BODY.transformed(T), transform_points(T, nipple), transform_points(T, V), F)
    for name in MEASURES:
        assert after[name] == pytest.approx(before[name], rel=1e-9, abs=1e-9), name


def test_asymmetry_is_left_minus_right_for_the_measures_both_sides_have():
    out = asymmetry({"left": {"volume_cc": 300.0, "width_mm": 120.0}, "right": {"volume_cc": 340.0}})
    assert out == {"volume_cc": {"left_minus_right": -40.0, "abs_difference": 40.0}}
    assert asymmetry({"left": {"volume_cc": 300.0}}) == {}


def test_landmarks_must_be_an_orthonormal_frame():
    with pytest.raises(ValueError, match="orthogonal unit"):
        BodyLandmarks(NOTCH, [0, 0, 0], [1.0, 0, 0], [0.1, 1.0, 0])
    with pytest.raises(ValueError, match="3 finite numbers"):
        BodyLandmarks([0, np.nan, 0], [0, 0, 0], [1.0, 0, 0], [0, 1.0, 0])
