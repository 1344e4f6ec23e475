"""Bad-input matrix, loaders: every public loader against broken, truncated, mislabelled and
borderline files (row format in `tests/bad_input.py`).

Each defect is written once as data and run through the format's own loader and through
`jaxvs.data.load`, so both entry points get the same row. A refused file must name the file
(or the variable) and say what to do; a borderline file that is legal must load exactly what
was written.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
from bad_input import Case, run_case

from jaxvs.data import (
    FRFData,
    Record,
    load,
    load_csv,
    load_emps,
    load_frf,
    load_hdf5,
    load_mat,
    load_mdf,
    load_npz,
    load_sinumerik,
    load_sinumerik_frf,
    load_tdms,
    load_twincat_scope,
    load_uff_frf,
    load_uff_record,
    save_csv,
    save_hdf5,
    save_mat,
    save_npz,
    save_uff,
)

N = 40
DT = 0.01
T = DT * np.arange(N)
Q = np.sin(2 * np.pi * 3 * T)
U = np.cos(2 * np.pi * 5 * T)

# --- writers of named variables (NPZ, MAT, HDF5) ---------------------------------------------


def _npz(path: Path, variables: dict, units: dict) -> Path:
    extra = {"jaxvs_units": np.array(json.dumps(units))} if units else {}
    np.savez(path, **variables, **extra)
    return path


def _mat(path: Path, variables: dict, units: dict) -> Path:
    content = {k: (np.asarray(v)[:, None] if np.ndim(v) == 1 else v) for k, v in variables.items()}
    if units:
        content["jaxvs_units"] = json.dumps(units)
    scipy.io.savemat(path, content)
    return path


def _h5(path: Path, variables: dict, units: dict) -> Path:
    with h5py.File(path, "w", track_order=True) as f:
        for k, v in variables.items():
            f.create_dataset(k, data=v)
            if k in units:
                f[k].attrs["unit"] = units[k]
    return path


_BINARY = {
    "npz": (_npz, load_npz, "NPZ file"),
    "mat": (_mat, load_mat, "MAT file"),
    "h5": (_h5, load_hdf5, "HDF5 file"),
}


def _vars(**over) -> dict:
    base = {"t": T, "q": Q, "u": U}
    base.update(over)
    return {k: v for k, v in base.items() if v is not None}


def _check_record(expected: dict[str, np.ndarray], *, t=T, units=None, original=None, t_atol=1e-15):
    def check(record):
        assert isinstance(record, Record), record
        assert set(record.names) == set(expected), record.names
        for name, values in expected.items():
            # Writers store float64; readers must give back exactly what was written, up to
            # the float64 rounding of a unit conversion (one multiplication: 1e-15 rel.).
            np.testing.assert_allclose(record[name], values, rtol=1e-15, atol=1e-300)
        np.testing.assert_allclose(record.t, t, rtol=1e-12, atol=t_atol)  # grid t0 + k dt
        if units is not None:
            assert record.units == units, record.units
        if original is not None:
            assert dict(record.metadata.get("original_units", {})) == original

    return check


# (id, what, variables, units, loader kwargs, exception, match, check)
# fmt: off
_VARIABLE_DEFECTS: list[tuple] = [
    ("signal-shorter-than-t", "signal u has 30 samples, t has 40",
     _vars(u=U[:30]), {}, {}, ValueError, r"'u' has 30 samples.*'t' has 40.*Trim or resample"),
    ("signal-longer-than-t", "signal u has 45 samples, t has 40",
     _vars(u=np.r_[U, U[:5]]), {}, {}, ValueError, r"'u' has 45 samples.*Trim or resample"),
    ("short-signal-named", "names=['u'] and u is shorter than t",
     _vars(u=U[:30]), {}, {"names": ["u"]}, ValueError, r"'u' has 30 samples.*names="),
    ("short-signal-not-named", "u shorter than t but only names=['q'] requested",
     _vars(u=U[:30]), {}, {"names": ["q"]}, None, "", _check_record({"q": Q})),
    ("nan-in-signal", "NaN at sample 7 of q",
     _vars(q=np.where(np.arange(N) == 7, np.nan, Q)), {}, {}, ValueError,
     r"'q' has a non-finite value.*sample 7.*interpolate"),
    ("inf-in-signal", "+inf at sample 3 of u",
     _vars(u=np.where(np.arange(N) == 3, np.inf, U)), {}, {}, ValueError,
     r"'u' has a non-finite value.*sample 3.*interpolate"),
    ("nan-in-time", "NaN in the time vector",
     _vars(t=np.where(np.arange(N) == 5, np.nan, T)), {}, {}, ValueError,
     r"time vector has a non-finite value at sample 5"),
    ("time-decreasing", "time vector reversed",
     _vars(t=T[::-1].copy()), {}, {}, ValueError, r"not strictly increasing.*Sort the samples"),
    ("time-duplicate-stamp", "two samples with the same time stamp",
     _vars(t=np.r_[T[:10], T[9:N - 1]]), {}, {}, ValueError,
     r"not strictly increasing.*drop duplicated time stamps"),
    ("time-non-uniform", "one time stamp 0.3 dt off the grid",
     _vars(t=T + np.where(np.arange(N) == 11, 0.3 * DT, 0.0)), {}, {}, ValueError,
     r"not uniform.*sample 11.*resample"),
    ("time-jitter-legal", "time stamps jittered by 1e-5 dt (a real DAQ clock)",
     _vars(t=T + 1e-5 * DT * np.sin(np.arange(N))), {}, {}, None, "",
     # the stored grid is t0 + k dt fitted to the jittered stamps: within the 1e-5 dt jitter
     _check_record({"q": Q, "u": U}, t_atol=2e-5 * DT)),
    ("no-time", "no time vector, no dt",
     _vars(t=None), {}, {}, ValueError, r"no time column 't'.*pass dt="),
    ("no-time-with-dt", "no time vector, dt=0.01 given",
     _vars(t=None), {}, {"dt": DT}, None, "", _check_record({"q": Q, "u": U})),
    ("time-and-dt", "a time vector and dt=0.01",
     _vars(), {}, {"dt": DT}, ValueError, r"time column 't' and dt=.*pass only one"),
    ("time-named-other", "time stored as 'time', time='time' passed",
     {"time": T, "q": Q}, {}, {"time": "time"}, None, "", _check_record({"q": Q})),
    ("wrong-time-name", "time stored as 'time', default time='t'",
     {"time": T, "q": Q}, {}, {}, ValueError, r"no time column 't'.*time='<column name>'"),
    ("missing-signal", "names=['x'] not in the file",
     _vars(), {}, {"names": ["x"]}, KeyError, r"no signal 'x'.*available signals"),
    ("only-time", "the file holds only t",
     {"t": T}, {}, {}, ValueError, r"no signal besides the time column"),
    ("unit-mm", "q stored with unit 'mm'",
     _vars(), {"q": "mm"}, {}, None, "",
     _check_record({"q": Q / 1000, "u": U}, units={"q": "m"}, original={"q": "mm"})),
    ("unit-kN", "u stored with unit 'kN'",
     _vars(), {"u": "kN"}, {}, None, "",
     _check_record({"q": Q, "u": U * 1000}, units={"u": "N"}, original={"u": "kN"})),
    ("time-in-ms", "t stored in ms",
     _vars(t=T * 1000), {"t": "ms"}, {}, None, "",
     _check_record({"q": Q, "u": U}, original={"t": "ms"})),
    ("time-in-newton", "t stored with unit 'N'",
     _vars(), {"t": "N"}, {}, ValueError, r"'N'.*does not measure the same quantity as 's'"),
    ("unknown-unit", "q stored with unit 'blorps'",
     _vars(), {"q": "blorps"}, {}, ValueError, r"unknown unit 'blorps'.*pint reads"),
    ("ambiguous-g", "acceleration stored with unit 'g'",
     _vars(), {"q": "g"}, {}, ValueError, r"'g' is ambiguous.*'g0'"),
    ("raw-counts", "q stored with unit 'inc' (encoder increments)",
     _vars(), {"q": "inc"}, {}, ValueError, r"not a physical unit.*Scale the signal"),
    ("unit-number", "q stored with unit '1000'",
     _vars(), {"q": "1000"}, {}, ValueError, r"is a number, not a unit.*write the unit"),
    ("two-samples", "t and q with two samples each (the shortest legal record)",
     {"t": T[:2], "q": Q[:2]}, {}, {"time": "t"}, None, "",
     _check_record({"q": Q[:2]}, t=T[:2])),
    ("column-vector", "q stored as an (n, 1) column",
     _vars(q=Q[:, None]), {}, {}, None, "", _check_record({"q": Q, "u": U})),
    ("integer-signal", "u stored as int32 counts",
     _vars(u=np.arange(N, dtype=np.int32)), {}, {}, None, "",
     _check_record({"q": Q, "u": np.arange(N, dtype=float)})),
    ("matrix-metadata", "a 3x3 matrix beside the signals (kept as metadata)",
     _vars(K=np.eye(3)), {}, {}, None, "", _check_record({"q": Q, "u": U})),
    ("short-vector-metadata", "a 3-element gain vector beside the signals",
     _vars(gains=np.array([1.0, 2.0, 3.0])), {}, {}, None, "", _check_record({"q": Q, "u": U})),
]
# fmt: on


def _binary_case(fmt: str, entry: str, row: tuple) -> Case:
    ident, what, variables, units, kwargs, exc, match, *rest = row
    writer, loader, label = _BINARY[fmt]
    fn = loader if entry == "own" else load
    name = f"jaxvs.data.{loader.__name__}" if entry == "own" else "jaxvs.data.load"
    if exc is ValueError and "samples but" in match:
        match = label + ".*" + match  # the refusal names the file

    def run(tmp: Path):
        path = writer(tmp / f"m.{fmt}", variables, units)
        return fn(path, **kwargs)

    return Case(
        id=f"{fmt}-{entry}-{ident}",
        area="loaders",
        entry=name,
        input=f"{fmt.upper()}: {what}",
        run=run,
        exc=exc,
        match=match,
        check=rest[0] if rest else None,
    )


CASES: list[Case] = [
    _binary_case(fmt, entry, row)
    for fmt in _BINARY
    for entry in ("own", "load")
    for row in _VARIABLE_DEFECTS
]

# --- damaged files, any format ---------------------------------------------------------------


def _valid_record() -> Record:
    return Record({"q": Q, "u": U}, t=T, units={"q": "m", "u": "N"}, metadata={"axis": "X"})


def _write_valid(fmt: str, path: Path) -> Path:
    record = _valid_record()
    if fmt == "csv":
        return save_csv(record, path)
    if fmt == "npz":
        return save_npz(record, path)
    if fmt == "mat":
        return save_mat(record, path)
    if fmt == "h5":
        return save_hdf5(record, path)
    return save_uff(path, record, binary=fmt == "uff")


_LOADERS: dict[str, Callable] = {
    "csv": load_csv,
    "npz": load_npz,
    "mat": load_mat,
    "h5": load_hdf5,
    "uff": load_uff_record,
    "unv": load_uff_record,  # ASCII UFF
}


def _damage(kind: str) -> Callable[[bytes], bytes]:
    rng = np.random.default_rng(15)
    return {
        "empty": lambda b: b"",
        "random-bytes": lambda b: rng.integers(0, 256, 600, dtype=np.uint8).tobytes(),
        "first-half": lambda b: b[: len(b) // 2],
        "first-90%": lambda b: b[: int(len(b) * 0.9)],
        "first-16-bytes": lambda b: b[:16],
        "zeroed-middle": lambda b: b[: len(b) // 3] + bytes(len(b) // 3) + b[2 * (len(b) // 3) :],
    }[kind]


_DAMAGE_TEXT = {
    "empty": "an empty file (0 bytes)",
    "random-bytes": "600 random bytes",
    "first-half": "the first half of a valid file",
    "first-90%": "the first 90 % of a valid file",
    "first-16-bytes": "the first 16 bytes of a valid file",
    "zeroed-middle": "a valid file with its middle third zeroed",
}


def _damaged_case(fmt: str, kind: str, entry: str) -> Case:
    loader = _LOADERS[fmt] if entry == "own" else load
    suffix = {"h5": ".h5", "unv": ".unv"}.get(fmt, "." + fmt)

    def run(tmp: Path):
        path = _write_valid(fmt, tmp / f"good{suffix}")
        path.write_bytes(_damage(kind)(path.read_bytes()))
        before = path.read_bytes()
        try:
            return loader(path)
        finally:
            assert path.read_bytes() == before, "the loader modified the user's file"

    return Case(
        id=f"{fmt}-{entry}-{kind}",
        area="loaders",
        entry=f"jaxvs.data.{loader.__name__}",
        input=f"{fmt.upper()}: {_DAMAGE_TEXT[kind]}",
        run=run,
        exc=ValueError,
        # The refusal names the file (its name is in every message).
        match=r"good\.",
    )


CASES += [
    _damaged_case(fmt, kind, entry)
    for fmt in _LOADERS
    for kind in _DAMAGE_TEXT
    for entry in ("own", "load")
    # A CSV cut at half is still a CSV with fewer rows: only a cut inside a row is damage.
    if not (fmt == "csv" and kind in ("first-half", "first-90%", "zeroed-middle"))
]


def _missing_case(loader: Callable) -> Case:
    return Case(
        id=f"missing-file-{loader.__name__}",
        area="loaders",
        entry=f"jaxvs.data.{loader.__name__}",
        input="a path that does not exist",
        run=lambda tmp: loader(tmp / "nowhere" / "x.csv"),
        exc=FileNotFoundError,
        match=r"No such file.*nowhere.*Check the path",
    )


def _directory_case(loader: Callable) -> Case:
    return Case(
        id=f"directory-{loader.__name__}",
        area="loaders",
        entry=f"jaxvs.data.{loader.__name__}",
        input="a directory instead of a file",
        run=lambda tmp: loader(tmp),
        exc=ValueError,
        match=r"is a directory.*give the path of a file",
    )


_ALL_LOADERS = [
    load,
    load_csv,
    load_npz,
    load_mat,
    load_hdf5,
    load_emps,
    load_uff_record,
    load_uff_frf,
    load_frf,
    load_sinumerik,
    load_sinumerik_frf,
    load_tdms,
    load_mdf,
    load_twincat_scope,
]
CASES += [_missing_case(f) for f in _ALL_LOADERS]
CASES += [_directory_case(f) for f in _ALL_LOADERS]

# --- CSV text defects ------------------------------------------------------------------------


def _csv_text(rows: list[str], header: str = "t [s],q [m],u [N]") -> str:
    return "\n".join([header, *rows]) + "\n"


_GOOD_ROWS = [f"{float(t)!r},{float(q)!r},{float(u)!r}" for t, q, u in zip(T, Q, U)]
_MS_ROWS = [f"{float(t) * 1000!r},{float(q)!r},{float(u)!r}" for t, q, u in zip(T, Q, U)]


def _rows(edit: Callable[[list[str]], list[str]]) -> list[str]:
    return edit(list(_GOOD_ROWS))


def _set(rows: list[str], i: int, value: str) -> list[str]:
    rows[i] = value
    return rows


# fmt: off
_CSV_DEFECTS: list[tuple] = [
    ("text-cell", "cell 'abc' in row 5", _csv_text(_rows(lambda r: _set(r, 4, "0.04,abc,1.0"))),
     {}, ValueError, r"line 6, column 'q': cell 'abc' is not a number.*must be numeric"),
    ("empty-cell", "an empty cell in row 3", _csv_text(_rows(lambda r: _set(r, 2, "0.02,,1.0"))),
     {}, ValueError, r"line 4, column 'q': cell '' is not a number"),
    ("short-row", "a row with 2 of 3 cells", _csv_text(_rows(lambda r: _set(r, 9, "0.09,1.0"))),
     {}, ValueError, r"line 11: 2 cells but the header has 3 columns"),
    ("long-row", "a row with 4 cells", _csv_text(_rows(lambda r: _set(r, 9, "0.09,1,2,3"))),
     {}, ValueError, r"line 11: 4 cells but the header has 3 columns"),
    ("cut-inside-row", "the file cut in the middle of its last row",
     _csv_text(_GOOD_ROWS)[:-12], {}, ValueError, r"ends inside a row.*truncated.*Export it again"),
    ("nan-cell", "a 'nan' cell", _csv_text(_rows(lambda r: _set(r, 6, "0.06,nan,1.0"))),
     {}, ValueError, r"'q' has a non-finite value.*sample 6.*interpolate"),
    ("inf-cell", "an 'inf' cell", _csv_text(_rows(lambda r: _set(r, 6, "0.06,1.0,inf"))),
     {}, ValueError, r"'u' has a non-finite value.*sample 6"),
    ("header-only", "a header and no data rows", _csv_text([]), {}, ValueError,
     r"header but no data rows"),
    ("empty-text", "an empty file", "", {}, ValueError, r"is empty.*header row"),
    ("blank-lines-only", "only blank lines", "\n\n\n", {}, ValueError, r"is empty.*header row"),
    ("duplicate-column", "column 'q' twice", _csv_text(_GOOD_ROWS, "t,q,q"), {}, ValueError,
     r"column name 'q' appears twice"),
    ("empty-header-cell", "an empty header cell", _csv_text(_GOOD_ROWS, "t,,u"), {}, ValueError,
     r"header cell 2.*is not 'name' or 'name \[unit\]'"),
    ("no-time-column", "columns x,q,u without t", _csv_text(_GOOD_ROWS, "x,q,u"), {},
     ValueError, r"no time column 't'.*columns found.*pass dt="),
    ("time-unit-ms", "header 't [ms]'", _csv_text(_MS_ROWS, "t [ms],q [m],u [N]"), {},
     None, "", _check_record({"q": Q, "u": U}, original={"t": "ms"})),
    ("q-in-mm", "header 'q [mm]'", _csv_text(_GOOD_ROWS, "t [s],q [mm],u [N]"), {}, None, "",
     _check_record({"q": Q / 1000, "u": U}, units={"q": "m", "u": "N"}, original={"q": "mm"})),
    ("q-in-um-parens", "header 'q (µm)'", _csv_text(_GOOD_ROWS, "t [s],q (µm),u [N]"), {},
     None, "", _check_record({"q": Q * 1e-6, "u": U}, original={"q": "µm"})),
    ("temperature-kelvin", "header 'T [K]'", _csv_text(_GOOD_ROWS, "t [s],T [K],u [N]"), {},
     None, "", _check_record({"T": Q - 273.15, "u": U}, units={"T": "degC", "u": "N"})),
    ("time-unit-newton", "header 't [N]'", _csv_text(_GOOD_ROWS, "t [N],q,u"), {}, ValueError,
     r"'N'.*does not measure the same quantity as 's'.*correct its unit"),
    ("unknown-unit", "header 'q [blorps]'", _csv_text(_GOOD_ROWS, "t,q [blorps],u"), {},
     ValueError, r"signal 'q': unknown unit 'blorps'.*pint reads"),
    ("unit-g", "header 'a [g]'", _csv_text(_GOOD_ROWS, "t,a [g],u"), {}, ValueError,
     r"'g' is ambiguous.*'g0'.*'gram'"),
    ("unit-inc", "header 'q [inc]'", _csv_text(_GOOD_ROWS, "t,q [inc],u"), {}, ValueError,
     r"not a physical unit.*Scale the signal"),
    ("bom", "UTF-8 byte-order mark before the header", "\ufeff" + _csv_text(_GOOD_ROWS), {},
     None, "", _check_record({"q": Q, "u": U})),
    ("crlf", "Windows line endings", _csv_text(_GOOD_ROWS).replace("\n", "\r\n"), {}, None, "",
     _check_record({"q": Q, "u": U})),
    ("comment-lines", "'#' comment lines before the header",
     "# exported by scope\n# axis X\n" + _csv_text(_GOOD_ROWS), {}, None, "",
     _check_record({"q": Q, "u": U})),
    ("trailing-blank-lines", "blank lines after the data", _csv_text(_GOOD_ROWS) + "\n\n\n", {},
     None, "", _check_record({"q": Q, "u": U})),
    ("bad-metadata-json", "a '# metadata:' line that is not JSON",
     "# metadata: {axis: X\n" + _csv_text(_GOOD_ROWS), {}, ValueError,
     r"stored metadata are not valid JSON"),
    ("unsorted-time", "rows out of time order", _csv_text(_GOOD_ROWS[::-1]), {}, ValueError,
     r"not strictly increasing.*Sort the samples"),
    ("gap-in-time", "one row missing (a gap of 2 dt)",
     _csv_text(_GOOD_ROWS[:10] + _GOOD_ROWS[11:]), {}, ValueError, r"not uniform.*resample"),
    ("names-missing", "names=['x']", _csv_text(_GOOD_ROWS), {"names": ["x"]}, KeyError,
     r"no signal 'x'.*available signals"),
    ("dt-and-time", "a time column and dt=0.01", _csv_text(_GOOD_ROWS), {"dt": DT}, ValueError,
     r"pass only one of them"),
    ("dt-zero", "no time column, dt=0", _csv_text(_GOOD_ROWS, "x,q,u"), {"dt": 0.0},
     ValueError, r"dt must be a positive finite sampling period"),
    ("dt-negative", "no time column, dt=-0.01", _csv_text(_GOOD_ROWS, "x,q,u"), {"dt": -DT},
     ValueError, r"dt must be a positive finite sampling period"),
    ("dt-nan", "no time column, dt=nan", _csv_text(_GOOD_ROWS, "x,q,u"), {"dt": float("nan")},
     ValueError, r"dt must be a positive finite sampling period"),
    ("dt-huge", "no time column, dt=1e308", _csv_text(_GOOD_ROWS, "x,q,u"), {"dt": 1e308},
     ValueError, r"does not fit in float64.*give dt and t0 in seconds"),
    ("time-rtol-zero", "time_rtol=0", _csv_text(_GOOD_ROWS), {"time_rtol": 0.0}, ValueError,
     r"time_rtol must be a positive number"),
    ("two-runs-concatenated", "two runs one after the other (time restarting at 0)",
     _csv_text(_GOOD_ROWS + _GOOD_ROWS), {}, ValueError,
     r"restarts at sample 40.*holds 2 runs.*Split it into one record per run.*do not sort"),
    ("coarse-time-stamps", "a 5 kHz time column printed with 3 decimals",
     _csv_text([f"{k * 2e-4:.3f},{float(q)!r},{float(u)!r}" for k, (q, u) in
                enumerate(zip(Q, U))]), {},
     ValueError, r"repeats \d+ of its 40 stamps.*too few decimals.*Pass the sampling period "
     r"instead of the time column \(dt=.*do not drop the repeated stamps"),
    ("units-row", "a units row (s, m, N) under the header",
     _csv_text(["s,m,N", *_GOOD_ROWS], "t,q,u"), {}, ValueError,
     r"line 2 holds units \('s', 'm', 'N'\).*move them into the header as 't \[s\]', "
     r"'q \[m\]', 'u \[N\]'"),
    ("excel-sep-line", "Excel's 'sep=;' first line, ;-separated",
     "sep=;\n" + _csv_text([r.replace(",", ";") for r in _GOOD_ROWS], "t [s];q [m];u [N]"),
     {}, None, "", _check_record({"q": Q, "u": U})),
    ("excel-sep-line-other-delimiter", "'sep=;' first line but delimiter='\\t' given",
     "sep=;\n" + _csv_text([r.replace(",", ";") for r in _GOOD_ROWS], "t;q;u"),
     {"delimiter": "\t"}, ValueError, r"names its separator \('sep=;'\).*pass delimiter=';'"),
    ("thousands-separators", "force values with thousands separators (1,234.5) in a ;-file",
     _csv_text([f"{float(t)!r};1,{234 + k}.5;1.0" for k, t in enumerate(T)], "t;q;u"),
     {"delimiter": ";"}, ValueError,
     r"cell '1,234\.5' is not a number; it looks like a number with thousands separators.*"
     r"export the numbers without grouping"),
]
# fmt: on


def _csv_case(row: tuple, entry: str) -> Case:
    ident, what, text, kwargs, exc, match, *rest = row
    loader = load_csv if entry == "own" else load

    def run(tmp: Path):
        path = tmp / "m.csv"
        path.write_bytes(text.encode("utf-8"))
        return loader(path, **kwargs)

    return Case(
        id=f"csv-{entry}-{ident}",
        area="loaders",
        entry=f"jaxvs.data.{loader.__name__}",
        input=f"CSV: {what}",
        run=run,
        exc=exc,
        match=match,
        check=rest[0] if rest else None,
    )


CASES += [_csv_case(row, entry) for row in _CSV_DEFECTS for entry in ("own", "load")]

# --- UFF defects -----------------------------------------------------------------------------


def _uff_lines(tmp: Path) -> list[str]:
    record = Record({"q": Q, "u": U, "y": T}, dt=DT, units={"q": "mm"})
    return save_uff(tmp / "src.unv", record, binary=False).read_text().splitlines()


def _delims(lines: list[str]) -> list[int]:
    return [i for i, line in enumerate(lines) if line.strip() == "-1"]


def _uff_truncated_third(lines):
    return lines[: _delims(lines)[-2] + 20]


def _uff_text_line(lines):
    lines[_delims(lines)[2] + 16] = "    hello world"
    return lines


def _uff_drop_line(lines):
    del lines[_delims(lines)[4] + 15]
    return lines


def _uff_no_closing(lines):
    return lines[: _delims(lines)[-1]]


def _uff_unit_mm(lines):
    return lines


def _check_uff_mm(record):
    # 'mm' on the ordinate goes to m; the other signals are as written (ASCII UFF keeps 12
    # significant digits, %20.11e: 1e-11 relative).
    np.testing.assert_allclose(record["q"], Q / 1000, rtol=1e-11, atol=1e-15)
    np.testing.assert_allclose(record["u"], U, rtol=1e-11, atol=1e-15)
    assert record.units["q"] == "m" and record.metadata["original_units"] == {"q": "mm"}


# fmt: off
_UFF_DEFECTS = [
    ("truncated-in-third-dataset", "file cut inside its third time dataset",
     _uff_truncated_third, ValueError, r"ends inside dataset 3.*truncated.*again"),
    ("text-data-line", "one data line replaced by text", _uff_text_line, ValueError,
     r"dataset 1 announces 40 values but 36 could be read.*Repair or export"),
    ("dropped-data-line", "one data line deleted", _uff_drop_line, ValueError,
     r"dataset 2 announces 40 values but 36.*Repair or export"),
    ("no-closing-tag", "last '-1' delimiter missing", _uff_no_closing, ValueError,
     r"ends inside dataset.*truncated"),
    ("unit-mm", "ordinate unit label 'mm'", _uff_unit_mm, None, "", _check_uff_mm),
]
# fmt: on


def _uff_case(row: tuple, entry: str) -> Case:
    ident, what, edit, exc, match, *rest = row
    loader = load_uff_record if entry == "own" else load

    def run(tmp: Path):
        path = tmp / "m.unv"
        path.write_text("\n".join(edit(_uff_lines(tmp))) + "\n")
        return loader(path)

    return Case(
        id=f"uff-{entry}-{ident}",
        area="loaders",
        entry=f"jaxvs.data.{loader.__name__}",
        input=f"UFF: {what}",
        run=run,
        exc=exc,
        match=match,
        check=rest[0] if rest else None,
    )


CASES += [_uff_case(row, entry) for row in _UFF_DEFECTS for entry in ("own", "load")]

# --- FRF files and FRFData -------------------------------------------------------------------

_F = np.linspace(1.0, 100.0, 25)
_H = 1.0 / (1.0 + 1j * _F / 30.0)


def _frf_uff(tmp: Path) -> Path:
    return save_uff(tmp / "frf.uff", FRFData(_F, _H, kind="receptance"))


def _check_frf(frf):
    np.testing.assert_allclose(np.asarray(frf.frequency), _F, rtol=1e-15)  # binary 58b: exact
    np.testing.assert_allclose(np.asarray(frf.H), _H, rtol=1e-15)


# fmt: off
CASES += [
    Case("frf-uff-round-trip", "loaders", "jaxvs.data.load_uff_frf", "a valid FRF UFF file",
         lambda tmp: load_uff_frf(_frf_uff(tmp)), exc=None, check=_check_frf),
    Case("frf-load-time-file", "loaders", "jaxvs.data.load_uff_frf",
         "a UFF file with time responses only",
         lambda tmp: load_uff_frf(save_uff(tmp / "r.uff", _valid_record())),
         match=r"no FRF in the file.*time response"),
    Case("frf-record-from-frf-file", "loaders", "jaxvs.data.load_uff_record",
         "a UFF file with FRFs only", lambda tmp: load_uff_record(_frf_uff(tmp)),
         match=r"no time response in the file.*frequency response"),
    Case("frf-bad-layout", "loaders", "jaxvs.data.load_uff_frf", "layout='grid'",
         lambda tmp: load_uff_frf(_frf_uff(tmp), layout="grid"),
         match=r"layout must be 'auto', 'mimo' or 'batch'"),
    Case("frf-index-out-of-range", "loaders", "jaxvs.data.load_uff_frf", "index=[7]",
         lambda tmp: load_uff_frf(_frf_uff(tmp), index=[7]),
         match=r"dataset index \[7\] out of range"),
    Case("frf-load-frf-csv", "loaders", "jaxvs.data.load_frf", "load_frf of a CSV time record",
         lambda tmp: load_frf(save_csv(_valid_record(), tmp / "r.csv")),
         match=r"(FRF|frequency).*(\.unv|\.uff|\.xml|load\b)"),
]
# fmt: on


# --- hostile files: nothing blocks, loops or allocates more than the file holds ---------------
# Every row runs under a short time bound (`Case.timeout`): a FIFO that blocked the reader, or a
# header loop that never ended, fails the row instead of hanging.

_HOSTILE_S = 30.0


def _fifo(tmp: Path) -> Path:
    import os

    path = tmp / "pipe.csv"
    os.mkfifo(path)
    return path


def _loop(tmp: Path) -> Path:
    path = tmp / "loop.csv"
    path.symlink_to(path.name)  # points at itself
    return path


_SPECIAL = [
    (
        "fifo",
        "a named pipe (FIFO) given as the file",
        _fifo,
        ValueError,
        r"named pipe \(FIFO\), not a regular file.*save the data to a file",
    ),
    (
        "device",
        "/dev/zero given as the file",
        lambda tmp: Path("/dev/zero"),
        ValueError,
        r"is a device, not a regular file.*save the data to a file",
    ),
    (
        "link-loop",
        "a symbolic link that points to itself",
        _loop,
        ValueError,
        r"symbolic link loop.*give the path of the real file",
    ),
]


def _special_case(kind, text, make, exc, match, loader) -> Case:
    return Case(
        id=f"{kind}-{loader.__name__}",
        area="loaders",
        entry=f"jaxvs.data.{loader.__name__}",
        input=text,
        run=lambda tmp: loader(make(tmp)),
        exc=exc,
        match=match,
        timeout=_HOSTILE_S,
    )


CASES += [_special_case(*row, f) for row in _SPECIAL for f in _ALL_LOADERS]


def _scope_head() -> bytes:
    # the header of a TwinCAT Scope export, written here (no shared data needed)
    rows = [
        "Name;probe;",
        "File;C:\\probe.csv;",
        "Starttime of export;132959733843760000;Montag, 2. Mai 2022;15:56:24.376",
        "Endtime of export;132959733843850000;Montag, 2. Mai 2022;15:56:24.385",
        "",
        "",
        "Name;x;Name;y",
        "SymbolComment;;SymbolComment;",
        "Data-Type;REAL64;Data-Type;INT16",
        "SampleTime[ms];1;SampleTime[ms];1",
        "VariableSize;8;VariableSize;2",
        "SymbolBased;True;SymbolBased;True",
        "IndexGroup;1;IndexGroup;1",
        "IndexOffset;0;IndexOffset;8",
        "SymbolName;MAIN.x;SymbolName;MAIN.y",
        "NetID;1.1.1.1.1.1;NetID;1.1.1.1.1.1",
        "Port;851;Port;851",
        "Offset;0;Offset;0",
        "ScaleFactor;1;ScaleFactor;1",
        "BitMask;0xff;BitMask;0xff",
        "Unit;(None);Unit;(None)",
        "Unit ScaleFactor;1;Unit ScaleFactor;1",
        "Unit Offset;0;Unit Offset;0",
        "",
    ]
    return ("\r\n".join(rows) + "\r\n").encode()


def _scope_cut(tmp: Path) -> Path:
    path = tmp / "scope.csv"
    path.write_bytes(_scope_head())
    return path


def _scope_integers(tmp: Path) -> Path:
    path = tmp / "scope.csv"
    rows = "".join(f"{k};{k % 3};{k};{-k}\r\n" for k in range(10))
    path.write_bytes(_scope_head() + rows.encode())
    return path


def _check_scope_integers(result) -> None:
    records = result if isinstance(result, list) else [result]
    (record,) = records
    np.testing.assert_array_equal(np.asarray(record["x"]), np.arange(10) % 3)
    np.testing.assert_array_equal(np.asarray(record["y"]), -np.arange(10))


def _npz_huge_header(tmp: Path) -> Path:
    import io
    import zipfile

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.zeros(4))
    raw = buf.getvalue()
    n = int.from_bytes(raw[8:10], "little")
    head = "{'descr': '<f8', 'fortran_order': False, 'shape': (4000000000,), }"
    raw = raw[:10] + (head.ljust(n - 1) + "\n").encode() + raw[10 + n :]
    path = tmp / "huge.npz"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("t.npy", raw)
    return path


def _xml_bomb(tmp: Path) -> Path:
    entities = "".join(
        f'<!ENTITY e{i} "' + (f"&e{i - 1};" if i > 1 else "ha") * 10 + '">' for i in range(1, 10)
    )
    path = tmp / "bomb.xml"
    path.write_text(f'<?xml version="1.0"?><!DOCTYPE d [{entities}]><d>&e9;</d>')
    return path


def _tdms_huge_segment(tmp: Path) -> Path:
    import struct

    path = tmp / "huge.tdms"
    path.write_bytes(b"TDSm" + struct.pack("<IIQQ", 0xE, 4713, 2**60, 2**60) + bytes(64))
    return path


def _utf16(tmp: Path) -> Path:
    path = tmp / "unicode.csv"
    path.write_bytes(_csv_text(_GOOD_ROWS).encode("utf-16"))  # with its byte-order mark
    return path


def _tdms_short_channel(tmp: Path) -> Path:
    from nptdms import ChannelObject, TdmsWriter

    path = tmp / "short.tdms"
    with TdmsWriter(path) as w:
        w.write_segment([
            ChannelObject("g", "q", Q, properties={"wf_increment": DT}),
            ChannelObject("g", "u", U[:-10], properties={"wf_increment": DT}),
        ])
    return path


# fmt: off
CASES += [
    Case("csv-utf16-unicode-text", "loaders", "jaxvs.data.load",
         "Excel 'Unicode text' export (UTF-16 with byte-order mark)",
         lambda tmp: load(_utf16(tmp)), exc=None, check=_check_record({"q": Q, "u": U})),
    Case("tdms-channel-shorter", "loaders", "jaxvs.check",
         "TDMS whose force channel u is 10 samples shorter than q, given to check",
         lambda tmp: __import__("jaxvs").check(str(_tdms_short_channel(tmp)), family="drive"),
         match=r"in 'short\.tdms' the channel '[qu]' has \d+ samples but \['[qu]'\] have \d+ "
               r"\(a channel shorter than the others.*cut the channels to a common length"),
    Case("scope-cut-after-header", "loaders", "jaxvs.data.load_twincat_scope",
         "TwinCAT Scope export cut right after its header (no data row)",
         lambda tmp: load_twincat_scope(_scope_cut(tmp)),
         match=r"ends after its header.*no data row.*Export the recording again",
         timeout=_HOSTILE_S),
    Case("scope-cut-after-header-load", "loaders", "jaxvs.data.load",
         "TwinCAT Scope export cut right after its header, through load",
         lambda tmp: load(_scope_cut(tmp)),
         match=r"ends after its header.*Export the recording again", timeout=_HOSTILE_S),
    Case("scope-whole-numbers-only", "loaders", "jaxvs.data.load",
         "TwinCAT Scope export whose values are all whole numbers (no decimal mark anywhere)",
         lambda tmp: load(_scope_integers(tmp)), exc=None, check=_check_scope_integers,
         timeout=_HOSTILE_S),
    Case("npz-header-declares-32-GB", "loaders", "jaxvs.data.load_npz",
         "NPZ whose array header declares 4e9 float64 values in a 200-byte member",
         lambda tmp: load_npz(_npz_huge_header(tmp)),
         match=r"declares 32000000000 bytes.*holds.*truncated or edited.*save_npz",
         timeout=_HOSTILE_S),
    Case("xml-entity-bomb", "loaders", "jaxvs.data.load",
         "XML with nested entities expanding to 10^9 characters (billion laughs)",
         lambda tmp: load(_xml_bomb(tmp)),
         match=r"bomb\.xml.*not well-formed.*Save it again", timeout=_HOSTILE_S),
    Case("tdms-segment-of-2^60-bytes", "loaders", "jaxvs.data.load_tdms",
         "TDMS lead-in declaring a 2^60-byte segment",
         lambda tmp: load_tdms(_tdms_huge_segment(tmp)),
         match=r"huge\.tdms.*cannot be read as TDMS.*again", timeout=_HOSTILE_S),
]
# fmt: on


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)
