"""First-order lag of a sampled signal: the heat capacity between a driving temperature
and the one measured behind it.

`τ ẏ + y = u`, the transfer function `1 / (τ s + 1)`, discretised exactly for an input
linear between its samples (first-order hold; Franklin, Powell & Workman, *Digital
Control of Dynamic Systems*, §6.3.2). Unlike [`DrivenFirstOrder`][] (an ODE integrated by
diffrax with a gain and a reference), the lag is one scan of a closed-form recursion, and
`τ = 0` is exactly the identity, so it composes with a static model as an effect that
vanishes at zero size.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._misc import check_physical
from .._base import AbstractModel

__all__ = ["FirstOrderLag"]


def _as_float(x) -> Array:
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.inexact):
        x = x.astype(jnp.result_type(float))
    return x


class FirstOrderLag(AbstractModel):
    """First-order lag `τ ẏ + y = u` of a sampled input, first-order hold.

    Exact discretisation for `u` linear between samples:
    `y_k = a y_{k−1} + (1 − a) u_{k−1} + (1 − b)(u_k − u_{k−1})`, `a = e^{−dt/τ}`,
    `b = (τ/dt)(1 − a)` (the ramp response of a first-order system). The state one sample
    before the first is `y_init`, with the input constant over that sample, so
    `y₀ = a·y_init + (1 − a)·u₀`. For `τ = 0` the output is the input exactly; as `τ → 0`
    it tends to it continuously (`y_k ≈ u_k − (τ/dt)(u_k − u_{k−1})`).

    **Arguments:**

    - `tau`: time constant [s], >= 0 (0: no lag).
    - `y_init`: the output one sample before the first [unit of `u`]; `None` (default)
      starts in equilibrium with the first input sample (`y_init = u₀`).
    """

    tau: Float[Array, ""]
    y_init: Float[Array, ""] | None

    def __init__(self, tau: ArrayLike, y_init: ArrayLike | None = None):
        check_physical(tau, "FirstOrderLag: tau", strict=False, unit="s")
        self.tau = _as_float(tau)
        self.y_init = None if y_init is None else _as_float(y_init)

    def predict(self, u: Float[ArrayLike, " time"], dt: float) -> Float[Array, " time"]:
        """The lagged signal.

        **Arguments:**

        - `u`: `(time,)` (or `(time, 1)`) input samples [any unit].
        - `dt`: sample time [s].

        **Returns:**

        `(time,)` output samples, in the unit of `u`.
        """
        s = jnp.asarray(u)
        if s.ndim == 2 and s.shape[1] == 1:
            s = s[:, 0]
        if s.ndim != 1 or s.shape[0] < 1:
            raise ValueError(
                "FirstOrderLag.predict: u must be one signal of shape (time,) or (time, 1); "
                f"got {s.shape}. Lag several signals with jax.vmap over their columns."
            )
        tau = self.tau
        pos = tau > 0
        tau_safe = jnp.where(pos, tau, 1.0)
        r = dt / tau_safe
        a = jnp.where(pos, jnp.exp(-r), 0.0)
        b = jnp.where(pos, -jnp.expm1(-r) / r, 0.0)
        ds = jnp.diff(s, prepend=s[:1])

        def step(y_prev, x):
            sk, dsk = x
            y = a * y_prev + (1.0 - a) * (sk - dsk) + (1.0 - b) * dsk
            return y, y

        y0 = s[0] if self.y_init is None else self.y_init
        _, y = jax.lax.scan(step, y0, (s, ds))
        return jnp.where(pos, y, s)
