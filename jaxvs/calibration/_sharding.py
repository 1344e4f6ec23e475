"""Families and parameter studies sharded across devices with `jax.sharding`.

A family (one model per position of another axis, one calibration per member, one grid
point of a parameter study) is embarrassingly parallel along its leading axis. These
functions lay that axis over a one-dimensional `jax.sharding.Mesh` and run the
single-device code on every shard with `jax.shard_map`: each device computes its members
exactly as one device would compute them all (no communication, no reordering of sums),
so sharded and unsharded results agree to floating-point rounding.

The same code runs on several CPU devices of one host
(`XLA_FLAGS=--xla_force_host_platform_device_count=8`), on several GPUs, and on several
hosts after `jax.distributed.initialize()` (the mesh then spans every process's devices;
see the documentation's "Scale-out" page for a worked example).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Unpack

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array, ArrayLike, PyTree

from .._misc import timed_call
from .._progress import Progress
from ..models import AbstractLinearModel, simulate
from ._calibrate import (
    CalibrateOptions,
    CalibrationError,
    CalibrationResult,
    SolveOptions,
    _failure_message,
    free_spec,
)
from ._family import (
    _check_batched,
    _family_impl,
    _index,
    _n_positions,
    _prepare_family,
    _solve_settings,
)
from ._parametrise import is_parameter
from ._residuals import AbstractResidual
from ._results import RESULTS
from ._solvers import make_solver

__all__ = [
    "SweepResult",
    "calibrate_family_sharded",
    "family_mesh",
    "shard_family",
    "simulate_sharded",
    "sweep",
]

FAMILY_AXIS = "family"


def family_mesh(
    n_devices: int | None = None,
    *,
    devices: Sequence[Any] | None = None,
    axis_name: str = FAMILY_AXIS,
) -> Mesh:
    """A one-dimensional device mesh for the family axis.

    **Arguments:**

    - `n_devices`: how many devices to use (the first `n_devices` of `devices`);
      default all.
    - `devices`: the devices (default `jax.devices()`: every device of every process, so
      after `jax.distributed.initialize()` the mesh spans all hosts).
    - `axis_name`: the mesh axis name (default `"family"`).

    **Returns:**

    A `jax.sharding.Mesh` of shape `(n_devices,)`.

    **Example:**

    ```python
    # XLA_FLAGS=--xla_force_host_platform_device_count=8 set before importing jax
    mesh = jaxvs.family_mesh()            # 8 CPU devices
    y = jaxvs.simulate_sharded(family, u, dt, mesh=mesh)
    ```
    """
    devs = list(jax.devices() if devices is None else devices)
    if n_devices is not None:
        if not isinstance(n_devices, int) or not 1 <= n_devices <= len(devs):
            raise ValueError(
                f"family_mesh: n_devices must be an int in 1..{len(devs)} (the devices "
                f"available); got {n_devices!r}. On CPU, more devices come from "
                "XLA_FLAGS=--xla_force_host_platform_device_count=N set before importing jax."
            )
        devs = devs[:n_devices]
    return Mesh(np.asarray(devs), (axis_name,))


def _axis(mesh: Mesh) -> str:
    if not isinstance(mesh, Mesh):
        raise TypeError(
            f"expected a jax.sharding.Mesh (e.g. jaxvs.family_mesh()); got {type(mesh).__name__}."
        )
    if len(mesh.axis_names) != 1:
        raise ValueError(
            f"the family is laid over a one-dimensional mesh; this mesh has axes "
            f"{mesh.axis_names}. Build one with jaxvs.family_mesh()."
        )
    return mesh.axis_names[0]


def _check_divides(n: int, mesh: Mesh, who: str) -> None:
    d = mesh.devices.size
    if n % d:
        up = -(-n // d) * d
        divisors = [k for k in range(1, d + 1) if n % k == 0]
        raise ValueError(
            f"{who}: a family of {n} members does not divide over a mesh of {d} devices. "
            f"Pad the family to {up} members (repeat the last member and drop its results), "
            f"or use a mesh of {max(divisors)} devices (jaxvs.family_mesh({max(divisors)}))."
        )


def _leading(tree: PyTree, who: str) -> int:
    sizes = {x.shape[0] for x in jax.tree_util.tree_leaves(tree) if eqx.is_array(x) and x.ndim}
    if len(sizes) != 1:
        raise ValueError(
            f"{who}: every array must carry the family axis first with one size; got "
            f"leading sizes {sorted(sizes) or 'none'}."
        )
    return sizes.pop()


def _put(x: Any, sharding: NamedSharding) -> Any:
    if not eqx.is_array(x):
        return x
    if isinstance(x, jax.Array) and x.sharding == sharding:
        return x
    if isinstance(x, jax.Array) and not x.is_fully_addressable:
        return jax.device_put(x, sharding)
    host = np.asarray(x)
    # make_array_from_callback also works across processes (each host fills its shards)
    return jax.make_array_from_callback(host.shape, sharding, lambda idx: host[idx])


def shard_family(tree: PyTree, mesh: Mesh) -> PyTree:
    """Place a family (every array leaf with the family axis first) across `mesh`.

    **Arguments:**

    - `tree`: a batched model, data pytree, ... Every array leaf must have the same
      leading size `n`; 0-d leaves are replicated.
    - `mesh`: a one-dimensional mesh (see [`family_mesh`][jaxvs.calibration.family_mesh]).

    **Returns:**

    The same pytree with `jax.Array` leaves sharded along axis 0 over the mesh.

    **Raises:**

    `ValueError` when the leading sizes differ, or when `n` is not a multiple of the
    number of devices (the message gives the padded size and a mesh that divides `n`).
    """
    axis = _axis(mesh)
    n = _leading(tree, "shard_family")
    _check_divides(n, mesh, "shard_family")
    rows, rep = NamedSharding(mesh, P(axis)), NamedSharding(mesh, P())
    return jax.tree_util.tree_map(
        lambda x: _put(x, rows if eqx.is_array(x) and x.ndim else rep), tree
    )


def _gather(x: Any) -> np.ndarray:
    if isinstance(x, jax.Array) and not x.is_fully_addressable:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)


# ----------------------------------------------------------------------------- simulate


@functools.lru_cache(maxsize=32)
def _simulators(mesh, static, dt, method, u_batched, x0_batched):
    """One compiled sharded simulator per (mesh, model structure, dt, method, batching)."""
    axis = mesh.axis_names[0]

    def local(dyn, u, x0):
        return simulate(eqx.combine(dyn, static), u, dt, method=method, x0=x0)

    return jax.jit(
        jax.shard_map(
            local,
            mesh=mesh,
            in_specs=(P(axis), P(axis) if u_batched else P(), P(axis) if x0_batched else P()),
            out_specs=P(axis),
            check_vma=False,
        )
    )


def simulate_sharded(
    model: AbstractLinearModel,
    u: ArrayLike,
    dt: float,
    *,
    mesh: Mesh,
    method: str = "zoh",
    x0: ArrayLike | None = None,
) -> Array:
    """[`simulate`][jaxvs.models.simulate] a family spread over the devices of `mesh`.

    Each device simulates its block of members with the single-device engine; the result
    equals `jaxvs.simulate(model, u, dt, method=method, x0=x0)` to rounding.

    **Arguments:**

    - `model`: a family: a jaxvs linear model with one batch axis `(n,)`.
    - `u`: inputs, either one per member `(n, time[, in])` or shared `(time[, in])`.
    - `dt`: sample time [s].
    - `mesh`: a one-dimensional mesh whose size divides `n`.
    - `method`, `x0`: as for `simulate` (`x0` shared `(order,)` or `(n, order)`).

    **Returns:**

    `(n, time[, out])`, a `jax.Array` sharded along the family axis (`np.asarray` gathers
    it on one host).

    **Raises:**

    `ValueError` for an unbatched model or a family whose size the mesh does not divide.
    """
    axis = _axis(mesh)
    if not isinstance(model, AbstractLinearModel):
        raise TypeError(
            f"simulate_sharded: expected a jaxvs linear model; got {type(model).__name__}."
        )
    if len(model.batch_shape) != 1:
        raise ValueError(
            f"simulate_sharded: the model must be a family with one batch axis (n,); its "
            f"batch shape is {model.batch_shape}. Reshape the parameters to (n, ...)."
        )
    n = model.batch_shape[0]
    _check_divides(n, mesh, "simulate_sharded")
    u = jnp.asarray(u)
    u_batched = u.ndim > (1 if model.n_inputs == 1 else 2)
    x0 = None if x0 is None else jnp.asarray(x0)
    x0_batched = x0 is not None and x0.ndim == 2
    for name, arr, batched in (("u", u, u_batched), ("x0", x0, x0_batched)):
        if batched and arr is not None and arr.shape[0] != n:
            raise ValueError(
                f"simulate_sharded: {name} has {arr.shape[0]} rows but the family {n} members."
            )
    dyn, static = eqx.partition(model, eqx.is_array)
    key = (mesh, static, float(dt), method, u_batched, x0_batched)
    try:
        fn = _simulators(*key)
    except TypeError:  # unhashable static fields: compile without caching
        fn = _simulators.__wrapped__(*key)
    rows, rep = NamedSharding(mesh, P(axis)), NamedSharding(mesh, P())
    dyn = jax.tree_util.tree_map(lambda x: _put(x, rows), dyn)
    u = _put(u, rows if u_batched else rep)
    if x0 is not None:
        x0 = _put(x0, rows if x0_batched else rep)
    return fn(dyn, u, x0)


# ----------------------------------------------------------------------------- calibrate


def calibrate_family_sharded(
    model: PyTree,
    data: Any,
    residual: AbstractResidual,
    solver: Any = None,
    *,
    mesh: Mesh,
    free: Any = None,
    **options: Unpack[CalibrateOptions],
) -> CalibrationResult:
    """[`calibrate_family`][jaxvs.calibration.calibrate_family] (independent members) over `mesh`.

    Every member is calibrated on its own experiment, as in the first form of
    `calibrate_family`; the members are split over the devices, each device running the
    vectorised solver on its block. Results equal the single-device `calibrate_family`
    to rounding (each member's Levenberg–Marquardt iterations do not depend on the
    others'). Each device of this process runs the compiled solver on its block, with no
    communication between devices. On several *CPU* host devices of one machine the
    blocks run one after another (XLA's CPU runtime can stall when two programs with
    LAPACK calls run at once), so the speed-up is there on GPUs and across hosts, not
    from `--xla_force_host_platform_device_count`.

    **Arguments:**

    - `model`: the batched initial family (every array leaf has the members axis first).
    - `data`: one experiment per member: a list, a pytree with the members axis first,
      or a batched `FRFData`.
    - `residual`: the residual of one member (e.g. `FrequencyError()`).
    - `mesh`: a one-dimensional mesh whose size divides the number of members.
    - `solver`, `free`, `max_steps`, `rtol`, `atol`, `throw`, `covariance`,
      `confidence`: as for [`calibrate`][jaxvs.calibration.calibrate].

    **Returns:**

    A batched [`CalibrationResult`][jaxvs.calibration.CalibrationResult] (one per member) with
    `stats["compile_time"]` and `stats["run_time"]` of the sharded call.

    **Raises:**

    `ValueError` when the mesh does not divide the family; `CalibrationError` when a
    member fails and `throw=True`.
    """
    o = SolveOptions.of("calibrate_family_sharded", options)
    axis = _axis(mesh)
    if not isinstance(residual, AbstractResidual):
        raise TypeError(
            "calibrate_family_sharded: `residual` is the residual of one member (e.g. "
            f"FrequencyError()); got {type(residual).__name__}."
        )
    solver = make_solver(solver, o.rtol, o.atol)
    prepared = _prepare_family(residual, data)
    n = _n_positions(prepared)
    _check_batched(model, jax.tree_util.tree_map(lambda _: 0, model, is_leaf=is_parameter), n)
    _check_divides(n, mesh, "calibrate_family_sharded")
    spec = free_spec(model, free)
    # The members are laid over the mesh; every device runs the vmapped solver on its
    # block (see timed_call for why neither shard_map nor the SPMD partitioner).
    rows = NamedSharding(mesh, P(axis))
    m_dyn, m_static = eqx.partition(model, eqx.is_array)
    m_dyn = jax.tree_util.tree_map(lambda x: _put(x, rows), m_dyn)
    d_dyn, d_static = eqx.partition(prepared, eqx.is_array)
    d_dyn = jax.tree_util.tree_map(lambda x: _put(x, rows), d_dyn)
    out, t_compile, t_run = timed_call(
        _family_impl,
        eqx.combine(m_dyn, m_static),
        eqx.combine(d_dyn, d_static),
        residual,
        solver,
        spec,
        _solve_settings(o),
        mesh=mesh,
    )
    shape = out.stats["compile_time"].shape
    out = eqx.tree_at(
        lambda o: (o.stats["compile_time"], o.stats["run_time"]),
        out,
        (jnp.full(shape, t_compile), jnp.full(shape, t_run)),
    )
    if o.throw:
        failed = _gather(out.result._value) != _gather(RESULTS.successful._value)
        if np.any(failed):
            bad = np.flatnonzero(failed)
            first = _index(jax.tree_util.tree_map(_gather_if_array, out), int(bad[0]))
            raise CalibrationError(
                f"calibrate_family_sharded: {bad.size} of {n} members failed (indices "
                f"{bad[:10].tolist()}{' ...' if bad.size > 10 else ''}). Member {bad[0]}: "
                + (_failure_message(first) or "")
            )
    return out


def _gather_if_array(x: Any) -> Any:
    return jnp.asarray(_gather(x)) if eqx.is_array(x) else x


# ----------------------------------------------------------------------------- sweep


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A labelled parameter study: outputs on the grid of the swept parameters.

    **Fields:**

    - `dims`: the swept parameters' names, in grid order (or `("point",)` for a list of
      points).
    - `coords`: name -> 1-D numpy array of its values (and any output coordinates).
    - `data`: output name -> numpy array of shape `grid_shape + output_shape`.
    - `output_dims`: output name -> names of its trailing (output) axes.
    - `stats`: `compile_time`, `run_time` [s], `n_points`, `n_devices`, `n_chunks`.

    `result["H"]` is `result.data["H"]`; [`to_xarray`][jaxvs.calibration.SweepResult.to_xarray]
    returns an `xarray.Dataset` with the same labels.
    """

    dims: tuple[str, ...]
    coords: dict[str, np.ndarray]
    data: dict[str, np.ndarray]
    output_dims: dict[str, tuple[str, ...]]
    stats: dict[str, float]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.data[name]

    @property
    def shape(self) -> tuple[int, ...]:
        """The grid shape."""
        return tuple(len(self.coords[d]) for d in self.dims)

    def to_xarray(self) -> Any:
        """The result as an `xarray.Dataset` (needs `pip install xarray`)."""
        try:
            import xarray as xr
        except ImportError as e:
            raise ImportError(
                "SweepResult.to_xarray needs xarray: pip install 'xarray>=2024.1' (or use "
                "result.data and result.coords directly)."
            ) from e
        variables = {k: (self.dims + self.output_dims[k], v) for k, v in self.data.items()}
        return xr.Dataset(variables, coords=dict(self.coords))


def _points(
    grid: Mapping[str, ArrayLike], product: bool
) -> tuple[tuple[str, ...], dict[str, np.ndarray], dict[str, np.ndarray], tuple[int, ...]]:
    if not isinstance(grid, Mapping) or not grid:
        raise TypeError(
            "sweep: grid must be a non-empty dict name -> 1-D values, e.g. "
            "{'y': jnp.linspace(0, 0.5, 16), 'zeta': jnp.array([0.01, 0.02])}."
        )
    values = {}
    for k, v in grid.items():
        if not isinstance(k, str):
            raise TypeError(f"sweep: grid keys are parameter names (str); got {k!r}.")
        a = np.asarray(v)
        if a.ndim != 1 or a.shape[0] == 0:
            raise ValueError(
                f"sweep: grid[{k!r}] must be a non-empty 1-D array; got shape {a.shape}."
            )
        values[k] = a
    if product:
        dims = tuple(values)
        mesh = np.meshgrid(*values.values(), indexing="ij")
        flat = {k: m.reshape(-1) for k, m in zip(dims, mesh)}
        return dims, values, flat, tuple(len(v) for v in values.values())
    lengths = {len(v) for v in values.values()}
    if len(lengths) != 1:
        raise ValueError(
            f"sweep: with product=False every grid entry is one column of a list of points "
            f"and needs the same length; got lengths { {k: len(v) for k, v in values.items()} }."
        )
    n = lengths.pop()
    coords = {"point": np.arange(n), **values}
    return ("point",), coords, dict(values), (n,)


def sweep(
    fn: Callable[[dict[str, Array], Any], PyTree],
    grid: Mapping[str, ArrayLike],
    args: Any = None,
    *,
    mesh: Mesh | None = None,
    product: bool = True,
    chunk_size: int | None = None,
    output_dims: Mapping[str, Sequence[str]] | None = None,
    output_coords: Mapping[str, ArrayLike] | None = None,
    progress: bool | None = None,
) -> SweepResult:
    """Evaluate `fn` on every point of a parameter grid in one sharded, vectorised call.

    `fn(point, args)` computes the outputs of one point: `point` maps each swept name to
    a scalar; `args` carries everything shared (models, data, frequency grid). The grid
    is flattened, padded to a multiple of the number of devices (pad results are
    dropped), split over `mesh` and evaluated with `vmap` on each device; the outputs come
    back on the grid with labels.

    **Arguments:**

    - `fn`: `fn(point: dict[str, scalar], args) -> array or dict of arrays`, pure and
      traceable (it is `vmap`ped and `jit`ted).
    - `grid`: name -> 1-D values. With `product=True` (default) the Cartesian product is
      swept (grid shape = the lengths, in the dict's order); with `product=False` the
      entries are columns of one list of points (dimension `"point"`).
    - `args`: the shared data (any pytree; arrays are replicated on every device).
    - `mesh`: a one-dimensional mesh ([`family_mesh`][jaxvs.calibration.family_mesh]);
      `None` runs on the default device.
    - `chunk_size`: evaluate this many points per call (rounded up to a multiple of the
      mesh size) to bound memory and show progress; default all points in one call.
    - `output_dims`: output name -> names of its trailing axes (default
      `"<name>_dim0"`, ...); a plain array output is named `"value"`.
    - `output_coords`: coordinate values of output axes (e.g. `{"omega": omega}`).
    - `progress`: show a progress bar over chunks (`None`: on a terminal; see
      [`Progress`][jaxvs.Progress]); Ctrl-C stops between chunks with a clean message.

    **Returns:**

    A [`SweepResult`][jaxvs.calibration.SweepResult] (`.to_xarray()` for an `xarray.Dataset`).

    **Example:**

    ```python
    def peak(point, omega):
        model = jaxvs.ModalModel(point["wn"][None], point["zeta"][None], jnp.ones(1))
        return {"H": jnp.abs(jaxvs.frequency_response(model, omega))}

    res = jaxvs.sweep(peak, {"wn": jnp.linspace(50, 150, 64), "zeta": jnp.array([0.01, 0.05])},
                      omega, mesh=jaxvs.family_mesh(), output_dims={"H": ("omega",)},
                      output_coords={"omega": omega})
    res.to_xarray()["H"].sel(zeta=0.05).max("omega")
    ```
    """
    if not callable(fn):
        raise TypeError(f"sweep: fn must be a function fn(point, args); got {type(fn).__name__}.")
    dims, coords, flat, grid_shape = _points(grid, product)
    n = math.prod(grid_shape)
    n_dev = 1 if mesh is None else mesh.devices.size
    axis = None if mesh is None else _axis(mesh)
    size = n if chunk_size is None else int(chunk_size)
    if size < 1:
        raise ValueError(f"sweep: chunk_size must be >= 1; got {chunk_size!r}.")
    size = -(-min(size, n) // n_dev) * n_dev
    n_chunks = -(-n // size)
    padded = n_chunks * size
    pts = {k: np.concatenate([v, np.repeat(v[-1:], padded - n)]) for k, v in flat.items()}
    a_dyn, a_static = eqx.partition(args, eqx.is_array)

    def one(point, a_dyn):
        return fn(point, eqx.combine(a_dyn, a_static))

    def block(points, a_dyn):
        return jax.vmap(one, in_axes=(0, None))(points, a_dyn)

    # The points are laid over the mesh; every device evaluates its block (timed_call),
    # which also holds for `fn`s that run lineax/optimistix solves.
    compiled = block
    if mesh is not None:
        rep = NamedSharding(mesh, P())
        a_dyn = jax.tree_util.tree_map(lambda x: _put(x, rep), a_dyn)
    dtype = jnp.result_type(float)
    outs: list[Any] = []
    t_compile = t_run = 0.0
    disable = {None: None, True: False, False: True}[progress]
    with Progress("sweep", total=padded, unit="point", disable=disable) as bar:
        for c in range(n_chunks):
            chunk = {
                k: jnp.asarray(v[c * size : (c + 1) * size], dtype=_dtype(v, dtype))
                for k, v in pts.items()
            }
            if mesh is not None:
                rows = NamedSharding(mesh, P(axis))
                chunk = {k: _put(v, rows) for k, v in chunk.items()}
            out, tc, tr = timed_call(compiled, chunk, a_dyn, mesh=mesh)
            t_compile += tc
            t_run += tr
            outs.append(jax.tree_util.tree_map(_gather, out))
            bar.update(size)
    if not outs:
        raise ValueError("sweep: the grid is empty.")
    first = outs[0]
    if isinstance(first, Mapping):
        names = list(first)
        stacked = {k: np.concatenate([o[k] for o in outs])[:n] for k in names}
    elif eqx.is_array(first):
        stacked = {"value": np.concatenate(outs)[:n]}
    else:
        raise TypeError(
            f"sweep: fn must return an array or a dict name -> array; got {type(first).__name__}."
        )
    data = {k: v.reshape(grid_shape + v.shape[1:]) for k, v in stacked.items()}
    od = {}
    for k, v in data.items():
        trailing = v.ndim - len(grid_shape)
        given = tuple((output_dims or {}).get(k, ()))
        if given and len(given) != trailing:
            raise ValueError(
                f"sweep: output_dims[{k!r}] = {given} names {len(given)} axes but the output "
                f"has {trailing} trailing axes (shape {v.shape[len(grid_shape) :]})."
            )
        od[k] = given or tuple(f"{k}_dim{i}" for i in range(trailing))
    all_coords = dict(coords)
    for k, v in (output_coords or {}).items():
        all_coords[k] = np.asarray(v)
    stats = {
        "compile_time": t_compile,
        "run_time": t_run,
        "n_points": n,
        "n_devices": n_dev,
        "n_chunks": n_chunks,
    }
    return SweepResult(dims, all_coords, data, od, stats)


def _dtype(v: np.ndarray, default) -> Any:
    if np.issubdtype(v.dtype, np.floating):
        return default
    return None
