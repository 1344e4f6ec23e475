r"""Cascade-controlled CNC axis drives: P position loop, PI velocity loop, current loop or
DC motor, mechanics (rigid, two-mass, distributed ball screw), friction, backlash,
saturation and encoder quantisation, simulated through diffrax.

The cascade of a CNC feed drive (Pislaru 2001, ch. 3–4, Fig. 4.1; Altintas 2012, ch. 6;
Janot, Gautier, Brunot 2019, eq. (6)–(7) for the EMPS):

```
 r ─►(+)─ kp ─►(+)─ kv·(1 + ki/s) ─ sat ─► actuator ─ f ─► mechanics ─┬─► q_table
      ▲−         ▲−                 (+ u_add)          (+ f_ext)       │
      └── q_fb ──┴───── v_motor ───────────────────────────────────────┘
```

- position loop: `v_ref = kp (r − q_fb)`, `q_fb` the motor (rotary encoder) or the table
  (linear encoder) position, optionally quantised;
- velocity loop: `u = sat(kv (e_v + ki ∫e_v) + u_add)`, `e_v = v_ref − v_motor` (P when
  `ki = 0`, as the EMPS);
- actuator: a gain (`ForceGain`, the EMPS `gτ`), a first-order current loop
  (`CurrentLoop`), or the electrical dynamics of a `DCMotor` driven by voltage.

A [`DriveAxis`][] is either continuous (analogue controller; `sample_time=None`), solved
by an adaptive diffrax solve over the whole record, or **sampled** (digital controller at
`sample_time`, zero-order hold, velocity from the encoder by a backward or central
difference: the EMPS estimates `q̇_k = (q_k − q_{k−2}) / (2 dt)`), solved by
`solve_sampled`. Both are differentiable in forward mode (for `jaxvs.calibrate`) and
batch with `jax.vmap` over parameter variants.
"""

import abc
import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real, check_physical, is_traced
from .._base import AbstractModel, check_parameters
from .._nonlinear_simulate import (
    ODEOptions,
    check_step,
    finite_or_error,
    solve_ode,
    solve_sampled,
    zoh_interval,
)
from ..lti import RationalTF, StateSpace
from ._ballscrew import AbstractMechanics
from ._friction import quantise, saturation

__all__ = [
    "AbstractActuator",
    "CurrentLoop",
    "DCMotor",
    "DriveAxis",
    "DriveResponse",
    "ForceGain",
    "PositionLoop",
    "UnstableLoopError",
    "VelocityLoop",
]


def _param(x: ArrayLike, name: str, where: str) -> Array:
    x = as_real(x, f"{where}: {name}")
    if x.ndim != 0:
        raise ValueError(
            f"{where}: {name} must be a scalar; got shape {x.shape}. Build families with "
            "jax.vmap over a function that builds the model."
        )
    return x


class UnstableLoopError(ValueError):
    """The closed loop of a drive is unstable (a controller gain is too high or has the
    wrong sign)."""


# ----------------------------------------------------------------------------- controllers


class PositionLoop(eqx.Module):
    """Proportional position controller `v_ref = kp · (r − q)`.

    **Arguments:**

    - `kp`: position gain (the "kv factor" of CNC practice) [1/s]; the position loop's
      bandwidth is about `kp` rad/s for a fast velocity loop.
    """

    def __check_init__(self):
        check_parameters(self)

    kp: Float[Array, ""]

    def __init__(self, kp: ArrayLike):
        self.kp = _param(kp, "kp", "PositionLoop")

    def __call__(self, error):
        return self.kp * error


class VelocityLoop(eqx.Module):
    """PI velocity controller `u = sat(kv · (e + ki ∫e dt))` with output saturation.

    **Arguments:**

    - `kv`: proportional gain [command unit per m/s] (V/(m/s) for the EMPS).
    - `ki`: integral gain [1/s] (`1 / T_n`, the reset time); 0 for a P controller.
    - `limit`: symmetric saturation of the output (static; `inf` for none), in the command
      unit (the EMPS amplifier saturates at 10 V).
    """

    def __check_init__(self):
        check_parameters(self)

    kv: Float[Array, ""]
    ki: Float[Array, ""]
    limit: float = eqx.field(static=True)

    def __init__(self, kv: ArrayLike, ki: ArrayLike = 0.0, *, limit: float = math.inf):
        self.kv = _param(kv, "kv", "VelocityLoop")
        self.ki = _param(ki, "ki", "VelocityLoop")
        if not float(limit) > 0:
            raise ValueError(f"VelocityLoop: limit must be > 0 (inf for none); got {limit}.")
        self.limit = float(limit)

    def __call__(self, error, integral, offset=0.0):
        return saturation(self.kv * (error + self.ki * integral) + offset, self.limit)


# ----------------------------------------------------------------------------- actuators


class AbstractActuator(eqx.Module):
    """Turns the velocity controller's command into the drive force [N] on the motor side
    (linear coordinates), possibly with its own states (current, force lag)."""

    def __check_init__(self):
        check_parameters(self)

    @property
    @abc.abstractmethod
    def n_states(self) -> int:
        """Number of internal states (static)."""

    @abc.abstractmethod
    def force(self, x: Float[Array, " state"], command: Float[Array, ""]) -> Float[Array, ""]:
        """Drive force [N] from the actuator state and the command."""

    @abc.abstractmethod
    def derivative(
        self, x: Float[Array, " state"], command: Float[Array, ""], motor_velocity
    ) -> Float[Array, " state"]:
        """Time derivative of the actuator state."""


class ForceGain(AbstractActuator):
    """An ideal current-controlled drive: `f = gain · command`, no lag (the EMPS drive
    gain `gτ` [N/V], Janot et al. 2019, eq. (7)).

    **Arguments:**

    - `gain`: [N per command unit].
    """

    gain: Float[Array, ""]

    def __init__(self, gain: ArrayLike):
        self.gain = _param(gain, "gain", "ForceGain")

    @property
    def n_states(self) -> int:
        return 0

    def force(self, x, command):
        return self.gain * command

    def derivative(self, x, command, motor_velocity):
        return jnp.zeros((0,), jnp.result_type(command))


class CurrentLoop(AbstractActuator):
    r"""The closed current (torque) loop as a first-order lag (Pislaru 2001, §3.3):
    `τ ḟ = gain · command − f`, i.e. `f/command = gain / (τ s + 1)`.

    **Arguments:**

    - `gain`: static gain [N per command unit].
    - `time_constant`: `τ` [s], > 0 (≈ 1/bandwidth of the current loop).
    """

    gain: Float[Array, ""]
    time_constant: Float[Array, ""]

    def __init__(self, gain: ArrayLike, time_constant: ArrayLike):
        self.gain = _param(gain, "gain", "CurrentLoop")
        tau = _param(time_constant, "time_constant", "CurrentLoop")
        self.time_constant = eqx.error_if(
            tau, ~(tau > 0), "CurrentLoop: time_constant must be > 0 s (use ForceGain for none)."
        )

    @property
    def n_states(self) -> int:
        return 1

    def force(self, x, command):
        return x[0]

    def derivative(self, x, command, motor_velocity):
        return ((self.gain * command - x[0]) / self.time_constant)[None]


class DCMotor(AbstractActuator):
    r"""Permanent-magnet DC motor (Pislaru 2001, §3.4): armature circuit
    `L di/dt = V − R i − k_e ω`, torque `T = k_t i`, rotor `J ω̇ = T − b ω − T_load`.

    As an actuator of a [`DriveAxis`][] it is voltage driven and contributes the current
    `i` as state; the force on the motor side is `k_t i · ratio` and `ω = ratio · v_motor`.
    The rotor inertia and damping belong to the mechanics there: add
    `inertia · ratio²` to the motor-side mass and `viscous_damping · ratio²` to its
    friction. [`DCMotor.speed_transfer_function`][] and [`DCMotor.vector_field`][]
    describe the motor alone.

    **Arguments:**

    - `resistance`: `R` [Ω]; `inductance`: `L` [H], > 0.
    - `torque_constant`: `k_t` [N·m/A]; `back_emf_constant`: `k_e` [V·s/rad] (equal to
      `k_t` in SI units for an ideal motor).
    - `inertia`: rotor `J` [kg·m²]; `viscous_damping`: `b` [N·m·s/rad].
    - `ratio`: transmission `2π/lead` [rad/m] to the linear coordinate (default 1: the
      coordinate is the motor angle).
    """

    resistance: Float[Array, ""]
    inductance: Float[Array, ""]
    torque_constant: Float[Array, ""]
    back_emf_constant: Float[Array, ""]
    inertia: Float[Array, ""]
    viscous_damping: Float[Array, ""]
    ratio: Float[Array, ""]

    def __init__(
        self,
        resistance: ArrayLike,
        inductance: ArrayLike,
        torque_constant: ArrayLike,
        back_emf_constant: ArrayLike,
        inertia: ArrayLike,
        viscous_damping: ArrayLike = 0.0,
        *,
        ratio: ArrayLike = 1.0,
    ):
        w = "DCMotor"
        check_physical(resistance, f"{w}: resistance", unit="Ω")
        check_physical(inductance, f"{w}: inductance", unit="H")
        check_physical(inertia, f"{w}: inertia", unit="kg·m²")
        check_physical(viscous_damping, f"{w}: viscous_damping", strict=False, unit="N·m·s")
        self.resistance = _param(resistance, "resistance", w)
        L = _param(inductance, "inductance", w)
        self.inductance = eqx.error_if(L, ~(L > 0), f"{w}: inductance must be > 0 H.")
        self.torque_constant = _param(torque_constant, "torque_constant", w)
        self.back_emf_constant = _param(back_emf_constant, "back_emf_constant", w)
        J = _param(inertia, "inertia", w)
        self.inertia = eqx.error_if(J, ~(J > 0), f"{w}: inertia must be > 0 kg·m².")
        self.viscous_damping = _param(viscous_damping, "viscous_damping", w)
        self.ratio = _param(ratio, "ratio", w)

    @property
    def n_states(self) -> int:
        return 1

    def force(self, x, command):
        return self.torque_constant * x[0] * self.ratio

    def derivative(self, x, command, motor_velocity):
        emf = self.back_emf_constant * self.ratio * motor_velocity
        return ((command - self.resistance * x[0] - emf) / self.inductance)[None]

    def vector_field(self, t, y, args):
        r"""The motor alone: `y = [i, ω]` [A, rad/s], `args = (V, T_load)` [V, N·m]."""
        voltage, load = args
        i, w = y[0], y[1]
        di = (voltage - self.resistance * i - self.back_emf_constant * w) / self.inductance
        dw = (self.torque_constant * i - self.viscous_damping * w - load) / self.inertia
        return jnp.stack([di, dw])

    def speed_transfer_function(self) -> RationalTF:
        r"""`ω/V = k_t / ((L s + R)(J s + b) + k_t k_e)` [rad/(s·V)], the unloaded motor."""
        L, R, J, b = self.inductance, self.resistance, self.inertia, self.viscous_damping
        kt, ke = self.torque_constant, self.back_emf_constant
        den = jnp.stack([L * J, L * b + R * J, R * b + kt * ke])
        num = jnp.stack([jnp.zeros_like(kt), jnp.zeros_like(kt), kt])
        return RationalTF(num, den)


# ----------------------------------------------------------------------------- the cascade


class DriveResponse(eqx.Module):
    """The simulated response of a [`DriveAxis`][] at the sample times.

    **Fields:**

    - `t`: `(time,)` [s].
    - `position`, `velocity`, `acceleration`: of the table (last degree of freedom)
      [m, m/s, m/s²].
    - `motor_position`, `motor_velocity`: of the motor side (degree of freedom 0).
    - `force`: drive force on the motor side [N].
    - `command`: velocity-controller output after saturation (V for the EMPS).
    - `states`: `(time, state)` plant states `[q (dof), v (dof), actuator, (∫e_v)]`.
    """

    t: Array
    position: Array
    velocity: Array
    acceleration: Array
    motor_position: Array
    motor_velocity: Array
    force: Array
    command: Array
    states: Array


class DriveAxis(AbstractModel):
    r"""A cascade-controlled feed drive (see the module docstring for the block diagram).

    **Arguments:**

    - `mechanics`: a `RigidAxis` or `FlexibleAxis` (e.g. from `BallScrew.lumped_axis` /
      `distributed_axis`).
    - `position_loop`: a [`PositionLoop`][] (`kp`).
    - `velocity_loop`: a [`VelocityLoop`][] (`kv`, `ki`, saturation `limit`).
    - `actuator`: [`ForceGain`][] (default gain 1: the command is the force [N]),
      [`CurrentLoop`][] or [`DCMotor`][].
    - `feedback`: `"motor"` (rotary encoder, semi-closed loop) or `"table"` (linear
      encoder, closed loop) position feedback (static). The velocity loop always uses
      the motor side.
    - `sample_time`: `None` for an analogue (continuous) controller, or the period [s] of a
      digital controller (static).
    - `velocity_estimate`: digital controller only (static): `"backward"`
      `(q_k − q_{k−1})/dt` or `"central"` `(q_k − q_{k−2})/(2dt)` (the EMPS filter
      `q_f,k = (q_k + q_{k−1})/2` followed by a backward difference).
    - `encoder_resolution`: quantisation step of the measured positions [m] (static;
      0 = none).
    - `n_substeps`: solver steps per controller sample (static, digital controller).
    """

    mechanics: AbstractMechanics
    position_loop: PositionLoop
    velocity_loop: VelocityLoop
    actuator: AbstractActuator
    feedback: Literal["motor", "table"] = eqx.field(static=True)
    sample_time: float | None = eqx.field(static=True)
    velocity_estimate: Literal["backward", "central"] = eqx.field(static=True)
    encoder_resolution: float = eqx.field(static=True)
    n_substeps: int = eqx.field(static=True)

    def __init__(
        self,
        mechanics: AbstractMechanics,
        position_loop: PositionLoop,
        velocity_loop: VelocityLoop,
        actuator: AbstractActuator | None = None,
        *,
        feedback: Literal["motor", "table"] = "motor",
        sample_time: float | None = None,
        velocity_estimate: Literal["backward", "central"] = "backward",
        encoder_resolution: float = 0.0,
        n_substeps: int = 4,
    ):
        w = "DriveAxis"
        if not isinstance(mechanics, AbstractMechanics):
            raise TypeError(
                f"{w}: mechanics must be a RigidAxis, FlexibleAxis (or another "
                f"AbstractMechanics); got {type(mechanics).__name__}."
            )
        if not isinstance(position_loop, PositionLoop):
            raise TypeError(f"{w}: position_loop must be a PositionLoop(kp).")
        if not isinstance(velocity_loop, VelocityLoop):
            raise TypeError(f"{w}: velocity_loop must be a VelocityLoop(kv, ki).")
        if actuator is None:
            actuator = ForceGain(1.0)
        if not isinstance(actuator, AbstractActuator):
            raise TypeError(
                f"{w}: actuator must be ForceGain, CurrentLoop or DCMotor; got "
                f"{type(actuator).__name__}."
            )
        if feedback not in ("motor", "table"):
            raise ValueError(f"{w}: feedback must be 'motor' or 'table'; got {feedback!r}.")
        if velocity_estimate not in ("backward", "central"):
            raise ValueError(
                f"{w}: velocity_estimate must be 'backward' or 'central'; got "
                f"{velocity_estimate!r}."
            )
        if sample_time is not None and not float(sample_time) > 0:
            raise ValueError(f"{w}: sample_time must be > 0 s or None; got {sample_time}.")
        if not float(encoder_resolution) >= 0:
            raise ValueError(f"{w}: encoder_resolution must be >= 0 m; got {encoder_resolution}.")
        if not isinstance(n_substeps, int) or n_substeps < 1:
            raise ValueError(f"{w}: n_substeps must be an int >= 1; got {n_substeps!r}.")
        self.mechanics = mechanics
        self.position_loop = position_loop
        self.velocity_loop = velocity_loop
        self.actuator = actuator
        self.feedback = feedback
        self.sample_time = None if sample_time is None else float(sample_time)
        self.velocity_estimate = velocity_estimate
        self.encoder_resolution = float(encoder_resolution)
        self.n_substeps = n_substeps

    # ------------------------------------------------------------------ state layout
    @property
    def n_dof(self) -> int:
        return self.mechanics.n_dof

    @property
    def n_plant_states(self) -> int:
        """`2·dof + actuator states`: `[q, v, actuator]`."""
        return 2 * self.n_dof + self.actuator.n_states

    def _split(self, y):
        n = self.n_dof
        return y[:n], y[n : 2 * n], y[2 * n : self.n_plant_states]

    def _fb(self, q):
        qf = q[0] if self.feedback == "motor" else q[-1]
        return quantise(qf, self.encoder_resolution)

    def _plant(self, t, y, args):
        (command, external), _ = args
        q, v, xa = self._split(y)
        force = self.actuator.force(xa, command)
        a = self.mechanics.acceleration(q, v, force, external)
        dxa = self.actuator.derivative(xa, command, v[0])
        return jnp.concatenate([v, a, dxa])

    def _continuous(self, t, y, args):
        ts, r, fe, ua = args
        yp, z = y[:-1], y[-1]
        q, v, xa = self._split(yp)
        rr = jnp.interp(t, ts, r)
        ff = jnp.interp(t, ts, fe)
        uu = jnp.interp(t, ts, ua)
        e_v = self.position_loop(rr - self._fb(q)) - v[0]
        command = self.velocity_loop(e_v, z, uu)
        dy = self._plant(t, yp, ((command, ff), None))
        return jnp.concatenate([dy, e_v[None]])

    def _controller(self, c, y, inp, args):
        r, fe, ua = inp
        dt = self.sample_time
        q, _, _ = self._split(y)
        qm = quantise(q[0], self.encoder_resolution)
        if self.velocity_estimate == "central":
            v_est = (qm - c["q2"]) / (2 * dt)
        else:
            v_est = (qm - c["q1"]) / dt
        e_v = self.position_loop(r - self._fb(q)) - v_est
        command = self.velocity_loop(e_v, c["z"], ua)
        c_next = {"z": c["z"] + dt * e_v, "q1": qm, "q2": c["q1"]}
        return (command, fe), c_next

    def _initial(self, q0, dtype):
        y0 = jnp.zeros((self.n_plant_states,), dtype)
        return y0.at[: self.n_dof].set(q0)

    # ------------------------------------------------------------------ linear analysis
    def linearise(self) -> StateSpace:
        r"""The continuous-time closed loop linearised about rest (`q = 0`, `v = 0`,
        analogue controller, saturation inactive, quantisation ignored).

        Inputs `[r, f_ext]` (reference [m], external force on the table [N]); outputs
        `[q_table, q_motor, force]` [m, m, N]. Friction laws enter through their slope
        at `v = 0` (a smooth Coulomb law acts there as the steep damper
        `Fc / velocity_scale`). For a digital controller this is its analogue
        equivalent; see [`DriveAxis.sampled_poles`][] for the sampled loop.

        **Returns:**

        A `jaxvs.StateSpace` with 3 outputs and 2 inputs.
        """
        return _linearise(self)

    def _linearise_impl(self) -> StateSpace:
        n = self.n_dof
        ny = self.n_plant_states + 1
        y0 = jnp.zeros((ny,), jnp.result_type(self.position_loop.kp, float))

        def f(y, u):
            ts = jnp.array([0.0, 1.0], y.dtype)
            args = (ts, jnp.full(2, u[0]), jnp.full(2, u[1]), jnp.zeros(2, y.dtype))
            return self._continuous(0.0, y, args)

        def out(y, u):
            q, _, xa = self._split(y[:-1])
            e_v = self.position_loop(u[0] - self._fb(q)) - y[n]
            command = self.velocity_loop(e_v, y[-1])
            return jnp.stack([q[-1], q[0], self.actuator.force(xa, command)])

        u0 = jnp.zeros((2,), y0.dtype)
        A = jax.jacfwd(f, 0)(y0, u0)
        B = jax.jacfwd(f, 1)(y0, u0)
        C = jax.jacfwd(out, 0)(y0, u0)
        D = jax.jacfwd(out, 1)(y0, u0)
        return StateSpace(A, B, C, D)

    def sampled_poles(self) -> np.ndarray:
        """Eigenvalues of the one-sample map of the digital closed loop linearised about
        rest (NumPy, complex); the loop is stable when all lie inside the unit circle.

        **Raises:**

        `ValueError` for an analogue drive (`sample_time=None`).
        """
        if self.sample_time is None:
            raise ValueError(
                "DriveAxis.sampled_poles: this drive has an analogue controller "
                "(sample_time=None); use jaxvs.poles(drive.linearise())."
            )
        return np.linalg.eigvals(np.asarray(_sampled_jacobian(self)))

    def _step_flat(self, x, inp):
        npl = self.n_plant_states
        y = x[:npl]
        c = {"z": x[npl], "q1": x[npl + 1], "q2": x[npl + 2]}
        u, c_next = self._controller(c, y, inp, None)
        y_next = zoh_interval(self._plant, y, u, None, self.sample_time, self.n_substeps)
        return jnp.concatenate([y_next, jnp.stack([c_next["z"], c_next["q1"], c_next["q2"]])])

    def plant_poles(self) -> np.ndarray:
        """Eigenvalues [1/s] of the plant (mechanics + actuator, command frozen)
        linearised about rest; the fastest sets the largest stable solver step."""
        return np.linalg.eigvals(np.asarray(_plant_jacobian(self)))

    def check_stability(self) -> None:
        """Raise [`UnstableLoopError`][] when the linearised closed loop is unstable
        (continuous: a pole with `Re s > 0`; digital: a pole outside the unit circle).

        Needs concrete parameters (not under `jit`/`vmap`).
        """
        if self.sample_time is None:
            lam = np.linalg.eigvals(np.asarray(self.linearise().A))
            scale = max(np.max(np.abs(lam)), 1.0)
            # heuristic: 1e-9 of the fastest pole is rounding of a marginal (integrator) pole
            bad = lam.real > 1e-9 * scale
            worst = lam[np.argmax(lam.real)]
            detail = f"pole s = {worst.real:.4g}{worst.imag:+.4g}j 1/s in the right half-plane"
        else:
            lam = self.sampled_poles()
            bad = np.abs(lam) > 1 + 1e-9
            worst = lam[np.argmax(np.abs(lam))]
            detail = (
                f"pole z = {worst.real:.4g}{worst.imag:+.4g}j outside the unit circle "
                f"(|z| = {abs(worst):.4g}, sampled at {self.sample_time:g} s)"
            )
        if np.any(bad):
            raise UnstableLoopError(
                f"DriveAxis: the closed loop is unstable ({detail}) with kp = "
                f"{float(self.position_loop.kp):.4g} 1/s, kv = "
                f"{float(self.velocity_loop.kv):.4g}, ki = {float(self.velocity_loop.ki):.4g}"
                " 1/s. Lower kp or kv (the velocity loop's bandwidth must stay well below "
                "the first mechanical resonance and, for a digital controller, the sample "
                "rate), check the gains' signs and units, or lower ki."
            )

    def frequency_response(self, omega: Float[ArrayLike, " freq"], *, output="table"):
        """Closed-loop response `q/r` of the linearised loop at `omega` [rad/s].

        **Arguments:**

        - `omega`: `(freq,)` [rad/s].
        - `output`: `"table"`, `"motor"` or `"force"` (force per m of reference [N/m]).

        **Returns:**

        `(freq,)` complex.
        """
        from ..lti import frequency_response

        idx = {"table": 0, "motor": 1, "force": 2}
        if output not in idx:
            raise ValueError(f"frequency_response: output must be one of {tuple(idx)}.")
        H = frequency_response(self.linearise(), jnp.asarray(omega))
        return H[:, idx[output], 0]

    def predict(self, u: Float[ArrayLike, " time"], dt: float) -> Float[Array, " time"]:
        """Table position [m] following the position reference `u` [m] sampled every `dt`
        [s] (the closed loop of [`simulate`][], from rest)."""
        return self.simulate(u, dt, check=False).position

    # ------------------------------------------------------------------ simulation
    def simulate(
        self,
        reference: Float[ArrayLike, " time"],
        dt: float,
        *,
        external_force: Float[ArrayLike, " time"] | None = None,
        command_offset: Float[ArrayLike, " time"] | None = None,
        q0: ArrayLike = 0.0,
        solver=None,
        rtol: float = 1e-7,
        atol: float = 1e-10,
        max_steps: int = 500_000,
        check: bool = True,
    ) -> DriveResponse:
        r"""Simulate the closed loop following the sampled `reference`.

        **Arguments:**

        - `reference`: `(time,)` position reference `r_k = r(k·dt)` [m] (a step, a
          trapezoidal move `jaxvs.data.trapezoid(...).position`, a swept sine, ...).
        - `dt`: sample time of the reference and of the outputs [s]; for a digital
          controller it must equal `sample_time`.
        - `external_force`: optional `(time,)` force on the table [N] (cutting force,
          force pulses).
        - `command_offset`: optional `(time,)` signal added to the velocity controller's
          output before saturation (a disturbance injected at the drive input, e.g. the
          EMPS validation pulses, which enter `vir` [V]).
        - `q0`: initial position of every degree of freedom [m] (at rest).
        - `solver`: diffrax solver (default Tsit5; adaptive for an analogue controller,
          `n_substeps` fixed steps per sample for a digital one).
        - `rtol`, `atol`, `max_steps`: adaptive step control (analogue controller).
        - `check`: with concrete parameters, first check that the linearised loop is
          stable ([`UnstableLoopError`][]) and, for fixed steps, that the step is stable
          for the stiffest plant mode (`ValueError`). Skipped under `jit`/`vmap`, where a
          diverging simulation raises instead.

        Signals are linearly interpolated between samples for an analogue controller and
        held (zero-order hold) for a digital one.

        **Returns:**

        A [`DriveResponse`][].
        """
        where = "DriveAxis.simulate"
        r = jnp.asarray(reference)
        if r.ndim != 1 or r.shape[0] < 2:
            raise ValueError(f"{where}: reference must be 1-D (time,) with >= 2 samples.")
        if not jnp.issubdtype(r.dtype, jnp.floating):
            r = r.astype(jnp.result_type(float))

        def signal(x, name):
            if x is None:
                return jnp.zeros_like(r)
            x = jnp.asarray(x, r.dtype)
            if x.shape != r.shape:
                raise ValueError(
                    f"{where}: {name} has shape {x.shape} but the reference has {r.shape}; "
                    "give one sample per reference sample."
                )
            return x

        fe = signal(external_force, "external_force")
        ua = signal(command_offset, "command_offset")
        try:
            dt = float(dt)
        except TypeError:
            raise TypeError(f"{where}: dt must be a Python float [s].") from None
        if not dt > 0:
            raise ValueError(f"{where}: dt must be > 0 s; got {dt}.")
        if self.sample_time is not None and not math.isclose(dt, self.sample_time, rel_tol=1e-6):
            raise ValueError(
                f"{where}: the data's dt = {dt:g} s differs from the controller's "
                f"sample_time = {self.sample_time:g} s; resample the reference to the "
                "controller rate."
            )
        if check and not is_traced((self, r, fe, ua)):
            # the step first: an unstable integration also shows as unstable sampled poles
            if self.sample_time is not None:
                check_step(self.plant_poles(), dt / self.n_substeps, solver, where=where)
            self.check_stability()
        y0 = self._initial(jnp.asarray(q0, r.dtype), r.dtype)
        out = _simulate(self, r, fe, ua, y0, dt, solver, rtol, atol, max_steps)
        return finite_or_error(
            out,
            f"{where}: the simulation diverged (NaN or inf). The closed loop is unstable (a "
            "gain too high), or the fixed step too large for a stiff mode; check "
            "drive.check_stability() with concrete parameters, or raise n_substeps.",
        )


@eqx.filter_jit
def _simulate(drive, r, fe, ua, y0, dt, solver, rtol, atol, max_steps):
    """The jitted body of `DriveAxis.simulate` (compiled once per drive structure)."""
    ts = dt * jnp.arange(r.shape[0], dtype=r.dtype)
    if drive.sample_time is None:
        yz0 = jnp.concatenate([y0, jnp.zeros((1,), r.dtype)])
        ys = solve_ode(
            drive._continuous,
            yz0,
            ts,
            (ts, r, fe, ua),
            solver=solver,
            rtol=rtol,
            atol=atol,
            throw=True,
            options=ODEOptions(max_steps=max_steps),
        )
        dys = jax.vmap(lambda t, y: drive._continuous(t, y, (ts, r, fe, ua)))(ts, ys)

        def cmd(t, y):
            q, v, _ = drive._split(y[:-1])
            rr, uu = jnp.interp(t, ts, r), jnp.interp(t, ts, ua)
            return drive.velocity_loop(drive.position_loop(rr - drive._fb(q)) - v[0], y[-1], uu)

        command = jax.vmap(cmd)(ts, ys)
        states = ys
        yp = ys[:, :-1]
    else:
        c0 = {"z": jnp.zeros((), r.dtype), "q1": y0[0], "q2": y0[0]}
        yp, (command, _) = solve_sampled(
            drive._plant,
            drive._controller,
            y0,
            c0,
            (r, fe, ua),
            dt,
            None,
            n_substeps=drive.n_substeps,
            solver=solver,
        )
        dys = jax.vmap(lambda t, y, u, f: drive._plant(t, y, ((u, f), None)))(ts, yp, command, fe)
        states = yp
    nd = drive.n_dof
    force = jax.vmap(lambda y, u: drive.actuator.force(drive._split(y)[2], u))(yp, command)
    out = DriveResponse(
        t=ts,
        position=yp[:, nd - 1],
        velocity=yp[:, 2 * nd - 1],
        acceleration=dys[:, 2 * nd - 1],
        motor_position=yp[:, 0],
        motor_velocity=yp[:, nd],
        force=force,
        command=command,
        states=states,
    )
    return out


@eqx.filter_jit
def _linearise(drive):
    return drive._linearise_impl()


@eqx.filter_jit
def _sampled_jacobian(drive):
    x0 = jnp.zeros((drive.n_plant_states + 3,), jnp.result_type(drive.position_loop.kp, float))
    z = jnp.zeros((), x0.dtype)
    return jax.jacfwd(lambda x: drive._step_flat(x, (z, z, z)))(x0)


@eqx.filter_jit
def _plant_jacobian(drive):
    y0 = jnp.zeros((drive.n_plant_states,), jnp.result_type(drive.position_loop.kp, float))
    z = jnp.zeros((), y0.dtype)
    return jax.jacfwd(lambda y: drive._plant(0.0, y, ((z, z), None)))(y0)
