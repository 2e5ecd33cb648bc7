"""The surgeon's requested changes turned into deformations of one fitted breast.

A change is a (kind, degree) pair; its parameters lie on the kind's condition line at the
position that gives this breast that degree (`deform.by_degree`: the exact inverse, the shipped
regressions, or a given `breastplan.model/1` file). The combination applies every requested
change together, in docs/model.md §3 order.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import Primitive, to_model_units
from breastplan.deform.by_degree import deform_by_degree, learnt_position, pick_condition
from breastplan.deform.degree import condition_extent, continuous_degree, reference_extents
from breastplan.deform.global_deformations import Deformation, apply_kind
from breastplan.deform.names import DD
from breastplan.model_file import load_model


@dataclass(frozen=True)
class Change:
    """One planned change of one breast: its name, the (kind, degree) pairs it makes and how."""

    name: str                              # "ptosis-3", "turn-2.5", or "combined"
    requested: tuple[tuple[str, float], ...]
    deformation: Deformation
    details: tuple[dict, ...]              # per kind: condition, t, params, degree reached


def change_name(kind: str, degree: float) -> str:
    """File-name form of a change: ptosis, 3 → "ptosis-3"; turn, 2.5 → "turn-2.5"."""
    return f"{kind}-{degree:g}"


def solve_change(local_mm: np.ndarray, kind: str, degree: float, primitive: Primitive, method: str) -> Change:
    """The change (kind, degree) of the breast `local_mm` (fitted surface, mm, primitive frame).

    `method`: exact, learnt, or the path of a `breastplan.model/1` file of one of kind's conditions."""
    if method in ("exact", "learnt"):
        r = deform_by_degree(local_mm, kind, degree, method=method, primitive=primitive)
        cond, t, params, reached = r.condition, r.t, r.params, r.degree_reached
    else:
        model = load_model(Path(method))
        cond = pick_condition(kind, model.meta.get("condition"))
        t = learnt_position(model, local_mm, kind, degree)
        params = cond.at(t)
        p_mu = to_model_units(local_mm)
        moved = apply_kind(p_mu, kind, params, primitive)
        reached = float(continuous_degree(condition_extent(cond, p_mu, moved, primitive), reference_extents(cond, DD)))
    details = {"kind": kind, "degree": degree, "condition": cond.name, "t": float(t),
               "params": [float(v) for v in params], "degree_reached": float(reached)}
    return Change(change_name(kind, degree), ((kind, degree),), Deformation.single(kind, params), (details,))


def combine(changes: list[Change]) -> Change:
    """All `changes` applied together (each kind's parameters as solved alone)."""
    deformation = Deformation()
    for change in changes:
        for kind, _ in change.requested:
            deformation = deformation.plus(kind, change.deformation.params(kind))
    requested = tuple(r for c in changes for r in c.requested)
    return Change("combined", requested, deformation, tuple(d for c in changes for d in c.details))
