"""Batched LTI simulation: `jaxvs.simulate` against a Python loop of `scipy.signal.lfilter`.

One run on one CPU times, for families of order-8 systems (4 lightly damped modes each,
natural frequencies log-spread over 5–150 Hz, damping 1–10 %, dt = 1 ms) and one input
signal per system:

- jaxvs: `jax.jit(jaxvs.simulate)` on the whole family (compile time and run time apart,
  `block_until_ready`, median of several runs);
- peer: a Python loop of `scipy.signal.lfilter(b, a, u_i)` over the same systems, ZOH
  discretised (`jaxvs.discretise`, then `scipy.signal.ss2tf`);
- this machine's memory bandwidth (numpy copy into a pre-faulted buffer), which bounds any
  simulation at `bandwidth / (bytes read + written per system·sample)`: 16 B in float64,
  8 B in float32;
- at the middle size, the engine variants that were tried (see the markdown notes).

Run: `python benchmarks/simulate.py [--quick] [--no-variants]`. Writes
`benchmarks/results/simulate.json` and `benchmarks/results/simulate.md` and prints the table.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.signal as sig  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.models import _simulate  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
DT = 1e-3
SIZES = [(64, 100_000), (1024, 10_000), (4096, 10_000)]
QUICK_SIZES = [(64, 10_000), (256, 10_000)]
TARGET_RATIO = 4.0  # target: >= 4x the lfilter loop at (1024, 1e4), float64
# glibc serves allocations above its mmap threshold (<= 32 MiB) with fresh pages, which
# the kernel must fault in on first write; raising the threshold keeps freed memory in the
# heap. Used only for the extra "allocator" row (a subprocess), never for the main rows.
GLIBC_TUNABLES = "glibc.malloc.mmap_threshold=2147483647:glibc.malloc.trim_threshold=4294967295"


def family(n_systems: int, seed: int = 0) -> jaxvs.ModalModel:
    rng = np.random.default_rng(seed)
    f = np.sort(np.exp(rng.uniform(np.log(5.0), np.log(150.0), (n_systems, 4))), axis=-1)
    w = 2 * np.pi * f
    zeta = rng.uniform(0.01, 0.1, (n_systems, 4))
    res = rng.normal(size=(n_systems, 4)) * w**2 / 4
    return jaxvs.ModalModel(jnp.asarray(w), jnp.asarray(zeta), jnp.asarray(res))


def lfilter_coefficients(model: jaxvs.ModalModel) -> list[tuple[np.ndarray, np.ndarray]]:
    A, B, C, D = (np.asarray(x) for x in jaxvs.discretise(model, DT, "zoh").to_state_space())
    out = []
    for i in range(A.shape[0]):
        b, a = sig.ss2tf(A[i], B[i], C[i], D[i])
        out.append((b[0], a))
    return out


def timed(fn, repeats: int) -> tuple[float, float]:
    """Median and minimum wall time of `repeats` calls (blocking on the result)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), float(np.min(times))


def memory_bandwidth() -> dict:
    """Copy bandwidth [GB/s] counting bytes read + written: numpy into a pre-faulted
    buffer (the physical limit used below), and a jitted JAX copy (fresh output buffer)."""
    n = 32 * 2**20  # 256 MiB of float64
    src = np.random.default_rng(0).normal(size=n)
    dst = np.empty_like(src)
    np.copyto(dst, src)
    t_np, _ = timed(lambda: np.copyto(dst, src), 7)
    t_np = min(t_np, timed(lambda: np.copyto(dst, src), 7)[1])
    x = jnp.asarray(src)
    f = jax.jit(lambda v: v * 1.0000001)
    jax.block_until_ready(f(x))
    t_jx, _ = timed(lambda: f(x), 7)
    return {
        "numpy_copy_prefaulted_GBps": 2 * src.nbytes / t_np / 1e9,
        "jax_copy_fresh_output_GBps": 2 * src.nbytes / t_jx / 1e9,
    }


# --- engine variants (only at the middle size) ----------------------------------------


def variant_scan_dense(model, u):
    """`lax.scan` over time, `vmap` over systems, dense discrete state space."""
    A, B, C, D = jaxvs.discretise(model, DT, "zoh").to_state_space()

    def one(a, b, c, d, ui):
        def step(x, uk):
            return a @ x + b[:, 0] * uk, c[0] @ x + d[0, 0] * uk

        return jax.lax.scan(step, jnp.zeros(a.shape[0], ui.dtype), ui)[1]

    return jax.vmap(one)(A, B, C, D, u)


def variant_scan_modal_lanes(model, u):
    """`lax.scan` over time with the systems in the vector lanes, 2x2 modal blocks."""
    r = jaxvs.discretise(model, DT, "zoh")
    a = jnp.moveaxis(r.a, 0, -1)  # (block, 2, 2, S)
    b = jnp.moveaxis(r.b[..., 0], 0, -1)  # (block, 2, S)
    c = jnp.moveaxis(r.c[:, 0], 0, -1)  # (block, 2, S)

    def step(x, uk):
        y = jnp.sum(c * x, axis=(0, 1))
        return a[:, :, 0] * x[:, None, 0] + a[:, :, 1] * x[:, None, 1] + b * uk, y

    _, y = jax.lax.scan(step, jnp.zeros(b.shape, u.dtype), u.T)
    return y.T


def run_variants(model, u, repeats: int) -> list[dict]:
    n = u.size
    rows = []
    cands = [
        ("lax.scan + vmap, dense state space", variant_scan_dense, {}),
        ("lax.scan, systems in lanes, modal blocks", variant_scan_modal_lanes, {}),
    ]
    for k in (8, 16, 32):
        cands.append((f"jaxvs blocked engine, K = {k}", None, {"_K": k}))
    for label, fn, patch in cands:
        saved = {name: getattr(_simulate, name) for name in patch}
        for name, value in patch.items():
            setattr(_simulate, name, value)
        try:
            if fn is None:
                f = jax.jit(lambda m, v: jaxvs.simulate(m, v, DT))
            else:
                f = jax.jit(fn)
            t0 = time.perf_counter()
            jax.block_until_ready(f(model, u))
            compile_s = time.perf_counter() - t0
            med, mn = timed(lambda f=f: f(model, u), repeats)
        finally:
            for name, value in saved.items():
                setattr(_simulate, name, value)
        rows.append(
            {
                "variant": label,
                "compile_s": compile_s,
                "run_s": med,
                "run_min_s": mn,
                "Mps": n / med / 1e6,
            }
        )
    return rows


def allocator_row(systems: int, samples: int) -> dict | None:
    """jaxvs at one size in a subprocess with glibc's mmap threshold raised (see above)."""
    code = (
        "import sys; sys.argv=['x'];"
        f"from benchmarks.simulate import _allocator_child; _allocator_child({systems}, {samples})"
    )
    env = dict(os.environ, GLIBC_TUNABLES=GLIBC_TUNABLES)
    root = Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(
            [sys.executable, "-c", code],
            env=env,
            cwd=root,
            capture_output=True,
            text=True,
            timeout=300,
        )
        return json.loads(out.stdout.strip().splitlines()[-1])
    except Exception as e:  # the extra row is informative only
        print(f"allocator row skipped: {e!r}")
        return None


def _allocator_child(systems: int, samples: int) -> None:
    model = family(systems)
    u = jnp.asarray(np.random.default_rng(1).normal(size=(systems, samples)))
    f = jax.jit(lambda m, v: jaxvs.simulate(m, v, DT))
    jax.block_until_ready(f(model, u))
    med, mn = timed(lambda: f(model, u), 5)
    print(json.dumps({"run_s": med, "run_min_s": mn, "Mps": systems * samples / med / 1e6}))


# --- main ---------------------------------------------------------------------------------


def bench_case(systems: int, samples: int, dtype, coeffs, model, repeats: int) -> dict:
    rng = np.random.default_rng(1)
    u64 = rng.normal(size=(systems, samples))
    u_np = u64.astype(dtype)
    u = jnp.asarray(u_np)
    f = jax.jit(lambda m, v: jaxvs.simulate(m, v, DT))
    t0 = time.perf_counter()
    y = jax.block_until_ready(f(model, u))
    compile_s = time.perf_counter() - t0
    cf = [(b.astype(dtype), a.astype(dtype)) for b, a in coeffs]

    def lfilter_loop():
        return [sig.lfilter(b, a, u_np[i]) for i, (b, a) in enumerate(cf)]

    # The fastest any jitted JAX program that reads u and writes a fresh (S, N) output can
    # be on this machine: one elementwise pass.
    floor = jax.jit(lambda v: v * 1.0000001)
    jax.block_until_ready(floor(u))
    # interleave the three so that they see the same background load
    t_j, t_l, t_c = [], [], []
    for _ in range(repeats):
        t_j.append(timed(lambda: f(model, u), 1)[0])
        t_l.append(timed(lfilter_loop, 1)[0])
        t_c.append(timed(lambda: floor(u), 1)[0])
    ref = lfilter_loop()
    check = [0, systems // 2, systems - 1]
    lf_err = max(
        float(np.max(np.abs(np.asarray(y[i], float) - ref[i])) / np.max(np.abs(ref[i])))
        for i in check
    )
    n = systems * samples
    return {
        "systems": systems,
        "samples": samples,
        "dtype": np.dtype(dtype).name,
        "compile_s": compile_s,
        "run_s": float(np.median(t_j)),
        "run_min_s": float(np.min(t_j)),
        "Mps": n / float(np.median(t_j)) / 1e6,
        "lfilter_s": float(np.median(t_l)),
        "lfilter_Mps": n / float(np.median(t_l)) / 1e6,
        "ratio_vs_lfilter": float(np.median(t_l)) / float(np.median(t_j)),
        "jax_copy_Mps": n / float(np.median(t_c)) / 1e6,
        "jax_copy_ratio_vs_lfilter": float(np.median(t_l)) / float(np.median(t_c)),
        "max_rel_diff_vs_lfilter": lf_err,
        "output": np.asarray(y),
    }


def _np_reduce(y: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """What a user does with a simulated member: RMS error and correlation vs a target."""
    e = y - t
    yc, tc = y - y.mean(), t - t.mean()
    return float(np.sqrt(np.mean(e * e))), float(
        np.dot(yc, tc) / np.sqrt(np.dot(yc, yc) * np.dot(tc, tc))
    )


def bench_fused(systems: int, samples: int, coeffs, model, repeats: int) -> dict:
    """Simulate-and-reduce (per-member RMS error and correlation against a measured target,
    float64): `jaxvs.simulate_metrics` (fused, never writes the output), `jaxvs.simulate`
    then the same reduction in the jitted program (materialising), and a Python loop of
    `lfilter` + numpy reduction; interleaved, median of `repeats`."""
    rng = np.random.default_rng(2)
    u_np = rng.normal(size=(systems, samples))
    t_np = rng.normal(size=(systems, samples))
    u, t = jnp.asarray(u_np), jnp.asarray(t_np)
    fused = jax.jit(lambda m, v, w: jaxvs.simulate_metrics(m, v, DT, w))

    def _mat(m, v, w):
        y = jaxvs.simulate(m, v, DT)
        e = y - w
        yc = y - y.mean(-1, keepdims=True)
        tc = w - w.mean(-1, keepdims=True)
        corr = jnp.sum(yc * tc, -1) / jnp.sqrt(jnp.sum(yc * yc, -1) * jnp.sum(tc * tc, -1))
        return jnp.sqrt(jnp.mean(e * e, -1)), corr

    mat = jax.jit(_mat)
    t0 = time.perf_counter()
    got = jax.block_until_ready(fused(model, u, t))
    compile_fused = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(mat(model, u, t))
    compile_mat = time.perf_counter() - t0

    def loop():
        return [_np_reduce(sig.lfilter(b, a, u_np[i]), t_np[i]) for i, (b, a) in enumerate(coeffs)]

    t_f, t_m, t_l = [], [], []
    for _ in range(repeats):
        t_f.append(timed(lambda: fused(model, u, t), 1)[0])
        t_m.append(timed(lambda: mat(model, u, t), 1)[0])
        t_l.append(timed(loop, 1)[0])
    ref = np.array(loop())
    err = float(np.max(np.abs(np.asarray(got.rms_error) - ref[:, 0]) / ref[:, 0]))
    n = systems * samples
    med = {k: float(np.median(v)) for k, v in (("f", t_f), ("m", t_m), ("l", t_l))}
    return {
        "systems": systems,
        "samples": samples,
        "dtype": "float64",
        "compile_fused_s": compile_fused,
        "compile_materialising_s": compile_mat,
        "fused_s": med["f"],
        "materialising_s": med["m"],
        "lfilter_numpy_s": med["l"],
        "fused_Mps": n / med["f"] / 1e6,
        "materialising_Mps": n / med["m"] / 1e6,
        "lfilter_numpy_Mps": n / med["l"] / 1e6,
        "fused_ratio_vs_lfilter_numpy": med["l"] / med["f"],
        "materialising_ratio_vs_lfilter_numpy": med["l"] / med["m"],
        "max_rel_diff_rms_error_vs_lfilter": err,
        "load_average": os.getloadavg()[0],
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    ap.add_argument("--no-variants", action="store_true", help="skip the engine variants")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument(
        "--markdown-only",
        action="store_true",
        help="rewrite simulate.md from the existing simulate.json (no timing)",
    )
    ap.add_argument(
        "--fused-only",
        action="store_true",
        help="time only simulate-and-reduce (keeps the other figures of simulate.json)",
    )
    args = ap.parse_args(argv)
    if args.fused_only:
        out = json.loads((RESULTS / "simulate.json").read_text())
        out["fused"] = run_fused(args)
        (RESULTS / "simulate.json").write_text(json.dumps(out, indent=2) + "\n")
        md = markdown(out)
        (RESULTS / "simulate.md").write_text(md)
        print(md)
        return out
    if args.markdown_only:
        out = json.loads((RESULTS / "simulate.json").read_text())
        (RESULTS / "simulate.md").write_text(markdown(out))
        return out
    sizes = QUICK_SIZES if args.quick else SIZES
    bw = memory_bandwidth()
    limit_gbps = bw["numpy_copy_prefaulted_GBps"]
    cases, f32_err = [], {}
    for systems, samples in sizes:
        model = family(systems)
        coeffs = lfilter_coefficients(model)
        res = {}
        for dtype in (np.float64, np.float32):
            row = bench_case(systems, samples, dtype, coeffs, model, args.repeats)
            res[row["dtype"]] = row.pop("output")
            bytes_per = 2 * np.dtype(dtype).itemsize
            row["bandwidth_limit_Mps"] = limit_gbps * 1e9 / bytes_per / 1e6
            row["fraction_of_limit"] = row["Mps"] / row["bandwidth_limit_Mps"]
            cases.append(row)
            print(
                f"{systems:5d} x {samples:6d} {row['dtype']:7s}  jaxvs {row['Mps']:7.1f} M/s "
                f"(compile {row['compile_s']:.2f} s)  lfilter {row['lfilter_Mps']:7.1f} M/s  "
                f"ratio {row['ratio_vs_lfilter']:.2f}",
                flush=True,
            )
        d = res["float32"].astype(np.float64) - res["float64"]
        f32_err[f"{systems}x{samples}"] = float(np.max(np.abs(d)) / np.max(np.abs(res["float64"])))
        del res
    variants, alloc = [], None
    mid = (1024, 10_000) if not args.quick else sizes[-1]
    if not args.no_variants:
        model = family(mid[0])
        u = jnp.asarray(np.random.default_rng(1).normal(size=mid))
        variants = run_variants(model, u, 3)
        alloc = allocator_row(*mid)
    fused = run_fused(args)
    target_case = next(
        (
            c
            for c in cases
            if (c["systems"], c["samples"]) == (1024, 10_000) and c["dtype"] == "float64"
        ),
        None,
    )
    out = {
        "benchmark": "batched LTI simulation, order 8 (4 lightly damped modes), dt = 1 ms",
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
            "load_average_at_end": os.getloadavg(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "numpy": np.__version__,
            "scipy": scipy.__version__,
        },
        "memory_bandwidth": bw,
        "bytes_per_system_sample": {"float64": 16, "float32": 8},
        "cases": cases,
        "float32_vs_float64_max_rel_err": f32_err,
        "fused": fused,
        "variants_at": list(mid),
        "variants": variants,
        "allocator_row": alloc,
        "target": {
            "ratio_vs_lfilter_at_1024x10000_float64": TARGET_RATIO,
            "measured": None if target_case is None else target_case["ratio_vs_lfilter"],
            "met": None if target_case is None else target_case["ratio_vs_lfilter"] >= TARGET_RATIO,
        },
    }
    # Keep a short history of the target-size measurement across runs (timings on a shared
    # machine are noisy; the markdown lists every recorded run).
    RESULTS.mkdir(parents=True, exist_ok=True)
    history = []
    previous = RESULTS / "simulate.json"
    if previous.exists():
        try:
            history = json.loads(previous.read_text()).get("history", [])
        except (ValueError, AttributeError):
            history = []
    if target_case is not None:
        history.append(
            {
                "date": time.strftime("%Y-%m-%d %H:%M"),
                "load_average": out["machine"]["load_average_at_end"][0],
                "jaxvs_Mps": target_case["Mps"],
                "lfilter_Mps": target_case["lfilter_Mps"],
                "ratio_vs_lfilter": target_case["ratio_vs_lfilter"],
                "jax_copy_ratio_vs_lfilter": target_case["jax_copy_ratio_vs_lfilter"],
            }
        )
    out["history"] = history[-6:]
    (RESULTS / "simulate.json").write_text(json.dumps(out, indent=2) + "\n")
    md = markdown(out)
    (RESULTS / "simulate.md").write_text(md)
    print(md)
    return out


def run_fused(args) -> list[dict]:
    sizes = [(256, 10_000)] if args.quick else [(1024, 10_000)]
    rows = []
    for systems, samples in sizes:
        model = family(systems)
        row = bench_fused(systems, samples, lfilter_coefficients(model), model, args.repeats)
        print(
            f"simulate-and-reduce {systems} x {samples}: fused {row['fused_Mps']:.1f} M/s, "
            f"materialising {row['materialising_Mps']:.1f} M/s, lfilter+numpy "
            f"{row['lfilter_numpy_Mps']:.1f} M/s; fused/loop "
            f"{row['fused_ratio_vs_lfilter_numpy']:.2f}x (load {row['load_average']:.1f})",
            flush=True,
        )
        rows.append(row)
    return rows


def markdown(out: dict) -> str:
    bw = out["memory_bandwidth"]
    load = tuple(round(x, 1) for x in out["machine"]["load_average_at_end"])
    lines = [
        "# Batched LTI simulation: `jaxvs.simulate` vs a loop of `scipy.signal.lfilter`",
        "",
        f"Order-8 systems (4 lightly damped modes), one input per system, dt = 1 ms. "
        f"Machine: {out['machine']['processor']}, {out['machine']['cpu_count']} cores, "
        f"load average at the end {load}; "
        f"jax {out['machine']['jax']}, scipy {out['machine']['scipy']}. Run time = median of "
        "several runs (jaxvs and lfilter interleaved), compile time separate; throughput in "
        "M system·samples/s. *JAX copy*: a jitted `y = 1.0000001 * u` on the same input, i.e. "
        "one streaming pass into a fresh output — no jitted JAX program can be faster.",
        "",
        f"Memory bandwidth (copy, read + write): {bw['numpy_copy_prefaulted_GBps']:.1f} GB/s "
        f"(numpy, pre-faulted buffer; used as the limit), {bw['jax_copy_fresh_output_GBps']:.1f} "
        "GB/s (jitted JAX copy into a fresh output). Limit = bandwidth / 16 B per "
        "system·sample in float64, / 8 B in float32.",
        "",
        "| systems | samples | dtype | compile [s] | jaxvs [ms] | jaxvs [M/s] | lfilter [M/s] "
        "| ratio | JAX copy [M/s] | copy/lfilter | limit [M/s] | of limit |",
        "|---:|---:|:---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in out["cases"]:
        lines.append(
            f"| {c['systems']} | {c['samples']} | {c['dtype']} | {c['compile_s']:.2f} | "
            f"{1e3 * c['run_s']:.1f} | {c['Mps']:.1f} | {c['lfilter_Mps']:.1f} | "
            f"{c['ratio_vs_lfilter']:.2f} | {c['jax_copy_Mps']:.0f} | "
            f"{c['jax_copy_ratio_vs_lfilter']:.2f} | {c['bandwidth_limit_Mps']:.0f} | "
            f"{100 * c['fraction_of_limit']:.1f} % |"
        )
    lines += ["", "float32 vs float64 (jaxvs), max relative error: "]
    lines.append(
        ", ".join(f"{k}: {v:.1e}" for k, v in out["float32_vs_float64_max_rel_err"].items())
    )
    t = out["target"]
    if t["measured"] is not None:
        lines += [
            "",
            f"Target: >= {t['ratio_vs_lfilter_at_1024x10000_float64']:.0f}x "
            f"the lfilter loop at 1024 x 10^4 in float64. Measured: {t['measured']:.2f}x — "
            f"{'met' if t['met'] else 'NOT met'}.",
        ]
    if out.get("history"):
        lines += [
            "",
            "Recorded runs at 1024 x 10^4, float64 (this file keeps the last six):",
            "",
            "| date | load avg | jaxvs [M/s] | lfilter [M/s] | jaxvs / lfilter "
            "| JAX copy / lfilter |",
            "|:---|---:|---:|---:|---:|---:|",
        ]
        for h in out["history"]:
            lines.append(
                f"| {h['date']} | {h['load_average']:.1f} | {h['jaxvs_Mps']:.1f} | "
                f"{h['lfilter_Mps']:.1f} | {h['ratio_vs_lfilter']:.2f} | "
                f"{h['jax_copy_ratio_vs_lfilter']:.2f} |"
            )
    if out.get("fused"):
        lines += [
            "",
            "## Simulate and reduce (float64)",
            "",
            "Per-member RMS error and correlation against a measured target: "
            "`jaxvs.simulate_metrics` (fused: each lane group's output is reduced inside the "
            "group and never written out), `jaxvs.simulate` followed by the same reduction in "
            "one jitted program (materialising), and a Python loop of `lfilter` + numpy "
            "reduction. Median of interleaved runs; compile separate.",
            "",
            "| systems | samples | fused [ms] | materialising [ms] | lfilter + numpy [ms] "
            "| fused / loop | materialising / loop | compile fused [s] | load avg |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for f in out["fused"]:
            lines.append(
                f"| {f['systems']} | {f['samples']} | {1e3 * f['fused_s']:.1f} | "
                f"{1e3 * f['materialising_s']:.1f} | {1e3 * f['lfilter_numpy_s']:.1f} | "
                f"{f['fused_ratio_vs_lfilter_numpy']:.2f} | "
                f"{f['materialising_ratio_vs_lfilter_numpy']:.2f} | "
                f"{f['compile_fused_s']:.2f} | {f['load_average']:.1f} |"
            )
    if out["variants"]:
        s, n = out["variants_at"]
        lines += [
            "",
            f"## Engine variants ({s} x {n}, float64, same run)",
            "",
            "| variant | compile [s] | run [ms] | M/s |",
            "|:---|---:|---:|---:|",
        ]
        for v in out["variants"]:
            lines.append(
                f"| {v['variant']} | {v['compile_s']:.2f} | {1e3 * v['run_s']:.1f} | "
                f"{v['Mps']:.1f} |"
            )
        if out["allocator_row"]:
            a = out["allocator_row"]
            lines.append(
                f"| jaxvs engine, glibc mmap threshold raised (subprocess) | – | "
                f"{1e3 * a['run_s']:.1f} | {a['Mps']:.1f} |"
            )
    hist = [h["jax_copy_ratio_vs_lfilter"] for h in out.get("history", [])] or [float("nan")]
    allr = [c["jax_copy_ratio_vs_lfilter"] for c in out["cases"]]
    lines += [
        "",
        NOTES.format(
            copy_target=f"{min(hist):.1f}–{max(hist):.1f}x",
            copy_all=f"{min(allr):.1f}–{max(allr):.1f}x",
        ),
    ]
    return "\n".join(lines) + "\n"


NOTES = """## What the engine does

`jaxvs.simulate` (`jaxvs/models/_simulate.py`) discretises the block-modal realisation
(one 2x2 block per pole pair) and runs it in blocks of K = 16 samples: per block the
output is a Toeplitz product of the Markov parameters with the block's inputs plus an
observability product with the block's initial state, and the block's zero-state end state
is a third product — dense matrix products over all blocks at once (XLA:CPU hands them to
YNNPACK). The block states follow from `s[q+1] = Ad^K s[q] + z[q]`, solved by the same
blocking recursively (fan-out 3–8, closed form inside a chunk) down to a scan of at most 16
steps. Lanes (family members or input experiments) run in groups of about 2^20 samples under
`jax.lax.map`. Results equal the sample-by-sample recursion to ~1e-15 relative in float64
(tests/test_simulate.py); float32 agrees with float64 to the error in the table.

## Why the 4x target is not met here

The *JAX copy* column is one jitted elementwise pass, `y = 1.0000001 * u`, on the same
input: it reads `u` once and writes a fresh output of the same size, which is the least any
jitted JAX function returning the simulated outputs has to do. At the target size it ran at
only {copy_target} the lfilter loop in the recorded runs (column "JAX copy / lfilter" above;
{copy_all} over all sizes of this run): XLA:CPU writes a freshly allocated
80–330 MB output, glibc hands such buffers out as fresh pages, and faulting them in costs
about as much as the copy itself (compare the numpy copy into a pre-faulted buffer with
the jitted copy in the header). A 4x target therefore sits above what a single streaming
pass achieves in JAX on this VM, before any arithmetic. The engine reaches about a third
of the copy's throughput: per lane group it slices the inputs (one read of u), writes the
group's outputs into the result (one write of y, after XLA initialised the whole result
buffer), and in between spends roughly equal time in the three products and in the
block-state levels (profiles with `jax.profiler` during development).

Variants, from the table above (same run) and from exploratory runs on the same 2-core VM
(load average 2–12 from other jobs, so only same-run ratios are meaningful):

- `lax.scan` over time, one step per sample (dense `vmap`, or the systems in the vector
  lanes with 2x2 modal blocks, `unroll` 1–64): 20–80 M/s. Each step re-reads the
  coefficients and the state through memory and costs several thunks; unrolling does not
  fuse steps (XLA recomputes a fused 2x2 recursion exponentially, so it splits it).
- The blocked engine with the products written as elementwise sums over the lanes
  (`Σ_j h_j u[..., j]`): fast in isolation but XLA fuses shared intermediates into every
  consumer (recomputation) and fuses the output sum into the dynamic-update-slice of the
  result, whose emitter does not vectorise; 2–4x slower than the `einsum` products kept.
- The blocked engine over all lanes at once (no lane groups): 2x slower (every
  intermediate is a fresh, memory-sized buffer).
- Block size K = 8 / 16 / 32 (rows above): K = 8 is slower (twice the block states),
  16 and 32 are within the noise; 16 kept. Lane groups of 2^16–2^22 samples: 2^20 was the
  best or within the noise in exploratory runs.
- The variant rows run jaxvs back to back, which is faster than the main rows where
  every jaxvs run is interleaved with the lfilter loop and the JAX copy (presumably those evict the
  caches and return freed memory to the OS between jaxvs runs); the main rows are the
  like-for-like comparison.
- A depthwise `conv_general_dilated` for the Toeplitz part, and `einsum` for the 2x2 block
  algebra: much slower in float64 on CPU (and ~0.5 s of compile time per tiny dot).

Reaching 4x the lfilter loop would take a kernel that streams each system's samples once
with the state in registers and writes into reused memory (e.g. a C or Numba kernel behind
an XLA custom call) — not something a pure-JAX library can ship; on such a kernel the
blocked formulation is not needed at all.
"""


if __name__ == "__main__":
    main()
