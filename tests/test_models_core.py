"""Core linear models against closed forms and scipy.signal."""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal as sig
from helpers import LINEAR_MODELS, random_modal

import jaxvs


@pytest.mark.parametrize("name,factory", LINEAR_MODELS)
def test_realisation_preserves_response(name, factory):
    rng = np.random.default_rng(1)
    model = factory(rng)
    w = np.logspace(0, 4, 200)
    g = np.asarray(jaxvs.frequency_response(model, w))
    g_ss = np.asarray(jaxvs.frequency_response(model.to_state_space(), w))
    # both are exact representations; only rounding separates them (order ≤ 8).
    np.testing.assert_allclose(g_ss, g, rtol=1e-9, atol=1e-12 * np.max(np.abs(g)))


def test_rational_matches_scipy_freqs():
    num, den = [2.0, 0.3, 5.0], [1.0, 0.4, 30.0, 2.0]
    w = np.logspace(-1, 3, 100)
    _, h = sig.freqs(num, den, w)
    g = jaxvs.frequency_response(jaxvs.RationalTF(jnp.array(num), jnp.array(den)), w)
    np.testing.assert_allclose(np.asarray(g), h, rtol=1e-12)


def test_modal_real_residues_closed_form():
    rng = np.random.default_rng(2)
    m = random_modal(rng, 3)
    w = np.linspace(1, 5000, 300)
    s = 1j * w
    expected = sum(
        float(m.residues[k])
        / (s**2 + 2 * float(m.zeta[k] * m.omega_n[k]) * s + float(m.omega_n[k]) ** 2)
        for k in range(3)
    )
    np.testing.assert_allclose(np.asarray(jaxvs.frequency_response(m, w)), expected, rtol=1e-12)


def test_modal_complex_residues_pole_residue_form():
    wn, z = np.array([30.0, 400.0]), np.array([0.05, 0.1])
    R = np.array([1.0 + 2.0j, -3.0 + 0.5j])
    m = jaxvs.ModalModel(jnp.asarray(wn), jnp.asarray(z), jnp.asarray(R))
    lam = wn * (-z + 1j * np.sqrt(1 - z**2))
    w = np.linspace(1, 1000, 300)
    s = 1j * w[:, None]
    expected = np.sum(R / (s - lam) + np.conj(R) / (s - np.conj(lam)), axis=1)
    np.testing.assert_allclose(np.asarray(jaxvs.frequency_response(m, w)), expected, rtol=1e-12)


def test_family_batch_axes():
    rng = np.random.default_rng(3)
    members = [random_modal(rng, 2) for _ in range(5)]
    fam = jaxvs.ModalModel(
        jnp.stack([m.omega_n for m in members]),
        jnp.stack([m.zeta for m in members]),
        jnp.stack([m.residues for m in members]),
    )
    assert fam.batch_shape == (5,)
    w = np.logspace(0, 3, 40)
    g = jaxvs.frequency_response(fam, w)
    assert g.shape == (5, 40)
    for i, m in enumerate(members):
        np.testing.assert_allclose(
            np.asarray(g[i]), np.asarray(jaxvs.frequency_response(m, w)), rtol=1e-13
        )


def test_bad_inputs():
    with pytest.raises(ValueError, match="improper"):
        jaxvs.RationalTF(jnp.array([1.0, 2.0, 3.0]), jnp.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="same shape"):
        jaxvs.ModalModel(jnp.array([1.0, 2.0]), jnp.array([0.1]), jnp.array([1.0, 1.0]))
    with pytest.raises(ValueError, match="inconsistent shapes"):
        jaxvs.StateSpace(jnp.eye(2), jnp.ones((3, 1)), jnp.ones((1, 2)), jnp.zeros((1, 1)))
    with pytest.raises(ValueError, match="1-D"):
        jaxvs.frequency_response(
            jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 1.0])), np.ones((2, 2))
        )
    with pytest.raises(Exception, match="omega_n must be > 0"):
        jaxvs.ModalModel(jnp.array([-1.0]), jnp.array([0.1]), jnp.array([1.0]))
