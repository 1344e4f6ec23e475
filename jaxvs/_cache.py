"""Opt-in persistent compilation cache for the Python API (the `jaxvs` command turns it on
for itself)."""

import os
from pathlib import Path

__all__ = ["enable_compilation_cache"]


def default_cache_dir() -> Path:
    """`$JAX_COMPILATION_CACHE_DIR`, else `~/.cache/jaxvs/xla`."""
    env = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "jaxvs" / "xla"


def enable_compilation_cache(
    path: str | os.PathLike | None = None, *, min_compile_time_s: float = 1.0
) -> Path | None:
    """Keep XLA's compiled programs on disk between Python sessions.

    The first call of `jaxvs.calibrate`, `jaxvs.fit_rational`, `jaxvs.diagnose` or
    `jaxvs.design` on data of a given size spends most of its time compiling; with the
    cache on, the next process that makes the same call (same shapes, options and jax
    version) loads the compiled program instead. jaxvs never configures JAX on import: a
    program opts in by calling this once, before its first jaxvs call. The `jaxvs`
    command does it for itself (`JAXVS_NO_CACHE=1` switches that off).

    **Arguments:**

    - `path`: the cache folder (created if needed). Default: `$JAX_COMPILATION_CACHE_DIR`,
      else `~/.cache/jaxvs/xla` — the folder the `jaxvs` command uses, so the command and
      scripts share their compiled programs.
    - `min_compile_time_s`: only programs that took at least this long to compile are
      stored (JAX's `jax_persistent_cache_min_compile_time_secs`; small ones are cheaper
      to recompile than to read).

    **Returns:**

    The cache folder, or `None` when it could not be used (a read-only location, or a jax
    without a persistent cache): the program then runs as before, without a cache.

    **Raises:**

    `ValueError` for a negative `min_compile_time_s`.
    """
    if not min_compile_time_s >= 0:
        raise ValueError(
            f"enable_compilation_cache: min_compile_time_s must be >= 0 s; got "
            f"{min_compile_time_s!r}."
        )
    import jax

    folder = Path(path).expanduser() if path is not None else default_cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(folder))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
        # JAX decides once per process, at its first compilation, whether a cache is in
        # use; anything compiled before this call (importing a library can compile) would
        # have latched "no cache". Reset that decision so the next compilation sees the
        # folder.
        from jax.experimental.compilation_cache import compilation_cache

        compilation_cache.reset_cache()
    except (OSError, AttributeError, ImportError):  # read-only location or an older jax
        return None
    return folder
