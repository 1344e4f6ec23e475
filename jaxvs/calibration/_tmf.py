r"""Identification of transmissibility functions (TMFs) for the TCP virtual sensor.

Three routes of the TMF study (Doerrer et al. 2022, §2.4-3.3), all returning a
`jaxvs.RationalTF` of the drive-side TMF `T_TE^D = x_T / x_E`:

- [`tmf_from_accelerations`][]: H1 estimate from two synchronised accelerometers (TCP and
  encoder) under drive-side excitation, fitted as a rational TMF with coherence weights;
- [`tmf_from_impacts`][]: modal fits of the FRFs `H_TE` and `H_EE` of a hammer test at the
  encoder, TMF from the modal parameters (eq. 6);
- [`tmf_from_time_domain`][]: simulation-error calibration on an excitation record
  (encoder position in, reference TCP position out).

A TMF depends on where the force acts (eq. 6, Fig. 4): `T^D ≈ T^E ≠ T^T`. Each route
checks the excitation location ([`check_excitation_location`][]) and warns with an
[`ExcitationLocationWarning`][] when the TMF meant for drive-side operation was identified
with TCP-side excitation. [`tmf_family`][] identifies a family smooth in the position of
another axis in one vectorised calibration.
"""

import functools
import warnings
from typing import Any, Literal, NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from ..data import FRFData
from ..models import RationalTF, SmoothFamily, frequency_response, simulate, static_gain
from ..signal import transmissibility
from ._calibrate import CalibrationResult, calibrate
from ._family import calibrate_family
from ._fit_rational import fit_rational
from ._modal_fit import modal_fit, tmf_from_modal
from ._parametrise import stable, unwrap
from ._residuals import FrequencyError, SimulationError

Side = Literal["drive", "encoder", "tcp"]
_SIDES = ("drive", "encoder", "tcp")

#: Tolerance of the data-based check: a drive- or encoder-side TMF has `T(0) = 1` (the
#: structure beyond the encoder moves rigidly under a static drive force); TCP-side
#: excitation gives `T(0) = H_TT(0) / H_ET(0) > 1`. Heuristic: 10 %.
STATIC_GAIN_TOL = 0.1


class ExcitationLocationWarning(UserWarning):
    """A TMF was identified with the force on the wrong side for its intended use."""


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
    check_excitation_location(
        model, excitation=excitation, operation=operation, omega_low=float(omega[0])
    )
    return TMFIdentification(model, "accelerations", excitation, est, report)


def tmf_from_impacts(
    omega: ArrayLike,
    H_tool: ArrayLike,
    H_encoder: ArrayLike,
    *,
    n_modes: int | None = None,
    band: tuple[float, float] | None = None,
    quantity: Literal["accelerance", "mobility", "receptance"] = "accelerance",
    order: tuple[int, int] | int | None = None,
    tmf_band: tuple[float, float] | None = None,
    excitation: Side = "encoder",
    operation: Literal["drive", "tcp"] = "drive",
) -> TMFIdentification:
    r"""Route (b): TMF from the modal parameters of two FRFs of one hammer test.

    Both FRFs (TCP response `H_TE`, encoder response `H_EE`, same hammer location) are
    fitted together by `modal_fit` (pLSCF poles shared, LSFD residues), and the TMF is
    their ratio (eq. 6) as an exact `RationalTF` of order `2m + 2` (`tmf_from_modal`), or,
    with `order`, that ratio refitted over the band as a rational TMF of the given order
    (removes the noise-fitting of the residual terms and gives the real-time sensor a
    low order).

    **Arguments:**

    - `omega`: `(freq,)` angular frequencies [rad/s] of the FRFs.
    - `H_tool`, `H_encoder`: `(freq,)` complex FRFs of the same quantity.
    - `n_modes`, `band` (rad/s), `quantity`: as for `jaxvs.modal_fit`.
    - `order`: optional `(nb, na)` of the reduced TMF.
    - `tmf_band`: `(low, high)` [rad/s] over which the reduced TMF is fitted (default
      `band`); keep it inside the band where both modal fits are good.
    - `excitation`, `operation`: see [`check_excitation_location`][] (default: hammer at
      the encoder, which gives `T^E = T^D`).

    **Returns:** a [`TMFIdentification`][] (`details` is the `ModalFit` of both FRFs).
    """
    where = "tmf_from_impacts"
    _check_side(excitation, "excitation", where)
    omega = np.asarray(omega, float)
    H_tool, H_encoder = np.asarray(H_tool), np.asarray(H_encoder)
    if H_tool.shape != omega.shape or H_encoder.shape != omega.shape:
        raise ValueError(
            f"{where}: H_tool {H_tool.shape} and H_encoder {H_encoder.shape} must both be "
            f"(freq,) = {omega.shape} on one frequency grid."
        )
    fit = modal_fit(
        jnp.asarray(omega),
        jnp.asarray(np.stack([H_tool, H_encoder], axis=-1)),
        n_modes=n_modes,
        band=band,
        quantity=quantity,
    )
    tmf = tmf_from_modal(fit.frf(0), fit.frf(1))
    if order is None:
        model = tmf.to_rational()
    else:
        rng = tmf_band if tmf_band is not None else band
        sel = np.ones_like(omega, bool) if rng is None else (omega >= rng[0]) & (omega <= rng[1])
        w = omega[sel]
        # heuristic: relative weights, so the sharp TMF peaks (anti-resonances of H_EE, where
        # the modal ratio is least certain) do not dominate the reduced fit
        T = tmf.response(jnp.asarray(w))
        model, _ = fit_rational(jnp.asarray(w), T, order, weights=1.0 / jnp.abs(T))
    low = tmf_band if tmf_band is not None else band
    w_low = float(low[0]) if low is not None else float(omega[omega > 0][0])
    check_excitation_location(model, excitation=excitation, operation=operation, omega_low=w_low)
    return TMFIdentification(model, "impacts", excitation, None, fit)


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


def _tmf_law(params, y, *, y0: float, y_scale: float, w0: float, nb: int) -> RationalTF:
    """Rational TMF at position `y`: log-frequencies, log-dampings of the second-order
    sections and the scaled numerator coefficients are polynomials in the normalised
    position `(y − y0) / y_scale` (always-stable denominator)."""
    v = _vander((y - y0) / y_scale, params["log_omega"].shape[0] - 1)
    w = jnp.exp(v @ params["log_omega"])
    z = jnp.exp(v @ params["log_zeta"])
    den = jnp.ones((1,), w.dtype)
    for k in range(w.shape[-1]):
        den = jnp.convolve(den, jnp.stack([jnp.ones((), w.dtype), 2 * z[k] * w[k], w[k] ** 2]))
    b = v @ params["num"]  # coefficients of (s / w0)^(nb .. 0)
    num = b / w0 ** jnp.arange(nb, -1, -1, dtype=b.dtype)
    return RationalTF(num, den)


def tmf_family(
    omega: ArrayLike,
    H: ArrayLike,
    positions: ArrayLike,
    order: tuple[int, int] = (2, 4),
    *,
    degree: int = 2,
    weights: ArrayLike | None = None,
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
    params = {
        "log_omega": jnp.asarray(lsq(lw)),
        "log_zeta": jnp.asarray(lsq(lz)),
        "num": jnp.asarray(lsq(b)),
    }
    law = functools.partial(_tmf_law, y0=y0, y_scale=ys, w0=w0, nb=nb)
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
