"""The pieces every model family of the diagnosis is made of.

- `Experiment`: one experiment after the family's preprocessing -- the arrays the model
  reads (`arrays`, with the measured target under `"y"`), the operating-point variables
  the gap map is drawn over (`ops`, `masks`), and the noise level of the target.
- `AbstractEffect`: a candidate unmodelled effect as a differentiable augmentation of
  the nominal model. It equals the nominal model when its size is zero. Fields named
  `size` hold the parameters the augmentation is linear in; everything else is a shape
  parameter (a frequency, a delay, a gap) searched on a grid and then calibrated. Every
  effect says whether its calibrated values are physically admissible
  (`admissible(context)`); an inadmissible fit is reported, never accepted.
- `AdmissibilityContext`: what the admissibility rules compare against (the record's
  sample time and position resolution, the analysed band, the nominal parameters).
- `EffectSpec`: the library entry of one effect -- its exact name (docs/guides/contracts.md), the
  signals it needs, the effect it extends (a Stribeck law contains Coulomb friction), and
  how to draw its starting points from the nominal residual.
- `GapModel`: the nominal model plus the effects added so far; a pure function of its
  parameters, calibrated by `jaxvs.calibrate` with Levenberg–Marquardt.
- `AbstractFamily`: what a family (drive, tmf, thermal) provides: preprocessing of a
  `jaxvs.data.Record`, the nominal model and its linear initialisation, the library.
"""

from __future__ import annotations

import abc
import dataclasses
import types
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..calibration import Positive, unwrap
from ..data import Record

__all__ = [
    "AbstractEffect",
    "AbstractFamily",
    "AdmissibilityContext",
    "EffectSpec",
    "Experiment",
    "GapModel",
    "NotIdentifiable",
]


class NotIdentifiable(Exception):
    """The record cannot identify the family's nominal model (no excitation, one
    direction only, too short, ...); the diagnosis answers with the reason instead of a
    verdict (docs/guides/contracts.md: `"verdict": null`, `"not_identifiable": reason`, exit 3)."""


@dataclasses.dataclass(frozen=True)
class Experiment:
    """One experiment as the diagnosis sees it (after the family's preprocessing).

    - `name`: a label (file name or `"experiment i"`).
    - `t`: analysis time base [s] (after any decimation), shape `(n,)`.
    - `arrays`: model inputs, all `(n,)` or `(n, k)` float arrays, and the target `"y"`.
    - `ops`: continuous operating-point variables over which the gap is mapped (speed,
      position, temperature, ...), each `(n,)`, keyed by a human label with its unit.
    - `masks`: named boolean operating-point cells (velocity reversals, pulses on, ...).
    - `noise_var`: variance of the measurement noise of `"y"` in the analysis band.
    - `signals`: the signal names the original record carried.
    - `source`: the original record (kept read-only, for figures).
    """

    name: str
    t: np.ndarray
    arrays: Mapping[str, np.ndarray]
    ops: Mapping[str, np.ndarray]
    masks: Mapping[str, np.ndarray]
    noise_var: float
    signals: frozenset[str]
    source: Record | None = None
    record_dt: float = 0.0  # sample time of the original record [s]
    resolution: float = 0.0  # quantisation step of the measured input (position) [unit]

    @property
    def y(self) -> np.ndarray:
        return np.asarray(self.arrays["y"])

    @property
    def n(self) -> int:
        return int(self.t.size)

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0]) if self.t.size > 1 else 1.0

    def jax_arrays(self) -> dict[str, Array]:
        return {k: jnp.asarray(v) for k, v in self.arrays.items()}

    def slice(self, start: int, stop: int, name: str | None = None) -> Experiment:
        """A contiguous block of this experiment (for hold-out by blocks)."""

        def cut(x):
            return np.asarray(x)[start:stop]

        return dataclasses.replace(
            self,
            name=name or f"{self.name}[{start}:{stop}]",
            t=cut(self.t),
            arrays={k: cut(v) for k, v in self.arrays.items()},
            ops={k: cut(v) for k, v in self.ops.items()},
            masks={k: cut(v) for k, v in self.masks.items()},
        )


@dataclasses.dataclass(frozen=True)
class AdmissibilityContext:
    """What the admissibility rules of the effects compare their parameters against.

    - `record_dt`: sample time of the original record [s] (a causal delay lasts at least
        one sample).
    - `analysis_dt`: sample time of the analysis arrays [s].
    - `band_hz`: `(low, high)` the analysed frequency band [Hz]: the lowest frequency the
        records resolve (two periods in the shortest experiment) and the upper edge of
        the preprocessing (drive: the low-pass cut-off; others: 0.45 of the sampling rate).
    - `resolution`: quantisation step of the measured position [m] (0 when unquantised).
    - `duration`: length of the shortest experiment [s].
    - `span`: travel of the measured position over all experiments [m] (drive).
    - `nominal`: the calibrated nominal parameters (e.g. `M`, `Fv` of the drive).
    - `nominal_model`: the calibrated nominal model (e.g. the TMF whose poles an effect
        moves).
    """

    record_dt: float
    analysis_dt: float
    band_hz: tuple[float, float]
    resolution: float = 0.0
    duration: float = float("inf")
    span: float = float("inf")
    nominal: Mapping[str, float] = dataclasses.field(default_factory=dict)
    nominal_model: Any = None  # the calibrated nominal model itself (e.g. a TMF)


Admissible = tuple[bool, str | None]
"""`(True, None)`, or `(False, reason)` with the rule that failed, in words."""


def check(*rules: tuple[bool, str]) -> Admissible:
    """The first failing rule's reason: `check((ok1, "why1"), (ok2, "why2"))`; non-finite
    values fail every comparison, so a NaN parameter is inadmissible."""
    for ok, reason in rules:
        if not bool(ok):
            return False, reason
    return True, None


def scalar(x: Any) -> float:
    """A one-entry parameter (0-d or `(1,)`) as a Python float, for reports and rules."""
    return float(np.asarray(x).reshape(-1)[0])


def floored_positive(x: Any) -> Positive:
    """A positive shape parameter as a log-parametrised leaf; a value that underflowed
    to zero (or went negative) in an earlier calibration restarts from a tiny floor."""
    x = jnp.asarray(x)
    return Positive(jnp.log(jnp.maximum(x, 1e-12)))


def delay_rules(
    tau: float, context: AdmissibilityContext, why: str = "", min_samples: float = 1.0
) -> tuple:
    """The physics of any delay (a force delay, a sensor delay): finite, causal, at least
    `min_samples` samples of the record (one: a computed or transported delay; a
    measurement chain's filter delays its channel by a fraction of a sample, so a sensor
    delay passes 0), and short against the record. `why` is appended to the non-causal
    reason (what cannot act early)."""
    return (
        (np.isfinite(tau), "non-finite delay"),
        (tau > 0, f"non-causal delay τ = {1e3 * tau:.3g} ms{why}"),
        (
            tau >= min_samples * context.record_dt * (1 - 1e-9),
            f"delay τ = {1e3 * tau:.3g} ms shorter than "
            f"{'one sample' if min_samples == 1 else f'{min_samples:g} samples'} "
            f"({1e3 * min_samples * context.record_dt:.3g} ms)",
        ),
        (tau < 0.1 * context.duration, f"delay τ = {tau:.3g} s not short against the record"),
    )


def exact_zero_at(cond: Array, e: Array) -> Array:
    """`e`, but exactly 0 where `cond` holds, keeping the derivative of `e` there (a
    `jnp.where` would zero it and stall the least-squares start at zero size)."""
    return e - jnp.where(cond, jax.lax.stop_gradient(e), 0.0)


def fft_delay(y: Float[Array, " n"], delay: Float[Array, ""]) -> Float[Array, " n"]:
    """`y` delayed by `delay` samples (any real number), band-limited: the phase of the
    spectrum of the even extension `[y, reversed y]` (continuous at both joints, so no
    ringing from the ends) is turned by `e^{−iωτ}`. Exactly `y` at zero delay."""
    n = y.shape[0]
    ext = jnp.concatenate([y, y[::-1]])
    freq = jnp.fft.rfftfreq(2 * n)
    out = jnp.fft.irfft(jnp.fft.rfft(ext) * jnp.exp(-2j * jnp.pi * freq * delay), 2 * n)[:n]
    return y + exact_zero_at(delay == 0, out - y)


class AbstractEffect(eqx.Module):
    """A candidate effect: an augmentation of the nominal model, nominal at zero size.

    Concrete effects are final classes that define `name` and `order` (class variables),
    `apply` (the augmented prediction), `parameters` (physical values, for the report)
    and `admissible` (the physics rules of the effect). Additive effects derive from
    [`AbstractAdditiveEffect`][] and define `contribution` instead of `apply`.

    `order` sets the composition: additive terms (0) before transforms of the whole
    prediction (1) and disturbance estimates (2).
    """

    name: eqx.AbstractClassVar[str]
    order: eqx.AbstractClassVar[int]

    @abc.abstractmethod
    def apply(
        self, y: Float[Array, " n"], arrays: Mapping[str, Array], nominal: Any
    ) -> Float[Array, " n"]:
        """The prediction `y` of the model without this effect, augmented by it."""

    @abc.abstractmethod
    def parameters(self) -> dict[str, float]:
        """The physical parameters of the effect, by name (with units in the name)."""

    @abc.abstractmethod
    def admissible(self, context: AdmissibilityContext) -> Admissible:
        """Whether the calibrated values are physically admissible, with the reason when
        not (a non-causal delay, a gap below the position resolution, an overdamped
        "resonance", negative friction, a negative mass ...). Concrete values only (run
        outside `jit`, on a calibrated effect)."""

    @abc.abstractmethod
    def constrained(self) -> AbstractEffect:
        """This effect with its constrained leaves reparametrised for calibration
        (`jaxvs.calibration.positive`, `fixed`); `unwrap` gives it back."""

    @abc.abstractmethod
    def extra_dof(self, arrays: Sequence[Mapping[str, Array]]) -> int:
        """Degrees of freedom beyond the calibrated leaves (for the information
        criterion), e.g. event locations found in the data; 0 for most effects."""


class AbstractAdditiveEffect(AbstractEffect):
    """An effect that adds a term to the prediction: `y + contribution(arrays, nominal)`."""

    @abc.abstractmethod
    def contribution(self, arrays: Mapping[str, Array], nominal: Any) -> Float[Array, " n"]:
        """The term the effect adds to the prediction (zero at zero size)."""

    def apply(self, y, arrays, nominal):
        return y + self.contribution(arrays, nominal)


class GapModel(eqx.Module):
    """Nominal model plus effects, applied in their `order()`:
    `y = T_k(... T_1(nominal) ...)`, each `T_i` exactly the identity at zero size.

    The engine recalibrates one model structure per candidate (all its starting shapes
    vmapped in one call), so effects are composed, never switched by data.
    """

    nominal: eqx.Module
    effects: tuple[AbstractEffect, ...] = ()

    def __call__(self, arrays: Mapping[str, Array]) -> Float[Array, " n"]:
        y = self.nominal(arrays)
        for effect in sorted(self.effects, key=lambda e: e.order):
            y = effect.apply(y, arrays, self.nominal)
        return y

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    def constrained(self) -> GapModel:
        return GapModel(self.nominal, tuple(e.constrained() for e in self.effects))

    def with_effect(self, effect: AbstractEffect, replaces: str | None = None) -> GapModel:
        effects = tuple(e for e in self.effects if e.name != replaces)
        return GapModel(self.nominal, effects + (effect,))


def predict(model: GapModel, exp: Experiment) -> np.ndarray:
    """Prediction of a (possibly wrapped) model on one experiment, as NumPy."""
    return np.asarray(_predict(unwrap(model), exp.jax_arrays()))


@eqx.filter_jit
def _predict(model: GapModel, arrays: dict[str, Array]) -> Array:
    return model(arrays)


@dataclasses.dataclass(frozen=True)
class Context:
    """What an effect's starting-point generator may look at."""

    model: GapModel  # the current (unwrapped) model
    experiments: Sequence[Experiment]  # calibration experiments
    residuals: Sequence[np.ndarray]  # y - model prediction, per experiment
    options: Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class EffectSpec:
    """One entry of a family's library of candidate effects.

    - `name`: the exact effect name of docs/guides/contracts.md.
    - `requires`: signals that must be present in every experiment.
    - `templates`: `Context -> list of effects` at zero (or least-squares) size, one per
        starting shape; the best by calibration residual seeds the recalibration.
    - `extends`: the name of a simpler effect this one contains (Stribeck contains
        Coulomb); the extension replaces its base in the model when added after it.
    - `testable`: optional `experiments -> reason or None` for conditions beyond signals
        (e.g. position dependence needs more than one position).
    - `signature`: the regressor the signature is drawn against in the figures.
    - `description`: one line for the report.
    - `refresh`: optional `(experiment, residual) -> experiment` run on every experiment
        (calibration and validation) before the effect is tried, to attach data the
        effect reads (e.g. the events of an unmeasured disturbance).
    """

    name: str
    requires: tuple[str, ...]
    templates: Callable[[Context], list[AbstractEffect]]
    extends: str | None = None
    testable: Callable[[Sequence[Experiment]], str | None] | None = None
    signature: str = ""
    description: str = ""
    refresh: Callable[[Experiment, np.ndarray], Experiment] | None = None

    def not_testable(self, experiments: Sequence[Experiment]) -> str | None:
        missing = sorted({s for e in experiments for s in self.requires if s not in e.signals})
        if missing:
            return f"needs signal(s) {', '.join(missing)}, absent from the data"
        if self.testable is not None:
            return self.testable(experiments)
        return None


class AbstractFamily(abc.ABC):
    """A model family of the diagnosis (`drive`, `tmf`, `thermal`): a frozen
    configuration (its options, read-only); every method is a function of its arguments.

    Besides preprocessing, the nominal model and the library, a family says whether a
    record identifies its nominal model (`identifiability`), what the admissibility rules
    of its effects compare against (`admissibility_context`), and how effect-free records
    of the same set-up are simulated (`null_experiments`, the null every candidate must
    beat). Options are validated against `option_keys`.
    """

    name: ClassVar[str]
    required: ClassVar[tuple[str, ...]]
    optional: ClassVar[tuple[str, ...]]
    option_keys: ClassVar[tuple[str, ...]]
    metric: ClassVar[str] = "nrmse"
    early_layout: ClassVar[bool] = False
    """Whether the structure of the library's templates is known before the nominal
    calibration (the search then compiles one fitting program for the nominal model, the
    null refits and the rounds)."""
    target_label: ClassVar[str] = "target"
    singular_rtol: ClassVar[float] = 1e-6
    """The relative singular value of the column-scaled Jacobian of the nominal model below
    which `jaxvs check` and the diagnosis call a parameter combination unidentifiable."""
    record_advice: ClassVar[Mapping[str, str]] = {}
    """What to record so that a nominal parameter becomes identifiable (named in refusals)."""
    options: Mapping[str, Any]
    """The options the family was built with (read-only)."""

    def __init__(self, **options: Any):
        unknown = sorted(set(options) - set(self.option_keys))
        if unknown:
            raise ValueError(
                f"diagnose(family={self.name!r}): unknown option(s) {unknown}; the "
                f"{self.name} family takes {list(self.option_keys)}."
            )
        # read-only: what a family derives from the data is returned (`prepare`'s
        # experiments, the nominal model, `settings`), never written back into it
        object.__setattr__(self, "options", types.MappingProxyType(dict(options)))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(
            f"{type(self).__name__} is a frozen configuration: give its options when it is "
            f"built ({type(self).__name__}(**options)); what it derives from data is "
            f"returned by its methods, never stored on it (cannot set {name!r})."
        )

    def __delattr__(self, name: str) -> None:
        raise AttributeError(
            f"{type(self).__name__} is a frozen configuration (cannot delete {name!r})."
        )

    @abc.abstractmethod
    def prepare(self, record: Record, name: str) -> Experiment:
        """Validate a record and turn it into the arrays the model reads."""

    @abc.abstractmethod
    def nominal(self, experiments: Sequence[Experiment]) -> eqx.Module:
        """The nominal model, initialised (e.g. by linear least squares) on `experiments`."""

    @abc.abstractmethod
    def library(self) -> list[EffectSpec]:
        """The candidate effects of this family, in the order of docs/guides/contracts.md."""

    @abc.abstractmethod
    def identifiability(self, experiments: Sequence[Experiment], model: GapModel) -> str | None:
        """`None` when the calibration experiments identify the calibrated nominal model
        `model`, else the reason in words (e.g. "the force never reverses: motion in one
        direction only")."""

    @abc.abstractmethod
    def admissibility_context(
        self, experiments: Sequence[Experiment], model: GapModel
    ) -> AdmissibilityContext:
        """What the effects' admissibility rules compare against, for these experiments."""

    @abc.abstractmethod
    def null_experiments(
        self,
        model: GapModel,
        experiments: Sequence[Experiment],
        rng: np.random.Generator,
        count: int,
    ) -> list[list[Experiment]]:
        """`count` effect-free copies of `experiments`: the calibrated model `model`
        simulated through each record's own set-up (sampling, quantisation, noise level,
        loop and preprocessing). Returns `count` lists, each like `experiments`."""

    def nominal_warnings(self, experiments: Sequence[Experiment]) -> tuple[str, ...]:
        """What the nominal model's start on `experiments` had to fix or bound, in words
        (e.g. a mass the record does not excite); reported as warnings. None by default."""
        return ()

    def settings(self, experiments: Sequence[Experiment]) -> dict[str, Any]:
        """The options as the analysis of `experiments` used them, with the values it
        derived from the data (e.g. a default cut-off); the report's `data.options`."""
        return dict(self.options)

    def nominal_parameters(
        self, model: GapModel, experiments: Sequence[Experiment]
    ) -> dict[str, float]:
        """The calibrated nominal model's physical parameters, by name (every nominal
        model states them: `parameters()`), in the terms of the calibration `experiments`
        (e.g. the thermal regression's input biases, each input's minimum over them)."""
        return unwrap(model.nominal).parameters()

    def describe_nominal(self) -> str:
        return ""
