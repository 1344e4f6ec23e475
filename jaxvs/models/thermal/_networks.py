"""Virtual-sensor networks of the thermal study: a static two-layer perceptron and a
time-delay network (TDNN), as `eqx.Module`s.

Dementjev et al. (2014), Fig. 7: a two-layer feed-forward network with `tansig` hidden
units and a linear output (MATLAB `feedforwardnet`), and the same network with tapped
delay lines on every input (`timedelaynet`, delays 0, 1, 2). As in MATLAB, inputs and
output are normalised to [-1, 1] by their training ranges (`mapminmax`); the
normalisation is part of the model but is not trained.

Both networks are a [`Perceptron`][] (the trainable weights) applied sample by sample to
*features*: the normalised inputs (static network) or the normalised inputs and their
delayed copies (TDNN). Trainers (`jaxvs.studies.train_lm`, `train_adam`) train the
perceptron on `net.features(u)`; batching over samples is one `vmap`.
"""

import abc
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from ..._misc import input_columns
from .._base import AbstractModel

__all__ = ["AbstractNetwork", "Perceptron", "StaticNetwork", "TimeDelayNetwork"]


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

    def normal_equations(
        self,
        X: Float[Array, "sample feature"],
        e: Float[Array, " sample"],
        *,
        dtype=None,
        chunk: int = 256,
    ) -> tuple[Float[Array, "weight weight"], Float[Array, " weight"]]:
        """Gauss-Newton normal equations `(JᵀJ, Jᵀe)` of all weights (order of
        [`jacobian`][]), without forming `J`.

        With `x̃ = [x, 1]`, `h̃ = [h, 1]` and `d = W2 (1 - h²)`, the rows of `J` are
        `[d ⊗ x̃, h̃]` (hidden weights and biases, then output weights and bias), so the
        hidden block of `JᵀJ` is `Σᵢ (dᵢdᵢᵀ) ⊗ (x̃ᵢx̃ᵢᵀ)`. Both factors are symmetric: one
        product of their upper triangles, `(H(H+1)/2) × ((F+1)(F+2)/2)` per sample (120 × 28
        for the study's TDNN) instead of `P² = 121²`, gives every entry; the mixed and
        output blocks are `(d ⊗ x̃)ᵀh̃` and `h̃ᵀh̃`. Samples are accumulated in chunks of
        `chunk` rows (`lax.scan`) so each chunk's products stay in cache.

        - `X`: `(sample, feature)` normalised features; `e`: `(sample,)` output errors.
        - `dtype`: dtype of the sample products and their sums (default `X.dtype`;
          `float32` under float64 halves the cost at ~1e-7 relative accuracy); the result
          is returned in `X.dtype`.
        """
        H, F = self.W1.shape
        n = X.shape[0]
        dtype = X.dtype if dtype is None else dtype
        ju, ku, ia, ib, gather_r, gather_c, order = _normal_equation_maps(H, F)
        size = max(1, min(int(chunk), n))
        n_chunks = -(-n // size)
        pad = n_chunks * size - n
        live = jnp.concatenate([jnp.ones(n, X.dtype), jnp.zeros(pad, X.dtype)])
        Xp = jnp.concatenate([X, jnp.zeros((pad, F), X.dtype)]).reshape(n_chunks, size, F)
        ep = jnp.concatenate([e, jnp.zeros(pad, e.dtype)]).reshape(n_chunks, size)
        live = live.reshape(n_chunks, size)

        def tdot(a, b):  # aᵀb over the sample axis, accumulated in `dtype`
            return jax.lax.dot_general(
                a.astype(dtype), b.astype(dtype), (((0,), (0,)), ((), ())),
                preferred_element_type=dtype,
            )  # fmt: skip

        def body(carry, chunk_data):
            x, err, m = chunk_data
            h = jnp.tanh(x @ self.W1.T + self.b1)
            d = (1 - h**2) * self.W2 * m[:, None]  # padded rows: zero Jacobian
            xa = jnp.concatenate([x, jnp.ones((size, 1), x.dtype)], axis=1)
            ha = jnp.concatenate([h * m[:, None], m[:, None]], axis=1)
            tri = tdot(d[:, ju] * d[:, ku], xa[:, ia] * xa[:, ib])
            dx = (d[:, :, None] * xa[:, None, :]).reshape(size, -1)
            mixed = tdot(dx, ha)
            out = tdot(ha, ha)
            g = jnp.concatenate([((d * err[:, None]).T @ xa).ravel(), ha.T @ err])
            c_tri, c_mixed, c_out, c_g = carry
            return (c_tri + tri, c_mixed + mixed, c_out + out, c_g + g), None

        zero = (
            jnp.zeros((ju.size, ia.size), dtype),
            jnp.zeros((H * (F + 1), H + 1), dtype),
            jnp.zeros((H + 1, H + 1), dtype),
            jnp.zeros(H * (F + 1) + H + 1, X.dtype),
        )
        (tri, mixed, out, g), _ = jax.lax.scan(body, zero, (Xp, ep, live))
        hidden = tri.astype(X.dtype)[gather_r, gather_c]
        mixed = mixed.astype(X.dtype)
        G = jnp.block([[hidden, mixed], [mixed.T, out.astype(X.dtype)]])
        # natural order [(j, a) for a in x̃] + [h̃] -> ravel order [W1, b1, W2, b2]
        return G[order[:, None], order[None, :]], g[order]

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


@functools.cache
def _normal_equation_maps(H: int, F: int):
    """Static index maps of [`Perceptron.normal_equations`][] for `H` hidden units and `F`
    features: upper-triangle pairs of `d` and `x̃`, the gather that expands their product
    to the full hidden block, and the permutation from the natural order to ravel order."""
    ju, ku = np.triu_indices(H)
    ia, ib = np.triu_indices(F + 1)
    tri_h = np.zeros((H, H), int)
    tri_h[ju, ku] = tri_h[ku, ju] = np.arange(ju.size)
    tri_f = np.zeros((F + 1, F + 1), int)
    tri_f[ia, ib] = tri_f[ib, ia] = np.arange(ia.size)
    j, a = np.divmod(np.arange(H * (F + 1)), F + 1)
    gather_r = tri_h[j[:, None], j[None, :]]
    gather_c = tri_f[a[:, None], a[None, :]]
    # natural index of ravel entry: W1[j, a] -> j(F+1)+a, b1[j] -> j(F+1)+F, W2/b2 after
    natural = np.concatenate(
        [
            (np.arange(H)[:, None] * (F + 1) + np.arange(F)[None, :]).ravel(),
            np.arange(H) * (F + 1) + F,
            H * (F + 1) + np.arange(H + 1),
        ]
    )
    return ju, ku, ia, ib, gather_r, gather_c, natural


def _as_inputs(u: ArrayLike, n_inputs: int, where: str) -> Array:
    u = jnp.asarray(u)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u = u.astype(jnp.result_type(float))
    return input_columns(u, n_inputs, where)


def _range_fields(lo, hi, n: int | None, dtype):
    """mapminmax: offset = mid-range, scale = half-range (1 where the range is empty)."""
    shape = () if n is None else (n,)
    lo = jnp.broadcast_to(jnp.asarray(-1.0 if lo is None else lo, dtype), shape)
    hi = jnp.broadcast_to(jnp.asarray(1.0 if hi is None else hi, dtype), shape)
    half = (hi - lo) / 2
    return (lo + hi) / 2, jnp.where(half > 0, half, 1.0)


def _normalisation(n_inputs: int, dtype, input_range, output_range):
    """`(u_offset, u_scale, y_offset, y_scale)` of the `mapminmax` normalisation from the
    `(lo, hi)` ranges of the inputs and the target (no scaling where a range is `None`)."""
    lo, hi = (None, None) if input_range is None else input_range
    u_offset, u_scale = _range_fields(lo, hi, n_inputs, dtype)
    lo, hi = (None, None) if output_range is None else output_range
    y_offset, y_scale = _range_fields(lo, hi, None, dtype)
    return u_offset, u_scale, y_offset, y_scale


class AbstractNetwork(AbstractModel):
    """A two-layer perceptron on normalised features of the inputs (the study's ANNs).

    Subclasses say which features a sample sees (`features`: the inputs themselves, or
    them and their delayed copies) and how far back that reaches (`max_delay`); the
    normalisation, the prediction and the model interface are shared."""

    perceptron: eqx.AbstractVar[Perceptron]
    u_offset: eqx.AbstractVar[Float[Array, " input"]]
    u_scale: eqx.AbstractVar[Float[Array, " input"]]
    y_offset: eqx.AbstractVar[Float[Array, ""]]
    y_scale: eqx.AbstractVar[Float[Array, ""]]

    @property
    @abc.abstractmethod
    def max_delay(self) -> int:
        """The longest input delay a prediction uses [samples]."""

    @abc.abstractmethod
    def features(self, u: Float[ArrayLike, "time input"]) -> Float[Array, "time feature"]:
        """Normalised features, one row per sample."""

    @property
    def n_inputs(self) -> int:
        return self.u_offset.shape[0]

    def output(self, yn: Float[Array, "..."]) -> Float[Array, "..."]:
        """Normalised output -> physical units."""
        return self.y_offset + self.y_scale * yn

    def __call__(self, u: Float[ArrayLike, "time input"]) -> Float[Array, " time"]:
        """Prediction `(time,)` for inputs `u` of shape `(time, input)`."""
        return self.output(jax.vmap(self.perceptron)(self.features(u)))

    def predict(self, u: Float[ArrayLike, " time input"], dt: float) -> Float[Array, " time"]:
        """The output for the input samples `u` (a static map of the delayed inputs; `dt`
        only names the sampling)."""
        return self(u)


class StaticNetwork(AbstractNetwork):
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
        self.u_offset, self.u_scale, self.y_offset, self.y_scale = _normalisation(
            n_inputs, self.perceptron.W1.dtype, input_range, output_range
        )

    @property
    def max_delay(self) -> int:
        return 0

    def features(self, u: Float[ArrayLike, "time input"]) -> Float[Array, "time feature"]:
        """Normalised inputs, one row per sample."""
        u = _as_inputs(u, self.n_inputs, "StaticNetwork")
        return (u - self.u_offset) / self.u_scale


class TimeDelayNetwork(AbstractNetwork):
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
        self.u_offset, self.u_scale, self.y_offset, self.y_scale = _normalisation(
            n_inputs, self.perceptron.W1.dtype, input_range, output_range
        )

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
