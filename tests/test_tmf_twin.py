"""Machine-structure twin: hidden effects and the `tmf` diagnosis data (`tmf_experiment`)."""

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as ss

import jaxvs
from jaxvs.calibration import SimulationError, stable, unwrap
from jaxvs.twins import TMF_TWIN_EFFECTS, MachineStructureTwin, draw_tmf_effect

NOMINAL = MachineStructureTwin(effects={})


def _dense_chain(m, k, c):
    """Independent numpy assembly of a left-grounded chain: (A, B) with forces at all masses."""
    n = len(m)
    K = np.zeros((n, n))
    C = np.zeros((n, n))
    for i in range(n):
        K[i, i] += k[i]
        C[i, i] += c[i]
        if i > 0:  # spring i joins masses i-1 and i
            K[i - 1, i - 1] += k[i]
            K[i, i - 1] -= k[i]
            K[i - 1, i] -= k[i]
            C[i - 1, i - 1] += c[i]
            C[i, i - 1] -= c[i]
            C[i - 1, i] -= c[i]
    Mi = np.diag(1.0 / np.asarray(m))
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ C]])
    B = np.vstack([np.zeros((n, n)), Mi])
    return A, B


def test_effect_names_and_draws():
    assert TMF_TWIN_EFFECTS == (
        "position_dependence",
        "missing_mode",
        "sensor_delay",
        "process_force",
    )
    assert draw_tmf_effect(jr.key(0), None) == {}
    assert draw_tmf_effect(jr.key(0), "none") == {}
    for i, label in enumerate(TMF_TWIN_EFFECTS):
        eff = draw_tmf_effect(jr.key(i), label)
        assert list(eff) == [label]
        twin = NOMINAL.with_effects(eff)
        assert list(twin.effects) == [label]  # exactly this effect is on
    with pytest.raises(ValueError, match="unknown label"):
        draw_tmf_effect(jr.key(0), "backlash")
    with pytest.raises(ValueError, match="unknown effect"):
        MachineStructureTwin(effects={"friction": 1.0})
    with pytest.raises(ValueError, match="unknown parameter"):
        MachineStructureTwin(effects={"missing_mode": {"freq": 200.0}})
    with pytest.raises(TypeError, match="mapping"):
        MachineStructureTwin(effects=["sensor_delay"])
    with pytest.raises(ValueError, match=r"\[0, 1\)"):
        MachineStructureTwin(effects={"position_dependence": 1.5})


def test_legacy_default_keeps_position_dependence_and_effects_off_remove_it():
    w = 2 * np.pi * np.linspace(5.0, 400.0, 200)
    legacy = MachineStructureTwin()
    assert float(legacy.head_softening) == 0.6 and legacy.chain(0.0).n_masses == 4
    T = np.asarray(NOMINAL.true_tmf(jnp.array([0.0, 0.6]), jnp.asarray(w)))
    np.testing.assert_allclose(T[0], T[1], rtol=1e-12)  # no y dependence when off
    T_leg = np.asarray(legacy.true_tmf(jnp.array([0.0, 0.6]), jnp.asarray(w)))
    assert np.max(np.abs(T_leg[0] - T_leg[1])) > 1.0  # resonances move with y


def test_missing_mode_adds_a_tool_oscillator():
    eff = {"missing_mode": {"frequency_hz": 200.0, "mass_ratio": 0.1, "damping": 0.03}}
    twin = NOMINAL.with_effects(eff)
    ch = twin.chain(0.3)
    assert ch.n_masses == 5 and twin.tcp == 4
    m_tool = float(ch.masses[0, 4])
    np.testing.assert_allclose(m_tool, 9.0)  # 0.1 x head mass 90 kg
    # uncoupled tool frequency sqrt(k/m) / 2π is the requested 200 Hz
    np.testing.assert_allclose(np.sqrt(float(ch.stiffnesses[0, 4]) / m_tool) / (2 * np.pi), 200.0)
    tmf = twin.tmf_model(jnp.array([0.3]))
    assert tmf.order == 6  # the nominal order 4 no longer suffices
    w = 2 * np.pi * np.linspace(5.0, 400.0, 300)
    H = np.asarray(ch.frf(jnp.asarray(w), response=4, force=0))[0]
    He = np.asarray(ch.frf(jnp.asarray(w), response=1, force=0))[0]
    got = np.asarray(jaxvs.frequency_response(tmf, jnp.asarray(w)))[0]
    np.testing.assert_allclose(got, H / He, rtol=1e-8)  # exact model vs FRF ratio, rounding


def test_perturb_varies_parameters_and_keeps_effects():
    twin = NOMINAL.with_effects({"sensor_delay": 3e-3}).perturb(jr.key(3), scale=0.1)
    ratio = np.asarray(twin.masses) / np.asarray(NOMINAL.masses)
    assert np.all(ratio != 1.0) and np.all(np.abs(np.log(ratio)) < 0.5)  # 5 sigma
    assert twin.effects == {"sensor_delay": 3e-3}
    assert twin.chain(0.1).n_masses == 4


def test_records_layout_and_no_label_leak():
    eff = draw_tmf_effect(jr.key(2), "process_force")
    twin = NOMINAL.with_effects(eff)
    recs = twin.tmf_experiment(jr.key(0), [0.1, 0.4], duration=1.0, dt=1e-3)
    assert len(recs) == 2
    for r, y in zip(recs, [0.1, 0.4]):
        assert set(r.names) == {"x_e", "x_t", "y", "f"}
        assert r.dt == pytest.approx(1e-3) and len(r) == 1000
        np.testing.assert_array_equal(r["y"], y)
        assert r.metadata["y"] == y
        text = repr(dict(r.metadata)).lower()
        assert set(r.metadata) == {"y", "source", "excitation"}
        assert not any(w in text for w in ("delay", "force", "mode", "effect", "depend"))
        assert r.units["f"] == "N" and r.units["x_t"] == "m"
    # the encoder is quantised to its resolution
    q = recs[0]["x_e"] / 1e-7
    np.testing.assert_allclose(q, np.round(q), atol=1e-6)
    # the force channel is present with the effect off, and then is sensor noise only
    off = NOMINAL.tmf_experiment(jr.key(0), [0.1], duration=1.0, force_noise=2.0)[0]["f"]
    assert abs(np.std(off) - 2.0) < 0.2 and abs(np.mean(off)) < 0.3  # 1000 samples: ±5 sigma
    on = recs[0]["f"]
    amp = eff["process_force"]["amplitude"]
    assert abs(np.mean(on) / amp - 0.6) < 0.1  # mean cutting force 0.6 A (±0.2 slow modulation)


def test_bad_arguments():
    with pytest.raises(ValueError, match="servo_cycle"):
        NOMINAL.tmf_experiment(jr.key(0), [0.1], duration=1.0, servo_cycle=2.5e-3)
    with pytest.raises(ValueError, match="ys"):
        NOMINAL.tmf_experiment(jr.key(0), [], duration=1.0)
    with pytest.raises(ValueError, match="duration"):
        NOMINAL.tmf_experiment(jr.key(0), [0.1], duration=0.0)


def test_simulation_matches_scipy_and_delay_is_a_shift():
    """Noiseless TCP/encoder motion equals scipy's ZOH simulation of an independently
    assembled chain on the same fine grid (rounding only); a delay of exactly 3 samples
    is a 3-sample shift of the undelayed truth."""
    twin = NOMINAL.with_effects(
        {"sensor_delay": 3e-3, "process_force": {"amplitude": 200.0, "tooth_pass_hz": 70.0}}
    )
    dt, os_ = 1e-3, 4
    recs, truth = twin.tmf_experiment(
        jr.key(1),
        [0.2],
        duration=0.5,
        dt=dt,
        oversample=os_,
        noise=0.0,
        encoder_resolution=1e-15,
        force_noise=0.0,
        return_truth=True,
    )
    ch = twin.chain(0.2)
    A, B = _dense_chain(*(np.asarray(a)[0] for a in (ch.masses, ch.stiffnesses, ch.dampings)))
    Cm = np.zeros((2, 8))
    Cm[0, 1] = Cm[1, 3] = 1.0
    sysd = ss.cont2discrete((A, B[:, [0, 3]], Cm, np.zeros((2, 2))), dt / os_)
    f = truth["f_true"][0]
    np.testing.assert_allclose(recs[0]["f"], f)  # no force noise asked
    # the TCP-force path (command off); the drive path is checked by the exact nominal fit
    twin_f = NOMINAL.with_effects({"process_force": {"amplitude": 200.0, "tooth_pass_hz": 70.0}})
    _, tr = twin_f.tmf_experiment(
        jr.key(1),
        [0.2],
        duration=0.5,
        dt=dt,
        oversample=os_,
        command_amplitude=0.0,
        noise=0.0,
        encoder_resolution=1e-15,
        force_noise=0.0,
        return_truth=True,
    )
    u = np.stack([np.zeros(f.size * os_), np.repeat(f, os_)], axis=-1)
    _, y, _ = ss.dlsim((*sysd[:4], dt / os_), u)
    y = y[::os_]
    scale = np.max(np.abs(y))
    np.testing.assert_allclose(tr["x_t_true"][0], y[:, 1], atol=1e-9 * scale)
    np.testing.assert_allclose(tr["x_e_true"][0], y[:, 0], atol=1e-9 * scale)
    # delay of exactly 3 samples: x_t[k] = x_t_true[k - 3], zeros before
    np.testing.assert_allclose(recs[0]["x_t"][3:], truth["x_t_true"][0][:-3], rtol=1e-12)
    np.testing.assert_array_equal(recs[0]["x_t"][:3], 0.0)


def _simulate_stacked(model, data):
    """All experiments in one batched `simulate` call (time axis first, as the data)."""
    return jaxvs.simulate(model, data["u"].T, data["dt"]).T


@eqx.filter_jit
def _calibrate(guess, data):
    residual = SimulationError(_simulate_stacked)
    return jaxvs.calibrate(guess, data, residual, covariance=False, throw=False)


def _fit_nominal(recs):
    """One 4/4 TMF by simulation error (zoh) from the exact nominal TMF at y = 0.3."""
    t = NOMINAL.tmf_model(jnp.array([0.3]))
    guess = stable(jaxvs.RationalTF(t.num[0] / t.den[0, 0], t.den[0] / t.den[0, 0]))
    u = jnp.stack([jnp.asarray(r["x_e"]) for r in recs], axis=-1)
    y = jnp.stack([jnp.asarray(r["x_t"]) for r in recs], axis=-1)
    res = _calibrate(guess, {"u": u, "y": y, "dt": recs[0].dt})  # one compilation for all
    assert res.result == jaxvs.calibration.RESULTS.successful
    model = unwrap(res.model)
    return model, np.asarray(_simulate_stacked(model, {"u": u, "dt": recs[0].dt}) - y).ravel()


@pytest.mark.slow
def test_nominal_is_exact_and_each_effect_shows():
    """Effects off: one 4/4 TMF fitted by simulation error to three positions reproduces x_t
    to the noise level (the nominal is position-independent, so this covers a single y).
    Oracle: the noise itself, reference-sensor noise plus the encoder quantisation passed
    through the fitted TMF; 10 % margin for the 9 fitted parameters and the 4/4 model's
    spare freedom. Each effect at a typical magnitude leaves > 3x that residual."""
    ys = [0.1, 0.3, 0.5]
    kw = dict(duration=2.0, dt=1e-3)
    recs, truth = NOMINAL.tmf_experiment(jr.key(7), ys, return_truth=True, **kw)
    model, r = _fit_nominal(recs)
    noise = np.stack([rec["x_t"] for rec in recs]) - truth["x_t_true"]
    quant = np.stack([rec["x_e"] for rec in recs]) - truth["x_e_true"]
    floor = np.std(noise + np.asarray(jaxvs.simulate(model, jnp.asarray(quant), 1e-3)))
    assert np.std(r) < 1.1 * floor, (np.std(r), floor)
    assert np.std(r) > 0.9 * floor  # not fitting the noise either (5991 dof left)
    typical = {
        "position_dependence": 0.4,
        "missing_mode": {"frequency_hz": 220.0, "mass_ratio": 0.08, "damping": 0.04},
        "sensor_delay": 3e-3,
        "process_force": {"amplitude": 100.0, "tooth_pass_hz": 90.0},
    }
    for label, value in typical.items():
        recs_e = NOMINAL.with_effects({label: value}).tmf_experiment(jr.key(7), ys, **kw)
        _, r_e = _fit_nominal(recs_e)
        assert np.std(r_e) > 3 * floor, (label, np.std(r_e) / floor)
