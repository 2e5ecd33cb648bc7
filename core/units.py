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



BREAST_EXTENT_MM = (5.0, 1000.0)
"""A breast (or its fit) in millimetres spans more than 5 mm and less than a metre."""


def breast_units_problem(points_mm) -> str | None:
    """Why (N, 3) points cannot be a breast in millimetres, judged by their extent, or None."""
    p = np.asarray(points_mm, dtype=float)
    extent = float(np.ptp(p, axis=0).max()) if p.size else 0.0
    if extent == 0.0:
        return "has all its points at one place: no surface"
    if extent < BREAST_EXTENT_MM[0]:
        return f"spans only {extent:.3g} units, too little for a breast in millimetres (is it in metres?)"
    if extent > BREAST_EXTENT_MM[1]:
        return f"spans {extent:.4g} units, too much for a breast in millimetres (is it in micrometres?)"
    return None
