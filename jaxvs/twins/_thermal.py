"""Spindle thermal twin: a lumped thermal network of a motor spindle with switchable effects.

The plant behind the thermal virtual-sensor study (/work/shared/seeds/000, Dementjev et
al. 2014, Fig. 3 and Table 1): a motor spindle whose bearing chassis is water cooled. The
target, the inner bearing ring temperature `T_bearing` (T_bearing,i), cannot be measured
while the spindle turns; the chassis temperature `T_chassis` and the motor speed `v_m`
can.

Network (conductances G [W/K], capacities C [J/K]):

```
                 P_b(n) bearing friction
                      │
 T_water ──G_bw── [ bearing, inner ring ] ──G_ba── T_air        (T_bearing)
                      │ G_bc
 T_water ──G_cw── [ chassis, C_c ] ──G_ca── T_air               (T_chassis)
                      │ G_mc
 T_water ──G_cmw─ [ motor chassis, C_cm ] ──G_cma── T_air       (T_chassis_m)
                      │ G_mcm
                  [ motor, C_m ] ← P_m(n) motor losses          (T_motor)
```

plus two read-out nodes heated by the bearing: the spindle flange (`T_flange`) and the
spindle shaft (`T_axis`, the study's second target). The outer bearing ring
(`T_bearing_o`) sits quasi-statically between chassis and inner ring.

**Nominal plant (every effect off).** The inner-ring node has no heat capacity, the
bearing friction is linear in speed, `P_b = P_ref · n / n_ref`, and the air and water
temperatures are constant apart from sensor noise. Its balance is then algebraic,

    T_bearing = (G_bc T_chassis + G_bw T_water + G_ba T_air + P_b(n)) / (G_bc + G_bw + G_ba),

i.e. exactly the study's static linear regression on `(T_chassis, v_m)` (eq. 2-3), up to
the 0.1 K sensor noise.

**Effects** (names as docs/guides/contracts.md; magnitudes in physical units):

- `dynamics`, magnitude `τ` [s] (realistic 120-1800): the inner ring / shaft node gets
  a heat capacity `C_b = τ (G_bc + G_bw + G_ba)`, so the target lags its static value
  with the time constant `τ`.
- `ambient_temperature`, drift amplitude [K] (realistic 1-4): `T_air` drifts slowly
  (periods 2-12 h) and drops at door openings (recovering in about 15 min); it reaches
  the target directly through `G_ba`, the chassis only slowly.
- `coolant_temperature`, half peak-to-peak [K] (realistic 0.5-2): `T_water` cycles with
  the chiller's hysteresis (a triangle wave, period 5-20 min); it reaches the target
  directly through the bearing's cooling jacket `G_bw`, the chassis only through its
  large heat capacity.
- `speed_nonlinearity`, exponent `α` [-] (realistic 1.4-2.0): Palmgren-like friction heat
  `P_b = P_ref (n / n_ref)^α` instead of linear in speed.

The simulation is the exact (zero-order-hold) discretisation of the linear network on the
sampling grid, run by one `lax.scan`; speed parts change on grid points. Everything is a
pure function of the twin's parameters and a PRNG key, so `jax.vmap` over keys (or over
twins) gives many experiments in one call.
"""

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._misc import expm
from ..data import Record

__all__ = [
    "THERMAL_TWIN_EFFECTS",
    "SparseTarget",
    "SpindleThermalTwin",
    "draw_thermal_effect",
    "thermal_speed_profile",
]

THERMAL_TWIN_EFFECTS: tuple[str, ...] = (
    "dynamics",
    "ambient_temperature",
    "coolant_temperature",
    "speed_nonlinearity",
)

# Physical range of each effect's magnitude (accepted by the twin), the "noticeable" range
# from which `draw_thermal_effect` draws, and the typical value. Units: dynamics τ [s],
# ambient drift amplitude [K], coolant half peak-to-peak [K], speed exponent α [-].
_EFFECT_RANGE = {
    "dynamics": (0.0, 7200.0),
    "ambient_temperature": (0.0, 10.0),
    "coolant_temperature": (0.0, 5.0),
    "speed_nonlinearity": (1.0, 3.0),
}
_NOTICEABLE = {
    "dynamics": (120.0, 1800.0),
    "ambient_temperature": (2.0, 4.0),
    "coolant_temperature": (1.0, 2.0),
    "speed_nonlinearity": (1.4, 2.0),
}
TYPICAL_THERMAL_EFFECTS: dict[str, float] = {
    "dynamics": 600.0,
    "ambient_temperature": 3.0,
    "coolant_temperature": 1.5,
    "speed_nonlinearity": 1.7,
}

# Column order: the study's Table 1 (measurable) then Table 2 (targets).
_COLUMNS = (
    "T_air",
    "T_chassis",
    "T_water",
    "T_bearing_o",
    "T_flange",
    "T_motor",
    "T_chassis_m",
    "preload_force",
    "bending_moment",
    "motor_moment",
    "v_m",
    "T_bearing",
    "T_axis",
)
_UNITS = {
    "T_air": "degC",
    "T_chassis": "degC",
    "T_water": "degC",
    "T_bearing_o": "degC",
    "T_flange": "degC",
    "T_motor": "degC",
    "T_chassis_m": "degC",
    "preload_force": "N",
    "bending_moment": "N m",
    "motor_moment": "N m",
    "v_m": "rpm",
    "T_bearing": "degC",
    "T_axis": "degC",
}
_TEMPERATURES = tuple(c for c in _COLUMNS if c.startswith("T_"))

# Speed profiles: parts of 20-120 min, levels 0-8000 rpm, consecutive levels at least
# 1000 rpm apart (an operating-point change at every part boundary).
_PART_MIN, _PART_MAX = 1200.0, 7200.0
_SPEED_MAX = 8000.0
_SPEED_STEP = 50.0
# The study's five experiment parts (Table 3): 2000, 5000, 500, 500, 2000 rpm.
STUDY_PARTS: tuple[float, ...] = (2000.0, 5000.0, 500.0, 500.0, 2000.0)


class SparseTarget(NamedTuple):
    """Target samples taken during short spindle stops (non-uniform in time).

    - `t`: `(sample,)` sample times [s], on the record's grid.
    - `T_bearing`: `(sample,)` inner bearing temperature [°C] (0.1 K sensor noise, plus
      outliers if asked for).
    - `T_axis`: `(sample,)` spindle axis temperature [°C].
    - `outlier`: `(sample,)` bool, which samples were corrupted (ground truth for tests).
    """

    t: np.ndarray
    T_bearing: np.ndarray
    T_axis: np.ndarray
    outlier: np.ndarray


def _effects_dict(effects: Mapping[str, Any] | None) -> dict[str, float]:
    if effects is None:
        return {}
    if not isinstance(effects, Mapping):
        raise TypeError(
            "SpindleThermalTwin: effects must be a dict effect -> magnitude, e.g. "
            f"{{'dynamics': 600.0}}; got {type(effects).__name__}."
        )
    out = {}
    for name, value in effects.items():
        if name not in THERMAL_TWIN_EFFECTS:
            raise ValueError(
                f"SpindleThermalTwin: unknown effect {name!r}; the effects are "
                f"{', '.join(THERMAL_TWIN_EFFECTS)}."
            )
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise TypeError(
                f"SpindleThermalTwin: the magnitude of {name!r} must be a number, got {value!r}."
            ) from None
        lo, hi = _EFFECT_RANGE[name]
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ValueError(
                f"SpindleThermalTwin: magnitude {value!r} of {name!r} is outside its physical "
                f"range [{lo}, {hi}] ({_effect_unit(name)}); typical: "
                f"{TYPICAL_THERMAL_EFFECTS[name]}."
            )
        out[name] = value
    return out


def _effect_unit(name: str) -> str:
    return {
        "dynamics": "time constant τ in s",
        "ambient_temperature": "air drift amplitude in K",
        "coolant_temperature": "water cycling half peak-to-peak in K",
        "speed_nonlinearity": "friction-heat exponent α, 1 = linear",
    }[name]


def draw_thermal_effect(key: PRNGKeyArray, label: str | None) -> dict[str, float]:
    """An effects dict with one effect of noticeable size, for blind benchmarks.

    **Arguments:**

    - `key`: PRNG key.
    - `label`: one of [`THERMAL_TWIN_EFFECTS`][], or `None` / `"none"` for the nominal
      plant (returns `{}`).

    **Returns:**

    `{label: magnitude}` with the magnitude drawn uniformly (log-uniformly for `dynamics`)
    from the range where the effect is clearly visible against 0.1 K sensor noise:
    `dynamics` τ 120-1800 s, `ambient_temperature` 1.5-4 K, `coolant_temperature`
    1-2 K, `speed_nonlinearity` α 1.4-2.0.
    """
    if label is None or label == "none":
        return {}
    if label not in THERMAL_TWIN_EFFECTS:
        raise ValueError(
            f"draw_thermal_effect: unknown effect {label!r}; choose one of "
            f"{', '.join(THERMAL_TWIN_EFFECTS)} or None."
        )
    lo, hi = _NOTICEABLE[label]
    u = float(jr.uniform(key, ()))
    if label == "dynamics":
        value = math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
    else:
        value = lo + u * (hi - lo)
    return {label: value}


def thermal_speed_profile(
    key: PRNGKeyArray, n: int, dt: float, parts: Any = None, part_duration: Any = None
) -> tuple[Float[Array, " time"], Float[Array, " time"]]:
    """Piecewise-constant motor speed on the grid `k·dt`, `k < n`.

    **Arguments:**

    - `key`: PRNG key (used when `parts` is `None`).
    - `n`: number of samples; `dt`: sampling period [s].
    - `parts`: `None` (random parts: 20-120 min, 0-8000 rpm, consecutive levels at least
      1000 rpm apart) or a sequence of speeds [rpm], one per part.
    - `part_duration`: with `parts`: duration of each part [s] (a scalar or one per part,
      rounded to the grid); `None` splits the record evenly.

    **Returns:**

    `(speed, part_index)`: speed [rpm] and the index of the part of every sample.
    """
    k = jnp.arange(n)
    if parts is None:
        max_parts = int(math.ceil(n * dt / _PART_MIN)) + 1
        # one random draw for the whole profile (each jr call compiles its own threefry)
        r = jr.uniform(key, (2 * max_parts,))
        dur = _PART_MIN + (_PART_MAX - _PART_MIN) * r[:max_parts]
        dur = jnp.maximum(jnp.round(dur / dt), 1.0)
        first = _SPEED_MAX * r[max_parts]
        jumps = 1000.0 + (_SPEED_MAX - 2000.0) * r[max_parts + 1 :]
        levels = jnp.mod(first + jnp.concatenate([jnp.zeros(1), jnp.cumsum(jumps)]), _SPEED_MAX)
        levels = jnp.round(levels / _SPEED_STEP) * _SPEED_STEP
    else:
        levels = jnp.asarray(np.asarray(parts, float))
        m = levels.shape[0]
        if part_duration is None:
            dur = jnp.full((m,), float(n) / m)
        else:
            dur = jnp.broadcast_to(jnp.asarray(part_duration, float) / dt, (m,))
        dur = jnp.maximum(jnp.round(dur), 1.0)
    ends = jnp.cumsum(dur)
    index = jnp.minimum(
        jnp.searchsorted(ends, k, side="right", method="compare_all"), levels.shape[0] - 1
    )
    return levels[index], index


def _triangle(phase: Array, duty: Array) -> Array:
    """Triangle wave in [-1, 1]: rising for a fraction `duty` of each period."""
    s = jnp.mod(phase, 1.0)
    return jnp.where(s < duty, -1.0 + 2.0 * s / duty, 1.0 - 2.0 * (s - duty) / (1.0 - duty))


# The default physical parameters of `SpindleThermalTwin` (units in its docstring).
_NOMINAL: dict[str, Any] = dict(
    T_air0=21.0,
    T_water0=20.0,
    P_bearing=320.0,
    n_ref=5000.0,
    G_bc=5.0,
    G_bw=8.0,
    G_ba=7.0,
    C_chassis=1.2e5,
    G_cw=40.0,
    G_ca=6.0,
    P_motor=(30.0, 150.0, 100.0),
    C_motor=2.0e4,
    G_mcm=25.0,
    C_chassis_m=6.0e4,
    G_cmw=20.0,
    G_cma=5.0,
    G_mc=5.0,
    C_flange=2.0e4,
    G_fc=8.0,
    G_fa=3.0,
    G_fb=4.0,
    C_shaft=3.0e4,
    G_sb=15.0,
    G_sa=3.0,
    G_sm=5.0,
)


class SpindleThermalTwin(eqx.Module):
    """Lumped thermal network of a water-cooled motor spindle with switchable effects.

    **Arguments:**

    - `effects`: dict effect -> magnitude (see the module docstring and
      [`THERMAL_TWIN_EFFECTS`][]); `{}` or `None` is the nominal plant, for which the
      study's static linear regression of `T_bearing` on `(T_chassis, v_m)` is exact up
      to sensor noise. Units: `dynamics` τ [s], `ambient_temperature` drift amplitude [K],
      `coolant_temperature` chiller half peak-to-peak [K], `speed_nonlinearity` exponent
      α [-] (1 = off).
    - `T_air0`, `T_water0`: mean air and cooling-water temperatures [°C].
    - `P_bearing`: bearing friction heat at `n_ref` [W]; `n_ref`: reference speed [rpm].
    - `G_bc`, `G_bw`, `G_ba`: conductances of the inner-ring node to chassis, cooling
      jacket and air (through the shaft) [W/K].
    - `C_chassis`, `G_cw`, `G_ca`: chassis heat capacity [J/K] and its conductances to
      water and air [W/K].
    - `P_motor`: motor losses `(P0, P1, P2)` [W]: `P_m = P0 + P1 (n/n_ref) + P2 (n/n_ref)²`.
    - `C_motor`, `G_mcm`: motor heat capacity [J/K], motor-to-motor-chassis conductance.
    - `C_chassis_m`, `G_cmw`, `G_cma`, `G_mc`: motor-chassis capacity and conductances to
      water, air and the spindle chassis.
    - `C_flange`, `G_fc`, `G_fa`, `G_fb`: flange capacity and conductances to chassis,
      air and bearing.
    - `C_shaft`, `G_sb`, `G_sa`, `G_sm`: shaft capacity and conductances to bearing, air
      and motor.

    The defaults give, at 5000 rpm, about 17 K of inner-ring and 4 K of chassis
    temperature rise, a chassis time constant of about 30 min and a motor time constant of
    about 15 min.
    """

    T_air0: Float[Array, ""]
    T_water0: Float[Array, ""]
    P_bearing: Float[Array, ""]
    G_bc: Float[Array, ""]
    G_bw: Float[Array, ""]
    G_ba: Float[Array, ""]
    C_chassis: Float[Array, ""]
    G_cw: Float[Array, ""]
    G_ca: Float[Array, ""]
    P_motor: Float[Array, "3"]
    C_motor: Float[Array, ""]
    G_mcm: Float[Array, ""]
    C_chassis_m: Float[Array, ""]
    G_cmw: Float[Array, ""]
    G_cma: Float[Array, ""]
    G_mc: Float[Array, ""]
    C_flange: Float[Array, ""]
    G_fc: Float[Array, ""]
    G_fa: Float[Array, ""]
    G_fb: Float[Array, ""]
    C_shaft: Float[Array, ""]
    G_sb: Float[Array, ""]
    G_sa: Float[Array, ""]
    G_sm: Float[Array, ""]
    # effect magnitudes (0 / 1 = off); arrays so that twins can be vmapped over them
    tau: Float[Array, ""]
    ambient_amplitude: Float[Array, ""]
    coolant_amplitude: Float[Array, ""]
    alpha: Float[Array, ""]
    n_ref: float = eqx.field(static=True)

    def __init__(self, effects: Mapping[str, float] | None = None, **parameters: ArrayLike):
        # The physical parameters are keywords with the defaults of `_NOMINAL` (the class
        # docstring lists them); an unknown name is refused.
        unknown = sorted(set(parameters) - set(_NOMINAL))
        if unknown:
            raise TypeError(
                f"SpindleThermalTwin: unknown parameter(s) {unknown}; the parameters are "
                f"{sorted(_NOMINAL)}."
            )
        p = {**_NOMINAL, **parameters}
        eff = _effects_dict(effects)
        f = jnp.result_type(float)
        P_motor, n_ref = p.pop("P_motor"), p.pop("n_ref")
        for name, value in p.items():
            v = jnp.asarray(value, f)
            if v.shape != ():
                raise ValueError(f"SpindleThermalTwin: {name} must be a scalar, got {v.shape}.")
            if not name.startswith("T_") and not isinstance(v, jax.core.Tracer):
                if not bool(v > 0):
                    raise ValueError(
                        f"SpindleThermalTwin: {name} must be positive (a heat capacity, "
                        f"conductance or power); got {value!r}."
                    )
            setattr(self, name, v)
        self.P_motor = jnp.asarray(P_motor, f)
        if self.P_motor.shape != (3,):
            raise ValueError(
                f"SpindleThermalTwin: P_motor must be (P0, P1, P2) [W], got {self.P_motor.shape}."
            )
        self.n_ref = float(n_ref)
        self.tau = jnp.asarray(eff.get("dynamics", 0.0), f)
        self.ambient_amplitude = jnp.asarray(eff.get("ambient_temperature", 0.0), f)
        self.coolant_amplitude = jnp.asarray(eff.get("coolant_temperature", 0.0), f)
        self.alpha = jnp.asarray(eff.get("speed_nonlinearity", 1.0), f)

    @property
    def effects(self) -> dict[str, float]:
        """The switched-on effects and their magnitudes (concrete twins only)."""
        values = {
            "dynamics": (self.tau, 0.0),
            "ambient_temperature": (self.ambient_amplitude, 0.0),
            "coolant_temperature": (self.coolant_amplitude, 0.0),
            "speed_nonlinearity": (self.alpha, 1.0),
        }
        return {k: float(v) for k, (v, off) in values.items() if float(v) != off}

    # ------------------------------------------------------------------ physics

    def bearing_heat(self, speed: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """Bearing friction heat [W] at motor speed `speed` [rpm]: `P_ref (|n|/n_ref)^α`."""
        x = jnp.abs(jnp.asarray(speed, self.P_bearing.dtype)) / self.n_ref
        # x^α with a safe gradient at x = 0
        safe = jnp.where(x > 0, x, 1.0)
        return jnp.where(x > 0, self.P_bearing * safe**self.alpha, 0.0)

    def motor_heat(self, speed: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """Motor losses [W] at motor speed `speed` [rpm] (iron/copper losses, quadratic)."""
        x = jnp.abs(jnp.asarray(speed, self.P_bearing.dtype)) / self.n_ref
        return self.P_motor[0] + self.P_motor[1] * x + self.P_motor[2] * x**2

    def _bearing_weights(self) -> tuple[Array, Array, Array, Array]:
        g = self.G_bc + self.G_bw + self.G_ba
        return self.G_bc / g, self.G_bw / g, self.G_ba / g, g

    def static_bearing_temperature(self, T_chassis, T_water, T_air, speed) -> Array:
        """The inner-ring temperature without heat capacity [°C] (the nominal law)."""
        wc, ww, wa, g = self._bearing_weights()
        return wc * T_chassis + ww * T_water + wa * T_air + self.bearing_heat(speed) / g

    def _network(self) -> tuple[Array, Array]:
        """`dx/dt = A x + B u`, x = [T_c, T_m, T_cm, T_f, T_s, T_bf], u = [T_a, T_w, P_b, P_m]."""
        wc, ww, wa, g = self._bearing_weights()
        z = jnp.zeros((), self.G_bc.dtype)
        # The static inner ring T_b = wc T_c + ww T_w + wa T_a + P_b / g enters the chassis,
        # flange and shaft balances through G_bc, G_fb, G_sb: its row over x and over u.
        tb_x = [wc, z, z, z, z, z]
        tb_u = [wa, ww, 1.0 / g, z]

        def row(c, x_terms, u_terms, g_b):
            """One node's balance divided by its capacity: own terms + g_b · T_b."""
            xr = [(x_terms.get(i, z) + g_b * tb_x[i]) / c for i in range(6)]
            ur = [(u_terms.get(i, z) + g_b * tb_u[i]) / c for i in range(4)]
            return xr, ur

        c, cm, cf, cs = self.C_chassis, self.C_chassis_m, self.C_flange, self.C_shaft
        rows = [
            # chassis: water, air, motor chassis, heat from the bearing
            row(
                c,
                {0: -(self.G_cw + self.G_ca + self.G_mc + self.G_bc), 2: self.G_mc},
                {0: self.G_ca, 1: self.G_cw},
                self.G_bc,
            ),
            # motor, heated by its losses
            row(self.C_motor, {1: -self.G_mcm, 2: self.G_mcm}, {3: jnp.ones_like(z)}, z),
            # motor chassis
            row(
                cm,
                {
                    2: -(self.G_mcm + self.G_cmw + self.G_cma + self.G_mc),
                    1: self.G_mcm,
                    0: self.G_mc,
                },
                {0: self.G_cma, 1: self.G_cmw},
                z,
            ),
            # flange (read-out node)
            row(
                cf,
                {3: -(self.G_fc + self.G_fa + self.G_fb), 0: self.G_fc},
                {0: self.G_fa},
                self.G_fb,
            ),
            # shaft (read-out node, the study's T_axis)
            row(
                cs,
                {4: -(self.G_sb + self.G_sa + self.G_sm), 1: self.G_sm},
                {0: self.G_sa},
                self.G_sb,
            ),
        ]
        # inner ring with heat capacity (the `dynamics` effect): a first-order lag τ of the
        # static value. With τ = 0 the state is a dummy (τ = 1 s) and the static value is
        # read out instead.
        tau = jnp.where(self.tau > 0, self.tau, 1.0)
        rows.append(row(tau, {5: -jnp.ones_like(z)}, {}, jnp.ones_like(z)))
        A = jnp.stack([jnp.stack(xr) for xr, _ in rows])
        B = jnp.stack([jnp.stack(ur) for _, ur in rows])
        return A, B

    def _discretise(self, dt: float) -> tuple[Array, Array]:
        """Exact ZOH discretisation: `expm([[A, B], [0, 0]] dt)`."""
        A, B = self._network()
        n, m = B.shape
        M = jnp.zeros((n + m, n + m), A.dtype).at[:n, :n].set(A).at[:n, n:].set(B)
        E = expm(M * dt)
        return E[:n, :n], E[:n, n:]

    def boundary_temperatures(
        self, key: PRNGKeyArray, t: Float[Array, " time"]
    ) -> tuple[Float[Array, " time"], Float[Array, " time"]]:
        """True air and water temperatures [°C] at times `t` [s] (no sensor noise).

        Air: `T_air0` plus, with `ambient_temperature = D`, a slow drift (three sinusoids
        with periods 2-12 h, scaled to peak `D`) and door openings (one per 3 h on average,
        a drop of `0.5 D` recovering with a 15 min time constant). Water: `T_water0` plus,
        with `coolant_temperature = A`, a chiller hysteresis triangle of half
        peak-to-peak `A`, period 5-20 min, asymmetric heating/cooling.
        """
        f = self.T_air0.dtype
        r = jr.uniform(key, (12 + 2 * 32,), f)  # one draw (one threefry) for everything
        lerp = lambda x, lo, hi: lo + (hi - lo) * x
        hours = 3600.0
        periods = lerp(r[0:3], 2 * hours, 12 * hours)
        phases = lerp(r[3:6], 0.0, 2 * jnp.pi)
        weights = lerp(r[6:9], 0.5, 1.0)
        drift = jnp.sum(weights * jnp.sin(2 * jnp.pi * t[:, None] / periods + phases), axis=1)
        drift = drift / jnp.maximum(jnp.max(jnp.abs(drift)), 1e-12)
        # door openings: up to 32 events, Poisson-like count from uniform times
        span = t[-1] - t[0] + (t[1] - t[0])
        n_max = 32
        times = t[0] + r[12 : 12 + n_max] * span
        # each of the n_max slots opens the door with probability rate/n_max (binomial,
        # close to Poisson with mean `rate`, and cheaper to compile than jr.poisson)
        rate = span / (3 * hours)
        active = r[12 + n_max : 12 + 2 * n_max] < jnp.minimum(rate / n_max, 1.0)
        dt_ev = t[:, None] - times[None, :]
        doors = jnp.where(
            (dt_ev >= 0) & active[None, :], jnp.exp(-jnp.maximum(dt_ev, 0.0) / 900.0), 0.0
        )
        doors = -0.5 * jnp.minimum(jnp.sum(doors, axis=1), 1.5)
        T_air = self.T_air0 + self.ambient_amplitude * (drift + doors)
        period, duty, phase0 = lerp(r[9], 300.0, 1200.0), lerp(r[10], 0.3, 0.7), r[11]
        T_water = self.T_water0 + self.coolant_amplitude * _triangle(t / period + phase0, duty)
        return T_air, T_water

    # ------------------------------------------------------------------ simulation

    def simulate(
        self,
        key: PRNGKeyArray,
        speed: Float[ArrayLike, " time"],
        dt: float = 5.0,
        noise: float = 0.1,
    ) -> dict[str, Array]:
        """All signals for a given speed profile (pure, jittable, vmappable over keys).

        **Arguments:**

        - `key`: PRNG key for boundary temperatures and sensor noise.
        - `speed`: `(time,)` motor speed [rpm] on the grid `k·dt` (held over each step).
        - `dt`: sampling period [s].
        - `noise`: temperature sensor noise, standard deviation [K] (force and moments get
          their own: 25 N, 5 %).

        **Returns:**

        A dict of `(time,)` arrays: the columns of [`SpindleThermalTwin.experiment`][]
        plus `"t"` and the noiseless targets `"T_bearing_true"`, `"T_axis_true"`.
        """
        speed = jnp.asarray(speed, self.P_bearing.dtype)
        if speed.ndim != 1 or speed.shape[0] < 2:
            raise ValueError(
                f"SpindleThermalTwin.simulate: speed must be a 1-D profile of at least 2 "
                f"samples [rpm]; got shape {speed.shape}."
            )
        return _simulate(self, key, speed, float(dt), jnp.asarray(noise, speed.dtype))

    def _simulate(self, key, speed, dt, noise):
        n = speed.shape[0]
        t = jnp.arange(n, dtype=speed.dtype) * dt
        k_bound, k_noise = jr.split(key)
        T_air, T_water = self.boundary_temperatures(k_bound, t)
        P_b = self.bearing_heat(speed)
        P_m = self.motor_heat(speed)
        u = jnp.stack([T_air, T_water, P_b, P_m], axis=1)
        A, B = self._network()
        # cold start: steady state with the spindle at rest and the initial boundaries
        u0 = jnp.stack([T_air[0], T_water[0], self.bearing_heat(0.0), self.motor_heat(0.0)])
        x0 = -jnp.linalg.solve(A, B @ u0)
        Ad, Bd = self._discretise(dt)

        def step(x, uk):
            return Ad @ x + Bd @ uk, x

        _, xs = jax.lax.scan(step, x0, u)
        T_c, T_m, T_cm, T_f, T_s, T_bf = (xs[:, i] for i in range(6))
        T_bs = self.static_bearing_temperature(T_c, T_water, T_air, speed)
        T_b = jnp.where(self.tau > 0, T_bf, T_bs)
        # outer ring: between chassis and inner ring
        T_bo = T_c + 0.35 * (T_b - T_c)
        # preload grows with the shaft's expansion against the housing [N]
        preload = 1800.0 + 45.0 * (T_s - T_c)
        bending = 6.0 + 4.0e-4 * speed + 0.05 * (T_s - T_c)
        motor_moment = (
            0.4 * (speed > 0)
            + 1.2e-4 * speed
            + (P_b / (2 * jnp.pi / 60.0)) / (jnp.maximum(speed, 1.0)) * (speed > 0)
        )
        e = jr.normal(k_noise, (12, n), speed.dtype)  # one draw for all sensors
        clean = {
            "T_air": T_air,
            "T_chassis": T_c,
            "T_water": T_water,
            "T_bearing_o": T_bo,
            "T_flange": T_f,
            "T_motor": T_m,
            "T_chassis_m": T_cm,
            "T_bearing": T_b,
            "T_axis": T_s,
        }
        out = {"t": t}
        for i, (name, value) in enumerate(clean.items()):
            out[name] = value + noise * e[i]
        out["preload_force"] = preload + 25.0 * e[9]
        out["bending_moment"] = bending * (1 + 0.05 * e[10])
        out["motor_moment"] = motor_moment * (1 + 0.05 * e[11])
        out["v_m"] = speed
        out["T_bearing_true"] = T_b
        out["T_axis_true"] = T_s
        return out

    def experiment(
        self,
        key: PRNGKeyArray,
        parts: Sequence[float] | None = None,
        part_duration: float | Sequence[float] | None = None,
        *,
        duration: float | None = None,
        dt: float = 5.0,
        noise: float = 0.1,
    ) -> Record:
        """One experiment as a `jaxvs.data.Record` on the uniform `dt` grid.

        **Arguments:**

        - `key`: PRNG key (speed profile, boundary temperatures, sensor noise).
        - `parts`: speeds [rpm], one per experiment part (e.g. the study's
          `STUDY_PARTS = (2000, 5000, 500, 500, 2000)`), or `None` for random parts of
          20-120 min at 0-8000 rpm with an operating-point change at every boundary.
        - `part_duration`: duration of each part [s], scalar or one per part (default 1 h
          for given parts).
        - `duration`: total length [s] (default: the sum of the part durations for given
          parts, 12 h for random parts). 35 h at 5 s (25 200 samples) takes well under
          a second after compilation.
        - `dt`: sampling period [s] (the study: 5 s); `noise`: temperature sensor noise [K].

        **Returns:**

        A `Record` with the columns `T_air, T_chassis, T_water, T_bearing_o, T_flange,
        T_motor, T_chassis_m` [°C], `preload_force` [N], `bending_moment`,
        `motor_moment` [N m], `v_m` [rpm] (study Table 1) and the targets `T_bearing`
        (inner ring, T_bearing,i) and `T_axis` [°C] (Table 2), all with sensor noise. The
        metadata hold the part boundaries and speeds, never the effects.
        """
        n, dt, parts_arg, dur_arg = self._plan(parts, part_duration, duration, dt, noise)
        out = _experiment_arrays(self, key, n, dt, float(noise), parts_arg, dur_arg)
        return _to_record({k: np.asarray(v) for k, v in out.items()}, dt)

    def _plan(self, parts, part_duration, duration, dt, noise):
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"experiment: dt must be a positive sampling period [s], got {dt}.")
        if noise < 0:
            raise ValueError(f"experiment: noise must be >= 0 [K], got {noise}.")
        if parts is not None:
            parts_np = np.atleast_1d(np.asarray(parts, float))
            if parts_np.ndim != 1 or parts_np.size == 0:
                raise ValueError("experiment: parts must be a non-empty sequence of speeds [rpm].")
            if np.any(parts_np < 0) or not np.all(np.isfinite(parts_np)):
                raise ValueError(f"experiment: part speeds must be finite and >= 0 rpm: {parts}.")
            if part_duration is None:
                part_duration = 3600.0
            durs = np.broadcast_to(np.asarray(part_duration, float), parts_np.shape)
            if np.any(durs < dt):
                raise ValueError(
                    f"experiment: every part must last at least one sample (dt = {dt} s)."
                )
            if duration is None:
                duration = float(np.sum(np.round(durs / dt)) * dt)
            parts_arg = tuple(float(p) for p in parts_np)
            dur_arg = tuple(float(d) for d in durs)
        else:
            if part_duration is not None:
                raise ValueError("experiment: part_duration needs parts=[...] speeds.")
            parts_arg, dur_arg = None, None
            duration = 12 * 3600.0 if duration is None else float(duration)
        n = int(round(duration / dt))
        if n < 2:
            raise ValueError(f"experiment: duration {duration} s gives fewer than 2 samples.")
        return n, dt, parts_arg, dur_arg

    def experiments(
        self,
        keys: PRNGKeyArray,
        parts: Sequence[float] | None = None,
        part_duration: float | Sequence[float] | None = None,
        *,
        duration: float | None = None,
        dt: float = 5.0,
        noise: float = 0.1,
    ) -> list[Record]:
        """Several experiments, simulated in one `vmap`-ped call over `keys` (`(batch,)`
        PRNG keys); the other arguments as for [`SpindleThermalTwin.experiment`][]."""
        keys = jnp.asarray(keys)
        if keys.ndim != 1:
            raise ValueError(f"experiments: keys must be a 1-D batch of keys; got {keys.shape}.")
        n, dt, parts_arg, dur_arg = self._plan(parts, part_duration, duration, dt, noise)
        out = jax.vmap(
            lambda k: _experiment_arrays(self, k, n, dt, float(noise), parts_arg, dur_arg)
        )(keys)
        out = {k: np.asarray(v) for k, v in out.items()}
        return [_to_record({k: v[i] for k, v in out.items()}, dt) for i in range(keys.shape[0])]

    def sparse_target(
        self,
        record: Record,
        key: PRNGKeyArray,
        every: float = 90.0,
        *,
        jitter: float = 15.0,
        outliers: float = 0.0,
        outlier_size: float = 4.0,
    ) -> SparseTarget:
        """Sparse target measurements, as taken by hand during short spindle stops.

        **Arguments:**

        - `record`: an experiment of this twin (its noisy targets are sampled).
        - `key`: PRNG key for the sampling times and outliers.
        - `every`: mean interval between measurements [s] (the study: about 90 s).
        - `jitter`: random deviation of each interval, uniform in ±`jitter` [s]; times are
          rounded to the record's grid.
        - `outliers`: fraction of corrupted samples (a reading error of ±`outlier_size`
          K, e.g. a sensor not yet in contact).

        **Returns:**

        A [`SparseTarget`][] `(t, T_bearing, T_axis, outlier)`.
        """
        if not isinstance(record, Record) or "T_bearing" not in record:
            raise TypeError(
                "sparse_target: give a Record produced by SpindleThermalTwin.experiment."
            )
        if not every > record.dt:
            raise ValueError(f"sparse_target: every = {every} s must exceed dt = {record.dt} s.")
        if not 0 <= jitter < every / 2:
            raise ValueError(f"sparse_target: jitter must lie in [0, every/2); got {jitter}.")
        if not 0 <= outliers < 0.5:
            raise ValueError(f"sparse_target: outliers is a fraction in [0, 0.5); got {outliers}.")
        rng = np.random.default_rng(np.asarray(jr.key_data(key)).ravel())
        span = record.t[-1] - record.t[0]
        m = int(span // every) + 2
        times = np.cumsum(every + rng.uniform(-jitter, jitter, m))
        times = record.t[0] + times - times[0] + rng.uniform(0, every / 2)
        idx = np.unique(np.round((times - record.t[0]) / record.dt).astype(int))
        idx = idx[idx < len(record)]
        y = np.array(record["T_bearing"][idx])
        bad = rng.uniform(size=idx.shape) < outliers
        y[bad] += outlier_size * rng.choice([-1.0, 1.0], size=int(bad.sum()))
        return SparseTarget(
            t=record.t[idx],
            T_bearing=y,
            T_axis=np.array(record["T_axis"][idx]),
            outlier=bad,
        )

    def perturb(self, key: PRNGKeyArray, scale: float = 0.1) -> "SpindleThermalTwin":
        """A copy with every nominal parameter (capacities, conductances, powers) multiplied
        by `exp(scale · N(0, 1))`; the effects and the mean boundary temperatures are kept.
        """
        names = [n for n in self.__dataclass_fields__ if n.startswith(("G_", "C_", "P_"))]
        keys = jr.split(key, len(names))
        new = [
            getattr(self, n) * jnp.exp(scale * jr.normal(k, getattr(self, n).shape))
            for n, k in zip(names, keys)
        ]
        return eqx.tree_at(lambda m: [getattr(m, n) for n in names], self, new)


@eqx.filter_jit
def _simulate(twin, key, speed, dt, noise):
    # one compiled program per (twin structure, length, dt), shared by every caller
    return twin._simulate(key, speed, dt, noise)


@eqx.filter_jit
def _profile(key, n, dt, parts, part_duration):
    return thermal_speed_profile(key, n, dt, parts, part_duration)


def _experiment_arrays(twin, key, n, dt, noise, parts, part_duration):
    k_speed, k_sim = jr.split(key)
    speed, part = _profile(k_speed, n, dt, parts, part_duration)
    out = twin.simulate(k_sim, speed, dt, noise)
    out["part"] = part
    return out


def _to_record(out: dict[str, np.ndarray], dt: float) -> Record:
    part = out["part"]
    starts = np.flatnonzero(np.diff(part, prepend=-1) != 0)
    signals = {c: out[c] for c in _COLUMNS}
    return Record(
        signals,
        dt=dt,
        units=_UNITS,
        metadata={
            "source": "jaxvs.twins.SpindleThermalTwin",
            "part_start_times": starts * dt,
            "part_speeds": out["v_m"][starts],
            "target": "T_bearing",
        },
    )
