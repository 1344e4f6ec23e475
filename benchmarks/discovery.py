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

Prints per case: fired, the input found, the formula, found / named instead, the
coefficients, the CPU seconds of discovery (compilation included) and the load average.
`--figure` writes the figure of the first case.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import scipy.integrate as si  # noqa: E402

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="")
    ap.add_argument("--figure", default="")
    args = ap.parse_args()
    names = [n for n in CASES if not args.only or n in args.only.split(",")]
    for i, name in enumerate(names):
        d, cpu = run(name)
        print(
            f"== {name}: fired={d.fired} input={d.input} found={d.found} "
            f"named_instead={d.named_instead} ({d.nearest_effect})"
        )
        print(f"   formula: {d.formula}; shrink {d.shrink} share {d.share}")
        for tm in d.terms:
            print(
                f"   {tm['kind']}: {tm['coefficients']} {tm.get('shape', '')} "
                f"freq {tm['frequency']:.2f}"
            )
        print(f"   {d.message}")
        print(f"   discovery CPU {cpu:.1f} s, load average {os.getloadavg()}")
        if args.figure and i == 0 and d.fired:
            import matplotlib

            matplotlib.use("Agg")
            from jaxvs.plotting import plot_discovered

            ax = plot_discovered(d)
            ax.figure.tight_layout()
            ax.figure.savefig(args.figure, dpi=110)
            print(f"   figure: {args.figure}")


if __name__ == "__main__":
    main()
