"""Resampling of non-uniformly or sparsely sampled measurements onto a uniform time grid.

Design choice: this is host-side I/O preparation (it runs once on raw logs, before a
`jaxvs.data.Record` is built, and its output length depends on the data), so it is
written with NumPy/SciPy and returns NumPy arrays; it is not traced by JAX. Everything
downstream (filtering, differentiation, spectra, calibration) then runs in JAX on the
uniform grid.
"""

import math
from typing import Literal

import numpy as np
import scipy.interpolate as si
from jaxtyping import ArrayLike, Float

from .._misc import check_finite, first_not_increasing
from ._filter import _positive_finite

_METHODS = ("linear", "cubic", "previous")
# Heuristic: grid points within 1e-9·dt of the last sample are kept (round-off in
# t0 + k·dt must not drop the final sample of an already uniform record).
_GRID_RTOL = 1e-9


def _time_vector(t) -> np.ndarray:
    time = np.asarray(t)
    if time.dtype == object or not (
        np.issubdtype(time.dtype, np.floating) or np.issubdtype(time.dtype, np.integer)
    ):
        raise TypeError(f"resample: t must be real numbers [s], got dtype {time.dtype}.")
    time = np.asarray(time, dtype=np.float64)
    if time.ndim != 1:
        raise ValueError(
            f"resample: t must be a 1-D time vector [s], got shape {time.shape}; flatten "
            "column vectors with np.ravel."
        )
    return time


def _check_finite(values: np.ndarray, name: str) -> None:
    fix = (
        "Drop those samples (e.g. keep = np.isfinite(x); resample(t[keep], x[keep])) so that "
        "they are interpolated over."
    )
    check_finite(values, f"resample: {name}", fix)


def _uniform_grid(time: np.ndarray, dt) -> np.ndarray:
    if dt is None:
        dt = float(np.median(np.diff(time)))
    else:
        dt = _positive_finite(dt, "resample: dt", "period", " [s]")
    n = int(math.floor((time[-1] - time[0]) / dt * (1 + _GRID_RTOL) + _GRID_RTOL)) + 1
    return time[0] + dt * np.arange(n)


def resample(
    t: Float[ArrayLike, " time"],
    x: Float[ArrayLike, "*batch time"],
    *,
    dt: float | None = None,
    t_new: Float[ArrayLike, " time_new"] | None = None,
    method: Literal["linear", "cubic", "previous"] = "linear",
    extrapolate: bool = False,
    axis: int = -1,
) -> tuple[Float[np.ndarray, " time_new"], Float[np.ndarray, "*batch time_new"]]:
    """Interpolate samples taken at (non-uniform) times `t` onto a uniform grid.

    The default grid is `t[0] + k·dt` for every `k` with `t[0] + k·dt ≤ t[-1]`, with `dt`
    the median spacing of `t` (robust to a few dropped or doubled samples). Methods:

    - `"linear"`: piecewise-linear interpolation between the two neighbouring samples
        (exact for ramps; error ≤ `h²·max|x''|/8` for spacing `h`).
    - `"cubic"`: not-a-knot cubic spline through all samples (`scipy.interpolate.
        CubicSpline`; exact for cubics, error `O(h⁴·max|x''''|)`), for smooth signals
        sampled sparsely. Needs at least 4 samples for not-a-knot ends (with fewer scipy
        falls back to a lower-degree interpolant).
    - `"previous"`: zero-order hold, the last sample at or before each new time (for
        event logs, set-points and encoder counts that change stepwise).

    Host-side NumPy/SciPy (see the module docstring), not traced by JAX.

    **Arguments:**

    - `t`: strictly increasing sample times [s], shape `(time,)`.
    - `x`: samples, time along `axis` (default last): `(*batch, time)`.
    - `dt`: period of the uniform output grid [s] (default: median of `diff(t)`).
    - `t_new`: explicit output times [s] instead of `dt`, in any order (give either `dt`
        or `t_new`).
    - `method`: `"linear"`, `"cubic"` or `"previous"`.
    - `extrapolate`: if `False` (default) every `t_new` must lie in `[t[0], t[-1]]`; if
        `True`, points outside hold the first/last sample value (constant extrapolation,
        for every method — never polynomial extrapolation, which diverges).
    - `axis`: the time axis of `x`.

    **Returns:**

    `(t_new, x_new)`: the output times [s] (NumPy, `(time_new,)`) and the resampled
    signals (NumPy float64, `x`'s shape with the time axis of length `time_new`).

    **Raises:**

    `ValueError` if `t` is not strictly increasing (naming the first bad index), contains
    NaN/inf, has fewer than 2 samples or another length than `x`'s time axis; if `x` has
    NaN/inf; if `t_new` leaves `[t[0], t[-1]]` without `extrapolate=True`; for both `dt`
    and `t_new`, a non-positive `dt` or an unknown method. `TypeError` for non-numeric or
    complex input.
    """
    if method not in _METHODS:
        raise ValueError(f"resample: method must be one of {_METHODS}, got {method!r}.")
    if dt is not None and t_new is not None:
        raise ValueError("resample: give either dt=... or t_new=..., not both.")
    time = _time_vector(t)
    values = np.asarray(x)
    if np.iscomplexobj(values):
        raise TypeError(
            "resample: x must be real; resample the real and imaginary parts separately."
        )
    if values.dtype == object or not (
        np.issubdtype(values.dtype, np.floating)
        or np.issubdtype(values.dtype, np.integer)
        or np.issubdtype(values.dtype, np.bool_)
    ):
        raise TypeError(f"resample: x must be real numbers, got dtype {values.dtype}.")
    values = np.asarray(values, dtype=np.float64)
    if values.ndim < 1:
        raise ValueError("resample: x must have a time axis; got a scalar.")
    if not -values.ndim <= axis < values.ndim:
        raise ValueError(
            f"resample: axis={axis} is out of range for x with {values.ndim} dimension(s)."
        )
    _check_finite(values, "x")
    values = np.moveaxis(values, axis, -1)
    if time.shape[0] < 2:
        raise ValueError(f"resample: need at least 2 samples to interpolate, got {time.shape[0]}.")
    if values.shape[-1] != time.shape[0]:
        raise ValueError(
            f"resample: t has {time.shape[0]} samples but x has {values.shape[-1]} along "
            f"axis {axis}; pass the time axis of x with axis=..."
        )
    _check_finite(time, "t")
    index = first_not_increasing(time)
    if index is not None:
        raise ValueError(
            f"resample: t is not strictly increasing: t[{index}] = {time[index]!r} <= "
            f"t[{index - 1}] = {time[index - 1]!r}. Sort by time (order = np.argsort(t, "
            "kind='stable')) and drop or average duplicated time stamps first."
        )

    if t_new is None:
        grid = _uniform_grid(time, dt)
    else:
        grid = _time_vector(t_new)
        _check_finite(grid, "t_new")
        outside = (grid < time[0]) | (grid > time[-1])
        if outside.any() and not extrapolate:
            index = int(np.argmax(outside))
            raise ValueError(
                f"resample: t_new[{index}] = {grid[index]!r} s lies outside the data range "
                f"[{time[0]!r}, {time[-1]!r}] s ({int(outside.sum())} point(s) in all). "
                "Restrict t_new to the data range or pass extrapolate=True to hold the end "
                "values."
            )
    inside = np.clip(grid, time[0], time[-1])  # constant extrapolation outside

    if method == "cubic":
        new = si.CubicSpline(time, values, axis=-1, bc_type="not-a-knot")(inside)
    else:
        # Interval index j with time[j] <= τ < time[j+1] (the last sample maps to the last
        # interval, so τ = t[-1] gives x[-1] exactly).
        if method == "previous":
            j = np.searchsorted(time, inside, side="right") - 1
            new = values[..., j]
        else:
            j = np.clip(np.searchsorted(time, inside, side="right") - 1, 0, time.shape[0] - 2)
            weight = (inside - time[j]) / (time[j + 1] - time[j])
            new = values[..., j] * (1 - weight) + values[..., j + 1] * weight
    return grid, np.moveaxis(new, -1, axis)
