"""The drive family's friction and external-force candidates on plants of their own.

The plants are forward simulations written here (a rigid carriage under a digital PID
position loop, Karnopp stick-slip friction, switched loads), not the diagnosis's
inverse-dynamics model; the oracles are the plants' own force terms.
"""

import math

import jax.numpy as jnp
import numpy as np

from jaxvs.data import Record
from jaxvs.diagnosis._base import Experiment
from jaxvs.diagnosis._drive import (
    AsymmetricFrictionEffect,
    CoulombEffect,
    DriveFamily,
    ExternalForce,
    RigidNominal,
    StribeckEffect,
    _refresh_events,
    detect_events,
    follows_command,
)

FS = 1000.0  # record and controller rate [Hz]
SUB = 10  # integration substeps per controller period


def _axis(ref, load, *, M=12.0, Fv=40.0, off=3.0, Fc=0.0, Fs=0.0, noise=0.3, seed=0):
    """A carriage of mass `M` [kg] on a guideway (viscous `Fv`, Karnopp friction with
    breakaway `Fs` and sliding level `Fc` [N]) under a PID loop at `FS`, with an
    unmeasured force `load(t)` [N] and a force offset `off` [N]. Returns a record of the
    encoder position (1 µm) and the commanded force (white noise `noise` [N])."""
    rng = np.random.default_rng(seed)
    h = 1.0 / (FS * SUB)
    kp, kd, ki = M * (2 * math.pi * 8) ** 2, 2 * M * 2 * math.pi * 8, M * 400.0
    x = v = integ = 0.0
    q_prev = 0.0
    n = ref.size
    q_log, u_log = np.empty(n), np.empty(n)
    for k in range(n):
        qk = round(x / 1e-6) * 1e-6
        err = ref[k] - qk
        integ += err / FS
        vel = (qk - q_prev) * FS if k else 0.0
        q_prev = qk
        vref = (ref[min(k + 1, n - 1)] - ref[k]) * FS
        u = kp * err + kd * (vref - vel) + ki * integ
        q_log[k], u_log[k] = qk, u
        for j in range(SUB):
            f = u - off + load((k * SUB + j) * h) - Fv * v
            if abs(v) < 1e-5 and abs(f) <= Fs:
                v = 0.0  # stuck: static friction balances the applied force
                continue
            fr = math.copysign(Fc if abs(v) >= 1e-5 else Fs, v if abs(v) >= 1e-5 else f)
            v_new = v + h * (f - fr) / M
            v = 0.0 if v != 0.0 and v_new * v < 0 else v_new
            x += h * v
    u_log = u_log + noise * rng.standard_normal(n)
    return Record({"q": q_log, "u": u_log}, dt=1.0 / FS)


def _p2p(n, amp=0.05, move=0.5, dwell=0.4):
    """Back-and-forth point-to-point moves (smoothstep) with dwells in between [m]."""
    t = np.arange(n) / FS
    period = 2 * (move + dwell)
    ph = np.mod(t, period)
    s = np.clip(ph / move, 0, 1)
    up = s * s * (3 - 2 * s)
    s2 = np.clip((ph - move - dwell) / move, 0, 1)
    down = s2 * s2 * (3 - 2 * s2)
    return amp * (up - down)


def _nominal_residual(fam, cal, val):
    """Experiments of the family and their residuals after the rigid axis calibrated on
    the calibration record (linear least squares, the family's initialisation)."""
    exps = [fam.prepare(cal, "cal"), fam.prepare(val, "val")]
    nom = fam.nominal(exps[:1])
    res = [e.y - np.asarray(nom(e.jax_arrays())) for e in exps]
    return exps, nom, res


def _held_axis(n, pulse, *, M=12.0, Fv=40.0, off=3.0, Fc=20.0, Fs=30.0, seed=0):
    """The force of an axis following `_p2p` exactly, with Karnopp friction: sliding at
    `Fc` [N], and at every dwell static friction holding whatever force the loop left,
    drawn uniformly within the breakaway level `Fs` [N]; plus the unmeasured `pulse(t)`,
    0.3 N of white force noise and a 1 µm encoder."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    q = _p2p(n, move=0.7, dwell=0.2)
    v = np.gradient(q, 1 / FS)
    a = np.gradient(v, 1 / FS)
    still = np.abs(v) < 1e-9
    u = M * a + Fv * v + off + Fc * np.sign(v) - np.array([pulse(x) for x in t])
    edges = np.flatnonzero(np.diff(still.astype(int)) == 1) + 1
    for k, e in enumerate(np.concatenate([[0], edges])):
        stop = e + int(np.argmin(still[e:])) if not still[e:].all() else n
        u[e:stop] += rng.uniform(-Fs, Fs)
    u = u + 0.3 * rng.standard_normal(n)
    return Record({"q": np.round(q / 1e-6) * 1e-6, "u": u}, dt=1 / FS)


def test_a_force_held_at_standstill_is_not_an_external_force():
    """Karnopp friction (breakaway 30 N, sliding 20 N) holds the axis at every dwell with
    whatever force the loop left: the rigid model's residual is box-shaped there, as an
    unmeasured pulse would be, but static friction can carry any force up to the
    breakaway level, so only the pulse that acts on the moving axis is an event."""
    n = 9000
    t0, t1 = 4.55, 4.85  # the pulse acts during a move (moves start every 0.9 s)

    def pulse(t):
        return -40.0 if t0 <= t <= t1 else 0.0

    exp = DriveFamily().prepare(_held_axis(n, pulse), "cal")
    # the residual the candidate sees once Coulomb friction is in the model (the rigid
    # axis and a smooth sign law of sharpness 0.2 % of the top speed, least squares)
    v = exp.arrays["v"]
    phi = np.stack([exp.arrays["a"], v, np.ones(exp.n), np.tanh(v / (2e-3 * np.abs(v).max()))])
    theta, *_ = np.linalg.lstsq(phi.T, exp.y, rcond=None)
    res = exp.y - theta @ phi
    # without the motion rule the held forces at the dwells are taken for pulses too
    assert np.sum(np.any(detect_events(res, exp.dt) != 0, axis=0)) > 1
    ev = np.asarray(_refresh_events(exp, res).arrays["events"])
    used = np.flatnonzero(np.any(ev != 0, axis=0))
    # one pulse and the level column (all ones) that goes with it
    assert used.tolist() == [0, ev.shape[1] - 1]
    assert np.all(ev[:, -1] == 1.0)
    on = exp.t[ev[:, 0] == 1]
    # located within the detection window (50 ms moving average) of the true pulse
    assert abs(on[0] - t0) < 0.05 and abs(on[-1] - t1) < 0.05


def test_a_switched_load_on_most_of_the_time_is_explained_with_its_level():
    """A load of -35 N switched on for most of the calibration record (so the median the
    events are found against is the loaded level, and the calibrated offset absorbs the
    load) and for a short time in the validation record: with the level between the
    events profiled per record, the external force explains the validation error up to
    the switching edges."""
    n_cal, n_val = 8000, 5000

    def switched(a, b):
        return lambda t: -35.0 if a <= t <= b else 0.0

    cal = _axis(_p2p(n_cal), switched(0.5, 6.5), seed=1)
    val = _axis(_p2p(n_val), switched(2.0, 3.0), seed=2)
    fam = DriveFamily()
    exps, nom, res = _nominal_residual(fam, cal, val)
    # the offset took most of the load: the validation error is load-sized at all times
    assert np.sqrt(np.mean(res[1] ** 2)) > 10.0
    exps = [_refresh_events(e, r) for e, r in zip(exps, res)]
    # the rigid axis recalibrated with the events of the calibration record (least
    # squares; the offset and the level column share one direction: minimum norm)
    c = exps[0]
    ev = c.arrays["events"][:, np.any(c.arrays["events"] != 0, axis=0)]
    phi = np.concatenate([np.stack([c.arrays["a"], c.arrays["v"], np.ones(c.n)], -1), ev], 1)
    theta, *_ = np.linalg.lstsq(phi, c.y, rcond=None)
    nom = RigidNominal(*(jnp.asarray(x) for x in theta[:3]))
    # the plant's own mass and viscous friction (12 kg, 40 N·s/m) within 5 %
    assert abs(float(nom.M) - 12.0) < 0.6 and abs(float(nom.Fv) - 40.0) < 2.0
    ext = ExternalForce()
    for e in exps:
        d = e.jax_arrays()
        before = e.y - np.asarray(nom(d))
        after = e.y - np.asarray(ext.apply(nom(d), d, nom))
        # the plant is linear outside the load: what is left is the noise (0.3 N) and the
        # switching edges the 50 ms detection window misplaces by up to half a window
        # (≤ 12 samples of 35 N per edge, a few % of the record): at least 80 % of the
        # RMS error goes (without the level, the validation's offset error would stay)
        assert np.sqrt(np.mean(after**2)) < 0.2 * np.sqrt(np.mean(before**2))
    # the information criterion counts 3 per event and 1 per level
    dof = ext.extra_dof([e.arrays for e in exps])
    n_events = sum(int(np.sum(np.any(e.arrays["events"][:, :-1] != 0, axis=0))) for e in exps)
    assert n_events >= 2 and dof == 3 * n_events + 2
    # identity without events (the nominal model at zero size)
    d = {**exps[1].jax_arrays(), "events": jnp.zeros_like(exps[1].jax_arrays()["events"])}
    assert np.allclose(np.asarray(ext.apply(nom(d), d, nom)), np.asarray(nom(d)))


def _rest_errors(Fc, Fs, effects):
    """RMS force errors [N] at rest of each effect in `effects` (callables `vmax ->
    effect`) on `_held_axis` with sliding level `Fc` and breakaway `Fs`, with the true
    rigid axis as the nominal model; and the largest change each makes while sliding."""
    exp = DriveFamily().prepare(_held_axis(7200, lambda t: 0.0, Fc=Fc, Fs=Fs), "cal")
    d = exp.jax_arrays()
    nom = RigidNominal(jnp.asarray(12.0), jnp.asarray(40.0), jnp.asarray(3.0))
    y0 = np.asarray(nom(d))
    v = np.abs(exp.arrays["v"])
    vmax = float(v.max())
    # deep rest, 40 ms (the analysis filter's settling) away from any motion
    moving = np.convolve((v > 1e-4 * vmax).astype(float), np.ones(41), mode="same") > 0
    rest = ~moving
    assert rest.mean() > 0.1  # the dwells are a fifth of the record
    out = []
    for make in effects:
        eff = make(vmax)
        y = np.asarray(eff.apply(jnp.asarray(y0), d, nom))
        law = y0 + np.asarray(eff.contribution(d, nom))
        sliding = v > 10 * float(eff.vs)
        out.append(
            (
                float(np.sqrt(np.mean((exp.y - y)[rest] ** 2))),
                float(np.max(np.abs(y - law)[sliding])),
            )
        )
    return out


def test_friction_holds_the_axis_at_rest_up_to_its_static_level():
    """A friction law is set-valued at zero velocity: at rest the axis is held by whatever
    force balances it, up to the static level. With the true levels, the Coulomb effect
    predicts the held forces of a Coulomb plant (all within ±Fc) at rest to the force
    noise (0.3 N white, bound 1 N), and leaves the sliding law untouched (the rest weight
    `exp(−(v/v_s)²)` is below 1e-40 beyond 10 v_s); with a breakaway level above the
    sliding one, only the Stribeck effect (held forces up to ±Fs) does."""

    def coulomb(fc):
        return lambda vmax: CoulombEffect(jnp.array([fc]), jnp.asarray(2e-3 * vmax))

    def stribeck(fc, fs):
        return lambda vmax: StribeckEffect(
            jnp.array([fc, fs]), jnp.asarray(0.02 * vmax), jnp.asarray(2e-3 * vmax)
        )

    def asymmetric(fp, fn):
        return lambda vmax: AsymmetricFrictionEffect(
            jnp.array([fp, fn, 0.0]), jnp.asarray(2e-3 * vmax)
        )

    (c, c_slide), (a, a_slide), (zero, _) = _rest_errors(
        20.0, 20.0, [coulomb(20.0), asymmetric(20.0, 20.0), coulomb(0.0)]
    )
    # the held forces are uniform in ±20 N: 11.5 N RMS when nothing holds the axis
    assert zero > 8.0
    assert c < 1.0 and a < 1.0
    assert c_slide < 1e-6 and a_slide < 1e-6
    (c, _), (s, s_slide) = _rest_errors(20.0, 40.0, [coulomb(20.0), stribeck(20.0, 40.0)])
    # held forces up to ±40 N: beyond ±20 N the Coulomb level cannot hold them
    assert c > 4.0
    assert s < 1.0 and s_slide < 1e-6


def test_pulses_that_follow_each_other_without_a_pause_are_separate_events():
    """Two unmeasured loads that follow each other without a pause (+40 N for 0.25 s, then
    −40 N for 0.3 s, then +25 N stacked on a 15 N load) form one run beyond the detection
    threshold but three levels: each level is its own event, so that one amplitude per
    event can represent them. Oracle: the plateaus written here."""
    dt = 2e-3
    t = np.arange(0, 6.0, dt)
    rng = np.random.default_rng(3)
    res = 0.5 * rng.standard_normal(t.size)
    truth = [(2.0, 2.25, 40.0), (2.25, 2.55, -40.0), (4.0, 4.3, 15.0), (4.3, 4.6, 40.0)]
    for a, b, level in truth:
        res[(t >= a) & (t < b)] += level
    ev = detect_events(res, dt)
    used = np.flatnonzero(np.any(ev != 0, axis=0))
    assert used.size == len(truth)
    spans = sorted((t[ev[:, k] == 1][0], t[ev[:, k] == 1][-1]) for k in used)
    for (a, b, _), (s, e) in zip(truth, spans):
        # each boundary within half the 50 ms detection window: the split is at the mean
        # shift of the raw residual, the outer ends are where the 50 ms average crosses
        assert abs(s - a) <= 0.025 + dt and abs(e - (b - dt)) <= 0.025 + dt
    # one amplitude per event reproduces each plateau: the outer end of an event may reach
    # half a window (25 ms) beyond the force, diluting its mean by at most 25 ms over the
    # plateau's duration, plus the noise (0.5 N white over ≥ 125 samples: 0.2 N is 4
    # standard errors); without the split, +40 and −40 N would share one amplitude near 0
    amp, *_ = np.linalg.lstsq(ev[:, used], res, rcond=None)
    for (a, b, level), got in zip(truth, amp):
        assert abs(got - level) <= abs(level) * 0.025 / (b - a) + 0.2
    # an event without a level step stays whole
    one = 0.5 * rng.standard_normal(t.size)
    one[(t >= 1.0) & (t < 1.5)] += 30.0
    assert int(np.sum(np.any(detect_events(one, dt) != 0, axis=0))) == 1


def test_a_force_that_follows_the_command_is_not_an_external_force():
    """A motor force that sags by 10 % for 1.5 s (a supply dip) leaves the command's own
    shape in the residual, `0.1 u`: it is found in pieces beyond the threshold, like pulses,
    but within each piece it is a multiple of the command, not a level, so the record
    has no external-force events. A 25 N load switched on during a move (same command)
    keeps its event. Oracle: closed-form commands and residuals."""
    rng = np.random.default_rng(4)
    dt = 1e-3
    t = np.arange(8000) * dt
    v = 0.3 * np.sin(2 * np.pi * 0.6 * t) + 0.1 * np.sin(2 * np.pi * 1.7 * t)
    a = np.gradient(v, dt)
    u = 40.0 * a + 80.0 * v + 30.0 * np.tanh(v / 0.01)
    noise = 0.3 * rng.standard_normal(t.size)
    cases = {
        "gain": 0.1 * u * ((t > 3.0) & (t < 4.5)) + noise,
        "load": np.where((t > 4.2) & (t < 4.6), 25.0, 0.0) + noise,
    }
    for name, res in cases.items():
        exp = Experiment(
            "x", t, {"y": u, "v": v, "a": a, "q": np.cumsum(v) * dt}, {}, {}, 0.09, frozenset()
        )
        found = detect_events(res, dt)
        assert np.any(found != 0)  # pieces beyond the threshold in both
        ev = np.asarray(_refresh_events(exp, res).arrays["events"])
        used = np.flatnonzero(np.any(ev != 0, axis=0))
        if name == "gain":
            assert follows_command(found, res, u)
            assert used.size == 0
        else:
            assert not follows_command(found, res, u)
            assert used.tolist() == [0, ev.shape[1] - 1]
