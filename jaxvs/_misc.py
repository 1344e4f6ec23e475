"""Helpers shared by every folder of jaxvs: ahead-of-time compilation with a small cache
(compile and run time reported separately, measured outside `jit`, as the benchmarks do),
the tracer test, and a matrix exponential that compiles fast."""

import collections
import math
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = [
    "as_real",
    "check_finite",
    "check_physical",
    "concrete",
    "expm",
    "is_traced",
    "json_safe",
    "timed_call",
]

_CACHE: collections.OrderedDict = collections.OrderedDict()
_CACHE_SIZE = 32


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
    x = jnp.asarray(x)
    if jnp.iscomplexobj(x):
        raise TypeError(
            f"{what} must be real; got a complex array (take .real or abs() explicitly)."
        )
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    return x


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


def _key(fn: Callable, dynamic: Any, static: Any) -> Any:
    dyn_leaves, dyn_def = jax.tree_util.tree_flatten(dynamic)
    st_leaves, st_def = jax.tree_util.tree_flatten(static)
    avals = tuple((x.shape, str(x.dtype), bool(getattr(x, "weak_type", False))) for x in dyn_leaves)
    key = (fn, dyn_def, st_def, tuple(st_leaves), avals)
    try:
        hash(key)
    except TypeError:  # an unhashable static leaf: compile without caching
        return None
    return key


def timed_call(fn: Callable, *args: Any) -> tuple[Any, float, float]:
    """Compile `fn(*args)` (arrays traced, everything else static), run it once.

    **Returns:**

    `(output, compile_time, run_time)` in seconds; `compile_time` is 0 when a compiled
    version for the same shapes and static arguments was cached.
    """
    dynamic, static = eqx.partition(args, eqx.is_array)
    key = _key(fn, dynamic, static)
    entry = _CACHE.get(key) if key is not None else None
    t0 = time.perf_counter()
    if entry is None:
        out_static = []

        def run(dyn):
            out = fn(*eqx.combine(dyn, static))
            out_dyn, out_st = eqx.partition(out, eqx.is_array)
            out_static.append(out_st)
            return out_dyn

        compiled = jax.jit(run).lower(dynamic).compile()
        entry = (compiled, out_static[0])
        if key is not None:
            _CACHE[key] = entry
            if len(_CACHE) > _CACHE_SIZE:
                _CACHE.popitem(last=False)
    elif key is not None:
        _CACHE.move_to_end(key)
    compile_time = time.perf_counter() - t0
    compiled, out_static = entry
    t1 = time.perf_counter()
    out_dyn = jax.block_until_ready(compiled(dynamic))
    run_time = time.perf_counter() - t1
    return eqx.combine(out_dyn, out_static), compile_time, run_time


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
