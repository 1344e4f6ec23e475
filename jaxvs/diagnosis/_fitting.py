"""The one fitting program of the diagnosis: every calibration of a search goes through it.

All experiments of one role are padded to a common length and stacked, so that every
prediction, Jacobian and calibration is one vectorised call, with padded samples carrying
zero weight. A [`Layout`][] fixes one model structure for a whole search (the nominal
model and one slot per effect of the library); which slots act is an array and the
calibrated parameters are picked by a selection matrix of fixed width, so every candidate
of every round, and the null records, are calibrated by the same compiled function.
Each start first gets its effect's sizes by least squares against the current residual
(the *signature*), then the whole model -- nominal and effect parameters together -- is
recalibrated by the package's one Levenberg-Marquardt kernel (`jaxvs.calibration.lm_step`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from ..calibration import free_spec, lm_init, lm_solve, unwrap
from ._base import Context, Experiment, GapModel

__all__ = [
    "Fits",
    "Layout",
    "has_size",
    "dof",
    "early_layout",
    "fit_many",
    "n_free",
    "same_structure",
    "stack",
]


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


def dof(model: GapModel, experiments: Sequence[Experiment]) -> int:
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


class Fits(NamedTuple):
    """What [`fit_many`][] returns: the calibrated (physical) models, their calibration
    SSR after LM and at the least-squares start (the signature), their predictions on
    every experiment, and the layout with the width the call used (pass it on)."""

    models: list[GapModel]
    ssr: np.ndarray
    ssr_start: np.ndarray
    predictions: list[list[np.ndarray]]
    layout: Layout


def fit_many(
    models: Sequence[GapModel],
    slots: Sequence[int | None],
    experiments: Sequence[Experiment] | Sequence[Sequence[Experiment]],
    n_cal: int,
    scale: float,
    max_steps: int,
    layout: Layout,
) -> Fits:
    """Calibrate several starting models of one structure on the first `n_cal`
    experiments through the one fixed structure of `layout` (so the compiled function is
    shared with every other structure of the search); the sizes of effect `slots[i]` of
    start `i` are first set by least squares. `experiments` is one list of experiments
    for all the models, or one list per model (the null records: start `i` on data set
    `i`)."""
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
    fitted, cost, cost_start, pred, layout = _fit_layout(
        layout, models, slots, batch, wfit, max_steps, data_axis
    )
    cost = np.asarray(cost) * 2.0 / scale**2
    cost = np.where(np.isfinite(cost), cost, np.inf)
    cost_start = np.asarray(cost_start) * 2.0 / scale**2
    cost_start = np.where(np.isfinite(cost_start), cost_start, np.inf)
    fitted = [unwrap(m) for m in fitted]
    preds = [_unstack(np.asarray(pred)[i], exp_lists[i]) for i in range(len(fitted))]
    return Fits(fitted, cost, cost_start, preds, layout)


# ------------------------------------------------------------------------------ one structure


@dataclasses.dataclass(frozen=True)
class Layout:
    """One fixed model structure for a whole search: the nominal model and one slot per
    effect of the family's library (in library order), each slot holding either an
    effect of the model being fitted or a default instance of the same shapes. Which
    slots act is an array (`active`), and the parameters calibrated are chosen by a
    selection matrix of fixed width, so every candidate of every round, and the null
    records, are calibrated by the same compiled function (one compilation per batch
    mode instead of one per candidate and round). Inactive slots are skipped by
    `lax.cond`, so they cost nothing at run time.

    - `defaults`: one effect per slot (constrained), in library order.
    - `keys`: the data every slot reads (the refreshed experiments' arrays).
    - `batch`: starts per call: every call has this many, padded or chunked.
    - `width`: calibrated parameters per call (0: not yet known). [`fit_many`][] returns
      the layout with the width it used: room for the nominal model and the two largest
      slots at the first call, in steps of `granularity` when a model needs more (one
      more compilation).
    """

    defaults: tuple
    keys: frozenset
    batch: int
    granularity: int = 2
    width: int = 0

    @classmethod
    def of(cls, defaults, keys, batch: int) -> Layout:
        return cls(tuple(defaults), frozenset(keys), int(batch))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.defaults)

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

    def widened(self, owners: np.ndarray, needed: int) -> Layout:
        """The layout with room for `needed` calibrated parameters (`owners`: the owner of
        every free parameter, 0 the nominal model, `i + 1` slot `i`)."""
        width = self.width
        if not width:
            counts = sorted(int(np.sum(owners == i + 1)) for i in range(len(self.defaults)))
            width = int(np.sum(owners == 0)) + sum(counts[-2:])
        width = max(width, needed)
        width = int(np.ceil(width / self.granularity)) * self.granularity
        return self if width == self.width else dataclasses.replace(self, width=width)


def has_size(effect) -> bool:
    """Whether an effect has a `size` field: the parameters it is linear in, which every
    start gets by least squares against the current residual before the calibration."""
    return any(f.name == "size" for f in dataclasses.fields(effect))


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
        state = lm_solve(evaluate, state, None, max_steps=max_steps, rtol=1e-8)
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
    layout = layout.widened(owners, chosen.size)
    width = layout.width
    sel = np.zeros((owners.size, width))
    sel[chosen, np.arange(chosen.size)] = 1.0
    size_width = max([int(np.size(d.size)) for d in layout.defaults if has_size(d)] or [1])
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
    return fitted, cost, cost_start, pred, layout


def _fixed_size_selector(cm: _Fixed, slot: int | None, width: int) -> np.ndarray:
    params, _ = eqx.partition(cm, free_spec(cm))
    marker = jax.tree_util.tree_map(jnp.zeros_like, params)
    n_all = int(jax.flatten_util.ravel_pytree(marker)[0].size)
    out = np.zeros((n_all, width))
    if slot is None or not has_size(cm.effects[slot]):
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


def early_layout(family, library, testable, start, exps, n_cal_exp) -> Layout | None:
    """The search's [`Layout`][] before the nominal calibration, from the templates of the
    uncalibrated start, for a family that says its templates' structure does not depend
    on the calibration (`family.early_layout`) and a library that refreshes no data; the
    first round checks the structure and puts its own templates in. `None` otherwise."""
    if not family.early_layout or any(s.refresh for s in library):
        return None
    cal = exps[:n_cal_exp]
    ctx = Context(start, cal, [e.y for e in cal], family.options)
    templates = {s.name: s.templates(ctx) for s in library if s.name in testable}
    defaults = [templates[s.name][0] for s in library if templates.get(s.name)]
    if not defaults:
        return None
    return Layout.of(defaults, exps[0].arrays.keys(), max(len(t) for t in templates.values()))


def same_structure(a: Layout, b: Layout) -> bool:
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
