"""Drive twin: an EMPS-like closed-loop prismatic axis with switchable hidden effects.

The plant is the Electro-Mechanical Positioning System of Janot, Gautier and Brunot
(2019, "Data set and reference models of EMPS", docs/guides/drive.md): a motor-side mass `Mm`
and a load mass `ML` (rigidly connected unless a coupling effect is switched on), viscous
friction `Fv`, a constant offset force, and the EMPS position controller running at the
sample rate

    ν_k = kp·kv·(r_k − q_k) − kv·v̂_k,      F_k = gτ·ν_k   (held over one sample, ZOH)

where `q_k` is the quantised motor-side encoder position and `v̂_k` the drive's velocity
estimate (backward difference of `q_k`, first-order low-pass). Between samples the
continuous plant is integrated with `oversample` Störmer–Verlet (kick–drift–kick)
substeps: second order and symplectic, so coupling and contact springs neither gain nor
lose energy numerically. Bristle states of LuGre friction are advanced with the exact
exponential update at the midpoint velocity, which is stable for any bristle stiffness.

Rigid plant (no coupling effect), with all effects off:

    M q̈ + Fv q̇ + offset = F.

Two-mass plant (`resonance` or `backlash` on), `δ = qm − qL`, `Fv` split in proportion
to the masses (so the rigid-body motion still sees exactly `Fv`), the offset on the motor:

    Mm q̈m = F − (Mm/M)·Fv q̇m − offset − f_c(δ, δ̇)
    ML q̈L = f_c(δ, δ̇) − (ML/M)·Fv q̇L − f_friction + f_external + f_position.

In the rigid plant the load forces act on the single mass `M = Mm + ML`.

The hidden effects are built differently from the simple augmentations a diagnosis would
try (LuGre bristle friction, not a sign law; a contact spring with clearance, not a
dead-zone operator; a fractional transport delay on a zero-order-held force ...).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._misc import options_object
from ..data import Record

# Stream identifiers for `jr.fold_in`: every random quantity has its own stream, so that
# switching an effect on or off never changes the reference or the noise of an experiment.
_REFERENCE, _NOISE_U, _NOISE_Q, _EXTERNAL = 0, 1, 2, 3

DRIVE_TWIN_EFFECTS: tuple[str, ...] = (
    "lugre",
    "asymmetric",
    "backlash",
    "resonance",
    "time_delay",
    "external_force",
    "position_dependence",
)
"""Keys accepted in `DriveTwin(effects={...})`."""

DRIVE_EFFECT_LABELS: tuple[str, ...] = (
    "coulomb_friction",
    "asymmetric_friction",
    "stribeck_friction",
    "backlash",
    "resonance",
    "time_delay",
    "external_force",
    "position_dependence",
)
"""The drive-family effect labels of docs/guides/contracts.md that `draw_drive_effect` knows."""

_REQUIRED = object()

# name -> (default, unit, description). A default of `None` is filled in from other
# parameters (documented in `DriveTwin`).
_EFFECT_PARAMETERS: dict[str, dict[str, Any]] = {
    "lugre": {
        "Fc": _REQUIRED,
        "Fs": None,
        "vs": 0.01,
        "sigma0": 1e5,
        "sigma1": 300.0,
        "sigma2": 0.0,
    },
    "asymmetric": {
        "Fc_pos": _REQUIRED,
        "Fc_neg": _REQUIRED,
        "dFv_pos": 0.0,
        "dFv_neg": 0.0,
        "sigma0": 1e5,
        "sigma1": 300.0,
    },
    "backlash": {"b": _REQUIRED, "k": 3e7, "c": None},
    "resonance": {"f_r": _REQUIRED, "zeta_r": 0.05},
    "time_delay": {"tau": _REQUIRED},
    "external_force": {"amplitude": _REQUIRED, "n_pulses": 5, "width": 0.4, "rise": 0.01},
    "position_dependence": {
        "amplitude": _REQUIRED,
        "pitch": 0.02,
        "phase": 0.0,
        "spring": 0.0,
        "center": 0.1,
        "length": 0.05,
    },
}

# Parameters that may be zero or negative; all others must be > 0.
_MAY_BE_ZERO = {
    ("lugre", "sigma2"),
    ("lugre", "sigma1"),
    ("asymmetric", "sigma1"),
    ("backlash", "c"),
    ("resonance", "zeta_r"),
    ("time_delay", "tau"),
    ("position_dependence", "spring"),
}
_MAY_BE_NEGATIVE = {
    ("asymmetric", "dFv_pos"),
    ("asymmetric", "dFv_neg"),
    ("position_dependence", "phase"),
    ("position_dependence", "center"),
    ("position_dependence", "spring"),
    ("external_force", "amplitude"),
    ("position_dependence", "amplitude"),
}


def _normalise_effects(
    effects: Mapping[str, Mapping[str, Any]] | None, Mm: float, ML: float
) -> dict[str, dict[str, float]]:
    """Validate the effect dictionary and fill in defaults; returns plain floats."""
    if effects is None:
        return {}
    if not isinstance(effects, Mapping):
        raise TypeError(
            f"effects must be a dict effect -> dict of parameters, got {type(effects).__name__}; "
            "e.g. effects={'lugre': dict(Fc=20.0)}."
        )
    out: dict[str, dict[str, float]] = {}
    for name, params in effects.items():
        if name not in _EFFECT_PARAMETERS:
            raise ValueError(
                f"Unknown drive-twin effect {name!r}; supported effects are "
                f"{DRIVE_TWIN_EFFECTS}. (Effect *labels* such as 'coulomb_friction' are mapped "
                "to twin effects by jaxvs.twins.draw_drive_effect.)"
            )
        if params is None:
            continue  # `effects={"lugre": None}` means off.
        if not isinstance(params, Mapping):
            raise TypeError(
                f"effects[{name!r}] must be a dict of parameters, got {type(params).__name__}."
            )
        spec = _EFFECT_PARAMETERS[name]
        unknown = set(params) - set(spec)
        if unknown:
            raise ValueError(
                f"Unknown parameter(s) {sorted(unknown)} for effect {name!r}; its parameters "
                f"are {list(spec)}."
            )
        values: dict[str, float] = {}
        for pname, default in spec.items():
            if pname in params:
                value = params[pname]
            elif default is _REQUIRED:
                raise ValueError(
                    f"Effect {name!r} needs the parameter {pname!r}; its parameters are "
                    f"{list(spec)} (required: "
                    f"{[p for p, d in spec.items() if d is _REQUIRED]})."
                )
            else:
                value = default
            if value is None:
                values[pname] = math.nan  # filled in below
                continue
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise TypeError(
                    f"Parameter {pname!r} of effect {name!r} must be a real number, got {value!r}."
                ) from None
            if not math.isfinite(value):
                raise ValueError(f"Parameter {pname!r} of effect {name!r} is not finite.")
            if (name, pname) not in _MAY_BE_NEGATIVE:
                if value < 0 or (value == 0 and (name, pname) not in _MAY_BE_ZERO):
                    bound = ">= 0" if (name, pname) in _MAY_BE_ZERO else "> 0"
                    raise ValueError(
                        f"Parameter {pname!r} of effect {name!r} must be {bound}, got {value}."
                    )
            values[pname] = value
        if name == "lugre":
            if math.isnan(values["Fs"]):
                values["Fs"] = values["Fc"]
            if values["Fs"] < values["Fc"]:
                raise ValueError(
                    f"LuGre friction needs Fs >= Fc (static friction at least the Coulomb "
                    f"level); got Fs={values['Fs']}, Fc={values['Fc']}."
                )
        if name == "backlash" and math.isnan(values["c"]):
            # Heuristic: contact damping ratio 0.1 of the contact mode of the two masses.
            values["c"] = 2.0 * 0.1 * math.sqrt(values["k"] * Mm * ML / (Mm + ML))
        if name == "external_force":
            n = values["n_pulses"]
            if n != int(n) or n < 1:
                raise ValueError(f"external_force n_pulses must be an integer >= 1, got {n}.")
        if name == "resonance" and values["zeta_r"] >= 1.0:
            raise ValueError(
                f"resonance zeta_r must be below 1 (an oscillating mode), got {values['zeta_r']}."
            )
        out[name] = values
    if "backlash" in out and "resonance" in out:
        raise ValueError(
            "The drive twin has one motor-load coupling: switch on either 'backlash' (contact "
            "spring with clearance) or 'resonance' (flexible coupling), not both."
        )
    return out


def _trapezoid_distance(tau, D, V, A):
    """Distance travelled `tau` [s] into a trapezoidal-velocity move of length `D` [m]
    (cruise speed `V` [m/s], acceleration `A` [m/s²]); `D` after the move ends."""
    full = D >= V * V / A
    Vp = jnp.where(full, V, jnp.sqrt(D * A))  # triangular profile for short moves
    ta = Vp / A
    tc = jnp.where(full, D / V - V / A, 0.0)
    T = 2.0 * ta + tc
    x1 = 0.5 * A * tau**2
    x2 = 0.5 * A * ta**2 + Vp * (tau - ta)
    x3 = D - 0.5 * A * (T - tau) ** 2
    return jnp.where(tau < ta, x1, jnp.where(tau < ta + tc, x2, jnp.where(tau < T, x3, D)))


def drive_reference(
    key: PRNGKeyArray,
    n: int,
    dt: float,
    *,
    position_range: tuple[float, float] = (0.0, 0.2),
    speed_range: tuple[float, float] = (0.05, 0.3),
    accel_range: tuple[float, float] = (0.5, 3.0),
    dwell_range: tuple[float, float] = (0.05, 0.5),
    smoothing: float = 0.02,
) -> Float[Array, " time"]:
    """Random point-to-point position reference, like the EMPS reference `qg`.

    A sequence of moves between random positions, each with a trapezoidal velocity profile
    of random cruise speed and acceleration followed by a random dwell; the profile is
    then smoothed by a moving average of length `smoothing`, which limits the jerk to
    `A / smoothing` (a jerk-limited "S-curve" move). Successive targets are independent,
    so about half of the moves reverse the direction of the previous one.

    **Arguments:**

    - `key`: PRNG key. `n`: number of samples; `dt`: sample time [s].
    - `position_range`: positions the moves go between [m].
    - `speed_range`: cruise speeds [m/s]; `accel_range`: accelerations [m/s²].
    - `dwell_range`: rest time after each move [s].
    - `smoothing`: moving-average length [s] (0 = trapezoidal velocity).

    **Returns:**

    The reference position `(n,)` [m], starting at rest at a random position.
    """
    lo, hi = (float(v) for v in position_range)
    if not (hi > lo):
        raise ValueError(
            f"position_range must be (low, high) with high > low, got {position_range}."
        )
    for name, rng in (
        ("speed_range", speed_range),
        ("accel_range", accel_range),
        ("dwell_range", dwell_range),
    ):
        if not (0 < rng[0] <= rng[1]):
            raise ValueError(f"{name} must be (low, high) with 0 < low <= high, got {rng}.")
    return _reference(
        key,
        int(n),
        float(dt),
        (lo, hi),
        tuple(float(v) for v in speed_range),
        tuple(float(v) for v in accel_range),
        tuple(float(v) for v in dwell_range),
        float(smoothing),
    )


@functools.partial(jax.jit, static_argnums=(1, 2, 3, 4, 5, 6, 7))
def _reference(key, n, dt, position_range, speed_range, accel_range, dwell_range, smoothing):
    lo, hi = position_range
    # Every segment (move + dwell) lasts at least the shortest dwell, so this many moves
    # always cover the record.
    n_moves = int(math.ceil(n * dt / dwell_range[0])) + 2
    kp, kv, ka, kw = jr.split(key, 4)
    f = jnp.result_type(float)
    p = jr.uniform(kp, (n_moves + 1,), f, lo, hi)
    V = jr.uniform(kv, (n_moves,), f, *speed_range)
    A = jr.uniform(ka, (n_moves,), f, *accel_range)
    W = jr.uniform(kw, (n_moves,), f, *dwell_range)
    step = jnp.diff(p)
    D = jnp.abs(step)
    Vp = jnp.where(D >= V * V / A, V, jnp.sqrt(D * A))
    T = jnp.where(D >= V * V / A, D / V + V / A, 2.0 * Vp / A)
    starts = jnp.concatenate([jnp.zeros(1, f), jnp.cumsum(T + W)[:-1]])
    t = jnp.arange(n, dtype=f) * dt
    i = jnp.clip(jnp.searchsorted(starts, t, side="right") - 1, 0, n_moves - 1)
    r = p[i] + jnp.sign(step[i]) * _trapezoid_distance(t - starts[i], D[i], V[i], A[i])
    w = max(1, int(round(smoothing / dt)))
    if w > 1:
        padded = jnp.concatenate([jnp.full((w - 1,), r[0]), r])
        r = jnp.convolve(padded, jnp.full((w,), 1.0 / w, f), mode="valid")
    return r


def _pulse_train(key, t, amplitude, n_pulses, width, rise, duration):
    """Smoothed rectangular force pulses [N] at times `t` [s]: one pulse in each of
    `n_pulses` equal slots of the record, at a random place in its slot, of random sign
    and of width `width·U(0.6, 1)` [s]; edges are tanh ramps of time constant `rise`."""
    ks, kw, kg = jr.split(key, 3)
    slot = duration / n_pulses
    widths = jnp.minimum(width * jr.uniform(kw, (n_pulses,), t.dtype, 0.6, 1.0), 0.8 * slot)
    starts = jnp.arange(n_pulses) * slot + jr.uniform(ks, (n_pulses,), t.dtype) * (slot - widths)
    signs = jnp.where(jr.bernoulli(kg, 0.5, (n_pulses,)), 1.0, -1.0)
    tt = t[..., None]
    shape = 0.5 * (jnp.tanh((tt - starts) / rise) - jnp.tanh((tt - starts - widths) / rise))
    return amplitude * jnp.sum(signs * shape, axis=-1)


@dataclasses.dataclass(frozen=True)
class DriveLoop:
    """The controller and sensor settings of a [`DriveTwin`][] (the EMPS loop): the
    position gain `kp` [1/s], velocity gain `kv` [V/(m/s)] and force constant `gtau` [N/V],
    the encoder `resolution` [m], the velocity filter's `velocity_cutoff` [Hz], the
    amplifier `saturation` [V] (`None`: none) and the simulation steps per sample
    `oversample`."""

    kp: float = 160.18
    kv: float = 243.45
    gtau: float = 35.15
    resolution: float = 1e-7
    velocity_cutoff: float = 200.0
    saturation: float | None = None
    oversample: int = 10


class DriveTwin(eqx.Module):
    """EMPS-like closed-loop prismatic axis with switchable hidden effects (the "real
    plant" of the drive family).

    **Arguments:**

    - `M`: total moving mass `Mm + ML` [kg] (EMPS: 95.1 kg).
    - `Fv`: viscous friction [N·s/m] (EMPS: 203.5 N·s/m).
    - `offset`: constant offset force [N] (EMPS: −3.16 N); it enters as `… + offset = F`.
    - `motor_mass`: motor-side mass `Mm` [kg]; the load is `ML = M − Mm`. Only matters
        when a coupling effect (`backlash`, `resonance`) separates the two.
    - `loop`: the controller and sensor settings, a [`DriveLoop`][], or its fields as
      keywords:
        - `kp` [1/s], `kv` [V/(m/s)], `gtau` [N/V]: EMPS controller gains.
        - `resolution`: encoder quantisation step [m] (0 = none).
        - `velocity_cutoff`: cut-off of the drive's first-order velocity filter [Hz].
        - `saturation`: controller output limit [V] (`None` = no saturation).
        - `oversample`: integration substeps per sample.
    - `effects`: dict effect -> dict of parameters (missing parameters take the defaults
        given here); all effects are off by default and then contribute exactly nothing:
        - `"lugre"`: LuGre friction on the load (Canudas de Wit et al. 1995, IEEE TAC 40(3)),
          `ż = v − σ0|v|z/g(v)`, `g(v) = Fc + (Fs − Fc)exp(−(v/vs)²)`,
          `f = σ0 z + σ1 ż + σ2 v`. `Fc` [N] (required), `Fs` [N] (default `Fc`: Coulomb-like;
          `Fs > Fc`: Stribeck), `vs` = 0.01 m/s, `sigma0` = 1e5 N/m, `sigma1` = 300 N·s/m,
          `sigma2` = 0 N·s/m. Steady sliding: `f = g(v)·sign(v) + σ2 v`.
        - `"asymmetric"`: direction-dependent friction on the load, a LuGre law whose
          level is `Fc_pos` [N] when moving forwards and `Fc_neg` [N] backwards (both
          required), plus extra viscous friction `dFv_pos` / `dFv_neg` [N·s/m] (added to
          `Fv`, default 0) per direction; `sigma0`, `sigma1` as for `lugre`.
        - `"backlash"`: contact spring with clearance between motor and load: contact
          force `k·(δ − b·sign δ) + c·δ̇` while `|δ| > b` (never pulling), zero inside the
          gap; `b` [m] half the total gap (required), `k` = 3e7 N/m, `c` [N·s/m] (default:
          damping ratio 0.1 of the contact mode).
        - `"resonance"`: flexible coupling whose free two-mass mode is at `f_r` [Hz]
          (required) with damping ratio `zeta_r` (default 0.05):
          `k = μ(2πf_r)²`, `c = 2ζ_r(2πf_r)μ`, `μ = Mm·ML/M`.
        - `"time_delay"`: the motor force acts `tau` [s] (required, any real value ≥ 0)
          after it is commanded; the measured `u` is the commanded force.
        - `"external_force"`: `n_pulses` (default 5) unmeasured force pulses on the load of
          amplitude `amplitude` [N] (required) and random sign, width `width·U(0.6, 1)`
          (`width` = 0.4 s), tanh edges of time constant `rise` = 0.01 s; one pulse at a
          random place in each of `n_pulses` equal slots of the record (drawn from the
          experiment key).
        - `"position_dependence"`: force on the load
          `amplitude·sin(2π qL/pitch + phase) − spring·tanh((qL − center)/length)`:
          a cogging ripple (`amplitude` [N] required, `pitch` = 0.02 m, `phase` = 0 rad)
          and a saturating gravity-like pull toward `center` (`spring` = 0 N,
          `center` = 0.1 m, `length` = 0.05 m).

    **Example:**

    ```python
    twin = jaxvs.twins.DriveTwin(effects={"lugre": dict(Fc=20.0)})
    rec = twin.experiment(jax.random.key(0))      # Record with t, q, u, r
    truth = twin.truth(rec)                       # internal signals, for plots and tests
    ```
    """

    Mm: Float[Array, ""]
    ML: Float[Array, ""]
    Fv: Float[Array, ""]
    offset: Float[Array, ""]
    kp: Float[Array, ""]
    kv: Float[Array, ""]
    gtau: Float[Array, ""]
    effects: dict[str, dict[str, Array]]
    resolution: float = eqx.field(static=True)
    velocity_cutoff: float = eqx.field(static=True)
    saturation: float | None = eqx.field(static=True)
    oversample: int = eqx.field(static=True)
    n_pulses: int = eqx.field(static=True)
    max_delay: float = eqx.field(static=True)

    def __init__(
        self,
        M: float = 95.0,
        Fv: float = 200.0,
        offset: float = -3.0,
        *,
        motor_mass: float = 30.0,
        effects: Mapping[str, Mapping[str, Any]] | None = None,
        loop: DriveLoop | None = None,
        **keywords: Any,
    ):
        # The controller and sensor settings: a DriveLoop, or its fields as keywords.
        loop = options_object(DriveLoop, loop, keywords, "DriveTwin", "loop")
        kp, kv, gtau = loop.kp, loop.kv, loop.gtau
        resolution, velocity_cutoff = loop.resolution, loop.velocity_cutoff
        saturation, oversample = loop.saturation, loop.oversample
        for name, value in (
            ("M", M),
            ("Fv", Fv),
            ("motor_mass", motor_mass),
            ("kp", kp),
            ("kv", kv),
            ("gtau", gtau),
            ("velocity_cutoff", velocity_cutoff),
        ):
            if not (isinstance(value, int | float | np.floating | np.integer) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}.")
        if not motor_mass < M:
            raise ValueError(
                f"motor_mass ({motor_mass} kg) must be smaller than the total mass M ({M} kg); "
                "the load mass is M − motor_mass."
            )
        if not (isinstance(resolution, int | float) and resolution >= 0):
            raise ValueError(f"resolution must be a number >= 0 (metres), got {resolution!r}.")
        if saturation is not None and not saturation > 0:
            raise ValueError(f"saturation must be None or a positive voltage, got {saturation!r}.")
        if not (isinstance(oversample, int | np.integer) and oversample >= 1):
            raise ValueError(f"oversample must be an integer >= 1, got {oversample!r}.")
        f = jnp.result_type(float)
        self.Mm = jnp.asarray(motor_mass, f)
        self.ML = jnp.asarray(M - motor_mass, f)
        self.Fv, self.offset = jnp.asarray(Fv, f), jnp.asarray(offset, f)
        self.kp, self.kv, self.gtau = (jnp.asarray(v, f) for v in (kp, kv, gtau))
        values = _normalise_effects(effects, float(motor_mass), float(M - motor_mass))
        self.n_pulses = int(values.get("external_force", {}).pop("n_pulses", 0))
        self.max_delay = float(values.get("time_delay", {}).get("tau", 0.0))
        self.effects = {
            name: {p: jnp.asarray(v, f) for p, v in params.items()}
            for name, params in values.items()
        }
        self.resolution = float(resolution)
        self.velocity_cutoff = float(velocity_cutoff)
        self.saturation = None if saturation is None else float(saturation)
        self.oversample = int(oversample)

    # ------------------------------------------------------------------ properties
    @property
    def M(self) -> Array:
        """Total moving mass [kg]."""
        return self.Mm + self.ML

    @property
    def two_mass(self) -> bool:
        """Whether motor and load are separate masses (a coupling effect is on)."""
        return "backlash" in self.effects or "resonance" in self.effects

    @property
    def effect_parameters(self) -> dict[str, dict[str, float]]:
        """The hidden effects with all their parameters, as plain floats (the label of a
        blind test; never written into a record)."""
        out = {
            name: {p: float(v) for p, v in params.items()} for name, params in self.effects.items()
        }
        if "external_force" in out:
            out["external_force"]["n_pulses"] = self.n_pulses
        return out

    @property
    def nominal(self) -> dict[str, float]:
        """The nominal rigid-model parameters `M` [kg], `Fv` [N·s/m], `offset` [N]."""
        return {"M": float(self.M), "Fv": float(self.Fv), "offset": float(self.offset)}

    def without_effects(self) -> DriveTwin:
        """The same twin with every hidden effect off."""
        new = object.__new__(DriveTwin)
        for field in dataclasses.fields(self):
            object.__setattr__(new, field.name, getattr(self, field.name))
        object.__setattr__(new, "effects", {})
        object.__setattr__(new, "n_pulses", 0)
        object.__setattr__(new, "max_delay", 0.0)
        return new

    def perturb(self, key: PRNGKeyArray, scale: float = 0.1) -> DriveTwin:
        """A twin whose nominal `M`, `Fv` and `offset` are each multiplied by an
        independent `1 + U(−scale, scale)` (both masses by the same factor); controller
        and effects unchanged. Models "ordinary parameter error" of a nominal model."""
        if not 0 <= scale < 1:
            raise ValueError(f"scale must be in [0, 1), got {scale!r}.")
        factors = 1.0 + jr.uniform(key, (3,), self.Mm.dtype, -scale, scale)
        return eqx.tree_at(
            lambda m: (m.Mm, m.ML, m.Fv, m.offset),
            self,
            (
                self.Mm * factors[0],
                self.ML * factors[0],
                self.Fv * factors[1],
                self.offset * factors[2],
            ),
        )

    # ------------------------------------------------------------------ simulation
    def reference(self, key: PRNGKeyArray, duration: float = 25.0, dt: float = 1e-3) -> Array:
        """The random point-to-point reference `r` [m] that `experiment(key, duration, dt)`
        uses (see `drive_reference`)."""
        return drive_reference(jr.fold_in(key, _REFERENCE), _n_samples(duration, dt), dt)

    def run(
        self,
        key: PRNGKeyArray,
        duration: float = 25.0,
        dt: float = 1e-3,
        noise_u: float | Array = 1.0,
        noise_q: float | Array = 0.0,
        reference: Float[ArrayLike, " time"] | None = None,
    ) -> dict[str, Array]:
        """Simulate one closed-loop experiment; pure JAX (jittable, `vmap` over keys).

        Same arguments as `experiment`. Returns a dict of `(time,)` arrays: the measured
        `q`, `u`, `r` and the true internal signals of `truth`.
        """
        dt = float(dt)
        if reference is None:
            r = self.reference(key, duration, dt)
        else:
            r = jnp.asarray(reference, self.Mm.dtype)
            if r.ndim != 1 or r.shape[0] < 2:
                raise ValueError(
                    f"reference must be a 1-D array of at least 2 samples [m], got shape {r.shape}."
                )
        return _run(self, key, r, dt, jnp.asarray(noise_u, r.dtype), jnp.asarray(noise_q, r.dtype))

    def experiment(
        self,
        key: PRNGKeyArray,
        duration: float = 25.0,
        dt: float = 1e-3,
        noise_u: float = 1.0,
        noise_q: float = 0.0,
        *,
        reference: Float[ArrayLike, " time"] | None = None,
    ) -> Record:
        """One closed-loop experiment as a `jaxvs.data.Record`, like an EMPS data file.

        **Arguments:**

        - `key`: PRNG key; it fixes the reference, the noise and the external-force pulses.
        - `duration`: length [s] (`round(duration/dt)` samples); ignored with `reference`.
        - `dt`: sample time of the controller and the record [s].
        - `noise_u`: standard deviation of the white noise on the measured force `u` [N].
        - `noise_q`: standard deviation of white noise added to the recorded position [m]
            (the controller sees the noise-free quantised encoder).
        - `reference`: optional position reference `(time,)` [m] instead of the random one.

        **Returns:**

        A `Record` with signals `q` [m] (motor-side position, quantised to `resolution`
        plus noise), `u` [N] (motor force `gτ·ν` plus noise), `r` [m] (reference) and
        metadata `kp`, `kv`, `gtau`, `source="DriveTwin"` and what `truth` needs to
        re-simulate it. The hidden effects are never in the record.
        """
        for name, value in (("noise_u", noise_u), ("noise_q", noise_q)):
            if not (isinstance(value, int | float | np.floating | np.integer) and value >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {value!r}.")
        if reference is None:
            _n_samples(duration, dt)
        out = self.run(key, duration, dt, noise_u, noise_q, reference)
        typed = jnp.issubdtype(key.dtype, jax.dtypes.prng_key)
        key_data = np.asarray(jr.key_data(key) if typed else key)
        metadata = {
            "kp": float(self.kp),
            "kv": float(self.kv),
            "gtau": float(self.gtau),
            "source": "DriveTwin",
            "resolution": self.resolution,
            "noise_u": float(noise_u),
            "noise_q": float(noise_q),
            "key_data": key_data,
            "key_typed": bool(typed),
        }
        if reference is not None:
            metadata["reference_given"] = True
        signals = {name: np.asarray(out[name]) for name in ("q", "u", "r")}
        return Record(signals, dt=dt, units={"q": "m", "u": "N", "r": "m"}, metadata=metadata)

    def truth(self, record: Record) -> dict[str, np.ndarray]:
        """The true internal signals behind a record made by `experiment` of this twin
        (re-simulated from the key stored in the record's metadata).

        **Returns:**

        A dict of `(time,)` NumPy arrays: `t` [s]; `q_motor`, `v_motor`, `q_load`,
        `v_load` (states at the samples, load = motor when rigid) [m, m/s];
        `velocity_estimate` [m/s] (the drive's `v̂`); `force_commanded` [N] (noise-free
        `u`); and, averaged over each sample interval `[t_k, t_k+dt)`, the forces [N]
        `force_applied` (motor force acting, after any delay), `friction` (effect friction
        on the load, opposing motion: enters as `… − friction`), `external_force`,
        `position_force` and `coupling_force` (force of the motor on the load; zero when
        rigid) and `load_force = external_force + position_force − friction`.
        """
        meta = record.metadata
        if meta.get("source") != "DriveTwin" or "key_data" not in meta:
            raise ValueError(
                "truth() needs a record made by DriveTwin.experiment (its metadata holds the "
                "key to re-simulate it); this record has none."
            )
        if record.t0 != 0.0:
            raise ValueError(
                "truth() re-simulates the whole experiment; call it on the record as "
                "experiment() returned it (not a slice) and slice the result instead."
            )
        key = jnp.asarray(meta["key_data"])
        if meta["key_typed"]:
            key = jr.wrap_key_data(key)
        n = len(record)
        out = self.run(
            key,
            n * record.dt,
            record.dt,
            meta["noise_u"],
            meta["noise_q"],
            reference=record["r"] if meta.get("reference_given") else None,
        )
        result = {k: np.asarray(v) for k, v in out.items() if k not in ("q", "u", "r")}
        result["t"] = np.asarray(record.t)
        return result

    def plant_response(
        self,
        force: Float[ArrayLike, " time"],
        dt: float = 1e-3,
    ) -> dict[str, Array]:
        """Open-loop response of the plant (no controller) to a motor force [N] held over
        each sample of length `dt` [s], from rest at `q = 0` (with the effects on; the
        external-force pulses use a fixed key). Returns the same internal signals as
        `truth` (no measured `q`, `u`, `r`)."""
        force = jnp.asarray(force, self.Mm.dtype)
        if force.ndim != 1:
            raise ValueError(f"force must be a 1-D array [N], got shape {force.shape}.")
        out = _run(
            self,
            jr.key(0),
            jnp.zeros_like(force),
            float(dt),
            jnp.asarray(0.0),
            jnp.asarray(0.0),
            open_loop=force,
        )
        return {k: v for k, v in out.items() if k not in ("q", "u", "r")}


def _n_samples(duration: float, dt: float) -> int:
    if not (isinstance(dt, int | float | np.floating) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}.")
    if not (isinstance(duration, int | float | np.floating) and duration > 0):
        raise ValueError(f"duration must be a positive number of seconds, got {duration!r}.")
    n = int(round(duration / dt))
    if n < 2:
        raise ValueError(f"duration {duration} s at dt {dt} s gives fewer than 2 samples.")
    return n


def _lugre_bristle(z, v, g, sigma0, h):
    """Exact bristle update over `h` for a frozen velocity `v`:
    `ż = v − λ z`, `λ = σ0|v|/g`; returns the new state."""
    lam = sigma0 * jnp.abs(v) / g
    lam_h = lam * h
    decay = jnp.exp(-lam_h)
    # (1 − e^{−λh})/λ, continuous at λ = 0 (where it is h).
    safe = jnp.where(lam_h > 1e-12, lam, 1.0)
    phi = jnp.where(lam_h > 1e-12, -jnp.expm1(-lam_h) / safe, h)
    return z * decay + v * phi


@eqx.filter_jit
def _run(twin: DriveTwin, key, r, dt: float, noise_u, noise_q, open_loop=None):
    n = r.shape[0]
    K = twin.oversample
    h = dt / K
    eff = twin.effects
    f = r.dtype
    Mm, ML, M = twin.Mm, twin.ML, twin.Mm + twin.ML
    two = twin.two_mass
    Fv_m, Fv_L = twin.Fv * Mm / M, twin.Fv * ML / M

    # Unmeasured external force on the load at the midpoint of every substep.
    if "external_force" in eff:
        e = eff["external_force"]
        t_sub = (jnp.arange(n, dtype=f)[:, None] + (jnp.arange(K, dtype=f)[None, :] + 0.5) / K) * dt
        f_ext_all = _pulse_train(
            jr.fold_in(key, _EXTERNAL),
            t_sub,
            e["amplitude"],
            twin.n_pulses,
            e["width"],
            e["rise"],
            n * dt,
        )
    else:
        f_ext_all = jnp.zeros((n, K), f)

    # Delay line of commanded forces: buf[j] = F_{k−j}. With τ = (m + φ)·dt the force
    # acting in substep j is F_{k−m−1} for the part of the substep before φ·dt and F_{k−m}
    # after it (exact impulse of the delayed zero-order-held force).
    if "time_delay" in eff:
        tau = eff["time_delay"]["tau"]
        n_buf = int(math.floor(twin.max_delay / dt)) + 2
        m = jnp.floor(tau / dt)
        phase = tau / dt - m
        m = jnp.clip(m.astype(jnp.int32), 0, n_buf - 2)
        w_old = jnp.clip(phase * K - jnp.arange(K, dtype=f), 0.0, 1.0)
    else:
        n_buf = 1

    if "resonance" in eff:
        res = eff["resonance"]
        mu = Mm * ML / M
        omega = 2 * jnp.pi * res["f_r"]
        k_res, c_res = mu * omega**2, 2 * res["zeta_r"] * omega * mu

    def lugre_force(p, v, z, g):
        # f = σ0 z + σ1 ż with ż = v − σ0|v|z/g evaluated at (v, z); |ż| ≤ 2|v| since the
        # exact bristle update keeps |z| ≤ max g/σ0.
        return p["sigma0"] * z + p["sigma1"] * (v - p["sigma0"] * jnp.abs(v) * z / g)

    def load_forces(q, v, z, x):
        """Effect forces on the load [N]: friction (opposing motion), external, position."""
        friction = jnp.zeros((), f)
        if "lugre" in eff:
            p = eff["lugre"]
            g = p["Fc"] + (p["Fs"] - p["Fc"]) * jnp.exp(-((v / p["vs"]) ** 2))
            friction += lugre_force(p, v, z["lugre"], g) + p["sigma2"] * v
        if "asymmetric" in eff:
            p = eff["asymmetric"]
            forward = v >= 0
            g = jnp.where(forward, p["Fc_pos"], p["Fc_neg"])
            friction += lugre_force(p, v, z["asymmetric"], g)
            friction += jnp.where(forward, p["dFv_pos"], p["dFv_neg"]) * v
        if "position_dependence" in eff:
            p = eff["position_dependence"]
            position = p["amplitude"] * jnp.sin(2 * jnp.pi * q / p["pitch"] + p["phase"])
            position -= p["spring"] * jnp.tanh((q - p["center"]) / p["length"])
        else:
            position = jnp.zeros((), f)
        return friction, x, position

    def advance_bristles(z, v):
        """Exact bristle update over one substep at the frozen (midpoint) velocity `v`."""
        z = dict(z)
        if "lugre" in eff:
            p = eff["lugre"]
            g = p["Fc"] + (p["Fs"] - p["Fc"]) * jnp.exp(-((v / p["vs"]) ** 2))
            z["lugre"] = _lugre_bristle(z["lugre"], v, g, p["sigma0"], h)
        if "asymmetric" in eff:
            p = eff["asymmetric"]
            g = jnp.where(v >= 0, p["Fc_pos"], p["Fc_neg"])
            z["asymmetric"] = _lugre_bristle(z["asymmetric"], v, g, p["sigma0"], h)
        return z

    def coupling(delta, ddelta):
        """Force of the motor on the load [N] through the coupling."""
        if "resonance" in eff:
            return k_res * delta + c_res * ddelta
        p = eff["backlash"]
        pen = delta - p["b"] * jnp.sign(delta)
        force = p["k"] * pen + p["c"] * ddelta
        # Contact only pushes: no force in the gap, and the damper never pulls.
        force = jnp.where(delta > p["b"], jnp.maximum(force, 0.0), force)
        force = jnp.where(delta < -p["b"], jnp.minimum(force, 0.0), force)
        return jnp.where(jnp.abs(delta) > p["b"], force, 0.0)

    def accelerations(qm, vm, qL, vL, z, F, x):
        """Accelerations [m/s²] of motor and load and the force components [N]."""
        if two:
            friction, external, position = load_forces(qL, vL, z, x)
            fc = coupling(qm - qL, vm - vL)
            am = (F - Fv_m * vm - twin.offset - fc) / Mm
            aL = (fc - Fv_L * vL - friction + external + position) / ML
        else:
            friction, external, position = load_forces(qm, vm, z, x)
            fc = jnp.zeros((), f)
            am = (F - twin.Fv * vm - twin.offset - friction + external + position) / M
            aL = am
        return am, aL, jnp.stack([F, friction, external, position, fc])

    def substep(state, inputs):
        # Störmer–Verlet (kick–drift–kick): second order and symplectic for the springs;
        # velocity-dependent forces use the velocity at the start of each half kick.
        F, x = inputs
        qm, vm, qL, vL, z = state["qm"], state["vm"], state["qL"], state["vL"], state["z"]
        am, aL, forces1 = accelerations(qm, vm, qL, vL, z, F, x)
        vm_h = vm + 0.5 * h * am
        qm_new = qm + h * vm_h
        if two:
            vL_h = vL + 0.5 * h * aL
            qL_new = qL + h * vL_h
        else:
            vL_h, qL_new = vm_h, qm_new
        z_new = advance_bristles(z, vL_h)
        am, aL, forces2 = accelerations(qm_new, vm_h, qL_new, vL_h, z_new, F, x)
        vm_new = vm_h + 0.5 * h * am
        vL_new = vL_h + 0.5 * h * aL if two else vm_new
        new = {"qm": qm_new, "vm": vm_new, "qL": qL_new, "vL": vL_new, "z": z_new}
        return new, 0.5 * (forces1 + forces2)

    alpha = 1.0 - math.exp(-2 * math.pi * twin.velocity_cutoff * dt)

    def quantise(q):
        if twin.resolution > 0:
            return jnp.round(q / twin.resolution) * twin.resolution
        return q

    def sample(carry, xs):
        state, q_prev, v_hat, buf = carry
        r_k, f_ext_k, F_ol = xs
        q_meas = quantise(state["qm"])
        v_hat = v_hat + alpha * ((q_meas - q_prev) / dt - v_hat)
        nu = twin.kp * twin.kv * (r_k - q_meas) - twin.kv * v_hat
        if twin.saturation is not None:
            nu = jnp.clip(nu, -twin.saturation, twin.saturation)
        F_cmd = twin.gtau * nu if open_loop is None else F_ol
        if "time_delay" in eff:
            buf = jnp.concatenate([F_cmd[None], buf[:-1]])
            F_sub = w_old * buf[m + 1] + (1.0 - w_old) * buf[m]
        else:
            F_sub = jnp.full((K,), F_cmd)
        new_state, forces = jax.lax.scan(substep, state, (F_sub, f_ext_k), unroll=min(K, 2))
        out = {
            "q_true": state["qm"],
            "q_meas": q_meas,
            "force_commanded": F_cmd,
            "velocity_estimate": v_hat,
            "v_motor": state["vm"],
            "q_load": state["qL"],
            "v_load": state["vL"],
            "forces": jnp.mean(forces, axis=0),
        }
        return (new_state, q_meas, v_hat, buf), out

    z0 = {name: jnp.zeros((), f) for name in ("lugre", "asymmetric") if name in eff}
    q0 = r[0]
    state0 = {"qm": q0, "vm": jnp.zeros((), f), "qL": q0, "vL": jnp.zeros((), f), "z": z0}
    carry0 = (state0, quantise(q0), jnp.zeros((), f), jnp.zeros((n_buf,), f))
    F_ol = jnp.zeros((n,), f) if open_loop is None else open_loop
    _, out = jax.lax.scan(sample, carry0, (r, f_ext_all, F_ol))

    k_u, k_q = jr.fold_in(key, _NOISE_U), jr.fold_in(key, _NOISE_Q)
    u = out["force_commanded"] + noise_u * jr.normal(k_u, (n,), f)
    q = out["q_meas"] + noise_q * jr.normal(k_q, (n,), f)
    F_act, friction, external, position, fc = out["forces"].T
    return {
        "q": q,
        "u": u,
        "r": r,
        "q_motor": out["q_true"],
        "v_motor": out["v_motor"],
        "q_load": out["q_load"],
        "v_load": out["v_load"],
        "velocity_estimate": out["velocity_estimate"],
        "force_commanded": out["force_commanded"],
        "force_applied": F_act,
        "friction": friction,
        "external_force": external,
        "position_force": position,
        "coupling_force": fc,
        "load_force": external + position - friction,
    }


def draw_drive_effect(
    key: PRNGKeyArray, effect_label: str, magnitude: str | float = "random"
) -> dict[str, dict[str, float]]:
    """A random, realistic hidden effect for `DriveTwin(effects=...)` from a drive
    effect label.

    Sizes are clearly noticeable but not absurd for the EMPS-like axis (rms motor force
    ≈ 70–100 N; the effect changes `u` by 2–60 N rms): Coulomb friction 8–30 N (LuGre,
    σ0 = 1e5–1e6 N/m), Stribeck excess 10–35 N, asymmetric levels differing by 8–25 N,
    backlash b = 20–200 µm with k = 1e7–5e7 N/m, a resonance at 20–80 Hz with ζ =
    0.02–0.1, a delay of 1–3.5 ms, 3–8 external pulses of 10–50 N, a cogging ripple of
    5–30 N with pitch 5–40 mm plus a pull of up to 20 N.

    Heuristic ranges: a transport delay beyond ≈ 4.5 ms makes the EMPS loop unstable, a
    resonance above ≈ 80 Hz barely shows in the force (< 2 N rms), and a contact stiffness
    above ≈ 5e7 N/m needs more than the default 10 substeps per sample to resolve impacts.

    **Arguments:**

    - `key`: PRNG key.
    - `effect_label`: one of `DRIVE_EFFECT_LABELS` (`coulomb_friction`,
        `asymmetric_friction`, `stribeck_friction`, `backlash`, `resonance`, `time_delay`,
        `external_force`, `position_dependence`).
    - `magnitude`: `"random"` (uniform in the range), or a number in `[0, 1]` placing
        the effect's size parameter in its range (0 = smallest, 1 = largest); the other
        parameters are still random.

    **Returns:**

    A dict `{effect: {parameter: value}}` for the `effects=` argument of `DriveTwin`.
    """
    if effect_label not in DRIVE_EFFECT_LABELS:
        raise ValueError(
            f"Unknown drive effect label {effect_label!r}; use one of {DRIVE_EFFECT_LABELS}."
        )
    keys = jr.split(key, 8)
    u = [float(v) for v in jr.uniform(keys[0], (8,))]
    if magnitude == "random":
        s = float(jr.uniform(keys[1], ()))
    elif isinstance(magnitude, int | float) and 0 <= magnitude <= 1:
        s = float(magnitude)
    else:
        raise ValueError(f"magnitude must be 'random' or a number in [0, 1], got {magnitude!r}.")

    def lin(lo, hi, x):
        return lo + (hi - lo) * x

    def log(lo, hi, x):
        return float(math.exp(lin(math.log(lo), math.log(hi), x)))

    sign = 1.0 if u[7] < 0.5 else -1.0
    if effect_label == "coulomb_friction":
        return {
            "lugre": dict(
                Fc=lin(8.0, 30.0, s), sigma0=log(1e5, 1e6, u[0]), sigma1=lin(100.0, 400.0, u[1])
            )
        }
    if effect_label == "stribeck_friction":
        Fc = lin(5.0, 15.0, u[2])
        return {
            "lugre": dict(
                Fc=Fc,
                Fs=Fc + lin(10.0, 35.0, s),
                vs=lin(0.005, 0.03, u[3]),
                sigma0=log(1e5, 1e6, u[0]),
                sigma1=lin(100.0, 400.0, u[1]),
            )
        }
    if effect_label == "asymmetric_friction":
        # A clear direction difference: the levels differ by 8–25 N, the viscous friction
        # by 20–60 N·s/m with the opposite sign.
        base = lin(5.0, 15.0, u[2])
        diff = lin(8.0, 25.0, s)
        dfv = lin(20.0, 60.0, u[3])
        Fc_pos, Fc_neg = (base + diff, base) if sign > 0 else (base, base + diff)
        return {
            "asymmetric": dict(
                Fc_pos=Fc_pos,
                Fc_neg=Fc_neg,
                dFv_pos=-sign * dfv / 2,
                dFv_neg=sign * dfv / 2,
                sigma0=log(1e5, 1e6, u[0]),
                sigma1=lin(100.0, 400.0, u[1]),
            )
        }
    if effect_label == "backlash":
        return {"backlash": dict(b=log(20e-6, 200e-6, s), k=log(1e7, 5e7, u[0]))}
    if effect_label == "resonance":
        # Lower frequency = larger effect on the force.
        return {"resonance": dict(f_r=log(80.0, 20.0, s), zeta_r=lin(0.02, 0.1, u[0]))}
    if effect_label == "time_delay":
        return {"time_delay": dict(tau=lin(1e-3, 3.5e-3, s))}
    if effect_label == "external_force":
        return {
            "external_force": dict(
                amplitude=lin(10.0, 50.0, s),
                n_pulses=3 + int(u[0] * 6),
                width=lin(0.15, 1.0, u[1]),
                rise=lin(0.005, 0.03, u[2]),
            )
        }
    # position_dependence
    return {
        "position_dependence": dict(
            amplitude=lin(5.0, 30.0, s),
            pitch=lin(5e-3, 40e-3, u[0]),
            phase=lin(0, 2 * math.pi, u[1]),
            spring=lin(0.0, 20.0, u[2]) * sign,
            center=lin(0.05, 0.15, u[3]),
            length=lin(0.03, 0.1, u[4]),
        )
    }
