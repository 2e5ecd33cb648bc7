"""An operation's change of her skin, over the cells her volume is measured on (`plan.breast_volume`: her skin as
a height field over 5 mm cells of her body frame, above one chest wall, inside each breast's footprint).

The operations (`plan.augmentation`, `plan.lumpectomy`) each shape a rise (or a sinking) of her skin over the
cells; `scaled` sizes it so that her volume on her skin changes by exactly the operation's volume, and
`SkinLift` moves her skin by it: each point at (x, y) along her anterior axis, by the rise there (bilinear
over the cells).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage, optimize

from breastplan import transform_points

from .breast_volume import CELL_MM, SkinCells


@dataclass(frozen=True, eq=False)
class SkinLift:
    """How far an operation moves her skin along her anterior axis over her skin's cells (body frame, x her left,
    y up; cell centres `x`, `y`), mm (< 0: it sinks), and the footprint her volume is then measured inside."""

    x: np.ndarray                    # (nx,) cell centres, mm
    y: np.ndarray                    # (ny,)
    lift_mm: np.ndarray              # (nx, ny)
    footprint: np.ndarray            # (nx, ny) bool
    body_from_input: np.ndarray      # (4, 4)

    def heights(self, height_mm: np.ndarray) -> np.ndarray:
        """Her skin's heights above the chest wall over the cells (`SkinCells.height_mm`, mm) after it."""
        return height_mm + self.lift_mm

    @property
    def made_by(self) -> str | None:
        """The file name of the clinic's model that made this operation; None: the built-in model made it."""
        return None

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far input-frame points of her skin move, input frame, mm."""
        body = transform_points(self.body_from_input, np.asarray(points_mm, float).reshape(-1, 3))
        return np.outer(self.sampled(self.lift_mm, body), self.body_from_input[2, :3])   # along her anterior axis

    def sampled(self, field: np.ndarray, xy: np.ndarray, mode: str = "constant") -> np.ndarray:
        """`field` (nx, ny) over the cells, bilinear at body-frame points' (x, y) ((N, 2+)); 0 off the cells, or
        (mode "nearest") the nearest cell's."""
        at = np.stack([(xy[:, 0] - self.x[0]) / CELL_MM, (xy[:, 1] - self.y[0]) / CELL_MM])
        return ndimage.map_coordinates(field, at, order=1, mode=mode, cval=0.0)

    def __call__(self, points_mm) -> np.ndarray:
        """Input-frame points (mm) as the operation would move them."""
        points = np.asarray(points_mm, float)
        return points + self.displacement(points).reshape(points.shape)


def facing(surface_mm: np.ndarray) -> np.ndarray:
    """(nx, ny) cos² of her skin's tilt from facing ahead over the cells (`surface_mm`: her skin's anterior coordinate
    over them, body frame, mm): 1 where it faces ahead, towards 0 where it turns to her side."""
    return 1.0 / (1.0 + np.square(np.hypot(*np.gradient(surface_mm, CELL_MM))))


def up_the_breast(cells: SkinCells, side: str, nipple_y_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(nx, ny) how far up each cell lies from the nipple's height (0) to her `side` footprint's upper border in its
    column (1), clipped to 0..1 (a column whose border lies within a cell of the nipple counts a cell); and (nx, 1)
    each column's border (y, mm; −inf off the footprint)."""
    top = np.max(np.where(cells.side(side), cells.y[None, :], -np.inf), axis=1, keepdims=True)
    return np.clip((cells.y[None, :] - nipple_y_mm) / np.maximum(top - nipple_y_mm, CELL_MM), 0.0, 1.0), top


def scaled(cells: SkinCells, side: str, shape_mm: np.ndarray, footprint: np.ndarray, change_cc: float) -> np.ndarray:
    """`shape_mm` (nx, ny) scaled so that her `side` breast's volume on her skin (heights above the wall, those
    above 0, over `footprint`) changes by `change_cc` exactly (< 0: falls)."""
    before = replace(cells, footprint=footprint).volume_cc(side)

    def changed(k: float) -> float:
        return replace(cells, height_mm=cells.height_mm + k * shape_mm, footprint=footprint).volume_cc(side) - before

    if change_cc == 0.0:
        return np.zeros_like(shape_mm)
    one = changed(1.0)
    reach = np.sign(change_cc) * np.sign(one) * abs(change_cc) / max(abs(one), 1e-9)   # k < 0 scales it the other way
    while abs(changed(reach)) < abs(change_cc):               # heights stop at the wall: a sinking saturates
        reach *= 2.0
        if abs(reach) > 1e6:
            raise ValueError(f"her skin cannot change by {change_cc:g} cc over these cells")
    return optimize.brentq(lambda k: changed(k) - change_cc, min(0.0, reach), max(0.0, reach), xtol=1e-12) * shape_mm
