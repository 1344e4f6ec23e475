"""Ctrl-C at many moments of `jaxvs diagnose`, `check`, `design` and `demo`
(docs/guides/refusals.md).

Each interrupt runs the real command in a subprocess and sends SIGINT at one moment: while
Python and JAX are still being imported, while a file is loaded, in the middle of the
computation (inside XLA), and while the report is written. Every one must end with exit
code 130 within seconds, print exactly one line saying what was and was not written, no
traceback, no "Exception ignored", no crash (a segmentation fault is -11), and leave
`--out` either absent (or holding the earlier report, unchanged) or complete, with no
staging folder beside it.

The moments are picked with the command's stage trace (`JAXVS_TRACE_STAGES`, one line
per stage as it starts); `JAXVS_STAGE_PAUSE=PREFIX:SECONDS` holds a stage long enough to
hit it (the pause is an ordinary `time.sleep`, interruptible like any Python code).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_bad_input_cli import _thermal_columns, write_csv

pytestmark = pytest.mark.slow  # ~20 real processes, each importing JAX

_REPO = Path(__file__).resolve().parents[1]
STOP_S = 20.0  # heuristic upper bound on SIGINT-to-exit on a loaded 2-core CI machine


def _start(args: list[str], cwd: Path, pause: str | None = None) -> subprocess.Popen:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(_REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env["JAXVS_NO_CACHE"] = "1"
    env["MPLBACKEND"] = "Agg"
    env["JAXVS_TRACE_STAGES"] = str(cwd / "stages.txt")
    env.pop("JAXVS_STAGE_PAUSE", None)
    if pause:
        env["JAXVS_STAGE_PAUSE"] = pause
    (cwd / "stages.txt").unlink(missing_ok=True)
    return subprocess.Popen(
        [sys.executable, "-m", "jaxvs._cli", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_stage(proc: subprocess.Popen, cwd: Path, prefix: str, timeout: float = 240.0) -> None:
    end = time.monotonic() + timeout
    trace = cwd / "stages.txt"
    while time.monotonic() < end:
        if trace.exists() and any(
            line.startswith(prefix) for line in trace.read_text().splitlines()
        ):
            return
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the command ended ({proc.returncode}) before {prefix!r}:\n{err}")
        time.sleep(0.02)
    proc.kill()
    pytest.fail(f"stage {prefix!r} not reached in {timeout} s")


def _interrupt(
    proc: subprocess.Popen, *, signals: int = 1, stop_s: float = STOP_S
) -> tuple[str, float]:
    """Send SIGINT; return stderr and the seconds until the process ended."""
    t0 = time.monotonic()
    for _ in range(signals):
        proc.send_signal(signal.SIGINT)
        time.sleep(0.05)
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the command did not stop within 120 s of Ctrl-C")
    seconds = time.monotonic() - t0
    assert proc.returncode not in (-signal.SIGSEGV, 139, -signal.SIGABRT), err  # no crash
    assert proc.returncode == 130, (proc.returncode, err)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    said = [line for line in err.splitlines() if "interrupted" in line]
    assert len(said) == 1, err  # one line ...
    assert "written" in said[0], said  # ... saying what was and was not written
    assert seconds < stop_s, f"stopped {seconds:.1f} s after Ctrl-C"
    return said[0], seconds


def _out_absent_or_complete(cwd: Path, out: str = "o", files=("report.json", "report.md")):
    folder = cwd / out
    leftovers = [p.name for p in cwd.iterdir() if p.name.startswith(f".{out}.")]
    assert not leftovers, leftovers  # no staging folder left beside --out
    if folder.exists():
        for name in files:
            assert (folder / name).stat().st_size > 0, name
        json.loads((folder / "report.json").read_text())  # complete JSON
        return True
    return False


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    import jax.random as jr

    from jaxvs.data import save_csv
    from jaxvs.twins import DriveTwin

    d = tmp_path_factory.mktemp("interrupts")
    # a drive twin's records with hidden friction: identifiable and above the null, so
    # `diagnose` searches the library for a minute, not seconds (an effect-free record
    # within the null is adequate at once: no candidate is tried)
    twin = DriveTwin(effects={"lugre": dict(Fc=20.0)})
    save_csv(twin.experiment(jr.key(0), duration=6.0), d / "cal.csv")
    save_csv(twin.experiment(jr.key(1), duration=3.0), d / "val.csv")
    t = np.arange(1500) * 1e-3  # one direction only: not identifiable, reported quickly
    write_csv(d / "ramp.csv", {"t": t, "q": 0.01 * t, "u": 30 + np.sin(40 * t), "r": 0.01 * t})
    write_csv(d / "th.csv", _thermal_columns(600))
    return d


def _run_dir(files: Path, tmp_path: Path) -> Path:
    for f in files.iterdir():
        (tmp_path / f.name).write_bytes(f.read_bytes())
    return tmp_path


DIAGNOSE = ["diagnose", "cal.csv", "--validate", "val.csv", "--family", "drive", "--out", "o"]
DIAGNOSE += ["--quiet"]
CHECK = ["check", "cal.csv", "--family", "drive", "--out", "o"]
DESIGN = ["design", "th.csv", "--target", "T_bearing", "--inputs", "T_chassis,v_m"]
DESIGN += ["--hidden", "3", "--inits", "1", "--max-delay", "1", "--out", "o", "--quiet"]
DESIGN += ["--no-figures"]
DEMO = ["demo", "--positions", "2", "--out", "o"]

# (command, args, how to pick the moment, expected words in the line)
MOMENTS = [
    ("diagnose", DIAGNOSE, ("after", 0.3), "nothing was written"),  # starting the interpreter
    ("diagnose", DIAGNOSE, ("after", 2.0), "nothing was written"),  # importing JAX
    ("diagnose", DIAGNOSE, ("pause", "loading"), "while loading cal.csv; nothing was written"),
    ("diagnose", DIAGNOSE, ("stage", "diagnosing", 1.0), "while diagnosing; nothing was written"),
    ("diagnose", DIAGNOSE, ("stage", "diagnosing", 6.0), "while diagnosing; nothing was written"),
    (
        "diagnose",
        ["diagnose", "ramp.csv", "--family", "drive", "--out", "o", "--quiet"],
        ("pause", "writing the report"),
        "while writing the report; nothing was written",
    ),
    ("check", CHECK, ("after", 1.0), "nothing was written"),
    ("check", CHECK, ("pause", "loading"), "while loading cal.csv; nothing was written"),
    ("check", CHECK, ("stage", "checking the data", 0.5), "nothing was written"),
    ("check", CHECK, ("pause", "writing the report"), "while writing the report; nothing"),
    ("design", DESIGN, ("after", 1.0), "nothing was written"),
    ("design", DESIGN, ("pause", "loading"), "while loading the data; nothing was written"),
    ("design", DESIGN, ("stage", "searching designs", 3.0), "written"),  # partial designs
    ("design", DESIGN, ("pause", "writing the report"), "nothing was written"),
    ("check", CHECK, ("after", 3.0), "nothing was written"),
    ("demo", DEMO, ("after", 1.5), "nothing was written"),
    ("demo", DEMO, ("stage", "[1/5]", 0.5), "nothing was written"),
    ("demo", DEMO, ("stage", "[2/5]", 0.1), "nothing was written"),
    ("demo", DEMO, ("stage", "[3/5]", 0.2), "nothing was written"),
]


@pytest.mark.parametrize(
    "command, args, moment, words",
    MOMENTS,
    ids=[f"{m[0]}-{'-'.join(str(x) for x in m[2])}".replace(" ", "_") for m in MOMENTS],
)
def test_interrupt(command, args, moment, words, files, tmp_path):
    cwd = _run_dir(files, tmp_path)
    kind = moment[0]
    proc = _start(args, cwd, pause=f"{moment[1]}:30" if kind == "pause" else None)
    if kind == "after":
        time.sleep(moment[1])
    else:
        _wait_stage(proc, cwd, moment[1])
        if kind == "stage":
            time.sleep(moment[2])
    said, seconds = _interrupt(proc, stop_s=40.0 if command == "design" else STOP_S)
    print(f"{command} {moment}: stopped {seconds:.2f} s after Ctrl-C: {said}")
    assert said.startswith(f"jaxvs {command}: interrupted"), said
    assert words in said, said
    complete = _out_absent_or_complete(cwd, files=("report.json", "report.md"))
    # the line and the folder agree: "nothing was written" means no folder
    assert complete == ("nothing was written" not in said), (said, complete)


def test_second_ctrl_c_ends_at_once(files, tmp_path):
    cwd = _run_dir(files, tmp_path)
    proc = _start(DIAGNOSE, cwd)
    _wait_stage(proc, cwd, "diagnosing")
    time.sleep(1.0)
    said, seconds = _interrupt(proc, signals=2, stop_s=5.0)
    assert "nothing was written" in said
    assert not _out_absent_or_complete(cwd)


def test_an_earlier_report_is_kept_until_the_new_one_is_complete(files, tmp_path):
    cwd = _run_dir(files, tmp_path)
    old = cwd / "o"
    old.mkdir()
    (old / "report.json").write_text('{"old": true}')
    (old / "report.md").write_text("old")
    marker = {"written_by": "jaxvs", "files": ["report.json", "report.md"]}
    (old / ".jaxvs-report").write_text(json.dumps(marker))  # an earlier report of jaxvs
    proc = _start(CHECK, cwd, pause="writing the report:30")
    _wait_stage(proc, cwd, "writing the report")
    said, _ = _interrupt(proc)
    assert "still holds the earlier report" in said, said
    assert json.loads((old / "report.json").read_text()) == {"old": True}  # untouched
    _out_absent_or_complete(cwd)


_PYTHON_API = r"""
import json, os, signal, sys, threading, time
import jax
jax.config.update("jax_enable_x64", True)
import equinox as eqx, jax.numpy as jnp, numpy as np
import jaxvs
from jaxvs.calibration import EquationError

def ctrl_c_after(seconds):
    threading.Timer(seconds, lambda: os.kill(os.getpid(), signal.SIGINT)).start()

def heavy(point, args):  # a slow point: 60 x 60 eigenvalues, enough to span several chunks
    a = point["a"] * args + jnp.eye(60)
    return {"v": jnp.sort(jnp.abs(jnp.linalg.eigvals(a)))}

grid = {"a": jnp.linspace(0.1, 1.0, 4096)}
args = jnp.asarray(np.random.default_rng(0).normal(size=(60, 60)))
run = lambda: jaxvs.sweep(heavy, grid, args, chunk_size=64, progress=False)["v"]
reference = np.asarray(run())
out = {}
ctrl_c_after(1.0)
t0 = time.monotonic()
try:
    run()
    out["sweep"] = {"caught": None}
except KeyboardInterrupt as e:
    out["sweep"] = {"caught": type(e).__name__, "message": str(e),
                    "seconds": time.monotonic() - t0}
out["sweep"]["same_after"] = bool(np.array_equal(np.asarray(run()), reference))

class Curve(eqx.Module):
    T0: jax.Array
    k: jax.Array
    T1: jax.Array
    def __call__(self, t):
        return self.T0 + self.k * (1 - jnp.exp(-t / self.T1))

t = np.linspace(0.0, 10.0, 400_000)
y = 20 + 5 * (1 - np.exp(-t / 2)) + 0.01 * np.random.default_rng(1).normal(size=t.size)
guess = Curve(jnp.asarray(15.0), jnp.asarray(1.0), jnp.asarray(1.0))
residual = EquationError(lambda m, d: m(d["t"]) - d["y"])
fit = lambda: jaxvs.calibrate(guess, {"t": t, "y": y}, residual)
ref = fit()
for delay in (0.05, 0.3):
    ctrl_c_after(delay)
    t0 = time.monotonic()
    try:
        fit()
        time.sleep(2.0)  # the interrupt lands here when the fit was faster
        caught = None
    except KeyboardInterrupt as e:
        caught = type(e).__name__
    again = fit()
    same = all(bool(jnp.array_equal(getattr(again.model, f), getattr(ref.model, f)))
               for f in ("T0", "k", "T1"))
    out[f"calibrate_{delay}"] = {"caught": caught, "seconds": time.monotonic() - t0,
                                 "same_after": same}
print(json.dumps(out))
"""


def test_python_api_interrupts_propagate_and_leave_no_state(tmp_path):
    """Ctrl-C in a long `sweep` and `calibrate` in a user's program: a `KeyboardInterrupt`
    (for `sweep` the `jaxvs.Interrupted` subclass, saying how far it got) reaches the
    program, and the same call afterwards gives bit-identical results (no state left
    behind in caches or compiled functions)."""
    script = tmp_path / "prog.py"
    script.write_text(_PYTHON_API)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(_REPO) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    print(out)
    assert out["sweep"]["caught"] == "Interrupted", out
    assert re.search(r"sweep interrupted after \d+/4096 points", out["sweep"]["message"])
    assert out["sweep"]["same_after"]
    for delay in ("0.05", "0.3"):
        assert out[f"calibrate_{delay}"]["caught"] == "KeyboardInterrupt", out
        assert out[f"calibrate_{delay}"]["same_after"], out


# --- randomised trials: SIGINT and SIGTERM at random moments, writing included ---------------

TRIALS = int(os.environ.get("JAXVS_INTERRUPT_TRIALS", "20"))
# Quick inputs (a one-direction ramp is not identifiable: diagnose and check report it fast),
# so each trial reaches "writing the report" within seconds.
QUICK = {
    "check": (
        ["check", "ramp.csv", "--family", "drive", "--out", "o"],
        ["loading", "checking the data", "writing the report", "writing the report"],
    ),
    "diagnose": (
        ["diagnose", "ramp.csv", "--family", "drive", "--out", "o", "--quiet"],
        ["loading", "diagnosing", "writing the report", "writing the report"],
    ),
    "design": (
        DESIGN,
        ["loading", "searching designs", "writing the report", "writing the report"],
    ),
}


def _trial(command: str, k: int, files: Path, root: Path) -> dict:
    rng = np.random.default_rng([hash(command) % 2**32, k])
    args, stages = QUICK[command]
    stage = stages[int(rng.integers(len(stages)))]
    # writing a report takes a fraction of a second: hit it early
    delay = float(rng.uniform(0.0, 0.05 if stage.startswith("writing") else 0.3))
    sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
    cwd = root / f"{command}-{k}"
    cwd.mkdir()
    _run_dir(files, cwd)
    proc = _start(args, cwd)
    trace = cwd / "stages.txt"
    end = time.monotonic() + 240
    while time.monotonic() < end and proc.poll() is None:
        if trace.exists() and any(s.startswith(stage) for s in trace.read_text().splitlines()):
            break
        time.sleep(0.005)
    time.sleep(delay)
    # a signal sent after the command has ended (traced "ended") cannot stop it
    late = proc.poll() is not None or (
        trace.exists() and "ended" in trace.read_text().splitlines()
    )
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        return {"where": (stage, delay, sig.name), "error": "did not stop within 120 s"}
    return {
        "where": (stage, round(delay, 3), sig.name),
        "code": proc.returncode,
        "late": late,
        "err": err,
        "cwd": cwd,
    }


def _judge(t: dict) -> str:
    """'stopped' or 'finished' (the signal came after the end); fails on anything else."""
    assert "error" not in t, t
    code, err, cwd = t["code"], t["err"], t["cwd"]
    assert "Traceback" not in err and "Exception ignored" not in err, (t["where"], err)
    said = [line for line in err.splitlines() if "interrupted" in line or "terminated" in line]
    if code in (0, 3):  # finished before the signal: a complete report, no interrupt line
        assert not said, (t["where"], err)
        assert _out_absent_or_complete(cwd), (t["where"], "finished without a report")
        return "finished"
    expected = 130 if t["where"][2] == "SIGINT" else 143
    assert code == expected, (t["where"], code, err)
    assert len(said) == 1, (t["where"], err)  # one line
    assert ("terminated" in said[0]) == (expected == 143), said
    complete = _out_absent_or_complete(cwd, files=("report.json", "report.md"))
    assert complete == ("nothing was written" not in said[0]), (t["where"], said, complete)
    return "stopped"


@pytest.mark.parametrize("command", list(QUICK))
def test_signals_at_random_moments(command, files, tmp_path):
    """TRIALS runs, two at a time, each stopped by SIGINT or SIGTERM (alternating) at a
    random moment of a random stage (writing the report twice as often): every one ends
    with 130 / 143 and one line, or -- when the signal came after the end -- with a
    complete report; never a crash, a traceback or a staging folder left behind."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:
        trials = list(pool.map(lambda k: _trial(command, k, files, tmp_path), range(TRIALS)))
    outcomes = [_judge(t) for t in trials]
    print(command, {o: outcomes.count(o) for o in set(outcomes)})
    # a signal sent after the command ended finds it finished; one sent before must stop it
    # (but for the moment between looking at the trace and the signal arriving)
    early = [o for o, t in zip(outcomes, trials, strict=True) if not t["late"]]
    assert len(early) >= TRIALS // 4, (outcomes, [t["where"] for t in trials])
    assert early.count("stopped") >= 0.8 * len(early), (early, [t["where"] for t in trials])
