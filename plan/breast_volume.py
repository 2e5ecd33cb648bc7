"""Each breast's volume measured on her skin: its footprint, the chest wall beneath, and how sure it is.

The fitted model plans a change of shape; this is the ruler. Clinics measure a breast as the tissue in
front of the chest wall inside the breast's footprint, and so does `measure_breasts`, from the torso's
points alone (docs/volume.md):

1. **Her body frame** from the body landmarks (`plan.measures.find_landmarks`): x to her left, y up,
   z anterior, origin the sternal notch, mm. The skin is a height field over (x, y): the median
   anterior coordinate of the points in each CELL_MM cell.
2. **One chest wall for both breasts**, the same on both sides (her mirror symmetry): a cubic height
   field in (|x| − cx, y − cy) around the breasts' mean place (cx, cy), with ODD_TERMS for the frame's
   own small turns, fitted to the chest within WALL_REACH · cx of it (WALL_ABOVE as far above it) —
   both sides' skin together — by trimmed least squares, the breasts left out (first a disc round
   each, then their footprints widened by FOOT_MARGIN cells; ROUNDS rounds).
3. **The footprint**: the skin standing more than FOOT_MM in front of the wall, connected to the
   nipple, in her half, no higher than UPPER · cx above the nipples and within REACH · cx of the
   nipple; holes filled. The two sides' outlines are joined, each with the other's mirror image:
   both breasts are measured inside one outline, mirrored, so that a left − right difference is a
   difference of tissue, not of outline.
4. **The volume**: the height of the skin above the wall, summed over the footprint's cells.
   Cells of the footprint the camera did not see take the mirror cell's height, scaled to how high
   this side's skin stands against the mirror side's around it (`mirror_scale`; estimated; zero where
   neither side was seen).
5. **Its uncertainty** (± cc): twice the wall's standard error (its residuals' robust σ times
   √(terms / cells fitted)) over the footprint's area, plus the volume of the cells estimated rather
   than seen, plus FLOOR_PCT of the volume for what moves with the landmarks between scans.
6. **Her unseen outer side** (cc, one-sided: it can only add): where the camera stopped seeing her at the
   footprint's outer edge, an estimate of what her breast may hold beyond (`unseen_outer_cc`).

The points are put in a canonical order first, so the result depends on her surface alone.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from breastplan import BadInputError, transform_points
from breastplan.body import Body
from breastplan.point_order import canonical_order
from breastplan.units import volume_problem

from .measures import BodyLandmarks, find_landmarks

CELL_MM = 5.0
"""Side of the square cells of the skin's height field."""
MIN_POINTS = 3
"""A cell with fewer points is unseen: the fewest whose median sets one stray point aside. A cell seen at a
grazing angle holds a few points of a steep surface; the middle one of three is a height of her skin there,
of one or two it may be a stray."""
WALL_DEGREE = 3
WALL_REACH, WALL_ABOVE = 1.9, 0.8
"""The wall is fitted within WALL_REACH times the nipples' distance from the midline of their mean place,
and above that place only WALL_ABOVE as far: the clavicles and shoulders bend her chest otherwise than
the wall beneath the breasts, and a frame tilted by a degree or two then moved the wall."""
ODD_TERMS = "x, x (y − cy)"
"""Two terms of the wall odd in x: they take up a body frame turned by a degree about her vertical or her
anterior axis (which a mirror-symmetric wall cannot follow: it set one breast's side 3 mm higher than the
other's), and leave the wall otherwise the same on both sides."""
MIN_WALL_CELLS = 100
"""The wall is fitted to at least this many cells of her chest (a quarter of a 10 × 10 cm patch)."""
AROUND_NIPPLE_MM, AROUND_SEEN = 20.0, 0.75
"""At least this share of the cells within AROUND_NIPPLE_MM of each nipple must be seen: the skin round her nipple
faces a camera in front of her, and a scan missing it has a hole where her breast is (cut out, or a scanner's
gap), which no volume can be measured across."""
DISC = 0.75
"""The first round leaves out a disc of this many times that distance round each breast."""
ROUNDS = 3
FOOT_MARGIN = 2
"""Cells round the footprints also left out of the wall's support."""
FOOT_MM = 5.0
"""The footprint's skin stands at least this far in front of the wall."""
UPPER, REACH = 1.2, 1.2
"""The footprint reaches at most UPPER · cx above the nipples' mean height, and REACH · cx from its nipple."""
TRIM_KEEP, TRIM_FRONT_MM, TRIM_BACK_MM, TRIM_ITERATIONS = 0.5, 3.0, 6.0, 12
"""The wall's robust fit: the first half of the iterations keep the TRIM_KEEP share of cells nearest the
wall, the rest those within max(3σ, TRIM_FRONT_MM) in front of it and max(3σ, TRIM_BACK_MM) behind."""
MODEL_DIFFERS_PCT = 25.0
"""A fitted model whose volume lies further than this from hers is said to (%)."""
MIRROR_SIGMA_MM = 15.0
"""`mirror_scale` compares the two sides' skin within about this distance of a cell (a Gaussian's σ)."""
SAME_WITHIN = 0.9
"""Two sides whose skin stands within this ratio of each other count as alike (`mirror_scale` is then 1):
a side turned from the camera is seen more obliquely and reads a few percent lower."""
OUTLINE_SIGMA = 1.0
"""A footprint's outline is drawn through the mask blurred over this many cells (σ): smooth, enclosing the
same area to a few percent."""
GRAZING_DEG = 78.0
"""A depth camera gets no depth from skin it sees at more than about this angle from its ray; beyond the last
cell it saw on her outer side, her skin falls to the wall at least as steeply (`unseen_outer_cc`)."""
FLOOR_PCT = 2.0
"""Share of the volume added to its ± for what moves between two scans of her (the landmarks, her
outline): set so that nine re-scans in ten fall within it (benchmarks/bench_volume_repeat.py)."""


@dataclass(frozen=True, eq=False)
class BreastVolume:
    """One breast measured on her skin: volume and its ± (cc), its footprint (a closed curve on her
    skin, input frame, mm), the footprint's area (cm², seen from the front), the share of the volume
    estimated where the camera did not see her (%), and what her outer side beyond the footprint may add
    where the camera stopped seeing her (cc, an estimate; `unseen_outer_cc`)."""

    volume_cc: float
    uncertainty_cc: float
    footprint_input_mm: np.ndarray      # (K, 3), closed: the last point is the first
    area_cm2: float
    unseen_pct: float
    unseen_outer_cc: float

    def as_dict(self) -> dict:
        return {"volume_cc": round(self.volume_cc, 1), "uncertainty_cc": round(self.uncertainty_cc, 1),
                "unseen_outer_cc": round(self.unseen_outer_cc, 1),
                "footprint_area_cm2": round(self.area_cm2, 1), "unseen_pct": round(self.unseen_pct, 1)}

    def model_differs_pct(self, model_cc: float) -> float | None:
        """How far a fitted model's volume (cc) lies from hers, % of hers (0.1); None when hers is 0."""
        return round(100.0 * (model_cc - self.volume_cc) / self.volume_cc, 1) if self.volume_cc > 0 else None


def model_differs_much(pct: float | None) -> bool:
    """Whether a `BreastVolume.model_differs_pct` is further than MODEL_DIFFERS_PCT from hers."""
    return pct is not None and abs(pct) > MODEL_DIFFERS_PCT


@dataclass(frozen=True, eq=False)
class SkinCells:
    """Her skin over the cells it was measured on, body frame: cell centres x (nx,) and y (ny,), mm; the
    height of her skin above the chest wall (nx, ny), mm (a cell unseen: its mirror cell's, else 0);
    which cells were seen; and the footprint, both sides' (her left: x > 0). The grid is symmetric:
    cell [i, j]'s mirror image is [nx − 1 − i, j]."""

    x: np.ndarray
    y: np.ndarray
    height_mm: np.ndarray
    seen: np.ndarray
    footprint: np.ndarray
    wall_mm: np.ndarray                 # (nx, ny) the chest wall's anterior coordinate

    def moved(self, points_body: np.ndarray) -> "SkinCells":
        """These cells with her skin moved to `points_body` (the torso's points as planned, body frame, mm):
        the same cells, wall and footprint; heights measured again as `measure_breasts` measures them."""
        lo = np.array([self.x[0], self.y[0]]) - 0.5 * CELL_MM
        skin = _median_heights(np.asarray(points_body, float), lo, self.height_mm.shape)
        return SkinCells(self.x, self.y, _filled(skin, self.wall_mm), np.isfinite(skin), self.footprint, self.wall_mm)

    def side(self, side: str) -> np.ndarray:
        """(nx, ny) the footprint's cells on one side."""
        return self.footprint & ((self.x > 0) if side == "left" else (self.x < 0))[:, None]

    def volume_cc(self, side: str) -> float:
        """One breast's volume: her skin's heights above the wall (those above 0) over its footprint, cc."""
        return _volume_cc(self.height_mm, self.side(side))


@dataclass(frozen=True, eq=False)
class BreastVolumes:
    """Both breasts (or one) measured on one torso, with the landmarks and frame they were measured in
    and her skin's cells."""

    sides: dict[str, BreastVolume]
    landmarks: BodyLandmarks
    body_from_input: np.ndarray         # (4, 4) input frame → her body frame, mm
    cells: SkinCells

    def in_body(self, point_mm) -> np.ndarray:
        """(3,) one input-frame point (mm) in her body frame."""
        return transform_points(self.body_from_input, np.asarray(point_mm, float).reshape(1, 3))[0]


def change_on_earlier_wall(earlier: BreastVolumes, torso_mm, earlier_from_input, side: str) -> tuple[float, float]:
    """One breast's volume then and now (cc), both on an earlier visit's chest wall and inside one
    footprint (`grown_footprint`): this scan's torso (input frame, mm) carried into the earlier scan's
    input frame by `earlier_from_input` (a registration of the two chests, (4, 4)) and its skin measured
    on the earlier visit's cells."""
    now, grown = grown_footprint(earlier, torso_mm, earlier_from_input)
    return replace(earlier.cells, footprint=grown).volume_cc(side), replace(now, footprint=grown).volume_cc(side)


def grown_footprint(earlier: BreastVolumes, torso_mm, earlier_from_input) -> tuple[SkinCells, np.ndarray]:
    """This scan's skin on the earlier visit's cells (as `change_on_earlier_wall` carries it), and the
    earlier footprint grown over the skin that now rises FOOT_MM from the wall next to it (a breast grown
    since), both sides' joined and mirrored as `measure_breasts` joins them ((nx, ny) bool)."""
    then = earlier.cells
    now = then.moved(transform_points(earlier.body_from_input @ np.asarray(earlier_from_input, float),
                                      np.asarray(torso_mm, float)))
    grown = ndimage.binary_propagation(then.footprint, mask=then.footprint | (now.height_mm > FOOT_MM))
    return now, grown | grown[::-1]


def body_frame(landmarks: BodyLandmarks) -> np.ndarray:
    """(4, 4) input frame → her body frame: x her left, y up, z anterior, origin the sternal notch (mm)."""
    R = np.vstack([landmarks.left_axis, landmarks.up_axis, landmarks.anterior_axis])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ landmarks.sternal_notch
    return T


def measure_breasts(body: Body, nipples: dict) -> BreastVolumes:
    """Each breast's volume between her skin and the chest wall, inside its footprint (module docstring).

    body: her torso as scanned; nipples: side → (3,) input frame, mm."""
    P = np.asarray(body.torso_input, float)
    P = P[canonical_order(P)]                          # the result is the surface's, whatever the order
    landmarks = find_landmarks(P, nipples, body.input_to_view, body.plumb_input)
    T = body_frame(landmarks)
    grid = _SkinGrid(transform_points(T, P), {s: transform_points(T, np.asarray(n, float)[None])[0]
                                             for s, n in nipples.items()})
    grid.check_around_nipples()
    (wall, se_mm), footprint = grid.wall_and_footprint(grid.seen & grid.near & ~grid.disc)
    height = grid.filled_height(wall)
    sides = {}
    for side in grid.nipples:
        mask = footprint & grid.half(side)
        volume = _volume_cc(height, mask)
        problem = volume_problem(volume)
        if problem:
            raise BadInputError(None, f"gives her {side} breast {volume:,.0f} cc on her skin, {problem}: the chest "
                                      "wall beneath it was not found on her (a scan wrapped round her body, or in "
                                      "other units?)")
        unseen = _volume_cc(height, mask & ~grid.seen)
        area_cm2 = float(mask.sum() * CELL_MM ** 2 / 100.0)
        sides[side] = BreastVolume(
            volume, float(2.0 * se_mm * area_cm2 / 10.0 + unseen + FLOOR_PCT / 100.0 * volume),
            transform_points(np.linalg.inv(T), grid.outline(mask, wall)), area_cm2,
            100.0 * unseen / volume if volume > 0 else 0.0, unseen_outer_cc(height, grid.seen, mask, side))
    return BreastVolumes(sides, landmarks, T, SkinCells(grid.X[:, 0], grid.Y[0], height, grid.seen, footprint, wall))


class _SkinGrid:
    """Her skin as a height field on CELL_MM cells of her body frame, symmetric about x = 0, around the
    breasts' mean place (cx, cy)."""

    def __init__(self, points: np.ndarray, nipples: dict[str, np.ndarray]):
        self.nipples = nipples
        self.cx = float(np.mean([abs(n[0]) for n in nipples.values()]))
        self.cy = float(np.mean([n[1] for n in nipples.values()]))
        reach = WALL_REACH * self.cx
        half = np.ceil((self.cx + reach) / CELL_MM)
        lo = np.array([-half * CELL_MM, np.floor((self.cy - reach) / CELL_MM) * CELL_MM])
        shape = (int(2 * half), max(1, int(np.ceil((min(self.cy + reach, 0.0) - lo[1]) / CELL_MM))))
        self.lo = lo
        xs, ys = lo[0] + (np.arange(shape[0]) + 0.5) * CELL_MM, lo[1] + (np.arange(shape[1]) + 0.5) * CELL_MM
        self.X, self.Y = np.meshgrid(xs, ys, indexing="ij")
        self.skin = _median_heights(points, lo, shape)
        self.seen = np.isfinite(self.skin)
        dx, dy = np.abs(self.X) - self.cx, self.Y - self.cy
        self.near = dx ** 2 + (dy / np.where(dy > 0, WALL_ABOVE, 1.0)) ** 2 < reach ** 2
        self.disc = dx ** 2 + dy ** 2 < (DISC * self.cx) ** 2
        uv = np.stack([(np.abs(self.X) - self.cx) / 100.0, (self.Y - self.cy) / 100.0], -1)
        e = np.array([(i, d - i) for d in range(WALL_DEGREE + 1) for i in range(d, -1, -1)])
        odd = np.stack([self.X / 100.0, self.X * (self.Y - self.cy) / 1e4], -1)    # see ODD_TERMS
        self.basis = np.concatenate([uv[..., :1] ** e[:, 0] * uv[..., 1:] ** e[:, 1], odd], -1)

    def half(self, side: str) -> np.ndarray:
        return self.X > 0 if side == "left" else self.X < 0

    def check_around_nipples(self) -> None:
        """BadInputError where the skin round a nipple was not seen (AROUND_SEEN)."""
        for side, n in self.nipples.items():
            seen = self.seen[np.hypot(self.X - n[0], self.Y - n[1]) <= AROUND_NIPPLE_MM].mean()
            if seen < AROUND_SEEN:
                raise BadInputError(None, f"shows only {seen:.0%} of her skin within {AROUND_NIPPLE_MM:g} mm of her "
                                          f"{side} nipple: the scan has a hole where her breast is (cut out, or a "
                                          "gap the scanner left), and her breast cannot be measured across it")

    def fit_wall(self, support: np.ndarray) -> tuple[np.ndarray, float]:
        """The wall's anterior coordinate on every cell, fitted robustly to the skin of `support`, and
        the mean standard error of a fitted value, σ √(terms / inliers), mm."""
        A, z = self.basis[support], self.skin[support]
        if len(z) < MIN_WALL_CELLS:
            raise BadInputError(None, f"shows too little of her chest around the breasts ({len(z)} cell"
                                      f"{'s' * (len(z) != 1)} of {CELL_MM:g} mm) to infer the chest wall beneath them")
        inlier = np.ones(len(z), bool)
        for it in range(TRIM_ITERATIONS):
            coef = np.linalg.lstsq(A[inlier], z[inlier], rcond=None)[0]
            r = z - A @ coef                                     # > 0: in front of the wall
            if it < TRIM_ITERATIONS // 2:
                new = np.abs(r) <= np.quantile(np.abs(r), TRIM_KEEP)
            else:
                sigma = max(1.4826 * float(np.median(np.abs(r[inlier]))), 0.5)
                new = (r < max(3 * sigma, TRIM_FRONT_MM)) & (r > -max(3 * sigma, TRIM_BACK_MM))
                if (new == inlier).all():
                    break
            inlier = new
        sigma = 1.4826 * float(np.median(np.abs(r[inlier])))
        return self.basis @ coef, sigma * np.sqrt(A.shape[1] / inlier.sum())

    def wall_and_footprint(self, support: np.ndarray) -> tuple[tuple[np.ndarray, float], np.ndarray]:
        """The wall (as `fit_wall` gives it) and the joined, mirrored footprint, after ROUNDS rounds of each
        leaving the other out."""
        for _ in range(ROUNDS):
            fitted = self.fit_wall(support)
            wall = fitted[0]
            footprint = np.zeros(self.X.shape, bool)
            for side, nipple in self.nipples.items():
                own = self._footprint(wall, side, nipple)
                footprint |= own | own[::-1]
            support = self.seen & self.near & ~ndimage.binary_dilation(footprint, iterations=FOOT_MARGIN)
        return fitted, footprint

    def _footprint(self, wall: np.ndarray, side: str, nipple: np.ndarray) -> np.ndarray:
        rises = np.where(self.seen, self.skin - wall, -np.inf) > FOOT_MM
        rises &= self.half(side) & (self.Y < self.cy + UPPER * self.cx)
        rises &= (self.X - nipple[0]) ** 2 + (self.Y - nipple[1]) ** 2 < (REACH * self.cx) ** 2
        labels, _ = ndimage.label(rises)
        i, j = np.floor((nipple[:2] - self.lo) / CELL_MM).astype(int)
        inside = 0 <= i < self.X.shape[0] and 0 <= j < self.X.shape[1]
        if not inside or labels[i, j] == 0:
            return np.zeros(self.X.shape, bool)
        return ndimage.binary_fill_holes(labels == labels[i, j])

    def filled_height(self, wall: np.ndarray) -> np.ndarray:
        return _filled(self.skin, wall)

    def outline(self, mask: np.ndarray, wall: np.ndarray) -> np.ndarray:
        """(K, 3) the longest closed boundary of `mask`, body frame: the half level of the mask blurred over
        OUTLINE_SIGMA cells (a smooth curve, not the cells' staircase), each point at the mean height of the
        surface (her skin where seen, else the wall) over the mask's cells around it."""
        import contourpy

        if not mask.any():
            return np.zeros((0, 3))
        blurred = ndimage.gaussian_filter(np.pad(mask, 1).astype(float), OUTLINE_SIGMA, mode="constant").T
        xs = self.lo[0] + (np.arange(-1, mask.shape[0] + 1) + 0.5) * CELL_MM
        ys = self.lo[1] + (np.arange(-1, mask.shape[1] + 1) + 0.5) * CELL_MM
        xy = max(contourpy.contour_generator(xs, ys, blurred, name="serial").lines(0.5), key=len)
        surface = np.where(mask, np.where(self.seen, self.skin, wall), np.nan)
        around = np.floor((xy - self.lo) / CELL_MM).astype(int)[:, None, :] + np.stack(
            np.meshgrid([-1, 0, 1], [-1, 0, 1]), -1).reshape(1, 9, 2)
        around = np.clip(around, 0, np.array(mask.shape) - 1)
        height = surface[around[..., 0], around[..., 1]]                   # (K, 9), NaN off the mask
        known = np.isfinite(height)
        z = np.where(known, height, 0.0).sum(axis=1) / np.maximum(known.sum(axis=1), 1)
        return np.column_stack([xy, z])


def _volume_cc(height: np.ndarray, mask: np.ndarray) -> float:
    """cc of the heights (mm) above 0 over the cells of `mask`."""
    return float(np.clip(height[mask], 0.0, None).sum()) * CELL_MM ** 2 / 1000.0


def unseen_outer_cc(height: np.ndarray, seen: np.ndarray, mask: np.ndarray, side: str) -> float:
    """What her breast may hold beyond a footprint's outer edge where the camera stopped seeing her (cc, an estimate):
    over each cell of `mask` whose neighbour away from her midline is neither in it nor seen, the wedge of
    skin falling from the cell's height h above the wall to the wall no less steeply than GRAZING_DEG,
    h² / (2 tan GRAZING_DEG) along CELL_MM of edge. `height`, `seen`, `mask`: (nx, ny) on a grid symmetric
    about x = 0, her left at x > 0; heights in mm."""
    outward = slice(1, None) if side == "left" else slice(None, -1)
    inward = slice(None, -1) if side == "left" else slice(1, None)
    edge = mask[inward] & ~(mask[outward] | seen[outward])
    h = np.clip(height[inward][edge], 0.0, None)
    return float((h ** 2).sum()) * CELL_MM / (2.0 * np.tan(np.radians(GRAZING_DEG))) / 1000.0


def _filled(skin: np.ndarray, wall: np.ndarray) -> np.ndarray:
    """Skin above the wall on every cell: seen, else the mirror cell's times `mirror_scale`, else 0 (mm)."""
    h = skin - wall
    return np.nan_to_num(np.where(np.isfinite(skin), h, h[::-1] * mirror_scale(h)), nan=0.0)


def mirror_scale(height: np.ndarray) -> np.ndarray:
    """(nx, ny) how high each side's skin stands against the mirror side's around each cell, at most 1: the
    ratio of Gaussian-weighted (σ MIRROR_SIGMA_MM) sums of the heights above 0 over the cells seen on both
    sides, over SAME_WITHIN; 1 where no such cell rises near. `height`: (nx, ny) skin above the wall on a
    grid symmetric about x = 0 (NaN unseen), mm. A smaller breast's hidden side then takes its own scale of
    the larger one's, not the larger one's."""
    both = np.isfinite(height) & np.isfinite(height[::-1])
    own = ndimage.gaussian_filter(np.where(both, np.clip(height, 0.0, None), 0.0), MIRROR_SIGMA_MM / CELL_MM,
                                  mode="constant")
    mirror = own[::-1]                                   # the grid and `both` are symmetric: the filter commutes
    rises = mirror > 1e-6
    return np.where(rises, np.clip(own / np.where(rises, mirror, 1.0) / SAME_WITHIN, 0.0, 1.0), 1.0)


def _median_heights(points: np.ndarray, lo: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(shape) the median anterior coordinate (z) of the points in each cell, NaN with under MIN_POINTS."""
    ij = np.floor((points[:, :2] - lo) / CELL_MM).astype(np.int64)
    ok = (ij >= 0).all(1) & (ij[:, 0] < shape[0]) & (ij[:, 1] < shape[1])
    cell, z = ij[ok, 0] * shape[1] + ij[ok, 1], points[ok, 2]
    order = np.lexsort((z, cell))
    cell, z = cell[order], z[order]
    counts = np.bincount(cell, minlength=shape[0] * shape[1])
    start = np.cumsum(counts) - counts
    out = np.full(counts.size, np.nan)
    seen = counts >= MIN_POINTS
    out[seen] = 0.5 * (z[start[seen] + (counts[seen] - 1) // 2] + z[start[seen] + counts[seen] // 2])
    return out.reshape(shape)
