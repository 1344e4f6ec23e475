"""Augment and recalibrate: the greedy search for the effects that close the gap.

1. The nominal model is recalibrated on the calibration experiments (Levenberg–Marquardt
   through the calibration kernel), so ordinary parameter error is never taken for a
   missing effect. A record that does not identify it gets no search at all
   (`family.identifiability`: the reason is reported instead of a verdict).
2. The null: `family.null_experiments` simulates K effect-free copies of the records
   from the calibrated model through the recorded set-up; the nominal model refitted on
   them gives the noise floor (the median of their held-out gaps).
3. Every testable candidate of the family's library is tried from its starting shapes:
   the parameters it is linear in are set by least squares against the current residual
   (the share of the residual this explains is its *signature*), then the whole model --
   nominal and effect parameters together -- is recalibrated with LM, all starts in one
   vectorised call. The best **admissible** start by calibration cost is kept
   (`effect.admissible`); an inadmissible best fit is reported, never accepted.
4. A candidate passes when, on held-out experiments the calibration never saw, its gap
   reduction has a moving-block bootstrap interval excluding zero, removes at least
   `min_shrink` of the gap, has ΔBIC > `min_delta_bic` with an effective sample size
   (that of the residual it leaves, never below that of the noise on the null records:
   a large effect partly explained leaves structure that must not discount its own
   evidence), and exceeds what the same candidate, from the same start, gains on the null records
   (`null_threshold`). Among those that pass, a base goes before its own extension
   (marginality), otherwise the largest held-out reduction wins. Effects are added
   greedily until none passes; the primary effect is the one that explains most of the
   held-out gap.

All experiments of one role are padded to a common length and stacked, so that every
prediction, Jacobian and calibration is one vectorised call (one compilation per model
structure), with padded samples carrying zero weight.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import scipy.stats

from ..calibration import free_spec, lm_init, lm_running, lm_step, unwrap
from ._base import AbstractFamily, Context, EffectSpec, Experiment, GapModel
from ._stats import (
    bic_effective,
    block_length,
    effective_samples,
    gap_change_interval,
    nrmse,
)

__all__ = ["CandidateResult", "SearchResult", "search"]


# ------------------------------------------------------------------------------ batching


def stack(experiments: Sequence[Experiment], scale: float) -> dict[str, np.ndarray]:
    """Pad experiments to a common length (edge values) and stack them; `"w"` holds the
    residual weight (`scale` on real samples, 0 on padding). NumPy arrays: the batches
    are cut and copied on the host, where no operation needs compiling."""
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
        out[k] = np.stack(cols)
    w = np.zeros((len(experiments), n_max))
    for i, e in enumerate(experiments):
        w[i, : e.n] = scale
    out["w"] = w
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
    # stacked on the host (an eager `jnp.stack` compiles once per shape)
    stacked = jax.tree_util.tree_map(
        lambda *xs: jnp.asarray(np.stack([np.asarray(x) for x in xs])), *arrays
    )
    return eqx.combine(stacked, static)


def fit_many(
    models: Sequence[GapModel],
    slots: Sequence[int | None],
    experiments: Sequence[Experiment] | Sequence[Sequence[Experiment]],
    n_cal: int,
    scale: float,
    max_steps: int,
    layout: Layout,
) -> tuple[list[GapModel], np.ndarray, np.ndarray, list[list[np.ndarray]]]:
    """Calibrate several starting models of one structure on the first `n_cal`
    experiments through the one fixed structure of `layout` (so the compiled function is
    shared with every other structure of the search); the sizes of effect `slots[i]` of
    start `i` are first set by least squares. `experiments` is one list of experiments
    for all the models, or one list per model (the null records: start `i` on data set
    `i`). Returns the (physical) models, their calibration SSR after LM and at the
    least-squares start (the signature), and their predictions on every experiment."""
    per_model = not isinstance(experiments[0], Experiment)
    if per_model:
        batches = [stack(list(e), scale) for e in experiments]
        batch = {k: np.stack([b[k] for b in batches]) for k in batches[0]}
        wfit = batch["w"].copy()
        wfit[:, n_cal:] = 0.0
        data_axis = 0
        exp_lists = [list(e) for e in experiments]
    else:
        batch = stack(experiments, scale)
        wfit = batch["w"].copy()
        wfit[n_cal:] = 0.0
        data_axis = None
        exp_lists = [list(experiments)] * len(models)
    if not layout.covers(models[0]) or not layout.keys <= set(batch):
        raise ValueError(
            f"fit_many: the layout has slots {layout.names} for data {sorted(layout.keys)}; "
            f"got effects {models[0].effect_names} and data {sorted(batch)}. Build the "
            "layout from the library and the refreshed experiments."
        )
    fitted, cost, cost_start, pred = _fit_layout(
        layout, models, slots, batch, wfit, max_steps, data_axis
    )
    cost = np.asarray(cost) * 2.0 / scale**2
    cost = np.where(np.isfinite(cost), cost, np.inf)
    cost_start = np.asarray(cost_start) * 2.0 / scale**2
    cost_start = np.where(np.isfinite(cost_start), cost_start, np.inf)
    fitted = [unwrap(m) for m in fitted]
    preds = [_unstack(np.asarray(pred)[i], exp_lists[i]) for i in range(len(fitted))]
    return fitted, cost, cost_start, preds


# ------------------------------------------------------------------------------ one structure


class Layout:
    """One fixed model structure for a whole search: the nominal model and one slot per
    effect of the family's library (in library order), each slot holding either an
    effect of the model being fitted or a default instance of the same shapes. Which
    slots act is an array (`active`), and the parameters calibrated are chosen by a
    selection matrix of fixed width, so every candidate of every round, and the null
    records, are calibrated by the same compiled function (one compilation per batch
    mode instead of one per candidate and round). Inactive slots are skipped by
    `lax.cond`, so they cost nothing at run time.

    `width` is the number of calibrated parameters the selection is padded to: it grows
    in steps of `granularity` when a model needs more (one more compilation)."""

    def __init__(self, defaults, keys, batch: int, granularity: int = 2):
        self.defaults = tuple(defaults)
        self.keys = frozenset(keys)  # the data every slot reads (refreshed experiments)
        self.names = tuple(e.name for e in self.defaults)
        self.batch = batch  # starts per call: every call has this many, padded or chunked
        self.granularity = granularity
        self.width = 0  # calibrated parameters per call, fixed at the first call

    def covers(self, model: GapModel) -> bool:
        return all(e.name in self.names for e in model.effects)

    def fixed(self, model: GapModel) -> tuple[_Fixed, np.ndarray]:
        by = {e.name: e for e in model.effects}
        effects = tuple(by.get(d.name, d.constrained()) for d in self.defaults)
        active = np.array([n in by for n in self.names])
        return _Fixed(model.nominal, effects), active

    def back(self, fixed: _Fixed, like: GapModel) -> GapModel:
        """The fitted fixed model as a `GapModel` with the effects of `like`, in its order."""
        slots = [self.names.index(e.name) for e in like.effects]
        return GapModel(fixed.nominal, tuple(fixed.effects[i] for i in slots))


class _Fixed(eqx.Module):
    """The nominal model and every slot of a [`Layout`][]; `active` picks the slots."""

    nominal: eqx.Module
    effects: tuple

    def __call__(self, arrays, active):
        y = self.nominal(arrays)
        order = sorted(range(len(self.effects)), key=lambda i: (self.effects[i].order, i))
        for i in order:
            eff = self.effects[i]
            y = jax.lax.cond(
                active[i],
                lambda y, eff=eff: eff.apply(y, arrays, self.nominal),
                lambda y: y,
                y,
            )
        return y


def _owners(cm) -> np.ndarray:
    """For every entry of the flat vector of free parameters of a constrained `_Fixed`
    model: 0 for the nominal model, `i + 1` for slot `i`."""
    params, _ = eqx.partition(cm, free_spec(cm))
    zeros = jax.tree_util.tree_map(jnp.zeros_like, params)
    n_all = int(jax.flatten_util.ravel_pytree(zeros)[0].size)
    owners = np.full(n_all, -1)
    getters = [lambda m: m.nominal] + [
        (lambda m, i=i: m.effects[i]) for i in range(len(cm.effects))
    ]
    for c, get in enumerate(getters):
        sub = get(zeros)
        if not jax.tree_util.tree_leaves(sub):
            continue
        marked = eqx.tree_at(get, zeros, jax.tree_util.tree_map(jnp.ones_like, sub))
        flat = np.asarray(jax.flatten_util.ravel_pytree(marked)[0])
        owners[flat == 1] = c
    return owners


@eqx.filter_jit
def _fit_fixed(arrays, static, active, sel, psize, batch, wfit, max_steps: int, data_axis):
    """[`_fit_many`][] for a [`Layout`][]: the starts' arrays (`arrays`, stacked) share
    `static`, the slots `active` and the selection `sel` (free entries calibrated, zero
    columns pad it to a fixed width)."""

    def one(arr, ps, batch, wfit):
        model = eqx.combine(arr, static)
        inputs = _model_inputs(batch)
        y = batch["y"]
        spec = free_spec(model)
        params, pstatic = eqx.partition(model, spec)
        flat, unravel = jax.flatten_util.ravel_pytree(params)

        def full(theta_full):
            m = unwrap(eqx.combine(unravel(theta_full), pstatic))
            return ((jax.vmap(lambda a: m(a, active))(inputs) - y) * wfit).ravel()

        def linear(flat_k):
            """The residual at `flat_k` and its Jacobian in the calibrated entries."""
            base_k = flat_k - sel @ (sel.T @ flat_k)

            def twice(theta):
                r = full(base_k + sel @ theta)
                return r, r

            jac, r = jax.jacfwd(twice, has_aux=True)(sel.T @ flat_k)
            return r, jac

        def sized(k, carry):
            # k = 0: the sizes of the start's effect by least squares from the columns of
            # the Jacobian they own (`ps` selects calibrated entries); k = 1: the residual
            # and Jacobian there, the Levenberg-Marquardt start. One loop body, so the
            # model's derivative is compiled once for both points
            flat_k, _, _ = carry
            r, jac = linear(flat_k)
            js = (jac @ (sel.T @ ps)).T  # (s, N)
            norms = jnp.linalg.norm(js, axis=1)
            safe = jnp.where(norms > 0, norms, 1.0)
            jn = js / safe[:, None]
            gram = jn @ jn.T + 1e-10 * jnp.eye(jn.shape[0], dtype=jn.dtype)
            delta = -jnp.linalg.solve(gram, jn @ r) / safe
            delta = jnp.where(jnp.all(jnp.isfinite(delta)), delta, 0.0)
            return jnp.where(k == 0, flat_k + ps @ delta, flat_k), r, jac

        n_res = y.size
        carry = (flat, jnp.zeros((n_res,), flat.dtype), jnp.zeros((n_res, sel.shape[1])))
        flat, r1, jac1 = jax.lax.fori_loop(0, 2, sized, carry)
        base = flat - sel @ (sel.T @ flat)

        def resid(theta):
            return full(base + sel @ theta)

        def evaluate(theta, args):
            r = resid(theta)
            jac = jax.jacfwd(resid)(theta)
            return 0.5 * jnp.dot(r, r), jac.T @ jac, jac.T @ r

        start = (0.5 * jnp.dot(r1, r1), jac1.T @ jac1, jac1.T @ r1)
        state = lm_init(lambda theta, args: start, sel.T @ flat, None, 1e-8)
        cost_start = state.cost
        state = jax.lax.while_loop(
            lambda s: lm_running(s, max_steps),
            lambda s: lm_step(evaluate, lambda t: jnp.asarray(True), s, None, 1e-8),
            state,
        )
        final = eqx.combine(unravel(base + sel @ state.theta), pstatic)
        pred = jax.vmap(lambda a: unwrap(final)(a, active))(inputs)
        return eqx.filter(final, eqx.is_array), state.cost, cost_start, pred

    return jax.vmap(one, in_axes=(0, 0, data_axis, data_axis))(arrays, psize, batch, wfit)


def _fit_layout(layout: Layout, models, slots, batch, wfit, max_steps, data_axis):
    """Calibrate `models` (one structure) through the layout's fixed structure, in calls
    of exactly `layout.batch` starts (the last padded by repeating the first start), each
    start on its own copy of the data."""
    count = len(models)
    fixed = [layout.fixed(m.constrained()) for m in models]
    active = fixed[0][1]
    cms = [f for f, _ in fixed]
    owners = _owners(cms[0])
    chosen = np.flatnonzero((owners == 0) | np.isin(owners - 1, np.flatnonzero(active)))
    if not layout.width:
        # room for the nominal model and the two largest slots from the start (one more
        # compilation only when a model outgrows it)
        counts = sorted(int(np.sum(owners == i + 1)) for i in range(len(layout.names)))
        layout.width = int(np.sum(owners == 0)) + sum(counts[-2:])
    g = layout.granularity
    layout.width = max(layout.width, chosen.size)
    width = int(np.ceil(layout.width / g)) * g
    sel = np.zeros((owners.size, width))
    sel[chosen, np.arange(chosen.size)] = 1.0
    size_width = max([int(np.size(d.size)) for d in layout.defaults if hasattr(d, "size")] or [1])
    psize = []
    for f, (m, s) in zip(cms, zip(models, slots)):
        slot = None if s is None else layout.names.index(m.effects[s].name)
        psize.append(_fixed_size_selector(f, slot, size_width))
    # the data of each call on the host (NumPy: cutting and copying compile nothing)
    batch = {k: np.asarray(v) for k, v in batch.items()}
    wfit = np.asarray(wfit)
    if data_axis is None:  # every start sees the same data: one copy per start
        batch = {k: np.broadcast_to(v, (count,) + v.shape) for k, v in batch.items()}
        wfit = np.broadcast_to(wfit, (count,) + wfit.shape)
    # calls of exactly `layout.batch` starts (the last one padded): one compiled function
    b = layout.batch
    n_pad = -count % b
    idx = np.concatenate([np.arange(count), np.zeros(n_pad, int)])
    cms = [cms[i] for i in idx]
    psize = np.stack([psize[i] for i in idx])
    active_j, sel_j = jnp.asarray(active), jnp.asarray(sel)
    outs = []
    static = None
    for c0 in range(0, idx.size, b):
        part = idx[c0 : c0 + b]
        arrays, static = eqx.partition(_stack_models(cms[c0 : c0 + b]), eqx.is_array)
        take = lambda x: jnp.asarray(x[part])  # noqa: E731
        outs.append(
            _fit_fixed(
                arrays,
                static,
                active_j,
                sel_j,
                jnp.asarray(psize[c0 : c0 + b]),
                jax.tree_util.tree_map(take, batch),
                take(wfit),
                max_steps,
                0,
            )
        )
    out, cost, cost_start, pred = jax.tree_util.tree_map(
        lambda *xs: np.concatenate([np.asarray(x) for x in xs])[:count], *outs
    )
    fitted = []
    for i in range(count):
        arr_i = jax.tree_util.tree_map(lambda x: jnp.asarray(x[i]), out)
        fitted.append(layout.back(eqx.combine(arr_i, static), models[i]))
    return fitted, cost, cost_start, pred


def _fixed_size_selector(cm: _Fixed, slot: int | None, width: int) -> np.ndarray:
    params, _ = eqx.partition(cm, free_spec(cm))
    marker = jax.tree_util.tree_map(jnp.zeros_like, params)
    n_all = int(jax.flatten_util.ravel_pytree(marker)[0].size)
    out = np.zeros((n_all, width))
    if slot is None or not hasattr(cm.effects[slot], "size"):
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


# ------------------------------------------------------------------------------ results


@dataclasses.dataclass
class CandidateResult:
    """One candidate effect as it was last tried."""

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


# ------------------------------------------------------------------------------ search


def _first_failure(c: CandidateResult, min_shrink: float, min_delta_bic: float) -> str | None:
    """The first acceptance test (before the null) a tried candidate fails, or None."""
    if not c.admissible:
        return f"inadmissible: {c.reason}"
    if c.reduction_interval is None or not c.reduction_interval[0] > 0:
        return "held-out reduction not significant (bootstrap interval includes zero)"
    if (c.shrink or 0.0) < min_shrink:
        return f"shrink below {min_shrink:g}"
    if c.delta_bic is None or not c.delta_bic > min_delta_bic:
        return f"ΔBIC (effective sample size) not above {min_delta_bic:g}"
    return None


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


def null_threshold(gains: Sequence[float], level: float, tested: int) -> float:
    """The held-out reduction a candidate must exceed: the `level` quantile of its gains on
    the null records, and, since several candidates face the null in one round, at
    least the normal tail quantile `mean + z·sd` at level `1 − (1 − level)/tested`
    (Bonferroni across the candidates tested; the few null records cannot resolve that
    tail empirically).

    A loss on a null record (a fit that made its held-out gap worse, e.g. one stuck in a
    local minimum away from the effect-free model) counts as no gain: such a fit is never
    accepted, so it is no false discovery, and its size must not widen the normal tail
    the candidate has to beat."""
    g = np.maximum(np.asarray([v for v in gains if np.isfinite(v)], float), 0.0)
    if g.size < 2:
        return float("inf")
    alpha = (1.0 - level) / max(int(tested), 1)
    z = float(scipy.stats.norm.ppf(1.0 - alpha))
    return max(float(np.quantile(g, level)), float(g.mean() + z * g.std(ddof=1)))


def noise_sample_share(null_residuals: Sequence[Sequence[np.ndarray]]) -> float:
    """The median share `N_eff / N` of independent samples in the residuals of the
    effect-free records (each record's experiments concatenated): the evidence one sample
    of the noise carries after the set-up's filters and loop. 0 without null records."""
    shares = []
    for rows in null_residuals:
        e = np.concatenate([np.asarray(r, float) for r in rows])
        if e.size >= 4:
            shares.append(effective_samples(e) / e.size)
    return float(np.median(shares)) if shares else 0.0


def evidence_samples(residual: np.ndarray, noise_share: float) -> float:
    """The effective sample size of the ΔBIC: that of the residual left by the model
    under test, but never below what the noise alone carries (`noise_share · N`, from the
    effect-free records). A candidate that removes a large share of a gap far above the
    floor leaves structure behind; that structure must not make its evidence smaller
    than that of a small effect leaving white noise."""
    n = np.size(residual)
    return float(max(effective_samples(residual), noise_share * n))


def _nrmse_rows(res: Sequence[np.ndarray], exps: Sequence[Experiment]) -> float:
    return nrmse(np.concatenate(list(res)), np.concatenate([e.y for e in exps]))


def _quantile(x: Sequence[float], q: float) -> float:
    x = np.asarray([v for v in x if np.isfinite(v)], float)
    return float(np.quantile(x, q)) if x.size else float("inf")


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
    n_null: int = 19,
    null_level: float = 0.95,
    seed: int = 0,
    stop_at_noise: float = 1.1,
    progress: Callable[[str], None] | None = None,
    initial: Any = None,
) -> SearchResult:
    """Nominal recalibration, the identifiability check, the null, then the greedy
    augment-and-recalibrate loop (module doc).

    A candidate is accepted when its best admissible fit passes every test: held-out
    reduction with a block-bootstrap interval above zero, shrink ≥ `min_shrink`, ΔBIC
    with the residual's effective sample size above `min_delta_bic`, and a held-out
    reduction above the `null_level` quantile of what the same candidate gains on
    `n_null` effect-free records of the same set-up (`family.null_experiments`). Among
    the accepted, a base goes before its extension (marginality), otherwise the largest
    held-out reduction wins. The loop stops when no candidate passes, after
    `max_effects` effects, or when the validation gap is within `stop_at_noise` times
    the null's noise floor. Every open candidate is tried in every round, also one whose
    fit made the held-out gap worse before: the residual it is fitted to changes with
    each accepted effect (a delay fitted beside unmodelled friction imitates the
    friction, and is only judged fairly once the friction is in the model).
    `initial`: the nominal model's start `family.nominal(calibration)` when the caller
    has it already (`jaxvs check` fits it on the same experiments).
    """
    say = progress or (lambda msg: None)
    rng = np.random.default_rng(seed)
    y_all = np.concatenate([e.y for e in calibration])
    scale = 1.0 / max(float(np.sqrt(np.mean(y_all**2))), 1e-300)
    n_cal_exp = len(calibration)
    n_cal = int(sum(e.n for e in calibration))
    y_cal = np.concatenate([e.y for e in calibration])
    y_val = np.concatenate([e.y for e in validation])
    exps = list(calibration) + list(validation)

    library = family.library()
    specs = {s.name: s for s in library}
    candidates: dict[str, CandidateResult] = {}
    for s in library:
        reason = s.not_testable(exps)
        candidates[s.name] = CandidateResult(
            s.name, reason is None, reason, extends=s.extends, description=s.description
        )

    say("recalibrating the nominal model")
    start = GapModel(family.nominal(calibration) if initial is None else initial)
    # the nominal model through the search's own structure when the family can say it
    # before the calibration (one compilation for the whole search), else a layout
    # without slots (one call per start)
    layout = _early_layout(family, library, candidates, start, exps, n_cal_exp)
    bare = layout or Layout([], exps[0].arrays.keys(), batch=1)
    (model,), cost, _, (pred,) = fit_many([start], [None], exps, n_cal_exp, scale, max_steps, bare)
    nominal_model = model
    res_all = [e.y - p for e, p in zip(exps, pred)]
    nominal_residuals = list(res_all)

    def result(**kw) -> SearchResult:
        base = dict(
            nominal=nominal_model,
            final=model,
            accepted=accepted,
            candidates=candidates,
            history=history,
            scale=scale,
            calibration=exps[:n_cal_exp],
            validation=exps[n_cal_exp:],
            nominal_residuals=nominal_residuals,
            final_residuals=list(res_all),
            round_residuals=round_residuals,
        )
        base.update(kw)
        return SearchResult(**base)

    accepted: list[str] = []
    history: list[dict[str, Any]] = []
    round_residuals: list[list[np.ndarray]] = []

    why = family.identifiability(exps[:n_cal_exp], model)
    if why is not None:
        say(f"not identifiable: {why}")
        return result(not_identifiable=why)
    context = family.admissibility_context(exps[:n_cal_exp], model)

    say(f"simulating {n_null} effect-free records of the same set-up (the null)")
    null_sets = family.null_experiments(model, exps, rng, n_null)
    null_fit, _, _, null_pred = fit_many(
        [model] * n_null, [None] * n_null, null_sets, n_cal_exp, scale, max_steps, bare
    )
    null_res = [[e.y - p for e, p in zip(ns, pr)] for ns, pr in zip(null_sets, null_pred)]
    null_gaps = [_nrmse_rows(r[n_cal_exp:], ns[n_cal_exp:]) for r, ns in zip(null_res, null_sets)]
    noise_floor = float(np.median(null_gaps))
    null_models = list(null_fit)
    # the evidence per sample of the noise: the effective share of independent samples in
    # the calibration residuals of the effect-free records (what the noise and the
    # set-up's filters leave, not what a missing effect leaves)
    noise_share = noise_sample_share([r[:n_cal_exp] for r in null_res])
    say(f"noise floor (median gap of the nominal model on the null records): {noise_floor:.4g}")

    dof0 = _dof(model, exps[:n_cal_exp])
    early = layout is not None
    null_stale = False
    for rnd in range(1, max_effects + 1):
        ssr0 = float(cost[0])
        e_val0 = np.concatenate(res_all[n_cal_exp:])
        blen = block_length(e_val0)
        # an accepted effect keeps the data it was accepted with: its events were found in
        # the residual without it, and the current residual no longer shows them
        refreshers = [
            s.refresh
            for s in library
            if s.refresh and candidates[s.name].testable and s.name not in accepted
        ]
        for refresh in refreshers:
            exps = [refresh(e, r) for e, r in zip(exps, res_all)]
        if not null_stale:
            null_sets = _refreshed(refreshers, null_sets, null_res)

        open_specs: list[EffectSpec] = []
        for s in library:
            if not candidates[s.name].testable or s.name in accepted:
                continue
            if s.extends is None and any(specs[a].extends == s.name for a in accepted):
                continue  # an extension of it is already in
            if s.extends is not None and any(specs[a].extends == s.extends for a in accepted):
                continue  # a sibling extension of the same base is already in
            open_specs.append(s)
        if not open_specs:
            break

        ctx = Context(model, exps[:n_cal_exp], res_all[:n_cal_exp], family.options)
        t_round = time.perf_counter()
        round_results: list[CandidateResult] = []
        all_templates = {s.name: s.templates(ctx) for s in open_specs}
        if layout is None or early:
            # one fixed structure for the rest of the search (Layout); the early one when
            # the calibrated model's templates have its structure (they take its place)
            fresh = Layout(
                [all_templates[s.name][0] for s in library if all_templates.get(s.name)],
                exps[0].arrays.keys(),
                batch=max(len(t) for t in all_templates.values()),
            )
            if layout is not None and _same_structure(layout, fresh):
                layout.defaults = fresh.defaults
            else:
                layout = fresh
            early = False
        for s in open_specs:
            templates = all_templates[s.name]
            if not templates:
                continue
            replaces = s.extends if s.extends in accepted else None
            starts = [model.with_effect(t, replaces=replaces) for t in templates]
            t0 = time.perf_counter()
            say(f"round {rnd}: {s.name} from {len(starts)} starting point(s)")
            slot = len(starts[0].effects) - 1
            fitted, costs, starts_ssr, preds = fit_many(
                starts, [slot] * len(starts), exps, n_cal_exp, scale, max_steps, layout
            )
            c = candidates[s.name]
            c.seconds += time.perf_counter() - t0
            c.signature = max(0.0, 1.0 - float(np.min(starts_ssr)) / max(ssr0, 1e-300))
            # the best admissible start by calibration cost; else the best, reported
            verdicts = []
            for m in fitted:
                eff = next(e for e in m.effects if e.name == s.name)
                verdicts.append(eff.admissible(context))
            order = np.argsort(costs)
            ok = [int(k) for k in order if verdicts[k][0] and np.isfinite(costs[k])]
            k = ok[0] if ok else int(order[0])
            m1, ssr1, pred1 = fitted[k], float(costs[k]), preds[k]
            if not np.isfinite(ssr1):
                continue
            dof_s = _dof(starts[0], exps[:n_cal_exp])
            r1 = [e.y - p for e, p in zip(exps, pred1)]
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
            # effective sample size: the candidate's own residual is what is left under the
            # alternative, but when the candidate removes only part of a large gap, what is
            # left is still structured and its correlation time would discount real
            # evidence the more, the larger the gap; the noise's own correlation (the null
            # records') bounds it from below. The held-out bootstrap and the null decide;
            # ΔBIC guards the complexity
            n_eff = evidence_samples(np.concatenate(r1[:n_cal_exp]), noise_share)
            c.delta_bic = bic_effective(ssr0, n_cal, dof0, n_eff) - bic_effective(
                ssr1, n_cal, dof_s, n_eff
            )
            eff = next(e for e in m1.effects if e.name == s.name)
            c.parameters = eff.parameters()
            c.admissible, why_not = verdicts[k]
            c.reason = why_not
            c.null_p95 = c.null_median = c.null_threshold = None
            c.model = m1
            c._state = (r1, ssr1, dof_s, starts[k], slot)  # type: ignore[attr-defined]
            c.rejected_by = _first_failure(c, min_shrink, min_delta_bic)
            round_results.append(c)

        # the null: what each remaining candidate gains, from the same start, on the
        # effect-free records (fitted after the current model has been refitted there)
        pending = [c for c in round_results if c.rejected_by is None]
        if pending and null_stale:
            # the current model refitted on every null record, done only when a candidate
            # of this round reaches the null (the last round often rejects all before it)
            say(f"round {rnd}: refitting the current model on the {n_null} null records")
            null_models, _, _, null_pred = fit_many(
                [model] * n_null, [None] * n_null, null_sets, n_cal_exp, scale, max_steps, layout
            )
            null_res = [[e.y - p for e, p in zip(ns, pr)] for ns, pr in zip(null_sets, null_pred)]
            null_sets = _refreshed(refreshers, null_sets, null_res)
            null_stale = False
        for c in pending:
            _, _, _, start, slot = c._state  # type: ignore[attr-defined]
            t0 = time.perf_counter()
            say(f"round {rnd}: {c.effect} on {n_null} null records")
            null_starts = [
                eqx.tree_at(lambda m: m.nominal, start, nm.nominal) for nm in null_models
            ]
            null_starts = [
                GapModel(ns.nominal, tuple(_with_fit(e, nm) for e, nm in zip_effects(ns, nm)))
                for ns, nm in zip(null_starts, null_models)
            ]
            _, _, _, pr1 = fit_many(
                null_starts, [slot] * n_null, null_sets, n_cal_exp, scale, max_steps, layout
            )
            gains = []
            for ns, nr, p in zip(null_sets, null_res, pr1):
                before = _nrmse_rows(nr[n_cal_exp:], ns[n_cal_exp:])
                after = _nrmse_rows([e.y - q for e, q in zip(ns, p)][n_cal_exp:], ns[n_cal_exp:])
                gains.append(before - after)
            c.seconds += time.perf_counter() - t0
            c.null_p95 = _quantile(gains, null_level)
            c.null_median = _quantile(gains, 0.5)
            c.null_threshold = null_threshold(gains, null_level, len(round_results))
            if not c.reduction > c.null_threshold:
                c.rejected_by = (
                    f"held-out reduction {c.reduction:.3g} not above the null threshold "
                    f"{c.null_threshold:.3g} (95th percentile {c.null_p95:.3g})"
                )
        elapsed = time.perf_counter() - t_round

        passing = [c for c in round_results if c.rejected_by is None]
        round_results.sort(key=lambda c: -c.reduction)
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
                        "admissible": c.admissible,
                        "reason": c.reason,
                        "null_p95": c.null_p95,
                        "null_threshold": c.null_threshold,
                        "rejected_by": c.rejected_by,
                        "passes": c in passing,
                        "parameters": dict(c.parameters),
                    }
                    for c in round_results
                },
            }
        )
        if not passing:
            break
        chosen = choose(passing, accepted)
        chosen.accepted = True
        chosen.rejected_by = None
        chosen.explained = chosen.reduction
        if chosen.extends in accepted:
            # the extension replaced its base in the model; both stay in the order of
            # addition, and the extension counts the base's reduction as its own
            base = candidates[chosen.extends]
            chosen.explained += base.explained
            base.explained = 0.0
        accepted.append(chosen.effect)
        model = chosen.model
        res_all, ssr, dof0, _, _ = chosen._state  # type: ignore[attr-defined]
        cost = np.array([ssr])
        null_stale = True  # the null records are refitted with this model when next needed
        say(f"round {rnd}: accepted {chosen.effect} (validation gap {chosen.validation_gap:.4f})")
        if chosen.validation_gap <= stop_at_noise * noise_floor:
            say("the remaining gap is within the noise floor: stopping")
            break

    model, res_all, pruning = _prune(
        model,
        res_all,
        exps,
        n_cal_exp,
        scale,
        max_steps,
        layout,
        accepted,
        candidates,
        specs,
        nominal_residuals,
        noise_share=noise_share,
        min_shrink=min_shrink,
        min_delta_bic=min_delta_bic,
        n_boot=n_boot,
        seed=seed,
        say=say,
    )
    primary = primary_effect(accepted, candidates)
    return result(noise_floor=noise_floor, null_gaps=null_gaps, primary=primary, pruning=pruning)


def _early_layout(family, library, candidates, start, exps, n_cal_exp) -> Layout | None:
    """The search's [`Layout`][] before the nominal calibration, from the templates of the
    uncalibrated start, for a family that says its templates' structure does not depend
    on the calibration (`family.early_layout`) and a library that refreshes no data; the
    first round checks the structure and puts its own templates in. `None` otherwise."""
    if not family.early_layout or any(s.refresh for s in library):
        return None
    cal = exps[:n_cal_exp]
    ctx = Context(start, cal, [e.y for e in cal], family.options)
    templates = {s.name: s.templates(ctx) for s in library if candidates[s.name].testable}
    defaults = [templates[s.name][0] for s in library if templates.get(s.name)]
    if not defaults:
        return None
    return Layout(defaults, exps[0].arrays.keys(), batch=max(len(t) for t in templates.values()))


def _same_structure(a: Layout, b: Layout) -> bool:
    """Whether two layouts compile to the same function: slots, batch, data and, slot by
    slot, the same tree, static fields, shapes and dtypes."""
    if (a.names, a.batch, a.keys) != (b.names, b.batch, b.keys):
        return False

    def signature(effect):
        tree = effect.constrained()
        leaves = jax.tree_util.tree_leaves(tree)
        return jax.tree_util.tree_structure(tree), [
            (jnp.shape(v), jnp.result_type(v)) for v in leaves
        ]

    return all(signature(x) == signature(y) for x, y in zip(a.defaults, b.defaults))


def _refreshed(refreshers, null_sets, null_res):
    """The null records with each refresh applied from the current model's residuals."""
    for refresh in refreshers:
        null_sets = [[refresh(e, r) for e, r in zip(ns, nr)] for ns, nr in zip(null_sets, null_res)]
    return null_sets


def _prune(
    model: GapModel,
    res_all: list[np.ndarray],
    exps: list[Experiment],
    n_cal_exp: int,
    scale: float,
    max_steps: int,
    layout: Layout | None,
    accepted: list[str],
    candidates: dict[str, CandidateResult],
    specs: Mapping[str, EffectSpec],
    nominal_residuals: Sequence[np.ndarray],
    *,
    noise_share: float,
    min_shrink: float,
    min_delta_bic: float,
    n_boot: int,
    seed: int,
    say: Callable[[str], None],
) -> tuple[GapModel, list[np.ndarray], list[dict[str, Any]]]:
    """Backward elimination after the greedy search: every effect of the final model must
    pass the acceptance tests against the final model *without it* (recalibrated), not only
    against the model it was added to. The greedy order can admit an effect that stands in
    for a later one (an ambient temperature acting as a lag before the lag itself is in);
    once the later effect is in, the proxy no longer earns its place. While some effect
    fails, the one with the smallest held-out reduction is removed (with the base it had
    replaced) and the rest are tested again. The drop-one reduction of every effect kept
    becomes what it `explained` (the primary effect is the largest). Mutates `accepted`
    and `candidates`; returns the model, its residuals and one record per test."""
    y_val = np.concatenate([e.y for e in exps[n_cal_exp:]])
    n_cal = int(sum(e.n for e in exps[:n_cal_exp]))
    records: list[dict[str, Any]] = []
    if len(model.effects) >= 2:
        say("testing every accepted effect against the final model without it")
    while len(model.effects) >= 2:
        e_full = np.concatenate(res_all[n_cal_exp:])
        r_cal = np.concatenate(res_all[:n_cal_exp])
        ssr_full = float(np.sum(r_cal**2))
        dof_full = _dof(model, exps[:n_cal_exp])
        n_eff = evidence_samples(r_cal, noise_share)
        tests = []
        for eff in model.effects:
            reduced = GapModel(model.nominal, tuple(e for e in model.effects if e is not eff))
            (fitted,), (ssr_red,), _, (pred,) = fit_many(
                [reduced], [None], exps, n_cal_exp, scale, max_steps, layout
            )
            r_red = [e.y - p for e, p in zip(exps, pred)]
            e_red = np.concatenate(r_red[n_cal_exp:])
            g0, g1, shrink, d_int, _ = gap_change_interval(
                e_red, e_full, y_val, length=block_length(e_red), n_boot=n_boot, seed=seed
            )
            dbic = bic_effective(float(ssr_red), n_cal, _dof(fitted, exps[:n_cal_exp]), n_eff) - (
                bic_effective(ssr_full, n_cal, dof_full, n_eff)
            )
            threshold = candidates[eff.name].null_threshold or 0.0
            reduction = g0 - g1
            why = None
            if not (d_int[0] > 0):
                why = "held-out reduction not significant (bootstrap interval includes zero)"
            elif shrink < min_shrink:
                why = f"shrink below {min_shrink:g}"
            elif not dbic > min_delta_bic:
                why = f"ΔBIC (effective sample size) not above {min_delta_bic:g}"
            elif not reduction > threshold:
                why = (
                    f"held-out reduction {reduction:.3g} not above its null threshold "
                    f"{threshold:.3g}"
                )
            tests.append((eff.name, reduction, why, fitted, r_red))
            records.append(
                {
                    "effect": eff.name,
                    "effects": list(model.effect_names),
                    "gap_without": g0,
                    "gap_with": g1,
                    "reduction": reduction,
                    "reduction_interval": list(d_int),
                    "shrink": shrink,
                    "delta_bic": dbic,
                    "null_threshold": threshold,
                    "kept": why is None,
                    "rejected_by": why,
                }
            )
        failing = [t for t in tests if t[2] is not None]
        if not failing:
            for name, reduction, _, _, _ in tests:
                candidates[name].explained = reduction
                base = specs[name].extends
                if base is not None and base in candidates:
                    candidates[base].explained = 0.0
            break
        name, _, why, fitted, r_red = min(failing, key=lambda t: t[1])
        say(f"removing {name}: without it, the final model loses nothing it must keep ({why})")
        removed = [name]
        while specs[removed[-1]].extends in accepted:
            removed.append(specs[removed[-1]].extends)
        for n in removed:
            accepted.remove(n)
            c = candidates[n]
            c.accepted = False
            c.explained = 0.0
            c.rejected_by = f"removed after the search, tested against the final model: {why}"
        model, res_all = fitted, r_red
    if len(model.effects) == 1 and records:
        # one effect left: what it explains is its reduction of the nominal held-out gap
        g_nom = nrmse(np.concatenate(list(nominal_residuals[n_cal_exp:])), y_val)
        g_fin = nrmse(np.concatenate(res_all[n_cal_exp:]), y_val)
        candidates[model.effects[0].name].explained = g_nom - g_fin
    return model, res_all, records


def zip_effects(start: GapModel, fitted: GapModel):
    """Pairs of (effect of `start`, effect of the same name in `fitted` or None)."""
    by_name = {e.name: e for e in fitted.effects}
    return [(e, by_name.get(e.name)) for e in start.effects]


def _with_fit(effect, fitted):
    """The start's effect with the values fitted on a null record when there are some
    (the accepted effects), else the start's template (the candidate)."""
    return fitted if fitted is not None else effect
