"""Metrics of the learned models (docs/model.md §7, thesis §4.2.4).

Direct metrics compare predicted with target parameters (RMSE%, MPE%, Eq. 4.23–4.24).
Indirect metrics compare the true deformed breast ("Original", O) with the one deformed by
the predicted parameters ("Modelled", M): nearest-point distances in both directions,
normalised by the original point's distance to the origin (Eq. 4.2), averaged (Euclidean)
or maximised (Hausdorff, Eq. 4.25). Methods are compared with a t-test at α = 0.05.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import stats
from scipy.spatial import cKDTree

ALPHA = 0.05
"""Significance level of `ttest` (docs/model.md §7)."""
INDIRECT_KEYS = ("modelled_to_original_euclidean", "modelled_to_original_hausdorff",
                 "original_to_modelled_euclidean", "original_to_modelled_hausdorff", "modelled_to_original_median")


def _pair(predicted, target) -> tuple[np.ndarray, np.ndarray]:
    f = np.asarray(predicted, dtype=float)
    y = np.asarray(target, dtype=float)
    if f.shape != y.shape or f.ndim not in (1, 2):
        raise ValueError(f"predicted {f.shape} and target {y.shape} must be equal (n,) or (n, k)")
    return f, y


def _column_result(values: np.ndarray):
    return float(values) if values.ndim == 0 else values


def rmse_pct(predicted, target):
    """Relative RMSE in %: sqrt(mean((f − y)²)) / |mean(y)| · 100 per column (Eq. 4.23).

    |mean(y)| rather than mean(y) because some targets are negative (top-shape s0), which
    would make the error negative. (n,) gives a float, (n, k) a (k,) array; a column whose
    targets average to 0 has no relative error and gives NaN.
    """
    f, y = _pair(predicted, target)
    rmse = np.sqrt(np.mean((f - y) ** 2, axis=0))
    scale = np.abs(np.mean(y, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(scale > 0, rmse / scale * 100.0, np.nan)
    return _column_result(out)


def mpe_pct(predicted, target):
    """Mean percentage error: mean(|f − y| / |y|) · 100 per column over the entries y ≠ 0 (Eq. 4.24).

    A parameter held at 0 has no relative error, so its entries are left out; a column
    with no entry y ≠ 0 gives NaN. (n,) gives a float, (n, k) a (k,) array.
    """
    f, y = _pair(predicted, target)
    valid = y != 0
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(valid, np.abs(f - y) / np.abs(y), 0.0)
        out = rel.sum(axis=0) / valid.sum(axis=0) * 100.0
    return _column_result(out)


def _points(p, name: str) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"{name} must be a non-empty (N, 3) point set, not {p.shape}")
    return p


def _indirect(original, modelled, workers: int) -> tuple[float, ...]:
    """The values of `indirect_distances` (unbalanced trees: half the build time, exact)."""
    o = _points(original, "original")
    m = _points(modelled, "modelled")
    o_norm = np.linalg.norm(o, axis=1)
    d_mo, nearest_o = cKDTree(o, balanced_tree=False).query(m, workers=workers)
    d_om, _ = cKDTree(m, balanced_tree=False).query(o, workers=workers)
    mo = d_mo / o_norm[nearest_o] * 100.0
    om = d_om / o_norm * 100.0
    return float(mo.mean()), float(mo.max()), float(om.mean()), float(om.max()), float(np.median(mo))


def indirect_distances(original, modelled) -> dict[str, float]:
    """Both-direction normalised nearest-point distances of one breast, in % (docs/model.md §7).

    `original`, `modelled`: (N, 3) and (M, 3) points in one frame and unit; they need not
    correspond. Modelled→original: each m's distance to its nearest original o* is
    ‖m − o*‖ / ‖o*‖; original→modelled: ‖o − m*‖ / ‖o‖ — always normalised by the original
    point (Eq. 4.2), so no original point may sit at the origin. Euclidean is the mean,
    Hausdorff the max (Eq. 4.25) over the query points; the modelled→original median too, the
    yardstick of `spike_ratios`.
    """
    return dict(zip(INDIRECT_KEYS, _indirect(original, modelled, workers=-1)))


def indirect_metrics(originals, modelled, threads: int | None = None) -> dict[str, np.ndarray]:
    """`indirect_distances` per example: (n_examples, N, 3) pairs → INDIRECT_KEYS → (n_examples,) %.

    Examples run on `threads` threads (default: all cores), one KD-tree query thread each:
    cKDTree releases the GIL, and this beats one example at a time with threaded queries
    because the tree builds run in parallel too.
    """
    if len(originals) != len(modelled):
        raise ValueError(f"{len(originals)} originals but {len(modelled)} modelled breasts")
    with ThreadPoolExecutor(threads or os.cpu_count() or 1) as pool:
        rows = list(pool.map(lambda o, m: _indirect(o, m, workers=1), originals, modelled))
    values = np.array(rows, dtype=float).reshape(len(rows), len(INDIRECT_KEYS))
    return dict(zip(INDIRECT_KEYS, values.T.copy()))


def spike_ratios(distances: dict[str, np.ndarray]) -> np.ndarray:
    """(n,) largest / median modelled→original distance of each modelled breast (`indirect_metrics`'
    result): its Hausdorff over the median of the distances its Euclidean averages. A smooth error
    stays within a few times its median; a control point gone astray makes a local spike far above it."""
    return distances["modelled_to_original_hausdorff"] / np.maximum(distances["modelled_to_original_median"], 1e-12)


def vertex_spike_ratios(truths: np.ndarray, modelled: np.ndarray) -> np.ndarray:
    """(n,) largest / median vertex error of each modelled breast, the vertex error being the distance
    (mm) of each modelled point to its true position (`truths` correspond to `modelled` point for
    point): a stricter yardstick than `spike_ratios`, which also counts how points slide along the
    surface."""
    errors = np.linalg.norm(np.asarray(modelled, float) - np.asarray(truths, float), axis=-1)
    return errors.max(axis=1) / np.maximum(np.median(errors, axis=1), 1e-12)


def summary(values) -> dict[str, float]:
    """Mean, sample SD (ddof = 1; NaN for one value), min and max, as in thesis Tables 5.4–5.8."""
    v = np.asarray(values, dtype=float).ravel()
    if v.size == 0:
        raise ValueError("summary of no values")
    sd = float(np.std(v, ddof=1)) if v.size > 1 else float("nan")
    return {"mean": float(v.mean()), "sd": sd, "min": float(v.min()), "max": float(v.max())}


def ttest(a, b) -> dict[str, float | bool]:
    """Independent-samples t-test of two methods' errors, α = 0.05 (docs/model.md §7).

    Pooled-variance (Student) test: the classical independent-samples test the thesis names,
    and the methods are compared on the same test examples, so the groups have equal sizes,
    where the pooled test is robust to unequal variances.
    """
    res = stats.ttest_ind(np.asarray(a, dtype=float), np.asarray(b, dtype=float), equal_var=True)
    t, p = float(res.statistic), float(res.pvalue)
    return {"t": t, "p": p, "significant": bool(p < ALPHA)}
