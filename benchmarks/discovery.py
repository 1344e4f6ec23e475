"""Discovery on drive plants whose extra force is outside the effect library.

Each plant is a carriage (mass 10 kg, viscous 60 N·s/m, offset 2 N) in a continuous PD
position loop (15 Hz), integrated by scipy's `solve_ivp` (no jaxvs model makes the data),
recorded at 1 kHz for 25 s (25 000 samples) with 0.5 N of force noise and a 1 µm encoder;
the last 30 % is held out. Discovery runs on the calibrated rigid axis (what the named
search leaves when no library effect is accepted) with 19 null records.

| case | extra force | in the dictionary |
|---|---|---|
| `viscous-decay` | `40·v·exp(−t/8)` (lubricant warming up) | yes |
| `ripple` | `6·sin(2πq/0.012)` (a position ripple: `position_dependence`) | yes (named) |
| `stribeck-like` | `8·exp(−(v/0.01)²)·sign(v)` (friction falling with speed) | yes (named) |
| `bump` | `15·exp(−((q − 0.01)/0.006)²)` (a local guideway bump) | no |
| `none` | — | — |

    python benchmarks/discovery.py [--only NAME,...] [--figure PATH]
    python benchmarks/discovery.py --emps [--data DIR] [--figure PATH]

Prints per case: fired, the input found, the formula, found / named instead, the
coefficients, the CPU seconds of discovery (compilation included) and the load average.
`--figure` writes the figure of the first case.

`--emps` runs discovery on the real EMPS records (calibrate on `DATA_EMPS.mat`, validate
on `DATA_EMPS_PULSES.mat`) after the named search has added Coulomb and asymmetric
friction (`max_effects=2`, as the EMPS description's models), and prints what it says;
`--emps-official` then asks whether the discovered terms help the official EMPS task
(free-run position from the force, `benchmarks/emps_official.py`): the asymmetric
friction model with and without them, each calibrated on the training file by the same
free-run output error and scored on the test file.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy.integrate as si  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.data import Record, split_blocks  # noqa: E402
from jaxvs.diagnosis import GapModel, discover  # noqa: E402
from jaxvs.diagnosis._drive import DriveFamily  # noqa: E402

FS = 1000.0

CASES = {
    "viscous-decay": lambda t, x, v: 40.0 * math.exp(-t / 8.0) * v,
    "ripple": lambda t, x, v: 6.0 * math.sin(2 * math.pi * x / 0.012),
    "stribeck-like": lambda t, x, v: 8.0 * math.exp(-((v / 0.01) ** 2)) * math.tanh(v / 1e-4),
    "bump": lambda t, x, v: 15.0 * math.exp(-(((x - 0.01) / 0.006) ** 2)),
    "none": lambda t, x, v: 0.0,
}


def _ref(t):
    w = 2 * np.pi * np.array([0.23, 0.61, 1.37])
    amp, ph = 0.05 * np.array([0.6, 0.3, 0.1]), np.array([0.0, 1.0, 2.0])
    arg = np.outer(t, w) + ph
    return (amp * np.sin(arg)).sum(-1), (amp * w * np.cos(arg)).sum(-1)


def plant(extra, n=25000, M=10.0, Fv=60.0, off=2.0, noise=0.5, seed=0) -> Record:
    rng = np.random.default_rng(seed)
    wn = 2 * np.pi * 15
    kp, kd = M * wn**2, 2 * 0.7 * M * wn

    def rhs(t, s):
        r, dr = _ref(np.array([t]))
        u = kp * (r[0] - s[0]) + kd * (dr[0] - s[1])
        return [s[1], (u - Fv * s[1] - off - extra(t, s[0], s[1])) / M]

    t = np.arange(n) / FS
    r0, dr0 = _ref(np.zeros(1))
    sol = si.solve_ivp(
        rhs, (0, t[-1]), [r0[0], dr0[0]], t_eval=t, rtol=1e-8, atol=1e-11, max_step=2e-3
    )
    x, v = sol.y
    r, dr = _ref(t)
    u = kp * (r - x) + kd * (dr - v) + noise * rng.normal(size=n)
    return Record({"q": np.round(x / 1e-6) * 1e-6, "u": u}, dt=1 / FS)


def run(name: str):
    a, b = split_blocks(plant(CASES[name]), (0.7, 0.3))
    fam = DriveFamily()
    cal, val = [fam.prepare(a, "cal")], [fam.prepare(b, "val")]
    c0 = time.process_time()
    d = discover(GapModel(fam.nominal(cal)), cal, val, family=fam, n_null=19)
    return d, time.process_time() - c0


EMPS_DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "EMPS"


def emps(data: Path, figure: str = ""):
    """Discovery on the real EMPS records after Coulomb and asymmetric friction."""
    c0 = time.process_time()
    rep = jaxvs.diagnose(
        data / "DATA_EMPS.mat",
        data / "DATA_EMPS_PULSES.mat",
        family="drive",
        max_effects=2,
        discover=False,
    )
    c1 = time.process_time()
    v = rep.verdict
    print(f"== EMPS: named search {v['effects']} status {v['status']}")
    print(
        f"   gap {rep.gap['validation']:.4g} -> {v['validation_gap']:.4g}, "
        f"floor {rep.gap.get('noise_floor')}; CPU {c1 - c0:.1f} s"
    )
    d = discover(rep)
    cpu = time.process_time() - c1
    _print(d)
    print(f"   discovery CPU {cpu:.1f} s, load average {os.getloadavg()}")
    for lab, fig in d.inputs.items():
        print(f"   flexible in {lab}: reduction {fig['reduction']:.4g} shrink {fig['shrink']:.3f}")
    print(f"   null threshold {d.flexible['null_threshold']:.4g}")
    if figure and d.fired:
        _figure(d, figure)
    return rep, d


def emps_official(data: Path, d) -> None:
    """The official EMPS task with the discovered velocity and position terms added to
    the asymmetric friction model, against that model alone (same calibration)."""
    import equinox as eqx
    import jax.numpy as jnp
    from emps_official import N0, _asym, _axis, _feasible

    from jaxvs.models import AbstractFriction
    from jaxvs.studies.benchmarks import EMPS, PositionForce, fit_multiple_shooting

    kinds = {tm["kind"]: tm for tm in d.terms}
    c_sqrt = kinds.get("sqrt|v|·sign(v)", {"coefficients": [0.0]})["coefficients"][0]

    class SqrtVelocityFriction(AbstractFriction):
        """Asymmetric friction plus the discovered `c·sign(v)·√|v|` (smoothed below
        0.1 mm/s: `c·v/√(|v| + 1e-4)`)."""

        base: AbstractFriction
        c: jnp.ndarray

        def __call__(self, velocity):
            v = jnp.asarray(velocity)
            return self.base(v) + self.c * v / jnp.sqrt(jnp.abs(v) + 1e-4)

    tr = EMPS.load(data)
    u, y = EMPS.arrays(tr.train[0])
    ut, yt = EMPS.arrays(tr.test[0])
    q = np.asarray(y)[:, 0]
    # the discovered ripple as a smooth position force over the stroke (Legendre series,
    # order 4, least squares on the discovered sin/cos, then calibrated)
    centre, half = float((q.max() + q.min()) / 2), float((q.max() - q.min()) / 2)
    pos = None
    if "ripple" in kinds:
        rp = kinds["ripple"]
        a, b = rp["coefficients"]
        ph = 2 * np.pi * q / rp["shape"]["value"]
        target = a * np.sin(ph) + b * np.cos(ph)
        pf = PositionForce(np.zeros(4), centre=centre, half_range=half)
        basis = np.stack(
            [
                np.asarray(PositionForce(np.eye(4)[k], centre=centre, half_range=half)(q))
                for k in range(4)
            ],
            -1,
        )
        coef = np.linalg.lstsq(basis, target - target.mean(), rcond=None)[0]
        pos = eqx.tree_at(lambda p: p.coefficients, pf, jnp.asarray(coef))
    from jaxvs.studies.benchmarks import OpenLoopAxis

    cands = {
        "asymmetric (eq. 12)": _axis(_asym()),
        "asymmetric + discovered c·sign(v)·√|v|": _axis(
            SqrtVelocityFriction(_asym(), jnp.asarray(0.0))
        ),
    }
    if pos is not None:
        m = _axis(SqrtVelocityFriction(_asym(), jnp.asarray(0.0)))
        cands["asymmetric + discovered √|v| and position terms"] = OpenLoopAxis(
            m.mechanics, pos, sample_time=m.sample_time, n_substeps=m.n_substeps
        )
    print(f"   EMPS official task (discovered c = {c_sqrt:.4g} N/√(m/s) as a start of 0):")
    for name, model in cands.items():
        c0 = time.process_time()
        fit = fit_multiple_shooting(
            model,
            u,
            y,
            segment_length=len(u) - N0,
            init_window=N0,
            output_scale=1e-3,
            free_states=False,
            feasible=_feasible,
            max_steps=15,
            throw=False,
        )
        rm = []
        for uu, yy in ((u, y), (ut, yt)):
            yh = np.asarray(fit.model(uu, yy[:N0]))[:, 0]
            e = (yh - np.asarray(yy)[:, 0])[N0:]
            rm.append(float(1e3 * np.sqrt(np.mean(e**2))))
        print(
            f"   {name}: train {rm[0]:.2f} mm, test {rm[1]:.2f} mm "
            f"({time.process_time() - c0:.0f} s CPU, load {os.getloadavg()[0]:.1f})",
            flush=True,
        )


def _print(d) -> None:
    print(
        f"   fired={d.fired} input={d.input} found={d.found} "
        f"named_instead={d.named_instead} ({d.nearest_effect})"
    )
    print(f"   formula: {d.formula}; shrink {d.shrink} {d.shrink_interval} share {d.share}")
    for tm in d.terms:
        print(
            f"   {tm['kind']}: {tm['coefficients']} {tm['intervals']} {tm.get('shape', '')} "
            f"freq {tm['frequency']:.2f}"
        )
    print(f"   frequencies {d.frequencies}")
    print(f"   {d.message}")


def _figure(d, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from jaxvs.plotting import plot_discovered

    ax = plot_discovered(d)
    ax.figure.tight_layout()
    ax.figure.savefig(path, dpi=110)
    print(f"   figure: {path}")


# ------------------------------------------------------------------------------ blind table
#
# Out-of-library cases per family whose true term is in the dictionary, cases whose true
# term is not, effect-free cases and cases of a library effect. Every plant's term is
# written here by hand (numpy), never through the dictionary's functions.

TH_DT, TH_SMAX = 10.0, 12000.0


def drive_plant(extra, n=25000, M=10.0, Fv=60.0, off=2.0, noise=0.5, seed=0) -> Record:
    """The carriage in the PD loop by a fourth-order Runge–Kutta at 1 kHz (`extra(t, x,
    v)` [N] opposes the motion), 0.5 N force noise, 1 µm encoder."""
    rng = np.random.default_rng(seed)
    h = 1 / FS
    wn = 2 * np.pi * 15
    kp, kd = M * wn**2, 2 * 0.7 * M * wn
    tt = np.arange(2 * n + 1) * (h / 2)
    r, dr = _ref(tt)

    def f(s, k, ti):
        u = kp * (r[k] - s[0]) + kd * (dr[k] - s[1])
        return np.array([s[1], (u - Fv * s[1] - off - extra(ti, s[0], s[1])) / M])

    out = np.zeros((n, 2))
    s = np.array([r[0], dr[0]])
    for k in range(n):
        out[k] = s
        ti = k * h
        k1 = f(s, 2 * k, ti)
        k2 = f(s + h / 2 * k1, 2 * k + 1, ti + h / 2)
        k3 = f(s + h / 2 * k2, 2 * k + 1, ti + h / 2)
        k4 = f(s + h * k3, 2 * k + 2, ti + h)
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    x, v = out.T
    u = kp * (r[::2][:n] - x) + kd * (dr[::2][:n] - v) + noise * rng.normal(size=n)
    return Record({"q": np.round(x / 1e-6) * 1e-6, "u": u}, dt=h)


def _speed(t):
    levels = np.array([6000, 6000, 12000, 3000, 9000, 0, 12000, 4500, 7500], float)
    k = np.minimum((t // 5400).astype(int), levels.size - 2)
    ramp = np.clip((t - 5400 * k) / 300.0, 0.0, 1.0)
    return levels[k] + ramp * (levels[k + 1] - levels[k])


def thermal_plant(heat=None, sensor=None, n=4320, noise=0.02, seed=0) -> Record:
    """Two-node spindle (chassis τ = 40 min, bearing lag τ = 10 min) by `solve_ivp`,
    12 h at 10 s; `heat(t, s)` [K] into the bearing node, `sensor(t)` [K] on its sensor."""
    rng = np.random.default_rng(seed)
    heat = heat or (lambda t, s: 0.0)
    sensor = sensor or (lambda t: 0.0)

    def air(t):
        return 20.0 + 1.0 * np.sin(2 * np.pi * t / 14400.0 + 0.3)

    def rhs(t, x):
        s = _speed(np.array([t]))[0]
        tc, tb = x
        static = 2.0 + tc + 6.0 * s / TH_SMAX + heat(t, s)
        return [(air(t) + 8.0 * s / TH_SMAX - tc) / 2400.0, (static - tb) / 600.0]

    t = np.arange(n) * TH_DT
    s0 = _speed(np.zeros(1))[0]
    tc0 = air(0.0) + 8.0 * s0 / TH_SMAX
    x0 = [tc0, 2.0 + tc0 + 6.0 * s0 / TH_SMAX + heat(0.0, s0)]
    sol = si.solve_ivp(rhs, (0, t[-1]), x0, t_eval=t, rtol=1e-9, atol=1e-9, max_step=TH_DT)
    tc, tb = sol.y
    tb = tb + np.array([sensor(x) for x in t])
    return Record(
        {
            "T_chassis": tc + noise * rng.normal(size=n),
            "T_bearing": tb + noise * rng.normal(size=n),
            "v_m": _speed(t),
            "T_air": air(t) + noise * rng.normal(size=n),
        },
        dt=TH_DT,
    )


def tmf_plant(extra, n, seed, sigma=2e-8, dt=1e-3) -> Record:
    """A random-phase multisine (1–80 Hz, 1 mm rms, amplitude modulated over 3 s, from
    rest) through a 40 Hz mode (ζ = 0.05, zero-order hold, `lfilter`); `extra(x_e, ẋ_e,
    x_t)` is the unknown part of the tool-side motion; white noise `sigma`."""
    import scipy.signal as ss

    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    k = np.arange(1, 80)
    xe = np.sum(np.cos(2 * np.pi * np.outer(t, k) + rng.uniform(0, 2 * np.pi, k.size)), 1)
    xe = 1e-3 * xe / np.std(xe) * (0.6 + 0.4 * np.sin(2 * np.pi * t / 3.0))
    xe = xe * np.clip(t / 0.2, 0, 1) ** 2
    om, z = 2 * np.pi * 40.0, 0.05
    b, a, _ = ss.cont2discrete(([om * om], [1, 2 * z * om, om * om]), dt, method="zoh")
    xt = ss.lfilter(np.ravel(b), a, xe)
    xt = xt + extra(xe, np.gradient(xe, dt), xt) + sigma * rng.standard_normal(n)
    return Record({"x_e": xe, "x_t": xt}, dt=dt)


# case: (family, plant keywords, truth) with truth None (effect-free), "named:<effect>"
# (a library effect), "not in dictionary", or (kinds, coefficient, shape, point, value):
# the kinds of the exact support, the coefficient and shape of its first term, or a
# point of the slot's inputs where the formula must equal `value` (coefficient error
# from the formula's value there)
BLIND = {
    "drive: viscous friction fading (40·v·e^(−t/8 s))": (
        "drive",
        dict(extra=lambda t, x, v: 40.0 * math.exp(-t / 8.0) * v),
        (["v·exp(-t/tau)"], 40.0, 8.0, None, None),
    ),
    "drive: quadratic drag (800·v·|v|)": (
        "drive",
        dict(extra=lambda t, x, v: 800.0 * v * abs(v)),
        (["v|v|"], 800.0, None, None, None),
    ),
    "drive: square-root friction (20·sign(v)·√|v|)": (
        "drive",
        dict(extra=lambda t, x, v: 20.0 * math.copysign(math.sqrt(abs(v)), v)),
        (["sqrt|v|·sign(v)"], 20.0, None, None, None),
    ),
    "drive: guideway bump (Gaussian in q)": (
        "drive",
        dict(extra=lambda t, x, v: 15.0 * math.exp(-(((x - 0.01) / 0.006) ** 2))),
        "not in dictionary",
    ),
    "drive: position ripple (library)": (
        "drive",
        dict(extra=lambda t, x, v: 6.0 * math.sin(2 * math.pi * x / 0.012)),
        "named:position_dependence",
    ),
    "drive: none (seed 1)": ("drive", dict(extra=lambda t, x, v: 0.0, seed=1), None),
    "drive: none (seed 2)": ("drive", dict(extra=lambda t, x, v: 0.0, seed=2), None),
    "thermal: running-in heat (3·s/12000·e^(−t/3 h))": (
        "thermal",
        dict(heat=lambda t, s: 3.0 * s / TH_SMAX * math.exp(-t / 10800.0)),
        (["(s/smax)·exp(-t/tau)"], 3.0, 10800.0, None, None),
    ),
    "thermal: settling thermocouple (0.8·e^(−t/2 h))": (
        "thermal",
        dict(sensor=lambda t: 0.8 * math.exp(-t / 7200.0)),
        (["exp(-t/tau)"], 0.8, 7200.0, None, None),
    ),
    "thermal: sensor drift (0.6 K over 12 h)": (
        "thermal",
        dict(sensor=lambda t: 0.6 * t / 43200.0),
        (["t"], 0.6 / 43200.0, None, None, None),
    ),
    "thermal: periodic sensor error (0.3·sin(2πt/5 h))": (
        "thermal",
        dict(sensor=lambda t: 0.3 * math.sin(2 * math.pi * t / 18000.0)),
        "not in dictionary",
    ),
    "thermal: quadratic friction heat (library)": (
        "thermal",
        dict(heat=lambda t, s: 4.0 * (s / TH_SMAX) ** 2),
        "named:speed_nonlinearity",
    ),
    "thermal: none (seed 1)": ("thermal", dict(seed=1), None),
    "thermal: none (seed 2)": ("thermal", dict(seed=2), None),
    "tmf: stiffening transmission (2e-5·(x_e/1 mm)³)": (
        "tmf",
        dict(extra=lambda xe, xd, xt: 2e-5 * (xe / 1e-3) ** 3),
        (["(x_e/xmax)^3"], None, None, {"x_e": 1e-3}, 2e-5),
    ),
    "tmf: lost motion (3 µm·tanh(ẋ_e/10 mm/s))": (
        "tmf",
        dict(extra=lambda xe, xd, xt: 3e-6 * np.tanh(xd / 0.01)),
        (["tanh(xdot_e/v0)"], 3e-6, 0.01, None, None),
    ),
    "tmf: clipped tool sensor (±2 mm)": (
        "tmf",
        dict(extra=lambda xe, xd, xt: np.clip(xt, -2e-3, 2e-3) - xt),
        (["xhat-clip(xhat)"], -1.0, 2e-3, None, None),
    ),
    "tmf: encoder-periodic error (20 µm·sin(x_e/0.3 mm))": (
        "tmf",
        dict(extra=lambda xe, xd, xt: 2e-5 * np.sin(xe / 3e-4)),
        "not in dictionary",
    ),
    "tmf: none (seed 1)": ("tmf", dict(extra=lambda xe, xd, xt: 0.0 * xe, seed=1), None),
    "tmf: none (seed 2)": ("tmf", dict(extra=lambda xe, xd, xt: 0.0 * xe, seed=2), None),
}


def _blind_data(family, kw):
    """`(family instance, model, calibration, validation)` of a blind case."""
    from jaxvs.diagnosis._thermal import Dynamics, ThermalFamily
    from jaxvs.diagnosis._tmf import TMFFamily

    if family == "tmf":
        seed = kw.get("seed", 0)
        fam = TMFFamily(order=2)
        cal = [fam.prepare(tmf_plant(kw["extra"], 17500, 10 * seed), "cal")]
        val = [fam.prepare(tmf_plant(kw["extra"], 7500, 10 * seed + 1), "val")]
        return fam, GapModel(fam.nominal(cal)), cal, val
    rec = drive_plant(**kw) if family == "drive" else thermal_plant(**kw)
    a, b = split_blocks(rec, (0.7, 0.3))
    fam = DriveFamily() if family == "drive" else ThermalFamily()
    cal, val = [fam.prepare(a, "cal")], [fam.prepare(b, "val")]
    if family == "thermal":
        # the model the named search leaves: the static regression with the bearing's lag
        return (
            fam,
            GapModel(fam.nominal(cal), (Dynamics(jax.numpy.asarray(600.0), TH_DT),)),
            cal,
            val,
        )
    return fam, GapModel(fam.nominal(cal)), cal, val


def _score(d, truth) -> dict:
    """The case's answer against its truth."""
    out = {"fired": d.fired, "found": d.found, "named": d.named_instead, "formula": d.formula}
    kinds = [tm["kind"] for tm in d.terms]
    new_formula = d.found and not d.named_instead
    if truth is None:
        out["ok"] = not new_formula
    elif isinstance(truth, str) and truth.startswith("named:"):
        out["ok"] = not new_formula
    elif truth == "not in dictionary":
        out["ok"] = not d.found and d.fired and d.shape.get("x") is not None
    else:
        want, coef, shape, point, value = truth
        out["ok"] = new_formula and sorted(kinds) == sorted(want)
        if out["ok"]:
            tm = d.terms[0]
            if point is not None:
                sym = {str(s): s for s in d.expression.free_symbols}
                got = float(d.expression.subs({sym[k]: v for k, v in point.items()}))
                out["coef_err"] = abs(got / value - 1)
            else:
                out["coef_err"] = abs(tm["coefficients"][0] / coef - 1)
            if shape is not None:
                out["shape_err"] = abs(tm["shape"]["value"] / shape - 1)
    return out


def blind(only: str = "") -> None:
    print(f"load average at start {os.getloadavg()}", flush=True)
    rows = []
    for name, (family, kw, truth) in BLIND.items():
        if only and not any(o in name for o in only.split(",")):
            continue
        fam, model, cal, val = _blind_data(family, kw)
        n = sum(e.n for e in cal + val)
        c0 = time.process_time()
        d = discover(model, cal, val, family=fam, n_null=19 if family != "tmf" else 9)
        cpu = time.process_time() - c0
        s = _score(d, truth)
        s.update(case=name, family=family, truth=truth, cpu=cpu, n=n, load=os.getloadavg()[0])
        rows.append(s)
        ce = f"{s['coef_err']:.1%}" if "coef_err" in s else "–"
        se = f"{s['shape_err']:.1%}" if "shape_err" in s else "–"
        tru = truth if isinstance(truth, str) or truth is None else "in dictionary"
        named = f" (named instead: {d.nearest_effect})" if d.found and d.named_instead else ""
        print(
            f"| {name} | {tru} | {d.input if d.fired else 'does not fire'} | "
            f"{d.formula if d.found else ('no formula found' if d.fired else '–')}"
            f"{named} | "
            f"{'yes' if s['ok'] else 'no'} | {ce} | {se} | {cpu:.1f} s ({n} samples, load "
            f"{s['load']:.1f}) |",
            flush=True,
        )
        if d.rival is not None:
            print(f"   rival: {d.rival}", flush=True)
    print(f"load average at end {os.getloadavg()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="")
    ap.add_argument("--figure", default="")
    ap.add_argument("--emps", action="store_true")
    ap.add_argument("--emps-official", action="store_true")
    ap.add_argument("--data", default=str(EMPS_DATA))
    ap.add_argument("--blind", action="store_true")
    args = ap.parse_args()
    if args.blind:
        blind(args.only)
        return
    if args.emps or args.emps_official:
        _, d = emps(Path(args.data), args.figure)
        if args.emps_official and d.found:
            emps_official(Path(args.data), d)
        return
    names = [n for n in CASES if not args.only or n in args.only.split(",")]
    for i, name in enumerate(names):
        d, cpu = run(name)
        print(f"== {name}")
        _print(d)
        print(f"   discovery CPU {cpu:.1f} s, load average {os.getloadavg()}")
        if args.figure and i == 0 and d.fired:
            _figure(d, args.figure)


if __name__ == "__main__":
    main()
