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

