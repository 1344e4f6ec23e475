"""Poles, zeros, static gain, stability and damping of linear models (MATLAB-style).

Open-ended questions over model types, answered with `functools.singledispatch`: a closed
form per family where one exists and a numeric fallback through the block-modal
realisation otherwise (the pattern of lineax's `_operator.py`). Every public function
accepts families (leading batch axes) and maps over them with one `jax.vmap`.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Complex, Float

from .._base import AbstractLinearModel
from ._convert import (
    block_poles,
    check_model,
    check_siso,
    jit_map_batch,
    sort_by_frequency,
    to_rational,
)
from ._modal import ModalModel
from ._rational import RationalTF, _frequency_scale
from ._statespace import StateSpace

# ---------------------------------------------------------------------------------------
# poles
# ---------------------------------------------------------------------------------------


@functools.singledispatch
def _poles(model: AbstractLinearModel) -> Complex[Array, " n"]:
    # Fallback: the eigenvalues of each 2x2 block of the block-modal realisation.
    r = model.modal_realisation()
    p = block_poles(r.a).reshape(-1)
    # An odd realisation pads its last block with a copy of its real pole: drop it.
    return p[: r.n_states]


@_poles.register
def _(model: RationalTF) -> Complex[Array, " n"]:
    return model.poles()


@_poles.register
def _(model: StateSpace) -> Complex[Array, " n"]:
    return jnp.linalg.eigvals(model.A)


@_poles.register
def _(model: ModalModel) -> Complex[Array, " n"]:
    # λ = ω (-ζ ± sqrt(ζ² - 1)); the square root of (1 - ζ)(1 + ζ) keeps its digits near
    # ζ = 1, and over-damped pairs use r2 = ω² / r1 (no cancellation).
    w, z = model.omega_n, model.zeta
    q = (1 - z) * (1 + z)
    under = q > 0
    root = jnp.sqrt(jnp.abs(q))
    upper_c = jax.lax.complex(-z * w, w * root)
    r1 = -w * (z + root)
    r1_safe = jnp.where(r1 == 0, 1.0, r1)
    r2 = w**2 / r1_safe
    zero = jnp.zeros_like(w)
    upper = jnp.where(under, upper_c, jax.lax.complex(r1, zero))
    lower = jnp.where(under, jnp.conj(upper_c), jax.lax.complex(r2, zero))
    return jnp.stack([upper, lower], axis=-1).reshape(-1)


def poles(model: AbstractLinearModel) -> Complex[Array, "*batch n"]:
    """Poles of a linear model or family [rad/s], sorted by magnitude (as MATLAB `damp`).

    Closed forms: `RationalTF` roots of the denominator in scaled frequency; `ModalModel`
    `ω_k (-ζ_k ± sqrt(ζ_k² - 1))`; `StateSpace` eigenvalues of `A`; any other model the
    eigenvalues of the 2x2 blocks of its modal realisation.

    **Arguments:**

    - `model`: a jaxvs linear model; leading batch axes make a family.

    **Returns:**

    Complex `(*batch, n)`: `n = order`, except for a `ModalModel` with several inputs,
    which lists each mode's pair once (`n = 2 * n_modes`). Conjugate pairs are adjacent,
    upper pole first.
    """
    check_model(model, "poles")
    return jit_map_batch(_sorted_poles, model)


def _sorted_poles(model: AbstractLinearModel) -> Complex[Array, " n"]:
    p = _poles(model)
    return p[sort_by_frequency(p)]


# ---------------------------------------------------------------------------------------
# zeros
# ---------------------------------------------------------------------------------------


def _polynomial_roots(c: Float[Array, " k1"], scale: Float[Array, ""]) -> Complex[Array, " k"]:
    """Roots of a polynomial whose leading coefficients may be (numerically) zero.

    Heuristic: coefficients below `100 eps` of the largest are leading zeros (a root at
    infinity each; scipy's `normalize` uses an absolute 1e-14). The polynomial is shifted
    left by their number `k` — which multiplies it by `x^k` — so the companion matrix is
    well defined under `jit`; `k` of the roots nearest 0 are then reported as `inf`.
    The roots are returned multiplied by `scale` (the frequency scale of `c`).
    """
    size = c.shape[0]
    tiny = 100 * jnp.finfo(c.dtype).eps * jnp.max(jnp.abs(c))
    lead_zero = jnp.cumprod(jnp.abs(c) <= tiny)
    k = jnp.minimum(jnp.sum(lead_zero), size - 1)
    shifted = c[(jnp.arange(size) + k) % size] * (jnp.arange(size) < size - k)
    lead = shifted[0]
    roots = jnp.roots(shifted / jnp.where(lead == 0, 1.0, lead), strip_zeros=False) * scale
    rank = jnp.argsort(jnp.argsort(jnp.abs(roots)))
    inf = jnp.asarray(jnp.inf, roots.real.dtype)
    return jnp.where(rank < k, jax.lax.complex(inf, jnp.zeros_like(inf)), roots)


@functools.singledispatch
def _zeros(model: AbstractLinearModel) -> Complex[Array, " n"]:
    # Fallback: through the rational form, which is built block by block (no companion).
    return _zeros(to_rational(model))


@_zeros.register
def _(model: RationalTF) -> Complex[Array, " m"]:
    if model.num.shape[-1] < 2:
        return jnp.zeros((0,), jnp.result_type(model.num.dtype, 1j))
    # Same frequency scale as the poles, so zeros near the poles keep their digits.
    w0 = jax.lax.stop_gradient(_frequency_scale(model.den))
    m = model.num.shape[-1] - 1
    scaled = model.num * w0 ** jnp.arange(m, -1, -1, dtype=w0.dtype)
    return _polynomial_roots(scaled, w0)


def zeros(model: AbstractLinearModel) -> Complex[Array, "*batch m"]:
    """Zeros of a SISO model or family [rad/s], finite ones sorted by magnitude.

    `RationalTF`: roots of the numerator in scaled frequency `s / ω0`. Other models:
    through [`to_rational`][] (the block-wise rational form), which equals the
    transmission zeros of a SISO state space.

    **Arguments:**

    - `model`: a SISO jaxvs linear model; leading batch axes make a family.

    **Returns:**

    Complex `(*batch, m)` with `m = len(num) - 1` (`= order` for non-rational models).
    Numerator coefficients that vanish (up to `100 eps` relative) are zeros at infinity and
    are reported as `inf`, listed last (the relative degree of the model).
    """
    check_model(model, "zeros")
    check_siso(model, "zeros")
    return jit_map_batch(_sorted_zeros, model)


def _sorted_zeros(model: AbstractLinearModel) -> Complex[Array, " m"]:
    z = _zeros(model)
    key = jnp.where(jnp.isfinite(z), jnp.abs(z), jnp.inf)
    return z[jnp.lexsort((-jnp.where(jnp.isfinite(z), z.imag, 0.0), key))]


# ---------------------------------------------------------------------------------------
# static gain
# ---------------------------------------------------------------------------------------


@functools.singledispatch
def _static_gain(model: AbstractLinearModel) -> Float[Array, "out in"]:
    leaves = [x for x in jax.tree_util.tree_leaves(model) if eqx.is_inexact_array(x)]
    s0 = jnp.zeros((1,), jnp.result_type(*leaves, 1j))
    return model.response(s0)[0].real


@_static_gain.register
def _(model: RationalTF) -> Float[Array, "1 1"]:
    return jnp.reshape(model.num[-1] / model.den[-1], (1, 1))


@_static_gain.register
def _(model: ModalModel) -> Float[Array, "out in"]:
    a, b = model._sections()
    d = model.feedthrough.reshape(model.n_outputs, model.n_inputs)
    return d + jnp.sum(b / model.omega_n[:, None, None] ** 2, axis=0)


@_static_gain.register
def _(model: StateSpace) -> Float[Array, "out in"]:
    # G(0) = D - C A^-1 B; a singular A (pole at 0) gives inf/nan through the LU pivots.
    return model.D - model.C @ jnp.linalg.solve(model.A, model.B)


def static_gain(model: AbstractLinearModel) -> Float[Array, "..."]:
    """Static (DC) gain `G(0)` of a linear model or family, as MATLAB `dcgain`.

    Closed forms: `RationalTF` `num[-1] / den[-1]`; `ModalModel` `Σ_k b_k / ω_k² + D`;
    `StateSpace` `D - C A⁻¹ B`; other models evaluate their response at `s = 0`.

    **Arguments:**

    - `model`: a jaxvs linear model; leading batch axes make a family.

    **Returns:**

    Real `(*batch,)` for a SISO model, else `(*batch, out, in)`. Where the model has a
    pole at `s = 0` the gain is infinite: `±inf` (or `nan` when the numerator also
    vanishes there, an uncancelled 0/0), like `dcgain`; check with `jnp.isfinite`.
    """
    check_model(model, "static_gain")
    g = jit_map_batch(_static_gain, model)
    return g[..., 0, 0] if model.is_siso else g


# ---------------------------------------------------------------------------------------
# stability and damping
# ---------------------------------------------------------------------------------------


def is_stable(model: AbstractLinearModel) -> Bool[Array, "*batch"]:
    """Asymptotic stability: every pole strictly in the left half-plane.

    **Arguments:**

    - `model`: a jaxvs linear model; leading batch axes make a family.

    **Returns:**

    Boolean `(*batch,)`. A pole on the imaginary axis (ζ = 0, an integrator) is not stable.
    """
    check_model(model, "is_stable")
    if isinstance(model, ModalModel):
        # ω_n > 0 is enforced by ModalModel, so stability is ζ_k > 0 for every mode.
        return jnp.all(model.zeta > 0, axis=-1)
    return jnp.all(poles(model).real < 0, axis=-1)


def damping(
    model: AbstractLinearModel,
) -> tuple[Float[Array, "*batch n"], Float[Array, "*batch n"]]:
    """Natural frequency and damping ratio of every pole, as MATLAB `damp`.

    `ω_n = |p|`, `ζ = -cos(arg p)` (`= -Re p / |p|`; a pole at 0 gets ζ = -1 as in MATLAB),
    sorted by ω_n, one entry per pole (a conjugate pair gives two equal entries).

    **Arguments:**

    - `model`: a jaxvs linear model; leading batch axes make a family.

    **Returns:**

    `(omega_n, zeta)`, each real `(*batch, n)` with `n` as in [`poles`][]; `omega_n` in
    rad/s.
    """
    check_model(model, "damping")
    p = poles(model)
    return jnp.abs(p), -jnp.cos(jnp.angle(p))
