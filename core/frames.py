"""Rigid frames: applying 4×4 homogeneous transforms to points (..., 3)."""
from __future__ import annotations

import numpy as np


def points_copy(points) -> np.ndarray:
    """A float64 copy of points (..., 3); ValueError for any other shape."""
    p = np.array(points, dtype=np.float64, copy=True)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {p.shape}")
    return p


def transform_points(T, points) -> np.ndarray:
    """Points (..., 3) mapped by the 4×4 transform T (rotation/translation, units unchanged)."""
    T = np.asarray(T, dtype=float)
    points = np.asarray(points, dtype=float)
    if np.array_equal(T, np.eye(4)):
        return points.copy()
    return (points.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]).reshape(points.shape)   # one product, not one per row


def is_rigid(T, tol: float = 1e-5) -> bool:
    """Whether T is a 4×4 rigid transform: an orthonormal 3×3 block, a finite translation, a last
    row 0 0 0 1."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        return False
    R = T[:3, :3]
    return bool(np.allclose(R @ R.T, np.eye(3), atol=tol) and np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]))
