"""Lumpectomy (breast-conserving surgery): V cc excised from one breast at a clock position and a distance from
the nipple, and the breast as it heals.

Measured as her volume is (`plan.breast_volume`, `plan.skin_lift`):

1. **Where**: the excision's centre lies `distance_mm` from the nipple towards `clock` (1–12, as the surgeon faces
   her: 12 up; 3 o'clock is towards her left, so lateral on her left breast and medial on her right).
2. **The volume lost**: healed, the breast is smaller by what was removed. Her skin sinks over the site by a
   Gaussian of σ = √(ρ² + d²), ρ the radius of a ball of V (the cavity the excision leaves) and d the cavity's
   depth beneath her skin if given (a deeper cavity is felt over a wider patch of skin, less deeply), scaled so
   that her volume on her skin, inside her footprint, falls by V exactly (a skin never sinks behind the chest
   wall). A depth at which her breast, there, is not as thick as the cavity needs (d + ρ) is refused.
3. **The deformity healing brings**: the scar contracts and draws the breast towards the cavity. Each point of
   her skin at distance r from its centre moves towards it by PULL · f · min(r, ρ) · exp(−(r − ρ)₊ / REACH_MM),
   f the excised fraction of her breast's volume, ρ the cavity's radius: her nipple deviates towards the defect,
   more for a larger fraction and for a nearer defect. PULL and REACH_MM are judgements, not calibrated on
   patients.

A resection no smaller than her breast, or centred more than EDGE_MM outside her footprint, is refused. Past
WARN_FRACTION of her breast's volume, `warning` says so in a surgeon's words: the fraction the literature
associates with a poor cosmetic result (Cochrane et al. 2003).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from breastplan import BadInputError, transform_points
from breastplan.options import OptionError

from .breast_volume import BreastVolumes
from .skin_lift import SkinLift, scaled

PULL = 2.0
"""How strongly the healing scar draws her skin towards the cavity, per unit of excised fraction."""
REACH_MM = 40.0
"""How far from the cavity the pull is felt (its e-folding distance beyond the cavity, mm)."""
EDGE_MM = 40.0
"""An excision centred this far outside her footprint (which a camera in front of her sees short of her breast's
lateral edge) is still on her breast; farther, it is not (mm)."""
WARN_FRACTION = 0.20
"""An excision of more than this share of the breast's volume is said to risk a poor cosmetic result."""


@dataclass(frozen=True, eq=False, kw_only=True)
class Lumpectomy(SkinLift):
    """An excision from one breast and the breast healed (`SkinLift`: her skin's sinking over the cells), with the
    scar's pull towards the cavity."""

    side: str
    volume_cc: float
    fraction: float                  # of her breast's volume on her skin
    centre_mm: np.ndarray            # (2,) the excision's centre, (x, y) body frame
    radius_mm: float                 # the cavity's: a ball of volume_cc

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far input-frame points of her skin move (sinking and pull), input frame, mm."""
        points = np.asarray(points_mm, float).reshape(-1, 3)
        body = transform_points(self.body_from_input, points)
        towards = self.centre_mm - body[:, :2]
        r = np.linalg.norm(towards, axis=1)
        pull = PULL * self.fraction * np.minimum(r, self.radius_mm) * np.exp(-np.clip(r - self.radius_mm, 0, None)
                                                                             / REACH_MM)
        on_side = (body[:, 0] > 0) if self.side == "left" else (body[:, 0] < 0)
        step = np.where(on_side[:, None], towards * (pull / np.maximum(r, 1e-9))[:, None], 0.0)
        return super().displacement(points) + step @ self.body_from_input[:2, :3]   # (x, y) body → input frame

    @property
    def warning(self) -> str | None:
        """A surgeon's warning where the excised fraction passes WARN_FRACTION, else None."""
        if self.fraction <= WARN_FRACTION:
            return None
        return (f"excising {100 * self.fraction:.0f} % of her {self.side} breast's volume: beyond the "
                f"{100 * WARN_FRACTION:.0f} % associated with a poor cosmetic result; expect her nipple to deviate "
                "towards the defect (pBRA) and her volume asymmetry to grow")


def clock_direction(clock: float) -> np.ndarray:
    """(2,) the unit direction of a clock position (as the surgeon faces her), in her body frame (x her left, y up)."""
    angle = np.radians(30.0 * clock)
    return np.array([np.sin(angle), np.cos(angle)])


def lumpectomy(volumes: BreastVolumes, side: str, nipple_mm, volume_cc: float, clock: float,
               distance_mm: float, depth_mm: float | None = None) -> Lumpectomy:
    """`volume_cc` excised from her `side` breast at `clock`, `distance_mm` from its nipple ((3,) input frame), its
    centre `depth_mm` beneath her skin if given: module docstring. OptionError for a clock outside 1–12 or a
    negative size; BadInputError for a resection no smaller than her breast, centred outside it, or deeper than
    her breast there."""
    if not (0.0 < clock <= 12.0 and volume_cc > 0.0 and distance_mm >= 0.0 and (depth_mm is None or depth_mm > 0)):
        raise OptionError("lumpectomy", "a lumpectomy takes a positive volume (cc), a clock position 1–12, a "
                                        "distance from the nipple (mm) and, if given, a positive depth (mm)")
    cells, T = volumes.cells, volumes.body_from_input
    breast = volumes.sides[side].volume_cc
    if volume_cc >= breast:
        raise BadInputError(None, f"gives a resection of {volume_cc:g} cc, no smaller than her {side} breast "
                                  f"({breast:.0f} cc on her skin)")
    nipple = volumes.in_body(nipple_mm)
    centre = nipple[:2] + distance_mm * clock_direction(clock)
    mask = cells.side(side)
    X, Y = np.meshgrid(cells.x - centre[0], cells.y - centre[1], indexing="ij")
    if not mask.any() or np.hypot(X, Y)[mask].min() > EDGE_MM:
        raise BadInputError(None, f"gives an excision {distance_mm:g} mm from her {side} nipple at {clock:g} o'clock, "
                                  f"outside her breast (over {EDGE_MM:g} mm from its footprint)")
    radius = float((3.0 * 1000.0 * volume_cc / (4.0 * np.pi)) ** (1.0 / 3.0))
    if depth_mm is not None:
        at = np.unravel_index(np.argmin(np.where(mask, np.hypot(X, Y), np.inf)), X.shape)
        thick = float(cells.height_mm[at])
        if depth_mm + radius > thick:
            raise BadInputError(None, f"gives an excision {depth_mm:g} mm deep at {clock:g} o'clock on her {side} "
                                      f"breast, where it is {thick:.0f} mm thick: a cavity of {volume_cc:g} cc, {radius:.0f} mm in "
                                      "radius, centred there would reach behind it")
    spread = float(np.hypot(radius, depth_mm or 0.0))
    sink = -np.exp(-(X * X + Y * Y) / (2.0 * spread * spread)) * mask
    return Lumpectomy(cells.x, cells.y, scaled(cells, side, sink, mask, -volume_cc), mask, T, side=side,
                      volume_cc=float(volume_cc), fraction=float(volume_cc / breast), centre_mm=centre,
                      radius_mm=radius)
