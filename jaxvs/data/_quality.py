"""Signal quality before any calibration: constant signals, clipping or saturation, and
the quantisation level (used by `jaxvs.check`, and by `jaxvs.diagnose` and `jaxvs.design`
through it or directly)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

__all__ = ["check_validation", "signal_quality"]

# heuristics, each documented where it is used
_CLIP_SHARE = 0.01
_CLIP_RUN = 3
_QUANT_SHARE = 0.05
_HELD_SHARE = 0.9
_STUCK_SHARE = 0.25  # a frozen sensor: the last (or first) quarter of the record one value
_CLIP_BLOCKING = 0.2  # a fifth of a required signal at its limit: the fit sees the limit
_FEW_LEVELS = 3  # a measured signal with this few values carries no waveform
_SCALE_RATIO = 50.0  # calibration vs validation range: 1000 (mm vs m) is a unit, not a test


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


def _stuck_share(x: np.ndarray) -> float:
    """Share of the record at its start or end over which the signal holds one value while
    it varies elsewhere (a sensor or a channel that froze)."""
    if x.size < 20 or float(np.ptp(x)) == 0:
        return 0.0
    changes = np.flatnonzero(np.diff(x) != 0)
    head = int(changes[0]) + 1  # samples before the first change
    tail = x.size - 1 - int(changes[-1])  # samples after the last change
    return max(head, tail) / x.size


def check_validation(
    calibration: Iterable[tuple[Any, str]],
    validation: Iterable[tuple[Any, str]],
    signals: Iterable[str],
) -> None:
    """Refuse a validation that cannot validate: a record identical to a calibration
    record, or one whose signals span a range 50 times larger or smaller than in the
    calibration (another unit, e.g. mm against m, without a unit in the header).

    **Arguments:** `calibration`, `validation`: `(record, name)` pairs; `signals`: the
    signals compared.

    **Raises:** `ValueError` naming both records, the signal and the fix.
    """
    calibration, validation = list(calibration), list(validation)
    signals = [s for s in signals]
    for rv, nv in validation:
        for rc, nc in calibration:
            if len(rv) == len(rc) and all(
                s in rv and s in rc and np.array_equal(np.asarray(rv[s]), np.asarray(rc[s]))
                for s in signals
            ):
                raise ValueError(
                    f"the validation record {nv!r} holds the same samples as the calibration "
                    f"record {nc!r}, so it cannot show how the model does on data it was not "
                    "fitted to. Give another experiment as validation, or none (a block of "
                    "the calibration record is then held out)."
                )

    def span(recs, sig):
        values = [np.asarray(r[sig], float).reshape(-1) for r, _ in recs if sig in r]
        x = np.concatenate(values) if values else np.zeros(0)
        x = x[np.isfinite(x)]
        if x.size < 2:
            return 0.0
        lo, hi = np.percentile(x, [1, 99])
        return float(hi - lo)

    for sig in signals:
        a, b = span(calibration, sig), span(validation, sig)
        if a > 0 and b > 0 and max(a / b, b / a) > _SCALE_RATIO:
            ratio = b / a
            raise ValueError(
                f"signal {sig!r} spans {b:.4g} in the validation record(s) "
                f"{[n for _, n in validation]} but {a:.4g} in the calibration record(s) "
                f"{[n for _, n in calibration]} ({ratio:.3g} times as much): the files are "
                "probably in different units (e.g. mm and m). Put the unit in each file's "
                f"header (e.g. '{sig} [mm]'; jaxvs converts to SI) or convert the values."
            )


def signal_quality(
    signals: Mapping[str, Any],
    *,
    name: str = "record",
    required: Iterable[str] = (),
    live: Iterable[str] = (),
) -> tuple[dict[str, dict[str, float]], list[str], list[str]]:
    """Constant signals, clipping and quantisation of the signals of one record.

    **Arguments:**

    - `signals`: signal name -> `(time,)` samples (NaN samples, e.g. of a sparse target
      between its measurements, are left out).
    - `name`: the record's name, used in the findings.
    - `required`: the signals without which the record is useless; one of them being
      constant, or taking 3 or fewer distinct values, is blocking, any other constant
      signal a warning.
    - `live`: measured signals that vary throughout a valid record (a drive's force: its
      noise alone keeps it moving); one of them frozen at one value over the first or last
      quarter of the record, or clipped over a fifth of it, is blocking. (A position that
      dwells at the ends of a move is not such a signal.)

    **Returns:**

    `(summary, blocking, warnings)`: per signal its `clipped_share` (share of samples in
    runs of 3 or more at the minimum or maximum), `quantisation_step` (smallest step
    between distinct values, in the signal's unit) and `quantisation_step_over_std`;
    the blocking findings and the warnings as sentences that say what to do.
    """
    required = set(required)
    live = set(live)
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
        levels = np.unique(x).size
        stuck = _stuck_share(x)
        summary[sig]["stuck_share"] = stuck
        summary[sig]["levels"] = float(levels)
        measured = sig in required
        if sig in live and stuck > _STUCK_SHARE:
            blocking.append(
                f"{name}: signal {sig!r} holds one value over the last or first "
                f"{100 * stuck:.0f} % of the record while it varies elsewhere (a frozen "
                "sensor or channel); cut the record to where it is live, or record again."
            )
            continue
        if measured and levels <= _FEW_LEVELS:
            blocking.append(
                f"{name}: signal {sig!r} takes only {levels} distinct values (quantised to "
                "nothing: the wrong scale or a too coarse channel); record it with a finer "
                "resolution or check its scaling."
            )
            continue
        if held > _HELD_SHARE:
            # heuristic: a set-point held between steps (a speed profile of operating
            # points, a bang-bang input) repeats its previous sample almost always, also
            # between its extremes; its few levels and its plateaus at the extremes are
            # the design of the experiment, not clipping or a coarse sensor
            continue
        if sig in live and clipped > _CLIP_BLOCKING:
            blocking.append(
                f"{name}: {100 * clipped:.1f} % of {sig!r} sits at its minimum or maximum (a "
                "clipped or saturated channel); the model would be fitted to the limit. "
                "Record again with a larger measuring range or a smaller excitation."
            )
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
