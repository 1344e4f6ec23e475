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
    "plan_predict",
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
    readings `measure`, the reading noise `sigma`.

    A test is the commanded points it visits (`points`) and what its instrument makes of
    the tool's actual position and orientation there (`readings`); a whole plan then
    evaluates the kinematic chain once for all its points ([`plan_predict`][])."""

    sigma: eqx.AbstractVar[float]
    runs: eqx.AbstractVar[int]
    tool_offset: eqx.AbstractVar[Array | None]

    @abc.abstractmethod
    def points(self, machine: CartesianMachine) -> tuple[Array, Array]:
        """`(q (k, 3) [m], direction (k, 3))`: commanded points and approach directions."""

    @abc.abstractmethod
    def readings(self, q: Array, P: Array, R: Array) -> Array:
        """Readings from the commanded points `q (k, 3)` [m], the tool points `P (k, 3)`
        [m] and the tool orientations `R (k, 3)` [rad] there."""

    def predict(self, machine: CartesianMachine) -> Array:
        """Noise-free readings [m or rad] of the test on `machine`."""
        return plan_predict(machine, [self])[0]

    @property
    def label(self) -> str:
        return type(self).__name__

    def check(self, machine: CartesianMachine) -> None:
        """Refuse a test that leaves the machine's travel (`ValueError`)."""
        _inside(np.asarray(self.points(machine)[0]), machine, self.label)

    def measure(self, machine: CartesianMachine, key: PRNGKeyArray) -> Array:
        """`(runs, *readings)` readings with white noise of standard deviation `sigma`."""
        self.check(machine)
        y = self.predict(machine)
        return y + self.sigma * jax.random.normal(key, (self.runs, *y.shape), y.dtype)


def plan_predict(machine: CartesianMachine, tests) -> list[Array]:
    """Noise-free readings of every test of a plan, with one evaluation of the kinematic
    chain over all the plan's points (the compiled graph grows with the number of tests
    only by their cheap read-outs)."""
    qs, ds, ts, sizes = [], [], [], []
    for t in tests:
        q, d = t.points(machine)
        qs.append(q)
        ds.append(d)
        off = machine.tool_offset if t.tool_offset is None else t.tool_offset
        ts.append(jnp.broadcast_to(off, q.shape))
        sizes.append(q.shape[0])
    q, d, off = (jnp.concatenate(v) for v in (qs, ds, ts))
    P = machine.tool_point(q, d, tool_offset=off)
    R = machine.tool_orientation(q)
    out, i = [], 0
    for t, k in zip(tests, sizes):
        out.append(t.readings(q[i : i + k], P[i : i + k], R[i : i + k]))
        i += k
    return out


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

    def points(self, machine):
        q = _line_targets(machine, self.axis, self.position, self.n)
        e = jnp.zeros((self.n, 3), q.dtype).at[:, self.axis].set(1.0)
        if not self.bidirectional:
            return q, e
        return jnp.concatenate([q, q]), jnp.concatenate([e, -e])

    def readings(self, q, P, R):
        k = 2 if self.bidirectional else 1
        e = (P - q)[:, self.axis].reshape(k, self.n)
        return e - e[0, 0]


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

    def points(self, machine):
        q = _line_targets(machine, self.axis, self.position, self.n)
        return q, jnp.zeros_like(q)

    def readings(self, q, P, R):
        # remove the least-squares line over the equally spaced targets: project onto the
        # orthogonal complement of span{1, s} (a fixed matrix, the targets are static)
        s = np.linspace(-1.0, 1.0, self.n)
        A = np.stack([np.ones(self.n), s], axis=1)
        proj = np.eye(self.n) - A @ np.linalg.pinv(A)
        return jnp.asarray(proj, P.dtype) @ (P - q)[:, self.across]


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
    tool_offset: None
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
        self.tool_offset = None
        self.n = _count(n, w, "n", 3)
        self.sigma = _positive(sigma, w, "sigma")
        self.runs = _count(runs, w, "runs", 1)

    @property
    def label(self) -> str:
        return f"angular {'XYZ'[self.axis]} about {'XYZ'[self.about]}"

    def points(self, machine):
        q = _line_targets(machine, self.axis, self.position, self.n)
        return q, jnp.zeros_like(q)

    def readings(self, q, P, R):
        a = R[:, self.about]
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

    def points(self, machine):
        iu, iv = _PLANES[self.plane]
        sgn = -1.0 if self.clockwise else 1.0
        c, s = np.cos(self.theta), sgn * np.sin(self.theta)
        off = np.zeros((self.n, 3))
        off[:, iu], off[:, iv] = self.radius * c, self.radius * s
        d = np.zeros((self.n, 3))
        d[:, iu], d[:, iv] = np.sign(np.round(-s, 12)), np.sign(np.round(c, 12))
        q = self.centre + jnp.asarray(off, self.centre.dtype)
        q = jnp.concatenate([q, self.centre[None]])
        return q, jnp.asarray(np.concatenate([d, np.zeros((1, 3))]), q.dtype)

    def readings(self, q, P, R):
        r = jnp.sqrt(jnp.sum((P[:-1] - P[-1]) ** 2, axis=-1)) - self.radius
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

    def _line(self, machine):
        span = np.asarray(machine.travel)
        c = span.mean(axis=1)
        h = (0.5 - self.margin) * (span[:, 1] - span[:, 0]) * np.asarray(self.signs)
        s = np.linspace(-1.0, 1.0, self.n)[:, None]
        return c + s * h, h / np.linalg.norm(h), np.sign(h)

    def points(self, machine):
        q, _, sg = self._line(machine)
        d = np.broadcast_to(sg, q.shape)
        if self.bidirectional:
            q, d = np.concatenate([q, q]), np.concatenate([d, -d])
        dtype = machine.tool_offset.dtype
        return jnp.asarray(q, dtype), jnp.asarray(d, dtype)

    def readings(self, q, P, R):
        k = 2 if self.bidirectional else 1
        d = (q[self.n - 1] - q[0]) / jnp.linalg.norm(q[self.n - 1] - q[0])
        # q_i − q_0 lies along d with positive length: d·(P_i − P_0) − |q_i − q_0| is the
        # error along the diagonal, d·(E_i − E_0) with E = P − q
        e = ((P - q) @ d).reshape(k, self.n)
        return e - e[0, 0]
