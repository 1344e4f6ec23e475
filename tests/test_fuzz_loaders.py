"""Property-based fuzzing of the loaders: random bytes, truncations, overwritten
bytes and cell edits of valid CSV / NPZ / MAT / HDF5 / UFF files must either load exactly
what the file holds or raise `ValueError` naming the file -- never a partial result, never
another exception type.

"Exactly what the file holds": for a file damaged at the byte level, the record written
before the damage (a format that cannot tell a changed number from a written one must not
be given such damage: CSV and ASCII UFF get cell edits instead, whose oracle is the edited
text parsed independently); for a CSV cut right after a line break, the rows before the cut
(a shorter CSV is a valid CSV).
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from jaxvs.data import (
    Record,
    load,
    load_csv,
    load_hdf5,
    load_mat,
    load_npz,
    load_uff_record,
    save_csv,
    save_hdf5,
    save_mat,
    save_npz,
    save_uff,
)

N = 12
DT = 0.5e-3
_RECORD = Record(
    {"q": np.sin(np.arange(N) / 3.0), "u": np.cos(np.arange(N) / 5.0) * 100.0},
    dt=DT,
    t0=0.25,
    units={"q": "m", "u": "N"},
)

# Few examples per property: the whole file stays well under a minute on one core (set
# JAXVS_FUZZ_EXAMPLES=500 for a deeper run by hand).
FUZZ = settings(
    max_examples=int(os.environ.get("JAXVS_FUZZ_EXAMPLES", "25")),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

_WRITERS = {
    "csv": (lambda p: save_csv(_RECORD, p), load_csv),
    "npz": (lambda p: save_npz(_RECORD, p), load_npz),
    "mat": (lambda p: save_mat(_RECORD, p), load_mat),
    "h5": (lambda p: save_hdf5(_RECORD, p), load_hdf5),
    "uff": (lambda p: save_uff(p, _RECORD, binary=True), load_uff_record),
    "unv": (lambda p: save_uff(p, _RECORD, binary=False), load_uff_record),
}
# Formats whose files detect a changed byte (zip CRC-32 of NPZ, HDF5 Fletcher-32 checksums
# written by save_hdf5): byte-level damage must be refused or harmless.
_CHECKED = ("npz", "h5")


def _valid_bytes(fmt: str, tmp: Path) -> bytes:
    path = tmp / f"valid.{fmt}"
    _WRITERS[fmt][0](path)
    return path.read_bytes()


def _same(record: Record, expected: Record, *, rtol: float = 0.0) -> None:
    assert isinstance(record, Record), record
    assert record.names == expected.names
    assert len(record) == len(expected)
    assert record.units == expected.units
    for name in expected.names:
        np.testing.assert_allclose(record[name], expected[name], rtol=rtol, atol=0)
    # the time base: same grid up to the rounding of t0 + k dt (1e-12 relative)
    np.testing.assert_allclose(record.t, expected.t, rtol=1e-12)


def _load_or_refuse(loader, path: Path):
    """The loaded record, or `None` after checking that the refusal is a ValueError naming
    the file."""
    try:
        return loader(path)
    except ValueError as error:
        assert path.name in str(error), f"refusal does not name the file: {error}"
        return None
    # any other exception type propagates and fails the property


@pytest.mark.parametrize("fmt", list(_WRITERS))
@FUZZ
@given(data=st.binary(min_size=0, max_size=400))
def test_random_bytes_are_refused(fmt, data, tmp_path):
    path = tmp_path / f"random.{fmt}"
    path.write_bytes(data)
    for loader in (_WRITERS[fmt][1], load):
        assert _load_or_refuse(loader, path) is None, "random bytes loaded as a record"


@pytest.mark.parametrize("fmt", list(_WRITERS))
@FUZZ
@given(cut=st.floats(min_value=0.0, max_value=1.0, exclude_max=True))
def test_truncated_files_are_refused(fmt, cut, tmp_path):
    valid = _valid_bytes(fmt, tmp_path)
    keep = int(cut * len(valid))
    path = tmp_path / f"cut.{fmt}"
    path.write_bytes(valid[:keep])
    record = _load_or_refuse(_WRITERS[fmt][1], path)
    if record is None:
        return
    if not valid[keep:].strip():
        _same(record, _RECORD)  # only the final line break was cut: the file is complete
        return
    # Otherwise only a CSV cut right after a line break is still a complete (shorter) file.
    assert fmt == "csv" and valid[keep - 1 : keep] in (b"\r", b"\n"), "a truncated file loaded"
    rows = len(valid[:keep].decode().splitlines()) - 1  # the header line
    _same(record, _RECORD.slice(0, rows))


@pytest.mark.parametrize("fmt", _CHECKED + ("mat", "uff"))
@FUZZ
@given(where=st.floats(min_value=0.0, max_value=1.0, exclude_max=True), byte=st.integers(0, 255))
def test_overwritten_byte(fmt, where, byte, tmp_path):
    valid = _valid_bytes(fmt, tmp_path)
    at = int(where * len(valid))
    damaged = valid[:at] + bytes([byte]) + valid[at + 1 :]
    path = tmp_path / f"flip.{fmt}"
    path.write_bytes(damaged)
    record = _load_or_refuse(_WRITERS[fmt][1], path)
    if record is None or fmt not in _CHECKED:
        # MAT v5 and binary UFF carry no checksum: a changed number cannot be told from a
        # written one. Their property is the exception contract only (ValueError or a
        # record, nothing else).
        return
    _same(record, _RECORD)


_CELL_TEXT = st.one_of(
    st.sampled_from(["", "nan", "inf", "-inf", "1e400", "abc", "1,5", " ", "0x10", "1e-320"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(alphabet="0123456789.-+eE xa", max_size=8),
)


def _parse_csv(text: str) -> tuple[list[str], np.ndarray]:
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    return rows[0], np.array([[float(c) for c in row] for row in rows[1:]])


@FUZZ
@given(row=st.integers(0, N - 1), col=st.integers(0, 2), cell=_CELL_TEXT)
def test_csv_cell_edit(row, col, cell, tmp_path):
    path = tmp_path / "edit.csv"
    save_csv(_RECORD, path)
    lines = path.read_text().splitlines()
    first = 1  # _RECORD has no metadata: line 0 is the header
    cells = lines[first + row].split(",")
    cells[col] = cell
    lines[first + row] = ",".join(cells)
    text = "\n".join(lines) + "\n"
    path.write_text(text)
    record = _load_or_refuse(load_csv, path)
    if record is None:
        return
    # It loaded: every number must be the one now in the file (parsed independently).
    _, table = _parse_csv(text)
    assert np.isfinite(table).all()
    np.testing.assert_array_equal(record["q"], table[:, 1])
    np.testing.assert_array_equal(record["u"], table[:, 2])
    # the time column: the stored grid is within time_rtol (1e-3) of the stamps
    np.testing.assert_allclose(record.t, table[:, 0], rtol=0, atol=1e-3 * record.dt)


@pytest.mark.parametrize("fmt", ["npz", "mat", "h5"])
@FUZZ
@given(
    name=st.sampled_from(["t", "q", "u"]),
    index=st.integers(0, N - 1),
    value=st.floats(allow_nan=True, allow_infinity=True, width=64),
)
def test_binary_cell_edit(fmt, name, index, value, tmp_path):
    """One value of one array changed (written with the format's own writer)."""
    import json

    import h5py
    import scipy.io

    arrays = {"t": _RECORD.t.copy(), "q": _RECORD["q"].copy(), "u": _RECORD["u"].copy()}
    arrays[name][index] = value
    path = tmp_path / f"edit.{fmt}"
    units = json.dumps(_RECORD.units)
    if fmt == "npz":
        np.savez(path, **arrays, jaxvs_units=np.array(units))
    elif fmt == "mat":
        scipy.io.savemat(path, {**{k: v[:, None] for k, v in arrays.items()}, "jaxvs_units": units})
    else:
        with h5py.File(path, "w", track_order=True) as f:
            for k, v in arrays.items():
                f[k] = v
                if k in _RECORD.units:
                    f[k].attrs["unit"] = _RECORD.units[k]
    record = _load_or_refuse(_WRITERS[fmt][1], path)
    if record is None:
        return
    assert all(math.isfinite(v) for v in arrays[name])
    np.testing.assert_array_equal(record["q"], arrays["q"])
    np.testing.assert_array_equal(record["u"], arrays["u"])
    np.testing.assert_allclose(record.t, arrays["t"], rtol=0, atol=1e-3 * record.dt)


@FUZZ
@given(line=st.integers(0, 10_000), text=_CELL_TEXT)
def test_ascii_uff_data_line_edit(line, text, tmp_path):
    """One data line of an ASCII UFF file replaced by other text: refused, or (only when the
    new text holds the same numbers) loaded exactly."""
    path = tmp_path / "edit.unv"
    save_uff(path, _RECORD, binary=False)
    lines = path.read_text().splitlines()
    # data lines: only numbers, past the 11 header records of a dataset 58 (floats in
    # %20.11e; header records hold integers and short labels)
    data = [i for i, s in enumerate(lines) if s.strip() and all("e" in c for c in s.split())]
    at = data[line % len(data)]
    original = [float(c) for c in lines[at].split()]
    lines[at] = text
    path.write_text("\n".join(lines) + "\n")
    record = _load_or_refuse(load_uff_record, path)
    if record is None:
        return
    edited = text.split()
    assert len(edited) == len(original) and all(
        _is_float(c) and math.isclose(float(c), v, rel_tol=1e-11) for c, v in zip(edited, original)
    ), f"data line {at} changed to {text!r} and the file still loaded"
    _same(record, _RECORD, rtol=1e-11)  # ASCII UFF keeps 12 significant digits


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
