"""Fitting the chest wall: a robust polynomial height field through the torso, mounds excluded.

Works in a viewing frame (`breastplan.chest_wall`). Points well in front of the surface
(the breast mounds) and well behind it (flanks, shoulders) are excluded iteratively, so the
surface under the breasts is interpolated from the chest around them.
"""
from __future__ import annotations

import numpy as np

from breastplan.chest_wall import ChestWall, exponents


def fit_chest_wall(points: np.ndarray, degree: int = 2, mask: np.ndarray | None = None,
                   front_mm: float = 4.0, back_mm: float = 8.0, keep: float = 0.5,
                   iterations: int = 12) -> ChestWall:
    """Robust least-squares height field through `points` (N, 3) (only those in `mask`, if given).

    The first iterations keep the fraction `keep` of points with the smallest residuals
    (least trimmed squares: robust to any start); the later ones keep residuals within
    max(3σ, front_mm) in front of the surface and max(3σ, back_mm) behind it, σ the MAD
    scale of the inliers.
    """
    p = np.asarray(points, float)
    allowed = np.ones(len(p), bool) if mask is None else np.asarray(mask, bool)
    inlier = allowed.copy()
    wall = ChestWall(np.zeros(len(exponents(degree))), degree, np.median(p[allowed, :2], axis=0), 0.0)
    A = wall.basis(p)
    for it in range(iterations):
        coef, *_ = np.linalg.lstsq(A[inlier], p[inlier, 2], rcond=None)
        r = p[:, 2] - A @ coef  # > 0 behind the surface, < 0 in front (mounds)
        if it < iterations // 2:
            new = allowed & (np.abs(r) <= np.quantile(np.abs(r[allowed]), keep))
        else:
            sigma = max(1.4826 * float(np.median(np.abs(r[inlier]))), 0.5)
            new = allowed & (r > -max(3 * sigma, front_mm)) & (r < max(3 * sigma, back_mm))
            if (new == inlier).all():
                break
        inlier = new
    sigma = 1.4826 * float(np.median(np.abs(r[inlier])))
    return ChestWall(coef, degree, wall.centre, sigma)
