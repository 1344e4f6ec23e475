"""The pieces every model family of the diagnosis is made of.

- `Experiment`: one experiment after the family's preprocessing -- the arrays the model
  reads (`arrays`, with the measured target under `"y"`), the operating-point variables
  the gap map is drawn over (`ops`, `masks`), and the noise level of the target.
- `AbstractEffect`: a candidate unmodelled effect as a differentiable augmentation of
  the nominal model. It equals the nominal model when its size is zero. Fields named
  `size` hold the parameters the augmentation is linear in; everything else is a shape
  parameter (a frequency, a delay, a gap) searched on a grid and then calibrated.
- `EffectSpec`: the library entry of one effect -- its exact name (DESIGN.md §3.2), the
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
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..calibration import unwrap
from ..data import Record

__all__ = ["AbstractEffect", "AbstractFamily", "EffectSpec", "Experiment", "GapModel"]


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


class AbstractEffect(eqx.Module):
    """A candidate effect: an augmentation of the nominal model, nominal at zero size.

    Additive effects implement `contribution(arrays, nominal)`; effects that transform
    the whole prediction (a delay, a thermal lag) override `apply`.
    """

    name: ClassVar[str]

    def contribution(self, arrays: Mapping[str, Array], nominal: Any) -> Float[Array, " n"]:
        raise NotImplementedError

    def apply(
        self, y: Float[Array, " n"], arrays: Mapping[str, Array], nominal: Any
    ) -> Float[Array, " n"]:
        return y + self.contribution(arrays, nominal)

    @abc.abstractmethod
    def parameters(self) -> dict[str, float]:
        """The physical parameters of the effect, by name (with units in the name)."""

    def physical(self) -> bool:
        """Whether the calibrated values are physically admissible (e.g. a non-negative
        mass); an inadmissible fit is never accepted."""
        return True

    def order(self) -> int:
        """Effects are applied in increasing order: additive terms (0) before transforms
        of the whole prediction (1) and disturbance estimates (2)."""
        return 0

    def constrained(self) -> AbstractEffect:
        """This effect with its constrained leaves reparametrised for calibration
        (`jaxvs.calibration.positive`, `fixed`); `unwrap` gives it back."""
        return self

    def extra_dof(self, arrays: Sequence[Mapping[str, Array]]) -> int:
        """Degrees of freedom beyond the calibrated leaves (for ΔBIC), e.g. event
        locations found in the data."""
        return 0


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
        for effect in sorted(self.effects, key=lambda e: e.order()):
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

    - `name`: the exact effect name of DESIGN.md §3.2.
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
    """A model family of the diagnosis (`drive`, `tmf`, `thermal`)."""

    name: ClassVar[str]
    required: ClassVar[tuple[str, ...]]
    optional: ClassVar[tuple[str, ...]]
    metric: ClassVar[str] = "nrmse"
    target_label: ClassVar[str] = "target"

    def __init__(self, **options: Any):
        self.options = dict(options)

    @abc.abstractmethod
    def prepare(self, record: Record, name: str) -> Experiment:
        """Validate a record and turn it into the arrays the model reads."""

    @abc.abstractmethod
    def nominal(self, experiments: Sequence[Experiment]) -> eqx.Module:
        """The nominal model, initialised (e.g. by linear least squares) on `experiments`."""

    @abc.abstractmethod
    def library(self) -> list[EffectSpec]:
        """The candidate effects of this family, in DESIGN.md's order."""

    def nominal_parameters(self, model: GapModel) -> dict[str, float]:
        nom = unwrap(model.nominal)
        if hasattr(nom, "parameters"):
            return nom.parameters()
        return {}

    def describe_nominal(self) -> str:
        return ""
