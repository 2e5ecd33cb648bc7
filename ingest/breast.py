"""Breast isolation and the breast frame (docs/model.md §1) from a torso cloud and its chest wall.

All inputs are in the viewing frame (camera convention: x to the image's right = the
patient's left, y down, z away from the viewer; mm). A mound is a basin of the height of
coarse voxels above the chest wall; the breasts are the mounds placed and shaped as breasts
are (docs/isolation.md); a breast is the fine points in front of the chest wall under
its mound (refitted, the mound and its skirt left out). The breast frame has its origin at the foot of
the nipple on the chest wall (see `breast_frame`), z along the chest normal (anterior), y
superior.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from breastplan import BadInputError
from breastplan.chest_wall import ChestWall

from .chest_wall import fit_chest_wall
from .nipple import DISC_MM, find_apex, find_nipple

MOUND_MM = 10.0
"""Coarse voxels at least this far in front of the chest wall form mounds."""
MIN_PEAK_MM = 12.0
"""A mound must rise at least this far: smaller bumps are not breasts."""
MERGE_MM = 6.0
"""Basins whose saddle lies within this of the lower summit are one mound."""
OFF_MIDLINE_MM = (35.0, 140.0)
"""A breast mound's centre lies this far from the trunk's midline (a chin or a belly nearer,
a shoulder further; docs/isolation.md §4 gives what the test bodies measure) …"""
BELOW_TOP_MM = (85.0, 340.0)
"""… and this far below the shoulders (a shoulder's own mound higher) …"""
RISE = (0.5, 3.0)
"""… and rises this share of its footprint's radius (`Mound.rise`; a back's shoulder blades rise
less, a hand standing out from the hips far more). Small flat breasts rise a little less …"""
LOW_RISE = 0.4
"""… so a mound rising from this share up is a breast too when no mound on its side rises as
breasts do (`Mound.low`), but only if a nipple stands on it …"""
LOW_NIPPLE_MM = 2.0
"""… its nipple-areola disc raised this far over the breast's smooth surface (on a back's shoulder
blades, skin noise gives 'discs' of about 1 mm)."""
MAX_LEVEL_MM = 110.0
"""The two breasts' centres differ in height by at most this much."""
PAIR_MM = (100.0, 420.0)
"""… and lie this far apart across the body."""
WALL_DEGREE, WALL_REACH_MM = 3, 120.0
"""Degree of the chest wall under a breast, and how far beyond its mound's radius it is fitted."""
SKIRT_MM = 20.0
"""The skirt of a mound, left out of the wall under it: the skin within this (x, y) distance
of the mound's voxels, still lifted by the breast though under MOUND_MM high."""
NIPPLE_OFF_MM = 25.0
"""A given nipple lies within this of its mound's skin (the nearest of its 10 mm voxels' centroids)."""
CROP_MM = 2.0
"""Breast points lie at least this far in front of the chest wall."""
UP_VIEW = np.array([0.0, -1.0, 0.0])
"""Superior in the viewing frame (image up)."""


@dataclass(frozen=True)
class Mound:
    """A breast mound found on the coarse voxels."""

    side: str                  # "left" | "right" (patient's)
    centre: np.ndarray         # (2,) height-weighted x, y, mm
    radius: float              # mm, in x, y
    peak_mm: float             # greatest height above the chest wall
    voxels: np.ndarray         # (M, 3) the mound's voxel centroids
    footprint_mm2: float       # area it covers seen from the viewer
    low: bool = False          # taken below RISE: a breast only if a nipple stands on it (LOW_NIPPLE_MM)

    @property
    def rise(self) -> float:
        """Peak height over the radius of a disc of the mound's footprint: how steeply it stands out."""
        return self.peak_mm / np.sqrt(self.footprint_mm2 / np.pi)


def find_mounds(voxels: np.ndarray, wall: ChestWall, midline_x: float, size: float) -> list[Mound]:
    """Mounds among voxel centroids (size mm), largest volume first: the basins of the height
    above the chest wall (a breast and a shoulder beside it are two, parted at their saddle)."""
    h = wall.height(voxels)
    high = np.flatnonzero(h > MOUND_MM)
    if len(high) < 3:
        return []
    labels = height_basins(voxels[high], h[high], size)
    mounds = []
    for k in range(1, labels.max() + 1):
        pts, hk = voxels[high][labels == k], h[high][labels == k]
        if len(pts) < 6 or hk.max() < MIN_PEAK_MM:
            continue
        centre = (pts[:, :2] * hk[:, None]).sum(0) / hk.sum()
        radius = float(np.linalg.norm(pts[:, :2] - centre, axis=1).max() + size)
        footprint = len(np.unique(np.floor(pts[:, :2] / size), axis=0)) * size * size
        mounds.append((float(hk.sum()), Mound("left" if centre[0] > midline_x else "right", centre, radius,
                                              float(hk.max()), pts, footprint)))
    return [m for _, m in sorted(mounds, key=lambda vm: -vm[0])]


def height_basins(points: np.ndarray, height: np.ndarray, size: float) -> np.ndarray:
    """(N,) basin label (1…) of points (x, y) by height: each cell of the height map (cells of
    `size` mm) climbs its steepest ascent to a summit; basins whose saddle lies within MERGE_MM
    of the lower summit are merged (a breast has one summit, whatever the noise)."""
    ij = np.floor(points[:, :2] / size).astype(np.int64)          # the voxels' own grid
    ij += 1 - ij.min(0)                                               # a border of empty cells
    H = np.full(tuple(ij.max(0) + 2), -np.inf)
    np.maximum.at(H, (ij[:, 0], ij[:, 1]), height)
    cols = H.shape[1]
    flat = H.ravel()
    inner = np.flatnonzero(np.isfinite(flat))
    steps = np.array([di * cols + dj for di in (-1, 0, 1) for dj in (-1, 0, 1)])
    up = inner[:, None] + steps[None, :]
    ascent = np.arange(flat.size)
    ascent[inner] = up[np.arange(len(inner)), np.argmax(flat[up], axis=1)]
    while True:                                           # pointer jumping: each cell to its summit
        jumped = ascent[ascent]
        if np.array_equal(jumped, ascent):
            break
        ascent = jumped
    _, label = np.unique(ascent[inner], return_inverse=True)
    basins = np.zeros(flat.size, np.int64)
    basins[inner] = label + 1
    basins = _merge_shallow(basins.reshape(H.shape), H)
    return basins[ij[:, 0], ij[:, 1]]


def _merge_shallow(basins: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Basins merged across saddles within MERGE_MM of the lower summit, highest saddles first
    (a merged basin's summit is its highest), so that noise never chains two mounds."""
    k = int(basins.max())
    peak = np.full(k + 1, -np.inf)
    np.maximum.at(peak, basins.ravel(), H.ravel())
    saddle = np.full((k + 1, k + 1), -np.inf)
    for a, b, ha, hb in ((basins[1:], basins[:-1], H[1:], H[:-1]), (basins[:, 1:], basins[:, :-1], H[:, 1:], H[:, :-1])):
        touch = (a > 0) & (b > 0) & (a != b)
        np.maximum.at(saddle, (np.minimum(a, b)[touch], np.maximum(a, b)[touch]), np.minimum(ha, hb)[touch])
    root = np.arange(k + 1)

    def find(i):
        while root[i] != i:
            i = root[i]
        return i
    pairs = np.argwhere(np.isfinite(saddle))
    for a, b in pairs[np.argsort(-saddle[pairs[:, 0], pairs[:, 1]])]:   # one edge per touching pair of basins
        ra, rb = find(a), find(b)
        if ra != rb and saddle[a, b] >= min(peak[ra], peak[rb]) - MERGE_MM:
            root[rb] = ra
            peak[ra] = max(peak[ra], peak[rb])
    roots = np.array([find(i) for i in range(k + 1)])
    _, compact = np.unique(roots, return_inverse=True)
    return compact[basins]


def find_breasts(mounds: list[Mound], midline_x: float, top_y: float) -> dict[str, Mound]:
    """Side → breast mound. A breast sits off the trunk's midline, below its shoulders, and
    rises as breasts do (RISE); of such mounds, the largest pair (by summed volume) level with
    each other and as far apart as breasts are is taken, else the largest one on each side (a
    patient may have one breast). A side with none is searched again from LOW_RISE up, and what
    that finds is marked `low`.

    A chin or a belly lies on the midline, a shoulder high and lateral, a hand on the hip
    stands out steeply, and a back's shoulder blades are broad and low: they are never taken
    (a low one only until the search for its nipple, which finds none)."""
    breasts = _breasts(mounds, midline_x, top_y, RISE)
    if len(breasts) == 2:
        return breasts
    low = _breasts(mounds, midline_x, top_y, (LOW_RISE, RISE[1]))
    return {side: breasts.get(side) or dataclasses.replace(low[side], low=True)
            for side in ("left", "right") if side in breasts or side in low}


def _breasts(mounds: list[Mound], midline_x: float, top_y: float, rises: tuple[float, float]) -> dict[str, Mound]:
    x = np.array([m.centre[0] - midline_x for m in mounds]).reshape(-1)
    y = np.array([m.centre[1] for m in mounds]).reshape(-1)
    rise = np.array([m.rise for m in mounds]).reshape(-1)
    size = np.array([m.voxels.shape[0] * m.peak_mm for m in mounds]).reshape(-1)
    ok = (_within(np.abs(x), OFF_MIDLINE_MM) & _within(y - top_y, BELOW_TOP_MM) & _within(rise, rises))
    left, right = np.flatnonzero(ok & (x > 0)), np.flatnonzero(ok & (x < 0))
    L, R = (a.ravel() for a in np.meshgrid(left, right, indexing="ij"))
    apart = x[L] - x[R]
    fits = (np.abs(y[L] - y[R]) <= MAX_LEVEL_MM) & (apart >= PAIR_MM[0]) & (apart <= PAIR_MM[1])
    if fits.any():
        best = np.argmax(np.where(fits, size[L] + size[R], -np.inf))
        return {"left": mounds[L[best]], "right": mounds[R[best]]}
    return {side: mounds[idx[np.argmax(size[idx])]] for side, idx in (("left", left), ("right", right)) if len(idx)}


def _within(values: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
    return (values >= bounds[0]) & (values <= bounds[1])


def choose_mound(mounds: list[Mound], nipple: np.ndarray | None, given: tuple | None = None) -> Mound:
    """The mound under a given nipple (viewing frame; `given`: as the user gave it, for the error),
    else the largest one (of those in a region of interest)."""
    if nipple is not None:
        near = [m for m in mounds if np.linalg.norm(m.centre - nipple[:2]) <= m.radius]
        where = "" if given is None else " " + ",".join(format(float(v), "g") for v in given) + " (camera mm)"
        if not near:
            raise BadInputError(None, f"no breast mound lies under the given nipple{where}")
        off = [float(np.min(np.linalg.norm(m.voxels - nipple, axis=1))) for m in near]
        if min(off) > NIPPLE_OFF_MM:
            raise BadInputError(None, f"the given nipple{where} lies {min(off):.0f} mm off the skin of the breast mound "
                                      f"under it (at most {NIPPLE_OFF_MM:g} mm)")
        return near[int(np.argmin(off))]
    if not mounds:
        raise BadInputError(None, "no breast mound found in the region of interest")
    return mounds[0]


def chest_wall_under(voxels: np.ndarray, mound: Mound, wall: ChestWall) -> ChestWall:
    """The chest wall under one mound: a cubic height field refitted on the chest within
    WALL_REACH_MM of the mound's footprint, the mound and its skirt (within SKIRT_MM of it) left
    out. A quadratic fitted on a narrow ring bent with whatever the mound's size left in the
    ring, and a bigger breast stood on a raised wall (docs/isolation.md §5)."""
    off, _ = cKDTree(mound.voxels[:, :2]).query(voxels[:, :2])
    near = np.linalg.norm(voxels[:, :2] - mound.centre, axis=1) < mound.radius + WALL_REACH_MM
    return fit_chest_wall(voxels, WALL_DEGREE, mask=near & (wall.height(voxels) < MOUND_MM) & (off > SKIRT_MM))


def breast_region(points: np.ndarray, mound: Mound, wall: ChestWall, size: float) -> np.ndarray:
    """Mask of the fine points of the breast: in front of the chest wall, near the mound's voxels."""
    near = np.flatnonzero(np.sum(np.square(points[:, :2] - mound.centre), axis=1) < (mound.radius + 2 * size) ** 2)
    idx = near[wall.height(points[near]) > CROP_MM]
    dist, _ = cKDTree(mound.voxels).query(points[idx], distance_upper_bound=2.0 * size)
    mask = np.zeros(len(points), bool)
    mask[idx[np.isfinite(dist)]] = True
    return mask


@dataclass(frozen=True)
class BreastFrame:
    """Breast frame in the viewing frame: origin (3,), axes (3, 3) with columns x, y, z."""

    origin: np.ndarray
    axes: np.ndarray

    def to_breast(self, points) -> np.ndarray:
        return (np.asarray(points, float) - self.origin) @ self.axes

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) viewing frame → breast frame."""
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self.axes.T, -self.axes.T @ self.origin
        return T


def frame_at(wall: ChestWall, xy: np.ndarray) -> BreastFrame:
    """Frame on the chest wall at (x, y): z the anterior normal, y superior, x = y × z."""
    z = wall.normal(xy)
    y = UP_VIEW - np.dot(UP_VIEW, z) * z
    y /= np.linalg.norm(y)
    return BreastFrame(wall.point(xy), np.column_stack([np.cross(y, z), y, z]))


def breast_frame(points: np.ndarray, wall: ChestWall, mound: Mound,
                 nipple: np.ndarray | None = None) -> tuple[BreastFrame, np.ndarray, str]:
    """The breast frame, the nipple (viewing frame) and how it was found ("areola" or "apex" as
    `ingest.nipple.find_nipple` says, "given" when `nipple` is; on a low mound, a disc under
    LOW_NIPPLE_MM counts as none).

    The base outline is rarely visible all round (the lateral side is seen at grazing angles,
    a ptotic lower pole hides its fold), so the origin is the foot of the nipple on the
    chest wall: exact for an undeformed primitive, below the base centre by the ptosis drop
    otherwise (the fit refines the pose). The apex and the frame are refined together, then the
    nipple is found near the apex (`ingest.nipple.find_nipple`) and the frame set under it.
    """
    frame = frame_at(wall, mound.centre)
    for _ in range(3):
        tip = frame.origin + frame.axes @ find_apex(frame.to_breast(points)) if nipple is None else nipple
        frame = frame_at(wall, foot_on_wall(wall, tip))
    if nipple is not None:
        return frame, nipple, "given"
    nipple, found = find_nipple(points, frame, LOW_NIPPLE_MM if mound.low else DISC_MM[0])
    return frame_at(wall, foot_on_wall(wall, nipple)), nipple, found


def foot_on_wall(wall: ChestWall, point: np.ndarray, iterations: int = 4) -> np.ndarray:
    """(x, y) of the chest-wall point whose normal passes through `point`."""
    xy = np.asarray(point, float)[:2].copy()
    for _ in range(iterations):
        n = wall.normal(xy)
        height = np.dot(point - wall.point(xy), n)
        xy = (point - height * n)[:2]
    return xy
