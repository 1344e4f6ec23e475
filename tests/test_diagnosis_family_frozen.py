"""A diagnosis family is a frozen configuration: its attributes cannot be set, and what it
derives from data (the thermal regression's biases) travels in what it returns, so two
calls on different data give independent results."""

import jax
import numpy as np
import pytest

from jaxvs.data import Record
from jaxvs.diagnosis._base import GapModel
from jaxvs.diagnosis._families import FAMILIES
from jaxvs.diagnosis._thermal import ThermalFamily


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_a_family_cannot_be_changed_after_it_is_built(name):
    fam = FAMILIES[name]()
    with pytest.raises(AttributeError, match="frozen configuration"):
        fam.options = {}
    with pytest.raises(AttributeError, match="frozen configuration"):
        fam.derived = 1.0
    with pytest.raises(AttributeError, match="frozen configuration"):
        del fam.options
    with pytest.raises(TypeError):  # the options themselves are read-only
        fam.options["x"] = 1  # type: ignore[index]
    assert not hasattr(fam, "derived")


def _record(t_chassis_start, speed_floor, seed):
    # the study's regression exactly: T_b = 2 + 0.9·T_c + 2e-3·v_m, plus 0.05 K noise
    rng = np.random.default_rng(seed)
    t = np.arange(2000) * 5.0
    tc = t_chassis_start + 6.0 * (1.0 - np.exp(-t / 3000.0))
    v = speed_floor + 1000.0 * (np.arange(t.size) // 400 % 3)
    tb = 2.0 + 0.9 * tc + 2e-3 * v + 0.05 * rng.standard_normal(t.size)
    return Record({"T_chassis": tc, "T_bearing": tb, "v_m": v}, dt=5.0)


def test_thermal_nominal_on_new_data_leaves_the_earlier_result_alone():
    fam = ThermalFamily()
    exps_a = [fam.prepare(_record(20.0, 500.0, 0), "a")]
    exps_b = [fam.prepare(_record(24.0, 800.0, 1), "b")]
    first = fam.nominal(exps_a)
    second = fam.nominal(exps_b)
    p1 = fam.nominal_parameters(GapModel(first), exps_a)
    p2 = fam.nominal_parameters(GapModel(second), exps_b)
    # each result carries the biases (the inputs' minima) of its own data; 1e-6 K: the
    # zero-phase smoothing of the temperature inputs moves the start of the rise by ~1e-8 K
    assert p1["bias_chassis"] == pytest.approx(20.0, abs=1e-6) and p1["bias_speed"] == 500.0
    assert p2["bias_chassis"] == pytest.approx(24.0, abs=1e-6) and p2["bias_speed"] == 800.0
    # and reads the same as from a family that never saw the other data
    fresh = ThermalFamily()
    assert fresh.nominal_parameters(GapModel(fresh.nominal(exps_a)), exps_a) == p1
    # the study's coefficients, recovered on either record: 0.05 K noise over 2000 samples
    for p in (p1, p2):
        assert p["c_chassis"] == pytest.approx(0.9, abs=0.02)
        assert p["c_speed"] == pytest.approx(2e-3, abs=1e-4)
    # one model structure for both data sets: one compiled program
    assert jax.tree_util.tree_structure(first) == jax.tree_util.tree_structure(second)
