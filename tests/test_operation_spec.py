"""Operations as a surgeon writes them (`plan.operation_spec`): each form the docs give is read to the settings it
names, every malformed one is an OptionError (a usage error) in a sentence naming it, and a spec makes its
operation on a MakeHuman patient, her volume on her skin changing by what the operation says."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import BadInputError, transform_points
from breastplan.options import OptionError
from breastplan.plan.augmentation import Augmentation
from breastplan.plan.implants import Implant
from breastplan.plan.lumpectomy import Lumpectomy
from breastplan.plan.mastopexy import Mastopexy
from breastplan.plan.operation_spec import OperationSpec
from breastplan.plan.reduction import Reduction
from breastplan.plan.symmetry import ptosis_from_cells


@pytest.mark.parametrize("text,kind,settings", [
    ("augmentation:300", "augmentation", {"profile": "moderate", "shape": "round", "pocket": "subglandular"}),
    ("augmentation:250:high:anatomical:submuscular", "augmentation",
     {"volume_cc": 250.0, "profile": "high", "shape": "anatomical", "pocket": "submuscular"}),
    ("augmentation:115x37", "augmentation", {"width_mm": 115.0, "projection_mm": 37.0}),
    ("lift:notch=210", "lift", {"lift": "notch", "mm": 210.0}),
    ("lift:fold=20", "lift", {"lift": "fold", "mm": 20.0}),
    ("lift:other", "lift", {"lift": "other"}),
    ("reduction:200", "reduction", {"volume_cc": 200.0, "lift": "needed"}),
    ("reduction:200:none", "reduction", {"volume_cc": 200.0, "lift": "none"}),
    ("reduction:to=350:other", "reduction", {"to_volume_cc": 350.0, "lift": "other"}),
    ("lumpectomy:40:10:30", "lumpectomy", {"volume_cc": 40.0, "clock": 10.0, "distance_mm": 30.0}),
    ("lumpectomy:40:10:30:15", "lumpectomy", {"volume_cc": 40.0, "clock": 10.0, "distance_mm": 30.0,
                                              "depth_mm": 15.0})])
def test_each_written_form_reads_to_the_settings_it_names(text, kind, settings):
    spec = OperationSpec.parse(text)
    assert spec.kind == kind and settings.items() <= spec.settings.items()


def test_an_implant_given_by_its_size_holds_the_volume_its_shape_gives():
    assert OperationSpec.parse("augmentation:115x37").settings["volume_cc"] == pytest.approx(
        Implant.sized(115.0, 37.0).volume_cc)


@pytest.mark.parametrize("text,words", [
    ("implant:300", "no operation"), ("augmentation", "needs the implant's volume"),
    ("augmentation:5000", "1000 cc"), ("augmentation:300:huge", "no profile"), ("augmentation:abc", "not a number"),
    ("lift", "one target"), ("lift:nipple=3", "notch=MM, fold=MM or other"), ("lift:notch=-5", "positive"),
    ("reduction", "cc resected"), ("reduction:100:notch=200", "fold=MM or other"),
    ("lumpectomy:40:10", "VOLUME:CLOCK:DISTANCE"), ("lumpectomy:40:10:30:0", "positive"),
    ("lumpectomy:40:13:30", "1–12")])
def test_a_malformed_operation_is_an_option_error_naming_it(text, words):
    with pytest.raises(OptionError, match=words):
        OperationSpec.parse(text)


@pytest.mark.parametrize("text,kind,want", [("augmentation:200:moderate", Augmentation, 200.0),
                                            ("lift:other", Mastopexy, 0.0), ("reduction:60", Reduction, -60.0),
                                            ("lumpectomy:30:2:30", Lumpectomy, -30.0)])
def test_a_spec_makes_its_operation_on_her_breast(text, kind, want):
    """On a patient whose breasts hang unequally, on her lower breast: her volume on her skin changes by what the
    operation says (the implant added, the resection or excision taken, none for a lift)."""
    torso, nipples, *_ = scanned("asymmetric")
    m = measured("asymmetric")
    body = {s: transform_points(m.body_from_input, n[None])[0] for s, n in nipples.items()}
    low = min(body, key=lambda s: body[s][1])
    fold = ptosis_from_cells(body[low], m.cells, low)["nipple_to_fold_mm"]
    done = OperationSpec.parse(text).operate(m, nipples, low, fold)
    assert isinstance(done, kind)
    grown = replace(m.cells, footprint=m.cells.footprint | done.footprint)
    change = replace(grown, height_mm=done.heights(grown.height_mm)).volume_cc(low) - grown.volume_cc(low)
    assert change == pytest.approx(want, abs=0.05)
    assert np.isfinite(done(nipples[low][None])).all()


@pytest.mark.parametrize("fold_mm,rise_mm", [(-20.0, 20.0), (15.0, 0.0)])
def test_a_reduction_lifts_a_nipple_below_her_fold_to_its_height_and_no_other(fold_mm, rise_mm):
    """`reduction:60` with the lift it needs: a nipple 20 mm below her fold rises 20 mm, to the fold's height (where
    a reduction places it); one 15 mm above her fold does not rise; `reduction:60:none` never lifts."""
    _, nipples, *_ = scanned("asymmetric")
    m = measured("asymmetric")
    up = lambda done: (transform_points(m.body_from_input, done(nipples["left"][None]))[0]  # noqa: E731
                       - transform_points(m.body_from_input, nipples["left"][None])[0])[1]
    assert up(OperationSpec.parse("reduction:60").operate(m, nipples, "left", fold_mm)) == pytest.approx(rise_mm,
                                                                                                        abs=0.5)
    assert up(OperationSpec.parse("reduction:60:none").operate(m, nipples, "left", fold_mm)) == pytest.approx(0.0,
                                                                                                             abs=0.5)


def test_a_reduction_whose_needed_lift_is_out_of_reach_says_how_to_plan_it():
    """Her nipple 200 mm below her fold: the lift a reduction needs is beyond any lift's reach; the sentence says
    so and names the two ways to write the reduction instead."""
    _, nipples, *_ = scanned("asymmetric")
    with pytest.raises(BadInputError, match="reduction:60:none"):
        OperationSpec.parse("reduction:60").operate(measured("asymmetric"), nipples, "left", -200.0)


def test_a_reduction_larger_than_her_breast_is_refused_as_such_whatever_lift_it_needs():
    _, nipples, *_ = scanned("asymmetric")
    with pytest.raises(BadInputError, match="less than the breast") as caught:
        OperationSpec.parse("reduction:5000").operate(measured("asymmetric"), nipples, "left", -20.0)
    assert "lift" not in str(caught.value)
