"""The five global deformations (docs/model.md §3): boundary conditions, identities, shears, inverses."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from breastplan import Primitive
from breastplan.deform import global_deformations as gd
from breastplan.deform.conditions import CONDITIONS
from breastplan.deform.global_deformations import Deformation, apply_kind
from breastplan.meshes import mesh_volume

import reference_model as ref

coef = st.floats(-8.0, 8.0)
PRIM = Primitive(9.0, 12.0, 10.5, 8.0, 11.0, 0.9, 1.1)


def poly_derivatives(f, degree):
    """Coefficients of f (a polynomial of `degree`) by interpolation, independent of its formula."""
    w = np.linspace(0.0, 1.0, degree + 4)
    return np.polynomial.Polynomial.fit(w, f(w), degree, domain=[0, 1], window=[0, 1])


@settings(max_examples=200, deadline=None)
@given(coef, coef, coef, coef)
def test_beta_meets_its_six_boundary_conditions(s0, s1, t0, t1):
    p = poly_derivatives(lambda w: gd.beta(w, s0, s1, t0, t1), 5)
    d1, d2 = p.deriv(1), p.deriv(2)
    scale = 1 + abs(s0) + abs(s1) + abs(t0) + abs(t1)
    assert p(0) == pytest.approx(1, abs=1e-9 * scale) and p(1) == pytest.approx(1, abs=1e-9 * scale)
    assert d1(0) == pytest.approx(s0, abs=1e-8 * scale) and d1(1) == pytest.approx(s1, abs=1e-8 * scale)
    assert d2(0) == pytest.approx(t0, abs=1e-7 * scale) and d2(1) == pytest.approx(t1, abs=1e-7 * scale)


@settings(max_examples=200, deadline=None)
@given(st.floats(-0.5, 0.9), coef)
def test_gamma_meets_its_four_boundary_conditions(h0, h1):
    p = poly_derivatives(lambda w: gd.gamma(w, h0, h1), 3)
    d1 = p.deriv(1)
    assert p(0) == pytest.approx(1, abs=1e-9) and d1(0) == pytest.approx(0, abs=1e-8)
    assert p(1) == pytest.approx(1 - h0, abs=1e-9) and d1(1) == pytest.approx(h1, abs=1e-8)


def test_hand_computed_ptosis_point():
    # ζ = 10/10 = 1: y ← 0 − (1·1 + 0.5·1²) = −1.5
    assert np.allclose(gd.ptosis([[0.0, 0.0, 10.0]], 1.0, 0.5), [[0.0, -1.5, 10.0]])
    # turn at z = 20 (ζ = 2): x ← 1 − (0.3·2 + 0.1·4) = 0
    assert np.allclose(gd.turn([[1.0, 2.0, 20.0]], 0.3, 0.1), [[0.0, 2.0, 20.0]])
    # turn-top at y = a3/2: x ← 0 − (0.4·0.5 + 0.2·0.25); below y = 0 nothing moves
    out = gd.turn_top([[0.0, 5.25, 3.0], [0.0, -5.0, 3.0]], 0.4, 0.2, primitive=PRIM)
    assert np.allclose(out, [[-0.25, 5.25, 3.0], [0.0, -5.0, 3.0]])


def test_hand_computed_flatten_side_and_top_shape():
    # flatten-side: the lateral extreme x = −a2 becomes −a2·(1 − h0); medial points stay
    out = gd.flatten_side([[-12.0, 0, 0], [5.0, 0, 0]], 0.1, 0.3, primitive=PRIM)
    assert np.allclose(out, [[-10.8, 0, 0], [5.0, 0, 0]])
    # top-shape leaves the base ring (w = 0) and the nipple (w = 1) in place
    prim = Primitive()
    out = gd.top_shape([[0.0, 10.0, 0.0], [0.0, 1e-9, 10.0]], 2.0, -3.0, 1.0, 1.0, primitive=prim)
    assert np.allclose(out, [[0.0, 10.0, 0.0], [0.0, 1e-9, 10.0]])


random_points = st.integers(0, 2**32 - 1).map(
    lambda seed: np.random.default_rng(seed).uniform([-12, -10, 0], [12, 10, 11], size=(200, 3)))
ALL_KINDS = list(gd.KIND_PARAMS)


@settings(max_examples=30, deadline=None)
@given(random_points, st.sampled_from(ALL_KINDS))
def test_zero_parameters_are_the_identity(points, kind):
    zeros = [0.0] * len(gd.KIND_PARAMS[kind])
    assert np.array_equal(apply_kind(points, kind, zeros, PRIM), points)


@settings(max_examples=30, deadline=None)
@given(random_points, st.sampled_from(["flatten-side", "turn-top", "ptosis", "turn"]),
       st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2))
def test_only_top_shape_changes_z(points, kind, params):
    assert np.array_equal(apply_kind(points, kind, params, PRIM)[:, 2], points[:, 2])


def test_input_is_not_modified_and_order_is_kept():
    points = PRIM.sample(20, 20)
    keep = points.copy()
    out = Deformation(top_shape=(1, -0.5, 0.5, -0.5), ptosis=(1, 0.2)).apply(points, PRIM)
    assert np.array_equal(points, keep) and out.shape == points.shape


def jacobian_det(f, points, h=1e-5):
    cols = [(f(points + h * e) - f(points - h * e)) / (2 * h) for e in np.eye(3)]
    return np.linalg.det(np.stack(cols, axis=-1))


@pytest.mark.parametrize("kind,params", [("ptosis", (2.25, 0.5)), ("turn", (1.1, 0.625)),
                                         ("turn-top", (0.41, 0.3))])
def test_shears_have_unit_jacobian_and_keep_volume(kind, params):
    rng = np.random.default_rng(1)
    inside = rng.uniform([-8, 0.5, 0.5], [8, 8, 9], size=(300, 3))  # y > 0 for turn-top's half
    det = jacobian_det(lambda p: apply_kind(p, kind, params, PRIM), inside)
    assert np.allclose(det, 1.0, atol=1e-6)
    V, F = PRIM.mesh(100, 100, closed=True)
    before = mesh_volume(V, F)
    assert mesh_volume(apply_kind(V, kind, params, PRIM), F) == pytest.approx(before, rel=1e-6)


TABLE_PARAMS = {  # Table 4.1 shape values and Table 4.2 range ends
    "top-shape": [(0.5, -1, 0, -1), (1, -0.5, 0.5, -0.5), (-2.5, 2, 0, 0), (1.75, -2, 0, 0)],
    "flatten-side": [(0, 0.01), (0, 0.05), (0.1, 0)],
    "turn-top": [(0.41, 0), (0.05, 0.05), (0, 0.3)],
    "ptosis": [(2.25, 0), (0.5, 0.5), (-0.2, 0)],
    "turn": [(1.1, 0.5), (0.5, 0.625), (0.38, 0)],
}


def first_fold(prim, params, n=200_001):
    """z where z·β(w(z)) first stops increasing on [0, a5] (a5 if never): the invertible branch."""
    z = np.linspace(0, prim.a5, n)
    f = z * gd.beta(np.arcsin((z / prim.a5) ** (1 / prim.eps1)) * 2 / np.pi, *params)
    falling = np.diff(f) <= 0
    return prim.a5 if not falling.any() else z[np.argmax(falling)]


@pytest.mark.parametrize("kind,params", [(k, p) for k, ps in TABLE_PARAMS.items() for p in ps])
def test_every_deformation_is_invertible(kind, params):
    inside = np.random.default_rng(2).uniform(-10, 10, (500, 3))
    if kind == "top-shape":  # off the surface, invertible where a height has one preimage (see the next test)
        moved = gd.top_shape(inside, *params, primitive=PRIM)
        inside = inside[(ref.top_shape_preimages(moved, PRIM.as_array(), *params) == 1) | (inside[:, 1] <= 0)]
    points = np.vstack([PRIM.sample(60, 60), inside])
    there = apply_kind(points, kind, params, PRIM)
    back = apply_kind(there, kind, params, PRIM, inverse=True)
    assert np.allclose(back, points, atol=1e-9)


@pytest.mark.parametrize("params", [(0.5, -1, 0, -1), (1.75, -2, 0, 0), (0.25, -0.5, 0, 0)])
def test_top_shape_with_negative_s1_folds_below_the_nipple(params):
    # β(1) = 1 and β'(1) = s1 < 0 while dw/dz → ∞ at the nipple: z·β(w(z)) must decrease
    # to a5 at the nipple, so two heights map to one and no inverse exists for that band.
    prim = Primitive()
    z_star = first_fold(prim, params)
    assert z_star < prim.a5
    pts = np.array([[0.0, 1.0, z_star], [0.0, 1.0, prim.a5]])
    lifted = gd.top_shape(pts, *params, primitive=prim)[:, 2]
    assert lifted[0] > lifted[1] == pytest.approx(prim.a5)
    # far above the nipple top-shape is the identity (β(1) = 1), and so is its inverse
    high = np.array([[0.0, 1.0, 2 * prim.a5]])
    assert np.array_equal(gd.top_shape_inverse(gd.top_shape(high, *params, primitive=prim), *params,
                                               primitive=prim), high)


def test_composition_follows_model_order_and_inverts():
    d = Deformation(top_shape=(-1, 0.5, 0, 0), flatten_side=(0.1, 0), turn_top=(0.41, 0),
                    ptosis=(-0.1, -0.05), turn=(0.38, 0))
    p = PRIM.sample(50, 50)
    expected = p
    for kind in ["top-shape", "flatten-side", "turn-top", "ptosis", "turn"]:  # docs/model.md §3 order
        expected = apply_kind(expected, kind, d.params(kind), PRIM)
    assert np.array_equal(d.apply(p, PRIM), expected)
    assert np.allclose(d.inverse(d.apply(p, PRIM), PRIM), p, atol=1e-9)
    assert Deformation.from_vector(d.as_vector()) == d


def test_primitive_is_required_where_the_formula_needs_it():
    for kind in ("top-shape", "flatten-side", "turn-top"):
        with pytest.raises(ValueError, match="primitive"):
            apply_kind(np.zeros((3, 3)), kind, {}, None)


def test_parameter_names_are_checked():
    with pytest.raises(ValueError, match="b0, b1"):
        apply_kind(np.zeros((1, 3)), "ptosis", {"c0": 1.0})
    with pytest.raises(ValueError, match="unknown deformation"):
        apply_kind(np.zeros((1, 3)), "sag", {})


SHAPED = Deformation(top_shape=(1.0, -0.5, 0.5, -0.5), flatten_side=(0.1, 0), turn_top=(0.41, 0),
                     ptosis=(-0.1, -0.05), turn=(0.38, 0))


@settings(max_examples=30, deadline=None)
@given(st.sampled_from(["ptosis", "turn"]), st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=2))
def test_a_change_of_the_last_stages_is_the_change_applied_on_top(kind, params):
    p = PRIM.sample(30, 30)
    moved = gd.changing(kind, p, SHAPED, PRIM)(params)
    assert np.allclose(moved, apply_kind(SHAPED.apply(p, PRIM), kind, params), atol=1e-12)


def test_a_top_shape_change_acts_on_the_breasts_own_top_shape():
    p = PRIM.sample(40, 40)
    change = gd.changing("top-shape", p, SHAPED, PRIM)
    assert np.allclose(change((0, 0, 0, 0)), SHAPED.apply(p, PRIM), atol=1e-12)
    # cancelling the breast's own top-shape leaves the breast without one: one chain, not two stacked
    flat = Deformation.from_vector(np.r_[0, 0, 0, 0, SHAPED.as_vector()[4:]])
    assert np.allclose(change((-1.0, 0.5, -0.5, 0.5)), flat.apply(p, PRIM), atol=1e-12)


def test_split_and_plus_keep_model_order():
    before, rest = SHAPED.split("turn-top")
    assert before.active() == ["top-shape", "flatten-side"] and rest.active() == ["turn-top", "ptosis", "turn"]
    assert np.allclose(rest.apply(before.apply(PRIM.sample(20, 20), PRIM), PRIM),
                       SHAPED.apply(PRIM.sample(20, 20), PRIM), atol=1e-12)
    assert SHAPED.plus("ptosis", {"b1": 0.05}).ptosis == (-0.1, 0.0)


@settings(max_examples=40, deadline=None)
@given(axes=st.tuples(*[st.floats(5.0, 15.0)] * 5), eps=st.tuples(st.floats(0.3, 2.0), st.floats(0.3, 2.0)),
       row=st.sampled_from([c for c in CONDITIONS.values() if c.kind == "top-shape"]), t=st.floats(0.0, 1.0))
def test_top_shape_takes_every_surface_point_back_even_where_its_map_folds(axes, eps, row, t):
    # on any primitive, along any top-shape condition (its map may fold once, or rise, fall and rise
    # again): a surface point's preimage is the primitive's own height above its (x, y)
    prim = Primitive(*axes, *eps)
    params = tuple(row.at(t))
    samples = prim.sample(40, 36)
    moved = gd.top_shape(samples, *params, primitive=prim)
    # near a turn of the map f' → 0, so rounding in f moves a preimage by up to its square root
    assert np.allclose(gd.top_shape_inverse(moved, *params, primitive=prim), samples, atol=1e-6)
    assert np.allclose(gd.top_shape_inverse(moved, *params, primitive=prim, fast=True), samples, atol=0.05)


def test_a_deformation_of_a_scalar_is_refused_in_a_sentence():
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        gd.ptosis(1.0, 1.0, 0.0)

