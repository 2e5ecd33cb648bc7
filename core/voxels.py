"""Points evened out on a voxel grid (numpy only)."""
from __future__ import annotations

import numpy as np

DENSE_CELLS = 4_000_000
"""Voxel grids up to this many cells are indexed densely (no sort)."""


def voxel_centroids(points: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Centroids of the occupied voxels of `size` (the points' units), in the grid's linear order,
    and each point's voxel index."""
    keys = np.floor(points / size).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    cell = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    if np.prod(span) <= DENSE_CELLS:  # count per cell without sorting
        occupied = np.bincount(cell, minlength=int(np.prod(span))) > 0
        rank = np.cumsum(occupied) - 1
        inverse = rank[cell]
        counts = np.bincount(inverse)
    else:
        _, inverse, counts = np.unique(cell, return_inverse=True, return_counts=True)
    sums = np.stack([np.bincount(inverse, points[:, k], len(counts)) for k in range(3)], 1)
    return sums / counts[:, None], inverse
