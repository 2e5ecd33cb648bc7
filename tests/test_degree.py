"""Extent and degree of deformation (docs/model.md §5) and the condition rows (docs/model.md §4)."""
import numpy as np
import pytest

from breastplan import Primitive
from breastplan.deform.conditions import CONDITIONS, find_condition
from breastplan.deform.degree import (P00, continuous_degree, degree_extent, discrete_degree, extent, reference_extents,
                                      reference_points, signed_extent)
from breastplan.deform.global_deformations import apply_kind
from breastplan.learn.datasets import build_dataset


def test_rows_interpolate_between_fixed_ends():
    b0 = find_condition("ptosis b0")
    assert np.allclose(b0.rows(4), [[0.45, 0], [1.05, 0], [1.65, 0], [2.25, 0]])  # step 0.6
    for cond in CONDITIONS.values():
        for dd in (4, 8):
            rows = cond.rows(dd)
            assert rows.shape == (dd, len(cond.param_names))
            assert np.allclose(rows[0], cond.first) and np.allclose(rows[-1], cond.last)
            assert np.allclose(np.diff(rows, 2, axis=0), 0)  # equally spaced


def test_table_4_2_range_ends():
    assert find_condition("b1≥b0", "ptosis").first == (0.05, 0.1)
    assert find_condition("ptosis b0>b1").last == (1.125, 0.25)
    assert find_condition("turn c1>c0").last == (0.5, 0.625)
    assert find_condition("top-shape s0⁻>s1⁺").last == (-2.5, 2.0, 0.0, 0.0)
    assert find_condition("top-shape s1->s0+").first == (0.25, -0.5, 0.0, 0.0)
    with pytest.raises(ValueError, match="unknown condition"):
        find_condition("ptosis sideways")


def test_extent_hand_computed():
    # points at distance 2 translated by 0.1: every normalised distance is 0.05
    o = np.array([[2.0, 0, 0], [0, 2.0, 0], [0, 0, 2.0], [0, -2.0, 0]])
    assert extent(o, o + [0.1, 0, 0]) == pytest.approx(0.05)
    # batch axes: a second copy moved twice as far
    assert np.allclose(extent(np.stack([o, o]), np.stack([o + [0, 0.1, 0], o + [0, 0.2, 0]])), [0.05, 0.1])


def test_signed_extent_hand_computed():
    o = np.array([[0, 1.0, 4.0], [0, 2.0, 6.0], [0, -1.0, 5.0]])
    d = o.copy()
    d[:, 2] *= [1.5, 0.5, 9.0]     # upper half: +2 and −3; the lower point is ignored
    assert signed_extent(o, d, a5=10.0) == pytest.approx((2 - 3) / 2 / 10)


@pytest.mark.parametrize("name", list(CONDITIONS))
@pytest.mark.parametrize("dd", [4, 8])
def test_p00_gets_exactly_its_own_degrees(name, dd):
    cond = CONDITIONS[name]
    ref = reference_extents(cond, dd, 50, 50)
    p0 = reference_points(50, 50)
    mine = []
    for row in cond.rows(dd):
        d = apply_kind(p0, cond.kind, row, P00)
        mine.append(signed_extent(p0, d, P00.a5) if cond.kind == "top-shape" else extent(p0, d))
    assert np.array_equal(discrete_degree(mine, ref), np.arange(1, dd + 1))
    assert np.allclose(continuous_degree(mine, ref), np.arange(1, dd + 1))


def test_discrete_degrees_clip_and_continuous_ones_extend_the_end_segments():
    ref = np.array([0.1, 0.2, 0.4, 0.8])
    assert list(discrete_degree([0.0, 0.14, 0.16, 0.35, 5.0], ref)) == [1, 1, 2, 3, 4]
    # inside: linear between reference extents; outside: the end segments continued (slopes 0.1 and 0.4)
    assert np.allclose(continuous_degree([0.0, 0.15, 0.3, 0.6, 1.2], ref), [0, 1.5, 2.5, 3.5, 5])
    assert np.allclose(degree_extent([0, 1.5, 2.5, 3.5, 5], ref), [0.0, 0.15, 0.3, 0.6, 1.2])
    # a decreasing (signed) reference works the same way
    assert np.allclose(continuous_degree([-0.15, -0.6, -1.2], -ref), [1.5, 3.5, 5])
    assert np.allclose(degree_extent([1.5, 5], -ref), [-0.15, -1.2])


@pytest.mark.parametrize("name", list(CONDITIONS))
def test_continuous_degree_rounds_to_discrete(db_s, name):
    data = build_dataset(db_s, name, 8)
    # ties (exact midpoints) aside, rounding and clipping the continuous degree gives the thesis degree
    assert np.array_equal(np.clip(np.floor(data.degree_continuous + 0.5), 1, 8).astype(int), data.degree)
    assert data.degree.min() >= 1 and data.degree.max() <= 8


@pytest.mark.parametrize("name", [n for n in CONDITIONS if not n.startswith("top-shape")])
def test_extent_is_monotone_along_ptosis_and_turn_conditions(db_v, db_s, name):
    cond = CONDITIONS[name]
    t = np.linspace(0, 1, 17)
    for db in (db_v, db_s):
        for i in range(0, len(db), 3):
            o = db.points_mu(i)
            e = [extent(o, apply_kind(o, cond.kind, cond.at(tt), db.primitive(i))) for tt in t]
            assert np.all(np.diff(e) > 0), f"{db.names[i]}: extent not increasing along {name}"


def test_top_shape_signed_extents_have_opposite_signs():
    neg = reference_extents(CONDITIONS["top-shape s0->s1+"], 8, 50, 50)
    pos = reference_extents(CONDITIONS["top-shape s1->s0+"], 8, 50, 50)
    assert np.all(neg < 0) and np.all(np.diff(neg) < 0)
    assert np.all(pos > 0) and np.all(np.diff(pos) > 0)


def test_reference_breast_is_p00_with_the_generic_shape():
    p0 = reference_points(30, 30)
    # turn (0.38, 0) moves the nipple (z = 10, ζ = 1) by −0.38 in x; turn-top leaves y ≤ 0 alone
    nipple = p0.reshape(30, 30, 3)[-1, 0]
    assert np.allclose(nipple, [-0.38, 0, 10])
    assert Primitive() == P00
