"""Tests of the excitation signals against closed forms and independent oracles."""

import math

import numpy as np
import pytest
import scipy.signal

from jaxvs.data import (
    PRBS_ORDERS,
    Motion,
    bang_bang,
    prbs,
    prbs_taps,
    swept_sine,
    trapezoid,
    white_noise,
)

# --- PRBS --------------------------------------------------------------------------------------


def _poly_mulmod(a: int, b: int, modulus: int, degree: int) -> int:
    """Product of two GF(2) polynomials (bit i = coefficient of x^i) modulo `modulus`."""
    result = 0
    while b:
        if b & 1:
            result ^= a
        b >>= 1
        a <<= 1
        if a >> degree & 1:
            a ^= modulus
    return result


def _x_power(exponent: int, modulus: int, degree: int) -> int:
    result, base = 1, 0b10
    while exponent:
        if exponent & 1:
            result = _poly_mulmod(result, base, modulus, degree)
        base = _poly_mulmod(base, base, modulus, degree)
        exponent >>= 1
    return result


def _prime_factors(n: int) -> set[int]:
    factors, p = set(), 2
    while p * p <= n:
        while n % p == 0:
            factors.add(p)
            n //= p
        p += 1
    if n > 1:
        factors.add(n)
    return factors


@pytest.mark.parametrize("order", PRBS_ORDERS)
def test_prbs_taps_are_primitive_polynomials(order):
    """Algebraic oracle: x has multiplicative order 2^n − 1 modulo the characteristic
    polynomial c(x) = x^n + Σ_t x^(n−t), so c is primitive and the LFSR is maximal."""
    modulus = 1 << order
    for tap in prbs_taps(order):
        modulus ^= 1 << (order - tap)
    period = 2**order - 1
    assert _x_power(period, modulus, order) == 1
    for p in _prime_factors(period):
        assert _x_power(period // p, modulus, order) != 1


@pytest.mark.parametrize("order", range(2, 21))
def test_prbs_is_an_m_sequence(order):
    sequence = prbs(order)
    period = 2**order - 1
    assert sequence.shape == (period,) and sequence.dtype == np.float64
    assert set(np.unique(sequence)) <= {-1.0, 1.0}
    # Balance: 2^(n−1) ones and one fewer minus ones.
    assert np.sum(sequence > 0) == 2 ** (order - 1)
    assert np.sum(sequence > 0) - np.sum(sequence < 0) == 1
    # Two-valued circular autocorrelation: N at lag 0, −1 elsewhere (so no shorter period).
    spectrum = np.fft.rfft(sequence)
    autocorrelation = np.fft.irfft(np.abs(spectrum) ** 2, period)
    # FFT rounding grows like log2(N)·eps·N; 1e-6 is far below the gap of 1 between values.
    np.testing.assert_allclose(autocorrelation[0], period, atol=1e-6)
    np.testing.assert_allclose(autocorrelation[1:], -1.0, atol=1e-6)
    # The bits obey the linear recurrence of the documented taps.
    bits = (sequence > 0).astype(np.uint8)
    expected = np.zeros(period - order, dtype=np.uint8)
    for tap in prbs_taps(order):
        expected ^= bits[order - tap : period - tap]
    np.testing.assert_array_equal(bits[order:], expected)


def test_prbs_matches_scipy_max_len_seq_properties():
    # scipy's generator is an independent m-sequence of the same order: same length,
    # same balance and same (flat) power spectrum away from DC.
    ours = prbs(9)
    theirs = 2.0 * scipy.signal.max_len_seq(9)[0] - 1.0
    assert ours.shape == theirs.shape and ours.sum() == theirs.sum() == 1.0
    np.testing.assert_allclose(
        np.abs(np.fft.fft(ours))[1:], np.abs(np.fft.fft(theirs))[1:], rtol=1e-9
    )


def test_prbs_state_shifts_the_sequence():
    reference = prbs(7)
    for state in (1, 37, 126):
        shifted = prbs(7, state=state)
        shifts = [k for k in range(127) if np.array_equal(np.roll(reference, -k), shifted)]
        assert len(shifts) == 1


def test_prbs_clock_divider_periods_and_amplitude():
    base = prbs(5)
    signal = prbs(5, clock_divider=4, n_periods=3, amplitude=2.5)
    assert signal.shape == (31 * 4 * 3,)
    np.testing.assert_array_equal(signal[: 31 * 4], 2.5 * np.repeat(base, 4))
    np.testing.assert_array_equal(signal, np.tile(signal[: 31 * 4], 3))
    # Holding each bit for c samples puts exact spectral zeros at multiples of fs/c.
    spectrum = np.abs(np.fft.fft(signal[: 31 * 4]))
    np.testing.assert_allclose(spectrum[[31, 62, 93]], 0.0, atol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"order": 1}, "order must be an integer in 2..24"),
        ({"order": 25}, "order must be an integer in 2..24"),
        ({"order": 4.0}, "order must be an integer"),
        ({"order": 4, "state": 0}, "nonzero integer"),
        ({"order": 4, "state": 16}, "below 2\\^order = 16"),
        ({"order": 4, "clock_divider": 0}, "clock_divider must be an integer >= 1"),
        ({"order": 4, "n_periods": 0}, "n_periods must be an integer >= 1"),
        ({"order": 4, "amplitude": math.nan}, "amplitude must be finite"),
    ],
)
def test_prbs_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        prbs(**kwargs)


# --- swept sine -----------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["linear", "logarithmic"])
def test_swept_sine_matches_scipy_chirp(method):
    n, dt = 5001, 1e-3
    t = dt * np.arange(n)
    ours = swept_sine((n, dt), 1.0, 200.0, method=method, amplitude=3.0, phase=0.3)
    theirs = 3.0 * scipy.signal.chirp(
        t, f0=1.0, t1=t[-1], f1=200.0, method=method, phi=np.degrees(0.3)
    )
    # Same closed form, different rounding of phases up to 2π·500 rad: 1e-9 absolute.
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        swept_sine(t, 1.0, 200.0, method=method, phase=0.3), ours / 3, rtol=0, atol=1e-15
    )


def test_swept_sine_starts_at_first_sample_and_reaches_f1():
    t = 2.0 + 1e-3 * np.arange(2001)
    signal = swept_sine(t, 5.0, 50.0)
    shifted = swept_sine(t - 2.0, 5.0, 50.0)
    np.testing.assert_array_equal(signal, shifted)  # the sweep starts at t[0]
    # Phase 2π(5τ + 45τ²/4) runs over 110 half-turns in 2 s: 110 zero crossings of cos.
    crossings = np.nonzero(np.diff(np.sign(signal)))[0]
    assert len(crossings) == 110
    # Instantaneous frequency from linearly interpolated crossing times: half a period apart.
    k = crossings
    times = t[k] - signal[k] * (t[k + 1] - t[k]) / (signal[k + 1] - signal[k])
    frequency = 0.5 / np.diff(times)
    expected = 5.0 + 45.0 * (0.5 * (times[1:] + times[:-1]) - 2.0) / 2.0
    # Linear interpolation of a sine sampled ≥ 20 times per period: well under 1 %.
    np.testing.assert_allclose(frequency, expected, rtol=0.01)


@pytest.mark.parametrize(
    ("args", "kwargs", "match"),
    [
        (((1000, 1e-3), 1.0, 600.0), {}, "above the Nyquist frequency 500 Hz"),
        (((1000, 1e-3), 0.0, 10.0), {"method": "logarithmic"}, "needs f0 > 0"),
        (((1000, 1e-3), 1.0, 10.0), {"method": "quadratic"}, "'linear' or 'logarithmic'"),
        (((1000, 1e-3), -1.0, 10.0), {}, "finite frequencies >= 0"),
        ((np.array([0.0, 0.2, 0.1]), 1.0, 2.0), {}, "strictly increasing"),
        (((1, 1e-3), 1.0, 2.0), {}, "n must be an integer >= 2"),
        (((10, 0.0), 1.0, 2.0), {}, "dt must be a positive"),
        (((10, 1e-3, 3), 1.0, 2.0), {}, "tuple \\(n, dt\\)"),
    ],
)
def test_swept_sine_errors(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        swept_sine(*args, **kwargs)


# --- white noise ----------------------------------------------------------------------------------


def test_white_noise_is_flat_in_band_and_attenuated_outside():
    n, dt, band, rms = 2**16, 1e-3, 100.0, 2.0
    noise = white_noise(n, dt, bandwidth=band, rms=rms, seed=3)
    assert noise.shape == (n,)
    assert math.isclose(np.sqrt(np.mean(noise**2)), rms, rel_tol=1e-12)
    assert abs(np.mean(noise)) < 1e-12
    frequency, psd = scipy.signal.welch(noise, fs=1 / dt, nperseg=1024)
    inside = (frequency > 5.0) & (frequency < 0.95 * band)
    outside = frequency > 1.1 * band
    level = rms**2 / band  # one-sided density of power rms² spread over [0, band]
    # ~127 averaged Hann segments: each bin scatters by ≈ 1/sqrt(127) ≈ 9 %; 35 % is > 3σ.
    np.testing.assert_allclose(psd[inside], level, rtol=0.35)
    assert math.isclose(np.mean(psd[inside]), level, rel_tol=0.05)
    # Ideal band limit; what remains outside is Hann-window leakage, > 60 dB down.
    assert np.max(psd[outside]) < 1e-6 * level


def test_white_noise_band_pass_seed_and_default_band():
    noise = white_noise(4096, 1e-3, bandwidth=(50.0, 150.0), rms=1.0, seed=1)
    spectrum = np.abs(np.fft.rfft(noise))
    frequency = np.fft.rfftfreq(4096, 1e-3)
    out_of_band = (frequency < 50.0) | (frequency > 150.0)
    assert np.max(spectrum[out_of_band]) < 1e-9 * np.max(spectrum)
    np.testing.assert_array_equal(noise, white_noise(4096, 1e-3, bandwidth=(50.0, 150.0), seed=1))
    assert not np.array_equal(noise, white_noise(4096, 1e-3, bandwidth=(50.0, 150.0), seed=2))
    full = white_noise(4096, 1e-3, seed=np.random.default_rng(0))
    assert math.isclose(np.std(full), 1.0, rel_tol=1e-12)


@pytest.mark.parametrize(
    ("args", "kwargs", "match"),
    [
        ((1000, 1e-3), {"bandwidth": 600.0}, "f_high <= 1/\\(2·dt\\) = 500 Hz"),
        ((1000, 1e-3), {"bandwidth": (100.0, 50.0)}, "f_low < f_high"),
        ((1000, 1e-3), {"bandwidth": (100.2, 100.7)}, "holds no frequency bin; the resolution"),
        ((1, 1e-3), {}, "n must be an integer >= 2"),
        ((100, -1e-3), {}, "dt must be a positive"),
        ((100, 1e-3), {"rms": -1.0}, "rms must be finite and >= 0"),
    ],
)
def test_white_noise_errors(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        white_noise(*args, **kwargs)


# --- motion profiles ---------------------------------------------------------------------------


def _check_kinematics(motion: Motion, dt: float) -> None:
    """Velocity is the derivative of position and acceleration that of velocity."""
    # Trapezoidal-rule integration is exact for piecewise-linear velocity except in the
    # samples around switches: O(a·dt²) per switch.
    integrated = np.concatenate(
        [[0.0], np.cumsum(0.5 * (motion.velocity[1:] + motion.velocity[:-1]) * dt)]
    )
    scale = np.max(np.abs(motion.acceleration)) * dt**2
    np.testing.assert_allclose(integrated, motion.position, atol=10 * scale)
    mean_acceleration = np.diff(motion.velocity) / dt
    exact = np.isclose(mean_acceleration, motion.acceleration[:-1], atol=1e-9)
    assert np.mean(exact) > 0.95  # all but the samples straddling a switch


def test_trapezoid_closed_forms():
    distance, v_max, a_max, dt = 0.5, 0.2, 1.0, 1e-3
    motion = trapezoid(distance, v_max, a_max, dt)
    total = distance / v_max + v_max / a_max  # 2.7 s
    assert isinstance(motion, Motion)
    assert total <= motion.t[-1] < total + dt
    np.testing.assert_allclose(motion.t, dt * np.arange(len(motion.t)), rtol=1e-15)
    assert motion.position[-1] == distance and motion.velocity[-1] == 0.0
    assert math.isclose(np.max(motion.velocity), v_max, rel_tol=1e-12)
    assert set(np.unique(motion.acceleration)) == {-a_max, 0.0, a_max}
    # Cruise from v/a = 0.2 s to d/v = 2.5 s, at v_max.
    cruise = (motion.t >= 0.2 + dt) & (motion.t < 2.5 - dt)
    np.testing.assert_allclose(motion.velocity[cruise], v_max, rtol=1e-12)
    # Position during acceleration: a·t²/2.
    early = motion.t < 0.2
    np.testing.assert_allclose(motion.position[early], 0.5 * a_max * motion.t[early] ** 2)
    _check_kinematics(motion, dt)


def test_trapezoid_becomes_triangular_for_short_moves():
    distance, v_max, a_max, dt = 0.01, 0.2, 1.0, 1e-4
    motion = trapezoid(-distance, v_max, a_max, dt)
    total = 2 * math.sqrt(distance / a_max)  # 0.2 s; v_max²/a_max = 0.04 > 0.01
    assert total <= motion.t[-1] < total + dt
    assert motion.position[-1] == -distance
    peak = math.sqrt(distance * a_max)  # 0.1 m/s, reached at total/2
    assert math.isclose(np.min(motion.velocity), -peak, rel_tol=1e-9)
    assert not np.any(np.isclose(motion.acceleration, 0.0)[: len(motion.t) - 1])
    _check_kinematics(motion, dt)
    assert trapezoid(0.0, v_max, a_max, dt).t.shape == (1,)


def test_trapezoid_dwell_holds_the_final_position():
    motion = trapezoid(0.1, 0.1, 1.0, 1e-3, dwell=0.5)
    total = 0.1 / 0.1 + 0.1 / 1.0
    assert total + 0.5 <= motion.t[-1] < total + 0.5 + 1e-3
    rest = motion.t >= total
    assert np.all(motion.position[rest] == 0.1) and np.all(motion.velocity[rest] == 0.0)


def test_bang_bang_back_and_forth():
    distance, a_max, dt = 0.2, 2.0, 1e-3
    motion = bang_bang(distance, a_max, dt, n_cycles=2, dwell=0.1)
    move = 2 * math.sqrt(distance / a_max)  # triangular move time
    period = move + 0.1
    assert 4 * period <= motion.t[-1] < 4 * period + dt
    assert math.isclose(motion.position[-1], 0.0, abs_tol=1e-15)
    assert np.min(motion.position) >= -1e-15 and np.max(motion.position) <= distance + 1e-15
    # End of each move: at +d after moves 1 and 3, back at 0 after moves 2 and 4.
    for i, target in enumerate([distance, 0.0, distance, 0.0]):
        at_rest = (motion.t >= i * period + move + dt) & (motion.t < (i + 1) * period - dt)
        np.testing.assert_allclose(motion.position[at_rest], target, atol=1e-14)
    peak = math.sqrt(distance * a_max)
    # The peak falls between samples: the sampled maximum is within a_max·dt below it.
    assert peak - a_max * dt <= np.max(motion.velocity) <= peak
    assert -peak <= np.min(motion.velocity) <= -peak + a_max * dt
    assert set(np.unique(motion.acceleration)) == {-a_max, 0.0, a_max}
    _check_kinematics(motion, dt)


def test_bang_bang_with_velocity_limit_is_a_sequence_of_trapezoids():
    motion = bang_bang(-0.3, 1.0, 1e-3, v_max=0.25)
    single = trapezoid(-0.3, 0.25, 1.0, 1e-3)
    k = len(single.t)
    np.testing.assert_allclose(motion.position[:k], single.position, atol=1e-15)
    assert math.isclose(np.min(motion.velocity), -0.25, rel_tol=1e-12)
    assert math.isclose(motion.position[-1], 0.0, abs_tol=1e-15)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: trapezoid(1.0, 1.0, 0.0, 1e-3), "a_max must be a positive"),
        (lambda: trapezoid(1.0, -1.0, 1.0, 1e-3), "v_max must be a positive"),
        (lambda: trapezoid(1.0, None, 1.0, 1e-3), "needs v_max"),
        (lambda: trapezoid(1.0, 1.0, 1.0, 0.0), "dt must be a positive"),
        (lambda: trapezoid(1.0, 1.0, 1.0, 1e-3, dwell=-1.0), "dwell must be a time >= 0"),
        (lambda: trapezoid(math.inf, 1.0, 1.0, 1e-3), "distance must be finite"),
        (lambda: bang_bang(0.0, 1.0, 1e-3), "finite and nonzero"),
        (lambda: bang_bang(1.0, 1.0, 1e-3, n_cycles=0), "n_cycles must be an integer >= 1"),
    ],
)
def test_motion_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()
