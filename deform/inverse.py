"""Exact inverse solver: where on a condition's line a breast reaches a target degree.

A condition is a line t ∈ [0, 1] in its kind's parameter space (docs/model.md §4). On that line
the breast's extent (docs/model.md §5; signed for top-shape) is monotone, so the position whose
extent equals the reference extent of the target degree is a 1-D root (`scipy.optimize.brentq`).
A continuous degree targets the piecewise-linear reference extent at d (continued past 1 and
#dd, `degree.continuous_degree`), so the degree of an example recovers its row exactly; a
discrete degree targets E_0d itself. This is the upper bound no learnt model can pass, and what
`plan` uses when the deformation is known.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from breastplan import Primitive

from .conditions import Condition
from .degree import condition_extent, degree_extent, reference_extents
from .global_deformations import apply_kind

XTOL = 1e-12
"""Tolerance on the line position t (dimensionless)."""
REACHED = 1e-9
"""Relative extent error under which a line end counts as reaching the target."""


@dataclass(frozen=True)
class InverseSolution:
    """The position t on the condition's line, its parameters (model units) and its extent."""

    t: float
    params: np.ndarray
    extent: float
    target_extent: float
    reached: bool       # False when the target lies beyond the line's ends (t clipped to 0 or 1)


def target_extent(condition: Condition, dd: int, degree: float, grid: tuple[int, int] = (100, 100)) -> float:
    """The reference extent of a (continuous) degree: E_0 interpolated (docs/model.md §5)."""
    if not np.isfinite(degree):
        raise ValueError(f"a degree of {condition.name} must be a finite number, got {degree}")
    return float(degree_extent(degree, reference_extents(condition, dd, *grid)))


def solve_degree(points_mu, condition: Condition, dd: int, degree: float, primitive: Primitive | None = None,
                 grid: tuple[int, int] = (100, 100), move: Callable | None = None) -> InverseSolution:
    """The parameters of `condition` that give the breast `points_mu` (model units, breast frame) the
    extent of `degree`; `grid` is the (n_u, n_v) sampling of the reference breast P00. `move(params)`
    deforms the breast (default: the condition's kind applied on top of `points_mu`; a database
    breast passes `Database.changer`, which changes its own parameters)."""
    p = np.asarray(points_mu, dtype=float)
    goal = target_extent(condition, dd, degree, grid)
    move = move or (lambda params: apply_kind(p, condition.kind, params, primitive))

    def excess(t: float) -> float:
        return float(condition_extent(condition, p, move(condition.at(t)), primitive)) - goal

    ends = excess(0.0), excess(1.0)
    if ends[0] * ends[1] > 0:               # the target lies beyond the line: its nearer end,
        t = float(np.argmin(np.abs(ends)))  # reached if only rounding separates them (a row's own degree)
        reached = abs(ends[int(t)]) <= REACHED * abs(goal)
    else:
        t = brentq(excess, 0.0, 1.0, xtol=XTOL, rtol=4 * np.finfo(float).eps)
        reached = True
    return InverseSolution(t=t, params=condition.at(t), extent=excess(t) + goal, target_extent=goal,
                           reached=reached)
