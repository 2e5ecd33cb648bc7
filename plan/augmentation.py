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
4. **Her skin moved** (`plan.skin_lift`): each point of her skin at (x, y) moves forward along her anterior axis
   by the draped thickness there (bilinear over the cells).

An implant whose base would reach within MEDIAL_MM of her midline (over her sternum) is refused: it is wider
than her chest leaves room for.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from breastplan import BadInputError
from breastplan.options import OptionError

from .breast_volume import CELL_MM, FOOT_MM, BreastVolumes
from .implants import Implant
from .skin_lift import SkinLift, scaled

POCKETS = ("subglandular", "submuscular")
SUBMUSCULAR = 0.5
"""Behind the muscle, the implant's thickness is cut by this share at its upper rim (linearly from its centre)."""
DRAPE_MM = 10.0
"""σ of the Gaussian her gland and skin spread the implant's rim over (mm)."""
FOLD_BELOW_WIDTH_MM = 40.0
"""The new fold lies the implant's base width less this below the nipple, unless hers lies lower already (mm)."""
MEDIAL_MM = 15.0
"""An implant's base stays this far from her midline: the edge of her sternum (mm)."""


@dataclass(frozen=True, eq=False, kw_only=True)
class Augmentation(SkinLift):
    """An implant under one breast, and how far it lifts her skin (`SkinLift`: the draped thickness over her
    skin's cells; its footprint, hers grown over the skin the implant raises)."""

    implant: Implant
    pocket: str
    side: str
    centre_mm: np.ndarray            # (2,) the implant's base centre, (x, y) body frame


def augmentation(volumes: BreastVolumes, side: str, nipple_mm, fold_below_nipple_mm: float, implant: Implant,
                 pocket: str = "subglandular") -> Augmentation:
    """`implant` placed under her `side` breast (module docstring): `volumes` her breasts measured on her skin,
    `nipple_mm` (3,) the nipple, input frame; `fold_below_nipple_mm` her fold's depth below it along her up axis.
    OptionError for a pocket not in POCKETS; BadInputError when its base would reach over her sternum."""
    if pocket not in POCKETS:
        raise OptionError("pocket", f"the pocket is {' or '.join(POCKETS)}, not '{pocket}'")
    cells, T = volumes.cells, volumes.body_from_input
    nipple = volumes.in_body(nipple_mm)
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
    raised = half & (cells.height_mm + lift > FOOT_MM)                    # skin the implant brings off the wall
    grown = ndimage.binary_propagation(cells.side(side), mask=cells.side(side) | raised)
    return Augmentation(cells.x, cells.y, scaled(cells, side, lift * grown, grown, implant.volume_cc), grown, T,
                        implant=implant, pocket=pocket, side=side, centre_mm=centre)
