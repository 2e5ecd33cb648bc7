"""The thesis study of deformation-parameter regressions (chapters 4.2 and 5.1), reproduced and beaten.

For each condition of a study: every regressor family on every feature set with the discrete
degree (the thesis's configurations), the same families on FS5 with the continuous degree
(ours), and the exact inverse solver (`breastplan.deform.inverse`) with either degree. Each
configuration is selected on the training split and evaluated on the test split: RMSE % and
MPE % of the parameters (Eq. 4.23–4.24) and the indirect distances between the truly deformed
breast ("Original") and the breast deformed by the predicted parameters ("Modelled"), docs/model.md §7.

The regressions predict the position t ∈ [0, 1] on the condition's line, and the parameters are
`condition.at(t)`. This is the thesis's regression of each varying parameter, not an
approximation: after the [0, 1] target scaling every varying parameter of a condition *is* t,
and LR and SVR model each output on its own (thesis §4.2.3), so they would fit the same model
twice; the NN's two outputs likewise share one target.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from breastplan.deform.conditions import Condition, find_condition
from breastplan.deform.inverse import solve_degree

from .databases import build_database
from .datasets import Dataset, build_dataset
from .features import VectorReducer, breast_table, example_features
from .metrics import indirect_metrics, mpe_pct, rmse_pct
from .regressors import FAMILIES, select
from .studies import STUDIES, Study

PCA_COMPONENTS = (1, 2, 3, 5, 10)
"""Candidate numbers of PCA scores of a feature set's vector blocks, chosen by cross-validation."""
QUICK_BREASTS = 4
"""Breasts per shape (and per split) kept by `--quick`, which also runs only FS5 (both degrees)."""


@dataclass
class Result:
    """One configuration evaluated on the test split of one condition."""

    study: str
    condition: str
    method: str                 # a regressor family or "exact"
    features: str               # a feature set, or "-" for the exact solver
    degree: str                 # "discrete" (thesis) or "continuous" (ours)
    outputs: tuple[str, ...]
    hyper: dict
    cv_rmse_pct: float
    target: np.ndarray          # (n_test, n_outputs) true parameters
    predicted: np.ndarray       # (n_test, n_outputs)
    distances: dict = field(default_factory=dict)   # INDIRECT_KEYS → (n_test,) %

    @property
    def label(self) -> str:
        return f"{self.method} {self.features} {self.degree}"


def outputs_of(condition: Condition) -> list[int]:
    """Indices of the parameters a condition varies (the regression targets)."""
    return [i for i, (a, b) in enumerate(zip(condition.first, condition.last)) if a != b]


def load_dataset(study: Study, condition: str, dd: int, quick: bool, cache: dict) -> Dataset:
    """The condition's dataset on the study's database (a few breasts per split with `quick`)."""
    key = (study.database, quick)
    if key not in cache:
        db = build_database(study.database, n_points=2500 if quick else 10_000)
        if quick:
            keep = np.concatenate([np.flatnonzero((db.shape == s) & (db.split == sp))[:QUICK_BREASTS]
                                   for s in np.unique(db.shape) for sp in ("train", "test")])
            db = db.subset(keep)
        cache[key] = db
    return build_dataset(cache[key], find_condition(condition), dd)


class ConditionRun:
    """Everything one condition's configurations share: dataset, split, targets, truths."""

    def __init__(self, study_name: str, ds: Dataset):
        self.study, self.ds = study_name, ds
        self.cond = ds.condition
        self.out = outputs_of(self.cond)
        self.train = np.flatnonzero(ds.split == "train")
        self.test = np.flatnonzero(ds.split == "test")
        self.table = breast_table(ds.database, self.cond.kind)
        self.truth = np.stack([ds.deformed_points(k) for k in self.test])

    def _result(self, method, features, degree, hyper, cv, t) -> Result:
        params = self.cond.at(np.asarray(t, dtype=float))
        modelled = np.stack([self.ds.deformed_points(k, p) for k, p in zip(self.test, params)])
        return Result(self.study, self.cond.name, method, features, degree,
                      tuple(self.cond.param_names[i] for i in self.out), hyper, cv,
                      self.ds.params[self.test][:, self.out], params[:, self.out],
                      indirect_metrics(self.truth, modelled))

    def features(self, feature_set: str, degree: str) -> tuple[np.ndarray, np.ndarray, dict]:
        """(X_train, X_test, info): scalars plus the CV-chosen number of PCA scores."""
        f = example_features(self.ds, feature_set, degree, self.table)
        if f.vectors is None:
            return f.scalars[self.train], f.scalars[self.test], {}
        reducer = VectorReducer(max(PCA_COMPONENTS)).fit(f.vectors[self.train])
        scores = {k: reducer.transform(f.vectors, k) for k in PCA_COMPONENTS if k <= reducer.pca.n_components_}
        groups = self.ds.breast[self.train]

        def cv(k):
            X = np.column_stack([f.scalars, scores[k]])[self.train]
            return select("LR", X, self.ds.position[self.train], groups, quick=True).cv_rmse_pct

        k = min(scores, key=cv)
        X = np.column_stack([f.scalars, scores[k]])
        return X[self.train], X[self.test], {"pca_components": k, "pca_explained_pct": reducer.explained(k)}

    def learnt(self, family: str, feature_set: str, degree: str, X_train, X_test, info, quick) -> Result:
        sel = select(family, X_train, self.ds.position[self.train], self.ds.breast[self.train], quick)
        return self._result(family, feature_set, degree, {**sel.params, **info}, sel.cv_rmse_pct,
                            sel.estimator.predict(X_test))

    def exact(self, degree: str) -> Result:
        db, ds = self.ds.database, self.ds
        dd = ds.degree if degree == "discrete" else ds.degree_continuous
        t = [solve_degree(db.points_mu(ds.breast[k]), self.cond, ds.dd, float(dd[k]), db.primitive(ds.breast[k]),
                          db.grid, move=ds.changer(k)).t for k in self.test]
        return self._result("exact", "-", degree, {}, float("nan"), t)


def run_condition(study_name: str, study: Study, ds: Dataset, quick: bool, advance=lambda: None) -> list[Result]:
    """All configurations of one condition (see the module docstring)."""
    run = ConditionRun(study_name, ds)
    results = []
    plans = [(fs, "discrete") for fs in thesis_sets(study, quick)] + [("FS5", "continuous")]
    for fs, degree in plans:
        X_train, X_test, info = run.features(fs, degree)
        for family in FAMILIES:
            results.append(run.learnt(family, fs, degree, X_train, X_test, info, quick))
            advance()
    for degree in ("discrete", "continuous"):
        results.append(run.exact(degree))
        advance()
    return results


def thesis_sets(study: Study, quick: bool) -> tuple[str, ...]:
    """The feature sets run with the discrete degree: the study's, or FS5 alone with `quick`."""
    return ("FS5",) if quick else study.feature_sets


def study_datasets(names: list[str], dd: int, quick: bool) -> list[tuple[str, Dataset]]:
    """(study name, dataset) of every condition of the named studies, databases built once."""
    cache = {}
    return [(n, load_dataset(STUDIES[n], c, dd, quick, cache)) for n in names for c in STUDIES[n].conditions]


def run_studies(datasets: list[tuple[str, Dataset]], quick: bool, advance=lambda: None) -> list[Result]:
    """Every configuration of every (study name, dataset)."""
    return [r for name, ds in datasets for r in run_condition(name, STUDIES[name], ds, quick, advance)]


def configurations(study: Study, quick: bool) -> int:
    """Configurations per condition (for progress bars)."""
    return (len(thesis_sets(study, quick)) + 1) * len(FAMILIES) + 2


def parameter_errors(result: Result) -> dict[str, float]:
    """RMSE % and MPE % averaged over the outputs (Eq. 4.23–4.24)."""
    return {"rmse_pct": float(np.mean(rmse_pct(result.predicted, result.target))),
            "mpe_pct": float(np.nanmean(mpe_pct(result.predicted, result.target)))}


def best_learnt(results: list[Result]) -> Result:
    """The learnt configuration with the lowest cross-validated RMSE % (chosen without the test split)."""
    return min((r for r in results if r.method != "exact" and r.features != "REF"), key=lambda r: r.cv_rmse_pct)
