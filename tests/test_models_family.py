"""Model families over a scheduling variable: GridFamily and SmoothFamily.

Oracles: `numpy.interp` and `scipy.interpolate.PchipInterpolator` for the interpolated
parameters, Python loops over positions for the vectorised calls.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.interpolate as si
from jax.test_util import check_grads

import jaxvs
from jaxvs import GridFamily, SmoothFamily
from jaxvs.models.lti._family import pchip_slopes

_frequency_response = eqx.filter_jit(jaxvs.frequency_response)  # one compile per structure
OMEGA = jnp.logspace(1, 4, 60)


def frf(model, w=OMEGA):
    return np.asarray(_frequency_response(model, jnp.asarray(w)))


def grid_modal(rng, n_points=8, *, complex_residues=False):
    """A ModalModel fitted at `n_points` positions y ∈ [0, 0.7] m: 3 modes that drift."""
    y = np.linspace(0.0, 0.7, n_points)
    base = 2 * np.pi * np.array([45.0, 130.0, 320.0])
    wn = base * (1 + 0.3 * y[:, None] + 0.05 * rng.normal(size=(n_points, 3)))
    z = 0.02 + 0.01 * rng.uniform(size=(n_points, 3))
    r = rng.normal(size=(n_points, 3)) * wn**2 / 3
    if complex_residues:
        r = r + 1j * rng.normal(size=(n_points, 3)) * wn / 3
    return y, jaxvs.ModalModel(jnp.asarray(wn), jnp.asarray(z), jnp.asarray(r))


def member(model, i):
    return jax.tree_util.tree_map(lambda x: x[i] if eqx.is_array(x) else x, model)


@pytest.mark.parametrize("method", ["linear", "pchip"])
@pytest.mark.parametrize("complex_residues", [False, True])
def test_grid_family_reproduces_members_and_interpolates(method, complex_residues):
    rng = np.random.default_rng(0)
    y, model = grid_modal(rng, complex_residues=complex_residues)
    fam = GridFamily(y, model, method=method)
    # at the grid points: the members exactly (Hermite/linear weights are exactly 0 and 1)
    at_grid = fam.at(jnp.asarray(y))
    for k in ("omega_n", "zeta", "residues", "feedthrough"):
        np.testing.assert_array_equal(
            np.asarray(getattr(at_grid, k)), np.asarray(getattr(model, k))
        )
    np.testing.assert_array_equal(frf(at_grid), frf(model))
    # between grid points: the 1-D interpolant of every parameter, against numpy/scipy
    yq = np.sort(rng.uniform(y[0], y[-1], 23))
    fq = fam.at(jnp.asarray(yq))
    assert fq.batch_shape == (23,)

    def oracle(values):
        values = np.asarray(values)
        if np.iscomplexobj(values):
            return oracle(values.real) + 1j * oracle(values.imag)
        if method == "linear":
            return np.stack([np.interp(yq, y, v) for v in values.T], axis=1)
        return si.PchipInterpolator(y, values, axis=0)(yq)

    for k in ("omega_n", "zeta", "residues"):
        # same formulas, different rounding order: 1e-13 relative
        np.testing.assert_allclose(
            np.asarray(getattr(fq, k)), oracle(getattr(model, k)), rtol=1e-13
        )


def test_pchip_slopes_match_scipy_and_preserve_bounds():
    rng = np.random.default_rng(1)
    x = np.sort(rng.uniform(0, 1, 9))
    y = np.stack(
        [rng.normal(size=9), np.cumsum(rng.uniform(size=9)), np.where(np.arange(9) % 2, 1.0, 0.0)],
        axis=1,
    )
    d = np.asarray(pchip_slopes(jnp.asarray(x), jnp.asarray(y)))
    # scipy's PchipInterpolator computes the same Fritsch–Carlson slopes (rounding only)
    np.testing.assert_allclose(
        d, si.PchipInterpolator(x, y, axis=0).derivative()(x), rtol=1e-12, atol=1e-12
    )
    d2 = np.asarray(pchip_slopes(jnp.asarray(x[:2]), jnp.asarray(y[:2])))
    np.testing.assert_allclose(
        d2, si.PchipInterpolator(x[:2], y[:2], axis=0).derivative()(x[:2]), rtol=1e-12
    )
    # damping ratios interpolated with pchip never leave [min, max] of their neighbours
    zeta = np.array([0.01, 0.9, 0.95, 0.02, 0.5])
    grid = np.arange(5.0)
    fam = GridFamily(
        grid,
        jaxvs.ModalModel(
            jnp.full((5, 1), 100.0), jnp.asarray(zeta)[:, None], jnp.ones((5, 1)) * (1 + 1j)
        ),
        method="pchip",
    )
    zq = np.asarray(fam.at(jnp.linspace(0, 4, 401)).zeta)[:, 0]
    assert zq.min() >= 0.01 and zq.max() <= 0.95


def test_grid_family_rational_normalises_den():
    rng = np.random.default_rng(2)
    y = np.array([0.0, 0.5, 1.0])
    den = np.array([[2.0, 3.0, 400.0], [1.0, 2.0, 500.0], [4.0, 4.0, 2400.0]])
    num = rng.normal(size=(3, 3))
    fam = GridFamily(y, jaxvs.RationalTF(jnp.asarray(num), jnp.asarray(den)))
    at = fam.at(jnp.asarray(y))
    # at grid points: the members divided by den[0] (one rounded division)
    np.testing.assert_allclose(np.asarray(at.den), den / den[:, :1], rtol=1e-15)
    np.testing.assert_allclose(np.asarray(at.num), num / den[:, :1], rtol=1e-15)
    np.testing.assert_allclose(
        frf(at), frf(jaxvs.RationalTF(jnp.asarray(num), jnp.asarray(den))), rtol=1e-13
    )
    mid = fam.at(jnp.array([0.25]))
    expect = 0.5 * den[0] / den[0, 0] + 0.5 * den[1] / den[1, 0]
    np.testing.assert_allclose(np.asarray(mid.den)[0], expect, rtol=1e-15)


def test_grid_family_batched_response_and_scalar_positions():
    rng = np.random.default_rng(3)
    y, model = grid_modal(rng, 6)
    fam = GridFamily.from_members(y, [member(model, i) for i in range(6)], method="pchip")
    yq = jnp.asarray(rng.uniform(0, 0.7, (4, 5)))
    batched = fam.at(yq)
    assert batched.batch_shape == (4, 5)
    g = frf(batched)
    assert g.shape == (4, 5, OMEGA.shape[0])
    for i in range(4):
        for j in range(5):
            one = fam.at(yq[i, j])  # a scalar position gives one unbatched model
            assert one.batch_shape == ()
            # identical arithmetic per member under vmap: 1e-13 covers reassociation
            np.testing.assert_allclose(g[i, j], frf(one), rtol=1e-13)
    # extrapolate="clamp" holds the end members
    clamp = GridFamily(y, model, extrapolate="clamp")
    out = clamp.at(jnp.array([-1.0, 5.0]))
    np.testing.assert_array_equal(np.asarray(out.omega_n), np.asarray(model.omega_n)[[0, -1]])


def test_smooth_family_matches_loop():
    def law(p, y):
        wn = p["w0"] + p["w1"] * y + p["w2"] * y**2
        return jaxvs.ModalModel(wn, p["zeta"] * jnp.ones_like(wn), p["r"] * wn**2)

    params = {
        "w0": jnp.array([300.0, 800.0, 2000.0]),
        "w1": jnp.array([50.0, -100.0, 300.0]),
        "w2": jnp.array([10.0, 20.0, -30.0]),
        "zeta": jnp.array(0.03),
        "r": jnp.array([1.0, -0.5, 0.2]),
    }
    fam = SmoothFamily(law, params)
    y = np.linspace(0.0, 0.8, 7)
    batched = fam.at(jnp.asarray(y))
    assert batched.batch_shape == (7,)
    g = frf(batched)
    for i, yi in enumerate(y):
        one = law(params, jnp.asarray(yi))
        # vmap of the same law: identical up to reassociation
        np.testing.assert_allclose(g[i], frf(one), rtol=1e-13)
        np.testing.assert_allclose(
            np.asarray(batched.omega_n[i]), np.asarray(one.omega_n), rtol=1e-15
        )
    assert fam.at(jnp.zeros((2, 3))).batch_shape == (2, 3)
    assert fam.at(0.3).batch_shape == ()
    # the family is jit-able as a whole (the law is static, params are leaves)
    g_jit = eqx.filter_jit(lambda f, yy: jaxvs.frequency_response(f.at(yy), OMEGA))(
        fam, jnp.asarray(y)
    )
    np.testing.assert_allclose(np.asarray(g_jit), g, rtol=1e-13)


def _simulate():
    if hasattr(jaxvs, "simulate"):
        return jaxvs.simulate
    try:  # written in parallel; exported from jaxvs once finished
        from jaxvs.models._simulate import simulate
    except ImportError:
        pytest.skip("jaxvs.simulate is not available yet")
    return simulate


def test_family_simulate_in_one_call():
    simulate = _simulate()
    rng = np.random.default_rng(4)
    y, model = grid_modal(rng, 5)
    yq = jnp.array([0.1, 0.33, 0.6])
    u = jnp.asarray(rng.normal(size=(3, 400)))

    def law(p, yy):
        return jaxvs.ModalModel(p[0] * (1 + 0.5 * yy), jnp.full(3, 0.03), p[1])

    smooth = SmoothFamily(law, (model.omega_n[0], model.residues[0]))
    for fam in (GridFamily(y, model), smooth):
        out = simulate(fam.at(yq), u, 1e-4)
        assert out.shape == (3, 400)
        for i in range(3):
            ref = simulate(fam.at(yq[i]), u[i], 1e-4)
            # the same discretisation and recursion per member: rounding only
            np.testing.assert_allclose(
                np.asarray(out[i]),
                np.asarray(ref),
                rtol=1e-10,
                atol=1e-12 * float(jnp.max(jnp.abs(ref))),
            )


def test_family_gradients_vs_finite_differences():
    """d/dθ of the batched FRF through GridFamily.at and SmoothFamily.at.

    Multiplicative perturbations θ (parameters span 1e-2..1e6): central differences with
    step 1e-6 have O(1e-12) truncation and O(1e-10) rounding error, well inside 1e-6.
    """
    rng = np.random.default_rng(5)
    y, model = grid_modal(rng, 4)
    yq = jnp.array([0.05, 0.3, 0.61])
    scale = np.max(np.abs(frf(GridFamily(y, model).at(yq))))

    for method in ("linear", "pchip"):
        fam = GridFamily(y, model, method=method)
        arrays, static = eqx.partition(fam, eqx.is_inexact_array)
        leaves, tree = jax.tree_util.tree_flatten(arrays)

        def f(thetas, static=static, tree=tree, leaves=leaves):
            p = jax.tree_util.tree_unflatten(tree, [x * (1 + t) for x, t in zip(leaves, thetas)])
            g = jaxvs.frequency_response(eqx.combine(p, static).at(yq), OMEGA[::6]) / scale
            return jnp.concatenate([g.real.ravel(), g.imag.ravel()])

        thetas = [jnp.zeros_like(x) for x in leaves]
        check_grads(
            jax.jit(f), (thetas,), order=1, modes=("fwd", "rev"), eps=1e-6, atol=1e-6, rtol=1e-6
        )

    def law(p, yy):
        return jaxvs.ModalModel(p[0] * (1 + p[1] * yy), p[2] * jnp.ones(2), p[3])

    p0 = [
        jnp.array([400.0, 1500.0]),
        jnp.array([0.3, -0.2]),
        jnp.array(0.04),
        jnp.array([2e5, -1e6]),
    ]

    def g(thetas):
        p = [x * (1 + t) for x, t in zip(p0, thetas)]
        out = jaxvs.frequency_response(SmoothFamily(law, p).at(yq), OMEGA[::6]) / 1e3
        return jnp.concatenate([out.real.ravel(), out.imag.ravel()])

    check_grads(
        jax.jit(g),
        ([jnp.zeros_like(x) for x in p0],),
        order=1,
        modes=("fwd", "rev"),
        eps=1e-6,
        atol=1e-6,
        rtol=1e-6,
    )


def test_bad_inputs():
    rng = np.random.default_rng(6)
    y, model = grid_modal(rng, 4)
    fam = GridFamily(y, model)
    with pytest.raises(ValueError, match="outside the grid"):
        fam.at(jnp.array([0.1, 0.9]))
    with pytest.raises(ValueError, match="outside the grid"):
        fam.at(jnp.array([jnp.nan]))
    with pytest.raises(Exception, match="outside the grid"):
        eqx.filter_jit(lambda f, p: f.at(p).omega_n)(fam, jnp.array([-0.2]))
    with pytest.raises(ValueError, match="strictly increasing"):
        GridFamily(y[::-1], model)
    with pytest.raises(ValueError, match="strictly increasing"):
        GridFamily(np.array([0.0, 0.2, 0.2, 0.7]), model)
    with pytest.raises(Exception, match="strictly increasing"):
        eqx.filter_jit(lambda g: GridFamily(g, model).grid)(jnp.asarray(y[::-1]))
    with pytest.raises(ValueError, match="at least 2 points"):
        GridFamily(np.array([0.0]), member(model, slice(0, 1)))
    with pytest.raises(ValueError, match="batch shape"):
        GridFamily(y[:3], model)
    with pytest.raises(TypeError, match="StateSpace"):
        GridFamily(y, model.to_state_space())
    with pytest.raises(TypeError, match="jaxvs linear model"):
        GridFamily(y, {"omega_n": model.omega_n})
    with pytest.raises(ValueError, match="method must be one of"):
        GridFamily(y, model, method="cubic")
    with pytest.raises(ValueError, match="extrapolate must be one of"):
        GridFamily(y, model, extrapolate="linear")
    with pytest.raises(TypeError, match="real"):
        GridFamily(y * 1j, model)
    with pytest.raises(TypeError, match="positions are real"):
        fam.at(jnp.array([0.1j]))
    other = jaxvs.ModalModel(jnp.ones(2), jnp.ones(2) * 0.1, jnp.ones(2))
    with pytest.raises(ValueError, match="differ in class"):
        GridFamily.from_members(y[:2], [member(model, 0), other])
    with pytest.raises(ValueError, match="at least two members"):
        GridFamily.from_members(y[:2], [])
    # SmoothFamily
    with pytest.raises(TypeError, match="must be a function"):
        SmoothFamily(3.0, {})
    with pytest.raises(TypeError, match="must return a jaxvs linear model"):
        SmoothFamily(lambda p, yy: p * yy, jnp.ones(2))
    with pytest.raises(ValueError, match="unbatched model"):
        SmoothFamily(lambda p, yy: jaxvs.ModalModel(p * yy, p * 0.1, p), jnp.ones((3, 2)))
