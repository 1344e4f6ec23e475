"""The real block-diagonal (modal) realisation that simulation and conversions share.

Every linear model is brought into this form before it is discretised or converted:
`ceil(n / 2)` real 2x2 blocks, one per complex-conjugate pole pair or per pair of real
poles, padded with one unobservable state when the order is odd. A complex pair
`alpha ± j beta` becomes the rotation block `[[alpha, -beta], [beta, alpha]]` and a real
pair `(p1, p2)` the diagonal block `diag(p1, p2)`; both are normal matrices, so the
realisation keeps its digits at order 8-12 where the companion form loses them
(cf. Golub & Van Loan, *Matrix Computations*, §7.4; scipy's `tf2ss` uses the companion
form). The number of blocks is static, so the form is `jit`/`vmap` friendly: which kind
each block is follows from the poles at run time through `jnp.where`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Complex, Float

from ._statespace import StateSpace


class ModalRealisation(eqx.Module):
    """Real block-diagonal state-space realisation `x' = A x + B u, y = C x + D u`.

    **Fields:**

    - `a`: `(block, 2, 2)` diagonal blocks of `A`.
    - `b`: `(block, 2, in)` rows of `B` belonging to each block.
    - `c`: `(out, block, 2)` columns of `C` belonging to each block.
    - `d`: `(out, in)` feedthrough.
    - `n_states`: true order; when odd, the last state of the last block is padding
      (zero input and output coupling) and is dropped by `to_state_space`.
    """

    a: Float[Array, "block 2 2"]
    b: Float[Array, "block 2 input"]
    c: Float[Array, "output block 2"]
    d: Float[Array, "output input"]
    n_states: int = eqx.field(static=True)

    @property
    def n_blocks(self) -> int:
        return self.a.shape[-3]

    def to_state_space(self) -> StateSpace:
        nb = self.n_blocks
        eye = jnp.eye(nb, dtype=self.a.dtype)
        # block_diag via a Kronecker-like scatter: A[2i + r, 2j + s] = δ_ij a[i, r, s].
        A = jnp.einsum("ij,irs->irjs", eye, self.a).reshape(2 * nb, 2 * nb)
        B = self.b.reshape(2 * nb, -1)
        C = self.c.reshape(self.c.shape[0], 2 * nb)
        n = self.n_states
        return StateSpace(A[:n, :n], B[:n], C[:, :n], self.d)

    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq out in"]:
        a = self.a
        s_ = s[:, None]
        a11, a12, a21, a22 = a[:, 0, 0], a[:, 0, 1], a[:, 1, 0], a[:, 1, 1]
        det = (s_ - a11) * (s_ - a22) - a12 * a21  # (freq, block)
        # (sI - a)^-1 = adj / det with adj = [[s - a22, a12], [a21, s - a11]]
        adj = jnp.stack(
            [
                jnp.stack([s_ - a22, jnp.broadcast_to(a12, det.shape)], -1),
                jnp.stack([jnp.broadcast_to(a21, det.shape), s_ - a11], -1),
            ],
            -2,
        )  # (freq, block, 2, 2)
        g = jnp.einsum("obr,fbrs,bsi->foi", self.c, adj / det[..., None, None], self.b)
        return g + self.d


def _pairing_order(p: Complex[Array, " n"]) -> Array:
    """Indices that put conjugate pairs next to each other, complex before real.

    Keys, most significant first: `-|Im p|` (complex pairs first, real poles last), `Re p`,
    the occurrence index `k` of `p` among bitwise-equal poles, `Im p`. LAPACK returns
    conjugate pairs exactly conjugate and real eigenvalues with an exactly zero imaginary
    part, so consecutive positions `(0, 1), (2, 3), ...` are always a conjugate pair or two
    real poles. `k` interleaves exactly repeated, non-defective pairs (e.g. one copy of each
    mode per input in the realisation of a MIMO `ModalModel`) as `λ̄, λ, λ̄, λ` instead of
    `λ̄, λ̄, λ, λ`. (Defective repeated pairs are not supported by any modal form.)
    """
    n = p.shape[0]
    idx = jnp.arange(n)
    k = jnp.sum((p[None, :] == p[:, None]) & (idx[None, :] < idx[:, None]), axis=1)
    return jnp.lexsort((p.imag, k, p.real, -jnp.abs(p.imag)))


def from_poles(
    poles: Complex[Array, " n"],
    right: Complex[Array, "out n"],
    left: Complex[Array, "n input"],
    d: Float[Array, "out input"],
) -> ModalRealisation:
    """Real block form of `G(s) = Σ_i right[:, i] left[i, :] / (s - poles[i]) + d`.

    `poles` must be closed under conjugation with matching conjugate vectors (as the
    eigen-decomposition of a real matrix gives).
    """
    n = poles.shape[0]
    order = _pairing_order(poles)
    p, v, w = poles[order], right[:, order], left[order, :]
    if n % 2:
        # Pad with a copy of the last (real) pole that is neither driven nor observed.
        p = jnp.concatenate([p, p[-1:]])
        v = jnp.concatenate([v, jnp.zeros_like(v[:, -1:])], axis=1)
        w = jnp.concatenate([w, jnp.zeros_like(w[-1:])], axis=0)
    p1, p2 = p[0::2], p[1::2]
    v1, v2 = v[:, 0::2], v[:, 1::2]
    w1, w2 = w[0::2], w[1::2]
    is_complex = p1.imag != 0

    al, be = p1.real, p1.imag
    a_cplx = jnp.stack([jnp.stack([al, -be], -1), jnp.stack([be, al], -1)], -2)
    zero = jnp.zeros_like(al)
    a_real = jnp.stack([jnp.stack([p1.real, zero], -1), jnp.stack([zero, p2.real], -1)], -2)
    # Complex pair: z' = λ z + w u, y += 2 Re(v z), with z = x1 + j x2.
    b_cplx = jnp.stack([w1.real, w1.imag], axis=1)
    c_cplx = jnp.stack([2 * v1.real, -2 * v1.imag], axis=-1)
    b_real = jnp.stack([w1.real, w2.real], axis=1)
    c_real = jnp.stack([v1.real, v2.real], axis=-1)

    a = jnp.where(is_complex[:, None, None], a_cplx, a_real)
    b = jnp.where(is_complex[:, None, None], b_cplx, b_real)
    c = jnp.where(is_complex[None, :, None], c_cplx, c_real)
    # Balance input and output coupling of each block (a similarity that keeps the
    # block's rotation structure): heuristic, equalises |b| and |c| for conditioning.
    nb = jnp.sqrt(jnp.sum(b**2, axis=(1, 2)))
    nc = jnp.sqrt(jnp.sum(c**2, axis=(0, 2)))
    ok = (nb > 0) & (nc > 0)
    scale = jnp.where(ok, jnp.sqrt(jnp.where(ok, nc / jnp.where(ok, nb, 1.0), 1.0)), 1.0)
    b = b * scale[:, None, None]
    c = c / scale[None, :, None]
    return ModalRealisation(a, b, c, d, n_states=n)


def from_dense(A, B, C, D) -> ModalRealisation:
    """Block form of a dense real state space by eigen-decomposition (distinct poles)."""
    lam, V = jax.lax.linalg.eig(
        A, compute_left_eigenvectors=False, enable_eigvec_derivs=True
    )[:2]
    left = jnp.linalg.solve(V, B.astype(V.dtype))
    right = C.astype(V.dtype) @ V
    return from_poles(lam, right, left, D)
