"""Three-axis machine study: the 21 geometric errors of a Cartesian machine, their
calibration from simulated ISO tests, the volumetric error before and after compensation,
3-D contouring, and the three drives simulated together against a SciPy loop.

1. **Calibration.** A vertical machining centre (table X on saddle Y, head Z; the drive
   study's machine, Pislaru 2001 §4.3.2) with error curves of the kind measured in its
   Appendix C (see `thesis_errors`), simulated tests with instrument noise, calibration
   of all 21 components and the reversal values from the complete plan (41 tests) and from
   ball-bar + diagonals (16 tests, with a weak prior); recovery table per component;
   identifiability of each plan. Compile and run time reported separately.
2. **Volumetric map** over a 50³ grid in one call, before and after compensation.
3. **Test-plan suggestion** for the ball-bar + diagonals plan.
4. **Contouring**: a helix and a conical frustum path (the 15° cone of ISO 10791-7 /
   NAS 979, by three-axis interpolation) at two feeds: 3-D contour error, drive lag plus
   geometry.
5. **Simulation speed**: the three drives over a 20 s path at 1 kHz (one compiled call)
   against a loop of `scipy.integrate.solve_ivp` (RK45, same tolerances) over the same
   three axes on an independent NumPy right-hand side, in the same process.

Default (`make bench`): Legendre degree 4 (69 coefficients + 3 reversal values), 20 s
path; `--quick`: degree 3 and a 4 s path (about 4 minutes on 2 cores). Writes
`benchmarks/results/machine_study.json` and `.md`. Run:
`python benchmarks/machine_study.py [--quick]`.
"""

import argparse
import json
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.integrate as si  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from jaxvs.models import (  # noqa: E402
    CartesianMachine,
    CoulombViscousFriction,
    CurrentLoop,
    DriveAxis,
    MachineErrors,
    PositionLoop,
    RigidAxis,
    VelocityLoop,
)
from jaxvs.studies.machine import (  # noqa: E402
    ballbar_diagonal_plan,
    calibrate_machine,
    candidate_tests,
    compensated_error,
    complete_plan,
    diagonal_plan,
    identifiability,
    suggest_test,
)

ROOT = Path(__file__).resolve().parent
# travel of the working volume [m] (assumed: the Beaver VC35's Table 5.2 is not in the
# text available to us; a 500 × 400 × 400 mm vertical machining centre)
TRAVEL = ((0.0, 0.5), (0.0, 0.4), (0.0, 0.4))
TOOL = (0.0, 0.0, -0.12)
# drives: moving mass [kg], P position gain kp [1/s], PI velocity loop kv [N/(m/s)], ki
# [1/s], current loop lag [s], Coulomb / viscous friction (assumed, of the size of the
# drive study's two-mass drive, benchmarks/drive_study.py)
DRIVES = {
    "x": (400.0, 30.0, 6e4, 20.0),
    "y": (650.0, 30.0, 9e4, 20.0),
    "z": (300.0, 30.0, 5e4, 20.0),
}
TAU, FC, FV, VSCALE = 1e-3, 40.0, 300.0, 1e-3


def thesis_errors(degree: int) -> MachineErrors:
    """Error curves of the kind of the thesis' Appendix C (Figures C1.1–C1.17): its
    captions name 17 measured curves — positioning of X, Y, Z (C1.1–3), the angular
    errors of X about X, Y, Z (C1.4–6), of Y about Y and X (C1.7–8) and about Z (C1.15),
    of Z about X and Y (C1.16–17), and the six straightness curves (C1.9–14). The curve
    values are not in the text we have, so shapes and sizes here are typical of a
    laser-calibrated vertical machining centre of that class (assumed): positioning
    10–15 µm over the travel with a lead-screw pitch trend, straightness 2–5 µm bows,
    pitch/yaw/roll 10–25 µrad (2–5″); the roll of Z (not among the 17) is 5 µrad, the
    squareness errors (measured by ball bar in §5) 10–20 µrad."""
    tab = {}
    for k, (lo, hi) in enumerate(TRAVEL):
        q = np.linspace(lo, hi, 41)
        u = (q - lo) / (hi - lo)
        a = "XYZ"[k]
        amp = {"X": 12e-6, "Y": 9e-6, "Z": 6e-6}[a]
        tab[f"E{a}{a}"] = (q, amp * (u + 0.3 * np.sin(2 * np.pi * u)))  # trend + screw
        others = [c for c in "XYZ" if c != a]
        tab[f"E{others[0]}{a}"] = (q, 4e-6 * (u - 0.5) ** 2 + 1e-6 * u**3)  # bow
        tab[f"E{others[1]}{a}"] = (q, -2.5e-6 * np.sin(np.pi * u) ** 2)
        for j, rot in enumerate("ABC"):
            size = 5e-6 if (a == "Z" and rot == "C") else (20e-6 - 5e-6 * j)
            tab[f"E{rot}{a}"] = (q, size * (u - 0.5) * (1 + 0.5 * np.cos(np.pi * u * (j + 1))))
    tab.update({"EC0Y": 15e-6, "EB0Z": -10e-6, "EA0Z": 12e-6})
    return MachineErrors.from_tables(TRAVEL, tab, degree=degree)


def _drive(mass, kp, kv, ki):
    return DriveAxis(
        RigidAxis(mass, CoulombViscousFriction(FC, FV, velocity_scale=VSCALE)),
        PositionLoop(kp),
        VelocityLoop(kv, ki),
        CurrentLoop(1.0, TAU),
    )


def machine(errors, reversal=(0.0, 0.0, 0.0)) -> CartesianMachine:
    return CartesianMachine(
        *(_drive(*DRIVES[a]) for a in "xyz"), errors, tool_offset=TOOL, reversal=reversal
    )


def _timed(fn, *a):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*a))
    return out, time.perf_counter() - t0


# ----------------------------------------------------------------------------- 1. calibration
def calibration_study(degree: int) -> dict:
    truth = machine(thesis_errors(degree), reversal=(3e-6, 4e-6, 2e-6))
    nominal = machine(MachineErrors(TRAVEL, degree))
    out = {"degree": degree}
    for name, plan, prior in (
        ("complete", complete_plan(nominal, runs=2), None),
        ("ballbar_diagonals", ballbar_diagonal_plan(nominal), (10e-6, 30e-6)),
    ):
        keys = jax.random.split(jax.random.key(1), len(plan))
        ys = [t.measure(truth, k) for t, k in zip(plan, keys)]
        t0 = time.perf_counter()
        cal = calibrate_machine(nominal, plan, ys, prior=prior)
        wall = time.perf_counter() - t0
        rep = identifiability(nominal, plan)
        out[name] = {
            "n_tests": len(plan),
            "n_readings": int(sum(np.size(y) for y in ys)),
            "n_parameters": len(cal.result.values),
            "rank": rep.content["rank"],
            "not_identified": rep.unidentified_components,
            "compile_s": float(cal.result.stats["compile_time"]),
            "run_s": float(cal.result.stats["run_time"]),
            "wall_s": wall,
            "steps": int(cal.result.num_steps),
            "recovery": cal.recovery(truth),
        }
        if name == "complete":
            estimate = cal.machine
    out["diagonals_rank"] = identifiability(nominal, diagonal_plan(nominal)).content["rank"]
    return out, truth, estimate, nominal


# ----------------------------------------------------------------------------- 2. volumetric map
def volumetric_map(truth, estimate) -> dict:
    g = [jnp.linspace(lo, hi, 50) for lo, hi in TRAVEL]
    X, Y, Z = jnp.meshgrid(*g, indexing="ij")
    _, t_first = _timed(truth.volumetric_error, X, Y, Z)
    E, t_map = _timed(truth.volumetric_error, X, Y, Z)
    q = jnp.stack([X, Y, Z], axis=-1)
    (before, after), _ = _timed(compensated_error, truth, estimate, q)
    nb, na = (np.linalg.norm(np.asarray(v), axis=-1) for v in (before, after))
    return {
        "grid": "50x50x50",
        "first_call_s": t_first,
        "map_s": t_map,
        "before_max_um": 1e6 * float(nb.max()),
        "before_rms_um": 1e6 * float(np.sqrt(np.mean(nb**2))),
        "after_max_um": 1e6 * float(na.max()),
        "after_rms_um": 1e6 * float(np.sqrt(np.mean(na**2))),
    }


# ----------------------------------------------------------------------------- 4. contouring
def helix(feed, dt, radius=0.05, pitch=0.01, turns=1.0):
    c = np.array([0.25, 0.2, 0.15])
    L = turns * np.hypot(2 * np.pi * radius, pitch)
    t = np.arange(0.0, L / feed + 0.5, dt)
    s = np.clip(t - 0.25, 0, None) * feed / L * turns * 2 * np.pi
    s = np.minimum(s, turns * 2 * np.pi)
    return c + np.stack([radius * np.cos(s), radius * np.sin(s), pitch * s / (2 * np.pi)], 1)


def cone_frustum(feed, dt, r_bottom=0.06, height=0.03, half_angle=np.deg2rad(15), turns=3):
    c = np.array([0.25, 0.2, 0.2])
    s_end = turns * 2 * np.pi
    length = s_end * r_bottom
    t = np.arange(0.0, length / feed + 0.5, dt)
    s = np.minimum(np.clip(t - 0.25, 0, None) * feed / r_bottom, s_end)
    z = height * s / s_end
    r = r_bottom - z * np.tan(half_angle)
    return c + np.stack([r * np.cos(s), r * np.sin(s), z], 1)


def _contour_error(actual, path, k=8):
    """Distance of each actual point to the commanded polyline `path`: the nearest of the
    segments that touch its `k` nearest vertices (a KD-tree), each by exact projection."""
    keep = np.r_[True, np.linalg.norm(np.diff(path, axis=0), axis=1) > 0]
    v = path[keep]
    _, idx = cKDTree(v).query(actual, k=k)
    a = v[np.clip(np.concatenate([idx - 1, idx], 1), 0, len(v) - 2)]  # segment starts
    b = v[np.clip(np.concatenate([idx, idx + 1], 1), 1, len(v) - 1)]  # segment ends
    ab = b - a
    s = np.einsum("nkd,nkd->nk", actual[:, None] - a, ab) / np.maximum(
        np.einsum("nkd,nkd->nk", ab, ab), 1e-300
    )
    foot = a + np.clip(s, 0.0, 1.0)[..., None] * ab
    return np.linalg.norm(actual[:, None] - foot, axis=-1).min(axis=1)


def contouring(truth, dt=1e-3) -> list:
    rows = []
    for name, path in (("helix", helix), ("cone frustum", cone_frustum)):
        for feed_mm_min in (1000.0, 4000.0):
            ref = path(feed_mm_min / 60e3, dt)
            sim = truth.simulate(jnp.asarray(ref), dt)
            tool = np.asarray(sim.tool)
            nominal = ref + np.asarray(TOOL)
            geo = np.asarray(truth.volumetric_error(*np.asarray(ref).T))
            e = _contour_error(tool, nominal)
            rows.append(
                {
                    "path": name,
                    "feed_mm_min": feed_mm_min,
                    "samples": len(ref),
                    "contour_max_um": 1e6 * float(e.max()),
                    "contour_rms_um": 1e6 * float(np.sqrt(np.mean(e**2))),
                    "geometric_max_um": 1e6 * float(np.linalg.norm(geo, axis=1).max()),
                }
            )
    return rows


# ----------------------------------------------------------------------------- 5. speed
def _scipy_rhs(t, y, ts, r, mass, kp, kv, ki):
    """Independent NumPy right-hand side of one axis (q, v, f, z)."""
    q, v, f, z = y
    e_v = kp * (np.interp(t, ts, r) - q) - v
    cmd = kv * (e_v + ki * z)
    fr = FC * np.tanh(v / VSCALE) + FV * v
    return [v, (f - fr) / mass, (cmd - f) / TAU, e_v]


def simulation_speed(truth, duration) -> dict:
    dt = 1e-3
    n_turns = duration / 4.0
    s = np.linspace(0, 1, int(duration / dt) + 1)
    ref = np.stack(
        [
            0.25 + 0.1 * np.sin(2 * np.pi * n_turns * s),
            0.2 + 0.1 * np.cos(2 * np.pi * n_turns * s),
            0.2 + 0.05 * np.sin(np.pi * n_turns * s),
        ],
        1,
    )
    ref = ref - ref[0] + np.array([0.25, 0.3, 0.2])  # start at rest on the path
    ref[:, 1] = np.clip(ref[:, 1], 0.0, 0.4)
    r = jnp.asarray(ref)
    t0 = time.perf_counter()
    jax.block_until_ready(truth.simulate(r, dt, check=False).axes)
    t_first = time.perf_counter() - t0
    (axes), t_run = _timed(lambda: truth.simulate(r, dt, check=False).axes)
    ts = dt * np.arange(len(ref))
    t0 = time.perf_counter()
    sp = []
    for k, a in enumerate("xyz"):
        sol = si.solve_ivp(
            _scipy_rhs,
            (ts[0], ts[-1]),
            [ref[0, k], 0, 0, 0],
            method="RK45",
            t_eval=ts,
            rtol=1e-7,
            atol=1e-10,
            args=(ts, ref[:, k], *DRIVES[a]),
        )
        sp.append(sol.y[0])
    t_scipy = time.perf_counter() - t0
    diff = float(np.max(np.abs(np.asarray(axes) - np.stack(sp, 1))))
    return {
        "duration_s": duration,
        "samples": len(ref),
        "jaxvs_first_call_s": t_first,
        "jaxvs_run_s": t_run,
        "scipy_loop_s": t_scipy,
        "speedup": t_scipy / t_run,
        "max_abs_axis_difference_um": 1e6 * diff,
    }


# ----------------------------------------------------------------------------- report
def markdown(res: dict) -> str:
    c = res["calibration"]
    lines = [
        "# Three-axis machine study",
        "",
        f"Load average at start {res['load_average'][0]:.1f}, at the end "
        f"{res['load_average_end'][0]:.1f} ({os.cpu_count()} CPU cores, jax backend "
        f"{jax.default_backend()}, jax {jax.__version__}); "
        f"size: {'full' if res['full'] else 'reduced (--quick)'}.",
        "",
        "## Calibration of the 21 components",
        "",
        "| plan | tests | readings | parameters | rank | LM steps | compile [s] | run [s] |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name in ("complete", "ballbar_diagonals"):
        p = c[name]
        lines.append(
            f"| {name} | {p['n_tests']} | {p['n_readings']} | {p['n_parameters']} | "
            f"{p['rank']} | {p['steps']} | {p['compile_s']:.1f} | {p['run_s']:.2f} |"
        )
    lines += [
        "",
        f"Diagonals only: rank {c['diagonals_rank']} of {c['complete']['n_parameters']}.",
        "",
        "Recovery (RMS over the travel; µm or µrad; ok: error ≤ 10 % of the RMS "
        "magnitude or within the 95 % interval):",
        "",
        "| component | true | complete: error | ±95 % | ok | ball-bar+diag: error | ok |",
        "|---|---:|---:|---:|---|---:|---|",
    ]
    for a, b in zip(c["complete"]["recovery"], c["ballbar_diagonals"]["recovery"]):
        lines.append(
            f"| {a['component']} | {1e6 * a['rms_true']:.2f} | {1e6 * a['rms_error']:.2f} | "
            f"{1e6 * a['rms_halfwidth']:.2f} | {'yes' if a['ok'] else 'no'} | "
            f"{1e6 * b['rms_error']:.2f} | {'yes' if b['ok'] else 'no'} |"
        )
    v = res["volumetric"]
    lines += [
        "",
        "## Volumetric error, 50³ grid",
        "",
        f"One call: {v['map_s']:.3f} s after compilation (first call {v['first_call_s']:.1f} s). "
        f"Before compensation max {v['before_max_um']:.1f} µm, RMS {v['before_rms_um']:.1f} µm; "
        f"after (complete-plan model) max {v['after_max_um']:.2f} µm, "
        f"RMS {v['after_rms_um']:.2f} µm.",
        "",
        "## Suggested next test for the ball-bar + diagonals plan",
        "",
    ]
    for row in res["suggestion"][:4]:
        lines.append(f"- {row['test']}: worst volumetric std {1e6 * row['worst_std']:.2f} µm")
    lines += [
        "",
        "## Contouring (drive lag + geometry)",
        "",
        "| path | feed [mm/min] | contour error max [µm] | RMS [µm] | geometric max [µm] |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in res["contouring"]:
        lines.append(
            f"| {r['path']} | {r['feed_mm_min']:.0f} | {r['contour_max_um']:.1f} | "
            f"{r['contour_rms_um']:.1f} | {r['geometric_max_um']:.1f} |"
        )
    s = res["speed"]
    lines += [
        "",
        f"## Three drives, {s['duration_s']:g} s at 1 kHz",
        "",
        "| | jaxvs (one call) | solve_ivp loop |",
        "|---|---:|---:|",
        f"| run time [s] | {s['jaxvs_run_s']:.2f} | {s['scipy_loop_s']:.2f} |",
        f"| first call (compile) [s] | {s['jaxvs_first_call_s']:.1f} | – |",
        f"| speed-up | **{s['speedup']:.1f}×** | 1 |",
        f"| max axis difference | {s['max_abs_axis_difference_um']:.3f} µm | |",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="degree 3 and a 4 s path")
    args = ap.parse_args()
    degree, duration = (3, 4.0) if args.quick else (4, 20.0)
    res = {"full": not args.quick, "load_average": os.getloadavg()}
    print("load average", res["load_average"])
    cal, truth, estimate, nominal = calibration_study(degree)
    res["calibration"] = cal
    print("calibration", {k: cal["complete"][k] for k in ("compile_s", "run_s", "steps")})
    res["volumetric"] = volumetric_map(truth, estimate)
    print("volumetric", res["volumetric"])
    res["suggestion"] = suggest_test(
        nominal, ballbar_diagonal_plan(nominal), candidate_tests(nominal)
    )
    res["contouring"] = contouring(truth)
    res["speed"] = simulation_speed(truth, duration)
    print("speed", res["speed"])
    res["load_average_end"] = os.getloadavg()
    out = ROOT / "results"
    out.mkdir(exist_ok=True)
    (out / "machine_study.json").write_text(json.dumps(res, indent=2, default=float) + "\n")
    (out / "machine_study.md").write_text(markdown(res))
    print(markdown(res))


if __name__ == "__main__":
    main()
