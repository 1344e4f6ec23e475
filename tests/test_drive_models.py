"""Drive components against closed forms: friction laws, dead zone, quantisation, current
loop, DC motor, cascaded loops (continuous and sampled), batching, gradients, bad input."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as ss
from jax.test_util import check_grads

from jaxvs.models import (
    AsymmetricFriction,
    BallScrew,
    CoulombFriction,
    CoulombViscousFriction,
    CurrentLoop,
    DCMotor,
    DriveAxis,
    FlexibleAxis,
    ForceGain,
    PositionLoop,
    RigidAxis,
    StribeckFriction,
    UnstableLoopError,
    VelocityLoop,
    ViscousFriction,
    amplification,
    dead_zone,
    quantise,
    saturation,
    smooth_sign,
    solve_ode,
)

# ----------------------------------------------------------------------------- friction


def test_friction_laws_match_their_closed_forms():
    v = jnp.array([-0.3, -0.05, 0.02, 0.4])  # all |v| >> velocity_scale = 1e-4
    f = CoulombViscousFriction(20.0, 200.0, -3.0)
    # tanh(200) = 1 to machine precision
    np.testing.assert_allclose(f(v), 200.0 * v + 20.0 * np.sign(v) - 3.0, rtol=1e-12)
    np.testing.assert_allclose(ViscousFriction(5.0)(v), 5.0 * v)
    np.testing.assert_allclose(CoulombFriction(3.0, velocity_scale=0.0)(v), 3.0 * np.sign(v))
    a = AsymmetricFriction(20.1, 166.7, 20.6, 240.4)
    # Janot et al. 2019 eq. (12)
    expect = np.where(v > 0, 166.7 * v + 20.1, 240.4 * v - 20.6)
    np.testing.assert_allclose(a(v), expect, rtol=1e-12)
    s = StribeckFriction(10.0, 15.0, 0.01, 2.0, velocity_scale=0.0)
    vv = np.array([-0.02, 0.005, 0.03])
    expect = (10 + 5 * np.exp(-((vv / 0.01) ** 2))) * np.sign(vv) + 2.0 * vv
    np.testing.assert_allclose(s(vv), expect, rtol=1e-12)


def test_smooth_sign_sharpness():
    # documented: tanh(1) ≈ 0.76 at v = velocity_scale, odd, 0 at 0
    assert float(smooth_sign(1e-3, 1e-3)) == pytest.approx(np.tanh(1.0), rel=1e-14)
    assert float(smooth_sign(0.0, 1e-3)) == 0.0
    assert float(AsymmetricFriction(1.0, 1.0, 2.0, 2.0)(0.0)) == 0.0
    with pytest.raises(ValueError, match="velocity_scale must be >= 0"):
        CoulombFriction(1.0, velocity_scale=-1.0)


def test_friction_gradients():
    v = jnp.array([-0.1, 0.002, 0.3])

    def stribeck(p):
        return StribeckFriction(p[0], p[1], p[2], p[3], velocity_scale=1e-3)(v)

    # automatic vs central-difference derivatives; eps = 1e-6 keeps the O(eps²) truncation
    # and the O(1e-16/eps) rounding far below check_grads' float64 tolerance
    check_grads(
        stribeck, (jnp.array([10.0, 14.0, 0.02, 3.0]),), order=1, modes=["fwd", "rev"], eps=1e-6
    )


def test_dead_zone_saturation_quantise():
    x = jnp.array([-3.0, -1.0, -0.5, 0.0, 0.7, 1.0, 2.5])
    np.testing.assert_allclose(dead_zone(x, 1.0), [-2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.5])
    smooth = dead_zone(x, 1.0, smoothness=1e-3)
    # softplus rounding: exact to ε log 2 at the corners, ε e^{-(|x|-b)/ε} away from them
    np.testing.assert_allclose(smooth, dead_zone(x, 1.0), atol=1e-3 * np.log(2) + 1e-12)
    np.testing.assert_allclose(saturation(x, 1.0), np.clip(np.asarray(x), -1, 1))
    # without play the dead zone is the identity, also for its derivative at 0 (which a
    # linearisation about rest uses)
    assert float(jax.grad(lambda z: dead_zone(z, 0.0))(0.0)) == 1.0
    q = quantise(jnp.array([0.12, -0.37, 0.5004]), 0.1)
    np.testing.assert_allclose(q, [0.1, -0.4, 0.5], atol=1e-15)
    # straight-through derivative: the quantiser differentiates as the identity
    assert float(jax.grad(lambda x: quantise(x, 0.1))(0.123)) == 1.0


# ----------------------------------------------------------------------------- actuators


def test_current_loop_is_a_first_order_lag():
    lag = CurrentLoop(gain=4.0, time_constant=2e-3)
    t = np.linspace(0, 0.02, 201)
    ys = solve_ode(lambda t, y, a: lag.derivative(y, 1.5, 0.0), jnp.zeros(1), t, rtol=1e-10)
    # step of 1.5: f = 4·1.5·(1 − e^{−t/τ}); tolerance from rtol 1e-10 of the solver
    np.testing.assert_allclose(ys[:, 0], 6.0 * (1 - np.exp(-t / 2e-3)), atol=1e-8)


def test_dc_motor_step_matches_its_transfer_function():
    motor = DCMotor(1.2, 3e-3, 0.25, 0.25, 2e-3, 1e-3)
    t = np.linspace(0, 0.5, 501)  # 13 mechanical time constants J R / (kt ke) = 38 ms
    ys = solve_ode(motor.vector_field, jnp.zeros(2), t, (24.0, 0.0), rtol=1e-10, atol=1e-12)
    tf = motor.speed_transfer_function()
    # oracle: scipy's step response of kt / ((Ls + R)(Js + b) + kt ke)
    _, w_ref = ss.step((np.trim_zeros(np.asarray(tf.num), "f"), np.asarray(tf.den)), T=t)
    np.testing.assert_allclose(ys[:, 1], 24.0 * w_ref, rtol=1e-6, atol=1e-6)
    # steady speed kt V / (R b + kt ke)
    w_inf = 0.25 * 24.0 / (1.2 * 1e-3 + 0.25**2)
    assert float(ys[-1, 1]) == pytest.approx(w_inf, rel=1e-3)


# ----------------------------------------------------------------------------- loops

M, FV, KP, KV = 10.0, 50.0, 40.0, 2000.0


def _rigid(sample_time=None, **kw):
    return DriveAxis(
        RigidAxis(M, ViscousFriction(FV)),
        PositionLoop(KP),
        VelocityLoop(KV),
        ForceGain(1.0),
        sample_time=sample_time,
        **kw,
    )


def test_continuous_cascade_step_matches_closed_form():
    """q/r = kp kv / (m s² + (kv + Fv) s + kp kv) for a rigid mass under P-P control."""
    dt = 1e-3
    t = dt * np.arange(400)
    r = np.ones_like(t)
    r[0] = 0.0  # the step happens during the first interval (linear interpolation)
    res = _rigid().simulate(r, dt, rtol=1e-10, atol=1e-12)
    sys = ss.lti([KP * KV], [M, KV + FV, KP * KV])
    _, y_ref, _ = ss.lsim(sys, r, t)  # lsim also interpolates linearly between samples
    np.testing.assert_allclose(res.position, y_ref, atol=1e-7)
    # the linearised loop has the same response (python-control-free closed form)
    w = np.array([5.0, 40.0, 200.0])
    H = np.asarray(_rigid().frequency_response(w))
    H_ref = KP * KV / (M * (1j * w) ** 2 + (KV + FV) * 1j * w + KP * KV)
    np.testing.assert_allclose(H, H_ref, rtol=1e-10)


def test_sampled_cascade_matches_exact_zoh_discretisation():
    """Oracle: the plant discretised exactly (scipy cont2discrete, ZOH) in closed loop with
    u_k = kv (kp (r_k − q_k) − (q_k − q_{k−1})/dt)."""
    dt = 1e-3
    n = 300
    r = np.r_[0.0, np.full(n - 1, 1e-3)]
    res = _rigid(sample_time=dt).simulate(r, dt)
    A = np.array([[0.0, 1.0], [0.0, -FV / M]])
    B = np.array([[0.0], [1.0 / M]])
    Ad, Bd, *_ = ss.cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), dt, method="zoh")
    x = np.zeros(2)
    q_prev = 0.0
    q = np.zeros(n)
    for k in range(n):
        q[k] = x[0]
        u = KV * (KP * (r[k] - x[0]) - (x[0] - q_prev) / dt)
        q_prev = x[0]
        x = Ad @ x + Bd[:, 0] * u
    # 4 Tsit5 steps per 1 ms sample on poles of at most ~200 1/s: error ~ (h λ)^5 ≪ 1e-9
    np.testing.assert_allclose(res.position, q, atol=1e-12, rtol=1e-9)


def test_pi_velocity_loop_rejects_a_constant_force():
    """With ki > 0 the steady position error under a constant load vanishes (integral
    action); with ki = 0 it is f / (kp kv)."""
    dt = 1e-3
    n = 3000
    f = np.full(n, -30.0)
    r = np.zeros(n)
    p_only = _rigid().simulate(r, dt, external_force=f)
    assert float(p_only.position[-1]) == pytest.approx(-30.0 / (KP * KV), rel=1e-4)
    pi = DriveAxis(RigidAxis(M, ViscousFriction(FV)), PositionLoop(KP), VelocityLoop(KV, 20.0))
    assert abs(float(pi.simulate(r, dt, external_force=f).position[-1])) < 1e-7


def test_variants_batch_with_vmap():
    dt = 1e-3
    r = jnp.asarray(np.r_[0.0, np.full(199, 1e-3)])
    masses = jnp.array([5.0, 10.0, 20.0])

    def run(m):
        ax = DriveAxis(RigidAxis(m, ViscousFriction(FV)), PositionLoop(KP), VelocityLoop(KV))
        return ax.simulate(r, dt).position

    batched = eqx.filter_jit(jax.vmap(run))(masses)
    for i, m in enumerate(np.asarray(masses)):
        sys = ss.lti([KP * KV], [m, KV + FV, KP * KV])
        _, y_ref, _ = ss.lsim(sys, np.asarray(r), dt * np.arange(200))
        np.testing.assert_allclose(batched[i], y_ref, atol=1e-7)


def test_forward_mode_derivative_matches_finite_difference():
    dt = 1e-3
    r = jnp.asarray(np.r_[0.0, np.full(99, 1e-3)])

    def q_end(m):
        ax = DriveAxis(
            RigidAxis(m, CoulombViscousFriction(2.0, FV)),
            PositionLoop(KP),
            VelocityLoop(KV, limit=50.0),
            sample_time=dt,
        )
        return ax.simulate(r, dt, check=False).position[30]

    d_ad = jax.jacfwd(q_end)(10.0)
    h = 1e-5
    d_fd = (q_end(10.0 + h) - q_end(10.0 - h)) / (2 * h)
    # central difference error O(h²) plus rounding 1e-16/h
    assert float(d_ad) == pytest.approx(float(d_fd), rel=1e-5)


def test_two_mass_backlash_transmits_nothing_inside_the_play():
    ax = FlexibleAxis(jnp.array([1.0, 2.0]), jnp.array([1e6]), jnp.array([0.0]), backlash=1e-4)
    # relative displacement inside the play: no spring force
    assert float(ax.spring_forces(jnp.array([5e-5, 0.0]), jnp.zeros(2))[0]) == 0.0
    # outside: k (Δ − b)
    f = ax.spring_forces(jnp.array([3e-4, 0.0]), jnp.zeros(2))[0]
    assert float(f) == pytest.approx(1e6 * 2e-4, rel=1e-12)


# ----------------------------------------------------------------------------- bad input


def test_unstable_controller_is_a_clear_error():
    r = np.r_[0.0, np.full(99, 1e-3)]
    bad = DriveAxis(RigidAxis(M, ViscousFriction(FV)), PositionLoop(KP), VelocityLoop(-KV))
    with pytest.raises(UnstableLoopError, match="closed loop is unstable"):
        bad.simulate(r, 1e-3)
    # a digital velocity loop too fast for its 1 ms sample rate (kv dt / m = 10 ≫ 1)
    fast = _rigid(sample_time=1e-3)
    fast = eqx.tree_at(lambda a: a.velocity_loop.kv, fast, jnp.asarray(1e5))
    with pytest.raises(UnstableLoopError, match="outside the unit circle"):
        fast.simulate(r, 1e-3)
    # under jit the eager check is skipped and the diverging simulation raises instead
    # (the state grows by orders of magnitude per sample and overflows to inf)
    long = jnp.asarray(np.r_[0.0, np.full(1499, 1e-3)])
    with pytest.raises(Exception, match="diverged"):
        jax.jit(lambda rr: fast.simulate(rr, 1e-3).position)(long)


def test_stiff_distributed_model_with_too_large_a_step():
    screw = BallScrew(1.0, 0.032, 0.01)
    mech = screw.distributed_axis(2e-3, 300.0, n_segments=40)
    ax = DriveAxis(mech, PositionLoop(30.0), VelocityLoop(5e3), sample_time=1e-3, n_substeps=2)
    with pytest.raises(ValueError, match="unstable for the Tsit5 solver"):
        ax.simulate(np.zeros(50), 1e-3)


def test_step_amplification_matches_stability_functions():
    # Euler R(z) = 1 + z, Heun R(z) = 1 + z + z²/2 (Hairer & Wanner, vol. II, IV.2)
    lam = np.array([-1000.0, -3000.0, 1000j])
    z = lam * 1e-3
    # atol: |R| = 0 exactly for Euler at z = −1, computed with rounding
    np.testing.assert_allclose(amplification(lam, 1e-3, "euler"), np.abs(1 + z), atol=1e-15)
    np.testing.assert_allclose(
        amplification(lam, 1e-3, "heun"), np.abs(1 + z + z**2 / 2), atol=1e-15
    )


def test_bad_arguments():
    with pytest.raises(TypeError, match="mechanics must be"):
        DriveAxis("axis", PositionLoop(1.0), VelocityLoop(1.0))
    with pytest.raises(ValueError, match="feedback must be"):
        DriveAxis(RigidAxis(1.0), PositionLoop(1.0), VelocityLoop(1.0), feedback="tacho")
    with pytest.raises(ValueError, match="differs from the controller"):
        _rigid(sample_time=1e-3).simulate(np.zeros(10), 2e-3)
    with pytest.raises(ValueError, match="one sample per reference"):
        _rigid().simulate(np.zeros(10), 1e-3, external_force=np.zeros(9))
    with pytest.raises(ValueError, match="2 entries"):
        FlexibleAxis(jnp.array([1.0]), jnp.array([]), jnp.array([]))
