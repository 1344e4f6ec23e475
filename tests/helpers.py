"""Shared test utilities: tree comparison and registries of models for parametrised tests."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxvs


def tree_allclose(x, y, *, rtol=1e-5, atol=1e-8) -> bool:
    lx, tx = jax.tree_util.tree_flatten(x)
    ly, ty = jax.tree_util.tree_flatten(y)
    if tx != ty:
        return False
    return all(
        np.allclose(np.asarray(a), np.asarray(b), rtol=rtol, atol=atol) for a, b in zip(lx, ly)
    )


def random_modal(rng: np.random.Generator, n_modes: int = 4, *, f_lo=5.0, f_hi=500.0):
    """Random stable lightly damped modal model, modes log-spread in [f_lo, f_hi] Hz."""
    f = np.sort(np.exp(rng.uniform(np.log(f_lo), np.log(f_hi), n_modes)))
    w = 2 * np.pi * f
    z = rng.uniform(0.01, 0.2, n_modes)
    r = rng.normal(size=n_modes) * w**2 / n_modes
    return jaxvs.ModalModel(jnp.asarray(w), jnp.asarray(z), jnp.asarray(r))


def random_rational(rng: np.random.Generator, order: int = 8, *, proper_equal: bool = True):
    """Random stable RationalTF of the given order from a random modal model."""
    m = random_modal(rng, order // 2)
    ss = m.to_state_space()
    import scipy.signal as sig

    num, den = sig.ss2tf(np.asarray(ss.A), np.asarray(ss.B), np.asarray(ss.C), np.asarray(ss.D))
    num = num[0]
    if proper_equal:
        num = num + rng.normal() * den
    return jaxvs.RationalTF(jnp.asarray(num), jnp.asarray(den))


# Registries: every linear model family, as (name, factory(rng)) pairs.
LINEAR_MODELS = [
    ("rational", lambda rng: random_rational(rng, 8)),
    (
        "rational_odd",
        lambda rng: jaxvs.RationalTF(jnp.array([1.0, 2.0, 3.0]), jnp.array([1.0, 6.0, 11.0, 6.0])),
    ),
    ("modal", lambda rng: random_modal(rng, 4)),
    (
        "modal_complex",
        lambda rng: jaxvs.ModalModel(
            jnp.array([30.0, 400.0]),
            jnp.array([0.05, 0.1]),
            jnp.array([1.0 + 2.0j, -3.0 + 0.5j]) * 1e3,
        ),
    ),
    ("statespace", lambda rng: random_modal(rng, 3).to_state_space()),
]


# ----------------------------------------------------------------------------- every model
class ModelCase:
    """One registry entry: a model, one experiment's input `u` at sample time `dt`, the
    identifiable parameters `free(model) -> leaves` for recovery and gradient checks, and
    documented construction errors `[(callable, exception, match)]`."""

    def __init__(self, model, u, dt, free, errors=(), rtol=1e-6):
        self.model, self.u, self.dt, self.free, self.errors = model, u, dt, free, list(errors)
        self.rtol = rtol  # recovery tolerance (noiseless data; diffrax models: its rtol)


def _prbs(n, seed=0):
    rng = np.random.default_rng(seed)
    return jnp.asarray(np.repeat(rng.choice([-1.0, 1.0], size=n // 10), 10))


def _first_order():
    m = jaxvs.models.FirstOrder(20.0, 5.0, 30.0)
    # a function of time only: u sets the length (a PRBS, so no ExcitationWarning)
    return ModelCase(m, _prbs(100), 1.0, lambda m: (m.T0, m.k, m.T1))


def _piecewise():
    m = jaxvs.models.PiecewiseFirstOrder([0.0, 50.0], [20.0, 24.0], [5.0, -3.0], [20.0, 10.0])
    errors = [
        (
            lambda: jaxvs.models.PiecewiseFirstOrder([0, 50.0], [20.0], [5.0, -3], [20.0, 10]),
            ValueError,
            "same length",
        )
    ]
    return ModelCase(m, _prbs(100), 1.0, lambda m: (m.k, m.T1), errors)


def _driven():
    m = jaxvs.models.DrivenFirstOrder(20.0, 0.002, 40.0)
    u = jnp.asarray(np.repeat([1000.0, 3000.0, 2000.0, 500.0], 50))
    return ModelCase(m, u, 1.0, lambda m: (m.K, m.T1), [], rtol=1e-4)


def _regression():
    m = jaxvs.models.BiasFreeRegression([0.8, -0.3], 1.5, [20.0, 10.0])
    u = jnp.stack([20 + _prbs(100), 10 + _prbs(100, 1)], axis=1)
    return ModelCase(m, u, 1.0, lambda m: (m.coef, m.intercept), [])


def _first_order_lag():
    m = jaxvs.models.FirstOrderLag(5.0, 0.5)
    return ModelCase(m, _prbs(100), 1.0, lambda m: (m.tau,))


def _rigid_inverse_dynamics():
    m = jaxvs.models.RigidInverseDynamics(12.0, 40.0, 3.0)
    # velocity [m/s] and acceleration [m/s²] of an axis moving both ways
    u = jnp.stack([0.1 * _prbs(100), 2.0 * _prbs(100, 1)], axis=1)
    return ModelCase(m, u, 1e-3, lambda m: (m.M, m.Fv, m.offset))


def _network(cls, **kw):
    import jax.random as jr

    m = cls(2, 4, key=jr.key(0), **kw)
    u = jnp.asarray(np.random.default_rng(3).normal(size=(100, 2)))  # rich in amplitude
    # the output layer is linear in its weights: identifiable from noiseless data
    return ModelCase(m, u, 1.0, lambda m: (m.perceptron.W2, m.perceptron.b2), [])


def _virtual_sensor():
    tmf = jaxvs.RationalTF(jnp.array([1.0, 40.0, 4e4]), jnp.array([1.0, 60.0, 4e4]))
    m = jaxvs.VirtualSensor(tmf)
    return ModelCase(m, 1e-3 * _prbs(200), 1e-3, lambda m: (m.tmf.num,), [])


def _drive_axis():
    from jaxvs.models import (
        DriveAxis,
        ForceGain,
        PositionLoop,
        RigidAxis,
        VelocityLoop,
        ViscousFriction,
    )

    m = DriveAxis(
        RigidAxis(10.0, ViscousFriction(50.0)), PositionLoop(40.0), VelocityLoop(2000.0),
        ForceGain(1.0),
    )
    u = jnp.asarray(np.r_[0.0, np.full(99, 1e-3)])
    return ModelCase(m, u, 1e-3, lambda m: (m.mechanics.mass,), [], rtol=1e-4)


def _oscillator_chain():
    # two masses, first mode ~ 140 rad/s: a force on each mass, both displacements out
    m = jaxvs.OscillatorChain([1.0, 0.5], [4e4, 2e4], [20.0, 10.0])
    u = jnp.stack([_prbs(300), _prbs(300, 1)], axis=1)
    errors = [
        (
            lambda: jaxvs.OscillatorChain([1.0, 0.5], [4e4], [20.0]),
            ValueError,
            "has 2 springs",
        )
    ]
    return ModelCase(m, u, 1e-3, lambda m: (m.stiffnesses,), errors)


def _stable_tmf():
    tf = jaxvs.RationalTF(jnp.array([1.0, 40.0, 4e4]), jnp.array([1.0, 60.0, 4e4]))
    m = jaxvs.models.StableTMF.from_rational(tf, 200.0, 1e-3)
    errors = [
        (
            lambda: jaxvs.models.StableTMF(
                jnp.array([1.0, jnp.nan, 1.0]), jnp.zeros(1), jnp.zeros(1), jnp.zeros(0), 1.0,
                1e-3,
            ),
            ValueError,
            "num has 1 non-finite",
        )
    ]
    return ModelCase(m, 1e-3 * _prbs(200), 1e-3, lambda m: (m.num, m.log_omega), errors)


def _designed_sensor():
    from jaxvs.studies.design import DesignedSensor, LagCore

    m = DesignedSensor(
        inputs=("a", "b"),
        target="y",
        columns=((0, 0), (0, 2), (1, 0), (1, -1)),  # a(k), a(k - 2), b(k), b(k)²
        structure="lag",
        dt=1.0,
        u_offset=jnp.array([0.5, -0.2]),
        u_scale=jnp.array([2.0, 1.5]),
        y_offset=jnp.asarray(20.0),
        y_scale=jnp.asarray(3.0),
        core=LagCore(jnp.asarray(0.8), jnp.array([0.5, -0.2, 0.3, 0.1]), jnp.asarray(0.1)),
    )
    u = jnp.asarray(np.random.default_rng(4).normal(size=(120, 2)))
    errors = [(lambda: m.predict(u, 2.0), ValueError, "designed at 1.0 s")]
    return ModelCase(m, u, 1.0, lambda m: (m.core.a, m.core.w), errors)


def _cartesian_machine():
    from jaxvs.models import (
        CartesianMachine,
        DriveAxis,
        MachineErrors,
        PositionLoop,
        RigidAxis,
        VelocityLoop,
        ViscousFriction,
    )

    def drive():
        return DriveAxis(RigidAxis(10.0, ViscousFriction(50.0)), PositionLoop(40.0),
                         VelocityLoop(2000.0))

    travel = ((0.0, 0.5), (0.0, 0.4), (0.0, 0.4))
    errors = MachineErrors(travel, 2, positioning=np.full((3, 2), 2e-6),
                           squareness=np.array([3e-5, -2e-5, 1e-5]))
    m = CartesianMachine(drive(), drive(), drive(), errors, tool_offset=(0.0, 0.0, -0.1))
    s = np.linspace(0.0, 1.0, 60)
    u = jnp.asarray(np.stack([0.1 + 0.2 * s, 0.1 + 0.2 * s**2, 0.3 - 0.2 * s], axis=1))
    errs = [
        (lambda: CartesianMachine(drive(), drive(), drive(), errors, structure="WXZT"),
         ValueError, "structure must read"),
        (lambda: MachineErrors(((0, 500), (0, 400), (0, 400))), ValueError, "in mm"),
    ]
    return ModelCase(m, u, 1e-3, lambda m: (m.errors.squareness,), errs, rtol=1e-4)


# Every concrete jaxvs.models.AbstractModel, as (name, factory) pairs; a new model class is
# added here and gets the jit / vmap / gradient / recovery / error tests of
# tests/test_models_registry.py (which fails while a model class is missing).
MODELS = [
    ("rational", lambda: ModelCase(random_rational(np.random.default_rng(0), 4), _prbs(200), 1e-3,
                                   lambda m: (m.num,), [])),
    ("modal", lambda: ModelCase(random_modal(np.random.default_rng(1), 2), _prbs(200), 1e-3,
                                lambda m: (m.omega_n, m.zeta), [])),
    ("statespace", lambda: ModelCase(random_modal(np.random.default_rng(2), 2).to_state_space(),
                                     _prbs(200), 1e-3, lambda m: (m.C,), [])),
    ("first_order", _first_order),
    ("piecewise_first_order", _piecewise),
    ("driven_first_order", _driven),
    ("bias_free_regression", _regression),
    ("first_order_lag", _first_order_lag),
    ("rigid_inverse_dynamics", _rigid_inverse_dynamics),
    ("static_network", lambda: _network(jaxvs.models.StaticNetwork)),
    ("time_delay_network", lambda: _network(jaxvs.models.TimeDelayNetwork)),
    ("virtual_sensor", _virtual_sensor),
    ("drive_axis", _drive_axis),
    ("oscillator_chain", _oscillator_chain),
    ("stable_tmf", _stable_tmf),
    ("designed_sensor", _designed_sensor),
    ("cartesian_machine", _cartesian_machine),
]
