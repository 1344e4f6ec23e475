r"""Discovery of an effect the library does not have: a flexible term in a physical slot,
then its formula.

After the named search, a gap that no library effect explains may still be above the
floor. Discovery asks *where* it enters the model and *what* it is:

1. **A flexible term in a slot.** The drive's slot is an additional force on the axis,
   `u = model(q, q̇, q̈) + f(q̇, q, q̈, u, t)`. `f` is additive over the slot inputs,
   `Σ_i f_i(x_i)`, plus a viscous coefficient that varies in time, `q̇·f_t(t)`; every
   `f_i` is a cubic B-spline on knots at quantiles of its input
   (`jaxvs.signal.bspline_basis`), with a P-spline roughness penalty and a small ridge.
   The term is linear in its coefficients and is calibrated **jointly** with the
   model's parameters by the one Levenberg–Marquardt kernel (`jaxvs.calibration.lm_step`),
   once per input alone and once with all inputs, all fits in one vectorised call. Each
   fit is scored on the held-out experiments (the held-out nrmse reduction with a
   moving-block bootstrap interval, `gap_change_interval`). The input whose term alone
   removes most of the held-out gap is the one that carries it.
2. **The null pays for the selection.** The same step (every input, then the best) runs
   on effect-free records simulated from the calibrated nominal model through the
   recorded set-up (`family.null_experiments`); the flexible term *fires* only when its
   held-out reduction exceeds the 95th percentile of the null's best reductions, its
   bootstrap interval excludes zero and it removes at least `min_shrink` of the gap.
3. **A formula.** A typed dictionary of physically motivated terms for the slot
   (`_dictionary`), each shape (a velocity scale, a pitch, a time constant, a force
   limit) on a grid (the two best grid members of each kind are kept by a screening on
   their single-term fit), is reduced by **backward elimination on the Bayesian evidence
   of the linear-Gaussian model with Zellner's g-prior** (`g = N_eff`, the
   unit-information prior; `jaxvs.calibration.backward_elimination`), the model's own
   Jacobian profiled out and `N_eff = N/τ` from the flexible term's residual. The
   elimination is repeated on moving-block bootstrap resamples: a kind is kept when it
   survives in at least 80 % of them (stability selection). The kept terms are then
   recalibrated with their shapes free, jointly with the model, by the same LM kernel;
   their coefficients get intervals from the Gauss–Newton covariance inflated by the
   residual's integrated autocorrelation time.
4. **Acceptance.** The formula is *found* when it is not empty, its held-out reduction
   has an interval excluding zero, exceeds the null's threshold and reaches at least
   `min_share` (0.8) of what the flexible term removes. When its support lies inside a
   named library effect (only `sign(v)`: Coulomb friction), that named effect is
   reported instead. Otherwise "no formula found", and the flexible term's shape is
   the answer ([`plot_discovered`][jaxvs.plotting.plot_discovered] draws it).

The thermal family has two slots: an additional heat flow into the bearing node (in
kelvin of the bearing's static temperature rise; inputs speed `s = |v_m|`, the measured
temperatures, and `s·f(t)`), which passes through the model's bearing lag when it has
one (the flexible basis at the calibrated time constant, the formula with it free), and
an additive term of the bearing sensor in time (after the lag). `s·f(t)` holds the
sensor's `f(t)` beside it and wins over it only by a held-out interval above zero. Its
formula is built from the variables of the winning input (`_dictionary`). The thermal
null is the calibrated model (its lag included) on the records' own inputs.

The drive's second slot is its **input nonlinearity** `u → g(u)`: the axis receives
`g(u)`, so the recorded force is `u = g⁻¹(f_m)` with `f_m` the force the model says the
axis needs; its term is a function of the model's force (a dead zone, a gain that falls
above a level). The tmf family has an **additive term of the tool-side output** in the
encoder position, its velocity and `x_e·f(A)` (`A` the motion's moving rms: a gain that
changes with the amplitude), and a **static output nonlinearity** `x_t = g(x̂_t)` of the
model's output (a stiffening, a clipped sensor). A term in the model's output reads the
calibrated model's output, held, in the flexible fits, and the model's output at every
iterate in the formula's recalibration; the tmf null is the calibrated model on the
records' own encoder motion.

5. **The next experiment** (`_next_experiment`). When the kept support and its best rival
   (one term swapped for a term of another kind) are within an evidence ratio of
   `design_ratio` (10) on the records, the excitation within the records' limits on which
   the two formulas' predictions differ most is proposed (drive and tmf).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ..calibration import (
    backward_elimination,
    free_spec,
    jacobian_normal_equations,
    lm_solve,
    log_evidence,
    stability_selection,
    unwrap,
)
from ..signal import bspline_basis, difference_penalty, quantile_knots
from ._base import Experiment, GapModel, predict
from ._dictionary import (
    DRIVE_NAMED,
    THERMAL_NAMED,
    TMF_NAMED,
    Member,
    drive_force_dictionary,
    drive_input_dictionary,
    nearest_named,
    thermal_heat_dictionary,
    thermal_sensor_dictionary,
    tmf_output_dictionary,
    tmf_static_dictionary,
)
from ._next_experiment import DESIGN_FAMILIES, NextExperiment, design, limits_from
from ._stats import (
    block_bootstrap_indices,
    block_length,
    effective_samples,
    gap_change_interval,
    integrated_time,
    nrmse,
)
from ._thermal import first_order_lag

__all__ = ["SLOT_FAMILIES", "Discovered", "DiscoveryOptions", "discover"]

# the families with a discovery slot (the others report that discovery was not run)
SLOT_FAMILIES = ("drive", "thermal", "tmf")

SLOT_FORCE = "additional force on the axis"
SLOT_INPUT = "input nonlinearity u → g(u)"
SLOT_HEAT = "additional heat flow into the bearing node"
SLOT_SENSOR = "additive term of the bearing sensor"
SLOT_OUTPUT = "additive term of the tool-side output"
SLOT_STATIC = "static output nonlinearity"

# slot inputs of the drive's force slot: label -> array key (the product `v·f(t)` is the
# viscous coefficient varying in time)
_DRIVE_INPUTS = {
    "velocity": "v",
    "position": "q",
    "acceleration": "a",
    "time": "t",
    "velocity·f(time)": "v*t",
}
# The recorded force `u` is the target of the inverse-dynamics model: every unmodelled
# force is in it, so a flexible term in `u` gains on any gap (not only an input
# nonlinearity) and cannot say where the gap enters. It is left out of the additive
# slot, and so is a term in it for the input nonlinearity: the axis receives `g(u)`, so
# the recorded force is `u = g⁻¹(f_m)` with `f_m` the force the model says the axis
# needs; the slot's term is a function of the model's force `f_m` (the calibrated model's
# output, held for the flexible term, the model's own output in the formula's
# recalibration), free of the force's noise.
_DRIVE_INPUT_INPUTS = {"force": "yhat"}

# slot inputs of the tmf slots: an additive term of the tool-side output in the encoder's
# position, velocity and the encoder position times a function of the motion's amplitude
# (a transmission that stiffens with the amplitude), and a static nonlinearity of the
# model's output (the calibrated TMF's prediction, held: the basis stays linear and known,
# as the thermal lag is held).
_TMF_OUTPUT_INPUTS = {
    "encoder position": "x_e",
    "encoder velocity": "xd_e",
    "x_e·f(amplitude)": "x_e*amp",
}
_TMF_STATIC_INPUTS = {"model output": "yhat"}

# slot inputs of the thermal slots: label -> array key. The heat flow enters the bearing
# node (before its lag, when the model has one); the sensor term is added after it. A heat
# flow in time alone and a sensor term in time differ only over the bearing's time
# constant (minutes, against drifts over hours), so time alone is the sensor's input; a
# heat flow in time enters through the speed (`s·f(t)`: friction heat that changes with
# time), and the heat-flow dictionary keeps the time kinds beside it.
_THERMAL_HEAT_INPUTS = {
    "speed": "s",
    "chassis temperature": "T_chassis",
    "air temperature": "T_air",
    "water temperature": "T_water",
    "speed·f(time)": "s*t",
}
_THERMAL_SENSOR_INPUTS = {"time (sensor)": "t"}


@dataclasses.dataclass(frozen=True)
class _Slots:
    """A family's discovery slots: the inputs of the flexible term (label -> array key),
    the slot of each input, the inputs whose term passes through the model's lag, the
    array keys the slots read, the dictionary of each slot, the named effects' supports
    and the SymPy symbol of each key."""

    inputs: dict[str, str]
    slot_of: dict[str, str]
    lagged: frozenset[str]
    keys: tuple[str, ...]
    dictionaries: dict[str, Any]
    named: dict[str, frozenset[str]]
    symbols: dict[str, str]
    axis_labels: dict[str, str]
    ylabel: str
    nested: dict[str, str] = dataclasses.field(default_factory=dict)
    # the figure's y label of a product input `a*b` (the term over `a`, against `b`)
    product_ylabels: dict[str, str] = dataclasses.field(default_factory=dict)


_DRIVE_SLOTS = _Slots(
    inputs={**_DRIVE_INPUTS, **_DRIVE_INPUT_INPUTS},
    slot_of=dict.fromkeys(_DRIVE_INPUTS, SLOT_FORCE)
    | dict.fromkeys(_DRIVE_INPUT_INPUTS, SLOT_INPUT),
    lagged=frozenset(),
    keys=("v", "q", "a", "u", "t", "yhat"),
    dictionaries={SLOT_FORCE: drive_force_dictionary, SLOT_INPUT: drive_input_dictionary},
    named=DRIVE_NAMED,
    symbols={k: k for k in ("v", "q", "a", "u", "t")} | {"yhat": "f_m"},
    axis_labels={
        "v": "velocity [m/s]",
        "q": "position [m]",
        "a": "acceleration [m/s²]",
        "t": "time [s]",
        "v*t": "time [s]",
        "u": "recorded force u [N]",
        "yhat": "model force f_m [N]",
    },
    ylabel="additional force [N]",
    product_ylabels={"v*t": "viscous coefficient f(t) [N·s/m]"},
)


def _thermal_slots(cal: Sequence[Experiment], lag: Any) -> _Slots:
    """The thermal slots on the calibration data (the inputs that vary); the heat flow's
    columns pass through the model's lag when it has one."""

    def varies(key):
        src = key.split("*")[0]
        x = np.concatenate([np.asarray(e.arrays[src], float) for e in cal])
        return float(np.ptp(x)) > 0

    heat = {lab: k for lab, k in _THERMAL_HEAT_INPUTS.items() if varies(k)}
    inputs = {**heat, **_THERMAL_SENSOR_INPUTS}
    slot_of = {lab: SLOT_HEAT for lab in heat} | dict.fromkeys(_THERMAL_SENSOR_INPUTS, SLOT_SENSOR)
    return _Slots(
        inputs=inputs,
        slot_of=slot_of,
        lagged=frozenset(heat) if lag is not None else frozenset(),
        keys=("s", "T_chassis", "T_air", "T_water", "t"),
        dictionaries={SLOT_HEAT: thermal_heat_dictionary, SLOT_SENSOR: thermal_sensor_dictionary},
        named=THERMAL_NAMED,
        symbols={"s": "s", "T_chassis": "T_c", "T_air": "T_a", "T_water": "T_w", "t": "t"},
        axis_labels={
            "s": "speed |v_m| [rpm]",
            "T_chassis": "chassis temperature [°C]",
            "T_air": "air temperature [°C]",
            "T_water": "water temperature [°C]",
            "t": "time [s]",
            "s*t": "time [s]",
        },
        ylabel="additional bearing temperature [K]",
        # a heat flow in speed and time holds the sensor's term in time beside it
        nested={"speed·f(time)": "time (sensor)"},
        product_ylabels={"s*t": "heat flow per unit speed f(t) [K/rpm]"},
    )


_TMF_SLOTS = _Slots(
    inputs={**_TMF_OUTPUT_INPUTS, **_TMF_STATIC_INPUTS},
    slot_of=dict.fromkeys(_TMF_OUTPUT_INPUTS, SLOT_OUTPUT)
    | dict.fromkeys(_TMF_STATIC_INPUTS, SLOT_STATIC),
    lagged=frozenset(),
    keys=("x_e", "xd_e", "amp", "yhat", "t"),
    dictionaries={SLOT_OUTPUT: tmf_output_dictionary, SLOT_STATIC: tmf_static_dictionary},
    named=TMF_NAMED,
    symbols={"x_e": "x_e", "xd_e": "xdot_e", "amp": "A", "yhat": "xhat_t", "t": "t"},
    axis_labels={
        "x_e": "encoder position x_e [m]",
        "xd_e": "encoder velocity [m/s]",
        "x_e*amp": "x_e amplitude A [m]",
        "yhat": "model output x̂_t [m]",
        "t": "time [s]",
    },
    ylabel="additional tool-side motion [m]",
    # a gain that changes with the amplitude holds a static term in x_e beside it
    nested={"x_e·f(amplitude)": "encoder position"},
    product_ylabels={"x_e*amp": "additional gain f(A) [m/m]"},
)


def _family_slots(name: str, cal: Sequence[Experiment], lag: Any) -> _Slots:
    """The slots of the family `name` on the calibration slot experiments."""
    if name == "thermal":
        return _thermal_slots(cal, lag)
    if name == "tmf":
        return _TMF_SLOTS
    return _DRIVE_SLOTS


def _dynamics(model: GapModel):
    """The bearing's lag of a (unwrapped) thermal model, or `None`."""
    for e in model.effects:
        if e.name == "dynamics":
            return e
    return None


def _lag(x, dyn):
    """A heat flow's share of the bearing temperature through the model's lag `dyn`
    (linear: the lag of the sum is the model's lag plus this, started from zero)."""
    return first_order_lag(x, jnp.asarray(dyn.tau), dyn.dt, jnp.zeros((), x.dtype))


@functools.partial(jax.jit, static_argnums=2)
def _lag_columns(x, tau, dt):
    """`_lag` of every column of `(exp, n, k)` at the time constant `tau` [s]."""

    def one(col):
        return first_order_lag(col, tau, dt, jnp.zeros((), col.dtype))

    return jax.vmap(jax.vmap(one, 1, 1))(x)


@dataclasses.dataclass
class Discovered:
    """What discovery found in one slot (see the module doc for the method).

    - `slot`: the physical place (drive: `"additional force on the axis"`; thermal:
        `"additional heat flow into the bearing node"` or `"additive term of the bearing
        sensor"`).
    - `fired`: whether the flexible term beat the null (nothing else is meaningful when not).
    - `input`: the slot input whose flexible term alone removes most of the held-out gap.
    - `inputs`: per input (and `"all"`), the flexible term's held-out `reduction`,
        `shrink` and `shrink_interval`.
    - `flexible`: the best flexible term's `reduction`, `reduction_interval`, `shrink`,
        `shrink_interval`, and the null's `null_threshold` and `null_reductions`.
    - `formula`: the formula as text (SymPy's printing), or `None`; `expression`: the
        SymPy expression.
    - `found`: whether the formula was accepted; `message`: the verdict in words
        (`"no formula found"` when not).
    - `terms`: per kept term, `kind`, `coefficients`, `intervals`, `shape` (name, value,
        interval) and `frequency` (stability selection).
    - `frequencies`: selection frequency of every kind of the dictionary.
    - `shrink`, `shrink_interval`, `reduction`, `reduction_interval`: the formula's
        held-out figures; `share`: its reduction over the flexible term's.
    - `nearest_effect`: the named library effect nearest to the formula;
        `named_instead`: the formula's support lies inside it, so it is reported instead.
    - `evidence`: the evidence used for the selection, in words.
    - `shape`: arrays for the figure (`x`, `partial`, `flexible`, `formula`, `label`).
    - `seconds`: wall time of the discovery.
    - `next_experiment`: when a rival formula is within an evidence ratio of
        `design_ratio` (10) on the records, the excitation that tells the two apart
        ([`NextExperiment`][jaxvs.diagnosis.NextExperiment]: the reference signal, its
        parameters, the predicted disagreement; drive and tmf); else `None`.
        `save_next_experiment(path)` writes its signal as CSV.
    - `rival`: the kept support (`formula`), its best rival with one term swapped
        (`rival`) and the log evidence of the first over the second on the records
        (`log_evidence_ratio`; negative: the rival is the more probable), or `None`.
    """

    slot: str
    fired: bool
    input: str | None
    inputs: dict[str, dict[str, Any]]
    flexible: dict[str, Any]
    formula: str | None = None
    found: bool = False
    message: str = ""
    terms: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    frequencies: dict[str, float] = dataclasses.field(default_factory=dict)
    shrink: float | None = None
    shrink_interval: tuple[float, float] | None = None
    reduction: float | None = None
    reduction_interval: tuple[float, float] | None = None
    share: float | None = None
    nearest_effect: str | None = None
    named_instead: bool = False
    evidence: str = ""
    shape: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)
    seconds: float = 0.0
    expression: Any = dataclasses.field(default=None, repr=False)
    next_experiment: NextExperiment | None = dataclasses.field(default=None, repr=False)
    rival: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """The content of `report.json["discovered"]` (no arrays)."""
        out = {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.name not in ("shape", "expression", "next_experiment")
        }
        nxt = self.next_experiment
        out["next_experiment"] = None if nxt is None else nxt.to_json()
        for k in ("shrink_interval", "reduction_interval"):
            if out[k] is not None:
                out[k] = [float(x) for x in out[k]]
        return out

    def save_next_experiment(self, path) -> Any:
        """Write the proposed next experiment's reference signal as CSV (`t`, signal);
        returns the path, or `None` when there is no proposal."""
        if self.next_experiment is None:
            return None
        return self.next_experiment.to_csv(path)

    def __repr__(self) -> str:
        if not self.fired:
            return f"Discovered(slot={self.slot!r}: {self.message})"
        return (
            f"Discovered(slot={self.slot!r}, input={self.input!r}, formula={self.formula!r}, "
            f"found={self.found}, shrink={self.shrink}, share={self.share}, "
            f"nearest_effect={self.nearest_effect!r}: {self.message})"
        )


# ------------------------------------------------------------------------------ data


def _slot_experiment(e: Experiment, family: str = "drive", model: Any = None) -> Experiment:
    """The experiment with the slot inputs the family's model does not read: time `t` [s]
    (the record's own), and for the drive the recorded force `u` (the target) and the
    calibrated `model`'s force `yhat`, for
    the thermal family the speed `s = |v_m|`, for the tmf family the encoder velocity
    `xd_e`, the motion's amplitude `amp` (the moving rms of `x_e` over 50 ms) and the
    calibrated `model`'s output `yhat`."""
    arrays = dict(e.arrays)
    arrays["t"] = np.asarray(e.t, float)
    if family == "thermal":
        arrays["s"] = np.abs(np.asarray(e.arrays["v_m"], float))
    elif family == "tmf":
        xe = np.asarray(e.arrays["x_e"], float)
        arrays["xd_e"] = np.gradient(xe, e.dt)
        w = max(4, int(round(0.05 / e.dt)))
        arrays["amp"] = np.sqrt(np.convolve((xe - xe.mean()) ** 2, np.ones(w) / w, mode="same"))
        arrays["yhat"] = predict(model, e)
    else:
        arrays["u"] = np.asarray(e.arrays["y"], float)
        arrays["yhat"] = predict(model, e)
    return dataclasses.replace(e, arrays=arrays)


def _stack(exps: Sequence[Experiment], keys) -> dict[str, np.ndarray]:
    n_max = max(e.n for e in exps)
    out = {}
    for k in keys:
        cols = []
        for e in exps:
            x = np.asarray(e.arrays[k], float)
            if x.ndim == 2:
                x = np.pad(x, ((0, n_max - x.shape[0]), (0, 0)), mode="edge")
            else:
                x = np.pad(x, (0, n_max - x.size), mode="edge")
            cols.append(x)
        out[k] = np.stack(cols)
    return out


class _Basis:
    """The flexible term's basis: cubic B-splines per slot input on quantile knots of the
    calibration data, and its penalty (P-spline second differences plus a small ridge)."""

    def __init__(
        self,
        cal: Sequence[Experiment],
        inputs: Mapping[str, str],
        n_basis: int,
        keys: Sequence[str] = ("v", "q", "a", "u", "t"),
    ):
        self.inputs = dict(inputs)
        self.keys = tuple(keys)
        self.compiled = None  # the basis on stacked experiments, compiled once
        self.knots: dict[str, np.ndarray] = {}
        self.blocks: dict[str, slice] = {}
        k0 = 0
        for label, key in self.inputs.items():
            src = key.split("*")[-1]
            x = np.concatenate([np.asarray(e.arrays[src], float) for e in cal])
            # a ripple of many periods over the travel needs many knots in position
            nb = 3 * n_basis if key == "q" else n_basis
            nb = max(4, n_basis - 2) if "*" in key else nb
            self.knots[label] = quantile_knots(x, nb)
            k = self.knots[label].size - 4
            self.blocks[label] = slice(k0, k0 + k)
            k0 += k
        self.size = k0

    def __call__(self, d: Mapping[str, Any]) -> jnp.ndarray:
        cols = []
        for label, key in self.inputs.items():
            if "*" in key:
                a, b_ = key.split("*")
                b = jnp.asarray(d[a])[:, None] * bspline_basis(d[b_], self.knots[label])
            else:
                b = bspline_basis(d[key], self.knots[label])
            cols.append(b)
        return jnp.concatenate(cols, axis=-1)

    def penalty(self, n: int, lam: float, ridge: float) -> np.ndarray:
        rows = []
        for label, key in self.inputs.items():
            sl = self.blocks[label]
            k = sl.stop - sl.start
            d2 = np.zeros((k - 2, self.size))
            d2[:, sl] = difference_penalty(k, 2)
            rows.append(math.sqrt(lam * n / k) * d2)
        rows.append(math.sqrt(ridge * n / self.size) * np.eye(self.size))
        return np.concatenate(rows)

    def masks(self, nested: Mapping[str, str] | None = None) -> tuple[list[str], np.ndarray]:
        """One mask per input, one with all, one with none; `nested` maps an input to a
        simpler one whose block its mask includes (the product `s·f(t)` with `f(t)`)."""
        labels = list(self.inputs) + ["all"]
        m = np.zeros((len(labels) + 1, self.size))  # the last row: no flexible term
        for i, label in enumerate(self.inputs):
            m[i, self.blocks[label]] = 1.0
            inner = (nested or {}).get(label)
            if inner in self.blocks:
                m[i, self.blocks[inner]] = 1.0
        m[len(self.inputs)] = 1.0
        return labels, m


# ------------------------------------------------------------------------------ LM fits


def _split(model: GapModel):
    cm = model.constrained()
    params, static = eqx.partition(cm, free_spec(cm))
    flat, unravel = ravel_pytree(params)
    return flat, unravel, static


@eqx.filter_jit
def _fit_flexible(params, static, inputs, y, wfit, phi, pen, masks, max_steps):
    """Model and flexible term calibrated jointly by LM, once per mask (vmapped): the
    parameters, the prediction on every experiment and the final cost.

    The normal equations are formed in blocks: the flexible term's Jacobian is its basis
    (known), so only the model's parameters take a Jacobian-vector product per step, and
    the basis Gram matrix is formed once per data set."""
    flat, unravel = ravel_pytree(params)
    p = flat.size
    phw = phi * wfit[..., None]  # (e, n, K): the weighted flexible Jacobian
    gram = jnp.einsum("enk,enj->kj", phw, phw) + pen.T @ pen

    def model_pred(tm):
        return jax.vmap(unwrap(eqx.combine(unravel(tm), static)))(inputs)

    def predict(theta, mask):
        return model_pred(theta[:p]) + jnp.einsum("enk,k->en", phi, theta[p:] * mask)

    def evaluate(theta, mask):
        tm, c = theta[:p], theta[p:]
        ym, jm = jax.vmap(lambda v: jax.jvp(model_pred, (tm,), (v,)), out_axes=(None, 0))(
            jnp.eye(p, dtype=tm.dtype)
        )
        r = (ym + jnp.einsum("enk,k->en", phi, c * mask) - y) * wfit
        jm = jm * wfit  # (p, e, n)
        rp = pen @ c
        jtj_mm = jnp.einsum("pen,qen->pq", jm, jm)
        jtj_fm = jnp.einsum("enk,pen->kp", phw, jm) * mask[:, None]
        jtj_ff = gram * jnp.outer(mask, mask) + pen.T @ pen * (1 - jnp.outer(mask, mask))
        jtj = jnp.block([[jtj_mm, jtj_fm.T], [jtj_fm, jtj_ff]])
        jtr = jnp.concatenate(
            [jnp.einsum("pen,en->p", jm, r), jnp.einsum("enk,en->k", phw, r) * mask + pen.T @ rp]
        )
        return 0.5 * (jnp.sum(r * r) + jnp.sum(rp * rp)), jtj, jtr

    theta0 = jnp.concatenate([flat, jnp.zeros(phi.shape[-1], flat.dtype)])

    def one(mask):
        st = lm_solve(evaluate, theta0, mask, max_steps=max_steps, rtol=1e-10)
        return st.theta, predict(st.theta, mask), st.cost

    return jax.vmap(one)(masks)


def _flexible_step(model, exps, n_cal, basis, scale, masks, pen, lagged=(), max_steps=40):
    """Fit every mask on one data set; returns (thetas, predictions (masks, exp, n)).
    The columns of the inputs `lagged` pass through the model's lag at its calibrated
    time constant (held there: the basis stays linear and known)."""
    keys = set(exps[0].arrays)
    st = _stack(exps, sorted(keys))
    w = np.zeros((len(exps), st["y"].shape[1]))
    for i, e in enumerate(exps):
        if i < n_cal:
            w[i, : e.n] = scale
    inputs = {k: jnp.asarray(v) for k, v in st.items()}
    phi = _basis_values(basis, inputs)
    dyn = _dynamics(unwrap(model))
    if lagged and dyn is not None:
        cols = np.concatenate([np.arange(basis.size)[basis.blocks[lab]] for lab in lagged])
        phi = phi.at[..., cols].set(_lag_columns(phi[..., cols], jnp.asarray(dyn.tau), dyn.dt))
    flat, unravel, static = _split(model)
    params = unravel(flat)
    thetas, preds, _ = _fit_flexible(
        params,
        static,
        inputs,
        jnp.asarray(st["y"]),
        jnp.asarray(w),
        phi,
        jnp.asarray(pen),
        jnp.asarray(masks),
        max_steps,
    )
    return np.asarray(thetas), np.asarray(preds), flat.size, np.asarray(phi)


def _basis_values(basis, inputs):
    """The flexible basis on stacked experiments `(e, n, K)`, in one compiled call."""
    if basis.compiled is None:
        basis.compiled = jax.jit(jax.vmap(basis))
    return basis.compiled({k: inputs[k] for k in basis.keys})


def _residuals(exps, pred):
    return [e.y - pred[i, : e.n] for i, e in enumerate(exps)]


def _val_reductions(exps, n_cal, preds) -> np.ndarray:
    """Held-out nrmse reduction of every mask against the last (no flexible term)."""
    y = np.concatenate([e.y for e in exps[n_cal:]])
    gaps = np.array([nrmse(np.concatenate(_residuals(exps, p)[n_cal:]), y) for p in preds])
    return gaps[-1] - gaps[:-1]


# ------------------------------------------------------------------------------ formula


def _screen(members: list[Member], X: list[np.ndarray], B: np.ndarray, r: np.ndarray, keep: int):
    """The `keep` best grid members of every kind by their single-term fit to the
    residual `r` with the base `B` profiled out."""
    Q, _ = np.linalg.qr(B)
    rr = r - Q @ (Q.T @ r)
    score = []
    for x in X:
        xr = x - Q @ (Q.T @ x)
        coef, *_ = np.linalg.lstsq(xr, rr, rcond=None)
        score.append(float(np.sum((xr @ coef) ** 2)))
    by_kind: dict[str, list[int]] = {}
    for i, m in enumerate(members):
        by_kind.setdefault(m.kind.name, []).append(i)
    chosen = []
    for idx in by_kind.values():
        chosen += sorted(idx, key=lambda i: -score[i])[:keep]
    return sorted(chosen)


@eqx.filter_jit
def _fit_formula(params, static, inputs, y, wfit, start, bounds, fns, max_steps):
    """Model and formula calibrated jointly by LM from `start = (coefficients, log
    shapes)`, the log shapes within `bounds = (lo, hi)`. Returns θ, the prediction, the
    Jacobian of the weighted residual and the weighted residual."""
    coefs0, logs0 = start
    lo, hi = bounds
    flat, unravel = ravel_pytree(params)
    p, k = flat.size, coefs0.size

    def formula(c, logs, d, dyn, ym):
        # terms of a heat flow (mode "lag") pass through the model's lag `dyn`; terms of
        # a static output nonlinearity (mode "static") read the model's own output
        out, heat, i = 0.0, 0.0, 0
        d_static = {**d, "yhat": ym}
        for j, (fn, ncol, _, mode) in enumerate(fns):
            term = fn(d_static if mode == "static" else d, jnp.exp(logs[j])) @ c[i : i + ncol]
            if mode == "lag":
                heat = heat + term
            else:
                out = out + term
            i += ncol
        if dyn is not None and any(f[3] == "lag" for f in fns):
            out = out + _lag(heat, dyn)
        else:
            out = out + heat
        return out

    def predict(theta):
        m = unwrap(eqx.combine(unravel(theta[:p]), static))
        c, logs = theta[p : p + k], theta[p + k :]
        dyn = _dynamics(m)

        def one(d):
            ym = m(d)
            return ym + formula(c, logs, d, dyn, ym)

        return jax.vmap(one)(inputs)

    # the log shape of a shapeless kind is carried with a zero Jacobian: LM leaves it
    def resid(theta, args):
        return ((predict(theta) - y) * wfit).ravel()

    def feasible(theta):  # shapes inside their bounds (a force limit above the median |u|)
        return jnp.all((theta[p + k :] > lo) & (theta[p + k :] < hi))

    evaluate = jacobian_normal_equations(resid)
    theta0 = jnp.concatenate([flat, coefs0, logs0])
    st = lm_solve(evaluate, theta0, None, max_steps=max_steps, rtol=1e-10, feasible=feasible)
    return st.theta, predict(st.theta), st.jtj, resid(st.theta, None)


# ------------------------------------------------------------------------------ options


@dataclasses.dataclass(frozen=True)
class DiscoveryOptions:
    """The settings of [`discover`][jaxvs.diagnosis.discover] (frozen; `replace` with
    `dataclasses.replace`).

    - `n_null`: effect-free records the discovery step is run on (the null that pays
        for the choice of the input; default 19: the 95th percentile is about their
        largest); `0` skips the null (threshold 0; for tests of the formula only).
    - `n_boot`: bootstrap resamples of the held-out intervals.
    - `n_stability`, `stability`: block-bootstrap resamples of the stability selection
        and the share of them a kind must survive in (default 50, 0.8).
    - `min_shrink`: the flexible term must remove at least this share of the held-out gap.
    - `min_share`: the formula must remove at least this share of what the flexible
        term removes to be *found*.
    - `min_evidence`: a term stays in the formula only when it raises the log evidence
        by more than this (default 5: a Bayes factor of e⁵, about the ΔBIC of 10 that
        named effects pass).
    - `n_basis`: B-splines per slot input (cubic, default 8).
    - `seed`: seed of the null records and the resamples.
    - `design`: propose the next experiment when two formulas are within an evidence
        ratio of `design_ratio` (default 10) on the records.
    """

    n_null: int = 19
    n_boot: int = 200
    n_stability: int = 50
    stability: float = 0.8
    min_shrink: float = 0.05
    min_share: float = 0.8
    min_evidence: float = 5.0
    n_basis: int = 8
    seed: int = 0
    design: bool = True
    design_ratio: float = 10.0

    def __post_init__(self):
        if not (isinstance(self.n_null, int) and self.n_null >= 0):
            raise ValueError(f"discover: n_null must be an integer >= 0; got {self.n_null!r}.")
        if not 0 < self.stability <= 1:
            raise ValueError(f"discover: stability must lie in (0, 1]; got {self.stability!r}.")
        for name in ("n_boot", "n_stability", "n_basis"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"discover: {name} must be an integer >= 1; got {v!r}.")
        if not self.design_ratio >= 1:
            raise ValueError(
                f"discover: design_ratio must be >= 1 (an evidence ratio); got "
                f"{self.design_ratio!r}."
            )


@dataclasses.dataclass(frozen=True)
class _Problem:
    """One discovery problem: the family, the model, the slot experiments (calibration
    first), the slots and the flexible basis with its penalty and masks."""

    fam: Any
    model: GapModel
    calibration: tuple[Experiment, ...]  # as given (the null is drawn from these)
    validation: tuple[Experiment, ...]
    exps: tuple[Experiment, ...]  # slot experiments, calibration first
    n_cal: int
    scale: float
    n_samples: int
    dyn: Any
    slots: _Slots
    basis: _Basis
    pen: np.ndarray
    labels: list[str]
    masks: np.ndarray
    lagged: tuple[str, ...]
    opts: DiscoveryOptions

    @property
    def cal(self) -> tuple[Experiment, ...]:
        return self.exps[: self.n_cal]

    @property
    def y_val(self) -> np.ndarray:
        return np.concatenate([e.y for e in self.exps[self.n_cal :]])

    def val_residual(self, pred) -> np.ndarray:
        return np.concatenate(_residuals(self.exps, pred)[self.n_cal :])

    def cal_residual(self, pred) -> np.ndarray:
        return np.concatenate(_residuals(self.exps, pred)[: self.n_cal])

    def interval(self, e0, e1, blen):
        """`gap_change_interval` of the held-out residual `e0` → `e1`."""
        o = self.opts
        return gap_change_interval(e0, e1, self.y_val, length=blen, n_boot=o.n_boot, seed=o.seed)


@dataclasses.dataclass(frozen=True)
class _Flexible:
    """The flexible fits of every mask on the records: parameters, predictions, the
    model's parameter count, the held-out figures per input, the residual without the
    flexible term and its block length."""

    thetas: np.ndarray
    preds: np.ndarray
    p_model: int
    inputs: dict[str, dict[str, Any]]
    e0: np.ndarray
    blen: int

    def pred(self, prob: _Problem, label: str) -> np.ndarray:
        return self.preds[prob.labels.index(label)]


@dataclasses.dataclass(frozen=True)
class _Selection:
    """The formula's selection: the screened members with their columns, the kept
    members, the selection frequencies, the full-data elimination, the shape bounds
    and the rows and matrices it ran on."""

    members: list[Member]
    X: list[np.ndarray]
    final: list[int]
    freq: dict[str, float]
    full: Any
    bounds: dict[str, tuple[float, float]]
    rows: slice
    Xs: np.ndarray
    rs: np.ndarray
    Bs: np.ndarray
    flat0: np.ndarray
    through_lag: bool
    limits: dict[str, float]
    n_eff: float  # a limit's lower bound (shape name -> median of its input)


# ------------------------------------------------------------------------------ steps


def _resolve(report_or_model, calibration, validation, family):
    """`(model, calibration, validation, family instance)` from a report or a model."""
    from ._families import FAMILIES

    if calibration is None:
        rep = report_or_model
        if getattr(rep, "final_model", None) is None or not getattr(rep, "calibration", None):
            raise ValueError(
                "discover: give a DiagnosisReport with its final model and experiments (a "
                "report of a record that was not identifiable has none), or a calibrated "
                "GapModel with its calibration and validation experiments."
            )
        model, calibration, validation = rep.final_model, rep.calibration, rep.validation
        if isinstance(family, str):
            # the report's family with its options: the null records go through the same
            # preprocessing as the records
            options = dict(rep.content.get("data", {}).get("options", {}))
            family = FAMILIES[rep.family](**options)
    else:
        model = report_or_model
        if not isinstance(model, GapModel):
            raise TypeError(
                f"discover: the model must be a jaxvs.diagnosis.GapModel; got "
                f"{type(model).__name__}. Pass a DiagnosisReport, or GapModel(nominal) "
                "with its experiments."
            )
        if not validation:
            raise ValueError(
                "discover: validation experiments are needed (the flexible term and the "
                "formula are scored on data they were not fitted to)."
            )
    fam = FAMILIES[family]() if isinstance(family, str) else family
    if fam.name not in SLOT_FAMILIES:
        raise ValueError(
            f"discover: the {fam.name!r} family has no discovery slot yet; the families "
            f"with slots are {', '.join(SLOT_FAMILIES)}."
        )
    return model, calibration, validation, fam


def _problem(model, calibration, validation, fam, opts: DiscoveryOptions) -> _Problem:
    """The slot experiments, the family's slots and the flexible basis."""
    cal = [_slot_experiment(e, fam.name, model) for e in calibration]
    val = [_slot_experiment(e, fam.name, model) for e in validation]
    y_cal = np.concatenate([e.y for e in cal])
    scale = 1.0 / max(float(np.sqrt(np.mean(y_cal**2))), 1e-300)
    n_samples = int(sum(e.n for e in cal))
    dyn = _dynamics(unwrap(model))
    slots = _family_slots(fam.name, cal, dyn)
    basis = _Basis(cal, slots.inputs, opts.n_basis, slots.keys)
    pen = basis.penalty(n_samples, lam=1e-3, ridge=1e-7) * scale
    labels, masks = basis.masks(slots.nested)
    return _Problem(
        fam=fam,
        model=model,
        calibration=tuple(calibration),
        validation=tuple(validation),
        exps=tuple(cal + val),
        n_cal=len(cal),
        scale=scale,
        n_samples=n_samples,
        dyn=dyn,
        slots=slots,
        basis=basis,
        pen=pen,
        labels=labels,
        masks=masks,
        lagged=tuple(lab for lab in slots.inputs if lab in slots.lagged),
        opts=opts,
    )


def _flexible(prob: _Problem) -> _Flexible:
    """Step 1: the flexible term on the records, per input and with all, scored on the
    held-out experiments."""
    thetas, preds, p_model, _ = _flexible_step(
        prob.model, prob.exps, prob.n_cal, prob.basis, prob.scale, prob.masks, prob.pen, prob.lagged
    )
    red = _val_reductions(prob.exps, prob.n_cal, preds)
    e0 = prob.val_residual(preds[-1])
    blen = block_length(e0)
    inputs: dict[str, dict[str, Any]] = {}
    for i, label in enumerate(prob.labels):
        _, _, sh, d_int, s_int = prob.interval(e0, prob.val_residual(preds[i]), blen)
        inputs[label] = {
            "reduction": float(red[i]),
            "reduction_interval": list(d_int),
            "shrink": float(sh),
            "shrink_interval": list(s_int),
        }
    return _Flexible(thetas, preds, p_model, inputs, e0, blen)


def _choose_input(prob: _Problem, flex: _Flexible) -> str:
    """The input whose term alone removes most of the held-out gap; a term that contains
    a simpler one (`s·f(t)` contains `f(t)`) wins only when it removes more than the
    simpler one alone, by a held-out interval above zero."""
    singles = prob.labels[:-1]
    best = max(singles, key=lambda lab: flex.inputs[lab]["reduction"])
    inner = prob.slots.nested.get(best)
    if inner in flex.inputs:
        e_in = prob.val_residual(flex.pred(prob, inner))
        e_best = prob.val_residual(flex.pred(prob, best))
        _, _, _, d_nest, _ = prob.interval(e_in, e_best, flex.blen)
        if not d_nest[0] > 0:
            best = inner
    return best


def _null_reductions(prob: _Problem, rng: np.random.Generator) -> list[float]:
    """Step 2: the same step on effect-free records: the best held-out reduction of each.
    The drive's null: the nominal axis in the recorded loop; the others: the model as
    calibrated (the thermal lag included) on the records' own inputs."""
    n_null = prob.opts.n_null
    if not n_null:
        return []
    fam = prob.fam
    nom = GapModel(unwrap(prob.model).nominal) if fam.name == "drive" else prob.model
    exps = list(prob.calibration) + list(prob.validation)
    out = []
    for s in fam.null_experiments(nom, exps, rng, n_null):
        s = [_slot_experiment(e, fam.name, prob.model) for e in s]
        _, p_null, _, _ = _flexible_step(
            nom, s, prob.n_cal, prob.basis, prob.scale, prob.masks, prob.pen, prob.lagged
        )
        out.append(float(np.max(_val_reductions(s, prob.n_cal, p_null)[:-1])))
    return out


def _fire(prob: _Problem, flex: _Flexible, best: str, null_red: list[float]) -> Discovered:
    """Whether the flexible term beat the null; the report's first part (and why not)."""
    o = prob.opts
    thr = float(np.quantile(null_red, 0.95)) if null_red else 0.0
    fb = flex.inputs[best]
    fired = (
        fb["reduction"] > thr and fb["reduction_interval"][0] > 0 and fb["shrink"] >= o.min_shrink
    )
    out = Discovered(
        slot=prob.slots.slot_of[best],
        fired=bool(fired),
        input=best if fired else None,
        inputs=flex.inputs,
        flexible={"input": best, **fb, "null_threshold": thr, "null_reductions": null_red},
        evidence="linear-Gaussian evidence, Zellner g-prior with g = N_eff (unit information)",
    )
    if not fired:
        why = []
        if fb["reduction"] <= thr:
            why.append(
                f"its held-out reduction {fb['reduction']:.3g} is within the null (95th "
                f"percentile {thr:.3g})"
            )
        if fb["reduction_interval"][0] <= 0:
            why.append("its bootstrap interval includes zero")
        if fb["shrink"] < o.min_shrink:
            why.append(f"its shrink {fb['shrink']:.3g} is below {o.min_shrink:g}")
        out.message = (
            "nothing to discover: the flexible term's gain is not real (" + "; ".join(why) + ")"
        )
    return out


def _slot_members(prob: _Problem, best: str, cal_d: dict[str, np.ndarray]) -> list[Member]:
    """The dictionary of the winning input's slot, restricted to what may carry it."""
    slot = prob.slots.slot_of[best]
    members = prob.slots.dictionaries[slot](cal_d)
    key = prob.slots.inputs[best]
    if prob.fam.name == "thermal":
        # the formula is made of the winning input's variables (the chassis temperature,
        # an input of the model, may join them): the gap lives there, and the thermal
        # inputs drift together over hours, so a term in another of them would stand in
        # for it
        src = {"s*t": ("s", "t")}.get(key, (key,))
        members = [m for m in members if set(m.kind.inputs) <= set(src) | {"T_chassis"}]
    return members


def _shape_bounds(members: Sequence[Member]) -> dict[str, tuple[float, float]]:
    """Each kind's grid range: its shape stays within a factor 3 of it in the
    recalibration (a shape that runs away turns its term into another kind: a Stribeck
    speed at infinity is a sign law)."""
    bounds: dict[str, tuple[float, float]] = {}
    for m in members:
        if m.shape is not None:
            lo_, hi_ = bounds.get(m.kind.name, (np.inf, -np.inf))
            bounds[m.kind.name] = (min(lo_, m.shape), max(hi_, m.shape))
    return bounds


def _select(prob: _Problem, flex: _Flexible, best: str, rng) -> _Selection:
    """Step 3: the dictionary screened, then backward elimination on the evidence and
    stability selection on block-bootstrap resamples; one member per kept kind."""
    o = prob.opts
    cal = prob.cal
    cal_d = {
        k: np.concatenate([np.asarray(e.arrays[k], float) for e in cal]) for k in prob.slots.keys
    }
    members = _slot_members(prob, best, cal_d)
    bounds = _shape_bounds(members)
    # a heat flow's terms pass through the model's lag (at its calibrated time constant
    # for the selection; with it free in the recalibration)
    through_lag = prob.slots.slot_of[best] == SLOT_HEAT and prob.dyn is not None
    flat0 = flex.thetas[-1][: flex.p_model]
    dyn = None
    if through_lag:
        # the lag at the time constant of the model recalibrated beside the flexible terms
        _, unravel0, static0 = _split(prob.model)
        dyn = _dynamics(unwrap(eqx.combine(unravel0(jnp.asarray(flat0)), static0)))
    X = [_member_columns(m, cal, dyn) for m in members]
    r_cal = prob.cal_residual(flex.preds[-1])
    B = _base_jacobian(prob.model, flat0, cal)
    chosen = _screen(members, X, B, r_cal, keep=2)
    members = [members[i] for i in chosen]
    X = [X[i] for i in chosen]
    groups, k0 = [], 0
    for x in X:
        groups.append(list(range(k0, k0 + x.shape[1])))
        k0 += x.shape[1]
    Xm = np.concatenate(X, axis=1)
    r_flex = prob.cal_residual(flex.pred(prob, "all"))
    # the selection on every `stride`-th sample (at most 4000): the terms are smooth and
    # the residual correlated over many samples, so this loses no evidence (N_eff is
    # measured on the same rows)
    stride = max(1, -(-r_cal.size // 4000))
    rows = slice(None, None, stride)
    Xs, rs, Bs, r_fs = Xm[rows], r_cal[rows], B[rows], r_flex[rows]
    n_eff = effective_samples(r_fs)
    full = backward_elimination(Xs, rs, groups, base=Bs, n_eff=n_eff, margin=o.min_evidence)
    idx = block_bootstrap_indices(rs.size, block_length(r_fs), o.n_stability, rng)
    _, supports = stability_selection(
        Xs, rs, groups, resamples=idx, base=Bs, n_eff=n_eff, margin=o.min_evidence
    )
    freq, final = _kept(members, supports, full, o.stability)
    # a limit (`L`, of the model's output) lies above the median of its input
    limits = {"L": float(np.median(np.abs(cal_d["yhat"])))} if "yhat" in cal_d else {}
    return _Selection(
        members, X, final, freq, full, bounds, rows, Xs, rs, Bs, flat0, through_lag, limits, n_eff
    )


def _kept(members, supports, full, stability) -> tuple[dict[str, float], list[int]]:
    """Selection frequency of every kind, and one member per kind kept in at least
    `stability` of the resamples (the shape is calibrated afterwards, so a second grid
    member of the kind would only split the same term in two)."""
    kinds = sorted({m.kind.name for m in members})
    freq = {
        k: float(np.mean([any(members[j].kind.name == k for j in s) for s in supports]))
        for k in kinds
    }
    member_freq = np.zeros(len(members))
    for s in supports:
        member_freq[list(s)] += 1
    member_freq /= max(len(supports), 1)
    final: list[int] = []
    for k in (k for k in kinds if freq[k] >= stability):
        in_full = [j for j in full.support if members[j].kind.name == k]
        cand = in_full or [j for j in range(len(members)) if members[j].kind.name == k]
        final.append(max(cand, key=lambda j: member_freq[j]))
    return freq, sorted(final)


def _start(sel: _Selection) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """The recalibration's start: coefficients, log shapes and their bounds."""
    fm = [sel.members[j] for j in sel.final]
    c0 = np.concatenate(
        [sel.full.coefficients.get(j, np.zeros(sel.members[j].kind.k)) for j in sel.final]
    )
    if not np.all(np.isfinite(c0)) or not all(j in sel.full.support for j in sel.final):
        # a kept kind the full-data elimination dropped: start from least squares of the
        # kept terms with the model's Jacobian beside them
        A = np.concatenate([sel.Bs] + [sel.X[j][sel.rows] for j in sel.final], 1)
        c0 = np.linalg.lstsq(A, sel.rs, rcond=None)[0][sel.Bs.shape[1] :]
    logs0 = np.log([m.shape if m.shape is not None else 1.0 for m in fm])
    b = sel.bounds
    lo = np.array([np.log(b[m.kind.name][0] / 3) if m.shape is not None else -np.inf for m in fm])
    hi = np.array([np.log(b[m.kind.name][1] * 3) if m.shape is not None else np.inf for m in fm])
    for name, med in sel.limits.items():
        # a limit lies above the median of its input (a limit, not the input itself)
        if med > 0:
            lo = np.where([m.kind.shape == name for m in fm], np.log(med), lo)
    logs0 = np.clip(logs0, lo + 1e-9, hi - 1e-9)
    return c0, logs0, (lo, hi)


def _recalibrate(prob: _Problem, flex: _Flexible, sel: _Selection, out: Discovered) -> None:
    """Step 4: the kept terms recalibrated with their shapes free, jointly with the
    model; held-out figures, intervals, the formula and the verdict into `out`."""
    o = prob.opts
    fm = [sel.members[j] for j in sel.final]
    c0, logs0, bounds = _start(sel)
    static_slot = prob.slots.slot_of[out.flexible["input"]] == SLOT_STATIC
    mode = "lag" if sel.through_lag else ("static" if static_slot else "add")
    theta, pred_f, jtj, r_w = _formula_fit(
        prob.model, sel.flat0, prob, fm, (c0, logs0), bounds, mode
    )
    e_f = prob.val_residual(pred_f)
    _, _, sh_f, d_f, s_f = prob.interval(flex.e0, e_f, flex.blen)
    red_f = nrmse(flex.e0, prob.y_val) - nrmse(e_f, prob.y_val)
    fb = out.flexible
    share = red_f / fb["reduction"] if fb["reduction"] > 0 else float("nan")
    out.terms, out.expression = _terms(prob, flex, fm, (theta, jtj, r_w, pred_f), sel.freq)
    out.formula = str(out.expression)
    out.shrink, out.shrink_interval = float(sh_f), (float(s_f[0]), float(s_f[1]))
    out.reduction, out.reduction_interval = float(red_f), (float(d_f[0]), float(d_f[1]))
    out.share = float(share)
    out.nearest_effect, out.named_instead = nearest_named(
        [m.kind.name for m in fm], prob.slots.named
    )
    out.found = bool(d_f[0] > 0 and red_f > fb["null_threshold"] and share >= o.min_share)
    out.shape["formula"] = _formula_on(prob.exps, prob.n_cal, pred_f, flex.preds[-1], out.shape)
    out.message = _formula_message(out, o.min_share)


def _terms(prob, flex, fm, fit, freq) -> tuple[list[dict[str, Any]], Any]:
    """Per kept term its coefficients with intervals (Gauss–Newton covariance inflated
    by the integrated autocorrelation time), its shape, frequency; and the SymPy sum."""
    theta, jtj, r_w, pred_f = fit
    p = flex.p_model
    k = int(sum(m.kind.k for m in fm))
    shaped = np.array([m.shape is not None for m in fm])
    free = np.concatenate([np.ones(p + k, bool), shaped])
    cov = _covariance(jtj, r_w, free, prob.n_samples, prob.cal_residual(pred_f))
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    terms, i = [], p
    sym_x = _symbols(prob.slots.symbols)
    expr = 0
    for j, m in enumerate(fm):
        c = theta[i : i + m.kind.k]
        ci = [
            [float(c[a] - 1.96 * sd[i + a]), float(c[a] + 1.96 * sd[i + a])]
            for a in range(m.kind.k)
        ]
        i += m.kind.k
        term: dict[str, Any] = {
            "kind": m.kind.name,
            "coefficients": [float(x) for x in c],
            "intervals": ci,
            "frequency": freq[m.kind.name],
        }
        shape_val = None
        if m.shape is not None:
            ls, lsd = theta[p + k + j], sd[p + k + j]
            shape_val = float(np.exp(ls))
            term["shape"] = {
                "name": m.kind.shape,
                "value": shape_val,
                "interval": [float(np.exp(ls - 1.96 * lsd)), float(np.exp(ls + 1.96 * lsd))],
                "unit": m.kind.unit.strip(),
            }
        terms.append(term)
        expr = expr + m.kind.sympy([_num4(x) for x in c], shape_val, sym_x)
    return terms, expr


def _formula_message(out: Discovered, min_share: float) -> str:
    best = out.flexible["input"]
    if not out.found:
        return (
            f"no formula found: the best formula {out.formula} removes {out.share:.0%} of what "
            f"the flexible term removes (needs {min_share:.0%}, an interval excluding zero and "
            f"more than the null); the flexible term's shape over {best} is the answer"
        )
    if out.named_instead:
        return (
            f"the formula's terms are those of the library effect {out.nearest_effect}: "
            f"report {out.nearest_effect} (formula {out.formula})"
        )
    return (
        f"formula found: {out.formula} (removes {out.shrink:.0%} of the held-out gap, "
        f"{out.share:.0%} of the flexible term's reduction)"
    )


# ------------------------------------------------------------------------------ entry

_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(DiscoveryOptions))


def discover(
    report_or_model: Any,
    calibration: Sequence[Experiment] | None = None,
    validation: Sequence[Experiment] | None = None,
    *,
    family: Any = "drive",
    options: DiscoveryOptions | None = None,
    progress: Any = None,
    **settings: Any,
) -> Discovered:
    """Discover an effect outside the library: a flexible term in the family's slot,
    scored against the null, then its formula from a typed dictionary (module doc).

    **Arguments:**

    - `report_or_model`: a [`DiagnosisReport`][jaxvs.diagnosis.DiagnosisReport] of
        `jaxvs.diagnose` (its final model and experiments are used), or a calibrated
        `GapModel`, with `calibration` and `validation` its prepared experiments (held
        out: the validation experiments are never fitted).
    - `family`: the family name (`"drive"`, `"thermal"`, `"tmf"`) or instance; taken
        from the report.
    - `options`: a [`DiscoveryOptions`][jaxvs.diagnosis.DiscoveryOptions]; its fields
        may also be given as keywords (`n_null=9`, `seed=1`, ...), which replace those
        of `options`.
    - `progress`: optional `callable(str)` told what runs.

    **Returns:** a [`Discovered`][jaxvs.diagnosis.Discovered].
    """
    unknown = set(settings) - _OPTION_NAMES
    if unknown:
        raise TypeError(
            f"discover: unknown setting(s) {', '.join(sorted(unknown))}; the settings are "
            f"the fields of DiscoveryOptions: {', '.join(sorted(_OPTION_NAMES))}."
        )
    opts = dataclasses.replace(options or DiscoveryOptions(), **settings)
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    model, calibration, validation, fam = _resolve(report_or_model, calibration, validation, family)
    rng = np.random.default_rng(opts.seed)
    prob = _problem(model, calibration, validation, fam, opts)

    say("discovery: the flexible term, input by input")
    flex = _flexible(prob)
    best = _choose_input(prob, flex)
    if opts.n_null:
        say(f"discovery: the same step on {opts.n_null} effect-free records")
    out = _fire(prob, flex, best, _null_reductions(prob, rng))
    if out.fired:
        say("discovery: the formula (evidence elimination, stability selection)")
        sel = _select(prob, flex, best, rng)
        out.frequencies = sel.freq
        out.shape = _shape(
            prob.exps,
            prob.n_cal,
            prob.basis,
            flex.thetas[prob.labels.index(best)],
            flex.p_model,
            best,
            flex.preds[-1],
            prob.slots,
            pred_flex=flex.pred(prob, best),
        )
        if not sel.final:
            for k in ("_keep", "_per", "_v", "_step"):
                out.shape.pop(k)
            out.message = (
                "no formula found: no term of the dictionary is kept in "
                f"{opts.stability:.0%} of the resamples; the flexible term's shape over "
                f"{best} is the answer"
            )
        else:
            say("discovery: recalibrating the formula")
            _recalibrate(prob, flex, sel, out)
        if opts.design and fam.name in DESIGN_FAMILIES and not out.named_instead:
            say("discovery: a rival formula, and the experiment that tells them apart")
            out.rival, out.next_experiment = _design_next(prob, sel)
    out.seconds = time.perf_counter() - t0
    return out


# ------------------------------------------------------------------------------ design


def _support_fit(sel: _Selection, support, rows_x=None):
    """Least squares of the record's residual on the base and the support's columns:
    `(coefficients, ssr)`."""
    A = np.concatenate([sel.Bs] + [sel.X[j][sel.rows] for j in support], 1)
    coef, *_ = np.linalg.lstsq(A, sel.rs, rcond=None)
    r = sel.rs - A @ coef
    return coef, float(r @ r)


def _rival(sel: _Selection, support) -> tuple[list[int], float] | None:
    """The best rival of `support` (one term swapped for a term of a kind not in it) and
    the log evidence of `support` over it."""
    n_eff, p_b = sel.n_eff, sel.Bs.shape[1]
    _, ssr0 = _support_fit(sel, [])

    def ev(sup):
        k = sum(sel.members[j].kind.k for j in sup)
        return log_evidence(_support_fit(sel, sup)[1], ssr0, n_eff - p_b, k, n_eff)

    kinds = {sel.members[j].kind.name for j in support}
    best = None
    for i in support:
        for j, m in enumerate(sel.members):
            if m.kind.name in kinds:
                continue
            sup = sorted([x for x in support if x != i] + [j])
            e = ev(sup)
            if best is None or e > best[1]:
                best = (sup, e)
    if best is None:
        return None
    return best[0], ev(support) - best[1]


def _candidate_experiment(prob: _Problem, t, sig) -> Experiment:
    """A slot experiment of the family on the candidate signal `sig` (relative to the
    records' start position), the target zero."""
    tpl = prob.calibration[0]
    n = t.size
    if prob.fam.name == "drive":
        q = float(np.asarray(tpl.arrays["q"])[0]) + sig
        v = np.gradient(q, t)
        arrays = {"q": q, "v": v, "a": np.gradient(v, t), "y": np.zeros(n)}
    else:
        pos = float(np.asarray(tpl.arrays["pos_y"])[0])
        arrays = {
            "x_e": sig,
            "pos_y": np.full(n, pos),
            "f": np.zeros(n),
            "f0": np.zeros(n),
            "y": np.zeros(n),
        }
    e = dataclasses.replace(tpl, t=t, arrays=arrays, ops={}, masks={})
    return _slot_experiment(e, prob.fam.name, prob.model)


def _design_next(
    prob: _Problem, sel: _Selection
) -> tuple[dict[str, Any] | None, NextExperiment | None]:
    """When a rival formula is within the evidence ratio `design_ratio` of the kept one,
    the candidate excitation within the records' limits on which the two (each fitted
    to the records with the model's Jacobian beside it) disagree most. The kept support
    is the formula's, or where stability selection kept none, the full-data
    elimination's (one member per kind)."""
    support = list(sel.final)
    if not support:
        by_kind: dict[str, int] = {}
        for j in sel.full.support:
            by_kind.setdefault(sel.members[j].kind.name, j)
        support = sorted(by_kind.values())
    found = _rival(sel, support) if support else None
    if found is None:
        return None, None
    rival, log_ratio = found

    def label(sup):
        return " + ".join(sel.members[j].label for j in sup)

    info = {"formula": label(support), "rival": label(rival), "log_evidence_ratio": log_ratio}
    if abs(log_ratio) >= math.log(prob.opts.design_ratio):
        return info, None
    fits = [(sup, _support_fit(sel, sup)[0]) for sup in (support, rival)]

    def outputs(B, cols):
        return [np.concatenate([B] + [cols[j] for j in sup], 1) @ coef for sup, coef in fits]

    rec = outputs(sel.Bs, {j: sel.X[j][sel.rows] for j in range(len(sel.members))})
    jac = _jacobian_fn(prob.model)
    lim = limits_from(prob.fam.name, prob.cal)

    def predict_pair(t, sig):
        e = _candidate_experiment(prob, t, sig)
        B = _base_jacobian(prob.model, sel.flat0, [e], jac)
        used = set(support) | set(rival)
        cols = {j: sel.members[j].evaluate(e.arrays) for j in used}
        pair = outputs(B, cols)
        if lim.force is not None and np.max(np.abs(e.arrays["yhat"] + pair[0])) > lim.force:
            return None  # beyond the largest recorded force
        return pair

    return info, design(
        prob.fam.name,
        lim,
        predict_pair,
        rec[0] - rec[1],
        (label(support), label(rival)),
        log_ratio,
    )


def _num4(x) -> float:
    return float(f"{float(x):.4g}")


def _symbols(names: Mapping[str, str]):
    """SymPy symbols of the slot inputs: array key -> symbol (printed by its name)."""
    import sympy as sp

    return {n: sp.Symbol(n, real=True) for n in names.values()}


def _member_columns(m: Member, cal: Sequence[Experiment], dyn) -> np.ndarray:
    """A member's columns on the calibration samples, through the lag `dyn` (per
    experiment, from zero) when it is not `None`."""
    cols = []
    for e in cal:
        x = m.evaluate(e.arrays)
        if dyn is not None:
            x = np.asarray(_lag_columns(jnp.asarray(x)[None], jnp.asarray(dyn.tau), dyn.dt))[0]
        cols.append(x)
    return np.concatenate(cols)


def _jacobian_fn(model):
    """`jac(flat, arrays)`: the Jacobian of the model's prediction with respect to its
    free parameters (compiled once per array shape)."""
    _, unravel, static = _split(model)

    def pred(theta, d):
        return unwrap(eqx.combine(unravel(theta), static))(d)

    return eqx.filter_jit(jax.jacfwd(pred))


def _base_jacobian(model, flat, cal, jac=None) -> np.ndarray:
    """Jacobian of the model's prediction on the calibration samples with respect to its
    free parameters (the columns the selection profiles out)."""
    jac = jac or _jacobian_fn(model)
    return np.concatenate([np.asarray(jac(jnp.asarray(flat), e.jax_arrays())) for e in cal])


def _formula_fit(model, flat0, prob, fm, start, bounds, mode="add"):
    """The formula's members `fm` and the model calibrated jointly from `start`
    (coefficients, log shapes) within the log-shape `bounds`; returns θ, the prediction,
    the Jacobian of the weighted residual and the weighted residual."""
    _, unravel, static = _split(model)
    exps = prob.exps
    st = _stack(exps, sorted(exps[0].arrays))
    w = np.zeros((len(exps), st["y"].shape[1]))
    for i, e in enumerate(exps[: prob.n_cal]):
        w[i, : e.n] = prob.scale
    fns = tuple((m.kind.columns, m.kind.k, m.shape is not None, mode) for m in fm)
    theta, pred, jtj, r_w = _fit_formula(
        unravel(jnp.asarray(flat0)),
        static,
        {k: jnp.asarray(v) for k, v in st.items()},
        jnp.asarray(st["y"]),
        jnp.asarray(w),
        tuple(jnp.asarray(x, float) for x in start),
        tuple(jnp.asarray(x, float) for x in bounds),
        fns,
        100,
    )
    return np.asarray(theta), np.asarray(pred), np.asarray(jtj), np.asarray(r_w)


def _covariance(jtj, r_w, free, n, residual) -> np.ndarray:
    """`s² τ (JᵀJ)⁻¹` on the free parameters (fixed ones: zero variance); `s²` from the
    weighted residual, `τ` its integrated autocorrelation time (at least 1)."""
    idx = np.flatnonzero(free)
    dof = max(n - idx.size, 1)
    s2 = float(np.sum(r_w**2)) / dof
    tau = max(1.0, integrated_time(residual) or 1.0)
    cov = np.zeros_like(jtj)
    sub = jtj[np.ix_(idx, idx)]
    cov[np.ix_(idx, idx)] = np.linalg.pinv(sub) * s2 * tau
    return cov


def _shape(
    exps, n_cal, basis, theta, p, label, pred0, slots=_DRIVE_SLOTS, pred_flex=None
) -> dict[str, Any]:
    """The flexible term of input `label` over its input, on the calibration samples:
    `x`, the term `flexible`, the partial residual `partial` (the residual without the
    flexible term). The term drawn is its net contribution, `pred_flex − pred0` (what the
    model with the term predicts beyond the model recalibrated without it: a part of the
    term the model's own parameters take up, such as a linear speed term a viscous
    coefficient absorbs, is not drawn), as the formula's is.
    For the term `v·f(t)` the figure is the viscous coefficient `f(t)`
    over time (term and residual divided by `v` where the speed is above 30 % of its top),
    likewise `s·f(t)` of the thermal heat flow (drawn before the lag)."""
    key = basis.inputs[label]
    c = np.asarray(theta[p:])
    sl = basis.blocks[label]
    xs, fl, pr, vs = [], [], [], []
    for i, e in enumerate(exps[:n_cal]):
        d = {k: jnp.asarray(e.arrays[k])[None] for k in basis.keys}
        phi = np.asarray(_basis_values(basis, d))[0]
        xs.append(np.asarray(e.arrays[key.split("*")[-1]]))
        if pred_flex is None or "*" in key:
            fl.append(phi[:, sl] @ c[sl])
        else:
            fl.append(pred_flex[i, : e.n] - pred0[i, : e.n])
        pr.append(e.y - pred0[i, : e.n])
        vs.append(np.asarray(e.arrays[key.split("*")[0]]))
    x, f, r, v = (np.concatenate(z) for z in (xs, fl, pr, vs))
    per_v = "*" in key
    keep = np.abs(v) > 0.3 * np.max(np.abs(v)) if per_v else np.ones(x.size, bool)
    if per_v:
        f, r = f / np.where(keep, v, 1.0), r / np.where(keep, v, 1.0)
    x, f, r = x[keep], f[keep], r[keep]
    step = max(1, x.size // 3000)
    ylabel = slots.product_ylabels.get(key, slots.ylabel)
    return {
        "label": slots.axis_labels[key],
        "ylabel": ylabel,
        "input": label,
        "x": x[::step],
        "flexible": f[::step],
        "partial": r[::step],
        "_keep": keep,
        "_per": per_v,
        "_v": v,
        "_step": step,
    }


def _formula_on(exps, n_cal, pred_f, pred0, shape) -> np.ndarray:
    """The formula's contribution on the samples of the figure (the formula fit minus
    the fit without it), divided by `v` where the figure shows `f(t)`."""
    d = np.concatenate([pred_f[i, : e.n] - pred0[i, : e.n] for i, e in enumerate(exps[:n_cal])])
    keep, v = shape.pop("_keep"), shape.pop("_v")
    if shape.pop("_per"):
        d = d / np.where(keep, v, 1.0)
    return d[keep][:: shape.pop("_step")]
