"""A rational transmissibility with an always-stable denominator in modal form.

`StableTMF` is the encoder-to-tool-centre-point transmissibility of the TMF study
(Doerrer et al. 2022, eq. 8) parametrised for calibration: the denominator as second-order
sections in `log ω`, `log ζ` (and `log p` for an odd order), so that no iterate of a
calibration can leave the stable region, simulated exactly with the zero-order hold in
modal coordinates ([`simulate_modal`][]). The `tmf` family of `jaxvs.diagnose` builds its
nominal model and its effects on it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Complex, Float

from ..._misc import polymul
from .._base import AbstractLinearModel
from .._realisation import ModalRealisation, from_poles
from ..lti import RationalTF

__all__ = ["StableTMF", "partial_fractions", "pole_sections", "section_poles", "simulate_modal"]


def _f(x) -> float:
    return float(np.asarray(x).reshape(-1)[0])


def pole_sections(poles: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """Pair stable poles into second-order sections `(ω, ζ)` plus at most one real pole
    `p`, all > 0 (two real poles `−a`, `−b` become `ω = √(ab)`, `ζ = (a + b)/(2√(ab))`).

    **Returns:** `(omegas, zetas, reals)` [rad/s, −, rad/s], sections by increasing `|pole|`."""
    tol = 1e-9 * max(1.0, float(np.max(np.abs(poles))))
    upper = sorted((p for p in poles if p.imag > tol), key=abs)
    real = sorted(float(p.real) for p in poles if abs(p.imag) <= tol)
    omegas, zetas = [abs(p) for p in upper], [-p.real / abs(p) for p in upper]
    while len(real) >= 2:
        a, b = -real.pop(0), -real.pop(0)
        omegas.append(math.sqrt(a * b))
        zetas.append((a + b) / (2 * math.sqrt(a * b)))
    return omegas, zetas, [-r for r in real]


def section_poles(omega: Array, zeta: Array, real: Array) -> Array:
    """The roots of `Π (s² + 2ζωs + ω²) · Π (s + p)`: `ω(−ζ ± √(ζ² − 1))` and `−p`.

    Both roots of each section are returned (a conjugate pair, or two real roots when
    `ζ > 1`); a double root at `ζ = 1` is split by 1e-10 so that residues stay finite.
    """
    cdt = jnp.result_type(omega.dtype, jnp.complex64)
    disc = zeta**2 - 1.0
    disc = jnp.where(jnp.abs(disc) < 1e-10, -1e-10, disc)
    root = jnp.sqrt(disc.astype(cdt))
    upper = omega * (-zeta + root)
    lower = omega * (-zeta - root)
    return jnp.concatenate([upper, lower, (-real).astype(cdt)])


def partial_fractions(num: Array, poles: Array) -> tuple[Array, Array]:
    """`B(s) / Π(s − p_i) = d + Σ r_i / (s − p_i)` for distinct poles and
    `len(num) <= len(poles) + 1` (highest power first): `d` and the residues
    `r_i = B(p_i) / Π_{j≠i}(p_i − p_j)` (the remainder `B − d·A` vanishes at every pole
    like `B` does up to `d·A(p_i) = 0`)."""
    n = poles.shape[0]
    num = jnp.concatenate([jnp.zeros((n + 1 - num.shape[0],), num.dtype), num])
    d = num[0]
    diff = poles[:, None] - poles[None, :]
    diff = jnp.where(jnp.eye(n, dtype=bool), 1.0, diff)
    res = jnp.polyval(num.astype(poles.dtype), poles) / jnp.prod(diff, axis=1)
    return d, res


def simulate_modal(
    d: Array, residues: Array, poles: Array, u: Float[Array, " n"], dt: float
) -> Float[Array, " n"]:
    """Zero-order-hold response from rest of `d + Σ r_i / (s − p_i)` (poles [rad/s]).

    Each first-order mode is discretised exactly, `x_{k+1} = e^{p dt} x_k + (e^{p dt} − 1)/p
    u_k` (the input held over each sample), and `y_k = d u_k + Re Σ r_i x_{i,k}`: the
    modal form of `jaxvs.simulate(..., method="zoh")`, as one `lax.scan` over time with
    closed-form poles. (Measured: for forward-mode Jacobians of a few thousand samples this
    plain scan beats an FFT convolution, an associative scan and a blocked scan on CPU.)
    """
    lam = jnp.exp(poles * dt)
    gam = jnp.expm1(poles * dt) / poles

    def step(x, uk):
        return lam * x + gam * uk, jnp.real(jnp.sum(residues * x))

    _, y = jax.lax.scan(step, jnp.zeros(poles.shape, poles.dtype), u)
    return d * u + y


def polish_roots(den: Float[Array, " n1"], start: Array, iterations: int = 24) -> Array:
    """Roots of the monic polynomial `den` (highest power first) by the Durand–Kerner
    (Weierstrass) simultaneous iteration from `start`, e.g. the roots of a nearby
    polynomial. A fixed number of iterations, so it is `jit`/`vmap`-friendly and
    differentiable; converged iterates give the implicit-function derivative."""
    n = start.shape[0]
    eye = jnp.eye(n, dtype=bool)
    den = den.astype(start.dtype)

    def step(z, _):
        diff = jnp.where(eye, 1.0, z[:, None] - z[None, :])
        return z - jnp.polyval(den, z) / jnp.prod(diff, axis=1), None

    z, _ = jax.lax.scan(step, start, None, length=iterations)
    return z


class StableTMF(AbstractLinearModel):
    """A rational TMF of equal orders with an always-stable denominator, `x_t = T(s) x_e`.

    `T(s) = B(σ) / A(σ)`, `σ = s / w0`, `A(σ) = Π (σ² + 2ζ_k ω_k σ + ω_k²) (σ + p)`, with
    `ω_k = exp(log_omega_k)`, `ζ_k = exp(log_zeta_k)`, `p = exp(log_pole)` (odd order
    only), all in units of `w0` [rad/s]. Simulated with the zero-order hold from rest
    (exact discretisation of the modal form, see [`simulate_modal`][]).

    **Fields:** `num` `(order + 1,)` numerator of `B(σ)`, highest power first;
    `log_omega`, `log_zeta` `(order // 2,)`; `log_pole` `(order % 2,)`; `w0` [rad/s]
    and `dt` [s] are constants (`simulate` and calling the TMF on a record use `dt`;
    `predict(u, dt)` and `jaxvs.simulate` take the sample time they are given).
    """

    num: Float[Array, " n1"]
    log_omega: Float[Array, " sec"]
    log_zeta: Float[Array, " sec"]
    log_pole: Float[Array, " odd"]
    w0: float = eqx.field(static=True)
    dt: float = eqx.field(static=True)

    @property
    def order(self) -> int:
        return self.num.shape[-1] - 1

    @property
    def n_inputs(self) -> int:
        return 1

    @property
    def n_outputs(self) -> int:
        return 1

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.num.shape[:-1]

    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq out in"]:
        sigma = s / self.w0
        den = self.scaled_denominator().astype(sigma.dtype)
        g = jnp.polyval(self.num.astype(sigma.dtype), sigma) / jnp.polyval(den, sigma)
        return g[:, None, None]

    def modal_realisation(self) -> ModalRealisation:
        # T(s) = d + Σ r_i / (σ − p_i) = d + Σ r_i w0 / (s − w0 p_i)
        p = self.scaled_poles()
        d, r = partial_fractions(self.num, p)
        return from_poles(
            p * self.w0,
            (r * self.w0)[None, :],
            jnp.ones((p.shape[0], 1), p.dtype),
            jnp.reshape(d, (1, 1)),
        )

    def flat(self) -> Float[Array, " p"]:
        return jnp.concatenate([self.num, self.log_omega, self.log_zeta, self.log_pole])

    def _split(self, delta: Array | None):
        th = self.flat() if delta is None else self.flat() + delta
        n1, ns, no = self.num.shape[0], self.log_omega.shape[0], self.log_pole.shape[0]
        return (
            th[:n1],
            th[n1 : n1 + ns],
            th[n1 + ns : n1 + 2 * ns],
            th[n1 + 2 * ns : n1 + 2 * ns + no],
        )

    def scaled_poles(self, delta: Array | None = None) -> Array:
        """Poles in units of `w0` (roots of `A(σ)`)."""
        _, lw, lz, lp = self._split(delta)
        return section_poles(jnp.exp(lw), jnp.exp(lz), jnp.exp(lp))

    def simulate(
        self, u: Float[Array, " n"], delta: Array | None = None, num: Array | None = None
    ) -> Float[Array, " n"]:
        """Response to `u` of `B(σ)/A(σ)` (or of `num(σ)/A(σ)`), parameters `flat() + delta`."""
        b, _, _, _ = self._split(delta)
        b = b if num is None else num
        p = self.scaled_poles(delta)
        d, r = partial_fractions(b, p)
        return simulate_modal(d, r * self.w0, p * self.w0, u, self.dt)

    def __call__(self, d: Mapping[str, Array]) -> Float[Array, " n"]:
        return self.simulate(d["x_e"])

    def scaled_denominator(self) -> Float[Array, " n1"]:
        """`A(σ)`, monic, highest power first."""
        _, lw, lz, lp = self._split(None)
        w, z = jnp.exp(lw), jnp.exp(lz)
        den = jnp.ones((1,), w.dtype)
        for k in range(w.shape[0]):
            den = polymul(den, jnp.stack([jnp.ones_like(w[k]), 2 * z[k] * w[k], w[k] ** 2]))
        for k in range(lp.shape[0]):
            den = polymul(den, jnp.stack([jnp.ones_like(lp[k]), jnp.exp(lp[k])]))
        return den

    def simulate_shifted(
        self, u: Float[Array, " n"], dnum: Float[Array, " n1"], dden: Float[Array, " n"]
    ) -> Float[Array, " n"]:
        """Response of `(B(σ) + dnum) / (A(σ) + [0, dden])`: coefficients moved linearly
        (the leading denominator coefficient stays 1); poles by Durand–Kerner from the
        nominal ones."""
        den = self.scaled_denominator() + jnp.concatenate([jnp.zeros((1,), dden.dtype), dden])
        p0 = self.scaled_poles()
        p = polish_roots(den, p0)
        # keep every iterate finite and stable: right-half-plane roots are reflected (pole
        # flipping), a failed root polish falls back to the nominal poles
        p = jnp.where(jnp.real(p) > 0, -jnp.conj(p), p)
        p = jnp.where(jnp.all(jnp.isfinite(p)), p, p0)
        d, r = partial_fractions(self.num + dnum, p)
        return simulate_modal(d, r * self.w0, p * self.w0, u, self.dt)

    def tf(self) -> RationalTF:
        """The TMF as a `RationalTF` in physical coefficients (concrete use)."""
        num, lw, lz, lp = (np.asarray(x) for x in self._split(None))
        den = np.ones(1)
        for w, z in zip(np.exp(lw), np.exp(lz)):
            den = np.polymul(den, [1.0, 2 * z * w, w * w])
        for p in np.exp(lp):
            den = np.polymul(den, [1.0, p])
        powers = self.w0 ** np.arange(0, self.order + 1, dtype=float)
        # Σ c_i σ^(n−i) with σ = s/w0, times w0^n: the coefficient of s^(n−i) is c_i w0^i
        return RationalTF(num * powers, den * powers)

    def parameters(self) -> dict[str, float]:
        out = {}
        w = np.exp(np.asarray(self.log_omega)) * self.w0
        z = np.exp(np.asarray(self.log_zeta))
        for i, k in enumerate(np.argsort(w)):
            out[f"f_{i + 1}_hz"] = float(w[k] / (2 * math.pi))
            out[f"zeta_{i + 1}"] = float(z[k])
        for k, p in enumerate(np.exp(np.asarray(self.log_pole)) * self.w0):
            out[f"real_pole_{k + 1}_rad_s"] = float(p)
        tf = self.tf()
        out["static_gain"] = float(np.asarray(tf.num)[-1] / np.asarray(tf.den)[-1])
        return out

    @classmethod
    def from_rational(cls, tf: RationalTF, w0: float, dt: float) -> StableTMF:
        """From a stable `RationalTF` of equal orders (concrete, outside `jit`); poles on
        or right of the imaginary axis are reflected into the left half-plane."""
        num = np.asarray(tf.num, float)
        den = np.asarray(tf.den, float)
        n = den.size - 1
        num = np.concatenate([np.zeros(n + 1 - num.size), num])
        poles = np.roots(den)
        poles = np.where(poles.real >= 0, -np.abs(poles.real) - 1e-3 * w0 + 1j * poles.imag, poles)
        omegas, zetas, reals = pole_sections(poles / w0)
        powers = w0 ** np.arange(0, n + 1, dtype=float)
        num_s = num / den[0] / powers
        return cls(
            jnp.asarray(num_s),
            jnp.log(jnp.asarray(omegas, float)),
            jnp.log(jnp.asarray(zetas, float)),
            jnp.log(jnp.asarray(reals, float)),
            float(w0),
            float(dt),
        )
