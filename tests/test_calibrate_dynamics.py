"""`jaxvs.calibrate` on dynamic models: one-step predictors, a nonlinear diffrax ODE, and
linear models simulated by `jaxvs.simulate`.

Oracles: data generated independently by `scipy.signal` (`cont2discrete`, `lfilter`,
`dlsim`), `scipy.integrate.solve_ivp` and a numpy recursion, with known parameters.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.signal as sig

import jaxvs
from jaxvs.calibration import PredictionError, SimulationError, stable


def test_prediction_error_linear_model():
    """The ARX one-step predictor of the ZOH-discretised model recovers a RationalTF
    exactly from noiseless data (equation error is exact without noise)."""
    num, den = [2.0, 50.0], [1.0, 4.0, 400.0]
    rng = np.random.default_rng(5)
    u = rng.normal(size=500)
    bd, ad, _ = sig.cont2discrete((num, den), 0.01, method="zoh")
    y = sig.lfilter(bd[0], ad, u)
    guess = jaxvs.RationalTF(jnp.array([1.0, 40.0]), jnp.array([1.0, 5.0, 300.0]))
    # den as second-order sections with den[0] = 1 fixed (the scale is in num)
    guess = eqx.tree_at(lambda m: m.den, guess, jaxvs.calibration.stable_denominator(guess.den))
    out = jaxvs.calibrate(guess, {"u": u, "y": y, "dt": 0.01}, PredictionError())
    # noiseless: exact up to the solver tolerance
    np.testing.assert_allclose(out.model.num, num, rtol=1e-7)
    np.testing.assert_allclose(out.model.den, den, rtol=1e-7)
    assert out.residual.shape == (500 - 2,)  # the predictor needs n = 2 past samples


class FrictionMass(jaxvs.models.AbstractModel):
    """Nonlinear axis `m v' = u - c v - Fc tanh(v / vs)`, `q' = v`, solved by diffrax."""

    m: jax.Array
    c: jax.Array
    Fc: jax.Array
    vs: float = 0.01

    def predict(self, u, dt):
        ts = dt * jnp.arange(u.shape[0])
        force = diffrax.LinearInterpolation(ts, u)

        def f(t, x, args):
            q, v = x
            return jnp.stack(
                [v, (force.evaluate(t) - self.c * v - self.Fc * jnp.tanh(v / self.vs)) / self.m]
            )

        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(f),
            diffrax.Tsit5(),
            0.0,
            ts[-1],
            dt / 4,  # fixed steps aligned with the input's knots: fast to compile
            jnp.zeros(2),
            saveat=diffrax.SaveAt(ts=ts),
            # LM builds Jacobians with jacfwd: forward-mode differentiation of the solve
            adjoint=diffrax.ForwardMode(),
            max_steps=4 * u.shape[0],
        )
        return sol.ys[:, 0]


def test_nonlinear_diffrax_ode():
    dt = 0.01
    ts = dt * np.arange(300)
    u = 3.0 * np.sin(2 * np.pi * 0.5 * ts) + 1.5 * np.sin(2 * np.pi * 1.3 * ts)
    truth = dict(m=2.0, c=1.5, Fc=0.8)

    def rhs(t, x):
        ut = np.interp(t, ts, u)
        return [x[1], (ut - truth["c"] * x[1] - truth["Fc"] * np.tanh(x[1] / 0.01)) / truth["m"]]

    ref = scipy.integrate.solve_ivp(
        rhs, (0, ts[-1]), [0.0, 0.0], t_eval=ts, rtol=1e-11, atol=1e-13, method="LSODA"
    )
    guess = FrictionMass(jnp.asarray(1.5), jnp.asarray(1.0), jnp.asarray(0.5))
    out = jaxvs.calibrate(guess, {"u": u, "y": ref.y[0], "dt": dt}, SimulationError())
    # LSODA at rtol 1e-11 vs fixed-step Tsit5 (h = 2.5 ms, 5th order): the parameters
    # agree to ~1e-7; 1e-5 leaves room for the discretisation error of other platforms
    np.testing.assert_allclose(out.values, [2.0, 1.5, 0.8], rtol=1e-5)
    assert out.names == ("m", "c", "Fc")


@pytest.mark.slow  # jaxvs.simulate's blocked recursion under jacfwd: ~30 s to compile
@pytest.mark.skipif(not hasattr(jaxvs.models, "simulate"), reason="jaxvs.simulate not built yet")
def test_simulation_error_linear_model():
    truth = jaxvs.ModalModel(
        jnp.array([40.0, 150.0]), jnp.array([0.05, 0.1]), jnp.array([1600.0, -9000.0])
    )
    rng = np.random.default_rng(6)
    u = rng.normal(size=800)
    ss = truth.to_state_space()
    d = sig.cont2discrete(
        tuple(np.asarray(x) for x in (ss.A, ss.B, ss.C, ss.D)), 0.002, method="zoh"
    )
    y = sig.dlsim(d[:4] + (0.002,), u)[1][:, 0]
    guess = stable(
        jaxvs.ModalModel(
            jnp.array([43.0, 140.0]), jnp.array([0.07, 0.08]), jnp.array([1400.0, -8000.0])
        )
    )
    out = jaxvs.calibrate(
        guess,
        {"u": u, "y": y, "dt": 0.002},
        SimulationError(),
        free=lambda m: (m.omega_n, m.zeta, m.residues),
    )
    # noiseless ZOH data, exact ZOH simulation: only the solver tolerance remains
    np.testing.assert_allclose(out.model.omega_n, [40.0, 150.0], rtol=1e-6)
    np.testing.assert_allclose(out.model.zeta, [0.05, 0.1], rtol=1e-5)
    np.testing.assert_allclose(out.model.residues, [1600.0, -9000.0], rtol=1e-5)


class FirstOrderARX(eqx.Module):
    """A discrete predictor `ŷ_k = a y_{k-1} + b u_{k-1}` (a NARX/TDNN-style model)."""

    a: jax.Array
    b: jax.Array

    def predict_one_step(self, u, y):
        return jnp.concatenate([y[:1], self.a * y[:-1] + self.b * u[:-1]])


ONE_STEP = PredictionError(lambda m, d: m.predict_one_step(d["u"], d["y"]), skip=1)


def test_prediction_error_user_predictor():
    rng = np.random.default_rng(9)
    u = rng.normal(size=300)
    y = np.zeros(300)
    for k in range(1, 300):  # independent numpy recursion
        y[k] = 0.9 * y[k - 1] + 0.5 * u[k - 1]
    guess = FirstOrderARX(jnp.asarray(0.5), jnp.asarray(1.0))
    out = jaxvs.calibrate(guess, {"u": u, "y": y, "dt": 1.0}, ONE_STEP)
    np.testing.assert_allclose(out.values, [0.9, 0.5], rtol=1e-10)  # linear in (a, b): exact
    assert out.residual.shape == (299,)
