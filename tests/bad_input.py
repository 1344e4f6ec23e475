"""The bad-input matrix: one row per bad or borderline input, shared by `tests/test_bad_input_*.py`.

Every row is a `Case`: what the user gave (in words), the public entry point it went to, and
what jaxvs must do with it:

- `exc` set: refuse it with that exception type and a message matching `match` (the message
  names the problem *and* the fix; `match` should pin both, e.g. ``"delimiter.*--delimiter"``);
- `exc=None`: handle it correctly; `check(result)` asserts the answer is right (a borderline
  input that is legal, e.g. a CSV with a BOM, must load exactly what was written).

A test module defines `CASES: list[Case]` and one parametrised test:

    @pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
    def test_bad_input(case, tmp_path):
        run_case(case, tmp_path)

`run_case` also records the outcome (case, input, message) as one JSON line in the file named
by the environment variable `JAXVS_MATRIX_OUT` when it is set; `docs/gen_refusals.py` turns those
lines into the docs page "What jaxvs refuses" and the counts in the README.

CLI rows call `run_cli(args, cwd)`, which runs `python -m jaxvs._cli` in a subprocess and raises
`CliExit` (carrying the exit code and stderr) when the exit code is not 0, so a CLI refusal is
matched like any other exception: `exc=CliExit`, `match=` on stderr, `exit_code=2`.

Every row runs under a time bound (`Case.timeout`, seconds): a reader that blocks on a FIFO or
loops on a hostile file fails its row with `ProbeTimeout` instead of hanging the suite.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Case", "CliExit", "ProbeTimeout", "run_case", "run_cli", "time_bound"]


class ProbeTimeout(BaseException):
    """A probe ran past its time bound (a hang); a BaseException so no `except Exception`
    in the code under test swallows it."""


@contextlib.contextmanager
def time_bound(seconds: float) -> Iterator[None]:
    """Raise `ProbeTimeout` in the block after `seconds` (SIGALRM; main thread only, else
    the block runs unbounded). Python-level loops and blocking system calls (`open` of a
    FIFO) are both interrupted."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(
        signal, "setitimer"
    ):
        yield
        return

    def expire(signum, frame):
        raise ProbeTimeout(f"did not finish within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


_REPO = Path(__file__).resolve().parents[1]


class CliExit(Exception):
    """A `jaxvs` command that ended with a non-zero exit code (message = its stderr)."""

    def __init__(self, code: int, stderr: str, stdout: str = ""):
        super().__init__(stderr.strip())
        self.code = code
        self.stderr = stderr
        self.stdout = stdout


@dataclass(frozen=True)
class Case:
    """One row of the matrix (see the module docstring)."""

    id: str
    area: str  # "loaders", "record", "models", "simulate", "calibration", "signal", "cli", ...
    entry: str  # the public entry point, e.g. "jaxvs.data.load_csv" or "jaxvs diagnose"
    input: str  # what the user gave, in words (goes into the docs table)
    run: Callable[[Path], object]  # performs the call; gets a fresh temporary directory
    exc: type[BaseException] | None = ValueError
    match: str = ""
    check: Callable[[object], None] | None = None
    exit_code: int | None = None  # CLI rows: the expected exit code
    timeout: float = 240.0  # seconds: a hang fails the row (generous for a loaded 2-core CI)


def run_cli(args: list[str], cwd: Path, *, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """Run `jaxvs ARGS` in a subprocess; raise `CliExit` when it does not exit with 0."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(_REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("JAXVS_NO_CACHE", "1")
    env.setdefault("MPLBACKEND", "Agg")
    proc = subprocess.run(
        [sys.executable, "-m", "jaxvs._cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    if proc.returncode != 0:
        raise CliExit(proc.returncode, proc.stderr, proc.stdout)
    return proc


def _record(case: Case, outcome: str, message: str) -> None:
    out = os.environ.get("JAXVS_MATRIX_OUT")
    if not out:
        return
    row = {
        "id": case.id,
        "area": case.area,
        "entry": case.entry,
        "input": case.input,
        "outcome": outcome,
        "message": message,
    }
    with open(out, "a", encoding="utf-8") as f:
        f.write(json.dumps(row) + "\n")


def run_case(case: Case, tmp_path: Path) -> None:
    """Run one row and assert what it promises (and record the outcome when asked)."""
    with time_bound(case.timeout):
        _run_case(case, tmp_path)


def _run_case(case: Case, tmp_path: Path) -> None:
    if case.exc is None:
        result = case.run(tmp_path)
        if case.check is not None:
            case.check(result)
        _record(case, "handled", "")
        return
    try:
        result = case.run(tmp_path)
    except case.exc as e:
        message = str(e)
        assert re.search(case.match, message, flags=re.S | re.I), (
            f"{case.id}: message does not name the problem and fix "
            f"(expected /{case.match}/):\n{message}"
        )
        if case.exit_code is not None:
            assert isinstance(e, CliExit) and e.code == case.exit_code, (
                f"{case.id}: exit code {getattr(e, 'code', None)}, expected {case.exit_code}"
            )
            assert "Traceback" not in e.stderr, f"{case.id}: traceback printed:\n{e.stderr}"
        _record(case, "refused", message)
        return
    raise AssertionError(f"{case.id}: expected {case.exc.__name__}, got a result: {result!r}")
