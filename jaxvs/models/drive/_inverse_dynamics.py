"""Inverse dynamics of a rigid axis: the drive force predicted from the measured motion.

The IDIM model of drive identification (Gautier & Khalil; the EMPS benchmark, Janot et al.
2019, eq. (1) and (3) without Coulomb friction): a rigid axis of mass `M` with viscous
friction `Fv` and a constant force offset,

    u = M q̈ + Fv q̇ + offset,

is linear in its parameters, so it is identified by least squares on the filtered
velocity and acceleration. The forward model of the same axis is
[`RigidAxis`][] with [`ViscousFriction`][].
"""

from typing import Any

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import check_physical
from .._base import AbstractModel
from ._friction import ViscousFriction

__all__ = ["RigidInverseDynamics"]


def _as_float(x: Any) -> Array:
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.inexact):
        x = x.astype(jnp.result_type(float))
    return x


class RigidInverseDynamics(AbstractModel):
    """Force of a rigid axis from its motion, `u = M q̈ + Fv q̇ + offset` [N].

    **Arguments:**

    - `M`: moving mass reflected to the axis [kg], >= 0 (0: a quasi-static rig that does
      not excite its inertia).
    - `Fv`: viscous friction coefficient [N·s/m], >= 0.
    - `offset`: constant force offset [N] (gravity on an inclined axis, a bias of the
      force measurement).
    """

    M: Float[Array, ""]
    Fv: Float[Array, ""]
    offset: Float[Array, ""]

    def __init__(self, M: ArrayLike, Fv: ArrayLike, offset: ArrayLike = 0.0):
        check_physical(M, "RigidInverseDynamics: M", strict=False, unit="kg")
        check_physical(Fv, "RigidInverseDynamics: Fv", strict=False, unit="N·s/m")
        self.M, self.Fv, self.offset = _as_float(M), _as_float(Fv), _as_float(offset)

    def force(
        self, velocity: Float[ArrayLike, " time"], acceleration: Float[ArrayLike, " time"]
    ) -> Float[Array, " time"]:
        """The force `M q̈ + Fv q̇ + offset` [N] for the velocity `q̇` [m/s] and the
        acceleration `q̈` [m/s²] (any matching shapes)."""
        # the viscous term is the library's friction law (the forward model's)
        return self.M * acceleration + ViscousFriction(self.Fv)(velocity) + self.offset

    def predict(self, u: Float[ArrayLike, "time 2"], dt: float) -> Float[Array, " time"]:
        """The force [N] for the measured motion.

        **Arguments:**

        - `u`: `(time, 2)` samples of the velocity `q̇` [m/s] (column 0) and the
          acceleration `q̈` [m/s²] (column 1), e.g. from `jaxvs.signal.DriveBand`.
        - `dt`: sample time [s]; the model is static, so it only names the sampling.

        **Returns:**

        `(time,)` force [N].
        """
        u = jnp.asarray(u)
        if u.ndim != 2 or u.shape[1] != 2:
            raise ValueError(
                "RigidInverseDynamics.predict: u must have shape (time, 2), the velocity "
                f"[m/s] and the acceleration [m/s²] as columns; got {u.shape}. Stack them "
                "with jnp.stack([v, a], axis=1)."
            )
        return self.force(u[:, 0], u[:, 1])

    def parameters(self) -> dict[str, float]:
        """`M` [kg], `Fv` [N·s/m] and `offset` [N] as Python floats."""
        return {
            name: float(np.asarray(getattr(self, name)).reshape(-1)[0])
            for name in ("M", "Fv", "offset")
        }
