"""The one `solver` argument of `calibrate`: optimistix least-squares solvers, optimistix
minimisers (on the sum of squares) and optax gradient transformations."""

from typing import Any

import equinox as eqx
import optax
import optimistix as optx

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


def make_solver(solver: Any, rtol: float, atol: float) -> Any:
    """Turn the user's `solver` argument into an optimistix solver.

    **Arguments:**

    - `solver`: `None` (Levenberg-Marquardt), an `optimistix.AbstractLeastSquaresSolver`
      (used as is), an `optimistix.AbstractMinimiser` (e.g. `optimistix.BFGS`; it
      minimises `0.5 Σ r²`), an `optax.GradientTransformation` (e.g. `optax.adam(1e-2)`,
      wrapped in `optimistix.OptaxMinimiser`), or one of the names in `SOLVER_NAMES`.
    - `rtol`, `atol`: tolerances used when the solver is built here.

    **Returns:**

    An optimistix least-squares solver or minimiser.
    """
    if solver is None or solver in ("levenberg_marquardt", "lm"):
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)
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
