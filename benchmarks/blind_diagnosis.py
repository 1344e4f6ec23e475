"""Blind benchmark of the sim-to-real gap diagnosis on withheld effects (issue 7).

A generator draws, for each case, a family, a hidden effect or none (at least 20 % none),
its magnitude, the noise and a perturbation of the nominal parameters, and produces
calibration and validation data from the twins, whose effects are built differently from
the diagnosis's augmentations (LuGre friction against Coulomb/Stribeck laws, a contact
spring with clearance against a play operator, a tool oscillator against an added mode, a
thermal network with capacities against a first-order lag, ...). `jaxvs.diagnose` sees
only the records. Reported: the confusion matrix, top-1 accuracy (the primary effect of
the verdict -- the most specific accepted effect of the first chain, e.g. Stribeck after
Coulomb -- equals the hidden label, or "none" when the verdict is empty), the false
positive rate on effect-free cases, the shrink of the validation gap, and the time per case.

    python benchmarks/blind_diagnosis.py [--cases 40] [--families drive,tmf,thermal] [--seed 0]

Writes benchmarks/results/blind_diagnosis.json and .md.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs import twins  # noqa: E402
from jaxvs.diagnosis import FAMILIES  # noqa: E402

RESULTS = pathlib.Path(__file__).parent / "results"
N_SAMPLES = 25_000  # per case, calibration + validation
P_NONE = 0.25


def drive_case(key, label):
    k1, k2, k3, k4, k5 = jr.split(key, 5)
    effects = twins.draw_drive_effect(k1, label) if label else {}
    twin = twins.DriveTwin(effects=effects).perturb(k2, 0.1)
    noise = float(jr.uniform(k5, minval=0.5, maxval=2.0))
    cal = twin.experiment(k3, duration=17.5, noise_u=noise)
    val = twin.experiment(k4, duration=7.5, noise_u=noise)
    return [cal], [val], {"noise_u": noise, "effects": _plain(effects)}


def thermal_case(key, label):
    k1, k2, k3, k4, k5 = jr.split(key, 5)
    effects = twins.draw_thermal_effect(k1, label) if label else {}
    twin = twins.SpindleThermalTwin(effects=effects).perturb(k2, 0.1)
    noise = float(jr.uniform(k5, minval=0.05, maxval=0.2))
    cal = twin.experiment(k3, duration=0.7 * N_SAMPLES * 5.0, noise=noise)
    val = twin.experiment(k4, duration=0.3 * N_SAMPLES * 5.0, noise=noise)
    return [cal], [val], {"noise": noise, "effects": _plain(effects)}


def tmf_case(key, label):
    k1, k2, k3, k4 = jr.split(key, 4)
    effects = twins.draw_tmf_effect(k1, label) if label else {}
    twin = twins.MachineStructureTwin(effects=effects).perturb(k2, 0.1)
    n_cal, n_val = 3, 2
    d_cal = 0.7 * N_SAMPLES * 1e-3 / n_cal
    d_val = 0.3 * N_SAMPLES * 1e-3 / n_val
    cal = twin.tmf_experiment(k3, ys=(0.1, 0.3, 0.5), duration=d_cal, dt=1e-3)
    val = twin.tmf_experiment(k4, ys=(0.2, 0.45), duration=d_val, dt=1e-3)
    return list(cal), list(val), {"effects": _plain(effects)}


GENERATORS = {
    "drive": (drive_case, lambda: twins.DRIVE_EFFECT_LABELS),
    "thermal": (thermal_case, lambda: twins.THERMAL_TWIN_EFFECTS),
    "tmf": (tmf_case, lambda: twins.TMF_TWIN_EFFECTS),
}


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    try:
        return float(x)
    except (TypeError, ValueError):
        return str(x)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=40)
    p.add_argument("--families", default=",".join(f for f in GENERATORS if f in FAMILIES))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(RESULTS))
    args = p.parse_args(argv)
    families = [f for f in args.families.split(",") if f]
    for f in families:
        if f not in FAMILIES or f not in GENERATORS:
            raise SystemExit(f"unknown or unregistered family {f!r}")

    # stratified draw: per family, every effect label in turn with effect-free cases mixed
    # in (at least P_NONE of the cases), in a seeded random order
    rng = np.random.default_rng(args.seed)
    key = jr.PRNGKey(args.seed)
    per_family = {
        f: args.cases // len(families) + (i < args.cases % len(families))
        for i, f in enumerate(families)
    }
    cases = []
    for fam in families:
        labels = list(GENERATORS[fam][1]())
        n_none = max(1, int(np.ceil(P_NONE * per_family[fam])))
        cycle = [labels[i % len(labels)] for i in range(per_family[fam] - n_none)]
        draw = [None] * n_none + cycle
        rng.shuffle(draw)
        cases += [(fam, label) for label in draw]
    order = rng.permutation(len(cases))
    cases = [(*cases[i], jr.fold_in(key, int(i))) for i in order]

    rows = []
    for i, (fam, label, k) in enumerate(cases):
        t0 = time.perf_counter()
        cal, val, info = GENERATORS[fam][0](k, label)
        t_gen = time.perf_counter() - t0
        t0 = time.perf_counter()
        rep = jaxvs.diagnose(cal, val, family=fam, seed=i)
        t_diag = time.perf_counter() - t0
        v = rep.verdict
        found = v["primary"] or "none"
        truth = label or "none"
        n = (
            sum(r.n_samples for r in cal + val)
            if hasattr(cal[0], "n_samples")
            else sum(len(r.t) for r in cal + val)
        )
        rows.append(
            {
                "case": i,
                "family": fam,
                "hidden": truth,
                "found": found,
                "effects": v["effects"],
                "correct": found == truth,
                "gap_validation": rep.gap["validation"],
                "noise_floor": rep.gap["noise_floor"],
                "gap_after": v["validation_gap"],
                "shrink": v["shrink"],
                "samples": int(n),
                "seconds": t_diag,
                "generate_seconds": t_gen,
                "info": info,
            }
        )
        print(
            f"case {i:3d} {fam:8s} hidden={truth:22s} found={found:22s} "
            f"{'ok ' if found == truth else 'MISS'} shrink={v['shrink']:.2f} "
            f"gap {rep.gap['validation']:.4f}->{v['validation_gap']:.4f} "
            f"(noise {rep.gap['noise_floor']:.4f}) {t_diag:.1f}s",
            flush=True,
        )

        _write(rows, args, families)  # after every case: a long run can be read as it goes
    print(_write(rows, args, families))
    return 0


def _write(rows, args, families) -> str:
    summary = _summarise(rows)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {
        "machine": platform.platform(),
        "cpu_count": os.cpu_count(),
        "jax": jax.__version__,
        "python": sys.version.split()[0],
        "load_average": os.getloadavg(),
        "cases_planned": args.cases,
        "seed": args.seed,
        "families": families,
    }
    (out / "blind_diagnosis.json").write_text(
        json.dumps({"meta": meta, "summary": summary, "cases": rows}, indent=2) + "\n"
    )
    md = _markdown(summary, meta)
    (out / "blind_diagnosis.md").write_text(md)
    return md


def _summarise(rows):
    labels = sorted({r["hidden"] for r in rows} | {r["found"] for r in rows})
    conf = {h: {f: 0 for f in labels} for h in labels}
    for r in rows:
        conf[r["hidden"]][r["found"]] += 1
    none = [r for r in rows if r["hidden"] == "none"]
    eff = [r for r in rows if r["hidden"] != "none"]
    shr = [r["shrink"] for r in eff]
    shr_ok = [r["shrink"] for r in eff if r["correct"]]
    per_family = {}
    for fam in sorted({r["family"] for r in rows}):
        rs = [r for r in rows if r["family"] == fam]
        per_family[fam] = {
            "cases": len(rs),
            "top1": float(np.mean([r["correct"] for r in rs])),
            "false_positive": float(
                np.mean([r["found"] != "none" for r in rs if r["hidden"] == "none"])
            )
            if any(r["hidden"] == "none" for r in rs)
            else None,
            "median_seconds": float(np.median([r["seconds"] for r in rs])),
        }
    return {
        "cases": len(rows),
        "top1_accuracy": float(np.mean([r["correct"] for r in rows])),
        "false_positive_rate": float(np.mean([r["found"] != "none" for r in none]))
        if none
        else None,
        "effect_free_cases": len(none),
        "median_shrink_effect_cases": float(np.median(shr)) if shr else None,
        "median_shrink_correct_cases": float(np.median(shr_ok)) if shr_ok else None,
        "median_seconds": float(np.median([r["seconds"] for r in rows])),
        "max_seconds": float(np.max([r["seconds"] for r in rows])),
        "median_samples": float(np.median([r["samples"] for r in rows])),
        "labels": labels,
        "confusion": conf,
        "per_family": per_family,
    }


def _fmt(x) -> str:
    return "—" if x is None else f"{x:.2f}"


def _markdown(s, meta):
    fpr = s["false_positive_rate"]
    fp = "—" if fpr is None else f"{100 * fpr:.1f} %"
    lines = [
        "# Blind diagnosis benchmark",
        "",
        f"{s['cases']} of {meta['cases_planned']} planned cases ({s['effect_free_cases']} effect-free), "
        f"{s['median_samples']:.0f} samples per case, {meta['cpu_count']} CPU cores "
        f"(load average at the end {meta['load_average'][0]:.1f}), jax {meta['jax']}.",
        "",
        "| metric | measured | target |",
        "|---|---|---|",
        f"| top-1 accuracy | {100 * s['top1_accuracy']:.1f} % | ≥ 90 % |",
        f"| false positives on effect-free cases | {fp} | ≤ 5 % |",
        f"| median shrink (cases with an effect) | {_fmt(s['median_shrink_effect_cases'])} | ≥ 0.8 |",
        f"| median shrink (correctly named) | {_fmt(s['median_shrink_correct_cases'])} | |",
        f"| time per case (median / max) | {s['median_seconds']:.1f} s / {s['max_seconds']:.1f} s | ≤ 60 s |",
        "",
        "Per family:",
        "",
        "| family | cases | top-1 | false positives | median time |",
        "|---|---|---|---|---|",
    ]
    for fam, d in s["per_family"].items():
        fp = "—" if d["false_positive"] is None else f"{100 * d['false_positive']:.0f} %"
        lines.append(
            f"| {fam} | {d['cases']} | {100 * d['top1']:.0f} % | {fp} | {d['median_seconds']:.1f} s |"
        )
    labels = s["labels"]
    lines += ["", "Confusion matrix (rows: hidden, columns: found):", ""]
    lines.append("| hidden \\ found | " + " | ".join(labels) + " |")
    lines.append("|---" * (len(labels) + 1) + "|")
    for h in labels:
        lines.append(f"| {h} | " + " | ".join(str(s["confusion"][h][f]) for f in labels) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
