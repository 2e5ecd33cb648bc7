"""Reduction: V cc resected from one breast (or down to a volume), with the lift it needs.

Measured as her volume is (`plan.breast_volume`, `plan.skin_lift`):

1. **The resection**: tissue is taken where a reduction takes it, most from the lower pole: her skin's height
   above the chest wall falls in proportion to itself (the breast's shape kept), fully from the nipple down and
   by UPPER_SHARE of that at the footprint's upper border (linearly between), scaled so that her volume on her
   skin falls by V exactly.
2. **The lift**: where a nipple height is asked, the reduced breast is then lifted to it (`plan.mastopexy`, its
   volume kept).

A resection no smaller than her breast is refused in a sentence.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from breastplan import BadInputError

from .breast_volume import BreastVolumes
from .mastopexy import Mastopexy, mastopexy
from .skin_lift import SkinLift, scaled, up_the_breast

UPPER_SHARE = 0.3
"""At the footprint's upper border, a reduction takes this share of what it takes from the nipple down."""


@dataclass(frozen=True, eq=False, kw_only=True)
class Reduction(SkinLift):
    """A resection from one breast (`SkinLift`: her skin's fall over the cells, then the lift's change), and the
    lift after it, if any."""

    side: str
    volume_cc: float
    resection: SkinLift
    lift: Mastopexy | None

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far input-frame points of her skin move (the resection, then the lift), input frame, mm."""
        points = np.asarray(points_mm, float).reshape(-1, 3)
        shift = self.resection.displacement(points)
        return shift if self.lift is None else shift + self.lift.displacement(points + shift)


def reduction(volumes: BreastVolumes, side: str, nipple_mm, *, volume_cc: float | None = None,
              to_volume_cc: float | None = None, nipple_height_mm: float | None = None) -> Reduction:
    """Her `side` breast reduced by `volume_cc` (or to `to_volume_cc`), then lifted so that its nipple ((3,) input
    frame) comes to `nipple_height_mm` (body frame y) if given: module docstring."""
    cells, T = volumes.cells, volumes.body_from_input
    breast = volumes.sides[side].volume_cc
    removed = float(volume_cc if volume_cc is not None else breast - to_volume_cc)
    if not 0.0 < removed < breast:
        raise BadInputError(None, f"gives a resection of {removed:g} cc from her {side} breast of {breast:.0f} cc on "
                                  "her skin: a reduction takes more than nothing and less than the breast")
    nipple = volumes.in_body(nipple_mm)
    mask = cells.side(side)
    above, _ = up_the_breast(cells, side, nipple[1])
    shape = -np.where(mask, np.clip(cells.height_mm, 0.0, None) * (1.0 - (1.0 - UPPER_SHARE) * above), 0.0)
    fall = scaled(cells, side, shape, mask, -removed)
    resection = SkinLift(cells.x, cells.y, fall, mask, T)
    lift = None
    if nipple_height_mm is not None:
        reduced = replace(volumes, cells=replace(cells, height_mm=cells.height_mm + fall))
        lift = mastopexy(reduced, side, resection(np.asarray(nipple_mm, float)[None])[0], nipple_height_mm)
    change = fall if lift is None else fall + lift.lift_mm
    return Reduction(cells.x, cells.y, change, mask, T, side=side, volume_cc=removed, resection=resection, lift=lift)
