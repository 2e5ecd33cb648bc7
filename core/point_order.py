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


def in_caller_order(order: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per-point values computed in canonical order (`canonical_order`'s `order`), back in the
    caller's order."""
    out = np.empty_like(values)
    out[order] = values
    return out
