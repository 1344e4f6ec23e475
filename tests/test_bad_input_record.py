"""Bad-input matrix, data layer in Python: `Record`, units, splits, excitation signals and
`FRFData` (row format in `tests/bad_input.py`)."""

from __future__ import annotations

import numpy as np
import pytest
from bad_input import Case, run_case

from jaxvs.data import (
    FRFData,
    Record,
    bang_bang,
    convert_units,
    parse_unit,
    prbs,
    si_record,
    split_blocks,
    split_experiments,
    swept_sine,
    to_si,
    trapezoid,
    white_noise,
)

N = 20
T = 0.1 * np.arange(N)
Q = np.sin(T)
NAN, INF = float("nan"), float("inf")


def _rec(**kw) -> Record:
    return Record({"q": Q, "u": np.cos(T)}, dt=0.1, **kw)


def _equal(expected):
    def check(result):
        # exact: these are copies or float64 scalings by powers of ten (1 ulp)
        np.testing.assert_allclose(np.asarray(result), expected, rtol=1e-15, atol=0)

    return check


def _case(ident, area, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return Case(
        id=ident,
        area=area,
        entry=entry,
        input=what,
        run=lambda tmp: fn(),
        exc=exc,
        match=match,
        check=check,
    )


def _r(ident, what, fn, exc=ValueError, match="", check=None) -> Case:
    return _case(f"record-{ident}", "record", "jaxvs.data.Record", what, fn, exc, match, check)


CASES: list[Case] = [
    # --- the constructor ---------------------------------------------------------------------
    _r(
        "dt-true",
        "dt=True (a boolean, read as 1 s before)",
        lambda: Record({"q": Q}, dt=True),
        exc=TypeError,
        match=r"dt and t0 must be numbers \[s\], got dt=True.*Pass the sampling period",
    ),
    _r(
        "dt-1e308",
        "dt=1e308",
        lambda: Record({"q": Q}, dt=1e308),
        match=r"does not fit in float64.*give dt and t0 in seconds",
    ),
    _r(
        "dt-subnormal",
        "dt=5e-324 (1/dt overflows)",
        lambda: Record({"q": Q}, dt=5e-324),
        match=r"does not fit in float64.*give dt and t0 in seconds",
    ),
    _r(
        "t0-huge",
        "t0=1e308, dt=1e290",
        lambda: Record({"q": Q}, dt=1e290, t0=1e308),
        match=r"consecutive sample times are equal in float64; subtract the start time",
    ),
    _r(
        "dt-zero",
        "dt=0",
        lambda: Record({"q": Q}, dt=0.0),
        match=r"dt must be a positive finite sampling period",
    ),
    _r(
        "dt-negative",
        "dt=-0.1",
        lambda: Record({"q": Q}, dt=-0.1),
        match=r"dt must be a positive finite sampling period",
    ),
    _r(
        "dt-nan",
        "dt=nan",
        lambda: Record({"q": Q}, dt=NAN),
        match=r"dt must be a positive finite sampling period",
    ),
    _r(
        "dt-inf",
        "dt=inf",
        lambda: Record({"q": Q}, dt=INF),
        match=r"dt must be a positive finite sampling period",
    ),
    _r("t0-nan", "t0=nan", lambda: Record({"q": Q}, dt=0.1, t0=NAN), match=r"t0 must be finite"),
    _r(
        "dt-string",
        "dt='0.1x'",
        lambda: Record({"q": Q}, dt="0.1x"),
        match=r"dt must be a positive finite sampling period \[s\].*Pass numbers",
    ),
    _r(
        "no-time-base",
        "neither t nor dt",
        lambda: Record({"q": Q}),
        match=r"needs a time base: pass the time vector t=.*or the sampling period dt=",
    ),
    _r(
        "t-and-dt",
        "both t and dt",
        lambda: Record({"q": Q}, t=T, dt=0.1),
        match=r"either the time vector t=.*or the sampling period dt=.*not both",
    ),
    _r(
        "nan-sample",
        "NaN at sample 4",
        lambda: Record({"q": np.where(T == T[4], NAN, Q)}, dt=0.1),
        match=r"'q' has a non-finite value \(nan\) at sample 4.*interpolate",
    ),
    _r(
        "inf-sample",
        "-inf at sample 2",
        lambda: Record({"q": np.where(T == T[2], -INF, Q)}, t=T),
        match=r"'q' has a non-finite value \(-inf\) at sample 2.*interpolate",
    ),
    _r(
        "length-mismatch",
        "q has 20 samples, u 19",
        lambda: Record({"q": Q, "u": Q[:-1]}, dt=0.1),
        match=r"different lengths.*Trim or resample them",
    ),
    _r(
        "t-length-mismatch",
        "t has 19 samples, q 20",
        lambda: Record({"q": Q}, t=T[:-1]),
        match=r"time vector has 19 samples but the signals have 20.*same length",
    ),
    _r(
        "t-decreasing",
        "t decreasing",
        lambda: Record({"q": Q}, t=T[::-1]),
        match=r"not strictly increasing.*Sort the samples",
    ),
    _r(
        "t-duplicate",
        "a repeated time stamp",
        lambda: Record({"q": Q}, t=np.r_[T[:5], T[4:-1]]),
        match=r"not strictly increasing.*drop duplicated time stamps",
    ),
    _r(
        "t-non-uniform",
        "a time stamp 0.2 dt off grid",
        lambda: Record({"q": Q}, t=T + np.where(np.arange(N) == 9, 0.02, 0.0)),
        match=r"not uniform: sample 9.*jaxvs.signal.resample.*time_rtol",
    ),
    _r(
        "t-nan",
        "NaN in t",
        lambda: Record({"q": Q}, t=np.where(np.arange(N) == 3, NAN, T)),
        match=r"time vector has a non-finite value at sample 3",
    ),
    _r(
        "t-2d",
        "t of shape (20, 2)",
        lambda: Record({"q": Q}, t=np.stack([T, T], 1)),
        match=r"time vector must be 1-D, got shape \(20, 2\)",
    ),
    _r(
        "t-one-sample",
        "one sample with t",
        lambda: Record({"q": Q[:1]}, t=T[:1]),
        match=r"fewer than 2 samples does not define a sampling period; pass dt=",
    ),
    _r(
        "t-strings",
        "t as strings",
        lambda: Record({"q": Q}, t=T.astype(str)),
        exc=TypeError,
        match=r"time vector must be real numbers",
    ),
    _r(
        "empty-signals",
        "an empty mapping",
        lambda: Record({}, dt=0.1),
        match=r"needs at least one signal",
    ),
    _r(
        "zero-samples",
        "signals of length 0",
        lambda: Record({"q": []}, dt=0.1),
        match=r"needs at least one sample",
    ),
    _r(
        "signal-2d",
        "a (20, 3) array as one signal",
        lambda: Record({"q": np.ones((N, 3))}, dt=0.1),
        match=r"shape \(20, 3\); each signal must be 1-D.*Split multi-channel data",
    ),
    _r(
        "signal-complex",
        "complex samples",
        lambda: Record({"q": Q + 1j}, dt=0.1),
        exc=TypeError,
        match=r"signals must be real numbers.*real and imaginary parts as two signals",
    ),
    _r(
        "signal-strings",
        "strings as samples",
        lambda: Record({"q": ["a", "b"]}, dt=0.1),
        exc=TypeError,
        match=r"dtype <U1.*Convert it with np.asarray",
    ),
    _r(
        "signal-objects",
        "an object array",
        lambda: Record({"q": np.array([1, None])}, dt=0.1),
        exc=TypeError,
        match=r"dtype object.*Convert it",
    ),
    _r(
        "name-t",
        "a signal named 't'",
        lambda: Record({"t": Q}, dt=0.1),
        match=r"'t' is reserved for the time base.*another name",
    ),
    _r(
        "name-empty",
        "a signal named ''",
        lambda: Record({"": Q}, dt=0.1),
        match=r"empty or has surrounding spaces; use a non-empty name",
    ),
    _r(
        "name-space",
        "a signal named ' q'",
        lambda: Record({" q": Q}, dt=0.1),
        match=r"surrounding spaces.*without leading or trailing whitespace",
    ),
    _r(
        "name-int",
        "a signal named 3",
        lambda: Record({3: Q}, dt=0.1),
        exc=TypeError,
        match=r"names must be strings, got 3",
    ),
    _r(
        "2d-no-names",
        "a 2-D array without names",
        lambda: Record(np.ones((N, 2)), dt=0.1),
        match=r"needs names=\[...\] with one name per column",
    ),
    _r(
        "2d-names-count",
        "a (20, 2) array with 3 names",
        lambda: Record(np.ones((N, 2)), names=["a", "b", "c"], dt=0.1),
        match=r"2 columns but 3 names.*one name per column",
    ),
    _r(
        "2d-transposed",
        "a (2, 20) array with 2 names (time on the wrong axis)",
        lambda: Record(np.ones((2, N)), names=["a", "b"], dt=0.1),
        match=r"20 columns but 2 names.*\[time, signal\]",
    ),
    _r(
        "1d-array",
        "a 1-D array instead of a mapping",
        lambda: Record(Q, dt=0.1),
        match=r"mapping name -> 1-D array or a 2-D array \[time, signal\]",
    ),
    _r(
        "mapping-with-names",
        "a mapping and names=",
        lambda: Record({"q": Q}, names=["q"], dt=0.1),
        match=r"names=... is only used with a 2-D array",
    ),
    _r(
        "units-unknown-signal",
        "units for a signal that is not there",
        lambda: Record({"q": Q}, dt=0.1, units={"x": "m"}),
        match=r"units given for unknown signal 'x'; available signals",
    ),
    _r(
        "units-not-str",
        "unit 5",
        lambda: Record({"q": Q}, dt=0.1, units={"q": 5}),
        exc=TypeError,
        match=r"unit of 'q' must be a string",
    ),
    _r(
        "metadata-list",
        "metadata as a list",
        lambda: Record({"q": Q}, dt=0.1, metadata=[1]),
        exc=TypeError,
        match=r"metadata must be a mapping \(dict\)",
    ),
    _r(
        "metadata-int-key",
        "a metadata key 1",
        lambda: Record({"q": Q}, dt=0.1, metadata={1: 2}),
        exc=TypeError,
        match=r"metadata keys must be strings",
    ),
    _r(
        "time-rtol-negative",
        "time_rtol=-1",
        lambda: Record({"q": Q}, t=T, time_rtol=-1.0),
        match=r"time_rtol must be a positive number",
    ),
    _r(
        "record-of-record",
        "a Record passed as signals",
        lambda: Record(_rec(), dt=0.1),
        exc=TypeError,
        match=r"already a Record; use its methods",
    ),
    _r(
        "single-sample-dt",
        "one sample with dt (legal)",
        lambda: Record({"q": [1.5]}, dt=0.1),
        exc=None,
        check=lambda r: (len(r) == 1 and r["q"][0] == 1.5) or pytest.fail(repr(r)),
    ),
    _r(
        "int-signal",
        "integer samples (legal, converted)",
        lambda: Record({"q": [1, 2, 3]}, dt=1.0)["q"],
        exc=None,
        check=_equal([1.0, 2.0, 3.0]),
    ),
    _r(
        "bool-signal",
        "boolean samples (legal, 0/1)",
        lambda: Record({"q": [True, False]}, dt=1.0)["q"],
        exc=None,
        check=_equal([1.0, 0.0]),
    ),
    _r(
        "column-vector",
        "an (n, 1) column (legal)",
        lambda: Record({"q": Q[:, None]}, dt=0.1)["q"],
        exc=None,
        check=_equal(Q),
    ),
    _r(
        "t-jitter",
        "t jittered by 1e-6 dt (legal)",
        lambda: Record({"q": Q}, t=T + 1e-7 * np.sin(np.arange(N))).dt,
        exc=None,
        check=lambda dt: abs(dt - 0.1) < 1e-7 or pytest.fail(f"dt={dt}"),
    ),
    # --- methods -----------------------------------------------------------------------------
    _r(
        "getitem-missing",
        "record['x']",
        lambda: _rec()["x"],
        exc=KeyError,
        match=r"No signal named 'x'.*available signals",
    ),
    _r(
        "getitem-int",
        "record[0]",
        lambda: _rec()[0],
        exc=TypeError,
        match=r"Index a Record by signal name.*record.slice",
    ),
    _r("select-empty", "select([])", lambda: _rec().select([]), match=r"needs at least one signal"),
    _r(
        "select-repeated",
        "select(['q', 'q'])",
        lambda: _rec().select(["q", "q"]),
        match=r"repeated names.*name each signal once",
    ),
    _r(
        "rename-collision",
        "rename q to u",
        lambda: _rec().rename({"q": "u"}),
        match=r"two signals the name 'u'; choose distinct names",
    ),
    _r(
        "rename-missing",
        "rename x",
        lambda: _rec().rename({"x": "y"}),
        exc=KeyError,
        match=r"No signal named 'x'",
    ),
    _r("slice-empty", "slice(5, 5)", lambda: _rec().slice(5, 5), match=r"selects no samples"),
    _r(
        "slice-float",
        "slice(1.5, 3)",
        lambda: _rec().slice(1.5, 3),
        exc=TypeError,
        match=r"integer sample indices",
    ),
    _r(
        "window-reversed",
        "window(1.0, 0.5)",
        lambda: _rec().window(1.0, 0.5),
        match=r"t_end must be greater than t_start",
    ),
    _r(
        "window-outside",
        "window(10, 20) outside the record",
        lambda: _rec().window(10.0, 20.0),
        match=r"holds no sample; the record spans",
    ),
    _r(
        "with-signal-length",
        "with_signal of the wrong length",
        lambda: _rec().with_signal("v", Q[:5]),
        match=r"shape \(5,\) but the record has 20 samples",
    ),
    _r(
        "with-signal-nan",
        "with_signal with NaN",
        lambda: _rec().with_signal("v", Q * NAN),
        match=r"'v' has a non-finite value.*interpolate",
    ),
    _r(
        "require-unit-mm",
        "q in mm, require_unit('q', 'm') (legal: converted)",
        lambda: _rec(units={"q": "mm"}).require_unit("q", "m")["q"],
        exc=None,
        check=_equal(Q / 1000),
    ),
    _r(
        "require-unit-wrong-quantity",
        "u in N, require_unit('u', 'm')",
        lambda: _rec(units={"u": "N"}).require_unit("u", "m"),
        match=r"signal 'u': unit 'N'.*does not measure the same quantity as 'm'.*correct its unit",
    ),
    _r(
        "require-unit-unknown",
        "require_unit('q', 'mx')",
        lambda: _rec().require_unit("q", "mx"),
        match=r"unknown unit 'mx'",
    ),
    _r(
        "setattr",
        "record.dt = 1",
        lambda: setattr(_rec(), "dt", 1.0),
        exc=AttributeError,
        match=r"immutable; use with_signal",
    ),
]


def _u(ident, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return _case(f"units-{ident}", "units", f"jaxvs.data.{entry}", what, fn, exc, match, check)


CASES += [
    _u(
        "mm", "to_si", "to_si(x, 'mm')", lambda: to_si(Q, "mm")[0], exc=None, check=_equal(Q / 1000)
    ),
    _u(
        "kN", "to_si", "to_si(x, 'kN')", lambda: to_si(Q, "kN")[0], exc=None, check=_equal(Q * 1000)
    ),
    _u(
        "degF",
        "to_si",
        "to_si(212, '°F') (offset scale)",
        lambda: to_si(np.array([212.0]), "°F")[0],
        exc=None,
        check=lambda v: np.testing.assert_allclose(v, [100.0], atol=1e-12),
    ),
    _u(
        "rpm",
        "to_si",
        "to_si(x, 'rpm') stays rpm",
        lambda: to_si(Q, "rpm"),
        exc=None,
        check=lambda r: (r[1] == "rpm" and np.array_equal(r[0], Q)) or pytest.fail(repr(r)),
    ),
    _u(
        "deg",
        "to_si",
        "to_si(180, 'deg')",
        lambda: to_si(np.array([180.0]), "deg")[0],
        exc=None,
        check=lambda v: np.testing.assert_allclose(v, [np.pi], rtol=1e-15),
    ),
    _u(
        "unknown",
        "to_si",
        "to_si(x, 'furlongs/fortnightx')",
        lambda: to_si(Q, "blorp"),
        match=r"unknown unit 'blorp'.*pint reads",
    ),
    _u(
        "g",
        "parse_unit",
        "parse_unit('g')",
        lambda: parse_unit("g"),
        match=r"'g' is ambiguous.*'g0'.*'gram'",
    ),
    _u(
        "inc",
        "parse_unit",
        "parse_unit('inc')",
        lambda: parse_unit("inc"),
        match=r"not a physical unit.*Scale the signal",
    ),
    _u(
        "number",
        "parse_unit",
        "parse_unit('1e3')",
        lambda: parse_unit("1e3"),
        match=r"is a number, not a unit",
    ),
    _u(
        "convert-incompatible",
        "convert_units",
        "convert_units(x, 'N', 'm')",
        lambda: convert_units(Q, "N", "m", name="q"),
        match=r"signal 'q': unit 'N'.*does not measure the same quantity as 'm'",
    ),
    _u(
        "convert-dimensionless",
        "convert_units",
        "convert_units(x, '-', 'm')",
        lambda: convert_units(Q, "-", "m"),
        match=r"one is dimensionless.*Check the signal",
    ),
    _u(
        "si-record",
        "si_record",
        "si_record of a record in mm and kN",
        lambda: si_record(_rec(units={"q": "mm", "u": "kN"})).to_array(),
        exc=None,
        check=_equal(np.stack([Q / 1000, np.cos(T) * 1000], 1)),
    ),
]


def _s(ident, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return _case(f"split-{ident}", "record", f"jaxvs.data.{entry}", what, fn, exc, match, check)


CASES += [
    _s(
        "fractions-sum",
        "split_blocks",
        "fractions (0.7, 0.7)",
        lambda: split_blocks(_rec(), (0.7, 0.7)),
        match=r"sum to 1.4, not 1; e.g. use \(0.7, 0.3\)",
    ),
    _s(
        "fraction-negative",
        "split_blocks",
        "fractions (1.2, -0.2)",
        lambda: split_blocks(_rec(), (1.2, -0.2)),
        match=r"fraction must be positive, got \[1.2, -0.2\]",
    ),
    _s(
        "too-short",
        "split_blocks",
        "a 20-sample record, min_samples=15",
        lambda: split_blocks(_rec(), (0.5, 0.5), min_samples=15),
        match=r"at least 15. Use a longer record or larger fractions",
    ),
    _s(
        "not-a-record",
        "split_blocks",
        "an array instead of a Record",
        lambda: split_blocks(Q),
        exc=TypeError,
        match=r"takes a Record, got ndarray; build one",
    ),
    _s(
        "ok",
        "split_blocks",
        "fractions (0.5, 0.5) (legal)",
        lambda: [len(r) for r in split_blocks(_rec(), (0.5, 0.5))],
        exc=None,
        check=lambda n: n == [10, 10] or pytest.fail(str(n)),
    ),
    _s(
        "experiments-one",
        "split_experiments",
        "one record only",
        lambda: split_experiments([_rec()]),
        match=r"at least two records, got 1; for one record use split_blocks",
    ),
    _s(
        "experiments-index",
        "split_experiments",
        "validation=5 of 2 records",
        lambda: split_experiments([_rec(), _rec()], validation=5),
        match=r"index 5 is out of range for 2 records; use an index in -2..1",
    ),
]


def _x(ident, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return _case(
        f"excitation-{ident}", "excitation", f"jaxvs.data.{entry}", what, fn, exc, match, check
    )


CASES += [
    _x(
        "prbs-order-0",
        "prbs",
        "prbs(order=0)",
        lambda: prbs(0),
        match=r"order must be an integer in 2..24, got 0",
    ),
    _x(
        "prbs-order-99",
        "prbs",
        "prbs(order=99)",
        lambda: prbs(99),
        match=r"order must be an integer in 2..24, got 99",
    ),
    _x(
        "prbs-divider-0",
        "prbs",
        "clock_divider=0",
        lambda: prbs(5, clock_divider=0),
        match=r"clock_divider must be an integer >= 1, got 0",
    ),
    _x(
        "prbs-state-0",
        "prbs",
        "state=0 (the all-zero register never leaves 0)",
        lambda: prbs(5, state=0),
        match=r"state must be a nonzero integer.*got 0",
    ),
    _x(
        "prbs-amplitude-nan",
        "prbs",
        "amplitude=nan",
        lambda: prbs(5, amplitude=NAN),
        match=r"amplitude must be finite, got nan",
    ),
    _x(
        "sine-f1-nyquist",
        "swept_sine",
        "f1 above Nyquist",
        lambda: swept_sine((100, 0.01), 1.0, 80.0),
        match=r"above the Nyquist frequency 50 Hz.*sample faster or lower f0/f1",
    ),
    _x(
        "sine-f0-negative",
        "swept_sine",
        "f0=-1",
        lambda: swept_sine((100, 0.01), -1.0, 10.0),
        match=r"must be finite frequencies >= 0 Hz, got -1.0",
    ),
    _x(
        "sine-log-zero",
        "swept_sine",
        "logarithmic sweep from 0 Hz",
        lambda: swept_sine((100, 0.01), 0.0, 10.0, method="logarithmic"),
        match=r"logarithmic sweep needs f0 > 0",
    ),
    _x(
        "sine-method",
        "swept_sine",
        "method='cubic'",
        lambda: swept_sine((100, 0.01), 1.0, 10.0, method="cubic"),
        match=r"method must be 'linear' or 'logarithmic', got 'cubic'",
    ),
    _x(
        "noise-n-0",
        "white_noise",
        "n=0",
        lambda: white_noise(0, 0.01),
        match=r"n must be an integer >= 2, got 0",
    ),
    _x(
        "noise-dt-nan",
        "white_noise",
        "dt=nan",
        lambda: white_noise(100, NAN),
        match=r"dt must be a positive sampling period \[s\], got nan",
    ),
    _x(
        "noise-band",
        "white_noise",
        "bandwidth above Nyquist",
        lambda: white_noise(100, 0.01, bandwidth=80.0),
        match=r"band must satisfy 0 <= f_low < f_high <= 1/\(2·dt\) = 50 Hz, got \(0, 80\)",
    ),
    _x(
        "noise-rms-negative",
        "white_noise",
        "rms=-1",
        lambda: white_noise(100, 0.01, rms=-1.0),
        match=r"rms must be finite and >= 0, got -1.0",
    ),
    _x(
        "trapezoid-vmax-0",
        "trapezoid",
        "v_max=0",
        lambda: trapezoid(0.1, 0.0, 1.0, 1e-3),
        match=r"v_max must be a positive velocity \(or inf\), got 0.0",
    ),
    _x(
        "trapezoid-amax-nan",
        "trapezoid",
        "a_max=nan",
        lambda: trapezoid(0.1, 0.1, NAN, 1e-3),
        match=r"a_max must be a positive acceleration, got nan",
    ),
    _x(
        "trapezoid-dt-0",
        "trapezoid",
        "dt=0",
        lambda: trapezoid(0.1, 0.1, 1.0, 0.0),
        match=r"dt must be a positive sampling period \[s\], got 0.0",
    ),
    _x(
        "bangbang-cycles-0",
        "bang_bang",
        "n_cycles=0",
        lambda: bang_bang(0.1, 1.0, 1e-3, n_cycles=0),
        match=r"n_cycles must be an integer >= 1, got 0",
    ),
    _x(
        "bangbang-distance-inf",
        "bang_bang",
        "distance=inf",
        lambda: bang_bang(INF, 1.0, 1e-3),
        match=r"distance must be finite and nonzero, got inf",
    ),
]


def _f(ident, what, fn, exc=ValueError, match="", check=None) -> Case:
    return _case(f"frfdata-{ident}", "record", "jaxvs.data.FRFData", what, fn, exc, match, check)


_FR = np.linspace(1.0, 50.0, 10)
_HH = 1.0 / (1.0 + 1j * _FR)

CASES += [
    _f(
        "nan-H",
        "NaN in H",
        lambda: FRFData(_FR, np.where(_FR == _FR[3], NAN, _HH)),
        match=r"H has 1 non-finite value.*index \(3,\).*Remove those frequencies",
    ),
    _f(
        "nan-f",
        "NaN in the frequency grid",
        lambda: FRFData(np.where(_FR == _FR[2], NAN, _FR), _HH),
        match=r"frequency has a non-finite value at index 2; remove that point",
    ),
    _f(
        "negative-f",
        "a negative frequency",
        lambda: FRFData(_FR - 5.0, _HH),
        match=r"is negative; store the one-sided response",
    ),
    _f(
        "unsorted-f",
        "frequency grid not increasing",
        lambda: FRFData(_FR[::-1], _HH),
        match=r"not strictly increasing.*Sort the grid",
    ),
    _f(
        "length",
        "H shorter than the grid",
        lambda: FRFData(_FR, _HH[:-1]),
        match=r"H of shape \(9,\) does not match 10 frequencies; expected \(\*batch, freq\)",
    ),
    _f(
        "coherence-range",
        "coherence 1.5",
        lambda: FRFData(_FR, _HH, coherence=np.full(10, 1.5)),
        match=r"coherence must lie in \[0, 1\]",
    ),
    _f(
        "kind",
        "kind='velocity'",
        lambda: FRFData(_FR, _HH, kind="velocity"),
        match=r"unknown kind 'velocity'; choose one of",
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)
