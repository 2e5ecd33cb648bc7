"""Rigid frames: applying 4×4 homogeneous transforms to points."""
from __future__ import annotations

import numpy as np


def transform_points(T, points) -> np.ndarray:
    """Points (..., 3) mapped by the 4×4 transform T (rotation/translation, units unchanged)."""
    T = np.asarray(T, dtype=float)
    points = np.asarray(points, dtype=float)
    if np.array_equal(T, np.eye(4)):
        return points.copy()
    return points @ T[:3, :3].T + T[:3, 3]
