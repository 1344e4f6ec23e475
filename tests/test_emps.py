"""IDIM-LS (`jaxvs.studies.idim_ls`): synthetic recovery, LS oracle, bad input, and the
reproduction of the published EMPS results (Janot, Gautier, Brunot 2019, §3.4)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxvs
from jaxvs.data import Record, load_emps
from jaxvs.studies import ForcePrediction, IDIMResult, idim_ls, idim_regressor, predict_force

DT = 1e-3
TRUE = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}
TRUE_ASYM = {"M": 95.0, "Fv_pos": 170.0, "Fc_pos": 20.0, "Fv_neg": 240.0, "Fc_neg": 21.0}


def _trajectory(n: int = 20_000):
    """A smooth back-and-forth motion (two sines, 0.25 Hz and 0.65 Hz) with its exact
    derivatives; starts/ends mid-stroke so no sample lands on a velocity zero exactly."""
    t = np.arange(n) * DT
    w1, w2 = 2 * np.pi * 0.25, 2 * np.pi * 0.65
    q = 0.1 * np.sin(w1 * t + 0.3) + 0.03 * np.sin(w2 * t + 1.1)
    dq = 0.1 * w1 * np.cos(w1 * t + 0.3) + 0.03 * w2 * np.cos(w2 * t + 1.1)
    ddq = -0.1 * w1**2 * np.sin(w1 * t + 0.3) - 0.03 * w2**2 * np.sin(w2 * t + 1.1)
    return t, q, dq, ddq


def _synthetic(friction: str = "coulomb_viscous", noise: float = 0.0, seed: int = 0) -> Record:
    _, q, dq, ddq = _trajectory()
    if friction == "coulomb_viscous":
        p = TRUE
        u = p["M"] * ddq + p["Fv"] * dq + p["Fc"] * np.sign(dq) + p["offset"]
    else:
        p = TRUE_ASYM
        pos, neg = dq > 0, dq < 0
        u = (
            p["M"] * ddq
            + pos * (p["Fv_pos"] * dq + p["Fc_pos"])
            + neg * (p["Fv_neg"] * dq - p["Fc_neg"])
        )
    u = u + noise * np.random.default_rng(seed).standard_normal(u.shape)
    return Record({"q": q, "u": u}, dt=DT, units={"q": "m", "u": "N"})


@pytest.mark.parametrize("friction", ["coulomb_viscous", "asymmetric"])
def test_synthetic_recovery(friction):
    result = idim_ls(_synthetic(friction), friction=friction)
    assert isinstance(result, IDIMResult)
    truth = TRUE if friction == "coulomb_viscous" else TRUE_ASYM
    assert result.names == tuple(truth)
    for name, value in truth.items():
        # Only error sources: central differences, O((ω·dt)²/6) ≈ 3e-6 relative on q̇, q̈ at
        # 0.65 Hz, the 200 Hz Butterworth (gain 1 − 1e-17 at 1 Hz) and the residue of its
        # edge transient (q̈ off by ≤ 2e-3 m/s² at the first kept samples). Measured
        # ≤ 1e-5 relative; 1e-4 leaves room, while keeping the edge transient (edge_samples=0)
        # gives ≈ 2e-3 and any lag or scaling bias ≥ 1e-2.
        assert result[name] == pytest.approx(value, rel=1e-4), name
    # Noise-free data: the fit is nearly exact (measured 3e-5; same error sources).
    assert float(result.relative_error) < 3e-4
    assert result.regressor.shape == (result.force.shape[0], len(truth))
    assert set(result.params) == set(truth)
    assert result.units["M"] == "kg"


def test_synthetic_noisy_within_standard_errors():
    result = idim_ls(_synthetic(noise=5.0, seed=3))
    for name, value in TRUE.items():
        # Unbiased LS (white noise, regressors from the noise-free position): each estimate
        # lies within 5 standard errors of the truth (fails with probability < 1e-5 per
        # parameter if σ̂²(ΦᵀΦ)⁻¹ is right; the decimation filter correlates the noise a
        # little, hence 5σ not 3σ).
        std = float(result.std_errors[result.names.index(name)])
        assert abs(float(result[name]) - value) < 5 * std, name


def test_least_squares_matches_numpy_oracle():
    result = idim_ls(_synthetic(noise=2.0, seed=1))
    phi = np.asarray(result.regressor)
    y = np.asarray(result.force)
    theta, *_ = np.linalg.lstsq(phi, y, rcond=None)
    e = y - phi @ theta
    n, p = phi.shape
    sigma2 = e @ e / (n - p)
    cov = sigma2 * np.linalg.inv(phi.T @ phi)
    # Same well-conditioned LS problem (cond ≈ 30) solved by SVD vs LAPACK gelsd and an
    # explicit inverse: agreement to ~1e-12 relative; 1e-9 for platform differences.
    np.testing.assert_allclose(np.asarray(result.values), theta, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(result.covariance), cov, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(result.std_errors), np.sqrt(np.diag(cov)), rtol=1e-9)
    assert float(result.relative_error) == pytest.approx(
        np.linalg.norm(e) / np.linalg.norm(y), rel=1e-9
    )
    assert float(result.sigma) == pytest.approx(np.sqrt(sigma2), rel=1e-9)
    assert float(result.condition_number) == pytest.approx(np.linalg.cond(phi), rel=1e-9)


def test_predict_force_on_fit_record_matches_fit():
    record = _synthetic(noise=2.0, seed=2)
    result = idim_ls(record)
    prediction = predict_force(result, record)
    assert isinstance(prediction, ForcePrediction)
    # Same record, same preprocessing: identical regressor, so identical numbers (1e-12:
    # float round-off only).
    np.testing.assert_allclose(prediction.predicted, result.predicted, rtol=1e-12, atol=1e-9)
    assert float(prediction.relative_error) == pytest.approx(
        float(result.relative_error), rel=1e-12
    )
    assert prediction.t.shape == prediction.force.shape


def test_regressor_columns_closed_form():
    # q = A sin(ωt): filtered (200 Hz ≫ 0.5 Hz) and differentiated, without decimation,
    # the velocity column must be Aω cos(ωt) and the acceleration column −Aω² sin(ωt).
    t = np.arange(10_000) * DT
    w = 2 * np.pi * 0.5
    record = Record({"q": 0.1 * np.sin(w * t), "u": np.zeros_like(t)}, dt=DT)
    phi, y, t_out = idim_regressor(record, decimation=1, edge_samples=0)
    inner = slice(500, -500)  # away from filtfilt's edge transients
    tt = t[1:-1][inner]
    # Central differences: relative error (ω·dt)²/6 ≈ 1.6e-6 (q̇) and /12 (q̈); tolerance
    # 1e-5 of the amplitude covers them and the Butterworth passband ripple (< 1e-15).
    np.testing.assert_allclose(phi[inner, 1], 0.1 * w * np.cos(w * tt), atol=1e-5 * 0.1 * w)
    np.testing.assert_allclose(phi[inner, 0], -0.1 * w**2 * np.sin(w * tt), atol=1e-5 * 0.1 * w**2)
    np.testing.assert_array_equal(t_out, t[1:-1])
    assert y.shape == t_out.shape
    # Default edge trimming: 3 periods of the 200 Hz cut-off = 15 samples at each end.
    _, _, t_trim = idim_regressor(record, decimation=1)
    np.testing.assert_array_equal(t_trim, t[16:-16])


def test_edge_trimming_matters():
    # Mid-stroke start/end: without trimming, filtfilt's odd-reflection padding corrupts q̈
    # at the edges (relative force error measured 8e-3 and M off by 9e-5); with it, the
    # error is 3e-5. A factor 10 between them is the check.
    record = _synthetic()
    untrimmed = idim_ls(record, edge_samples=0, decimation=1)
    trimmed = idim_ls(record, decimation=1)
    assert float(trimmed.relative_error) < 0.1 * float(untrimmed.relative_error)


def test_least_squares_jit_grad():
    # The LS core is a pure JAX function: its estimate is differentiable w.r.t. the data.
    from jaxvs.studies.drive._idim import _least_squares

    result = idim_ls(_synthetic(noise=1.0))
    phi, y = result.regressor, result.force

    def mass(y):
        return _least_squares(phi, y)[0][0]

    g = jax.grad(mass)(y)
    # dθ/dy = (ΦᵀΦ)⁻¹Φᵀ, first row; closed-form oracle, round-off tolerance.
    expected = np.linalg.solve(np.asarray(phi).T @ np.asarray(phi), np.asarray(phi).T)[0]
    np.testing.assert_allclose(np.asarray(g), expected, rtol=1e-8, atol=1e-12)
    assert jnp.isfinite(g).all()


# ------------------------------------------------------------------------- bad input


def test_no_motion_raises():
    t = np.arange(5000) * DT
    still = Record({"q": 0.01 + 1e-9 * np.sin(t), "u": np.ones_like(t)}, dt=DT)
    with pytest.raises(ValueError, match="Friction is not identifiable"):
        idim_ls(still)
    # Moving in one direction only: Coulomb friction and offset are collinear.
    forward = Record({"q": 0.05 * t, "u": np.ones_like(t)}, dt=DT)
    with pytest.raises(ValueError, match="0 in − direction"):
        idim_ls(forward, friction="asymmetric")


def test_rank_deficient_raises():
    # With the motion check off, a still axis gives empty q̇, q̈ columns: rank deficient.
    t = np.arange(5000) * DT
    still = Record({"q": np.zeros_like(t), "u": np.ones_like(t)}, dt=DT)
    with pytest.raises(ValueError, match="rank deficient"):
        idim_ls(still, min_speed=None)


def test_missing_signals_raise():
    _, q, _, _ = _trajectory(5000)
    with pytest.raises(ValueError, match="no force signal 'u'"):
        idim_ls(Record({"q": q}, dt=DT))
    with pytest.raises(ValueError, match="no position signal 'q'"):
        idim_ls(Record({"x": q, "u": q}, dt=DT))
    # Other names are accepted through position=/force=.
    ok = idim_ls(Record({"x": q, "f": 100 * q + 50 * np.sign(np.gradient(q))}, dt=DT),
                 position="x", force="f")
    assert ok.names[0] == "M"
    with pytest.raises(TypeError, match="must be a jaxvs.data.Record"):
        idim_ls({"q": q, "u": q})  # type: ignore[arg-type]


def test_bad_options_raise():
    record = _synthetic()
    with pytest.raises(ValueError, match="friction must be one of"):
        idim_ls(record, friction="stribeck")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="Nyquist"):
        idim_ls(record, cutoff_hz=600.0)
    with pytest.raises(ValueError, match="decimation must be an integer"):
        idim_ls(record, decimation=0)
    with pytest.raises(ValueError, match="filter_order must be an integer"):
        idim_ls(record, filter_order=0)
    with pytest.raises(ValueError, match="edge_samples must be an integer"):
        idim_ls(record, edge_samples=-1)
    short = record.slice(0, 100)
    with pytest.raises(ValueError, match="needs at least"):
        idim_ls(short)
    with pytest.raises(TypeError, match="IDIMResult returned by idim_ls"):
        predict_force({"M": 1.0}, record)  # type: ignore[arg-type]
    with pytest.raises(KeyError, match="No parameter 'Fv_pos'"):
        idim_ls(record)["Fv_pos"]


# ------------------------------------------------------------------ EMPS reproduction

# Description §3.4 : the MATLAB Script_IDIM_LS output.
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
PUBLISHED_STD = {"M": 0.1085, "Fv": 1.1460, "Fc": 0.1012, "offset": 0.0444}
PUBLISHED_ASYM = {"M": 95.154, "Fv_pos": 166.71, "Fc_pos": 20.144, "Fv_neg": 240.42,
                  "Fc_neg": 20.628}


@pytest.fixture
def emps(shared_data):
    path = shared_data / "EMPS"
    return load_emps(path / "DATA_EMPS.mat"), load_emps(path / "DATA_EMPS_PULSES.mat")


@pytest.mark.slow
def test_emps_published_idim_ls(emps):
    estimation, validation = emps
    result = jaxvs.idim_ls(estimation)
    # 2 % as required by the issue; we get ≤ 0.15 % (the MATLAB and SciPy decimate filters
    # and edge handling differ, and the cut-off of the published script is not printed).
    for name in ("M", "Fv", "Fc"):
        assert float(result[name]) == pytest.approx(PUBLISHED[name], rel=0.02), name
    assert float(result["offset"]) == pytest.approx(PUBLISHED["offset"], abs=0.1)
    for name, std in PUBLISHED_STD.items():
        # Standard errors: same recipe ⇒ same σ̂²(ΦᵀΦ)⁻¹ up to a few % (measured 1.1-1.7 %); 5 %.
        assert float(result.std_errors[result.names.index(name)]) == pytest.approx(std, rel=0.05)
    # Published 4.0834 % and 5.9824 %; the issue allows ±0.3 percentage points.
    assert 100 * float(result.relative_error) == pytest.approx(4.08, abs=0.3)
    assert 100 * float(predict_force(result, validation).relative_error) == pytest.approx(
        5.98, abs=0.3
    )
    # Condition number of Φ: published 25.9883; 1 % (only filter details differ).
    assert float(result.condition_number) == pytest.approx(25.9883, rel=0.01)


@pytest.mark.slow
def test_emps_published_asymmetric(emps):
    estimation, _ = emps
    result = jaxvs.idim_ls(estimation, friction="asymmetric")
    for name, value in PUBLISHED_ASYM.items():
        # 2 % as required; measured ≤ 0.25 % for every parameter, Fv± included.
        assert float(result[name]) == pytest.approx(value, rel=0.02), name
    # Published 3.11 %; same ±0.3 percentage points as the symmetric model.
    assert 100 * float(result.relative_error) == pytest.approx(3.11, abs=0.3)
