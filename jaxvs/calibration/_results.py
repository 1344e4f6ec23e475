"""Result codes of every jaxvs fit: one enumeration, extending optimistix's (which extends
lineax's), so a code from an optimistix or lineax solve is promoted without translation.

`calibrate`, `fit_rational`, `fit_first_order`, `train_lm` and the diagnosis report one of
these; `RESULTS.successful` is the only success. Each member's value is the message
raised with `throw=True`; [`describe`][] prints a code readably (outside `jit`).
"""

import warnings

import numpy as np
import optimistix as optx

__all__ = ["RESULTS", "describe", "failure_message"]

# The members shared with optimistix/lineax get messages that say what to do in jaxvs;
# equinox warns that an inherited message is replaced, which is the point here.
with warnings.catch_warnings():
    warnings.simplefilter("ignore", UserWarning)

    class RESULTS(optx.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
        """Outcome of a fit. `RESULTS.successful` is the only success.

        Compare codes with `result == RESULTS.successful` (works under `jit` and `vmap`);
        `jaxvs.calibration.describe(result)` gives the name and message.
        """

        successful = ""
        max_steps_reached = (
            "The maximum number of Levenberg-Marquardt (or solver) steps was reached: the fit "
            "did not converge within max_steps. Increase `max_steps` (or the "
            "training `epochs`), loosen the solver's `rtol`, start closer to the solution "
            "(e.g. jaxvs.calibration.multistart), or reparametrise badly scaled parameters "
            "(positive/bounded); for fit_rational check the model order. Pass throw=False "
            "to inspect the last iterate."
        )
        nonfinite = (
            "Non-finite values (NaN or inf) appeared during the fit: the model could not be "
            "evaluated at some "
            "iterate (a parameter crossed zero, a simulation diverged, a frequency grid "
            "with a pole at the origin, extreme weights or data spanning ~300 decades). "
            "Constrain the parameters (jaxvs.calibration.positive / bounded / stable), "
            "start closer to the solution, or rescale the data (e.g. divide by its RMS)."
        )
        singular = (
            "The Jacobian at the solution is rank deficient: some parameters are not "
            "identifiable from these data (an unexciting input, redundant or compensating "
            "parameters, or an order so high that a pole-zero pair cancels). Excite the "
            "system more (PRBS, swept sine), add experiments, fix parameters with free=..., "
            "or lower the order; the estimate may still be usable (throw=False), its "
            "covariance is not."
        )
        nonfinite_initial_guess = (
            "The residual or its Jacobian is NaN or inf at the initial guess. Start from "
            "parameters where the model can be evaluated (no zero time constant or mass, no "
            "division by a zero parameter, a simulation that does not blow up), check the "
            "data for NaN/inf, and check the initial state."
        )
        degenerate_initial_guess = (
            "The initial guess is degenerate: some free parameters had no influence on the "
            "residual there (zero Jacobian columns: a zero gain or residue hides time "
            "constants and frequencies; a zero or constant input excites nothing) and are "
            "still not identified at the end. Start from a non-degenerate guess, use an "
            "exciting input, or fix those parameters with free=..."
        )
        linear_solve_failed = (
            "The solver's linear solve failed (a singular or ill-posed step). Reparametrise "
            "badly scaled parameters, fix redundant ones with free=..., or use the default "
            "solver (jaxvs.calibration.LevenbergMarquardt)."
        )
        unstable_initial_guess = (
            "The initial guess has poles in the right half-plane: the initial guess is "
            "unstable, so its simulation diverges, or every iterate must stay stable. Start "
            "from a stable model (reflect unstable poles p -> -conj(p)), parametrise it with "
            "jaxvs.calibration.stable(model), or pass stable=False to fit_rational to fit "
            "an unstable model."
        )
        unstable_data = (
            "The data look like the response of an unstable system: the unconstrained linear "
            "fit needs poles in the right half-plane, and the best stable model fits at least "
            "twice worse. Pass `stable=False` to fit an unstable model (e.g. an open-loop "
            "unstable plant measured in closed loop), or check the sign convention of the "
            "phase of H (H(jw) with w > 0, e^{+jwt} convention)."
        )
        zero_data = (
            "The data are identically zero (or every weight is zero): there is nothing to "
            "fit. Check the signal selection, the units and the weights."
        )
        # Training stops of trainlm (Hagan & Menhaj 1994; MATLAB trainlm). They end a
        # training normally but are not convergence of the least-squares problem.
        validation_stop = (
            "Training stopped early: the validation error did not improve for `max_fail` "
            "epochs (the best-validation weights are returned)."
        )
        damping_limit = (
            "Training stopped: the damping reached `mu_max` without reducing the error "
            "(a local minimum for this initialisation); try more initialisations."
        )
        gradient_small = "Training stopped: the gradient fell below `min_grad`."
        goal_reached = "Training stopped: the training error reached `goal`."


def describe(result: RESULTS) -> str:
    """The member name of a concrete result code (`"successful"`, `"max_steps_reached"`,
    ...); `"mixed"` for a batch holding several codes."""
    value = np.unique(np.asarray(result._value))  # pyright: ignore[reportAttributeAccessIssue]
    if value.size != 1:
        return "mixed"
    for name, index in RESULTS._name_to_item.items():  # pyright: ignore
        if int(index._value) == int(value[0]):
            return name
    return f"unknown({int(value[0])})"


def failure_message(result: RESULTS) -> str | None:
    """The message of the first failed member of a concrete (possibly batched) result, or
    `None` when every member succeeded."""
    values = np.asarray(result._value).ravel()  # pyright: ignore[reportAttributeAccessIssue]
    failed = values[values != int(RESULTS.successful._value)]  # pyright: ignore
    if failed.size == 0:
        return None
    return RESULTS._index_to_message[int(failed[0])]  # pyright: ignore
