"""Round trips between jaxvs linear models / FRFs and scipy.signal / python-control.

Oracles: scipy's and python-control's own frequency-response evaluation of the converted
systems (independent code paths), and exact equality of the coefficients or matrices that
a round trip must preserve.
"""

import control
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as sig
from helpers import LINEAR_MODELS

import jaxvs
from jaxvs.data import FRFData

OMEGA = np.logspace(0, 4, 300)
# Tolerance: responses of order-8 systems evaluated by two different realisations /
# polynomial evaluations agree to ~1e-12 relative; 1e-8 leaves margin near sharp resonances.
RTOL = 1e-8


def jaxvs_response(model, omega=OMEGA):
    return np.asarray(jaxvs.frequency_response(model, jnp.asarray(omega)))


def response_of(system, omega=OMEGA):
    """(freq, out, in) response of a scipy or control system at `omega` [rad/s]."""
    if isinstance(system, sig.lti):
        ss = system.to_ss()
        s = 1j * omega
        n = ss.A.shape[0]
        X = np.linalg.solve(
            s[:, None, None] * np.eye(n) - ss.A, np.broadcast_to(ss.B, (len(s),) + ss.B.shape)
        )
        return np.einsum("on,fni->foi", ss.C, X) + ss.D
    r = np.asarray(system(1j * omega, squeeze=False))  # (out, in, freq)
    return np.moveaxis(r, -1, 0)


def _assert_same_response(system_or_model, ref):
    g = (
        jaxvs_response(system_or_model)
        if isinstance(system_or_model, jaxvs.AbstractLinearModel)
        else response_of(system_or_model)
    )
    np.testing.assert_allclose(
        np.asarray(g).reshape(ref.shape), ref, rtol=RTOL, atol=RTOL * np.abs(ref).max()
    )


SCIPY_TYPES = {"ss": sig.StateSpace, "tf": sig.TransferFunction, "zpk": sig.ZerosPolesGain}


@pytest.mark.parametrize("name, factory", LINEAR_MODELS)
def test_round_trips(name, factory):
    """Every form of both libraries: the converted system (oracle: the library's own
    evaluation) and the model converted back have the model's frequency response."""
    model = factory(np.random.default_rng(0))
    ref = jaxvs_response(model)
    auto = "tf" if isinstance(model, jaxvs.RationalTF) else "ss"
    for form in ("auto", "ss", "tf", "zpk"):
        system = jaxvs.to_scipy(model, form=form)
        assert isinstance(system, SCIPY_TYPES[auto if form == "auto" else form])
        _assert_same_response(system, ref)
        _assert_same_response(jaxvs.from_scipy(system), ref)
    for form, kind in (("auto", auto), ("ss", "ss"), ("tf", "tf")):
        system = jaxvs.to_control(model, form=form)
        expected = control.StateSpace if kind == "ss" else control.TransferFunction
        assert isinstance(system, expected)
        _assert_same_response(system, ref)
        _assert_same_response(jaxvs.from_control(system), ref)


def test_rational_coefficients_round_trip_exactly():
    tf = jaxvs.RationalTF(jnp.array([0.5, 3.0, 7.0]), jnp.array([2.0, 1.0, 40.0]))
    for back in (
        jaxvs.from_scipy(jaxvs.to_scipy(tf)),
        jaxvs.from_control(jaxvs.to_control(tf)),
    ):
        assert isinstance(back, jaxvs.RationalTF)
        # scipy normalises den[0] = 1, python-control keeps it: compare num/den ratios.
        np.testing.assert_allclose(back.num / back.den[0], tf.num / tf.den[0], rtol=1e-15)
        np.testing.assert_allclose(back.den / back.den[0], tf.den / tf.den[0], rtol=1e-15)
    back = jaxvs.from_control(jaxvs.to_control(tf))
    np.testing.assert_array_equal(back.num, tf.num)  # python-control stores them as given
    np.testing.assert_array_equal(back.den, tf.den)


def test_statespace_matrices_round_trip_exactly():
    rng = np.random.default_rng(2)
    A, B = rng.normal(size=(4, 4)) - 3 * np.eye(4), rng.normal(size=(4, 2))
    C, D = rng.normal(size=(3, 4)), rng.normal(size=(3, 2))
    ss = jaxvs.StateSpace(A, B, C, D)
    for back in (jaxvs.from_scipy(jaxvs.to_scipy(ss)), jaxvs.from_control(jaxvs.to_control(ss))):
        assert isinstance(back, jaxvs.StateSpace)
        for x, y in zip((back.A, back.B, back.C, back.D), (A, B, C, D)):
            np.testing.assert_array_equal(np.asarray(x), y)


def test_from_scipy_of_externally_built_systems():
    # Oracle: scipy's own bode() of the same system.
    w = np.logspace(-1, 2, 50)
    for system in (
        sig.lti([1.0, 3.0], [1.0, 2.0, 10.0]),  # TransferFunction
        sig.lti([-3.0], [-1.0 + 3j, -1.0 - 3j], 1.0),  # ZerosPolesGain
        sig.ZerosPolesGain([], [-2.0, -5.0], 10.0),
    ):
        model = jaxvs.from_scipy(system)
        assert isinstance(model, jaxvs.RationalTF)
        _, H = system.freqresp(w)
        np.testing.assert_allclose(jaxvs_response(model, w).reshape(H.shape), H, rtol=1e-12)


def test_simo_transfer_function_becomes_statespace():
    system = sig.TransferFunction([[1.0, 2.0], [0.0, 3.0]], [1.0, 4.0, 5.0])
    model = jaxvs.from_scipy(system)
    assert isinstance(model, jaxvs.StateSpace) and model.n_outputs == 2
    np.testing.assert_allclose(
        jaxvs_response(model)[:, :, 0], response_of(system)[:, :, 0], rtol=1e-10
    )


def test_family_converts_to_list_of_members():
    w = jnp.array([[10.0, 50.0], [12.0, 55.0], [14.0, 60.0]])
    family = jaxvs.ModalModel(w, jnp.full((3, 2), 0.05), jnp.ones((3, 2)))
    systems = jaxvs.to_control(family)
    assert isinstance(systems, list) and len(systems) == 3
    ref = jaxvs_response(family)  # (3, freq)
    for i, system in enumerate(systems):
        np.testing.assert_allclose(response_of(system)[:, 0, 0], ref[i], rtol=RTOL)
    back = jaxvs.from_scipy(jaxvs.to_scipy(family))
    assert len(back) == 3
    np.testing.assert_allclose(jaxvs_response(back[2]), ref[2], rtol=RTOL)
    # two batch axes: nested lists
    fam2 = jaxvs.RationalTF(jnp.ones((2, 3, 1)), jnp.tile(jnp.array([1.0, 2.0, 5.0]), (2, 3, 1)))
    nested = jaxvs.to_scipy(fam2)
    assert len(nested) == 2 and len(nested[0]) == 3


# ----------------------------------------------------------------------------- FRF / FRD


def _pyuff_frf(shared_data):
    files = [shared_data / "pyuff_frf" / f"meas_point_{k}.txt" for k in (1, 2, 3)]
    H = np.stack([np.loadtxt(f, dtype=complex) for f in files], axis=0)  # (3, 1001)
    return np.arange(H.shape[1], dtype=float), H


def test_measured_frf_round_trip_through_control_frd(shared_data):
    f, H = _pyuff_frf(shared_data)
    frf = FRFData(f, H[0], kind="accelerance", input_unit="N", output_unit="m/s^2")
    frd = jaxvs.to_control(frf)
    assert isinstance(frd, control.FrequencyResponseData)
    np.testing.assert_allclose(frd.omega, 2 * np.pi * f, rtol=1e-15)
    # oracle: control's own evaluation at its frequency points returns the measured values
    np.testing.assert_array_equal(np.asarray(frd(2j * np.pi * f[5:8], squeeze=True)), H[0, 5:8])
    back = jaxvs.from_control(frd, kind="accelerance", input_unit="N", output_unit="m/s^2")
    np.testing.assert_array_equal(np.asarray(back.H), H[0])
    np.testing.assert_allclose(np.asarray(back.frequency), f, rtol=1e-15, atol=1e-300)
    assert (back.kind, back.input_unit, back.output_unit) == ("accelerance", "N", "m/s^2")
    # a family of three measured FRFs -> three FRDs
    fam = FRFData(f, H)
    frds = jaxvs.to_control(fam)
    assert len(frds) == 3
    np.testing.assert_array_equal(np.asarray(jaxvs.from_control(frds[2]).H), H[2])


def test_mimo_frf_round_trip():
    f = np.linspace(1.0, 100.0, 64)
    rng = np.random.default_rng(3)
    H = rng.normal(size=(64, 2, 3)) + 1j * rng.normal(size=(64, 2, 3))
    frd = jaxvs.to_control(FRFData(f, H))
    assert (frd.noutputs, frd.ninputs) == (2, 3)
    back = jaxvs.from_control(frd)
    assert back.io_shape == (2, 3)
    np.testing.assert_array_equal(np.asarray(back.H), H)


def test_model_frd_from_control_matches_jaxvs_response():
    model = jaxvs.ModalModel(
        jnp.array([30.0, 200.0]), jnp.array([0.02, 0.05]), jnp.array([1.0, -2.0])
    )
    w = np.linspace(1.0, 400.0, 200)
    frd = control.frd(jaxvs.to_control(model), w)
    frf = jaxvs.from_control(frd)
    np.testing.assert_allclose(np.asarray(frf.omega), w, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(frf.H), jaxvs_response(model, w).reshape(-1), rtol=RTOL)


# ----------------------------------------------------------------------------- bad input


def test_discrete_time_systems_are_rejected():
    with pytest.raises(TypeError, match="continuous-time"):
        jaxvs.from_scipy(sig.dlti([1.0], [1.0, -0.5], dt=0.1))
    with pytest.raises(TypeError, match="continuous-time"):
        jaxvs.from_control(control.tf([1.0], [1.0, -0.5], 0.1))


def test_tf_form_of_mimo_model_is_rejected():
    ss = jaxvs.StateSpace(-np.eye(2), np.eye(2), np.eye(2), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="SISO"):
        jaxvs.to_scipy(ss, form="tf")
    with pytest.raises(ValueError, match="SISO"):
        jaxvs.to_control(ss, form="tf")
    with pytest.raises(ValueError, match="form must be one of"):
        jaxvs.to_scipy(ss, form="frd")


def test_improper_and_static_systems_are_rejected():
    with pytest.raises(ValueError, match="improper"):
        jaxvs.from_scipy(sig.ZerosPolesGain([-1.0, -2.0], [-3.0], 1.0))
    with pytest.raises(ValueError, match="static gain"):
        jaxvs.from_control(control.tf([2.0], [1.0]))


def test_wrong_objects_are_rejected():
    with pytest.raises(TypeError, match="jaxvs linear model"):
        jaxvs.to_scipy(np.ones(3))
    with pytest.raises(TypeError, match="scipy.signal"):
        jaxvs.from_scipy(control.tf([1.0], [1.0, 1.0]))
    with pytest.raises(TypeError, match="python-control"):
        jaxvs.from_control(sig.lti([1.0], [1.0, 1.0]))


def test_conversion_under_jit_is_rejected():
    tf = jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 2.0]))
    with pytest.raises(TypeError, match="outside jax.jit"):
        jax.jit(lambda m: jaxvs.to_scipy(m) and 0.0)(tf)
