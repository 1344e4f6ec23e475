"""Welch spectra, FRF estimators, coherence, windows, TMF estimation and `FRFData`.

Oracles: scipy.signal (welch / csd / coherence / windows / freqz / lsim), closed forms of
the H1/H2 noise bias (Bendat & Piersol, *Random Data*, 2010, ch. 6 and 9), exact FRFs of
`jaxvs.ModalModel`, and the real impact data of ladisk/pyFRF.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as ss

import jaxvs
from jaxvs.data import FRFData
from jaxvs.signal import (
    coherence,
    csd,
    exponential_window,
    exponential_window_correction,
    force_window,
    frf_h1,
    frf_h2,
    frf_hv,
    get_window,
    impact_windows,
    psd,
    transmissibility,
)

FS = 100.0


@pytest.fixture
def rng():
    return np.random.default_rng(20240611)


def _rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


# ---------------------------------------------------------------------------------------
# Windows
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["hann", "hamming", "boxcar", "flattop"])
@pytest.mark.parametrize("n", [1, 2, 7, 64])
@pytest.mark.parametrize("periodic", [True, False])
def test_windows_match_scipy(name, n, periodic):
    w = get_window(name, n, periodic=periodic)
    expected = ss.get_window(name, n, fftbins=periodic)
    # Same cosine sums evaluated on the same grid: agreement to rounding.
    np.testing.assert_allclose(np.asarray(w), expected, rtol=0, atol=1e-15)
    assert getattr(jaxvs.signal, name)(n, periodic=periodic).shape == (n,)


def test_exponential_window_matches_scipy():
    fs, tau = 200.0, 0.3
    w = exponential_window(100, fs, tau=tau)
    expected = ss.windows.exponential(100, center=0, tau=tau * fs, sym=False)
    np.testing.assert_allclose(np.asarray(w), expected, rtol=1e-14)  # same formula
    w_end = exponential_window(100, fs, end_value=0.01)
    # end_value fixes the last sample exactly (up to exp/log rounding).
    assert float(w_end[-1]) == pytest.approx(0.01, rel=1e-12)
    assert float(w_end[0]) == 1.0


def test_force_window_closed_form():
    fs = 1000.0
    w = np.asarray(force_window(100, fs, t_start=0.02, t_stop=0.03, taper=0.004))
    t = np.arange(100) / fs
    assert np.all(w[(t >= 0.02) & (t <= 0.03)] == 1.0)  # flat part
    assert np.all(w[(t < 0.016 - 1e-12) | (t > 0.034 + 1e-12)] == 0.0)  # outside the flanks
    # Half-cosine flank: 0.5·(1 + cos(π·d/taper)) at distance d; d = 2 ms -> 0.5.
    np.testing.assert_allclose(w[32], 0.5, atol=1e-12)
    np.testing.assert_allclose(w[18], 0.5, atol=1e-12)
    np.testing.assert_allclose(w[33], 0.5 * (1 + np.cos(np.pi * 0.75)), atol=1e-12)
    rect = np.asarray(force_window(100, fs, t_start=0.02, t_stop=0.03))
    np.testing.assert_array_equal(rect, ((t >= 0.02 - 1e-12) & (t <= 0.03 + 1e-12)) * 1.0)
    # One hit time per record -> one window per record.
    batch = force_window(100, fs, t_start=jnp.array([0.01, 0.05]), t_stop=jnp.array([0.02, 0.06]))
    assert batch.shape == (2, 100)


def test_impact_windows_locate_each_hit():
    fs, n = 1000.0, 200
    force = np.zeros((2, n))
    force[0, 10:13] = [1.0, 3.0, 1.0]
    force[1, 50:53] = [2.0, 5.0, 2.0]
    w_force, w_resp = impact_windows(force, fs, margin=0.002, taper=0.0, tau=0.05)
    w_exp = np.exp(-np.arange(n) / fs / 0.05)
    # Flat over the detected pulse widened by 2 samples, times the exponential.
    for k, (a, b) in enumerate([(10, 12), (50, 52)]):
        expected = np.zeros(n)
        expected[a - 2 : b + 3] = 1.0
        np.testing.assert_allclose(np.asarray(w_force[k]), expected * w_exp, atol=1e-15)
        np.testing.assert_allclose(np.asarray(w_resp[k]), w_exp, atol=1e-15)
    # Without tau/end_value the response window is all ones.
    _, ones = impact_windows(force, fs)
    assert np.all(np.asarray(ones) == 1.0)


def test_exponential_window_correction_inverts_pole_shift():
    # True modes; the window exp(-t/τ) moves every pole λ to λ − 1/τ.
    omega = np.array([2 * np.pi * 40.0, 2 * np.pi * 700.0])
    zeta = np.array([0.01, 0.002])
    tau = 0.05
    lam = omega * (-zeta + 1j * np.sqrt(1 - zeta**2)) - 1.0 / tau
    omega_w, zeta_w = np.abs(lam), -lam.real / np.abs(lam)
    omega_c, zeta_c = exponential_window_correction(omega_w, zeta_w, tau)
    np.testing.assert_allclose(np.asarray(omega_c), omega, rtol=1e-12)  # exact algebra
    np.testing.assert_allclose(np.asarray(zeta_c), zeta, rtol=1e-10)
    # First-order rule ζ ≈ ζ_w − 1/(τ ω_n): within (1/(τ ω))² ~ 0.6 % of ζ_w at 40 Hz.
    np.testing.assert_allclose(zeta_w - 1 / (tau * omega_w), zeta, atol=1e-3 * zeta_w.max())


# ---------------------------------------------------------------------------------------
# Welch spectra vs scipy
# ---------------------------------------------------------------------------------------

WELCH_CASES = [
    {},
    {"nperseg": 300, "noverlap": 100, "window": "hamming", "detrend": "linear"},
    {"nperseg": 257, "nfft": 300, "window": "flattop", "detrend": False},
    {"nperseg": 128, "noverlap": 0, "window": "boxcar", "scaling": "spectrum"},
    {"nperseg": 200, "window": np.random.default_rng(3).uniform(0.5, 1.0, 200)},
]


@pytest.mark.parametrize("kwargs", WELCH_CASES)
def test_psd_csd_match_scipy(rng, kwargs):
    x = rng.normal(size=(3, 2000))
    y = rng.normal(size=(3, 2000)) + 0.5 * x
    f, pxy = csd(x, y, FS, **kwargs)
    f_ref, pxy_ref = ss.csd(x, y, FS, **kwargs)
    # Same arithmetic (segment, detrend, window, FFT, average): rounding-level agreement.
    np.testing.assert_allclose(np.asarray(f), f_ref, rtol=1e-12)
    assert _rel(pxy, pxy_ref) < 1e-10
    f, pxx = psd(x, FS, **kwargs)
    _, pxx_ref = ss.welch(x, FS, **kwargs)
    assert _rel(pxx, pxx_ref) < 1e-10
    assert not jnp.iscomplexobj(pxx)


@pytest.mark.parametrize("kwargs", [{}, {"nperseg": 300, "noverlap": 100, "window": "hamming"}])
def test_coherence_matches_scipy(rng, kwargs):
    x = rng.normal(size=(2, 3000))
    y = ss.lfilter([1.0, 0.5], [1.0, -0.6], x) + 0.3 * rng.normal(size=x.shape)
    f, c = coherence(x, y, FS, **kwargs)
    _, c_ref = ss.coherence(x, y, FS, **kwargs)
    assert np.max(np.abs(np.asarray(c) - c_ref)) < 1e-10  # same arithmetic


def test_df_sets_segment_length(rng):
    x = rng.normal(size=5000)
    f, p = psd(x, FS, df=0.25)  # nperseg = fs/df = 400
    _, p_ref = ss.welch(x, FS, nperseg=400)
    assert f.shape == (201,) and float(f[1]) == pytest.approx(0.25)
    assert _rel(p, p_ref) < 1e-10  # same arithmetic


def test_records_axis_averages_blocks(rng):
    # Averaging over a records axis equals Welch over one record made of the same blocks
    # (boxcar, no overlap: the blocks are identical either way).
    x = rng.normal(size=(4, 256))
    y = rng.normal(size=(4, 256))
    f, pxy = csd(x, y, FS, window="boxcar", detrend=None, records_axis=0)
    _, pxy_ref = ss.csd(
        x.reshape(-1), y.reshape(-1), FS, window="boxcar", nperseg=256, noverlap=0, detrend=False
    )
    assert _rel(pxy, pxy_ref) < 1e-10  # same arithmetic
    est = frf_h1(x, y, FS, window="boxcar", detrend=None, records_axis=0)
    assert est.n_averages == 4 and est.H.shape == (129,)


# ---------------------------------------------------------------------------------------
# FRF estimators on known systems
# ---------------------------------------------------------------------------------------

B_FILT, A_FILT = [0.2, 0.3, -0.1], [1.0, -1.2, 0.72]  # poles at radius 0.85


def _multisine(rng, n_period):
    """One period of a flat-spectrum random-phase multisine (|X_k| = 1, no DC/Nyquist)."""
    spectrum = np.exp(2j * np.pi * rng.uniform(size=n_period // 2 + 1))
    spectrum[0] = spectrum[-1] = 0
    return np.fft.irfft(spectrum, n_period)


def test_estimators_match_scipy_spectra_and_eigenvector(rng):
    x = rng.normal(size=(2, 4000))
    y = ss.lfilter([0.5, 0.2], [1.0, -0.5], x) + 0.4 * rng.normal(size=x.shape)
    x_meas = x + 0.3 * rng.normal(size=x.shape)
    _, sxy = ss.csd(x_meas, y, FS, nperseg=512)
    _, sxx = ss.welch(x_meas, FS, nperseg=512)
    _, syy = ss.welch(y, FS, nperseg=512)
    h1, h2, hv = (f(x_meas, y, FS, nperseg=512) for f in (frf_h1, frf_h2, frf_hv))
    # Same spectra, so the ratios agree to rounding.
    np.testing.assert_allclose(np.asarray(h1.H), sxy / sxx, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(h2.H), syy / np.conj(sxy), rtol=1e-10)
    # Hv: principal eigenvector [v0, v1] of [[Sxx, Syx], [Sxy, Syy]], Hv = v1 / v0.
    spectral = np.stack([np.stack([sxx, np.conj(sxy)], -1), np.stack([sxy, syy], -1)], -2).astype(
        complex
    )
    _, vectors = np.linalg.eigh(spectral)
    principal = vectors[..., :, -1]
    np.testing.assert_allclose(
        np.asarray(hv.H), principal[..., 1] / principal[..., 0], rtol=1e-9
    )  # eigh vs the closed form: rounding of a 2x2 eigenproblem
    assert hv.H.shape == (2, 257) and h1.n_averages == 14


def test_periodic_excitation_gives_exact_frf(rng):
    n_period, n_periods = 256, 6
    x = np.tile(_multisine(rng, n_period), n_periods)
    y = ss.lfilter(B_FILT, A_FILT, x)
    # Drop two periods: the transient decays as 0.85^k < 1e-18 after 256 samples.
    x, y = x[2 * n_period :], y[2 * n_period :]
    opts = dict(window="boxcar", nperseg=n_period, noverlap=0, detrend=None)
    h1, h2, hv = (est(x, y, 1.0, **opts) for est in (frf_h1, frf_h2, frf_hv))
    _, h_true = ss.freqz(B_FILT, A_FILT, worN=2 * np.pi * np.asarray(h1.frequency))
    band = slice(1, -1)  # DC and Nyquist carry no excitation
    for est in (h1, h2, hv):
        # Steady-state periodic data, rectangular window: DFT ratio = H(e^{jω}) exactly.
        np.testing.assert_allclose(np.asarray(est.H)[band], h_true[band], rtol=1e-10)
        np.testing.assert_allclose(np.asarray(est.coherence)[band], 1.0, atol=1e-10)
    assert h1.n_averages == 4
    assert h1.metadata["estimator"] == "H1" and hv.metadata["estimator"] == "HV"


def test_bins_without_power_are_flagged(rng):
    # A ±1 sequence, rectangular window, mean removed per segment: the DC bin of every
    # segment is exactly 0, so H1 there is 0/0. It is reported as H = 0, γ² = 0.
    x = np.sign(rng.normal(size=4096))
    y = ss.lfilter([1.0, 0.5], [1.0], x)
    est = frf_h1(x, y, FS, window="boxcar", nperseg=256, noverlap=0)
    assert float(np.abs(est.H[0])) == 0.0 and float(est.coherence[0]) == 0.0
    _, h_true = ss.freqz([1.0, 0.5], [1.0], worN=2 * np.pi * np.asarray(est.frequency) / FS)
    # Other bins: FIR of length 2 vs 256-sample segments, edge error ~1/256 per segment.
    assert np.median(np.abs(np.asarray(est.H)[1:] / h_true[1:] - 1)) < 0.02


def test_white_noise_welch_recovers_filter(rng):
    x = rng.normal(size=2**15)
    y = ss.lfilter(B_FILT, A_FILT, x)
    est = frf_h1(x, y, FS, nperseg=1024)
    _, h_true = ss.freqz(B_FILT, A_FILT, worN=2 * np.pi * np.asarray(est.frequency) / FS)
    # Noise-free data: the error is Hann leakage and the segment-edge transient, which
    # scale with (pole time constant ~6 samples / nperseg); measured 1.1e-3. The DC bin
    # is left out: detrend="constant" removes exactly what it would measure.
    assert np.max(np.abs(np.asarray(est.H)[1:] / h_true[1:] - 1)) < 1e-2
    assert np.min(np.asarray(est.coherence)) > 0.99


def _noisy_multisine(rng, sigma_in, sigma_out):
    n_period, n_periods = 128, 400
    x = np.tile(_multisine(rng, n_period), n_periods + 2)
    y = ss.lfilter(B_FILT, A_FILT, x)[2 * n_period :]
    x = x[2 * n_period :]
    x_meas = x + sigma_in * rng.normal(size=x.shape)
    y_meas = y + sigma_out * rng.normal(size=y.shape)
    opts = dict(window="boxcar", nperseg=n_period, noverlap=0, detrend=None)
    ests = {
        name: f(x_meas, y_meas, 1.0, **opts)
        for name, f in (("h1", frf_h1), ("h2", frf_h2), ("hv", frf_hv))
    }
    _, h_true = ss.freqz(B_FILT, A_FILT, worN=2 * np.pi * np.asarray(ests["h1"].frequency))
    return ests, h_true, n_period


def _median_ratio(est, h_true):
    ratio = np.asarray(est.H)[1:-1] / h_true[1:-1]
    return np.median(ratio.real), np.median(ratio.imag)


def test_h1_biased_low_by_input_noise_h2_unbiased(rng):
    # Per bin |X_k|² = 1 and E|M_k|² = N σ²: input noise-to-signal ratio 0.25, so
    # E[H1] = H / (1 + 0.25) = 0.8 H, while H2 = S_yy / S_yx is unbiased.
    n_period = 128
    sigma = np.sqrt(0.25 / n_period)
    ests, h_true, _ = _noisy_multisine(rng, sigma, 0.0)
    re, im = _median_ratio(ests["h1"], h_true)
    # 400 averages: the median over 63 bins scatters ~0.3 %; 1.5 % allows 5 sigma.
    assert re == pytest.approx(0.8, abs=0.015) and abs(im) < 0.015
    re, im = _median_ratio(ests["h2"], h_true)
    assert re == pytest.approx(1.0, abs=0.015) and abs(im) < 0.015
    # The identity |H1| = γ²|H2| holds for every estimate.
    h1, h2 = ests["h1"], ests["h2"]
    np.testing.assert_allclose(np.asarray(h1.H), np.asarray(h1.coherence * h2.H), rtol=1e-10)


def test_h2_biased_high_by_output_noise_h1_unbiased(rng):
    n_period = 128
    sigma = np.sqrt(0.25 / n_period)  # E|N_k|² = 0.25 per bin
    ests, h_true, _ = _noisy_multisine(rng, 0.0, sigma)
    re, im = _median_ratio(ests["h1"], h_true)
    assert re == pytest.approx(1.0, abs=0.015) and abs(im) < 0.015  # 5 sigma, as above
    # E[H2] = H·(1 + E|N|²/(|H|²|X|²)) = H·(1 + 0.25/|H|²), bin by bin.
    expected = h_true * (1 + 0.25 / np.abs(h_true) ** 2)
    ratio = np.asarray(ests["h2"].H)[1:-1] / expected[1:-1]
    assert np.median(ratio.real) == pytest.approx(1.0, abs=0.015)
    assert np.all(np.abs(np.asarray(ests["h2"].H)) >= np.abs(np.asarray(ests["h1"].H)))


def test_hv_unbiased_with_equal_noise_on_both_channels(rng):
    n_period = 128
    sigma = np.sqrt(0.1 / n_period)
    ests, h_true, _ = _noisy_multisine(rng, sigma, sigma)
    re, _ = _median_ratio(ests["hv"], h_true)
    assert re == pytest.approx(1.0, abs=0.02)  # 400 averages; TLS is consistent here
    assert _median_ratio(ests["h1"], h_true)[0] < 0.95  # while H1 is biased low ...
    assert _median_ratio(ests["h2"], h_true)[0] > 1.05  # ... and H2 high
    mag = {k: np.abs(np.asarray(v.H)) for k, v in ests.items()}
    # |H1| <= |Hv| <= |H2| bin by bin (up to rounding).
    assert np.all(mag["h1"] <= mag["hv"] * (1 + 1e-12))
    assert np.all(mag["hv"] <= mag["h2"] * (1 + 1e-12))


# ---------------------------------------------------------------------------------------
# Impact testing
# ---------------------------------------------------------------------------------------


def test_exponential_window_gives_frf_of_damped_system():
    # Discrete resonator that has not decayed within the record (leakage without a window).
    fs, n = 1000.0, 4096
    radius, theta = 0.999, 2 * np.pi * 50 / fs
    b, a = [0.0, 1.0], [1.0, -2 * radius * np.cos(theta), radius**2]
    force = np.zeros(n)
    force[20:25] = np.sin(np.pi * np.arange(1, 6) / 6)
    response = ss.lfilter(b, a, force)
    w_f, w_r = impact_windows(force, fs, end_value=1e-8)
    est = frf_h1(force, response, fs, window=(w_f, w_r), detrend=None, nperseg=n)
    assert est.n_averages == 1
    # Windowing both channels by r^k maps H(z) to H(z/r): coefficients scaled by r^k.
    r = float(exponential_window(2, fs, end_value=1e-8 ** (1 / (n - 1)))[1])
    k = np.arange(3)
    _, h_damped = ss.freqz(
        np.array(b) * r ** k[:2],
        np.array(a) * r**k,
        worN=2 * np.pi * np.asarray(est.frequency) / fs,
    )
    pulse = np.abs(np.fft.rfft(force))
    band = pulse > 0.01 * pulse.max()  # where the pulse excites (it has zeros above 200 Hz)
    # Exact up to the part of y_w beyond the record, ~1e-8·0.999^4096 relative (the
    # same check with end_value=1e-4 errs by 0.6 %: choose the decay to kill the tail).
    np.testing.assert_allclose(np.asarray(est.H)[band], h_damped[band], rtol=1e-5)


@pytest.fixture(scope="module")
def impact(shared_data):
    records = [np.load(shared_data / "pyFRF_impact" / f"measurements_{i}.npy") for i in range(1, 6)]
    data = np.stack(records)  # (hit, row, time)
    t = data[0, 0]
    return 1.0 / (t[1] - t[0]), data[:, 1], data[:, 2]


@pytest.mark.slow
def test_impact_real_data_h1_h2_coherence(impact):
    fs, force, accel = impact
    w_f, w_r = impact_windows(force, fs, end_value=0.01)
    opts = dict(window=(w_f, w_r), records_axis=0, detrend=None)
    h1 = frf_h1(force, accel, fs, input_unit="N", output_unit="m/s^2", kind="accelerance", **opts)
    h2 = frf_h2(force, accel, fs, **opts)
    assert h1.n_averages == 5 and h1.H.shape == (12801,)
    # Identity γ² = H1/H2 (exact in the formulas; rounding only).
    np.testing.assert_allclose(
        np.asarray(h1.H / h2.H), np.asarray(h1.coherence), rtol=1e-9, atol=1e-12
    )
    assert np.all(np.abs(np.asarray(h1.H)) <= np.abs(np.asarray(h2.H)) * (1 + 1e-12))
    # Well-excited band: the hammer force spectrum is within 10 dB of its peak up to
    # 3.47 kHz; above 20 Hz the accelerometer is reliable.
    band = h1.select(20.0, 3400.0)
    c = np.asarray(band.coherence)
    assert np.median(c) > 0.995  # measured 0.9999
    assert np.mean(c > 0.9) > 0.98  # dips only at antiresonances; measured 99.5 %
    # The resonance peaks of H1 and H2 coincide (γ² ~ 1 there).
    f = np.asarray(h1.frequency)
    peaks1, _ = ss.find_peaks(np.abs(np.asarray(h1.H)) * (f < 6000), prominence=200.0)
    peaks2, _ = ss.find_peaks(np.abs(np.asarray(h2.H)) * (f < 6000), prominence=200.0)
    np.testing.assert_array_equal(peaks1, peaks2)
    assert len(peaks1) >= 5 and any(abs(f[p] - 900.0) < 2 for p in peaks1)


# ---------------------------------------------------------------------------------------
# Transmissibility
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def two_point_structure():
    """Tool and encoder responses of one 2-mode structure to one white-noise force."""
    rng = np.random.default_rng(7)
    omega, zeta = 2 * np.pi * np.array([40.0, 120.0]), np.array([0.06, 0.08])
    residues = np.array([[1.0, 0.6], [1.0, -0.8]]) * omega[:, None] ** 2  # (mode, tool/enc)
    model = jaxvs.ModalModel(omega, zeta, residues)
    # Independent state space x = (q1, q1', q2, q2'), q'' + 2ζω q' + ω² q = u.
    A, B = np.zeros((4, 4)), np.zeros((4, 1))
    for k in range(2):
        A[2 * k, 2 * k + 1] = 1
        A[2 * k + 1, 2 * k : 2 * k + 2] = [-(omega[k] ** 2), -2 * zeta[k] * omega[k]]
        B[2 * k + 1, 0] = 1
    c_pos = np.zeros((2, 4))
    c_pos[:, 0::2] = residues.T
    C = np.vstack([c_pos, c_pos @ A @ A])  # positions, then accelerations
    D = np.vstack([np.zeros((2, 1)), c_pos @ A @ B])
    fs, n = 4000.0, 2**17
    t = np.arange(n) / fs
    _, y, _ = ss.lsim((A, B, C, D), rng.normal(size=n), t)
    return model, fs, y.T  # rows: x_tool, x_enc, a_tool, a_enc


def _tmf_error(est, model):
    f = np.asarray(est.frequency)
    g = np.asarray(jaxvs.frequency_response(model, 2 * np.pi * f))
    t_true = g[:, 0, 0] / g[:, 1, 0]
    err = np.abs(np.asarray(est.H) / t_true - 1)
    band = (f > 5) & (f < 150)
    return err[band], np.asarray(est.coherence)[band]


@pytest.mark.parametrize(
    "tool, encoder",
    [
        ("position", "position"),
        ("acceleration", "acceleration"),
        ("acceleration", "position"),
        ("position", "acceleration"),
    ],
)
@pytest.mark.parametrize("estimator", ["h1", "h2", "hv"])
def test_transmissibility_recovers_ratio_of_frfs(two_point_structure, tool, encoder, estimator):
    model, fs, y = two_point_structure
    x_tool = y[0] if tool == "position" else y[2]
    x_enc = y[1] if encoder == "position" else y[3]
    est = transmissibility(
        x_tool,
        x_enc,
        fs,
        estimator=estimator,
        tool_quantity=tool,
        encoder_quantity=encoder,
        nperseg=8192,
    )
    assert est.kind == "transmissibility" and est.input_unit == est.output_unit == "m"
    # A conversion by (jω)^±2 drops the DC bin, where the factor is singular or zero.
    assert est.n_freq == (4097 if tool == encoder else 4096)
    err, coh = _tmf_error(est, model)
    # Noise-free: Hann leakage at the sharp TMF peak (encoder antiresonance near 21 Hz,
    # a few bins wide) and the FOH discretisation of lsim, ~(πf/fs)²; measured median
    # 0.07-0.25 %, worst 8 % at the peak, where the coherence drops below 0.99.
    assert np.median(err) < 5e-3
    assert np.max(err) < 0.12
    assert np.max(err[coh > 0.99]) < 0.05


def test_transmissibility_without_conversion_is_ratio_of_measured_quantities(
    two_point_structure,
):
    model, fs, y = two_point_structure
    raw = transmissibility(
        y[2], y[1], fs, tool_quantity="acceleration", to_position=False, nperseg=8192
    )
    conv = transmissibility(y[2], y[1], fs, tool_quantity="acceleration", nperseg=8192)
    assert raw.output_unit == "m/s^2" and raw.input_unit == "m" and raw.n_freq == 4097
    jw = 2j * np.pi * np.asarray(conv.frequency)
    # Same spectra, only the factor (jω)² between them: rounding-level agreement.
    np.testing.assert_allclose(np.asarray(raw.H)[1:], np.asarray(conv.H) * jw**2, rtol=1e-10)
    np.testing.assert_allclose(
        np.asarray(raw.coherence)[1:], np.asarray(conv.coherence), rtol=1e-10
    )


# ---------------------------------------------------------------------------------------
# Batching, jit, grad, dtypes
# ---------------------------------------------------------------------------------------


def test_batched_estimation_equals_loop_and_jit(rng):
    x = rng.normal(size=(8, 2048))
    y = ss.lfilter(B_FILT, A_FILT, x) + 0.1 * rng.normal(size=x.shape)
    batched = frf_hv(x, y, FS, nperseg=256)
    assert batched.batch_shape == (8,) and batched.H.shape == (8, 129)
    for k in range(8):
        one = frf_hv(x[k], y[k], FS, nperseg=256)
        # Same arithmetic per member.
        np.testing.assert_allclose(np.asarray(batched.H[k]), np.asarray(one.H), rtol=1e-12)
        np.testing.assert_allclose(
            np.asarray(batched.coherence[k]), np.asarray(one.coherence), rtol=1e-12
        )
    jitted = jax.jit(lambda a, b: frf_hv(a, b, FS, nperseg=256))(x, y)
    assert isinstance(jitted, FRFData)
    np.testing.assert_allclose(np.asarray(jitted.H), np.asarray(batched.H), rtol=1e-12)
    vmapped = jax.vmap(lambda a, b: frf_hv(a, b, FS, nperseg=256).H)(x, y)
    np.testing.assert_allclose(np.asarray(vmapped), np.asarray(batched.H), rtol=1e-12)
    # One input broadcast against several outputs, and records within a family.
    multi = frf_h1(x[0], y[:3], FS, nperseg=256)
    np.testing.assert_allclose(
        np.asarray(multi.H[1]), np.asarray(frf_h1(x[0], y[1], FS, nperseg=256).H), rtol=1e-12
    )
    fam = frf_h1(x.reshape(2, 4, 2048), y.reshape(2, 4, 2048), FS, records_axis=1, nperseg=256)
    assert fam.H.shape == (2, 129) and fam.n_averages == 4 * 15


def test_grad_matches_finite_differences(rng):
    x = jnp.asarray(rng.normal(size=512))
    y = jnp.asarray(ss.lfilter(B_FILT, A_FILT, np.asarray(x)) + 0.2 * rng.normal(size=512))
    weights = jnp.asarray(rng.normal(size=33))

    @jax.jit
    def loss(scale):
        # A nonlinear function of the parameter, through all three estimators.
        y_s = scale * y + 0.1 * scale**2 * x**2
        total = 0.0
        for est in (frf_h1, frf_h2, frf_hv):
            total = total + jnp.sum(weights * jnp.abs(est(x, y_s, FS, nperseg=64).H) ** 2)
        return total

    g = jax.grad(loss)(1.3)
    eps = 1e-6
    fd = (loss(1.3 + eps) - loss(1.3 - eps)) / (2 * eps)
    # Central difference: truncation O(eps²), rounding ~1e-16·|loss|/eps ~ 1e-9 relative.
    assert float(g) == pytest.approx(float(fd), rel=1e-6)


def test_float32_is_preserved(rng):
    x = rng.normal(size=1024).astype(np.float32)
    y = (2 * x + 0.1 * rng.normal(size=1024)).astype(np.float32)
    est = frf_h1(x, y, FS)
    assert est.H.dtype == jnp.complex64 and est.coherence.dtype == jnp.float32
    _, p = psd(x, FS)
    assert p.dtype == jnp.float32


# ---------------------------------------------------------------------------------------
# FRFData
# ---------------------------------------------------------------------------------------


def test_frfdata_container():
    f = np.linspace(0.0, 100.0, 11)
    h = np.exp(1j * f / 10)
    data = FRFData(
        f,
        h,
        coherence=np.full(11, 0.9),
        n_averages=3,
        input_unit="N",
        output_unit="m",
        kind="receptance",
        metadata={"sensor": "acc-1"},
    )
    assert data.is_siso and data.n_freq == 11 and data.batch_shape == ()
    np.testing.assert_allclose(np.asarray(data.omega), 2 * np.pi * f)
    text = repr(data)
    assert "receptance" in text and "'N' -> 'm'" in text and "n_averages=3" in text
    sub = data.select(25.0, 55.0)
    np.testing.assert_allclose(np.asarray(sub.frequency), [30.0, 40.0, 50.0])
    np.testing.assert_allclose(np.asarray(sub.H), h[3:6])
    assert sub.metadata["sensor"] == "acc-1" and sub.kind == "receptance"
    with pytest.raises(dataclasses.FrozenInstanceError):
        data.kind = "frf"
    with pytest.raises(TypeError):
        data.metadata["sensor"] = "other"
    mimo = FRFData(f, np.ones((4, 11, 2, 3)))
    assert mimo.io_shape == (2, 3) and mimo.batch_shape == (4,) and not mimo.is_siso
    assert mimo.select(f_max=20.0).H.shape == (4, 3, 2, 3)
    real = FRFData(f, np.ones(11))
    assert jnp.iscomplexobj(real.H)
    # Passes through jit as a pytree.
    doubled = jax.jit(lambda d: FRFData(d.frequency, 2 * d.H, kind=d.kind))(data)
    np.testing.assert_allclose(np.asarray(doubled.H), 2 * h)


def test_frfdata_errors():
    f = np.linspace(0.0, 100.0, 5)
    h = np.ones(5, complex)
    with pytest.raises(ValueError, match="strictly increasing"):
        FRFData(f[::-1], h)
    with pytest.raises(ValueError, match="negative"):
        FRFData(f - 10, h)
    with pytest.raises(ValueError, match="frequency has a non-finite"):
        FRFData(np.array([0, 1, np.nan, 3, 4.0]), h)
    with pytest.raises(ValueError, match="H has 1 non-finite"):
        FRFData(f, np.array([1, 1, np.inf, 1, 1.0]))
    with pytest.raises(ValueError, match="does not match 5 frequencies"):
        FRFData(f, np.ones(4))
    with pytest.raises(ValueError, match="1-D grid"):
        FRFData(f[None], h)
    with pytest.raises(ValueError, match="reads both"):
        FRFData(f, np.ones((5, 5, 5)))
    assert FRFData(f, np.ones((5, 5, 5)), io_shape=()).batch_shape == (5, 5)
    with pytest.raises(ValueError, match="does not fit io_shape"):
        FRFData(f, h, io_shape=(1, 1))
    with pytest.raises(ValueError, match=r"coherence must lie in \[0, 1\]"):
        FRFData(f, h, coherence=np.full(5, 1.5))
    with pytest.raises(ValueError, match="coherence has shape"):
        FRFData(f, h, coherence=np.ones(4))
    with pytest.raises(TypeError, match="coherence must be real"):
        FRFData(f, h, coherence=h)
    with pytest.raises(TypeError, match="frequency must be real"):
        FRFData(f + 0j, h)
    with pytest.raises(ValueError, match="unknown kind"):
        FRFData(f, h, kind="compliance")
    with pytest.raises(ValueError, match="n_averages must be >= 1"):
        FRFData(f, h, n_averages=0)
    with pytest.raises(TypeError, match="n_averages must be a Python int"):
        FRFData(f, h, n_averages=2.0)
    with pytest.raises(TypeError, match="input_unit must be a string"):
        FRFData(f, h, input_unit=None)
    with pytest.raises(TypeError, match="not hashable"):
        FRFData(f, h, metadata={"window": np.ones(3)})
    with pytest.raises(ValueError, match="no frequency in"):
        FRFData(f, h).select(200.0, 300.0)
    with pytest.raises(ValueError, match="is above f_max"):
        FRFData(f, h).select(50.0, 10.0)
    with pytest.raises(eqx.EquinoxRuntimeError, match="H contains NaN or inf"):
        eqx.filter_jit(lambda a: FRFData(f, a))(jnp.array([1, 1, jnp.nan, 1, 1.0]))


# ---------------------------------------------------------------------------------------
# Documented errors of the estimators
# ---------------------------------------------------------------------------------------


def test_estimator_errors(rng):
    x = rng.normal(size=1000)
    y = rng.normal(size=1000)
    with pytest.raises(ValueError, match="resample"):
        frf_h1(x, y[:900], FS)
    with pytest.raises(ValueError, match="different rates.*resample"):
        frf_h1(x, y, (FS, 2 * FS))
    assert frf_h1(x, y, (FS, FS)).metadata["fs"] == FS  # agreeing rates are fine
    with pytest.raises(ValueError, match="fewer than nperseg = 256"):
        frf_h1(x[:200], y[:200], FS)
    with pytest.raises(ValueError, match=r"df = 0.05 Hz needs segments of nperseg .* 2000"):
        frf_h1(x, y, FS, df=0.05)
    with pytest.raises(ValueError, match="either nperseg or df"):
        psd(x, FS, nperseg=100, df=1.0)
    bad = x.copy()
    bad[7] = np.nan
    with pytest.raises(
        ValueError, match=r"x has 1 non-finite sample\(s\), the first at index \(7,\)"
    ):
        frf_h1(bad, y, FS)
    bad[7] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        csd(x, bad, FS)
    with pytest.raises(ValueError, match="input x is constant.*broadband"):
        frf_h1(np.ones(1000), y, FS)
    with pytest.raises(ValueError, match=r"output y is constant \(family member 1 of 2\)"):
        frf_h2(np.stack([x, x]), np.stack([y, np.zeros(1000)]), FS)
    with pytest.raises(ValueError, match="input x_encoder is constant"):
        transmissibility(y, np.zeros(1000), FS)
    with pytest.raises(ValueError, match="noverlap = 256 must satisfy"):
        psd(x, FS, noverlap=256)
    with pytest.raises(ValueError, match="nfft must be an int >= nperseg"):
        psd(x, FS, nfft=100)
    with pytest.raises(ValueError, match="window has 100 samples but nperseg = 128"):
        psd(x, FS, window=np.ones(100), nperseg=128)
    with pytest.raises(ValueError, match="Unknown window 'kaiser'"):
        psd(x, FS, window="kaiser")
    with pytest.raises(ValueError, match="detrend must be"):
        psd(x, FS, detrend="quadratic")
    with pytest.raises(ValueError, match="scaling must be"):
        psd(x, FS, scaling="magnitude")
    with pytest.raises(ValueError, match="records_axis=-1 must name a leading axis"):
        frf_h1(x, y, FS, records_axis=-1)
    with pytest.raises(ValueError, match="do not broadcast"):
        frf_h1(np.ones((2, 1000)), np.ones((3, 1000)), FS)
    with pytest.raises(ValueError, match="does not broadcast against signals"):
        frf_h1(x, y, FS, window=np.ones((3, 256)))
    with pytest.raises(ValueError, match="pair makes the cross-spectrum scaling ambiguous"):
        csd(x, y, FS, window=("hann", "boxcar"))
    with pytest.raises(TypeError, match="must be a real time record"):
        frf_h1(x + 0j, y, FS)
    with pytest.raises(ValueError, match="sampling rate fs must be a finite positive"):
        frf_h1(x, y, -1.0)
    with pytest.raises(TypeError, match="static_argnames"):
        jax.jit(lambda fs: frf_h1(x, y, fs))(FS)
    with pytest.raises(ValueError, match="estimator must be one of"):
        transmissibility(x, y, FS, estimator="h3")
    with pytest.raises(ValueError, match="tool_quantity must be one of"):
        transmissibility(x, y, FS, tool_quantity="jerk")
    with pytest.raises(ValueError, match="exactly one of tau"):
        exponential_window(10, FS)
    with pytest.raises(ValueError, match="end_value must lie in"):
        exponential_window(10, FS, end_value=2.0)
    with pytest.raises(ValueError, match="t_start must not be after t_stop"):
        force_window(10, FS, t_start=0.05, t_stop=0.01)
    with pytest.raises(ValueError, match="window length must be a positive int"):
        get_window("hann", 0)
    with pytest.raises(ValueError, match="threshold must lie in"):
        impact_windows(x, FS, threshold=1.5)
    with pytest.raises(TypeError, match="give margin= explicitly"):
        jax.jit(lambda f: impact_windows(f, FS))(x)


def test_errors_under_jit(rng):
    x = rng.normal(size=1000)
    y = rng.normal(size=1000)
    f = eqx.filter_jit(lambda a, b: frf_h1(a, b, FS))
    bad = x.copy()
    bad[3] = np.nan
    with pytest.raises(eqx.EquinoxRuntimeError, match="x contains NaN or inf"):
        f(jnp.asarray(bad), jnp.asarray(y))
    with pytest.raises(eqx.EquinoxRuntimeError, match="input x is constant"):
        f(jnp.ones(1000), jnp.asarray(y))


def test_welch_options_object_equals_keywords():
    """`welch=Welch(...)` is the same estimate as its fields given as keywords; mixing the
    two, or an unknown option, is refused."""
    from jaxvs.signal import Welch, frf_h2

    rng = np.random.default_rng(0)
    x = rng.normal(size=4096)
    y = np.convolve(x, [1.0, 0.5, 0.2])[:4096] + 0.1 * rng.normal(size=4096)
    opts = Welch(nperseg=256, noverlap=64, window="hamming")
    a = frf_h2(x, y, 1000.0, nperseg=256, noverlap=64, window="hamming")
    b = frf_h2(x, y, 1000.0, welch=opts)
    np.testing.assert_array_equal(np.asarray(a.H), np.asarray(b.H))  # same arithmetic
    assert a.metadata["nperseg"] == 256 and b.metadata["noverlap"] == 64
    with pytest.raises(TypeError, match="not both"):
        frf_h2(x, y, 1000.0, welch=opts, nperseg=128)
    with pytest.raises(TypeError, match="unknown option.*nperseq"):
        frf_h2(x, y, 1000.0, nperseq=128)


def test_transmissibility_takes_the_welch_options_object():
    # the same estimate from welch=Welch(...) and from its fields as keywords
    from jaxvs.signal import Welch, transmissibility

    rng = np.random.default_rng(1)
    xe = rng.normal(size=4096)
    xt = np.convolve(xe, [0.8, 0.3, 0.1])[:4096] + 0.05 * rng.normal(size=4096)
    a = transmissibility(xt, xe, 1000.0, nperseg=512, window="hamming")
    b = transmissibility(xt, xe, 1000.0, welch=Welch(nperseg=512, window="hamming"))
    np.testing.assert_array_equal(np.asarray(a.H), np.asarray(b.H))  # same arithmetic
    with pytest.raises(TypeError, match="not both"):
        transmissibility(xt, xe, 1000.0, welch=Welch(nperseg=512), nperseg=256)
    with pytest.raises(TypeError, match=r"unknown option.*npersg.*the Welch options"):
        transmissibility(xt, xe, 1000.0, npersg=512)
