"""Generate the figures of the docs page "Reading a verdict" (`docs/guides/verdict.md`).

- `docs/img/verdict_states.png`: the four verdict states on the spindle thermal twin
  (12 h at 5 s): effect-free (`adequate`), a hidden heat capacity (`explained`), a
  thermocouple that starts drifting in the last quarter of the record -- an effect in no
  library -- (`unexplained`) and both at once (`partly_explained`); each panel is
  `jaxvs.plotting.plot_verdict`.
- `docs/img/verdict_floor.png`: the noise floor a nonlinearity cannot hide in: the best
  linear approximation of a static cubic `y = u + 0.05 u³` under 16 random-phase
  multisines of 4 periods each, with noise, by `jaxvs.signal.best_linear_approximation`
  (`jaxvs.plotting.plot_bla`): the noise from period to period, the distortion from
  realisation to realisation, the output at the lines the excitation leaves empty.

Usage (from the repository root): `python docs/gen_verdict_figures.py`; prints each
diagnosis' status line.
"""

from __future__ import annotations

import pathlib

import jax

jax.config.update("jax_enable_x64", True)

import jax.random as jr  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.data import Record  # noqa: E402
from jaxvs.plotting import plot_bla, plot_verdict  # noqa: E402
from jaxvs.twins import SpindleThermalTwin  # noqa: E402

IMG = pathlib.Path(__file__).parent / "img"
HOURS = 3600.0


def drifting(rec: Record, kelvin: float) -> Record:
    """The record with its bearing thermocouple drifting by `kelvin` over its last
    quarter (quadratically from where the drift starts)."""
    sig = {k: np.asarray(rec[k]) for k in rec.names}
    s = np.clip((np.linspace(0.0, 1.0, len(rec)) - 0.75) / 0.25, 0.0, 1.0)
    sig["T_bearing"] = sig["T_bearing"] + kelvin * s**2
    return Record(sig, dt=rec.dt, metadata=rec.metadata)


def states() -> None:
    def twin(effects):
        return SpindleThermalTwin(effects=effects).experiment(jr.key(11), duration=12 * HOURS)

    cases = [
        ("effect-free", twin({})),
        ("hidden heat capacity", twin({"dynamics": 600.0})),
        ("thermocouple drift (in no library)", drifting(twin({}), 1.0)),
        ("heat capacity and drift", drifting(twin({"dynamics": 600.0}), 1.0)),
    ]
    fig, axs = plt.subplots(4, 1, figsize=(7.5, 9.5))
    for ax, (label, rec) in zip(axs, cases):
        rep = jaxvs.diagnose(rec, family="thermal")
        print(f"{label}: {rep.status_line}")
        plot_verdict(rep, ax=ax, title=f"{label}: {rep.status.replace('_', ' ')}")
    fig.tight_layout()
    fig.savefig(IMG / "verdict_states.png", dpi=110)
    plt.close(fig)


def floor() -> None:
    rng = np.random.default_rng(0)
    n, lines, periods, m = 256, 24, 4, 16
    t, k = np.arange(n), np.arange(1, lines + 1)
    u, y = [], []
    for _ in range(m):
        one = (0.5 * np.cos(2 * np.pi * np.outer(t, k) / n + rng.uniform(0, 6.3, lines))).sum(1)
        per = np.tile(one, (periods, 1))
        u.append(per)
        y.append(per + 0.05 * per**3 + 0.05 * rng.standard_normal(per.shape))
    bla = jaxvs.signal.best_linear_approximation(np.array(u), np.array(y))
    fig, ax = plt.subplots(figsize=(7.5, 4))
    plot_bla(bla, ax=ax)
    fig.tight_layout()
    fig.savefig(IMG / "verdict_floor.png", dpi=110)
    plt.close(fig)
    print(f"BLA: noise {bla.noise_level:.4f}, distortion {bla.distortion_level:.4f}")


if __name__ == "__main__":
    import sys

    if "--states-only" not in sys.argv:
        floor()
    if "--floor-only" not in sys.argv:
        states()
