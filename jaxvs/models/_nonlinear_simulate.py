r"""Time-stepping engines for nonlinear ODE models (drives with friction, backlash, saturation).

Two engines, both built on diffrax solvers and both differentiable in forward mode (so
that Levenberg–Marquardt can build Jacobians of a simulation) and batched by `jax.vmap`
(one call simulates a whole family of parameter variants):

- [`solve_ode`][]: `diffrax.diffeqsolve` of `y' = f(t, y, args)` saved at given times,
  adaptive (PID step-size control) or fixed step, with `diffrax.ForwardMode()` as the
  default adjoint (the one Levenberg–Marquardt needs, STYLE.md).
- [`solve_sampled`][]: a sampled-data loop -- a discrete controller computes a command at
  every sample instant `t_k = k·dt` from the state, holds it (zero-order hold) over
  `[t_k, t_{k+1})`, and the continuous plant is integrated over the interval by a fixed
  number of explicit diffrax solver steps. This is how a digital drive controller (the
  1 kHz dSPACE loop of the EMPS) really acts on the axis; `lax.scan` over the samples.

A fixed explicit step is only stable when every eigenvalue `λ` of the plant's Jacobian
satisfies `|R(λh)| <= 1` (`R` the solver's stability function): [`check_step`][]
evaluates `R` on the actual solver and raises a clear error for a stiff model (a finely
distributed ball screw, a very sharp friction law) with too large a step.
"""

from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PyTree

__all__ = [
    "ODEOptions",
    "amplification",
    "check_step",
    "finite_or_error",
    "solve_ode",
    "solve_sampled",
    "zoh_interval",
]

_SOLVERS: dict[str, Callable[[], diffrax.AbstractSolver]] = {
    "euler": diffrax.Euler,
    "heun": diffrax.Heun,
    "midpoint": diffrax.Midpoint,
    "bosh3": diffrax.Bosh3,
    "tsit5": diffrax.Tsit5,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
    "kvaerno5": diffrax.Kvaerno5,
}


def _solver(solver: Any, where: str) -> diffrax.AbstractSolver:
    if solver is None:
        solver = diffrax.Tsit5()
    elif isinstance(solver, str):
        if solver.lower() not in _SOLVERS:
            raise ValueError(
                f"{where}: unknown solver {solver!r}; use one of {sorted(_SOLVERS)} or a "
                "diffrax solver instance."
            )
        solver = _SOLVERS[solver.lower()]()
    elif not isinstance(solver, diffrax.AbstractSolver):
        raise TypeError(
            f"{where}: solver must be a diffrax solver (e.g. diffrax.Tsit5()) or a name; got "
            f"{type(solver).__name__}."
        )
    # Runge-Kutta stages default to a checkpointed loop (a custom VJP), which forward-mode
    # differentiation (Levenberg-Marquardt Jacobians) cannot pass; a plain lax loop can.
    if getattr(solver, "scan_kind", "lax") is None:
        solver = eqx.tree_at(lambda s: s.scan_kind, solver, "lax", is_leaf=lambda x: x is None)
    return solver


class ODEOptions(eqx.Module):
    """The rarely changed settings of [`solve_ode`][].

    **Fields:**

    - `max_steps`: step budget; exceeding it is an error (stiff model, or a simulation
      that diverges) unless `throw=False`.
    - `adjoint`: differentiation through the solve; default `diffrax.ForwardMode()`
      (forward-mode Jacobians, as `jaxvs.calibrate`'s Levenberg–Marquardt needs). Use
      `diffrax.RecursiveCheckpointAdjoint()` for reverse-mode gradient methods.
    - `jump_ts`: times where the inputs jump (the step controller restarts there).
    """

    max_steps: int = eqx.field(static=True, default=200_000)
    adjoint: diffrax.AbstractAdjoint | None = None
    jump_ts: Float[ArrayLike, " jump"] | None = None


def solve_ode(
    vector_field: Callable[[Any, PyTree, Any], PyTree],
    y0: PyTree[ArrayLike],
    ts: Float[ArrayLike, " time"],
    args: Any = None,
    *,
    solver: Any = None,
    dt: float | None = None,
    rtol: float = 1e-7,
    atol: float = 1e-10,
    throw: bool = True,
    options: ODEOptions = ODEOptions(),
) -> PyTree[Float[Array, "time ..."]]:
    r"""Solve `y' = vector_field(t, y, args)` from `y(ts[0]) = y0` and return `y(ts)`.

    **Arguments:**

    - `vector_field`: `f(t, y, args) -> dy/dt` (a pure function of pytrees of arrays).
    - `y0`: initial state (pytree of arrays).
    - `ts`: `(time,)` increasing save times [s]; the solve runs from `ts[0]` to `ts[-1]`.
    - `args`: anything `vector_field` needs (parameters, sampled inputs).
    - `solver`: a diffrax solver or a name (`"tsit5"` default, `"dopri5"`, `"heun"`,
      `"kvaerno5"` for stiff models, ...).
    - `dt`: `None` for adaptive steps (PID control with `rtol`, `atol`), or a fixed step
      [s] (checked for stability with [`check_step`][] by the drive models).
    - `rtol`, `atol`: tolerances of the adaptive step-size controller.
    - `throw`: raise on solver failure (also under `jit`); with `False` the failed
      samples are NaN.
    - `options`: the step budget, the adjoint and the input jumps ([`ODEOptions`][]).

    **Returns:**

    The states at `ts`, each leaf with a leading `(time,)` axis. Batch by `jax.vmap`.
    """
    where = "solve_ode"
    solver = _solver(solver, where)
    ts = jnp.asarray(ts)
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ValueError(f"{where}: ts must be 1-D with >= 2 save times; got shape {ts.shape}.")
    if not isinstance(options, ODEOptions):
        raise TypeError(f"{where}: options must be a jaxvs.models.ODEOptions; got {options!r}.")
    adjoint, max_steps = options.adjoint, options.max_steps
    if dt is None:
        controller = diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=options.jump_ts)
        dt0 = None
    else:
        if not dt > 0:
            raise ValueError(f"{where}: the fixed step dt must be > 0 s; got {dt}.")
        controller = diffrax.ConstantStepSize()
        dt0 = dt
    if adjoint is None:
        adjoint = diffrax.ForwardMode()
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        solver,
        t0=ts[0],
        t1=ts[-1],
        dt0=dt0,
        y0=y0,
        args=args,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller,
        adjoint=adjoint,
        max_steps=max_steps,
        throw=throw,
    )
    return sol.ys


def solve_sampled(
    plant: Callable[[Any, PyTree, Any], PyTree],
    controller: Callable[[PyTree, PyTree, Any, Any], tuple[PyTree, PyTree]],
    y0: PyTree[ArrayLike],
    c0: PyTree[ArrayLike],
    inputs: PyTree[Float[ArrayLike, "time ..."]],
    dt: float,
    args: Any = None,
    *,
    n_substeps: int = 4,
    solver: Any = None,
) -> tuple[PyTree[Float[Array, "time ..."]], PyTree[Float[Array, "time ..."]]]:
    r"""Sampled-data simulation: a discrete controller with zero-order hold on a
    continuous plant.

    At every sample `k` (time `t_k = k·dt`):

    1. `u_k, c_{k+1} = controller(c_k, y(t_k), inputs_k, args)`;
    2. `y(t_{k+1})` from `y(t_k)` by `n_substeps` steps of the explicit `solver` on
       `y' = plant(t, y, (u_k, args))`, `u_k` held constant.

    **Arguments:**

    - `plant`: `plant(t, y, (u, args)) -> dy/dt`.
    - `controller`: `controller(c, y, inputs_k, args) -> (u, c_next)`; `c` is the
      controller's memory (integrators, past measurements).
    - `y0`, `c0`: initial plant state and controller memory (pytrees of arrays).
    - `inputs`: pytree of sampled inputs with a leading `(time,)` axis (references, feed
      forward, disturbances); its length is the number of samples simulated.
    - `dt`: sample time [s] (Python float).
    - `args`: parameters shared by `plant` and `controller`.
    - `n_substeps`: solver steps per sample (static, >= 1).
    - `solver`: an explicit diffrax Runge–Kutta solver or a name (default `"tsit5"`).

    **Returns:**

    `(ys, us)`: the plant state at every `t_k` (before `u_k` acts) and the commands
    `u_k`, each leaf with a leading `(time,)` axis.
    """
    where = "solve_sampled"
    solver = _solver(solver, where)
    if not isinstance(n_substeps, int) or n_substeps < 1:
        raise ValueError(f"{where}: n_substeps must be an int >= 1; got {n_substeps!r}.")
    if not dt > 0:
        raise ValueError(f"{where}: dt must be > 0 s; got {dt}.")
    def interval(y, t0, u):
        return zoh_interval(plant, y, u, args, dt, n_substeps, solver, t0=t0)

    def body(carry, xs):
        y, c = carry
        k, inp = xs
        u, c_next = controller(c, y, inp, args)
        y_next = interval(y, k * dt, u)
        return (y_next, c_next), (y, u)

    n = jax.tree_util.tree_leaves(inputs)[0].shape[0]
    _, (ys, us) = jax.lax.scan(body, (y0, c0), (jnp.arange(n), inputs))
    return ys, us


def zoh_interval(
    plant: Callable[[Any, PyTree, Any], PyTree],
    y: PyTree,
    u: PyTree,
    args: Any,
    dt: float,
    n_substeps: int,
    solver: Any = None,
    *,
    t0: Any = 0.0,
) -> PyTree:
    """`y(t0 + dt)` from `y(t0)` under the held command `u`: `n_substeps` steps of the
    explicit `solver` on `y' = plant(t, y, (u, args))` (one interval of [`solve_sampled`][]).
    """
    solver = _solver(solver, "zoh_interval")
    term = diffrax.ODETerm(plant)
    h = dt / n_substeps
    a = (u, args)
    state = solver.init(term, t0, t0 + h, y, a)

    def sub(carry, j):
        y, state = carry
        t = t0 + j * h
        y1, _, _, state, _ = solver.step(term, t, t + h, y, a, state, made_jump=False)
        return (y1, state), None

    (y, _), _ = jax.lax.scan(sub, (y, state), jnp.arange(n_substeps))
    return y


def amplification(
    eigenvalues: ArrayLike, h: float, solver: Any = None
) -> np.ndarray:
    r"""`|R(λh)|`: the factor by which one step of `solver` multiplies the mode
    `e^{λt}` of a linear ODE, for every eigenvalue `λ` [1/s].

    Computed by running the actual solver for one step on the real 2×2 system
    `[[Re λ, −Im λ], [Im λ, Re λ]]` (a normal matrix, so the growth of its state norm is
    `|R(λh)|` exactly). `|R| <= 1` is needed for a stable fixed-step simulation.

    **Arguments:**

    - `eigenvalues`: complex eigenvalues of the plant's Jacobian [1/s].
    - `h`: step [s], a scalar or one per eigenvalue.
    - `solver`: an explicit diffrax solver or a name (default `"tsit5"`).

    **Returns:**

    NumPy array of `|R(λh)|`, one per eigenvalue.
    """
    solver = _solver(solver, "amplification")
    lam = np.asarray(eigenvalues, dtype=complex).ravel()
    if lam.size == 0:
        return np.zeros(0)
    mats = np.stack([np.array([[z.real, -z.imag], [z.imag, z.real]]) for z in lam])
    hs = np.broadcast_to(np.asarray(h, dtype=float), lam.shape)
    return np.asarray(_amplification(solver, jnp.asarray(mats), jnp.asarray(hs)))


@eqx.filter_jit
def _amplification(solver, mats, hs):
    term = diffrax.ODETerm(lambda t, y, a: a @ y)

    def one(a, h):
        y0 = jnp.array([1.0, 0.0], a.dtype)
        state = solver.init(term, 0.0, h, y0, a)
        y1 = solver.step(term, 0.0, h, y0, a, state, made_jump=False)[0]
        return jnp.linalg.norm(y1)

    return jax.vmap(one)(mats, hs)


def check_step(
    eigenvalues: ArrayLike, h: float, solver: Any = None, *, where: str = "simulate"
) -> None:
    """Raise `ValueError` when a fixed step `h` is unstable for any plant eigenvalue.

    **Arguments:**

    - `eigenvalues`: complex eigenvalues of the plant's Jacobian [1/s] (concrete).
    - `h`: step [s].
    - `solver`: the explicit solver (default `"tsit5"`).
    - `where`: name of the caller, for the message.

    **Raises:**

    `ValueError` naming the fastest offending mode and the largest stable step.
    """
    lam = np.asarray(eigenvalues, dtype=complex).ravel()
    lam = lam[np.isfinite(lam)]
    if lam.size == 0:
        return
    amp = amplification(lam, h, solver)
    # heuristic: 1e-9 above 1 is rounding of a marginal (undamped or rigid-body) mode.
    bad = amp > 1 + 1e-9
    if not bad.any():
        return
    worst = lam[bad][np.argmax(np.abs(lam[bad]))]
    # largest stable step for that eigenvalue, on a fine grid of steps (one vectorised call)
    grid = h * np.geomspace(1e-6, 1.0, 400)
    stable = amplification(np.full(grid.shape, worst), grid, solver) <= 1 + 1e-9
    lo = grid[np.flatnonzero(stable)[-1]] if stable.any() else grid[0]
    name = type(_solver(solver, where)).__name__
    raise ValueError(
        f"{where}: the fixed step h = {h:.3g} s is unstable for the {name} solver: the "
        f"model has a fast mode λ = {worst.real:.4g}{worst.imag:+.4g}j 1/s "
        f"(|λ|/2π = {abs(worst) / (2 * np.pi):.4g} Hz) and a stable step needs h <= "
        f"{lo:.3g} s. Use at least {int(np.ceil(h / max(lo, 1e-300)))}x as many substeps "
        "per sample (n_substeps), fewer ball-screw segments, a softer friction law (a larger "
        "velocity_scale), or adaptive steps with an implicit solver such as 'kvaerno5'."
    )


def finite_or_error(x: PyTree, message: str) -> PyTree:
    """`eqx.error_if(x, any non-finite leaf, message)` for a pytree of arrays."""
    leaves = jax.tree_util.tree_leaves(x)
    bad = jnp.any(jnp.stack([~jnp.all(jnp.isfinite(leaf)) for leaf in leaves]))
    return eqx.error_if(x, bad, message)
