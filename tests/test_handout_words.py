"""Her words on her breasts' unseen outer sides: said for the breasts planned, right first as the handout's columns
run, from a teaspoon (5 cc) on, and not at all below."""
from types import SimpleNamespace

from breastplan.plan.handout import outer_words


def _plan(**unseen_cc):
    return SimpleNamespace(sides=dict.fromkeys(unseen_cc), shown_sides=[s for s in ("right", "left") if s in unseen_cc],
                           volumes=SimpleNamespace(sides={s: SimpleNamespace(unseen_outer_cc=v)
                                                          for s, v in unseen_cc.items()}))


def test_her_words_say_what_her_unseen_outer_sides_may_hold_right_breast_first():
    assert outer_words(_plan(left=24.4, right=31.6)) == [
        "The volumes above are measured on her skin as seen from the front, which does not reach all the way round "
        "each breast: as scanned, her right breast may hold about 32\u00a0cc more, and her left about 24\u00a0cc "
        "more."]


def test_one_breast_planned_or_past_a_teaspoon_is_named_alone_and_less_is_not_said():
    for plan in (_plan(left=12.0), _plan(left=12.0, right=4.9)):
        assert outer_words(plan) == [
            "The volume of her left breast above is measured on her skin as seen from the front, which does not "
            "reach all the way round it: as scanned, it may hold about 12\u00a0cc more."]
    assert outer_words(_plan(left=4.9, right=2.0)) == []
