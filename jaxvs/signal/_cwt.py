r"""Morlet continuous wavelet transform (CWT), ridge extraction and damping from free decays.

The damping identification of the drive study (Pislaru 2001, §7.3.4; after W. J.
Staszewski, "Identification of damping in MDOF systems using time-scale decomposition",
*J. Sound Vib.* 203(2), 1997, 283–305): the CWT of a free response with the Morlet
wavelet separates the modes in scale; along the ridge of one mode the modulus is its
envelope `A e^{−ζ ω_n t}`, so the slope of `ln |W|` against time gives `ζ ω_n` and the
ridge frequency the damped natural frequency `ω_d = ω_n sqrt(1 − ζ²)`.

**Definition used here.** With the analytic Morlet wavelet of centre frequency `ω0`
(`ψ̂(ω) = π^{−1/4} e^{−(ω − ω0)²/2}` for `ω > 0`, 0 otherwise; Grossmann & Morlet 1984,
Torrence & Compo 1998) and the scale `s = ω0 / (2π f)` of the analysed frequency `f`,

    W(f, b) = F⁻¹[ X(ω) · 2 e^{−(s ω − ω0)²/2} · 1(ω > 0) ](b),

i.e. an *amplitude-normalised* transform: for `x = A cos(2π f t + φ)`,
`W(f, b) = A e^{i(2π f b + φ)}` exactly, so `|W|` on the ridge is the envelope in the
unit of `x` and `arg W` its phase. The Gaussian in time has standard deviation `s`
[s]; the "cone of influence" where the record's ends bias `W` is `|b − edge| < 3 s`
(heuristic, where the Gaussian has fallen to 1 %).

Convolution by FFT (zero-padded to at least twice the record, so the ends do not wrap);
pure JAX, jittable, vmappable over records.
"""

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from .._misc import as_real
from ._filter import _positive_finite

__all__ = ["CWTDamping", "cwt_damping", "cwt_morlet", "cwt_ridge", "morlet_scales"]

DEFAULT_OMEGA0 = 6.0


def _check_omega0(omega0: float, where: str) -> float:
    try:
        w = float(omega0)
    except TypeError:
        raise TypeError(f"{where}: omega0 must be a Python float.") from None
    # heuristic: below ~5 the Morlet wavelet is not admissible (its mean is not ~0) and
    # the analytic approximation ψ̂(0) ≈ 0 fails.
    if not w >= 5:
        raise ValueError(
            f"{where}: omega0 = {omega0} is too small; the Morlet wavelet needs omega0 >= 5 "
            "(6 is the usual choice; larger values separate close modes better in frequency "
            "at the cost of time resolution)."
        )
    return w


def _as_record(x: ArrayLike, where: str) -> Array:
    x = as_real(x, f"{where}: x")
    if x.ndim < 1 or x.shape[-1] < 8:
        raise ValueError(
            f"{where}: x must be (*batch, time) with at least 8 samples; got shape {x.shape}."
        )
    return x


def _as_frequencies(frequencies: ArrayLike, dt: float, where: str) -> Array:
    f = jnp.asarray(frequencies)
    if not jnp.issubdtype(f.dtype, jnp.floating):
        f = f.astype(jnp.result_type(float))
    if f.ndim != 1 or f.shape[0] < 1:
        raise ValueError(f"{where}: frequencies must be 1-D (freq,) [Hz]; got shape {f.shape}.")
    fc = np.asarray(f) if not isinstance(f, jnp.ndarray) or not _traced(f) else None
    if fc is not None and (np.any(fc <= 0) or np.any(fc >= 0.5 / dt)):
        raise ValueError(
            f"{where}: analysis frequencies must lie in (0, {0.5 / dt:g}) Hz (below the "
            f"Nyquist frequency of dt = {dt:g} s); got [{fc.min():g}, {fc.max():g}] Hz."
        )
    return f


def _traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def morlet_scales(frequencies: ArrayLike, omega0: float = DEFAULT_OMEGA0) -> Array:
    """Wavelet scales `s = ω0 / (2π f)` [s] of the analysed frequencies `f` [Hz]; `s` is
    also the standard deviation of the wavelet's Gaussian envelope in time."""
    return omega0 / (2 * jnp.pi * jnp.asarray(frequencies))


def cwt_morlet(
    x: Float[ArrayLike, "*batch time"],
    dt: float,
    frequencies: Float[ArrayLike, " freq"],
    *,
    omega0: float = DEFAULT_OMEGA0,
) -> Complex[Array, "*batch freq time"]:
    r"""Amplitude-normalised Morlet CWT of `x` at the analysis `frequencies`.

    **Arguments:**

    - `x`: `(*batch, time)` real signal, sampled every `dt`.
    - `dt`: sample time [s].
    - `frequencies`: `(freq,)` analysis frequencies [Hz], in `(0, 1/(2 dt))`; log-spaced
      is usual.
    - `omega0`: centre frequency of the mother wavelet [rad] (static, >= 5; default 6).
      The relative frequency resolution is about `1/omega0`, the time resolution at `f`
      about `omega0/(2π f)` seconds.

    **Returns:**

    `(*batch, freq, time)` complex coefficients; `|W|` of a sinusoid of amplitude `A` at
    an analysis frequency is `A` (see the module docstring).
    """
    where = "cwt_morlet"
    x = _as_record(x, where)
    dt = _positive_finite(dt, f"{where}: dt", "sample time", " [s]")
    omega0 = _check_omega0(omega0, where)
    f = _as_frequencies(frequencies, dt, where)
    return _cwt(x, f, dt, omega0)


@functools.partial(jax.jit, static_argnums=(2, 3))
def _cwt(x: Array, f: Array, dt: float, omega0: float) -> Array:
    n = x.shape[-1]
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    X = jnp.fft.fft(x, nfft, axis=-1)
    omega = 2 * jnp.pi * jnp.fft.fftfreq(nfft, dt).astype(x.dtype)
    s = morlet_scales(f, omega0).astype(x.dtype)
    psi = 2 * jnp.exp(-0.5 * (s[:, None] * omega[None, :] - omega0) ** 2)
    psi = jnp.where(omega[None, :] > 0, psi, 0.0).astype(X.dtype)
    W = jnp.fft.ifft(X[..., None, :] * psi, axis=-1)
    return W[..., :n]


def cwt_ridge(
    coefficients: Complex[ArrayLike, "freq time"],
    frequencies: Float[ArrayLike, " freq"],
) -> tuple[Float[Array, " time"], Float[Array, " time"]]:
    """The ridge of a CWT: at every time, the frequency of largest modulus.

    The maximum over the frequency grid is refined by a parabola through the
    log-modulus at the three neighbouring grid points (in log-frequency), so the ridge is
    not quantised to the grid.

    **Arguments:**

    - `coefficients`: `(freq, time)` from [`cwt_morlet`][] (restrict the frequencies to
      the band of one mode to follow that mode).
    - `frequencies`: `(freq,)` the analysis frequencies [Hz], increasing.

    **Returns:**

    `(frequency, amplitude)`: ridge frequency [Hz] and modulus `|W|` on the ridge, each
    `(time,)`.
    """
    W = jnp.asarray(coefficients)
    f = jnp.asarray(frequencies)
    if W.ndim != 2 or W.shape[0] != f.shape[0]:
        raise ValueError(
            f"cwt_ridge: coefficients must be (freq, time) with freq = {f.shape[0]}; got {W.shape}."
        )
    tiny = jnp.finfo(jnp.abs(W).dtype).tiny
    logm = jnp.log(jnp.abs(W) + tiny)
    k = jnp.argmax(logm, axis=0)
    nf = f.shape[0]
    if nf < 3:
        return f[k], jnp.exp(jnp.take_along_axis(logm, k[None], 0)[0])
    kc = jnp.clip(k, 1, nf - 2)
    cols = jnp.arange(W.shape[1])
    y0, y1, y2 = logm[kc - 1, cols], logm[kc, cols], logm[kc + 1, cols]
    lf = jnp.log(f)
    x0, x1, x2 = lf[kc - 1], lf[kc], lf[kc + 1]
    # vertex of the parabola through three points (possibly non-uniform abscissae)
    d0, d2 = x0 - x1, x2 - x1
    a = ((y0 - y1) * d2 - (y2 - y1) * d0) / (d0 * d2 * (d0 - d2))
    b = ((y0 - y1) - a * d0**2) / d0
    interior = (k == kc) & (a < 0)
    shift = jnp.where(interior, jnp.clip(-b / (2 * jnp.where(a < 0, a, -1.0)), d0, d2), 0.0)
    peak = jnp.where(interior, y1 + b * shift + a * shift**2, logm[k, cols])
    return jnp.exp(x1 + shift), jnp.exp(peak)


class CWTDamping(eqx.Module):
    """Modal parameters of one mode from a free decay (see [`cwt_damping`][]).

    **Fields:**

    - `frequency_hz`: damped natural frequency `f_d` [Hz] (median ridge frequency).
    - `omega_n`: undamped natural frequency `sqrt(σ² + ω_d²)` [rad/s].
    - `zeta`: damping ratio `σ / ω_n` [-].
    - `decay_rate`: `σ = ζ ω_n` [1/s], minus the slope of `ln |W|`.
    - `amplitude`: `(time,)` `|W|` at the ridge scale (the envelope) [unit of x].
    - `ridge_hz`: `(time,)` ridge frequency at every time [Hz].
    - `window`: `(time,)` bool, the samples used in the envelope fit.
    """

    frequency_hz: Array
    omega_n: Array
    zeta: Array
    decay_rate: Array
    amplitude: Array
    ridge_hz: Array
    window: Array


def cwt_damping(
    x: Float[ArrayLike, " time"],
    dt: float,
    band: tuple[float, float],
    *,
    omega0: float = DEFAULT_OMEGA0,
    n_frequencies: int = 64,
    min_amplitude: float = 0.02,
    edge: float = 3.0,
) -> CWTDamping:
    r"""Damped frequency and damping ratio of the mode in `band` from a free response
    (Staszewski 1997, §3; Pislaru 2001, §7.3.4.2).

    1. `W = cwt_morlet(x)` on `n_frequencies` log-spaced frequencies in `band`;
    2. the ridge ([`cwt_ridge`][]) gives `f_d` (median over the window);
    3. `ln |W(f_d, b)| = c − σ b` is fitted by least squares over the window: samples
       outside the cone of influence (`edge` wavelet standard deviations from either
       end) whose envelope is above `min_amplitude` × its maximum (below, noise flattens
       the decay);
    4. `ω_n = sqrt(σ² + (2π f_d)²)`, `ζ = σ / ω_n`.

    **Arguments:**

    - `x`: `(time,)` free response (displacement, velocity or acceleration: the envelope
      decays at the same rate), e.g. an impulse response. Starts at the excitation.
    - `dt`: sample time [s].
    - `band`: `(f_low, f_high)` [Hz] containing one mode only (and its ridge for the whole
      decay); choose `omega0` so that neighbouring modes are at least `~3 f/omega0` away.
    - `omega0`: Morlet centre frequency (static, >= 5).
    - `n_frequencies`: number of analysis frequencies in the band (static).
    - `min_amplitude`: relative envelope level where the fit stops (noise floor).
    - `edge`: half width of the excluded cone of influence, in wavelet standard deviations
      `s = omega0 / (2π f_d)`.

    **Returns:**

    A [`CWTDamping`][].

    **Raises:**

    `ValueError` for a band outside `(0, Nyquist)`, or (with concrete data) when fewer
    than 8 samples remain for the fit: the record is too short for this `omega0` (the
    cone of influence covers it) or the decay too fast.
    """
    where = "cwt_damping"
    x = _as_record(x, where)
    if x.ndim != 1:
        raise ValueError(f"{where}: x must be 1-D (time,); vmap over several records.")
    dt = _positive_finite(dt, f"{where}: dt", "sample time", " [s]")
    try:
        f_lo, f_hi = (float(b) for b in band)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: band must be a pair (f_low, f_high) in Hz.") from None
    if not 0 < f_lo < f_hi < 0.5 / dt:
        raise ValueError(
            f"{where}: band must satisfy 0 < f_low < f_high < {0.5 / dt:g} Hz (Nyquist); "
            f"got ({f_lo:g}, {f_hi:g})."
        )
    if not isinstance(n_frequencies, int) or n_frequencies < 3:
        raise ValueError(f"{where}: n_frequencies must be an int >= 3.")
    freqs = jnp.asarray(np.geomspace(f_lo, f_hi, n_frequencies), x.dtype)
    _check_omega0(omega0, where)
    out, sw = _damping_core(x, freqs, dt, float(omega0), float(edge), min_amplitude)
    count = np.asarray(sw) if not _traced(sw) else None
    if count is not None and count < 8:
        raise ValueError(
            f"{where}: only {int(count)} samples are left for the envelope fit; the record "
            "is too short for this omega0 (the cone of influence covers it) or the decay "
            "falls below min_amplitude too fast. Record longer, lower omega0, or lower "
            "min_amplitude."
        )
    return out


@functools.partial(jax.jit, static_argnums=(2, 3, 4))
def _damping_core(x, freqs, dt, omega0, edge, min_amplitude):
    W = _cwt(x, freqs, dt, omega0)
    n_frequencies = freqs.shape[0]
    ridge_hz, ridge_amp = cwt_ridge(W, freqs)
    n = x.shape[0]
    t = dt * jnp.arange(n, dtype=x.dtype)
    # ridge frequency over the part of the record with energy (no cone cut yet)
    strong = ridge_amp >= min_amplitude * jnp.max(ridge_amp)
    fd0 = _masked_median(ridge_hz, strong)
    s = omega0 / (2 * jnp.pi * fd0)
    inside = (t >= edge * s) & (t <= t[-1] - edge * s)
    # the envelope at the (fixed) ridge scale: interpolate |W| between grid frequencies
    logm = jnp.log(jnp.abs(W) + jnp.finfo(x.dtype).tiny)
    lf = jnp.log(freqs)
    pos = jnp.interp(jnp.log(fd0), lf, jnp.arange(n_frequencies, dtype=x.dtype))
    k0 = jnp.clip(jnp.floor(pos).astype(int), 0, n_frequencies - 2)
    w1 = pos - k0
    env_log = (1 - w1) * logm[k0] + w1 * logm[k0 + 1]
    env = jnp.exp(env_log)
    window = inside & (env >= min_amplitude * jnp.max(jnp.where(inside, env, 0.0)))
    fd = _masked_median(ridge_hz, window)
    # weighted least squares for ln|W| = c − σ t over the window
    w = window.astype(x.dtype)
    sw = jnp.sum(w)
    tm = jnp.sum(w * t) / sw
    ym = jnp.sum(w * env_log) / sw
    slope = jnp.sum(w * (t - tm) * (env_log - ym)) / jnp.sum(w * (t - tm) ** 2)
    sigma = -slope
    wd = 2 * jnp.pi * fd
    wn = jnp.sqrt(sigma**2 + wd**2)
    out = CWTDamping(
        frequency_hz=fd,
        omega_n=wn,
        zeta=sigma / wn,
        decay_rate=sigma,
        amplitude=env,
        ridge_hz=ridge_hz,
        window=window,
    )
    return out, sw


def _masked_median(x: Array, mask: Array) -> Array:
    """Median of `x[mask]` with a static shape (masked entries sorted to the end)."""
    big = jnp.where(mask, x, jnp.inf)
    srt = jnp.sort(big)
    m = jnp.sum(mask)
    lo = srt[jnp.maximum((m - 1) // 2, 0)]
    hi = srt[jnp.maximum(m // 2, 0)]
    return 0.5 * (lo + hi)
