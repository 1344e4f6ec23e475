"""First-order interpolation model (study eq. 1), its fits, and sparse-target resampling."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as sig

import jaxvs
from jaxvs.models import DrivenFirstOrder, FirstOrder, PiecewiseFirstOrder
from jaxvs.studies import (
    ThermalFitWarning,
    correct_outliers,
    detect_outliers,
    fit_piecewise_first_order,
    resample_sparse,
)

# Study Table 3 (Dementjev et al. 2014): k [°C], T0 [°C], T1 [s] of the five parts.
TABLE3 = [
    (38.90, 20.40, 150.0),
    (72.00, 20.48, 155.0),
    (-55.00, 92.63, 280.0),
    (15.05, 20.98, 225.0),
    (-23.85, 89.41, 185.0),
]


def test_first_order_closed_form_and_gradient():
    m = FirstOrder(20.0, 10.0, 100.0)
    t = jnp.array([0.0, 100.0, 1e6])
    np.testing.assert_allclose(m(t), [20.0, 20.0 + 10 * (1 - np.exp(-1)), 30.0], rtol=1e-12)
    assert float(m.final_value) == 30.0
    # gradient w.r.t. T1 against the analytic derivative -k t/T1² exp(-t/T1)
    g = jax.grad(lambda T1: FirstOrder(20.0, 10.0, T1)(50.0))(100.0)
    assert float(g) == pytest.approx(-10.0 * 50.0 / 100.0**2 * np.exp(-0.5), rel=1e-12)


@pytest.mark.parametrize("row", range(5))
def test_table3_recovered_from_90s_samples(row):
    """The study's check: samples every 90 s with 0.1 K noise; k, T0 within 2 %, T1 within 8 %."""
    k, T0, T1 = TABLE3[row]
    rng = np.random.default_rng(row)
    t = np.arange(0.0, 1800.0, 90.0)
    y = T0 + k * (1 - np.exp(-t / T1)) + 0.1 * rng.normal(size=t.size)
    m = jaxvs.fit_first_order(t, y)
    assert float(m.k) == pytest.approx(k, rel=0.02)
    assert float(m.T0) == pytest.approx(T0, rel=0.02)
    assert float(m.T1) == pytest.approx(T1, rel=0.08)


def test_fit_is_exact_on_noiseless_data_and_vmaps_parts():
    starts = np.array([0.0, 1800.0, 3600.0, 5400.0, 7200.0])
    t = np.arange(0.0, 9000.0, 90.0) + 7.0
    truth = PiecewiseFirstOrder(starts, *np.array(TABLE3)[:, [1, 0, 2]].T)
    y = np.asarray(truth(t))
    fit = fit_piecewise_first_order(t, y, starts)
    # noiseless: LM converges to the exact parameters (rtol 1e-10 on the cost)
    np.testing.assert_allclose(fit.k, truth.k, rtol=1e-6)
    np.testing.assert_allclose(fit.T0, truth.T0, rtol=1e-6)
    np.testing.assert_allclose(fit.T1, truth.T1, rtol=1e-6)


def test_continuous_piecewise_is_continuous():
    starts = np.array([0.0, 3000.0, 6000.0])
    truth = PiecewiseFirstOrder(
        starts, [20.0, 0.0, 0.0], [30.0, -10.0, 5.0], [400.0, 600.0, 300.0], continuous=True
    )
    eps = 1e-6
    for s in starts[1:]:
        assert float(truth(jnp.array([s - eps]))[0]) == pytest.approx(
            float(truth(jnp.array([s]))[0]), abs=1e-6
        )
    t = np.arange(0.0, 9000.0, 90.0)
    y = np.asarray(truth(t)) + 0.05 * np.random.default_rng(0).normal(size=t.size)
    fit = fit_piecewise_first_order(t, y, starts, continuous=True)
    # 0.05 K noise on 100 samples: gains within 1 % (3σ of the LM covariance is ~0.3 %)
    np.testing.assert_allclose(fit.k, truth.k, rtol=0.01)
    np.testing.assert_allclose(fit.start_values, truth.start_values, atol=0.1)


def test_driven_first_order_matches_lsim():
    """Oracle: scipy.signal.lsim with linear input interpolation (same input model)."""
    m = DrivenFirstOrder(20.0, 0.004, 300.0)
    t = np.arange(0.0, 3600.0, 5.0)
    u = np.where(t < 1500, 2000.0, 5000.0) + 500 * np.sin(t / 400)
    y = m.simulate(t, u)
    ss = (np.array([[-1 / 300]]), np.array([[0.004 / 300]]), np.eye(1), np.zeros((1, 1)))
    _, yr, _ = sig.lsim(ss, u, t, X0=[0.004 * u[0]], interp=True)
    # both exact for piecewise-linear input; diffrax at rtol 1e-8
    np.testing.assert_allclose(np.asarray(y), 20.0 + yr, atol=1e-5)
    # a step from steady state is the FirstOrder law with k = K Δu; the input is
    # interpolated linearly, so the 0 -> 5 s ramp acts as a step at its centre, 2.5 s
    # (difference O(k (dt/T1)²) = 12 K · 3e-4 ≈ 0.004 K)
    step = np.where(t > 0, 5000.0, 2000.0)
    y_step = m.simulate(t, step)
    ref = FirstOrder(20.0 + 0.004 * 2000, 0.004 * 3000, 300.0)(t - 2.5)
    np.testing.assert_allclose(np.asarray(y_step)[1:], np.asarray(ref)[1:], atol=0.01)


def test_resampling_through_exponentials_beats_linear():
    starts = np.array([0.0, 1800.0, 3600.0])
    truth = PiecewiseFirstOrder(
        starts, [20.4, 20.48, 92.63], [38.9, 72.0, -55.0], [150.0, 155.0, 280.0]
    )
    grid = np.arange(0.0, 5400.0, 5.0)
    rng = np.random.default_rng(1)
    ts = np.sort(rng.choice(grid[grid > 0], 60, replace=False))
    ys = np.asarray(truth(ts)) + 0.1 * rng.normal(size=ts.size)
    y_exp, model = resample_sparse(ts, ys, grid, part_starts=starts)
    y_lin, _ = resample_sparse(ts, ys, grid, method="linear", part_starts=starts)
    y_spl, _ = resample_sparse(ts, ys, grid, method="spline", part_starts=starts)
    true = np.asarray(truth(grid))
    err = lambda y: float(np.sqrt(np.mean((y - true) ** 2)))
    assert isinstance(model, PiecewiseFirstOrder)
    # Away from the part starts the law is right: error well below the 0.1 K noise
    # (20 samples per part average it); right after a start it extrapolates back to T0
    # over up to 90 s of a 150 s transient, which dominates the overall figure.
    settled = grid % 1800 > 300
    rms_settled = float(np.sqrt(np.mean((y_exp - true)[settled] ** 2)))
    assert rms_settled < 0.05
    assert err(y_exp) < 0.3
    # linear / spline hold the previous part's end value until the first sample
    assert err(y_exp) < 0.1 * err(y_lin) and err(y_exp) < 0.1 * err(y_spl)
    # linear resampling reproduces np.interp within each part
    mid = (grid >= 1800) & (grid < 3600)
    inpart = (ts >= 1800) & (ts < 3600)
    np.testing.assert_allclose(y_lin[mid], np.interp(grid[mid], ts[inpart], ys[inpart]))


def test_outliers_detected_and_corrected():
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 3600.0, 90.0)
    truth = FirstOrder(20.0, 30.0, 400.0)
    y = np.asarray(truth(t)) + 0.1 * rng.normal(size=t.size)
    bad = np.zeros(t.size, bool)
    bad[[5, 17, 30]] = True
    y_bad = y.copy()
    y_bad[bad] += np.array([4.0, -3.0, 5.0])
    found = detect_outliers(t, y_bad)
    np.testing.assert_array_equal(found, bad)
    fixed = correct_outliers(t, y_bad, found)
    np.testing.assert_allclose(fixed[bad], np.asarray(truth(t[bad])), atol=0.15)
    assert np.all(fixed[~bad] == y_bad[~bad])


def test_bad_input_errors_and_warnings():
    t = np.arange(0.0, 900.0, 90.0)
    y = 20 + 10 * (1 - np.exp(-t / 200.0))
    with pytest.raises(ValueError, match="not strictly increasing"):
        jaxvs.fit_first_order(t[::-1], y)
    y_nan = y.copy()
    y_nan[3] = np.nan
    with pytest.raises(ValueError, match="missing"):
        jaxvs.fit_first_order(t, y_nan)
    with pytest.raises(ValueError, match="too few"):
        jaxvs.fit_first_order(t[:3], y[:3])
    with pytest.raises(ValueError, match="same length"):
        jaxvs.fit_first_order(t, y[:-1])
    # a part far shorter than its time constant: k and T1 trade off
    tt = np.arange(0.0, 300.0, 30.0)
    yy = 20 + 30 * (1 - np.exp(-tt / 3000.0)) + 0.01 * np.random.default_rng(0).normal(size=tt.size)
    with pytest.warns(ThermalFitWarning, match="too short for its time constant"):
        jaxvs.fit_first_order(tt, yy)
    with pytest.raises(ValueError, match="at least 4 samples"):
        fit_piecewise_first_order(t, y, [0.0, 700.0])
    with pytest.raises(ValueError, match="method"):
        resample_sparse(t, y, t, method="cubic")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jaxvs.fit_first_order(t, y)  # a well-posed part warns nothing
