"""The breast primitive against closed forms and geometric identities (docs/model.md §2)."""
import numpy as np
import pymeshlab
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from breastplan import Primitive, mu3_to_cc, uv_grid
from breastplan.meshes import mesh_volume

axes = st.floats(4.0, 16.0)
exps = st.floats(0.5, 1.6)
primitives = st.builds(Primitive, axes, axes, axes, axes, axes, exps, exps)


@pytest.mark.parametrize("a", [1.0, 6.5, 10.0, 23.0])
def test_hemisphere_volume_is_two_thirds_pi_a_cubed(a):
    assert Primitive(a, a, a, a, a, 1.0, 1.0).volume_mu3 == pytest.approx(2 / 3 * np.pi * a**3, rel=1e-12)


def test_p00_is_452_cc():
    # 60 mm hemisphere: (2/3)·π·60³ mm³ = 452.389 cc (docs/model.md §1)
    assert Primitive().volume_cc == pytest.approx(2 / 3 * np.pi * 60**3 / 1000, rel=1e-12)
    assert mu3_to_cc(1.0) == pytest.approx(0.216)


@pytest.mark.parametrize("eps", [(1.0, 1.0), (0.6, 0.8), (0.8, 1.3), (1.2, 0.7), (1.5, 1.5)])
def test_closed_mesh_volume_matches_closed_form(eps):
    prim = Primitive(9.0, 12.0, 10.5, 8.0, 11.0, *eps)
    V, F = prim.mesh(100, 100, closed=True)
    assert mesh_volume(V, F) == pytest.approx(prim.volume_mu3, rel=0.005)


def test_closed_mesh_volume_matches_pymeshlab_and_is_watertight():
    prim = Primitive(9.0, 12.0, 10.5, 8.0, 11.0, 0.8, 1.2)
    V, F = prim.mesh(100, 100, closed=True)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(V, F))
    measures = ms.get_geometric_measures()
    assert measures["mesh_volume"] == pytest.approx(prim.volume_mu3, rel=0.005)
    topo = ms.get_topological_measures()
    assert topo["boundary_edges"] == 0
    assert topo["non_two_manifold_edges"] == 0
    assert topo["number_holes"] == 0


def test_open_mesh_has_one_boundary_ring_on_the_chest_wall():
    V, F = Primitive().mesh(40, 60, closed=False)
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    boundary = np.unique(uniq[count == 1])
    assert len(boundary) == 60
    assert np.allclose(V[boundary, 2], 0.0)


@settings(max_examples=40, deadline=None)
@given(primitives)
def test_samples_lie_on_the_surface(prim):
    p = prim.sample(30, 40)
    assert np.allclose(prim.inside_outside(p), 1.0, atol=1e-9)
    assert np.allclose(prim.radial_distance(p), 0.0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(primitives, st.floats(0.3, 3.0))
def test_scaled_points_radial_distance(prim, lam):
    # F(λp) = λ^(2/eps1) F(p), so a surface point scaled by λ is |λ − 1|·|p| from the surface
    p = prim.sample(20, 24)
    q = lam * p
    assert np.allclose(prim.inside_outside(q), lam ** (2 / prim.eps1), rtol=1e-9)
    assert np.allclose(prim.radial_distance(q), abs(lam - 1) * np.linalg.norm(p, axis=1), atol=1e-9)
    assert np.allclose(prim.radial_projection(q), p, atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(primitives)
def test_latitude_of_samples_is_their_grid_latitude(prim):
    u, v = uv_grid(25, 16)
    p = prim.sample(25, 16)
    assert np.allclose(prim.latitude(p), np.repeat(u, 16), atol=1e-7)


def test_sample_landmarks():
    prim = Primitive(8.0, 12.0, 9.0, 11.0, 7.0, 1.0, 1.0)
    p = prim.sample(11, 8).reshape(11, 8, 3)
    assert np.allclose(p[-1], [0, 0, 7.0])            # last latitude row is the nipple
    assert np.allclose(p[0, :, 2], 0.0)               # first row is the chest-wall ring
    ring = p[0]                                       # v = −π, −3π/4, ..., 3π/4
    assert np.allclose(ring[0], [-12.0, 0, 0], atol=1e-12)   # v = −π: lateral semi-axis a2
    assert np.allclose(ring[2], [0, -11.0, 0], atol=1e-12)   # v = −π/2: lower pole a4
    assert np.allclose(ring[4], [8.0, 0, 0], atol=1e-12)     # v = 0: a1
    assert np.allclose(ring[6], [0, 9.0, 0], atol=1e-12)     # v = π/2: upper pole a3


def test_invalid_primitive_is_refused():
    with pytest.raises(ValueError):
        Primitive(a1=-1.0)
    with pytest.raises(ValueError):
        Primitive(eps1=float("nan"))
    with pytest.raises(TypeError, match="a1 must be a real number"):
        Primitive(a1="10")


@pytest.mark.parametrize("count", [0, 6, 8])
def test_a_primitive_from_other_than_seven_values_is_refused_not_filled_in(count):
    with pytest.raises(ValueError, match=f"7 parameters .* got {count} values"):
        Primitive.from_array(np.full(count, 5.0))


def test_a_primitive_comment_naming_only_some_parameters_is_refused():
    assert Primitive.from_comments([Primitive(a1=3.0).comment()]) == Primitive(a1=3.0)
    with pytest.raises(ValueError, match="names a1, not a1, a2"):
        Primitive.from_comments(["primitive (model units) a1=3"])


@pytest.mark.parametrize("e", [0.1, 0.3, 0.5, 1.0, 1.7, 2.0, 3.5, 60.0, 150.0])
def test_euler_beta_matches_scipy(e):
    from scipy.special import beta
    from breastplan.primitive import euler_beta

    for a, b in ((e / 2 + 1, e), (e / 2, e / 2)):
        assert euler_beta(a, b) == pytest.approx(beta(a, b), rel=1e-12)


def _disc_breast(a=60.0):
    """A closed hemisphere-like breast (mm) on a round base of radius a: the primitive with equal
    semi-axes and eps2 = 1, scaled to mm."""
    V, F = Primitive(10, 10, 10, 10, 8, 1.0, 1.0).mesh(40, 96)
    return V * (a / 10.0), F


@settings(max_examples=30, deadline=None)
@given(st.floats(-30, 30), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5))
def test_below_a_flat_base_a_plane_holds_its_mean_depth_times_the_base_area(c, p, q):
    """Truth: between the base z = 0 and the plane z = c + p x + q y lie −(c A + p Sx + q Sy) mm³,
    A and (Sx, Sy) the base polygon's area and first moments (shoelace formulas)."""
    from breastplan.meshes import volume_below_base

    V, F = _disc_breast()
    ring = V[:96, :2]
    x, y = ring.T
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    A = cross.sum() / 2
    Sx, Sy = ((x + x1) * cross).sum() / 6, ((y + y1) * cross).sum() / 6
    below = volume_below_base(V, F, lambda xy: c + p * xy[..., 0] + q * xy[..., 1])
    assert below == pytest.approx(-(c * abs(A) + np.sign(A) * (p * Sx + q * Sy)), rel=1e-9, abs=1e-6)


def test_below_a_round_base_a_falling_paraboloid_holds_pi_a4_over_4r():
    """Truth: under a disc of radius a, the chest z = −r²/(2R) lies π a⁴/(4R) below the base plane."""
    from breastplan.meshes import volume_below_base

    a, R = 60.0, 300.0
    V, F = _disc_breast(a)
    below = volume_below_base(V, F, lambda xy: -np.sum(np.square(xy), -1) / (2 * R))
    assert below == pytest.approx(np.pi * a ** 4 / (4 * R), rel=0.005)
