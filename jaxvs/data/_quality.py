"""Signal quality before any calibration: constant signals, clipping or saturation, and
the quantisation level (used by `jaxvs.check`, and by `jaxvs.diagnose` and `jaxvs.design`
through it or directly)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

__all__ = ["signal_quality"]

# heuristics, each documented where it is used
_CLIP_SHARE = 0.01
_CLIP_RUN = 3
_QUANT_SHARE = 0.05
_HELD_SHARE = 0.9


def _clipped_share(x: np.ndarray) -> float:
    """Share of samples in runs of >= 3 equal samples at the signal's minimum or maximum.

    Heuristic: a saturated sensor or amplifier sits at its limit for consecutive samples,
    a signal that merely touches its extreme does not.
    """
    span = float(np.ptp(x))
    if span == 0:
        return 1.0
    tol = 1e-9 * span
    share = 0
    for level in (x.min(), x.max()):
        at = np.abs(x - level) <= tol
        # lengths of the runs of consecutive True
        edges = np.diff(np.concatenate([[0], at.astype(int), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        runs = stops - starts
        share += int(runs[runs >= _CLIP_RUN].sum())
    return share / x.size


def _quantisation_step(x: np.ndarray) -> float:
    """The smallest positive difference between distinct sample values (the resolution
    when the signal was quantised, else a tiny number)."""
    levels = np.unique(x)
    if levels.size < 2:
        return 0.0
    return float(np.min(np.diff(levels)))


def _held_share(x: np.ndarray) -> float:
    """Share of the samples strictly between the signal's extremes that repeat their
    predecessor (1 for a two-level signal). A clipped signal varies between its
    plateaus (small share); a held set-point does not (share near 1)."""
    inner = (x[1:] > x.min()) & (x[1:] < x.max())
    if inner.sum() < 10:
        return 1.0
    return float(np.mean(x[1:][inner] == x[:-1][inner]))


def signal_quality(
    signals: Mapping[str, Any], *, name: str = "record", required: Iterable[str] = ()
) -> tuple[dict[str, dict[str, float]], list[str], list[str]]:
    """Constant signals, clipping and quantisation of the signals of one record.

    **Arguments:**

    - `signals`: signal name -> `(time,)` samples (NaN samples, e.g. of a sparse target
      between its measurements, are left out).
    - `name`: the record's name, used in the findings.
    - `required`: the signals without which the record is useless; one of them being
      constant is blocking, any other constant signal a warning.

    **Returns:**

    `(summary, blocking, warnings)`: per signal its `clipped_share` (share of samples in
    runs of 3 or more at the minimum or maximum), `quantisation_step` (smallest step
    between distinct values, in the signal's unit) and `quantisation_step_over_std`;
    the blocking findings and the warnings as sentences that say what to do.
    """
    required = set(required)
    summary: dict[str, dict[str, float]] = {}
    blocking: list[str] = []
    warnings: list[str] = []
    for sig, values in signals.items():
        x = np.asarray(values, float).reshape(-1)
        x = x[np.isfinite(x)]
        if x.size == 0:
            blocking.append(f"{name}: signal {sig!r} has no finite sample.")
            continue
        std = float(np.std(x))
        clipped = _clipped_share(x)
        step = _quantisation_step(x)
        ratio = step / std if std > 0 else math.inf
        held = _held_share(x)
        summary[sig] = {
            "clipped_share": clipped,
            "quantisation_step": step,
            "quantisation_step_over_std": ratio,
            "held_share": held,
        }
        if std == 0:
            (blocking if sig in required else warnings).append(
                f"{name}: signal {sig!r} is constant; it carries no information."
            )
            continue
        if held > _HELD_SHARE:
            # heuristic: a set-point held between steps (a speed profile of operating
            # points, a bang-bang input) repeats its previous sample almost always, also
            # between its extremes; its few levels and its plateaus at the extremes are
            # the design of the experiment, not clipping or a coarse sensor
            continue
        if clipped > _CLIP_SHARE:
            warnings.append(
                f"{name}: {100 * clipped:.1f} % of {sig!r} sits at its minimum or maximum for "
                "3+ samples (clipping or saturation); exclude those stretches or reduce the "
                "excitation."
            )
        if ratio > _QUANT_SHARE:
            warnings.append(
                f"{name}: {sig!r} is quantised coarsely (step {step:.3g} = {ratio:.2f} of its "
                "standard deviation); raise the excitation or the sensor resolution."
            )
    return summary, blocking, warnings
