"""Saving and loading models and calibration results exactly (.eqx, .h5, CSV).

Oracle: bitwise equality of every array leaf and equality of every static field (the
round trip must not re-round, re-validate or re-order anything), and h5py / the csv module
reading the files independently.
"""

import json

import equinox as eqx
import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import LINEAR_MODELS

import jaxvs
from jaxvs.calibration import FrequencyError, positive


def assert_identical(a, b):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb  # same classes and static fields
    for x, y in zip(la, lb):
        assert type(x) is type(y) or (isinstance(x, jax.Array) and isinstance(y, jax.Array))
        assert np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture(scope="module")
def result():
    """A real calibration result: a two-mode accelerance fitted to a noisy FRF."""
    true = jaxvs.ModalModel(
        jnp.array([60.0, 250.0]), jnp.array([0.03, 0.05]), jnp.array([1.0, 3.0])
    )
    omega = jnp.linspace(10.0, 400.0, 300)
    H = jaxvs.frequency_response(true, omega)
    noise = 1e-3 * (jax.random.normal(jax.random.key(0), H.shape) * (1 + 1j))
    guess = jaxvs.ModalModel(
        jnp.array([58.0, 255.0]), jnp.array([0.04, 0.04]), jnp.array([0.8, 3.5])
    )
    guess = eqx.tree_at(lambda m: m.zeta, guess, positive(guess.zeta))
    return jaxvs.calibrate(guess, {"omega": omega, "H": H + noise}, FrequencyError())


@pytest.mark.parametrize("suffix", [".eqx", ".h5"])
def test_calibration_result_round_trips_exactly(tmp_path, result, suffix):
    path = jaxvs.save_model(tmp_path / f"fit{suffix}", result, metadata={"machine": "twin"})
    back = jaxvs.load_model(path)
    assert isinstance(back, jaxvs.CalibrationResult)
    assert_identical(back, result)
    assert back.names == result.names and back.dof == result.dof
    assert bool(back.result == jaxvs.calibration.RESULTS.successful)
    assert back.summary() == result.summary()
    np.testing.assert_array_equal(back.covariance, result.covariance)
    # the loaded model is usable as it was
    w = jnp.linspace(1.0, 500.0, 50)
    np.testing.assert_array_equal(
        jaxvs.frequency_response(back.model, w), jaxvs.frequency_response(result.model, w)
    )
    header = jaxvs.load_header(path)
    assert header["format_version"] == jaxvs.FORMAT_VERSION
    assert header["metadata"] == {"machine": "twin"}
    assert header["object"].endswith(":CalibrationResult")
    summary = header["summary"]["parameters"]
    assert summary[result.names[0]]["value"] == float(result.values[0])


def test_hdf5_file_is_readable_without_jaxvs(tmp_path, result):
    path = jaxvs.save_model(tmp_path / "fit.h5", result)
    with h5py.File(path, "r") as f:  # oracle: plain h5py
        names = [n.decode() if isinstance(n, bytes) else n for n in f["parameters/names"][()]]
        assert tuple(names) == result.names
        np.testing.assert_array_equal(f["parameters/values"][()], result.values)
        np.testing.assert_array_equal(f["parameters/covariance"][()], result.covariance)
        header = json.loads(f.attrs["jaxvs_header"])
        assert header["format"] == "jaxvs-model"
        paths = {f["leaves"][k].attrs["path"] for k in f["leaves"]}
        assert ".covariance" in paths


@pytest.mark.parametrize("name, factory", LINEAR_MODELS)
def test_every_linear_model_round_trips(tmp_path, name, factory):
    model = factory(np.random.default_rng(4))
    assert_identical(jaxvs.load_model(jaxvs.save_model(tmp_path / "m.eqx", model)), model)


def test_containers_scalars_families_and_parametrisations(tmp_path):
    family = jaxvs.GridFamily(
        jnp.array([0.0, 0.5, 1.0]),
        jaxvs.ModalModel(
            jnp.array([[10.0], [12.0], [15.0]]), jnp.full((3, 1), 0.02), jnp.ones((3, 1))
        ),
        method="pchip",
    )
    obj = {
        "family": family,
        "wrapped": positive(jnp.array([1.0, 2.0])),
        "numpy": np.arange(6, dtype=np.int32).reshape(2, 3),
        "scalars": (1, 2.5, float("nan"), float("-inf"), 1 + 2j, np.float64(0.1), None, True),
        "list": ["a", jnp.array(3.0 + 4.0j), jnp.float32(1.5)],
        "function": jax.nn.tanh,
    }
    for suffix in (".eqx", ".h5"):
        back = jaxvs.load_model(jaxvs.save_model(tmp_path / f"obj{suffix}", obj))
        assert set(back) == set(obj)
        assert_identical(back["family"], family)
        assert back["family"].method == "pchip"
        assert_identical(back["wrapped"], obj["wrapped"])
        assert isinstance(back["numpy"], np.ndarray) and back["numpy"].dtype == np.int32
        np.testing.assert_array_equal(back["numpy"], obj["numpy"])
        s = back["scalars"]
        assert s[0] == 1 and s[1] == 2.5 and np.isnan(s[2]) and s[3] == -np.inf
        assert s[4] == 1 + 2j and s[5] == np.float64(0.1) and type(s[5]) is np.float64
        assert s[6:] == (None, True)
        assert back["list"][0] == "a" and back["list"][1].dtype == jnp.complex128
        assert back["list"][2].dtype == jnp.float32
        assert back["function"] is jax.nn.tanh


def test_objects_with_lambdas_load_with_like(tmp_path):
    def law(p, y):
        return jaxvs.ModalModel(p["w"][0] + p["w"][1] * y, p["z"], p["r"])

    params = {"w": jnp.array([[100.0], [20.0]]), "z": jnp.array([0.02]), "r": jnp.array([1.0])}
    family = jaxvs.SmoothFamily(law, params)
    path = jaxvs.save_model(tmp_path / "law.eqx", family)
    assert jaxvs.load_header(path)["needs_like"] == [".law"]
    with pytest.raises(jaxvs.IncompatibleFileError, match="like="):
        jaxvs.load_model(path)
    like = jaxvs.SmoothFamily(law, jax.tree_util.tree_map(jnp.zeros_like, params))
    back = jaxvs.load_model(path, like=like)
    assert_identical(back, family)
    with pytest.raises(ValueError, match="does not match"):
        jaxvs.load_model(path, like=jaxvs.SmoothFamily(law, {**params, "w": jnp.ones((3, 1))}))


def _rewrite_header(path, change):
    raw = path.read_bytes()
    magic, rest = raw.split(b"\n", 1)
    n, rest = rest.split(b"\n", 1)
    header = json.loads(rest[: int(n)])
    change(header)
    blob = json.dumps(header).encode()
    path.write_bytes(magic + b"\n" + b"%d\n" % len(blob) + blob + rest[int(n) :])


def test_incompatible_files_give_clear_errors(tmp_path):
    model = jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 2.0]))
    newer = jaxvs.save_model(tmp_path / "newer.eqx", model)
    _rewrite_header(newer, lambda h: h.update(format_version=99))
    with pytest.raises(jaxvs.IncompatibleFileError, match="format version 99.*Upgrade jaxvs"):
        jaxvs.load_model(newer)
    older = jaxvs.save_model(tmp_path / "older.eqx", model)
    _rewrite_header(older, lambda h: h.update(format_version=0))
    with pytest.raises(jaxvs.IncompatibleFileError, match="version that wrote it"):
        jaxvs.load_model(older)
    changed = jaxvs.save_model(tmp_path / "changed.eqx", model)

    def rename(h):
        fields = h["tree"]["fields"]
        fields["numerator"] = fields.pop("num")

    _rewrite_header(changed, rename)
    with pytest.raises(jaxvs.IncompatibleFileError, match="class changed"):
        jaxvs.load_model(changed)
    other = tmp_path / "record.eqx"
    other.write_bytes(b"not a model")
    with pytest.raises(jaxvs.IncompatibleFileError, match="not a jaxvs model file"):
        jaxvs.load_model(other)
    h5 = tmp_path / "record.h5"
    jaxvs.data.save_hdf5(jaxvs.data.Record({"x": np.ones(4)}, dt=0.1), h5)
    with pytest.raises(jaxvs.IncompatibleFileError, match="jaxvs_header"):
        jaxvs.load_model(h5)
    with pytest.raises(ValueError, match="unknown file type"):
        jaxvs.save_model(tmp_path / "m.pkl", model)
    with pytest.raises(TypeError, match="JSON"):
        jaxvs.save_model(tmp_path / "m.eqx", model, metadata={"a": np.ones(2)})


def test_float64_file_in_32_bit_mode_is_rejected(tmp_path):
    path = jaxvs.save_model(
        tmp_path / "m.eqx", jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 2.0]))
    )
    with jax.enable_x64(False):
        with pytest.raises(ValueError, match="jax_enable_x64"):
            jaxvs.load_model(path)


def test_results_csv_round_trip_exactly(tmp_path, result):
    table, cov = jaxvs.save_results_csv(tmp_path / "fit.csv", result)
    assert cov.name == "fit_covariance.csv"
    back = jaxvs.load_results_csv(table)
    assert back["names"] == result.names
    for key in ("values", "std_errors", "confidence_intervals", "covariance"):
        np.testing.assert_array_equal(back[key], np.asarray(getattr(result, key)))
    # oracle: the csv module sees a plain table
    import csv

    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["name"] for r in rows] == list(result.names)
    assert float(rows[0]["value"]) == float(result.values[0])
    # a batched (family) result gets a member column
    family = jax.tree_util.tree_map(lambda *x: jnp.stack(x), result, result)
    table2, _ = jaxvs.save_results_csv(tmp_path / "family.csv", family)
    back2 = jaxvs.load_results_csv(table2)
    assert back2["values"].shape == (2, len(result.names))
    np.testing.assert_array_equal(back2["covariance"][1], result.covariance)
    with pytest.raises(TypeError, match="CalibrationResult"):
        jaxvs.save_results_csv(tmp_path / "x.csv", result.model)
    with pytest.raises(jaxvs.IncompatibleFileError, match="parameter table"):
        jaxvs.load_results_csv(cov)


def test_saving_traced_values_is_rejected(tmp_path):
    @jax.jit
    def f(x):
        jaxvs.save_model(tmp_path / "t.eqx", {"x": x})
        return x

    with pytest.raises(TypeError, match="outside jax.jit"):
        f(jnp.ones(2))


def test_loaded_module_is_a_working_pytree(tmp_path, result):
    back = jaxvs.load_model(jaxvs.save_model(tmp_path / "m.eqx", result.model))
    g = eqx.filter_grad(lambda m: jnp.sum(jnp.abs(jaxvs.frequency_response(m, jnp.array([60.0])))))(
        back
    )
    assert np.all(np.isfinite(np.asarray(g.omega_n)))
