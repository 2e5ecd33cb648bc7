"""A statistical deformation model as a `breastplan.model/1` file, and training it from a pairs folder.

The file holds the FieldModel's weights regressor (exported without pickle by `breastplan.model_file`),
its PCA modes as extra arrays (`mean`, `components`: fields in box units) and, in its metadata,
`"model": "statistical"`, the lattice, the types it learnt and its features. `FieldFile.deformation`
needs numpy and the breast fit only: it fits the breast model to her points, boxes the fitted
surface and predicts the field for the type and degree: a lattice that moves her points.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import ArtefactError, to_model_units
from breastplan.deform.by_degree import (ByDegree, check_degree, deform_by_degree, degree_model, degree_reached,
                                         pick_condition)
from breastplan.deform.lattice import Lattice
from breastplan.model_file import ModelFile, load_model
from breastplan.options import DEGREE_KINDS
from breastplan.units import displacement_problem

from .displacements import (FitCache, PairOptions, feature_names, field_lattice, fit_before, fit_pair,
                            pair_features)

STATISTICAL = "statistical"


@dataclass
class FieldFile:
    """A loaded statistical model (`load_field_model`)."""

    model: ModelFile
    path: Path

    @property
    def kinds(self) -> list[str]:
        return list(self.model.meta["kinds"])

    @property
    def lattice(self) -> int:
        return int(self.model.meta["lattice"])

    def field(self, before, kind: str, degree: float) -> np.ndarray:
        """(K·3,) predicted field, box units, for a fitted before breast."""
        if kind not in self.kinds:
            raise ArtefactError(self.path, f"models {', '.join(self.kinds)}, not {kind}")
        X = pair_features([before], [degree], [kind], self.kinds)
        scores = self.model.predict(X).reshape(1, -1)
        return (scores @ self.model.extra["components"] + self.model.extra["mean"])[0]

    def deformation(self, points_mm: np.ndarray, kind: str, degree: float) -> Lattice:
        """The lattice (mm, the points' frame) that makes `kind` at `degree` of her breast points."""
        before = fit_before(points_mm, self.lattice)
        return field_lattice(self.field(before, kind, degree), before.box(self.lattice))


def by_degree(points_mm, kind: str, degree: float, *, method: str = "exact", primitive=None,
              model: ModelFile | None = None) -> ByDegree:
    """`deform_by_degree` (mm, the points' frame), or, when `method` is a statistical model file, the
    breast moved by its FFD lattice (the result's `lattice`; no position t or parameters). `model`:
    the file `method` names, already loaded (else it is loaded here)."""
    if model is None and str(method).endswith(".npz"):
        model = load_model(Path(method))
    if model is None or not is_field_model(model):
        given = None if model is None else degree_model(model, Path(method))
        return deform_by_degree(points_mm, kind, degree, method=method, primitive=primitive, given=given)
    cond = pick_condition(kind)
    check_degree(degree)
    points_mm = np.asarray(points_mm, dtype=float)
    lattice = field_file(model, Path(method)).deformation(points_mm, kind, degree)
    moved = lattice(points_mm)
    problem = displacement_problem(points_mm, moved)[1]
    if problem:
        raise ArtefactError(Path(method), f"for {kind} at degree {degree:g}, {problem}: a damaged "
                                          "model, or one trained on other breasts")
    reached = degree_reached(cond, to_model_units(points_mm), to_model_units(moved), primitive)
    return ByDegree(moved, cond, str(method), float("nan"), np.zeros(0), reached, lattice)


def is_field_model(model: ModelFile) -> bool:
    return model.meta.get("model") == STATISTICAL


def load_field_model(path: str | Path) -> FieldFile:
    """Load a statistical model file; ArtefactError naming it if it is not one or is inconsistent."""
    return field_file(load_model(path), Path(path))


def field_file(model: ModelFile, path: Path) -> FieldFile:
    """The statistical model of a loaded model file (from `path`); ArtefactError naming it if the file
    is not one or is inconsistent."""
    if not is_field_model(model):
        raise ArtefactError(path, "is a parametric model, not a statistical one (train-statistical writes those)")
    mean, components = model.extra.get("mean"), model.extra.get("components")
    n = model.meta.get("lattice")
    if (mean is None or components is None or not isinstance(n, int) or mean.dtype.kind not in "fiu"
            or components.dtype.kind not in "fiu" or mean.shape != (3 * n ** 3,)
            or components.shape != (model.n_outputs, mean.size) or not set(model.meta.get("kinds", ())) <= set(DEGREE_KINDS)
            or not model.meta.get("kinds")):
        raise ArtefactError(path, "holds an inconsistent statistical model (its modes, lattice or types)")
    k, features = len(model.meta["kinds"]), len(feature_names(model.meta["kinds"]))
    if model.n_features != features:
        raise ArtefactError(path, f"takes {model.n_features} features, where a model of {k} type(s) takes {features}")
    return FieldFile(model, path)


def train_from_pairs(train, clouds, options: PairOptions = PairOptions(), cache: FitCache = FitCache(None),
                     regressor: str = "kernel-ridge", advance=lambda: None):
    """A FieldModel trained on the checked training pairs of a pairs folder and their before breasts'
    points (`learn.pair_folder.training_pairs`).

    Returns (estimator, meta): hyper-parameters are chosen by 4-fold cross-validation
    grouped by before scan when there are at least 4 of them."""
    from .pair_folder import breast_cloud
    from .statistical_study import GRIDS, grid_select
    from .statistical import FieldModel

    befores = {}
    for r in train:
        if r.before not in befores:
            befores[r.before] = fit_before(clouds[r.before], options.lattice, cache)
        advance()
    fields = np.stack([fit_pair(befores[r.before], clouds[r.before], breast_cloud(r.after), options, cache, r.kind)
                       for r in train])
    kinds = sorted({r.kind for r in train}, key=DEGREE_KINDS.index)
    X = pair_features([befores[r.before] for r in train], [r.degree for r in train], [r.kind for r in train], kinds)
    groups = np.array([str(r.before) for r in train])
    if len(set(groups)) >= 4:
        est, hyper, cv = grid_select(FieldModel(regressor), GRIDS[regressor], X, fields, groups)
    else:
        est, hyper, cv = FieldModel(regressor).fit(X, fields), {}, float("nan")
    meta = {"model": STATISTICAL, "lattice": options.lattice, "kinds": kinds, "regressor": regressor,
            "hyper": {k: float(v) for k, v in hyper.items()}, "cv_field_rmse_pct": cv,
            "features": feature_names(kinds),
            "target": "PCA weights of the FFD displacement field, box units",
            "training": {"pairs": len(train), "befores": len(befores), "fit": "corresponding" if options.corresponding
                         else "closest"}}
    return est, meta


def save_field_model(path: str | Path, estimator, meta: dict) -> Path:
    """Write a trained FieldModel as a `breastplan.model/1` file, atomically."""
    from breastplan.model_file import save_model

    extra = {"mean": estimator.pca_.mean_, "components": estimator.pca_.components_}
    return save_model(path, estimator.weights_, meta=meta, extra=extra)
