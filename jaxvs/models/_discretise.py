"""Discretisation of linear models block by block: exact (ZOH) and the real-time integrators.

Every model is first brought to its real block-diagonal (modal) realisation
(`ModalRealisation`, one 2x2 block per pole pair). All four methods map a block to a block:
the zero-order hold is the exponential of the block, and Tustin, forward Euler and Heun are
rational functions or polynomials of it, so the discrete system keeps the block structure
and its good conditioning (no companion form, no dense eigen-decomposition).

Methods that use the next input sample (Tustin and Heun, `x[k+1] = Ad x[k] + B0 u[k] +
B1 u[k+1]`) are brought to the standard form `ξ[k+1] = Ad ξ[k] + Bd u[k]`,
`y[k] = C ξ[k] + Dd u[k]` by the change of variable `ξ[k] = x[k] - B1 u[k]`, which gives
`Bd = Ad B1 + B0` and `Dd = D + C B1` (Franklin, Powell & Workman, *Digital Control of
Dynamic Systems*, 3rd ed., 1998, §6.3).
"""

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from ._base import AbstractLinearModel, check_model, map_batch
from ._realisation import ModalRealisation

METHODS: tuple[str, ...] = ("zoh", "tustin", "euler", "heun")
Method = Literal["zoh", "tustin", "euler", "heun"]


class DiscreteModalRealisation(eqx.Module):
    """A discrete-time system in real block-diagonal form, as returned by [`discretise`][].

    `ξ[k+1] = Ad ξ[k] + Bd u[k]`, `y[k] = C ξ[k] + Dd u[k]`, with `Ad` block diagonal. The
    state of the continuous realisation is `x[k] = ξ[k] + B1 u[k]` (`B1 = 0` for `"zoh"` and
    `"euler"`, so there `ξ = x`).

    **Fields:**

    - `a`: `(*batch, block, 2, 2)` diagonal blocks of `Ad`.
    - `b`: `(*batch, block, 2, in)` rows of `Bd`.
    - `c`: `(*batch, out, block, 2)` columns of `C`.
    - `d`: `(*batch, out, in)` feedthrough `Dd`.
    - `b1`: `(*batch, block, 2, in)` coupling `B1` of the next input sample.
    - `dt`: sample time [s].
    - `method`: the discretisation method (static).
    - `n_states`: true order; when odd, the last state of the last block is padding.
    """

    a: Float[Array, "*batch block 2 2"]
    b: Float[Array, "*batch block 2 input"]
    c: Float[Array, "*batch output block 2"]
    d: Float[Array, "*batch output input"]
    b1: Float[Array, "*batch block 2 input"]
    dt: Float[Array, ""]
    method: str = eqx.field(static=True)
    n_states: int = eqx.field(static=True)

    @property
    def n_blocks(self) -> int:
        return self.a.shape[-3]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.a.shape[:-3]

    def to_state_space(self) -> tuple[Array, Array, Array, Array]:
        """Dense discrete matrices `(Ad, Bd, C, Dd)`, with any leading batch axes.

        The padding state of an odd order is dropped. For `"zoh"` and `"euler"` these are
        exactly what `scipy.signal.cont2discrete` returns for the dense form of the same
        continuous realisation; for `"tustin"` the state differs from scipy's by a
        similarity, the transfer function is the same.
        """
        nb = self.n_blocks
        eye = jnp.eye(nb, dtype=self.a.dtype)
        batch = self.batch_shape
        A = jnp.einsum("ij,...irs->...irjs", eye, self.a).reshape(*batch, 2 * nb, 2 * nb)
        B = self.b.reshape(*batch, 2 * nb, self.b.shape[-1])
        C = self.c.reshape(*batch, self.c.shape[-3], 2 * nb)
        n = self.n_states
        return A[..., :n, :n], B[..., :n, :], C[..., :, :n], self.d

    def response(self, z: Complex[Array, " freq"]) -> Complex[Array, "*batch freq out in"]:
        """Discrete transfer matrix `G(z) = C (zI - Ad)^-1 Bd + Dd` at complex points `z`.

        At `z = exp(jω dt)` this is the frequency response of the discrete system.
        """
        a = self.a[..., None, :, :, :]  # (*batch, 1, block, 2, 2)
        z_ = z[:, None]
        a11, a12, a21, a22 = a[..., 0, 0], a[..., 0, 1], a[..., 1, 0], a[..., 1, 1]
        det = (z_ - a11) * (z_ - a22) - a12 * a21  # (*batch, freq, block)
        adj = jnp.stack(
            [
                jnp.stack([z_ - a22, jnp.broadcast_to(a12, det.shape)], -1),
                jnp.stack([jnp.broadcast_to(a21, det.shape), z_ - a11], -1),
            ],
            -2,
        )
        inv = adj / det[..., None, None]
        g = jnp.einsum("...obr,...fbrs,...bsi->...foi", self.c, inv, self.b)
        return g + self.d[..., None, :, :]


def _check_method(method: str, who: str) -> None:
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(
            f"{who}: unknown method {method!r}; choose one of {', '.join(map(repr, METHODS))} "
            "('zoh' = exact zero-order hold, 'tustin' = bilinear, 'euler' = forward Euler, "
            "'heun' = explicit trapezoid predictor-corrector)."
        )


def _check_dt(dt: ArrayLike, who: str) -> Array:
    """`dt` as a 0-d float array; ValueError when it is concrete and not positive/finite."""
    dt_arr = jnp.asarray(dt)
    if dt_arr.ndim != 0:
        raise ValueError(
            f"{who}: dt is the sample time in seconds, a scalar; got shape {dt_arr.shape}."
        )
    if jnp.iscomplexobj(dt_arr):
        raise TypeError(f"{who}: dt must be real; got a complex number.")
    if not jnp.issubdtype(dt_arr.dtype, jnp.floating):
        dt_arr = dt_arr.astype(jnp.result_type(float))
    if not isinstance(dt_arr, jax.core.Tracer):
        value = float(np.asarray(dt_arr))
        if not (np.isfinite(value) and value > 0):
            raise ValueError(
                f"{who}: dt must be a positive, finite sample time in seconds; got {value}."
            )
    else:
        dt_arr = eqx.error_if(
            dt_arr,
            ~(jnp.isfinite(dt_arr) & (dt_arr > 0)),
            f"{who}: dt must be a positive, finite sample time in seconds.",
        )
    return dt_arr


def _mm(x: Array, y: Array) -> Array:
    """Batched product of (..., 2, 2) with (..., 2, k), written elementwise (tiny matrices:
    XLA fuses this, while a dot_general per product is slow to compile and to run)."""
    return x[..., :, 0, None] * y[..., None, 0, :] + x[..., :, 1, None] * y[..., None, 1, :]


def _inv2(m: Array) -> Array:
    """Inverse of a batch of 2x2 matrices by the adjugate."""
    det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    adj = jnp.stack(
        [
            jnp.stack([m[..., 1, 1], -m[..., 0, 1]], -1),
            jnp.stack([-m[..., 1, 0], m[..., 0, 0]], -1),
        ],
        -2,
    )
    return adj / det[..., None, None]


# Scaling and squaring for the 2x2 blocks (Moler & Van Loan, SIAM Rev. 45(1), 2003, §3):
# ‖X / 2^s‖_1 <= _THETA, Taylor degree _TAYLOR: truncation error <= θ^15/15! ≈ 2e-17.
_THETA = 0.5
_TAYLOR = 14
_MAX_SQUARINGS = 64


def _exp_and_integral(a: Array, h: Array) -> tuple[Array, Array]:
    """`E = exp(a h)` and `Γ = ∫_0^h exp(a τ) dτ` for a batch of 2x2 blocks `a`.

    Γ is the top-right block of `exp([[a, I], [0, 0]] h)` (Van Loan, IEEE TAC 23(3), 1978);
    here both come from one Taylor series of the scaled block and the doubling rule
    `E(2t) = E(t)²`, `Γ(2t) = (I + E(t)) Γ(t)`, which stays valid for singular `a` (poles at
    the origin) and for defective blocks (critically damped modes). The number of
    squarings is data dependent but the loop has a fixed trip count, so the result is
    differentiable in forward and reverse mode.
    """
    x = a * h
    norm = jnp.max(jnp.sum(jnp.abs(x), axis=-2), axis=-1)  # 1-norm per block
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / _THETA)), 0, _MAX_SQUARINGS)
    s = jax.lax.stop_gradient(s)
    scale = 2.0 ** (-s)
    xs = x * scale[..., None, None]
    hs = h * scale
    eye = jnp.broadcast_to(jnp.eye(2, dtype=a.dtype), a.shape)
    # Horner: E = Σ xs^k / k!, Γ/hs = Σ xs^k / (k+1)!
    e = g = eye
    for k in range(_TAYLOR, 0, -1):
        e = eye + _mm(xs, e) / k
        g = eye + _mm(xs, g) / (k + 1)
    g = g * hs[..., None, None]

    def square(i, eg):
        e_, g_ = eg
        keep = (i < s)[..., None, None]
        return jnp.where(keep, _mm(e_, e_), e_), jnp.where(keep, _mm(eye + e_, g_), g_)

    return jax.lax.fori_loop(0, _MAX_SQUARINGS, square, (e, g))


def discretise_realisation(r: ModalRealisation, dt: Array, method: str) -> DiscreteModalRealisation:
    """Discretise one (unbatched) modal realisation block by block; see [`discretise`][]."""
    a, b, c, d = r.a, r.b, r.c, r.d
    h = dt.astype(a.dtype)
    eye = jnp.broadcast_to(jnp.eye(2, dtype=a.dtype), a.shape)
    zero_b1 = jnp.zeros_like(b)
    if method == "zoh":
        ad, gamma = _exp_and_integral(a, h)
        return DiscreteModalRealisation(
            ad, _mm(gamma, b), c, d, zero_b1, h, method=method, n_states=r.n_states
        )
    if method == "euler":
        # x[k+1] = x[k] + h (a x[k] + b u[k])
        return DiscreteModalRealisation(
            eye + h * a, h * b, c, d, zero_b1, h, method=method, n_states=r.n_states
        )
    if method == "tustin":
        # Trapezoidal rule: (I - ah/2) x[k+1] = (I + ah/2) x[k] + (h/2) b (u[k] + u[k+1]).
        w = _inv2(eye - 0.5 * h * a)
        ad = _mm(w, eye + 0.5 * h * a)
        b0 = b1 = _mm(w, 0.5 * h * b)
    elif method == "heun":
        # Predictor x~ = x + h f(x, u[k]); corrector x[k+1] = x + h/2 (f(x, u[k]) +
        # f(x~, u[k+1])) with f = a x + b u: Ad = I + ah + (ah)²/2,
        # B0 = h/2 (I + ah) b, B1 = h/2 b (Heun's method, e.g. Hairer, Nørsett & Wanner,
        # *Solving ODEs I*, §II.1; the TMF study's real-time integrator, seed 002 §2.3).
        ah = a * h
        ad = eye + ah + 0.5 * _mm(ah, ah)
        b0 = 0.5 * h * (b + _mm(ah, b))
        b1 = 0.5 * h * b
    else:  # pragma: no cover - guarded by _check_method
        raise ValueError(method)
    bd = _mm(ad, b1) + b0
    dd = d + jnp.sum(c[:, :, :, None] * b1[None], axis=(1, 2))
    return DiscreteModalRealisation(ad, bd, c, dd, b1, h, method=method, n_states=r.n_states)


def discretise(
    model: AbstractLinearModel, dt: ArrayLike, method: Method = "zoh"
) -> DiscreteModalRealisation:
    """Discrete-time version of a linear model (or of every member of a family).

    The model's real block-diagonal realisation is discretised block by block:

    - `"zoh"`: exact zero-order hold, `Ad = exp(A dt)`, `Bd = ∫_0^dt exp(Aτ) dτ B`
      (matrix exponential of the 4x4 augmented block, Van Loan 1978).
    - `"tustin"`: bilinear / trapezoidal rule, `Ad = (I - A dt/2)^-1 (I + A dt/2)`.
    - `"euler"`: forward Euler, `Ad = I + A dt`, `Bd = B dt`.
    - `"heun"`: explicit trapezoid (predictor-corrector) with `u[k]` and `u[k+1]`,
      `Ad = I + A dt + (A dt)²/2` — the real-time integrator of the TMF study
      (Doerrer et al. 2022, §2.3).

    Tustin and Heun use `u[k+1]`; their result is given in the standard form through
    `ξ = x - B1 u` (see [`DiscreteModalRealisation`][]).

    **Arguments:**

    - `model`: any jaxvs linear model; leading batch axes of its parameters make a family.
    - `dt`: sample time [s], a positive scalar.
    - `method`: one of `"zoh"`, `"tustin"`, `"euler"`, `"heun"`.

    **Returns:**

    A [`DiscreteModalRealisation`][] whose arrays carry the model's batch axes.
    """
    check_model(model, "discretise")
    _check_method(method, "discretise")
    dt_arr = _check_dt(dt, "discretise")
    out = map_batch(lambda m: discretise_realisation(m.modal_realisation(), dt_arr, method), model)
    # map_batch stacks every output leaf; the sample time is one scalar for the family.
    return eqx.tree_at(lambda r: r.dt, out, dt_arr.astype(out.a.dtype))
