"""Vectorised calibration: families over positions (independent, shared, smooth) and
multi-start."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxvs
from jaxvs.calibration import RESULTS, EquationError, FrequencyError, calibrate_family, multistart


class FirstOrder(eqx.Module):
    T0: jax.Array
    k: jax.Array
    T1: jax.Array

    def __call__(self, t):
        return self.T0 + self.k * (1 - jnp.exp(-t / self.T1))


CURVE = EquationError(lambda m, d: m(d["t"]) - d["y"])
T = np.linspace(0.0, 10.0, 50)
N_POS = 4


def family_data(seed=0, shared_T0=False):
    rng = np.random.default_rng(seed)
    T0 = np.full(N_POS, 20.0) if shared_T0 else np.linspace(18.0, 22.0, N_POS)
    k, T1 = np.linspace(3.0, 6.0, N_POS), np.linspace(1.0, 3.0, N_POS)
    y = T0[:, None] + k[:, None] * (1 - np.exp(-T / T1[:, None]))
    y = y + 0.05 * rng.normal(size=y.shape)
    return [{"t": T, "y": y[i]} for i in range(N_POS)], (T0, k, T1)


def test_independent_family_equals_loop():
    data, _ = family_data()
    guess = FirstOrder(jnp.full(N_POS, 15.0), jnp.full(N_POS, 1.0), jnp.full(N_POS, 1.5))
    fam = calibrate_family(guess, data, CURVE)
    assert fam.values.shape == (N_POS, 3)
    assert bool(jnp.all(fam.result == RESULTS.successful))
    for i in range(N_POS):
        member = jax.tree_util.tree_map(lambda x: x[i], guess)
        one = jaxvs.calibrate(member, data[i], CURVE)
        # same arithmetic, batched or not: equal to rounding (LM's iterates may differ in
        # the last bits under vmap, well below the 1e-8 solver tolerance)
        np.testing.assert_allclose(fam.values[i], one.values, rtol=1e-8)
        np.testing.assert_allclose(fam.std_errors[i], one.std_errors, rtol=1e-6)
    # the same family as one batched data pytree
    stacked = {"t": np.broadcast_to(T, (N_POS, T.size)), "y": np.stack([d["y"] for d in data])}
    fam2 = calibrate_family(guess, stacked, CURVE)
    np.testing.assert_allclose(fam2.values, fam.values, rtol=1e-12)


class SharedT0(eqx.Module):
    """Hand-written joint model: one T0, per-position k and T1 (the oracle)."""

    T0: jax.Array
    k: jax.Array
    T1: jax.Array

    def __call__(self, t):
        return self.T0 + self.k[:, None] * (1 - jnp.exp(-t[None, :] / self.T1[:, None]))


def test_shared_parameters_equal_hand_written_joint_problem():
    data, (T0, k, T1) = family_data(seed=1, shared_T0=True)
    guess = FirstOrder(jnp.asarray(15.0), jnp.full(N_POS, 1.0), jnp.full(N_POS, 1.5))
    fam = calibrate_family(guess, data, CURVE, shared=lambda m: m.T0)
    assert fam.model.T0.shape == () and fam.model.k.shape == (N_POS,)
    assert fam.names[:3] == ("T0", "k[0]", "k[1]")
    # oracle: the same joint least-squares problem written by hand
    Y = np.stack([d["y"] for d in data])
    hand = jaxvs.calibrate(
        SharedT0(jnp.asarray(15.0), jnp.full(N_POS, 1.0), jnp.full(N_POS, 1.5)),
        {"t": T, "y": Y},
        EquationError(lambda m, d: m(d["t"]) - d["y"]),
    )
    np.testing.assert_allclose(fam.values, hand.values, rtol=1e-8)  # same problem
    np.testing.assert_allclose(fam.covariance, hand.covariance, rtol=1e-6)
    truth = np.r_[T0[0], k, T1]
    assert np.all(np.abs(np.asarray(fam.values) - truth) < 4 * np.asarray(fam.std_errors))


def test_smooth_family_law_in_position():
    """ω_n(y) = ω0 + ω1 y per mode, calibrated on a batched FRFData over 6 positions."""

    def law(p, y):
        return jaxvs.ModalModel(p["w"][0] + p["w"][1] * y, p["zeta"], p["r"])

    true_p = {
        "w": jnp.array([[120.0, 400.0], [30.0, -60.0]]),
        "zeta": jnp.array([0.03, 0.05]),
        "r": jnp.array([2e4, -1e5]),
    }
    pos = jnp.linspace(0.0, 1.0, 6)
    f = np.linspace(5.0, 90.0, 160)
    H = jaxvs.frequency_response(jaxvs.SmoothFamily(law, true_p).at(pos), 2 * np.pi * f)
    data = jaxvs.data.FRFData(f, H)  # a family FRF: H of shape (6, freq)
    guess_p = {
        "w": jnp.array([[115.0, 410.0], [25.0, -50.0]]),
        "zeta": jnp.array([0.04, 0.04]),
        "r": jnp.array([1.8e4, -0.9e5]),
    }
    out = calibrate_family(jaxvs.SmoothFamily(law, guess_p), data, FrequencyError(), positions=pos)
    # noiseless: the law's coefficients are recovered to solver tolerance
    np.testing.assert_allclose(out.model.params["w"], true_p["w"], rtol=1e-7)
    np.testing.assert_allclose(out.model.params["zeta"], true_p["zeta"], rtol=1e-6)
    np.testing.assert_allclose(out.model.params["r"], true_p["r"], rtol=1e-6)
    with pytest.raises(ValueError, match="6 experiments"):
        calibrate_family(
            jaxvs.SmoothFamily(law, guess_p), data, FrequencyError(), positions=pos[:5]
        )


class Sine(eqx.Module):
    f: jax.Array
    a: jax.Array

    def __call__(self, t):
        return self.a * jnp.sin(self.f * t)


def test_multistart_finds_global_optimum():
    """A sinusoid's frequency: the cost has a local minimum every ~π/t_max rad/s."""
    t = np.linspace(0.0, 10.0, 300)
    data = {"t": t, "y": 1.3 * np.sin(3.1 * t)}
    res = EquationError(lambda m, d: m(d["t"]) - d["y"])
    local = jaxvs.calibrate(Sine(jnp.asarray(1.0), jnp.asarray(1.0)), data, res)
    assert float(local.cost) > 10.0  # stuck in a local minimum far from f = 3.1
    starts = Sine(jnp.linspace(0.5, 5.5, 12), jnp.ones(12))
    ms = multistart(starts, data, res, throw=False)
    assert ms.starts.values.shape == (12, 2)
    np.testing.assert_allclose(ms.best.values, [3.1, 1.3], rtol=1e-8)  # noiseless
    assert int(ms.index) == int(
        np.argmin(np.where(ms.starts.result == RESULTS.successful, ms.starts.cost, np.inf))
    )
    # a list of guesses is the same as a batched model
    as_list = [Sine(jnp.asarray(f), jnp.asarray(1.0)) for f in np.linspace(0.5, 5.5, 12)]
    ms2 = multistart(as_list, data, res, throw=False)
    np.testing.assert_allclose(ms2.best.values, ms.best.values, rtol=1e-12)
    with pytest.raises(ValueError, match="same leading start axis"):
        multistart(Sine(jnp.linspace(0.5, 5.5, 12), jnp.ones(3)), data, res)
