"""The seeded point subsets the fits solve on (the same points on every run)."""
from __future__ import annotations

import numpy as np


def seeded_subset(points: np.ndarray, n: int) -> np.ndarray:
    """A seeded random subset of n points (all of them if there are fewer)."""
    return points[np.random.default_rng(0).choice(len(points), n, replace=False)] if len(points) > n else points
