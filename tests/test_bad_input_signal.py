"""Bad-input matrix, signal processing (`jaxvs.signal`): NaN samples, wrong axes, rates and
windows (row format in `tests/bad_input.py`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from bad_input import Case, run_case

from jaxvs.signal import (
    coherence,
    csd,
    cwt_morlet,
    decimate,
    differentiate,
    filtfilt_lowpass,
    frf_h1,
    get_window,
    psd,
    resample,
    transmissibility,
)

N = 256
FS = 100.0
_t = np.arange(N) / FS
X = np.sin(2 * np.pi * 5 * _t) + 0.1 * np.random.default_rng(0).standard_normal(N)
Y = np.roll(X, 2) * 0.5
X_NAN = X.copy()
X_NAN[7] = np.nan
NAN = float("nan")


def _case(ident, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return Case(
        id=f"signal-{ident}",
        area="signal",
        entry=f"jaxvs.signal.{entry}",
        input=what,
        run=lambda tmp: fn(),
        exc=exc,
        match=match,
        check=check,
    )


def _jit(fn):
    """`fn` under `eqx.filter_jit`, so that value checks run as `eqx.error_if`."""
    return eqx.filter_jit(fn)


CASES: list[Case] = [
    _case(
        "psd-nan",
        "psd",
        "x with a NaN sample",
        lambda: psd(X_NAN, FS),
        match=r"x has 1 non-finite sample\(s\), the first at index \(7,\).*Remove or interpolate",
    ),
    _case(
        "psd-nan-jit",
        "psd",
        "x with a NaN sample, under jit",
        lambda: _jit(lambda x: psd(x, FS))(jnp.asarray(X_NAN)),
        exc=eqx.EquinoxRuntimeError,
        match=r"x contains NaN or inf",
    ),
    _case(
        "psd-fs-zero",
        "psd",
        "fs=0",
        lambda: psd(X, 0.0),
        match=r"sampling rate fs must be a finite positive number \[Hz\], got 0.0",
    ),
    _case(
        "psd-fs-nan",
        "psd",
        "fs=nan",
        lambda: psd(X, NAN),
        match=r"sampling rate fs must be a finite positive number \[Hz\], got nan",
    ),
    _case(
        "psd-nperseg-long",
        "psd",
        "nperseg longer than the record",
        lambda: psd(X, FS, nperseg=4 * N),
        match=r"fewer than nperseg = 1024.*Pass nperseg <= 256.*or record a longer",
    ),
    _case(
        "psd-noverlap",
        "psd",
        "noverlap >= nperseg",
        lambda: psd(X, FS, nperseg=64, noverlap=64),
        match=r"noverlap = 64 must satisfy 0 <= noverlap < nperseg = 64",
    ),
    _case(
        "psd-window",
        "psd",
        "window='blackmanharris7'",
        lambda: psd(X, FS, window="blackmanharris7"),
        match=r"Unknown window 'blackmanharris7'; use one of",
    ),
    _case(
        "psd-detrend",
        "psd",
        "detrend='quadratic'",
        lambda: psd(X, FS, detrend="quadratic"),
        match=r"detrend must be None, 'constant' or 'linear', got 'quadratic'",
    ),
    _case(
        "psd-scaling",
        "psd",
        "scaling='power'",
        lambda: psd(X, FS, scaling="power"),
        match=r"scaling must be 'density' or 'spectrum', got 'power'",
    ),
    _case(
        "psd-constant",
        "psd",
        "a constant record (legal: zero spectrum except DC)",
        lambda: psd(np.ones(N), FS, nperseg=64)[1],
        exc=None,
        check=lambda p: np.testing.assert_allclose(p, 0.0, atol=1e-20),
    ),
    _case(
        "csd-length",
        "csd",
        "x and y of different lengths",
        lambda: csd(X, Y[:-5], FS),
        match=r"x has 256 samples and y has 251.*cut them to the common time span",
    ),
    _case(
        "coherence-nan",
        "coherence",
        "y with a NaN sample",
        lambda: coherence(X, X_NAN, FS),
        match=r"y has 1 non-finite sample.*Remove or interpolate",
    ),
    _case(
        "frf-constant-input",
        "frf_h1",
        "a constant (unexciting) input",
        lambda: frf_h1(np.ones(N), Y, FS, nperseg=64),
        match=r"input x is constant.*Excite the structure with a broadband signal",
    ),
    _case(
        "frf-length",
        "frf_h1",
        "x and y of different lengths",
        lambda: frf_h1(X, Y[:100], FS),
        match=r"x has 256 samples and y has 100.*resample both",
    ),
    _case(
        "frf-kind",
        "frf_h1",
        "kind='speed'",
        lambda: frf_h1(X, Y, FS, kind="speed"),
        match=r"unknown kind 'speed'; choose one of",
    ),
    _case(
        "transmissibility-quantity",
        "transmissibility",
        "tool_quantity='jerk'",
        lambda: transmissibility(X, Y, FS, tool_quantity="jerk"),
        match=r"tool_quantity must be one of.*got 'jerk'",
    ),
    _case(
        "filt-cutoff-nyquist",
        "filtfilt_lowpass",
        "cutoff above Nyquist",
        lambda: filtfilt_lowpass(X, FS, 80.0),
        match=r"cutoff = 80 Hz must lie below the Nyquist frequency fs/2 = 50 Hz",
    ),
    _case(
        "filt-cutoff-zero",
        "filtfilt_lowpass",
        "cutoff=0",
        lambda: filtfilt_lowpass(X, FS, 0.0),
        match=r"cutoff must be a positive finite number, got 0.0",
    ),
    _case(
        "filt-nan",
        "filtfilt_lowpass",
        "x with a NaN sample",
        lambda: filtfilt_lowpass(X_NAN, FS, 10.0),
        match=r"non-finite sample.*Remove or interpolate",
    ),
    _case(
        "filt-nan-jit",
        "filtfilt_lowpass",
        "x with a NaN sample, under jit",
        lambda: _jit(lambda x: filtfilt_lowpass(x, FS, 10.0))(jnp.asarray(X_NAN)),
        exc=eqx.EquinoxRuntimeError,
        match=r"NaN or inf.*remove or interpolate",
    ),
    _case(
        "filt-order",
        "filtfilt_lowpass",
        "order=0",
        lambda: filtfilt_lowpass(X, FS, 10.0, order=0),
        match=r"order must be a positive integer, got 0",
    ),
    _case(
        "filt-short",
        "filtfilt_lowpass",
        "a record shorter than the filter's padding",
        lambda: filtfilt_lowpass(X[:8], FS, 10.0),
        match=r"has 8 samples.*pads 15 samples.*Use a longer record or a lower filter order",
    ),
    _case(
        "filt-axis",
        "filtfilt_lowpass",
        "axis=3 of a 1-D signal",
        lambda: filtfilt_lowpass(X, FS, 10.0, axis=3),
        match=r"axis=3 is out of range",
    ),
    _case(
        "decimate-factor-0",
        "decimate",
        "factor=0",
        lambda: decimate(X, 0),
        match=r"factor must be a positive integer, got 0",
    ),
    _case(
        "decimate-factor-float",
        "decimate",
        "factor=2.5",
        lambda: decimate(X, 2.5),
        exc=TypeError,
        match=r"factor must be a positive integer, got 2.5",
    ),
    _case(
        "diff-dt-zero",
        "differentiate",
        "dt=0",
        lambda: differentiate(X, 0.0),
        match=r"dt must be a positive finite sampling period \[s\], got 0.0",
    ),
    _case(
        "diff-order-3",
        "differentiate",
        "order=3",
        lambda: differentiate(X, 0.01, order=3),
        match=r"order must be 1 or 2, got 3; for higher derivatives apply differentiate",
    ),
    _case(
        "diff-method",
        "differentiate",
        "method='forward'",
        lambda: differentiate(X, 0.01, method="forward"),
        match=r"method must be one of \('central', 'spectral'\), got 'forward'",
    ),
    _case(
        "diff-nan",
        "differentiate",
        "x with a NaN sample",
        lambda: differentiate(X_NAN, 0.01),
        match=r"x has 1 non-finite sample.*Remove or interpolate",
    ),
    _case(
        "resample-unsorted",
        "resample",
        "t not increasing",
        lambda: resample(_t[::-1], X, dt=0.02),
        match=r"t is not strictly increasing.*Sort by time",
    ),
    _case(
        "resample-both",
        "resample",
        "dt and t_new both given",
        lambda: resample(_t, X, dt=0.02, t_new=_t),
        match=r"give either dt=... or t_new=..., not both",
    ),
    _case(
        "resample-method",
        "resample",
        "method='spline'",
        lambda: resample(_t, X, dt=0.02, method="spline"),
        match=r"method must be one of.*got 'spline'",
    ),
    _case(
        "resample-extrapolate",
        "resample",
        "t_new beyond the data without extrapolate",
        lambda: resample(_t, X, t_new=_t + 10.0),
        match=r"outside the data range.*Restrict t_new to the data range or pass extrapolate=True",
    ),
    _case(
        "resample-legal",
        "resample",
        "linear resampling onto a finer grid (legal)",
        lambda: resample(np.arange(5.0), np.arange(5.0) * 2, dt=0.5)[1],
        exc=None,
        # a straight line is resampled exactly by linear interpolation (rounding only)
        check=lambda y: np.testing.assert_allclose(y, np.arange(9) * 1.0, rtol=1e-14),
    ),
    _case(
        "window-name",
        "get_window",
        "get_window('kaiser-ish', 64)",
        lambda: get_window("kaiser-ish", 64),
        match=r"Unknown window 'kaiser-ish'; use one of",
    ),
    _case(
        "window-n-0",
        "get_window",
        "n=0",
        lambda: get_window("hann", 0),
        match=r"window length must be a positive int, got 0",
    ),
    _case(
        "cwt-freq-nyquist",
        "cwt_morlet",
        "a frequency above Nyquist",
        lambda: cwt_morlet(X, 0.01, np.array([10.0, 80.0])),
        match=r"must lie in \(0, 50\) Hz \(below the Nyquist frequency.*got \[10, 80\] Hz",
    ),
    _case(
        "cwt-freq-zero",
        "cwt_morlet",
        "frequency 0",
        lambda: cwt_morlet(X, 0.01, np.array([0.0])),
        match=r"frequencies must lie in \(0, 50\) Hz.*got \[0, 0\] Hz",
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)
