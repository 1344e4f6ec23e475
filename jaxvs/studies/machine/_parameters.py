"""The calibrated parameters of a `CartesianMachine`: the Legendre coefficients of the 21
geometric error components and the three reversal values, as one named vector."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ...models import COMPONENTS, CartesianMachine, plan_predict
from ...models.drive import AbstractMachineTest

__all__ = [
    "component_curves",
    "geometry",
    "parameter_names",
    "plan_jacobian",
    "plan_readings",
    "with_parameters",
    "parameters",
]

_POS, _STR, _ANG = COMPONENTS[:3], COMPONENTS[3:9], COMPONENTS[9:18]


def geometry(machine: CartesianMachine):
    """The calibrated leaves (a where-function for `jaxvs.calibrate`'s `free`): the error
    coefficients, the squareness and the reversal values."""
    e = machine.errors
    return (e.positioning, e.straightness, e.angular, e.squareness, machine.reversal)


def parameter_names(machine: CartesianMachine) -> list[str]:
    """Names of the entries of [`parameters`][]: `EXX[P1]` … `EC0Y`, `B_X` …."""
    n = machine.errors.degree
    names = [f"{c}[P{k}]" for c in _POS for k in range(1, n + 1)]
    names += [f"{c}[P{k}]" for c in _STR for k in range(2, n + 1)]
    names += [f"{c}[P{k}]" for c in _ANG for k in range(1, n + 1)]
    names += list(COMPONENTS[18:]) + ["B_X", "B_Y", "B_Z"]
    return names


def parameters(machine: CartesianMachine) -> Float[Array, " p"]:
    """The calibrated parameters as one vector, in the order of [`parameter_names`][]."""
    return jnp.concatenate([jnp.ravel(x) for x in geometry(machine)])


def with_parameters(machine: CartesianMachine, theta: Float[Array, " p"]) -> CartesianMachine:
    """`machine` with the parameters of [`parameters`][] replaced by `theta`."""
    leaves = geometry(machine)
    out, i = [], 0
    for x in leaves:
        out.append(jnp.reshape(theta[i : i + x.size], x.shape).astype(x.dtype))
        i += x.size
    return eqx.tree_at(geometry, machine, out)


def plan_readings(machine: CartesianMachine, tests) -> Float[Array, " readings"]:
    """The whitened noise-free readings of a test plan, one vector: each test's readings
    divided by its `sigma / sqrt(runs)` (the noise of its run average)."""
    ys = plan_predict(machine, tests)
    return jnp.concatenate(
        [jnp.ravel(y) * (np.sqrt(t.runs) / t.sigma) for t, y in zip(tests, ys)]
    )


@eqx.filter_jit
def plan_jacobian(machine: CartesianMachine, tests) -> Float[Array, "readings p"]:
    """Jacobian of [`plan_readings`][] in the parameters (forward mode): the whitened
    sensitivity matrix whose `JᵀJ` is the Fisher information of the plan."""
    theta = parameters(machine)
    return jax.jacfwd(lambda th: plan_readings(with_parameters(machine, th), tests))(theta)


def component_curves(machine: CartesianMachine, n_points: int = 51):
    """The 21 components on `n_points` positions over their axis' travel.

    **Returns:** `(positions (3, n_points) [m], curves (21, n_points) [m or rad])`, the
    components in the order of `jaxvs.models.COMPONENTS` (squareness broadcast)."""
    span = np.asarray(machine.travel)
    q = jnp.asarray(np.linspace(span[:, 0], span[:, 1], n_points).T)
    rows = []
    for c in COMPONENTS:
        rows.append(machine.errors.component(c, q["XYZ".index(c[-1])]))
    return q, jnp.stack(rows)


def _assert_tests(tests) -> list[AbstractMachineTest]:
    tests = list(tests)
    if not tests or not all(isinstance(t, AbstractMachineTest) for t in tests):
        raise TypeError(
            "give the test plan as a non-empty list of jaxvs.models tests (LaserLine, "
            "StraightnessLine, AngularLine, BallbarCircle, DiagonalLine)."
        )
    return tests
