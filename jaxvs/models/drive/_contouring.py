r"""Two-axis (XY) contouring: two drives, geometric-error lookup tables, the ball-bar test.

The contouring model of the drive study (Pislaru 2001, §4.3.2, §6.4–6.5 and Appendix
D5–D7): the X and Y drives follow their references independently (Cartesian axes do not
couple dynamically), and the tool's actual position is their positions distorted by the
machine's geometric errors, measured by laser interferometry and stored as lookup tables
(ISO 230-1; Ramesh, Mannan, Poo, "Error compensation in machine tools — a review",
Int. J. Mach. Tools Manuf. 40, 2000):

    X = x + δ_xx(x) + δ_xy(y) + α · y
    Y = y + δ_yy(y) + δ_yx(x)

with `δ_xx`, `δ_yy` the positioning (linear displacement) errors of each axis,
`δ_yx(x)` the straightness of the X axis (its Y deviation along its travel), `δ_xy(y)` the
straightness of the Y axis, and `α` [rad] the out-of-squareness of Y against X (Y leans
towards +X for `α > 0`). Tables are linearly interpolated (held constant beyond their
ends).

The **ball-bar (circular) test** (ISO 230-4; Kakino et al. 1993): the axes interpolate a
circle of radius `R` at feed `F` and a telescopic ball bar records the radius. The plot of
`ΔR(θ)` shows reversal spikes where an axis changes direction (friction), an ellipse at
±45° when the two position loops differ (servo mismatch), an ellipse at ±45° that does not
change with direction or feed (squareness), and a smaller circle from the loops' lag
(`R (|G(jω)| − 1)`, `ω = F/R`).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._drive import DriveAxis

__all__ = ["BallbarResult", "GeometricErrors", "XYTable", "ballbar_test", "circle_path"]


def _table(grid, values, name: str) -> tuple[Array, Array]:
    g = jnp.asarray(grid, dtype=jnp.result_type(float))
    v = jnp.asarray(values, dtype=g.dtype)
    if g.ndim != 1 or g.shape != v.shape or g.shape[0] < 2:
        raise ValueError(
            f"GeometricErrors: the {name} table needs 1-D positions and values of the same "
            f"length (>= 2); got {g.shape} and {v.shape}."
        )
    gc = np.asarray(g)
    if np.any(np.diff(gc) <= 0):
        raise ValueError(f"GeometricErrors: the {name} table positions must be increasing.")
    return g, v


class GeometricErrors(eqx.Module):
    """Geometric errors of an XY plane as lookup tables (see the module docstring).

    **Arguments** (each table a pair `(positions, errors)` in metres, or `None` for no
    error):

    - `positioning_x`: `δ_xx(x)`, error along X as a function of x.
    - `positioning_y`: `δ_yy(y)`.
    - `straightness_x`: `δ_yx(x)`, Y deviation while X travels.
    - `straightness_y`: `δ_xy(y)`, X deviation while Y travels.
    - `squareness`: `α` [rad], out-of-squareness of Y against X.
    """

    tables: dict[str, tuple[Array, Array]]
    squareness: Float[Array, ""]

    def __init__(
        self,
        *,
        positioning_x=None,
        positioning_y=None,
        straightness_x=None,
        straightness_y=None,
        squareness: ArrayLike = 0.0,
    ):
        tables = {}
        for name, tab in (
            ("positioning_x", positioning_x),
            ("positioning_y", positioning_y),
            ("straightness_x", straightness_x),
            ("straightness_y", straightness_y),
        ):
            if tab is None:
                tab = ([0.0, 1.0], [0.0, 0.0])
            try:
                grid, vals = tab
            except (TypeError, ValueError):
                raise ValueError(
                    f"GeometricErrors: {name} must be a pair (positions, errors) or None."
                ) from None
            tables[name] = _table(grid, vals, name)
        self.tables = tables
        self.squareness = jnp.asarray(squareness, dtype=jnp.result_type(float))

    def _lookup(self, name, x):
        g, v = self.tables[name]
        return jnp.interp(x, g, v)

    def __call__(self, x: ArrayLike, y: ArrayLike) -> tuple[Array, Array]:
        """Actual position `(X, Y)` [m] of the tool for axis positions `(x, y)` [m]."""
        x, y = jnp.asarray(x), jnp.asarray(y)
        X = x + self._lookup("positioning_x", x) + self._lookup("straightness_y", y)
        X = X + self.squareness * y
        Y = y + self._lookup("positioning_y", y) + self._lookup("straightness_x", x)
        return X, Y


class XYTable(eqx.Module):
    """Two drives (X and Y) and the geometric errors of their plane.

    **Arguments:**

    - `x_axis`, `y_axis`: `jaxvs.models.DriveAxis` of each axis (positions in m).
    - `errors`: [`GeometricErrors`][] (default: none).
    """

    x_axis: DriveAxis
    y_axis: DriveAxis
    errors: GeometricErrors

    def __init__(self, x_axis: DriveAxis, y_axis: DriveAxis, errors: GeometricErrors | None = None):
        if not isinstance(x_axis, DriveAxis) or not isinstance(y_axis, DriveAxis):
            raise TypeError("XYTable: x_axis and y_axis must be jaxvs.models.DriveAxis.")
        self.x_axis, self.y_axis = x_axis, y_axis
        self.errors = GeometricErrors() if errors is None else errors

    def simulate(
        self, x_ref: Float[ArrayLike, " time"], y_ref: Float[ArrayLike, " time"], dt: float
    ) -> tuple[Array, Array]:
        """Actual tool path `(X, Y)` [m] when the axes follow `(x_ref, y_ref)`: each drive
        simulated from rest at its first reference point, then the geometric errors."""
        x_ref, y_ref = jnp.asarray(x_ref), jnp.asarray(y_ref)
        if x_ref.shape != y_ref.shape or x_ref.ndim != 1:
            raise ValueError(
                f"XYTable.simulate: x_ref {x_ref.shape} and y_ref {y_ref.shape} must be 1-D "
                "and of the same length."
            )
        x = self.x_axis.simulate(x_ref, dt, q0=x_ref[0]).position
        y = self.y_axis.simulate(y_ref, dt, q0=y_ref[0]).position
        return self.errors(x, y)


def circle_path(
    radius: float,
    feed: float,
    dt: float,
    *,
    center: tuple[float, float] = (0.0, 0.0),
    clockwise: bool = False,
    lead: float = np.pi / 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference of a circular interpolation at constant feed, with a lead-in and
    lead-out arc (the measured revolution starts and ends at θ = 0, at `+x` of the centre).

    **Arguments:**

    - `radius`: [m] (> 0); `feed`: path speed [m/s] (> 0); `dt`: sample time [s].
    - `center`: `(x, y)` [m].
    - `clockwise`: direction of travel.
    - `lead`: lead-in and lead-out arc [rad] (>= 0) run before and after the measured
      revolution so that the start-up transient has decayed.

    **Returns:**

    `(t, x, y, theta)`: time [s], references [m] and the commanded angle [rad] (0..2π over
    the measured revolution, beyond it in the leads).
    """
    if not (radius > 0 and feed > 0 and dt > 0 and lead >= 0):
        raise ValueError(
            f"circle_path: radius, feed and dt must be > 0 and lead >= 0; got radius={radius}, "
            f"feed={feed}, dt={dt}, lead={lead}."
        )
    omega = feed / radius
    if omega * dt > 0.1:
        raise ValueError(
            f"circle_path: {omega * dt:.3g} rad per sample is too coarse for a circle; lower "
            "the feed or the sample time (≤ 0.1 rad per sample)."
        )
    total = (2 * np.pi + 2 * lead) / omega
    t = dt * np.arange(int(np.ceil(total / dt)) + 1)
    theta = omega * t - lead
    sgn = -1.0 if clockwise else 1.0
    x = center[0] + radius * np.cos(sgn * theta)
    y = center[1] + radius * np.sin(sgn * theta)
    return t, x, y, theta


class BallbarResult(eqx.Module):
    """The result of [`ballbar_test`][] over the measured revolution.

    **Fields:**

    - `theta`: `(n,)` angle of the actual position around the centre [rad], in [0, 2π).
    - `radial_error`: `(n,)` `|P − c| − R` [m].
    - `x`, `y`: `(n,)` actual tool position [m]; `t`: `(n,)` [s].
    - `radius`, `feed`: the test's nominal radius [m] and feed [m/s].
    """

    theta: Array
    radial_error: Array
    x: Array
    y: Array
    t: Array
    radius: float = eqx.field(static=True)
    feed: float = eqx.field(static=True)


def ballbar_test(
    table: XYTable,
    radius: float,
    feed: float,
    dt: float,
    *,
    center: tuple[float, float] = (0.0, 0.0),
    clockwise: bool = False,
    lead: float = np.pi / 2,
) -> BallbarResult:
    """Simulate a ball-bar circular test of an [`XYTable`][].

    **Arguments:**

    - `table`: the XY model.
    - `radius`: ball-bar length [m]; `feed`: contouring feed [m/s]; `dt`: sample time [s]
      (the controller's for digital drives).
    - `center`, `clockwise`, `lead`: as [`circle_path`][].

    **Returns:**

    A [`BallbarResult`][] (angle, radial deviation, path) over the measured revolution.
    """
    if not isinstance(table, XYTable):
        raise TypeError("ballbar_test: table must be a jaxvs.models.XYTable.")
    t, xr, yr, theta_cmd = circle_path(
        radius, feed, dt, center=center, clockwise=clockwise, lead=lead
    )
    X, Y = table.simulate(xr, yr, dt)
    keep = (theta_cmd >= 0) & (theta_cmd < 2 * np.pi)
    dx, dy = X[keep] - center[0], Y[keep] - center[1]
    theta = jnp.mod(jnp.arctan2(dy, dx), 2 * jnp.pi)
    err = jnp.sqrt(dx**2 + dy**2) - radius
    return BallbarResult(
        theta=theta,
        radial_error=err,
        x=X[keep],
        y=Y[keep],
        t=jnp.asarray(t[keep]),
        radius=float(radius),
        feed=float(feed),
    )
