"""Statistics of the gap: the gap metric, noise floor, block bootstrap, false discovery rate
and information criteria.

Residuals of a calibrated model are autocorrelated (a missing effect leaves structure in
them by definition), so every resampling here works on contiguous blocks (Künsch 1989;
the moving-block bootstrap) whose length follows the residual's correlation time, and
every family of tests over gap-map cells is corrected with Benjamini–Hochberg (1995).
All of this is host-side NumPy: it runs once per diagnosis on vectors of residuals.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.signal as ss

from ..signal import block_bootstrap_indices, block_length, integrated_time

__all__ = [
    "benjamini_hochberg",
    "bic",
    "block_bootstrap_indices",
    "block_length",
    "gap_change_interval",
    "nrmse",
    "ar1_draws",
    "ar1_noise",
    "noise_like",
    "white_noise_floor",
]


def nrmse(residual: np.ndarray, target: np.ndarray) -> float:
    """Normalised RMS error `‖e‖ / ‖y − 0‖`: the relative error of the EMPS description
    (eq. 11), a fraction (×100 for %). The target is not de-meaned, as in the study."""
    den = float(np.sqrt(np.mean(np.square(target))))
    if den == 0.0:
        return float("inf")
    return float(np.sqrt(np.mean(np.square(residual))) / den)


def gap_change_interval(
    e_before: np.ndarray,
    e_after: np.ndarray,
    target: np.ndarray,
    *,
    length: int,
    n_boot: int = 400,
    level: float = 0.95,
    seed: int = 0,
) -> tuple[float, float, float, tuple[float, float], tuple[float, float]]:
    """Held-out gap reduction with a paired moving-block bootstrap interval.

    The gap is `nrmse`; the reduction `Δ = gap(e_before) − gap(e_after)` and the shrink
    `1 − gap_after/gap_before` are resampled together (same blocks for both models and
    the target), so the interval accounts for the autocorrelation of both residuals.

    **Returns:** `(gap_before, gap_after, shrink, reduction_interval, shrink_interval)`.
    """
    e0 = np.asarray(e_before, float)
    e1 = np.asarray(e_after, float)
    y = np.asarray(target, float)
    g0, g1 = nrmse(e0, y), nrmse(e1, y)
    rng = np.random.default_rng(seed)
    idx = block_bootstrap_indices(e0.size, length, n_boot, rng)
    s0 = np.sqrt(np.mean(e0[idx] ** 2, axis=1))
    s1 = np.sqrt(np.mean(e1[idx] ** 2, axis=1))
    sy = np.sqrt(np.mean(y[idx] ** 2, axis=1))
    sy = np.where(sy > 0, sy, np.inf)
    d = (s0 - s1) / sy
    with np.errstate(divide="ignore", invalid="ignore"):
        sh = np.where(s0 > 0, 1.0 - s1 / s0, 0.0)
    a = (1.0 - level) / 2.0
    d_int = (float(np.quantile(d, a)), float(np.quantile(d, 1 - a)))
    s_int = (float(np.quantile(sh, a)), float(np.quantile(sh, 1 - a)))
    shrink = 1.0 - g1 / g0 if g0 > 0 else 0.0
    return g0, g1, shrink, d_int, s_int


def bic(ssr: float, n: int, p: int) -> float:
    """Bayesian information criterion of a Gaussian least-squares fit,
    `N ln(SSR/N) + p ln N` (Schwarz 1978)."""
    return float(n * math.log(max(ssr, 1e-300) / n) + p * math.log(n))


def benjamini_hochberg(p_values: Sequence[float], q: float = 0.05) -> np.ndarray:
    """Benjamini–Hochberg step-up procedure: a boolean mask of the discoveries at false
    discovery rate `q` (valid under independence and positive regression dependence)."""
    p = np.asarray(p_values, float)
    m = p.size
    if m == 0:
        return np.zeros(0, bool)
    order = np.argsort(p)
    thresh = q * np.arange(1, m + 1) / m
    below = p[order] <= thresh
    out = np.zeros(m, bool)
    if below.any():
        k = int(np.nonzero(below)[0].max())
        out[order[: k + 1]] = True
    return out


def white_noise_floor(
    residual: np.ndarray, fs: float, band: tuple[float, float] | None = None
) -> tuple[float, float]:
    """Noise level of a residual from its high-frequency content.

    The residual's Welch PSD in the top part of the spectrum (by default 70–95 % of the
    Nyquist frequency), where a model's systematic error has no power left, is taken as
    the level of a white measurement noise; its median (robust to lines) over that band
    gives the one-sided noise PSD `S₀` [unit²/Hz]. The noise variance in the analysed band
    `[0, B]` is then `S₀·B`.

    **Returns:** `(S0, sigma_full)` with `sigma_full = sqrt(S0·fs/2)`, the standard
    deviation of a white noise over the whole band.
    """
    e = np.asarray(residual, float)
    nper = int(min(e.size, 1024))
    f, pxx = ss.welch(e - e.mean(), fs=fs, nperseg=nper)
    lo, hi = band if band is not None else (0.70 * fs / 2, 0.95 * fs / 2)
    sel = (f >= lo) & (f <= hi)
    if not sel.any():
        sel = f >= 0.5 * fs / 2
    s0 = float(np.median(pxx[sel]))
    return s0, math.sqrt(s0 * fs / 2.0)


def noise_like(residual: np.ndarray, fs: float, rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` Gaussian draws of the length of `residual` with its power spectrum.

    The spectrum is the residual's Welch estimate with the **median** over segments
    (Bartlett-bias corrected): a disturbance confined to a few segments (pulses, a
    transient) does not raise it, while a coloured measurement noise is carried with its
    in-band power -- what a white estimate from the differences or the top of the spectrum
    misses by the noise's correlation time. Each draw is white Gaussian noise shaped in
    the frequency domain, `Y(f) = W(f)·sqrt(S(f)·fs/2)` (a white unit-variance sequence has
    the one-sided PSD `2/fs`), so its PSD is `S`.

    **Returns:** array `(count, len(residual))`.
    """
    e = np.asarray(residual, float)
    n = e.size
    nper = int(min(n, 1024))
    f, pxx = ss.welch(e - e.mean(), fs=fs, nperseg=nper, average="median")
    fk = np.fft.rfftfreq(n, 1.0 / fs)
    gain = np.sqrt(np.maximum(np.interp(fk, f, pxx), 0.0) * fs / 2.0)
    w = np.fft.rfft(rng.standard_normal((count, n)), axis=1)
    return np.fft.irfft(w * gain, n=n, axis=1)


def difference_noise_sigma(residual: np.ndarray) -> float:
    """Standard deviation of the white part of a residual from its first differences,
    `σ² ≈ median-based var(Δe)/2` (von Neumann's successive-difference estimator, made
    robust with the MAD): a smooth systematic error contributes almost nothing to `Δe`."""
    d = np.diff(np.asarray(residual, float))
    if d.size == 0:
        return 0.0
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / math.sqrt(2.0)


# the standard deviation of `ar1_noise`'s lag-one correlation on white noise is
# `AR1_WHITE_SD / sqrt(N)` (simulated: 2.4 at N = 1000 to 16 000); the correlation is taken
# as zero unless it exceeds the one-sided 1 % quantile of that distribution
AR1_WHITE_SD = 2.4
AR1_LEVEL_Z = 2.326


def ar1_noise(x: np.ndarray) -> tuple[float, float]:
    """Level and lag-one correlation of a first-order autoregressive (AR(1)) measurement
    noise `e` in a sampled signal `x = s + e` whose systematic part `s` is smooth.

    Differences of `x` leave the noise and almost nothing of `s`. For an AR(1) noise of
    standard deviation `σ` and correlation `ρ`, the lag-two difference `x_{k+1} − x_{k−1}`
    has the variance `2σ²(1 − ρ²)` and the second difference `x_{k+1} − 2x_k + x_{k−1}`
    the variance `2σ²(1 − ρ)(3 − ρ)`; their ratio `R = (1 + ρ)/(3 − ρ)` gives
    `ρ = (3R − 1)/(1 + R)`, then `σ`. Both variances are robust (MAD), so the steps of
    `s` at a few instants do not count. White noise (`ρ = 0`) gives `R = 1/3` and the
    second-difference level `σ² = var(Δ²x)/6`; a correlation within the white noise's
    sampling spread (`AR1_WHITE_SD/√N` at the one-sided 1 % level) is taken as zero.

    **Returns:** `(sigma, rho)`, `0 ≤ rho < 1`.
    """
    x = np.asarray(x, float)
    if x.size < 8:
        return 0.0, 0.0

    def var(d):
        return (1.4826 * float(np.median(np.abs(d - np.median(d))))) ** 2

    v2 = var(np.diff(x, 2))
    if v2 <= 0.0:
        return 0.0, 0.0
    ratio = var(x[2:] - x[:-2]) / v2
    rho = (3.0 * ratio - 1.0) / (1.0 + ratio)
    if rho <= AR1_LEVEL_Z * AR1_WHITE_SD / math.sqrt(x.size):
        rho = 0.0
    rho = min(rho, 0.999)
    return math.sqrt(v2 / (2.0 * (1.0 - rho) * (3.0 - rho))), rho


def ar1_draws(
    sigma: float, rho: float, n: int, rng: np.random.Generator, count: int
) -> np.ndarray:
    """`count` stationary AR(1) sequences of length `n`, standard deviation `sigma` and
    lag-one correlation `rho` (`e_k = ρ e_{k−1} + σ√(1 − ρ²) w_k`, started in the
    stationary distribution). **Returns:** array `(count, n)`."""
    w = rng.standard_normal((count, n))
    if rho <= 0.0:
        return sigma * w
    zi = (sigma * rng.standard_normal(count) * rho)[:, None]
    return ss.lfilter([sigma * math.sqrt(1.0 - rho * rho)], [1.0, -rho], w, axis=1, zi=zi)[0]


def quantisation_step(x: np.ndarray) -> float:
    """The quantisation step of a sampled signal, 0 when it is not quantised.

    A quantised signal moves by integer multiples of its step `Δ`; the smallest non-zero
    absolute difference between samples is taken as the candidate (a slow motion crosses
    single counts) and accepted when at least 99 % of the non-zero differences are within
    1 % of a multiple of it (sensor noise or floating-point data break this).
    """
    d = np.abs(np.diff(np.asarray(x, float)))
    scale = float(np.max(np.abs(x))) if np.size(x) else 0.0
    d = d[d > 1e-12 * max(scale, 1e-300)]
    if d.size < 10:
        return 0.0
    step = float(np.min(d))
    ratio = d / step
    if ratio.max() > 1e7:
        return 0.0
    on_grid = np.abs(ratio - np.round(ratio)) < 0.01
    return step if float(np.mean(on_grid)) >= 0.99 else 0.0


def effective_samples(residual: np.ndarray) -> float:
    """Effective number of independent samples of an autocorrelated residual,
    `N_eff = N / τ`, `τ = 1 + 2 Σ ρ_k` its integrated autocorrelation time (summed up
    to the first non-positive autocorrelation, Geyer's initial positive sequence).
    An information criterion with `N_eff` in place of `N` does not count correlated
    samples as independent evidence (Box, Jenkins & Reinsel, *Time Series Analysis*)."""
    n = np.size(residual)
    tau = integrated_time(residual)
    if tau is None:
        return float(max(n, 1))
    return float(n / max(1.0, tau))


def bic_effective(ssr: float, n: int, p: int, n_eff: float) -> float:
    """BIC with an effective sample size: `N_eff ln(SSR/N) + p ln N_eff`. The log
    likelihood of `N` correlated samples carries the information of `N_eff` independent
    ones; with white residuals (`N_eff = N`) this is `bic`."""
    n_eff = float(min(max(n_eff, 2.0), n))
    return float(n_eff * math.log(max(ssr, 1e-300) / n) + p * math.log(n_eff))
