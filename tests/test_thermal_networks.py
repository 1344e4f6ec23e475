"""Virtual-sensor models (regression, static network, TDNN), LM/Adam training, metrics,
residual analysis and input selection."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.stats as st

from jaxvs.calibration import ExcitationWarning, describe
from jaxvs.data import Record
from jaxvs.models import BiasFreeRegression, Perceptron, StaticNetwork, TimeDelayNetwork
from jaxvs.studies import (
    ExtrapolationWarning,
    NoOperatingPointChangeWarning,
    correlation_matrix,
    fit_regression,
    mapd,
    r2,
    rank_inputs,
    residual_analysis,
    rmse,
    split_train_test,
    train_adam,
    train_lm,
    vs_metrics,
)


def test_regression_matches_lstsq_and_study_form():
    rng = np.random.default_rng(0)
    u = np.column_stack([19.8 + 10 * rng.random(500), 496 + 4000 * rng.random(500)])
    y = 20.40 + 5.48 * (u[:, 0] - u[:, 0].min()) + 0.0035 * (u[:, 1] - u[:, 1].min())
    m = fit_regression(u, y)
    # noiseless linear data: coefficients exact to rounding
    np.testing.assert_allclose(m.coef, [5.48, 0.0035], rtol=1e-9)
    assert float(m.intercept) == pytest.approx(20.40, rel=1e-9)
    np.testing.assert_allclose(m.bias, u.min(axis=0))
    np.testing.assert_allclose(m(u), y, atol=1e-9)
    with pytest.warns(ExcitationWarning, match="constant"):
        fit_regression(np.column_stack([u[:, 0], np.ones(500)]), y)


def test_tdnn_features_are_delayed_inputs():
    net = TimeDelayNetwork(2, 4, (0, 1, 2), key=jr.key(0))
    u = jnp.arange(10.0).reshape(5, 2)
    X = net.features(u)
    assert X.shape == (5, 6)
    np.testing.assert_allclose(X[3], [6, 7, 4, 5, 2, 3])
    np.testing.assert_allclose(X[0], [0, 1, 0, 1, 0, 1])  # before the start: the first sample
    # the TDNN with only delay 0 is a static network with the same weights
    tdnn0 = TimeDelayNetwork(2, 4, (0,), key=jr.key(1))
    static = StaticNetwork(2, 4, key=jr.key(1))
    np.testing.assert_allclose(tdnn0(u), static(u))


def test_perceptron_is_the_formula():
    p = Perceptron(3, 5, key=jr.key(2))
    x = jnp.array([0.1, -0.3, 0.7])
    ref = np.asarray(p.W2) @ np.tanh(np.asarray(p.W1) @ np.asarray(x) + np.asarray(p.b1))
    assert float(p(x)) == pytest.approx(float(ref + p.b2), rel=1e-12)


def _teacher_data(n=600, key=3):
    """Data from a known TDNN (a reachable zero-error target)."""
    teacher = TimeDelayNetwork(2, 5, (0, 1, 2), key=jr.key(key))
    u = np.asarray(jr.uniform(jr.key(key + 1), (n, 2), minval=-1.0, maxval=1.0))
    u = np.cumsum(u, axis=0) / 10.0  # smooth-ish inputs
    return u, np.asarray(teacher(u))


def test_lm_fits_a_reachable_target_and_beats_adam_per_epoch():
    u, y = _teacher_data()
    student = TimeDelayNetwork(2, 5, (0, 1, 2), key=jr.key(10))
    lm = train_lm(student, u, y, max_epochs=200)
    mse_lm = float(lm.train_mse[int(lm.epochs)])
    # a network of the teacher's size can reach the teacher: the LM MSE falls by >4
    # decades from its start (some seeds stall in a local minimum at larger values)
    assert mse_lm < 1e-4 * float(lm.train_mse[0])
    assert np.all(np.diff(lm.train_mse[: int(lm.epochs) + 1]) <= 0)  # LM only accepts descents
    adam = train_adam(student, u, y, epochs=200, learning_rate=1e-2)
    assert mse_lm < float(adam.train_mse[-1])
    # the returned model reproduces the reported MSE
    assert float(np.mean((np.asarray(lm.model(u)) - y) ** 2)) == pytest.approx(mse_lm, rel=1e-6)


def test_early_stopping_on_validation_block():
    u, y = _teacher_data(800)
    y = y + 0.3 * np.random.default_rng(0).normal(size=y.size)  # noise to overfit
    net = StaticNetwork(2, 15, key=jr.key(4))
    res = train_lm(net, u[:500], y[:500], validation=(u[500:], y[500:]), max_epochs=500, max_fail=6)
    k, best = int(res.epochs), int(res.best_epoch)
    assert res.stop_reason in ("validation_stop", "mu_max", "min_grad")
    # the same stop as a code of the one RESULTS enumeration
    names = {"validation_stop": "validation_stop", "mu_max": "damping_limit"}
    names["min_grad"] = "gradient_small"
    assert describe(res.result) == names[res.stop_reason]
    if res.stop_reason == "validation_stop":
        assert k == best + 6
    val = np.asarray(res.val_mse[: k + 1])
    assert val[best] == pytest.approx(np.min(val))
    pred = np.asarray(res.model(u[500:]))
    assert float(np.mean((pred - y[500:]) ** 2)) == pytest.approx(val[best], rel=1e-6)


def test_lm_jacobian_matches_jacfwd():
    """The batched per-sample reverse-mode Jacobian the trainer uses equals jax.jacfwd of
    the whole output (an independent forward-mode oracle)."""
    from jax.flatten_util import ravel_pytree

    net = TimeDelayNetwork(2, 4, key=jr.key(5))
    X = jr.normal(jr.key(6), (50, 6))
    params, static = eqx.partition(net.perceptron, eqx.is_inexact_array)
    theta, unravel = ravel_pytree(params)
    pred = lambda th, x: eqx.combine(unravel(th), static)(x)
    J = jax.vmap(jax.grad(pred), in_axes=(None, 0))(theta, X)
    Jf = jax.jacfwd(lambda th: jax.vmap(lambda x: pred(th, x))(X))(theta)
    np.testing.assert_allclose(J, Jf, rtol=1e-12, atol=1e-14)


def test_metrics_against_closed_forms():
    y = np.array([20.0, 25.0, 30.0, 35.0])
    p = np.array([21.0, 24.0, 30.0, 36.0])
    assert rmse(y, p) == pytest.approx(np.sqrt(3 / 4))
    assert r2(y, p) == pytest.approx(1 - 3 / 125)
    assert mapd(y, p) == pytest.approx(25 * (1 / 20 + 1 / 25 + 0 + 1 / 35))
    assert vs_metrics(y, p)["RMSE"] == rmse(y, p)
    with pytest.raises(ValueError, match="same length"):
        rmse(y, p[:3])


def test_residual_analysis_white_vs_correlated():
    rng = np.random.default_rng(7)
    e = rng.normal(size=4000)
    a = residual_analysis(e, max_lag=20)
    # ACF against the direct (biased) estimator
    c = e - e.mean()
    ref = np.array([np.dot(c[: len(c) - k], c[k:]) for k in range(21)]) / np.dot(c, c)
    np.testing.assert_allclose(a.acf, ref, atol=1e-12)
    assert a.bound == pytest.approx(1.959964 / np.sqrt(4000), rel=1e-5)
    assert a.white and a.normality_pvalue > 0.01
    k2, p = st.normaltest(e)
    assert a.normality == pytest.approx(k2)
    # AR(1) residuals (a model missing dynamics) are not white
    ar = np.zeros(4000)
    for i in range(1, 4000):
        ar[i] = 0.8 * ar[i - 1] + e[i]
    b = residual_analysis(ar, max_lag=20)
    assert not b.white and b.fraction_outside > 0.5
    # uniform residuals are not normal
    assert residual_analysis(rng.uniform(size=4000)).normality_pvalue < 1e-6


def test_split_warns_without_operating_point_change():
    t = np.arange(1000) * 5.0
    v = np.where(t < 2000, 1000.0, 4000.0)  # the only change in the first 70 %
    rec = Record({"v_m": v, "T": 20 + v / 1000}, dt=5.0)
    with pytest.warns(NoOperatingPointChangeWarning, match="no change"):
        train, test = split_train_test(rec, 0.7)
    assert len(train) == 700 and len(test) == 300
    # test speeds inside the training range: no warning
    v2 = np.where((t < 1000) | (t > 3700), 1000.0, 4000.0)
    split_train_test(Record({"v_m": v2, "T": v2}, dt=5.0), 0.7)
    # a test block at a speed (and temperature) never trained on: extrapolation warned
    v3 = np.where(t < 4000, 1000.0, 4000.0)
    rec3 = Record({"v_m": v3, "T": 20 + v3 / 1000 + t / 5000}, dt=5.0)
    with pytest.warns(ExtrapolationWarning, match=r"v_m reaches \[1000, 4000\]"):
        split_train_test(rec3, 0.7)
    with pytest.warns(ExtrapolationWarning, match="T reaches"):
        split_train_test(rec3, 0.7, inputs=["T"])
    with pytest.raises(ValueError, match="no input 'T_chassis'"):
        split_train_test(rec3, 0.7, inputs=["T_chassis"])


def test_correlation_and_ranking():
    rng = np.random.default_rng(8)
    n = 5000
    a = rng.normal(size=n)
    b = rng.normal(size=n)
    target = a + 0.5 * b + 0.1 * rng.normal(size=n)
    data = {
        "a": a,
        "a_copy": a + 0.01 * rng.normal(size=n),  # redundant with a
        "b": b,
        "noise": rng.normal(size=n),
        "target": target,
    }
    names, R = correlation_matrix(data)
    np.testing.assert_allclose(
        R, np.corrcoef(np.column_stack([data[k] for k in names]).T), atol=1e-12
    )
    ranks = rank_inputs(data, "target")
    assert ranks[0].name in ("a", "a_copy")
    assert ranks[1].name == "b"  # relevant and not redundant beats the copy of a
    copy = next(r for r in ranks if r.name in ("a", "a_copy") and r is not ranks[0])
    assert copy.redundant and copy.redundancy > 0.99
    assert ranks[-1].name == "noise" or ranks[-1].redundant
    with pytest.warns(ExcitationWarning, match="constant"):
        rank_inputs({**data, "const": np.ones(n)}, "target")


def test_network_input_errors():
    net = StaticNetwork(2, 3, key=jr.key(0))
    with pytest.raises(ValueError, match=r"shape \(time, 2\)"):
        net(jnp.ones((10, 3)))
    with pytest.raises(ValueError, match="NaN"):
        train_lm(net, np.full((10, 2), np.nan), np.ones(10))
    with pytest.raises(ValueError, match="delays"):
        TimeDelayNetwork(2, 3, (0, -1), key=jr.key(0))
    with pytest.warns(ExcitationWarning, match="constant"):
        train_lm(
            net, np.column_stack([np.arange(10.0), np.ones(10)]), np.arange(10.0), max_epochs=2
        )
    assert isinstance(fit_regression(np.arange(10.0), np.arange(10.0)), BiasFreeRegression)


def test_perceptron_closed_form_jacobian_matches_jacfwd():
    from jax.flatten_util import ravel_pytree

    p = Perceptron(6, 5, key=jr.key(12))
    X = jr.normal(jr.key(13), (40, 6))
    params, static = eqx.partition(p, eqx.is_inexact_array)
    theta, unravel = ravel_pytree(params)
    Jf = jax.jacfwd(lambda th: jax.vmap(eqx.combine(unravel(th), static))(X))(theta)
    np.testing.assert_allclose(p.jacobian(X), Jf, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("n, chunk", [(40, 7), (257, 256), (100, 1000)])
def test_structured_normal_equations_match_jacobian(n, chunk):
    """`Perceptron.normal_equations` (Kronecker/triangle structure, chunked, J never formed)
    equals JᵀJ and Jᵀe of the closed-form Jacobian to rounding, for chunk sizes that do
    and do not divide the sample count; float32 accumulation to ~1e-6 relative."""
    p = Perceptron(6, 5, key=jr.key(14))
    X = jr.uniform(jr.key(15), (n, 6), minval=-1.0, maxval=1.0)
    e = jr.normal(jr.key(16), (n,))
    J = p.jacobian(X)
    G, g = p.normal_equations(X, e, chunk=chunk)
    np.testing.assert_allclose(G, J.T @ J, rtol=1e-12, atol=1e-12 * float(jnp.abs(J.T @ J).max()))
    np.testing.assert_allclose(g, J.T @ e, rtol=1e-12, atol=1e-12 * float(jnp.abs(J.T @ e).max()))
    G32, _ = p.normal_equations(X, e, chunk=chunk, dtype=jnp.float32)
    assert G32.dtype == X.dtype
    assert float(jnp.abs(G32 - J.T @ J).max()) < 1e-6 * float(jnp.abs(J.T @ J).max())


def test_adam_history_is_the_mse_after_each_epoch():
    """`train_mse[i]` is the training MSE after i Adam epochs: without a validation block
    the returned model is the last epoch's, so its MSE is the last entry."""
    u, y = _teacher_data()
    net = TimeDelayNetwork(2, 5, (0, 1, 2), key=jr.key(17))
    r = train_adam(net, u, y, epochs=30, learning_rate=1e-2)
    assert int(r.epochs) == 30 and r.train_mse.shape == (31,)
    mse = float(jnp.mean((r.model(jnp.asarray(u)) - jnp.asarray(y)) ** 2))
    np.testing.assert_allclose(float(r.train_mse[30]), mse, rtol=1e-10)
    assert float(r.train_mse[30]) < float(r.train_mse[0])


def test_float32_gram_trains_like_float64():
    u, y = _teacher_data()
    net = TimeDelayNetwork(2, 5, (0, 1, 2), key=jr.key(10))
    a = train_lm(net, u, y, max_epochs=15)
    b = train_lm(net, u, y, max_epochs=15, gram_dtype=jnp.float32)
    # same steps up to the float32 rounding of JᵀJ: MSE histories agree to ~1e-3 relative
    np.testing.assert_allclose(b.train_mse[:16], a.train_mse[:16], rtol=1e-2)


@pytest.mark.slow
def test_joint_calibration_of_interpolation_and_tdnn():
    """Per-part laws and TDNN weights in one jaxvs.calibrate problem."""
    import warnings

    import jaxvs
    from jaxvs.calibration import EquationError, positive
    from jaxvs.studies import fit_piecewise_first_order
    from jaxvs.twins import SpindleThermalTwin

    twin = SpindleThermalTwin({"dynamics": 240.0})
    rec = twin.experiment(jr.key(0), [2000.0, 5000.0, 1000.0], 2400.0)
    sp = twin.sparse_target(rec, jr.key(1))
    starts = rec.metadata["part_start_times"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        laws = fit_piecewise_first_order(sp.t, sp.T_bearing, starts)
    u = np.column_stack([rec["T_chassis"], rec["v_m"]])
    y_res = np.asarray(laws(rec.t))
    net = train_lm(TimeDelayNetwork(2, 4, key=jr.key(2)), u, y_res, max_epochs=30).model

    def residual(model, d):
        laws, net = jaxvs.calibration.unwrap(model)
        return jnp.concatenate([(laws(d["ts"]) - d["ys"]) / 0.1, (net(d["u"]) - laws(d["t"]))])

    data = {"ts": sp.t, "ys": sp.T_bearing, "t": rec.t, "u": u}
    model = (eqx.tree_at(lambda m: m.T1, laws, replace_fn=positive), net)
    res = jaxvs.calibrate(
        model,
        data,
        EquationError(residual),
        free=lambda m: (m[0].T0, m[0].k, m[0].T1, m[1].perceptron),
        covariance=False,
        max_steps=10,
        throw=False,
    )
    assert float(res.cost) < float(res.stats["initial_cost"])  # LM only accepts descents
    laws_j, _ = res.model
    # the interpolation still follows the sparse samples within a few noise levels
    e = np.asarray(laws_j(sp.t)) - sp.T_bearing
    assert np.sqrt(np.mean(e**2)) < 0.5
    np.testing.assert_allclose(laws_j.T1, laws.T1, rtol=0.5)
