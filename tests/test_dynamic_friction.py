"""Friction laws with internal states (`jaxvs.models.DahlFriction`, `LuGreFriction`,
`DriftingFriction`) and their simulation in `OpenLoopAxis`, against closed forms and an
independent numpy integrator."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxvs.models import (
    AsymmetricFriction,
    CoulombViscousFriction,
    DahlFriction,
    DriftingFriction,
    LuGreFriction,
    RigidAxis,
)
from jaxvs.studies.benchmarks import OpenLoopAxis

V = np.array([-0.2, -0.01, 0.03, 0.15])


def test_steady_states_are_the_static_laws():
    # Dahl: Fc sign(v) + Fv v + offset (smooth sign far from 0)
    d = DahlFriction(20.0, 1e4, 150.0, -2.0)
    np.testing.assert_allclose(d(V), 20.0 * np.sign(V) + 150.0 * V - 2.0, rtol=1e-12)
    # LuGre: the Stribeck curve g(v) sign(v) + Fv v (Canudas de Wit et al. 1995, eq. 7)
    lg = LuGreFriction(20.0, 30.0, 0.02, 1e5, 300.0, 100.0)
    g = 20.0 + 10.0 * np.exp(-((V / 0.02) ** 2))
    np.testing.assert_allclose(lg(V), g * np.sign(V) + 100.0 * V, rtol=1e-12)
    # drifting: (1 + κ |F0 v| / P) F0(v) + offset
    f0 = AsymmetricFriction(20.0, 170.0, 22.0, 240.0)
    dr = DriftingFriction(f0, -0.3, 5.0, 1.5)
    p0 = np.asarray(f0(V))
    np.testing.assert_allclose(dr(V), (1 - 0.3 * np.abs(p0 * V) / 100.0) * p0 + 1.5, rtol=1e-12)


def test_bristle_state_relaxes_as_the_closed_form():
    """At constant v, ż = v − σ0|v| z / g is linear in z: z(t) = z_ss + (z0 − z_ss) e^{−t/T},
    T = g / (σ0 |v|). Check the rates against it by a fine explicit integration."""
    lg = LuGreFriction(20.0, 30.0, 0.02, 1e4, 0.0, 0.0)
    v = 0.05
    g = 20.0 + 10.0 * np.exp(-((v / 0.02) ** 2))
    T = g / (1e4 * v)
    z, h = jnp.zeros(1), T / 2000
    for _ in range(2000):
        z = z + h * lg.rates(z, v)
    z_ss = g / 1e4
    assert float(z[0]) == pytest.approx(z_ss * (1 - np.exp(-1.0)), rel=1e-3)


def _numpy_drift(u, q0, v0, M, Fc, Fv, off, kappa, tau, vs, dt=1e-3, sub=8):
    """Oracle: RK4, `sub` steps per sample, force held, state (q, v, θ)."""

    def f(x, uk):
        q, v, th = x
        F0 = Fv * v + Fc * np.tanh(v / vs)
        return np.array(
            [v, (uk - (1 + th) * F0 - off) / M, (kappa * abs(F0 * v) / 100.0 - th) / tau]
        )

    F0 = Fv * v0 + Fc * np.tanh(v0 / vs)
    x = np.array([q0, v0, kappa * abs(F0 * v0) / 100.0])
    out = np.empty((len(u), 3))
    h = dt / sub
    for k, uk in enumerate(u):
        out[k] = x
        for _ in range(sub):
            k1 = f(x, uk)
            k2 = f(x + h / 2 * k1, uk)
            k3 = f(x + h / 2 * k2, uk)
            k4 = f(x + h * k3, uk)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


def test_drifting_axis_against_numpy_oracle():
    rng = np.random.default_rng(1)
    u = np.repeat(rng.normal(size=40) * 60, 25)[:, None]
    law = CoulombViscousFriction(20.0, 200.0, velocity_scale=1e-3)
    model = OpenLoopAxis(RigidAxis(95.0, DriftingFriction(law, -0.8, 0.2, -3.0)), sample_time=1e-3)
    x0 = model._with_friction_state(jnp.array([0.1, 0.05]))
    x = np.asarray(model.simulate(u, x0))
    ref = _numpy_drift(u[:, 0], 0.1, 0.05, 95.0, 20.0, 200.0, -3.0, -0.8, 0.2, 1e-3)
    np.testing.assert_allclose(x[:, 0], ref[:, 0], atol=1e-8)
    np.testing.assert_allclose(x[:, 2], ref[:, 2], atol=1e-8)
    # zero gain: exactly the static law plus the offset
    flat = OpenLoopAxis(RigidAxis(95.0, DriftingFriction(law, 0.0, 0.2, -3.0)), sample_time=1e-3)
    static = OpenLoopAxis(
        RigidAxis(95.0, CoulombViscousFriction(20.0, 200.0, -3.0, velocity_scale=1e-3)),
        sample_time=1e-3,
    )
    y_init = np.asarray(static(u, np.full((20, 1), 0.1)))[:20]
    np.testing.assert_allclose(flat(u, y_init), static(u, y_init), atol=1e-12)
    # differentiable (forward mode, as the calibration uses it)
    g = jax.jacfwd(lambda k: model.simulate(u[:200], x0.at[2].set(k))[-1, 0])(0.0)
    assert np.isfinite(g)


def test_bad_input():
    with pytest.raises(TypeError, match="static jaxvs friction law"):
        DriftingFriction(DahlFriction(1.0, 1.0))
    with pytest.raises(ValueError, match="power_scale"):
        DriftingFriction(CoulombViscousFriction(1.0, 1.0), power_scale=0.0)
