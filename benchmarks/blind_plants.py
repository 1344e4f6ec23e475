"""Blind plants for the sim-to-real diagnosis benchmark.

Records of the three diagnosis families (drive, tmf, thermal; docs/guides/contracts.md)
from plants written here with numpy/scipy only -- no jaxvs model, twin or diagnosis code is
used to make the data, so the diagnosis cannot be tuned to them. Every effect of the
effect-name table is built in at least two structurally different ways, and differently
from the library's augmentations and from `jaxvs.twins`:

drive (a rigid axis `M q̈ + Fv q̇ + offset = u` is the nominal model):
- `coulomb_friction`: (A) Karnopp stick-slip with a zero-velocity band; (B) Dahl
  presliding model, updated exactly in displacement.
- `asymmetric_friction`: (A) Karnopp with direction-dependent levels and viscous terms;
  (B) Dahl with direction-dependent levels.
- `stribeck_friction`: (A) Karnopp with a generalised Stribeck curve `exp(-|v/vs|^δ)`,
  δ < 2; (B) Dahl with a Lorentzian Stribeck level and direction-dependent viscous terms.
- `backlash`: (A) motor and load with a Hertzian (`k·δ^1.5`, Hunt–Crossley) dead-zone
  contact; (B) friction-loaded gap: a hybrid motor/table model with plastic impact, the
  table held by stick-slip friction (after a reversal the motor crosses the gap unloaded).
- `resonance`: (A) two-mass axis measured at the load (non-collocated linear scale);
  (B) frame mode: the motor sits on a sprung base, the encoder measures relative to it.
- `time_delay`: (A) continuous transport delay of the force (sub-sample resolution);
  (B) computational delay of whole controller periods.
- `external_force`: (A) process pulses (trapezoid envelope with tooth ripple);
  (B) a gravity-like constant load switched on and off.
- `position_dependence`: (A) cogging ripple (two harmonics of a magnet pitch);
  (B) a wavy inclined guideway (gravity) plus a cable-carrier spring.
- `saturation`: (A) current limit: the amplifier clips the held command of the digital
  cascade at ±F_max (hard clip, integrator wind-up; the logger records the command);
  (B) a lagged amplifier: the command passes a first-order current loop (τ of 0.5–1 ms)
  before the clip.

tmf (root-excited beam, modal sum; the nominal is one 4/4 rational TMF):
- `position_dependence`: (A) overhang `L(y)`, every mode scales with `1/L²`; (B) joint
  preload: frequency and damping of the first mode vary with `sin(πy/Y)`.
- `missing_mode`: (A) the third beam mode inside the band; (B) an extra mode near or
  above the Nyquist frequency.
- `sensor_delay`: (A) pure delay of the tool-side channel; (B) a 4th-order Bessel
  anti-alias filter on the tool-side channel only.
- `process_force`: (A) milling force (tooth passing, slow modulation) at the tool,
  measured; (B) random bursts measured through a dynamometer with its own mode and gain.

thermal (lumped network; the nominal is the static regression of the study):
- `dynamics`: (A) bearing heat capacity (first order); (B) two-node heat path
  bearing–shaft–chassis (second order).
- `ambient_temperature`: (A) conductance bearing ↔ air; (B) the bearing sensor biased
  towards the air temperature (mounting error).
- `coolant_temperature`: (A) conductance bearing ↔ water jacket; (B) the coolant reaches
  the bearing with a transport delay.
- `speed_nonlinearity`: (A) power-law friction heat `∝ |v|^α`; (B) quadratic friction
  heat with speed-dependent convection.

Sizes: the setting `effect_size` (default 1) scales an effect's magnitude (friction levels,
backlash gap, external and position forces, tmf pure delay, thermal quadratic heat) with
every other parameter of the plant unchanged. Each library effect has a case whose
held-out gap is 3–20 times the noise floor (the hard, small size) and one with a larger
gap, where the plant can make one (a delay or resonance inside a stable loop stays small).

Effect-free plants (the nominal model of the family is exact) run through the same
pipeline artefacts: quantised encoders, digital P/PI cascades at their own rate with
velocity estimation by differencing and filters, force sample-and-hold, white and
coloured noise, temperature sensor quantisation.

    python benchmarks/blind_plants.py          # list the cases and time their generation
    python benchmarks/blind_plants.py --write DIR [--only NAME,...]   # .npz for the CLI

`cases()` is the deterministic case list; `generate(case)` returns
`(calibration_records, validation_records, info)` of `jaxvs.data.Record`s that
`jaxvs.diagnose` accepts. Every case carries its ground truth (effect set, primary effect,
true parameters) and its seed.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
import zlib
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.signal as ss

from jaxvs.data import Record

__all__ = ["Case", "cases", "generate", "select", "write_case"]


@dataclasses.dataclass(frozen=True)
class Case:
    """One blind case: a plant variant, its settings and its ground truth.

    - `name`: unique, stable identifier (also the seed's source).
    - `family`: `"drive"`, `"tmf"` or `"thermal"`.
    - `effects`: the effects built into the plant (the diagnosis's effect names); empty when the
        family's nominal model is exact.
    - `primary`: the effect that dominates the gap (`None` when effect-free).
    - `primary_alternatives`: other effects that are an equally right primary answer (for
        two effects of comparable size).
    - `variant`: how each effect is built (see the module table).
    - `settings`: sampling, loop, noise, lengths (plain values).
    """

    name: str
    family: str
    effects: tuple[str, ...]
    primary: str | None
    variant: str
    settings: dict
    primary_alternatives: tuple[str, ...] = ()

    @property
    def seed(self) -> int:
        return zlib.crc32(self.name.encode())

    @property
    def effect_free(self) -> bool:
        return not self.effects

    @property
    def out_of_library(self) -> bool:
        """The plant's effect is in no library of the diagnosis (`effects` = `("ool:…",)`)."""
        return any(e.startswith("ool:") for e in self.effects)


# ================================================================================ helpers


def _coloured(rng: np.random.Generator, n: int, sigma: float, rho: float) -> np.ndarray:
    """AR(1) noise of standard deviation `sigma` and lag-one correlation `rho` (0: white)."""
    w = rng.standard_normal(n)
    if rho <= 0:
        return sigma * w
    x = ss.lfilter([math.sqrt(1 - rho * rho)], [1.0, -rho], w)
    return sigma * x


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(x / step) * step if step > 0 else x


def _smoothstep(s):
    """Quintic 0→1 ramp with zero velocity and acceleration at both ends."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10 - 15 * s + 6 * s * s)


def _p2p_reference(rng, n, dt, amp, t_move, dwell, centre=0.0):
    """Random point-to-point moves (quintic profiles) with dwells; returns position [m]."""
    r = np.empty(n)
    k, pos = 0, centre
    while k < n:
        target = centre + amp * rng.uniform(-1, 1)
        if abs(target - pos) < 0.25 * amp:
            target = centre - math.copysign(0.6 * amp, pos - centre) if pos != centre else amp
        dur = t_move * rng.uniform(0.5, 1.8)
        m = max(2, int(dur / dt))
        s = _smoothstep(np.arange(1, m + 1) / m)
        seg = pos + (target - pos) * s
        take = min(m, n - k)
        r[k : k + take] = seg[:take]
        k += take
        pos = target
        d = int(dwell * rng.uniform(0.3, 1.5) / dt)
        take = min(d, n - k)
        r[k : k + take] = pos
        k += take
    return r


def _sine_reference(rng, n, dt, amp, f0, centre=0.0):
    """Two or three sines around `f0` [Hz], faded in and out; position [m]."""
    t = np.arange(n) * dt
    r = np.zeros(n)
    k = int(rng.integers(2, 4))
    for i in range(k):
        f = f0 * rng.uniform(0.6, 1.6) * (1 + 0.8 * i)
        r += amp / k * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) / (1 + 0.5 * i)
    fade = _smoothstep(t / min(1.0 / f0, t[-1] / 4)) * _smoothstep((t[-1] - t) / (1.0 / f0))
    return centre + r * fade


# ================================================================================= drive
#
# One fine-step loop (step h) with the digital controller every `nc` steps and the logger
# every `nr` steps. Rigid plants use the exact exponential update of M v' = F - Fv v for a
# force held over the step (exact for the effect-free plant); friction and other nonlinear
# forces are held over a step. Two-body plants use semi-implicit Euler with h resolving
# the highest contact/coupling frequency (ω h ≤ 0.25).


def _rigid_update(x, v, F, M, Fv, h):
    a = math.exp(-Fv * h / M)
    vinf = F / Fv
    v1 = vinf + (v - vinf) * a
    x1 = x + vinf * h + (v - vinf) * (1 - a) * M / Fv
    return x1, v1


def simulate_drive(p: dict, r_ctrl: np.ndarray | None, u_ol: np.ndarray | None, rng) -> dict:
    """Simulate one drive experiment.

    **Arguments:**

    - `p`: plant and pipeline parameters (see `_drive_params`); masses [kg], forces [N],
        positions [m], rates [Hz].
    - `r_ctrl`: position reference at the controller rate [m] (closed loop) or `None`.
    - `u_ol`: force at the controller rate [N] (open loop) or `None`.
    - `rng`: numpy generator for the noise.

    **Returns:** dict of logged arrays `q` (quantised sensor position), `u` (commanded
    force with noise), `r` (reference, closed loop), and the true motor/load positions
    `x_motor`, `x_load` at the log instants [m].
    """
    structure = p["structure"]
    fs_c, fs_r, nsub = p["fs_ctrl"], p["fs_rec"], p["nsub"]
    base = math.lcm(int(fs_c), int(fs_r))
    nc, nr = base // int(fs_c), base // int(fs_r)
    h = 1.0 / (base * nsub)
    nc, nr = nc * nsub, nr * nsub
    n_ctrl = (r_ctrl if r_ctrl is not None else u_ol).size
    n_fine = n_ctrl * nc
    n_log = n_fine // nr

    M = p["M"]
    Fv = p["Fv"]
    off = p["offset"]
    res = p["resolution"]
    # friction of the rigid plant: ("none"|"karnopp"|"dahl", params)
    fr = p.get("friction", "none")
    Fc_p, Fc_n = p.get("Fc_pos", 0.0), p.get("Fc_neg", 0.0)
    Fs_p, Fs_n = p.get("Fs_pos", Fc_p), p.get("Fs_neg", Fc_n)
    dFv_p, dFv_n = p.get("dFv_pos", 0.0), p.get("dFv_neg", 0.0)
    vst, delta = p.get("v_stribeck", 1.0), p.get("stribeck_exp", 1.0)
    lorentz = p.get("stribeck_shape", "exp") == "lorentz"
    sigma_d = p.get("sigma_dahl", 1e6)
    dv_stick = p.get("dv_stick", 1e-5)

    def level(v):
        if v >= 0:
            fc, fs = Fc_p, Fs_p
        else:
            fc, fs = Fc_n, Fs_n
        if fs == fc:
            return fc
        z = abs(v) / vst
        if lorentz:
            return fc + (fs - fc) / (1 + z * z)
        return fc + (fs - fc) * math.exp(-(z**delta))

    f_lim = p.get("force_limit", math.inf)  # amplifier limit [N] on the applied force
    tau_i = p.get("current_tau", 0.0)  # first-order current loop before the limit [s]
    i_dec = math.exp(-h / tau_i) if tau_i > 0 else 0.0
    i_amp = 0.0
    ext = p.get("external")  # callable t -> force, or None
    ool = p.get("ool")  # out-of-library: callable (t, x, v) -> (force, mass factor, gain)
    posf = p.get("position_force")  # callable x -> force, or None
    tau_steps = int(p.get("transport_steps", 0))
    ctrl_delay = int(p.get("ctrl_delay", 0))

    # controller
    closed = r_ctrl is not None
    Kp, Kv, Ti = p.get("Kp", 0.0), p.get("Kv", 0.0), p.get("Ti", 1.0)
    Tc = 1.0 / fs_c
    alpha_v = math.exp(-2 * math.pi * p.get("fv_filter", fs_c / 5) * Tc)
    kff = p.get("Kff", 0.0)

    # state
    xm = vm = 0.0
    xl = vl = 0.0  # load (two-mass, gap) or base (frame)
    Fd = 0.0  # Dahl friction force
    contact = 0  # gap model: 0 free, +1/-1 engaged on that side
    ml, cl, kc, cc, gap_b = (p.get(k, 0.0) for k in ("M_load", "c_load", "k_c", "c_c", "b"))
    Fc_L = p.get("Fc_load", 0.0)
    hertz = p.get("contact", "") == "hertz"
    sensor_on_load = p.get("sensor", "motor") == "load"
    if structure in ("two_mass", "gap"):
        mm = M - ml
    u_hold = 0.0
    pipe = [0.0] * ctrl_delay  # commands computed but not yet applied
    hist = [0.0] * tau_steps  # applied force history of the transport delay
    q_prev = 0.0
    v_est = 0.0
    integ = 0.0
    r_prev = r_ctrl[0] if closed else 0.0
    v_ref_prev = 0.0

    q_log = np.empty(n_log)
    u_log = np.empty(n_log)
    r_log = np.empty(n_log)
    xm_log = np.empty(n_log)
    xl_log = np.empty(n_log)
    u_cmd = 0.0
    k_ctrl = -1
    for j in range(n_fine):
        t = j * h
        if structure == "frame":
            x_sens = xm - xl
        elif sensor_on_load:
            x_sens = xl
        else:
            x_sens = xm
        if j % nc == 0:
            k_ctrl += 1
            qk = round(x_sens / res) * res
            # dual-loop drive: with a load-side scale, the velocity loop still differences
            # the motor encoder (collocated), only the position loop closes on the scale
            qv = round(xm / res) * res if sensor_on_load else qk
            if closed:
                rk = r_ctrl[k_ctrl]
                v_ref = (rk - r_prev) / Tc
                a_ref = (v_ref - v_ref_prev) / Tc
                r_prev, v_ref_prev = rk, v_ref
                v_raw = (qv - q_prev) / Tc if k_ctrl > 0 else 0.0
                v_est = alpha_v * v_est + (1 - alpha_v) * v_raw
                ev = Kp * (rk - qk) + v_ref - v_est
                # anti-wind-up of a limited amplifier: no integration while the command is
                # beyond the limit and the error drives it further (clamping)
                if not (abs(u_cmd) > f_lim and ev * u_cmd > 0):
                    integ += ev * Tc
                u_cmd = Kv * (ev + integ / Ti) + kff * a_ref
            else:
                u_cmd = float(u_ol[k_ctrl])
            q_prev = qv
            pipe.append(u_cmd)
            u_hold = pipe.pop(0)
        if j % nr == 0:
            i = j // nr
            q_log[i] = x_sens
            u_log[i] = u_cmd
            r_log[i] = r_ctrl[k_ctrl] if closed else 0.0
            xm_log[i] = xm
            xl_log[i] = xl
        hist.append(u_hold)
        F = hist.pop(0)
        if f_lim < math.inf:
            i_amp = F + (i_amp - F) * i_dec  # exact for a held input (0: no lag)
            F = min(max(i_amp, -f_lim), f_lim)
        m_fac = 1.0
        if ool is not None:
            dF, m_fac, gain = ool(t, xm, vm)
            F = gain * F + dF
        F -= off
        if ext is not None:
            F += ext(t)
        if structure == "rigid":
            if posf is not None:
                F += posf(xm)
            if fr == "none":
                xm, vm = _rigid_update(xm, vm, F, M * m_fac, Fv, h)
            elif fr == "karnopp":
                if abs(vm) < dv_stick:
                    brk = Fs_p if F > 0 else Fs_n
                    if abs(F) <= brk:
                        vm = 0.0
                        continue
                    ff = math.copysign(brk, F)
                    fvv = Fv + (dFv_p if F > 0 else dFv_n)
                else:
                    ff = math.copysign(level(vm), vm)
                    fvv = Fv + (dFv_p if vm > 0 else dFv_n)
                v0 = vm
                xm, vm = _rigid_update(xm, vm, F - ff, M, fvv, h)
                if v0 != 0.0 and vm * v0 < 0:  # friction cannot reverse the motion
                    vm = 0.0
            else:  # dahl
                fvv = Fv + (dFv_p if vm > 0 else dFv_n)
                x0 = xm
                xm, vm = _rigid_update(xm, vm, F - Fd, M, fvv, h)
                dx = xm - x0
                if dx != 0.0:
                    g = level(vm if vm != 0.0 else dx)
                    s = g if dx > 0 else -g
                    Fd = s + (Fd - s) * math.exp(-sigma_d * abs(dx) / g)
        elif structure == "two_mass":
            d = xm - xl
            dd = vm - vl
            if hertz:
                pen = abs(d) - gap_b
                if pen > 0:
                    fk = kc * pen**1.5
                    fcon = math.copysign(fk, d) + cc * fk * dd
                    if fcon * d < 0:
                        fcon = 0.0
                else:
                    fcon = 0.0
            else:
                fcon = kc * d + cc * dd
            fm = F - Fv * (mm / M) * vm - fcon
            fl = fcon - Fv * (ml / M) * vl - cl * vl
            vm += h * fm / mm
            vl += h * fl / ml
            xm += h * vm
            xl += h * vl
        elif structure == "frame":
            # carriage (mass M, absolute xm) pushed by the motor on the base (xl)
            rel_v = vm - vl
            fc_ = F - Fv * rel_v
            fb = -fc_ - kc * xl - cc * vl
            vm += h * fc_ / M
            vl += h * fb / ml
            xm += h * vm
            xl += h * vl
        else:  # "gap": motor mm moves through the gap; the table ml carries friction Fc_L
            Fm = F - Fv * (mm / M) * vm
            if contact:
                v = vm
                if abs(v) < dv_stick and abs(Fm) <= Fc_L:
                    vm = vl = 0.0
                    if contact * Fm < 0:
                        contact = 0  # the motor pulls back: it leaves the table
                    continue
                ff = math.copysign(Fc_L, v if abs(v) >= dv_stick else Fm)
                fvl = Fv * (ml / M)
                a = (Fm - ff - fvl * v) / M
                normal = Fm - mm * a  # force the motor puts on the table
                if contact * normal < 0:
                    contact = 0
                else:
                    vm += h * a
                    vm = 0.0 if v != 0.0 and vm * v < 0 else vm
                    vl = vm
                    xm += h * vm
                    xl = xm - contact * gap_b
                    continue
            # free flight: motor alone; table decelerated by its own friction
            vm += h * Fm / mm
            xm += h * vm
            if vl != 0.0:
                vl_new = vl - h * (math.copysign(Fc_L, vl) + Fv * (ml / M) * vl) / ml
                vl = 0.0 if vl_new * vl <= 0 else vl_new
                xl += h * vl
            d = xm - xl
            if abs(d) >= gap_b and (vm - vl) * d > 0:
                contact = 1 if d > 0 else -1
                xm = xl + contact * gap_b
                vm = vl = (mm * vm + ml * vl) / M  # plastic impact
    u_meas = u_log + _coloured(rng, n_log, p["noise_u"], p["noise_rho"])
    q_meas = _quantise(q_log, res)
    out = {"q": q_meas, "u": u_meas, "x_motor": xm_log, "x_load": xl_log}
    if closed:
        out["r"] = r_log
    return out


def _drive_params(case: Case, rng: np.random.Generator) -> tuple[dict, dict]:
    """Plant, pipeline and truth of a drive case (all drawn from the case's seed)."""
    s = case.settings
    M = float(rng.uniform(8, 40))
    p: dict[str, Any] = {
        "structure": "rigid",
        "M": M,
        "Fv": float(rng.uniform(20, 150)),
        "offset": float(rng.uniform(-5, 5)),
        "fs_ctrl": s["fs_ctrl"],
        "fs_rec": s["fs_rec"],
        "nsub": s.get("nsub", 1),
        "resolution": s["resolution"],
        "noise_u": s["noise_u"],
        "noise_rho": s.get("noise_rho", 0.0),
    }
    truth: dict[str, float] = {}
    v = case.variant
    # `effect_size` scales the library effect's magnitude (drawn first, so that the
    # random stream and every other parameter stay those of the unscaled plant)
    size = float(s.get("effect_size", 1.0))
    fc = float(rng.uniform(6, 20)) * (size if ("karnopp" in v or "dahl" in v) else 1.0)
    if "karnopp" in v or "dahl" in v:
        p["friction"] = "karnopp" if "karnopp" in v else "dahl"
        p["Fc_pos"] = p["Fc_neg"] = fc
        p["dv_stick"] = 2e-4 * s.get("speed", 0.2)
        # presliding stiffness: the presliding mode resolved by the step (ω h ≤ 0.2)
        h = 1.0 / (math.lcm(int(s["fs_ctrl"]), int(s["fs_rec"])) * p["nsub"])
        p["sigma_dahl"] = min(M * (0.2 / h) ** 2, 2e7)
        truth["Fc"] = fc
    if "asym" in v:
        d = float(rng.uniform(0.3, 0.6)) * fc
        p["Fc_pos"], p["Fc_neg"] = fc + d, fc - d
        truth["Fc_pos"], truth["Fc_neg"] = fc + d, fc - d
        if "karnopp" in v:
            p["dFv_pos"] = float(rng.uniform(0.3, 0.6)) * p["Fv"]
            p["dFv_neg"] = -float(rng.uniform(0.1, 0.3)) * p["Fv"]
    if "stribeck" in v:
        fs_ = fc * float(rng.uniform(1.6, 2.4))
        p["Fs_pos"] = p["Fs_neg"] = fs_
        p["v_stribeck"] = s.get("speed", 0.2) * float(rng.uniform(0.04, 0.1))
        truth["Fs"] = fs_
        truth["v_stribeck"] = p["v_stribeck"]
        if "karnopp" in v:
            p["stribeck_exp"] = float(rng.uniform(0.6, 1.2))
        else:
            p["stribeck_shape"] = "lorentz"
            p["dFv_pos"] = float(rng.uniform(0.2, 0.4)) * p["Fv"]
            p["dFv_neg"] = -float(rng.uniform(0.1, 0.2)) * p["Fv"]
    if "hertz" in v:
        ml = M * float(rng.uniform(0.3, 0.55))
        b = float(rng.uniform(40e-6, 150e-6)) * size
        mu = ml * (M - ml) / M
        f_c = 150.0
        F_typ = 30.0
        k_eff = mu * (2 * math.pi * f_c) ** 2
        p.update(
            structure="two_mass",
            contact="hertz",
            M_load=ml,
            b=b,
            k_c=(k_eff / (1.5 * F_typ ** (1 / 3))) ** 1.5,
            c_c=5.0,  # Hunt–Crossley λ [s/m]: a partly plastic impact
            c_load=0.0,
        )
        truth["gap"] = 2 * b
    if "gapfriction" in v:
        # a light table on guideways with high friction (box ways): its friction
        # decelerates it faster than the axis does, so it stays where the motor leaves it
        ml = M * float(rng.uniform(0.15, 0.25))
        b = float(rng.uniform(60e-6, 200e-6))
        fc = ml * float(rng.uniform(10.0, 15.0))
        p.update(structure="gap", M_load=ml, b=b, Fc_load=fc)
        p["dv_stick"] = 2e-4 * s.get("speed", 0.2)
        truth["gap"] = 2 * b
        truth["Fc"] = fc
    if "noncollocated" in v or "frame" in v:
        f_r = float(rng.uniform(25, 60))
        zeta = float(rng.uniform(0.02, 0.06))
        truth["f_r"] = f_r
        if "noncollocated" in v:
            ml = M * float(rng.uniform(0.4, 0.6))
            mm = M - ml
            # the zero of u/q_load: ω² = k·M/(mm·ml)
            k = (2 * math.pi * f_r) ** 2 * mm * ml / M
            mu = mm * ml / M
            p.update(
                structure="two_mass",
                sensor="load",
                M_load=ml,
                k_c=k,
                c_c=2 * zeta * math.sqrt(k * mu),
                c_load=0.0,
            )
        else:
            mb = M * float(rng.uniform(0.6, 1.5))
            # u/q has its pole at ω² = k_b/(M + m_b) (carriage on a sprung base)
            kb = (2 * math.pi * f_r) ** 2 * (M + mb)
            p.update(structure="frame", M_load=mb, k_c=kb, c_c=2 * zeta * math.sqrt(kb * (M + mb)))
        truth["zeta"] = zeta
    if "transport" in v:
        h = 1.0 / (math.lcm(int(s["fs_ctrl"]), int(s["fs_rec"])) * p["nsub"])
        m = int(rng.integers(int(0.6e-3 / h), int(2.5e-3 / h)))
        p["transport_steps"] = m
        truth["delay"] = m * h
    if "ctrl_delay" in v:
        d = int(rng.integers(2, 4))
        p["ctrl_delay"] = d
        truth["delay"] = d / s["fs_ctrl"]
    if "currentlimit" in v:
        # the limit itself is set from the calibration moves (`_drive_records`)
        p["limit_exceeded"] = float(rng.uniform(0.005, 0.015))
        if "lag" in v:
            p["current_tau"] = float(rng.uniform(0.5e-3, 1e-3))
    return p, truth


def _drive_external(case, rng, n, dt, force_scale):
    """Unmeasured force on the axis as a function of time, or None."""
    v = case.variant
    size = float(case.settings.get("effect_size", 1.0))
    T = n * dt
    if "pulses" in v:
        k = int(rng.integers(3, 6))
        t0s = np.sort(rng.uniform(0.05, 0.9, k)) * T
        width = float(rng.uniform(0.03, 0.06)) * T
        amp = float(rng.uniform(0.4, 0.8)) * size * force_scale * rng.choice([-1, 1], k)
        f_tooth = float(rng.uniform(20, 40)) if dt < 2e-3 else 0.0
        ramp = 0.15 * width

        def ext(t):
            out = 0.0
            for t0, a in zip(t0s, amp):
                if t0 <= t <= t0 + width:
                    e = min((t - t0) / ramp, (t0 + width - t) / ramp, 1.0)
                    out += a * e * (1 + 0.3 * math.sin(2 * math.pi * f_tooth * t))
            return out

        return ext, {"amplitude": float(np.mean(np.abs(amp)))}
    if "gravityload" in v:
        edges = np.sort(rng.uniform(0.05, 0.95, 4)) * T
        amp = float(rng.uniform(0.4, 0.8)) * size * force_scale * float(rng.choice([-1, 1]))
        ramp = 0.02

        def ext(t):
            for a0, a1 in ((edges[0], edges[1]), (edges[2], edges[3])):
                if a0 <= t <= a1:
                    return amp * min((t - a0) / ramp, (a1 - t) / ramp, 1.0)
            return 0.0

        return ext, {"amplitude": abs(amp)}
    return None, {}


def _drive_position(case, rng, amp_travel, force_scale, M):
    v = case.variant
    size = float(case.settings.get("effect_size", 1.0))
    if "cogging" in v:
        pitch = amp_travel * float(rng.uniform(0.25, 0.5))
        a1 = float(rng.uniform(0.25, 0.45)) * size * force_scale
        a2 = 0.35 * a1
        ph1, ph2 = rng.uniform(0, 2 * np.pi, 2)
        k = 2 * math.pi / pitch
        return (
            lambda x: a1 * math.sin(k * x + ph1) + a2 * math.sin(2 * k * x + ph2),
            {"pitch": pitch, "amplitude": a1},
        )
    if "guideway" in v:
        lam = amp_travel * float(rng.uniform(1.5, 2.5))
        th1 = float(rng.uniform(0.3, 0.5)) * size * force_scale / (M * 9.81)
        ks = float(rng.uniform(0.2, 0.4)) * size * force_scale / amp_travel
        k = 2 * math.pi / lam
        return (
            lambda x: -M * 9.81 * math.sin(0.01 + th1 * math.sin(k * x)) - ks * x,
            {"wavelength": lam, "spring": ks},
        )
    return None, {}


def _drive_out_of_library(case, p, speed, amp):
    """An effect in no library of the diagnosis, as `(t, x, v) -> (force [N], mass
    factor, force gain)`; `size` (settings) scales it. Time runs from each record's start
    (each experiment starts cold).

    - `ool-warmup`: viscous friction that falls as the lubricant warms up,
      `Fv (1 + k e^{−t/τ})`, τ = 4 s;
    - `ool-mass`: a moving mass that grows with the position (a telescopic axis),
      `M (1 + β x/A)`, with the momentum term `−M′ v²`;
    - `ool-drag`: fluid drag `−c v|v|` (a sealed axis in oil);
    - `ool-gain`: a motor force constant falling as the winding warms,
      `1 − g (1 − e^{−t/τ})`, τ = 3 s.
    """
    k = float(case.settings["size"])
    M, Fv = p["M"], p["Fv"]
    kind = case.variant
    if kind == "ool-warmup":
        return (lambda t, x, v: (-k * Fv * math.exp(-t / 4.0) * v, 1.0, 1.0)), {"k": k}
    if kind == "ool-mass":
        beta = k
        return (lambda t, x, v: (-M * beta / amp * v * v, 1.0 + beta * x / amp, 1.0)), {
            "beta": beta
        }
    if kind == "ool-drag":
        c = k * Fv / speed
        return (lambda t, x, v: (-c * v * abs(v), 1.0, 1.0)), {"c": c}
    if kind == "ool-gain":
        return (lambda t, x, v: (0.0, 1.0, 1.0 - k * (1.0 - math.exp(-t / 3.0)))), {"g": k}
    raise ValueError(f"unknown out-of-library drive variant {kind!r}")


def _drive_reference(kind, rng, n_ctrl, dtc, amp, t_move):
    if kind == "p2p":
        return _p2p_reference(rng, n_ctrl, dtc, amp, t_move, 0.4 * t_move)
    return _sine_reference(rng, n_ctrl, dtc, amp, 1.0 / (3 * t_move))


def _drive_records(case: Case) -> tuple[list[Record], list[Record], dict]:
    s = case.settings
    rng = np.random.default_rng(case.seed)
    p, truth = _drive_params(case, rng)
    M = p["M"]
    speed = s.get("speed", 0.2)  # typical speed [m/s]
    t_move = s.get("t_move", 0.4)
    amp = speed * t_move  # travel amplitude [m]
    force_scale = M * speed / t_move * 4 + p["Fv"] * speed
    closed = s.get("loop", "closed") == "closed"
    fsc = s["fs_ctrl"]
    # controller: velocity loop bandwidth f_v, PI and P cascade, on a 10 %-off mass
    f_v = min(fsc / 25.0, s.get("f_v", 15.0))
    m_est = M * float(rng.uniform(0.9, 1.1))
    p.update(
        Kv=m_est * 2 * math.pi * f_v,
        Ti=4.0 / (2 * math.pi * f_v),
        Kp=2 * math.pi * f_v / 5.0,
        fv_filter=min(fsc / 4.0, 5 * f_v),
        Kff=m_est if s.get("feedforward") else 0.0,
    )
    posf, ptruth = _drive_position(case, rng, amp, force_scale, M)
    p["position_force"] = posf
    if case.variant.startswith("ool-"):
        p["ool"], otruth = _drive_out_of_library(case, p, speed, amp)
        truth.update(otruth)
    truth.update({f"position_{k}": v for k, v in ptruth.items()})
    roles = (
        ("calibration", s["n_cal"], s.get("ref_cal", "p2p")),
        ("validation", s["n_val"], s.get("ref_val", "sine")),
    )
    refs: dict[str, np.ndarray] = {}
    if "limit_exceeded" in p:
        # the amplifier limit: the force that the moves of each experiment ask for
        # (rigid-body feedforward of the references) on 0.5-1.5 % of their samples, the lower
        # of the two, so that both reach it
        peaks = []
        for role, n_rec, kind in roles:
            dtc = 1.0 / fsc
            r = _drive_reference(
                kind, rng, int(math.ceil(n_rec * fsc / s["fs_rec"])), dtc, amp, t_move
            )
            vr = np.gradient(r, dtc)
            need = np.abs(M * np.gradient(vr, dtc) + p["Fv"] * vr)
            peaks.append(float(np.quantile(need, 1.0 - p["limit_exceeded"])))
            refs[role] = r
        p["force_limit"] = min(peaks)
        truth["F_max"] = p["force_limit"]
    recs = []
    for role, n_rec, kind in roles:
        ratio = fsc / s["fs_rec"]
        n_ctrl = int(math.ceil(n_rec * ratio))
        dtc = 1.0 / fsc
        ext, etruth = _drive_external(case, rng, n_ctrl, dtc, force_scale)
        p["external"] = ext
        if role == "calibration":
            truth.update({f"external_{k}": v for k, v in etruth.items()})
        if closed:
            r = refs[role] if refs else _drive_reference(kind, rng, n_ctrl, dtc, amp, t_move)
            out = simulate_drive(p, r, None, rng)
        else:
            r = _drive_reference(kind, rng, n_ctrl, dtc, amp, t_move)
            vr = np.gradient(r, dtc)
            ar = np.gradient(vr, dtc)
            fc_ff = p.get("Fc_pos", 0.0)
            u = M * ar + p["Fv"] * vr + p["offset"] + fc_ff * np.tanh(vr / (0.05 * speed))
            u = u + _coloured(rng, n_ctrl, 0.15 * force_scale, 0.98)
            out = simulate_drive(p, None, u, rng)
        sig = {k: out[k][:n_rec] for k in ("q", "u", "r") if k in out}
        meta = {
            "source": "blind_plants",
            "case": case.name,
            "role": role,
            "loop": "closed" if closed else "open",
            "encoder_resolution": p["resolution"],
            "controller_rate_hz": float(fsc),
        }
        if closed:
            meta.update(
                Kp=p["Kp"],
                Kv=p["Kv"],
                Ti=p["Ti"],
                Kff=p["Kff"],
                velocity_filter_hz=p["fv_filter"],
            )
        rec = Record(
            sig,
            dt=1.0 / s["fs_rec"],
            units={k: {"q": "m", "u": "N", "r": "m"}[k] for k in sig},
            metadata={**meta, "name": f"{case.name}-{role}"},
        )
        recs.append((rec, out))
    plant = {k: v for k, v in p.items() if isinstance(v, int | float | str)}
    return [recs[0][0]], [recs[1][0]], {"truth": truth, "plant": plant, "raw": recs}


# =================================================================================== tmf
#
# The structure between the encoder-side motion x_e and the tool is a clamped-free beam
# (the ram or spindle head) excited at its root, written as a modal sum (Euler–Bernoulli:
# ω_n ∝ (β_n L)², tip participations φ_n(L)Γ_n of the cantilever):
#
#     x_t = x_e − Σ_n w_n s²/(s² + 2ζ_n ω_n s + ω_n²) x_e  (+ tool receptance · f)
#
# discretised with a first-order hold at 8× the record rate and sampled without an
# anti-alias filter (unless the sensor-delay variant puts one on the tool channel).

_BETA = np.array([1.8751, 4.6941, 7.8548, 10.9955])
_PARTICIPATION = np.array([1.5660, -0.8672, 0.5091, -0.3636])


def _foh_filter(num, den, dt, x):
    b, a, _ = ss.cont2discrete((num, den), dt, method="foh")
    return ss.lfilter(np.ravel(b), a, x)


def tmf_response(x_e: np.ndarray, dt: float, modes: list[tuple[float, float, float]]) -> np.ndarray:
    """Tool-side motion of the root-excited modal structure.

    **Arguments:**

    - `x_e`: encoder-side (root) motion on a fine grid [m].
    - `dt`: fine step [s].
    - `modes`: `(f_n [Hz], ζ_n, w_n)` per mode, `w_n` the tip participation.

    **Returns:** `x_t` [m] on the same grid, starting at rest.
    """
    x = np.asarray(x_e, float)
    out = x.copy()
    for f, z, w in modes:
        om = 2 * np.pi * f
        out -= _foh_filter([w, 0.0, 0.0], [1.0, 2 * z * om, om * om], dt, x - x[0])
    return out


def _tmf_modes(case, rng, y, base):
    """Modes `(f, ζ, w)` of the structure at position `y` [m]."""
    v = case.variant
    f1, zetas, kappa = base["f1"], base["zeta"], base.get("kappa", 0.0)
    n_modes = 3 if "beam3" in v else 2
    scale = 1.0
    if "overhang" in v:
        scale = 1.0 / (1.0 + kappa * y) ** 2  # ω ∝ 1/L², L = L0 (1 + κ y)
    modes = []
    for n in range(n_modes):
        f = f1 * (_BETA[n] / _BETA[0]) ** 2 * scale
        z = zetas[n]
        if "preload" in v and n == 0:
            s_ = math.sin(math.pi * y / 0.6)
            f *= 1 + base["preload_df"] * s_
            z *= 1 + 0.6 * s_
        modes.append((f, z, _PARTICIPATION[n]))
    if "nyquist" in v:
        modes.append((base["f_extra"], 0.02, base["w_extra"]))
    return modes


def _tmf_out_of_library(case, x_e, dt_f, modes):
    """Tool-side motion with the first mode replaced by one outside every library, its
    modal coordinate `η` (`η″ + 2ζω η′ + ω² η = w x_e″`, `x_t = x_e − Σ η`) integrated
    step by step relative to the root motion (classical Runge–Kutta on the 8× grid);
    `size` scales it.

    - `ool-duffing`: a stiffness that grows with the amplitude, `ω² (η + ε η³/η_ref²)`;
    - `ool-drift`: a mode frequency drifting through the record (thermal growth of the
      structure), `ω (1 + δ t/T)`;
    - `ool-joint`: dry friction in a joint of the mode, `μ ω² η_ref sign(η′)` (the sign
      smoothed over 0.1 % of the mode's velocity scale);
    - `ool-sensor`: a tool-side sensor with a cubic calibration error,
      `x_t + c (x_t − x̄)³/s²` (the structure linear).
    `η_ref` is the RMS of the linear mode's coordinate."""
    k = float(case.settings["size"])
    kind = case.variant
    if kind == "ool-sensor":
        x_t = tmf_response(x_e, dt_f, modes)
        d = x_t - x_t.mean()
        return x_t + k * d**3 / float(np.var(d))
    (f, z, w), rest = modes[0], modes[1:]
    om = 2 * np.pi * f
    # in the coordinate ξ = η − w x_e relative to the root motion the mode needs only the
    # root velocity: ξ″ = −2ζω (ξ′ + w x_e′) − k(ξ + w x_e)
    xe = x_e - x_e[0]
    ve = np.gradient(xe, dt_f)
    lin = _foh_filter([w, 0.0, 0.0], [1.0, 2 * z * om, om * om], dt_f, xe)
    eta_ref = float(np.std(lin))
    n = x_e.size
    T = n * dt_f
    eta = np.empty(n)

    def accel(xi, dxi, x, v, t):
        e, de = xi + w * x, dxi + w * v
        if kind == "ool-drift":
            o = om * (1 + k * t / T)
            spring = (o * o) * e
        elif kind == "ool-duffing":
            o = om
            spring = (o * o) * (e + k * e**3 / eta_ref**2)
        elif kind == "ool-joint":
            o = om
            spring = (o * o) * e + k * (om * om) * eta_ref * math.tanh(de / (1e-3 * eta_ref * om))
        else:
            raise ValueError(f"unknown out-of-library tmf variant {kind!r}")
        return -2 * z * o * de - spring

    # classical Runge–Kutta, the root motion interpolated linearly within a step
    xi = dxi = 0.0
    eta[0] = w * xe[0]
    h = dt_f
    for i in range(n - 1):
        t = i * h
        xm, vm = 0.5 * (xe[i] + xe[i + 1]), 0.5 * (ve[i] + ve[i + 1])
        k1x, k1v = dxi, accel(xi, dxi, xe[i], ve[i], t)
        k2x, k2v = dxi + 0.5 * h * k1v, accel(xi + 0.5 * h * k1x, dxi + 0.5 * h * k1v, xm, vm, t)
        k3x, k3v = dxi + 0.5 * h * k2v, accel(xi + 0.5 * h * k2x, dxi + 0.5 * h * k2v, xm, vm, t)
        k4x = dxi + h * k3v
        k4v = accel(xi + h * k3x, dxi + h * k3v, xe[i + 1], ve[i + 1], t + h)
        xi += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        dxi += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        eta[i + 1] = xi + w * xe[i + 1]
    return tmf_response(x_e, dt_f, rest) - eta


def _tmf_excitation(kind, rng, n_fine, dt_f, fs):
    if kind == "noise":
        w = rng.standard_normal(n_fine)
        sos = ss.butter(4, 0.42 * fs, fs=1 / dt_f, output="sos")
        hf = ss.sosfilt(sos, w)
        lf = ss.sosfilt(ss.butter(2, 3.0, fs=1 / dt_f, output="sos"), rng.standard_normal(n_fine))
        x = hf / np.std(hf) * 2e-6 + lf / np.std(lf) * 20e-6
    else:  # repeated logarithmic sweeps plus a slow move
        t = np.arange(n_fine) * dt_f
        T = t[-1] / 3
        x = 3e-6 * ss.chirp(t % T, 2.0, T, 0.42 * fs, method="logarithmic")
        x += 20e-6 * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6.3))
    fade = _smoothstep(np.arange(n_fine) / (0.02 * n_fine))
    return x * fade


def _tmf_records(case: Case) -> tuple[list[Record], list[Record], dict]:
    s = case.settings
    rng = np.random.default_rng(case.seed)  # excitation and noise
    # the plant's parameters from their own stream: a variant never changes the excitation
    rng_p = np.random.default_rng([case.seed, 1])
    fs = float(s["fs"])
    os_ = 8
    dt_f = 1.0 / (fs * os_)
    v = case.variant
    if "beam3" in v:
        f1 = fs * float(rng_p.uniform(0.012, 0.019))
    else:
        f1 = fs * float(rng_p.uniform(0.022, 0.04))
    base: dict[str, Any] = {"f1": f1, "zeta": rng_p.uniform(0.02, 0.05, 4)}
    truth: dict[str, float] = {"f1": f1}
    if "beam3" in v:
        truth["f_r"] = f1 * (_BETA[2] / _BETA[0]) ** 2
    if "nyquist" in v:
        base["f_extra"] = 0.5 * fs * float(rng_p.uniform(0.75, 1.15))
        base["w_extra"] = float(rng_p.uniform(0.2, 0.35)) * float(rng_p.choice([-1, 1]))
        truth["f_r"] = base["f_extra"]
    if "overhang" in v:
        base["kappa"] = float(rng_p.uniform(0.3, 0.6))
        truth["kappa"] = base["kappa"]
    if "preload" in v:
        base["preload_df"] = float(rng_p.uniform(0.12, 0.2))
        truth["preload_df"] = base["preload_df"]
    if "puredelay" in v:
        m = int(rng_p.integers(int(0.6 * os_), int(2.2 * os_)))
        m = max(1, int(round(m * float(s.get("effect_size", 1.0)))))
        truth["delay"] = m * dt_f
    if "bessel" in v:
        tau = float(rng_p.uniform(0.6, 1.8)) / fs
        bz, az = ss.bessel(4, 1.0 / tau, analog=True, norm="delay")
        truth["delay"] = tau  # group delay at low frequency of a delay-normalised Bessel
    noise_rel = s.get("noise", 0.005)
    rho = s.get("noise_rho", 0.0)
    res_e = s.get("resolution", 1e-8)
    force_ratio = float(rng_p.uniform(0.04, 0.08))
    f_tooth = fs * float(rng_p.uniform(0.05, 0.12))
    f_dyn = fs * float(rng_p.uniform(0.3, 0.4))
    with_force_channel = "milling" in v or "dynamometer" in v or s.get("force_channel", False)
    y_mode = s.get("y", "metadata")
    out_recs = []
    for role, ys, kind, n_total in (
        ("calibration", s.get("ys_cal", (0.1, 0.3, 0.5)), "noise", s["n_cal"]),
        ("validation", s.get("ys_val", (0.2, 0.45)), "sweep", s["n_val"]),
    ):
        recs = []
        n = n_total // len(ys)
        n_fine = n * os_ + 4 * os_
        for y in ys:
            x_e = _tmf_excitation(kind, rng, n_fine, dt_f, fs)
            if v.startswith("ool-"):
                x_t = _tmf_out_of_library(case, x_e, dt_f, _tmf_modes(case, rng, y, base))
            else:
                x_t = tmf_response(x_e, dt_f, _tmf_modes(case, rng, y, base))
            f_meas = None
            if with_force_channel:
                t = np.arange(n_fine) * dt_f
                if "dynamometer" in v:
                    imp = (rng.random(n_fine) < 200 * dt_f) * rng.standard_normal(n_fine)
                    f_true = ss.sosfilt(ss.butter(2, 0.3 * fs, fs=1 / dt_f, output="sos"), imp)
                    f_true += 0.3 * np.std(f_true) * np.sin(2 * np.pi * 4.0 * t)
                else:
                    env = (
                        1
                        + 0.5
                        * ss.sosfilt(
                            ss.butter(1, 2.0, fs=1 / dt_f, output="sos"),
                            rng.standard_normal(n_fine),
                        )
                        / 0.02
                    )
                    teeth = np.maximum(np.sin(2 * np.pi * f_tooth * t), 0) ** 2
                    f_true = env * (0.3 + teeth)
                f_true = f_true - f_true[0]
                if "milling" in v or "dynamometer" in v:
                    comp = [(m_[0], m_[1], 1.0) for m_ in _tmf_modes(case, rng, y, base)[:2]]
                    defl = np.zeros(n_fine)
                    for (fm, zm, _), g in zip(comp, (0.75, 0.25)):
                        om = 2 * np.pi * fm
                        defl += _foh_filter(
                            [g * om * om], [1.0, 2 * zm * om, om * om], dt_f, f_true
                        )
                    scale = force_ratio * np.std(x_t) / max(np.std(defl), 1e-300)
                    x_t = x_t + scale * defl
                    truth["compliance"] = scale
                if "dynamometer" in v:
                    om = 2 * np.pi * f_dyn
                    f_meas = 0.9 * _foh_filter([om * om], [1.0, 0.1 * om, om * om], dt_f, f_true)
                else:
                    f_meas = f_true.copy()
                f_meas = f_meas + 0.02 * np.std(f_meas) * rng.standard_normal(n_fine)
            if "puredelay" in v:
                m = int(round(truth["delay"] / dt_f))
                x_t = np.concatenate([np.full(m, x_t[0]), x_t[:-m]])
            if "bessel" in v:
                x_t = x_t[0] + _foh_filter(bz, az, dt_f, x_t - x_t[0])
            sl = slice(4 * os_, None, os_)
            xe_s, xt_s = x_e[sl][:n], x_t[sl][:n]
            xt_s = xt_s + _coloured(rng, n, noise_rel * float(np.std(xt_s)), rho)
            sig = {"x_e": _quantise(xe_s, res_e), "x_t": xt_s}
            meta: dict[str, Any] = {"source": "blind_plants", "case": case.name, "role": role}
            if y_mode == "column":
                sig["y"] = np.full(n, y)
            elif y_mode == "metadata":
                meta["y"] = float(y)
            if f_meas is not None:
                sig["f"] = f_meas[sl][:n]
            meta["name"] = f"{case.name}-{role}-y{y:.2f}"
            recs.append(Record(sig, dt=1 / fs, metadata=meta))
        out_recs.append(recs)
    return out_recs[0], out_recs[1], {"truth": truth, "plant": {"fs": fs, "f1": f1}}


# =============================================================================== thermal
#
# A lumped thermal network of a motor spindle: chassis node (motor losses, cooled by the
# air and the water jacket) and the bearing node (friction heat Q_b, coupled to the
# chassis); each capacity-free node is given a 0.05 s time constant (static at the record's
# sampling); a linear network with inputs held over the step is advanced by the exact
# matrix exponential (Van Loan's augmented matrix).


def thermal_step_matrices(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation `x_{k+1} = Ad x_k + Bd u_k` of `x' = A x + B u` with `u` held."""
    n, m = B.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = A
    aug[:n, n:] = B
    e = sla.expm(aug * h)
    return e[:n, :n], e[:n, n:]


def _ou(rng, n, dt, sigma, tau):
    a = math.exp(-dt / tau)
    return _coloured(rng, n, sigma, a)


def _speed_profile(rng, n, dt, vmax, dwell_s):
    levels = vmax * np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    v = np.empty(n)
    k, last = 0, -1
    while k < n:
        i = int(rng.integers(0, levels.size))
        if i == last:
            i = (i + 2) % levels.size
        last = i
        d = int(dwell_s * rng.uniform(0.6, 1.4) / dt)
        v[k : k + d] = levels[i]
        k += d
    return v


def _chiller(rng, n, dt, t_air):
    """Cooling water of an on/off chiller with a hysteresis of ±0.5–1 K around a set point
    that follows the hall temperature."""
    tw = np.empty(n)
    band = float(rng.uniform(0.5, 1.0))
    T, on = 19.0, False
    heat = float(rng.uniform(1.0, 2.0)) / 600  # K/s while the chiller is off
    cool = float(rng.uniform(2.5, 4.0)) / 600
    for k in range(n):
        sp = 19.0 + 0.3 * (t_air[k] - 21.0)
        if T > sp + band:
            on = True
        elif T < sp - band:
            on = False
        T += dt * (heat - (cool if on else 0.0))
        tw[k] = T
    return tw


def _thermal_out_of_library(case, rng, t, x, T_ch, noise):
    """What an effect in no library adds to the measured bearing temperature [K]; its RMS
    is `size` times the sensor noise.

    - `ool-drift`: a thermocouple drifting quadratically through the record;
    - `ool-step`: the sensor re-seated: an offset step at a random time of each record;
    - `ool-interaction`: bearing heat from the preload, which grows with the chassis
      temperature at speed: `∝ (v/v_max)·(T_chassis − mean)`;
    - `ool-neighbour`: an unmeasured neighbouring unit switching on and off (2 h
      cycle, 40 % on), seen through a 20 min lag."""
    k = float(case.settings["size"])
    kind = case.variant
    T = t[-1] - t[0]
    if kind == "ool-drift":
        add = ((t - t[0]) / T) ** 2
    elif kind == "ool-step":
        add = (t >= t[0] + T * float(rng.uniform(0.3, 0.7))).astype(float)
    elif kind == "ool-interaction":
        add = x * (T_ch - T_ch.mean())
    elif kind == "ool-neighbour":
        on = (((t - t[0]) / 7200.0 + float(rng.uniform(0, 1))) % 1.0 < 0.4).astype(float)
        dt = t[1] - t[0]
        add = ss.lfilter([1 - math.exp(-dt / 1200.0)], [1, -math.exp(-dt / 1200.0)], on)
    else:
        raise ValueError(f"unknown out-of-library thermal variant {kind!r}")
    add = add - add.mean()
    return k * noise * add / max(float(np.std(add)), 1e-300)


def _thermal_records(case: Case) -> tuple[list[Record], list[Record], dict]:
    s = case.settings
    rng = np.random.default_rng(case.seed)
    v = case.variant
    dt_rec = float(s["dt"])
    dt_sim = min(dt_rec, 5.0)
    ndec = int(round(dt_rec / dt_sim))
    vmax = float(rng.choice([8000.0, 12000.0, 18000.0]))
    G_ca, G_cw = float(rng.uniform(15, 30)), float(rng.uniform(20, 50))
    tau_ch = float(rng.uniform(40, 80)) * 60
    C_ch = tau_ch * (G_ca + G_cw)
    q_m = float(rng.uniform(300, 800))
    q_b0, q_b1 = float(rng.uniform(5, 20)), float(rng.uniform(60, 150))
    G_bc = float(rng.uniform(10, 25))
    G_ba = float(rng.uniform(0.3, 0.7)) * G_bc if "air_conductance" in v else 0.0
    G_bw = (
        float(rng.uniform(0.3, 0.7)) * G_bc
        if "water_conductance" in v or "coolant_delay" in v
        else 0.0
    )
    kappa = float(rng.uniform(0.15, 0.3)) if "air_sensor" in v else 0.0
    tau_w = float(rng.uniform(60, 240)) if "coolant_delay" in v else 0.0
    tau_b = float(rng.uniform(10, 30)) * 60 if "firstorder" in v else 0.05
    two_node = "twonode" in v
    alpha = float(rng.uniform(1.6, 2.2)) if "powerlaw" in v else 1.0
    size = float(s.get("effect_size", 1.0))
    q2 = float(rng.uniform(1.5, 3.0)) * size * q_b1 if "quadratic" in v else 0.0
    gamma = 0.3 * size if "quadratic" in v else 0.0
    truth: dict[str, float] = {}
    if "firstorder" in v:
        truth["tau"] = tau_b
    if "powerlaw" in v:
        truth["alpha"] = alpha
    if "quadratic" in v:
        truth["q2_over_q1"] = q2 / q_b1
    if "air_conductance" in v:
        truth["c_air"] = G_ba / (G_bc + G_ba + G_bw)
    if "air_sensor" in v:
        truth["c_air"] = kappa
    if G_bw:
        truth["c_water"] = G_bw / (G_bc + G_ba + G_bw)
    if tau_w:
        truth["coolant_delay"] = tau_w

    # nodes: chassis, bearing[, shaft]; boundary inputs u = [Q_m, Q_b, T_air, T_water]
    def matrices(x):
        gbc = G_bc * (1 + gamma * x**0.8)
        if two_node:
            tau1 = float(rng_nodes[0]) * 60
            tau2 = float(rng_nodes[1]) * 60
            g1 = 2 * gbc
            g2 = 2 * gbc  # series: total bearing→chassis conductance gbc
            C1, C2 = tau1 * g1, tau2 * g2
            A = np.array(
                [
                    [-(G_ca + G_cw + g2) / C_ch, 0.0, g2 / C_ch],
                    [0.0, -(g1 + G_ba + G_bw) / C1, g1 / C1],
                    [g2 / C2, g1 / C2, -(g1 + g2) / C2],
                ]
            )
            B = np.array(
                [
                    [1 / C_ch, 0, G_ca / C_ch, G_cw / C_ch],
                    [0, 1 / C1, G_ba / C1, G_bw / C1],
                    [0, 0, 0, 0],
                ]
            )
        else:
            Cb = tau_b * (gbc + G_ba + G_bw)
            A = np.array(
                [
                    [-(G_ca + G_cw + gbc) / C_ch, gbc / C_ch],
                    [gbc / Cb, -(gbc + G_ba + G_bw) / Cb],
                ]
            )
            B = np.array(
                [[1 / C_ch, 0, G_ca / C_ch, G_cw / C_ch], [0, 1 / Cb, G_ba / Cb, G_bw / Cb]]
            )
        return thermal_step_matrices(A, B, dt_sim)

    rng_nodes = rng.uniform([3, 12], [8, 25])
    if two_node:
        truth["tau"] = float(rng_nodes[1]) * 60  # the slow node dominates
    noise = s.get("noise", 0.03)
    rho = s.get("noise_rho", 0.0)
    quant = s.get("quantisation", 0.0)
    signals = s.get("signals", ("v_m", "T_air", "T_water"))
    recs = []
    cache: dict[float, tuple] = {}
    for role, hours in (("calibration", s["hours_cal"]), ("validation", s["hours_val"])):
        n = int(hours * 3600 / dt_sim)
        n_rec = n // ndec
        speed = _speed_profile(rng, n, dt_sim, vmax, s.get("dwell_s", 3600.0))
        t = np.arange(n) * dt_sim
        t_air = (
            21
            + 2.0 * np.sin(2 * np.pi * t / 86400 + rng.uniform(0, 6.3))
            + _ou(rng, n, dt_sim, 0.6, 5400.0)
        )
        t_w = _chiller(rng, n, dt_sim, t_air)
        m = int(round(tau_w / dt_sim))
        t_w_eff = np.concatenate([np.full(m, t_w[0]), t_w[: n - m]]) if m else t_w
        x = speed / vmax
        Qm = q_m * x**1.3
        Qb = q_b0 + q_b1 * x**alpha + q2 * x * x
        nn = 3 if two_node else 2
        # start from the steady state of the first inputs
        Ad, Bd = cache.setdefault(float(x[0]), matrices(float(x[0])))
        u0 = np.array([Qm[0], Qb[0], t_air[0], t_w_eff[0]])
        X = np.linalg.solve(np.eye(nn) - Ad, Bd @ u0)
        T_ch = np.empty(n)
        T_b = np.empty(n)
        for k in range(n):
            # sample k is taken at the end of the step over which speed[k] was held
            key = float(x[k])
            if key not in cache:
                cache[key] = matrices(key)
            Ad, Bd = cache[key]
            X = Ad @ X + Bd @ np.array([Qm[k], Qb[k], t_air[k], t_w_eff[k]])
            T_ch[k], T_b[k] = X[0], X[1]
        T_meas = T_b + kappa * (t_air - T_b)
        if v.startswith("ool-"):
            T_meas = T_meas + _thermal_out_of_library(case, rng, t, x, T_ch, noise)
        sl = slice(0, n_rec * ndec, ndec)

        def sensor(y):
            y = y[sl] + _coloured(rng, n_rec, noise, rho)
            return _quantise(y, quant)

        sig = {"T_chassis": sensor(T_ch), "T_bearing": sensor(T_meas)}
        if "v_m" in signals:
            sig["v_m"] = speed[sl]
        if "T_air" in signals:
            sig["T_air"] = sensor(t_air)
        if "T_water" in signals:
            sig["T_water"] = sensor(t_w)
        meta = {"source": "blind_plants", "case": case.name, "role": role}
        meta["name"] = f"{case.name}-{role}"
        recs.append(Record(sig, dt=dt_rec, metadata=meta))
    plant = {"G_bc": G_bc, "q_b0": q_b0, "q_b1": q_b1, "vmax": vmax, "tau_ch": tau_ch}
    return [recs[0]], [recs[1]], {"truth": truth, "plant": plant}


# ================================================================================= cases


def _d(name, effects, variant, primary=None, alt=(), **settings):
    base = dict(resolution=1e-6, noise_u=0.5, n_cal=12000, n_val=6000)
    effects = tuple(effects)
    if primary is None and effects:
        primary = effects[0]
    return Case(f"drive-{name}", "drive", effects, primary, variant, {**base, **settings}, alt)


def _t(name, effects, variant, primary=None, alt=(), **settings):
    base = dict(n_cal=12000, n_val=6000, noise=0.005)
    effects = tuple(effects)
    if primary is None and effects:
        primary = effects[0]
    return Case(f"tmf-{name}", "tmf", effects, primary, variant, {**base, **settings}, alt)


def _h(name, effects, variant, primary=None, alt=(), **settings):
    base = dict(dt=10.0, hours_cal=24.0, hours_val=10.0, noise=0.03, dwell_s=3600.0)
    effects = tuple(effects)
    if primary is None and effects:
        primary = effects[0]
    return Case(f"thermal-{name}", "thermal", effects, primary, variant, {**base, **settings}, alt)


CF, AF, SF, BL = "coulomb_friction", "asymmetric_friction", "stribeck_friction", "backlash"
RS, TD, EF, PD = "resonance", "time_delay", "external_force", "position_dependence"
SA = "saturation"
MM, SD, PF = "missing_mode", "sensor_delay", "process_force"
DY, AT, CT, SN = "dynamics", "ambient_temperature", "coolant_temperature", "speed_nonlinearity"


def cases() -> list[Case]:
    """The deterministic list of blind cases (56: 16 effect-free)."""
    robot = dict(fs_rec=10, fs_ctrl=200, resolution=2e-5, speed=0.05, t_move=4.0)
    robot.update(n_cal=3000, n_val=1500, noise_u=0.3)
    drive = [
        _d("coulomb-karnopp", [CF], "karnopp", fs_rec=1000, fs_ctrl=1000, effect_size=0.5),
        _d(
            "coulomb-dahl",
            [CF],
            "dahl",
            fs_rec=4000,
            fs_ctrl=2000,
            resolution=1e-7,
            noise_u=1.0,
            noise_rho=0.9,
            n_cal=16000,
            n_val=8000,
        ),
        _d(
            "asym-karnopp",
            [AF],
            "karnopp-asym",
            effect_size=0.35,
            fs_rec=500,
            fs_ctrl=500,
            resolution=5e-6,
            noise_u=0.3,
            n_cal=10000,
            n_val=5000,
        ),
        _d(
            "asym-dahl",
            [AF],
            "dahl-asym",
            fs_rec=2000,
            fs_ctrl=2000,
            noise_u=2.0,
            noise_rho=0.95,
            n_cal=14000,
            n_val=7000,
        ),
        _d(
            "stribeck-karnopp",
            [SF],
            "karnopp-stribeck",
            fs_rec=1000,
            fs_ctrl=1000,
            speed=0.15,
            effect_size=0.4,
        ),
        _d(
            "stribeck-dahl-lorentz",
            [SF],
            "dahl-stribeck",
            fs_rec=250,
            fs_ctrl=1000,
            resolution=2e-6,
            n_cal=8000,
            n_val=4000,
        ),
        _d(
            "backlash-hertz",
            [BL],
            "hertz",
            fs_rec=2000,
            fs_ctrl=2000,
            nsub=4,
            resolution=1e-7,
            n_cal=14000,
            n_val=7000,
        ),
        _d(
            "backlash-hertz-small",
            [BL],
            "hertz",
            effect_size=0.1,
            fs_rec=2000,
            fs_ctrl=2000,
            nsub=4,
            resolution=1e-7,
            noise_rho=0.9,
            n_cal=14000,
            n_val=7000,
        ),
        _d(
            "backlash-friction-loaded",
            [BL, CF],
            "gapfriction",
            alt=(CF,),
            fs_rec=1000,
            fs_ctrl=1000,
            nsub=4,
            noise_u=1.0,
        ),
        _d(
            "resonance-load-encoder",
            [RS],
            "noncollocated",
            fs_rec=2000,
            fs_ctrl=2000,
            nsub=2,
            f_v=6.0,
            resolution=1e-7,
            n_cal=14000,
            n_val=7000,
        ),
        _d(
            "resonance-frame",
            [RS],
            "frame",
            fs_rec=5000,
            fs_ctrl=5000,
            f_v=8.0,
            resolution=1e-7,
            noise_u=1.0,
            noise_rho=0.8,
            n_cal=16000,
            n_val=8000,
        ),
        _d(
            "delay-transport",
            [TD],
            "transport",
            fs_rec=2000,
            fs_ctrl=2000,
            nsub=4,
            n_cal=14000,
            n_val=7000,
        ),
        _d(
            "delay-controller",
            [TD],
            "ctrl_delay",
            fs_rec=4000,
            fs_ctrl=1000,
            noise_rho=0.9,
            n_cal=16000,
            n_val=8000,
        ),
        _d("external-pulses", [EF], "pulses", fs_rec=1000, fs_ctrl=1000),
        _d(
            "external-gravity-load",
            [EF],
            "gravityload",
            effect_size=0.3,
            fs_rec=1000,
            fs_ctrl=1000,
            resolution=5e-6,
            noise_u=1.0,
        ),
        _d(
            "position-cogging",
            [PD],
            "cogging",
            loop="open",
            fs_rec=2000,
            fs_ctrl=2000,
            noise_rho=0.9,
            n_cal=14000,
            n_val=7000,
        ),
        _d("position-guideway-10hz", [PD], "guideway", effect_size=4.0, **robot),
        _d(
            "two-coulomb-delay",
            [CF, TD],
            "karnopp-transport",
            alt=(TD,),
            fs_rec=2000,
            fs_ctrl=2000,
            nsub=4,
            n_cal=14000,
            n_val=7000,
        ),
        _d("two-coulomb-cogging", [CF, PD], "dahl-cogging", alt=(PD,), fs_rec=1000, fs_ctrl=1000),
        _d("two-pulses-delay", [EF, TD], "pulses-ctrl_delay", alt=(TD,), fs_rec=1000, fs_ctrl=1000),
        _d(
            "saturation-current-limit",
            [SA],
            "currentlimit",
            fs_rec=1000,
            fs_ctrl=2000,
            ref_val="p2p",
        ),
        _d(
            "saturation-slow-amplifier",
            [SA],
            "currentlimit-lag",
            ref_val="p2p",
            fs_rec=2000,
            fs_ctrl=2000,
            nsub=2,
            noise_rho=0.9,
            n_cal=14000,
            n_val=7000,
        ),
        _d("free-1khz", [], "none", fs_rec=1000, fs_ctrl=1000),
        # the current-limit case without its limit (same settings, its own seed)
        _d("free-current-limit-twin", [], "none", fs_rec=1000, fs_ctrl=2000, ref_val="p2p"),
        _d(
            "free-10khz-held",
            [],
            "none",
            fs_rec=10000,
            fs_ctrl=2500,
            resolution=1e-7,
            noise_u=1.0,
            noise_rho=0.95,
            n_cal=16000,
            n_val=8000,
            speed=0.3,
            t_move=0.25,
        ),
        _d("free-robot-10hz", [], "none", **robot),
        _d("free-open-loop", [], "none", loop="open", fs_rec=2000, fs_ctrl=2000),
        _d(
            "free-500hz-ff",
            [],
            "none",
            fs_rec=500,
            fs_ctrl=500,
            resolution=5e-6,
            feedforward=True,
            noise_u=0.3,
            noise_rho=0.9,
            n_cal=10000,
            n_val=5000,
        ),
        _d(
            "free-4khz-1khz-ctrl",
            [],
            "none",
            fs_rec=4000,
            fs_ctrl=1000,
            resolution=2e-6,
            noise_u=0.2,
            n_cal=16000,
            n_val=8000,
        ),
        _d(
            "free-250hz-sine",
            [],
            "none",
            fs_rec=250,
            fs_ctrl=250,
            ref_cal="sine",
            ref_val="p2p",
            noise_u=1.0,
            n_cal=8000,
            n_val=4000,
        ),
    ]
    tmf = [
        _t("position-overhang", [PD], "overhang", fs=2000),
        _t(
            "position-preload",
            [PD],
            "preload",
            fs=5000,
            noise_rho=0.8,
            y="column",
            ys_cal=(0.05, 0.2, 0.35, 0.5, 0.6),
            ys_val=(0.15, 0.3, 0.45),
            n_cal=15000,
            n_val=9000,
        ),
        _t("mode-beam3", [MM], "beam3", fs=1000, noise_rho=0.8),
        _t("mode-near-nyquist", [MM], "nyquist", fs=2000),
        _t("delay-pure", [SD], "puredelay", fs=5000, n_cal=15000, n_val=8000, effect_size=3.0),
        _t("delay-antialias", [SD], "bessel", fs=10000, n_cal=16000, n_val=8000),
        _t("force-milling", [PF], "milling", fs=2000),
        _t(
            "force-dynamometer",
            [PF],
            "dynamometer",
            fs=5000,
            n_cal=15000,
            n_val=8000,
            noise_rho=0.8,
        ),
        _t("two-delay-force", [SD, PF], "puredelay-milling", alt=(PF,), fs=2000),
        _t("free-1khz", [], "none", fs=1000),
        _t(
            "free-5khz-force-channel",
            [],
            "none",
            fs=5000,
            y="column",
            force_channel=True,
            noise_rho=0.9,
            n_cal=15000,
            n_val=8000,
        ),
        _t(
            "free-10khz-no-y",
            [],
            "none",
            fs=10000,
            y="none",
            resolution=5e-8,
            n_cal=16000,
            n_val=8000,
        ),
        _t("free-2khz-noisy", [], "none", fs=2000, noise=0.02, noise_rho=0.8),
    ]
    thermal = [
        _h("dynamics-first-order", [DY], "firstorder", dt=5.0, hours_cal=12.0, hours_val=6.0),
        _h("dynamics-two-node", [DY], "twonode"),
        _h("ambient-conductance", [AT], "air_conductance", dt=30.0, hours_cal=48.0, hours_val=24.0),
        _h(
            "ambient-sensor",
            [AT],
            "air_sensor",
            noise_rho=0.9,
            dt=1.0,
            hours_cal=4.0,
            hours_val=2.0,
            dwell_s=1200.0,
        ),
        _h("coolant-conductance", [CT], "water_conductance"),
        _h(
            "coolant-delay",
            [CT],
            "coolant_delay",
            dt=5.0,
            hours_cal=12.0,
            hours_val=6.0,
            noise_rho=0.8,
        ),
        _h("speed-powerlaw", [SN], "powerlaw"),
        _h(
            "speed-quadratic-convection",
            [SN],
            "quadratic",
            dt=30.0,
            hours_cal=48.0,
            hours_val=24.0,
            effect_size=0.4,
        ),
        _h("two-dynamics-speed", [DY, SN], "firstorder-powerlaw", alt=(SN,)),
        _h("free-5s", [], "none", dt=5.0, hours_cal=12.0, hours_val=6.0),
        _h(
            "free-30s-quantised",
            [],
            "none",
            dt=30.0,
            hours_cal=48.0,
            hours_val=24.0,
            quantisation=0.1,
        ),
        _h(
            "free-1s-coloured",
            [],
            "none",
            dt=1.0,
            hours_cal=4.0,
            hours_val=2.0,
            dwell_s=1200.0,
            noise=0.05,
            noise_rho=0.95,
        ),
        _h("free-10s-no-air-water", [], "none", noise=0.08, signals=("v_m",)),
    ]
    return drive + tmf + thermal


# effects in no library of the diagnosis (`Case.effects` holds their own names, prefixed
# "ool:"): no library name may be given; the verdict is `unexplained`
OUT_OF_LIBRARY = {
    "drive": ("warmup", "mass", "drag", "gain"),
    "tmf": ("duffing", "drift", "joint", "sensor"),
    "thermal": ("drift", "step", "interaction", "neighbour"),
}
# two sizes of each (drive: the effect's force relative to the friction/drag it acts
# through; tmf: nonlinearity / drift level; thermal: RMS in noise units)
OOL_SIZES = {
    "drive": {"warmup": (0.3, 1.0), "mass": (0.1, 0.3), "drag": (0.2, 0.6), "gain": (0.05, 0.15)},
    "tmf": {
        "duffing": (0.3, 1.0),
        "drift": (0.02, 0.06),
        "joint": (0.03, 0.1),
        "sensor": (0.03, 0.1),
    },
    "thermal": {
        "drift": (3.0, 10.0),
        "step": (3.0, 10.0),
        "interaction": (3.0, 10.0),
        "neighbour": (3.0, 10.0),
    },
}


def all_cases() -> list[Case]:
    """The library cases (`cases()`) followed by the out-of-library ones."""
    return cases() + out_of_library()


def out_of_library() -> list[Case]:
    """The out-of-library cases: 4 effects per family, each at a small and a large size."""
    out = []
    make = {"drive": _d, "tmf": _t, "thermal": _h}
    base = {
        "drive": dict(fs_rec=1000, fs_ctrl=1000),
        "tmf": dict(fs=2000),
        "thermal": dict(dt=10.0, hours_cal=12.0, hours_val=6.0, dwell_s=1800.0),
    }
    for fam, kinds in OUT_OF_LIBRARY.items():
        for kind in kinds:
            for label, size in zip(("small", "large"), OOL_SIZES[fam][kind]):
                c = make[fam](f"ool-{kind}-{label}", [], f"ool-{kind}", size=size, **base[fam])
                out.append(dataclasses.replace(c, effects=(f"ool:{kind}",), primary=None))
    return out


def select(all_cases: list[Case], n: int | None = None, family: str | None = None) -> list[Case]:
    """A deterministic, representative subset: per family, effect-free and effect cases
    interleaved (every fourth case effect-free while any remain), the effect cases taking
    each primary effect in turn (first variant A of every effect, then variant B, then
    two-effect cases), families round-robin. `n=None` keeps all."""
    fams = [family] if family else ["drive", "tmf", "thermal"]
    queues = []
    for f in fams:
        free = [c for c in all_cases if c.family == f and c.effect_free]
        single = [c for c in all_cases if c.family == f and len(c.effects) == 1]
        groups: dict[str, list[Case]] = {}
        for c in single:
            groups.setdefault(c.primary, []).append(c)
        eff = []
        while any(groups.values()):
            for g in groups.values():
                if g:
                    eff.append(g.pop(0))
        eff += [c for c in all_cases if c.family == f and len(c.effects) > 1]
        q = []
        while free or eff:
            if free and (len(q) % 4 == 0 or not eff):
                q.append(free.pop(0))
            else:
                q.append(eff.pop(0))
        queues.append(q)
    out = []
    while any(queues):
        for q in queues:
            if q:
                out.append(q.pop(0))
    return out if n is None else out[:n]


_GENERATORS: dict[str, Callable] = {
    "drive": _drive_records,
    "tmf": _tmf_records,
    "thermal": _thermal_records,
}


def generate(case: Case) -> tuple[list[Record], list[Record], dict]:
    """Calibration and validation records of a case (validation with a different
    excitation from the same plant) and `info` with `truth` (true parameters: `delay` [s],
    `gap` [m], `f_r` [Hz], `Fc` [N], ...) and `plant`. Deterministic in the case's seed."""
    if case.family not in _GENERATORS:
        raise ValueError(f"unknown family {case.family!r}; choose drive, tmf or thermal.")
    cal, val, info = _GENERATORS[case.family](case)
    info["truth"] = {k: float(v) for k, v in info["truth"].items()}
    return cal, val, info


def write_case(case: Case, folder) -> list[str]:
    """Write a case for the CLI (`jaxvs diagnose cal*.npz --validate val*.npz`): one `.npz`
    per record (a tmf position kept in the metadata becomes a constant `y` column) and
    `truth.json` (effects, primary, true parameters, seed). Returns the files written."""
    import json
    import pathlib

    from jaxvs.data import save_npz

    out = pathlib.Path(folder) / case.name
    out.mkdir(parents=True, exist_ok=True)
    cal, val, info = generate(case)
    files = []
    for role, recs in (("cal", cal), ("val", val)):
        for i, rec in enumerate(recs):
            if "y" in rec.metadata and "y" not in rec.names:
                sig = {k: np.asarray(rec[k]) for k in rec.names}
                sig["y"] = np.full(len(rec), float(rec.metadata["y"]))
                rec = Record(sig, dt=rec.dt, metadata=rec.metadata)
            files.append(str(save_npz(rec, out / f"{role}{i + 1}.npz")))
    truth = {
        "case": case.name,
        "family": case.family,
        "variant": case.variant,
        "seed": case.seed,
        "effects": list(case.effects),
        "primary": case.primary,
        "primary_alternatives": list(case.primary_alternatives),
        "truth": info["truth"],
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return files


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(description="List (and time) the blind cases, or write them.")
    p.add_argument("--write", default=None, help="folder: write every case as .npz files")
    p.add_argument("--only", default=None, help="comma-separated case names")
    args = p.parse_args(argv)
    chosen = all_cases()
    if args.only:
        names = set(args.only.split(","))
        unknown = names - {c.name for c in chosen}
        if unknown:
            raise SystemExit(f"unknown case(s) {sorted(unknown)}")
        chosen = [c for c in chosen if c.name in names]
    n_free = sum(c.effect_free for c in chosen)
    print(f"{len(chosen)} cases, {n_free} effect-free ({100 * n_free / len(chosen):.0f} %)")
    if args.write:
        for c in chosen:
            print(c.name, len(write_case(c, args.write)), "files")
        return 0
    for c in chosen:
        t0 = time.perf_counter()
        cal, val, info = generate(c)
        dt = time.perf_counter() - t0
        n = sum(len(r) for r in cal + val)
        print(
            f"{c.name:34s} {','.join(c.effects) or 'none':42s} {n:6d} samples "
            f"{dt:5.2f} s  {info['truth']}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
