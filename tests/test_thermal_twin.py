"""Spindle thermal twin: nominal plant = static regression, effects break it, physics checks."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as sig

import jaxvs
from jaxvs.twins import (
    STUDY_PARTS,
    THERMAL_TWIN_EFFECTS,
    TYPICAL_THERMAL_EFFECTS,
    SpindleThermalTwin,
    draw_thermal_effect,
)

HOURS = 3600.0


def _regression_rms(rec) -> float:
    """RMS residual of the study's static regression (eq. 2-3) by numpy least squares."""
    X = np.column_stack(
        [
            rec["T_chassis"] - rec["T_chassis"].min(),
            rec["v_m"] - rec["v_m"].min(),
            np.ones(len(rec)),
        ]
    )
    y = rec["T_bearing"]
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    return float(np.sqrt(np.mean((X @ c - y) ** 2)))


def test_nominal_plant_is_static_linear_regression():
    twin = SpindleThermalTwin()
    recs = twin.experiments(jr.split(jr.key(0), 3), duration=12 * HOURS)
    assert _regression_rms(twin.experiment(jr.key(0), duration=12 * HOURS)) < 0.15
    for rec in recs:
        # Noise floor: 0.1 K on the target plus 0.1 K·a on the chassis input with
        # a ≈ 0.25 -> sqrt(0.1² + 0.025²) ≈ 0.103 K; 0.15 K leaves room for estimation.
        assert _regression_rms(rec) < 0.15


@pytest.mark.parametrize("effect", THERMAL_TWIN_EFFECTS)
def test_each_effect_breaks_the_static_regression(effect):
    twin = SpindleThermalTwin({effect: TYPICAL_THERMAL_EFFECTS[effect]})
    recs = twin.experiments(jr.split(jr.key(1), 3), duration=12 * HOURS)
    for rec in recs:
        # 0.3 K is three times the noise floor (0.103 K): a clearly visible gap.
        assert _regression_rms(rec) > 0.3


def test_record_columns_units_and_no_hidden_effect_in_metadata():
    twin = SpindleThermalTwin({"dynamics": 600.0})
    rec = twin.experiment(jr.key(2), STUDY_PARTS, 1800.0)
    for name in (
        "T_chassis",
        "T_bearing",
        "v_m",
        "T_air",
        "T_water",
        "T_bearing_o",
        "T_flange",
        "T_motor",
        "T_chassis_m",
        "preload_force",
        "bending_moment",
        "motor_moment",
        "T_axis",
    ):
        assert name in rec
    assert rec.dt == 5.0 and len(rec) == 5 * 360
    assert rec.units["T_bearing"] == "degC" and rec.units["v_m"] == "rpm"
    assert set(rec.metadata) == {"source", "part_start_times", "part_speeds", "target"}
    text = repr(dict(rec.metadata)).lower()
    for effect in THERMAL_TWIN_EFFECTS + ("tau", "dynamic"):
        assert effect not in text
    np.testing.assert_allclose(rec.metadata["part_speeds"], STUDY_PARTS)
    np.testing.assert_allclose(rec.metadata["part_start_times"], np.arange(5) * 1800.0)


def test_random_profile_parts_and_long_record():
    rec = SpindleThermalTwin().experiment(jr.key(3), duration=35 * HOURS)
    assert len(rec) == 25200
    starts = rec.metadata["part_start_times"]
    lengths = np.diff(np.append(starts, 35 * HOURS))
    assert np.all(lengths[:-1] >= 1200.0 - 5) and np.all(lengths <= 7200.0 + 5)
    speeds = rec.metadata["part_speeds"]
    assert np.all((speeds >= 0) & (speeds <= 8000))
    assert np.all(np.abs(np.diff(speeds)) >= 950)  # an operating-point change at each boundary
    assert len(speeds) >= 17  # 35 h of parts no longer than 2 h


def test_vmap_over_keys_matches_single_runs():
    twin = SpindleThermalTwin({"coolant_temperature": 1.0})
    keys = jr.split(jr.key(4), 2)
    batch = twin.experiments(keys, duration=12 * HOURS)
    for k, rec in zip(keys, batch):
        single = twin.experiment(k, duration=12 * HOURS)
        np.testing.assert_allclose(single.to_array(), rec.to_array(), rtol=1e-12, atol=1e-9)


def test_energy_balance_at_steady_state():
    """Heat in (bearing friction + motor losses) = heat out to water and air.

    Oracle: the conservation law, evaluated on the twin's noiseless steady state after
    30 h at 6000 rpm (the slowest time constant is about 40 min)."""
    twin = SpindleThermalTwin()
    n = int(30 * HOURS / 5.0)
    out = twin.simulate(jr.key(5), jnp.full(n, 6000.0), 5.0, noise=0.0)
    last = {k: float(v[-1]) for k, v in out.items()}
    Ta, Tw = last["T_air"], last["T_water"]
    Tc, Tcm, Tb = last["T_chassis"], last["T_chassis_m"], last["T_bearing"]
    q_in = float(twin.bearing_heat(6000.0) + twin.motor_heat(6000.0))
    g = lambda name: float(getattr(twin, name))
    q_out = (
        g("G_bw") * (Tb - Tw)
        + g("G_ba") * (Tb - Ta)
        + g("G_cw") * (Tc - Tw)
        + g("G_ca") * (Tc - Ta)
        + g("G_cmw") * (Tcm - Tw)
        + g("G_cma") * (Tcm - Ta)
    )
    assert q_in == pytest.approx(q_out, rel=1e-6)  # steady to < 1e-6 after 18 time constants


def test_dynamics_effect_is_first_order_lag_of_nominal_target():
    """Oracle: scipy.signal.lfilter of the nominal target with the exact ZOH pole."""
    speed = jnp.repeat(jnp.array([2000.0, 6000.0, 500.0, 4000.0]), 2160)  # 12 h
    key = jr.key(6)
    nominal = SpindleThermalTwin().simulate(key, speed, 5.0, noise=0.0)
    tau = 900.0
    lagged = SpindleThermalTwin({"dynamics": tau}).simulate(key, speed, 5.0, noise=0.0)
    # The chassis does not depend on τ (it sees the bearing's static heat flow).
    np.testing.assert_allclose(lagged["T_chassis"], nominal["T_chassis"], atol=1e-10)
    # ZOH of a first-order lag: x[k+1] = a x[k] + (1 - a) u[k], output x[k].
    a = np.exp(-5.0 / tau)
    u = np.asarray(nominal["T_bearing_true"])
    # the machine starts cold: at rest, the static value without friction heat
    x0 = float(u[0] - SpindleThermalTwin().bearing_heat(2000.0) / 20.0)  # Σ G_b = 20 W/K
    ref, _ = sig.lfilter([0.0, 1 - a], [1.0, -a], u, zi=[x0])
    # Input held over a step vs the exact continuous chassis: differences well below 0.05 K.
    np.testing.assert_allclose(np.asarray(lagged["T_bearing_true"]), ref, atol=0.05)


def test_speed_nonlinearity_is_power_law():
    twin = SpindleThermalTwin({"speed_nonlinearity": 1.8})
    n = jnp.array([1000.0, 2500.0, 5000.0, 8000.0])
    np.testing.assert_allclose(twin.bearing_heat(n), 320.0 * (n / 5000.0) ** 1.8, rtol=1e-12)
    np.testing.assert_allclose(SpindleThermalTwin().bearing_heat(n), 320.0 * n / 5000.0)


def test_sparse_target_every_90_s_with_outliers():
    twin = SpindleThermalTwin()
    rec = twin.experiment(jr.key(7), duration=12 * HOURS)
    sp = twin.sparse_target(rec, jr.key(8), every=90.0, outliers=0.1)
    gaps = np.diff(sp.t)
    assert 85.0 < gaps.mean() < 95.0 and gaps.min() >= 70.0 and gaps.max() <= 110.0
    idx = np.round(sp.t / rec.dt).astype(int)
    clean = ~sp.outlier
    np.testing.assert_allclose(sp.T_bearing[clean], rec["T_bearing"][idx][clean])
    np.testing.assert_allclose(np.abs(sp.T_bearing - rec["T_bearing"][idx])[sp.outlier], 4.0)
    assert 0.03 < sp.outlier.mean() < 0.2


def test_perturb_and_draw():
    twin = SpindleThermalTwin({"dynamics": 300.0})
    other = twin.perturb(jr.key(9), scale=0.1)
    ratio = float(other.G_cw / twin.G_cw)
    assert ratio != 1.0 and 0.5 < ratio < 2.0
    assert other.effects == {"dynamics": 300.0}
    # a perturbed nominal plant is still a static regression
    rec = SpindleThermalTwin().perturb(jr.key(10)).experiment(jr.key(11), duration=12 * HOURS)
    assert _regression_rms(rec) < 0.15
    for i, label in enumerate(THERMAL_TWIN_EFFECTS):
        eff = draw_thermal_effect(jr.key(i), label)
        assert list(eff) == [label]
        SpindleThermalTwin(eff)  # within the accepted physical range
    assert draw_thermal_effect(jr.key(0), None) == {}


def test_gradient_through_twin():
    """The twin is a differentiable function of its parameters (finite-difference oracle)."""
    speed = jnp.repeat(jnp.array([3000.0, 6000.0]), 4320)  # 12 h

    def f(g_cw):
        twin = eqx_tree_at(SpindleThermalTwin({"dynamics": 300.0}), g_cw)
        return jnp.mean(twin.simulate(jr.key(0), speed, 5.0, noise=0.0)["T_bearing"])

    g = jax.grad(f)(40.0)
    # h = 0.1: truncation (h² f'''/6) and the 1e-11 rounding of the 2^16-squaring expm
    # divided by 2h both stay below 1e-5 relative
    h = 0.1
    fd = (f(40.0 + h) - f(40.0 - h)) / (2 * h)
    assert float(g) == pytest.approx(float(fd), rel=1e-4)


def eqx_tree_at(twin, g_cw):
    return eqx.tree_at(lambda m: m.G_cw, twin, jnp.asarray(g_cw))


def test_bad_input():
    with pytest.raises(ValueError, match="unknown effect"):
        SpindleThermalTwin({"friction": 1.0})
    with pytest.raises(ValueError, match="outside its physical range"):
        SpindleThermalTwin({"speed_nonlinearity": 0.5})
    with pytest.raises(ValueError, match="must be positive"):
        SpindleThermalTwin(G_cw=-1.0)
    twin = SpindleThermalTwin()
    with pytest.raises(ValueError, match="part_duration needs parts"):
        twin.experiment(jr.key(0), part_duration=100.0)
    with pytest.raises(ValueError, match="at least one sample"):
        twin.experiment(jr.key(0), [1000.0, 2000.0], 1.0)
    with pytest.raises(ValueError, match="unknown effect"):
        draw_thermal_effect(jr.key(0), "backlash")
    rec = twin.experiment(jr.key(0), duration=12 * HOURS)
    with pytest.raises(ValueError, match="must exceed dt"):
        twin.sparse_target(rec, jr.key(1), every=2.0)
    assert isinstance(rec, jaxvs.data.Record)
