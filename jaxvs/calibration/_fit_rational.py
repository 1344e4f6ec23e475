"""`fit_rational`: frequency-domain fit of rational transfer / transmissibility functions."""

import functools
import math
import operator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._misc import check_finite, concrete, require_x64
from ..models import RationalTF
from . import _lm, _sk
from ._lm import batched_while
from ._results import RESULTS, describe

# Heuristic: a unit-diagonal-scaled JᵀJ with condition number above 1e13 (float64 keeps
# ~16 digits, the inverse then has at most ~3) is treated as singular.
_SINGULAR_COND = 1e13
# Heuristic: Sanathanan-Koerner stops at a relative change of the denominator of 1e-3;
# it only has to reach the basin of the optimum, which Levenberg-Marquardt then polishes
# (same success on 2048 benchmark systems as with 1e-8, two iterations fewer on average).
_SK_TOL = 1e-3
# Heuristic work schedule of `batched_while` (tuned on 256 order-6 fits of 2000 points):
# blocks of 16 members (their per-iteration rows, 16 x 8 x n_freq doubles, stay in the CPU
# caches); a first sweep of 3 SK / 1 LM iterations per block (most members need 3-4 and
# 1), then blocks of the 4 first still-running members, 2 iterations at a time, so that
# the few slow members do not make whole blocks iterate.
_BLOCK = 16
_SK_FIRST = 3
_LM_FIRST = 1
_TAIL_BLOCK = 4
_BLOCK_STEPS = 2
# Heuristic: initial Levenberg-Marquardt damping relative to the unit-diagonal scaled
# JᵀJ; small, as the Sanathanan-Koerner start is usually in the quadratic basin (the
# gain-ratio update raises it within a few rejected steps when it is not).
_MU0 = 1e-6


class FitReport(eqx.Module):
    """What [`fit_rational`][] found, for one fit or (with leading axes) a family of fits.

    The parameter vector is `θ = (num[0], …, num[nb], den[1], …, den[na])`: the free
    coefficients of the returned `RationalTF`, highest power first (`den[0] = 1` is fixed).

    **Fields:**

    - `result`: a [`RESULTS`][] code, `RESULTS.successful` when the fit converged.
    - `residual_norm`: `‖w (Ĥ - H)‖₂` over the frequency points [units of `w H`].
    - `relative_error`: `‖w (Ĥ - H)‖₂ / ‖w H‖₂` [-].
    - `noise_variance`: `σ² = ‖w (Ĥ - H)‖² / (2 n_freq - n_params)`, the variance of each
      real and imaginary part of the weighted residual (units of `(w H)²`).
    - `covariance`: `(…, n_params, n_params)` parameter covariance `σ² (JᵀJ)⁻¹`
      (Gauss-Newton / Cramér-Rao approximation, e.g. Pintelon & Schoukens 2012, *System
      Identification: A Frequency Domain Approach*, §7.2.3); valid when the weights are
      proportional to the inverse noise standard deviation and the noise is small.
    - `num_stderr`, `den_stderr`: standard errors `sqrt(diag(covariance))` laid out as
      `num` and `den` (`den_stderr[..., 0] = 0`: the monic coefficient is fixed).
    - `jacobian_condition`: condition number of the column-scaled `JᵀJ` (large values
      mean poorly identifiable parameters; above 1e13 the result is `singular`).
    - `frequency_scale`: `ω0` [rad/s], the geometric mean of the positive band edges;
      the fit works in `s / ω0`.
    - `num_steps`: Levenberg-Marquardt steps taken (accepted or rejected).
    - `num_init_steps`: Sanathanan-Koerner iterations of the linear initialisation
      (0 when `init` was given).
    - `flipped`: whether the initialisation had right-half-plane poles that were
      reflected into the left half-plane.
    """

    result: RESULTS
    residual_norm: Float[Array, "*batch"]
    relative_error: Float[Array, "*batch"]
    noise_variance: Float[Array, "*batch"]
    covariance: Float[Array, "*batch p p"]
    num_stderr: Float[Array, "*batch nb1"]
    den_stderr: Float[Array, "*batch na1"]
    jacobian_condition: Float[Array, "*batch"]
    frequency_scale: Float[Array, ""]
    num_steps: Int[Array, "*batch"]
    num_init_steps: Int[Array, "*batch"]
    flipped: Bool[Array, "*batch"]

    def summary(self) -> str:
        """A plain-text account of the fit (like `CalibrationResult.summary`)."""
        rel = np.asarray(self.relative_error)
        if rel.ndim:
            ok = np.asarray(self.result._value) == 0  # pyright: ignore
            return (
                f"FitReport over a batch of shape {rel.shape}: {int(ok.sum())} of {ok.size} "
                f"fits successful, relative error median {np.median(rel):.3g}, max "
                f"{np.max(rel):.3g}; index it for one fit."
            )
        num_se, den_se = np.asarray(self.num_stderr), np.asarray(self.den_stderr)
        lines = [
            f"result: {describe(self.result)}",
            f"relative error {float(rel):.4g}, residual norm {float(self.residual_norm):.4g}, "
            f"noise variance {float(self.noise_variance):.3g}",
            f"numerator std errors   {np.array2string(num_se, precision=3)}",
            f"denominator std errors {np.array2string(den_se, precision=3)}",
            f"Jacobian condition {float(self.jacobian_condition):.3g}, frequency scale "
            f"{float(self.frequency_scale):.4g} rad/s",
            f"{int(self.num_steps)} LM steps after {int(self.num_init_steps)} "
            f"Sanathanan-Koerner iterations" + (", poles reflected" if bool(self.flipped) else ""),
        ]
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """The fit as a table (notebooks)."""
        from .._html import table

        if np.ndim(self.relative_error):
            return f"<p>{self.summary()}</p>"
        rows = [
            ("result", describe(self.result)),
            ("relative error", float(self.relative_error)),
            ("residual norm", float(self.residual_norm)),
            ("noise variance", float(self.noise_variance)),
            ("numerator std errors", np.array2string(np.asarray(self.num_stderr), precision=3)),
            ("denominator std errors", np.array2string(np.asarray(self.den_stderr), precision=3)),
            ("Jacobian condition", float(self.jacobian_condition)),
            ("frequency scale [rad/s]", float(self.frequency_scale)),
            ("Levenberg-Marquardt steps", int(self.num_steps)),
            ("Sanathanan-Koerner iterations", int(self.num_init_steps)),
            ("poles reflected", bool(self.flipped)),
        ]
        return "<p><strong>FitReport</strong></p>" + table(("", "value"), rows, markup=False)


def _as_order(order) -> tuple[int, int]:
    if isinstance(order, (int, np.integer)) and not isinstance(order, bool):
        order = (int(order), int(order))
    try:
        nb, na = (operator.index(o) for o in order)
    except (TypeError, ValueError):
        raise TypeError(
            f"fit_rational: order must be a pair of integers (nb, na) (numerator and "
            f"denominator orders), or one integer n for a TMF (n, n); got {order!r}."
        ) from None
    if na < 1 or nb < 0:
        raise ValueError(
            f"fit_rational: order (nb, na) = ({nb}, {na}) needs na >= 1 and nb >= 0; a "
            "pure gain (na = 0) has no dynamics to fit."
        )
    if nb > na:
        raise ValueError(
            f"fit_rational: order (nb, na) = ({nb}, {na}) is improper (numerator order > "
            "denominator order); jaxvs models are proper. Use nb <= na (a TMF has nb == na)."
        )
    return nb, na


@functools.partial(jax.jit, static_argnames=("order",))
def _fit_batch(
    omega: Float[Array, " freq"],
    hr: Float[Array, "batch freq"],
    hi: Float[Array, "batch freq"],
    w2: Float[Array, "batch freq"] | Float[Array, " freq"],
    init_theta: Float[Array, "batch p"] | None,
    stable: Bool[Array, ""],
    max_steps: Int[Array, ""],
    sk_steps: Int[Array, ""],
    rtol: Float[Array, ""],
    order: tuple[int, int],
):
    # Only the orders `(nb, na)` (shapes) are static: options are traced, so changing
    # them does not recompile.
    nb, na = order
    n = na
    p = nb + 1 + na
    dtype = omega.dtype
    size = hr.shape[0]
    w0 = _frequency_scale(omega)
    grid = _sk.make_grid(omega / w0, n)
    lo = jnp.min(jnp.where(omega > 0, omega, jnp.inf))
    alpha_start = _sk.start_denominator(lo / w0, jnp.max(omega) / w0, n).astype(dtype)
    # Scale of each θ entry in the original coefficients: (s/ω0)^k -> ω0^(n-k) s^k.
    scale = jnp.concatenate([w0 ** (n - jnp.arange(nb + 1)), w0 ** (n - jnp.arange(n))])
    # Per-member data; shared weights stay out of it (no (batch, freq) copy).
    shared_w = w2.ndim == 1
    data = (hr, hi, None if shared_w else w2)

    def full(d):
        return (d[0], d[1], w2 if shared_w else d[2])

    def evaluate(theta, d):
        return _sk.normal_equations(theta, full(d), grid, nb)

    def feasible(theta):
        return _sk.is_hurwitz(theta[nb + 1 :]) | ~stable

    if init_theta is None:

        def sk_cond(c, d):
            return (~c[3]) & (c[2] < sk_steps)

        def sk_body(c, d):
            alpha, _, k, _ = c
            new, beta, ok = _sk.sk_step_relaxed(alpha, full(d), grid, nb)
            change = jnp.linalg.norm(new - alpha) / (jnp.linalg.norm(new) + 1e-300)
            done = (change <= _SK_TOL) | ~ok | ~jnp.all(jnp.isfinite(new))
            return new, beta, k + 1, done

        sk0 = (
            jnp.broadcast_to(alpha_start, (size, n)),
            jnp.zeros((size, nb + 1), dtype),
            jnp.zeros((size,), int),
            jnp.zeros((size,), bool),
        )
        alpha_sk, beta_sk, k_sk, _ = batched_while(
            sk_cond,
            sk_body,
            sk0,
            data,
            block=_BLOCK,
            first_steps=_SK_FIRST,
            tail_block=_TAIL_BLOCK,
            block_steps=_BLOCK_STEPS,
        )
        # The numerator of the last iteration starts Levenberg-Marquardt (its weight
        # 1/|A_prev|² is within _SK_TOL of the output-error weight 1/|A|²), unless the
        # poles are flipped or no iteration ran: then it is refitted for the new A.
        flipped = stable & ~jax.vmap(_sk.is_hurwitz)(alpha_sk)
        refit = flipped | (k_sk == 0)

        def refit_all(alpha_sk):
            # Only when some member needs it (a batch-level branch: roots are expensive).
            def one(alpha, beta, d, again):
                flipped_alpha, _ = _sk.flip_unstable(alpha)
                alpha0 = jnp.where(stable, flipped_alpha, alpha)
                beta0 = _sk.refit_numerator(alpha0, full(d), grid, nb)
                # The unconstrained fit, to tell unstable data from a spurious pole.
                _, cost_free = _sk.refit_numerator(alpha, full(d), grid, nb, with_cost=True)
                return (
                    jnp.where(again, alpha0, alpha),
                    jnp.where(again, beta0, beta),
                    jnp.where(again, cost_free, jnp.inf),
                )

            return _chunked(one, alpha_sk, beta_sk, data, refit)

        def keep(alpha_sk):
            return alpha_sk, beta_sk, jnp.full((size,), jnp.inf, dtype)

        alpha0, beta0, cost_free = jax.lax.cond(jnp.any(refit), refit_all, keep, alpha_sk)
        theta0 = jnp.concatenate([beta0, alpha0], axis=1)
        bad_init = jnp.zeros((size,), bool)
    else:
        theta0 = init_theta
        k_sk = jnp.zeros((size,), int)
        flipped = jnp.zeros((size,), bool)
        cost_free = jnp.full((size,), jnp.inf, dtype)
        bad_init = ~jax.vmap(feasible)(theta0)

    state = _chunked(lambda t, d: _lm.lm_init(evaluate, t, d, rtol, _MU0), theta0, data)
    # An infeasible initial guess is reported, not iterated.
    state = eqx.tree_at(lambda st: st.converged, state, state.converged | bad_init)
    schedule = _lm.BatchSchedule(_BLOCK, _LM_FIRST, _TAIL_BLOCK, _BLOCK_STEPS)
    state = _lm.lm_solve_family(
        evaluate, state, data, max_steps=max_steps, rtol=rtol, schedule=schedule, feasible=feasible
    )

    def summarise(st, d, flip, c_free, bad):
        hr, hi, ww = full(d)
        # Covariance σ² (JᵀJ)⁻¹ through the eigen-decomposition of the unit-diagonal
        # scaled JᵀJ; directions below 1 / _SINGULAR_COND get infinite variance.
        dg = jnp.diagonal(st.jtj)
        sc = 1.0 / jnp.sqrt(jnp.where(dg > 0, dg, 1.0))
        eig, vec = jnp.linalg.eigh(st.jtj * sc[:, None] * sc[None, :])
        cond = eig[-1] / jnp.where(eig[0] > 0, eig[0], 0.0)
        singular = ~(cond <= _SINGULAR_COND)
        inv_eig = jnp.where(eig > eig[-1] / _SINGULAR_COND, 1.0 / eig, jnp.inf)
        inv = (vec * inv_eig) @ vec.T * sc[:, None] * sc[None, :]
        dof = jnp.maximum(2 * jnp.sum(ww > 0) - p, 1)
        sigma2 = 2.0 * st.cost / dof
        cov = sigma2 * inv * scale[:, None] * scale[None, :]

        # Precedence: bad initial guess > non-finite > unstable data > max steps >
        # singular > successful.
        result = _lm.lm_result(st)
        ok_or_steps = (result == RESULTS.successful) | (result == RESULTS.max_steps_reached)
        result = RESULTS.where(
            (result == RESULTS.successful) & singular, RESULTS.singular, result
        )
        res_norm = jnp.sqrt(2.0 * st.cost)
        rel_err = res_norm / jnp.sqrt(jnp.sum(ww * (hr**2 + hi**2)))
        # Unstable data: the stable optimum is > 2x worse in error (> 4x in cost) than
        # the unconstrained linear fit that needed right-half-plane poles. Heuristic
        # floor: relative errors below 1e-6 are rounding (exact data, where a cancelling
        # pole-zero pair of an over-parametrised model may land anywhere).
        unstable_data = flip & (st.cost > 4.0 * c_free) & (rel_err > 1e-6)
        result = RESULTS.where(ok_or_steps & unstable_data, RESULTS.unstable_data, result)
        result = RESULTS.where(bad, RESULTS.unstable_initial_guess, result)
        out = dict(
            theta=st.theta,
            cov=cov,
            residual_norm=res_norm,
            relative_error=rel_err,
            noise_variance=sigma2,
            cond=cond,
            num_steps=st.num_steps,
        )
        return out, result

    out, result = _chunked(summarise, state, data, flipped, cost_free, bad_init)

    theta = out["theta"] * scale
    num = theta[:, : nb + 1][:, ::-1]
    den_free = theta[:, nb + 1 :][:, ::-1]
    den = jnp.concatenate([jnp.ones((size, 1), dtype), den_free], axis=1)
    # Reorder θ from ascending scaled powers to the RationalTF layout (highest first).
    perm = np.concatenate([np.arange(nb, -1, -1), nb + 1 + np.arange(n - 1, -1, -1)])
    cov = out["cov"][:, perm][:, :, perm]
    std = jnp.sqrt(jnp.clip(jnp.diagonal(cov, axis1=-2, axis2=-1), 0.0))
    report = FitReport(
        result=result,
        residual_norm=out["residual_norm"],
        relative_error=out["relative_error"],
        noise_variance=out["noise_variance"],
        covariance=cov,
        num_stderr=std[:, : nb + 1],
        den_stderr=jnp.concatenate([jnp.zeros((size, 1), dtype), std[:, nb + 1 :]], axis=1),
        jacobian_condition=out["cond"],
        frequency_scale=w0,
        num_steps=out["num_steps"],
        num_init_steps=k_sk,
        flipped=flipped,
    )
    return num, den, report


def _chunked(fn, *args):
    """`vmap(fn)` over the family in chunks of `_BLOCK` members (`lax.map`): the per-point
    work of a chunk stays in the CPU caches, which a whole-family `vmap` of 2000-point
    rows (hundreds of MB) does not."""
    size = jax.tree_util.tree_leaves(args)[0].shape[0]
    if size <= _BLOCK:
        return jax.vmap(fn)(*args)
    return jax.lax.map(lambda a: fn(*a), args, batch_size=_BLOCK)


def _real_imag(H, size: int, n_freq: int) -> tuple[Array, Array]:
    """Real and imaginary parts as float64 `(size, freq)` arrays (NumPy when concrete:
    splitting a complex array is a strided copy that NumPy does much faster than XLA:CPU)."""
    value = concrete(H)
    if value is not None:
        value = value.reshape(size, n_freq).astype(np.complex128, copy=False)
        return jnp.asarray(np.ascontiguousarray(value.real)), jnp.asarray(
            np.ascontiguousarray(value.imag)
        )
    H = H.reshape(size, n_freq).astype(jnp.complex128)
    return jnp.real(H), jnp.imag(H)


def _frequency_scale(omega: Float[Array, " freq"]) -> Float[Array, ""]:
    """`ω0`: geometric mean of the smallest positive and the largest frequency [rad/s]."""
    lo = jnp.min(jnp.where(omega > 0, omega, jnp.inf))
    return jnp.sqrt(lo * jnp.max(omega))


def _raise_if_failed(result: RESULTS, x: Array) -> Array:
    """`throw=True`: raise the message of the first failed member (works under `jit`)."""
    return jax.vmap(lambda r, y: r.error_if(y, r != RESULTS.successful))(result, x)


def fit_rational(
    omega: ArrayLike,
    H: ArrayLike,
    order: tuple[int, int] | int,
    *,
    weights: ArrayLike | None = None,
    init: RationalTF | None = None,
    stable: bool = True,
    max_steps: int = 100,
    sk_steps: int = 20,
    rtol: float = 1e-8,
    throw: bool = True,
) -> tuple[RationalTF, FitReport]:
    r"""Fit `G(s) = B(s) / A(s)` of orders `(nb, na)` to a measured frequency response.

    Minimises the weighted output error `½ Σ_i w_i² |G(jω_i) - H_i|²` (real and imaginary
    parts), in scaled frequency `s / ω0` (`ω0` = geometric mean of the band edges) for
    conditioning, in three stages:

    1. **Linear initialisation**, no initial guess needed: relaxed Sanathanan-Koerner
       iterations (Sanathanan & Koerner 1963, IEEE TAC 8(1); the relaxed normalisation of
       vector fitting, Gustavsen 2006, IEEE TPWRD 21(3)) from lightly damped starting
       poles spread over the band (Gustavsen & Semlyen 1999, IEEE TPWRD 14(3)).
    2. **Pole flipping** (`stable=True`): right-half-plane poles of the initialisation are
       reflected into the left half-plane and the numerator is refitted.
    3. **Levenberg-Marquardt** on the numerator and monic-denominator coefficients. With
       `stable=True`, a step that would make the denominator unstable (Routh test) is
       shortened to stay stable, so every iterate and the result are stable.

    The normal equations of every stage are formed from power moments of the data (Levy
    1959, IRE Trans. AC-4): `O(n_freq · order)` work per iteration, no Jacobian in memory.
    A family (leading axes of `H`) is fitted in one vectorised call; members that need
    more iterations are gathered into small blocks, so a few slow members do not slow the
    rest.

    **Arguments:**

    - `omega`: `(freq,)` angular frequencies [rad/s], real, finite, `>= 0` with at least
      one positive value; shared by every member of a family.
    - `H`: `(*batch, freq)` complex response (e.g. a TMF or an FRF, any units); leading
      axes make a family (e.g. one TMF per axis position) fitted in one call.
    - `order`: `(nb, na)` numerator and denominator orders with `0 <= nb <= na`, `na >= 1`;
      an integer `n` means `(n, n)` (a transmissibility function).
    - `weights`: optional real, non-negative weights `w` [1 / units of H], shape `(freq,)`
      or `(*batch, freq)`; e.g. `1 / |H|` for relative errors (maximum likelihood for noise
      proportional to `|H|`), coherence-based weights `sqrt(γ² / (1 - γ²))`, or `1 / σ_H`;
      `0` drops a point. Default: all ones.
    - `init`: optional initial `RationalTF` of the same orders (unbatched, or with the
      batch shape of `H`); replaces stages 1-2. With `stable=True` it must be stable,
      otherwise the result is `RESULTS.unstable_initial_guess` (not iterated).
    - `stable`: keep every pole in the open left half-plane (default). When the data need
      right-half-plane poles (the unconstrained initialisation has some, and the best
      stable fit is more than twice worse), the result is `RESULTS.unstable_data`; pass
      `stable=False` to fit unstable systems (no flipping, no constraint).
    - `max_steps`: Levenberg-Marquardt step limit (accepted and rejected steps).
    - `sk_steps`: largest number of Sanathanan-Koerner iterations.
    - `rtol`: Levenberg-Marquardt stops when the Gauss-Newton model promises less than
      `rtol · cost` of further reduction (parameters within `sqrt(2 rtol n_freq)` standard
      errors of the optimum), or its step is below `rtol` relative to the parameters.
    - `throw`: raise an `equinox.EquinoxRuntimeError` with the [`RESULTS`][] message if
      any member did not succeed; with `throw=False` check `report.result` instead.

    **Returns:**

    `(model, report)`: a `RationalTF` with `num` `(*batch, nb + 1)` and monic `den`
    `(*batch, na + 1)` (highest power first, `den[..., 0] = 1`), and a [`FitReport`][]
    (residual, covariance and standard errors of the coefficients, result code, steps).

    **Raises:**

    `TypeError` for a real `H`, complex `omega` or weights, a non-integer `order` or an
    `init` that is not a `RationalTF`; `ValueError` for mismatched shapes, NaN/inf (an
    `EquinoxRuntimeError` under `jit`), negative `omega` or weights, an improper order
    (`nb > na`), fewer frequency points than parameters (`nb + na + 1`), or float64
    disabled.

    !!! note
        Needs float64 (`jax.config.update("jax_enable_x64", True)`): the normal equations
        square the condition number of the problem. Changing `max_steps`, `sk_steps`,
        `rtol`, `stable` or `throw` does not recompile; the orders and shapes do.
    """
    nb, na = _as_order(order)
    n_params = nb + na + 1
    require_x64("fit_rational", "the normal equations square the condition number")
    # Concrete inputs are checked and split in NumPy (no device round trips); traced ones
    # (a caller's `jit`) keep their shape checks and get `eqx.error_if` for values.
    omega_c, H_c = concrete(omega), concrete(H)
    omega = jnp.asarray(omega) if omega_c is None else omega_c
    H = jnp.asarray(H) if H_c is None else H_c
    if np.iscomplexobj(omega):
        raise TypeError("fit_rational: omega is the real angular frequency [rad/s].")
    if omega.ndim != 1:
        raise ValueError(
            f"fit_rational: omega must be 1-D (freq,) and shared by the family; got shape "
            f"{omega.shape}."
        )
    if not np.iscomplexobj(H):
        raise TypeError(
            "fit_rational: H must be the complex frequency response; got a real array of "
            f"dtype {H.dtype}. Magnitudes alone do not determine a rational model; if the "
            "response really is real, pass H.astype(complex)."
        )
    if H.ndim < 1 or H.shape[-1] != omega.shape[0]:
        raise ValueError(
            f"fit_rational: H of shape {H.shape} does not match omega of shape "
            f"{omega.shape}; H must be (*batch, freq) with freq = len(omega)."
        )
    n_freq = omega.shape[0]
    if n_freq < n_params:
        raise ValueError(
            f"fit_rational: {n_freq} frequency points cannot determine {n_params} "
            f"parameters (order {(nb, na)}: nb + na + 1). Give at least {n_params} "
            "points, or lower the order."
        )
    batch = H.shape[:-1]
    size = math.prod(batch)
    omega = check_finite(omega, "fit_rational: omega", "Remove those frequency points.")
    if omega_c is not None and (np.any(omega_c < 0) or not np.any(omega_c > 0)):
        raise ValueError(
            "fit_rational: omega must be >= 0 with at least one positive value [rad/s]; "
            "the response at -w is the complex conjugate of the one at w."
        )
    H = check_finite(
        H, "fit_rational: H", "Drop those frequency points (or give them zero weight)."
    )
    if H_c is not None and not np.any(H_c):
        raise ValueError(
            "fit_rational: H is zero at every frequency, so there is nothing to fit (every "
            "coefficient would be 0). Check the measurement channel and its scaling, or "
            "the array passed as H."
        )

    if weights is None:
        w2 = jnp.ones((n_freq,), jnp.float64)
    else:
        w_c = concrete(weights)
        w = jnp.asarray(weights) if w_c is None else w_c
        if np.iscomplexobj(w):
            raise TypeError("fit_rational: weights must be real and non-negative.")
        try:
            shape = np.broadcast_shapes(w.shape, H.shape)
        except ValueError:
            shape = None
        if shape != H.shape:
            raise ValueError(
                f"fit_rational: weights of shape {w.shape} do not broadcast to H's shape "
                f"{H.shape}; give (freq,) or (*batch, freq)."
            )
        w = check_finite(w, "fit_rational: weights", "Use 0 to drop a point.")
        if w_c is not None and np.any(w_c < 0):
            raise ValueError("fit_rational: weights must be non-negative (0 drops a point).")
        if w_c is not None and not np.any(w_c):
            raise ValueError(
                "fit_rational: the weights are all zero, so every point is dropped; give "
                "positive weights where the data count (e.g. 1/|H| or the coherence)."
            )
        w2 = jnp.asarray(w, jnp.float64) ** 2
        if w2.ndim > 1:
            w2 = jnp.broadcast_to(w2, H.shape).reshape(size, n_freq)
    if H_c is not None:
        # Splitting a complex array is a strided copy that NumPy does much faster than
        # XLA:CPU (measured).
        H_c = H_c.reshape(size, n_freq).astype(np.complex128, copy=False)
        hr = jnp.asarray(np.ascontiguousarray(H_c.real))
        hi = jnp.asarray(np.ascontiguousarray(H_c.imag))
    else:
        H = H.reshape(size, n_freq).astype(jnp.complex128)
        hr, hi = jnp.real(H), jnp.imag(H)
    omega = jnp.asarray(omega, jnp.float64)

    init_theta = None
    if init is not None:
        if not isinstance(init, RationalTF):
            raise TypeError(f"fit_rational: init must be a RationalTF; got {type(init).__name__}.")
        if init.num.shape[-1] != nb + 1 or init.den.shape[-1] != na + 1:
            raise ValueError(
                f"fit_rational: init has orders ({init.num.shape[-1] - 1}, "
                f"{init.den.shape[-1] - 1}), but order = {(nb, na)}; give an initial model "
                "of the orders being fitted."
            )
        if init.batch_shape not in ((), batch):
            raise ValueError(
                f"fit_rational: init has batch shape {init.batch_shape}; it must be "
                f"unbatched or match H's batch shape {batch}."
            )
        init_theta = _init_theta(omega, init, nb, na, batch, size)

    num, den, report = _fit_batch(
        omega,
        hr,
        hi,
        w2,
        init_theta,
        jnp.asarray(bool(stable)),
        jnp.asarray(int(max_steps)),
        jnp.asarray(int(sk_steps)),
        jnp.asarray(float(rtol), jnp.float64),
        (nb, na),
    )
    if throw:
        num = _raise_if_failed(report.result, num)
    num, den = num.reshape(batch + (nb + 1,)), den.reshape(batch + (na + 1,))
    # A failed member (throw=False) keeps its last, possibly non-finite iterate for
    # inspection: set past the constructor, which refuses NaN parameters.
    model = eqx.tree_at(
        lambda m: (m.num, m.den), RationalTF(jnp.ones_like(num), jnp.ones_like(den)), (num, den)
    )
    report = jax.tree_util.tree_map(
        lambda x: x if x.ndim == 0 else x.reshape(batch + x.shape[1:]), report
    )
    return model, report


def _init_theta(omega, init: RationalTF, nb: int, na: int, batch, size) -> Array:
    """θ (ascending, scaled by ω0, monic) of a user's initial model."""
    w0 = _frequency_scale(omega)
    num = jnp.broadcast_to(init.num.astype(jnp.float64), batch + (nb + 1,)).reshape(size, -1)
    den = jnp.broadcast_to(init.den.astype(jnp.float64), batch + (na + 1,)).reshape(size, -1)
    num, den = num / den[:, :1], den / den[:, :1]
    beta = num[:, ::-1] / w0 ** (na - jnp.arange(nb + 1))
    alpha = den[:, 1:][:, ::-1] / w0 ** (na - jnp.arange(na))
    return jnp.concatenate([beta, alpha], axis=1)
