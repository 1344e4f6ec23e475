r"""The TMF virtual sensor: tool-centre-point motion from the linear encoder (study 002).

Doerrer et al. (2022), eq. 5:

    x_T(s) = T_TE^D(s) · [x_E(s) − H_ET(s) F_T(s)] + H_TT(s) F_T(s),

with the drive-side transmissibility `T_TE^D` from the encoder to the TCP and, when a
process force `F_T` at the TCP is known, the receptances `H_ET` (encoder motion per TCP
force) and `H_TT` (TCP motion per TCP force). Without a force it reduces to eq. 7,
`x_T = T_TE^D x_E`, which the study integrates in real time with Euler or Heun steps at
the encoder rate.
"""

from typing import Literal

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._base import AbstractLinearModel, AbstractModel
from .._discretise import METHODS
from .._simulate import simulate

_WHO = "VirtualSensor"


def _upsample(x: Array, n: int) -> Array:
    """Linear interpolation of `(*batch, time)` samples onto `n` sub-steps per sample."""
    if n == 1:
        return x
    frac = jnp.arange(n, dtype=x.dtype) / n
    nxt = jnp.concatenate([x[..., 1:], x[..., -1:]], axis=-1)
    fine = x[..., :, None] * (1 - frac) + nxt[..., :, None] * frac
    return fine.reshape(*x.shape[:-1], x.shape[-1] * n)


class VirtualSensor(AbstractModel):
    r"""TCP position from the encoder position (and optionally the TCP force), eq. 5 / eq. 7.

    **Arguments:**

    - `tmf`: the transmissibility `T_TE^D` (any jaxvs linear model, e.g. a `RationalTF`
      of equal orders, or a family with a leading position axis).
    - `h_et`, `h_tt`: optional receptances [m/N] from the TCP force to the encoder and to
      the TCP (eq. 5); give both or neither.
    - `method`: time stepping at the encoder rate: `"euler"` or `"heun"` (the study's
      real-time integrators), `"zoh"` (exact for inputs held over each sample) or
      `"tustin"`. Match it to how the TMF was identified: a continuous TMF fitted in the
      frequency domain (accelerometer or impact routes) wants `"tustin"` or sub-stepped
      `"heun"`, since the encoder signal is not held between samples (`"zoh"` then adds
      half a sample of delay, which at a 1 kHz encoder rate can cost more than the
      deflection it estimates); a TMF calibrated by simulation error with `"zoh"` (the
      time-domain route) wants `"zoh"`, which reproduces its calibration exactly.
    - `substeps`: integration steps per encoder sample (static, >= 1); the encoder
      signal is linearly interpolated between samples. Explicit Euler/Heun need
      `dt/substeps · |λ|` small for every pole `λ` (e.g. `substeps >= 8` for 200 Hz
      modes at 1 kHz).
    """

    tmf: AbstractLinearModel
    h_et: AbstractLinearModel | None
    h_tt: AbstractLinearModel | None
    method: str = eqx.field(static=True)
    substeps: int = eqx.field(static=True)

    def __init__(
        self,
        tmf: AbstractLinearModel,
        h_et: AbstractLinearModel | None = None,
        h_tt: AbstractLinearModel | None = None,
        *,
        method: Literal["zoh", "tustin", "euler", "heun"] = "heun",
        substeps: int = 1,
    ):
        for name, m in (("tmf", tmf), ("h_et", h_et), ("h_tt", h_tt)):
            if m is not None and not isinstance(m, AbstractLinearModel):
                raise TypeError(
                    f"{_WHO}: {name} must be a jaxvs linear model (RationalTF, ModalModel, "
                    f"StateSpace, ...); got {type(m).__name__}."
                )
            if m is not None and (m.n_inputs != 1 or m.n_outputs != 1):
                raise ValueError(f"{_WHO}: {name} must be single-input single-output.")
        if (h_et is None) != (h_tt is None):
            raise ValueError(
                f"{_WHO}: the process-force term of eq. 5 needs both receptances h_et "
                "(encoder per TCP force) and h_tt (TCP per TCP force); give both or neither."
            )
        if method not in METHODS:
            raise ValueError(f"{_WHO}: method={method!r}; choose one of {METHODS}.")
        if not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"{_WHO}: substeps must be a positive int; got {substeps!r}.")
        self.tmf, self.h_et, self.h_tt = tmf, h_et, h_tt
        self.method, self.substeps = method, substeps

    @property
    def uses_force(self) -> bool:
        """Whether the process-force terms of eq. 5 are part of the sensor."""
        return self.h_et is not None

    def _sim(self, model: AbstractLinearModel, u: Array, dt: Array) -> Array:
        n = self.substeps
        y = simulate(model, _upsample(u, n), dt / n, method=self.method)  # type: ignore[arg-type]
        return y[..., ::n] if n > 1 else y

    def __call__(
        self,
        x_e: Float[ArrayLike, "*batch time"],
        dt: float,
        force: Float[ArrayLike, "*batch time"] | None = None,
    ) -> Float[Array, "*batch time"]:
        """Estimated TCP position [m] at the encoder samples.

        **Arguments:**

        - `x_e`: `(*batch, time)` encoder position [m] sampled every `dt`, from rest.
        - `dt`: encoder sample time [s].
        - `force`: `(*batch, time)` process force at the TCP [N]; required when the sensor
          has the eq. 5 receptances, refused otherwise.

        **Returns:**

        `(*batch, time)` TCP position [m].
        """
        x_e = jnp.asarray(x_e)
        if x_e.ndim < 1:
            raise ValueError(f"{_WHO}: x_e must be (*batch, time); got a scalar.")
        dt_arr = jnp.asarray(dt)
        if self.uses_force:
            if force is None:
                raise ValueError(
                    f"{_WHO}: this sensor has the process-force terms of eq. 5; pass the "
                    "measured TCP force as force=... (or build it without h_et/h_tt)."
                )
            force = jnp.asarray(force, x_e.dtype)
            if force.shape[-1] != x_e.shape[-1]:
                raise ValueError(
                    f"{_WHO}: force has {force.shape[-1]} samples but x_e has "
                    f"{x_e.shape[-1]}; resample them onto one time base first."
                )
            x_drive = x_e - self._sim(self.h_et, force, dt_arr)  # eq. 5, square bracket
            return self._sim(self.tmf, x_drive, dt_arr) + self._sim(self.h_tt, force, dt_arr)
        if force is not None:
            raise ValueError(
                f"{_WHO}: a force was given but the sensor has no receptances h_et, h_tt "
                "(eq. 7 form); build VirtualSensor(tmf, h_et, h_tt) to use it."
            )
        return self._sim(self.tmf, x_e, dt_arr)

    def predict(self, u: Float[ArrayLike, " time *input"], dt: float) -> Float[Array, " time"]:
        """TCP position [m] from `u`: the encoder position `(time,)`, or `(time, 2)` with
        the encoder position and the process force [N] for an eq. 5 sensor."""
        u = jnp.asarray(u)
        if u.ndim == 2 and u.shape[1] == 2:
            return self(u[:, 0], dt, u[:, 1])
        return self(u, dt)
