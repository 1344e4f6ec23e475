"""The volumetric error of a machine before and after compensation with a calibrated model."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

from ...models import CartesianMachine

__all__ = ["compensated_error"]


@eqx.filter_jit
def compensated_error(
    truth: CartesianMachine, estimate: CartesianMachine, q: ArrayLike
) -> tuple[Array, Array]:
    r"""Volumetric error `(…, 3)` [m] at commanded positions `q` `(…, 3)` [m] without and
    with compensation by `estimate`.

    Compensation commands `q' = q − E_est(q)` so that the tool reaches the nominal point
    `q + t`; what remains is `P_true(q') − (q + t) = E_true(q') − E_est(q)` (to second
    order in the errors: the residual map of the compensated machine).

    **Returns:** `(before, after)`.
    """
    q = jnp.asarray(q)
    t = truth.tool_offset
    before = truth.tool_point(q) - q - t
    q_comp = q - (estimate.tool_point(q) - q - estimate.tool_offset)
    after = truth.tool_point(q_comp) - q - t
    return before, after
