"""Honest scoring of designs on held-out data: RMSE / R² / MAPD with moving-block
bootstrap intervals (residuals of virtual sensors are autocorrelated, so samples are
resampled in contiguous blocks; Künsch 1989, Ann. Statist. 17(3)), residual whiteness
(Ljung-Box) and residual-input cross-correlation, and a ranking in which a more complex
design is placed above a simpler one only when its held-out gain is significant. The
bootstrap itself is `jaxvs.signal.block_bootstrap_means`.
"""

from __future__ import annotations

import math

import numpy as np

from ..thermal import residual_analysis

__all__ = ["rank_designs", "residual_checks"]


def residual_checks(e: np.ndarray, inputs: dict[str, np.ndarray], max_lag: int = 20) -> dict:
    """Whiteness (Ljung-Box p-value, share of ACF lags outside the bound) of held-out
    residuals `e`, and for every candidate input the largest |cross-correlation| between
    the residuals and the input at lags 0..`max_lag` (input leading), against the
    white-noise bound `1.96/√n`: a large value says the input still explains part of the
    error (a missing input or delay)."""
    n = e.size
    out: dict = {"white": None, "ljung_box_pvalue": None, "acf_outside": None}
    if n >= 20 and np.ptp(e) > 0:
        ra = residual_analysis(e, max_lag=min(max_lag, n // 4))
        out.update(
            white=bool(ra.white),
            ljung_box_pvalue=float(ra.ljung_box_pvalue),
            acf_outside=float(ra.fraction_outside),
        )
    c = e - e.mean()
    sc = np.sqrt(np.dot(c, c))
    xc = {}
    for name, u in inputs.items():
        v = u - u.mean()
        sv = np.sqrt(np.dot(v, v))
        if sc == 0 or sv == 0:
            xc[name] = None
            continue
        lags = range(0, min(max_lag, n - 2) + 1)
        xc[name] = float(max(abs(np.dot(c[lag:], v[: n - lag])) / (sc * sv) for lag in lags))
    out["input_xcorr"] = xc
    out["xcorr_bound"] = 1.96 / math.sqrt(max(n, 1))
    return out


def rank_designs(
    rmse: np.ndarray, params: np.ndarray, reps: np.ndarray, level: float = 0.95
) -> tuple[list[int], dict[int, int | None]]:
    """Rank designs: lowest held-out RMSE first, except that a design is preferred to a
    more complex one (more parameters) whose held-out gain over it is not significant.

    Significance: the complex design `c` beats the simpler `s` when `mse_c < mse_s` in at
    least `level` of the paired block-bootstrap replicates `reps` (a one-sided paired
    test). Greedy: the next rank goes to the lowest-RMSE remaining design, replaced by the
    best remaining simpler design it does not significantly beat, repeatedly.

    **Returns:** `(order, preferred_over)`: indices best first, and for each design that
    was moved above a lower-RMSE one, that design's index (else `None`).
    """
    remaining = [i for i in range(len(rmse)) if np.isfinite(rmse[i])]
    order: list[int] = []
    over: dict[int, int | None] = {}
    while remaining:
        rem = np.asarray(remaining)
        c = int(rem[np.argmin(rmse[rem])])
        first = c
        while True:
            simpler = rem[params[rem] < params[c]]
            if simpler.size == 0:
                break
            wins = np.mean(reps[c][None, :] < reps[simpler], axis=1)
            equal = simpler[wins < level]
            if equal.size == 0:
                break
            c = int(equal[np.argmin(rmse[equal])])
        over[c] = first if c != first else None
        order.append(c)
        remaining.remove(c)
    return order, over
