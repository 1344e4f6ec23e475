"""Modal fitting of measured FRFs (poles by pLSCF, residues by LSFD) and TMFs from it.

The classical two-step experimental modal analysis (Peeters et al., "The PolyMAX
frequency-domain method", Shock and Vibration 11, 2004, §2.3):

1. poles `λ_k` from the stabilisation diagram of the pLSCF estimator
   ([`stabilisation_diagram`][], [`select_poles`][]);
2. residues and out-of-band residual terms by linear least squares in the frequency
   domain (LSFD, eq. 14) for the chosen poles ([`lsfd`][]).

The result is a [`ModalFit`][]: a `jaxvs.ModalModel` of the measured quantity plus the
residual terms reported separately, so that
`frequency_response(fit.model, ω) + fit.residual_response(ω)` reproduces the data.

Transmissibilities (Doerrer et al. 2022, J. Manuf. Mater. Process. 6, 137, eq. 6 and
§3.3, Figures 7-8): `T_ab = H_ac / H_bc` from the modal fits of two FRFs with the same
excitation point ([`tmf_from_modal`][]); when both FRFs come from one fit they share the
denominator and `T_ab = N_a / N_b` is an exact `RationalTF` of equal orders.
"""

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from ..models import ModalModel, RationalTF, frequency_response
from ._lscf import (
    StabilisationCriteria,
    StabilisationDiagram,
    _frfdata_arrays,
    prepare_frf,
    select_poles,
    stabilisation_diagram,
)

Quantity = Literal["receptance", "mobility", "accelerance"]
# Power q of s that turns displacement per force into the quantity: H_q = s^q H_0.
_QUANTITY_POWER = {"receptance": 0, "mobility": 1, "accelerance": 2}


def _resolve_quantity(quantity: str | None, data, where: str) -> str:
    """`quantity`, defaulting to the `kind` of an `FRFData` and then to accelerance."""
    from ..data import FRFData

    kind = data.kind if isinstance(data, FRFData) else None
    if quantity is None:
        quantity = kind if kind in _QUANTITY_POWER else "accelerance"
    _quantity_power(quantity, where)
    if kind in _QUANTITY_POWER and kind != quantity:
        raise ValueError(
            f"{where}: the FRFData holds {kind} data but quantity={quantity!r} was given; "
            "leave quantity out to use the data's kind."
        )
    return quantity


def _quantity_power(quantity: str, where: str) -> int:
    if quantity not in _QUANTITY_POWER:
        raise ValueError(
            f"{where}: quantity must be 'receptance' (displacement/force), 'mobility' "
            f"(velocity/force) or 'accelerance' (acceleration/force); got {quantity!r}."
        )
    return _QUANTITY_POWER[quantity]


class ModalFit(eqx.Module):
    """Modal model of measured FRFs with its out-of-band residual terms and diagnostics.

    The FRF of output `o` to input `i` is (Ewins, *Modal Testing*, 2000, §4.3;
    PolyMAX eq. 14, with `s = jω` and `q = 0, 1, 2` for receptance, mobility,
    accelerance)

        H_oi(s) = Σ_k [ A_koi / (s - λ_k) + conj(A_koi) / (s - conj λ_k) ]
                  + s^q ( L_oi / s² + U_oi ),

    where `L_oi / s²` (lower residual: modes below the band, rigid-body mass line) and
    `U_oi` (upper residual: static compliance of modes above the band) are real.
    For accelerance the residual is `L + U s²`.

    **Fields:**

    - `model`: `jaxvs.ModalModel` with `omega_n`, `zeta` and complex upper-pole residues
      `A_k` of the *measured quantity*, shaped like one FRF: `(mode,)`, `(mode, out)` or
      `(mode, out, in)`.
    - `lower_residual`, `upper_residual`: `L`, `U` shaped like one FRF (`()`, `(out,)` or
      `(out, in)`).
    - `quantity`: `"receptance"`, `"mobility"` or `"accelerance"` (static).
    - `poles`: `(mode,)` upper poles `λ_k = ω_k (-ζ_k + j sqrt(1 - ζ_k²))` [rad/s].
    - `fit_error`: relative RMS error `||H - Ĥ|| / ||H||` of every FRF over the fitted bins.
    - `mac`: `(mode, mode)` auto-MAC of the residue vectors (mode shapes across all FRFs);
      small off-diagonal values mean distinct modes.
    - `omega`: `(freq,)` the fitted frequency grid [rad/s].
    - `diagram`: the [`StabilisationDiagram`][] the poles came from (`None` when the poles
      were given).
    """

    model: ModalModel
    lower_residual: Float[Array, "..."]
    upper_residual: Float[Array, "..."]
    poles: Complex[Array, " mode"]
    fit_error: Float[Array, "..."]
    mac: Float[Array, "mode mode"]
    omega: Float[Array, " freq"]
    diagram: StabilisationDiagram | None
    quantity: str = eqx.field(static=True)

    @property
    def n_modes(self) -> int:
        return self.model.n_modes

    @property
    def natural_frequencies_hz(self) -> Float[Array, " mode"]:
        """Natural frequencies [Hz]."""
        return self.model.omega_n / (2 * jnp.pi)

    @property
    def damping_ratios(self) -> Float[Array, " mode"]:
        return self.model.zeta

    def residual_response(self, omega: ArrayLike) -> Complex[Array, "freq ..."]:
        """Residual terms `s^q (L / s² + U)` at `omega` [rad/s], shaped `(freq, *io)`."""
        omega = jnp.asarray(omega)
        s = (1j * omega).reshape((-1,) + (1,) * self.lower_residual.ndim)
        q = _QUANTITY_POWER[self.quantity]
        return s ** (q - 2) * self.lower_residual + s**q * self.upper_residual

    def response(self, omega: ArrayLike) -> Complex[Array, "freq ..."]:
        """Fitted FRFs (modes + residual terms) at `omega` [rad/s], shaped like the data."""
        return _fit_response(self, _as_omega(omega))

    def frf(self, output: int = 0, input: int = 0) -> "ModalFit":
        """The fit of one FRF (output `output`, input `input`) as a single-FRF `ModalFit`.

        The modes (poles) stay shared, so two FRFs taken from one fit give an exact
        rational TMF in [`tmf_from_modal`][]. (Its `mac` is all ones: one FRF carries no
        mode-shape information.)
        """
        shape = self.lower_residual.shape
        nd = len(shape)
        idx = ((), (output,), (output, input))[nd]
        full = tuple(shape) + (1,) * (2 - nd)
        if not (0 <= output < full[0] and 0 <= input < full[1]):
            raise IndexError(
                f"ModalFit.frf: (output, input) = ({output}, {input}) is outside the "
                f"{full[0]} output(s) x {full[1]} input(s) of this fit."
            )
        r = self.model.residues[(slice(None),) + idx]
        model = ModalModel(self.model.omega_n, self.model.zeta, r)
        return ModalFit(
            model=model,
            lower_residual=self.lower_residual[idx],
            upper_residual=self.upper_residual[idx],
            poles=self.poles,
            fit_error=self.fit_error[idx],
            mac=jnp.ones((self.n_modes, self.n_modes)),
            omega=self.omega,
            diagram=self.diagram,
            quantity=self.quantity,
        )


def _as_omega(omega: ArrayLike) -> Array:
    omega = jnp.asarray(omega)
    if jnp.iscomplexobj(omega) or omega.ndim != 1:
        raise ValueError(
            f"ModalFit.response: omega must be a real 1-D grid [rad/s]; got {omega.dtype} "
            f"of shape {omega.shape}."
        )
    return omega.astype(jnp.result_type(float))


@eqx.filter_jit
def _fit_response(fit: ModalFit, omega: Array) -> Array:
    g = frequency_response(fit.model, omega)
    return g.reshape((g.shape[0],) + fit.lower_residual.shape) + fit.residual_response(omega)


def _upper_poles(omega_n: Array, zeta: Array) -> Array:
    return jax.lax.complex(-zeta * omega_n, omega_n * jnp.sqrt(1 - zeta**2))


def _lsfd_arrays(omega, H3, W, omega_n, zeta, q: int, use_lower: bool = True):
    """LSFD for every FRF: real least squares in (Re A_k, Im A_k, L, U).

    Columns `1/(s-λ) + 1/(s-λ̄)` and `j/(s-λ) - j/(s-λ̄)` for the residue, `s^(q-2)` and
    `s^q` for the residual terms; each column is scaled to unit norm (conditioning
    heuristic), real and imaginary parts of the equations are stacked. Without
    `use_lower` the `s^(q-2)` column is left out (`L = 0`).
    """
    s = 1j * omega
    lam = _upper_poles(omega_n, zeta)
    a = 1.0 / (s[:, None] - lam[None, :])
    b = 1.0 / (s[:, None] - jnp.conj(lam)[None, :])
    lower_col = (s ** (q - 2))[:, None] * (1.0 if use_lower else 0.0)
    basis = jnp.concatenate(
        [a + b, 1j * (a - b), lower_col, (s**q)[:, None]], axis=1
    )  # (freq, 2 m + 2); an all-zero column gets a zero coefficient from lstsq
    m = omega_n.shape[0]
    F, n_out, n_in = H3.shape
    Hc = H3.reshape(F, n_out * n_in)
    Wc = jnp.broadcast_to(W[:, :, None], (F, n_out, n_in)).reshape(F, n_out * n_in)

    def one(h, w):
        Aw = basis * w[:, None]
        A_ri = jnp.concatenate([Aw.real, Aw.imag], axis=0)
        y = jnp.concatenate([(h * w).real, (h * w).imag])
        scale = jnp.linalg.norm(A_ri, axis=0)
        scale = jnp.where(scale > 0, scale, 1.0)
        x = jnp.linalg.lstsq(A_ri / scale, y)[0] / scale
        return x

    x = jax.vmap(one, in_axes=(1, 1))(Hc, Wc)  # (n_out n_in, 2m + 2)
    if not use_lower:
        x = x.at[:, 2 * m].set(0.0)
    res = (x[:, :m] + 1j * x[:, m : 2 * m]).T.reshape(m, n_out, n_in)
    lower = x[:, 2 * m].reshape(n_out, n_in)
    upper = x[:, 2 * m + 1].reshape(n_out, n_in)
    fitted = (basis @ x.T.astype(basis.dtype)).reshape(F, n_out, n_in)
    err = jnp.sqrt(
        jnp.sum(jnp.abs(H3 - fitted) ** 2, axis=0)
        / jnp.maximum(jnp.sum(jnp.abs(H3) ** 2, axis=0), jnp.finfo(omega.dtype).tiny)
    )
    vec = res.reshape(m, n_out * n_in)
    num = jnp.abs(jnp.conj(vec) @ vec.T) ** 2
    nrm = jnp.sum(jnp.abs(vec) ** 2, axis=1)
    mac = num / jnp.maximum(nrm[:, None] * nrm[None, :], jnp.finfo(omega.dtype).tiny)
    return res, lower, upper, err, mac, lam


def lsfd(
    omega: ArrayLike,
    H: ArrayLike | None,
    omega_n: ArrayLike,
    zeta: ArrayLike,
    *,
    quantity: Quantity | None = None,
    band: tuple[float, float] | None = None,
    unit: Literal["rad/s", "Hz"] = "rad/s",
    weights: ArrayLike | None = None,
    diagram: StabilisationDiagram | None = None,
    lower_residual: bool = True,
) -> ModalFit:
    """Residues and residual terms for given poles (least-squares frequency domain).

    Linear least squares of the model of [`ModalFit`][] to every FRF separately
    (PolyMAX eq. 14; Peeters et al. 2004, §2.3).

    **Arguments:**

    - `omega`: `(freq,)` frequencies in `unit`, > 0 inside `band`.
    - `H`: `(freq,)`, `(freq, out)` or `(freq, out, in)` complex FRFs of `quantity`.
    - `omega_n`: `(mode,)` natural frequencies [rad/s] (always rad/s).
    - `zeta`: `(mode,)` damping ratios, `0 <= zeta < 1`.
    - `quantity`: `"accelerance"`, `"mobility"` or `"receptance"`: sets the form of
      the residual terms; default the `kind` of an `FRFData`, else accelerance.
    - `band`, `unit`: as in [`stabilisation_diagram`][].
    - `weights`: `(freq,)` or `(freq, out)` frequency weights (default uniform).
    - `diagram`: attached to the result for reference.
    - `lower_residual`: fit the lower residual `L` (default). `False` fixes `L = 0`: a
      supported (grounded) structure without rigid-body motion, fitted as receptance, then
      has a finite static compliance `H(0) = Σ_k 2 Re(-A_k / λ_k) + U` set by the modes
      instead of a free `L / s²` term (the low-frequency physics of a TMF, `T(0) = 1`).

    **Returns:** a [`ModalFit`][].
    """
    where = "lsfd"
    quantity = _resolve_quantity(quantity, omega, where)
    q = _QUANTITY_POWER[quantity]
    omega, H = _frfdata_arrays(omega, H, unit, where)
    w, h3, wt, io = prepare_frf(omega, H, band=band, unit=unit, weights=weights, where=where)
    wn = np.atleast_1d(np.asarray(omega_n, dtype=np.float64))
    ze = np.atleast_1d(np.asarray(zeta, dtype=np.float64))
    if wn.ndim != 1 or wn.shape != ze.shape:
        raise ValueError(
            f"{where}: omega_n and zeta must be 1-D of equal length (mode,); got "
            f"{wn.shape} and {ze.shape}."
        )
    if not (np.all(np.isfinite(wn)) and np.all(wn > 0)):
        raise ValueError(f"{where}: omega_n must be finite and > 0 rad/s.")
    if not (np.all(np.isfinite(ze)) and np.all(ze >= 0) and np.all(ze < 1)):
        raise ValueError(f"{where}: zeta must lie in [0, 1) (underdamped modes).")
    n_unknown = 2 * wn.shape[0] + 1 + bool(lower_residual)
    if 2 * w.shape[0] < n_unknown:
        raise ValueError(
            f"{where}: {w.shape[0]} frequency points cannot determine {wn.shape[0]} modes "
            f"and the residual terms ({n_unknown} real unknowns per FRF); give at least "
            f"{(n_unknown + 1) // 2} points or fewer modes."
        )
    order = np.argsort(wn)
    wn, ze = wn[order], ze[order]
    W = np.ones(h3.shape[:2]) if wt is None else wt
    res, lower, upper, err, mac, lam = _lsfd_jit(
        jnp.asarray(w),
        jnp.asarray(h3),
        jnp.asarray(W),
        jnp.asarray(wn),
        jnp.asarray(ze),
        q,
        bool(lower_residual),
    )
    m = wn.shape[0]
    model = ModalModel(jnp.asarray(wn), jnp.asarray(ze), res.reshape((m,) + io))
    return ModalFit(
        model=model,
        lower_residual=lower.reshape(io),
        upper_residual=upper.reshape(io),
        poles=lam,
        fit_error=err.reshape(io),
        mac=mac,
        omega=jnp.asarray(w),
        diagram=diagram,
        quantity=quantity,
    )


_lsfd_jit = jax.jit(_lsfd_arrays, static_argnums=(5, 6))


def modal_fit(
    omega: ArrayLike,
    H: ArrayLike | None = None,
    *,
    n_modes: int | None = None,
    band: tuple[float, float] | None = None,
    max_order: int = 40,
    quantity: Quantity | None = None,
    unit: Literal["rad/s", "Hz"] = "rad/s",
    weights: ArrayLike | None = None,
    criteria: StabilisationCriteria | None = None,
    lower_residual: bool = True,
) -> ModalFit:
    """Modal parameters of measured FRFs: pLSCF poles, automatic selection, LSFD residues.

    **Arguments:**

    - `omega`: `(freq,)` strictly increasing frequencies in `unit`; or a
      `jaxvs.data.FRFData` (then `H` is omitted; its grid is read in `unit`, and its
      `kind` gives the default `quantity`).
    - `H`: `(freq,)`, `(freq, out)` or `(freq, out, in)` complex FRFs sharing their poles
      (e.g. responses at several points to one force).
    - `n_modes`: number of modes to keep (the longest-lived pole tracks); default: every
      track that is stable over `min_orders` orders.
    - `band`: `(low, high)` in `unit`, the fitted frequency range (modes outside it are
      represented by the residual terms). The DC bin must be excluded.
    - `max_order`: highest pLSCF polynomial order of the stabilisation diagram.
    - `quantity`: `"accelerance"`, `"mobility"` or `"receptance"`; default the `kind`
      of an `FRFData`, else accelerance.
    - `unit`: `"rad/s"` or `"Hz"` for `omega` and `band`.
    - `weights`: `(freq,)` or `(freq, out)` weights for the pole estimator (default
      `1 / RMS|H_o|` per output) and the residue fit (default uniform).
    - `criteria`: the stabilisation and selection criteria ([`StabilisationCriteria`][];
      default: 1 %, 5 %, MAC 0.98).
    - `lower_residual`: see [`lsfd`][] (`False`: `L = 0`, no rigid-body / out-of-band
      mass line).

    **Returns:** a [`ModalFit`][] whose `diagram` is the stabilisation diagram.

    The pole selection is a discrete decision made host-side, so this function runs
    outside `jit`; the returned model is an ordinary differentiable `ModalModel`.
    """
    where = "modal_fit"
    quantity = _resolve_quantity(quantity, omega, where)
    if criteria is None:
        criteria = StabilisationCriteria()
    if not isinstance(criteria, StabilisationCriteria):
        raise TypeError(
            f"{where}: criteria must be a jaxvs.calibration.StabilisationCriteria; got "
            f"{type(criteria).__name__}."
        )
    diagram = stabilisation_diagram(
        omega,
        H,
        max_order=max_order,
        band=band,
        unit=unit,
        weights=weights,
        frequency_tol=criteria.frequency_tol,
        damping_tol=criteria.damping_tol,
        mac_tol=criteria.mac_tol,
    )
    wn, ze = select_poles(diagram, n_modes=n_modes, min_orders=criteria.min_orders)
    return lsfd(
        omega,
        H,
        wn,
        ze,
        quantity=quantity,
        band=band,
        unit=unit,
        weights=weights,
        diagram=diagram,
        lower_residual=lower_residual,
    )


# --------------------------------------------------------------------------------------
# Transmissibility from two modal fits
# --------------------------------------------------------------------------------------


class ModalTMF(eqx.Module):
    """Transmissibility `T_ab(jω) = H_a(jω) / H_b(jω)` built from two single-FRF modal fits.

    Doerrer et al. (2022), eq. 6: with a common excitation point `c`,
    `T_ab^c = H_ac / H_bc` (the ratio of two FRFs of the same quantity).

    **Fields:** `numerator` (`H_a`) and `denominator` (`H_b`), single-FRF [`ModalFit`][]s.
    """

    numerator: ModalFit
    denominator: ModalFit

    def response(self, omega: ArrayLike) -> Complex[Array, " freq"]:
        """`T_ab(jω)` at `omega` [rad/s]."""
        omega = _as_omega(omega)
        return _fit_response(self.numerator, omega) / _fit_response(self.denominator, omega)

    def to_rational(self) -> RationalTF:
        """`T_ab` as a `RationalTF` of equal numerator and denominator order.

        Exact when both fits share their poles (take both FRFs from one `ModalFit` with
        `fit.frf(j)`): over the common modal denominator `D(s)` every FRF of the fit is
        `H(s) = s^(q-2) [s^(2-q) N_modal(s) + (L + U s²) D(s)] / D(s)`, the factor
        `s^(q-2) / D(s)` cancels and `T = N_a / N_b` with numerator and denominator of
        order `2 m + 2` (a common factor `s^k` is cancelled: receptance fits without
        the lower residual give order `2 m`). Its poles are
        the zeros (anti-resonances) of `H_b`. The polynomials are built in the scaled
        variable `s / ω_0` (`ω_0` the geometric mean of the natural frequencies) to keep
        their coefficients within a few decades (conditioning heuristic).
        """
        a, b = self.numerator, self.denominator
        if a.lower_residual.ndim or b.lower_residual.ndim:
            raise ValueError(
                "ModalTMF.to_rational: numerator and denominator must be single FRFs; "
                "select them with fit.frf(output, input)."
            )
        if a.quantity != b.quantity:
            raise ValueError(
                "ModalTMF.to_rational: numerator and denominator are different quantities "
                f"({a.quantity} vs {b.quantity}); fit both in the same quantity."
            )
        same = a.model.omega_n.shape == b.model.omega_n.shape and bool(
            np.all(np.asarray(a.model.omega_n) == np.asarray(b.model.omega_n))
            and np.all(np.asarray(a.model.zeta) == np.asarray(b.model.zeta))
        )
        if not same:
            raise ValueError(
                "ModalTMF.to_rational: the two fits have different poles, so their "
                "denominators do not cancel and T is not a TMF of order 2m+2. Fit both "
                "FRFs in one modal_fit call (H of shape (freq, out)) and take fit.frf(a), "
                "fit.frf(b); or use ModalTMF.response for the FRF of the ratio."
            )
        q = _QUANTITY_POWER[a.quantity]
        num, den = _tmf_coefficients(a, b, q)
        return RationalTF(jnp.asarray(num), jnp.asarray(den))


def _scaled_numerator(fit: ModalFit, q: int, w0: float) -> np.ndarray:
    """Coefficients (in `x = s / w0`, highest power first) of `G(x) = H(w0 x) K(x)` with the
    factor `K(x) = x^(2-q) D(x) / w0^(q-2)` that is common to every FRF of one fit.

    With `μ_k = λ_k / w0`, `Ã_k = A_k / w0` and `D(x) = Π_k (x - μ_k)(x - conj μ_k)`:
    `H(w0 x) = N_modal(x) / D(x) + w0^(q-2) x^(q-2) (L + U w0² x²)`, so
    `G(x) = w0^(2-q) x^(2-q) N_modal(x) + (L + U w0² x²) D(x)`, a polynomial of order
    `2 m + 2` (the modal part has order `<= 2 m + 1 - q`). Host-side NumPy: a one-off
    conversion of a handful of coefficients.
    """
    lam = np.asarray(fit.poles) / w0
    A = np.asarray(fit.model.residues) / w0
    m = lam.shape[0]
    # Real quadratic factor of each mode: (x - μ)(x - conj μ) = x² - 2 Re μ x + |μ|².
    quad = [np.array([1.0, -2 * mu.real, abs(mu) ** 2]) for mu in lam]
    D = np.array([1.0])
    for qd in quad:
        D = np.polymul(D, qd)
    n_modal = np.zeros(2 * m)
    for k in range(m):
        Pk = np.array([1.0])
        for j, qd in enumerate(quad):
            if j != k:
                Pk = np.polymul(Pk, qd)
        # Ã/(x - μ) + conj(Ã)/(x - conj μ) = (2 Re Ã x - 2 Re(Ã conj μ)) / ((x - μ)(x - conj μ))
        section = np.array([2 * A[k].real, -2 * (A[k] * np.conj(lam[k])).real])
        n_modal = np.polyadd(n_modal, np.polymul(Pk, section))
    modal = np.concatenate([n_modal, np.zeros(2 - q)]) * w0 ** (2 - q)
    L, U = float(fit.lower_residual), float(fit.upper_residual)
    residual = np.polymul(np.array([U * w0**2, 0.0, L]), D)
    return np.polyadd(modal, residual)


def _tmf_coefficients(a: ModalFit, b: ModalFit, q: int) -> tuple[np.ndarray, np.ndarray]:
    w0 = float(np.exp(np.mean(np.log(np.asarray(a.model.omega_n)))))
    na = _scaled_numerator(a, q, w0)
    nb = _scaled_numerator(b, q, w0)
    n = 2 * a.model.n_modes + 2
    na = np.concatenate([np.zeros(n + 1 - na.size), na])
    nb = np.concatenate([np.zeros(n + 1 - nb.size), nb])
    # N(s / w0) with coefficients c_k x^(n-k): multiply both by w0^n → c_k w0^k s^(n-k).
    unscale = w0 ** np.arange(n + 1, dtype=float)
    na, nb = na * unscale, nb * unscale
    # A common factor s^k (exact zeros at the end of both, e.g. receptance fits without
    # the lower residual: G(x) = x² (...)) cancels; keep T(0) finite.
    k = 0
    while k < n and na[n - k] == 0.0 and nb[n - k] == 0.0:
        k += 1
    return na[: n + 1 - k], nb[: n + 1 - k]


def tmf_from_modal(numerator: ModalFit, denominator: ModalFit) -> ModalTMF:
    """Transmissibility `T = H_a / H_b` from the modal fits of two FRFs (the study's first
    route, Doerrer et al. 2022, §3.3 and Figure 8).

    **Arguments:**

    - `numerator`: single-FRF [`ModalFit`][] of `H_a` (e.g. `fit.frf(1)`).
    - `denominator`: single-FRF [`ModalFit`][] of `H_b` with the same excitation point.

    **Returns:** a [`ModalTMF`][]; `.response(omega)` is the TMF, `.to_rational()` its exact
    `RationalTF` when both fits share their poles.
    """
    for name, f in (("numerator", numerator), ("denominator", denominator)):
        if not isinstance(f, ModalFit):
            raise TypeError(f"tmf_from_modal: {name} must be a ModalFit; got {type(f).__name__}.")
        if f.lower_residual.ndim:
            raise ValueError(
                f"tmf_from_modal: {name} holds {f.lower_residual.shape} FRFs; select one "
                "with fit.frf(output, input)."
            )
    if numerator.quantity != denominator.quantity:
        raise ValueError(
            "tmf_from_modal: numerator and denominator are different quantities "
            f"({numerator.quantity} vs {denominator.quantity}); a TMF relates two FRFs "
            "of the same quantity."
        )
    return ModalTMF(numerator, denominator)
