"""Welch spectra, FRF estimators (H1, H2, Hv), coherence and transmissibility (TMF).

Conventions (those of `scipy.signal`): signals are `(*batch, time)`, leading axes broadcast
against each other and make a family estimated in one call; the cross-spectrum is
`S_xy = E[conj(X)·Y]`, so the FRF from input `x` to output `y` is `H1 = S_xy / S_xx`.

Welch's method (Welch, *IEEE Trans. Audio Electroacoust.* 15(2), 1967): the record is cut
into `nperseg`-sample segments overlapping by `noverlap`, each segment is detrended and
multiplied by the window, transformed with an `nfft`-point FFT, and the products are
averaged. With `records_axis`, repeated records (e.g. impact hits) are averaged as well, so
an estimate rests on `n_averages = n_segments × n_records` blocks.
"""

import dataclasses
import math
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from .._custom_types import RealScalarLike
from .._misc import check_finite, is_traced, options_object, real_array
from ..data import FRFData
from ._windows import _ALIASES, _check_fs, get_window

Detrend = Literal["constant", "linear", "none"] | None
Estimator = Literal["h1", "h2", "hv"]
_DETRENDS = {
    None: "none",
    False: "none",
    "none": "none",
    "constant": "constant",
    "linear": "linear",
}
_ESTIMATORS = ("h1", "h2", "hv")
# Differentiation order of each measured quantity relative to position (study 002, eq. 6:
# a(s) = s² x(s)).
_QUANTITY_ORDER = {"position": 0, "velocity": 1, "acceleration": 2}
_DEFAULT_NPERSEG = 256  # scipy.signal.welch's default segment length


class _Segments(NamedTuple):
    fs: float
    n_time: int
    nperseg: int
    noverlap: int
    nfft: int
    n_segments: int
    batch: tuple[int, ...]
    records_axis: int | None
    window_label: str


# ---------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------


def _sampling_rate(fs, fn: str) -> float:
    if isinstance(fs, (tuple, list)):
        if len(fs) != 2:
            raise ValueError(f"{fn}: fs is one sampling rate or a pair (fs_x, fs_y) [Hz].")
        fs_x, fs_y = (_check_fs(f, fn) for f in fs)
        if not math.isclose(fs_x, fs_y, rel_tol=1e-9):
            raise ValueError(
                f"{fn}: the two signals are sampled at different rates ({fs_x:g} Hz and "
                f"{fs_y:g} Hz). Spectral estimates need one common time base: resample both "
                "signals onto one uniform grid first (e.g. scipy.signal.resample_poly), "
                "aligning their start times."
            )
        return fs_x
    return _check_fs(fs, fn)


def _as_signal(x, name: str, fn: str) -> Array:
    x = real_array(
        x,
        f"{fn}: {name} must be a real time record; got a complex array. Estimate the "
        "real and imaginary parts separately or use a two-sided analysis elsewhere.",
    )
    if x.ndim < 1:
        raise ValueError(
            f"{fn}: {name} must be a time record of shape (*batch, time); got a scalar."
        )
    return x


def _check_finite(x: Array, name: str, fn: str) -> Array:
    fix = "Remove or interpolate them (or cut the record before the gap) before estimating spectra."
    return check_finite(x, f"{fn}: {name}", fix, unit="sample(s)")


def _check_exciting(x: Array, name: str, role: str, records_axis: int | None, fn: str) -> Array:
    """A constant signal has no spectrum: H1/H2/coherence would divide zero by zero."""
    advice = (
        "Excite the structure with a broadband signal (jaxvs.data.prbs, white_noise, "
        "swept_sine or an impact) and check that the channel is connected and scaled."
        if role == "input"
        else "The sensor recorded no response: check that it is connected and scaled."
    )
    message = f"{fn}: the {role} {name} is constant, so it has no spectrum to divide by. {advice}"
    xp = jnp if is_traced(x) else np
    values = x if is_traced(x) else np.asarray(x)
    spread = xp.max(values, axis=-1) - xp.min(values, axis=-1)
    if records_axis is not None and spread.ndim > records_axis:
        spread = xp.max(spread, axis=records_axis)
    if is_traced(x):
        return eqx.error_if(x, jnp.any(spread == 0), message)
    flat = np.reshape(spread, -1)
    if np.any(flat == 0):
        member = int(np.argmax(flat == 0))
        where = f" (family member {member} of {flat.size})" if flat.size > 1 else ""
        raise ValueError(message.replace(" is constant,", f" is constant{where},"))
    return x


def _records_axis(records_axis, batch_ndim: int, fn: str) -> int | None:
    if records_axis is None:
        return None
    if isinstance(records_axis, bool) or not isinstance(records_axis, (int, np.integer)):
        raise TypeError(f"{fn}: records_axis must be an int or None, got {records_axis!r}.")
    axis = int(records_axis)
    ndim = batch_ndim + 1  # leading axes + time
    normalised = axis + ndim if axis < 0 else axis
    if not 0 <= normalised < batch_ndim:
        raise ValueError(
            f"{fn}: records_axis={axis} must name a leading axis of the (*batch, time) "
            f"signals (they have {batch_ndim} leading axis/axes; the last axis is time). "
            "Stack repeated records along a leading axis, e.g. shape (n_records, time) and "
            "records_axis=0."
        )
    return normalised


def _split_window(window, allow_pair: bool, fn: str):
    """`window` is one spec (name or array) shared by both signals, or a pair."""
    if isinstance(window, (tuple, list)) and len(window) == 2:
        first, second = window
        is_spec = lambda w: isinstance(w, str) or (hasattr(w, "ndim") and w.ndim >= 1)
        if is_spec(first) and is_spec(second):
            if not allow_pair:
                raise ValueError(
                    f"{fn}: a (window_x, window_y) pair makes the cross-spectrum scaling "
                    "ambiguous; psd/csd take one window. Use the pair with frf_h1/frf_h2/"
                    "frf_hv/coherence/transmissibility, where the scaling cancels."
                )
            return first, second
    return window, window


def _window_length(window) -> int | None:
    if isinstance(window, str):
        return None
    w = jnp.asarray(window) if not hasattr(window, "shape") else window
    if w.ndim < 1:
        return None
    return int(w.shape[-1])


def _window_label(window) -> str:
    if isinstance(window, str):
        return _ALIASES.get(window.lower(), window.lower())
    return "custom"


def _segments(
    fn: str,
    n_time: int,
    batch: tuple[int, ...],
    fs: float,
    windows: tuple,
    nperseg,
    noverlap,
    nfft,
    df,
    records_axis,
) -> _Segments:
    axis = _records_axis(records_axis, len(batch), fn)
    lengths = {_window_length(w) for w in windows} - {None}
    if len(lengths) > 1:
        raise ValueError(f"{fn}: the two windows have different lengths {sorted(lengths)}.")
    window_n = lengths.pop() if lengths else None
    if df is not None:
        if nperseg is not None:
            raise ValueError(f"{fn}: give either nperseg or df (frequency resolution), not both.")
        df = float(df)
        if not (math.isfinite(df) and df > 0):
            raise ValueError(f"{fn}: df must be a positive frequency resolution [Hz], got {df!r}.")
        # Δf = fs / nperseg; round up so the resolution is at least as fine as asked.
        nperseg = max(1, math.ceil(fs / df * (1 - 1e-12)))
        if nperseg > n_time:
            raise ValueError(
                f"{fn}: a frequency resolution of df = {df:g} Hz needs segments of "
                f"nperseg = ceil(fs/df) = {nperseg} samples ({nperseg / fs:g} s at "
                f"fs = {fs:g} Hz), but the record has only {n_time} samples "
                f"({n_time / fs:g} s). Record at least {nperseg / fs:g} s (several times "
                f"that for averaging), or ask for df >= fs/n = {fs / n_time:g} Hz."
            )
    if nperseg is None:
        if window_n is not None:
            nperseg = window_n
        elif axis is not None:
            nperseg = n_time  # repeated records: each record is one block
        else:
            nperseg = _DEFAULT_NPERSEG
    if isinstance(nperseg, bool) or not isinstance(nperseg, (int, np.integer)) or nperseg < 1:
        raise ValueError(f"{fn}: nperseg must be a positive int, got {nperseg!r}.")
    nperseg = int(nperseg)
    if window_n is not None and window_n != nperseg:
        raise ValueError(
            f"{fn}: the window has {window_n} samples but nperseg = {nperseg}; give a window "
            "of nperseg samples (or leave nperseg out)."
        )
    if nperseg > n_time:
        raise ValueError(
            f"{fn}: the record has {n_time} samples, fewer than nperseg = {nperseg} "
            f"(a resolution of df = fs/nperseg = {fs / nperseg:g} Hz). Pass nperseg <= "
            f"{n_time} (df >= {fs / n_time:g} Hz) or record a longer experiment."
        )
    if noverlap is None:
        # One block per record needs no overlap; otherwise Welch's usual 50 %.
        noverlap = 0 if nperseg == n_time else nperseg // 2
    if isinstance(noverlap, bool) or not isinstance(noverlap, (int, np.integer)):
        raise ValueError(f"{fn}: noverlap must be an int, got {noverlap!r}.")
    noverlap = int(noverlap)
    if not 0 <= noverlap < nperseg:
        raise ValueError(
            f"{fn}: noverlap = {noverlap} must satisfy 0 <= noverlap < nperseg = {nperseg} "
            "(50 % overlap, nperseg // 2, is the usual choice with a Hann window)."
        )
    if nfft is None:
        nfft = nperseg
    if isinstance(nfft, bool) or not isinstance(nfft, (int, np.integer)) or nfft < nperseg:
        raise ValueError(
            f"{fn}: nfft must be an int >= nperseg = {nperseg} (zero padding), got {nfft!r}."
        )
    n_segments = (n_time - noverlap) // (nperseg - noverlap)
    labels = {_window_label(w) for w in windows}
    label = labels.pop() if len(labels) == 1 else "+".join(_window_label(w) for w in windows)
    return _Segments(fs, n_time, nperseg, noverlap, int(nfft), n_segments, batch, axis, label)


def _welch_segments(fn: str, n: int, batch, fs: float, windows, w: "Welch") -> _Segments:
    """The segmentation of the options `w` for records of `n` samples."""
    return _segments(fn, n, batch, fs, windows, w.nperseg, w.noverlap, w.nfft, w.df, w.records_axis)


def _window_array(window, seg: _Segments, dtype, fn: str) -> Array:
    if isinstance(window, str):
        return get_window(window, seg.nperseg, dtype=dtype)
    w = jnp.asarray(window)
    if jnp.iscomplexobj(w):
        raise TypeError(f"{fn}: the window must be real.")
    w = w.astype(dtype)
    w_batch = w.shape[:-1]
    try:
        ok = jnp.broadcast_shapes(w_batch, seg.batch) == seg.batch
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(
            f"{fn}: a window of shape {w.shape} does not broadcast against signals with "
            f"leading axes {seg.batch}; give (nperseg,) or (*batch, nperseg)."
        )
    return w


def _prepare_pair(x, y, fs, fn: str, *, names=("x", "y")):
    fs = _sampling_rate(fs, fn)
    x = _as_signal(x, names[0], fn)
    y = _as_signal(y, names[1], fn)
    if x.shape[-1] != y.shape[-1]:
        raise ValueError(
            f"{fn}: {names[0]} has {x.shape[-1]} samples and {names[1]} has {y.shape[-1]}. "
            "The two signals must be sampled synchronously on one time base: cut them to "
            "the common time span, and if they come from different acquisition systems "
            "(e.g. encoder at the control cycle, accelerometer at its DAQ rate) resample "
            "both onto one grid first."
        )
    try:
        batch = jnp.broadcast_shapes(x.shape[:-1], y.shape[:-1])
    except ValueError:
        raise ValueError(
            f"{fn}: the leading (family) axes of {names[0]} {x.shape[:-1]} and {names[1]} "
            f"{y.shape[:-1]} do not broadcast; give both (*batch, time) with the same batch "
            "axes (or one of them without batch axes)."
        ) from None
    dtype = jnp.result_type(x.dtype, y.dtype)
    x = x if x.dtype == dtype else x.astype(dtype)
    y = y if y.dtype == dtype else y.astype(dtype)
    return fs, x, y, tuple(batch)


# ---------------------------------------------------------------------------------------
# Core: segment spectra
# ---------------------------------------------------------------------------------------


def _frames(x: Array, seg: _Segments) -> Array:
    """`(*batch, time)` -> `(*batch, n_segments, nperseg)` overlapping segments."""
    step = seg.nperseg - seg.noverlap
    if seg.n_segments == 1:
        return x[..., None, : seg.nperseg]
    # Cut the record into blocks of g = gcd(step, nperseg) samples; segment k is blocks
    # k·s .. k·s + q − 1 (s = step/g, q = nperseg/g), so q strided slices build all
    # segments. XLA runs this several times faster than a gather when q is small
    # (q = 2 for the usual 50 % overlap, 1 without overlap).
    g = math.gcd(step, seg.nperseg)
    q, s = seg.nperseg // g, step // g
    if q <= 16:
        used = (seg.n_segments - 1) * step + seg.nperseg
        blocks = x[..., :used].reshape(*x.shape[:-1], used // g, g)
        stop = (seg.n_segments - 1) * s + 1
        parts = [blocks[..., j : j + stop : s, :] for j in range(q)]
        return parts[0] if q == 1 else jnp.concatenate(parts, axis=-1)
    index = np.arange(seg.n_segments)[:, None] * step + np.arange(seg.nperseg)[None, :]
    return x[..., index]


def _detrend(frames: Array, kind: str) -> Array:
    if kind == "none":
        return frames
    centred = frames - jnp.mean(frames, axis=-1, keepdims=True)
    if kind == "constant":
        return centred
    # Least-squares line a + b·t per segment; with t centred, a = mean and
    # b = Σ t·x / Σ t² (the normal equations decouple).
    n = frames.shape[-1]
    t = jnp.arange(n, dtype=frames.dtype) - (n - 1) / 2
    denom = jnp.sum(t**2)
    slope = jnp.sum(centred * t, axis=-1, keepdims=True) / jnp.where(denom > 0, denom, 1)
    return centred - slope * t


def _segment_fft(x: Array, window: Array, seg: _Segments, detrend: str) -> Array:
    frames = _detrend(_frames(x, seg), detrend)
    return jnp.fft.rfft(frames * window[..., None, :], n=seg.nfft, axis=-1)


def _average(products: Array, seg: _Segments) -> Array:
    """Mean over segments and, with `records_axis`, over records."""
    products = jnp.broadcast_to(products, seg.batch + products.shape[-2:])
    mean = jnp.mean(products, axis=-2)
    if seg.records_axis is not None:
        mean = jnp.mean(mean, axis=seg.records_axis)
    return mean


def _frequencies(seg: _Segments) -> np.ndarray:
    return np.fft.rfftfreq(seg.nfft, 1.0 / seg.fs)


def _scale(window: Array, seg: _Segments, scaling: str) -> Array:
    """scipy's normalisation: PSD [unit²/Hz] or power spectrum [unit²] of a sinusoid."""
    if scaling == "density":
        s = 1.0 / (seg.fs * jnp.sum(window**2, axis=-1))
    else:
        s = 1.0 / jnp.sum(window, axis=-1) ** 2
    return s[..., None, None]


def _one_sided(p: Array, nfft: int) -> Array:
    # Fold the negative frequencies onto the positive ones: every bin but DC (and Nyquist
    # for even nfft) appears twice in the two-sided spectrum of a real signal.
    factor = np.full(p.shape[-1], 2.0)
    factor[0] = 1.0
    if nfft % 2 == 0:
        factor[-1] = 1.0
    return p * jnp.asarray(factor, dtype=jnp.real(p).dtype)


def _welch_options(fn: str, scaling: str, detrend) -> tuple[str, str]:
    if scaling not in ("density", "spectrum"):
        raise ValueError(f"{fn}: scaling must be 'density' or 'spectrum', got {scaling!r}.")
    return scaling, _detrend_kind(detrend, fn)


def _detrend_kind(detrend, fn: str) -> str:
    try:
        return _DETRENDS[detrend]
    except (KeyError, TypeError):
        raise ValueError(
            f"{fn}: detrend must be None, 'constant' or 'linear', got {detrend!r}."
        ) from None


# One compiled kernel per public call (segment, window, FFT, average, ratio); the
# configuration is static, so repeated calls with the same shapes reuse it.


@eqx.filter_jit
def _csd_core(x, y, w, seg: _Segments, detrend: str, scaling: str) -> Array:
    X = _segment_fft(x, w, seg, detrend)
    Y = _segment_fft(y, w, seg, detrend)
    return _one_sided(_average(jnp.conj(X) * Y * _scale(w, seg, scaling), seg), seg.nfft)


@eqx.filter_jit
def _psd_core(x, w, seg: _Segments, detrend: str, scaling: str) -> Array:
    X = _segment_fft(x, w, seg, detrend)
    power = jnp.real(X) ** 2 + jnp.imag(X) ** 2
    return _one_sided(_average(power * _scale(w, seg, scaling), seg), seg.nfft)


@eqx.filter_jit
def _ratio_core(x, y, wx, wy, seg: _Segments, detrend: str, estimator, power: int, drop_dc):
    """Unscaled averaged spectra and the ratio estimates (H1, H2, Hv, coherence).

    Every block weighs the same and no density scale is applied: the ratios do not depend
    on a common scale, and with different windows per channel (impact testing) or per
    record only equal weights keep H1 = ΣS_xy / ΣS_xx the average over blocks.

    `power` re-expresses `y` as `(jω)^power · y` (transmissibility conversion).
    """
    X = _segment_fft(x, wx, seg, detrend)
    Y = _segment_fft(y, wy, seg, detrend)
    sxx = _average(jnp.real(X) ** 2 + jnp.imag(X) ** 2, seg)
    syy = _average(jnp.real(Y) ** 2 + jnp.imag(Y) ** 2, seg)
    sxy = _average(jnp.conj(X) * Y, seg)
    if drop_dc:
        sxx, syy, sxy = sxx[..., 1:], syy[..., 1:], sxy[..., 1:]
    if power != 0:
        frequency = _frequencies(seg)[1:] if drop_dc else _frequencies(seg)
        factor = (1j * 2 * np.pi * frequency) ** power
        sxy = jnp.asarray(factor, dtype=sxy.dtype) * sxy
        syy = jnp.asarray(np.abs(factor) ** 2, dtype=syy.dtype) * syy
    # A bin where either auto-spectrum is exactly zero carries no information (typically
    # DC after detrending a rectangular-windowed record of a ±1 PRBS): report H = 0 and
    # γ² = 0 there instead of 0/0, with safe denominators so gradients stay finite.
    undefined = (sxx == 0) | (syy == 0)
    sxx = jnp.where(undefined, 1, sxx)
    syy = jnp.where(undefined, 1, syy)
    sxy = jnp.where(undefined, 1, sxy)
    gamma2 = (jnp.real(sxy) ** 2 + jnp.imag(sxy) ** 2) / (sxx * syy)
    gamma2 = jnp.where(undefined, 0, gamma2)
    if estimator is None:
        return None, gamma2
    return jnp.where(undefined, 0, _estimate(sxx, syy, sxy, estimator)), gamma2


# ---------------------------------------------------------------------------------------
# Public spectra
# ---------------------------------------------------------------------------------------


def csd(
    x: Float[ArrayLike, "*batch time"],
    y: Float[ArrayLike, "*batch time"],
    fs: RealScalarLike,
    *,
    welch: "Welch | None" = None,
    scaling: Literal["density", "spectrum"] = "density",
    **options: Any,
) -> tuple[Float[Array, " freq"], Complex[Array, "*batch freq"]]:
    """One-sided cross power spectral density `P_xy = E[conj(X)·Y]` by Welch's method.

    Matches `scipy.signal.csd` for the same arguments (one-sided, mean averaging), and
    additionally batches over leading axes and averages repeated records.

    **Arguments:**

    - `x`, `y`: `(*batch, time)` real records of equal length on one time base; leading
      axes broadcast.
    - `fs`: sampling rate [Hz], a concrete number (static under `jax.jit`).
    - `welch`: the averaging options as one [`Welch`][], or its fields as keywords (as
      `scipy.signal.csd`):
    - `window`: `"hann"` (default), `"hamming"`, `"boxcar"`, `"flattop"`, or the samples
      `(nperseg,)` / `(*batch, nperseg)` (e.g. from [`exponential_window`][]).
    - `nperseg`: segment length [samples]; default 256, the window's length, or the whole
      record when `records_axis` is given. Sets the resolution `Δf = fs / nperseg`.
    - `noverlap`: overlap of consecutive segments [samples], default `nperseg // 2`.
    - `nfft`: FFT length >= `nperseg` (zero padding), default `nperseg`.
    - `df`: alternative to `nperseg`: the frequency resolution wanted [Hz]
      (`nperseg = ceil(fs / df)`).
    - `detrend`: per segment, `"constant"` (remove the mean, default), `"linear"`, or `None`.
    - `records_axis`: a leading axis holding repeated records, averaged as well.
    - `scaling`: `"density"` [unit²/Hz] or `"spectrum"` [unit²].

    **Returns:**

    `(frequency, P_xy)`: `(freq,)` frequencies [Hz] and the complex `(*batch, freq)`
    spectrum (`records_axis` removed).

    **Raises:**

    `ValueError` when the lengths differ, when the record is shorter than `nperseg` (or
    than `1/df`), for NaN/inf samples and inconsistent options; `TypeError` for complex
    signals or a traced `fs`.
    """
    fn = "csd"
    w = options_object(Welch, welch, options, fn, "welch")
    scaling, detrend_kind = _welch_options(fn, scaling, w.detrend)
    wx, _ = _split_window(w.window, False, fn)
    fs, x, y, batch = _prepare_pair(x, y, fs, fn)
    seg = _welch_segments(fn, x.shape[-1], batch, fs, (wx,), w)
    x = _check_finite(x, "x", fn)
    y = _check_finite(y, "y", fn)
    w = _window_array(wx, seg, x.dtype, fn)
    return jnp.asarray(_frequencies(seg)), _csd_core(x, y, w, seg, detrend_kind, scaling)


def psd(
    x: Float[ArrayLike, "*batch time"],
    fs: RealScalarLike,
    *,
    welch: "Welch | None" = None,
    scaling: Literal["density", "spectrum"] = "density",
    **options: Any,
) -> tuple[Float[Array, " freq"], Float[Array, "*batch freq"]]:
    """One-sided (auto) power spectral density by Welch's method, as `scipy.signal.welch`.

    Arguments as [`csd`][] with one signal.

    **Returns:**

    `(frequency, P_xx)`: `(freq,)` frequencies [Hz] and the real `(*batch, freq)` PSD
    [unit²/Hz] (or power spectrum [unit²] with `scaling="spectrum"`).
    """
    fn = "psd"
    w = options_object(Welch, welch, options, fn, "welch")
    scaling, detrend_kind = _welch_options(fn, scaling, w.detrend)
    wx, _ = _split_window(w.window, False, fn)
    fs = _sampling_rate(fs, fn)
    x = _as_signal(x, "x", fn)
    batch = tuple(x.shape[:-1])
    seg = _welch_segments(fn, x.shape[-1], batch, fs, (wx,), w)
    x = _check_finite(x, "x", fn)
    w = _window_array(wx, seg, x.dtype, fn)
    return jnp.asarray(_frequencies(seg)), _psd_core(x, w, seg, detrend_kind, scaling)


class _RatioInputs(NamedTuple):
    x: Array
    y: Array
    wx: Array
    wy: Array
    seg: _Segments
    detrend: str


def _ratio_inputs(fn: str, x, y, fs, welch: "Welch", names) -> _RatioInputs:
    """Validate the records and options of a ratio estimator (H1, H2, Hv, coherence)."""
    w = welch
    detrend_kind = _detrend_kind(w.detrend, fn)
    wx, wy = _split_window(w.window, True, fn)
    fs, x, y, batch = _prepare_pair(x, y, fs, fn, names=names)
    seg = _welch_segments(fn, x.shape[-1], batch, fs, (wx, wy), w)
    x = _check_finite(x, names[0], fn)
    y = _check_finite(y, names[1], fn)
    x = _check_exciting(x, names[0], "input", seg.records_axis, fn)
    y = _check_exciting(y, names[1], "output", seg.records_axis, fn)
    wx = _window_array(wx, seg, x.dtype, fn)
    wy = _window_array(wy, seg, y.dtype, fn)
    return _RatioInputs(x, y, wx, wy, seg, detrend_kind)


def _estimate(sxx: Array, syy: Array, sxy: Array, estimator: str) -> Array:
    if estimator == "h1":
        # H1: least squares with noise on the output only (Bendat & Piersol 2010, ch. 6).
        return sxy / sxx
    if estimator == "h2":
        # H2: least squares with noise on the input only (Ewins 2000, ch. 3).
        return syy / jnp.conj(sxy)
    # Hv (Rocklin, Crowley & Vold, IMAC 1985): total least squares. The direction [1, H]
    # is the principal eigenvector of the spectral matrix [[Sxx, Syx], [Sxy, Syy]]:
    # λ = (Sxx + Syy + r)/2, r = sqrt((Syy − Sxx)² + 4|Sxy|²), and
    # H = (λ − Sxx)/Syx = Sxy/(λ − Syy). Each row is cancellation-free on one side of
    # Syy = Sxx; the two branches are selected before dividing so gradients stay finite.
    d = syy - sxx
    r = jnp.sqrt(d**2 + 4 * (jnp.real(sxy) ** 2 + jnp.imag(sxy) ** 2))
    upper = d >= 0
    num = jnp.where(upper, (d + r).astype(sxy.dtype), 2 * sxy)
    den = jnp.where(upper, 2 * jnp.conj(sxy), (r - d).astype(sxy.dtype))
    return num / den


def coherence(
    x: Float[ArrayLike, "*batch time"],
    y: Float[ArrayLike, "*batch time"],
    fs: RealScalarLike,
    *,
    window="hann",
    nperseg: int | None = None,
    noverlap: int | None = None,
    nfft: int | None = None,
    df: float | None = None,
    detrend: Detrend = "constant",
    records_axis: int | None = None,
) -> tuple[Float[Array, " freq"], Float[Array, "*batch freq"]]:
    """Magnitude-squared (ordinary) coherence `γ² = |S_xy|² / (S_xx·S_yy)`.

    `γ² = 1` where `y` is a noise-free linear response of `x`; it drops with noise,
    leakage, nonlinearity or other unmeasured inputs (Bendat & Piersol, *Random Data*,
    4th ed., 2010, ch. 6).
    With a single block (`n_averages = 1`) it is 1 by construction and says nothing; a
    bin where either auto-spectrum is exactly zero gets `γ² = 0`. Matches
    `scipy.signal.coherence` for a single window (scipy returns NaN in those bins).

    **Arguments:**

    As [`csd`][]; `window` may also be a pair `(window_x, window_y)` (impact testing).

    **Returns:**

    `(frequency, γ²)`, `(freq,)` [Hz] and `(*batch, freq)`.

    **Raises:**

    As [`csd`][], and `ValueError` when a signal is constant (no spectrum).
    """
    welch = Welch(window, nperseg, noverlap, nfft, df, detrend, records_axis)
    r = _ratio_inputs("coherence", x, y, fs, welch, ("x", "y"))
    _, gamma2 = _ratio_core(r.x, r.y, r.wx, r.wy, r.seg, r.detrend, None, 0, False)
    return jnp.asarray(_frequencies(r.seg)), gamma2


def _metadata(seg: _Segments, estimator: str, detrend, extra=None) -> dict:
    meta = {
        "estimator": estimator.upper(),
        "fs": seg.fs,
        "nperseg": seg.nperseg,
        "noverlap": seg.noverlap,
        "nfft": seg.nfft,
        "window": seg.window_label,
        "detrend": _DETRENDS.get(detrend, str(detrend)),
    }
    meta.update(extra or {})
    return meta


def _n_averages(seg: _Segments) -> int:
    records = seg.batch[seg.records_axis] if seg.records_axis is not None else 1
    return seg.n_segments * records


def _frf(estimator, x, y, fs, *, welch, input_unit, output_unit, kind, fn) -> FRFData:
    r = _ratio_inputs(fn, x, y, fs, welch, ("x", "y"))
    h, gamma2 = _ratio_core(r.x, r.y, r.wx, r.wy, r.seg, r.detrend, estimator, 0, False)
    return FRFData(
        _frequencies(r.seg),
        h,
        coherence=gamma2,
        n_averages=_n_averages(r.seg),
        input_unit=input_unit,
        output_unit=output_unit,
        kind=kind,
        metadata=_metadata(r.seg, estimator, welch.detrend),
    )


_FRF_DOC = """FRF estimate `{formula}` from an input and an output record, with coherence.

{what}

**Arguments:**

- `x`: `(*batch, time)` input (excitation) records, e.g. force [N].
- `y`: `(*batch, time)` output (response) records on the same time base; leading axes
  broadcast with `x` (one input, several responses: `x` `(time,)`, `y` `(out, time)`).
- `fs`: sampling rate [Hz] (static under `jax.jit`), or a pair `(fs_x, fs_y)` that must
  agree.
- `welch`: a [`Welch`][] options object, or its fields as keywords: `window` (a name /
  samples shared by both channels, or a pair `(window_x, window_y)`, impact testing: see
  `impact_windows`), `nperseg`, `noverlap`, `nfft`, `df`, `detrend` (as in `csd`),
  `records_axis` (a leading axis of repeated records, e.g. 5 impact hits, averaged too;
  then each whole record is one block unless `nperseg`/`df` says otherwise).
- `input_unit`, `output_unit`: unit labels stored in the result (e.g. `"N"`, `"m/s^2"`).
- `kind`: what the FRF is (`"frf"`, `"receptance"`, `"mobility"`, `"accelerance"`).

**Returns:**

`FRFData` with `H` and `coherence` of shape `(*batch, freq)` (`records_axis` removed),
`n_averages` = segments × records, and the estimation settings in `metadata`. A bin
where the input or output spectrum is exactly zero (e.g. DC after `detrend="constant"`
with a rectangular window) has `H = 0` and `γ² = 0`. Judge every bin by its coherence:
band-limited excitation (a PRBS above its clock frequency, a hammer above its tip's
bandwidth) leaves bins with little input power, finite but unreliable estimates and a low
coherence.

**Raises:**

`ValueError` for signals of different lengths or sampling rates (resample first), a record
shorter than `nperseg` (or than `1/df`), NaN/inf samples, a constant input or output, and
inconsistent options; `TypeError` for complex signals or a traced `fs`. Under `jax.jit`
the value checks are `eqx.error_if`.
"""


@dataclasses.dataclass(frozen=True)
class Welch:
    """Welch averaging options of the spectra (`csd`, `psd`), the FRF estimators
    (`frf_h1`, `frf_h2`, `frf_hv`) and `transmissibility`, as one
    frozen object that can be built once and passed to several estimates.

    **Fields:** `window` (a name / samples shared by both channels, or a pair
    `(window_x, window_y)`), `nperseg`, `noverlap`, `nfft`, `df` [Hz], `detrend` (as in
    `csd`), `records_axis` (a leading axis of repeated records, averaged too).
    """

    window: Any = "hann"
    nperseg: int | None = None
    noverlap: int | None = None
    nfft: int | None = None
    df: float | None = None
    detrend: Any = "constant"
    records_axis: int | None = None


def _frf_estimator(estimator: str) -> Callable[..., FRFData]:
    """The public estimator `frf_<estimator>`: `welch=Welch(...)`, or its fields as
    keywords (`nperseg=...`), never both."""
    name = f"frf_{estimator}"

    def estimate(
        x: Float[ArrayLike, "*batch time"],
        y: Float[ArrayLike, "*batch time"],
        fs,
        *,
        welch: Welch | None = None,
        input_unit: str = "",
        output_unit: str = "",
        kind: str = "frf",
        **options: Any,
    ) -> FRFData:
        return _frf(
            estimator,
            x,
            y,
            fs,
            welch=options_object(Welch, welch, options, name, "welch"),
            input_unit=input_unit,
            output_unit=output_unit,
            kind=kind,
            fn=name,
        )

    estimate.__name__ = estimate.__qualname__ = name
    return estimate


frf_h1 = _frf_estimator("h1")
frf_h2 = _frf_estimator("h2")
frf_hv = _frf_estimator("hv")


frf_h1.__doc__ = _FRF_DOC.format(
    formula="H1 = S_xy / S_xx",
    what=(
        "H1 is the least-squares estimate with noise on the output only: unbiased by "
        "output noise, biased **low** by input noise, `E[H1] = H·S_uu/(S_uu + S_mm)` "
        "(Bendat & Piersol, *Random Data*, 4th ed., 2010, ch. 6). The usual choice for shaker / "
        "PRBS tests and the estimator of study 002. `|H1| = γ²·|H2|`."
    ),
)
frf_h2.__doc__ = _FRF_DOC.format(
    formula="H2 = S_yy / S_yx",
    what=(
        "H2 is the least-squares estimate with noise on the input only: unbiased by input "
        "noise, biased **high** by output noise, `E[H2] = H·(1 + S_nn/(|H|² S_uu))` "
        "(Ewins, *Modal Testing*, 2000, ch. 3). Preferred at resonances, where the response "
        "is strong and the force (leakage, noise) is the weak channel. `H1/H2 = γ²`."
    ),
)
frf_hv.__doc__ = _FRF_DOC.format(
    formula="Hv (total least squares)",
    what=(
        "Hv minimises the orthogonal distance of the `(X, Y)` pairs to the line `Y = H X`: "
        "per frequency `[1, Hv]` is the principal eigenvector of the 2×2 spectral matrix "
        "(Rocklin, Crowley & Vold, *Proc. 3rd IMAC*, 1985). Unbiased when input and output "
        "noise have equal spectra; `|H1| <= |Hv| <= |H2|`. Not invariant to the units of "
        "`x` and `y`: scale the signals so their noise levels are comparable."
    ),
)


def transmissibility(
    x_tool: Float[ArrayLike, "*batch time"],
    x_encoder: Float[ArrayLike, "*batch time"],
    fs,
    *,
    estimator: Estimator = "h1",
    tool_quantity: Literal["position", "velocity", "acceleration"] = "position",
    encoder_quantity: Literal["position", "velocity", "acceleration"] = "position",
    to_position: bool = True,
    length_unit: str = "m",
    welch: Welch | None = None,
    **options: Any,
) -> FRFData:
    """Transmissibility (TMF) `T_te = x_t / x_e` from two responses to the same excitation.

    The TMF of study 002 (eq. 6-7) maps the encoder-side motion to the tool-centre-point
    motion. It is estimated like an FRF with the encoder signal as "input":
    `T = S_et / S_ee` (H1, default), `S_tt / S_te` (H2) or the total-least-squares Hv,
    with the coherence between the two responses. Both signals must come from the same
    excitation location (a drive-side PRBS or a hammer hit near the encoder, study 002
    §2.4): a TMF depends on where the force acts.

    **Acceleration ↔ position.** A TMF between two accelerations equals the TMF between
    the positions (eq. 6: `a = s² x` on both sides cancels), so two accelerometers need no
    conversion. Conversion matters when the two signals are **different quantities**,
    e.g. an accelerometer at the TCP and the linear encoder's position: then
    `T_pos = T_meas · (jω)^(k_e − k_t)`, with `k` = 0, 1, 2 for position, velocity,
    acceleration, i.e. acceleration is integrated in the frequency domain by dividing by
    `(jω)²` (eq. 6). The tool channel is converted at the spectral level, so H2 and Hv are
    formed in consistent units. The factor is singular or zero at 0 Hz, so the DC bin is
    dropped whenever a conversion happens. The coherence does not change.

    **Arguments:**

    - `x_tool`: `(*batch, time)` tool-side response (the TMF's output).
    - `x_encoder`: `(*batch, time)` encoder-side response (the TMF's input), same time base.
    - `fs`: sampling rate [Hz], or a pair `(fs_tool, fs_encoder)` that must agree.
    - `estimator`: `"h1"` (noise on the tool signal), `"h2"` (noise on the encoder signal)
      or `"hv"` (both).
    - `tool_quantity`, `encoder_quantity`: `"position"`, `"velocity"` or `"acceleration"`.
    - `to_position`: convert to the TMF between positions (default); `False` keeps the
      ratio of the measured quantities.
    - `length_unit`: unit of length for the unit labels (default `"m"`).
    - `welch`: the Welch averaging options ([`Welch`][]), or its fields as keywords
      (`nperseg=...`, `records_axis=...`), as in [`frf_h1`][].

    **Returns:**

    `FRFData` of kind `"transmissibility"`.

    **Raises:**

    As [`frf_h1`][], and `ValueError` for an unknown estimator or quantity.
    """
    fn = "transmissibility"
    if estimator not in _ESTIMATORS:
        raise ValueError(f"{fn}: estimator must be one of {_ESTIMATORS}, got {estimator!r}.")
    quantities = (("tool_quantity", tool_quantity), ("encoder_quantity", encoder_quantity))
    for name, quantity in quantities:
        if quantity not in _QUANTITY_ORDER:
            raise ValueError(
                f"{fn}: {name} must be one of {tuple(_QUANTITY_ORDER)}, got {quantity!r}."
            )
    welch = options_object(Welch, welch, options, fn, "welch")
    r = _ratio_inputs(fn, x_encoder, x_tool, fs, welch, ("x_encoder", "x_tool"))
    k_t, k_e = _QUANTITY_ORDER[tool_quantity], _QUANTITY_ORDER[encoder_quantity]
    # The tool spectrum is re-expressed in the encoder's quantity, Y' = (jω)^power · Y;
    # the factor is singular (integration) or zero (differentiation) at DC, dropped then.
    power = k_e - k_t if to_position else 0
    frequency = _frequencies(r.seg)
    drop_dc = bool(power != 0 and frequency[0] == 0)
    h, gamma2 = _ratio_core(r.x, r.y, r.wx, r.wy, r.seg, r.detrend, estimator, power, drop_dc)
    frequency = frequency[1:] if drop_dc else frequency
    units = {0: length_unit, 1: f"{length_unit}/s", 2: f"{length_unit}/s^2"}
    input_unit = units[0 if to_position else k_e]
    output_unit = units[0 if to_position else k_t]
    extra = {
        "tool_quantity": tool_quantity,
        "encoder_quantity": encoder_quantity,
        "to_position": bool(to_position),
    }
    return FRFData(
        frequency,
        h,
        coherence=gamma2,
        n_averages=_n_averages(r.seg),
        input_unit=input_unit,
        output_unit=output_unit,
        kind="transmissibility",
        metadata=_metadata(r.seg, estimator, welch.detrend, extra),
    )
