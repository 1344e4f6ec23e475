"""Tests of the record loaders and writers, and of the EMPS benchmark loader on real data."""

import hashlib
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
import scipy.signal

from jaxvs.data import (
    SUPPORTED_SUFFIXES,
    Record,
    load,
    load_csv,
    load_emps,
    load_hdf5,
    load_mat,
    load_npz,
    save_csv,
    save_hdf5,
    save_mat,
    save_npz,
)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
EMPS = DATA / "EMPS"
needs_emps = pytest.mark.skipif(
    not EMPS.is_dir(), reason=f"real EMPS data folder {EMPS} is absent (it sits beside the repo)"
)

WRITERS = {".csv": save_csv, ".npz": save_npz, ".mat": save_mat, ".h5": save_hdf5}
READERS = {".csv": load_csv, ".npz": load_npz, ".mat": load_mat, ".h5": load_hdf5}


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def sample_record() -> Record:
    rng = np.random.default_rng(1)
    n = 257
    return Record(
        {
            "q": rng.standard_normal(n) * 1e-3,
            "u": rng.standard_normal(n) * 50.0,
            "T_bearing": 20.0 + np.cumsum(rng.standard_normal(n)) * 1e-2,
        },
        dt=1e-3,
        t0=0.25,
        units={"q": "m", "u": "N", "T_bearing": "°C"},
        metadata={"kp": 160.18, "kv": 243.45, "axis": "x", "ok": True, "poles": [1.5, -2.0]},
    )


def assert_same_record(loaded: Record, original: Record) -> None:
    assert loaded.names == original.names
    for name in original.names:
        # Signals are written at full precision (repr / binary): they come back bit-exact.
        np.testing.assert_array_equal(loaded[name], original[name])
    assert len(loaded) == len(original)
    assert loaded.t0 == original.t0
    # dt is re-estimated from the written end times: equal up to rounding of t0 + (n-1)·dt.
    assert math.isclose(loaded.dt, original.dt, rel_tol=1e-12)
    np.testing.assert_allclose(loaded.t, original.t, rtol=1e-13)
    assert loaded.units == original.units
    assert dict(loaded.metadata) == dict(original.metadata)


# --- round trips -----------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", list(WRITERS))
def test_round_trip(tmp_path, suffix):
    record = sample_record()
    path = WRITERS[suffix](record, tmp_path / f"record{suffix}")
    assert path.exists()
    assert_same_record(load(path), record)
    assert_same_record(READERS[suffix](path), record)
    selected = load(path, names=["u", "q"])
    assert selected.names == ("u", "q") and selected.units == {"u": "N", "q": "m"}


def test_save_npz_appends_suffix(tmp_path):
    path = save_npz(sample_record(), tmp_path / "record")
    assert path.name == "record.npz" and path.exists()


@pytest.mark.parametrize("suffix", list(WRITERS))
def test_loading_never_modifies_the_file(tmp_path, suffix):
    path = WRITERS[suffix](sample_record(), tmp_path / f"record{suffix}")
    before = (digest(path), path.stat().st_mtime_ns)
    load(path)
    load(path, names="q")
    assert (digest(path), path.stat().st_mtime_ns) == before


@pytest.mark.parametrize(
    ("writer", "name", "match"),
    [
        (save_csv, "a,b", "cannot be written to a CSV header"),
        (save_mat, "2x", "not a valid MATLAB variable name"),
        (save_npz, "jaxvs_units", "reserved in jaxvs files"),
        (save_hdf5, "a/b", "HDF5 reads as a group"),
    ],
)
def test_writers_reject_unwritable_names(tmp_path, writer, name, match):
    record = Record({name: np.zeros(3)}, dt=1.0)
    with pytest.raises(ValueError, match=match):
        writer(record, tmp_path / "out")


def test_writers_reject_non_json_metadata(tmp_path):
    record = Record({"q": np.zeros(3)}, dt=1.0, metadata={"f": object()})
    with pytest.raises(TypeError, match="cannot be written; writers store metadata as JSON"):
        save_npz(record, tmp_path / "out.npz")


# --- CSV details -------------------------------------------------------------------------------


def test_csv_with_units_comments_and_custom_time(tmp_path):
    path = tmp_path / "thermal.csv"
    path.write_text(
        "# spindle run 3\n"
        "\n"
        "time [s], T_chassis [°C], v_m [rpm]\n"
        "0.0, 20.0, 1000\n"
        "60.0, 20.5, 1000\n"
        "120.0, 21.0, 2000\n",
        encoding="utf-8",
    )
    record = load(path, time="time")
    assert record.names == ("T_chassis", "v_m")
    assert record.units == {"T_chassis": "°C", "v_m": "rpm"}
    assert record.dt == 60.0
    np.testing.assert_array_equal(record["v_m"], [1000, 1000, 2000])
    assert dict(record.metadata) == {}


def test_csv_without_time_column_uses_dt(tmp_path):
    path = tmp_path / "no_time.csv"
    path.write_text("x_e,x_t\n1,2\n3,4\n5,6\n")
    record = load_csv(path, dt=0.5)
    np.testing.assert_array_equal(record.t, [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(record["x_t"], [2, 4, 6])


def test_csv_semicolon_delimiter(tmp_path):
    path = tmp_path / "semi.csv"
    path.write_text("t;q\n0;1\n1;2\n")
    assert load_csv(path, delimiter=";")["q"].tolist() == [1.0, 2.0]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("time,q\n0,1\n1,2\n", r"no time column 't'; columns found: \['q', 'time'\]\. Name"),
        ("t,q\n0,1\n1,abc\n", r"line 3, column 'q': cell 'abc' is not a number"),
        ("t,q\n0,1\n1,\n", r"line 3, column 'q': cell '' is not a number"),
        ("t,q\n0,1\n1,2,3\n", r"line 3: 3 cells but the header has 2 columns"),
        ("t,q,q\n0,1,1\n", "appears twice"),
        ("t,q [m\n0,1\n", "is not 'name' or 'name \\[unit\\]'"),
        ("t [mm],q\n0,1\n1,2\n", "'mm' .* does not measure the same quantity as 's'"),
        ("# only a comment\n", "is empty"),
        ("t,q\n", "no data rows"),
        ("t,q\n0,1\n1,nan\n", r"Signal 'q' has a non-finite value \(nan\) at sample 1"),
        ("t,q\n0,1\n1,2\n3,3\n", r"not uniform: sample 1 .*resample"),
        ("t,q\n0,1\n0,2\n", r"not strictly increasing: t\[1\]"),
        ("# metadata: {oops\nt,q\n0,1\n1,2\n", "metadata are not valid JSON"),
    ],
)
def test_csv_errors(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load(path)


def test_csv_time_and_dt_together_is_an_error(tmp_path):
    path = tmp_path / "ok.csv"
    path.write_text("t,q\n0,1\n1,2\n")
    with pytest.raises(ValueError, match="pass only one of them"):
        load(path, dt=1.0)


# --- generic files from other tools ------------------------------------------------------------


def test_generic_mat_columns_rows_scalars_and_strings(tmp_path):
    n = 6
    path = tmp_path / "from_matlab.mat"
    scipy.io.savemat(
        path,
        {
            "t": (0.1 * np.arange(n))[:, None],
            "x_e": np.arange(n, dtype=float)[:, None],  # column vector
            "x_t": np.arange(n, dtype=float)[None, :] ** 2,  # row vector
            "y": 0.35,  # scalar -> metadata
            "label": "run A",  # string -> metadata
            "geometry": np.eye(3),  # matrix -> metadata, unchanged
        },
    )
    record = load(path)
    assert record.names == ("x_e", "x_t")
    np.testing.assert_array_equal(record["x_t"], np.arange(n) ** 2)
    assert record.metadata["y"] == 0.35 and record.metadata["label"] == "run A"
    np.testing.assert_array_equal(record.metadata["geometry"], np.eye(3))
    assert math.isclose(record.fs, 10.0, rel_tol=1e-12)


def test_generic_npz(tmp_path):
    path = tmp_path / "arrays.npz"
    np.savez(path, t=np.arange(4.0), q=np.ones(4), gain=np.float64(2.5), name=np.array("axis x"))
    record = load(path)
    assert record.names == ("q",)
    assert dict(record.metadata) == {"gain": 2.5, "name": "axis x"}


def test_generic_hdf5_groups_attrs_and_units(tmp_path):
    path = tmp_path / "daq.hdf5"
    with h5py.File(path, "w") as f:
        f.create_dataset("t", data=0.01 * np.arange(5))
        f.create_dataset("axis_x/q", data=np.arange(5.0)).attrs["units"] = "m"
        f.create_dataset("axis_x/u", data=np.arange(5.0)[:, None]).attrs["unit"] = b"N"
        f.create_dataset("gain", data=3.0)
        f.create_dataset("comment", data="bench 2")
        f.create_dataset("map", data=np.ones((2, 3)))
        f.attrs["operator"] = "ab"
        f.attrs["temperature"] = 21.5
    record = load(path)
    assert record.names == ("axis_x/q", "axis_x/u")
    assert record.units == {"axis_x/q": "m", "axis_x/u": "N"}
    meta = record.metadata
    assert meta["gain"] == 3.0 and meta["comment"] == "bench 2"
    assert meta["operator"] == "ab" and meta["temperature"] == 21.5
    np.testing.assert_array_equal(meta["map"], np.ones((2, 3)))
    assert load(path, names=["axis_x/u"]).names == ("axis_x/u",)


# --- dispatch errors -------------------------------------------------------------------------


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="No such file"):
        load(tmp_path / "absent.csv")
    with pytest.raises(FileNotFoundError, match="No such file"):
        load_emps(tmp_path / "absent.mat")


def test_unsupported_suffix_lists_supported(tmp_path):
    path = tmp_path / "data.xlsx"
    path.write_bytes(b"")
    with pytest.raises(ValueError, match=r"Unsupported file type '.xlsx'.*\.csv, \.npz, \.mat"):
        load(path)
    assert SUPPORTED_SUFFIXES[:5] == (".csv", ".npz", ".mat", ".h5", ".hdf5")


def test_directory_is_not_a_file(tmp_path):
    with pytest.raises(ValueError, match="is a directory, not a file"):
        load(tmp_path)


@pytest.mark.parametrize("suffix", [".npz", ".mat", ".h5"])
def test_binary_formats_without_time_list_what_they_hold(tmp_path, suffix):
    path = tmp_path / f"no_time{suffix}"
    if suffix == ".npz":
        np.savez(path, q=np.ones(4), u=np.zeros(4))
    elif suffix == ".mat":
        scipy.io.savemat(path, {"q": np.ones((4, 1)), "u": np.zeros((4, 1))})
    else:
        with h5py.File(path, "w") as f:
            f["q"] = np.ones(4)
            f["u"] = np.zeros(4)
    with pytest.raises(ValueError, match=r"no time column 't'; columns found: \['q', 'u'\]"):
        load(path)
    record = load(path, dt=0.2)
    assert record.names == ("q", "u") and record.dt == 0.2


def test_missing_requested_signal(tmp_path):
    path = save_npz(sample_record(), tmp_path / "r.npz")
    with pytest.raises(
        KeyError, match=r"no signal 'x'; available signals: \['T_bearing', 'q', 'u'\]"
    ):
        load(path, names=["x"])


def test_not_an_hdf5_file(tmp_path):
    path = tmp_path / "fake.h5"
    path.write_bytes(b"not hdf5")
    with pytest.raises(ValueError, match="cannot be read as HDF5"):
        load(path)


def test_mat_errors(tmp_path):
    garbage = tmp_path / "garbage.mat"
    garbage.write_bytes(b"\x00" * 200)
    with pytest.raises(ValueError, match="MAT file .* cannot be read.*export it again"):
        load(garbage)
    # A MATLAB v7.3 file: a 512-byte user block with the MAT header, then HDF5.
    v73 = tmp_path / "v73.mat"
    with h5py.File(v73, "w", userblock_size=512) as f:
        f["t"] = np.arange(3.0)
    with open(v73, "r+b") as f:
        f.write(b"MATLAB 7.3 MAT-file".ljust(124) + b"\x00\x02IM")
    with pytest.raises(ValueError, match="MATLAB v7.3 file, which is HDF5 inside; load it with"):
        load(v73)
    with pytest.raises(ValueError, match="v7.3"):
        load_mat(v73)


def test_load_emps_rejects_other_mat_files(tmp_path):
    path = tmp_path / "other.mat"
    scipy.io.savemat(path, {"t": np.arange(3.0), "qm": np.ones(3)})
    with pytest.raises(ValueError, match=r"not an EMPS benchmark file: missing \['qg', 'vir'"):
        load_emps(path)


def test_emps_like_file_is_routed_by_load(tmp_path):
    n = 5
    path = tmp_path / "emps_like.mat"
    scipy.io.savemat(
        path,
        {
            "t": 1e-3 * np.arange(n)[:, None],
            "qm": np.arange(n, dtype=float)[:, None],
            "qg": np.ones((n, 1)),
            "vir": np.full((n, 1), 2.0),
            "kp": 1.0,
            "kv": 2.0,
            "gtau": 3.0,
        },
    )
    record = load(path)
    assert record.names == ("q", "r", "u", "vir")
    np.testing.assert_array_equal(record["u"], np.full(n, 6.0))  # u = gtau·vir
    assert load(path, names=["u"]).names == ("u",)


# --- the real EMPS benchmark ---------------------------------------------------------------------


@needs_emps
@pytest.mark.slow
@pytest.mark.parametrize("name", ["DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"])
def test_emps_files(name):
    path = EMPS / name
    before = (digest(path), path.stat().st_mtime_ns)
    record = load(path)
    assert (digest(path), path.stat().st_mtime_ns) == before  # the shared file is untouched

    raw = scipy.io.loadmat(path)
    assert len(record) == 24_841
    # 1 kHz: the files' time stamps jitter by ≈3e-5·dt, the end-point estimate of dt by less.
    assert math.isclose(record.fs, 1000.0, rel_tol=1e-9)
    assert math.isclose(record.t[-1], 24.84, rel_tol=1e-9)
    np.testing.assert_allclose(record.t, raw["t"].ravel(), rtol=0, atol=1e-7)
    meta = record.metadata
    # Gains quoted to the published digits (docs/guides/drive.md).
    assert math.isclose(meta["kp"], 160.18, abs_tol=5e-3)
    assert math.isclose(meta["kv"], 243.45, abs_tol=5e-3)
    assert math.isclose(meta["gtau"], 35.15, abs_tol=5e-3)
    np.testing.assert_array_equal(record["q"], raw["qm"].ravel())
    np.testing.assert_array_equal(record["r"], raw["qg"].ravel())
    np.testing.assert_array_equal(record["vir"], raw["vir"].ravel())
    np.testing.assert_array_equal(record["u"], meta["gtau"] * raw["vir"].ravel())
    assert record.units == {"q": "m", "r": "m", "u": "N", "vir": "V"}
    assert ("pulses" in record) == (name == "DATA_EMPS_PULSES.mat")
    if "pulses" in record:
        # A 0/5 square wave, on for half of the samples (0.5 s on, 0.5 s off).
        assert set(np.unique(record["pulses"])) == {0.0, 5.0}
        assert math.isclose(np.mean(record["pulses"] > 0), 0.5, abs_tol=0.01)
    assert load_emps(path).names == record.names

    # Independent check of the mapping: the controller of the description (§1.3),
    # vir = kp·kv·(qg − qm) − kv·q̇m with q̇m the difference of the 2-tap FIR-filtered qm,
    # reproduces the recorded vir, plus a constant step while a force pulse is on (the pulses
    # were injected into the command, so vir and u already contain them).
    q, r, vir = record["q"], record["r"], record["vir"]
    q_filtered = 0.5 * (q[1:] + q[:-1])
    velocity = np.diff(q_filtered) / record.dt
    predicted = meta["kp"] * meta["kv"] * (r[2:] - q[2:]) - meta["kv"] * velocity
    residual = vir[2:] - predicted
    if "pulses" in record:
        on = record["pulses"][2:] > 0
        step = residual[on].mean()
        assert 4.9 < step < 5.2  # V: measured 5.07 V for a pulse value of 5
        residual = residual - step * on
    # 1 %: the file does not show the dSPACE's internal rounding (measured 0.24 %, 0.28 %).
    assert np.sqrt(np.mean(residual**2) / np.mean(vir[2:] ** 2)) < 0.01


@needs_emps
@pytest.mark.slow
def test_emps_force_reproduces_published_idim_ls_estimate():
    """u = gtau·vir in N: least squares on M q̈ + Fv q̇ + Fc sign(q̇) + offset = u gives the
    published IDIM-LS parameters (docs/guides/drive.md: M = 95.1089 kg, Fv = 203.5034 N·s/m,
    Fc = 20.3935 N, offset = −3.1648 N, relative force error 4.08 %)."""
    record = load(EMPS / "DATA_EMPS.mat")
    # Zero-phase 4th-order Butterworth at 20 Hz before differentiating; the paper decimates
    # and filters differently, hence tolerances of a few percent below.
    b, a = scipy.signal.butter(4, 20.0 * 2 * record.dt)
    q = scipy.signal.filtfilt(b, a, record["q"])
    u = scipy.signal.filtfilt(b, a, record["u"])
    v = np.gradient(q, record.dt)
    acc = np.gradient(v, record.dt)
    keep = slice(100, -100)  # drop filter edge transients
    regressors = np.column_stack([acc, v, np.sign(v), np.ones_like(v)])[keep]
    theta, *_ = np.linalg.lstsq(regressors, u[keep], rcond=None)
    mass, viscous, coulomb, offset = theta
    assert math.isclose(mass, 95.1089, rel_tol=0.02)
    assert math.isclose(viscous, 203.5034, rel_tol=0.03)
    assert math.isclose(coulomb, 20.3935, rel_tol=0.03)
    assert math.isclose(offset, -3.1648, rel_tol=0.05)
    relative_error = np.linalg.norm(u[keep] - regressors @ theta) / np.linalg.norm(u[keep])
    assert relative_error < 0.05

    # The validation file: the pulses are already inside u (no extra weight for them).
    pulses = load(EMPS / "DATA_EMPS_PULSES.mat")
    q = scipy.signal.filtfilt(b, a, pulses["q"])
    u = scipy.signal.filtfilt(b, a, pulses["u"])
    v = np.gradient(q, pulses.dt)
    regressors = np.column_stack(
        [
            np.gradient(v, pulses.dt),
            v,
            np.sign(v),
            np.ones_like(v),
            scipy.signal.filtfilt(b, a, pulses["pulses"]),
        ]
    )[keep]
    theta, *_ = np.linalg.lstsq(regressors, u[keep], rcond=None)
    assert abs(theta[4]) < 0.1  # N per pulse unit; an unmodelled external force would be ≈ −1
