"""A cloud's points in a canonical order, and per-point values back in the caller's: what makes a
result depend on the point set alone, not on the order a file or a caller lists the points in."""
from __future__ import annotations

import numpy as np


def canonical_order(points: np.ndarray) -> np.ndarray:
    """Indices that put (N, 3) points in lexicographic order of their coordinates (x, then y, then
    z): any order of the same points comes out as the same array (equal points are interchangeable),
    so every subset, sum and discrete choice made in it is the same too."""
    p = np.asarray(points)
    return np.lexsort(p.T[::-1])


def canonical_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) the triangles `faces` (indices into (N, 3) `vertices`) in a canonical order: each starting at its
    lexicographically least corner (its orientation kept), the triangles in lexicographic order of their
    corners' coordinates. The same surface, whatever the order of its vertices, its triangles and each
    triangle's corners, comes out as the same triangles in the same order (coinciding vertices, as at a
    texture's seams, are interchangeable), so a sampling of it seeded the same is the same."""
    f = np.asarray(faces, np.int64)
    order = canonical_order(vertices)
    p = np.asarray(vertices)[order]
    dense = np.empty(len(order), np.int64)
    dense[order] = np.concatenate([[0], np.cumsum(np.any(p[1:] != p[:-1], axis=1))])   # equal points: one rank
    r = dense[f]
    turn = (np.argmin(r, axis=1)[:, None] + np.arange(3)) % 3
    f, r = np.take_along_axis(f, turn, 1), np.take_along_axis(r, turn, 1)
    if len(order) < 1 << 21:                          # the three ranks packed in one key: one sort, not three
        return f[np.argsort((r[:, 0] << 42) | (r[:, 1] << 21) | r[:, 2], kind="stable")]
    return f[np.lexsort(r.T[::-1])]


def in_caller_order(order: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per-point values computed in canonical order (`canonical_order`'s `order`), back in the
    caller's order."""
    out = np.empty_like(values)
    out[order] = values
    return out
