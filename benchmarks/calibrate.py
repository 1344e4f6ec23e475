"""Benchmark: rational TMF fits with `jaxvs.fit_rational` against a scipy loop.

Three measurements in ONE run on the same CPU:

1. **Success rate**: random order-6/6 TMF-like systems, 1 % complex noise, no initial guess:
   the fraction whose fit recovers the noiseless response within 1 % relative L2 error.
2. **Speed**: one vectorised call fitting 256 such systems vs a Python loop of
   `scipy.optimize.least_squares(method="lm")` (MINPACK) with an analytic Jacobian, started
   from the same linear initialisation (jaxvs's Sanathanan-Koerner result) and working in
   the same scaled coefficients; compile time reported separately.
3. **Optimisers**: Levenberg-Marquardt (jaxvs) vs BFGS (optimistix) vs Adam (optax) from
   the same initialisation: time to reach the Levenberg-Marquardt residual.

Run `python benchmarks/calibrate.py` (3-4 minutes; `--quick` for a smoke run). Writes
`benchmarks/results/calibrate.json` and `.md` and prints the table. The machine is shared
while this runs, so absolute timings are noisy; ratios within one run are what count.

Resources: by default the process is pinned to ONE core (before JAX and NumPy start their
thread pools), so jaxvs and scipy's single-threaded MINPACK loop get the same resources;
on a shared machine this also keeps XLA's two-thread pool from waiting on a core that
another process holds. The speed comparison is then repeated unpinned (all cores, a
subprocess with `--no-pin`) and both are reported.
"""

import os
import sys

if "--no-pin" not in sys.argv:
    os.sched_setaffinity(0, {max(os.sched_getaffinity(0))})
# scipy's per-fit work is small matrix products: BLAS threads only add contention with
# XLA's thread pool, so both peers run with the library defaults except this one.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402
import optimistix as optx  # noqa: E402
import scipy  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.calibration import RESULTS, _sk  # noqa: E402

F_LO, F_HI = 5.0, 500.0  # Hz, band of the natural frequencies
BAND = (F_LO / 2, 2 * F_HI)  # Hz, measured band: an octave of margin on each side
N_FREQ = 2000
ORDER = (6, 6)
NOISE = 0.01  # complex noise, standard deviation 1 % of |H|


def make_problems(seed: int, count: int):
    """Random TMF-like systems `H(s) = d + Σ_k r_k ω_k² / (s² + 2 ζ_k ω_k s + ω_k²)`.

    Three modes with natural frequencies log-uniform in [5, 500] Hz and damping ratios
    log-uniform in [0.005, 0.05]; modal constants `r_k` and feedthrough `d` standard
    normal. Numerator and denominator have order 6 (a transmissibility function:
    resonances and anti-resonances, `H(∞) = d`). Data: 2000 log-spaced points over
    [2.5, 1000] Hz with complex noise of standard deviation 1 % of |H| at each point.
    """
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * np.geomspace(*BAND, N_FREQ)
    s = 1j * omega
    h0 = np.empty((count, N_FREQ), complex)
    for i in range(count):
        w = 2 * np.pi * np.exp(rng.uniform(np.log(F_LO), np.log(F_HI), 3))
        z = np.exp(rng.uniform(np.log(0.005), np.log(0.05), 3))
        r, d = rng.normal(size=3), rng.normal()
        h0[i] = d + np.sum(r * w**2 / (s[:, None] ** 2 + 2 * z * w * s[:, None] + w**2), axis=1)
    e = (rng.normal(size=h0.shape) + 1j * rng.normal(size=h0.shape)) / np.sqrt(2)
    return omega, h0, h0 + NOISE * np.abs(h0) * e


def rel_error(model, omega, h0):
    g = np.asarray(jaxvs.frequency_response(model, jnp.asarray(omega)))
    return np.linalg.norm(g - h0, axis=-1) / np.linalg.norm(h0, axis=-1)


def timed(fn, repeat: int):
    """First call (compile + run) and the median / min of `repeat` further calls [s]."""
    t = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = jax.block_until_ready(fn())
        runs.append(time.perf_counter() - t)
    return out, first, float(np.median(runs)), float(np.min(runs))


def code_counts(report) -> dict[str, int]:
    values = np.asarray(report.result._value).ravel()
    return {
        name: int(np.sum(values == i))
        for i, name in enumerate(RESULTS._name_to_item)
        if np.any(values == i)
    }


def percentiles(x) -> dict[str, float]:
    q = np.percentile(x, [50, 90, 99, 100])
    return {"median": float(q[0]), "p90": float(q[1]), "p99": float(q[2]), "max": float(q[3])}


# --- 1. success rate -----------------------------------------------------------------


def success(seed: int, count: int):
    omega, h0, h = make_problems(seed, count)
    out = {}
    for name, w in (("unweighted", None), ("weights=1/|H|", 1 / np.abs(h))):
        model, report = jaxvs.fit_rational(omega, h, ORDER, weights=w, throw=False)
        err = rel_error(model, omega, h0)
        out[name] = {
            "systems": count,
            "success_rate": float(np.mean(err < 0.01)),
            "rel_error": percentiles(err),
            "result_codes": code_counts(report),
            "lm_steps_mean": float(np.mean(report.num_steps)),
            "sk_steps_mean": float(np.mean(report.num_init_steps)),
        }
    return out


# --- 2. speed: one vectorised call vs a scipy loop -----------------------------------


def scaled_theta(model, w0, nb, na):
    """Coefficients in s / ω0, highest power first, monic denominator without its 1."""
    num = np.asarray(model.num) * w0 ** -np.arange(na - nb, na + 1)
    den = np.asarray(model.den) * w0 ** -np.arange(na + 1)
    return np.concatenate([num, den[..., 1:]], axis=-1)


def scipy_loop(omega, h, theta0, w0, **options):
    """`least_squares(method="lm", **options)` per problem, analytic Jacobian, scaled
    coefficients (the parametrisation jaxvs uses), default tolerances (1e-8)."""
    nb, na = ORDER
    x = 1j * omega / w0
    vb = x[:, None] ** np.arange(nb, -1, -1)  # Vandermonde, highest power first
    va = x[:, None] ** np.arange(na - 1, -1, -1)
    xn = x**na

    def parts(th):
        a = xn + va @ th[nb + 1 :]
        return a, (vb @ th[: nb + 1]) / a

    def fun(th, hh):
        _, g = parts(th)
        r = g - hh
        return np.concatenate([r.real, r.imag])

    def jac(th, hh):
        a, g = parts(th)
        j = np.hstack([vb / a[:, None], -(g / a)[:, None] * va])
        return np.vstack([j.real, j.imag])

    costs, nfev, stable = [], [], []
    t = time.perf_counter()
    for i in range(h.shape[0]):
        res = least_squares(fun, theta0[i], jac=jac, method="lm", args=(h[i],), **options)
        costs.append(res.cost)
        nfev.append(res.nfev)
        stable.append(np.all(np.roots(np.concatenate([[1.0], res.x[nb + 1 :]])).real < 0))
    elapsed = time.perf_counter() - t
    return elapsed, np.array(costs), np.array(nfev), np.array(stable)


def speed(seed: int, count: int, repeat: int, rounds: int):
    """jaxvs and scipy alternately, `rounds` times (the machine is shared: alternating
    spreads load changes over both peers); medians over the rounds."""
    omega, h0, h = make_problems(seed, count)
    om, hj = jnp.asarray(omega), jnp.asarray(h)
    full = lambda: jaxvs.fit_rational(om, hj, ORDER, throw=False)
    t = time.perf_counter()
    model, report = jax.block_until_ready(full())
    first = time.perf_counter() - t
    err = rel_error(model, omega, h0)
    # The linear initialisation alone (Levenberg-Marquardt switched off), for both peers.
    init, init_report = jaxvs.fit_rational(om, hj, ORDER, max_steps=0, throw=False)
    w0 = float(init_report.frequency_scale)
    lm_only = lambda: jaxvs.fit_rational(om, hj, ORDER, init=init, throw=False)
    t = time.perf_counter()
    _, lm_report = jax.block_until_ready(lm_only())
    lm_first = time.perf_counter() - t
    theta0 = scaled_theta(init, w0, *ORDER)
    times = {"full": [], "lm": [], "scipy": [], "scipy_jac": []}
    for _ in range(rounds):
        times["full"].append(timed(full, repeat)[2])
        times["lm"].append(timed(lm_only, repeat)[2])
        sp_time, sp_cost, sp_nfev, sp_stable = scipy_loop(omega, h, theta0, w0)
        times["scipy"].append(sp_time)
        # MINPACK's own column scaling (x_scale="jac"), a setting more favourable to scipy.
        spj_time, _, spj_nfev, _ = scipy_loop(omega, h, theta0, w0, x_scale="jac")
        times["scipy_jac"].append(spj_time)
    med = {k: float(np.median(v)) for k, v in times.items()}
    jx_cost = np.asarray(report.residual_norm) ** 2 / 2
    return {
        "systems": count,
        "rounds": rounds,
        "times_s_per_round": times,
        "jaxvs_full_fit": {
            "compile_and_first_run_s": first,
            "run_s_median": med["full"],
            "per_fit_ms": 1e3 * med["full"] / count,
            "success_rate": float(np.mean(err < 0.01)),
            "lm_steps": percentiles(np.asarray(report.num_steps)),
            "sk_steps": percentiles(np.asarray(report.num_init_steps)),
            "result_codes": code_counts(report),
        },
        "jaxvs_lm_only_from_same_init": {
            "compile_and_first_run_s": lm_first,
            "run_s_median": med["lm"],
            "lm_steps": percentiles(np.asarray(lm_report.num_steps)),
        },
        "scipy_least_squares_lm_loop": {
            "run_s": med["scipy"],
            "per_fit_ms": 1e3 * med["scipy"] / count,
            "nfev": percentiles(sp_nfev),
            "stable_fraction": float(np.mean(sp_stable)),
        },
        "scipy_least_squares_lm_loop_x_scale_jac": {
            "run_s": med["scipy_jac"],
            "per_fit_ms": 1e3 * med["scipy_jac"] / count,
            "nfev": percentiles(spj_nfev),
        },
        "speedup_full_fit_vs_scipy_lm": med["scipy"] / med["full"],
        "speedup_lm_only_vs_scipy_lm": med["scipy"] / med["lm"],
        "speedup_full_fit_vs_scipy_lm_x_scale_jac": med["scipy_jac"] / med["full"],
        "speedup_lm_only_vs_scipy_lm_x_scale_jac": med["scipy_jac"] / med["lm"],
        "speedup_full_fit_per_round": [a / b for a, b in zip(times["scipy"], times["full"])],
        "cost_ratio_jaxvs_over_scipy": percentiles(jx_cost / sp_cost),
        "_problems": (omega, h, init, w0, jx_cost, report),
    }


# --- 3. LM vs BFGS vs Adam -----------------------------------------------------------


def optimisers(problems, count: int, bfgs_steps: int, adam_steps: int, repeat: int):
    omega, h, init, w0, lm_cost_all, _ = problems
    nb, _ = ORDER
    om = jnp.asarray(omega)
    h = jnp.asarray(h[:count])
    init = jax.tree_util.tree_map(lambda x: x[:count], init)
    # The target: the residual Levenberg-Marquardt reaches (its stopping rule leaves
    # ≤ 1e-8 relative), plus 1e-6 relative.
    (lm_model, lm_report), _, lm_med, _ = timed(
        lambda: jaxvs.fit_rational(om, h, ORDER, init=init, throw=False), repeat
    )
    target = np.asarray(lm_report.residual_norm) ** 2 / 2 * (1 + 1e-6)
    grid = _sk.make_grid(om / w0, ORDER[1])
    data = (h.real, h.imag, jnp.ones_like(h.real))
    theta0 = jnp.asarray(scaled_theta(init, w0, *ORDER))
    # jaxvs works with ascending powers.
    theta0 = jnp.concatenate([theta0[:, : nb + 1][:, ::-1], theta0[:, nb + 1 :][:, ::-1]], 1)

    def cost(theta, d):
        return _sk.model_cost(theta, d, grid, nb)

    def bfgs_traj(steps):
        solver = optx.BFGS(rtol=1e-14, atol=1e-14)
        fn = lambda y, d: (cost(y, d), None)

        def one(y0, d):
            f_struct = jax.ShapeDtypeStruct((), y0.dtype)
            state = solver.init(fn, y0, d, {}, f_struct, None, frozenset())
            dyn, static = eqx.partition(state, eqx.is_array)

            def body(carry, _):
                y, dyn_ = carry
                y, st, _ = solver.step(fn, y, d, {}, eqx.combine(static, dyn_), frozenset())
                return (y, eqx.partition(st, eqx.is_array)[0]), cost(y, d)

            return jax.lax.scan(body, (y0, dyn), None, length=steps)[1]

        return jax.jit(jax.vmap(one))

    def adam_traj(steps, lr):
        opt = optax.adam(lr)

        def one(y0, d):
            def body(carry, _):
                y, st = carry
                f, g = jax.value_and_grad(cost)(y, d)
                upd, st = opt.update(g, st, y)
                return (optax.apply_updates(y, upd), st), f

            return jax.lax.scan(body, (y0, opt.init(y0)), None, length=steps)[1]

        return jax.jit(jax.vmap(one))

    def steps_to_target(traj):
        hit = np.asarray(traj) <= target[:, None]
        reached = hit.any(axis=1)
        first = np.where(reached, hit.argmax(axis=1) + 1, traj.shape[1])
        return reached, first

    rows = {
        "levenberg_marquardt (jaxvs)": {
            "time_to_target_s": lm_med,
            "steps_median": float(np.median(lm_report.num_steps)),
            "reached_fraction": 1.0,
        }
    }
    def time_to_target(run, reached, first, cap):
        # Batched run: every system takes as many steps as the slowest one that arrives.
        return run * int(np.max(first[reached])) / cap if reached.any() else None

    fn = bfgs_traj(bfgs_steps)
    traj, _, run, _ = timed(lambda: fn(theta0, data), 1)
    reached, first = steps_to_target(traj)
    rows["bfgs (optimistix)"] = {
        "time_to_target_s": time_to_target(run, reached, first, bfgs_steps),
        "time_for_cap_s": run,
        "steps_median": float(np.median(first)),
        "steps_cap": bfgs_steps,
        "reached_fraction": float(np.mean(reached)),
    }
    best = None
    for lr in (1e-3, 1e-4):  # 1e-2 and above diverge on these problems
        fn = adam_traj(adam_steps, lr)
        traj, _, run, _ = timed(lambda: fn(theta0, data), 1)
        reached, first = steps_to_target(traj)
        final_gap = float(np.median(np.asarray(traj)[:, -1] / target - 1))
        row = {
            "learning_rate": lr,
            "time_to_target_s": time_to_target(run, reached, first, adam_steps),
            "time_for_cap_s": run,
            "steps_median": float(np.median(first)),
            "steps_cap": adam_steps,
            "reached_fraction": float(np.mean(reached)),
            "median_cost_excess_at_cap": final_gap,
        }
        if best is None or (row["reached_fraction"], -final_gap) > (
            best["reached_fraction"],
            -best["median_cost_excess_at_cap"],
        ):
            best = row
    rows["adam (optax, best learning rate)"] = best
    return {"systems": count, "target": "LM residual x (1 + 1e-6)", "rows": rows}


# --- report --------------------------------------------------------------------------


def fmt(x, unit=""):
    return "-" if x is None else f"{x:.3g}{unit}"


def speed_table(sp, title: str) -> list[str]:
    jf, lo = sp["jaxvs_full_fit"], sp["jaxvs_lm_only_from_same_init"]
    sc, scj = sp["scipy_least_squares_lm_loop"], sp["scipy_least_squares_lm_loop_x_scale_jac"]
    n = sp["systems"]
    return [
        f"### {title}",
        "",
        "| method | compile + first run | run (median) | per fit | speed-up vs scipy "
        "(default / x_scale='jac') |",
        "|---|---|---|---|---|",
        f"| jaxvs.fit_rational, one vectorised call (SK init + LM) | "
        f"{jf['compile_and_first_run_s']:.2f} s | {jf['run_s_median']:.3f} s | "
        f"{jf['per_fit_ms']:.2f} ms | **{sp['speedup_full_fit_vs_scipy_lm']:.1f}x** / "
        f"{sp['speedup_full_fit_vs_scipy_lm_x_scale_jac']:.1f}x |",
        f"| jaxvs LM only, from the same init as scipy | "
        f"{lo['compile_and_first_run_s']:.2f} s | {lo['run_s_median']:.3f} s | "
        f"{1e3 * lo['run_s_median'] / n:.2f} ms | "
        f"**{sp['speedup_lm_only_vs_scipy_lm']:.1f}x** / "
        f"{sp['speedup_lm_only_vs_scipy_lm_x_scale_jac']:.1f}x |",
        f"| loop of scipy least_squares(method='lm'), analytic Jacobian (LM only) | - | "
        f"{sc['run_s']:.3f} s | {sc['per_fit_ms']:.2f} ms | 1x |",
        f"| same, x_scale='jac' (MINPACK column scaling) | - | "
        f"{scj['run_s']:.3f} s | {scj['per_fit_ms']:.2f} ms | - |",
        "",
        f"Medians over {sp['rounds']} alternating rounds; full-fit speed-up per round: "
        + ", ".join(f"{x:.1f}x" for x in sp["speedup_full_fit_per_round"])
        + ".",
        "",
    ]


def markdown(res) -> str:
    s, sp, op = res["success"], res["speed"], res["optimisers"]
    m = res["machine"]
    lines = [
        "# Rational TMF fit benchmark (`benchmarks/calibrate.py`)",
        "",
        f"Machine: {m['cpus']} CPU cores (shared with other work), {m['platform']}; load "
        f"average {m['load_start']} at start, {m['load_end']} at the end. Absolute timings "
        "are noisy; compare the numbers of one run only. Unless stated otherwise the run is "
        f"pinned to one core ({m['cores_used']}): scipy's loop is single-threaded, so both "
        "peers get the same resources.",
        "",
        f"Problems: order {ORDER[0]}/{ORDER[1]} TMF-like systems (three modes, 5-500 Hz, "
        f"ζ 0.005-0.05, modal constants and feedthrough N(0, 1)), {N_FREQ} log-spaced "
        f"points over {BAND[0]}-{BAND[1]:.0f} Hz, complex noise of 1 % of |H|, no initial "
        "guess.",
        "",
        "## Success rate (fit within 1 % relative L2 error of the noiseless response)",
        "",
        "| weighting | systems | success | median error | p99 error | max error | codes |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in s.items():
        e = r["rel_error"]
        lines.append(
            f"| {name} | {r['systems']} | {100 * r['success_rate']:.1f} % | "
            f"{100 * e['median']:.3f} % | {100 * e['p99']:.3f} % | {100 * e['max']:.3f} % | "
            f"{r['result_codes']} |"
        )
    jf = sp["jaxvs_full_fit"]
    sc, scj = sp["scipy_least_squares_lm_loop"], sp["scipy_least_squares_lm_loop_x_scale_jac"]
    lines += ["", f"## Speed: {sp['systems']} fits", ""]
    lines += speed_table(sp, f"Cores used: {m['cores_used']}")
    if "speed_all_cores" in res:
        lines += speed_table(res["speed_all_cores"], "All cores (same comparison, unpinned)")
    lines += [
        f"jaxvs success rate on these {sp['systems']}: {100 * jf['success_rate']:.1f} % "
        f"(codes {jf['result_codes']}); LM steps median {jf['lm_steps']['median']:.0f} "
        f"(max {jf['lm_steps']['max']:.0f}), SK iterations median "
        f"{jf['sk_steps']['median']:.0f} (max {jf['sk_steps']['max']:.0f}); scipy function "
        f"evaluations median {sc['nfev']['median']:.0f} (x_scale='jac': "
        f"{scj['nfev']['median']:.0f}). Final cost jaxvs / scipy: median "
        f"{sp['cost_ratio_jaxvs_over_scipy']['median']:.6f}, max "
        f"{sp['cost_ratio_jaxvs_over_scipy']['max']:.4f} (scipy is unconstrained; "
        f"{100 * sc['stable_fraction']:.1f} % of its fits are stable, all of jaxvs's are).",
        "",
        f"## Optimisers from the same initialisation ({op['systems']} systems, vectorised)",
        "",
        f"Target: {op['target']} for every system.",
        "",
        "| optimiser | time to target (systems that reach it) | steps (median) | reached |",
        "|---|---|---|---|",
    ]
    for name, r in op["rows"].items():
        extra = ""
        if "steps_cap" in r:
            extra = f" (cap {r['steps_cap']} steps: {fmt(r['time_for_cap_s'], ' s')})"
        if "learning_rate" in r:
            name = f"{name}, lr={r['learning_rate']:g}"
        lines.append(
            f"| {name} | {fmt(r['time_to_target_s'], ' s')} | {r['steps_median']:.0f} | "
            f"{100 * r['reached_fraction']:.0f} %{extra} |"
        )
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small smoke run")
    parser.add_argument("--no-pin", action="store_true", help="use all cores")
    parser.add_argument("--speed-only", metavar="JSON", help="only the speed part, to JSON")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    q = args.quick
    speed_args = dict(seed=1, count=32 if q else 256, repeat=2 if q else 5, rounds=1 if q else 3)
    if args.speed_only:
        sp = speed(**speed_args)
        sp.pop("_problems")
        Path(args.speed_only).write_text(json.dumps(sp))
        return
    load_start = os.getloadavg()
    res = {
        "machine": {
            "cpus": os.cpu_count(),
            "cores_used": "all" if args.no_pin else "one, pinned",
            "platform": platform.platform(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "scipy": scipy.__version__,
            "load_start": [round(x, 2) for x in load_start],
        },
        "success": success(seed=0, count=20 if q else 100),
    }
    sp = speed(**speed_args)
    problems = sp.pop("_problems")
    res["speed"] = sp
    res["optimisers"] = optimisers(
        problems,
        count=8 if q else 32,
        bfgs_steps=200 if q else 2000,
        adam_steps=500 if q else 5000,
        repeat=2 if q else 5,
    )
    if not args.no_pin:
        with tempfile.TemporaryDirectory() as tmp:
            out_json = Path(tmp) / "speed.json"
            cmd = [sys.executable, __file__, "--no-pin", "--speed-only", str(out_json)]
            subprocess.run(cmd + (["--quick"] if q else []), check=True)
            res["speed_all_cores"] = json.loads(out_json.read_text())
    res["machine"]["load_end"] = [round(x, 2) for x in os.getloadavg()]
    md = markdown(res)
    print(md)
    if not q:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "calibrate.json").write_text(json.dumps(res, indent=2) + "\n")
        (out / "calibrate.md").write_text(md)


if __name__ == "__main__":
    main()
