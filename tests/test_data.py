"""Tests of `jaxvs.data.Record` and the calibration/validation splits."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from jaxvs.data import (
    DEFAULT_TIME_RTOL,
    Record,
    Split,
    split_blocks,
    split_experiments,
)


def make_record(n=100, dt=0.01, t0=0.0, **kwargs):
    k = np.arange(n)
    signals = {"q": np.sin(0.1 * k), "u": np.cos(0.05 * k), "r": 0.5 * k}
    kwargs.setdefault("units", {"q": "m", "u": "N"})
    return Record(signals, dt=dt, t0=t0, **kwargs)


# --- construction ------------------------------------------------------------------------------


def test_record_from_mapping_with_time_vector():
    t = 0.5 + 0.001 * np.arange(50)
    q = np.linspace(0, 1, 50)
    u = np.linspace(2, 3, 50)
    record = Record({"q": q, "u": u}, t=t, units={"q": "m", "u": "N"}, metadata={"kp": 160.18})
    assert len(record) == 50
    assert record.names == ("q", "u")
    assert record.t0 == 0.5
    # dt from the end points: (t[-1] - t[0]) / (n - 1), exact up to rounding of the sum.
    assert math.isclose(record.dt, 0.001, rel_tol=1e-12)
    assert math.isclose(record.fs, 1000.0, rel_tol=1e-12)
    assert math.isclose(record.duration, 0.049, rel_tol=1e-12)
    np.testing.assert_allclose(record.t, t, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(record["q"], q)
    assert record.units == {"q": "m", "u": "N"}
    assert record.unit("q") == "m"
    assert record.metadata["kp"] == 160.18
    assert "q" in record and "x" not in record and 3 not in record


def test_record_from_2d_array_matches_mapping():
    data = np.arange(30.0).reshape(10, 3)
    record = Record(data, names=["a", "b", "c"], dt=0.1)
    np.testing.assert_array_equal(record["b"], data[:, 1])
    np.testing.assert_array_equal(record.to_array(), data)
    np.testing.assert_array_equal(record.to_array(["c", "a"]), data[:, [2, 0]])
    np.testing.assert_allclose(record.t, 0.1 * np.arange(10), rtol=1e-15)


def test_record_accepts_column_vectors_and_integers():
    record = Record({"n": np.arange(5)[:, None]}, dt=1.0)
    assert record["n"].shape == (5,)
    assert record["n"].dtype == np.float64


def test_record_accepts_clock_jitter_and_stores_uniform_grid():
    rng = np.random.default_rng(0)
    n, dt = 1000, 1e-3
    grid = dt * np.arange(n)
    jitter = rng.uniform(-1, 1, n) * 1e-5 * dt  # 1e-5·dt: inside the default 1e-3·dt
    jitter[[0, -1]] = 0.0
    record = Record({"x": np.zeros(n)}, t=grid + jitter)
    np.testing.assert_allclose(record.t, grid, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="not uniform"):
        Record({"x": np.zeros(n)}, t=grid + jitter, time_rtol=1e-7)


# --- immutability --------------------------------------------------------------------------------


def test_record_never_aliases_user_arrays():
    q = np.linspace(0.0, 1.0, 20)
    data = np.ones((20, 2))
    t = 0.1 * np.arange(20)
    meta_gains = np.array([1.0, 2.0])
    record = Record({"q": q}, t=t, metadata={"gains": meta_gains, "info": {"axis": "x"}})
    matrix = Record(data, names=["a", "b"], dt=0.1)
    q[:] = -5.0
    data[:] = -5.0
    t[:] = 0.0
    meta_gains[:] = -1.0
    np.testing.assert_array_equal(record["q"], np.linspace(0.0, 1.0, 20))
    np.testing.assert_array_equal(matrix["a"], np.ones(20))
    np.testing.assert_allclose(record.t, 0.1 * np.arange(20), rtol=1e-14)
    np.testing.assert_array_equal(record.metadata["gains"], [1.0, 2.0])
    assert not np.shares_memory(record["q"], q)
    assert q.flags.writeable  # the user's array is left as it was


def test_record_arrays_are_read_only_for_good():
    record = make_record()
    for values in (record["q"], record.t, record.slice(2, 10)["q"]):
        assert not values.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            values[0] = 1.0
        with pytest.raises(ValueError, match="WRITEABLE"):
            values.setflags(write=True)
    out = record.to_array()
    out[:] = 0.0  # to_array returns a fresh writable copy
    assert record["q"][1] != 0.0
    with pytest.raises(AttributeError, match="immutable"):
        record.dt = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        record.metadata["new"] = 1  # type: ignore[index]


def test_record_from_jax_arrays_copy_pickle():
    import copy
    import pickle

    import jax.numpy as jnp

    record = Record({"q": jnp.arange(4.0)}, t=jnp.arange(4.0) * 0.5, units={"q": "m"})
    assert isinstance(record["q"], np.ndarray) and record.dt == 0.5
    assert copy.copy(record) is record and copy.deepcopy(record) is record
    restored = pickle.loads(pickle.dumps(record))
    np.testing.assert_array_equal(restored["q"], record["q"])
    assert (restored.t0, restored.dt, restored.units) == (0.0, 0.5, {"q": "m"})
    assert not restored["q"].flags.writeable


def test_with_signal_returns_new_record():
    record = make_record()
    added = record.with_signal("v", np.ones(100), unit="m/s")
    assert added.names == ("q", "u", "r", "v") and added.unit("v") == "m/s"
    assert "v" not in record
    replaced = added.with_signal("q", 2 * record["q"])
    np.testing.assert_array_equal(replaced["q"], 2 * record["q"])
    assert replaced.unit("q") is None  # a replaced signal takes exactly the given unit
    assert record.unit("q") == "m"
    with pytest.raises(ValueError, match="has shape \\(99,\\) but the record has 100 samples"):
        record.with_signal("v", np.ones(99))
    with pytest.raises(ValueError, match="Signal 'v' has a non-finite value .* at sample 3"):
        record.with_signal("v", np.r_[np.zeros(3), np.nan, np.zeros(96)])
    with pytest.raises(TypeError, match="unit must be a string"):
        record.with_signal("v", np.ones(100), unit=3)  # type: ignore[arg-type]


def test_with_metadata_merges():
    record = make_record(metadata={"kp": 1.0})
    updated = record.with_metadata({"kv": 2.0})
    assert dict(updated.metadata) == {"kp": 1.0, "kv": 2.0}
    assert dict(record.metadata) == {"kp": 1.0}


# --- access ---------------------------------------------------------------------------------


def test_missing_signal_lists_available_names():
    record = make_record()
    with pytest.raises(
        KeyError, match=r"No signal named 'x'.*available signals: \['q', 'u', 'r'\]"
    ):
        record["x"]
    with pytest.raises(KeyError, match="available signals"):
        record.select(["q", "x"])
    with pytest.raises(KeyError, match="available signals"):
        record.to_array(["x"])
    with pytest.raises(TypeError, match="Index a Record by signal name"):
        record[0]  # type: ignore[index]
    with pytest.raises(TypeError, match="not iterable"):
        iter(record)


def test_select_and_rename():
    record = make_record(metadata={"kp": 3.0})
    selected = record.select(["u", "q"])
    assert selected.names == ("u", "q")
    assert selected.units == {"q": "m", "u": "N"}
    assert selected.dt == record.dt and selected.metadata["kp"] == 3.0
    assert record.select("r").names == ("r",)
    with pytest.raises(ValueError, match="repeated"):
        record.select(["q", "q"])
    with pytest.raises(ValueError, match="at least one"):
        record.select([])
    renamed = record.rename({"q": "x_e", "u": "force"})
    assert renamed.names == ("x_e", "force", "r")
    assert renamed.units == {"x_e": "m", "force": "N"}
    np.testing.assert_array_equal(renamed["x_e"], record["q"])
    with pytest.raises(ValueError, match="two signals the name 'r'"):
        record.rename({"q": "r"})
    with pytest.raises(KeyError, match="available signals"):
        record.rename({"zz": "a"})
    with pytest.raises(ValueError, match="reserved for the time base"):
        record.rename({"q": "t"})


def test_slice_and_window():
    record = make_record(n=100, dt=0.01, t0=2.0)
    part = record.slice(10, 30)
    assert len(part) == 20
    assert math.isclose(part.t0, 2.1, rel_tol=1e-12)
    np.testing.assert_array_equal(part["q"], record["q"][10:30])
    np.testing.assert_allclose(part.t, record.t[10:30], rtol=1e-14)
    assert len(record.slice(-5)) == 5
    assert len(record.slice(stop=-90)) == 10
    # Half-open window [2.1, 2.3): grid times given as decimals still hit their samples.
    window = record.window(2.1, 2.3)
    assert len(window) == 20 and math.isclose(window.t0, 2.1, rel_tol=1e-12)
    assert len(record.window(2.905)) == 9
    assert len(record.window(t_end=2.05)) == 5
    assert len(record.window(-10.0, 100.0)) == 100
    with pytest.raises(ValueError, match="selects no samples"):
        record.slice(50, 50)
    with pytest.raises(TypeError, match="integer sample indices"):
        record.slice(1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="t_end must be greater than t_start"):
        record.window(2.5, 2.5)
    with pytest.raises(ValueError, match=r"holds no sample; the record spans \[2, 2.99\] s"):
        record.window(5.0, 6.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 98), st.integers(1, 99))
def test_window_matches_slice_on_grid_times(start, length):
    record = make_record(n=100, dt=0.001, t0=0.3)
    stop = min(start + length, 100)
    by_index = record.slice(start, stop)
    t_end = record.t0 + stop * record.dt
    by_time = record.window(float(record.t[start]), t_end)
    assert len(by_time) == len(by_index)
    np.testing.assert_array_equal(by_time["q"], by_index["q"])


def test_repr_names_units_and_rate():
    record = make_record(metadata={"kp": 1.0})
    text = repr(record)
    assert text.startswith("Record(100 samples, fs=100 Hz, t=[0, 0.99] s")
    assert "q [m], u [N], r" in text and "metadata: kp" in text


# --- validation errors -----------------------------------------------------------------------


def test_nan_and_inf_name_signal_and_first_index():
    q = np.zeros(10)
    q[4] = np.nan
    q[7] = np.nan
    with pytest.raises(ValueError, match=r"Signal 'q' has a non-finite value \(nan\) at sample 4 "):
        Record({"u": np.zeros(10), "q": q}, dt=1.0)
    u = np.zeros(10)
    u[2] = -np.inf
    with pytest.raises(ValueError, match=r"Signal 'u' has a non-finite value \(-inf\) at sample 2"):
        Record({"u": u}, dt=1.0)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"signals": {"q": np.zeros(5), "u": np.zeros(6)}}, ValueError, "different lengths"),
        ({"signals": np.zeros((5, 2)), "names": ["a", "a"]}, ValueError, "Duplicate signal name"),
        ({"signals": np.zeros((5, 2)), "names": ["a"]}, ValueError, "2 columns but 1 names"),
        ({"signals": np.zeros((5, 2))}, ValueError, "needs names="),
        ({"signals": np.zeros(5)}, ValueError, "2-D array"),
        ({"signals": {"q": np.zeros(5)}, "names": ["q"]}, ValueError, "only used with a 2-D"),
        ({"signals": {"q": np.zeros((5, 2))}}, ValueError, "must be 1-D"),
        ({"signals": {"q": np.zeros(5, complex)}}, TypeError, "real numbers"),
        ({"signals": {"q": np.array(["a", "b"])}}, TypeError, "real numbers"),
        ({"signals": {"t": np.zeros(5)}}, ValueError, "reserved for the time base"),
        ({"signals": {"": np.zeros(5)}}, ValueError, "empty or has surrounding spaces"),
        ({"signals": {1: np.zeros(5)}}, TypeError, "names must be strings"),
        ({"signals": {}}, ValueError, "at least one signal"),
        ({"signals": {"q": np.zeros(0)}}, ValueError, "at least one sample"),
        ({"signals": {"q": np.zeros(5)}, "units": {"x": "m"}}, ValueError, "unknown signal 'x'"),
        ({"signals": {"q": np.zeros(5)}, "units": {"q": 1}}, TypeError, "must be a string"),
        ({"signals": {"q": np.zeros(5)}, "metadata": [1]}, TypeError, "metadata must be"),
        ({"signals": {"q": np.zeros(5)}, "dt": -1.0}, ValueError, "positive finite sampling"),
        ({"signals": {"q": np.zeros(5)}, "dt": 1.0, "t": np.arange(5)}, ValueError, "not both"),
        ({"signals": {"q": np.zeros(5)}, "dt": None}, ValueError, "needs a time base"),
        ({"signals": {"q": np.zeros(5)}, "t": np.arange(4.0)}, ValueError, "4 samples but"),
        ({"signals": {"q": np.zeros(1)}, "t": np.zeros(1)}, ValueError, "pass dt="),
        ({"signals": {"q": np.zeros(3)}, "t": [0, 1, np.nan]}, ValueError, "non-finite value at"),
        ({"signals": {"q": np.zeros(3)}, "dt": 1.0, "time_rtol": 0}, ValueError, "time_rtol"),
    ],
)
def test_record_construction_errors(kwargs, error, match):
    kwargs = dict(kwargs)
    signals = kwargs.pop("signals")
    if "t" not in kwargs:
        kwargs.setdefault("dt", 0.1)
    with pytest.raises(error, match=match):
        Record(signals, **kwargs)


def test_non_increasing_time_names_index():
    t = np.array([0.0, 0.1, 0.2, 0.2, 0.4])
    with pytest.raises(ValueError, match=r"not strictly increasing: t\[3\] = 0.2 <= t\[2\]"):
        Record({"q": np.zeros(5)}, t=t)
    with pytest.raises(ValueError, match=r"t\[2\]"):
        Record({"q": np.zeros(4)}, t=[0.0, 1.0, 0.5, 3.0])


def test_non_uniform_time_names_index_and_fix():
    t = 0.01 * np.arange(10)
    t[6] += 0.002
    with pytest.raises(ValueError, match=r"not uniform: sample 6 .*jaxvs\.signal\.resample"):
        Record({"q": np.zeros(10)}, t=t)
    assert DEFAULT_TIME_RTOL == 1e-3


# --- splits ------------------------------------------------------------------------------------


def test_split_blocks_70_30_is_contiguous_and_complete():
    record = make_record(n=1000, dt=0.01, t0=1.0)
    calibration, validation = split_blocks(record)
    assert (len(calibration), len(validation)) == (700, 300)
    np.testing.assert_array_equal(np.r_[calibration["q"], validation["q"]], record["q"])
    assert calibration.t0 == record.t0
    assert math.isclose(validation.t0, record.t[700], rel_tol=1e-14)
    assert validation.units == record.units


def test_split_blocks_three_way_and_rounding():
    record = make_record(n=101)
    blocks = split_blocks(record, (0.5, 0.25, 0.25))
    assert [len(b) for b in blocks] == [50, 26, 25]  # edges round(50.5)=50, round(75.75)=76
    assert sum(len(b) for b in blocks) == 101


@pytest.mark.parametrize(
    ("fractions", "kwargs", "match"),
    [
        ((0.7, 0.2), {}, "sum to 0.9, not 1"),
        ((1.0,), {}, "at least two fractions"),
        ((1.2, -0.2), {}, "must be positive"),
        ((0.999, 0.001), {}, r"blocks of \[999, 1\] samples; every block needs at least 2"),
        ((0.5, 0.5), {"min_samples": 600}, "at least 600"),
        ((0.5, 0.5), {"min_samples": 0}, "min_samples"),
    ],
)
def test_split_blocks_errors(fractions, kwargs, match):
    with pytest.raises(ValueError, match=match):
        split_blocks(make_record(n=1000), fractions, **kwargs)


def test_split_experiments_holds_out_whole_records():
    records = [make_record(n=10 + i) for i in range(4)]
    split = split_experiments(records)
    assert isinstance(split, Split)
    assert split.calibration == tuple(records[:3]) and split.validation == (records[3],)
    split = split_experiments(records, validation=[2, 0])
    assert split.calibration == (records[1], records[3])
    assert split.validation == (records[2], records[0])
    assert split_experiments(records, validation=-4).validation == (records[0],)


@pytest.mark.parametrize(
    ("n", "validation", "error", "match"),
    [
        (1, -1, ValueError, "at least two records.*split_blocks"),
        (3, [0, 1, 2], ValueError, "every experiment"),
        (3, [1, -2], ValueError, "repeats"),
        (3, 3, ValueError, "out of range"),
        (3, [], ValueError, "no experiment"),
        (3, [0.5], TypeError, "integers"),
    ],
)
def test_split_experiments_errors(n, validation, error, match):
    with pytest.raises(error, match=match):
        split_experiments([make_record() for _ in range(n)], validation=validation)
    with pytest.raises(TypeError, match="not a Record"):
        split_experiments([make_record(), np.zeros(3)])  # type: ignore[list-item]
