"""Resampling, zero-phase low-pass filtering, decimation and numerical differentiation.

Oracles: scipy.signal (filtfilt, sosfiltfilt, decimate, butter), numpy (interp, gradient),
scipy.interpolate.interp1d, the Butterworth magnitude at the cut-off (closed form), and
closed-form derivatives of sines, ramps and polynomials.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.interpolate as si
import scipy.signal as ss
from jax.test_util import check_grads

from jaxvs.data import Record
from jaxvs.signal import decimate, differentiate, filtfilt_lowpass, resample

FS = 1000.0
DT = 1 / FS


@pytest.fixture
def rng():
    return np.random.default_rng(20241121)


# ---------------------------------------------------------------------------------------
# filtfilt_lowpass
# ---------------------------------------------------------------------------------------


def test_filtfilt_matches_scipy_filtfilt(rng):
    x = rng.standard_normal((3, 2, 1500)) + np.linspace(0, 4, 1500)  # offset + ramp ends
    b, a = ss.butter(4, 50.0, fs=FS)
    expected = ss.filtfilt(b, a, x)
    got = filtfilt_lowpass(x, FS, 50.0)
    assert got.shape == x.shape
    # 1e-10: both are forward-backward Butterworth with identical padding and initial
    # conditions; they differ only in round-off ((b, a) vs second-order sections, ~1e-12).
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


@pytest.mark.parametrize("order", [1, 2, 5])
def test_filtfilt_matches_sosfiltfilt_padlen_axis(rng, order):
    x = rng.standard_normal((700, 3))
    sos = ss.butter(order, 2.0, fs=FS, output="sos")  # cutoff/fs = 2e-3: (b, a) loses digits
    expected = ss.sosfiltfilt(sos, x, axis=0, padlen=200)
    got = filtfilt_lowpass(x, FS, 2.0, order=order, padlen=200, axis=0)
    # 1e-12: same sections, same recursion; only the summation order differs.
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_filtfilt_half_power_at_cutoff():
    # Closed form: a digital Butterworth has |H(f_c)|² = 1/2, and forward-backward filtering
    # squares the magnitude, so a sine at the cut-off comes out with amplitude 1/2, in phase.
    t = np.arange(20000) * DT
    fc = 37.0
    y = np.asarray(filtfilt_lowpass(np.sin(2 * np.pi * fc * t), FS, fc))
    inner = slice(2000, -2000)  # away from the end transients
    basis = np.stack([np.sin(2 * np.pi * fc * t), np.cos(2 * np.pi * fc * t)], axis=1)
    (in_phase, quadrature), *_ = np.linalg.lstsq(basis[inner], y[inner], rcond=None)
    # 1e-6: steady state is exact; the residual transient 2000 samples in is < 1e-6.
    assert abs(in_phase - 0.5) < 1e-6
    assert abs(quadrature) < 1e-6  # zero phase


def test_filtfilt_jit_vmap_grad_float32(rng):
    x = rng.standard_normal((4, 300))
    eager = filtfilt_lowpass(x, FS, 80.0)
    jitted = jax.jit(lambda v: filtfilt_lowpass(v, FS, 80.0))(x)
    mapped = jax.vmap(lambda v: filtfilt_lowpass(v, FS, 80.0))(x)
    # 1e-13: the same operations compiled differently (round-off only).
    np.testing.assert_allclose(jitted, eager, rtol=0, atol=1e-13)
    np.testing.assert_allclose(mapped, eager, rtol=0, atol=1e-13)
    # Gradients of a linear filter against finite differences (check_grads defaults for
    # float64: the filter is linear, so central differences are exact up to round-off).
    check_grads(
        jax.jit(lambda v: jnp.sum(filtfilt_lowpass(v, FS, 80.0) ** 2)),
        (x[0, :40],),
        1,
        modes=("rev",),
    )
    assert filtfilt_lowpass(x.astype(np.float32), FS, 80.0).dtype == jnp.float32


def test_filtfilt_errors(rng):
    x = rng.standard_normal(100)
    with pytest.raises(ValueError, match="below the Nyquist frequency"):
        filtfilt_lowpass(x, FS, 600.0)
    with pytest.raises(ValueError, match="cutoff must be a positive finite"):
        filtfilt_lowpass(x, FS, -1.0)
    with pytest.raises(ValueError, match="fs must be a positive finite"):
        filtfilt_lowpass(x, 0.0, 10.0)
    with pytest.raises(ValueError, match="order must be a positive integer"):
        filtfilt_lowpass(x, FS, 10.0, order=0)
    with pytest.raises(TypeError, match="order must be a positive integer"):
        filtfilt_lowpass(x, FS, 10.0, order=2.5)
    with pytest.raises(ValueError, match="padlen must be a non-negative integer"):
        filtfilt_lowpass(x, FS, 10.0, padlen=-1)
    with pytest.raises(ValueError, match="needs more than 15"):
        filtfilt_lowpass(x[:15], FS, 10.0)
    with pytest.raises(ValueError, match="got a scalar"):
        filtfilt_lowpass(1.0, FS, 10.0)
    with pytest.raises(ValueError, match="axis=2 is out of range"):
        filtfilt_lowpass(x, FS, 10.0, axis=2)
    with pytest.raises(TypeError, match="must be a real signal"):
        filtfilt_lowpass(x + 1j, FS, 10.0)
    with pytest.raises(TypeError, match="concrete Python number"):
        jax.jit(lambda v, c: filtfilt_lowpass(v, FS, c))(x, 10.0)
    bad = x.copy()
    bad[42] = np.nan
    with pytest.raises(ValueError, match=r"first at index \(42,\)"):
        filtfilt_lowpass(bad, FS, 10.0)
    with pytest.raises(eqx.EquinoxRuntimeError, match="NaN or inf"):
        eqx.filter_jit(lambda v: filtfilt_lowpass(v, FS, 10.0))(bad)


# ---------------------------------------------------------------------------------------
# decimate
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("zero_phase", [True, False])
@pytest.mark.parametrize("factor", [2, 5, 13])
def test_decimate_matches_scipy(rng, factor, zero_phase):
    x = rng.standard_normal((2, 1001)) + 3.0
    expected = ss.decimate(x, factor, zero_phase=zero_phase)
    got = decimate(x, factor, zero_phase=zero_phase)
    assert got.shape == expected.shape == (2, -(-1001 // factor))
    # 1e-11: same Chebyshev sections and padding as scipy; round-off only.
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-11)


def test_decimate_axis_jit_identity(rng):
    x = rng.standard_normal((400, 2))
    expected = ss.decimate(x, 4, axis=0)
    got = jax.jit(lambda v: decimate(v, 4, axis=0))(x)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-11)  # round-off only
    np.testing.assert_array_equal(decimate(x, 1, axis=0), x)  # factor 1: documented no-op


def test_decimate_errors(rng):
    x = rng.standard_normal(100)
    with pytest.raises(ValueError, match="factor must be a positive integer"):
        decimate(x, 0)
    with pytest.raises(TypeError, match="factor must be a positive integer"):
        decimate(x, 2.0)
    with pytest.raises(ValueError, match="needs more than 27"):
        decimate(x[:20], 2)
    bad = x.copy()
    bad[3] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        decimate(bad, 2)


# ---------------------------------------------------------------------------------------
# differentiate
# ---------------------------------------------------------------------------------------


def _sine(n=2001, f0=3.0, phase=0.4):
    t = np.arange(n) * DT
    w = 2 * np.pi * f0
    x = np.sin(w * t + phase) + 0.5 * t
    return t, w, x, w * np.cos(w * t + phase) + 0.5, -(w**2) * np.sin(w * t + phase)


def test_central_matches_numpy_gradient(rng):
    x = rng.standard_normal((3, 50))
    # 1e-12: identical stencils (numpy.gradient with edge_order=2), round-off only.
    np.testing.assert_allclose(
        differentiate(x, 0.01), np.gradient(x, 0.01, axis=-1, edge_order=2), atol=1e-12
    )
    np.testing.assert_allclose(
        differentiate(x.T, 0.01, axis=0),
        np.gradient(x.T, 0.01, axis=0, edge_order=2),
        atol=1e-12,
    )


def test_central_on_sine_closed_form():
    _, w, x, d1, d2 = _sine()
    e1 = np.abs(differentiate(x, DT) - d1)
    e2 = np.abs(differentiate(x, DT, order=2) - d2)
    # Truncation errors (Fornberg 1988): inside h²ω³/6 and h²ω⁴/12; the one-sided ends
    # have twice (order 1: h²ω³/3) and 11× (order 2: 11h²ω⁴/12) the interior constant.
    h = DT
    assert e1[1:-1].max() <= 1.01 * h**2 * w**3 / 6
    assert e1.max() <= 1.01 * h**2 * w**3 / 3
    assert e2[1:-1].max() <= 1.01 * h**2 * w**4 / 12
    assert e2.max() <= 1.01 * 11 * h**2 * w**4 / 12


def test_central_exact_on_quadratic():
    t = np.arange(7) * 0.1
    x = 2 + 3 * t - 4 * t**2
    # Second-order stencils are exact for quadratics (round-off only: 1e-12).
    np.testing.assert_allclose(differentiate(x, 0.1), 3 - 8 * t, atol=1e-12)
    np.testing.assert_allclose(differentiate(x, 0.1, order=2), np.full(7, -8.0), atol=1e-11)


def test_spectral_on_sine_closed_form():
    _, w, x, d1, d2 = _sine()
    e1 = np.abs(differentiate(x, DT, method="spectral") - d1) / w
    e2 = np.abs(differentiate(x, DT, order=2, method="spectral") - d2) / w**2
    # Relative errors, measured 4e-6 / 2e-8 (order 1, ends / interior) and 8e-4 / 5e-8
    # (order 2): the end correction is a cubic fitted over 8 samples, so the ends are
    # limited by its curvature estimate; the interior is near spectral accuracy (central
    # differences: ~6e-5 inside). Bounds leave ~5× margin.
    assert e1.max() < 2e-5
    assert e1[20:-20].max() < 1e-7
    assert e2.max() < 4e-3
    assert e2[20:-20].max() < 3e-7


def test_spectral_exact_on_cubic_and_batch():
    t = np.arange(64) * 0.05
    x = np.stack([1 - t + 0.3 * t**3, 2 * t**2])
    # A cubic is removed exactly by the end correction (its 8-sample cubic fit is exact),
    # leaving a zero residual: round-off only (1e-9 relative to values ~ 30).
    np.testing.assert_allclose(
        differentiate(x, 0.05, method="spectral"),
        np.stack([-1 + 0.9 * t**2, 4 * t]),
        atol=1e-9,
    )
    np.testing.assert_allclose(
        differentiate(x.T, 0.05, order=2, method="spectral", axis=0),
        np.stack([1.8 * t, np.full_like(t, 4.0)], axis=1),
        atol=1e-8,
    )


def test_filter_then_differentiate_noisy_ramp_plus_sine(rng):
    t = np.arange(4000) * DT
    v, amplitude, w = 0.2, 0.01, 2 * np.pi * 2.0
    sigma = 1e-5  # encoder-like position noise [m]
    x = v * t + amplitude * np.sin(w * t) + sigma * rng.standard_normal(t.size)
    velocity = v + amplitude * w * np.cos(w * t)  # peak 0.33 m/s
    acceleration = -amplitude * w**2 * np.sin(w * t)  # peak 1.6 m/s²
    raw = np.abs(differentiate(x, DT) - velocity).max()
    filtered = filtfilt_lowpass(x, FS, 20.0, padlen=150)
    central = np.abs(differentiate(filtered, DT) - velocity).max()
    spectral = np.abs(differentiate(x, DT, method="spectral", cutoff=20.0) - velocity).max()
    # Raw central differences amplify the noise by ~1/(√2·dt): max error ≈ 4σ/(√2·dt)
    # ≈ 0.03 m/s (measured 0.025–0.08 over seeds). A 20 Hz low-pass leaves noise std
    # ≈ σ·2π·20·√(20/500)/√3 ≈ 1.5e-4 m/s; measured max 4e-4–2e-3 over the whole record
    # including ends. 5e-3 m/s = 1.5 % of the peak velocity.
    assert raw > 1e-2
    assert central < 5e-3
    assert spectral < 5e-3
    # Second derivative: noise std after the low-pass ≈ σ·(2π·20)²·0.2 ≈ 0.03 m/s²; the
    # bound 0.25 m/s² (15 % of the peak) covers the maximum over 4000 samples and ends
    # (measured 0.04–0.11).
    acc_central = np.abs(differentiate(filtered, DT, order=2) - acceleration).max()
    acc_spectral = np.abs(
        differentiate(x, DT, order=2, method="spectral", cutoff=20.0) - acceleration
    ).max()
    assert acc_central < 0.25
    assert acc_spectral < 0.25


def test_differentiate_jit_grad(rng):
    x = rng.standard_normal(40)
    for method in ("central", "spectral"):
        eager = differentiate(x, 0.1, method=method)
        jitted = jax.jit(lambda v, d: differentiate(v, d, method=method))(x, 0.1)
        np.testing.assert_allclose(jitted, eager, atol=1e-12)  # round-off only
        check_grads(
            jax.jit(lambda v: jnp.sum(differentiate(v, 0.1, method=method) ** 2)),
            (x,),
            1,
            modes=("rev",),
        )


def test_differentiate_errors(rng):
    x = rng.standard_normal(10)
    with pytest.raises(ValueError, match="method must be one of"):
        differentiate(x, 0.1, method="forward")
    with pytest.raises(ValueError, match="order must be 1 or 2"):
        differentiate(x, 0.1, order=3)
    with pytest.raises(ValueError, match="dt must be a positive finite"):
        differentiate(x, 0.0)
    with pytest.raises(TypeError, match="resample first"):
        differentiate(x, np.arange(10) * 0.1)
    with pytest.raises(ValueError, match="cutoff is only used by method='spectral'"):
        differentiate(x, 0.1, cutoff=1.0)
    with pytest.raises(ValueError, match="at least 4 samples"):
        differentiate(x[:3], 0.1, order=2)
    with pytest.raises(ValueError, match="at least 3 samples"):
        differentiate(x[:2], 0.1, method="spectral")
    with pytest.raises(ValueError, match="cutoff must be a positive finite"):
        differentiate(x, 0.1, method="spectral", cutoff=0.0)
    with pytest.raises(eqx.EquinoxRuntimeError, match="dt must be a positive"):
        eqx.filter_jit(differentiate)(x, jnp.asarray(-0.1))
    bad = x.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match=r"first at index \(5,\)"):
        differentiate(bad, 0.1)
    with pytest.raises(eqx.EquinoxRuntimeError, match="NaN or inf"):
        eqx.filter_jit(lambda v: differentiate(v, 0.1, method="spectral"))(bad)


# ---------------------------------------------------------------------------------------
# resample
# ---------------------------------------------------------------------------------------


def _jittered_time(rng, n=300):
    return np.cumsum(rng.uniform(0.5e-3, 1.5e-3, n)) + 0.2


def test_resample_linear_matches_numpy_interp(rng):
    t = _jittered_time(rng)
    x = rng.standard_normal((2, t.size))
    t_new, x_new = resample(t, x, dt=1e-3)
    assert t_new[0] == t[0] and t_new[-1] <= t[-1] < t_new[-1] + 1e-3
    np.testing.assert_allclose(np.diff(t_new), 1e-3, rtol=1e-9)  # uniform grid
    for row in range(2):
        # 1e-13: same linear interpolation; round-off only.
        np.testing.assert_allclose(x_new[row], np.interp(t_new, t, x[row]), atol=1e-13)


def test_resample_default_dt_is_median_and_keeps_uniform_samples():
    t = 0.1 + 0.002 * np.arange(11)
    t_new, x_new = resample(t, 3 * t - 1)
    # A uniform record maps onto itself (default dt = its spacing; last sample kept).
    np.testing.assert_allclose(t_new, t, atol=1e-15)
    np.testing.assert_allclose(x_new, 3 * t - 1, atol=1e-14)
    t_gap = np.array([0.0, 1.0, 2.0, 3.0, 5.0, 6.0])  # one dropped sample: median dt = 1
    t_new, _ = resample(t_gap, t_gap)
    np.testing.assert_allclose(t_new, np.arange(7.0))


def test_resample_cubic_exact_on_cubic_and_accurate_on_sine(rng):
    t = np.sort(rng.uniform(0, 1, 40))
    t_new, x_new = resample(t, 1 - 2 * t + t**3, dt=0.01, method="cubic")
    # Not-a-knot splines reproduce cubics exactly (round-off only).
    np.testing.assert_allclose(x_new, 1 - 2 * t_new + t_new**3, atol=1e-12)
    t = _jittered_time(rng, 60) * 10  # sparse: h ≤ 15 ms, 5 Hz sine
    t_new, x_new = resample(t, np.sin(2 * np.pi * 5 * t), dt=1e-3, method="cubic")
    # Spline error ≤ (5/384)·h⁴·max|x''''| = (5/384)·(0.015)⁴·(2π·5)⁴ ≈ 6e-4 inside; the
    # not-a-knot ends are a few times worse, so 3e-3 (linear would give ~3e-2).
    assert np.abs(x_new - np.sin(2 * np.pi * 5 * t_new)).max() < 3e-3


def test_resample_previous_matches_interp1d(rng):
    t = _jittered_time(rng, 50)
    x = rng.integers(0, 5, (3, t.size)).astype(float).T  # step-wise signals, time first
    t_new, x_new = resample(t, x, dt=7e-4, method="previous", axis=0)
    expected = si.interp1d(t, x, kind="previous", axis=0)(t_new)
    np.testing.assert_array_equal(x_new, expected)  # exact: values are copied


def test_resample_extrapolate_holds_end_values():
    t = np.array([0.0, 1.0, 2.0])
    x = np.array([1.0, 3.0, 2.0])
    for method in ("linear", "cubic", "previous"):
        _, x_new = resample(t, x, t_new=[-1.0, 0.0, 2.0, 5.0], method=method, extrapolate=True)
        np.testing.assert_allclose(x_new[[0, 1]], 1.0)
        np.testing.assert_allclose(x_new[[2, 3]], 2.0)


def test_resample_feeds_record(rng):
    # The advertised workflow of jaxvs.data.Record for a jittered clock.
    t = _jittered_time(rng)
    with pytest.raises(ValueError, match="jaxvs.signal.resample"):
        Record({"q": np.sin(t)}, t=t)
    t_new, q = resample(t, np.sin(t), dt=1e-3)
    record = Record({"q": q}, t=t_new)
    assert record.dt == pytest.approx(1e-3, rel=1e-12)


def test_resample_errors(rng):
    t = np.array([0.0, 0.1, 0.3, 0.25, 0.4])
    x = np.arange(5.0)
    with pytest.raises(ValueError, match=r"not strictly increasing: t\[3\]"):
        resample(t, x)
    with pytest.raises(ValueError, match=r"not strictly increasing: t\[2\]"):
        resample(np.array([0.0, 1.0, 1.0]), x[:3])
    with pytest.raises(ValueError, match="at least 2 samples"):
        resample([0.0], [1.0])
    with pytest.raises(ValueError, match=r"t has 1 non-finite value\(s\), the first at index \(1,"):
        resample([0.0, np.nan, 1.0], x[:3])
    with pytest.raises(ValueError, match="x has 1 non-finite value"):
        resample([0.0, 0.5, 1.0], [0.0, np.nan, 1.0])
    with pytest.raises(ValueError, match="outside the data range"):
        resample([0.0, 1.0], [0.0, 1.0], t_new=[0.5, 1.5])
    with pytest.raises(ValueError, match="either dt=... or t_new"):
        resample([0.0, 1.0], [0.0, 1.0], dt=0.1, t_new=[0.5])
    with pytest.raises(ValueError, match="dt must be a positive finite"):
        resample([0.0, 1.0], [0.0, 1.0], dt=-0.1)
    with pytest.raises(ValueError, match="method must be one of"):
        resample([0.0, 1.0], [0.0, 1.0], method="quadratic")
    with pytest.raises(ValueError, match="t has 2 samples but x has 3"):
        resample([0.0, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="1-D time vector"):
        resample(np.zeros((2, 2)), [0.0, 1.0])
    with pytest.raises(TypeError, match="x must be real"):
        resample([0.0, 1.0], [0.0, 1j])


def test_block_bootstrap_means_are_the_means_of_the_indexed_resamples():
    # The cumulative-sum form and the explicit resamples draw the same blocks from the
    # same generator state; they differ only by the order of the additions (1e-12).
    from jaxvs.signal import block_bootstrap_indices, block_bootstrap_means

    x = np.random.default_rng(0).normal(size=(3, 103))  # 103 = 10 blocks of 10 + 3
    idx = block_bootstrap_indices(103, 10, 50, np.random.default_rng(1))
    means = block_bootstrap_means(x, 10, 50, np.random.default_rng(1))
    assert means.shape == (3, 50)
    np.testing.assert_allclose(means, x[:, idx].mean(axis=-1), rtol=1e-12, atol=1e-12)
