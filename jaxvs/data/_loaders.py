"""Reading and writing `Record`s: CSV, NPZ, MAT and HDF5, plus the EMPS benchmark files.

Conventions shared by every format (docs/guides/contracts.md):

- one experiment per file, signals as 1-D columns, the time vector (default name `t`) in
  seconds;
- loaders only read: the user's file is opened read-only and never modified;
- writers store units and metadata so that `load(save_xxx(record))` gives the same record.
  Metadata are written as JSON, so they must be JSON-serialisable (NumPy scalars and arrays
  are converted to numbers and lists).
"""

from __future__ import annotations

import csv
import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._csv_dialect import decimal_hint, delimiter_hint, encoding_error
from ._paths import existing_file
from ._record import DEFAULT_TIME_RTOL, Record
from ._units import ORIGINAL_UNITS_KEY, convert_units, parse_header, to_si

SUPPORTED_SUFFIXES = (
    ".csv",
    ".npz",
    ".mat",
    ".h5",
    ".hdf5",
    ".xml",
    ".tdms",
    ".mf4",
    ".mdf",
    ".unv",
    ".uff",
)
FRF_SUFFIXES = (".unv", ".uff", ".xml")

# Leading bytes of the binary formats, for files whose suffix says nothing.
_MAGIC = (
    (b"\x89HDF\r\n\x1a\n", ".h5"),
    (b"PK\x03\x04", ".npz"),
    (b"MATLAB", ".mat"),
    (b"TDSm", ".tdms"),
    (b"MDF     ", ".mf4"),
    (b"UnFinMF ", ".mf4"),
)

# Names under which the writers store units and metadata as JSON text.
_UNITS_KEY = "jaxvs_units"
_METADATA_KEY = "jaxvs_metadata"
_CSV_METADATA_PREFIX = "# metadata:"

PathLike = str | os.PathLike[str]


# --- helpers ---------------------------------------------------------------------------------


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(
        f"Metadata value {value!r} of type {type(value).__name__} cannot be written; writers "
        "store metadata as JSON (numbers, strings, booleans, None, lists, dicts, NumPy arrays)."
    )


def _metadata_json(record: Record) -> str:
    return json.dumps(dict(record.metadata), default=_json_default, allow_nan=True)


def _names_list(names: Iterable[str] | str | None) -> list[str] | None:
    if names is None:
        return None
    if isinstance(names, str):
        return [names]
    return list(names)


def _build(
    columns: Mapping[str, np.ndarray],
    *,
    time: str,
    dt: float | None,
    names: Sequence[str] | None,
    units: Mapping[str, str],
    metadata: Mapping[str, Any],
    source: str,
    found: Iterable[str],
    time_rtol: float,
) -> Record:
    """Assemble a `Record` from equal-length 1-D `columns`, one of which may be the time."""
    if time in columns and dt is not None:
        raise ValueError(
            f"{source} has a time column {time!r} and dt={dt!r} was given; pass only one of them "
            "(dt is for files without a time column)."
        )
    if time not in columns and dt is None:
        raise ValueError(
            f"{source} has no time column {time!r}; columns found: {sorted(found)}. Name the "
            f"time column 't' (seconds), pass time='<column name>', or pass dt=<sampling "
            "period in s> for a file without time."
        )
    columns = dict(columns)
    units = dict(units)
    metadata = dict(metadata)
    original: dict[str, str] = dict(metadata.get(ORIGINAL_UNITS_KEY) or {})
    time_unit = units.pop(time, None)
    if time in columns and time_unit:
        # The time base goes to seconds; a unit that is not a time is refused.
        columns[time] = convert_units(columns[time], time_unit, "s", name=time, source=source)
        if time_unit.strip() != "s":
            original[time] = time_unit
    for name, unit in list(units.items()):
        if name not in columns or not unit:
            continue
        columns[name], si = to_si(columns[name], unit, name=name, source=source)
        if si != unit:
            original[name] = unit
        units[name] = si
    if original:
        metadata[ORIGINAL_UNITS_KEY] = original
    signals = {name: values for name, values in columns.items() if name != time}
    if names is not None:
        missing = [name for name in names if name not in signals]
        if missing:
            raise KeyError(
                f"{source} has no signal {', '.join(map(repr, missing))}; available signals: "
                f"{sorted(signals)}."
            )
        signals = {name: signals[name] for name in names}
    if not signals:
        raise ValueError(
            f"{source} holds no signal besides the time column {time!r}; save the measured "
            "signals in the same file (one column or array per signal)."
        )
    kept_units = {name: unit for name, unit in units.items() if name in signals and unit}
    try:
        if time in columns:
            return Record(
                signals, t=columns[time], units=kept_units, metadata=metadata, time_rtol=time_rtol
            )
        return Record(signals, dt=dt, units=kept_units, metadata=metadata)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def _as_column(value: np.ndarray) -> np.ndarray | None:
    """`value` as a 1-D numeric column, or `None` when it is not one."""
    if not (
        np.issubdtype(value.dtype, np.number) or np.issubdtype(value.dtype, np.bool_)
    ) or np.iscomplexobj(value):
        return None
    if value.ndim == 1 and value.shape[0] > 1:
        return value
    if value.ndim == 2 and 1 in value.shape and value.size > 1:
        return value.reshape(-1)
    return None


def _scalar(value: np.ndarray) -> Any:
    """A size-1 numeric array or a string array as a Python scalar, else `None`."""
    if value.dtype.kind in "US" and value.size == 1:
        item = value.reshape(-1)[0]
        return item.decode() if isinstance(item, bytes) else str(item)
    if value.size == 1 and (
        np.issubdtype(value.dtype, np.number) or np.issubdtype(value.dtype, np.bool_)
    ):
        return value.reshape(-1)[0].item()
    return None


def _split_variables(
    variables: Mapping[str, np.ndarray],
    *,
    time: str,
    source: str,
    names: Sequence[str] | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Sort named arrays into signal columns (the length of the time vector) and metadata.

    A vector that looks like a signal but has another length than the time vector is
    refused, never moved silently to the metadata (that would load the file without it).
    """
    columns_1d = {name: col for name, v in variables.items() if (col := _as_column(v)) is not None}
    if time in columns_1d:
        n = columns_1d[time].shape[0]
        base = f"the time vector {time!r}"
    else:
        lengths = [col.shape[0] for col in columns_1d.values()]
        # Without a time vector, the signals are the columns of the most common length.
        n = max(set(lengths), key=lengths.count) if lengths else -1
        base = "the other signals"
    columns: dict[str, np.ndarray] = {}
    metadata: dict[str, Any] = {}
    for name, value in variables.items():
        column = columns_1d.get(name)
        if column is not None and column.shape[0] == n:
            columns[name] = column
            continue
        # Heuristic: a vector at least half as long as the time base is a signal whose
        # samples were lost or added (short vectors -- gains, poles -- are metadata). With
        # names=[...] only the requested signals are checked.
        if (
            column is not None
            and name != time
            and 2 * column.shape[0] >= n
            and (names is None or name in names)
        ):
            raise ValueError(
                f"{source}: variable {name!r} has {column.shape[0]} samples but {base} has "
                f"{n}; every signal needs one value per time step. Trim or resample it to "
                "the time base, or pass names=[...] to load only the signals you need."
            )
        scalar = _scalar(value)
        if scalar is not None:
            metadata[name] = scalar
        else:
            other = np.array(value, copy=True)
            other.setflags(write=False)
            metadata[name] = other
    return columns, metadata


def _decode_json(text: Any, what: str, source: str) -> Any:
    if isinstance(text, np.ndarray):
        text = _scalar(text)
    if isinstance(text, bytes):
        text = text.decode()
    try:
        return json.loads(str(text))
    except json.JSONDecodeError as error:
        raise ValueError(
            f"{source}: the stored {what} are not valid JSON ({error}); correct them or "
            "delete them (jaxvs writers store them as JSON)."
        ) from None


# --- dispatch --------------------------------------------------------------------------------


def _is_emps(variables: Iterable[str]) -> bool:
    return {"qm", "qg", "vir"} <= set(variables)


def _sniff(file: Path) -> str:
    """The format of `file`: its suffix when known, else what its first bytes say."""
    suffix = file.suffix.lower()
    if suffix in SUPPORTED_SUFFIXES:
        return suffix
    with open(file, "rb") as handle:
        head = handle.read(64)
    for magic, kind in _MAGIC:
        if head.startswith(magic):
            return kind
    text = head.lstrip(b"\xef\xbb\xbf").lstrip()
    if text.startswith(b"<?xml") or text.startswith(b"<"):
        return ".xml"
    if text.startswith(b"-1") and b"\n" in text:
        return ".unv"
    raise ValueError(
        f"Unsupported file type {file.suffix!r} for {str(file)!r}; supported suffixes: "
        f"{', '.join(SUPPORTED_SUFFIXES)} (binary formats are also recognised by content)."
    )


def load(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time: str = "t",
    dt: float | None = None,
    time_rtol: float = DEFAULT_TIME_RTOL,
    delimiter: str = ",",
    decimal: str = ".",
    encoding: str = "utf-8",
) -> Record | list[Record]:
    """Load the time series of a measurement file, recognised by suffix and content.

    | format | suffix | reader | returns |
    |---|---|---|---|
    | CSV with a header row (units as `name [unit]`) | `.csv` | `load_csv` | `Record` |
    | TwinCAT Scope text export | `.csv` (recognised by content) | `load_twincat_scope` | list |
    | NumPy archive | `.npz` | `load_npz` | `Record` |
    | MATLAB v5/v7 (EMPS files → `load_emps`) | `.mat` | `load_mat` | `Record` |
    | HDF5 (MATLAB v7.3 too) | `.h5`, `.hdf5` | `load_hdf5` | `Record` |
    | Sinumerik frequency measurement / trace XML | `.xml` | `load_sinumerik` | list |
    | NI TDMS | `.tdms` | `load_tdms` | list |
    | ASAM MDF 3/4 | `.mf4`, `.mdf` | `load_mdf` | list |
    | UFF dataset 58 time responses | `.unv`, `.uff` | `load_uff_record` | `Record` |

    A reader that finds several time bases (channels sampled at different rates, the two
    runs of a Sinumerik measurement) returns a list of `Record`s, never resampling; a list
    with one record is returned as that record. Files without a known suffix are
    recognised by their first bytes (HDF5, NPZ, MAT, TDMS, MDF, XML). Units go to SI
    (`jaxvs.data.to_si`), the originals stay in `metadata["original_units"]`.

    **Arguments:**

    - `path`: the file; it is only read.
    - `names`: the signals to keep (default: all).
    - `time`: name of the time column [s] (CSV, NPZ, MAT, HDF5; ignored for EMPS files).
    - `dt`: sampling period [s] for CSV/NPZ/MAT/HDF5 files without a time column.
    - `time_rtol`: tolerance of the uniform-time check, relative to the sampling period.
    - `delimiter`, `decimal`, `encoding`: the CSV dialect (see `load_csv`; other formats
      ignore them).

    **Returns:**

    A `Record`, or a list of `Record`s for files with several time bases.

    **Raises:**

    `FileNotFoundError`; `ValueError` for an unsupported file, a missing time column, a
    non-numeric cell, a non-uniform time vector, an unknown unit, or a truncated file
    (each naming the file and the fix); `KeyError` for a requested signal that the file
    does not hold.
    """
    file = existing_file(path)
    kind = _sniff(file)
    options = dict(names=names, time=time, dt=dt, time_rtol=time_rtol)
    if kind == ".csv":
        from ._testbench import is_twincat_scope, load_twincat_scope

        if is_twincat_scope(file):
            return _one_or_list(load_twincat_scope(file, names=names, time_rtol=time_rtol))
        dialect = dict(delimiter=delimiter, decimal=decimal, encoding=encoding)
        return load_csv(file, **options, **dialect)  # type: ignore[arg-type]
    if kind == ".npz":
        return load_npz(file, **options)  # type: ignore[arg-type]
    if kind == ".mat":
        if _is_emps(_read_mat(file, names_only=True)):
            record = load_emps(file, time_rtol=time_rtol)
            return record if names is None else record.select(_names_list(names) or [])
        return load_mat(file, **options)  # type: ignore[arg-type]
    if kind in (".h5", ".hdf5"):
        return load_hdf5(file, **options)  # type: ignore[arg-type]
    if kind == ".xml":
        from ._sinumerik import load_sinumerik

        records = load_sinumerik(file, time_rtol=time_rtol)
        return _one_or_list(_keep(records, names, str(file)))
    if kind == ".tdms":
        from ._testbench import load_tdms

        return _one_or_list(load_tdms(file, names=names, time_rtol=time_rtol))
    if kind in (".mf4", ".mdf"):
        from ._testbench import load_mdf

        return _one_or_list(load_mdf(file, names=names, time_rtol=time_rtol))
    from ._uff import load_uff_record

    record = load_uff_record(file)
    return record if names is None else record.select(_names_list(names) or [])


def _keep(records: list[Record], names: Iterable[str] | str | None, source: str) -> list[Record]:
    if names is None:
        return records
    wanted = _names_list(names) or []
    kept = [
        record.select([n for n in wanted if n in record])
        for record in records
        if any(n in record for n in wanted)
    ]
    if not kept:
        available = sorted({n for r in records for n in r.names})
        raise KeyError(f"{source} has no signal {wanted}; available signals: {available}.")
    return kept


def _one_or_list(records: list[Record]) -> Record | list[Record]:
    return records[0] if len(records) == 1 else records


def load_frf(path: PathLike, **options: Any) -> Any:
    """Load the frequency response stored in a file, recognised by suffix and content.

    | format | suffix | reader |
    |---|---|---|
    | UFF dataset 58 FRFs / transmissibilities (+ coherence) | `.unv`, `.uff` | `load_uff_frf` |
    | Sinumerik frequency measurement (H1 from the stored spectra) | `.xml` | `load_sinumerik_frf` |
    | Sinumerik auto-tuning (AST): plant + controller settings | `.xml` | `load_sinumerik_frf` |

    **Arguments:**

    - `path`: the file (only read).
    - `options`: passed to the reader (`index=`, `layout=` for UFF; `index=` for AST).

    **Returns:**

    An `FRFData` (frequencies in Hz).

    **Raises:**

    `FileNotFoundError`; `ValueError` naming the file and the fix for a time-domain file
    (estimate the FRF with `jaxvs.signal.frf_h1`), an unsupported suffix or a damaged file.
    """
    file = existing_file(path)
    kind = _sniff(file)
    if kind in (".unv", ".uff"):
        from ._uff import load_uff_frf

        return load_uff_frf(file, **options)
    if kind == ".xml":
        from ._sinumerik import load_sinumerik_frf

        return load_sinumerik_frf(file, **options)
    raise ValueError(
        f"{str(file)!r} ({kind}) holds time series, not a frequency response; load it with "
        "jaxvs.data.load and estimate the FRF with jaxvs.signal.frf_h1. load_frf reads "
        f"{', '.join(FRF_SUFFIXES)} (UFF 58, Sinumerik frequency measurement and AST XML)."
    )


# --- CSV -------------------------------------------------------------------------------------


def load_csv(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time: str = "t",
    dt: float | None = None,
    delimiter: str = ",",
    decimal: str = ".",
    encoding: str = "utf-8",
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> Record:
    """Load a CSV file with a header row: one column per signal, time column `t` [s].

    A header cell may carry a unit, `name [unit]` (e.g. `q [m]`); the time column may be
    written `t [s]`. Lines starting with `#` before the header are comments; a comment
    `# metadata: {...}` (JSON, as written by `save_csv`) becomes the record's metadata.
    Every other cell must be a number (`nan`/`inf` are parsed and then rejected by `Record`).

    **Arguments:** as `load`, plus `delimiter` (default `,`; `;` for many European
    spreadsheets), `decimal` (the decimal mark, default `.`; `,` for `0,5`) and `encoding`
    (default UTF-8, a byte-order mark is skipped; `latin-1` for older spreadsheets). A file
    that looks written in another dialect is refused with the option that reads it.

    **Returns:**

    A `Record`.

    **Raises:**

    `ValueError` naming the row and column of a non-numeric cell, a row with the wrong
    number of cells, duplicate or empty column names, a time unit other than seconds, or
    a missing time column (listing the columns found).
    """
    file = existing_file(path)
    source = f"CSV file {str(file)!r}"
    metadata: dict[str, Any] = {}
    raw = file.read_bytes()
    try:
        utf8 = encoding.lower().replace("_", "-") in ("utf-8", "utf8")
        if utf8 and raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
            encoding = "utf-16"  # Excel's "Unicode text": its byte-order mark says so
            utf8 = False
        text = raw.decode("utf-8-sig" if utf8 else encoding)
    except UnicodeDecodeError as error:
        raise ValueError(encoding_error(source, error, raw, encoding)) from None
    except LookupError:
        raise ValueError(
            f"load_csv: unknown encoding {encoding!r}; use e.g. 'utf-8' or 'latin-1'."
        ) from None
    if len(decimal) != 1 or decimal == delimiter or len(delimiter) != 1:
        raise ValueError(
            f"load_csv: delimiter {delimiter!r} and decimal {decimal!r} must be two different "
            "single characters, e.g. delimiter=';', decimal=','."
        )
    lines = text.splitlines()
    if "\x00" in text:
        raise ValueError(f"{source} holds NUL bytes: it is binary or damaged, not a CSV text.")
    if text and text[-1] not in "\r\n" and lines[-1].strip() and lines[-1].lstrip()[0] != "#":
        # A file cut inside its last row would still parse (a shorter last number):
        # complete CSV files end with a line break.
        raise ValueError(
            f"{source}, line {len(lines)}: the file ends inside a row, without a line break: "
            "it looks truncated. Export it again; if it is complete, add a line break at the "
            "end of the last line."
        )
    # Excel writes "sep=;" as the first line of a CSV whose separator is not the list
    # separator of the locale: it names the separator, it is not the header.
    if lines and re.fullmatch(r"\s*sep=(.)\s*", lines[0].lstrip("\ufeff")):
        named = re.fullmatch(r"\s*sep=(.)\s*", lines[0].lstrip("\ufeff")).group(1)  # type: ignore[union-attr]
        if delimiter not in (",", named):
            raise ValueError(
                f"{source}, line 1: the file names its separator ('sep={named}') but "
                f"delimiter={delimiter!r} was given; pass delimiter={named!r} or leave it out."
            )
        if named == decimal:
            raise ValueError(
                f"{source}, line 1: the file's separator ('sep={named}') is the decimal mark "
                f"{decimal!r}; pass the file's decimal mark, e.g. decimal=','."
            )
        delimiter = named
        lines[0] = "# " + lines[0]  # skipped below like a comment line
    # Leading blank and comment lines are read as raw text: JSON metadata holds commas and
    # quotes that a CSV reader would split.
    first = 0
    while first < len(lines) and (not lines[first].strip() or lines[first].lstrip()[:1] == "#"):
        text = lines[first].strip()
        if text.startswith(_CSV_METADATA_PREFIX):
            metadata.update(_decode_json(text[len(_CSV_METADATA_PREFIX) :], "metadata", source))
        first += 1
    rows = csv.reader(lines[first:], delimiter=delimiter)
    header = next(rows, None)
    if header is None:
        raise ValueError(f"{source} is empty; it needs a header row such as 't,q,u'.")
    if len(header) == 1 and (hint := delimiter_hint(lines[first], delimiter)):
        raise ValueError(f"{source}, line {first + 1}: {hint}")
    column_names: list[str] = []
    units: dict[str, str] = {}
    for i, cell in enumerate(header):
        name, unit = parse_header(cell)
        if not name or "[" in name or "]" in name:
            raise ValueError(
                f"{source}, line {first + 1}: header cell {i + 1} ({cell!r}) is not "
                "'name' or 'name [unit]' (or 'name (unit)', 'name/unit'); give every column a "
                "name."
            )
        if name in column_names:
            raise ValueError(
                f"{source}: column name {name!r} appears twice in the header; rename one of "
                "the columns."
            )
        column_names.append(name)
        if unit:
            units[name] = unit
    values: list[list[float]] = []
    for row in rows:
        line = first + rows.line_num
        if not row or not "".join(row).strip():
            continue
        if len(row) != len(column_names):
            raise ValueError(
                f"{source}, line {line}: {len(row)} cells but the header has "
                f"{len(column_names)} columns; complete or remove that line (a truncated "
                "file ends this way)."
            )
        parsed = []
        if not values and not units and _is_units_row(row):
            shown = ", ".join(f"'{n} [{c.strip()}]'" for n, c in zip(column_names, row))
            raise ValueError(
                f"{source}, line {line} holds units ({', '.join(repr(c) for c in row)}), not "
                f"numbers: move them into the header as {shown} (jaxvs converts to SI), then "
                "the data start on the line after the header."
            )
        for name, cell in zip(column_names, row):
            try:
                parsed.append(float(cell if decimal == "." else cell.replace(decimal, ".")))
            except ValueError:
                raise ValueError(
                    f"{source}, line {line}, column {name!r}: cell {cell!r} is not a number; "
                    + (
                        decimal_hint(cell, decimal)
                        or "every cell below the header must be numeric (write nan for a "
                        "missing value)."
                    )
                ) from None
        values.append(parsed)
    if not values:
        raise ValueError(f"{source} has a header but no data rows; add one row per sample.")
    table = np.asarray(values, dtype=np.float64)
    columns = {name: table[:, i] for i, name in enumerate(column_names)}
    return _build(
        columns,
        time=time,
        dt=dt,
        names=_names_list(names),
        units=units,
        metadata=metadata,
        source=source,
        found=column_names,
        time_rtol=time_rtol,
    )


def _is_units_row(row: list[str]) -> bool:
    """A row of unit names under the header (every cell a short non-numeric word)."""

    def number(cell: str) -> bool:
        try:
            float(cell.replace(",", "."))
        except ValueError:
            return False
        return True

    cells = [c.strip() for c in row]
    return all(c and len(c) <= 12 and not number(c) and c.lower() != "nan" for c in cells)


def save_csv(record: Record, path: PathLike) -> Path:
    """Write `record` as CSV: metadata as a `# metadata: {json}` comment, a header
    `t [s],name [unit],...`, then one row per sample with full float precision.

    **Returns:**

    The path written.
    """
    file = Path(path)
    header = ["t [s]"] + [
        f"{name} [{record.units[name]}]" if name in record.units else name for name in record.names
    ]
    for name in record.names:
        if any(char in name for char in '[],\n\r"#'):
            raise ValueError(
                f"Signal name {name!r} cannot be written to a CSV header; rename it without "
                "brackets, commas, quotes or '#'."
            )
    table = np.column_stack([record.t, record.to_array()])
    with open(file, "w", newline="", encoding="utf-8") as handle:
        if record.metadata:
            handle.write(f"{_CSV_METADATA_PREFIX} {_metadata_json(record)}\n")
        writer = csv.writer(handle)
        writer.writerow(header)
        for row in table:
            writer.writerow([repr(float(value)) for value in row])
    return file


# --- NPZ -------------------------------------------------------------------------------------


def load_npz(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time: str = "t",
    dt: float | None = None,
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> Record:
    """Load a NumPy `.npz` archive: 1-D arrays (or `[n, 1]` columns) with the length of the
    time array are signals; size-1 arrays and strings go to metadata as Python scalars;
    other arrays go to metadata as read-only arrays. Units and metadata written by
    `save_npz` are restored. Pickled objects are refused.

    **Arguments:** as `load`.

    **Returns:**

    A `Record`.
    """
    file = existing_file(path)
    source = f"NPZ file {str(file)!r}"
    try:
        # The file is opened here so that it is closed when NumPy fails half-way.
        with open(file, "rb") as handle, np.load(handle, allow_pickle=False) as archive:
            if not hasattr(archive, "files"):
                raise ValueError("it holds a single .npy array, not an archive of named arrays")
            _check_npz_sizes(archive)
            variables = {key: archive[key] for key in archive.files}
    except Exception as error:
        # zipfile, zlib, EOF and format errors of a truncated or foreign file, and pickled
        # objects (refused: loading them runs code): one refusal naming the file.
        raise ValueError(
            f"{source} cannot be read as a NumPy .npz archive of numeric arrays ({error}). "
            "Check that the file is complete and was written with np.savez or save_npz."
        ) from None
    return _from_variables(
        variables, time=time, dt=dt, names=names, source=source, time_rtol=time_rtol
    )


def _check_npz_sizes(archive: Any) -> None:
    """Each member's array header must not declare more bytes than the member holds, so a
    damaged or crafted header cannot make NumPy allocate more than the archive contains."""
    for info in archive.zip.infolist():
        with archive.zip.open(info) as member:
            version = np.lib.format.read_magic(member)
            read = (
                np.lib.format.read_array_header_1_0
                if version == (1, 0)
                else np.lib.format.read_array_header_2_0
            )
            shape, _, dtype = read(member)
        need = int(np.prod(shape, dtype=object)) * dtype.itemsize
        if need > info.file_size:
            raise ValueError(
                f"its member {info.filename} declares {need} bytes of data but holds "
                f"{info.file_size}; it is truncated or edited"
            )


def _from_variables(
    variables: dict[str, np.ndarray],
    *,
    time: str,
    dt: float | None,
    names: Iterable[str] | str | None,
    source: str,
    time_rtol: float,
    units: dict[str, str] | None = None,
    metadata: dict[str, Any] | None = None,
) -> Record:
    """A `Record` from the named arrays of a binary file (NPZ, MAT, HDF5): the arrays of the
    time vector's length are signals, the rest metadata (after `metadata`, which holds what
    the format stores elsewhere); the units and metadata that jaxvs writers store as JSON
    (`jaxvs_units`, `jaxvs_metadata`) are restored."""
    units = dict(units or {})
    stored_metadata: dict[str, Any] = {}
    if _UNITS_KEY in variables:
        units.update(_decode_json(variables.pop(_UNITS_KEY), "units", source))
    if _METADATA_KEY in variables:
        stored_metadata = _decode_json(variables.pop(_METADATA_KEY), "metadata", source)
    columns, found_metadata = _split_variables(
        variables, time=time, source=source, names=_names_list(names)
    )
    return _build(
        columns,
        time=time,
        dt=dt,
        names=_names_list(names),
        units=units,
        metadata={**found_metadata, **(metadata or {}), **stored_metadata},
        source=source,
        found=variables,
        time_rtol=time_rtol,
    )


def save_npz(record: Record, path: PathLike) -> Path:
    """Write `record` as an uncompressed `.npz`: one array per signal, `t` [s], and units
    and metadata as JSON strings (`jaxvs_units`, `jaxvs_metadata`).

    **Returns:**

    The path written (NumPy appends `.npz` when missing).
    """
    file = Path(path)
    if file.suffix != ".npz":
        file = file.with_name(file.name + ".npz")
    _check_writable_names(record, reserved=("t", _UNITS_KEY, _METADATA_KEY))
    arrays = {name: np.asarray(record[name]) for name in record.names}
    np.savez(
        file,
        t=record.t,
        **arrays,
        **{_UNITS_KEY: np.array(json.dumps(record.units))},
        **{_METADATA_KEY: np.array(_metadata_json(record))},
    )
    return file


def _check_writable_names(record: Record, reserved: Sequence[str]) -> None:
    for name in record.names:
        if name in reserved:
            raise ValueError(
                f"Signal name {name!r} is reserved in jaxvs files ({', '.join(reserved)}); "
                "rename it first with record.rename({...})."
            )


# --- MAT -------------------------------------------------------------------------------------


def _read_mat(file: Path, *, names_only: bool = False) -> dict[str, Any]:
    """The variables of a MAT file (or only their names, as keys with value `None`)."""
    import scipy.io

    try:
        if names_only:
            return {name: None for name, *_ in scipy.io.whosmat(file)}
        content = scipy.io.loadmat(file, squeeze_me=False, mat_dtype=False)
    except NotImplementedError:
        raise ValueError(
            f"{str(file)!r} is a MATLAB v7.3 file, which is HDF5 inside; load it with "
            "load_hdf5 (or save it in MATLAB with -v7)."
        ) from None
    except Exception as error:
        # scipy reports a truncated or foreign file with many exception types (MatReadError,
        # ValueError, IndexError, struct.error, zlib.error ...): one refusal naming the file.
        raise ValueError(
            f"MAT file {str(file)!r} cannot be read ({type(error).__name__}: {error}). Check "
            "that the file is complete and a MATLAB v5/v7 .mat file; export it again."
        ) from None
    return {key: value for key, value in content.items() if not key.startswith("__")}


def load_mat(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time: str = "t",
    dt: float | None = None,
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> Record:
    """Load a MATLAB v5/v7 `.mat` file (`scipy.io.loadmat`).

    Column or row vectors with the length of the time vector are signals (squeezed to 1-D);
    scalar variables and strings go to metadata as Python scalars; other variables
    (matrices, structs, cells) go to metadata unchanged. Units and metadata written by
    `save_mat` are restored. Use `load_emps` (or `load`) for the EMPS benchmark files.

    **Arguments:** as `load`.

    **Returns:**

    A `Record`.
    """
    file = existing_file(path)
    variables = _read_mat(file)
    return _from_variables(
        variables,
        time=time,
        dt=dt,
        names=names,
        source=f"MAT file {str(file)!r}",
        time_rtol=time_rtol,
    )


def save_mat(record: Record, path: PathLike) -> Path:
    """Write `record` as a MATLAB v5 `.mat` file: one column vector per signal, `t` [s],
    and units and metadata as JSON strings (`jaxvs_units`, `jaxvs_metadata`).

    **Returns:**

    The path written.
    """
    import scipy.io

    file = Path(path)
    _check_writable_names(record, reserved=("t", _UNITS_KEY, _METADATA_KEY))
    for name in record.names:
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", name):
            raise ValueError(
                f"Signal name {name!r} is not a valid MATLAB variable name (letter first, then "
                "letters, digits, underscores); rename it first."
            )
    content: dict[str, Any] = {"t": record.t[:, None]}
    content.update({name: np.asarray(record[name])[:, None] for name in record.names})
    content[_UNITS_KEY] = json.dumps(record.units)
    content[_METADATA_KEY] = _metadata_json(record)
    scipy.io.savemat(file, content, format="5", do_compression=False, oned_as="column")
    return file


# --- HDF5 ------------------------------------------------------------------------------------


def _attr_value(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray):
        scalar = _scalar(value)
        if scalar is not None:
            return scalar
        value = np.array(value, copy=True)
        value.setflags(write=False)
        return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def load_hdf5(
    path: PathLike,
    *,
    names: Iterable[str] | str | None = None,
    time: str = "t",
    dt: float | None = None,
    time_rtol: float = DEFAULT_TIME_RTOL,
) -> Record:
    """Load an HDF5 file (`h5py`, opened read-only).

    Every dataset in the file is visited, in creation order where the file tracks it, else
    alphabetically (a dataset in a group is named by its path without the leading `/`, e.g.
    `axis_x/q`). Datasets with the length of the time dataset are
    signals, with the unit from their `unit` (or `units`) attribute; scalar datasets and the
    root group's attributes go to metadata; other datasets go to metadata as read-only
    arrays. The metadata written by `save_hdf5` (attribute `jaxvs_metadata`) are restored.

    **Arguments:** as `load`.

    **Returns:**

    A `Record`.
    """
    import h5py

    file = existing_file(path)
    source = f"HDF5 file {str(file)!r}"
    variables: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    metadata: dict[str, Any] = {}
    try:
        handle = h5py.File(file, "r")
    except OSError as error:
        raise ValueError(
            f"{source} cannot be read as HDF5 ({error}). Check that the file is complete and "
            "an HDF5 file; copy or export it again."
        ) from None
    with handle:

        def visit(group: Any, prefix: str) -> None:
            # Iterating a group (unlike `visititems`) keeps the creation order when the
            # file tracks it, so signals come back in the order they were written.
            for key in group.keys():
                name = prefix + key
                item = group[key]  # unlike items(), raises for an object it cannot open
                if isinstance(item, h5py.Group):
                    visit(item, name + "/")
                    continue
                if not isinstance(item, h5py.Dataset):
                    continue
                if item.dtype.kind in "SO" and item.shape == ():
                    value = item.asstr()[()] if item.dtype.kind == "O" else item[()].decode()
                    variables[name] = np.array(value)
                elif item.dtype.kind in "biuf":
                    variables[name] = np.asarray(item[()])
                else:
                    metadata[name] = _attr_value(item[()])
                unit = item.attrs.get("unit", item.attrs.get("units"))
                if unit is not None:
                    units[name] = str(_attr_value(unit))

        try:
            visit(handle, "")
            attributes = {key: _attr_value(value) for key, value in handle.attrs.items()}
        except (OSError, KeyError, RuntimeError, TypeError) as error:
            # h5py reports damaged objects (a truncated or overwritten file) only on access.
            raise ValueError(
                f"{source} is damaged: an object in it cannot be read ({error}). Check that "
                "the file is complete; copy or export it again."
            ) from None
    stored = attributes.pop(_METADATA_KEY, None)
    if stored is not None:
        variables[_METADATA_KEY] = np.array(stored)
    return _from_variables(
        variables,
        time=time,
        dt=dt,
        names=names,
        source=source,
        time_rtol=time_rtol,
        units=units,
        metadata={**metadata, **attributes},
    )


def save_hdf5(record: Record, path: PathLike) -> Path:
    """Write `record` as HDF5: one dataset per signal at the root with a `unit` attribute,
    a dataset `t` [s] (`unit = "s"`), and the metadata as JSON in the root attribute
    `jaxvs_metadata`.

    **Returns:**

    The path written.
    """
    import h5py

    file = Path(path)
    _check_writable_names(record, reserved=("t",))
    for name in record.names:
        if "/" in name:
            raise ValueError(
                f"Signal name {name!r} contains '/', which HDF5 reads as a group; rename it."
            )
    # Checksums everywhere, so a damaged copy is refused instead of read with wrong numbers:
    # the HDF5 1.8 file format (readable by HDF5 >= 1.8, MATLAB, h5py) checksums object
    # headers, links and attributes; Fletcher-32 checksums each dataset's data.
    with h5py.File(file, "w", track_order=True, libver=("v108", "latest")) as handle:
        handle.create_dataset("t", data=record.t, fletcher32=True).attrs["unit"] = "s"
        for name in record.names:
            dataset = handle.create_dataset(name, data=np.asarray(record[name]), fletcher32=True)
            if name in record.units:
                dataset.attrs["unit"] = record.units[name]
        handle.attrs[_METADATA_KEY] = _metadata_json(record)
    return file


# --- EMPS ------------------------------------------------------------------------------------

_EMPS_REQUIRED = ("t", "qm", "qg", "vir", "kp", "kv", "gtau")


def load_emps(path: PathLike, *, time_rtol: float = DEFAULT_TIME_RTOL) -> Record:
    """Load an EMPS benchmark file (`DATA_EMPS.mat` or `DATA_EMPS_PULSES.mat`) as it is
    distributed (Janot, Gautier, Brunot 2019), with jaxvs' canonical drive names.

    | file | record | unit |
    |---|---|---|
    | `qm` measured motor position (load side) | `q` | m |
    | `qg` reference position | `r` | m |
    | `gtau·vir` motor force | `u` | N |
    | `vir` controller output | `vir` | V |
    | `pulses_N` force pulses (validation file only), as stored | `pulses` | — |

    The scalars `kp` [1/s], `kv` [V/(m/s)] and `gtau` [N/V] go to the metadata, with
    `"source": "EMPS"` and the file name. The controller is
    `vir = kp·kv·(qg − qm) − kv·q̇m` (description, §1.3), the force `gtau·vir`.

    On the pulses: `pulses_N` is a 0/5 square wave (0.5 s on, 0.5 s off) that the
    description calls "given in N". The recorded `vir` already contains them: it equals the
    controller law applied to `qm`, `qg` plus ≈5.07 V while a pulse is on, so `u = gtau·vir`
    is the *total* motor force including the pulses, and a rigid-body fit of
    `M q̈ + Fv q̇ + Fc sign(q̇) + offset = u` gives the pulses no extra weight. They are
    therefore kept under the neutral name `pulses` without a unit, not as an external force
    `f_ext` to add to `u` (that would count them twice).

    **Arguments:**

    - `path`: the `.mat` file.
    - `time_rtol`: tolerance of the uniform-time check (the files jitter by ≈3e-5·dt).

    **Returns:**

    A `Record` with 1 kHz sampling.

    **Raises:**

    `ValueError` when a required EMPS variable is missing.
    """
    file = existing_file(path)
    variables = _read_mat(file)
    missing = [name for name in _EMPS_REQUIRED if name not in variables]
    if missing:
        raise ValueError(
            f"{str(file)!r} is not an EMPS benchmark file: missing {missing} (found "
            f"{sorted(variables)}). Use load_mat for other MAT files."
        )

    def column(name: str) -> np.ndarray:
        return np.asarray(variables[name], dtype=np.float64).reshape(-1)

    def scalar(name: str) -> float:
        value = np.asarray(variables[name], dtype=np.float64)
        if value.size != 1:
            raise ValueError(f"EMPS variable {name!r} should be a scalar, got shape {value.shape}.")
        return float(value.reshape(()))

    gains = {name: scalar(name) for name in ("kp", "kv", "gtau")}
    signals = {
        "q": column("qm"),
        "r": column("qg"),
        "u": gains["gtau"] * column("vir"),
        "vir": column("vir"),
    }
    units = {"q": "m", "r": "m", "u": "N", "vir": "V"}
    if "pulses_N" in variables:
        signals["pulses"] = column("pulses_N")
    metadata: dict[str, Any] = {**gains, "source": "EMPS", "file": file.name}
    try:
        return Record(signals, t=column("t"), units=units, metadata=metadata, time_rtol=time_rtol)
    except ValueError as error:
        raise ValueError(f"EMPS file {str(file)!r}: {error}") from None
