"""breastplan.model/1 files: numpy predictions equal the estimator's; validation; round trips."""
import os
import re
import warnings

import numpy as np
import pytest
from sklearn.compose import TransformedTargetRegressor
from sklearn.exceptions import ConvergenceWarning, DataConversionWarning
from sklearn.kernel_ridge import KernelRidge
from sklearn.linear_model import Lasso, LinearRegression
from sklearn.multioutput import MultiOutputRegressor
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import MinMaxScaler, PolynomialFeatures, StandardScaler
from sklearn.svm import SVR
from threadpoolctl import threadpool_limits

from breastplan import ArtefactError, save_npz
from breastplan.model_file import SCHEMA, ModelFile, export_arrays, load_model, save_model

RNG = np.random.default_rng(7)
X_TRAIN = RNG.normal(size=(60, 4))
Y_TRAIN = np.c_[X_TRAIN @ [1.0, -2.0, 0.5, 0.0] + np.sin(X_TRAIN[:, 0]), X_TRAIN[:, 1] * X_TRAIN[:, 2]]
X_FRESH = 1.5 * RNG.normal(size=(50, 4))                       # partly outside the training range


def model(reg, degree=None):
    """The estimator structure breastplan trains: scaled inputs, optional polynomial, scaled targets."""
    poly = [("poly", PolynomialFeatures(degree=degree, include_bias=False))] if degree else []
    return TransformedTargetRegressor(regressor=Pipeline([("scale", MinMaxScaler()), *poly, ("reg", reg)]),
                                      transformer=MinMaxScaler())


def svr(kernel, degree=3):
    return SVR(kernel=kernel, C=3.0, gamma=0.7, degree=degree, coef0=0.3, epsilon=0.01)


def mlp(hidden, activation):
    return MLPRegressor(hidden_layer_sizes=(hidden,), activation=activation, solver="lbfgs",
                        max_iter=20, random_state=0)


def fit(estimator, y):
    with warnings.catch_warnings(), threadpool_limits(1, "blas"):   # tiny problems: threads only contend
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.simplefilter("ignore", DataConversionWarning)   # MLP and (n, 1) targets
        return estimator.fit(X_TRAIN, y)


LINEAR = [(f"linear-d{d}-{'b' if b else 'nob'}", lambda d=d, b=b: model(LinearRegression(fit_intercept=b), d))
          for d in (1, 2, 3, 4) for b in (True, False)]
SVR_KERNELS = {"linear": ("linear", 3), "poly2": ("poly", 2), "poly3": ("poly", 3), "rbf": ("rbf", 3)}
SVR_ONE = [(f"svr-{k}", lambda k=k: model(svr(*SVR_KERNELS[k]))) for k in SVR_KERNELS]
SVR_TWO = [(f"svr2-{k}", lambda k=k: model(MultiOutputRegressor(svr(*SVR_KERNELS[k])))) for k in SVR_KERNELS]
MLP = [(f"mlp{h}-{a}", lambda h=h, a=a: model(mlp(h, a)))
       for h in (5, 25) for a in ("relu", "tanh", "logistic", "identity")]
CASES = ([(n, m, 1) for n, m in LINEAR + SVR_ONE + MLP] + [(n, m, 2) for n, m in LINEAR + SVR_TWO + MLP])


@pytest.mark.parametrize("name, make, n_out", CASES, ids=[f"{n}-{k}out" for n, _, k in CASES])
def test_predictions_match_the_estimator(tmp_path, name, make, n_out):
    est = fit(make(), Y_TRAIN[:, 0] if n_out == 1 else Y_TRAIN)
    m = load_model(save_model(tmp_path / f"{name}.npz", est, meta={"name": name}))
    expected = est.predict(X_FRESH)
    got = m.predict(X_FRESH)
    assert (m.n_features, m.n_outputs) == (4, n_out)
    assert got.shape == expected.shape == ((50,) if n_out == 1 else (50, 2))
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.predict(X_FRESH[0]), expected[:1], rtol=1e-12, atol=1e-12)  # one row


@pytest.mark.parametrize("make", [LINEAR[2][1], SVR_TWO[3][1], MLP[1][1]], ids=["linear", "svr", "mlp"])
def test_column_vector_targets_keep_their_shape(tmp_path, make):
    est = fit(make(), Y_TRAIN[:, :1])
    got = load_model(save_model(tmp_path / "m.npz", est, meta={})).predict(X_FRESH)
    assert got.shape == (50, 1)
    np.testing.assert_allclose(got, est.predict(X_FRESH), rtol=1e-12, atol=1e-12)


def test_file_loads_without_pickle_and_holds_plain_arrays(tmp_path):
    path = save_model(tmp_path / "m.npz", fit(model(mlp(5, "tanh")), Y_TRAIN), meta={})
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    assert str(arrays["schema"]) == SCHEMA
    assert str(arrays["kind"]) == "mlp" and str(arrays["mlp_activation"]) == "tanh"
    assert {"x_min", "x_scale", "y_min", "y_scale", "mlp_w0", "mlp_b0", "mlp_w1", "mlp_b1"} <= set(arrays)
    assert all(a.dtype.kind in "fiuU" for a in arrays.values())


def test_meta_and_extra_round_trip(tmp_path):
    meta = {"training_set": "V", "cv_score": 0.93, "features": ["a", "b", "c", "d"], "grid": {"k": 5}}
    extra = {"pca_components": RNG.normal(size=(3, 4)), "pca_mean": np.arange(4.0), "labels": np.array(["x", "y"])}
    est = fit(model(LinearRegression(), 2), Y_TRAIN)
    m = load_model(save_model(tmp_path / "m.npz", est, meta=meta, extra=extra))
    assert {k: v for k, v in m.meta.items() if k != "estimator"} == meta
    assert m.meta["estimator"]["kind"] == "linear"
    assert m.extra.keys() == extra.keys()
    for k, v in extra.items():
        assert m.extra[k].dtype == v.dtype and np.array_equal(m.extra[k], v)
    with pytest.raises(ValueError, match="reserved"):
        save_model(tmp_path / "n.npz", est, meta={"estimator": "mine"})


def test_writes_are_atomic(tmp_path):
    est = fit(model(LinearRegression()), Y_TRAIN[:, 0])
    save_model(tmp_path / "m.npz", est, meta={})
    before = (tmp_path / "m.npz").read_bytes()
    with pytest.raises(ValueError):                            # object dtype: refused mid-way
        save_model(tmp_path / "m.npz", est, meta={}, extra={"bad": np.array([None, 1], dtype=object)})
    assert os.listdir(tmp_path) == ["m.npz"]                   # no temporary file left behind
    assert (tmp_path / "m.npz").read_bytes() == before


def test_truncated_file_and_wrong_schema_raise_artefact_error(tmp_path):
    good = save_model(tmp_path / "m.npz", fit(model(svr("rbf")), Y_TRAIN[:, 0]), meta={})
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:300])
    other = save_npz(tmp_path / "other.npz", "breastplan.database/1", export_arrays(fit(model(svr("rbf")), Y_TRAIN[:, 0])))
    for path in (cut, other, tmp_path / "missing.npz"):
        with pytest.raises(ArtefactError, match=re.escape(path.name)):
            load_model(path)


def _break(name, arrays):
    """Spoil one thing in exported arrays; returns the arrays and the text the error must contain."""
    a = dict(arrays)
    if name == "x_min-length":
        a["x_min"] = a["x_min"][:-1]
        return a, "x_scale"                                    # x_min fixed the size; x_scale disagrees
    if name == "missing":
        del a["y_scale"]
        return a, "y_scale"
    if name == "mlp-chain":
        a["mlp_w1"] = a["mlp_w1"][:-1]
        return a, "mlp_w1"
    if name == "nan":
        a["mlp_b0"] = np.full_like(a["mlp_b0"], np.nan)
        return a, "NaN"
    if name == "activation":
        a["mlp_activation"] = np.str_("softplus")
        return a, "softplus"
    if name == "kind":
        a["kind"] = np.str_("forest")
        return a, "forest"
    if name == "out_ndim":
        a["out_ndim"] = np.int64(1)
        return a, "out_ndim"
    raise AssertionError(name)


@pytest.fixture(scope="module")
def mlp_arrays():
    return export_arrays(fit(model(mlp(5, "relu")), Y_TRAIN))


@pytest.mark.parametrize("name", ["x_min-length", "missing", "mlp-chain", "nan", "activation", "kind", "out_ndim"])
def test_inconsistent_arrays_raise_artefact_error(tmp_path, mlp_arrays, name):
    arrays, says = _break(name, mlp_arrays)
    path = save_npz(tmp_path / "bad.npz", SCHEMA, arrays)
    with pytest.raises(ArtefactError, match=re.escape(str(path))) as err:
        load_model(path)
    assert says in str(err.value)


@pytest.mark.parametrize("kind", ["svr-width", "poly-width"])
def test_feature_width_must_chain(tmp_path, kind):
    if kind == "svr-width":
        arrays = export_arrays(fit(model(MultiOutputRegressor(svr("poly"))), Y_TRAIN))
        arrays["svr1_support"] = arrays["svr1_support"][:, :3]
    else:
        arrays = export_arrays(fit(model(LinearRegression(), 3), Y_TRAIN))
        arrays["poly_powers"] = arrays["poly_powers"][:-1]
    path = save_npz(tmp_path / "bad.npz", SCHEMA, arrays)
    with pytest.raises(ArtefactError, match="inconsistent"):
        load_model(path)


@pytest.mark.parametrize("make", [
    lambda: Pipeline([("scale", MinMaxScaler()), ("reg", LinearRegression())]),
    lambda: model(Lasso(alpha=0.01)),
    lambda: model(svr("sigmoid")),
    lambda: TransformedTargetRegressor(regressor=Pipeline([("scale", StandardScaler()), ("reg", LinearRegression())]),
                                       transformer=MinMaxScaler()),
    lambda: TransformedTargetRegressor(regressor=model(LinearRegression()).regressor, transformer=StandardScaler()),
], ids=["no-ttr", "lasso", "sigmoid-kernel", "standard-scaler", "standard-target"])
def test_unsupported_estimators_are_refused(make):
    with pytest.raises(ValueError, match="expected"):
        export_arrays(fit(make(), Y_TRAIN[:, 0]))


def test_unfitted_estimators_are_refused():
    with pytest.raises(ValueError, match="fitted"):
        export_arrays(model(LinearRegression()))


@pytest.mark.parametrize("make, change, says", [
    (lambda: model(LinearRegression(), 2), {"poly_powers": lambda p: p * 10**9}, "'poly_powers' outside 0..16"),
    (lambda: model(LinearRegression(), 2), {"poly_powers": lambda p: p.astype(np.uint64) + np.uint64(2**63)},
     "beyond the range of integers"),
    (lambda: model(svr("poly")), {"svr_degree": lambda d: d + 10**9}, "'svr_degree' outside 0..16"),
    (lambda: model(svr("rbf")), {"svr_gamma": lambda g: -g}, "negative kernel"),
    (lambda: model(KernelRidge(kernel="rbf", gamma=0.5)), {"krr_gamma": lambda g: -g}, "negative kernel"),
], ids=["huge-power", "unsigned-wrap", "huge-svr-degree", "negative-svr-gamma", "negative-krr-gamma"])
def test_a_model_whose_powers_or_kernels_no_training_gives_is_refused(tmp_path, make, change, says):
    """Truth: PolynomialFeatures' powers and an SVR's degree are small non-negative integers and an RBF
    kernel's γ is non-negative; a file saying otherwise would make a prediction explode or never end."""
    arrays = export_arrays(fit(make(), Y_TRAIN[:, 0]))
    arrays.update({k: f(arrays[k]) for k, f in change.items()})
    path = save_npz(tmp_path / "bad.npz", SCHEMA, arrays)
    with pytest.raises(ArtefactError, match=re.escape(str(path))) as err:
        load_model(path)
    assert says in str(err.value)


def test_a_prediction_that_is_not_finite_is_refused_naming_the_file(tmp_path):
    arrays = export_arrays(fit(model(LinearRegression()), Y_TRAIN[:, 0]))
    arrays["x_scale"] = arrays["x_scale"] * 1e307                 # finite, but its products overflow
    m = load_model(save_npz(tmp_path / "far.npz", SCHEMA, arrays))
    with pytest.raises(ArtefactError, match=r"far\.npz: predicts values that are not finite"):
        m.predict(X_FRESH * 1000)


def test_a_single_output_kept_as_a_column_gives_one_position(tmp_path):
    """A model of one output saved with out_ndim 2 predicts (n, 1); a position on a condition is its one value."""
    from breastplan.deform.by_degree import learnt_position

    est = model(LinearRegression()).fit(X_TRAIN[:, :2], Y_TRAIN[:, :1])      # the degree and v0
    m = load_model(save_model(tmp_path / "m.npz", est, meta={"feature_set": "FS1"}))
    assert m.predict(X_FRESH[:1, :2]).shape == (1, 1)
    cube = np.mgrid[0:2, 0:2, 0:2].reshape(3, -1).T * 10.0
    assert 0.0 <= learnt_position(m, cube, "ptosis", 3.0) <= 1.0


def test_predict_checks_the_input_width(tmp_path):
    m = load_model(save_model(tmp_path / "m.npz", fit(model(LinearRegression()), Y_TRAIN), meta={}))
    assert isinstance(m, ModelFile)
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        m.predict(np.zeros((3, 5)))


def test_svr_without_support_vectors_predicts_its_intercept(tmp_path):
    est = fit(model(SVR(kernel="rbf", epsilon=1.0)), Y_TRAIN[:, 0])   # targets scaled to [0, 1]: all in the tube
    assert est.regressor_[-1].support_vectors_.shape[0] == 0
    got = load_model(save_model(tmp_path / "m.npz", est, meta={})).predict(X_FRESH)
    np.testing.assert_allclose(got, est.predict(X_FRESH), rtol=1e-12, atol=1e-12)
