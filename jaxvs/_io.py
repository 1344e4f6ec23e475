"""Save and load calibrated models and their reports, exactly.

A saved file holds two things:

- a **JSON header**: the file format and its version, the jaxvs version, the user's
  metadata, and a description of the object's structure (which classes, which static
  fields, which arrays where), readable by any JSON tool;
- the **array leaves**, written with `equinox.tree_serialise_leaves` (`.eqx`) or as HDF5
  datasets (`.h5`), bit for bit: float64 stays float64, complex stays complex.

Loading rebuilds the same classes with the same field values without calling their
`__init__` (so nothing is re-validated or re-rounded): a `CalibrationResult` comes back
with its model, estimates, covariance, confidence intervals, names, result code and
statistics equal to the saved ones. Objects with fields that cannot be described in JSON
(e.g. a `SmoothFamily` law written as a lambda) are saved with their arrays; load them
with `like=` (a skeleton of the same structure), as `equinox.tree_deserialise_leaves`.

CSV is the exchange format for spreadsheets: [`save_results_csv`][jaxvs.save_results_csv]
writes the parameter table and the covariance with round-trip-exact decimal numbers.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import datetime
import io
import json
import math
import os
import sys
import types
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._files import regular_file
from ._version import __version__

__all__ = [
    "FORMAT_VERSION",
    "IncompatibleFileError",
    "load_header",
    "load_model",
    "load_results_csv",
    "save_model",
    "save_results_csv",
]

FORMAT_NAME = "jaxvs-model"
# Version history: 1 -- first format (JSON header + tree_serialise_leaves / HDF5 leaves).
FORMAT_VERSION = 1
_MIN_READABLE = 1
_MAGIC = b"JAXVS-MODEL\n"
_EQX_SUFFIXES = (".eqx", ".jaxvs")
_H5_SUFFIXES = (".h5", ".hdf5")

# The safe model format: a file names classes and functions only by text, and loading
# resolves that text against two registries, never by importing or walking arbitrary names:
# - classes: dataclasses (eqx.Modules) defined in the packages below, named by the module
#   that defines them (re-exports and attribute paths through other objects are refused);
#   they are rebuilt without calling any method;
# - functions: the activation and elementwise functions below (`_SAFE_FUNCTIONS`);
# - types: those classes and the scalar types of Python and NumPy.
# Anything else (`os:system`, `subprocess:run`, `builtins:eval`, a user's function) is
# refused before anything is called; a user's own classes load with `like=`.
_MODEL_PACKAGES = ("jaxvs", "equinox", "diffrax", "lineax", "optimistix")
_SCALAR_TYPES = (bool, int, float, complex, str)
_JAX_NN = (
    "celu elu gelu glu hard_sigmoid hard_silu hard_swish hard_tanh identity leaky_relu "
    "log_sigmoid log_softmax logsumexp mish relu relu6 selu sigmoid silu soft_sign softmax "
    "softplus sparse_plus sparse_sigmoid squareplus standardize swish tanh"
)
_JAX_NUMPY = (
    "abs absolute arctan arctanh cbrt cos cosh exp exp2 expm1 log log10 log1p log2 "
    "logaddexp negative sign sin sinc sinh sqrt square tan tanh"
)


class IncompatibleFileError(ValueError):
    """The file was written in a format this jaxvs cannot read (another format version,
    another kind of file, or classes whose fields have changed)."""


# ----------------------------------------------------------------------------- encoding


def _version() -> str:
    return __version__


def _ref(obj: Any) -> str:
    return f"{obj.__module__}:{obj.__qualname__}"


def _float(x: float) -> Any:
    return x if math.isfinite(x) else {"__float__": repr(x)}


class _Encoder:
    def __init__(self):
        self.leaves: list[Any] = []
        self.opaque: list[str] = []

    def array(self, x: Any, path: str) -> dict:
        kind = "jax" if isinstance(x, jax.Array) else "numpy"
        if isinstance(x, jax.core.Tracer):
            raise TypeError(
                f"save_model: {path or 'the object'} is a traced value; save outside jax.jit."
            )
        self.leaves.append(x)
        return {"__array__": len(self.leaves) - 1, "kind": kind}

    def __call__(self, x: Any, path: str = "") -> Any:
        if isinstance(x, (jax.Array, np.ndarray)):
            return self.array(x, path)
        if isinstance(x, np.generic):
            return {"__scalar__": self.array(np.asarray(x), path)["__array__"]}
        if x is None or isinstance(x, (bool, str)):
            return x
        if isinstance(x, int):
            return x
        if isinstance(x, float):
            return _float(x)
        if isinstance(x, complex):
            return {"__complex__": [_float(x.real), _float(x.imag)]}
        if isinstance(x, type):
            return {"__type__": _ref(x)}
        if dataclasses.is_dataclass(x):
            cls = type(x)
            fields = {
                f.name: self(getattr(x, f.name), f"{path}.{f.name}")
                for f in dataclasses.fields(x)
                if hasattr(x, f.name)
            }
            return {"__class__": _ref(cls), "fields": fields}
        if isinstance(x, (dict, types.MappingProxyType)):
            bad = [k for k in x if not isinstance(k, str)]
            if bad:
                raise TypeError(
                    f"save_model: {path or 'the object'} is a dict with a non-string key "
                    f"{bad[0]!r}; use string keys."
                )
            # keys in sorted order, as JAX flattens dicts (so `like=` lines up)
            return {"__dict__": {k: self(x[k], f"{path}[{k!r}]") for k in sorted(x)}}
        if isinstance(x, list):
            return {"__list__": [self(v, f"{path}[{i}]") for i, v in enumerate(x)]}
        if isinstance(x, tuple):
            return {"__tuple__": [self(v, f"{path}[{i}]") for i, v in enumerate(x)]}
        if isinstance(x, (types.FunctionType, types.BuiltinFunctionType)) or (
            callable(x) and hasattr(x, "__qualname__") and hasattr(x, "__module__")
        ):
            qual = getattr(x, "__qualname__", "")
            if "<lambda>" not in qual and "<locals>" not in qual and _resolves(x):
                return {"__function__": _ref(x)}
        # not describable in JSON: kept out of the file, supplied by `like=` on load
        self.opaque.append(path or "the object")
        return {"__opaque__": repr(x)[:200]}


def _resolves(obj: Any) -> bool:
    """Whether the safe format can name `obj` (a function of the registry)."""
    try:
        return _safe_functions().get(_ref(obj)) is obj
    except Exception:
        return False


_FUNCTIONS: dict[str, Any] = {}


def _safe_functions() -> dict[str, Any]:
    """The functions a model file may name: `module:qualname` -> the function."""
    if not _FUNCTIONS:
        for namespace, names in ((jax.nn, _JAX_NN), (jnp, _JAX_NUMPY)):
            for name in names.split():
                fn = getattr(namespace, name, None)
                if fn is not None:
                    with contextlib.suppress(AttributeError):
                        _FUNCTIONS[_ref(fn)] = fn
    return _FUNCTIONS


def _refused(ref: Any, what: str) -> IncompatibleFileError:
    return IncompatibleFileError(
        f"load_model: the file names {what} {ref!r}, which is not a jaxvs model {what}; a "
        "model file may only name the classes of jaxvs, equinox, diffrax, lineax and "
        "optimistix and the activation functions of jax.nn / elementwise functions of "
        "jax.numpy, so the file was edited or not written by jaxvs.save_model. Nothing of it "
        "was run. If you trust it and it holds your own classes, load it with "
        "like=<an object of the same structure>."
    )


def _split_ref(ref: Any, what: str) -> tuple[str, str]:
    if not isinstance(ref, str) or ref.count(":") != 1:
        raise _refused(ref, what)
    module_name, qualname = ref.split(":")
    parts = [*module_name.split("."), *qualname.split(".")]
    if not all(p.isidentifier() and not p.startswith("__") for p in parts):
        raise _refused(ref, what)
    return module_name, qualname


def _resolve_class(ref: Any, what: str = "class") -> type:
    """A class defined in one of `_MODEL_PACKAGES`, named by the module that defines it (a
    dataclass, as it is rebuilt field by field, unless it is only named as a type)."""
    module_name, qualname = _split_ref(ref, what)
    if module_name.split(".")[0] not in _MODEL_PACKAGES:
        raise _refused(ref, what)
    # never imported on the file's word: jaxvs and the packages it builds on are loaded
    module = sys.modules.get(module_name)
    if module is None:
        raise IncompatibleFileError(
            f"load_model: the file names the class {ref}, whose module is not part of this "
            "installation (nothing of it was run); it was written by another version of the "
            "package or edited. Load it with the version that wrote it "
            "(load_header(path)['jaxvs_version']) or re-run the calibration."
        )
    obj: Any = module
    for part in qualname.split("."):
        obj = vars(obj).get(part) if isinstance(obj, type | types.ModuleType) else None
        if obj is None:
            raise IncompatibleFileError(
                f"load_model: {ref} is not a class of this installation (nothing of it was "
                "run); the file was written against another version of it. Load it with "
                "the version that wrote it (load_header(path)['jaxvs_version']) or re-run "
                "the calibration."
            )
    if not (
        isinstance(obj, type)
        and (what == "type" or dataclasses.is_dataclass(obj))
        and obj.__module__ == module_name
        and obj.__qualname__ == qualname
    ):
        raise _refused(ref, what)
    return obj


def _resolve_type(ref: Any) -> type:
    for scalar in _SCALAR_TYPES:
        if ref == _ref(scalar):
            return scalar
    if isinstance(ref, str) and ref.startswith("numpy:"):
        name = ref.partition(":")[2]
        obj = getattr(np, name, None) if name.isidentifier() else None
        if isinstance(obj, type) and issubclass(obj, np.generic) and _ref(obj) == ref:
            return obj
    return _resolve_class(ref, "type")


def _resolve_function(ref: Any) -> Any:
    fn = _safe_functions().get(ref) if isinstance(ref, str) else None
    if fn is None:
        raise _refused(ref, "function")
    return fn


class _Decoder:
    def __init__(self, leaves: list[Any]):
        self.leaves = leaves

    def __call__(self, d: Any) -> Any:
        if d is None or isinstance(d, (bool, str, int, float)):
            return d
        if isinstance(d, list):  # never written, but tolerate
            return [self(v) for v in d]
        if "__array__" in d:
            return self.leaves[d["__array__"]]
        if "__scalar__" in d:
            return self.leaves[d["__scalar__"]][()]
        if "__float__" in d:
            return float(d["__float__"])
        if "__complex__" in d:
            re, im = (self(v) for v in d["__complex__"])
            return complex(re, im)
        if not isinstance(d, dict):
            raise IncompatibleFileError(f"load_model: unknown entry in the header: {d!r}.")
        if "__type__" in d:
            return _resolve_type(d["__type__"])
        if "__function__" in d:
            return _resolve_function(d["__function__"])
        if "__dict__" in d:
            return {k: self(v) for k, v in d["__dict__"].items()}
        if "__list__" in d:
            return [self(v) for v in d["__list__"]]
        if "__tuple__" in d:
            return tuple(self(v) for v in d["__tuple__"])
        if "__class__" in d:
            cls = _resolve_class(d["__class__"])
            if not isinstance(d.get("fields"), dict):
                raise IncompatibleFileError(f"load_model: {d['__class__']} has no fields entry.")
            saved = set(d["fields"])
            current = {f.name for f in dataclasses.fields(cls)}
            if saved != current:
                raise IncompatibleFileError(
                    f"load_model: the saved {cls.__qualname__} has fields {sorted(saved)} but "
                    f"this version's has {sorted(current)}; the class changed since the file "
                    "was written. Load it with the jaxvs version that wrote it (see "
                    "load_header(path)['jaxvs_version']) or re-run the calibration."
                )
            obj = object.__new__(cls)
            for name, value in d["fields"].items():
                object.__setattr__(obj, name, self(value))
            return obj
        if "__opaque__" in d:
            raise IncompatibleFileError(
                f"load_model: the file holds a value that cannot be rebuilt from JSON "
                f"({d['__opaque__']}); pass like=<an object of the same structure>."
            )
        raise IncompatibleFileError(f"load_model: unknown entry in the header: {d!r}.")


def _jsonable(metadata: Any, what: str) -> Any:
    try:
        return json.loads(json.dumps(metadata, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise TypeError(
            f"save_model: {what} must be JSON-serialisable (str, numbers, lists, dicts of "
            f"them); {e}. Keep arrays in the object itself."
        ) from e


def _summary(obj: Any) -> dict | None:
    """A human-readable digest of a calibration result in the header (not used to load)."""
    names = getattr(obj, "names", None)
    values = getattr(obj, "values", None)
    if isinstance(names, tuple) and isinstance(values, (jax.Array, np.ndarray)):
        v = np.asarray(values)
        if v.ndim == 1 and v.shape[0] == len(names):
            se = np.asarray(getattr(obj, "std_errors", np.full(v.shape, np.nan)))
            return {
                "parameters": {
                    n: {"value": _float(float(a)), "std_error": _float(float(b))}
                    for n, a, b in zip(names, v, se)
                }
            }
    return None


def _header(obj: Any, metadata: Mapping[str, Any] | None) -> tuple[dict, list[Any]]:
    enc = _Encoder()
    tree = enc(obj)
    leaves = enc.leaves
    header = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "jaxvs_version": _version(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "object": _ref(type(obj)),
        "metadata": _jsonable(dict(metadata or {}), "metadata"),
        "needs_like": enc.opaque,
        "leaves": [
            {
                "shape": list(x.shape),
                "dtype": str(x.dtype),
                "kind": "jax" if isinstance(x, jax.Array) else "numpy",
            }
            for x in leaves
        ],
        "tree": tree,
    }
    summary = _summary(obj)
    if summary is not None:
        header["summary"] = summary
    return header, leaves


def _check_header(header: Any, path: Path) -> dict:
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise IncompatibleFileError(
            f"load_model: {path} is not a jaxvs model file (no '{FORMAT_NAME}' header). "
            "Records load with jaxvs.data.load; results written by save_results_csv with "
            "load_results_csv."
        )
    version = header.get("format_version")
    if not isinstance(version, int) or not _MIN_READABLE <= version <= FORMAT_VERSION:
        newer = isinstance(version, int) and version > FORMAT_VERSION
        raise IncompatibleFileError(
            f"load_model: {path} has format version {version!r} (written by jaxvs "
            f"{header.get('jaxvs_version', '?')}); this jaxvs {_version()} reads versions "
            f"{_MIN_READABLE}..{FORMAT_VERSION}. "
            + (
                "Upgrade jaxvs to read it."
                if newer
                else "Load it with the jaxvs version that wrote it and save it again."
            )
        )
    return header


def _check_leaves(header: dict, path: Path, size: int) -> None:
    """The header's array list is well formed, numeric, and its arrays fit in the file (a
    damaged or crafted header cannot make the reader allocate more than the file holds)."""
    leaves = header.get("leaves")
    tree = header.get("tree")
    damaged = f"load_model: {path} has a damaged header"
    fix = "Write it again with jaxvs.save_model."
    if not isinstance(leaves, list) or tree is None:
        raise IncompatibleFileError(f"{damaged} (no array list or tree). {fix}")
    total = 0
    for i, leaf in enumerate(leaves):
        try:
            dtype = np.dtype(leaf["dtype"])
            shape = [int(n) for n in leaf["shape"]]
            ok = (
                isinstance(leaf["dtype"], str)
                and dtype.kind in "biufc"
                and leaf["kind"] in ("jax", "numpy")
                and all(type(n) is int and n >= 0 for n in leaf["shape"])
            )
        except (KeyError, TypeError, ValueError):
            ok = False
        if not ok:
            raise IncompatibleFileError(f"{damaged} (array {i}: {str(leaf)[:80]}). {fix}")
        total += math.prod(shape) * dtype.itemsize
    if total > size:
        raise IncompatibleFileError(
            f"{damaged}: its arrays would take {total} bytes but the file has {size}; it is "
            f"truncated or edited. {fix}"
        )


def _check_x64(header: dict, path: Path) -> None:
    wide = {"float64", "complex128", "int64", "uint64"}
    if not jax.config.jax_enable_x64 and any(
        leaf["dtype"] in wide and leaf["kind"] == "jax" for leaf in header["leaves"]
    ):
        raise ValueError(
            f"load_model: {path} holds float64/complex128 arrays but JAX runs in 32-bit mode, "
            "which would round them. Enable 64-bit first: "
            'jax.config.update("jax_enable_x64", True).'
        )


def _placeholders(header: dict) -> list[Any]:
    out = []
    for leaf in header["leaves"]:
        dtype = np.dtype(leaf["dtype"])
        z = np.zeros(leaf["shape"], dtype)
        out.append(jnp.asarray(z) if leaf["kind"] == "jax" else z)
    return out


def _suffix(path: Path, who: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in _EQX_SUFFIXES + _H5_SUFFIXES:
        raise ValueError(
            f"{who}: unknown file type {suffix!r} for {path}; use one of "
            f"{_EQX_SUFFIXES + _H5_SUFFIXES} (.eqx: equinox serialisation, .h5: HDF5)."
        )
    return suffix


# ----------------------------------------------------------------------------- public API


def save_model(
    path: str | os.PathLike, obj: Any, *, metadata: Mapping[str, Any] | None = None
) -> Path:
    """Save a model, a calibration result or any pytree of them, exactly.

    **Arguments:**

    - `path`: the file; its suffix picks the format: `.eqx` (or `.jaxvs`) -- a JSON header
      followed by `equinox.tree_serialise_leaves`; `.h5` (or `.hdf5`) -- HDF5 with the
      header as the root attribute `jaxvs_header`, the arrays as datasets `leaves/<i>`
      (attribute `path`: where the array sits in the object) and, for a calibration
      result, a readable `parameters` group (names, values, std_errors,
      confidence_intervals, covariance).
    - `obj`: an `eqx.Module` (a jaxvs model, a
      [`CalibrationResult`][jaxvs.calibration.CalibrationResult], a family, a neural
      network) or a dataclass, dict, list or tuple of them.
    - `metadata`: JSON-serialisable information to keep with it (experiment, operator,
      units, ...), returned by [`load_header`][jaxvs.load_header].

    **Returns:**

    The path written.

    **Example:**

    ```python
    result = jaxvs.calibrate(model, record, jaxvs.calibration.SimulationError("u", "y"))
    jaxvs.save_model("drive.eqx", result, metadata={"machine": "EMPS", "set": "estimation"})
    again = jaxvs.load_model("drive.eqx")      # same model, values, covariance, names
    ```
    """
    path = Path(path)
    suffix = _suffix(path, "save_model")
    header, leaves = _header(obj, metadata)
    blob = json.dumps(header, allow_nan=False).encode()
    if suffix in _EQX_SUFFIXES:
        buf = io.BytesIO()
        eqx.tree_serialise_leaves(buf, leaves)
        with open(path, "wb") as f:
            f.write(_MAGIC)
            f.write(b"%d\n" % len(blob))
            f.write(blob)
            f.write(buf.getvalue())
        return path
    import h5py

    paths = _leaf_paths(obj, len(leaves))
    with h5py.File(path, "w") as f:
        f.attrs["jaxvs_header"] = blob.decode()
        group = f.create_group("leaves")
        for i, (x, p) in enumerate(zip(leaves, paths)):
            ds = group.create_dataset(str(i), data=np.asarray(x))
            ds.attrs["path"] = p
        _write_h5_parameters(f, obj)
    return path


def _leaf_paths(obj: Any, n: int) -> list[str]:
    enc = _Encoder()
    paths: list[str] = []
    original = enc.array

    def array(x, path):
        paths.append(path or ".")
        return original(x, path)

    enc.array = array  # type: ignore[method-assign]
    enc(obj)
    return paths if len(paths) == n else [""] * n


def _write_h5_parameters(f: Any, obj: Any) -> None:
    names = getattr(obj, "names", None)
    if not isinstance(names, tuple) or not hasattr(obj, "values"):
        return
    g = f.create_group("parameters")
    g.create_dataset("names", data=np.array(names, dtype=object), dtype=_h5_str())
    for field in ("values", "std_errors", "confidence_intervals", "covariance", "correlation"):
        if hasattr(obj, field):
            g.create_dataset(field, data=np.asarray(getattr(obj, field)))
    g.attrs["note"] = "readable copy; load_model reads the object from /leaves"


def _h5_str():
    import h5py

    return h5py.string_dtype()


def load_header(path: str | os.PathLike) -> dict:
    """The JSON header of a file written by [`save_model`][jaxvs.save_model].

    **Returns:**

    A dict with `format`, `format_version`, `jaxvs_version`, `created` (UTC, ISO 8601),
    `object` (the saved class), `metadata` (as given to `save_model`), `leaves` (shape and
    dtype of each array), `tree` (the structure) and, for calibration results, a readable
    `summary` of the estimates.

    **Raises:**

    [`IncompatibleFileError`][jaxvs.IncompatibleFileError] for a file of another kind or
    format version.
    """
    path = regular_file(path, "load_header")
    suffix = _suffix(path, "load_header")
    if suffix in _EQX_SUFFIXES:
        with open(path, "rb") as f:
            header, _ = _read_eqx_header(f, path)
    else:
        import h5py

        with h5py.File(path, "r") as f:
            header = _h5_header(f, path)
    return _check_header(header, path)


def _read_eqx_header(f: Any, path: Path) -> tuple[Any, int]:
    magic = f.read(len(_MAGIC))
    if magic != _MAGIC:
        raise IncompatibleFileError(
            f"load_model: {path} is not a jaxvs model file (it does not start with "
            f"{_MAGIC!r}). Write it with jaxvs.save_model."
        )
    line = f.readline(24)  # the header's length: a short decimal number
    try:
        n = int(line)
        if n < 2:
            raise ValueError(f"header length {n}")
        header = json.loads(f.read(n).decode())
    except (ValueError, RecursionError) as e:
        raise IncompatibleFileError(
            f"load_model: {path} has a damaged header ({type(e).__name__}: {str(e)[:120]}). "
            "Write it again with jaxvs.save_model."
        ) from None
    return header, f.tell()


def _h5_header(f: Any, path: Path) -> Any:
    raw = f.attrs.get("jaxvs_header")
    if raw is None:
        raise IncompatibleFileError(
            f"load_model: {path} has no 'jaxvs_header' attribute; it was not written by "
            "jaxvs.save_model (records written by jaxvs.data.save_hdf5 load with "
            "jaxvs.data.load_hdf5)."
        )
    try:
        return json.loads(raw)
    except ValueError as e:
        raise IncompatibleFileError(f"load_model: {path} has a damaged header ({e}).") from e


def load_model(path: str | os.PathLike, *, like: Any = None) -> Any:
    """Load what [`save_model`][jaxvs.save_model] wrote, exactly as it was saved.

    **Arguments:**

    - `path`: a `.eqx`/`.jaxvs` or `.h5`/`.hdf5` file from `save_model`.
    - `like`: optional object of the same structure (e.g. the initial model); its
      structure and static fields are used and only the arrays are read from the file,
      as `equinox.tree_deserialise_leaves`. Needed only for objects holding values that
      JSON cannot describe (lambdas, closures); `load_header(path)["needs_like"]` lists them.

    **Returns:**

    The saved object: same classes, static fields and array values (dtype and bits).

    **Raises:**

    [`IncompatibleFileError`][jaxvs.IncompatibleFileError] (a `ValueError`) for a file of
    another kind, of a format version this jaxvs cannot read, or of classes whose fields
    changed; `ValueError` when float64 arrays would be loaded with 64-bit JAX disabled, or
    when `like` does not match the saved arrays.
    """
    path = regular_file(path, "load_model")
    suffix = _suffix(path, "load_model")
    if suffix in _EQX_SUFFIXES:
        with open(path, "rb") as f:
            header, _ = _read_eqx_header(f, path)
            header = _check_header(header, path)
            _check_leaves(header, path, os.fstat(f.fileno()).st_size)
            _check_x64(header, path)
            try:
                leaves = eqx.tree_deserialise_leaves(f, _placeholders(header))
            except Exception as e:  # numpy / equinox raise assorted errors on damaged arrays
                raise IncompatibleFileError(
                    f"load_model: {path} has damaged arrays ({type(e).__name__}: {e}); it is "
                    "truncated or edited. Write it again with jaxvs.save_model."
                ) from None
    else:
        import h5py

        with h5py.File(path, "r") as f:
            header = _check_header(_h5_header(f, path), path)
            _check_leaves(header, path, 2**62)  # HDF5 arrays are sized by h5py itself
            _check_x64(header, path)
            leaves = []
            for i, spec in enumerate(header["leaves"]):
                x = np.array(f["leaves"][str(i)][()], dtype=np.dtype(spec["dtype"]))
                x = x.reshape(spec["shape"])
                leaves.append(jnp.asarray(x) if spec["kind"] == "jax" else x)
    if like is not None:
        return _fill_like(like, leaves, path)
    try:
        return _Decoder(leaves)(header["tree"])
    except IncompatibleFileError as e:  # say which file
        raise IncompatibleFileError(
            f"load_model: {path}: {str(e).removeprefix('load_model: ')}"
        ) from None
    except (KeyError, IndexError, TypeError, AttributeError, RecursionError) as e:
        raise IncompatibleFileError(
            f"load_model: {path} has a damaged header ({type(e).__name__}: {str(e)[:120]}). "
            "Write it again with jaxvs.save_model."
        ) from None


def _fill_like(like: Any, leaves: list[Any], path: Path) -> Any:
    enc = _Encoder()
    enc(like)
    mine = enc.leaves
    if len(mine) != len(leaves) or any(
        np.shape(a) != np.shape(b) or np.asarray(a).dtype != np.asarray(b).dtype
        for a, b in zip(mine, leaves)
    ):
        raise ValueError(
            f"load_model: `like` does not match {path}: it has {len(mine)} arrays "
            f"{[tuple(np.shape(a)) for a in mine][:6]}..., the file {len(leaves)} "
            f"{[tuple(np.shape(b)) for b in leaves][:6]}.... Give an object built like the "
            "saved one (same class, orders, modes, family size)."
        )
    ids = {id(a): i for i, a in enumerate(mine)}

    def swap(x):
        return leaves[ids[id(x)]] if id(x) in ids else x

    return jax.tree_util.tree_map(swap, like, is_leaf=lambda x: id(x) in ids)


# ----------------------------------------------------------------------------- CSV


def save_results_csv(path: str | os.PathLike, result: Any) -> tuple[Path, Path]:
    """Write a calibration result's parameter table and covariance as CSV, exactly.

    Numbers are written with Python's shortest round-trip representation (`repr`), so
    [`load_results_csv`][jaxvs.load_results_csv] reads back the same float64 values.

    **Arguments:**

    - `path`: the parameter table, e.g. `"fit.csv"`, with columns `name, value,
      std_error, ci_low, ci_high` (a batched result, e.g. from `calibrate_family`, has a
      leading `member` column). The covariance goes to `<stem>_covariance.csv` beside it
      (first column the row name, header the column names; batched: a `member` column).
    - `result`: a [`CalibrationResult`][jaxvs.calibration.CalibrationResult] (anything with `names`,
      `values`, `std_errors`, `confidence_intervals`, `covariance`).

    **Returns:**

    The two paths written.
    """
    for field in ("names", "values", "std_errors", "confidence_intervals", "covariance"):
        if not hasattr(result, field):
            raise TypeError(
                f"save_results_csv: expected a CalibrationResult; {type(result).__name__} has "
                f"no {field!r}. Save other objects with save_model."
            )
    path = Path(path)
    cov_path = path.with_name(path.stem + "_covariance" + (path.suffix or ".csv"))
    names = list(result.names)
    values = np.asarray(result.values)
    se = np.asarray(result.std_errors)
    ci = np.asarray(result.confidence_intervals)
    cov = np.asarray(result.covariance)
    if values.ndim not in (1, 2):
        raise ValueError(
            f"save_results_csv: values of shape {values.shape}: give one result or a family "
            "with one batch axis."
        )
    batched = values.ndim == 2
    if not batched:
        values, se, ci, cov = values[None], se[None], ci[None], cov[None]
    r = lambda x: repr(float(x))  # noqa: E731
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            (["member"] if batched else []) + ["name", "value", "std_error", "ci_low", "ci_high"]
        )
        for m in range(values.shape[0]):
            for j, n in enumerate(names):
                row = [n, r(values[m, j]), r(se[m, j]), r(ci[m, j, 0]), r(ci[m, j, 1])]
                w.writerow(([m] if batched else []) + row)
    with open(cov_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow((["member"] if batched else []) + ["name"] + names)
        for m in range(values.shape[0]):
            for j, n in enumerate(names):
                w.writerow(([m] if batched else []) + [n] + [r(c) for c in cov[m, j]])
    return path, cov_path


def load_results_csv(path: str | os.PathLike) -> dict[str, Any]:
    """Read a parameter table written by [`save_results_csv`][jaxvs.save_results_csv].

    **Returns:**

    A dict with `names` (tuple), `values`, `std_errors`, `confidence_intervals` (`(p, 2)`)
    and `covariance` (`(p, p)`, read from `<stem>_covariance.csv` when present) as float64
    numpy arrays; a batched table gives a leading member axis on every array.
    """
    path = Path(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or rows[0][-5:] != ["name", "value", "std_error", "ci_low", "ci_high"]:
        raise IncompatibleFileError(
            f"load_results_csv: {path} is not a parameter table from save_results_csv "
            "(expected the header name,value,std_error,ci_low,ci_high)."
        )
    batched = rows[0][0] == "member"
    body = rows[1:]
    members = sorted({int(row[0]) for row in body}) if batched else [0]
    k = 1 if batched else 0
    names = tuple(dict.fromkeys(row[k] for row in body))
    p = len(names)
    table = np.array([[float(x) for x in row[k + 1 : k + 5]] for row in body]).reshape(
        len(members), p, 4
    )
    out: dict[str, Any] = {
        "names": names,
        "values": table[..., 0],
        "std_errors": table[..., 1],
        "confidence_intervals": table[..., 2:4],
    }
    cov_path = path.with_name(path.stem + "_covariance" + (path.suffix or ".csv"))
    if cov_path.exists():
        with open(cov_path, newline="") as f:
            crow = list(csv.reader(f))[1:]
        out["covariance"] = np.array([[float(x) for x in row[k + 1 :]] for row in crow]).reshape(
            len(members), p, p
        )
    if not batched:
        out = {key: (v[0] if isinstance(v, np.ndarray) else v) for key, v in out.items()}
    return out
