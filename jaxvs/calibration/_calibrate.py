"""`calibrate`: fit the free parameters of any `eqx.Module` to experiments, with
covariance and confidence intervals.

The problem is a nonlinear least-squares problem over the *unconstrained* free leaves of
the model (after reparametrisation, see `_parametrise.py`):

    min_θ  ½ ‖r(unwrap(model(θ)), data)‖²,

solved by optimistix (Levenberg-Marquardt by default). The free leaves are flattened into
one real vector -- complex leaves as real and imaginary parts -- and scaled by their
initial magnitude so that every coordinate is O(1) for the solver. After the solve the
Jacobian at the estimate gives `σ̂² (JᵀJ)⁻¹`, mapped to the physical parameters by the
delta method.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypedDict

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, Int, PyTree

from .._misc import concrete, is_traced, timed_call
from ._covariance import delta_method, jacobian_covariance, t_quantile
from ._parametrise import is_parameter, unwrap
from ._residuals import AbstractResidual, Joint
from ._results import RESULTS, describe, failure_message
from ._solvers import make_solver

__all__ = ["CalibrateOptions", "CalibrationResult", "SolveOptions", "calibrate", "free_spec"]


class CalibrationResult(eqx.Module):
    """The outcome of [`calibrate`][].

    **Fields:**

    - `model`: the calibrated model, physical (every reparametrisation unwrapped).
    - `result`: a `RESULTS` code; `result == RESULTS.successful` on success.
    - `residual`: `(N,)` weighted residual vector at the estimate.
    - `cost`: `½ Σ residual²` (the minimised objective, as scipy's `least_squares`).
    - `values`: `(p,)` physical values of the free parameters, in the order of `names`.
    - `covariance`: `(p, p)` covariance of `values` (`σ̂² (JᵀJ)⁻¹` mapped by the delta
      method); infinite variance for parameters that are not identifiable.
    - `std_errors`: `(p,)` standard errors, `sqrt(diag(covariance))`.
    - `confidence_intervals`: `(p, 2)` two-sided intervals at level `confidence`, from
      Student-t quantiles with `dof` degrees of freedom.
    - `correlation`: `(p, p)` correlation matrix.
    - `sigma2`: residual variance `σ̂² = SSR / (N - p_free)`.
    - `names`: names of the entries of `values`, from the pytree paths (e.g.
      `"omega_n[1]"`, `"[0].mass"`, `"residues[0].real"`).
    - `dof`: degrees of freedom `N - p_free` (`p_free` counts unconstrained parameters).
    - `confidence`: the level of `confidence_intervals`.
    - `stats`: `num_steps`, `rank` of the Jacobian, `initial_cost`, `compile_time` and
      `run_time` [s] (measured outside `jit`; NaN when `calibrate` itself is traced).
    """

    model: Any
    result: RESULTS
    residual: Float[Array, " residual"]
    cost: Float[Array, ""]
    values: Float[Array, " param"]
    covariance: Float[Array, "param param"]
    std_errors: Float[Array, " param"]
    confidence_intervals: Float[Array, "param 2"]
    correlation: Float[Array, "param param"]
    sigma2: Float[Array, ""]
    stats: dict[str, Array]
    names: tuple[str, ...] = eqx.field(static=True)
    dof: int = eqx.field(static=True)
    confidence: float = eqx.field(static=True)

    @property
    def num_steps(self) -> Int[Array, "..."]:
        return self.stats["num_steps"]

    def summary(self) -> str:
        """A plain-text table of the estimates (name, value, standard error, interval)."""
        vals, se = np.asarray(self.values), np.asarray(self.std_errors)
        ci = np.asarray(self.confidence_intervals)
        if vals.ndim != 1:
            return f"CalibrationResult over a batch of shape {vals.shape[:-1]}; index it first."
        width = max([len(n) for n in self.names] + [9])
        pct = f"{100 * self.confidence:g}% interval"
        lines = [f"{'parameter':<{width}}  {'value':>12}  {'std error':>10}  {pct}"]
        for n, v, s, (lo, hi) in zip(self.names, vals, se, ci):
            lines.append(f"{n:<{width}}  {v:12.6g}  {s:10.3g}  [{lo:.6g}, {hi:.6g}]")
        lines.append(
            f"cost {float(self.cost):.6g}, sigma^2 {float(self.sigma2):.3g}, dof {self.dof}, "
            f"{int(self.num_steps)} steps, result: {describe(self.result)}"
        )
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """The estimates as a table (notebooks)."""
        from .._html import table

        vals, ci = np.asarray(self.values), np.asarray(self.confidence_intervals)
        if vals.ndim != 1:
            return f"<p>{self.summary()}</p>"
        rows = [
            (n, float(v), float(s), f"[{lo:.6g}, {hi:.6g}]")
            for n, v, s, (lo, hi) in zip(self.names, vals, np.asarray(self.std_errors), ci)
        ]
        head = ("parameter", "value", "std error", f"{100 * self.confidence:g} % interval")
        return (
            f"<p><strong>CalibrationResult</strong>: {describe(self.result)}; cost "
            f"{float(self.cost):.6g}, σ² {float(self.sigma2):.3g}, dof {self.dof}, "
            f"{int(self.num_steps)} steps</p>" + table(head, rows, markup=False)
        )


# ----------------------------------------------------------------------------- free leaves


def _default_free(model: PyTree) -> PyTree[bool]:
    def spec(x):
        return x.free_spec() if is_parameter(x) else eqx.is_inexact_array(x)

    return jax.tree_util.tree_map(spec, model, is_leaf=is_parameter)


def free_spec(model: PyTree, free: Any = None) -> PyTree[bool]:
    """The full filter spec (a pytree of bools shaped like `model`) of the calibrated leaves.

    **Arguments:**

    - `model`: the (possibly reparametrised) model.
    - `free`: `None` (every floating-point array leaf, except the fixed fields of
      parametrisations and [`Fixed`][] leaves); a filter spec as for `eqx.partition` (a
      pytree of bools, or a predicate such as `eqx.is_inexact_array`, possibly as the
      leaves of a prefix pytree); or a where-function `model -> node or sequence of
      nodes` as for `eqx.tree_at` (e.g. `lambda m: (m.omega_n, m.zeta)`).

    **Returns:**

    A pytree of bools with the structure of `model`.
    """
    default = _default_free(model)
    if free is None:
        return default
    is_where = callable(free) and not isinstance(free, eqx.Module | list | tuple | dict)
    if is_where:
        # a filter predicate (e.g. eqx.is_inexact_array) returns a bool for the whole
        # model, a where-function returns nodes of it
        try:
            is_where = not isinstance(free(model), bool | np.bool_)
        except Exception:  # a where-function that fails on the model: report below
            is_where = True
    if is_where:

        def where(tree):
            nodes = free(tree)
            return tuple(nodes) if isinstance(nodes, list) else nodes

        try:
            chosen = where(default)
            nothing = jax.tree_util.tree_map(lambda _: False, default)
            spec = eqx.tree_at(where, nothing, replace=chosen)
        except Exception as e:
            raise ValueError(
                "calibrate: the where-function `free` must select nodes by attribute or "
                "item access only (as for eqx.tree_at), e.g. lambda m: (m.omega_n, m.zeta); "
                f"it failed with {type(e).__name__}: {e}"
            ) from e
        nodes = chosen if isinstance(chosen, tuple) else (chosen,)
        for node in nodes:
            if not any(jax.tree_util.tree_leaves(node)):
                raise ValueError(
                    "calibrate: `free` selects a node without floating-point arrays to "
                    "calibrate (an integer or Python scalar, or a fixed field); convert it "
                    "with jnp.asarray(x, float) or drop it from `free`."
                )
        return spec
    try:
        selected = eqx.filter(model, free)
    except Exception as e:
        raise ValueError(
            "calibrate: `free` must be None, a where-function, or a filter spec (pytree of "
            f"bools) matching the model's structure; eqx.filter failed with: {e}"
        ) from e
    chosen = jax.tree_util.tree_map(lambda x: x is not None, selected, is_leaf=lambda x: x is None)

    def combine(sel, node, dflt):
        if is_parameter(node):
            return jax.tree_util.tree_map(lambda s, d: bool(s) and d, sel, dflt)
        if sel and eqx.is_array(node) and not dflt:
            raise TypeError(
                "calibrate: `free` selects a leaf that is not a floating-point array "
                f"({type(node).__name__} {getattr(node, 'dtype', '')}); only inexact arrays "
                "can be calibrated. Convert it with jnp.asarray(x, float) or fix it."
            )
        return bool(sel) and bool(dflt)

    return jax.tree_util.tree_map(combine, chosen, model, default, is_leaf=is_parameter)


class _Flat:
    """Flatten the free leaves (a partition with `None` elsewhere) into one real vector."""

    def __init__(self, params: PyTree):
        leaves, self.treedef = jax.tree_util.tree_flatten(params)
        self.shapes = [x.shape for x in leaves]
        self.dtypes = [x.dtype for x in leaves]
        self.is_complex = [jnp.iscomplexobj(x) for x in leaves]
        reals = [jnp.finfo(x.dtype).dtype for x in leaves]
        self.dtype = jnp.result_type(*reals) if reals else jnp.result_type(float)
        self.sizes = [
            int(np.prod(s)) * (2 if c else 1) for s, c in zip(self.shapes, self.is_complex)
        ]
        self.size = sum(self.sizes)

    def ravel(self, params: PyTree) -> Float[Array, " p"]:
        parts = []
        for x, c in zip(jax.tree_util.tree_leaves(params), self.is_complex):
            parts += [jnp.real(x).ravel(), jnp.imag(x).ravel()] if c else [x.ravel()]
        return jnp.concatenate([p.astype(self.dtype) for p in parts])

    def unravel(self, theta: Float[Array, " p"]) -> PyTree:
        leaves, i = [], 0
        for shape, dtype, c, size in zip(self.shapes, self.dtypes, self.is_complex, self.sizes):
            chunk = theta[i : i + size]
            i += size
            if c:
                half = size // 2
                x = jax.lax.complex(chunk[:half], chunk[half:]).reshape(shape)
            else:
                x = chunk.reshape(shape)
            leaves.append(x.astype(dtype))
        return jax.tree_util.tree_unflatten(self.treedef, leaves)


def _physical(model: PyTree, spec: PyTree[bool]) -> PyTree:
    """The physical values of the free parameters (`None` for fixed ones)."""

    def phys(node, sub):
        if is_parameter(node):
            return unwrap(node) if any(jax.tree_util.tree_leaves(sub)) else None
        return node if sub else None

    return jax.tree_util.tree_map(phys, model, spec, is_leaf=is_parameter)


def _names(phys: PyTree) -> list[str]:
    names = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(phys)[0]:
        base = jax.tree_util.keystr(path)
        base = base[1:] if base.startswith(".") else base
        idx = (
            [""]
            if leaf.ndim == 0
            else ["[" + ",".join(map(str, i)) + "]" for i in np.ndindex(leaf.shape)]
        )
        if jnp.iscomplexobj(leaf):
            names += [f"{base}{i}.real" for i in idx] + [f"{base}{i}.imag" for i in idx]
        else:
            names += [f"{base}{i}" for i in idx]
    return names


def _real_ravel(tree: PyTree, dtype) -> Float[Array, " n"]:
    parts = []
    for x in jax.tree_util.tree_leaves(tree):
        x = jnp.asarray(x)
        parts += [jnp.real(x).ravel(), jnp.imag(x).ravel()] if jnp.iscomplexobj(x) else [x.ravel()]
    return jnp.concatenate([p.astype(dtype) for p in parts])


# ----------------------------------------------------------------------------- the solve


def _check_weights(weights: Any) -> None:
    """Refuse weights that make the cost meaningless: NaN/inf, negative, or all zero."""
    values = [concrete(w) for w in jax.tree_util.tree_leaves(weights)]
    known = [np.asarray(v, dtype=float) for v in values if v is not None]
    if any(not np.isfinite(v).all() for v in known):
        raise ValueError(
            "calibrate: the weights contain NaN or inf; give finite weights (e.g. 1/σ_noise "
            "of each experiment)."
        )
    if any((v < 0).any() for v in known):
        raise ValueError(
            "calibrate: weights must be >= 0 (they multiply the residual, e.g. 1/σ_noise); "
            "got a negative weight."
        )
    if known and len(known) == len(values) and all((v == 0).all() for v in known):
        raise ValueError(
            "calibrate: the weights are all zero, so the cost is 0 for any parameter and "
            "nothing can be calibrated; give positive weights (e.g. 1/σ_noise)."
        )


def _normalise(residual: Any, data: Any, weights: Any) -> tuple[AbstractResidual, Any]:
    """One residual for the whole problem: several experiments become a `Joint`."""
    if weights is not None:
        _check_weights(weights)
    if isinstance(residual, list | tuple):
        if not isinstance(data, list | tuple) or len(data) != len(residual):
            raise ValueError(
                f"calibrate: {len(residual)} residuals need a list of {len(residual)} data "
                "objects, one per residual."
            )
        return Joint(residual, weights), list(data)
    if not isinstance(residual, AbstractResidual):
        raise TypeError(
            "calibrate: `residual` must be a jaxvs residual (SimulationError, PredictionError, "
            "FrequencyError, EquationError, Joint) or a list of them; wrap a plain function "
            f"as EquationError(fn). Got {type(residual).__name__}."
        )
    if isinstance(data, list) and not isinstance(residual, Joint):
        return Joint([residual] * len(data), weights), data
    if weights is not None:
        return Joint([residual], [weights]), [data]
    return residual, data


def _solver_result(result: optx.RESULTS) -> RESULTS:
    """An optimistix/lineax outcome as a jaxvs code (the solver's own failure modes)."""
    out = RESULTS.successful
    for name in ("max_steps_reached", "nonlinear_max_steps_reached"):
        out = RESULTS.where(result == getattr(optx.RESULTS, name), RESULTS.max_steps_reached, out)
    for name in ("nonfinite", "nonfinite_input", "nonlinear_divergence"):
        out = RESULTS.where(result == getattr(optx.RESULTS, name), RESULTS.nonfinite, out)
    for name in ("singular", "breakdown", "stagnation", "conlim"):
        out = RESULTS.where(
            result == getattr(optx.RESULTS, name), RESULTS.linear_solve_failed, out
        )
    return out


def _impl(
    model: PyTree,
    data: PyTree,
    residual: AbstractResidual,
    solver: Any,
    spec: PyTree[bool],
    max_steps: int,
    covariance: bool,
    confidence: float,
    throw: bool,
) -> CalibrationResult:
    params, static = eqx.partition(model, spec)
    flat = _Flat(params)
    p = flat.size
    if p == 0:
        raise ValueError(
            "calibrate: no free parameters. Give `free` (a where-function or a filter spec) "
            "or check that the model's parameters are floating-point arrays."
        )
    theta0 = flat.ravel(params)
    # heuristic: solve for z = θ / s with s = |θ0| for plain leaves (1 if θ0 = 0) so that
    # every coordinate is O(1) for LM's damping and Adam's step size; reparametrised
    # leaves are already on a natural unit scale (logs, logits).
    inside = jax.tree_util.tree_map(
        lambda x: jax.tree_util.tree_map(lambda _: True, x) if is_parameter(x) else False,
        model,
        is_leaf=is_parameter,
    )
    inside_params = eqx.filter(inside, spec)
    mask = [
        jnp.full(size, bool(flag))
        for flag, size in zip(jax.tree_util.tree_leaves(inside_params), flat.sizes)
    ]
    wrapped = jnp.concatenate(mask)
    scale = jnp.where(wrapped | (theta0 == 0), 1.0, jnp.abs(theta0)).astype(flat.dtype)
    scale = jax.lax.stop_gradient(scale)

    def build(theta, static):
        return eqx.combine(flat.unravel(theta), static)

    def fn(z, args):
        static, data, residual, scale = args
        return residual(unwrap(build(z * scale, static)), data)

    args = (static, data, residual, scale)
    z0 = theta0 / scale
    r_struct = eqx.filter_eval_shape(fn, z0, args)
    if r_struct.ndim != 1 or not jnp.issubdtype(r_struct.dtype, jnp.floating):
        raise TypeError(
            f"calibrate: the residual must be a real vector; got {r_struct.dtype}{r_struct.shape}."
        )
    n = r_struct.shape[0]
    if n <= p:
        raise ValueError(
            f"calibrate: {n} residuals for {p} free parameters; a least-squares fit needs "
            "more data points than free parameters (N > p, and N >> p for useful "
            "confidence intervals). Record more samples or frequencies, add experiments, "
            "or fix parameters with free=..."
        )
    unstable0 = residual.is_unstable(unwrap(model))

    sol = optx.least_squares(fn, solver, z0, args, max_steps=max_steps, throw=False)
    z = sol.value
    theta = z * scale

    # Residual (and Jacobian) at the initial guess and at the estimate in one vmapped
    # trace: the residual is traced once here instead of twice, which halves this part
    # of the compile time.
    def value_and_jac(zz):
        f = lambda z_: fn(z_, args)  # noqa: E731
        basis = jnp.eye(zz.shape[0], dtype=zz.dtype)
        r_, jac_t = jax.vmap(lambda v: jax.jvp(f, (zz,), (v,)), out_axes=(None, 0))(basis)
        return r_, jac_t.T

    if covariance:
        rs, jacs = jax.vmap(value_and_jac)(jnp.stack([z0, z]))
        jac0, jac_z = jacs[0], jacs[1]
    else:
        rs = jax.vmap(lambda zz: fn(zz, args))(jnp.stack([z0, z]))
        jac0 = jnp.zeros((n, p), rs.dtype)
    r0, r = rs[0], rs[1]
    nonfinite0 = ~(jnp.all(jnp.isfinite(r0)) & jnp.all(jnp.isfinite(jac0)))
    zero_col0 = jnp.all(jac0 == 0, axis=0)
    result = _solver_result(sol.result)
    ok = result == RESULTS.successful
    result = RESULTS.where(jnp.all(jnp.isfinite(r)) | ~ok, result, RESULTS.nonfinite)

    fitted = build(theta, static)
    phys_tree = _physical(fitted, spec)
    values = _real_ravel(phys_tree, flat.dtype)
    q = values.shape[0]
    dof = n - p
    if covariance:
        jac = jac_z / scale  # ∂r/∂θ
        cov_raw, unidentified, rank, sigma2 = jacobian_covariance(jac, r)
        grad = jax.jacfwd(lambda t: _real_ravel(_physical(build(t, static), spec), flat.dtype))(
            theta
        )
        cov = delta_method(grad, cov_raw, unidentified)
        singular = jnp.any(unidentified) & (result == RESULTS.successful)
        result = RESULTS.where(
            singular,
            RESULTS.where(
                jnp.any(zero_col0), RESULTS.degenerate_initial_guess, RESULTS.singular
            ),
            result,
        )
    else:
        cov = jnp.full((q, q), jnp.nan, flat.dtype)
        rank = jnp.asarray(-1)
        sigma2 = jnp.sum(r**2) / dof
    result = RESULTS.where(nonfinite0, RESULTS.nonfinite_initial_guess, result)
    result = RESULTS.where(unstable0, RESULTS.unstable_initial_guess, result)

    se = jnp.sqrt(jnp.diag(cov))
    tq = t_quantile(confidence, dof)
    ci = jnp.stack([values - tq * se, values + tq * se], axis=-1)
    corr = cov / jnp.outer(se, se)
    stats = {
        "num_steps": jnp.asarray(sol.stats["num_steps"]),
        "rank": jnp.asarray(rank),
        "initial_cost": 0.5 * jnp.sum(r0**2),
        "compile_time": jnp.asarray(jnp.nan, flat.dtype),
        "run_time": jnp.asarray(jnp.nan, flat.dtype),
    }
    out = CalibrationResult(
        model=unwrap(fitted),
        result=result,
        residual=r,
        cost=0.5 * jnp.sum(r**2),
        values=values,
        covariance=cov,
        std_errors=se,
        confidence_intervals=ci,
        correlation=corr,
        sigma2=sigma2,
        stats=stats,
        names=tuple(_names(phys_tree)),
        dof=dof,
        confidence=float(confidence),
    )
    if throw:
        out = result.error_if(out, result != RESULTS.successful)
    return out


def _failure_message(out: CalibrationResult) -> str | None:
    """Message for a concrete, failed calibration, naming the parameters involved."""
    msg = failure_message(out.result)
    if msg is None:
        return None
    msg = "calibrate: " + msg
    if msg.endswith((RESULTS[RESULTS.singular], RESULTS[RESULTS.degenerate_initial_guess])):
        bad = np.isinf(np.asarray(out.std_errors))
        if bad.ndim == 1 and bad.any():
            names = [n for n, b in zip(out.names, bad) if b]
            msg += f" Not identifiable: {', '.join(names)}."
    return msg


class CalibrateOptions(TypedDict, total=False):
    """The keyword options every calibration entry point shares with [`calibrate`][]
    (`multistart`, `calibrate_family`, `calibrate_family_sharded` take them as `**options`):
    `max_steps`, `rtol`, `atol`, `throw`, `covariance`, `confidence`."""

    max_steps: int
    rtol: float | None
    atol: float | None
    throw: bool
    covariance: bool
    confidence: float


@dataclass(frozen=True)
class SolveOptions:
    """[`CalibrateOptions`][] resolved and checked: defaults filled in, bad values refused.

    Built by `SolveOptions.of(where, options)`, which also refuses unknown keywords (a
    misspelt option is an error, never silently ignored)."""

    max_steps: int = 256
    rtol: float | None = None
    atol: float | None = None
    throw: bool = True
    covariance: bool = True
    confidence: float = 0.95

    @classmethod
    def of(cls, where: str, options: Mapping[str, Any]) -> "SolveOptions":
        unknown = sorted(set(options) - set(CalibrateOptions.__annotations__))
        if unknown:
            raise TypeError(
                f"{where}: unknown option(s) {', '.join(unknown)}; the options are "
                f"{', '.join(CalibrateOptions.__annotations__)}."
            )
        out = cls(**options)
        if not isinstance(out.max_steps, int) or out.max_steps < 1:
            raise ValueError(f"{where}: max_steps must be a positive int; got {out.max_steps!r}.")
        if not 0 < out.confidence < 1:
            raise ValueError(f"{where}: confidence must lie in (0, 1); got {out.confidence}.")
        return out


class CalibrationError(RuntimeError):
    """A calibration failed and `throw=True` (the message says why and what to do)."""


def calibrate(
    model: PyTree,
    data: Any,
    residual: AbstractResidual | Sequence[AbstractResidual],
    solver: Any = None,
    *,
    free: Any = None,
    weights: Any = None,
    max_steps: int = 256,
    rtol: float | None = None,
    atol: float | None = None,
    throw: bool = True,
    covariance: bool = True,
    confidence: float = 0.95,
) -> CalibrationResult:
    r"""Calibrate the free parameters of a model against one or several experiments.

    Solves `min_θ ½ Σ r(model(θ), data)²` over the free (unconstrained) leaves `θ` of
    `model`, then reports the physical estimates with the asymptotic covariance
    `σ̂² (JᵀJ)⁻¹`, `σ̂² = SSR/(N - p)` (Seber & Wild, *Nonlinear Regression*, 1989,
    §2.1), mapped through reparametrisations by the delta method, and Student-t
    confidence intervals. Works under `jax.jit` and `jax.vmap` (one calibration per
    batch element: starts, positions, noise realisations).

    **Arguments:**

    - `model`: any `eqx.Module` or pytree of them (a jaxvs linear model, a neural network,
      a user's module, a tuple of models sharing parameters through a composite module).
      Constrained leaves may be reparametrised (`positive`, `bounded`, `stable`, ...).
    - `data`: the experiment(s): a `jaxvs.data.Record`, `jaxvs.data.FRFData` or a mapping
      of arrays, as the residual expects; a `list` for several experiments.
    - `residual`: a residual (`SimulationError`, `PredictionError`, `FrequencyError`,
      `EquationError`, `Joint`), applied to every experiment of a list, or a list of
      residuals paired with the list of data.
    - `solver`: `None` ([`jaxvs.calibration.LevenbergMarquardt`][]), an optimistix least-squares
      solver, an optimistix minimiser such as `optimistix.BFGS` (on `½ Σ r²`), an optax
      optimiser such as `optax.adam(1e-2)`, or a name (`"levenberg_marquardt"`, `"bfgs"`,
      ...). Least-squares solvers and the covariance build Jacobians in forward mode, so
      a diffrax model needs `adjoint=diffrax.ForwardMode()` in its `diffeqsolve`;
      gradient methods (BFGS, optax) differentiate in reverse mode, for which
      `diffrax.DirectAdjoint()` serves both (or pass `covariance=False`).
    - `free`: which leaves are calibrated: `None` (all floating-point arrays), a filter
      spec (pytree of bools), or a where-function `model -> nodes` (as `eqx.tree_at`).
      Everything else is fixed.
    - `weights`: scalar or array weight of the residual, or one weight per experiment when
      `data` is a list (e.g. `1/σ_noise` of each).
    - `max_steps`: solver budget. `rtol`, `atol`: tolerances of a solver built here from
      `None` or a name (default `1e-8`); a solver object carries its own (giving both is
      an error).
    - `throw`: raise [`CalibrationError`][] (eagerly) or an `EquinoxRuntimeError` (under
      `jit`/`vmap`) with an actionable message when the calibration fails; with `False`,
      inspect `result.result` instead.
    - `covariance`: compute the Jacobian at the estimate, the covariance and the
      identifiability check (costs one Jacobian; switch off for over-parametrised models
      such as neural networks, whose Jacobian is rank deficient by design).
    - `confidence`: level of the confidence intervals.

    **Returns:**

    A [`CalibrationResult`][].

    **Raises:**

    `ValueError`/`TypeError` at trace time for malformed data, fewer residuals than free
    parameters, or an invalid `free`/`solver`; `CalibrationError` for a failed calibration
    (non-convergence, NaN, an unstable or degenerate initial guess, non-identifiable
    parameters) when `throw=True`. Warns `ExcitationWarning` for a constant input.
    """
    residual, data = _normalise(residual, data, weights)
    solver = make_solver(solver, rtol, atol)
    SolveOptions.of(
        "calibrate", dict(max_steps=max_steps, rtol=rtol, atol=atol, confidence=confidence)
    )
    prepared = residual.prepare(data)
    spec = free_spec(model, free)
    args = (model, prepared, residual, solver, spec, max_steps, covariance, confidence)
    if is_traced((model, prepared, residual)):
        return _impl(*args, throw)
    out, t_compile, t_run = timed_call(_impl, *args, False)
    out = eqx.tree_at(
        lambda o: (o.stats["compile_time"], o.stats["run_time"]),
        out,
        (jnp.asarray(t_compile), jnp.asarray(t_run)),
    )
    if throw:
        msg = _failure_message(out)
        if msg is not None:
            raise CalibrationError(msg)
    return out
