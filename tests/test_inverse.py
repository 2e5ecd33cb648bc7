"""The exact inverse solver against rows of known parameters."""
import numpy as np
import pytest

from breastplan.deform.conditions import CONDITIONS
from breastplan.deform.degree import condition_extent, reference_extents
from breastplan.deform.global_deformations import apply_kind
from breastplan.deform.inverse import solve_degree, target_extent
from breastplan.learn.datasets import build_dataset


@pytest.mark.parametrize("name", list(CONDITIONS))
def test_continuous_degree_recovers_the_true_row(db_s, name):
    """An example's continuous degree leads back to its row's position j/(#dd − 1), also beyond [1, 8]."""
    ds = build_dataset(db_s, name, 8)
    outside = np.flatnonzero((ds.degree_continuous < 1) | (ds.degree_continuous > 8))
    rng = np.random.default_rng(1)
    for k in np.r_[rng.choice(len(ds.row), 4, replace=False), outside[:2]]:
        i = ds.breast[k]
        sol = solve_degree(db_s.points_mu(i), ds.condition, 8, float(ds.degree_continuous[k]),
                           db_s.primitive(i), db_s.grid, move=ds.changer(k))
        assert sol.reached
        assert abs(sol.t - ds.row[k] / 7) < 1e-6
        np.testing.assert_allclose(sol.params, ds.params[k], atol=1e-6)


def test_discrete_degree_meets_the_reference_extent(db_s):
    """With an integer degree d the deformed breast's extent is the reference extent E_0d itself."""
    cond = CONDITIONS["turn c1>c0"]
    p, prim = db_s.points_mu(5), db_s.primitive(5)
    ref = reference_extents(cond, 8, *db_s.grid)
    for d in (2, 5, 7):
        sol = solve_degree(p, cond, 8, d, prim, db_s.grid)
        moved = apply_kind(p, cond.kind, sol.params, prim)
        assert condition_extent(cond, p, moved, prim) == pytest.approx(ref[d - 1], rel=1e-9)


def test_target_between_degrees_is_the_linear_interpolation():
    cond = CONDITIONS["ptosis b0"]
    ref = reference_extents(cond, 4)
    assert target_extent(cond, 4, 2.25) == pytest.approx(ref[1] + 0.25 * (ref[2] - ref[1]))
    assert target_extent(cond, 4, 4.5) == pytest.approx(ref[3] + 0.5 * (ref[3] - ref[2]))
    with pytest.raises(ValueError, match="finite"):
        target_extent(cond, 4, float("nan"))


def test_unreachable_degree_stops_at_the_line_end(db_s):
    """A breast that the whole line cannot move as far as degree 8 gets the last row, flagged."""
    cond = CONDITIONS["ptosis b1"]
    ds = build_dataset(db_s, cond, 8)
    last = np.flatnonzero(ds.row == 7)
    k = last[np.argmin(ds.extent[last])]   # the breast the last row moves least
    assert ds.degree_continuous[k] < 8, "the test needs a breast that cannot reach degree 8"
    i = ds.breast[k]
    sol = solve_degree(db_s.points_mu(i), cond, 8, 8.0, db_s.primitive(i), db_s.grid, move=ds.changer(k))
    assert not sol.reached and sol.t == 1.0
