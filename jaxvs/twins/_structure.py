"""Machine-structure twin: encoder-to-TCP dynamics of a milling machine in one direction.

A lumped chain in the X direction (cf. the TMF study, /work/shared/seeds/002, Fig. 1 and
Fig. 6): the drive (motor and screw inertia, held by the position loop, which acts as a
servo stiffness to ground), the slide with the ball-screw nut and the linear encoder,
the column, and the spindle head carrying the tool-centre point (TCP). The head sits on
the Y carriage of the column, so the head-to-column stiffness falls as the head moves
up: the encoder-to-TCP transmissibility depends on the Y position, as the study's
X-axis TMFs do.

```
ground ─k_servo─ drive ─k_screw─ slide/encoder ─k_joint─ column ─k_head(y)─ head/TCP
```
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray
from scipy.signal import butter

from ..data import prbs
from ..models import OscillatorChain, RationalTF, simulate

DRIVE, ENCODER, COLUMN, TCP = 0, 1, 2, 3


class StructureData(NamedTuple):
    """One excitation experiment per Y position, sampled at the encoder rate.

    - `t`: `(time,)` [s]; `y`: `(position,)` Y positions [m].
    - `force`: `(position, time)` drive force [N] (the excitation).
    - `x_encoder`, `x_tcp`: `(position, time)` measured positions [m] (encoder with its
      resolution, TCP from a reference sensor used only for identification).
    - `a_encoder`, `a_tcp`: `(position, time)` accelerometer signals [m/s²] with noise.
    - `x_tcp_true`: `(position, time)` noiseless TCP position [m] (the truth).
    """

    t: np.ndarray
    y: np.ndarray
    force: np.ndarray
    x_encoder: np.ndarray
    x_tcp: np.ndarray
    a_encoder: np.ndarray
    a_tcp: np.ndarray
    x_tcp_true: np.ndarray


class MachineStructureTwin(eqx.Module):
    """Lumped X-direction structure whose encoder-to-TCP TMF depends on the Y position.

    **Arguments** (all optional; defaults give modes near 26 Hz (servo), 120-185 Hz
    (head on column, falling with Y), 230 Hz and 340 Hz):

    - `masses`: `(4,)` drive, slide, column, head masses [kg].
    - `k_servo`, `k_screw`, `k_joint`: servo, ball-screw/nut and slide-column
      stiffnesses [N/m].
    - `k_head`: head-to-column stiffness at `y = 0` [N/m]; it falls linearly to
      `k_head * (1 - head_softening)` at `y = y_max`.
    - `loss_factor`: stiffness-proportional damping `c = loss_factor * k` [s].
    - `y_max`: travel of the Y axis [m].
    """

    masses: Float[Array, "4"]
    k_servo: Float[Array, ""]
    k_screw: Float[Array, ""]
    k_joint: Float[Array, ""]
    k_head: Float[Array, ""]
    head_softening: Float[Array, ""]
    loss_factor: Float[Array, ""]
    y_max: float = eqx.field(static=True)

    def __init__(
        self,
        masses: ArrayLike = (60.0, 180.0, 450.0, 90.0),
        k_servo: float = 2.4e7,
        k_screw: float = 1.5e8,
        k_joint: float = 3.6e8,
        k_head: float = 1.2e8,
        head_softening: float = 0.6,
        loss_factor: float = 2.0e-4,
        y_max: float = 0.6,
    ):
        f = jnp.result_type(float)
        self.masses = jnp.asarray(masses, f)
        self.k_servo, self.k_screw, self.k_joint, self.k_head = (
            jnp.asarray(v, f) for v in (k_servo, k_screw, k_joint, k_head)
        )
        self.head_softening = jnp.asarray(head_softening, f)
        self.loss_factor = jnp.asarray(loss_factor, f)
        self.y_max = float(y_max)

    def chain(self, y: ArrayLike) -> OscillatorChain:
        """The structure at Y positions `y` [m], shape `(position,)`: a chain family."""
        y = jnp.atleast_1d(jnp.asarray(y, self.masses.dtype))
        k_head = self.k_head * (1.0 - self.head_softening * y / self.y_max)
        n = y.shape[0]
        k = jnp.stack(
            [
                jnp.broadcast_to(self.k_servo, (n,)),
                jnp.broadcast_to(self.k_screw, (n,)),
                jnp.broadcast_to(self.k_joint, (n,)),
                k_head,
            ],
            axis=-1,
        )
        m = jnp.broadcast_to(self.masses, (n, 4))
        return OscillatorChain(m, k, self.loss_factor * k, grounded="left")

    def true_tmf(self, y: ArrayLike, omega: ArrayLike) -> Array:
        """True encoder-to-TCP TMF `T_TE^D(jω)` for drive-side excitation, `(position, freq)`."""
        return self.chain(y).tmf(omega, TCP, ENCODER, DRIVE)

    def prbs_experiment(
        self,
        y: ArrayLike,
        key: PRNGKeyArray,
        *,
        dt: float = 1e-3,
        prbs_order: int = 12,
        n_periods: int = 4,
        force_amplitude: float = 400.0,
        encoder_resolution: float = 1e-8,
        accel_noise: float = 0.01,
        tcp_noise: float = 2e-8,
        oversample: int = 16,
    ) -> StructureData:
        """Drive-force PRBS excitation at every Y position, simulated in one batched call.

        **Arguments:**

        - `y`: `(position,)` Y positions [m]; `key`: PRNG key for the sensor noise.
        - `dt`: encoder/servo sample time [s]; the PRBS is held for one sample.
        - `prbs_order`, `n_periods`: maximum-length sequence of period `2^order - 1`.
        - `force_amplitude`: PRBS amplitude of the drive force [N].
        - `encoder_resolution`: quantisation step of the linear encoder [m].
        - `accel_noise`: accelerometer noise, relative to the signal RMS [-].
        - `tcp_noise`: white noise of the reference TCP position sensor [m].
        - `oversample`: internal simulation steps per sample (continuous plant).
        """
        y = np.atleast_1d(np.asarray(y, float))
        force = force_amplitude * np.asarray(prbs(prbs_order, n_periods=n_periods), float)
        n_t = force.shape[0]
        # The plant is continuous: simulate at `oversample` x the sample rate with the
        # drive force held over each servo cycle, then sample. The accelerometer chain
        # has an analogue anti-alias filter (4th-order Butterworth at 0.4 fs, identical on
        # both channels, so it cancels in the TMF); the encoder samples position directly.
        h = dt / oversample
        u = np.repeat(force, oversample)
        fam = self.chain(jnp.asarray(y))
        ub = jnp.broadcast_to(jnp.asarray(u), (y.shape[0], u.shape[0]))
        pos = simulate(fam.state_space(DRIVE, (ENCODER, TCP)), ub, h)[..., ::oversample, :]
        acc_fine = simulate(fam.state_space(DRIVE, (ENCODER, TCP), quantity="acceleration"), ub, h)
        b, a = butter(4, 2 * np.pi * 0.4 / dt, analog=True)
        aa = RationalTF(jnp.asarray(b), jnp.asarray(a))
        acc = simulate(aa, jnp.moveaxis(acc_fine, -1, -2), h)[..., ::oversample]
        acc = jnp.moveaxis(acc, -2, -1)
        k1, k2 = jr.split(key)
        x_e = jnp.round(pos[..., 0] / encoder_resolution) * encoder_resolution
        x_t = pos[..., 1] + tcp_noise * jr.normal(k1, pos[..., 1].shape, pos.dtype)
        rms = jnp.sqrt(jnp.mean(acc**2, axis=-2, keepdims=True))
        acc = acc + accel_noise * rms * jr.normal(k2, acc.shape, acc.dtype)
        t = np.arange(n_t) * dt
        as_np = lambda a: np.asarray(jax.device_get(a))
        return StructureData(
            t=t,
            y=y,
            force=np.broadcast_to(force, (y.shape[0], n_t)).copy(),
            x_encoder=as_np(x_e),
            x_tcp=as_np(x_t),
            a_encoder=as_np(acc[..., 0]),
            a_tcp=as_np(acc[..., 1]),
            x_tcp_true=as_np(pos[..., 1]),
        )
