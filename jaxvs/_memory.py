"""Memory guard: estimate what a large step will allocate before it starts, and refuse it
with the estimate, the machine's memory and how to make the problem smaller, instead of
growing until the kernel kills the process (or XLA reports RESOURCE_EXHAUSTED).

The limit is the memory available when the step starts (`MemAvailable` of
`/proc/meminfo`, else the physical memory), or the one set by `jaxvs ... --max-memory`
(`limit(...)`). Estimates are upper-bound models of the step's largest arrays, stated
where they are computed; they decide only whether to start.

Only the standard library is imported here.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

__all__ = ["MemoryEstimateError", "available_bytes", "guard", "limit", "parse_size"]

_LIMIT: list[float] = []  # set by `limit` (the command's --max-memory)
_UNITS = {"": 1, "b": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


class MemoryEstimateError(ValueError):
    """A step would need more memory than the machine has (or `--max-memory` allows)."""


def _gb(n: float) -> str:
    return f"{n / 2**30:.3g} GB"


def total_bytes() -> int | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return None


def available_bytes() -> int | None:
    """Memory available to a new allocation now (None when the system does not say)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return total_bytes()


def parse_size(text: str) -> float:
    """`"8G"`, `"512M"`, `"2.5GB"`, `"1e9"` (bytes) -> bytes; `ValueError` otherwise."""
    t = str(text).strip().lower().removesuffix("ib").removesuffix("b")
    unit = t[-1:] if t[-1:] in _UNITS and t[-1:] else ""
    number = t[: len(t) - len(unit)] if unit else t
    value = float(number) * _UNITS[unit]  # ValueError for text that is not a number
    if not value > 0 or value == float("inf"):
        raise ValueError(f"not a positive size: {text!r}")
    return value


@contextlib.contextmanager
def limit(max_bytes: float | None) -> Iterator[None]:
    """Use `max_bytes` instead of the available memory inside the block."""
    if max_bytes is None:
        yield
        return
    _LIMIT.append(float(max_bytes))
    try:
        yield
    finally:
        _LIMIT.pop()


def guard(estimate: float, what: str, fix: str) -> None:
    """Refuse (`MemoryEstimateError`) when `estimate` bytes exceed the limit.

    The message: "`what` would need about X GB of memory; the limit is Y GB (available
    memory of this machine with Z GB / --max-memory). `fix`"."""
    if _LIMIT:
        cap, whose = _LIMIT[-1], "set by --max-memory"
    else:
        avail = available_bytes()
        if avail is None:  # pragma: no cover - a system that does not say
            return
        total = total_bytes()
        cap = 0.8 * avail  # heuristic: leave a fifth for the rest of the process and system
        whose = (
            f"80 % of the {_gb(avail)} available"
            + (f" on this machine with {_gb(total)}" if total else "")
            + "; --max-memory sets another"
        )
    if estimate > cap:
        raise MemoryEstimateError(
            f"{what} would need about {_gb(estimate)} of memory, more than the limit of "
            f"{_gb(cap)} ({whose}). {fix}"
        )
