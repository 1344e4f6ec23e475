"""Virtual-sensor networks of the thermal study: a static two-layer perceptron and a
time-delay network (TDNN), as `eqx.Module`s.

Dementjev et al. (2014), Fig. 7: a two-layer feed-forward network with `tansig` hidden
units and a linear output (MATLAB `feedforwardnet`), and the same network with tapped
delay lines on every input (`timedelaynet`, delays 0, 1, 2). As in MATLAB, inputs and
output are normalised to [-1, 1] by their training ranges (`mapminmax`); the
normalisation is part of the model but is not trained.

Both networks are a [`Perceptron`][] (the trainable weights) applied sample by sample to
*features*: the normalised inputs (static network) or the normalised inputs and their
delayed copies (TDNN). Trainers (`jaxvs.calibration.train_lm`, `train_adam`) train the
perceptron on `net.features(u)`; batching over samples is one `vmap`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

__all__ = ["Perceptron", "StaticNetwork", "TimeDelayNetwork"]


class Perceptron(eqx.Module):
    """`y = W2 · tanh(W1 x + b1) + b2`: one hidden `tanh` layer, one linear output.

    **Arguments:**

    - `n_features`: inputs per sample; `n_hidden`: hidden units.
    - `key`: PRNG key of the initial weights (Nguyen-Widrow-like: hidden weights of norm
      `0.7 n_hidden^(1/n_features)` in random directions, biases spread over [-1, 1] times
      that norm, as MATLAB's `initnw`, for inputs normalised to [-1, 1]).
    """

    W1: Float[Array, "hidden feature"]
    b1: Float[Array, " hidden"]
    W2: Float[Array, " hidden"]
    b2: Float[Array, ""]

    def __init__(self, n_features: int, n_hidden: int, *, key: PRNGKeyArray, dtype=None):
        if not (isinstance(n_features, int) and n_features > 0):
            raise ValueError(f"Perceptron: n_features must be a positive int, got {n_features!r}.")
        if not (isinstance(n_hidden, int) and n_hidden > 0):
            raise ValueError(f"Perceptron: n_hidden must be a positive int, got {n_hidden!r}.")
        dtype = jnp.result_type(float) if dtype is None else dtype
        k1, k2, k3 = jr.split(key, 3)
        beta = 0.7 * n_hidden ** (1.0 / n_features)
        w = jr.normal(k1, (n_hidden, n_features), dtype)
        w = beta * w / jnp.linalg.norm(w, axis=1, keepdims=True)
        self.W1 = w
        self.b1 = (
            beta
            * jnp.linspace(-1.0, 1.0, n_hidden, dtype=dtype)
            * jnp.sign(jr.normal(k2, (n_hidden,), dtype))
        )
        self.W2 = jr.uniform(k3, (n_hidden,), dtype, -1.0, 1.0) / jnp.sqrt(n_hidden)
        self.b2 = jnp.zeros((), dtype)

    @property
    def n_features(self) -> int:
        return self.W1.shape[1]

    @property
    def n_hidden(self) -> int:
        return self.W1.shape[0]

    def __call__(self, x: Float[Array, " feature"]) -> Float[Array, ""]:
        """Output for one sample of (normalised) features."""
        return jnp.dot(self.W2, jnp.tanh(self.W1 @ x + self.b1)) + self.b2

    def jacobian(self, X: Float[Array, "sample feature"]) -> Float[Array, "sample weight"]:
        """Jacobian of the outputs for all samples `X` with respect to all weights, in the
        order of `jax.flatten_util.ravel_pytree` (`W1` row-major, `b1`, `W2`, `b2`).

        Closed form of backpropagation through one hidden layer: with
        `h = tanh(W1 x + b1)` and `d = W2 (1 - h²)`, `∂y/∂W1 = d xᵀ`, `∂y/∂b1 = d`,
        `∂y/∂W2 = h`, `∂y/∂b2 = 1`; O(samples · weights), no per-sample autodiff.
        """
        h = jnp.tanh(X @ self.W1.T + self.b1)
        d = (1 - h**2) * self.W2
        n = X.shape[0]
        return jnp.concatenate(
            [(d[:, :, None] * X[:, None, :]).reshape(n, -1), d, h, jnp.ones((n, 1), X.dtype)],
            axis=1,
        )


def _as_inputs(u: ArrayLike, n_inputs: int, where: str) -> Array:
    u = jnp.asarray(u)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u = u.astype(jnp.result_type(float))
    if u.ndim == 1 and n_inputs == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[1] != n_inputs:
        raise ValueError(
            f"{where}: inputs must have shape (time, {n_inputs}) (one column per input); "
            f"got {u.shape}."
        )
    return u


def _range_fields(lo, hi, n: int | None, dtype):
    """mapminmax: offset = mid-range, scale = half-range (1 where the range is empty)."""
    shape = () if n is None else (n,)
    lo = jnp.broadcast_to(jnp.asarray(-1.0 if lo is None else lo, dtype), shape)
    hi = jnp.broadcast_to(jnp.asarray(1.0 if hi is None else hi, dtype), shape)
    half = (hi - lo) / 2
    return (lo + hi) / 2, jnp.where(half > 0, half, 1.0)


class StaticNetwork(eqx.Module):
    """Static two-layer network: `y(k) = f(u(k))` (the study's static ANN, Fig. 7(a)).

    **Arguments:**

    - `n_inputs`: number of input signals; `n_hidden`: hidden `tanh` units.
    - `key`: PRNG key of the initial weights.
    - `input_range`: `(lo, hi)` per input, mapped to [-1, 1] (default: no scaling);
      `output_range`: `(lo, hi)` of the target, mapped to [-1, 1]. The trainers set
      both from the training data (MATLAB's `mapminmax`) unless told otherwise.
    """

    perceptron: Perceptron
    u_offset: Float[Array, " input"]
    u_scale: Float[Array, " input"]
    y_offset: Float[Array, ""]
    y_scale: Float[Array, ""]

    def __init__(
        self,
        n_inputs: int,
        n_hidden: int = 15,
        *,
        key: PRNGKeyArray,
        input_range: tuple[ArrayLike, ArrayLike] | None = None,
        output_range: tuple[ArrayLike, ArrayLike] | None = None,
    ):
        self.perceptron = Perceptron(n_inputs, n_hidden, key=key)
        dtype = self.perceptron.W1.dtype
        lo, hi = (None, None) if input_range is None else input_range
        self.u_offset, self.u_scale = _range_fields(lo, hi, n_inputs, dtype)
        lo, hi = (None, None) if output_range is None else output_range
        self.y_offset, self.y_scale = _range_fields(lo, hi, None, dtype)

    @property
    def n_inputs(self) -> int:
        return self.u_offset.shape[0]

    @property
    def max_delay(self) -> int:
        return 0

    def features(self, u: Float[ArrayLike, "time input"]) -> Float[Array, "time feature"]:
        """Normalised inputs, one row per sample."""
        u = _as_inputs(u, self.n_inputs, "StaticNetwork")
        return (u - self.u_offset) / self.u_scale

    def output(self, yn: Float[Array, "..."]) -> Float[Array, "..."]:
        """Normalised output -> physical units."""
        return self.y_offset + self.y_scale * yn

    def __call__(self, u: Float[ArrayLike, "time input"]) -> Float[Array, " time"]:
        """Prediction `(time,)` for inputs `u` of shape `(time, input)`."""
        return self.output(jax.vmap(self.perceptron)(self.features(u)))


class TimeDelayNetwork(eqx.Module):
    """Time-delay network (TDNN): `y(k) = f(u(k), u(k-1), ..., u(k-d))` (study Fig. 7(b)).

    **Arguments:**

    - `n_inputs`: number of input signals; `n_hidden`: hidden `tanh` units.
    - `delays`: the input delays in samples (the study: `(0, 1, 2)`).
    - `key`, `input_range`, `output_range`: as [`StaticNetwork`][].

    Before the first sample the inputs are taken as constant at their first value (the
    machine at rest in its initial state), so the output has one value per input sample.
    """

    perceptron: Perceptron
    u_offset: Float[Array, " input"]
    u_scale: Float[Array, " input"]
    y_offset: Float[Array, ""]
    y_scale: Float[Array, ""]
    delays: tuple[int, ...] = eqx.field(static=True)

    def __init__(
        self,
        n_inputs: int,
        n_hidden: int = 15,
        delays: tuple[int, ...] = (0, 1, 2),
        *,
        key: PRNGKeyArray,
        input_range: tuple[ArrayLike, ArrayLike] | None = None,
        output_range: tuple[ArrayLike, ArrayLike] | None = None,
    ):
        delays = tuple(int(d) for d in delays)
        if not delays or any(d < 0 for d in delays) or len(set(delays)) != len(delays):
            raise ValueError(
                f"TimeDelayNetwork: delays must be distinct non-negative sample counts, e.g. "
                f"(0, 1, 2); got {delays}."
            )
        self.delays = delays
        self.perceptron = Perceptron(n_inputs * len(delays), n_hidden, key=key)
        dtype = self.perceptron.W1.dtype
        lo, hi = (None, None) if input_range is None else input_range
        self.u_offset, self.u_scale = _range_fields(lo, hi, n_inputs, dtype)
        lo, hi = (None, None) if output_range is None else output_range
        self.y_offset, self.y_scale = _range_fields(lo, hi, None, dtype)

    @property
    def n_inputs(self) -> int:
        return self.u_offset.shape[0]

    @property
    def max_delay(self) -> int:
        return max(self.delays)

    def features(self, u: Float[ArrayLike, "time input"]) -> Float[Array, "time feature"]:
        """Normalised inputs and their delayed copies: `[u(k-d) for d in delays]` per row."""
        u = _as_inputs(u, self.n_inputs, "TimeDelayNetwork")
        un = (u - self.u_offset) / self.u_scale
        d = self.max_delay
        padded = jnp.concatenate([jnp.repeat(un[:1], d, axis=0), un], axis=0)
        n = un.shape[0]
        cols = [jax.lax.dynamic_slice_in_dim(padded, d - k, n, axis=0) for k in self.delays]
        return jnp.concatenate(cols, axis=1)

    def output(self, yn: Float[Array, "..."]) -> Float[Array, "..."]:
        """Normalised output -> physical units."""
        return self.y_offset + self.y_scale * yn

    def __call__(self, u: Float[ArrayLike, "time input"]) -> Float[Array, " time"]:
        """Prediction `(time,)` for inputs `u` of shape `(time, input)`."""
        return self.output(jax.vmap(self.perceptron)(self.features(u)))
