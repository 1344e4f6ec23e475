"""Data of a design search: reading experiments (dense or sparse targets), resampling a
sparse target per segment as the thermal study does, segments of constant operating
point, and the honest split into training, stopping and held-out (validation) samples.
"""

from __future__ import annotations

import csv
import math
import os
import pathlib
import re
import warnings
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from ...data import Record, load, load_renamed, parse_header, rename_signals
from ..thermal import ThermalFitWarning, resample_sparse

__all__ = ["DesignDataWarning", "DesignRecord", "Prepared", "prepare"]

_HEADER = re.compile(r"^\s*(?P<name>[^\[\]]+?)\s*(\[(?P<unit>[^\]]*)\])?\s*$")
# The fewest training samples of the smallest design, per free parameter (heuristic: a
# regression on one input has 2 parameters; below ~10 samples per parameter no held-out
# figure means anything).
_MIN_SAMPLES = 30


class DesignRecord(NamedTuple):
    """One experiment of a design search (host arrays).

    - `name`: where it came from; `t`: `(time,)` uniform time [s]; `dt` [s].
    - `signals`: name -> `(time,)` candidate-input values (finite).
    - `target`: `(time,)` the target, NaN where it was not measured.
    - `units`: name -> unit string, where known.
    """

    name: str
    t: np.ndarray
    dt: float
    signals: dict[str, np.ndarray]
    target: np.ndarray
    units: dict[str, str]


class Prepared(NamedTuple):
    """Experiments ready for the search (see [`prepare`][]).

    - `experiments`: calibration experiments followed by held-out ones.
    - `inputs`: candidate input names; `target`: target name.
    - `y`: `(time,)` target of all experiments concatenated (sparse targets resampled).
    - `measured`: `(time,)` bool, where the target was really measured (scored there).
    - `role`: `(time,)` 0 training, 1 stopping (early stopping, input selection), 2
      held out (validation: only the final ranking sees it), -1 warm-up (unused).
    - `starts`: `(time,)` bool, first sample of each experiment.
    - `segments`: `(time,)` int, segment (constant operating point) index per sample.
    - `sparse`: a description of the resampling, or `None` for a dense target.
    - `holdout`: how the held-out samples were chosen (text); `warnings`: texts.
    """

    experiments: list[DesignRecord]
    inputs: list[str]
    target: str
    U: np.ndarray
    y: np.ndarray
    measured: np.ndarray
    role: np.ndarray
    starts: np.ndarray
    segments: np.ndarray
    sparse: dict[str, Any] | None
    holdout: str
    warnings: list[str]


class DesignDataWarning(UserWarning):
    """A property of the data that limits what the design search can tell (e.g. a
    held-out block with no change of operating point, study §4)."""


# ----------------------------------------------------------------------------- reading


def _read_csv_nan(path: pathlib.Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """A CSV with a header row whose cells may be empty or NaN (a sparse target column)."""
    with open(path, newline="", encoding="utf-8-sig") as handle:
        lines = [ln for ln in handle.read().splitlines() if ln.strip() and ln.lstrip()[:1] != "#"]
    rows = list(csv.reader(lines))
    if len(rows) < 2:
        raise ValueError(f"design: {path} has no data rows below its header.")
    names, units = [], {}
    for cell in rows[0]:
        m = _HEADER.match(cell)
        if not m:
            raise ValueError(f"design: header cell {cell!r} of {path} is not 'name [unit]'.")
        names.append(m.group("name"))
        if m.group("unit"):
            units[m.group("name")] = m.group("unit").strip()
    cols: dict[str, list[float]] = {n: [] for n in names}
    for k, row in enumerate(rows[1:], start=2):
        if len(row) != len(names):
            raise ValueError(f"design: {path}, row {k}: {len(row)} cells, header has {len(names)}.")
        for n, cell in zip(names, row):
            try:
                cols[n].append(float(cell) if cell.strip() else math.nan)
            except ValueError:
                raise ValueError(
                    f"design: {path}, row {k}, column {n!r}: {cell!r} is not a number."
                )
    return {n: np.asarray(v) for n, v in cols.items()}, units


def _from_mapping(data: Mapping[str, Any], name: str, target: str) -> DesignRecord:
    if "t" not in data:
        raise ValueError(f"design: {name} has no time signal 't' [s]; add it (uniform sampling).")
    t = np.asarray(data["t"], float)
    signals = {k: np.asarray(v, float) for k, v in data.items() if k != "t"}
    if target not in signals:
        raise ValueError(
            f"design: {name} has no target signal {target!r}; it has {sorted(signals)}. "
            "Give the target's name with target=... (--target), or its sparse samples with "
            "target_samples=... (--target-samples)."
        )
    y = signals.pop(target)
    for k, v in signals.items():
        if v.shape != t.shape:
            raise ValueError(f"design: signal {k!r} of {name} has {v.shape}, time has {t.shape}.")
    if y.shape != t.shape:
        raise ValueError(f"design: the target of {name} has {y.shape}, time has {t.shape}.")
    rec = Record(signals, t=t) if signals else None  # validates time and finiteness
    dt = rec.dt if rec is not None else float(np.median(np.diff(t)))
    sig = {k: np.asarray(rec[k]) for k in rec.names} if rec is not None else {}
    return DesignRecord(name, np.asarray(rec.t if rec else t), dt, sig, y, {})


def _from_record(rec: Record, name: str, target: str | None) -> DesignRecord:
    sig = {k: np.asarray(rec[k]) for k in rec.names}
    y = sig.pop(target) if target in sig else np.full(len(rec), np.nan)
    units = {k: u for k, u in rec.units.items() if k in sig}
    return DesignRecord(name, np.asarray(rec.t), rec.dt, sig, y, units)


def _new_names(columns: Mapping[str, Any], signals: Mapping[str, str]) -> dict[str, str]:
    """`{column: new name}` for the user's mapping `signals` (new name -> column, written
    with or without its unit) over the columns of one experiment."""
    out = {}
    for name, column in signals.items():
        key = column if column in columns else parse_header(column)[0]
        if key not in columns:
            raise ValueError(
                f"design: the column {column!r} mapped to {name!r} is not in the data; its "
                f"columns are {sorted(columns)}."
            )
        out[key] = name
    return out


def _renamed(columns: Mapping[str, Any], new: Mapping[str, str]) -> dict[str, Any]:
    return {new.get(k, k): v for k, v in columns.items()}


def _read(
    item: Any, target: str, index: int, has_samples: bool, signals: Mapping[str, str] | None
) -> DesignRecord:
    if signals:
        if isinstance(item, Record):
            item = rename_signals(item, signals)
        elif isinstance(item, Mapping):
            item = _renamed(item, _new_names(item, signals))
    if isinstance(item, Record):
        if target not in item and not has_samples:
            raise ValueError(
                f"design: experiment {index} has no target signal {target!r}; it has "
                f"{list(item.names)}. Pass the target's name, or its sparse samples with "
                "target_samples=..."
            )
        return _from_record(item, f"experiment {index}", target)
    if isinstance(item, Mapping):
        return _from_mapping(item, f"experiment {index}", target)
    if isinstance(item, str | os.PathLike):
        path = pathlib.Path(item)
        if not path.exists():
            raise ValueError(f"design: no such file: {path}")
        try:
            rec = load_renamed(path, signals)
        except ValueError as err:
            if path.suffix.lower() != ".csv" or "non-finite" not in str(err):
                raise ValueError(f"design: cannot read {path}: {err}") from None
            cols, units = _read_csv_nan(path)  # a sparse target: NaN between measurements
            if signals:
                new = _new_names(cols, signals)
                cols, units = _renamed(cols, new), _renamed(units, new)
            exp = _from_mapping(cols, str(path), target)
            return exp._replace(units={k: u for k, u in units.items() if k in exp.signals})
        if isinstance(rec, list):
            raise ValueError(f"design: {path} holds several time bases; split it first.")
        if target not in rec and not has_samples:
            raise ValueError(
                f"design: {path} has no target signal {target!r}; it has {list(rec.names)}. "
                "Choose the target with --target, or give its sparse samples with "
                "--target-samples."
            )
        return _from_record(rec, str(path), target)
    raise TypeError(
        "design: each experiment must be a file path, a jaxvs.data.Record or a mapping "
        f"name -> array with a time signal 't'; got {type(item).__name__}."
    )


def _as_list(data: Any) -> list[Any]:
    if data is None:
        return []
    if isinstance(data, Record | Mapping | str | os.PathLike):
        return [data]
    if isinstance(data, Sequence):
        return list(data)
    raise TypeError(
        "design: data must be a file path, a Record, a mapping of signals, or a list of them; "
        f"got {type(data).__name__}."
    )


def _samples(target_samples: Any, target: str) -> tuple[np.ndarray, np.ndarray] | None:
    if target_samples is None:
        return None
    if isinstance(target_samples, str | os.PathLike):
        path = pathlib.Path(target_samples)
        if not path.exists():
            raise ValueError(f"design: no such file: {path}")
        cols, _ = _read_csv_nan(path) if path.suffix.lower() == ".csv" else (None, None)
        if cols is None:
            rec = load(path)
            cols = {"t": np.asarray(rec.t), **{k: np.asarray(rec[k]) for k in rec.names}}
        if "t" not in cols or target not in cols:
            raise ValueError(
                f"design: the target-samples file {path} needs the columns 't' and {target!r}; "
                f"it has {sorted(cols)}."
            )
        ts, ys = cols["t"], cols[target]
    elif isinstance(target_samples, tuple | list) and len(target_samples) == 2:
        ts, ys = (np.asarray(a, float) for a in target_samples)
    else:
        raise TypeError("design: target_samples must be a file or a pair (t [s], values).")
    ok = np.isfinite(ts) & np.isfinite(ys)
    ts, ys = np.asarray(ts, float)[ok], np.asarray(ys, float)[ok]
    order = np.argsort(ts)
    return ts[order], ys[order]


# ----------------------------------------------------------------------------- segments


def _segments(signals: dict[str, np.ndarray], n: int) -> np.ndarray:
    """Segment index per sample: a new segment starts where some input steps.

    Heuristic: a step is a one-sample change larger than 20 % of the signal's range and
    larger than 8 robust standard deviations of its sample-to-sample changes (an operating
    point change such as a new spindle speed, not noise or a slow drift). Segments
    shorter than 5 samples are merged into their predecessor.
    """
    edges = np.zeros(n, bool)
    for v in signals.values():
        if n < 3:
            break
        d = np.abs(np.diff(v))
        span = np.ptp(v)
        if span == 0:
            continue
        sigma = 1.4826 * np.median(np.abs(d - np.median(d))) + 1e-12 * span
        edges[1:] |= (d > 0.2 * span) & (d > 8 * sigma)
    idx = np.flatnonzero(edges)
    kept, last = [], 0
    for i in idx:
        if i - last >= 5:
            kept.append(i)
            last = i
    seg = np.zeros(n, int)
    for i in kept:
        seg[i:] += 1
    return seg


def _resample(exp: DesignRecord, seg: np.ndarray) -> tuple[np.ndarray, int, float]:
    """The target on the experiment's grid, per segment by first-order laws (study §3.3.1):
    returns `(y, n_measured, rmse_of_the_laws_at_the_measurements)`."""
    ok = np.isfinite(exp.target)
    ts, ys = exp.t[ok], exp.target[ok]
    if ts.size < 4:
        raise ValueError(
            f"design: {exp.name} has only {ts.size} target measurements; at least 4 per "
            "experiment are needed to resample a sparse target."
        )
    starts = exp.t[np.flatnonzero(np.diff(seg, prepend=-1))]
    starts[0] = min(starts[0], ts[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ThermalFitWarning)
        try:
            y, _ = resample_sparse(ts, ys, exp.t, method="exponential", part_starts=starts)
        except (ValueError, RuntimeError):
            y, _ = resample_sparse(ts, ys, exp.t, method="linear", part_starts=starts)
    if not np.all(np.isfinite(y)):
        y, _ = resample_sparse(ts, ys, exp.t, method="linear", part_starts=starts)
    err = float(np.sqrt(np.mean((np.interp(ts, exp.t, y) - ys) ** 2)))
    return np.asarray(y, float), int(ts.size), err


# ----------------------------------------------------------------------------- prepare


def prepare(
    data: Any,
    *,
    target: str,
    inputs: Sequence[str] | None,
    validation: Any,
    target_samples: Any = None,
    holdout: float = 0.3,
    stop_fraction: float = 0.2,
    warmup: float = 0.05,
    signals: Mapping[str, str] | None = None,
) -> Prepared:
    """Read the experiments, check them, resample a sparse target, and split.

    Held out (role 2): the `validation` experiments; else, with several experiments, the
    last one; else the last `holdout` share of the record as one contiguous block. Within
    the calibration data the last `stop_fraction` of each experiment is the stopping
    block (role 1: early stopping and input selection); never random samples. The first
    `warmup` share of each experiment (role -1) is neither trained on nor scored: dynamic
    designs start in equilibrium with their first input sample, which a record starting
    from a cold machine is not.
    """
    if not isinstance(target, str) or not target:
        raise TypeError("design: target must be the target signal's name, e.g. 'T_bearing'.")
    if not 0 < holdout < 1:
        raise ValueError(f"design: holdout must lie in (0, 1); got {holdout}.")
    samples = _samples(target_samples, target)
    sparse = samples is not None
    cal = [_read(d, target, i, sparse, signals) for i, d in enumerate(_as_list(data))]
    val = [
        _read(d, target, i, sparse, signals)
        for i, d in enumerate(_as_list(validation), start=len(cal))
    ]
    if not cal:
        raise ValueError("design: no calibration data; give at least one experiment.")
    exps = cal + val
    if samples is not None:  # sparse samples from a separate file, matched by time
        ts, ys = samples
        new = []
        for e in exps:
            y = np.full(e.t.shape, np.nan)
            inside = (ts >= e.t[0] - e.dt / 2) & (ts <= e.t[-1] + e.dt / 2)
            idx = np.clip(np.round((ts[inside] - e.t[0]) / e.dt).astype(int), 0, e.t.size - 1)
            y[idx] = ys[inside]
            new.append(e._replace(target=np.where(np.isfinite(e.target), e.target, y)))
        exps = new
    # candidate inputs
    common = set(exps[0].signals)
    for e in exps[1:]:
        common &= set(e.signals)
    available = [k for k in exps[0].signals if k in common]
    if inputs is None:
        names = [k for k in available if k != target]
    else:
        names = [inputs] if isinstance(inputs, str) else list(inputs)
        unknown = [k for k in names if k not in common]
        if unknown:
            raise ValueError(
                f"design: unknown input signal(s) {unknown}; every experiment has "
                f"{sorted(common)}. Check the names (--inputs A,B,...)."
            )
        if target in names:
            raise ValueError(f"design: the target {target!r} cannot also be an input.")
    if not names:
        raise ValueError(
            "design: no candidate inputs: the data hold only the time and the target. Add "
            "measured signals (e.g. temperatures, speeds) to the files."
        )
    dts = {round(e.dt, 12) for e in exps}
    if len(dts) != 1:
        raise ValueError(
            f"design: the experiments have different sampling periods {dts} s; "
            "resample them to one grid first."
        )
    notes: list[str] = []
    # sparse target: resample per segment
    sparse = None
    ys, measured, segs = [], [], []
    seg_offset = 0
    n_meas, errs = 0, []
    is_sparse = any(not np.all(np.isfinite(e.target)) for e in exps)
    for e in exps:
        seg = _segments({k: e.signals[k] for k in names}, e.t.size)
        if is_sparse:
            y, m, err = _resample(e, seg)
            n_meas += m
            errs.append(err)
        else:
            y = e.target
        ys.append(y)
        measured.append(np.isfinite(e.target))
        segs.append(seg + seg_offset)
        seg_offset += int(seg.max()) + 1
    if is_sparse:
        sparse = {
            "measured_samples": n_meas,
            "grid_samples": int(sum(e.t.size for e in exps)),
            "method": "first-order law T0 + k(1 - exp(-t/T1)) per segment of constant "
            "operating point (study §3.3.1, eq. 1)",
            "segments": seg_offset,
            "law_rmse_at_measurements": float(np.sqrt(np.mean(np.square(errs)))),
            "scored_on": "measured samples only",
        }
    y = np.concatenate(ys)
    meas = np.concatenate(measured)
    seg_all = np.concatenate(segs)
    if np.ptp(y[meas]) == 0 if meas.any() else True:
        raise ValueError(
            f"design: the target {target!r} is constant; there is nothing to predict. "
            "Check the column (units, a stuck sensor) or choose another target."
        )
    U = np.concatenate([np.column_stack([e.signals[k] for k in names]) for e in exps])
    for j, k in enumerate(names):
        if np.ptp(U[:, j]) == 0:
            notes.append(f"input {k!r} is constant; it carries no information.")
    starts = np.concatenate([np.arange(e.t.size) == 0 for e in exps])
    role = np.zeros(y.size, int)
    offs = np.cumsum([0] + [e.t.size for e in exps])
    if val:
        for i in range(len(cal), len(exps)):
            role[offs[i] : offs[i + 1]] = 2
        how = f"the {len(val)} validation experiment(s) given"
    elif len(cal) > 1:
        role[offs[-2] : offs[-1]] = 2
        how = f"the last experiment ({exps[-1].name}), whole"
    else:
        n = y.size
        role[int(round((1 - holdout) * n)) :] = 2
        how = f"the last {100 * holdout:.0f} % of the record as one contiguous block"
    for i in range(len(exps)):
        sl = np.arange(offs[i], offs[i + 1])
        c = sl[role[sl] != 2]
        if c.size:
            role[c[int(round((1 - stop_fraction) * c.size)) :]] = 1
        role[sl[: int(math.ceil(warmup * sl.size))]] = -1
    n_train = int(np.sum(meas & (role == 0)))
    if n_train < _MIN_SAMPLES or np.sum(meas & (role == 2)) < 10 or np.sum(role == 1) < 5:
        raise ValueError(
            f"design: too few samples: {n_train} measured training samples (need at least "
            f"{_MIN_SAMPLES} for the smallest design) and {int(np.sum(meas & (role == 2)))} "
            "held-out ones (need 10). Record longer or measure the target more often."
        )
    if len(np.unique(seg_all[role == 2])) < 2:
        msg = (
            "the held-out data contain no change of operating point: their errors show only "
            "steady behaviour and may look better than the calibration errors (the study's "
            "own trap, Table 4 and §4). Hold out a block or an experiment with a change."
        )
        notes.append(msg)
        warnings.warn("design: " + msg, DesignDataWarning, stacklevel=3)
    return Prepared(
        experiments=exps,
        inputs=names,
        target=target,
        U=U,
        y=y,
        measured=meas,
        role=role,
        starts=starts,
        segments=seg_all,
        sparse=sparse,
        holdout=how,
        warnings=notes,
    )
