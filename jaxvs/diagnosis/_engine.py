"""Augment and recalibrate: the greedy search for the effects that close the gap.

The search runs in named steps:

1. **nominal** ([`_nominal`][]): the nominal model is recalibrated on the calibration
   experiments, so ordinary parameter error is never taken for a missing effect. A
   record that does not identify it gets no search at all (`family.identifiability`: the
   reason is reported instead of a verdict).
2. **null** ([`_null`][]): `family.null_experiments` simulates K effect-free copies of the
   records from the calibrated model through the recorded set-up; the nominal model
   refitted on them gives the noise floor (the median of their held-out gaps). When the
   nominal model's own held-out gap already lies within the null's distribution (the
   verdict's `adequate` bound), no candidate is tried: the one omnibus test protects the
   many candidate tests that would follow (Fisher's protected tests; a closed testing
   procedure, Marcus, Peritz & Gabriel 1976), so an effect-free record cannot pick up an
   effect by trying many.
3. **round** ([`_round`][]): every open candidate of the family's library is tried from its
   starting shapes ([`_try`][]: sizes by least squares, then the whole model recalibrated,
   all starts in one call of the one fitting program, `_fitting.fit_many`); the best
   **admissible** start by calibration cost is kept. Each try is one immutable
   [`Trial`][]. A trial passes the acceptance tests (`_acceptance.rejection`), then the
   null ([`_null_test`][]: what the same candidate gains on the null records). Among those
   that pass, a base goes before its own extension (marginality), otherwise the largest
   held-out reduction wins ([`choose`][]). Rounds go on until none passes, after
   `max_effects` effects, or when the held-out gap is within the noise floor.
4. **prune** ([`_prune`][]): every accepted effect is tested again, by the same acceptance
   function, against the final model without it; the primary effect is the one that
   explains most of the held-out gap.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ._acceptance import (
    Evidence,
    Thresholds,
    compare,
    noise_sample_share,
    null_threshold,
    rejection,
)
from ._base import AbstractFamily, Context, EffectSpec, Experiment, GapModel
from ._fitting import Layout, dof, early_layout, fit_many, same_structure
from ._stats import nrmse
from ._verdict import null_bound

__all__ = ["CandidateResult", "SearchOptions", "SearchResult", "Trial", "search"]


@dataclasses.dataclass(frozen=True)
class SearchOptions:
    """The settings of one search (`jaxvs.diagnose` documents each).

    - `gate`: try no candidate when the nominal model's held-out gap is already within
      the null (module doc, step 2).
    """

    max_effects: int = 3
    max_steps: int = 40
    thresholds: Thresholds = Thresholds()
    n_null: int = 19
    null_level: float = 0.95
    seed: int = 0
    stop_at_noise: float = 1.1
    gate: bool = True

    @classmethod
    def of(cls, **kw: Any) -> SearchOptions:
        """Options from flat keywords (`min_shrink`, `min_delta_bic` and `n_boot` go into
        the thresholds)."""
        names = {f.name for f in dataclasses.fields(Thresholds)}
        th = Thresholds(**{k: kw.pop(k) for k in list(kw) if k in names})
        return cls(thresholds=th, **kw)


# ------------------------------------------------------------------------------ records


@dataclasses.dataclass
class CandidateResult:
    """One candidate effect as it was last tried (what the report shows)."""

    effect: str
    testable: bool
    reason: str | None = None  # why not testable, or why inadmissible
    round: int = 0
    signature: float = 0.0  # share of the current residual its regressors explain
    calibration_gap: float | None = None
    validation_gap: float | None = None
    gap_before: float | None = None
    shrink: float | None = None
    shrink_interval: tuple[float, float] | None = None
    reduction_interval: tuple[float, float] | None = None
    delta_bic: float | None = None
    accepted: bool = False
    parameters: dict[str, float] = dataclasses.field(default_factory=dict)
    extends: str | None = None
    description: str = ""
    admissible: bool | None = None
    null_p95: float | None = None  # the null's 95th percentile of the held-out reduction
    null_median: float | None = None
    null_threshold: float | None = None  # the level it had to beat (multiplicity-corrected)
    rejected_by: str | None = None  # the first acceptance test it failed
    explained: float = 0.0  # held-out reduction it brought when accepted (gap units)
    model: GapModel | None = None
    seconds: float = 0.0

    @property
    def reduction(self) -> float:
        if self.gap_before is None or self.validation_gap is None:
            return -np.inf
        return self.gap_before - self.validation_gap

    def to_json(self) -> dict[str, Any]:
        """The candidate as `report.json` shows it (`candidates[i]`)."""
        return {
            "effect": self.effect,
            "testable": self.testable,
            "reason": self.reason,
            "description": self.description,
            "signature": self.signature,
            "round": self.round,
            "calibration_gap": self.calibration_gap,
            "validation_gap": self.validation_gap,
            "validation_gap_before": self.gap_before,
            "shrink": self.shrink,
            "shrink_interval": list(self.shrink_interval) if self.shrink_interval else None,
            "reduction_interval": (
                list(self.reduction_interval) if self.reduction_interval else None
            ),
            "delta_bic": self.delta_bic,
            "admissible": self.admissible,
            "null_p95": self.null_p95,
            "null_median": self.null_median,
            "null_threshold": self.null_threshold,
            "rejected_by": self.rejected_by,
            "explained": self.explained if self.accepted else None,
            "accepted": self.accepted,
            "extends": self.extends,
            "parameters": self.parameters,
            "seconds": self.seconds,
        }

    def record(self, trial: Trial, y_cal: np.ndarray, n_cal_exp: int) -> None:
        """Show `trial` as this candidate's latest try."""
        ev = trial.evidence
        self.round = trial.round
        self.calibration_gap = nrmse(np.concatenate(trial.residuals[:n_cal_exp]), y_cal)
        self.validation_gap = ev.gap_after
        self.gap_before = ev.gap_before
        self.shrink = ev.shrink
        self.shrink_interval = ev.shrink_interval
        self.reduction_interval = ev.reduction_interval
        self.delta_bic = ev.delta_bic
        self.parameters = trial.effect.parameters()
        self.admissible, self.reason = trial.admissible
        self.null_p95 = self.null_median = self.null_threshold = None
        self.model = trial.model
        self.rejected_by = trial.rejected_by


@dataclasses.dataclass(frozen=True)
class Trial:
    """One candidate tried in one round: its best admissible fit and what it showed."""

    name: str
    round: int
    start: GapModel  # the start it was fitted from (the null records start there too)
    slot: int  # the candidate's position among the start's effects
    model: GapModel  # the calibrated model with the candidate
    residuals: tuple[np.ndarray, ...]  # per experiment, calibration first
    ssr: float  # calibration SSR
    dof: int
    evidence: Evidence
    admissible: tuple[bool, str | None]
    rejected_by: str | None  # the first test failed before the null, or None

    @property
    def effect(self):
        return next(e for e in self.model.effects if e.name == self.name)


@dataclasses.dataclass(frozen=True)
class _Problem:
    """What every step reads: the family, its library, the experiments (calibration
    first; replaced by their refreshed copies round by round) and the options."""

    family: AbstractFamily
    library: tuple[EffectSpec, ...]
    exps: tuple[Experiment, ...]
    n_cal_exp: int
    scale: float
    opts: SearchOptions
    say: Callable[[str], None]
    context: Any = None  # the admissibility context, from the calibrated nominal model

    @property
    def specs(self) -> dict[str, EffectSpec]:
        return {s.name: s for s in self.library}

    @property
    def cal(self) -> list[Experiment]:
        return list(self.exps[: self.n_cal_exp])

    @property
    def val(self) -> list[Experiment]:
        return list(self.exps[self.n_cal_exp :])

    def y(self, role: str) -> np.ndarray:
        return np.concatenate([e.y for e in (self.cal if role == "cal" else self.val)])

    def gap(self, residuals: Sequence[np.ndarray]) -> float:
        """The held-out gap (nrmse) of per-experiment residuals."""
        return nrmse(np.concatenate(list(residuals[self.n_cal_exp :])), self.y("val"))

    def fit(self, models, slots, layout, data=None):
        """`fit_many` on these experiments (or per-model `data`, the null records)."""
        exps = self.exps if data is None else data
        opts = self.opts
        return fit_many(models, slots, exps, self.n_cal_exp, self.scale, opts.max_steps, layout)


@dataclasses.dataclass(frozen=True)
class _Current:
    """The model a round starts from, with what its fit left."""

    model: GapModel
    residuals: tuple[np.ndarray, ...]
    ssr: float
    dof: int
    layout: Layout | None
    layout_checked: bool  # the layout was built from a calibrated model's templates


@dataclasses.dataclass(frozen=True)
class _Null:
    """The effect-free records and the current model refitted on them (`stale` once an
    effect has been accepted and they have not been refitted with it yet)."""

    sets: list
    residuals: list
    models: list
    gaps: list[float]  # the nominal model's held-out gaps on them
    floor: float
    noise_share: float
    stale: bool = False


@dataclasses.dataclass
class SearchResult:
    nominal: GapModel
    final: GapModel
    accepted: list[str]
    candidates: dict[str, CandidateResult]
    history: list[dict[str, Any]]
    scale: float
    calibration: list[Experiment]
    validation: list[Experiment]
    nominal_residuals: list[np.ndarray]
    final_residuals: list[np.ndarray]
    round_residuals: list[list[np.ndarray]]  # at the start of each round
    noise_floor: float = 0.0
    null_gaps: list[float] = dataclasses.field(default_factory=list)
    not_identifiable: str | None = None
    primary: str | None = None
    pruning: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    gated: bool = False  # no candidate tried: the nominal gap was within the null


# ------------------------------------------------------------------------------ choice


def choose(passing: Sequence[CandidateResult], accepted: Sequence[str]) -> CandidateResult:
    """The candidate to add among those that pass every test: by held-out evidence, the
    largest reduction of the validation gap; but a base before its own extension when
    both pass (the principle of marginality: Stribeck friction only after Coulomb)."""
    names = {c.effect for c in passing}
    eligible = [c for c in passing if not (c.extends in names and c.extends not in accepted)]
    return max(eligible, key=lambda c: c.reduction)


def primary_effect(
    accepted: Sequence[str], candidates: Mapping[str, CandidateResult]
) -> str | None:
    """The accepted effect that explains most of the held-out gap: the largest validation
    gap reduction it brought when it was added (an extension that replaced its base
    counts with the base's reduction, as itself)."""
    if not accepted:
        return None
    return max(accepted, key=lambda a: candidates[a].explained)


def _quantile(x: Sequence[float], q: float) -> float:
    x = np.asarray([v for v in x if np.isfinite(v)], float)
    return float(np.quantile(x, q)) if x.size else float("inf")


# ------------------------------------------------------------------------------ search


def search(
    family: AbstractFamily,
    calibration: list[Experiment],
    validation: list[Experiment],
    options: SearchOptions | None = None,
    *,
    progress: Callable[[str], None] | None = None,
    initial: Any = None,
    **overrides: Any,
) -> SearchResult:
    """Nominal recalibration, the identifiability check, the null, the greedy rounds and
    the pruning (module doc).

    - `options`: a [`SearchOptions`][]; keywords (`max_effects`, `min_shrink`, ...)
      override its fields.
    - `initial`: the nominal model's start `family.nominal(calibration)` when the caller
      has it already (`jaxvs check` fits it on the same experiments).
    """
    opts = options or SearchOptions()
    if overrides:
        flat = {f.name: getattr(opts, f.name) for f in dataclasses.fields(opts)}
        flat.pop("thresholds")
        flat.update(dataclasses.asdict(opts.thresholds))
        opts = SearchOptions.of(**{**flat, **overrides})
    y_all = np.concatenate([e.y for e in calibration])
    prob = _Problem(
        family,
        tuple(family.library()),
        tuple(calibration) + tuple(validation),
        len(calibration),
        1.0 / max(float(np.sqrt(np.mean(y_all**2))), 1e-300),
        opts,
        progress or (lambda msg: None),
    )
    candidates = {}
    for s in prob.library:
        reason = s.not_testable(list(prob.exps))
        candidates[s.name] = CandidateResult(
            s.name, reason is None, reason, extends=s.extends, description=s.description
        )
    cur = _nominal(prob, candidates, initial)
    nominal, nominal_residuals = cur.model, list(cur.residuals)

    def result(prob: _Problem, cur: _Current, **kw) -> SearchResult:
        return SearchResult(
            nominal=nominal,
            final=cur.model,
            candidates=candidates,
            scale=prob.scale,
            calibration=prob.cal,
            validation=prob.val,
            nominal_residuals=nominal_residuals,
            final_residuals=list(cur.residuals),
            **{"accepted": [], "history": [], "round_residuals": [], **kw},
        )

    why = family.identifiability(prob.cal, cur.model)
    if why is not None:
        prob.say(f"not identifiable: {why}")
        return result(prob, cur, not_identifiable=why)
    prob = dataclasses.replace(prob, context=family.admissibility_context(prob.cal, cur.model))
    null = _null(prob, cur)
    floor = dict(noise_floor=null.floor, null_gaps=null.gaps)
    if opts.gate and prob.gap(cur.residuals) <= null_bound(null.gaps):
        prob.say("the nominal model's held-out gap lies within the null: no candidate tried")
        return result(prob, cur, gated=True, **floor)

    accepted: list[str] = []
    history: list[dict[str, Any]] = []
    round_residuals: list[list[np.ndarray]] = []
    for rnd in range(1, opts.max_effects + 1):
        round_residuals.append(list(cur.residuals))
        prob, cur, null, entry, chosen = _round(prob, cur, null, candidates, accepted, rnd)
        if entry is None:  # no candidate open
            round_residuals.pop()
            break
        history.append(entry)
        if chosen is None:
            break
        if chosen.validation_gap <= opts.stop_at_noise * null.floor:
            prob.say("the remaining gap is within the noise floor: stopping")
            break
    nominal_gap = prob.gap(nominal_residuals)
    cur, pruning = _prune(prob, cur, accepted, candidates, null.noise_share, nominal_gap)
    return result(
        prob,
        cur,
        accepted=accepted,
        history=history,
        round_residuals=round_residuals,
        primary=primary_effect(accepted, candidates),
        pruning=pruning,
        **floor,
    )


def _nominal(prob: _Problem, candidates: Mapping[str, CandidateResult], initial) -> _Current:
    """Step 1: the nominal model recalibrated. Through the search's own structure when the
    family can say it before the calibration (one compilation for the whole search), else
    through a layout without slots."""
    prob.say("recalibrating the nominal model")
    start = GapModel(prob.family.nominal(prob.cal) if initial is None else initial)
    testable = {n for n, c in candidates.items() if c.testable}
    layout = early_layout(prob.family, prob.library, testable, start, prob.exps, prob.n_cal_exp)
    bare = layout or Layout.of([], prob.exps[0].arrays.keys(), 1)
    fits = prob.fit([start], [None], bare)
    (model,), (pred,) = fits.models, fits.predictions
    residuals = tuple(e.y - p for e, p in zip(prob.exps, pred))
    return _Current(
        model,
        residuals,
        float(fits.ssr[0]),
        dof(model, prob.cal),
        fits.layout if layout is not None else None,
        layout_checked=False,
    )


def _null(prob: _Problem, cur: _Current) -> _Null:
    """Step 2: the effect-free records of the same set-up, the nominal model refitted on
    them, the noise floor and the evidence one sample of the noise carries."""
    n_null, n = prob.opts.n_null, prob.n_cal_exp
    prob.say(f"simulating {n_null} effect-free records of the same set-up (the null)")
    rng = np.random.default_rng(prob.opts.seed)
    sets = prob.family.null_experiments(cur.model, list(prob.exps), rng, n_null)
    bare = cur.layout or Layout.of([], prob.exps[0].arrays.keys(), 1)
    fits = prob.fit([cur.model] * n_null, [None] * n_null, bare, data=sets)
    res = [[e.y - p for e, p in zip(ns, pr)] for ns, pr in zip(sets, fits.predictions)]
    gaps = [_gap_rows(r[n:], ns[n:]) for r, ns in zip(res, sets)]
    floor = float(np.median(gaps))
    prob.say(f"noise floor (median gap of the nominal model on the null records): {floor:.4g}")
    # the evidence per sample of the noise: the effective share of independent samples in
    # the calibration residuals of the effect-free records (what the noise and the
    # set-up's filters leave, not what a missing effect leaves)
    share = noise_sample_share([r[:n] for r in res])
    return _Null(sets, res, list(fits.models), gaps, floor, share)


def _gap_rows(res: Sequence[np.ndarray], exps: Sequence[Experiment]) -> float:
    return nrmse(np.concatenate(list(res)), np.concatenate([e.y for e in exps]))


def _refreshed(refreshers, null_sets, null_res):
    """The null records with each refresh applied from the current model's residuals."""
    for refresh in refreshers:
        null_sets = [[refresh(e, r) for e, r in zip(ns, nr)] for ns, nr in zip(null_sets, null_res)]
    return null_sets


def _open_specs(prob: _Problem, candidates, accepted) -> list[EffectSpec]:
    """The candidates still to try: testable, not accepted, and neither a base whose
    extension is in nor a sibling of an accepted extension."""
    specs = prob.specs
    out = []
    for s in prob.library:
        if not candidates[s.name].testable or s.name in accepted:
            continue
        if s.extends is None and any(specs[a].extends == s.name for a in accepted):
            continue  # an extension of it is already in
        if s.extends is not None and any(specs[a].extends == s.extends for a in accepted):
            continue  # a sibling extension of the same base is already in
        out.append(s)
    return out


def _round_layout(prob: _Problem, cur: _Current, templates) -> _Current:
    """The one fixed structure for the rest of the search, built at the first round from
    the calibrated model's templates; an early layout of the same structure takes their
    defaults (one compilation for the whole search)."""
    if cur.layout is not None and cur.layout_checked:
        return cur
    fresh = Layout.of(
        [templates[s.name][0] for s in prob.library if templates.get(s.name)],
        prob.exps[0].arrays.keys(),
        max(len(t) for t in templates.values()),
    )
    if cur.layout is not None and same_structure(cur.layout, fresh):
        fresh = dataclasses.replace(cur.layout, defaults=fresh.defaults)
    return dataclasses.replace(cur, layout=fresh, layout_checked=True)


def _round(prob, cur, null, candidates, accepted, rnd):
    """Step 3: one round. Returns the refreshed problem, the current model (the accepted
    candidate's when one passes), the null, the round's history entry (`None` when no
    candidate is open) and the accepted candidate (or `None`). Adds the accepted
    effect to `accepted` and updates `candidates`."""
    # an accepted effect keeps the data it was accepted with: its events were found in the
    # residual without it, and the current residual no longer shows them
    refreshers = [
        s.refresh
        for s in prob.library
        if s.refresh and candidates[s.name].testable and s.name not in accepted
    ]
    exps = list(prob.exps)
    for refresh in refreshers:
        exps = [refresh(e, r) for e, r in zip(exps, cur.residuals)]
    prob = dataclasses.replace(prob, exps=tuple(exps))
    if not null.stale:
        null = dataclasses.replace(null, sets=_refreshed(refreshers, null.sets, null.residuals))
    open_specs = _open_specs(prob, candidates, accepted)
    if not open_specs:
        return prob, cur, null, None, None
    t_round = time.perf_counter()
    ctx = Context(cur.model, prob.cal, cur.residuals[: prob.n_cal_exp], prob.family.options)
    templates = {s.name: s.templates(ctx) for s in open_specs}
    cur = _round_layout(prob, cur, templates)
    trials: dict[str, Trial] = {}
    for s in open_specs:
        if not templates[s.name]:
            continue
        t0 = time.perf_counter()
        trial, signature, cur = _try(
            prob, cur, null.noise_share, s, templates[s.name], accepted, rnd
        )
        c = candidates[s.name]
        c.seconds += time.perf_counter() - t0
        c.signature = signature
        if trial is not None:
            c.record(trial, prob.y("cal"), prob.n_cal_exp)
            trials[s.name] = trial
    round_results = [candidates[n] for n in trials]
    null, cur = _null_test(prob, cur, null, refreshers, trials, candidates)
    entry = _history_entry(prob, cur, round_results, rnd, time.perf_counter() - t_round)
    passing = [c for c in round_results if c.rejected_by is None]
    if not passing:
        return prob, cur, null, entry, None
    chosen = choose(passing, accepted)
    _accept(chosen, candidates, accepted)
    trial = trials[chosen.effect]
    cur = _Current(trial.model, trial.residuals, trial.ssr, trial.dof, cur.layout, True)
    # the null records are refitted with this model when next needed
    null = dataclasses.replace(null, stale=True)
    prob.say(f"round {rnd}: accepted {chosen.effect} (validation gap {chosen.validation_gap:.4f})")
    return prob, cur, null, entry, chosen


def _try(
    prob: _Problem, cur: _Current, noise_share: float, spec: EffectSpec, templates, accepted, rnd
):
    """One candidate from its starting shapes, all in one call: the best admissible start
    by calibration cost (else the best, reported), its evidence against the current model
    and the first acceptance test it fails before the null. Returns the trial (`None`
    when no fit is finite), its signature and the current state (its layout widened)."""
    replaces = spec.extends if spec.extends in accepted else None
    starts = [cur.model.with_effect(t, replaces=replaces) for t in templates]
    prob.say(f"round {rnd}: {spec.name} from {len(starts)} starting point(s)")
    slot = len(starts[0].effects) - 1
    fits = prob.fit(starts, [slot] * len(starts), cur.layout)
    cur = dataclasses.replace(cur, layout=fits.layout)
    signature = max(0.0, 1.0 - float(np.min(fits.ssr_start)) / max(cur.ssr, 1e-300))
    verdicts = [
        next(e for e in m.effects if e.name == spec.name).admissible(prob.context)
        for m in fits.models
    ]
    order = np.argsort(fits.ssr)
    ok = [int(k) for k in order if verdicts[k][0] and np.isfinite(fits.ssr[k])]
    k = ok[0] if ok else int(order[0])
    if not np.isfinite(fits.ssr[k]):
        return None, signature, cur
    residuals = tuple(e.y - p for e, p in zip(prob.exps, fits.predictions[k]))
    n = prob.n_cal_exp
    dof_s = dof(starts[0], prob.cal)
    ev = compare(
        np.concatenate(cur.residuals[n:]),
        np.concatenate(residuals[n:]),
        prob.y("val"),
        (cur.ssr, cur.dof),
        (float(fits.ssr[k]), dof_s, np.concatenate(residuals[:n])),
        noise_share=noise_share,
        thresholds=prob.opts.thresholds,
        seed=prob.opts.seed + rnd,
    )
    why = rejection(ev, prob.opts.thresholds, admissible=verdicts[k])
    trial = Trial(
        spec.name, rnd, starts[k], slot, fits.models[k], residuals, float(fits.ssr[k]), dof_s,
        ev, verdicts[k], why,
    )  # fmt: skip
    return trial, signature, cur


def _null_test(prob, cur, null, refreshers, trials, candidates):
    """What every trial that passed the other tests gains, from the same start, on the
    null records (refitted with the current model first when an effect was accepted
    since); a trial must beat `null_threshold`. Returns the null and the current state
    (its layout widened)."""
    pending = [t for t in trials.values() if t.rejected_by is None]
    opts, n = prob.opts, prob.n_cal_exp
    if pending and null.stale:
        # the current model refitted on every null record, done only when a candidate of
        # this round reaches the null (the last round often rejects all before it)
        rnd = pending[0].round
        prob.say(f"round {rnd}: refitting the current model on the {opts.n_null} null records")
        fits = prob.fit([cur.model] * opts.n_null, [None] * opts.n_null, cur.layout, null.sets)
        cur = dataclasses.replace(cur, layout=fits.layout)
        res = [[e.y - p for e, p in zip(ns, pr)] for ns, pr in zip(null.sets, fits.predictions)]
        sets = _refreshed(refreshers, null.sets, res)
        null = dataclasses.replace(null, sets=sets, residuals=res, models=fits.models, stale=False)
    for trial in pending:
        c = candidates[trial.name]
        t0 = time.perf_counter()
        prob.say(f"round {trial.round}: {trial.name} on {opts.n_null} null records")
        starts = [
            GapModel(nm.nominal, tuple(_with_fit(e, f) for e, f in _zip_effects(trial.start, nm)))
            for nm in null.models
        ]
        fits = prob.fit(starts, [trial.slot] * opts.n_null, cur.layout, null.sets)
        cur = dataclasses.replace(cur, layout=fits.layout)
        gains = []
        for ns, nr, p in zip(null.sets, null.residuals, fits.predictions):
            after = [e.y - q for e, q in zip(ns, p)]
            gains.append(_gap_rows(nr[n:], ns[n:]) - _gap_rows(after[n:], ns[n:]))
        c.seconds += time.perf_counter() - t0
        c.null_p95 = _quantile(gains, opts.null_level)
        c.null_median = _quantile(gains, 0.5)
        c.null_threshold = null_threshold(gains, opts.null_level, len(trials))
        c.rejected_by = rejection(trial.evidence, opts.thresholds, null=c.null_threshold)
        if c.rejected_by is not None:
            c.rejected_by += f" (95th percentile {c.null_p95:.3g})"
    return null, cur


def _zip_effects(start: GapModel, fitted: GapModel):
    """Pairs of (effect of `start`, effect of the same name in `fitted` or None)."""
    by_name = {e.name: e for e in fitted.effects}
    return [(e, by_name.get(e.name)) for e in start.effects]


def _with_fit(effect, fitted):
    """The start's effect with the values fitted on a null record when there are some
    (the accepted effects), else the start's template (the candidate)."""
    return fitted if fitted is not None else effect


def _history_entry(prob, cur, round_results, rnd, seconds) -> dict[str, Any]:
    """The round as `report.json` shows it (`rounds[i]`)."""
    ordered = sorted(round_results, key=lambda c: -c.reduction)
    return {
        "round": rnd,
        "gap_before": prob.gap(cur.residuals),
        "seconds": seconds,
        "tried": {
            c.effect: {
                "validation_gap": c.validation_gap,
                "shrink": c.shrink,
                "delta_bic": c.delta_bic,
                "admissible": c.admissible,
                "reason": c.reason,
                "null_p95": c.null_p95,
                "null_threshold": c.null_threshold,
                "rejected_by": c.rejected_by,
                "passes": c.rejected_by is None,
                "parameters": dict(c.parameters),
            }
            for c in ordered
        },
    }


def _accept(chosen: CandidateResult, candidates, accepted: list[str]) -> None:
    """Add `chosen`: an extension that replaced its base counts the base's reduction as its
    own (both stay in the order of addition)."""
    chosen.accepted = True
    chosen.rejected_by = None
    chosen.explained = chosen.reduction
    if chosen.extends in accepted:
        base = candidates[chosen.extends]
        chosen.explained += base.explained
        base.explained = 0.0
    accepted.append(chosen.effect)


# ------------------------------------------------------------------------------ prune


def _prune(prob: _Problem, cur: _Current, accepted, candidates, noise_share, nominal_gap):
    """Step 4, backward elimination: every effect of the final model must pass the
    acceptance tests against the final model *without it* (recalibrated), not only against
    the model it was added to. The greedy order can admit an effect that stands in for a
    later one (an ambient temperature acting as a lag before the lag itself is in); once
    the later effect is in, the proxy no longer earns its place. While some effect fails,
    the one with the smallest held-out reduction is removed (with the base it had
    replaced) and the rest are tested again. The drop-one reduction of every effect kept
    becomes what it `explained` (the primary effect is the largest). Updates `accepted`
    and `candidates`; returns the final state and one record per test."""
    records: list[dict[str, Any]] = []
    specs = prob.specs
    if len(cur.model.effects) >= 2:
        prob.say("testing every accepted effect against the final model without it")
    while len(cur.model.effects) >= 2:
        tests = [_drop_one(prob, cur, eff, candidates, noise_share) for eff in cur.model.effects]
        records += [t[0] for t in tests]
        failing = [t for t in tests if t[0]["rejected_by"] is not None]
        if not failing:
            for rec, _ in tests:
                candidates[rec["effect"]].explained = rec["reduction"]
                base = specs[rec["effect"]].extends
                if base is not None and base in candidates:
                    candidates[base].explained = 0.0
            break
        rec, reduced = min(failing, key=lambda t: t[0]["reduction"])
        why = rec["rejected_by"]
        prob.say(
            f"removing {rec['effect']}: without it, the final model loses nothing it must "
            f"keep ({why})"
        )
        removed = [rec["effect"]]
        while specs[removed[-1]].extends in accepted:
            removed.append(specs[removed[-1]].extends)
        for name in removed:
            accepted.remove(name)
            c = candidates[name]
            c.accepted = False
            c.explained = 0.0
            c.rejected_by = f"removed after the search, tested against the final model: {why}"
        cur = reduced
    if len(cur.model.effects) == 1 and records:
        # one effect left: what it explains is its reduction of the nominal held-out gap
        candidates[cur.model.effects[0].name].explained = nominal_gap - prob.gap(cur.residuals)
    return cur, records


def _drop_one(prob: _Problem, cur: _Current, eff, candidates, noise_share: float):
    """The final model without `eff`, recalibrated, and the acceptance tests of `eff`
    against it. Returns the test's record and the state without the effect."""
    n = prob.n_cal_exp
    reduced = GapModel(cur.model.nominal, tuple(e for e in cur.model.effects if e is not eff))
    fits = prob.fit([reduced], [None], cur.layout)
    r_red = tuple(e.y - p for e, p in zip(prob.exps, fits.predictions[0]))
    fitted = fits.models[0]
    r_cal = np.concatenate(cur.residuals[:n])
    ev = compare(
        np.concatenate(r_red[n:]),
        np.concatenate(cur.residuals[n:]),
        prob.y("val"),
        (float(fits.ssr[0]), dof(fitted, prob.cal)),
        (float(np.sum(r_cal**2)), dof(cur.model, prob.cal), r_cal),
        noise_share=noise_share,
        thresholds=prob.opts.thresholds,
        seed=prob.opts.seed,
    )
    threshold = candidates[eff.name].null_threshold or 0.0
    why = rejection(ev, prob.opts.thresholds, null=threshold)
    record = {
        "effect": eff.name,
        "effects": list(cur.model.effect_names),
        "gap_without": ev.gap_before,
        "gap_with": ev.gap_after,
        "reduction": ev.reduction,
        "reduction_interval": list(ev.reduction_interval),
        "shrink": ev.shrink,
        "delta_bic": ev.delta_bic,
        "null_threshold": threshold,
        "kept": why is None,
        "rejected_by": why,
    }
    state = _Current(fitted, r_red, float(fits.ssr[0]), dof(fitted, prob.cal), fits.layout, True)
    return record, state
