"""Measures of closed triangle meshes, and integrals over their triangles."""
from __future__ import annotations

import numpy as np


def mesh_volume(vertices, faces) -> float:
    """Enclosed volume of a closed, outward-oriented triangle mesh (units of vertices³): the sum of the signed
    volumes of the tetrahedra each triangle makes with the origin, (v0 · (v1 × v2)) / 6 (as libigl's centroid)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    return float(np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])) / 6.0)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit normals: each vertex's sum of its triangles' area-weighted normals (zero where it has none)."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.zeros_like(vertices, dtype=float)
    for k in range(3):
        np.add.at(out, faces[:, k], n)
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, length, out=np.zeros_like(out), where=length > 0)


BASE_QUADRATURE = 8
"""`volume_below_base` cuts each base-cap triangle into 8² triangles and samples their centroids."""


def volume_below_base(vertices, faces, floor) -> float:
    """Volume between the base cap of a closed mesh (the faces around its last vertex, the base
    centre) and the surface `floor` ((..., 2) x, y → (...,) z) beneath it (units of vertices³);
    negative where the floor rises above the cap. A breast's cap is flat; this is the tissue it
    leaves out where the chest falls away from its plane."""
    V, F = np.asarray(vertices, float), np.asarray(faces, np.int64)
    cap = V[F[(F == len(V) - 1).any(axis=1)]]                                   # (T, 3, 3)
    k = BASE_QUADRATURE
    i, j = (g.ravel() for g in np.meshgrid(np.arange(k), np.arange(k), indexing="ij"))
    up, down = i + j < k, i + j < k - 1                                         # k(k+1)/2 + k(k−1)/2 = k²
    ij = np.r_[np.c_[3 * i[up] + 1, 3 * j[up] + 1], np.c_[3 * i[down] + 2, 3 * j[down] + 2]] / (3 * k)
    centroids = np.einsum("sc,tcd->tsd", np.c_[1.0 - ij.sum(1), ij], cap)      # (T, k², 3)
    e1, e2 = cap[:, 1, :2] - cap[:, 0, :2], cap[:, 2, :2] - cap[:, 0, :2]
    area = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) / k**2             # signed, per sub-triangle
    gap = centroids[..., 2] - floor(centroids[..., :2])
    return float(np.sum(area[:, None] * gap) * np.sign(area.sum()))


def positive_part_mean(f: np.ndarray) -> np.ndarray:
    """(...) mean over each triangle of max(f, 0), f linear with vertex values f (..., 3) (exact)."""
    f = np.asarray(f, dtype=float)
    return corners_positive_part_mean(f[..., 0], f[..., 1], f[..., 2])


def corners_positive_part_mean(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """`positive_part_mean` of triangles whose corners' values are a, b and c (arrays of one shape)."""
    lo, hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    out = np.where(lo >= 0, (a + b + c) / 3.0, 0.0)
    mixed = (lo < 0) & (hi > 0)                     # the triangles the zero level crosses
    s = np.sort(np.stack([a[mixed], b[mixed], c[mixed]], axis=-1), axis=-1)[:, ::-1]   # f1 > 0 > f3
    f1, f2, f3 = s.T
    part = s.mean(1)
    # f1³ / (3 (f1 − f2)(f1 − f3)) and its twin, written as f/3 times two edge fractions in (0, 1]:
    # cubes and their products under- or overflow (tiny or huge values gave NaN)
    one = f2 <= 0                                   # only the largest is positive
    a = f1[one]
    part[one] = a / 3.0 * (a / (a - f2[one])) * (a / (a - f3[one]))
    two = ~one                                      # the smallest is negative
    g = -f3[two]
    part[two] += g / 3.0 * (g / (f1[two] + g)) * (g / (f2[two] + g))
    out[mixed] = part
    return out
