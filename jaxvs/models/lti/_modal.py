"""Modal models: a sum of damped second-order modes (experimental modal analysis)."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float, Shaped

from ..._misc import as_real
from .._base import AbstractLinearModel, check_batch
from .._realisation import ModalRealisation


class ModalModel(AbstractLinearModel):
    r"""Sum of second-order modes, `G(s) = Σ_k (a_k s + b_k) / (s² + 2 ζ_k ω_k s + ω_k²) + D`.

    The mode numerators come from the residues (Ewins, *Modal Testing*, 2000, §2.6):

    - **real** residues `r_k` are modal constants (mass-normalised mode-shape products):
      `r_k / (s² + 2 ζ_k ω_k s + ω_k²)`, i.e. `a_k = 0`, `b_k = r_k`. Valid for any ζ ≥ 0.
    - **complex** residues `R_k` belong to the upper pole
      `λ_k = ω_k (-ζ_k + j sqrt(1 - ζ_k²))`: `R_k / (s - λ_k) + conj(R_k) / (s - conj(λ_k))`,
      i.e. `a_k = 2 Re R_k`, `b_k = -2 Re(R_k conj(λ_k))`. Requires ζ_k < 1.

    **Arguments:**

    - `omega_n`: `(*batch, mode)` natural frequencies [rad/s], > 0.
    - `zeta`: `(*batch, mode)` damping ratios [-], >= 0.
    - `residues`: `(*batch, mode)` for one output, `(*batch, mode, out)` for several
      outputs of one input, or `(*batch, mode, out, in)`; units of the response per
      input per s².
    - `feedthrough`: optional direct term `D`, shape `(*batch, *io)` like one mode's
      residue (default 0).
    """

    omega_n: Float[Array, "*batch mode"]
    zeta: Float[Array, "*batch mode"]
    residues: Shaped[Array, "..."]
    feedthrough: Float[Array, "..."]
    io_shape: tuple[int, ...] = eqx.field(static=True)

    def __init__(
        self,
        omega_n: ArrayLike,
        zeta: ArrayLike,
        residues: ArrayLike,
        *,
        feedthrough: ArrayLike | None = None,
    ):
        omega_n, zeta = as_real(omega_n, "omega_n"), as_real(zeta, "zeta")
        residues = jnp.asarray(residues)
        if not (jnp.issubdtype(residues.dtype, jnp.inexact)):
            residues = residues.astype(jnp.result_type(float))
        if omega_n.ndim < 1 or omega_n.shape != zeta.shape:
            raise ValueError(
                "ModalModel: omega_n and zeta must have the same shape (*batch, mode); "
                f"got {omega_n.shape} and {zeta.shape}."
            )
        batch, n_modes = omega_n.shape[:-1], omega_n.shape[-1]
        lead = residues.shape[: len(batch) + 1]
        io = residues.shape[len(batch) + 1 :]
        if lead != omega_n.shape or len(io) > 2:
            raise ValueError(
                f"ModalModel: residues of shape {residues.shape} do not match "
                f"omega_n {omega_n.shape}; expected (*batch, mode), (*batch, mode, out) "
                "or (*batch, mode, out, in) with the same batch and mode axes."
            )
        if feedthrough is None:
            feedthrough = jnp.zeros(batch + io, omega_n.dtype)
        feedthrough = as_real(feedthrough, "feedthrough")
        if feedthrough.shape != batch + io:
            feedthrough = jnp.broadcast_to(feedthrough, batch + io)
        check_batch([batch, zeta.shape[:-1], lead[:-1]], "ModalModel")
        omega_n = eqx.error_if(
            omega_n, omega_n <= 0, "ModalModel: natural frequencies omega_n must be > 0 rad/s."
        )
        zeta = eqx.error_if(zeta, zeta < 0, "ModalModel: damping ratios zeta must be >= 0.")
        if jnp.iscomplexobj(residues):
            zeta = eqx.error_if(
                zeta,
                zeta >= 1,
                "ModalModel: complex residues need underdamped modes (zeta < 1); give "
                "real modal constants for over-damped modes.",
            )
        self.omega_n, self.zeta, self.residues = omega_n, zeta, residues
        self.feedthrough = feedthrough
        self.io_shape = tuple(io)
        del n_modes

    @property
    def n_modes(self) -> int:
        return self.omega_n.shape[-1]

    @property
    def n_outputs(self) -> int:
        return self.io_shape[0] if len(self.io_shape) >= 1 else 1

    @property
    def n_inputs(self) -> int:
        return self.io_shape[1] if len(self.io_shape) == 2 else 1

    @property
    def order(self) -> int:
        return 2 * self.n_modes * self.n_inputs

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.omega_n.shape[:-1]

    def _sections(self) -> tuple[Float[Array, "mode out in"], Float[Array, "mode out in"]]:
        """Numerator coefficients `(a_k, b_k)` of every mode, shape `(mode, out, in)`."""
        r = self.residues.reshape(self.n_modes, self.n_outputs, self.n_inputs)
        if jnp.iscomplexobj(r):
            w, z = self.omega_n[:, None, None], self.zeta[:, None, None]
            lam = jax.lax.complex(-z * w, w * jnp.sqrt(1 - z**2))
            return 2 * r.real, -2 * (r * jnp.conj(lam)).real
        return jnp.zeros_like(r), r

    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq out in"]:
        a, b = self._sections()
        w, z = self.omega_n, self.zeta
        den = s[:, None] ** 2 + 2 * z * w * s[:, None] + w**2  # (freq, mode)
        num = s[:, None, None, None] * a + b  # (freq, mode, out, in)
        d = self.feedthrough.reshape(self.n_outputs, self.n_inputs)
        return jnp.sum(num / den[..., None, None], axis=1) + d

    def modal_realisation(self) -> ModalRealisation:
        # One block per (mode, input), scaled coordinates x = (ω q, q') of
        # q'' + 2ζω q' + ω² q = u_j, y = b q + a q'; well-conditioned for any ζ.
        a, b = self._sections()
        m, p, n_in = self.n_modes, self.n_outputs, self.n_inputs
        w = jnp.repeat(self.omega_n, n_in)  # block = mode * n_in + j
        z = jnp.repeat(self.zeta, n_in)
        zero = jnp.zeros_like(w)
        A = jnp.stack([jnp.stack([zero, w], -1), jnp.stack([-w, -2 * z * w], -1)], -2)
        j_of_block = jnp.tile(jnp.arange(n_in), m)
        B = jnp.zeros((m * n_in, 2, n_in), w.dtype).at[jnp.arange(m * n_in), 1, j_of_block].set(1.0)
        # C[o, block, :] = [b_k,o,j / ω_k, a_k,o,j]
        bb = jnp.transpose(b, (1, 0, 2)).reshape(p, m * n_in)
        aa = jnp.transpose(a, (1, 0, 2)).reshape(p, m * n_in)
        C = jnp.stack([bb / w, aa], axis=-1)
        d = self.feedthrough.reshape(p, n_in)
        return ModalRealisation(A, B, C, d, n_states=2 * m * n_in)
