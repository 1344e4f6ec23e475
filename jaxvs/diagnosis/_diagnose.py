"""`jaxvs.diagnose`: the Python face of `jaxvs diagnose` (docs/guides/contracts.md)."""

from __future__ import annotations

import math
import pathlib
import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._misc import require_x64
from ..data import (
    Record,
    check_validation,
    load_renamed,
    rename_signals,
    require_signals,
    split_blocks,
)
from ._base import AbstractFamily, NotIdentifiable
from ._distortion import nonlinear_distortion
from ._engine import search
from ._gapmap import gap_map
from ._options import validate_options
from ._report import DiagnosisReport
from ._stats import block_length, gap_change_interval, nrmse
from ._verdict import decide, status_line

__all__ = ["FAMILIES", "diagnose"]

from ._families import FAMILIES  # noqa: E402


def _records(
    data: Any, role: str, signals: Any = None, who: str = "diagnose"
) -> list[tuple[Record, str]]:
    if data is None:
        return []
    items = list(data) if isinstance(data, list | tuple) else [data]
    if not items:
        raise ValueError(f"{who}: no {role} experiments given.")
    out = []
    for i, item in enumerate(items):
        if isinstance(item, Record):
            name = str(item.metadata.get("name") or item.metadata.get("file") or f"{role} {i + 1}")
            item = rename_signals(item, signals) if signals else item
            out.append((item, pathlib.Path(name).name))
        elif isinstance(item, str | pathlib.Path):
            loaded = load_renamed(item, signals)
            # A file with several time bases or runs (Sinumerik, TwinCAT, TDMS, MDF) gives
            # one experiment per record.
            recs = loaded if isinstance(loaded, list) else [loaded]
            base = pathlib.Path(item).name
            for k, rec in enumerate(recs):
                out.append((rec, base if len(recs) == 1 else f"{base}[{k}]"))
        else:
            raise TypeError(
                f"{who}: {role} experiment {i + 1} is a {type(item).__name__}; give a "
                "jaxvs.data.Record or a path to a CSV, NPZ, MAT or HDF5 file."
            )
    return out


def _check_signals(
    fam: AbstractFamily, recs: list[tuple[Record, str]], who: str = "diagnose"
) -> None:
    for rec, name in recs:
        missing = [s for s in fam.required if s not in rec.names]
        base = name.split("[")[0]
        apart = [  # the file holds it, in a record of another length (a channel cut short)
            (s, other, n2)
            for s in missing
            for other, n2 in recs
            if n2 != name and n2.split("[")[0] == base and s in other.names
        ]
        if apart:
            s, other, n2 = apart[0]
            raise ValueError(
                f"{who}(family={fam.name!r}): in {base!r} the channel {s!r} has {len(other)} "
                f"samples but {list(rec.names)} have {len(rec)} (a channel shorter than the "
                "others, so the file was read as separate records); cut the channels to a "
                f"common length (Record.slice(0, {min(len(other), len(rec))})) and merge them, "
                "or export the recording again with all channels complete."
            )
        where = f"{who}(family={fam.name!r})"
        require_signals(rec, fam.required, where=where, name=name, optional=fam.optional)


def _check_int(name: str, value: Any, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"diagnose: {name} must be an integer >= {minimum}; got {value!r}.")


def _check_sampling(recs: list[tuple[Record, str]]) -> None:
    """All experiments must share one sampling rate: the analysis filters, the delays and
    the null are built for one sample time; a record at another rate would show its
    resampling as an effect."""
    dts = [(float(r.dt), n) for r, n in recs]
    dt0, n0 = dts[0]
    for dt, n in dts[1:]:
        if abs(dt - dt0) > 1e-6 * dt0:
            raise ValueError(
                f"diagnose: experiment {n!r} is sampled at {1 / dt:g} Hz, {n0!r} at "
                f"{1 / dt0:g} Hz; all experiments must share one sampling rate. Resample "
                "them to a common rate first and say so in your report."
            )


# heuristics: float64 working values per recorded sample, the search's first round from a
# drive record of 2·10^6 samples whose first round asked for 12 GB (an upper bound for
# families that decimate less), the check's Jacobian and quality measures a tenth of it
_SEARCH_VALUES = 750
_CHECK_VALUES = 75


def _memory_check(fam: AbstractFamily, n: int, who: str, values_per_sample: int) -> None:
    """Refuse a run whose largest step would not fit in memory, before it starts."""
    from .._memory import guard

    guard(
        8.0 * values_per_sample * n,
        f"{who}: the {fam.name} family's {'search' if who == 'diagnose' else 'check'} on "
        f"{n} samples",
        "Decimate the records (jaxvs.signal.decimate) or slice them to the stretch that "
        "matters (Record.slice); a few 10^4 samples per experiment are usually enough.",
    )


def _not_identifiable_report(fam, why, cal_recs, val_recs, how, t_start, res=None, check=None):
    """The report of a record that cannot identify the nominal model: no verdict."""
    names = ", ".join(n for _, n in cal_recs)
    content = {
        "check": check,
        "warnings": (check or {}).get("warnings", []),
        "family": fam.name,
        "gap": None,
        "where": [],
        "candidates": [],
        "verdict": None,
        "not_identifiable": f"{why} (calibration records: {names})",
        "nominal": {
            "model": fam.describe_nominal(),
            "parameters": fam.nominal_parameters(res.nominal) if res is not None else {},
        },
        "data": {
            "calibration": [{"name": n, "samples": len(r)} for r, n in cal_recs],
            "validation": [{"name": n, "samples": len(r)} for r, n in val_recs],
            "holdout": how,
        },
        "rounds": [],
        "timing": {"seconds": time.perf_counter() - t_start},
    }
    return DiagnosisReport(content)


def diagnose(
    calibration: Any,
    validation: Any = None,
    *,
    family: str,
    holdout: float = 0.3,
    max_effects: int = 3,
    min_shrink: float = 0.05,
    min_delta_bic: float = 10.0,
    fdr: float = 0.05,
    n_boot: int = 300,
    n_null: int = 19,
    seed: int = 0,
    progress: bool = False,
    signals: Mapping[str, str] | None = None,
    discover: bool = True,
    **options: Any,
) -> DiagnosisReport:
    """Diagnose the sim-to-real gap of a family's nominal model on measured experiments.

    Recalibrates the nominal model, measures the gap against a noise floor, maps where it
    lies (time windows, frequency bands, operating points; block-bootstrap significance
    with false-discovery control), then adds candidate effects from the family's library
    greedily with Levenberg–Marquardt recalibration, accepting one only when the held-out
    gap reduction has a bootstrap interval excluding zero, its best fit is physically
    admissible, ΔBIC (with the residual's effective sample size) exceeds
    `min_delta_bic`, and the held-out gain exceeds the 95th percentile of what the same
    candidate gains on `n_null` effect-free records simulated from the calibrated
    nominal model through the recorded set-up (the null). Among the accepted, the
    largest held-out reduction wins (a base before its extension). A record that cannot
    identify the nominal model gets no verdict: `report["verdict"]` is `None` and
    `report["not_identifiable"]` says why.

    **Arguments:**

    - `calibration`: one or several experiments: `jaxvs.data.Record`s or paths to CSV,
        NPZ, MAT or HDF5 files with the canonical signal names of the family
        (docs/guides/contracts.md), or the EMPS `.mat` files as they are. Several are
        calibrated jointly.
    - `validation`: optional held-out experiments. Without them, the last `holdout` share
        of the experiments (whole experiments) is held out when there are several, or the
        last contiguous `holdout` block of a single experiment — never random samples.
    - `family`: `"drive"`, `"tmf"` or `"thermal"`.
    - `holdout`: share held out when `validation` is not given (default 0.3).
    - `max_effects`: most effects added (default 3).
    - `min_shrink`: an accepted effect must remove at least this share of the validation
        gap (default 0.05), besides being significant.
    - `min_delta_bic`: ΔBIC threshold (default 10, "very strong" evidence).
    - `fdr`: false discovery rate of the gap map (default 0.05).
    - `n_boot`: bootstrap resamples (default 300).
    - `n_null`: effect-free records simulated for the null (default 19: the 95th
        percentile is then about the largest of them).
    - `seed`: seed of the bootstrap and the gap-map permutations.
    - `progress`: print progress to stderr.
    - `signals`: the user's own column names mapped onto the canonical ones,
        `{"q": "Position", "u": "Torque", "t": "Time"}` (`jaxvs.data.rename_signals`).
    - `discover`: after the named search, when the remainder stays above the null
        (`unexplained` or `partly_explained`), look for an effect outside the library
        ([`discover`][jaxvs.diagnosis.discover]: a flexible term in the family's slot,
        then its formula); the result is `report["discovered"]` (default `True`).
    - `**options`: family options (drive: `cutoff_hz`, `decimation`,
      `friction_sharpness`, `zoh_force`, `mass` (the moving mass used when the record does
      not excite the inertia); tmf: `order`; thermal: see the family).

    **Returns:**

    A [`DiagnosisReport`][]: `report.to_json()` is the content of `report.json`,
    `report.save(folder)` writes `report.json` and `report.md`.
    """
    t_start = time.perf_counter()
    require_x64("diagnose", "the recalibrations and the information criteria")
    if family not in FAMILIES:
        raise ValueError(f"diagnose: unknown family {family!r}; choose one of {sorted(FAMILIES)}.")
    if not 0 < holdout < 1:
        raise ValueError(f"diagnose: holdout must lie in (0, 1); got {holdout}.")
    _check_int("max_effects", max_effects, 1)
    _check_int("n_boot", n_boot, 50)
    _check_int("n_null", n_null, 4)
    if not (isinstance(min_shrink, int | float) and 0 <= min_shrink < 1):
        raise ValueError(f"diagnose: min_shrink must lie in [0, 1); got {min_shrink!r}.")
    if not (isinstance(min_delta_bic, int | float) and np.isfinite(min_delta_bic)):
        raise ValueError(f"diagnose: min_delta_bic must be a finite number; got {min_delta_bic!r}.")
    if not (isinstance(fdr, int | float) and 0 < fdr < 1):
        raise ValueError(f"diagnose: fdr must lie in (0, 1); got {fdr!r}.")

    def say(msg: str) -> None:
        if progress:
            print(f"[jaxvs diagnose {time.perf_counter() - t_start:6.1f} s] {msg}", file=sys.stderr)

    fam = FAMILIES[family](
        **validate_options(family, options, "diagnose", FAMILIES[family].option_keys)
    )
    cal_recs = _records(calibration, "calibration", signals)
    val_recs = _records(validation, "validation", signals)
    _check_signals(fam, cal_recs + val_recs)
    _check_sampling(cal_recs + val_recs)
    if val_recs:  # the same record twice is no validation; another scale is no twin
        check_validation([(r, n) for r, n in cal_recs], [(r, n) for r, n in val_recs], fam.required)
    if not val_recs:
        if len(cal_recs) >= 2:
            k = max(1, int(round(holdout * len(cal_recs))))
            k = min(k, len(cal_recs) - 1)
            val_recs, cal_recs = cal_recs[-k:], cal_recs[:-k]
            how = f"last {k} experiment(s) held out"
        else:
            rec, name = cal_recs[0]
            a, b = split_blocks(rec, (1 - holdout, holdout))
            cal_recs, val_recs = (
                [(a, f"{name} (first {1 - holdout:.0%})")],
                [(b, f"{name} (last {holdout:.0%})")],
            )
            how = f"last {holdout:.0%} of the record held out as a contiguous block"
    else:
        how = "validation experiments given"
    # `jaxvs check` first (docs/guides/check.md), on exactly the calibration experiments (the
    # search then reuses the compiled nominal fit): blocking findings end the run without
    # a verdict, the others travel with the report as warnings
    from ._check import check_records

    _memory_check(fam, sum(len(r) for r, _ in cal_recs + val_recs), "diagnose", _SEARCH_VALUES)
    say("checking the calibration data (jaxvs check)")
    check_report = check_records(fam, cal_recs, raise_value_errors=True)
    checked = check_report.content
    if checked["blocking"]:
        why = "jaxvs check: " + " ".join(checked["blocking"])
        return _not_identifiable_report(fam, why, cal_recs, val_recs, how, t_start, None, checked)
    say(f"preparing {len(cal_recs)} calibration and {len(val_recs)} validation experiment(s)")
    try:
        # the check prepared the calibration experiments and fitted the nominal model's
        # start on them already: the same calls on the same records, not made twice
        cal = check_report.experiments or [fam.prepare(r, n) for r, n in cal_recs]
        val = [fam.prepare(r, n) for r, n in val_recs]
    except NotIdentifiable as err:
        return _not_identifiable_report(
            fam, str(err), cal_recs, val_recs, how, t_start, None, checked
        )

    res = search(
        fam,
        cal,
        val,
        max_effects=max_effects,
        min_shrink=min_shrink,
        min_delta_bic=min_delta_bic,
        n_boot=n_boot,
        n_null=n_null,
        seed=seed,
        progress=say,
        initial=check_report.nominal_model if check_report.experiments else None,
    )
    if res.not_identifiable is not None:
        return _not_identifiable_report(
            fam, res.not_identifiable, cal_recs, val_recs, how, t_start, res, checked
        )
    say("mapping the gap")
    exps = res.calibration + res.validation
    ncal = len(res.calibration)
    r0, r1 = res.nominal_residuals, res.final_residuals
    y_cal = np.concatenate([e.y for e in res.calibration])
    y_val = np.concatenate([e.y for e in res.validation])
    gap_cal = nrmse(np.concatenate(r0[:ncal]), y_cal)
    gap_val = nrmse(np.concatenate(r0[ncal:]), y_val)
    noise = res.noise_floor
    white = math.sqrt(sum(e.noise_var * e.n for e in res.validation) / float(np.sum(y_val**2)))

    cells = gap_map(exps, r0, q=fdr, seed=seed)
    cells_after_list = gap_map(exps, r1, q=fdr, seed=seed)
    cells_after = {c.label: c for c in cells_after_list}
    where = []
    for c in cells:
        if not c.significant:
            continue
        d = c.to_json()
        after = cells_after.get(c.label)
        d["gap_after"] = after.gap if after is not None else None
        d["share_after"] = after.share if after is not None else None
        where.append(d)
    where = where[:12]
    where_after = [
        c.to_json() for c in cells_after.values() if c.significant and c.axis != "frequency"
    ]
    where_after.sort(key=lambda d: -(d["share"] - d["fraction"]))
    where_after = where_after[:8]

    for h, rr in zip(res.history, res.round_residuals):
        if h["round"] == 1:
            continue  # the nominal map is `where`
        top = [
            c
            for c in gap_map(exps, rr, q=fdr, seed=seed)
            if c.significant and c.axis != "frequency"
        ]
        h["where_before"] = [c.to_json() for c in top[:6]]
    e_val0 = np.concatenate(r0[ncal:])
    e_val1 = np.concatenate(r1[ncal:])
    g0, g1, shrink, d_int, s_int = gap_change_interval(
        e_val0, e_val1, y_val, length=block_length(e_val0), n_boot=n_boot, seed=seed
    )
    if not res.accepted:
        g1, shrink, s_int = g0, 0.0, (0.0, 0.0)
    state = decide(
        res.accepted,
        g1,
        res.null_gaps,
        noise,
        [c.to_json() for c in cells_after_list],
        fdr=fdr,
    )

    distortion = nonlinear_distortion(fam.name, exps)
    if distortion.get("finding"):
        state["remainder"]["findings"] = [distortion["finding"]]

    cands = list(res.candidates.values())
    order = {n: i for i, n in enumerate(res.accepted)}
    cands.sort(
        key=lambda c: (
            0 if c.effect in order else (1 if c.testable and c.round else 2),
            order.get(c.effect, 0),
            -c.reduction,
        )
    )
    primary = res.primary
    cand_json = []
    for c in cands:
        cand_json.append(
            {
                "effect": c.effect,
                "testable": c.testable,
                "reason": c.reason,
                "description": c.description,
                "signature": c.signature,
                "round": c.round,
                "calibration_gap": c.calibration_gap,
                "validation_gap": c.validation_gap,
                "validation_gap_before": c.gap_before,
                "shrink": c.shrink,
                "shrink_interval": list(c.shrink_interval) if c.shrink_interval else None,
                "reduction_interval": list(c.reduction_interval) if c.reduction_interval else None,
                "delta_bic": c.delta_bic,
                "admissible": c.admissible,
                "null_p95": c.null_p95,
                "null_median": c.null_median,
                "null_threshold": c.null_threshold,
                "rejected_by": c.rejected_by,
                "explained": c.explained if c.accepted else None,
                "accepted": c.accepted,
                "extends": c.extends,
                "parameters": c.parameters,
                "seconds": c.seconds,
            }
        )
    content = {
        "family": fam.name,
        "gap": {
            "metric": "nrmse",
            "calibration": gap_cal,
            "validation": gap_val,
            "noise_floor": noise,
            "noise_floor_white": white,
            "null_gaps": list(res.null_gaps),
            "target": fam.target_label,
        },
        "not_identifiable": None,
        "distortion": distortion,
        "check": checked,
        "warnings": list(checked["warnings"]),
        "where": where,
        "where_after": where_after,
        "candidates": cand_json,
        "verdict": {
            "status": state["status"],
            "effects": list(res.accepted),
            "final_effects": list(res.final.effect_names),
            "primary": primary,
            "validation_gap": g1,
            "calibration_gap": nrmse(np.concatenate(r1[:ncal]), y_cal),
            "shrink": shrink,
            "shrink_interval": list(s_int),
            "remaining_over_noise": g1 / noise if noise > 0 else None,
            "adequate": state["adequate"],
            "remainder": state["remainder"],
            "parameters": {
                "nominal": fam.nominal_parameters(res.final),
                **{e.name: e.parameters() for e in res.final.effects},
            },
        },
        "nominal": {
            "model": fam.describe_nominal(),
            "parameters": fam.nominal_parameters(res.nominal),
        },
        "data": {
            "calibration": [{"name": e.name, "samples": e.n} for e in res.calibration],
            "validation": [{"name": e.name, "samples": e.n} for e in res.validation],
            "holdout": how,
            "options": {k: v for k, v in fam.options.items() if isinstance(v, int | float | str)},
        },
        "rounds": res.history,
        "pruning": res.pruning,
        "timing": {"seconds": time.perf_counter() - t_start},
    }
    content["verdict"]["status_line"] = status_line(content["verdict"])
    content["discovered"] = None
    say("done: " + content["verdict"]["status_line"])
    report = DiagnosisReport(
        content,
        nominal_model=res.nominal,
        final_model=res.final,
        calibration=res.calibration,
        validation=res.validation,
        predictions={
            "nominal": [e.y - r for e, r in zip(exps, r0)],
            "final": [e.y - r for e, r in zip(exps, r1)],
        },
        cells=cells,
    )
    if discover and state["status"] in ("unexplained", "partly_explained"):
        _discover_into(report, fam, n_null=n_null, seed=seed, say=say)
    return report


def _discover_into(
    report: DiagnosisReport, fam: AbstractFamily, *, n_null: int, seed: int, say: Any
) -> None:
    """Discovery after the named search (`report["discovered"]`, `report.discovered`):
    only for a remainder above the null, and only where the family has a slot."""
    from ._discover import SLOT_FAMILIES, discover

    if fam.name not in SLOT_FAMILIES:
        report.content["discovered"] = {
            "fired": False,
            "found": False,
            "message": f"not run: the {fam.name} family has no discovery slot yet",
        }
        return
    say("discovery: a flexible term in the family's slot, then its formula")
    found = discover(report, family=fam, n_null=n_null, seed=seed, progress=say)
    report.discovered = found
    report.content["discovered"] = found.to_json()
