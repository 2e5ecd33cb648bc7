"""Lumpectomy (`plan.lumpectomy`) on a MakeHuman patient scanned as a clinic scans her, against truths stated
here: the volume lost is the volume excised, on her skin; her other breast does not change; her nipple deviates
towards the defect, more for a larger excision and a nearer one; her breasts' asymmetry (pBRA) grows with the
volume excised; the clock is read as the surgeon faces her."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import BadInputError, transform_points
from breastplan.options import OptionError
from breastplan.plan.lumpectomy import WARN_FRACTION, clock_direction, lumpectomy
from breastplan.plan.symmetry import bcct_measures

BODY = "symmetric"


def _excised(side: str, volume_cc: float, clock: float, distance_mm: float):
    torso, nipples, *_ = scanned(BODY)
    m = measured(BODY)
    return m, nipples, lumpectomy(m, side, nipples[side], volume_cc, clock, distance_mm)


def _nipple_shift(m, nipples, cut, side: str) -> np.ndarray:
    """(3,) how far the nipple moves, her body frame."""
    T = m.body_from_input
    return transform_points(T, cut(nipples[side][None]))[0] - transform_points(T, nipples[side][None])[0]


@pytest.mark.parametrize("volume_cc,clock,distance_mm", [(20.0, 3, 40.0), (50.0, 12, 30.0), (80.0, 7.5, 35.0)])
def test_her_breast_loses_the_volume_excised_and_her_other_breast_nothing(volume_cc, clock, distance_mm):
    m, _, cut = _excised("left", volume_cc, clock, distance_mm)
    after = replace(m.cells, height_mm=cut.heights(m.cells.height_mm))
    assert after.volume_cc("left") - m.cells.volume_cc("left") == pytest.approx(-volume_cc, abs=0.1)
    assert after.volume_cc("right") == m.cells.volume_cc("right")
    assert cut.fraction == pytest.approx(volume_cc / m.sides["left"].volume_cc)


def test_the_clock_is_read_as_the_surgeon_faces_her():
    """12 up; 3 o'clock towards her left (lateral on her left breast, medial on her right); 6 down."""
    assert clock_direction(12) == pytest.approx([0.0, 1.0])
    assert clock_direction(3) == pytest.approx([1.0, 0.0])
    assert clock_direction(6) == pytest.approx([0.0, -1.0])
    m, nipples, cut = _excised("right", 40.0, 3, 35.0)
    assert _nipple_shift(m, nipples, cut, "right")[0] > 1.0                    # her right nipple drawn medially


def test_her_nipple_deviates_towards_the_defect_more_for_more_tissue_and_a_nearer_defect():
    """At 3 o'clock on her left breast: the nipple moves laterally (towards the defect), by more for 20 → 50 →
    100 cc at 40 mm, and by more for a defect 60 → 40 → 20 mm away (50 cc); her right breast's nipple not at all."""
    shifts = []
    for volume in (20.0, 50.0, 100.0):
        m, nipples, cut = _excised("left", volume, 3, 40.0)
        shifts.append(_nipple_shift(m, nipples, cut, "left"))
        assert np.abs(_nipple_shift(m, nipples, cut, "right")).max() == 0.0
    assert all(s[0] > 0.5 for s in shifts) and shifts[0][0] < shifts[1][0] < shifts[2][0]
    by_distance = []
    for distance in (60.0, 40.0, 20.0):
        m, nipples, cut = _excised("left", 50.0, 3, distance)
        by_distance.append(_nipple_shift(m, nipples, cut, "left")[0])
    assert by_distance[0] < by_distance[1] < by_distance[2]


def test_her_breasts_asymmetry_grows_with_the_volume_excised_and_a_large_excision_is_warned():
    """pBRA (her nipples against each other's mirror image, BCCT.core) after 20, 50 and 100 cc at 3 o'clock on
    her left breast: growing. The warning names the fraction past WARN_FRACTION, and only then."""
    pbra, fractions = [], []
    for volume in (20.0, 50.0, 100.0):
        m, nipples, cut = _excised("left", volume, 3, 40.0)
        T = m.body_from_input
        moved = {s: transform_points(T, cut(nipples[s][None]))[0] for s in ("left", "right")}
        cells = replace(m.cells, height_mm=cut.heights(m.cells.height_mm))
        pbra.append(bcct_measures(moved, cells)["pBRA_pct"])
        fractions.append(cut.fraction)
        assert (cut.warning is not None) == (cut.fraction > WARN_FRACTION)
    assert pbra[0] < pbra[1] < pbra[2]
    assert fractions[-1] > WARN_FRACTION and "poor cosmetic result" in cut.warning


@pytest.mark.parametrize("volume_cc,clock,distance_mm,error,words", [
    (2000.0, 3, 30.0, BadInputError, "no smaller than her left breast"),
    (30.0, 3, 250.0, BadInputError, "outside her breast"),
    (30.0, 13, 30.0, OptionError, "clock position"),
    (-5.0, 3, 30.0, OptionError, "positive volume")])
def test_a_lumpectomy_that_cannot_be_done_is_refused_in_a_sentence(volume_cc, clock, distance_mm, error, words):
    with pytest.raises(error, match=words):
        _excised("left", volume_cc, clock, distance_mm)


def test_a_deeper_cavity_sinks_a_wider_patch_of_her_skin_less_deeply_and_loses_the_same_volume():
    """40 cc at 2 o'clock, 40 mm out, excised just beneath her skin and 20 mm deep: both lose 40 cc on her skin;
    the deeper one's skin sinks less at its deepest and over more of her breast (cells sunk over 0.5 mm)."""
    m, nipples, shallow = _excised("left", 40.0, 2, 40.0)
    deep = lumpectomy(m, "left", nipples["left"], 40.0, 2, 40.0, depth_mm=20.0)
    for cut in (shallow, deep):
        after = replace(m.cells, height_mm=cut.heights(m.cells.height_mm))
        assert after.volume_cc("left") - m.cells.volume_cc("left") == pytest.approx(-40.0, abs=0.1)
    assert -deep.lift_mm.min() < -shallow.lift_mm.min()
    assert (deep.lift_mm < -0.5).sum() > (shallow.lift_mm < -0.5).sum()


def test_an_excision_deeper_than_her_breast_is_thick_there_is_refused():
    m, nipples, _ = _excised("left", 40.0, 2, 40.0)
    with pytest.raises(BadInputError, match="mm thick"):
        lumpectomy(m, "left", nipples["left"], 40.0, 2, 40.0, depth_mm=150.0)
