r"""The machine-tool geometric tests as differentiable functions of a
[`CartesianMachine`][]: what each instrument reads, and its noise.

Every test is an `eqx.Module` with `predict(machine)` (the noise-free readings, a pure
function of the machine's parameters, so any mix of tests calibrates it jointly),
`measure(machine, key)` (readings with the instrument's noise, `runs` repeats) and `sigma`
(the noise standard deviation of one reading, which weights it in a calibration):

- [`LaserLine`][] (ISO 230-2): positioning deviation along an axis at an offset line,
  forward and reverse runs (reversal);
- [`StraightnessLine`][] (ISO 230-1 §8.2): deviation across the motion, least-squares
  line removed;
- [`AngularLine`][] (ISO 230-1 §8.4): relative rotation tool–workpiece (electronic level
  or angular interferometer);
- [`BallbarCircle`][] (ISO 230-4): radius deviation of a quasi-static circle in the XY,
  YZ or ZX plane, mean removed;
- [`DiagonalLine`][] (ISO 230-6): displacement deviation along a body diagonal, forward
  and reverse.

Instruments read *relative* quantities: a laser or level is zeroed at the first target,
a straightness optic is aligned to the line (its slope and offset are lost), a ball bar's
absolute length is only known to the calibrator's accuracy (its mean radius is left out).
These are exactly the reasons why one kind of test alone cannot separate all 21
components (see `jaxvs.studies.machine.identifiability`).
"""

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..._misc import as_real
from ._cartesian import CartesianMachine

__all__ = [
    "AbstractMachineTest",
    "AngularLine",
    "BallbarCircle",
    "DiagonalLine",
    "LaserLine",
    "StraightnessLine",
]

_AXIS = {"x": 0, "y": 1, "z": 2, 0: 0, 1: 1, 2: 2}
_PLANES = {"xy": (0, 1), "yz": (1, 2), "zx": (2, 0)}


def _axis(a, where: str, what: str = "axis") -> int:
    key = a.lower() if isinstance(a, str) else a
    if key not in _AXIS:
        raise ValueError(f"{where}: {what} must be 'x', 'y' or 'z'; got {a!r}.")
    return _AXIS[key]


def _vector(v, where: str, name: str) -> Array:
    a = as_real(v, f"{where}: {name}")
    if a.shape != (3,):
        raise ValueError(f"{where}: {name} must be a (3,) position (x, y, z) in m; got {a.shape}.")
    return a


def _positive(x, where: str, name: str) -> float:
    x = float(x)
    if not (x > 0 and math.isfinite(x)):
        raise ValueError(f"{where}: {name} must be a finite number > 0; got {x}.")
    return x


def _count(n, where: str, name: str, least: int) -> int:
    if not isinstance(n, int) or n < least:
        raise ValueError(f"{where}: {name} must be an int >= {least}; got {n!r}.")
    return n


def _inside(q: np.ndarray, machine: CartesianMachine, where: str) -> None:
    span = np.asarray(machine.travel)
    tol = 1e-9 * np.max(span[:, 1] - span[:, 0])
    bad = (q < span[:, 0] - tol) | (q > span[:, 1] + tol)
    if np.any(bad):
        k = int(np.argwhere(bad)[0][-1])
        raise ValueError(
            f"{where}: the test reaches {'xyz'[k]} = "
            f"{q[..., k].min():.4g}..{q[..., k].max():.4g} m, outside the travel "
            f"{span[k, 0]:.4g}..{span[k, 1]:.4g} m; move it inside the working volume (are "
            "its positions in mm?)."
        )


class AbstractMachineTest(eqx.Module):
    """A geometric test of a [`CartesianMachine`][]: noise-free readings `predict`, noisy
    readings `measure`, the reading noise `sigma`."""

    sigma: eqx.AbstractVar[float]
    runs: eqx.AbstractVar[int]

    @abc.abstractmethod
    def commanded(self, machine: CartesianMachine) -> np.ndarray:
        """`(..., 3)` commanded axis positions [m] of the test (NumPy, static geometry)."""

    @abc.abstractmethod
    def predict(self, machine: CartesianMachine) -> Array:
        """Noise-free readings [m or rad] of the test on `machine`."""

    @property
    def label(self) -> str:
        return type(self).__name__

    def check(self, machine: CartesianMachine) -> None:
        """Refuse a test that leaves the machine's travel (`ValueError`)."""
        _inside(np.asarray(self.commanded(machine)), machine, self.label)

    def measure(self, machine: CartesianMachine, key: PRNGKeyArray) -> Array:
        """`(runs, *readings)` readings with white noise of standard deviation `sigma`."""
        self.check(machine)
        y = self.predict(machine)
        return y + self.sigma * jax.random.normal(key, (self.runs, *y.shape), y.dtype)


def _line_targets(machine, axis: int, position, n: int) -> Array:
    lo, hi = machine.travel[axis]
    s = jnp.linspace(lo, hi, n, dtype=position.dtype)
    return jnp.broadcast_to(position, (n, 3)).at[:, axis].set(s)


class LaserLine(AbstractMachineTest):
    r"""Positioning of one axis along a line, by laser interferometer (ISO 230-2).

    Targets at `n` equally spaced positions over the axis' travel, the other two axes at
    `position` (the offset line: Abbé arms for the pitch and yaw). Forward run (approach
    from below, `+B/2`) then reverse run (from above, `−B/2`); the laser is zeroed at the
    first forward target. Reading: `e·(P(q_i) − P(q_0)) − e·(q_i − q_0)` [m], `e` the axis
    direction.

    **Arguments:** `axis` (`"x"`, `"y"`, `"z"`); `position` `(3,)` [m] (its `axis` entry is
    ignored); `n` targets (>= 3); `bidirectional` (static); `tool_offset` `(3,)` [m] of the
    retro-reflector on the spindle (default the machine's); `sigma` [m] per reading
    (default 0.5 µm); `runs` repeats (ISO 230-2: 5).

    **Returns** of `predict`: `(2, n)` (forward, reverse) or `(1, n)`.
    """

    position: Float[Array, "3"]
    tool_offset: Float[Array, "3"] | None
    axis: int = eqx.field(static=True)
    n: int = eqx.field(static=True)
    bidirectional: bool = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    runs: int = eqx.field(static=True)

    def __init__(
        self, axis, position=(0.0, 0.0, 0.0), *, n: int = 11, bidirectional: bool = True,
        tool_offset=None, sigma: float = 0.5e-6, runs: int = 1,
    ):
        w = "LaserLine"
        self.axis = _axis(axis, w)
        self.position = _vector(position, w, "position")
        self.tool_offset = None if tool_offset is None else _vector(tool_offset, w, "tool_offset")
        self.n = _count(n, w, "n", 3)
        self.bidirectional = bool(bidirectional)
        self.sigma = _positive(sigma, w, "sigma")
        self.runs = _count(runs, w, "runs", 1)

    @property
    def label(self) -> str:
        return f"laser {'XYZ'[self.axis]} at {np.round(np.asarray(self.position), 3).tolist()}"

    def commanded(self, machine):
        return np.asarray(_line_targets(machine, self.axis, self.position, self.n))

    def predict(self, machine):
        q = _line_targets(machine, self.axis, self.position, self.n)
        e = jnp.zeros(3, q.dtype).at[self.axis].set(1.0)
        dirs = [1.0, -1.0] if self.bidirectional else [1.0]
        P0 = machine.tool_point(q[0], e, tool_offset=self.tool_offset)
        out = []
        for d in dirs:
            P = machine.tool_point(q, d * e, tool_offset=self.tool_offset)
            out.append((P - P0)[:, self.axis] - (q[:, self.axis] - q[0, self.axis]))
        return jnp.stack(out)


class StraightnessLine(AbstractMachineTest):
    r"""Straightness of one axis in one perpendicular direction (laser straightness
    optics or a straightedge with a probe, ISO 230-1 §8.2).

    Reading: `e_⊥·(P(q_i) − P(q_0))` [m] with its least-squares line over the targets
    removed (the optic is aligned to the line, so its slope and offset are not measured).

    **Arguments:** `axis`, `across` (the direction of the deviation, another axis);
    `position` `(3,)` [m]; `n` (>= 4); `tool_offset`; `sigma` [m] (default 1 µm); `runs`.

    **Returns** of `predict`: `(n,)`.
    """

    position: Float[Array, "3"]
    tool_offset: Float[Array, "3"] | None
    axis: int = eqx.field(static=True)
    across: int = eqx.field(static=True)
    n: int = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    runs: int = eqx.field(static=True)

    def __init__(
        self, axis, across, position=(0.0, 0.0, 0.0), *, n: int = 11, tool_offset=None,
        sigma: float = 1e-6, runs: int = 1,
    ):
        w = "StraightnessLine"
        self.axis = _axis(axis, w)
        self.across = _axis(across, w, "across")
        if self.across == self.axis:
            raise ValueError(
                f"{w}: the straightness of {'XYZ'[self.axis]} is measured across the motion; "
                "give `across` as one of the two other axes."
            )
        self.position = _vector(position, w, "position")
        self.tool_offset = None if tool_offset is None else _vector(tool_offset, w, "tool_offset")
        self.n = _count(n, w, "n", 4)
        self.sigma = _positive(sigma, w, "sigma")
        self.runs = _count(runs, w, "runs", 1)

    @property
    def label(self) -> str:
        return (
            f"straightness {'XYZ'[self.axis]} in {'XYZ'[self.across]} at "
            f"{np.round(np.asarray(self.position), 3).tolist()}"
        )

    def commanded(self, machine):
        return np.asarray(_line_targets(machine, self.axis, self.position, self.n))

    def predict(self, machine):
        q = _line_targets(machine, self.axis, self.position, self.n)
        P = machine.tool_point(q, tool_offset=self.tool_offset)[:, self.across]
        s = q[:, self.axis]
        A = jnp.stack([jnp.ones_like(s), s - jnp.mean(s)], axis=1)
        # remove the least-squares line: projection onto the orthogonal complement of A
        Q, _ = jnp.linalg.qr(A)
        return P - Q @ (Q.T @ P)


class AngularLine(AbstractMachineTest):
    r"""Angular error of one axis about one direction: the relative rotation of the tool
    against the workpiece (a differential electronic level for rotations about X and Y,
    an angular interferometer for pitch and yaw; ISO 230-1 §8.4), zeroed at the first
    target. Reading `(Σ_j ε_j(q_j))·e_about − (same at q_0)` [rad].

    **Arguments:** `axis`; `about` (`"x"`, `"y"`, `"z"`); `position`; `n` (>= 3); `sigma`
    [rad] (default 1 µrad ≈ 0.2″); `runs`.

    The roll of the vertical Z axis (about Z) is refused: no level or angular optic
    measures it; it shows as straightness of Z measured with a lateral tool offset.

    **Returns** of `predict`: `(n,)`.
    """

    position: Float[Array, "3"]
    axis: int = eqx.field(static=True)
    about: int = eqx.field(static=True)
    n: int = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    runs: int = eqx.field(static=True)

    def __init__(
        self, axis, about, position=(0.0, 0.0, 0.0), *, n: int = 11, sigma: float = 1e-6,
        runs: int = 1,
    ):
        w = "AngularLine"
        self.axis = _axis(axis, w)
        self.about = _axis(about, w, "about")
        if self.axis == 2 and self.about == 2:
            raise ValueError(
                f"{w}: the roll of the vertical Z axis (ECZ) cannot be measured with a level "
                "or an angular interferometer; measure the straightness of Z with a lateral "
                "tool offset (StraightnessLine('z', 'x', tool_offset=(0, 0.1, 0)))."
            )
        self.position = _vector(position, w, "position")
        self.n = _count(n, w, "n", 3)
        self.sigma = _positive(sigma, w, "sigma")
        self.runs = _count(runs, w, "runs", 1)

    @property
    def label(self) -> str:
        return f"angular {'XYZ'[self.axis]} about {'XYZ'[self.about]}"

    def commanded(self, machine):
        return np.asarray(_line_targets(machine, self.axis, self.position, self.n))

    def predict(self, machine):
        q = _line_targets(machine, self.axis, self.position, self.n)
        rot = sum(machine.errors.axis_motion(q[:, j], j)[1] for j in range(3))
        a = rot[:, self.about]
        return a - a[0]


class BallbarCircle(AbstractMachineTest):
    r"""Ball-bar circular test (ISO 230-4) in a plane, quasi-static (low feed: the
    geometry and the axes' reversal, no servo lag; for the dynamic test see
    `CartesianMachine.simulate`).

    Commanded circle `q(θ) = c + R (cos θ u + sin θ v)`, `(u, v)` the plane's axes
    (`"xy"`: X, Y; `"yz"`: Y, Z; `"zx"`: Z, X), `θ` counter-clockwise (or clockwise)
    from `u`; each axis approaches from the side it moves to (reversal `±B/2`). The centre
    pivot is set at the commanded centre, so its actual position is `P(c)`. Reading:
    `|P(q(θ_i)) − P(c)| − R` [m] minus its mean (the bar's absolute length is not known
    to the test's accuracy).

    **Arguments:** `plane`; `centre` `(3,)` [m]; `radius` [m] (> 0); `n` angles (>= 8);
    `clockwise`; `tool_offset`; `sigma` [m] (default 0.5 µm); `runs`.

    **Returns** of `predict`: `(n,)` at `θ_i = 2π i/n`.
    """

    centre: Float[Array, "3"]
    tool_offset: Float[Array, "3"] | None
    plane: str = eqx.field(static=True)
    radius: float = eqx.field(static=True)
    n: int = eqx.field(static=True)
    clockwise: bool = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    runs: int = eqx.field(static=True)

    def __init__(
        self, plane, centre=(0.0, 0.0, 0.0), radius: float = 0.1, *, n: int = 72,
        clockwise: bool = False, tool_offset=None, sigma: float = 0.5e-6, runs: int = 1,
    ):
        w = "BallbarCircle"
        if plane not in _PLANES:
            raise ValueError(f"{w}: plane must be one of {tuple(_PLANES)}; got {plane!r}.")
        self.plane = plane
        self.centre = _vector(centre, w, "centre")
        self.radius = _positive(radius, w, "radius")
        if self.radius > 2.0:
            raise ValueError(
                f"{w}: a ball bar of radius {self.radius:g} m is longer than any; the radius "
                "is probably in mm — give it in m."
            )
        self.tool_offset = None if tool_offset is None else _vector(tool_offset, w, "tool_offset")
        self.n = _count(n, w, "n", 8)
        self.clockwise = bool(clockwise)
        self.sigma = _positive(sigma, w, "sigma")
        self.runs = _count(runs, w, "runs", 1)

    @property
    def label(self) -> str:
        d = "cw" if self.clockwise else "ccw"
        return f"ball-bar {self.plane.upper()} R{1e3 * self.radius:g} mm {d}"

    @property
    def theta(self) -> np.ndarray:
        """`(n,)` commanded angles [rad]."""
        return 2 * np.pi * np.arange(self.n) / self.n

    def _path(self, dtype):
        iu, iv = _PLANES[self.plane]
        th = jnp.asarray(self.theta, dtype)
        sgn = -1.0 if self.clockwise else 1.0
        c, s = jnp.cos(th), sgn * jnp.sin(th)
        q = jnp.broadcast_to(self.centre, (self.n, 3))
        q = q.at[:, iu].add(self.radius * c).at[:, iv].add(self.radius * s)
        d = jnp.zeros((self.n, 3), dtype).at[:, iu].set(jnp.sign(-s)).at[:, iv].set(jnp.sign(c))
        return q, d

    def commanded(self, machine):
        return np.asarray(self._path(self.centre.dtype)[0])

    def predict(self, machine):
        q, d = self._path(self.centre.dtype)
        P = machine.tool_point(q, d, tool_offset=self.tool_offset)
        C = machine.tool_point(self.centre, tool_offset=self.tool_offset)
        r = jnp.sqrt(jnp.sum((P - C) ** 2, axis=-1)) - self.radius
        return r - jnp.mean(r)


class DiagonalLine(AbstractMachineTest):
    r"""Displacement along a body diagonal of the working volume by laser (ISO 230-6).

    The diagonal runs from the corner `centre − s∘h` to `centre + s∘h`, `s` the corner's
    signs (`(1, 1, 1)`, `(−1, 1, 1)`, `(1, −1, 1)`, `(1, 1, −1)` for the four body
    diagonals) and `h` the half-size of the measured volume (`margin` of the travel left
    at each end). Forward and reverse runs; reading `d·(P(q_i) − P(q_0)) − |q_i − q_0|`
    [m], `d` the unit diagonal.

    **Arguments:** `signs` (3 of ±1, static); `n`; `margin` (fraction of each travel, in
    [0, 0.4]); `bidirectional`; `tool_offset`; `sigma` [m] (default 1 µm); `runs`.

    **Returns** of `predict`: `(2, n)` or `(1, n)`.
    """

    tool_offset: Float[Array, "3"] | None
    signs: tuple[float, float, float] = eqx.field(static=True)
    n: int = eqx.field(static=True)
    margin: float = eqx.field(static=True)
    bidirectional: bool = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    runs: int = eqx.field(static=True)

    def __init__(
        self, signs=(1, 1, 1), *, n: int = 11, margin: float = 0.05,
        bidirectional: bool = True, tool_offset=None, sigma: float = 1e-6, runs: int = 1,
    ):
        w = "DiagonalLine"
        try:
            sg = tuple(float(v) for v in signs)
        except (TypeError, ValueError):
            sg = ()
        if len(sg) != 3 or any(v not in (1.0, -1.0) for v in sg):
            raise ValueError(f"{w}: signs must be three of +1/-1, e.g. (1, -1, 1); got {signs!r}.")
        self.signs = sg  # type: ignore[assignment]
        self.n = _count(n, w, "n", 3)
        if not 0 <= float(margin) <= 0.4:
            raise ValueError(f"{w}: margin must lie in [0, 0.4] of the travel; got {margin}.")
        self.margin = float(margin)
        self.bidirectional = bool(bidirectional)
        self.tool_offset = None if tool_offset is None else _vector(tool_offset, w, "tool_offset")
        self.sigma = _positive(sigma, w, "sigma")
        self.runs = _count(runs, w, "runs", 1)

    @property
    def label(self) -> str:
        return "diagonal " + "".join("+" if v > 0 else "-" for v in self.signs)

    def _line(self, machine, dtype):
        span = np.asarray(machine.travel)
        c = span.mean(axis=1)
        h = (0.5 - self.margin) * (span[:, 1] - span[:, 0]) * np.asarray(self.signs)
        s = np.linspace(-1.0, 1.0, self.n)[:, None]
        q = jnp.asarray(c + s * h, dtype)
        return q, jnp.asarray(h / np.linalg.norm(h), dtype), jnp.asarray(np.sign(h), dtype)

    def commanded(self, machine):
        return np.asarray(self._line(machine, float)[0])

    def predict(self, machine):
        dtype = machine.tool_offset.dtype
        q, d, sg = self._line(machine, dtype)
        dirs = [1.0, -1.0] if self.bidirectional else [1.0]
        P0 = machine.tool_point(q[0], sg, tool_offset=self.tool_offset)
        L = jnp.sqrt(jnp.sum((q - q[0]) ** 2, axis=-1))
        return jnp.stack(
            [
                (machine.tool_point(q, v * sg, tool_offset=self.tool_offset) - P0) @ d - L
                for v in dirs
            ]
        )
