"""Before/after pairs as FFD displacement fields: what the statistical models learn (docs/model.md §8).

The breast before the change is fitted with the breast model (`fit_breast`: superquadric, then an
n³ FFD) and its closed surface is boxed in an n³ lattice (`box_around`). The same lattice, at rest
on that box, is then FFD-fitted to the breast after the change by closest points (`fit_ffd`: no
point correspondence needed, as between a clinic's two scans), or by least squares when the two
clouds correspond point for point (`corresponding`: a synthetic pair). A pair becomes the control
points' displacements in box units, (P − R) / (hi − lo): a field that does not depend on the
breast's size, which a model predicts and `Lattice`'s box of a new breast turns back into mm.

Every fit is cached on disk by the content hash of its inputs and options (`FitCache`), so a
study or a training run fits each breast and each pair once.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from breastplan import ArtefactError, load_npz, save_npz
from breastplan.deform.lattice import Lattice
from breastplan.fitting.ffd import STOP_RESIDUAL, fit_ffd
from breastplan.options import FitOptions

CACHE_SCHEMA = "breastplan.ffd-cache/2"
"""Part of every cache key: a new version whenever the fit changes, so that no stale fit is reused."""
MARGIN = 0.25
"""Padding of the box around the before surface, as a share of its extent: room for the lattice
to carry the breast's surface where the change takes it."""


SMOOTHNESS = {"ptosis": 1e-8, "turn": 1e-8, "top-shape": 1e-6}
"""λ of ‖L(P − R)‖² per point in a fit from corresponding points, per deformation kind (the largest
for a pair of no stated kind). Ptosis and turn shear the breast by a quadratic in z, which the
lattice holds: a light penalty keeps their fields exact to microns, so that no model learns a bump
of the fit's own. Top-shape's crease along y = 0 is beyond the lattice: unregularised control points
chase it boxes away, and a firmer penalty keeps its fields learnable (docs/model.md §8)."""


CLOSEST_SMOOTHNESS = 1e-4
"""λ of the closest-point fit (`fit_ffd`'s smoothness, per data point): the breast fit's own λ lets
control points far from the after cloud wander boxes away; this one gave the most faithful fields
(docs/model.md §8)."""


@dataclass(frozen=True)
class PairOptions:
    """How pairs are fitted: control points per lattice axis (5 = 125 CP, 6 = 216), the mean
    normalised residual that ends a closest-point fit (the thesis's rule: 5·10⁻⁴ measured 5.7 times
    slower on database S for a floor 10 % lower), and whether the two clouds correspond point for
    point."""

    lattice: int = 5
    stop: float = STOP_RESIDUAL
    corresponding: bool = False

    def __post_init__(self):
        if not 3 <= self.lattice <= 7:
            raise ValueError(f"the lattice must have 3..7 control points per axis, got {self.lattice}")
        if not 0 < self.stop < 0.1:
            raise ValueError(f"the stopping residual must lie in (0, 0.1), got {self.stop}")


@dataclass(frozen=True)
class Before:
    """A breast before the change: its fitted closed surface (mm, breast frame), the fitted model's
    control points (mm; the thesis's features), its volume (cc) and the rest lattice of the pair fits."""

    vertices: np.ndarray
    faces: np.ndarray
    control_points: np.ndarray
    volume_cc: float

    def box(self, n: int) -> Lattice:
        return box_around(self.vertices, n)


def box_around(vertices: np.ndarray, n: int) -> Lattice:
    """The n³ rest lattice of a before surface (mm): its bounding box padded by MARGIN."""
    return Lattice.around(vertices, n, margin=MARGIN)


def field_to_mm(field: np.ndarray, box: Lattice) -> np.ndarray:
    """(K, 3) displacements in mm of a field in box units ((K·3,) or (K, 3))."""
    return np.asarray(field, float).reshape(-1, 3) * (box.hi - box.lo)


def field_lattice(field: np.ndarray, box: Lattice) -> Lattice:
    """The lattice on `box` whose control points a field in box units displaces (a deformation, mm)."""
    moved = Lattice(box.lo, box.hi, box.shape)
    moved.displacements = field_to_mm(field, box)
    return moved


def apply_field(points: np.ndarray, field: np.ndarray, box: Lattice) -> np.ndarray:
    """Points (mm, breast frame) moved by a displacement field in box units on `box`."""
    return field_lattice(field, box)(points)


class FitCache:
    """Fits by content hash: the last MEMORY ones in memory, and all on disk as one NPZ each under
    `folder` (None: memory only)."""

    MEMORY = 16

    def __init__(self, folder: str | Path | None):
        self.folder = Path(folder) if folder is not None else None
        self.memory: dict[str, dict] = {}

    @staticmethod
    def key(*parts) -> str:
        """Hash of arrays (their dtype, shape and bytes) and plain values."""
        h = hashlib.sha256(CACHE_SCHEMA.encode())
        for part in parts:
            if isinstance(part, np.ndarray):
                a = np.ascontiguousarray(part)
                h.update(f"{a.dtype.str}{a.shape}".encode())
                h.update(a.tobytes())
            else:
                h.update(repr(part).encode())
        return h.hexdigest()

    def get(self, key: str) -> dict | None:
        if key in self.memory or self.folder is None or not (self.folder / f"{key}.npz").is_file():
            return self.memory.get(key)
        try:
            return dict(load_npz(self.folder / f"{key}.npz", CACHE_SCHEMA))
        except ArtefactError:                  # a damaged entry is refitted and rewritten
            return None

    def put(self, key: str, arrays: dict) -> None:
        self.memory[key] = arrays
        while len(self.memory) > self.MEMORY:
            self.memory.pop(next(iter(self.memory)))
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            save_npz(self.folder / f"{key}.npz", CACHE_SCHEMA, arrays)


def default_cache() -> Path:
    """$BREASTPLAN_CACHE, or the user's cache folder (XDG) / breastplan / ffd."""
    if os.environ.get("BREASTPLAN_CACHE"):
        return Path(os.environ["BREASTPLAN_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "breastplan" / "ffd"


MEMORY = FitCache(None)
"""This process's fits in memory: a plan asks for one breast's field at many degrees."""


def fit_before(points: np.ndarray, n: int, cache: FitCache = MEMORY) -> Before:
    """The breast model fitted to a before cloud (mm, breast frame) with an n³ lattice."""
    points = np.asarray(points, float)
    key = FitCache.key("before", points, n)
    hit = cache.get(key)
    if hit is None:
        from breastplan.fitting.breast_fit import fit_breast

        fit = fit_breast(points, FitOptions(lattice=n))
        hit = {"vertices": fit.vertices, "faces": fit.faces, "control_points": fit.ffd.lattice.points,
               "volume_cc": np.float64(fit.volume_cc)}
        cache.put(key, hit)
    return Before(hit["vertices"], hit["faces"], hit["control_points"], float(hit["volume_cc"]))


@lru_cache(maxsize=None)
def _laplacian_gram(shape: tuple[int, int, int]) -> np.ndarray:
    """LᵀL of the Laplacian of a lattice of `shape`, dense and read-only: it depends on the shape alone,
    so a training run's thousands of pair fits compute it once."""
    L = Lattice(np.zeros(3), np.ones(3), shape).laplacian()
    gram = (L.T @ L).toarray()
    gram.setflags(write=False)
    return gram


def fit_pair(before: Before, before_points: np.ndarray, after: np.ndarray, options: PairOptions = PairOptions(),
             cache: FitCache = MEMORY, kind: str | None = None) -> np.ndarray:
    """(K·3,) displacement field, in box units, that takes the before breast to the after cloud (mm).

    Closest points: the before's fitted surface is FFD-fitted to the after cloud. Corresponding:
    least squares of the Bernstein rows of the before points against their displacements, with
    the SMOOTHNESS of the pair's `kind` (one of `options.DEGREE_KINDS`) on the lattice Laplacian."""
    before_points, after = np.asarray(before_points, float), np.asarray(after, float)
    box = before.box(options.lattice)
    smoothness = SMOOTHNESS[kind] if kind in SMOOTHNESS else max(SMOOTHNESS.values())
    key = FitCache.key("pair", before.vertices, before_points if options.corresponding else 0, after,
                       sorted(asdict(options).items()), smoothness if options.corresponding else CLOSEST_SMOOTHNESS)
    hit = cache.get(key)
    if hit is None:
        if options.corresponding:
            if before_points.shape != after.shape:
                raise ValueError(f"corresponding clouds must have equal shapes, got {before_points.shape} "
                                 f"and {after.shape}")
            B = box.basis(before_points)
            normal = B.T @ B + smoothness * len(B) * _laplacian_gram(box.shape)
            moved = np.linalg.solve(normal, B.T @ (after - before_points))
        else:
            moved = fit_ffd(after, before.vertices, before.faces, smoothness=CLOSEST_SMOOTHNESS, box=box,
                            stop=options.stop).lattice.displacements
        hit = {"field": (moved / (box.hi - box.lo)).ravel()}
        cache.put(key, hit)
    return hit["field"]


FEATURES = ("degree", "volume_cc", "width_mm", "height_mm", "projection_mm")


def feature_names(types) -> list[str]:
    """The names of `pair_features`' columns (ours) for a model of `types`."""
    if len(types) < 2:
        return list(FEATURES)
    return [f"type={k}" for k in types] + [f"{f} if type={k}" for k in types for f in FEATURES]


def pair_features(befores: list[Before], degree, kinds=None, types=(), *, thesis: bool = False) -> np.ndarray:
    """One row of features per pair, from its before breast, degree and type.

    Ours: degree, volume (cc), the before surface's extents (mm: width, height, projection). For a
    model of several `types`: each pair's kind (`kinds`) one-hot over them, then those five
    features once per type, zero but for the pair's own (a regressor's products of them are then
    the type's own).
    Thesis (§4.3): the before model's control-point coordinates (mm), its volume and the degree.
    """
    degree = np.asarray(degree, float)[:, None]
    volume = np.array([[b.volume_cc] for b in befores])
    if thesis:
        return np.hstack([np.stack([b.control_points.ravel() for b in befores]), volume, degree])
    base = np.hstack([degree, volume, np.stack([np.ptp(b.vertices, axis=0) for b in befores])])
    if len(types) < 2:
        return base
    one_hot = (np.asarray(kinds)[:, None] == np.array(types)[None, :]).astype(float)
    return np.hstack([one_hot] + [one_hot[:, [t]] * base for t in range(len(types))])
