"""The one `solver` argument of `calibrate`: optimistix least-squares solvers, optimistix
minimisers (on the sum of squares) and optax gradient transformations."""

from typing import Any

import equinox as eqx
import optax
import optimistix as optx

from ._lm import LevenbergMarquardt

__all__ = ["SOLVER_NAMES", "make_solver"]

SOLVER_NAMES = ("levenberg_marquardt", "gauss_newton", "dogleg", "bfgs")


class _StaticOptax(eqx.Module):
    """An optax transformation held as a static field.

    `optimistix.OptaxMinimiser` turns the closures of the optimiser into pytrees, which
    fails for optax's nested closures such as learning-rate schedules ("Cell is empty").
    Held statically, the transformation is passed through untouched; it holds no arrays
    to trace (its hyper-parameters are Python numbers baked into the compiled solve).
    """

    transform: optax.GradientTransformation = eqx.field(static=True)

    def init(self, params: Any) -> Any:
        return self.transform.init(params)

    def update(self, updates: Any, state: Any, params: Any = None, **extra: Any) -> Any:
        # optimistix passes value/grad/value_fn for optax's "extra args" transformations
        # (e.g. line searches); plain transformations ignore them.
        return optax.with_extra_args_support(self.transform).update(updates, state, params, **extra)


def make_solver(solver: Any, rtol: float | None, atol: float | None) -> Any:
    """Turn the user's `solver` argument into an optimistix solver.

    **Arguments:**

    - `solver`: `None` (jaxvs's [`LevenbergMarquardt`][]), an
      `optimistix.AbstractLeastSquaresSolver` (used as is), an
      `optimistix.AbstractMinimiser` (e.g. `optimistix.BFGS`; it minimises `0.5 Σ r²`),
      an `optax.GradientTransformation` (e.g. `optax.adam(1e-2)`, wrapped in
      `optimistix.OptaxMinimiser`), or one of the names in `SOLVER_NAMES`.
    - `rtol`, `atol`: tolerances of a solver built here from `None` or a name (default
      `1e-8` each). A solver object carries its own: giving both is an error, never
      silently ignored.

    **Returns:**

    An optimistix least-squares solver or minimiser.
    """
    if not (solver is None or isinstance(solver, str)) and (rtol, atol) != (None, None):
        raise ValueError(
            "calibrate: rtol/atol were given together with a solver object, whose own "
            "tolerances would win; set them on the solver instead (e.g. "
            "jaxvs.calibration.LevenbergMarquardt(rtol=1e-10, atol=1e-10))."
        )
    rtol = 1e-8 if rtol is None else rtol
    atol = 1e-8 if atol is None else atol
    if solver is None or solver in ("levenberg_marquardt", "lm"):
        return LevenbergMarquardt(rtol=rtol, atol=atol)
    if isinstance(solver, str):
        if solver == "gauss_newton":
            return optx.GaussNewton(rtol=rtol, atol=atol)
        if solver == "dogleg":
            return optx.Dogleg(rtol=rtol, atol=atol)
        if solver == "bfgs":
            return optx.BFGS(rtol=rtol, atol=atol)
        raise ValueError(
            f"calibrate: unknown solver {solver!r}; use one of {SOLVER_NAMES}, an optimistix "
            "solver object, or an optax optimiser such as optax.adam(1e-2)."
        )
    if isinstance(solver, optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser):
        return solver
    if isinstance(solver, optax.GradientTransformation):
        return optx.OptaxMinimiser(_StaticOptax(solver), rtol=rtol, atol=atol)
    raise TypeError(
        f"calibrate: solver must be None, a name in {SOLVER_NAMES}, an optimistix "
        "least-squares solver or minimiser (e.g. optimistix.BFGS(rtol, atol)), or an optax "
        f"GradientTransformation (e.g. optax.adam(1e-2)); got {type(solver).__name__}."
    )
