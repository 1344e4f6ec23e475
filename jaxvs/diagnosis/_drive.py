"""The `drive` family: a rigid axis `M q̈ + Fv q̇ + offset = u` and its candidate effects.

The model is an inverse-dynamics model (the force is predicted from the measured motion),
as in IDIM-LS identification of drives and robots (Gautier & Khalil; the EMPS description,
§3): the position is low-pass filtered forward and backward, differentiated, the force is
filtered by the same filter, and everything is decimated to the analysis rate. The gap is
the normalised RMS force error (EMPS eq. 11).

Each candidate effect is a differentiable augmentation that is zero at zero size:

| effect | augmentation of the predicted force |
|---|---|
| `coulomb_friction` | `Fc·tanh(q̇/v_s)` (smooth sign, sharpness `v_s` fixed) |
| `asymmetric_friction` | `Fc·s + ΔFc·|s| + ΔFv·q̇·s`, `s = tanh(q̇/v_s)`: direction-dependent levels |
| `stribeck_friction` | `(Fc + Fs·exp(−(q̇/v_st)²))·tanh(q̇/v_s)` |
| `backlash` | `m_L(q̈_L − q̈) + c_L(q̇_L − q̇)`, load motion `q_L` = play operator of `q` (half gap `b`) |
| `resonance` | `−s²/(s² + 2ζωs + ω²)·(m_r q̈ + c_r q̇)`: a load `m_r` on a spring-damper |
| `time_delay` | the whole prediction advanced by `τ` (force acting `τ` after it is commanded) |
| `external_force` | force pulses at events found in the residual (amplitude per event) |
| `position_dependence` | `Σ c_k P_k(q̄) + A·sin(2πq/p) + B·cos(2πq/p)` (Legendre + ripple of pitch `p`) |

Friction extensions (asymmetric, Stribeck) contain Coulomb friction and replace it when
they are added after it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.signal as ss
from jaxtyping import Array, Float

from ..calibration import fixed, positive
from ..data import Record
from ._base import AbstractEffect, AbstractFamily, Context, EffectSpec, Experiment
from ._stats import white_noise_floor

__all__ = ["DriveFamily", "RigidAxis"]


def _f(x) -> float:
    return float(np.asarray(x).reshape(-1)[0])


class RigidAxis(eqx.Module):
    """Nominal rigid axis, `u = M q̈ + Fv q̇ + offset` [N]."""

    M: Float[Array, ""]
    Fv: Float[Array, ""]
    offset: Float[Array, ""]

    def __call__(self, d: Mapping[str, Array]) -> Array:
        return self.M * d["a"] + self.Fv * d["v"] + self.offset

    def parameters(self) -> dict[str, float]:
        return {"M": _f(self.M), "Fv": _f(self.Fv), "offset": _f(self.offset)}


# ------------------------------------------------------------------------------ effects


def _pos(x):
    """`positive` with a floor: a shape that underflowed to 0 stays admissible."""
    return positive(jnp.maximum(jnp.asarray(x), 1e-12))


def _smooth_sign(v: Array, vs: Array) -> Array:
    return jnp.tanh(v / vs)


class CoulombFriction(AbstractEffect):
    name: ClassVar[str] = "coulomb_friction"
    size: Float[Array, 1]
    vs: Any  # fixed sharpness [m/s]

    def contribution(self, d, nominal):
        return self.size[0] * _smooth_sign(d["v"], self.vs)

    def constrained(self):
        return eqx.tree_at(lambda e: e.vs, self, replace_fn=fixed)

    def parameters(self):
        return {"Fc": _f(self.size[0]), "v_s": _f(self.vs)}


class AsymmetricFriction(AbstractEffect):
    name: ClassVar[str] = "asymmetric_friction"
    size: Float[Array, 3]  # Fc, ΔFc, ΔFv
    vs: Any

    def contribution(self, d, nominal):
        s = _smooth_sign(d["v"], self.vs)
        fc, dfc, dfv = self.size[0], self.size[1], self.size[2]
        return fc * s + dfc * jnp.abs(s) + dfv * d["v"] * s

    def constrained(self):
        return eqx.tree_at(lambda e: e.vs, self, replace_fn=fixed)

    def parameters(self):
        fc, dfc, dfv = (float(x) for x in np.asarray(self.size))
        return {"Fc_pos": fc + dfc, "Fc_neg": fc - dfc, "dFv": dfv, "v_s": _f(self.vs)}


class StribeckFriction(AbstractEffect):
    name: ClassVar[str] = "stribeck_friction"
    size: Float[Array, 2]  # Fc, Fs (excess static friction)
    v_st: Any  # positive, calibrated
    vs: Any

    def contribution(self, d, nominal):
        v = d["v"]
        level = self.size[0] + self.size[1] * jnp.exp(-jnp.square(v / self.v_st))
        return level * _smooth_sign(v, self.vs)

    def constrained(self):
        e = eqx.tree_at(lambda e: e.vs, self, replace_fn=fixed)
        return eqx.tree_at(lambda e: e.v_st, e, replace_fn=_pos)

    def parameters(self):
        fc, fs = (float(x) for x in np.asarray(self.size))
        return {"Fc": fc, "Fs": fc + fs, "v_stribeck": _f(self.v_st), "v_s": _f(self.vs)}


def _play(q: Array, b: Array) -> Array:
    """Play (backlash) operator: the load follows the motor only after `2b` of slack."""

    def step(ql, qk):
        ql = jnp.clip(ql, qk - b, qk + b)
        return ql, ql

    _, out = jax.lax.scan(step, q[0], q)
    return out


class Backlash(AbstractEffect):
    name: ClassVar[str] = "backlash"
    size: Float[Array, 2]  # load mass m_L [kg], load damping c_L [N·s/m]
    b: Any  # half gap [m], positive
    dt: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        ql = _play(d["q"], self.b)
        vl = jnp.gradient(ql, self.dt)
        al = jnp.gradient(vl, self.dt)
        # the contact spring of a real axis smooths the re-engagement over a few samples
        kernel = jnp.array([0.25, 0.5, 0.25])
        al = jnp.convolve(al, kernel, mode="same")
        return self.size[0] * (al - d["a"]) + self.size[1] * (vl - d["v"])

    def constrained(self):
        return eqx.tree_at(lambda e: e.b, self, replace_fn=_pos)

    def physical(self) -> bool:
        return bool(np.all(np.asarray(self.size) >= 0))

    def parameters(self):
        return {"gap": 2 * _f(self.b), "m_load": _f(self.size[0]), "c_load": _f(self.size[1])}


def _highpass2(x: Array, w: Array, z: Array, dt: float) -> Array:
    """`s²/(s² + 2ζωs + ω²)` applied to `x` by the bilinear (Tustin) rule with the
    resonance pre-warped, as a biquad recursion in `lax.scan`."""
    k = w / jnp.tan(w * dt / 2)  # pre-warped bilinear constant
    a0 = k * k + 2 * z * w * k + w * w
    b = jnp.stack([k * k, -2 * k * k, k * k]) / a0
    a1 = (2 * w * w - 2 * k * k) / a0
    a2 = (k * k - 2 * z * w * k + w * w) / a0

    def step(carry, xk):
        x1, x2, y1, y2 = carry
        yk = b[0] * xk + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2
        return (xk, x1, yk, y1), yk

    zero = jnp.zeros((), x.dtype)
    init = (x[0], x[0], zero, zero)  # at rest: a constant input has no high-pass output
    return jax.lax.scan(step, init, x)[1]


class Resonance(AbstractEffect):
    """A load `m_r` on a spring-damper behind the motor (mode `ω`, `ζ`), with its own
    viscous friction `c_r`: the load's acceleration and velocity are those of the motor
    filtered by `H(s) = (2ζωs + ω²)/(s² + 2ζωs + ω²)`, so the force changes by
    `m_r (H − 1) q̈ + c_r (H − 1) q̇`, with `H − 1 = −s²/(s² + 2ζωs + ω²)`."""

    name: ClassVar[str] = "resonance"
    size: Float[Array, 2]  # resonating mass m_r [kg], its viscous friction c_r [N·s/m]
    omega: Any  # positive [rad/s]
    zeta: Any  # positive
    dt: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        hp = lambda x: _highpass2(x, self.omega, self.zeta, self.dt)
        return -self.size[0] * hp(d["a"]) - self.size[1] * hp(d["v"])

    def constrained(self):
        return eqx.tree_at(lambda e: (e.omega, e.zeta), self, replace_fn=_pos)

    def physical(self) -> bool:
        return bool(np.asarray(self.size)[0] >= 0 and np.asarray(self.zeta) < 2.0)

    def parameters(self):
        return {
            "f_r": _f(self.omega) / (2 * math.pi),
            "zeta": _f(self.zeta),
            "m_r": _f(self.size[0]),
            "c_r": float(np.asarray(self.size)[1]),
        }


class TimeDelay(AbstractEffect):
    name: ClassVar[str] = "time_delay"
    tau: Float[Array, ""]  # [s]; > 0: the force acts tau after it is commanded
    dt: float = eqx.field(static=True)

    def apply(self, y, d, nominal):
        n = y.shape[0]
        idx = jnp.arange(n, dtype=y.dtype)
        return jnp.interp(idx + self.tau / self.dt, idx, y)

    def order(self) -> int:
        return 1

    def parameters(self):
        return {"tau": _f(self.tau)}


def _legendre(x: Array, degree: int) -> Array:
    cols = [x]
    p0, p1 = jnp.ones_like(x), x
    for k in range(1, degree):
        p0, p1 = p1, ((2 * k + 1) * x * p1 - k * p0) / (k + 1)
        cols.append(p1)
    return jnp.stack(cols, axis=-1)


class PositionDependence(AbstractEffect):
    name: ClassVar[str] = "position_dependence"
    size: Float[Array, 5]  # 3 Legendre coefficients, sine and cosine of the ripple
    pitch: Any  # positive [m]
    centre: float = eqx.field(static=True)
    half_range: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        q = d["q"]
        x = (q - self.centre) / self.half_range
        ph = 2 * jnp.pi * q / self.pitch
        basis = jnp.concatenate(
            [_legendre(x, 3), jnp.stack([jnp.sin(ph), jnp.cos(ph)], -1)], axis=-1
        )
        return basis @ self.size

    def constrained(self):
        return eqx.tree_at(lambda e: e.pitch, self, replace_fn=_pos)

    def parameters(self):
        s = np.asarray(self.size)
        return {
            "ripple_amplitude": float(np.hypot(s[3], s[4])),
            "ripple_pitch": _f(self.pitch),
            "legendre_1": float(s[0]),
            "legendre_2": float(s[1]),
            "legendre_3": float(s[2]),
        }


class ExternalForce(AbstractEffect):
    """Unmeasured force pulses: one constant force per event found in the residual.

    The events are data (`d["events"]`, one unit-pulse column per event, located by
    `detect_events` in the residual of the model without this effect, on every
    experiment); the amplitudes are profiled out by least squares against the remaining
    force error of each experiment (variable projection), since an unmeasured disturbance
    cannot be predicted from one experiment to the next. ΔBIC counts three parameters per
    event (start, end, amplitude).
    """

    name: ClassVar[str] = "external_force"

    def apply(self, y, d, nominal):
        ev = d["events"]
        r = d["y"] - y
        gram = ev.T @ ev
        eps = 1e-9 * (jnp.trace(gram) / ev.shape[-1] + 1.0)
        amp = jnp.linalg.solve(gram + eps * jnp.eye(ev.shape[-1], dtype=ev.dtype), ev.T @ r)
        return y + ev @ amp

    def order(self) -> int:
        return 2

    def extra_dof(self, arrays: Sequence[Mapping[str, Array]]) -> int:
        return 3 * sum(int(np.sum(np.any(np.asarray(d["events"]) != 0, axis=0))) for d in arrays)

    def parameters(self):
        return {}


# ------------------------------------------------------------------------------ templates


def _vmax(ctx: Context) -> float:
    return max(float(np.max(np.abs(e.arrays["v"]))) for e in ctx.experiments)


def _vs_default(ctx: Context) -> float:
    return float(ctx.options.get("friction_sharpness", 0.005)) * _vmax(ctx)


def _t_coulomb(ctx: Context) -> list[AbstractEffect]:
    vm = _vmax(ctx)
    return [CoulombFriction(jnp.zeros(1), jnp.asarray(f * vm)) for f in (0.002, 0.01)]


def _t_asym(ctx: Context) -> list[AbstractEffect]:
    base = _existing(ctx, "coulomb_friction")
    vs = base.vs if base is not None else jnp.asarray(_vs_default(ctx))
    fc = base.size[0] if base is not None else 0.0
    return [AsymmetricFriction(jnp.array([fc, 0.0, 0.0]), vs)]


def _t_stribeck(ctx: Context) -> list[AbstractEffect]:
    base = _existing(ctx, "coulomb_friction")
    vs = base.vs if base is not None else jnp.asarray(_vs_default(ctx))
    fc = base.size[0] if base is not None else 0.0
    vm = _vmax(ctx)
    return [StribeckFriction(jnp.array([fc, 0.0]), jnp.asarray(f * vm), vs) for f in (0.02, 0.1)]


def _t_backlash(ctx: Context) -> list[AbstractEffect]:
    dt = ctx.experiments[0].dt
    return [Backlash(jnp.zeros(2), jnp.asarray(b), dt) for b in (2e-5, 1.5e-4)]


def _t_resonance(ctx: Context) -> list[AbstractEffect]:
    exp0 = ctx.experiments[0]
    dt = exp0.dt
    fs = 1.0 / dt
    e = np.concatenate([np.asarray(r) for r in ctx.residuals])
    f, p = ss.welch(e - e.mean(), fs=fs, nperseg=min(e.size, 2048))
    band = (f > 2.0) & (f < 0.8 * float(ctx.options.get("cutoff_hz", fs / 2)))
    peaks, props = ss.find_peaks(np.where(band, p, 0.0), prominence=0)
    top = peaks[np.argsort(props["prominences"])[::-1][:2]] if peaks.size else []
    freqs = [float(f[i]) for i in top] or [fs / 10]
    out = []
    for fr in freqs:
        for z in (0.05,):
            out.append(Resonance(jnp.zeros(2), jnp.asarray(2 * math.pi * fr), jnp.asarray(z), dt))
    return out


def _t_delay(ctx: Context) -> list[AbstractEffect]:
    dt = ctx.experiments[0].dt
    taus = [1.0e-3, 3.0e-3, -1.5e-3]
    return [TimeDelay(jnp.asarray(t), dt) for t in taus if abs(t) >= 0.25 * dt]


def _t_position(ctx: Context) -> list[AbstractEffect]:
    """Ripple pitches from the spectrum of the residual over position: the residual is
    averaged in 512 position bins and its strongest spatial frequencies seed the pitch."""
    q = np.concatenate([e.arrays["q"] for e in ctx.experiments])
    r = np.concatenate([np.asarray(x) for x in ctx.residuals])
    lo, hi = float(q.min()), float(q.max())
    centre, half = (lo + hi) / 2, max((hi - lo) / 2, 1e-12)
    span = max(hi - lo, 1e-12)
    nb = 512
    idx = np.clip(((q - lo) / span * nb).astype(int), 0, nb - 1)
    cnt = np.bincount(idx, minlength=nb)
    mean = np.bincount(idx, weights=r, minlength=nb) / np.maximum(cnt, 1)
    ok = cnt > 0
    grid = np.arange(nb)
    mean = np.interp(grid, grid[ok], mean[ok]) if ok.any() else mean
    # remove the smooth part the Legendre terms take, then look for the ripple
    x = (grid + 0.5) / nb * 2 - 1
    mean = mean - np.polyval(np.polyfit(x, mean, 3), x)
    spec = np.abs(np.fft.rfft(mean * np.hanning(nb)))
    spec[:3] = 0.0
    top = np.argsort(spec)[::-1][:2]
    pitches = [span / k for k in top if k > 0] + [span / 1.5]
    return [PositionDependence(jnp.zeros(5), jnp.asarray(p), centre, half) for p in pitches]


def _t_external(ctx: Context) -> list[AbstractEffect]:
    return [ExternalForce()]


def _existing(ctx: Context, name: str):
    for e in ctx.model.effects:
        if e.name == name:
            return e
    return None


def _needs_motion_both_ways(experiments: Sequence[Experiment]) -> str | None:
    v = np.concatenate([e.arrays["v"] for e in experiments])
    vm = float(np.max(np.abs(v)))
    if vm == 0 or np.mean(v > 0.05 * vm) < 0.02 or np.mean(v < -0.05 * vm) < 0.02:
        return "needs motion in both directions"
    return None


def _needs_travel(experiments: Sequence[Experiment]) -> str | None:
    q = np.concatenate([e.arrays["q"] for e in experiments])
    if float(np.ptp(q)) <= 0:
        return "needs travel along the axis"
    return None


# ------------------------------------------------------------------------------ family


MAX_EVENTS = 16


def detect_events(
    residual: np.ndarray, dt: float, *, window_s: float = 0.05, threshold: float = 5.0
) -> np.ndarray:
    """Columns of unit pulses where the smoothed residual stays far from zero.

    The residual is smoothed by a moving average of `window_s`; samples beyond `threshold`
    robust standard deviations (MAD of the smoothed residual) form events, merged when
    closer than one window and dropped when shorter than one window. Returns
    `(n, MAX_EVENTS)`, unused columns zero.
    """
    e = np.asarray(residual, float)
    w = max(1, int(round(window_s / dt)))
    sm = np.convolve(e, np.ones(w) / w, mode="same")
    med = np.median(sm)
    sigma = 1.4826 * np.median(np.abs(sm - med)) + 1e-300
    on = np.abs(sm - med) > threshold * sigma
    # merge gaps shorter than a window
    idx = np.flatnonzero(on)
    cols = []
    if idx.size:
        starts = [idx[0]]
        ends = []
        for a, b in zip(idx[:-1], idx[1:]):
            if b - a > w:
                ends.append(a)
                starts.append(b)
        ends.append(idx[-1])
        for s0, s1 in zip(starts, ends):
            if s1 - s0 + 1 >= w:
                col = np.zeros(e.size)
                col[s0 : s1 + 1] = 1.0
                cols.append(col)
    out = np.zeros((e.size, MAX_EVENTS))
    for k, col in enumerate(cols[:MAX_EVENTS]):
        out[:, k] = col
    return out


class DriveFamily(AbstractFamily):
    """Rigid prismatic axis driven by a force `u` with measured position `q`.

    **Options:** `cutoff_hz` (zero-phase low-pass of position and force, default
    `min(fs/8, 100)` Hz), `filter_order` (4), `decimation` (default so that the analysis
    rate is about 4× the cut-off), `friction_sharpness` (`v_s` of the smooth sign as a
    fraction of the largest speed, 0.005), `zoh_force` (default `True`: the recorded force
    is zero-order held by the drive, i.e. acts on average half a sample after its time
    stamp; the half-sample shift is compensated so that it is not reported as a delay).
    """

    name = "drive"
    required = ("q", "u")
    optional = ("r",)
    target_label = "force u [N]"

    _MODEL_SIGNALS = ("q", "u", "r", "vir", "q_ref", "qg")

    def prepare(self, record: Record, name: str) -> Experiment:
        fs = 1.0 / record.dt
        cutoff = float(self.options.get("cutoff_hz") or min(fs / 8.0, 100.0))
        if not 0 < cutoff < fs / 2:
            raise ValueError(
                f"diagnose(drive): cutoff_hz={cutoff} must lie in (0, fs/2 = {fs / 2:g}) Hz."
            )
        self.options["cutoff_hz"] = cutoff
        order = int(self.options.get("filter_order", 4))
        nd = int(self.options.get("decimation") or max(1, int(fs / (4.0 * cutoff))))
        q = np.asarray(record["q"], float)
        u = np.asarray(record["u"], float)
        if self.options.get("zoh_force", True):
            # a digital drive holds each force sample over the next period: its mean time
            # is half a sample later than its time stamp (Franklin, Powell & Workman,
            # *Digital Control of Dynamic Systems*, §6.3), so the force acting at t_k is
            # the mean of the held samples k-1 and k.
            u = np.concatenate([u[:1], 0.5 * (u[1:] + u[:-1])])
        n_min = 20 * nd + 64
        if q.size < n_min:
            raise ValueError(
                f"diagnose(drive): experiment {name!r} has {q.size} samples; at least {n_min} "
                "are needed for filtering and differentiation. Give longer records."
            )
        sos = ss.butter(order, cutoff, fs=fs, output="sos")
        pad = int(min(q.size - 1, 3 * fs / cutoff))
        qf = ss.sosfiltfilt(sos, q, padlen=pad)
        uf = ss.sosfiltfilt(sos, u, padlen=pad)
        v = np.gradient(qf, 1.0 / fs, edge_order=2)
        a = np.gradient(v, 1.0 / fs, edge_order=2)
        edge = int(math.ceil(3 * fs / cutoff))
        sl = slice(edge, q.size - edge, nd)
        t = np.asarray(record.t)[sl]
        arrays = {"q": qf[sl], "v": v[sl], "a": a[sl], "y": uf[sl]}
        if float(np.ptp(q)) == 0.0:
            raise ValueError(
                f"diagnose(drive): experiment {name!r} has no motion (q is constant); the "
                "inertia and friction are not identifiable. Give experiments with motion."
            )
        # noise: the white part of the force above the cut-off, carried into the band
        s0, _ = white_noise_floor(u - uf, fs)
        w, h = ss.sosfreqz(sos, worN=4096, fs=fs)
        enbw = float(np.trapezoid(np.abs(h) ** 4, w))
        noise_var = s0 * enbw
        vmax = float(np.max(np.abs(arrays["v"])))
        vv = arrays["v"]
        masks = _drive_masks(vv, vmax, 1.0 / fs * nd)
        for sig in record.names:
            if sig in self._MODEL_SIGNALS:
                continue
            x = np.asarray(record[sig])[sl]
            levels = np.unique(np.round(x, 9))
            if 2 <= levels.size <= 3 and np.ptp(x) > 0:
                masks[f"{sig} on"] = x > (levels.min() + levels.max()) / 2
        ops = {"velocity [m/s]": vv, "speed [m/s]": np.abs(vv), "position [m]": arrays["q"]}
        arrays["events"] = np.zeros((t.size, MAX_EVENTS))
        return Experiment(
            name=name,
            t=t,
            arrays=arrays,
            ops=ops,
            masks=masks,
            noise_var=float(noise_var),
            signals=frozenset(record.names),
            source=record,
        )

    def describe_nominal(self) -> str:
        return "rigid axis M q̈ + Fv q̇ + offset = u (inverse dynamics, force predicted from motion)"

    def nominal(self, experiments: Sequence[Experiment]) -> RigidAxis:
        phi = np.concatenate(
            [np.stack([e.arrays["a"], e.arrays["v"], np.ones(e.n)], -1) for e in experiments]
        )
        y = np.concatenate([e.y for e in experiments])
        th, *_ = np.linalg.lstsq(phi, y, rcond=None)
        return RigidAxis(jnp.asarray(th[0]), jnp.asarray(th[1]), jnp.asarray(th[2]))

    def library(self) -> list[EffectSpec]:
        return [
            EffectSpec(
                "coulomb_friction",
                ("q", "u"),
                _t_coulomb,
                testable=_needs_motion_both_ways,
                signature="sign(velocity)",
                description="dry friction of constant level opposing the motion",
            ),
            EffectSpec(
                "asymmetric_friction",
                ("q", "u"),
                _t_asym,
                extends="coulomb_friction",
                testable=_needs_motion_both_ways,
                signature="|velocity|",
                description="friction levels that differ between the two directions",
            ),
            EffectSpec(
                "stribeck_friction",
                ("q", "u"),
                _t_stribeck,
                extends="coulomb_friction",
                testable=_needs_motion_both_ways,
                signature="sign(v)·exp(-(v/v_st)²)",
                description="friction peak at low speed (Stribeck curve)",
            ),
            EffectSpec(
                "backlash",
                ("q", "u"),
                _t_backlash,
                testable=_needs_motion_both_ways,
                signature="acceleration near reversals",
                description="play between motor and load",
            ),
            EffectSpec(
                "resonance",
                ("q", "u"),
                _t_resonance,
                signature="residual spectrum peak",
                description="a compliant load: a mode between motor and load",
            ),
            EffectSpec(
                "time_delay",
                ("q", "u"),
                _t_delay,
                signature="cross-correlation lag",
                description="the force acts later than it is recorded",
            ),
            EffectSpec(
                "external_force",
                ("q", "u"),
                _t_external,
                refresh=_refresh_events,
                signature="residual bursts",
                description="unmeasured force pulses on the axis",
            ),
            EffectSpec(
                "position_dependence",
                ("q", "u"),
                _t_position,
                testable=_needs_travel,
                signature="position",
                description="force depending on the position (cogging, gravity, spring)",
            ),
        ]


def _refresh_events(exp: Experiment, residual: np.ndarray) -> Experiment:
    """Attach the event columns of the external-force candidate to an experiment."""
    ev = detect_events(residual, exp.dt)
    return dataclasses.replace(exp, arrays={**exp.arrays, "events": ev})


def _drive_masks(v: np.ndarray, vmax: float, dt: float) -> dict[str, np.ndarray]:
    """Operating-point cells of an axis: velocity reversals (the low-speed passages,
    |v| < 10 % of the largest speed, between motions of opposite sign), standstill
    (|v| < 2 %, not a reversal), and the two directions."""
    thr = 0.02 * vmax
    low = np.abs(v) < 0.1 * vmax
    sign = np.sign(v)
    # runs of constant `low`; a low run is a reversal when the motion before and after it
    # has opposite signs (runs touching the record's ends are not)
    edges = np.flatnonzero(np.diff(low.astype(int))) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [v.size]])
    inner = (starts > 0) & (ends < v.size)
    before = sign[np.maximum(starts - 1, 0)]
    after = sign[np.minimum(ends, v.size - 1)]
    rev = np.repeat(low[starts] & inner & (before * after < 0), ends - starts)
    return {
        "velocity reversals": rev,
        "standstill": (np.abs(v) < thr) & ~rev,
        "positive velocity": v > thr,
        "negative velocity": v < -thr,
    }
