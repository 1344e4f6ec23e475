"""Linear regression on bias-free inputs, the thermal study's first virtual sensor.

Dementjev et al. (2014), eq. (2)-(3): `T_bearing = c + a · T_chassis* + b · v_m*` with the
bias-free inputs `x* = x - bias`, where the bias of each input is the minimum of its
measured series (19.8 °C and 496 rpm in the study). The intercept `c` is then the target
at the lowest operating point.
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._base import AbstractModel

__all__ = ["BiasFreeRegression"]


class BiasFreeRegression(AbstractModel):
    """`y = intercept + Σ_i coef_i (u_i - bias_i)` (study eq. 2-3).

    **Arguments:**

    - `coef`: `(input,)` coefficients [target unit per input unit].
    - `intercept`: target value at `u = bias` [target unit].
    - `bias`: `(input,)` input biases (the minimum of each training series) [input units].
    """

    coef: Float[Array, " input"]
    intercept: Float[Array, ""]
    bias: Float[Array, " input"]

    def __init__(self, coef: ArrayLike, intercept: ArrayLike, bias: ArrayLike):
        f = jnp.result_type(float)
        self.coef = jnp.atleast_1d(jnp.asarray(coef, f))
        self.intercept = jnp.asarray(intercept, f)
        self.bias = jnp.broadcast_to(jnp.asarray(bias, f), self.coef.shape)

    @property
    def n_inputs(self) -> int:
        return self.coef.shape[0]

    @property
    def max_delay(self) -> int:
        return 0

    def __call__(self, u: Float[ArrayLike, "time input"]) -> Float[Array, " time"]:
        """Prediction `(time,)` for inputs `u` of shape `(time, input)`."""
        u = jnp.asarray(u)
        if u.ndim == 1 and self.n_inputs == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[1] != self.n_inputs:
            raise ValueError(
                f"BiasFreeRegression: inputs must have shape (time, {self.n_inputs}); got "
                f"{u.shape}."
            )
        return self.intercept + (u - self.bias) @ self.coef

    def predict(self, u: Float[ArrayLike, " time input"], dt: float) -> Float[Array, " time"]:
        """The output for the input samples `u` (a static map of the delayed inputs; `dt`
        only names the sampling)."""
        return self(u)
