"""Her breast's width measured on her skin, as a tape laid across its base at her nipple's height.

Along the row of her skin's height field at her nipple's height (heights above the chest wall, her body frame:
x to her left, mm; the two rows of cells round that height interpolated linearly), from her nipple outwards
and inwards to where her skin first stands less than FOOT_MM in front of the wall — the height her footprint
starts at — each crossing interpolated linearly between two cells; inwards at most to her midline, outwards
at most to the last cell measured. The fitted model's base outline gives a width too, but the model's fit is
not continuous in her points, and a re-scan moves it far more (docs/volume.md).
"""
from __future__ import annotations

import numpy as np

from .breast_volume import CELL_MM, FOOT_MM, SkinCells


def base_width_mm(cells: SkinCells, nipple_body: np.ndarray, side: str) -> float:
    """The width (mm) of her `side` breast at the height of its nipple (`nipple_body`, (3,) body frame, mm) on
    her skin's `cells` (module docstring); 0 where her skin at the nipple stands less than FOOT_MM out."""
    x = cells.x
    j = float(np.clip((nipple_body[1] - cells.y[0]) / CELL_MM, 0.0, len(cells.y) - 1.000001))
    row = (1.0 - (j % 1.0)) * cells.height_mm[:, int(j)] + (j % 1.0) * cells.height_mm[:, int(j) + 1]
    own = (x > 0) if side == "left" else (x < 0)
    at = int(np.argmin(np.where(own, np.abs(x - nipple_body[0]), np.inf)))
    if not row[at] >= FOOT_MM:
        return 0.0
    outwards = 1 if side == "left" else -1
    ends = [_crossing(x, row, own, at, step) for step in (outwards, -outwards)]
    return float(abs(ends[0] - ends[1]))


def _crossing(x: np.ndarray, row: np.ndarray, own: np.ndarray, at: int, step: int) -> float:
    """x (mm) where `row` first falls below FOOT_MM from cell `at` by `step`: between the last cell at or above it
    and the next, linearly; the midline where it stays above it to the last cell of her half (`own`) that way, or
    the outer edge of the grid."""
    ahead = np.arange(at, len(x)) if step > 0 else np.arange(at, -1, -1)
    low = ~(row[ahead] >= FOOT_MM) | ~own[ahead]
    if not low.any():
        return float(x[ahead[-1]])
    last, next_ = ahead[np.argmax(low) - 1], ahead[np.argmax(low)]
    if not own[next_]:
        return 0.0                                        # her midline, between her half's last cell and the other's
    t = (row[last] - FOOT_MM) / (row[last] - row[next_])
    return float(x[last] + t * (x[next_] - x[last]))
