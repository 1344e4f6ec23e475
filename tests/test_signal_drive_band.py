"""`jaxvs.signal.DriveBand`, the one preprocessing of a drive record, against independent
oracles: the JAX zero-phase filter, closed-form derivatives and the half-sample hold."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxvs.signal import DriveBand, filtfilt_lowpass  # noqa: E402


def test_defaults_follow_the_sampling_rate_and_bad_cutoffs_are_refused():
    band = DriveBand.of(1000.0)
    assert band.cutoff_hz == 100.0 and band.decimation == 2 and band.hold
    assert DriveBand.of(200.0).cutoff_hz == 25.0  # fs/8 below 100 Hz
    with pytest.raises(ValueError, match=r"cutoff_hz=600.0 must lie in \(0, fs/2 = 500\) Hz"):
        DriveBand.of(1000.0, 600.0)


def test_lowpass_equals_the_jax_zero_phase_filter_with_the_same_padding():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.standard_normal(3000))
    band = DriveBand.of(1000.0, 40.0)
    ref = np.asarray(filtfilt_lowpass(x, 1000.0, 40.0, order=4, padlen=75))
    np.testing.assert_allclose(band.lowpass(x), ref, rtol=0, atol=1e-9 * np.ptp(x))


def test_derivatives_of_a_slow_sine_and_the_half_sample_hold():
    fs, f0 = 1000.0, 2.0
    t = np.arange(4000) / fs
    q = 0.1 * np.sin(2 * np.pi * f0 * t)
    band = DriveBand.of(fs, 50.0)
    sig = band.apply(q, np.arange(t.size, dtype=float))
    w = sig.window
    w0 = 2 * np.pi * f0
    # a 2 Hz sine passes a 50 Hz zero-phase filter unchanged (|H|² = 1 − 1e-22)
    np.testing.assert_allclose(sig.q[w], q[w], atol=1e-9)
    # central differences: truncation error h²ω²/6 of the amplitude per difference
    h2 = (w0 / fs) ** 2
    v_amp, a_amp = 0.1 * w0, 0.1 * w0**2
    np.testing.assert_allclose(sig.v[w], v_amp * np.cos(w0 * t[w]), atol=1.5 * h2 / 6 * v_amp)
    np.testing.assert_allclose(sig.a[w], -a_amp * np.sin(w0 * t[w]), atol=1.5 * h2 / 3 * a_amp)
    # a ramp force u_k = k acts at t_k as k − 1/2 (the held sample's mean time)
    # (the first held sample has no predecessor: its kink of 0.5 decays to < 1e-3 by the
    # window's edge)
    np.testing.assert_allclose(sig.u[w], np.arange(t.size)[w] - 0.5, atol=1e-3)
    assert w.start == band.edge == 60 and w.step == band.decimation == 5
    # the white-noise bandwidth of the zero-phase filter: ∫|H|⁴ ≈ cutoff for order 4
    assert band.enbw == pytest.approx(50.0 * 0.92, rel=0.05)
