"""FFD lattice as a deformation object (docs/model.md §6): independent truths of the Bernstein
tensor product, the chunked evaluation, points outside the box, and the lattice file."""
import math
import zipfile

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from breastplan import ArtefactError, save_npz
from breastplan.deform.lattice import SCHEMA, Lattice, bernstein

LO, HI = np.array([-40.0, -30.0, 0.0]), np.array([50.0, 35.0, 60.0])
shapes = st.tuples(*[st.integers(2, 6)] * 3)
unit = st.floats(0, 1, allow_nan=False)


def lattice(shape=(5, 5, 5), seed=0, scale=5.0) -> Lattice:
    """A lattice on [LO, HI] with random control-point displacements (mm)."""
    lat = Lattice(LO, HI, shape)
    lat.displacements = np.random.default_rng(seed).normal(0, scale, (lat.size, 3))
    return lat


def inside(s: np.ndarray) -> np.ndarray:
    """Points (mm) at lattice coordinates s ∈ [0, 1]³ of the box [LO, HI]."""
    return LO + np.asarray(s) * (HI - LO)


def bernstein_weight(shape, ijk, s) -> float:
    """B_ijk(s) from binomial coefficients, factor by factor (independent of the module)."""
    w = 1.0
    for d, i, t in zip(shape, ijk, s):
        deg = d - 1
        w *= math.comb(deg, i) * t**i * (1 - t) ** (deg - i)
    return w


@settings(max_examples=50, deadline=None)
@given(shapes, arrays(float, st.tuples(st.integers(1, 40), st.just(3)), elements=unit))
def test_a_rest_lattice_is_the_identity_inside_its_box(shape, s):
    pts = inside(s)
    assert np.allclose(Lattice(LO, HI, shape)(pts), pts, rtol=0, atol=1e-10)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 8), arrays(float, st.integers(1, 30), elements=unit))
def test_bernstein_rows_are_non_negative_and_sum_to_one(n, s):
    b = bernstein(n, s)
    assert b.shape == (len(s), n + 1) and (b >= 0).all()
    assert np.allclose(b.sum(axis=1), 1.0)


@settings(max_examples=60, deadline=None)
@given(shapes, st.data(), st.tuples(unit, unit, unit),
       st.tuples(*[st.floats(-20, 20, allow_nan=False)] * 3))
def test_moving_one_control_point_by_d_moves_a_point_by_its_weight_times_d(shape, data, s, d):
    ijk = tuple(data.draw(st.integers(0, k - 1)) for k in shape)
    lat = Lattice(LO, HI, shape)
    row = (ijk[0] * shape[1] + ijk[1]) * shape[2] + ijk[2]          # "ij" order
    assert np.array_equal(lat.rest[row], [np.linspace(LO[a], HI[a], shape[a])[ijk[a]] for a in range(3)])
    moved_points = lat.points.copy()
    moved_points[row] += d
    lat.points = moved_points
    p = inside(s)
    moved = lat(p[None])[0] - p
    assert np.allclose(moved, bernstein_weight(shape, ijk, s) * np.array(d), rtol=1e-9, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(shapes, st.integers(0, 2**31), st.integers(1, 70),
       arrays(float, st.tuples(st.integers(1, 150), st.just(3)), elements=unit))
def test_apply_equals_the_dense_basis_product_for_any_chunk(shape, seed, chunk, s):
    lat, pts = lattice(shape, seed), inside(s)
    assert np.allclose(lat.apply(pts, chunk=chunk), lat.basis(pts) @ lat.points, rtol=0, atol=1e-9)


# lattice coordinates on the box's faces or clearly off them (an ulp beyond a face may round onto it)
around_box = st.one_of(st.sampled_from([0.0, 1.0]),
                       st.floats(-3, 4, allow_nan=False).filter(lambda x: min(abs(x), abs(x - 1)) > 1e-9))


@settings(max_examples=40, deadline=None)
@given(shapes, st.integers(0, 2**31), st.integers(1, 50),
       arrays(float, st.tuples(st.integers(1, 60), st.just(3)), elements=around_box))
def test_points_outside_the_box_are_unchanged_and_inside_ones_deformed(shape, seed, chunk, s):
    lat, pts = lattice(shape, seed), inside(s)
    out = lat.apply(pts, chunk=chunk)
    outside = ((s < 0) | (s > 1)).any(axis=1)
    assert np.array_equal(out[outside], pts[outside])
    if (~outside).any():
        assert np.allclose(out[~outside], lat.basis(pts[~outside]) @ lat.points, rtol=0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(shapes, arrays(float, (3, 3), elements=st.floats(-2, 2, allow_nan=False)),
       arrays(float, 3, elements=st.floats(-100, 100, allow_nan=False)),
       arrays(float, st.tuples(st.integers(1, 50), st.just(3)), elements=unit))
def test_an_affine_map_of_the_control_points_maps_the_points_alike(shape, A, t, s):
    lat, pts = Lattice(LO, HI, shape), inside(s)
    lat.points = lat.rest @ A.T + t
    assert np.allclose(lat(pts), pts @ A.T + t, rtol=0, atol=1e-9)


def test_around_pads_the_bounding_box_and_accepts_three_axis_shapes():
    pts = np.random.default_rng(1).uniform([-50, -20, 0], [50, 40, 70], (300, 3))
    lat = Lattice.around(pts, (3, 4, 5), margin=0.1)
    ext = pts.max(0) - pts.min(0)
    assert np.allclose(lat.lo, pts.min(0) - 0.1 * ext - 1.0) and np.allclose(lat.hi, pts.max(0) + 0.1 * ext + 1.0)
    assert lat.shape == (3, 4, 5) and lat.rest.shape == (60, 3) and lat.basis(pts).shape == (300, 60)
    assert Lattice.around(pts, 5).n == 5


@pytest.mark.parametrize("shape", [(5, 5, 5), (2, 3, 4)])
def test_the_laplacian_is_the_sparse_six_neighbour_graph_laplacian(shape):
    L = Lattice(LO, HI, shape).laplacian()
    assert L.format == "csr"
    idx = np.arange(np.prod(shape)).reshape(shape)
    want = np.zeros((idx.size, idx.size))
    for a, b in [(idx[:-1], idx[1:]), (idx[:, :-1], idx[:, 1:]), (idx[:, :, :-1], idx[:, :, 1:])]:
        for u, v in zip(a.ravel(), b.ravel()):
            want[u, v] = want[v, u] = -1
    np.fill_diagonal(want, -want.sum(axis=1))
    assert np.array_equal(L.toarray(), want)


def test_a_saved_lattice_loads_back_exactly(tmp_path):
    lat = lattice((4, 5, 3), seed=3)
    loaded = Lattice.load(lat.save(tmp_path / "lattice.npz"))
    for key, value in lat.arrays().items():
        assert np.array_equal(loaded.arrays()[key], value) and loaded.arrays()[key].dtype == value.dtype
    pts = inside(np.random.default_rng(4).random((100, 3)))
    assert np.array_equal(loaded(pts), lat(pts))


def _write(path, **override):
    arrays = lattice((3, 3, 3), seed=5).arrays()
    arrays.update(override)
    return save_npz(path, SCHEMA, arrays)


@pytest.mark.parametrize("override", [
    {"shape": np.array([3, 3, 4])},                                     # shape ≠ number of control points
    {"shape": np.array([3, 9, 1])},                                     # an axis with one control point
    {"box": np.array([[0.0, 0, 0], [10.0, -1, 10]])},                   # hi below lo
    {"rest": lattice((3, 3, 3)).rest + 1.0},                            # rest not the box's grid
    {"points": np.zeros((26, 3))},                                      # control points of another size
    {"box": np.array([[0.0, 0, 0], [np.nan, 1, 1]])},                   # not finite
    {"shape": np.array([3.0, 3, 3])},                                   # wrong dtype
])
def test_an_inconsistent_lattice_file_raises_an_artefact_error_naming_it(tmp_path, override):
    path = _write(tmp_path / "bad.npz", **override)
    with pytest.raises(ArtefactError, match="bad.npz"):
        Lattice.load(path)


def test_a_corrupt_or_foreign_lattice_file_raises_an_artefact_error_naming_it(tmp_path):
    good = _write(tmp_path / "good.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    foreign = save_npz(tmp_path / "foreign.npz", "breastplan.fit/1", lattice().arrays())
    with zipfile.ZipFile(good) as zf:
        assert "shape.npy" in zf.namelist()
    for path in (corrupt, foreign, tmp_path / "missing.npz"):
        with pytest.raises(ArtefactError, match=path.name):
            Lattice.load(path)


def test_a_lattices_arrays_change_only_through_its_setters_which_refuse_non_finite_points():
    lat = Lattice(LO, HI, 3)
    for array in (lat.points, lat.rest, lat.lo, lat.hi):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        lat.points = np.where(np.arange(lat.size)[:, None] == 0, np.nan, lat.rest)
    lat.displacements = np.ones((lat.size, 3))
    assert np.array_equal(lat(lat.rest[13:14]), lat.rest[13:14] + 1.0)   # the middle control point, moved by 1 mm



def test_a_lattice_around_no_point_or_a_scalar_point_is_refused_in_a_sentence_and_one_point_is_boxed():
    for bad in (np.zeros((0, 3)), 5.0, np.full((2, 3), np.nan)):
        with pytest.raises(ValueError, match="around one or more finite points"):
            Lattice.around(bad, 3)
    lat = Lattice.around(np.array([1.0, 2.0, 3.0]), 3)                 # one point: its box padded by 1 mm
    assert np.allclose(lat.lo, [0.0, 1.0, 2.0]) and np.allclose(lat.hi, [2.0, 3.0, 4.0])
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        lat(5.0)
