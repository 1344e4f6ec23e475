r"""Identification of transmissibility functions (TMFs) for the TCP virtual sensor.

Three routes of the TMF study (Doerrer et al. 2022, §2.4-3.3), all returning a
`jaxvs.RationalTF` of the drive-side TMF `T_TE^D = x_T / x_E`:

- [`tmf_from_accelerations`][]: H1 estimate from two synchronised accelerometers (TCP and
  encoder) under drive-side excitation, fitted as a rational TMF with coherence weights;
- [`tmf_from_impacts`][]: modal fits of the FRFs `H_TE` and `H_EE` of a hammer test at the
  encoder, TMF from the modal parameters (eq. 6); [`tmf_from_hammer`][] does the same from
  the raw hammer records (H1 with force and exponential windows, whose damping, like the
  accelerometers' high-pass, is undone in the modal fit);
- [`tmf_from_time_domain`][]: simulation-error calibration on an excitation record
  (encoder position in, reference TCP position out).

[`tmf_from_frfs`][] forms the TMF `H_a / H_b` of two measured FRFs with one excitation
point and identifies it by either a rational fit of the ratio or the modal route.

A TMF depends on where the force acts (eq. 6, Fig. 4): `T^D ≈ T^E ≠ T^T`. Each route
checks the excitation location ([`check_excitation_location`][]) and warns with an
[`ExcitationLocationWarning`][] when the TMF meant for drive-side operation was identified
with TCP-side excitation. [`tmf_family`][] identifies a family smooth in the position of
another axis in one vectorised calibration.
"""

import dataclasses
import functools
import warnings
from typing import Any, Literal, NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from ..._misc import options_object
from ...calibration import (
    CalibrationResult,
    FrequencyError,
    ModalFit,
    SimulationError,
    calibrate,
    calibrate_family,
    fit_rational,
    lsfd,
    modal_fit,
    pole_tracks,
    stable,
    tmf_from_modal,
    unwrap,
)
from ...data import FRFData
from ...models import (
    ModalModel,
    RationalTF,
    SmoothFamily,
    frequency_response,
    simulate,
    static_gain,
)
from ...signal import exponential_window_correction, transmissibility

Side = Literal["drive", "encoder", "tcp"]
_SIDES = ("drive", "encoder", "tcp")

#: Tolerance of the data-based check: a drive- or encoder-side TMF has `T(0) = 1` (the
#: structure beyond the encoder moves rigidly under a static drive force); TCP-side
#: excitation gives `T(0) = H_TT(0) / H_ET(0) > 1`. Heuristic: 10 %.
STATIC_GAIN_TOL = 0.1


class ExcitationLocationWarning(UserWarning):
    """A TMF was identified with the force on the wrong side for its intended use."""


@dataclasses.dataclass(frozen=True)
class TMFFit:
    """How a TMF is identified from the modal parameters of two FRFs of one hammer test
    ([`tmf_from_impacts`][], [`tmf_from_hammer`][]), as one frozen object that can be built
    once and passed to several identifications. Its fields are also accepted as keywords of
    those functions.

    **Fields:**

    - `n_modes`, `max_order`: as for `jaxvs.modal_fit` (default: modes found by the
      stabilisation diagram, up to model order 40).
    - `lower_residual`: fit the lower residual of the measured quantity (default `False`:
      a supported structure fitted to the receptance, see [`tmf_from_impacts`][]).
    - `weights`: of the residue fit (LSFD): `"uniform"`, `"relative"` or an array (see
      [`tmf_from_impacts`][]).
    - `order`: optional `(nb, na)` of a reduced rational TMF refitted over the band.
    - `excitation`, `operation`: see [`check_excitation_location`][] (default: hammer at
      the encoder, the drive-side TMF); `excitation=None` skips the check.
    - `static_gain`: imposed `T(0)` (default 1; `None` keeps the fitted gain).
    """

    n_modes: int | None = None
    max_order: int = 40
    lower_residual: bool = False
    weights: Any = "uniform"
    order: tuple[int, int] | int | None = None
    excitation: Side | None = "encoder"
    operation: Literal["drive", "tcp"] = "drive"
    static_gain: float | None = 1.0


class TMFIdentification(NamedTuple):
    """Result of a TMF identification route.

    - `model`: the identified `RationalTF` (a family with leading axes when the data had
      them).
    - `route`: `"accelerations"`, `"impacts"` or `"time_domain"`.
    - `excitation`: the declared excitation side.
    - `estimate`: the measured TMF (`FRFData`) of the accelerometer route, else `None`.
    - `details`: the route's fit report (`FitReport`, `ModalFit`, `CalibrationResult`).
    """

    model: RationalTF
    route: str
    excitation: str
    estimate: FRFData | None
    details: Any


def _check_side(side: str, name: str, where: str) -> None:
    if side not in _SIDES:
        raise ValueError(f"{where}: {name}={side!r}; use one of {_SIDES}.")


def check_excitation_location(
    tmf: Any = None,
    *,
    excitation: Side | None = None,
    operation: Literal["drive", "tcp"] = "drive",
    static_tol: float = STATIC_GAIN_TOL,
    omega_low: float | None = None,
) -> bool:
    r"""Warn when a TMF was identified with the excitation on the wrong side.

    The virtual sensor (eq. 7) needs `T_TE^D`: the force acts on the drive side of the
    encoder, as it does in operation. A drive-side PRBS or a hammer at the encoder gives
    it (`T^D = T^E`, the study's Fig. 4); a hammer at the TCP gives `T^T`, a different
    function. Two checks:

    1. **flag**: `excitation="tcp"` for `operation="drive"` (or a drive/encoder
       excitation for a TCP-side use) warns;
    2. **data**: a drive-side TMF has the static gain `T(0) = 1` (under a static drive
       force everything beyond the encoder moves with it), while TCP-side excitation
       gives `T(0) = H_TT(0) / H_ET(0) > 1` (the compliance between encoder and TCP adds
       up). A fitted `tmf` with `|T − 1| > static_tol` at `omega_low` (or at 0) warns for
       `operation="drive"`. Evaluate it at the low end of the identified band when the
       model is not trustworthy at 0 Hz (e.g. accelerance fits, whose residual terms
       decide the DC value); the band's low end must lie well below the TMF's first
       resonance (`|T^D − 1| ≈ (ω / ω_1)²`).

    **Arguments:**

    - `tmf`: optional identified linear model (or family) to check by its static gain.
    - `excitation`: the declared excitation side, `"drive"`, `"encoder"` or `"tcp"`.
    - `operation`: where the force acts when the TMF is used: `"drive"` (feed motion, the
      virtual sensor of eq. 7) or `"tcp"`.
    - `static_tol`: tolerance of the static-gain check [-].
    - `omega_low`: frequency [rad/s] of the low-frequency gain check (default 0).

    **Returns:**

    `True` when no warning was issued.

    **Warns:** [`ExcitationLocationWarning`][].
    """
    where = "check_excitation_location"
    if operation not in ("drive", "tcp"):
        raise ValueError(f"{where}: operation={operation!r}; use 'drive' or 'tcp'.")
    ok = True
    if excitation is not None:
        _check_side(excitation, "excitation", where)
        drive_side = excitation in ("drive", "encoder")
        if operation == "drive" and not drive_side:
            warnings.warn(
                "The TMF was identified with excitation at the TCP, but it is meant for "
                "drive-side operation (the virtual sensor x_T = T_TE^D x_E, eq. 7). A TMF "
                "depends on where the force acts (T^T != T^D, Doerrer et al. 2022, Fig. 4): "
                "identify it with a drive-side PRBS or a hammer at the encoder instead.",
                ExcitationLocationWarning,
                stacklevel=3,
            )
            ok = False
        elif operation == "tcp" and drive_side:
            warnings.warn(
                f"The TMF was identified with {excitation}-side excitation but is meant for "
                "a force at the TCP; use a hammer at the TCP.",
                ExcitationLocationWarning,
                stacklevel=3,
            )
            ok = False
    if tmf is not None and operation == "drive" and ok:
        if omega_low is None:
            g = np.abs(np.asarray(static_gain(tmf)))
        else:
            w = jnp.asarray([float(omega_low)])
            g = np.abs(np.asarray(frequency_response(tmf, w)))[..., 0]
        bad = np.abs(g - 1.0) > static_tol
        if np.any(bad):
            worst = np.ravel(g)[np.argmax(np.ravel(bad))]
            warnings.warn(
                f"The identified TMF has a low-frequency gain |T| = {worst:.3g}"
                f" (!= 1 by more than {static_tol:.0%}). A drive-side TMF T_TE^D has "
                "T(0) = 1; a larger value is the signature of excitation at the TCP "
                "(T^T, compliance between encoder and TCP), a smaller one of a poor fit at "
                "low frequency. Check where the force acted, and the low end of the band.",
                ExcitationLocationWarning,
                stacklevel=3,
            )
            ok = False
    return ok


def _coherence_weights(gamma2: np.ndarray, min_coherence: float) -> np.ndarray:
    """`sqrt(γ² / (1 − γ²))`, the inverse standard deviation of the H1 estimate up to a
    constant (Bendat & Piersol, *Random Data*, 4th ed., §9.1.4), zero below
    `min_coherence`; capped at γ² = 0.9999 (heuristic: keeps one bin from dominating)."""
    g = np.clip(gamma2, 0.0, 0.9999)
    w = np.sqrt(g / (1.0 - g))
    return np.where(gamma2 >= min_coherence, w, 0.0)


def tmf_from_accelerations(
    a_tool: ArrayLike,
    a_encoder: ArrayLike,
    fs: float,
    order: tuple[int, int] | int = (2, 4),
    *,
    band: tuple[float, float] = (5.0, 400.0),
    nperseg: int = 1024,
    min_coherence: float = 0.5,
    excitation: Side = "drive",
    operation: Literal["drive", "tcp"] = "drive",
    static_gain: float | None = 1.0,
) -> TMFIdentification:
    r"""Route (a): rational TMF fitted to the H1 TMF of two synchronised accelerometers.

    `T = S_et / S_ee` from the TCP and encoder accelerations (the ratio of accelerations
    is the ratio of positions, eq. 6), Welch-averaged with its coherence; then
    `fit_rational` with weights `sqrt(γ² / (1 − γ²))` (bins with `γ² < min_coherence`
    dropped) over `band`. Leading axes make a family (e.g. one record per position),
    estimated and fitted in one call each.

    **Arguments:**

    - `a_tool`, `a_encoder`: `(*batch, time)` accelerations [m/s²] on one time base.
    - `fs`: sampling rate [Hz].
    - `order`: `(nb, na)` of the rational TMF (default (2, 4), the chain's encoder-to-TCP
      structure; an int `n` is `(n, n)`).
    - `band`: fitted band [Hz]; its upper end must stay below the excitation's usable
      bandwidth (e.g. ~333 Hz for a PRBS at a 3 ms servo cycle).
    - `nperseg`: Welch segment length (frequency resolution `fs / nperseg`).
    - `min_coherence`: bins below it get zero weight.
    - `excitation`, `operation`: see [`check_excitation_location`][].
    - `static_gain`: the TMF's gain at 0 Hz, imposed by scaling the numerator after the
      fit (default 1: under a drive-side force the structure beyond the encoder moves
      rigidly at 0 Hz). Accelerometers see nothing below a few Hz, so the fitted `T(0)`
      is off by a few tenths of a percent, and on millimetre moves that static error
      dominates the virtual sensor's error. Not applied when the excitation check fails
      (a TCP-side TMF has `T(0) > 1`) or the fitted `T(0)` is more than `STATIC_GAIN_TOL`
      off; `None` keeps the fitted gain.

    **Returns:** a [`TMFIdentification`][] (`details` is the `FitReport`).

    **Raises:** `ValueError` for records of different lengths, a record shorter than
    `nperseg`, or fewer usable bins than parameters.
    """
    where = "tmf_from_accelerations"
    _check_side(excitation, "excitation", where)
    a_tool, a_encoder = np.asarray(a_tool, float), np.asarray(a_encoder, float)
    if a_tool.shape != a_encoder.shape:
        raise ValueError(
            f"{where}: a_tool {a_tool.shape} and a_encoder {a_encoder.shape} must be "
            "synchronised records of the same shape (resample them onto one time base "
            "with jaxvs.signal.resample first)."
        )
    if a_tool.shape[-1] < nperseg:
        raise ValueError(
            f"{where}: the records have {a_tool.shape[-1]} samples, fewer than "
            f"nperseg={nperseg} (frequency resolution {fs / nperseg:.3g} Hz); record longer "
            "or lower nperseg."
        )
    est = transmissibility(
        a_tool,
        a_encoder,
        fs,
        tool_quantity="acceleration",
        encoder_quantity="acceleration",
        nperseg=nperseg,
    )
    f = np.asarray(est.frequency)
    sel = (f >= band[0]) & (f <= band[1]) & (f > 0)
    H = np.asarray(est.H)[..., sel]
    w = _coherence_weights(np.asarray(est.coherence)[..., sel], min_coherence)
    nb, na = (order, order) if isinstance(order, int) else order
    usable = int(np.min(np.sum(w > 0, axis=-1)))
    if 2 * usable < nb + na + 1:
        raise ValueError(
            f"{where}: only {usable} bins in {band} Hz have coherence >= {min_coherence}; a "
            f"TMF of order ({nb}, {na}) needs at least {(nb + na + 2) // 2}. Lower the order, "
            "widen the band, or excite harder / average longer."
        )
    omega = 2 * np.pi * f[sel]
    model, report = fit_rational(
        jnp.asarray(omega), jnp.asarray(H), (nb, na), weights=jnp.asarray(w)
    )
    drive_side = check_excitation_location(
        model, excitation=excitation, operation=operation, omega_low=float(omega[0])
    )
    model = _impose_static_gain(model, static_gain, drive_side)
    return TMFIdentification(model, "accelerations", excitation, est, report)


def _impose_static_gain(model, gain: float | None, drive_side: bool):
    """`model` scaled to `T(0) = gain` when the excitation check passed and the fitted
    static gain is a small error (within `STATIC_GAIN_TOL`) of it; a fit whose
    extrapolation to 0 Hz is far off (e.g. a free lower residual) is left as it is."""
    if gain is None or not drive_side or not isinstance(model, RationalTF):
        return model
    t0 = np.asarray(static_gain(model))
    if not np.all(np.isfinite(t0) & (np.abs(t0 / gain - 1.0) <= STATIC_GAIN_TOL)):
        return model
    return with_static_gain(model, gain)


def with_static_gain(model: RationalTF, gain: float = 1.0) -> RationalTF:
    """`model` with its numerator scaled so that its gain at 0 Hz is `gain` (a drive- or
    encoder-side TMF has `T(0) = 1`); leading (family) axes are scaled member by member.

    **Raises:** `ValueError` when the model has a pole or a zero at 0 Hz (no finite,
    non-zero static gain to scale)."""
    num, den = jnp.asarray(model.num), jnp.asarray(model.den)
    t0 = num[..., -1] / den[..., -1]
    if not bool(jnp.all(jnp.isfinite(t0) & (t0 != 0))):
        raise ValueError(
            "with_static_gain: the model has a pole or a zero at 0 Hz; its static gain "
            "cannot be imposed."
        )
    return RationalTF(num * (gain / t0)[..., None], den)


def _highpass(sw: np.ndarray, a: float) -> np.ndarray:
    """First-order sensor high-pass `s / (s + a)` at the (complex) frequencies `sw`."""
    return sw / (sw + a)


def _receptance_lsfd(omega, H2, sw, q, wn, ze, band, a_hp, diagram, rw):
    """LSFD of both FRFs as receptance `H / (s^q HP(s))` without the lower residual, with
    weights `|s^q HP(s)| rw` that keep the equation error in the measured quantity
    (times the residue weights `rw`, `(freq, 2)`)."""
    factor = sw**q * _highpass(sw, a_hp) if a_hp > 0 else sw**q
    return lsfd(
        omega,
        H2 / factor[:, None],
        wn,
        ze,
        quantity="receptance",
        band=band,
        weights=np.abs(factor)[:, None] * rw,
        diagram=diagram,
        lower_residual=False,
    )


def _estimate_highpass(omega, H2, sw, q, wn, ze, band, diagram, rw) -> float:
    """Corner `a` [rad/s] of a first-order sensor high-pass common to both channels, by
    minimising the LSFD misfit of the grounded receptance model (a coarse grid from 0 to
    the band's low edge, then a bounded scalar search around the best point). The misfit
    is sharp in `a` because the receptance model without the lower residual cannot absorb
    the high-pass's phase lead near the low band edge (heuristic search range)."""
    from scipy.optimize import minimize_scalar

    lo = float(band[0]) if band is not None else float(omega[omega > 0][0])

    def cost(a):
        fit = _receptance_lsfd(omega, H2, sw, q, wn, ze, band, float(a), diagram, rw)
        return float(np.sum(np.asarray(fit.fit_error) ** 2))

    grid = np.linspace(0.0, lo, 11)
    costs = [cost(a) for a in grid]
    k = int(np.argmin(costs))
    left, right = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = minimize_scalar(
        cost, bounds=(left, right), method="bounded", options={"xatol": 1e-3 * lo}
    )
    return float(res.x) if res.fun <= costs[k] else float(grid[k])


#: Heuristic: a further pole track joins the automatic mode selection of route (b) when it
#: lowers the summed squared relative misfit of both FRFs by more than this fraction (a
#: missing physical mode measured 60-85 %, a noise or duplicate track < 2 %).
MODE_GAIN = 0.1


def _add_modes_by_misfit(omega, H2, sw, q, modes, band, a_hp, diagram, rw, auto_hp: bool):
    """Forward selection on top of the stabilisation-diagram choice: the remaining pole
    tracks (stable over >= 2 orders, > 2 % away in frequency from the chosen ones) are
    tried longest first, and each joins when it lowers the summed squared LSFD misfit of
    both FRFs by more than `MODE_GAIN`. Heavily damped modes (ζ ~ 0.2) stabilise over few
    orders and may miss the diagram's default threshold, and a TMF without one of its modes
    is wrong by far more than the noise. With `auto_hp` the sensor high-pass is estimated
    again after each added mode (a missing mode biases it). `modes`: the chosen
    `(omega_n, zeta)`.

    **Returns:** `(omega_n, zeta, a_hp)`."""
    wn, ze = modes

    def misfit(w_, z_):
        fit = _receptance_lsfd(omega, H2, sw, q, w_, z_, band, a_hp, diagram, rw)
        return float(np.sum(np.asarray(fit.fit_error) ** 2))

    current = misfit(wn, ze)
    for t in pole_tracks(diagram):  # longest first
        if t.n_orders < 2 or np.any(np.abs(t.omega_n - wn) <= 0.02 * np.maximum(wn, t.omega_n)):
            continue
        trial = misfit(np.append(wn, t.omega_n), np.append(ze, t.zeta))
        if trial < (1.0 - MODE_GAIN) * current:
            wn, ze = np.append(wn, t.omega_n), np.append(ze, t.zeta)
            if auto_hp:
                a_hp = _estimate_highpass(omega, H2, sw, q, wn, ze, band, diagram, rw)
            current = misfit(wn, ze)
    order = np.argsort(wn)
    return wn[order], ze[order], a_hp


def _window_corrected(fit: ModalFit, tau: float) -> ModalFit:
    """The receptance fit of exponentially windowed FRFs moved back to the unwindowed
    system: the window `exp(-t/τ)` turns `R(s)` into `R(s + 1/τ)`, so the modes of
    `R(s + 1/τ) = Σ A_k / (s − λ_k^w) + U` are those of `R` with `λ_k = λ_k^w + 1/τ` and the
    same residues and upper residual (exact without the lower residual)."""
    wn, ze = exponential_window_correction(fit.model.omega_n, fit.model.zeta, tau)
    if np.any(np.asarray(ze) <= 0):
        raise ValueError(
            "tmf_from_impacts: a mode of the windowed FRFs is less damped than the "
            f"exponential window (tau={tau} s) alone makes it; window_tau does not match the "
            "window the FRFs were estimated with."
        )
    lam = jnp.asarray(-ze * wn + 1j * wn * jnp.sqrt(1 - ze**2))
    return ModalFit(
        model=ModalModel(wn, ze, fit.model.residues),
        lower_residual=fit.lower_residual,
        upper_residual=fit.upper_residual,
        poles=lam,
        fit_error=fit.fit_error,
        mac=fit.mac,
        omega=fit.omega,
        diagram=fit.diagram,
        quantity=fit.quantity,
    )


def _shift_polynomial(c: np.ndarray, sigma: float) -> np.ndarray:
    """Coefficients of `p(s − σ)` from those of `p(s)` (highest power first)."""
    r = np.poly1d(c)(np.poly1d([1.0, -sigma])).coeffs
    return np.concatenate([np.zeros(c.size - r.size), r])


def tmf_from_impacts(
    omega: ArrayLike,
    H_tool: ArrayLike,
    H_encoder: ArrayLike,
    *,
    band: tuple[float, float] | None = None,
    quantity: Literal["accelerance", "mobility", "receptance"] = "accelerance",
    tmf_band: tuple[float, float] | None = None,
    window_tau: float | None = None,
    highpass: float | Literal["auto"] | None = None,
    options: TMFFit | None = None,
    **keywords: Any,
) -> TMFIdentification:
    r"""Route (b): TMF from the modal parameters of two FRFs of one hammer test.

    Both FRFs (TCP response `H_TE`, encoder response `H_EE`, same hammer location) share
    their poles (pLSCF on both, `jaxvs.modal_fit`); their residues are fitted by LSFD and
    the TMF is their ratio (eq. 6) as an exact `RationalTF` (`tmf_from_modal`), or, with
    `order`, that ratio refitted over the band as a rational TMF of the given order
    (removes the noise-fitting of the residual terms and gives the real-time sensor a
    low order).

    Low frequencies (`T(0) = 1`): by default (`lower_residual=False`) the residues are
    fitted to the *receptance* `H / s^q` (`q` = 2 for accelerance) with an upper residual
    only, weighted by `|s^q|` so that the equation error stays that of the measured
    quantity. The structure is then supported (no rigid-body mass line), its static
    compliance is set by the modes, and `T(0) = R_TE(0) / R_EE(0)`, which is 1 for a
    drive- or encoder-side force and `> 1` for a TCP-side one (the data check of
    [`check_excitation_location`][] then works). `lower_residual=True` fits the measured
    quantity with both residual terms (`L + U s²` for accelerance): more freedom in the
    band, but `T(0)` is then an extrapolation of the lower residual and meaningless.

    Hammer-test processing that the FRFs may carry, undone here:

    - `window_tau`: the time constant of an exponential window applied to force and
      response (`jaxvs.signal.impact_windows(..., tau=)`). Such FRFs are those of the
      system with every pole moved by `−1/τ`; the modal fit is done on them (the extra
      damping separates the modes) and moved back exactly (`λ = λ_w + 1/τ`, residues
      unchanged), so short windows, which cut the noise of long records, cost no bias.
    - `highpass`: corner [rad/s] of a first-order high-pass `s / (s + a)` of the
      accelerometer channels (piezoelectric sensors, ICP couplings), divided out before the
      residue fit; `"auto"` estimates it from the data (the grounded receptance model
      cannot absorb its phase lead near the low band edge, so the misfit is sharp in `a`;
      needs `lower_residual=False`). It cancels in the measured TMF but not in the two
      modal fits, where it costs a few % of TMF accuracy near the anti-resonances of `H_EE`.

    **Arguments:**

    - `omega`: `(freq,)` angular frequencies [rad/s] of the FRFs.
    - `H_tool`, `H_encoder`: `(freq,)` complex FRFs of the same quantity.
    - `band` (rad/s), `quantity`: as for `jaxvs.modal_fit`.
    - `options`: a [`TMFFit`][] (`n_modes`, `max_order`, `lower_residual`, `weights`,
      `order`, `excitation`, `operation`, `static_gain`), or its fields as keywords.
    - `order`: optional `(nb, na)` of the reduced TMF.
    - `tmf_band`: `(low, high)` [rad/s] over which the reduced TMF is fitted (default
      `band`); keep it inside the band where both modal fits are good.
    - `excitation`, `operation`: see [`check_excitation_location`][] (default: hammer at
      the encoder, which gives `T^E = T^D`); `excitation=None` skips the check (a TMF
      between two arbitrary points).
    - `static_gain`: imposed `T(0)` (default 1, the drive-side TMF's; see
      [`tmf_from_accelerations`][]): the supported-structure fit gets it from the static
      compliances to ~0.1-1 %, which on millimetre moves is still comparable with the
      deflection. Applied only when the excitation check passes; `None` keeps the fitted
      gain (and so does `excitation=None`), as does a fit whose `T(0)` is more than
      `STATIC_GAIN_TOL` off (its extrapolation to 0 Hz is not a small error to correct,
      e.g. with `lower_residual=True`).
    - `window_tau`: exponential-window time constant [s] of the FRFs, or `None`.
    - `highpass`: sensor high-pass corner [rad/s], `"auto"`, or `None` (none).
    - `lower_residual`: fit the lower residual (see above); default `False`.
    - `weights`: of the residue fit (LSFD): `"uniform"` (the equation error of the
      measured quantity: right for white noise on the FRFs), `"relative"` (`1 / |H|` per
      FRF: the TMF's relative error is the difference of the two FRFs' relative errors,
      so this spends the fit where the ratio is decided, between the resonances, instead
      of on the peaks, whose leakage errors dominate measured FRFs of lightly damped
      structures), or a `(freq,)` / `(freq, 2)` array (tool, encoder).

    **Returns:** a [`TMFIdentification`][]; `details` is the `ModalFit` of both FRFs (with
    `lower_residual=False` a receptance fit, window-corrected: the modal parameters of the
    structure; with `lower_residual=True` the fit of the FRFs as given, i.e. of the
    windowed system when `window_tau` is set, see `jaxvs.signal.exponential_window_correction`).
    """
    where = "tmf_from_impacts"
    o = options_object(TMFFit, options, keywords, where)
    n_modes, max_order, lower_residual, weights = (
        o.n_modes,
        o.max_order,
        o.lower_residual,
        o.weights,
    )
    order, excitation, operation, static_gain = o.order, o.excitation, o.operation, o.static_gain
    if excitation is not None:
        _check_side(excitation, "excitation", where)
    omega = np.asarray(omega, float)
    H_tool, H_encoder = np.asarray(H_tool), np.asarray(H_encoder)
    if H_tool.shape != omega.shape or H_encoder.shape != omega.shape:
        raise ValueError(
            f"{where}: H_tool {H_tool.shape} and H_encoder {H_encoder.shape} must both be "
            f"(freq,) = {omega.shape} on one frequency grid."
        )
    if window_tau is not None and not (np.isfinite(window_tau) and window_tau > 0):
        raise ValueError(f"{where}: window_tau must be a time constant > 0 [s]; got {window_tau}.")
    if highpass == "auto" and lower_residual:
        raise ValueError(
            f"{where}: highpass='auto' needs lower_residual=False (the free lower residual "
            "absorbs the high-pass, so the data cannot tell its corner); give the corner [rad/s]."
        )
    if (
        highpass is not None
        and highpass != "auto"
        and not (np.isfinite(highpass) and highpass >= 0)
    ):
        raise ValueError(f"{where}: highpass must be a corner >= 0 [rad/s], 'auto' or None.")
    sigma = 0.0 if window_tau is None else 1.0 / float(window_tau)
    H2 = np.stack([H_tool, H_encoder], axis=-1)
    if isinstance(weights, str):
        if weights not in ("uniform", "relative"):
            raise ValueError(
                f"{where}: weights={weights!r}; use 'uniform', 'relative' or an array."
            )
        mag = np.abs(H2)
        tiny = np.finfo(float).tiny
        rw = np.ones(H2.shape) if weights == "uniform" else 1.0 / np.maximum(mag, tiny)
    else:
        rw = np.broadcast_to(np.asarray(weights, float).reshape(omega.shape[0], -1), H2.shape)
        if not (np.all(np.isfinite(rw)) and np.all(rw >= 0)):
            raise ValueError(f"{where}: weights must be finite and >= 0.")
    fit = modal_fit(
        jnp.asarray(omega),
        jnp.asarray(H2),
        n_modes=n_modes,
        band=band,
        quantity=quantity,
        max_order=max_order,
    )
    q = {"receptance": 0, "mobility": 1, "accelerance": 2}[quantity]
    sw = 1j * omega + sigma  # the windowed FRFs are H(jω + σ)
    wn, ze = np.asarray(fit.model.omega_n), np.asarray(fit.model.zeta)
    if highpass == "auto":
        a_hp = _estimate_highpass(omega, H2, sw, q, wn, ze, band, fit.diagram, rw)
    else:
        a_hp = 0.0 if highpass is None else float(highpass)
    if n_modes is None and not lower_residual:
        wn, ze, a_hp = _add_modes_by_misfit(
            omega, H2, sw, q, (wn, ze), band, a_hp, fit.diagram, rw, highpass == "auto"
        )
    if not lower_residual:
        fit = _receptance_lsfd(omega, H2, sw, q, wn, ze, band, a_hp, fit.diagram, rw)
        if sigma > 0:
            fit = _window_corrected(fit, float(window_tau))
        model = tmf_from_modal(fit.frf(0), fit.frf(1)).to_rational()
    else:
        if a_hp > 0:
            H2 = H2 / _highpass(sw, a_hp)[:, None]
        if a_hp > 0 or not np.all(rw == 1.0):
            fit = lsfd(
                omega, H2, wn, ze, quantity=quantity, band=band, diagram=fit.diagram, weights=rw
            )
        model = tmf_from_modal(fit.frf(0), fit.frf(1)).to_rational()
        if sigma > 0:  # T(s) = T_w(s − σ), exact for the rational ratio
            num = _shift_polynomial(np.asarray(model.num), sigma)
            den = _shift_polynomial(np.asarray(model.den), sigma)
            model = RationalTF(jnp.asarray(num), jnp.asarray(den))
    if order is not None:
        rng = tmf_band if tmf_band is not None else band
        sel = np.ones_like(omega, bool) if rng is None else (omega >= rng[0]) & (omega <= rng[1])
        w = omega[sel & (omega > 0)]
        # heuristic: weights 1/sqrt|T|, between uniform (the sharp TMF peaks at the
        # anti-resonances of H_EE, where the modal ratio is least certain, would dominate)
        # and relative (the top of the band, where |T| << 1 and the TCP response is buried in
        # noise, would): on the twin's hammer tests 1.8 % mean error to the truth for a
        # (2, 4) / (4, 4) reduction over 5-684 Hz, against 4.4 % / 3.1 % with 1/|T|
        T = frequency_response(model, jnp.asarray(w))
        model, _ = fit_rational(jnp.asarray(w), T, order, weights=1.0 / jnp.sqrt(jnp.abs(T)))
    if excitation is not None:
        low = tmf_band if tmf_band is not None else band
        w_low = float(low[0]) if low is not None else float(omega[omega > 0][0])
        drive_side = check_excitation_location(
            model, excitation=excitation, operation=operation, omega_low=w_low
        )
        model = _impose_static_gain(model, static_gain, drive_side)
    side = excitation if excitation is not None else "unspecified"
    return TMFIdentification(model, "impacts", side, None, fit)


def _force_band(force: np.ndarray, fs: float, drop_db: float) -> float:
    """Highest frequency [Hz] below which the mean force auto-spectrum stays within
    `drop_db` of its low-frequency level (the usual hammer-tip bandwidth criterion, e.g.
    Ewins, *Modal Testing*, 2000, §3.6: use the band where the force spectrum has dropped
    by less than 10-20 dB), capped at 0.4 fs (the anti-alias band)."""
    F = np.mean(np.abs(np.fft.rfft(force, axis=-1)) ** 2, axis=tuple(range(force.ndim - 1)))
    f = np.fft.rfftfreq(force.shape[-1], 1.0 / fs)
    ref = np.median(F[(f > 0) & (f <= 0.05 * fs)])
    below = np.nonzero((F < ref * 10 ** (-drop_db / 10)) & (f > 0))[0]
    top = f[below[0]] if below.size else f[-1]
    return float(min(top, 0.4 * fs))


def _decay_tau(responses: list[np.ndarray], fs: float) -> float:
    """Heuristic exponential-window time constant [s]: a tenth of the time after which the
    responses' envelope (RMS over hits, 10 ms moving average) has sunk to 3x the noise
    level of the last fifth of the record (at least 20 samples). The window's damping is
    removed exactly, so a short window costs no bias while it cuts the noise of the tail;
    on the twin, τ = 0.05-0.08 s (a tenth of the ~0.7 s decay) measured 1.7 % mean / 4.1 %
    worst TMF error against 2.0 % / 6.2 % for a quarter of it."""
    t_end = 0.0
    for x in responses:
        x = np.reshape(x, (-1, x.shape[-1]))
        n = x.shape[-1]
        noise = np.sqrt(np.mean(x[:, int(0.8 * n) :] ** 2))
        k = max(int(0.01 * fs), 1)
        env = np.sqrt(np.convolve(np.mean(x**2, axis=0), np.ones(k) / k, mode="same"))
        above = np.nonzero(env > 3 * noise)[0]
        t_end = max(t_end, (above[-1] + 1) / fs if above.size else n / fs)
    return max(t_end / 10, 20.0 / fs)


def tmf_from_hammer(
    force: ArrayLike,
    a_tool: ArrayLike,
    a_encoder: ArrayLike,
    fs: float,
    *,
    band: tuple[float, float] | None = None,
    tau: float | Literal["auto"] | None = "auto",
    highpass: float | Literal["auto"] | None = "auto",
    tmf_band: tuple[float, float] | None = None,
    options: TMFFit | None = None,
    **keywords: Any,
) -> TMFIdentification:
    r"""Route (b) from raw hammer records: H1 FRFs with impact windows, then
    [`tmf_from_impacts`][].

    The force window keeps the pulse (`jaxvs.signal.impact_windows`) and an exponential
    window of time constant `tau` multiplies force and responses, which cuts the noise of
    the record's tail where the response has died out (the dominant error of an
    unwindowed FRF of a well-damped structure); its extra damping is removed exactly in the
    modal fit. H1 (`jaxvs.signal.frf_h1`) averages the hits (noise on the response).

    **Arguments:**

    - `force`: `(hit, time)` or `(time,)` hammer force [N], one record per hit, each
      starting shortly before its hit.
    - `a_tool`, `a_encoder`: accelerations [m/s²] at the TCP and the encoder, same shape.
    - `fs`: sampling rate [Hz].
    - `band`: `(low, high)` [Hz] of the modal fit; default from 5 Hz (accelerometers are
      unreliable below) to where the force spectrum has dropped by 10 dB (the hammer's
      band), at most 0.4 fs.
    - `tau`: exponential-window time constant [s]; `"auto"` (default): a tenth of the
      time after which the responses sink into their noise; `None`: no exponential window.
    - `highpass`: accelerometer high-pass corner [**Hz**], `"auto"` (default) or `None`;
      see [`tmf_from_impacts`][].
    - `tmf_band` [**Hz**]: as in [`tmf_from_impacts`][] (default `band`).
    - `options`: a [`TMFFit`][] (modal fit, residue fit, reduction, excitation check), or
      its fields as keywords, as in [`tmf_from_impacts`][].

    **Returns:** a [`TMFIdentification`][] with route `"impacts"`; `estimate` is the
    measured TMF `H_TE / H_EE` of plain H1 estimates (force window only, kind
    `"transmissibility"`, coherence the smaller of both FRFs'); `details` the `ModalFit`.

    **Raises:** `ValueError` for records of different shapes, a record too short for the
    band, or a bad `tau`.
    """
    from ...data import FRFData
    from ...signal import frf_h1, impact_windows

    where = "tmf_from_hammer"
    options = options_object(TMFFit, options, keywords, where)
    force = np.asarray(force, float)
    a_tool, a_encoder = np.asarray(a_tool, float), np.asarray(a_encoder, float)
    if not (force.shape == a_tool.shape == a_encoder.shape) or force.ndim not in (1, 2):
        raise ValueError(
            f"{where}: force {force.shape}, a_tool {a_tool.shape} and a_encoder "
            f"{a_encoder.shape} must be synchronised records of one shape, (time,) or "
            "(hit, time)."
        )
    force, a_tool, a_encoder = (np.atleast_2d(x) for x in (force, a_tool, a_encoder))
    n = force.shape[-1]
    if band is None:
        band = (5.0, _force_band(force, fs, 10.0))
    if not 0 < band[0] < band[1] <= fs / 2:
        raise ValueError(f"{where}: band must satisfy 0 < low < high <= fs/2 [Hz]; got {band}.")
    if n < 4 * fs / band[0]:
        raise ValueError(
            f"{where}: records of {n / fs:.3g} s resolve {fs / n:.3g} Hz; the band starts at "
            f"{band[0]} Hz, which needs records of at least {4 / band[0]:.3g} s."
        )
    if tau == "auto":
        tau = _decay_tau([a_tool, a_encoder], fs)
    elif tau is not None and not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"{where}: tau must be > 0 [s], 'auto' or None; got {tau!r}.")
    wf, wr = impact_windows(jnp.asarray(force), fs, tau=tau)
    kw = dict(records_axis=0, input_unit="N", output_unit="m/s^2", kind="accelerance")
    acc = jnp.asarray(np.stack([a_tool, a_encoder], axis=1))  # (hit, 2, time)
    frf = frf_h1(jnp.asarray(force)[:, None], acc, fs, window=(wf[:, None], wr[:, None]), **kw)
    f = np.asarray(frf.frequency)
    keep = f > 0
    H = np.asarray(frf.H)[:, keep]  # (2, freq)
    if tau is None:
        plain = frf
    else:
        wf0, wr0 = impact_windows(jnp.asarray(force), fs)
        plain = frf_h1(
            jnp.asarray(force)[:, None], acc, fs, window=(wf0[:, None], wr0[:, None]), **kw
        )
    Hp = np.asarray(plain.H)
    T = np.where(Hp[1] != 0, Hp[0] / np.where(Hp[1] != 0, Hp[1], 1.0), 0.0)
    estimate = FRFData(
        f,
        T,
        coherence=np.min(np.asarray(plain.coherence), axis=0),
        n_averages=plain.n_averages,
        kind="transmissibility",
        metadata={"estimator": "h1 ratio", "fs": float(fs), "route": "impacts"},
    )
    hp = (
        None
        if highpass is None
        else ("auto" if highpass == "auto" else 2 * np.pi * float(highpass))
    )
    result = tmf_from_impacts(
        2 * np.pi * f[keep],
        H[0],
        H[1],
        band=(2 * np.pi * band[0], 2 * np.pi * band[1]),
        quantity="accelerance",
        tmf_band=None if tmf_band is None else (2 * np.pi * tmf_band[0], 2 * np.pi * tmf_band[1]),
        window_tau=tau,
        highpass=hp,
        options=options,
    )
    return result._replace(estimate=estimate)


# The options of `tmf_from_frfs` besides the ratio's fit, and their defaults.
_FRF_OPTIONS: dict[str, Any] = dict(
    n_modes=None, lower_residual=True, max_order=40, excitation=None, operation="drive"
)


def tmf_from_frfs(
    frf_response: FRFData,
    frf_reference: FRFData,
    order: tuple[int, int] | int | None = None,
    *,
    route: Literal["rational", "modal"] = "rational",
    band: tuple[float, float] | None = None,
    weights: Literal["uniform", "relative"] | ArrayLike = "uniform",
    stable: bool = True,
    **options: Any,
) -> TMFIdentification:
    r"""Transmissibility `T = H_response / H_reference` of two measured FRFs with one
    excitation point (eq. 6), identified by either route.

    - `route="rational"`: a rational TMF of order `order` (default `(4, 4)`) fitted
      directly to the measured ratio (`jaxvs.fit_rational`);
    - `route="modal"`: modal fits of both FRFs with shared poles and the TMF from the modal
      parameters ([`tmf_from_impacts`][]; `order` then reduces it).

    Without coherence, the ratio is weighted `"uniform"`ly, `"relative"`ly, or by a given
    array. Bins where `|H_reference|` is small (its anti-resonances) make the measured ratio
    large and noisy; keep them out of `band` or down-weight them.

    **Arguments:**

    - `frf_response`, `frf_reference`: single `FRFData` (no family) on one frequency grid,
      of the same kind (e.g. accelerance, hammer at one point, responses at two points; by
      reciprocity also one response point and a roving hammer). Bin 0 is skipped.
    - `order`: `(nb, na)` or `n` for `(n, n)`.
    - `route`: see above.
    - `band`: `(low, high)` [Hz] of the fit (default: every bin above 0).
    - `weights`: rational route: weights of the ratio (`"relative"` = `1 / |T|`); modal
      route: weights of the residue fit (see [`tmf_from_impacts`][]).
    - `stable`: rational route: keep the poles in the left half-plane. A TMF's poles are
      the zeros of `H_reference`, which for a transfer (not driving-point) FRF may lie in
      the right half-plane: pass `False` when the fit reports unstable-looking data.
    - `**options` (keywords; defaults in `_FRF_OPTIONS`):
        - `n_modes` (`None`), `lower_residual` (`True`), `max_order` (40): modal route, see
          [`tmf_from_impacts`][]; `lower_residual` defaults to `True` here (any structure,
          e.g. free-free: `T(0)` is then not identified).
        - `excitation` (`None`: skipped), `operation` (`"drive"`): optional
          [`check_excitation_location`][].

    **Returns:** a [`TMFIdentification`][] with route `"ratio"` or `"modal"`; `estimate` is
    the measured ratio (`FRFData`, kind `"transmissibility"`, coherence the smaller of both
    FRFs' when they carry one), `details` the `FitReport` or `ModalFit`.
    """
    where = "tmf_from_frfs"
    unknown = sorted(set(options) - set(_FRF_OPTIONS))
    if unknown:
        raise TypeError(
            f"{where}: unknown option(s) {unknown}; the options are {list(_FRF_OPTIONS)}."
        )
    o = {**_FRF_OPTIONS, **options}
    n_modes, lower_residual, max_order = o["n_modes"], o["lower_residual"], o["max_order"]
    excitation, operation = o["excitation"], o["operation"]
    for name, d in (("frf_response", frf_response), ("frf_reference", frf_reference)):
        if not isinstance(d, FRFData):
            raise TypeError(
                f"{where}: {name} must be a jaxvs.data.FRFData; got {type(d).__name__}. Wrap "
                "arrays with FRFData(frequency_hz, H, kind='accelerance')."
            )
        if d.batch_shape or d.io_shape:
            raise ValueError(f"{where}: {name} must hold one FRF (no family, no io axes).")
    if route not in ("rational", "modal"):
        raise ValueError(f"{where}: route={route!r}; use 'rational' or 'modal'.")
    if excitation is not None:
        _check_side(excitation, "excitation", where)
    f = np.asarray(frf_response.frequency, float)
    if f.shape != np.asarray(frf_reference.frequency).shape or not np.allclose(
        f, np.asarray(frf_reference.frequency)
    ):
        raise ValueError(f"{where}: the two FRFs must share one frequency grid; resample one.")
    if frf_response.kind != frf_reference.kind:
        raise ValueError(
            f"{where}: a TMF relates two FRFs of one quantity; got {frf_response.kind} and "
            f"{frf_reference.kind}."
        )
    Ha, Hb = np.asarray(frf_response.H), np.asarray(frf_reference.H)
    lo, hi = (0.0, np.inf) if band is None else (float(band[0]), float(band[1]))
    sel = (f > 0) & (f >= lo) & (f <= hi)
    if band is not None and not lo < hi:
        raise ValueError(f"{where}: band must be (low, high) with low < high [Hz]; got {band}.")
    if np.any(Hb[sel] == 0):
        raise ValueError(f"{where}: frf_reference is exactly 0 in the band; drop those bins.")
    T = np.zeros_like(Ha)
    T[sel] = Ha[sel] / Hb[sel]
    coh = None
    if frf_response.coherence is not None and frf_reference.coherence is not None:
        coh = np.minimum(np.asarray(frf_response.coherence), np.asarray(frf_reference.coherence))
    estimate = FRFData(
        f,
        T,
        coherence=coh,
        kind="transmissibility",
        metadata={"estimator": "ratio of FRFs"},
    )
    w = 2 * np.pi * f[sel]
    if route == "rational":
        nb, na = (4, 4) if order is None else (order, order) if isinstance(order, int) else order
        if isinstance(weights, str):
            if weights not in ("uniform", "relative"):
                raise ValueError(
                    f"{where}: weights={weights!r}; use 'uniform', 'relative' or an array."
                )
            wt = np.ones(w.shape) if weights == "uniform" else 1.0 / np.abs(T[sel])
        else:
            wt = np.asarray(weights, float)
            wt = wt[sel] if wt.shape == f.shape else wt
        if 2 * int(np.sum(wt > 0)) < nb + na + 1:
            raise ValueError(
                f"{where}: {int(np.sum(wt > 0))} weighted bins cannot determine a TMF of order "
                f"({nb}, {na}); widen the band or lower the order."
            )
        model, report = fit_rational(
            jnp.asarray(w), jnp.asarray(T[sel]), (nb, na), weights=jnp.asarray(wt), stable=stable
        )
        if excitation is not None:
            check_excitation_location(
                model, excitation=excitation, operation=operation, omega_low=float(w[0])
            )
        return TMFIdentification(
            model,
            "ratio",
            excitation if excitation is not None else "unspecified",
            estimate,
            report,
        )
    kind = frf_response.kind if frf_response.kind in ("receptance", "mobility") else "accelerance"
    if isinstance(weights, str):
        rw = weights
    else:
        rw = np.asarray(weights, float)
        rw = rw[sel] if rw.shape[0] == f.shape[0] else rw
    result = tmf_from_impacts(
        w,
        Ha[sel],
        Hb[sel],
        n_modes=n_modes,
        quantity=kind,
        order=order,
        excitation=excitation,
        operation=operation,
        lower_residual=lower_residual,
        max_order=max_order,
        weights=rw,
    )
    return result._replace(route="modal", estimate=estimate)


def _stacked_simulation(model, data, *, method: str):
    """Every experiment in one batched `simulate` call (data time axis first)."""
    return simulate(model, data["u"].T, data["dt"], method=method).T


def tmf_from_time_domain(
    guess: RationalTF,
    x_encoder: ArrayLike,
    x_tool: ArrayLike,
    dt: float,
    *,
    method: Literal["zoh", "tustin"] = "zoh",
    skip: int = 0,
    equal_orders: bool = True,
    excitation: Side = "drive",
    operation: Literal["drive", "tcp"] = "drive",
    **calibrate_options: Any,
) -> TMFIdentification:
    r"""Route (c): TMF calibrated by simulation error on excitation records.

    Minimises `Σ_k (T ⊛ x_E − x_T)_k²` over the coefficients of `guess` (Levenberg-
    Marquardt through `jaxvs.calibrate`, the denominator kept stable by
    `jaxvs.calibration.stable`), simulating every record from rest in one batched call.
    `"zoh"` is recommended: the zero-order-hold discretisation of a TMF of equal orders
    is a general discrete TF of that order, so it also absorbs the inter-sample
    behaviour of the sampled encoder signal.

    **Arguments:**

    - `guess`: stable initial `RationalTF` (e.g. from route (a)).
    - `x_encoder`, `x_tool`: `(time,)` or `(experiment, time)` encoder and reference TCP
      positions [m], sampled every `dt` [s], from rest.
    - `method`: discretisation used in the fit (and to be used by the sensor).
    - `skip`: initial samples excluded from the residual.
    - `equal_orders`: pad the guess's numerator to the denominator order (a TMF of equal
      orders, eq. 8); its extra coefficients start at zero and absorb the inter-sample
      behaviour of the encoder signal under the zero-order hold.
    - `excitation`, `operation`: see [`check_excitation_location`][].
    - `calibrate_options`: passed to `jaxvs.calibrate` (`max_steps`, `rtol`, `throw`, ...).

    **Returns:** a [`TMFIdentification`][] (`details` is the `CalibrationResult`, whose
    `model` is the reparametrised TMF).
    """
    where = "tmf_from_time_domain"
    _check_side(excitation, "excitation", where)
    if not isinstance(guess, RationalTF) or guess.batch_shape != ():
        raise TypeError(f"{where}: guess must be one (unbatched) RationalTF.")
    xe = np.atleast_2d(np.asarray(x_encoder, float))
    xt = np.atleast_2d(np.asarray(x_tool, float))
    if xe.shape != xt.shape or xe.ndim != 2:
        raise ValueError(
            f"{where}: x_encoder {xe.shape} and x_tool {xt.shape} must have the same shape "
            "(time,) or (experiment, time), sampled on one time base; resample first."
        )
    n_par = guess.num.shape[-1] + guess.den.shape[-1] - 1
    if xe.shape[-1] - skip < 4 * n_par:
        raise ValueError(
            f"{where}: {xe.shape[-1] - skip} samples are too few for a TMF with {n_par} "
            "coefficients (need >= 4 per coefficient); record longer or lower the order."
        )
    lead = float(guess.den[0])
    num = guess.num
    if equal_orders and num.shape[-1] < guess.den.shape[-1]:
        num = jnp.concatenate([jnp.zeros(guess.den.shape[-1] - num.shape[-1], num.dtype), num])
    g = stable(RationalTF(num / lead, guess.den / lead))
    data = {"u": jnp.asarray(xe.T), "y": jnp.asarray(xt.T), "dt": float(dt)}
    residual = SimulationError(functools.partial(_stacked_simulation, method=method), skip=skip)
    options = {"covariance": False} | calibrate_options
    result: CalibrationResult = calibrate(g, data, residual, **options)
    model = unwrap(result.model)
    check_excitation_location(model, excitation=excitation, operation=operation)
    return TMFIdentification(model, "time_domain", excitation, None, result)


# -- families smooth in position -------------------------------------------------------


def _vander(y: Array, degree: int) -> Array:
    return y[..., None] ** jnp.arange(degree + 1, dtype=y.dtype)


def _tmf_law(
    params, y, *, y0: float, y_scale: float, w0: float, nb: int, unit_gain: bool = False
) -> RationalTF:
    """Rational TMF at position `y`: log-frequencies, log-dampings of the second-order
    sections and the scaled numerator coefficients are polynomials in the normalised
    position `(y − y0) / y_scale` (always-stable denominator). With `unit_gain` the
    numerator's constant term equals the denominator's (`T(0) = 1` at every position)
    and `params["num"]` holds the other `nb` coefficients."""
    v = _vander((y - y0) / y_scale, params["log_omega"].shape[0] - 1)
    w = jnp.exp(v @ params["log_omega"])
    z = jnp.exp(v @ params["log_zeta"])
    den = jnp.ones((1,), w.dtype)
    for k in range(w.shape[-1]):
        den = jnp.convolve(den, jnp.stack([jnp.ones((), w.dtype), 2 * z[k] * w[k], w[k] ** 2]))
    b = v @ params["num"]  # coefficients of (s / w0)^(nb .. 0), or (nb .. 1) with unit_gain
    num = b / w0 ** jnp.arange(nb, nb - b.shape[-1], -1, dtype=b.dtype)
    if unit_gain:
        num = jnp.concatenate([num, den[-1:]])
    return RationalTF(num, den)


def tmf_family(
    omega: ArrayLike,
    H: ArrayLike,
    positions: ArrayLike,
    order: tuple[int, int] = (2, 4),
    *,
    degree: int = 2,
    weights: ArrayLike | None = None,
    unit_static_gain: bool = True,
    **calibrate_options: Any,
) -> tuple[SmoothFamily, CalibrationResult]:
    r"""A TMF family smooth in the position of another axis, calibrated in one call.

    1. One rational TMF per measured position (`fit_rational`, vectorised);
    2. a polynomial law of degree `degree` in the position for the log natural
       frequencies and log damping ratios of the poles and for the (scaled) numerator
       coefficients, initialised by least squares on the per-position fits;
    3. all law coefficients calibrated jointly on all positions' FRFs
       (`calibrate_family(..., positions=...)` with `FrequencyError`).

    The result predicts the TMF at positions never measured: `family.at(y_new)`.

    **Arguments:**

    - `omega`: `(freq,)` angular frequencies [rad/s].
    - `H`: `(position, freq)` measured TMFs (e.g. route (a) estimates).
    - `positions`: `(position,)` positions of the other axis [m], at least `degree + 1`.
    - `order`: `(nb, na)` with even `na` (second-order sections).
    - `degree`: polynomial degree in the position.
    - `weights`: optional `(position, freq)` or `(freq,)` weights (e.g. coherence based).
    - `unit_static_gain`: every member has `T(0) = 1` by construction (drive-side TMFs;
      the measured band usually starts above the frequencies that fix the static gain,
      whose error would otherwise dominate the virtual sensor on large moves). `False`
      fits the constant numerator term like the others (TCP-side or other transfer
      functions).
    - `calibrate_options`: passed to `calibrate_family`.

    **Returns:** `(family, result)`: a `jaxvs.models.SmoothFamily` and the
    `CalibrationResult` of the joint calibration.
    """
    where = "tmf_family"
    omega = np.asarray(omega, float)
    H = np.asarray(H)
    y = np.asarray(positions, float)
    nb, na = order
    if na % 2:
        raise ValueError(f"{where}: the denominator order must be even (sections); got {na}.")
    if H.ndim != 2 or H.shape != (y.shape[0], omega.shape[0]):
        raise ValueError(
            f"{where}: H must be (position, freq) = ({y.shape[0]}, {omega.shape[0]}); "
            f"got {H.shape}."
        )
    if y.shape[0] < degree + 1:
        raise ValueError(
            f"{where}: a law of degree {degree} needs at least {degree + 1} positions; got "
            f"{y.shape[0]}. Measure more positions or lower the degree."
        )
    wts = None if weights is None else np.broadcast_to(np.asarray(weights, float), H.shape)
    fits, _ = fit_rational(
        jnp.asarray(omega), jnp.asarray(H), order, weights=None if wts is None else jnp.asarray(wts)
    )
    den = np.asarray(fits.den)
    num = np.asarray(fits.num) / den[:, :1]
    lw, lz = [], []
    for d in den:
        p = np.roots(d)
        p = p[p.imag > 0] if np.sum(p.imag > 0) == na // 2 else np.sort_complex(p)[: na // 2]
        p = p[np.argsort(np.abs(p))]
        lw.append(np.log(np.abs(p)))
        lz.append(np.log(np.clip(-p.real / np.abs(p), 1e-4, None)))
    w0 = float(np.exp(np.mean(lw)))
    y0 = float(0.5 * (y.min() + y.max()))
    ys = float(max(0.5 * (y.max() - y.min()), 1e-12))
    V = np.asarray(_vander(jnp.asarray((y - y0) / ys), degree))
    lsq = lambda target: np.linalg.lstsq(V, np.asarray(target), rcond=None)[0]  # noqa: E731
    b = num * w0 ** np.arange(nb, -1, -1)
    if unit_static_gain:
        b = b[:, :-1]
    params = {
        "log_omega": jnp.asarray(lsq(lw)),
        "log_zeta": jnp.asarray(lsq(lz)),
        "num": jnp.asarray(lsq(b)),
    }
    law = functools.partial(_tmf_law, y0=y0, y_scale=ys, w0=w0, nb=nb, unit_gain=unit_static_gain)
    family = SmoothFamily(law, params)
    data = [
        {"omega": jnp.asarray(omega), "H": jnp.asarray(H[i])}
        | ({} if wts is None else {"weights": jnp.asarray(wts[i])})
        for i in range(y.shape[0])
    ]
    options = {"covariance": False} | calibrate_options
    result = calibrate_family(family, data, FrequencyError(), positions=jnp.asarray(y), **options)
    return result.model, result


def family_error(family: SmoothFamily, positions: ArrayLike, omega: ArrayLike, truth: ArrayLike):
    """Relative L2 error `||T_family(y) − T_true(y)|| / ||T_true(y)||` per position.

    **Arguments:** `family` (anything with `at(positions)`), `positions` `(n,)` [m],
    `omega` `(freq,)` [rad/s], `truth` `(n, freq)` complex.

    **Returns:** `(n,)` numpy array.
    """
    G = np.asarray(frequency_response(family.at(jnp.asarray(positions)), jnp.asarray(omega)))
    T = np.asarray(truth)
    return np.linalg.norm(G - T, axis=-1) / np.linalg.norm(T, axis=-1)
