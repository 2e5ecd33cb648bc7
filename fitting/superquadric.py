"""Fit the breast primitive (docs/model.md §2) and a rigid pose to a breast point cloud.

Least squares on the radial (geometric) distance of docs/model.md §2 with a robust loss
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

from breastplan import BadInputError, Primitive, to_mm, to_model_units
from breastplan.deform.breast_model import BreastModel
from breastplan.deform.global_deformations import TABULATED, Deformation, apply_kind, beta
from breastplan.deform.names import KIND_PARAMS, PLAUSIBLE

from .sampling import seeded_subset

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
DEFORMED_FIT_POINTS = 600
"""Points of a fit with deformations (finite-difference Jacobian: each point costs more)."""
START_NFEV = 50
"""Evaluations of each solve of a top-shape start: a start need not converge, and on a breast the
model cannot hold it may wander for the solver's whole budget (200), a second each."""
START_TURN_RAD = 1e-6
"""The pose of a top-shape start keeps the breast frame's axes: a cloud's lower part alone lets a
turn about z trade places with a1 and a2."""
LOWER_MARGIN, LOW_SHARE = 0.7, 0.1
"""A top-shape fit starts from the points top-shape barely moves: those below y = −0.7·a4 (cloud
centre, breast frame), in the lower half whatever ptosis moved down, and those below 10 % of the
height, which z·(β − 1) moves by under 0.02·a5 for |s0| ≤ 2.5 (docs/model.md §3–4)."""
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
    x: np.ndarray                 # the fitted parameter vector (log a1..a5, eps, rotation vector, t, deformations)

    @property
    def model(self) -> BreastModel:
        """The fitted primitive, deformations and pose."""
        return BreastModel(self.primitive, self.deformation, self.pose)

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
        values[kind.replace("-", "_")] = tuple(map(float, x[i: i + n]))
        i += n
    return Deformation(**values)


def _radial(x: np.ndarray, p: np.ndarray, kinds: tuple[str, ...] = ()) -> np.ndarray:
    """Radial distance (mu) of points p (mu, data frame) to the posed, deformed primitive x.

    Points are taken back through the inverse deformations (docs/model.md §3) to the primitive.
    Signed (negative inside), unlike `Primitive.radial_distance`, so that least squares sees
    a smooth residual through the surface.
    """
    return _radial_batch(x[None], p, kinds)[0]


def _radial_jacobian(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(N, 13) analytic Jacobian of `_radial` for the plain posed primitive (no deformations).

    r = |q|(1 − F^(−eps1/2)), q = Rᵀ(p − t), F the inside–outside function of docs/model.md §2; each
    point sees the semi-axes of its half (a1/a2 by the sign of x, a3/a4 by that of y), so the
    derivative w.r.t. each log semi-axis is masked by that sign. The rotation-vector part uses
    d(Rᵀv)/dw = Rᵀ[v]ₓ J_l(w) (J_l the left Jacobian of SO(3)).
    """
    a, e1, e2, rot, t = _unpack(x)
    R = _rotation(rot)
    v = p - t
    q = v @ R
    pos = q >= 0
    ax, ay = np.where(pos[:, 0], a[0], a[1]), np.where(pos[:, 1], a[2], a[3])
    X, Y, Z = np.abs(q[:, 0]) / ax, np.abs(q[:, 1]) / ay, np.abs(q[:, 2]) / a[4]
    s1, s2 = 2 / e1, 2 / e2
    Xp, Yp, Zp = X**s2, Y**s2, Z**s1
    G = Xp + Yp
    on_axis = G <= 1e-300
    G = np.where(on_axis, 1.0, G)
    Gk = np.where(on_axis, 0.0, G ** (e2 / e1))
    Gk1 = Gk / G                                           # G^(eps2/eps1 − 1), 0 on the z axis
    F = np.maximum(Gk + Zp, 1e-12)
    h = F ** (-e1 / 2)
    n = np.linalg.norm(q, axis=1)
    A = n * h * e1 / (2 * F)                               # ∂r/∂F
    J = np.empty((len(p), 13))
    dx, dy = -s1 * A * Gk1 * Xp, -s1 * A * Gk1 * Yp        # ∂r/∂log(semi-axis the point sees)
    J[:, 0], J[:, 1] = np.where(pos[:, 0], dx, 0.0), np.where(pos[:, 0], 0.0, dx)
    J[:, 2], J[:, 3] = np.where(pos[:, 1], dy, 0.0), np.where(pos[:, 1], 0.0, dy)
    J[:, 4] = -s1 * A * Zp
    lX, lY, lZ = (np.log(np.where(c > 0, c, 1.0)) for c in (X, Y, Z))   # c^s·log c → 0 at c = 0
    lG = np.log(G)
    J[:, 5] = n * h * np.log(F) / 2 - A * (e2 * lG * Gk + 2 * lZ * Zp) / e1**2
    J[:, 6] = A * Gk / e1 * (lG - s2 * (Xp * lX + Yp * lY) / G)
    grad_F = np.column_stack([s1 * Gk1 * X ** (s2 - 1) * np.sign(q[:, 0]) / ax,
                              s1 * Gk1 * Y ** (s2 - 1) * np.sign(q[:, 1]) / ay,
                              s1 * Z ** (s1 - 1) * np.sign(q[:, 2]) / a[4]])
    grad_q = (1 - h)[:, None] * q / np.maximum(n, 1e-300)[:, None] + A[:, None] * grad_F
    u = grad_q @ R.T                                       # ∂r/∂v
    J[:, 7:10] = np.cross(u, v) @ _left_jacobian(rot)
    J[:, 10:13] = -u
    return J


def _rotation(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector w (Rodrigues; series near θ = 0): scipy's Rotation
    costs 50 µs a call, a tenth of a deformed fit's residual."""
    th2 = float(w @ w)
    if th2 < 1e-8:
        s, c = 1.0 - th2 / 6, 0.5 - th2 / 24
    else:
        th = np.sqrt(th2)
        s, c = np.sin(th) / th, (1 - np.cos(th)) / th2
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + s * K + c * K @ K


def _left_jacobian(w: np.ndarray) -> np.ndarray:
    """J_l(w) = I + (1 − cos θ)/θ²·[w]ₓ + (θ − sin θ)/θ³·[w]ₓ² (series near θ = 0)."""
    th2 = float(w @ w)
    th = np.sqrt(th2)
    if th < 1e-4:
        c1, c2 = 0.5 - th2 / 24, 1 / 6 - th2 / 120
    else:
        c1, c2 = (1 - np.cos(th)) / th2, (th - np.sin(th)) / (th2 * th)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + c1 * K + c2 * K @ K


def _chest_prior(x: np.ndarray) -> np.ndarray:
    """The base's tilt off the chest wall (x, y of its normal R·e_z) and its height t_z."""
    normal = _rotation(x[7:10])[:, 2]
    return np.array([normal[0], normal[1], x[12]])


def _chest_prior_jacobian(x: np.ndarray) -> np.ndarray:
    """(3, len(x)) Jacobian of `_chest_prior`: d(R·e_z)/dw = −R[e_z]ₓ J_l(−w)."""
    R = _rotation(x[7:10])
    ez = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])   # [e_z]ₓ
    J = np.zeros((3, len(x)))
    J[:2, 7:10] = -(R @ ez @ _left_jacobian(-x[7:10]))[:2]
    J[2, 12] = 1.0
    return J


def initial_guess(p: np.ndarray, kinds: tuple[str, ...] = ()) -> np.ndarray:
    """Parameters from the cloud's extents in the breast frame (base on z = 0, nipple along z),
    with the deformations of `kinds` at zero."""
    lo, hi = np.percentile(p, [1, 99], axis=0)
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.0])
    half = np.maximum((hi - lo)[:2] / 2, 1e-3)
    a = np.array([half[0], half[0], half[1], half[1], max(hi[2], 1e-3)])
    deformations = np.zeros(sum(len(KIND_PARAMS[k]) for k in kinds))
    return np.concatenate([np.log(a), [1.0, 1.0], np.zeros(3), centre, deformations])


def fit_superquadric(points_mm, *, deformations=(), chest_prior: bool = True, loss: str = "soft_l1",
                     f_scale_mm: float = 1.0, x0: np.ndarray | None = None) -> SuperquadricFit:
    """Fit primitive + pose (+ the global `deformations`, e.g. ("top-shape", "ptosis", "turn")) to
    (N, 3) points (mm, breast frame).

    The deformation parameters start from zero, or with top-shape from `_top_shape_start`, unless
    `x0` gives the whole parameter vector.
    """
    kinds = tuple(k for k in KIND_PARAMS if k in set(deformations))  # docs/model.md §3 order
    unknown = set(deformations) - set(KIND_PARAMS)
    if unknown:
        raise ValueError(f"unknown deformations {sorted(unknown)}; choose from {', '.join(KIND_PARAMS)}")
    start = time.perf_counter()
    everything = to_model_units(_checked(points_mm))
    p = seeded_subset(everything, FIT_POINTS)
    solve = _Solver(chest_prior, loss, float(to_model_units(f_scale_mm)))
    nfev = 0
    if x0 is None and "top-shape" in kinds:
        x0, nfev = _top_shape_start(p, kinds, solve)
    elif x0 is None:
        x0 = initial_guess(p, kinds)
    fitted = seeded_subset(p, DEFORMED_FIT_POINTS) if kinds else p
    bounded = not _plausible(x0, kinds)       # a breast the model cannot hold starts out of range
    sol = solve(fitted, kinds, x0, plausible=bounded)
    if not _plausible(sol.x, kinds):          # … or ends there: again, within bounds
        nfev += sol.nfev
        sol = solve(fitted, kinds, sol.x, plausible=True)
    a, e1, e2, rot, t = _unpack(sol.x)
    pose = np.eye(4)
    pose[:3, :3] = _rotation(rot)
    pose[:3, 3] = to_mm(t)
    return SuperquadricFit(Primitive(*map(float, a), float(e1), float(e2)), pose, _deformation(sol.x, kinds),
                           to_mm(_radial(sol.x, everything, kinds)), int(nfev + sol.nfev), time.perf_counter() - start,
                           sol.x)


def _top_shape_start(p: np.ndarray, kinds: tuple[str, ...], solve: "_Solver") -> tuple[np.ndarray, int]:
    """Start of a fit with top-shape (p in mu). Top-shape scales only the heights of the upper half
    (docs/model.md §3), so the primitive, pose and other deformations are first fitted to the points it
    barely moves (LOWER_MARGIN, LOW_SHARE; picked again once the fit can take points back), then
    (s0, s1) solve the linear least squares z = h·β(w) over the upper points, h the fitted
    primitive's height above each (t0 = t1 = 0). Returns the start and the solver's evaluations."""
    rest = tuple(k for k in kinds if k != "top-shape")
    x = initial_guess(p, rest)
    q, nfev = p - x[10:13], 0
    for _ in range(2):
        still = (q[:, 1] < -LOWER_MARGIN * np.exp(x[3])) | (q[:, 2] < LOW_SHARE * np.exp(x[4]))
        sol = solve(seeded_subset(p[still], DEFORMED_FIT_POINTS), rest, x, max_nfev=START_NFEV, max_turn=START_TURN_RAD)
        x, nfev, q = sol.x, nfev + sol.nfev, _undone(sol.x, p, rest)
    a, e1, e2, _, _ = _unpack(x)
    primitive = Primitive(*a, e1, e2)
    upper = q[(q[:, 1] > 0) & (q[:, 2] > 0)]
    h = primitive.height(upper)
    seen = h > 0.05 * primitive.a5                           # β is undefined where h → 0
    w = primitive.latitude_at(h[seen]) * (2 / np.pi)
    basis = np.column_stack([beta(w, 1, 0, 0, 0), beta(w, 0, 1, 0, 0)]) - 1
    s, *_ = np.linalg.lstsq(basis * h[seen, None], upper[seen, 2] - h[seen], rcond=None)
    return np.concatenate([x[:13], s, [0.0, 0.0], x[13:]]), nfev


def _plausible_range(kinds: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) PLAUSIBLE values of the deformation parameters of `kinds`, in x's order."""
    names = [n for kind in kinds for n in KIND_PARAMS[kind]]
    lo, hi = np.array([PLAUSIBLE[n] for n in names]).reshape(-1, 2).T
    return lo, hi


def _plausible(x: np.ndarray, kinds: tuple[str, ...]) -> bool:
    """Whether the deformation parameters of x lie in their PLAUSIBLE ranges."""
    lo, hi = _plausible_range(kinds)
    return bool(np.all((x[13:] >= lo) & (x[13:] <= hi)))


def _radial_batch(xs: np.ndarray, p: np.ndarray, kinds: tuple[str, ...]) -> np.ndarray:
    """(B, N) `_radial` of the parameter vectors xs (B, len(x)), which share the primitive and the
    tabulated deformations (see `_undone_batch`)."""
    a, e1, e2, _, _ = _unpack(xs[0])
    q = _undone_batch(xs, p, kinds)
    f = np.maximum(Primitive(*a, e1, e2).inside_outside(q), 1e-12)
    return np.linalg.norm(q, axis=-1) * (1.0 - f ** (-e1 / 2))


def _undone(x: np.ndarray, p: np.ndarray, kinds: tuple[str, ...]) -> np.ndarray:
    """Points p (mu, data frame) taken back through the pose and deformations of x to the primitive."""
    return _undone_batch(x[None], p, kinds)[0]


def _undone_batch(xs: np.ndarray, p: np.ndarray, kinds: tuple[str, ...]) -> np.ndarray:
    """(B, N, 3) `_undone` of the parameter vectors xs (B, len(x)), which differ only in the pose and in
    the deformations that need no table (docs/model.md §3): each tabulated inverse, most of a
    residual's cost, runs once over all B·N points; zero-parameter kinds are skipped, as by
    `Deformation.inverse`."""
    a, e1, e2, _, _ = _unpack(xs[0])
    primitive = Primitive(*a, e1, e2)
    q = np.stack([(p - x[10:13]) @ _rotation(x[7:10]) for x in xs])
    deformations = [_deformation(x, kinds) for x in xs]
    for kind in reversed(kinds):                               # the inverses, in reverse §3 order
        if kind in TABULATED:
            params = deformations[0].params(kind)
            if any(params):
                q = apply_kind(q.reshape(-1, 3), kind, params, primitive, inverse=True, fast=True).reshape(q.shape)
            continue
        for k, d in enumerate(deformations):
            if any(d.params(kind)):
                q[k] = apply_kind(q[k], kind, d.params(kind), primitive, inverse=True)
    return q


@dataclass(frozen=True)
class _Solver:
    """Robust least squares of the radial residual (+ the chest-wall prior) on a point set."""

    chest_prior: bool
    loss: str
    f_scale: float              # model units

    def residuals(self, x: np.ndarray, p: np.ndarray, kinds: tuple[str, ...]) -> np.ndarray:
        r = _radial(x, p, kinds)
        return np.concatenate([r, self.weight(p) * _chest_prior(x)]) if self.chest_prior else r

    def jacobian(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        J = _radial_jacobian(x, p)
        return np.vstack([J, self.weight(p) * _chest_prior_jacobian(x)]) if self.chest_prior else J

    def weight(self, p: np.ndarray) -> float:
        return CHEST_PRIOR_WEIGHT * np.sqrt(len(p))

    def differences(self, x: np.ndarray, f0: np.ndarray, p: np.ndarray, kinds: tuple[str, ...],
                    bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Forward-difference Jacobian at x (f0 = residuals there), stepped as scipy's '2-point' steps
        (√eps·max(1, |x|), away from a bound it would cross). The columns that leave the primitive and
        the tabulated deformations alone — the pose's and the other deformations' — run as one batch."""
        lower, upper = bounds
        h = np.sqrt(np.finfo(float).eps) * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        h = np.where((x + h > upper) | (x + h < lower), -h, h)
        h = (x + h) - x
        stepped = x + np.diag(h)                                # row j: x with its j-th value stepped
        batched = _batched_columns(kinds)
        J = np.empty((len(f0), len(x)))
        for j in np.setdiff1d(np.arange(len(x)), batched):
            J[:, j] = self.residuals(stepped[j], p, kinds) - f0
        r = _radial_batch(stepped[batched], p, kinds)
        if self.chest_prior:
            r = np.hstack([r, self.weight(p) * np.stack([_chest_prior(s) for s in stepped[batched]])])
        J[:, batched] = (r - f0).T
        return J / h

    def __call__(self, p: np.ndarray, kinds: tuple[str, ...], x0: np.ndarray, max_nfev: int = 200,
                 max_turn: float = MAX_TURN_RAD, plausible: bool = False):
        """least_squares from x0: analytic Jacobian for the plain primitive, 2-point with deformations;
        `plausible` bounds the deformations to their PLAUSIBLE ranges (free otherwise)."""
        lower, upper = _bounds(x0, max_turn, kinds if plausible else ())
        x0 = np.clip(x0, lower + 1e-9, upper - 1e-9)
        last = {}

        def residuals(x):
            last["x"], last["f"] = x.copy(), self.residuals(x, p, kinds)
            return last["f"]

        def differences(x):
            f0 = last["f"] if np.array_equal(last.get("x"), x) else self.residuals(x, p, kinds)
            return self.differences(x, f0, p, kinds, (lower, upper))

        jac = differences if kinds else (lambda x: self.jacobian(x, p))
        return least_squares(residuals, x0, jac=jac, bounds=(lower, upper),
                             loss=self.loss, f_scale=self.f_scale, x_scale="jac", max_nfev=max_nfev)


def _batched_columns(kinds: tuple[str, ...]) -> np.ndarray:
    """Indices of x that `_radial_batch` may step: the pose (7–12) and the parameters of the
    untabulated deformations among `kinds`."""
    columns, i = list(range(7, 13)), 13
    for kind in kinds:
        n = len(KIND_PARAMS[kind])
        columns += [] if kind in TABULATED else list(range(i, i + n))
        i += n
    return np.array(columns)


def _bounds(x0: np.ndarray, max_turn: float, bounded: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """eps in EPS_BOUNDS, each rotation-vector component within ±max_turn, semi-axes within
    SEMI_AXIS_RANGE × the largest initial one, the deformations of the `bounded` kinds (all the
    fitted ones, or none) in their PLAUSIBLE ranges; the rest free."""
    lower, upper = np.full(len(x0), -np.inf), np.full(len(x0), np.inf)
    lower[13:], upper[13:] = _plausible_range(bounded) if bounded else (-np.inf, np.inf)
    lower[5:7], upper[5:7] = EPS_BOUNDS
    lower[7:10], upper[7:10] = -max_turn, max_turn
    size = np.log(np.exp(x0[:5]).max())
    lower[:5], upper[:5] = size + np.log(SEMI_AXIS_RANGE[0]), size + np.log(SEMI_AXIS_RANGE[1])
    return lower, upper


def _checked(points_mm) -> np.ndarray:
    p = np.asarray(points_mm, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise BadInputError(None, f"holds points of shape {p.shape}, not (N, 3)")
    if not np.isfinite(p).all():
        raise BadInputError(None, "has NaN or infinite coordinates")
    if len(p) < 50:
        raise BadInputError(None, f"has only {len(p)} points; a fit needs at least 50")
    s = np.linalg.svd(p - p.mean(0), compute_uv=False)
    if s[2] <= 1e-6 * s[0]:                            # all three 0: the points are one point
        raise BadInputError(None, "has coplanar or collinear points: no surface to fit")
    return p
