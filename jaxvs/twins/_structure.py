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
                                                            (missing_mode: ─k_tool─ tool/TCP)
```

The twin has switchable hidden effects (`TMF_TWIN_EFFECTS`) for blind tests of the
sim-to-real diagnosis; each is exactly off at zero, where the encoder-to-TCP motion is
one position-independent rational TMF of order (2, 4) (padded: 4/4).
"""

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray
from scipy.signal import butter

from .._misc import options_object
from ..data import Record, prbs
from ..models import OscillatorChain, RationalTF, StateSpace, simulate

DRIVE, ENCODER, COLUMN, TCP = 0, 1, 2, 3

#: Names of the hidden effects of [`MachineStructureTwin`][] (docs/guides/contracts.md,
#: family `tmf`).
TMF_TWIN_EFFECTS: tuple[str, ...] = (
    "position_dependence",
    "missing_mode",
    "sensor_delay",
    "process_force",
)

# Defaults of the effect parameters when an effect is given by its main magnitude only.
_MISSING_MODE_DEFAULTS = {"frequency_hz": 220.0, "mass_ratio": 0.1, "damping": 0.03}
_PROCESS_FORCE_DEFAULTS = {"amplitude": 200.0, "tooth_pass_hz": 80.0}


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


class ImpactData(NamedTuple):
    """Repeated hammer hits at one location, at every Y position (accelerometer data).

    - `t`: `(time,)` [s] time of one hit record; `y`: `(position,)` [m].
    - `location`: `"encoder"` or `"tcp"`, where the hammer hits.
    - `force`: `(position, hit, time)` measured hammer force [N] with noise.
    - `a_encoder`, `a_tcp`: `(position, hit, time)` accelerometer signals [m/s²]
      (high-passed, noisy).
    """

    t: np.ndarray
    y: np.ndarray
    location: str
    force: np.ndarray
    a_encoder: np.ndarray
    a_tcp: np.ndarray


def _series(first: tuple, second: tuple) -> tuple:
    """State space `(A, B, C, D)` of `second ∘ first` (SISO `second`; `first` may be batched)."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    batch = A1.shape[:-2]
    n1, n2 = A1.shape[-1], A2.shape[0]
    A = np.zeros(batch + (n1 + n2, n1 + n2))
    A[..., :n1, :n1], A[..., n1:, n1:], A[..., n1:, :n1] = A1, A2, B2 @ C1
    B = np.concatenate([B1, B2 @ D1], axis=-2)
    C = np.concatenate([D2 @ C1, np.broadcast_to(C2, batch + C2.shape)], axis=-1)
    return A, B, C, D2 @ D1


def _accelerometer_chain(highpass_hz: float, bandwidth_hz: float | None, fs: float) -> tuple:
    """Well-conditioned state space of the accelerometer channel: first-order high-pass,
    optional second-order Butterworth bandwidth, 8th-order Butterworth anti-alias filter at
    0.4 fs, as a cascade of sections in frequency-scaled states (the expanded polynomial of
    the 10th-order filter has coefficients up to ~1e40)."""
    a = 2 * np.pi * highpass_hz
    chain = (np.array([[-a]]), np.array([[1.0]]), np.array([[-a]]), np.array([[1.0]]))
    poles = list(butter(8, 2 * np.pi * 0.4 * fs, analog=True, output="zpk")[1])
    if bandwidth_hz is not None:
        poles += list(butter(2, 2 * np.pi * bandwidth_hz, analog=True, output="zpk")[1])
    for p in (p for p in poles if p.imag > 0):  # unit-gain section w² / (s² + 2ζw s + w²)
        w, c = abs(p), -2 * p.real
        sec = (
            np.array([[0.0, w], [-w, -c]]),
            np.array([[0.0], [w]]),
            np.eye(1, 2),
            np.zeros((1, 1)),
        )
        chain = _series(chain, sec)
    return chain


def _as_params(name: str, value: Any, defaults: Mapping[str, float], main: str) -> dict:
    """Effect parameters from a number (the main magnitude) or a mapping."""
    if isinstance(value, Mapping):
        unknown = set(value) - set(defaults)
        if unknown:
            raise ValueError(
                f"MachineStructureTwin: unknown parameter(s) {sorted(unknown)} of effect "
                f"{name!r}; valid ones are {sorted(defaults)}."
            )
        return {**defaults, **{k: float(v) for k, v in value.items()}}
    return {**defaults, main: float(value)}


def _parse_effects(effects: Mapping[str, Any]) -> dict[str, float]:
    """Effect mapping → flat twin parameters (every effect off unless given)."""
    if not isinstance(effects, Mapping):
        raise TypeError(
            "MachineStructureTwin: effects must be a mapping effect name -> magnitude, e.g. "
            f"{{'sensor_delay': 2e-3}}; got {type(effects).__name__}."
        )
    unknown = set(effects) - set(TMF_TWIN_EFFECTS)
    if unknown:
        raise ValueError(
            f"MachineStructureTwin: unknown effect(s) {sorted(unknown)}; the twin has "
            f"{TMF_TWIN_EFFECTS}."
        )
    out = {
        "head_softening": 0.0,
        "tool_frequency": 0.0,
        "tool_mass_ratio": 0.0,
        "tool_damping": 0.0,
        "sensor_delay": 0.0,
        "process_force": 0.0,
        "tooth_pass_hz": _PROCESS_FORCE_DEFAULTS["tooth_pass_hz"],
    }
    if effects.get("position_dependence"):
        v = effects["position_dependence"]
        v = v["softening"] if isinstance(v, Mapping) else v
        out["head_softening"] = float(v)
    if effects.get("missing_mode"):
        p = _as_params(
            "missing_mode", effects["missing_mode"], _MISSING_MODE_DEFAULTS, "frequency_hz"
        )
        out["tool_frequency"] = p["frequency_hz"]
        out["tool_mass_ratio"] = p["mass_ratio"]
        out["tool_damping"] = p["damping"]
    if effects.get("sensor_delay"):
        out["sensor_delay"] = float(effects["sensor_delay"])
    if effects.get("process_force"):
        p = _as_params(
            "process_force", effects["process_force"], _PROCESS_FORCE_DEFAULTS, "amplitude"
        )
        out["process_force"] = p["amplitude"]
        out["tooth_pass_hz"] = p["tooth_pass_hz"]
    return out


def draw_tmf_effect(key: PRNGKeyArray, label: str | None) -> dict[str, Any]:
    """A random effect of typical magnitude for blind tests of the `tmf` diagnosis.

    **Arguments:**

    - `key`: PRNG key.
    - `label`: one of [`TMF_TWIN_EFFECTS`][], or `None` / `"none"` for no effect.

    **Returns:**

    An effects mapping for `MachineStructureTwin(effects=...)` /
    [`MachineStructureTwin.with_effects`][]:

    - `position_dependence`: head softening at `y_max` uniform in 0.3-0.6 (the TMF's
      first resonance drops by ~15-35 % over the Y travel);
    - `missing_mode`: a tool/spindle sub-oscillator at the head, uncoupled frequency
      150-280 Hz, tool mass 6-15 % of the head mass, damping ratio 2-5 %;
    - `sensor_delay`: 2-5 ms (not an integer number of samples in general). Shorter delays
      (up to ~1.5 samples at 1 kHz) are absorbed by the spare numerator freedom of the
      4/4 nominal TMF and leave no trace in the residual;
    - `process_force`: milling-like force at the TCP, amplitude 50-500 N, tooth-pass
      frequency 40-150 Hz.
    """
    if label is None or label == "none":
        return {}
    if label not in TMF_TWIN_EFFECTS:
        raise ValueError(
            f"draw_tmf_effect: unknown label {label!r}; use None or one of {TMF_TWIN_EFFECTS}."
        )
    u = np.asarray(jr.uniform(key, (3,)), float)
    lerp = lambda i, lo, hi: float(lo + (hi - lo) * u[i])  # noqa: E731
    if label == "position_dependence":
        return {label: lerp(0, 0.3, 0.6)}
    if label == "missing_mode":
        return {
            label: {
                "frequency_hz": lerp(0, 150.0, 280.0),
                "mass_ratio": lerp(1, 0.06, 0.15),
                "damping": lerp(2, 0.02, 0.05),
            }
        }
    if label == "sensor_delay":
        return {label: lerp(0, 2e-3, 5e-3)}
    return {label: {"amplitude": lerp(0, 50.0, 500.0), "tooth_pass_hz": lerp(1, 40.0, 150.0)}}


@dataclasses.dataclass(frozen=True)
class ImpactSensors:
    """The sensors of [`MachineStructureTwin.impact_experiment`][]: force-sensor noise
    `force_noise` [N], accelerometer noise `accel_noise` [m/s²], high-pass
    `accel_highpass_hz` [Hz] and bandwidth `accel_bandwidth_hz` [Hz] (`None`: unlimited),
    and the simulation steps per sample `oversample`."""

    force_noise: float = 0.5
    accel_noise: float = 0.02
    accel_highpass_hz: float = 2.0
    accel_bandwidth_hz: float | None = None
    oversample: int = 8


@dataclasses.dataclass(frozen=True)
class TMFSensors:
    """The sensors of [`MachineStructureTwin.tmf_experiment`][]: the reference TCP
    sensor's noise `noise` [m], the linear encoder's `encoder_resolution` [m], the force
    sensor's noise `force_noise` [N], and the simulation steps per sample `oversample`."""

    noise: float = 5e-8
    encoder_resolution: float = 1e-7
    force_noise: float = 2.0
    oversample: int = 16


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
    - `effects`: hidden effects for blind tests, a mapping with keys from
      [`TMF_TWIN_EFFECTS`][] (see [`draw_tmf_effect`][] for typical magnitudes). When
      given, it specifies *every* effect: the ones it does not name are off, including
      the position dependence (`head_softening` is then ignored), so
      `MachineStructureTwin(effects={})` is the nominal twin whose encoder-to-TCP motion
      is one position-independent TMF. Values:
        - `"position_dependence"`: head softening at `y_max` [-], in [0, 1);
        - `"missing_mode"`: uncoupled frequency [Hz] of a tool/spindle oscillator on
          the head (the TCP is then the tool tip), or a mapping with `frequency_hz`,
          `mass_ratio` (tool / head mass, default 0.1) and `damping` (ratio, 0.03);
        - `"sensor_delay"`: delay of the recorded `x_t` behind `x_e` [s];
        - `"process_force"`: amplitude of a milling force at the TCP [N], or a mapping
          with `amplitude` and `tooth_pass_hz` (default 80 Hz).
    """

    masses: Float[Array, "4"]
    k_servo: Float[Array, ""]
    k_screw: Float[Array, ""]
    k_joint: Float[Array, ""]
    k_head: Float[Array, ""]
    head_softening: Float[Array, ""]
    loss_factor: Float[Array, ""]
    tool_frequency: Float[Array, ""]
    tool_mass_ratio: Float[Array, ""]
    tool_damping: Float[Array, ""]
    sensor_delay: Float[Array, ""]
    process_force: Float[Array, ""]
    tooth_pass_hz: Float[Array, ""]
    y_max: float = eqx.field(static=True)
    has_tool: bool = eqx.field(static=True)

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
        *,
        effects: Mapping[str, Any] | None = None,
    ):
        f = jnp.result_type(float)
        self.masses = jnp.asarray(masses, f)
        if self.masses.shape != (4,):
            raise ValueError(
                f"MachineStructureTwin: masses must be 4 values (drive, slide, column, head) "
                f"[kg]; got shape {self.masses.shape}."
            )
        self.k_servo, self.k_screw, self.k_joint, self.k_head = (
            jnp.asarray(v, f) for v in (k_servo, k_screw, k_joint, k_head)
        )
        self.loss_factor = jnp.asarray(loss_factor, f)
        self.y_max = float(y_max)
        p = _parse_effects({} if effects is None else effects)
        if effects is None:
            p["head_softening"] = float(head_softening)
        if not 0.0 <= p["head_softening"] < 1.0:
            raise ValueError(
                "MachineStructureTwin: the head softening (position dependence) must lie in "
                f"[0, 1); got {p['head_softening']}."
            )
        if p["tool_frequency"] < 0 or p["sensor_delay"] < 0 or p["process_force"] < 0:
            raise ValueError(
                "MachineStructureTwin: effect magnitudes must be >= 0 (0 switches an effect off)."
            )
        if p["tool_frequency"] > 0 and not (p["tool_mass_ratio"] > 0 and p["tool_damping"] >= 0):
            raise ValueError(
                "MachineStructureTwin: missing_mode needs mass_ratio > 0 and damping >= 0."
            )
        self.head_softening = jnp.asarray(p["head_softening"], f)
        self.tool_frequency = jnp.asarray(p["tool_frequency"], f)
        self.tool_mass_ratio = jnp.asarray(p["tool_mass_ratio"], f)
        self.tool_damping = jnp.asarray(p["tool_damping"], f)
        self.sensor_delay = jnp.asarray(p["sensor_delay"], f)
        self.process_force = jnp.asarray(p["process_force"], f)
        self.tooth_pass_hz = jnp.asarray(p["tooth_pass_hz"], f)
        self.has_tool = p["tool_frequency"] > 0

    # -- effects -----------------------------------------------------------------------

    def _base_kwargs(self) -> dict[str, Any]:
        return dict(
            masses=self.masses,
            k_servo=self.k_servo,
            k_screw=self.k_screw,
            k_joint=self.k_joint,
            k_head=self.k_head,
            loss_factor=self.loss_factor,
            y_max=self.y_max,
        )

    @property
    def effects(self) -> dict[str, Any]:
        """The effects that are on, as a mapping accepted by [`with_effects`][]."""
        out: dict[str, Any] = {}
        if float(self.head_softening) > 0:
            out["position_dependence"] = float(self.head_softening)
        if self.has_tool:
            out["missing_mode"] = {
                "frequency_hz": float(self.tool_frequency),
                "mass_ratio": float(self.tool_mass_ratio),
                "damping": float(self.tool_damping),
            }
        if float(self.sensor_delay) > 0:
            out["sensor_delay"] = float(self.sensor_delay)
        if float(self.process_force) > 0:
            out["process_force"] = {
                "amplitude": float(self.process_force),
                "tooth_pass_hz": float(self.tooth_pass_hz),
            }
        return out

    def with_effects(self, effects: Mapping[str, Any]) -> "MachineStructureTwin":
        """The same structure with exactly the given hidden `effects` (others off)."""
        return MachineStructureTwin(**self._base_kwargs(), effects=effects)

    def perturb(self, key: PRNGKeyArray, scale: float = 0.1) -> "MachineStructureTwin":
        """A randomly varied machine of the same kind (same effects).

        Every mass, stiffness and the loss factor is multiplied by `exp(scale · ε)`,
        `ε ~ N(0, 1)` independent, so `scale = 0.1` varies them by about ±10 %.
        """
        eps = np.asarray(jr.normal(key, (9,)), float)
        g = np.exp(float(scale) * eps)
        kw = self._base_kwargs()
        kw["masses"] = np.asarray(self.masses) * g[:4]
        for i, name in enumerate(("k_servo", "k_screw", "k_joint", "k_head", "loss_factor")):
            kw[name] = float(kw[name]) * g[4 + i]
        return MachineStructureTwin(**kw, effects=self.effects)

    # -- structure ---------------------------------------------------------------------

    @property
    def tcp(self) -> int:
        """Mass index of the TCP: the head (3), or the tool tip (4) with `missing_mode`."""
        return 4 if self.has_tool else TCP

    def chain(self, y: ArrayLike) -> OscillatorChain:
        """The structure at Y positions `y` [m], shape `(position,)`: a chain family."""
        y = jnp.atleast_1d(jnp.asarray(y, self.masses.dtype))
        k_head = self.k_head * (1.0 - self.head_softening * y / self.y_max)
        n = y.shape[0]
        cols = [
            jnp.broadcast_to(self.k_servo, (n,)),
            jnp.broadcast_to(self.k_screw, (n,)),
            jnp.broadcast_to(self.k_joint, (n,)),
            k_head,
        ]
        k = jnp.stack(cols, axis=-1)
        c = self.loss_factor * k
        m = jnp.broadcast_to(self.masses, (n, 4))
        if self.has_tool:
            m_tool = self.tool_mass_ratio * self.masses[3]
            w_tool = 2 * jnp.pi * self.tool_frequency
            k_tool = m_tool * w_tool**2
            c_tool = 2 * self.tool_damping * m_tool * w_tool
            m = jnp.concatenate([m, jnp.broadcast_to(m_tool, (n, 1))], axis=-1)
            k = jnp.concatenate([k, jnp.broadcast_to(k_tool, (n, 1))], axis=-1)
            c = jnp.concatenate([c, jnp.broadcast_to(c_tool, (n, 1))], axis=-1)
        return OscillatorChain(m, k, c, grounded="left")

    def true_tmf(self, y: ArrayLike, omega: ArrayLike) -> Array:
        """True encoder-to-TCP TMF `T_TE^D(jω)` for drive-side excitation, `(position, freq)`."""
        return self.chain(y).tmf(omega, self.tcp, ENCODER, DRIVE)

    def tmf_model(self, y: ArrayLike) -> RationalTF:
        """The exact encoder-to-TCP TMF `T_TE^D(s)` as a `RationalTF` family `(position,)`.

        Order (2, 4) for the nominal structure (numerator padded with leading zeros to
        4/4), (3, 6) with `missing_mode`. Drive-side excitation only: a force at the TCP
        (impact there, or `process_force`) breaks `x_t = T_TE^D x_e`.
        """
        return self.chain(y).transmissibility_model(self.tcp, ENCODER, DRIVE)

    # -- experiments -------------------------------------------------------------------

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
        tcp = self.tcp
        ub = jnp.broadcast_to(jnp.asarray(u), (y.shape[0], u.shape[0]))
        pos = simulate(fam.state_space(DRIVE, (ENCODER, tcp)), ub, h)[..., ::oversample, :]
        acc_fine = simulate(fam.state_space(DRIVE, (ENCODER, tcp), quantity="acceleration"), ub, h)
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
        as_np = lambda a: np.asarray(jax.device_get(a))  # noqa: E731
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

    def impact_experiment(
        self,
        y: ArrayLike,
        key: PRNGKeyArray,
        *,
        location: str = "encoder",
        n_hits: int = 5,
        fs: float = 4096.0,
        record_length: float = 2.0,
        hit_duration: float = 1.5e-3,
        force_peak: float = 2000.0,
        sensors: ImpactSensors | None = None,
        **keywords: Any,
    ) -> ImpactData:
        """Impact-hammer test at the encoder or at the TCP, at every Y position.

        Each hit is a half-sine force pulse of `hit_duration` (hammer tip, ~1-2 ms: flat
        force spectrum to about `1 / hit_duration`) with a random peak (±20 %) in its own
        record of `record_length`, starting from rest. Accelerometers at the encoder and
        the TCP: a first-order high-pass at `accel_highpass_hz` (piezoelectric sensors
        are unreliable at low frequency), optionally a second-order Butterworth low-pass
        at `accel_bandwidth_hz` (the sensor bandwidth, ~800 Hz; the same on both channels,
        so it cancels in a TMF), and white noise of `accel_noise` [m/s²]. Every channel
        (force included) passes the acquisition's anti-alias filter (8th-order
        Butterworth at 0.4 `fs`, as steep as a measurement front end).

        **Arguments:**

        - `y`: `(position,)` Y positions [m]; `key`: PRNG key.
        - `location`: `"encoder"` or `"tcp"`.
        - `n_hits`, `fs` [Hz], `record_length` [s]: repeated records for averaging.
        - `hit_duration` [s], `force_peak` [N]: the hammer.
        - `sensors`: an [`ImpactSensors`][], or its fields as keywords: `force_noise` [N],
          `accel_noise` [m/s²], `accel_highpass_hz` [Hz], `accel_bandwidth_hz` [Hz],
          `oversample` (internal simulation steps per sample).

        **Returns:** an [`ImpactData`][].
        """
        sensors = options_object(ImpactSensors, sensors, keywords, "impact_experiment", "sensors")
        force_noise, accel_noise = sensors.force_noise, sensors.accel_noise
        accel_highpass_hz = sensors.accel_highpass_hz
        accel_bandwidth_hz = sensors.accel_bandwidth_hz
        oversample = sensors.oversample
        if location not in ("encoder", "tcp"):
            raise ValueError(f"impact_experiment: location={location!r}; use 'encoder' or 'tcp'.")
        y = np.atleast_1d(np.asarray(y, float))
        n_p = y.shape[0]
        n_t = int(round(record_length * fs))
        h = 1.0 / (fs * oversample)
        k1, k2, k3, k4 = jr.split(key, 4)
        t_fine = np.arange(n_t * oversample) * h
        pulse = np.where(t_fine < hit_duration, np.sin(np.pi * t_fine / hit_duration), 0.0)
        peaks = force_peak * (1 + 0.2 * (2 * np.asarray(jr.uniform(k1, (n_p, n_hits))) - 1))
        f_fine = peaks[..., None] * pulse  # (pos, hit, fine)
        fam = self.chain(jnp.asarray(y))
        at = ENCODER if location == "encoder" else self.tcp
        # accelerometer dynamics on both channels: high-pass (and optional bandwidth), then
        # the acquisition's analogue anti-alias filter (8th-order Butterworth at 0.4 fs, on
        # every channel, force included, so the FRFs see no aliasing of the short pulse).
        # Structure and sensor chain are simulated as one series system per channel, exact
        # for the held force: filtering the *sampled* acceleration as a held signal would
        # delay its smooth part by half a step but not the driving-point feedthrough, an
        # error of ~15 % in the TMF at the anti-resonances of H_EE (route b).
        ss = fam.state_space(at, (ENCODER, self.tcp), quantity="acceleration")
        full = (n_p, n_hits, 2)  # one SISO system per position, hit and channel
        A, B, C, D = (np.asarray(m) for m in (ss.A, ss.B, ss.C, ss.D))
        structure = (
            np.broadcast_to(A[:, None, None], full + A.shape[1:]),
            np.broadcast_to(B[:, None, None], full + B.shape[1:]),
            np.broadcast_to(C[:, None, :, None], full + (1, C.shape[-1])),
            np.broadcast_to(D[:, None, :, None], full + (1, 1)),
        )
        sensor = _accelerometer_chain(accel_highpass_hz, accel_bandwidth_hz, fs)
        chan = StateSpace(*(jnp.asarray(m) for m in _series(structure, sensor)))
        u = jnp.broadcast_to(jnp.asarray(f_fine)[:, :, None], full + f_fine.shape[-1:])
        acc = simulate(chan, u, h)[..., ::oversample]  # (pos, hit, 2, time)
        acc = np.asarray(acc) + accel_noise * np.asarray(jr.normal(k2, acc.shape))
        b4, a4 = butter(8, 2 * np.pi * 0.4 * fs, analog=True)
        anti_alias = RationalTF(jnp.asarray(b4), jnp.asarray(a4))
        f_meas = np.asarray(simulate(anti_alias, jnp.asarray(f_fine), h))[..., ::oversample]
        force = f_meas + force_noise * np.asarray(jr.normal(k3, (n_p, n_hits, n_t)))
        del k4
        return ImpactData(
            t=np.arange(n_t) / fs,
            y=y,
            location=location,
            force=force,
            a_encoder=acc[:, :, 0],
            a_tcp=acc[:, :, 1],
        )

    def tmf_experiment(
        self,
        key: PRNGKeyArray,
        ys: ArrayLike = (0.1, 0.3, 0.5),
        *,
        duration: float = 8.0,
        dt: float = 1e-3,
        servo_cycle: float | None = None,
        command_amplitude: float = 2e-5,
        emphasis: float = 3.0,
        command: ArrayLike | None = None,
        return_truth: bool = False,
        **sensors: Any,
    ) -> list[Record] | tuple[list[Record], dict[str, np.ndarray]]:
        """Diagnosis data of the `tmf` family: one record per Y position (docs/guides/contracts.md).

        Drive-side excitation: a pre-emphasised random binary sequence `b` (PRBS-like,
        ±1) in the commanded position, `x_cmd = A (b[k] + emphasis (b[k] − b[k−1]))`, held
        for one servo cycle; the position loop turns it into a drive force
        `k_servo · x_cmd` (P-position / velocity-feedback control, no command derivative).
        The pre-emphasis lifts the encoder motion at 100-300 Hz, where the TMF's resonances
        are, above the 1/ω² roll-off of the servo mode, so the excitation is rich up to
        ~300 Hz at 1 ms. With `process_force` on, a milling-like force acts at the TCP at the same
        time. The structure is continuous: simulated at `oversample` × the sample rate
        (one batched call over the positions), then sampled.

        Every record has the signals `x_e` (linear encoder [m], quantised to
        `encoder_resolution`), `x_t` (TCP position [m] from a reference sensor with white
        noise `noise`, delayed by `sensor_delay` when that effect is on), `y` (Y position
        [m], constant column; also `metadata["y"]`) and `f` (measured process force at the
        TCP [N] = actual force + white noise `force_noise`; the actual force is zero unless
        `process_force` is on). The metadata never names the hidden effects.

        **Arguments:**

        - `key`: PRNG key (excitation, process force, noise).
        - `ys`: Y positions [m], one record each.
        - `duration`: length of each record [s]; `dt`: sample time [s].
        - `servo_cycle`: hold time of the command [s], a multiple of `dt` (default `dt`).
        - `command_amplitude`: amplitude `A` of the commanded-position sequence [m].
        - `emphasis`: pre-emphasis of the command [-] (0: a plain binary sequence).
        - `command`: optional commanded position [m], `(time,)` or `(position, time)`
          sampled every `dt`, replacing the random sequence (e.g. a dynamic test cycle);
          `duration` is then its length.
        - `return_truth`: also return a dict with the noiseless, undelayed `x_t`
          (`"x_t_true"`, `(position, time)`), the encoder position before quantisation
          (`"x_e_true"`) and the actual force (`"f_true"`).
        - the fields of [`TMFSensors`][] as keywords (defaults there): `noise` (standard
          deviation of the reference TCP sensor noise [m]), `encoder_resolution`
          (quantisation step of the linear encoder [m]), `force_noise` (standard deviation
          of the force-sensor noise [N]), `oversample` (internal simulation steps per
          sample).

        **Returns:**

        A list of `jaxvs.data.Record`, one per Y position (and the truth, see above).
        """
        sensors = options_object(TMFSensors, None, sensors, "tmf_experiment", "sensors")
        noise, encoder_resolution = sensors.noise, sensors.encoder_resolution
        force_noise, oversample = sensors.force_noise, sensors.oversample
        ys = np.atleast_1d(np.asarray(ys, float))
        if ys.ndim != 1 or ys.size == 0 or not np.all(np.isfinite(ys)):
            raise ValueError(
                f"tmf_experiment: ys must be a non-empty 1-D array of Y positions [m]; got {ys!r}."
            )
        if dt <= 0 or duration <= 2 * dt:
            raise ValueError("tmf_experiment: need dt > 0 and duration > 2 dt [s].")
        if not isinstance(oversample, int) or oversample < 1:
            raise ValueError(
                f"tmf_experiment: oversample must be a positive int; got {oversample!r}."
            )
        hold = 1 if servo_cycle is None else servo_cycle / dt
        if servo_cycle is not None and (hold < 1 or abs(hold - round(hold)) > 1e-9):
            raise ValueError(
                f"tmf_experiment: servo_cycle={servo_cycle} s must be a whole multiple of "
                f"dt={dt} s (the command changes only at sample instants)."
            )
        hold = int(round(hold))
        n_p = ys.shape[0]
        k_cmd, k_force, k_x, k_f = jr.split(key, 4)
        if command is not None:
            cmd = np.asarray(command, float)
            if cmd.ndim not in (1, 2) or (cmd.ndim == 2 and cmd.shape[0] != n_p):
                raise ValueError(
                    f"tmf_experiment: command must be (time,) or ({n_p}, time); got {cmd.shape}."
                )
            if not np.all(np.isfinite(cmd)):
                raise ValueError("tmf_experiment: command contains NaN or inf.")
            cmd = np.broadcast_to(cmd, (n_p, cmd.shape[-1])).copy()
            n_t = cmd.shape[-1]
        else:
            n_t = int(round(duration / dt))
            # command: pre-emphasised random ±A per servo cycle (a PRBS in the command)
            n_cycles = -(-n_t // hold)
            bits = np.asarray(jr.bernoulli(k_cmd, 0.5, (n_p, n_cycles)), float)
            b = 2 * bits - 1
            b = b + emphasis * (b - np.concatenate([np.zeros((n_p, 1)), b[:, :-1]], axis=-1))
            cmd = command_amplitude * np.repeat(b, hold, axis=-1)[:, :n_t]
        drive_force = float(self.k_servo) * cmd
        f_true = self._milling_force(k_force, n_p, n_t, dt)
        # inputs held over each sample (the force as its measurement sees it)
        u = np.stack([drive_force, f_true], axis=-1)
        u_fine = np.repeat(u, oversample, axis=1)
        h = dt / oversample
        fam = self.chain(jnp.asarray(ys))
        tcp = self.tcp
        ss = fam.state_space((DRIVE, tcp), (ENCODER, tcp))
        pos = np.asarray(simulate(ss, jnp.asarray(u_fine), h))  # (pos, fine, 2)
        x_e_true = pos[:, ::oversample, 0]
        x_t_fine = pos[..., 1]
        x_t_true = x_t_fine[:, ::oversample]
        tau = float(self.sensor_delay)
        if tau > 0:
            t_fine = np.arange(x_t_fine.shape[1]) * h
            t_query = np.arange(n_t) * dt - tau
            x_t_rec = np.stack([np.interp(t_query, t_fine, xf, left=0.0) for xf in x_t_fine])
        else:
            x_t_rec = x_t_true
        x_e = np.round(x_e_true / encoder_resolution) * encoder_resolution
        x_t = x_t_rec + noise * np.asarray(jr.normal(k_x, x_t_rec.shape), float)
        f_meas = f_true + force_noise * np.asarray(jr.normal(k_f, f_true.shape), float)
        units = {"x_e": "m", "x_t": "m", "y": "m", "f": "N"}
        records = [
            Record(
                {"x_e": x_e[i], "x_t": x_t[i], "y": np.full(n_t, ys[i]), "f": f_meas[i]},
                dt=dt,
                units=units,
                metadata={
                    "y": float(ys[i]),
                    "source": "MachineStructureTwin.tmf_experiment",
                    "excitation": "drive-side PRBS in the commanded position",
                },
            )
            for i in range(n_p)
        ]
        if return_truth:
            return records, {"x_t_true": x_t_true, "x_e_true": x_e_true, "f_true": f_true}
        return records

    def _milling_force(self, key: PRNGKeyArray, n_p: int, n_t: int, dt: float) -> np.ndarray:
        """Random milling-like force at the TCP [N], `(position, time)`; zeros when off.

        Heuristic model of interrupted cutting: a mean force plus the first three
        tooth-pass harmonics with random phases and a slow random modulation of the
        amplitude (varying engagement), plus low-pass filtered noise (chip-thickness
        variation).
        """
        amp = float(self.process_force)
        if amp <= 0:
            return np.zeros((n_p, n_t))
        f_tp = float(self.tooth_pass_hz)
        k1, k2, k3 = jr.split(key, 3)
        t = np.arange(n_t) * dt
        phases = 2 * np.pi * np.asarray(jr.uniform(k1, (n_p, 3)), float)
        harm = np.array([0.5, 0.25, 0.12])
        fh = np.arange(1, 4)[:, None] * f_tp
        nyq = 0.5 / dt
        use = (fh[:, 0] < 0.9 * nyq).astype(float)
        wave = np.einsum(
            "h,pht->pt",
            harm * use,
            np.cos(2 * np.pi * fh[None] * t[None, None] + phases[..., None]),
        )
        # slow engagement modulation (~1 Hz) and coloured noise (first-order low-pass ~100 Hz)
        slow = 1.0 + 0.2 * np.sin(
            2 * np.pi * 0.7 * t[None] + 2 * np.pi * np.asarray(jr.uniform(k2, (n_p, 1)), float)
        )
        white = np.asarray(jr.normal(k3, (n_p, n_t)), float)
        alpha = math.exp(-2 * np.pi * 100.0 * dt)
        from scipy.signal import lfilter

        coloured = lfilter([1 - alpha], [1, -alpha], white, axis=-1)
        coloured /= max(float(np.std(coloured)), 1e-30)
        return amp * (slow * (0.6 + wave) + 0.15 * coloured)


__all__ = [
    "DRIVE",
    "ENCODER",
    "COLUMN",
    "TCP",
    "TMF_TWIN_EFFECTS",
    "ImpactData",
    "ImpactSensors",
    "MachineStructureTwin",
    "StructureData",
    "TMFSensors",
    "draw_tmf_effect",
]
