r"""Rational frequency-domain least squares through power moments (Levy / Sanathanan-Koerner).

Everything here works on ONE problem in *scaled frequency* `x = s / ω0 = j ν`,
`ν = ω / ω0`, with the model

    G(x) = B(x) / A(x),   B(x) = Σ_{p=0}^{nb} β_p x^p,   A(x) = x^n + Σ_{q=0}^{n-1} α_q x^q,

and the parameter vector `θ = (β_0 … β_nb, α_0 … α_{n-1})` (ascending powers, monic `A`).
Callers `vmap` over a family.

**Why moments.** Every least-squares problem met while fitting `G` has columns
`x^p · f_i` with a per-point complex factor `f_i`, so every entry of a normal matrix is

    Re Σ_i ρ_i conj(x_i^p) x_i^q g_i = Re( j^{q-p} Σ_i ρ_i g_i ν_i^{p+q} ),

a *power moment* `Σ_i (ρ g)_i ν_i^m` of order `m = p + q` (Levy 1959, "Complex-curve fitting",
IRE Trans. Autom. Control AC-4, eq. 10-14, uses the same sums). One `(k, freq) @ (freq, m)`
matrix product with the table `ν_i^m` (shared by the whole family) therefore forms the normal
equations of all `k` weighted quantities at once: `O(freq · n)` work per problem instead of
`O(freq · n²)`, and no `(freq, parameter)` Jacobian is ever materialised.

**Conditioning.** With `ω0` the geometric mean of the band and columns scaled to unit norm,
the weighted columns `x^p / A(x)` have condition numbers of 10-1000 for lightly damped
order-6 TMFs over 2.6 decades (measured), so the normal equations (condition squared) keep
10+ digits in float64. Wider bands or higher orders degrade this; see `fit_rational`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

# Re(j^d) and Im(j^d) for d mod 4.
_RE_J = np.array([1.0, 0.0, -1.0, 0.0])
_IM_J = np.array([0.0, 1.0, 0.0, -1.0])


def _re_jd(d) -> np.ndarray:
    return _RE_J[np.mod(d, 4)]


def _im_jd(d) -> np.ndarray:
    return _IM_J[np.mod(d, 4)]


class Grid(eqx.Module):
    """The scaled frequency grid shared by a family: `ν` and the table of `μ^k = ν^{2k}`."""

    nu: Float[Array, " freq"]
    even_powers: Float[Array, "k freq"]


def make_grid(nu: Float[Array, " freq"], n: int) -> Grid:
    """Grid with `ν^{2k}`, `k = 0 … max(n, 1)` (repeated products: exact powers)."""
    mu = nu * nu
    rows = [jnp.ones_like(nu)]
    for _ in range(max(n, 1)):
        rows.append(rows[-1] * mu)
    return Grid(nu, jnp.stack(rows, axis=0))


# The hot path below uses real arithmetic on (re, im) pairs: XLA:CPU fuses it into one
# loop, whereas complex128 division and complex-valued products of matrices are several
# times slower there (measured).
#
# Parity: Re(x^k) = Re((jν)^k) vanishes for odd k and Im(x^k) for even k, so a polynomial
# evaluates as `Σ_even ± c_k μ^{k/2} + j ν Σ_odd ± c_k μ^{(k-1)/2}` (μ = ν²), and every
# normal-equation entry needs the moments of the real parts at even orders and of the
# imaginary parts at odd orders only (the others are multiplied by Re/Im(j^d) = 0). This
# halves the work of both.


def _horner(coef: Array, mu: Array) -> Array:
    """`Σ_k coef_k μ^k` by Horner's rule: elementwise, so XLA fuses it with its consumers."""
    acc = jnp.broadcast_to(coef[-1], mu.shape)
    for c in coef[-2::-1]:
        acc = acc * mu + c
    return acc


def evaluate(coef: Float[Array, " k"], grid: Grid) -> tuple[Array, Array]:
    """`Σ_k coef_k (j ν)^k` at every point (ascending coefficients), as `(re, im)`."""
    ce, co = coef[0::2], coef[1::2]
    mu = grid.even_powers[1]
    re = _horner(ce * (-1.0) ** np.arange(ce.shape[0]), mu)
    if co.shape[0] == 0:
        return re, jnp.zeros_like(re)
    im = grid.nu * _horner(co * (-1.0) ** np.arange(co.shape[0]), mu)
    return re, im


def _moments(even: list[Array], odd: list[Array], grid: Grid) -> list[Array]:
    """Power moments `Σ_i z_i ν_i^m`, indexed by `m`, of the rows `even + odd`.

    Rows in `even` are only needed at even `m`, rows in `odd` at odd `m`; the entries of
    the other parity are returned as zeros. One matrix product over the frequency axis.
    """
    rows = jnp.stack(list(even) + [grid.nu * z for z in odd])
    mom = jnp.einsum("rf,kf->rk", rows, grid.even_powers)
    zero = jnp.zeros_like(mom[0])
    out = []
    for i in range(len(even) + len(odd)):
        pair = [mom[i], zero] if i < len(even) else [zero, mom[i]]
        out.append(jnp.stack(pair, axis=-1).reshape(-1))  # out[m] = moment of order m
    return out


def denominator(alpha: Float[Array, " n"]) -> Float[Array, " n1"]:
    """Ascending coefficients of the monic `A` from its free coefficients `α_0 … α_{n-1}`."""
    return jnp.concatenate([alpha, jnp.ones((1,), alpha.dtype)])


def _gram(
    lam: Float[Array, " m"],
    u: Float[Array, " m"],
    s_re: Float[Array, " m"],
    s_im: Float[Array, " m"],
    nb: int,
    n: int,
) -> Float[Array, "p p"]:
    r"""Normal matrix `Re(Φ^H Φ)` of the columns `Φ = [x^p / A | -G x^q / A]` (weighted).

    `lam`, `u`, `s` are the moments of `ρ`, `ρ |G|²` and `ρ G` with `ρ = w² / |A|²`:

    - `BB[p, q] =  Re(j^{q-p}) λ_{p+q}`
    - `AA[p, q] =  Re(j^{q-p}) U_{p+q}`
    - `BA[p, q] = -Re(j^{q-p} S_{p+q})`
    """
    pb, qb = np.meshgrid(np.arange(nb + 1), np.arange(nb + 1), indexing="ij")
    pa, qa = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    pc, qc = np.meshgrid(np.arange(nb + 1), np.arange(n), indexing="ij")
    bb = _re_jd(qb - pb) * lam[pb + qb]
    aa = _re_jd(qa - pa) * u[pa + qa]
    ba = -(_re_jd(qc - pc) * s_re[pc + qc] - _im_jd(qc - pc) * s_im[pc + qc])
    top = jnp.concatenate([bb, ba], axis=1)
    bottom = jnp.concatenate([ba.T, aa], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


def _re_conj_j(z_re: Float[Array, " m"], z_im: Float[Array, " m"], k: int) -> Float[Array, " k"]:
    """`Re((-j)^p Z_p)` for `p = 0 … k-1` (the projection `Re Σ conj(x^p) z`)."""
    p = np.arange(k)
    return _re_jd(-p) * z_re[:k] - _im_jd(-p) * z_im[:k]


def solve_spd(m: Float[Array, "p p"], rhs: Float[Array, " p"]) -> Float[Array, " p"]:
    """Solve a symmetric positive (semi)definite system after scaling it to unit diagonal.

    Heuristic: a ridge of `1e-13` (relative to the unit diagonal) keeps the Cholesky
    factorisation defined when columns are numerically dependent; it changes the solution
    of a well-posed problem by ~1e-13 relative.
    """
    d = jnp.diagonal(m)
    d = jnp.where(d > 0, d, 1.0)
    sc = 1.0 / jnp.sqrt(d)
    ms = m * sc[:, None] * sc[None, :] + 1e-13 * jnp.eye(m.shape[0], dtype=m.dtype)
    chol = jnp.linalg.cholesky(ms)
    y = jax.scipy.linalg.cho_solve((chol, True), rhs * sc)
    return y * sc


Data = tuple[Float[Array, " freq"], Float[Array, " freq"], Float[Array, " freq"]]
"""`(Re H, Im H, w²)` of one problem."""


def sk_step_relaxed(
    alpha_prev: Float[Array, " n"], data: Data, grid: Grid, nb: int
) -> tuple[Float[Array, " n"], Float[Array, " nb1"], Bool[Array, ""]]:
    r"""One relaxed Sanathanan-Koerner iteration: the new monic denominator and numerator.

    Sanathanan & Koerner (1963, IEEE TAC 8(1), eq. 8) minimise the linearised error
    `Σ w² |B(x) - H A(x)|² / |A_prev(x)|²` over `(B, A)`; at a fixed point `A = A_prev`
    this is the output error `Σ w² |B/A - H|²` up to the variation of the weight. Instead
    of fixing `A` monic, all `n + 1` coefficients of `A` are free under the normalisation
    `Re Σ_i A(x_i) / A_prev(x_i) = const`: the *relaxed* vector fitting of Gustavsen
    (2006, "Improving the pole relocating properties of vector fitting", IEEE TPWRD 21(3),
    eq. 8), which relocates poles more reliably. The equality-constrained least squares
    `min θᵀMθ s.t. cᵀθ = 1` has the solution `θ ∝ M⁻¹c`; `A` is then made monic.
    `|A_prev(jν)|` does not change when poles are reflected about the imaginary axis, so
    the iterates do not depend on pole flipping.

    Returns `(α, β, ok)`; `ok` is false when the leading coefficient of `A` vanished (a
    pole went to infinity), in which case `α = alpha_prev`.
    """
    hr, hi, w2 = data
    n = alpha_prev.shape[-1]
    ar, ai = evaluate(denominator(alpha_prev), grid)
    a2 = ar**2 + ai**2
    rho = w2 / a2
    lam, u, z_re, s_re, s_im, z_im = _moments(
        [rho, rho * (hr**2 + hi**2), ar / a2, rho * hr], [rho * hi, -ai / a2], grid
    )
    gram = _gram(lam, u, s_re, s_im, nb, n + 1)
    q = np.arange(n + 1)
    c_a = _re_jd(q) * z_re[q] - _im_jd(q) * z_im[q]  # Re Σ x^q / A_prev(x)
    c = jnp.concatenate([jnp.zeros((nb + 1,), c_a.dtype), c_a])
    theta = solve_spd(gram, c)
    alpha = theta[nb + 1 :]
    # A vanishing leading coefficient sends a pole to infinity: keep the previous
    # denominator.
    lead_ok = jnp.abs(alpha[n]) > 1e-12 * jnp.max(jnp.abs(alpha))
    lead = jnp.where(lead_ok, alpha[n], 1.0)
    return jnp.where(lead_ok, alpha[:n] / lead, alpha_prev), theta[: nb + 1] / lead, lead_ok


def refit_numerator(
    alpha: Float[Array, " n"], data: Data, grid: Grid, nb: int, *, with_cost: bool = False
):
    """Numerator minimising `Σ w² |B/A - H|²` for a fixed denominator (linear least squares).

    With `with_cost=True` also returns that minimum, `½ (Σ w² |H|² - βᵀ g)` with `g` the
    right-hand side of the normal equations `M β = g` (so `βᵀ M β = βᵀ g`).
    """
    hr, hi, w2 = data
    ar, ai = evaluate(denominator(alpha), grid)
    rho = w2 / (ar**2 + ai**2)
    # z = ρ H A = w² H / conj(A)
    z_re = rho * (hr * ar - hi * ai)
    z_im = rho * (hr * ai + hi * ar)
    lam, z_re, z_im = _moments([rho, z_re], [z_im], grid)
    gram = _gram(lam, lam, lam, lam, nb, 0)
    rhs = _re_conj_j(z_re, z_im, nb + 1)
    beta = solve_spd(gram, rhs)
    if not with_cost:
        return beta
    return beta, 0.5 * (jnp.dot(w2, hr * hr + hi * hi) - jnp.dot(beta, rhs))


def _model(theta, grid, nb):
    """`G = B / A` as `(re, im)` and `(Re A, Im A, |A|²)`."""
    beta, alpha = theta[: nb + 1], theta[nb + 1 :]
    ar, ai = evaluate(denominator(alpha), grid)
    br, bi = evaluate(beta, grid)
    a2 = ar**2 + ai**2
    return (br * ar + bi * ai) / a2, (bi * ar - br * ai) / a2, ar, ai, a2


def normal_equations(
    theta: Float[Array, " p"], data: Data, grid: Grid, nb: int
) -> tuple[Float[Array, ""], Float[Array, "p p"], Float[Array, " p"]]:
    r"""Cost `½ Σ w² |G - H|²`, Gauss-Newton matrix `JᵀJ` and gradient `Jᵀr` of the output error.

    With `r = w (G - H)` split into real and imaginary parts, `∂G/∂β_p = x^p / A` and
    `∂G/∂α_q = -G x^q / A`; then `JᵀJ` is [`_gram`][] with `ρ = w²/|A|²` and `G` the model,
    and with `E = w² (G - H) / conj(A)`: `(Jᵀr)_β = Re((-j)^p T_p)`, `(Jᵀr)_α = -Re((-j)^q V_q)`
    where `T`, `V` are the moments of `E` and `conj(G) E`.
    """
    hr, hi, w2 = data
    n = theta.shape[-1] - nb - 1
    gr, gi, ar, ai, a2 = _model(theta, grid, nb)
    rr, ri = gr - hr, gi - hi
    # A dot product rather than a sum: XLA:CPU's fused reductions are slower (measured).
    cost = 0.5 * jnp.dot(w2, rr * rr + ri * ri)
    rho = w2 / a2
    # E = w² r / conj(A) = ρ r A
    er = rho * (rr * ar - ri * ai)
    ei = rho * (rr * ai + ri * ar)
    even = [rho, rho * (gr**2 + gi**2), rho * gr, er, gr * er + gi * ei]  # conj(G) E last
    odd = [rho * gi, ei, gr * ei - gi * er]
    lam, u, s_re, t_re, v_re, s_im, t_im, v_im = _moments(even, odd, grid)
    jtj = _gram(lam, u, s_re, s_im, nb, n)
    jtr = jnp.concatenate([_re_conj_j(t_re, t_im, nb + 1), -_re_conj_j(v_re, v_im, n)])
    return cost, jtj, jtr


def model_cost(
    theta: Float[Array, " p"], data: Data, grid: Grid, nb: int
) -> Float[Array, ""]:
    """`½ Σ w² |B/A - H|²` only."""
    hr, hi, w2 = data
    gr, gi, *_ = _model(theta, grid, nb)
    rr, ri = gr - hr, gi - hi
    return 0.5 * jnp.dot(w2, rr * rr + ri * ri)


def is_hurwitz(alpha: Float[Array, " n"]) -> Bool[Array, ""]:
    r"""Whether the monic `A(x) = x^n + Σ α_q x^q` has all roots in the open left half-plane.

    Routh's test (Routh 1877; Ogata, *Modern Control Engineering*, §5-6): all entries of
    the first column of the Routh array are positive. `O(n²)` arithmetic, no roots; a zero
    first-column entry (a root on, or a pair symmetric about, the imaginary axis) counts
    as unstable.
    """
    n = alpha.shape[-1]
    c = jnp.concatenate([alpha, jnp.ones((1,), alpha.dtype)])[::-1]  # highest power first
    r0 = c[0::2]
    r1 = c[1::2]
    width = (n + 2) // 2
    r0 = jnp.pad(r0, (0, width - r0.shape[0]))
    r1 = jnp.pad(r1, (0, width - r1.shape[0]))
    ok = r0[0] > 0
    for _ in range(n):
        ok = ok & (r1[0] > 0)
        piv = jnp.where(r1[0] > 0, r1[0], 1.0)
        nxt = (r1[0] * r0[1:] - r0[0] * r1[1:]) / piv
        r0, r1 = r1, jnp.pad(nxt, (0, 1))
    return ok


def flip_unstable(alpha: Float[Array, " n"]) -> tuple[Float[Array, " n"], Bool[Array, ""]]:
    """Reflect right-half-plane roots of the monic `A` about the imaginary axis.

    Keeps `|A(jν)|` (hence the Sanathanan-Koerner weight) unchanged, so it is the usual
    stabilisation of vector fitting (Gustavsen & Semlyen 1999, IEEE TPWRD 14(3), §III.B).
    Returns the new coefficients and whether any root was flipped.
    """
    n = alpha.shape[-1]
    roots = jnp.roots(denominator(alpha)[::-1], strip_zeros=False)
    flipped = jnp.any(roots.real > 0)
    roots = jax.lax.complex(-jnp.abs(roots.real), roots.imag)
    # Rebuild by repeated multiplication (jnp.poly); imaginary parts cancel in conjugate
    # pairs up to rounding.
    coef = jnp.poly(roots).real[::-1][:n]
    return jnp.where(flipped, coef, alpha), flipped


def start_denominator(nu_lo: Float[Array, ""], nu_hi: Float[Array, ""], n: int) -> Array:
    """Starting poles in the manner of vector fitting (Gustavsen & Semlyen 1999, §IV).

    Heuristic: `n // 2` complex pairs of damping ratio 0.1 whose natural frequencies are
    the geometric midpoints of `n // 2` equal log-intervals of the band `[nu_lo, nu_hi]`
    (scaled units), plus one real pole at the band's geometric mean when `n` is odd.
    Measured on 1280 random lightly damped order-6 TMFs with 1 % noise, this start missed
    the global optimum 4x less often than pairs at the band edges with damping 0.01.
    Returns the free coefficients `α` (ascending) of the monic polynomial.
    """
    k = n // 2
    edges = jnp.exp(jnp.linspace(jnp.log(nu_lo), jnp.log(nu_hi), k + 1))
    nus = jnp.sqrt(edges[1:] * edges[:-1])
    coef = jnp.ones((1,), nus.dtype)
    for i in range(k):
        # x² + 2 ζ ν_k x + ν_k², ascending
        coef = jnp.convolve(coef, jnp.stack([nus[i] ** 2, 0.2 * nus[i], jnp.ones_like(nus[i])]))
    if n % 2:
        mid = jnp.sqrt(nu_lo * nu_hi)
        coef = jnp.convolve(coef, jnp.stack([mid, jnp.ones_like(mid)]))
    return coef[:n]
