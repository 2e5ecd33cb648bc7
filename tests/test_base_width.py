"""Her breast's width on her skin (`plan.base_width`): a closed-form height field, and MakeHuman bodies whose
symmetry is known, scanned again from other places, and one whose breasts differ by a cup."""
from __future__ import annotations

import numpy as np
import pytest

from breastplan.plan.base_width import base_width_mm
from breastplan.plan.breast_volume import FOOT_MM, SkinCells
from test_breast_volume import SYMMETRIC, measured, scanned

CELL = 5.0


def _ridge(x0: float, peak: float, slope: float, tilt: float) -> SkinCells:
    """Her skin as a ridge over the cells: peak − slope·|x − x0| − tilt·y mm above the wall on each side
    (mirrored), the wall flat; cells 5 mm, symmetric about x = 0."""
    x = CELL * (np.arange(60) - 29.5)
    y = CELL * np.arange(-20, 20)
    h = peak - slope * np.abs(np.abs(x)[:, None] - x0) - tilt * y[None, :]
    return SkinCells(x, y, h, np.ones(h.shape, bool), np.zeros(h.shape, bool), np.zeros(h.shape))


@pytest.mark.parametrize("side", ["left", "right"])
def test_the_width_is_where_her_skin_falls_to_the_footprints_height_either_side_of_her_nipple(side):
    """Linear in x either side of a cell's centre and in y, so the linear interpolation is exact: at her nipple's
    height y_n the skin stands peak − tilt·y_n at the nipple and falls to FOOT_MM at ± (that − FOOT_MM) / slope."""
    x0, peak, slope, tilt, y_n = 102.5, 60.0, 1.5, 0.3, -12.0          # the nipple between two rows of cells
    cells = _ridge(x0, peak, slope, tilt)
    nipple = np.array([x0 if side == "left" else -x0, y_n, 0.0])
    assert base_width_mm(cells, nipple, side) == pytest.approx(2 * (peak - tilt * y_n - FOOT_MM) / slope, rel=1e-9)


def test_a_breast_that_reaches_her_midline_is_measured_to_it():
    x0, peak, slope = 42.5, 70.0, 0.8                                  # would fall to FOOT_MM 81 mm inwards
    cells = _ridge(x0, peak, slope, 0.0)
    assert base_width_mm(cells, np.array([x0, 0.0, 0.0]), "left") == pytest.approx(
        x0 + (peak - FOOT_MM) / slope, rel=1e-9)


def test_skin_that_does_not_stand_out_at_her_nipple_has_no_width():
    cells = _ridge(100.0, FOOT_MM - 1.0, 1.0, 0.0)
    assert base_width_mm(cells, np.array([-102.5, 0.0, 0.0]), "right") == 0.0


def _widths(body: str, **view) -> dict[str, float]:
    nipples, m = scanned(body, **view)[1], measured(body, **view)
    return {s: base_width_mm(m.cells, m.in_body(n), s) for s, n in nipples.items()}


VIEWS = [dict(distance=610.0, pitch=3.0, yaw=-6.0, height=20.0), dict(distance=700.0, pitch=9.0, yaw=5.0, height=-20.0,
                                                                   wall=None), dict(yaw=10.0, wall=None)]


def test_a_symmetric_woman_scanned_from_three_places_has_the_same_width_on_both_sides_and_every_scan():
    """Truth: her symmetry, and her body, the same in every scan. The fitted model's base moves by 5–17 mm over such
    re-scans (docs/volume.md)."""
    widths = np.array([[w["left"], w["right"]] for w in (_widths(SYMMETRIC, **v) for v in VIEWS)])
    assert 80.0 < widths.min() and widths.max() < 160.0
    assert np.abs(widths[:, 0] - widths[:, 1]).max() <= 3.0
    assert np.ptp(widths, axis=0).max() <= 6.0



def test_a_breast_a_cup_larger_than_the_other_is_wider_in_every_view():
    """Truth: her left half is a cup-0.8 body's, her right a cup-0.4 body's (the same body otherwise)."""
    for view in VIEWS:
        w = _widths("one cup larger", **view)
        assert w["left"] - w["right"] > 8.0, (view, w)

