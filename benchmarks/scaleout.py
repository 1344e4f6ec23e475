"""Benchmark: scale-out of families over host devices with `jax.sharding`.

This machine has 2 CPU cores. XLA exposes them as 2 host devices when
`XLA_FLAGS=--xla_force_host_platform_device_count=2` is set before JAX starts (done at the
top of this script). In ONE run, the same three family workloads run on a mesh of 1
device and on a mesh of 2 devices (the peer is the 1-device run of the same code, plus
the plain unsharded `jaxvs` call):

1. `simulate_sharded`: a family of 256 order-8 modal models (4 modes each), 20 000
   samples each, one white-noise input per member (zero-order-hold engine).
2. `calibrate_family_sharded`: 32 independent two-mode accelerance fits (FRFs with 400
   lines, 1 % noise) by Levenberg-Marquardt with covariance. On CPU host devices its
   blocks run one after another (XLA's CPU runtime can stall when two programs with
   LAPACK calls run at once), so expect no speed-up here; it is measured to show that.
3. `sweep`: peak receptance of a single-mode model over a 64 x 32 grid of natural
   frequency and damping, 2000 frequency lines per point.

Compile time and run time (median of repeats) are reported separately; the speed-up is
run time on 1 device / run time on 2 devices. The machine is shared with other jobs while
this runs, so absolute timings are noisy; the ratio within one run is what counts. Run
`python benchmarks/scaleout.py` (about 2 minutes; `--quick` for a smoke run). Writes
`benchmarks/results/scaleout.json` and `.md`.
"""

import os

os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
).strip()

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.calibration import FrequencyError  # noqa: E402


def timed(fn, repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        runs.append(time.perf_counter() - t0)
    run = statistics.median(runs)
    return max(first - run, 0.0), run


def simulate_case(n, n_samples, repeats):
    rng = np.random.default_rng(0)
    f = np.sort(rng.uniform(5.0, 400.0, (n, 4)), axis=1)
    fam = jaxvs.ModalModel(
        jnp.asarray(2 * np.pi * f),
        jnp.asarray(rng.uniform(0.01, 0.1, (n, 4))),
        jnp.asarray(rng.normal(size=(n, 4)) * (2 * np.pi * f) ** 2),
    )
    u = jnp.asarray(rng.normal(size=(n, n_samples)))
    dt = 1e-4
    out = {}
    out["unsharded"] = timed(lambda: jaxvs.simulate(fam, u, dt), repeats)
    ref = np.asarray(jaxvs.simulate(fam, u, dt))
    for d in (1, 2):
        mesh = jaxvs.family_mesh(d)
        out[d] = timed(lambda mesh=mesh: jaxvs.simulate_sharded(fam, u, dt, mesh=mesh), repeats)
        y = np.asarray(jaxvs.simulate_sharded(fam, u, dt, mesh=mesh))
        out[f"{d}_max_rel_diff"] = float(np.max(np.abs(y - ref)) / np.max(np.abs(ref)))
    return out


def calibrate_case(n, repeats):
    rng = np.random.default_rng(1)
    w = jnp.asarray(2 * np.pi * np.sort(rng.uniform(20.0, 200.0, (n, 2)), axis=1))
    z = jnp.asarray(rng.uniform(0.02, 0.06, (n, 2)))
    r = jnp.asarray(rng.uniform(0.5, 2.0, (n, 2)))
    true = jaxvs.ModalModel(w, z, r * w**2)
    omega = jnp.linspace(2 * np.pi * 5.0, 2 * np.pi * 300.0, 400)
    H = np.asarray(jaxvs.frequency_response(true, omega))
    H = H + 0.01 * np.abs(H).mean(axis=-1, keepdims=True) * (
        rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape)
    )
    data = [{"omega": omega, "H": jnp.asarray(H[i])} for i in range(n)]
    guess = jaxvs.ModalModel(w * 1.01, z * 1.2, r * w**2 * 0.9)
    out = {}
    ref = jaxvs.calibrate_family(guess, data, FrequencyError())
    out["unsharded"] = (float(ref.stats["compile_time"][0]), float(ref.stats["run_time"][0]))
    for d in (1, 2):
        mesh = jaxvs.family_mesh(d)
        res = jaxvs.calibrate_family_sharded(guess, data, FrequencyError(), mesh=mesh)
        compile_time = float(np.asarray(res.stats["compile_time"])[0])
        runs = []
        for _ in range(repeats):
            again = jaxvs.calibrate_family_sharded(guess, data, FrequencyError(), mesh=mesh)
            runs.append(float(np.asarray(again.stats["run_time"])[0]))
        out[d] = (compile_time, statistics.median(runs))
        out[f"{d}_max_rel_diff"] = float(
            np.max(np.abs(np.asarray(res.values) - np.asarray(ref.values)) / np.abs(ref.values))
        )
    return out


def sweep_case(n_w, n_z, n_freq, repeats):
    omega = jnp.linspace(1.0, 2000.0, n_freq)

    def peak(p, omega):
        m = jaxvs.ModalModel(p["wn"][None], p["zeta"][None], jnp.ones(1))
        return {"peak": jnp.max(jnp.abs(jaxvs.frequency_response(m, omega)))}

    grid = {"wn": jnp.linspace(100.0, 1500.0, n_w), "zeta": jnp.linspace(0.005, 0.2, n_z)}
    out = {}
    ref = jaxvs.sweep(peak, grid, omega, progress=False)
    for d in (1, 2):
        mesh = jaxvs.family_mesh(d)
        res = jaxvs.sweep(peak, grid, omega, mesh=mesh, progress=False)
        runs = [
            jaxvs.sweep(peak, grid, omega, mesh=mesh, progress=False).stats["run_time"]
            for _ in range(repeats)
        ]
        out[d] = (res.stats["compile_time"], statistics.median(runs))
        out[f"{d}_max_rel_diff"] = float(
            np.max(np.abs(res["peak"] - ref["peak"]) / np.abs(ref["peak"]))
        )
    runs = [
        jaxvs.sweep(peak, grid, omega, progress=False).stats["run_time"] for _ in range(repeats)
    ]
    out["unsharded"] = (ref.stats["compile_time"], statistics.median(runs))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, for a smoke run")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    assert jax.device_count() >= 2, "needs 2 host devices (XLA_FLAGS set before jax import)"
    q = args.quick
    repeats = 2 if q else 5
    cases = {
        "simulate: 256 order-8 models x 20000 samples": simulate_case(
            32 if q else 256, 2000 if q else 20000, repeats
        ),
        "calibrate_family: 32 two-mode FRF fits": calibrate_case(8 if q else 32, repeats),
        "sweep: 64 x 32 grid x 2000 lines": sweep_case(
            16 if q else 64, 8 if q else 32, 500 if q else 2000, repeats
        ),
    }
    rows = []
    for name, c in cases.items():
        rows.append(
            {
                "workload": name,
                "unsharded_compile_s": c["unsharded"][0],
                "unsharded_run_s": c["unsharded"][1],
                "compile_1dev_s": c[1][0],
                "run_1dev_s": c[1][1],
                "compile_2dev_s": c[2][0],
                "run_2dev_s": c[2][1],
                "speedup_1_to_2": c[1][1] / c[2][1],
                "max_rel_diff_vs_unsharded": max(c["1_max_rel_diff"], c["2_max_rel_diff"]),
            }
        )
    meta = {
        "machine": platform.machine(),
        "cpu_cores": os.cpu_count(),
        "devices": [str(d) for d in jax.devices()],
        "jax": jax.__version__,
        "quick": q,
        "repeats": repeats,
    }
    lines = [
        "| workload | unsharded run [s] | 1 device run [s] | 2 devices run [s] | speed-up 1→2 "
        "| compile 1 / 2 dev [s] | max rel. diff vs unsharded |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['workload']} | {r['unsharded_run_s']:.3f} | {r['run_1dev_s']:.3f} | "
            f"{r['run_2dev_s']:.3f} | **{r['speedup_1_to_2']:.2f}x** | "
            f"{r['compile_1dev_s']:.1f} / {r['compile_2dev_s']:.1f} | "
            f"{r['max_rel_diff_vs_unsharded']:.1e} |"
        )
    table = "\n".join(lines)
    print(table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not q:
        (out / "scaleout.json").write_text(
            json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n"
        )
        header = (
            "Scale-out over host devices (jax.sharding mesh on the family axis), "
            f"{meta['cpu_cores']} CPU cores, jax {meta['jax']}, median of {repeats} runs.\n\n"
        )
        (out / "scaleout.md").write_text(header + table + "\n")


if __name__ == "__main__":
    main()
