r"""A small Levenberg-Marquardt kernel for ONE problem, written to be `vmap`-ped over families.

The problem enters only through its *normal equations*: `evaluate(θ, args)` returns the
cost `½‖r‖²`, the Gauss-Newton matrix `JᵀJ` and the gradient `Jᵀr`. Problems with
structure (e.g. rational frequency responses, see `_sk.normal_equations`) form these in
`O(data · parameters)` without the Jacobian; a generic problem can form them from
`jax.jacfwd`. A `feasible(θ, args)` predicate rejects steps that leave the admissible set
(e.g. unstable denominators), exactly as steps that increase the cost are rejected, so
every accepted iterate stays feasible.

Algorithm: Marquardt's scaled damping `(JᵀJ + μ diag(JᵀJ)) δ = -Jᵀr` (Marquardt 1963,
SIAM J. Appl. Math. 11(2)), with Nielsen's update of `μ` from the gain ratio (Nielsen
1999, IMM-REP-1999-05, eq. 2.20; Madsen, Nielsen & Tingleff 2004, *Methods for non-linear
least squares problems*, Alg. 3.16), and MINPACK-style stopping rules (Moré 1978,
"The Levenberg-Marquardt algorithm: implementation and theory"): relative reductions of
the cost below `rtol`, or a scaled step below `rtol` relative to the scaled parameters.

Under `vmap` the `while_loop` runs until the slowest member stops; members that have
stopped are frozen by the batching rule of `while_loop`, so each member's result equals an
unbatched run.
"""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._results import RESULTS


class LMState(eqx.Module):
    theta: Float[Array, " p"]
    cost: Float[Array, ""]
    jtj: Float[Array, "p p"]
    jtr: Float[Array, " p"]
    mu: Float[Array, ""]
    nu: Float[Array, ""]
    num_steps: Int[Array, ""]
    converged: Bool[Array, ""]
    nonfinite: Bool[Array, ""]


def _damped_step(jtj, jtr, mu):
    """Solve `(JᵀJ + μ D) δ = -Jᵀr`, `D = diag(JᵀJ)`, by Cholesky in unit-diagonal scaling."""
    d = jnp.diagonal(jtj)
    d = jnp.where(d > 0, d, 1.0)
    sc = 1.0 / jnp.sqrt(d)
    m = jtj * sc[:, None] * sc[None, :] + mu * jnp.eye(jtj.shape[0], dtype=jtj.dtype)
    chol = jnp.linalg.cholesky(m)
    y = jax.scipy.linalg.cho_solve((chol, True), -jtr * sc)
    return y * sc, sc


def levenberg_marquardt(
    evaluate: Callable[[Array, Any], tuple[Array, Array, Array]],
    feasible: Callable[[Array, Any], Array],
    theta0: Float[Array, " p"],
    args: Any,
    *,
    max_steps: int,
    rtol: float,
    mu0: float = 1e-3,
) -> tuple[LMState, RESULTS]:
    """Minimise `½‖r(θ)‖²` from a feasible `theta0`.

    **Arguments:**

    - `evaluate`: `(θ, args) -> (cost, JᵀJ, Jᵀr)`.
    - `feasible`: `(θ, args) -> bool`; `theta0` must be feasible (callers check).
    - `theta0`: `(p,)` starting point.
    - `max_steps`: largest number of trial steps (accepted or rejected).
    - `rtol`: relative tolerance on the cost reduction and on the scaled step.
    - `mu0`: initial damping, relative to the unit-diagonal-scaled `JᵀJ`.

    **Returns:**

    The final state (the best feasible point found, its normal equations and counters)
    and a result code: `successful`, `max_steps_reached` or `nonfinite`.
    """
    dtype = theta0.dtype
    cost0, jtj0, jtr0 = evaluate(theta0, args)
    bad0 = ~(jnp.isfinite(cost0) & jnp.all(jnp.isfinite(jtj0)) & jnp.all(jnp.isfinite(jtr0)))
    state = LMState(
        theta=theta0,
        cost=cost0,
        jtj=jtj0,
        jtr=jtr0,
        mu=jnp.asarray(mu0, dtype),
        nu=jnp.asarray(2.0, dtype),
        num_steps=jnp.asarray(0),
        # A zero residual is already optimal (noiseless data and an exact initial guess).
        converged=cost0 == 0,
        nonfinite=bad0,
    )

    def cond(s: LMState):
        return (~s.converged) & (~s.nonfinite) & (s.num_steps < max_steps)

    def body(s: LMState):
        delta, sc = _damped_step(s.jtj, s.jtr, s.mu)
        trial = s.theta + delta
        cost_t, jtj_t, jtr_t = evaluate(trial, args)
        # Predicted reduction of the Gauss-Newton model: -(gᵀδ + ½ δᵀ JᵀJ δ) > 0.
        pred = -(jnp.dot(s.jtr, delta) + 0.5 * jnp.dot(delta, s.jtj @ delta))
        actual = s.cost - cost_t
        finite = (
            jnp.isfinite(cost_t)
            & jnp.all(jnp.isfinite(jtj_t))
            & jnp.all(jnp.isfinite(jtr_t))
            & jnp.all(jnp.isfinite(delta))
        )
        accept = finite & (actual > 0) & feasible(trial, args)
        gain = actual / jnp.where(pred > 0, pred, 1.0)
        mu = jnp.where(
            accept,
            s.mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3),
            s.mu * s.nu,
        )
        nu = jnp.where(accept, 2.0, 2.0 * s.nu)
        # Stopping rules (MINPACK lmder's ftol and xtol tests, with ftol = xtol = rtol).
        small_reduction = accept & (actual <= rtol * s.cost) & (pred <= rtol * s.cost)
        step_norm = jnp.linalg.norm(delta / sc)
        theta_norm = jnp.linalg.norm(s.theta / sc)
        small_step = jnp.all(jnp.isfinite(delta)) & (step_norm <= rtol * (theta_norm + rtol))
        pick = lambda new, old: jnp.where(accept, new, old)
        return LMState(
            theta=pick(trial, s.theta),
            cost=pick(cost_t, s.cost),
            jtj=pick(jtj_t, s.jtj),
            jtr=pick(jtr_t, s.jtr),
            mu=mu,
            nu=nu,
            num_steps=s.num_steps + 1,
            converged=small_reduction | small_step | (accept & (cost_t == 0)),
            # A damping that overflows means no step can be taken any more.
            nonfinite=~jnp.isfinite(mu),
        )

    state = jax.lax.while_loop(cond, body, state)
    result = RESULTS.where(
        state.nonfinite,
        RESULTS.nonfinite,
        RESULTS.where(state.converged, RESULTS.successful, RESULTS.max_steps_reached),
    )
    return state, result
