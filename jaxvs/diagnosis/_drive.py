"""The `drive` family: a rigid axis `M q̈ + Fv q̇ + offset = u` and its candidate effects.

The model is an inverse-dynamics model (the force is predicted from the measured motion),
as in IDIM-LS identification of drives and robots (Gautier & Khalil; the EMPS description,
§3): the position is low-pass filtered forward and backward, differentiated, the force is
filtered by the same filter, and everything is decimated to the analysis rate. The gap is
the normalised RMS force error (EMPS eq. 11).

Each candidate effect is a differentiable augmentation that is zero at zero size:

| effect | augmentation of the predicted force |
|---|---|
| `coulomb_friction` | `jaxvs.models.CoulombFriction`: `Fc·tanh(q̇/v_s)` (sharpness `v_s` fixed) |
| `asymmetric_friction` | `jaxvs.models.AsymmetricFriction`: levels `Fc+`, `Fc−` and viscous `±ΔFv/2` per direction |
| `stribeck_friction` | `jaxvs.models.StribeckFriction`: `(Fc + (Fs − Fc)·exp(−(q̇/v_st)²))·tanh(q̇/v_s)` |
| `backlash` | `m_L(q̈_L − q̈) + F_L(s(q̇_L) − s(q̇))`, `q_L` = play of `q` (half gap `b`): a load with inertia and friction, unloaded while the gap is crossed |
| `resonance` | `−s²/(s² + 2ζωs + ω²)·(m_r q̈ + c_r q̇)`: a load `m_r` on a spring-damper |
| `time_delay` | the whole prediction advanced by `τ` (force acting `τ` after it is commanded) |
| `external_force` | force pulses at events found in the residual (amplitude per event) |
| `position_dependence` | `Σ c_k P_k(q̄) + Σ_h A_h sin(2πhq/p) + B_h cos(2πhq/p)` (Legendre + ripple of pitch `p`, 2 harmonics) |
| `saturation` | `u − sat(u)`, `sat` the library's `jaxvs.models.ActuatorSaturation` at `±F_max`: the recorded command beyond the limit is not applied |

Every friction effect is set-valued at rest, as friction is (Karnopp): an axis at rest is
held by whatever friction force balances the applied force, up to the static level
(`Fc`, `Fc±`, `Fs`), so at rest the force is predicted as the measured one projected onto
that band (`_held`); a static level above the sliding one shows as held forces beyond
`±Fc`. Friction extensions (asymmetric, Stribeck) contain Coulomb friction and replace it
when they are added after it. External-force events are only found while the axis moves
(at rest static friction carries any force), and each record with events gets its own
level. Every effect states its physical admissibility
(`admissible(context)`); the family states when a record identifies the rigid axis
(`identifiability`: motion both ways and a Jacobian of the calibrated parameters of full
rank; a mass the record does not excite is fixed, at zero or the `mass` option, with a
warning, instead of refusing the record) and simulates the effect-free null records of the recorded set-up
(`null_experiments`: the closed loop with the controller identified from the record, or
the record's motion replayed).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.signal as ss
import scipy.stats
from jaxtyping import Array, Float

from .. import models
from .._misc import legendre
from ..calibration import bounded, fixed, positive, unwrap
from ..data import Record
from ..signal import DriveBand
from ._base import (
    AbstractAdditiveEffect,
    AbstractEffect,
    AbstractFamily,
    AdmissibilityContext,
    Context,
    EffectSpec,
    Experiment,
    GapModel,
    NotIdentifiable,
    check,
    delay_rules,
    fft_delay,
    scalar,
)
from ._stats import (
    difference_noise_sigma,
    noise_like,
    quantisation_step,
    white_noise_floor,
)

__all__ = ["DriveFamily", "RigidNominal"]


class RigidNominal(eqx.Module):
    """Nominal rigid axis, `u = M q̈ + Fv q̇ + offset` [N]: the library's
    `jaxvs.models.RigidInverseDynamics` on the family's experiment arrays.

    `M` is an array when it is calibrated and a Python float when it is fixed (a record
    that does not excite the inertia, e.g. a quasi-static friction rig: `DriveFamily`
    fixes it at zero or at the `mass` option); a float is no calibrated leaf."""

    M: Any  # [kg]: Float[Array, ""] calibrated, float fixed
    Fv: Any  # [N·s/m]: Float[Array, ""] calibrated, float fixed (bounded at zero)
    offset: Float[Array, ""]

    def model(self) -> models.RigidInverseDynamics:
        """The library model with these parameters."""
        return models.RigidInverseDynamics(self.M, self.Fv, self.offset)

    def __call__(self, d: Mapping[str, Array]) -> Array:
        return self.model().force(d["v"], d["a"])

    def parameters(self) -> dict[str, float]:
        return {"M": scalar(self.M), "Fv": scalar(self.Fv), "offset": scalar(self.offset)}


# ------------------------------------------------------------------------------ effects


def _pos(x):
    """`positive` with a floor: a shape that underflowed to 0 stays admissible."""
    return positive(jnp.maximum(jnp.asarray(x), 1e-12))


def _ok(x) -> bool:
    return bool(np.all(np.isfinite(np.asarray(x))))


def _held(y, d, negative, positive, vs):
    """The prediction `y` (with the sliding friction law) completed at rest: a friction
    law is set-valued at zero velocity -- an axis at rest is held by whatever friction
    force balances the applied force, up to the static level of each direction (Karnopp
    1985; Armstrong-Hélouvry et al. 1994, §2) -- so at rest the force is predicted as the
    measured one projected onto `[−negative, positive]` around `y`. The rest weight
    `exp(−(q̇/v_s)²)` is 1 at rest and vanishes once the axis slides (`v_s` the
    sharpness of the sign law)."""
    rest = jnp.exp(-jnp.square(d["v"] / vs))
    held = jnp.clip(d["y"] - y, -jnp.abs(negative), jnp.abs(positive))
    return y + rest * held


class CoulombEffect(AbstractEffect):
    """Dry friction of constant level, the library's `jaxvs.models.CoulombFriction`
    (`Fc·tanh(q̇/v_s)`, sharpness `v_s` fixed) while sliding; at rest it holds the axis
    with any force up to `±Fc` (`_held`)."""

    name: ClassVar[str] = "coulomb_friction"
    order: ClassVar[int] = 0
    size: Float[Array, 1]  # Fc [N]
    vs: Any  # sharpness [m/s], fixed

    def contribution(self, d, nominal):
        # the library law on the velocity in units of the sharpness (`v/v_s`, sharpness 1):
        # `v_s` stays an array, so starts of several sharpnesses share one structure
        return models.CoulombFriction(self.size[0], velocity_scale=1.0)(d["v"] / self.vs)

    def apply(self, y, d, nominal):
        return _held(y + self.contribution(d, nominal), d, self.size[0], self.size[0], self.vs)

    def constrained(self):
        return eqx.tree_at(lambda e: e.vs, self, replace_fn=fixed)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        fc = scalar(self.size[0])
        return check((np.isfinite(fc) and fc >= 0, f"negative Coulomb friction Fc = {fc:.4g} N"))

    def parameters(self):
        return {"Fc": scalar(self.size[0]), "v_s": scalar(self.vs)}


class AsymmetricFrictionEffect(AbstractEffect):
    """Direction-dependent Coulomb and viscous friction, the library's
    `jaxvs.models.AsymmetricFriction` (Janot et al. 2019, eq. 12) with levels `Fc+`,
    `Fc−` and viscous coefficients `±ΔFv/2` on top of the nominal `Fv`; at rest it holds
    the axis with any force in `[−Fc−, Fc+]` (`_held`)."""

    name: ClassVar[str] = "asymmetric_friction"
    order: ClassVar[int] = 0
    size: Float[Array, 3]  # Fc+ [N], Fc− [N], ΔFv [N·s/m]
    vs: Any  # sharpness [m/s], fixed

    def contribution(self, d, nominal):
        fp, fn, dfv = self.size[0], self.size[1], self.size[2]
        h = 0.5 * dfv * self.vs  # viscous coefficients per unit of v/v_s
        law = models.AsymmetricFriction(fp, h, fn, -h, velocity_scale=1.0)
        return law(d["v"] / self.vs)

    def apply(self, y, d, nominal):
        y = y + self.contribution(d, nominal)
        return _held(y, d, self.size[1], self.size[0], self.vs)

    def constrained(self):
        return eqx.tree_at(lambda e: e.vs, self, replace_fn=fixed)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        fp, fn, dfv = (float(x) for x in np.asarray(self.size))
        fv = float(context.nominal.get("Fv", 0.0))
        return check(
            (_ok(self.size), "non-finite friction parameters"),
            (fp >= 0, f"negative friction level in the positive direction, Fc+ = {fp:.4g} N"),
            (fn >= 0, f"negative friction level in the negative direction, Fc− = {fn:.4g} N"),
            (
                fv - 0.5 * abs(dfv) >= 0,
                f"negative viscous friction in one direction (Fv = {fv:.4g}, ΔFv = {dfv:.4g} "
                "N·s/m)",
            ),
        )

    def parameters(self):
        fp, fn, dfv = (float(x) for x in np.asarray(self.size))
        return {"Fc_pos": fp, "Fc_neg": fn, "dFv": dfv, "v_s": scalar(self.vs)}


class StribeckEffect(AbstractEffect):
    """Friction falling from a static level `Fs` to the Coulomb level `Fc` over the
    Stribeck speed, the library's `jaxvs.models.StribeckFriction` (Armstrong-Hélouvry
    et al. 1994, eq. 5); at rest it holds the axis with any force up to the static
    level `±Fs` (`_held`)."""

    name: ClassVar[str] = "stribeck_friction"
    order: ClassVar[int] = 0
    size: Float[Array, 2]  # Fc, Fs [N]
    v_st: Any  # Stribeck speed [m/s], positive, calibrated
    vs: Any  # sharpness [m/s], fixed

    def contribution(self, d, nominal):
        ratio = self.v_st / self.vs
        # the library law checks `vs > 0` at run time; a trial step of LM may underflow it
        # or make it non-finite (that step is then rejected by its cost), so keep it valid
        ratio = jnp.where(jnp.isfinite(ratio), jnp.maximum(ratio, 1e-12), 1.0)
        law = models.StribeckFriction(self.size[0], self.size[1], ratio, velocity_scale=1.0)
        return law(d["v"] / self.vs)

    def apply(self, y, d, nominal):
        return _held(y + self.contribution(d, nominal), d, self.size[1], self.size[1], self.vs)

    def constrained(self):
        e = eqx.tree_at(lambda e: e.vs, self, replace_fn=fixed)
        return eqx.tree_at(lambda e: e.v_st, e, replace_fn=_pos)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        fc, fs = (float(x) for x in np.asarray(self.size))
        v_st = scalar(self.v_st)
        return check(
            (_ok(self.size) and np.isfinite(v_st), "non-finite friction parameters"),
            (fc >= 0, f"negative Coulomb level Fc = {fc:.4g} N"),
            (
                fs >= fc,
                f"static friction below the Coulomb level (Fs = {fs:.4g} < Fc = {fc:.4g} N)",
            ),
            (
                v_st > scalar(self.vs),
                f"Stribeck speed {v_st:.3g} m/s below the sharpness of the sign law",
            ),
        )

    def parameters(self):
        fc, fs = (float(x) for x in np.asarray(self.size))
        return {"Fc": fc, "Fs": fs, "v_stribeck": scalar(self.v_st), "v_s": scalar(self.vs)}


def _play(q: Array, b: Array) -> Array:
    """Play (backlash) operator: the load follows the motor only after `2b` of slack."""

    def step(ql, qk):
        ql = jnp.clip(ql, qk - b, qk + b)
        return ql, ql

    _, out = jax.lax.scan(step, q[0], q)
    return out


def _motion(q: Array, dt: float) -> tuple[Array, Array]:
    """Velocity and acceleration of a sampled position by central differences, smoothed
    by `[1/4, 1/2, 1/4]` (the contact spring of a real axis spreads an impact over a few
    samples)."""
    kernel = jnp.array([0.25, 0.5, 0.25])
    v = jnp.gradient(q, dt)
    a = jnp.gradient(v, dt)
    return jnp.convolve(v, kernel, mode="same"), jnp.convolve(a, kernel, mode="same")


PRESLIDING = 20e-6
"""Longest presliding displacement of dry friction the diagnosis expects [m] (heuristic:
the elastic micro-displacement of rolling and sliding contacts before gross sliding is
of the order of 1 to 20 µm; Al-Bender & Swevers 2008, *IEEE Control Systems* 28(6)).
A friction-loaded gap shorter than it cannot be told from friction that keeps its sign
for that distance after a reversal; an inertial gap (an impact) still can."""


class Backlash(AbstractAdditiveEffect):
    """Play of total width `2b` between the motor and a load `m_L` carried by friction.

    The load follows the motor through the play operator, `q_L = play(q, b)`; while the
    motor crosses the gap after a reversal it moves unloaded, so the load's inertia and
    dry friction act with the load's motion, not the motor's:
    `m_L (q̈_L − q̈) + F_L (s(q̇_L) − s(q̇))`, `s` the smooth sign. A load held by table
    friction (`F_L > 0`, a ball screw with its table) makes the force drop by `F_L` during
    the crossing; a free inertial load (`F_L = 0`) makes the re-engagement impact. The
    load's viscous friction is left in the nominal `Fv`: its correction acts only inside
    the gap, near a reversal where the speed is low, so the record does not determine it
    (left free, it trades with `F_L` and drives both to unphysical signs).

    `terms` (fixed, 0 or 1 each) says which of `m_L`, `F_L` the load has: the starts
    include a load carried by friction alone (`m_L = 0`: a table whose inertia does not
    show when the gap is crossed slowly at a reversal) and a free inertial load
    (`F_L = 0`), so that a term the record does not determine is not fitted to a small
    unphysical value of the wrong sign."""

    name: ClassVar[str] = "backlash"
    order: ClassVar[int] = 0
    size: Float[Array, 2]  # m_L [kg], F_L [N]
    b: Any  # half gap [m], positive
    vs: Any  # sharpness of the load's sign law [m/s], fixed
    terms: Any  # (2,) 1 where m_L, F_L act, 0 where the load has none; fixed
    dt: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        # the load's and the motor's motion through the same differentiation (and the
        # same smoothing), so that the effect is exactly zero without a gap: the motor's
        # `d["v"]`, `d["a"]` come from another differentiator (at the record rate), and
        # the difference of two differentiators would be a free correction of q̈ that a
        # "backlash" of zero gap buys on any record (its quantisation noise)
        vl, al = _motion(_play(d["q"], self.b), self.dt)
        vm, am = _motion(d["q"], self.dt)
        dry = jnp.tanh(vl / self.vs) - jnp.tanh(vm / self.vs)
        m, fl = self.size[0] * self.terms[0], self.size[1] * self.terms[1]
        return m * (al - am) + fl * dry

    def constrained(self):
        e = eqx.tree_at(lambda e: (e.vs, e.terms), self, replace_fn=fixed)
        return eqx.tree_at(lambda e: e.b, e, replace_fn=_pos)

    def _sizes(self) -> tuple[float, float]:
        m, fl = (float(x) for x in np.asarray(self.size) * np.asarray(self.terms))
        return m, fl

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        m, fl = self._sizes()
        gap = 2 * scalar(self.b)
        res = context.resolution
        mass = float(context.nominal.get("M", np.inf))
        coulomb = float(context.nominal.get("coulomb_level", np.inf))
        coulomb_se = float(context.nominal.get("coulomb_level_se", 0.0))
        return check(
            (_ok(self.size) and np.isfinite(gap), "non-finite backlash parameters"),
            (
                gap > max(res, 0.0) and gap > 0,
                f"gap {gap:.3g} m not above the position resolution {res:.3g} m",
            ),
            (gap < 0.1 * context.span, f"gap {gap:.3g} m not small against the travel"),
            (
                fl <= 0 or gap > PRESLIDING,
                f"gap {gap:.3g} m with a load carried by friction is within the presliding "
                f"range of dry friction ({PRESLIDING:.0e} m): friction that keeps its sign "
                "for a few micrometres after a reversal (Dahl) looks the same",
            ),
            (m >= 0, f"negative load mass m_L = {m:.4g} kg"),
            (m <= mass, f"load mass m_L = {m:.4g} kg above the whole moving mass {mass:.4g} kg"),
            (fl >= 0, f"negative load friction F_L = {fl:.4g} N"),
            (
                fl <= 0 or not fl > coulomb + 3.0 * coulomb_se,
                f"load friction F_L = {fl:.4g} N behind the gap, but the axis drags a dry "
                f"friction of {coulomb:.4g} ± {coulomb_se:.2g} N while it moves: a load "
                "carried by friction is dragged whenever the gap is closed",
            ),
            (m > 0 or fl > 0, "neither a load mass nor a load friction behind the gap"),
        )

    def parameters(self):
        m, fl = self._sizes()
        return {"gap": 2 * scalar(self.b), "m_load": m, "F_load": fl}


def _highpass2(x: Array, w: Array, z: Array, dt: float) -> Array:
    """`s²/(s² + 2ζωs + ω²)` applied to `x` by the bilinear (Tustin) rule with the
    resonance pre-warped, as a biquad recursion in `lax.scan`."""
    k = w / jnp.tan(w * dt / 2)  # pre-warped bilinear constant
    a0 = k * k + 2 * z * w * k + w * w
    b = jnp.stack([k * k, -2 * k * k, k * k]) / a0
    a1 = (2 * w * w - 2 * k * k) / a0
    a2 = (k * k - 2 * z * w * k + w * w) / a0

    def step(carry, xk):
        x1, x2, y1, y2 = carry
        yk = b[0] * xk + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2
        return (xk, x1, yk, y1), yk

    zero = jnp.zeros((), x.dtype)
    init = (x[0], x[0], zero, zero)  # at rest: a constant input has no high-pass output
    return jax.lax.scan(step, init, x)[1]


class Resonance(AbstractAdditiveEffect):
    """A load `m_r` on a spring-damper behind the motor (mode `ω`, `ζ`), with its own
    viscous friction `c_r`: the load's acceleration and velocity are those of the motor
    filtered by `H(s) = (2ζωs + ω²)/(s² + 2ζωs + ω²)`, so the force changes by
    `m_r (H − 1) q̈ + c_r (H − 1) q̇`, with `H − 1 = −s²/(s² + 2ζωs + ω²)`."""

    name: ClassVar[str] = "resonance"
    order: ClassVar[int] = 0
    size: Float[Array, 2]  # resonating mass m_r [kg], its viscous friction c_r [N·s/m]
    omega: Any  # positive [rad/s]
    zeta: Any  # positive
    dt: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        hp = lambda x: _highpass2(x, self.omega, self.zeta, self.dt)
        return -self.size[0] * hp(d["a"]) - self.size[1] * hp(d["v"])

    def constrained(self):
        return eqx.tree_at(lambda e: (e.omega, e.zeta), self, replace_fn=_pos)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        m = float(np.asarray(self.size)[0])
        f = scalar(self.omega) / (2 * math.pi)
        z = scalar(self.zeta)
        lo, hi = context.band_hz
        mass = float(context.nominal.get("M", np.inf))
        return check(
            (_ok(self.size) and np.isfinite(f) and np.isfinite(z), "non-finite parameters"),
            (z < ZETA_MAX, f"damping ratio ζ = {z:.3g}: not a lightly damped mode (< {ZETA_MAX})"),
            (lo <= f <= hi, f"f = {f:.4g} Hz outside the analysed band [{lo:.3g}, {hi:.4g}] Hz"),
            (m > 0, f"non-positive resonating mass m_r = {m:.4g} kg"),
            (m <= mass, f"resonating mass m_r = {m:.4g} kg above the whole mass {mass:.4g} kg"),
            # c_r is not ruled: at low frequency its term is a mass-like correction that
            # trades with the nominal M and Fv, so its sign is not a friction's
        )

    def parameters(self):
        return {
            "f_r": scalar(self.omega) / (2 * math.pi),
            "zeta": scalar(self.zeta),
            "m_r": scalar(self.size[0]),
            "c_r": float(np.asarray(self.size)[1]),
        }


ZETA_MAX = 0.3
"""Largest damping ratio of a mode the diagnosis calls a resonance (heuristic: above
about 0.3 a "mode" has no peak left in the force spectrum and only bends the phase)."""


class TimeDelay(AbstractEffect):
    """The force acts `τ` after it is recorded: the whole prediction advanced by `τ`.

    The advance is band-limited (`fft_delay`: the phase of the spectrum turned by
    `e^{iωτ}`), an all-pass operator like a real delay. A linear interpolation between
    analysis samples would also low-pass the prediction by up to 22 % at the cut-off for a
    quarter-sample shift, and that smoothing of the quantisation noise of `q̈` is a gain a
    fitted "delay" buys on effect-free records."""

    name: ClassVar[str] = "time_delay"
    order: ClassVar[int] = 1
    tau: Float[Array, ""]  # [s]; > 0: the force acts tau after it is commanded
    dt: float = eqx.field(static=True)

    def apply(self, y, d, nominal):
        return fft_delay(y, -self.tau / self.dt)

    def constrained(self):
        return self

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        return check(*delay_rules(scalar(self.tau), context, " (the force cannot act early)"))

    def parameters(self):
        return {"tau": scalar(self.tau)}


class PositionForceEffect(AbstractAdditiveEffect):
    """`Σ c_k P_k(q̄) + Σ_h A_h·sin(2πhq/p) + B_h·cos(2πhq/p)`, `h = 1, 2`: a smooth
    force over the travel (Legendre terms: gravity, a spring) plus a ripple of pitch `p`
    and its second harmonic (cogging of a magnet pitch is a Fourier series in `q/p`,
    rarely a pure sine). `q̄` maps the calibrated travel onto `[−1, 1]`; the smooth part
    is known only there, so beyond it it keeps its value at the end of the travel (a
    held-out record that travels elsewhere, e.g. an open loop drifting, would otherwise
    see the cubic diverge); the ripple is periodic and continues as it is."""

    name: ClassVar[str] = "position_dependence"
    order: ClassVar[int] = 0
    size: Float[Array, 7]  # 3 Legendre coefficients, sine and cosine of 2 ripple harmonics
    pitch: Any  # positive [m]
    centre: float = eqx.field(static=True)
    half_range: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        q = d["q"]
        x = jnp.clip((q - self.centre) / self.half_range, -1.0, 1.0)
        ph = 2 * jnp.pi * q / self.pitch
        ripple = [jnp.sin(ph), jnp.cos(ph), jnp.sin(2 * ph), jnp.cos(2 * ph)]
        basis = jnp.concatenate([legendre(x, 3), jnp.stack(ripple, -1)], axis=-1)
        return basis @ self.size

    def constrained(self):
        return eqx.tree_at(lambda e: e.pitch, self, replace_fn=_pos)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        p = scalar(self.pitch)
        return check(
            (_ok(self.size) and np.isfinite(p), "non-finite parameters"),
            (p <= context.span, f"ripple pitch {p:.3g} m longer than the travel"),
            (
                p > 4 * max(context.resolution, 0.0),
                f"ripple pitch {p:.3g} m not resolved by the encoder",
            ),
        )

    def parameters(self):
        s = np.asarray(self.size)
        return {
            "ripple_amplitude": float(np.hypot(s[3], s[4])),
            "ripple_amplitude_2": float(np.hypot(s[5], s[6])),
            "ripple_pitch": scalar(self.pitch),
            "legendre_1": float(s[0]),
            "legendre_2": float(s[1]),
            "legendre_3": float(s[2]),
        }


class ExternalForce(AbstractEffect):
    """Unmeasured force pulses: one constant force per event found in the residual.

    The events are data (`d["events"]`, one unit-pulse column per event, located by
    `detect_events` in the residual of the model without this effect, on every
    experiment); the amplitudes are profiled out by least squares against the remaining
    force error of each experiment (variable projection), since an unmeasured disturbance
    cannot be predicted from one experiment to the next. An experiment with events also
    carries a column of ones (`events_level`): where unmeasured forces switch on and off,
    the level between the events is unknown too (a load may be on at the start of the
    record, so the median the events are found against is not zero force), and a load
    applied in one experiment does not carry over to the next. The information criterion
    counts three parameters per event (start, end, amplitude) and one per level.
    """

    name: ClassVar[str] = "external_force"
    order: ClassVar[int] = 2

    def apply(self, y, d, nominal):
        ev = d["events"]
        r = d["y"] - y
        gram = ev.T @ ev
        eps = 1e-9 * (jnp.trace(gram) / ev.shape[-1] + 1.0)
        amp = jnp.linalg.solve(gram + eps * jnp.eye(ev.shape[-1], dtype=ev.dtype), ev.T @ r)
        return y + ev @ amp

    def constrained(self):
        return self

    def extra_dof(self, arrays: Sequence[Mapping[str, Array]]) -> int:
        dof = 0
        for d in arrays:
            ev = np.asarray(d["events"])
            used = np.any(ev != 0, axis=0)
            level = np.all(ev == 1, axis=0)
            dof += 3 * int(np.sum(used & ~level)) + int(np.sum(level))
        return dof

    def admissible(self, context):
        # the events are found in the data; with none, the effect is the nominal model
        return True, None

    def parameters(self):
        return {}


SATURATION_MIN_SHARE = 0.01
"""Smallest share of the calibration samples whose recorded command lies beyond a
`saturation` limit (heuristic: a limit reached on fewer samples is a handful of force
peaks, which any misfit at the largest accelerations can imitate; an amplifier that
limits the axis does so at every hard acceleration of the record)."""

SATURATION_MAX_SHARE = 0.25
"""Largest share of the calibration samples beyond a `saturation` limit (heuristic: an
amplifier at its limit for more than a quarter of the record no longer controls the
axis; and a limit low in the bulk of the command explains the force by the command
itself, `u − sat(u)` being most of `u`: a trivial fit that any record admits). The limit
is calibrated inside `(|u| quantile 1 − SATURATION_MAX_SHARE, 1.05·max |u|)`."""

SATURATION_SMOOTHNESS = 0.01
"""Corner rounding of the `saturation` clip as a share of the largest recorded command
(the smooth clip of `jaxvs.models.ActuatorSaturation`: within 0.7 % of the peak of the
hard clip at the corners, exact on the plateaus)."""


class Saturation(AbstractEffect):
    """The amplifier limits the force: the recorded force `u` is the command, the force
    applied to the axis is `sat(u)`, the library's `jaxvs.models.ActuatorSaturation` at
    `±F_max` (Pislaru 2001, §4.3; a drive's current limit). The motion shows the applied
    force, so the prediction of the recorded command is the predicted applied force plus
    the part of the command the amplifier does not apply, `u − sat(u)`: the residual is
    then `sat(u) − ŷ`. Identity once `F_max` is above the largest command.

    Admissible only when the limit is below the largest recorded command and the command
    lies beyond it on at least `SATURATION_MIN_SHARE` of the calibration samples (the
    quantiles of `|u|` the limit is compared against are kept with the effect)."""

    name: ClassVar[str] = "saturation"
    order: ClassVar[int] = 1
    limit: Any  # F_max [N], positive, calibrated
    eps: float = eqx.field(static=True)  # corner rounding [N]
    quantiles: tuple = eqx.field(static=True)  # (shares, |u| levels) of the calibration

    def apply(self, y, d, nominal):
        law = models.ActuatorSaturation(self.limit, self.eps)
        return y + law.excess(d["y"])

    def bounds(self) -> tuple[float, float]:
        """The interval the limit is calibrated in (`SATURATION_MAX_SHARE`)."""
        shares, levels = (np.asarray(x) for x in self.quantiles)
        lo = float(np.interp(1.0 - SATURATION_MAX_SHARE, shares, levels))
        return lo, 1.05 * float(levels[-1])

    def constrained(self):
        lo, hi = self.bounds()
        pad = 1e-6 * (hi - lo)
        return eqx.tree_at(
            lambda e: e.limit,
            self,
            replace_fn=lambda x: bounded(jnp.clip(x, lo + pad, hi - pad), lo, hi),
        )

    def extra_dof(self, arrays):
        return 0

    def share_beyond(self, limit: float) -> float:
        """Share of the calibration samples whose |command| exceeds `limit`."""
        shares, levels = (np.asarray(x) for x in self.quantiles)
        if limit >= levels[-1]:
            return 0.0
        return float(1.0 - np.interp(limit, levels, shares))

    def admissible(self, context):
        f = scalar(self.limit)
        umax = float(self.quantiles[1][-1])
        share = self.share_beyond(f) if np.isfinite(f) else 0.0
        return check(
            (np.isfinite(f) and f > 0, f"non-finite or non-positive limit F_max = {f:.4g} N"),
            (
                f < umax,
                f"F_max = {f:.4g} N not below the largest recorded force {umax:.4g} N: the "
                "limit is never reached",
            ),
            (
                share >= SATURATION_MIN_SHARE,
                f"the recorded force exceeds F_max = {f:.4g} N on {100 * share:.2g} % of the "
                f"samples only (at least {100 * SATURATION_MIN_SHARE:g} %: a limit the record "
                "reaches)",
            ),
            (
                share <= SATURATION_MAX_SHARE,
                f"the recorded force exceeds F_max = {f:.4g} N on {100 * share:.2g} % of the "
                f"samples (at most {100 * SATURATION_MAX_SHARE:g} %: an amplifier limited "
                "most of the time does not control the axis)",
            ),
        )

    def parameters(self):
        f = scalar(self.limit)
        return {"F_max": f, "share_at_limit": self.share_beyond(f)}


# ------------------------------------------------------------------------------ templates


def _vmax(ctx: Context) -> float:
    return max(float(np.max(np.abs(e.arrays["v"]))) for e in ctx.experiments)


def _vs_default(ctx: Context) -> float:
    return float(ctx.options.get("friction_sharpness", 0.005)) * _vmax(ctx)


def _t_coulomb(ctx: Context) -> list[AbstractEffect]:
    vm = _vmax(ctx)
    return [CoulombEffect(jnp.zeros(1), jnp.asarray(f * vm)) for f in (0.002, 0.01)]


def _t_asym(ctx: Context) -> list[AbstractEffect]:
    base = _existing(ctx, "coulomb_friction")
    vs = base.vs if base is not None else jnp.asarray(_vs_default(ctx))
    fc = base.size[0] if base is not None else 0.0
    return [AsymmetricFrictionEffect(jnp.array([fc, fc, 0.0]), vs)]


def _t_stribeck(ctx: Context) -> list[AbstractEffect]:
    base = _existing(ctx, "coulomb_friction")
    vs = base.vs if base is not None else jnp.asarray(_vs_default(ctx))
    fc = base.size[0] if base is not None else 0.0
    vm = _vmax(ctx)
    return [StribeckEffect(jnp.array([fc, fc]), jnp.asarray(f * vm), vs) for f in (0.02, 0.1)]


def _t_backlash(ctx: Context) -> list[AbstractEffect]:
    dt = ctx.experiments[0].dt
    vs = jnp.asarray(_vs_default(ctx))
    # a load with inertia and friction, carried by friction alone, or inertial alone
    terms = [(1.0, 1.0), (0.0, 1.0), (1.0, 0.0)]
    return [
        Backlash(jnp.zeros(2), jnp.asarray(b), vs, jnp.asarray(t), dt)
        for b in (2e-5, 1.5e-4)
        for t in terms
    ]


def _t_resonance(ctx: Context) -> list[AbstractEffect]:
    exp0 = ctx.experiments[0]
    dt = exp0.dt
    fs = 1.0 / dt
    e = np.concatenate([np.asarray(r) for r in ctx.residuals])
    f, p = ss.welch(e - e.mean(), fs=fs, nperseg=min(e.size, 2048))
    cutoff = drive_band(ctx.options, exp0.record_dt).cutoff_hz
    band = (f > 2.0) & (f < 0.8 * cutoff)
    peaks, props = ss.find_peaks(np.where(band, p, 0.0), prominence=0)
    top = peaks[np.argsort(props["prominences"])[::-1][:2]] if peaks.size else []
    freqs = [float(f[i]) for i in top] or [fs / 10]
    out = []
    for fr in freqs:
        for z in (0.05,):
            out.append(Resonance(jnp.zeros(2), jnp.asarray(2 * math.pi * fr), jnp.asarray(z), dt))
    return out


def _t_delay(ctx: Context) -> list[AbstractEffect]:
    """Causal starts only: one and a half and four samples of the record, and 1 and 3 ms
    when they are longer than a sample (a delay shorter than a sample is inadmissible)."""
    dt = ctx.experiments[0].dt
    rec = ctx.experiments[0].record_dt or dt
    taus = sorted({1.5 * rec, 4.0 * rec} | {t for t in (1.0e-3, 3.0e-3) if t > 1.5 * rec})
    return [TimeDelay(jnp.asarray(t), dt) for t in taus[:3]]


def _t_position(ctx: Context) -> list[AbstractEffect]:
    """Ripple pitches from the spectrum of the residual over position: the residual is
    averaged in 512 position bins and its strongest spatial frequencies seed the pitch."""
    q = np.concatenate([e.arrays["q"] for e in ctx.experiments])
    r = np.concatenate([np.asarray(x) for x in ctx.residuals])
    lo, hi = float(q.min()), float(q.max())
    centre, half = (lo + hi) / 2, max((hi - lo) / 2, 1e-12)
    span = max(hi - lo, 1e-12)
    nb = 512
    idx = np.clip(((q - lo) / span * nb).astype(int), 0, nb - 1)
    cnt = np.bincount(idx, minlength=nb)
    mean = np.bincount(idx, weights=r, minlength=nb) / np.maximum(cnt, 1)
    ok = cnt > 0
    grid = np.arange(nb)
    mean = np.interp(grid, grid[ok], mean[ok]) if ok.any() else mean
    # remove the smooth part the Legendre terms take, then look for the ripple
    x = (grid + 0.5) / nb * 2 - 1
    mean = mean - np.polyval(np.polyfit(x, mean, 3), x)
    spec = np.abs(np.fft.rfft(mean * np.hanning(nb)))
    spec[:3] = 0.0
    top = np.argsort(spec)[::-1][:2]
    pitches = [span / k for k in top if k > 0] + [span / 1.5]
    return [PositionForceEffect(jnp.zeros(7), jnp.asarray(p), centre, half) for p in pitches]


def _t_saturation(ctx: Context) -> list[AbstractEffect]:
    """Limits at the 90 % and 98 % quantiles of the recorded |force|: the calibration
    moves `F_max` down where the command is beyond the applied force, up otherwise."""
    y = np.abs(np.concatenate([e.y for e in ctx.experiments]))
    shares = np.linspace(0.5, 1.0, 201)
    levels = np.quantile(y, shares)
    table = (tuple(float(x) for x in shares), tuple(float(x) for x in levels))
    eps = SATURATION_SMOOTHNESS * float(levels[-1])
    return [Saturation(jnp.asarray(float(np.quantile(y, p))), eps, table) for p in (0.9, 0.98)]


def _t_external(ctx: Context) -> list[AbstractEffect]:
    return [ExternalForce()]


def _existing(ctx: Context, name: str):
    for e in ctx.model.effects:
        if e.name == name:
            return e
    return None


def _needs_motion_both_ways(experiments: Sequence[Experiment]) -> str | None:
    v = np.concatenate([e.arrays["v"] for e in experiments])
    vm = float(np.max(np.abs(v)))
    if vm == 0 or np.mean(v > 0.05 * vm) < 0.02 or np.mean(v < -0.05 * vm) < 0.02:
        return "needs motion in both directions"
    return None


def _needs_travel(experiments: Sequence[Experiment]) -> str | None:
    q = np.concatenate([e.arrays["q"] for e in experiments])
    if float(np.ptp(q)) <= 0:
        return "needs travel along the axis"
    return None


# ------------------------------------------------------------------------------ family


MAX_EVENTS = 16


def detect_events(
    residual: np.ndarray,
    dt: float,
    *,
    window_s: float = 0.05,
    threshold: float = 5.0,
    moving: np.ndarray | None = None,
) -> np.ndarray:
    """Columns of unit pulses where the smoothed residual stays far from zero.

    The residual is smoothed by a moving average of `window_s`; samples beyond `threshold`
    robust standard deviations (MAD of the smoothed residual) form events, merged when
    closer than one window and dropped when shorter than one window. With `moving` (a
    boolean mask of the samples where the axis moves), an event must also act on the
    moving axis for at least one window: a force that appears while the axis stands still
    is balanced by static friction, which can take any value up to the breakaway level,
    so it is not observable as an unmeasured force (the held force of a sticking axis
    would otherwise be taken for one). Returns `(n, MAX_EVENTS)` with at most
    `MAX_EVENTS − 1` events (the last column is left for `ExternalForce`'s level), unused
    columns zero.
    """
    e = np.asarray(residual, float)
    w = max(1, int(round(window_s / dt)))
    sm = np.convolve(e, np.ones(w) / w, mode="same")
    med = np.median(sm)
    sigma = 1.4826 * np.median(np.abs(sm - med)) + 1e-300
    on = np.abs(sm - med) > threshold * sigma
    # merge gaps shorter than a window
    idx = np.flatnonzero(on)
    cols = []
    if idx.size:
        starts = [idx[0]]
        ends = []
        for a, b in zip(idx[:-1], idx[1:]):
            if b - a > w:
                ends.append(a)
                starts.append(b)
        ends.append(idx[-1])
        for s0, s1 in zip(starts, ends):
            if s1 - s0 + 1 < w:
                continue
            for p0, p1 in _split_levels(e, s0, s1 + 1, w, threshold * sigma):
                if moving is not None and int(np.sum(moving[p0:p1])) < w:
                    continue
                col = np.zeros(e.size)
                col[p0:p1] = 1.0
                cols.append(col)
    out = np.zeros((e.size, MAX_EVENTS))
    for k, col in enumerate(cols[: MAX_EVENTS - 1]):
        out[:, k] = col
    return out


def follows_command(events: np.ndarray, residual: np.ndarray, command: np.ndarray) -> bool:
    """Whether the force of the events follows the recorded command rather than acting on
    its own.

    An unmeasured external force does not know the command: within an event it is a
    level (`ExternalForce`'s model). A force that scales with the command -- a motor
    force constant that drifts, a mass that changes -- has the command's shape within
    each event. The two one-parameter-per-event descriptions of the residual (about its
    median, the level the events are found against) are compared on all the events of
    the record together: one level per event, or one multiple of the command per event;
    when the command's multiples leave the smaller sum of squares, the events are not
    external forces."""
    ev = np.asarray(events) != 0
    used = [k for k in range(ev.shape[1]) if ev[:, k].any()]
    if not used:
        return False
    e = np.asarray(residual, float)
    e = e - np.median(e)
    u = np.asarray(command, float)
    ssr_level = ssr_gain = 0.0
    for k in used:
        m = ev[:, k]
        ek, uk = e[m], u[m]
        ssr_level += float(np.sum((ek - ek.mean()) ** 2))
        uu = float(uk @ uk)
        ssr_gain += float(np.sum((ek - (ek @ uk) / uu * uk) ** 2)) if uu > 0 else float(ek @ ek)
    return ssr_gain < ssr_level


def _split_levels(e: np.ndarray, start: int, stop: int, w: int, step: float):
    """Pieces of constant level of the event `e[start:stop]`: unmeasured forces that
    overlap or follow each other without a pause (a pulse of one sign right after one of
    the other, a second load added to the first) form one run beyond the threshold but
    several levels. The run is cut by binary segmentation (Scott & Knott 1974): at the
    sample where the likelihood ratio of a mean shift, `|mean_left − mean_right|·
    sqrt(n_l n_r / n)`, is largest, when the two means differ by more than `step` (the
    threshold an event itself must pass) and both pieces last at least `w` samples.
    The cut is sought in the core of the run, half a window inside its ends: the run was
    found on the residual averaged over `w` samples, so its ends may reach up to half a
    window beyond the force, and that margin is not a level of its own.

    **Returns:** a list of `(start, stop)` index pairs, in order."""
    h = w // 2
    cuts = [start + h + k for k in _level_cuts(e[start + h : stop - h], w, step)]
    bounds = [start, *cuts, stop]
    return list(zip(bounds[:-1], bounds[1:]))


def _level_cuts(x: np.ndarray, w: int, step: float) -> list[int]:
    """Indices where `x` changes level by more than `step` (binary segmentation, pieces
    of at least `w` samples), in order."""
    n = x.size
    if n < 2 * w:
        return []
    c = np.cumsum(x)
    k = np.arange(w, n - w + 1)
    left = c[k - 1] / k
    right = (c[-1] - c[k - 1]) / (n - k)
    diff = np.abs(left - right)
    best = int(np.argmax(diff * np.sqrt(k * (n - k) / n)))
    if not diff[best] > step:
        return []
    cut = int(k[best])
    return [*_level_cuts(x[:cut], w, step), cut, *(cut + j for j in _level_cuts(x[cut:], w, step))]


MASS_RELATIVE_SE = 0.25
"""Largest relative standard error of a calibrated mass that counts as excited (four
standard errors from zero; Fisher information with the white noise level of the
residual). Below it the inertial force the record shows is within a few noise standard
deviations over the whole record: fixing the mass loses nothing the record can show."""

JACOBIAN_RTOL = 1e-3
"""Relative singular value of the column-scaled Jacobian of the nominal parameters below
which a drive record is refused (heuristic: at 1e-3 a parameter combination is a
thousand times less determined than the best one; the search's recalibrations trade it
with every effect)."""


def coulomb_level(experiments: Sequence[Experiment]) -> dict[str, float]:
    """The dry friction level the records show while the axis moves: the coefficient of
    `sign(q̇)` in a least-squares fit of the force by `q̈`, `q̇`, `sign(q̇)` and a constant
    on the samples above `REVERSAL_SPEED` of the largest speed (away from the
    reversals, where a play is crossed and friction laws differ), with its standard
    error (white residual). `{"coulomb_level": Fc, "coulomb_level_se": se}`; `nan` when
    the records do not move both ways."""
    y = np.concatenate([e.y for e in experiments])
    a = np.concatenate([e.arrays["a"] for e in experiments])
    v = np.concatenate([e.arrays["v"] for e in experiments])
    fast = np.abs(v) > REVERSAL_SPEED * float(np.max(np.abs(v)))
    nan = {"coulomb_level": float("nan"), "coulomb_level_se": float("nan")}
    if np.sum(fast & (v > 0)) < 10 or np.sum(fast & (v < 0)) < 10:
        return nan
    phi = np.stack([a, v, np.sign(v), np.ones_like(v)], -1)[fast]
    th, *_ = np.linalg.lstsq(phi, y[fast], rcond=None)
    res = y[fast] - phi @ th
    dof = max(res.size - phi.shape[1], 1)
    try:
        cov = np.linalg.inv(phi.T @ phi) * float(res @ res) / dof
    except np.linalg.LinAlgError:
        return nan
    return {"coulomb_level": float(th[2]), "coulomb_level_se": float(np.sqrt(cov[2, 2]))}


def mass_not_excited(experiments: Sequence[Experiment]) -> str | None:
    """`None` when the records determine a positive mass, else why not: no acceleration,
    a least-squares mass that is not positive, or one not determined to better than
    `MASS_RELATIVE_SE` (Fisher information with the record's noise, the white part of the
    residual by robust successive differences: the slow part of the residual is the
    unmodelled effect the search is there to explain, not a lack of excitation)."""
    a = np.concatenate([e.arrays["a"] for e in experiments])
    v = np.concatenate([e.arrays["v"] for e in experiments])
    y = np.concatenate([e.y for e in experiments])
    if not np.any(a):
        return "no acceleration in the record"
    phi = np.stack([a, v, np.ones_like(a)], -1)
    th, *_ = np.linalg.lstsq(phi, y, rcond=None)
    mass = float(th[0])
    if not mass > 0:
        return f"the least-squares mass is not positive, M = {mass:.4g} kg"
    sigma2 = difference_noise_sigma(y - phi @ th) ** 2
    se_m = float(np.sqrt(max((sigma2 * np.linalg.pinv(phi.T @ phi))[0, 0], 0.0)))
    if se_m > MASS_RELATIVE_SE * mass:
        return (
            f"M = {mass:.4g} ± {se_m:.2g} kg, one standard error with the record's noise, is "
            f"not determined to {100 * MASS_RELATIVE_SE:g} %"
        )
    return None


def jacobian_refusal(experiments: Sequence[Experiment], nominal: RigidNominal) -> str | None:
    """`None` when the calibrated parameters of the rigid axis are identifiable, else the
    refusal naming the parameter and what to record: the Jacobian of the prediction in
    the calibrated parameters (`q̈`, `q̇`, `1` for `M`, `Fv`, `offset`; fixed ones left
    out), column-scaled, must have every relative singular value above `JACOBIAN_RTOL`."""
    cols = {
        "M": np.concatenate([e.arrays["a"] for e in experiments]),
        "Fv": np.concatenate([e.arrays["v"] for e in experiments]),
        "offset": np.ones(sum(e.n for e in experiments)),
    }
    free = [n for n in ("M", "Fv") if not isinstance(getattr(nominal, n), float)] + ["offset"]
    advice = DriveFamily.record_advice
    phi = np.stack([cols[n] for n in free], -1)
    norms = np.linalg.norm(phi, axis=0)
    for name, norm in zip(free, norms):
        if norm == 0:
            return (
                f"{name} is not identifiable: its regressor is zero in the record; {advice[name]}"
            )
    _, sv, vt = np.linalg.svd(phi / norms, full_matrices=False)
    rel = sv[-1] / sv[0]
    if rel >= JACOBIAN_RTOL:
        return None
    w = vt[-1] / np.max(np.abs(vt[-1]))
    involved = [n for n, x in zip(free, w) if abs(x) > 0.05]
    worst = free[int(np.argmax(np.abs(vt[-1])))]
    combo = " + ".join(f"{x:+.2f}·{n}" for n, x in zip(free, w) if abs(x) > 0.05)
    return (
        f"{' and '.join(involved)} cannot be told apart in the record (the combination "
        f"{combo} has relative singular value {rel:.1e} < {JACOBIAN_RTOL:g}); "
        f"{worst} is the least determined: {advice[worst]}"
    )


class DriveFamily(AbstractFamily):
    """Rigid prismatic axis driven by a force `u` with measured position `q`.

    **Options:** `cutoff_hz` (zero-phase low-pass of position and force, default
    `min(fs/8, 100)` Hz), `filter_order` (4), `decimation` (default so that the analysis
    rate is about 4× the cut-off), `friction_sharpness` (`v_s` of the smooth sign as a
    fraction of the largest speed, 0.005), `zoh_force` (default `True`: the recorded force
    is zero-order held by the drive, i.e. acts on average half a sample after its time
    stamp; the half-sample shift is compensated so that it is not reported as a delay),
    `mass` (the moving mass [kg] used when the record does not excite the inertia;
    default 0).
    """

    name = "drive"
    required = ("q", "u")
    optional = ("r",)
    option_keys = (
        "cutoff_hz",
        "filter_order",
        "decimation",
        "friction_sharpness",
        "zoh_force",
        "controller_taps",
        "mass",
    )
    target_label = "force u [N]"

    _MODEL_SIGNALS = ("q", "u", "r", "vir", "q_ref", "qg")

    def prepare(self, record: Record, name: str) -> Experiment:
        fs = 1.0 / record.dt
        # the analysis band (zero-phase low-pass, derivatives, the held force's half-sample
        # shift, decimation): derived from the record, never written back into the options
        band = drive_band(self.options, record.dt)
        q = np.asarray(record["q"], float)
        u = band.held(np.asarray(record["u"], float))
        n_min = band.min_samples
        if q.size < n_min:
            raise ValueError(
                f"diagnose(drive): experiment {name!r} has {q.size} samples; at least {n_min} "
                "are needed for filtering and differentiation. Give longer records."
            )
        sig = band.apply(q, np.asarray(record["u"], float))
        qf, uf, v, a, sl = sig.q, sig.u, sig.v, sig.a, sig.window
        t = np.asarray(record.t)[sl]
        arrays = {"q": qf[sl], "v": v[sl], "a": a[sl], "y": uf[sl]}
        if float(np.ptp(q)) == 0.0:
            raise NotIdentifiable(
                f"experiment {name!r} has no motion (q is constant): the inertia and friction "
                "are not identifiable; record experiments with motion in both directions"
            )
        # noise: the white part of the force above the cut-off, carried into the band
        s0, _ = white_noise_floor(u - uf, fs)
        noise_var = s0 * band.enbw
        vmax = float(np.max(np.abs(arrays["v"])))
        vv = arrays["v"]
        masks = _drive_masks(vv, vmax, 1.0 / fs * band.decimation)
        for sig in record.names:
            if sig in self._MODEL_SIGNALS:
                continue
            x = np.asarray(record[sig])[sl]
            levels = np.unique(np.round(x, 9))
            if 2 <= levels.size <= 3 and np.ptp(x) > 0:
                masks[f"{sig} on"] = x > (levels.min() + levels.max()) / 2
        ops = {"velocity [m/s]": vv, "speed [m/s]": np.abs(vv), "position [m]": arrays["q"]}
        arrays["events"] = np.zeros((t.size, MAX_EVENTS))
        return Experiment(
            name=name,
            t=t,
            arrays=arrays,
            ops=ops,
            masks=masks,
            noise_var=float(noise_var),
            signals=frozenset(record.names),
            source=record,
            record_dt=float(record.dt),
            resolution=quantisation_step(q),
        )

    def identifiability(self, experiments: Sequence[Experiment], model: GapModel) -> str | None:
        """The rigid axis is identified when the motion goes both ways (one reversal
        suffices: motion in both directions separates friction from the offset) and the
        Jacobian of the calibrated parameters (`(q̈, q̇, 1)`, without `q̈` when the mass is
        fixed), column-scaled, has no relative singular value below `JACOBIAN_RTOL`. A
        mass the record does not excite, or a negative viscous friction, is not a
        refusal: `nominal` fixes them (with a warning) before the calibration."""
        v = np.concatenate([e.arrays["v"] for e in experiments])
        vm = float(np.max(np.abs(v)))
        if vm == 0 or np.mean(v > 0.05 * vm) < 0.02 or np.mean(v < -0.05 * vm) < 0.02:
            return (
                "the axis moves in one direction only: viscous friction and the offset (and "
                "every friction effect) need motion both ways; record a back-and-forth motion"
            )
        return jacobian_refusal(experiments, unwrap(model.nominal))

    singular_rtol: ClassVar[float] = 1e-3
    """The relative singular value of the column-scaled Jacobian below which `jaxvs check`
    and the diagnosis refuse a drive record (`JACOBIAN_RTOL`)."""

    record_advice: ClassVar[dict[str, str]] = {
        "M": "record moves with clear, varied accelerations, or give the moving mass with "
        "the mass option",
        "Fv": "record moves at several different speeds",
        "offset": "record motion in both directions at several speeds",
    }
    """What to record so that a parameter becomes identifiable (named in refusals)."""

    def admissibility_context(
        self, experiments: Sequence[Experiment], model: GapModel
    ) -> AdmissibilityContext:
        q = np.concatenate([e.arrays["q"] for e in experiments])
        dur = min(e.n * e.dt for e in experiments)
        return AdmissibilityContext(
            record_dt=max(e.record_dt or e.dt for e in experiments),
            analysis_dt=experiments[0].dt,
            band_hz=(2.0 / dur, drive_band(self.options, experiments[0].record_dt).cutoff_hz),
            resolution=max(e.resolution for e in experiments),
            duration=dur,
            span=float(np.ptp(q)),
            nominal={**self.nominal_parameters(model, experiments), **coulomb_level(experiments)},
        )

    def null_experiments(
        self,
        model: GapModel,
        experiments: Sequence[Experiment],
        rng: np.random.Generator,
        count: int,
    ) -> list[list[Experiment]]:
        """Effect-free records of the calibrated rigid axis through each record's set-up.

        With a reference `r` whose controller the record identifies (a linear controller
        from `r` and the measured `q` to `u`, fitted by least squares, explaining at least
        95 % of the force variance): the closed loop is simulated at the record's sampling
        with that controller, the rigid axis (exact zero-order-hold discretisation), the
        record's quantisation step (a random encoder zero per draw) and the recorded
        force's measurement noise (`force_noise`: what the controller fit leaves of the
        force, with its own spectrum when it is Gaussian noise, else its white part).
        Otherwise (open loop, or no identifiable
        controller) the record's own motion, low-pass filtered, is replayed: the force is
        the nominal model's, plus white noise of the record's level, the position
        re-quantised. Each simulated record then goes through the same preprocessing."""
        nom = unwrap(model.nominal)
        mass, fv, off = float(nom.M), float(nom.Fv), float(nom.offset)
        out: list[list[Experiment]] = [[] for _ in range(count)]
        for exp in experiments:
            rec = exp.source
            if rec is None:
                raise ValueError(
                    "diagnose(drive): the null needs the original records of the experiments."
                )
            sims = _null_records(rec, mass, fv, off, rng, count, self.options)
            for k, sim in enumerate(sims):
                out[k].append(self.prepare(sim, exp.name))
        return out

    def settings(self, experiments: Sequence[Experiment]) -> dict[str, Any]:
        """The options with the analysis band derived from the records' sampling rate."""
        band = drive_band(self.options, experiments[0].record_dt)
        return {
            **self.options,
            "cutoff_hz": band.cutoff_hz,
            "filter_order": band.order,
            "decimation": band.decimation,
            "zoh_force": band.hold,
        }

    def describe_nominal(self) -> str:
        return "rigid axis M q̈ + Fv q̇ + offset = u (inverse dynamics, force predicted from motion)"

    def nominal(self, experiments: Sequence[Experiment]) -> RigidNominal:
        return self._nominal_start(experiments)[0]

    def nominal_warnings(self, experiments: Sequence[Experiment]) -> tuple[str, ...]:
        return self._nominal_start(experiments)[1]

    def _nominal_start(self, experiments: Sequence[Experiment]) -> tuple[RigidNominal, tuple]:
        """The rigid axis by linear least squares. A mass the record does not excite
        (`mass_not_excited`) is fixed at the `mass` option (default 0 kg) and a negative
        viscous friction at zero, each with a warning (`nominal_warnings`, reported by
        `jaxvs check` and in the diagnosis report): a quasi-static friction rig does not
        excite its inertia by design, and its friction and play are still diagnosed."""
        y = np.concatenate([e.y for e in experiments])
        a = np.concatenate([e.arrays["a"] for e in experiments])
        v = np.concatenate([e.arrays["v"] for e in experiments])
        one = np.ones_like(v)
        warnings: list[str] = []
        why = mass_not_excited(experiments)
        if why is None:
            th, *_ = np.linalg.lstsq(np.stack([a, v, one], -1), y, rcond=None)
            mass: Any = jnp.asarray(th[0])
            fv, off = th[1], th[2]
        else:
            mass = self.options.get("mass") or 0.0
            if isinstance(mass, bool) or not isinstance(mass, int | float) or not mass >= 0:
                raise ValueError(
                    f"diagnose(drive): the mass option must be a moving mass >= 0 kg; got {mass!r}."
                )
            mass = float(mass)
            (fv, off), *_ = np.linalg.lstsq(np.stack([v, one], -1), y - mass * a, rcond=None)
            source = "the mass option" if self.options.get("mass") else "zero"
            warnings.append(
                f"the inertia is not excited ({why}): the mass is fixed at {mass:.4g} kg "
                f"({source}) and the diagnosis goes on with friction and play; give the "
                "moving mass with the mass option, or record moves with clear accelerations"
            )
        if fv < 0:
            # a force falling with speed (Stribeck friction) or traded with the inertia:
            # the viscous friction is bounded at zero, the falling part left to the search
            ph = np.stack([a, one], -1) if not isinstance(mass, float) else one[:, None]
            rhs = y if not isinstance(mass, float) else y - mass * a
            th, *_ = np.linalg.lstsq(ph, rhs, rcond=None)
            if isinstance(mass, float):
                off = th[0]
            else:
                mass, off = jnp.asarray(th[0]), th[1]
            warnings.append(
                f"the least-squares viscous friction is negative (Fv = {fv:.4g} N·s/m): it is "
                "fixed at 0 N·s/m (a force that falls with speed is left to the friction "
                "effects)"
            )
            return RigidNominal(mass, 0.0, jnp.asarray(off)), tuple(warnings)
        return RigidNominal(mass, jnp.asarray(fv), jnp.asarray(off)), tuple(warnings)

    def library(self) -> list[EffectSpec]:
        return [
            EffectSpec(
                "coulomb_friction",
                ("q", "u"),
                _t_coulomb,
                testable=_needs_motion_both_ways,
                signature="sign(velocity)",
                description="dry friction of constant level opposing the motion",
            ),
            EffectSpec(
                "asymmetric_friction",
                ("q", "u"),
                _t_asym,
                extends="coulomb_friction",
                testable=_needs_motion_both_ways,
                signature="|velocity|",
                description="friction levels that differ between the two directions",
            ),
            EffectSpec(
                "stribeck_friction",
                ("q", "u"),
                _t_stribeck,
                extends="coulomb_friction",
                testable=_needs_motion_both_ways,
                signature="sign(v)·exp(-(v/v_st)²)",
                description="friction peak at low speed (Stribeck curve)",
            ),
            EffectSpec(
                "backlash",
                ("q", "u"),
                _t_backlash,
                testable=_needs_motion_both_ways,
                signature="acceleration near reversals",
                description="play between motor and load",
            ),
            EffectSpec(
                "resonance",
                ("q", "u"),
                _t_resonance,
                signature="residual spectrum peak",
                description="a compliant load: a mode between motor and load",
            ),
            EffectSpec(
                "time_delay",
                ("q", "u"),
                _t_delay,
                signature="cross-correlation lag",
                description="the force acts later than it is recorded",
            ),
            EffectSpec(
                "external_force",
                ("q", "u"),
                _t_external,
                refresh=_refresh_events,
                signature="residual bursts",
                description="unmeasured force pulses on the axis",
            ),
            EffectSpec(
                "position_dependence",
                ("q", "u"),
                _t_position,
                testable=_needs_travel,
                signature="position",
                description="force depending on the position (cogging, gravity, spring)",
            ),
            EffectSpec(
                "saturation",
                ("q", "u"),
                _t_saturation,
                signature="|recorded force|",
                description="the amplifier limits the applied force to ±F_max",
            ),
        ]


STANDSTILL = 0.02
"""Share of the largest speed below which an axis counts as standing still (the
standstill cell of the gap map, and where external-force events are not sought)."""

REVERSAL_SPEED = 0.1
"""Share of the largest speed below which a passage between motions of opposite sign is
a velocity reversal (the reversal cell of the gap map; the dry friction level is read
above it, see `coulomb_level`)."""


def _refresh_events(exp: Experiment, residual: np.ndarray) -> Experiment:
    """Attach the event columns of the external-force candidate to an experiment: the
    pulses `detect_events` finds while the axis moves (the same standstill threshold as
    the operating-point cells, 2 % of the largest speed) and, when there is at least one,
    a last column of ones for the unknown level between them (`ExternalForce`). Events
    whose force follows the recorded command (`follows_command`) are no external force:
    the record then has none."""
    v = np.asarray(exp.arrays["v"])
    moving = np.abs(v) > STANDSTILL * float(np.max(np.abs(v)))
    ev = detect_events(residual, exp.dt, moving=moving)
    if follows_command(ev, residual, exp.y):
        ev[:] = 0.0
    if np.any(ev != 0):
        ev[:, -1] = 1.0
    return dataclasses.replace(exp, arrays={**exp.arrays, "events": ev})


def _drive_masks(v: np.ndarray, vmax: float, dt: float) -> dict[str, np.ndarray]:
    """Operating-point cells of an axis: velocity reversals (the low-speed passages,
    |v| < 10 % of the largest speed, between motions of opposite sign), standstill
    (|v| < 2 %, not a reversal), and the two directions."""
    thr = STANDSTILL * vmax
    low = np.abs(v) < REVERSAL_SPEED * vmax
    sign = np.sign(v)
    # runs of constant `low`; a low run is a reversal when the motion before and after it
    # has opposite signs (runs touching the record's ends are not)
    edges = np.flatnonzero(np.diff(low.astype(int))) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [v.size]])
    inner = (starts > 0) & (ends < v.size)
    before = sign[np.maximum(starts - 1, 0)]
    after = sign[np.minimum(ends, v.size - 1)]
    rev = np.repeat(low[starts] & inner & (before * after < 0), ends - starts)
    return {
        "velocity reversals": rev,
        "standstill": (np.abs(v) < thr) & ~rev,
        "positive velocity": v > thr,
        "negative velocity": v < -thr,
    }


# ------------------------------------------------------------------------------ the null


def _quantiser(step: float, sigma: float, rng: np.random.Generator, count: int):
    """`x -> step·round((x + φ)/step) − φ + σ·n` per draw, `φ ~ U(0, step)` a random
    encoder zero (so every draw has its own quantisation error), or white noise `σ`."""
    phase = rng.uniform(0.0, step, size=(count, 1)) if step > 0 else np.zeros((count, 1))

    def quantise(x: np.ndarray) -> np.ndarray:
        if step > 0:
            return step * np.round((x + phase) / step) - phase
        return x + sigma * rng.standard_normal(x.shape)

    return quantise


def identify_controller(
    q: np.ndarray, u: np.ndarray, r: np.ndarray, dt: float, taps: int
) -> tuple[np.ndarray, float, float]:
    """A linear digital controller `u_k = Σ_i a_i r_{k−i} + Σ_i b_i q_{k−i} + c·I_k + d`
    (`taps` past samples of each, `I` the integral of `r − q`) fitted to a closed-loop
    record by least squares: it reproduces P, PI, cascade and filtered-velocity loops
    without knowing their structure.

    **Returns:** `(coefficients, r2, sigma)`: coefficients in the order
    `a_0..a_{L−1}, b_0..b_{L−1}, c, d`, the share of the force variance explained, and
    the standard deviation of the residual's white part [N] (the force measurement
    noise when the controller is linear and the noise white)."""
    coef, r2, res = _controller_fit(q, u, r, dt, taps)
    # the white part of the residual (robust successive differences): a disturbance the
    # record carries besides the controller output (force pulses injected into the drive)
    # is not measurement noise and does not belong in the null
    return coef, r2, difference_noise_sigma(res)


def _controller_fit(
    q: np.ndarray, u: np.ndarray, r: np.ndarray, dt: float, taps: int
) -> tuple[np.ndarray, float, np.ndarray]:
    """`identify_controller`'s least squares: `(coefficients, r2, residual)`; the
    residual is what the recorded force carries besides the controller's output."""
    n = q.size
    win = np.lib.stride_tricks.sliding_window_view
    rp = np.concatenate([np.full(taps - 1, r[0]), r])
    qp = np.concatenate([np.full(taps - 1, q[0]), q])
    cols_r = win(rp, taps)[:, ::-1]
    cols_q = win(qp, taps)[:, ::-1]
    integ = np.cumsum(r - q) * dt
    phi = np.concatenate([cols_r, cols_q, integ[:, None], np.ones((n, 1))], axis=1)
    scale = np.sqrt(np.mean(phi**2, axis=0)) + 1e-300
    coef, *_ = np.linalg.lstsq(phi / scale, u, rcond=1e-10)
    coef = coef / scale
    res = u - phi @ coef
    var_u = float(np.var(u))
    r2 = 1.0 - float(np.var(res)) / var_u if var_u > 0 else 0.0
    return coef, r2, res


GAUSSIAN_LEVEL = 0.01
"""Significance level of the normality test (`force_noise`) below which the in-band
controller residual is not taken as measurement noise."""


def force_noise(
    residual: np.ndarray, fs: float, cutoff: float, rng: np.random.Generator, count: int
) -> np.ndarray:
    """`count` draws of the recorded force's measurement noise, from what the identified
    controller leaves of the force (`residual`).

    A measurement noise is stationary and Gaussian; so is its in-band part, coloured or
    not. When the in-band residual (low-passed at `cutoff`, taken every `fs/(2·cutoff)`
    samples so that the samples are nearly independent) passes D'Agostino and Pearson's
    normality test at `GAUSSIAN_LEVEL`, the draws have the residual's own power spectrum
    (`noise_like`: a coloured noise keeps its in-band power). Otherwise the residual holds
    more than noise -- force pulses injected into the drive, an anti-wind-up or other
    nonlinearity of the controller -- and only its white part (robust successive
    differences) is measurement noise."""
    e = np.asarray(residual, float)
    sos = ss.butter(4, cutoff, fs=fs, output="sos")
    pad = int(min(e.size - 1, 3 * fs / cutoff))
    band = ss.sosfiltfilt(sos, e - e.mean(), padlen=pad)
    every = max(1, int(fs / (2.0 * cutoff)))
    x = band[pad : e.size - pad : every]
    if x.size >= 20 and scipy.stats.normaltest(x).pvalue >= GAUSSIAN_LEVEL:
        return noise_like(e, fs, rng, count)
    return difference_noise_sigma(e) * rng.standard_normal((count, e.size))


def drive_band(options: Mapping[str, Any], dt: float) -> DriveBand:
    """The analysis band of a drive record sampled every `dt` under the family's options
    (`cutoff_hz`, `filter_order`, `decimation`, `zoh_force`)."""
    return DriveBand.of(
        1.0 / float(dt),
        options.get("cutoff_hz"),
        order=int(options.get("filter_order", 4)),
        decimation=options.get("decimation"),
        hold=bool(options.get("zoh_force", True)),
        who="diagnose(drive)",
    )


def _null_records(rec: Record, mass, fv, off, rng, count, options) -> list[Record]:
    q = np.asarray(rec["q"], float)
    u = np.asarray(rec["u"], float)
    dt = float(rec.dt)
    fs = 1.0 / dt
    n = q.size
    step = quantisation_step(q)
    band = drive_band(options, dt)
    cutoff = band.cutoff_hz
    qf = band.lowpass(q)
    sigma_q = 0.0 if step > 0 else float(np.std(q - qf))
    quantise = _quantiser(step, sigma_q, rng, count)
    sims = None
    if "r" in rec.names and mass > 0:  # a fixed zero mass: no loop to simulate, replay
        r = np.asarray(rec["r"], float)
        taps = int(options.get("controller_taps", 16))
        coef, r2, res_u = _controller_fit(q, u, r, dt, taps)
        if r2 >= 0.95:
            sims = _closed_loop(coef, taps, r, q[0], mass, fv, off, dt, quantise, count)
            track = float(np.sqrt(np.mean((q - r) ** 2))) + 10 * max(step, sigma_q)
            ok = np.all(np.isfinite(sims[0]), axis=1) & (
                np.sqrt(np.mean((sims[0] - r) ** 2, axis=1)) < 10 * track
            )
            if not np.all(ok):
                sims = None  # the identified loop does not track: replay instead
            else:
                q_sim, u_sim = sims
                u_sim = u_sim + force_noise(res_u, fs, cutoff, rng, count)
                sims = (q_sim, u_sim)
    if sims is None:
        # replay of the record's in-band motion; the force acting at t_k + dt/2 is what a
        # held sample represents (see `prepare`)
        v, a = band.derivatives(qf)
        force = mass * a + fv * v + off
        if band.hold:
            t = np.arange(n) * dt
            force = np.interp(t + 0.5 * dt, t, force)
        sigma_u = white_noise_floor(u - band.lowpass(u), fs)[1]
        u_sim = force[None, :] + sigma_u * rng.standard_normal((count, n))
        q_sim = quantise(np.broadcast_to(qf, (count, n)))
        sims = (q_sim, u_sim)
    q_sim, u_sim = sims
    out = []
    for k in range(count):
        signals = {"q": q_sim[k], "u": u_sim[k]}
        if "r" in rec.names:
            signals["r"] = np.asarray(rec["r"], float)
        out.append(Record(signals, dt=dt, metadata={"source": "null"}))
    return out


def _closed_loop(coef, taps, r, q0, mass, fv, off, dt, quantise, count):
    """`count` closed loops of the rigid axis with the identified controller, vectorised
    over the draws: exact zero-order-hold discretisation of `M q̈ + Fv q̇ = F − offset`."""
    import scipy.linalg as sl

    a_c = np.array([[0.0, 1.0], [0.0, -fv / mass]])
    b_c = np.array([[0.0], [1.0 / mass]])
    big = np.zeros((3, 3))
    big[:2, :2], big[:2, 2:] = a_c * dt, b_c * dt
    e = sl.expm(big)
    ad, bd = e[:2, :2], e[:2, 2]
    n = r.size
    a_r, b_q, c_i, d0 = coef[:taps], coef[taps : 2 * taps], coef[2 * taps], coef[2 * taps + 1]
    rp = np.concatenate([np.full(taps - 1, r[0]), r])
    u_r = np.lib.stride_tricks.sliding_window_view(rp, taps)[:, ::-1] @ a_r + d0
    x = np.zeros((count, 2))
    x[:, 0] = q0
    qbuf = np.tile(quantise(np.full((count, 1), q0))[:, :1], (1, taps))
    integ = np.zeros(count)
    q_out = np.empty((count, n))
    u_out = np.empty((count, n))
    for k in range(n):
        qm = quantise(x[:, :1])[:, 0]
        qbuf = np.concatenate([qm[:, None], qbuf[:, :-1]], axis=1)
        integ = integ + (r[k] - qm) * dt
        force = u_r[k] + qbuf @ b_q + c_i * integ
        q_out[:, k], u_out[:, k] = qm, force
        x = x @ ad.T + np.outer(force - off, bd)
    return q_out, u_out
