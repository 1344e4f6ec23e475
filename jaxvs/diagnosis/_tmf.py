"""The `tmf` family: one position-independent transmissibility from the encoder to the tool
centre point, and its candidate effects.

Nominal model (the TMF study, Doerrer et al. 2022, eq. 8; `jaxvs.models.StableTMF`): the
tool-side motion is the encoder-side motion through one rational TMF of equal numerator
and denominator order `order` (option, default 4),

    x_t = T(s) x_e,   T(s) = B(s) / A(s),   A(s) = Π_k (s² + 2 ζ_k ω_k s + ω_k²) [· (s + p)],

simulated from rest with the zero-order-hold discretisation (`jaxvs.simulate(...,
method="zoh")`). The denominator is stored as second-order sections with `log ω`, `log ζ`
(and `log p` for an odd order), so every iterate of the calibration is stable; all
coefficients live in the frequency scale `s / w0` for conditioning. The model is initialised
by `jaxvs.fit_rational` on the H1 transmissibility estimate over the band where the
coherence is high. Each experiment is taken relative to its first sample (the machine is
assumed at rest there).

Each candidate effect is a differentiable augmentation that equals the nominal model when
its size (or delay) is zero:

Augmentations of the predicted `x_t`:

- `position_dependence`: every parameter of the modal TMF (numerator `B`, `log ω`, `log ζ`)
  moved by `x·slope + x²·curvature` in the other axis' position, `x = (y − ȳ)/h` (the
  curvature with three positions or more); `size = (slopes, curvatures)`.
- `missing_mode`: `+ (r₁ ω s + r₀ ω²) / (s² + 2ζωs + ω²) · x_e`, a mode in parallel,
  `size = (r₀, r₁)`; `ω` seeded at the peaks of the residual spectrum.
- `sensor_delay`: the prediction delayed by `τ` (`x_t` recorded late), fractional by a
  band-limited (FFT phase) shift.
- `process_force`: `+ g · N(σ) / A(σ) · f`, the compliance between the measured process
  force and the tool relative to the encoder, with the structure's own poles (those of
  the nominal TMF, `A`) and a free numerator, `size = N`.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.signal as ss
from jaxtyping import Array, Float

from ..calibration import fit_rational, fixed, unwrap
from ..data import Record
from ..models import RationalTF, StableTMF, partial_fractions, section_poles, simulate_modal
from ..signal import find_period, period_noise, transmissibility
from ._base import (
    AbstractAdditiveEffect,
    AbstractEffect,
    AbstractFamily,
    AdmissibilityContext,
    Context,
    EffectSpec,
    Experiment,
    GapModel,
    NotIdentifiable,
    check,
    delay_rules,
    exact_zero_at,
    fft_delay,
    floored_positive as _positive,
    predict,
    scalar as _f,
)
from ._stats import quantisation_step

__all__ = ["StableTMF", "TMFFamily"]


# ------------------------------------------------------------------------------ effects


def _position_layout(n_size: int) -> tuple[int, int, int]:
    """`(order + 1, sections, odd poles)` of the TMF behind a position effect's `size`
    of `n_size` entries: `2 order + 1` slopes (every `flat()` parameter), then as many
    curvatures."""
    order, rest = divmod(n_size // 2 - 1, 2)
    if n_size % 2 or rest or order < 1:
        raise ValueError(f"position effect: {n_size} sizes fit no TMF order")
    return order + 1, order // 2, order % 2


class TMFPositionEffect(AbstractAdditiveEffect):
    """TMF parameters that change with the other axis' position `y`: the numerator
    `B(σ)`, the log natural frequencies, log damping ratios (and the log real pole) of
    the nominal TMF move by `x · slope + x² · curvature`, `x = (y − ȳ)/h` with `ȳ`, `h`
    the centre and half-range of the calibration positions. A fixed `offset` (never
    calibrated) moves the nominal TMF to the centre TMF of the start: where the modes
    move by more than their bandwidth over the travel, the nominal model fitted to all
    positions at once is a blur (one broad mode where each position has a sharp one),
    and a slope alone cannot make every position sharp again; the nominal parameters
    stay calibrated, so the offset only chooses where the joint calibration starts and
    adds no degree of freedom.

    The modal form keeps the TMF stable at every position and every iterate (no root
    of a moved polynomial can cross the imaginary axis); a mode frequency that changes
    by a share per unit travel (a stiffness or an overhang length changing with the
    position, `ω ∝ √(k/m)`) is linear in `log ω` to first order, and the curvature
    holds a change that is not monotonic over the travel (a preload or a guide whose
    stiffness peaks mid-travel) and the numerator's, which moves with the modes'
    frequencies and residues nonlinearly (a slope alone leaves the far positions worse
    than the nominal model). With two positions the curvature is not identified
    (`x² = 1` at both: an extrapolation would amplify whatever it took from the
    nominal model), so it acts only with three positions or more (`curved`).
    """

    name: ClassVar[str] = "position_dependence"
    order: ClassVar[int] = 0
    # (ΔB (order + 1), Δlog ω, Δlog ζ, Δlog p) per half-range, then the same curvatures
    # per squared half-range
    size: Float[Array, " p"]
    centre: Any  # ȳ [m]; never calibrated
    half_range: Any  # h [m]; never calibrated
    curved: bool = eqx.field(static=True, default=True)  # three positions or more
    # change of the nominal's `flat()` parameters at the centre; never calibrated
    offset: Any = None

    def __post_init__(self):
        if self.offset is None:
            n1, ns, no = _position_layout(int(self.size.shape[0]))
            object.__setattr__(self, "offset", jnp.zeros((n1 + 2 * ns + no,), self.size.dtype))

    def constrained(self):
        return eqx.tree_at(lambda e: (e.centre, e.half_range, e.offset), self, replace_fn=fixed)

    def delta(self, x: Any) -> Array:
        """The change of the nominal TMF's `flat()` parameters at `x` (half-ranges)."""
        p = int(self.size.shape[0]) // 2
        lin, curv = self.size[:p], self.size[p:]
        if not self.curved:
            return self.offset + x * lin
        return self.offset + x * lin + x * x * curv

    def contribution(self, d, nominal):
        x = (d["pos_y"][0] - self.centre) / self.half_range
        delta = self.delta(x)
        diff = nominal.simulate(d["x_e"], delta=delta) - nominal(d)
        return exact_zero_at(jnp.all(delta == 0), diff)

    def extra_dof(self, arrays):
        # without curvature its entries of `size` are calibrated leaves that act on
        # nothing: not degrees of freedom
        return 0 if self.curved else -(int(self.size.shape[0]) // 2)

    def admissible(self, context):
        """Finite values, and every mode of the TMF inside the analysed band over the
        measured positions (`−1 ≤ x ≤ 1`): a mode that would leave it is not a position
        dependence the records resolve."""
        s = np.asarray(self.size)
        nom = context.nominal_model
        if not np.all(np.isfinite(s)):
            return False, "non-finite parameter slopes"
        if nom is None:
            return True, None
        n1, ns, _ = _position_layout(s.size)
        lo, hi = context.band_hz
        for x in np.linspace(-1.0, 1.0, 21):
            lw = np.asarray(nom.log_omega) + np.asarray(self.delta(x))[n1 : n1 + ns]
            f = np.exp(lw) * nom.w0 / (2 * math.pi)
            if np.any(f > hi) or np.any(f < lo):
                end = {-1.0: "lower end", 1.0: "upper end"}.get(round(float(x), 6), "inside")
                return False, (
                    f"a mode leaves the analysed band [{lo:.3g}, {hi:.4g}] Hz at the {end} "
                    f"of y (x = {x:+.1f}: f = {', '.join(f'{v:.4g}' for v in f)} Hz)"
                )
        return True, None

    def parameters(self):
        s = np.asarray(self.size)
        n1, ns, no = _position_layout(s.size)
        p = n1 + 2 * ns + no
        out = {
            "y_centre": _f(self.centre),
            "y_half_range": _f(self.half_range),
            "numerator_slope_norm": float(np.linalg.norm(s[:n1])),
            "centre_offset_norm": float(np.linalg.norm(np.asarray(self.offset))),
        }
        out["numerator_curvature_norm"] = float(np.linalg.norm(s[p : p + n1]))
        for k in range(ns):  # sections in the nominal's order
            # relative change from the centre to the upper end of the positions
            w, z = n1 + k, n1 + ns + k
            out[f"mode_{k + 1}_frequency_change"] = float(np.expm1(s[w] + s[p + w]))
            out[f"mode_{k + 1}_damping_change"] = float(np.expm1(s[z] + s[p + z]))
            out[f"mode_{k + 1}_log_frequency_curvature"] = float(s[p + w])
        return out


class MissingMode(AbstractAdditiveEffect):
    """A mode in parallel on `x_e`: `(r₁ ω s + r₀ ω²) / (s² + 2ζωs + ω²)`."""

    name: ClassVar[str] = "missing_mode"
    order: ClassVar[int] = 0
    size: Float[Array, 2]  # residue (r0, r1) [-]
    omega: Any  # [rad/s], positive
    zeta: Any  # [-], positive
    dt: float = eqx.field(static=True)

    def contribution(self, d, nominal):
        w, z = jnp.reshape(self.omega, (1,)), jnp.reshape(self.zeta, (1,))
        p = section_poles(w, z, jnp.zeros((0,), w.dtype))
        _, r = partial_fractions(jnp.stack([self.size[1] * w[0], self.size[0] * w[0] ** 2]), p)
        return simulate_modal(jnp.zeros((), w.dtype), r, p, d["x_e"], self.dt)

    def constrained(self):
        return eqx.tree_at(lambda e: (e.omega, e.zeta), self, replace_fn=_positive)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        """A mode is a lightly damped resonance (`ζ < 0.3`) up to the Nyquist frequency
        (a heavily damped "mode" only bends the phase, as a delay does)."""
        f = _f(self.omega) / (2 * math.pi)
        z = _f(self.zeta)
        lo, hi = context.band_hz
        return check(
            (np.all(np.isfinite(np.asarray(self.size))) and np.isfinite(f), "non-finite mode"),
            (z < ZETA_MAX, f"damping ratio ζ = {z:.3g}: not a lightly damped mode (< {ZETA_MAX})"),
            (lo <= f <= hi, f"f = {f:.4g} Hz outside the analysed band [{lo:.3g}, {hi:.4g}] Hz"),
        )

    def parameters(self):
        s = np.asarray(self.size)
        return {
            "f_hz": _f(self.omega) / (2 * math.pi),
            "zeta": _f(self.zeta),
            "residue_static": float(s[0]),
            "residue_velocity": float(s[1]),
        }


ZETA_MAX = 0.3
"""Largest damping ratio of a mode (heuristic: above it a mode has no peak left)."""


class SensorDelay(AbstractEffect):
    """`x_t` recorded `tau` [s] after the motion it measures (a transport or filter delay).

    `lag` holds the delay's signature measured before the fit (never calibrated): the
    phase delay `(τ_φ, its standard error)` [s] of the measured `x_t` behind the current
    model's prediction ([`phase_delay`][]); `None` when not measured."""

    name: ClassVar[str] = "sensor_delay"
    order: ClassVar[int] = 1
    tau: Float[Array, ""]  # [s]
    dt: float = eqx.field(static=True)
    lag: Any = None  # (τ_φ, standard error) [s]

    def apply(self, y, d, nominal):
        return fft_delay(y, self.tau / self.dt)

    def constrained(self):
        if self.lag is None:
            return self
        return eqx.tree_at(lambda e: e.lag, self, replace_fn=fixed)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        """Finite, causal and short against the record; a fraction of a sample is
        admissible: the tool-side channel's own measurement chain (an anti-alias filter's
        group delay, a converter) delays it by less than a sample, and the band-limited
        shift resolves that."""
        lag, se = (math.nan, math.nan) if self.lag is None else np.asarray(self.lag, float)
        return check(
            *delay_rules(_f(self.tau), context, min_samples=0.0),
            (
                not np.isfinite(lag) or lag > LAG_Z * se,
                f"the measured x_t does not lag the model (phase delay of the cross spectrum "
                f"{1e3 * lag:.3g} ± {1e3 * se:.2g} ms): no delay's signature",
            ),
        )

    def parameters(self):
        out = {"tau_s": _f(self.tau)}
        if self.lag is not None:
            lag, se = np.asarray(self.lag, float)
            out["phase_delay_before_s"] = float(lag)
            out["phase_delay_before_se_s"] = float(se)
        return out


LAG_Z = 3.0
"""Standard errors by which the signature's phase delay must exceed zero (one-sided,
p ≈ 0.001): a lag the phase estimate's own noise does not explain."""


class ProcessForce(AbstractAdditiveEffect):
    """The measured process force `f` moves the tool relative to the encoder through a
    compliance with the structure's poles: `+ g·A(0)·N(σ) / A(σ) · (f + b)`, `A` the
    nominal TMF's denominator, `N(σ) = Σ b_i σ^i` the size; the static compliance is
    `g·b₀` [m/N].

    `f` is taken relative to its first sample (as `x_t` is), and `b = κ f(0)` is the
    force not balanced by the structure's deflection at the record's start, applied
    from rest: `κ = 0` when the structure was at rest under the force acting then (a
    record that starts mid-cut), `κ = 1` when the force came on with the record (the
    structure unloaded before). The record does not say which, so `κ` is calibrated
    (one value for all experiments of one set-up), as `κ = 1 / (1 + e^{−θ})`: a share,
    between 0 and 1 at every iterate (it starts at one half).

    The same poles as the TMF are exact for a lumped structure: `x_t − T x_e =
    (G_tf − T G_ef) f`, and by the Desnanot–Jacobi identity the numerator of this
    difference of compliances is divisible by the full characteristic polynomial, leaving
    the TMF's denominator (the structure with the encoder held)."""

    name: ClassVar[str] = "process_force"
    order: ClassVar[int] = 0
    size: Float[Array, " n1"]  # N(σ), highest power first, in units of g
    gain: Any  # g [m/N] = RMS(x_t) / RMS(f) of the calibration data; never calibrated
    unbalanced: Any = 0.0  # θ [-]: κ = sigmoid(θ), share of f(0) unbalanced at the start
    # the signature measured before the fit (never calibrated): the largest coherence of
    # the residual with f and its null level ([`force_coherence`][]); None: not measured
    coherence: Any = None

    def contribution(self, d, nominal):
        a0 = nominal.scaled_denominator()[-1]
        force = d["f"] + jax.nn.sigmoid(self.unbalanced) * d["f0"]
        return nominal.simulate(force, num=self.gain * a0 * self.size)

    def constrained(self):
        if self.coherence is None:
            return eqx.tree_at(lambda e: e.gain, self, replace_fn=fixed)
        return eqx.tree_at(lambda e: (e.gain, e.coherence), self, replace_fn=fixed)

    def extra_dof(self, arrays):
        return 0

    def admissible(self, context):
        # the compliance has the structure's own (stable) poles; its numerator is free
        ok = bool(np.all(np.isfinite(np.asarray(self.size)))) and bool(
            np.isfinite(_f(self.unbalanced))
        )
        coh, level = (1.0, 0.0) if self.coherence is None else np.asarray(self.coherence)
        return check(
            (ok, "non-finite compliance numerator"),
            (
                coh > level,
                f"the residual is not coherent with the measured force (largest coherence "
                f"{coh:.3g}, null level {level:.3g}): no process force's signature",
            ),
        )

    def parameters(self):
        b = np.asarray(self.size)
        out = {"static_compliance_m_per_N": _f(self.gain) * float(b[-1])}
        for i, bi in enumerate(b[::-1][1:], start=1):
            out[f"b{i}"] = float(bi)  # coefficient of σ^i (σ = s / w0), in units of g
        out["unbalanced_share_at_start"] = 0.5 * (1 + math.tanh(0.5 * _f(self.unbalanced)))
        if self.coherence is not None:
            coh, level = np.asarray(self.coherence, float)
            out["force_coherence_before"] = float(coh)
            out["force_coherence_null_level"] = float(level)
        return out


# ------------------------------------------------------------------------------ signatures


def _spectra(u: Sequence[np.ndarray], v: Sequence[np.ndarray], dt: float, nperseg: int):
    """Welch auto and cross spectra `S_uu`, `S_vv`, `S_uv` (scipy's `csd(u, v)`: `E[U* V]`)
    summed over experiments, and the number of independent segments behind them."""
    suu = svv = suv = 0.0
    freq = None
    segments = 0
    for a, b in zip(u, v):
        a, b = np.asarray(a, float), np.asarray(b, float)
        seg = int(min(nperseg, a.size))
        freq, p = ss.welch(a, fs=1.0 / dt, nperseg=seg)
        suu = suu + p
        svv = svv + ss.welch(b, fs=1.0 / dt, nperseg=seg)[1]
        suv = suv + ss.csd(a, b, fs=1.0 / dt, nperseg=seg)[1]
        segments += a.size // seg
    return np.asarray(freq), suu, svv, suv, max(segments, 1)


def phase_delay(
    u: Sequence[np.ndarray],
    v: Sequence[np.ndarray],
    dt: float,
    nperseg: int = 256,
    min_coherence: float = 0.5,
) -> tuple[float, float, float]:
    """The delay of `v` behind `u` from the phase of their cross spectrum: the signature of
    a delay is a ratio `H = S_uv / S_uu = e^{−jωτ}`, a phase linear in frequency.

    **Arguments:**

    - `u`, `v`: one array per experiment each, of equal lengths per experiment (e.g. a
        model's prediction and the measured signal).
    - `dt`: sample time [s].
    - `nperseg`: Welch segment length [samples].
    - `min_coherence`: frequencies below this coherence of `u` and `v` (and above 0.45 of
        the sampling rate) are left out.

    **Returns:**

    `(τ [s], standard error [s], χ²/dof)`: the weighted least-squares slope `−dφ/dω`
    through the origin of the unwrapped phase, each frequency weighted by the inverse
    variance of its phase estimate `(1 − γ²) / (2 n_d γ²)` (Bendat & Piersol, random
    data, eq. 9.52; `n_d` the independent segments), and the reduced χ² of the phase
    about the line (about 1 when the phase is linear within its confidence). `nan`s when
    fewer than three frequencies are coherent.
    """
    freq, suu, svv, suv, nd = _spectra(u, v, dt, nperseg)
    coh = np.abs(suv) ** 2 / np.maximum(suu * svv, 1e-300)
    phase = np.unwrap(np.angle(suv))
    band = (freq > 0) & (freq < 0.45 / dt) & (coh >= min_coherence)
    if band.sum() < 3:
        return math.nan, math.nan, math.nan
    c = np.clip(coh[band], 1e-12, 1 - 1e-12)
    w = 2 * np.pi * freq[band]
    var = (1 - c) / (2 * nd * c)
    info = float(np.sum(w * w / var))
    tau = float(-np.sum(w * phase[band] / var) / info)
    chi2 = float(np.sum((phase[band] + w * tau) ** 2 / var) / (band.sum() - 1))
    return tau, 1.0 / math.sqrt(info), chi2


def coherence_null_level(segments: int, frequencies: int, alpha: float = 0.05) -> float:
    """The magnitude-squared coherence two independent signals exceed at `frequencies`
    frequencies with probability `alpha` in all (Bonferroni), from `segments`
    independent Welch segments: `P(γ̂² > c) = (1 − c)^(n_d − 1)` (Carter, Knapp,
    Nuttall 1973), so `c = 1 − (alpha / frequencies)^(1 / (n_d − 1))`."""
    if segments < 2 or frequencies < 1:
        return 1.0
    return float(1.0 - (alpha / frequencies) ** (1.0 / (segments - 1)))


def force_coherence(
    residual: Sequence[np.ndarray], force: Sequence[np.ndarray], dt: float, nperseg: int = 256
) -> tuple[float, float]:
    """The signature of a process force: the residual is coherent with the measured
    force. **Returns** `(largest coherence of residual and force below 0.45 of the
    sampling rate, its null level)` ([`coherence_null_level`][] at 5 % over those
    frequencies)."""
    freq, srr, sff, srf, nd = _spectra(residual, force, dt, nperseg)
    coh = np.abs(srf) ** 2 / np.maximum(srr * sff, 1e-300)
    band = (freq > 0) & (freq < 0.45 / dt)
    return float(np.max(coh[band])), coherence_null_level(nd, int(band.sum()))


# ------------------------------------------------------------------------------ templates


def _residual_peaks(ctx: Context, k: int) -> list[float]:
    """Frequencies [Hz] of the `k` most prominent peaks of the residual spectrum."""
    dt = ctx.experiments[0].dt
    fs = 1.0 / dt
    p_sum, f = None, None
    for r in ctx.residuals:
        r = np.asarray(r)
        f, p = ss.welch(r - r.mean(), fs=fs, nperseg=min(r.size, 1024))
        p_sum = p if p_sum is None else p_sum + p
    band = (f > 2 * fs / 1024) & (f < 0.45 * fs)
    peaks, props = ss.find_peaks(np.where(band, p_sum, 0.0), prominence=0)
    top = [float(f[i]) for i in peaks[np.argsort(props["prominences"])[::-1][:k]]]
    # always k starting points (one compilation): fill with frequencies spread over the band
    fill = [
        float(x)
        for x in np.geomspace(0.05 * fs, 0.4 * fs, k + 2)
        if all(abs(x - t) > 0.02 * fs for t in top)
    ]
    return (top + fill)[:k]


def _t_position(ctx: Context) -> list[AbstractEffect]:
    """Two starts: no change, and the changes of the TMFs fitted to each position alone.

    The second is the signature of a position dependence: a TMF initialised on each
    calibration experiment by itself (the nominal model's own rational fit), its
    parameters regressed on the position (a line, and a parabola in the log frequencies
    and dampings when there are three positions or more). It starts the calibration near
    a mode that moves by more than its bandwidth over the travel, where the mean TMF's
    cost has no slope towards it."""
    ys = np.array([float(e.arrays["pos_y"][0]) for e in ctx.experiments])
    lo, hi = float(ys.min()), float(ys.max())
    half = max((hi - lo) / 2, 1e-12)
    centre = (lo + hi) / 2
    nom = ctx.model.nominal
    n_size = 2 * int(nom.flat().shape[0])
    zero = jnp.zeros((n_size,))
    curved = np.unique(np.round(ys, 12)).size >= 3
    starts = [TMFPositionEffect(zero, jnp.asarray(centre), jnp.asarray(half), curved)]
    fitted = _position_start(ctx, (ys - centre) / half)
    if fitted is None:
        return starts + starts  # always two starts: one compilation
    size, offset = fitted
    start = TMFPositionEffect(
        jnp.asarray(size), jnp.asarray(centre), jnp.asarray(half), curved, jnp.asarray(offset)
    )
    return starts + [start]


def _position_start(ctx: Context, x: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The position effect's `size` and centre `offset` regressed from TMFs fitted to each
    calibration experiment alone (in the nominal model's frequency scale, sections matched
    by frequency rank): the slope (and curvature) of the regression, and its intercept
    less the nominal parameters; `None` when a fit has another structure than the
    nominal model (a real pole pair instead of a section) or fails."""
    nom = ctx.model.nominal
    fam = TMFFamily(**ctx.options)
    rank = np.argsort(np.asarray(nom.log_omega))
    flats = []
    for e in ctx.experiments:
        try:
            m = StableTMF.from_rational(fam.nominal([e]).tf(), nom.w0, nom.dt)
        except (NotIdentifiable, ValueError, np.linalg.LinAlgError):
            return None
        if m.log_omega.shape != nom.log_omega.shape or m.log_pole.shape != nom.log_pole.shape:
            return None
        lw, lz = np.asarray(m.log_omega), np.asarray(m.log_zeta)
        lw_m, lz_m = np.empty_like(lw), np.empty_like(lz)
        lw_m[rank], lz_m[rank] = np.sort(lw), lz[np.argsort(lw)]
        flats.append(np.concatenate([np.asarray(m.num), lw_m, lz_m, np.asarray(m.log_pole)]))
    flats_a = np.stack(flats)
    distinct = np.unique(np.round(x, 9)).size
    if not np.all(np.isfinite(flats_a)) or distinct < 2:
        return None
    cols = [np.ones_like(x), x] + ([x * x] if distinct >= 3 else [])
    coef, *_ = np.linalg.lstsq(np.stack(cols, axis=1), flats_a, rcond=None)
    curv = coef[2] if distinct >= 3 else np.zeros_like(coef[1])
    return np.concatenate([coef[1], curv]), coef[0] - np.asarray(nom.flat())


def _t_mode(ctx: Context) -> list[AbstractEffect]:
    """Starts at the residual's spectral peaks, plus one just below the Nyquist frequency:
    a mode near Nyquist has no resolved peak in a Welch spectrum but still bends the
    phase and the gain at the top of the band."""
    dt = ctx.experiments[0].dt
    freqs = _residual_peaks(ctx, 3) + [0.45 / dt]
    return [
        MissingMode(jnp.zeros(2), jnp.asarray(2 * math.pi * fr), jnp.asarray(0.03), dt)
        for fr in freqs
    ]


def _t_delay(ctx: Context) -> list[AbstractEffect]:
    dt = ctx.experiments[0].dt
    # The cost is not unimodal in τ: the encoder samples without an anti-alias filter, so
    # the content it aliases is shifted by the wrong phase by any fractional delay and the
    # cost has local minima about a sample apart; and the TMF's numerator absorbs part of
    # a delay. Starts from half a sample (a filter's group delay) to six samples; the best
    # admissible fit by calibration cost is kept.
    pred = [e.y - np.asarray(r) for e, r in zip(ctx.experiments, ctx.residuals)]
    lag = jnp.asarray(phase_delay(pred, [e.y for e in ctx.experiments], dt)[:2])
    return [SensorDelay(jnp.asarray(k * dt), dt, lag) for k in (0.5, 1.5, 3.0, 6.0)]


def _t_force(ctx: Context) -> list[AbstractEffect]:
    xt = np.concatenate([e.y for e in ctx.experiments])
    f = np.concatenate([np.asarray(e.arrays["f"]) for e in ctx.experiments])
    fr = float(np.sqrt(np.mean((f - f.mean()) ** 2 + f.mean() ** 2)))
    if fr <= 0:
        return []
    gain = float(np.sqrt(np.mean(xt**2))) / fr
    n1 = int(ctx.model.nominal.num.shape[0])
    dt = ctx.experiments[0].dt
    forces = [np.asarray(e.arrays["f"]) for e in ctx.experiments]
    coherence = jnp.asarray(force_coherence(ctx.residuals, forces, dt))
    return [ProcessForce(jnp.zeros(n1), jnp.asarray(gain), jnp.asarray(0.0), coherence)]


def _needs_positions(experiments: Sequence[Experiment]) -> str | None:
    ys = {round(float(e.arrays["pos_y"][0]), 12) for e in experiments}
    if len(ys) < 2:
        return "needs experiments at two or more positions y of the other axis"
    return None


def _needs_force(experiments: Sequence[Experiment]) -> str | None:
    f = np.concatenate([np.asarray(e.arrays["f"]) for e in experiments])
    if float(np.ptp(f)) <= 0:
        return "needs a varying process force f; it is constant"
    return None


# ------------------------------------------------------------------------------ family


def _fir_residual(
    xe: np.ndarray,
    xt: np.ndarray,
    f: np.ndarray | None,
    taps: int,
    extra: np.ndarray | None = None,
) -> tuple[np.ndarray, int] | None:
    """Residual of a long FIR regression of `x_t` on `x_e` (and `f`), taps −3 … `taps` − 4,
    plus optional regressor columns `extra` `(n, m)` aligned with `x_t`: whatever a linear
    time-invariant map of the inputs cannot explain. Solved by the normal equations on
    normalised columns. Returns the residual and the number of regressors, or `None` when
    the record is too short for the regression."""
    n = xt.size
    lead = 3
    m = n - taps + 1  # windows of `taps` samples ending `lead` samples after k
    if m <= 4 * taps:
        return None
    win = np.lib.stride_tricks.sliding_window_view
    cols = [win(xe, taps)]
    if f is not None:
        cols.append(win(f, taps))
    start = taps - 1 - lead
    # a constant: the record is taken relative to its first sample, which shifts its
    # noise by that sample's noise (an offset, not noise)
    cols.append(np.ones((m, 1)))
    if extra is not None:
        cols.append(np.asarray(extra)[start : start + m])
    phi = np.concatenate(cols, axis=1)  # row j: inputs j … j + taps − 1
    y = xt[start : start + m]
    scale = np.sqrt(np.mean(phi**2, axis=0)) + 1e-300
    phi = phi / scale
    g = phi.T @ phi
    g[np.diag_indices_from(g)] += 1e-12 * np.trace(g) / g.shape[0]
    th = np.linalg.solve(g, phi.T @ y)
    return y - phi @ th, phi.shape[1]


def _fir_noise_var(xe: np.ndarray, xt: np.ndarray, f: np.ndarray | None, taps: int) -> float:
    """Noise level of `x_t`: the residual variance of a long FIR regression on `x_e` (and
    `f`) ([`_fir_residual`][]): sensor noise, encoder quantisation carried through the TMF,
    and what `taps` samples cannot represent (the slow decay of a lightly damped mode, see
    [`_pole_basis`][]). Corrected for the fitted parameters, `SSR / (n − p)`."""
    out = _fir_residual(xe, xt, f, taps)
    if out is None:
        return float(np.var(xt)) * 1e-6
    r, p = out
    return float(np.sum(r**2) / (r.size - p))


def _pole_basis(nominal: StableTMF, u: np.ndarray) -> np.ndarray:
    """`u` filtered by `σ^k / A(σ)`, `k = 0 … order − 1` (`A` the nominal TMF's
    denominator, `σ = s / w0`), zero-order hold from rest, as columns `(n, order)`.

    With these columns a linear regression represents any response with the structure's
    own poles, however lightly damped (a mode that rings far longer than an FIR window),
    and any numerator: the generalised orthonormal basis idea (Heuberger, Van den Hof,
    Wahlberg 2005) with the poles of the calibrated model."""
    den = np.asarray(nominal.scaled_denominator(), float)
    order = den.size - 1
    dts = nominal.dt * nominal.w0  # the time step in units of 1 / w0
    cols = []
    for k in range(order):
        num = np.zeros(order)
        num[order - 1 - k] = 1.0
        with warnings.catch_warnings():
            # scipy flags the leading zeros of the strictly proper numerator it trims
            warnings.simplefilter("ignore", ss.BadCoefficients)
            b, a, _ = ss.cont2discrete((num, den), dts, method="zoh")
        cols.append(ss.lfilter(np.ravel(b), a, u))
    return np.stack(cols, axis=1)


def periodic_noise(
    xe: np.ndarray, xt: np.ndarray, resolution: float = 0.0
) -> tuple[float, float] | None:
    """The noise of `x_t` from its period-to-period variation when `x_e` repeats in at
    least two whole periods (the first dropped as a transient when there are three or
    more): variance (less the quantisation `Δ²/12`) and lag-one autocorrelation; `None`
    for a record that does not repeat."""
    period = find_period(xe, rtol=1e-3)
    if period is None:
        return None
    var, rho, _ = period_noise(xt, period)
    return max(var - resolution**2 / 12.0, 0.0), float(np.clip(rho, 0.0, 0.99))


def _distortion_basis(
    linear: np.ndarray, xe: np.ndarray, xt: np.ndarray, models: Sequence[StableTMF]
) -> np.ndarray:
    """Columns for the nonlinear distortion of a structure driven by `x_e`: the squares
    and cubes of the linear response `x̂_t` (the pole-basis columns `linear` fitted to
    `x_t`), of the deflection `x_e − x̂_t` and of its rate, each as it is (a static
    nonlinearity of the sensor) and filtered through the poles of each TMF of `models`
    (a nonlinear force inside the structure: a stiffness that grows with the amplitude,
    dry friction in a joint, whose response rings with the structure's modes). The
    second- and third-degree terms of a Volterra series of the structure (Schetzen,
    *The Volterra and Wiener Theories of Nonlinear Systems*, 1980), in the structure's own
    modal basis. On a linear structure they explain nothing but their share of the noise,
    which the degrees-of-freedom correction removes; on a nonlinear one they keep the
    distortion out of the noise, where it would raise the floor to the gap."""
    a = np.concatenate([linear, np.ones((linear.shape[0], 1))], axis=1)
    th, *_ = np.linalg.lstsq(a, xt, rcond=None)
    fit = a @ th
    defl = xe - fit
    rate = np.gradient(defl)
    cols = []
    for z in (fit, defl, rate):
        z = z - z.mean()
        sd = float(np.std(z))
        if sd <= 0:
            continue
        z = z / sd
        for power in (z * z, z * z * z):
            cols.append(power[:, None])
            cols.extend(_pole_basis(m, power) for m in models)
    if not cols:
        return np.zeros((xe.size, 0))
    return np.concatenate(cols, axis=1)


def record_noise(exp: Experiment, models: Sequence[StableTMF], taps: int) -> tuple[float, float]:
    """The measurement noise of one experiment's `x_t`: variance and lag-one
    autocorrelation of what no time-invariant map of the inputs explains.

    The regression holds an FIR window of `x_e` and `f` (delays, short responses) and
    both inputs filtered through the poles of each TMF of `models`
    ([`_pole_basis`][]: the calibrated nominal TMF, and one fitted to this experiment
    alone, whose poles are right where a position moves them), so a lightly damped mode
    or a force compliance that rings past the window is explained rather than counted
    as noise. The squares and cubes of the linear response, its deflection and the
    deflection's rate, as they are and through the same poles ([`_distortion_basis`][]),
    keep a nonlinear distortion out of the noise: a distortion above the noise is a
    finding the gap must show, never part of the floor. Every effect of the library is linear and
    time-invariant within one experiment (one position y), so on a record with an effect
    the estimate is still the noise, not the gap. The variance is corrected for the
    fitted parameters and less the record's own quantisation `Δ²/12` (the null quantises
    its records again). A record whose `x_e` repeats in periods gives the noise from the
    measurement instead ([`periodic_noise`][]): what changes from period to period, which
    no nonlinearity can hide in."""
    measured = periodic_noise(np.asarray(exp.arrays["x_e"], float), exp.y, exp.resolution)
    if measured is not None:
        return measured
    xe = np.asarray(exp.arrays["x_e"], float)
    f = np.asarray(exp.arrays["f"], float)
    has_f = "f" in exp.signals and float(np.ptp(f)) > 0
    inputs = [xe, f] if has_f else [xe]
    extra = np.concatenate([_pole_basis(m, u) for m in models for u in inputs], axis=1)
    extra = np.concatenate([extra, _distortion_basis(extra, xe, exp.y, models)], axis=1)
    out = _fir_residual(xe, exp.y, f if has_f else None, taps, extra)
    if out is None:
        return float(exp.noise_var), 0.0
    r, p = out
    var = float(np.sum(r**2) / (r.size - p))
    var = max(var - exp.resolution**2 / 12.0, 0.0)
    rc = r - r.mean()
    rho = float(np.dot(rc[1:], rc[:-1]) / max(float(np.dot(rc, rc)), 1e-300))
    return var, float(np.clip(rho, 0.0, 0.99))


class TMFFamily(AbstractFamily):
    """Encoder-side (`x_e`) to tool-side (`x_t`) motion through one rational TMF.

    **Options:** `order` (numerator and denominator order of the nominal TMF, default 4),
    `coherence` (lowest coherence of the band used for the initial fit, default 0.5),
    `fir_taps` (length of the FIR regression behind the noise floor, default 150).
    """

    name = "tmf"
    required = ("x_e", "x_t")
    optional = ("y", "f")
    option_keys = ("order", "coherence", "fir_taps")
    target_label = "tool-side motion x_t"
    # the templates' shapes follow from the nominal model's structure alone: the search
    # calibrates the nominal model through its own structure (one compilation)
    early_layout = True

    def __init__(self, **options: Any):
        order = options.get("order", 4)
        if isinstance(order, bool) or not isinstance(order, int | np.integer) or order < 1:
            raise ValueError(
                f"diagnose(tmf): order must be a positive integer (numerator and denominator "
                f"order of the TMF); got {order!r}."
            )
        super().__init__(**{**options, "order": int(order)})

    def prepare(self, record: Record, name: str) -> Experiment:
        order = self.options["order"]
        n = len(record)
        n_min = max(64, 20 * (2 * order + 1))
        if n < n_min:
            raise ValueError(
                f"diagnose(tmf): experiment {name!r} has {n} samples; at least {n_min} are "
                f"needed for a TMF of order {order}. Give longer records."
            )
        xe = np.asarray(record["x_e"], float)
        xt = np.asarray(record["x_t"], float)
        if float(np.ptp(xe)) == 0.0:
            raise NotIdentifiable(
                f"diagnose(tmf): x_e of experiment {name!r} is constant; the TMF is not "
                "identifiable without motion. Give experiments with excitation."
            )
        # motion relative to the first sample (the machine is at rest there)
        xe = xe - xe[0]
        xt = xt - xt[0]
        signals = set(record.names)
        if "y" in record.names:
            ycol = np.asarray(record["y"], float)
            if float(np.ptp(ycol)) > 1e-9 * max(1.0, float(np.max(np.abs(ycol)))):
                raise ValueError(
                    f"diagnose(tmf): the position y changes within experiment {name!r}; the "
                    "TMF is simulated per experiment at one position. Cut the record into "
                    "parts of constant y (Record.slice) and pass them as experiments."
                )
            pos = float(ycol[0])
        elif "y" in record.metadata:
            pos = float(record.metadata["y"])
            signals.add("y")
        else:
            pos = 0.0
        has_f = "f" in record.names
        # the process force relative to its first sample too: the deflection under the
        # force at rest is already in x_t[0], which was taken off
        f = np.asarray(record["f"], float) if has_f else np.zeros(n)
        f0 = np.full(n, f[0])  # the force at the start (see ProcessForce)
        f = f - f[0]
        taps = int(self.options.get("fir_taps", 150))
        measured = periodic_noise(xe, xt)
        if measured is not None:
            noise_var = measured[0]
        else:
            noise_var = _fir_noise_var(xe, xt, f if has_f and np.ptp(f) > 0 else None, taps)
        w = max(4, int(round(0.05 / record.dt)))
        amp = np.sqrt(np.convolve((xe - xe.mean()) ** 2, np.ones(w) / w, mode="same"))
        ops = {"position y [m]": np.full(n, pos), "x_e amplitude [m]": amp}
        return Experiment(
            name=name,
            t=np.asarray(record.t),
            arrays={"x_e": xe, "pos_y": np.full(n, pos), "f": f, "f0": f0, "y": xt},
            ops=ops,
            masks={},
            noise_var=noise_var,
            signals=frozenset(signals),
            source=record,
            record_dt=float(record.dt),
            resolution=quantisation_step(np.asarray(record["x_t"], float)),
        )

    def identifiability(self, experiments: Sequence[Experiment], model: GapModel) -> str | None:
        """The TMF is identified when the calibrated model explains the tool-side motion
        better than no model at all (`x_t = 0`); the coherence over the band is checked
        when the model is initialised."""
        y = np.concatenate([e.y for e in experiments])
        r = np.concatenate([e.y - predict(model, e) for e in experiments])
        if not float(np.sum(r**2)) < float(np.sum(y**2)):
            return (
                "the calibrated TMF does not explain the tool-side motion at all: x_t does not "
                "respond to x_e in the record; excite the axis over the band of interest"
            )
        return None

    def admissibility_context(
        self, experiments: Sequence[Experiment], model: GapModel
    ) -> AdmissibilityContext:
        dt = experiments[0].dt
        dur = min(e.n * dt for e in experiments)
        nom = unwrap(model.nominal)
        return AdmissibilityContext(
            record_dt=dt,
            analysis_dt=dt,
            band_hz=(2.0 / dur, 0.5 / dt),
            resolution=max(e.resolution for e in experiments),
            duration=dur,
            nominal=nom.parameters(),
            nominal_model=nom,
        )

    def null_experiments(
        self,
        model: GapModel,
        experiments: Sequence[Experiment],
        rng: np.random.Generator,
        count: int,
    ) -> list[list[Experiment]]:
        """The calibrated TMF driven by each record's own `x_e`, plus noise of the
        record's level and colour and the record's quantisation of `x_t` (a random zero
        per draw).

        The noise is what no linear time-invariant map of the record's inputs explains
        ([`record_noise`][]: an FIR window plus the calibrated TMF's own poles), simulated
        as a first-order autoregression with the residual's variance and lag-one
        autocorrelation. It is neither the nominal model's residual (which holds any
        unmodelled effect, so the floor would equal the gap) nor the plain FIR residual
        (which holds the slow decay of a lightly damped mode)."""
        nom = unwrap(model.nominal)
        taps = int(self.options.get("fir_taps", 150))
        out: list[list[Experiment]] = [[] for _ in range(count)]
        for exp in experiments:
            clean = predict(model, exp)
            models = [nom]
            try:
                models.append(self.nominal([exp]))
            except NotIdentifiable:
                pass
            var, rho = record_noise(exp, models, taps)
            sigma = math.sqrt(var)
            step = exp.resolution
            for k in range(count):
                w = sigma * math.sqrt(1 - rho * rho) * rng.standard_normal(clean.shape)
                w[0] = sigma * rng.standard_normal()
                noise = ss.lfilter([1.0], [1.0, -rho], w)
                y = clean + noise
                if step > 0:
                    phase = rng.uniform(0.0, step)
                    y = step * np.round((y + phase) / step) - phase
                y = y - y[0]  # relative to the first sample, as `prepare` takes the record
                out[k].append(dataclasses.replace(exp, arrays={**exp.arrays, "y": y}))
        return out

    def describe_nominal(self) -> str:
        o = self.options["order"]
        return f"one position-independent rational TMF of order {o}/{o}, x_t = T(s) x_e (zoh)"

    def nominal(self, experiments: Sequence[Experiment]) -> StableTMF:
        order = self.options["order"]
        dt = experiments[0].dt
        fs = 1.0 / dt
        nper = int(min(min(e.n for e in experiments) // 4, 1024))
        nper = max(nper, 16)
        # H1 per experiment, averaged with weights n·γ² (experiments at several positions
        # give a mean TMF, which is what the position-independent nominal model is)
        h_sum, c_sum, n_sum = 0.0, 0.0, 0.0
        freq = None
        for e in experiments:
            frf = transmissibility(e.y, e.arrays["x_e"], fs, nperseg=nper)
            freq = np.asarray(frf.frequency)
            coh_e = np.asarray(frf.coherence).reshape(-1)
            h_sum = h_sum + e.n * coh_e * np.asarray(frf.H).reshape(-1)
            c_sum = c_sum + e.n * coh_e
            n_sum = n_sum + e.n
        h = h_sum / np.maximum(c_sum, 1e-300)
        coh = c_sum / n_sum
        cmin = float(self.options.get("coherence", 0.5))
        grid = (freq > 0) & (freq < 0.45 * fs)
        band = grid & (coh >= cmin)
        if band.sum() < 2 * order + 2:
            band = grid & (coh >= np.quantile(coh[grid], 0.5))
        if band.sum() < 2 * order + 2:
            raise NotIdentifiable(
                "the encoder and tool signals are not coherent over enough frequencies to fit "
                "a TMF; check that x_t responds to x_e (same excitation)"
            )
        # the whole grid with zero weight outside the coherent band: one frequency grid
        # (one compilation of the fit) whatever the band
        c = np.clip(coh[grid], 1e-6, 0.999)
        weights = np.where(band[grid], np.sqrt(c / (1 - c)), 0.0)
        weights = weights / np.maximum(np.abs(h[grid]), 1e-300)
        omega = 2 * np.pi * freq[grid]
        w0 = float(np.sqrt(omega[band[grid]].min() * omega[band[grid]].max()))
        tf, _ = fit_rational(omega, h[grid], (order, order), weights=weights, throw=False)
        num = np.asarray(tf.num)
        den = np.asarray(tf.den)
        if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
            # fall back to a unit-gain TMF with modes spread over the band
            poles = []
            for wk in np.geomspace(omega.min(), omega.max(), max(order // 2, 1) + 2)[1:-1]:
                poles += [wk * (-0.05 + 1j), wk * (-0.05 - 1j)]
            if order % 2:
                poles.append(-w0)
            den = np.real(np.poly(poles))
            num = den.copy()
            tf = RationalTF(num, den)
        # the frequency scale only conditions the coefficients: a power of two keeps the
        # model's structure (a static field) the same across data sets, one compilation
        w0_q = float(2.0 ** round(math.log2(w0)))
        return StableTMF.from_rational(tf, w0_q, dt)

    def library(self) -> list[EffectSpec]:
        return [
            EffectSpec(
                "position_dependence",
                ("x_e", "x_t", "y"),
                _t_position,
                testable=_needs_positions,
                signature="position y",
                description="TMF coefficients that change with the position of the other axis",
            ),
            EffectSpec(
                "missing_mode",
                ("x_e", "x_t"),
                _t_mode,
                signature="residual spectrum peak",
                description="a structural mode between encoder and tool the TMF order misses",
            ),
            EffectSpec(
                "sensor_delay",
                ("x_e", "x_t"),
                _t_delay,
                signature="cross-correlation lag",
                description="the tool-side signal is recorded later than the encoder's",
            ),
            EffectSpec(
                "process_force",
                ("x_e", "x_t", "f"),
                _t_force,
                testable=_needs_force,
                signature="process force f",
                description="a process force at the tool deflects it relative to the encoder",
            ),
        ]
