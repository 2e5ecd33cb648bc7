"""Lift (`plan.mastopexy`) on a MakeHuman patient whose breasts hang unequally (MakeHuman's asymmetry target),
scanned as a clinic scans her, against truths stated here: her volume on her skin is kept; her nipple comes to
the height asked (her other nipple's, or a distance from her sternal notch as lifted); her areola travels with it;
her other breast and her chest above the breast stay; her skin is drawn whole and her footprint's outline stays;
the lifted nipple stands as far in front of her as her other one; a lift no breast allows is refused in a sentence;
the heights carried up are the heights the skin had."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from test_breast_volume import measured, scanned

from breastplan import BadInputError, transform_points
from breastplan.plan.mastopexy import carried_up, mastopexy, nipple_height, to_notch_distance
from breastplan.plan.operated import operate
from breastplan.plan.operation_spec import OperationSpec
from breastplan.plan.symmetry import ptosis_from_cells

BODY = "asymmetric"


def _her():
    torso, nipples, *_ = scanned(BODY)
    m = measured(BODY)
    body = {s: transform_points(m.body_from_input, n[None])[0] for s, n in nipples.items()}
    return torso, nipples, m, body


def _lower_side(body) -> tuple[str, str]:
    low = min(body, key=lambda s: body[s][1])
    return low, "right" if low == "left" else "left"


def test_her_lower_nipple_lifted_to_her_other_nipples_height_keeps_her_volume_and_her_other_breast():
    torso, nipples, m, body = _her()
    low, high = _lower_side(body)
    assert body[high][1] - body[low][1] > 8.0                                  # her breasts hang unequally
    lifted = mastopexy(m, low, nipples[low], nipple_height(body[low], as_nipple_body=body[high]))
    after = replace(m.cells, height_mm=lifted.heights(m.cells.height_mm))
    assert after.volume_cc(low) == pytest.approx(m.cells.volume_cc(low), abs=0.01)
    assert after.volume_cc(high) == m.cells.volume_cc(high)
    nipple = transform_points(m.body_from_input, lifted(nipples[low][None]))[0]
    assert nipple[1] == pytest.approx(body[high][1], abs=0.5)
    assert abs(nipple[0] - body[low][0]) < 0.5                                # straight up, not across
    assert abs(nipple[2] - body[high][2]) < 5.0           # as far in front of her as her other nipple (within 0.4 mm
    #                                                       before): raised, not thrust forward (8 mm, the two maps)
    moved = transform_points(m.body_from_input, lifted(torso)) - transform_points(m.body_from_input, torso)
    at = transform_points(m.body_from_input, torso)
    areola = np.linalg.norm(at[:, :2] - body[low][:2], axis=1) < 8.0
    assert np.allclose(moved[areola, 1], lifted.rise_mm, atol=1.0)            # her areola travels with her nipple
    other = (at[:, 0] > 0) != (low == "left")
    assert np.abs(moved[other]).max() == 0.0                                  # her other half stays
    above = at[:, 1] > body[low][1] + 150.0
    assert np.abs(moved[above]).max() < 0.5                                   # her upper chest stays


@pytest.mark.parametrize("rise", [10.0, 20.0, 30.0])
def test_no_point_of_her_skin_moves_more_than_twice_her_nipples_rise(rise):
    """Her skin rises by at most the nipple's rise and follows her surface forward or back; at the side of her
    breast, seen nearly edge-on, a point risen a few mm took a height tens of mm behind it (30 mm for a 10 mm rise)."""
    torso, nipples, m, body = _her()
    for side in ("left", "right"):
        lifted = mastopexy(m, side, nipples[side], body[side][1] + rise)
        assert np.linalg.norm(lifted.displacement(torso), axis=1).max() <= 2.0 * rise, side


@pytest.mark.parametrize("rise", [30.0, 50.0])
def test_her_lifted_skin_is_drawn_whole_and_her_footprints_outline_stays(rise):
    """Her skin is drawn as moved: a torn skin is two points a few mm apart, one risen with her breast and one left
    with her chest (they moved the whole rise apart, at her footprint's border and at the steep side of her breast).
    Whole, neighbours move apart by a share of the rise as her skin stretches over the band her breast rose from;
    the outline her volume is measured inside stays on her chest."""
    torso, nipples, m, body = _her()
    at = transform_points(m.body_from_input, torso)
    pairs = cKDTree(at).query_pairs(4.0, output_type="ndarray")
    for side in ("left", "right"):
        lifted = mastopexy(m, side, nipples[side], body[side][1] + rise)
        moved = lifted.displacement(torso)
        assert np.linalg.norm(moved[pairs[:, 0]] - moved[pairs[:, 1]], axis=1).max() <= 0.6 * rise, side
        outline = m.sides[side].footprint_input_mm
        assert np.linalg.norm(lifted.displacement(outline), axis=1).max() <= 0.2 * rise, side


def test_a_lift_of_a_breast_that_does_not_hang_is_warned_of_and_of_one_that_hangs_not():
    """A small firm breast (cup 0.4: Regnault grade 0 as scanned, its nipple 40 mm above its fold) lifted to 50 mm
    above its fold is warned of, in a sentence naming its grade and the rise (10 mm); her breasts that hang (cup 0.85,
    firmness 0.2: pseudoptosis) are lifted as far without. Above their folds, none is given the lift a reduction
    "needs", and the reduction says so."""
    for body, warned in (("small", True), (BODY, False)):
        _, nipples, *_ = scanned(body)
        m = measured(body)
        for side in ("left", "right"):
            nipple = transform_points(m.body_from_input, nipples[side][None])[0]
            found = ptosis_from_cells(nipple, m.cells, side)
            assert (found["grade"] == "0") == warned, (body, side, found["grade"])
            done = operate(m, nipples, side, found["nipple_to_fold_mm"],
                           (OperationSpec.parse(f"lift:fold={found['nipple_to_fold_mm'] + 10.0:.1f}"),))
            reduced = operate(m, nipples, side, found["nipple_to_fold_mm"], (OperationSpec.parse("reduction:40"),))
            assert reduced.words.endswith("; none needed: her nipple lies above her fold")   # it lies above its fold
            if warned:
                assert done.warnings == (f"her {side} breast shows no ptosis as scanned (Regnault grade 0: its nipple "
                                         f"{found['nipple_to_fold_mm']:.0f} mm above her fold); this lift raises a "
                                         "nipple that does not hang, by 10 mm",)
            else:
                assert done.warnings == (), (body, side)


def test_a_lift_to_a_distance_from_her_sternal_notch_reaches_it_as_lifted():
    torso, nipples, m, body = _her()
    low, _ = _lower_side(body)
    now = float(np.linalg.norm(body[low]))
    lifted = to_notch_distance(m, low, nipples[low], now - 15.0)
    nipple = transform_points(m.body_from_input, lifted(nipples[low][None]))[0]
    assert np.linalg.norm(nipple) == pytest.approx(now - 15.0, abs=0.1)
    assert lifted.rise_mm > 15.0                                             # it comes forward as it rises


@pytest.mark.parametrize("how,words", [("lower", "above the height asked"), ("far", "beyond the"),
                                       ("notch", "which no lift of her breast reaches")])
def test_a_lift_no_breast_allows_is_refused_in_a_sentence(how, words):
    _, nipples, m, body = _her()
    low, _ = _lower_side(body)
    with pytest.raises(BadInputError, match=words):
        if how == "notch":
            to_notch_distance(m, low, nipples[low], 100.0)
        else:
            mastopexy(m, low, nipples[low], body[low][1] + (-10.0 if how == "lower" else 300.0))


def test_the_heights_carried_up_are_the_heights_the_rising_skin_had():
    """`carried_up` on a column of known heights: where the skin at y rises to y + r(y) (r falling from 20 mm to 0
    up the column, as a lift's does), the height found there is the height at y (to 0.5 mm: two linear
    interpolations over 5 mm cells of a curve 20 mm deep)."""
    y = np.arange(-100.0, 100.0, 5.0)
    height = 30.0 + 20.0 * np.cos(y / 40.0)
    rise = 20.0 * np.clip(1.0 - (y + 100.0) / 150.0, 0.0, 1.0)
    carried = carried_up(height[None], y, rise[None])[0]
    inside = (y + rise >= y[0]) & (y + rise <= y[-1])
    assert np.interp(y + rise, y, carried)[inside] == pytest.approx(height[inside], abs=0.5)
