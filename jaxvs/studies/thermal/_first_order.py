"""Fits of the thermal study's exponential interpolation model `T0 + k (1 - exp(-t/T1))`.

The model is linear in `(T0, k)` for a fixed `T1`, so the fit is initialised by variable
projection on a logarithmic grid of `T1` (a linear least-squares solve per grid point,
all in one vectorised call) and refined by Levenberg-Marquardt over `(T0, k, log T1)`
(the kernel of `_lm.py`). Piecewise fits run all parts in one `vmap`-ped call (parts of
different lengths are padded and masked); the continuous variant (each part starting
where the previous one ended) refines all parts jointly.
"""

import warnings
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import first_not_increasing
from ...calibration import lm_solve
from ...models import FirstOrder, PiecewiseFirstOrder

__all__ = ["ThermalFitWarning", "fit_first_order", "fit_piecewise_first_order"]

# log-spaced T1 candidates of the variable-projection start, relative to the span
_GRID = np.geomspace(1e-3, 30.0, 64)
# heuristic: a part is "too short for T1" when the fitted T1 exceeds this multiple of its
# time span (the curve is then nearly a straight line: k and T1 trade off) or is below
# this fraction of the sample interval (the transient is over before the second sample)
_T1_OVER_SPAN = 2.0
_T1_UNDER_STEP = 0.5


class ThermalFitWarning(UserWarning):
    """A first-order fit whose parameters are poorly determined by the data."""


def _check_series(t: Any, y: Any, where: str, min_samples: int = 4) -> tuple[np.ndarray, ...]:
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.ndim != 1 or y.shape != t.shape:
        raise ValueError(
            f"{where}: t and y must be 1-D arrays of the same length; got shapes {t.shape} "
            f"and {y.shape}."
        )
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{where}: t has NaN/inf; every sample needs a time stamp [s].")
    bad = ~np.isfinite(y)
    if bad.any():
        raise ValueError(
            f"{where}: the target has {int(bad.sum())} missing (NaN/inf) samples, the first "
            f"at index {int(np.argmax(bad))}. Drop them (keep = np.isfinite(y); "
            f"{where}(t[keep], y[keep])) -- the fit does not need a uniform grid."
        )
    i = first_not_increasing(t)
    if i is not None:
        raise ValueError(
            f"{where}: t is not strictly increasing (t[{i}] = {t[i]} <= t[{i - 1}] = "
            f"{t[i - 1]}); sort the samples by time and drop duplicated time stamps."
        )
    if t.shape[0] < min_samples:
        raise ValueError(
            f"{where}: {t.shape[0]} samples are too few for T0, k and T1; a part needs at "
            f"least {min_samples} samples (better: samples over 2-3 time constants)."
        )
    return t, y


def _residual(theta: Float[Array, "3"], args) -> Float[Array, " n"]:
    tau, y, w = args
    T0, k, logT1 = theta[0], theta[1], theta[2]
    return w * (T0 + k * -jnp.expm1(-tau / jnp.exp(logT1)) - y)


def _lm(fun: Callable, theta0: Array, args: Any, max_steps: int, rtol: float):
    def evaluate(theta, a):
        r = fun(theta, a)
        J = jax.jacfwd(fun)(theta, a)
        return 0.5 * jnp.dot(r, r), J.T @ J, J.T @ r

    feasible = lambda theta: jnp.all(jnp.isfinite(theta))
    return lm_solve(evaluate, theta0, args, max_steps=max_steps, rtol=rtol, feasible=feasible)


def _vp_start(tau, y, w, span):
    """Best `(T0, k, log T1)` over the T1 grid by weighted linear least squares."""

    def one(T1):
        phi = -jnp.expm1(-tau / T1)
        X = jnp.stack([w, w * phi], axis=1)
        coef, _, _, _ = jnp.linalg.lstsq(X, w * y)
        r = X @ coef - w * y
        return jnp.dot(r, r), coef

    grid = jnp.asarray(_GRID, tau.dtype) * span
    ssr, coef = jax.vmap(one)(grid)
    i = jnp.argmin(jnp.where(jnp.isfinite(ssr), ssr, jnp.inf))
    return jnp.stack([coef[i, 0], coef[i, 1], jnp.log(grid[i])])


def _fit_one_impl(tau, y, w, span, max_steps: int, rtol: float):
    theta0 = _vp_start(tau, y, w, span)
    state = _lm(_residual, theta0, (tau, y, w), max_steps, rtol)
    return state.theta, state.converged


_fit_one = eqx.filter_jit(_fit_one_impl)
_fit_many = eqx.filter_jit(eqx.filter_vmap(_fit_one_impl, in_axes=(0, 0, 0, 0, None, None)))


def _warn_identifiability(T1: np.ndarray, span: np.ndarray, step: np.ndarray, where: str):
    for i, (T1_i, s_i, h_i) in enumerate(zip(T1, span, step)):
        label = f" (part {i})" if T1.shape[0] > 1 else ""
        if T1_i > _T1_OVER_SPAN * s_i:
            warnings.warn(
                f"{where}{label}: the part is too short for its time constant: T1 = "
                f"{T1_i:.4g} s exceeds {_T1_OVER_SPAN:g}x the part's span {s_i:.4g} s, so k "
                "and T1 are poorly determined (only their ratio, the initial slope, is). "
                "Use a longer part, or fix T1 from a longer experiment.",
                ThermalFitWarning,
                stacklevel=3,
            )
        elif T1_i < _T1_UNDER_STEP * h_i:
            warnings.warn(
                f"{where}{label}: T1 = {T1_i:.4g} s is shorter than the sample interval "
                f"({h_i:.4g} s): the transient is over before the second sample, so T1 is "
                "not determined. Sample faster at the start of the part.",
                ThermalFitWarning,
                stacklevel=3,
            )


def fit_first_order(
    t: Float[ArrayLike, " time"],
    y: Float[ArrayLike, " time"],
    *,
    t_start: float | None = None,
    max_steps: int = 200,
    rtol: float = 1e-10,
) -> FirstOrder:
    """Fit the study's interpolation model `T(t) = T0 + k (1 - exp(-t/T1))` (eq. 1).

    **Arguments:**

    - `t`: `(time,)` sample times [s], strictly increasing (need not be uniform, e.g.
      measurements every ~90 s during short spindle stops).
    - `y`: `(time,)` measured temperatures [°C].
    - `t_start`: start of the part [s], where `T(t_start) = T0` (default `t[0]`).
    - `max_steps`, `rtol`: Levenberg-Marquardt budget and relative tolerance.

    **Returns:**

    A [`jaxvs.models.FirstOrder`][] with fields `T0` [°C], `k` [K], `T1` [s], in the
    part's local time: evaluate it at `t - t_start`.

    **Raises / warns:**

    `ValueError` for non-monotonic time, NaN/missing samples, length mismatch or fewer
    than 4 samples; `ThermalFitWarning` when the part is too short for its time constant
    (fitted `T1` above twice the part's span) or `T1` is below half the sample interval.
    """
    t, y = _check_series(t, y, "fit_first_order")
    t0 = float(t[0]) if t_start is None else float(t_start)
    if t0 > t[0]:
        raise ValueError(f"fit_first_order: t_start = {t0} is after the first sample {t[0]}.")
    tau = jnp.asarray(t - t0)
    span = float(t[-1] - t0)
    theta, _ = _fit_one(tau, jnp.asarray(y), jnp.ones_like(tau), span, max_steps, rtol)
    theta = np.asarray(theta)
    T1 = float(np.exp(theta[2]))
    _warn_identifiability(
        np.array([T1]), np.array([span]), np.array([np.min(np.diff(t))]), "fit_first_order"
    )
    return FirstOrder(theta[0], theta[1], T1)


def _pad_parts(t, y, starts):
    edges = np.append(starts, np.inf)
    idx = [np.flatnonzero((t >= edges[i]) & (t < edges[i + 1])) for i in range(len(starts))]
    for i, ix in enumerate(idx):
        if ix.size < 4:
            raise ValueError(
                f"fit_piecewise_first_order: part {i} (from t = {starts[i]} s) has "
                f"{ix.size} samples; every part needs at least 4 samples for T0, k and T1 "
                "(merge short parts or drop their start)."
            )
    m = max(ix.size for ix in idx)
    tau = np.zeros((len(starts), m))
    yy = np.zeros((len(starts), m))
    w = np.zeros((len(starts), m))
    for i, ix in enumerate(idx):
        n = ix.size
        tau[i, :n] = t[ix] - starts[i]
        tau[i, n:] = tau[i, n - 1]
        yy[i, :n] = y[ix]
        yy[i, n:] = y[ix][-1]
        w[i, :n] = 1.0
    return idx, tau, yy, w


def _piecewise_residual(theta, args):
    starts, t, y = args
    p = starts.shape[0]
    model = PiecewiseFirstOrder(
        starts,
        jnp.full((p,), theta[0]),
        theta[1 : 1 + p],
        jnp.exp(theta[1 + p :]),
        continuous=True,
    )
    return model(t) - y


@eqx.filter_jit
def _fit_continuous(theta0, starts, t, y, max_steps: int, rtol: float):
    return _lm(_piecewise_residual, theta0, (starts, t, y), max_steps, rtol).theta


def fit_piecewise_first_order(
    t: Float[ArrayLike, " time"],
    y: Float[ArrayLike, " time"],
    starts: Float[ArrayLike, " parts"],
    *,
    continuous: bool = False,
    max_steps: int = 200,
    rtol: float = 1e-10,
) -> PiecewiseFirstOrder:
    """Fit one first-order law per experiment part (operating point) in one call.

    **Arguments:**

    - `t`, `y`: `(time,)` sample times [s] (strictly increasing) and temperatures [°C].
    - `starts`: `(parts,)` start time of each part [s] (e.g. the times where the motor
      speed changes; `Record.metadata["part_start_times"]` of the spindle twin). Samples
      before `starts[0]` are not allowed.
    - `continuous`: `False`: independent parts with their own `T0` (jumps allowed, the
      study's Table 3); `True`: each part starts where the previous one ended (one joint
      fit of `T0` of the first part and `k`, `T1` of every part).
    - `max_steps`, `rtol`: Levenberg-Marquardt budget and relative tolerance.

    **Returns:**

    A [`jaxvs.models.PiecewiseFirstOrder`][] evaluated at absolute times.

    **Raises / warns:** as [`fit_first_order`][], per part; `ValueError` when a part has
    fewer than 4 samples or `starts` is not increasing.
    """
    t, y = _check_series(t, y, "fit_piecewise_first_order")
    starts = np.atleast_1d(np.asarray(starts, dtype=float))
    if starts.ndim != 1 or np.any(np.diff(starts) <= 0) or not np.all(np.isfinite(starts)):
        raise ValueError(
            "fit_piecewise_first_order: starts must be a 1-D increasing array of part start "
            f"times [s]; got {starts}."
        )
    if t[0] < starts[0]:
        raise ValueError(
            f"fit_piecewise_first_order: the first sample (t = {t[0]} s) is before the first "
            f"part start ({starts[0]} s); drop those samples or start the first part earlier."
        )
    idx, tau, yy, w = _pad_parts(t, y, starts)
    span = np.array([(t[ix[-1]] - s) for ix, s in zip(idx, starts)])
    spans = np.maximum(span, np.diff(np.append(starts, t[-1]))[: len(starts)])
    theta, _ = _fit_many(
        jnp.asarray(tau), jnp.asarray(yy), jnp.asarray(w), jnp.asarray(spans), max_steps, rtol
    )
    theta = np.asarray(theta)
    if continuous:
        p = len(starts)
        theta0 = jnp.asarray(np.concatenate([[theta[0, 0]], theta[:, 1], theta[:, 2]]))
        th = np.asarray(
            _fit_continuous(
                theta0, jnp.asarray(starts), jnp.asarray(t), jnp.asarray(y), max_steps, rtol
            )
        )
        T0 = np.full(p, th[0])
        k, T1 = th[1 : 1 + p], np.exp(th[1 + p :])
    else:
        T0, k, T1 = theta[:, 0], theta[:, 1], np.exp(theta[:, 2])
    steps = np.array([np.min(np.diff(t[ix])) for ix in idx])
    _warn_identifiability(T1, spans, steps, "fit_piecewise_first_order")
    model = PiecewiseFirstOrder(starts, T0, k, T1, continuous=continuous)
    if continuous:
        model = eqx.tree_at(lambda m: m.T0, model, model.start_values)
    return model
