"""The best linear approximation (BLA) of a system under periodic excitation, and the split
of what it does not explain into measurement noise and nonlinear distortion.

Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed. (Wiley
2012), §3.7 (the "robust method"): with `M` realisations of a random-phase multisine (same
amplitude spectrum, independent phases), each measured over `P` steady-state periods,

- the noise is what varies from **period to period** of one realisation: the sample
  variance over the periods of the DFT of each period;
- the nonlinear distortion is what varies from **realisation to realisation** beyond the
  noise: a static or dynamic nonlinearity under a random-phase multisine acts at the
  excited lines as the BLA plus a zero-mean "stochastic nonlinear contribution" whose
  phase changes with the realisation, and at the lines not excited as output power with
  no input there.

With the one-period DFT `Y_m,p(k)` of period `p` of realisation `m` (normalised by the
number of samples `N`, so that `A cos(2π k t/N)` gives `|Y(k)| = A/2`):

    Ŷ_m = mean_p Y_m,p,   σ²_Ŷm = Σ_p |Y_m,p − Ŷ_m|² / (P (P − 1))     (likewise U)
    Ĝ_m = Ŷ_m / Û_m,      Ĝ = mean_m Ĝ_m                               (the BLA)
    σ²_Ĝ = Σ_m |Ĝ_m − Ĝ|² / (M (M − 1))                                (total)
    σ²_Ĝ,n = Σ_m σ²_Ĝm / M²,  σ²_Ĝm = |Ĝ_m|² (σ²_Ŷm/|Ŷ_m|² + σ²_Ûm/|Û_m|²
                                                − 2 Re(σ²_ŶÛm / (Ŷ_m conj(Û_m))))
    σ²_Gs = M (σ²_Ĝ − σ²_Ĝ,n)                                          (one realisation)

The output-level variances at an excited line are `σ²_Yn(k) = P·mean_m σ²_Ŷm` (the noise
of one period) and `σ²_Ys(k) = σ²_Gs(k)·mean_m |Û_m(k)|²`; summed over the lines `k` and
`−k` they are the time-domain variances of the noise and the distortion in the excited band.
Everything is host-side NumPy: it runs once on a record.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = [
    "BLA",
    "best_linear_approximation",
    "find_period",
    "period_noise",
    "settled_periods",
]


@dataclasses.dataclass(frozen=True)
class BLA:
    """The best linear approximation and its noise / distortion split.

    - `lines`: the excited DFT lines `k` of one period (frequency `k/(N dt)`).
    - `frf`: the BLA `Ĝ(k)` at `lines`, complex.
    - `frf_noise_var`: `σ²_Ĝ,n(k)`, the variance of `Ĝ` due to the noise.
    - `frf_total_var`: `σ²_Ĝ(k)` from the realisation-to-realisation spread (`nan` with one
      realisation).
    - `frf_distortion_var`: `σ²_Gs(k)`, the variance of the stochastic nonlinear
      contribution of one realisation (`nan` with one realisation; clipped at 0).
    - `y_noise_var`: `σ²_Yn(k)` at every line `0..N/2` (one period's DFT).
    - `y_distortion_var`: `σ²_Ys(k)` at `lines` (`nan` with one realisation).
    - `y_excess`: at every line `0..N/2`, the power of the averaged output above the
      noise of that average (`|Ŷ|² − σ²_Ŷ`, mean over realisations): at lines not excited
      it is nonlinear distortion (or another input).
    - `noise_level`, `distortion_level`: time-domain standard deviations [unit of `y`] of
      the noise and of the distortion in the excited band (the distortion from the
      realisations when `M ≥ 2`, else from the lines not excited between the lowest and
      three times the highest excited line; 0 when no such line shows power above the
      noise).
    - `periods`, `realisations`, `period_samples`: `P`, `M`, `N`.
    """

    lines: np.ndarray
    frf: np.ndarray
    frf_noise_var: np.ndarray
    frf_total_var: np.ndarray
    frf_distortion_var: np.ndarray
    y_noise_var: np.ndarray
    y_distortion_var: np.ndarray
    y_excess: np.ndarray
    noise_level: float
    distortion_level: float
    periods: int
    realisations: int
    period_samples: int


def _as_mpn(x: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3:
        raise ValueError(
            f"best_linear_approximation: {name} must be (periods, samples) or (realisations, "
            f"periods, samples); got shape {x.shape}. Cut the steady-state record into whole "
            "periods first (find_period gives the period)."
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"best_linear_approximation: {name} holds NaN or inf; drop those samples.")
    return x


def best_linear_approximation(u: np.ndarray, y: np.ndarray, *, excited: float = 1e-6) -> BLA:
    """The BLA from `u` to `y` over periods and realisations, with the variance of its
    noise and of its nonlinear distortion (Pintelon & Schoukens 2012, §3.7; module doc).

    **Arguments:**

    - `u`, `y`: input and output, `(P, N)` (one realisation) or `(M, P, N)`: `M`
        realisations of `P` steady-state periods of `N` samples each. `P ≥ 2`.
    - `excited`: a line is excited when its input power is above this share of the
        largest line's.

    **Returns:** a [`BLA`][].
    """
    u3, y3 = _as_mpn(u, "u"), _as_mpn(y, "y")
    if u3.shape != y3.shape:
        raise ValueError(
            f"best_linear_approximation: u has shape {u3.shape} and y {y3.shape}; give both "
            "the same (realisations, periods, samples)."
        )
    m, p, n = u3.shape
    if p < 2 or n < 4:
        raise ValueError(
            f"best_linear_approximation: needs at least 2 periods of at least 4 samples; got "
            f"{p} period(s) of {n}. Record more periods of the excitation."
        )
    uf = np.fft.rfft(u3, axis=-1) / n  # (M, P, K)
    yf = np.fft.rfft(y3, axis=-1) / n
    um, ym = uf.mean(axis=1), yf.mean(axis=1)  # (M, K)
    du, dy = uf - um[:, None], yf - ym[:, None]
    var_y = np.sum(np.abs(dy) ** 2, axis=1) / (p * (p - 1))  # variance of the mean
    var_u = np.sum(np.abs(du) ** 2, axis=1) / (p * (p - 1))
    cov_yu = np.sum(dy * np.conj(du), axis=1) / (p * (p - 1))
    power_u = np.mean(np.abs(um) ** 2, axis=0)
    lines = np.flatnonzero(power_u > excited * power_u.max())
    lines = lines[lines > 0]
    if lines.size == 0:
        raise ValueError("best_linear_approximation: u excites no line; u is constant.")
    ue, ye = um[:, lines], ym[:, lines]
    g_m = ye / ue
    g = g_m.mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = (
            var_y[:, lines] / np.abs(ye) ** 2
            + var_u[:, lines] / np.abs(ue) ** 2
            - 2 * np.real(cov_yu[:, lines] / (ye * np.conj(ue)))
        )
    var_gm = np.abs(g_m) ** 2 * np.maximum(np.nan_to_num(rel), 0.0)
    var_gn = var_gm.sum(axis=0) / m**2
    y_noise = p * var_y.mean(axis=0)  # one period's DFT
    y_excess = np.mean(np.abs(ym) ** 2 - var_y, axis=0)
    if m >= 2:
        var_g = np.sum(np.abs(g_m - g) ** 2, axis=0) / (m * (m - 1))
        var_gs = np.maximum(m * (var_g - var_gn), 0.0)
        y_dist = var_gs * np.mean(np.abs(ue) ** 2, axis=0)
        distortion = math.sqrt(2.0 * float(np.sum(y_dist)))
    else:
        var_g = np.full(lines.size, np.nan)
        var_gs = np.full(lines.size, np.nan)
        y_dist = np.full(lines.size, np.nan)
        # one realisation: the distortion shows only at lines not excited, between the
        # lowest excited line and three times the highest (where a cubic term lands)
        k = np.arange(y_excess.size)
        free = (k >= lines.min()) & (k <= 3 * lines.max()) & ~np.isin(k, lines) & (k > 0)
        distortion = math.sqrt(2.0 * max(float(np.sum(y_excess[free])), 0.0))
    noise = math.sqrt(2.0 * float(np.sum(y_noise[lines])))
    return BLA(
        lines=lines,
        frf=g,
        frf_noise_var=var_gn,
        frf_total_var=var_g,
        frf_distortion_var=var_gs,
        y_noise_var=y_noise,
        y_distortion_var=y_dist,
        y_excess=y_excess,
        noise_level=noise,
        distortion_level=distortion,
        periods=p,
        realisations=m,
        period_samples=n,
    )


def find_period(x: np.ndarray, *, min_periods: int = 2, rtol: float = 1e-6) -> int | None:
    """The period of a repeated signal [samples], or `None` when it does not repeat.

    The smallest lag `L ≥ 4` with at least `min_periods` whole periods in the record and
    `‖x[L:] − x[:-L]‖² ≤ rtol · ‖x − x̄‖² · (N − L)/N`: the signal repeats exactly up to
    the relative level `rtol` (a commanded excitation repeats to rounding; a measured
    one does not: give the command), after it has first decorrelated (a difference of at
    least half its energy at a shorter lag: a slow signal is close to itself a few
    samples later without repeating). Computed for every lag at once by FFT
    autocorrelation.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    if x.ndim != 1 or n < 8 or not np.all(np.isfinite(x)):
        return None
    xc = x - x.mean()
    energy = float(np.dot(xc, xc))
    if energy <= 0:
        return None
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    f = np.fft.rfft(xc, nfft)
    acf = np.fft.irfft(f * np.conj(f), nfft)[:n]
    c2 = np.concatenate([[0.0], np.cumsum(xc**2)])
    lags = np.arange(1, n // max(min_periods, 1) + 1)
    if lags.size < 4:
        return None
    # ‖x[L:] − x[:-L]‖² = Σ_{i≥L} x² + Σ_{i<N−L} x² − 2 acf(L)
    diff = (c2[n] - c2[lags]) + c2[n - lags] - 2.0 * acf[lags]
    ref = energy * (n - lags) / n
    # a period is a return: the signal must first decorrelate (a slow signal differs little
    # from itself a few samples later without repeating)
    apart = np.flatnonzero(diff >= 0.5 * ref)
    if apart.size == 0:
        return None
    ok = (diff <= rtol * ref) & (lags > lags[apart[0]]) & (lags >= 4)
    return int(lags[np.argmax(ok)]) if ok.any() else None


def settled_periods(y: np.ndarray, period: int, *, factor: float = 2.0) -> int:
    """The number of leading whole periods of `y` that still hold a transient: the
    variance of the difference between consecutive periods,
    `v_p = mean((y_{p+1} − y_p)²)/2`, is the noise's once the response is periodic; the
    leading periods with `v_p` above `factor` times the median of the `v_p` are skipped
    (at least one, when three or more periods are recorded)."""
    y = np.asarray(y, dtype=float)
    p = y.size // period
    if p < 3:
        return 0
    yp = y[: p * period].reshape(p, period)
    v = np.mean(np.diff(yp, axis=0) ** 2, axis=1) / 2.0
    med = float(np.median(v))
    skip = 1
    while skip < p - 2 and v[skip] > factor * med:
        skip += 1
    return skip


def period_noise(
    y: np.ndarray, period: int, *, skip: int | None = None
) -> tuple[float, float, int]:
    """The noise of a periodic response from its period-to-period variation.

    **Arguments:** `y` the record, `period` [samples], `skip` whole periods dropped at the
    start (the transient; `None`: [`settled_periods`][]).

    **Returns:** `(variance, rho, periods)`: the noise variance (sample variance over the
    periods, per sample, averaged), the lag-one autocorrelation of the deviations from
    the mean period (the noise's colour) and the number of periods used.
    """
    y = np.asarray(y, dtype=float)
    if skip is None:
        skip = settled_periods(y, period)
    p = y.size // period - skip
    if p < 2:
        raise ValueError(
            f"period_noise: {y.size} samples hold fewer than 2 periods of {period} after "
            f"skipping {skip}; record more periods."
        )
    yp = y[skip * period : (skip + p) * period].reshape(p, period)
    dev = yp - yp.mean(axis=0)
    var = float(np.sum(dev**2) / ((p - 1) * period))
    d = dev.ravel()
    den = float(np.dot(d, d))
    rho = float(np.dot(d[1:], d[:-1]) / den) if den > 0 else 0.0
    return var, max(min(rho, 0.999), 0.0), p
