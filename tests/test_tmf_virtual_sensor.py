"""The TMF virtual sensor (study 002, eq. 5 and 7): integrators and the process-force term."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as ss

import jaxvs
from jaxvs import VirtualSensor
from jaxvs.twins import MachineStructureTwin

# a TMF-like (2, 4) system with modes at 60 and 110 Hz (T(0) = 1)
W1, W2, Z = 2 * np.pi * 60.0, 2 * np.pi * 110.0, 0.03
DEN = np.polymul([1, 2 * Z * W1, W1**2], [1, 2 * Z * W2, W2**2])
NUM = np.array([0.0, 0.0, 0.0, 0.02 * W1 * W2, (W1 * W2) ** 2])
TMF = jaxvs.RationalTF(jnp.asarray(NUM), jnp.asarray(DEN))


def _input(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    b, a = ss.butter(2, 0.2)
    return ss.lfilter(b, a, rng.standard_normal(n)) * 1e-5


def _dense():
    A, B, C, D = ss.tf2ss(np.trim_zeros(NUM, "f"), DEN)
    return A, B[:, 0], C[0], D[0, 0]


def _explicit(u, dt, heun):
    """Independent oracle: forward Euler / Heun on scipy's controllable canonical form."""
    A, B, C, D = _dense()
    x = np.zeros(A.shape[0])
    y = np.empty_like(u)
    for k in range(u.size):
        y[k] = C @ x + D * u[k]
        f = A @ x + B * u[k]
        if heun:
            u1 = u[k + 1] if k + 1 < u.size else u[k]
            pred = x + dt * f
            x = x + 0.5 * dt * (f + A @ pred + B * u1)
        else:
            x = x + dt * f
    return y


@pytest.mark.parametrize("method", ["euler", "heun"])
def test_explicit_integrators_match_a_plain_loop(method):
    dt = 2e-4  # dt·|λ| = 0.14: stable explicit steps
    u = _input()
    got = np.asarray(VirtualSensor(TMF, method=method)(u, dt))
    want = _explicit(u, dt, method == "heun")
    # different realisations (modal vs companion), same recursion: rounding only
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9 * np.max(np.abs(want)))


def test_exact_matches_scipy_zoh():
    dt = 1e-3
    u = _input()
    got = np.asarray(VirtualSensor(TMF, method="zoh")(u, dt))
    A, B, C, D = _dense()
    sysd = ss.cont2discrete((A, B[:, None], C[None], np.array([[D]])), dt, method="zoh")
    _, want, _ = ss.dlsim(sysd[:4] + (dt,), u)
    np.testing.assert_allclose(got, want[:, 0], atol=1e-8 * np.max(np.abs(want)))


def test_substeps_make_heun_usable_at_the_encoder_rate():
    """At 1 kHz, one Heun step per sample is unstable for 110 Hz modes (dt·ω = 0.69);
    sub-steps with linear interpolation of the encoder signal converge to the response to
    the linearly interpolated input (reference: trapezoidal rule on a 64x finer grid)."""
    dt = 1e-3
    u = _input(4000)
    fine = 64
    t = np.arange(u.size) * dt
    t_f = np.arange((u.size - 1) * fine + 1) * dt / fine
    u_f = jnp.asarray(np.interp(t_f, t, u))
    ref = np.asarray(jaxvs.simulate(TMF, u_f, dt / fine, method="tustin"))[::fine]
    err = {}
    for n in (1, 8, 16):
        y = np.asarray(VirtualSensor(TMF, method="heun", substeps=n)(u, dt))
        err[n] = np.std(y - ref) / np.std(ref)
    assert err[1] > 1.0  # one explicit step per sample is unstable (|1 + λdt + ...| > 1)
    assert err[8] < 0.02, err
    assert err[16] < err[8] / 3, err  # second order: halving the step gives ~1/4


def test_family_and_batched_inputs():
    fam = jaxvs.RationalTF(jnp.stack([TMF.num, 2 * TMF.num]), jnp.stack([TMF.den, TMF.den]))
    u = np.stack([_input(500, 1), _input(500, 2)])
    y = np.asarray(VirtualSensor(fam, method="zoh")(u, 1e-3))
    y0 = np.asarray(VirtualSensor(TMF, method="zoh")(u[0], 1e-3))
    np.testing.assert_allclose(y[0], y0, rtol=1e-10, atol=1e-18)
    assert y.shape == (2, 500)


def test_bad_input():
    with pytest.raises(ValueError, match="both"):
        VirtualSensor(TMF, h_et=TMF)
    with pytest.raises(ValueError, match="method"):
        VirtualSensor(TMF, method="rk4")
    with pytest.raises(ValueError, match="substeps"):
        VirtualSensor(TMF, substeps=0)
    with pytest.raises(TypeError, match="linear model"):
        VirtualSensor(np.ones(3))
    vs = VirtualSensor(TMF, TMF, TMF)
    with pytest.raises(ValueError, match="force="):
        vs(np.zeros(10), 1e-3)
    with pytest.raises(ValueError, match="samples"):
        vs(np.zeros(10), 1e-3, force=np.zeros(9))
    with pytest.raises(ValueError, match="no receptances"):
        VirtualSensor(TMF)(np.zeros(10), 1e-3, force=np.zeros(10))


@pytest.mark.slow
def test_process_force_term_of_eq5_on_the_twin():
    """With a cutting force at the TCP, eq. 5 (true T, H_ET, H_TT of the twin) recovers the
    TCP motion where eq. 7 cannot: its error is < 1/3 of eq. 7's (the remainder is the
    trapezoidal discretisation of the smooth encoder signal)."""
    twin = MachineStructureTwin(
        effects={"process_force": {"amplitude": 400.0, "tooth_pass_hz": 60.0}}
    )
    y = 0.3
    dt = 2.5e-4  # a fast encoder: the discretisation error stays below the force's share
    _, truth = twin.tmf_experiment(jr.key(0), [y], duration=1.0, dt=dt, return_truth=True)
    ch = twin.chain(y)
    t = twin.tmf_model(jnp.array([y]))
    tmf = jaxvs.RationalTF(t.num[0], t.den[0])
    sse = ch.state_space(twin.tcp, 1)
    sst = ch.state_space(twin.tcp, twin.tcp)
    h_et = jaxvs.StateSpace(sse.A[0], sse.B[0], sse.C[0], sse.D[0])
    h_tt = jaxvs.StateSpace(sst.A[0], sst.B[0], sst.C[0], sst.D[0])
    x_e, x_t, f = truth["x_e_true"][0], truth["x_t_true"][0], truth["f_true"][0]
    eq7 = np.asarray(VirtualSensor(tmf, method="tustin")(x_e, dt))
    eq5 = np.asarray(VirtualSensor(tmf, h_et, h_tt, method="tustin")(x_e, dt, force=f))
    defl = np.std(x_t - x_e)
    e7, e5 = np.std(eq7 - x_t) / defl, np.std(eq5 - x_t) / defl
    assert e5 < e7 / 3, (e5, e7)
