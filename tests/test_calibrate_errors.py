"""Bad input and failed calibrations: each documented error, eagerly and under jit, and
the parametrisation helpers."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxvs
from jaxvs.calibration import (
    RESULTS,
    CalibrationError,
    EquationError,
    ExcitationWarning,
    FrequencyError,
    Joint,
    PredictionError,
    SimulationError,
    bounded,
    calibrate_family,
    fixed,
    positive,
    stable,
    stable_denominator,
    unwrap,
)


class FirstOrder(eqx.Module):
    T0: jax.Array
    k: jax.Array
    T1: jax.Array

    def __call__(self, t):
        return self.T0 + self.k * (1 - jnp.exp(-t / self.T1))


CURVE = EquationError(lambda m, d: m(d["t"]) - d["y"])
T = np.linspace(0.0, 10.0, 40)
Y = 20.0 + 5.0 * (1 - np.exp(-T / 2.0))


def first_order(T0=15.0, k=1.0, T1=1.0):
    return FirstOrder(jnp.asarray(T0), jnp.asarray(k), jnp.asarray(T1))


# ----------------------------------------------------------------------------- data


def test_nonfinite_data():
    y = Y.copy()
    y[7] = np.nan
    with pytest.raises(ValueError, match=r"non-finite value\(s\), the first at index \(7,\)"):
        jaxvs.calibrate(first_order(), {"t": T, "y": y}, CURVE)
    with pytest.raises(ValueError, match="'y' has 1 non-finite"):
        jaxvs.calibrate(first_order(), {"u": np.ones(40), "y": y, "dt": 0.1}, SimulationError())
    with pytest.raises(ValueError, match="'H' has 1 non-finite"):
        jaxvs.calibrate(first_order(), {"omega": T + 1, "H": y + 0j}, FrequencyError())
    # under jit the values are checked at run time
    fit = eqx.filter_jit(lambda y: jaxvs.calibrate(first_order(), {"t": T, "y": y}, CURVE).values)
    with pytest.raises(eqx.EquinoxRuntimeError, match="NaN or inf"):
        fit(jnp.asarray(y))


def test_fewer_data_points_than_parameters():
    with pytest.raises(ValueError, match="3 residuals for 3 free parameters"):
        jaxvs.calibrate(first_order(), {"t": T[:3], "y": Y[:3]}, CURVE)


def test_malformed_time_data():
    res = SimulationError()
    with pytest.raises(ValueError, match="same number of samples"):
        jaxvs.calibrate(first_order(), {"u": np.ones(40), "y": np.ones(39), "dt": 0.1}, res)
    with pytest.raises(ValueError, match="no signal 'force'"):
        jaxvs.calibrate(
            first_order(), {"u": np.ones(40), "y": Y, "dt": 0.1}, SimulationError(inputs="force")
        )
    with pytest.raises(ValueError, match="sample time 'dt'"):
        jaxvs.calibrate(first_order(), {"u": np.ones(40), "y": Y}, res)
    with pytest.raises(ValueError, match="positive finite scalar"):
        jaxvs.calibrate(first_order(), {"u": np.ones(40), "y": Y, "dt": -1.0}, res)
    with pytest.raises(ValueError, match="not uniform"):
        jaxvs.calibrate(first_order(), {"u": np.ones(40), "y": Y, "t": T**2}, res)
    with pytest.raises(ValueError, match="skip=40 leaves no samples"):
        jaxvs.calibrate(
            first_order(), {"u": np.arange(40.0), "y": Y, "dt": 0.1}, SimulationError(skip=40)
        )
    with pytest.raises(ValueError, match="unknown method 'rk4'"):
        SimulationError(method="rk4")
    with pytest.raises(TypeError, match="do not know how to simulate a FirstOrder"):
        jaxvs.calibrate(first_order(), {"u": np.arange(40.0), "y": Y, "dt": 0.1}, res)
    with pytest.raises(TypeError, match="pass several experiments to calibrate as a list"):
        res.prepare(({"u": 1}, {"u": 2}))


def test_malformed_frequency_data():
    with pytest.raises(ValueError, match="do not match"):
        jaxvs.calibrate(first_order(), {"omega": T, "H": np.ones(39) + 0j}, FrequencyError())
    with pytest.raises(ValueError, match="needs the data's coherence"):
        FrequencyError(weighting="coherence").prepare({"omega": T, "H": Y + 0j})
    with pytest.raises(ValueError, match="weighting must be None"):
        FrequencyError(weighting="magnitude")
    with pytest.raises(ValueError, match="divides by \\|H\\|"):
        FrequencyError(weighting="relative").prepare({"omega": T, "H": np.zeros(40) + 0j})
    model = jaxvs.ModalModel(jnp.array([10.0]), jnp.array([0.1]), jnp.array([[1.0, 2.0]]))
    with pytest.raises(ValueError, match=r"response has shape \(40, 2, 1\)"):
        jaxvs.calibrate(model, {"omega": T + 1, "H": Y + 0j}, FrequencyError())


def test_malformed_problem():
    data = {"t": T, "y": Y}
    with pytest.raises(TypeError, match="must be a jaxvs residual"):
        jaxvs.calibrate(first_order(), data, lambda m, d: m(d["t"]) - d["y"])
    with pytest.raises(ValueError, match="2 residuals need a list of 2"):
        jaxvs.calibrate(first_order(), data, [CURVE, CURVE])
    with pytest.raises(ValueError, match="one weight per residual"):
        Joint([CURVE, CURVE], weights=[1.0])
    with pytest.raises(ValueError, match="Joint: 2 residuals need a list of 2"):
        jaxvs.calibrate(first_order(), [data], Joint([CURVE, CURVE]))
    with pytest.raises(TypeError, match="solver must be None"):
        jaxvs.calibrate(first_order(), data, CURVE, solver=3)
    with pytest.raises(ValueError, match="unknown solver 'newton'"):
        jaxvs.calibrate(first_order(), data, CURVE, solver="newton")
    with pytest.raises(ValueError, match="max_steps must be a positive int"):
        jaxvs.calibrate(first_order(), data, CURVE, max_steps=0)
    with pytest.raises(ValueError, match="confidence must lie in"):
        jaxvs.calibrate(first_order(), data, CURVE, confidence=95)


def test_free_spec_forms():
    model = first_order()
    by_where = jaxvs.calibration.free_spec(model, lambda m: [m.T0, m.T1])
    by_spec = jaxvs.calibration.free_spec(model, FirstOrder(True, False, True))
    assert by_where == by_spec == FirstOrder(True, False, True)
    by_predicate = jaxvs.calibration.free_spec(model, eqx.is_inexact_array)
    assert by_predicate == jaxvs.calibration.free_spec(model) == FirstOrder(True, True, True)
    # fixed leaves and bounds are never free
    wrapped = eqx.tree_at(lambda m: (m.k, m.T1), model, (fixed(1.0), bounded(1.0, 0.5, 3.0)))
    spec = jaxvs.calibration.free_spec(wrapped)
    assert spec.k.value is False and spec.T1.raw is True and spec.T1.lo is False
    with pytest.raises(ValueError, match="attribute or item access"):
        jaxvs.calibration.free_spec(model, lambda m: m.T0[0])
    with pytest.raises(ValueError, match="without floating-point arrays"):
        jaxvs.calibration.free_spec(wrapped, lambda m: m.k)
    ints = FirstOrder(jnp.asarray(15.0), jnp.asarray(1), jnp.asarray(1.0))
    with pytest.raises(TypeError, match="not a floating-point array"):
        jaxvs.calibration.free_spec(ints, FirstOrder(True, True, True))
    with pytest.raises(ValueError, match="no free parameters"):
        jaxvs.calibrate(model, {"t": T, "y": Y}, CURVE, free=FirstOrder(False, False, False))


# ----------------------------------------------------------------------------- failures


MODAL = jaxvs.ModalModel(jnp.array([40.0]), jnp.array([0.1]), jnp.array([1600.0]))


def test_constant_input_is_unexciting():
    """Zero input: every parameter of the predictor is invisible. Warned at set-up, and
    the calibration fails with advice."""
    data = {"u": np.zeros(200), "y": np.zeros(200), "dt": 0.01}
    with pytest.warns(ExcitationWarning, match="is constant"):
        with pytest.raises(CalibrationError, match="a zero or constant input excites nothing"):
            jaxvs.calibrate(MODAL, data, PredictionError(), free=lambda m: m.residues)


def test_unstable_initial_guess():
    unstable = eqx.tree_at(lambda m: m.zeta, MODAL, jnp.array([-0.1]))  # pole in the RHP
    rng = np.random.default_rng(0)
    data = {"u": rng.normal(size=200), "y": rng.normal(size=200), "dt": 0.01}
    free = lambda m: (m.omega_n, m.zeta, m.residues)  # noqa: E731
    with pytest.raises(CalibrationError, match="initial guess is unstable"):
        jaxvs.calibrate(unstable, data, PredictionError(), free=free)
    out = jaxvs.calibrate(unstable, data, PredictionError(), free=free, throw=False)
    assert out.result == RESULTS.unstable_initial_guess
    fit = eqx.filter_jit(
        lambda d: jaxvs.calibrate(unstable, d, PredictionError(), free=free).values
    )
    with pytest.raises(eqx.EquinoxRuntimeError, match="initial guess is unstable"):
        fit(data)
    with pytest.raises(ValueError, match="not stable"):
        stable_denominator(jnp.array([1.0, -1.0, 300.0]))


def test_degenerate_and_nonfinite_initial_guess():
    data = {"t": T, "y": Y}
    # with the gain k fixed at 0, T1 has no influence on the residual: not identifiable
    with pytest.raises(CalibrationError, match="degenerate.*Not identifiable: T1"):
        jaxvs.calibrate(first_order(k=0.0), data, CURVE, free=lambda m: (m.T0, m.T1))
    out = jaxvs.calibrate(first_order(k=0.0), data, CURVE, free=lambda m: (m.T0, m.T1), throw=False)
    assert out.result == RESULTS.degenerate_initial_guess  # singular, traced to the guess
    assert np.isinf(out.std_errors[1]) and np.isfinite(out.std_errors[0])
    # T1 = 0 divides 0 by 0 at t = 0
    with pytest.raises(CalibrationError, match="NaN or inf at the initial guess"):
        jaxvs.calibrate(first_order(T1=0.0), data, CURVE)


def test_non_convergence():
    data = {"t": T, "y": Y}
    with pytest.raises(CalibrationError, match="did not converge within max_steps"):
        jaxvs.calibrate(first_order(), data, CURVE, max_steps=2)
    out = jaxvs.calibrate(first_order(), data, CURVE, max_steps=2, throw=False)
    assert out.result == RESULTS.max_steps_reached and int(out.num_steps) == 2
    fit = eqx.filter_jit(
        lambda y: jaxvs.calibrate(first_order(), {"t": T, "y": y}, CURVE, max_steps=2).values
    )
    with pytest.raises(eqx.EquinoxRuntimeError, match="did not converge within max_steps"):
        fit(jnp.asarray(Y))


def test_family_errors():
    guess = FirstOrder(jnp.full(3, 15.0), jnp.asarray(1.0), jnp.full(3, 1.0))
    data = [{"t": T, "y": Y}] * 3
    with pytest.raises(ValueError, match=r"\.k should carry the positions axis first \(size 3\)"):
        calibrate_family(guess, data, CURVE)
    with pytest.raises(TypeError, match="method at\\(positions\\)"):
        calibrate_family(guess, data, CURVE, positions=[0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="positions axis first"):
        calibrate_family(guess, {"t": T, "y": np.ones((3, 40))}, CURVE)


def test_shared_options_are_checked_by_every_entry_point():
    # multistart / calibrate_family take calibrate's options as **options: a misspelt
    # option or a bad value is refused before any work, as calibrate refuses it.
    guess = FirstOrder(jnp.full(3, 15.0), jnp.full(3, 1.0), jnp.full(3, 1.0))
    data = [{"t": T, "y": Y}] * 3
    with pytest.raises(TypeError, match="unknown option.*max_step.*the options are max_steps"):
        calibrate_family(guess, data, CURVE, max_step=10)
    with pytest.raises(ValueError, match="calibrate_family: max_steps must be a positive int"):
        calibrate_family(guess, data, CURVE, max_steps=0)
    with pytest.raises(ValueError, match="multistart: confidence must lie in"):
        jaxvs.calibration.multistart(guess, {"t": T, "y": Y}, CURVE, confidence=1.5)


# ----------------------------------------------------------------------------- parametrisations


def test_parametrisations_round_trip_and_constrain():
    x = jnp.array([1e-3, 0.5, 20.0])
    for transform in ("log", "softplus"):
        p = positive(x, transform=transform)
        np.testing.assert_allclose(p.unwrap(), x, rtol=1e-12)  # exact inverse up to rounding
        assert jnp.all(
            positive(x, transform=transform).__class__(p.raw - 50, transform).unwrap() > 0
        )
    b = bounded(x, 0.0, 30.0)
    np.testing.assert_allclose(b.unwrap(), x, rtol=1e-12)
    extreme = eqx.tree_at(lambda q: q.raw, b, jnp.array([-30.0, 0.0, 30.0]))
    assert jnp.all((extreme.unwrap() > 0) & (extreme.unwrap() < 30))
    with pytest.raises(ValueError, match="must be > 0"):
        positive(jnp.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="strictly inside"):
        bounded(3.0, 0.0, 3.0)
    with pytest.raises(ValueError, match="need lo < hi"):
        bounded(1.0, 2.0, 0.0)
    with pytest.raises(ValueError, match="transform must be"):
        positive(1.0, transform="exp")
    with pytest.raises(eqx.EquinoxRuntimeError, match="must be > 0"):
        eqx.filter_jit(lambda v: positive(v).unwrap())(jnp.array(-1.0))


@pytest.mark.parametrize(
    "den", [[1.0, 3.0, 2.0], np.polymul([2.0, 0.8, 8.0], [1.0, 2.0, 100.0]), [1.0, 6.0, 11.0, 6.0]]
)
def test_stable_denominator(den):
    """Round trip against numpy, and every raw value gives a Hurwitz polynomial."""
    p = stable_denominator(jnp.asarray(den))
    np.testing.assert_allclose(p.unwrap(), den, rtol=1e-10)  # roots → sections → poly
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = jax.tree_util.tree_map(lambda a: a + rng.normal(size=a.shape) * 2, p)
        q = eqx.tree_at(lambda s: s.lead, q, p.lead)
        assert np.all(np.roots(np.asarray(q.unwrap())).real < 0)
    batched = stable_denominator(jnp.stack([jnp.asarray(den), 2 * jnp.asarray(den)]))
    np.testing.assert_allclose(batched.unwrap()[1], 2 * np.asarray(den), rtol=1e-10)


def test_stable_wraps_linear_models():
    modal = jaxvs.ModalModel(jnp.array([10.0, 50.0]), jnp.array([0.1, 0.2]), jnp.array([1.0, 2.0]))
    tf = jaxvs.RationalTF(jnp.array([1.0, 2.0]), jnp.array([1.0, 3.0, 2.0]))
    for m in (modal, tf):
        assert jax.tree_util.tree_all(jax.tree_util.tree_map(jnp.allclose, unwrap(stable(m)), m))
    with pytest.raises(TypeError, match="no always-stable parametrisation for StateSpace"):
        stable(modal.to_state_space())
    with pytest.raises(TypeError, match="concrete denominator"):
        jax.jit(lambda d: stable_denominator(d).lead)(jnp.array([1.0, 2.0]))
