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
from breastplan.deform.global_deformations import (REFERENCE_AXIS, TABULATED, Deformation,
                                                   apply_kind, beta, top_shape_table)
from breastplan.deform.names import KIND_PARAMS, PLAUSIBLE
from breastplan.errors import counted
from breastplan.point_order import canonical_order, in_caller_order
from breastplan.primitive import EPS_BOUNDS

from .sampling import one_blas_thread, position_subset

FIT_POINTS = 3000
"""Larger clouds are fitted on a subset of this size chosen by the points' positions
(`position_subset`: the same subset whatever the order of the points or their last bits; the
residuals of all points are reported): 3000 surface points pin 7 shape and 6 pose parameters to ≈ 0.1 %."""
MAX_TURN_RAD = 0.35
"""Bound on each rotation-vector component (≈ 20°): the breast frame already fixes the axes, and
a free turn about z lets the fit trade ptosis for turn (docs/model.md §6)."""
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
    """mean, rms, p95 and max of |distances| (mm); summed in sorted order, so that any order of the
    same distances gives the same figures to the last bit."""
    r = np.sort(np.abs(distances_mm))
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
    return _radial_rows(x[None], p, kinds)[0]


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


_ROTATIONS: dict[bytes, np.ndarray] = {}
"""Rotation vector (its bytes) ↦ its matrix, read-only: a fit asks for the same few many times (its
residual, the chest prior and every column of its Jacobian but the pose's)."""


def _rotation(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector w (Rodrigues; series near θ = 0): scipy's Rotation
    costs 50 µs a call, a tenth of a deformed fit's residual. Read-only (cached)."""
    w = np.asarray(w, dtype=float)
    key = w.tobytes()
    R = _ROTATIONS.get(key)
    if R is None:
        if len(_ROTATIONS) >= 256:
            _ROTATIONS.clear()
        R = _ROTATIONS[key] = _rodrigues(w)
        R.flags.writeable = False
    return R


def _rodrigues(w: np.ndarray) -> np.ndarray:
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

    The deformation parameters start from zero unless `x0` gives the whole parameter vector; with
    top-shape, see `_fit_with_top_shape`. The fit is a function of the point set: it works on the
    points in canonical order (`breastplan.point_order`), solves on subsets chosen by position
    (`position_subset`) on one BLAS thread, and returns the residuals in the caller's order.
    """
    kinds = tuple(k for k in KIND_PARAMS if k in set(deformations))  # docs/model.md §3 order
    unknown = set(deformations) - set(KIND_PARAMS)
    if unknown:
        raise ValueError(f"unknown deformations {sorted(unknown)}; choose from {', '.join(KIND_PARAMS)}")
    start = time.perf_counter()
    with one_blas_thread():
        points, order = _checked(points_mm)
        everything = to_model_units(points)
        sol = _fit(everything, kinds, x0, chest_prior, loss, f_scale_mm)
        residuals = to_mm(_radial(sol.x, everything, kinds))
    a, e1, e2, rot, t = _unpack(sol.x)
    pose = np.eye(4)
    pose[:3, :3] = _rotation(rot)
    pose[:3, 3] = to_mm(t)
    return SuperquadricFit(Primitive(*map(float, a), float(e1), float(e2)), pose, _deformation(sol.x, kinds),
                           in_caller_order(order, residuals), int(sol.nfev), time.perf_counter() - start, sol.x)


def _fit(everything: np.ndarray, kinds: tuple[str, ...], x0: np.ndarray | None, chest_prior: bool, loss: str,
         f_scale_mm: float):
    """The solver's end for `fit_superquadric` on every point (mu, canonical order)."""
    p = position_subset(everything, FIT_POINTS)
    solve = _Solver(chest_prior, loss, float(to_model_units(f_scale_mm)))
    fitted = position_subset(p, DEFORMED_FIT_POINTS) if kinds else p
    if x0 is None and "top-shape" in kinds:
        return _fit_with_top_shape(p, fitted, kinds, solve)
    return _solve_plausibly(fitted, kinds, initial_guess(p, kinds) if x0 is None else x0, 0, solve)


def _solve_plausibly(fitted: np.ndarray, kinds: tuple[str, ...], x0: np.ndarray, nfev: int, solve: "_Solver"):
    """The solver's result from x0, with the deformations kept in their PLAUSIBLE ranges: free from a
    start within them, bounded from one outside (a breast the model cannot hold) or if the free
    solve ends outside; its `nfev` counts every evaluation since the start's own `nfev`."""
    sol = solve(fitted, kinds, x0, plausible=not _plausible(x0, kinds))
    if not _plausible(sol.x, kinds):
        nfev += sol.nfev
        sol = solve(fitted, kinds, sol.x, plausible=True)
    sol.nfev += nfev
    return sol


def _fit_with_top_shape(p: np.ndarray, fitted: np.ndarray, kinds: tuple[str, ...], solve: "_Solver"):
    """The better (lower cost, on the same points) of the solver's ends from two starts: `_top_shape_start`, and
    the plain primitive with every deformation at zero, solved within the PLAUSIBLE ranges from the start (a free
    solve could leave them, and the bounded one from where it left end above the primitive). Either start can
    end in a local minimum the other avoids (docs/model.md §6)."""
    primitive = solve(fitted, (), initial_guess(fitted))
    first = _solve_plausibly(fitted, kinds, *_top_shape_start(p, kinds, solve), solve)
    x0 = np.concatenate([primitive.x, np.zeros(sum(len(KIND_PARAMS[k]) for k in kinds))])
    second = solve(fitted, kinds, x0, plausible=True)    # bounded from a plausible start: ends at or below it
    best = second if second.cost < first.cost else first
    best.nfev = primitive.nfev + first.nfev + second.nfev          # the evaluations of every solve
    return best


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
        sol = solve(position_subset(p[still], DEFORMED_FIT_POINTS), rest, x, max_nfev=START_NFEV, max_turn=START_TURN_RAD)
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


def _radial_rows(xs: np.ndarray, p: np.ndarray, kinds: tuple[str, ...],
                 calls: np.ndarray | None = None) -> np.ndarray:
    """(B, N) `_radial` of each parameter vector of xs (B, len(x)) at the points p (N, 3, mu).

    Each row gets what `_radial` of that row alone gives, to the last bit (the same operations on
    the same values), but the rows run together: the poses, tables and deformations that rows
    share are computed once, and the rest as (B, N) arrays. Only flatten-side's table depends on
    the points it inverts: rows with the same id in `calls` share that table (as rows of one
    batched evaluation did); by default each row has its own.
    """
    q, a, e = _undone_rows(xs, p, kinds, calls)
    f = np.maximum(_inside_outside_rows(q, a, e), 1e-12)
    r = np.linalg.norm(q, axis=-1)
    for b in range(len(r)):                      # a scalar exponent per row: `**` as Primitive's code runs it
        r[b] *= 1.0 - f[b] ** (-e[b, 0] / 2)
    return r


def _inside_outside_rows(q: np.ndarray, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(B, N) `Primitive.inside_outside` of the points q (B, N, 3), row b with semi-axes a[b] and
    exponents e[b] (the same operations: numpy takes some scalar exponents, such as 0.5 and 2, by
    another route than an array of them, so the powers run row by row)."""
    x, y = q[..., 0], q[..., 1]
    X = np.abs(x / np.where(x >= 0, a[:, 0, None], a[:, 1, None]))
    Y = np.abs(y / np.where(y >= 0, a[:, 2, None], a[:, 3, None]))
    Z = np.abs(q[..., 2] / a[:, 4, None])
    for b in range(len(q)):
        e1, e2 = e[b]
        s = 2 / e2
        X[b] = (X[b] ** s + Y[b] ** s) ** (e2 / e1) + Z[b] ** (2 / e1)
    return X


def _height(points: np.ndarray, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """`Primitive.height` of points (n, 3) with y > 0, for semi-axes a (5,) and exponents e (2,)."""
    x = points[:, 0]
    e1, e2 = e
    s = 2 / e2
    flat = (np.abs(x / np.where(x >= 0, a[0], a[1])) ** s + np.abs(points[:, 1] / a[2]) ** s) ** (e2 / e1)
    return a[4] * np.maximum(1.0 - flat, 0.0) ** (e1 / 2)     # (F at z = 0 is flat + 0.0: the same value)


def _folded(q: np.ndarray, sel: np.ndarray, a: np.ndarray, e: np.ndarray, fold: float) -> np.ndarray:
    """(R, N) `_height(q[k], a[k], e) > fold` of the points sel (y > 0) of each row k of q (R, N, 3), False
    elsewhere; e (and a5) the same for every row. The heights are computed only where they may pass: the
    surface rises above `fold` only where F at z = 0 is below c = 1 − (fold/a5)^(2/eps1), and there
    F ≥ max(|x|/a1|a2, y/a3)^(2/eps1), so a point whose larger ratio exceeds c^(eps1/2) — here by a
    margin far above rounding — stays below."""
    e1 = e[0]
    c = max(1.0 - (fold / a[0, 4]) ** (2 / e1), 0.0)
    bound = c ** (e1 / 2) * (1 + 1e-4) + 1e-12
    x = q[..., 0]
    near = sel & (np.abs(x) < bound * np.where(x >= 0, a[:, 0, None], a[:, 1, None])) \
        & (np.abs(q[..., 1]) < bound * a[:, 2, None])
    out = np.zeros(sel.shape, dtype=bool)
    for k in np.flatnonzero(near.any(axis=1)):
        out[k, near[k]] = _height(q[k][near[k]], a[k], e) > fold
    return out


def _undone(x: np.ndarray, p: np.ndarray, kinds: tuple[str, ...]) -> np.ndarray:
    """Points p (mu, data frame) taken back through the pose and deformations of x to the primitive."""
    return _undone_rows(x[None], p, kinds)[0][0]


def _undone_rows(xs: np.ndarray, p: np.ndarray, kinds: tuple[str, ...], calls: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(B, N, 3) `_undone` of each parameter vector of xs (B, len(x)) (see `_radial_rows`), with each
    row's semi-axes (B, 5) and exponents (B, 2). The inverses run in reverse docs/model.md §3 order;
    a kind whose parameters are all zero is the identity and is skipped, as by `Deformation.inverse`."""
    B = len(xs)
    a = np.empty((B, 5))
    for b in range(B):
        a[b] = np.exp(xs[b, :5])
    e = xs[:, 5:7]
    poses: dict[bytes, np.ndarray] = {}
    q = np.empty((B, len(p), 3))
    for b in range(B):
        key = xs[b, 7:13].tobytes()
        if key not in poses:
            poses[key] = (p - xs[b, 10:13]) @ _rotation(xs[b, 7:10])
        q[b] = poses[key]
    offsets, i = {}, 13
    for kind in kinds:
        offsets[kind] = i
        i += len(KIND_PARAMS[kind])
    for kind in reversed(kinds):
        params = xs[:, offsets[kind]: offsets[kind] + len(KIND_PARAMS[kind])]
        active = np.flatnonzero(params.any(axis=1))
        if not len(active):
            continue
        every = len(active) == B
        sub = q if every else q[active]
        if kind in ("ptosis", "turn"):                 # shears by z (docs/model.md §3), undone
            k0, k1 = -params[active, 0, None], -params[active, 1, None]
            zeta = sub[..., 2] / REFERENCE_AXIS
            sub[..., 1 if kind == "ptosis" else 0] -= zeta * (k0 + k1 * zeta)
        elif kind == "turn-top":
            g0, g1 = -params[active, 0, None], -params[active, 1, None]
            w = sub[..., 1] / a[active, 2, None]
            sub[..., 0] -= np.where(w > 0, w * (g0 + g1 * w), 0.0)
        elif kind == "top-shape":
            _top_shape_undone(sub, active, params, a, e)
        else:                                          # flatten-side: its table spans its call's points
            ids = np.arange(B) if calls is None else np.asarray(calls)
            for call in dict.fromkeys(ids[active].tolist()):
                rows = np.flatnonzero(ids[active] == call)
                first = active[rows[0]]
                primitive = Primitive(*a[first], *e[first])
                sub[rows] = apply_kind(sub[rows].reshape(-1, 3), kind, params[first], primitive, inverse=True,
                                       fast=True).reshape(len(rows), -1, 3)
        if not every:
            q[active] = sub
    return q, a, e


def _top_shape_undone(q: np.ndarray, rows: np.ndarray, params: np.ndarray, a: np.ndarray, e: np.ndarray) -> None:
    """`top_shape_inverse(..., fast=True)` of each q[k] (in place), the row rows[k] of the parameters,
    semi-axes a and exponents e: one table for the rows that share a5, eps1 and (s0, s1, t0, t1). The fit
    keeps the single fold of Table 4.1's shapes: the rising branch, then the falling one read backwards
    (on a map that rises again after it, as `top_shape_inverse` handles, the fits of bench_realistic
    end in other minima, one of them far worse: docs/realistic.md)."""
    groups: dict[tuple, list[int]] = {}
    for k, b in enumerate(rows):
        groups.setdefault((a[b, 4], e[b, 0], *params[b].tolist()), []).append(k)
    for members in groups.values():
        b = rows[members[0]]
        z, image, bounds = top_shape_table(a[b, 4], e[b, 0], *params[b].tolist())
        top = bounds[1] if image[1] > image[0] else 0     # the map's first maximum (its first node if it falls)
        sub = q[members] if len(members) < len(q) else q
        height = sub[..., 2]
        sel = (sub[..., 1] > 0) & (height > 0)
        h = height[sel]
        solved = np.interp(h, image[:top + 1], z[:top + 1])
        if top < len(z) - 1:                           # past the fold: the folding branch (surface points)
            fold = _folded(sub, sel, a[rows[members]], e[b], z[top])[sel]
            solved[fold] = np.interp(h[fold], image[top:][::-1], z[top:][::-1])
        height[sel] = solved
        if sub is not q:
            q[members] = sub


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
        (√eps·max(1, |x|), away from a bound it would cross), its columns bit-identical to stepping
        each parameter alone. All columns run as one `_radial_rows`, which computes what the stepped
        vectors share once: the pose of every column but the pose's, top-shape's table of every
        column but a5's, eps1's and top-shape's own."""
        lower, upper = bounds
        h = np.sqrt(np.finfo(float).eps) * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        h = np.where((x + h > upper) | (x + h < lower), -h, h)
        h = (x + h) - x
        stepped = x + np.diag(h)                                # row j: x with its j-th value stepped
        calls = np.arange(len(x))
        calls[_batched_columns(kinds)] = -1                     # flatten-side: one table for these, as before
        r = _radial_rows(stepped, p, kinds, calls)
        if self.chest_prior:
            weight, priors = self.weight(p), {}
            for s in stepped:
                key = s[7:13].tobytes()
                if key not in priors:
                    priors[key] = weight * _chest_prior(s)
            r = np.hstack([r, np.stack([priors[s[7:13].tobytes()] for s in stepped])])
        r -= f0
        return np.ascontiguousarray(r.T) / h

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


def _checked(points_mm) -> tuple[np.ndarray, np.ndarray]:
    """The points (mm) in canonical order and that order (`breastplan.point_order`); BadInputError
    for points no surface can be fitted to."""
    p = np.asarray(points_mm, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise BadInputError(None, f"holds points of shape {p.shape}, not (N, 3)")
    if not np.isfinite(p).all():
        raise BadInputError(None, "has NaN or infinite coordinates")
    if len(p) < 50:
        raise BadInputError(None, f"has only {counted(len(p), 'point')}; a fit needs at least 50")
    order = canonical_order(p)
    p = p[order]
    s = np.linalg.svd(p - p.mean(0), compute_uv=False)
    if s[2] <= 1e-6 * s[0]:                            # all three 0: the points are one point
        raise BadInputError(None, "has coplanar or collinear points: no surface to fit")
    return p, order
