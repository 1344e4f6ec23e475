"""Helpers shared by every folder of jaxvs: ahead-of-time compilation with a small cache
(compile and run time reported separately, measured outside `jit`, as the benchmarks do),
the tracer test, and a matrix exponential that compiles fast."""

import collections
import concurrent.futures
import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from jaxtyping import Array, Float

__all__ = [
    "as_real",
    "check_finite",
    "check_physical",
    "concrete",
    "expm",
    "first_not_increasing",
    "input_columns",
    "is_traced",
    "json_safe",
    "legendre",
    "options_object",
    "polymul",
    "real_array",
    "timed_call",
]

_CACHE: collections.OrderedDict = collections.OrderedDict()
_CACHE_SIZE = 64


def as_real(x: Any, what: str) -> Array:
    """`x` as a real floating JAX array (integers promoted to the default float).

    **Arguments:** `x`, anything `jnp.asarray` takes; `what`, how the error names it
    (e.g. ``"ModalModel: omega"``).

    **Raises:** `TypeError` for complex input: a parameter or signal of a machine model is
    real; take `.real` or `abs()` explicitly if that is what was meant."""
    if not isinstance(x, jax.Array) and np.asarray(x).dtype.kind in "USOV":
        raise TypeError(
            f"{what} must be real numbers; got {np.asarray(x).dtype} values. Convert them "
            "with np.asarray(..., dtype=float)."
        )
    return real_array(
        x, f"{what} must be real; got a complex array (take .real or abs() explicitly)."
    )


def real_array(x: Any, complex_error: str) -> Array:
    """`x` as a JAX array of a real floating dtype (integers promoted to the default float).

    **Raises:** `TypeError(complex_error)` for complex input; the caller's message names the
    argument and the fix."""
    x = jnp.asarray(x)
    if jnp.iscomplexobj(x):
        raise TypeError(complex_error)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    return x


def first_not_increasing(x: np.ndarray) -> int | None:
    """The index `k` of the first sample with `x[k] <= x[k - 1]` in a 1-D grid (time or
    frequency), `None` when `x` is strictly increasing; the caller's error names both."""
    not_increasing = np.diff(x) <= 0
    return int(np.argmax(not_increasing)) + 1 if not_increasing.any() else None


def input_columns(u: Any, n_inputs: int, where: str) -> Any:
    """The inputs `u` (a NumPy or JAX array) as columns `(time, n_inputs)`: one 1-D input is
    made a column; any other shape is refused with a `ValueError` naming `where`."""
    if u.ndim == 1 and n_inputs == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[1] != n_inputs:
        raise ValueError(
            f"{where}: inputs must have shape (time, {n_inputs}) (one column per input); "
            f"got {u.shape}."
        )
    return u


def concrete(x: Any) -> np.ndarray | None:
    """`x` as a NumPy array when its value is known, `None` when it is traced (under `jit`)."""
    if isinstance(x, jax.core.Tracer):
        return None
    try:
        return np.asarray(x)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return None


def check_finite(x: Any, what: str, fix: str, *, unit: str = "value(s)") -> Any:
    """Refuse NaN/inf in `x`, which would otherwise spread silently through the result.

    Eagerly: `ValueError` "`what` has n non-finite `unit`, the first at index (i, ...).
    `fix`". Under `jit` (traced `x`): `x` wrapped in `eqx.error_if` with "`what` contains
    NaN or inf. `fix`". Returns `x` unchanged otherwise."""
    value = concrete(x)
    if value is None:
        return eqx.error_if(x, ~jnp.all(jnp.isfinite(x)), f"{what} contains NaN or inf. {fix}")
    bad = ~np.isfinite(value)
    if bad.any():
        index = tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), bad.shape))
        raise ValueError(
            f"{what} has {int(bad.sum())} non-finite {unit}, the first at index {index}. {fix}"
        )
    return x


def check_physical(x: Any, what: str, *, strict: bool = True, unit: str = "") -> Any:
    """The one rule of every model constructor for a physical parameter that cannot be
    negative (a mass, a friction level, a resistance, a time constant): refuse a value
    `<= 0` (`strict`) or `< 0` with a `ValueError` naming it, the value and the fix.

    Only values given by the user are checked -- Python numbers, lists and NumPy arrays; a
    JAX array is a computed value (a fit's trial point, a diagnosis effect's signed
    parameter, a model built inside `jit`) and passes unchanged: fits judge their results
    with their own admissibility checks. Returns `x`."""
    if isinstance(x, jax.Array):
        return x
    value = concrete(x)
    if value is None:
        return x
    value = np.asarray(value, float)
    bad = value <= 0 if strict else value < 0  # NaN: left to the finite-value check
    if not bad.any():
        return x
    got = float(value[bad].flat[0]) if value.ndim else float(value)
    bound = "> 0" if strict else ">= 0"
    raise ValueError(
        f"{what} must be {bound}{' ' + unit if unit else ''} (a physical value that cannot be "
        f"negative); got {got:g}. Give its magnitude: the direction of a force comes from the "
        "velocity, and a decay from the model itself."
    )


def require_x64(who: str, why: str) -> None:
    """Refuse to run `who` in JAX's default 32-bit mode, where it would round silently.

    Raises `ValueError` "`who`: needs float64 (`why`). Enable it at the start of your
    program with jax.config.update(...)". Library code never enables it itself (STYLE)."""
    if jax.dtypes.canonicalize_dtype(jnp.float64) != jnp.float64:
        raise ValueError(
            f"{who}: needs float64 ({why}). Enable it at the start of your program with "
            'jax.config.update("jax_enable_x64", True).'
        )


def is_traced(tree: Any) -> bool:
    """Whether any leaf of `tree` is a JAX tracer (we are inside `jit`/`vmap`/`grad`)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _local(x: Any, device: Any) -> Any:
    """The block of a global array that lives on `device` (or the whole local value)."""
    if isinstance(x, jax.Array) and len(x.sharding.device_set) > 1:
        return next(s.data for s in x.addressable_shards if s.device == device)
    return jax.device_put(x, device)


def _lapack(executable: Any) -> bool:
    try:
        return "lapack" in executable.as_text()
    except Exception:  # pragma: no cover - no HLO text: assume the worst
        return True


def _hashable(key: Any) -> Any:
    try:
        hash(key)
    except TypeError:  # an unhashable static leaf: compile without caching
        return None
    return key


def timed_call(fn: Callable, *args: Any, mesh: Mesh | None = None) -> tuple[Any, float, float]:
    """Compile `fn(*args)` (arrays traced, everything else static) and run it once; with a
    `mesh`, once per device on that device's block.

    With a `mesh`, the array arguments are global arrays laid over `mesh` along axis 0 (or
    replicated); every device of this process runs the compiled `fn` on its own block,
    asynchronously, and the outputs (members axis first) are assembled into global arrays
    sharded the same way. No collective operation is involved, so no device waits for
    another, and each member is computed exactly as on one device. (`jax.shard_map` and
    XLA's SPMD partitioner are the usual tools; the first conflicts with lineax's
    structure checks inside the solvers, the second inserts an all-reduce into the
    vmapped solver's loop condition, which can stall on small CPU hosts.)

    Compiled executables are cached (least recently used first out) by function, static
    arguments, shapes and device.

    **Returns:**

    `(output, compile_time, run_time)` in seconds; `compile_time` is 0 when every
    executable was cached.
    """
    dynamic, static = eqx.partition(args, eqx.is_array)
    dyn_leaves, dyn_def = jax.tree_util.tree_flatten(dynamic)
    st_leaves, st_def = jax.tree_util.tree_flatten(static)
    if mesh is None:
        devices = [None]
    else:
        devices = [d for d in mesh.devices.flat if d.process_index == jax.process_index()]
    per_device = [dyn_leaves if d is None else [_local(x, d) for x in dyn_leaves] for d in devices]
    avals = tuple(
        (x.shape, str(x.dtype), bool(getattr(x, "weak_type", False))) for x in per_device[0]
    )
    out_static: list[Any] = []

    def run(dyn):
        out = fn(*eqx.combine(dyn, static))
        out_dyn, out_st = eqx.partition(out, eqx.is_array)
        out_static.append(out_st)
        return out_dyn

    keys = [_hashable((fn, dyn_def, st_def, tuple(st_leaves), avals, d)) for d in devices]
    missing = [i for i, k in enumerate(keys) if k is None or k not in _CACHE]
    t0 = time.perf_counter()
    fresh: dict[int, Any] = {}
    if missing:
        jitted = jax.jit(run)
        lowered = {
            i: jitted.lower(jax.tree_util.tree_unflatten(dyn_def, per_device[i])) for i in missing
        }
        if len(missing) == 1:
            compiled = {missing[0]: lowered[missing[0]].compile()}
        else:
            # XLA compiles one executable per device; the compilations run in threads (XLA
            # releases the GIL), which halves the wait on a 2-core host with several devices.
            with concurrent.futures.ThreadPoolExecutor(max_workers=min(len(missing), 8)) as pool:
                compiled = dict(zip(missing, pool.map(lambda i: lowered[i].compile(), missing)))
        for i in missing:
            d = devices[i]
            serial = d is not None and d.platform == "cpu" and _lapack(compiled[i])
            fresh[i] = (compiled[i], out_static[0], serial)
            if keys[i] is not None:
                _CACHE[keys[i]] = fresh[i]
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    for k in keys:
        if k is not None and k in _CACHE:
            _CACHE.move_to_end(k)
    compile_time = time.perf_counter() - t0
    executables = [fresh[i] if i in fresh else _CACHE[k] for i, k in enumerate(keys)]
    t1 = time.perf_counter()
    outs = []
    for (exe, _, serial), leaves in zip(executables, per_device):
        outs.append(exe(jax.tree_util.tree_unflatten(dyn_def, leaves)))
        if serial:
            # heuristic: XLA's CPU runtime can stall when programs with LAPACK calls
            # (the solvers' QR / SVD) run on two host devices at once on a small machine;
            # such blocks run one after another (GPUs and other hosts run concurrently).
            jax.block_until_ready(outs[-1])
    outs = jax.block_until_ready(outs)
    run_time = time.perf_counter() - t1
    out_st = executables[0][1]
    if mesh is None:
        return eqx.combine(outs[0], out_st), compile_time, run_time
    sharding = NamedSharding(mesh, PartitionSpec(mesh.axis_names[0]))
    flat = [jax.tree_util.tree_flatten(o) for o in outs]
    treedef = flat[0][1]
    assembled = []
    for i, x in enumerate(flat[0][0]):
        blocks = [f[0][i] for f in flat]
        shape = (x.shape[0] * mesh.devices.size,) + x.shape[1:]
        assembled.append(jax.make_array_from_single_device_arrays(shape, sharding, blocks))
    out = eqx.combine(jax.tree_util.tree_unflatten(treedef, assembled), out_st)
    return out, compile_time, run_time


def options_object(
    cls: type, given: Any, keywords: dict[str, Any], who: str, argument: str = "options"
) -> Any:
    """The options object `cls` (a frozen dataclass) of the function `who`: the object
    given as its `argument`, or one built from its fields passed as `keywords`
    (`nperseg=...`), never both; a `TypeError` names unknown keywords and the fields."""
    name = cls.__name__
    if given is not None and keywords:
        raise TypeError(
            f"{who}: give the {name} options either as {argument}={name}(...) or as keywords "
            f"({', '.join(keywords)}), not both."
        )
    if given is not None and not isinstance(given, cls):
        raise TypeError(f"{who}: {argument} must be a {name}, got {type(given).__name__}.")
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(keywords) - fields)
    if unknown:
        raise TypeError(
            f"{who}: unknown option(s) {unknown}; the {name} options are {sorted(fields)}."
        )
    return cls(**keywords) if given is None else given


def polymul(a: Array, b: Array) -> Array:
    """Product of polynomials along the last axis (a batched `jnp.polymul`, coefficients
    highest power first); leading axes broadcast."""
    n, m = a.shape[-1], b.shape[-1]
    shape = jnp.broadcast_shapes(a.shape[:-1], b.shape[:-1]) + (n + m - 1,)
    out = jnp.zeros(shape, jnp.result_type(a, b))
    for j in range(m):
        out = out.at[..., j : j + n].add(a * b[..., j : j + 1])
    return out


def legendre(x: Array, degree: int) -> Array:
    """`(P_1(x), ..., P_degree(x))` along a new last axis, by Bonnet's recursion
    `(k + 1) P_{k+1} = (2k + 1) x P_k - k P_{k-1}` (`P_0 = 1` is left out)."""
    p_prev, p = jnp.ones_like(x), x
    out = [p]
    for k in range(1, degree):
        p_prev, p = p, ((2 * k + 1) * x * p - k * p_prev) / (k + 1)
        out.append(p)
    return jnp.stack(out, axis=-1)


# Padé (7, 7) coefficients of exp (Higham, "The scaling and squaring method for the matrix
# exponential revisited", SIAM J. Matrix Anal. Appl. 26, 2005, Table 2.3).
_PADE7 = (17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0)


def expm(m: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """Matrix exponential of a small matrix by scaling and squaring with Padé (7, 7).

    The scaled matrix has 1-norm <= 0.5, well inside the range where Padé (7, 7) is
    accurate to unit roundoff (θ_7 = 0.95, Higham 2005). Unlike `jax.scipy.linalg.expm`
    it has one fixed branch, so it compiles quickly under `jacfwd` and inside solver
    loops; the squarings are a fixed-length loop (masked), so reverse mode works too.
    """
    n = m.shape[0]
    norm = jnp.max(jnp.sum(jnp.abs(m), axis=0))
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / 0.5)), 0, 60)
    x = m / 2.0**s
    eye = jnp.eye(n, dtype=m.dtype)
    x2 = x @ x
    x4 = x2 @ x2
    x6 = x4 @ x2
    b = _PADE7
    u = x @ (b[7] * x6 + b[5] * x4 + b[3] * x2 + b[1] * eye)
    v = b[6] * x6 + b[4] * x4 + b[2] * x2 + b[0] * eye
    e = jnp.linalg.solve(v - u, v + u)
    return jax.lax.fori_loop(0, 60, lambda i, e: jnp.where(i < s, e @ e, e), e)


def json_safe(x: Any) -> Any:
    """JSON-safe: NumPy scalars to Python, non-finite floats to None."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating | float):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.bool_):
        return bool(x)
    return x
