"""EMPS on the official benchmark split: jaxvs grey-box models, one of them selected on
the training file alone, against the published deep-learning results and the published
IDIM-LS parameters.

The task (`jaxvs.studies.benchmarks.EMPS`): from the motor force `u = gτ·vir` [N] simulate
the motor position `qm` [m] free-run; train on `DATA_EMPS.mat`, test on
`DATA_EMPS_PULSES.mat`; the first 20 output samples of a record initialise the state
(position and velocity from a least-squares parabola; a friction state from its steady
state at that velocity); score the RMSE of the position after them [mm].

Candidates: `OpenLoopAxis`, the rigid axis `M q̈ = u − F(q̇)` of the description (eq. (3))
with `jaxvs.models` friction laws — Coulomb + viscous + offset, asymmetric (eq. (12)), Dahl
(a pre-sliding state, `DahlFriction`, left out of the run below: in a trial its
calibration on half the record diverged to NaN), and friction whose level drifts with
the power it dissipates
(`DriftingFriction`: a temperature-like state driven by the recent work of the axis, so
that two records with other histories see other friction without any measurement of it)
— simulated with the measured force held over each sample (Tsit5, 2 steps per sample).

Calibration: free-run (single-shooting) output error from the 20-sample state estimate,
Levenberg–Marquardt (`fit_multiple_shooting` with one segment and fixed state: the
benchmark's own protocol as the training objective).

Selection uses the training file only, and the test file stays sealed until it is final
(`SealedTestSplit`): two time-ordered folds of the training record — calibrate on its
first half and score the free run over its second half, then the reverse — each
simulation running over the whole record from its first 20 samples (so slow states evolve
over the held-out span as they would in a free run; the held-out outputs never enter the
fit). The candidate with the lowest mean held-out RMSE is selected, recalibrated on the
whole training file and scored once on the test file; the other candidates are scored
after that as ablations.

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
    DahlFriction,
    DriftingFriction,
    RigidAxis,
)
from jaxvs.studies.benchmarks import (  # noqa: E402
    EMPS,
    EMPS_PUBLISHED,
    EMPS_PUBLISHED_IDIM,
    ModelReport,
    OpenLoopAxis,
    SealedTestSplit,
    fit_multiple_shooting,
    write_report,
)

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = ROOT.parent.parent / "shared" / "data" / "EMPS"
DT = EMPS.sample_time
N0 = EMPS.init_window


def _axis(friction):
    return OpenLoopAxis(RigidAxis(95.0, friction), sample_time=DT, n_substeps=2)


def _asym():
    return AsymmetricFriction(20.0, 170.0, 20.0, 240.0)


STRUCTURES = {
    "Coulomb + viscous + offset": lambda: _axis(CoulombViscousFriction(20.0, 200.0, -3.0)),
    "asymmetric (eq. 12)": lambda: _axis(_asym()),
    "asymmetric, drifting with dissipated power, + offset": lambda: _axis(
        DriftingFriction(_asym(), 0.0, 10.0, -3.0)
    ),
}


def _feasible(m):
    f = m.mechanics.friction
    ok = m.mechanics.mass > 0
    if isinstance(f, DriftingFriction):
        ok = ok & (f.time_constant > 0.05)
    if isinstance(f, DahlFriction):
        ok = ok & (f.sigma0 > 0) & (f.Fc > 0)
    return ok


def _calibrate(name, u, y, weights, max_steps, start=None):
    """Free-run output error over the record from its 20-sample state estimate, the
    samples with weight 0 held out of the fit (the simulation still runs over them);
    from the structure's nominal guess or from `start`."""
    fit = fit_multiple_shooting(
        STRUCTURES[name]() if start is None else start,
        u,
        y,
        segment_length=len(u) - N0,
        init_window=N0,
        output_scale=1e-3,  # residuals in mm
        free_states=False,
        feasible=_feasible,
        max_steps=max_steps,
        weights=weights,
        throw=False,
    )
    info = {
        "n_parameters": fit.n_parameters,
        "run_s": fit.run_s,
        "compile_s": fit.compile_s,
        "lm_steps": int(fit.num_steps),
        "converged": bool(fit.result == RESULTS.successful),
        "cost": float(fit.cost),
    }
    return fit.model, info


def _params(model) -> dict:
    leaves = jax.tree_util.tree_flatten_with_path(model.mechanics)[0]
    out = {}
    for path, x in leaves:
        if eqx.is_inexact_array(x):
            out[jax.tree_util.keystr(path)] = float(np.asarray(x))
    return out


def _masked_rmse(model, u, y, mask) -> float:
    """Free-run RMSE [mm] over the samples in `mask` (after the window), the whole record
    simulated from its first 20 samples."""
    y_hat = np.asarray(model(u, y[:N0]))[:, 0]
    e = (y_hat - y[:, 0])[N0:][mask[N0:]]
    return float(1e3 * np.sqrt(np.mean(e**2))) if np.all(np.isfinite(e)) else float("inf")


def select(split: SealedTestSplit, max_steps: int) -> tuple[str, dict]:
    """Two time-ordered folds on the training file; returns the selected structure and
    the evidence (held-out RMSE per fold and candidate). Reads only `split.train`."""
    u, y = EMPS.arrays(split.train.train[0])
    first = np.arange(len(u)) < len(u) // 2
    evidence, fold_models = {}, {}
    for name in STRUCTURES:
        folds = []
        for fit_mask in (first, ~first):
            # each fold from the nominal guess: nothing of its held-out half reaches it
            model, _ = _calibrate(name, u, y, fit_mask.astype(float), max_steps)
            folds.append(_masked_rmse(model, u, y, ~fit_mask))
            fold_models.setdefault(name, model)
        evidence[name] = {"held_out_rmse_mm": folds, "mean_mm": float(np.mean(folds))}
        print(
            f"selection, {name}: held out (fit 1st half -> 2nd, fit 2nd -> 1st) "
            f"{folds[0]:.2f} / {folds[1]:.2f} mm, mean {np.mean(folds):.2f} mm "
            f"(load {os.getloadavg()[0]:.1f})",
            flush=True,
        )
    best = min(evidence, key=lambda k: evidence[k]["mean_mm"])
    return best, evidence, fold_models


def run(split: SealedTestSplit, max_steps: int) -> tuple[list[ModelReport], dict]:
    best, evidence, fold_models = select(split, max_steps)
    split.select(best, evidence)  # final: the test split opens only now
    u, y = EMPS.arrays(split.train.train[0])
    ones = np.ones(len(u))
    rows = []
    for name in [best] + [n for n in STRUCTURES if n != best]:
        # the whole training file, warm-started from the first fold's estimate
        model, info = _calibrate(name, u, y, ones, max_steps, start=fold_models[name])
        score = split.score(model)
        chosen = (
            "selected: lowest held-out free-run RMSE on the training file"
            if name == best
            else "ablation (a candidate not selected)"
        )
        rows.append(
            ModelReport(
                name,
                score,
                parameters=info["n_parameters"],
                train_s=info["run_s"],
                compile_s=info["compile_s"],
                details={"params": _params(model), "selection": evidence[name], **info},
                chosen=chosen,
                selected=name == best,
            )
        )
        print(
            f"{name}{' [selected]' if name == best else ''}: train "
            f"{score.mean('rmse', 'train'):.2f} mm, test {score.mean('rmse'):.2f} mm",
            flush=True,
        )
    p = EMPS_PUBLISHED_IDIM
    pub = _axis(CoulombViscousFriction(p["Fc"], p["Fv"], p["offset"]))
    pub = eqx.tree_at(lambda m: m.mechanics.mass, pub, jax.numpy.asarray(p["M"]))
    rows.append(
        ModelReport(
            "published IDIM-LS parameters, simulated",
            split.score(pub),
            details={"params": p},
            chosen="reference (no training here)",
        )
    )
    return rows, {"selected": best, "selection_evidence": evidence}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--quick", action="store_true", help="10 LM steps (development)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "emps_official")
    args = parser.parse_args()
    load0 = os.getloadavg()
    split = SealedTestSplit.load(EMPS, args.data)
    max_steps = 5 if args.quick else 15
    rows, selection = run(split, max_steps)
    load1 = os.getloadavg()
    best = selection["selected"]
    best_row = next(r for r in rows if r.selected)
    ev = selection["selection_evidence"]
    # IDIM-LS per file: the friction balance of each experiment (after the selection)
    idim = {
        label: {k: float(v) for k, v in jaxvs.idim_ls(rec, friction="asymmetric").params.items()}
        for label, rec in (("train", split.train.train[0]), ("test", split.test[0]))
    }
    preamble = f"""{EMPS.description}

Train `DATA_EMPS.mat`, test `DATA_EMPS_PULSES.mat` (24 841 samples each, 1 kHz); the first
{N0} position samples of a record initialise the state (position and velocity from a
least-squares parabola, a friction state from its steady state at that velocity); RMSE of
the position after them, free-run simulation from the measured force, no other use of the
measured output. Source: {EMPS.source}.

jaxvs models: rigid axis `M q̈ = u − F(q̇)` (`OpenLoopAxis`: `jaxvs.models.RigidAxis` with
`jaxvs.models` friction laws: `CoulombViscousFriction`, `AsymmetricFriction`, and
`DriftingFriction`, whose level follows the power it dissipated recently through a
first-order lag), force held over each
sample, Tsit5 with 2 steps per sample; calibrated by free-run output error
(Levenberg–Marquardt, at most {max_steps} steps).

**Selection without the test file.** The test split is sealed (`SealedTestSplit`) until
the choice is recorded. Each candidate is calibrated on the first half of the training
record and scored by the free run over its second half, then the reverse; every simulation
runs over the whole record from its first {N0} samples, so a slow state evolves over the
held-out half as in a free run, while the held-out outputs never enter the fit. Lowest mean
held-out RMSE: **{best}** ({ev[best]["mean_mm"]:.2f} mm), recalibrated on the whole training
file: **{best_row.score.mean("rmse"):.2f} mm on the test file** — jaxvs's result. The other
rows are ablations, scored only after the selection was final. Machine load average
{load0[0]:.1f} → {load1[0]:.1f} on {os.cpu_count()} CPU(s), beside other jobs: times are
indicative."""
    held = "\n".join(
        f"| {name} | {v['held_out_rmse_mm'][0]:.2f} | {v['held_out_rmse_mm'][1]:.2f} | "
        f"{v['mean_mm']:.2f} |"
        for name, v in ev.items()
    )
    tr, te = idim["train"], idim["test"]
    epilogue = f"""Selection evidence (training file only) [mm]:

| candidate | fit 1st half, free run scored on 2nd | fit 2nd half, scored on 1st | mean |
|---|---:|---:|---:|
{held}

The published rows are black-box networks on the same split (test RMSE and training time
as published). The published IDIM-LS parameters run through the same simulator and the
same 20-sample initialisation.

**What limits the free-run error.** Integrating `M q̈ + F(q̇) = u` over time gives the
position as the time integral of the force balance divided by the viscous coefficient: an
error of 1 % in `Fv` is 2.5 mm over the 0.25 m stroke and 0.1 N of unmodelled constant
force drifts 12 mm in 25 s. The two recordings do not have the same balance: IDIM-LS with
asymmetric friction on each file (computed after the selection) gives `Fv+ / Fv−` =
{tr["Fv_pos"]:.1f} / {tr["Fv_neg"]:.1f} N·s/m on the training file and
{te["Fv_pos"]:.1f} / {te["Fv_neg"]:.1f} N·s/m on the test file, Coulomb
`Fc+ / Fc−` = {tr["Fc_pos"]:.2f} / {tr["Fc_neg"]:.2f} and {te["Fc_pos"]:.2f} /
{te["Fc_neg"]:.2f} N. A model selected on one recording can follow such a change only
through a state it can predict from the input; the drifting-friction candidates are that
attempt, and the table shows how far it carries."""
    md = write_report(
        EMPS,
        rows,
        args.out,
        published=EMPS_PUBLISHED,
        preamble=preamble,
        epilogue=epilogue,
        extra={
            "selected": best,
            "selection": {
                "protocol": "two time-ordered folds of the training file (halves); free-run "
                "RMSE over the held-out half, the whole record simulated from its first "
                f"{N0} samples; lowest mean selected; test split sealed until then",
                "evidence": ev,
            },
            "idim_ls_asymmetric_per_file": idim,
            "settings": {"max_steps": max_steps, "n_substeps": 2, "solver": "tsit5"},
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
