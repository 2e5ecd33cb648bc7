"""Rigid frames: applying 4×4 homogeneous transforms to points."""
from __future__ import annotations

import numpy as np


def transform_points(T, points) -> np.ndarray:
    """Points (..., 3) mapped by the 4×4 transform T (rotation/translation, units unchanged)."""
    T = np.asarray(T, dtype=float)
    return np.asarray(points, dtype=float) @ T[:3, :3].T + T[:3, 3]
