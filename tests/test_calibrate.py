"""`jaxvs.calibrate`: recovery of known parameters for several model types and residuals.

Oracles: the true parameters of synthetic data generated independently (numpy closed
forms, `scipy.signal.cont2discrete` + `dlsim`), and closed-form least-squares
covariances. Dynamic models (predictors, diffrax ODEs, `jaxvs.simulate`) are in
`test_calibrate_dynamics.py`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as sig

import jaxvs
from jaxvs.calibration import (
    RESULTS,
    EquationError,
    FrequencyError,
    Joint,
    SimulationError,
    positive,
    stable,
)


class FirstOrder(eqx.Module):
    """The thermal study's exponential interpolation `T0 + k (1 - exp(-t / T1))`."""

    T0: jax.Array
    k: jax.Array
    T1: jax.Array

    def __call__(self, t):
        return self.T0 + self.k * (1 - jnp.exp(-t / self.T1))


CURVE = EquationError(lambda m, d: m(d["t"]) - d["y"])
T = np.linspace(0.0, 10.0, 120)
TRUE = dict(T0=20.0, k=5.0, T1=2.0)


def first_order(T0, k, T1):
    return FirstOrder(jnp.asarray(T0), jnp.asarray(k), jnp.asarray(T1))


def test_first_order_noiseless_and_noisy():
    y_true = TRUE["T0"] + TRUE["k"] * (1 - np.exp(-T / TRUE["T1"]))
    guess = first_order(15.0, 1.0, 1.0)
    out = jaxvs.calibrate(guess, {"t": T, "y": y_true}, CURVE)
    assert out.result == RESULTS.successful
    assert out.names == ("T0", "k", "T1")
    # noiseless: only the solver's tolerance separates the estimate from the truth
    np.testing.assert_allclose(out.values, [20.0, 5.0, 2.0], rtol=1e-8)
    assert float(out.cost) < 1e-16

    rng = np.random.default_rng(0)
    sigma = 0.05
    y = y_true + sigma * rng.normal(size=T.shape)
    out = jaxvs.calibrate(guess, {"t": T, "y": y}, CURVE)
    # noisy: the truth lies within 4 standard errors (a 4σ event has probability 6e-5)
    assert np.all(
        np.abs(np.asarray(out.values) - [20.0, 5.0, 2.0]) < 4 * np.asarray(out.std_errors)
    )
    # σ̂² estimates the noise variance; its relative scatter is sqrt(2/dof) ≈ 13 %
    assert 0.6 < float(out.sigma2) / sigma**2 < 1.4
    assert out.dof == T.size - 3
    # the covariance is exactly σ̂² (JᵀJ)⁻¹ with the analytic Jacobian (closed form)
    T0, k, T1 = (float(v) for v in out.values)
    e = np.exp(-T / T1)
    J = np.stack([np.ones_like(T), 1 - e, -k * T / T1**2 * e], axis=1)
    r = T0 + k * (1 - e) - y
    cov = (r @ r / (T.size - 3)) * np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(out.covariance, cov, rtol=1e-6)  # rounding of JᵀJ inverse
    np.testing.assert_allclose(np.diag(out.correlation), 1.0, rtol=1e-12)
    half = np.asarray(out.confidence_intervals[:, 1] - out.values)
    import scipy.stats

    np.testing.assert_allclose(
        half, scipy.stats.t.ppf(0.975, T.size - 3) * np.sqrt(np.diag(cov)), rtol=1e-6
    )
    assert "T1" in out.summary()
    assert float(out.stats["compile_time"]) >= 0 and float(out.stats["run_time"]) > 0


def test_parametrised_covariance_by_delta_method():
    """With T1 = exp(raw) the delta method maps the covariance back to the physical T1.

    For a one-to-one reparametrisation the first-order covariance is invariant, so it must
    equal that of the unconstrained fit (same optimum, same σ̂²)."""
    rng = np.random.default_rng(1)
    y = TRUE["T0"] + TRUE["k"] * (1 - np.exp(-T / TRUE["T1"])) + 0.05 * rng.normal(size=T.shape)
    plain = first_order(15.0, 1.0, 1.0)
    wrapped = eqx.tree_at(lambda m: m.T1, plain, replace_fn=positive)
    a = jaxvs.calibrate(plain, {"t": T, "y": y}, CURVE)
    b = jaxvs.calibrate(wrapped, {"t": T, "y": y}, CURVE)
    assert isinstance(b.model.T1, jax.Array)  # the result is physical (unwrapped)
    np.testing.assert_allclose(b.values, a.values, rtol=1e-7)  # same optimum to tolerance
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-5)


def test_modal_model_frequency_error():
    w_true = jnp.array([2 * np.pi * 30.0, 2 * np.pi * 95.0])
    truth = jaxvs.ModalModel(w_true, jnp.array([0.02, 0.05]), jnp.array([3e4, -1e5]))
    omega = 2 * np.pi * np.linspace(5.0, 150.0, 400)
    H = np.asarray(jaxvs.frequency_response(truth, omega))
    guess = jaxvs.ModalModel(
        w_true * jnp.array([1.03, 0.97]), jnp.array([0.03, 0.04]), jnp.array([2e4, -8e4])
    )
    guess = stable(guess)
    free = lambda m: (m.omega_n, m.zeta, m.residues)  # noqa: E731
    out = jaxvs.calibrate(guess, {"omega": omega, "H": H}, FrequencyError(), free=free)
    np.testing.assert_allclose(out.model.omega_n, w_true, rtol=1e-9)  # noiseless
    np.testing.assert_allclose(out.model.zeta, [0.02, 0.05], rtol=1e-7)
    np.testing.assert_allclose(out.model.residues, [3e4, -1e5], rtol=1e-7)

    rng = np.random.default_rng(2)
    noise = 0.01 * np.median(np.abs(H))
    Hn = H + noise * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape))
    out = jaxvs.calibrate(guess, {"omega": omega, "H": Hn}, FrequencyError(), free=free)
    z = (np.asarray(out.values) - np.r_[w_true, 0.02, 0.05, 3e4, -1e5]) / np.asarray(out.std_errors)
    assert np.all(np.abs(z) < 4)  # the truth lies within 4 standard errors
    # complex data of independent real/imag noise σ: σ̂² estimates σ² (±15 % at dof ≈ 800)
    assert 0.85 < float(out.sigma2) / noise**2 < 1.15


def test_frequency_error_weightings_and_frfdata():
    truth = jaxvs.ModalModel(jnp.array([200.0]), jnp.array([0.05]), jnp.array([4e4]))
    f = np.linspace(5.0, 80.0, 150)
    H = np.asarray(jaxvs.frequency_response(truth, 2 * np.pi * f))
    coh = np.clip(0.5 + 0.5 * np.abs(H) / np.abs(H).max(), 0, 0.999)
    data = jaxvs.data.FRFData(f, H, coherence=coh)
    guess = stable(jaxvs.ModalModel(jnp.array([190.0]), jnp.array([0.07]), jnp.array([3e4])))
    free = lambda m: (m.omega_n, m.zeta, m.residues)  # noqa: E731
    for weighting in (None, "relative", "coherence"):
        out = jaxvs.calibrate(guess, data, FrequencyError(weighting=weighting), free=free)
        # noiseless data: every weighting has the truth as its exact minimiser
        np.testing.assert_allclose(out.values, [200.0, 0.05, 4e4], rtol=1e-7)
    # the weights are what the docstring says: w = sqrt(γ²/(1-γ²)) / |H|
    prep = FrequencyError(weighting="coherence").prepare(data)
    np.testing.assert_allclose(prep["w"], np.sqrt(coh / (1 - coh)) / np.abs(H), rtol=1e-12)


class Oscillator(jaxvs.models.AbstractModel):
    """Mass-spring-damper `m q'' + c q' + k q = u`: exact ZOH simulation and FRF."""

    m: jax.Array
    c: jax.Array
    k: jax.Array

    def matrices(self):
        A = jnp.array([[0.0, 1.0], [-self.k / self.m, -self.c / self.m]])
        B = jnp.array([0.0, 1.0 / self.m])
        return A, B

    def predict(self, u, dt):
        # closed-form exp(A dt) of an underdamped oscillator: e^{σt}[cos(ω_d t) I +
        # sin(ω_d t)/ω_d (A - σI)], σ = -c/2m, ω_d² = k/m - σ²; ZOH input matrix
        # Γ = A⁻¹ (Φ - I) B (A is invertible for k > 0).
        A, B = self.matrices()
        sigma = -self.c / (2 * self.m)
        wd = jnp.sqrt(self.k / self.m - sigma**2)
        eye = jnp.eye(2)
        phi = jnp.exp(sigma * dt) * (
            jnp.cos(wd * dt) * eye + jnp.sin(wd * dt) / wd * (A - sigma * eye)
        )
        gamma = jnp.linalg.solve(A, (phi - eye) @ B)

        def step(x, uk):
            return phi @ x + gamma * uk, x[0]

        return jax.lax.scan(step, jnp.zeros(2), u)[1]

    def frequency_response(self, omega):
        return 1.0 / (self.k - self.m * omega**2 + 1j * self.c * omega)


OSC = dict(m=2.0, c=3.0, k=800.0)
# a user model that is not a jaxvs linear model gives its frequency response through fn
OSC_FRF = FrequencyError(lambda m, d: m.frequency_response(d["omega"]))
DT = 2e-3


def oscillator(m, c, k):
    return Oscillator(jnp.asarray(m), jnp.asarray(c), jnp.asarray(k))


def scipy_response(u):
    """Independent oracle: scipy's ZOH discretisation and dlsim."""
    A = np.array([[0.0, 1.0], [-OSC["k"] / OSC["m"], -OSC["c"] / OSC["m"]]])
    B = np.array([[0.0], [1.0 / OSC["m"]]])
    d = sig.cont2discrete((A, B, np.array([[1.0, 0.0]]), np.zeros((1, 1))), DT, method="zoh")
    return sig.dlsim(d[:4] + (DT,), u)[1][:, 0]


def test_two_time_experiments_share_parameters():
    rng = np.random.default_rng(3)
    u1 = np.repeat(rng.choice([-1.0, 1.0], size=60), 10)  # PRBS-like, 600 samples
    u2 = np.sin(2 * np.pi * 3.0 * DT * np.arange(600)) * 2.0
    sigma = 1e-5
    y1 = scipy_response(u1) + sigma * rng.normal(size=600)
    y2 = scipy_response(u2) + sigma * rng.normal(size=600)
    guess = oscillator(1.5, 2.0, 700.0)
    data = [{"u": u1, "y": y1, "dt": DT}, {"u": u2, "y": y2, "dt": DT}]
    both = jaxvs.calibrate(guess, data, SimulationError())
    one = jaxvs.calibrate(guess, data[0], SimulationError())
    truth = np.array([OSC["m"], OSC["c"], OSC["k"]])
    assert np.all(np.abs(np.asarray(both.values) - truth) < 4 * np.asarray(both.std_errors))
    # a second experiment adds information: no standard error grows (up to σ̂² scatter)
    assert np.all(np.asarray(both.std_errors) < 1.05 * np.asarray(one.std_errors))
    assert both.residual.shape == (1200,)


def test_joint_time_and_frequency():
    """The same parameters from a step response and a measured FRF, each block weighted
    by one over its noise level so that the stacked residual is homoscedastic."""
    rng = np.random.default_rng(4)
    u = np.ones(400)
    sig_t, sig_f = 2e-5, 5e-6
    y = scipy_response(u) + sig_t * rng.normal(size=400)
    omega = np.linspace(5.0, 40.0, 120)
    H = 1.0 / (OSC["k"] - OSC["m"] * omega**2 + 1j * OSC["c"] * omega)
    H = H + sig_f * (rng.normal(size=120) + 1j * rng.normal(size=120))
    guess = oscillator(1.5, 2.0, 700.0)
    with pytest.warns(jaxvs.calibration.ExcitationWarning, match="constant"):
        out = jaxvs.calibrate(
            guess,
            [{"u": u, "y": y, "dt": DT}, {"omega": omega, "H": H}],
            [SimulationError(), OSC_FRF],
            weights=[1 / sig_t, 1 / sig_f],
        )
    truth = np.array([OSC["m"], OSC["c"], OSC["k"]])
    assert np.all(np.abs(np.asarray(out.values) - truth) < 4 * np.asarray(out.std_errors))
    # weighted by 1/σ, the residual variance is ≈ 1 (±15 % at dof ≈ 640)
    assert 0.85 < float(out.sigma2) < 1.15
    # the same problem spelled with Joint
    joint = Joint([SimulationError(), OSC_FRF], weights=[1 / sig_t, 1 / sig_f])
    with pytest.warns(jaxvs.calibration.ExcitationWarning):
        out2 = jaxvs.calibrate(guess, [{"u": u, "y": y, "dt": DT}, {"omega": omega, "H": H}], joint)
    np.testing.assert_allclose(out2.values, out.values, rtol=1e-10)


class Gain(eqx.Module):
    g: jax.Array


def test_composite_model_shares_parameters():
    """A dict of modules: the plant's FRF is measured directly and through a sensor of
    unknown gain; one joint problem calibrates both (the plant's parameters are shared)."""
    omega = np.linspace(5.0, 40.0, 80)
    plant = 1.0 / (OSC["k"] - OSC["m"] * omega**2 + 1j * OSC["c"] * omega)
    model = {"plant": oscillator(1.5, 2.0, 700.0), "sensor": Gain(jnp.asarray(1.0))}
    direct = FrequencyError(lambda m, d: m["plant"].frequency_response(d["omega"]))
    sensed = FrequencyError(lambda m, d: m["sensor"].g * m["plant"].frequency_response(d["omega"]))
    data = [{"omega": omega, "H": plant}, {"omega": omega, "H": 2.5 * plant}]
    out = jaxvs.calibrate(model, data, [direct, sensed])
    assert out.names == ("['plant'].m", "['plant'].c", "['plant'].k", "['sensor'].g")
    np.testing.assert_allclose(out.values, [2.0, 3.0, 800.0, 2.5], rtol=1e-8)  # noiseless


def test_residual_building_blocks():
    """Records as data, the initial-transient skip, and Joint's 'size' weighting."""
    rng = np.random.default_rng(8)
    rec = jaxvs.data.Record({"force": rng.normal(size=50), "q": rng.normal(size=50)}, dt=0.01)
    prep = SimulationError(inputs="force", outputs="q").prepare(rec)
    assert prep["dt"] == 0.01
    np.testing.assert_array_equal(prep["u"], rec["force"])
    model = oscillator(**OSC)
    full = SimulationError(inputs="force", outputs="q")(model, prep)
    skipped = SimulationError(inputs="force", outputs="q", skip=10)(model, prep)
    np.testing.assert_array_equal(skipped, full[10:])
    curve = first_order(20.0, 5.0, 2.0)
    d1, d2 = {"t": T[:30], "y": np.zeros(30)}, {"t": T, "y": np.zeros(T.size)}
    r = Joint([CURVE, CURVE], weights="size")(curve, (d1, d2))
    np.testing.assert_allclose(r[:30], CURVE(curve, d1) / np.sqrt(30), rtol=1e-15)
    np.testing.assert_allclose(r[30:], CURVE(curve, d2) / np.sqrt(T.size), rtol=1e-15)
