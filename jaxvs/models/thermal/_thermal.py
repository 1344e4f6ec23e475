"""First-order thermal laws: the thermal study's exponential interpolation model.

Dementjev et al. (2014), eq. (1): after a step of the operating point at `t = 0`,

    T(t) = T0 + k (1 - exp(-t / T1)),

with the start temperature `T0` [°C], the gain `k` [K] and the time constant `T1` [s] --
the step response of a first-order transfer function `k / (T1 s + 1)`. Three models:

- [`FirstOrder`][]: one experiment part;
- [`PiecewiseFirstOrder`][]: one law per part of an experiment (operating points), either
  with jumps (each part its own `T0`, as the study's Table 3) or continuous (each part
  starts where the previous one ended);
- [`DrivenFirstOrder`][]: the same law as an ODE `T1 dT/dt = T_ref + K u(t) - T` driven by
  an arbitrary input (e.g. a speed profile), integrated by diffrax.
"""

import diffrax
import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._misc import check_physical
from .._base import AbstractModel

__all__ = ["DrivenFirstOrder", "FirstOrder", "PiecewiseFirstOrder"]


def _scalar(x, name: str) -> Array:
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.inexact):
        x = x.astype(jnp.result_type(float))
    return x


class FirstOrder(AbstractModel):
    """`T(t) = T0 + k (1 - exp(-t/T1))` (study eq. 1).

    **Arguments:**

    - `T0`: temperature at `t = 0` [°C].
    - `k`: gain, the final change of temperature [K] (negative when cooling).
    - `T1`: time constant [s], positive.

    Fields may carry a batch shape (a family of curves, e.g. the five parts of the
    study's Table 3); `__call__` broadcasts them against `t`.
    """

    T0: Float[Array, "*batch"]
    k: Float[Array, "*batch"]
    T1: Float[Array, "*batch"]

    def __init__(self, T0: ArrayLike, k: ArrayLike, T1: ArrayLike):
        check_physical(T1, "FirstOrder: T1", unit="s")
        self.T0, self.k, self.T1 = (_scalar(v, n) for v, n in ((T0, "T0"), (k, "k"), (T1, "T1")))

    def __call__(self, t: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """Temperature [°C] at times `t` [s] after the start of the part."""
        t = jnp.asarray(t)
        return self.T0 + self.k * -jnp.expm1(-t / self.T1)

    def predict(self, u: Float[ArrayLike, " time *input"], dt: float) -> Float[Array, " time"]:
        """Temperature [°C] at `t = k·dt`, `k = 0 … len(u)-1` (a function of time only)."""
        return self(jnp.arange(jnp.shape(u)[0]) * dt)

    @property
    def final_value(self) -> Float[Array, "*batch"]:
        """`T0 + k` [°C], the steady state."""
        return self.T0 + self.k


class PiecewiseFirstOrder(AbstractModel):
    """One first-order law per experiment part (operating point).

    **Arguments:**

    - `starts`: `(parts,)` start time of each part [s], increasing; part `i` covers
      `[starts[i], starts[i+1])`, the last one extends to infinity (and the first one
      backwards).
    - `T0`, `k`, `T1`: `(parts,)` start temperature [°C], gain [K], time constant [s].
    - `continuous`: `False` (default): every part has its own `T0` (jumps allowed, as
      after a cool-down between parts, study Table 3); `True`: `T0[i]` for `i > 0` is
      ignored and each part starts where the previous one ended.
    """

    starts: Float[Array, " parts"]
    T0: Float[Array, " parts"]
    k: Float[Array, " parts"]
    T1: Float[Array, " parts"]
    continuous: bool = eqx.field(static=True, default=False)

    def __init__(self, starts, T0, k, T1, continuous: bool = False):
        check_physical(T1, "PiecewiseFirstOrder: T1", unit="s")
        self.starts = _scalar(starts, "starts")
        self.T0, self.k, self.T1 = (_scalar(v, n) for v, n in ((T0, "T0"), (k, "k"), (T1, "T1")))
        shapes = {self.starts.shape, self.T0.shape, self.k.shape, self.T1.shape}
        if len(shapes) != 1 or self.starts.ndim != 1:
            raise ValueError(
                "PiecewiseFirstOrder: starts, T0, k and T1 must be 1-D arrays of the same "
                f"length (one entry per part); got shapes {[s for s in shapes]}."
            )
        self.continuous = bool(continuous)

    @property
    def start_values(self) -> Float[Array, " parts"]:
        """The temperature at the start of every part [°C] (continuous: chained)."""
        if not self.continuous:
            return self.T0
        lengths = jnp.diff(self.starts)
        rise = self.k[:-1] * -jnp.expm1(-lengths / self.T1[:-1])
        return self.T0[0] + jnp.concatenate([jnp.zeros(1, rise.dtype), jnp.cumsum(rise)])

    def part_index(self, t: Float[ArrayLike, " time"]) -> Array:
        """Index of the part every time `t` [s] falls in."""
        idx = jnp.searchsorted(self.starts, jnp.asarray(t), side="right", method="compare_all")
        return jnp.clip(idx - 1, 0, self.starts.shape[0] - 1)

    def __call__(self, t: Float[ArrayLike, " time"]) -> Float[Array, " time"]:
        """Temperature [°C] at absolute times `t` [s]."""
        t = jnp.asarray(t)
        i = self.part_index(t)
        local = t - self.starts[i]
        return self.start_values[i] + self.k[i] * -jnp.expm1(-local / self.T1[i])

    def predict(self, u: Float[ArrayLike, " time *input"], dt: float) -> Float[Array, " time"]:
        """Temperature [°C] at `t = k·dt`, `k = 0 … len(u)-1` (a function of time only)."""
        return self(jnp.arange(jnp.shape(u)[0]) * dt)

    def parts(self) -> FirstOrder:
        """The parts as a batched [`FirstOrder`][] (local time of each part)."""
        return FirstOrder(self.start_values, self.k, self.T1)


class DrivenFirstOrder(AbstractModel):
    """The first-order law as an ODE driven by an input: `T1 dT/dt = T_ref + K u(t) - T`.

    A step of `u` by `Δu` at `t = 0` from steady state gives exactly [`FirstOrder`][] with
    `k = K Δu`; for arbitrary profiles (speed ramps, random parts) it is integrated by
    diffrax with the input linearly interpolated between its samples.

    **Arguments:**

    - `T_ref`: steady-state temperature at `u = 0` [°C].
    - `K`: steady-state gain [K per unit of `u`, e.g. K/rpm].
    - `T1`: time constant [s].
    - `solver`: a diffrax solver (default `diffrax.Tsit5()`); `rtol`, `atol`: step-size
      control; `adjoint`: diffrax adjoint (default `diffrax.ForwardMode()`, which
      `jaxvs.calibrate`'s Levenberg-Marquardt needs; use
      `diffrax.RecursiveCheckpointAdjoint()` for reverse-mode gradients).
    """

    T_ref: Float[Array, ""]
    K: Float[Array, ""]
    T1: Float[Array, ""]
    solver: diffrax.AbstractSolver = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    adjoint: diffrax.AbstractAdjoint = eqx.field(static=True)

    def __init__(
        self,
        T_ref: ArrayLike,
        K: ArrayLike,
        T1: ArrayLike,
        *,
        solver: diffrax.AbstractSolver | None = None,
        rtol: float = 1e-8,
        atol: float = 1e-8,
        adjoint: diffrax.AbstractAdjoint | None = None,
    ):
        check_physical(T1, "DrivenFirstOrder: T1", unit="s")
        self.T_ref, self.K, self.T1 = (
            _scalar(v, n) for v, n in ((T_ref, "T_ref"), (K, "K"), (T1, "T1"))
        )
        self.solver = diffrax.Tsit5() if solver is None else solver
        self.rtol, self.atol = float(rtol), float(atol)
        self.adjoint = diffrax.ForwardMode() if adjoint is None else adjoint

    def steady_state(self, u: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """`T_ref + K u` [°C]."""
        return self.T_ref + self.K * jnp.asarray(u)

    def simulate(
        self,
        t: Float[ArrayLike, " time"],
        u: Float[ArrayLike, " time"],
        T_init: Float[ArrayLike, ""] | None = None,
        *,
        max_steps: int = 16384,
    ) -> Float[Array, " time"]:
        """Temperature [°C] at the times `t` [s] for the input samples `u` at `t`.

        **Arguments:**

        - `t`: `(time,)` increasing sample times [s]; `u`: `(time,)` input samples.
        - `T_init`: temperature at `t[0]` [°C] (default: the steady state of `u[0]`).
        - `max_steps`: diffrax step budget.

        **Returns:**

        `(time,)` temperatures [°C].
        """
        t = jnp.asarray(t, self.T1.dtype)
        u = jnp.asarray(u, self.T1.dtype)
        if t.ndim != 1 or u.shape != t.shape or t.shape[0] < 2:
            raise ValueError(
                "DrivenFirstOrder.simulate: t and u must be 1-D arrays of the same length "
                f"(at least 2 samples); got {t.shape} and {u.shape}."
            )
        y0 = self.steady_state(u[0]) if T_init is None else jnp.asarray(T_init, t.dtype)
        control = diffrax.LinearInterpolation(ts=t, ys=u)

        def field(s, T, args):
            return (self.T_ref + self.K * control.evaluate(s) - T) / self.T1

        # Step size control with the input's sample points as jump locations keeps the
        # kinks of the interpolated input exact.
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            self.solver,
            t0=t[0],
            t1=t[-1],
            dt0=None,
            y0=y0,
            saveat=diffrax.SaveAt(ts=t),
            stepsize_controller=diffrax.PIDController(rtol=self.rtol, atol=self.atol, jump_ts=t),
            adjoint=self.adjoint,
            max_steps=max_steps,
        )
        return sol.ys

    def __call__(self, t, u, T_init=None):
        return self.simulate(t, u, T_init)

    def predict(self, u: Float[ArrayLike, " time"], dt: float) -> Float[Array, " time"]:
        """Temperature [°C] for the input samples `u` every `dt` [s], from the steady
        state of `u[0]`."""
        u = jnp.asarray(u, self.T1.dtype)
        return self.simulate(jnp.arange(u.shape[0], dtype=u.dtype) * dt, u)
