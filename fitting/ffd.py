"""Free-form deformation lattice fitted to a breast cloud (MODEL.md §6, Bardinet et al. 1998).

The model surface (a triangle mesh, mm) sits in a box of n×n×n control points; each vertex
has fixed lattice coordinates and a row of the trivariate Bernstein basis, precomputed once,
so the deformed surface is B·P. Fitting alternates *match* (each data point ↔ its closest
point on the current surface, as barycentric weights of a triangle's vertices) and *solve*
(P = argmin ‖W B P − D‖² + λ‖L (P − P0)‖², L the lattice Laplacian), until the mean
normalised residual ‖d − m‖/‖d‖ is below 0.0015 (thesis stopping rule) or the iterations or
time run out.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.special import comb

STOP_RESIDUAL = 0.0015
MAX_ITERATIONS = 1000


def bernstein(n: int, s: np.ndarray) -> np.ndarray:
    """(..., n+1) Bernstein polynomials B_i^n(s), s ∈ [0, 1]."""
    i = np.arange(n + 1)
    s = np.asarray(s, float)[..., None]
    return comb(n, i) * s**i * (1 - s) ** (n - i)


@dataclass
class Lattice:
    """Control points of an n³ lattice on an axis-aligned box (mm)."""

    n: int                     # control points per axis (degree n − 1)
    lo: np.ndarray             # (3,) box corner
    hi: np.ndarray             # (3,) opposite corner
    rest: np.ndarray           # (n³, 3) rest control points
    points: np.ndarray         # (n³, 3) current control points

    @classmethod
    def around(cls, points: np.ndarray, n: int, margin: float = 0.1) -> "Lattice":
        lo, hi = points.min(0), points.max(0)
        pad = margin * (hi - lo) + 1.0
        lo, hi = lo - pad, hi + pad
        axes = [np.linspace(lo[k], hi[k], n) for k in range(3)]
        rest = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        return cls(n, lo, hi, rest, rest.copy())

    def basis(self, points: np.ndarray) -> np.ndarray:
        """(N, n³) trivariate Bernstein rows of points (mm) inside the box."""
        s = (points - self.lo) / (self.hi - self.lo)
        bx, by, bz = (bernstein(self.n - 1, s[:, k]) for k in range(3))
        return (bx[:, :, None, None] * by[:, None, :, None] * bz[:, None, None, :]).reshape(len(points), -1)

    def laplacian(self) -> np.ndarray:
        """(n³, n³) graph Laplacian of the lattice (6-neighbourhood)."""
        n = self.n
        idx = np.arange(n**3).reshape(n, n, n)
        L = np.zeros((n**3, n**3))
        for axis in range(3):
            a = np.moveaxis(idx, axis, 0)[:-1].ravel()
            b = np.moveaxis(idx, axis, 0)[1:].ravel()
            L[a, b] -= 1
            L[b, a] -= 1
            L[a, a] += 1
            L[b, b] += 1
        return L


@dataclass
class FFDFit:
    lattice: Lattice
    vertices: np.ndarray       # (V, 3) fitted surface, mm
    residual: float            # mean normalised residual at the end
    residuals_mm: np.ndarray   # data ↔ surface distances at the end, mm
    iterations: int
    seconds: float
    converged: bool


def fit_ffd(data: np.ndarray, vertices: np.ndarray, faces: np.ndarray, n: int = 5, smoothness: float = 1e-3,
            max_iterations: int = MAX_ITERATIONS, max_seconds: float = 30.0) -> FFDFit:
    """Deform the surface (vertices, faces; mm) by an n³ lattice to fit data (N, 3) mm."""
    start = time.perf_counter()
    lattice = Lattice.around(np.vstack([data, vertices]), n)
    B = lattice.basis(vertices)
    L = lattice.laplacian()
    LtL = L.T @ L
    norm = np.maximum(np.linalg.norm(data, axis=1), 1e-9)
    faces32 = np.ascontiguousarray(faces, dtype=np.uint32)
    current = vertices.copy()
    residual, it = np.inf, 0
    for it in range(1, max_iterations + 1):
        tri, bary, dist = _closest(current, faces32, data)
        residual = float(np.mean(dist / norm))
        if residual < STOP_RESIDUAL or time.perf_counter() - start > max_seconds:
            break
        rows = np.einsum("nk,nkc->nc", bary, B[faces[tri]])        # basis rows of the matched surface points
        A = rows.T @ rows + smoothness * len(data) * LtL
        rhs = rows.T @ data + smoothness * len(data) * LtL @ lattice.rest
        lattice.points = np.linalg.solve(A, rhs)
        current = B @ lattice.points
    return FFDFit(lattice, current, residual, dist, it, time.perf_counter() - start, residual < STOP_RESIDUAL)


def _closest(vertices: np.ndarray, faces: np.ndarray, data: np.ndarray):
    """Closest surface point of each data point: triangle ids, barycentric weights (N, 3), distances."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces))
    hit = scene.compute_closest_points(o3d.core.Tensor(data.astype(np.float32)))
    tri = hit["primitive_ids"].numpy().astype(np.int64)
    uv = hit["primitive_uvs"].numpy().astype(float)
    bary = np.column_stack([1 - uv.sum(1), uv[:, 0], uv[:, 1]])
    dist = np.linalg.norm(hit["points"].numpy() - data, axis=1)
    return tri, bary, dist
