"""Reduction (`plan.reduction`) on a MakeHuman patient scanned as a clinic scans her, against truths stated here:
her breast loses the volume resected (or comes to the volume asked), on her skin, exactly; her other breast does
not change; more is taken below the nipple than above it; with a lift, her nipple comes to the height asked and
the volume stays the reduced one; a resection no smaller than her breast is refused in a sentence."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import BadInputError, transform_points
from breastplan.plan.reduction import reduction

BODY = "symmetric"


def _reduced(**how):
    torso, nipples, *_ = scanned(BODY)
    m = measured(BODY)
    cut = reduction(m, "left", nipples["left"], **how)
    return m, nipples, cut, replace(m.cells, height_mm=cut.heights(m.cells.height_mm))


@pytest.mark.parametrize("how,left_cc", [(dict(volume_cc=100.0), None), (dict(to_volume_cc=200.0), 200.0)])
def test_her_breast_loses_the_volume_resected_and_her_other_breast_nothing(how, left_cc):
    m, _, cut, after = _reduced(**how)
    want = left_cc if left_cc is not None else m.cells.volume_cc("left") - how["volume_cc"]
    assert after.volume_cc("left") == pytest.approx(want, abs=0.01)
    assert after.volume_cc("right") == m.cells.volume_cc("right")
    assert cut.volume_cc == pytest.approx(m.cells.volume_cc("left") - want, abs=0.01)


def test_more_is_taken_below_her_nipple_than_above_it():
    m, nipples, cut, _ = _reduced(volume_cc=100.0)
    nipple = transform_points(m.body_from_input, nipples["left"][None])[0]
    rows = cut.y[None, :]
    fall = -cut.lift_mm
    below = (fall * (rows < nipple[1])).sum()
    above = (fall * (rows > nipple[1] + 20.0)).sum()
    tissue = np.clip(m.cells.height_mm, 0, None) * m.cells.side("left")
    share_below = below / (tissue * (rows < nipple[1])).sum()
    share_above = above / (tissue * (rows > nipple[1] + 20.0)).sum()
    assert share_below > share_above                                           # a larger share of what is there


def test_with_a_lift_her_nipple_comes_to_the_height_asked_and_her_volume_is_the_reduced_one():
    m, nipples, cut, after = _reduced(volume_cc=100.0, nipple_height_mm=-180.0)
    nipple = transform_points(m.body_from_input, cut(nipples["left"][None]))[0]
    assert nipple[1] == pytest.approx(-180.0, abs=0.5)
    assert after.volume_cc("left") == pytest.approx(m.cells.volume_cc("left") - 100.0, abs=0.01)


@pytest.mark.parametrize("how", [dict(volume_cc=5000.0), dict(to_volume_cc=9000.0), dict(volume_cc=-10.0)])
def test_a_resection_no_smaller_than_her_breast_is_refused_in_a_sentence(how):
    with pytest.raises(BadInputError, match="a reduction takes more than nothing and less than the breast"):
        _reduced(**how)
