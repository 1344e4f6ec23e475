"""`frequency_response`: the complex response of any linear model, one call for a family."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex

from ..._misc import real_array
from .._base import AbstractLinearModel, check_model, map_batch


def as_omega(omega: ArrayLike, where: str) -> Array:
    """`omega` as a real floating 1-D grid `(freq,)` of angular frequencies [rad/s]; a
    `TypeError` (complex) or `ValueError` (shape) names `where`."""
    omega = real_array(
        omega, f"{where}: omega is the real angular frequency [rad/s]; got a complex array."
    )
    if omega.ndim != 1:
        raise ValueError(
            f"{where}: omega must be 1-D (freq,); got shape {omega.shape}. Flatten it, or "
            "vmap over extra axes."
        )
    return omega


def frequency_response(
    model: AbstractLinearModel, omega: ArrayLike
) -> Complex[Array, "*batch freq"] | Complex[Array, "*batch freq out in"]:
    """Complex frequency response `G(jω)` of a linear model or a family of models.

    **Arguments:**

    - `model`: any jaxvs linear model (`RationalTF`, `ModalModel`, `StateSpace`, ...);
      leading batch axes of its parameters make a family.
    - `omega`: `(freq,)` angular frequencies [rad/s], real and finite.

    **Returns:**

    `(*batch, freq)` for a SISO model (as `scipy.signal.freqs`), otherwise
    `(*batch, freq, out, in)`.
    """
    check_model(model, "frequency_response")
    omega = as_omega(omega, "frequency_response")
    if not isinstance(omega, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(omega))):
        raise ValueError("frequency_response: omega contains NaN or inf.")
    return _response(model, omega)


@eqx.filter_jit
def _response(model: AbstractLinearModel, omega: Array) -> Array:
    s = jax.lax.complex(jnp.zeros_like(omega), omega)
    g = map_batch(lambda m: m.response(s), model)
    if model.is_siso:
        return g[..., 0, 0]
    return g
