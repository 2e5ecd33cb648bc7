"""What makes a fit a function of its point set alone, beside the canonical order it works in
(`breastplan.point_order`): the seeded subsets it solves on (drawn in that order: the same points
whatever the caller's order), and the one BLAS thread it runs on (the same sums whatever the
machine's thread count)."""
from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np
from threadpoolctl import threadpool_limits

_within = threading.local()


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
