"""Model families over a scheduling variable (e.g. the position of another axis).

A family is one model whose parameters carry a leading batch axis. The TMF study
(Doerrer et al. 2022, §3.2, Fig. 6) measures transmissibilities that change with the
position of the other axis; these classes turn such measurements, or a parametric law,
into one batched model at any set of positions, so that `frequency_response` and
`simulate` evaluate every position in one vectorised call, and calibration can
differentiate through the family's parameters.
"""

import functools
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PyTree

from ..._misc import real_array
from .._base import AbstractFamilyLaw, AbstractLinearModel
from ._modal import ModalModel
from ._rational import RationalTF

_METHODS = ("linear", "pchip")
_EXTRAPOLATE = ("error", "clamp")


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _as_positions(position: ArrayLike, dtype, who: str) -> Array:
    pos = jnp.asarray(position)
    if jnp.iscomplexobj(pos):
        raise TypeError(f"{who}: positions are real numbers; got a complex array.")
    if not jnp.issubdtype(pos.dtype, jnp.floating):
        pos = pos.astype(dtype)
    return pos


def _map_arrays(fn: Callable[[Array], Array], tree: Any) -> Any:
    return jax.tree_util.tree_map(lambda x: fn(x) if eqx.is_array(x) else x, tree)


# ---------------------------------------------------------------------------------------
# Which parameters are interpolated
# ---------------------------------------------------------------------------------------


@functools.singledispatch
def _interpolation_form(model: AbstractLinearModel) -> AbstractLinearModel:
    raise TypeError(
        f"GridFamily: cannot interpolate a {type(model).__name__} between grid points. "
        "Parameters of a StateSpace depend on the realisation (interpolating A, B, C, D of "
        "two realisations of similar systems is meaningless); convert the members with "
        "jaxvs.models.to_modal or to_rational first, or describe the family with a "
        "SmoothFamily law."
    )


@_interpolation_form.register
def _(model: ModalModel) -> ModalModel:
    # ω_n, ζ, residues (real and imaginary parts) and feedthrough, mode by mode.
    return model


@_interpolation_form.register
def _(model: RationalTF) -> RationalTF:
    # Coefficients of num / den after normalising den[0] = 1 (den is defined up to scale).
    lead = model.den[..., :1]
    return eqx.tree_at(lambda m: (m.num, m.den), model, (model.num / lead, model.den / lead))


# ---------------------------------------------------------------------------------------
# Interpolation kernels (vectorised over the queried positions)
# ---------------------------------------------------------------------------------------


def _safe_div(num: Array, den: Array, ok: Array) -> Array:
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def pchip_slopes(x: Float[Array, " point"], y: Float[Array, "point ..."]) -> Array:
    """Fritsch–Carlson monotone slopes at the knots, as `scipy.interpolate.PchipInterpolator`.

    Fritsch & Carlson, *SIAM J. Numer. Anal.* 17 (1980) 238; the weighted harmonic mean of
    Fritsch & Butland (1984) inside, the shape-preserving three-point formula at the ends.
    The interpolant never leaves the range of two neighbouring knot values, so positive
    parameters (ω_n, ζ) stay positive and ζ < 1 stays < 1.
    """
    h = jnp.diff(x).reshape((-1,) + (1,) * (y.ndim - 1))
    delta = jnp.diff(y, axis=0) / h
    if x.shape[0] == 2:
        return jnp.concatenate([delta, delta], axis=0)
    h0, h1 = h[:-1], h[1:]
    d0, d1 = delta[:-1], delta[1:]
    w1, w2 = 2 * h1 + h0, h1 + 2 * h0
    same = d0 * d1 > 0
    inner = _safe_div(w1 + w2, _safe_div(w1, d0, same) + _safe_div(w2, d1, same), same)

    def edge(ha, hb, ma, mb):
        d = ((2 * ha + hb) * ma - ha * mb) / (ha + hb)
        d = jnp.where(jnp.sign(d) != jnp.sign(ma), 0.0, d)
        overshoot = (jnp.sign(ma) != jnp.sign(mb)) & (jnp.abs(d) > 3 * jnp.abs(ma))
        return jnp.where(overshoot, 3 * ma, d)

    first = edge(h[0], h[1], delta[0], delta[1])
    last = edge(h[-1], h[-2], delta[-1], delta[-2])
    return jnp.concatenate([first[None], inner, last[None]], axis=0)


def _interpolate_leaf(leaf: Array, grid: Array, idx: Array, t: Array, method: str) -> Array:
    """Interpolate one parameter array `(point, *core)` at positions given by `(idx, t)`."""
    if jnp.iscomplexobj(leaf):
        re = _interpolate_leaf(leaf.real, grid, idx, t, method)
        im = _interpolate_leaf(leaf.imag, grid, idx, t, method)
        return jax.lax.complex(re, im)
    t = t.reshape(t.shape + (1,) * (leaf.ndim - 1)).astype(leaf.dtype)
    y0, y1 = leaf[idx], leaf[idx + 1]
    if method == "linear":
        # (1 - t) y0 + t y1 (not y0 + t (y1 - y0)): exact at both ends of an interval.
        return (1 - t) * y0 + t * y1
    m = pchip_slopes(grid, leaf)
    h = (grid[idx + 1] - grid[idx]).reshape(t.shape).astype(leaf.dtype)
    t2, t3 = t * t, t * t * t
    h00, h10 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t
    h01, h11 = -2 * t3 + 3 * t2, t3 - t2
    return h00 * y0 + h10 * h * m[idx] + h01 * y1 + h11 * h * m[idx + 1]


# ---------------------------------------------------------------------------------------
# GridFamily
# ---------------------------------------------------------------------------------------


class GridFamily(AbstractFamilyLaw):
    """A model family given at grid points of a scheduling variable, interpolated between.

    E.g. a `ModalModel` fitted at each of 8 positions of the y-axis (Doerrer et al. 2022,
    Fig. 6):
    `GridFamily(y_grid, model)` with `model.batch_shape == (8,)`, and
    `family.at(y)` the batched model at any positions `y` inside the grid.

    Interpolated parameters, index by index along the grid:

    - `ModalModel`: `omega_n`, `zeta`, `residues` (real and imaginary parts separately)
      and `feedthrough`, mode by mode: keep mode `k` the same physical mode at every grid
      point (do not re-sort modes whose frequencies cross).
    - `RationalTF`: the numerator and denominator coefficients after normalising
      `den[0] = 1`. Stability is not guaranteed between stable members (coefficient
      interpolation is not pole interpolation); prefer a `ModalModel` family.
    - Other models (e.g. `StateSpace`, whose matrices depend on the realisation): rejected
      with a `TypeError`.

    `method="linear"` is piecewise linear; `method="pchip"` the monotone piecewise cubic
    Hermite interpolant of Fritsch & Carlson (C¹, as `scipy.interpolate.PchipInterpolator`),
    which never overshoots the neighbouring knot values, so ω_n > 0, ζ >= 0 and ζ < 1 hold
    between members that satisfy them. `extrapolate="error"` (default) rejects positions
    outside `[grid[0], grid[-1]]` (`ValueError`, or `eqx.error_if` under `jit`);
    `extrapolate="clamp"` holds the end members constant outside.

    The family is an `eqx.Module` whose array leaves (the members' parameters, and the
    grid) can be calibrated by gradient or Levenberg–Marquardt.

    **Arguments:**

    - `grid`: `(point,)` strictly increasing positions of the scheduling variable, e.g. the
      other axis' position [m]; at least 2.
    - `model`: a `ModalModel` or `RationalTF` with `batch_shape == (point,)`.
    - `method`: `"linear"` or `"pchip"`.
    - `extrapolate`: `"error"` or `"clamp"`.
    """

    grid: Float[Array, " point"]
    model: AbstractLinearModel
    method: str = eqx.field(static=True)
    extrapolate: str = eqx.field(static=True)

    def __init__(
        self,
        grid: ArrayLike,
        model: AbstractLinearModel,
        *,
        method: str = "linear",
        extrapolate: str = "error",
    ):
        if not isinstance(model, AbstractLinearModel):
            raise TypeError(
                f"GridFamily: model must be a jaxvs linear model; got {type(model).__name__}."
            )
        if method not in _METHODS:
            raise ValueError(f"GridFamily: method must be one of {_METHODS}; got {method!r}.")
        if extrapolate not in _EXTRAPOLATE:
            raise ValueError(
                f"GridFamily: extrapolate must be one of {_EXTRAPOLATE}; got {extrapolate!r}."
            )
        _interpolation_form(model)  # raises a TypeError with advice for other families
        grid = real_array(grid, "GridFamily: grid positions are real numbers.")
        if grid.ndim != 1 or grid.shape[0] < 2:
            raise ValueError(
                f"GridFamily: grid must be 1-D with at least 2 points; got shape {grid.shape}."
            )
        if model.batch_shape != grid.shape:
            raise ValueError(
                f"GridFamily: the model's batch shape {model.batch_shape} must be (point,) = "
                f"{grid.shape}, one member per grid point. Stack the members with "
                "GridFamily.from_members(grid, members), or build the model with parameters "
                "of leading shape (point, ...)."
            )
        msg = (
            "GridFamily: grid must be strictly increasing and finite; sort the grid (and "
            "the members with it) and remove duplicate positions."
        )
        if _is_concrete(grid):
            g = np.asarray(grid)
            if not (np.all(np.isfinite(g)) and np.all(np.diff(g) > 0)):
                raise ValueError(msg)
        else:
            grid = eqx.error_if(grid, ~jnp.all(jnp.diff(grid) > 0), msg)
        self.grid = grid
        self.model = model
        self.method = method
        self.extrapolate = extrapolate

    @classmethod
    def from_members(
        cls,
        grid: ArrayLike,
        members: Sequence[AbstractLinearModel],
        **kwargs: Any,
    ) -> "GridFamily":
        """Stack unbatched models of one class and structure into a `GridFamily`.

        **Arguments:**

        - `grid`: `(point,)` positions, one per member.
        - `members`: `point` models of the same class, orders and channel counts.
        - `kwargs`: `method`, `extrapolate` as for `GridFamily`.
        """
        members = list(members)
        if len(members) == 0:
            raise ValueError("GridFamily.from_members: give at least two members.")
        structure = jax.tree_util.tree_structure(members[0])
        shapes = [tuple(x.shape for x in jax.tree_util.tree_leaves(m)) for m in members]
        if any(jax.tree_util.tree_structure(m) != structure for m in members) or any(
            s != shapes[0] for s in shapes
        ):
            raise ValueError(
                "GridFamily.from_members: the members differ in class, order, number of "
                "modes, channels or residue type; give members of one structure (e.g. the "
                "same number of modes at every position)."
            )
        stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *members)
        return cls(grid, stacked, **kwargs)

    @property
    def n_points(self) -> int:
        return self.grid.shape[0]

    def at(self, position: ArrayLike) -> AbstractLinearModel:
        """The family's model at `position`: one batched model for all positions.

        **Arguments:**

        - `position`: scalar or array of positions (same unit as `grid`).

        **Returns:**

        A model of the members' class with `batch_shape == position.shape`; at a grid
        point it equals that member (after normalising `den[0] = 1` for a `RationalTF`).
        """
        who = "GridFamily.at"
        pos = _as_positions(position, self.grid.dtype, who)
        shape = pos.shape
        flat = pos.reshape(-1)
        lo, hi = self.grid[0], self.grid[-1]
        if self.extrapolate == "clamp":
            flat = jnp.clip(flat, lo, hi)
        else:
            msg = (
                f"{who}: a position lies outside the grid [grid[0], grid[-1]] or is NaN. "
                "Extend the grid, or build the family with extrapolate='clamp' to hold the "
                "end members constant."
            )
            outside = ~((flat >= lo) & (flat <= hi))
            if _is_concrete(flat) and _is_concrete(self.grid):
                if bool(np.any(np.asarray(outside))):
                    raise ValueError(msg)
            else:
                flat = eqx.error_if(flat, jnp.any(outside), msg)
        n = self.n_points
        idx = jnp.clip(jnp.searchsorted(self.grid, flat, side="right") - 1, 0, n - 2)
        g0, g1 = self.grid[idx], self.grid[idx + 1]
        t = (flat - g0) / (g1 - g0)
        form = _interpolation_form(self.model)
        out = _map_arrays(
            lambda leaf: _interpolate_leaf(leaf, self.grid, idx, t, self.method), form
        )
        return _map_arrays(lambda leaf: leaf.reshape(shape + leaf.shape[1:]), out)


# ---------------------------------------------------------------------------------------
# SmoothFamily
# ---------------------------------------------------------------------------------------


class SmoothFamily(AbstractFamilyLaw):
    """A model family given by a law of a scheduling variable: `law(params, position)`.

    E.g. a natural frequency that depends on the other axis' position,
    `ω_n(y) = ω0 + ω1 y + ω2 y²`:

    ```python
    def law(p, y):
        return jaxvs.ModalModel(p["w"][0] + p["w"][1] * y + p["w"][2] * y**2, p["zeta"], p["r"])

    family = SmoothFamily(law, params)
    g = jaxvs.frequency_response(family.at(jnp.linspace(0.0, 0.5, 64)), omega)  # (64, freq)
    ```

    `at` evaluates the law for every position with one `eqx.filter_vmap`, so the result is
    one batched model, differentiable in `params` (the array leaves of the family).

    **Arguments:**

    - `law`: `law(params, position) -> model`, a pure function returning one unbatched
      jaxvs linear model for a scalar position. Its structure (class, orders, channels)
      must not depend on the position.
    - `params`: PyTree of the law's parameters.
    """

    law: Callable[[PyTree, Array], AbstractLinearModel] = eqx.field(static=True)
    params: PyTree

    def __init__(self, law: Callable[[PyTree, Array], AbstractLinearModel], params: PyTree):
        if not callable(law):
            raise TypeError(
                f"SmoothFamily: law must be a function law(params, position) -> model; got "
                f"{type(law).__name__}."
            )
        probe = jnp.zeros((), jnp.result_type(float))
        out = eqx.filter_eval_shape(law, params, probe)
        if not isinstance(out, AbstractLinearModel):
            raise TypeError(
                "SmoothFamily: law(params, position) must return a jaxvs linear model "
                f"(RationalTF, ModalModel, StateSpace, ...); it returned {type(out).__name__}."
            )
        if out.batch_shape != ():
            raise ValueError(
                "SmoothFamily: law(params, position) must return one unbatched model for a "
                f"scalar position; it returned batch shape {out.batch_shape}. The family "
                "axis is added by SmoothFamily.at."
            )
        self.law = law
        self.params = params

    def at(self, position: ArrayLike) -> AbstractLinearModel:
        """The family's model at `position`: the law evaluated for every position at once.

        **Arguments:**

        - `position`: scalar or array of positions.

        **Returns:**

        The law's model class with `batch_shape == position.shape`.
        """
        pos = _as_positions(position, jnp.result_type(float), "SmoothFamily.at")
        if pos.ndim == 0:
            return self.law(self.params, pos)
        shape = pos.shape
        out = eqx.filter_vmap(lambda p: self.law(self.params, p))(pos.reshape(-1))
        return _map_arrays(lambda leaf: leaf.reshape(shape + leaf.shape[1:]), out)
