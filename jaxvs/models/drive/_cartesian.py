r"""The three-axis Cartesian machine: three `DriveAxis` drives, the stacking order of the
axes, the tool offset and the 21 geometric errors, combined in the small-angle
homogeneous-transform chain of the kinematic loop.

**Kinematic chain.** The structural loop runs from the workpiece `W` through the axes that
carry it to the frame `F`, and from the frame through the axes that carry the tool to the
tool `T`; `structure="WXYFZT"` is the thesis' machine (Pislaru 2001, §4.3.2: the table X
on the saddle Y on the bed, the head Z on the column), `"WYFXZT"` a moving-column machine
(table Y, column X, head Z). Every axis joint `j` moves the tool-side body relative to the
workpiece-side body by the homogeneous transform

    H_j(q_j) = [ I + [ε_j(q_j)]×   q_j e_j + δ_j(q_j) ]
               [ 0                 1                  ],

`ε_j` the angular and `δ_j` the translational error motion of the axis (ISO 230-1
components, [`MachineErrors`][]), `e_j` its actual direction (squareness), `[·]×` the
skew matrix (first-order rotation). The tool point is

    P(q) = H_1(q_1) H_2(q_2) H_3(q_3) t,

the axes numbered from the workpiece to the tool and `t` the tool offset (tool length and
lateral offset of the tool tip from the spindle gauge point). The volumetric error is
`E(q) = P(q) − (q + t)`; the angles of an axis act on everything after it in the chain, so
the commanded positions of the later axes and the tool offset are their **Abbé arms**.
This is the rigid-body, small-angle formulation of Schwenke, Knapp, Haitjema, Weckenmann,
Schmitt, Delbressine, "Geometric error measurement and compensation of machines — an
update", CIRP Annals 57 (2008), §2.2 and eq. (1)–(3), and of Ramesh, Mannan, Poo, "Error
compensation in machine tools — a review. Part I", Int. J. Mach. Tools Manuf. 40 (2000),
§2; products of two errors are kept (the product of the `H_j`), only the rotations are
linearised, so the chain agrees with the exact rotation matrices to second order in the
angles.

Where on the table the workpiece sits does not add an Abbé arm of its own: the workpiece is
rigid with the table, so its offset enters through the commanded positions `q` at which the
tests run (a laser line at `y = 0.2 m` has the Abbé arm 0.2 m for the yaw of X).

**Reversal.** Static positioning (ISO 230-2) approaches each target from one side; the lost
motion of an axis (backlash, elastic wind-up) then shifts the axis by `±B/2`, `B` the
axis' reversal value (ISO 230-2 §2.9: mean forward minus mean reverse deviation). The
dynamic simulation does not use `B`: there each drive's own backlash and friction act.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real, concrete, is_traced
from .._base import AbstractModel
from ._drive import DriveAxis
from ._geometric_errors import MachineErrors

__all__ = ["STRUCTURES", "CartesianMachine", "MachineResponse"]

STRUCTURES = {
    "WXYFZT": "table X on saddle Y on the bed, head Z on the column (the thesis' vertical "
    "machining centre)",
    "WYFXZT": "table Y on the bed, column X, head Z on the column (moving-column machine)",
}

# heuristic unit guard: no tool offset (gauge length, lateral offset) reaches 2 m
_MAX_OFFSET = 2.0


def _check_structure(structure: str) -> tuple[int, int, int]:
    ok = (
        isinstance(structure, str)
        and len(structure) == 6
        and structure[0] == "W"
        and structure[-1] == "T"
        and sorted(structure[1:-1]) == sorted("XYZF")
    )
    if not ok:
        raise ValueError(
            f"CartesianMachine: structure must read from the workpiece W through the axes "
            f"carrying it, the frame F, the axes carrying the tool, to the tool T, e.g. "
            f"{' or '.join(repr(k) for k in STRUCTURES)}; got {structure!r}."
        )
    return tuple("XYZ".index(c) for c in structure if c in "XYZ")  # type: ignore[return-value]


class MachineResponse(eqx.Module):
    """The simulated response of a [`CartesianMachine`][] at the sample times.

    **Fields:**

    - `t`: `(time,)` [s].
    - `reference`: `(time, 3)` commanded axis positions [m].
    - `axes`: `(time, 3)` actual axis (table / saddle / head) positions from the drives [m].
    - `tool`: `(time, 3)` actual tool point relative to the workpiece [m] (chain of the
      geometric errors at the actual axis positions, tool offset included).
    - `error`: `(time, 3)` `tool − (reference + tool_offset)` [m]: the 3-D path error,
      drive lag plus geometry.
    """

    t: Array
    reference: Array
    axes: Array
    tool: Array
    error: Array


class CartesianMachine(AbstractModel):
    r"""A three-axis Cartesian machine tool (see the module docstring for the chain).

    **Arguments:**

    - `x_axis`, `y_axis`, `z_axis`: the `DriveAxis` of each axis (positions in m).
    - `errors`: [`MachineErrors`][] (the 21 components and the travel).
    - `structure`: stacking order, a string from `W` to `T` (static; default the thesis'
      `"WXYFZT"`; see `STRUCTURES`).
    - `tool_offset`: `(3,)` tool tip relative to the spindle gauge point [m] (e.g.
      `(0, 0, −0.15)` for a 150 mm tool).
    - `reversal`: `(3,)` ISO 230-2 reversal value `B` of each axis [m] for static
      positioning tests (default 0).
    """

    x_axis: DriveAxis
    y_axis: DriveAxis
    z_axis: DriveAxis
    errors: MachineErrors
    tool_offset: Float[Array, "3"]
    reversal: Float[Array, "3"]
    structure: str = eqx.field(static=True)

    def __init__(
        self,
        x_axis: DriveAxis,
        y_axis: DriveAxis,
        z_axis: DriveAxis,
        errors: MachineErrors,
        *,
        structure: str = "WXYFZT",
        tool_offset: ArrayLike = (0.0, 0.0, 0.0),
        reversal: ArrayLike = (0.0, 0.0, 0.0),
    ):
        w = "CartesianMachine"
        for name, ax in (("x_axis", x_axis), ("y_axis", y_axis), ("z_axis", z_axis)):
            if not isinstance(ax, DriveAxis):
                raise TypeError(
                    f"{w}: {name} must be a jaxvs.models.DriveAxis; got {type(ax).__name__}."
                )
        if not isinstance(errors, MachineErrors):
            raise TypeError(
                f"{w}: errors must be jaxvs.models.MachineErrors (the 21 components); got "
                f"{type(errors).__name__}."
            )
        _check_structure(structure)
        t = as_real(tool_offset, f"{w}: tool_offset")
        b = as_real(reversal, f"{w}: reversal")
        for name, v, limit in (("tool_offset", t, _MAX_OFFSET), ("reversal", b, 1e-3)):
            if v.shape != (3,):
                raise ValueError(
                    f"{w}: {name} must be a (3,) vector (x, y, z) in m; got {v.shape}."
                )
            c = concrete(v)
            if c is not None and np.max(np.abs(c)) > limit:
                raise ValueError(
                    f"{w}: {name} {c.tolist()} is larger than {limit:g} m; it is probably in "
                    "mm — give it in m."
                )
        self.x_axis, self.y_axis, self.z_axis = x_axis, y_axis, z_axis
        self.errors = errors
        self.structure = structure
        self.tool_offset = t
        self.reversal = b

    # ------------------------------------------------------------------ geometry
    @property
    def chain(self) -> tuple[int, int, int]:
        """The axes (0 = X, 1 = Y, 2 = Z) from the workpiece to the tool."""
        return _check_structure(self.structure)

    @property
    def travel(self) -> tuple[tuple[float, float], ...]:
        return self.errors.travel

    def tool_point(
        self,
        q: Float[ArrayLike, "... 3"],
        direction: Float[ArrayLike, "... 3"] | None = None,
        *,
        tool_offset: Float[ArrayLike, "... 3"] | None = None,
    ) -> Float[Array, "... 3"]:
        """Actual tool point `P(q)` relative to the workpiece [m] (the chain of the module
        docstring) at commanded axis positions `q` [m], any leading shape.

        `direction`: approach direction of each axis (+1, −1, or 0 for none), which
        shifts the axis by `direction · B / 2` (reversal); `tool_offset` replaces the
        machine's (an instrument's optic on the spindle, for a test)."""
        q = jnp.asarray(q)
        t = self.tool_offset if tool_offset is None else jnp.asarray(tool_offset, q.dtype)
        if direction is not None:
            q = q + jnp.asarray(direction, q.dtype) * self.reversal / 2
        dirs = self.errors.directions()
        P = jnp.broadcast_to(t, q.shape)
        for j in reversed(self.chain):
            delta, eps = self.errors.axis_motion(q[..., j], j)
            P = P + jnp.cross(eps, P) + q[..., j, None] * dirs[j] + delta
        return P

    def tool_orientation(self, q: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
        """Small rotation `(…, 3)` [rad] of the tool relative to the workpiece at commanded
        positions `q`: the sum of the axes' angular errors (first order)."""
        q = jnp.asarray(q)
        return sum(self.errors.axis_motion(q[..., j], j)[1] for j in range(3))

    def volumetric_error(self, x: ArrayLike, y: ArrayLike, z: ArrayLike) -> Float[Array, "... 3"]:
        r"""Volumetric error `E = P(q) − (q + t)` [m] at commanded positions (x, y, z) [m],
        broadcast against each other (a `50×50×50` grid from `jnp.meshgrid` is one call);
        returns `(..., 3)`.

        **Raises:** `ValueError` for positions outside the travel (with concrete input).
        """
        x, y, z = (jnp.asarray(v, jnp.result_type(float)) for v in (x, y, z))
        for k, v in enumerate((x, y, z)):
            c = concrete(v)
            lo, hi = self.travel[k]
            tol = 1e-9 * (hi - lo)
            if c is not None and c.size and (c.min() < lo - tol or c.max() > hi + tol):
                raise ValueError(
                    f"CartesianMachine.volumetric_error: {'xyz'[k]} spans {c.min():.4g}.."
                    f"{c.max():.4g} m outside the travel {lo:.4g}..{hi:.4g} m (the error "
                    "curves are defined over the travel only); are the positions in mm?"
                )
        q = jnp.stack(jnp.broadcast_arrays(x, y, z), axis=-1)
        return _volumetric(self, q)

    # ------------------------------------------------------------------ dynamics
    def simulate(
        self, reference: Float[ArrayLike, "time 3"], dt: float, *, check: bool = True
    ) -> MachineResponse:
        """The three drives follow the 3-D reference (each from rest at its first point,
        with its own loops, friction and backlash) and the geometric errors map their
        actual positions to the tool; one compiled call.

        **Arguments:**

        - `reference`: `(time, 3)` commanded axis positions [m] sampled every `dt`.
        - `dt`: sample time [s] (a digital drive's `sample_time`).
        - `check`: check each drive's loop stability first (concrete parameters).

        **Returns:** a [`MachineResponse`][].
        """
        r = jnp.asarray(reference)
        if r.ndim != 2 or r.shape[1] != 3 or r.shape[0] < 2:
            raise ValueError(
                f"CartesianMachine.simulate: reference must be (time, 3) with >= 2 samples "
                f"(columns x, y, z in m); got shape {r.shape}."
            )
        if not jnp.issubdtype(r.dtype, jnp.floating):
            r = r.astype(jnp.result_type(float))
        c = concrete(r)
        if c is not None:
            span = np.asarray(self.travel)
            if np.any(c < span[:, 0] - 1e-6) or np.any(c > span[:, 1] + 1e-6):
                raise ValueError(
                    "CartesianMachine.simulate: the reference leaves the travel "
                    f"{[list(s) for s in self.travel]} m; are the positions in mm?"
                )
        if check and not is_traced((self, r)):
            for ax in (self.x_axis, self.y_axis, self.z_axis):
                ax.check_stability()
        return _simulate(self, r, float(dt))

    def predict(self, u: Float[ArrayLike, "time 3"], dt: float) -> Float[Array, "time 3"]:
        """Actual tool point `(time, 3)` [m] following the reference `u` `(time, 3)`."""
        return self.simulate(u, dt, check=False).tool


@eqx.filter_jit
def _volumetric(machine: CartesianMachine, q):
    return machine.tool_point(q) - q - machine.tool_offset


@eqx.filter_jit
def _simulate(machine: CartesianMachine, r, dt):
    axes = jnp.stack(
        [
            ax.simulate(r[:, k], dt, q0=r[0, k], check=False).position
            for k, ax in enumerate((machine.x_axis, machine.y_axis, machine.z_axis))
        ],
        axis=-1,
    )
    tool = machine.tool_point(axes)
    return MachineResponse(
        t=dt * jnp.arange(r.shape[0], dtype=r.dtype),
        reference=r,
        axes=axes,
        tool=tool,
        error=tool - r - machine.tool_offset,
    )
