"""Bad-input matrix, calibration and fitting: residuals that turn NaN on the way, zero or
bad weights, degenerate data, bad options (row format in `tests/bad_input.py`).

The problems are tiny (one or two parameters, 20 samples) so the whole file runs in
seconds; each row checks the refusal or the answer, never only that "something" happened.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from bad_input import Case, run_case

from jaxvs.calibration import (
    RESULTS,
    CalibrationError,
    EquationError,
    ExcitationWarning,
    FrequencyError,
    SimulationError,
    calibrate,
    fit_rational,
)
from jaxvs.data import Record
from jaxvs.models import RationalTF, frequency_response

NAN = float("nan")


class Slope(eqx.Module):
    """`y = a x`: the smallest calibration problem."""

    a: jax.Array


_X = jnp.linspace(0.0, 1.0, 20)
_Y = 3.0 * _X + 0.05 * jnp.sin(7.0 * _X)  # optimum a ≈ 3, cost > 0 (not an exact fit)
_DATA = {"x": _X, "y": _Y}


def _line(m, d):
    return m.a * d["x"] - d["y"]


def _wall(m, d):
    """NaN for a > 1.5: the optimum a ≈ 3 cannot be reached from a = 1."""
    return jnp.where(m.a > 1.5, jnp.nan, _line(m, d))


def _band(m, d):
    """NaN for 1.5 < a < 2.5 only: a band across the path to the optimum."""
    return jnp.where((m.a > 1.5) & (m.a < 2.5), jnp.nan, _line(m, d))


def _sqrt(m, d):
    """sqrt(2 - a): NaN beyond a = 2, with a gradient that blows up towards it."""
    return jnp.sqrt(2.0 - m.a) * 0.0 * d["x"] + _line(m, d)


def _calibrate(fn, **kw):
    return calibrate(Slope(jnp.array(1.0)), _DATA, EquationError(fn), **kw)


def _never_false_success(result):
    """With throw=False: never a success with a non-finite cost or at a stale parameter."""
    cost = float(result.cost)
    ok = result.result == RESULTS.successful
    if ok:
        # a success must be the optimum of the reachable set: here a ≈ 3.0 (the cost of
        # the least-squares slope; the data are 3x plus a small wiggle)
        a = float(result.values[0])
        assert np.isfinite(cost) and abs(a - 3.0) < 0.05, (a, cost)
    else:
        assert result.result != RESULTS.successful


def _c(ident, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return Case(
        id=f"calibration-{ident}",
        area="calibration",
        entry=f"jaxvs.calibration.{entry}",
        input=what,
        run=lambda tmp: fn(),
        exc=exc,
        match=match,
        check=check,
    )


_ON_PATH = r"(NaN or inf|non-finite).*(on the way|during|while).*"

CASES: list[Case] = [
    # --- a residual that turns NaN on the way to the optimum -------------------------------
    _c(
        "nan-wall",
        "calibrate",
        "residual NaN for a > 1.5, optimum at a ≈ 3 (start a = 1)",
        lambda: _calibrate(_wall),
        exc=CalibrationError,
        match=_ON_PATH + r"(bound|constrain)",
    ),
    _c(
        "nan-wall-no-throw",
        "calibrate",
        "the same with throw=False: no success at a = 1.5",
        lambda: _calibrate(_wall, throw=False),
        exc=None,
        check=_never_false_success,
    ),
    _c(
        "nan-band",
        "calibrate",
        "residual NaN for 1.5 < a < 2.5 (a band across the path)",
        lambda: _calibrate(_band, throw=False),
        exc=None,
        check=_never_false_success,
    ),
    _c(
        "nan-sqrt",
        "calibrate",
        "sqrt(2 - a) in the residual: NaN beyond a = 2",
        lambda: _calibrate(_sqrt, throw=False),
        exc=None,
        check=_never_false_success,
    ),
    _c(
        "nan-start",
        "calibrate",
        "initial guess a = nan",
        lambda: calibrate(Slope(jnp.array(NAN)), _DATA, EquationError(_line)),
        exc=CalibrationError,
        match=r"NaN or inf at the initial guess.*Start from parameters",
    ),
    _c(
        "nan-data",
        "calibrate",
        "a NaN sample in the data",
        lambda: calibrate(
            Slope(jnp.array(1.0)), {"x": _X, "y": _Y.at[3].set(NAN)}, EquationError(_line)
        ),
        match=r"non-finite value.*index \(3,\).*Remove or interpolate",
    ),
    # --- weights -------------------------------------------------------------------------
    _c(
        "weights-zero",
        "calibrate",
        "weights=0.0",
        lambda: _calibrate(_line, weights=0.0),
        match=r"weights are all zero.*cost.*(positive|1/σ)",
    ),
    _c(
        "weights-zero-array",
        "calibrate",
        "weights = zeros(20)",
        lambda: _calibrate(_line, weights=jnp.zeros(20)),
        match=r"weights are all zero.*(positive|1/σ)",
    ),
    _c(
        "weights-nan",
        "calibrate",
        "weights=nan",
        lambda: _calibrate(_line, weights=NAN),
        match=r"weights .*(NaN|non-finite).*finite",
    ),
    _c(
        "weights-negative",
        "calibrate",
        "weights=-1.0",
        lambda: _calibrate(_line, weights=-1.0),
        match=r"weights must be >= 0.*1/σ",
    ),
    _c(
        "weights-some-zero",
        "calibrate",
        "half of the weights 0 (legal: those samples ignored)",
        lambda: float(_calibrate(_line, weights=jnp.r_[jnp.ones(10), jnp.zeros(10)]).values[0]),
        exc=None,
        # the weighted fit uses the first 10 samples only: the least-squares slope there
        check=lambda a: np.testing.assert_allclose(
            a, float(jnp.dot(_X[:10], _Y[:10]) / jnp.dot(_X[:10], _X[:10])), rtol=1e-6
        ),
    ),
    # --- options -------------------------------------------------------------------------
    _c(
        "max-steps-zero",
        "calibrate",
        "max_steps=0",
        lambda: _calibrate(_line, max_steps=0),
        match=r"max_steps must be a positive int",
    ),
    _c(
        "confidence",
        "calibrate",
        "confidence=1.5",
        lambda: _calibrate(_line, confidence=1.5),
        match=r"confidence must lie in \(0, 1\)",
    ),
    _c(
        "residual-function",
        "calibrate",
        "a plain function as the residual",
        lambda: calibrate(Slope(jnp.array(1.0)), _DATA, _line),
        exc=TypeError,
        match=r"wrap a plain function as EquationError\(fn\)",
    ),
    _c(
        "residuals-vs-data",
        "calibrate",
        "2 residuals, 1 data set",
        lambda: calibrate(Slope(jnp.array(1.0)), _DATA, [EquationError(_line)] * 2),
        match=r"2 residuals need a list of 2 data objects",
    ),
    _c(
        "too-few-residuals",
        "calibrate",
        "1 residual for 2 free parameters",
        lambda: calibrate(
            (Slope(jnp.array(1.0)), Slope(jnp.array(2.0))),
            {"x": _X[:1]},
            EquationError(lambda m, d: m[0].a * d["x"] - m[1].a),
        ),
        match=r"1 residuals for 2 free parameters.*needs more data points than free parameters",
    ),
    _c(
        "solver-name",
        "calibrate",
        "solver='newton-raphson'",
        lambda: _calibrate(_line, solver="newton-raphson"),
        match=r"unknown solver 'newton-raphson'; use one of",
    ),
    _c(
        "constant-input",
        "calibrate",
        "SimulationError with a constant input",
        lambda: calibrate(
            RationalTF([1.0], [0.1, 1.0]),
            Record({"u": np.ones(50), "y": np.ones(50)}, dt=0.01),
            SimulationError(),
        ),
        exc=ExcitationWarning,
        match=r"constant.*excit",
    ),
    _c(
        "frequency-error-shapes",
        "calibrate",
        "FrequencyError with omega (10,) and H (9,)",
        lambda: calibrate(
            RationalTF([1.0], [0.1, 1.0]),
            {"omega": jnp.linspace(1, 10, 10), "H": jnp.ones(9, complex)},
            FrequencyError(),
        ),
        match=r"omega \(10,\) and H \(9,\) do not match",
    ),
    _c(
        "frequency-error-relative-zero",
        "calibrate",
        "weighting='relative' with |H| = 0 somewhere",
        lambda: calibrate(
            RationalTF([1.0], [0.1, 1.0]),
            {"omega": jnp.linspace(1, 10, 10), "H": jnp.zeros(10, complex)},
            FrequencyError(weighting="relative"),
        ),
        match=r"divides by \|H\|, which is 0.*drop those frequencies",
    ),
]

# --- fit_rational --------------------------------------------------------------------------

_F = jnp.linspace(1.0, 100.0, 40)
_H = 1.0 / (1.0 - (_F / 50.0) ** 2 + 0.1j * _F / 50.0)


def _fr(ident, what, fn, exc=ValueError, match="", check=None) -> Case:
    return _c(f"fit-rational-{ident}", "fit_rational", what, fn, exc, match, check)


CASES += [
    _fr(
        "zero-data",
        "H = 0 at every frequency",
        lambda: fit_rational(2 * jnp.pi * _F, jnp.zeros(40, complex), (0, 2)),
        match=r"H is zero at every frequency.*(measurement|channel|scal)",
    ),
    _fr(
        "nan-data",
        "H with a NaN",
        lambda: fit_rational(2 * jnp.pi * _F, _H.at[4].set(NAN), (0, 2)),
        match=r"H (contains NaN or inf|has 1 non-finite).*Drop those frequency points",
    ),
    _fr(
        "order-negative",
        "order (0, -1)",
        lambda: fit_rational(2 * jnp.pi * _F, _H, (0, -1)),
        match=r"order \(nb, na\) = \(0, -1\) needs na >= 1 and nb >= 0",
    ),
    _fr(
        "too-few-points",
        "3 frequencies for order (2, 4)",
        lambda: fit_rational(2 * jnp.pi * _F[:3], _H[:3], (2, 4)),
        match=r"3 frequency points cannot determine 7 parameters.*Give at least 7 points",
    ),
    _fr(
        "weights-zero",
        "weights all zero",
        lambda: fit_rational(2 * jnp.pi * _F, _H, (0, 2), weights=jnp.zeros(40)),
        match=r"weights are all zero",
    ),
    _fr(
        "shapes",
        "omega (40,) and H (39,)",
        lambda: fit_rational(2 * jnp.pi * _F, _H[:-1], (0, 2)),
        match=r"H of shape \(39,\) does not match omega of shape \(40,\)",
    ),
    _fr(
        "exact",
        "an exact second-order FRF (legal: recovered)",
        lambda: fit_rational(2 * jnp.pi * _F, _H, (0, 2))[0],
        exc=None,
        # noiseless data of the model class: the fit reproduces H to solver precision
        check=lambda tf: np.testing.assert_allclose(
            np.asarray(frequency_response(tf, 2 * jnp.pi * _F)), np.asarray(_H), rtol=1e-6
        ),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)
