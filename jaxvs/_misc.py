"""Ahead-of-time compilation with a small cache, so that compile and run time can be
reported separately (measured outside `jit`, as the benchmarks do)."""

import collections
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax

__all__ = ["is_traced", "timed_call"]

_CACHE: collections.OrderedDict = collections.OrderedDict()
_CACHE_SIZE = 32


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
