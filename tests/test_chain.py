"""N-mass oscillator chains: FRFs, TMFs and conversions against independent oracles.

Indices are 0-based in the code; the study's (Doerrer et al. 2022) masses 1, 2, 3 are 0, 1, 2.
"""

import itertools

import control
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg as sl
import scipy.signal as sig

import jaxvs

# jaxvs.frequency_response, compiled once per model structure (eager dispatch of its many
# small ops dominates these tests' run time otherwise)
frequency_response = eqx.filter_jit(jaxvs.frequency_response)

# A drive-like three-mass chain (motor side, slide, tool side) with light damping.
M3 = np.array([8.0, 40.0, 15.0])  # kg
K3 = np.array([3e7, 1.2e8, 4e7])  # N/m: ground-m0, m0-m1, m1-m2
C3 = np.array([900.0, 1500.0, 300.0])  # N·s/m


def reference_matrices(m, k, c, g=None, grounded="left"):
    """M, C, K assembled element by element (independent of the library's vectorised code)."""
    n = len(m)
    g = np.zeros(n) if g is None else np.asarray(g)
    K, C = np.zeros((n, n)), np.zeros((n, n))
    # (dof i, dof j or None for ground) for every spring/damper pair, left to right
    elements = [(0, None)] + [(i, i + 1) for i in range(n - 1)]
    if grounded == "both":
        elements.append((n - 1, None))
    for (i, j), ke, ce in zip(elements, k, c, strict=True):
        for mat, v in ((K, ke), (C, ce)):
            mat[i, i] += v
            if j is not None:
                mat[j, j] += v
                mat[i, j] -= v
                mat[j, i] -= v
    C += np.diag(g)
    return np.diag(m), C, K


def reference_state_space(m, k, c, g=None, grounded="left"):
    M, C, K = reference_matrices(m, k, c, g, grounded)
    n = len(m)
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
    B = np.vstack([np.zeros((n, n)), Minv])
    return A, B


def random_chain_params(rng, n, grounded="left"):
    ns = n if grounded == "left" else n + 1
    m = rng.uniform(0.5, 20.0, n)
    k = 10 ** rng.uniform(5, 7, ns)
    c = rng.uniform(0.0, 1e-4, ns) * k  # ζ of order 1 %
    g = rng.uniform(0.0, 5.0, n)
    return m, k, c, g


def grid_around(chain, decades=2, n=1500):
    wn = np.asarray(chain.modal_parameters().omega_n)
    return np.logspace(np.log10(wn.min()) - decades, np.log10(wn.max()) + decades, n)


# --- the study's Figure 3 -----------------------------------------------------------


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_figure3_tmf_depends_on_excitation_side(grounded):
    k = K3 if grounded == "left" else np.append(K3, 2e7)
    c = C3 if grounded == "left" else np.append(C3, 200.0)
    chain = jaxvs.OscillatorChain(M3, k, c, grounded=grounded)
    w = grid_around(chain)
    # T_32^1, T_32^2, T_32^3 of the paper = tmf(a=2, b=1, c=0|1|2)
    t1, t2, t3 = (np.asarray(chain.tmf(w, 2, 1, c)) for c in range(3))

    # Why T_32^1 = T_32^2: with the force at mass 1 or 2 (left of, or at, b = 2), the part
    # of the chain right of mass 2 carries no external force and is driven only through the
    # motion of mass 2, so x3 / x2 is a property of that right part alone (mass 3 base-
    # excited through k23, c23), whatever c is:
    # x3 = (k23 + c23 s) / (m3 s² + c_right s + k_right) · x2, with c_right, k_right
    # including the ground spring of mass 3 when the chain is grounded at both ends.
    # Both are computed by separate linear solves, so only rounding (cond(Z) · eps near
    # resonances, ζ ≈ 1 %) separates them.
    np.testing.assert_allclose(t2, t1, rtol=1e-12)
    s = 1j * w
    k_right = k[2] + (k[3] if grounded == "both" else 0.0)
    c_right = c[2] + (c[3] if grounded == "both" else 0.0)
    closed = (k[2] + c[2] * s) / (M3[2] * s**2 + c_right * s + k_right)
    np.testing.assert_allclose(t1, closed, rtol=1e-11)  # closed form, rounding only

    # With the force at mass 3 it is the left part (masses 1, 2) that is driven only
    # through the coupling κ = k23 + c23 s: x2 = H^L_22 κ (x3 − x2), where H^L_22 is the
    # receptance at mass 2 of the left sub-chain alone, so x3/x2 = 1 + 1/(κ H^L_22) (a ground
    # spring at mass 3 acts on mass 3's own balance only and does not enter).
    left = jaxvs.OscillatorChain(M3[:2], k[:2], c[:2])
    h_left = np.asarray(left.frf(w, response=1, force=1))
    kappa = k[2] + c[2] * s
    np.testing.assert_allclose(t3, 1 + 1 / (kappa * h_left), rtol=1e-10)  # rounding only

    # Clearly different for c = 3: relative separation |T^3 − T^1| / |T^1| is O(1) over most
    # of the grid; it is smallest close to the first natural frequency, where the motion
    # is dominated by one mode shape and both ratios approach φ_3 / φ_2 of that mode
    # (measured 9e-3 'left', 2e-2 'both' at ζ ≈ 1 %; median 1.1 and 1.6), still ten
    # decades above the c = 1, 2 agreement (measured ≤ 6e-15).
    sep = np.abs(t3 - t1) / np.abs(t1)
    assert np.min(sep) > 5e-3
    assert np.median(sep) > 0.5

    # The exact rational TMF models agree coefficient by coefficient (common factors are
    # cancelled symbolically), and the c = 3 TMF x3/x2 is improper (mass 3 is the nearer
    # one to the force): no proper model exists.
    m1, m2 = chain.transmissibility_model(2, 1, 0), chain.transmissibility_model(2, 1, 1)
    np.testing.assert_array_equal(np.asarray(m1.num), np.asarray(m2.num))
    np.testing.assert_array_equal(np.asarray(m1.den), np.asarray(m2.den))
    assert m1.num.shape == m1.den.shape == (3,)  # order 2: mass 3 on its spring
    with pytest.raises(ValueError, match="improper"):
        chain.transmissibility_model(2, 1, 2)


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_tmf_independent_of_force_on_one_side(grounded):
    # The generalisation of Figure 3: T_ab^c is the same for every c <= min(a, b), and for
    # every c >= max(a, b), and differs between the two sides.
    rng = np.random.default_rng(16)
    n = 5
    m, k, c, g = random_chain_params(rng, n, grounded)
    chain = jaxvs.OscillatorChain(m, k, c, grounded=grounded, ground_dampings=g)
    w = grid_around(chain, 1, 200)
    for a, b in itertools.permutations(range(n), 2):
        lo, hi = min(a, b), max(a, b)
        left = [np.asarray(chain.tmf(w, a, b, cc)) for cc in range(lo + 1)]
        right = [np.asarray(chain.tmf(w, a, b, cc)) for cc in range(hi, n)]
        for t in left[1:]:
            np.testing.assert_allclose(t, left[0], rtol=1e-10)  # separate solves, rounding
        for t in right[1:]:
            np.testing.assert_allclose(t, right[0], rtol=1e-10)
        # the two sides differ by O(1) somewhere on the grid
        assert np.max(np.abs(right[0] / left[0] - 1)) > 0.1


# --- FRFs against independent oracles --------------------------------------------------


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_frf_matches_python_control(grounded):
    rng = np.random.default_rng(10)
    m, k, c, g = random_chain_params(rng, 4, grounded)
    chain = jaxvs.OscillatorChain(m, k, c, grounded=grounded, ground_dampings=g)
    A, B = reference_state_space(m, k, c, g, grounded)
    n = len(m)
    w = grid_around(chain, 1, 400)
    for quantity, Cm, D in (
        ("displacement", np.hstack([np.eye(n), np.zeros((n, n))]), np.zeros((n, n))),
        ("velocity", np.hstack([np.zeros((n, n)), np.eye(n)]), np.zeros((n, n))),
        ("acceleration", A[n:], B[n:]),
    ):
        sys = control.ss(A, B, Cm, D)
        expected = np.moveaxis(sys(1j * w), -1, 0)  # (freq, out, in)
        got = np.asarray(chain.frf(w, quantity=quantity))
        # both are dense solves of the same well-scaled 4-8 dimensional problem
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_sdof_closed_form(grounded):
    m, k, c = 3.0, 2e5, 40.0
    ks, cs = ([k], [c]) if grounded == "left" else ([k, 0.5 * k], [c, 0.25 * c])
    chain = jaxvs.OscillatorChain([m], ks, cs, grounded=grounded)
    w = np.linspace(0.0, 2000.0, 501)
    expected = 1 / (sum(ks) - m * w**2 + 1j * sum(cs) * w)
    np.testing.assert_allclose(np.asarray(chain.frf(w, response=0, force=0)), expected, rtol=1e-13)
    acc = np.asarray(chain.frf(w, response=0, force=0, quantity="acceleration"))
    np.testing.assert_allclose(acc, -(w**2) * expected, rtol=1e-13)
    assert chain.frf(w).shape == (501, 1, 1)


def test_two_mass_resonances_closed_form():
    m1, m2, k1, k2 = 5.0, 2.0, 4e6, 1e6
    chain = jaxvs.OscillatorChain([m1, m2], [k1, k2], [0.0, 0.0])
    # det(K − ω² M) = 0: m1 m2 λ² − (m1 k2 + m2 (k1 + k2)) λ + k1 k2 = 0, λ = ω²
    p = m1 * k2 + m2 * (k1 + k2)
    disc = np.sqrt(p**2 - 4 * m1 * m2 * k1 * k2)
    expected = np.sqrt([(p - disc) / (2 * m1 * m2), (p + disc) / (2 * m1 * m2)])
    wn = np.asarray(chain.modal_parameters().omega_n)
    np.testing.assert_allclose(wn, expected, rtol=1e-13)  # 2x2 eigh vs quadratic formula

    # Light damping (ζ ≈ 0.1 %): the FRF peaks sit at the undamped natural frequencies
    # up to the grid step (0.01 %) and the damping shift ζ² ≈ 1e-6.
    damped = jaxvs.OscillatorChain([m1, m2], [k1, k2], [1e-6 * k1, 1e-6 * k2])
    for wk in expected:
        w = np.linspace(0.98 * wk, 1.02 * wk, 401)
        h = np.abs(np.asarray(damped.frf(w, response=1, force=0)))
        assert abs(w[np.argmax(h)] / wk - 1) < 2e-4


# --- modal parameters -----------------------------------------------------------------


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_generalised_eigenproblem_vs_scipy(grounded):
    rng = np.random.default_rng(11)
    m, k, c, g = random_chain_params(rng, 6, grounded)
    chain = jaxvs.OscillatorChain(m, k, c, grounded=grounded, ground_dampings=g)
    M, C, K = reference_matrices(m, k, c, g, grounded)
    np.testing.assert_array_equal(np.asarray(chain.mass_matrix()), M)
    np.testing.assert_allclose(np.asarray(chain.stiffness_matrix()), K, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(chain.damping_matrix()), C, rtol=1e-15)

    lam, V = sl.eigh(K, M)
    modes = chain.modal_parameters()
    wn, phi = np.asarray(modes.omega_n), np.asarray(modes.mode_shapes)
    # reduction + eigh vs LAPACK's generalised solver; eigenvalues spread over ~3 decades
    np.testing.assert_allclose(wn**2, lam, rtol=1e-11)
    # scipy's eigenvectors are also mass-normalised; signs are arbitrary there
    V = V * np.sign(V[0])
    np.testing.assert_allclose(phi, V, rtol=1e-8, atol=1e-10 * np.abs(V).max())
    assert np.all(phi[0] > 0)  # the documented sign convention
    np.testing.assert_allclose(phi.T @ M @ phi, np.eye(6), atol=1e-12)
    np.testing.assert_allclose(phi.T @ K @ phi, np.diag(lam), atol=1e-9 * lam.max())
    zeta = np.einsum("ik,ij,jk->k", phi, C, phi) / (2 * wn)
    np.testing.assert_allclose(np.asarray(modes.zeta), zeta, rtol=1e-12)


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_to_modal_rayleigh_matches_direct_solve(grounded):
    rng = np.random.default_rng(12)
    m, k, _, _ = random_chain_params(rng, 5, grounded)
    alpha, beta = 3.0, 2e-5
    chain = jaxvs.OscillatorChain.rayleigh(m, k, alpha, beta, grounded=grounded)
    M, C, K = reference_matrices(m, k, beta * k, alpha * m, grounded)
    np.testing.assert_allclose(np.asarray(chain.damping_matrix()), alpha * M + beta * K, rtol=1e-14)
    wn = np.asarray(chain.modal_parameters().omega_n)
    # Rayleigh: ζ_k = α / (2 ω_k) + β ω_k / 2
    np.testing.assert_allclose(
        np.asarray(chain.modal_parameters().zeta), alpha / (2 * wn) + beta * wn / 2, rtol=1e-11
    )

    w = grid_around(chain, 1, 600)
    model = chain.to_modal([0, 3], None)
    assert isinstance(model, jaxvs.ModalModel) and model.io_shape == (5, 2)
    got = np.asarray(frequency_response(model, w))
    direct = np.asarray(chain.frf(w, force=[0, 3]))
    # modal superposition is exact for proportional damping; ~cond · eps at resonances
    np.testing.assert_allclose(got, direct, rtol=1e-9, atol=1e-9 * np.abs(direct).max())

    siso = chain.to_modal(1, 4)
    assert siso.residues.shape == (5,) and siso.is_siso
    h41 = np.asarray(chain.frf(w, response=4, force=1))
    np.testing.assert_allclose(
        np.asarray(frequency_response(siso, w)), h41, rtol=1e-9, atol=1e-9 * np.abs(h41).max()
    )
    assert chain.to_modal(1, [0, 2]).residues.shape == (5, 2)
    assert chain.to_modal([1], 2).residues.shape == (5, 1, 1)


def test_reciprocity():
    rng = np.random.default_rng(13)
    m, k, c, g = random_chain_params(rng, 5, "both")
    chain = jaxvs.OscillatorChain(m, k, c, grounded="both", ground_dampings=g)
    h = np.asarray(chain.frf(grid_around(chain, 1, 300)))
    # Maxwell–Betti: M, C, K symmetric ⇒ H = Hᵀ; both triangles come from one LU solve
    np.testing.assert_allclose(h, np.swapaxes(h, -1, -2), rtol=1e-10, atol=1e-12 * np.abs(h).max())


# --- TMF models --------------------------------------------------------------------------


@pytest.mark.parametrize("grounded", ["left", "both"])
def test_transmissibility_model_all_triples(grounded):
    rng = np.random.default_rng(14)
    n = 4
    m, k, c, g = random_chain_params(rng, n, grounded)
    chain = jaxvs.OscillatorChain(m, k, c, grounded=grounded, ground_dampings=g)
    w = grid_around(chain, 1, 300)
    # Oracle 2 input: a scaled state space for scipy's ss2tf, which subtracts two
    # characteristic polynomials and so needs O(1) entries. States (x, x'/w0) in time
    # w0·t and a unit force (the TMF does not depend on the force's scale or units).
    M, C, K = reference_matrices(m, k, c, g, grounded)
    w0 = np.exp(np.mean(np.log(np.asarray(chain.modal_parameters().omega_n))))
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K / w0**2, -Minv @ C / w0]])
    B = np.vstack([np.zeros((n, n)), np.eye(n)])
    Cd = np.hstack([np.eye(n), np.zeros((n, n))])
    n_models = 0
    for a, b, cc in itertools.product(range(n), repeat=3):
        if a == b:
            continue
        if abs(a - cc) < abs(b - cc):
            with pytest.raises(ValueError, match="improper"):
                chain.transmissibility_model(a, b, cc)
            continue
        tm = chain.transmissibility_model(a, b, cc)
        n_models += 1
        assert tm.num.shape == tm.den.shape  # a TMF of equal orders (eq. 8)
        # Cancelled order 2N − 2 − |b − c| − (common factors); never above 2N − 2.
        assert tm.order <= 2 * n - 2
        got = np.asarray(frequency_response(tm, w))
        # oracle 1: the ratio of two direct FRF solves
        ratio = np.asarray(chain.tmf(w, a, b, cc))
        np.testing.assert_allclose(got, ratio, rtol=1e-8)  # order ≤ 6 polynomials
        # oracle 2: scipy's ss2tf numerators N_ac / N_bc (the shared denominator cancels),
        # in the scaled frequency s / w0. H_ac has relative degree 2 + |a − c| (the force
        # passes |a − c| springs), so the leading ss2tf coefficients above that are
        # rounding noise (~1e-15) and are dropped.
        num, _ = sig.ss2tf(A, B, Cd, np.zeros((n, n)), input=cc)
        na, nb = num[a][-(2 * n - 1 - abs(a - cc)) :], num[b][-(2 * n - 1 - abs(b - cc)) :]
        s = 1j * w / w0
        expected = np.polyval(na, s) / np.polyval(nb, s)
        np.testing.assert_allclose(got, expected, rtol=1e-8)  # measured ≤ 1e-10
    # per force location c, the ordered pairs a != b with |a - c| >= |b - c|: 6 at either
    # end (all distances distinct), 7 for an inner c (5 strict + the tie pair both ways)
    assert n_models == 26


def test_transmissibility_model_orders_closed_form():
    chain = jaxvs.OscillatorChain(M3, K3, C3)
    # c ≤ b < a: T = Π κ · φ_{a+1} / φ_{b+1}; for a = 2, b = 0: (κ0 κ1 is not in it)
    tm = chain.transmissibility_model(2, 0, 0)
    # x2/x0 with masses 1, 2 driven through mass 0: order 4 (2 · (N − 1 − b))
    assert tm.order == 4
    np.testing.assert_allclose(np.asarray(tm.den)[0], M3[1] * M3[2], rtol=1e-15)
    # leading numerator coefficients vanish: κ1 κ2 has order 2
    np.testing.assert_array_equal(np.asarray(tm.num)[:2], 0.0)
    np.testing.assert_allclose(np.asarray(tm.num)[2:], np.convolve([C3[1], K3[1]], [C3[2], K3[2]]))


# --- state space --------------------------------------------------------------------------


def test_state_space_quantities_and_feedthrough():
    chain = jaxvs.OscillatorChain(M3, K3, C3)
    w = grid_around(chain, 1, 300)
    A, B = reference_state_space(M3, K3, C3)
    for quantity in ("displacement", "velocity", "acceleration"):
        ss = chain.state_space([0, 2], [2, 1], quantity=quantity)
        assert isinstance(ss, jaxvs.StateSpace) and ss.order == 6
        np.testing.assert_allclose(np.asarray(ss.A), A, rtol=1e-15)
        np.testing.assert_allclose(np.asarray(ss.B), B[:, [0, 2]], rtol=1e-15)
        got = np.asarray(frequency_response(ss, w))
        h = np.asarray(chain.frf(w, response=[2, 1], force=[0, 2], quantity=quantity))
        np.testing.assert_allclose(got, h, rtol=1e-8, atol=1e-10 * np.abs(h).max())
    acc = chain.state_space([0, 2], [2, 1], quantity="acceleration")
    # D = E_outᵀ M⁻¹ E_force: only output mass 2 is forced (input 1)
    np.testing.assert_allclose(np.asarray(acc.D), [[0.0, 1 / M3[2]], [0.0, 0.0]], rtol=1e-15)
    # the block-modal realisation keeps the response (eig of a 6x6 with ζ ≈ 1 %)
    siso = chain.state_space(0, 2)
    assert siso.is_siso
    block = eqx.filter_jit(lambda ss: jaxvs.StateSpace(*ss.modal_realisation().dense()))(siso)
    g1 = np.asarray(frequency_response(block, w))
    g0 = np.asarray(chain.frf(w, response=2, force=0))
    np.testing.assert_allclose(g1, g0, rtol=1e-8, atol=1e-10 * np.abs(g0).max())


# --- gradients, batching, jit ---------------------------------------------------------------


def test_gradients_match_finite_differences():
    w = jnp.array([500.0, 1500.0, 2500.0, 4000.0])
    params = {"m": jnp.asarray(M3), "k": jnp.asarray(K3), "c": jnp.asarray(C3)}

    def loss(p):
        chain = jaxvs.OscillatorChain(p["m"], p["k"], p["c"])
        h = chain.frf(w, response=2, force=0)
        t = chain.tmf(w, 0, 1, 2)
        wn = chain.modal_parameters().omega_n
        tm = jaxvs.frequency_response(chain.transmissibility_model(2, 0, 0), w)
        return (
            jnp.sum(jnp.log(jnp.abs(h)))
            + jnp.sum(jnp.real(t) + jnp.imag(t))
            + jnp.sum(jnp.log(wn))
            + jnp.sum(jnp.abs(tm))
        )

    grad = jax.jit(jax.grad(loss))(params)
    loss = jax.jit(loss)
    for name in ("m", "k", "c"):
        for i in range(3):
            x = params[name]
            step = 1e-6 * x[i]
            up = loss({**params, name: x.at[i].add(step)})
            dn = loss({**params, name: x.at[i].add(-step)})
            fd = (up - dn) / (2 * step)
            # central differences: truncation ~ step² · f''' plus rounding eps/step ≈ 1e-10
            np.testing.assert_allclose(float(grad[name][i]), float(fd), rtol=1e-5, atol=1e-14)


def test_batched_family_matches_loop():
    rng = np.random.default_rng(15)
    members = [random_chain_params(rng, 3, "both") for _ in range(4)]
    stack = [np.stack([p[j] for p in members]) for j in range(4)]
    family = jaxvs.OscillatorChain(*stack[:3], grounded="both", ground_dampings=stack[3])
    assert family.batch_shape == (4,) and family.n_masses == 3
    w = np.logspace(1, 4, 120)
    h = np.asarray(family.frf(w, response=[2, 0], force=1))
    t = np.asarray(family.tmf(w, 2, 1, 0))
    wn = np.asarray(family.modal_parameters().omega_n)
    ss = family.state_space(0, 2, quantity="acceleration")
    tm = family.transmissibility_model(2, 1, 0)
    assert h.shape == (4, 120, 2) and t.shape == (4, 120) and ss.A.shape == (4, 6, 6)
    assert family.mass_matrix().shape == (4, 3, 3)
    for i, p in enumerate(members):
        one = jaxvs.OscillatorChain(*p[:3], grounded="both", ground_dampings=p[3])
        # same operations, vmapped vs not: only reassociation-level rounding differs
        h_one = np.asarray(one.frf(w, response=[2, 0], force=1))
        np.testing.assert_allclose(h[i], h_one, rtol=1e-12)
        np.testing.assert_allclose(t[i], np.asarray(one.tmf(w, 2, 1, 0)), rtol=1e-12)
        np.testing.assert_allclose(wn[i], np.asarray(one.modal_parameters().omega_n), rtol=1e-12)
        d_one = one.state_space(0, 2, quantity="acceleration").D
        np.testing.assert_array_equal(np.asarray(ss.D[i]), np.asarray(d_one))
        np.testing.assert_allclose(
            np.asarray(tm.den[i]), np.asarray(one.transmissibility_model(2, 1, 0).den), rtol=1e-13
        )
    # a batched family through the generic entry points
    g = np.asarray(frequency_response(tm, w))
    np.testing.assert_allclose(g, t, rtol=1e-8)

    # jax.vmap over a function that builds the chain from its parameters, under jit
    @jax.jit
    @jax.vmap
    def build_and_respond(m, k, c, gd):
        chain = jaxvs.OscillatorChain(m, k, c, grounded="both", ground_dampings=gd)
        return chain.frf(jnp.asarray(w), response=[2, 0], force=1)

    np.testing.assert_allclose(np.asarray(build_and_respond(*stack)), h, rtol=1e-12)


def test_rayleigh_family_to_modal():
    m = np.array([[1.0, 2.0], [3.0, 1.0]])
    k = np.array([[1e4, 2e4], [3e4, 1e4]])
    chain = jaxvs.OscillatorChain.rayleigh(m, k, np.array([0.5, 1.0]), np.array([1e-4, 2e-4]))
    model = chain.to_modal(0, 1)
    assert model.batch_shape == (2,)
    w = np.logspace(0, 3, 100)
    h = np.asarray(chain.frf(w, response=1, force=0))
    np.testing.assert_allclose(np.asarray(frequency_response(model, w)), h, rtol=1e-10)


# --- bad input ----------------------------------------------------------------------------


def test_bad_values_raise_at_run_time():
    with pytest.raises(eqx.EquinoxRuntimeError, match="masses must be > 0"):
        jaxvs.OscillatorChain([1.0, 0.0], [1.0, 1.0], [0.0, 0.0])
    with pytest.raises(eqx.EquinoxRuntimeError, match="stiffnesses must be > 0"):
        jaxvs.OscillatorChain([1.0, 1.0], [1.0, -1.0], [0.0, 0.0])
    with pytest.raises(eqx.EquinoxRuntimeError, match="dampings must be >= 0"):
        jaxvs.OscillatorChain([1.0, 1.0], [1.0, 1.0], [0.0, -1.0])
    with pytest.raises(eqx.EquinoxRuntimeError, match="ground_dampings must be >= 0"):
        jaxvs.OscillatorChain([1.0, 1.0], [1.0, 1.0], [0.0, 0.0], ground_dampings=[-1.0, 0.0])
    with pytest.raises(eqx.EquinoxRuntimeError, match="masses must be > 0"):
        jaxvs.OscillatorChain([1.0, np.nan], [1.0, 1.0], [0.0, 0.0])

    @eqx.filter_jit
    def build(m):
        chain = jaxvs.OscillatorChain(m, jnp.ones(2), jnp.zeros(2))
        return chain.frf(jnp.ones(3), response=0, force=0)

    build(jnp.ones(2))
    with pytest.raises(eqx.EquinoxRuntimeError, match="masses must be > 0"):
        build(jnp.array([1.0, -2.0]))

    # non-proportional damping: only c0 damped, so ΦᵀCΦ is full
    chain = jaxvs.OscillatorChain(M3, K3, [900.0, 0.0, 0.0])
    with pytest.raises(eqx.EquinoxRuntimeError, match="not proportional"):
        chain.to_modal(0, 2)
    with pytest.raises(eqx.EquinoxRuntimeError, match="not proportional"):
        eqx.filter_jit(lambda ch: ch.to_modal(0, 2))(chain)
    # the undamped chain has C = 0, which is (trivially) proportional
    jaxvs.OscillatorChain(M3, K3, [0.0, 0.0, 0.0]).to_modal(0, 2)

    # force strictly between a and b with undamped couplings c..b: order drops at run time
    undamped = jaxvs.OscillatorChain(M3, K3, [1.0, 0.0, 0.0])
    with pytest.raises(eqx.EquinoxRuntimeError, match="undamped"):
        undamped.transmissibility_model(0, 2, 1)
    # … which the same chain does not hit when the force is on one side
    undamped.transmissibility_model(2, 1, 0)


def test_bad_structure_raises_at_trace_time():
    with pytest.raises(ValueError, match=r"has 3 springs .* shape \(\*batch, 3\)"):
        jaxvs.OscillatorChain(M3, K3[:2], C3[:2])
    with pytest.raises(ValueError, match=r"has 4 springs"):
        jaxvs.OscillatorChain(M3, K3, C3, grounded="both")
    with pytest.raises(ValueError, match="same shape as stiffnesses"):
        jaxvs.OscillatorChain(M3, K3, C3[:2])
    with pytest.raises(ValueError, match="ground_dampings must have the shape"):
        jaxvs.OscillatorChain(M3, K3, C3, ground_dampings=[1.0])
    with pytest.raises(ValueError, match="grounded='right'"):
        jaxvs.OscillatorChain(M3, K3, C3, grounded="right")
    with pytest.raises(ValueError, match="N >= 1"):
        jaxvs.OscillatorChain(np.zeros(0), np.zeros(0), np.zeros(0))
    with pytest.raises(ValueError, match="different leading"):
        jaxvs.OscillatorChain(np.ones((2, 3)), np.ones((3, 3)), np.zeros((3, 3)))
    with pytest.raises(TypeError, match="must be real"):
        jaxvs.OscillatorChain(M3 + 0j, K3, C3)

    chain = jaxvs.OscillatorChain(M3, K3, C3)
    w = np.logspace(1, 3, 5)
    valid = r"valid mass indices are 0\.\.2"
    with pytest.raises(ValueError, match=r"response=3 is out of range; " + valid):
        chain.frf(w, response=3, force=0)
    with pytest.raises(ValueError, match=r"force=-4 is out of range; " + valid):
        chain.frf(w, response=0, force=-4)
    with pytest.raises(ValueError, match=r"c=5 is out of range; " + valid):
        chain.tmf(w, 2, 1, 5)
    with pytest.raises(ValueError, match=r"outputs=7 is out of range"):
        chain.state_space(0, [0, 7])
    with pytest.raises(ValueError, match=r"force=3 is out of range"):
        chain.to_modal(3)
    with pytest.raises(ValueError, match=r"a=9 is out of range"):
        chain.transmissibility_model(9, 1, 0)
    with pytest.raises(ValueError, match="empty sequence"):
        chain.frf(w, response=[], force=0)
    with pytest.raises(TypeError, match="must be a Python int"):
        chain.frf(w, response=1.5, force=0)
    with pytest.raises(TypeError, match="must be a Python int"):
        jax.jit(lambda i: chain.tmf(w, i, 1, 0))(2)
    with pytest.raises(ValueError, match="quantity='jerk'"):
        chain.frf(w, quantity="jerk")
    with pytest.raises(ValueError, match="quantity='force'"):
        chain.state_space(0, quantity="force")
    with pytest.raises(ValueError, match="omega must be 1-D"):
        chain.frf(np.ones((2, 2)))
    with pytest.raises(TypeError, match="real angular frequency"):
        chain.tmf(1j * w, 2, 1, 0)
    with pytest.raises(ValueError, match="a and b are both 1"):
        chain.transmissibility_model(1, 1, 0)
    # negative indices count from the right end
    t_neg, t_pos = chain.tmf(w, -1, -2, 0), chain.tmf(w, 2, 1, 0)
    np.testing.assert_array_equal(np.asarray(t_neg), np.asarray(t_pos))
