"""Symmetrising: the operation on one breast that best matches her other breast, in volume and nipple height.

From her breasts measured on her skin (`plan.breast_volume`), with `side` the breast to operate on and the
other as the one to match:

* **volume**: a breast smaller by at least the catalogue's smallest implant takes the implant (`plan.implants`,
  moderate profile, in front of the muscle) of the difference (`plan.augmentation`), a smaller difference is left
  (and said: `note`); a breast larger by more than SAME_CC is reduced by it (`plan.reduction`);
* **nipple height**: a nipple lower than the other's by more than SAME_MM is lifted to its height (`plan.mastopexy`,
  after the augmentation, or within the reduction); one higher by more than SAME_MM is said (`note`): no operation
  lowers a nipple.

Each operation changes her volume on her skin by exactly its own volume (inside her footprint grown over what an
implant raises), so the breasts come to the same volume on her skin; the nipple comes to the other's height where
a lift was asked, and otherwise moves as the operations move it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .breast_volume import BreastVolumes
from .implants import VOLUME_CC
from .operated import Operated, operate
from .operation_spec import OperationSpec
from .skin_lift import SkinLift

SAME_CC = 20.0
"""Breasts within this volume of each other (cc) are not changed in volume."""
SAME_MM = 5.0
"""Nipples within this height of each other (mm) are not lifted."""


@dataclass(frozen=True, eq=False)
class Symmetrising:
    """The operations proposed on one breast, as written and made (`operated`), what they bring her to (its nipple
    after, her body frame, mm) against her other breast's volume (cc) and its nipple's mirror image."""

    operated: Operated
    other_volume_cc: float
    nipple_body_mm: np.ndarray
    other_nipple_mirrored_mm: np.ndarray
    note: str | None = None          # what is left unmatched, in words

    @property
    def side(self) -> str:
        return self.operated.side

    @property
    def operations(self) -> tuple[SkinLift, ...]:
        """The operations as made, in order."""
        return self.operated.made

    @property
    def volume_cc(self) -> float:
        """Her breast's volume on her skin after them (cc)."""
        return self.operated.volume_cc

    @property
    def nipple_off_mm(self) -> float:
        """How far her nipple lies, after, from her other nipple's mirror image (mm)."""
        return float(np.linalg.norm(self.nipple_body_mm - self.other_nipple_mirrored_mm))

    def __call__(self, points_mm) -> np.ndarray:
        """Input-frame points (mm) as the operations, in turn, would move them."""
        return self.operated(points_mm)


def symmetrising(volumes: BreastVolumes, nipples: dict, side: str, fold_below_nipple_mm: float,
                 models: dict | None = None) -> Symmetrising:
    """The operations on her `side` breast that match her other one (module docstring), written as a surgeon
    writes them (`plan.operation_spec`) and made (`plan.operated`, by the clinic's `models` where given): `nipples`
    side → (3,) input frame; her fold `fold_below_nipple_mm` below the `side` nipple (where an implant's lower rim
    goes)."""
    other = "right" if side == "left" else "left"
    body = {s: volumes.in_body(n) for s, n in nipples.items()}
    mirrored = body[other] * [-1.0, 1.0, 1.0]
    gap = volumes.sides[other].volume_cc - volumes.sides[side].volume_cc
    lift = mirrored[1] - body[side][1] > SAME_MM
    written, notes = [], []
    if gap >= VOLUME_CC[0]:
        written = [f"augmentation:{min(float(gap), VOLUME_CC[1]):.1f}:moderate"] + (["lift:other"] if lift else [])
    elif gap < -SAME_CC:
        written = [f"reduction:{-gap:.1f}" + (":other" if lift else ":none")]
    else:
        written = ["lift:other"] if lift else []
        if gap > SAME_CC:
            notes.append(f"her {side} breast is {gap:.0f} cc smaller than her {other}, less than the smallest implant "
                         f"({VOLUME_CC[0]:g} cc): left as it is")
    higher = body[side][1] - mirrored[1]
    if higher > SAME_MM:
        notes.append(f"her {side} nipple lies {higher:.0f} mm above her {other}: no operation lowers a nipple (a lift "
                     f"of her {other} breast raises hers: --symmetrise {other})")
    note = "; ".join(notes) or None
    operated = operate(volumes, nipples, side, fold_below_nipple_mm, tuple(map(OperationSpec.parse, written)), models)
    return Symmetrising(operated, volumes.sides[other].volume_cc, volumes.in_body(operated.nipple_mm),
                        mirrored, note)
