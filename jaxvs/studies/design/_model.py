"""The virtual sensor a design search returns: named inputs, their delays, the
normalisation, and one of the searched model structures, as one `eqx.Module` that
`jaxvs.save_model` writes and `jaxvs.load_model` reads back.

Every structure works on the same *features*: the inputs normalised to [-1, 1] by their
training ranges (MATLAB `mapminmax`, as the study's networks) and their delayed copies
`u_i(k - d)`; before the first sample an input is held at its first value (the machine at
rest in its initial state), so a prediction has one value per input sample.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import concrete
from ...data import Record
from ...models import AbstractModel, Perceptron

__all__ = [
    "AbstractDesignCore",
    "ARXCore",
    "DesignedSensor",
    "LagCore",
    "LinearCore",
    "NetworkCore",
]

STRUCTURES: tuple[str, ...] = ("regression", "lag", "arx", "mlp", "tdnn")


class AbstractDesignCore(eqx.Module):
    """A model from normalised features `(time, feature)` to the normalised target
    `(time,)`; `reset` `(time,)` marks the first sample of each experiment (dynamic
    cores restart there in steady state)."""

    @abc.abstractmethod
    def __call__(
        self, X: Float[Array, "time feature"], reset: Array | None = None
    ) -> Float[Array, " time"]:
        """Normalised prediction `(time,)`."""


class LinearCore(AbstractDesignCore):
    """`y = X w + b`: the study's static regression (eq. 2-3; bias-free inputs are an
    affine change of the normalised ones, so the fit is the same)."""

    w: Float[Array, " feature"]
    b: Float[Array, ""]

    def __call__(self, X, reset=None):
        return X @ self.w + self.b


def _recursion(v: Array, a: Array, reset: Array | None, gain: Array) -> Array:
    """`y(k) = Σ_j a_j y(k-j) + gain · v(k)`, started (and restarted at `reset`) in the
    steady state of the current `v`: `y = gain · v / (1 - Σ a)`."""
    na = a.shape[0]
    reset = jnp.zeros(v.shape, bool).at[0].set(True) if reset is None else reset.at[0].set(True)
    ss = gain / (1.0 - jnp.sum(a))

    def step(hist, vr):
        vk, rk = vr
        hist = jnp.where(rk, jnp.full((na,), ss * vk), hist)
        yk = jnp.dot(a, hist) + gain * vk
        return jnp.concatenate([yk[None], hist[:-1]]), yk

    return jax.lax.scan(step, jnp.zeros((na,), v.dtype), (v, reset))[1]


class LagCore(AbstractDesignCore):
    """First-order lag of a linear combination: `y(k) = a y(k-1) + (1-a)(X(k) w + b)`,
    `a = exp(-dt/τ)`: the thermal time constant `τ` (the exact ZOH discretisation of
    `τ ẏ + y = x w + b`, study eq. 1)."""

    a: Float[Array, ""]
    w: Float[Array, " feature"]
    b: Float[Array, ""]

    def __call__(self, X, reset=None):
        return _recursion(X @ self.w + self.b, self.a[None], reset, 1.0 - self.a)


class ARXCore(AbstractDesignCore):
    """Linear dynamic model `y(k) = Σ_j a_j y(k-j) + X(k) w + b` (ARX structure, fitted by
    equation error and used by simulation: a virtual sensor never sees the target)."""

    a: Float[Array, " na"]
    w: Float[Array, " feature"]
    b: Float[Array, ""]

    def __call__(self, X, reset=None):
        return _recursion(X @ self.w + self.b, self.a, reset, jnp.asarray(1.0, X.dtype))


class NetworkCore(AbstractDesignCore):
    """The study's two-layer `tansig` network (static ANN on delay 0, TDNN with delays)."""

    perceptron: Perceptron

    def __call__(self, X, reset=None):
        p = self.perceptron
        return jnp.tanh(X @ p.W1.T + p.b1) @ p.W2 + p.b2


def delayed_features(U: np.ndarray, starts: np.ndarray, columns) -> np.ndarray:
    """`(time, feature)` delayed copies `U[k - d, i]` for `(i, d)` in `columns`, each
    experiment (from a `starts` sample on) held at its first value before it began; `d =
    -1` denotes the square `U[k, i]²`."""
    n = U.shape[0]
    first = np.maximum.accumulate(np.where(starts, np.arange(n), 0))
    out = np.empty((n, len(columns)), U.dtype)
    for c, (i, d) in enumerate(columns):
        out[:, c] = U[:, i] ** 2 if d < 0 else U[np.maximum(np.arange(n) - d, first), i]
    return out


class DesignedSensor(AbstractModel):
    """A virtual sensor found by [`jaxvs.design`][]: `target ≈ f(inputs and their delays)`.

    **Fields:**

    - `inputs`: the input signal names, in order; `target`: the target's name.
    - `columns`: `((input index, delay [samples]), ...)`, the features in order; delay
      `-1` is the square of the (normalised) input.
    - `structure`: one of `"regression"`, `"lag"`, `"arx"`, `"mlp"`, `"tdnn"`.
    - `dt`: sampling period the delays and dynamics refer to [s].
    - `u_offset`, `u_scale`: `(input,)` normalisation `(u - offset) / scale`;
      `y_offset`, `y_scale`: target de-normalisation `offset + scale · ŷ`.
    - `core`: the fitted model on the normalised features.

    Call it with a `jaxvs.data.Record` (or a mapping name -> array) holding the inputs, or
    with an array `(time, input)` in the order of `inputs`; it returns `(time,)`. As a
    `jaxvs.models.AbstractModel`, `predict(u, dt)` is the same prediction from the input
    array (pure JAX: `jit`, `vmap`, gradients, `jaxvs.calibrate`).
    """

    inputs: tuple[str, ...] = eqx.field(static=True)
    target: str = eqx.field(static=True)
    columns: tuple[tuple[int, int], ...] = eqx.field(static=True)
    structure: str = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    u_offset: Float[Array, " input"]
    u_scale: Float[Array, " input"]
    y_offset: Float[Array, ""]
    y_scale: Float[Array, ""]
    core: AbstractDesignCore

    @property
    def delays(self) -> dict[str, list[int]]:
        out: dict[str, list[int]] = {n: [] for n in self.inputs}
        for i, d in self.columns:
            if d >= 0:
                out[self.inputs[i]].append(int(d))
        return out

    def _matrix(self, data: Any) -> np.ndarray:
        if isinstance(data, Record | Mapping):
            missing = [n for n in self.inputs if n not in data]
            if missing:
                have = list(data.names) if isinstance(data, Record) else sorted(data)
                raise ValueError(
                    f"DesignedSensor: the data lack the input(s) {missing} (they have {have})."
                )
            U = np.column_stack([np.asarray(data[n], float) for n in self.inputs])
            if isinstance(data, Record) and abs(data.dt - self.dt) > 1e-9 * self.dt:
                raise ValueError(
                    f"DesignedSensor: the record is sampled every {data.dt} s but the sensor "
                    f"was designed at {self.dt} s (its delays and dynamics are in samples). "
                    "Resample the record first."
                )
        else:
            U = np.asarray(data, float)
            if U.ndim == 1 and len(self.inputs) == 1:
                U = U[:, None]
        if U.ndim != 2 or U.shape[1] != len(self.inputs) or U.shape[0] < 1:
            raise ValueError(
                f"DesignedSensor: inputs must have shape (time, {len(self.inputs)}) in the order "
                f"{list(self.inputs)}; got {U.shape}."
            )
        if not np.all(np.isfinite(U)):
            raise ValueError("DesignedSensor: the inputs have NaN/inf; cut or fill them first.")
        return U

    def __call__(self, data: Any) -> Float[Array, " time"]:
        """The predicted target `(time,)` [target unit] for one experiment."""
        return self.predict(self._matrix(data), self.dt)

    def predict(self, u: Float[ArrayLike, "time input"], dt: float) -> Float[Array, " time"]:
        """The predicted target `(time,)` from the inputs `(time, input)` in the order of
        `inputs`, sampled every `dt` [s] (the sensor's own `dt`: its delays and dynamics
        count samples)."""
        value = concrete(dt)
        if value is not None and abs(float(value) - self.dt) > 1e-9 * self.dt:
            raise ValueError(
                f"DesignedSensor: the inputs are sampled every {float(value)} s but the "
                f"sensor was designed at {self.dt} s (its delays and dynamics are in "
                "samples). Resample the inputs first."
            )
        U = jnp.asarray(u)
        if U.ndim == 1 and len(self.inputs) == 1:
            U = U[:, None]
        if U.ndim != 2 or U.shape[1] != len(self.inputs):
            raise ValueError(
                f"DesignedSensor: inputs must have shape (time, {len(self.inputs)}) in the order "
                f"{list(self.inputs)}; got {U.shape}."
            )
        Un = (U - self.u_offset) / self.u_scale
        k = jnp.arange(U.shape[0])
        # held at the first sample before the record began (the machine at rest)
        X = jnp.stack(
            [Un[:, i] ** 2 if d < 0 else Un[jnp.maximum(k - d, 0), i] for i, d in self.columns],
            axis=1,
        )
        return self.y_offset + self.y_scale * self.core(X, k == 0)
