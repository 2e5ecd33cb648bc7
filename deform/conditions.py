"""Deformation conditions and their parameter rows (docs/model.md §4, thesis Table 4.2).

A condition is a line in one kind's parameter space from a first to a last row; with
#dd degrees, row j is the linear interpolation between them (first and last never move).
The table is plain data: the `breastplan` command lists the conditions in its help without
loading numpy, which `Condition.at` and `rows` import when they compute.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from .names import KIND_PARAMS

if TYPE_CHECKING:
    import numpy as np


@dataclass(frozen=True)
class Condition:
    """A named parameter line of one deformation kind (all of the kind's parameters)."""

    name: str
    kind: str
    first: tuple[float, ...]
    last: tuple[float, ...]

    @property
    def param_names(self) -> tuple[str, ...]:
        return KIND_PARAMS[self.kind]

    @property
    def signed(self) -> bool:
        """Top-shape degrees use the signed extent (docs/model.md §5)."""
        return self.kind == "top-shape"

    def at(self, t) -> np.ndarray:
        """Parameters at position t ∈ [0, 1] on the line (t may be an array: (..., n_params))."""
        import numpy as np

        t = np.asarray(t, dtype=float)[..., None]
        first, last = np.array(self.first), np.array(self.last)
        return first + t * (last - first)

    def rows(self, dd: int) -> np.ndarray:
        """(dd, n_params) parameter matrix: row j interpolates first → last."""
        if dd < 2:
            raise ValueError(f"the number of degrees must be at least 2, got {dd}")
        import numpy as np

        return self.at(np.linspace(0.0, 1.0, dd))


CONDITIONS: dict[str, Condition] = {c.name: c for c in [
    Condition("ptosis b0", "ptosis", (0.45, 0.0), (2.25, 0.0)),
    Condition("ptosis b1", "ptosis", (0.0, 0.1), (0.0, 0.5)),
    Condition("ptosis b0>b1", "ptosis", (0.225, 0.05), (1.125, 0.25)),
    Condition("ptosis b1>=b0", "ptosis", (0.05, 0.1), (0.5, 0.5)),
    Condition("turn c0>c1", "turn", (0.3, 0.05), (1.1, 0.5)),
    Condition("turn c1>c0", "turn", (0.05, 0.125), (0.5, 0.625)),
    Condition("top-shape s0->s1+", "top-shape", (-0.5, 0.25, 0.0, 0.0), (-2.5, 2.0, 0.0, 0.0)),
    Condition("top-shape s1->s0+", "top-shape", (0.25, -0.5, 0.0, 0.0), (1.75, -2.0, 0.0, 0.0)),
]}
"""The eight conditions of docs/model.md §4 by canonical name."""


def _normalise(name: str) -> str:
    for a, b in (("≥", ">="), ("⁻", "-"), ("⁺", "+"), ("only", ""), ("_", "-"), (" ", "")):
        name = name.replace(a, b)
    return name.lower()


def find_condition(name: str, kind: str | None = None) -> Condition:
    """Look up a condition by name ("ptosis b0>b1", "b1≥b0", "top-shape s0⁻>s1⁺", ...)."""
    key = _normalise(name)
    for cond in CONDITIONS.values():
        full, short = _normalise(cond.name), _normalise(cond.name.split(" ", 1)[1])
        if key == full or (key == short and kind in (None, cond.kind)):
            return cond
    raise ValueError(f"unknown condition '{name}'; choose one of: {', '.join(CONDITIONS)}")
