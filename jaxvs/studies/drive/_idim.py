"""Inverse-dynamics identification with least squares (IDIM-LS) of a rigid drive axis.

The rigid-body inverse dynamic model of one prismatic axis (Janot, Gautier, Brunot 2019,
"Data set and reference models of EMPS", eq. (1)-(2) and §3) is linear in its parameters,

    u(t) = M q̈(t) + Fv q̇(t) + Fc sign(q̇(t)) + offset                      (coulomb_viscous)
    u(t) = M q̈ + Fv+ q̇·[q̇>0] + Fc+ [q̇>0] + Fv− q̇·[q̇<0] − Fc− [q̇<0]        (asymmetric)

so it is identified by ordinary least squares once q̇, q̈ are estimated from the measured
position. The recipe is the description's §3.1-3.3:

1. zero-phase (forward-backward) low-pass Butterworth filter of the position `q`;
2. q̇, q̈ by central differences of the filtered position (steps 1-2 are the package's
   drive preprocessing, `jaxvs.signal.DriveBand`, without hold compensation of the force);
3. "parallel decimation": every column of the observation matrix and the measured force are
   low-pass filtered by the same zero-phase decimation filter and down-sampled by `nd`
   (removes the torque ripple the controller rejects, eq. (9));
4. θ̂ = (ΦᵀΦ)⁻¹Φᵀy (eq. (10)), covariance σ̂²(ΦᵀΦ)⁻¹ with σ̂² = ‖y − Φθ̂‖²/(N − p), and the
   relative error ‖y − ŷ‖/‖y‖ (eq. (11)).

Steps 1-3 are signal preprocessing of a `Record` (NumPy/SciPy, outside JAX); step 4 is a
pure, jit-compatible JAX function.
"""

from __future__ import annotations

import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.signal as ss
from jaxtyping import Array, Float

from ...data import Record
from ...signal import DriveBand

FRICTION_MODELS = ("coulomb_viscous", "asymmetric")
_PARAMETER_NAMES = {
    "coulomb_viscous": ("M", "Fv", "Fc", "offset"),
    "asymmetric": ("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"),
}
_PARAMETER_UNITS = {
    "M": "kg",
    "Fv": "N·s/m",
    "Fc": "N",
    "offset": "N",
    "Fv_pos": "N·s/m",
    "Fc_pos": "N",
    "Fv_neg": "N·s/m",
    "Fc_neg": "N",
}

# Heuristic: the parameters are declared not identifiable when the column-normalised
# observation matrix has a condition number above this (float64 LS keeps ~16 - log10(cond)
# digits; at 1e8 the standard errors no longer mean anything). EMPS itself has cond ≈ 26.
_MAX_CONDITION = 1e8


class IDIMResult(eqx.Module):
    """The IDIM-LS estimate of a rigid drive axis (see `idim_ls`).

    **Fields:**

    - `names`: parameter names, `("M", "Fv", "Fc", "offset")` for `"coulomb_viscous"`
        friction, `("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg")` for `"asymmetric"`.
    - `values`: the estimates θ̂, in that order [kg, N·s/m, N, N].
    - `std_errors`: their standard deviations, √diag(σ̂²(ΦᵀΦ)⁻¹), same units.
    - `covariance`: σ̂²(ΦᵀΦ)⁻¹.
    - `sigma`: σ̂ = ‖y − Φθ̂‖/√(N − p) [N], the standard deviation of the force error.
    - `relative_error`: ‖y − Φθ̂‖/‖y‖ (a fraction; ×100 for the published %).
    - `condition_number`: condition number of Φ (unscaled, as the description prints it).
    - `regressor`: the decimated observation matrix Φ, shape `(sample, param)`.
    - `force`: the decimated measured force y [N], shape `(sample,)`.
    - `predicted`: Φθ̂ [N].
    - `friction`, `cutoff_hz`, `filter_order`, `decimation`, `edge_samples`, `position`,
        `force_name`: the settings used, so that
        `predict_force` applies the same preprocessing to another record.
    """

    values: Float[Array, " param"]
    std_errors: Float[Array, " param"]
    covariance: Float[Array, "param param"]
    sigma: Float[Array, ""]
    relative_error: Float[Array, ""]
    condition_number: Float[Array, ""]
    regressor: Float[Array, "sample param"]
    force: Float[Array, " sample"]
    predicted: Float[Array, " sample"]
    names: tuple[str, ...] = eqx.field(static=True)
    friction: str = eqx.field(static=True)
    cutoff_hz: float = eqx.field(static=True)
    filter_order: int = eqx.field(static=True)
    decimation: int = eqx.field(static=True)
    edge_samples: int | None = eqx.field(static=True)
    position: str = eqx.field(static=True)
    force_name: str = eqx.field(static=True)

    @property
    def params(self) -> dict[str, Array]:
        """The estimates by name, e.g. `result.params["M"]` [kg]."""
        return {name: self.values[i] for i, name in enumerate(self.names)}

    @property
    def units(self) -> dict[str, str]:
        """The unit of each parameter by name."""
        return {name: _PARAMETER_UNITS[name] for name in self.names}

    def __getitem__(self, name: str) -> Array:
        if name not in self.names:
            raise KeyError(f"No parameter {name!r}; this {self.friction!r} fit has {self.names}.")
        return self.values[self.names.index(name)]


class ForcePrediction(eqx.Module):
    """The force of a record predicted by IDIM-LS parameters (see `predict_force`).

    **Fields:**

    - `force`: the decimated measured force y [N].
    - `predicted`: Φθ̂ [N] with Φ built from this record.
    - `relative_error`: ‖y − Φθ̂‖/‖y‖ (fraction), the description's cross-test validation
        error (eq. (11)).
    - `t`: time of each decimated sample [s].
    """

    force: Float[Array, " sample"]
    predicted: Float[Array, " sample"]
    relative_error: Float[Array, ""]
    t: Float[Array, " sample"]


def _check_options(
    friction: str, cutoff_hz: float, filter_order: int, decimation: int, fs: float
) -> None:
    if friction not in FRICTION_MODELS:
        raise ValueError(
            f"friction must be one of {FRICTION_MODELS}, got {friction!r}: 'coulomb_viscous' "
            "fits M, Fv, Fc and an offset; 'asymmetric' fits direction-dependent Fv, Fc."
        )
    if not isinstance(decimation, int | np.integer) or decimation < 1:
        raise ValueError(f"decimation must be an integer >= 1, got {decimation!r}.")
    if not isinstance(filter_order, int | np.integer) or filter_order < 1:
        raise ValueError(f"filter_order must be an integer >= 1, got {filter_order!r}.")
    if not 0 < cutoff_hz < fs / 2:
        raise ValueError(
            f"cutoff_hz = {cutoff_hz!r} Hz must lie strictly between 0 and the Nyquist "
            f"frequency {fs / 2:g} Hz of this record; the description's rule of thumb is "
            "cutoff >= 5x the highest closed-loop natural frequency."
        )


def _signal(record: Record, name: str, role: str, argument: str) -> np.ndarray:
    if not isinstance(record, Record):
        raise TypeError(
            f"record must be a jaxvs.data.Record, got {type(record).__name__}; load the data "
            "with jaxvs.data.load_emps (or build a Record from your arrays)."
        )
    if name not in record:
        raise ValueError(
            f"The record has no {role} signal {name!r} (signals: {list(record.names)}); "
            f"pass {argument}=... with the name of the {role} signal."
        )
    return np.asarray(record[name], dtype=np.float64)


def idim_regressor(
    record: Record,
    *,
    friction: Literal["coulomb_viscous", "asymmetric"] = "coulomb_viscous",
    cutoff_hz: float = 200.0,
    filter_order: int = 4,
    decimation: int = 10,
    position: str = "q",
    force: str = "u",
    min_speed: float | None = 1e-4,
    edge_samples: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The decimated IDIM observation matrix Φ and force vector y of one record
    (description §3.1-3.2; see `idim_ls` for the arguments).

    `min_speed=None` skips the motion check (used by `predict_force`).

    **Returns:**

    `(Phi, y, t)`: Φ of shape `(sample, param)`, y [N] and the time of each sample [s],
    as NumPy arrays.

    **Raises:**

    `ValueError` for a missing signal, bad options, a record too short for the filters, or
    too little motion in either direction to identify friction.
    """
    q = _signal(record, position, "position", "position")
    u = _signal(record, force, "force", "force")
    dt = record.dt
    fs = 1.0 / dt
    _check_options(friction, cutoff_hz, filter_order, decimation, fs)
    # filtfilt pads 3·max(len(a), len(b)) samples on each side; the decimation filter is an
    # order-8 Chebyshev (scipy.signal.decimate, like MATLAB's decimate).
    min_length = max(3 * (filter_order + 1) + 1, 27 + 2) * max(decimation, 1) + 2
    if edge_samples is None:
        edge_samples = math.ceil(3 * fs / cutoff_hz)
    if not isinstance(edge_samples, int | np.integer) or edge_samples < 0:
        raise ValueError(f"edge_samples must be an integer >= 0 or None, got {edge_samples!r}.")
    min_length += 2 * edge_samples
    if q.shape[0] < min_length:
        raise ValueError(
            f"The record has {q.shape[0]} samples; IDIM-LS with decimation={decimation} "
            f"needs at least {min_length}. Use a longer record or a smaller decimation."
        )

    # 1.-2. the package's drive band (description §3.1): zero-phase Butterworth low-pass of
    #    the position, velocity and acceleration by central differences; the force is
    #    the measured one (no hold compensation), decimated in step 3 with the regressor.
    band = DriveBand(fs, cutoff_hz, int(filter_order), decimation=1, hold=False)
    dq, ddq = band.derivatives(band.lowpass(q))
    # the two end samples have no centred neighbours and are dropped
    dq, ddq = dq[1:-1], ddq[1:-1]
    u = u[1:-1]
    t = record.t[1:-1]
    # Drop the filter's edge transients (heuristic length, see `idim_ls`).
    if edge_samples > 0:
        keep = slice(edge_samples, -edge_samples)
        dq, ddq, u, t = dq[keep], ddq[keep], u[keep], t[keep]

    # Heuristic: ask for at least 1 % of the samples moving in each direction; with fewer,
    # sign(q̇) is (nearly) constant and Fc is collinear with the offset (or, for the
    # asymmetric model, the missing direction's Fv−/Fc− columns are empty).
    n_pos = n_neg = needed = 0
    if min_speed is not None:
        n_pos = int(np.count_nonzero(dq > min_speed))
        n_neg = int(np.count_nonzero(dq < -min_speed))
        needed = max(int(0.01 * dq.shape[0]), 1)
    if min_speed is not None and (n_pos < needed or n_neg < needed):
        raise ValueError(
            f"Friction is not identifiable from this record: only {n_pos} samples move in "
            f"+ direction and {n_neg} in − direction faster than min_speed = {min_speed:g} "
            f"m/s (need >= {needed} each, 1 % of the record). Use a trajectory that moves "
            "back and forth (e.g. jaxvs.data.trapezoid), or lower min_speed if the axis is "
            "very slow."
        )

    sign = np.sign(dq)
    if friction == "coulomb_viscous":
        columns = [ddq, dq, sign, np.ones_like(dq)]
    else:
        pos = (dq > 0).astype(np.float64)
        neg = (dq < 0).astype(np.float64)
        columns = [ddq, dq * pos, pos, dq * neg, -neg]
    phi = np.stack(columns, axis=1)

    # 3. parallel decimation (§3.2, eq. (9)): the same zero-phase low-pass (Chebyshev I,
    #    order 8, cut-off 0.8·fs/(2·nd)) on every column and on the force, then one sample
    #    in nd. Linear and identical on both sides, so it keeps y = Φθ + v.
    if decimation > 1:
        phi = ss.decimate(phi, decimation, axis=0, zero_phase=True)
        u = ss.decimate(u, decimation, zero_phase=True)
        t = t[::decimation]
    return phi, u, t


@jax.jit
def _least_squares(phi: Float[Array, "n p"], y: Float[Array, " n"]):
    """θ̂ = argmin ‖y − Φθ‖ via the SVD of the column-normalised Φ, with σ̂²(ΦᵀΦ)⁻¹."""
    n, p = phi.shape
    # Column scaling makes the SVD cut-off relative to each parameter's own magnitude
    # (q̈ ~ 1 m/s², sign ~ 1): Φ = (Φ S⁻¹) S with S = diag(‖Φ_j‖).
    scale = jnp.linalg.norm(phi, axis=0)
    scale = jnp.where(scale > 0, scale, 1.0)
    u_, s, vt = jnp.linalg.svd(phi / scale, full_matrices=False)
    theta = (vt.T @ ((u_.T @ y) / s)) / scale
    residual = y - phi @ theta
    sigma2 = jnp.sum(residual**2) / (n - p)
    # (ΦᵀΦ)⁻¹ = S⁻¹ V Σ⁻² Vᵀ S⁻¹
    inv = (vt.T / s**2) @ vt / jnp.outer(scale, scale)
    covariance = sigma2 * inv
    relative = jnp.linalg.norm(residual) / jnp.linalg.norm(y)
    condition_scaled = s[0] / s[-1]
    condition = jnp.linalg.cond(phi)
    return theta, covariance, jnp.sqrt(sigma2), relative, condition_scaled, condition


def idim_ls(
    record: Record,
    *,
    friction: Literal["coulomb_viscous", "asymmetric"] = "coulomb_viscous",
    cutoff_hz: float = 200.0,
    filter_order: int = 4,
    decimation: int = 10,
    position: str = "q",
    force: str = "u",
    min_speed: float = 1e-4,
    edge_samples: int | None = None,
) -> IDIMResult:
    """Identify mass and friction of a rigid drive axis by IDIM-LS (Janot, Gautier, Brunot
    2019, "Data set and reference models of EMPS", §3, eq. (8)-(11)).

    Fits `u = M q̈ + Fv q̇ + Fc sign(q̇) + offset` (or the asymmetric friction model, see
    the module docstring) by ordinary least squares after zero-phase Butterworth filtering
    of the position, central differences and parallel decimation.

    On the EMPS estimation set the defaults give M = 95.12 kg, Fv = 203.4 N·s/m,
    Fc = 20.41 N, offset = −3.17 N and a 4.03 % relative error (published: 95.11, 203.50,
    20.39, −3.16, 4.08 %); see `benchmarks/results/emps.md`.

    **Arguments:**

    - `record`: a `jaxvs.data.Record` with the measured position [m] and motor force [N]
        (e.g. `jaxvs.data.load_emps(".../DATA_EMPS.mat")`).
    - `friction`: `"coulomb_viscous"` (parameters `M, Fv, Fc, offset`) or `"asymmetric"`
        (`M, Fv_pos, Fc_pos, Fv_neg, Fc_neg`, force `… − Fc_neg` when moving backwards; no
        offset, which would be collinear with the two Coulomb columns).
    - `cutoff_hz`: cut-off of the position Butterworth filter [Hz]. The description's rule
        of thumb is ≥ 5× the highest closed-loop natural frequency; the default 200 Hz
        (heuristic) is the value that reproduces the published EMPS results.
    - `filter_order`: order of that Butterworth filter (applied forwards and backwards, so
        the effective order is twice this).
    - `decimation`: decimation factor `nd` of the parallel decimation (1 = none).
    - `position`, `force`: names of the position and force signals in `record`.
    - `min_speed`: speed [m/s] above which a sample counts as moving, for the check that
        the record moves in both directions.
    - `edge_samples`: samples dropped at each end after differentiation, where the
        forward-backward filter's start-up transient corrupts q̈ (its padding by odd
        reflection flips the sign of q̈). Default (heuristic): 3 periods of the cut-off,
        `ceil(3·fs/cutoff_hz)`, after which the Butterworth transient has decayed.

    **Returns:**

    An `IDIMResult` (estimates, standard errors, covariance, relative error, Φ, y).

    **Raises:**

    `ValueError` for a missing signal, bad options, a record without motion in both
    directions, or a rank-deficient observation matrix (parameters not identifiable).
    """
    phi, y, _ = idim_regressor(
        record,
        friction=friction,
        cutoff_hz=cutoff_hz,
        filter_order=filter_order,
        decimation=decimation,
        position=position,
        force=force,
        min_speed=min_speed,
        edge_samples=edge_samples,
    )
    names = _PARAMETER_NAMES[friction]
    if phi.shape[0] <= len(names):
        raise ValueError(
            f"After decimation only {phi.shape[0]} samples remain for {len(names)} "
            "parameters; use a longer record or a smaller decimation."
        )
    phi_j = jnp.asarray(phi)
    y_j = jnp.asarray(y)
    theta, cov, sigma, relative, cond_scaled, cond = _least_squares(phi_j, y_j)
    if not float(cond_scaled) < _MAX_CONDITION:
        raise ValueError(
            f"The observation matrix is rank deficient (condition number {float(cond_scaled):.3g} "
            f"after column scaling): the parameters {names} are not identifiable from this "
            "record. Excite the axis with accelerations and speeds in both directions."
        )
    return IDIMResult(
        values=theta,
        std_errors=jnp.sqrt(jnp.diag(cov)),
        covariance=cov,
        sigma=sigma,
        relative_error=relative,
        condition_number=cond,
        regressor=phi_j,
        force=y_j,
        predicted=phi_j @ theta,
        names=names,
        friction=friction,
        cutoff_hz=float(cutoff_hz),
        filter_order=int(filter_order),
        decimation=int(decimation),
        edge_samples=edge_samples,
        position=position,
        force_name=force,
    )


def predict_force(params: IDIMResult, record: Record) -> ForcePrediction:
    """The force of another record predicted by IDIM-LS estimates: the description's
    cross-test validation (§3.4, eq. (11) with Φ_CTV built from the new record).

    The new record goes through exactly the preprocessing of the fit (same filter, cut-off,
    decimation, friction model and signal names).

    **Arguments:**

    - `params`: the `IDIMResult` of `idim_ls`.
    - `record`: the validation record (position [m] and force [N]).

    **Returns:**

    A `ForcePrediction` with the decimated measured and predicted force [N] and the
    relative error ‖y − ŷ‖/‖y‖.

    **Raises:**

    `TypeError` if `params` is not an `IDIMResult`; otherwise as `idim_regressor`.
    """
    if not isinstance(params, IDIMResult):
        raise TypeError(
            f"params must be the IDIMResult returned by idim_ls, got {type(params).__name__}."
        )
    # min_speed=None: a validation record need not identify anything, only be predicted.
    phi, y, t = idim_regressor(
        record,
        friction=params.friction,  # type: ignore[arg-type]
        cutoff_hz=params.cutoff_hz,
        filter_order=params.filter_order,
        decimation=params.decimation,
        position=params.position,
        force=params.force_name,
        min_speed=None,
        edge_samples=params.edge_samples,
    )
    predicted = jnp.asarray(phi) @ params.values
    y_j = jnp.asarray(y)
    relative = jnp.linalg.norm(y_j - predicted) / jnp.linalg.norm(y_j)
    return ForcePrediction(
        force=y_j, predicted=predicted, relative_error=relative, t=jnp.asarray(t)
    )
