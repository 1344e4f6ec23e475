"""Sharded families and sweeps (jax.sharding), and the progress / logging helpers.

The 8-device checks run in a subprocess: XLA_FLAGS must be set before jax is imported,
and this process has already imported it with one CPU device. Oracle: the single-device
`simulate` / `calibrate_family` / unsharded sweep of the same family; the sharded code
runs the same per-member computation, so the results must agree to rounding (we assert
1e-12 relative and report whether they are bitwise equal).
"""

import io
import json
import logging
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxvs
from jaxvs.calibration import _sharding

EIGHT_DEVICES = textwrap.dedent(
    """
    import json, os
    os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=8"
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp, numpy as np
    import jaxvs
    from jaxvs.calibration import FrequencyError

    out = {"devices": jax.device_count()}
    mesh = jaxvs.family_mesh()
    n = 16
    w = jnp.linspace(20.0, 80.0, n)[:, None] * jnp.array([1.0, 3.1])
    fam = jaxvs.ModalModel(w, jnp.full((n, 2), 0.03), jnp.ones((n, 2)))
    u = jnp.asarray(np.random.default_rng(0).normal(size=(n, 500)))
    y1 = np.asarray(jaxvs.simulate(fam, u, 1e-3))
    y8 = jaxvs.simulate_sharded(fam, u, 1e-3, mesh=mesh)
    out["sim_sharding"] = list(y8.sharding.spec)
    out["sim_devices"] = len(y8.sharding.device_set)
    out["sim_err"] = float(np.max(np.abs(np.asarray(y8) - y1)) / np.max(np.abs(y1)))
    out["sim_equal"] = bool(np.array_equal(np.asarray(y8), y1))
    shared = np.asarray(jaxvs.simulate_sharded(fam, u[0], 1e-3, mesh=mesh))
    ref = np.asarray(jaxvs.simulate(fam, u[0], 1e-3))
    out["sim_shared_err"] = float(np.max(np.abs(shared - ref)) / np.max(np.abs(ref)))

    omega = jnp.linspace(5.0, 400.0, 120)
    H = jaxvs.frequency_response(fam, omega)
    data = [{"omega": omega, "H": H[i]} for i in range(n)]
    guess = jaxvs.ModalModel(w * 1.02, jnp.full((n, 2), 0.04), jnp.full((n, 2), 0.9))
    r1 = jaxvs.calibrate_family(guess, data, FrequencyError())
    # calibration compiles one executable per device: a 2-device sub-mesh of the 8 keeps
    # this test's compile time in budget (the 8-device mesh is used by the rest)
    r8 = jaxvs.calibrate_family_sharded(guess, data, FrequencyError(), mesh=jaxvs.family_mesh(2))
    out["cal_sharding"] = list(r8.values.sharding.spec)
    out["cal_err"] = float(np.max(np.abs(np.asarray(r8.values) - np.asarray(r1.values))
                                  / np.abs(np.asarray(r1.values))))
    out["cal_cov_err"] = float(np.max(np.abs(np.asarray(r8.covariance) - np.asarray(r1.covariance)))
                               / np.max(np.abs(np.asarray(r1.covariance))))
    out["cal_equal"] = bool(np.array_equal(np.asarray(r8.values), np.asarray(r1.values)))
    out["cal_truth_err"] = float(np.max(np.abs(np.asarray(r8.model.omega_n) - np.asarray(w))))
    out["cal_names"] = list(r8.names) == list(r1.names)

    def peak(p, omega):
        m = jaxvs.ModalModel(p["wn"][None], p["zeta"][None], jnp.ones(1))
        return {"peak": jnp.max(jnp.abs(jaxvs.frequency_response(m, omega)))}

    grid = {"wn": jnp.linspace(50.0, 150.0, 13), "zeta": jnp.array([0.01, 0.05])}
    s8 = jaxvs.sweep(peak, grid, omega, mesh=mesh)   # 26 points: padded to 32
    s1 = jaxvs.sweep(peak, grid, omega)
    out["sweep_equal"] = bool(np.array_equal(s8["peak"], s1["peak"]))
    out["sweep_devices"] = s8.stats["n_devices"]
    errors = {}
    for name, call in [
        ("shard", lambda: jaxvs.shard_family({"a": jnp.ones((10, 3))}, mesh)),
        ("simulate", lambda: jaxvs.simulate_sharded(
            jaxvs.ModalModel(w[:10], jnp.full((10, 2), 0.03), jnp.ones((10, 2))), u[0], 1e-3,
            mesh=mesh)),
        ("calibrate", lambda: jaxvs.calibrate_family_sharded(
            jaxvs.ModalModel(w[:12], jnp.full((12, 2), 0.03), jnp.ones((12, 2))),
            data[:12], FrequencyError(), mesh=mesh)),
    ]:
        try:
            call()
            errors[name] = None
        except ValueError as e:
            errors[name] = str(e)
    out["errors"] = errors
    print("RESULT" + json.dumps(out))
    """
)


@pytest.fixture(scope="module")
def eight_devices():
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    proc = subprocess.run(
        [sys.executable, "-c", EIGHT_DEVICES],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))
    return json.loads(line[len("RESULT") :])


@pytest.mark.slow
def test_eight_devices_agree_with_one(eight_devices):
    out = eight_devices
    assert out["devices"] == 8
    # simulate: each device runs the single-device engine on 2 members
    assert out["sim_sharding"] == ["family"] and out["sim_devices"] == 8
    assert out["sim_err"] <= 1e-12, out
    assert out["sim_shared_err"] <= 1e-12
    # calibration (2 of the 8 devices): same LM iterations per member -> same estimates
    assert out["cal_sharding"] == ["family"]
    assert out["cal_err"] <= 1e-12 and out["cal_cov_err"] <= 1e-10, out
    assert out["cal_names"]
    assert out["cal_truth_err"] < 1e-6  # noiseless data: the true ω_n are recovered
    assert out["sweep_equal"] and out["sweep_devices"] == 8
    print(
        f"\nbitwise equal: simulate {out['sim_equal']}, calibrate {out['cal_equal']}, "
        f"sweep {out['sweep_equal']}"
    )


@pytest.mark.slow
def test_mesh_that_does_not_divide_the_family(eight_devices):
    errors = eight_devices["errors"]
    assert "10 members does not divide over a mesh of 8 devices" in errors["shard"]
    assert "Pad the family to 16 members" in errors["shard"]
    assert "jaxvs.family_mesh(5)" in errors["shard"]
    assert "does not divide" in errors["simulate"]
    assert "12 members does not divide" in errors["calibrate"]
    assert "family_mesh(6)" in errors["calibrate"]


# ----------------------------------------------------------------------------- one device


def _peak(point, omega):
    m = jaxvs.ModalModel(point["wn"][None], point["zeta"][None], jnp.ones(1))
    H = jaxvs.frequency_response(m, omega)
    return {"H": jnp.abs(H), "peak": jnp.max(jnp.abs(H))}


def test_sweep_labels_and_values_against_a_loop():
    omega = jnp.linspace(10.0, 300.0, 120)
    grid = {"wn": jnp.array([50.0, 100.0, 150.0]), "zeta": jnp.array([0.01, 0.02, 0.05, 0.1])}
    res = jaxvs.sweep(
        _peak,
        grid,
        omega,
        mesh=jaxvs.family_mesh(1),
        output_dims={"H": ("omega",)},
        output_coords={"omega": omega},
    )
    assert res.dims == ("wn", "zeta") and res.shape == (3, 4)
    assert res["H"].shape == (3, 4, 120) and res["peak"].shape == (3, 4)
    # oracle: a Python loop over the grid
    for i, wn in enumerate(np.asarray(grid["wn"])):
        for j, z in enumerate(np.asarray(grid["zeta"])):
            ref = _peak({"wn": jnp.asarray(wn), "zeta": jnp.asarray(z)}, omega)
            np.testing.assert_allclose(res["H"][i, j], ref["H"], rtol=1e-13)
    ds = res.to_xarray()
    assert ds["H"].dims == ("wn", "zeta", "omega")
    np.testing.assert_array_equal(ds["peak"].sel(wn=100.0).values, res["peak"][1])
    np.testing.assert_array_equal(ds.coords["omega"].values, np.asarray(omega))


def test_sweep_points_chunks_and_plain_outputs():
    def f(p, args):
        return p["a"] * args["scale"] + p["b"]

    pts = {"a": jnp.arange(7.0), "b": jnp.arange(7.0) * 10}
    res = jaxvs.sweep(f, pts, {"scale": jnp.asarray(2.0)}, product=False, chunk_size=3)
    assert res.dims == ("point",) and res.stats["n_chunks"] == 3
    np.testing.assert_array_equal(res["value"], np.arange(7.0) * 12)
    assert res.output_dims["value"] == ()
    with pytest.raises(ValueError, match="same length"):
        jaxvs.sweep(f, {"a": jnp.ones(3), "b": jnp.ones(2)}, {"scale": 1.0}, product=False)
    with pytest.raises(TypeError, match="non-empty dict"):
        jaxvs.sweep(f, [1, 2], None)
    with pytest.raises(ValueError, match="1-D"):
        jaxvs.sweep(f, {"a": jnp.ones((2, 2))}, None)
    with pytest.raises(ValueError, match="names 2 axes"):
        jaxvs.sweep(
            _peak,
            {"wn": jnp.array([50.0]), "zeta": jnp.array([0.1])},
            jnp.ones(4),
            output_dims={"H": ("a", "b")},
        )


def test_sharding_helpers_and_their_errors():
    mesh = jaxvs.family_mesh(1)
    u = jnp.sin(jnp.arange(300) * 0.05)  # simulate_sharded vs simulate: 8-device test
    placed = jaxvs.shard_family({"x": jnp.ones((4, 2)), "s": jnp.asarray(1.0)}, mesh)
    assert placed["x"].sharding.spec == jax.sharding.PartitionSpec("family")
    with pytest.raises(ValueError, match="one batch axis"):
        jaxvs.simulate_sharded(
            jaxvs.RationalTF(jnp.ones(1), jnp.array([1.0, 2.0])), u, 0.01, mesh=mesh
        )
    with pytest.raises(ValueError, match="n_devices must be"):
        jaxvs.family_mesh(99)
    with pytest.raises(TypeError, match="Mesh"):
        jaxvs.shard_family({"x": jnp.ones(2)}, "cpu")
    with pytest.raises(ValueError, match="leading sizes"):
        jaxvs.shard_family({"x": jnp.ones(2), "y": jnp.ones(3)}, mesh)


# ----------------------------------------------------------------------------- progress


def test_progress_bar_and_structured_log(caplog):
    stream = io.StringIO()
    with caplog.at_level(logging.DEBUG, logger="jaxvs"):
        with jaxvs.Progress("calibration", total=3, unit="start", disable=False, file=stream) as p:
            for k in range(3):
                p.update(1, cost=10.0**-k)
    assert "calibration" in stream.getvalue() and "3/3" in stream.getvalue()
    events = [r.jaxvs for r in caplog.records]
    assert [e["event"] for e in events] == ["start", "update", "update", "update", "end"]
    assert events[2]["step"] == 2 and events[2]["cost"] == 0.1 and events[2]["total"] == 3
    assert events[-1]["task"] == "calibration" and events[-1]["elapsed_s"] >= 0


def test_progress_interrupt_gives_a_clean_message(capsys):
    with pytest.raises(jaxvs.Interrupted, match=r"sweep interrupted after 2/5 points"):
        with jaxvs.Progress("sweep", total=5, unit="point", disable=True) as p:
            p.update(2)
            raise KeyboardInterrupt
    assert "jaxvs: sweep interrupted after 2/5 points" in capsys.readouterr().err
    with jaxvs.Progress("diagnosis", total=4, disable=True, on_interrupt="return") as p:
        p.update(1)
        raise KeyboardInterrupt
    assert p.interrupted and "after 1/4" in p.message
    with pytest.raises(ValueError, match="on_interrupt"):
        jaxvs.Progress("x", on_interrupt="ignore")
    with pytest.raises(RuntimeError, match="inside `with`"):
        jaxvs.Progress("x").update()


def test_sweep_is_interruptible_between_chunks(monkeypatch, capsys):
    calls = []
    real = _sharding.timed_call

    def interrupted_after_one(*args, **kwargs):
        if calls:
            raise KeyboardInterrupt
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(_sharding, "timed_call", interrupted_after_one)
    with pytest.raises(jaxvs.Interrupted, match="sweep interrupted after 2/6 points"):
        jaxvs.sweep(lambda p, a: p["x"] * 2, {"x": jnp.arange(6.0)}, chunk_size=2, progress=False)


def test_log_to_json_lines_and_tick_inside_jit(tmp_path):
    path = tmp_path / "run.jsonl"
    handler = jaxvs.log_to(path, level="DEBUG")
    try:
        with jaxvs.Progress("scan", total=4, disable=True) as p:
            f = jax.jit(lambda x: p.tick(x * 2))
            for k in range(4):
                jax.block_until_ready(f(jnp.asarray(float(k))))
            jax.effects_barrier()
    finally:
        logging.getLogger("jaxvs").removeHandler(handler)
        handler.close()
    assert p.step == 4
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    assert lines[0]["event"] == "start" and lines[-1]["event"] == "end"
    assert lines[-1]["step"] == 4 and lines[0]["level"] == "INFO"
