r"""Friction laws with internal states: the Dahl and LuGre bristle models, and a friction
level that drifts with the work recently done.

A static law ([`AbstractFriction`][jaxvs.models.AbstractFriction]) maps the velocity to a
force. The laws here carry a state `z` of their own, integrated beside the mechanics:
`ż = rates(z, v)`, `F = force(z, v)`. Called as a static law (`law(v)`) they return their
**steady-state** force at constant velocity, so they can stand wherever a static law is
expected (IDIM regressors, a rigid axis's linear part); a simulator that knows about the
state ([`jaxvs.studies.benchmarks.OpenLoopAxis`][]) integrates it.

- **Dahl** (P. R. Dahl, *A solid friction model*, Aerospace Corp. TOR-0158, 1968):
  `ż = v − σ0 |v| z / Fc`, `F = σ0 z + Fv v`: a pre-sliding spring of stiffness `σ0` that
  saturates at the Coulomb level.
- **LuGre** (C. Canudas de Wit, H. Olsson, K. J. Åström, P. Lischinsky, *A new model for
  control of systems with friction*, IEEE TAC 40(3), 1995, eq. (2)–(5)):
  `ż = v − σ0 |v| z / g(v)`, `g(v) = Fc + (Fs − Fc) e^{−(v/vs)²}`,
  `F = σ0 z + σ1 ż + Fv v`.
- **Drifting friction**: a static law scaled by `1 + θ`, where `θ` follows the power the
  law dissipates through a first-order lag,
  `θ̇ = (κ |F0(v) v| / P_ref − θ) / τ`, `F = (1 + θ) F0(v) + offset` — a lumped
  temperature of the lubricant and the preloaded contacts: friction that changes with the
  recent work of the axis (κ < 0: it falls as the axis warms up). Its state starts from the
  steady state of the record's first velocity, so two records with the same history see
  the same friction, and records with another history (pulses, another speed profile)
  another one — without any measurement of the state.

All three are `eqx.Module`s, pure and differentiable in their parameters.
"""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real
from ._friction import DEFAULT_VELOCITY_SCALE, AbstractFriction, _check_scale, smooth_sign

__all__ = ["AbstractDynamicFriction", "DahlFriction", "DriftingFriction", "LuGreFriction"]


class AbstractDynamicFriction(AbstractFriction):
    """A friction law with internal states `z` (`n_states` of them)."""

    @property
    @abc.abstractmethod
    def n_states(self) -> int:
        """Number of internal states."""

    @abc.abstractmethod
    def steady_state(self, velocity: Float[ArrayLike, ""]) -> Float[Array, " n_states"]:
        """The internal state reached at constant `velocity` [m/s]."""

    @abc.abstractmethod
    def rates(
        self, z: Float[Array, " n_states"], velocity: Float[ArrayLike, ""]
    ) -> Float[Array, " n_states"]:
        """`ż` at state `z` and velocity `velocity` [m/s]."""

    @abc.abstractmethod
    def force(
        self, z: Float[Array, " n_states"], velocity: Float[ArrayLike, ""]
    ) -> Float[Array, ""]:
        """Friction force [N] at state `z` and velocity `velocity` (opposing it)."""

    def __call__(self, velocity):
        """Steady-state friction force [N] at constant `velocity` [m/s], elementwise."""
        v = jnp.asarray(velocity)
        return jnp.vectorize(lambda x: self.force(self.steady_state(x), x))(v)


class LuGreFriction(AbstractDynamicFriction):
    r"""LuGre friction (Canudas de Wit et al. 1995): bristles of stiffness `σ0` and damping
    `σ1` whose mean deflection `z` follows `ż = v − σ0 |v| z / g(v)`, with the Stribeck
    curve `g(v) = Fc + (Fs − Fc) exp(−(v / vs)²)`; `F = σ0 z + σ1 ż + Fv v`.

    **Arguments:**

    - `Fc`, `Fs`: Coulomb and static force [N] (`Fs >= Fc > 0`).
    - `vs`: Stribeck speed [m/s] (> 0).
    - `sigma0`: bristle stiffness [N/m] (> 0); `sigma1`: bristle damping [N·s/m] (>= 0).
    - `Fv`: viscous coefficient [N·s/m].
    - `velocity_scale`: sharpness [m/s] of the smooth sign of the steady state (static).

    The bristle dynamics are fast (rate `σ0 |v| / Fc`); an explicit solver needs
    `h σ0 |v|max / Fc ≲ 2.5` per step `h`.
    """

    Fc: Float[Array, ""]
    Fs: Float[Array, ""]
    vs: Float[Array, ""]
    sigma0: Float[Array, ""]
    sigma1: Float[Array, ""]
    Fv: Float[Array, ""]
    velocity_scale: float = eqx.field(static=True)

    def __init__(
        self, Fc, Fs, vs, sigma0, sigma1=0.0, Fv=0.0, *, velocity_scale=DEFAULT_VELOCITY_SCALE
    ):
        where = "LuGreFriction"
        self.Fc = as_real(Fc, f"{where}: Fc")
        self.Fs = as_real(Fs, f"{where}: Fs")
        self.vs = as_real(vs, f"{where}: vs")
        self.sigma0 = as_real(sigma0, f"{where}: sigma0")
        self.sigma1 = as_real(sigma1, f"{where}: sigma1")
        self.Fv = as_real(Fv, f"{where}: Fv")
        self.velocity_scale = _check_scale(velocity_scale, where)

    @property
    def n_states(self):
        return 1

    def _g(self, v):
        return self.Fc + (self.Fs - self.Fc) * jnp.exp(-((v / self.vs) ** 2))

    def steady_state(self, velocity):
        v = jnp.asarray(velocity)
        return (self._g(v) * smooth_sign(v, self.velocity_scale) / self.sigma0)[None]

    def rates(self, z, velocity):
        v = jnp.asarray(velocity)
        return v - self.sigma0 * jnp.abs(v) * z / self._g(v)

    def force(self, z, velocity):
        v = jnp.asarray(velocity)
        return self.sigma0 * z[0] + self.sigma1 * self.rates(z, v)[0] + self.Fv * v


class DahlFriction(AbstractDynamicFriction):
    r"""Dahl friction (1968): `ż = v − σ0 |v| z / Fc`, `F = σ0 z + Fv v + offset` — a
    pre-sliding spring of stiffness `σ0` saturating at the Coulomb force `Fc`; LuGre
    without the Stribeck dip and the bristle damping.

    **Arguments:**

    - `Fc`: Coulomb force [N] (> 0); `sigma0`: stiffness [N/m] (> 0).
    - `Fv`: viscous coefficient [N·s/m]; `offset`: constant force [N].
    - `velocity_scale`: sharpness [m/s] of the smooth sign of the steady state (static).
    """

    Fc: Float[Array, ""]
    sigma0: Float[Array, ""]
    Fv: Float[Array, ""]
    offset: Float[Array, ""]
    velocity_scale: float = eqx.field(static=True)

    def __init__(self, Fc, sigma0, Fv=0.0, offset=0.0, *, velocity_scale=DEFAULT_VELOCITY_SCALE):
        where = "DahlFriction"
        self.Fc = as_real(Fc, f"{where}: Fc")
        self.sigma0 = as_real(sigma0, f"{where}: sigma0")
        self.Fv = as_real(Fv, f"{where}: Fv")
        self.offset = as_real(offset, f"{where}: offset")
        self.velocity_scale = _check_scale(velocity_scale, where)

    @property
    def n_states(self):
        return 1

    def steady_state(self, velocity):
        v = jnp.asarray(velocity)
        return (self.Fc * smooth_sign(v, self.velocity_scale) / self.sigma0)[None]

    def rates(self, z, velocity):
        v = jnp.asarray(velocity)
        return v - self.sigma0 * jnp.abs(v) * z / self.Fc

    def force(self, z, velocity):
        v = jnp.asarray(velocity)
        return self.sigma0 * z[0] + self.Fv * v + self.offset


class DriftingFriction(AbstractDynamicFriction):
    r"""A static friction law whose level drifts with the power it dissipates:
    `F = (1 + θ) F0(v) + offset`, `θ̇ = (κ |F0(v) v| / P_ref − θ) / τ`.

    `θ` is a lumped, temperature-like state (lubricant, preload of the screw and the
    guides): at constant speed it settles at `κ |F0 v| / P_ref` within a few `τ`. It
    starts from the steady state of a record's first velocity, so it needs no measurement.

    **Arguments:**

    - `law`: the static law `F0` (e.g. `AsymmetricFriction`).
    - `gain`: `κ`, the relative change of friction per `P_ref` of dissipated power (any
      sign).
    - `time_constant`: `τ` [s] (> 0).
    - `offset`: a constant force [N] not scaled by `θ`.
    - `power_scale`: `P_ref` [W] (static, default 100 W).
    """

    law: AbstractFriction
    gain: Float[Array, ""]
    time_constant: Float[Array, ""]
    offset: Float[Array, ""]
    power_scale: float = eqx.field(static=True)

    def __init__(self, law, gain=0.0, time_constant=10.0, offset=0.0, *, power_scale=100.0):
        where = "DriftingFriction"
        if not isinstance(law, AbstractFriction) or isinstance(law, AbstractDynamicFriction):
            raise TypeError(
                f"{where}: law must be a static jaxvs friction law; got {type(law).__name__}."
            )
        if not power_scale > 0:
            raise ValueError(f"{where}: power_scale must be > 0 W; got {power_scale!r}.")
        self.law = law
        self.gain = as_real(gain, f"{where}: gain")
        self.time_constant = as_real(time_constant, f"{where}: time_constant")
        self.offset = as_real(offset, f"{where}: offset")
        self.power_scale = float(power_scale)

    @property
    def n_states(self):
        return 1

    def steady_state(self, velocity):
        v = jnp.asarray(velocity)
        return (self.gain * jnp.abs(self.law(v) * v) / self.power_scale)[None]

    def rates(self, z, velocity):
        return (self.steady_state(velocity) - z) / self.time_constant

    def force(self, z, velocity):
        v = jnp.asarray(velocity)
        return (1 + z[0]) * self.law(v) + self.offset
