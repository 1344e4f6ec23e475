"""Covariance of least-squares estimates from the Jacobian, and its delta-method map to
physical parameters."""

import jax.numpy as jnp
import scipy.stats
from jaxtyping import Array, Bool, Float, Int

__all__ = ["jacobian_covariance", "delta_method", "t_quantile"]


def jacobian_covariance(
    jac: Float[Array, "residual param"], residual: Float[Array, " residual"]
) -> tuple[Float[Array, "param param"], Bool[Array, " param"], Int[Array, ""], Float[Array, ""]]:
    r"""Asymptotic covariance `σ̂² (JᵀJ)⁻¹` of a least-squares estimate, with a rank test.

    `σ̂² = SSR / (N - p)` is the unbiased residual variance (Seber & Wild, *Nonlinear
    Regression*, 1989, §2.1). `(JᵀJ)⁻¹` is formed from the SVD of
    the column-equilibrated Jacobian `J D⁻¹` (`D` = column norms), so that parameters in
    different units do not fake a rank deficiency: `(JᵀJ)⁻¹ = D⁻¹ V S⁻² Vᵀ D⁻¹`.
    Singular values below `max(N, p) · ε · s_max` (numpy's `matrix_rank` rule) span the
    non-identifiable directions; every parameter with a weight above 1e-6 in them
    (heuristic) is flagged and gets an infinite variance.

    **Arguments:**

    - `jac`: `(N, p)` Jacobian of the residual at the estimate.
    - `residual`: `(N,)` residual at the estimate.

    **Returns:**

    `(covariance (p, p), unidentified (p,) bool, rank, sigma2)`.
    """
    n, p = jac.shape
    col = jnp.sqrt(jnp.sum(jac**2, axis=0))
    d = jnp.where(col > 0, col, 1.0)
    _, s, vt = jnp.linalg.svd(jac / d, full_matrices=False)
    eps = jnp.finfo(jac.dtype).eps
    keep = s > max(n, p) * eps * jnp.max(s)
    rank = jnp.sum(keep)
    s_inv2 = jnp.where(keep, 1.0 / jnp.where(keep, s, 1.0) ** 2, 0.0)
    inv = (vt.T * s_inv2) @ vt / jnp.outer(d, d)
    null_weight = jnp.sum(jnp.where(keep[:, None], 0.0, vt**2), axis=0)
    unidentified = (null_weight > 1e-6) | (col == 0)
    sigma2 = jnp.sum(residual**2) / (n - p)
    cov = sigma2 * inv
    cov = jnp.where(unidentified[:, None] | unidentified[None, :], jnp.nan, cov)
    cov = jnp.where(jnp.diag(unidentified), jnp.inf, cov)
    return cov, unidentified, rank, sigma2


def delta_method(
    grad: Float[Array, "phys raw"],
    cov_raw: Float[Array, "raw raw"],
    unidentified: Bool[Array, " raw"],
) -> Float[Array, "phys phys"]:
    r"""Covariance of `φ(θ)` from that of `θ`: `G Σ Gᵀ`, `G = ∂φ/∂θ` (first-order delta
    method; Casella & Berger, *Statistical Inference*, 2nd ed., 2002, §5.5.4). Physical
    parameters that depend on a non-identified raw parameter get an infinite variance and
    NaN covariances."""
    finite = jnp.where(unidentified[:, None] | unidentified[None, :], 0.0, cov_raw)
    cov = grad @ finite @ grad.T
    bad = jnp.any((grad != 0) & unidentified[None, :], axis=1)
    cov = jnp.where(bad[:, None] | bad[None, :], jnp.nan, cov)
    return jnp.where(jnp.diag(bad), jnp.inf, cov)


def t_quantile(level: float, dof: int) -> float:
    """Two-sided Student-t quantile `t_{(1+level)/2, dof}` (static `dof`)."""
    return float(scipy.stats.t.ppf(0.5 + level / 2, dof))
