"""Data windows for spectral estimation and impact testing.

The classical windows (`hann`, `hamming`, `boxcar`, `flattop`) are the periodic
("DFT-even") forms by default, as `scipy.signal.get_window` gives them to `welch`/`csd`.
The impact-testing windows (`force_window`, `exponential_window`, `impact_windows`) follow
experimental modal analysis practice (Ewins, *Modal Testing*, 2000, ch. 3; Fladung & Rost,
"Application and correction of the exponential window for frequency response functions",
*Mech. Syst. Signal Process.* 11(1), 1997).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._custom_types import RealScalarLike

# Coefficients of the general cosine windows w = Σ_k a_k cos(k·x), x ∈ [-π, π]
# (Harris, Proc. IEEE 66(1), 1978; flat top: D'Antonio's five-term window as in
# scipy.signal.windows.flattop).
_COSINE_COEFFS = {
    "hann": (0.5, 0.5),
    "hamming": (0.54, 0.46),
    "boxcar": (1.0,),
    "flattop": (0.21557895, 0.41663158, 0.277263158, 0.083578947, 0.006947368),
}
WINDOW_NAMES = tuple(_COSINE_COEFFS)
_ALIASES = {"hanning": "hann", "rectangular": "boxcar", "rect": "boxcar", "ones": "boxcar"}


def _check_length(n: int, fn: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"{fn}: the window length must be a positive int, got {n!r}.")
    return int(n)


def _general_cosine(n: int, coeffs: tuple[float, ...], periodic: bool) -> np.ndarray:
    if n == 1:
        return np.ones(1)
    # A periodic window of length n is the symmetric one of length n + 1 without its
    # last sample, so that its n-point DFT has no discontinuity at the wrap-around.
    m = n + 1 if periodic else n
    x = np.linspace(-np.pi, np.pi, m)
    w = sum(a * np.cos(k * x) for k, a in enumerate(coeffs))
    return np.asarray(w[:n], dtype=np.float64)


def _named(name: str, n: int, periodic: bool, dtype) -> Float[Array, " n"]:
    w = _general_cosine(n, _COSINE_COEFFS[name], periodic)
    return jnp.asarray(w, dtype=jnp.result_type(float) if dtype is None else dtype)


def hann(n: int, *, periodic: bool = True, dtype=None) -> Float[Array, " n"]:
    """Hann window `0.5 − 0.5 cos(2π k / N)`, `N = n` (periodic) or `n − 1` (symmetric).

    **Arguments:**

    - `n`: number of samples.
    - `periodic`: the DFT-even form used for spectral analysis (default), or the
      symmetric one used for filter design (`periodic=False`, scipy's default).
    - `dtype`: floating dtype of the result (default: JAX's default float).

    **Returns:**

    `(n,)` window, equal to `scipy.signal.windows.hann(n, sym=not periodic)`.
    """
    return _named("hann", _check_length(n, "hann"), periodic, dtype)


def hamming(n: int, *, periodic: bool = True, dtype=None) -> Float[Array, " n"]:
    """Hamming window `0.54 − 0.46 cos(2π k / N)`; arguments as [`hann`][]."""
    return _named("hamming", _check_length(n, "hamming"), periodic, dtype)


def boxcar(n: int, *, periodic: bool = True, dtype=None) -> Float[Array, " n"]:
    """Rectangular window (all ones); arguments as [`hann`][]."""
    del periodic
    return _named("boxcar", _check_length(n, "boxcar"), True, dtype)


def flattop(n: int, *, periodic: bool = True, dtype=None) -> Float[Array, " n"]:
    """Five-term flat-top window (amplitude-accurate spectra of sinusoids, < 0.01 dB
    scalloping); arguments as [`hann`][]."""
    return _named("flattop", _check_length(n, "flattop"), periodic, dtype)


def get_window(name: str, n: int, *, periodic: bool = True, dtype=None) -> Float[Array, " n"]:
    """A window by name: one of `"hann"`, `"hamming"`, `"boxcar"`, `"flattop"` (aliases
    `"hanning"`, `"rectangular"`).

    **Raises:**

    `ValueError` for an unknown name.
    """
    if not isinstance(name, str):
        raise TypeError(f"get_window: the window name must be a string, got {name!r}.")
    key = _ALIASES.get(name.lower(), name.lower())
    if key not in _COSINE_COEFFS:
        raise ValueError(
            f"Unknown window {name!r}; use one of {WINDOW_NAMES}, or pass the window samples "
            "as an array (e.g. jaxvs.signal.exponential_window(...))."
        )
    return _named(key, _check_length(n, "get_window"), periodic, dtype)


def _time(n: int, fs: float, dtype) -> Array:
    return jnp.arange(n, dtype=jnp.result_type(float) if dtype is None else dtype) / fs


def _check_fs(fs: RealScalarLike, fn: str) -> float:
    if isinstance(fs, jax.core.Tracer):
        raise TypeError(
            f"{fn}: the sampling rate fs must be a concrete number (it fixes array shapes); "
            "mark it static under jax.jit, e.g. jax.jit(f, static_argnames='fs')."
        )
    fs_value = float(fs)
    if not math.isfinite(fs_value) or fs_value <= 0:
        raise ValueError(
            f"{fn}: the sampling rate fs must be a finite positive number [Hz], got {fs!r}."
        )
    return fs_value


def exponential_window(
    n: int,
    fs: RealScalarLike,
    *,
    tau: RealScalarLike | None = None,
    end_value: RealScalarLike | None = None,
    dtype=None,
) -> Float[Array, " n"]:
    """Exponential window `w(t) = exp(−t / τ)`, `t = k / fs`, for impact-test responses.

    Applied to **both** channels of an impact test (force and response), it turns the
    estimated FRF into the exact FRF of the system whose impulse response is
    `h(t)·exp(−t/τ)`: every pole `λ = −σ + jω_d` moves to `λ − 1/τ`. The damped natural
    frequencies are unchanged and the modal damping identified from the windowed FRF is
    too high; undo it with [`exponential_window_correction`][] (Fladung & Rost 1997).
    [`impact_windows`][] builds the pair.

    **Arguments:**

    - `n`: number of samples.
    - `fs`: sampling rate [Hz].
    - `tau`: time constant τ [s], > 0; or
    - `end_value`: the window value at the last sample, in (0, 1], which fixes
      `τ = −(n − 1) / (fs · ln end_value)` (analyser convention, e.g. 0.01).
    - `dtype`: floating dtype of the result.

    **Returns:**

    `(n,)` window; equals `scipy.signal.windows.exponential(n, center=0, tau=τ·fs,
    sym=False)`.

    **Raises:**

    `ValueError` unless exactly one of `tau`, `end_value` is given, or for values out of
    range.
    """
    n = _check_length(n, "exponential_window")
    fs = _check_fs(fs, "exponential_window")
    tau_value = _exponential_tau(n, fs, tau, end_value, "exponential_window")
    return jnp.exp(-_time(n, fs, dtype) / tau_value)


def _exponential_tau(n, fs, tau, end_value, fn) -> float:
    if (tau is None) == (end_value is None):
        raise ValueError(f"{fn}: give exactly one of tau [s] or end_value (in (0, 1]).")
    if tau is not None:
        tau = float(tau)
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f"{fn}: tau must be a positive time constant [s], got {tau!r}.")
        return tau
    end_value = float(end_value)
    if not (0 < end_value <= 1):
        raise ValueError(f"{fn}: end_value must lie in (0, 1], got {end_value!r}.")
    if end_value == 1 or n == 1:
        return math.inf
    return -(n - 1) / (fs * math.log(end_value))


def force_window(
    n: int,
    fs: RealScalarLike,
    *,
    t_start: ArrayLike,
    t_stop: ArrayLike,
    taper: RealScalarLike = 0.0,
    dtype=None,
) -> Float[Array, "*batch n"]:
    """Force window for impact tests: 1 on `[t_start, t_stop]`, a half-cosine taper of
    length `taper` on either side, 0 elsewhere.

    It keeps the hammer pulse and removes the force-channel noise recorded before and
    after the hit (Ewins 2000, ch. 3). `t_start` and `t_stop` may carry leading axes (one
    hit time per record), which the window then carries too.

    **Arguments:**

    - `n`: number of samples; `fs`: sampling rate [Hz].
    - `t_start`, `t_stop`: `(*batch,)` start and end of the flat part [s], `t_start <= t_stop`.
    - `taper`: duration of each cosine flank [s], >= 0 (0: rectangular).

    **Returns:**

    `(*batch, n)` window with values in [0, 1].
    """
    n = _check_length(n, "force_window")
    fs = _check_fs(fs, "force_window")
    taper = float(taper)
    if not (math.isfinite(taper) and taper >= 0):
        raise ValueError(f"force_window: taper must be a duration >= 0 s, got {taper!r}.")
    dtype = jnp.result_type(float) if dtype is None else dtype
    t0 = jnp.asarray(t_start, dtype=dtype)
    t1 = jnp.asarray(t_stop, dtype=dtype)
    if not isinstance(t0, jax.core.Tracer) and not isinstance(t1, jax.core.Tracer):
        if np.any(np.asarray(t0) > np.asarray(t1)):
            raise ValueError("force_window: t_start must not be after t_stop.")
    return _force_window(t0, t1, n, fs, taper)


@eqx.filter_jit
def _force_window(t0: Array, t1: Array, n: int, fs: float, taper: float) -> Array:
    t = _time(n, fs, t0.dtype)
    t0, t1 = t0[..., None], t1[..., None]
    # Distance outside the flat part [s]; 0 inside it.
    outside = jnp.maximum(t0 - t, 0) + jnp.maximum(t - t1, 0)
    if taper == 0:
        return jnp.where(outside > 0, 0.0, 1.0).astype(t.dtype)
    return 0.5 * (1 + jnp.cos(jnp.pi * jnp.minimum(outside / taper, 1.0)))


@eqx.filter_jit
def _pulse_extent(force: Array, threshold: float, fs: float) -> tuple[Array, Array]:
    """Times [s] of the first and last sample with |force| >= threshold·max|force|."""
    n = force.shape[-1]
    t = _time(n, fs, force.dtype)
    level = jnp.abs(force)
    above = level >= threshold * jnp.max(level, axis=-1, keepdims=True)
    first = jnp.argmax(above, axis=-1)
    last = n - 1 - jnp.argmax(above[..., ::-1], axis=-1)
    return t[first], t[last]


def impact_windows(
    force: Float[ArrayLike, "*batch time"],
    fs: RealScalarLike,
    *,
    threshold: float = 0.05,
    margin: RealScalarLike | None = None,
    taper: RealScalarLike | None = None,
    tau: RealScalarLike | None = None,
    end_value: RealScalarLike | None = None,
) -> tuple[Float[Array, "*batch time"], Float[Array, "*batch time"]]:
    """The (force, response) window pair for impact-hammer records, hit located per record.

    The pulse is where `|force| >= threshold · max|force|` (first to last such sample, so a
    double hit stays inside); the force window is flat over the pulse widened by `margin`
    on both sides, with cosine flanks of length `taper`. When `tau` or `end_value` is
    given, an exponential window multiplies **both** windows, which makes the FRF estimate
    exact for the system with poles shifted by `−1/τ` (see [`exponential_window`][]; correct
    the identified damping with [`exponential_window_correction`][]).

    Pass the pair as `window=(w_force, w_response)` to `frf_h1`/`frf_h2`/`coherence` with
    `records_axis=` the axis of the repeated hits.

    **Arguments:**

    - `force`: `(*batch, time)` hammer force records.
    - `fs`: sampling rate [Hz].
    - `threshold`: heuristic pulse detection level relative to the peak, in (0, 1).
    - `margin`: widening of the flat part on each side [s]; default: the longest detected
      pulse duration (plus one sample).
    - `taper`: cosine flank length [s]; default: `margin`.
    - `tau` / `end_value`: optional exponential window (at most one of them).

    **Returns:**

    `(w_force, w_response)`, both `(*batch, time)`.
    """
    fs = _check_fs(fs, "impact_windows")
    force = jnp.asarray(force)
    if force.ndim < 1 or force.shape[-1] < 2:
        raise ValueError(
            f"impact_windows: force must be (*batch, time) with at least 2 samples; got shape "
            f"{force.shape}."
        )
    if not 0 < threshold < 1:
        raise ValueError(f"impact_windows: threshold must lie in (0, 1), got {threshold!r}.")
    n = force.shape[-1]
    if not jnp.issubdtype(force.dtype, jnp.floating):
        force = force.astype(jnp.result_type(float))
    t_start, t_stop = _pulse_extent(force, float(threshold), fs)
    if margin is None:
        if isinstance(force, jax.core.Tracer):
            raise TypeError(
                "impact_windows: under jax.jit give margin= explicitly (the default is "
                "measured from the data)."
            )
        margin = float(np.max(np.asarray(t_stop - t_start))) + 1.0 / fs
    margin = float(margin)
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"impact_windows: margin must be a duration >= 0 s, got {margin!r}.")
    taper = margin if taper is None else taper
    w_force = force_window(
        n, fs, t_start=t_start - margin, t_stop=t_stop + margin, taper=taper, dtype=force.dtype
    )
    if tau is None and end_value is None:
        return w_force, jnp.ones_like(w_force)
    w_exp = exponential_window(n, fs, tau=tau, end_value=end_value, dtype=force.dtype)
    return w_force * w_exp, jnp.broadcast_to(w_exp, w_force.shape)


def exponential_window_correction(
    omega_n: Float[ArrayLike, "*shape"],
    zeta: Float[ArrayLike, "*shape"],
    tau: RealScalarLike,
) -> tuple[Float[Array, "*shape"], Float[Array, "*shape"]]:
    """Remove the damping an exponential window `exp(−t/τ)` added to identified modes.

    A mode identified from an exponentially windowed FRF has the pole
    `λ_w = −ζ_w ω_w + j ω_w sqrt(1 − ζ_w²)`; the true pole is `λ = λ_w + 1/τ` (same damped
    frequency, decay rate smaller by `1/τ`; Fladung & Rost 1997). Hence
    `ω_n = |λ|` and `ζ = −Re λ / |λ|`; to first order `ζ ≈ ζ_w − 1/(τ ω_n)`.

    **Arguments:**

    - `omega_n`: identified natural frequencies [rad/s] (windowed data).
    - `zeta`: identified damping ratios [-] (windowed data), `< 1`.
    - `tau`: the window's time constant [s].

    **Returns:**

    `(omega_n, zeta)` of the unwindowed system. A negative `zeta` means the window's decay
    was faster than the identified one allows: the identification is inconsistent.
    """
    omega_n = jnp.asarray(omega_n)
    zeta = jnp.asarray(zeta)
    decay = zeta * omega_n - 1.0 / tau
    omega_d = omega_n * jnp.sqrt(1 - zeta**2)
    omega_true = jnp.sqrt(decay**2 + omega_d**2)
    return omega_true, decay / omega_true
