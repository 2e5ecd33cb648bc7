"""Many states of one surface stored compactly: their displacements as a few shared modes.

The report carries every state its sliders reach (hundreds), each a displacement of the same points. Those
displacements span few dimensions (a handful of deformation parameters move them), so they are stored as K
modes shared by every state and K coefficients per state: state i ≈ Σₖ coefficients[i, k] · scales[k] ·
modes[k], the modes quantised to int16. K is the fewest leading modes whose reconstruction, quantised as stored,
puts no point of any state farther than TOLERANCE_MM from where the plan computed it (checked on every state, not
estimated): sought among the modes whose singular value exceeds TOLERANCE_MM, on a sample of the states first,
then, if every state is not held so, on every state from there.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TOLERANCE_MM = 0.05
"""No point of any state is drawn farther than this from where the plan put it (mm): a fifth of a pixel of the
report's view of her torso, and a tenth of the scan's noise."""


@dataclass(frozen=True, eq=False)
class Modes:
    """States' displacements (S states of N points) as K shared modes: `decode` gives them back."""

    coefficients: np.ndarray    # (S, K) float32
    modes: np.ndarray           # (K, N, 3) int16
    scales: np.ndarray          # (K,) float32, mm per step of each mode
    worst_mm: float             # the largest distance of a decoded point from its state's

    def decode(self, i: int | slice = slice(None)) -> np.ndarray:
        """The displacements of state(s) i as stored ((N, 3) or (S', N, 3), mm), as the page rebuilds them."""
        weights = self.coefficients[i].astype(np.float64) * self.scales
        return np.tensordot(weights, self.modes.astype(np.float64), axes=(-1, 0))


STATES_AT_ONCE = 64
"""States decoded at a time when checking the modes (their displacements held at once)."""
SAMPLED_STATES = 64
"""States, spread evenly over them, on which the fewest modes are first sought (each check of every state costs
as much as projecting them all)."""


def modes_of(displacements: np.ndarray) -> Modes:
    """`displacements` (S, N, 3) (mm) as the fewest modes that hold every state within TOLERANCE_MM."""
    S, shape = len(displacements), displacements.shape[1:]
    X = np.asarray(displacements).reshape(S, -1)
    gram = np.zeros((S, S))
    for at in range(0, X.shape[1], 4096):                       # the states' Gram matrix, in float64
        part = X[:, at:at + 4096].astype(np.float64)
        gram += part @ part.T
    values, vectors = np.linalg.eigh(gram)
    order = np.argsort(values)[::-1]
    values, vectors = np.clip(values[order], 0.0, None), vectors[:, order]
    top = int(np.sum(np.sqrt(values) > TOLERANCE_MM))           # the modes that can move a point by the tolerance
    sample = np.unique(np.linspace(0, S - 1, min(S, SAMPLED_STATES)).round().astype(int))
    while True:
        out = _quantised(X, vectors[:, :top], shape)
        k = _fewest(out, X[sample], sample)
        if (worst := _worst(out, X, k)) > TOLERANCE_MM:                        # checked on every state
            k = _fewest(out, X, np.arange(S), k + 1)
            worst = _worst(out, X, k)
        if worst <= TOLERANCE_MM or top >= S:
            return Modes(out.coefficients[:, :k].copy(), out.modes[:k].copy(), out.scales[:k].copy(), worst)
        top += 1


def _quantised(X: np.ndarray, vectors: np.ndarray, shape) -> Modes:
    """X's projection onto the K state-space `vectors` (orthonormal), its modes quantised to int16 (worst error not
    yet checked: inf)."""
    basis = np.zeros((vectors.shape[1], X.shape[1]))                                  # (K, M): each mode with its σ
    for at in range(0, len(X), STATES_AT_ONCE):
        basis += vectors[at:at + STATES_AT_ONCE].T @ X[at:at + STATES_AT_ONCE].astype(np.float64)
    steps = np.abs(basis).max(axis=1) / 32767.0 if basis.size else np.zeros(len(basis))
    steps = np.where(steps > 0, steps, 1.0).astype(np.float32)
    return Modes(vectors.astype(np.float32), np.round(basis / steps[:, None]).astype(np.int16).reshape(-1, *shape),
                 steps, np.inf)


def _worst(modes: Modes, X: np.ndarray, k: int, rows: np.ndarray | None = None) -> float:
    """The largest distance (mm) of a point of the states X (S', M) from its reconstruction by the first k of `modes`,
    decoded as the page does (float32 is ample here); `rows`: the states of `modes` that X holds (default all)."""
    rows = np.arange(len(X)) if rows is None else rows
    weights = modes.coefficients[rows, :k] * modes.scales[:k]
    flat = modes.modes[:k].reshape(k, X.shape[1]).astype(np.float32)
    worst = 0.0
    for at in range(0, len(X), STATES_AT_ONCE):
        error = np.square(weights[at:at + STATES_AT_ONCE] @ flat - X[at:at + STATES_AT_ONCE]).reshape(-1, 3)
        worst = max(worst, float(np.sqrt(error.sum(axis=1).max())) if error.size else 0.0)
    return worst


def _fewest(modes: Modes, X: np.ndarray, rows: np.ndarray, lo: int = 0) -> int:
    """The fewest leading `modes`, from `lo` on, that hold the states X (those of `rows`) within TOLERANCE_MM
    (bisection: the error falls as modes are added), or all of them."""
    hi = len(modes.scales)
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if _worst(modes, X, mid, rows) <= TOLERANCE_MM else (mid + 1, hi)
    return lo
