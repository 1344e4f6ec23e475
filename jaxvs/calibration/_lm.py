r"""A small Levenberg-Marquardt kernel for ONE problem, and a driver that runs a family of them.

The problem enters only through its *normal equations*: `evaluate(θ, args)` returns the
cost `½‖r‖²`, the Gauss-Newton matrix `JᵀJ` and the gradient `Jᵀr`. Problems with
structure (e.g. rational frequency responses, see `_sk.normal_equations`) form these in
`O(data · parameters)` without the Jacobian; a generic problem can form them from
`jax.jacfwd`. A `feasible(θ)` predicate describes an open admissible set (e.g. stable
denominators): a step that would leave it is shortened to the largest feasible fraction
on a fixed grid (the "fraction to the boundary" rule of interior-point methods, Nocedal &
Wright 2006, *Numerical Optimization*, eq. 19.9), so every iterate is feasible.

Algorithm: Marquardt's scaled damping `(JᵀJ + μ diag(JᵀJ)) δ = -Jᵀr` (Marquardt 1963,
SIAM J. Appl. Math. 11(2)) and Nielsen's update of `μ` from the gain ratio (Nielsen 1999,
IMM-REP-1999-05; Madsen, Nielsen & Tingleff 2004, *Methods for non-linear least squares
problems*, Alg. 3.16). Stopping rules, all relative to `rtol`:

- the undamped Gauss-Newton model predicts less than `rtol · cost` of further reduction,
  or its step is below `rtol` relative to `θ` (see `_newton_converged`): a step kept
  small by the damping is never mistaken for convergence;
- at the feasible boundary, the feasible part of the step predicts less than
  `rtol · cost` (MINPACK's relative-reduction test, Moré 1978, "The Levenberg-Marquardt
  algorithm: implementation and theory", restricted to shortened steps).

[`batched_while`][] runs any per-member iteration over a family with *work compaction*:
blocks of still-running members are iterated a few steps at a time, so a few slow members
do not make the whole family pay for their steps (a `vmap`-ped `while_loop` runs every
member until the slowest stops), and each block's work stays in the CPU caches.
"""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PyTree

from ._results import RESULTS

# Candidate fractions of a step: a step that would leave the feasible set is shortened to
# the largest feasible one. Heuristic: 1 - 10^-k close to 1 (an optimum on the boundary is
# then approached in a few steps instead of geometrically slowly), then 2^(-k/4); below
# 2^-12 the step is rejected instead.
_FRACTIONS = np.concatenate([[1.0, 0.999, 0.99, 0.95], 2.0 ** (-np.arange(1, 49) / 4.0)])


def batched_while(
    cond: Callable[[Any, Any], Array],
    body: Callable[[Any, Any], Any],
    state: PyTree,
    args: PyTree,
    *,
    block: int,
    first_steps: int,
    tail_block: int,
    block_steps: int,
) -> PyTree:
    """`while cond(s, a): s = body(s, a)` for every member of a family, with compaction.

    **Arguments:**

    - `cond`, `body`: per-member functions of `(state, args)`; `body` must eventually
      make `cond` false (e.g. through a step counter in the state).
    - `state`, `args`: pytrees whose leaves carry the family axis first; `args` is
      read-only.
    - `block`: members iterated together (`vmap`). A family of at most `block` members is
      one `vmap`-ped `while_loop`.
    - `first_steps`: first sweep: consecutive blocks, at most `first_steps` iterations
      each (no data movement; enough for most members).
    - `tail_block`, `block_steps`: then, until no member runs, the first `tail_block`
      still-running members are gathered, iterated at most `block_steps` times, and
      scattered back (a small block: the few slow members do not carry idle ones).

    **Returns:**

    The final states; each equals what an unbatched `while_loop` gives for that member.
    """
    size = jax.tree_util.tree_leaves(state)[0].shape[0]
    tail_block = min(tail_block, size)

    def one(s, a, limit):
        def c(carry):
            return cond(carry[0], a) & (carry[1] < limit)

        def b(carry):
            return body(carry[0], a), carry[1] + 1

        return jax.lax.while_loop(c, b, (s, jnp.asarray(0)))[0]

    if size <= block:
        return jax.vmap(lambda s, a: one(s, a, jnp.iinfo(jnp.int32).max))(state, args)

    state = jax.lax.map(lambda sa: one(*sa, first_steps), (state, args), batch_size=block)

    def outer_cond(st):
        return jnp.any(jax.vmap(cond)(st, args))

    def outer_body(st):
        active = jax.vmap(cond)(st, args)
        idx = jnp.argsort(~active, stable=True)[:tail_block]  # running members first
        take = lambda x: x[idx]
        sub = jax.vmap(lambda s, a: one(s, a, block_steps))(
            jax.tree_util.tree_map(take, st), jax.tree_util.tree_map(take, args)
        )
        return jax.tree_util.tree_map(lambda x, y: x.at[idx].set(y), st, sub)

    return jax.lax.while_loop(outer_cond, outer_body, state)


class LMState(eqx.Module):
    """Iterate of [`lm_step`][]: the best feasible point, its normal equations, the
    damping `mu` (relative to the unit-diagonal scaled `JᵀJ`) and its growth factor `nu`."""

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


def _finite(*xs) -> Array:
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in xs]))


def _newton_converged(theta, cost, jtj, jtr, rtol) -> Array:
    """Convergence of the Gauss-Newton model at `θ` (no step needed).

    With the undamped step `δ = -(JᵀJ)⁻¹ Jᵀr`: the largest reduction the model predicts,
    `½ (Jᵀr)ᵀ (JᵀJ)⁻¹ Jᵀr`, is below `rtol · cost` (noisy data: parameters within a tiny
    fraction of their standard errors of the optimum, however flat some directions are),
    or `δ` is below `rtol` relative to `θ` in the unit-diagonal scaling (zero-residual
    data, where the relative reduction stays O(1) until rounding).
    """
    d = jnp.diagonal(jtj)
    sc = 1.0 / jnp.sqrt(jnp.where(d > 0, d, 1.0))
    m = jtj * sc[:, None] * sc[None, :] + 1e-13 * jnp.eye(jtj.shape[0], dtype=jtj.dtype)
    chol = jnp.linalg.cholesky(m)
    y = jax.scipy.linalg.cho_solve((chol, True), -jtr * sc)  # scaled Newton step
    pred = -0.5 * jnp.dot(jtr * sc, y)
    small_pred = pred <= rtol * cost
    small_step = jnp.linalg.norm(y) <= rtol * (jnp.linalg.norm(theta / sc) + rtol)
    return _finite(y) & (small_pred | small_step) | (cost == 0)


def lm_init(evaluate, theta0: Array, args: Any, rtol, mu0: float = 1e-3) -> LMState:
    """State at a starting point (one evaluation of the normal equations)."""
    cost0, jtj0, jtr0 = evaluate(theta0, args)
    dtype = theta0.dtype
    finite = _finite(cost0, jtj0, jtr0)
    return LMState(
        theta=theta0,
        cost=cost0,
        jtj=jtj0,
        jtr=jtr0,
        mu=jnp.asarray(mu0, dtype),
        nu=jnp.asarray(2.0, dtype),
        num_steps=jnp.asarray(0),
        converged=finite & _newton_converged(theta0, cost0, jtj0, jtr0, rtol),
        nonfinite=~finite,
    )


def lm_running(state: LMState, max_steps) -> Bool[Array, ""]:
    """Whether [`lm_step`][] should be called again."""
    return (~state.converged) & (~state.nonfinite) & (state.num_steps < max_steps)


def lm_step(evaluate, feasible, state: LMState, args: Any, rtol) -> LMState:
    """One trial step: solve, shorten to the feasible set, evaluate, accept or reject."""
    s = state
    delta, sc = _damped_step(s.jtj, s.jtr, s.mu)
    ok = jax.vmap(lambda t: feasible(s.theta + t * delta))(jnp.asarray(_FRACTIONS, delta.dtype))
    frac = jnp.max(jnp.where(ok, _FRACTIONS, 0.0))
    delta = frac * delta
    trial = s.theta + delta
    cost_t, jtj_t, jtr_t = evaluate(trial, args)
    # Predicted reduction of the Gauss-Newton model: -(gᵀδ + ½ δᵀ JᵀJ δ) > 0.
    pred = -(jnp.dot(s.jtr, delta) + 0.5 * jnp.dot(delta, s.jtj @ delta))
    actual = s.cost - cost_t
    finite = _finite(cost_t, jtj_t, jtr_t, delta)
    accept = finite & (actual > 0) & (frac > 0)
    gain = actual / jnp.where(pred > 0, pred, 1.0)
    mu = jnp.where(
        accept,
        s.mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3),
        s.mu * s.nu,
    )
    nu = jnp.where(accept, 2.0, 2.0 * s.nu)
    pick = lambda new, old: jnp.where(accept, new, old)
    theta, cost, jtj, jtr = (
        pick(trial, s.theta),
        pick(cost_t, s.cost),
        pick(jtj_t, s.jtj),
        pick(jtr_t, s.jtr),
    )
    # An optimum on the boundary of the feasible set (e.g. a spurious pole pair that would
    # rather be unstable): the feasible part of the step no longer promises a reduction
    # of more than rtol (in particular when no fraction of it is feasible). Following
    # the boundary further by raising the damping gains ~1e-6 relative in many steps.
    at_boundary = (frac < 1) & (pred <= rtol * s.cost)
    converged = at_boundary | _newton_converged(theta, cost, jtj, jtr, rtol)
    return LMState(
        theta=theta,
        cost=cost,
        jtj=jtj,
        jtr=jtr,
        mu=mu,
        nu=nu,
        num_steps=s.num_steps + 1,
        converged=converged,
        # A damping that overflows means no step can be taken any more.
        nonfinite=~jnp.isfinite(mu),
    )


def lm_result(state: LMState) -> RESULTS:
    """`successful`, `max_steps_reached` or `nonfinite`."""
    return RESULTS.where(
        state.nonfinite,
        RESULTS.nonfinite,
        RESULTS.where(state.converged, RESULTS.successful, RESULTS.max_steps_reached),
    )
