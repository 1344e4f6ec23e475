"""`jaxvs.enable_compilation_cache`: the persistent compilation cache for the Python API.

Run in a subprocess: the cache is process-wide JAX configuration, which a test must not
leave switched on for the rest of the suite."""

import os
import subprocess
import sys
import textwrap

import pytest

import jaxvs

SCRIPT = textwrap.dedent(
    """
    import sys
    import jax
    import jax.numpy as jnp
    jax.jit(lambda x: x + 1)(1.0)  # a compilation before the cache is switched on
    import jaxvs
    print(jaxvs.enable_compilation_cache(sys.argv[1], min_compile_time_s=0.0))
    jax.jit(lambda x: jnp.sin(x) @ jnp.cos(x).T)(jnp.ones((30, 30))).block_until_ready()
    """
)


def test_cache_is_written_even_after_an_earlier_compilation(tmp_path):
    folder = tmp_path / "xla"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(folder)], capture_output=True, text=True, env=env
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == str(folder)
    # the program compiled after the call is on disk (JAX latches "no cache" at the first
    # compilation of a process; enable_compilation_cache resets that decision)
    assert any(folder.iterdir())


def test_bad_argument():
    with pytest.raises(ValueError, match="min_compile_time_s must be >= 0"):
        jaxvs.enable_compilation_cache(min_compile_time_s=-1.0)
