"""Deform a breast by type and degree: the surgeon's request turned into deformation parameters.

`exact` solves the condition's line for the degree (`deform.inverse`, the upper bound);
`learnt` runs the shipped regression of the condition (`deform/models/*.npz`, trained by
`breastplan train` on database S, `breastplan.model/1`) on the breast's FS5 descriptors
(`deform.descriptors`). Either way the parameters lie on the condition's line (docs/model.md §4).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import ArtefactError, Primitive, to_mm, to_model_units
from breastplan.model_file import ModelFile, load_model

from .conditions import CONDITIONS, Condition, find_condition
from .degree import condition_extent, continuous_degree, reference_extents
from .descriptors import breast_scalars, scalar_names
from .lattice import Lattice
from .global_deformations import apply_kind
from .inverse import solve_degree
from .names import DD, DEFAULT_CONDITION, METHODS

MODELS = Path(__file__).parent / "models"
"""The shipped models, one `<slug>.npz` per condition."""


@dataclass(frozen=True)
class ByDegree:
    """The deformed breast (mm) and how it was obtained."""

    points_mm: np.ndarray
    condition: Condition
    method: str
    t: float                    # position on the condition's line
    params: np.ndarray          # the condition's kind's parameters, model units
    degree_reached: float       # continuous degree of the result (docs/model.md §5)
    lattice: Lattice | None = None   # a statistical model's deformation (mm, the points' frame); then t is NaN


def slug(condition: Condition) -> str:
    """File-name form of a condition: "ptosis b0>b1" → "ptosis-b0-gt-b1", "top-shape s0->s1+" →
    "top-shape-s0-to-s1-plus"."""
    name = condition.name
    for a, b in (("->", " to "), (">=", " ge "), (">", " gt "), ("+", " plus"), (" ", "-")):
        name = name.replace(a, b)
    return "-".join(part for part in name.split("-") if part)


def pick_condition(kind: str, condition: str | None = None) -> Condition:
    """The named condition of `kind`, or its default; ValueError for kinds without conditions."""
    kinds = sorted({c.kind for c in CONDITIONS.values()})
    if kind not in kinds:
        raise ValueError(f"{kind} has no degrees of deformation; choose one of {', '.join(kinds)}")
    cond = find_condition(condition or DEFAULT_CONDITION[kind], kind)
    if cond.kind != kind:
        raise ValueError(f"'{cond.name}' is a {cond.kind} condition, not a {kind} one")
    return cond


def load_degree_model(path: Path) -> ModelFile:
    """Load a regression model file of one condition (`degree_model`)."""
    return degree_model(load_model(path), path)


def degree_model(model: ModelFile, path: Path) -> ModelFile:
    """A loaded regression model file of one condition (`breastplan train`, from `path`); ArtefactError
    naming it unless its condition is known and its inputs are the degree and its feature set's scalars,
    its output one."""
    try:
        cond = find_condition(str(model.meta.get("condition")))
    except ValueError:
        raise ArtefactError(path, f"names no known condition ({model.meta.get('condition')})") from None
    if model.meta.get("kind", cond.kind) != cond.kind:
        raise ArtefactError(path, f"is a model of {model.meta['kind']}, but its condition '{cond.name}' is of "
                                  f"{cond.kind}")
    names = scalar_names(str(model.meta.get("feature_set")), cond.kind)
    if model.n_features != len(names) or model.n_outputs != 1:
        raise ArtefactError(path, f"takes {model.n_features} features and gives {model.n_outputs} outputs, where its "
                                  f"feature set takes {len(names)} and a position on the condition is one")
    return model


def learnt_position(model: ModelFile, points_mm, kind: str, degree: float) -> float:
    """The model's position t on its condition's line for this breast and degree, clipped to [0, 1]."""
    features = np.concatenate([[degree], breast_scalars(points_mm, kind, model.meta["feature_set"])])
    return float(np.clip(model.predict(features[None, :]).reshape(-1)[0], 0.0, 1.0))   # (1,) or (1, 1)


def deform_by_degree(points_mm, kind: str, degree: float, *, condition: str | None = None,
                     method: str = "exact", primitive: Primitive | None = None,
                     models: Path = MODELS, given: ModelFile | None = None) -> ByDegree:
    """Deform a breast (mm, breast frame) to `degree` ∈ [1, 8] of `kind` along `condition`.

    `method`: exact, learnt (the condition's model in `models`), or the path of a `breastplan.model/1`
    file (`.npz`) trained for one condition of `kind`, whose condition is then the default.
    `given`: that file, already loaded and checked (`degree_model`; else it is loaded here).
    (`learn.field_file.by_degree` also takes statistical model files.)"""
    if method not in METHODS and not str(method).endswith(".npz"):
        raise ValueError(f"unknown method '{method}'; choose one of {', '.join(METHODS)} or a model file")
    if given is None and method not in METHODS:
        given = load_degree_model(Path(method))
    cond = pick_condition(kind, condition or (given.meta.get("condition") if given else None))
    check_degree(degree)
    p_mu = to_model_units(np.asarray(points_mm, dtype=float))
    if method == "exact":
        t = solve_degree(p_mu, cond, DD, degree, primitive).t
    else:
        t = learnt_position(given or load_degree_model(models / f"{slug(cond)}.npz"), points_mm, kind, degree)
    params = cond.at(t)
    moved = apply_kind(p_mu, kind, params, primitive)
    return ByDegree(to_mm(moved), cond, method, t, params, degree_reached(cond, p_mu, moved, primitive))


def check_degree(degree: float) -> None:
    """ValueError unless the degree lies in [1, DD]."""
    if not 1.0 <= degree <= DD:
        raise ValueError(f"the degree must lie in [1, {DD}], got {float(degree)!r}")


def degree_reached(cond: Condition, p_mu, moved_mu, primitive) -> float:
    """The continuous degree of a breast moved from p_mu to moved_mu (model units) on `cond`."""
    return float(continuous_degree(condition_extent(cond, p_mu, moved_mu, primitive), reference_extents(cond, DD)))
