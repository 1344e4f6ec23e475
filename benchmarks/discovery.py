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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="")
    ap.add_argument("--figure", default="")
    ap.add_argument("--emps", action="store_true")
    ap.add_argument("--emps-official", action="store_true")
    ap.add_argument("--data", default=str(EMPS_DATA))
    args = ap.parse_args()
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
