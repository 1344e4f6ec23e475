r"""The one Levenberg-Marquardt of jaxvs: a kernel for ONE problem, a driver that runs a
family of them, and the kernel as an optimistix least-squares solver.

`calibrate` (through [`LevenbergMarquardt`][], an `optimistix.AbstractLeastSquaresSolver`),
`fit_rational` (batched, with [`batched_while`][]), the diagnosis and every other fit step
with [`lm_step`][]; the loop around it is [`lm_solve`][] (one problem) or
[`lm_solve_family`][] (a family, with work compaction): `fit_first_order`, the multiple
shooting fit, the design search's networks (with early stopping, an
[`AbstractLMMonitor`][]) and `train_lm` (trainlm's epochs: an `lm_solve` until a step is
accepted, with its structured Gauss-Newton matrix and trainlm's damping).

The problem enters only through its *normal equations*: `evaluate(θ, args)` returns the
cost `½‖r‖²`, the Gauss-Newton matrix `JᵀJ` and the gradient `Jᵀr`. Problems with
structure (e.g. rational frequency responses, see `_sk.normal_equations`) form these in
`O(data · parameters)` without the Jacobian; a generic problem can form them from
`jax.jacfwd`. A `feasible(θ)` predicate describes an open admissible set (e.g. stable
denominators): a step that would leave it is shortened to the largest feasible fraction
on a fixed grid (the "fraction to the boundary" rule of interior-point methods, Nocedal &
Wright 2006, *Numerical Optimization*, eq. 19.9), so every iterate is feasible.

Algorithm: the damped Gauss-Newton step `(JᵀJ + μ D) δ = -Jᵀr`; the damping policy is a
component ([`AbstractDamping`][]): [`NielsenDamping`][] (default) uses Marquardt's scaling
`D = diag(JᵀJ)` (Marquardt 1963, SIAM J. Appl. Math. 11(2)) and Nielsen's update of `μ`
from the gain ratio (Nielsen 1999, IMM-REP-1999-05; Madsen, Nielsen & Tingleff 2004,
*Methods for non-linear least squares problems*, Alg. 3.16); [`MarquardtDamping`][] is
MATLAB trainlm's `D = I`, `μ ← μ·mu_dec` on success and `μ ← μ·mu_inc` on failure (Hagan
& Menhaj 1994, IEEE TNN 5(6)). Stopping rules, all relative to `rtol`:

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

import abc
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree
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


class AbstractDamping(eqx.Module):
    """How the damping `μ` of the step `(JᵀJ + μ D) δ = -Jᵀr` is scaled and updated."""

    scaled: eqx.AbstractVar[bool]

    @abc.abstractmethod
    def update(self, mu: Array, nu: Array, accept: Array, gain: Array) -> tuple[Array, Array]:
        """`(μ, ν)` after a trial step with gain ratio `gain` (accepted or not)."""


class NielsenDamping(AbstractDamping):
    """Nielsen's gain-ratio update of the damping (the default).

    `μ ← μ · max(1/3, 1 - (2ρ - 1)³)` after an accepted step with gain ratio `ρ`, else
    `μ ← μ ν`, `ν ← 2ν` (Madsen, Nielsen & Tingleff 2004, Alg. 3.16). `scaled=True`:
    Marquardt's scaling `D = diag(JᵀJ)` (invariant to the units of the parameters);
    `False`: Levenberg's `D = I`, which bounds the step in the parameters' own units and
    so damps weakly determined directions most (right for parameters normalised to O(1),
    as `calibrate` does)."""

    scaled: bool = True

    def __init__(self, scaled: bool = True):
        self.scaled = bool(scaled)

    def update(self, mu, nu, accept, gain):
        mu = jnp.where(accept, mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3), mu * nu)
        return mu, jnp.where(accept, 2.0, 2.0 * nu)


class MarquardtDamping(AbstractDamping):
    """MATLAB trainlm's damping: `D = I`, `μ ← μ·dec` after an accepted step, `μ ← μ·inc`
    after a rejected one (Hagan & Menhaj 1994; defaults `dec = 0.1`, `inc = 10`)."""

    dec: float = 0.1
    inc: float = 10.0
    scaled: bool = False

    def __init__(self, dec: float = 0.1, inc: float = 10.0):
        if not 0 < dec < 1 < inc:
            raise ValueError(f"MarquardtDamping: need 0 < dec < 1 < inc; got {dec}, {inc}.")
        self.dec, self.inc = dec, inc

    def update(self, mu, nu, accept, gain):
        del gain
        return jnp.where(accept, mu * self.dec, mu * self.inc), nu


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


def _damped_step(jtj, jtr, mu, scaled: bool = True):
    """Solve `(JᵀJ + μ D) δ = -Jᵀr` by Cholesky: `D = diag(JᵀJ)` in unit-diagonal scaling
    (`scaled`), else `D = I`."""
    if not scaled:
        chol = jnp.linalg.cholesky(jtj + mu * jnp.eye(jtj.shape[0], dtype=jtj.dtype))
        return jax.scipy.linalg.cho_solve((chol, True), -jtr)
    d = jnp.diagonal(jtj)
    d = jnp.where(d > 0, d, 1.0)
    sc = 1.0 / jnp.sqrt(d)
    m = jtj * sc[:, None] * sc[None, :] + mu * jnp.eye(jtj.shape[0], dtype=jtj.dtype)
    chol = jnp.linalg.cholesky(m)
    y = jax.scipy.linalg.cho_solve((chol, True), -jtr * sc)
    return y * sc


def _finite(*xs) -> Array:
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in xs]))


def _newton_converged(theta, cost, jtj, jtr, rtol, atol=0.0) -> tuple[Array, Array]:
    """Convergence of the Gauss-Newton model at `θ` (no step needed), and the undamped
    Gauss-Newton step `δ = -(JᵀJ)⁻¹ Jᵀr` itself.

    `atol = 0`: the largest reduction the model predicts, `½ (Jᵀr)ᵀ (JᵀJ)⁻¹ Jᵀr`, is below
    `rtol · cost` (noisy data: parameters within a tiny fraction of their standard errors
    of the optimum, however flat some directions are), or `δ` is below `rtol` relative to
    `θ` in the unit-diagonal scaling (zero-residual data, where the relative reduction
    stays O(1) until rounding).

    `atol > 0` (a Python number): optimistix's Cauchy test, per entry
    `|δ_i| <= atol + rtol |θ_i|` (the solver [`LevenbergMarquardt`][], whose parameters
    `calibrate` normalises to O(1)); [`lm_step`][] then takes that last, tiny `δ`.
    """
    d = jnp.diagonal(jtj)
    sc = 1.0 / jnp.sqrt(jnp.where(d > 0, d, 1.0))
    m = jtj * sc[:, None] * sc[None, :] + 1e-13 * jnp.eye(jtj.shape[0], dtype=jtj.dtype)
    chol = jnp.linalg.cholesky(m)
    y = jax.scipy.linalg.cho_solve((chol, True), -jtr * sc)  # scaled Newton step
    delta = y * sc
    if atol > 0:
        ok = jnp.all(jnp.abs(delta) <= atol + rtol * jnp.abs(theta))
    else:
        pred = -0.5 * jnp.dot(jtr * sc, y)
        small_pred = pred <= rtol * cost
        small_step = jnp.linalg.norm(y) <= rtol * (jnp.linalg.norm(theta / sc) + rtol)
        ok = small_pred | small_step
    return _finite(y) & ok | (cost == 0), delta


def lm_init(evaluate, theta0: Array, args: Any, rtol, mu0: float = 1e-3, atol=0.0) -> LMState:
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
        converged=finite & _newton_converged(theta0, cost0, jtj0, jtr0, rtol, atol)[0],
        nonfinite=~finite,
    )


def lm_running(state: LMState, max_steps) -> Bool[Array, ""]:
    """Whether [`lm_step`][] should be called again."""
    return (~state.converged) & (~state.nonfinite) & (state.num_steps < max_steps)


def _always(theta) -> Array:
    return jnp.asarray(True)


def lm_step(
    evaluate,
    feasible,
    state: LMState,
    args: Any,
    rtol,
    damping: AbstractDamping = NielsenDamping(),
    cost: Callable | None = None,
    atol=0.0,
) -> LMState:
    """One trial step: solve, shorten to the feasible set, evaluate, accept or reject.

    **Arguments:**

    - `evaluate(θ, args) -> (cost, JᵀJ, Jᵀr)`: the normal equations, `cost = ½‖r‖²`.
    - `feasible(θ) -> bool` (or `None`): the open admissible set.
    - `state`, `args`: the iterate and the problem's data.
    - `rtol`: relative tolerance of the stopping rules (module doc); `atol`: absolute
      floor of the Newton step (converged when every entry is below it; default 0).
    - `damping`: the damping policy ([`NielsenDamping`][] or [`MarquardtDamping`][]).
    - `cost(θ, args) -> ½‖r‖²` (optional): a cheaper cost; the trial is then judged by it
      and the normal equations are formed only for an accepted trial (trainlm's epoch:
      several trials, one `JᵀJ`).
    """
    s = state
    feasible = _always if feasible is None else feasible
    delta = _damped_step(s.jtj, s.jtr, s.mu, damping.scaled)
    ok = jax.vmap(lambda t: feasible(s.theta + t * delta))(jnp.asarray(_FRACTIONS, delta.dtype))
    frac = jnp.max(jnp.where(ok, _FRACTIONS, 0.0))
    delta = frac * delta
    trial = s.theta + delta
    if cost is None:
        cost_t, jtj_t, jtr_t = evaluate(trial, args)
    else:
        cost_t = cost(trial, args)
        good = jnp.isfinite(cost_t) & (cost_t < s.cost) & (frac > 0)
        _, jtj_t, jtr_t = jax.lax.cond(
            good, lambda: evaluate(trial, args), lambda: (cost_t, s.jtj, s.jtr)
        )
    # Predicted reduction of the Gauss-Newton model: -(gᵀδ + ½ δᵀ JᵀJ δ) > 0.
    pred = -(jnp.dot(s.jtr, delta) + 0.5 * jnp.dot(delta, s.jtj @ delta))
    actual = s.cost - cost_t
    finite = _finite(cost_t, jtj_t, jtr_t, delta)
    accept = finite & (actual > 0) & (frac > 0)
    gain = actual / jnp.where(pred > 0, pred, 1.0)
    mu, nu = damping.update(s.mu, s.nu, accept, gain)
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
    if atol > 0:
        # optimistix's Cauchy test on the undamped Gauss-Newton step from the new θ (a step
        # kept small only by the damping is never taken for convergence); once it holds,
        # that last tiny step is taken: exact for a linear problem, quadratically small
        # error otherwise, and harmless at a noisy optimum where damped steps are rejected.
        newton, step = _newton_converged(theta, cost, jtj, jtr, rtol, atol)
        theta = jnp.where(newton & _finite(step), theta + step, theta)
        # A rejected step already inside the tolerance: no move that small lowers the
        # cost, so θ is stationary to rounding (a noisy, ill-conditioned optimum, where
        # the Newton step itself is rounding noise).
        # Not when the Gauss-Newton model still promises a real reduction: then the steps
        # failed because the residual turns NaN/inf just ahead (a wall on the path to the
        # optimum), and stopping would return a stale θ as a success. The damping keeps
        # growing instead and the fit ends as `nonfinite`. (heuristic: sqrt(rtol) of the
        # cost separates rounding noise at an optimum from a wall.)
        promised = -(jnp.dot(jtr, step) + 0.5 * jnp.dot(step, jtj @ step))
        stalled = (
            ~accept
            & finite
            & (promised <= jnp.sqrt(rtol) * cost)
            & jnp.all(jnp.abs(delta) <= atol + rtol * jnp.abs(s.theta))
        )
        converged = at_boundary | newton | stalled
    else:
        converged = at_boundary | _newton_converged(theta, cost, jtj, jtr, rtol)[0]
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


# ----------------------------------------------------------------------------- driver


class AbstractLMMonitor(eqx.Module):
    """What a fit watches beside the Levenberg-Marquardt iterate: a further stopping rule
    (early stopping on validation data, the end of trainlm's epoch) and the quantities it
    keeps (the best validated parameters). [`lm_solve`][] carries its state in the loop.
    """

    @abc.abstractmethod
    def init(self, state: LMState, args: Any) -> PyTree:
        """The monitor's state at the starting point."""

    @abc.abstractmethod
    def update(self, watch: PyTree, old: LMState, new: LMState, args: Any) -> PyTree:
        """The monitor's state after the step from `old` to `new`."""

    @abc.abstractmethod
    def running(self, watch: PyTree, state: LMState, args: Any) -> Bool[Array, ""]:
        """Whether the fit goes on (besides [`lm_running`][])."""


class BatchSchedule(eqx.Module):
    """The work compaction of [`batched_while`][] for a family of fits (heuristic: tune
    it on the family's sizes; the results do not depend on it)."""

    block: int = eqx.field(static=True, default=16)
    first_steps: int = eqx.field(static=True, default=10)
    tail_block: int = eqx.field(static=True, default=16)
    block_steps: int = eqx.field(static=True, default=5)


def _lm_loop(evaluate, feasible, rtol, damping, cost, monitor, max_steps):
    def cond(carry, args):
        state, watch = carry
        go = lm_running(state, max_steps)
        return go if monitor is None else go & monitor.running(watch, state, args)

    def body(carry, args):
        state, watch = carry
        new = lm_step(evaluate, feasible, state, args, rtol, damping, cost=cost)
        if monitor is not None:
            watch = monitor.update(watch, state, new, args)
        return new, watch

    return cond, body


def _lm_start(evaluate, theta0, args, rtol, mu0, monitor):
    state = theta0 if isinstance(theta0, LMState) else lm_init(evaluate, theta0, args, rtol, mu0)
    return state, (None if monitor is None else monitor.init(state, args))


def lm_solve(
    evaluate: Callable,
    theta0: Float[Array, " p"] | LMState,
    args: Any,
    *,
    max_steps: int,
    rtol: float,
    damping: AbstractDamping = NielsenDamping(),
    feasible: Callable | None = None,
    mu0: float = 1e-3,
    cost: Callable | None = None,
    monitor: AbstractLMMonitor | None = None,
) -> LMState | tuple[LMState, PyTree]:
    """Levenberg-Marquardt on one problem: [`lm_step`][] from `theta0` while
    [`lm_running`][] (and `monitor.running`) holds, in one `jax.lax.while_loop`.

    **Arguments:**

    - `evaluate(θ, args) -> (½‖r‖², JᵀJ, Jᵀr)`: the normal equations (module doc;
      [`jacobian_normal_equations`][] forms them from a residual).
    - `theta0`: the flat starting parameters, or an [`LMState`][] to go on from (its
      damping kept).
    - `args`: the problem's data, passed to `evaluate`, `feasible`'s caller and `cost`.
    - `max_steps`: the most trial steps; `rtol`: the relative tolerance of the stopping
      rules (module doc).
    - `damping`: [`NielsenDamping`][] (default) or [`MarquardtDamping`][].
    - `feasible(θ) -> bool`: the open admissible set (default: everywhere).
    - `mu0`: the initial damping (a fresh start only).
    - `cost(θ, args) -> ½‖r‖²`: a cheaper cost judging the trials ([`lm_step`][]).
    - `monitor`: an [`AbstractLMMonitor`][] with a further stopping rule.

    **Returns:**

    The final [`LMState`][] (its status by [`lm_result`][]); with a `monitor`, the pair
    `(state, monitor state)`.
    """
    cond, body = _lm_loop(evaluate, feasible, rtol, damping, cost, monitor, max_steps)
    carry = _lm_start(evaluate, theta0, args, rtol, mu0, monitor)
    state, watch = jax.lax.while_loop(lambda c: cond(c, args), lambda c: body(c, args), carry)
    return state if monitor is None else (state, watch)


def lm_solve_family(
    evaluate: Callable,
    theta0: Float[Array, "member p"] | LMState,
    args: Any,
    *,
    max_steps: int,
    rtol: float,
    schedule: BatchSchedule = BatchSchedule(),
    damping: AbstractDamping = NielsenDamping(),
    feasible: Callable | None = None,
    mu0: float = 1e-3,
    monitor: AbstractLMMonitor | None = None,
) -> LMState | tuple[LMState, PyTree]:
    """[`lm_solve`][] for a family of problems of one shape, with the work compaction of
    [`batched_while`][] (`schedule`). `theta0` (flat parameters or an [`LMState`][] to go
    on from) and the leaves of `args` carry the family axis first; the results do too,
    each member's equal to its own [`lm_solve`][] (a family of one runs exactly that)."""
    cond, body = _lm_loop(evaluate, feasible, rtol, damping, None, monitor, max_steps)
    carry = jax.vmap(lambda t, a: _lm_start(evaluate, t, a, rtol, mu0, monitor))(theta0, args)
    if jax.tree_util.tree_leaves(theta0)[0].shape[0] == 1:
        one = lambda x: x[0]
        a0 = jax.tree_util.tree_map(one, args)
        final = jax.lax.while_loop(
            lambda c: cond(c, a0), lambda c: body(c, a0), jax.tree_util.tree_map(one, carry)
        )
        final = jax.tree_util.tree_map(lambda x: x[None], final)
    else:
        final = batched_while(
            cond,
            body,
            carry,
            args,
            block=schedule.block,
            first_steps=schedule.first_steps,
            tail_block=schedule.tail_block,
            block_steps=schedule.block_steps,
        )
    return final[0] if monitor is None else final


# ----------------------------------------------------------------------------- optimistix


def jacobian_normal_equations(fn: Callable) -> Callable:
    """`evaluate(θ, args) -> (½‖r‖², JᵀJ, Jᵀr)` from a residual `fn(θ, args) -> r` on a
    flat `θ`, with the Jacobian in forward mode (one JVP per parameter)."""

    def evaluate(theta, args):
        r, jac = jax.vmap(
            lambda v: jax.jvp(lambda t: fn(t, args), (theta,), (v,)), out_axes=(None, 0)
        )(jnp.eye(theta.shape[0], dtype=theta.dtype))
        return 0.5 * jnp.sum(r**2), jac @ jac.T, jac @ r

    return evaluate


class _SolverState(eqx.Module):
    lm: LMState
    has_aux: bool = eqx.field(static=True)


class LevenbergMarquardt(optx.AbstractLeastSquaresSolver):
    """The jaxvs Levenberg-Marquardt as an optimistix least-squares solver.

    Use it anywhere optimistix takes a solver (`optimistix.least_squares`, and
    `jaxvs.calibrate`, where it is the default). It steps with [`lm_step`][] (module doc:
    scaled damping, Nielsen's update, relative stopping rules).

    **Arguments:**

    - `rtol`: relative tolerance of the stopping rule (below).
    - `atol`: with `atol > 0` (default `1e-8`) the stopping rule is optimistix's Cauchy
      test on the Gauss-Newton step, per entry `|δ_i| <= atol + rtol |θ_i|`; with
      `atol = 0` the relative rules of the module doc.
    - `damping`: [`NielsenDamping`][] (default: `scaled=False`, Levenberg's `D = I` on
      the normalised parameters of `calibrate`) or [`MarquardtDamping`][].
    - `mu0`: initial damping `τ`; with `D = I` the damping starts at `τ max diag(JᵀJ)`
      (default `τ = 1`: a cautious first step, as the weakly determined directions of a
      calibration need).
    - `norm`: the norm optimistix reports with (unused by the stopping rules).

    `options` of the solve may hold `"normal_equations"`, a structured
    `evaluate(θ, args) -> (½‖r‖², JᵀJ, Jᵀr)` on the flattened parameters (default: from
    forward-mode Jacobians), and `"feasible"`, a predicate of the flattened parameters
    (steps are shortened to stay inside).
    """

    rtol: float
    atol: float
    norm: Callable[[PyTree], Array] = optx.max_norm
    damping: AbstractDamping = NielsenDamping(scaled=False)
    mu0: float = 1.0

    def __init__(
        self,
        rtol: float = 1e-8,
        atol: float = 1e-8,
        damping: AbstractDamping = NielsenDamping(scaled=False),
        norm: Callable[[PyTree], Array] = optx.max_norm,
        mu0: float = 1.0,
    ):
        if not rtol > 0:
            raise ValueError(f"LevenbergMarquardt: rtol must be > 0; got {rtol!r}.")
        if not atol >= 0:
            raise ValueError(f"LevenbergMarquardt: atol must be >= 0; got {atol!r}.")
        self.rtol, self.atol, self.damping, self.norm = float(rtol), float(atol), damping, norm
        self.mu0 = float(mu0)

    def _problem(self, fn, y, args, options):
        options = {} if options is None else options
        flat, unravel = ravel_pytree(y)

        def residual(theta, a):
            r, _ = fn(unravel(theta), a)
            return ravel_pytree(r)[0]

        evaluate = options.get("normal_equations") or jacobian_normal_equations(residual)
        return flat, unravel, evaluate, options.get("feasible")

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        flat, _, evaluate, _ = self._problem(fn, y, args, options)
        state = lm_init(evaluate, flat, args, self.rtol, self.mu0, atol=self.atol)
        if not self.damping.scaled:
            # D = I: the damping relative to the largest curvature, μ0 = τ max diag(JᵀJ)
            # (Madsen, Nielsen & Tingleff 2004, §3.2), so the first step does not depend
            # on the units of the residual.
            d = jnp.max(jnp.diagonal(state.jtj))
            mu = self.mu0 * jnp.where(jnp.isfinite(d) & (d > 0), d, 1.0)
            state = eqx.tree_at(lambda st: st.mu, state, mu.astype(state.mu.dtype))
        return _SolverState(state, aux_struct is not None)

    def step(self, fn, y, args, options, state, tags):
        _, unravel, evaluate, feasible = self._problem(fn, y, args, options)
        lm = lm_step(evaluate, feasible, state.lm, args, self.rtol, self.damping, atol=self.atol)
        y_new = unravel(lm.theta)
        aux = fn(y_new, args)[1] if state.has_aux else None
        return y_new, _SolverState(lm, state.has_aux), aux

    def terminate(self, fn, y, args, options, state, tags):
        lm = state.lm
        done = lm.converged | lm.nonfinite
        result = optx.RESULTS.where(lm.nonfinite, optx.RESULTS.nonfinite, optx.RESULTS.successful)
        return done, result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {"num_steps": state.lm.num_steps}
