"""The blind benchmark's plants (benchmarks/blind_plants.py) are right: checked against
closed forms and scipy, never against the diagnosis."""

import dataclasses
import math

import numpy as np
import pytest
import scipy.signal as ss
from benchmark_module import load_benchmark

# docs/guides/contracts.md, effect names (exact strings) -- the oracle for the case list
EFFECT_NAMES = {
    "drive": {
        "coulomb_friction",
        "asymmetric_friction",
        "stribeck_friction",
        "backlash",
        "resonance",
        "time_delay",
        "external_force",
        "position_dependence",
        "saturation",
    },
    "tmf": {"position_dependence", "missing_mode", "sensor_delay", "process_force"},
    "thermal": {
        "dynamics",
        "ambient_temperature",
        "coolant_temperature",
        "speed_nonlinearity",
    },
}


@pytest.fixture(scope="module")
def bp():
    return load_benchmark("blind_plants")


def _quiet(case, **settings):
    """The same plant (same name, so same seed) with its measurement noise switched off."""
    return dataclasses.replace(case, settings={**case.settings, **settings})


def _case(bp, name):
    return next(c for c in bp.cases() if c.name == name)


def test_case_list(bp):
    cs = bp.cases()
    assert [c.name for c in cs] == [c.name for c in bp.cases()]  # deterministic
    assert len({c.name for c in cs}) == len(cs)
    assert len({c.seed for c in cs}) == len(cs)
    for fam, names in EFFECT_NAMES.items():
        fc = [c for c in cs if c.family == fam]
        # at least 25 % effect-free cases, per family
        assert sum(c.effect_free for c in fc) >= 0.25 * len(fc)
        for eff in names:
            variants = {c.variant for c in fc if eff in c.effects}
            assert len(variants) >= 2, (fam, eff, variants)
        assert {e for c in fc for e in c.effects} == names  # only contract names
        assert any(len(c.effects) == 2 for c in fc)
        for c in fc:
            assert (c.primary is None) == c.effect_free
            assert c.primary is None or c.primary in c.effects
        # white and coloured noise on cases with effects and on effect-free ones
        for free in (True, False):
            rhos = {c.settings.get("noise_rho", 0.0) > 0 for c in fc if c.effect_free == free}
            assert rhos == {True, False}, (fam, free)
    rates = {c.settings.get("fs_rec") for c in cs if c.family == "drive"}
    assert min(rates) == 10 and max(rates) == 10000
    # the stratified selection keeps effect-free cases in every prefix
    sel = bp.select(cs, 12)
    assert len(sel) == 12 and sum(c.effect_free for c in sel) >= 3


def test_generation_is_deterministic_and_fast(bp):
    import time

    for name in ("drive-backlash-hertz", "tmf-force-dynamometer", "thermal-dynamics-two-node"):
        c = _case(bp, name)
        t0 = time.perf_counter()
        cal1, val1, info1 = bp.generate(c)
        took = time.perf_counter() - t0
        cal2, val2, info2 = bp.generate(c)
        assert info1["truth"] == info2["truth"]
        for a, b in zip(cal1 + val1, cal2 + val2):
            assert a.names == b.names
            for s in a.names:
                np.testing.assert_array_equal(np.asarray(a[s]), np.asarray(b[s]))
        # < 2 s per case on an idle machine; 10 s leaves room for a loaded CI machine
        assert took < 10.0


def _rigid(fs=1000, nsub=1, **kw):
    p = dict(
        structure="rigid",
        M=12.0,
        Fv=40.0,
        offset=3.0,
        fs_ctrl=fs,
        fs_rec=fs,
        nsub=nsub,
        resolution=1e-15,
        noise_u=0.0,
        noise_rho=0.0,
    )
    p.update(kw)
    return p


@pytest.mark.parametrize("nsub", [1, 3])
def test_rigid_open_loop_matches_closed_form(bp, nsub):
    """Effect-free rigid plant, open loop: a force step from rest gives
    q(t) = (F/Fv)·(t − τ(1 − e^{−t/τ})), τ = M/Fv; a zero-order-held random force agrees
    with scipy's exact ZOH discretisation of M q̈ + Fv q̇ = u − offset."""
    rng = np.random.default_rng(0)
    p = _rigid(nsub=nsub)
    n = 2000
    u = np.full(n, 50.0)
    out = bp.simulate_drive(p, None, u, rng)
    t = np.arange(n) / 1000.0
    F, tau = 50.0 - 3.0, 12.0 / 40.0
    q_exact = F / 40.0 * (t - tau * (1 - np.exp(-t / tau)))
    # exact exponential update: agreement to rounding (1e-12 of the 2.3 m travel)
    np.testing.assert_allclose(out["q"], q_exact, rtol=0, atol=1e-11)
    np.testing.assert_array_equal(out["u"], u)  # logged force = commanded force

    u = rng.normal(0, 30, n)
    out = bp.simulate_drive(p, None, u, rng)
    A = np.array([[0.0, 1.0], [0.0, -40.0 / 12.0]])
    B = np.array([[0.0], [1 / 12.0]])
    sysd = ss.cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), 1e-3, method="zoh")
    _, y, _ = ss.dlsim(sysd, u - 3.0)
    np.testing.assert_allclose(out["q"], y[:, 0], rtol=0, atol=1e-12)


def test_amplifier_limit_applies_the_clipped_command(bp):
    """Current limit: the motion is scipy's exact ZOH response to the command clipped at
    ±F_max, the logged force the command itself; with a first-order current loop in
    front (exact exponential update of the current per step), the motion does not depend
    on the step: a 10× finer one agrees to 0.2 % of the travel."""
    rng = np.random.default_rng(2)
    n = 1500
    u = rng.normal(0, 60, n)
    out = bp.simulate_drive(_rigid(force_limit=50.0), None, u, rng)
    np.testing.assert_array_equal(out["u"], u)  # the logger records the command
    A = np.array([[0.0, 1.0], [0.0, -40.0 / 12.0]])
    B = np.array([[0.0], [1 / 12.0]])
    sysd = ss.cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), 1e-3, method="zoh")
    _, y, _ = ss.dlsim(sysd, np.clip(u, -50.0, 50.0) - 3.0)
    np.testing.assert_allclose(out["q"], y[:, 0], rtol=0, atol=1e-12)
    assert np.mean(np.abs(u) > 50.0) > 0.3  # the limit acts on a third of the samples
    # the current loop's lag: the exact exponential update does not depend on the step
    lag = dict(force_limit=1e9, current_tau=2e-3)
    coarse = bp.simulate_drive(_rigid(nsub=1, **lag), None, u, rng)
    fine = bp.simulate_drive(_rigid(nsub=10, **lag), None, u, rng)
    np.testing.assert_allclose(coarse["q"], fine["q"], rtol=0, atol=2e-3 * np.ptp(fine["q"]))


def test_transport_delay_shifts_the_response(bp):
    """A transport delay of m fine steps (8 = 2 samples) is the undelayed response later."""
    rng = np.random.default_rng(1)
    u = np.repeat(rng.normal(0, 30, 300), 1)
    # no offset: the offset acts at once, the delayed force only after the delay
    a = bp.simulate_drive(_rigid(nsub=4, offset=0.0), None, u, rng)
    b = bp.simulate_drive(_rigid(nsub=4, offset=0.0, transport_steps=8), None, u, rng)
    # motion is unchanged up to the delayed force's start and then shifted by 2 samples
    np.testing.assert_allclose(b["q"][2:], a["q"][:-2], rtol=0, atol=1e-13)


def test_karnopp_sticks_below_breakaway(bp):
    rng = np.random.default_rng(2)
    p = _rigid(friction="karnopp", Fc_pos=10.0, Fc_neg=10.0, Fs_pos=15.0, Fs_neg=15.0)
    p["offset"] = 0.0
    out = bp.simulate_drive(p, None, np.full(500, 14.0), rng)
    assert np.all(out["q"] == 0.0)  # 14 N < 15 N breakaway: no motion at all
    out = bp.simulate_drive(p, None, np.full(500, 30.0), rng)
    # sliding: M q̈ + Fv q̇ = 30 − Fc(v); the level is between Fc and Fs, so the final
    # speed lies between (30 − 15)/Fv and (30 − 10)/Fv (exp(-0.5/0.3) of it not yet reached)
    v_end = (out["q"][-1] - out["q"][-2]) * 1000.0
    assert (30 - 15) / 40 * 0.8 < v_end < (30 - 10) / 40


@pytest.mark.parametrize("name", ["drive-backlash-friction-loaded", "drive-backlash-hertz"])
def test_backlash_dead_band(bp, name):
    """The load position against the motor position shows the dead band of the gap: the
    relative position stays within ±b (plus contact penetration for the Hertz contact),
    and after reversals it crosses the whole gap."""
    c = _case(bp, name)
    cal, _, info = bp.generate(_quiet(c, noise_u=0.0))
    out = info["raw"][0][1]
    b = info["truth"]["gap"] / 2
    d = out["x_motor"] - out["x_load"]
    if "friction" in name:
        assert np.max(np.abs(d)) <= b * (1 + 1e-9)  # rigid stops at ±b
    else:
        # Hertz contact: penetration (F/k)^(2/3) ≈ 10 µm at 30 N by design, 40 µm at the
        # largest impacts; far below the gap's 2b but not zero
        assert np.max(np.abs(d)) <= 1.6 * b
    # both stops reached: the motor crossed the whole gap at the reversals (5 %: the
    # Hertz contact may leave before touching exactly)
    assert np.max(d) > 0.95 * b and np.min(d) < -0.95 * b
    # the dead band: while the motor crosses the gap the load does not follow
    xm, xl = out["x_motor"], out["x_load"]
    crossing = (np.abs(d) < 0.5 * b) & (np.abs(np.gradient(xm)) > 0)
    assert crossing.sum() > 10
    if "friction" in name:
        moved_m = np.abs(np.diff(xm))[crossing[1:]]
        moved_l = np.abs(np.diff(xl))[crossing[1:]]
        # the table is held by its friction: it moves much less than the motor
        assert moved_l.sum() < 0.2 * moved_m.sum()


def test_resonance_truth_is_the_inverse_dynamics_mode(bp):
    """Frame variant: u/q has its lightly damped pole at √(k_b/(M + m_b)) = truth f_r;
    checked on the simulated record by the peak of the empirical u→q inverse FRF."""
    c = _case(bp, "drive-resonance-frame")
    _, _, info = bp.generate(c)
    p = info["plant"]
    f = math.sqrt(p["k_c"] / (p["M"] + p["M_load"])) / (2 * math.pi)
    assert f == pytest.approx(info["truth"]["f_r"], rel=1e-12)
    # open-loop simulation of the linear plant with a random force: |q/u| has a dip
    # (u/q a peak) at f_r
    rng = np.random.default_rng(3)
    q = dict(p, structure="frame", noise_u=0.0, resolution=1e-15, transport_steps=0)
    q.update(fs_ctrl=2000, fs_rec=2000, nsub=1, Fv=p["Fv"])
    u = rng.normal(0, 50, 40000)
    out = bp.simulate_drive(q, None, u, rng)
    fr, puu = ss.welch(u, fs=2000, nperseg=4096)
    _, pqu = ss.csd(u, out["q"], fs=2000, nperseg=4096)
    h = np.abs(pqu / puu) * (2 * np.pi * fr) ** 2  # accelerance: flat except at the mode
    band = (fr > 5) & (fr < 200)
    f_dip = fr[band][np.argmin(h[band])]
    assert abs(f_dip - f) < 2 * (fr[1] - fr[0]) + 0.02 * f  # two bins or 2 %


def test_tmf_mode_frequency_and_frf(bp):
    """The modal beam: the FRF x_e → x_t estimated from a noise-free record follows
    1 − Σ w s²/(s² + 2ζωs + ω²); its peak is at the first mode's frequency."""
    dt = 1 / 16000.0
    modes = [(60.0, 0.03, 1.566), (376.0, 0.04, -0.867)]
    rng = np.random.default_rng(4)
    x_e = ss.sosfilt(ss.butter(4, 1500, fs=16000, output="sos"), rng.normal(0, 1, 2**17))
    x_t = bp.tmf_response(x_e, dt, modes)
    fr, pee = ss.welch(x_e, fs=16000, nperseg=8192)
    _, pet = ss.csd(x_e, x_t, fs=16000, nperseg=8192)
    h = pet / pee
    s = 2j * np.pi * fr
    exact = 1 - sum(
        w * s**2 / (s**2 + 2 * z * 2 * np.pi * f * s + (2 * np.pi * f) ** 2) for f, z, w in modes
    )
    # H1 of a noise-free LTI response: leakage bias only, which is large within a few
    # half-power bandwidths of the lightly damped peaks (excluded: ±20 %); errors relative
    # to max(|T|, 1), the unit static transmissibility (anti-resonances are near zero)
    band = (fr > 10) & (fr < 1000) & (np.abs(fr / 60 - 1) > 0.2) & (np.abs(fr / 376 - 1) > 0.2)
    err = np.abs(h[band] - exact[band]) / np.maximum(np.abs(exact[band]), 1.0)
    assert np.median(err) < 0.01 and np.max(err) < 0.03
    peak = fr[(fr > 10) & (fr < 200)][np.argmax(np.abs(h[(fr > 10) & (fr < 200)]))]
    assert abs(peak - 60.0) <= 2 * (fr[1] - fr[0])

    # and on a generated case: the truth f1 is where the record's FRF peaks
    c = _quiet(_case(bp, "tmf-free-1khz"), noise=0.0, resolution=0.0)
    cal, _, info = bp.generate(c)
    xe, xt = np.asarray(cal[0]["x_e"]), np.asarray(cal[0]["x_t"])
    fr, pee = ss.welch(xe, fs=1000, nperseg=1024)
    _, pet = ss.csd(xe, xt, fs=1000, nperseg=1024)
    band = (fr > 5) & (fr < 150)
    peak = fr[band][np.argmax(np.abs(pet / pee)[band])]
    assert abs(peak - info["truth"]["f1"]) <= 2 * (fr[1] - fr[0])


def test_tmf_delays(bp):
    """Pure delay: x_t is the undelayed tool motion `delay` later. Bessel filter: the
    group delay at low frequency of the delay-normalised Bessel filter is the truth."""
    tau = 2.3e-4
    bz, az = ss.bessel(4, 1 / tau, analog=True, norm="delay")
    w = np.array([1e-2, 1e-1]) / tau
    _, hh = ss.freqs(bz, az, worN=w)
    gd = -np.diff(np.unwrap(np.angle(hh))) / np.diff(w)
    assert gd[0] == pytest.approx(tau, rel=1e-3)  # closed form: Bessel normalised by delay
    c = _quiet(_case(bp, "tmf-delay-pure"), noise=0.0, resolution=0.0)
    c0 = dataclasses.replace(c, variant="none")
    cal, _, info = bp.generate(c)
    cal0, _, _ = bp.generate(c0)
    fs = 1 / cal[0].dt
    xt, xt0 = np.asarray(cal[0]["x_t"]), np.asarray(cal0[0]["x_t"])
    # same excitation and plant, only the delay differs: the cross-spectrum phase of the
    # delayed against the undelayed tool signal is −2πfτ (fit over 2 %–30 % of fs)
    fr, pxx = ss.welch(xt0, fs=fs, nperseg=1024)
    _, pxy = ss.csd(xt0, xt, fs=fs, nperseg=1024)
    band = (fr > 0.02 * fs) & (fr < 0.3 * fs)
    phase = np.unwrap(np.angle(pxy[band] / pxx[band]))
    tau_fit = -np.polyfit(2 * np.pi * fr[band], phase, 1)[0]
    assert tau_fit == pytest.approx(info["truth"]["delay"], rel=0.01)


def test_thermal_first_order_matches_exponential(bp):
    """Exact discretisation of one node equals the exponential; in the first-order
    bearing case T_b relaxes to T_chassis + Q_b/G_bc with the truth time constant."""
    ad, bd = bp.thermal_step_matrices(np.array([[-1 / 300.0]]), np.array([[1 / 300.0]]), 7.0)
    assert ad[0, 0] == pytest.approx(math.exp(-7 / 300), rel=1e-13)
    assert bd[0, 0] == pytest.approx(1 - math.exp(-7 / 300), rel=1e-12)

    c = _quiet(_case(bp, "thermal-dynamics-first-order"), noise=0.0, quantisation=0.0)
    cal, _, info = bp.generate(c)
    r, p, tau = cal[0], info["plant"], info["truth"]["tau"]
    tb, tc, v = (np.asarray(r[s]) for s in ("T_bearing", "T_chassis", "v_m"))
    x = v / p["vmax"]
    t_ss = tc + (p["q_b0"] + p["q_b1"] * x) / p["G_bc"]
    a = math.exp(-r.dt / tau)
    # sample k+1 ends the step over which v[k+1] is held; the chassis moves within the
    # step, taken at its mean: error O(h²·dT_ch/dt/τ), far below 1 mK
    pred = a * tb[:-1] + (1 - a) * (0.5 * (tc[1:] + tc[:-1]) + (t_ss[1:] - tc[1:]))
    assert np.max(np.abs(tb[1:] - pred)) < 2e-3
    assert np.ptp(tb) > 5  # a real warm-up, not a flat record

    # effect-free: the bearing is static, T_b = T_ch + Q_b/G_bc (0.05 s node, 5 s steps)
    c = _quiet(_case(bp, "thermal-free-5s"), noise=0.0, quantisation=0.0)
    cal, _, info = bp.generate(c)
    r, p = cal[0], info["plant"]
    tb, tc, v = (np.asarray(r[s]) for s in ("T_bearing", "T_chassis", "v_m"))
    static = tc + (p["q_b0"] + p["q_b1"] * v / p["vmax"]) / p["G_bc"]
    assert np.max(np.abs(tb - static)) < 1e-3  # e^(-100) of a step left, chassis drift


def test_write_case_round_trip(bp, tmp_path):
    """Written cases load back (for the CLI) with the same samples; a tmf position kept in
    the metadata becomes a constant `y` column; truth.json carries the ground truth."""
    import json

    from jaxvs.data import load

    c = _case(bp, "tmf-position-overhang")
    files = bp.write_case(c, tmp_path)
    cal, val, info = bp.generate(c)
    assert len(files) == len(cal) + len(val)
    for f, rec in zip(files, cal + val):
        back = load(f)
        np.testing.assert_array_equal(np.asarray(back["x_t"]), np.asarray(rec["x_t"]))
        np.testing.assert_array_equal(np.asarray(back["y"]), float(rec.metadata["y"]))
        assert back.dt == pytest.approx(rec.dt, rel=1e-12)
    truth = json.loads((tmp_path / c.name / "truth.json").read_text())
    assert truth["effects"] == ["position_dependence"] and truth["truth"] == info["truth"]


def test_out_of_library_cases(bp):
    """Four effects per family in no library, each at two sizes; no library name."""
    ool = bp.out_of_library()
    names = {c.name for c in bp.cases()}
    assert not names & {c.name for c in ool}
    assert [c.name for c in bp.all_cases()] == [c.name for c in bp.cases() + ool]
    for fam in ("drive", "tmf", "thermal"):
        fc = [c for c in ool if c.family == fam]
        assert len({c.variant for c in fc}) >= 4 and len(fc) == 2 * len({c.variant for c in fc})
        for c in fc:
            assert c.out_of_library and not c.effect_free and c.primary is None
            assert all(e.startswith("ool:") for e in c.effects)
            assert not set(c.effects) & EFFECT_NAMES[fam]
        sizes = {}
        for c in fc:
            sizes.setdefault(c.variant, []).append(c.settings["size"])
        assert all(len(v) == 2 and v[0] < v[1] for v in sizes.values())


def test_out_of_library_mode_integrator_is_the_linear_mode_at_size_zero(bp):
    """The step-by-step modal integrator of the out-of-library tmf plants (Runge–Kutta on
    the 8× grid, relative to the root motion) against the exact first-order-hold filter
    of the linear modes: at size zero the Duffing, joint-friction and drifting plants are
    the linear structure (within 0.1 % of the modal response's RMS; RK4 at ω dt ≈ 0.02
    and the root velocity by central differences leave about 2e-5)."""
    fs, os_ = 2000.0, 8
    dt = 1.0 / (fs * os_)
    rng = np.random.default_rng(5)
    x_e = ss.sosfilt(ss.butter(4, 0.4 * fs, fs=1 / dt, output="sos"), rng.standard_normal(40000))
    x_e = 1e-5 * x_e / np.std(x_e) * bp._smoothstep(np.arange(x_e.size) / 2000)  # from rest
    modes = [(60.0, 0.03, 1.566), (376.0, 0.04, -0.867)]
    exact = bp.tmf_response(x_e, dt, modes)
    for variant in ("ool-duffing", "ool-joint", "ool-drift"):
        case = bp.Case("t", "tmf", ("ool:x",), None, variant, {"size": 0.0})
        got = bp._tmf_out_of_library(case, x_e, dt, modes)
        assert np.std(got - exact) < 1e-3 * np.std(exact - x_e), variant
    # and a size changes it: the cubic sensor error of size c adds c·d³/var(d)
    case = bp.Case("t", "tmf", ("ool:sensor",), None, "ool-sensor", {"size": 0.1})
    got = bp._tmf_out_of_library(case, x_e, dt, modes)
    d = exact - exact.mean()
    np.testing.assert_allclose(got - exact, 0.1 * d**3 / np.var(d), rtol=1e-12, atol=1e-20)


def test_out_of_library_thermal_size_is_in_noise_units(bp):
    """The thermal out-of-library terms have an RMS of `size` times the sensor noise: the
    case generated with and without the term (same seed) differs by exactly that."""
    for kind in ("drift", "step", "interaction", "neighbour"):
        case = next(c for c in bp.out_of_library() if c.name == f"thermal-ool-{kind}-small")
        cal, _, _ = bp.generate(case)
        quiet = _quiet(case, noise=0.0)
        calq, _, _ = bp.generate(quiet)
        free = dataclasses.replace(quiet, variant="none", effects=())
        cal0, _, _ = bp.generate(free)
        add = np.asarray(calq[0]["T_bearing"]) - np.asarray(cal0[0]["T_bearing"])
        # noise 0 makes the term 0: size × noise with noise = 0
        assert np.allclose(add, 0.0)
        assert np.std(np.asarray(cal[0]["T_bearing"])) > 0


@pytest.mark.parametrize(
    ("name", "key", "size"),
    [
        ("drive-coulomb-dahl", "Fc", 0.5),
        ("drive-external-gravity-load", "external_amplitude", 0.3),
        ("drive-backlash-hertz", "gap", 0.1),
        ("thermal-speed-quadratic-convection", "q2_over_q1", 0.25),
    ],
)
def test_effect_size_scales_only_the_effect(bp, name, key, size):
    """`effect_size` scales the library effect's magnitude; every other parameter of the
    plant (same seed, same random stream) stays."""
    c = _case(bp, name)
    base = dataclasses.replace(c, settings={**c.settings, "effect_size": 1.0})
    scaled = dataclasses.replace(c, settings={**c.settings, "effect_size": size})
    t1 = bp.generate(base)[2]["truth"]
    t2 = bp.generate(scaled)[2]["truth"]
    assert t2[key] == pytest.approx(size * t1[key], rel=1e-12)
    for k in t1:
        if k != key and not (key == "Fc" and k.startswith("Fc")):
            assert t2[k] == pytest.approx(t1[k], rel=1e-12), k


def test_tmf_delay_size_scales_the_delay_in_fine_steps(bp):
    c = _case(bp, "tmf-delay-pure")
    d1 = bp.generate(dataclasses.replace(c, settings={**c.settings, "effect_size": 1.0}))[2]
    d3 = bp.generate(c)[2]
    dt_f = 1.0 / (8 * c.settings["fs"])
    assert c.settings["effect_size"] == 3.0
    assert d3["truth"]["delay"] == pytest.approx(3 * d1["truth"]["delay"], abs=0.5 * dt_f)
