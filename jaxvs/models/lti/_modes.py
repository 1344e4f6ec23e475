r"""Natural frequencies and mode shapes of lumped mechanical models by the generalised
eigenvalue problem `K φ = ω² M φ` (Pislaru 2001, Appendix E; Ewins, *Modal Testing*,
2000, ch. 2), and damped natural frequencies from the first-order (state-space) form.

For any symmetric positive definite mass matrix `M` and symmetric positive semi-definite
stiffness `K` (a free-free drive chain has a rigid-body mode at `ω = 0`):

- undamped: Cholesky `M = L Lᵀ`, `K̃ = L⁻¹ K L⁻ᵀ`, `K̃ v = ω² v` by `eigh`, `φ = L⁻ᵀ v`,
  so that `Φᵀ M Φ = I` and `Φᵀ K Φ = diag(ω²)` (mass-normalised shapes);
- damped: the eigenvalues `λ = −ζ ω_n ± j ω_n sqrt(1 − ζ²)` of
  `[[0, I], [−M⁻¹K, −M⁻¹C]]` give `ω_n = |λ|`, `ζ = −Re λ / |λ|` and the damped natural
  frequency `ω_d = Im λ` (exact for any, also non-proportional, viscous damping).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real
from ._chain import NormalModes

__all__ = ["DampedModes", "damped_modes", "normal_modes"]


def _square(x: ArrayLike, name: str, where: str) -> Array:
    x = as_real(x, f"{where}: {name}")
    if x.ndim != 2 or x.shape[0] != x.shape[1]:
        raise ValueError(
            f"{where}: {name} must be a square matrix (dof, dof); got shape {x.shape}. vmap "
            "over families."
        )
    return x


def _check_symmetric(x: Array, name: str, where: str) -> Array:
    scale = jnp.max(jnp.abs(x))
    asym = jnp.max(jnp.abs(x - x.T))
    # heuristic: 1e-10 relative asymmetry is rounding; more is a modelling error.
    return eqx.error_if(
        x,
        asym > 1e-10 * scale,
        f"{where}: {name} must be symmetric (K φ = ω² M φ with symmetric M, K); symmetrise "
        "it as (A + A.T) / 2 if the asymmetry is rounding.",
    )


def normal_modes(
    stiffness: Float[ArrayLike, "dof dof"],
    mass: Float[ArrayLike, "dof dof"],
    damping: Float[ArrayLike, "dof dof"] | None = None,
) -> NormalModes:
    r"""Undamped natural frequencies and mass-normalised mode shapes from `(K, M)`.

    Solves `K φ = ω² M φ` (the generalised symmetric-definite eigenproblem, as
    `scipy.linalg.eigh(K, M)`) through the Cholesky factor of `M` and `jnp.linalg.eigh`;
    differentiable (for simple eigenvalues), jittable, vmappable over families.

    **Arguments:**

    - `stiffness`: `(dof, dof)` symmetric positive semi-definite `K` [N/m].
    - `mass`: `(dof, dof)` symmetric positive definite `M` [kg].
    - `damping`: optional `(dof, dof)` viscous damping `C` [N·s/m] for the modal damping
      ratios `ζ_k = φ_kᵀ C φ_k / (2 ω_k)` (exact for proportional damping; the
      classical-normal-mode approximation otherwise, see [`damped_modes`][]). Default 0.

    **Returns:**

    A `NormalModes` with `omega_n` `(mode,)` [rad/s] ascending (rigid-body modes at 0),
    `mode_shapes` `(dof, mode)` with `Φᵀ M Φ = I`, sign fixed so that the entry of largest
    magnitude of each shape is positive, and `zeta` `(mode,)` (0 where `ω = 0`).
    """
    where = "normal_modes"
    K = _square(stiffness, "stiffness", where)
    M = _square(mass, "mass", where)
    if K.shape != M.shape:
        raise ValueError(f"{where}: K {K.shape} and M {M.shape} must have the same shape.")
    C = None
    if damping is not None:
        C = _square(damping, "damping", where)
        if C.shape != K.shape:
            raise ValueError(f"{where}: damping {C.shape} must have K's shape {K.shape}.")
    return _normal_modes(K, M, C)


@jax.jit
def _normal_modes(K, M, C):
    where = "normal_modes"
    dtype = jnp.result_type(K, M)
    K, M = K.astype(dtype), M.astype(dtype)
    K = _check_symmetric(K, "stiffness", where)
    M = _check_symmetric(M, "mass", where)
    L = jnp.linalg.cholesky(M)
    L = eqx.error_if(
        L,
        ~jnp.all(jnp.isfinite(L)),
        f"{where}: the mass matrix is not positive definite (Cholesky failed); every degree "
        "of freedom needs a positive mass.",
    )
    # K̃ = L⁻¹ K L⁻ᵀ by two triangular solves
    Linv_K = jnp.linalg.solve(L, K)
    Kt = jnp.linalg.solve(L, Linv_K.T).T
    Kt = 0.5 * (Kt + Kt.T)
    lam, V = jnp.linalg.eigh(Kt)
    phi = jnp.linalg.solve(L.T, V)
    idx = jnp.argmax(jnp.abs(phi), axis=0)
    sign = jnp.sign(phi[idx, jnp.arange(phi.shape[1])])
    phi = phi * jnp.where(sign == 0, 1.0, sign)
    # rigid-body modes give λ ≈ ±rounding; clip them to 0
    omega = jnp.sqrt(jnp.maximum(lam, 0.0))
    if C is None:
        zeta = jnp.zeros_like(omega)
    else:
        modal_c = jnp.einsum("ik,ij,jk->k", phi, C, phi)
        zeta = jnp.where(omega > 0, modal_c / (2 * jnp.where(omega > 0, omega, 1.0)), 0.0)
    return NormalModes(omega, phi, zeta)


class DampedModes(eqx.Module):
    """Damped modes of `M x'' + C x' + K x = f` (see [`damped_modes`][]).

    **Fields:**

    - `eigenvalues`: `(mode,)` complex eigenvalues with `Im λ >= 0` [1/s], by ascending
      `|λ|` (one per oscillatory mode; an overdamped pair gives two real entries).
    - `omega_n`: `|λ|` [rad/s], the undamped natural frequency of each mode.
    - `omega_d`: `Im λ` [rad/s], the damped natural frequency.
    - `zeta`: `−Re λ / |λ|` [-].
    """

    eigenvalues: Array
    omega_n: Array
    omega_d: Array
    zeta: Array


def damped_modes(
    stiffness: Float[ArrayLike, "dof dof"],
    mass: Float[ArrayLike, "dof dof"],
    damping: Float[ArrayLike, "dof dof"],
) -> DampedModes:
    r"""Damped natural frequencies and damping ratios from the eigenvalues of the
    first-order form `[[0, I], [−M⁻¹K, −M⁻¹C]]` (Pislaru 2001, Appendix E: undamped and
    damped natural frequencies by generalised eigenvalues).

    Exact for any viscous damping, proportional or not. Uses a non-symmetric eigensolver
    (NumPy, on the host), so it is for analysis, not for differentiation.

    **Arguments:**

    - `stiffness`, `mass`, `damping`: `(dof, dof)` `K` [N/m], `M` [kg], `C` [N·s/m].

    **Returns:**

    A [`DampedModes`][]; rigid-body modes (`λ = 0`) are dropped.
    """
    where = "damped_modes"
    K = np.asarray(_square(stiffness, "stiffness", where))
    M = np.asarray(_square(mass, "mass", where))
    C = np.asarray(_square(damping, "damping", where))
    n = K.shape[0]
    if M.shape != (n, n) or C.shape != (n, n):
        raise ValueError(
            f"{where}: K, M, C must have the same shape; got {K.shape}, {M.shape}, {C.shape}."
        )
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
    lam = np.linalg.eigvals(A)
    scale = max(np.max(np.abs(lam)), 1.0)
    # heuristic: |λ| below 1e-9 of the largest is a rigid-body (zero) eigenvalue
    lam = lam[np.abs(lam) > 1e-9 * scale]
    lam = lam[lam.imag >= -1e-12 * scale]
    lam = lam[np.argsort(np.abs(lam))]
    wn = np.abs(lam)
    return DampedModes(
        eigenvalues=jnp.asarray(lam),
        omega_n=jnp.asarray(wn),
        omega_d=jnp.asarray(np.abs(lam.imag)),
        zeta=jnp.asarray(-lam.real / wn),
    )
