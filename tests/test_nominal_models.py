"""The nominal models of the diagnosis as library models: the rigid axis's inverse dynamics
(`RigidInverseDynamics`) and the first-order lag (`FirstOrderLag`) against independent
oracles; the diagnosis's nominal adapters give exactly the library's numbers. Jit, vmap,
gradients and recovery run for both in tests/test_models_registry.py."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as sig

import jaxvs
from jaxvs.diagnosis._drive import RigidNominal
from jaxvs.diagnosis._thermal import StaticRegression, first_order_lag
from jaxvs.models import FirstOrderLag, RigidAxis, RigidInverseDynamics, ViscousFriction

DT = 1e-3


def _motion(n=400):
    # q = A sin(ωt) + B sin(3ωt): velocity and acceleration in closed form
    t = np.arange(n) * DT
    w = 2 * np.pi * 2.0
    v = 0.05 * w * np.cos(w * t) + 0.01 * 3 * w * np.cos(3 * w * t)
    a = -0.05 * w**2 * np.sin(w * t) - 0.01 * (3 * w) ** 2 * np.sin(3 * w * t)
    return t, v, a


def test_inverse_dynamics_is_the_closed_form():
    _, v, a = _motion()
    model = RigidInverseDynamics(12.0, 40.0, 3.0)
    u = np.asarray(model.predict(jnp.stack([v, a], axis=1), DT))
    # closed form in NumPy; 1e-12 relative: the same three products and sums
    np.testing.assert_allclose(u, 12.0 * a + 40.0 * v + 3.0, rtol=1e-12, atol=1e-12)
    assert model.parameters() == {"M": 12.0, "Fv": 40.0, "offset": 3.0}


def test_inverse_dynamics_inverts_the_forward_rigid_axis():
    # Oracle: the library's forward model `M q̈ = f − Fv q̇` (RigidAxis with viscous
    # friction) driven by the predicted force minus the offset gives back the acceleration.
    _, v, a = _motion()
    model = RigidInverseDynamics(12.0, 40.0, 3.0)
    f = model.predict(jnp.stack([v, a], axis=1), DT)
    axis = RigidAxis(12.0, ViscousFriction(40.0))
    accel = jax.vmap(lambda vk, fk: axis.acceleration(jnp.zeros(1), vk[None], fk, 0.0)[0])
    # 1e-9 m/s²: rounding of forces of ~1e3 N divided by 12 kg
    np.testing.assert_allclose(accel(jnp.asarray(v), f - 3.0), a, atol=1e-9)


def test_inverse_dynamics_refuses_a_wrong_input_shape():
    model = RigidInverseDynamics(12.0, 40.0)
    with pytest.raises(ValueError, match=r"shape \(time, 2\).*jnp.stack"):
        model.predict(jnp.zeros(10), DT)
    with pytest.raises(ValueError, match=r"must be >= 0 kg"):
        RigidInverseDynamics(-12.0, 40.0)


@pytest.mark.parametrize("y_init", [None, 18.0])
def test_lag_matches_scipy_lsim_and_first_order_hold(y_init):
    # Oracles: scipy.signal.lsim integrates τẏ + y = u exactly for u linear between
    # samples (interp=True); cont2discrete(method="foh") is the same exact discretisation.
    dt, tau = 5.0, 430.0
    t = np.arange(400) * dt
    u = 20 + 5 * np.sin(2 * np.pi * t / 1800.0) + np.where(t > 700, 8.0, 0.0)
    y = np.asarray(FirstOrderLag(tau, y_init).predict(jnp.asarray(u), dt))
    # the first sample: the state y_init one sample before, the input held at u0 over it
    start = u[0] if y_init is None else y_init
    y0 = u[0] + (start - u[0]) * np.exp(-dt / tau)
    assert y[0] == pytest.approx(y0, rel=1e-12)
    _, y_ref, _ = sig.lsim(([1.0], [tau, 1.0]), u, t, X0=[y0 * tau], interp=True)
    # 1e-9 K: both are exact discretisations; only rounding differs
    np.testing.assert_allclose(y, y_ref, atol=1e-9)
    system = tuple(np.array([[x]]) for x in (-1.0 / tau, 1.0 / tau, 1.0, 0.0))
    ad, bd, cd, dd, _ = sig.cont2discrete(system, dt, method="foh")
    # scipy's foh realisation has the state ξ_k = x_k − Γ₂ u_k: y_k = c ξ_k + d u_k
    a, b, c, d = (float(np.asarray(m).reshape(-1)[0]) for m in (ad, bd, cd, dd))
    xi = (y0 - d * u[0]) / c
    ref = [y0]
    for k in range(1, u.size):
        xi = a * xi + b * u[k - 1]
        ref.append(c * xi + d * u[k])
    np.testing.assert_allclose(y, ref, atol=1e-9)


def test_lag_is_the_identity_at_zero_time_constant_and_refuses_two_signals():
    u = jnp.asarray(np.random.default_rng(0).normal(size=50))
    assert np.array_equal(np.asarray(FirstOrderLag(0.0, 3.0).predict(u, 5.0)), np.asarray(u))
    with pytest.raises(ValueError, match=r"one signal.*jax.vmap"):
        FirstOrderLag(10.0).predict(jnp.zeros((50, 2)), 5.0)


def test_diagnosis_nominals_are_the_library_models():
    # bit for bit: the diagnosis's adapters call the library's models
    _, v, a = _motion()
    d = {"v": jnp.asarray(v), "a": jnp.asarray(a)}
    for M in (jnp.asarray(12.0), 0.0):  # calibrated, or fixed as a Python float
        nominal = RigidNominal(M, jnp.asarray(40.0), jnp.asarray(3.0))
        ref = RigidInverseDynamics(M, 40.0, 3.0).predict(jnp.stack([v, a], axis=1), DT)
        assert np.array_equal(np.asarray(nominal(d)), np.asarray(ref))
    s = jnp.asarray(20 + np.cumsum(np.random.default_rng(1).normal(size=200)))
    lag = first_order_lag(s, jnp.asarray(300.0), 5.0, jnp.asarray(19.0))
    assert np.array_equal(np.asarray(lag), np.asarray(FirstOrderLag(300.0, 19.0).predict(s, 5.0)))
    tc, vm = s, jnp.abs(s - 20) * 100
    reg = StaticRegression(jnp.array([2.0, 0.9, 1e-3]))({"T_chassis": tc, "v_m": vm})
    law = jaxvs.models.BiasFreeRegression([0.9, 1e-3], 2.0, [0.0, 0.0])
    assert np.array_equal(np.asarray(reg), np.asarray(law.predict(jnp.stack([tc, vm], 1), 5.0)))
