"""Units (docs/model.md §1): scans in millimetres, model formulas in model units, 1 mu = 6 mm.

Conversion happens once, at the boundary between files (mm) and the model (mu).
"""
from __future__ import annotations

import numpy as np

MM_PER_MU = 6.0
"""Millimetres per model unit (docs/model.md §1): P00's 10-mu semi-axes are 60 mm."""


def to_model_units(mm):
    """Lengths or points in mm → model units."""
    return np.asarray(mm, dtype=float) / MM_PER_MU


def to_mm(mu):
    """Lengths or points in model units → mm."""
    return np.asarray(mu, dtype=float) * MM_PER_MU


def mu3_to_cc(volume_mu3):
    """Volume in cubic model units → cubic centimetres (1 cc = 1000 mm³)."""
    return np.asarray(volume_mu3, dtype=float) * MM_PER_MU**3 / 1000.0


BREAST_EXTENT_MM = (20.0, 600.0)
"""A breast (or its fit) in millimetres spans more than 20 mm and less than 600 mm (the base of the
smallest breast is some 80 mm across, of the largest some 350 mm)."""
BREAST_VOLUME_CC = 12_000.0
"""More than any breast holds: about twice the heaviest tissue removed from one breast in the reports of
gigantomastia we found (6.6 kg, at about 1 g per cc). A larger measure is a failed one."""
FLAT_RATIO = 0.05
"""A breast rises from its base by more than this share of its width (a flat chest by some 0.1)."""
SCAN_EXTENT_MM = 8000.0
"""A scan of a patient in millimetres, the room around her included, spans less than 8 m (the
range of a depth camera)."""
FAR_EXTENT_MM = 3.0e6
"""More than a body spans even in micrometres (3 m): a point lies far from the others."""


def extent(points) -> float:
    """The largest side of the axis-aligned bounding box of (N, 3) points (0 for none; inf on overflow)."""
    p = np.asarray(points, dtype=float)
    if not p.size:
        return 0.0
    with np.errstate(over="ignore", invalid="ignore"):      # ±1e308 coordinates: an infinite extent
        return float(np.max(p.max(axis=0) - p.min(axis=0)))


def breast_points_problem(points_mm) -> str | None:
    """Why (N, 3) points cannot be a breast in millimetres in its breast frame (base on z = 0, rising
    along +z), judged by their extent and shape, or None."""
    size = extent(points_mm)
    if size == 0.0:
        return "has all its points at one place: no surface"
    if size < BREAST_EXTENT_MM[0]:
        return (f"spans only {size:.3g} units, too little for a breast in millimetres "
                f"(is it in {'metres' if size < 2.0 else 'centimetres'}?)")
    if size > FAR_EXTENT_MM:
        return (f"spans {size:.3g} units, more than any body in millimetres or micrometres "
                f"(a point lies far from the others?)")
    if size > SCAN_EXTENT_MM:
        return (f"spans {size:.4g} units, more than a breast or a whole body in millimetres "
                f"(is it in micrometres?)")
    if size > BREAST_EXTENT_MM[1]:
        return (f"spans {size:.4g} mm, far too large for one breast: if it is a whole scan, "
                f"`breastplan ingest` (or `breastplan plan`) cuts its breast out first")
    p = np.asarray(points_mm, dtype=float)
    thickness = np.sqrt(max(np.linalg.eigvalsh(np.cov((p - p.mean(0)).T))[0], 0.0)) * np.sqrt(12.0)
    if thickness < FLAT_RATIO * size:
        return f"is flat (some {thickness:.3g} mm thick over {size:.4g} mm): no breast rises from it"
    if np.median(p[:, 2]) < 0.0:
        return "lies mostly below z = 0: a breast rises from its base along +z (is its z axis reversed?)"
    return None


def volume_problem(cc: float) -> str | None:
    """Why `cc` cannot be a breast's volume (not a number, negative, more than any breast holds), or None."""
    if not np.isfinite(cc):
        return "not a number"
    if cc < 0.0:
        return "a negative volume"
    if cc > BREAST_VOLUME_CC:
        return f"more than any breast holds ({BREAST_VOLUME_CC:,.0f} cc)"
    return None


def displacement_problem(before_mm, after_mm) -> tuple[np.ndarray, str | None]:
    """Each point's displacement (mm) from `before_mm` to `after_mm` (..., 3), and why they cannot be a
    change of a breast (points sent to infinity, or moved further than any breast spans), or None."""
    with np.errstate(over="ignore", invalid="ignore"):
        shift = np.linalg.norm(np.asarray(after_mm, float) - before_mm, axis=-1)
    if not np.isfinite(shift).all():
        return shift, "sends points to infinity"
    if shift.max() > BREAST_EXTENT_MM[1]:
        return shift, f"moves points by {shift.max():.3g} mm, more than any breast spans ({BREAST_EXTENT_MM[1]:g} mm)"
    return shift, None
