"""The time a user waits: cold and warm first calls of jaxvs's entry points.

Each measurement is a fresh Python process that imports jaxvs and makes one entry point's
first call twice: the first call includes tracing and XLA compilation, the second is the
run alone. Per entry point, two processes share one persistent compilation cache folder
(`jaxvs.enable_compilation_cache(path)`), empty before the first:

- **cold**: nothing compiled yet (the cache is empty; the process fills it);
- **warm**: a new process with the cache the first one left (what a user sees the second
  time a script runs, or after changing an option that does not change shapes).

Entry points and workloads:

- `calibrate`: a 4-mode `ModalModel` calibrated on a 5000-sample simulated time record by
  simulation error (Levenberg–Marquardt);
- `fit_rational`: 256 TMFs of order (6, 6) on 2000 frequency points in one call
  (`benchmarks/calibrate.py`'s problems);
- `diagnose`: one blind drive case of `benchmarks/blind_plants.py` (the null included);
- `design`: the thermal design assistant on 12 h of spindle records, hidden size 3.

Writes `benchmarks/results/latency.json` and `.md`; prints the load average (the machine
may be shared: the figures are indicative).
Run: `python benchmarks/latency.py [--only NAME ...]`.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
ENTRIES = ("calibrate", "fit_rational", "design", "diagnose")
DIAGNOSE_CASE = "drive-coulomb-karnopp"


def _workload(name: str):
    """A zero-argument function making the entry point's call (imports done here)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxvs

    if name == "calibrate":
        from jaxvs.calibration import SimulationError

        rng = np.random.default_rng(0)
        truth = jaxvs.ModalModel(
            jnp.array([60.0, 150.0, 400.0, 900.0]),
            jnp.array([0.02, 0.03, 0.02, 0.05]),
            jnp.array([1.0, -0.5, 0.3, 0.2]) * jnp.array([60.0, 150.0, 400.0, 900.0]) ** 2,
        )
        u = jnp.asarray(rng.normal(size=5000))
        y = jaxvs.simulate(truth, u, 1e-3) + 0.01 * jnp.asarray(rng.normal(size=5000))
        guess = jaxvs.ModalModel(truth.omega_n * 1.05, truth.zeta * 1.3, truth.residues * 0.9)

        def call():
            r = jaxvs.calibrate(guess, {"u": u, "y": y, "dt": 1e-3}, SimulationError())
            return jax.block_until_ready(r.model)

        return call
    if name == "fit_rational":
        sys.path.insert(0, str(HERE))
        import calibrate as cal_bench

        omega, _, h = cal_bench.make_problems(0, 256)
        om, hj = jnp.asarray(omega), jnp.asarray(h)
        return lambda: jax.block_until_ready(
            jaxvs.fit_rational(om, hj, cal_bench.ORDER, throw=False)[0]
        )
    if name == "diagnose":
        sys.path.insert(0, str(HERE))
        import blind_plants

        case = next(c for c in blind_plants.cases() if c.name == DIAGNOSE_CASE)
        cal, val, _ = blind_plants.generate(case)
        return lambda: jaxvs.diagnose(cal, val, family=case.family, seed=0)
    if name == "design":
        sys.path.insert(0, str(HERE))
        import design_study

        rec = design_study.spindle_records(12.0, 60.0)
        return lambda: jaxvs.design(rec, target="T_bearing", progress=False, hidden=(3,), inits=1)
    raise ValueError(f"unknown entry point {name!r}; choose from {ENTRIES}")


def child(name: str, cache: str) -> None:
    t0 = time.perf_counter()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxvs

    jaxvs.enable_compilation_cache(cache)
    t_import = time.perf_counter() - t0
    call = _workload(name)
    t1 = time.perf_counter()
    call()
    first = time.perf_counter() - t1
    t2 = time.perf_counter()
    call()
    second = time.perf_counter() - t2
    print(json.dumps({"import_s": t_import, "first_s": first, "second_s": second}))


def measure(name: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="jaxvs-latency-") as cache:
        out = {}
        for kind in ("cold", "warm"):
            load = os.getloadavg()[0]
            proc = subprocess.run(
                [sys.executable, __file__, "--child", name, "--cache", cache],
                capture_output=True,
                text=True,
                check=False,
            )
            if proc.returncode != 0:
                raise RuntimeError(f"{name} ({kind}) failed:\n{proc.stderr[-3000:]}")
            row = json.loads(proc.stdout.strip().splitlines()[-1])
            row["load_average"] = load
            out[kind] = row
            print(
                f"{name:12s} {kind}: first call {row['first_s']:6.1f} s, second "
                f"{row['second_s']:6.2f} s (import {row['import_s']:.1f} s, load {load:.1f})",
                flush=True,
            )
        n_files = sum(1 for _ in Path(cache).iterdir())
        out["cache_entries"] = n_files
    return out


def markdown(res: dict) -> str:
    lines = [
        "# The time a user waits: first calls, cold and warm",
        "",
        "Fresh process per measurement; *first call* = trace + compile + run, *second call* "
        "= the same call again in that process (run only); *warm* = a new process with the "
        "persistent compilation cache (`jaxvs.enable_compilation_cache`) that the cold one "
        f"filled. Machine: {res['machine']['cpus']} CPUs, load average "
        f"{res['machine']['load_start']:.1f} → {res['machine']['load_end']:.1f} "
        "(above about 1 per core the figures are those of a shared machine, indicative only); jax "
        f"{res['machine']['jax']}, backend {res['machine'].get('backend', 'cpu')}.",
        "",
        "| entry point | workload | first call, cold [s] | first call, warm [s] | second call "
        "[s] | share of the cold call not spent running | cache files |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for name, r in res["entries"].items():
        c, w = r["cold"], r["warm"]
        share = max(0.0, 1 - c["second_s"] / c["first_s"])
        lines.append(
            f"| `{name}` | {WORKLOADS[name]} | {c['first_s']:.1f} | {w['first_s']:.1f} | "
            f"{c['second_s']:.2f} | {100 * share:.0f} % | {r['cache_entries']} |"
        )
    lines += [
        "",
        "Reproduce: `python benchmarks/latency.py`. Turn the cache on in a script with "
        "`jaxvs.enable_compilation_cache()` (the `jaxvs` command does it itself; "
        "`JAXVS_NO_CACHE=1` switches that off).",
    ]
    return "\n".join(lines) + "\n"


WORKLOADS = {
    "calibrate": "4-mode ModalModel, 5000 samples, simulation error",
    "fit_rational": "256 TMFs, order (6, 6), 2000 frequencies",
    "diagnose": f"blind case `{DIAGNOSE_CASE}` (null included)",
    "design": "thermal assistant, 12 h of records, hidden size 3",
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--cache", help=argparse.SUPPRESS)
    ap.add_argument("--only", nargs="*", choices=ENTRIES, default=list(ENTRIES))
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.cache)
        return
    import jax

    load0 = os.getloadavg()[0]
    path = RESULTS / "latency.json"
    old = json.loads(path.read_text()).get("entries", {}) if path.exists() else {}
    entries = {}
    for name in args.only:  # the files are rewritten after each entry point
        entries[name] = measure(name)
        res = {
            "entries": {**old, **entries},
            "machine": {
                "cpus": os.cpu_count(),
                "load_start": load0,
                "load_end": os.getloadavg()[0],
                "platform": platform.platform(),
                "jax": jax.__version__,
                "backend": jax.default_backend(),
            },
        }
        RESULTS.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=2) + "\n")
        md = markdown(res)
        (RESULTS / "latency.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
