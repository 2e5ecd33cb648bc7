"""Lift (`plan.mastopexy`) on a MakeHuman patient whose breasts hang unequally (MakeHuman's asymmetry target),
scanned as a clinic scans her, against truths stated here: her volume on her skin is kept; her nipple comes to
the height asked (her other nipple's, or a distance from her sternal notch as lifted); her areola travels with it;
her other breast and her chest above the breast stay; a lift no breast allows is refused in a sentence."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import BadInputError, transform_points
from breastplan.plan.mastopexy import mastopexy, nipple_height, to_notch_distance

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
    moved = transform_points(m.body_from_input, lifted(torso)) - transform_points(m.body_from_input, torso)
    at = transform_points(m.body_from_input, torso)
    areola = np.linalg.norm(at[:, :2] - body[low][:2], axis=1) < 8.0
    assert np.allclose(moved[areola, 1], lifted.rise_mm, atol=1.0)            # her areola travels with her nipple
    other = (at[:, 0] > 0) != (low == "left")
    assert np.abs(moved[other]).max() == 0.0                                  # her other half stays
    above = at[:, 1] > body[low][1] + 150.0
    assert np.abs(moved[above]).max() < 0.5                                   # her upper chest stays


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
