"""The best linear approximation and its noise / nonlinear-distortion split
(`jaxvs.signal.best_linear_approximation`).

Oracle: a static cubic `y = u + a u³` under random-phase multisines. With `F` lines of
one-sided DFT amplitude `U` (`u = Σ 2U cos(2π k t/N + φ_k)`, variance `σ² = 2 F U²`), the
phase-coherent part of `u³` at an excited line `k` gives the BLA in closed form,
`G = 1 + 3a (σ² − U²)`; every other triple of lines `(f₁, f₂, f₃)` with `f₁ + f₂ + f₃ = k`
has a phase independent of `φ_k`, so the variance of the stochastic nonlinear
contribution is `σ²_Gs(k) = a² U⁴ Σ c²` summed over those triples (as multisets; `c` the
number of their orderings). The noise variance of one period's DFT line of a white noise
`σ_n` is `σ_n²/N`.
"""

import itertools
import math

import numpy as np
import pytest

from jaxvs.signal import best_linear_approximation, find_period, period_noise, settled_periods

F, N, A = 24, 256, 0.05  # lines, samples per period, cubic coefficient
U = 0.25  # one-sided amplitude of each line: σ² = 2 F U² = 3


def _multisines(rng, m, p, sigma_n):
    t = np.arange(N)
    k = np.arange(1, F + 1)
    u, y = [], []
    for _ in range(m):
        phi = rng.uniform(0, 2 * np.pi, F)
        one = (2 * U * np.cos(2 * np.pi * np.outer(t, k) / N + phi)).sum(axis=1)
        per = np.tile(one, (p, 1))
        u.append(per)
        y.append(per + A * per**3 + sigma_n * rng.standard_normal(per.shape))
    return np.array(u), np.array(y)


def _distortion_var_closed_form() -> dict[int, float]:
    """σ²_Gs(k) of `a u³` at every excited line `k` (module doc): the sum over the
    non-coherent multisets of signed lines adding up to `k`."""
    signed = [f for f in range(-F, F + 1) if f != 0]
    total = dict.fromkeys(range(1, F + 1), 0.0)
    for trip in itertools.combinations_with_replacement(signed, 3):
        k = sum(trip)
        if k not in total:
            continue
        rest = list(trip)
        if k in rest:
            rest.remove(k)
            if rest[0] == -rest[1]:
                continue  # {k, l, −l}: in phase with line k, part of the BLA
        orderings = len(set(itertools.permutations(trip)))
        total[k] += orderings**2
    return {k: A**2 * U**4 * v for k, v in total.items()}


def test_bla_of_a_static_cubic_matches_the_closed_form():
    rng = np.random.default_rng(0)
    sigma_n = 0.05
    m, p = 24, 4
    u, y = _multisines(rng, m, p, sigma_n)
    bla = best_linear_approximation(u, y)
    assert bla.lines.tolist() == list(range(1, F + 1))
    sigma2 = 2 * F * U**2
    g_true = 1 + 3 * A * (sigma2 - U**2)
    closed = _distortion_var_closed_form()
    gs_true = np.array([closed[k] for k in bla.lines])
    # the BLA: every line within 4 standard deviations of its own spread (noise and
    # distortion of M realisations), and no systematic offset over the lines
    sd = np.sqrt((gs_true + sigma_n**2 / (N * p * U**2)) / m)
    assert np.all(np.abs(bla.frf - g_true) < 4 * sd + 1e-12)
    assert abs(np.mean(bla.frf.real) - g_true) < 4 * np.mean(sd) / math.sqrt(F)
    assert np.max(np.abs(bla.frf.imag)) < 4 * np.max(sd)
    # the distortion variance: the mean over lines of an estimate from M = 24
    # realisations (relative sd about sqrt(2/M)/sqrt(F) ≈ 6 %), within 20 %
    assert np.mean(bla.frf_distortion_var) == pytest.approx(np.mean(gs_true), rel=0.2)
    # the noise of one period's DFT line: σ_n²/N, mean over lines within 10 %
    # (M (P − 1) F = 1728 complex degrees of freedom)
    assert np.mean(bla.y_noise_var[bla.lines]) == pytest.approx(sigma_n**2 / N, rel=0.1)
    # the time-domain levels: the noise in the excited band, sqrt(2 F σ_n²/N); the
    # distortion above it (a finding, not noise)
    assert bla.noise_level == pytest.approx(sigma_n * math.sqrt(2 * F / N), rel=0.1)
    dist_true = math.sqrt(2 * np.sum(gs_true * U**2))
    assert bla.distortion_level == pytest.approx(dist_true, rel=0.15)
    assert bla.distortion_level > 3 * bla.noise_level


def test_a_linear_system_has_no_distortion_and_one_realisation_shows_it_off_the_lines():
    rng = np.random.default_rng(1)
    sigma_n = 0.05
    u, y = _multisines(rng, 8, 4, sigma_n)
    y_lin = u + sigma_n * rng.standard_normal(u.shape)
    lin = best_linear_approximation(u, y_lin)
    np.testing.assert_allclose(lin.frf, 1.0, atol=5 * math.sqrt(sigma_n**2 / (N * 4 * U**2 * 8)))
    # zero up to its sampling spread: far below the cubic's level
    assert lin.distortion_level < 0.5 * lin.noise_level
    # one realisation: the cubic's power lands on the lines up to 3F that are not excited
    one = best_linear_approximation(u[0], y[0])
    assert one.realisations == 1 and np.isnan(one.frf_distortion_var).all()
    assert one.distortion_level > 3 * one.noise_level
    assert best_linear_approximation(u[0], y_lin[0]).distortion_level < one.noise_level


def test_period_and_period_noise():
    rng = np.random.default_rng(2)
    one = rng.standard_normal(200)
    x = np.tile(one, 5)
    assert find_period(x) == 200
    assert find_period(rng.standard_normal(1000)) is None
    noise = 0.1 * rng.standard_normal(x.size)
    var, rho, p = period_noise(x + noise, 200, skip=0)
    assert p == 5
    # 4 × 200 degrees of freedom: within 15 %
    assert var == pytest.approx(0.01, rel=0.15)
    assert abs(rho) < 0.1


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="at least 2 periods"):
        best_linear_approximation(np.ones((1, 16)), np.ones((1, 16)))
    with pytest.raises(ValueError, match="same"):
        best_linear_approximation(np.ones((2, 16)), np.ones((3, 16)))
    with pytest.raises(ValueError, match="constant"):
        best_linear_approximation(np.ones((2, 16)), np.ones((2, 16)))
    with pytest.raises(ValueError, match="fewer than 2 periods"):
        period_noise(np.ones(300), 200)


def test_settled_periods_skip_the_transient():
    # a decaying transient over the first two periods, then a periodic response with noise
    rng = np.random.default_rng(3)
    one = rng.standard_normal(100)
    y = np.tile(one, 8) + 0.01 * rng.standard_normal(800)
    y[:200] += 5 * np.exp(-np.arange(200) / 40.0)
    assert settled_periods(y, 100) == 2
    var, _, p = period_noise(y, 100)
    assert p == 6 and var == pytest.approx(1e-4, rel=0.2)
    # a settled record still drops its first period
    assert settled_periods(np.tile(one, 4) + 0.01 * rng.standard_normal(400), 100) == 1


def test_a_slow_signal_is_not_taken_for_a_periodic_one():
    # a point-to-point move with dwells, sampled fast: a few samples apart it is nearly
    # itself, but it never returns
    t = np.linspace(0, 10, 40000)
    r = np.clip(np.sin(2 * np.pi * 0.13 * t) * 1.7, -1, 1) + 0.3 * t
    assert find_period(r, rtol=1e-3) is None
    # a held (zero-order) copy of a periodic command is still periodic
    one = np.repeat(np.random.default_rng(4).standard_normal(50), 4)
    assert find_period(np.tile(one, 3), rtol=1e-3) == 200
