r"""The EMPS benchmark's official task and jaxvs's grey-box simulator for it.

**Task** (Janot, Gautier, Brunot 2019, *Data set and reference models of EMPS*, §2.2;
split and initialisation window as in the `nonlinear_benchmarks` package's `EMPS()`, the
split behind the identibench tables): from the motor force `u = gτ·vir` [N] simulate the
motor position `qm` [m]; train on `DATA_EMPS.mat`, test on the cross-test validation
file `DATA_EMPS_PULSES.mat` (force pulses added, §2.2); both 24 841 samples at 1 kHz
(≈ 25 s); the first 20 output samples of a record may initialise the state; score the RMSE
of the position after them.

**Model**: [`OpenLoopAxis`][], the direct dynamic model of the description (eq. (3))
`M q̈ = u − F(q̇) − P(q)` with any `jaxvs.models` friction law `F` inside a
`jaxvs.models.RigidAxis` and an optional position-dependent force `P` ([`PositionForce`][]),
simulated open loop from the measured force held over each sample (zero-order hold, as
the 1 kHz dSPACE controller outputs it) with `jaxvs.models.solve_sampled`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._misc import legendre
from ...data import load_emps
from ...models import AbstractDynamicFriction, AbstractFriction, RigidAxis, solve_sampled
from ._shooting import AbstractSimulator
from ._task import BenchmarkTask, PublishedResult, Segment

__all__ = [
    "EMPS",
    "EMPS_PUBLISHED",
    "EMPS_PUBLISHED_IDIM",
    "OpenLoopAxis",
    "PositionForce",
]


EMPS = BenchmarkTask(
    name="EMPS",
    loader=load_emps,
    train=(
        Segment(
            "DATA_EMPS.mat",
            samples=24841,
            sha256="6cf6814ae14618795da0101aae2bb97ff0c6351b0501b5492751b02b07facf7e",
        ),
    ),
    test=(
        Segment(
            "DATA_EMPS_PULSES.mat",
            samples=24841,
            sha256="0eab75bb1f6b16228ee78791343a88bf9bfd9a51036ac9807d7b5fc11c0e1704",
        ),
    ),
    inputs=("u",),
    outputs=("q",),
    init_window=20,
    sample_time=1e-3,
    output_units=("m",),
    display_scale=1e3,
    display_unit="mm",
    description=(
        "Electro-Mechanical Positioning System: a prismatic axis (DC motor, ball screw, "
        "load) in closed loop with a P/PD cascade at 1 kHz. Input: the motor force "
        "u = gτ·vir [N]; output: the motor position qm [m]; free-run simulation of the "
        "position on the cross-test validation file with force pulses."
    ),
    source=(
        "A. Janot, M. Gautier, M. Brunot, Data Set and Reference Models of EMPS, "
        "Workshop on Nonlinear System Identification Benchmarks, Eindhoven, 2019; "
        "split and 20-sample initialisation window as in nonlinear_benchmarks.EMPS()"
    ),
)
"""The official EMPS task (train `DATA_EMPS.mat`, test `DATA_EMPS_PULSES.mat`, input
`u` [N], output `q` [m], 20-sample initialisation window, RMSE shown in mm)."""

# Description §3.4 (MATLAB Script_IDIM_LS output).
EMPS_PUBLISHED_IDIM = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
"""Published IDIM-LS estimates: mass [kg], viscous [N·s/m], Coulomb [N], offset [N]."""

_IDENTIBENCH = "identibench / tsfast benchmark tables, as published"
EMPS_PUBLISHED = (
    PublishedResult("GRU", (54.6, 54.6), (107.0, 198.0), _IDENTIBENCH),
    PublishedResult("LSTM", (82.0, 89.0), (107.0, 198.0), _IDENTIBENCH),
    PublishedResult("TCN", (156.0, 164.0), (107.0, 198.0), _IDENTIBENCH),
)
"""Published black-box results on the same task (test RMSE [mm]; the training-time range
107–198 s is given for the three networks together)."""


class PositionForce(eqx.Module):
    r"""A smooth position-dependent force, a Legendre series over the stroke:
    `P(q) = Σ_{k=1..n} c_k P_k((q − centre) / half_range)`.

    Models what depends on where the axis is rather than how fast it moves: a ball-screw
    lead or preload variation, a cable chain, gravity on a slightly inclined guide, motor
    cogging averaged over a pole pitch. `P_0` is left out (a constant force is the
    friction law's offset). The Legendre basis is orthogonal on the stroke, so the
    coefficients are well conditioned.

    **Arguments:**

    - `coefficients`: `(order,)` amplitudes `c_k` [N].
    - `centre`, `half_range`: the stroke `[centre − half_range, centre + half_range]` [m]
      (static), mapped to `[−1, 1]`.
    """

    coefficients: Float[Array, " order"]
    centre: float = eqx.field(static=True)
    half_range: float = eqx.field(static=True)

    def __init__(self, coefficients: ArrayLike, *, centre: float, half_range: float):
        c = jnp.asarray(coefficients, dtype=float)
        if c.ndim != 1 or c.shape[0] < 1:
            raise ValueError(
                f"PositionForce: coefficients must be a 1-D array of >= 1 amplitudes [N]; "
                f"got shape {c.shape}."
            )
        if not half_range > 0:
            raise ValueError(f"PositionForce: half_range must be > 0 m; got {half_range!r}.")
        self.coefficients = c
        self.centre = float(centre)
        self.half_range = float(half_range)

    def __call__(self, q: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """Force [N] at position `q` [m] (opposing the drive force, like friction)."""
        x = (jnp.asarray(q) - self.centre) / self.half_range
        return legendre(x, self.coefficients.shape[0]) @ self.coefficients


class OpenLoopAxis(AbstractSimulator):
    r"""Open-loop simulator of a rigid axis driven by a measured force:
    `M q̈ = u − F(q̇) − P(q)`, state `x = (q, q̇)`, output `q`. A friction law with
    internal states (`jaxvs.models.AbstractDynamicFriction`: LuGre, Dahl, drifting
    friction) appends them, `x = (q, q̇, z)`, starting from their steady state at the
    estimated initial velocity.

    The force `u_k` is held over `[t_k, t_{k+1})` (zero-order hold) and the interval is
    integrated by `n_substeps` explicit Runge–Kutta steps (`jaxvs.models.solve_sampled`).
    The initial state is estimated from a window of measured positions by a least-squares
    parabola (position and velocity at the window's last sample).

    **Arguments:**

    - `mechanics`: a `jaxvs.models.RigidAxis` (mass [kg] and friction law).
    - `position_force`: optional [`PositionForce`][] `P(q)` [N].
    - `sample_time`: sampling period [s] of the force (static).
    - `n_substeps`: solver steps per sample (static, >= 1). A smooth-sign friction law of
      sharpness `v_s` needs `h · Fc / (v_s · M) ≲ 2` with `h = sample_time / n_substeps`.
    - `solver`: an explicit diffrax solver name (static, default `"tsit5"`).
    """

    mechanics: RigidAxis
    position_force: PositionForce | None
    sample_time: float = eqx.field(static=True)
    n_substeps: int = eqx.field(static=True)
    solver: str = eqx.field(static=True)

    def __init__(
        self,
        mechanics: RigidAxis,
        position_force: PositionForce | None = None,
        *,
        sample_time: float,
        n_substeps: int = 2,
        solver: str = "tsit5",
    ):
        if not isinstance(mechanics, RigidAxis):
            raise TypeError(
                "OpenLoopAxis: mechanics must be a jaxvs.models.RigidAxis(mass, friction); got "
                f"{type(mechanics).__name__}."
            )
        if not isinstance(mechanics.friction, AbstractFriction):
            raise TypeError("OpenLoopAxis: the axis needs a jaxvs friction law.")
        if position_force is not None and not isinstance(position_force, PositionForce):
            raise TypeError(
                "OpenLoopAxis: position_force must be a PositionForce or None; got "
                f"{type(position_force).__name__}."
            )
        if not sample_time > 0:
            raise ValueError(f"OpenLoopAxis: sample_time must be > 0 s; got {sample_time!r}.")
        if not isinstance(n_substeps, int) or n_substeps < 1:
            raise ValueError(f"OpenLoopAxis: n_substeps must be an int >= 1; got {n_substeps!r}.")
        self.mechanics = mechanics
        self.position_force = position_force
        self.sample_time = float(sample_time)
        self.n_substeps = n_substeps
        self.solver = str(solver)

    def _plant(self, t, x, args):
        u, model = args
        q, v = x[:1], x[1:2]
        external = 0.0 if model.position_force is None else -model.position_force(q[0])
        friction = model.mechanics.friction
        if isinstance(friction, AbstractDynamicFriction):
            z = x[2:]
            force = friction.force(z, v[0])
            acc = (u + external - force) / model.mechanics.mass
            return jnp.concatenate([v, acc[None], friction.rates(z, v[0])])
        return jnp.concatenate([v, model.mechanics.acceleration(q, v, u, external)])

    def simulate(self, u, x0):
        """States `(q [m], q̇ [m/s], friction states)` at every sample (before `u_k`
        acts) from `x0` at `k = 0`; `u` is `(time, 1)` or `(time,)` [N]."""
        u = jnp.asarray(u)
        u = u[:, 0] if u.ndim == 2 else u
        xs, _ = solve_sampled(
            self._plant,
            lambda c, x, u_k, args: (u_k, c),
            jnp.asarray(x0, dtype=float),
            jnp.zeros(()),
            u,
            self.sample_time,
            self,
            n_substeps=self.n_substeps,
            solver=self.solver,
        )
        return xs

    def output(self, x):
        """The position `q` [m] of each state, as `(time, 1)`."""
        return x[:, :1]

    def initial_state(self, y_init):
        """`(q, q̇)` at the last sample of the measured positions `y_init` [m]
        (`(window, 1)` or `(window,)`) from a least-squares parabola in time (a line for
        two samples, zero velocity for one)."""
        q = jnp.asarray(y_init, dtype=float)
        q = q[:, 0] if q.ndim == 2 else q
        n = q.shape[0]
        if n == 1:
            return self._with_friction_state(jnp.stack([q[0], jnp.zeros_like(q[0])]))
        tau = (jnp.arange(n) - (n - 1)) * self.sample_time
        basis = jnp.stack([jnp.ones(n), tau] + ([tau**2] if n > 2 else []), axis=1)
        coef = jnp.linalg.lstsq(basis, q)[0]
        return self._with_friction_state(coef[:2])

    def _with_friction_state(self, qv):
        friction = self.mechanics.friction
        if isinstance(friction, AbstractDynamicFriction):
            return jnp.concatenate([qv, friction.steady_state(qv[1])])
        return qv

    def n_parameters(self) -> int:
        """Number of floating-point parameters (mass, friction, position force)."""
        leaves = jax.tree_util.tree_leaves((self.mechanics, self.position_force))
        return int(sum(x.size for x in leaves if eqx.is_inexact_array(x)))
