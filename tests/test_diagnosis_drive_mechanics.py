"""The mechanical effects of the drive diagnosis (backlash, resonance, time delay,
position dependence) against plants built here independently of the effect classes."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as ss

from jaxvs.diagnosis._base import AdmissibilityContext, Experiment
from jaxvs.diagnosis._drive import Backlash, PositionForceEffect, TimeDelay, coulomb_level

# a 1 kHz record of a 25 kg axis with a 1 µm encoder over 0.2 m, analysed up to 100 Hz
AXIS = AdmissibilityContext(1e-3, 2.5e-3, (0.2, 100.0), 1e-6, span=0.2, nominal={"M": 25.0})


def _columns(effect, arrays):
    """The effect's contribution for each unit size (its regressors)."""
    n = int(np.size(effect.size))
    cols = []
    for k in range(n):
        unit = eqx.tree_at(lambda e: e.size, effect, jnp.eye(n)[k])
        cols.append(np.asarray(unit.contribution(arrays, None)))
    return np.stack(cols, -1)


def test_time_delay_is_all_pass_and_exact_on_a_band_limited_signal():
    dt = 2.5e-3
    n = 800
    t = np.arange(n) * dt
    rng = np.random.default_rng(0)
    # band-limited noise (below half the Nyquist frequency, like the analysis arrays)
    sos = ss.butter(8, 0.5, output="sos")
    x = ss.sosfiltfilt(sos, rng.standard_normal(n))
    tau = 0.3 * dt  # a fraction of a sample: where an interpolation smooths the most
    out = np.asarray(TimeDelay(jnp.asarray(tau), dt).apply(jnp.asarray(x), {}, None))
    inner = slice(50, n - 50)
    # all-pass: the power of the signal is kept (an interpolation between samples would
    # remove 9 % of it here); 1 % allows the ends of the record
    assert np.sqrt(np.mean(out[inner] ** 2) / np.mean(x[inner] ** 2)) == pytest.approx(1, abs=0.01)
    # a sine of 7 Hz advanced by tau: closed form to 1e-4 of its amplitude away from the ends
    y = np.sin(2 * np.pi * 7 * t)
    out = np.asarray(TimeDelay(jnp.asarray(4.3e-3), dt).apply(jnp.asarray(y), {}, None))
    np.testing.assert_allclose(out[inner], np.sin(2 * np.pi * 7 * (t[inner] + 4.3e-3)), atol=1e-4)


def test_position_ripple_with_harmonic_predicts_travel_outside_calibration():
    # cogging of pitch 12 mm with a second harmonic (35 %), as a numpy function of q
    pitch, a1, a2 = 0.012, 30.0, 10.5

    def cogging(q):
        return a1 * np.sin(2 * np.pi * q / pitch + 0.7) + a2 * np.sin(4 * np.pi * q / pitch + 2.1)

    q_cal = 0.05 + 0.05 * np.sin(np.linspace(0, 6 * np.pi, 3000))  # travel [0, 0.1] m
    q_val = -0.12 + 0.08 * np.sin(np.linspace(0, 4 * np.pi, 2000))  # [-0.2, -0.04] m
    eff = PositionForceEffect(jnp.zeros(7), jnp.asarray(pitch), 0.05, 0.05)
    phi_cal = _columns(eff, {"q": jnp.asarray(q_cal)})
    coef, *_ = np.linalg.lstsq(phi_cal, cogging(q_cal), rcond=None)
    pred = _columns(eff, {"q": jnp.asarray(q_val)}) @ coef
    err = np.sqrt(np.mean((pred - cogging(q_val)) ** 2)) / np.sqrt(np.mean(cogging(q_val) ** 2))
    # the ripple and its harmonic are periodic and the smooth part is held beyond the
    # travel: the held-out record far from the calibrated travel is predicted to rounding
    # (1e-6 of the force; a cubic extrapolated 5 half-ranges away would be off by ~100 %)
    assert err < 1e-6
    # the held smooth part: beyond the travel it keeps its value at the end
    eff = PositionForceEffect(
        jnp.array([1.0, -2.0, 0.5, 0, 0, 0, 0.0]), jnp.asarray(pitch), 0.05, 0.05
    )
    far = np.asarray(eff.contribution({"q": jnp.asarray([-0.3, 0.0, 0.4, 0.1])}, None))
    end = np.polynomial.legendre.legval([-1.0, -1.0, 1.0, 1.0], [0.0, 1.0, -2.0, 0.5])
    np.testing.assert_allclose(far, end, rtol=1e-12)


def test_backlash_without_gap_adds_nothing_to_a_quantised_record():
    # a quantised position (1 µm encoder) whose record-rate derivatives `v`, `a` differ
    # from central differences on the analysis grid: a gap far below a count is no gap
    dt = 2.5e-3
    t = np.arange(1000) * dt
    q = np.round(0.05 * np.sin(2 * np.pi * 0.8 * t) / 1e-6) * 1e-6
    v = 0.05 * 2 * np.pi * 0.8 * np.cos(2 * np.pi * 0.8 * t)
    a = -0.05 * (2 * np.pi * 0.8) ** 2 * np.sin(2 * np.pi * 0.8 * t)
    arrays = {"q": jnp.asarray(q), "v": jnp.asarray(v), "a": jnp.asarray(a)}
    eff = Backlash(jnp.array([5.0, 10.0]), jnp.asarray(1e-12), jnp.asarray(1e-3), jnp.ones(2), dt)
    # of the order of the gap (the same differentiator for load and motor: 3e-6 N with a
    # 1e-12 m gap, from the 1 mm/s sharpness of the sign law); with the motor's motion
    # taken from the record-rate derivatives it was 2.3 N at most (0.07 N RMS)
    assert np.max(np.abs(np.asarray(eff.contribution(arrays, None)))) < 1e-5


def test_backlash_recovers_a_friction_loaded_gap():
    # a motor oscillating through a 0.2 mm gap pushes a table held by 40 N of friction:
    # the table (numpy loop, not the play operator) stays where the motor leaves it
    dt, b, f_load = 1e-3, 1e-4, 40.0
    t = np.arange(4000) * dt
    qm = 0.02 * np.sin(2 * np.pi * 0.5 * t) + 0.004 * np.sin(2 * np.pi * 3.1 * t)
    ql = np.empty_like(qm)
    pos = qm[0]
    for k, x in enumerate(qm):
        if x - pos > b:
            pos = x - b
        elif pos - x > b:
            pos = x + b
        ql[k] = pos
    vl = np.gradient(ql, dt)
    force = f_load * np.tanh(vl / 1e-4)  # the friction the motor feels through the table
    vm = np.gradient(qm, dt)
    arrays = {"q": jnp.asarray(qm), "v": jnp.asarray(vm), "a": jnp.asarray(np.gradient(vm, dt))}
    # the nominal model carries the friction of the motion (Coulomb friction added
    # first); the backlash corrects it where the table stands still in the gap
    nominal = f_load * np.tanh(vm / 1e-4)
    eff = Backlash(jnp.zeros(2), jnp.asarray(b), jnp.asarray(1e-4), jnp.ones(2), dt)
    phi = _columns(eff, arrays)[:, 1:]  # the table's friction (it has no mass here)
    coef, *_ = np.linalg.lstsq(phi, force - nominal, rcond=None)
    # F_L to 10 % (the plant's table velocity is not smoothed like the effect's, and the
    # gap crossings last only a few samples)
    assert coef[0] == pytest.approx(f_load, rel=0.1)
    # and it explains most of the force the rigid model with friction leaves (90 %)
    left = force - nominal - phi @ coef
    assert np.sum(left**2) < 0.1 * np.sum((force - nominal) ** 2)


def test_backlash_terms_the_load_has_not_are_neither_fitted_nor_ruled():
    # a load carried by friction alone: its mass term is off, so a small value left in
    # the (unused) size is neither reported nor ruled inadmissible
    ctx = AXIS
    friction_only = jnp.array([0.0, 1.0])
    eff = Backlash(
        jnp.array([-0.2, 53.0]), jnp.asarray(1.3e-4), jnp.asarray(1e-3), friction_only, 2.5e-3
    )
    assert eff.admissible(ctx) == (True, None)
    assert eff.parameters()["m_load"] == 0.0 and eff.parameters()["F_load"] == 53.0
    # and its contribution has no mass term: the same with any value in the unused size
    t = np.arange(400) * 2.5e-3
    q = 0.01 * np.sin(2 * np.pi * 1.0 * t)
    d = {"q": jnp.asarray(q)}
    other = eqx.tree_at(lambda e: e.size, eff, jnp.array([30.0, 53.0]))
    np.testing.assert_array_equal(
        np.asarray(eff.contribution(d, None)), np.asarray(other.contribution(d, None))
    )
    # with both terms on, the negative mass is ruled out
    both = eqx.tree_at(lambda e: e.terms, eff, jnp.ones(2))
    ok, why = both.admissible(ctx)
    assert not ok and "negative load mass" in why


def test_a_friction_loaded_gap_within_the_presliding_range_is_not_a_backlash():
    ctx = AXIS
    vs, both = jnp.asarray(1e-3), jnp.ones(2)
    # a 9 µm gap behind which 40 N of friction act: presliding friction looks the same
    ok, why = Backlash(jnp.array([3.0, 40.0]), jnp.asarray(4.5e-6), vs, both, 2.5e-3).admissible(
        ctx
    )
    assert not ok and "presliding" in why
    # the same gap with an inertial load only (an impact) stays a backlash
    inertial = Backlash(jnp.array([3.0, 0.0]), jnp.asarray(4.5e-6), vs, both, 2.5e-3)
    assert inertial.admissible(ctx) == (True, None)
    # and a 0.2 mm friction-loaded gap is one
    wide = Backlash(jnp.array([3.0, 40.0]), jnp.asarray(1e-4), vs, both, 2.5e-3)
    assert wide.admissible(ctx) == (True, None)


def test_a_friction_loaded_gap_needs_the_dry_friction_the_axis_drags():
    """A table held by friction `F_L` behind a play is dragged whenever the play is
    closed: the axis shows at least `F_L` of dry friction while it moves. Oracle: a
    force with a closed-form Coulomb level (40 N) and one with fluid drag `c v|v|`,
    which a linear viscous law plus a constant reads as a negative dry friction."""
    rng = np.random.default_rng(2)
    t = np.arange(20_000) * 1e-3
    v = 0.5 * np.sin(2 * np.pi * 0.5 * t) + 0.2 * np.sin(2 * np.pi * 1.3 * t)
    a = np.gradient(v, 1e-3)
    found = {}
    for name, force in (
        ("coulomb", 25.0 * a + 80.0 * v + 40.0 * np.sign(v)),
        ("drag", 25.0 * a + 80.0 * v + 300.0 * v * np.abs(v)),
    ):
        exp = Experiment(
            "x", t, {"y": force + rng.normal(size=t.size), "v": v, "a": a}, {}, {}, 1.0, frozenset()
        )
        found[name] = coulomb_level([exp])
    assert found["coulomb"]["coulomb_level"] == pytest.approx(40.0, abs=0.1)
    assert found["drag"]["coulomb_level"] < -10.0
    vs, friction = jnp.asarray(1e-3), jnp.array([0.0, 1.0])
    load = Backlash(jnp.array([0.0, 8.0]), jnp.asarray(5e-3), vs, friction, 2.5e-3)
    for name, ok in (("coulomb", True), ("drag", False)):
        ctx = AdmissibilityContext(
            1e-3, 2.5e-3, (0.2, 100.0), 1e-6, span=0.8, nominal={"M": 25.0, **found[name]}
        )
        verdict, why = load.admissible(ctx)
        assert verdict is ok
        assert ok or "dragged whenever the gap is closed" in why
    # an inertial load needs no friction
    inertial = Backlash(jnp.array([3.0, 0.0]), jnp.asarray(5e-3), vs, jnp.ones(2), 2.5e-3)
    ctx = AdmissibilityContext(
        1e-3, 2.5e-3, (0.2, 100.0), 1e-6, span=0.8, nominal={"M": 25.0, **found["drag"]}
    )
    assert inertial.admissible(ctx) == (True, None)


def test_a_position_force_does_not_make_the_mass_unidentifiable():
    # a 20 kg axis at 100 Hz whose force is dominated by a slow position-dependent force
    # (a wavy incline, numpy): the mass is determined by the record's noise, the slow
    # residual is the effect the search is for
    from jaxvs.data import Record
    from jaxvs.diagnosis._base import GapModel
    from jaxvs.diagnosis._drive import DriveFamily

    fs, n, mass, fv = 100.0, 3000, 20.0, 60.0
    t = np.arange(n) / fs
    w1, w2 = 2 * np.pi * 0.2, 2 * np.pi * 0.9
    q = 0.1 * np.sin(w1 * t) + 0.02 * np.sin(w2 * t)
    v = 0.1 * w1 * np.cos(w1 * t) + 0.02 * w2 * np.cos(w2 * t)
    a = -0.1 * w1**2 * np.sin(w1 * t) - 0.02 * w2**2 * np.sin(w2 * t)
    incline = 40.0 * np.cos(2 * np.pi * q / 0.25)  # even in q: not taken for inertia
    rng = np.random.default_rng(4)
    u = mass * a + fv * v + incline + 0.2 * rng.standard_normal(n)
    fam = DriveFamily()
    exp = fam.prepare(Record({"q": q, "u": u}, dt=1 / fs), "incline")
    model = GapModel(fam.nominal([exp]))
    assert fam.identifiability([exp], model) is None
    assert not isinstance(model.nominal.M, float)  # calibrated, not fixed
    # a force unrelated to the motion (noise only) leaves the mass undetermined: it is
    # fixed at zero with a warning, and the record is not refused
    flat = fam.prepare(Record({"q": q, "u": 10 + rng.standard_normal(n)}, dt=1 / fs), "flat")
    nominal = fam.nominal([flat])
    assert nominal.M == 0.0 and "mass is fixed" in fam.nominal_warnings([flat])[0]
    assert fam.identifiability([flat], GapModel(nominal)) is None
