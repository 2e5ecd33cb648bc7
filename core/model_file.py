"""Trained regressors as `breastplan.model/1` NPZ files, run without pickle or scikit-learn.

A model is a fitted `TransformedTargetRegressor(Pipeline([MinMaxScaler, PolynomialFeatures?,
R]), transformer=MinMaxScaler)` with R a LinearRegression or Ridge, an SVR (linear, poly or rbf
kernel), a MultiOutputRegressor of such SVRs, a KernelRidge (rbf kernel) or an MLPRegressor
(docs/artefacts.md).
`export_arrays` flattens it into plain arrays; `ModelFile.predict` replays the forward pass
in numpy in scikit-learn's order of operations, so predictions match the estimator's to the
last bit or within a few ulps.

Arrays: `kind` ("linear" | "svr" | "mlp"), `out_ndim` (1: predictions of shape (n,), 2:
(n, n_outputs)), `x_min`, `x_scale` (input scaler: X * x_scale + x_min), optional
`poly_powers` (PolynomialFeatures.powers_), `y_min`, `y_scale` (target scaler, undone as
(Z - y_min) / y_scale), and by kind:

* linear: `lin_coef` (n_outputs, n_terms), `lin_intercept` (n_outputs,);
* svr: `svr_kernel`, and per output `svr_gamma`, `svr_degree`, `svr_coef0`, `svr_intercept`
  (n_outputs,) with `svr<k>_support` (n_sv, n_terms) and `svr<k>_dual_coef` (n_sv,);
* kernel: `krr_gamma` (), `krr_support` (n_fit, n_terms), `krr_dual_coef` (n_fit, n_outputs);
* mlp: `mlp_activation`, and per layer `mlp_w<i>` (n_in, n_out) and `mlp_b<i>` (n_out,).

Caller arrays (e.g. a PCA feature stage) are stored as `extra_<name>`.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np
from scipy.special import expit

from breastplan import ArtefactError, load_npz, save_npz
from breastplan.artefacts import check_arrays

SCHEMA = "breastplan.model/1"
KERNELS = ("linear", "poly", "rbf")
MAX_POWER = 16
"""The largest polynomial power (a feature's, or an SVR's degree) a model file may hold: a power
beyond it is no trained model's, and makes a prediction's cost or value explode."""
ACTIVATIONS = {"identity": lambda z: z, "relu": lambda z: np.maximum(z, 0, out=z),
               "tanh": lambda z: np.tanh(z, out=z), "logistic": lambda z: expit(z, out=z)}
EXTRA = "extra_"


# ---------------------------------------------------------------- export

def export_arrays(estimator) -> dict[str, np.ndarray]:
    """The arrays of a fitted estimator of the supported structure; ValueError otherwise."""
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import MinMaxScaler, PolynomialFeatures

    if not (isinstance(estimator, TransformedTargetRegressor) and hasattr(estimator, "regressor_")):
        raise ValueError(f"expected a fitted TransformedTargetRegressor, got {type(estimator).__name__}")
    y_scaler, pipe = estimator.transformer_, estimator.regressor_
    steps = [step for _, step in pipe.steps] if isinstance(pipe, Pipeline) else []
    has_poly = len(steps) == 3 and isinstance(steps[1], PolynomialFeatures)
    scalers = [y_scaler, *steps[:1]]
    if not (len(steps) == 2 + has_poly and all(type(s) is MinMaxScaler and not s.clip for s in scalers)):
        raise ValueError("expected TransformedTargetRegressor(Pipeline([MinMaxScaler, [PolynomialFeatures,] "
                         "regressor]), transformer=MinMaxScaler), without clipping")
    arrays = {"out_ndim": np.int64(estimator._training_dim),  # TTR's own record of y's ndim
              "x_min": steps[0].min_, "x_scale": steps[0].scale_,
              "y_min": y_scaler.min_, "y_scale": y_scaler.scale_}
    if has_poly:
        arrays["poly_powers"] = steps[1].powers_
    arrays.update(_regressor_arrays(steps[-1]))
    return {k: np.array(v) for k, v in arrays.items()}


def _regressor_arrays(reg) -> dict:
    """`kind` and the arrays of the pipeline's final regressor."""
    from sklearn.kernel_ridge import KernelRidge
    from sklearn.linear_model import LinearRegression, Ridge
    from sklearn.multioutput import MultiOutputRegressor
    from sklearn.neural_network import MLPRegressor
    from sklearn.svm import SVR

    if type(reg) is KernelRidge and reg.kernel == "rbf":
        gamma = 1.0 / reg.X_fit_.shape[1] if reg.gamma is None else reg.gamma   # sklearn's default
        return {"kind": np.str_("kernel"), "krr_gamma": np.float64(gamma), "krr_support": reg.X_fit_,
                "krr_dual_coef": reg.dual_coef_.reshape(len(reg.X_fit_), -1)}
    if type(reg) in (LinearRegression, Ridge):
        coef = np.atleast_2d(reg.coef_)
        return {"kind": np.str_("linear"), "lin_coef": coef,
                "lin_intercept": np.broadcast_to(reg.intercept_, coef.shape[:1])}
    if type(reg) is MLPRegressor and reg.activation in ACTIVATIONS and reg.out_activation_ == "identity":
        layers = {f"mlp_{p}{i}": a for i, (w, b) in enumerate(zip(reg.coefs_, reg.intercepts_))
                  for p, a in (("w", w), ("b", b))}
        return {"kind": np.str_("mlp"), "mlp_activation": np.str_(reg.activation), **layers}
    svrs = reg.estimators_ if type(reg) is MultiOutputRegressor else [reg]
    if all(type(s) is SVR for s in svrs) and len({s.kernel for s in svrs}) == 1 and svrs[0].kernel in KERNELS:
        arrays = {"kind": np.str_("svr"), "svr_kernel": np.str_(svrs[0].kernel),
                  "svr_gamma": [s._gamma for s in svrs], "svr_degree": [s.degree for s in svrs],
                  "svr_coef0": [s.coef0 for s in svrs], "svr_intercept": [s.intercept_[0] for s in svrs]}
        for k, s in enumerate(svrs):
            arrays[f"svr{k}_support"], arrays[f"svr{k}_dual_coef"] = s.support_vectors_, s.dual_coef_[0]
        return arrays
    raise ValueError(f"unsupported regressor {reg!r}: expected LinearRegression, Ridge, SVR with a "
                     f"{'/'.join(KERNELS)} kernel, MultiOutputRegressor(SVR), KernelRidge (rbf) or MLPRegressor")


def save_model(path: str | Path, estimator, *, meta: Mapping,
               extra: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write `estimator` as a breastplan.model/1 NPZ, atomically; `extra` arrays come back on load."""
    import sklearn

    if "estimator" in meta:
        raise ValueError("meta key 'estimator' is reserved for the model description")
    arrays = export_arrays(estimator)
    arrays.update({EXTRA + k: np.asarray(v) for k, v in (extra or {}).items()})
    info = {"kind": str(arrays["kind"]), "sklearn": sklearn.__version__}
    return save_npz(path, SCHEMA, arrays, units="model", frame="breast", meta={**meta, "estimator": info})


# ---------------------------------------------------------------- load and predict

@dataclass
class ModelFile:
    """A loaded model: caller `meta` and `extra` arrays, and a numpy-only `predict`.

    `arrays` holds the model's own arrays (module docstring), as validated on load.
    """

    meta: dict
    extra: dict[str, np.ndarray]
    n_features: int
    n_outputs: int
    arrays: dict[str, np.ndarray] = field(repr=False)
    path: Path | None = None

    @property
    def kinds(self) -> list[str]:
        """The deformation types the model makes: a statistical model's `kinds`, a parametric one's `kind`."""
        return list(self.meta.get("kinds") or [self.meta.get("kind")])

    def predict(self, X) -> np.ndarray:
        """Predictions for the rows of X: shape (n,) or (n, n_outputs), as the estimator's; ArtefactError
        naming the file if they are not finite (a damaged model, or inputs far outside its training)."""
        with np.errstate(over="ignore", invalid="ignore"):         # what overflows is refused below
            Z = self._predict(X)
        if not np.isfinite(Z).all():
            raise ArtefactError(self.path, "predicts values that are not finite for this breast (a damaged model, "
                                           "or one trained far from such breasts)")
        return Z

    def _predict(self, X) -> np.ndarray:
        a = self.arrays
        X = np.array(X, dtype=np.float64, ndmin=2)            # a copy, scaled in place
        if X.ndim != 2 or X.shape[1] != self.n_features:
            raise ValueError(f"X has shape {X.shape}, expected (n, {self.n_features})")
        X *= a["x_scale"]
        X += a["x_min"]
        if "poly_powers" in a:
            X = _poly(X, a["poly_powers"])
        Z = _PREDICT[str(a["kind"])](a, X)
        Z -= a["y_min"]
        Z /= a["y_scale"]
        return Z[:, 0] if a["out_ndim"] == 1 else Z


def load_model(path: str | Path) -> ModelFile:
    """Load and validate a breastplan.model/1 NPZ; any defect raises ArtefactError naming the file."""
    art = load_npz(path, SCHEMA, meta_spec={"model": str, "kind": str, "kinds": [str], "condition": str,
                                            "lattice": int, "feature_set": str, "estimator": dict})
    arrays = {k: v for k, v in art.items() if not k.startswith(EXTRA)}
    _check(Path(path), arrays)
    extra = {k[len(EXTRA):]: v for k, v in art.items() if k.startswith(EXTRA)}
    for key, v in extra.items():
        if v.dtype.kind == "f" and not np.isfinite(v).all():
            raise ArtefactError(Path(path), f"has NaN or infinite values in '{EXTRA}{key}'")
    return ModelFile(meta=art.meta, extra=extra, n_features=arrays["x_min"].size,
                     n_outputs=arrays["y_min"].size, arrays=arrays, path=Path(path))


def _poly(X: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """PolynomialFeatures columns, each multiplied in sklearn's order: x_last * ... * x_first."""
    cols = []
    for p in powers:
        idx = np.repeat(np.arange(p.size), p)
        col = X[:, idx[-1]] if idx.size else np.ones(len(X))
        for i in idx[-2::-1]:
            col = col * X[:, i]
        cols.append(col)
    return np.column_stack(cols)


def _linear(a: dict, X: np.ndarray) -> np.ndarray:
    coef, intercept = a["lin_coef"], a["lin_intercept"]
    if a["out_ndim"] == 1:                                    # sklearn's 1-D coef_: matrix @ vector
        return (X @ coef[0] + intercept[0])[:, None]
    return X @ coef.T + intercept


def _svr(a: dict, X: np.ndarray) -> np.ndarray:
    """libsvm's decision values: kernel per support vector, then a running sum over them."""
    kernel, out = str(a["svr_kernel"]), []
    for k in range(a["svr_intercept"].size):
        sv, dual = a[f"svr{k}_support"], a[f"svr{k}_dual_coef"]
        K = np.zeros((len(X), len(sv)))
        for j, v in enumerate(sv):
            K[:, j] = _rowdot(X - v, X - v) if kernel == "rbf" else _rowdot(X, v)
        if kernel == "rbf":
            K = np.exp(-a["svr_gamma"][k] * K)
        elif kernel == "poly":
            K = _powi(a["svr_gamma"][k] * K + a["svr_coef0"][k], int(a["svr_degree"][k]))
        total = np.cumsum(dual * K, axis=1)[:, -1] if len(sv) else np.zeros(len(X))
        out.append(total + a["svr_intercept"][k])
    return np.column_stack(out)


def _rowdot(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product of each row of A with b (a vector or rows), one BLAS ddot each, as libsvm does."""
    return (A[:, None, :] @ b[..., None])[:, 0, 0]


def _powi(base: np.ndarray, times: int) -> np.ndarray:
    """base ** times by libsvm's repeated squaring."""
    result = np.ones_like(base)
    while times > 0:
        if times % 2:
            result = result * base
        base = base * base
        times //= 2
    return result


def _kernel(a: dict, X: np.ndarray) -> np.ndarray:
    """KernelRidge's rbf prediction: exp(−γ‖x − s‖²) against the training rows s, times the dual
    coefficients; the squared distances are summed in scikit-learn's order (−2x·s + ‖x‖² + ‖s‖²)."""
    S = a["krr_support"]
    d2 = -2.0 * (X @ S.T)
    d2 += np.einsum("ij,ij->i", X, X)[:, None]
    d2 += np.einsum("ij,ij->i", S, S)[None, :]
    np.maximum(d2, 0, out=d2)
    d2 *= -float(a["krr_gamma"])
    return np.exp(d2, out=d2) @ a["krr_dual_coef"]


def _mlp(a: dict, X: np.ndarray) -> np.ndarray:
    act, n_layers = ACTIVATIONS[str(a["mlp_activation"])], _count(a, "mlp_w")
    for i in range(n_layers):
        X = X @ a[f"mlp_w{i}"]
        X += a[f"mlp_b{i}"]
        if i < n_layers - 1:
            X = act(X)
    return X


_PREDICT = {"linear": _linear, "svr": _svr, "kernel": _kernel, "mlp": _mlp}


# ---------------------------------------------------------------- validation

def _count(a: Mapping, prefix: str) -> int:
    """How many arrays are named <prefix><i>."""
    return sum(bool(re.fullmatch(rf"{prefix}\d+", k)) for k in a)


def _spec(a: Mapping) -> dict[str, tuple[str, tuple]]:
    """name → (dtype kinds, shape of named sizes) for the arrays this model's kind needs."""
    terms = "terms" if "poly_powers" in a else "in"
    spec = {"kind": ("U", ()), "out_ndim": ("iu", ()), "x_min": ("f", ("in",)), "x_scale": ("f", ("in",)),
            "y_min": ("f", ("out",)), "y_scale": ("f", ("out",))}
    if "poly_powers" in a:
        spec["poly_powers"] = ("iu", ("terms", "in"))
    kind = str(a.get("kind", ""))
    if kind == "linear":
        spec.update(lin_coef=("f", ("out", terms)), lin_intercept=("f", ("out",)))
    elif kind == "svr":
        spec.update(svr_kernel=("U", ()), svr_gamma=("f", ("out",)), svr_degree=("iu", ("out",)),
                    svr_coef0=("f", ("out",)), svr_intercept=("f", ("out",)))
        for k in range(np.size(a.get("y_min", ()))):
            spec[f"svr{k}_support"] = ("f", (f"sv{k}", terms))
            spec[f"svr{k}_dual_coef"] = ("f", (f"sv{k}",))
    elif kind == "kernel":
        spec.update(krr_gamma=("f", ()), krr_support=("f", ("fit", terms)), krr_dual_coef=("f", ("fit", "out")))
    elif kind == "mlp":
        spec["mlp_activation"] = ("U", ())
        n = max(_count(a, "mlp_w"), _count(a, "mlp_b"), 1)
        sizes = [terms, *(f"hidden{i}" for i in range(1, n)), "out"]
        for i in range(n):
            spec[f"mlp_w{i}"] = ("f", (sizes[i], sizes[i + 1]))
            spec[f"mlp_b{i}"] = ("f", (sizes[i + 1],))
    return spec


def _check(path: Path, a: dict[str, np.ndarray]) -> None:
    """ArtefactError naming `path` unless the arrays form a consistent model."""
    sizes = check_arrays(path, a, _spec(a))
    problems = {
        f"has unknown model kind '{a['kind']}'": str(a["kind"]) not in _PREDICT,
        f"has out_ndim {a['out_ndim']} with {sizes['out']} outputs; expected 2, or 1 for a single output":
            a["out_ndim"] not in (1, 2) or (a["out_ndim"] == 1 and sizes["out"] != 1),
        "has a zero in 'y_scale'": not np.all(a["y_scale"]),
        f"has 'poly_powers' outside 0..{MAX_POWER}": "poly_powers" in a and not _within(a["poly_powers"], 0, MAX_POWER),
        f"has unknown SVR kernel '{a.get('svr_kernel')}'": "svr_kernel" in a and str(a["svr_kernel"]) not in KERNELS,
        f"has an 'svr_degree' outside 0..{MAX_POWER}": "svr_degree" in a and not _within(a["svr_degree"], 0, MAX_POWER),
        "has a negative kernel 'svr_gamma' or 'krr_gamma'": any((a[k] < 0).any() for k in ("svr_gamma", "krr_gamma")
                                                                if k in a),
        f"has unknown MLP activation '{a.get('mlp_activation')}'":
            "mlp_activation" in a and str(a["mlp_activation"]) not in ACTIVATIONS,
    }
    for problem, found in problems.items():
        if found:
            raise ArtefactError(path, problem)


def _within(values: np.ndarray, low: int, high: int) -> bool:
    return bool(((values >= low) & (values <= high)).all())
