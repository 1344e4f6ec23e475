"""A user's own column names: map them onto the names a workflow expects.

`jaxvs diagnose` and `jaxvs check` read a family's *canonical* signals (`t`, `q`, `u`,
`x_e`, ...); a measurement file names its columns as its writer chose ("Position [mm]",
"Torque", "時間 (s)"). A mapping `{canonical: column}` renames the columns instead of the
user rewriting the file: `{"t": "時間", "q": "Position", "u": "Torque"}`. The column may be
written as its bare name or as its whole header cell with the unit ("Position [mm]");
the unit is always the one the header gave (already converted to SI by the loader).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from ._loaders import load
from ._record import Record
from ._units import ORIGINAL_UNITS_KEY, parse_header

__all__ = ["load_renamed", "rename_signals", "require_signals"]


def require_signals(
    record: Record, required: Any, *, where: str, name: str | None = None, optional: Any = ()
) -> None:
    """Refuse a record that lacks one of the `required` signal names: a `ValueError`
    naming the missing ones, listing the record's columns and showing how to map the
    user's own column names onto the required ones (Python and command line)."""
    missing = [s for s in required if s not in record.names]
    if not missing:
        return
    which = f"experiment {name!r}" if name else "the data"
    extra = f" (optional: {list(optional)})" if optional else ""
    example = missing[0]
    raise ValueError(
        f"{where}: {which} lacks the required signal(s) {missing}{extra}; its columns are "
        f"{list(record.names)}. Rename the columns by mapping yours onto the required "
        f"names: signals={{{example!r}: '<column>', ...}} in Python "
        f"(jaxvs.data.rename_signals for a Record), --signal {example}=<column> on the "
        "command line (--time <column> for a time column not named 't')."
    )


def _check_map(signals: Any, where: str) -> dict[str, str]:
    if signals is None:
        return {}
    if not isinstance(signals, Mapping):
        raise TypeError(
            f"{where}: signals must be a mapping {{canonical name: column name}}, e.g. "
            f"{{'q': 'Position', 'u': 'Torque'}}; got {type(signals).__name__}."
        )
    out: dict[str, str] = {}
    for key, column in signals.items():
        for text, what in ((key, "canonical name"), (column, "column name")):
            if not isinstance(text, str) or not text.strip():
                raise TypeError(
                    f"{where}: every {what} in signals must be a non-empty string; got "
                    f"{text!r} (in {key!r}: {column!r})."
                )
        out[key.strip()] = column.strip()
    used: dict[str, str] = {}
    for key, column in out.items():
        name = _bare(column)
        if name in used:
            raise ValueError(
                f"{where}: column {column!r} is mapped twice (to {used[name]!r} and {key!r}); "
                "map each column to one name."
            )
        used[name] = key
    return out


def _bare(column: str) -> str:
    """A column as written by the user: `"Position [mm]"` or `"Position"` -> `"Position"`."""
    name, _ = parse_header(column)
    return name


def _find(record: Record, column: str, key: str, where: str) -> str:
    if column in record.names:
        return column
    name = _bare(column)
    if name in record.names:
        return name
    raise ValueError(
        f"{where}: the column {column!r} mapped to {key!r} is not in the data; its columns "
        f"are {list(record.names)}. Give one of them (the name without its unit is enough)."
    )


def rename_signals(
    record: Record, signals: Mapping[str, str], *, time: str | None = None
) -> Record:
    """`record` with its columns renamed to the names a workflow expects.

    **Arguments:**

    - `record`: a `jaxvs.data.Record`.
    - `signals`: `{new name: column}`, e.g. `{"q": "Position", "u": "Torque"}`; a column
      may be written with its unit as in the file's header (`"Position [mm]"`). Columns
      not mentioned keep their names. The key `"t"` names the time column (as `time`).
    - `time`: a column holding the time [s] (any time unit in the header is already
      converted) that becomes the record's time axis, e.g. `"時間 (s)"`; the record's
      own time axis is then replaced.

    **Returns:**

    A new `Record` (units and metadata kept; the mapping is added to
    `metadata["signal_map"]`).

    **Raises:**

    `TypeError` for a mapping that is not `{str: str}`; `ValueError` naming the record's
    columns for a column it does not hold, a column mapped twice, or a new name that
    another column already has.
    """
    where = "rename_signals"
    if not isinstance(record, Record):
        raise TypeError(f"{where}: expected a jaxvs.data.Record, got {type(record).__name__}.")
    mapping = _check_map(signals, where)
    if "t" in mapping:
        if time is not None and _bare(time) != _bare(mapping["t"]):
            raise ValueError(
                f"{where}: the time column is given twice ({time!r} and signals['t'] = "
                f"{mapping['t']!r}); give it once."
            )
        time = mapping.pop("t")
    renames = {_find(record, column, key, where): key for key, column in mapping.items()}
    time_column = None
    if time is not None and not isinstance(time, str):
        raise TypeError(f"{where}: time must be a column name (str); got {time!r}.")
    if time is not None and _bare(time) not in ("t", ""):
        time_column = _find(record, time, "t", where)
    units = record.units
    data: dict[str, Any] = {}
    new_units: dict[str, str] = {}
    for name in record.names:
        if name == time_column:
            continue
        new = renames.get(name, name)
        if new in data:
            raise ValueError(
                f"{where}: two columns would be named {new!r}; the data already has a column "
                f"{new!r}. Map that one to another name too, or drop it from the file."
            )
        data[new] = record[name]
        if units.get(name):
            new_units[new] = units[name]
    if time_column is not None:
        unit = units.get(time_column)
        if unit not in (None, "s"):
            raise ValueError(
                f"{where}: the time column {time_column!r} is in {unit!r}, not a time; give "
                "the column that holds the time."
            )
        t = np.asarray(record[time_column], dtype=float)
    else:
        t = record.t
    metadata = {**record.metadata, "signal_map": {**mapping, **({"t": time} if time else {})}}
    original = record.metadata.get(ORIGINAL_UNITS_KEY)
    if original:
        metadata[ORIGINAL_UNITS_KEY] = {renames.get(k, k): u for k, u in original.items()}
    return Record(data, t=t, units=new_units, metadata=metadata)


def load_renamed(
    path: str | os.PathLike[str], signals: Mapping[str, str] | None = None, **options: Any
) -> Record | list[Record]:
    """`jaxvs.data.load(path, **options)` with the columns renamed by `signals`
    ([`rename_signals`][]); the time column named by `signals["t"]` (with or without its
    unit) is read as the file's time column."""
    mapping = _check_map(signals, "load")
    if "t" in mapping and "time" not in options:
        options["time"] = _bare(mapping["t"])
    try:
        loaded = load(path, **options)
    except ValueError as err:
        if "no time column" not in str(err):
            raise
        raise ValueError(
            f"{err} In jaxvs.diagnose, check and design: signals={{'t': '<column>'}}; on the "
            "command line: --time <column>."
        ) from None
    if not mapping:
        return loaded
    rest = {k: v for k, v in mapping.items() if k != "t"}
    if isinstance(loaded, list):
        return [rename_signals(rec, rest) for rec in loaded]
    return rename_signals(loaded, rest)
