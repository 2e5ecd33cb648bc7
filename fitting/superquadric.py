"""Fit the breast primitive (MODEL.md §2) and a rigid pose to a breast point cloud.

Least squares on the radial (geometric) distance of MODEL.md §2 with a robust loss
(`scipy.optimize.least_squares`). Data are in the breast frame (mm): the base of the
breast lies on the chest wall z = 0, which a prior holds the model's base to (a scanner
sees only the front of the breast, so without it the hidden half is unconstrained).
Parameters (model units): log a1..a5, eps1, eps2, rotation vector (rad), translation.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from breastplan import BadInputError, Primitive, to_mm, to_model_units
from breastplan.deform.global_deformations import KIND_PARAMS, Deformation

EPS_BOUNDS = (0.3, 2.0)
FIT_POINTS = 3000
"""Larger clouds are fitted on a seeded random subset of this size (the residuals of all
points are reported): 3000 surface points pin 7 shape and 6 pose parameters to ≈ 0.1 %."""
MAX_TURN_RAD = 0.5
"""Bound on each rotation-vector component (≈ 29°): the breast frame already fixes the axes, and
a free turn about z would let the fit trade ptosis for turn on a near-round breast."""
SEMI_AXIS_RANGE = (0.2, 1.5)
"""Semi-axes bounded to this range × the largest initial one: a side the scanner did not see
(the medial side, cropped between the breasts) would otherwise let its semi-axis run away."""
CHEST_PRIOR_WEIGHT = 30.0
"""Weight of the prior residuals (tilt of the base, rad; height of the base, mu) per √point."""


@dataclass(frozen=True)
class SuperquadricFit:
    """The fitted primitive (model units) and pose (4×4, primitive frame → data frame, mm)."""

    primitive: Primitive
    pose: np.ndarray
    deformation: Deformation      # the fitted global deformations (zero for kinds not fitted)
    residuals_mm: np.ndarray      # radial distance of each point, mm
    iterations: int
    seconds: float

    def summary(self) -> dict[str, float]:
        return {f"{k}_mm": v for k, v in distance_stats(self.residuals_mm).items()}


def distance_stats(distances_mm) -> dict[str, float]:
    """mean, rms, p95 and max of |distances| (mm)."""
    r = np.abs(distances_mm)
    return {"mean": float(r.mean()), "rms": float(np.sqrt(np.mean(r * r))),
            "p95": float(np.percentile(r, 95)), "max": float(r.max())}


def _unpack(x: np.ndarray) -> tuple[np.ndarray, float, float, np.ndarray, np.ndarray]:
    return np.exp(x[:5]), x[5], x[6], x[7:10], x[10:13]


def _deformation(x: np.ndarray, kinds: tuple[str, ...]) -> Deformation:
    values, i = {}, 13
    for kind in kinds:
        n = len(KIND_PARAMS[kind])
        values[kind.replace("-", "_")] = tuple(x[i: i + n])
        i += n
    return Deformation(**values)


def _radial(x: np.ndarray, p: np.ndarray, kinds: tuple[str, ...] = ()) -> np.ndarray:
    """Radial distance (mu) of points p (mu, data frame) to the posed, deformed primitive x.

    Points are taken back through the inverse deformations (MODEL.md §3) to the primitive.
    Signed (negative inside), unlike `Primitive.radial_distance`, so that least squares sees
    a smooth residual through the surface.
    """
    a, e1, e2, rot, t = _unpack(x)
    primitive = Primitive(*a, e1, e2)
    q = Rotation.from_rotvec(rot).inv().apply(p - t)
    if kinds:
        q = _deformation(x, kinds).inverse(q, primitive)
    f = np.maximum(primitive.inside_outside(q), 1e-12)
    return np.linalg.norm(q, axis=1) * (1.0 - f ** (-e1 / 2))


def initial_guess(p: np.ndarray) -> np.ndarray:
    """Parameters from the cloud's extents in the breast frame (base on z = 0, nipple along z)."""
    lo, hi = np.percentile(p, [1, 99], axis=0)
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.0])
    half = np.maximum((hi - lo)[:2] / 2, 1e-3)
    a = np.array([half[0], half[0], half[1], half[1], max(hi[2], 1e-3)])
    return np.concatenate([np.log(a), [1.0, 1.0], np.zeros(3), centre])


def fit_superquadric(points_mm, *, deformations=(), chest_prior: bool = True, loss: str = "soft_l1",
                     f_scale_mm: float = 1.0, x0: np.ndarray | None = None, path=None) -> SuperquadricFit:
    """Fit primitive + pose (+ the global `deformations`, e.g. ("ptosis", "turn")) to (N, 3) points
    (mm, breast frame)."""
    kinds = tuple(k for k in KIND_PARAMS if k in set(deformations))  # MODEL.md §3 order
    unknown = set(deformations) - set(KIND_PARAMS)
    if unknown:
        raise ValueError(f"unknown deformations {sorted(unknown)}; choose from {', '.join(KIND_PARAMS)}")
    start = time.perf_counter()
    everything = to_model_units(_checked(points_mm, path))
    p = everything
    if len(p) > FIT_POINTS:
        p = p[np.random.default_rng(0).choice(len(p), FIT_POINTS, replace=False)]
    n_deform = sum(len(KIND_PARAMS[k]) for k in kinds)
    x0 = np.concatenate([initial_guess(p), np.zeros(n_deform)]) if x0 is None else x0
    weight = CHEST_PRIOR_WEIGHT * np.sqrt(len(p)) if chest_prior else 0.0

    def residuals(x):
        r = _radial(x, p, kinds)
        if not chest_prior:
            return r
        base_normal = Rotation.from_rotvec(x[7:10]).apply([0.0, 0.0, 1.0])
        return np.concatenate([r, weight * np.array([base_normal[0], base_normal[1], x[12]])])

    lower = np.full(len(x0), -np.inf)
    upper = np.full(len(x0), np.inf)
    lower[5:7], upper[5:7] = EPS_BOUNDS
    lower[7:10], upper[7:10] = -MAX_TURN_RAD, MAX_TURN_RAD
    size = np.log(np.exp(x0[:5]).max())
    lower[:5], upper[:5] = size + np.log(SEMI_AXIS_RANGE[0]), size + np.log(SEMI_AXIS_RANGE[1])
    x0 = np.clip(x0, lower + 1e-9, upper - 1e-9)
    sol = least_squares(residuals, x0, bounds=(lower, upper), loss=loss, f_scale=float(to_model_units(f_scale_mm)),
                        x_scale="jac", max_nfev=200)
    a, e1, e2, rot, t = _unpack(sol.x)
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(rot).as_matrix()
    pose[:3, 3] = to_mm(t)
    return SuperquadricFit(Primitive(*map(float, a), float(e1), float(e2)), pose, _deformation(sol.x, kinds),
                           to_mm(_radial(sol.x, everything, kinds)), int(sol.nfev), time.perf_counter() - start)


def _checked(points_mm, path) -> np.ndarray:
    p = np.asarray(points_mm, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise BadInputError(path, f"holds points of shape {p.shape}, not (N, 3)")
    if not np.isfinite(p).all():
        raise BadInputError(path, "has NaN or infinite coordinates")
    if len(p) < 50:
        raise BadInputError(path, f"has only {len(p)} points; a fit needs at least 50")
    s = np.linalg.svd(p - p.mean(0), compute_uv=False)
    if s[2] < 1e-6 * s[0]:
        raise BadInputError(path, "has coplanar or collinear points: no surface to fit")
    return p
