"""Diagnosis of the `thermal` family on the spindle thermal twin (docs/guides/contracts.md).

The twin's nominal plant is exactly the study's static regression (plus 0.1 K sensor noise),
and each of its effects is built as physics (a heat capacity, a drifting air temperature,
a cycling chiller, Palmgren friction heat), not as the library's augmentation. All
diagnoses use 12 h records at 5 s (8640 samples) so that they share one compilation.
"""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as sig

import jaxvs
from jaxvs.diagnosis._thermal import first_order_lag
from jaxvs.twins import SpindleThermalTwin

HOURS = 3600.0
DURATION = 12 * HOURS


def _record(effects, key=11):
    return SpindleThermalTwin(effects=effects).experiment(jr.key(key), duration=DURATION)


@pytest.fixture(scope="module")
def effect_free():
    return _record({})


def test_lag_matches_scipy_lsim_for_linear_interpolated_input():
    # Oracle: scipy.signal.lsim integrates τẏ + y = s exactly for s linear between samples
    # (interp=True), from the initial state given.
    dt, tau = 5.0, 430.0
    t = np.arange(400) * dt
    s = 20 + 5 * np.sin(2 * np.pi * t / 1800.0) + np.where(t > 700, 8.0, 0.0)
    y = np.asarray(first_order_lag(jnp.asarray(s), jnp.asarray(tau), dt, jnp.asarray(18.0)))
    # the recursion's first sample: state 18 one sample before, input held at s0
    y0 = s[0] + (18.0 - s[0]) * np.exp(-dt / tau)
    _, y_ref, _ = sig.lsim(([1.0], [tau, 1.0]), s, t, X0=[y0 * tau], interp=True)
    assert y[0] == pytest.approx(y0, rel=1e-12)
    # 1e-9 K: both are exact discretisations; only rounding differs
    np.testing.assert_allclose(y, y_ref, atol=1e-9)


def test_lag_is_exactly_nominal_at_zero_time_constant():
    s = jnp.asarray(np.random.default_rng(0).normal(size=50))
    assert np.array_equal(np.asarray(first_order_lag(s, jnp.asarray(0.0), 5.0, s[0] + 3)), s)
    # and tends to it continuously: for τ ≪ dt the first-order hold leaves a share τ/dt of
    # the previous sample, y_k ≈ s_k − (τ/dt)(s_k − s_{k−1}); |Δs| < 6 here
    y = np.asarray(first_order_lag(s, jnp.asarray(5e-6), 5.0))
    np.testing.assert_allclose(y, s, atol=6e-6)
    np.testing.assert_allclose(y[1:], s[1:] - 1e-6 * np.diff(s), atol=1e-12)


def test_effect_free_twin_accepts_nothing_and_reports_untestable(effect_free):
    # Without T_air and T_water the ambient and coolant candidates cannot be tested:
    # they must be reported as such, never silently dropped.
    rec = effect_free.select(["T_chassis", "T_bearing", "v_m"])
    rep = jaxvs.diagnose(rec, family="thermal")
    assert rep.verdict["effects"] == []
    by_name = {c["effect"]: c for c in rep.candidates}
    assert set(by_name) == {
        "dynamics",
        "ambient_temperature",
        "coolant_temperature",
        "speed_nonlinearity",
    }
    assert by_name["ambient_temperature"]["testable"] is False
    assert "T_air" in by_name["ambient_temperature"]["reason"]
    assert by_name["coolant_temperature"]["testable"] is False
    assert "T_water" in by_name["coolant_temperature"]["reason"]
    assert by_name["dynamics"]["testable"] and by_name["speed_nonlinearity"]["testable"]
    # Noise floor: the twin's 0.1 K sensor noise, recovered within 30 % (brief).
    sigma = np.sqrt(rep.calibration[0].noise_var)
    assert 0.07 < sigma < 0.13
    # the validation gap of an adequate model sits at the noise floor (within 30 %)
    assert rep.gap["validation"] == pytest.approx(rep.gap["noise_floor"], rel=0.3)
    json = rep.to_json()
    assert json["family"] == "thermal" and json["verdict"]["effects"] == []
    # nothing accepted and the remainder within the null: adequate, said first
    assert json["verdict"]["status"] == "adequate" and json["verdict"]["adequate"] is True
    # within the null already: no candidate is tried (the omnibus test protects the many)
    assert json["verdict"]["searched"] is False and json["rounds"] == []
    assert "no candidate effect was tried" in rep.to_markdown()
    assert repr(rep).splitlines()[1].startswith("verdict: adequate")
    assert rep.to_markdown().splitlines()[2].startswith("**verdict: adequate")


@pytest.mark.parametrize(
    "effect, magnitude, parameter, expected, rtol",
    [
        # τ of the heat capacity [s]; the lag is exact for the twin's network up to the
        # inter-sample behaviour of the chassis, so 10 % is generous
        ("dynamics", 600.0, "tau_s", 600.0, 0.1),
        # the air's weight in the bearing balance is G_ba / (G_bc + G_bw + G_ba) = 0.35
        ("ambient_temperature", 3.0, "c_air", 0.35, 0.1),
    ],
)
def test_typical_effect_is_found_first_and_closes_the_gap(
    effect, magnitude, parameter, expected, rtol
):
    rep = jaxvs.diagnose(_record({effect: magnitude}), family="thermal")
    assert rep.verdict["effects"][:1] == [effect]
    assert rep.verdict["status"] in ("explained", "partly_explained")
    assert not rep.verdict["adequate"]
    found = next(c for c in rep.candidates if c["effect"] == effect)
    assert found["accepted"] and found["shrink"] > 0.5
    assert found["parameters"][parameter] == pytest.approx(expected, rel=rtol)
    assert rep.verdict["shrink"] > 0.5


def test_missing_required_signal_is_named(effect_free):
    rec = effect_free.select(["T_bearing", "v_m"])
    with pytest.raises(ValueError, match="T_chassis"):
        jaxvs.diagnose(rec, family="thermal")


def test_bad_options_are_rejected(effect_free):
    with pytest.raises(ValueError, match="smoothing_s"):
        jaxvs.diagnose(effect_free, family="thermal", smoothing_s=-1.0)
