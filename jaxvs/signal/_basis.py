"""Bases of flexible functions that are linear in their coefficients.

- [`quantile_knots`][]: a clamped knot vector whose interior knots sit at quantiles of
  the data, so every basis function carries about the same number of samples.
- [`bspline_basis`][]: the B-spline basis of a degree on a knot vector, evaluated by the
  Cox–de Boor recursion (de Boor 1978, *A Practical Guide to Splines*, ch. IX); values
  outside the knot range are clamped to it (constant extrapolation).
- [`difference_penalty`][]: the difference matrix of P-splines (Eilers & Marx 1996,
  *Statistical Science* 11(2)): `λ‖D c‖²` penalises the roughness of the coefficients.
- [`rbf_basis`][]: Gaussian radial basis functions on given centres.

All functions are pure JAX (jit-, vmap- and grad-able in `x`) except `quantile_knots`,
which looks at the data once (NumPy).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = ["bspline_basis", "difference_penalty", "quantile_knots", "rbf_basis"]


def quantile_knots(x, n_basis: int, degree: int = 3) -> np.ndarray:
    """A clamped knot vector for `n_basis` B-splines of `degree` over the range of `x`.

    The `n_basis − degree − 1` interior knots sit at equally spaced quantiles of `x`
    (repeated values are merged, so a variable with few distinct values gets fewer
    knots); the two end knots are repeated `degree + 1` times.

    **Returns:** the knot vector `(n_basis + degree + 1,)` (fewer when quantiles merge).
    """
    x = np.asarray(x, float).ravel()
    x = x[np.isfinite(x)]
    if x.size < 2 or float(np.ptp(x)) == 0.0:
        raise ValueError(
            "quantile_knots: x must hold at least two distinct finite values; got "
            f"{x.size} finite value(s) with range {float(np.ptp(x)) if x.size else 0.0}."
        )
    if n_basis < degree + 1:
        raise ValueError(
            f"quantile_knots: n_basis={n_basis} must be at least degree + 1 = {degree + 1}."
        )
    lo, hi = float(x.min()), float(x.max())
    n_inner = n_basis - degree - 1
    inner = np.quantile(x, np.linspace(0, 1, n_inner + 2)[1:-1]) if n_inner else np.zeros(0)
    inner = np.unique(inner[(inner > lo) & (inner < hi)])
    # merge knots closer than 1e-6 of the range (ties of a quantised variable)
    if inner.size > 1:
        keep = np.concatenate([[True], np.diff(inner) > 1e-6 * (hi - lo)])
        inner = inner[keep]
    return np.concatenate([np.full(degree + 1, lo), inner, np.full(degree + 1, hi)])


def bspline_basis(
    x: Float[Array, " n"], knots: Float[Array, " m"], degree: int = 3
) -> Float[Array, "n k"]:
    """B-spline basis functions of `degree` on the clamped knot vector `knots` at `x`.

    Returns `(n, m − degree − 1)`; the rows sum to one (partition of unity) and every
    function is non-negative. `x` outside `[knots[0], knots[-1]]` is clamped to the range.
    """
    t = jnp.asarray(knots)
    x = jnp.clip(jnp.asarray(x), t[0], t[-1])
    n_int = t.shape[0] - 1
    # degree 0: indicator of [t_i, t_{i+1}); the last non-empty interval is closed on the
    # right so that x = t[-1] belongs to it
    last = jnp.max(jnp.where(t[1:] > t[:-1], jnp.arange(n_int), -1))
    xi = x[:, None]
    b = ((xi >= t[None, :-1]) & (xi < t[None, 1:])).astype(x.dtype)
    at_end = (x >= t[-1])[:, None] & (jnp.arange(n_int) == last)[None, :]
    b = jnp.where(at_end, 1.0, b)
    for k in range(1, degree + 1):
        left_den = t[k:-1] - t[: -k - 1]
        right_den = t[k + 1 :] - t[1:-k]
        left = jnp.where(
            left_den > 0, (xi - t[None, : -k - 1]) / jnp.where(left_den > 0, left_den, 1.0), 0.0
        )
        right = jnp.where(
            right_den > 0, (t[None, k + 1 :] - xi) / jnp.where(right_den > 0, right_den, 1.0), 0.0
        )
        b = left * b[:, :-1] + right * b[:, 1:]
    return b


def difference_penalty(k: int, order: int = 2) -> np.ndarray:
    """The `(k − order, k)` matrix of `order`-th differences of `k` coefficients (the
    P-spline roughness penalty `‖D c‖²`; a polynomial of degree `< order` in the
    coefficients is not penalised)."""
    if not 0 <= order < k:
        raise ValueError(f"difference_penalty: need 0 <= order < k; got order={order}, k={k}.")
    return np.diff(np.eye(k), n=order, axis=0)


def rbf_basis(
    x: Float[Array, " n"], centres: Float[Array, " k"], width: float | Array
) -> Float[Array, "n k"]:
    """Gaussian radial basis functions `exp(−((x − c_j)/width)²/2)` at `x`."""
    z = (jnp.asarray(x)[:, None] - jnp.asarray(centres)[None, :]) / width
    return jnp.exp(-0.5 * z * z)
