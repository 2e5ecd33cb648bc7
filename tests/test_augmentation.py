"""Augmentation (`plan.implants`, `plan.augmentation`) against truths computed here: an implant's volume by
numerical integration of its thickness over its base, the catalogue's widths from its stated ratios, and an
implant placed under a MakeHuman patient's breast (scanned as a clinic scans her) measured on her skin."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import BadInputError, transform_points
from breastplan.options import OptionError
from breastplan.plan.augmentation import augmentation
from breastplan.plan.implants import PROFILES, Implant
from breastplan.plan.symmetry import ptosis_from_cells


def _integrated_cc(implant: Implant, step: float = 0.25) -> float:
    """The implant's volume by the midpoint rule over its base (cc)."""
    R = implant.width_mm / 2.0
    u = np.arange(-R, R, step) + step / 2.0
    x, y = np.meshgrid(u, u)
    return float(implant.thickness(x, y).sum() * step * step / 1000.0)


@pytest.mark.parametrize("profile", list(PROFILES))
@pytest.mark.parametrize("shape", ["round", "anatomical"])
def test_a_catalogue_implant_holds_its_volume_and_its_profiles_proportions(profile, shape):
    """300 cc of each profile: its thickness integrates to 300 cc; its projection is its profile's share of its
    width; a round one is as thick as its projection on its axis and its rim is flat on the chest; the
    anatomical one is fuller below its centre than above."""
    implant = Implant.of(300.0, profile, shape)
    assert _integrated_cc(implant) == pytest.approx(300.0, rel=2e-3)
    assert implant.projection_mm / implant.width_mm == pytest.approx(PROFILES[profile])
    R = implant.width_mm / 2.0
    assert implant.thickness(R, 0.0) == 0.0 and implant.thickness(0.0, -1.01 * R) == 0.0
    if shape == "round":
        assert implant.thickness(0.0, 0.0) == pytest.approx(implant.projection_mm)
    else:
        assert implant.thickness(0.0, -0.5 * R) > implant.thickness(0.0, 0.5 * R)


def test_the_catalogue_widens_with_volume_and_flattens_with_a_lower_profile():
    widths = [Implant.of(v, "moderate").width_mm for v in (150, 300, 450)]
    assert widths == sorted(widths) and widths[-1] / widths[0] == pytest.approx(3 ** (1 / 3))
    by_profile = [Implant.of(300, p) for p in PROFILES]                           # low → extra-high
    assert [i.width_mm for i in by_profile] == sorted((i.width_mm for i in by_profile), reverse=True)
    assert 100 < Implant.of(300, "moderate").width_mm < 130                       # a clinic's 300 cc moderate
    sized = Implant.sized(115.0, 36.8)
    assert _integrated_cc(sized) == pytest.approx(sized.volume_cc, rel=2e-3)


@pytest.mark.parametrize("bad", [dict(volume_cc=5.0, profile="moderate"), dict(volume_cc=300.0, profile="huge"),
                                 dict(volume_cc=300.0, profile="moderate", shape="square")])
def test_an_implant_no_catalogue_holds_is_an_option_error(bad):
    with pytest.raises(OptionError):
        Implant.of(**bad)


def _placed(body: str, side: str, implant: Implant, pocket: str = "subglandular"):
    torso, nipples, *_ = scanned(body)
    m = measured(body)
    nipple = transform_points(m.body_from_input, nipples[side][None])[0]
    fold = ptosis_from_cells(nipple, m.cells, side)["nipple_to_fold_mm"]
    return m, torso, nipples, augmentation(m, side, nipples[side], fold, implant, pocket)


@pytest.mark.parametrize("body,implant,pocket", [("small", Implant.of(300, "moderate"), "subglandular"),
                                                 ("small", Implant.of(200, "high", "anatomical"), "submuscular"),
                                                 ("symmetric", Implant.of(250, "low"), "subglandular")])
def test_an_implant_under_her_left_breast_adds_its_volume_there_and_nothing_on_the_right(body, implant, pocket):
    """A MakeHuman patient (a small breast of 140 cc, or a fuller one), scanned from 650 mm: her left breast
    measured on her skin with the implant (inside her footprint grown over what it raises) grows by the
    implant's volume to 0.1 cc; her right breast and her skin beyond her left half do not move; her nipple comes
    forward, along her anterior axis, by at least half the implant's projection and less than its thickness
    at its thickest."""
    m, torso, nipples, aug = _placed(body, "left", implant, pocket)
    grown = aug.footprint | m.cells.footprint
    after = replace(m.cells, height_mm=aug.heights(m.cells.height_mm), footprint=grown)
    before = replace(m.cells, footprint=grown)
    assert after.volume_cc("left") - before.volume_cc("left") == pytest.approx(implant.volume_cc, abs=0.1)
    assert after.volume_cc("right") == before.volume_cc("right")
    moved = aug.displacement(torso)
    body_x = transform_points(m.body_from_input, torso)[:, 0]
    assert np.abs(moved[body_x < 0]).max() == 0.0                                  # her right half stays
    forward = aug.displacement(nipples["left"][None])[0] @ m.landmarks.anterior_axis
    assert 0.5 * implant.projection_mm < forward < 1.5 * implant.projection_mm
    assert np.allclose(np.cross(moved, m.landmarks.anterior_axis), 0.0, atol=1e-9)  # along her anterior axis


def test_behind_the_muscle_the_upper_pole_rises_less():
    """The same implant behind the muscle lifts her skin above its centre less, and below it more (its volume
    kept), than in front of it."""
    implant = Implant.of(300, "moderate")
    glandular, muscular = (_placed("small", "left", implant, pocket)[3] for pocket in ("subglandular", "submuscular"))
    above = glandular.y[None, :] > glandular.centre_mm[1] + 20.0
    below = glandular.y[None, :] < glandular.centre_mm[1] - 20.0
    assert (muscular.lift_mm * above).sum() < 0.8 * (glandular.lift_mm * above).sum()
    assert (muscular.lift_mm * below).sum() > (glandular.lift_mm * below).sum()


def test_an_implant_that_would_reach_over_her_sternum_is_refused_in_a_sentence():
    with pytest.raises(BadInputError, match="over her sternum.*choose a narrower implant"):
        _placed("small", "left", Implant.sized(200.0, 20.0))


def test_a_pocket_that_is_neither_in_front_of_nor_behind_the_muscle_is_an_option_error():
    with pytest.raises(OptionError, match="subglandular or submuscular"):
        _placed("small", "left", Implant.of(300, "moderate"), "subcutaneous")


def test_the_fold_is_lowered_as_a_surgeon_lowers_it_for_a_wide_implant_and_kept_where_it_is_low_enough():
    """An 11 cm implant under a small breast whose fold lies 40 mm below her nipple: its lower rim on a new fold
    7 cm below the nipple (the rule of thumb: an 11 cm implant, 7 cm from nipple to fold), so its centre 15 mm
    below the nipple, under it across her body. A fold 90 mm below the nipple stays where it is."""
    torso, nipples, *_ = scanned("small")
    m = measured("small")
    nipple = transform_points(m.body_from_input, nipples["left"][None])[0]
    implant = Implant.sized(110.0, 35.0)
    low = augmentation(m, "left", nipples["left"], 40.0, implant)
    assert low.centre_mm == pytest.approx([nipple[0], nipple[1] - 15.0])
    kept = augmentation(m, "left", nipples["left"], 90.0, implant)
    assert kept.centre_mm[1] == pytest.approx(nipple[1] - 90.0 + 55.0)
