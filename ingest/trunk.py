"""The patient's trunk in a frontal view: the body apart from head, neck, arms and hands.

Works in the viewing frame (camera convention: x to the image's right, y down, z away from
the viewer; mm) on the body's points (the pipeline has removed the background). The trunk
is what a disc wider than a neck or an arm keeps of the body's frontal silhouette (a
morphological opening of its orthographic occupancy map), its largest part; arms hanging by
the flanks are first parted from them at the depth steps they make (docs/isolation.md §2).
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
"""A depth step this large between horizontal neighbours, the lateral one nearer, parts an arm
from the flank it hangs by."""
ARM_EDGE_MM = 40.0
"""… along at least this length down the body (a breast's lower edge is shorter and curved)."""
REGROW_CELLS = 3
"""The trunk regrows this many cells over the steps and the opening's trim."""
SHOULDER_SHARE = 0.6
UPPER_MM = 350.0
"""The shoulders are the highest part of the trunk at least SHOULDER_SHARE as wide as its widest
part within UPPER_MM of its top (lower down, hips and hanging arms may be wider)."""
MIN_TRUNK_MM2 = 200.0 * 200.0
"""A trunk covers at least this frontal area."""
NECK_MM = 180.0
"""A row of the body narrower than this where it crosses the midline is a neck's or a head's (a waist
is wider; between the thighs the midline is empty)."""
HEAD_SEEN_MM = 50.0
"""Her head is seen at one end of the trunk when its narrow rows span this much on that side of the
trunk's middle and twice what they span on the other (a neck cut by the view spans less, and so do
the few narrow rows where the thighs part)."""


@dataclass(frozen=True)
class Trunk:
    """The trunk's points (mask over the body's points) and its frontal outline."""

    mask: np.ndarray          # (N,) bool over the body's points
    midline_x: float          # mm, x of the trunk's vertical axis at chest height
    top_y: float              # mm, the shoulders (see SHOULDER_SHARE)
    head: str | None = None   # where her neck and head are seen: "above" or "below" her chest, None if not

    def chest(self, points: np.ndarray) -> np.ndarray:
        """Mask of the points (viewing frame) from above the shoulders to CHEST_MM below them."""
        return points[:, 1] < self.top_y + CHEST_MM


def disc_opening(mask: np.ndarray, radius: float) -> np.ndarray:
    """Morphological opening of a 2-D mask by a disc of `radius` cells (outside the mask is
    empty), by two Euclidean distance transforms: linear in the cells whatever the radius."""
    pad = int(np.ceil(radius)) + 1
    padded = np.pad(mask, pad)
    eroded = ndimage.distance_transform_edt(padded) > radius
    return (ndimage.distance_transform_edt(~eroded) <= radius)[pad:-pad, pad:-pad]


def find_trunk(points: np.ndarray) -> Trunk:
    """The trunk of a body's points (N, 3), viewing frame."""
    ij = np.floor(points[:, :2] / CELL_MM).astype(np.int64)
    lo = ij.min(0)
    ij -= lo
    nearest = np.full(tuple(ij.max(0)[::-1] + 1), np.inf)                 # rows = y, cols = x
    np.minimum.at(nearest, (ij[:, 1], ij[:, 0]), points[:, 2])
    seen = np.isfinite(nearest)
    seen |= ndimage.binary_closing(seen, iterations=2)
    edges = arm_edges(nearest, axis=np.median(ij[:, 0]) + 0.5)
    occupied = seen.copy()
    occupied[:, 1:] &= ~edges
    occupied[:, :-1] &= ~edges
    labels, n = ndimage.label(disc_opening(occupied, LIMB_MM / CELL_MM))
    sizes = np.bincount(labels.ravel())[1:]
    if n == 0 or sizes.max() * CELL_MM**2 < MIN_TRUNK_MM2:
        raise BadInputError(None, "shows no trunk: nothing in view is as wide as a chest")
    trunk = ndimage.binary_dilation(labels == 1 + sizes.argmax(), iterations=REGROW_CELLS) & seen
    top, midline = _landmarks(trunk)
    x0, y0 = lo * CELL_MM
    return Trunk(trunk[ij[:, 1], ij[:, 0]], float(x0 + midline * CELL_MM), float(y0 + top * CELL_MM),
                 _head(seen, trunk, int(midline)))


def arm_edges(nearest: np.ndarray, axis: float) -> np.ndarray:
    """(rows, cols − 1) where an arm hangs in front of the flank, between horizontal cells of the
    nearest-depth map (inf: empty): a step over SIDE_STEP_MM with the cell away from the body's
    `axis` (a column) nearer, running ARM_EDGE_MM down the body. A breast is nearer than what
    lies beside it towards the axis, and its lower edge is short: it makes no edge."""
    lateral_right = np.arange(nearest.shape[1] - 1) + 1 > axis
    with np.errstate(invalid="ignore"):
        outward_nearer = np.where(lateral_right, nearest[:, :-1] - nearest[:, 1:], nearest[:, 1:] - nearest[:, :-1])
    step = np.nan_to_num(outward_nearer, nan=0.0, posinf=0.0, neginf=0.0) > SIDE_STEP_MM   # a hole is not a step
    step = ndimage.binary_dilation(step, structure=np.ones((1, 3), bool))
    return ndimage.binary_opening(step, structure=np.ones((int(ARM_EDGE_MM / CELL_MM), 1), bool))


def _landmarks(trunk: np.ndarray) -> tuple[int, float]:
    """(row of the shoulders, column of the midline) of a trunk mask (see SHOULDER_SHARE; the
    midline is the middle of the outline over the 250 mm below the shoulders)."""
    width = trunk.sum(1)
    first = int(np.argmax(width > 0))
    upper = width[first: first + int(UPPER_MM / CELL_MM)]                  # head, neck and shoulders
    top = first + int(np.argmax(upper >= SHOULDER_SHARE * upper.max()))   # a head or a chin is narrower
    xs = np.nonzero(trunk[top: top + int(250 / CELL_MM)])[1]
    return top, 0.5 * (np.percentile(xs, 5) + np.percentile(xs, 95)) + 0.5


def _head(seen: np.ndarray, trunk: np.ndarray, midline: int) -> str | None:
    """Where the neck and head are (see NECK_MM, HEAD_SEEN_MM) on the occupancy map `seen`, rows = y
    downwards, with the trunk's mask and midline column."""
    runs, _ = ndimage.label(seen, structure=[[0, 0, 0], [1, 1, 1], [0, 0, 0]])      # each row's runs of cells
    crossing = runs[:, midline]
    width = np.bincount(runs.ravel())[crossing] * CELL_MM
    narrow = np.flatnonzero((crossing > 0) & (width < NECK_MM))
    rows = np.flatnonzero(trunk.any(1))
    middle = 0.5 * (np.percentile(rows, 5) + np.percentile(rows, 95))
    above, below = (narrow < middle).sum() * CELL_MM, (narrow > middle).sum() * CELL_MM
    if max(above, below) >= max(HEAD_SEEN_MM, 2.0 * min(above, below)):
        return "above" if above > below else "below"
    return None
