"""Rational transfer functions `G(s) = num(s) / den(s)`, including TMFs (equal orders)."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float

from ..._misc import as_real
from .._base import AbstractLinearModel, check_batch
from .._realisation import ModalRealisation, from_poles


def _frequency_scale(den: Float[Array, " n1"]) -> Array:
    """Geometric mean of the pole magnitudes, `|a_n / a_0|^(1/n)` (heuristic scaling).

    Evaluating polynomials in `s / ω0` instead of `s` keeps the coefficients of
    lightly damped high-frequency systems within a few decades of each other.
    """
    n = den.shape[-1] - 1
    a0, an = jnp.abs(den[0]), jnp.abs(den[-1])
    ok = (an > 0) & (a0 > 0)
    return jnp.where(ok, (jnp.where(ok, an, 1.0) / jnp.where(ok, a0, 1.0)) ** (1.0 / n), 1.0)


class RationalTF(AbstractLinearModel):
    """Continuous-time SISO rational transfer function.

    `G(s) = (b_0 s^m + ... + b_m) / (a_0 s^n + ... + a_n)`, coefficients highest power
    first as in `scipy.signal` (docs/guides/contracts.md). Proper: `m <= n`. A transmissibility
    function (TMF, study eq. 8) has `m == n`.

    **Arguments:**

    - `num`: `(*batch, m + 1)` numerator coefficients.
    - `den`: `(*batch, n + 1)` denominator coefficients, `a_0 != 0`.

    Leading `batch` axes make a family of transfer functions of the same orders.
    """

    num: Float[Array, "*batch m1"]
    den: Float[Array, "*batch n1"]

    def __init__(self, num: ArrayLike, den: ArrayLike):
        num, den = as_real(num, "num"), as_real(den, "den")
        if num.ndim < 1 or den.ndim < 1:
            raise ValueError(
                "RationalTF: num and den are coefficient vectors (highest power first); "
                f"got shapes {num.shape} and {den.shape}."
            )
        if num.shape[-1] == 0:
            raise ValueError(
                "RationalTF: num is empty; give at least one coefficient (e.g. [1.0]; [0.0] "
                "for a zero response)."
            )
        if den.shape[-1] < 2:
            raise ValueError(
                "RationalTF: the denominator must have order >= 1 (at least two "
                f"coefficients); got {den.shape[-1]}. A pure gain has no dynamics: "
                "multiply the signal by it instead."
            )
        if num.shape[-1] > den.shape[-1]:
            raise ValueError(
                f"RationalTF: improper transfer function (numerator order "
                f"{num.shape[-1] - 1} > denominator order {den.shape[-1] - 1}); jaxvs "
                "models are proper. Add poles (e.g. a low-pass roll-off) or lower the "
                "numerator order."
            )
        check_batch([num.shape[:-1], den.shape[:-1]], "RationalTF")
        dtype = jnp.result_type(num, den)
        den = eqx.error_if(
            den,
            den[..., 0] == 0,
            "RationalTF: the leading denominator coefficient is zero; strip leading zeros "
            "so that den[0] != 0.",
        )
        self.num, self.den = num.astype(dtype), den.astype(dtype)

    @property
    def n_inputs(self) -> int:
        return 1

    @property
    def n_outputs(self) -> int:
        return 1

    @property
    def order(self) -> int:
        return self.den.shape[-1] - 1

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.den.shape[:-1]

    def _num_padded(self) -> Array:
        pad = self.den.shape[-1] - self.num.shape[-1]
        return jnp.concatenate([jnp.zeros(pad, self.num.dtype), self.num])

    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq 1 1"]:
        w0 = _frequency_scale(self.den)
        n = self.order
        powers = w0 ** jnp.arange(n, -1, -1, dtype=w0.dtype)
        x = s / w0
        g = jnp.polyval(self._num_padded() * powers, x) / jnp.polyval(self.den * powers, x)
        return g[:, None, None]

    def poles(self) -> Complex[Array, " n"]:
        """Roots of the denominator [rad/s], computed in scaled frequency."""
        w0 = _frequency_scale(self.den)
        n = self.order
        scaled = self.den * w0 ** jnp.arange(n, -1, -1, dtype=w0.dtype)
        return jnp.roots(scaled / scaled[0], strip_zeros=False) * w0

    def modal_realisation(self) -> ModalRealisation:
        w0 = _frequency_scale(self.den)
        n = self.order
        powers = w0 ** jnp.arange(n, -1, -1, dtype=w0.dtype)
        den = self.den * powers
        num = self._num_padded() * powers
        direct = num[0] / den[0]
        rem = (num - direct * den)[1:]  # strictly proper remainder, order n - 1
        p = jnp.roots(den / den[0], strip_zeros=False)  # poles in s / w0
        dden = jnp.polyder(den)
        p_c = p
        # Residues of the scaled function; r_i = w0 * r~_i in the original frequency.
        r = jnp.polyval(rem, p_c) / jnp.polyval(dden, p_c) * w0
        return from_poles(
            p_c * w0,
            r[None, :],
            jnp.ones((n, 1), p_c.dtype),
            jnp.reshape(direct, (1, 1)),
        )
