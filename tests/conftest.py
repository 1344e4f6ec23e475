import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("JAXVS_NO_CACHE", "1")  # the CLI's XLA disk cache stays off in tests

import jax  # noqa: E402
import jax.random as jr  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
# Promotion stays "standard": FRF code mixes real parameters with complex frequencies by
# design, which "strict" forbids. float32 preservation is tested explicitly instead.

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture
def getkey():
    """Fresh PRNG keys, deterministic per test."""
    counter = iter(range(10**9))
    base = jr.key(5678)

    def _getkey():
        return jr.fold_in(base, next(counter))

    return _getkey


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} is absent (it sits beside the repo)")
    return SHARED_DATA


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Drop XLA's compiled executables after each test module.

    Every compiled executable keeps a few memory mappings of JIT code; a worker that runs
    a few hundred test functions would exceed the kernel's `vm.max_map_count` (65530 by
    default), and XLA then crashes mid-compilation (segfault or abort). Clearing the caches
    between modules keeps a worker's mappings to what one module needs."""
    yield
    import gc

    jax.clear_caches()
    gc.collect()
