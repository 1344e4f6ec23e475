"""The nulls carry the record's own noise, coloured or white: the drive's force noise and
no disturbance the force carries besides it; the thermal sensors' first-order
autoregressive noise.

Oracles: the closed-form variance and lag-one correlation of an AR(1) noise
(`x_k = ρ x_{k−1} + sqrt(1−ρ²) σ w_k`: variance σ², correlation ρ) and a closed loop
written here in NumPy (rigid axis, P position / PI velocity cascade at 1 kHz), independent
of the library's twins and models.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as ss

from jaxvs.data import Record
from jaxvs.diagnosis._base import GapModel, predict
from jaxvs.diagnosis._drive import _controller_fit, _null_records, force_noise
from jaxvs.diagnosis._stats import ar1_noise, difference_noise_sigma, noise_like
from jaxvs.diagnosis._thermal import StaticRegression, ThermalFamily


def _ar1(rng, n, sigma, rho):
    w = rng.standard_normal(n)
    return sigma * ss.lfilter([math.sqrt(1 - rho * rho)], [1.0, -rho], w)


def _lag1(x):
    x = x - x.mean()
    return float(np.dot(x[1:], x[:-1]) / np.dot(x, x))


@pytest.mark.parametrize("rho", [0.0, 0.9])
def test_noise_like_keeps_variance_and_correlation_of_ar1_despite_pulses(rho):
    rng = np.random.default_rng(0)
    n, sigma = 20_000, 1.0
    e = _ar1(rng, n, sigma, rho)
    # sparse disturbance: three pulses of 20 σ on 1.5 % of the samples
    for k in (3_000, 9_000, 15_000):
        e[k : k + 100] += 20.0 * sigma
    assert np.var(e) > 6 * sigma**2  # the pulses dominate the sample variance
    draws = noise_like(e, 1000.0, np.random.default_rng(1), 8)
    assert draws.shape == (8, n)
    # the median over Welch segments: a few segments with pulses move it by < 20 %
    assert np.var(draws) == pytest.approx(sigma**2, rel=0.2)
    assert np.mean([_lag1(d) for d in draws]) == pytest.approx(rho, abs=0.03)


def _closed_loop_record(rng, n=8000, dt=1e-3, sigma=1.0, rho=0.95):
    """A rigid axis `M q̈ + Fv q̇ = u` (explicit Euler at dt/10) under a P position / PI
    velocity cascade; the logger adds AR(1) noise to the force it records."""
    mass, fv = 12.0, 60.0
    kv, ti, kp = mass * 2 * math.pi * 15.0, 4.0 / (2 * math.pi * 15.0), 2 * math.pi * 3.0
    t = np.arange(n) * dt
    r = 0.05 * np.sin(2 * math.pi * 0.7 * t) + 0.02 * np.sin(2 * math.pi * 2.3 * t)
    q = np.zeros(n)
    u = np.zeros(n)
    x = v = integ = q_prev = 0.0
    for k in range(n):
        qk = round(x / 1e-7) * 1e-7
        v_est = (qk - q_prev) / dt if k else 0.0
        ev = kp * (r[k] - qk) + (r[k] - r[k - 1]) / dt * (k > 0) - v_est
        integ += ev * dt
        u[k] = kv * (ev + integ / ti)
        q[k], q_prev = qk, qk
        for _ in range(10):
            v += dt / 10 * (u[k] - fv * v) / mass
            x += dt / 10 * v
    u_meas = u + _ar1(rng, n, sigma, rho)
    return Record({"q": q, "u": u_meas, "r": r}, dt=dt), mass, fv


def test_drive_null_force_noise_is_the_records_coloured_noise():
    """The controller identified from the record leaves the force's measurement noise;
    the null records carry that noise with its variance and correlation, not only its
    white part (`σ·sqrt(1−ρ)` from the differences, 5 % of the variance at ρ = 0.95)."""
    sigma, rho = 1.0, 0.95
    rec, mass, fv = _closed_loop_record(np.random.default_rng(3), sigma=sigma, rho=rho)
    q, u, r = (np.asarray(rec[k]) for k in ("q", "u", "r"))
    _, r2, res = _controller_fit(q, u, r, rec.dt, 16)
    assert r2 > 0.95
    # the white part alone is far below the noise: what the null carried before
    assert difference_noise_sigma(res) < 0.35 * sigma
    sims = _null_records(rec, mass, fv, 0.0, np.random.default_rng(4), 4, {"cutoff_hz": 100.0})
    for sim in sims:
        qs, us, rs = (np.asarray(sim[k]) for k in ("q", "u", "r"))
        _, r2s, res_s = _controller_fit(qs, us, rs, sim.dt, 16)
        assert r2s > 0.95
        assert np.std(res_s) == pytest.approx(sigma, rel=0.15)
        assert _lag1(res_s) == pytest.approx(rho, abs=0.04)


def test_force_noise_is_the_white_part_when_the_residual_holds_pulses():
    """Trapezoid force pulses on 60 % of the record beside a white 0.2 N noise: the
    in-band residual is not Gaussian, so only the white part (successive differences) is
    measurement noise -- not the pulses' in-band power, 50 times larger."""
    rng = np.random.default_rng(5)
    n, fs = 20_000, 1000.0
    e = 0.2 * rng.standard_normal(n)
    t = np.arange(n) / fs
    for t0 in np.arange(0.5, 19.0, 1.0):
        e += 8.0 * np.clip(np.minimum(t - t0, t0 + 0.6 - t) / 0.05, 0.0, 1.0)
    draws = force_noise(e, fs, 100.0, np.random.default_rng(6), 4)
    assert np.std(draws) == pytest.approx(0.2, rel=0.1)
    assert np.mean([_lag1(d) for d in draws]) == pytest.approx(0.0, abs=0.03)


def test_force_noise_keeps_a_gaussian_coloured_noise():
    e = _ar1(np.random.default_rng(7), 20_000, 1.0, 0.95)
    draws = force_noise(e, 1000.0, 100.0, np.random.default_rng(8), 4)
    assert np.std(draws) == pytest.approx(1.0, rel=0.15)
    assert np.mean([_lag1(d) for d in draws]) == pytest.approx(0.95, abs=0.02)


def _thermal_record(rng, n, dt, sigma, rho):
    """A bearing temperature that follows the chassis (closed form: a slow first-order
    heating, `T_b = 2 + 0.9 T_ch`) with AR(1) sensor noise on both channels."""
    t = np.arange(n) * dt
    t_ch = 25.0 + 8.0 * (1.0 - np.exp(-t / 5400.0))
    t_b = 2.0 + 0.9 * t_ch
    return Record(
        {
            "T_chassis": t_ch + _ar1(rng, n, sigma, rho),
            "T_bearing": t_b + _ar1(rng, n, sigma, rho),
        },
        dt=dt,
    )


@pytest.mark.parametrize("rho", [0.0, 0.95])
def test_ar1_noise_measures_level_and_colour_beside_a_slow_temperature(rho):
    """`ar1_noise` on an AR(1) noise over a heating curve: the closed-form variance and
    correlation of the noise, not the curve's; white noise is called white."""
    rec = _thermal_record(np.random.default_rng(9), 14_400, 1.0, 0.05, rho)
    sigma, rho_hat = ar1_noise(np.asarray(rec["T_bearing"]))
    assert sigma == pytest.approx(0.05, rel=0.15)
    assert rho_hat == pytest.approx(rho, abs=0.03)
    if rho == 0.0:
        assert rho_hat == 0.0  # within the white noise's sampling spread


def test_thermal_null_carries_the_residuals_coloured_noise():
    """The thermal null draws the AR(1) noise the regression's residual shows (its
    variance and correlation): a white null of the second-difference level (0.16 σ at
    ρ = 0.95) put a coloured sensor's wander into the gap."""
    sigma, rho = 0.05, 0.95
    rec = _thermal_record(np.random.default_rng(10), 14_400, 1.0, sigma, rho)
    rec = Record(
        {"T_chassis": 25.0 + 8.0 * (1.0 - np.exp(-rec.t / 5400.0)), "T_bearing": rec["T_bearing"]},
        dt=1.0,
    )
    fam = ThermalFamily()
    exp = fam.prepare(rec, "cal")
    model = GapModel(StaticRegression(jnp.array([2.0, 0.9]), use_speed=False))
    clean = predict(model, exp)
    (null,) = zip(*fam.null_experiments(model, [exp], np.random.default_rng(11), 6))
    noise = np.stack([e.y - clean for e in null])
    assert np.std(noise) == pytest.approx(sigma, rel=0.2)
    assert np.mean([_lag1(x) for x in noise]) == pytest.approx(rho, abs=0.03)
