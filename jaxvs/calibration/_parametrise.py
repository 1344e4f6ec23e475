"""Constraints by reparametrisation: small wrappers whose `unwrap()` is the physical value.

A constrained parameter of a model (a positive mass, a damping ratio in a range, a
stable denominator) is replaced *inside the model* by a wrapper that stores an
unconstrained value; `unwrap(model)` turns every wrapper back into its physical array.
The calibration engine solves over the unconstrained values, so unconstrained solvers
(Levenberg-Marquardt, BFGS, Adam) stay valid and no iterate can leave the feasible set.

    model = eqx.tree_at(lambda m: m.omega_n, model, replace_fn=positive)

The idea follows `paramax` (D. Ward, `Parameterize` / `unwrap`); it is written here
rather than depended on because jaxvs needs two things paramax does not give: the engine
must know which fields of a wrapper are calibrated (`bounded`'s limits are not), and
the stable-denominator and family wrappers are specific to linear models. The whole
mechanism is ~200 lines and has no other dependency than equinox.
"""

import abc
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PyTree

from .._misc import as_real, concrete, polymul
from ..models import pole_sections

__all__ = [
    "AbstractParameter",
    "Bounded",
    "Fixed",
    "Positive",
    "StableDenominator",
    "bounded",
    "fixed",
    "is_parameter",
    "positive",
    "stable",
    "stable_denominator",
    "unwrap",
]


class AbstractParameter(eqx.Module):
    """A reparametrised model parameter: stores unconstrained values, `unwrap()` gives
    the physical array.

    Subclasses list in `fixed_fields` the names of fields that are data of the
    parametrisation (bounds, scales) and are never calibrated.
    """

    fixed_fields: eqx.AbstractClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def unwrap(self) -> Array:
        """The physical value of the parameter."""

    def free_spec(self) -> PyTree[bool]:
        """This wrapper with `True` at the leaves the calibration engine may change."""

        def spec(path, leaf):
            name = getattr(path[0], "name", None) if path else None
            if name in self.fixed_fields:
                return jax.tree_util.tree_map(lambda _: False, leaf)
            if isinstance(leaf, AbstractParameter):
                return leaf.free_spec()
            return eqx.is_inexact_array(leaf)

        return jax.tree_util.tree_map_with_path(spec, self, is_leaf=is_parameter_not(self))


def is_parameter(x: Any) -> bool:
    """Whether `x` is a reparametrised parameter (an [`AbstractParameter`][])."""
    return isinstance(x, AbstractParameter)


def is_parameter_not(node: Any):
    """`is_leaf` predicate stopping at wrappers nested inside `node` (not `node` itself)."""
    return lambda x: isinstance(x, AbstractParameter) and x is not node


def unwrap(tree: PyTree) -> PyTree:
    """Replace every [`AbstractParameter`][] in `tree` by its physical value.

    Nested wrappers are unwrapped innermost first. Arrays and other leaves are returned
    unchanged, so `unwrap` of a model without wrappers is the model itself.
    """

    def _unwrap_node(x):
        if isinstance(x, AbstractParameter):
            inner = jax.tree_util.tree_map(_unwrap_node, x, is_leaf=is_parameter_not(x))
            return inner.unwrap()
        return x

    return jax.tree_util.tree_map(_unwrap_node, tree, is_leaf=is_parameter)


class Fixed(AbstractParameter):
    """A parameter excluded from calibration whatever `free` says.

    **Arguments:**

    - `value`: the (physical) value, returned by `unwrap()` unchanged.
    """

    value: Array
    fixed_fields = ("value",)

    def unwrap(self) -> Array:
        return jax.lax.stop_gradient(self.value)


class Positive(AbstractParameter):
    r"""A strictly positive parameter, `x = exp(raw)` or `x = softplus(raw)`.

    `"log"` makes relative changes the natural step (right for scale parameters spanning
    decades: masses, stiffnesses, natural frequencies, time constants). `"softplus"` is
    nearly linear above ~1 and suits parameters that may approach 0.

    **Arguments:**

    - `raw`: unconstrained value(s).
    - `transform`: `"log"` (default) or `"softplus"`.
    """

    raw: Array
    transform: Literal["log", "softplus"] = eqx.field(static=True, default="log")
    fixed_fields = ()

    def unwrap(self) -> Array:
        if self.transform == "log":
            return jnp.exp(self.raw)
        return jax.nn.softplus(self.raw)


class Bounded(AbstractParameter):
    r"""A parameter in the open interval `(lo, hi)`, `x = lo + (hi - lo) sigmoid(raw)`.

    **Arguments:**

    - `raw`: unconstrained value(s).
    - `lo`, `hi`: bounds (broadcastable to `raw`), never calibrated.
    """

    raw: Array
    lo: Array
    hi: Array
    fixed_fields = ("lo", "hi")

    def unwrap(self) -> Array:
        lo, hi = jax.lax.stop_gradient(self.lo), jax.lax.stop_gradient(self.hi)
        return lo + (hi - lo) * jax.nn.sigmoid(self.raw)


def fixed(x: ArrayLike) -> Fixed:
    """Mark a model parameter as fixed (not calibrated), e.g.
    `eqx.tree_at(lambda m: m.mass, model, replace_fn=fixed)`."""
    return Fixed(jnp.asarray(x))


def positive(x: ArrayLike, *, transform: Literal["log", "softplus"] = "log") -> Positive:
    """Reparametrise a strictly positive physical value `x` (any shape).

    **Arguments:**

    - `x`: the physical value(s), all > 0.
    - `transform`: `"log"` (`x = exp(raw)`, default) or `"softplus"`.

    **Returns:**

    A [`Positive`][] wrapper with `unwrap() == x`.

    **Raises:** `ValueError` if a concrete `x` has entries <= 0 (under `jit`: an
    `eqx.error_if` runtime error).
    """
    x = as_real(x, "positive")
    if transform not in ("log", "softplus"):
        raise ValueError(f"positive: transform must be 'log' or 'softplus'; got {transform!r}.")
    msg = (
        "positive: the initial value must be > 0 to be reparametrised; start from a "
        "small positive guess instead of 0 or a negative value."
    )
    xc = concrete(x)
    if xc is not None and not np.all(xc > 0):
        raise ValueError(msg + f" Got {xc}.")
    x = eqx.error_if(x, ~(x > 0), msg)
    # softplus^-1(x) = x + log(1 - exp(-x)), written with expm1 for small x.
    raw = jnp.log(x) if transform == "log" else x + jnp.log(-jnp.expm1(-x))
    return Positive(raw, transform)


def bounded(x: ArrayLike, lo: ArrayLike, hi: ArrayLike) -> Bounded:
    """Reparametrise a value `x` constrained to the open interval `(lo, hi)`.

    **Arguments:**

    - `x`: the physical value(s), strictly inside `(lo, hi)`.
    - `lo`, `hi`: bounds, broadcastable to `x`, `lo < hi`.

    **Returns:**

    A [`Bounded`][] wrapper with `unwrap() == x` (to rounding).

    **Raises:** `ValueError` if a concrete `x` is not strictly inside the bounds or
    `lo >= hi`.
    """
    x = as_real(x, "bounded")
    lo = jnp.broadcast_to(jnp.asarray(lo, x.dtype), x.shape)
    hi = jnp.broadcast_to(jnp.asarray(hi, x.dtype), x.shape)
    xc, loc, hic = concrete(x), concrete(lo), concrete(hi)
    if loc is not None and hic is not None and not np.all(loc < hi):
        raise ValueError(f"bounded: need lo < hi; got lo={loc}, hi={hic}.")
    msg = (
        "bounded: the initial value must lie strictly inside (lo, hi); a value on a bound "
        "corresponds to an infinite unconstrained parameter. Move the guess inside or "
        "widen the bounds."
    )
    if xc is not None and loc is not None and hic is not None:
        if not np.all((xc > loc) & (xc < hic)):
            raise ValueError(msg + f" Got x={xc}, lo={loc}, hi={hic}.")
    x = eqx.error_if(x, ~((x > lo) & (x < hi)), msg)
    u = (x - lo) / (hi - lo)
    return Bounded(jnp.log(u) - jnp.log1p(-u), lo, hi)


class StableDenominator(AbstractParameter):
    r"""An always-stable denominator polynomial built from second-order sections.

    `a(s) = lead · Π_k (s² + 2 ζ_k ω_k s + ω_k²) · (s + p)`, with `ω_k = exp(log_omega_k)`,
    `ζ_k = exp(log_zeta_k)` and (odd order only) `p = exp(log_pole)`: every section with
    `ω > 0`, `ζ > 0` has both roots in the open left half-plane (Routh-Hurwitz for a
    quadratic), and conversely every stable pair of poles -- complex or two real ones --
    is such a section (`ω² = product`, `2ζω = sum` of the pole magnitudes), so the
    parametrisation covers exactly the stable polynomials of the given order.

    `lead` (the leading coefficient) is data, not calibrated: it is redundant with the
    numerator's scale.

    **Arguments:**

    - `log_omega`, `log_zeta`: `(*batch, section)` logs of natural frequencies [rad/s]
      and damping ratios.
    - `log_pole`: `(*batch, 1)` log of the real pole [rad/s] for odd orders, `(*batch, 0)`
      otherwise.
    - `lead`: `(*batch,)` leading coefficient.
    """

    log_omega: Float[Array, "*batch section"]
    log_zeta: Float[Array, "*batch section"]
    log_pole: Float[Array, "*batch odd"]
    lead: Float[Array, "*batch"]
    fixed_fields = ("lead",)

    def unwrap(self) -> Float[Array, "*batch n1"]:
        w, z = jnp.exp(self.log_omega), jnp.exp(self.log_zeta)
        batch = w.shape[:-1]
        one = jnp.ones(batch + (1,), w.dtype)
        poly = one
        # Static (small) number of sections: polynomial products as a short Python loop
        # of batched convolutions; "highest power first" as in scipy.
        for k in range(w.shape[-1]):
            sec = jnp.stack([one[..., 0], 2 * z[..., k] * w[..., k], w[..., k] ** 2], -1)
            poly = polymul(poly, sec)
        if self.log_pole.shape[-1] == 1:
            poly = polymul(poly, jnp.concatenate([one, jnp.exp(self.log_pole)], -1))
        return jax.lax.stop_gradient(self.lead)[..., None] * poly


def stable_denominator(den: ArrayLike) -> StableDenominator:
    """Reparametrise a stable denominator (highest power first) as second-order sections.

    **Arguments:**

    - `den`: `(*batch, n + 1)` coefficients of a Hurwitz-stable polynomial, concrete
      (this is set-up code: call it outside `jit`).

    **Returns:**

    A [`StableDenominator`][] with `unwrap()` equal to `den` (to rounding).

    **Raises:** `ValueError` if a root has a non-negative real part (flip unstable poles
    to the left half-plane first, as `fit_rational` does, or start from a stable guess)
    or lies at 0; `TypeError` under tracing.
    """
    den_c = concrete(den)
    if den_c is None:
        raise TypeError(
            "stable_denominator needs a concrete denominator (it finds the roots with "
            "numpy); build the parametrised model outside jit/vmap."
        )
    den_c = np.asarray(den_c, dtype=np.result_type(float, den_c.dtype))
    if den_c.ndim < 1 or den_c.shape[-1] < 2:
        raise ValueError(
            f"stable_denominator: need (*batch, n + 1) with n >= 1; got {den_c.shape}."
        )
    batch, n = den_c.shape[:-1], den_c.shape[-1] - 1
    n_sec, odd = n // 2, n % 2
    lw = np.zeros(batch + (n_sec,))
    lz = np.zeros(batch + (n_sec,))
    lp = np.zeros(batch + (odd,))
    lead = np.zeros(batch)
    for idx in np.ndindex(*batch):
        d = den_c[idx]
        if d[0] == 0 or not np.all(np.isfinite(d)):
            raise ValueError(
                "stable_denominator: the leading coefficient must be non-zero and all "
                f"coefficients finite; got {d}."
            )
        poles = np.roots(d)
        if np.any(poles.real >= 0):
            raise ValueError(
                "stable_denominator: the initial denominator is not stable (poles "
                f"{poles[poles.real >= 0]} have real part >= 0). Reflect them into the "
                "left half-plane (p -> -conj(p)) or start from a stable guess."
            )
        omegas, zetas, reals = pole_sections(poles)
        lw[idx], lz[idx], lp[idx], lead[idx] = np.log(omegas), np.log(zetas), np.log(reals), d[0]
    dtype = as_real(den, "stable_denominator").dtype
    return StableDenominator(*(jnp.asarray(a, dtype) for a in (lw, lz, lp, lead)))


def stable(model: Any) -> Any:
    """Reparametrise a jaxvs linear model so that every iterate of a calibration is stable.

    - `ModalModel`: `omega_n` and `zeta` become [`Positive`][] (log).
    - `RationalTF`: the denominator becomes a [`StableDenominator`][].

    **Arguments:**

    - `model`: a concrete, stable `ModalModel` or `RationalTF` (families allowed).

    **Returns:**

    The same model with wrapped fields; `unwrap(stable(model))` equals `model`.

    **Raises:** `TypeError` for other model types (wrap their fields with `positive`,
    `bounded` or `stable_denominator` by `eqx.tree_at` instead).
    """
    from ..models import ModalModel, RationalTF

    if isinstance(model, ModalModel):
        return eqx.tree_at(
            lambda m: (m.omega_n, m.zeta), model, (positive(model.omega_n), positive(model.zeta))
        )
    if isinstance(model, RationalTF):
        return eqx.tree_at(lambda m: m.den, model, stable_denominator(model.den))
    raise TypeError(
        f"stable: no always-stable parametrisation for {type(model).__name__}; wrap its "
        "fields yourself, e.g. eqx.tree_at(lambda m: m.k, model, replace_fn=positive)."
    )
