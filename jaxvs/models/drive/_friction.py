r"""Guideway and drive friction laws, backlash, saturation and encoder quantisation.

The nonlinear elements of a CNC feed drive (Pislaru 2001, §3.5 and §4.3; Armstrong-
Hélouvry, Dupont, Canudas de Wit, "A survey of models, analysis tools and compensation
methods for the control of machines with friction", Automatica 30, 1994). Every friction
law is an `eqx.Module` whose array fields are its parameters and whose `__call__` maps a
velocity [m/s] to a friction force [N] opposing it; all are pure, jittable, vmappable and
differentiable in their parameters.

**Smooth approximations.** `sign(v)` is discontinuous at `v = 0`, which an ODE solver and a
Levenberg–Marquardt Jacobian both dislike. Every law here replaces it by
`tanh(v / velocity_scale)`: the *sharpness parameter* `velocity_scale` [m/s] is the speed at
which the smooth sign reaches `tanh(1) ≈ 0.76` of its final value (and 0.995 at three
times that speed). `velocity_scale = 0` gives the exact discontinuous `sign` (for data
evaluation, e.g. IDIM regressors, not for simulation). Below `velocity_scale` the law acts
as a steep viscous damper of slope `Fc / velocity_scale`: a simulation with a fixed step
`h` needs `h · Fc / (velocity_scale · m) ≲ 2` to stay stable (see
`jaxvs.models.DriveAxis.simulate`, which checks it).
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real, check_physical, concrete
from .._base import check_parameters

__all__ = [
    "AbstractFriction",
    "ActuatorSaturation",
    "AsymmetricFriction",
    "CoulombFriction",
    "CoulombViscousFriction",
    "FrictionSum",
    "NoFriction",
    "StribeckFriction",
    "ViscousFriction",
    "dead_zone",
    "quantise",
    "saturation",
    "smooth_sign",
]

# heuristic: 0.1 mm/s. Well below the feed speeds of a machine-tool axis (mm/s to m/s) and
# above its encoder's velocity resolution at 1 kHz (µm/ms = 1 mm/s ... 0.1 mm/s).
DEFAULT_VELOCITY_SCALE = 1e-4


def _check_scale(velocity_scale: float, where: str) -> float:
    try:
        v = float(velocity_scale)
    except TypeError:
        raise TypeError(
            f"{where}: velocity_scale must be a Python float [m/s] (it is a fixed modelling "
            f"choice, not a calibrated parameter); got {type(velocity_scale).__name__}."
        ) from None
    if not v >= 0:
        raise ValueError(
            f"{where}: velocity_scale must be >= 0 m/s (0 = exact sign, > 0 = smooth tanh); "
            f"got {velocity_scale}."
        )
    return v


def smooth_sign(velocity: ArrayLike, velocity_scale: float) -> Array:
    """`tanh(v / velocity_scale)`, or the exact `sign(v)` when `velocity_scale == 0`.

    **Arguments:**

    - `velocity`: velocity [m/s] (any shape).
    - `velocity_scale`: sharpness [m/s] (a Python float, >= 0): the speed at which the
      smooth sign reaches `tanh(1) ≈ 0.76`.

    **Returns:**

    An array shaped like `velocity`, values in `[-1, 1]`.
    """
    v = jnp.asarray(velocity)
    if velocity_scale == 0:
        return jnp.sign(v)
    return jnp.tanh(v / velocity_scale)


def _level(x: ArrayLike, what: str, unit: str) -> ArrayLike:
    """A friction level given by the user: >= 0 (the sign comes from the velocity)."""
    return check_physical(x, what, strict=False, unit=unit)


class AbstractFriction(eqx.Module):
    """A friction law: `friction(v)` is the force [N] that opposes the velocity `v` [m/s]
    (same sign as `v`, to be subtracted in `m a = f − friction(v)`)."""

    def __check_init__(self):
        check_parameters(self)

    @abc.abstractmethod
    def __call__(self, velocity: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """Friction force [N] at `velocity` [m/s], elementwise."""


class NoFriction(AbstractFriction):
    """Frictionless guideway (`F = 0`)."""

    def __call__(self, velocity):
        return jnp.zeros_like(jnp.asarray(velocity, dtype=jnp.result_type(velocity, float)))


class ViscousFriction(AbstractFriction):
    """Viscous friction `F = Fv · v`.

    **Arguments:**

    - `Fv`: viscous coefficient [N·s/m].
    """

    Fv: Float[Array, ""]

    def __init__(self, Fv: ArrayLike):
        self.Fv = as_real(_level(Fv, "ViscousFriction: Fv", "N·s/m"), "ViscousFriction: Fv")

    def __call__(self, velocity):
        return self.Fv * jnp.asarray(velocity)


class CoulombFriction(AbstractFriction):
    """Coulomb (dry) friction `F = Fc · sign(v)`, smoothed as `Fc · tanh(v / velocity_scale)`.

    **Arguments:**

    - `Fc`: Coulomb force [N].
    - `velocity_scale`: sharpness [m/s] of the smooth sign (static; 0 = exact sign).
    """

    Fc: Float[Array, ""]
    velocity_scale: float = eqx.field(static=True)

    def __init__(self, Fc: ArrayLike, *, velocity_scale: float = DEFAULT_VELOCITY_SCALE):
        self.Fc = as_real(_level(Fc, "CoulombFriction: Fc", "N"), "CoulombFriction: Fc")
        self.velocity_scale = _check_scale(velocity_scale, "CoulombFriction")

    def __call__(self, velocity):
        return self.Fc * smooth_sign(velocity, self.velocity_scale)


class CoulombViscousFriction(AbstractFriction):
    """Coulomb + viscous friction with a constant offset, the rigid-axis model of the EMPS
    benchmark (Janot, Gautier, Brunot 2019, eq. (1)):
    `F = Fv · v + Fc · sign(v) + offset`.

    `offset` [N] is a constant force (a measurement offset of the drive force, or gravity
    on an inclined axis); it does not depend on the velocity.

    **Arguments:**

    - `Fc`: Coulomb force [N].
    - `Fv`: viscous coefficient [N·s/m].
    - `offset`: constant force [N] (default 0).
    - `velocity_scale`: sharpness [m/s] of the smooth sign (static; 0 = exact sign).
    """

    Fc: Float[Array, ""]
    Fv: Float[Array, ""]
    offset: Float[Array, ""]
    velocity_scale: float = eqx.field(static=True)

    def __init__(
        self,
        Fc: ArrayLike,
        Fv: ArrayLike,
        offset: ArrayLike = 0.0,
        *,
        velocity_scale: float = DEFAULT_VELOCITY_SCALE,
    ):
        where = "CoulombViscousFriction"
        self.Fc = as_real(_level(Fc, f"{where}: Fc", "N"), f"{where}: Fc")
        self.Fv = as_real(_level(Fv, f"{where}: Fv", "N·s/m"), f"{where}: Fv")
        self.offset = as_real(offset, f"{where}: offset")
        self.velocity_scale = _check_scale(velocity_scale, where)

    def __call__(self, velocity):
        v = jnp.asarray(velocity)
        return self.Fv * v + self.Fc * smooth_sign(v, self.velocity_scale) + self.offset


class StribeckFriction(AbstractFriction):
    r"""Stribeck friction with viscous part (Armstrong-Hélouvry et al. 1994, eq. (5)):

    `F = (Fc + (Fs − Fc) · exp(−|v / vs|^shape)) · sign(v) + Fv · v`.

    The static (breakaway) force `Fs` falls to the Coulomb level `Fc` over the Stribeck
    speed `vs`; `shape` is 2 (Gaussian, the usual choice) or 1 (Tustin's exponential).

    **Arguments:**

    - `Fc`: Coulomb force [N].
    - `Fs`: static (breakaway) force [N], usually `Fs > Fc`.
    - `vs`: Stribeck speed [m/s], > 0.
    - `Fv`: viscous coefficient [N·s/m] (default 0).
    - `shape`: exponent δ of the Stribeck curve (static, default 2).
    - `velocity_scale`: sharpness [m/s] of the smooth sign (static; 0 = exact sign).
      Choose it well below `vs`, or the Stribeck dip is smoothed away.
    """

    Fc: Float[Array, ""]
    Fs: Float[Array, ""]
    vs: Float[Array, ""]
    Fv: Float[Array, ""]
    shape: float = eqx.field(static=True)
    velocity_scale: float = eqx.field(static=True)

    def __init__(
        self,
        Fc: ArrayLike,
        Fs: ArrayLike,
        vs: ArrayLike,
        Fv: ArrayLike = 0.0,
        *,
        shape: float = 2.0,
        velocity_scale: float = DEFAULT_VELOCITY_SCALE / 10,
    ):
        where = "StribeckFriction"
        self.Fc = as_real(_level(Fc, f"{where}: Fc", "N"), f"{where}: Fc")
        self.Fs = as_real(_level(Fs, f"{where}: Fs", "N"), f"{where}: Fs")
        self.vs = eqx.error_if(
            as_real(vs, f"{where}: vs"), ~(jnp.asarray(vs) > 0), f"{where}: vs must be > 0."
        )
        self.Fv = as_real(_level(Fv, f"{where}: Fv", "N·s/m"), f"{where}: Fv")
        if not float(shape) > 0:
            raise ValueError(f"{where}: shape must be > 0 (1 or 2 usually); got {shape}.")
        self.shape = float(shape)
        self.velocity_scale = _check_scale(velocity_scale, where)

    def __call__(self, velocity):
        v = jnp.asarray(velocity)
        level = self.Fc + (self.Fs - self.Fc) * jnp.exp(-(jnp.abs(v / self.vs) ** self.shape))
        return level * smooth_sign(v, self.velocity_scale) + self.Fv * v


class AsymmetricFriction(AbstractFriction):
    r"""Direction-dependent Coulomb + viscous friction (Janot, Gautier, Brunot 2019,
    eq. (12)): `F = Fv+ · v + Fc+` for `v > 0` and `F = Fv− · v − Fc−` for `v < 0`.

    Smoothed as `w(v) (Fv+ v + Fc+ s(v)) + (1 − w(v)) (Fv− v + Fc− s(v))` with
    `s = tanh(v / velocity_scale)` and the blend `w = (1 + s) / 2`; for
    `|v| ≫ velocity_scale` this is eq. (12) exactly, and `F(0) = 0`.

    **Arguments:**

    - `Fc_pos`, `Fv_pos`: Coulomb force [N] and viscous coefficient [N·s/m] for `v > 0`.
    - `Fc_neg`, `Fv_neg`: the same for `v < 0` (`Fc_neg > 0` opposes negative motion).
    - `velocity_scale`: sharpness [m/s] (static; 0 = exact sign and switch).
    """

    Fc_pos: Float[Array, ""]
    Fv_pos: Float[Array, ""]
    Fc_neg: Float[Array, ""]
    Fv_neg: Float[Array, ""]
    velocity_scale: float = eqx.field(static=True)

    def __init__(
        self,
        Fc_pos: ArrayLike,
        Fv_pos: ArrayLike,
        Fc_neg: ArrayLike,
        Fv_neg: ArrayLike,
        *,
        velocity_scale: float = DEFAULT_VELOCITY_SCALE,
    ):
        where = "AsymmetricFriction"
        self.Fc_pos = as_real(Fc_pos, f"{where}: Fc_pos")
        self.Fv_pos = as_real(Fv_pos, f"{where}: Fv_pos")
        self.Fc_neg = as_real(Fc_neg, f"{where}: Fc_neg")
        self.Fv_neg = as_real(Fv_neg, f"{where}: Fv_neg")
        self.velocity_scale = _check_scale(velocity_scale, where)

    def __call__(self, velocity):
        v = jnp.asarray(velocity)
        s = smooth_sign(v, self.velocity_scale)
        w = 0.5 * (1 + s)
        pos = self.Fv_pos * v + self.Fc_pos * s
        neg = self.Fv_neg * v + self.Fc_neg * s
        return w * pos + (1 - w) * neg


class FrictionSum(AbstractFriction):
    """The sum of several friction laws, `F = Σ_i F_i(v)`: compose e.g. an
    `AsymmetricFriction` with the excess static friction of a `StribeckFriction` whose
    `Fc = 0` (a Stribeck dip on top of direction-dependent Coulomb + viscous friction).

    **Arguments:**

    - `*laws`: friction laws (at least one).
    """

    laws: tuple[AbstractFriction, ...]

    def __init__(self, *laws: AbstractFriction):
        if not laws or not all(isinstance(f, AbstractFriction) for f in laws):
            raise TypeError("FrictionSum: give one or more friction laws (AbstractFriction).")
        self.laws = tuple(laws)

    def __call__(self, velocity):
        return sum(f(velocity) for f in self.laws)


def dead_zone(x: ArrayLike, half_width: ArrayLike, *, smoothness: float = 0.0) -> Array:
    r"""Dead zone: `0` for `|x| <= b`, `x − b·sign(x)` outside (backlash of a gear, nut or
    coupling when applied to the relative displacement across a spring, Pislaru 2001, §4.3.1).

    With `smoothness = ε > 0` the corners are rounded by softplus:
    `ε·log(1 + e^{(x − b)/ε}) − ε·log(1 + e^{(−x − b)/ε})`, exact to `ε·log 2` at the
    corners and to `ε·e^{−(|x| − b)/ε}` away from them.

    **Arguments:**

    - `x`: relative displacement [m] (any shape).
    - `half_width`: half the backlash `b` [m], >= 0 (the total play is `2b`).
    - `smoothness`: corner rounding ε [m] (Python float, >= 0).

    **Returns:**

    The transmitted displacement [m], shaped like `x`.
    """
    x = jnp.asarray(x)
    b = jnp.asarray(half_width)
    if smoothness < 0:
        raise ValueError(f"dead_zone: smoothness must be >= 0 m; got {smoothness}.")
    if smoothness == 0:
        # not `x − clip(x, −b, b)`: at b = 0 its derivative at x = 0 is 1/4 (ties of
        # min/max split the gradient), which would corrupt linearisations about rest
        return jnp.where(jnp.abs(x) < b, jnp.zeros_like(x), x - b * jnp.sign(x))
    eps = smoothness
    return eps * (jax.nn.softplus((x - b) / eps) - jax.nn.softplus((-x - b) / eps))


def saturation(u: ArrayLike, limit: ArrayLike) -> Array:
    """Symmetric output saturation `clip(u, −limit, limit)` of an amplifier or controller
    (e.g. the ±10 V of the EMPS drive). Its derivative is 1 inside and 0 outside.

    **Arguments:**

    - `u`: command (any unit, any shape).
    - `limit`: saturation level (> 0, same unit; `inf` for none).

    **Returns:**

    The saturated command, shaped like `u`.
    """
    u = jnp.asarray(u)
    return jnp.clip(u, -limit, limit)


class ActuatorSaturation(eqx.Module):
    r"""Force (current) limit of an amplifier: the force applied to the axis is the command
    clipped at `±F_max` (Pislaru 2001, §4.3: the saturation of the servo amplifier; the
    current limit of a digital drive).

    With `smoothness = ε > 0` the corners are rounded by softplus,
    `u − ε·log(1 + e^{(u − F)/ε}) + ε·log(1 + e^{(−u − F)/ε})`: odd in `u`, within `ε·log 2`
    of the hard clip at the corners and `ε·e^{−(F − |u|)/ε}` of it inside, differentiable in
    `u` and in `F_max` everywhere (a Levenberg–Marquardt calibration of the limit sees every
    sample near it, not only those beyond). `smoothness = 0` is the hard clip.

    **Arguments:**

    - `limit`: `F_max` [N] (or the command's unit), > 0.
    - `smoothness`: corner rounding `ε` (Python float, >= 0, same unit; default 0).
    """

    limit: Float[Array, ""]
    smoothness: float = eqx.field(static=True, default=0.0)

    def __init__(self, limit: ArrayLike, smoothness: float = 0.0):
        self.limit = as_real(limit, "ActuatorSaturation: limit")
        try:
            eps = float(smoothness)
        except TypeError:
            raise TypeError(
                "ActuatorSaturation: smoothness must be a Python float (a fixed modelling "
                f"choice, not a calibrated parameter); got {type(smoothness).__name__}."
            ) from None
        if not eps >= 0:
            raise ValueError(f"ActuatorSaturation: smoothness must be >= 0; got {smoothness}.")
        self.smoothness = eps

    def __check_init__(self):
        check_parameters(self)
        lim = concrete(self.limit)  # None when traced (inside jit): left to the caller
        if lim is not None and not np.all(lim > 0):
            raise ValueError(
                "ActuatorSaturation: limit must be > 0 (the largest force the amplifier "
                f"applies); got {lim}."
            )

    def __call__(self, command: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """The applied force for the `command` (elementwise)."""
        u = jnp.asarray(command)
        f = self.limit
        if self.smoothness == 0:
            return jnp.clip(u, -f, f)
        eps = self.smoothness
        return u - eps * jax.nn.softplus((u - f) / eps) + eps * jax.nn.softplus((-u - f) / eps)

    def excess(self, command: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """The part of the command the amplifier does not apply, `command − self(command)`."""
        return jnp.asarray(command) - self(command)


def quantise(x: ArrayLike, resolution: float) -> Array:
    """Encoder quantisation `resolution · round(x / resolution)`.

    The rounding has zero derivative almost everywhere, which would hide every parameter
    behind an encoder from a gradient-based calibration; the derivative is therefore
    passed straight through (`x + stop_gradient(round(x) − x)`, the straight-through
    estimator), i.e. the quantiser is differentiated as the identity.

    **Arguments:**

    - `x`: position [m or rad] (any shape).
    - `resolution`: one encoder increment [m or rad] (Python float, >= 0; 0 = none). The
      EMPS encoder has 50 000 counts per revolution.

    **Returns:**

    The quantised position, shaped like `x`.
    """
    x = jnp.asarray(x)
    if resolution < 0:
        raise ValueError(f"quantise: resolution must be >= 0; got {resolution}.")
    if resolution == 0:
        return x
    q = resolution * jnp.round(x / resolution)
    return x + jax.lax.stop_gradient(q - x)
