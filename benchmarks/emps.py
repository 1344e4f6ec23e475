"""EMPS IDIM-LS: jaxvs beside the published reference (Janot, Gautier, Brunot 2019, §3.4).

Identifies mass and friction of the Electro-Mechanical Positioning System from
`DATA_EMPS.mat` with `jaxvs.idim_ls` (zero-phase Butterworth position filter, central
differences, parallel decimation, ordinary least squares) for both friction models, and
cross-validates on `DATA_EMPS_PULSES.mat` with `predict_force`. Prints the table "ours
beside published" and writes `benchmarks/results/emps.json` and `benchmarks/results/emps.md`.

Run: `python benchmarks/emps.py [--data PATH_TO_EMPS_FOLDER]`.
"""

import argparse
import json
import math
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jaxvs  # noqa: E402
from jaxvs.calibration import predict_force  # noqa: E402
from jaxvs.data import load_emps  # noqa: E402

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = ROOT.parent.parent / "shared" / "data" / "EMPS"

# Description §3.4 and DESIGN.md §4 (MATLAB Script_IDIM_LS / Script_IDIM_LS_CTV output).
PUBLISHED = {
    "coulomb_viscous": {
        "params": {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648},
        "std_errors": {"M": 0.1085, "Fv": 1.1460, "Fc": 0.1012, "offset": 0.0444},
        "relative_error_estimation_pct": 4.0834,
        "relative_error_validation_pct": 5.9824,
        "condition_number": 25.9883,
    },
    "asymmetric": {
        "params": {
            "M": 95.154, "Fv_pos": 166.71, "Fc_pos": 20.144, "Fv_neg": 240.42, "Fc_neg": 20.628
        },
        "std_errors": None,
        "relative_error_estimation_pct": 3.11,
        "relative_error_validation_pct": None,
        "condition_number": None,
    },
}
UNITS = {"M": "kg", "Fv": "N·s/m", "Fc": "N", "offset": "N", "Fv_pos": "N·s/m",
         "Fc_pos": "N", "Fv_neg": "N·s/m", "Fc_neg": "N"}


def run(data: Path) -> dict:
    estimation = load_emps(data / "DATA_EMPS.mat")
    validation = load_emps(data / "DATA_EMPS_PULSES.mat")
    out = {}
    for friction, ref in PUBLISHED.items():
        start = time.perf_counter()
        result = jaxvs.idim_ls(estimation, friction=friction)
        fit_s = time.perf_counter() - start
        ctv = predict_force(result, validation)
        out[friction] = {
            "settings": {
                "cutoff_hz": result.cutoff_hz,
                "filter_order": result.filter_order,
                "decimation": result.decimation,
                # None = the default, ceil(3·fs/cutoff_hz) samples at each end
                "edge_samples": result.edge_samples
                if result.edge_samples is not None
                else math.ceil(3 / (estimation.dt * result.cutoff_hz)),
            },
            "params": {k: float(v) for k, v in result.params.items()},
            "std_errors": {n: float(s) for n, s in zip(result.names, result.std_errors)},
            "relative_error_estimation_pct": 100 * float(result.relative_error),
            "relative_error_validation_pct": 100 * float(ctv.relative_error),
            "condition_number": float(result.condition_number),
            "n_samples": int(result.force.shape[0]),
            "wall_s_including_compile": fit_s,
            "published": ref,
        }
    return out


def _fmt(x, digits=4):
    return "—" if x is None else f"{x:.{digits}f}"


def markdown(results: dict) -> str:
    lines = ["# EMPS IDIM-LS: jaxvs beside the published reference", ""]
    lines.append(
        "Janot, Gautier, Brunot (2019), *Data set and reference models of EMPS*, §3.4. "
        "Estimation on `DATA_EMPS.mat`, cross-test validation on `DATA_EMPS_PULSES.mat`. "
        "Relative error = ‖y − ŷ‖/‖y‖ of the decimated force."
    )
    for friction, r in results.items():
        ref = r["published"]
        s = r["settings"]
        lines += ["", f"## friction = `{friction}`", ""]
        lines.append(
            f"Butterworth order {s['filter_order']} at {s['cutoff_hz']:g} Hz (zero phase), "
            f"decimation {s['decimation']}, {s['edge_samples']} samples dropped at "
            f"each end, N = {r['n_samples']} samples."
        )
        lines += ["", "| quantity | jaxvs | ± std | published | ± std | rel. diff |",
                  "|---|---|---|---|---|---|"]
        for name, ours in r["params"].items():
            pub = ref["params"][name]
            pub_std = ref["std_errors"][name] if ref["std_errors"] else None
            lines.append(
                f"| {name} [{UNITS[name]}] | {ours:.4f} | {r['std_errors'][name]:.4f} | "
                f"{pub:.4f} | {_fmt(pub_std)} | {100 * (ours - pub) / abs(pub):+.2f} % |"
            )
        for key, label in (
            ("relative_error_estimation_pct", "relative error, estimation [%]"),
            ("relative_error_validation_pct", "relative error, validation [%]"),
            ("condition_number", "condition number of Φ"),
        ):
            pub = ref[key]
            diff = "—" if pub is None else f"{r[key] - pub:+.2f}"
            lines.append(f"| {label} | {r[key]:.4f} | | {_fmt(pub)} | | {diff} (abs) |")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    results = run(args.data)
    out = ROOT / "results"
    out.mkdir(exist_ok=True)
    (out / "emps.json").write_text(json.dumps(results, indent=2) + "\n")
    table = markdown(results)
    (out / "emps.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
