"""Test plans of a three-axis machine: the complete plan (laser, straightness, angular,
ball-bar and diagonals), ball-bar plus diagonals, diagonals only, and candidate tests."""

import numpy as np

from ...models import (
    AngularLine,
    BallbarCircle,
    CartesianMachine,
    DiagonalLine,
    LaserLine,
    StraightnessLine,
)

__all__ = ["ballbar_diagonal_plan", "ballbar_plan", "candidate_tests", "complete_plan",
           "diagonal_plan"]

DIAGONALS = ((1, 1, 1), (-1, 1, 1), (1, -1, 1), (1, 1, -1))


def _centre(machine: CartesianMachine) -> np.ndarray:
    return np.asarray(machine.travel).mean(axis=1)


def _span(machine):
    s = np.asarray(machine.travel)
    return s[:, 1] - s[:, 0]


def diagonal_plan(machine: CartesianMachine, *, n: int = 11, runs: int = 1) -> list:
    """The four body diagonals (ISO 230-6), forward and reverse."""
    return [DiagonalLine(s, n=n, runs=runs) for s in DIAGONALS]


def ballbar_plan(machine: CartesianMachine, *, radii=None, n: int = 72, runs: int = 1) -> list:
    """Ball-bar circles in the XY, YZ and ZX planes at two radii (default 40 % and 20 % of
    the shortest travel), both directions (ISO 230-4): 12 tests."""
    c = _centre(machine)
    if radii is None:
        short = float(np.min(_span(machine)))
        radii = (0.4 * short, 0.2 * short)
    return [
        BallbarCircle(p, c, r, n=n, clockwise=cw, runs=runs)
        for p in ("xy", "yz", "zx")
        for r in radii
        for cw in (False, True)
    ]


def ballbar_diagonal_plan(machine: CartesianMachine, **kw) -> list:
    """[`ballbar_plan`][] plus [`diagonal_plan`][] (16 tests): the quick volumetric check."""
    return ballbar_plan(machine) + diagonal_plan(machine, **kw)


def complete_plan(machine: CartesianMachine, *, n: int = 11, runs: int = 1,
                  lateral_offset: float = 0.1) -> list:
    """A plan that separates all 21 components and the reversal values (41 tests):

    - laser positioning of each axis on its centre line and on two offset lines (Abbé
      arms for pitch and yaw), forward and reverse (ISO 230-2): 9;
    - straightness of each axis in both perpendicular directions, and of Z in X with the
      optic offset laterally by `lateral_offset` in Y, which shows the roll of Z: 7;
    - angular errors: X and Y about all three directions, Z about X and Y (level /
      angular interferometer): 8;
    - [`ballbar_plan`][] (squareness): 12, and one ZX circle with the same lateral optic
      offset (the linear part of the roll of Z, which the straightness optic's alignment
      removes, tilts that circle); [`diagonal_plan`][]: 4.
    """
    c = _centre(machine)
    span = np.asarray(machine.travel)
    tests = []
    for a in range(3):
        others = [k for k in range(3) if k != a]
        tests.append(LaserLine(a, c, n=n, runs=runs))
        for k in others:
            p = c.copy()
            p[k] = span[k, 0] + 0.1 * (span[k, 1] - span[k, 0])
            tests.append(LaserLine(a, p, n=n, runs=runs))
        for k in others:
            tests.append(StraightnessLine(a, k, c, n=n, runs=runs))
    tool = np.asarray(machine.tool_offset) + np.array([0.0, lateral_offset, 0.0])
    tests.append(StraightnessLine(2, 0, c, n=n, runs=runs, tool_offset=tool))
    for a in range(3):
        for about in range(3):
            if not (a == 2 and about == 2):
                tests.append(AngularLine(a, about, c, n=n, runs=runs))
    bb = ballbar_plan(machine, runs=runs)
    lateral = BallbarCircle("zx", c, bb[2].radius, tool_offset=tool, runs=runs)
    return tests + bb + [lateral] + diagonal_plan(machine, n=n, runs=runs)


def candidate_tests(machine: CartesianMachine, *, n: int = 11, offsets: int = 3) -> list:
    """Candidate extra tests: laser lines of each axis at `offsets × offsets` offset lines,
    straightness lines of each axis at the centre, angular lines, ball-bars in the three
    planes."""
    span = np.asarray(machine.travel)
    c = _centre(machine)
    out = []
    fr = np.linspace(0.1, 0.9, offsets)
    for a in range(3):
        j, k = [m for m in range(3) if m != a]
        for fj in fr:
            for fk in fr:
                p = c.copy()
                p[j] = span[j, 0] + fj * (span[j, 1] - span[j, 0])
                p[k] = span[k, 0] + fk * (span[k, 1] - span[k, 0])
                out.append(LaserLine(a, p, n=n))
        for m in (j, k):
            out.append(StraightnessLine(a, m, c, n=n))
        for about in range(3):
            if not (a == 2 and about == 2):
                out.append(AngularLine(a, about, c, n=n))
    return out + ballbar_plan(machine)
