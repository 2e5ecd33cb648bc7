"""Extent and degree of deformation (docs/model.md §5, thesis §4.1.1).

Extent of a deformed breast: mean normalised distance of corresponding points,
‖p_ij,k − p_i0,k‖ / ‖p_i0,k‖ (Eq. 4.2). Top-shape uses a signed extent instead: the mean
z-change of the upper half (y > 0) divided by a5, because its unsigned extents of
opposite-sign parameters overlap (docs/model.md §5). Degrees compare an extent with the
reference extents E_0j of P00 (generic shape, all semi-axes 10) under the same rows.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from breastplan import Primitive

from .conditions import Condition
from .global_deformations import Deformation, changing

GENERIC_SHAPE = Deformation(turn=(0.38, 0.0), turn_top=(0.41, 0.0))
"""Database V's generic breast shape (docs/model.md §4, Table 4.1)."""
P00 = Primitive()
"""The reference primitive: all semi-axes 10 mu, eps = (1, 1)."""


def extent(original, deformed) -> np.ndarray:
    """Mean normalised point distance over the point axis (-2); any leading batch axes."""
    o = np.asarray(original, dtype=float)
    d = np.asarray(deformed, dtype=float)
    return np.mean(np.linalg.norm(d - o, axis=-1) / np.linalg.norm(o, axis=-1), axis=-1)


def signed_extent(original, deformed, a5) -> np.ndarray:
    """Mean signed z-change of the upper half (original y > 0), divided by a5 (docs/model.md §5)."""
    o = np.asarray(original, dtype=float)
    d = np.asarray(deformed, dtype=float)
    upper = o[..., 1] > 0
    dz = np.where(upper, d[..., 2] - o[..., 2], 0.0).sum(axis=-1) / upper.sum(axis=-1)
    return dz / np.asarray(a5, dtype=float)


def condition_extent(condition: Condition, original, deformed, primitive: Primitive) -> np.ndarray:
    """The extent the condition's degrees are defined on (signed for top-shape)."""
    if condition.signed:
        return signed_extent(original, deformed, primitive.a5)
    return extent(original, deformed)


def reference_points(n_u: int = 100, n_v: int = 100) -> np.ndarray:
    """P00 with the generic shape, sampled on the (u, v) grid (model units)."""
    return GENERIC_SHAPE.apply(P00.sample(n_u, n_v), P00)


@lru_cache(maxsize=64)
def _reference_extents(name: str, kind: str, first, last, dd: int, n_u: int, n_v: int) -> np.ndarray:
    cond = Condition(name, kind, first, last)
    p0, move = reference_points(n_u, n_v), changing(kind, P00.sample(n_u, n_v), GENERIC_SHAPE, P00)
    ext = [condition_extent(cond, p0, move(row), P00) for row in cond.rows(dd)]
    out = np.array(ext)
    out.setflags(write=False)
    return out


def reference_extents(condition: Condition, dd: int, n_u: int = 100, n_v: int = 100) -> np.ndarray:
    """E_0j, j = 1..dd: extents of P00 under the condition's rows (cached)."""
    c = condition
    return _reference_extents(c.name, c.kind, c.first, c.last, dd, n_u, n_v)


def discrete_degree(extents, reference) -> np.ndarray:
    """Thesis degree: argmin_j |E − E_0j| + 1, integers 1..#dd (ends clip naturally)."""
    e = np.asarray(extents, dtype=float)
    ref = np.asarray(reference, dtype=float)
    return np.argmin(np.abs(e[..., None] - ref), axis=-1) + 1


def continuous_degree(extents, reference) -> np.ndarray:
    """Piecewise-linear degree over the reference extents, extended past degrees 1 and #dd along
    the end segments; rounded and clipped to [1, #dd] it is the discrete degree.

    The thesis clips it to [1, #dd]; docs/model.md §5 extends it: on database S many examples
    lie beyond the reference extents (ζ = z/10 is in model units, so a larger breast deforms more),
    and a clipped degree maps them all to the line's end, so neither the exact solver nor a
    learnt model could recover their row. Unclipped, degree and extent determine each other.
    """
    ref = np.asarray(reference, dtype=float)
    e = np.asarray(extents, dtype=float)
    if ref[-1] < ref[0]:  # a decreasing signed extent (top-shape s0⁻ > s1⁺)
        ref, e = -ref, -e
    if np.any(np.diff(ref) <= 0):
        raise ValueError("reference extents are not monotone; no continuous degree exists")
    return _line(e, ref, np.arange(1, len(ref) + 1, dtype=float))


def degree_extent(degree, reference) -> np.ndarray:
    """The reference extent of a continuous degree: the inverse of `continuous_degree`."""
    ref = np.asarray(reference, dtype=float)
    return _line(np.asarray(degree, dtype=float), np.arange(1, len(ref) + 1, dtype=float), ref)


def _line(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """Piecewise-linear through (xp, fp), xp increasing, continued straight past both ends."""
    y = np.interp(x, xp, fp)
    y = np.where(x < xp[0], fp[0] + (x - xp[0]) * (fp[1] - fp[0]) / (xp[1] - xp[0]), y)
    return np.where(x > xp[-1], fp[-1] + (x - xp[-1]) * (fp[-1] - fp[-2]) / (xp[-1] - xp[-2]), y)
