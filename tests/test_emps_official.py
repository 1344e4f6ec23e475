"""The EMPS official benchmark task and the benchmark-task API (`jaxvs.studies.benchmarks`).

The task definition is checked against its two sources:

- the benchmark's description (Janot, Gautier, Brunot 2019, `EMPS_Description.pdf`, read
  here with a small stdlib PDF text extractor): the files, input and output, 1 kHz, ≈ 25 s,
  the cross-test validation file, the relative error of eq. (11);
- the data files themselves (read independently with scipy.io.loadmat): sample counts,
  sampling period, `u = gtau·vir`, `q = qm`.

The RMSE metric and the 20-sample initialisation window are NOT in the description: they
are the convention of the `nonlinear_benchmarks` package (`EMPS()` sets
`test.state_initialization_window_length = 20` and scores `RMSE(y[n:], ŷ[n:])`), the split
the published black-box results use. They are checked here against hand computations.
"""

import dataclasses
import json
import re
import zlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.io

from jaxvs.data import Record
from jaxvs.models import CoulombViscousFriction, RigidAxis
from jaxvs.studies import benchmarks as bm
from jaxvs.studies.benchmarks import (
    EMPS,
    EMPS_PUBLISHED_IDIM,
    BenchmarkTask,
    OpenLoopAxis,
    PositionForce,
    Segment,
    fit_multiple_shooting,
    score_predictor,
)

N_SAMPLES = 24841  # both EMPS files


_TEXT_OPERATOR = re.compile(rb"\[((?:[^\[\]\\]|\\.)*)\]\s*TJ|\(((?:[^()\\]|\\.)*)\)\s*Tj")


def _pdf_text(path) -> str:
    """Text of a TeX-generated PDF: the strings of every `TJ`/`Tj` operator of every
    FlateDecode content stream, whitespace removed (enough to find phrases)."""
    raw = path.read_bytes()
    parts = []
    for m in re.finditer(rb"stream\r?\n", raw):
        try:
            content = zlib.decompressobj().decompress(raw[m.end() :])
        except zlib.error:
            continue
        for op in _TEXT_OPERATOR.finditer(content):
            body = op.group(1) if op.group(1) is not None else b"(" + op.group(2) + b")"
            for s in re.finditer(rb"\(((?:[^()\\]|\\.)*)\)", body):
                parts.append(s.group(1).decode("latin-1"))
    return re.sub(r"\s+", "", "".join(parts))


@pytest.fixture(scope="module")
def description(shared_data):
    path = shared_data / "EMPS" / "EMPS_Description.pdf"
    if not path.is_file():
        pytest.skip("EMPS_Description.pdf is absent")
    return _pdf_text(path)


@pytest.fixture(scope="module")
def emps_folder(shared_data):
    return shared_data / "EMPS"


# ----------------------------------------------------------------------------- the task


def test_task_matches_description(description):
    # the extractor works on this file: the title is there
    assert "DataSetandReferenceModelsofEMPS" in description
    # §2.2: input is the force, output the motor position qm
    assert "theinputoftheEMPSistheforcei.e.virMATLABvariable" in description
    assert "theoutputisthepositioni.e.qmMATLABvariable" in description
    assert EMPS.inputs == ("u",) and EMPS.outputs == ("q",) and EMPS.output_units == ("m",)
    # §2.2: 1 kHz, ≈ 25 s
    assert "Thesamplingfrequencyis1kHzwhilethedurationis25sapproximately" in description
    assert EMPS.sample_time == 1e-3
    # §2.2 / §3.5: estimation on DATA_EMPS.mat, cross-test validation (pulses) on
    # DATA_EMPS_PULSES.mat
    assert "cross-testvalidationsmustbeexecuted" in description
    assert "EMPSDATAPULSEmat" in description and "pulsesNgiveninN" in description
    assert "SimulationofEMSPwithDATA_EMPS.mat" in description
    assert "SimulationofEMSPwithDATA_EMPS_PULSES.mat" in description
    assert [s.file for s in EMPS.train] == ["DATA_EMPS.mat"]
    assert [s.file for s in EMPS.test] == ["DATA_EMPS_PULSES.mat"]
    # eq. (11), the description's relative error, is one of the task's metrics
    assert "relativeerrorgivenbyrelerr=100" in description
    # the initialisation window is the nonlinear_benchmarks convention, not the PDF's
    assert EMPS.init_window == 20
    assert "initiali" not in description.lower()


def test_task_matches_files(emps_folder):
    data = EMPS.load(emps_folder)
    for record, seg in zip(data.train + data.test, EMPS.train + EMPS.test):
        raw = scipy.io.loadmat(emps_folder / seg.file)
        t = raw["t"].ravel()
        assert t.size == N_SAMPLES == len(record) == seg.samples
        # 1 kHz: the file's time steps agree with 1 ms to the file's jitter (≈ 3e-5 dt)
        np.testing.assert_allclose(np.diff(t), 1e-3, rtol=1e-3)
        assert 24.8 < t[-1] - t[0] < 25.0  # "25 s approximately"
        u, y = EMPS.arrays(record)
        # the output is qm [m] and the input gtau·vir [N], exactly as stored
        np.testing.assert_array_equal(y[:, 0], raw["qm"].ravel())
        gtau = float(raw["gtau"].squeeze())
        np.testing.assert_allclose(u[:, 0], gtau * raw["vir"].ravel(), rtol=1e-15)
        # the description calls vir a force "in N"; in the files it is the controller
        # output in volts (±10 V amplifier, gtau = 35.15 N/V, §1.3), hence u = gtau·vir
        assert np.max(np.abs(raw["vir"])) < 10.0
        assert gtau == pytest.approx(35.15, abs=0.01)


def test_metric_against_hand_computation():
    rng = np.random.default_rng(0)
    n = 100
    y = 0.1 + 0.05 * rng.standard_normal((n, 1))
    y_hat = y + 1e-3 * rng.standard_normal((n, 1))
    got = EMPS.score(y, y_hat)
    e = (y - y_hat)[20:, 0]
    ys = y[20:, 0]
    # by hand, on the samples after the 20-sample window, RMSE in mm (rounding only)
    assert got["rmse"][0] == pytest.approx(1e3 * np.sqrt(np.sum(e**2) / (n - 20)), rel=1e-12)
    assert got["nrmse"][0] == pytest.approx(
        np.sqrt(np.mean(e**2)) / np.sqrt(np.mean((ys - ys.mean()) ** 2)), rel=1e-12
    )
    assert got["relative_error"][0] == pytest.approx(
        100 * np.sqrt(np.sum(e**2)) / np.sqrt(np.sum(ys**2)), rel=1e-12
    )


def test_init_window_is_not_scored_and_is_all_a_model_sees():
    n = 60
    y = np.linspace(0.0, 0.2, n)[:, None]
    base = EMPS.score(y, y + 1e-3)["rmse"][0]
    inside = y + 1e-3
    inside[:20] += 5.0  # anything inside the window: not scored
    assert EMPS.score(y, inside)["rmse"][0] == pytest.approx(base, rel=1e-14)
    outside = y + 1e-3
    outside[20] += 5.0  # the first scored sample
    assert EMPS.score(y, outside)["rmse"][0] > 10 * base

    seen = {}

    def spy(u, y_init):
        seen["u"], seen["y"] = u.shape, np.array(y_init)
        return np.zeros((u.shape[0], 1)) + y_init[-1]

    record = Record({"u": np.sin(np.arange(n) / 5.0), "q": y[:, 0]}, dt=1e-3)
    data = bm.TaskData((record,), (record,), ("a",), ("b",))
    score_predictor(EMPS, spy, data)
    assert seen["u"] == (n, 1)
    np.testing.assert_array_equal(seen["y"], y[:20])


# ----------------------------------------------------------------------------- the model


def _numpy_axis(u, q0, v0, M, Fv, Fc, off, vs, dt=1e-3, sub=8):
    """Independent oracle: RK4 with `sub` steps per sample, force held over the sample."""
    q, v = q0, v0
    out = np.empty(len(u))
    h = dt / sub

    def acc(v, f):
        return (f - Fv * v - Fc * np.tanh(v / vs) - off) / M

    for k, f in enumerate(u):
        out[k] = q
        for _ in range(sub):
            k1v = acc(v, f)
            k2v = acc(v + h / 2 * k1v, f)
            k3v = acc(v + h / 2 * k2v, f)
            k4v = acc(v + h * k3v, f)
            q += h * (v + h / 6 * (k1v + k2v + k3v))
            v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return out


def _published_axis(velocity_scale=1e-4):
    p = EMPS_PUBLISHED_IDIM
    friction = CoulombViscousFriction(p["Fc"], p["Fv"], p["offset"], velocity_scale=velocity_scale)
    return OpenLoopAxis(RigidAxis(p["M"], friction), sample_time=1e-3, n_substeps=2)


def test_open_loop_axis_against_numpy_oracle(emps_folder):
    record = EMPS.load(emps_folder).test[0]
    u, y = EMPS.arrays(record)
    u = u[:3000]
    model = _published_axis(velocity_scale=1e-3)
    x = np.asarray(model.simulate(u, jnp.array([y[0, 0], 0.05])))
    p = EMPS_PUBLISHED_IDIM
    ref = _numpy_axis(u[:, 0], y[0, 0], 0.05, p["M"], p["Fv"], p["Fc"], p["offset"], 1e-3)
    # Tsit5 ×2 against RK4 ×8 on 3 s: both converged to well below 1 µm
    np.testing.assert_allclose(x[:, 0], ref, atol=1e-7)


@pytest.mark.slow
def test_published_parameters_reference(emps_folder):
    data = EMPS.load(emps_folder)
    model = _published_axis()
    score = score_predictor(EMPS, model, data)
    # the official protocol (state from the first 20 samples); measured 5.29 / 8.39 mm
    assert score.mean("rmse", "train") == pytest.approx(5.3, abs=0.15)
    assert score.mean("rmse") == pytest.approx(8.4, abs=0.15)
    # started at rest from q[0] on the whole record: the numpy figures 6.6 / 9.2 mm
    for record, expected in ((data.train[0], 6.7), (data.test[0], 9.2)):
        u, y = EMPS.arrays(record)
        x = model.simulate(u, jnp.array([y[0, 0], 0.0]))
        err = 1e3 * np.sqrt(np.mean((np.asarray(x[:, 0]) - y[:, 0]) ** 2))
        assert err == pytest.approx(expected, abs=0.15)


def test_initial_state_is_exact_for_a_parabola():
    model = _published_axis()
    t = np.arange(20) * 1e-3
    q = 0.01 + 0.1 * t - 3.0 * t**2
    x = model.initial_state(q[:, None])
    # exact for a parabola up to rounding of the 20x3 least squares
    np.testing.assert_allclose(x, [q[-1], 0.1 - 6.0 * t[-1]], rtol=1e-9)


def test_position_force_is_a_legendre_series():
    c = np.array([0.5, -1.0, 2.0])
    force = PositionForce(c, centre=0.1, half_range=0.2)
    q = np.linspace(-0.1, 0.3, 11)
    expected = np.polynomial.legendre.legval((q - 0.1) / 0.2, np.r_[0.0, c])
    np.testing.assert_allclose(force(q), expected, rtol=1e-13)


@pytest.mark.slow
def test_multiple_shooting_recovers_parameters():
    # noiseless synthetic record of a known axis with a position force; recover it from a
    # guess 10-30 % off
    rng = np.random.default_rng(1)
    n = 1600
    steps = np.repeat(rng.uniform(-60, 60, n // 160), 160)
    u = (steps + 40 * np.sin(np.arange(n) * 2 * np.pi / 800))[:, None]
    true = OpenLoopAxis(
        RigidAxis(90.0, CoulombViscousFriction(18.0, 210.0, -2.0, velocity_scale=1e-3)),
        PositionForce(np.array([3.0, -1.5]), centre=0.0, half_range=0.2),
        sample_time=1e-3,
    )
    y = np.asarray(true.output(true.simulate(u, jnp.array([0.0, 0.0]))))
    guess = OpenLoopAxis(
        RigidAxis(100.0, CoulombViscousFriction(14.0, 180.0, 0.0, velocity_scale=1e-3)),
        PositionForce(np.zeros(2), centre=0.0, half_range=0.2),
        sample_time=1e-3,
    )
    fit = fit_multiple_shooting(
        guess,
        u,
        y,
        segment_length=400,
        output_scale=1e-3,
        state_scale=(1e-3, 2e-3),
        max_steps=60,
    )
    mech = fit.model.mechanics
    got = np.r_[
        float(mech.mass),
        [float(getattr(mech.friction, n)) for n in ("Fc", "Fv", "offset")],
        np.asarray(fit.model.position_force.coefficients),
    ]
    want = np.array([90.0, 18.0, 210.0, -2.0, 3.0, -1.5])
    # noiseless data: the optimum is the truth; 1e-5 relative allows the solver's rtol
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert fit.n_parameters == 6
    assert fit.starts.shape == (int((n - 20) // 400),)
    # the segment states join up: continuity holds at the truth
    assert float(fit.cost) < 1e-8 * float(fit.initial_cost)

    # single shooting (one segment, its state fixed at the window estimate, as the
    # benchmark's protocol) from the same guess also finds the truth
    single = fit_multiple_shooting(
        guess, u, y, segment_length=n - 20, output_scale=1e-3, free_states=False, max_steps=60
    )
    assert single.starts.shape == (1,)
    np.testing.assert_allclose(single.initial_states[0], guess.initial_state(y[:20]), rtol=1e-12)
    mech = single.model.mechanics
    # the window estimate of the state is not exact (the truth is not a parabola), so the
    # parameters absorb it: 1 % here against 1e-5 above
    np.testing.assert_allclose(
        [float(mech.mass), float(mech.friction.Fc), float(mech.friction.Fv)],
        [90.0, 18.0, 210.0],
        rtol=1e-2,
    )


# ----------------------------------------------------------------------------- bad input


def test_bad_input():
    with pytest.raises(TypeError, match="non-empty file name"):
        Segment("")
    with pytest.raises(ValueError, match="stop must be"):
        Segment("a.mat", start=10, stop=5)
    with pytest.raises(ValueError, match="samples must be"):
        Segment("a.mat", samples=0)
    kwargs = dict(
        name="x",
        loader=lambda p: None,
        train=(Segment("a"),),
        test=(Segment("b"),),
        inputs=("u",),
        outputs=("y",),
        init_window=5,
        sample_time=0.1,
        output_units=("m",),
    )
    with pytest.raises(ValueError, match="init_window must be"):
        BenchmarkTask(**{**kwargs, "init_window": -1})
    with pytest.raises(TypeError, match="outputs must be a non-empty tuple"):
        BenchmarkTask(**{**kwargs, "outputs": "y"})
    with pytest.raises(ValueError, match="one unit per output"):
        BenchmarkTask(**{**kwargs, "output_units": ("m", "m")})
    with pytest.raises(FileNotFoundError, match="does not exist"):
        EMPS.load("/nonexistent/folder")
    with pytest.raises(ValueError, match="one prediction per measured sample|shape"):
        EMPS.score(np.zeros((50, 1)), np.zeros((49, 1)))
    with pytest.raises(ValueError, match="NaN or inf"):
        bm.rmse(np.zeros(5), np.full(5, np.nan))
    with pytest.raises(ValueError, match="constant"):
        bm.nrmse(np.ones(5), np.zeros(5))
    with pytest.raises(TypeError, match="callable"):
        score_predictor(EMPS, 3.0, None)
    with pytest.raises(TypeError, match="RigidAxis"):
        OpenLoopAxis(CoulombViscousFriction(1.0, 1.0), sample_time=1e-3)
    with pytest.raises(ValueError, match="n_substeps"):
        OpenLoopAxis(RigidAxis(1.0), sample_time=1e-3, n_substeps=0)
    with pytest.raises(ValueError, match="coefficients"):
        PositionForce(np.zeros((2, 2)), centre=0.0, half_range=1.0)
    model = _published_axis()
    with pytest.raises(ValueError, match="y_init must hold"):
        model(np.zeros((10, 1)), np.zeros((0, 1)))
    with pytest.raises(ValueError, match=r"\(time, input\)"):
        model(np.zeros(10), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="segment_length"):
        fit_multiple_shooting(model, np.zeros((100, 1)), np.zeros((100, 1)), segment_length=1)
    with pytest.raises(ValueError, match="no segment"):
        fit_multiple_shooting(model, np.zeros((100, 1)), np.zeros((100, 1)), segment_length=500)
    with pytest.raises(ValueError, match="equal"):
        fit_multiple_shooting(model, np.zeros((100, 1)), np.zeros((90, 1)))
    with pytest.raises(TypeError, match="AbstractSimulator"):
        fit_multiple_shooting(eqx.nn.Identity(), np.zeros((100, 1)), np.zeros((100, 1)))


def test_load_checks_the_files(tmp_path, emps_folder):
    task = BenchmarkTask(
        name="EMPS-short",
        loader=EMPS.loader,
        train=(Segment("DATA_EMPS.mat", samples=1000),),
        test=(Segment("DATA_EMPS_PULSES.mat"),),
        inputs=("u",),
        outputs=("q",),
        init_window=20,
        sample_time=1e-3,
        output_units=("m",),
    )
    with pytest.raises(ValueError, match="24841 samples; the benchmark's file has 1000"):
        task.load(emps_folder)
    with pytest.raises(FileNotFoundError, match="is not in"):
        task.load(tmp_path)
    sliced = dataclasses.replace(
        task, train=(Segment("DATA_EMPS.mat", start=100, stop=1100, samples=1000),)
    )
    data = sliced.load(emps_folder)
    full = EMPS.load(emps_folder)
    np.testing.assert_array_equal(data.train[0]["q"], full.train[0]["q"][100:1100])
    assert data.labels_train == ("DATA_EMPS.mat[100:1100]",)
    wrong_dt = dataclasses.replace(sliced, sample_time=1e-4)
    with pytest.raises(ValueError, match="sampled every"):
        wrong_dt.load(emps_folder)


def test_simulation_gradient_matches_finite_differences():
    # forward-mode derivative of the simulated position w.r.t. mass and Coulomb force
    # (what the Levenberg–Marquardt Jacobian uses) against central differences
    rng = np.random.default_rng(2)
    u = jnp.asarray(np.repeat(rng.uniform(-50, 50, 6), 50)[:, None])

    def position(theta):
        model = OpenLoopAxis(
            RigidAxis(theta[0], CoulombViscousFriction(theta[1], 200.0, -1.0, velocity_scale=1e-2)),
            sample_time=1e-3,
        )
        return model.simulate(u, jnp.array([0.0, 0.01]))[:, 0]

    theta = jnp.array([95.0, 20.0])
    jac = np.asarray(jax.jacfwd(position)(theta))
    h = np.array([1e-3, 1e-4])
    fd = np.stack(
        [
            (position(theta + h[i] * e) - position(theta - h[i] * e)) / (2 * h[i])
            for i, e in enumerate(np.eye(2))
        ],
        axis=1,
    )
    # central differences with these steps are accurate to ~1e-7 relative (smooth model)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-12)


def test_write_report(tmp_path):
    n = 200
    t = np.arange(n) * 1e-3
    record = Record({"u": np.sin(40 * t), "q": 0.1 + 0.01 * np.cos(40 * t)}, dt=1e-3)
    data = bm.TaskData((record,), (record, record), ("train",), ("test a", "test b"))

    def hold(u, y_init):  # predicts the last initial sample forever
        return np.broadcast_to(y_init[-1:], (u.shape[0], 1))

    score = score_predictor(EMPS, hold, data)
    row = bm.ModelReport("hold", score, parameters=0, train_s=0.5, compile_s=0.3)
    pub = bm.PublishedResult("net", (50.0, 60.0), None, "somewhere")
    md = bm.write_report(EMPS, [row], tmp_path / "r", published=[pub], preamble="intro")

    saved = json.loads((tmp_path / "r.json").read_text())
    assert (tmp_path / "r.md").read_text() == md
    expected = 1e3 * np.sqrt(np.mean((0.01 * np.cos(40 * t[20:]) - 0.01 * np.cos(40 * t[19])) ** 2))
    # JSON and table carry the same RMSE, computed by hand (mm; rounding only)
    assert saved["models"][0]["test_rmse"] == pytest.approx(expected, rel=1e-12)
    assert len(saved["models"][0]["scores"]["test"]) == 2
    assert f"| hold | 0 | 0.5 | 0.3 | {expected:.2f} | **{expected:.2f}** |" in md
    assert "| net (published) | — | — | — | — | 50.0–60.0 | — | — |" in md
    assert saved["task"]["init_window"] == 20 and saved["published"][0]["source"] == "somewhere"


# ----------------------------------------------------------------------------- honest selection


def _tiny_data():
    n = 60
    t = np.arange(n) * 1e-3
    train = Record({"u": np.sin(t * 50), "q": 0.1 + 0.01 * t}, dt=1e-3)
    test = Record({"u": np.cos(t * 50), "q": 0.2 - 0.01 * t}, dt=1e-3)
    return bm.TaskData((train,), (test,), ("train",), ("test",))


def test_sealed_test_split_refuses_the_test_split_before_selection():
    split = bm.SealedTestSplit(EMPS, _tiny_data())
    calls = []

    def hold(u, y_init):
        calls.append(u.shape)
        return np.zeros((u.shape[0], 1)) + y_init[-1]

    # selection sees the training records only
    assert split.train.test == () and len(split.train.train) == 1
    assert split.selected is None
    with pytest.raises(bm.TestSplitSealedError, match="before a model is selected"):
        split.score(hold)
    with pytest.raises(bm.TestSplitSealedError, match="before a model is selected"):
        split.test  # noqa: B018
    assert calls == []  # the scorer refused before running the model on anything
    # scoring on the training records only is allowed
    score_predictor(EMPS, hold, split.train)
    split.select("hold", {"held_out": 1.0})
    assert split.selected == "hold" and split.evidence == {"held_out": 1.0}
    s = split.score(hold)
    assert len(s.test) == 1 and len(s.train) == 1
    # a selection is final
    with pytest.raises(bm.TestSplitSealedError, match="already selected"):
        split.select("another")
    with pytest.raises(TypeError, match="BenchmarkTask"):
        bm.SealedTestSplit(EMPS, "data")


def test_results_mark_the_model_selected_on_training_data():
    """The committed benchmark result: one selected row, and it is the candidate with the
    lowest held-out error on the training file (the recorded evidence), not the lowest
    test error."""
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "benchmarks/results/emps_official.json"
    out = json.loads(path.read_text())
    selected = [m for m in out["models"] if m["selected"]]
    assert len(selected) == 1 and selected[0]["name"] == out["selected"]
    evidence = out["selection"]["evidence"]
    assert min(evidence, key=lambda k: evidence[k]["mean_mm"]) == out["selected"]
    for m in out["models"]:
        assert m["chosen"], m["name"]


@pytest.mark.slow
def test_fit_weights_hold_samples_out():
    """Zero weights take samples out of the fit: a model calibrated on the first half of
    a record with the second half weighted 0 equals one calibrated on the first half
    alone (the simulation over the held-out span does not change earlier outputs)."""
    rng = np.random.default_rng(0)
    n = 400
    u = rng.normal(size=(n, 1)) * 30
    truth = OpenLoopAxis(
        RigidAxis(90.0, CoulombViscousFriction(15.0, 180.0, -2.0)), sample_time=1e-3
    )
    y = np.array(truth(u, np.zeros((20, 1))))
    y[200:] += 0.05  # the held-out half disagrees with the model
    start = OpenLoopAxis(
        RigidAxis(95.0, CoulombViscousFriction(20.0, 200.0, 0.0)), sample_time=1e-3
    )
    w = (np.arange(n) < 200).astype(float)
    kw = dict(init_window=20, output_scale=1e-3, free_states=False, max_steps=30)
    a = fit_multiple_shooting(start, u, y, segment_length=n - 20, weights=w, **kw)
    b = fit_multiple_shooting(start, u[:200], y[:200], segment_length=180, **kw)
    np.testing.assert_allclose(a.model.mechanics.mass, b.model.mechanics.mass, rtol=1e-6)
    np.testing.assert_allclose(a.model.mechanics.friction.Fv, 180.0, rtol=1e-3)
    with pytest.raises(ValueError, match="weights must be"):
        fit_multiple_shooting(start, u, y, segment_length=n - 20, weights=np.zeros(n), **kw)


def test_swapped_or_edited_files_are_refused(emps_folder, tmp_path):
    """The task's files are checked against the published SHA-256: the two files swapped
    under each other's names are named as swapped (training on the test file would report a
    figure the test data chose); an edited file is refused as not the published one."""
    import shutil

    swapped = tmp_path / "swapped"
    swapped.mkdir()
    shutil.copy(emps_folder / "DATA_EMPS.mat", swapped / "DATA_EMPS_PULSES.mat")
    shutil.copy(emps_folder / "DATA_EMPS_PULSES.mat", swapped / "DATA_EMPS.mat")
    with pytest.raises(ValueError, match=r"holds the benchmark's 'DATA_EMPS_PULSES.mat'.*swapped"):
        EMPS.load(swapped)
    edited = tmp_path / "edited"
    edited.mkdir()
    shutil.copy(emps_folder / "DATA_EMPS_PULSES.mat", edited / "DATA_EMPS_PULSES.mat")
    raw = scipy.io.loadmat(emps_folder / "DATA_EMPS.mat")
    kept = {k: v for k, v in raw.items() if not k.startswith("__")}
    scipy.io.savemat(edited / "DATA_EMPS.mat", kept)
    with pytest.raises(ValueError, match="not the benchmark's published 'DATA_EMPS.mat'"):
        EMPS.load(edited)
    # the published files load, unchanged
    assert len(EMPS.load(emps_folder).train[0]) == 24841
