"""Conversions, analysis (poles, zeros, gain, damping) and position ↔ acceleration.

Oracles: python-control (`tf`, `ss`, `poles`, `zeros`, `dcgain`, `damp`), scipy.signal
(`tf2zpk`, `freqs`, `ss2tf`, `invres`, `tf2ss`, `cont2discrete`) and closed forms.
"""

import control
import equinox as eqx
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as sig
from helpers import LINEAR_MODELS, random_modal
from hypothesis import given, settings
from jax.test_util import check_grads

import jaxvs
from jaxvs.models import (
    acceleration_to_position,
    acceleration_to_position_frf,
    damping,
    is_stable,
    poles,
    position_to_acceleration,
    position_to_acceleration_frf,
    static_gain,
    to_modal,
    to_rational,
    zeros,
)

W = np.logspace(0, 4, 200)


_frequency_response = eqx.filter_jit(jaxvs.frequency_response)  # one compile per structure


def frf(model, w=W):
    return np.asarray(_frequency_response(model, jnp.asarray(w)))


def rel_err(h, ref):
    """Largest error relative to the largest magnitude of the reference."""
    return float(np.max(np.abs(np.asarray(h) - ref)) / np.max(np.abs(ref)))


def spread_modal(rng, n_modes, *, lo=10.0, hi=1000.0, zeta=(0.005, 0.05)):
    """Lightly damped modes spread over two decades [Hz] (the hard case for coefficients)."""
    f = np.geomspace(lo, hi, n_modes) * np.exp(rng.uniform(-0.1, 0.1, n_modes))
    wn = 2 * np.pi * f
    z = rng.uniform(*zeta, n_modes)
    r = rng.normal(size=n_modes) * wn**2
    return jaxvs.ModalModel(jnp.asarray(wn), jnp.asarray(z), jnp.asarray(r))


def exact_poles_residues(m):
    """Upper poles and pole residues of a real-residue ModalModel, in numpy (closed form)."""
    wn, z, r = (np.asarray(x) for x in (m.omega_n, m.zeta, m.residues))
    lam = wn * (-z + 1j * np.sqrt(1 - z**2))
    # r / ((s - λ)(s - λ̄)): residue at λ is r / (λ - λ̄)
    return lam, r / (lam - np.conj(lam))


def control_tf(model):
    r = to_rational(model)
    return control.tf(np.asarray(r.num), np.asarray(r.den))


def control_ss(model):
    ss = model.to_state_space()
    return control.ss(*(np.asarray(x) for x in (ss.A, ss.B, ss.C, ss.D)))


def sorted_c(x):
    x = np.asarray(x)
    return x[np.lexsort((-x.imag, np.abs(x)))]


# ---------------------------------------------------------------------------------------
# Round trips
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name,factory", LINEAR_MODELS)
def test_round_trips_registry(name, factory):
    model = factory(np.random.default_rng(11))
    g = frf(model)
    r = to_rational(model)
    assert isinstance(r, jaxvs.RationalTF) and r.order == model.order
    # order <= 8, well separated modes: exact conversions, only rounding separates them.
    assert rel_err(frf(r), g) < 1e-10
    assert rel_err(frf(r.to_state_space()), g) < 1e-10
    if model.order % 2:
        with pytest.raises(ValueError, match="odd order"):
            to_modal(model)
        return
    mm = to_modal(model)
    assert isinstance(mm, jaxvs.ModalModel) and mm.n_modes == model.order // 2
    assert np.all(np.diff(np.asarray(mm.omega_n)) >= 0)  # documented: sorted by ω_n
    assert rel_err(frf(mm), g) < 1e-10  # same reason
    # and back through every form
    assert rel_err(frf(to_rational(to_modal(r.to_state_space()))), g) < 1e-10
    # scipy.signal.freqs is an independent evaluation of the rational coefficients
    _, h = sig.freqs(np.asarray(r.num), np.asarray(r.den), W)
    assert rel_err(h, g) < 1e-9  # freqs evaluates unscaled polynomials: a few more digits lost


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("n_modes", [4, 6])
def test_to_rational_matches_invres_at_high_order(seed, n_modes):
    m = spread_modal(np.random.default_rng(seed), n_modes)
    lam, res = exact_poles_residues(m)
    p = np.concatenate([lam, np.conj(lam)])
    rr = np.concatenate([res, np.conj(res)])
    num_ref, den_ref = sig.invres(rr, p, [])
    r = to_rational(m)
    num, den = np.asarray(r.num), np.asarray(r.den)
    n = r.order
    # Compare in scaled frequency s/ω0, where all coefficients are O(1)-comparable; the
    # oracle (invres: products of (s - p) in unscaled complex arithmetic) carries ~1e-13
    # relative rounding at order 12, ours less; 1e-10 leaves room for both.
    w0 = np.prod(np.abs(p)) ** (1 / n)
    sc = w0 ** -np.arange(n + 1)
    den_ref = np.real(den_ref / den_ref[0])
    num_ref = np.concatenate([np.zeros(n + 1 - len(num_ref)), np.real(num_ref)])
    np.testing.assert_allclose(
        den * sc, den_ref * sc, rtol=0, atol=1e-10 * np.max(np.abs(den * sc))
    )
    np.testing.assert_allclose(
        num * sc, num_ref * sc, rtol=0, atol=1e-10 * np.max(np.abs(num * sc))
    )
    # scipy.signal.ss2tf of the dense modal state space: a second oracle (poly(A) for den,
    # poly(A - BC) - poly(A) for num, which cancels digits: 1e-9 in scaled frequency)
    ss = m.to_state_space()
    num2, den2 = sig.ss2tf(*(np.asarray(x) for x in (ss.A, ss.B, ss.C, ss.D)))
    np.testing.assert_allclose(den * sc, den2 * sc, rtol=0, atol=1e-9 * np.max(np.abs(den * sc)))
    np.testing.assert_allclose(num * sc, num2[0] * sc, rtol=0, atol=1e-9 * np.max(np.abs(num * sc)))
    # Response of the coefficients against the exact modal response, point by point
    # (relative to |G| at each frequency, anti-resonances included). Measured: 2e-14..5e-14
    # for ours, 1e-13..6e-13 for the ss2tf coefficients.
    w = np.geomspace(2 * np.pi * 3, 2 * np.pi * 3000, 1000)
    g = frf(m, w)
    assert np.max(np.abs(frf(r, w) - g) / np.abs(g)) < 1e-11
    g2 = frf(jaxvs.RationalTF(jnp.asarray(num2[0]), jnp.asarray(den2)), w)
    assert np.max(np.abs(g2 - g) / np.abs(g)) < 1e-9  # the oracle's own accuracy


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("n_modes", [5, 6])
def test_block_realisation_keeps_digits_where_companion_loses_them(seed, n_modes):
    """Order 10-12: ZOH impulse responses of two realisations of the same coefficients.

    Exact reference: the modal model's own block-diagonal state space. Ours: the
    `RationalTF`'s block-modal realisation (roots in scaled frequency). Companion:
    `scipy.signal.tf2ss`. Both discretised by `scipy.signal.cont2discrete` (expm).
    Measured: ours 1e-14..1e-13, companion 3e-6..1e-2.
    """
    m = spread_modal(np.random.default_rng(seed), n_modes)
    r = to_rational(m)
    dt = 1e-4

    def impulse(A, B, C, D):
        Ad, Bd, Cd, _, _ = sig.cont2discrete((A, B, C, D), dt, "zoh")
        x, out = Bd[:, 0].copy(), []
        for _ in range(2000):
            out.append(Cd[0] @ x)
            x = Ad @ x
        return np.asarray(out)

    def dense(ss):
        return tuple(np.asarray(v) for v in (ss.A, ss.B, ss.C, ss.D))

    y_ref = impulse(*dense(m.to_state_space()))
    y_ours = impulse(*dense(r.to_state_space()))
    # strip the structural leading zeros (relative degree 2) so tf2ss gets a clean numerator
    y_comp = impulse(*sig.tf2ss(np.asarray(r.num)[2:], np.asarray(r.den)))
    e_ours = np.linalg.norm(y_ours - y_ref) / np.linalg.norm(y_ref)
    e_comp = np.linalg.norm(y_comp - y_ref) / np.linalg.norm(y_ref)
    assert e_ours < 1e-10  # rounding of the coefficients and roots only
    assert e_comp > 100 * e_ours  # the companion route loses (many) more digits


def test_mimo_state_space_to_modal():
    rng = np.random.default_rng(4)
    m = random_modal(rng, 3)
    ss = m.to_state_space()
    B = np.concatenate([np.asarray(ss.B), rng.normal(size=(6, 1))], axis=1)
    C = np.concatenate([np.asarray(ss.C), rng.normal(size=(2, 6))], axis=0)
    mimo = jaxvs.StateSpace(ss.A, B, C, rng.normal(size=(3, 2)))
    mm = to_modal(mimo)
    assert mm.residues.shape == (3, 3, 2)
    assert rel_err(frf(mm), frf(mimo)) < 1e-10  # exact conversion, rounding only
    simo = jaxvs.StateSpace(ss.A, ss.B, C, np.zeros((3, 1)))
    assert to_modal(simo).residues.shape == (3, 3)
    with pytest.raises(ValueError, match="single-input single-output"):
        to_rational(mimo)
    # The dense realisation of a MIMO ModalModel repeats every pole pair once per input
    # (bitwise-equal eigenvalues): the block realisation must still pair λ with λ̄.
    mimo_modal = jaxvs.ModalModel(
        jnp.array([10.0, 30.0]), jnp.array([0.1, 0.2]), jnp.arange(1, 9.0).reshape(2, 2, 2)
    )
    dense = mimo_modal.to_state_space()
    assert rel_err(frf(to_modal(dense)), frf(mimo_modal)) < 1e-12  # rounding only
    r = dense.modal_realisation()
    g_blocks = np.asarray(r.response(jnp.asarray(1j * W)))
    assert rel_err(g_blocks, frf(mimo_modal)) < 1e-12


def test_to_modal_residue_kinds():
    rng = np.random.default_rng(5)
    m = random_modal(rng, 3)
    mc = to_modal(m)  # real modal constants → complex residues (closed form)
    assert jnp.iscomplexobj(mc.residues)
    assert rel_err(frf(mc), frf(m)) < 1e-12
    mr = to_modal(mc, residues="real")
    # complex → real is exact when a_k = 2 Re R_k = 0: recovers the modal constants.
    np.testing.assert_allclose(np.asarray(mr.residues), np.asarray(m.residues), rtol=1e-12)
    # from a dense state space (eigenvectors): exact up to rounding of the eigensolver
    mr2 = to_modal(m.to_state_space(), residues="real")
    np.testing.assert_allclose(np.asarray(mr2.residues), np.asarray(m.residues), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(mr2.omega_n), np.asarray(m.omega_n), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(mr2.zeta), np.asarray(m.zeta), rtol=1e-10)


def test_over_damped_mode_as_real_modal_constant():
    m = jaxvs.ModalModel(jnp.array([50.0, 300.0]), jnp.array([0.05, 1.5]), jnp.array([2e3, 5e4]))
    ss = m.to_state_space()
    mr = to_modal(ss, residues="real")
    np.testing.assert_allclose(np.asarray(mr.zeta), [0.05, 1.5], rtol=1e-10)
    assert rel_err(frf(mr), frf(m)) < 1e-10  # exact representation, rounding only
    with pytest.raises(Exception, match="real poles"):
        to_modal(ss)
    with pytest.raises(Exception, match="over-damped"):
        to_modal(m)  # the ModalModel route: its own modes, ζ = 1.5 has no complex residue


# ---------------------------------------------------------------------------------------
# Analysis against python-control
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name,factory", LINEAR_MODELS)
def test_poles_gain_damping_vs_control(name, factory):
    model = factory(np.random.default_rng(3))
    sys_ss = control_ss(model)
    p = np.asarray(poles(model))
    p_ref = sorted_c(control.poles(sys_ss))
    # poles of the realisation vs python-control's eig of the dense A: both backward stable,
    # separated poles → agreement to ~1e-13 relative.
    if isinstance(model, jaxvs.ModalModel) and model.n_inputs > 1:
        pytest.skip("MIMO modal poles are listed once per mode")
    np.testing.assert_allclose(p, p_ref, rtol=1e-10)
    wn, z = damping(model)
    wn_ref, z_ref, _ = control.damp(sys_ss, doprint=False)
    np.testing.assert_allclose(np.asarray(wn), np.sort(wn_ref), rtol=1e-10)
    np.testing.assert_allclose(np.sort(np.asarray(z)), np.sort(z_ref), rtol=1e-9, atol=1e-12)
    # static gain: closed forms vs dcgain of the dense state space (solve(A, B)); 1e-10
    # leaves room for the conditioning of A.
    np.testing.assert_allclose(float(static_gain(model)), control.dcgain(sys_ss), rtol=1e-10)
    assert bool(is_stable(model))


@pytest.mark.parametrize("name,factory", [x for x in LINEAR_MODELS])
def test_zeros_vs_control_and_scipy(name, factory):
    model = factory(np.random.default_rng(3))
    z = np.asarray(zeros(model))
    finite = z[np.isfinite(z)]
    r = to_rational(model)
    num = np.asarray(r.num)
    den = np.asarray(r.den)
    # leading coefficients that vanish in scaled frequency s/ω0 (up to rounding of the
    # block products) are zeros at infinity, as documented; strip them for the oracles.
    w0 = np.abs(den[-1] / den[0]) ** (1 / (len(den) - 1))
    scaled = np.abs(num) * w0 ** np.arange(len(num) - 1, -1, -1)
    n_lead = int(np.argmax(scaled > 100 * np.finfo(float).eps * scaled.max()))
    num = num[n_lead:]
    z_scipy, _, _ = sig.tf2zpk(num, den)
    z_ctrl = control.zeros(control.tf(num, den))
    assert len(finite) == len(z_scipy) == len(z_ctrl)
    assert len(z) == r.num.shape[-1] - 1
    assert np.sum(~np.isinf(z)) == len(finite) and np.sum(np.isinf(z)) == n_lead  # zeros at ∞
    # zeros are roots of the numerator; scaled-frequency roots vs unscaled np.roots:
    # agreement to 1e-8 relative (zeros of order-8 numerators are less well conditioned
    # than poles: some are real pairs near each other).
    np.testing.assert_allclose(sorted_c(finite), sorted_c(z_scipy), rtol=1e-8)
    np.testing.assert_allclose(sorted_c(finite), sorted_c(z_ctrl), rtol=1e-8)


def test_analysis_closed_forms_and_edge_cases():
    # pole at 0: dcgain-like inf, and ζ = -1 for the pole at 0 as MATLAB damp
    integ = jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 3.0, 0.0]))
    assert np.isinf(float(static_gain(integ)))
    assert np.isinf(control.dcgain(control.tf([1.0], [1.0, 3.0, 0.0])))
    wn, z = damping(integ)
    np.testing.assert_allclose(np.asarray(wn), [0.0, 3.0], atol=1e-14)
    np.testing.assert_allclose(np.asarray(z), [-1.0, 1.0], atol=1e-14)
    assert not bool(is_stable(integ))
    ss_int = jaxvs.StateSpace(
        jnp.zeros((1, 1)), jnp.ones((1, 1)), jnp.ones((1, 1)), jnp.zeros((1, 1))
    )
    assert not np.isfinite(float(static_gain(ss_int)))
    # unstable and marginally stable
    assert not bool(is_stable(jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, -1.0, 4.0]))))
    assert not bool(
        is_stable(jaxvs.ModalModel(jnp.array([10.0]), jnp.array([0.0]), jnp.array([1.0])))
    )
    # ModalModel poles: closed form including over- and critically damped modes
    m = jaxvs.ModalModel(jnp.array([10.0, 20.0, 40.0]), jnp.array([0.1, 1.0, 2.0]), jnp.ones(3))
    p_ref = np.concatenate(
        [np.roots([1.0, 2 * zz * ww, ww**2]) for ww, zz in [(10, 0.1), (20, 1.0), (40, 2.0)]]
    )
    np.testing.assert_allclose(
        np.asarray(poles(m)), sorted_c(p_ref), rtol=1e-7
    )  # double root at -20: sqrt(eps)
    # static gain of a MIMO model: (out, in) like dcgain
    mimo = jaxvs.ModalModel(
        jnp.array([10.0, 30.0]), jnp.array([0.1, 0.2]), jnp.arange(8.0).reshape(2, 2, 2)
    )
    g0 = np.asarray(static_gain(mimo))
    np.testing.assert_allclose(
        g0, np.asarray(mimo.residues)[0] / 100 + np.asarray(mimo.residues)[1] / 900, rtol=1e-14
    )
    np.testing.assert_allclose(g0, control.dcgain(control_ss(mimo)), rtol=1e-10)
    # zeros at infinity of a strictly proper rational, and a zero at the origin
    z = np.asarray(zeros(jaxvs.RationalTF(jnp.array([0.0, 2.0, 0.0]), jnp.array([1.0, 3.0, 2.0]))))
    assert z[0] == 0 and np.isinf(z[1])


def test_analysis_on_families():
    rng = np.random.default_rng(7)
    members = [random_modal(rng, 3) for _ in range(4)]
    fam = jaxvs.ModalModel(
        *(jnp.stack([getattr(m, k) for m in members]) for k in ("omega_n", "zeta", "residues"))
    )
    for fn in (
        poles,
        zeros,
        static_gain,
        is_stable,
        lambda m: damping(m)[1],
        lambda m: to_rational(m).num,
    ):
        out = np.asarray(fn(fam))
        for i, m in enumerate(members):
            np.testing.assert_allclose(out[i], np.asarray(fn(m)), rtol=1e-12)  # same arithmetic
    ss_fam = fam.to_state_space()
    np.testing.assert_allclose(np.asarray(poles(ss_fam)), np.asarray(poles(fam)), rtol=1e-10)
    mm = eqx.filter_jit(to_modal)(ss_fam)
    assert mm.batch_shape == (4,)
    assert rel_err(frf(mm), frf(fam)) < 1e-10  # exact conversion, rounding only
    rf = eqx.filter_jit(to_rational)(ss_fam)
    assert rel_err(frf(rf), frf(fam)) < 1e-10


# ---------------------------------------------------------------------------------------
# Hypothesis properties over random stable systems
# ---------------------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_modes=st.sampled_from([1, 3, 5]))
def test_property_conversions_agree(seed, n_modes):
    rng = np.random.default_rng(seed)
    m = random_modal(rng, n_modes)
    g = frf(m)
    r = to_rational(m)
    # round trips through the rational and the dense forms: exact up to rounding of the
    # polynomial roots (random modes may be close; 1e-8 covers the conditioning).
    assert rel_err(frf(r), g) < 1e-8
    assert rel_err(frf(to_modal(r)), g) < 1e-8
    np.testing.assert_allclose(np.asarray(poles(r)), np.asarray(poles(m)), rtol=1e-6)
    np.testing.assert_allclose(float(static_gain(r)), float(static_gain(m)), rtol=1e-8)
    np.testing.assert_allclose(
        float(static_gain(m)), np.real(frf(m, np.array([0.0]))[0]), rtol=1e-12
    )
    wn, z = damping(m)
    np.testing.assert_allclose(np.asarray(wn)[::2], np.sort(np.asarray(m.omega_n)), rtol=1e-12)
    assert bool(is_stable(r)) and bool(is_stable(m))


# ---------------------------------------------------------------------------------------
# Position ↔ acceleration (study eq. 6)
# ---------------------------------------------------------------------------------------


def test_position_acceleration_models():
    rng = np.random.default_rng(8)
    m = random_modal(rng, 3)  # a receptance: real modal constants, relative degree 2
    s = 1j * W
    g = frf(m)
    for model in (
        m,
        m.to_state_space(),
        jaxvs.RationalTF(to_rational(m).num[2:], to_rational(m).den),
    ):
        acc = position_to_acceleration(model)
        assert type(acc) is type(model)
        assert rel_err(frf(acc), s**2 * g) < 1e-10  # exact algebra, rounding only
        back = acceleration_to_position(acc)
        # G_acc / s² cancels two O(1) terms at low frequency: rounding grows like
        # (ω_n,max / ω)² ≈ (3e3 / 1)² ≈ 1e7 times eps, hence 1e-8.
        assert rel_err(frf(back), g) < 1e-8
        if not isinstance(model, jaxvs.ModalModel):
            # divide by s²: two integrators (a ModalModel receptance has G(0) != 0: error,
            # tested in test_bad_inputs)
            assert rel_err(frf(acceleration_to_position(model)), g / s**2) < 1e-10
    # the ModalModel accelerance is a ModalModel with complex residues and feedthrough Σ r_k
    acc = position_to_acceleration(m)
    assert jnp.iscomplexobj(acc.residues)
    np.testing.assert_allclose(float(acc.feedthrough), float(jnp.sum(m.residues)), rtol=1e-14)


def test_tmf_of_accelerations_equals_tmf_of_positions():
    """Study eq. 6: T = x_a / x_b = (a_a / s²) / (a_b / s²) = a_a / a_b."""
    rng = np.random.default_rng(9)
    wn = 2 * np.pi * np.array([40.0, 110.0, 260.0])
    phi = rng.normal(size=(3, 3))  # mode shapes at points (a, b, c)
    # receptances H_ac and H_bc from modal constants φ_a φ_c and φ_b φ_c
    res = np.stack([phi[:, 0] * phi[:, 2], phi[:, 1] * phi[:, 2]], axis=1)
    H = jaxvs.ModalModel(jnp.asarray(wn), jnp.full(3, 0.03), jnp.asarray(res))  # 2 outputs
    w = np.linspace(2 * np.pi * 5, 2 * np.pi * 500, 400)
    Hx = np.asarray(jaxvs.frequency_response(H, w))[:, :, 0]
    Ha = np.asarray(jaxvs.frequency_response(position_to_acceleration(H), w))[:, :, 0]
    T_pos = Hx[:, 0] / Hx[:, 1]
    T_acc = Ha[:, 0] / Ha[:, 1]
    # the same ratio computed from two different models: rounding only (1e-9 relative
    # covers the anti-resonances of the denominator FRF)
    np.testing.assert_allclose(T_acc, T_pos, rtol=1e-9)
    # and with measured-style FRF arrays: differentiate both FRFs, the ratio is unchanged
    Aa = np.asarray(position_to_acceleration_frf(Hx, w, axis=0))
    np.testing.assert_allclose(Aa[:, 0] / Aa[:, 1], T_pos, rtol=1e-13)
    np.testing.assert_allclose(Aa, Ha, rtol=1e-9)
    # integrating the accelerations back gives the receptances
    np.testing.assert_allclose(
        np.asarray(acceleration_to_position_frf(Aa, w, axis=0)), Hx, rtol=1e-14
    )


def test_frf_conversions_closed_form_and_batches():
    w = np.array([1.0, 2.0, 4.0])
    H = np.arange(12.0).reshape(2, 3, 2) + 1j
    out = np.asarray(acceleration_to_position_frf(H, w, axis=1))
    np.testing.assert_allclose(out, H / (1j * w[None, :, None]) ** 2, rtol=1e-15)
    out = np.asarray(position_to_acceleration_frf(H[..., 0], w))
    np.testing.assert_allclose(out, H[..., 0] * (1j * w) ** 2, rtol=1e-15)
    # jit: the ω = 0 check becomes a runtime check
    f = eqx.filter_jit(acceleration_to_position_frf)
    np.testing.assert_allclose(np.asarray(f(H[..., 0], w)), H[..., 0] / -(w**2), rtol=1e-15)
    with pytest.raises(Exception, match="0 rad/s"):
        f(H[..., 0], np.array([0.0, 1.0, 2.0]))


# ---------------------------------------------------------------------------------------
# Gradients vs central finite differences
# ---------------------------------------------------------------------------------------


def _relative_check(fn, params):
    """check_grads on multiplicative perturbations θ: params (1 + θ), θ = 0.

    Parameters span 1e-2..1e6, so a relative step (1e-6) is the right finite difference;
    central differences have error O(h²) ≈ 1e-12 relative, rounding ≈ eps / h ≈ 1e-10:
    tolerances 1e-6 leave a wide margin without hiding a wrong gradient (those are O(1)).
    """
    leaves, tree = jax.tree_util.tree_flatten(params)

    def f(thetas):
        scaled = [x * (1 + t) for x, t in zip(leaves, thetas)]
        out = fn(jax.tree_util.tree_unflatten(tree, scaled))
        return (
            jnp.concatenate([out.real.ravel(), out.imag.ravel()]) if jnp.iscomplexobj(out) else out
        )

    thetas = [jnp.zeros_like(x, dtype=jnp.result_type(x.real.dtype)) for x in leaves]
    check_grads(
        jax.jit(f), (thetas,), order=1, modes=("fwd", "rev"), eps=1e-6, atol=1e-6, rtol=1e-6
    )


@pytest.mark.parametrize("name,factory", LINEAR_MODELS)
def test_gradients_of_frequency_response(name, factory):
    model = factory(np.random.default_rng(12))
    w = jnp.logspace(0.5, 3.5, 25)
    scale = np.max(np.abs(frf(model, np.asarray(w))))
    arrays, static = eqx.partition(model, eqx.is_inexact_array)

    def fn(p):
        return jaxvs.frequency_response(eqx.combine(p, static), w) / scale

    _relative_check(fn, arrays)


@pytest.mark.slow  # ~15 s of compilation (derivatives of eig and roots, both modes)
def test_gradients_through_conversions_and_analysis():
    rng = np.random.default_rng(13)
    m = random_modal(rng, 3)
    w = jnp.logspace(0.5, 3.5, 20)
    scale = np.max(np.abs(frf(m, np.asarray(w))))
    arrays, static = eqx.partition(m, eqx.is_inexact_array)

    def via_rational(p):
        return jaxvs.frequency_response(to_rational(eqx.combine(p, static)), w) / scale

    def via_modal_complex(p):
        return (
            jaxvs.frequency_response(to_modal(eqx.combine(p, static).to_state_space()), w) / scale
        )

    def pole_values(p):
        return poles(to_rational(eqx.combine(p, static))) / 1e3

    def gain(p):
        return static_gain(eqx.combine(p, static).to_state_space())[None]

    def all_outputs(p):  # one function, so the derivatives compile once
        parts = (via_rational(p), via_modal_complex(p), pole_values(p), gain(p))
        return jnp.concatenate([jnp.ravel(x).astype(complex) for x in parts])

    _relative_check(all_outputs, arrays)


# ---------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------


def test_bad_inputs():
    rng = np.random.default_rng(14)
    m = random_modal(rng, 2)
    for fn in (
        to_rational,
        to_modal,
        poles,
        zeros,
        static_gain,
        is_stable,
        damping,
        acceleration_to_position,
        position_to_acceleration,
    ):
        with pytest.raises(TypeError, match="expected a jaxvs linear model"):
            fn(np.ones(3))
    with pytest.raises(ValueError, match="residues must be one of"):
        to_modal(m, residues="modal")
    with pytest.raises(ValueError, match="odd order 3"):
        to_modal(jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 6.0, 11.0, 6.0])))
    mimo = jaxvs.ModalModel(m.omega_n, m.zeta, jnp.ones((2, 2, 2)))
    with pytest.raises(ValueError, match="single-input single-output"):
        zeros(mimo)
    real_poles = jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 5.0, 4.0]))
    with pytest.raises(Exception, match="real poles"):
        to_modal(real_poles)
    with pytest.raises(Exception, match="real poles"):
        to_modal(jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 3.0, -4.0])), residues="real")
    with pytest.raises(Exception, match="unstable"):
        to_modal(jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, -1.0, 100.0])))
    with pytest.raises(Exception, match="velocity term"):
        to_modal(
            jaxvs.RationalTF(jnp.array([1.0, 0.0]), jnp.array([1.0, 1.0, 100.0])), residues="real"
        )
    # the same checks under jit
    with pytest.raises(Exception, match="real poles"):
        eqx.filter_jit(to_modal)(real_poles)
    # position_to_acceleration: improper results
    with pytest.raises(ValueError, match="improper"):
        position_to_acceleration(
            jaxvs.RationalTF(jnp.array([1.0, 0.0]), jnp.array([1.0, 1.0, 100.0]))
        )
    ss = m.to_state_space()
    with pytest.raises(Exception, match="improper"):
        position_to_acceleration(jaxvs.StateSpace(ss.A, ss.B, ss.C, jnp.ones((1, 1))))
    with pytest.raises(Exception, match="improper"):
        position_to_acceleration(jaxvs.ModalModel(m.omega_n, m.zeta, m.residues, feedthrough=1.0))
    with pytest.raises(Exception, match="improper"):
        eqx.filter_jit(position_to_acceleration)(
            jaxvs.StateSpace(ss.A, ss.B, ss.C, jnp.ones((1, 1)))
        )
    over = jaxvs.ModalModel(jnp.array([10.0]), jnp.array([1.5]), jnp.array([1.0]))
    with pytest.raises(Exception, match="over-damped"):
        position_to_acceleration(over)
    # acceleration_to_position of a ModalModel with G(0) != 0: rigid-body poles
    with pytest.raises(Exception, match="rigid-body"):
        acceleration_to_position(m)
    # FRF helpers
    with pytest.raises(ValueError, match="0 rad/s"):
        acceleration_to_position_frf(np.ones(3), np.array([0.0, 1.0, 2.0]))
    with pytest.raises(ValueError, match="axis=-3"):
        acceleration_to_position_frf(np.ones((3, 2, 2)), np.array([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="1-D"):
        position_to_acceleration_frf(np.ones(3), np.ones((3, 1)))
    with pytest.raises(TypeError, match="real angular frequency"):
        position_to_acceleration_frf(np.ones(3), np.ones(3) * 1j)
    with pytest.raises(ValueError, match="out of range"):
        position_to_acceleration_frf(np.ones(3), np.ones(3), axis=2)
    with pytest.raises(ValueError, match="scalar"):
        position_to_acceleration_frf(1.0, np.ones(1))
