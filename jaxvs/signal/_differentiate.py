"""Numerical time derivatives of sampled signals (velocities and accelerations from positions).

Runs in JAX (jit/vmap/grad compatible), because derivatives of measured positions are the
regressors of inverse-dynamics identification (`q̇`, `q̈` in the EMPS study) and are rebuilt
inside calibration pipelines.
"""

import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._filter import _as_real_signal, _check_axis, _check_finite, _positive_float

_METHODS = ("central", "spectral")
# Order of the Butterworth-shaped taper of the spectral method: |H|² of a 4th-order
# Butterworth, i.e. the same magnitude as filtfilt_lowpass(order=4).
_TAPER_ORDER = 4


def _check_dt(dt, fn: str):
    if isinstance(dt, jax.core.Tracer):
        dt = jnp.asarray(dt)
        if dt.ndim != 0:
            raise ValueError(f"{fn}: dt must be a scalar sampling period [s], got {dt.shape}.")
        return eqx.error_if(dt, ~(dt > 0), f"{fn}: dt must be a positive sampling period [s].")
    try:
        value = float(dt)
    except (TypeError, ValueError):
        raise TypeError(
            f"{fn}: dt must be a scalar sampling period [s], got {dt!r}. For a non-uniform "
            "time vector, resample first with jaxvs.signal.resample."
        ) from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{fn}: dt must be a positive finite sampling period [s], got {dt!r}.")
    return value


def _central(x: Array, dt, order: int) -> Array:
    """Second-order accurate finite differences along axis 0 (Fornberg 1988, Table 1)."""
    if order == 1:
        # Interior: (x[i+1] − x[i−1]) / 2dt. Ends: one-sided (∓3x₀ ± 4x₁ ∓ x₂) / 2dt.
        # Same stencils as numpy.gradient(edge_order=2); truncation error −h²x'''/6 inside.
        interior = (x[2:] - x[:-2]) / (2 * dt)
        first = (-3 * x[0] + 4 * x[1] - x[2]) / (2 * dt)
        last = (3 * x[-1] - 4 * x[-2] + x[-3]) / (2 * dt)
    else:
        # Interior: (x[i+1] − 2x[i] + x[i−1]) / dt², error −h²x''''/12.
        # Ends: one-sided (2x₀ − 5x₁ + 4x₂ − x₃) / dt², error 11h²x''''/12.
        interior = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
        first = (2 * x[0] - 5 * x[1] + 4 * x[2] - x[3]) / dt**2
        last = (2 * x[-1] - 5 * x[-2] + 4 * x[-3] - x[-4]) / dt**2
    return jnp.concatenate([first[None], interior, last[None]], axis=0)


def _end_curvature_weights(k: int) -> np.ndarray:
    """Weights `w` such that `w @ x[:k] ≈ x''(t₀)·dt²` (least-squares cubic over k samples)."""
    s = np.arange(k, dtype=np.float64)
    vandermonde = np.stack([s**j for j in range(4)], axis=1)
    return 2 * np.linalg.pinv(vandermonde)[2]  # x''(0) = 2·(coefficient of s²)


def _end_window(n: int, dt, cutoff: float | None) -> int:
    """Samples used to estimate the end curvatures of the spectral method.

    Heuristic: 8 samples (a cubic over 8 samples is accurate on smooth data); with a
    low-pass, one period of the cut-off frequency, `1/(cutoff·dt)` samples, so that noise
    above the cut-off does not enter the estimate (a cubic over one period still follows
    content below the cut-off). The estimate only shapes the end correction, never the
    derivative itself (see `_spectral`).
    """
    k = 8
    if cutoff is not None and not isinstance(dt, jax.core.Tracer):
        k = max(k, math.ceil(1 / (cutoff * dt)))
    return min(n, k)


def _spectral(x: Array, dt, order: int, cutoff: float | None) -> Array:
    """FFT differentiation of a non-periodic record along axis 0.

    The FFT derivative `x^(k) = IFFT[(i2πf)^k · X(f)]` (Trefethen, *Spectral Methods in
    MATLAB*, SIAM 2000, ch. 3) assumes a periodic signal; a record is not. So:
    1. subtract a cubic `p` that matches the two end samples and (estimated) end
       curvatures; its derivative is added back exactly, so errors in the curvature
       estimates only affect the end smoothness, never the derivative of `p`;
    2. extend the residual `r = x − p` oddly about both ends (length `2n − 2`, a sine
       series): `r = 0` and `r'' ≈ 0` at the ends make the periodic extension smooth up to
       the third derivative, so the spectrum decays fast and the derivatives have no Gibbs
       ringing at the ends (with plain line removal the second derivative would jump from
       `r''` to `−r''` there);
    3. optionally multiply by the zero-phase Butterworth magnitude
       `1 / (1 + (f/cutoff)^(2·4))` (the `|H|²` of a 4th-order Butterworth, the same
       low-pass as `filtfilt_lowpass(order=4)`), which tames amplified noise: the
       derivative multiplies noise at frequency f by `(2πf)^k`.
    """
    n = x.shape[0]
    span = (n - 1) * dt  # record length T [s]; s = (t − t₀)/T ∈ [0, 1]
    shape = (n,) + (1,) * (x.ndim - 1)
    s = (jnp.arange(n, dtype=x.dtype) / (n - 1)).reshape(shape)
    weights = jnp.asarray(_end_curvature_weights(_end_window(n, dt, cutoff)), dtype=x.dtype)
    k = weights.shape[0]
    # End curvatures in s-units: d²x/ds² = T²·x'' = (n−1)²·dt²·x''.
    c0 = jnp.tensordot(weights, x[:k], axes=(0, 0)) * (n - 1) ** 2
    c1 = jnp.tensordot(weights, x[::-1][:k], axes=(0, 0)) * (n - 1) ** 2
    # p(s) = a + b·s + c·s² + d·s³ with p(0) = x₀, p(1) = x_{n−1}, p''(0) = c0, p''(1) = c1.
    a = x[0]
    c = c0 / 2
    d = (c1 - c0) / 6
    b = x[-1] - a - c - d
    poly = a + b * s + c * s**2 + d * s**3
    if order == 1:
        poly_derivative = (b + 2 * c * s + 3 * d * s**2) / span
    else:
        poly_derivative = (2 * c + 6 * d * s) / span**2
    residual = x - poly
    extended = jnp.concatenate([residual, -residual[-2:0:-1]], axis=0)
    m = extended.shape[0]  # 2n − 2, even
    spectrum = jnp.fft.rfft(extended, axis=0)
    f = jnp.fft.rfftfreq(m, d=1.0).astype(x.dtype) / dt  # [Hz]
    gain = (2j * jnp.pi * f) ** order
    if order % 2 == 1:
        # The Nyquist bin of an odd derivative of a real signal is ill-defined (its
        # imaginary part is dropped by the inverse real FFT); zero it explicitly.
        gain = gain.at[-1].set(0)
    if cutoff is not None:
        gain = gain / (1 + (f / cutoff) ** (2 * _TAPER_ORDER))
    gain = gain.reshape((-1,) + (1,) * (x.ndim - 1))
    derivative = jnp.fft.irfft(spectrum * gain, n=m, axis=0)[:n]
    return (derivative + poly_derivative).astype(x.dtype)


def differentiate(
    x: Float[ArrayLike, "*batch time"],
    dt: float,
    *,
    order: Literal[1, 2] = 1,
    method: Literal["central", "spectral"] = "central",
    cutoff: float | None = None,
    axis: int = -1,
) -> Float[Array, "*batch time"]:
    """First or second time derivative of uniformly sampled signals.

    - `method="central"`: second-order accurate central differences inside and one-sided
        second-order differences at both ends (B. Fornberg, "Generation of finite
        difference formulas on arbitrarily spaced grids", *Math. Comp.* 51, 1988); for
        `order=1` identical to `numpy.gradient(x, dt, edge_order=2)`. Truncation error
        `h²·x'''/6` (order 1) or `h²·x''''/12` (order 2) inside, with `h = dt`. Noise is
        amplified by up to `1/dt` (order 1) or `4/dt²` (order 2): low-pass first with
        `filtfilt_lowpass`.
    - `method="spectral"`: FFT differentiation after removing the end-to-end line and
        extending the residual oddly (a sine series), optionally with a zero-phase
        Butterworth low-pass of `cutoff` [Hz] applied in the frequency domain (Trefethen
        2000, ch. 3). Near spectral accuracy inside the record for band-limited content;
        a smooth end correction (a cubic matching end values and curvatures) keeps the ends
        free of Gibbs ringing. The low-pass, like any filter, distorts content near
        `cutoff` and within a few `1/cutoff` of the ends.

    Runs in JAX: jit/vmap/grad compatible in `x` (and `dt`).

    **Arguments:**

    - `x`: signal(s) `(*batch, time)` sampled every `dt`, e.g. positions [m] or [rad].
    - `dt`: sampling period [s].
    - `order`: 1 (velocity from position) or 2 (acceleration).
    - `method`: `"central"` or `"spectral"`.
    - `cutoff`: low-pass cut-off [Hz] of the spectral method (`0 < cutoff`; above `fs/2`
        it has no effect). `None` keeps every frequency. Only for `method="spectral"`.
    - `axis`: the time axis of `x` (default last).

    **Returns:**

    The derivative, same shape as `x`, in units of `x` per second (order 1) or per second
    squared (order 2).

    **Raises:**

    `ValueError` for an unknown method or order, a non-positive `dt`, a record shorter than
    the stencil (3 samples for order 1, 4 for order 2), a `cutoff` with `method="central"`,
    or NaN/inf samples (`eqx.error_if` under jit); `TypeError` for complex `x`.
    """
    fn = "differentiate"
    if method not in _METHODS:
        raise ValueError(f"{fn}: method must be one of {_METHODS}, got {method!r}.")
    if isinstance(order, bool) or order not in (1, 2):
        raise ValueError(
            f"{fn}: order must be 1 or 2, got {order!r}; for higher derivatives apply "
            "differentiate repeatedly (and low-pass in between)."
        )
    x = _as_real_signal(x, fn)
    axis = _check_axis(axis, x.ndim, fn)
    dt = _check_dt(dt, fn)
    if cutoff is not None:
        if method != "spectral":
            raise ValueError(
                f"{fn}: cutoff is only used by method='spectral'; with central differences "
                "low-pass first with jaxvs.signal.filtfilt_lowpass(x, fs, cutoff)."
            )
        cutoff = _positive_float(cutoff, "cutoff", fn)
    n_min = order + 2
    if x.shape[axis] < n_min:
        raise ValueError(
            f"{fn}: a derivative of order {order} needs at least {n_min} samples along the "
            f"time axis; got {x.shape[axis]}."
        )
    x = _check_finite(x, fn)
    xt = jnp.moveaxis(x, axis, 0)
    if method == "central":
        out = _central(xt, dt, order)
    else:
        out = _spectral(xt, dt, order, cutoff)
    return jnp.moveaxis(out, 0, axis)
