"""The handout's line on her breasts' unseen outer sides: said for the breasts planned, right first as the
handout's columns run, and not at all when the camera saw them."""
from types import SimpleNamespace

from breastplan.plan.handout import outer_words


def _plan(**unseen_cc):
    return SimpleNamespace(sides=dict.fromkeys(unseen_cc),
                           volumes=SimpleNamespace(sides={s: SimpleNamespace(unseen_outer_cc=v)
                                                          for s, v in unseen_cc.items()}))


def test_the_handout_says_what_her_unseen_outer_sides_may_hold_right_breast_first():
    assert outer_words(_plan(left=24.4, right=31.6)) == [
        "Seen from in front of her, the scan does not show all of each breast's outer side: perhaps 32\u00a0cc more of "
        "her right breast and 24\u00a0cc more of her left lie there."]


def test_one_breast_unseen_or_planned_is_named_alone_and_breasts_seen_whole_say_nothing():
    for plan in (_plan(left=12.0), _plan(left=12.0, right=0.4)):
        assert outer_words(plan) == [
            "Seen from in front of her, the scan does not show all of her left breast's outer side: perhaps 12\u00a0cc "
            "more lies there."]
    assert outer_words(_plan(left=0.2, right=0.4)) == []
