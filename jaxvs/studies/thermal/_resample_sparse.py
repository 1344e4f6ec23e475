"""Resampling of sparse target measurements onto the inputs' uniform grid, with outlier
detection and correction.

The thermal study measures the inner bearing temperature only about every 90 s, during
short spindle stops, and resamples it to the 5 s grid of the inputs "through the fitted
exponential models" (§3.3.1, Fig. 4): one first-order law `T0 + k (1 - exp(-t/T1))` per
experiment part, evaluated on the grid. Linear and spline interpolation are offered for
comparison. Outliers are found robustly against the fitted laws (median absolute
deviation) and replaced by the refitted law's value ("the present outliers were
corrected").

It lives in `calibration` (not `signal`) because the exponential method is a fit.
"""

import warnings
from typing import Literal

import numpy as np
import scipy.interpolate as si
from jaxtyping import ArrayLike, Float

from ...models import PiecewiseFirstOrder
from ._first_order import ThermalFitWarning, _check_series, fit_piecewise_first_order

__all__ = ["correct_outliers", "detect_outliers", "resample_sparse"]

_METHODS = ("exponential", "linear", "spline")
# MAD -> standard deviation for normal data
_MAD_TO_SIGMA = 1.4826


def _starts(t: np.ndarray, part_starts) -> np.ndarray:
    if part_starts is None:
        return np.array([t[0]])
    s = np.atleast_1d(np.asarray(part_starts, dtype=float))
    return s


def _parts_of(t: np.ndarray, starts: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)


def _merge_short_parts(t: np.ndarray, starts: np.ndarray, min_samples: int = 4) -> np.ndarray:
    """Merge parts with fewer than `min_samples` measurements into their predecessor (the
    first part into its successor), e.g. a part cut short by the end of the record."""
    starts = np.asarray(starts, dtype=float)
    while len(starts) > 1:
        counts = np.bincount(_parts_of(t, starts), minlength=len(starts))
        counts[0] += int(np.sum(t < starts[0]))
        short = np.flatnonzero(counts < min_samples)
        if short.size == 0:
            break
        i = int(short[0])
        warnings.warn(
            f"resample_sparse: part {i} (from t = {starts[i]} s) has {counts[i]} measurements, "
            f"too few for a first-order law; it is merged with its "
            f"{'successor' if i == 0 else 'predecessor'}.",
            ThermalFitWarning,
            stacklevel=3,
        )
        starts = np.delete(starts, 1 if i == 0 else i)
    return starts


def resample_sparse(
    t_sparse: Float[ArrayLike, " sample"],
    y_sparse: Float[ArrayLike, " sample"],
    t_grid: Float[ArrayLike, " time"],
    *,
    method: Literal["exponential", "linear", "spline"] = "exponential",
    part_starts: Float[ArrayLike, " parts"] | None = None,
    continuous: bool = False,
) -> tuple[np.ndarray, PiecewiseFirstOrder | None]:
    """Values of a sparsely measured signal on a uniform grid.

    **Arguments:**

    - `t_sparse`, `y_sparse`: `(sample,)` measurement times [s] (strictly increasing) and
      values (e.g. the inner bearing temperature every ~90 s).
    - `t_grid`: `(time,)` the target grid [s] (e.g. `record.t`).
    - `method`: `"exponential"` (the study: one first-order law per part, fitted by
      [`fit_piecewise_first_order`][]), `"linear"` or `"spline"` (cubic, per part, so
      that it does not ring across the jumps between parts).
    - `part_starts`: `(parts,)` start times of the experiment parts [s] (where the
      operating point changes); default: one part. The first start must not be after
      the first sample.
    - `continuous`: exponential method only: parts chained continuously.

    **Returns:**

    `(y_grid, model)`: `(time,)` resampled values and the fitted
    [`jaxvs.models.PiecewiseFirstOrder`][] (`None` for linear/spline). Outside the
    measured span, linear and spline hold the end values; the exponential law
    extrapolates along its curve.
    """
    if method not in _METHODS:
        raise ValueError(f"resample_sparse: method must be one of {_METHODS}; got {method!r}.")
    t, y = _check_series(t_sparse, y_sparse, "resample_sparse", min_samples=2)
    grid = np.asarray(t_grid, dtype=float)
    if grid.ndim != 1 or not np.all(np.isfinite(grid)):
        raise ValueError("resample_sparse: t_grid must be a finite 1-D time vector [s].")
    starts = _starts(t, part_starts)
    if method == "exponential":
        if part_starts is None:
            starts = np.array([min(t[0], grid[0])])
        starts = _merge_short_parts(t, starts)
        model = fit_piecewise_first_order(t, y, starts, continuous=continuous)
        return np.asarray(model(grid)), model
    out = np.empty_like(grid)
    part_t, part_g = _parts_of(t, starts), _parts_of(grid, starts)
    for p in range(len(starts)):
        ts, ys = t[part_t == p], y[part_t == p]
        g = part_g == p
        if not g.any():
            continue
        if ts.size == 0:
            raise ValueError(
                f"resample_sparse: part {p} (from {starts[p]} s) has no measurement; merge "
                "it with its neighbour or measure it."
            )
        if method == "linear" or ts.size < 4:
            out[g] = np.interp(grid[g], ts, ys)
        else:
            spline = si.CubicSpline(ts, ys, bc_type="natural", extrapolate=False)
            v = spline(grid[g])
            v = np.where(grid[g] < ts[0], ys[0], v)
            out[g] = np.where(grid[g] > ts[-1], ys[-1], v)
    return out, None


def detect_outliers(
    t: Float[ArrayLike, " sample"],
    y: Float[ArrayLike, " sample"],
    *,
    part_starts: Float[ArrayLike, " parts"] | None = None,
    threshold: float = 4.0,
    iterations: int = 3,
) -> np.ndarray:
    """Outliers of sparse measurements against per-part first-order laws.

    Fits the laws, estimates the noise robustly as `1.4826 · MAD` of the residuals, flags
    `|residual| > threshold · σ`, refits without the flagged samples and repeats.

    **Arguments:**

    - `t`, `y`: `(sample,)` times [s] and values.
    - `part_starts`: start times of the parts [s] (default one part from `t[0]`).
    - `threshold`: in robust standard deviations (4: about 1 false alarm in 16 000
      normal samples).
    - `iterations`: fit-flag rounds.

    **Returns:** `(sample,)` bool mask, `True` for outliers.
    """
    t, y = _check_series(t, y, "detect_outliers")
    starts = _starts(t, part_starts)
    bad = np.zeros(t.shape, bool)
    for _ in range(iterations):
        keep = ~bad
        model = fit_piecewise_first_order(t[keep], y[keep], starts)
        r = y - np.asarray(model(t))
        med = np.median(r[keep])
        sigma = _MAD_TO_SIGMA * np.median(np.abs(r[keep] - med))
        if sigma == 0:
            break
        new = np.abs(r - med) > threshold * sigma
        if np.array_equal(new, bad):
            break
        bad = new
    return bad


def correct_outliers(
    t: Float[ArrayLike, " sample"],
    y: Float[ArrayLike, " sample"],
    outliers: ArrayLike,
    *,
    part_starts: Float[ArrayLike, " parts"] | None = None,
) -> np.ndarray:
    """`y` with the flagged samples replaced by the first-order laws refitted without them.

    **Arguments:** `t`, `y` as [`detect_outliers`][]; `outliers`: `(sample,)` bool mask
    (e.g. from [`detect_outliers`][]); `part_starts` as there.

    **Returns:** a corrected copy of `y` (the input is never modified).
    """
    t, y = _check_series(t, y, "correct_outliers")
    bad = np.asarray(outliers, dtype=bool)
    if bad.shape != t.shape:
        raise ValueError(f"correct_outliers: the mask has shape {bad.shape}, need {t.shape}.")
    out = y.copy()
    if bad.any():
        model = fit_piecewise_first_order(t[~bad], y[~bad], _starts(t, part_starts))
        out[bad] = np.asarray(model(t[bad]))
    return out
