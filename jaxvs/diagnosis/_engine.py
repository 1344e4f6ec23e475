"""Augment and recalibrate: the greedy search for the effects that close the gap.

1. The nominal model is recalibrated on the calibration experiments (Levenberg–Marquardt
   through `jaxvs.calibrate`), so ordinary parameter error is never taken for a missing
   effect.
2. Every testable candidate of the family's library is tried from its starting shapes:
   the parameters it is linear in are set by least squares against the current residual
   (a score test: the share of the residual the effect's regressors explain is its
   *signature*), the best shape is kept.
3. The best candidates by signature are added to the model one at a time and the whole
   model -- nominal and effect parameters together -- is recalibrated with LM.
4. A candidate is accepted when, on held-out experiments the calibration never saw, the
   gap reduction has a moving-block bootstrap interval excluding zero, ΔBIC > 10 on the
   calibration data, and it removes at least `min_shrink` of the gap. Among the accepted,
   a simpler effect goes before its own extension (Coulomb before Stribeck, the
   principle of marginality), otherwise the lowest held-out gap wins. Effects are added
   greedily until none passes.

All experiments of one role are padded to a common length and stacked, so that every
prediction, Jacobian and calibration is one vectorised call (one compilation per model
structure), with padded samples carrying zero weight.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from ..calibration import free_spec, lm_init, lm_running, lm_step, unwrap
from ._base import AbstractFamily, Context, EffectSpec, Experiment, GapModel
from ._stats import bic, block_length, gap_change_interval, nrmse

__all__ = ["CandidateResult", "SearchResult", "search"]


# ------------------------------------------------------------------------------ batching


def stack(experiments: Sequence[Experiment], scale: float) -> dict[str, jnp.ndarray]:
    """Pad experiments to a common length (edge values) and stack them; `"w"` holds the
    residual weight (`scale` on real samples, 0 on padding)."""
    n_max = max(e.n for e in experiments)
    keys = experiments[0].arrays.keys()
    out: dict[str, Any] = {}
    for k in keys:
        cols = [np.asarray(e.arrays[k], float) for e in experiments]
        if cols[0].ndim == 2:
            kmax = max(c.shape[1] for c in cols)
            cols = [np.pad(c, ((0, 0), (0, kmax - c.shape[1]))) for c in cols]
            cols = [np.pad(c, ((0, n_max - c.shape[0]), (0, 0))) for c in cols]
        else:
            cols = [np.pad(c, (0, n_max - c.size), mode="edge") for c in cols]
        out[k] = jnp.asarray(np.stack(cols))
    w = np.zeros((len(experiments), n_max))
    for i, e in enumerate(experiments):
        w[i, : e.n] = scale
    out["w"] = jnp.asarray(w)
    return out


def _model_inputs(batch):
    return {k: v for k, v in batch.items() if k != "w"}


def _unstack(values, experiments: Sequence[Experiment]) -> list[np.ndarray]:
    v = np.asarray(values)
    return [v[i, : e.n] for i, e in enumerate(experiments)]


def n_free(model: GapModel) -> int:
    """Free parameters of a model (nominal and effects)."""
    cm = model.constrained()
    leaves = jax.tree_util.tree_leaves(eqx.filter(cm, free_spec(cm)))
    return int(sum(np.size(x) for x in leaves))


def _dof(model: GapModel, experiments: Sequence[Experiment]) -> int:
    arrays = [e.arrays for e in experiments]
    return n_free(model) + sum(e.extra_dof(arrays) for e in model.effects)


def _stack_models(models: Sequence[GapModel]) -> GapModel:
    """Stack models of one structure along a new leading axis of every array leaf."""
    arrays = [eqx.filter(m, eqx.is_array) for m in models]
    static = eqx.filter(models[0], eqx.is_array, inverse=True)
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *arrays)
    return eqx.combine(stacked, static)


def _index_model(models: GapModel, i: int) -> GapModel:
    arrays, static = eqx.partition(models, eqx.is_array)
    return eqx.combine(jax.tree_util.tree_map(lambda x: x[i], arrays), static)


@eqx.filter_jit
def _fit_many(models: GapModel, psize, batch, wfit, max_steps: int):
    """For each stacked starting model (same structure, gated effects): least-squares
    values of the parameters selected by `psize` (the candidate's sizes, one one-hot
    column each), then LM on every free parameter (weights `wfit`: zero on held-out rows;
    switched-off effects have zero Jacobian columns and stay put). Returns the calibrated
    (constrained) models, the cost after LM and after the least-squares start, and the
    predictions on every row."""
    inputs = _model_inputs(batch)
    y = batch["y"]

    def one(model: GapModel, ps):
        spec = free_spec(model)
        params, static = eqx.partition(model, spec)
        flat, unravel = jax.flatten_util.ravel_pytree(params)

        def resid(theta):
            m = unwrap(eqx.combine(unravel(theta), static))
            return ((jax.vmap(m)(inputs) - y) * wfit).ravel()

        # least-squares start of the candidate's sizes (exact when it is linear in them)
        r0 = resid(flat)
        js = jax.vmap(lambda v: jax.jvp(resid, (flat,), (v,))[1])(ps.T)  # (s, N)
        norms = jnp.linalg.norm(js, axis=1)
        safe = jnp.where(norms > 0, norms, 1.0)
        jn = js / safe[:, None]
        gram = jn @ jn.T + 1e-10 * jnp.eye(jn.shape[0], dtype=jn.dtype)
        delta = -jnp.linalg.solve(gram, jn @ r0) / safe
        delta = jnp.where(jnp.all(jnp.isfinite(delta)), delta, 0.0)
        flat = flat + ps @ delta

        def evaluate(theta, args):
            r = resid(theta)
            jac = jax.jacfwd(resid)(theta)
            return 0.5 * jnp.dot(r, r), jac.T @ jac, jac.T @ r

        state = lm_init(evaluate, flat, None, 1e-8)
        cost_start = state.cost
        state = jax.lax.while_loop(
            lambda s: lm_running(s, max_steps),
            lambda s: lm_step(evaluate, lambda t: jnp.asarray(True), s, None, 1e-8),
            state,
        )
        final = eqx.combine(unravel(state.theta), static)
        pred = jax.vmap(unwrap(final))(inputs)
        return final, state.cost, cost_start, pred

    return eqx.filter_vmap(one)(models, psize)


def size_selector(model: GapModel, slot: int | None, width: int) -> np.ndarray:
    """One-hot columns selecting the `size` entries of effect `slot` in the flat vector of
    the model's free parameters (zero columns pad to `width`)."""
    cm = model.constrained()
    params, _ = eqx.partition(cm, free_spec(cm))
    marker = jax.tree_util.tree_map(jnp.zeros_like, params)
    n_all = int(jax.flatten_util.ravel_pytree(marker)[0].size)
    out = np.zeros((n_all, width))
    if slot is None or not hasattr(model.effects[slot], "size"):
        return out
    leaf = marker.effects[slot].size
    marker = eqx.tree_at(
        lambda m: m.effects[slot].size, marker, jnp.arange(1, leaf.size + 1, dtype=leaf.dtype)
    )
    flat = np.asarray(jax.flatten_util.ravel_pytree(marker)[0])
    for k in range(1, int(leaf.size) + 1):
        idx = np.flatnonzero(flat == k)
        if idx.size and k - 1 < width:
            out[idx[0], k - 1] = 1.0
    return out


def fit_many(
    models: Sequence[GapModel],
    slots: Sequence[int | None],
    experiments: Sequence[Experiment],
    n_cal: int,
    scale: float,
    max_steps: int,
) -> tuple[list[GapModel], np.ndarray, np.ndarray, list[list[np.ndarray]]]:
    """Calibrate several gated starting models of one structure on the first `n_cal`
    experiments in one vectorised call (the sizes of effect `slots[i]` of start `i` are
    first set by least squares). Returns the (physical) models, their calibration SSR
    after LM and at the least-squares start (the signature), and their predictions on
    every experiment."""
    batch = stack(experiments, scale)
    wfit = batch["w"].at[n_cal:].set(0.0)
    width = max(
        [
            int(np.size(m.effects[s].size))
            for m, s in zip(models, slots)
            if s is not None and hasattr(m.effects[s], "size")
        ]
        or [1]
    )
    psize = jnp.asarray(np.stack([size_selector(m, s, width) for m, s in zip(models, slots)]))
    stacked = _stack_models([m.constrained() for m in models])
    out, cost, cost_start, pred = _fit_many(stacked, psize, batch, wfit, max_steps)
    cost = np.asarray(cost) * 2.0 / scale**2
    cost = np.where(np.isfinite(cost), cost, np.inf)
    cost_start = np.asarray(cost_start) * 2.0 / scale**2
    cost_start = np.where(np.isfinite(cost_start), cost_start, np.inf)
    fitted = [unwrap(_index_model(out, i)) for i in range(len(models))]
    preds = [_unstack(np.asarray(pred)[i], experiments) for i in range(len(models))]
    return fitted, cost, cost_start, preds


# ------------------------------------------------------------------------------ results


@dataclasses.dataclass
class CandidateResult:
    """One candidate effect as it was last tried."""

    effect: str
    testable: bool
    reason: str | None = None
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
    physical: bool = True
    model: GapModel | None = None
    seconds: float = 0.0

    @property
    def passes(self) -> bool:
        return bool(self.accepted)


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


# ------------------------------------------------------------------------------ search


def _passes(c: CandidateResult, min_shrink: float, min_delta_bic: float) -> bool:
    return (
        c.physical
        and c.delta_bic is not None
        and c.delta_bic > min_delta_bic
        and c.reduction_interval is not None
        and c.reduction_interval[0] > 0
        and (c.shrink or 0.0) >= min_shrink
    )


def search(
    family: AbstractFamily,
    calibration: list[Experiment],
    validation: list[Experiment],
    *,
    max_effects: int = 3,
    max_steps: int = 40,
    min_shrink: float = 0.05,
    min_delta_bic: float = 10.0,
    n_boot: int = 300,
    seed: int = 0,
    stop_at_noise: float = 1.1,
    progress: Callable[[str], None] | None = None,
) -> SearchResult:
    """Nominal recalibration, then the greedy augment-and-recalibrate loop (module doc).

    The loop stops when no candidate passes, after `max_effects` effects, or when the
    validation gap is within `stop_at_noise` times the noise floor (nothing left to
    explain). A candidate with no evidence at all (ΔBIC ≤ 0) in one round is not tried in
    later rounds.

    Every effect of the library sits in one gated model (see `GapModel`), so that each
    round -- all candidates from all their starting shapes -- is one vectorised
    calibration with one compilation for the whole diagnosis.
    """
    say = progress or (lambda msg: None)
    y_all = np.concatenate([e.y for e in calibration])
    scale = 1.0 / max(float(np.sqrt(np.mean(y_all**2))), 1e-300)
    n_cal_exp = len(calibration)
    n_cal = int(sum(e.n for e in calibration))
    y_cal = np.concatenate([e.y for e in calibration])
    y_val = np.concatenate([e.y for e in validation])
    exps = list(calibration) + list(validation)
    noise_floor = float(
        np.sqrt(sum(e.noise_var * e.n for e in validation) / max(float(np.sum(y_val**2)), 1e-300))
    )

    library = family.library()
    specs = {s.name: s for s in library}
    candidates: dict[str, CandidateResult] = {}
    for s in library:
        reason = s.not_testable(exps)
        candidates[s.name] = CandidateResult(
            s.name, reason is None, reason, extends=s.extends, description=s.description
        )

    say("recalibrating the nominal model")
    (model,), cost, _, (pred,) = fit_many(
        [GapModel(family.nominal(calibration))], [None], exps, n_cal_exp, scale, max_steps
    )
    nominal_model = model
    res_all = [e.y - p for e, p in zip(exps, pred)]
    nominal_residuals = list(res_all)
    accepted: list[str] = []
    history: list[dict[str, Any]] = []
    round_residuals: list[list[np.ndarray]] = []

    dof0 = _dof(model, exps[:n_cal_exp])
    for rnd in range(1, max_effects + 1):
        ssr0 = float(cost[0])
        bic0 = bic(ssr0, n_cal, dof0)
        e_val0 = np.concatenate(res_all[n_cal_exp:])
        blen = block_length(e_val0)
        for s in library:
            if s.refresh is not None and candidates[s.name].testable:
                exps = [s.refresh(e, r) for e, r in zip(exps, res_all)]

        open_specs: list[EffectSpec] = []
        for s in library:
            if not candidates[s.name].testable or s.name in accepted:
                continue
            if s.extends is None and any(specs[a].extends == s.name for a in accepted):
                continue  # an extension of it is already in
            if s.extends is not None and any(specs[a].extends == s.extends for a in accepted):
                continue  # a sibling extension of the same base is already in
            prev = candidates[s.name]
            if prev.delta_bic is not None and prev.delta_bic <= 0 and s.extends is None:
                continue  # no evidence at all in an earlier round: not tried again
            open_specs.append(s)
        if not open_specs:
            break

        ctx = Context(model, exps[:n_cal_exp], res_all[:n_cal_exp], family.options)
        tried: list[tuple[EffectSpec, list[GapModel], np.ndarray, np.ndarray, list]] = []
        t_round = time.perf_counter()
        for s in open_specs:
            templates = s.templates(ctx)
            if not templates:
                continue
            replaces = s.extends if s.extends in accepted else None
            starts = [model.with_effect(t, replaces=replaces) for t in templates]
            t0 = time.perf_counter()
            say(f"round {rnd}: {s.name} from {len(starts)} starting point(s)")
            slot = len(starts[0].effects) - 1
            fitted, costs, starts_ssr, preds = fit_many(
                starts, [slot] * len(starts), exps, n_cal_exp, scale, max_steps
            )
            candidates[s.name].seconds += time.perf_counter() - t0
            # the structure (hence the parameter count) is that of the starting points
            dof_s = _dof(starts[0], exps[:n_cal_exp])
            tried.append((s, fitted, costs, starts_ssr, preds, dof_s))
        elapsed = time.perf_counter() - t_round

        round_results: list[CandidateResult] = []
        for s, fitted, costs, starts_ssr, preds, dof_s in tried:
            k = int(np.argmin(costs))
            m1, ssr1, pred1 = fitted[k], float(costs[k]), preds[k]
            c = candidates[s.name]
            c.signature = max(0.0, 1.0 - float(np.min(starts_ssr)) / max(ssr0, 1e-300))
            if not np.isfinite(ssr1):
                continue
            r1 = [e.y - p for e, p in zip(exps, pred1)]
            dbic = bic0 - bic(ssr1, n_cal, dof_s)
            g0, g1, shrink, d_int, s_int = gap_change_interval(
                e_val0,
                np.concatenate(r1[n_cal_exp:]),
                y_val,
                length=blen,
                n_boot=n_boot,
                seed=seed + rnd,
            )
            c.round = rnd
            c.calibration_gap = nrmse(np.concatenate(r1[:n_cal_exp]), y_cal)
            c.validation_gap = g1
            c.gap_before = g0
            c.shrink = shrink
            c.shrink_interval = s_int
            c.reduction_interval = d_int
            c.delta_bic = dbic
            eff = next(e for e in m1.effects if e.name == s.name)
            c.parameters = eff.parameters()
            c.physical = eff.physical()
            c.model = m1
            c._state = (r1, ssr1, dof_s)  # type: ignore[attr-defined]
            round_results.append(c)
        round_results.sort(key=lambda c: -(c.delta_bic or -np.inf))

        passing = [c for c in round_results if _passes(c, min_shrink, min_delta_bic)]
        round_residuals.append(list(res_all))
        history.append(
            {
                "round": rnd,
                "gap_before": nrmse(e_val0, y_val),
                "seconds": elapsed,
                "tried": {
                    c.effect: {
                        "validation_gap": c.validation_gap,
                        "shrink": c.shrink,
                        "delta_bic": c.delta_bic,
                        "physical": c.physical,
                        "passes": c in passing,
                    }
                    for c in round_results
                },
            }
        )
        if not passing:
            break
        names = {c.effect for c in passing}
        # marginality: a base before its extension when both pass; else the best ΔBIC
        eligible = [c for c in passing if not (c.extends in names and c.extends not in accepted)]
        chosen = max(eligible, key=lambda c: c.delta_bic)
        chosen.accepted = True
        accepted.append(chosen.effect)
        model = chosen.model
        res_all, ssr, dof0 = chosen._state  # type: ignore[attr-defined]
        cost = np.array([ssr])
        say(f"round {rnd}: accepted {chosen.effect} (validation gap {chosen.validation_gap:.4f})")
        if chosen.validation_gap <= stop_at_noise * noise_floor:
            say("the remaining gap is within the noise floor: stopping")
            break

    return SearchResult(
        nominal_model,
        model,
        accepted,
        candidates,
        history,
        scale,
        exps[:n_cal_exp],
        exps[n_cal_exp:],
        nominal_residuals,
        list(res_all),
        round_residuals,
    )
