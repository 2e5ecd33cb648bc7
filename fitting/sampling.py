"""What makes a fit a function of its point set alone: the canonical order the fits work in, the
seeded subsets they solve on (drawn in that order: the same points whatever the caller's order),
and the one BLAS thread they run on (the same sums whatever the machine's thread count)."""
from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np
from threadpoolctl import threadpool_limits

_within = threading.local()


def canonical_order(points: np.ndarray) -> np.ndarray:
    """Indices that put (N, 3) points in lexicographic order of their coordinates (x, then y, then
    z): any order of the same points comes out as the same array (equal points are interchangeable),
    so every subset, sum and discrete choice of a fit made in it is the same too."""
    p = np.asarray(points)
    return np.lexsort(p.T[::-1])


def in_caller_order(order: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per-point values computed in canonical order (`canonical_order`'s `order`), back in the
    caller's order."""
    out = np.empty_like(values)
    out[order] = values
    return out


def seeded_subset(points: np.ndarray, n: int) -> np.ndarray:
    """A seeded random subset of n points (all of them if there are fewer), drawn by position in
    `points`: the fits pass them in canonical order, so it is a subset of the point set."""
    return points[np.random.default_rng(0).choice(len(points), n, replace=False)] if len(points) > n else points


@contextmanager
def one_blas_thread():
    """Context in which BLAS and LAPACK run on one thread: OpenBLAS sums a product (sgemm, syrk) or
    factorises (getrf) in another order on two threads, which moves a fit's last bits and, through
    its accept/reject and stopping decisions, its result. Within another such context (a stage of
    `fit_breast`) it does nothing: setting the limit costs milliseconds."""
    if getattr(_within, "depth", 0):
        yield
        return
    _within.depth = 1
    try:
        with threadpool_limits(1, "blas"):
            yield
    finally:
        _within.depth = 0
