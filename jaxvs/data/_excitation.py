"""Excitation signals for identification experiments on machine-tool axes.

Excitation design happens once, on the host, before an experiment or a simulation; none of
these functions is differentiated. They are therefore written in NumPy and return NumPy
float64 arrays (pass them through `jnp.asarray` to feed a jitted simulation). Times are in
seconds, frequencies in hertz; amplitudes carry the unit of the quantity they drive
(force [N], voltage [V], position [m] …).
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np
from jaxtyping import Float

# Feedback taps of maximum-length Fibonacci LFSRs, one primitive trinomial/pentanomial per
# order (Xilinx XAPP052, table 3): the bit sequence obeys s[k] = XOR_t s[k - t].
_PRBS_TAPS: dict[int, tuple[int, ...]] = {
    2: (2, 1),
    3: (3, 2),
    4: (4, 3),
    5: (5, 3),
    6: (6, 5),
    7: (7, 6),
    8: (8, 6, 5, 4),
    9: (9, 5),
    10: (10, 7),
    11: (11, 9),
    12: (12, 6, 4, 1),
    13: (13, 4, 3, 1),
    14: (14, 5, 3, 1),
    15: (15, 14),
    16: (16, 15, 13, 4),
    17: (17, 14),
    18: (18, 11),
    19: (19, 6, 2, 1),
    20: (20, 17),
    21: (21, 19),
    22: (22, 21),
    23: (23, 18),
    24: (24, 23, 22, 17),
}
PRBS_ORDERS = tuple(_PRBS_TAPS)


def prbs_taps(order: int) -> tuple[int, ...]:
    """The feedback taps `prbs` uses for `order`: its bits obey `s[k] = XOR_t s[k − t]`
    (characteristic polynomial `x^order + Σ_t x^(order − t)` over GF(2), primitive).

    **Raises:**

    `ValueError` for an order outside 2..24.
    """
    if not isinstance(order, int) or order not in _PRBS_TAPS:
        raise ValueError(
            f"PRBS order must be an integer in {PRBS_ORDERS[0]}..{PRBS_ORDERS[-1]}, got {order!r}."
        )
    taps = _PRBS_TAPS[order]
    # A primitive polynomial's reciprocal is primitive too; use the form whose smallest lag
    # is larger, as that many bits are computed per vectorised step in `_m_sequence_bits`.
    reciprocal = tuple(sorted({order} | {order - t for t in taps if t != order}, reverse=True))
    return reciprocal if min(reciprocal) > min(taps) else taps


def _m_sequence_bits(order: int, state: int) -> np.ndarray:
    """One period (2^order − 1 bits) of the m-sequence whose first `order` bits are those
    of `state`, least significant first."""
    taps = prbs_taps(order)
    period = 2**order - 1
    bits = np.zeros(period, dtype=np.uint8)
    bits[:order] = [(state >> i) & 1 for i in range(order)]
    filled = order
    smallest = min(taps)
    while filled < period:
        # Over GF(2), c(E)^(2^j) = c(E^(2^j)): the sequence also obeys
        # s[k] = XOR_t s[k - 2^j·t], whose lags grow with j, so blocks grow geometrically.
        scale = 1 << ((filled // order).bit_length() - 1)
        stop = min(filled + scale * smallest, period)
        block = np.zeros(stop - filled, dtype=np.uint8)
        for tap in taps:
            lag = scale * tap
            block ^= bits[filled - lag : stop - lag]
        bits[filled:stop] = block
        filled = stop
    return bits


def prbs(
    order: int,
    *,
    clock_divider: int = 1,
    n_periods: int = 1,
    amplitude: float = 1.0,
    state: int | None = None,
) -> Float[np.ndarray, " time"]:
    """Maximum-length pseudo-random binary sequence (m-sequence) of values ±`amplitude`.

    One period has `2^order − 1` bits, `2^(order−1)` of them +`amplitude` and one fewer
    −`amplitude`; its circular autocorrelation is `N·amplitude²` at lag 0 and
    `−amplitude²` at every other lag (Godfrey 1993, *Perturbation Signals for System
    Identification*, ch. 1). Each bit is held for `clock_divider` samples, which moves the
    spectrum's first zero from `fs` to `fs/clock_divider` Hz.

    **Arguments:**

    - `order`: register length, 2..24.
    - `clock_divider`: samples per bit (≥ 1).
    - `n_periods`: number of periods (≥ 1); use 2 or more to discard a transient and
        average periodic responses.
    - `amplitude`: level of the signal, in the unit of the driven input.
    - `state`: the first `order` bits of the sequence as an integer in `1..2^order − 1`
        (least significant bit first); a different state circularly shifts the
        sequence. Default: all ones.

    **Returns:**

    float64 array of `(2^order − 1)·clock_divider·n_periods` samples.
    """
    prbs_taps(order)  # validates the order
    for name, value in (("clock_divider", clock_divider), ("n_periods", n_periods)):
        if not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}.")
    if not math.isfinite(amplitude):
        raise ValueError(f"amplitude must be finite, got {amplitude!r}.")
    if state is None:
        state = 2**order - 1
    if not isinstance(state, int) or not 1 <= state < 2**order:
        raise ValueError(
            f"state must be a nonzero integer below 2^order = {2**order} (an all-zero register "
            f"never leaves zero), got {state!r}."
        )
    bits = _m_sequence_bits(order, state)
    levels = np.where(bits == 1, float(amplitude), -float(amplitude))
    return np.tile(np.repeat(levels, clock_divider), n_periods)


def _time_grid(t: object) -> np.ndarray:
    if isinstance(t, tuple):
        if len(t) != 2:
            raise ValueError("Give the time as an array [s] or as a tuple (n, dt).")
        n, dt = t
        if not isinstance(n, int) or n < 2:
            raise ValueError(f"n must be an integer >= 2, got {n!r}.")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive sampling period [s], got {dt!r}.")
        return dt * np.arange(n, dtype=np.float64)
    time = np.asarray(t, dtype=np.float64)
    if time.ndim != 1 or time.shape[0] < 2:
        raise ValueError(f"t must be a 1-D array of at least 2 times [s], got shape {time.shape}.")
    if not np.all(np.isfinite(time)):
        raise ValueError("t holds NaN or inf.")
    if np.any(np.diff(time) <= 0):
        raise ValueError("t must be strictly increasing.")
    return time


def swept_sine(
    t: Float[np.ndarray, " time"] | tuple[int, float],
    f0: float,
    f1: float,
    *,
    method: Literal["linear", "logarithmic"] = "linear",
    amplitude: float = 1.0,
    phase: float = 0.0,
) -> Float[np.ndarray, " time"]:
    """Swept sine (chirp) `amplitude·cos(φ(t) + phase)` whose instantaneous frequency goes
    from `f0` at the first sample to `f1` at the last.

    With `τ = t − t[0]` and `T = t[-1] − t[0]`:

    - linear: `f(τ) = f0 + (f1 − f0)·τ/T`, `φ = 2π(f0·τ + (f1 − f0)·τ²/(2T))`;
    - logarithmic: `f(τ) = f0·(f1/f0)^(τ/T)`, `φ = 2π·f0·T·((f1/f0)^(τ/T) − 1)/ln(f1/f0)`.

    These are `scipy.signal.chirp` with `t1 = T` and `phi` in degrees.

    **Arguments:**

    - `t`: sample times [s] (strictly increasing), or `(n, dt)` for `t = k·dt`.
    - `f0`, `f1`: start and end frequency [Hz]; both ≥ 0 (> 0 for logarithmic) and below
        the Nyquist frequency of the sampling.
    - `method`: `"linear"` or `"logarithmic"` (exponential) sweep.
    - `amplitude`: amplitude, in the unit of the driven input.
    - `phase`: phase at the first sample [rad].

    **Returns:**

    float64 array, one value per time.
    """
    time = _time_grid(t)
    tau = time - time[0]
    duration = float(tau[-1])
    if not (math.isfinite(f0) and math.isfinite(f1) and f0 >= 0 and f1 >= 0):
        raise ValueError(f"f0 and f1 must be finite frequencies >= 0 Hz, got {f0!r}, {f1!r}.")
    nyquist = 0.5 / float(np.max(np.diff(time)))
    if max(f0, f1) > nyquist:
        raise ValueError(
            f"The sweep reaches {max(f0, f1):g} Hz, above the Nyquist frequency {nyquist:g} Hz "
            "of the sampling; sample faster or lower f0/f1 (it would alias)."
        )
    if method == "linear":
        phi = 2 * np.pi * (f0 * tau + (f1 - f0) * tau**2 / (2 * duration))
    elif method == "logarithmic":
        if f0 <= 0 or f1 <= 0:
            raise ValueError("A logarithmic sweep needs f0 > 0 and f1 > 0.")
        if f0 == f1:
            phi = 2 * np.pi * f0 * tau
        else:
            ratio = f1 / f0
            phi = 2 * np.pi * f0 * duration * (ratio ** (tau / duration) - 1) / math.log(ratio)
    else:
        raise ValueError(f"method must be 'linear' or 'logarithmic', got {method!r}.")
    return amplitude * np.cos(phi + phase)


def white_noise(
    n: int,
    dt: float,
    *,
    bandwidth: float | tuple[float, float] | None = None,
    rms: float = 1.0,
    seed: int | np.random.Generator | None = 0,
) -> Float[np.ndarray, " time"]:
    """Band-limited zero-mean Gaussian noise with a flat spectrum in the band.

    Gaussian white noise is filtered by an ideal (brick-wall) filter in the discrete
    Fourier domain: bins outside the band and the DC bin are zeroed. The result is
    periodic with period `n·dt`, has exactly zero mean and is scaled to exactly `rms`.

    **Arguments:**

    - `n`: number of samples.
    - `dt`: sampling period [s].
    - `bandwidth`: upper band edge [Hz], or `(f_low, f_high)` [Hz] for a band-pass; default
        the Nyquist frequency `1/(2·dt)`.
    - `rms`: root-mean-square value, in the unit of the driven input.
    - `seed`: integer seed or a `numpy.random.Generator`.

    **Returns:**

    float64 array of `n` samples.
    """
    if not isinstance(n, int) or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}.")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive sampling period [s], got {dt!r}.")
    if not (math.isfinite(rms) and rms >= 0):
        raise ValueError(f"rms must be finite and >= 0, got {rms!r}.")
    nyquist = 0.5 / dt
    if bandwidth is None:
        low, high = 0.0, nyquist
    elif isinstance(bandwidth, tuple | list):
        low, high = (float(b) for b in bandwidth)
    else:
        low, high = 0.0, float(bandwidth)
    if not (0 <= low < high <= nyquist * (1 + 1e-12)):
        raise ValueError(
            f"The band must satisfy 0 <= f_low < f_high <= 1/(2·dt) = {nyquist:g} Hz, got "
            f"({low:g}, {high:g}) Hz."
        )
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    frequency = np.fft.rfftfreq(n, dt)
    keep = (frequency >= low) & (frequency <= high) & (frequency > 0)
    if not keep.any():
        raise ValueError(
            f"The band ({low:g}, {high:g}) Hz holds no frequency bin; the resolution is "
            f"1/(n·dt) = {1 / (n * dt):g} Hz. Use a wider band or more samples."
        )
    signal = np.fft.irfft(np.where(keep, spectrum, 0.0), n)
    return signal * (rms / np.sqrt(np.mean(signal**2)))


class Motion(NamedTuple):
    """A sampled motion profile: time [s], position [m or rad], velocity [m/s or rad/s],
    acceleration [m/s² or rad/s²]."""

    t: Float[np.ndarray, " time"]
    position: Float[np.ndarray, " time"]
    velocity: Float[np.ndarray, " time"]
    acceleration: Float[np.ndarray, " time"]


def _move_duration(distance: float, v_max: float, a_max: float) -> tuple[float, float, float]:
    """`(t_acc, t_dec_start, T)` of a trapezoidal move of |distance| (triangular when the
    distance is too short to reach `v_max`, i.e. |distance| < v_max²/a_max)."""
    d = abs(distance)
    if d == 0:
        return 0.0, 0.0, 0.0
    if d >= v_max**2 / a_max:
        t_acc = v_max / a_max
        return t_acc, d / v_max, d / v_max + t_acc
    t_acc = math.sqrt(d / a_max)
    return t_acc, t_acc, 2 * t_acc


def _move(
    tau: np.ndarray, distance: float, v_max: float, a_max: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of one move starting at rest at `tau = 0`."""
    t1, t2, total = _move_duration(distance, v_max, a_max)
    d = abs(distance)
    sign = math.copysign(1.0, distance)
    v_peak = a_max * t1
    accelerating = (tau >= 0) & (tau < t1)
    cruising = (tau >= t1) & (tau < t2)
    braking = (tau >= t2) & (tau < total)
    done = tau >= total
    position = np.select(
        [accelerating, cruising, braking, done],
        [
            0.5 * a_max * tau**2,
            0.5 * a_max * t1**2 + v_peak * (tau - t1),
            d - 0.5 * a_max * (total - tau) ** 2,
            np.full_like(tau, d),
        ],
        0.0,
    )
    velocity = np.select(
        [accelerating, cruising, braking],
        [a_max * tau, np.full_like(tau, v_peak), a_max * (total - tau)],
        0.0,
    )
    acceleration = np.select([accelerating, braking], [a_max, -a_max], 0.0)
    return sign * position, sign * velocity, sign * acceleration


def _check_motion_args(dt: float, dwell: float, a_max: float, v_max: float | None) -> None:
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive sampling period [s], got {dt!r}.")
    if not (math.isfinite(a_max) and a_max > 0):
        raise ValueError(f"a_max must be a positive acceleration, got {a_max!r}.")
    if v_max is not None and not (v_max > 0):
        raise ValueError(f"v_max must be a positive velocity (or inf), got {v_max!r}.")
    if not (math.isfinite(dwell) and dwell >= 0):
        raise ValueError(f"dwell must be a time >= 0 [s], got {dwell!r}.")


def _samples(duration: float, dt: float) -> np.ndarray:
    # Enough samples for the last one to reach `duration` (up to rounding of 1e-9·dt).
    n = math.ceil(duration / dt - 1e-9) + 1
    return dt * np.arange(n, dtype=np.float64)


def trapezoid(
    distance: float, v_max: float, a_max: float, dt: float, *, dwell: float = 0.0
) -> Motion:
    """Point-to-point move with a trapezoidal velocity profile, sampled every `dt`.

    The axis accelerates at `a_max` to `v_max`, cruises, and brakes at `a_max` to stop
    after `distance`; when `|distance| < v_max²/a_max` it never reaches `v_max` and the
    profile is triangular with peak velocity `sqrt(|distance|·a_max)`. Move time:
    `T = |distance|/v_max + v_max/a_max` (trapezoid) or `2·sqrt(|distance|/a_max)`
    (triangle). The samples are the exact profile at `t = k·dt`, so position and velocity
    are exact (no integration error). The acceleration takes its value from the right
    at a switching instant.

    **Arguments:**

    - `distance`: signed move [m or rad].
    - `v_max`: velocity limit (> 0) [m/s]; `math.inf` gives a bang-bang (triangular) move.
    - `a_max`: acceleration limit (> 0) [m/s²].
    - `dt`: sampling period [s].
    - `dwell`: time at rest after the move [s].

    **Returns:**

    A `Motion` `(t, position, velocity, acceleration)` that ends at or just after
    `T + dwell`, at rest at `distance`.
    """
    if v_max is None:
        raise ValueError("trapezoid() needs v_max > 0 (math.inf for a triangular move).")
    _check_motion_args(dt, dwell, a_max, v_max)
    if not math.isfinite(distance):
        raise ValueError(f"distance must be finite, got {distance!r}.")
    total = _move_duration(distance, v_max, a_max)[2]
    time = _samples(total + dwell, dt)
    return Motion(time, *_move(time, distance, v_max, a_max))


def bang_bang(
    distance: float,
    a_max: float,
    dt: float,
    *,
    v_max: float | None = None,
    n_cycles: int = 1,
    dwell: float = 0.0,
) -> Motion:
    """Back-and-forth moves at maximum acceleration: `+distance`, then `−distance`,
    repeated `n_cycles` times, each move followed by `dwell` at rest.

    Without `v_max` each move is pure bang-bang (accelerate at `a_max` for half the move,
    brake for the other half: a triangular velocity); with `v_max` the velocity is
    clipped to a trapezoid, as in the EMPS excitation (Janot et al. 2019, §2.1). Moves do
    not overlap, so the profile is the exact superposition of shifted `trapezoid` moves.

    **Arguments:**

    - `distance`: stroke of each move [m or rad], signed (the first move goes this way).
    - `a_max`: acceleration limit (> 0) [m/s²].
    - `dt`: sampling period [s].
    - `v_max`: optional velocity limit [m/s].
    - `n_cycles`: number of there-and-back cycles (≥ 1).
    - `dwell`: time at rest after each move [s].

    **Returns:**

    A `Motion` `(t, position, velocity, acceleration)` of `2·n_cycles` moves, ending back
    at position 0.
    """
    _check_motion_args(dt, dwell, a_max, v_max)
    if not (math.isfinite(distance) and distance != 0):
        raise ValueError(f"distance must be finite and nonzero, got {distance!r}.")
    if not isinstance(n_cycles, int) or n_cycles < 1:
        raise ValueError(f"n_cycles must be an integer >= 1, got {n_cycles!r}.")
    limit = math.inf if v_max is None else v_max
    period = _move_duration(distance, limit, a_max)[2] + dwell
    time = _samples(2 * n_cycles * period, dt)
    position = np.zeros_like(time)
    velocity = np.zeros_like(time)
    acceleration = np.zeros_like(time)
    for i in range(2 * n_cycles):
        signed = distance if i % 2 == 0 else -distance
        q, v, a = _move(time - i * period, signed, limit, a_max)
        position += q
        velocity += v
        acceleration += a
    return Motion(time, position, velocity, acceleration)
