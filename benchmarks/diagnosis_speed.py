"""The time a tmf diagnosis of 25 000 samples takes, stage by stage.

One blind tmf case of `benchmarks/blind_plants.py` (`tmf-delay-antialias`: a sensor
delay behind an anti-alias filter, sampled at 10 kHz, three calibration records at three
positions and two validation sweeps) with its lengths set to 15 000 calibration and
10 000 validation samples, diagnosed by `jaxvs.diagnose` with its defaults (the check,
the null of 19 records, the bootstrap of 300 resamples, discovery when it fires).

Every measurement is a fresh Python process (nothing compiled yet, no persistent
compilation cache: what a user waits for the first time), which reports

- the CPU time of the `diagnose` call (user + system of the process and its children,
  `resource.getrusage`): the headline, robust to other jobs on a shared machine;
- its wall time and the load average before and after;
- the CPU time per stage, read off the diagnosis's progress messages (check, preparation,
  nominal calibration, null, candidate search, the candidates on the null records,
  pruning, gap map and report, discovery), the block bootstrap's share of each, and the
  XLA compilation time per stage (`jax.monitoring`'s compile events);
- a fingerprint of the result (verdict, effects, gaps, every candidate's figures), so that
  two labelled runs (`--label before`, `--label after`) are compared value by value.

    python benchmarks/diagnosis_speed.py [--label after] [--repeat 1] [--profile]
    python benchmarks/diagnosis_speed.py --label "warm cache" --repeat 2 --cache /tmp/xla

With `--cache`, the runs share a persistent compilation cache, as the `jaxvs` command
does: the first run fills it (cold), the next ones read it (what a user waits the second
time the same command runs on records of the same size).

Writes benchmarks/results/diagnosis_speed.json and .md (runs under other labels kept).
`--profile` also writes a cProfile listing of one run (benchmarks/results/
diagnosis_speed_profile.txt), which inflates the times it reports.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import pathlib
import platform
import resource
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
RESULTS = HERE / "results"
CASE = "tmf-delay-antialias"
N_CAL, N_VAL = 15000, 10000

# progress message prefix -> stage (the first match wins; messages in `jaxvs.diagnose`
# and its search)
STAGES = (
    ("checking the calibration data", "check"),
    ("preparing", "preparation"),
    ("recalibrating the nominal model", "nominal calibration"),
    ("simulating", "null (simulation and nominal refits)"),
    ("noise floor", "candidate search"),
    ("refitting the current model", "null (candidates)"),
    (" on ", "null (candidates)"),  # "round r: <effect> on 19 null records"
    ("round", "candidate search"),
    ("accepted", "candidate search"),
    ("the remaining gap", "candidate search"),
    ("testing every accepted", "pruning"),
    ("removing", "pruning"),
    ("mapping the gap", "gap map and report"),
    ("discovery", "discovery"),
    ("done", "gap map and report"),
)


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _stage_of(message: str) -> str:
    body = message.split("] ", 1)[-1]
    for prefix, stage in STAGES:
        if prefix == " on ":
            if body.startswith("round") and " null records" in body and " on " in body:
                return stage
            continue
        if body.startswith(prefix):
            return stage
    return "other"


class _Stages:
    """A stderr stand-in that books CPU time to the stage of the last progress message."""

    def __init__(self, stream):
        self.stream = stream
        self.stage = "before the search"
        self.cpu: dict[str, float] = {}
        self.compile: dict[str, float] = {}
        self.compiles: dict[str, int] = {}
        self.bootstrap: dict[str, float] = {}
        self.t = _cpu()
        self.messages: list[tuple[float, str]] = []

    def switch(self, stage: str) -> None:
        now = _cpu()
        self.cpu[self.stage] = self.cpu.get(self.stage, 0.0) + now - self.t
        self.t = now
        self.stage = stage

    def write(self, text: str) -> int:
        for line in text.splitlines():
            if line.startswith("[jaxvs diagnose"):
                self.messages.append((_cpu(), line.split("] ", 1)[-1]))
                self.switch(_stage_of(line))
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def on_event(self, event: str, seconds: float, **_: object) -> None:
        if event.endswith("backend_compile_duration"):
            self.compile[self.stage] = self.compile.get(self.stage, 0.0) + seconds
            self.compiles[self.stage] = self.compiles.get(self.stage, 0) + 1
        elif event.endswith(("jaxpr_trace_duration", "jaxpr_to_mlir_module_duration")):
            self.compile[self.stage] = self.compile.get(self.stage, 0.0) + seconds


def _fingerprint(content: dict) -> dict:
    """What must not change when the diagnosis gets faster."""
    v = content.get("verdict") or {}
    gap = content.get("gap") or {}
    cands = {
        c["effect"]: {
            k: c.get(k)
            for k in (
                "validation_gap",
                "calibration_gap",
                "delta_bic",
                "shrink",
                "null_p95",
                "null_threshold",
                "rejected_by",
                "accepted",
                "parameters",
            )
        }
        for c in content.get("candidates") or []
    }
    return {
        "status": v.get("status"),
        "effects": v.get("effects"),
        "primary": v.get("primary"),
        "validation_gap": v.get("validation_gap"),
        "shrink": v.get("shrink"),
        "shrink_interval": v.get("shrink_interval"),
        "parameters": v.get("parameters"),
        "gap": {k: gap.get(k) for k in ("calibration", "validation", "noise_floor", "null_gaps")},
        "candidates": cands,
        "where": [(w.get("label"), w.get("gap")) for w in content.get("where") or []],
        "discovered": (content.get("discovered") or {}).get("found"),
    }


def child(args) -> dict:
    """One measurement in this (fresh) process."""
    import jax

    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(HERE))
    import blind_plants

    import jaxvs

    if args.cache:  # what the `jaxvs` command does for itself
        jaxvs.enable_compilation_cache(args.cache)
    case = next(c for c in blind_plants.cases() if c.name == args.case)
    case = dataclasses.replace(case, settings={**case.settings, "n_cal": N_CAL, "n_val": N_VAL})
    cal, val, _ = blind_plants.generate(case)
    samples = int(sum(len(r) for r in cal + val))
    stages = _Stages(sys.stderr)
    jax.monitoring.register_event_duration_secs_listener(stages.on_event)

    # the block bootstrap's share: time the one function every stage calls it through
    import jaxvs.diagnosis._diagnose as diag_mod
    import jaxvs.diagnosis._engine as engine_mod

    def timed(fn):
        def wrapper(*a, **k):
            c0 = _cpu()
            try:
                return fn(*a, **k)
            finally:
                s = stages.stage
                stages.bootstrap[s] = stages.bootstrap.get(s, 0.0) + _cpu() - c0

        return wrapper

    for mod in (diag_mod, engine_mod):
        mod.gap_change_interval = timed(mod.gap_change_interval)

    compile_log: list[tuple[str, str]] = []
    if args.profile:
        import logging

        class _Log(logging.Handler):
            def emit(self, record):
                msg = record.getMessage()
                if "Finished XLA compilation" in msg or "Compiling" in msg:
                    compile_log.append((stages.stage, msg[:200]))

        jax.config.update("jax_log_compiles", True)
        logger = logging.getLogger("jax")
        logger.addHandler(_Log())
        logger.propagate = False

    load0 = os.getloadavg()
    profiler = None
    if args.profile:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
    sys.stderr = stages
    t0, c0 = time.perf_counter(), _cpu()
    stages.t = c0
    rep = jaxvs.diagnose(cal, val, family="tmf", seed=0, progress=True)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    stages.switch("end")
    sys.stderr = stages.stream
    if profiler is not None:
        import io
        import pstats

        profiler.disable()
        if os.environ.get("DIAGNOSIS_SPEED_PSTATS"):  # the raw statistics, for pstats
            profiler.dump_stats(os.environ["DIAGNOSIS_SPEED_PSTATS"])
        buf = io.StringIO()
        pstats.Stats(profiler, stream=buf).sort_stats("cumulative").print_stats(60)
        buf.write("\n\nXLA compilations (stage, message):\n")
        buf.writelines(f"{st}: {m}\n" for st, m in compile_log)
        (RESULTS / "diagnosis_speed_profile.txt").write_text(buf.getvalue())
    content = rep.to_json()
    return {
        "samples": samples,
        "records": {"calibration": [len(r) for r in cal], "validation": [len(r) for r in val]},
        "cpu_seconds": cpu,
        "wall_seconds": wall,
        "process_cpu_seconds": _cpu(),
        "load_average_before": load0,
        "load_average_after": os.getloadavg(),
        "stages_cpu": {k: v for k, v in stages.cpu.items() if k != "end"},
        "stages_compile": stages.compile,
        "stages_compiles": stages.compiles,
        "stages_bootstrap": stages.bootstrap,
        "compile_seconds": sum(stages.compile.values()),
        "compiles": sum(stages.compiles.values()),
        "fingerprint": _fingerprint(content),
        "messages": [(round(c - c0, 2), m) for c, m in stages.messages],
    }


def _diff(a, b, path="", out=None, worst=None):
    """Differences between two fingerprints: (path, a, b) for any non-numeric difference,
    and the largest relative difference of the numbers."""
    out = [] if out is None else out
    worst = [0.0, ""] if worst is None else worst
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            _diff(a.get(k), b.get(k), f"{path}.{k}", out, worst)
    elif isinstance(a, list | tuple) and isinstance(b, list | tuple) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            _diff(x, y, f"{path}[{i}]", out, worst)
    elif (
        isinstance(a, int | float)
        and isinstance(b, int | float)
        and not isinstance(a, bool)
        and not isinstance(b, bool)
    ):
        if a != b and not (math.isnan(a) and math.isnan(b)):
            rel = abs(a - b) / max(abs(a), abs(b), 1e-300)
            if rel > worst[0]:
                worst[:] = [rel, path]
    elif a != b:
        out.append((path, a, b))
    return out, worst


def _fmt_stage_table(run: dict) -> list[str]:
    lines = [
        "| stage | CPU [s] | XLA compile in it, wall clock [s] (compilations) | bootstrap [s] |",
        "|---|---|---|---|",
    ]
    for stage, cpu in sorted(run["stages_cpu"].items(), key=lambda kv: -kv[1]):
        comp = run["stages_compile"].get(stage, 0.0)
        n = run["stages_compiles"].get(stage, 0)
        boot = run["stages_bootstrap"].get(stage, 0.0)
        lines.append(f"| {stage} | {cpu:.1f} | {comp:.1f} ({n}) | {boot:.1f} |")
    return lines


def write(results: dict) -> None:
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "diagnosis_speed.json").write_text(json.dumps(results, indent=1) + "\n")
    lines = [
        "# tmf diagnosis of 25 000 samples: time per stage",
        "",
        f"Case `{CASE}` of `benchmarks/blind_plants.py` with {N_CAL} calibration and {N_VAL} "
        "validation samples; `jaxvs.diagnose(cal, val, family='tmf')` with its defaults, in a "
        "fresh process without a persistent compilation cache. CPU time is user + system "
        "time of the process (the headline: robust to other jobs on the machine); the "
        "machine has 2 cores shared with other jobs, so wall times vary with the load "
        "average shown. Goal: ≤ 60 s CPU.",
        "",
        "Reproduce: `python benchmarks/diagnosis_speed.py --label after`.",
        "",
        "Where the time goes: XLA compilation of the search's fitting program (in the nominal "
        "calibration, the first call), of `fit_rational` (in the check, which initialises "
        "the nominal TMF) and of the check's Jacobian is the largest share of a first run; "
        "the rest is the Levenberg-Marquardt runs of the candidates and of the null records "
        "(a scan over the record per derivative, bound by the steps of the scan). CPU time "
        "grows with the machine's load (shared caches): compare labels measured under "
        "similar load averages.",
        "",
        "| label | date | commit | persistent cache | CPU [s] | wall [s] | load average (1 min, "
        "before → after) | XLA compile, wall clock [s] (compilations) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, entry in results["runs"].items():
        for run in entry["runs"]:
            lines.append(
                f"| {label} | {entry['date']} | {entry['commit']} | "
                f"{run.get('compilation_cache', 'none')} | {run['cpu_seconds']:.1f} | "
                f"{run['wall_seconds']:.1f} | {run['load_average_before'][0]:.2f} → "
                f"{run['load_average_after'][0]:.2f} | {run['compile_seconds']:.1f} "
                f"({run['compiles']}) |"
            )
    for label, entry in results["runs"].items():
        run = min(entry["runs"], key=lambda r: r["cpu_seconds"])
        fp = run["fingerprint"]
        lines += [
            "",
            f"## {label}: stages (the run with the least CPU time)",
            "",
            f"Verdict: {fp['status']}, effects {fp['effects']}, primary {fp['primary']}, "
            f"validation gap {fp['validation_gap']}.",
            "",
            *_fmt_stage_table(run),
        ]
    labels = list(results["runs"])
    if "before" in results["runs"] and len(labels) > 1:
        ref = results["runs"]["before"]["runs"][0]["fingerprint"]
        lines += ["", "## Result against `before`", ""]
        for label in labels:
            if label == "before":
                continue
            fp = results["runs"][label]["runs"][0]["fingerprint"]
            diffs, (rel, where) = _diff(ref, fp)
            if not diffs and rel == 0.0:
                lines.append(f"- {label}: identical (every value of the fingerprint equal).")
            else:
                text = "; ".join(f"{p}: {a!r} → {b!r}" for p, a, b in diffs[:5]) or "none"
                lines.append(
                    f"- {label}: non-numeric differences: {text}; largest relative "
                    f"difference of a number {rel:.2g} ({where or '—'})."
                )
            results["runs"][label]["against_before"] = {
                "differences": [list(map(str, d)) for d in diffs],
                "largest_relative_difference": rel,
                "where": where,
            }
    (RESULTS / "diagnosis_speed.md").write_text("\n".join(lines) + "\n")
    (RESULTS / "diagnosis_speed.json").write_text(json.dumps(results, indent=1) + "\n")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--label", default="after", help="name of this set of runs (kept apart)")
    p.add_argument("--repeat", type=int, default=1, help="fresh processes to measure")
    p.add_argument("--profile", action="store_true", help="cProfile one run")
    p.add_argument("--commit", default=None, help="commit measured (default: HEAD)")
    p.add_argument(
        "--cache",
        default=None,
        help="persistent compilation cache folder (as the jaxvs command uses); the first "
        "run fills it, later runs read it",
    )
    p.add_argument("--case", default=CASE, help=argparse.SUPPRESS)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print("RESULT " + json.dumps(child(args)))
        return
    path = RESULTS / "diagnosis_speed.json"
    results = json.loads(path.read_text()) if path.exists() else {"runs": {}}
    commit = (
        args.commit
        or subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=HERE
        ).stdout.strip()
    )
    runs = []
    for _ in range(args.repeat):
        cmd = [sys.executable, __file__, "--child", "--case", args.case]
        if args.cache:
            cmd += ["--cache", args.cache]
        if args.profile:
            cmd.append("--profile")
        cached = bool(args.cache) and any(pathlib.Path(args.cache).glob("*"))
        proc = subprocess.run(cmd, capture_output=True, text=True)
        line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
        if proc.returncode or not line:
            sys.exit(f"the measurement failed:\n{proc.stderr[-4000:]}")
        run = json.loads(line[-1][7:])
        run["compilation_cache"] = (
            "none" if not args.cache else ("read (warm)" if cached else "filled (cold)")
        )
        runs.append(run)
        print(
            f"{args.label}: CPU {run['cpu_seconds']:.1f} s, wall {run['wall_seconds']:.1f} s, "
            f"load {run['load_average_before'][0]:.2f} -> {run['load_average_after'][0]:.2f}, "
            f"compile {run['compile_seconds']:.1f} s ({run['compiles']}); "
            f"{run['fingerprint']['status']} {run['fingerprint']['effects']}"
        )
        for row in _fmt_stage_table(run)[2:]:
            print("  " + row)
    import jax

    results["runs"][args.label] = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "commit": commit,
        "python": platform.python_version(),
        "jax": jax.__version__,
        "cpu_count": os.cpu_count(),
        "runs": runs,
    }
    write(results)


if __name__ == "__main__":
    main()
