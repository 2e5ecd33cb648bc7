"""The regressors of the thesis study (§4.2.3) as scikit-learn estimators with their grids.

Every estimator scales its features to [0, 1] (fitted on the rows it is trained on, so the test
split and the held-out CV fold never reach a scaler) and its targets to [0, 1]:
`TransformedTargetRegressor(Pipeline([scale, (poly,) reg]), MinMaxScaler())`, the structure
`breastplan.model_file` exports without pickle.

* LR: linear regression on polynomial bases of degree 1–4, with and without intercept.
* SVR: linear, polynomial (degree 1–4; γ = 1/n_features and coef0 = 1, LIBSVM's default γ: with
  γ = 1 a degree-4 kernel is so ill-conditioned that one fit takes 13 s) and RBF kernels;
  C = 2^-5, 2^-3, …, 2^7 and, for RBF, γ = 2^-5, 2^-3, …, 2^3 (the thesis's grid).
* MLP: one hidden layer of 5, 10, 25, 50 or 75 neurons. The thesis trained with scaled conjugate
  gradient, which scikit-learn lacks; we use L-BFGS, the closest full-batch second-order method.

Hyper-parameters are chosen by 4-fold cross-validation on the training split, selecting by
RMSE % (Eq. 4.23). Folds group the rows of one breast (`GroupKFold`), so a fold never tests on a
breast it trained on (the thesis's folds did not say; rows of one breast are near-duplicates).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.compose import TransformedTargetRegressor
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LinearRegression
from sklearn.metrics import make_scorer
from sklearn.model_selection import GridSearchCV, GroupKFold
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import MinMaxScaler, PolynomialFeatures
from sklearn.svm import SVR

from .metrics import rmse_pct

FAMILIES = ("LR", "SVR-linear", "SVR-poly", "SVR-rbf", "MLP")
C_GRID = tuple(2.0 ** np.arange(-5, 8, 2))
GAMMA_GRID = tuple(2.0 ** np.arange(-5, 4, 2))
NEURONS = (5, 10, 25, 50, 75)
POLY_DEGREES = (1, 2, 3, 4)
QUICK = {"C": (2.0 ** -1, 2.0 ** 3), "gamma": (2.0 ** -1,), "neurons": (10,), "degrees": (1, 2)}
"""The small grid of `--quick`."""
SVR_EPSILON = 0.01
"""ε-tube of the SVRs, in scaled target units ([0, 1])."""
CV_FOLDS = 4
N_JOBS = -1
"""Grid points fitted in parallel, one process per core (joblib gives each one BLAS thread)."""


@dataclass
class Selected:
    """A family's estimator refitted on the whole training split with its best grid point."""

    family: str
    estimator: TransformedTargetRegressor
    params: dict
    cv_rmse_pct: float


def _grid(family: str, quick: bool) -> tuple[object, dict]:
    """The family's final step and its grid (keys relative to the step)."""
    c = QUICK["C"] if quick else C_GRID
    if family == "LR":
        return LinearRegression(), {"fit_intercept": [True, False]}
    if family == "MLP":
        mlp = MLPRegressor(solver="lbfgs", max_iter=2000, random_state=0)
        return mlp, {"hidden_layer_sizes": [(h,) for h in (QUICK["neurons"] if quick else NEURONS)]}
    kernel = family.split("-")[1]
    grid = {"C": list(c)}
    if kernel == "poly":
        grid.update(degree=list(QUICK["degrees"] if quick else POLY_DEGREES), gamma=["auto"], coef0=[1.0])
    if kernel == "rbf":
        grid["gamma"] = list(QUICK["gamma"] if quick else GAMMA_GRID)
    return SVR(kernel=kernel, epsilon=SVR_EPSILON), grid


def make_search(family: str, quick: bool = False) -> GridSearchCV:
    """The grid search of one family (unfitted)."""
    if family not in FAMILIES:
        raise ValueError(f"unknown regressor family '{family}'; choose one of {', '.join(FAMILIES)}")
    reg, grid = _grid(family, quick)
    prefix = "regressor__reg__"
    steps = [("scale", MinMaxScaler())]
    if family == "LR":
        steps.append(("poly", PolynomialFeatures(include_bias=False)))
        grid["degree"] = list(QUICK["degrees"] if quick else POLY_DEGREES)
    steps.append(("reg", reg))
    full_grid = {(("regressor__poly__" if k == "degree" and family == "LR" else prefix) + k): v
                 for k, v in grid.items()}
    model = TransformedTargetRegressor(regressor=Pipeline(steps), transformer=MinMaxScaler())
    scorer = make_scorer(lambda y, f: float(np.mean(rmse_pct(f, y))), greater_is_better=False)
    return GridSearchCV(model, full_grid, scoring=scorer, cv=GroupKFold(CV_FOLDS), refit=True, n_jobs=N_JOBS)


def select(family: str, X: np.ndarray, y: np.ndarray, groups: np.ndarray, quick: bool = False) -> Selected:
    """Cross-validate the family's grid on (X, y) grouped by breast; refit the best on all rows."""
    search = make_search(family, quick)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        search.fit(X, y, groups=groups)
    params = {k.rsplit("__", 1)[1]: v for k, v in search.best_params_.items()}
    return Selected(family, search.best_estimator_, params, float(-search.best_score_))
