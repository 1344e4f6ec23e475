"""The `thermal` family: the study's static regression of the bearing temperature and its
candidate effects.

Nominal model (Dementjev et al. 2014, eq. 2-3): the inner bearing temperature is a static
linear regression on bias-free inputs,

    T_bearing = c0 + c1·(T_chassis − T_chassis,min) + c2·(v_m − v_m,min),

the speed term only when the motor speed `v_m` is recorded. The biases (each input's
minimum) are taken from the calibration experiments and stored in the model as constants,
so validation data are shifted by the same amounts. The temperature inputs are smoothed by
a zero-phase low-pass (option `smoothing_s`, default 60 s) before they enter any model: the
chassis moves with a time constant of tens of minutes, so the filter changes nothing
systematic, but it removes the sensor noise of the inputs, which a lag would otherwise
"explain" by averaging it out (errors in the variables).

Each candidate effect is a differentiable augmentation that equals the nominal model when
its size (or its time constant) is zero:

Augmentations of the predicted `T_bearing` [°C]:

- `dynamics`: the prediction passed through a first-order lag of time constant `τ` (heat
  capacity of the inner ring); exact discretisation for inputs linear between samples,
  started from the measured target.
- `ambient_temperature`: `+ c_a·(T_air − T_air,min)`.
- `coolant_temperature`: `+ c_w·(T_water − T_water,min)`.
- `speed_nonlinearity`: `+ c2·x² + c3·x³`, `x = |v_m| / v_max`: friction heat growing
  faster than linearly with speed (Palmgren: `∝ n^α`, `α ≈ 1.3-2`; reported as the
  equivalent `α`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.signal as ss
from jaxtyping import Array, Float

from .. import models
from ..calibration import fixed, unwrap
from ..data import Record
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
    floored_positive,
    predict,
    scalar,
)
from ._stats import ar1_draws, ar1_noise, quantisation_step

__all__ = ["StaticRegression", "ThermalFamily"]

_INPUTS = ("T_chassis", "v_m", "T_air", "T_water")


def _biases(experiments: Sequence[Experiment], use_speed: bool) -> tuple[float, float]:
    """The study's input biases (eq. 2-3) of the calibration experiments: each input's
    minimum, `T_chassis` [°C] and `v_m` [rpm] (0 without the speed term)."""
    tc = min(float(np.min(e.arrays["T_chassis"])) for e in experiments)
    vm = min(float(np.min(e.arrays["v_m"])) for e in experiments) if use_speed else 0.0
    return tc, vm


class StaticRegression(eqx.Module):
    """The study's static regression (eq. 2-3), `T_bearing` [°C], with the biases folded
    into the intercept: `T_bearing = c0' + c1·T_chassis [+ c2·v_m]`, the library's
    `jaxvs.models.BiasFreeRegression` on the experiment arrays.

    The study's form on bias-free inputs, `c0 + c1·(T_chassis − b_c) + c2·(v_m − b_v)`, is
    the same function with `c0 = c0' + c1·b_c + c2·b_v`; [`ThermalFamily`][] reports it that
    way with the biases of its calibration data. Keeping the biases out of the prediction
    keeps its structure independent of the data (one compilation for every data set).

    **Fields:** `coef` = `(c0' [°C], c1 [-], c2 [K/rpm])`, or `(c0', c1)` when
    `use_speed` is false.
    """

    coef: Float[Array, " k"]
    use_speed: bool = eqx.field(static=True, default=True)

    def __call__(self, d: Mapping[str, Array]) -> Float[Array, " n"]:
        # the library's regression (biases folded into the intercept, see above)
        cols = [d["T_chassis"]] + ([d["v_m"]] if self.use_speed else [])
        slopes = self.coef[1:]
        law = models.BiasFreeRegression(slopes, self.coef[0], jnp.zeros_like(slopes))
        return law(jnp.stack(cols, axis=-1))

    def parameters(self) -> dict[str, float]:
        c = np.asarray(self.coef)
        out = {"intercept": float(c[0]), "c_chassis": float(c[1])}
        if self.use_speed:
            out["c_speed"] = float(c[2])
        return out


# ------------------------------------------------------------------------------ effects


def first_order_lag(
    s: Float[Array, " n"], tau: Float[Array, ""], dt: float, y_init: Float[Array, ""] | None = None
) -> Float[Array, " n"]:
    """First-order lag `τ ẏ + y = s` of a sampled signal, first-order hold: the library's
    `jaxvs.models.FirstOrderLag` (`tau` [s] >= 0, the state `y_init` one sample before
    the first, default `s₀`; `τ = 0` is the identity)."""
    return models.FirstOrderLag(tau, y_init).predict(s, dt)


class Dynamics(AbstractEffect):
    """The bearing temperature lags its static value with a time constant `tau` [s]."""

    name: ClassVar[str] = "dynamics"
    order: ClassVar[int] = 1
    tau: Any  # [s], > 0 when calibrated (log-parametrised); 0 is the nominal model
    dt: float = eqx.field(static=True)

    def apply(self, y, d, nominal):
        # The initial state of the bearing is unknown (a machine rarely starts in
        # equilibrium); it is taken from the measured target at the first sample.
        return first_order_lag(y, jnp.asarray(self.tau), self.dt, d["y"][0])

    def constrained(self):
        return eqx.tree_at(lambda e: e.tau, self, replace_fn=floored_positive)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        tau = scalar(self.tau)
        return check(
            (np.isfinite(tau), "non-finite time constant"),
            (tau >= context.record_dt, f"time constant {tau:.3g} s shorter than one sample"),
            (
                tau <= context.duration,
                f"time constant {tau:.3g} s longer than the record ({context.duration:.3g} s): "
                "not identifiable from it",
            ),
        )

    def parameters(self):
        return {"tau_s": scalar(self.tau)}


class _MeasuredTemperature(AbstractAdditiveEffect):
    """`+ c·(T − bias)` for a measured temperature `T` that reaches the bearing; `bias` is
    the minimum over the calibration data and is never calibrated."""

    signal: eqx.AbstractClassVar[str]
    suffix: eqx.AbstractClassVar[str]
    size: Float[Array, 1]  # [-]
    bias: Any  # [°C]

    def contribution(self, d, nominal):
        return self.size[0] * (d[self.signal] - self.bias)

    def constrained(self):
        return eqx.tree_at(lambda e: e.bias, self, replace_fn=fixed)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        c = scalar(self.size[0])
        return check(
            (np.isfinite(c), "non-finite coefficient"),
            (
                c >= 0.0,
                f"coefficient {c:.3g} < 0: through passive heat paths a temperature acts on "
                "the bearing with a non-negative weight (eliminating the unmeasured nodes of "
                "a conductance network, Kron reduction, keeps every conductance >= 0); a "
                "negative weight stands in for a lag or another missing effect",
            ),
            (
                c <= 1.0,
                f"coefficient {c:.3g}: a passive heat path cannot amplify a temperature change",
            ),
        )

    def parameters(self):
        return {f"c_{self.suffix}": scalar(self.size[0]), f"bias_{self.suffix}": scalar(self.bias)}


class AmbientTemperature(_MeasuredTemperature):
    """`+ c·(T_air − bias)`: the air temperature reaches the bearing through the shaft."""

    name: ClassVar[str] = "ambient_temperature"
    order: ClassVar[int] = 0
    signal: ClassVar[str] = "T_air"
    suffix: ClassVar[str] = "air"


class CoolantTemperature(_MeasuredTemperature):
    """`+ c·(T_water − bias)`: the cooling water reaches the bearing through its jacket."""

    name: ClassVar[str] = "coolant_temperature"
    order: ClassVar[int] = 0
    signal: ClassVar[str] = "T_water"
    suffix: ClassVar[str] = "water"


def equivalent_exponent(c2: float, c3: float) -> float:
    """The exponent `α` of the power law `a·x^α + b·x` closest (least squares on
    `x ∈ [0, 1]`) to `c2·x² + c3·x³`: the Palmgren-like exponent a fitted polynomial
    nonlinearity corresponds to (`nan` when it is zero)."""
    x = np.linspace(0.0, 1.0, 201)
    f = c2 * x**2 + c3 * x**3
    if not np.any(f):
        return float("nan")
    best, alpha = np.inf, float("nan")
    for a in np.linspace(1.02, 4.0, 299):
        phi = np.stack([x**a, x], -1)
        r = f - phi @ np.linalg.lstsq(phi, f, rcond=None)[0]
        if float(r @ r) < best:
            best, alpha = float(r @ r), float(a)
    return alpha


class SpeedNonlinearity(AbstractAdditiveEffect):
    """`+ c2·x² + c3·x³`, `x = |v_m| / v_max`: friction heat growing faster than linearly
    with speed (the nominal model holds the linear term).

    A polynomial rather than a free power law `c·x^α`: linear in its parameters, so the
    calibration cannot run off to `α → ∞` (where `x^α` is an indicator of the top speed
    and its gradient vanishes); on `[0, 1]` it matches `x^α + linear` for `α` in 1.2-3 to
    better than 1 % of the range. The report gives the equivalent `α`."""

    name: ClassVar[str] = "speed_nonlinearity"
    order: ClassVar[int] = 0
    size: Float[Array, 2]  # c2, c3 [K]
    scale: Any  # v_max [rpm] of the calibration data; never calibrated

    def contribution(self, d, nominal):
        x = jnp.abs(d["v_m"]) / self.scale
        return self.size[0] * x**2 + self.size[1] * x**3

    def constrained(self):
        return eqx.tree_at(lambda e: e.scale, self, replace_fn=fixed)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        """Friction heat never falls with speed: with the nominal linear term, the speed
        law `c1·x + c2·x² + c3·x³` (`x = |v|/v_max`) is non-decreasing on [0, 1]."""
        c2, c3 = (float(c) for c in np.asarray(self.size))
        c1 = float(context.nominal.get("c_speed", 0.0)) * scalar(self.scale)
        x = np.linspace(0.0, 1.0, 101)
        slope = c1 + 2 * c2 * x + 3 * c3 * x**2
        tol = 1e-9 * (abs(c1) + abs(c2) + abs(c3))
        return check(
            (np.isfinite(c2) and np.isfinite(c3), "non-finite coefficients"),
            (bool(np.all(slope >= -tol)), "the heat it adds falls with speed somewhere"),
        )

    def parameters(self):
        c2, c3 = (float(c) for c in np.asarray(self.size))
        return {
            "c2": c2,
            "c3": c3,
            "alpha_equivalent": equivalent_exponent(c2, c3),
            "v_max": scalar(self.scale),
        }


# ------------------------------------------------------------------------------ templates


def _min_of(ctx: Context, key: str) -> float:
    return min(float(np.min(e.arrays[key])) for e in ctx.experiments)


def _t_dynamics(ctx: Context) -> list[AbstractEffect]:
    dt = ctx.experiments[0].dt
    # heuristic: time constants from a few samples up to hours, one per decade-ish
    taus = [t for t in (4.0 * dt, 150.0, 900.0, 3600.0) if t >= 2.0 * dt]
    taus = sorted(set(taus))[:4]
    return [Dynamics(jnp.asarray(t), dt) for t in taus]


def _t_ambient(ctx: Context) -> list[AbstractEffect]:
    return [AmbientTemperature(jnp.zeros(1), jnp.asarray(_min_of(ctx, "T_air")))]


def _t_coolant(ctx: Context) -> list[AbstractEffect]:
    return [CoolantTemperature(jnp.zeros(1), jnp.asarray(_min_of(ctx, "T_water")))]


def _t_speed(ctx: Context) -> list[AbstractEffect]:
    vmax = max(float(np.max(np.abs(e.arrays["v_m"]))) for e in ctx.experiments)
    return [SpeedNonlinearity(jnp.zeros(2), jnp.asarray(vmax))]


def _varies(key: str, what: str):
    def check(experiments: Sequence[Experiment]) -> str | None:
        x = np.concatenate([np.asarray(e.arrays[key]) for e in experiments])
        if float(np.ptp(x)) <= 0:
            return f"needs {what}; {key} is constant"
        return None

    return check


def _needs_speed_levels(experiments: Sequence[Experiment]) -> str | None:
    v = np.concatenate([np.abs(np.asarray(e.arrays["v_m"])) for e in experiments])
    vmax = float(np.max(v)) if v.size else 0.0
    if vmax <= 0:
        return "needs the spindle turning; v_m is zero throughout"
    levels = np.unique(np.round(v[v > 0.01 * vmax] / (0.02 * vmax)))
    if levels.size < 3:
        return (
            "needs at least three distinct speeds to separate a nonlinearity from the linear term"
        )
    return None


# ------------------------------------------------------------------------------ family


def _noise_sigma(y: np.ndarray) -> float:
    """White-noise level of a sampled temperature from its second differences:
    `Δ²y = Δ²s + Δ²e` with `var(Δ²e) = 6σ²`; a smooth signal (and a linear drift)
    leaves nothing in `Δ²s`, and the median absolute deviation ignores the few steps at
    speed changes."""
    d2 = np.diff(np.asarray(y, float), 2)
    if d2.size < 8:
        return 0.0
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


def _residual_noise(y: np.ndarray, residual: np.ndarray) -> tuple[float, float]:
    """`(sigma, rho)` of the AR(1) noise in a regression's residual (see
    `ThermalFamily.null_experiments`)."""
    if quantisation_step(y) > 0:
        return min(_noise_sigma(y), float(np.std(residual))), 0.0
    sigma, rho = ar1_noise(residual)
    return min(sigma, float(np.std(residual))), rho


def _smooth(x: np.ndarray, dt: float, smoothing: float) -> np.ndarray:
    """The zero-phase low-pass of a temperature input (cut-off period `smoothing` [s]),
    along the last axis; skipped when the sampling is coarser than a quarter of it."""
    n = x.shape[-1]
    if not (smoothing > 4 * dt and n > 40):
        return x
    sos = ss.butter(2, 1.0 / smoothing, fs=1.0 / dt, output="sos")
    return ss.sosfiltfilt(sos, x, axis=-1, padlen=min(n - 1, int(3 * smoothing / dt)))


class ThermalFamily(AbstractFamily):
    """Inner bearing temperature of a motor spindle from chassis temperature and speed.

    **Options:** `smoothing_s` (zero-phase low-pass of the temperature inputs: cut-off
    period in seconds, default 60; 0 switches it off; skipped when the sampling is
    coarser than a quarter of it), `speed_change_s` (length of the "after a speed change"
    cell of the gap map, default 3600 s).
    """

    name = "thermal"
    required = ("T_chassis", "T_bearing")
    optional = ("v_m", "T_air", "T_water")
    option_keys = ("smoothing_s", "speed_change_s")
    target_label = "bearing temperature T_bearing [°C]"

    def prepare(self, record: Record, name: str) -> Experiment:
        n = len(record)
        if n < 16:
            raise ValueError(
                f"diagnose(thermal): experiment {name!r} has {n} samples; at least 16 are "
                "needed (the study samples every 5 s over hours). Give longer records."
            )
        dt = float(record.dt)
        smoothing = float(self.options.get("smoothing_s", 60.0))
        if smoothing < 0:
            raise ValueError(
                "diagnose(thermal): smoothing_s must be >= 0 [s] (0: no smoothing); got "
                f"{smoothing}."
            )
        arrays: dict[str, np.ndarray] = {}
        for key in _INPUTS:
            if key not in record.names:
                arrays[key] = np.zeros(n)
                continue
            x = np.asarray(record[key], float)
            arrays[key] = x if key == "v_m" else _smooth(x, dt, smoothing)
        y = np.asarray(record["T_bearing"], float)
        arrays["y"] = y
        sigma = _noise_sigma(y)
        ops: dict[str, np.ndarray] = {"T_chassis [°C]": arrays["T_chassis"]}
        masks: dict[str, np.ndarray] = {}
        if "T_air" in record.names:
            ops["T_air [°C]"] = arrays["T_air"]
        if "v_m" in record.names:
            v = np.abs(arrays["v_m"])
            ops["speed [rpm]"] = v
            masks.update(self._speed_masks(v, dt))
        return Experiment(
            name=name,
            t=np.asarray(record.t),
            arrays=arrays,
            ops=ops,
            masks=masks,
            noise_var=sigma**2,
            signals=frozenset(record.names),
            source=record,
        )

    def _speed_masks(self, v: np.ndarray, dt: float) -> dict[str, np.ndarray]:
        vmax = float(np.max(v))
        if vmax <= 0:
            return {}
        masks = {}
        still = v < 0.01 * vmax
        if 0 < still.sum() < v.size:
            masks["standstill"] = still
        change = np.flatnonzero(np.abs(np.diff(v)) > 0.05 * vmax) + 1
        if change.size:
            w = max(1, int(round(float(self.options.get("speed_change_s", 3600.0)) / dt)))
            after = np.zeros(v.size, bool)
            for c in change:
                after[c : c + w] = True
            if 0 < after.sum() < v.size:
                masks["after a speed change"] = after
                masks["steady speed"] = ~after
        levels = np.unique(np.round(v / max(0.01 * vmax, 1e-12)) * 0.01 * vmax)
        if 2 <= levels.size <= 8:
            for lev in levels:
                m = np.abs(v - lev) <= 0.005 * vmax
                if 0 < m.sum() < v.size:
                    masks[f"speed level {lev:.0f} rpm"] = m
        return masks

    def describe_nominal(self) -> str:
        return (
            "static linear regression on bias-free inputs, T_bearing = c0 + c1·(T_chassis − min)"
            + " [+ c2·(v_m − min) when the spindle speed v_m is recorded]"
            + " (study eq. 2-3)"
        )

    def nominal(self, experiments: Sequence[Experiment]) -> StaticRegression:
        tc = np.concatenate([e.arrays["T_chassis"] for e in experiments])
        if float(np.ptp(tc)) <= 0:
            raise NotIdentifiable(
                "T_chassis is constant over the calibration data: the regression coefficient "
                "is not identifiable; give experiments in which the spindle warms up or cools "
                "down"
            )
        use_speed = all("v_m" in e.signals for e in experiments)
        v = np.concatenate([e.arrays["v_m"] for e in experiments])
        if use_speed and float(np.ptp(v)) <= 0:
            use_speed = False
        # the study's biases: each input's minimum over the calibration data (eq. 2-3)
        b_c, b_v = _biases(experiments, use_speed)
        cols = [np.ones(tc.size), tc - b_c]
        if use_speed:
            cols.append(v - b_v)
        phi = np.stack(cols, -1)
        y = np.concatenate([e.y for e in experiments])
        th, *_ = np.linalg.lstsq(phi, y, rcond=None)
        # fold the biases into the intercept (see StaticRegression)
        th[0] -= th[1] * b_c + (th[2] * b_v if use_speed else 0.0)
        return StaticRegression(jnp.asarray(th), use_speed)

    def identifiability(self, experiments: Sequence[Experiment], model: GapModel) -> str | None:
        """The regression is identified when its regressors are not collinear (the
        chassis temperature and the speed vary independently enough)."""
        cols = [np.concatenate([e.arrays["T_chassis"] for e in experiments])]
        if unwrap(model.nominal).use_speed:
            cols.append(np.concatenate([e.arrays["v_m"] for e in experiments]))
        phi = np.stack([c - c.mean() for c in cols], -1)
        norms = np.linalg.norm(phi, axis=0)
        if np.any(norms == 0):
            return "an input of the regression is constant"
        sv = np.linalg.svd(phi / norms, compute_uv=False)
        if sv[-1] / sv[0] < 1e-3:
            return (
                "the chassis temperature and the speed move together in the record: their "
                "coefficients cannot be told apart; record different speeds at different "
                "temperatures"
            )
        return None

    def admissibility_context(
        self, experiments: Sequence[Experiment], model: GapModel
    ) -> AdmissibilityContext:
        dt = experiments[0].dt
        dur = min(e.n * dt for e in experiments)
        return AdmissibilityContext(
            record_dt=dt,
            analysis_dt=dt,
            band_hz=(2.0 / dur, 0.5 / dt),
            duration=dur,
            nominal=unwrap(model.nominal).parameters(),
        )

    def null_experiments(
        self,
        model: GapModel,
        experiments: Sequence[Experiment],
        rng: np.random.Generator,
        count: int,
    ) -> list[list[Experiment]]:
        """The calibrated regression on each record's own inputs, plus a noise of the
        level and colour of what the regression leaves of the record: the first-order
        autoregression (`ar1_noise`) the residual's differences measure -- white for a
        white sensor, with its in-band power for a coloured one (a white null of the
        second-difference level puts a coloured sensor's slow wander into the gap; the
        residual holds the inputs' sensor noise too, which reaches it through the
        regression). The noise's level is bounded by the residual's own (a stationary
        noise has no more variance than the residual it is part of); a quantised record
        takes the white level of its second differences' median absolute deviation, as
        before (quantisation breaks the robust difference ratio)."""
        out: list[list[Experiment]] = [[] for _ in range(count)]
        for exp in experiments:
            clean = predict(model, exp)
            sigma, rho = _residual_noise(exp.y, exp.y - clean)
            ys = clean + ar1_draws(sigma, rho, clean.size, rng, count)
            for k in range(count):
                out[k].append(dataclasses.replace(exp, arrays={**exp.arrays, "y": ys[k]}))
        return out

    def nominal_parameters(self, model, experiments) -> dict[str, float]:
        """The regression in the study's bias-free form: `c0`, `c_chassis`, `c_speed` and
        the biases `bias_chassis` [°C], `bias_speed` [rpm] of the calibration
        `experiments` (each input's minimum)."""
        p = unwrap(model.nominal).parameters()
        b_c, b_v = _biases(experiments, "c_speed" in p)
        out = {"c0": p["intercept"] + p["c_chassis"] * b_c}
        out["c_chassis"] = p["c_chassis"]
        if "c_speed" in p:
            out["c0"] += p["c_speed"] * b_v
            out["c_speed"] = p["c_speed"]
        out["bias_chassis"] = b_c
        if "c_speed" in p:
            out["bias_speed"] = b_v
        return out

    def library(self) -> list[EffectSpec]:
        return [
            EffectSpec(
                "dynamics",
                ("T_chassis", "T_bearing"),
                _t_dynamics,
                signature="residual against the rate of change of the prediction",
                description="the bearing lags its static temperature (heat capacity)",
            ),
            EffectSpec(
                "ambient_temperature",
                ("T_air",),
                _t_ambient,
                testable=_varies("T_air", "a varying air temperature"),
                signature="T_air",
                description="air temperature acting on the bearing directly",
            ),
            EffectSpec(
                "coolant_temperature",
                ("T_water",),
                _t_coolant,
                testable=_varies("T_water", "a varying water temperature"),
                signature="T_water",
                description="cooling-water temperature acting on the bearing directly",
            ),
            EffectSpec(
                "speed_nonlinearity",
                ("v_m",),
                _t_speed,
                testable=_needs_speed_levels,
                signature="(|v_m| / v_max)², (|v_m| / v_max)³",
                description="friction heat growing faster than linearly with speed",
            ),
        ]
