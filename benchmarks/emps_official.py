"""EMPS on the official benchmark split: jaxvs grey-box models against the published
deep-learning results and the published IDIM-LS parameters.

The task (`jaxvs.studies.benchmarks.EMPS`): from the motor force `u = gτ·vir` [N] simulate
the motor position `qm` [m] free-run; train on `DATA_EMPS.mat`, test on
`DATA_EMPS_PULSES.mat`; the first 20 output samples of a record may initialise the state
(here: position and velocity from a least-squares parabola through them); score the RMSE of
the position after them [mm].

Models: `OpenLoopAxis`, the rigid axis `M q̈ = u − F(q̇) − P(q)` of the description
(eq. (3)) with `jaxvs.models` friction laws (Coulomb + viscous + offset, asymmetric,
Stribeck) and an optional position-dependent force (Legendre series over the stroke),
simulated with the measured force held over each sample (Tsit5, 2 steps per sample).

Calibration uses the TRAINING file only: multiple shooting (1 s segments with free initial
states and a continuity penalty, `fit_multiple_shooting`, jaxvs's Levenberg–Marquardt
kernel); the "+ free-run refinement" variants then minimise the free-run error itself on the
whole training record (state fixed at its 20-sample estimate, as the test protocol). Model
structures are selected on training data only: each is calibrated on the
first 80 % of `DATA_EMPS.mat` and simulated free-run on its last 20 % (initialised from
that part's first 20 samples); the structure with the lowest held-out RMSE is the
"selected" one. Every structure is then recalibrated on the whole training file and run
once on the test file.

Reference rows: the published IDIM-LS parameters (description §3.4) through the same
simulator, and the published black-box networks (identibench / tsfast tables).

Writes `benchmarks/results/emps_official.json` and `.md`.
Run: `python benchmarks/emps_official.py [--data PATH] [--quick]`.
"""

import argparse
import os
import platform
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

import jaxvs  # noqa: E402
from jaxvs.calibration import RESULTS  # noqa: E402
from jaxvs.models import (  # noqa: E402
    AsymmetricFriction,
    CoulombViscousFriction,
    FrictionSum,
    RigidAxis,
    StribeckFriction,
)
from jaxvs.studies.benchmarks import (  # noqa: E402
    EMPS,
    EMPS_PUBLISHED,
    EMPS_PUBLISHED_IDIM,
    ModelReport,
    OpenLoopAxis,
    PositionForce,
    TaskData,
    fit_multiple_shooting,
    score_predictor,
    write_report,
)

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = ROOT.parent.parent / "shared" / "data" / "EMPS"
DT = EMPS.sample_time
SEGMENT = 1000  # 1 s segments: a few rise times M/Fv ≈ 0.5 s each
HELD_OUT = 0.2  # last 20 % of the training file for structure selection
# Stroke of the EMPS (0 … 0.246 m on both files): the Legendre basis lives on it.
STROKE_CENTRE, STROKE_HALF = 0.125, 0.13


def _axis(friction, position_order=0):
    pos = None
    if position_order:
        pos = PositionForce(np.zeros(position_order), centre=STROKE_CENTRE, half_range=STROKE_HALF)
    return OpenLoopAxis(RigidAxis(95.0, friction), pos, sample_time=DT, n_substeps=2)


def _cv():
    return CoulombViscousFriction(20.0, 200.0, 0.0)


def _free_sum(m):
    """Free leaves of a FrictionSum(CV, Stribeck(Fc=0, Fv=0)): mass, CV, Fs, vs."""
    laws = m.mechanics.friction.laws
    nodes = [m.mechanics.mass, laws[0], laws[1].Fs, laws[1].vs]
    if m.position_force is not None:
        nodes.append(m.position_force.coefficients)
    return tuple(nodes)


def _stribeck():
    # excess static friction 5 N over 10 mm/s; its own Coulomb and viscous parts stay 0.
    # Sharpness 0.1 mm/s as the Coulomb law's (the default 0.01 mm/s is too stiff for
    # 0.5 ms steps: the two smooth signs together exceed Tsit5's stability limit).
    return StribeckFriction(0.0, 5.0, 0.01, 0.0, velocity_scale=1e-4)


STRUCTURES = {
    "Coulomb + viscous + offset": (lambda: _axis(_cv()), None),
    "asymmetric (eq. 12)": (
        lambda: _axis(AsymmetricFriction(20.0, 170.0, 20.0, 240.0)),
        None,
    ),
    "asymmetric + offset": (
        lambda: _axis(
            FrictionSum(
                AsymmetricFriction(20.0, 170.0, 20.0, 240.0), CoulombViscousFriction(0.0, 0.0, 0.0)
            )
        ),
        lambda m: (
            m.mechanics.mass,
            m.mechanics.friction.laws[0],
            m.mechanics.friction.laws[1].offset,
        ),
    ),
    "Coulomb + viscous + offset + Stribeck": (
        lambda: _axis(FrictionSum(_cv(), _stribeck())),
        _free_sum,
    ),
    "Coulomb + viscous + offset + position force (4)": (
        lambda: _axis(_cv(), position_order=4),
        None,
    ),
    "Coulomb + viscous + offset + Stribeck + position force (4)": (
        lambda: _axis(FrictionSum(_cv(), _stribeck()), position_order=4),
        _free_sum,
    ),
}


# A last free-run (single-shooting) stage on top of multiple shooting: the whole record as
# one segment, its initial state fixed at the 20-sample estimate, exactly the benchmark's
# protocol, so the training objective is the metric itself.
REFINED = ("Coulomb + viscous + offset", "asymmetric + offset")
REFINE_SUFFIX = ", + free-run refinement"
REFINE_STEPS = 30
for _name in REFINED:
    STRUCTURES[_name + REFINE_SUFFIX] = STRUCTURES[_name]


def _feasible(m):
    return m.mechanics.mass > 0


def _fit(model, free, u, y, max_steps):
    return fit_multiple_shooting(
        model,
        u,
        y,
        segment_length=SEGMENT,
        init_window=EMPS.init_window,
        free=free,
        output_scale=1e-3,  # residuals in mm
        state_scale=(1e-3, 2e-3),  # 1 mm, 2 mm/s (≈ 1 mm of drift over M/Fv ≈ 0.5 s)
        continuity=1.0,
        feasible=_feasible,
        max_steps=max_steps,
    )


def _calibrate(name, u, y, max_steps):
    """Multiple shooting, then (refined variants) free-run output error from the
    window-estimated state; returns the model and the solver statistics."""
    make, free = STRUCTURES[name]
    fits = [_fit(make(), free, u, y, max_steps)]
    if name.endswith(REFINE_SUFFIX):
        fits.append(
            fit_multiple_shooting(
                fits[0].model,
                u,
                y,
                segment_length=len(u) - EMPS.init_window,
                init_window=EMPS.init_window,
                free=free,
                output_scale=1e-3,
                free_states=False,
                feasible=_feasible,
                max_steps=max(1, max_steps * REFINE_STEPS // 100),
            )
        )
    last = fits[-1]
    info = {
        "n_parameters": last.n_parameters,
        "run_s": sum(f.run_s for f in fits),
        "compile_s": sum(f.compile_s for f in fits),
        "lm_steps": [int(f.num_steps) for f in fits],
        "converged": [bool(f.result == RESULTS.successful) for f in fits],
        "cost": [float(f.cost) for f in fits],
        "initial_cost": [float(f.initial_cost) for f in fits],
        "segments": [int(f.starts.shape[0]) for f in fits],
    }
    return last.model, info


def _params(model) -> dict:
    leaves = jax.tree_util.tree_flatten_with_path((model.mechanics, model.position_force))[0]
    out = {}
    for path, x in leaves:
        if eqx.is_inexact_array(x):
            key = jax.tree_util.keystr(path)
            vals = np.atleast_1d(np.asarray(x)).tolist()
            out[key] = vals[0] if np.ndim(x) == 0 else vals
    return out


def _held_out(model, u, y) -> float:
    """Free-run RMSE [mm] on the last HELD_OUT of the training record, initialised from
    its first 20 samples, as on the test file."""
    k = int(len(u) * (1 - HELD_OUT))
    u_v, y_v = u[k:], y[k:]
    n0 = EMPS.init_window
    y_hat = np.asarray(model(u_v, y_v[:n0]))
    return float(EMPS.score(y_v, y_hat)["rmse"][0])


def run(data: TaskData, max_steps: int) -> tuple[list[ModelReport], dict]:
    u, y = EMPS.arrays(data.train[0])
    rows = []
    p = EMPS_PUBLISHED_IDIM
    pub = OpenLoopAxis(
        RigidAxis(p["M"], CoulombViscousFriction(p["Fc"], p["Fv"], p["offset"])),
        sample_time=DT,
        n_substeps=2,
    )
    score = score_predictor(EMPS, pub, data)
    rows.append(
        ModelReport(
            "published IDIM-LS parameters (no training here)",
            score,
            details={"params": p, "held_out_rmse": _held_out(pub, u, y)},
        )
    )
    print(
        f"published IDIM: train {score.mean('rmse', 'train'):.2f} mm, "
        f"test {score.mean('rmse'):.2f} mm",
        flush=True,
    )
    k = int(len(u) * (1 - HELD_OUT))
    selection = {}
    for name in STRUCTURES:
        # 1. selection: calibrate on the first 80 %, free-run the last 20 %
        part, _ = _calibrate(name, u[:k], y[:k], max_steps)
        held = _held_out(part, u, y)
        # 2. the reported model: calibrated on the whole training file
        model, info = _calibrate(name, u, y, max_steps)
        score = score_predictor(EMPS, model, data)
        selection[name] = held
        rows.append(
            ModelReport(
                name,
                score,
                parameters=info["n_parameters"],
                train_s=info["run_s"],
                compile_s=info["compile_s"],
                details={"params": _params(model), "held_out_rmse": held, **info},
            )
        )
        print(
            f"{name}: held-out {held:.2f} mm | train {score.mean('rmse', 'train'):.2f} mm, "
            f"test {score.mean('rmse'):.2f} mm | {info['n_parameters']} params, "
            f"{info['lm_steps']} LM steps, run {info['run_s']:.1f} s, compile "
            f"{info['compile_s']:.1f} s",
            flush=True,
        )
    best = min(selection, key=selection.get)
    # Diagnosis only, NOT a benchmark result: the same structures calibrated on the TEST
    # file show how much of the test error is the structure and how much the change of
    # the axis between the two experiments (the test file is used for nothing else).
    test_u, test_y = EMPS.arrays(data.test[0])
    oracle = {}
    for name in dict.fromkeys(["Coulomb + viscous + offset" + REFINE_SUFFIX, best]):
        model, _ = _calibrate(name, test_u, test_y, max_steps)
        s = score_predictor(EMPS, model, data)
        oracle[name] = {
            "test_rmse_mm": s.mean("rmse"),
            "train_rmse_mm": s.mean("rmse", "train"),
            "params": _params(model),
        }
        print(
            f"diagnosis, {name} calibrated on the TEST file: test {s.mean('rmse'):.2f} mm, "
            f"train {s.mean('rmse', 'train'):.2f} mm",
            flush=True,
        )
    # The friction balance of each experiment by IDIM-LS (description §3.4), per file
    idim = {
        friction: {
            label: {k: float(v) for k, v in jaxvs.idim_ls(rec, friction=friction).params.items()}
            for label, rec in (("train", data.train[0]), ("test", data.test[0]))
        }
        for friction in ("coulomb_viscous", "asymmetric")
    }
    return rows, {
        "held_out_rmse_mm": selection,
        "selected": best,
        "oracle": oracle,
        "idim_ls_per_file": idim,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--quick", action="store_true", help="10 LM steps (development)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "emps_official")
    args = parser.parse_args()
    load0 = os.getloadavg()
    data = EMPS.load(args.data)
    rows, selection = run(data, max_steps=10 if args.quick else 100)
    load1 = os.getloadavg()
    best = selection["selected"]
    rows = [
        ModelReport(
            r.name + (" ← selected" if r.name == best else ""),
            r.score,
            r.parameters,
            r.train_s,
            r.compile_s,
            r.details,
        )
        for r in rows
    ]
    by_name = {r.name.removesuffix(" ← selected"): r for r in rows}
    best_row = by_name[best]
    ours = [r for r in rows[1:]]
    lowest = min(ours, key=lambda r: r.score.mean("rmse"))
    preamble = f"""{EMPS.description}

Train `DATA_EMPS.mat`, test `DATA_EMPS_PULSES.mat` (24 841 samples each, 1 kHz); the first
{EMPS.init_window} position samples of a record initialise the state (position and velocity
from a least-squares parabola); RMSE of the position after them, free-run simulation from
the measured force. Source: {EMPS.source}.

jaxvs models: rigid axis `M q̈ = u − F(q̇) − P(q)` (`OpenLoopAxis`: `jaxvs.models.RigidAxis`
with `jaxvs.models` friction laws, optional Legendre position force), force held over each
sample, Tsit5 with 2 steps per sample. Calibrated on the training file only by multiple
shooting ({SEGMENT}-sample segments with free initial states and a continuity penalty;
Levenberg–Marquardt, `fit_multiple_shooting`); the rows "+ free-run refinement" add
{REFINE_STEPS} steps of free-run output error on the whole record from the 20-sample state
estimate (one segment, state fixed: the benchmark's own protocol). Structure selection on
training data only: calibrate on its first {100 * (1 - HELD_OUT):.0f} %, free-run its
last {100 * HELD_OUT:.0f} % (held-out RMSE below); selected: **{best}**
({selection["held_out_rmse_mm"][best]:.2f} mm held out,
**{best_row.score.mean("rmse"):.2f} mm** on the test file). Train time = run time of the
whole-file calibration; compile time separate. Machine load average
{load0[0]:.1f} → {load1[0]:.1f} on {os.cpu_count()} CPU(s) (shared machine: timings are
indicative)."""
    held = "\n".join(f"| {name} | {v:.2f} |" for name, v in selection["held_out_rmse_mm"].items())
    oracle = selection["oracle"]
    idim = selection["idim_ls_per_file"]
    oracle_lines = "\n".join(
        f"| {name} | {by_name[name].score.mean('rmse'):.2f} | {o['test_rmse_mm']:.2f} |"
        for name, o in oracle.items()
    )
    cvp, cvt = idim["coulomb_viscous"]["train"], idim["coulomb_viscous"]["test"]
    asp, ast = idim["asymmetric"]["train"], idim["asymmetric"]["test"]
    epilogue = f"""Held-out RMSE (calibrated on the first 80 % of the training file, free-run on
its last 20 %) [mm]:

| structure | held-out RMSE [mm] |
|---|---:|
| published IDIM-LS parameters | {rows[0].details["held_out_rmse"]:.2f} |
{held}

The published rows are black-box networks on the same split (test RMSE and training time
as published; their NRMSE and train RMSE were not quoted). The published IDIM-LS parameters
run through the same simulator give the 20-sample-initialised figure above; started at rest
(`q̇0 = 0`) instead, as a plain simulation would, they give ≈ 9.2 mm on the test file and
≈ 6.7 mm on the training file.

**What limits the free-run error.** Integrating `M q̈ + Fv q̇ + Fc sign(q̇) + offset = u`
over time gives `Fv (q(t) − q(0)) = ∫u dt − M (q̇(t) − q̇(0)) − Fc ∫sign(q̇) dt −
offset · t`: the simulated position is the *time integral of the force balance* divided
by `Fv`. An error of 1 % in `Fv` is 2.5 mm at the end of the 0.25 m stroke, 0.1 N of
unmodelled constant force drifts 12 mm in 25 s, and a direction-dependent error
(asymmetric viscous or Coulomb friction) grows with the distance travelled (≈ 2 m per
record). The two experiments do not have the same balance: IDIM-LS on each file gives
`Fv` = {cvp["Fv"]:.1f} N·s/m (training) and {cvt["Fv"]:.1f} N·s/m (test), and asymmetric
viscous coefficients `Fv+ / Fv−` = {asp["Fv_pos"]:.1f} / {asp["Fv_neg"]:.1f} (training) and
{ast["Fv_pos"]:.1f} / {ast["Fv_neg"]:.1f} N·s/m (test). Diagnosis only (the test file is
used for nothing else, and these are not benchmark results): the same structures
calibrated on the test file itself reach

| structure | test RMSE, calibrated on the training file [mm] | calibrated on the test file [mm] |
|---|---:|---:|
{oracle_lines}

(so the structures can follow the test experiment this closely when calibrated on it).
Measured on the training file only, the selected structure gives
{best_row.score.mean("rmse"):.2f} mm on the test file; the lowest test error of the table
is {lowest.score.mean("rmse"):.2f} mm ({lowest.name.removesuffix(" ← selected")}). The
change of the axis between the two experiments is larger than the 3 mm target allows, and
no selection on training data can see it: the held-out part of the training file comes
from the same experiment, so the structures and refinements that follow the training
experiment more closely (lower held-out error) carry its particular force balance into the
test, where the free run integrates the difference."""
    md = write_report(
        EMPS,
        rows,
        args.out,
        published=EMPS_PUBLISHED,
        preamble=preamble,
        epilogue=epilogue,
        extra={
            "selection": selection,
            "settings": {
                "segment_length": SEGMENT,
                "held_out_fraction": HELD_OUT,
                "max_steps": 10 if args.quick else 100,
                "n_substeps": 2,
                "solver": "tsit5",
            },
            "machine": {
                "load_average_start": list(load0),
                "load_average_end": list(load1),
                "cpus": os.cpu_count(),
                "platform": platform.platform(),
                "jax": jax.__version__,
            },
        },
    )
    print(md)


if __name__ == "__main__":
    main()
