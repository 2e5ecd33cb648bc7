"""Statistical deformation models: displacement fields of an FFD lattice learnt from before/after pairs.

Both follow scikit-learn's estimator contract (settings in `__init__`, `fit(X, Y)` returns self,
learnt attributes end in `_`); X holds one row of features per pair (`pair_features`), Y its
displacement field in box units (K·3 columns, `learn.displacements`).

* `thesis_mlp`: the thesis's model (§4.3): one MLP, as many hidden neurons as control points by
  default, from every feature scaled to [0, 1] to every displacement scaled to [0, 1].
* `FieldModel` (ours): a statistical deformation model. PCA of the training fields keeps a few
  modes, and a regressor (ridge on quadratic features, rbf kernel ridge, a Gaussian process or an
  MLP) predicts the modes' weights from a few descriptors of the breast, the degree and the type.
  A field is then a smooth combination of observed fields: no control point can move on its own,
  which is what gave the thesis's "local strange deformations".
"""
from __future__ import annotations

import numbers

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.compose import TransformedTargetRegressor
from sklearn.decomposition import PCA
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
from sklearn.kernel_ridge import KernelRidge
from sklearn.linear_model import Ridge
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import MinMaxScaler, PolynomialFeatures
from sklearn.utils.validation import check_is_fitted, validate_data

REGRESSORS = ("ridge", "kernel-ridge", "gp", "mlp")
THESIS_EPOCHS = 500
"""L-BFGS iterations of the thesis's network, a budget in iterations (never in seconds): each one maps
hundreds of features to hundreds of outputs for every training pair."""
EXPORTABLE = ("ridge", "kernel-ridge", "mlp")
"""Regressors a `breastplan.model/1` file holds (a Gaussian process is studied, not shipped)."""


def scaled(regressor, poly: int = 0) -> TransformedTargetRegressor:
    """`regressor` between [0, 1] scalers of features and targets (and quadratic features if poly)."""
    steps = [("scale", MinMaxScaler())] + ([("poly", PolynomialFeatures(poly))] if poly else [])
    return TransformedTargetRegressor(Pipeline(steps + [("regressor", regressor)]), transformer=MinMaxScaler())


def thesis_mlp(hidden: int, seed: int = 0, epochs: int = THESIS_EPOCHS) -> TransformedTargetRegressor:
    """The thesis's network: one hidden layer of `hidden` neurons, features and targets in [0, 1]
    (scaled conjugate gradient in the thesis; L-BFGS here, the closest full-batch method, for `epochs`
    iterations)."""
    return scaled(MLPRegressor(hidden_layer_sizes=(hidden,), solver="lbfgs", max_iter=epochs, random_state=seed))


class FieldModel(RegressorMixin, BaseEstimator):
    """PCA of displacement fields, its weights regressed from features (module docstring).

    regressor: one of REGRESSORS; n_modes: PCA modes kept (at most the training rows − 1);
    alpha: ridge / kernel-ridge regularisation (in [0, 1]-scaled units); gamma: rbf width of the
    kernel ridge; poly: degree of the ridge's polynomial features; seed: the MLP's initialisation.
    """

    def __init__(self, regressor: str = "kernel-ridge", n_modes: int = 6, alpha: float = 1e-3,
                 gamma: float = 1.0, poly: int = 2, seed: int = 0):
        self.regressor = regressor
        self.n_modes = n_modes
        self.alpha = alpha
        self.gamma = gamma
        self.poly = poly
        self.seed = seed

    def _weights_model(self, n_features: int) -> TransformedTargetRegressor:
        if self.regressor == "ridge":
            return scaled(Ridge(self.alpha), poly=self.poly)
        if self.regressor == "kernel-ridge":
            return scaled(KernelRidge(alpha=self.alpha, kernel="rbf", gamma=self.gamma))
        if self.regressor == "gp":
            kernel = ConstantKernel() * RBF(np.ones(n_features), (1e-2, 1e3)) + WhiteKernel(1e-4, (1e-8, 1e-1))
            return scaled(GaussianProcessRegressor(kernel, normalize_y=True, random_state=self.seed))
        if self.regressor == "mlp":
            return scaled(MLPRegressor(hidden_layer_sizes=(32,), solver="lbfgs", alpha=self.alpha, max_iter=2000, random_state=self.seed))
        raise ValueError(f"unknown regressor '{self.regressor}'; choose one of {', '.join(REGRESSORS)}")

    def fit(self, X, Y) -> "FieldModel":
        """Learn from X (n, features) and Y (n, K·3) displacement fields (box units); returns self."""
        X, Y = validate_data(self, X, Y, multi_output=True, y_numeric=True, dtype=float, ensure_min_samples=2)
        self.single_output_ = Y.ndim == 1                    # a scalar target, as scikit-learn allows
        Y = Y.reshape(len(Y), -1)
        if isinstance(self.n_modes, bool) or not isinstance(self.n_modes, numbers.Integral) or self.n_modes < 1:
            raise ValueError(f"n_modes must be a whole number of PCA modes >= 1, got {self.n_modes!r}")
        modes = min(self.n_modes, len(Y) - 1, Y.shape[1])
        self.pca_ = PCA(modes, svd_solver="full").fit(Y)     # exact, so one seed gives one model
        self.weights_ = self._weights_model(X.shape[1]).fit(X, self.pca_.transform(Y))
        return self

    def predict(self, X) -> np.ndarray:
        """(n, K·3) displacement fields, box units ((n,) for a model fitted on a 1-D Y)."""
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=float)
        fields = self.pca_.inverse_transform(self.weights_.predict(X).reshape(len(X), -1))
        return fields[:, 0] if self.single_output_ else fields

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags
