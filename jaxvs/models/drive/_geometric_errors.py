r"""The 21 geometric error components of a three-axis machine as smooth functions of the
axis positions (Legendre series), with a lookup-table constructor.

Names and meaning follow ISO 230-1:2012 (§3.4): `E` + the direction of the error + the
axis that moves. For each linear axis `a ∈ {X, Y, Z}`:

- **positioning** `EAA`: `EXX`, `EYY`, `EZZ` — error along the axis' own direction [m];
- **straightness** `EYX, EZX, EXY, EZY, EXZ, EYZ` — error across the motion [m];
- **angular** `EAa, EBa, ECa` — rotation about X (A), Y (B), Z (C) while `a` moves [rad]:
  for a horizontal axis one is its *roll*, the other two its *pitch* and *yaw*;
- **squareness** `EC0Y` (Y-axis line to X, about Z), `EB0Z` (Z to X, about Y), `EA0Z`
  (Z to Y, about X) [rad], constant. X is the reference line and the XY plane the
  reference plane (ISO 230-1, §3.4.2), so the axis directions are
  `e_x = (1, 0, 0)`, `e_y = (−EC0Y, 1, 0)`, `e_z = (EB0Z, −EA0Z, 1)`.

All components describe the motion of the **tool relative to the workpiece** (the ISO
230-1 convention), whichever body the axis physically moves.

Representation (`n` = `degree`): each component is a Legendre series in the normalised
position `u = 2 (q − q_min)/(q_max − q_min) − 1 ∈ [−1, 1]` over the axis' travel,

- positioning and angular: `Σ_{k=1..n} c_k P_k(u)` (no `P_0`: a constant offset of a
  positioning or angular error is a rigid shift of the whole volume, which no relative
  measurement sees; each curve has zero mean over the travel);
- straightness: `Σ_{k=2..n} c_k P_k(u)` (no `P_0`, no `P_1`: `P_{k≥2}` are orthogonal to
  the straight line, so the curve is the deviation from its least-squares reference line,
  the ISO 230-1 §3.4.8 definition; the slope of an axis line is its squareness).

That is `3n + 6(n−1) + 9n + 3 = 18n − 3` identifiable parameters (69 for `n = 4`), none of
them a null direction of the representation itself. Legendre series are used instead of
lookup tables because they are smooth and differentiable in position and in their
coefficients, and well conditioned for least squares (Soons, Theuws, Schellekens,
"Modeling the errors of multi-axis machines: a general methodology", Precision
Engineering 14, 1992, use polynomial fits for the same reason).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real, concrete, legendre as _legendre
from .._base import check_parameters

__all__ = [
    "ANGULAR",
    "COMPONENTS",
    "POSITIONING",
    "SQUARENESS",
    "STRAIGHTNESS",
    "MachineErrors",
    "legendre",
]

AXES = ("X", "Y", "Z")
ROT = ("A", "B", "C")
POSITIONING = ("EXX", "EYY", "EZZ")
STRAIGHTNESS = ("EYX", "EZX", "EXY", "EZY", "EXZ", "EYZ")
ANGULAR = ("EAX", "EBX", "ECX", "EAY", "EBY", "ECY", "EAZ", "EBZ", "ECZ")
SQUARENESS = ("EC0Y", "EB0Z", "EA0Z")
COMPONENTS = POSITIONING + STRAIGHTNESS + ANGULAR + SQUARENESS

# heuristic unit guards: no machine has a geometric error above 5 mm or 5 mrad (17 arcmin),
# nor a linear travel above 20 m; larger values are almost always mm, µm or arcsec in m/rad.
_MAX_TRANSLATION = 5e-3
_MAX_ANGLE = 5e-3
_MAX_TRAVEL = 20.0


def legendre(u: ArrayLike, degree: int) -> Float[Array, "... degree+1"]:
    """Legendre polynomials `P_0 … P_degree` at `u` (Bonnet's recurrence), stacked last."""
    u = jnp.asarray(u)
    ones = jnp.ones_like(u)[..., None]
    return jnp.concatenate([ones, _legendre(u, max(degree, 1))], axis=-1)[..., : degree + 1]


def _kind(name: str) -> tuple[str, int]:
    for kind, names in (
        ("positioning", POSITIONING),
        ("straightness", STRAIGHTNESS),
        ("angular", ANGULAR),
        ("squareness", SQUARENESS),
    ):
        if name in names:
            return kind, names.index(name)
    raise ValueError(
        f"MachineErrors: unknown error component {name!r}; the 21 components are "
        f"{', '.join(COMPONENTS)} (ISO 230-1 names)."
    )


def _axis_of(name: str) -> int:
    """The moving axis (0, 1, 2) of a position-dependent component."""
    return AXES.index(name[-1])


class MachineErrors(eqx.Module):
    r"""The 21 geometric errors of a three-axis machine (see the module docstring).

    **Arguments:**

    - `travel`: `((x_min, x_max), (y_min, y_max), (z_min, z_max))` [m], the axes' travel
      over which the series are defined (static).
    - `degree`: highest Legendre degree `n >= 2` (static).
    - `positioning`: `(3, n)` coefficients of `P_1 … P_n` for EXX, EYY, EZZ [m].
    - `straightness`: `(6, n−1)` coefficients of `P_2 … P_n` for EYX, EZX, EXY, EZY,
      EXZ, EYZ [m].
    - `angular`: `(9, n)` coefficients of `P_1 … P_n` for EAX … ECZ [rad].
    - `squareness`: `(3,)` EC0Y, EB0Z, EA0Z [rad].

    Omitted coefficients are zero. Build from measured curves with
    [`MachineErrors.from_tables`][].
    """

    positioning: Float[Array, "3 n"]
    straightness: Float[Array, "6 n1"]
    angular: Float[Array, "9 n"]
    squareness: Float[Array, "3"]
    travel: tuple[tuple[float, float], ...] = eqx.field(static=True)
    degree: int = eqx.field(static=True)

    def __init__(
        self,
        travel,
        degree: int = 4,
        *,
        positioning: ArrayLike | None = None,
        straightness: ArrayLike | None = None,
        angular: ArrayLike | None = None,
        squareness: ArrayLike | None = None,
    ):
        w = "MachineErrors"
        self.travel = _check_travel(travel, w)
        if not isinstance(degree, int) or degree < 2:
            raise ValueError(f"{w}: degree must be an int >= 2; got {degree!r}.")
        self.degree = degree
        n = degree

        def coef(x, shape, name, limit, unit):
            if x is None:
                return jnp.zeros(shape, jnp.result_type(float))
            a = as_real(x, f"{w}: {name}")
            if a.shape != shape:
                raise ValueError(
                    f"{w}: {name} must have shape {shape} (components × Legendre degrees "
                    f"{'2' if name == 'straightness' else '1'}..{n}); got {a.shape}."
                )
            big = concrete(a)
            if big is not None and np.nanmax(np.abs(big), initial=0.0) > limit:
                raise ValueError(
                    f"{w}: {name} has a coefficient of {np.nanmax(np.abs(big)):.3g} {unit}, "
                    f"more than any machine's error ({limit:g} {unit}); the values are "
                    f"probably in {'mm or µm' if unit == 'm' else 'µrad or arcsec'} — give "
                    f"them in {unit}."
                )
            return a

        self.positioning = coef(positioning, (3, n), "positioning", _MAX_TRANSLATION, "m")
        self.straightness = coef(straightness, (6, n - 1), "straightness", _MAX_TRANSLATION, "m")
        self.angular = coef(angular, (9, n), "angular", _MAX_ANGLE, "rad")
        self.squareness = coef(squareness, (3,), "squareness", _MAX_ANGLE, "rad")

    def __check_init__(self):
        check_parameters(self)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_tables(cls, travel, tables: dict, degree: int = 4) -> "MachineErrors":
        r"""Least-squares Legendre fit of measured error curves (lookup tables).

        **Arguments:**

        - `travel`: the axes' travel [m], as for the constructor.
        - `tables`: `{name: (positions [m], errors [m or rad])}` for any of the 18
          position-dependent components (ISO 230-1 names, e.g. `"EXX"`, `"ECX"`), and
          `{name: angle [rad]}` for the squareness components `"EC0Y"`, `"EB0Z"`,
          `"EA0Z"`. Missing components are zero. Positions must lie inside the axis'
          travel; each table needs more points than the degree.
        - `degree`: highest Legendre degree.

        The mean of every curve is removed (a constant is a rigid shift); from a
        straightness curve its least-squares line too (that slope is squareness or an
        alignment of the instrument, ISO 230-1 §3.4.8).
        """
        w = "MachineErrors.from_tables"
        travel = _check_travel(travel, w)
        if not isinstance(tables, dict):
            raise TypeError(f"{w}: tables must be a dict {{component name: (positions, errors)}}.")
        n = degree
        pos = np.zeros((3, n))
        strt = np.zeros((6, n - 1))
        ang = np.zeros((9, n))
        sq = np.zeros(3)
        for name, tab in tables.items():
            kind, i = _kind(name)
            if kind == "squareness":
                sq[i] = float(tab)
                continue
            try:
                q, v = (np.asarray(t, dtype=float) for t in tab)
            except (TypeError, ValueError):
                raise ValueError(
                    f"{w}: {name} must be a pair (positions [m], errors); got {type(tab).__name__}."
                ) from None
            if q.ndim != 1 or q.shape != v.shape:
                raise ValueError(
                    f"{w}: {name} needs 1-D positions and errors of the same length; got "
                    f"{q.shape} and {v.shape}."
                )
            if q.size <= n:
                raise ValueError(
                    f"{w}: {name} has {q.size} points, too few for degree {n}; give more than "
                    f"{n} points or lower the degree."
                )
            if not (np.isfinite(q).all() and np.isfinite(v).all()):
                raise ValueError(f"{w}: {name} contains NaN or inf; remove those rows.")
            lo, hi = travel[_axis_of(name)]
            tol = 1e-9 * (hi - lo)
            if q.min() < lo - tol or q.max() > hi + tol:
                hint = (
                    " The positions look like mm; give them in m."
                    if q.max() > 50 * max(abs(lo), abs(hi), 1e-3)
                    else ""
                )
                raise ValueError(
                    f"{w}: {name} has positions {q.min():.4g}..{q.max():.4g} m outside the "
                    f"{name[-1]} travel {lo:.4g}..{hi:.4g} m.{hint} Measure inside the "
                    "travel, or widen `travel`."
                )
            u = 2 * (q - lo) / (hi - lo) - 1
            basis = np.asarray(legendre(u, n))
            c, *_ = np.linalg.lstsq(basis, v, rcond=None)
            if kind == "positioning":
                pos[i] = c[1:]
            elif kind == "straightness":
                strt[i] = c[2:]
            else:
                ang[i] = c[1:]
        return cls(travel, n, positioning=pos, straightness=strt, angular=ang, squareness=sq)

    # ------------------------------------------------------------------ evaluation
    @property
    def n_parameters(self) -> int:
        return 18 * self.degree - 3

    def normalised(self, q: ArrayLike, axis: int) -> Array:
        lo, hi = self.travel[axis]
        return 2 * (jnp.asarray(q) - lo) / (hi - lo) - 1

    def axis_motion(self, q: ArrayLike, axis: int) -> tuple[Array, Array]:
        """Translational `(…, 3)` [m] and rotational `(…, 3)` [rad] error motion of `axis`
        (0, 1, 2) at positions `q` [m] (any shape)."""
        P = legendre(self.normalised(q, axis), self.degree)
        p1, p2 = P[..., 1:], P[..., 2:]
        lin = p1 @ self.positioning[axis]
        others = [k for k in range(3) if k != axis]
        s = [p2 @ self.straightness[2 * axis + j] for j in range(2)]
        trans = [None, None, None]
        trans[axis] = lin
        trans[others[0]], trans[others[1]] = s
        rot = [p1 @ self.angular[3 * axis + j] for j in range(3)]
        return jnp.stack(trans, axis=-1), jnp.stack(rot, axis=-1)

    def component(self, name: str, q: ArrayLike) -> Array:
        """One component at positions `q` [m] of its axis (m or rad; squareness: the
        constant broadcast to `q`'s shape)."""
        kind, i = _kind(name)
        q = jnp.asarray(q)
        if kind == "squareness":
            return jnp.broadcast_to(self.squareness[i], q.shape)
        axis = _axis_of(name)
        trans, rot = self.axis_motion(q, axis)
        if kind == "angular":
            return rot[..., ROT.index(name[1])]
        return trans[..., AXES.index(name[1])]

    def directions(self) -> Float[Array, "3 3"]:
        """Rows: the actual directions of the X, Y and Z axis lines (squareness)."""
        c0y, b0z, a0z = self.squareness
        one, zero = jnp.ones_like(c0y), jnp.zeros_like(c0y)
        return jnp.stack(
            [
                jnp.stack([one, zero, zero]),
                jnp.stack([-c0y, one, zero]),
                jnp.stack([b0z, -a0z, one]),
            ]
        )


def _check_travel(travel, where: str) -> tuple[tuple[float, float], ...]:
    try:
        t = np.asarray(travel, dtype=float)
    except (TypeError, ValueError):
        t = None
    if t is None or t.shape != (3, 2):
        raise ValueError(
            f"{where}: travel must be ((x_min, x_max), (y_min, y_max), (z_min, z_max)) in m."
        )
    if not np.isfinite(t).all() or np.any(t[:, 1] <= t[:, 0]):
        raise ValueError(f"{where}: every travel needs finite min < max; got {t.tolist()}.")
    if np.any(t[:, 1] - t[:, 0] > _MAX_TRAVEL):
        raise ValueError(
            f"{where}: a travel of {np.max(t[:, 1] - t[:, 0]):g} m is longer than any machine's; "
            "the travel is probably in mm — give it in m."
        )
    return tuple((float(a), float(b)) for a, b in t)
