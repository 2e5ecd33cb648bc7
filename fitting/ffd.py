"""Free-form deformation lattice fitted to a breast cloud (docs/model.md §6, Bardinet et al. 1998).

The model surface (a closed triangle mesh, mm, breast frame) sits in a box of n×n×n control
points (`breastplan.deform.lattice.Lattice`); each vertex has fixed lattice coordinates and a
row of the trivariate Bernstein basis, precomputed once, so the deformed surface is B·P.
Fitting alternates *match* (each data point ↔ its closest point on the current surface) and
*solve* (a damped Gauss–Newton step on the control points: the distance along the surface
normal, a small weight on the tangential offset, and λ‖L(P − P0)‖² with L the lattice
Laplacian) until the mean normalised residual ‖d − m‖/‖d‖ (docs/model.md §7's normalisation
by ‖o‖) is below 0.0015 (thesis stopping rule), the residual stops improving, or the
iterations run out: the budget is counted in iterations, never in seconds, so a result does not
depend on the machine's load. Nor on the order of the data points or the BLAS thread count: the fit
works on the points in canonical order (`breastplan.point_order`) and on a subset chosen by their
positions (`position_subset`), on one BLAS thread, and returns the residuals in the caller's order.

Matching on the *closed* mesh holds the base cap to the data's base ring on the chest wall;
the tangential weight is the Levenberg–Marquardt damping: raised after a step that made the
fit worse (the step is undone), lowered after a good one.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import igl
import numpy as np
from scipy import sparse

from breastplan.deform.lattice import Lattice
from breastplan.point_order import canonical_order, in_caller_order

from .closest import closest_points
from .sampling import one_blas_thread, position_subset

STOP_RESIDUAL = 0.0015
MAX_ITERATIONS = 1000
STALL = 1e-3
"""Relative improvement below which a least-damped step counts as no progress (the fit has
converged); a damped step that gains little is a short step, not convergence."""
CREEP = (20, 0.01)
"""(iterations, relative gain): a fit whose residual gained less than 1 % over its last 20
iterations has converged too — it is creeping towards a shape the lattice cannot hold."""
FIT_POINTS = 2000
"""Data points per solve (`position_subset`): 2000 surface points pin
375 lattice coordinates."""
DAMPING = (0.01, 0.03, 1.0)
"""Tangential weight: floor, start, ceiling."""


@dataclass
class FFDFit:
    lattice: Lattice           # its control points set to the fitted ones
    vertices: np.ndarray       # (V, 3) fitted surface, mm
    residual: float            # mean normalised residual of every data point at the end
    residuals_mm: np.ndarray   # data ↔ surface distances at the end, mm, in the order of the data
    iterations: int
    seconds: float
    converged: bool            # met the stopping rule or stopped improving (not cut by a limit)


def fit_ffd(data: np.ndarray, vertices: np.ndarray, faces: np.ndarray, n: int = 5, smoothness: float = 1e-9,
            held: np.ndarray | None = None, max_iterations: int = MAX_ITERATIONS, *,
            box: Lattice | None = None, stop: float = STOP_RESIDUAL) -> FFDFit:
    """Deform the closed surface (vertices, faces; mm) by an n³ lattice to fit data (N, 3) mm.

    `held` (V, 3): weight, as a share of the data's total weight, that holds each vertex
    coordinate where it starts — for the parts of the surface no data point sees. `box`: the
    lattice whose box and shape to fit (it starts at rest and must hold every vertex; default: an
    n³ one around data and vertices). `stop`: the mean normalised residual that ends the fit.
    """
    start = time.perf_counter()
    order = canonical_order(data)
    with one_blas_thread():
        lattice, current, final, dist, it, converged = _fit(np.asarray(data, float)[order], vertices, faces, n,
                                                            smoothness, held, max_iterations, box, stop)
    return FFDFit(lattice, current, final, in_caller_order(order, dist), it, time.perf_counter() - start, converged)


def _fit(data, vertices, faces, n, smoothness, held, max_iterations, box, stop):
    """`fit_ffd` on the data in canonical order: the lattice, fitted vertices, final residual, the
    data's distances, iterations and whether it converged."""
    sub = position_subset(data, FIT_POINTS)
    lattice = Lattice.around(np.vstack([data, vertices]), n) if box is None else Lattice(box.lo, box.hi, box.shape)
    B = lattice.basis(vertices)
    K = lattice.size
    L = lattice.laplacian()                                # sparse; K ≤ 343, so LL is solved dense
    LL = sparse.kron(sparse.identity(3), L.T @ L).toarray() * smoothness * len(sub)   # λ‖L(P − P0)‖², x, y, z
    for c in range(3 if held is not None else 0):          # Σ_v held_vc·(B_v (P_c − rest_c))², per coordinate
        h = np.flatnonzero(held[:, c])                     # the held vertices
        LL[c * K:(c + 1) * K, c * K:(c + 1) * K] += len(sub) * (B[h] * held[h, c, None]).T @ B[h]
    rest = lattice.rest.T.reshape(-1)                      # coordinate-major: x of every CP, then y, z
    # both penalties are quadratic in P − rest (B·rest = vertices), so LL @ (P − rest) is their gradient
    faces32 = np.ascontiguousarray(faces, dtype=np.uint32)
    norm = np.maximum(np.linalg.norm(sub, axis=1), 1e-9)
    P, current, damping = rest.copy(), vertices.copy(), DAMPING[1]
    hit = _closest(current, faces32, sub, detail=True)    # the current surface's closest points
    match = products = None                                # their basis rows and normals, the normal matrix's
    residual, it, stalled = np.mean(hit[1] / norm), 0, False   # products: made when a step needs them
    history = [residual]                                   # the residual after each iteration
    target = stop                                          # on the subset; tightened if the whole cloud misses it
    data_norm = np.maximum(np.linalg.norm(data, axis=1), 1e-9)

    while True:
        while residual >= target and not stalled and it < max_iterations:
            it += 1
            if match is None:
                match = _matched(current, faces32, B, *hit)
            delta, products = _step(match, sub, damping, LL, P - rest, K, products)
            step = P + delta
            trial = B @ step.reshape(3, K).T
            trial_hit = _closest(trial, faces32, sub, detail=True)
            trial_residual = np.mean(trial_hit[1] / norm)
            if trial_residual < residual:
                stalled = trial_residual > (1 - STALL) * residual and damping <= DAMPING[0]
                P, current, hit, residual = step, trial, trial_hit, trial_residual
                match = products = None
                damping = max(damping / 2, DAMPING[0])
            else:                                          # undone: the next step reuses this match's products
                stalled = damping >= DAMPING[2]
                damping = min(damping * 4, DAMPING[2])
            history.append(residual)
            stalled = stalled or (it >= CREEP[0] and residual > (1 - CREEP[1]) * history[it - CREEP[0]])
        dist = hit[1] if sub is data else _closest(current, faces32, data)[1]
        final = float(np.mean(dist / data_norm))
        if final < stop or residual >= target or stalled or it >= max_iterations:
            break
        target *= 0.9
    lattice.points = P.reshape(3, K).T
    return lattice, current, final, dist, it, final < stop or stalled


def _step(match, data, damping, LL, offset, K, products=None):
    """Gauss–Newton step ΔP (3K,) for the matched rows, normals and closest points, and the products
    (AᵀA, RᵀR) it used, which a step from the same match (after an undone one) takes again.

    Each point weighs its offset by W = (1 − d²)·nnᵀ + d²·I (d the damping), so the normal
    matrix is (1 − d²)·AᵀA + d²·I₃⊗RᵀR with A = [n_x R, n_y R, n_z R]. Its products run in
    float32, twice as fast; a step that a rounding error spoils is rejected like any other.
    """
    rows, normals, points, _ = match
    d2 = damping**2
    delta = data - points
    if products is None:
        A = np.empty((len(rows), 3, rows.shape[1]), np.float32)           # n_c·R, rounded once to float32
        np.multiply(normals[:, :, None], rows[:, None, :], out=A, casting="same_kind")
        A = A.reshape(len(rows), -1)
        R = rows.astype(np.float32)
        products = ((A.T @ A).astype(float), (R.T @ R).astype(float))
    AtA, RtR = products
    M = (1 - d2) * AtA
    damped = d2 * RtR
    for c in range(3):                                     # + I₃⊗(d²·RᵀR)
        M[c * K:(c + 1) * K, c * K:(c + 1) * K] += damped
    M += LL
    g = (1 - d2) * normals * np.einsum("nc,nc->n", normals, delta)[:, None] + d2 * delta
    rhs = (rows.T @ g).T.reshape(-1) - LL @ offset
    return np.linalg.solve(M, rhs), products


def _match(vertices, faces, data, B):
    """Closest points of data on the mesh: their basis rows, unit normals, points and distances."""
    return _matched(vertices, faces, B, *_closest(vertices, faces, data, detail=True))


def _matched(vertices, faces, B, tri, dist, points, bary):
    """`_match` from `_closest`'s answer: the basis row of each closest point is the barycentric
    mix of its triangle's corner rows (a sparse product: the same sums as gathering the rows)."""
    corners = faces[tri].astype(np.int64)
    mix = sparse.csr_matrix((bary.ravel(), corners.ravel(), np.arange(0, corners.size + 1, 3)),
                            shape=(len(tri), len(B)))
    rows = mix @ B
    vertex_normals = igl.per_vertex_normals(vertices, faces.astype(np.int64),
                                            igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)   # unit
    normals = np.einsum("nk,nkc->nc", bary, vertex_normals[corners])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return rows, normals, points, dist


def _closest(vertices, faces, data, detail: bool = False):
    """Exact closest points of data (N, 3) on the mesh (vertices (V, 3), faces (T, 3); mm, one frame):
    triangle ids and distances, mm (and the points, mm, and the weights of each triangle's corners
    in faces' order). Ties go to the smaller triangle index (`fitting.closest`)."""
    hit = closest_points(vertices, faces, data)
    return hit if detail else hit[:2]
