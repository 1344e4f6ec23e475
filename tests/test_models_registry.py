"""Every model of jaxvs (tests/helpers.py MODELS) through the same checks: the registry is
complete, `predict` under jit and vmap, gradients against finite differences, recovery of
known parameters by `calibrate`, and the documented construction errors."""

import inspect

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MODELS

import jaxvs
from jaxvs.calibration import SimulationError

CASES = [pytest.param(factory, id=name) for name, factory in MODELS]


def _concrete_models():
    # every concrete AbstractModel of the package, wherever it lives (models, studies, ...)
    import jaxvs.studies  # noqa: F401

    def subclasses(cls):
        for sub in cls.__subclasses__():
            yield sub
            yield from subclasses(sub)

    return {
        cls
        for cls in subclasses(jaxvs.models.AbstractModel)
        if cls.__module__.startswith("jaxvs.")
        and not inspect.isabstract(cls)
        and not cls.__name__.startswith(("Abstract", "_"))
    }


def test_registry_holds_every_model():
    registered = {type(factory().model) for _, factory in MODELS}
    missing = _concrete_models() - registered
    assert not missing, f"add these models to tests/helpers.py MODELS: {missing}"


def _scale_free(case, factor):
    leaves = case.free(case.model)
    return eqx.tree_at(case.free, case.model, [leaf * factor for leaf in leaves])


@pytest.mark.parametrize("factory", CASES)
def test_predict_jit_and_vmap(factory):
    case = factory()
    eager = case.model.predict(case.u, case.dt)
    assert eager.shape[0] == case.u.shape[0] and bool(jnp.all(jnp.isfinite(eager)))
    jitted = eqx.filter_jit(lambda m, u: m.predict(u, case.dt))(case.model, case.u)
    np.testing.assert_allclose(jitted, eager, rtol=1e-9, atol=1e-12)  # same arithmetic
    # a family of two parameter sets in one vmapped call equals two calls
    other = _scale_free(case, 1.02)
    dyn = [eqx.filter(m, eqx.is_inexact_array) for m in (case.model, other)]
    static = eqx.filter(case.model, eqx.is_inexact_array, inverse=True)
    stacked = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), *dyn)
    both = eqx.filter_vmap(lambda d: eqx.combine(d, static).predict(case.u, case.dt))(stacked)
    np.testing.assert_allclose(both[0], eager, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(both[1], other.predict(case.u, case.dt), rtol=1e-7, atol=1e-12)


@pytest.mark.parametrize("factory", CASES)
def test_gradient_matches_finite_differences(factory):
    case = factory()
    leaves = case.free(case.model)
    weights = jnp.cos(jnp.arange(case.u.shape[0]) * 0.37)

    def loss(ls):
        y = eqx.tree_at(case.free, case.model, ls).predict(case.u, case.dt)
        return jnp.sum(weights * jnp.reshape(y, (y.shape[0], -1))[:, 0])

    for i, leaf in enumerate(leaves):
        flat = np.asarray(leaf).ravel()
        j = int(np.argmax(np.abs(flat)))  # the largest entry: a well-scaled direction
        h = 1e-6 * max(abs(flat[j]), 1.0)
        e = jnp.zeros(flat.size).at[j].set(1.0).reshape(leaf.shape)
        tangent = [e if k == i else jnp.zeros_like(lf) for k, lf in enumerate(leaves)]
        # forward mode: every model (diffrax ones use a ForwardMode adjoint, as LM needs)
        _, g = jax.jvp(loss, (list(leaves),), (tangent,))
        up = [lf + h * e if k == i else lf for k, lf in enumerate(leaves)]
        dn = [lf - h * e if k == i else lf for k, lf in enumerate(leaves)]
        fd = (float(loss(up)) - float(loss(dn))) / (2 * h)
        # central differences: O(h²) truncation plus rounding ~1e-16·|loss|/h
        assert float(g) == pytest.approx(fd, rel=1e-4, abs=1e-6 * (abs(fd) + 1.0)), (i, g, fd)


@pytest.mark.parametrize("factory", CASES)
def test_recovers_known_parameters(factory):
    case = factory()
    y = case.model.predict(case.u, case.dt)
    guess = _scale_free(case, 1.05)
    out = jaxvs.calibrate(
        guess, {"u": case.u, "y": y, "dt": case.dt}, SimulationError(), free=case.free
    )
    truth = jnp.concatenate([jnp.ravel(leaf) for leaf in case.free(case.model)])
    got = jnp.concatenate([jnp.ravel(leaf) for leaf in case.free(out.model)])
    # noiseless data: the truth is the optimum, to the solver / integrator tolerance
    np.testing.assert_allclose(got, truth, rtol=case.rtol, atol=case.rtol * 1e-3)


@pytest.mark.parametrize("factory", CASES)
def test_documented_errors(factory):
    case = factory()
    for build, exc, match in case.errors:
        with pytest.raises(exc, match=match):
            build()
    with pytest.raises(TypeError):  # predict needs the sample time
        case.model.predict(case.u)  # type: ignore[call-arg]


# --- the physical-range rule: one forbidden value per sign-constrained parameter --------------
# Every model of MODELS is listed; a model without a parameter that cannot be negative says so
# with an empty list (a new model must be added here, or the test below fails).
def _drive(friction=None, mass=10.0):
    from jaxvs.models import DriveAxis, ForceGain, PositionLoop, RigidAxis, VelocityLoop

    return DriveAxis(
        RigidAxis(mass, friction), PositionLoop(40.0), VelocityLoop(2000.0), ForceGain(1.0)
    )


_MOTOR = dict(inductance=1e-3, torque_constant=0.1, back_emf_constant=0.1, inertia=1e-4)
M = jaxvs.models
FORBIDDEN = {
    "rational": [],
    "modal": [],
    "statespace": [],
    "first_order": [(lambda: M.FirstOrder(20.0, 5.0, -300.0), r"FirstOrder: T1 must be > 0 s")],
    "piecewise_first_order": [
        (
            lambda: M.PiecewiseFirstOrder([0.0, 50.0], [20.0, 24.0], [5.0, -3.0], [20.0, -10.0]),
            r"PiecewiseFirstOrder: T1 must be > 0 s",
        )
    ],
    "driven_first_order": [
        (lambda: M.DrivenFirstOrder(20.0, 0.002, 0.0), r"DrivenFirstOrder: T1 must be > 0 s")
    ],
    "bias_free_regression": [],
    "first_order_lag": [(lambda: M.FirstOrderLag(-30.0), r"FirstOrderLag: tau must be >= 0 s")],
    "rigid_inverse_dynamics": [
        (lambda: M.RigidInverseDynamics(-1.0, 40.0), r"RigidInverseDynamics: M must be >= 0 kg"),
        (
            lambda: M.RigidInverseDynamics(12.0, -40.0),
            r"RigidInverseDynamics: Fv must be >= 0 N·s/m",
        ),
    ],
    "static_network": [],
    "time_delay_network": [],
    "virtual_sensor": [],
    "drive_axis": [
        (lambda: _drive(M.ViscousFriction(-200.0)), r"ViscousFriction: Fv must be >= 0"),
        (lambda: _drive(M.CoulombFriction(-20.0)), r"CoulombFriction: Fc must be >= 0 N"),
        (lambda: M.CoulombViscousFriction(10.0, -1.0), r"CoulombViscousFriction: Fv must be"),
        (lambda: M.StribeckFriction(10.0, -12.0, 0.01), r"StribeckFriction: Fs must be >= 0"),
        (lambda: M.DCMotor(-1.0, **_MOTOR), r"DCMotor: resistance must be > 0 Ω"),
        (
            lambda: M.DCMotor(1.0, **{**_MOTOR, "inertia": -1e-4}),
            r"DCMotor: inertia must be > 0 kg·m²",
        ),
    ],
    # no parameter with a physical sign in the constructor: StableTMF holds log-frequencies
    # and signed residues, the designed sensor normalisations and weights, the machine
    # signed geometric errors; the chain's masses and stiffnesses are checked also under
    # jit (`eqx.error_if`, tests/test_chain.py)
    "stable_tmf": [],
    "designed_sensor": [],
    "oscillator_chain": [],
    "cartesian_machine": [],
}


def test_every_model_declares_its_forbidden_values():
    assert set(FORBIDDEN) == {name for name, _ in MODELS}


@pytest.mark.parametrize("name", sorted(FORBIDDEN))
def test_physical_range_rule(name):
    """A negative mass, friction level, resistance or time constant is refused by the
    constructor with one message form: the parameter, its bound and unit, the value, the fix."""
    for build, match in FORBIDDEN[name]:
        with pytest.raises(ValueError, match=match + r".*cannot be negative.*Give its magnitude"):
            build()


def test_computed_values_pass_the_rule():
    """A JAX array is a computed value (a fit's trial point, a diagnosis effect's signed
    parameter): the constructor takes it, so a fit is not stopped on its way."""
    assert float(M.ViscousFriction(jnp.asarray(-1.0)).Fv) == -1.0
    fit = jax.jit(lambda t1: M.FirstOrder(20.0, 5.0, t1).predict(jnp.zeros(3), 1.0))
    assert np.all(np.isfinite(np.asarray(fit(jnp.asarray(-30.0)))))
