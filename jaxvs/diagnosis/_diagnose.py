"""`jaxvs.diagnose`: the Python face of `jaxvs diagnose` (docs/guides/contracts.md)."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._misc import require_x64
from ..data import (
    check_validation,
    split_blocks,
)
from ._base import AbstractFamily, NotIdentifiable
from ._check import check_records
from ._distortion import nonlinear_distortion
from ._engine import SearchOptions, search
from ._gapmap import gap_map
from ._inputs import (
    SEARCH_VALUES,
    check_int,
    check_sampling,
    check_signals,
    memory_check,
    records,
)
from ._options import validate_options
from ._report import (
    DataSummary,
    DiagnosisContent,
    DiagnosisReport,
    ExperimentSize,
    Gap,
    Nominal,
    Timing,
    Verdict,
)
from ._stats import block_length, gap_change_interval, nrmse
from ._verdict import decide, status_line

__all__ = ["FAMILIES", "diagnose"]

from ._families import FAMILIES  # noqa: E402


def _not_identifiable_report(setup: _Setup, why: str, res, check) -> DiagnosisReport:
    """The report of a record that cannot identify the nominal model: no verdict."""
    fam = setup.fam
    names = ", ".join(n for _, n in setup.cal_recs)
    content = DiagnosisContent(
        family=fam.name,
        not_identifiable=f"{why} (calibration records: {names})",
        check=check,
        warnings=list(check.warnings) if check is not None else [],
        nominal=Nominal(
            model=fam.describe_nominal(),
            parameters=(
                fam.nominal_parameters(res.nominal, res.calibration) if res is not None else {}
            ),
        ),
        data=_data_json(setup),
        timing=Timing(seconds=time.perf_counter() - setup.t_start),
    )
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
    _check_arguments(family, holdout, max_effects, n_boot, n_null, min_shrink, min_delta_bic, fdr)

    def say(msg: str) -> None:
        if progress:
            print(f"[jaxvs diagnose {time.perf_counter() - t_start:6.1f} s] {msg}", file=sys.stderr)

    fam = FAMILIES[family](
        **validate_options(family, options, "diagnose", FAMILIES[family].option_keys)
    )
    cal_recs = records(calibration, "calibration", signals)
    val_recs = records(validation, "validation", signals)
    check_signals(fam, cal_recs + val_recs)
    check_sampling(cal_recs + val_recs)
    if val_recs:  # the same record twice is no validation; another scale is no twin
        check_validation([(r, n) for r, n in cal_recs], [(r, n) for r, n in val_recs], fam.required)
    cal_recs, val_recs, how = _split_holdout(cal_recs, val_recs, holdout)
    setup = _Setup(fam, cal_recs, val_recs, how, t_start)
    memory_check(fam, sum(len(r) for r, _ in cal_recs + val_recs), "diagnose", SEARCH_VALUES)
    prepared = _prepare(setup, say)
    if isinstance(prepared, DiagnosisReport):
        return prepared
    cal, val, check_report = prepared
    res = search(
        fam,
        cal,
        val,
        SearchOptions.of(
            max_effects=max_effects,
            min_shrink=min_shrink,
            min_delta_bic=min_delta_bic,
            n_boot=n_boot,
            n_null=n_null,
            seed=seed,
        ),
        progress=say,
        initial=check_report.nominal_model if check_report.experiments else None,
    )
    checked = check_report.content
    if res.not_identifiable is not None:
        return _not_identifiable_report(setup, res.not_identifiable, res, checked)
    say("mapping the gap")
    report = _report(setup, res, checked, fdr=fdr, n_boot=n_boot, seed=seed)
    say("done: " + report.status_line)
    if discover and report.status in ("unexplained", "partly_explained"):
        report = _discover_into(report, fam, n_null=n_null, seed=seed, say=say)
    return report


def _check_arguments(family, holdout, max_effects, n_boot, n_null, min_shrink, min_dbic, fdr):
    """`diagnose`'s settings, each refused with the range it must lie in."""
    if family not in FAMILIES:
        raise ValueError(f"diagnose: unknown family {family!r}; choose one of {sorted(FAMILIES)}.")
    if not 0 < holdout < 1:
        raise ValueError(f"diagnose: holdout must lie in (0, 1); got {holdout}.")
    check_int("max_effects", max_effects, 1)
    check_int("n_boot", n_boot, 50)
    check_int("n_null", n_null, 4)
    if not (isinstance(min_shrink, int | float) and 0 <= min_shrink < 1):
        raise ValueError(f"diagnose: min_shrink must lie in [0, 1); got {min_shrink!r}.")
    if not (isinstance(min_dbic, int | float) and np.isfinite(min_dbic)):
        raise ValueError(f"diagnose: min_delta_bic must be a finite number; got {min_dbic!r}.")
    if not (isinstance(fdr, int | float) and 0 < fdr < 1):
        raise ValueError(f"diagnose: fdr must lie in (0, 1); got {fdr!r}.")


def _split_holdout(cal_recs, val_recs, holdout: float):
    """The held-out experiments when none are given: the last `holdout` share of whole
    experiments when there are several, else the last contiguous block of the one record
    (never random samples). Returns the calibration and validation records and how."""
    if val_recs:
        return cal_recs, val_recs, "validation experiments given"
    if len(cal_recs) >= 2:
        k = max(1, int(round(holdout * len(cal_recs))))
        k = min(k, len(cal_recs) - 1)
        return cal_recs[:-k], cal_recs[-k:], f"last {k} experiment(s) held out"
    rec, name = cal_recs[0]
    a, b = split_blocks(rec, (1 - holdout, holdout))
    return (
        [(a, f"{name} (first {1 - holdout:.0%})")],
        [(b, f"{name} (last {holdout:.0%})")],
        f"last {holdout:.0%} of the record held out as a contiguous block",
    )


@dataclasses.dataclass(frozen=True)
class _Setup:
    """The family and the records of one diagnosis, as the report names them."""

    fam: AbstractFamily
    cal_recs: list
    val_recs: list
    how: str
    t_start: float


def _prepare(setup: _Setup, say):
    """`jaxvs check` on exactly the calibration experiments (the search then reuses its
    prepared experiments and nominal fit), then the validation experiments prepared.
    Returns `(calibration, validation, check report)`, or the report without a verdict
    when the check blocks or a record cannot identify the model."""

    fam = setup.fam
    say("checking the calibration data (jaxvs check)")
    check_report = check_records(fam, setup.cal_recs, raise_value_errors=True)
    checked = check_report.content
    if checked.blocking:
        why = "jaxvs check: " + " ".join(checked.blocking)
        return _not_identifiable_report(setup, why, None, checked)
    n_cal, n_val = len(setup.cal_recs), len(setup.val_recs)
    say(f"preparing {n_cal} calibration and {n_val} validation experiment(s)")
    try:
        cal = check_report.experiments or [fam.prepare(r, n) for r, n in setup.cal_recs]
        val = [fam.prepare(r, n) for r, n in setup.val_recs]
    except NotIdentifiable as err:
        return _not_identifiable_report(setup, str(err), None, checked)
    return cal, val, check_report


def _gap_maps(res, fdr: float, seed: int):
    """Where the gap lies before and after the search: the significant cells of the
    nominal residual (with their gap after), those of the final residual, and, in every
    round after the first, those at its start (`rounds[i]["where_before"]`)."""
    exps = res.calibration + res.validation
    cells = gap_map(exps, res.nominal_residuals, q=fdr, seed=seed)
    cells_after = gap_map(exps, res.final_residuals, q=fdr, seed=seed)
    by_label = {c.label: c for c in cells_after}
    where = []
    for c in cells:
        if not c.significant:
            continue
        d = c.to_json()
        after = by_label.get(c.label)
        d["gap_after"] = after.gap if after is not None else None
        d["share_after"] = after.share if after is not None else None
        where.append(d)
    where_after = [c.to_json() for c in cells_after if c.significant and c.axis != "frequency"]
    where_after.sort(key=lambda d: -(d["share"] - d["fraction"]))
    for h, rr in zip(res.history, res.round_residuals):
        if h["round"] == 1:
            continue  # the nominal map is `where`
        top = [
            c
            for c in gap_map(exps, rr, q=fdr, seed=seed)
            if c.significant and c.axis != "frequency"
        ]
        h["where_before"] = [c.to_json() for c in top[:6]]
    return cells, cells_after, where[:12], where_after[:8]


def _candidates_json(res) -> list[dict[str, Any]]:
    """Every candidate, accepted first (in order), then those tried, then the others."""
    order = {n: i for i, n in enumerate(res.accepted)}
    cands = sorted(
        res.candidates.values(),
        key=lambda c: (
            0 if c.effect in order else (1 if c.testable and c.round else 2),
            order.get(c.effect, 0),
            -c.reduction,
        ),
    )
    return [c.to_json() for c in cands]


def _report(setup: _Setup, res, checked, *, fdr: float, n_boot: int, seed: int):
    """The report of a search: the gap, where it lies, the candidates and the verdict."""
    fam = setup.fam
    exps = res.calibration + res.validation
    ncal = len(res.calibration)
    r0, r1 = res.nominal_residuals, res.final_residuals
    y_cal = np.concatenate([e.y for e in res.calibration])
    y_val = np.concatenate([e.y for e in res.validation])
    noise = res.noise_floor
    white = math.sqrt(sum(e.noise_var * e.n for e in res.validation) / float(np.sum(y_val**2)))
    cells, cells_after, where, where_after = _gap_maps(res, fdr, seed)
    e_val0 = np.concatenate(r0[ncal:])
    g0, g1, shrink, _, s_int = gap_change_interval(
        e_val0,
        np.concatenate(r1[ncal:]),
        y_val,
        length=block_length(e_val0),
        n_boot=n_boot,
        seed=seed,
    )
    if not res.accepted:
        g1, shrink, s_int = g0, 0.0, (0.0, 0.0)
    state = decide(
        res.accepted, g1, res.null_gaps, noise, [c.to_json() for c in cells_after], fdr=fdr
    )
    distortion = nonlinear_distortion(fam.name, exps)
    if distortion.get("finding"):
        state["remainder"]["findings"] = [distortion["finding"]]
    verdict = Verdict(
        status=state["status"],
        effects=list(res.accepted),
        final_effects=list(res.final.effect_names),
        primary=res.primary,
        validation_gap=g1,
        calibration_gap=nrmse(np.concatenate(r1[:ncal]), y_cal),
        shrink=shrink,
        shrink_interval=list(s_int),
        remaining_over_noise=g1 / noise if noise > 0 else None,
        adequate=state["adequate"],
        remainder=state["remainder"],
        searched=not res.gated,
        parameters={
            "nominal": fam.nominal_parameters(res.final, res.calibration),
            **{e.name: e.parameters() for e in res.final.effects},
        },
    )
    verdict = dataclasses.replace(verdict, status_line=status_line(verdict._json()))
    content = DiagnosisContent(
        family=fam.name,
        gap=Gap(
            metric="nrmse",
            calibration=nrmse(np.concatenate(r0[:ncal]), y_cal),
            validation=g0,
            noise_floor=noise,
            noise_floor_white=white,
            null_gaps=list(res.null_gaps),
            target=fam.target_label,
        ),
        not_identifiable=None,
        distortion=distortion,
        check=checked,
        warnings=list(checked.warnings),
        where=where,
        where_after=where_after,
        candidates=_candidates_json(res),
        verdict=verdict,
        nominal=Nominal(
            model=fam.describe_nominal(),
            parameters=fam.nominal_parameters(res.nominal, res.calibration),
        ),
        data=_data_json(setup, res),
        rounds=res.history,
        pruning=res.pruning,
        timing=Timing(seconds=time.perf_counter() - setup.t_start),
        discovered=None,
    )
    return DiagnosisReport(
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


def _data_json(setup: _Setup, res=None) -> DataSummary:
    """The experiments of the diagnosis (prepared ones when the search ran)."""
    if res is None or not res.calibration:
        cal = [ExperimentSize(name=n, samples=len(r)) for r, n in setup.cal_recs]
        val = [ExperimentSize(name=n, samples=len(r)) for r, n in setup.val_recs]
    else:
        cal = [ExperimentSize(name=e.name, samples=e.n) for e in res.calibration]
        val = [ExperimentSize(name=e.name, samples=e.n) for e in res.validation]
    options = None
    if res is not None and res.calibration:
        opts = setup.fam.settings(res.calibration)
        options = {k: v for k, v in opts.items() if isinstance(v, int | float | str)}
    return DataSummary(calibration=cal, validation=val, holdout=setup.how, options=options)


def _discover_into(
    report: DiagnosisReport, fam: AbstractFamily, *, n_null: int, seed: int, say: Any
) -> DiagnosisReport:
    """The report with the discovery after the named search (`report["discovered"]`,
    `report.discovered`): only for a remainder above the null, and only where the family
    has a slot."""
    from ._discover import SLOT_FAMILIES, discover

    if fam.name not in SLOT_FAMILIES:
        not_run = {
            "fired": False,
            "found": False,
            "message": f"not run: the {fam.name} family has no discovery slot yet",
        }
        return dataclasses.replace(
            report, content=dataclasses.replace(report.content, discovered=not_run)
        )
    say("discovery: a flexible term in the family's slot, then its formula")
    found = discover(report, family=fam, n_null=n_null, seed=seed, progress=say)
    return dataclasses.replace(
        report,
        content=dataclasses.replace(report.content, discovered=found.to_json()),
        discovered=found,
    )
