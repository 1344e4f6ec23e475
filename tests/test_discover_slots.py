"""Discovery's tmf slots on plants written here with scipy (a lightly damped mode between
encoder and tool, `scipy.signal.lfilter` of its zero-order-hold discretisation): a
transmission that stiffens with the motion (an additive output term in `x_e³`) and a
tool-side sensor clipped at ±2 mm (a static output nonlinearity)."""

import numpy as np
import pytest
import scipy.signal as ss

from jaxvs.data import Record
from jaxvs.diagnosis import Discovered, GapModel, discover
from jaxvs.diagnosis._tmf import TMFFamily

DT = 1e-3


def _tmf_plant(extra, n, seed, sigma=2e-8) -> Record:
    """A random-phase multisine (1–80 Hz, 1 mm rms, amplitude modulated over 3 s, from
    rest) through `ω² / (s² + 2ζωs + ω²)` at 40 Hz, ζ = 0.05; `extra(x_e, x_t)` is the
    unknown part of the tool-side motion; white noise `sigma`."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    k = np.arange(1, 80)
    xe = np.sum(np.cos(2 * np.pi * np.outer(t, k) + rng.uniform(0, 2 * np.pi, k.size)), 1)
    xe = 1e-3 * xe / np.std(xe) * (0.6 + 0.4 * np.sin(2 * np.pi * t / 3.0))
    xe = xe * np.clip(t / 0.2, 0, 1) ** 2
    om, z = 2 * np.pi * 40.0, 0.05
    b, a, _ = ss.cont2discrete(([om * om], [1, 2 * z * om, om * om]), DT, method="zoh")
    xt = ss.lfilter(np.ravel(b), a, xe)
    xt = xt + extra(xe, xt) + sigma * rng.standard_normal(n)
    return Record({"x_e": xe, "x_t": xt}, dt=DT)


def _discover_tmf(extra) -> Discovered:
    fam = TMFFamily(order=2)
    cal = [fam.prepare(_tmf_plant(extra, 3000, 0), "cal")]
    val = [fam.prepare(_tmf_plant(extra, 1500, 1), "val")]
    return discover(
        GapModel(fam.nominal(cal)), cal, val, family=fam, n_null=3, n_boot=50, n_stability=10
    )


@pytest.mark.slow
def test_a_stiffening_transmission_is_found_as_a_cubic_output_term():
    """`x_t = T x_e + 2·10⁻⁵ (x_e / 1 mm)³`: the additive output slot on the encoder
    position, the formula exactly `x_e³` with its coefficient within 5 %."""
    d = _discover_tmf(lambda xe, xt: 2e-5 * (xe / 1e-3) ** 3)
    assert d.fired and d.found, d.message
    assert d.slot == "additive term of the tool-side output"
    assert [tm["kind"] for tm in d.terms] == ["(x_e/xmax)^3"]
    (x_e,) = d.expression.free_symbols
    c = float(d.expression.subs(x_e, 1e-3))  # the term at x_e = 1 mm
    assert c == pytest.approx(2e-5, rel=0.05)


@pytest.mark.slow
def test_a_clipped_tool_sensor_is_found_as_a_static_output_nonlinearity():
    """The tool-side sensor saturates at ±2 mm: the static slot on the model's output,
    the formula `x̂ − clip(x̂, ±L)` with coefficient −1 and L = 2 mm within 5 %."""
    d = _discover_tmf(lambda xe, xt: np.clip(xt, -2e-3, 2e-3) - xt)
    assert d.fired and d.found, d.message
    assert d.slot == "static output nonlinearity"
    assert [tm["kind"] for tm in d.terms] == ["xhat-clip(xhat)"]
    assert d.terms[0]["coefficients"][0] == pytest.approx(-1.0, rel=0.05)
    assert d.terms[0]["shape"]["value"] == pytest.approx(2e-3, rel=0.05)
