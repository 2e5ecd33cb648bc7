"""Points on a triangle mesh, spread evenly by area and chosen by no random draw: what a scanner's mesh is read as.

Each triangle takes its share of the points by its area, the shares rounded along the triangles in a running sum
(so that they add up to the number asked for); within it, the points lie at the next terms of one R2 sequence (a
low-discrepancy sequence of the unit square, Roberts 2018) folded onto the triangle. The triangles are taken in
a canonical order (`point_order.canonical_faces`), so the points are the surface's, whatever the order a file
lists its vertices, triangles and corners in; and no two readings of one surface differ by a draw.
"""
from __future__ import annotations

import numpy as np

from breastplan.point_order import canonical_faces

PLASTIC = 1.324717957244746
"""The plastic number, whose powers give the R2 sequence's steps."""
R2_STEP = np.array([1.0 / PLASTIC, 1.0 / PLASTIC ** 2])


def surface_samples(vertices: np.ndarray, faces: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    """`n` points on the mesh (vertices (V, 3), faces (F, 3); module docstring): (n, 3) points; (n, 3) the unit
    normals of their triangles (zero for a triangle of no area); (n, 3) the vertex indices of each point's triangle
    and (n, 3) its weights of them (barycentric coordinates), to carry values at the vertices to the points."""
    f = canonical_faces(vertices, faces)
    corners = np.asarray(vertices, float)[f]                                   # (F, 3, 3)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    total = np.cumsum(0.5 * np.linalg.norm(cross, axis=1))
    ends = np.floor(total * (n / total[-1]) + 0.5).astype(np.int64)
    which = np.repeat(np.arange(len(f)), np.diff(np.concatenate([[0], ends])))   # each point's triangle
    uv = (0.5 + np.arange(len(which))[:, None] * R2_STEP) % 1.0
    fold = uv.sum(axis=1) > 1.0
    uv[fold] = 1.0 - uv[fold]
    weights = np.column_stack([1.0 - uv.sum(axis=1), uv])                      # of corners 0, 1, 2
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    normals = np.divide(cross, length, out=np.zeros_like(cross), where=length > 0)
    return np.einsum("nk,nkc->nc", weights, corners[which]), normals[which], f[which], weights
