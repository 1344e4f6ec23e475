"""A model file never makes `load_model` run code: every class, type and function a file
names is looked up in the registries of the safe format (jaxvs / equinox / diffrax / lineax
/ optimistix classes by the module that defines them; jax.nn activations and jax.numpy
elementwise functions), so a crafted header naming `os:system`, `subprocess:run` or
`builtins:eval` is refused before anything is called.

The fuzz target mutates a valid `.eqx` file (its header JSON as structure, and its bytes)
with a seeded generator: every mutant loads to an object or raises `ValueError` (the
`IncompatibleFileError` naming the file), within a time bound, and never calls a spy put in
place of the dangerous functions.
"""

from __future__ import annotations

import builtins
import copy
import json
import os
import random
import subprocess

import jax
import jax.numpy as jnp
import pytest
from bad_input import time_bound

import jaxvs

DANGEROUS = [
    "os:system",
    "subprocess:run",
    "subprocess:Popen",
    "builtins:eval",
    "builtins:exec",
    "builtins:__import__",
    "posix:system",
    "jaxvs._io:os.system",  # an attribute path through a module jaxvs imports
    "jaxvs._io:importlib.import_module",
    "jaxvs.data._loaders:os.remove",
    "jaxvs._cli:main",
    "jaxvs:save_model",  # a jaxvs function that writes files
    "jaxvs.models:FirstOrder.__init__.__globals__",
    "equinox:tree_at",
    "numpy:load",
    "shutil:rmtree",
]


@pytest.fixture
def spies(monkeypatch):
    calls = []

    def spy(name):
        def record(*args, **kwargs):
            calls.append(name)
            raise AssertionError(f"{name} was called")

        return record

    monkeypatch.setattr(os, "system", spy("os.system"))
    monkeypatch.setattr(os, "remove", spy("os.remove"))
    monkeypatch.setattr(subprocess, "run", spy("subprocess.run"))
    monkeypatch.setattr(subprocess, "Popen", spy("subprocess.Popen"))
    monkeypatch.setattr(builtins, "eval", spy("eval"))
    monkeypatch.setattr(builtins, "exec", spy("exec"))
    return calls


def _model():
    return {
        "sensor": jaxvs.models.FirstOrder(20.0, 5.0, 30.0),
        "activation": jax.nn.tanh,
        "tf": jaxvs.RationalTF(jnp.array([1.0]), jnp.array([1.0, 2.0])),
    }


def _split(raw: bytes) -> tuple[bytes, dict, bytes]:
    magic, rest = raw.split(b"\n", 1)
    n, rest = rest.split(b"\n", 1)
    return magic + b"\n", json.loads(rest[: int(n)]), rest[int(n) :]


def _join(magic: bytes, header: dict, leaves: bytes) -> bytes:
    blob = json.dumps(header).encode()
    return magic + b"%d\n" % len(blob) + blob + leaves


@pytest.fixture
def saved(tmp_path):
    jax.config.update("jax_enable_x64", True)
    path = jaxvs.save_model(tmp_path / "m.eqx", _model())
    return _split(path.read_bytes())


def _craft(saved, tmp_path, change) -> os.PathLike:
    magic, header, leaves = saved
    header = copy.deepcopy(header)
    change(header)
    path = tmp_path / "crafted.eqx"
    path.write_bytes(_join(magic, header, leaves))
    return path


@pytest.mark.parametrize("ref", DANGEROUS)
@pytest.mark.parametrize("entry", ["__function__", "__type__", "__class__"])
def test_a_file_naming_a_callable_outside_the_registry_is_refused(
    ref, entry, saved, tmp_path, spies
):
    def change(header):
        tree = header["tree"]["__dict__"]
        if entry == "__class__":
            tree["sensor"]["__class__"] = ref
        else:
            tree["activation"] = {entry: ref}

    path = _craft(saved, tmp_path, change)
    with time_bound(30), pytest.raises(jaxvs.IncompatibleFileError) as err:
        jaxvs.load_model(path)
    message = str(err.value)
    assert "nothing of it was run" in message.lower(), message
    assert "like=" in message or "version" in message
    assert spies == []


def test_the_registry_still_loads_what_save_model_writes(saved, tmp_path, spies):
    magic, header, leaves = saved
    path = tmp_path / "same.eqx"
    path.write_bytes(_join(magic, header, leaves))
    back = jaxvs.load_model(path)
    assert back["activation"] is jax.nn.tanh
    assert isinstance(back["sensor"], jaxvs.models.FirstOrder)
    assert float(back["sensor"].T1) == 30.0


def test_a_function_outside_the_registry_is_not_written_by_name(tmp_path):
    """A user's function is kept out of the file (loaded with `like=`), so a file naming a
    function by `module:name` was always edited."""

    def mine(x):
        return x

    path = jaxvs.save_model(tmp_path / "f.eqx", {"f": os.getcwd, "g": mine})
    assert jaxvs.load_header(path)["needs_like"] == ["['f']", "['g']"]
    with pytest.raises(jaxvs.IncompatibleFileError, match="like="):
        jaxvs.load_model(path)


def test_crafted_array_list_cannot_allocate_more_than_the_file(saved, tmp_path):
    def huge(header):
        header["leaves"][0]["shape"] = [10**6, 10**6]

    with time_bound(30), pytest.raises(jaxvs.IncompatibleFileError, match="bytes.*file has"):
        jaxvs.load_model(_craft(saved, tmp_path, huge))

    def objects(header):
        header["leaves"][0]["dtype"] = "object"

    with pytest.raises(jaxvs.IncompatibleFileError, match="damaged header"):
        jaxvs.load_model(_craft(saved, tmp_path, objects))


# --- fuzz target: seeded mutations of a valid file --------------------------------------------

_VALUES = [None, 0, -1, 2**40, 1.5, "x", "", [], {}, [1, 2], {"__array__": 99}, *DANGEROUS]


def _mutate_json(node, rng: random.Random):
    """One random structural change somewhere in the header tree."""
    if isinstance(node, dict) and node:
        key = rng.choice(list(node))
        action = rng.random()
        if action < 0.3:
            node[key] = rng.choice(_VALUES)
        elif action < 0.4:
            del node[key]
        elif action < 0.5:
            node[rng.choice(["__function__", "__class__", "__type__", key])] = rng.choice(_VALUES)
        else:
            if not _mutate_json(node[key], rng):
                node[key] = rng.choice(_VALUES)
        return True
    if isinstance(node, list) and node:
        i = rng.randrange(len(node))
        if rng.random() < 0.5 and _mutate_json(node[i], rng):
            return True
        node[i] = rng.choice(_VALUES)
        return True
    return False


@pytest.mark.parametrize("seed", range(4))
def test_fuzz_eqx_reader(seed, saved, tmp_path, spies):
    """300 mutants per seed (header structure, header bytes, array bytes, truncation):
    each loads or raises ValueError naming the file, within a time bound."""
    magic, header, leaves = saved
    raw = _join(magic, header, leaves)
    rng = random.Random(seed)
    path = tmp_path / "fuzz.eqx"
    outcomes = {"loaded": 0, "refused": 0}
    for _ in range(int(os.environ.get("JAXVS_FUZZ_EXAMPLES", "75"))):
        kind = rng.choice(["json", "json", "bytes", "truncate", "leaves"])
        if kind == "json":
            mutant = copy.deepcopy(header)
            for _ in range(rng.randint(1, 3)):
                _mutate_json(mutant, rng)
            data = _join(magic, mutant, leaves)
        elif kind == "bytes":
            data = bytearray(raw)
            for _ in range(rng.randint(1, 8)):
                data[rng.randrange(len(data))] = rng.randrange(256)
            data = bytes(data)
        elif kind == "truncate":
            data = raw[: rng.randrange(len(raw))]
        else:
            tail = bytearray(leaves)
            for _ in range(rng.randint(1, 4)):
                tail[rng.randrange(len(tail))] = rng.randrange(256)
            data = _join(magic, header, bytes(tail))
        path.write_bytes(data)
        with time_bound(20):
            try:
                jaxvs.load_model(path)
                outcomes["loaded"] += 1
            except ValueError as e:
                assert str(path) in str(e), e
                outcomes["refused"] += 1
    assert spies == []
    assert outcomes["refused"] > 0
