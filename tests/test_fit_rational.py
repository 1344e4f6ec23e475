"""`jaxvs.fit_rational` against closed forms, scipy.signal / scipy.optimize and Monte Carlo.

Every fit here shares one frequency grid (`OMEGA`) so that the compiled solver is reused
between tests of the same order and batch size.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize as opt
import scipy.signal as sig

import jaxvs
from jaxvs.calibration import RESULTS, batched_while

OMEGA = 2 * np.pi * np.geomspace(1.0, 1000.0, 300)  # rad/s, 1 Hz - 1 kHz


def _pairs(rng, k, f_lo=5.0, f_hi=500.0, z_lo=0.01, z_hi=0.1):
    """`k` lightly damped conjugate root pairs, log-uniform in [f_lo, f_hi] Hz."""
    w = 2 * np.pi * np.exp(rng.uniform(np.log(f_lo), np.log(f_hi), k))
    z = rng.uniform(z_lo, z_hi, k)
    upper = w * (-z + 1j * np.sqrt(1 - z**2))
    return np.concatenate([upper, np.conj(upper)])


def _roots(rng, n):
    roots = _pairs(rng, n // 2)
    if n % 2:
        roots = np.concatenate([roots, [-2 * np.pi * rng.uniform(5.0, 500.0)]])
    return roots


def _system(nb, na, seed):
    """Stable (nb, na) system with known poles and zeros; num, den highest power first."""
    rng = np.random.default_rng(seed)
    poles, zeros = _roots(rng, na), _roots(rng, nb)
    den = np.real(np.poly(poles))
    num = np.atleast_1d(np.real(np.poly(zeros)))
    num = num * den[-1] / num[-1] * rng.uniform(0.5, 2.0)  # static gain in [0.5, 2]
    return num, den, poles, zeros


def _response(num, den, omega=OMEGA):
    return sig.freqs(num, den, omega)[1]  # independent oracle: scipy.signal


def _noisy(h, rel, seed):
    """Complex Gaussian noise of standard deviation `rel * |h|` (1 % = 0.01)."""
    rng = np.random.default_rng(seed)
    e = (rng.normal(size=h.shape) + 1j * rng.normal(size=h.shape)) / np.sqrt(2)
    return h + rel * np.abs(h) * e


def _family(order, seeds, rel, noise_seed=None):
    """Noisy responses of the systems `_system(*order, seed)`, stacked `(len(seeds), freq)`."""
    rows = []
    for i, s in enumerate(seeds):
        h0 = _response(*_system(*order, seed=s)[:2])
        rows.append(_noisy(h0, rel, i if noise_seed is None else noise_seed))
    return np.stack(rows)


def _match(found, truth):
    """Relative distance of each true root to the nearest found root."""
    found = np.asarray(found)
    return np.array([np.min(np.abs(found - t)) / np.abs(t) for t in truth])


def _rel(g, h):
    return np.linalg.norm(np.asarray(g) - h, axis=-1) / np.linalg.norm(h, axis=-1)


@pytest.mark.parametrize("order", [(2, 2), (4, 4), (6, 6), (3, 4)])
def test_noiseless_recovery(order):
    num, den, poles, zeros = _system(*order, seed=sum(order))
    h = _response(num, den)
    # rtol=1e-12: iterate to rounding level, so that the comparison below can be tight.
    model, report = jaxvs.fit_rational(OMEGA, h, order, rtol=1e-12)
    assert report.result == RESULTS.successful
    assert model.num.shape == (order[0] + 1,) and model.den.shape == (order[1] + 1,)
    assert float(model.den[0]) == 1.0  # monic by construction
    # Exact data: only rounding (float64, condition numbers <= 1e4 in scaled frequency)
    # separates the fit from the truth.
    assert _rel(jaxvs.frequency_response(model, OMEGA), h) < 1e-9
    assert np.max(_match(np.roots(np.asarray(model.den)), poles)) < 1e-8
    assert np.max(_match(np.roots(np.asarray(model.num)), zeros), initial=0.0) < 1e-8
    np.testing.assert_allclose(float(model.num[0]), num[0] / den[0], rtol=1e-8)
    assert float(report.relative_error) < 1e-9


def test_order_shorthand_and_dtype():
    num, den, *_ = _system(2, 2, seed=4)
    h = _response(num, den)
    m1, _ = jaxvs.fit_rational(OMEGA, h, (2, 2))
    m2, _ = jaxvs.fit_rational(OMEGA.astype(np.float32), h.astype(np.complex64), 2)
    assert m2.num.dtype == jnp.float64  # computed in float64 whatever the input precision
    # complex64 input carries ~1e-7 relative rounding, which moves the fit by as much.
    np.testing.assert_allclose(np.asarray(m2.den), np.asarray(m1.den), rtol=1e-5)


def test_noisy_recovery_within_noise_and_least_squares_optimum():
    order = (4, 4)
    num, den, poles, _ = _system(*order, seed=8)
    h0 = _response(num, den)
    h = _noisy(h0, 0.01, seed=0)
    model, report = jaxvs.fit_rational(OMEGA, h, order)
    g = np.asarray(jaxvs.frequency_response(model, OMEGA))
    # 1 % noise averaged over 300 points by 9 parameters: the fit is closer to the
    # noiseless response than the data (~1 %); 0.5 % leaves a factor ~3 of margin.
    assert _rel(g, h0) < 5e-3
    assert 0.5e-2 < float(report.relative_error) < 1.5e-2  # the residual is the noise
    # Poles of lightly damped modes are determined to ~1e-3 relative by these data.
    assert np.max(_match(np.roots(np.asarray(model.den)), poles)) < 5e-3
    # Independent oracle: scipy's MINPACK LM started at the truth reaches the same
    # least-squares optimum (same cost to 1e-6; the optimum is unique near the truth).
    w0 = float(report.frequency_scale)
    x = 1j * OMEGA / w0
    sc = w0 ** -np.arange(5, dtype=float)  # coefficient k (highest first) times w0^-k: in s/w0
    th0 = np.concatenate([num * sc, den[1:] * sc[1:]])

    def resid(th):
        g_ = np.polyval(th[:5], x) / np.polyval(np.concatenate([[1.0], th[5:]]), x)
        return np.concatenate([(g_ - h).real, (g_ - h).imag])

    ref = opt.least_squares(resid, th0, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    np.testing.assert_allclose(float(report.residual_norm) ** 2 / 2, ref.cost, rtol=1e-6)


@pytest.mark.slow
def test_covariance_matches_monte_carlo():
    # A (2, 2) TF with additive white noise of known standard deviation on the real and
    # imaginary parts: the setting in which σ² (JᵀJ)⁻¹ is the exact small-noise covariance.
    num, den, *_ = _system(2, 2, seed=12)
    h0 = _response(num, den)
    sigma = 0.01 * np.sqrt(np.mean(np.abs(h0) ** 2))
    rng = np.random.default_rng(3)
    n_mc = 128
    noise = sigma * (rng.normal(size=(n_mc, OMEGA.size)) + 1j * rng.normal(size=(n_mc, OMEGA.size)))
    model, report = jaxvs.fit_rational(OMEGA, h0 + noise, (2, 2))
    assert model.batch_shape == (n_mc,)
    assert bool(jnp.all(report.result == RESULTS.successful))
    theta = np.concatenate([np.asarray(model.num), np.asarray(model.den)[:, 1:]], axis=1)
    empirical = np.std(theta, axis=0, ddof=1)
    predicted = np.sqrt(np.mean(np.diagonal(np.asarray(report.covariance), axis1=1, axis2=2), 0))
    # 128 samples estimate a standard deviation to ~6 % (1/sqrt(2·127)); the linearised
    # covariance is exact up to O(noise) = 1 %; a factor 1.5 is > 5 sampling sigmas.
    ratio = empirical / predicted
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), ratio
    # The noise-variance estimate is σ² per real component (1 - 2·sqrt(2/600) ≈ ±12 %).
    np.testing.assert_allclose(np.mean(np.asarray(report.noise_variance)), sigma**2, rtol=0.1)
    # Standard errors are the square roots of the covariance diagonal, laid out as num/den.
    std = np.sqrt(np.diagonal(np.asarray(report.covariance), axis1=1, axis2=2))
    np.testing.assert_allclose(np.asarray(report.num_stderr), std[:, :3], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(report.den_stderr)[:, 1:], std[:, 3:], rtol=1e-12)
    assert np.all(np.asarray(report.den_stderr)[:, 0] == 0)


def test_covariance_matches_finite_difference_jacobian():
    num, den, *_ = _system(2, 2, seed=12)
    h = _noisy(_response(num, den), 0.01, seed=5)
    model, report = jaxvs.fit_rational(OMEGA, h, (2, 2))
    theta = np.concatenate([np.asarray(model.num), np.asarray(model.den)[1:]])

    def resid(th):
        g = _response(th[:3], np.concatenate([[1.0], th[3:]]))
        return np.concatenate([(g - h).real, (g - h).imag])

    # Central differences with relative steps (the coefficients span ~10 decades).
    cols = []
    for i in range(theta.size):
        d = np.zeros_like(theta)
        d[i] = 1e-6 * abs(theta[i])
        cols.append((resid(theta + d) - resid(theta - d)) / (2 * d[i]))
    jac = np.stack(cols, axis=1)
    r = resid(theta)
    sigma2 = r @ r / (r.size - theta.size)
    scale = np.abs(theta)
    js = jac * scale
    cov = np.linalg.inv(js.T @ js) * sigma2 * np.outer(scale, scale)  # (JᵀJ)⁻¹ = S (JsᵀJs)⁻¹ S
    # Finite differences carry ~1e-8 relative error; the covariance inherits ~1e-5.
    np.testing.assert_allclose(np.asarray(report.covariance), cov, rtol=1e-4)
    np.testing.assert_allclose(float(report.noise_variance), sigma2, rtol=1e-8)


def test_batched_equals_loop_of_single_fits():
    h = _family((4, 4), range(20, 25), 0.01)
    w = 1.0 / np.abs(h)  # per-member weights (*batch, freq)
    # rtol=1e-12: both iterate to the optimum up to rounding.
    model, report = jaxvs.fit_rational(OMEGA, h, (4, 4), weights=w, rtol=1e-12)
    for i in range(5):
        m_i, r_i = jaxvs.fit_rational(OMEGA, h[i], (4, 4), weights=w[i], rtol=1e-12)
        # Same algorithm, same data; vectorised code rounds differently, which can move
        # the last accepted step: the optimum agrees to ~1e-8 relative (cf. test_initial_guess).
        np.testing.assert_allclose(np.asarray(model.den[i]), np.asarray(m_i.den), rtol=1e-7)
        np.testing.assert_allclose(np.asarray(model.num[i]), np.asarray(m_i.num), rtol=1e-7)


@pytest.mark.slow
def test_family_with_compaction_equals_loop_and_keeps_batch_shape():
    # 2 x 20 = 40 members > one block (16): exercises the sweep and the gather/scatter rounds.
    keys = [(i, j) for i in range(2) for j in range(20)]
    h = _family((4, 4), range(40, 80), 0.01, noise_seed=9)
    model, report = jaxvs.fit_rational(OMEGA, h.reshape(2, 20, -1), (4, 4), rtol=1e-12)
    assert model.batch_shape == (2, 20) and report.covariance.shape == (2, 20, 9, 9)
    for k in (0, 17, 33, 39):
        i, j = keys[k]
        m_k, _ = jaxvs.fit_rational(OMEGA, h[k], (4, 4), rtol=1e-12)
        # As in test_batched_equals_loop_of_single_fits.
        np.testing.assert_allclose(np.asarray(model.den[i, j]), np.asarray(m_k.den), rtol=1e-7)


def test_batched_while_compaction_matches_per_member_loop():
    # Newton's iteration for sqrt(a) needs a member-dependent number of steps.
    a = jnp.asarray(np.geomspace(1e-6, 1e6, 13))

    def cond(s, a_):
        return jnp.abs(s[0] ** 2 - a_) > 1e-12 * a_

    def body(s, a_):
        return (0.5 * (s[0] + a_ / s[0]), s[1] + 1)

    x0 = (jnp.ones_like(a), jnp.zeros(a.shape, int))
    x, k = batched_while(cond, body, x0, a, block=3, first_steps=4, tail_block=2, block_steps=2)
    np.testing.assert_allclose(np.asarray(x), np.sqrt(np.asarray(a)), rtol=1e-11)
    for i in range(a.size):
        ref = jax.lax.while_loop(lambda s: cond(s, a[i]), lambda s: body(s, a[i]), (1.0, 0))
        assert int(k[i]) == int(ref[1])  # the same number of steps as alone


def test_results_are_stable_for_stable_data():
    # Single fits (the (6, 6) solver compiled by test_noiseless_recovery is reused).
    for h in _family((6, 6), range(60, 65), 0.02):
        model, _ = jaxvs.fit_rational(OMEGA, h, (6, 6), throw=False)
        assert np.all(np.roots(np.asarray(model.den)).real < 0)  # oracle: numpy roots


def _unstable_data():
    w1, w2 = 2 * np.pi * 30, 2 * np.pi * 200
    den = np.polymul([1, -2 * 0.05 * w1, w1**2], [1, 2 * 0.03 * w2, w2**2])  # RHP pair
    num = np.polymul([1, 0.26 * w1, (1.3 * w1) ** 2], [0.5, 0.04 * w2, 0.32 * w2**2])
    return num, den, _response(num, den)


def test_unstable_data_flagged_refused_and_fitted_with_stable_false():
    num, den, h = _unstable_data()
    model, report = jaxvs.fit_rational(OMEGA, h, (4, 4), throw=False)
    assert report.result == RESULTS.unstable_data and bool(report.flipped)
    assert np.all(np.roots(np.asarray(model.den)).real < 0)  # still a stable model
    with pytest.raises(eqx.EquinoxRuntimeError, match="response of an unstable system"):
        jaxvs.fit_rational(OMEGA, h, (4, 4))
    model, report = jaxvs.fit_rational(OMEGA, h, (4, 4), stable=False)
    # Exact data: the unconstrained fit recovers the right-half-plane poles.
    assert np.max(_match(np.roots(np.asarray(model.den)), np.roots(den))) < 1e-8


def test_initial_guess():
    num, den, *_ = _system(4, 4, seed=8)
    h = _noisy(_response(num, den), 0.01, seed=0)
    ref, _ = jaxvs.fit_rational(OMEGA, h, (4, 4), rtol=1e-12)
    init = jaxvs.RationalTF(num, den)
    model, report = jaxvs.fit_rational(OMEGA, h, (4, 4), init=init, rtol=1e-12)
    assert int(report.num_init_steps) == 0
    # Both stop within sqrt(rtol · 2 n_freq) ≈ 2e-5 standard errors (~1e-3 relative here)
    # of the same least-squares optimum: ~2e-8 relative.
    np.testing.assert_allclose(np.asarray(model.den), np.asarray(ref.den), rtol=1e-7)
    bad = np.polymul([1, -10.0, 1e4], [1, 50.0, 1e6])  # a right-half-plane pair
    _, report = jaxvs.fit_rational(OMEGA, h, (4, 4), init=jaxvs.RationalTF(num, bad), throw=False)
    assert report.result == RESULTS.unstable_initial_guess
    with pytest.raises(eqx.EquinoxRuntimeError, match="initial guess has poles in the right"):
        jaxvs.fit_rational(OMEGA, h, (4, 4), init=jaxvs.RationalTF(num, bad))
    with pytest.raises(ValueError, match="init has orders"):
        jaxvs.fit_rational(OMEGA, h, (4, 4), init=jaxvs.RationalTF(num[1:], den))


def test_weights_zero_drops_points_and_scale_is_irrelevant():
    num, den, poles, _ = _system(4, 4, seed=8)
    h = _response(num, den)
    corrupted = h.copy()
    corrupted[::7] *= 3.0
    w = np.ones_like(OMEGA)
    w[::7] = 0.0
    model, report = jaxvs.fit_rational(OMEGA, corrupted, (4, 4), weights=5.0 * w)
    # Zero-weight points do not enter the fit: the exact system is recovered.
    assert np.max(_match(np.roots(np.asarray(model.den)), poles)) < 1e-8
    assert float(report.relative_error) < 1e-9


def test_jit_and_errors_under_jit():
    num, den, *_ = _system(2, 2, seed=4)
    h = _response(num, den)
    eager, _ = jaxvs.fit_rational(OMEGA, h, (2, 2))
    jitted = eqx.filter_jit(lambda hh: jaxvs.fit_rational(OMEGA, hh, (2, 2)))
    model, report = jitted(jnp.asarray(h))
    np.testing.assert_allclose(np.asarray(model.den), np.asarray(eager.den), rtol=1e-12)
    with pytest.raises(eqx.EquinoxRuntimeError, match="H contains NaN or inf"):
        jitted(jnp.asarray(h).at[3].set(jnp.nan))


def test_bad_input():
    num, den, *_ = _system(2, 2, seed=4)
    h = _response(num, den)
    first = r"H has 180 non-finite value\(s\), the first at index \(120,\)"
    with pytest.raises(ValueError, match=first):
        jaxvs.fit_rational(OMEGA, np.where(OMEGA > 100, np.inf, h), (2, 2))
    with pytest.raises(ValueError, match=r"omega has 180 non-finite value"):
        jaxvs.fit_rational(np.where(OMEGA > 100, np.nan, OMEGA), h, (2, 2))
    with pytest.raises(ValueError, match=r"weights has \d+ non-finite value"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), weights=np.full(OMEGA.shape, np.nan))
    with pytest.raises(ValueError, match="cannot determine 5 parameters"):
        jaxvs.fit_rational(OMEGA[:4], h[:4], (2, 2))
    with pytest.raises(ValueError, match="does not match omega"):
        jaxvs.fit_rational(OMEGA, h[:-1], (2, 2))
    with pytest.raises(ValueError, match="must be 1-D"):
        jaxvs.fit_rational(OMEGA[None], h, (2, 2))
    with pytest.raises(ValueError, match="do not broadcast"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), weights=np.ones(7))
    with pytest.raises(ValueError, match="weights must be non-negative"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), weights=-np.ones_like(OMEGA))
    with pytest.raises(TypeError, match="weights must be real"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), weights=np.ones_like(h))
    with pytest.raises(ValueError, match="improper"):
        jaxvs.fit_rational(OMEGA, h, (3, 2))
    with pytest.raises(ValueError, match="needs na >= 1"):
        jaxvs.fit_rational(OMEGA, h, (0, 0))
    with pytest.raises(TypeError, match="pair of integers"):
        jaxvs.fit_rational(OMEGA, h, (2.5, 3))
    with pytest.raises(TypeError, match="complex frequency response"):
        jaxvs.fit_rational(OMEGA, np.abs(h), (2, 2))
    with pytest.raises(TypeError, match="real angular frequency"):
        jaxvs.fit_rational(OMEGA + 0j, h, (2, 2))
    with pytest.raises(ValueError, match="omega must be >= 0"):
        jaxvs.fit_rational(-OMEGA, h, (2, 2))
    with pytest.raises(TypeError, match="init must be a RationalTF"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), init=(num, den))
    pair = jaxvs.RationalTF(np.stack([num] * 2), np.stack([den] * 2))
    with pytest.raises(ValueError, match="init has batch shape"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), init=pair)
    with jax.enable_x64(False):
        with pytest.raises(ValueError, match="needs float64"):
            jaxvs.fit_rational(OMEGA, h, (2, 2))


def test_throw_on_non_convergence_and_result_codes():
    num, den, *_ = _system(2, 2, seed=4)
    h = _noisy(_response(num, den), 0.01, seed=1)
    # rtol=0 can never be met: the step limit decides.
    with pytest.raises(eqx.EquinoxRuntimeError, match="maximum number of Levenberg-Marquardt"):
        jaxvs.fit_rational(OMEGA, h, (2, 2), max_steps=2, rtol=0.0)
    _, report = jaxvs.fit_rational(OMEGA, h, (2, 2), max_steps=2, rtol=0.0, throw=False)
    assert report.result == RESULTS.max_steps_reached and int(report.num_steps) == 2
    # Overflowing data (|H|² = inf) cannot be fitted.
    _, report = jaxvs.fit_rational(OMEGA, h * 1e200, (2, 2), throw=False)
    assert report.result == RESULTS.nonfinite
    with pytest.raises(eqx.EquinoxRuntimeError, match="Non-finite values"):
        jaxvs.fit_rational(OMEGA, h * 1e200, (2, 2))


def test_overparametrised_exact_data_is_singular():
    num, den, *_ = _system(2, 2, seed=4)
    h = _response(num, den)
    model, report = jaxvs.fit_rational(OMEGA, h, (4, 4), throw=False)
    # A (4, 4) model of (2, 2) data has a free cancelling pole-zero pair: the response is
    # exact but the parameters are not identifiable.
    assert report.result == RESULTS.singular
    assert _rel(jaxvs.frequency_response(model, OMEGA), h) < 1e-8
    with pytest.raises(eqx.EquinoxRuntimeError, match="not identifiable"):
        jaxvs.fit_rational(OMEGA, h, (4, 4))


def test_fit_report_summary_is_readable():
    """FitReport prints its result by name (not `RESULTS<>`) and its figures."""
    omega = jnp.linspace(1.0, 100.0, 200)
    H = jaxvs.frequency_response(jaxvs.RationalTF([1.0, 2.0], [1.0, 3.0, 50.0]), omega)
    _, report = jaxvs.fit_rational(omega, H, (1, 2))
    text = report.summary()
    assert text.startswith("result: successful") and "relative error" in text
    assert "RESULTS<" not in text
