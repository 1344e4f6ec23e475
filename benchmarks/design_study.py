"""The virtual-sensor design assistant on the spindle twin and on real data.

1. **Recovery** on a `SpindleThermalTwin` with inner-ring dynamics and Palmgren-like
   friction heat (the thermal study's twin): records with the true inputs (`T_chassis`,
   `v_m`) and five distractors -- `T_near` (correlated with `T_chassis`, not causal), a
   slow `drift`, white `noise` and coloured `hum` channels, and `v_cmd`, the commanded
   speed leading `v_m` by 3 samples (it matters only through a delay). Targets: the top
   design uses the true inputs and no distractor, is dynamic, and its held-out RMSE is
   within 10 % of the true-structure model (a first-order lag of `T_chassis` and
   `v_m^α`, fitted alone by scipy).
2. **Speed**: the same search counts the candidate designs (target >= 256 in <= 5 min on
   2 cores), and every group is trained again one candidate after another with the same
   compiled trainer, in the same process on the same data (target: the vectorised search
   >= 10x faster; compile times apart).
3. **Table 4** of the study as a design ranking: the target measured every ~90 s
   (resampled per segment), inputs `T_chassis, v_m`, structures regression / static
   network / TDNN (15 hidden): the best design of each must order TDNN < static <
   regression by held-out RMSE.
4. **EMPS** (real drive): the motor force from motion signals (position, velocity,
   acceleration, reference), estimation set for calibration and the pulses set held out.
5. **Measured FRFs** (pyuff): the order of a rational model as the design choice, chosen
   by held-out error on alternating contiguous 8 Hz frequency bands.

Run: `python benchmarks/design_study.py [--quick]`; writes
`benchmarks/results/design_study.json` and `.md`.
"""

import argparse
import json
import os
import platform
import time
import warnings
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402
import scipy.optimize as so  # noqa: E402
import scipy.signal as ss  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.twins import SpindleThermalTwin  # noqa: E402

ROOT = Path(__file__).resolve().parent
DATA = ROOT.parent.parent / "shared" / "data"
TWIN_EFFECTS = {"dynamics": 240.0, "speed_nonlinearity": 1.6}
# recovery: the ambient air also drifts (unmeasured): the chassis temperature carries it
RECOVERY_EFFECTS = {**TWIN_EFFECTS, "ambient_temperature": 3.0}
DISTRACTORS = ("T_near", "drift", "noise", "hum", "v_cmd")


def spindle_records(hours: float, dt: float, seed: int = 0) -> dict:
    twin = SpindleThermalTwin(RECOVERY_EFFECTS)
    rec = twin.experiment(jr.key(seed), duration=hours * 3600.0, dt=dt)
    rng = np.random.default_rng(seed)
    n = len(rec)
    tc = np.asarray(rec["T_chassis"])
    v = np.asarray(rec["v_m"])
    hum = ss.lfilter([1.0], [1, -0.95], rng.normal(size=n))
    return {
        "t": np.asarray(rec.t),
        "T_chassis": tc,
        "v_m": v,
        "T_bearing": np.asarray(rec["T_bearing"]),
        "T_near": 0.8 * tc + 4.0 + np.cumsum(rng.normal(0, 0.05, n)) + 0.2 * rng.normal(size=n),
        "drift": 20.0 + 3.0 * np.sin(2 * np.pi * np.arange(n) * dt / (hours * 3600.0 * 0.8)),
        "noise": rng.normal(size=n),
        "hum": hum,
        "v_cmd": np.concatenate([v[3:], np.repeat(v[-1], 3)]),  # leads v_m by 3 samples
    }


def true_structure(rec: dict, role: np.ndarray, dt: float) -> dict:
    """The twin's own structure fitted alone: `τ ẏ + y = c0 + c1 T_chassis + c2 (v/5000)^α`
    (ZOH discretised, equilibrium start), least squares by scipy on the calibration
    samples, scored on the held-out ones."""
    T, V = (role == 0) | (role == 1), role == 2
    u1, u2, y = rec["T_chassis"], rec["v_m"] / 5000.0, rec["T_bearing"]

    def sim(p):
        tau, alpha, c0, c1, c2 = p
        a = np.exp(-dt / max(tau, 1e-3))
        x = c0 + c1 * u1 + c2 * np.abs(u2) ** alpha
        return ss.lfilter([1 - a], [1, -a], x, zi=[a * x[0]])[0]

    fit = so.least_squares(lambda p: (sim(p) - y)[T], [300.0, 1.3, 20.0, 0.3, 15.0])
    pred = sim(fit.x)
    return {
        "params": dict(zip(["tau_s", "alpha", "c0", "c1", "c2"], map(float, fit.x))),
        "validation_rmse": float(np.sqrt(np.mean((pred - y)[V] ** 2))),
    }


def recovery_and_speed(quick: bool, hidden: tuple[int, ...] = (3, 6)) -> dict:
    hours, dt = (12.0, 60.0) if quick else (24.0, 60.0)
    rec = spindle_records(hours, dt)
    # default hidden sizes 3 and 6: 330 candidate designs, enough for the >= 256 target
    # (`--hidden 3,6,10,15` adds the study's sizes: 420 designs, longer loop reference)
    kw = dict(hidden=hidden, inits=2 if quick else 3)
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    rep = jaxvs.design(rec, target="T_bearing", progress=False, **kw)
    wall = time.perf_counter() - t0
    load1 = os.getloadavg()
    best = rep.best
    # the same search, with every group also trained one candidate after another
    t1 = time.perf_counter()
    rep_loop = jaxvs.design(rec, target="T_bearing", progress=False, compare_loop=True, **kw)
    wall_loop = time.perf_counter() - t1
    groups = rep_loop["timing"]["groups"]
    # the second search finds its programs compiled already: compile times of the first
    first = {g["group"]: g for g in rep["timing"]["groups"]}
    for g in groups:
        g["compile_s"] = max(g["compile_s"], first[g["group"]]["compile_s"])
    batch_run = sum(g["run_s"] for g in groups)
    loop_run = sum(g["loop_run_s"] for g in groups)
    net = [g for g in groups if g["group"].startswith("network")]
    truth = true_structure(rec, rep.arrays["role"], dt)
    inputs_ok = set(best["inputs"]) == {"T_chassis", "v_m"}
    return {
        "hours": hours,
        "dt_s": dt,
        "samples": len(rec["t"]),
        "hidden": list(kw["hidden"]),
        "inits": kw["inits"],
        "distractors": list(DISTRACTORS),
        "candidates_evaluated": rep["candidates_evaluated"],
        "wall_s": wall,
        "load_before_after": [load0[0], load1[0]],
        "best": best,
        "selected": rep["forward_selection"]["selected"],
        "pool": rep["forward_selection"]["pool"],
        "input_ranking": rep["input_ranking"],
        "best_rank_by_structure": rep["best_rank_by_structure"],
        "top5": [
            {k: d[k] for k in ("rank", "structure", "inputs", "delays", "hidden", "parameters")}
            | {"rmse": d["validation"]["rmse"]}
            for d in rep.designs[:5]
        ],
        "true_structure": truth,
        "checks": {
            "true_inputs_no_distractor": inputs_ok,
            "dynamic": best["structure"] in ("lag", "arx", "tdnn"),
            "rmse_ratio_to_true_structure": best["validation"]["rmse"] / truth["validation_rmse"],
        },
        "speed": {
            "groups": groups,
            "batched_run_s": batch_run,
            "loop_run_s": loop_run,
            "speedup_all": loop_run / batch_run,
            "speedup_networks": sum(g["loop_run_s"] for g in net) / sum(g["run_s"] for g in net),
            "batched_compile_s": sum(g["compile_s"] for g in groups),
            "loop_compile_s": sum(g["loop_compile_s"] for g in groups),
            "wall_with_loop_s": wall_loop,
            "load": os.getloadavg()[0],
        },
        "warnings": rep["warnings"],
    }


def table4(quick: bool) -> dict:
    """The study's comparison as a design ranking, from a target measured every ~90 s."""
    hours, dt = (12.0, 30.0) if quick else (35.0, 5.0)
    twin = SpindleThermalTwin(TWIN_EFFECTS)
    rec = twin.experiment(jr.key(7), duration=hours * 3600.0, dt=dt)
    sparse = twin.sparse_target(rec, jr.key(8), every=90.0)
    y = np.full(len(rec), np.nan)
    y[np.round((sparse.t - rec.t[0]) / dt).astype(int)] = sparse.T_bearing
    data = {
        "t": np.asarray(rec.t),
        "T_chassis": np.asarray(rec["T_chassis"]),
        "v_m": np.asarray(rec["v_m"]),
        "T_bearing": y,
    }
    t0 = time.perf_counter()
    rep = jaxvs.design(
        data,
        target="T_bearing",
        inputs=["T_chassis", "v_m"],
        structures=("regression", "mlp", "tdnn"),
        hidden=(15,),
        inits=3,
        progress=False,
    )
    best = {}
    for d in rep.designs:
        name = {"regression": "regression", "mlp": "static network", "tdnn": "TDNN"}[d["structure"]]
        if d.get("quadratic"):  # beyond the study's linear regression (eq. 2-3)
            name = "regression with squares"
        best.setdefault(name, d)
    study = ("regression", "static network", "TDNN")
    order = sorted(study, key=lambda k: best[k]["validation"]["rmse"])
    return {
        "hours": hours,
        "dt_s": dt,
        "sparse_target": rep["data"]["sparse_target"],
        "seconds": time.perf_counter() - t0,
        "best_by_structure": {
            k: {
                "rank": d["rank"],
                "inputs": d["inputs"],
                "delays": d["delays"],
                "validation": d["validation"],
                "calibration": d["calibration"],
                "parameters": d["parameters"],
            }
            for k, d in best.items()
        },
        "order_by_rmse": order,
        "ordering_met": order == ["TDNN", "static network", "regression"],
        "warnings": rep["warnings"],
    }


def emps(quick: bool) -> dict:
    """EMPS: force from motion signals; estimation set to calibrate, pulses set held out."""

    def motion(path: Path) -> dict:
        rec = jaxvs.data.load_emps(path)
        q, r, u = (np.asarray(rec[k]) for k in ("q", "r", "u"))
        fs = 1.0 / rec.dt
        b, a = ss.butter(4, 20.0 / (fs / 2))
        qf = ss.filtfilt(b, a, q)
        qd = np.gradient(qf, rec.dt)
        qdd = np.gradient(qd, rec.dt)
        k = 10  # 1 kHz -> 100 Hz after the 20 Hz low-pass
        return {
            "t": np.asarray(rec.t)[::k],
            "q": qf[::k],
            "qd": qd[::k],
            "qdd": qdd[::k],
            "r": r[::k],
            "u": ss.filtfilt(b, a, u)[::k],
        }

    est = motion(DATA / "EMPS" / "DATA_EMPS.mat")
    val = motion(DATA / "EMPS" / "DATA_EMPS_PULSES.mat")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = jaxvs.design(
            est,
            target="u",
            validation=[val],
            progress=False,
            hidden=(3, 6) if quick else (3, 6, 10),
            inits=2 if quick else 3,
        )
    best = {}
    for d in rep.designs:
        best.setdefault(d["structure"], d)
    y = val["u"]
    return {
        "seconds": time.perf_counter() - t0,
        "candidates_evaluated": rep["candidates_evaluated"],
        "best": rep.best,
        "selected": rep["forward_selection"]["selected"],
        "best_by_structure": {
            k: {
                "rank": d["rank"],
                "inputs": d["inputs"],
                "rmse": d["validation"]["rmse"],
                "relative_error_pct": 100 * d["validation"]["rmse"] / float(np.sqrt(np.mean(y**2))),
                "parameters": d["parameters"],
                "hidden": d["hidden"],
                "delays": d["delays"],
            }
            for k, d in best.items()
        },
        "warnings": rep["warnings"],
    }


def frf_orders() -> dict:
    """Rational order as the design choice on measured FRFs: fit on alternate 8 Hz bands,
    score on the bands in between (held out, contiguous), for H_11 (accelerance) and the
    TMF T_21 = H_21 / H_11."""
    files = [DATA / "pyuff_frf" / f"meas_point_{k}.txt" for k in (1, 2, 3)]
    H = np.stack([np.loadtxt(p, dtype=complex) for p in files], axis=1)
    f = np.arange(H.shape[0], dtype=float)
    out = {}
    cases = {
        "H_11 (accelerance)": (H[:, 0], (f >= 10) & (f <= 1000), True, (4, 6, 8, 10, 12, 14, 16)),
        "T_21 (TMF)": (H[:, 1] / H[:, 0], (f >= 20) & (f <= 880), False, (2, 4, 6, 8, 10)),
    }
    for name, (h, band, stable, orders) in cases.items():
        fb, hb = f[band], h[band]
        held = ((fb // 8).astype(int) % 2) == 1
        rows = []
        for n in orders:
            w = np.where(held, 0.0, 1.0)
            t0 = time.perf_counter()
            try:
                model, fit = jaxvs.fit_rational(
                    2 * np.pi * fb, hb, (n, n), weights=w, stable=stable, throw=False
                )
                g = np.asarray(jaxvs.frequency_response(model, jnp.asarray(2 * np.pi * fb)))
                err = lambda m: float(np.linalg.norm((g - hb)[m]) / np.linalg.norm(hb[m]))  # noqa: E731
                rows.append(
                    {
                        "order": n,
                        "calibration_error": err(~held),
                        "heldout_error": err(held),
                        "seconds": time.perf_counter() - t0,
                    }
                )
            except Exception as e:  # a failed order is reported, not hidden
                rows.append({"order": n, "error": f"{type(e).__name__}: {e}"[:200]})
        ok = [r for r in rows if "heldout_error" in r and np.isfinite(r["heldout_error"])]
        best = min(ok, key=lambda r: r["heldout_error"])
        # the simplest order within 10 % of the best held-out error (parsimony)
        pick = min(
            (r for r in ok if r["heldout_error"] <= 1.1 * best["heldout_error"]),
            key=lambda r: r["order"],
        )
        out[name] = {"rows": rows, "lowest_heldout": best["order"], "suggested": pick["order"]}
    return out


def markdown(res: dict) -> str:
    r = res["recovery"]
    s = r["speed"]
    b = r["best"]
    L = ["# Virtual-sensor design assistant", ""]
    L += [
        "## Recovery on the spindle twin",
        "",
        f"Twin effects {RECOVERY_EFFECTS} (air temperature unmeasured); "
        f"{r['hours']:.0f} h of random speed parts at "
        f"{r['dt_s']:.0f} s ({r['samples']} samples); candidate inputs T_chassis, v_m and the "
        f"distractors {', '.join(r['distractors'])}; last 30 % held out as one block; "
        f"networks with {', '.join(map(str, r.get('hidden', [])))} hidden units, "
        f"{r.get('inits', '?')} initialisations each. "
        f"{r['candidates_evaluated']} candidate designs in {r['wall_s']:.0f} s (load average "
        f"{r['load_before_after'][0]:.1f} -> {r['load_before_after'][1]:.1f} on 2 cores shared "
        "with other jobs).",
        "",
        f"Forward selection chose **{', '.join(r['selected'])}** (pool {', '.join(r['pool'])}).",
        "",
        "| rank | structure | inputs | delays | hidden | params | held-out RMSE [K] |",
        "|---:|---|---|---|---:|---:|---:|",
    ]
    for d in r["top5"]:
        L.append(
            f"| {d['rank']} | {d['structure']} | {', '.join(d['inputs'])} | "
            f"{d['delays']} | {d['hidden'] or '–'} | {d['parameters']} | {d['rmse']:.4f} |"
        )
    c = r["checks"]
    t = r["true_structure"]
    L += [
        "",
        f"True-structure model fitted alone (scipy, lag of T_chassis and v_m^α): held-out "
        f"RMSE {t['validation_rmse']:.4f} K (τ = {t['params']['tau_s']:.0f} s, α = "
        f"{t['params']['alpha']:.2f}; twin: 240 s, 1.6).",
        "",
        "| check | result | target | met |",
        "|---|---|---|---|",
        f"| top design's inputs | {', '.join(b['inputs'])} | T_chassis, v_m, no distractor | "
        f"{'yes' if c['true_inputs_no_distractor'] else 'no'} |",
        f"| top design's structure | {b['structure']} | dynamic (lag, ARX or TDNN) | "
        f"{'yes' if c['dynamic'] else 'no'} |",
        f"| held-out RMSE / true structure | {c['rmse_ratio_to_true_structure']:.3f} | <= 1.10 | "
        f"{'yes' if c['rmse_ratio_to_true_structure'] <= 1.1 else 'no'} |",
        "",
        "## Speed: one vectorised search against a loop of the same trainings",
        "",
        "Same process, same data, same compiled trainer per group (the loop runs one candidate "
        "-- networks: one initialisation -- at a time); run times exclude compilation. "
        f"Load average {s['load']:.1f}.",
        "",
        "| group | candidates | trainings | batched [s] | loop [s] | speed-up | "
        "compile batched / loop [s] |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for g in s["groups"]:
        L.append(
            f"| {g['group']} | {g['candidates']} | {g['members']} | {g['run_s']:.2f} | "
            f"{g['loop_run_s']:.2f} | {g['loop_run_s'] / g['run_s']:.1f}x | "
            f"{g['compile_s']:.1f} / {g['loop_compile_s']:.1f} |"
        )
    L += [
        f"| **all** | {r['candidates_evaluated']} | | {s['batched_run_s']:.2f} | "
        f"{s['loop_run_s']:.2f} | **{s['speedup_all']:.1f}x** | |",
        "",
        f"Networks alone: {s['speedup_networks']:.1f}x. Targets: >= 256 designs in <= 300 s "
        f"({r['candidates_evaluated']} in {r['wall_s']:.0f} s: "
        f"{'met' if r['candidates_evaluated'] >= 256 and r['wall_s'] <= 300 else 'not met'}); "
        f">= 10x the loop ({s['speedup_all']:.1f}x: "
        f"{'met' if s['speedup_all'] >= 10 else 'not met'}).",
        "",
    ]
    t4 = res["table4"]
    L += [
        "## Study Table 4 as a design ranking",
        "",
        f"{t4['hours']:.0f} h at {t4['dt_s']:.0f} s, target measured every ~90 s "
        f"({t4['sparse_target']['measured_samples']} samples, resampled per segment by "
        "first-order laws, scored on the measurements); inputs T_chassis, v_m; 15 hidden.",
        "",
        "| structure (best design) | rank | held-out RMSE [K] | R² | MAPD % | calib. RMSE |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for k in ("regression", "static network", "TDNN", "regression with squares"):
        d = t4["best_by_structure"].get(k)
        if d:
            v = d["validation"]
            L.append(
                f"| {k} | {d['rank']} | {v['rmse']:.3f} | {v['r2']:.4f} | {v['mapd']:.2f} | "
                f"{d['calibration']['rmse']:.3f} |"
            )
    L += [
        "",
        f"Ordering {' < '.join(t4['order_by_rmse'])}: "
        f"**{'met' if t4['ordering_met'] else 'not met'}** (study: TDNN < static < regression; "
        "regression = the study's linear eq. 2-3; the search's regression with input squares "
        "is listed apart).",
        "",
    ]
    e = res["emps"]
    L += [
        "## EMPS: motor force from motion signals (real data)",
        "",
        "Estimation set to calibrate, pulses set held out; 20 Hz low-pass, 100 Hz. "
        f"Forward selection chose {', '.join(e['selected'])}. {e['candidates_evaluated']} "
        f"designs in {e['seconds']:.0f} s.",
        "",
        "| structure (best design) | rank | inputs | held-out RMSE [N] | rel. error % | params |",
        "|---|---:|---|---:|---:|---:|",
    ]
    for k, d in sorted(e["best_by_structure"].items(), key=lambda kv: kv[1]["rank"]):
        L.append(
            f"| {k} | {d['rank']} | {', '.join(d['inputs'])} | {d['rmse']:.2f} | "
            f"{d['relative_error_pct']:.2f} | {d['parameters']} |"
        )
    L += [
        "",
        "## Measured FRFs: rational order by held-out error",
        "",
        "Fitted on alternate 8 Hz bands, scored on the bands in between.",
        "",
    ]
    for name, o in res["frf"].items():
        L += [
            f"**{name}**: lowest held-out error at order {o['lowest_heldout']}, suggested "
            f"(simplest within 10 %) {o['suggested']}.",
            "",
            "| order | calibration error | held-out error | time [s] |",
            "|---:|---:|---:|---:|",
        ]
        for row in o["rows"]:
            if "heldout_error" in row:
                L.append(
                    f"| {row['order']} | {row['calibration_error']:.4f} | "
                    f"{row['heldout_error']:.4f} | {row['seconds']:.1f} |"
                )
            else:
                L.append(f"| {row['order']} | failed: {row['error'][:60]} | | |")
        L.append("")
    L.append(f"Machine: {platform.machine()}, {os.cpu_count()} cpu, jax {jax.__version__}.")
    return "\n".join(L) + "\n"


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    p.add_argument(
        "--sections", default="recovery,table4,emps,frf", help="comma-separated subset to run"
    )
    p.add_argument(
        "--merge", action="store_true", help="only merge the saved sections into json + md"
    )
    p.add_argument("--hidden", default="3,6", help="recovery section: network hidden sizes")
    args = p.parse_args()
    from jaxvs._misc import json_safe

    suffix = "_quick" if args.quick else ""
    out = ROOT / "results"
    out.mkdir(exist_ok=True)
    parts = out / f".design_study{suffix}_parts"
    parts.mkdir(exist_ok=True)
    runs = {
        "recovery": lambda: recovery_and_speed(
            args.quick, tuple(int(h) for h in args.hidden.split(","))
        ),
        "table4": lambda: table4(args.quick),
        "emps": lambda: emps(args.quick),
        "frf": frf_orders,
    }
    if not args.merge:
        for name in args.sections.split(","):
            t0 = time.perf_counter()
            result = runs[name]()
            (parts / f"{name}.json").write_text(json.dumps(json_safe(result), indent=2) + "\n")
            print(
                f"{name}: {time.perf_counter() - t0:.0f} s, load {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    res = {
        n: json.loads((parts / f"{n}.json").read_text())
        for n in runs
        if (parts / f"{n}.json").exists()
    }
    if set(res) != set(runs):
        print("sections saved so far:", sorted(res))
        return
    (out / f"design_study{suffix}.json").write_text(json.dumps(res, indent=2) + "\n")
    md = markdown(res)
    (out / f"design_study{suffix}.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
