"""The interface every jaxvs model implements, and the batching convention.

[`AbstractModel`][] is one experiment in, one prediction out: `predict(u, dt)`, a pure
function of the model's parameters. [`AbstractLinearModel`][] adds the frequency response
and a state-space realisation (and gets `predict` from the exact-discretisation engine).
[`AbstractFamilyLaw`][] describes how a family of linear models varies with a position.

A model's array fields are its physical parameters. One model describes one system;
a *family* is the same model class whose array fields carry extra leading axes
(`batch_shape`), e.g. one system per position of the other axis. Methods of a model
handle one system; the public free functions (`frequency_response`, `simulate`, ...)
map over `batch_shape` with `jax.vmap`, so a family of 4096 systems is one call.
"""

import abc
import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float

from .._misc import check_finite, concrete
from ._realisation import ModalRealisation

if TYPE_CHECKING:
    from .lti import StateSpace


PARAMETER_FIX = (
    "Every parameter must be a finite number (a NaN usually comes from a failed fit or a "
    "division by zero upstream)."
)


def check_parameters(module: eqx.Module) -> None:
    """Refuse NaN/inf in the concrete array fields of a model or model part
    (docs/guides/refusals.md): a `ValueError` naming the class, the field and the first bad
    index. Traced fields
    (a model built inside `jit`/`vmap`) are left to the run-time checks of `simulate`."""
    for field in dataclasses.fields(module):
        if field.metadata.get("static", False):
            continue
        value = getattr(module, field.name, None)
        if eqx.is_inexact_array(value) and concrete(value) is not None:
            check_finite(value, f"{type(module).__name__}: {field.name}", PARAMETER_FIX)


class AbstractModel(eqx.Module):
    """A model of one experiment: a pure, differentiable function of its parameters.

    Every jaxvs model implements `predict`; `jaxvs.calibration.SimulationError` calibrates
    any of them, `jax.vmap` over the parameters makes a family, `jax.jit` compiles it.
    Concrete NaN/inf parameters are refused when the model is built.
    """

    def __check_init__(self):
        check_parameters(self)

    @abc.abstractmethod
    def predict(
        self, u: Float[ArrayLike, " time *input"], dt: float
    ) -> Float[Array, " time *output"]:
        """The model's output for one experiment.

        **Arguments:**

        - `u`: `(time,)` or `(time, input)` input samples (time axis first), in the units
          the model documents; models that depend on time only use its length.
        - `dt`: sample time [s].

        **Returns:**

        `(time,)` or `(time, output)` predicted output samples.
        """


class AbstractLinearModel(AbstractModel):
    """A continuous-time, finite-dimensional linear time-invariant model.

    Subclasses implement the response of one system; batching over a family is done by
    the free functions of `jaxvs` through [`map_batch`][].
    """

    @property
    @abc.abstractmethod
    def n_inputs(self) -> int:
        """Number of inputs (static)."""

    @property
    @abc.abstractmethod
    def n_outputs(self) -> int:
        """Number of outputs (static)."""

    @property
    @abc.abstractmethod
    def order(self) -> int:
        """Number of states of a minimal realisation (static)."""

    @property
    @abc.abstractmethod
    def batch_shape(self) -> tuple[int, ...]:
        """Leading axes of the parameters: `()` for one system, `(n,)` for a family."""

    @abc.abstractmethod
    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq out in"]:
        """Transfer matrix `G(s)` of one (unbatched) system at complex frequencies `s`."""

    @abc.abstractmethod
    def modal_realisation(self) -> ModalRealisation:
        """A well-conditioned real block-diagonal realisation of one (unbatched) system."""

    def to_state_space(self) -> "StateSpace":
        """Dense state-space form `(A, B, C, D)` of one or a family of systems.

        The realisation is the real block-diagonal (modal) one, which keeps its digits
        at order 8-12 where companion forms do not.
        """
        # The state-space model is built on this interface, so it is looked up at call time.
        from .lti import StateSpace

        return map_batch(lambda m: StateSpace(*m.modal_realisation().dense()), self)

    @property
    def is_siso(self) -> bool:
        return self.n_inputs == 1 and self.n_outputs == 1

    def predict(
        self, u: Float[ArrayLike, " time *input"], dt: float
    ) -> Float[Array, " time *output"]:
        """Zero-order-hold response from rest (`jaxvs.simulate(self, u, dt)`)."""
        # The simulation engine builds on this module, so it is looked up at call time.
        from ._simulate import simulate

        return simulate(self, u, dt)


def check_model(model: Any, who: str) -> None:
    """Refuse anything but a jaxvs linear model with a `TypeError` naming `who`."""
    if not isinstance(model, AbstractLinearModel):
        raise TypeError(
            f"{who}: expected a jaxvs linear model (RationalTF, ModalModel, StateSpace, ...), "
            f"got {type(model).__name__}."
        )


class AbstractFamilyLaw(eqx.Module):
    """How a linear model varies with the position of another axis (a TMF family)."""

    @abc.abstractmethod
    def at(self, position: ArrayLike) -> AbstractLinearModel:
        """The batched linear models at `(n,)` positions [m]."""


def _leaf_batch(leaf: Array, core_ndim: int) -> tuple[int, ...]:
    return tuple(leaf.shape[: leaf.ndim - core_ndim])


def check_batch(shapes: list[tuple[int, ...]], what: str) -> tuple[int, ...]:
    """All fields of a model must carry the same leading batch shape."""
    first = shapes[0]
    for s in shapes[1:]:
        if s != first:
            raise ValueError(
                f"{what}: the parameters carry different leading (family) axes {shapes}. "
                "Give every parameter the same leading batch shape, e.g. (n_positions,), "
                "or broadcast them with jnp.broadcast_to before building the model."
            )
    return first


def map_batch(fn: Callable[..., Any], model: Any, *args: Any, batch_shape=None) -> Any:
    """Apply `fn(model, *args)` to every member of a batched model.

    `args` are either unbatched (shared by every member) or carry the model's batch
    shape as leading axes; pass them already broadcast. The batch axes are flattened,
    mapped with one `jax.vmap`, and restored on every output leaf.
    """
    shape = model.batch_shape if batch_shape is None else batch_shape
    if shape == ():
        return fn(model, *args)
    size = math.prod(shape)
    nd = len(shape)

    def flat(x):
        return jnp.reshape(x, (size,) + x.shape[nd:])

    flat_model = jax.tree_util.tree_map(flat, model)
    arg_axes = []
    flat_args = []
    for a in args:
        if a is None:
            arg_axes.append(None)
            flat_args.append(a)
        elif isinstance(a, tuple) and len(a) == 2 and a[0] == "batched":
            arg_axes.append(0)
            flat_args.append(jax.tree_util.tree_map(flat, a[1]))
        else:
            arg_axes.append(None)
            flat_args.append(a)
    out = jax.vmap(fn, in_axes=(0, *arg_axes))(flat_model, *flat_args)
    return jax.tree_util.tree_map(lambda y: jnp.reshape(y, shape + y.shape[1:]), out)


def batched(x: Any) -> tuple[str, Any]:
    """Mark an argument of [`map_batch`][] as carrying the model's batch axes."""
    return ("batched", x)
