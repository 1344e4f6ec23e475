"""Conversions between linear model forms, and position ↔ acceleration.

Every conversion goes through the real block-diagonal (modal) realisation
(`ModalRealisation`): each 2x2 block `a_i` contributes the second-order section

    G_i(s) = c_i adj(sI - a_i) b_i / det(sI - a_i)
           = (s c_i b_i + c_i adj(-a_i) b_i) / (s² - tr(a_i) s + det(a_i)),

so rational coefficients, modal parameters and poles are formed block by block from
well-conditioned 2x2 data, never from a companion matrix. Polynomials are multiplied in the
scaled frequency `x = s / ω0` (ω0 = geometric mean of the pole magnitudes), which keeps
their coefficients within a few decades of each other at order 8-12.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float, Shaped

from .._base import AbstractLinearModel, check_model, map_batch
from .._realisation import ModalRealisation
from ._modal import ModalModel
from ._rational import RationalTF
from ._response import as_omega
from ._statespace import StateSpace

_RESIDUE_KINDS = ("complex", "real")


# ---------------------------------------------------------------------------------------
# Shared checks and 2x2-block algebra
# ---------------------------------------------------------------------------------------


def check_siso(model: AbstractLinearModel, who: str) -> None:
    if not model.is_siso:
        raise ValueError(
            f"{who}: needs a single-input single-output model; got {model.n_outputs} "
            f"output(s) and {model.n_inputs} input(s). Convert one channel at a time, e.g. "
            "jaxvs.StateSpace(A, B[:, [j]], C[[i], :], D[[i]][:, [j]])."
        )


def _safe_sqrt(x: Array) -> Array:
    """`sqrt(x)` for `x >= 0` whose gradient stays finite at 0 (it is 0 there)."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def block_invariants(a: Float[Array, "block 2 2"]) -> tuple[Array, Array, Array]:
    """`(m, det, disc)` of every 2x2 block: eigenvalues are `m ± sqrt(disc)`, `det = λ1 λ2`.

    `m = tr/2`, `disc = ((a11 - a22)/2)² + a12 a21`. Written this way (not `m² - det`) the
    discriminant of a rotation block `[[α, -β], [β, α]]` is exactly `-β²` and that of a
    diagonal block exactly `((p1 - p2)/2)²`, so no digits cancel.
    """
    a11, a12, a21, a22 = a[..., 0, 0], a[..., 0, 1], a[..., 1, 0], a[..., 1, 1]
    m = (a11 + a22) / 2
    p = (a11 - a22) / 2
    return m, a11 * a22 - a12 * a21, p * p + a12 * a21


def block_poles(a: Float[Array, "block 2 2"]) -> Complex[Array, "block 2"]:
    """Both eigenvalues of every 2x2 block; a complex pair comes upper pole first.

    Real pairs use the cancellation-free form `r1 = m + sign(m) sqrt(disc)`, `r2 = det / r1`
    (Press et al., *Numerical Recipes*, 3rd ed., §5.6).
    """
    m, det, disc = block_invariants(a)
    is_complex = disc < 0
    root = _safe_sqrt(jnp.abs(disc))
    r1 = m + jnp.where(m >= 0, 1.0, -1.0) * root
    r1_zero = r1 == 0
    r2 = jnp.where(r1_zero, 0.0, det / jnp.where(r1_zero, 1.0, r1))
    zero = jnp.zeros_like(m)
    upper = jnp.where(is_complex, jax.lax.complex(m, root), jax.lax.complex(r1, zero))
    lower = jnp.where(is_complex, jax.lax.complex(m, -root), jax.lax.complex(r2, zero))
    return jnp.stack([upper, lower], axis=-1)


def block_sections(
    r: ModalRealisation,
) -> tuple[Float[Array, "block out in"], Float[Array, "block out in"]]:
    """Numerator `(s1, s0)` of every block: `G_i(s) = (s1 s + s0) / det(sI - a_i)`.

    `s1 = c_i b_i`, `s0 = c_i adj(-a_i) b_i` with `adj(-a) = [[-a22, a12], [a21, -a11]]`.
    """
    a = r.a
    adj = jnp.stack(
        [
            jnp.stack([-a[:, 1, 1], a[:, 0, 1]], -1),
            jnp.stack([a[:, 1, 0], -a[:, 0, 0]], -1),
        ],
        -2,
    )
    s1 = jnp.einsum("obr,bri->boi", r.c, r.b)
    s0 = jnp.einsum("obr,brs,bsi->boi", r.c, adj, r.b)
    return s1, s0


def sort_by_frequency(p: Complex[Array, " n"]) -> Array:
    """Indices sorting poles/zeros by magnitude, upper pole of a pair first (as `damp`)."""
    return jnp.lexsort((-p.imag, jnp.abs(p)))


@eqx.filter_jit
def jit_map_batch(fn, model):
    """`map_batch(fn, model)` compiled once per function, model structure and shapes.

    `fn` must be a module-level function (it is a static argument, hashed by identity).
    """
    return map_batch(fn, model)


def _tolerance(dtype) -> float:
    # heuristic: sqrt(eps) relative, the usual threshold for "zero up to rounding" of a
    # quantity formed from O(n) rounded products (≈1.5e-8 in float64, 3e-4 in float32).
    return float(np.sqrt(np.finfo(dtype).eps))


# ---------------------------------------------------------------------------------------
# to_rational
# ---------------------------------------------------------------------------------------


def _rational_from_realisation(r: ModalRealisation) -> RationalTF:
    """SISO rational coefficients from the blocks, multiplied in scaled frequency."""
    n, nb = r.n_states, r.n_blocks
    odd = n % 2 == 1
    a = r.a
    m, det, _ = block_invariants(a)
    s1, s0 = block_sections(r)
    s1, s0 = s1[:, 0, 0], s0[:, 0, 0]
    # The last block of an odd realisation is (real pole, unobservable padding copy):
    # it contributes the first-order section c0 b0 / (s - a00).
    p_odd = a[-1, 0, 0]
    g_odd = r.c[0, -1, 0] * r.b[-1, 0, 0]

    # ω0 = geometric mean of the non-zero pole magnitudes, Σ log|p| / n_poles. The result
    # does not depend on ω0 mathematically, so its gradient is stopped (and log(0) of an
    # integrator never reaches the backward pass).
    logs = jnp.log(jnp.abs(det)) / 2  # mean log|p| of each 2-pole block
    weights = jnp.full((nb,), 2.0, det.dtype)
    if odd:
        logs = logs.at[-1].set(jnp.log(jnp.abs(p_odd)))
        weights = weights.at[-1].set(1.0)
    finite = jnp.isfinite(logs)
    w_eff = jnp.where(finite, weights, 0.0)
    total = jnp.sum(jnp.where(finite, logs * weights, 0.0))
    w0 = jnp.where(jnp.sum(w_eff) > 0, jnp.exp(total / jnp.maximum(jnp.sum(w_eff), 1.0)), 1.0)
    w0 = jax.lax.stop_gradient(w0)

    dens, nums = [], []
    for i in range(nb):
        if odd and i == nb - 1:
            dens.append(jnp.stack([jnp.ones_like(p_odd), -p_odd / w0]))
            nums.append(jnp.reshape(g_odd / w0, (1,)))
        else:
            dens.append(jnp.stack([jnp.ones_like(m[i]), -2 * m[i] / w0, det[i] / w0**2]))
            nums.append(jnp.stack([s1[i] / w0, s0[i] / w0**2]))

    # den(x) = Π_i den_i(x);  num(x) = d den(x) + Σ_i num_i(x) Π_{j≠i} den_j(x), the
    # products over j ≠ i formed from prefix and suffix products (2 nb polynomial products).
    one = jnp.ones((1,), a.dtype)
    prefix = [one]
    for dn in dens:
        prefix.append(jnp.convolve(prefix[-1], dn))
    suffix = [one]
    for dn in reversed(dens):
        suffix.append(jnp.convolve(suffix[-1], dn))
    suffix = suffix[::-1]
    den_x = prefix[-1]  # monic, degree n
    num_x = r.d[0, 0] * den_x
    for i in range(nb):
        term = jnp.convolve(jnp.convolve(prefix[i], nums[i]), suffix[i + 1])
        num_x = num_x.at[1:].add(term)
    # Back to s: multiply both by w0^n, so coefficient k (power n - k) gains w0^k.
    powers = w0 ** jnp.arange(n + 1, dtype=den_x.dtype)
    return RationalTF(num_x * powers, den_x * powers)


@functools.singledispatch
def _to_rational(model: AbstractLinearModel) -> RationalTF:
    return _rational_from_realisation(model.modal_realisation())


@_to_rational.register
def _(model: RationalTF) -> RationalTF:
    return model


def to_rational(model: AbstractLinearModel) -> RationalTF:
    """Rational transfer function `num(s) / den(s)` of a SISO model or family.

    The coefficients come from the block-modal realisation: the characteristic polynomial
    of every 2x2 block and its first-order numerator, multiplied in scaled frequency
    `s / ω0` (ω0 the geometric mean of the pole magnitudes), never through a companion
    matrix or `poly(A - B C)` differences, so order 8-12 systems keep their digits.

    **Arguments:**

    - `model`: a SISO jaxvs linear model (`ModalModel`, `StateSpace`, ...); leading batch
      axes make a family. A `RationalTF` is returned unchanged.

    **Returns:**

    A `RationalTF` with a monic denominator of degree `model.order` and a numerator of the
    same length (leading coefficients are zero when the model is strictly proper).
    """
    check_model(model, "to_rational")
    check_siso(model, "to_rational")
    return jit_map_batch(_to_rational, model)


# ---------------------------------------------------------------------------------------
# to_modal
# ---------------------------------------------------------------------------------------


def _io_shape(n_out: int, n_in: int) -> tuple[int, ...]:
    if n_out == 1 and n_in == 1:
        return ()
    if n_in == 1:
        return (n_out,)
    return (n_out, n_in)


def modal_from_sections(
    omega: Float[Array, " mode"],
    zeta: Float[Array, " mode"],
    sec_a: Float[Array, "mode out in"],
    sec_b: Float[Array, "mode out in"],
    d: Float[Array, "out in"],
    io_shape: tuple[int, ...],
    kind: str,
    who: str,
) -> ModalModel:
    """`ModalModel` with sections `(a_k s + b_k) / (s² + 2 ζ_k ω_k s + ω_k²)`, sorted by ω.

    `kind="complex"`: the residue of the upper pole `λ = α + jβ` is
    `R = a/2 - j (b + a α) / (2 β)` (inverse of `a = 2 Re R`, `b = -2 Re(R conj λ)`,
    `ModalModel` docstring). `kind="real"`: the modal constant `b_k`, exact only if
    `a_k = 0` (checked up to rounding).
    """
    tol = _tolerance(omega.dtype)
    if kind == "complex":
        omega = eqx.error_if(
            omega,
            jnp.any(zeta >= 1),
            f"{who}: a mode has real poles (over-damped, zeta >= 1), which have no complex "
            "residue. Use residues='real' (exact when that mode's numerator has no s term) or "
            "keep the model as a StateSpace / RationalTF.",
        )
        alpha = -zeta * omega
        beta = omega * _safe_sqrt((1 - zeta) * (1 + zeta))
        beta_safe = jnp.where(beta > 0, beta, 1.0)[:, None, None]
        res = jax.lax.complex(sec_a / 2, -(sec_b + sec_a * alpha[:, None, None]) / (2 * beta_safe))
    else:
        scale = jnp.abs(sec_b) + jnp.abs(sec_a) * omega[:, None, None]
        omega = eqx.error_if(
            omega,
            jnp.any(jnp.abs(sec_a) * omega[:, None, None] > tol * scale),
            f"{who}: a mode's numerator has a velocity term a_k s (it is not a real modal "
            "constant r_k / (s² + 2 ζ ω s + ω²)). Use residues='complex'.",
        )
        res = sec_b
    order = jnp.argsort(omega)
    n_modes = omega.shape[0]
    res = res[order].reshape((n_modes,) + io_shape)
    return ModalModel(omega[order], zeta[order], res, feedthrough=d.reshape(io_shape))


@functools.singledispatch
def _to_modal(model: AbstractLinearModel, kind: str) -> ModalModel:
    r = model.modal_realisation()
    who = "to_modal"
    m, det, disc = block_invariants(r.a)
    det = eqx.error_if(
        det,
        jnp.any(det <= 0) if kind == "real" else jnp.any(disc >= 0),
        f"{who}: the model has real poles that do not form a second-order mode "
        + (
            "(a pair of real poles must have the same sign and be non-zero). "
            if kind == "real"
            else "(only complex-conjugate pairs have complex residues; pass "
            "residues='real' for exact over-damped pairs). "
        )
        + "Keep the model as a StateSpace / RationalTF.",
    )
    omega = _safe_sqrt(det)
    zeta = -m / jnp.where(omega > 0, omega, 1.0)
    omega = eqx.error_if(
        omega,
        jnp.any(zeta < 0),
        f"{who}: the model has unstable poles (negative damping); a ModalModel holds damped "
        "modes only. Keep the model as a StateSpace / RationalTF.",
    )
    s1, s0 = block_sections(r)
    io = _io_shape(model.n_outputs, model.n_inputs)
    return modal_from_sections(omega, zeta, s1, s0, r.d, io, kind, who)


@_to_modal.register
def _(model: ModalModel, kind: str) -> ModalModel:
    if jnp.iscomplexobj(model.residues) == (kind == "complex"):
        return model
    a, b = model._sections()
    d = model.feedthrough.reshape(model.n_outputs, model.n_inputs)
    return modal_from_sections(model.omega_n, model.zeta, a, b, d, model.io_shape, kind, "to_modal")


_TO_MODAL = {kind: functools.partial(_to_modal, kind=kind) for kind in _RESIDUE_KINDS}


def to_modal(model: AbstractLinearModel, *, residues: str = "complex") -> ModalModel:
    """Modal parameters (ω_n, ζ, residues) of a linear model or family.

    Each 2x2 block of the block-modal realisation becomes one mode: `ω_n = sqrt(det a)`,
    `ζ = -tr(a) / (2 ω_n)`, and its numerator `(s c b + c adj(-a) b)` gives the residues.
    Modes are sorted by natural frequency.

    What can be represented (the choice documented here):

    - `residues="complex"` (default): every pole must belong to a complex-conjugate pair
      (ζ < 1); the residues are those of the upper poles, per output (and input). Real
      poles raise an error (`eqx.error_if`; the pole kinds are values).
    - `residues="real"`: real modal constants `r_k / (s² + 2ζω s + ω²)`. Over-damped
      modes (a pair of real poles of the same sign, ζ >= 1) are allowed, but the result is
      only exact when no mode has a velocity term `a_k s` in its numerator; otherwise an
      error is raised. Pairs of real poles are formed as the realisation pairs them
      (sorted by real part for `RationalTF`/`StateSpace`; a `ModalModel` keeps its modes).

    A model of odd order has an unpaired real pole and is rejected at trace time; unstable
    poles (ζ < 0) are rejected because a `ModalModel` holds damped modes only.

    **Arguments:**

    - `model`: any jaxvs linear model; leading batch axes make a family.
    - `residues`: `"complex"` or `"real"`, see above.

    **Returns:**

    A `ModalModel` with `order // 2` modes and residues of shape `(mode,)` (SISO),
    `(mode, out)` (one input) or `(mode, out, in)`; a `ModalModel` keeps its own modes.
    """
    check_model(model, "to_modal")
    if residues not in _RESIDUE_KINDS:
        raise ValueError(f"to_modal: residues must be one of {_RESIDUE_KINDS}; got {residues!r}.")
    if not isinstance(model, ModalModel) and model.order % 2:
        raise ValueError(
            f"to_modal: a model of odd order {model.order} has an unpaired real pole, which "
            "is not a second-order mode. Keep it as a StateSpace / RationalTF, or add a "
            "far-away pole to pair it."
        )
    return jit_map_batch(_TO_MODAL[residues], model)


# ---------------------------------------------------------------------------------------
# Position <-> acceleration (Doerrer et al. 2022, eq. 6: x(s) = a(s) / s²)
# ---------------------------------------------------------------------------------------


@functools.singledispatch
def _acc_to_pos(model: AbstractLinearModel) -> AbstractLinearModel:
    return _acc_to_pos(model.to_state_space())


@_acc_to_pos.register
def _(model: RationalTF) -> RationalTF:
    zeros = jnp.zeros((2,), model.den.dtype)
    return RationalTF(model.num, jnp.concatenate([model.den, zeros]))


@_acc_to_pos.register
def _(model: StateSpace) -> StateSpace:
    # Two integrators per output: z1' = C x + D u, z2' = z1, y = z2.
    A, B, C, D = model.A, model.B, model.C, model.D
    n, p = model.order, model.n_outputs
    Z = functools.partial(jnp.zeros, dtype=A.dtype)
    eye = jnp.eye(p, dtype=A.dtype)
    A2 = jnp.block([[A, Z((n, 2 * p))], [C, Z((p, 2 * p))], [Z((p, n)), eye, Z((p, p))]])
    B2 = jnp.concatenate([B, D, Z((p, B.shape[1]))], axis=0)
    C2 = jnp.concatenate([Z((p, n + p)), eye], axis=1)
    return StateSpace(A2, B2, C2, jnp.zeros_like(D))


@_acc_to_pos.register
def _(model: ModalModel) -> ModalModel:
    # Each accelerance section (a s + b)/den divided by s² is c1/s + c0/s² + (p s + q)/den
    # with c0 = b/ω², c1 = (a ω² - 2ζω b)/ω⁴, p = -c1, q = -(2ζω c1 + c0); the rigid-body
    # terms sum to G(0)/s² + G'(0)/s, so the result is a ModalModel iff G(0) = G'(0) = 0.
    a, b = model._sections()
    w, z = model.omega_n[:, None, None], model.zeta[:, None, None]
    d = model.feedthrough.reshape(model.n_outputs, model.n_inputs)
    c0 = b / w**2
    c1 = (a * w**2 - 2 * z * w * b) / w**4
    tol = _tolerance(w.dtype)
    g0 = d + jnp.sum(c0, axis=0)
    g0_scale = jnp.abs(d) + jnp.sum(jnp.abs(c0), axis=0)
    g1 = jnp.sum(c1, axis=0)
    g1_scale = jnp.sum(jnp.abs(a) / w**2 + 2 * z * jnp.abs(b) / w**3, axis=0)
    c1 = eqx.error_if(
        c1,
        jnp.any(jnp.abs(g0) > tol * g0_scale) | jnp.any(jnp.abs(g1) > tol * g1_scale),
        "acceleration_to_position: the ModalModel does not vanish like s² at s = 0 "
        "(G(0) or G'(0) is not 0), so G(s)/s² has rigid-body poles at 0 that a ModalModel "
        "cannot hold. Convert first (model.to_state_space() or to_rational(model)) to get "
        "the double integrator, or use acceleration_to_position_frf on FRF data.",
    )
    sec_a, sec_b = -c1, -(2 * z * w * c1 + c0)
    return _modal_result(model, sec_a, sec_b, jnp.zeros_like(d), "acceleration_to_position")


def _modal_result(model: ModalModel, sec_a, sec_b, d, who: str) -> ModalModel:
    zeta = eqx.error_if(
        model.zeta,
        jnp.any(model.zeta >= 1),
        f"{who}: over-damped modes (zeta >= 1) would need a velocity term with real "
        "residues, which a ModalModel cannot hold. Convert first with model.to_state_space().",
    )
    return modal_from_sections(model.omega_n, zeta, sec_a, sec_b, d, model.io_shape, "complex", who)


def acceleration_to_position(model: AbstractLinearModel) -> AbstractLinearModel:
    """Divide a model by `s²`: an accelerance (or any `a(s)`) becomes a receptance `x(s)`.

    Doerrer et al. 2022, eq. 6 (position = acceleration / s², integration in the frequency
    domain). Exact
    for every family:

    - `RationalTF`: `num / (den s²)` (two poles at 0 appended to the denominator).
    - `StateSpace` (and any other model, through `to_state_space()`): two integrator
      states per output, `z1' = C x + D u`, `z2' = z1`, `y = z2`.
    - `ModalModel`: a `ModalModel` with complex residues (ζ < 1). This needs `G(0) = 0`
      and `G'(0) = 0` (as for the accelerance of a grounded structure); otherwise the
      quotient has rigid-body poles at 0 and an error is raised (`eqx.error_if`).

    The double pole at `s = 0` of the first two cases is defective: frequency responses
    are exact, but the block-modal realisation (`simulate`, `to_modal`, `to_rational` of a
    `StateSpace`) does not support it; integrate the signals or use the FRF variant.

    **Arguments:**

    - `model`: a jaxvs linear model or family.

    **Returns:**

    A model of the same family (`StateSpace` for families without a closed form) with
    `G(s) / s²`.
    """
    check_model(model, "acceleration_to_position")
    return jit_map_batch(_acc_to_pos, model)


@functools.singledispatch
def _pos_to_acc(model: AbstractLinearModel) -> AbstractLinearModel:
    return _pos_to_acc(model.to_state_space())


@_pos_to_acc.register
def _(model: RationalTF) -> RationalTF:
    zeros = jnp.zeros((2,), model.num.dtype)
    return RationalTF(jnp.concatenate([model.num, zeros]), model.den)


@_pos_to_acc.register
def _(model: StateSpace) -> StateSpace:
    # s² C (sI - A)^-1 B = C B s + C A B + C A² (sI - A)^-1 B: proper iff D = 0 and C B = 0.
    A, B, C, D = model.A, model.B, model.C, model.D
    tol = _tolerance(A.dtype)
    nc, nb, na = jnp.linalg.norm(C), jnp.linalg.norm(B), jnp.linalg.norm(A)
    CB = C @ B
    bad = (
        (jnp.max(jnp.abs(CB)) > tol * nc * nb)
        | (jnp.max(jnp.abs(D)) * na > tol * nc * nb)
        | ((nc * nb == 0) & jnp.any(D != 0))
    )
    A = eqx.error_if(
        A,
        bad,
        "position_to_acceleration: G(s) s² is improper because the StateSpace has a "
        "feedthrough D != 0 or C B != 0 (G(s) does not fall like 1/s² at high frequency). "
        "Only receptance-like models (relative degree >= 2) have a proper accelerance; "
        "use position_to_acceleration_frf on FRF data instead.",
    )
    CA = C @ A
    return StateSpace(A, B, CA @ A, CA @ B)


@_pos_to_acc.register
def _(model: ModalModel) -> ModalModel:
    # s² (a s + b)/den = (a s + b) - 2ζωa - [(a ω²(1 - 4ζ²) + 2ζωb) s + (bω² - 2ζω³a)]/den,
    # using s² ≡ -2ζω s - ω² (mod den). Proper iff Σ_k a_k = 0 and D = 0; the new
    # feedthrough is Σ_k (b_k - 2 ζ_k ω_k a_k).
    a, b = model._sections()
    w, z = model.omega_n[:, None, None], model.zeta[:, None, None]
    d = model.feedthrough.reshape(model.n_outputs, model.n_inputs)
    tol = _tolerance(w.dtype)
    g_scale = jnp.sum(jnp.abs(b) / w**2 + jnp.abs(a) / w, axis=0)
    bad = jnp.any(jnp.abs(jnp.sum(a, axis=0)) > tol * jnp.sum(jnp.abs(a), axis=0)) | jnp.any(
        jnp.abs(d) > tol * g_scale
    )
    a = eqx.error_if(
        a,
        bad,
        "position_to_acceleration: G(s) s² is improper because the ModalModel has a "
        "feedthrough or its modes' velocity terms do not cancel (Σ_k a_k != 0); it does not "
        "fall like 1/s² at high frequency. Real modal constants without feedthrough always "
        "work; use position_to_acceleration_frf on FRF data otherwise.",
    )
    sec_a = -(a * w**2 * (1 - 4 * z**2) + 2 * z * w * b)
    sec_b = -(b * w**2 - 2 * z * w**3 * a)
    d_new = jnp.sum(b - 2 * z * w * a, axis=0)
    return _modal_result(model, sec_a, sec_b, d_new, "position_to_acceleration")


def position_to_acceleration(model: AbstractLinearModel) -> AbstractLinearModel:
    """Multiply a model by `s²`: a receptance `x(s)` becomes an accelerance `a(s)`.

    The inverse of [`acceleration_to_position`][] (Doerrer et al. 2022, eq. 6). The result
    is proper only when `G(s)` falls like `1/s²` at high frequency:

    - `RationalTF`: needs `len(den) - len(num) >= 2` (checked at trace time; strip leading
      zero numerator coefficients first); the numerator gains two trailing zeros.
    - `StateSpace` (and other models through `to_state_space()`): needs `D = 0` and
      `C B = 0` (checked with `eqx.error_if`, relative tolerance `sqrt(eps)`); the result
      is `(A, B, C A², C A B)`.
    - `ModalModel`: needs zero feedthrough and `Σ_k a_k = 0` (always true for real modal
      constants); the result has complex residues (ζ < 1) and feedthrough `Σ_k r_k`.

    **Arguments:**

    - `model`: a jaxvs linear model or family.

    **Returns:**

    A model of the same family (`StateSpace` for families without a closed form) with
    `G(s) s²`.
    """
    check_model(model, "position_to_acceleration")
    if isinstance(model, RationalTF) and model.den.shape[-1] - model.num.shape[-1] < 2:
        raise ValueError(
            "position_to_acceleration: num(s) s² / den(s) would be improper: numerator "
            f"order {model.num.shape[-1] - 1} + 2 > denominator order {model.order}. Only "
            "a receptance-like model (relative degree >= 2) has a proper accelerance; strip "
            "leading zero numerator coefficients, or use position_to_acceleration_frf."
        )
    return jit_map_batch(_pos_to_acc, model)


def _check_frf(H, omega, axis: int, who: str) -> tuple[Array, Array, int]:
    H = jnp.asarray(H)
    omega = as_omega(omega, who)
    if H.ndim == 0:
        raise ValueError(f"{who}: H must have a frequency axis; got a scalar.")
    if not -H.ndim <= axis < H.ndim:
        raise ValueError(f"{who}: axis {axis} is out of range for H of shape {H.shape}.")
    axis = axis % H.ndim
    if H.shape[axis] != omega.shape[0]:
        raise ValueError(
            f"{who}: H has {H.shape[axis]} points along axis {axis} but omega has "
            f"{omega.shape[0]}. Pass the frequency axis, e.g. axis=-3 for a (freq, out, in) "
            "FRF from jaxvs.frequency_response."
        )
    if not jnp.issubdtype(H.dtype, jnp.inexact):
        H = H.astype(jnp.result_type(float))
    shape = [1] * H.ndim
    shape[axis] = -1
    return H, omega.reshape(shape), axis


def acceleration_to_position_frf(
    H: Shaped[ArrayLike, "..."], omega: Float[ArrayLike, " freq"], *, axis: int = -1
) -> Shaped[Array, "..."]:
    """Integrate an FRF twice in the frequency domain: `H / (jω)² = -H / ω²`.

    Doerrer et al. 2022, eq. 6: acceleration data are integrated in the frequency domain.

    Turns an accelerance (acceleration per force) into a receptance, or an acceleration
    spectrum into a position spectrum. A transmissibility (ratio of two such FRFs) is
    unchanged by it, so a TMF between accelerations equals the TMF between positions.

    **Arguments:**

    - `H`: FRF values, any shape with a frequency axis (`axis`, default last; use
      `axis=-3` for the `(freq, out, in)` output of `frequency_response`).
    - `omega`: `(freq,)` angular frequencies [rad/s]; must not contain 0.
    - `axis`: the frequency axis of `H`.

    **Returns:**

    `-H / ω²`, same shape and dtype as `H`.
    """
    who = "acceleration_to_position_frf"
    H, w, _ = _check_frf(H, omega, axis, who)
    msg = (
        f"{who}: omega contains 0 rad/s, where the double integration 1/(jω)² is infinite. "
        "Drop the DC line (e.g. H[..., 1:], omega[1:]) or start the grid above 0 Hz "
        "(accelerometers do not measure DC anyway)."
    )
    if isinstance(w, jax.core.Tracer):
        w = eqx.error_if(w, jnp.any(w == 0), msg)
    elif bool(np.any(np.asarray(w) == 0)):
        raise ValueError(msg)
    return -H / w.astype(H.real.dtype) ** 2


def position_to_acceleration_frf(
    H: Shaped[ArrayLike, "..."], omega: Float[ArrayLike, " freq"], *, axis: int = -1
) -> Shaped[Array, "..."]:
    """Differentiate an FRF twice in the frequency domain: `H (jω)² = -ω² H`.

    The inverse of [`acceleration_to_position_frf`][] (Doerrer et al. 2022, eq. 6).

    **Arguments:**

    - `H`: FRF values with a frequency axis (`axis`, default last).
    - `omega`: `(freq,)` angular frequencies [rad/s].
    - `axis`: the frequency axis of `H`.

    **Returns:**

    `-ω² H`, same shape and dtype as `H`.
    """
    H, w, _ = _check_frf(H, omega, axis, "position_to_acceleration_frf")
    return -(w.astype(H.real.dtype) ** 2) * H
