r"""Simulation-error calibration by multiple shooting for state-space simulators.

A free-run (output-error) fit of a model with a pure integrator, friction or a slow mode
over a long record is a hard least-squares problem: a small parameter change moves the
simulated trajectory far away late in the record, so the cost is rugged and the solver
stalls in local minima. **Multiple shooting** (Bock & Plitt 1984, *A multiple shooting
algorithm for direct solution of optimal control problems*, IFAC 9th World Congress;
for system identification: Ribeiro, Tiels, Umenberger, Schön, Aguirre 2020, "On the
smoothness of nonlinear system identification", Automatica 121) cuts the record into
`S` segments of `L` samples, gives each segment its own free initial state `x_s`, and
adds a continuity residual between the end of segment `s` and the start of `s + 1`:

    min_{θ, x_1..x_S}  Σ_s ‖(y_s(θ, x_s) − y_s^meas) / σ_y‖²
                     + ρ² Σ_{s<S} ‖(x_s^end(θ, x_s) − x_{s+1}) / σ_x‖².

Each segment is short, so the cost is smooth; the continuity term ties the segments into
one trajectory as `ρ` grows. The one Levenberg–Marquardt of `jaxvs.calibration`
(`lm_solve`) solves it from its normal equations; the Jacobian is built per
segment (forward mode, `p + n_x` directions on `L` samples each) and assembled in its
block structure, so a step costs `O(S·L·(p + n_x))` simulations steps instead of
`O(S·L·(p + S·n_x))`.
"""

from __future__ import annotations

import abc
import dataclasses
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, ArrayLike, Float, Int

from ..._misc import options_object
from ...calibration import RESULTS, free_spec, lm_init, lm_result, lm_solve

__all__ = ["AbstractSimulator", "ShootingOptions", "ShootingResult", "fit_multiple_shooting"]


class AbstractSimulator(eqx.Module):
    """A state-space model that predicts outputs from inputs by free-run simulation.

    Subclasses implement `simulate`, `output` and `initial_state`; `__call__` is then the
    benchmark predictor `model(u, y_init) -> y` (see `score_predictor`).
    """

    @abc.abstractmethod
    def simulate(
        self, u: Float[Array, "time input"], x0: Float[Array, " state"]
    ) -> Float[Array, "time state"]:
        """States at every sample `k` (before input `u_k` acts), starting from `x0` at `k = 0`."""

    @abc.abstractmethod
    def output(self, x: Float[Array, "time state"]) -> Float[Array, "time output"]:
        """Outputs of a sequence of states."""

    @abc.abstractmethod
    def initial_state(self, y_init: Float[Array, "init output"]) -> Float[Array, " state"]:
        """The state at the LAST sample of a window of measured outputs."""

    def __call__(
        self, u: Float[ArrayLike, "time input"], y_init: Float[ArrayLike, "init output"]
    ) -> Float[Array, "time output"]:
        """Free-run prediction of a whole record from its input and the first
        `len(y_init)` output samples (returned unchanged but the last, which the state
        estimate replaces)."""
        u = jnp.asarray(u)
        y_init = jnp.asarray(y_init)
        if u.ndim != 2 or y_init.ndim != 2:
            raise ValueError(
                f"{type(self).__name__}: u must be (time, input) and y_init (init, output); "
                f"got {u.shape} and {y_init.shape}."
            )
        n0 = y_init.shape[0]
        if n0 < 1 or n0 >= u.shape[0]:
            raise ValueError(
                f"{type(self).__name__}: y_init must hold 1 to time-1 samples (the state "
                f"estimate needs at least one); got {n0} for {u.shape[0]} samples."
            )
        return _predict(self, u, y_init)


@eqx.filter_jit
def _predict(model: AbstractSimulator, u, y_init):
    n0 = y_init.shape[0]
    x0 = model.initial_state(y_init)
    y = model.output(model.simulate(u[n0 - 1 :], x0))
    return jnp.concatenate([y_init[: n0 - 1], y], axis=0)


class ShootingResult(eqx.Module):
    """The outcome of [`fit_multiple_shooting`][].

    **Fields:**

    - `model`: the calibrated model.
    - `initial_states`: `(segment, state)` calibrated initial state of every segment.
    - `starts`: `(segment,)` first sample of every segment.
    - `result`: a `RESULTS` code (`successful`, `max_steps_reached`, `nonfinite`).
    - `cost`: final `½‖r‖²` (scaled residuals); `initial_cost` at the start.
    - `num_steps`: Levenberg–Marquardt steps taken.
    - `n_parameters`: number of calibrated model parameters (segment states excluded).
    - `compile_s`, `run_s`: compile time and run time of the solve [s].
    """

    model: Any
    initial_states: Float[Array, "segment state"]
    starts: Int[Array, " segment"]
    result: RESULTS
    cost: Float[Array, ""]
    initial_cost: Float[Array, ""]
    num_steps: Int[Array, ""]
    n_parameters: int = eqx.field(static=True)
    compile_s: float = eqx.field(static=True)
    run_s: float = eqx.field(static=True)


@dataclasses.dataclass(frozen=True)
class ShootingOptions:
    """The segmentation, scaling and solver settings of [`fit_multiple_shooting`][].

    **Fields:**

    - `segment_length`: samples per segment `L` (>= 2); the number of segments is
      `(time − init_window) // L`, the remaining samples at the end are not used.
    - `init_window`: output samples used by each segment's initial-state guess (>= 1).
    - `output_scale`: `σ_y`, the output error that counts as 1 (e.g. 1e-3 m: residuals
      in mm), a scalar or one per output.
    - `state_scale`: `σ_x`, the state mismatch that counts as 1 at a segment joint (a
      scalar or one per state; default `output_scale` for every state).
    - `continuity`: `ρ`, the weight of the continuity residuals (> 0).
    - `free_states`: calibrate the segments' initial states (multiple shooting); with
      `False` they stay at their `initial_state` estimates. One segment with fixed state
      is plain free-run (single-shooting) output error, exactly the benchmark protocol
      (`segment_length = time − init_window`).
    - `max_steps`, `rtol`: Levenberg–Marquardt budget and relative tolerance.
    """

    segment_length: int = 1000
    init_window: int = 20
    output_scale: Any = 1.0
    state_scale: Any = None
    continuity: float = 1.0
    free_states: bool = True
    max_steps: int = 100
    rtol: float = 1e-8


def fit_multiple_shooting(
    model: AbstractSimulator,
    u: Float[ArrayLike, "time input"],
    y: Float[ArrayLike, "time output"],
    *,
    free: Any = None,
    feasible: Callable[[Any], Any] | None = None,
    weights: Float[ArrayLike, " time"] | None = None,
    throw: bool = True,
    options: ShootingOptions | None = None,
    **keywords: Any,
) -> ShootingResult:
    r"""Calibrate a simulator on one record by multiple-shooting simulation error.

    The record is cut into segments of `segment_length` samples starting at sample
    `init_window − 1` (the first state is where a free-run prediction with that window
    would start). Each segment's initial state starts from `model.initial_state` on the
    `init_window` measured outputs that end at its first sample, and is calibrated with
    the model's free parameters.

    **Arguments:**

    - `model`: an [`AbstractSimulator`][], the initial guess.
    - `u`, `y`: `(time, input)` input and `(time, output)` measured output.
    - `free`: which leaves of `model` are calibrated, as for `jaxvs.calibrate`
      (`None` = every floating-point array; a where-function; a filter spec).
    - `feasible`: optional predicate `model -> bool` (a traced boolean) of admissible
      parameters (e.g. a positive mass); a step that leaves it is shortened.
    - `weights`: optional `(time,)` weights `>= 0` of the output residuals (default 1).
      A zero weight takes a sample out of the fit while the simulation still runs through
      it: hold out a span of the record (cross-validation) and let the states evolve
      over it as they would in a free run.
    - `throw`: raise `RuntimeError` when the solve ends with NaN (non-convergence within
      `max_steps` is reported in `result`, not raised).
    - `options`: the segmentation, scaling and solver settings, a [`ShootingOptions`][],
      or its fields as keywords (`segment_length=400`, ...).

    **Returns:**

    A [`ShootingResult`][].

    **Raises:**

    `ValueError` for mismatched or too short data, or invalid options; `RuntimeError`
    when the simulation becomes NaN and `throw=True`.
    """
    where = "fit_multiple_shooting"
    o = options_object(ShootingOptions, options, keywords, where)
    segment_length, init_window, continuity = o.segment_length, o.init_window, o.continuity
    output_scale, state_scale, free_states = o.output_scale, o.state_scale, o.free_states
    max_steps, rtol = o.max_steps, o.rtol
    if not isinstance(model, AbstractSimulator):
        raise TypeError(f"{where}: model must be an AbstractSimulator; got {type(model).__name__}.")
    u = jnp.asarray(u, dtype=float)
    y = jnp.asarray(y, dtype=float)
    if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
        raise ValueError(
            f"{where}: u and y must be (time, input) and (time, output) arrays of equal "
            f"length; got {u.shape} and {y.shape}."
        )
    if not (jnp.all(jnp.isfinite(u)) and jnp.all(jnp.isfinite(y))):
        raise ValueError(f"{where}: NaN or inf in u or y; clean the record first.")
    if not isinstance(segment_length, int) or segment_length < 2:
        raise ValueError(f"{where}: segment_length must be an int >= 2; got {segment_length!r}.")
    if not isinstance(init_window, int) or init_window < 1:
        raise ValueError(f"{where}: init_window must be an int >= 1; got {init_window!r}.")
    if not continuity > 0:
        raise ValueError(f"{where}: continuity must be > 0; got {continuity!r}.")
    if not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"{where}: max_steps must be an int >= 1; got {max_steps!r}.")
    n = u.shape[0]
    k0 = init_window - 1
    n_seg = (n - 1 - k0) // segment_length
    if n_seg < 1:
        raise ValueError(
            f"{where}: {n} samples hold no segment of {segment_length} samples after the "
            f"{init_window}-sample window; shorten segment_length."
        )
    if weights is None:
        w = jnp.ones(n)
    else:
        w = jnp.asarray(weights, dtype=float)
        if w.shape != (n,) or not bool(jnp.all(w >= 0)) or not bool(jnp.any(w > 0)):
            raise ValueError(
                f"{where}: weights must be a ({n},) array of values >= 0, not all 0 (one "
                f"per sample of y); got shape {w.shape}."
            )
    L = segment_length
    starts = k0 + L * np.arange(n_seg)
    # inputs u[k_s .. k_s + L] give L + 1 states at k_s .. k_s + L (the last one is the
    # state the next segment starts from)
    u_seg = jnp.stack([u[s : s + L + 1] for s in starts])
    y_seg = jnp.stack([y[s : s + L] for s in starts])
    w_seg = jnp.stack([w[s : s + L] for s in starts])
    windows = jnp.stack([y[s - k0 : s + 1] for s in starts])
    x_guess = jax.vmap(model.initial_state)(windows)
    n_x = x_guess.shape[1]
    n_y = y.shape[1]
    sy = jnp.broadcast_to(jnp.asarray(output_scale, dtype=float), (n_y,))
    sx = sy[0] * jnp.ones(n_x) if state_scale is None else jnp.asarray(state_scale, float)
    sx = jnp.broadcast_to(sx, (n_x,))
    if not (jnp.all(sy > 0) and jnp.all(sx > 0)):
        raise ValueError(f"{where}: output_scale and state_scale must be > 0.")

    spec = free_spec(model, free)
    params, static = eqx.partition(model, spec)
    theta0, unravel = ravel_pytree(params)
    p = theta0.shape[0]
    if p == 0:
        raise ValueError(f"{where}: no free parameters; check `free`.")
    # heuristic: solve for θ / |θ0| (1 where θ0 = 0) and x / σ_x so that all unknowns are
    # O(1) for the relative stopping rules; LM's own diagonal scaling does the rest.
    th_scale = jnp.where(theta0 == 0, 1.0, jnp.abs(theta0))
    xs_fixed = x_guess / sx
    z0 = theta0 / th_scale
    if free_states:
        z0 = jnp.concatenate([z0, xs_fixed.ravel()])
    is_ok = (lambda m: True) if feasible is None else feasible

    def build(th):
        return eqx.combine(unravel(th * th_scale), static)

    def segment(zs, us, ys, ws):
        th, xs = zs[:p], zs[p:] * sx
        states = build(th).simulate(us, xs)
        fit = (build(th).output(states[:-1]) - ys) / sy * ws[:, None]
        return fit.ravel(), states[-1] / sx

    def evaluate(z, args):
        us, ys, ws, fixed = args
        th = z[:p]
        xs = z[p:].reshape(n_seg, n_x) if free_states else fixed
        zs = jnp.concatenate([jnp.broadcast_to(th, (n_seg, p)), xs], axis=1)

        def with_jac(zz, uu, yy, ww):
            out = segment(zz, uu, yy, ww)
            jac = jax.jacfwd(segment)(zz, uu, yy, ww)
            return out, jac

        (fit, end), (j_fit, j_end) = jax.vmap(with_jac)(zs, us, ys, ws)
        eye = jnp.eye(n_seg, dtype=z.dtype)
        m = fit.shape[1]
        # fit rows: global columns, then this segment's state columns (block diagonal)
        jf = jnp.concatenate(
            [
                j_fit[:, :, :p].reshape(n_seg * m, p),
                jnp.einsum("sij,st->sitj", j_fit[:, :, p:], eye).reshape(n_seg * m, n_seg * n_x),
            ],
            axis=1,
        )
        r = [fit.ravel()]
        jac = [jf]
        if n_seg > 1:
            # continuity rows c_s = ρ (x_s^end − x_{s+1}) for s < S − 1
            je = j_end[:-1]
            jc_x = jnp.einsum("sij,st->sitj", je[:, :, p:], eye[:-1]) - jnp.einsum(
                "ij,st->sitj", jnp.eye(n_x, dtype=z.dtype), eye[1:]
            )
            jc = continuity * jnp.concatenate(
                [
                    je[:, :, :p].reshape((n_seg - 1) * n_x, p),
                    jc_x.reshape((n_seg - 1) * n_x, n_seg * n_x),
                ],
                axis=1,
            )
            r.append(continuity * (end[:-1] - xs[1:]).ravel())
            jac.append(jc)
        r = jnp.concatenate(r)
        jac = jnp.concatenate(jac, axis=0)
        if not free_states:
            jac = jac[:, :p]
        return 0.5 * r @ r, jac.T @ jac, jac.T @ r

    def feasible_z(z):
        return jnp.asarray(is_ok(build(z[:p])))

    def solve(z0, us, ys, ws, fixed):
        args = (us, ys, ws, fixed)
        state = lm_init(evaluate, z0, args, rtol)
        initial = state.cost
        state = lm_solve(evaluate, state, args, max_steps=max_steps, rtol=rtol, feasible=feasible_z)
        return state, initial

    start = time.perf_counter()
    compiled = jax.jit(solve).lower(z0, u_seg, y_seg, w_seg, xs_fixed).compile()
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    state, initial = compiled(z0, u_seg, y_seg, w_seg, xs_fixed)
    jax.block_until_ready(state)
    run_s = time.perf_counter() - start
    result = lm_result(state)
    if throw and bool(state.nonfinite | ~jnp.isfinite(state.cost)):
        raise RuntimeError(
            f"{where}: the simulation became NaN or inf during the solve; start closer to "
            "the solution, shorten segment_length, or add substeps to the simulator."
        )
    z = state.theta
    return ShootingResult(
        model=build(z[:p]),
        initial_states=(z[p:].reshape(n_seg, n_x) if free_states else xs_fixed) * sx,
        starts=jnp.asarray(starts),
        result=result,
        cost=state.cost,
        initial_cost=initial,
        num_steps=state.num_steps,
        n_parameters=int(p),
        compile_s=compile_s,
        run_s=run_s,
    )
