"""Databases V and S (docs/model.md §4) and deformation datasets."""
import numpy as np
import pytest

from breastplan import ArtefactError, Primitive, read_ply
from breastplan.deform.global_deformations import Deformation, apply_kind
from breastplan.learn.databases import Database, build_database
from breastplan.learn.datasets import Dataset, build_dataset

# Table 4.1, typed here from docs/model.md §4: (b0,b1) (c0,c1) (s0,s1,t0,t1) (h0,h1) (g0,g1)
TABLE_4_1 = {
    "generic": [(0, 0), (0.38, 0), (0, 0, 0, 0), (0, 0), (0.41, 0)],
    "shape1": [(-0.2, 0), (0.25, 0), (0.5, -1, 0, -1), (0, 0.01), (0, 0.2)],
    "shape2": [(-0.1, 0), (0, 0.05), (1.5, -7, 0, -5), (0, 0.05), (0.05, 0.05)],
    "shape3": [(0, -0.05), (0.3, 0.05), (1, -0.5, 0.5, -0.5), (0.1, 0), (0, 0.3)],
    "shape4": [(-0.1, -0.05), (0.38, 0), (1, -0.5, 0.5, -0.5), (0, 0), (0.41, 0)],
}


def test_same_seed_same_arrays_other_seed_other_arrays(db_v):
    again = build_database("V", seed=0)
    for key, value in db_v.arrays().items():
        assert np.array_equal(value, again.arrays()[key]), key
    other = build_database("V", seed=1)
    assert not np.array_equal(other.volume_cc, db_v.volume_cc)


def test_split_sizes(db_v, db_s):
    assert (len(db_v), (db_v.split == "train").sum(), (db_v.split == "test").sum()) == (65, 50, 15)
    assert (len(db_s), (db_s.split == "train").sum(), (db_s.split == "test").sum()) == (60, 48, 12)
    for shape in ("shape1", "shape2", "shape3", "shape4"):  # every shape in both splits
        assert set(db_s.split[db_s.shape == shape]) == {"train", "test"}


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_volume_law(seed):
    for name in ("V", "S"):
        db = build_database(name, seed=seed, n_points=400)
        assert db.volume_cc.mean() == pytest.approx(452, rel=0.10)
        assert db.volume_cc.std(ddof=1) == pytest.approx(120, rel=0.10)
        assert db.volume_cc.min() >= 150 and db.volume_cc.max() <= 1200


def test_database_v_is_one_shape_at_many_scales(db_v):
    assert np.allclose(db_v.semi_axes, db_v.semi_axes[:, :1])        # five equal semi-axes
    b, c, s, h, g = TABLE_4_1["generic"]
    for vector in db_v.deformation:                                   # the generic shape of Table 4.1
        d = Deformation.from_vector(vector)
        assert (d.ptosis, d.turn, d.top_shape, d.flatten_side, d.turn_top) == (b, c, s, h, g)
    # the generic shape is two shears: breast volume = hemisphere (2/3)πa³, a in mm
    a_mm = db_v.semi_axes[:, 0] * 6
    assert np.allclose(db_v.volume_cc, 2 / 3 * np.pi * a_mm**3 / 1000, rtol=0.005)


def test_database_s_uses_table_4_1(db_s):
    for i in range(len(db_s)):
        b, c, s, h, g = TABLE_4_1[db_s.shape[i]]
        d = Deformation.from_vector(db_s.deformation[i])
        assert (d.ptosis, d.turn, d.top_shape, d.flatten_side, d.turn_top) == (b, c, s, h, g)
    # the points are the primitive deformed by those parameters, in mm
    i = 17
    prim = db_s.primitive(i)
    b, c, s, h, g = TABLE_4_1[db_s.shape[i]]
    p = prim.sample(*db_s.grid)
    for kind, params in (("top-shape", s), ("flatten-side", h), ("turn-top", g), ("ptosis", b), ("turn", c)):
        p = apply_kind(p, kind, params, prim)
    assert np.allclose(db_s.points[i], 6 * p)
    # semi-axes jittered: not all equal, within ±10 % of each other's scale
    ratios = db_s.semi_axes / db_s.semi_axes.mean(axis=1, keepdims=True)
    assert ratios.std() > 0.01 and ratios.min() > 0.8 and ratios.max() < 1.25


def test_points_are_square_grids():
    db = build_database("S", n_points=2500)
    assert db.points.shape == (60, 2500, 3) and db.grid == (50, 50)
    with pytest.raises(ValueError, match="square"):
        build_database("S", n_points=1000)


def test_database_round_trip_and_plys(tmp_path, db_s):
    path = db_s.save(tmp_path / "database.npz")
    loaded = Database.load(path)
    for key, value in db_s.arrays().items():
        assert np.array_equal(value, loaded.arrays()[key]), key
    assert (loaded.name, loaded.seed) == ("S", 0)
    small = build_database("V", n_points=100)
    files = small.write_plys(tmp_path / "ply")
    assert len(files) == 65
    assert np.allclose(read_ply(files[3]).points, small.points[3])


def test_dataset_examples_and_on_demand_points(tmp_path, db_s):
    data = build_dataset(db_s, "turn c0>c1", 4)
    assert len(data) == 60 * 4
    k = 4 * 5 + 3                                   # breast 5, last row (c0, c1) = (1.1, 0.5)
    assert data.breast[k] == 5 and data.row[k] == 3 and np.allclose(data.params[k], [1.1, 0.5])
    o, d = data.original_points(k), data.deformed_points(k)
    zeta = o[:, 2] / 60                             # ζ = z/10 with z in mu = z_mm/6
    assert np.allclose(o[:, 0] - d[:, 0], 6 * (1.1 * zeta + 0.5 * zeta**2))
    assert np.allclose(o[:, 1:], d[:, 1:])
    loaded = Dataset.load(data.save(tmp_path / "ds.npz"))
    assert loaded.condition.name == "turn c0>c1" and loaded.dd == 4
    assert np.array_equal(loaded.degree, data.degree) and np.array_equal(loaded.split, data.split)
    assert np.allclose(loaded.deformed_points(k), d)


def test_loading_the_wrong_artefact_is_refused(tmp_path, db_s):
    data_path = build_dataset(db_s, "ptosis b0", 4).save(tmp_path / "ds.npz")
    with pytest.raises(ArtefactError, match="breastplan.database/1"):
        Database.load(data_path)
    with pytest.raises(ArtefactError, match="no such file"):
        Dataset.load(tmp_path / "missing.npz")


@pytest.mark.parametrize("change, problem", [
    ({"semi_axes": lambda a: -a}, "whose primitive parameters must be finite and positive"),
    ({"semi_axes": lambda a: a * 1e3}, "whose primitive spans"),
    ({"eps": lambda a: a * 1e9}, "shape exponents"),
    ({"grid": lambda a: np.array([-20, -20])}, "does not match its sampling grid"),
    ({"points": lambda a: a * 1e300}, "spans 1.*e\\+30. units"),
    ({"points": lambda a: a * np.array([1.0, 1.0, 0.0])}, "is flat"),
    ({"volume_cc": lambda a: -a}, "whose volume is not positive"),
    ({k: (lambda a: a[:0]) for k in ("names", "shape", "split", "semi_axes", "eps", "deformation", "volume_cc",
                                     "primitive_volume_cc", "points")}, "holds no breasts"),
])
def test_a_database_whose_breasts_are_no_breasts_is_refused(tmp_path, change, problem):
    """Truth: a database holds breasts — primitives 20–600 mm across with eps 0.3–2, sampled on its
    (n_u ≥ 2, n_v ≥ 3) grid into clouds that rise from their base, of positive volume."""
    path = build_database("V", n_points=100).save(tmp_path / "db.npz")
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update({k: f(arrays[k]) for k, f in change.items()})
    np.savez(path, **arrays)
    with pytest.raises(ArtefactError, match=problem):
        Database.load(path)


def test_drawn_volumes_follow_the_truncated_normal():
    from scipy.stats import kstest, truncnorm

    from breastplan.learn.databases import draw_volumes

    law = truncnorm((150 - 452) / 120, (1200 - 452) / 120, loc=452, scale=120)
    sample = draw_volumes(np.random.default_rng(3), 5000)
    assert sample.min() >= 150 and sample.max() <= 1200
    assert kstest(sample, law.cdf).statistic < 1 / 5000 + 1e-9   # one draw per quantile bin
