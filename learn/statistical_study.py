"""The study of statistical deformation models (thesis §4.3, §5.2, Table 5.8), reproduced and beaten.

For each condition: every breast of database S before, and deformed to each of 8 degrees, is
turned into displacement fields of an n³ FFD lattice (`learn.displacements`, cached on disk). On
the training split, models learn the field from the before breast, the degree (and the type, for
the model of all types); on the test split each predicted field moves the original breast
("Modelled"), which is compared with the truly deformed one ("Original") by the indirect metrics
(docs/model.md §7) and by the largest/median ratio of those distances and of its vertex errors (local
spikes).

Rows: "no change" (the original breast as the prediction: the ceiling), "FFD fit" (each test
pair's own fitted field: the floor every model stands on), the
thesis's MLP (125 and 216 control points, as many hidden neurons as control points, and a
cross-validated sweep), and our FieldModel with each regressor (hyper-parameters by 4-fold
cross-validation grouped by breast), from the discrete degree as the thesis, and from the
continuous degree. Features and targets are scaled on the training split.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GridSearchCV, GroupKFold

from breastplan.deform.conditions import find_condition
from breastplan.options import DEGREE_KINDS

from .databases import Database, build_database
from .datasets import Dataset, build_dataset
from .displacements import Before, FitCache, PairOptions, apply_field, fit_before, fit_pair, pair_features
from .metrics import indirect_metrics, spike_ratios, vertex_spike_ratios
from .statistical import REGRESSORS, THESIS_EPOCHS, FieldModel, thesis_mlp

CONDITIONS = ("ptosis b0>b1", "ptosis b1>=b0", "turn c0>c1", "turn c1>c0", "top-shape s0->s1+", "top-shape s1->s0+")
THESIS_CONDITION = "ptosis b0>b1"
THESIS_HAUSDORFF = {5: 210.76, 6: 341.13}
"""Thesis Table 5.8: Hausdorff µ (%) of its statistical model with 125 and 216 control points."""
SPIKE = 3.0
"""A modelled breast has a local spike when its largest modelled→original distance exceeds SPIKE × their
median (and, by the stricter yardstick, its largest vertex error SPIKE × their median)."""
GRIDS = {
    "ridge": {"n_modes": (3, 6, 10, 20), "alpha": (1e-4, 1e-3, 1e-2)},
    "kernel-ridge": {"n_modes": (3, 6, 10, 20), "alpha": (1e-4, 1e-3, 1e-2), "gamma": (0.3, 1.0, 3.0)},
    "gp": {"n_modes": (3, 6, 10)},
    "mlp": {"n_modes": (6,), "alpha": (1e-4, 1e-2)},
}
QUICK_GRIDS = {"ridge": {"n_modes": (6, 20)}, "kernel-ridge": {"n_modes": (6, 20), "gamma": (1.0,)},
               "gp": {"n_modes": (6,)}, "mlp": {"n_modes": (6,)}}
QUICK_EPOCHS = 150
"""A quick study trains the thesis's network for this many L-BFGS iterations (THESIS_EPOCHS otherwise): the
quick study shows every method at work, not the thesis's best figure."""
ALL_TYPES = ("ptosis b0>b1", "turn c0>c1", "top-shape s1->s0+")
"""The conditions one model learns together, a condition per type (the types' default conditions)."""
CONTINUOUS = ("ridge", "kernel-ridge")
"""Regressors also learnt with the continuous degree: the degree measured on each pair rather than
its rounded grade, a finer input for the same change."""
CONTINUOUS_ROW = ", continuous degree"
"""The suffix of their rows' method names."""
HIDDEN = (0.2, 0.5, 1.0)
"""The thesis MLP's sweep: hidden neurons as multiples of the control points."""
QUICK_BREASTS = 4
FITS = ("corresponding", "closest")
"""How pairs are fitted: database S's breasts correspond point for point (least squares), or by
closest points as between a clinic's scans (the thesis's way)."""


@dataclass
class Pairs:
    """One condition's pairs on one lattice: befores per breast, fields per example (box units)."""

    dataset: Dataset
    options: PairOptions
    befores: list[Before]
    fields: np.ndarray             # (n_examples, K·3)

    @property
    def train(self) -> np.ndarray:
        return np.flatnonzero(self.dataset.split == "train")

    @property
    def test(self) -> np.ndarray:
        return np.flatnonzero(self.dataset.split == "test")

    def features(self, examples, thesis: bool = False, types=(), continuous: bool = False) -> np.ndarray:
        """Features of the examples (`pair_features`): the thesis's, or ours with the type one-hot over
        `types`; with the discrete degree, or the continuous one (docs/model.md §5)."""
        ds = self.dataset
        degree = (ds.degree_continuous if continuous else ds.degree)[examples]
        return pair_features([self.befores[int(i)] for i in ds.breast[examples]], degree,
                             [ds.condition.kind] * len(examples), types, thesis=thesis)

    def modelled(self, examples, fields) -> np.ndarray:
        """(n, N, 3) original breasts of the examples moved by the fields, mm."""
        ds = self.dataset
        return np.stack([apply_field(ds.original_points(k), f, self.befores[int(ds.breast[k])].box(self.options.lattice))
                         for k, f in zip(examples, fields)])


def fit_condition(db: Database, condition: str, options: PairOptions, cache: FitCache, advance=lambda: None) -> Pairs:
    """Every breast of `db` before and after each degree of `condition`, as FFD fields."""
    ds = build_dataset(db, find_condition(condition), 8)
    befores = []
    for i in range(len(db)):
        befores.append(fit_before(db.points[i], options.lattice, cache))
        advance()
    fields = []
    for k in range(len(ds)):
        fields.append(fit_pair(befores[int(ds.breast[k])], ds.original_points(k), ds.deformed_points(k), options, cache,
                               ds.condition.kind))
        advance()
    return Pairs(ds, options, befores, np.stack(fields))


@dataclass
class StatResult:
    """One method on one condition's test split."""

    condition: str
    lattice: int                       # control points per axis
    fit: str                           # one of FITS
    method: str
    hyper: dict
    cv_rmse_pct: float                 # field RMSE, % of the box, cross-validated on the training split
    rmse_pct: float                    # the same on the test split
    distances: dict = field(default_factory=dict)   # INDIRECT_KEYS → (n_test,) %
    vertex_spikes: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (n_test,) `vertex_spike_ratios`

    @property
    def control_points(self) -> int:
        return self.lattice ** 3

    @property
    def spikes(self) -> np.ndarray:
        """(n_test,) largest / median modelled→original distance (`spike_ratios`)."""
        return spike_ratios(self.distances)

    @property
    def spike_free_pct(self) -> float:
        """Test breasts whose largest modelled→original distance is at most SPIKE × their median, %."""
        return float(np.mean(self.spikes <= SPIKE) * 100.0)

    @property
    def vertex_spike_free_pct(self) -> float:
        """The same on the vertex errors against the true positions (`vertex_spike_ratios`), %."""
        return float(np.mean(self.vertex_spikes <= SPIKE) * 100.0)


def fit_name(options: PairOptions) -> str:
    return FITS[0] if options.corresponding else FITS[1]


def field_rmse_pct(predicted, target) -> float:
    """RMSE of fields in box units, as % of the box."""
    return float(np.sqrt(np.mean((np.asarray(predicted) - np.asarray(target)) ** 2)) * 100.0)


def grid_select(estimator, grid: dict, X, Y, groups) -> tuple[object, dict, float]:
    """The grid point with the lowest grouped 4-fold CV field RMSE, refitted on all of X."""
    search = GridSearchCV(estimator, {k: list(v) for k, v in grid.items()}, cv=GroupKFold(4),
                          scoring="neg_root_mean_squared_error", n_jobs=1, error_score="raise")
    with warnings.catch_warnings():            # an optimiser at its budget or a kernel at a bound: still a model
        warnings.simplefilter("ignore", ConvergenceWarning)
        search.fit(X, Y, groups=groups)
    return search.best_estimator_, search.best_params_, float(-search.best_score_ * 100.0)


def evaluate(pairs: Pairs, method: str, hyper: dict, cv: float, predicted: np.ndarray) -> StatResult:
    """Metrics of predicted test fields."""
    ds, test = pairs.dataset, pairs.test
    truth = np.stack([ds.deformed_points(k) for k in test])
    modelled = pairs.modelled(test, predicted)
    return StatResult(ds.condition.name, pairs.options.lattice, fit_name(pairs.options), method, hyper, cv,
                      field_rmse_pct(predicted, pairs.fields[test]), indirect_metrics(truth, modelled),
                      vertex_spike_ratios(truth, modelled))


def run_condition(pairs: Pairs, quick: bool, thesis: bool, advance=lambda: None) -> list[StatResult]:
    """The rows of one condition on one lattice (module docstring); `thesis` adds the thesis's MLPs."""
    train, test, ds = pairs.train, pairs.test, pairs.dataset
    Y, groups = pairs.fields[train], ds.breast[train]
    results = [evaluate(pairs, "no change", {}, float("nan"), np.zeros_like(pairs.fields[test])),
               evaluate(pairs, "FFD fit", {}, float("nan"), pairs.fields[test])]
    advance()
    if thesis:
        X, Xt = pairs.features(train, thesis=True), pairs.features(test, thesis=True)
        K = pairs.options.lattice ** 3
        est, _, cv = grid_select(thesis_mlp(K, epochs=QUICK_EPOCHS if quick else THESIS_EPOCHS), {}, X, Y, groups)
        results.append(evaluate(pairs, "MLP (thesis)", {"hidden": K}, cv, est.predict(Xt)))
        advance()
        if not quick:
            grid = {"regressor__regressor__hidden_layer_sizes": [(max(1, round(h * K)),) for h in HIDDEN]}
            est, params, cv = grid_select(thesis_mlp(K), grid, X, Y, groups)
            results.append(evaluate(pairs, "MLP (thesis, swept)", {"hidden": params[next(iter(grid))][0]}, cv,
                                    est.predict(Xt)))
        advance()
    for continuous, regressors in ((False, REGRESSORS), (True, CONTINUOUS)):
        X, Xt = pairs.features(train, continuous=continuous), pairs.features(test, continuous=continuous)
        for regressor in regressors:
            grid = (QUICK_GRIDS if quick else GRIDS)[regressor]
            est, params, cv = grid_select(FieldModel(regressor), grid, X, Y, groups)
            name = f"PCA + {regressor}" + (CONTINUOUS_ROW if continuous else "")
            results.append(evaluate(pairs, name, params, cv, est.predict(Xt)))
            advance()
    return results


def study_database(quick: bool) -> Database:
    """Database S (10 000 points per breast), or 4 breasts per shape and split of 2 500 points."""
    db = build_database("S", n_points=2500 if quick else 10_000)
    if quick:
        keep = np.concatenate([np.flatnonzero((db.shape == s) & (db.split == sp))[:QUICK_BREASTS]
                               for s in np.unique(db.shape) for sp in ("train", "test")])
        db = db.subset(keep)
    return db


@dataclass(frozen=True)
class StudyPlan:
    """What the study runs: conditions, lattices and ways of fitting the pairs (the thesis's
    condition gets them all, the others the first of each), quick grids."""

    conditions: tuple[str, ...] = CONDITIONS
    lattices: tuple[int, ...] = (5, 6)
    fits: tuple[str, ...] = FITS
    quick: bool = False

    @classmethod
    def quick_plan(cls) -> "StudyPlan":
        """The thesis's condition alone, 125 CP from corresponding points, small grids, the thesis's network
        trained for QUICK_EPOCHS (CI)."""
        return cls(conditions=(THESIS_CONDITION,), lattices=(5,), fits=FITS[:1], quick=True)

    def runs(self) -> list[tuple[str, PairOptions]]:
        """(condition, pair options) of every run: the thesis's condition on every lattice with the
        first way of fitting and on the first lattice with the others, then the other conditions on
        the first lattice and way."""
        def options(n: int, fit: str) -> PairOptions:
            return PairOptions(lattice=n, corresponding=fit == "corresponding")

        thesis = ([options(n, self.fits[0]) for n in self.lattices] + [options(self.lattices[0], f) for f in self.fits[1:]]
                  if THESIS_CONDITION in self.conditions else [])
        return ([(THESIS_CONDITION, o) for o in thesis]
                + [(c, options(self.lattices[0], self.fits[0])) for c in self.conditions if c != THESIS_CONDITION])

    def steps(self, breasts: int, examples: int) -> int:
        """Progress steps: fits, then rows, then the model of all types."""
        rows = 1 + len(REGRESSORS) + len(CONTINUOUS)
        return sum(breasts + examples + rows + (2 if c == THESIS_CONDITION else 0) for c, _ in self.runs()) + 1


def run_study(plan: StudyPlan, cache: FitCache, advance=lambda: None) -> tuple[list[StatResult], dict]:
    """Every run of `plan`; returns the results and the fitting seconds per (condition, lattice)."""
    import time

    db = study_database(plan.quick)
    results, seconds = [], {}
    first, per_type = plan.runs()[0][1], []
    for condition, options in plan.runs():
        start = time.perf_counter()
        pairs = fit_condition(db, condition, options, cache, advance)
        seconds[f"{condition} {options.lattice ** 3} CP {fit_name(options)}"] = time.perf_counter() - start
        results += run_condition(pairs, plan.quick, thesis=condition == THESIS_CONDITION, advance=advance)
        if condition in ALL_TYPES and options == first:
            per_type.append(pairs)
    if len(per_type) > 1:
        results += run_all_types(per_type, plan.quick)
        advance()
    return results, seconds


def run_all_types(per_type: list[Pairs], quick: bool) -> list[StatResult]:
    """One model learnt from the pairs of every type together, the type one-hot among its features,
    evaluated on each type's test split. Its cross-validated RMSE spans the types, so it is kept in
    `hyper` and the row is not a candidate for a condition's best."""
    X = np.vstack([p.features(p.train, types=DEGREE_KINDS) for p in per_type])
    Y = np.vstack([p.fields[p.train] for p in per_type])
    groups = np.concatenate([p.dataset.breast[p.train] for p in per_type])      # the same breasts in every type
    results = []
    for regressor in ("ridge", "kernel-ridge"):
        est, params, cv = grid_select(FieldModel(regressor), (QUICK_GRIDS if quick else GRIDS)[regressor], X, Y, groups)
        for p in per_type:
            results.append(evaluate(p, f"PCA + {regressor}, all types", {**params, "cv_all_types": cv}, float("nan"),
                                    est.predict(p.features(p.test, types=DEGREE_KINDS))))
    return results
