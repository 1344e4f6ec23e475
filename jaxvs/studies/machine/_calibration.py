"""Calibration of the 21 geometric errors of a `CartesianMachine` from any mix of tests,
through `jaxvs.calibrate` (the one Levenberg–Marquardt), with covariance, intervals per
component and the recovery table against a known machine."""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ...calibration import CalibrationResult, EquationError, calibrate
from ...models import COMPONENTS, CartesianMachine, plan_predict
from ._identifiability import identifiability
from ._parameters import (
    _assert_tests,
    component_curves,
    geometry,
    parameters,
    with_parameters,
)

__all__ = ["MachineCalibration", "calibrate_machine", "machine_residual"]


def machine_residual(machine: CartesianMachine, data: dict) -> Array:
    """Whitened residual of a test plan, `(reading − predict)/sigma` of every reading of
    every run, plus the prior's rows `θ/σ_prior` when `data["prior"]` holds the `(p,)`
    prior standard deviations. `data`: `{"tests": [...], "readings": [...]}` (the
    `EquationError` function of [`calibrate_machine`][], usable under `jax.vmap`)."""
    predicted = plan_predict(machine, data["tests"])
    parts = [
        ((y - p[None]) / t.sigma).ravel()
        for t, y, p in zip(data["tests"], data["readings"], predicted)
    ]
    if data.get("prior") is not None:
        parts.append(parameters(machine) / data["prior"])
    return jnp.concatenate(parts)


def prior_scale(machine: CartesianMachine, prior) -> Array:
    """`(p,)` prior standard deviations from `(σ_translation [m], σ_angle [rad])`."""
    st, sa = (float(v) for v in prior)
    if not (st > 0 and sa > 0):
        raise ValueError(
            f"calibrate_machine: prior must be (sigma_translation [m], sigma_angle [rad]), both "
            f"> 0; got {prior!r}."
        )
    e = machine.errors
    return jnp.concatenate(
        [
            jnp.full(e.positioning.size + e.straightness.size, st),
            jnp.full(e.angular.size + e.squareness.size, sa),
            jnp.full(3, st),
        ]
    )


class MachineCalibration(eqx.Module):
    """The outcome of [`calibrate_machine`][].

    **Fields:**

    - `machine`: the calibrated machine.
    - `result`: the `jaxvs.calibration.CalibrationResult` (values, covariance,
      intervals per coefficient, stats with compile and run time).
    - `positions`: `(3, m)` positions [m] over each axis' travel.
    - `curves`: `(21, m)` the estimated components at those positions (order of
      `jaxvs.models.COMPONENTS`) [m or rad].
    - `std`: `(21, m)` their standard errors (delta method from the covariance).
    - `quantile`: the Student-t quantile of the intervals (level `result.confidence`).
    """

    machine: CartesianMachine
    result: CalibrationResult
    positions: Array
    curves: Array
    std: Array
    quantile: float = eqx.field(static=True)

    def recovery(self, truth: CartesianMachine) -> list[dict[str, Any]]:
        """Per component: RMS of the true curve, RMS of the estimation error, RMS of the
        interval half-width, and whether the estimate is within 10 % of the true RMS or
        inside its interval (in m or rad)."""
        _, true = component_curves(truth, self.curves.shape[1])
        true, est = np.asarray(true), np.asarray(self.curves)
        half = self.quantile * np.asarray(self.std)
        rows = []
        for i, name in enumerate(COMPONENTS):
            rms_true = float(np.sqrt(np.mean(true[i] ** 2)))
            rms_err = float(np.sqrt(np.mean((est[i] - true[i]) ** 2)))
            rms_half = float(np.sqrt(np.mean(half[i] ** 2)))
            inside = bool(np.all(np.abs(est[i] - true[i]) <= half[i]))
            rows.append(
                {
                    "component": name,
                    "rms_true": rms_true,
                    "rms_error": rms_err,
                    "rms_halfwidth": rms_half,
                    "relative_error": rms_err / rms_true if rms_true > 0 else float("nan"),
                    "inside_interval": inside,
                    "ok": bool(rms_err <= 0.1 * rms_true or rms_err <= rms_half),
                }
            )
        return rows


def _readings(machine, tests, readings) -> list[Array]:
    if not isinstance(readings, list | tuple) or len(readings) != len(tests):
        raise ValueError(
            f"calibrate_machine: give one readings array per test ({len(tests)} tests); got "
            f"{type(readings).__name__}."
        )
    out = []
    for t, y in zip(tests, readings):
        y = jnp.asarray(y, jnp.result_type(float))
        shape = eqx.filter_eval_shape(t.predict, machine).shape
        if y.shape == shape:
            y = y[None]
        if y.shape[1:] != shape:
            raise ValueError(
                f"calibrate_machine: the readings of '{t.label}' have shape {y.shape}; the test "
                f"reads {shape} per run, so give {shape} or (runs, *{shape})."
            )
        out.append(y)
    return out


def calibrate_machine(
    machine: CartesianMachine,
    tests,
    readings,
    *,
    prior=None,
    n_points: int = 51,
    **options,
) -> MachineCalibration:
    r"""Calibrate the 21 geometric error components (and the three reversal values) of a
    machine jointly from any subset of tests.

    Minimises `Σ ((reading − predict)/σ)²` over the Legendre coefficients with
    `jaxvs.calibrate` (Levenberg–Marquardt), then maps the covariance to each component
    curve (delta method). A plan that cannot separate every component is refused before
    solving, naming what it cannot see (see [`identifiability`][]) — unless `prior` is
    given: a zero-mean Gaussian prior on the coefficients (ridge), which makes the
    problem solvable and leaves wide intervals on what the data do not determine.

    **Arguments:**

    - `machine`: the initial guess (e.g. the nominal machine with zero errors); its drives,
      structure, travel and tool offset are kept.
    - `tests`: the plan, a list of tests (`LaserLine`, `BallbarCircle`, ...).
    - `readings`: one array per test, its `predict` shape or `(runs, *shape)` (from
      `test.measure` or a file).
    - `prior`: `None` or `(σ_translation [m], σ_angle [rad])`.
    - `n_points`: positions per axis of the returned curves.
    - `options`: as `jaxvs.calibrate` (`max_steps`, `confidence`, `throw`, ...).

    **Returns:** a [`MachineCalibration`][].
    """
    if not isinstance(machine, CartesianMachine):
        raise TypeError("calibrate_machine: machine must be a jaxvs.models.CartesianMachine.")
    tests = _assert_tests(tests)
    readings = _readings(machine, tests, readings)
    for t in tests:
        t.check(machine)
    scale = None
    if prior is None:
        report = identifiability(machine, tests)
        if not report.identified:
            raise ValueError(
                "calibrate_machine: the test plan cannot separate "
                f"{', '.join(report.unidentified_components)} "
                f"({len(report.content['unidentifiable'])} unidentifiable combinations; see "
                "jaxvs.studies.machine.identifiability). Add "
                "tests that see them (suggest_test ranks candidates), or give a prior "
                "(sigma_translation, sigma_angle) to regularise."
            )
    else:
        scale = prior_scale(machine, prior)
    data = {"tests": tests, "readings": readings, "prior": scale}
    res = calibrate(machine, data, EquationError(machine_residual), free=geometry, **options)
    theta = parameters(res.model)
    cov = jnp.where(jnp.isfinite(res.covariance), res.covariance, 0.0)
    G = jax.jacfwd(lambda th: component_curves(with_parameters(res.model, th), n_points)[1])(
        theta
    )
    std = jnp.sqrt(jnp.maximum(jnp.einsum("cmp,pq,cmq->cm", G, cov, G), 0.0))
    pos, curves = component_curves(res.model, n_points)
    se = np.asarray(res.std_errors)
    ci = np.asarray(res.confidence_intervals)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = float(np.nanmedian((ci[:, 1] - np.asarray(res.values)) / se))
    return MachineCalibration(
        machine=res.model, result=res, positions=pos, curves=curves, std=std, quantile=q
    )
