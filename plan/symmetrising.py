"""Symmetrising: the operation on one breast that best matches her other breast, in volume and nipple height.

From her breasts measured on her skin (`plan.breast_volume`), with `side` the breast to operate on and the
other as the one to match:

* **volume**: a breast smaller by at least the catalogue's smallest implant takes the implant (`plan.implants`,
  moderate profile, in front of the muscle) of the difference (`plan.augmentation`), a smaller difference is left
  (and said: `note`); a breast larger by more than SAME_CC is reduced by it (`plan.reduction`);
* **nipple height**: a nipple lower than the other's by more than SAME_MM is lifted to its height (`plan.mastopexy`,
  after the augmentation, or within the reduction).

Each operation changes her volume on her skin by exactly its own volume (inside her footprint grown over what an
implant raises), so the breasts come to the same volume on her skin; the nipple comes to the other's height where
a lift was asked, and otherwise moves as the operations move it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from breastplan import transform_points

from .augmentation import augmentation
from .breast_volume import BreastVolumes
from .implants import VOLUME_CC, Implant
from .mastopexy import mastopexy
from .reduction import reduction
from .skin_lift import SkinLift

SAME_CC = 20.0
"""Breasts within this volume of each other (cc) are not changed in volume."""
SAME_MM = 5.0
"""Nipples within this height of each other (mm) are not lifted."""


@dataclass(frozen=True, eq=False)
class Symmetrising:
    """The operations proposed on `side`, in order, and what they bring her to: its volume on her skin (cc) and its
    nipple (her body frame, mm) against her other breast's volume and its nipple's mirror image."""

    side: str
    operations: tuple[SkinLift, ...]
    volume_cc: float
    other_volume_cc: float
    nipple_body_mm: np.ndarray
    other_nipple_mirrored_mm: np.ndarray
    note: str | None = None          # what is left unmatched, in words

    @property
    def nipple_off_mm(self) -> float:
        """How far her nipple lies, after, from her other nipple's mirror image (mm)."""
        return float(np.linalg.norm(self.nipple_body_mm - self.other_nipple_mirrored_mm))

    def __call__(self, points_mm) -> np.ndarray:
        """Input-frame points (mm) as the operations, in turn, would move them."""
        points = np.asarray(points_mm, float)
        for operation in self.operations:
            points = operation(points)
        return points


def symmetrising(volumes: BreastVolumes, nipples: dict, side: str, fold_below_nipple_mm: float) -> Symmetrising:
    """The operations on her `side` breast that match her other one (module docstring): `nipples` side → (3,)
    input frame; her fold `fold_below_nipple_mm` below the `side` nipple (where an implant's lower rim goes)."""
    other = "right" if side == "left" else "left"
    T = volumes.body_from_input
    body = {s: transform_points(T, np.asarray(n, float)[None])[0] for s, n in nipples.items()}
    mirrored = body[other] * [-1.0, 1.0, 1.0]
    gap = volumes.sides[other].volume_cc - volumes.sides[side].volume_cc
    lift_to = float(mirrored[1]) if mirrored[1] - body[side][1] > SAME_MM else None
    operations, cells, nipple, note = [], volumes.cells, np.asarray(nipples[side], float), None
    if gap >= VOLUME_CC[0]:
        implant = Implant.of(min(float(gap), VOLUME_CC[1]), "moderate")
        operations.append(augmentation(volumes, side, nipple, fold_below_nipple_mm, implant))
    elif gap > SAME_CC:
        note = (f"her {side} breast is {gap:.0f} cc smaller than her {other}, less than the smallest implant "
                f"({VOLUME_CC[0]:g} cc): left as it is")
    elif gap < -SAME_CC:
        operations.append(reduction(volumes, side, nipple, volume_cc=-gap, nipple_height_mm=lift_to))
        lift_to = None
    for done in operations:
        cells = replace(cells, height_mm=done.heights(cells.height_mm), footprint=cells.footprint | done.footprint)
        nipple = done(nipple[None])[0]
    if lift_to is not None:
        lift = mastopexy(replace(volumes, cells=cells), side, nipple, lift_to)
        operations.append(lift)
        cells, nipple = replace(cells, height_mm=lift.heights(cells.height_mm)), lift(nipple[None])[0]
    return Symmetrising(side, tuple(operations), cells.volume_cc(side) if operations else volumes.sides[side].volume_cc,
                        volumes.sides[other].volume_cc, transform_points(T, nipple[None])[0], mirrored, note)
