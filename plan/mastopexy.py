"""Lift (mastopexy): one breast raised so that its nipple comes to a chosen height, its volume kept.

Measured as her volume is (`plan.breast_volume`, `plan.skin_lift`), in her body frame (x her left, y up, the
sternal notch the origin):

1. **The target**: the nipple's new height, chosen as a surgeon chooses it: a sternal-notch-to-nipple distance
   (`to_notch_distance`), a height above her inframammary fold or her other nipple's height (`nipple_height`).
2. **The breast raised**: over her footprint, her skin rises by δ · w (δ the nipple's rise) and carries its height
   above the chest wall with it (each cell takes the height of the skin that rises to it): w is 1 from the nipple
   down (the lower pole and the nipple rise whole, which is what tightens the lower pole against the fold) and falls
   to 0 at the footprint's upper border with a C² step (the upper chest stays). The fold rises with the breast.
3. **Volume kept**: the raised heights are then scaled so that her volume on her skin is as before, exactly.
4. **Her skin moved**: each point of her skin moves up by δ · w · f where it lies, and forward or back by the change
   of the surface's height between its old place and its new one, so that the areola travels with the nipple (that
   move fading where her skin, before or after, turns from ahead, STEEP_FADE). f rises from 0 at her footprint's
   border to 1 at her areola with a C² step, so that her skin is drawn whole: the skin at the footprint's border stays
   where the chest beyond it does, and the lower pole's skin stretches over the band the breast rose from, landing on
   the planned surface there.

A target at or below her nipple, or more than MAX_RISE of the way from her nipple to her footprint's upper border
(beyond what a lift can reach: above it her breast has no skin left to bring), is refused in a sentence.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from breastplan import BadInputError, transform_points

from .breast_volume import CELL_MM, BreastVolumes, SkinCells
from .skin_lift import SkinLift, facing, scaled, up_the_breast
from .surface import smoothstep

STEEP_FADE = 2.0
"""Her skin's move forward or back is scaled by min(1, STEEP_FADE · cos² of its tilt from ahead) (`skin_lift.facing`),
where it lies or where it rises to, whichever is steeper: whole up to 45°, fading to none on skin seen edge-on. At the
side of her breast a height field holds her skin poorly, and a point risen a few millimetres would otherwise take a
height tens of millimetres away, into her or out of her."""
MAX_RISE = 0.6
"""A lift raises the nipple at most this share of the way to her footprint's upper border above it."""
FADE_MM = 15.0
"""The least distance inside her footprint's border over which her skin's rise fades to none (mm)."""
AREOLA_MM = 15.0
"""Her skin within this distance of the nipple rises with it whole (mm)."""


@dataclass(frozen=True, eq=False, kw_only=True)
class Mastopexy(SkinLift):
    """One breast lifted: her skin's change of height over the cells (`SkinLift`), how far each cell's skin rises
    (`rise_mm`, along her up axis), and the cells' heights before and the wall, to move her skin."""

    side: str
    rise_mm: float                   # δ: the nipple's rise
    weight: np.ndarray               # (nx, ny) w · f: how much of δ her skin rises by over the cells
    height_mm: np.ndarray            # (nx, ny) her skin's heights above the wall before
    wall_mm: np.ndarray              # (nx, ny)

    def displacement(self, points_mm) -> np.ndarray:
        """(N, 3) how far input-frame points of her skin move (up, and forward or back), input frame, mm."""
        T = self.body_from_input
        body = transform_points(T, np.asarray(points_mm, float).reshape(-1, 3))
        up = self.rise_mm * self.sampled(self.weight, body)
        moved = body[:, :2] + np.column_stack([np.zeros_like(up), up])
        surface = self.wall_mm + self.height_mm
        forward = (self.sampled(surface + self.lift_mm, moved, "nearest") - self.sampled(surface, body, "nearest"))
        steep = [self.sampled(np.minimum(1.0, STEEP_FADE * facing(s)), at, "nearest")
                 for s, at in ((surface, body), (surface + self.lift_mm, moved))]
        forward *= np.minimum(*steep)
        return np.column_stack([np.zeros_like(up), up, forward * (up > 0)]) @ T[:3, :3]   # body → input frame


def carried_up(height_mm: np.ndarray, y_mm: np.ndarray, rise_mm: np.ndarray) -> np.ndarray:
    """(nx, ny) her skin's heights over the cells after each cell's skin rises by `rise_mm` (nx, ny) along its
    column (`y_mm` (ny,) the cells' heights): each cell takes the height of the skin that rises to it, as her skin's
    points move (the map y → y + rise made monotone where a steep fall of the rise would fold it)."""
    to = np.maximum.accumulate(y_mm[None, :] + rise_mm, axis=1)
    return np.stack([np.interp(y_mm, to[i], height_mm[i]) for i in range(len(height_mm))])   # per column


def _inside(cells: SkinCells, mask: np.ndarray, nipple_body) -> np.ndarray:
    """(nx, ny) f over the cells: 0 at the border of the footprint `mask`, rising to 1 with a C² step over the distance
    from the border to AREOLA_MM short of the nipple ((3,) body frame), FADE_MM at least: her areola rises whole."""
    inside = (ndimage.distance_transform_edt(mask) - 0.5) * CELL_MM          # mm from the border, at cell centres
    nipple = inside[np.argmin(np.abs(cells.x - nipple_body[0])), np.argmin(np.abs(cells.y - nipple_body[1]))]
    return np.where(mask, smoothstep(1.0 - inside / max(FADE_MM, nipple - AREOLA_MM)), 0.0)


def nipple_height(nipple_body, *, above_fold_mm: float | None = None, fold_below_nipple_mm: float | None = None,
                  as_nipple_body=None) -> float:
    """The nipple's new height (body frame y, mm) as a surgeon sets it: its height above her fold
    (`fold_below_nipple_mm` below it now), or another nipple's height (`as_nipple_body`, her other side's). For a
    sternal-notch-to-nipple distance, `to_notch_distance`."""
    if above_fold_mm is not None:
        return float(np.asarray(nipple_body, float)[1] - fold_below_nipple_mm + above_fold_mm)
    return float(np.asarray(as_nipple_body, float)[1])


NOTCH_TOLERANCE_MM = 0.1


def to_notch_distance(volumes: BreastVolumes, side: str, nipple_mm, distance_mm: float) -> Mastopexy:
    """Her `side` breast lifted until its nipple ((3,) input frame) lies `distance_mm` from her sternal notch, as
    lifted (it comes forward as it rises onto her breast): secant steps on its height, to NOTCH_TOLERANCE_MM."""
    nipple = volumes.in_body(nipple_mm)

    def chord(height: float) -> tuple[float, Mastopexy]:
        lifted = mastopexy(volumes, side, nipple_mm, height)
        return float(np.linalg.norm(volumes.in_body(lifted(np.asarray(nipple_mm, float)[None])))), lifted

    y = [-float(np.sqrt(max(distance_mm ** 2 - nipple[0] ** 2 - nipple[2] ** 2, 0.0)))]   # raised straight up
    try:
        d = [chord(y[0])]
        y.append(y[0] - (d[0][0] - distance_mm))
        for _ in range(8):
            d.append(chord(y[-1]))
            if abs(d[-1][0] - distance_mm) <= NOTCH_TOLERANCE_MM:
                break
            slope = (d[-1][0] - d[-2][0]) / (y[-1] - y[-2]) if y[-1] != y[-2] else -1.0
            y.append(y[-1] - (d[-1][0] - distance_mm) / (slope if slope < 0 else -1.0))
    except BadInputError:
        raise BadInputError(None, f"asks for her {side} nipple {distance_mm:g} mm from her sternal notch, which no "
                                  f"lift of her breast reaches (it lies {np.linalg.norm(nipple):.0f} mm from it now)") \
            from None
    return d[-1][1]


def mastopexy(volumes: BreastVolumes, side: str, nipple_mm, height_mm: float) -> Mastopexy:
    """Her `side` breast lifted so that its nipple ((3,) input frame) comes to `height_mm` (body frame y,
    `nipple_height`): module docstring."""
    cells, T = volumes.cells, volumes.body_from_input
    nipple = volumes.in_body(nipple_mm)
    rise = float(height_mm - nipple[1])
    if rise <= 0.0:
        raise BadInputError(None, f"gives her {side} nipple {-rise:.0f} mm above the height asked for a lift: "
                                  "no lift raises it there")
    mask = cells.side(side)
    above, top = up_the_breast(cells, side, nipple[1])
    column = int(np.argmin(np.abs(cells.x - nipple[0])))
    if rise > MAX_RISE * (top[column, 0] - nipple[1]):
        raise BadInputError(None, f"asks for her {side} nipple {rise:.0f} mm higher, beyond the "
                                  f"{MAX_RISE * (top[column, 0] - nipple[1]):.0f} mm a lift reaches on her breast")
    weight = np.where(mask, smoothstep(above), 0.0)
    raised = carried_up(cells.height_mm, cells.y, rise * weight)
    change = np.where(mask, raised - cells.height_mm, 0.0)
    after = replace(cells, height_mm=cells.height_mm + change)
    kept = scaled(after, side, np.where(mask, raised, 0.0), mask, cells.volume_cc(side) - after.volume_cc(side))
    return Mastopexy(cells.x, cells.y, change + kept, mask, T, side=side, rise_mm=rise,
                     weight=weight * _inside(cells, mask, nipple),
                     height_mm=cells.height_mm, wall_mm=cells.wall_mm)
