"""Scalar descriptors of a breast point set, the inputs of the learnt deformation models.

Thesis Table 4.3 describes a breast by its volume v0 and its mean point; top-shape adds the
upper-pole profile. Every descriptor is computed from the points alone (mm, breast
frame), so training on database breasts and deploying on a patient use one definition.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from breastplan import BadInputError

PROFILE_BINS = 5
"""Height bins of the upper-pole profile (y > 0)."""
AXES = {"ptosis": (1, 2), "turn": (0, 2), "top-shape": (2, 1)}
"""kind → (moved axis, driver axis) in the breast frame."""


def hull_volume_cc(points_mm) -> float:
    """Volume (cc) of the convex hull of the points: v0 for any point set, faces or not.

    A database breast's hull is within a few % of its closed-surface volume (the base is flat);
    the learnt models only need one definition shared by training and use.
    """
    try:
        return ConvexHull(np.asarray(points_mm, dtype=float)).volume / 1000.0
    except QhullError:
        raise BadInputError(None, "the breast points span no volume (flat or too few points)") from None


def upper_profile(points_mm, bins: int = PROFILE_BINS) -> np.ndarray:
    """Mean height z of the upper pole (y > 0) in `bins` bands of y / max(y), over max(z).

    The top-shape deformation changes exactly this profile (docs/model.md §3); empty bands borrow
    their neighbours' value by linear interpolation.
    """
    p = np.asarray(points_mm, dtype=float)
    upper = p[p[:, 1] > 0]
    if len(upper) < bins:
        raise BadInputError(None, f"the breast has fewer than {bins} points on its upper pole (y > 0)")
    band = np.minimum((upper[:, 1] / upper[:, 1].max() * bins).astype(int), bins - 1)
    count = np.bincount(band, minlength=bins)
    height = np.bincount(band, weights=upper[:, 2], minlength=bins) / np.maximum(count, 1)
    full = count > 0
    height = np.interp(np.arange(bins), np.flatnonzero(full), height[full])
    return height / max(p[:, 2].max(), 1e-9)


def scalar_names(feature_set: str, kind: str) -> list[str]:
    """Names of the scalar columns of a feature set (its vector blocks become PCA scores)."""
    if feature_set != "FS5":
        return ["DD", "v0"]
    return ["DD", "v0", "d0", "m0"] + ([f"profile{i}" for i in range(PROFILE_BINS)] if kind == "top-shape" else [])


def breast_scalars(points_mm, kind: str, feature_set: str = "FS5") -> np.ndarray:
    """The scalar features of one breast besides DD: v0 (cc), and for FS5 the mean point's
    driver and moved coordinates (mm) and, for top-shape, the upper-pole profile."""
    out = [hull_volume_cc(points_mm)]
    if feature_set == "FS5":
        moved, driver = AXES[kind]
        mean = np.asarray(points_mm, dtype=float).mean(axis=0)
        out += [mean[driver], mean[moved]]
        if kind == "top-shape":
            out += list(upper_profile(points_mm))
    return np.array(out)
