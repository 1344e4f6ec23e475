"""Vectorised calibration: multi-start, and families of models over positions.

- [`multistart`][]: one calibration per initial guess, all in one `vmap`, and the best.
- [`calibrate_family`][]: one model per position of another axis, calibrated either
  independently (one `vmap`), jointly with parameters shared across positions, or
  jointly through a law in position (a family object with `.at(positions)`, such as
  `jaxvs.models.SmoothFamily`).
"""

from collections.abc import Sequence
from typing import Any, Unpack

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PyTree

from .._misc import is_traced, timed_call
from ..data import FRFData
from ..models import AbstractFamilyLaw
from ._calibrate import (
    CalibrateOptions,
    CalibrationError,
    CalibrationResult,
    SolveOptions,
    _failure_message,
    _impl,
    _normalise,
    calibrate,
    free_spec,
)
from ._parametrise import is_parameter
from ._residuals import AbstractResidual
from ._results import RESULTS
from ._solvers import make_solver

__all__ = ["MultistartResult", "calibrate_family", "multistart"]


def _index(tree: PyTree, i: Any) -> PyTree:
    return jax.tree_util.tree_map(lambda x: x[i] if eqx.is_array(x) else x, tree)


def _stack(trees: Sequence[PyTree]) -> PyTree:
    """Stack pytrees along a new leading axis; equal non-array leaves stay unbatched."""

    def stack(*xs):
        if all(not eqx.is_array(x) for x in xs):
            if all(x == xs[0] for x in xs):
                return xs[0]
            return jnp.asarray(xs)
        return jnp.stack([jnp.asarray(x) for x in xs])

    return jax.tree_util.tree_map(stack, *trees)


def _run_batched(fn, *args):
    """Run `fn(*args)` compiled and timed when eager; plainly when traced."""
    if is_traced(args):
        return fn(*args), None
    out, t_compile, t_run = timed_call(fn, *args)
    return out, (t_compile, t_run)


def _with_times(out: CalibrationResult, times: tuple[float, float] | None) -> CalibrationResult:
    if times is None:
        return out
    shape = out.stats["compile_time"].shape
    return eqx.tree_at(
        lambda o: (o.stats["compile_time"], o.stats["run_time"]),
        out,
        (jnp.full(shape, times[0]), jnp.full(shape, times[1])),
    )


# ----------------------------------------------------------------------------- multistart


class MultistartResult(eqx.Module):
    """The outcome of [`multistart`][].

    **Fields:**

    - `best`: the [`CalibrationResult`][] of lowest cost among the successful starts.
    - `starts`: every start's `CalibrationResult`, batched along a leading axis.
    - `index`: the index of `best` in `starts`.
    """

    best: CalibrationResult
    starts: CalibrationResult
    index: Int[Array, ""]


def _multistart_impl(params, static, data, residual, solver, spec, settings):
    def one(p):
        return _impl(eqx.combine(p, static), data, residual, solver, spec, *settings, False)

    starts = eqx.filter_vmap(one)(params)
    ok = starts.result == RESULTS.successful
    costs = jnp.where(ok, starts.cost, jnp.inf)
    index = jnp.argmin(costs)
    return MultistartResult(_index(starts, index), starts, index)


def multistart(
    models: PyTree | list,
    data: Any,
    residual: AbstractResidual | Sequence[AbstractResidual],
    solver: Any = None,
    *,
    free: Any = None,
    weights: Any = None,
    **options: Unpack[CalibrateOptions],
) -> MultistartResult:
    """Calibrate from several initial guesses in one vectorised call; keep the best.

    Every start runs the same solver (under `vmap`, each for as many steps as the
    slowest); the best is the successful start of lowest cost. Use it for problems with
    local minima (lightly damped modes, periodic responses, neural networks).

    **Arguments:**

    - `models`: the initial guesses: one model whose *free* leaves carry a leading start
      axis (its fixed leaves are shared by every start), e.g. `jax.vmap(make_guess)(keys)`,
      or a `list` of models of one structure (fixed leaves are taken from the first).
    - `data`, `residual`, `solver`, `free`, `weights`, `max_steps`, `rtol`, `atol`,
      `covariance`, `confidence`: as for [`calibrate`][].
    - `throw`: raise [`CalibrationError`][] if no start succeeds.

    **Returns:**

    A [`MultistartResult`][] with the best result, all results and the best index.
    """
    o = SolveOptions.of("multistart", options)
    residual, data = _normalise(residual, data, weights)
    solver = make_solver(solver, o.rtol, o.atol)
    if isinstance(models, list):
        if not models:
            raise ValueError("multistart: give at least one initial model.")
        spec = free_spec(models[0], free)
        parts = [eqx.partition(m, free_spec(m, free)) for m in models]
        params = _stack([p for p, _ in parts])
        static = parts[0][1]
    else:
        spec = free_spec(models, free)
        params, static = eqx.partition(models, spec)
    leaves = jax.tree_util.tree_leaves(params)
    if not leaves:
        raise ValueError("multistart: the models have no free parameters.")
    sizes = {x.shape[0] if x.ndim else None for x in leaves}
    if len(sizes) != 1 or None in sizes:
        raise ValueError(
            "multistart: every free leaf needs the same leading start axis; got leading "
            f"sizes {sorted(map(str, sizes))}. Build the guesses with jax.vmap, or pass a list."
        )
    prepared = residual.prepare(data)
    out, times = _run_batched(
        _multistart_impl,
        params,
        static,
        prepared,
        residual,
        solver,
        spec,
        _solve_settings(o),
    )
    out = eqx.tree_at(lambda o: o.starts, out, _with_times(out.starts, times))
    out = eqx.tree_at(lambda o: o.best, out, _with_times(out.best, times))
    ok = out.starts.result == RESULTS.successful
    if o.throw:
        if times is None:
            out = _first_failure(out.starts.result).error_if(out, ~jnp.any(ok))
        elif not bool(np.any(np.asarray(ok))):
            first = _index(out.starts, int(np.argmin(np.asarray(out.starts.cost))))
            raise CalibrationError(
                f"multistart: none of the {len(np.asarray(ok))} starts succeeded. Best start: "
                + (_failure_message(first) or "")
            )
    return out


# ----------------------------------------------------------------------------- families


class _FamilyResidual(AbstractResidual):
    """The residual of a whole family: `residual` applied to every position, stacked."""

    residual: AbstractResidual
    positions: Array | None
    axes: Any = eqx.field(static=True)

    def prepare(self, data: Any) -> PyTree:
        return _prepare_family(self.residual, data)

    def _members(self, model: Any) -> Any:
        return model.at(self.positions) if self.positions is not None else model

    def _map(self, fn, model, data):
        members = self._members(model)
        axes = eqx.if_array(0) if self.axes is None else self.axes
        return eqx.filter_vmap(fn, in_axes=(axes, eqx.if_array(0)))(members, data)

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        return self._map(self.residual, model, data).ravel()

    def is_unstable(self, model: Any) -> Bool[Array, ""]:
        members = self._members(model)
        axes = eqx.if_array(0) if self.axes is None else self.axes
        return jnp.any(eqx.filter_vmap(self.residual.is_unstable, in_axes=(axes,))(members))


def _first_failure(result: RESULTS) -> RESULTS:
    """The code of the first failed member of a batched result (successful if none)."""
    failed = (result != RESULTS.successful).reshape(-1)
    return jax.tree_util.tree_map(lambda v: v.reshape(-1)[jnp.argmax(failed)], result)


def _frf_family_to_list(data: Any) -> list | None:
    """A batched `FRFData` (H with leading family axes) as a list of per-position dicts."""
    batch = getattr(data, "batch_shape", None)
    if not isinstance(data, FRFData) or batch is None or len(batch) != 1:
        return None
    coh = getattr(data, "coherence", None)
    out = []
    for i in range(batch[0]):
        d = {"omega": data.omega, "H": data.H[i]}
        if coh is not None:
            d["coherence"] = coh[i]
        out.append(d)
    return out


def _prepare_family(residual: AbstractResidual, data: Any) -> PyTree:
    as_list = data if isinstance(data, list) else _frf_family_to_list(data)
    if as_list is not None:
        if not as_list:
            raise ValueError("calibrate_family: the family has no positions (empty data list).")
        return _stack([residual.prepare(d) for d in as_list])
    sizes = {
        x.shape[0] if x.ndim else None for x in jax.tree_util.tree_leaves(data) if eqx.is_array(x)
    }
    if len(sizes) != 1 or None in sizes:
        raise ValueError(
            "calibrate_family: give the data as a list with one experiment per position, or "
            "as a pytree whose every array has the positions axis first (got leading sizes "
            f"{sorted(map(str, sizes))})."
        )
    return eqx.filter_vmap(residual.prepare, in_axes=(eqx.if_array(0),))(data)


def _n_positions(prepared: PyTree) -> int:
    return next(x.shape[0] for x in jax.tree_util.tree_leaves(prepared) if eqx.is_array(x))


def _solve_settings(o: SolveOptions) -> tuple[int, bool, float]:
    """The options the compiled solve depends on (static): `(max_steps, covariance,
    confidence)`."""
    return o.max_steps, o.covariance, o.confidence


def _family_impl(model, data, residual, solver, spec, settings):
    def one(m, d):
        return _impl(m, d, residual, solver, spec, *settings, False)

    return eqx.filter_vmap(one, in_axes=(eqx.if_array(0), eqx.if_array(0)))(model, data)


def _check_batched(model: PyTree, axes: PyTree, n: int) -> None:
    """Every leaf mapped over positions (axis 0) must have `n` rows."""

    def check(path, node, axis):
        if axis != 0:
            return None
        for leaf in jax.tree_util.tree_leaves(node):
            if eqx.is_array(leaf) and (leaf.ndim == 0 or leaf.shape[0] != n):
                raise ValueError(
                    f"calibrate_family: {jax.tree_util.keystr(path) or 'the model'} should "
                    f"carry the positions axis first (size {n}) but has shape {leaf.shape}; "
                    "broadcast it to the family, or list it in `shared`."
                )
        return None

    jax.tree_util.tree_map_with_path(check, model, axes, is_leaf=is_parameter)


def calibrate_family(
    model: PyTree,
    data: Any,
    residual: AbstractResidual,
    solver: Any = None,
    *,
    positions: Any = None,
    shared: Any = None,
    free: Any = None,
    **options: Unpack[CalibrateOptions],
) -> CalibrationResult:
    """Calibrate a family of models, one per position (of another axis), in one call.

    Three forms:

    1. **Independent** (neither `shared` nor `positions`): `model` is batched -- every
       array leaf has the positions axis first -- and each position is calibrated on its
       own experiment, all in one `vmap`. Returns a batched [`CalibrationResult`][] (one
       covariance per position).
    2. **Shared parameters** (`shared` given): the leaves selected by `shared` are
       unbatched and common to all positions, the others are batched; one joint
       least-squares problem over both.
    3. **Smooth in position** (`positions` given): `model` is a family law with a method
       `at(positions)` returning the batched member models (e.g.
       `jaxvs.models.SmoothFamily(law, params)` with polynomial coefficients as
       parameters); its parameters are calibrated on all positions jointly.

    Forms 2 and 3 return one `CalibrationResult` whose `model` is the calibrated family.

    **Arguments:**

    - `model`: the family (see above).
    - `data`: a list with one experiment per position, a pytree whose every array has the
      positions axis first, or a batched `FRFData`.
    - `residual`: the residual of one position (applied to each).
    - `positions`: `(n,)` positions for form 3.
    - `shared`: leaves common to all positions (where-function or filter spec), form 2.
    - `solver`, `free`, `max_steps`, `rtol`, `atol`, `throw`, `covariance`,
      `confidence`: as for [`calibrate`][].

    **Returns:**

    A batched (form 1) or joint (forms 2-3) [`CalibrationResult`][].
    """
    o = SolveOptions.of("calibrate_family", options)
    if not isinstance(residual, AbstractResidual):
        raise TypeError(
            "calibrate_family: `residual` is the residual of one position (e.g. "
            f"FrequencyError()); got {type(residual).__name__}."
        )
    if positions is not None:
        if not isinstance(model, AbstractFamilyLaw):
            raise TypeError(
                "calibrate_family: with `positions`, the model must be a family law with a "
                "method at(positions) returning the batched models (e.g. "
                "jaxvs.models.SmoothFamily)."
            )
        positions = jnp.asarray(positions)
        if positions.ndim != 1:
            raise ValueError(
                f"calibrate_family: positions must be 1-D (n,); got {positions.shape}."
            )
        fam = _FamilyResidual(residual, positions, None)
        prepared = fam.prepare(data)
        if _n_positions(prepared) != positions.shape[0]:
            raise ValueError(
                f"calibrate_family: {positions.shape[0]} positions but "
                f"{_n_positions(prepared)} experiments; give one experiment per position."
            )
        return calibrate(model, prepared, _Prepared(fam), solver, free=free, **options)
    if shared is not None:
        spec = free_spec(model, shared)
        axes = jax.tree_util.tree_map(
            lambda node, sub: (
                None
                if any(jax.tree_util.tree_leaves(sub))
                or not (is_parameter(node) or eqx.is_array(node))
                else 0
            ),
            model,
            spec,
            is_leaf=is_parameter,
        )
        fam = _FamilyResidual(residual, None, axes)
        prepared = fam.prepare(data)
        _check_batched(model, axes, _n_positions(prepared))
        return calibrate(model, prepared, _Prepared(fam), solver, free=free, **options)

    solver = make_solver(solver, o.rtol, o.atol)
    prepared = _prepare_family(residual, data)
    n = _n_positions(prepared)
    _check_batched(model, jax.tree_util.tree_map(lambda _: 0, model, is_leaf=is_parameter), n)
    spec = free_spec(model, free)
    out, times = _run_batched(
        _family_impl,
        model,
        prepared,
        residual,
        solver,
        spec,
        _solve_settings(o),
    )
    out = _with_times(out, times)
    if o.throw:
        failed = out.result != RESULTS.successful
        if times is None:
            out = _first_failure(out.result).error_if(out, jnp.any(failed))
        elif bool(np.any(np.asarray(failed))):
            bad = np.flatnonzero(np.asarray(failed))
            first = _index(out, int(bad[0]))
            raise CalibrationError(
                f"calibrate_family: {bad.size} of {n} positions failed (indices "
                f"{bad[:10].tolist()}{' ...' if bad.size > 10 else ''}). Position {bad[0]}: "
                + (_failure_message(first) or "")
            )
    return out


class _Prepared(AbstractResidual):
    """A residual whose data are already prepared (prepare is the identity)."""

    inner: AbstractResidual

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        return self.inner(model, data)

    def is_unstable(self, model: Any) -> Bool[Array, ""]:
        return self.inner.is_unstable(model)
