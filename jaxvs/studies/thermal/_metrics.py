"""Validation of virtual sensors: RMSE, R², MAPD, the 70/30 contiguous split, residual
analysis (Dementjev et al. 2014, §3.3.4 and Fig. 10).

Host-side evaluation (NumPy/SciPy): these run once per trained model on its predictions.
"""

import math
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import scipy.stats as st
from jaxtyping import ArrayLike, Float

from ...data import Record, split_blocks

__all__ = [
    "NoOperatingPointChangeWarning",
    "ResidualAnalysis",
    "mapd",
    "r2",
    "residual_analysis",
    "rmse",
    "split_train_test",
    "vs_metrics",
]


class NoOperatingPointChangeWarning(UserWarning):
    """The test block holds a single operating point: it cannot show how a model handles
    operating-point changes (the study notes its test set had none, §4)."""


class ExtrapolationWarning(UserWarning):
    """The test block leaves the range of the training block: data-driven models
    (networks in particular) extrapolate there, and the test figures judge that
    extrapolation rather than the model's fit."""


def _pair(y, y_hat, where: str) -> tuple[np.ndarray, np.ndarray]:
    y = np.asarray(y, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y.shape != y_hat.shape or y.ndim != 1 or y.size == 0:
        raise ValueError(
            f"{where}: measured and predicted values must be 1-D arrays of the same length; "
            f"got {y.shape} and {y_hat.shape}."
        )
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(y_hat))):
        raise ValueError(f"{where}: NaN/inf in the measured or predicted values; drop them.")
    return y, y_hat


def rmse(y: Float[ArrayLike, " n"], y_hat: Float[ArrayLike, " n"]) -> float:
    """Root mean square error `sqrt(mean((y - ŷ)²))` [target unit]."""
    y, y_hat = _pair(y, y_hat, "rmse")
    return float(np.sqrt(np.mean((y - y_hat) ** 2)))


def r2(y: Float[ArrayLike, " n"], y_hat: Float[ArrayLike, " n"]) -> float:
    """Coefficient of determination `1 - Σ(y - ŷ)² / Σ(y - ȳ)²` [-]."""
    y, y_hat = _pair(y, y_hat, "r2")
    sst = np.sum((y - y.mean()) ** 2)
    if sst == 0:
        raise ValueError("r2: the measured values are constant, so R² is undefined.")
    return float(1.0 - np.sum((y - y_hat) ** 2) / sst)


def mapd(y: Float[ArrayLike, " n"], y_hat: Float[ArrayLike, " n"]) -> float:
    """Mean absolute percentage deviation `100 · mean(|y - ŷ| / |y|)` [%].

    Note: relative to the target's value, so it depends on the temperature scale's
    zero (°C in the study)."""
    y, y_hat = _pair(y, y_hat, "mapd")
    if np.any(y == 0):
        raise ValueError("mapd: a measured value is 0, where the percentage is undefined.")
    return float(100.0 * np.mean(np.abs(y - y_hat) / np.abs(y)))


def vs_metrics(y: Float[ArrayLike, " n"], y_hat: Float[ArrayLike, " n"]) -> dict[str, float]:
    """The study's three figures of merit (Table 4): `{"R2", "RMSE", "MAPD"}`."""
    return {"R2": r2(y, y_hat), "RMSE": rmse(y, y_hat), "MAPD": mapd(y, y_hat)}


def split_train_test(
    record: Record,
    fraction: float = 0.7,
    *,
    operating_point: str | None = "v_m",
    min_change: float = 0.05,
    inputs: Sequence[str] | None = None,
    max_extrapolation: float = 0.05,
) -> tuple[Record, Record]:
    """The study's cross-validation split: the first `fraction` of the record (training
    and validation) and the rest (test), as contiguous blocks.

    **Arguments:**

    - `record`: one experiment.
    - `fraction`: share of the first block (the study: about 0.7).
    - `operating_point`: the signal that defines the operating point (motor speed); `None`
      skips the check.
    - `min_change`: a change of the operating point counts when the signal's range in the
      test block exceeds this fraction of its range over the whole record.
    - `inputs`: the model inputs to check for extrapolation (default: the operating point
      only); `max_extrapolation`: the share of a signal's training range by which the test
      block may leave it.

    **Returns:** `(train, test)` Records.

    **Warns:** [`NoOperatingPointChangeWarning`][] when the test block has no operating-point
    change (its figures then say little about dynamic behaviour);
    [`ExtrapolationWarning`][] when a checked input leaves its training range in the test
    block by more than `max_extrapolation` (the figures then judge extrapolation).
    """
    if not 0 < fraction < 1:
        raise ValueError(f"split_train_test: fraction must lie in (0, 1); got {fraction}.")
    train, test = split_blocks(record, (fraction, 1.0 - fraction))
    if operating_point is not None:
        if operating_point not in record:
            raise ValueError(
                f"split_train_test: the record has no signal {operating_point!r} "
                f"(it has {list(record.names)}); pass operating_point=None to skip the check."
            )
        full = np.ptp(record[operating_point])
        part = np.ptp(test[operating_point])
        if full == 0 or part <= min_change * full:
            warnings.warn(
                f"split_train_test: the test block (last {100 * (1 - fraction):.0f} %) has no "
                f"change of the operating point {operating_point!r}: its errors show only "
                "steady behaviour and may look better than the training errors (the study's "
                "Table 4 has this artefact). Choose a split point before a change, or test "
                "on another experiment.",
                NoOperatingPointChangeWarning,
                stacklevel=2,
            )
    checked = (
        list(inputs) if inputs is not None else [operating_point] * (operating_point is not None)
    )
    outside = []
    for name in checked:
        if name not in record:
            raise ValueError(
                f"split_train_test: the record has no input {name!r} (it has {list(record.names)})."
            )
        lo, hi = float(np.min(train[name])), float(np.max(train[name]))
        t_lo, t_hi = float(np.min(test[name])), float(np.max(test[name]))
        beyond = max(lo - t_lo, t_hi - hi, 0.0)
        if beyond > max_extrapolation * (hi - lo):
            share = (
                f"{100 * beyond / (hi - lo):.0f} % of its range"
                if hi > lo
                else "a single value in training"
            )
            outside.append(
                f"{name} reaches [{t_lo:.4g}, {t_hi:.4g}] against [{lo:.4g}, {hi:.4g}] in "
                f"training ({share})"
            )
    if outside:
        warnings.warn(
            "split_train_test: the test block leaves the training range: "
            + "; ".join(outside)
            + ". Networks extrapolate there (tanh units saturate), so their test errors "
            "judge extrapolation. Move the split, train on a record that covers these "
            "operating points, or test on another experiment.",
            ExtrapolationWarning,
            stacklevel=2,
        )
    return train, test


class ResidualAnalysis(NamedTuple):
    """Residual analysis of a virtual sensor (study Fig. 10).

    - `lags`: `(lag,)` lags 0..max_lag [samples]; `acf`: autocorrelation at those lags.
    - `bound`: `z_{1-α/2}/sqrt(N)`, the white-noise confidence bound of the ACF.
    - `fraction_outside`: share of lags ≥ 1 whose |ACF| exceeds `bound` (≈ 1 - confidence
      for white residuals).
    - `ljung_box`, `ljung_box_pvalue`: Ljung-Box portmanteau statistic over the lags and
      its p-value (small: the residuals are correlated, the model misses dynamics).
    - `normality`, `normality_pvalue`: D'Agostino-Pearson K² statistic and p-value (small:
      the residuals are not normal).
    - `mean`, `std`: of the residuals.
    - `confidence`: the level of `bound`.
    """

    lags: np.ndarray
    acf: np.ndarray
    bound: float
    fraction_outside: float
    ljung_box: float
    ljung_box_pvalue: float
    normality: float
    normality_pvalue: float
    mean: float
    std: float
    confidence: float

    @property
    def white(self) -> bool:
        """Whether the residuals pass the Ljung-Box test at the 1 - confidence level."""
        return self.ljung_box_pvalue > 1 - self.confidence


def residual_analysis(
    residuals: Float[ArrayLike, " n"],
    *,
    max_lag: int | None = None,
    confidence: float = 0.95,
) -> ResidualAnalysis:
    """Autocorrelation with confidence bounds, Ljung-Box whiteness and D'Agostino-Pearson
    normality tests of model residuals.

    **Arguments:**

    - `residuals`: `(n,)` measured minus predicted values (uniform sampling).
    - `max_lag`: largest lag [samples] (default `min(50, n // 4)`).
    - `confidence`: level of the ACF bounds and of the tests.

    **Returns:** a [`ResidualAnalysis`][].
    """
    e = np.asarray(residuals, dtype=float)
    if e.ndim != 1 or e.size < 20:
        raise ValueError(
            f"residual_analysis: need a 1-D residual series of at least 20 samples; got "
            f"shape {e.shape}."
        )
    if not np.all(np.isfinite(e)):
        raise ValueError("residual_analysis: the residuals have NaN/inf; drop them first.")
    if not 0 < confidence < 1:
        raise ValueError(f"residual_analysis: confidence must lie in (0, 1); got {confidence}.")
    n = e.size
    max_lag = min(50, n // 4) if max_lag is None else int(max_lag)
    if not 1 <= max_lag < n:
        raise ValueError(f"residual_analysis: max_lag must lie in [1, {n - 1}]; got {max_lag}.")
    c = e - e.mean()
    var = np.dot(c, c) / n
    if var == 0:
        raise ValueError("residual_analysis: the residuals are constant; nothing to analyse.")
    # biased ACF estimator (Box & Jenkins), via FFT
    m = 1 << int(math.ceil(math.log2(2 * n)))
    f = np.fft.rfft(c, m)
    acov = np.fft.irfft(f * np.conj(f), m)[: max_lag + 1] / n
    acf = acov / var
    z = st.norm.ppf(0.5 + confidence / 2)
    bound = float(z / math.sqrt(n))
    lags = np.arange(max_lag + 1)
    outside = float(np.mean(np.abs(acf[1:]) > bound))
    q = float(n * (n + 2) * np.sum(acf[1:] ** 2 / (n - lags[1:])))
    q_p = float(st.chi2.sf(q, max_lag))
    k2, k2_p = st.normaltest(e)
    return ResidualAnalysis(
        lags=lags,
        acf=acf,
        bound=bound,
        fraction_outside=outside,
        ljung_box=q,
        ljung_box_pvalue=q_p,
        normality=float(k2),
        normality_pvalue=float(k2_p),
        mean=float(e.mean()),
        std=float(e.std(ddof=1)),
        confidence=float(confidence),
    )
