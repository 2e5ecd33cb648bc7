"""What makes a fit a function of its point set alone: the subsets it solves on (chosen by the points'
positions, not by their index in any order, so that a last-bit change upstream, another machine's rounding,
picks the same points), and the one BLAS thread it runs on (the same sums whatever the machine's thread
count)."""
from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np
from threadpoolctl import threadpool_limits

_within = threading.local()
_MIX = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))


def position_subset(points: np.ndarray, n: int) -> np.ndarray:
    """n of the (N, 3) points (all of them if there are fewer), in an order that looks random and depends on
    each point's position alone: the points ranked by a hash of their coordinates rounded to float32 (a
    relative 6e-8: far above a last-bit change, far below the spacing of a scan's points). The same point set
    gives the same subset in any order, and the first n of a subset of n' > n are the first n of the whole."""
    p = np.asarray(points)
    if len(p) <= n:
        return p
    bits = np.ascontiguousarray(p, np.float32).view(np.uint32).astype(np.uint64)
    h = np.zeros(len(p), np.uint64)
    with np.errstate(over="ignore"):
        for c in range(3):
            h = (h ^ bits[:, c]) * _MIX[c]
            h ^= h >> np.uint64(31)
    return p[np.lexsort((*p.T[::-1], h))[:n]]             # equal hashes: in lexicographic order, x first


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
