"""Diagnosis of the `tmf` family on the machine-structure twin (docs/guides/contracts.md).

The twin's nominal encoder-to-TCP motion is one position-independent TMF of order (2, 4);
its effects are built as structure (a tool oscillator, a delayed reference sensor, a
softening head joint), not as the library's augmentations. The diagnoses share one signal
set and record length, so they share their compilations.
"""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import jaxvs
from jaxvs.diagnosis._base import AdmissibilityContext, fft_delay
from jaxvs.diagnosis._tmf import (
    MissingMode,
    ProcessForce,
    SensorDelay,
    TMFPositionEffect,
    coherence_null_level,
    force_coherence,
    phase_delay,
)
from jaxvs.models import StableTMF
from jaxvs.twins import MachineStructureTwin

DT = 1e-3
# A 4/4 TMF with modes near 122 Hz and 214 Hz (the twin's nominal at y = 0).
TMF = jaxvs.RationalTF(
    [0.0, 0.0, 1.728e9, 1.728e13, 4.32e16], [4.05e4, 1.944e7, 9.8928e10, 1.728e13, 4.32e16]
)


def _records(effects, ys=(0.3, 0.3, 0.3), key=3):
    """Three 4 s records; without `f` (no process force measured)."""
    recs = MachineStructureTwin(effects=effects).tmf_experiment(jr.key(key), ys=ys, duration=4.0)
    return [r.select(["x_e", "x_t", "y"]) for r in recs]


@pytest.fixture(scope="module")
def u():
    return jnp.asarray(np.random.default_rng(0).normal(size=2000))


def test_stable_tmf_matches_jaxvs_simulate(u):
    # Oracle: jaxvs.simulate (zoh) of the same rational TMF; rounding only.
    model = StableTMF.from_rational(TMF, 1000.0, DT)
    ref = np.asarray(jaxvs.simulate(TMF, u, DT, method="zoh"))
    np.testing.assert_allclose(np.asarray(model({"x_e": u})), ref, atol=1e-11 * np.abs(ref).max())
    # an odd order (one real pole) too
    tf3 = jaxvs.RationalTF([1.0, 2.0, 3.0, 4.0], [1.0, 30.0, 2e4, 1e5])
    m3 = StableTMF.from_rational(tf3, 100.0, DT)
    ref3 = np.asarray(jaxvs.simulate(tf3, u, DT))
    np.testing.assert_allclose(np.asarray(m3({"x_e": u})), ref3, atol=1e-11 * np.abs(ref3).max())
    params = model.parameters()
    assert params["f_1_hz"] == pytest.approx(122.1, rel=1e-3)
    assert params["static_gain"] == pytest.approx(1.0, rel=1e-12)


def test_missing_mode_and_position_dependence_match_rational_simulation(u):
    model = StableTMF.from_rational(TMF, 1000.0, DT)
    w = 2 * np.pi * 200.0
    mode = MissingMode(jnp.array([0.3, -0.2]), jnp.asarray(w), jnp.asarray(0.03), DT)
    ref = jaxvs.simulate(jaxvs.RationalTF([-0.2 * w, 0.3 * w * w], [1, 0.06 * w, w * w]), u, DT)
    np.testing.assert_allclose(
        np.asarray(mode.contribution({"x_e": u}, model)), np.asarray(ref), atol=1e-11
    )
    # moved parameters: every flat parameter θ + x Δθ + x² Δ²θ (numerator B, log ω,
    # log ζ); oracle: jaxvs.simulate of the TMF rebuilt in NumPy from the moved modes
    lin = [0.0, 0.0, 0.01, -0.02, 0.03, 0.05, -0.1, 0.2, -0.3]
    curv = [0.0, 0.001, 0.0, 0.002, -0.001, 0.01, 0.02, -0.05, 0.1]
    size = jnp.array(lin + curv)
    eff = TMFPositionEffect(size, 0.2, 0.1)
    d = {"x_e": u, "pos_y": jnp.full(u.shape, 0.4)}  # x = 2
    got = np.asarray(model(d) + eff.contribution(d, model))
    s = np.asarray(size)
    w = np.exp(np.asarray(model.log_omega) + 2 * s[5:7] + 4 * s[14:16])
    z = np.exp(np.asarray(model.log_zeta) + 2 * s[7:9] + 4 * s[16:18])
    den = np.polymul([1.0, 2 * z[0] * w[0], w[0] ** 2], [1.0, 2 * z[1] * w[1], w[1] ** 2])
    powers = 1000.0 ** np.arange(5)
    num = (np.asarray(model.num) + 2 * s[:5] + 4 * s[9:14]) * powers
    ref = np.asarray(jaxvs.simulate(jaxvs.RationalTF(num, den * powers), u, DT, method="zoh"))
    # exact discretisation of the same TMF: rounding of the modal form only
    np.testing.assert_allclose(got, ref, atol=1e-9 * np.abs(ref).max())
    # the moved modes are reported as relative changes from the centre to the upper end
    params = eff.parameters()
    assert params["mode_1_frequency_change"] == pytest.approx(np.expm1(0.05 + 0.01), rel=1e-12)
    assert params["mode_2_damping_change"] == pytest.approx(np.expm1(-0.3 + 0.1), rel=1e-12)
    # zero size is exactly the nominal model (the engine gates effects by data)
    zero = TMFPositionEffect(jnp.zeros(18), 0.2, 0.1).contribution(d, model)
    assert np.all(np.asarray(zero) == 0.0)
    # a fixed centre offset moves the TMF at every position, x = 0 included: oracle the
    # rational TMF with the offset's log ω (mode 1 up 10 %) and nothing else moved
    offset = jnp.zeros(9).at[5].set(np.log(1.1))
    moved = TMFPositionEffect(jnp.zeros(18), 0.2, 0.1, True, offset)
    assert moved.parameters()["centre_offset_norm"] == pytest.approx(np.log(1.1), rel=1e-12)
    at_centre = {"x_e": u, "pos_y": jnp.full(u.shape, 0.2)}
    got = np.asarray(model(at_centre) + moved.contribution(at_centre, model))
    w = np.exp(np.asarray(model.log_omega)) * np.array([1.1, 1.0])
    z = np.exp(np.asarray(model.log_zeta))
    den = np.polymul([1.0, 2 * z[0] * w[0], w[0] ** 2], [1.0, 2 * z[1] * w[1], w[1] ** 2])
    num = np.asarray(model.num) * powers
    ref = np.asarray(jaxvs.simulate(jaxvs.RationalTF(num, den * powers), u, DT, method="zoh"))
    np.testing.assert_allclose(got, ref, atol=1e-9 * np.abs(ref).max())
    # the offset is never calibrated
    assert isinstance(moved.constrained().offset, jaxvs.calibration.Fixed)


def test_fractional_delay_of_band_limited_signal():
    k = jnp.arange(400.0)
    for f in (0.1, 0.3, 0.4):  # cycles per sample
        x = jnp.sin(2 * np.pi * f * k)
        for delay in (2.4, -1.3, 3.0):
            got = np.asarray(fft_delay(x, jnp.asarray(delay)))
            exact = np.sin(2 * np.pi * f * (np.asarray(k) - delay))
            # band-limited shift of the even extension: 1e-3 up to 0.4 cycles/sample away
            # from the ends (the extension is not the sinusoid's continuation there)
            np.testing.assert_allclose(got[30:-30], exact[30:-30], atol=1e-3)
    assert np.array_equal(np.asarray(fft_delay(x, jnp.asarray(0.0))), np.asarray(x))


@pytest.mark.slow
def test_effect_free_twin_accepts_nothing_and_reports_untestable():
    rep = jaxvs.diagnose(_records({}), family="tmf")
    assert rep.verdict["effects"] == []
    by_name = {c["effect"]: c for c in rep.candidates}
    assert by_name["process_force"]["testable"] is False
    assert "f" in by_name["process_force"]["reason"]
    assert by_name["position_dependence"]["testable"] is False
    assert "position" in by_name["position_dependence"]["reason"]
    assert by_name["missing_mode"]["testable"] and by_name["sensor_delay"]["testable"]
    # an adequate model leaves the noise: the validation gap within 30 % of the floor
    assert rep.gap["validation"] == pytest.approx(rep.gap["noise_floor"], rel=0.3)


@pytest.mark.slow
@pytest.mark.parametrize(
    "effect, magnitude",
    [
        ("sensor_delay", 3.5e-3),
        ("missing_mode", {"frequency_hz": 220.0, "mass_ratio": 0.1, "damping": 0.03}),
    ],
)
def test_typical_effect_is_found_first_and_closes_the_gap(effect, magnitude):
    rep = jaxvs.diagnose(_records({effect: magnitude}), family="tmf")
    assert rep.verdict["effects"][:1] == [effect]
    found = next(c for c in rep.candidates if c["effect"] == effect)
    # a process force is modelled exactly; the position dependence to first order in
    # log ω, here extrapolated three half-ranges beyond the calibration positions (the
    # twin's stiffness is linear in y, so ω² is, not log ω): it must still close a third
    minimum = 0.5 if effect == "process_force" else 0.33
    assert found["accepted"] and found["shrink"] > minimum
    if effect == "sensor_delay":
        # about 1 ms of the 3.5 ms is absorbed by the spare numerator freedom of the 4/4
        # TMF (the twin's TMF is 2/4): the delay that is left is 1.5-4 ms
        assert 1.5e-3 < found["parameters"]["tau_s"] < 4e-3


@pytest.mark.slow
@pytest.mark.parametrize(
    "effect, magnitude",
    [
        ("position_dependence", 0.45),
        ("process_force", {"amplitude": 200.0, "tooth_pass_hz": 80.0}),
    ],
)
def test_effects_needing_positions_or_force_are_found(effect, magnitude):
    # all four signals, three positions: every candidate is testable; the validation
    # experiment (y = 0.5) lies outside the calibration positions (extrapolation)
    recs = MachineStructureTwin(effects={effect: magnitude}).tmf_experiment(
        jr.key(4), ys=(0.1, 0.3, 0.5), duration=4.0
    )
    rep = jaxvs.diagnose(recs, family="tmf")
    assert all(c["testable"] for c in rep.candidates)
    assert rep.verdict["effects"][:1] == [effect]
    found = next(c for c in rep.candidates if c["effect"] == effect)
    # a process force is modelled exactly; the position dependence to first order in
    # log ω, here extrapolated three half-ranges beyond the calibration positions (the
    # twin's stiffness is linear in y, so ω² is, not log ω): it must still close a third
    minimum = 0.5 if effect == "process_force" else 0.33
    assert found["accepted"] and found["shrink"] > minimum
    if effect == "process_force":
        # Oracle: a static force at the head, the encoder (slide) held, stretches the
        # slide-column joint and the head joint in series: 1/k_joint + 1/k_head.
        twin = MachineStructureTwin()
        expected = 1 / float(twin.k_joint) + 1 / float(twin.k_head)
        compliance = found["parameters"]["static_compliance_m_per_N"]
        assert compliance == pytest.approx(expected, rel=0.05)


def test_missing_required_signal_is_named():
    rec = jaxvs.data.Record({"x_e": np.sin(np.arange(500.0)), "y": np.zeros(500)}, dt=DT)
    with pytest.raises(ValueError, match="x_t"):
        jaxvs.diagnose([rec, rec], family="tmf")


def test_bad_order_and_varying_position_are_rejected():
    n = 500
    x = np.sin(0.3 * np.arange(n))
    rec = jaxvs.data.Record({"x_e": x, "x_t": x}, dt=DT)
    with pytest.raises(ValueError, match="order"):
        jaxvs.diagnose([rec, rec], family="tmf", order=0)
    moving = jaxvs.data.Record({"x_e": x, "x_t": x, "y": np.linspace(0, 0.5, n)}, dt=DT)
    with pytest.raises(ValueError, match="constant y"):
        jaxvs.diagnose([moving, moving], family="tmf")


def test_null_noise_is_the_noise_not_the_gap_of_an_unmodelled_force():
    """On a record with a process force the nominal TMF does not model, the null's noise
    is still the record's noise: the force's response is linear and time-invariant in the
    measured force, so the noise regression explains it (here it rings through a 40 Hz
    mode with ζ = 0.01, 0.4 s time constant, far beyond the FIR window). Oracle: scipy
    ZOH simulations of a 1-mode TMF and a compliance with the same poles (a different
    route than the modal form), noise σ."""
    import scipy.signal as ss

    from jaxvs.data import Record
    from jaxvs.diagnosis._base import GapModel, predict
    from jaxvs.diagnosis._tmf import TMFFamily

    dt, n, sigma = 1e-3, 6000, 1e-8
    w = 2 * np.pi * 40.0
    den = [1.0, 2 * 0.01 * w, w * w]
    rng = np.random.default_rng(4)
    xe = np.cumsum(rng.normal(size=n)) * 1e-7
    xe -= xe[0]
    f = ss.lfilter([0.05], [1.0, -0.95], rng.normal(size=n))
    f -= f[0]  # the structure at rest and unloaded at the start

    def zoh(num, u):
        ad, bd, cd, dd, _ = ss.cont2discrete(ss.tf2ss(num, den), dt, method="zoh")
        return ss.dlsim((ad, bd, cd, dd, dt), u)[1][:, 0]

    c = 2e-7  # [m/N]
    defl = zoh([c * w * w], f)
    xt = zoh([w * w], xe) + defl + sigma * rng.normal(size=n)
    family = TMFFamily(order=2)
    exp = family.prepare(Record({"x_e": xe, "x_t": xt, "f": f}, dt=dt), "force")
    model = GapModel(StableTMF.from_rational(jaxvs.RationalTF([w * w], den), 100.0, dt))
    clean = predict(model, exp)
    # the unmodelled force leaves a residual far above the noise ...
    assert float(np.std(exp.y - clean)) > 5 * sigma
    nulls = family.null_experiments(model, [exp], np.random.default_rng(5), 4)
    added = [float(np.std(ns[0].y - clean)) for ns in nulls]
    # ... but the null adds the noise: estimated on 6000 samples (≈ 1 %) and drawn 4 ×
    # 6000 times; 10 % allows the regression's finite window at the record's start
    assert float(np.mean(added)) == pytest.approx(sigma, rel=0.10)


def test_null_noise_is_the_noise_not_a_sensors_static_nonlinearity():
    """A tool-side sensor with a cubic calibration error, `x + c (x − x̄)³/var(x)` (a
    distortion 10 times the noise): what no linear map of `x_e` explains is the noise
    plus the distortion, but the noise regression's Volterra columns (squares and cubes
    of the linear response) take the distortion, so the null adds the noise only and the
    distortion stays in the gap. Oracle: a scipy ZOH simulation of a 1-mode TMF, noise σ;
    the same estimate on the linear sensor."""
    import scipy.signal as ss

    from jaxvs.data import Record
    from jaxvs.diagnosis._base import GapModel
    from jaxvs.diagnosis._tmf import TMFFamily, record_noise

    dt, n = 1e-3, 6000
    w = 2 * np.pi * 40.0
    den = [1.0, 2 * 0.05 * w, w * w]
    rng = np.random.default_rng(6)
    xe = np.cumsum(rng.normal(size=n)) * 1e-7
    xe -= xe[0]
    ad, bd, cd, dd, _ = ss.cont2discrete(ss.tf2ss([w * w], den), dt, method="zoh")
    lin = ss.dlsim((ad, bd, cd, dd, dt), xe)[1][:, 0]
    sigma = 0.002 * float(np.std(lin))
    d = lin - lin.mean()
    family = TMFFamily(order=2)
    model = GapModel(StableTMF.from_rational(jaxvs.RationalTF([w * w], den), 100.0, dt))
    found = []
    for c in (0.0, 0.02):
        xt = lin + c * d**3 / np.var(d) + sigma * rng.normal(size=n)
        exp = family.prepare(Record({"x_e": xe, "x_t": xt}, dt=dt), "sensor")
        found.append(np.sqrt(record_noise(exp, [model.nominal], 150)[0]))
        if c > 0:  # the distortion is far above the noise
            assert np.std(c * d**3 / np.var(d)) > 10 * sigma
    assert found[0] == pytest.approx(sigma, rel=0.15)
    assert found[1] == pytest.approx(sigma, rel=0.15)


def _multisine(t, rng, f_max, count=400):
    """A band-limited signal with a closed form at any time `t` [samples]: `count`
    sinusoids of random frequencies below `f_max` [cycles/sample] and phases."""
    f = rng.uniform(0.002, f_max, count)
    ph = rng.uniform(0, 2 * np.pi, count)
    return np.sin(2 * np.pi * f[None, :] * t[:, None] + ph[None, :]).sum(axis=1)


def test_phase_delay_is_the_slope_of_the_cross_spectrum_phase():
    # Oracle: the closed form. v is the multisine evaluated 2.3 samples later in its own
    # time (a pure sub-sample delay, no interpolation), plus 10 % noise; the phase of the
    # cross spectrum is −ωτ, so the weighted slope returns τ
    rng = np.random.default_rng(1)
    dt, tau, n = 1e-3, 2.3e-3, 8192
    k = np.arange(n, dtype=float)
    u = [_multisine(k, np.random.default_rng(2), 0.4)]
    v = [_multisine(k - tau / dt, np.random.default_rng(2), 0.4)]
    v[0] = v[0] + 0.1 * np.std(v[0]) * rng.standard_normal(n)
    got, se, chi2 = phase_delay(u, v, dt)
    # Welch's window cuts u and v at the same instants, a 2.3/256 misalignment: its bias
    # on the phase is below 0.5 % of τ; the standard error is far below that
    assert got == pytest.approx(tau, rel=5e-3)
    assert 0 < se < 1e-3 * tau
    # a pure delay: the phase is linear within its confidence, χ²/dof of order one (the
    # χ² of ~115 frequencies exceeds 1.5 per degree of freedom with p < 1e-4)
    assert chi2 < 1.5
    # the other way round it leads: the sign says which signal is late
    assert phase_delay(v, u, dt)[0] == pytest.approx(-tau, rel=5e-3)
    # a phase that is not linear (a lightly damped mode's phase turn at 100 Hz): χ²/dof
    # far above one. Oracle for the filter: scipy's bilinear discretisation
    import scipy.signal as ss

    w = 2 * np.pi * 100.0
    b, a = ss.bilinear([w * w], [1.0, 0.1 * w, w * w], fs=1 / dt)
    mode = [ss.lfilter(b, a, u[0]) + 0.01 * np.std(u[0]) * rng.standard_normal(n)]
    assert phase_delay(u, mode, dt)[2] > 100.0


def test_force_coherence_matches_scipy_and_its_null_level_holds():
    import scipy.signal as ss

    rng = np.random.default_rng(5)
    n, dt = 4096, 1e-3
    f = rng.standard_normal(n)
    r = ss.lfilter([0.2], [1.0, -0.8], f) + rng.standard_normal(n)
    coh, level = force_coherence([r], [f], dt)
    # Oracle: scipy.signal.coherence of the same pair (same Welch settings), its largest
    # value below 0.45 of the sampling rate; rounding only
    fr, c = ss.coherence(r, f, fs=1 / dt, nperseg=256)
    assert coh == pytest.approx(float(np.max(c[(fr > 0) & (fr < 450.0)])), rel=1e-9)
    # the level: 1 − (0.05 / frequencies)^(1 / (segments − 1)), 16 segments, 115 bins
    assert level == pytest.approx(1 - (0.05 / 115) ** (1 / 15), rel=1e-12)
    assert level == coherence_null_level(16, 115)
    assert coh > level  # a residual driven by the force is coherent with it
    # Oracle for the level: Monte Carlo of independent pairs. At most 5 % of them may
    # exceed it (Bonferroni over the frequencies, and the independent segments counted
    # without Welch's overlap: conservative); 200 pairs, so 10 exceedances at most
    exceed = 0
    for _ in range(200):
        a, b = rng.standard_normal(n), rng.standard_normal(n)
        c_ab, lvl = force_coherence([a], [b], dt)
        exceed += c_ab > lvl
    assert exceed <= 10


def test_signatures_gate_sensor_delay_and_process_force():
    dt = 1e-3
    ctx = AdmissibilityContext(record_dt=dt, analysis_dt=dt, band_hz=(0.5, 500.0), duration=4.0)

    def verdict(e):
        return e.admissible(ctx)

    # a delay of 0.4 samples (an anti-alias filter's group delay) is causal and
    # admissible; a lag of 0.05 ± 0.01 ms before the fit is its signature (5 standard
    # errors)
    assert verdict(SensorDelay(jnp.asarray(0.4e-3), dt)) == (True, None)
    assert verdict(SensorDelay(jnp.asarray(0.4e-3), dt, jnp.array([5e-5, 1e-5]))) == (True, None)
    # the measured signal leads the model, or lags it within its noise: no signature
    for lag in ([-5e-5, 1e-5], [2e-5, 1e-5]):
        ok, why = verdict(SensorDelay(jnp.asarray(0.4e-3), dt, jnp.array(lag)))
        assert not ok and "does not lag" in why
    ok, why = verdict(SensorDelay(jnp.asarray(-0.4e-3), dt))
    assert not ok and "non-causal" in why
    # a process force: the residual must be coherent with f above the null level
    force = ProcessForce(jnp.ones(5), jnp.asarray(1e-8), jnp.asarray(0.0), jnp.array([0.9, 0.2]))
    assert verdict(force) == (True, None)
    quiet = ProcessForce(jnp.ones(5), jnp.asarray(1e-8), jnp.asarray(0.0), jnp.array([0.1, 0.2]))
    ok, why = verdict(quiet)
    assert not ok and "not coherent" in why
    # the signatures are reported with the parameters
    assert force.parameters()["force_coherence_null_level"] == pytest.approx(0.2)
    lagged = SensorDelay(jnp.asarray(0.4e-3), dt, jnp.array([5e-5, 1e-5]))
    assert lagged.parameters()["phase_delay_before_s"] == pytest.approx(5e-5)
