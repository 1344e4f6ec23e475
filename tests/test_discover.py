"""Discovery of an effect outside the library, against independent oracles.

- The g-prior evidence against the marginal likelihood integrated numerically (the
  Gaussian likelihood with the prior covariance, σ² integrated under Jeffreys' prior).
- Backward elimination against the brute-force best subset of a small dictionary.
- The selection against pysindy's STLSQ on clean data.
- The coefficient intervals of the recalibrated formula: Monte Carlo coverage.
- End to end, on drive plants written here with scipy's `solve_ivp` (a carriage in a
  continuous PD position loop, nothing of jaxvs's models): a viscous friction that falls
  with time (in the dictionary, outside the library), no effect, and a local guideway
  bump (in neither).
"""

import itertools
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate as si
from benchmark_module import load_benchmark

from jaxvs.calibration import backward_elimination, log_evidence, stability_selection
from jaxvs.data import Record, split_blocks
from jaxvs.diagnosis import Discovered, GapModel, discover
from jaxvs.diagnosis._dictionary import DRIVE_NAMED, Member, _k_vexp, nearest_named
from jaxvs.diagnosis._discover import _covariance, _fit_formula, _split
from jaxvs.diagnosis._drive import DriveFamily, RigidNominal
from jaxvs.signal import bspline_basis, quantile_knots


def _numerical_log_bf(y_r, Xs, g):
    """log of `∫ N(y_r | 0, σ²(I + g P)) dσ²/σ²` over that with `P = 0`, by quadrature
    in `log σ²` (`y_r`, `Xs` already orthogonal to the base)."""
    m = y_r.size
    if Xs.shape[1]:
        q, _ = np.linalg.qr(Xs)
        cov = np.eye(m) + g * q @ q.T
    else:
        cov = np.eye(m)

    def log_ml(c):
        # the Gaussian log density at σ² = e^ls, from the covariance's log determinant
        # and quadratic form (numerically, not from the g-prior's algebra)
        logdet = np.linalg.slogdet(c)[1]
        quad_form = float(y_r @ np.linalg.solve(c, y_r))

        def logpdf(ls):
            return -0.5 * (m * (math.log(2 * math.pi) + ls) + logdet + quad_form / math.exp(ls))

        s2 = quad_form / m
        ref = logpdf(math.log(s2))
        val, _ = si.quad(lambda ls: math.exp(logpdf(ls) - ref), math.log(s2) - 8, math.log(s2) + 8)
        return ref + math.log(val)

    return log_ml(cov) - log_ml(np.eye(m))


def test_g_prior_evidence_equals_the_integrated_likelihood():
    rng = np.random.default_rng(1)
    n, g = 30, 30.0
    X = rng.normal(size=(n, 3))
    y = 0.8 * X[:, 0] + rng.normal(size=n) + 2.0
    # the base (an intercept) profiled out: an orthonormal basis of its complement
    q, _ = np.linalg.qr(np.column_stack([np.ones(n), rng.normal(size=(n, n - 1))]))
    comp = q[:, 1:]
    y_r, X_r = comp.T @ y, comp.T @ X
    for cols in [(0,), (0, 2), (1, 2)]:
        Xs = X_r[:, cols]
        beta, *_ = np.linalg.lstsq(Xs, y_r, rcond=None)
        ssr = float(np.sum((y_r - Xs @ beta) ** 2))
        ours = log_evidence(ssr, float(y_r @ y_r), n - 1, len(cols), g)
        assert ours == pytest.approx(_numerical_log_bf(y_r, Xs, g), abs=1e-6)


def _brute_force(X, y, base, n, margin=0.0):
    """The best subset by evidence (less `margin` per term), every subset fitted by
    `lstsq` with the base."""
    ssr0 = float(np.sum((y - base @ np.linalg.lstsq(base, y, rcond=None)[0]) ** 2))
    best = (-np.inf, ())
    for k in range(X.shape[1] + 1):
        for sub in itertools.combinations(range(X.shape[1]), k):
            A = np.column_stack([base, X[:, list(sub)]])
            r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
            ev = log_evidence(float(r @ r), ssr0, n - base.shape[1], k, n) - margin * k
            best = max(best, (ev, sub))
    return best


def test_backward_elimination_finds_the_best_subset_of_a_small_dictionary():
    rng = np.random.default_rng(3)
    n = 400
    x = rng.uniform(-1, 1, n)
    t = np.linspace(0, 1, n)
    X = np.column_stack([np.sign(x), np.tanh(x / 0.3), x * np.abs(x), x**3, t, np.sin(6 * x)])
    base = np.column_stack([np.ones(n), x])
    y = 1.0 + 2.0 * x + 0.7 * np.sign(x) + 0.5 * np.sin(6 * x) + 0.3 * rng.normal(size=n)
    ev, sub = _brute_force(X, y, base, n)
    sel = backward_elimination(X, y, base=base)
    assert sel.support == sub == (0, 5)
    assert sel.log_evidence == pytest.approx(ev, rel=1e-6)
    # a term must raise the log evidence by more than `margin` to stay: the best subset
    # of the evidence less `margin` per term (the weaker sine drops out at 100)
    for margin, expected in ((5.0, (0, 5)), (100.0, (0,))):
        _, sub_m = _brute_force(X, y, base, n, margin)
        assert backward_elimination(X, y, base=base, margin=margin).support == sub_m == expected
    # stability: every resample of a clean case keeps the same terms
    idx = rng.integers(0, n, size=(20, n))
    freq, _ = stability_selection(X, y, resamples=idx, base=base)
    assert freq[0] == 1.0 and freq[5] >= 0.6 and freq[[1, 2, 3, 4]].max() <= 0.4, freq


def test_selection_agrees_with_pysindy_stlsq_on_clean_data():
    ps = pytest.importorskip("pysindy")
    rng = np.random.default_rng(0)
    x = rng.uniform(-2, 2, 500)
    X = np.column_stack([x, x**2, x**3, np.sin(x), np.cos(x), np.tanh(x)])
    for true in [(1, 3), (0, 4), (2, 5)]:
        coef = np.zeros(6)
        coef[list(true)] = [1.5, -0.8]
        y = X @ coef + 1e-4 * rng.normal(size=x.size)
        opt = ps.STLSQ(threshold=0.1)
        opt.fit(X, y)
        # STLSQ's ridge (alpha 0.05) leaves crumbs of 1e-4 on removed columns
        sindy = tuple(np.flatnonzero(np.abs(opt.coef_[0]) > 0.01))
        ours = backward_elimination(X, y).support
        assert ours == sindy == true


def test_nearest_named_effect():
    assert nearest_named(["sign(v)"], DRIVE_NAMED) == ("coulomb_friction", True)
    assert nearest_named(["sign(v)", "stribeck"], DRIVE_NAMED) == ("stribeck_friction", True)
    assert nearest_named(["ripple"], DRIVE_NAMED) == ("position_dependence", True)
    assert nearest_named(["v·exp(-t/tau)"], DRIVE_NAMED) == (None, False)
    assert nearest_named(["ripple", "t"], DRIVE_NAMED) == ("position_dependence", False)


def test_bspline_basis_equals_scipy():
    from scipy.interpolate import BSpline

    x = np.random.default_rng(2).normal(size=300)
    knots = quantile_knots(x, 9)
    ours = np.asarray(jax.jit(bspline_basis)(jnp.asarray(x), jnp.asarray(knots)))
    ref = BSpline.design_matrix(x, knots, 3).toarray()
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    np.testing.assert_allclose(ours.sum(1), 1.0, atol=1e-12)


def _synthetic(rng, n, c, tau, sigma):
    """Arrays of a rigid axis with the force `c·v·exp(−t/τ)` and white noise (the data
    of the formula's recalibration, without preprocessing)."""
    t = np.arange(n) * 0.01
    v = 0.1 * np.sin(2 * np.pi * 0.3 * t) + 0.05 * np.sin(2 * np.pi * 1.1 * t)
    a = np.gradient(v, t)
    y = 10 * a + 60 * v + 2.0 + c * v * np.exp(-t / tau) + sigma * rng.normal(size=(n,))
    return {"t": t, "v": v, "a": a, "q": np.cumsum(v) * 0.01, "y": y, "u": y}


def test_formula_coefficient_intervals_cover_the_truth():
    """200 noisy records of one plant: the 95 % intervals of the coefficient and the time
    constant contain the truth in 91–99 % of them (binomial: ±2 sd of 200 draws)."""
    rng = np.random.default_rng(0)
    n, c, tau, sigma = 1500, 40.0, 6.0, 0.5
    member = Member(_k_vexp(), 5.0)
    model = GapModel(RigidNominal(jnp.asarray(10.0), jnp.asarray(60.0), jnp.asarray(2.0)))
    flat, unravel, static = _split(model)
    fns = ((member.kind.columns, 1, True, "add"),)
    hits = np.zeros(2)
    reps = 200
    for _ in range(reps):
        d = _synthetic(rng, n, c, tau, sigma)
        theta, _, jtj, r_w = _fit_formula(
            unravel(flat),
            static,
            {k: jnp.asarray(v)[None] for k, v in d.items()},
            jnp.asarray(d["y"])[None],
            jnp.ones((1, n)),
            (jnp.asarray([30.0]), jnp.asarray([math.log(5.0)])),
            (jnp.asarray([-jnp.inf]), jnp.asarray([jnp.inf])),
            fns,
            100,
        )
        theta, jtj, r_w = np.asarray(theta), np.asarray(jtj), np.asarray(r_w)
        cov = _covariance(jtj, r_w, np.ones(theta.size, bool), n, r_w)
        sd = np.sqrt(np.diag(cov))
        hits[0] += abs(theta[3] - c) <= 1.96 * sd[3]
        hits[1] += abs(theta[4] - math.log(tau)) <= 1.96 * sd[4]
    cover = hits / reps
    assert np.all(cover >= 0.91) and np.all(cover <= 0.99), cover


# ------------------------------------------------------------------------------ end to end

FS = 1000.0


def _ref(t):
    w = 2 * np.pi * np.array([0.23, 0.61, 1.37])
    amp, ph = 0.05 * np.array([0.6, 0.3, 0.1]), np.array([0.0, 1.0, 2.0])
    return (amp * np.sin(np.outer(t, w) + ph)).sum(-1), (amp * w * np.cos(np.outer(t, w) + ph)).sum(
        -1
    )


def _plant(extra, n=16000, M=10.0, Fv=60.0, off=2.0, noise=0.5, seed=0) -> Record:
    """A carriage (mass `M`, viscous `Fv`, offset `off`) in a continuous PD position loop
    (15 Hz), with the unknown force `extra(t, x, v)` [N], integrated by `solve_ivp`;
    the record holds the loop's force with white noise and a 1 µm encoder."""
    rng = np.random.default_rng(seed)
    wn = 2 * np.pi * 15
    kp, kd = M * wn**2, 2 * 0.7 * M * wn

    def rhs(t, s):
        r, dr = _ref(np.array([t]))
        u = kp * (r[0] - s[0]) + kd * (dr[0] - s[1])
        return [s[1], (u - Fv * s[1] - off - extra(t, s[0], s[1])) / M]

    t = np.arange(n) / FS
    r0, dr0 = _ref(np.zeros(1))
    sol = si.solve_ivp(rhs, (0, t[-1]), [r0[0], dr0[0]], t_eval=t, rtol=1e-8, atol=1e-11)
    x, v = sol.y
    r, dr = _ref(t)
    u = kp * (r - x) + kd * (dr - v) + noise * rng.normal(size=n)
    return Record({"q": np.round(x / 1e-6) * 1e-6, "u": u}, dt=1 / FS)


def _discover(extra, **kw) -> Discovered:
    a, b = split_blocks(_plant(extra), (0.7, 0.3))
    fam = DriveFamily()
    cal, val = [fam.prepare(a, "cal")], [fam.prepare(b, "val")]
    return discover(GapModel(fam.nominal(cal)), cal, val, family=fam, n_null=9, **kw)


@pytest.mark.slow
def test_viscous_friction_falling_with_time_is_found_with_its_formula():
    """Viscous friction `c·v·exp(−t/τ)` (c = 40 N·s/m, τ = 6 s): no library effect; the
    flexible term finds it in `v·f(t)`, the formula's support is exactly that kind and
    its coefficient and time constant are within 10 %."""
    d = _discover(lambda t, x, v: 40.0 * np.exp(-t / 6.0) * v)
    assert d.fired and d.input == "velocity·f(time)"
    assert d.found and not d.named_instead, d.message
    assert [tm["kind"] for tm in d.terms] == ["v·exp(-t/tau)"]
    assert d.terms[0]["coefficients"][0] == pytest.approx(40.0, rel=0.1)
    assert d.terms[0]["shape"]["value"] == pytest.approx(6.0, rel=0.1)
    assert d.share >= 0.8 and d.shrink_interval[0] > 0
    assert "exp" in d.formula and json.loads(json.dumps(d.to_json()))["formula"] == d.formula


@pytest.mark.slow
def test_an_effect_free_record_gets_no_formula():
    d = _discover(lambda t, x, v: 0.0)
    assert not d.fired and d.formula is None and not d.found
    assert "nothing to discover" in d.message


@pytest.mark.slow
def test_a_term_outside_the_dictionary_gets_its_shape_and_no_formula():
    """A local bump of the guideway (a Gaussian in position, 15 N over 6 mm): the flexible
    term finds it in the position; no dictionary formula reaches its gain, so the answer
    is its shape over the position."""
    d = _discover(lambda t, x, v: 15.0 * math.exp(-(((x - 0.01) / 0.006) ** 2)))
    assert d.fired and d.input == "position"
    assert not d.found and "no formula found" in d.message
    shape = d.shape
    assert shape["x"].size == shape["flexible"].size > 100
    # the flexible term has the bump's shape (up to a constant the offset absorbs)
    true = 15.0 * np.exp(-(((shape["x"] - 0.01) / 0.006) ** 2))
    k = np.corrcoef(true, shape["flexible"])[0, 1]
    assert k > 0.95


def test_bad_input_is_refused_with_the_fix():
    model = GapModel(RigidNominal(jnp.asarray(1.0), jnp.asarray(1.0), jnp.asarray(0.0)))
    with pytest.raises(TypeError, match="GapModel"):
        discover("model", [object()], [object()])
    with pytest.raises(ValueError, match="validation experiments are needed"):
        discover(model, [object()], [])
    with pytest.raises(TypeError, match="unknown setting"):
        discover(model, [object()], [object()], n_nul=3)
    with pytest.raises(ValueError, match="design_ratio"):
        discover(model, [object()], [object()], design_ratio=0.5)
    with pytest.raises(ValueError, match="DiagnosisReport"):
        discover(object())
    with pytest.raises(ValueError, match="n_null"):
        discover(model, [object()], [object()], n_null=-1)


@pytest.mark.slow
def test_diagnose_runs_discovery_when_the_remainder_stays_above_the_null(tmp_path):
    """`jaxvs.diagnose` on a record whose effect is in no library (viscous friction fading
    with time): the named search leaves a remainder above the null, so discovery runs and
    its result is in `report.json`, `report.md` and the figures; `discover=False` skips it."""
    import jaxvs
    from jaxvs.plotting import plot_diagnosis

    record = _plant(lambda t, x, v: 40.0 * np.exp(-t / 6.0) * v)
    report = jaxvs.diagnose(record, family="drive", n_null=9, n_boot=100)
    assert report["verdict"]["status"] in ("unexplained", "partly_explained")
    found = report["discovered"]
    assert found is not None and found["fired"], found
    assert found["input"] == "velocity·f(time)"
    assert json.loads(json.dumps(report.to_json()))["discovered"]["message"] == found["message"]
    assert "## Discovery" in report.to_markdown()
    assert "discovered.png" in plot_diagnosis(report, tmp_path)
    assert report.discovered is not None and report.discovered.fired


# ------------------------------------------------------------------------------ thermal

DT_TH = 10.0
SMAX = 12000.0


# the plant of the discovery benchmark (one copy): a spindle written as a two-node network
# integrated by `solve_ivp`, the chassis following the air and the motor's heat (40 min),
# the bearing's static temperature `2 + T_chassis + 6·s/12000` lagging it by 10 min;
# `heat(t, s)` [K] is an extra heat flow into the bearing node, `sensor(t)` [K] an extra
# term of the bearing sensor; 12 h at 10 s, white noise on the sensors
_thermal_plant = load_benchmark("discovery").thermal_plant


def _discover_thermal(record, **kw) -> Discovered:
    """Discovery on the model the named search leaves on these plants: the static
    regression with the bearing's lag (calibrated jointly inside discovery)."""
    from jaxvs.diagnosis._thermal import Dynamics, ThermalFamily

    a, b = split_blocks(record, (0.7, 0.3))
    fam = ThermalFamily()
    cal, val = [fam.prepare(a, "cal")], [fam.prepare(b, "val")]
    model = GapModel(fam.nominal(cal), (Dynamics(jnp.asarray(600.0), DT_TH),))
    return discover(model, cal, val, family=fam, n_null=9, **kw)


@pytest.mark.slow
def test_a_heat_flow_of_a_running_in_bearing_is_found_in_speed_and_time():
    """Friction heat of a bearing running in, `3·(s/12000)·exp(−t/3 h)` K into the bearing
    node: in no library, in the dictionary. The flexible term fires in the heat-flow slot
    on speed·f(time); the formula holds that kind with its coefficient and time constant
    within 10 % and removes at least 80 % of what the flexible term removes. (It also keeps
    small speed-power and time-polynomial terms that nearly cancel: the support is not
    exact on these records.)"""
    d = _discover_thermal(_thermal_plant(heat=lambda t, s: 3.0 * s / SMAX * math.exp(-t / 10800.0)))
    assert d.fired and d.found and not d.named_instead, d.message
    assert d.slot == "additional heat flow into the bearing node"
    assert d.input == "speed·f(time)"
    term = next(tm for tm in d.terms if tm["kind"] == "(s/smax)·exp(-t/tau)")
    assert term["coefficients"][0] == pytest.approx(3.0, rel=0.1)
    assert term["shape"]["value"] == pytest.approx(10800.0, rel=0.1)


@pytest.mark.slow
def test_a_drifting_bearing_sensor_is_placed_in_the_sensor_slot():
    """A bearing sensor drifting by 0.6 K over 12 h: the flexible term fires on time in
    the sensor slot (not as a heat flow: a term in speed and time does not beat time
    alone on held-out data)."""
    d = _discover_thermal(_thermal_plant(sensor=lambda t: 0.6 * t / 43200.0))
    assert d.fired, d.message
    assert d.slot == "additive term of the bearing sensor" and d.input == "time (sensor)"
    assert d.flexible["shrink"] > 0.3


@pytest.mark.slow
def test_an_effect_free_thermal_record_gets_no_formula():
    d = _discover_thermal(_thermal_plant())
    assert not d.fired and d.formula is None and "nothing to discover" in d.message


@pytest.mark.slow
def test_a_thermal_term_of_a_library_effect_is_reported_as_that_effect():
    """Friction heat growing with the square of the speed is the library's
    `speed_nonlinearity`: discovery on the model without it says so, names that effect
    instead of a new formula."""
    d = _discover_thermal(_thermal_plant(heat=lambda t, s: 4.0 * (s / SMAX) ** 2))
    assert d.fired and d.slot == "additional heat flow into the bearing node"
    assert d.named_instead and d.nearest_effect == "speed_nonlinearity", d.message


@pytest.mark.slow
def test_diagnose_runs_thermal_discovery_after_the_named_search():
    """`jaxvs.diagnose` on the running-in plant: the named search adds the bearing's lag
    (`dynamics`), the remainder stays above the null, and discovery finds the heat flow
    in speed and time through that lag; its result is in `report.json`."""
    import jaxvs

    record = _thermal_plant(heat=lambda t, s: 3.0 * s / SMAX * math.exp(-t / 10800.0))
    report = jaxvs.diagnose(record, family="thermal", n_null=9, n_boot=100)
    assert report["verdict"]["effects"] == ["dynamics"]
    found = json.loads(json.dumps(report.to_json()))["discovered"]
    assert found["fired"] and found["found"], found["message"]
    assert found["slot"] == "additional heat flow into the bearing node"
    assert "(s/smax)·exp(-t/tau)" in [tm["kind"] for tm in found["terms"]]
