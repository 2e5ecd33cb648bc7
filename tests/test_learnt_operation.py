"""A clinic's model of an operation learnt from before/after pairs (`plan.learnt_operation`), against truths built
here: her scanned skin with a bump of known shape and volume added and her nipple moved by a known shift (the
"after" of each pair), her mirror symmetry, and a MakeHuman body one cup larger (the body an augmentation aims at)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_breast_volume import measured, scanned

from breastplan import ArtefactError, BadInputError
from breastplan.plan.breast_volume import CELL_MM
from breastplan.plan.learnt_operation import (AXIS, LearntOperation, Pair, load_operation_model, operation_models,
                                              save, train)
from breastplan.plan.operation_spec import OperationSpec

BODY = "symmetric"
SIGMA_MM = 30.0
"""The bump's width: a Gaussian of this σ round her nipple, lowered by LOWER_MM (an implant fills the lower pole) and
moved outwards by OUT_MM (so that its mirror image is another bump)."""
LOWER_MM, OUT_MM = 10.0, 12.0
DROP_MM_PER_CC = 0.05
"""The pairs' nipple goes this far down, and half as far outwards, per cc added."""


def _bump(volumes, side: str) -> tuple[np.ndarray, float]:
    """(nx, ny) a Gaussian bump of unit height round her `side` nipple (lowered), and its volume (cc)."""
    cells = volumes.cells
    n = volumes.in_body(scanned(BODY)[1][side])
    outwards = 1.0 if side == "left" else -1.0
    X, Y = np.meshgrid(cells.x - n[0] - outwards * OUT_MM, cells.y - n[1] + LOWER_MM, indexing="ij")
    bump = np.exp(-0.5 * (X ** 2 + Y ** 2) / SIGMA_MM ** 2)
    return bump, float(bump.sum() * CELL_MM ** 2 / 1000.0)


def _after(volumes, change_cc: float, sides=("left",)):
    """Her torso's cells with `change_cc` of bump on each of `sides`, and her nipples moved as DROP_MM_PER_CC says
    (input frame)."""
    height, nipples = volumes.cells.height_mm, dict(scanned(BODY)[1])
    R = volumes.body_from_input[:3, :3]
    for side in sides:
        bump, cc = _bump(volumes, side)
        height = height + bump * change_cc / cc
        out = 1.0 if side == "left" else -1.0
        nipples[side] = nipples[side] + np.array([0.5 * out, -1.0, 0.0]) @ R * DROP_MM_PER_CC * change_cc
    return replace(volumes, cells=replace(volumes.cells, height_mm=height)), nipples


def _pairs(volumes, changes=(150.0, 250.0, 350.0, 450.0), side="left"):
    nipples = scanned(BODY)[1]
    out = []
    for cc in changes:
        after, moved = _after(volumes, cc, (side,))
        out.append(Pair(volumes, after, nipples[side], moved[side], side, OperationSpec.parse(f"augmentation:{cc:g}"),
                        f"woman {cc:g}"))
    return out


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "augmentation.npz"
    save(path, train(_pairs(measured(BODY)), "ridge"))
    return load_operation_model(path)


def test_a_pairs_skin_change_is_the_bump_it_was_given():
    volumes = measured(BODY)
    pair = _pairs(volumes, (300.0,))[0]
    change = pair.skin_change()
    assert change.shape == (AXIS.size, AXIS.size)
    assert change.sum() * CELL_MM ** 2 / 1000.0 == pytest.approx(300.0, rel=0.01)     # the bump, all of it
    assert np.unravel_index(np.argmax(change), change.shape)[1] < AXIS.size // 2    # below her nipple
    assert pair.nipple_shift() == pytest.approx([0.5 * DROP_MM_PER_CC * 300, -DROP_MM_PER_CC * 300], abs=1e-6)


def test_the_model_makes_the_operation_the_pairs_show_with_her_volume_changed_exactly(model):
    """A 200 cc implant, an amount no pair shows: her skin rises in the bump's shape over her footprint (the part
    of the bump outside it made up inside, so that her volume on her skin grows by 200 cc exactly), her nipple
    moves as the pairs' line says."""
    volumes = measured(BODY)
    nipple = scanned(BODY)[1]["left"]
    op = model.operate(volumes, nipple, "left", OperationSpec.parse("augmentation:200"))
    assert isinstance(op, LearntOperation) and op.model == "augmentation.npz"
    after = replace(volumes.cells, height_mm=op.heights(volumes.cells.height_mm), footprint=op.footprint)
    grown = replace(volumes.cells, footprint=op.footprint)
    assert after.volume_cc("left") - grown.volume_cc("left") == pytest.approx(200.0, abs=0.01)
    bump, cc = _bump(volumes, "left")
    inside = op.footprint & (volumes.cells.x > 0)[:, None]
    ratio = op.lift_mm[inside] / bump[inside]
    assert ratio.std() < 0.01 * ratio.mean() and 1.0 <= ratio.mean() < 1.0 / 0.8 * 200.0 / cc
    assert (op.lift_mm[~inside] == 0.0).all()
    assert np.abs(op.lift_mm[volumes.cells.x < 0]).max() == 0.0                      # her other breast untouched
    moved = volumes.in_body(op(nipple[None])[0]) - volumes.in_body(nipple)
    assert moved[:2] == pytest.approx([0.5 * DROP_MM_PER_CC * 200, -DROP_MM_PER_CC * 200], abs=0.05)
    assert moved[2] > 0.0                                                             # onto the risen skin


def test_a_change_outside_the_pairs_is_shaped_as_the_nearest_of_them_and_said(model):
    """Learnt from 150–450 cc: 600 cc has the bump's shape, 600 cc of it, and the plan says she lies outside."""
    volumes = measured(BODY)
    op = model.operate(volumes, scanned(BODY)[1]["left"], "left", OperationSpec.parse("augmentation:600"))
    assert op.note is not None and "600 cc lies outside the pairs' 150–450 cc" in op.note
    assert np.allclose(model.field(600.0, 500.0), model.field(450.0, 500.0))
    bump, _ = _bump(volumes, "left")
    inside = op.footprint & (volumes.cells.x > 0)[:, None]
    ratio = op.lift_mm[inside] / bump[inside]
    assert ratio.std() < 0.01 * ratio.mean()
    cells = replace(volumes.cells, footprint=op.footprint)
    assert replace(cells, height_mm=op.heights(cells.height_mm)).volume_cc("left") - cells.volume_cc("left") \
        == pytest.approx(600.0, abs=0.01)
    assert model.operate(volumes, scanned(BODY)[1]["left"], "left",
                         OperationSpec.parse("augmentation:300")).note is None


def test_a_model_learnt_on_left_breasts_makes_the_mirror_change_on_a_right_one(model):
    """Learnt from left breasts only, on her right breast: the bump round her right nipple, and the nipple's shift
    mirrored (outwards is to her right)."""
    volumes = measured(BODY)
    nipple = scanned(BODY)[1]["right"]
    op = model.operate(volumes, nipple, "right", OperationSpec.parse("augmentation:300"))
    bump, _ = _bump(volumes, "right")
    inside = op.footprint & (volumes.cells.x < 0)[:, None]
    ratio = op.lift_mm[inside] / bump[inside]
    assert ratio.std() < 0.01 * ratio.mean()
    assert np.abs(op.lift_mm[volumes.cells.x > 0]).max() == 0.0
    moved = volumes.in_body(op(nipple[None])[0]) - volumes.in_body(nipple)
    assert moved[:2] == pytest.approx([-0.5 * DROP_MM_PER_CC * 300, -DROP_MM_PER_CC * 300], abs=0.05)


def test_a_reduction_model_lowers_her_skin_by_the_resection_exactly(tmp_path):
    volumes = measured(BODY)
    nipple = scanned(BODY)[1]["right"]
    pairs = []
    for cc in (100.0, 200.0):
        after, moved = _after(volumes, -cc, ("right",))
        pairs.append(Pair(volumes, after, nipple, moved["right"], "right", OperationSpec.parse(f"reduction:{cc:g}"),
                          f"woman {cc:g}"))
    save(tmp_path / "reduction.npz", train(pairs, "ridge"))
    model = load_operation_model(tmp_path / "reduction.npz")
    assert model.kind == "reduction" and model.pairs == 2
    op = model.operate(volumes, nipple, "right", OperationSpec.parse("reduction:150"))
    cells = replace(volumes.cells, footprint=op.footprint)
    assert replace(cells, height_mm=op.heights(cells.height_mm)).volume_cc("right") - cells.volume_cc("right") \
        == pytest.approx(-150.0, abs=0.01)
    assert (op.footprint == volumes.cells.side("right")).all()                 # a resection grows no footprint
    breast = volumes.sides["right"].volume_cc
    most = model.operate(volumes, nipple, "right", OperationSpec.parse(f"reduction:{0.9 * breast:.1f}"))
    assert (cells.height_mm + most.lift_mm >= -1e-9)[cells.side("right") & (cells.height_mm > 0)].all()
    assert replace(cells, height_mm=most.heights(cells.height_mm)).volume_cc("right") - cells.volume_cc("right") \
        == pytest.approx(-round(0.9 * breast, 1), abs=0.01)                     # her skin to her wall, not behind it
    for cut in (f"reduction:{breast + 1:.0f}", f"reduction:to={breast + 1:.0f}"):     # more than she has, or nothing
        with pytest.raises(BadInputError, match="more than nothing and less than the breast"):
            model.operate(volumes, nipple, "right", OperationSpec.parse(cut))


def test_a_reductions_share_is_learnt_round_each_place_so_one_cells_stray_height_does_not_reach_the_model():
    """A resection of 30 % of her tissue everywhere (her skin after at 0.7 of its height above the wall), scanned
    after with 3 % of the cells off by 15 mm (a cell seen at a grazing angle holds a few points): the share learnt
    over her breast (where her tissue stands over 10 mm) stays within 0.25 of the truth, −0.3, at every place, and
    within 0.02 at the median; one cell's stray height over one cell's tissue would read up to −1 or 0 there."""
    volumes = measured(BODY)
    nipple = scanned(BODY)[1]["left"]
    h = volumes.cells.height_mm
    cut = np.where(h > 0.0, 0.7 * h, h)
    rng = np.random.default_rng(5)
    stray = (rng.random(h.shape) < 0.03) * rng.choice([-15.0, 15.0], h.shape)

    def pair(after_mm):
        after = replace(volumes, cells=replace(volumes.cells, height_mm=after_mm))
        return Pair(volumes, after, nipple, nipple, "left", OperationSpec.parse("reduction:100:none"), "woman")

    tissue = -pair(cut).skin_change() / 0.3                                   # her tissue's height at each place
    error = np.abs(pair(cut + stray).learnt() + 0.3)[tissue > 10.0]
    assert error.size > 300
    assert error.max() < 0.25 and np.median(error) < 0.02


def test_a_file_that_is_no_operation_model_and_two_models_of_one_operation_are_refused(model, tmp_path):
    bad = tmp_path / "bad.npz"
    np.savez(bad, a=np.zeros(3))
    with pytest.raises(ArtefactError) as refused:
        load_operation_model(bad)
    assert "bad.npz" in str(refused.value)
    with pytest.raises(BadInputError, match="one model per operation"):
        operation_models([model.path, model.path])
    with pytest.raises(ValueError, match="one operation"):
        volumes = measured(BODY)
        mixed = _pairs(volumes, (150.0,)) + [replace(_pairs(volumes, (250.0,))[0],
                                                     spec=OperationSpec.parse("reduction:100"))]
        train(mixed)


def test_the_model_is_the_same_whatever_the_order_of_the_pairs(tmp_path):
    pairs = _pairs(measured(BODY))
    save(tmp_path / "a.npz", train(pairs, "ridge"))
    save(tmp_path / "b.npz", train(pairs[::-1], "ridge"))
    a, b = (load_operation_model(tmp_path / f) for f in ("a.npz", "b.npz"))
    assert np.allclose(a.field(222.0, 500.0), b.field(222.0, 500.0), atol=1e-9)
    assert np.allclose(a.nipple_shift(222.0), b.nipple_shift(222.0), atol=1e-9)
