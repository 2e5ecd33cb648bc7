"""Figures of the learned models: the residual six-plot (docs/model.md §7, thesis §4.2.4).

Figures are built as `matplotlib.figure.Figure` objects on the Agg canvas (no pyplot state,
no GUI), so they are safe to draw from several threads, and written atomically.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy import stats

from breastplan.atomic import atomic_open

_DPI = 100
_SIZE_IN = (9.0, 5.5)
_DOT = {"s": 6, "alpha": 0.5, "linewidths": 0}


def _png_bytes(fig: Figure) -> bytes:
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    return buf.getvalue()


def six_plot(target, predicted, path: str | Path, title: str) -> Path:
    """Residual six-plot of one output as a PNG at `path` (docs/model.md §7); returns the path.

    Panels: predicted vs target (with y = x), residual vs target, residual vs predicted,
    lag plot (residual k vs k − 1), histogram and normal probability plot of the residuals,
    where residual = predicted − target. `target`, `predicted`: equal-length 1-D arrays.
    """
    y = np.asarray(target, dtype=float)
    f = np.asarray(predicted, dtype=float)
    if y.ndim != 1 or f.shape != y.shape or y.size < 2:
        raise ValueError(f"six_plot needs two equal 1-D arrays of ≥ 2 values, not {y.shape} and {f.shape}")
    r = f - y
    fig = Figure(figsize=_SIZE_IN, dpi=_DPI, layout="constrained")
    fig.suptitle(title)
    ax = fig.subplots(2, 3).ravel()

    ax[0].scatter(y, f, **_DOT)
    lo, hi = min(y.min(), f.min()), max(y.max(), f.max())
    ax[0].plot([lo, hi], [lo, hi], color="C3", lw=1, label="y = x")
    ax[0].legend(loc="upper left", fontsize="small")
    ax[0].set(title="predicted vs target", xlabel="target", ylabel="predicted")
    for a, x, name in ((ax[1], y, "target"), (ax[2], f, "predicted")):
        a.scatter(x, r, **_DOT)
        a.axhline(0, color="C3", lw=1)
        a.set(title=f"residual vs {name}", xlabel=name, ylabel="residual")
    ax[3].scatter(r[:-1], r[1:], **_DOT)
    ax[3].set(title="lag plot", xlabel="residual k − 1", ylabel="residual k")
    ax[4].hist(r, bins="sturges", color="C0")
    ax[4].set(title="histogram", xlabel="residual", ylabel="count")
    (osm, osr), (slope, intercept, _) = stats.probplot(r)
    ax[5].scatter(osm, osr, **_DOT)
    ax[5].plot(osm, slope * osm + intercept, color="C3", lw=1)
    ax[5].set(title="normal probability plot", xlabel="normal quantile", ylabel="ordered residual")

    png = _png_bytes(fig)
    with atomic_open(path) as fh:
        fh.write(png)
    return Path(path)
