"""The surgeon's requested changes turned into deformations of one fitted breast.

A change is a (kind, degree) pair; its parameters lie on the kind's condition line at the
position that gives this breast that degree (`deform.by_degree`: the exact inverse, the shipped
regressions, or a given `breastplan.model/1` file), or, for a statistical model file, the FFD
lattice it predicts. The combination applies every requested change together: the global
deformations in docs/model.md §3 order, then the lattices.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import Primitive
from breastplan.learn.field_file import by_degree, field_file, is_field_model
from breastplan.deform.by_degree import degree_model
from breastplan.deform.global_deformations import Deformation
from breastplan.deform.lattice import Lattice
from breastplan.deform.names import METHODS
from breastplan.model_file import ModelFile, load_model

from .result import OPERATED


@dataclass(frozen=True)
class Change:
    """One planned change of one breast: its name, the (kind, degree) pairs it makes and how."""

    name: str                              # "ptosis-3", "turn-2.5", or "combined"
    requested: tuple[tuple[str, float], ...]
    deformation: Deformation
    details: tuple[dict, ...]              # per kind: condition, t, params, degree_reached, reached (REACH)
    fields: tuple[Lattice, ...] = ()       # a statistical model's deformations (mm, primitive frame), after it


UNCHANGED = Change(OPERATED, (), Deformation(), ())
"""No change by degree: the change of a plan of operations alone."""

REACH = 0.5
"""A change reaches the degree asked when the degree of its result lies within half a degree of it
(rounds to it: the thesis's degrees are the rounded continuous ones)."""


@dataclass(frozen=True, eq=False)
class Method:
    """How a plan turns a degree into a change, resolved once: `name` exact (the inverse solver), learnt
    (the shipped regressions) or the path of a model file, then loaded and checked as `model` (a
    regression of one condition, or a statistical model), which plans its own kinds."""

    name: str
    model: ModelFile | None = None

    @classmethod
    def resolve(cls, name: str) -> "Method":
        """The method `name` (plan.json's `options.method`); ArtefactError naming a model file that is
        missing, unreadable or inconsistent."""
        if name in METHODS:
            return cls(name)
        path = Path(name)
        model = load_model(path)
        if is_field_model(model):
            field_file(model, path)
        else:
            degree_model(model, path)
        return cls(name, model)

    @property
    def kinds(self) -> tuple[str, ...]:
        """The kinds a model file plans (every kind for exact and learnt: empty)."""
        return () if self.model is None else tuple(self.model.kinds)

    def for_kind(self, kind: str) -> "Method":
        """The method that plans `kind`: this one, or exact for a kind a model file does not plan."""
        return self if self.model is None or kind in self.kinds else Method("exact")


def short_of(detail: dict, method: str) -> str | None:
    """What a change's `details` entry reaches and why, when it does not round to the degree asked
    (`method` as planned: exact, learnt or a model file); None when it does."""
    if detail["reached"]:
        return None
    why = "the end of its condition's line for this breast" if method == "exact" else "the model's prediction"
    return f"degree {detail['degree_reached']:.2f}, not {detail['degree']:g} ({why})"


def change_name(kind: str, degree: float) -> str:
    """File-name form of a change: ptosis, 3 → "ptosis-3"; turn, 2.5 → "turn-2.5"."""
    return f"{kind}-{degree:g}"


def solve_change(local_mm: np.ndarray, kind: str, degree: float, primitive: Primitive, method: Method) -> Change:
    """The change (kind, degree) of the breast `local_mm` (fitted surface, mm, primitive frame), by
    `method` (`Method.for_kind`)."""
    method = method.for_kind(kind)
    r = by_degree(local_mm, kind, degree, method=method.name, primitive=primitive, model=method.model)
    details = {"kind": kind, "degree": degree, "condition": r.condition.name,
               "t": float(r.t) if r.lattice is None else None, "params": [float(v) for v in r.params],
               "degree_reached": r.degree_reached, "reached": bool(abs(r.degree_reached - degree) < REACH),
               "model": "statistical" if r.lattice is not None else "parametric"}
    if r.lattice is not None:
        return Change(change_name(kind, degree), ((kind, degree),), Deformation(), (details,), (r.lattice,))
    return Change(change_name(kind, degree), ((kind, degree),), Deformation.single(kind, r.params), (details,))


def combine(changes: list[Change]) -> Change:
    """All `changes` applied together (each kind's parameters as solved alone)."""
    deformation = Deformation()
    for change in changes:
        for kind, _ in change.requested:
            deformation = deformation.plus(kind, change.deformation.params(kind))
    requested = tuple(r for c in changes for r in c.requested)
    return Change("combined", requested, deformation, tuple(d for c in changes for d in c.details),
                  tuple(f for c in changes for f in c.fields))
