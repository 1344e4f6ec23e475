"""Zero-phase IIR filtering and decimation in JAX.

Design choice: the filter *coefficients* are designed on the host with `scipy.signal`
(`butter`, `cheby1`, `sosfilt_zi`): they depend only on Python numbers (order, cutoff,
sampling rate), so they are static constants of the computation. The *filtering* runs in
JAX (`jax.lax.scan` over time, vectorised over every leading axis), so it is jit/vmap/grad
compatible and can sit inside an identification pipeline (e.g. filtering positions before
differentiating them for inverse-dynamics regressors).

Filters run as cascaded second-order sections in transposed direct form II, the numerically
robust form used by `scipy.signal.sosfilt` (a 4th-order Butterworth at `cutoff/fs = 1e-3`
loses ~6 digits in transfer-function `(b, a)` form, none in sections). Zero-phase filtering
follows Gustafsson's forward–backward scheme as implemented by `scipy.signal.filtfilt` /
`sosfiltfilt`: odd extension of `padlen` samples at both ends, steady-state initial
conditions scaled by the first sample of each pass (F. Gustafsson, "Determining the initial
states in forward-backward filtering", *IEEE Trans. Signal Process.* 44(4), 1996).
"""

import math
import operator

import jax
import jax.numpy as jnp
import numpy as np
import scipy.signal as ss
from jaxtyping import Array, ArrayLike, Float

from .._misc import check_finite, real_array

# ---------------------------------------------------------------------------------------
# Validation helpers (shared with _differentiate.py)
# ---------------------------------------------------------------------------------------


def _as_real_signal(x, fn: str) -> Array:
    x = real_array(
        x,
        f"{fn}: x must be a real signal; got a complex array. Filter the real and "
        "imaginary parts separately.",
    )
    if x.ndim < 1:
        raise ValueError(f"{fn}: x must be a signal of shape (*batch, time); got a scalar.")
    return x


def _check_axis(axis, ndim: int, fn: str) -> int:
    try:
        axis = operator.index(axis)
    except TypeError:
        raise TypeError(f"{fn}: axis must be an integer, got {axis!r}.") from None
    if not -ndim <= axis < ndim:
        raise ValueError(
            f"{fn}: axis={axis} is out of range for x with {ndim} dimension(s); pass the "
            "index of the time axis (default -1)."
        )
    return axis % ndim


def _check_finite(x: Array, fn: str) -> Array:
    """NaN/inf would silently spread over the whole record through the IIR recursion."""
    fix = (
        "Remove or interpolate them (e.g. with jaxvs.signal.resample on the valid samples) "
        "before filtering."
    )
    return check_finite(x, f"{fn}: x", fix, unit="sample(s)")


def _positive_float(value, name: str, fn: str) -> float:
    if isinstance(value, jax.core.Tracer):
        raise TypeError(
            f"{fn}: {name} must be a concrete Python number (the filter is designed on the "
            "host with scipy.signal); do not pass it as a traced jit argument — close over "
            "it or mark it static."
        )
    return _positive_finite(value, f"{fn}: {name}")


def _positive_finite(value, what: str, kind: str = "number", unit: str = "") -> float:
    """`value` as a positive finite float; errors name `what`, e.g. "resample: dt", as a
    `kind` ("period") in `unit` (" [s]")."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{what} must be a number{unit}, got {value!r}.") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be a positive finite {kind}{unit}, got {value!r}.")
    return value


def _positive_int(value, name: str, fn: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TypeError(f"{fn}: {name} must be a positive integer, got {value!r}.")
    if value < 1:
        raise ValueError(f"{fn}: {name} must be a positive integer, got {value!r}.")
    return int(value)


# ---------------------------------------------------------------------------------------
# Core recursions
# ---------------------------------------------------------------------------------------


def _sosfilt_time_major(sos: np.ndarray, x: Array, zi: Array) -> Array:
    """Cascade of biquads in transposed direct form II along axis 0 of `x`.

    `sos` is `(section, 6)` = `[b0, b1, b2, 1, a1, a2]`; `zi` is `(section, 2, *rest)`. Per
    section and sample (scipy.signal.sosfilt's recursion):
    `y = b0·u + z0`, `z0 ← b1·u − a1·y + z1`, `z1 ← b2·u − a2·y`.
    """
    coef = jnp.asarray(sos, dtype=x.dtype)
    n_sections = sos.shape[0]

    def step(z, u):
        new_z = []
        for k in range(n_sections):  # static, small (order/2 sections)
            b0, b1, b2, _, a1, a2 = (coef[k, j] for j in range(6))
            y = b0 * u + z[k, 0]
            new_z.append(jnp.stack([b1 * u - a1 * y + z[k, 1], b2 * u - a2 * y]))
            u = y
        return jnp.stack(new_z), u

    _, y = jax.lax.scan(step, zi.astype(x.dtype), x)
    return y


def _odd_extension(x: Array, padlen: int) -> Array:
    """Odd (point-symmetric) extension about both end samples along axis 0, as scipy's."""
    if padlen == 0:
        return x
    left = 2 * x[:1] - x[padlen:0:-1]
    right = 2 * x[-1:] - x[-2 : -padlen - 2 : -1]
    return jnp.concatenate([left, x, right], axis=0)


def _sosfiltfilt(sos: np.ndarray, x: Array, axis: int, padlen: int, fn: str) -> Array:
    n_time = x.shape[axis]
    if n_time <= padlen:
        raise ValueError(
            f"{fn}: the signal has {n_time} samples along axis {axis}, but zero-phase "
            f"filtering pads {padlen} samples at each end and needs more than {padlen}. "
            "Use a longer record or a lower filter order."
        )
    xt = jnp.moveaxis(x, axis, 0)
    # Steady-state state of each section for a unit step input (host-side, static).
    zi_unit = jnp.asarray(ss.sosfilt_zi(sos), dtype=x.dtype)  # (section, 2)
    expand = (...,) + (None,) * (xt.ndim - 1)
    ext = _odd_extension(xt, padlen)
    y = _sosfilt_time_major(sos, ext, zi_unit[expand] * ext[0])
    y = _sosfilt_time_major(sos, y[::-1], zi_unit[expand] * y[-1])[::-1]
    if padlen:
        y = y[padlen:-padlen]
    return jnp.moveaxis(y, 0, axis)


def _default_padlen(sos: np.ndarray) -> int:
    # scipy.signal.sosfiltfilt's default: 3 × (number of filter coefficients), discounting
    # trailing zero coefficients of first-order sections.
    n_zeros = min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return 3 * (2 * sos.shape[0] + 1 - n_zeros)


# ---------------------------------------------------------------------------------------
# Public functions
# ---------------------------------------------------------------------------------------


def filtfilt_lowpass(
    x: Float[ArrayLike, "*batch time"],
    fs: float,
    cutoff: float,
    *,
    order: int = 4,
    padlen: int | None = None,
    axis: int = -1,
) -> Float[Array, "*batch time"]:
    """Zero-phase Butterworth low-pass filter (forward–backward, like `scipy.signal.filtfilt`).

    The Butterworth filter of `order` is designed with `scipy.signal.butter` and run forward
    and then backward, so the result has zero phase shift and the squared magnitude
    response `|H(f)|² = 1 / (1 + (f/cutoff)^(2·order))` (digital, bilinear-warped): the
    attenuation at `cutoff` is −6 dB, not −3 dB. Ends are handled as in scipy: odd
    extension of `3·(order + 1)` samples and steady-state initial conditions (Gustafsson,
    1996), so a record starting at an offset or on a ramp shows no start-up transient.
    The result equals `scipy.signal.filtfilt(*butter(order, cutoff, fs=fs), x)` up to
    round-off (and is better conditioned for low `cutoff/fs`, as it runs in second-order
    sections).

    Runs in JAX: jit/vmap/grad compatible in `x`; `fs`, `cutoff` and `order` must be
    concrete Python numbers (the filter is designed on the host).

    **Arguments:**

    - `x`: real signal(s) `(*batch, time)`; every leading axis is filtered independently.
    - `fs`: sampling rate [Hz].
    - `cutoff`: cut-off frequency [Hz], `0 < cutoff < fs/2`.
    - `order`: order of the Butterworth prototype (the zero-phase result has twice the
        attenuation slope, `40·order` dB/decade of power).
    - `padlen`: samples of odd extension at each end (default scipy's `3·(order + 1)`).
        Heuristic: for `cutoff ≪ fs` the filter's memory (≈ `fs/cutoff` samples) is much
        longer than the default padding, and the start-up transient of a record that
        starts on a slope leaks into the first and last samples; `padlen ≈ 3·fs/cutoff`
        removes it (e.g. before differentiating a ramp).
    - `axis`: the time axis of `x` (default last).

    **Returns:**

    The filtered signal, same shape as `x` (floating dtype of `x`).

    **Raises:**

    `ValueError` for a cutoff outside `(0, fs/2)`, a non-positive `fs` or `order`, a
    negative `padlen`, a record not longer than the padding, or NaN/inf samples
    (`eqx.error_if` under jit); `TypeError` for complex `x` or traced `fs`/`cutoff`.
    """
    fn = "filtfilt_lowpass"
    x = _as_real_signal(x, fn)
    axis = _check_axis(axis, x.ndim, fn)
    fs = _positive_float(fs, "fs", fn)
    cutoff = _positive_float(cutoff, "cutoff", fn)
    order = _positive_int(order, "order", fn)
    if not cutoff < fs / 2:
        raise ValueError(
            f"{fn}: cutoff = {cutoff:g} Hz must lie below the Nyquist frequency fs/2 = "
            f"{fs / 2:g} Hz."
        )
    sos = ss.butter(order, cutoff, btype="low", fs=fs, output="sos")
    if padlen is None:
        padlen = _default_padlen(sos)
    elif isinstance(padlen, bool) or not isinstance(padlen, int | np.integer) or padlen < 0:
        raise ValueError(f"{fn}: padlen must be a non-negative integer, got {padlen!r}.")
    x = _check_finite(x, fn)
    return _sosfiltfilt(sos, x, axis, int(padlen), fn)


def decimate(
    x: Float[ArrayLike, "*batch time"],
    factor: int,
    *,
    zero_phase: bool = True,
    axis: int = -1,
) -> Float[Array, "*batch time_out"]:
    """Downsample by an integer factor after an anti-aliasing filter (`scipy.signal.decimate`).

    The anti-aliasing filter is scipy's default: an 8th-order Chebyshev type I low-pass
    with 0.05 dB pass-band ripple and edge at `0.8·(fs/2)/factor`, in second-order
    sections; it is run forward–backward (`zero_phase=True`, no delay, doubled attenuation)
    or forward only with zero initial state (`zero_phase=False`, causal, with phase lag).
    Then every `factor`-th sample is kept, starting with the first, so the output has
    `ceil(n_time / factor)` samples and sampling period `factor·dt`. `factor=1` returns
    `x` unchanged (scipy would still low-pass it at `0.8·fs/2`).

    Runs in JAX (jit/vmap/grad in `x`); `factor` must be a Python integer.

    **Arguments:**

    - `x`: real signal(s) `(*batch, time)`.
    - `factor`: integer downsampling factor ≥ 1 (scipy recommends ≤ 13; decimate in
        stages for larger factors).
    - `zero_phase`: forward–backward filtering (default) or causal filtering.
    - `axis`: the time axis of `x` (default last).

    **Returns:**

    The decimated signal, shape of `x` with the time axis of length `ceil(n_time/factor)`.

    **Raises:**

    `ValueError` for `factor < 1`, a record too short for zero-phase padding (27 samples)
    or NaN/inf samples; `TypeError` for non-integer `factor` or complex `x`.
    """
    fn = "decimate"
    x = _as_real_signal(x, fn)
    axis = _check_axis(axis, x.ndim, fn)
    factor = _positive_int(factor, "factor", fn)
    if factor == 1:
        return x
    x = _check_finite(x, fn)
    sos = ss.cheby1(8, 0.05, 0.8 / factor, output="sos")
    if zero_phase:
        y = _sosfiltfilt(sos, x, axis, _default_padlen(sos), fn)
    else:
        xt = jnp.moveaxis(x, axis, 0)
        zi = jnp.zeros((sos.shape[0], 2) + xt.shape[1:], dtype=x.dtype)
        y = jnp.moveaxis(_sosfilt_time_major(sos, xt, zi), 0, axis)
    index = [slice(None)] * y.ndim
    index[axis] = slice(None, None, factor)
    return y[tuple(index)]
