"""Result codes of the jaxvs calibration solvers (one enumeration, shared by every fit)."""

import equinox as eqx


class RESULTS(eqx.Enumeration):
    """Outcome of a calibration. `RESULTS.successful` is the only success.

    Each member's value is the message raised when `throw=True`; compare codes with
    `report.result == RESULTS.successful` (works under `jit` and `vmap`).
    """

    successful = ""
    max_steps_reached = (
        "The maximum number of Levenberg-Marquardt steps was reached before the fit "
        "converged. Increase `max_steps`, loosen `rtol`, or check the model order and the "
        "data (pass `throw=False` to inspect the partial result)."
    )
    nonfinite = (
        "Non-finite values (NaN or inf) appeared during the fit. Check the data for "
        "zeros in the frequency grid combined with poles at the origin, extreme weights, "
        "or responses spanning more than ~300 decades; rescale H (e.g. divide by its "
        "RMS) if it is very large or very small."
    )
    singular = (
        "The Jacobian is singular at the solution: the parameters are not identifiable "
        "from these data (typically the order is too high and a pole-zero pair cancels, "
        "or the frequency grid does not cover the dynamics). Lower `order`, or widen the "
        "frequency band; the fitted response may still be usable (pass `throw=False`), "
        "but its covariance is not."
    )
    unstable_initial_guess = (
        "The initial guess has poles in the right half-plane, but `stable=True` keeps "
        "every iterate stable. Give a stable `init` (e.g. reflect its unstable poles into "
        "the left half-plane), or pass `stable=False` to fit an unstable model."
    )
    unstable_data = (
        "The data look like the response of an unstable system: the unconstrained linear "
        "fit needs poles in the right half-plane, and the best stable model fits at least "
        "twice worse. Pass `stable=False` to fit an unstable model (e.g. an open-loop "
        "unstable plant measured in closed loop), or check the sign convention of the "
        "phase of H (H(jw) with w > 0, e^{+jwt} convention)."
    )
