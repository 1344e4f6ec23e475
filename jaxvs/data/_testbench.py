"""Test-bench and PLC formats: TwinCAT Scope text exports, NI TDMS and ASAM MDF.

Each is read through the well-kept library of its community, and every reader obeys the
same rules as the rest of `jaxvs.data`:

- channels on one time base (same sampling period, start and length) form one `Record`;
  channels on different time bases become separate records, **never resampled**;
- a channel whose own time stamps are not uniform is refused (name, file, fix);
- units go to SI through `jaxvs.data.to_si` (the original units are kept in
  `metadata["original_units"]`); time is in seconds.

| format | library | what becomes a channel's time |
|---|---|---|
| TwinCAT Scope `.csv` text export (any separator, decimal point or comma, with or without oversampling channels) | `pytcs` (Beckhoff-specific, BSD-3) | its own time column [ms], scaled and offset by the export |
| TDMS (NI LabVIEW, DIAdem) | `npTDMS` | `wf_increment`, `wf_start_offset` waveform properties, or a time channel of the group |
| MDF 3 / 4 (`.mdf`, `.mf4`, ASAM) | `asammdf` | the master channel of its channel group |
"""

from __future__ import annotations

import gc
import logging
import os
import sys
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ._paths import existing_file
from ._record import DEFAULT_TIME_RTOL, Record, si_record

__all__ = ["is_twincat_scope", "load_mdf", "load_tdms", "load_twincat_scope"]

PathLike = str | os.PathLike[str]


def _group_records(
    channels: list[tuple[str, np.ndarray, np.ndarray, str]],
    *,
    source: str,
    metadata: dict[str, Any],
    time_rtol: float,
) -> list[Record]:
    """One record per distinct time vector; `channels` are `(name, t [s], values, unit)`."""
    groups: dict[tuple, list[tuple[str, np.ndarray, np.ndarray, str]]] = {}
    for name, t, values, unit in channels:
        if t.shape != values.shape or t.ndim != 1:
            raise ValueError(
                f"{source}: channel {name!r} has {values.size} values for {t.size} time stamps."
            )
        if t.size < 2:
            raise ValueError(
                f"{source}: channel {name!r} has {t.size} sample(s); a channel needs at least "
                "two to define a sampling period. Drop it or export a longer recording."
            )
        dt = (t[-1] - t[0]) / (t.size - 1)
        deviation = np.abs(t - (t[0] + dt * np.arange(t.size))) if dt > 0 else np.ones(1)
        if not dt > 0 or deviation.max() > time_rtol * dt:
            k = int(np.argmax(deviation))
            raise ValueError(
                f"{source}: channel {name!r} has time stamps that are not uniform (sample {k} "
                f"at t = {t[k]!r} s lies {deviation[k] / dt if dt > 0 else np.inf:.3g}·dt off "
                "the grid): mixed or jittered sample times. The file is not resampled by jaxvs; "
                "record or export the channel with a constant sample time, or resample it "
                "yourself and save it as CSV."
            )
        key = (t.size, round(float(t[0]) / dt, 6), round(float(dt), 15))
        groups.setdefault(key, []).append((name, t, values, unit))
    records = []
    for members in groups.values():
        names = [m[0] for m in members]
        t = members[0][1]
        for name, other, _, _ in members[1:]:
            if not np.allclose(other, t, rtol=0, atol=time_rtol * (t[1] - t[0])):
                raise ValueError(
                    f"{source}: channels {names[0]!r} and {name!r} have the same sampling but "
                    "different time stamps; jaxvs does not align them silently."
                )
        try:
            record = Record(
                {name: values for name, _, values, _ in members},
                t=t,
                units={name: unit for name, _, _, unit in members if unit},
                metadata=metadata,
                time_rtol=time_rtol,
            )
        except ValueError as error:
            raise ValueError(
                f"{source}, channels {names}: {error} The file is not resampled by jaxvs; "
                "export the channels with a constant sample time."
            ) from None
        records.append(si_record(record, source))
    return sorted(records, key=lambda r: (r.dt, r.t0))


def _select(records: list[Record], names: Iterable[str] | str | None, source: str) -> list[Record]:
    if names is None:
        return records
    wanted = [names] if isinstance(names, str) else list(names)
    out = []
    for record in records:
        present = [name for name in wanted if name in record]
        if present:
            out.append(record.select(present))
    found = {name for record in out for name in record.names}
    missing = [name for name in wanted if name not in found]
    if missing:
        available = sorted({n for r in records for n in r.names})
        raise KeyError(f"{source} has no channel {missing}; available channels: {available}.")
    return out


# --- TwinCAT Scope -------------------------------------------------------------------------


def is_twincat_scope(path: PathLike) -> bool:
    """Whether `path` starts like a TwinCAT Scope text export (`Name<sep>...`, a
    `SampleTime[ms]` row within the header)."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as handle:
            head = [handle.readline() for _ in range(20)]
    except OSError:
        return False
    return head[0].startswith("Name") and any(line.startswith("SampleTime[ms]") for line in head)


def _export_span(file: Path) -> float | None:
    """Duration [s] between the export's start and end time stamps (100 ns ticks)."""
    with open(file, encoding="utf-8-sig", errors="replace") as handle:
        head = [handle.readline() for _ in range(6)]
    sep = head[0][4:5] if len(head[0]) > 4 else ""
    ticks = {}
    for line in head:
        for key in ("Starttime of export", "Endtime of export"):
            if sep and line.startswith(key + sep):
                cell = line[len(key) + 1 :].split(sep)[0].strip()
                if cell.isdigit():
                    ticks[key] = int(cell)
    if len(ticks) != 2:
        return None
    return (ticks["Endtime of export"] - ticks["Starttime of export"]) * 1e-7


_SCOPE_SCAN_LINES = 100_000  # heuristic: a decimal mark shows within the first rows


def _scope_decimal(file: Path, source: str) -> str:
    """The decimal mark of a scope export's data rows, found here (bounded) rather than by
    pytcs, whose search reads past the end of a file without a fractional number forever.

    Refuses an export cut after its header (no data row) with a `ValueError`."""
    with open(file, encoding="utf-8-sig", errors="replace") as handle:
        first = handle.readline()
        sep = first[4:5]
        rows = 0
        in_data = False
        for _, line in zip(range(_SCOPE_SCAN_LINES), handle):
            line = line.rstrip("\r\n")
            if not in_data:
                in_data = line[:1].isnumeric()
                if not in_data:
                    continue
            if not line:
                continue
            rows += 1
            marks = {c for c in line if not (c.isalnum() or c in (sep, "-", "+", " "))}
            if len(marks) == 1:
                return marks.pop()
            if len(marks) > 1:
                raise ValueError(
                    f"{source}: data row {rows} holds {''.join(sorted(marks))!r} besides the "
                    f"separator {sep!r}, so its decimal mark is ambiguous; the file was edited. "
                    "Export it again from TwinCAT Scope."
                )
    if rows == 0:
        raise ValueError(
            f"{source} ends after its header: it holds no data row (the export was cut or "
            "interrupted). Export the recording again from TwinCAT Scope."
        )
    return "."  # whole numbers only: any decimal mark reads them


def load_twincat_scope(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    scaling: str = "as_exported",
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> list[Record]:
    """Read a Beckhoff TwinCAT Scope text export (`.csv`) through `pytcs`.

    Every export variant of TwinCAT 3 Scope is accepted: tab, colon or semicolon
    separators, decimal point or decimal comma, with or without oversampling channels.
    The channel unit (`Unit`, e.g. `dV (Voltage)` → `dV`) is converted to SI. Channels
    with different sample times or time offsets become separate records (e.g. a 0.2 ms
    oversampling channel beside 1 ms channels), never resampled.

    **Scaling.** An export holds either the scaled values or the raw PLC values, and its
    header does not say which: the header rows `ScaleFactor`, `Offset`, `Unit ScaleFactor`
    and `Unit Offset` are written either way. In the shared pytcs exports, the decimal-comma,
    separator and no-oversampling exports hold scaled values while the default export holds
    raw ones. `scaling="as_exported"` (default) takes the values as written;
    `scaling="apply"` applies `(raw·ScaleFactor + Offset)·UnitScaleFactor + UnitOffset`
    (the order reproduces the scaled exports from the raw one) to raw exports.

    **Arguments:**

    - `path`: the export (only read).
    - `names`: channels to keep (default all); records without any of them are dropped.
    - `scaling`: `"as_exported"` or `"apply"` (see above).
    - `time_rtol`: tolerance of the uniform-time check, relative to the sample time.

    **Returns:**

    A list of `Record`s, fastest sampling first; metadata holds the file name, the start
    time of the export and each channel's PLC symbol and data type.

    **Raises:**

    `ValueError` naming the file and the fix for a file pytcs cannot parse (truncated,
    not a scope export, unknown variant) or a channel with non-uniform time stamps;
    `KeyError` for a requested channel the file does not hold.
    """
    import pytcs

    if scaling not in ("as_exported", "apply"):
        raise ValueError(f"scaling must be 'as_exported' or 'apply', got {scaling!r}.")
    file = existing_file(path)
    source = f"TwinCAT Scope export {str(file)!r}"
    if not is_twincat_scope(file):
        raise ValueError(
            f"{source} does not start like a TwinCAT Scope text export (a 'Name' line and a "
            "'SampleTime[ms]' header row). Export the scope recording as 'CSV' from TwinCAT "
            "Scope, or load a plain CSV with jaxvs.data.load_csv."
        )
    decimal = _scope_decimal(file, source)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scope = pytcs.ScopeFile(str(file), decimal=decimal)
            scope.load()
            items = list(scope.items())
    except Exception as error:  # pytcs raises assorted errors on malformed files
        raise ValueError(
            f"{source} cannot be parsed ({type(error).__name__}: {error}); the file is truncated "
            "or an export variant pytcs does not know. Export it again from TwinCAT Scope."
        ) from None
    if not items:
        raise ValueError(f"{source} holds no channel.")
    channels = []
    info: dict[str, Any] = {}
    span = _export_span(file)
    for name, channel in items:
        values = np.asarray(channel.values, dtype=np.float64)
        t = np.asarray(channel.time, dtype=np.float64) / 1000.0  # ms -> s
        if values.size != t.size:
            raise ValueError(
                f"{source}: channel {name!r} has {values.size} values for {t.size} time stamps; "
                "the file is truncated. Export it again."
            )
        finite = np.isfinite(values) & np.isfinite(t)
        if not finite.all():
            raise ValueError(
                f"{source}: channel {name!r} has empty or non-numeric cells (first at row "
                f"{int(np.argmin(finite))}); the file is truncated or edited. Export it again."
            )
        step = float(getattr(channel, "sample_time", 0.0) or 0.0) / 1000.0
        if span is not None and t.size and (t[-1] - t[0]) < span - 2 * step - 1e-9:
            raise ValueError(
                f"{source}: channel {name!r} covers {t[-1] - t[0]:.6g} s but the export spans "
                f"{span:.6g} s (its start and end time stamps); the file is truncated. Export "
                "the recording again."
            )
        unit = str(getattr(channel, "units", "") or "").strip()
        meta = getattr(channel, "info", {}) or {}
        if scaling == "apply":
            factors = []
            for key, default in (
                ("ScaleFactor", 1.0),
                ("Offset", 0.0),
                ("Unit ScaleFactor", 1.0),
                ("Unit Offset", 0.0),
            ):
                try:
                    factors.append(float(str(meta.get(key, default)).replace(",", ".")))
                except ValueError:
                    raise ValueError(
                        f"{source}: channel {name!r} has {key} {meta.get(key)!r}, not a number."
                    ) from None
            factor, offset, unit_factor, unit_offset = factors
            values = (values * factor + offset) * unit_factor + unit_offset
        info[name] = {
            "symbol": meta.get("SymbolName", ""),
            "data_type": meta.get("Data-Type", ""),
            "sample_time_ms": float(getattr(channel, "sample_time", np.nan)),
        }
        channels.append((name, t, values, unit))
    metadata = {
        "source": "TwinCAT Scope",
        "file": file.name,
        "start_time": str(getattr(scope, "start_time", "")),
        "channels": info,
    }
    records = _group_records(channels, source=source, metadata=metadata, time_rtol=time_rtol)
    return _select(records, names, source)


# --- TDMS -----------------------------------------------------------------------------------

_TIME_CHANNEL_NAMES = ("t", "time", "Time", "TIME", "Zeit", "timestamp")


def load_tdms(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> list[Record]:
    """Read an NI TDMS file (LabVIEW, DIAdem, VeriStand) through `npTDMS`.

    Each channel's time comes from its waveform properties `wf_increment` [s] and
    `wf_start_offset` [s], or, without them, from a channel of the same group named `t`,
    `time` or `Time` [s, or the unit it carries]. Units come from `unit_string`. A channel
    is named `channel` when the name is unique in the file, else `group/channel`.

    **Arguments:** as `load_twincat_scope`.

    **Returns:**

    A list of `Record`s, one per time base; metadata holds the file's root properties
    (strings and numbers) and each record's group names.

    **Raises:**

    `ValueError` naming the file and the fix for a file npTDMS cannot read (truncated,
    not TDMS), a non-numeric channel, or a channel without any time information.
    """
    from nptdms import TdmsFile

    file = existing_file(path)
    source = f"TDMS file {str(file)!r}"
    # npTDMS reads what it can of a truncated file and only logs a warning; the warning
    # is caught here so that a cut file is refused instead of silently shortened.
    problems: list[str] = []

    class _Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if record.levelno >= logging.WARNING:
                problems.append(record.getMessage())

    logger = logging.getLogger("nptdms")
    handler = _Collect()
    logger.addHandler(handler)
    propagate = logger.propagate
    logger.propagate = False
    try:
        tdms = TdmsFile.read(str(file))
    except Exception as error:
        problems.append(f"{type(error).__name__}: {error}")
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
    if problems:
        raise ValueError(
            f"{source} cannot be read as TDMS ({problems[0]}); the file is truncated or not a "
            "TDMS file. Copy it again from the test bench."
        )
    all_names = [c.name for g in tdms.groups() for c in g.channels()]
    channels = []
    for group in tdms.groups():
        time_channel = None
        for candidate in _TIME_CHANNEL_NAMES:
            if candidate in [c.name for c in group.channels()]:
                time_channel = group[candidate]
                break
        for channel in group.channels():
            if channel is time_channel:
                continue
            label = (
                channel.name
                if all_names.count(channel.name) == 1
                else (f"{group.name}/{channel.name}")
            )
            data = channel[:]
            if not (np.issubdtype(data.dtype, np.number) or np.issubdtype(data.dtype, np.bool_)):
                raise ValueError(
                    f"{source}: channel {label!r} holds {data.dtype} data, not numbers; drop "
                    "it or select numeric channels with names=[...]."
                )
            values = np.asarray(data, dtype=np.float64)
            props = channel.properties
            if "wf_increment" in props:
                dt = float(props["wf_increment"])
                t0 = float(props.get("wf_start_offset", 0.0))
                t = t0 + dt * np.arange(values.size)
            elif time_channel is not None:
                t = np.asarray(time_channel[:], dtype=np.float64)
                time_unit = time_channel.properties.get("unit_string", "s") or "s"
                if time_unit != "s":
                    from ._units import convert_units

                    t = convert_units(t, time_unit, "s", name=time_channel.name, source=source)
            else:
                raise ValueError(
                    f"{source}: channel {label!r} has no waveform timing (wf_increment) and "
                    f"group {group.name!r} has no time channel (t, time, Time). "
                    "Write the channel as a waveform in LabVIEW, or add a time channel in s."
                )
            unit = str(props.get("unit_string", "") or "")
            channels.append((label, t, values, unit))
    if not channels:
        raise ValueError(f"{source} holds no data channel.")
    root = {
        key: value
        for key, value in tdms.properties.items()
        if isinstance(value, str | int | float | bool)
    }
    metadata = {"source": "TDMS", "file": file.name, **root}
    records = _group_records(channels, source=source, metadata=metadata, time_rtol=time_rtol)
    return _select(records, names, source)


# --- MDF ---------------------------------------------------------------------------------------


def load_mdf(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> list[Record]:
    """Read an ASAM MDF file (versions 3 and 4, `.mdf` / `.mf4`) through `asammdf`.

    Every channel group has its own master (time) channel; its channels become one record
    (groups with the same time stamps are merged, others stay separate). Values are the
    physical values (the file's conversion rules applied); units come from the channel
    units. Channel names must be unique across the groups that end in one record.

    **Arguments:** as `load_twincat_scope`.

    **Returns:**

    A list of `Record`s, one per time base.

    **Raises:**

    `ValueError` naming the file and the fix for a file asammdf cannot read, a channel
    group with non-uniform time stamps (asynchronous CAN signals: resample them in your
    tool first), or a non-numeric channel.
    """
    from asammdf import MDF

    file = existing_file(path)
    source = f"MDF file {str(file)!r}"
    failure = None
    # asammdf's half-built reader of a damaged file raises again in its __del__; that
    # second, unraisable error is swallowed here (the first one is reported below).
    previous_hook = sys.unraisablehook

    def _hook(unraisable: Any) -> None:
        owner = getattr(unraisable.object, "__module__", None) or type(unraisable.object).__module__
        if str(owner).startswith("asammdf"):
            return
        previous_hook(unraisable)

    sys.unraisablehook = _hook
    try:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mdf = MDF(str(file))
        except Exception as error:
            failure = f"{type(error).__name__}: {error}"
        gc.collect()
    finally:
        sys.unraisablehook = previous_hook
    if failure is not None:
        raise ValueError(
            f"{source} cannot be read as MDF ({failure}); the file is truncated or not an MDF "
            "file. Copy it again from the data logger."
        )
    channels = []
    try:
        masters = getattr(mdf, "masters_db", {})
        for gi, group in enumerate(mdf.groups):
            master = masters.get(gi)
            for ci, channel in enumerate(group.channels):
                if ci == master:
                    continue
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    signal = mdf.get(group=gi, index=ci)
                values = np.asarray(signal.samples)
                if values.dtype.names is not None or not (
                    np.issubdtype(values.dtype, np.number) or np.issubdtype(values.dtype, np.bool_)
                ):
                    raise ValueError(
                        f"{source}: channel {signal.name!r} holds {values.dtype} data, not "
                        "numbers; select numeric channels with names=[...]."
                    )
                channels.append(
                    (
                        signal.name,
                        np.asarray(signal.timestamps, dtype=np.float64),
                        values.astype(np.float64),
                        str(signal.unit or ""),
                    )
                )
    finally:
        mdf.close()
    if not channels:
        raise ValueError(f"{source} holds no data channel.")
    metadata = {"source": "MDF", "file": file.name}
    records = _group_records(channels, source=source, metadata=metadata, time_rtol=time_rtol)
    return _select(records, names, source)
