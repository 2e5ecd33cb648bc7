"""Symmetrising (`plan.symmetrising`) on MakeHuman patients scanned as a clinic scans them, against truths stated
here: the operation proposed on one breast brings it to her other breast's volume on her skin (exactly, where an
operation changes its volume), its nipple to the other's height where it was lower (within 0.5 mm), and a
symmetric woman is left as she is."""
from __future__ import annotations

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import transform_points
from breastplan.plan.augmentation import Augmentation
from breastplan.plan.mastopexy import Mastopexy
from breastplan.plan.reduction import Reduction
from breastplan.plan.symmetrising import symmetrising
from breastplan.plan.symmetry import ptosis_from_cells


def _proposed(body: str, side: str):
    torso, nipples, *_ = scanned(body)
    m = measured(body)
    nipple = transform_points(m.body_from_input, nipples[side][None])[0]
    return m, nipples, symmetrising(m, nipples, side, ptosis_from_cells(nipple, m.cells, side)["nipple_to_fold_mm"])


@pytest.mark.parametrize("side,kind", [("left", Reduction), ("right", Augmentation)])
def test_a_breast_a_cup_apart_is_brought_to_her_other_breasts_volume(side, kind):
    """Her left breast a cup larger than her right (328 cc apart on her skin): reducing the left, or an implant
    under the right, brings it to the other's volume on her skin to 0.1 cc."""
    m, _, proposal = _proposed("one cup larger", side)
    assert isinstance(proposal.operations[0], kind)
    assert proposal.volume_cc == pytest.approx(proposal.other_volume_cc, abs=0.1)
    assert abs(m.sides["left"].volume_cc - m.sides["right"].volume_cc) > 300.0


def test_her_lower_nipple_is_lifted_to_her_other_nipples_height_and_a_small_difference_is_said():
    """Her breasts hang unequally (MakeHuman's asymmetry target) and differ by less than the smallest implant: her
    lower breast is lifted, its nipple to the other's height within 0.5 mm, its volume kept; the note says the
    volume was left."""
    m, nipples, _ = _proposed("asymmetric", "left")
    body = {s: transform_points(m.body_from_input, n[None])[0] for s, n in nipples.items()}
    low = min(body, key=lambda s: body[s][1])
    _, _, proposal = _proposed("asymmetric", low)
    assert [type(o) for o in proposal.operations] == [Mastopexy]
    assert proposal.nipple_body_mm[1] == pytest.approx(proposal.other_nipple_mirrored_mm[1], abs=0.5)
    assert proposal.volume_cc == pytest.approx(m.sides[low].volume_cc, abs=0.01)
    assert "smaller" in (proposal.note or "") or abs(m.sides["left"].volume_cc - m.sides["right"].volume_cc) <= 20.0


def test_a_symmetric_woman_is_left_as_she_is():
    _, nipples, proposal = _proposed("symmetric", "left")
    assert proposal.operations == () and proposal.note is None
    assert np.array_equal(proposal(nipples["left"][None])[0], nipples["left"])


def test_her_higher_nipple_is_not_lowered_and_the_note_says_so():
    """Her breasts hang unequally (MakeHuman's asymmetry target): symmetrising the breast whose nipple is higher
    lifts nothing, and the note says no operation lowers a nipple and names the other side to symmetrise."""
    m, nipples, _ = _proposed("asymmetric", "left")
    body = {s: transform_points(m.body_from_input, n[None])[0] for s, n in nipples.items()}
    high = max(body, key=lambda s: body[s][1])
    low = "right" if high == "left" else "left"
    _, _, proposal = _proposed("asymmetric", high)
    assert not any(isinstance(o, Mastopexy) for o in proposal.operations)
    assert "no operation lowers a nipple" in proposal.note and f"--symmetrise {low}" in proposal.note
