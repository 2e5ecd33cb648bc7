"""The patient's trunk in a frontal view: the body apart from the background, head, neck and arms.

Works in the viewing frame (camera convention: x to the image's right, y down, z away from
the viewer; mm). The body is the nearest large connected cluster (a wall behind her is a
larger one); the trunk is what a disc wider than a neck or an arm keeps of the body's front
silhouette (a morphological opening of its orthographic occupancy map), its largest part.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from breastplan import BadInputError

CELL_MM = 5.0
"""Cell of the orthographic occupancy map."""
CHEST_MM = 450.0
"""The chest: the trunk down to this far below its top."""
LIMB_MM = 65.0
"""Radius of the opening disc: necks and arms are narrower than its diameter, a trunk is wider."""
SIDE_STEP_MM = 30.0
"""A depth step this large between horizontal neighbours parts an arm from the flank it hangs by."""
REGROW_CELLS = 3
"""The trunk regrows this many cells over the steps and the opening's trim."""
SHOULDER_SHARE = 0.6
"""The shoulders are the highest part of the trunk this wide relative to its widest part."""
MIN_TRUNK_MM2 = 200.0 * 200.0
"""A trunk covers at least this frontal area."""


@dataclass(frozen=True)
class Trunk:
    """The trunk's points (mask over the body's points) and its frontal outline."""

    mask: np.ndarray          # (N,) bool over the body's points
    midline_x: float          # mm, x of the trunk's vertical axis at chest height
    top_y: float              # mm, the shoulders: the highest row of the trunk at least
                              # SHOULDER_SHARE as wide as its widest
    width_mm: float           # widest extent across x

    def chest(self, points: np.ndarray) -> np.ndarray:
        """Mask of the points (viewing frame) from above the shoulders to CHEST_MM below them."""
        return points[:, 1] < self.top_y + CHEST_MM


def find_trunk(points: np.ndarray) -> Trunk:
    """The trunk of a body's points (N, 3), viewing frame."""
    ij = np.floor(points[:, :2] / CELL_MM).astype(np.int64)
    x0, y0 = ij.min(0) * CELL_MM
    ij -= ij.min(0)
    shape = tuple(ij.max(0)[::-1] + 1)                      # rows = y, cols = x
    nearest = np.full(shape, np.inf)
    np.minimum.at(nearest, (ij[:, 1], ij[:, 0]), points[:, 2])
    seen = np.isfinite(nearest)
    seen |= ndimage.binary_closing(seen, iterations=2)
    with np.errstate(invalid="ignore"):
        step = np.abs(np.diff(nearest, axis=1)) > SIDE_STEP_MM
    step &= np.isfinite(nearest[:, 1:]) & np.isfinite(nearest[:, :-1])   # a hole is not a step
    occupied = seen.copy()
    occupied[:, 1:] &= ~step
    occupied[:, :-1] &= ~step
    r = int(round(LIMB_MM / CELL_MM))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    opened = ndimage.binary_opening(occupied, structure=xx * xx + yy * yy <= r * r)
    labels, n = ndimage.label(opened)
    if n == 0 or np.bincount(labels.ravel())[1:].max() * CELL_MM**2 < MIN_TRUNK_MM2:
        raise BadInputError(None, "shows no trunk: nothing in view is as wide as a chest")
    trunk = labels == 1 + np.bincount(labels.ravel())[1:].argmax()
    trunk = ndimage.binary_dilation(trunk, iterations=REGROW_CELLS) & seen     # back over the steps it cut
    mask = trunk[ij[:, 1], ij[:, 0]]
    width = trunk.sum(1)
    top = int(np.argmax(width >= SHOULDER_SHARE * width.max()))   # a head or a chin above is narrower
    cols = np.flatnonzero(trunk.any(0))
    xs = np.nonzero(trunk[top: top + int(250 / CELL_MM)])[1]      # the upper 250 mm of the chest
    midline = x0 + (0.5 * (np.percentile(xs, 5) + np.percentile(xs, 95)) + 0.5) * CELL_MM
    return Trunk(mask, float(midline), float(y0 + top * CELL_MM), float((cols[-1] - cols[0] + 1) * CELL_MM))
