"""Natural frequencies and mode shapes by the generalised eigenproblem (K, M): against
scipy.linalg.eigh, closed forms (two-mass oscillator, Rayleigh damping) and the continuous
torsional shaft with a tip mass (distributed ball screw)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg as sl
import scipy.optimize as so

from jaxvs.models import BallScrew, FlexibleAxis, damped_modes, normal_modes


def _random_spd(rng, n, semidefinite=False):
    a = rng.normal(size=(n, n))
    m = a @ a.T + (0 if semidefinite else n) * np.eye(n)
    if semidefinite:  # one zero eigenvalue
        v = rng.normal(size=n)
        p = np.eye(n) - np.outer(v, v) / (v @ v)
        m = p @ m @ p
    return 0.5 * (m + m.T)


def test_generalised_eigenvalues_match_scipy_eigh():
    rng = np.random.default_rng(3)
    K = _random_spd(rng, 6) * 1e6
    M = _random_spd(rng, 6)
    modes = normal_modes(K, M)
    lam_ref, phi_ref = sl.eigh(K, M)
    # both are backward-stable symmetric solvers: eigenvalues agree to ~cond·eps
    np.testing.assert_allclose(np.asarray(modes.omega_n) ** 2, lam_ref, rtol=1e-10)
    phi = np.asarray(modes.mode_shapes)
    # same mass-normalised shapes up to sign
    signs = np.sign(np.sum(phi * phi_ref, axis=0))
    np.testing.assert_allclose(phi, phi_ref * signs, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(phi.T @ M @ phi, np.eye(6), atol=1e-10)
    np.testing.assert_allclose(phi.T @ K @ phi, np.diag(lam_ref), rtol=1e-9, atol=1e-3)


def test_semidefinite_stiffness_gives_a_rigid_body_mode():
    rng = np.random.default_rng(4)
    K = _random_spd(rng, 4, semidefinite=True)
    M = np.diag(rng.uniform(1, 3, 4))
    modes = normal_modes(K, M)
    assert float(modes.omega_n[0]) < 1e-6  # rounding of a zero eigenvalue
    np.testing.assert_allclose(
        np.asarray(modes.omega_n[1:]) ** 2, sl.eigh(K, M, eigvals_only=True)[1:], rtol=1e-10
    )


def test_two_mass_resonance_closed_form():
    m1, m2, k = 12.0, 300.0, 4e7
    modes = FlexibleAxis(jnp.array([m1, m2]), jnp.array([k]), jnp.array([0.0])).normal_modes()
    assert float(modes.omega_n[0]) < 1e-3
    assert float(modes.omega_n[1]) == pytest.approx(np.sqrt(k * (1 / m1 + 1 / m2)), rel=1e-12)


def test_rayleigh_damping_closed_form_and_damped_modes():
    M = np.diag([2.0, 1.0, 3.0])
    K = np.array([[3e4, -1e4, 0], [-1e4, 2e4, -1e4], [0, -1e4, 1e4]])
    alpha, beta = 2.0, 1e-4
    C = alpha * M + beta * K
    und = normal_modes(K, M, C)
    w = np.sqrt(sl.eigh(K, M, eigvals_only=True))
    zeta = alpha / (2 * w) + beta * w / 2  # Rayleigh: exact for proportional damping
    np.testing.assert_allclose(und.omega_n, w, rtol=1e-12)
    np.testing.assert_allclose(und.zeta, zeta, rtol=1e-10)
    dm = damped_modes(K, M, C)
    np.testing.assert_allclose(dm.omega_n, w, rtol=1e-9)
    np.testing.assert_allclose(dm.zeta, zeta, rtol=1e-8)
    np.testing.assert_allclose(dm.omega_d, w * np.sqrt(1 - zeta**2), rtol=1e-9)


def test_normal_modes_jit_vmap_grad():
    def first(k):
        K = jnp.array([[2 * k, -k], [-k, k]])
        return normal_modes(K, jnp.eye(2)).omega_n[0]

    ks = jnp.array([1.0, 4.0, 9.0])
    vals = jax.jit(jax.vmap(first))(ks)
    ref = np.sqrt(ks * (3 - np.sqrt(5)) / 2)  # closed form of this 2-DOF chain
    np.testing.assert_allclose(vals, ref, rtol=1e-12)
    # dω/dk = ω / (2k)
    np.testing.assert_allclose(jax.grad(first)(4.0), ref[1] / 8.0, rtol=1e-10)


def test_distributed_screw_converges_to_the_continuous_shaft():
    """A torsional shaft fixed at the motor (huge motor inertia) with the table as tip mass:
    β tan β = m_shaft / m_tip, ω = β sqrt(K_shaft / m_shaft) (Timoshenko, *Vibration
    Problems in Engineering*, §5.4)."""
    screw = BallScrew(
        1.0, 0.032, 0.01, nut_stiffness=1e18, bearing_stiffness=1e18, youngs_modulus=1e24
    )
    n2 = float(screw.ratio) ** 2
    m_shaft = float(screw.inertia()) * n2
    k_shaft = float(screw.torsional_stiffness()) * n2
    m_tip = 300.0
    beta = so.brentq(lambda b: b * np.tan(b) - m_shaft / m_tip, 1e-6, np.pi / 2 - 1e-9)
    w_exact = beta * np.sqrt(k_shaft / m_shaft)
    errors = []
    for n in (4, 16, 64):
        build = eqx.filter_jit(
            lambda s, n=n: s.distributed_axis(1e3, m_tip, n_segments=n).normal_modes().omega_n
        )
        w = float(build(screw)[1])
        errors.append(abs(w - w_exact) / w_exact)
    # lumped-mass finite elements converge as O(1/n²): x16 per 4x refinement
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 2e-4
    assert errors[1] / errors[2] > 8
    # the lumped two-mass model puts the whole shaft inertia on the motor side, so with a
    # fixed motor it sees only the tip mass: sqrt(k_eq / m_tip)
    lumped = screw.lumped_axis(1e3, m_tip)
    w_l = float(lumped.normal_modes().omega_n[1])
    assert w_l == pytest.approx(np.sqrt(float(screw.equivalent_stiffness()) / m_tip), rel=1e-6)


def test_bad_matrices():
    with pytest.raises(ValueError, match="square matrix"):
        normal_modes(np.ones((2, 3)), np.eye(2))
    with pytest.raises(Exception, match="symmetric"):
        normal_modes(np.array([[2.0, 1.0], [0.0, 1.0]]), np.eye(2))
    with pytest.raises(Exception, match="positive definite"):
        normal_modes(np.eye(2), np.diag([1.0, -1.0]))
