"""The virtual-sensor design assistant: `jaxvs.design` and `jaxvs design`."""

import json

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as ss

import jaxvs
from jaxvs._cli import main
from jaxvs.signal import block_bootstrap_means
from jaxvs.studies.design import DesignDataWarning, DesignedSensor
from jaxvs.studies.design._score import rank_designs
from jaxvs.studies.design._search import (
    Candidate,
    NetworkTraining,
    feature_mask,
    fit_linear_group,
    train_network_group,
)
from jaxvs.twins import SpindleThermalTwin

FAST = dict(hidden=(3,), inits=2, max_steps=30, progress=False)


def _lag(x, a):
    """First-order lag `z = a z + (1-a) x`, steady start (scipy oracle)."""
    return ss.lfilter([1 - a], [1, -a], x, zi=[a * x[0]])[0]


@pytest.fixture(scope="module")
def spindle():
    """6 h of the spindle twin (lagging inner ring, τ = 240 s) at 30 s, with a distractor
    correlated with T_chassis and a noise channel."""
    twin = SpindleThermalTwin({"dynamics": 240.0})
    rec = twin.experiment(jr.key(3), duration=8 * 3600.0, dt=30.0)
    rng = np.random.default_rng(1)
    n = len(rec)
    tc = np.asarray(rec["T_chassis"])
    walk = np.cumsum(rng.normal(0, 0.15, n))
    return {
        "t": np.asarray(rec.t),
        "T_chassis": tc,
        "v_m": np.asarray(rec["v_m"]),
        "T_bearing": np.asarray(rec["T_bearing"]),
        "T_near": 0.9 * tc + 2.0 + walk,  # correlated with T_chassis, not causal
        "noise": rng.normal(size=n),
    }


def test_regression_group_matches_lstsq():
    rng = np.random.default_rng(0)
    n, m, dmax = 200, 3, 1
    U = rng.normal(size=(n, m * (dmax + 1)))
    U = np.column_stack([U, U[:, :: dmax + 1] ** 2])  # delayed copies, then squares
    y = U @ rng.normal(size=U.shape[1]) + 0.1 * rng.normal(size=n)
    cands = [Candidate("regression", s, (0,)) for s in [(0,), (1, 2), (0, 1, 2)]]
    cands.append(Candidate("regression", (0, 2), (0,), quadratic=True))
    train = np.ones(n)
    train[150:] = 0
    res = fit_linear_group("regression", cands, U, y, np.eye(1, n, 0, bool)[0], train, m, dmax, 1.0)
    for c, prm, p in zip(cands, res.params, res.pred):
        idx = np.flatnonzero(feature_mask(c, m, dmax))
        A = np.column_stack([U[:150][:, idx], np.ones(150)])
        w, *_ = np.linalg.lstsq(A, y[:150], rcond=None)
        # same least-squares problem, solved by normal equations: agree to rounding (1e-9)
        np.testing.assert_allclose(prm["w"][idx], w[:-1], atol=1e-9)
        np.testing.assert_allclose(p, np.column_stack([U[:, idx], np.ones(n)]) @ w, atol=1e-9)
        # masked features get exactly zero weight
        assert np.all(prm["w"][np.setdiff1d(np.arange(U.shape[1]), idx)] == 0)


def test_lag_recovers_time_constant_and_arx_core_matches_lfilter():
    dt, tau = 5.0, 60.0
    a = np.exp(-dt / tau)
    rng = np.random.default_rng(2)
    u = np.repeat(rng.uniform(-1, 1, 40), 25)  # steps every 125 s
    y = _lag(2.0 * u + 0.5, a)
    starts = np.zeros(u.size, bool)
    starts[0] = True
    train = np.ones(u.size)
    X = np.column_stack([u, u**2])
    res = fit_linear_group("lag", [Candidate("lag", (0,), (0,))], X, y, starts, train, 1, 0, dt)
    tau_hat = -dt / np.log(res.params[0]["a"])
    # the time constant is profiled on a geometric grid of ratio ~1.17: within 10 %
    assert abs(tau_hat / tau - 1) < 0.1
    # the ARX core simulates y(k) = a1 y(k-1) + a2 y(k-2) + x w + b exactly as lfilter
    from jaxvs.studies.design import ARXCore

    core = ARXCore(jnp.array([1.2, -0.35]), jnp.array([0.3]), jnp.array(0.1))
    v = 0.3 * u + 0.1
    ss_y = v[0] / (1 - 1.2 + 0.35)
    zi = ss.lfiltic([1.0], [1, -1.2, 0.35], [ss_y, ss_y], [v[0], v[0]])
    ref = ss.lfilter([1.0], [1, -1.2, 0.35], v, zi=zi)[0]
    np.testing.assert_allclose(np.asarray(core(jnp.asarray(u[:, None]))), ref, atol=1e-10)


def test_batched_network_training_equals_loop():
    rng = np.random.default_rng(3)
    n, m, dmax = 160, 2, 1
    X = rng.uniform(-1, 1, size=(n, m * (dmax + 1)))
    y = np.tanh(X[:, 0] - 0.5 * X[:, 2]) + 0.05 * rng.normal(size=n)
    role = np.zeros(n, int)
    role[120:] = 1
    cands = [Candidate("mlp", (0,), (0,), hidden=3), Candidate("tdnn", (0, 1), (0, 1), hidden=3)]
    kw = dict(inits=2, key=jr.key(0), training=NetworkTraining(max_steps=20))
    a = train_network_group(cands, X, y, role, m, dmax, **kw)
    b = train_network_group(cands, X, y, role, m, dmax, loop=True, **kw)
    # the same per-member computation, batched by vmap or run one by one: equal to rounding
    np.testing.assert_allclose(a.pred, b.pred, rtol=1e-7, atol=1e-9)
    # the masked weights of the one-input design stay exactly zero
    W1 = a.params[0]["theta"][: 3 * 4].reshape(3, 4)
    assert np.all(W1[:, 1:] == 0)


def test_block_bootstrap_iid_matches_closed_form():
    rng = np.random.default_rng(4)
    e2 = rng.normal(size=(1, 4000)) ** 2
    reps = block_bootstrap_means(e2, 1, 2000, np.random.default_rng(0))
    # iid resampling of n values: sd of the mean = sd(e²)/√n; 2000 replicates: ~3 % error
    assert abs(reps.std() / (e2.std() / np.sqrt(4000)) - 1) < 0.1


def test_complexity_penalty_ranks_simpler_unless_significant():
    rng = np.random.default_rng(5)
    base = 1 + 0.1 * rng.normal(size=(1, 300))
    # design 0: 3 params, design 1: 10 params with an insignificant gain (noise only),
    # design 2: 20 params with a clear gain
    reps = np.concatenate([base, base - 0.001 + 0.05 * rng.normal(size=(1, 300)), base - 0.5])
    rmse = np.sqrt(reps.mean(axis=1))
    order, over = rank_designs(rmse, np.array([3, 10, 20]), reps)
    assert order[0] == 2  # a significant gain wins whatever its complexity
    assert order.index(0) < order.index(1) or rmse[0] <= rmse[1]


@pytest.mark.slow
def test_design_recovers_inputs_and_round_trips(spindle, tmp_path):
    rep = jaxvs.design(spindle, target="T_bearing", max_inputs=3, **FAST)
    best = rep.best
    # the true inputs, no distractor
    assert set(best["inputs"]) == {"T_chassis", "v_m"}
    assert best["structure"] in ("lag", "arx", "tdnn")  # the twin lags (τ = 240 s)
    # contract keys (docs/guides/design.md)
    c = rep.to_json()
    for k in ("target", "metric", "designs", "best", "baseline", "candidates_evaluated"):
        assert k in c
    for k in (
        "rank",
        "structure",
        "inputs",
        "delays",
        "hidden",
        "validation",
        "calibration",
        "parameters",
        "seconds",
    ):
        assert k in best
    assert set(best["validation"]) >= {"rmse", "r2", "mapd", "rmse_interval"}
    lo, hi = best["validation"]["rmse_interval"]
    assert lo <= best["validation"]["rmse"] <= hi
    assert c["baseline"]["validation"]["rmse"] > best["validation"]["rmse"]
    assert [d["rank"] for d in c["designs"]] == list(range(1, len(c["designs"]) + 1))
    assert "T_near" not in c["forward_selection"]["selected"]
    from jaxvs.plotting import plot_design

    out = rep.save(tmp_path / "rep", figures=plot_design)
    assert json.loads((out / "report.json").read_text())["best"]["rank"] == 1
    for f in ("report.md", "report.html", "best.eqx", "heldout_prediction.png"):
        assert (out / f).exists()
    model = jaxvs.load_model(out / "best.eqx")
    assert isinstance(model, DesignedSensor)
    rec = jaxvs.data.Record({k: v for k, v in spindle.items() if k != "t"}, t=spindle["t"])
    # the loaded sensor predicts from a new record in one call, as the search did (1e-10)
    np.testing.assert_allclose(np.asarray(model(rec)), rep.predictions[1], atol=1e-10)
    with pytest.raises(ValueError, match="lack the input"):
        model({"v_m": spindle["v_m"]})


def test_sparse_target_is_resampled_and_scored_on_measurements(spindle, tmp_path):
    y = spindle["T_bearing"].copy()
    keep = np.zeros(y.size, bool)
    keep[::3] = True  # a measurement every 90 s
    sparse = dict(spindle, T_bearing=np.where(keep, y, np.nan))
    rep = jaxvs.design(
        sparse,
        target="T_bearing",
        structures=("regression", "lag"),
        inputs=["T_chassis", "v_m"],
        progress=False,
    )
    s = rep["data"]["sparse_target"]
    assert s is not None and s["measured_samples"] == int(keep.sum())
    assert s["segments"] >= 2  # per segment of constant speed
    # scored on measured samples only: recompute the best RMSE from them
    V = (rep.arrays["role"] == 2) & keep
    r = np.sqrt(np.mean((y[V] - rep.predictions[1][V]) ** 2))
    assert rep.best["validation"]["rmse"] == pytest.approx(r, rel=1e-12)
    # the same samples from a separate file
    path = tmp_path / "samples.csv"
    np.savetxt(
        path,
        np.column_stack([spindle["t"][keep], y[keep]]),
        delimiter=",",
        header="t,T_bearing",
        comments="",
    )
    dense = {k: v for k, v in spindle.items() if k != "T_bearing"}
    rec = jaxvs.data.Record({k: v for k, v in dense.items() if k != "t"}, t=dense["t"])
    rep2 = jaxvs.design(
        rec,
        target="T_bearing",
        target_samples=path,
        structures=("regression", "lag"),
        inputs=["T_chassis", "v_m"],
        progress=False,
    )
    assert rep2["data"]["sparse_target"]["measured_samples"] == int(keep.sum())
    assert rep2.best["validation"]["rmse"] == pytest.approx(rep.best["validation"]["rmse"])


def test_budget_stops_gracefully(spindle):
    rep = jaxvs.design(spindle, target="T_bearing", budget=1e-3, **FAST)
    cov = rep["coverage"]
    assert cov["stopped_by"] == "budget" and cov["evaluated"] < cov["total"]


def test_no_operating_point_change_warns(spindle):
    t = spindle["t"]
    n = t.size
    steady = dict(spindle, v_m=np.where(np.arange(n) < 0.6 * n, spindle["v_m"], 3000.0))
    with pytest.warns(DesignDataWarning, match="no change of operating point"):
        rep = jaxvs.design(steady, target="T_bearing", structures=("regression",), progress=False)
    assert any("no change of operating point" in w for w in rep["warnings"])


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(inputs=["nope"]), "unknown input"),
        (dict(target="nope"), "no target signal"),
        (dict(inputs=[]), "no candidate inputs"),
        (dict(budget=-1.0), "budget"),
        (dict(structures=("svm",)), "unknown structure"),
    ],
)
def test_bad_input(spindle, change, match):
    kw = dict(target="T_bearing", progress=False) | change
    with pytest.raises(ValueError, match=match):
        jaxvs.design(spindle, **kw)


def test_bad_data():
    t = np.arange(200.0)
    with pytest.raises(ValueError, match="no candidate inputs"):
        jaxvs.design({"t": t, "y": np.sin(t)}, target="y", progress=False)
    with pytest.raises(ValueError, match="constant"):
        jaxvs.design({"t": t, "u": np.sin(t), "y": np.ones(200)}, target="y", progress=False)
    with pytest.raises(ValueError, match="too few samples"):
        jaxvs.design(
            {"t": t[:20], "u": np.sin(t[:20]), "y": np.cos(t[:20])}, target="y", progress=False
        )
    with pytest.raises(TypeError, match="data must be"):
        jaxvs.design(3.0, target="y")
    with jax.enable_x64(False):  # 32-bit would round every calibration silently
        with pytest.raises(ValueError, match=r"design: needs float64.*jax_enable_x64"):
            jaxvs.design({"t": t, "u": np.sin(t), "y": np.cos(t)}, target="y", progress=False)


@pytest.mark.slow
def test_cli(spindle, tmp_path, capsys):
    rec = jaxvs.data.Record({k: v for k, v in spindle.items() if k != "t"}, t=spindle["t"])
    path = jaxvs.data.save_csv(rec, tmp_path / "run.csv")
    assert main(["design", str(path), "--target", "nope", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("jaxvs: error:") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
    code = main(
        [
            "design",
            str(path),
            "--target",
            "T_bearing",
            "--inputs",
            "T_chassis,v_m",
            "--hidden",
            "3",
            "--inits",
            "1",
            "--out",
            str(tmp_path / "o"),
            "--quiet",
            "--no-figures",
        ]
    )
    assert code == 0
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["target"] == "T_bearing" and rep["best"]["rank"] == 1
    assert not any(p.name.startswith(".o.") for p in tmp_path.iterdir())  # no temp folder left


def test_ctrl_c_returns_designs_ranked_so_far(spindle, monkeypatch, tmp_path, capsys):
    import jaxvs.studies.design._design as D

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(D, "train_network_group", interrupted)
    rep = jaxvs.design(spindle, target="T_bearing", inputs=["T_chassis", "v_m"], **FAST)
    assert rep["interrupted"] and rep["coverage"]["stopped_by"] == "interrupt"
    # the linear groups ran before the networks: they are ranked, the networks are not
    assert rep["candidates_evaluated"] > 0
    assert {d["structure"] for d in rep.designs} <= {"regression", "lag", "arx"}
    rec = jaxvs.data.Record({k: v for k, v in spindle.items() if k != "t"}, t=spindle["t"])
    path = jaxvs.data.save_csv(rec, tmp_path / "run.csv")
    code = main(
        [
            "design",
            str(path),
            "--target",
            "T_bearing",
            "--inputs",
            "T_chassis,v_m",
            "--out",
            str(tmp_path / "o"),
            "--quiet",
            "--no-figures",
        ]
    )
    assert code == 130
    assert "interrupted" in capsys.readouterr().err
    assert json.loads((tmp_path / "o" / "report.json").read_text())["interrupted"] is True
