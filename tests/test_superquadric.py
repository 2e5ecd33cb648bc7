"""Superquadric fit: known primitives are recovered (independent truth: the sampled primitive)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from breastplan import BadInputError, Primitive, to_mm
from breastplan.fitting.superquadric import (_chest_prior, _chest_prior_jacobian, _radial, _radial_jacobian,
                                             fit_superquadric)

CASES = [Primitive(11, 9, 10, 12, 9, 0.8, 1.1), Primitive(10, 11, 9.5, 10, 10, 1.0, 1.0),  # asymmetric: the turn about z is defined
         Primitive(9, 12, 8, 11, 10, 1.2, 0.7)]


def posed_samples(P, degrees=10.0, shift=(3.0, -2.0, 0.0)):
    R = Rotation.from_euler("z", degrees, degrees=True).as_matrix()
    return to_mm(P.sample(80, 80)) @ R.T + np.asarray(shift), R


@pytest.mark.parametrize("P", CASES)
def test_noise_free_samples_recover_parameters_and_pose(P):
    data, R = posed_samples(P)
    fit = fit_superquadric(data)
    assert np.allclose(fit.primitive.as_array()[:5], P.as_array()[:5], rtol=0.005)
    assert np.allclose(fit.primitive.as_array()[5:], P.as_array()[5:], atol=0.02)
    assert np.linalg.norm(fit.pose[:3, 3] - [3.0, -2.0, 0.0]) < 0.5
    angle = np.degrees(Rotation.from_matrix(fit.pose[:3, :3].T @ R).magnitude())
    assert angle < 0.5


def test_front_only_with_noise_and_outliers_keeps_volume():
    P = CASES[0]
    data, _ = posed_samples(P)
    view = np.array([0.0, 0.3, 1.0]) / np.linalg.norm([0.0, 0.3, 1.0])   # camera slightly above
    front = data[(data - data.mean(0)) @ view > -20.0]                     # the side facing the camera
    rng = np.random.default_rng(0)
    noisy = front + rng.normal(0.0, 1.0, front.shape)
    k = len(noisy) // 10
    noisy[:k] += rng.normal(0.0, 15.0, (k, 3))
    fit = fit_superquadric(noisy)
    assert abs(fit.primitive.volume_cc / P.volume_cc - 1) < 0.02
    inlier_rms = np.sqrt(np.mean(fit.residuals_mm[k:] ** 2))
    assert inlier_rms <= 1.1


@pytest.mark.parametrize("points,problem", [
    (np.zeros((10, 3)), "at least 50"),
    (np.column_stack([np.arange(100.0), np.zeros(100), np.zeros(100)]), "coplanar or collinear"),
    (np.full((100, 3), np.nan), "NaN"),
])
def test_bad_clouds_are_bad_input(points, problem):
    with pytest.raises(BadInputError, match=problem) as caught:
        fit_superquadric(points)
    assert caught.value.path is None                     # the command that read the file names it


def test_ptotic_breast_recovers_ptosis_parameters():
    from breastplan.deform.global_deformations import Deformation
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    truth = Deformation(ptosis=(1.0, 0.3))
    data = to_mm(truth.apply(P.sample(80, 80), P))
    fit = fit_superquadric(data, deformations=("ptosis",))
    assert np.allclose(fit.deformation.ptosis, (1.0, 0.3), atol=0.02)
    assert np.allclose(fit.primitive.as_array()[:5], P.as_array()[:5], rtol=0.005)
    plain = fit_superquadric(data)
    assert np.sqrt(np.mean(fit.residuals_mm ** 2)) < 0.1 * np.sqrt(np.mean(plain.residuals_mm ** 2))


def test_fit_of_an_ingested_synthetic_scan_matches_the_true_breast():
    from breastplan import transform_points
    from breastplan.scenes import synthetic
    from breastplan.ingest.pipeline import ingest_frames
    from breastplan.options import IngestOptions
    from breastplan.ingest.recording import DepthFrames

    scene = synthetic.make_scene(2, tilt_deg=10.0)
    frames = DepthFrames(synthetic.depth_frames(scene, 10, 2), scene.K, "synthetic")
    for side in synthetic.SIDES:
        scan = ingest_frames(frames, IngestOptions(side))
        fit = fit_superquadric(scan.points, deformations=("turn-top", "ptosis", "turn"))
        model = to_mm(fit.deformation.apply(fit.primitive.sample(60, 96), fit.primitive))
        camera = transform_points(np.linalg.inv(scan.input_to_breast), transform_points(fit.pose, model))
        d = scene.surface_distance(side, camera)
        assert np.sqrt(np.mean(d ** 2)) <= 1.0                          # within 1 mm RMS
        assert abs(fit.primitive.volume_cc / scene.breasts[side].primitive.volume_cc - 1) <= 0.03  # shears keep volume


def central_differences(f, x, h=1e-6):
    """(len(f(x)), len(x)) Jacobian of f by central differences."""
    return np.column_stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(6.0, 14.0), min_size=5, max_size=5), st.floats(0.3, 2.0), st.floats(0.3, 2.0),
       st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3), st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
       st.integers(0, 2**31))
def test_analytic_jacobian_matches_finite_differences(axes, eps1, eps2, rotvec, shift, seed):
    """Truth: central differences of the residual itself, at random parameters and points off the surface."""
    rng = np.random.default_rng(seed)
    P = Primitive(*axes, eps1, eps2)
    points = P.sample(12, 25) * rng.uniform(0.7, 1.3, (300, 1)) + rng.normal(0.0, 0.5, (300, 3))
    q = Rotation.from_rotvec(rotvec).inv().apply(points - shift)
    points = points[np.all(np.abs(q) > 1e-3, axis=1)]    # off the planes where the halves meet (kinks)
    x = np.concatenate([np.log(axes) + rng.normal(0.0, 0.1, 5), [eps1, eps2], rotvec, shift])
    numeric = central_differences(lambda y: _radial(y, points), x)
    assert np.allclose(_radial_jacobian(x, points), numeric, rtol=1e-4, atol=1e-5 * np.abs(numeric).max())
    prior = central_differences(_chest_prior, x)
    assert np.allclose(_chest_prior_jacobian(x), prior, atol=1e-8)


@pytest.mark.parametrize("shape", ["shape1", "shape2", "shape3", "shape4"])
def test_fast_inverse_undoes_the_deformations_of_each_table_4_1_shape(shape):
    """Truth: the primitive samples the library's forward deformations (docs/model.md §3) started from —
    on both sides of top-shape's fold, where the exact inverse keeps the first branch."""
    from breastplan.learn.databases import SHAPES
    P = Primitive(10.5, 9, 11, 9.5, 10, 1.0, 1.0)
    samples = P.sample(60, 60)
    deformed = SHAPES[shape].apply(samples, P)
    assert np.abs(SHAPES[shape].inverse(deformed, P, fast=True) - samples).max() < 0.01


@pytest.mark.parametrize("shape", ["shape2", "shape3"])
def test_full_chen_fit_recovers_a_database_shape(shape):
    """Truth: the primitive and Table 4.1 deformation the breast was built from. Shape 2's top-shape
    lifts its upper half up to 2.25× (β(0.5) = 2.25 by hand from docs/model.md §3's quintic)."""
    from breastplan.deform.global_deformations import KIND_PARAMS
    from breastplan.learn.databases import SHAPES
    P = Primitive(10.5, 9, 11, 9.5, 10, 1.0, 1.0)
    data = to_mm(SHAPES[shape].apply(P.sample(100, 100), P))
    fit = fit_superquadric(data, deformations=tuple(KIND_PARAMS))
    # flatten-side scales the lateral half by γ(1) = 1 − h0 at |x| = a2 (docs/model.md §3), so the data
    # fix the lateral extent a2·(1 − h0), not a2 and h0 apart: compare that extent with the truth's
    truth_h0, fitted_h0 = SHAPES[shape].flatten_side[0], fit.deformation.flatten_side[0]
    extents = fit.primitive.as_array()[:5] * [1, 1 - fitted_h0, 1, 1, 1]
    assert np.allclose(extents, P.as_array()[:5] * [1, 1 - truth_h0, 1, 1, 1], rtol=0.01)
    assert np.median(np.abs(fit.residuals_mm)) < 0.05


@pytest.mark.parametrize("s0,s1", [(1.5, -2.0), (-0.5, 0.25), (0.8, 0.0)])
def test_top_shape_fit_recovers_the_profile_of_a_ptotic_breast(s0, s1):
    """Truth: the top-shape profile β(w) (t0 = t1 = 0) and ptosis the samples were deformed by. The
    four top-shape parameters trade against each other; the profile they give does not. Points
    that cross the tear along y = 0 (docs/model.md §3) make the cost jump, so ptosis is held to the
    drop it gives along the breast's axis, within 0.6 mm (its b0 and b1 trade against each other too)."""
    from breastplan.deform.global_deformations import Deformation, beta, ptosis
    P = Primitive(10, 11, 9.5, 10.5, 9, 0.9, 1.0)
    truth = Deformation(top_shape=(s0, s1, 0.0, 0.0), ptosis=(0.8, 0.2))
    fit = fit_superquadric(to_mm(truth.apply(P.sample(100, 100), P)), deformations=("top-shape", "ptosis", "turn"))
    w = np.linspace(0, 1, 101)
    assert np.abs(beta(w, *fit.deformation.top_shape) - beta(w, s0, s1, 0, 0)).max() < 0.03
    axis = np.column_stack([np.zeros(50), np.zeros(50), np.linspace(0.0, P.a5, 50)])
    drop = lambda params: to_mm(axis[:, 1] - ptosis(axis, *params)[:, 1])  # noqa: E731
    assert np.abs(drop(fit.deformation.ptosis) - drop((0.8, 0.2))).max() < 0.6
    assert np.allclose(fit.primitive.as_array()[:5], P.as_array()[:5], rtol=0.01)
