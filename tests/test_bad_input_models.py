"""Bad-input matrix, models and `simulate`: non-finite or impossible parameters, empty
polynomials, inputs on the wrong axis, NaN initial states -- eagerly and under `jit`
(row format in `tests/bad_input.py`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from bad_input import Case, run_case

from jaxvs.models import (
    BallScrew,
    CoulombFriction,
    CoulombViscousFriction,
    CurrentLoop,
    DCMotor,
    FirstOrder,
    FlexibleAxis,
    ForceGain,
    ModalModel,
    OscillatorChain,
    PositionLoop,
    RationalTF,
    RigidAxis,
    StateSpace,
    StribeckFriction,
    VelocityLoop,
    ViscousFriction,
    simulate,
)

NAN, INF = float("nan"), float("inf")
ERR = eqx.EquinoxRuntimeError
NONFINITE = r"has \d+ non-finite value.*must be a finite number"


def _m(ident, entry, what, fn, exc=ValueError, match="", check=None) -> Case:
    return Case(
        id=f"model-{ident}",
        area="models",
        entry=f"jaxvs.models.{entry}",
        input=what,
        run=lambda tmp: fn(),
        exc=exc,
        match=match,
        check=check,
    )


def _jit_build(build, value):
    """Build a model from a traced `value` inside `eqx.filter_jit` and simulate it."""

    @eqx.filter_jit
    def run(v):
        return simulate(build(v), jnp.ones(8), 0.1)

    return run(jnp.asarray(value))


def _tf(a):
    return RationalTF(jnp.ones(1), jnp.stack([jnp.ones(()), a]))


def _modal_w(w):
    return ModalModel(jnp.stack([w]), jnp.array([0.05]), jnp.array([1.0]))


def _modal_z(z):
    return ModalModel(jnp.array([10.0]), jnp.stack([z]), jnp.array([1.0]))


def _modal_r(r):
    return ModalModel(jnp.array([10.0]), jnp.array([0.05]), jnp.stack([r]))


def _ss(a):
    return StateSpace(a.reshape(1, 1), jnp.ones((1, 1)), jnp.ones((1, 1)), jnp.zeros((1, 1)))


CASES: list[Case] = [
    # --- RationalTF ----------------------------------------------------------------------
    _m(
        "tf-nan-den",
        "RationalTF",
        "RationalTF([1], [1, nan])",
        lambda: RationalTF([1.0], [1.0, NAN]),
        match=r"RationalTF: den " + NONFINITE,
    ),
    _m(
        "tf-inf-num",
        "RationalTF",
        "RationalTF([inf], [1, 1])",
        lambda: RationalTF([INF], [1.0, 1.0]),
        match=r"RationalTF: num " + NONFINITE,
    ),
    _m(
        "tf-empty-num",
        "RationalTF",
        "RationalTF([], [1, 1]) (empty numerator)",
        lambda: RationalTF([], [1.0, 1.0]),
        match=r"num is empty.*at least one coefficient",
    ),
    _m(
        "tf-empty-den",
        "RationalTF",
        "RationalTF([1], []) (empty denominator)",
        lambda: RationalTF([1.0], []),
        match=r"denominator must have order >= 1",
    ),
    _m(
        "tf-constant-den",
        "RationalTF",
        "RationalTF([1], [2]) (a pure gain)",
        lambda: RationalTF([1.0], [2.0]),
        match=r"order >= 1.*multiply the signal by it",
    ),
    _m(
        "tf-leading-zero",
        "RationalTF",
        "den [0, 1] (leading coefficient 0)",
        lambda: RationalTF([1.0], [0.0, 1.0]),
        exc=ERR,
        match=r"leading denominator coefficient is zero; strip leading zeros",
    ),
    _m(
        "tf-string",
        "RationalTF",
        "num ['a']",
        lambda: RationalTF(["a"], [1.0, 1.0]),
        exc=TypeError,
        match=r"num must be real numbers; got <U1 values. Convert them",
    ),
    _m(
        "tf-complex",
        "RationalTF",
        "num [1j]",
        lambda: RationalTF([1j], [1.0, 1.0]),
        exc=TypeError,
        match=r"num must be real",
    ),
    _m(
        "tf-improper",
        "RationalTF",
        "num of higher order than den",
        lambda: RationalTF([1.0, 0.0, 0.0], [1.0, 1.0]),
        match=r"improper transfer function.*Add poles.*or lower the numerator order",
    ),
    _m(
        "tf-nan-den-jit",
        "RationalTF",
        "den [1, nan] built from a traced value under jit (refused when simulated)",
        lambda: _jit_build(_tf, NAN),
        exc=ERR,
        match=r"simulate: the model's parameters are NaN or inf; give finite parameters",
    ),
    _m(
        "tf-zero-num",
        "RationalTF",
        "RationalTF([0], [1, 1]) (legal: a zero response)",
        lambda: simulate(RationalTF([0.0], [1.0, 1.0]), jnp.ones(5), 0.1),
        exc=None,
        check=lambda y: np.testing.assert_array_equal(y, 0.0),
    ),
    # --- ModalModel ----------------------------------------------------------------------
    _m(
        "modal-nan-omega",
        "ModalModel",
        "omega_n = [nan]",
        lambda: ModalModel([NAN], [0.05], [1.0]),
        match=r"ModalModel: omega_n " + NONFINITE,
    ),
    _m(
        "modal-nan-zeta",
        "ModalModel",
        "zeta = [nan]",
        lambda: ModalModel([10.0], [NAN], [1.0]),
        match=r"ModalModel: zeta " + NONFINITE,
    ),
    _m(
        "modal-nan-residue",
        "ModalModel",
        "residues = [nan]",
        lambda: ModalModel([10.0], [0.05], [NAN]),
        match=r"ModalModel: residues " + NONFINITE,
    ),
    _m(
        "modal-inf-residue",
        "ModalModel",
        "residues = [inf]",
        lambda: ModalModel([10.0], [0.05], [INF]),
        match=r"ModalModel: residues " + NONFINITE,
    ),
    _m(
        "modal-nan-feedthrough",
        "ModalModel",
        "feedthrough = nan",
        lambda: ModalModel([10.0], [0.05], [1.0], feedthrough=NAN),
        match=r"ModalModel: feedthrough " + NONFINITE,
    ),
    _m(
        "modal-negative-omega",
        "ModalModel",
        "omega_n = [-10]",
        lambda: ModalModel([-10.0], [0.05], [1.0]),
        exc=ERR,
        match=r"natural frequencies omega_n must be > 0 rad/s",
    ),
    _m(
        "modal-negative-zeta",
        "ModalModel",
        "zeta = [-0.1]",
        lambda: ModalModel([10.0], [-0.1], [1.0]),
        exc=ERR,
        match=r"damping ratios zeta must be >= 0",
    ),
    _m(
        "modal-shapes",
        "ModalModel",
        "2 frequencies, 1 damping ratio",
        lambda: ModalModel([10.0, 20.0], [0.1], [1.0]),
        match=r"omega_n and zeta must have the same shape",
    ),
    _m(
        "modal-nan-omega-jit",
        "ModalModel",
        "omega_n = [nan] traced under jit (refused when simulated)",
        lambda: _jit_build(_modal_w, NAN),
        exc=ERR,
        match=r"simulate: the model's parameters are NaN or inf; give finite parameters",
    ),
    _m(
        "modal-nan-zeta-jit",
        "ModalModel",
        "zeta = [nan] traced under jit (refused when simulated)",
        lambda: _jit_build(_modal_z, NAN),
        exc=ERR,
        match=r"simulate: the model's parameters are NaN or inf; give finite parameters",
    ),
    _m(
        "modal-nan-residue-jit",
        "ModalModel",
        "residues = [nan] traced under jit (refused when simulated)",
        lambda: _jit_build(_modal_r, NAN),
        exc=ERR,
        match=r"simulate: the model's parameters are NaN or inf; give finite parameters",
    ),
    # --- StateSpace ----------------------------------------------------------------------
    _m(
        "ss-nan-a",
        "StateSpace",
        "A = [[nan]]",
        lambda: StateSpace([[NAN]], [[1.0]], [[1.0]], [[0.0]]),
        match=r"StateSpace: A " + NONFINITE,
    ),
    _m(
        "ss-inf-b",
        "StateSpace",
        "B = [[inf]]",
        lambda: StateSpace([[-1.0]], [[INF]], [[1.0]], [[0.0]]),
        match=r"StateSpace: B " + NONFINITE,
    ),
    _m(
        "ss-nan-d",
        "StateSpace",
        "D = [[nan]]",
        lambda: StateSpace([[-1.0]], [[1.0]], [[1.0]], [[NAN]]),
        match=r"StateSpace: D " + NONFINITE,
    ),
    _m(
        "ss-nonsquare",
        "StateSpace",
        "A of shape (2, 3)",
        lambda: StateSpace(np.ones((2, 3)), np.ones((2, 1)), np.ones((1, 2)), np.ones((1, 1))),
        match=r"inconsistent shapes.*expected A \(n, n\)",
    ),
    _m(
        "ss-1d",
        "StateSpace",
        "B given as a 1-D vector",
        lambda: StateSpace([[-1.0]], [1.0], [[1.0]], [[0.0]]),
        match=r"B must be at least 2-D.*reshape\(-1, 1\)",
    ),
    _m(
        "ss-nan-a-jit",
        "StateSpace",
        "A = [[nan]] traced under jit (refused when simulated)",
        lambda: _jit_build(_ss, NAN),
        exc=ERR,
        match=r"simulate: the model's parameters are NaN or inf; give finite parameters",
    ),
    # --- thermal and drive models --------------------------------------------------------
    _m(
        "first-order-nan",
        "FirstOrder",
        "T1 = nan",
        lambda: FirstOrder(20.0, 1.0, NAN),
        match=r"FirstOrder: T1 " + NONFINITE,
    ),
    _m(
        "first-order-inf-k",
        "FirstOrder",
        "k = inf",
        lambda: FirstOrder(20.0, INF, 1.0),
        match=r"FirstOrder: k " + NONFINITE,
    ),
    _m(
        "rigid-mass-nan",
        "RigidAxis",
        "mass = nan",
        lambda: RigidAxis(NAN),
        exc=ERR,
        match=r"RigidAxis: mass must be > 0 kg",
    ),
    _m(
        "rigid-mass-zero",
        "RigidAxis",
        "mass = 0",
        lambda: RigidAxis(0.0),
        exc=ERR,
        match=r"RigidAxis: mass must be > 0 kg",
    ),
    _m(
        "flexible-nan",
        "FlexibleAxis",
        "masses [1, nan]",
        lambda: FlexibleAxis([1.0, NAN], [1e6], [10.0]),
        exc=ERR,
        match=r"FlexibleAxis: masses must be > 0 kg",
    ),
    _m(
        "flexible-lengths",
        "FlexibleAxis",
        "2 masses, 2 stiffnesses",
        lambda: FlexibleAxis([1.0, 1.0], [1e6, 2e6], [10.0]),
        match=r"2 masses need 1 stiffnesses and dampings",
    ),
    _m(
        "chain-nan",
        "OscillatorChain",
        "masses [1, nan]",
        lambda: OscillatorChain([1.0, NAN], [1e3, 1e3], [1.0, 1.0]),
        exc=ERR,
        match=r"OscillatorChain: masses must be > 0 kg",
    ),
    _m(
        "ballscrew-negative",
        "BallScrew",
        "length = -1",
        lambda: BallScrew(-1.0, 0.02, 0.01),
        exc=ERR,
        match=r"BallScrew: length must be > 0",
    ),
    _m(
        "coulomb-nan",
        "CoulombFriction",
        "Fc = nan",
        lambda: CoulombFriction(NAN),
        match=r"CoulombFriction: Fc " + NONFINITE,
    ),
    _m(
        "coulomb-viscous-nan",
        "CoulombViscousFriction",
        "Fv = nan",
        lambda: CoulombViscousFriction(1.0, NAN),
        match=r"CoulombViscousFriction: Fv " + NONFINITE,
    ),
    _m(
        "viscous-inf",
        "ViscousFriction",
        "Fv = inf",
        lambda: ViscousFriction(INF),
        match=r"ViscousFriction: Fv " + NONFINITE,
    ),
    _m(
        "stribeck-vs-zero",
        "StribeckFriction",
        "vs = 0",
        lambda: StribeckFriction(1.0, 2.0, 0.0),
        exc=ERR,
        match=r"StribeckFriction: vs must be > 0",
    ),
    _m(
        "dcmotor-nan",
        "DCMotor",
        "resistance = nan",
        lambda: DCMotor(NAN, 1e-3, 0.1, 0.1, 1e-3),
        match=r"DCMotor: resistance " + NONFINITE,
    ),
    _m(
        "velocity-loop-nan",
        "VelocityLoop",
        "kv = nan",
        lambda: VelocityLoop(NAN),
        match=r"VelocityLoop: kv " + NONFINITE,
    ),
    _m(
        "position-loop-nan",
        "PositionLoop",
        "kp = nan",
        lambda: PositionLoop(NAN),
        match=r"PositionLoop: kp " + NONFINITE,
    ),
    _m(
        "current-loop-zero",
        "CurrentLoop",
        "time_constant = 0",
        lambda: CurrentLoop(1.0, 0.0),
        exc=ERR,
        match=r"time_constant must be > 0 s \(use ForceGain for none\)",
    ),
    _m(
        "force-gain-nan",
        "ForceGain",
        "gain = nan",
        lambda: ForceGain(NAN),
        match=r"ForceGain: gain " + NONFINITE,
    ),
]

# --- simulate -------------------------------------------------------------------------------

_TF = RationalTF([1.0], [0.1, 1.0])  # 1/(0.1 s + 1): a first-order lag, 10 rad/s
_U = jnp.sin(jnp.arange(300) * 0.05)
_MIMO = StateSpace(-np.eye(2), np.eye(2), np.eye(2), np.zeros((2, 2)))


def _s(ident, what, fn, exc=ValueError, match="", check=None) -> Case:
    return Case(
        id=f"simulate-{ident}",
        area="simulate",
        entry="jaxvs.models.simulate",
        input=what,
        run=lambda tmp: fn(),
        exc=exc,
        match=match,
        check=check,
    )


def _same_as_vector(y):
    # A (300, 1) column for a single-input model is time x inputs: the same response as
    # the (300,) vector (same computation, so equal to rounding).
    np.testing.assert_allclose(np.asarray(y), np.asarray(simulate(_TF, _U, 0.01)), rtol=1e-12)


CASES += [
    _s(
        "column-input",
        "u of shape (300, 1) for a single-input model",
        lambda: simulate(_TF, _U[:, None], 0.01),
        exc=None,
        check=_same_as_vector,
    ),
    _s(
        "row-input",
        "u of shape (1, 300) (one experiment as a batch of 1; legal)",
        lambda: simulate(_TF, _U[None, :], 0.01)[0],
        exc=None,
        check=_same_as_vector,
    ),
    _s(
        "x0-nan",
        "x0 = [nan]",
        lambda: simulate(_TF, _U, 0.01, x0=jnp.array([NAN])),
        match=r"x0 .*(NaN|non-finite).*initial state",
    ),
    _s(
        "x0-nan-jit",
        "x0 = [nan] under jit",
        lambda: eqx.filter_jit(lambda x0: simulate(_TF, _U, 0.01, x0=x0))(jnp.array([NAN])),
        exc=ERR,
        match=r"x0 contains NaN or inf.*initial state",
    ),
    _s(
        "x0-shape",
        "x0 of shape (3,) for a 1-state model",
        lambda: simulate(_TF, _U, 0.01, x0=jnp.zeros(3)),
        match=r"x0 has shape \(3,\); expected \(1,\)",
    ),
    _s(
        "u-nan",
        "u with a NaN sample",
        lambda: simulate(_TF, _U.at[5].set(NAN), 0.01),
        exc=ERR,
        match=r"u contains NaN or inf; clean or interpolate the input",
    ),
    _s(
        "u-complex",
        "complex u",
        lambda: simulate(_TF, _U * 1j, 0.01),
        exc=TypeError,
        match=r"u must be real.*real and imaginary parts separately",
    ),
    _s(
        "u-empty",
        "u with 0 samples",
        lambda: simulate(_TF, jnp.ones(0), 0.01),
        match=r"u has no samples",
    ),
    _s(
        "u-scalar",
        "u a scalar",
        lambda: simulate(_TF, 1.0, 0.01),
        match=r"u has shape \(\); this model has 1 input",
    ),
    _s(
        "mimo-wrong-inputs",
        "u (300, 3) for a 2-input model",
        lambda: simulate(_MIMO, jnp.ones((300, 3)), 0.01),
        match=r"model has 2 inputs; give u as \(\*batch, time, 2\)",
    ),
    _s(
        "mimo-transposed",
        "u (2, 300) for a 2-input model (time on the wrong axis)",
        lambda: simulate(_MIMO, jnp.ones((2, 300)), 0.01),
        match=r"u has shape \(2, 300\) but the model has 2 inputs.*inputs on the last axis",
    ),
    _s(
        "dt-zero",
        "dt = 0",
        lambda: simulate(_TF, _U, 0.0),
        match=r"dt must be a positive, finite sample time in seconds",
    ),
    _s(
        "dt-nan",
        "dt = nan",
        lambda: simulate(_TF, _U, NAN),
        match=r"dt must be a positive, finite sample time in seconds",
    ),
    _s(
        "dt-negative",
        "dt = -0.01",
        lambda: simulate(_TF, _U, -0.01),
        match=r"dt must be a positive, finite sample time in seconds",
    ),
    _s(
        "method",
        "method='rk4'",
        lambda: simulate(_TF, _U, 0.01, method="rk4"),
        match=r"unknown method 'rk4'; choose one of",
    ),
    _s(
        "not-a-model",
        "a function instead of a model",
        lambda: simulate(lambda u: u, _U, 0.01),
        exc=TypeError,
        match=r"expected a jaxvs linear model",
    ),
    _s(
        "batch-mismatch",
        "a family of 3 and inputs for 4",
        lambda: simulate(RationalTF(jnp.ones((3, 1)), jnp.ones((3, 2))), jnp.ones((4, 50)), 0.01),
        match=r"batch shape \(3,\) and u has batch shape \(4,\).*Broadcast explicitly",
    ),
    _s(
        "unstable-model",
        "an unstable model (pole at +50 rad/s)",
        lambda: simulate(RationalTF([1.0], [1.0, -50.0]), jnp.ones(1000), 0.1),
        exc=ERR,
        match=r"not finite.*unstable",
    ),
    _s(
        "nan-model",
        "a model whose parameters became NaN (set with eqx.tree_at)",
        lambda: simulate(eqx.tree_at(lambda m: m.den, _TF, jnp.array([NAN, 1.0])), _U, 0.01),
        exc=ValueError,
        match=r"the model \(RationalTF\) has NaN or inf parameters; give finite parameters",
    ),
    _s(
        "integer-input",
        "integer u (legal: converted to float)",
        lambda: simulate(_TF, jnp.ones(50, dtype=jnp.int32), 0.01),
        exc=None,
        # step response of 1/(0.1 s + 1) held over 0.01 s steps: 1 - exp(-k dt / 0.1)
        check=lambda y: np.testing.assert_allclose(
            np.asarray(y), 1 - np.exp(-np.arange(50) * 0.1), atol=1e-12
        ),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)
