"""Augmentation: an implant (`plan.implants`) placed under one breast, and her skin as it would lie over it.

Measured as her volume is (`plan.breast_volume`: her skin as a height field over 5 mm cells of her body frame,
above one chest wall, inside each breast's footprint):

1. **Where**: the implant's base lies on the chest wall, centred under her nipple across her body and with its
   lower rim on her inframammary fold (the fold's height as her ptosis measure finds it), lowered where the
   implant needs it: a surgeon sets the new fold FOLD_BELOW_WIDTH_MM less than the implant's base width below
   the nipple (the rule of thumb of tissue-based implant selection: an 11 cm implant, 7 cm from nipple to fold).
2. **How thick**: the implant's thickness over each cell; behind the muscle (`pocket` "submuscular") the
   pectoralis flattens its upper half, by up to SUBMUSCULAR at its upper rim.
3. **Draped**: her gland and skin do not follow the implant's steep rim: the thickness is spread by a Gaussian of
   σ DRAPE_MM, kept to the skin that then stands FOOT_MM in front of the wall (her footprint grown over what the
   implant raises: `footprint`), and scaled so that her volume on her skin, measured inside that footprint
   (`heights`), grows by the implant's exactly.
4. **Her skin moved**: each point of her skin at (x, y) moves forward along her anterior axis by the draped
   thickness there (bilinear over the cells).

An implant whose base would reach within MEDIAL_MM of her midline (over her sternum) is refused: it is wider
than her chest leaves room for.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage, optimize

from breastplan import BadInputError, transform_points
from breastplan.options import OptionError

from .breast_volume import CELL_MM, FOOT_MM, BreastVolumes
from .implants import Implant

POCKETS = ("subglandular", "submuscular")
SUBMUSCULAR = 0.5
"""Behind the muscle, the implant's thickness is cut by this share at its upper rim (linearly from its centre)."""
DRAPE_MM = 10.0
"""σ of the Gaussian her gland and skin spread the implant's rim over (mm)."""
FOLD_BELOW_WIDTH_MM = 40.0
"""The new fold lies the implant's base width less this below the nipple, unless hers lies lower already (mm)."""
MEDIAL_MM = 15.0
"""An implant's base stays this far from her midline: the edge of her sternum (mm)."""


@dataclass(frozen=True, eq=False)
class Augmentation:
    """An implant under one breast, and how far it lifts her skin: `lift_mm` over her skin's cells (body frame,
    x her left, y up; cell centres `x`, `y`), along her anterior axis."""

    implant: Implant
    pocket: str
    side: str
    centre_mm: np.ndarray            # (2,) the implant's base centre, (x, y) body frame
    x: np.ndarray                    # (nx,) cell centres, mm
    y: np.ndarray                    # (ny,)
    lift_mm: np.ndarray              # (nx, ny) the draped thickness: her skin's rise over each cell
    footprint: np.ndarray            # (nx, ny) bool: her footprint grown over the skin the implant raises
    body_from_input: np.ndarray      # (4, 4)

    def heights(self, height_mm: np.ndarray) -> np.ndarray:
        """Her skin's heights above the chest wall over the cells (`SkinCells.height_mm`, mm) with the implant."""
        return height_mm + self.lift_mm

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far input-frame points of her skin move, input frame, mm."""
        body = transform_points(self.body_from_input, np.asarray(points_mm, float).reshape(-1, 3))
        at = np.stack([(body[:, 0] - self.x[0]) / CELL_MM, (body[:, 1] - self.y[0]) / CELL_MM])
        lift = ndimage.map_coordinates(self.lift_mm, at, order=1, mode="constant", cval=0.0)
        return np.outer(lift, self.body_from_input[2, :3])             # along her anterior axis, input frame

    def __call__(self, points_mm) -> np.ndarray:
        """Input-frame points (mm) as the implant would move them."""
        points = np.asarray(points_mm, float)
        return points + self.displacement(points).reshape(points.shape)


def augmentation(volumes: BreastVolumes, side: str, nipple_mm, fold_below_nipple_mm: float, implant: Implant,
                 pocket: str = "subglandular") -> Augmentation:
    """`implant` placed under her `side` breast (module docstring): `volumes` her breasts measured on her skin,
    `nipple_mm` (3,) the nipple, input frame; `fold_below_nipple_mm` her fold's depth below it along her up axis.
    OptionError for a pocket not in POCKETS; BadInputError when its base would reach over her sternum."""
    if pocket not in POCKETS:
        raise OptionError("pocket", f"the pocket is {' or '.join(POCKETS)}, not '{pocket}'")
    cells, T = volumes.cells, volumes.body_from_input
    nipple = transform_points(T, np.asarray(nipple_mm, float)[None])[0]
    R = implant.width_mm / 2.0
    fold = max(fold_below_nipple_mm, implant.width_mm - FOLD_BELOW_WIDTH_MM)
    centre = np.array([nipple[0], nipple[1] - fold + R])
    X, Y = np.meshgrid(cells.x - centre[0], cells.y - centre[1], indexing="ij")
    thick = implant.thickness(X, Y)
    if pocket == "submuscular":
        thick *= 1.0 - SUBMUSCULAR * np.clip(Y / R, 0.0, 1.0)
    inner = abs(centre[0]) - R
    if inner < MEDIAL_MM:
        raise BadInputError(None, f"gives an implant {implant.width_mm:.0f} mm wide under her {side} breast, whose "
                                  f"base would reach {inner:.0f} mm from her midline, over her sternum (at least "
                                  f"{MEDIAL_MM:g} mm): choose a narrower implant")
    half = (cells.x > 0 if side == "left" else cells.x < 0)[:, None]
    lift = ndimage.gaussian_filter(thick, DRAPE_MM / CELL_MM, mode="constant") * half
    grown = ndimage.binary_propagation(cells.side(side), mask=cells.side(side) | (half & (cells.height_mm + lift
                                                                                             > FOOT_MM)))
    lift *= grown
    before = replace(cells, footprint=grown).volume_cc(side)

    def added(k: float) -> float:                   # cc her volume grows by with k times the draped thickness
        return replace(cells, height_mm=cells.height_mm + k * lift, footprint=grown).volume_cc(side) - before

    k = optimize.brentq(lambda k: added(k) - implant.volume_cc, 0.0, 4.0 * implant.volume_cc / max(added(1.0), 1e-9),
                        xtol=1e-12)
    return Augmentation(implant, pocket, side, centre, cells.x, cells.y, k * lift, grown, T)
