"""Morlet CWT, ridges and damping from free decays (jaxvs.signal._cwt)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxvs.signal import cwt_damping, cwt_morlet, cwt_ridge, morlet_scales

DT = 1e-3


def _decay(t, f_n, zeta, amp=1.0, phase=0.0):
    wn = 2 * np.pi * f_n
    wd = wn * np.sqrt(1 - zeta**2)
    return amp * np.exp(-zeta * wn * t) * np.sin(wd * t + phase)


def test_amplitude_normalisation_sinusoid():
    t = DT * np.arange(4000)
    x = 2.5 * np.cos(2 * np.pi * 50 * t + 0.3)
    W = np.asarray(cwt_morlet(x, DT, np.array([50.0])))[0]
    mid = slice(1000, 3000)  # away from the cone of influence (3 s = 57 ms at 50 Hz)
    # amplitude-normalised: |W| = A, arg W = 2π f t + φ; the analytic Morlet leaves
    # e^{-ω0²/2} ≈ 1.5e-8 of the negative frequency, rounding the rest.
    np.testing.assert_allclose(np.abs(W[mid]), 2.5, rtol=1e-6)
    phase = np.angle(W[mid] * np.exp(-1j * (2 * np.pi * 50 * t[mid] + 0.3)))
    np.testing.assert_allclose(phase, 0.0, atol=1e-6)


def test_matches_direct_convolution():
    """Oracle: time-domain convolution with g(t) = sqrt(2/π)/s · e^{-t²/2s²} e^{iω0 t/s}."""
    rng = np.random.default_rng(1)
    t = DT * np.arange(1500)
    x = rng.standard_normal(t.size)
    f, omega0 = 80.0, 6.0
    s = float(morlet_scales(f, omega0))
    tau = DT * np.arange(-400, 401)
    g = np.sqrt(2 / np.pi) / s * np.exp(-(tau**2) / (2 * s**2)) * np.exp(1j * omega0 * tau / s)
    direct = np.convolve(x, g, mode="same") * DT
    W = np.asarray(cwt_morlet(x, DT, np.array([f]), omega0=omega0))[0]
    inner = slice(500, 1000)
    # the rectangle-rule convolution of a smooth Gaussian (s = 12 samples) is spectrally
    # accurate and the truncation of g at ±400 samples is e^{-555}; what differs is the
    # analytic wavelet's missing negative-frequency lobe, e^{-ω0²/2} ≈ 1.5e-8 relative.
    scale = np.max(np.abs(direct[inner]))
    np.testing.assert_allclose(W[inner], direct[inner], rtol=1e-6, atol=1e-7 * scale)


def test_ridge_follows_a_chirp():
    t = DT * np.arange(3000)
    f_inst = 30 + 40 * t / t[-1]  # linear chirp 30 -> 70 Hz
    phi = 2 * np.pi * (30 * t + 40 * t**2 / (2 * t[-1]))
    freqs = np.geomspace(20, 90, 80)
    W = cwt_morlet(np.cos(phi), DT, freqs, omega0=10.0)
    ridge, amp = cwt_ridge(W, freqs)
    mid = slice(500, 2500)
    # a linear chirp's ridge is its instantaneous frequency up to the chirp-rate bias
    # (≈ (rate·s²)-order, < 0.5 % here) and the parabolic refinement of a 2 % grid.
    np.testing.assert_allclose(np.asarray(ridge)[mid], f_inst[mid], rtol=0.01)
    np.testing.assert_allclose(np.asarray(amp)[mid], 1.0, rtol=0.01)


@pytest.mark.parametrize(
    "f_n, zeta", [(12.0, 0.02), (30.0, 0.01), (80.0, 0.03), (120.0, 0.05), (200.0, 0.002)]
)
def test_damping_single_mode_noiseless(f_n, zeta):
    t = DT * np.arange(5000)
    res = cwt_damping(_decay(t, f_n, zeta, phase=0.4), DT, (0.7 * f_n, 1.3 * f_n))
    # target: ζ within 10 %; noiseless decays give far better (< 1 %).
    assert abs(float(res.zeta) - zeta) / zeta < 0.01
    wd = f_n * np.sqrt(1 - zeta**2)
    assert abs(float(res.frequency_hz) - wd) / wd < 0.01


def test_damping_two_modes_with_noise():
    rng = np.random.default_rng(7)
    t = DT * np.arange(4000)
    x = _decay(t, 40.0, 0.02) + 0.5 * _decay(t, 110.0, 0.04, phase=1.0)
    x = x + 2e-3 * rng.standard_normal(t.size)  # noise 0.2 % of the first mode's amplitude
    for band, f_n, zeta in (((30, 55), 40.0, 0.02), ((85, 140), 110.0, 0.04)):
        res = cwt_damping(x, DT, band, omega0=12.0)
        # within 10 % of the true ζ on synthetic decays
        assert abs(float(res.zeta) - zeta) / zeta < 0.10
        assert abs(float(res.frequency_hz) - f_n) / f_n < 0.01


def test_damping_is_jittable_and_vmappable():
    t = DT * np.arange(3000)
    zetas = np.array([0.01, 0.02, 0.04])
    xs = jnp.stack([jnp.asarray(_decay(t, 50.0, z)) for z in zetas])
    fn = jax.jit(jax.vmap(lambda x: cwt_damping(x, DT, (35.0, 65.0)).zeta))
    np.testing.assert_allclose(np.asarray(fn(xs)), zetas, rtol=0.01)


def test_bad_input():
    t = DT * np.arange(2000)
    x = _decay(t, 50.0, 0.02)
    with pytest.raises(ValueError, match="omega0 >= 5"):
        cwt_morlet(x, DT, [50.0], omega0=2.0)
    with pytest.raises(ValueError, match="Nyquist"):
        cwt_morlet(x, DT, [600.0])
    with pytest.raises(ValueError, match="Nyquist"):
        cwt_damping(x, DT, (400.0, 700.0))
    with pytest.raises(TypeError, match="x must be real"):
        cwt_morlet(x + 0j, DT, [50.0])
    with pytest.raises(ValueError, match="too short"):
        cwt_damping(x[:120], DT, (5.0, 15.0), omega0=20.0)
