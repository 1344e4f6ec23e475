"""The next experiment: an excitation that tells two formulas apart.

When discovery's selection leaves two formulas within an evidence ratio of 10 on the
records (the kept support and its best rival: the support with one term swapped for a
term of another kind), the records cannot decide between them. Each formula is fitted
to the records' residual with the model's Jacobian beside it (the linearised joint
calibration of the selection); both then predict the model's output on candidate
excitations, and the candidate whose predictions differ most (the mean squared
difference) is proposed.

The candidates stay within the family's limits taken from the records: the travel (the
range of the position, or of the encoder motion), the largest speed, the largest force
(drive: the model's force on the candidate within the largest recorded force), and the
band (from the record's length to a tenth of the sampling rate). Two parametrised
families: sines (amplitude a share of the half travel, frequency on a log grid over the
band, speed within the limit) and trapezoidal moves back and forth over a share of the
travel (cruise speed a share of the largest, acceleration the records' largest). Each
candidate lasts as long as the shortest record (at most 20 s) at the record's sampling
step, and starts at rest at the records' start position.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._base import Experiment

__all__ = ["Limits", "NextExperiment", "candidates", "limits_from"]

# the designed signal of each family: its array key, the CSV column and the unit
_SIGNAL = {"drive": ("q", "q_ref", "m"), "tmf": ("x_e", "x_e_ref", "m")}
DESIGN_FAMILIES = tuple(_SIGNAL)


@dataclasses.dataclass(frozen=True)
class Limits:
    """The family's limits from the records: `travel` (lo, hi) of the designed signal,
    its largest `speed`, largest `acceleration`, the largest recorded `force` (drive;
    `None` otherwise), the `band` (lo, hi) [Hz], the sampling step `dt` and the
    candidates' `duration` [s], and the `start` value of the signal (the records' first
    sample; the candidates are relative to it)."""

    travel: tuple[float, float]
    speed: float
    acceleration: float
    force: float | None
    band: tuple[float, float]
    dt: float
    duration: float
    start: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {
            "travel": [float(x) for x in self.travel],
            "speed": float(self.speed),
            "acceleration": float(self.acceleration),
            "force": None if self.force is None else float(self.force),
            "band_hz": [float(x) for x in self.band],
            "dt": float(self.dt),
            "duration": float(self.duration),
            "start": float(self.start),
        }


def limits_from(family: str, exps: Sequence[Experiment]) -> Limits:
    """The limits of the family `family` (`"drive"`, `"tmf"`) from its slot experiments."""
    key = _SIGNAL[family][0]
    x = np.concatenate([np.asarray(e.arrays[key], float) for e in exps])
    dt = float(exps[0].dt)
    vel = np.concatenate([np.gradient(np.asarray(e.arrays[key], float), dt) for e in exps])
    acc = np.concatenate(
        [np.gradient(np.gradient(np.asarray(e.arrays[key], float), dt), dt) for e in exps]
    )
    duration = min(20.0, min(e.n for e in exps) * dt)
    force = None
    if family == "drive":
        force = float(np.max(np.abs(np.concatenate([e.y for e in exps]))))
    return Limits(
        travel=(float(np.min(x)), float(np.max(x))),
        speed=float(np.max(np.abs(vel))),
        acceleration=float(np.quantile(np.abs(acc), 0.99)),
        force=force,
        band=(2.0 / duration, 0.1 / dt),
        dt=dt,
        duration=duration,
        start=float(np.asarray(exps[0].arrays[key])[0]),
    )


def _sine(lim: Limits, t, amp, freq):
    x = amp * np.sin(2 * np.pi * freq * t)
    # a smooth start from rest over one period (the records start at rest)
    ramp = np.clip(t * freq, 0.0, 1.0)
    return x * ramp * ramp * (3 - 2 * ramp)


def _move(t, dist, speed, acc):
    """Position along a trapezoidal move of `dist` (> 0) at `speed` and acceleration
    `acc` (triangular where the speed is not reached), at times `t` from its start;
    returns the positions and the move's duration."""
    t_acc = speed / acc
    if acc * t_acc**2 > dist:  # triangular
        t_acc = math.sqrt(dist / acc)
        speed = acc * t_acc
    d_acc = 0.5 * acc * t_acc**2
    t_cruise = (dist - 2 * d_acc) / speed
    t_end = 2 * t_acc + t_cruise
    x = np.where(
        t < t_acc,
        0.5 * acc * t**2,
        np.where(
            t < t_acc + t_cruise,
            d_acc + speed * (t - t_acc),
            dist - 0.5 * acc * np.clip(t_end - t, 0, None) ** 2,
        ),
    )
    return np.clip(x, 0.0, dist), t_end


def _trapezoid(lim: Limits, t, amp, speed):
    """From rest at 0 (the start position) to `c + amp`, then back and forth between
    `c − amp` and `c + amp` (`c` the travel's centre), each move trapezoidal at `speed`
    with acceleration `lim.acceleration`."""
    c = 0.5 * (lim.travel[0] + lim.travel[1]) - lim.start
    x = np.zeros_like(t)
    start, pos, target = 0.0, 0.0, c + amp
    while start < t[-1]:
        dist = abs(target - pos)
        rel, dur = _move(t - start, dist, speed, lim.acceleration)
        sel = t >= start
        x[sel] = pos + np.sign(target - pos) * rel[sel]
        start, pos, target = start + dur, target, 2 * c - target
    return x


def candidates(lim: Limits) -> list[tuple[str, dict[str, float], np.ndarray, np.ndarray]]:
    """`(kind, parameters, t, signal)` of every candidate within the limits (the
    signal relative to the records' start position)."""
    n = int(round(lim.duration / lim.dt))
    t = np.arange(n) * lim.dt
    half = 0.5 * (lim.travel[1] - lim.travel[0])
    # sines about the start position: within the travel on both sides of it
    room = min(lim.travel[1] - lim.start, lim.start - lim.travel[0])
    out = []
    for share in (0.25, 0.5, 1.0):
        amp = share * half
        if amp <= 0:
            continue
        for freq in np.geomspace(lim.band[0], lim.band[1], 12):
            w = 2 * np.pi * freq
            a_s = share * room
            # the ramp-in adds up to a quarter of the sine's speed
            if a_s <= 0 or 1.25 * a_s * w > lim.speed or a_s * w * w > 4 * lim.acceleration:
                continue
            out.append(
                (
                    "sine",
                    {"amplitude": a_s, "frequency_hz": float(freq)},
                    t,
                    _sine(lim, t, a_s, freq),
                )
            )
        for vs in (0.25, 0.5, 0.75, 1.0):
            speed = vs * lim.speed
            out.append(
                (
                    "trapezoid",
                    {"amplitude": amp, "speed": speed, "acceleration": lim.acceleration},
                    t,
                    _trapezoid(lim, t, amp, speed),
                )
            )
    return out


@dataclasses.dataclass
class NextExperiment:
    """The proposed excitation.

    - `formulas`: the two formulas it tells apart; `log_evidence_ratio`: their log
        evidence ratio on the records (below `log 10` when designed).
    - `kind`, `parameters`: the candidate family (`"sine"`, `"trapezoid"`) and its
        parameters; `t`, `signal`: the ready-to-run reference (`signal_name`, in m,
        relative to the records' start position; drive: the axis position, tmf: the
        encoder motion).
    - `disagreement`: rms difference of the two formulas' predicted outputs on it;
        `record_disagreement`: the same on the records; `gain`: the ratio of their
        mean squares.
    - `limits`: the limits it was designed within.
    """

    formulas: tuple[str, str]
    log_evidence_ratio: float
    kind: str
    parameters: dict[str, float]
    t: np.ndarray
    signal: np.ndarray
    signal_name: str
    disagreement: float
    record_disagreement: float
    gain: float
    limits: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """The proposal without its arrays (`report.json["discovered"]["next_experiment"]`)."""
        return {
            "formulas": list(self.formulas),
            "log_evidence_ratio": float(self.log_evidence_ratio),
            "kind": self.kind,
            "parameters": {k: float(v) for k, v in self.parameters.items()},
            "signal": self.signal_name,
            "samples": int(self.t.size),
            "disagreement": float(self.disagreement),
            "record_disagreement": float(self.record_disagreement),
            "gain": float(self.gain),
            "limits": self.limits,
        }

    def to_csv(self, path: str | Path) -> Path:
        """Write the reference signal as CSV (`t`, the signal) and return the path."""
        path = Path(path)
        np.savetxt(
            path,
            np.column_stack([self.t, self.signal]),
            delimiter=",",
            header=f"t,{self.signal_name}",
            comments="",
        )
        return path


def design(
    family: str,
    lim: Limits,
    predict: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray] | None],
    record_difference: np.ndarray,
    formulas: tuple[str, str],
    log_ratio: float,
) -> NextExperiment | None:
    """The candidate that maximises the mean squared difference of the two formulas'
    predictions: `predict(t, signal)` returns the two predicted outputs on a candidate
    (or `None` where the candidate breaks a limit the prediction shows, such as the
    force); `record_difference` is their difference on the records."""
    best = None
    for kind, params, t, sig in candidates(lim):
        pair = predict(t, sig)
        if pair is None:
            continue
        score = float(np.mean((pair[0] - pair[1]) ** 2))
        if best is None or score > best[0]:
            best = (score, kind, params, t, sig)
    if best is None:
        return None
    score, kind, params, t, sig = best
    rec = float(np.mean(np.asarray(record_difference) ** 2))
    return NextExperiment(
        formulas=formulas,
        log_evidence_ratio=float(log_ratio),
        kind=kind,
        parameters=params,
        t=t,
        signal=sig,
        signal_name=_SIGNAL[family][1],
        disagreement=math.sqrt(score),
        record_disagreement=math.sqrt(rec),
        gain=score / rec if rec > 0 else float("inf"),
        limits=lim.to_json(),
    )
