"""BCCT.core's asymmetry measures and Regnault's ptosis grade taken on her skin (plan.symmetry), on MakeHuman
bodies whose nipples and sternal notch are known: a symmetric woman, one breast lowered by MakeHuman's
asymmetry target, one breast moved down by a known amount, a firm and a soft breast of one size, a small
firm one, and planned heights whose overlap is known in closed form."""
from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest

from breastplan import transform_points
from breastplan.body import Body
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.ingest.pipeline import ingest_frames
from breastplan.scenes.realistic import BodyScene, CameraOptions, camera_pose
from breastplan.ingest.recording import DepthFrames
from breastplan.options import IngestOptions
from breastplan.plan.breast_volume import measure_breasts
from breastplan.plan.symmetry import GRADES, bcct_measures, ptosis_grade, symmetry_measures

BODIES = {"symmetric": BodyOptions(cup=0.7, firmness=0.4, weight=0.6, pose="hands-on-hips"),
          "asymmetric": BodyOptions(cup=0.85, firmness=0.2, modifiers={"asymmetry": 0.5}, pose="arms-down"),
          "firm": BodyOptions(cup=0.8, firmness=1.0, pose="hands-on-hips"),
          "soft": BodyOptions(cup=0.8, firmness=0.0, pose="hands-on-hips"),
          "small": BodyOptions(cup=0.2, firmness=0.9, pose="hands-on-hips")}
RANK = {"0": 0, "pseudoptosis": 1, "I": 1, "II": 2, "III": 3}
"""How ptotic a grade is, for comparing two (pseudoptosis: the gland has fallen, the nipple not)."""


@lru_cache(maxsize=None)
def scanned(body: str):
    """(the made body, what `plan` ingests of it: torso, nipples, view, plumb — input frame, mm)."""
    made = make_body(BODIES[body])
    camera = CameraOptions(650.0, 5.0, 0.0, "800x600", wall_mm=400.0)
    target = 0.5 * (made.nipples["left"] + made.nipples["right"])
    frames = DepthFrames(BodyScene(made, camera, camera_pose(target, camera)).frames(8, 0), camera.K, "test")
    sides = {side: ingest_frames(frames, IngestOptions(side)) for side in ("left", "right")}
    first = sides["left"]
    return made, first.torso_camera, {s: i.nipple_camera for s, i in sides.items()}, first.input_to_view, \
        first.plumb_camera


@lru_cache(maxsize=None)
def measured(body: str):
    made, torso, nipples, view_from, plumb = scanned(body)
    return measure_breasts(Body(torso, view_from, plumb), nipples), nipples


def test_a_symmetric_woman_measures_symmetric():
    m, nipples = measured("symmetric")
    s = symmetry_measures(m, nipples)
    for name in ("pBRA_pct", "pUNR_pct", "pLBC_pct", "pBCE_pct"):
        assert 0.0 <= s[name] < 1.5, name
    assert s["BCD_mm"] < 3.0                          # under one 5 mm cell
    assert 97.0 < s["overlap_pct"] <= 100.0


def test_a_lowered_breast_gives_the_retraction_its_true_nipples_give():
    """MakeHuman's asymmetry target lowers the left breast: pBRA and pUNR from the scan match the same
    measures written out here from the true nipples and notch (MakeHuman's frame: x her left, y up)."""
    made = scanned("asymmetric")[0]
    m, nipples = measured("asymmetric")
    s = symmetry_measures(m, nipples)
    rel = {side: made.nipples[side] - made.sternal_notch for side in ("left", "right")}
    mirrored_right = rel["right"] * [-1.0, 1.0, 1.0]
    true_pbra = 100.0 * np.linalg.norm(rel["left"] - mirrored_right) / np.mean([np.linalg.norm(v) for v in rel.values()])
    below = {side: -v[1] for side, v in rel.items()}
    true_punr = 100.0 * abs(below["left"] - below["right"]) / (0.5 * (below["left"] + below["right"]))
    assert true_punr > 5.0                            # the target lowers one nipple by over a centimetre
    assert s["pBRA_pct"] == pytest.approx(true_pbra, abs=1.0)
    assert s["pUNR_pct"] == pytest.approx(true_punr, abs=1.0)
    assert 80.0 < s["overlap_pct"] < 97.0             # no longer mirror twins


def moved_down(body: str) -> dict:
    """The symmetry measures of `body`'s scan with its left breast, skin and nipple, moved 10 mm down her up
    axis (the whole breast within 100 mm of its nipple, tapering to nothing at 150 mm)."""
    made, torso, nipples, view_from, plumb = scanned(body)
    T = measured(body)[0].body_from_input
    points = transform_points(T, torso)
    nipple = transform_points(T, nipples["left"][None])[0]
    d = np.linalg.norm(points[:, :2] - nipple[:2], axis=1)
    shift = 10.0 * np.where(d < 100.0, 1.0, np.where(d < 150.0, 0.5 * (1.0 + np.cos(np.pi * (d - 100.0) / 50.0)), 0.0))
    points[:, 1] -= np.where(points[:, 0] > 0, shift, 0.0)
    moved = dict(nipples, left=transform_points(np.linalg.inv(T), (nipple - [0.0, 10.0, 0.0])[None])[0])
    after = measure_breasts(Body(transform_points(np.linalg.inv(T), points), view_from, plumb), moved)
    return symmetry_measures(after, moved)


def test_a_breast_moved_down_moves_its_contour_and_nipple_by_as_much():
    """The symmetric woman's left breast moved 10 mm down (`moved_down`): the nipples and the lower contours
    differ by 10 mm, and the nipples' heights above their contours alike."""
    s = moved_down("symmetric")
    assert s["UNR_mm"] == pytest.approx(10.0, abs=2.0)
    assert s["BRA_mm"] == pytest.approx(10.0, abs=2.5)
    assert s["LBC_mm"] == pytest.approx(10.0, abs=3.0)
    assert s["BCE_mm"] < 3.0


def test_a_lower_contour_read_from_her_other_side_is_said_to_be():
    """A soft cup-0.8 breast hangs over skin the camera does not see. Moved 10 mm down, either its lower
    contour reads the move, or the measures say that a lowest point lay on a hidden cell, whose height is her
    other side's, mirrored. The small firm breasts' lowest points are seen."""
    s = moved_down("soft")
    assert s["UNR_mm"] == pytest.approx(10.0, abs=2.0)
    assert s["LBC_mm"] > 8.0 or s["lower_contours_hidden"] >= 1
    assert symmetry_measures(*measured("small"))["lower_contours_hidden"] == 0


def test_a_soft_breast_hangs_at_least_as_far_as_a_firm_one():
    """Same size, firmness 1 against 0: MakeHuman's soft breast carries its nipple 32 mm nearer its fold
    and hangs lower; the grade is at least as ptotic, the nipple nearer the fold (or further below it)."""
    grades = {}
    for body in ("firm", "soft"):
        m, nipples = measured(body)
        grades[body] = {side: ptosis_grade(m, nipples, side) for side in ("left", "right")}
    for side in ("left", "right"):
        firm, soft = grades["firm"][side], grades["soft"][side]
        assert firm["grade"] in GRADES and soft["grade"] in GRADES
        assert RANK[soft["grade"]] >= RANK[firm["grade"]]
        assert soft["nipple_to_fold_mm"] < firm["nipple_to_fold_mm"] - 10.0
        assert soft["nipple_to_lowest_mm"] < firm["nipple_to_lowest_mm"] - 10.0
        assert {firm["fold_from"], soft["fold_from"]} <= {"seen", "estimated"}


def test_a_small_firm_breast_is_not_ptotic_and_its_fold_is_seen():
    """A small firm breast does not hang over its fold: the camera sees the skin under the nipple come
    down to the chest, and the nipple is well above it (MakeHuman's: 45 mm)."""
    m, nipples = measured("small")
    for side in ("left", "right"):
        p = ptosis_grade(m, nipples, side)
        assert p["grade"] in ("0", "I")
        assert p["fold_from"] == "seen"
        assert p["lowest_to_fold_mm"] == pytest.approx(0.0, abs=2.0)
        assert 25.0 < p["nipple_to_fold_mm"] < 65.0


def test_a_planned_state_is_measured_from_its_nipples_and_cells_alone():
    """Planned heights on the scan's cells: her left breast mirrored onto her right gives mirror twins
    (overlap 100 %, no retraction, no contour difference); the right then shrunk to 80 % of the left's
    heights shares 0.8 of the left's volume with it, over a mean of 0.9: 88.9 %."""
    m, nipples = measured("asymmetric")
    cells = m.cells
    T = m.body_from_input
    left = transform_points(T, nipples["left"][None])[0]
    twin = {"left": left, "right": left * [-1.0, 1.0, 1.0]}
    half = cells.x > 0
    h = np.where(half[:, None], cells.height_mm, cells.height_mm[::-1])
    s = bcct_measures(twin, dataclasses.replace(cells, height_mm=h))
    assert s["overlap_pct"] == pytest.approx(100.0, abs=1e-9)
    for name in ("BRA_mm", "UNR_mm", "LBC_mm", "BCE_mm", "BCD_mm"):
        assert s[name] == pytest.approx(0.0, abs=1e-9), name
    shrunk = np.where(half[:, None], h, 0.8 * np.clip(h, 0.0, None))
    s = bcct_measures(twin, dataclasses.replace(cells, height_mm=shrunk))
    assert s["overlap_pct"] == pytest.approx(100.0 * 0.8 / 0.9, abs=1e-6)


def test_one_breast_alone_has_no_symmetry_measures():
    m, nipples = measured("symmetric")
    assert symmetry_measures(m, {"left": nipples["left"]}) == {}
    assert symmetry_measures(dataclasses.replace(m, sides={"left": m.sides["left"]}), nipples) == {}


def _hanging_cells(depth_mm: float) -> "SkinCells":
    """Synthetic skin cells (5 mm, her body frame): the chest wall flat at height 0, seen everywhere, and
    each breast a block standing `depth_mm` in front of it over x ∈ [62.5, 137.5] (mirrored on her right),
    y ∈ [−250, −150] (cell centres); the footprint is both blocks."""
    from breastplan.plan.breast_volume import SkinCells

    x = -147.5 + 5.0 * np.arange(60)
    y = -400.0 + 5.0 * np.arange(80)
    block = ((np.abs(x) >= 62.5) & (np.abs(x) <= 137.5))[:, None] & ((y >= -250.0) & (y <= -150.0))[None, :]
    zeros = np.zeros(block.shape)
    return SkinCells(x, y, np.where(block, depth_mm, 0.0), np.ones(block.shape, bool), block, zeros)


# (depth of the breast's lowest cell in front of the wall, the nipple's height above the fold, Regnault's grade)
REGNAULT = [(100.0, 6.0, "pseudoptosis"), (100.0, 4.0, "I"), (100.0, -9.0, "I"), (100.0, -11.0, "II"),
            (100.0, -29.0, "II"), (100.0, -31.0, "III"), (60.0, -16.0, "II"), (60.0, -18.0, "III"),
            (60.0, 6.0, "pseudoptosis"), (40.0, 6.0, "0"), (50.0, 6.0, "pseudoptosis"),
            (20.0, 6.0, "0"), (20.0, 4.0, "I"), (20.0, -9.0, "I"), (20.0, -11.0, "III")]


@pytest.mark.parametrize("depth, above_fold, grade", REGNAULT)
def test_regnaults_grade_follows_the_nipples_height_above_the_fold(depth, above_fold, grade):
    """docs/symmetry.md on cells whose fold is known in closed form. The breast's lower contour: its lowest
    cell's centre (y = −250) less the fraction (d − 5)/d of a cell where the skin falls through 5 mm above the
    wall. A breast ending in a cliff (over 25 mm in front of the wall) hides its fold, put 0.45 × the depth
    above that contour; a low one (20 mm) meets the wall in view: the fold is where its skin comes within
    2 mm of the skin below, (20 − 2)/20 of a cell below its lowest centre. Then Regnault: above the fold by
    over 5 mm, "0" — or "pseudoptosis" when the contour hangs over 20 mm below the fold; to 1 cm below,
    "I"; to 3 cm below with the nipple over 1 cm above the contour, "II"; lower, "III"."""
    from breastplan.plan.symmetry import ptosis_from_cells

    cells = _hanging_cells(depth)
    contour = -250.0 - 5.0 * (depth - 5.0) / depth
    if depth > 25.0:
        fold, lowest, fold_from = contour + 0.45 * depth, contour, "estimated"
    else:
        fold = -250.0 - 5.0 * (depth - 2.0) / depth
        lowest, fold_from = min(contour, fold), "seen"
    for side, x in (("left", 100.0), ("right", -100.0)):
        nipple = np.array([x, fold + above_fold, depth])
        p = ptosis_from_cells(nipple, cells, side)
        assert p["fold_from"] == fold_from
        assert p["nipple_to_fold_mm"] == pytest.approx(above_fold, abs=1e-9)
        assert p["lowest_to_fold_mm"] == pytest.approx(lowest - fold, abs=1e-9)
        assert p["nipple_to_lowest_mm"] == pytest.approx(fold + above_fold - lowest, abs=1e-9)
        assert p["grade"] == grade, (side, p)
