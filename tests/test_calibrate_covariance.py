"""Covariance against Monte-Carlo scatter, and the solvers against each other."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx
import pytest

import jaxvs
from jaxvs.calibration import RESULTS, EquationError, bounded, positive


class FirstOrder(eqx.Module):
    T0: jax.Array
    k: jax.Array
    T1: jax.Array

    def __call__(self, t):
        return self.T0 + self.k * (1 - jnp.exp(-t / self.T1))


CURVE = EquationError(lambda m, d: m(d["t"]) - d["y"])
T = np.linspace(0.0, 10.0, 60)
TRUTH = np.array([20.0, 5.0, 2.0])
GUESS = FirstOrder(jnp.asarray(15.0), jnp.asarray(1.0), jnp.asarray(1.0))


def clean():
    return TRUTH[0] + TRUTH[1] * (1 - np.exp(-T / TRUTH[2]))


@pytest.mark.parametrize("parametrised", [False, True])
def test_confidence_intervals_cover_monte_carlo(parametrised):
    """1000 noisy repeats, calibrated in one vmapped call: the 95 % intervals cover the
    truth in 90-99 % of the repeats, and the predicted standard errors match the scatter.

    Binomial scatter of a 95 % coverage over 1000 repeats is 0.7 %, so the 90-99 % band
    is -7σ/+6σ; the sample standard deviation over 1000 repeats scatters by
    1/sqrt(2000) ≈ 2.2 %, hence the ±15 % band on the standard-error ratio."""
    rng = np.random.default_rng(11)
    n_rep, sigma = 1000, 0.1
    Y = clean() + sigma * rng.normal(size=(n_rep, T.size))
    guess = GUESS
    if parametrised:  # the delta method must give the same physical intervals
        guess = eqx.tree_at(lambda m: (m.k, m.T1), GUESS, (positive(1.0), bounded(1.0, 0.1, 10.0)))

    def fit(y):  # throw=True under vmap: raises if any repeat fails
        return jaxvs.calibrate(guess, {"t": T, "y": y}, CURVE)

    out = jax.jit(jax.vmap(fit))(Y)
    assert bool(jnp.all(out.result == RESULTS.successful))
    values, ci, se = (
        np.asarray(out.values),
        np.asarray(out.confidence_intervals),
        np.asarray(out.std_errors),
    )
    covered = (ci[..., 0] <= TRUTH) & (TRUTH <= ci[..., 1])
    coverage = covered.mean(axis=0)
    assert np.all((0.90 <= coverage) & (coverage <= 0.99)), coverage
    ratio = values.std(axis=0, ddof=1) / se.mean(axis=0)
    assert np.all((0.85 < ratio) & (ratio < 1.15)), ratio
    # σ̂² is unbiased for the noise variance (mean over 1000 repeats: ±0.6 % scatter)
    assert abs(float(np.mean(out.sigma2)) / sigma**2 - 1) < 0.05
    # under a caller's jit the timings are not measured
    assert np.all(np.isnan(np.asarray(out.stats["compile_time"])))


def test_solvers_reach_the_same_optimum():
    """Levenberg-Marquardt, BFGS and Adam minimise the same ½‖r‖²."""
    rng = np.random.default_rng(7)
    data = {"t": T, "y": clean() + 0.05 * rng.normal(size=T.size)}
    lm = jaxvs.calibrate(GUESS, data, CURVE)
    bfgs = jaxvs.calibrate(GUESS, data, CURVE, optx.BFGS(rtol=1e-10, atol=1e-10))
    by_name = jaxvs.calibrate(GUESS, data, CURVE, "bfgs", rtol=1e-10, atol=1e-10)
    # Adam with a constant step never meets the Cauchy termination test; it runs out its
    # budget, which is reported honestly with throw=False.
    adam = jaxvs.calibrate(GUESS, data, CURVE, optax.adam(0.02), max_steps=3000, throw=False)
    assert adam.result == RESULTS.max_steps_reached
    # an optax schedule works too (optax closures are passed through untouched)
    sched = optax.adam(optax.exponential_decay(0.02, 1000, 0.9))
    adam2 = jaxvs.calibrate(GUESS, data, CURVE, sched, max_steps=3000, throw=False)
    se = np.asarray(lm.std_errors)
    for other, tol in ((bfgs, 1e-4), (by_name, 1e-4), (adam, 0.1), (adam2, 0.1)):
        # quasi-Newton converges to the optimum to solver tolerance; Adam to within a
        # small fraction of a standard error (statistically the same estimate)
        assert np.all(np.abs(np.asarray(other.values) - np.asarray(lm.values)) < tol * se)
        assert abs(float(other.cost) / float(lm.cost) - 1) < 1e-3
    assert int(lm.num_steps) < int(bfgs.num_steps) < int(adam.num_steps)
