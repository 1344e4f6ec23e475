r"""Geometric test files of machine tools: laser-interferometer positioning runs and
ball-bar circles as CSV.

**Laser interferometer CSV** (ISO 230-2 runs, one row per reading), columns by header,
units in brackets (converted to SI; default m):

```
target [mm], deviation [um], run, direction
0, 0.0, 1, +
50, 1.8, 1, +
...
500, 3.1, 1, -
```

`target`: commanded position; `deviation`: measured minus commanded position; `run`: run
number (1, 2, ...); `direction`: `+` / `forward` / `1` (approach from below) or `-` /
`reverse` / `-1`. Every run must cover the same targets in both directions.

**Ball-bar CSV** (ISO 230-4), an optional header comment with the bar length, then
`angle` and `deviation` columns:

```
# radius: 100 mm
angle [deg], deviation [um]
0, 0.4
...
```

(Renishaw's QC10/QC20 `.b5r` and laser `.rtl` files are binary or undocumented; export
them as these CSV layouts.)
"""

import csv
import re

import numpy as np

from ._loaders import existing_file
from ._units import parse_header, to_si

__all__ = ["BallbarData", "LaserRuns", "load_ballbar_csv", "load_laser_csv"]

_FORWARD = {"+", "forward", "fwd", "1", "+1", "up"}
_REVERSE = {"-", "reverse", "rev", "-1", "down"}


class LaserRuns:
    """Laser positioning runs of one axis.

    **Attributes:** `targets` `(n,)` [m], increasing; `deviations` `(runs, 2, n)` [m]
    (forward, reverse); `source`."""

    def __init__(self, targets: np.ndarray, deviations: np.ndarray, source: str = ""):
        self.targets, self.deviations, self.source = targets, deviations, source

    @property
    def reversal(self) -> np.ndarray:
        """ISO 230-2 reversal value at each target: mean forward minus mean reverse [m]."""
        return self.deviations[:, 0].mean(axis=0) - self.deviations[:, 1].mean(axis=0)


class BallbarData:
    """A ball-bar circle: `angle` `(n,)` [rad], `deviation` `(n,)` [m], `radius` [m] or
    `None` (not in the file), `source`."""

    def __init__(self, angle, deviation, radius, source=""):
        self.angle, self.deviation, self.radius, self.source = angle, deviation, radius, source


def _read(path, where: str) -> tuple[list[str], list[list[str]], list[str]]:
    file = existing_file(path)
    text = file.read_text(encoding="utf-8-sig").splitlines()
    comments = [ln.lstrip("#").strip() for ln in text if ln.lstrip().startswith("#")]
    rows = list(csv.reader(ln for ln in text if ln.strip() and not ln.lstrip().startswith("#")))
    if len(rows) < 2:
        raise ValueError(f"{where}: {file} has no data rows under its header.")
    return rows[0], rows[1:], comments


def _columns(header, rows, wanted, where, source):
    names = {}
    for i, cell in enumerate(header):
        name, unit = parse_header(cell)
        names[name.strip().lower()] = (i, unit)
    out = {}
    for key, default in wanted.items():
        if key not in names:
            raise ValueError(
                f"{where}: {source} has no '{key}' column (found {list(names)}); name the "
                f"columns {', '.join(wanted)} (units in brackets, e.g. 'target [mm]')."
            )
        i, unit = names[key]
        col = []
        for r_i, row in enumerate(rows, start=2):
            try:
                col.append(row[i].strip())
            except IndexError:
                raise ValueError(f"{where}: row {r_i} of {source} has too few cells.") from None
        if default is None:
            out[key] = col
            continue
        try:
            values = np.asarray(col, dtype=float)
        except ValueError:
            bad = next(c for c in col if not _is_number(c))
            raise ValueError(
                f"{where}: column '{key}' of {source} holds the non-number {bad!r}; fix or "
                "remove that row."
            ) from None
        if not np.isfinite(values).all():
            raise ValueError(f"{where}: column '{key}' of {source} holds NaN or inf.")
        out[key] = to_si(values, unit or default, name=key, source=source)[0]
    return out


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def load_laser_csv(path) -> LaserRuns:
    """Read laser-interferometer positioning runs (module doc for the layout).

    **Returns:** [`LaserRuns`][] with `deviations` `(runs, 2, n)` [m].

    **Raises:** `ValueError` naming the row or column for a missing column, a non-number,
    an unknown direction, or runs that do not cover the same targets in both directions.
    """
    where = "load_laser_csv"
    header, rows, _ = _read(path, where)
    src = str(path)
    cols = _columns(header, rows, {"target": "m", "deviation": "m", "run": None,
                                   "direction": None}, where, src)
    direction = []
    for i, d in enumerate(cols["direction"], start=2):
        d = d.lower()
        if d in _FORWARD:
            direction.append(0)
        elif d in _REVERSE:
            direction.append(1)
        else:
            raise ValueError(
                f"{where}: row {i} of {src} has direction {d!r}; write '+' (forward) or '-' "
                "(reverse)."
            )
    targets = np.unique(np.round(cols["target"], 9))
    runs = sorted(set(cols["run"]), key=lambda r: (len(r), r))
    dev = np.full((len(runs), 2, targets.size), np.nan)
    for t, v, r, d in zip(cols["target"], cols["deviation"], cols["run"], direction):
        dev[runs.index(r), d, np.searchsorted(targets, round(t, 9))] = v
    if np.isnan(dev).any():
        r, d, k = np.argwhere(np.isnan(dev))[0]
        raise ValueError(
            f"{where}: run {runs[r]} of {src} has no {'forward' if d == 0 else 'reverse'} "
            f"reading at target {targets[k]:.6g} m; every run must visit every target in both "
            "directions (ISO 230-2)."
        )
    return LaserRuns(targets, dev, src)


_RADIUS = re.compile(r"radius\s*[:=]\s*([-+0-9.eE]+)\s*([a-zµ]*)", re.IGNORECASE)


def load_ballbar_csv(path, *, radius: float | None = None) -> BallbarData:
    """Read a ball-bar circle (module doc for the layout).

    **Arguments:** `path`; `radius`, the bar length the test plan expects [m]: a file
    whose `# radius:` comment disagrees by more than 0.1 % is refused.

    **Returns:** [`BallbarData`][], angles in [rad], deviations in [m], sorted by angle.
    """
    where = "load_ballbar_csv"
    header, rows, comments = _read(path, where)
    src = str(path)
    cols = _columns(header, rows, {"angle": "rad", "deviation": "m"}, where, src)
    file_r = None
    for c in comments:
        m = _RADIUS.search(c)
        if m:
            file_r = float(to_si(float(m.group(1)), m.group(2) or "m", name="radius",
                                 source=src)[0])
    if radius is not None and file_r is not None and abs(file_r - radius) > 1e-3 * radius:
        raise ValueError(
            f"{where}: {src} was measured with a {1e3 * file_r:g} mm bar but the test expects "
            f"{1e3 * radius:g} mm; load the file of the right test or pass radius="
            f"{file_r:g} (m)."
        )
    if np.max(np.abs(cols["deviation"])) > 1e-3:
        raise ValueError(
            f"{where}: {src} has radius deviations up to "
            f"{np.max(np.abs(cols['deviation'])):.3g} m, more than a ball-bar reads; give "
            "the unit in the header, e.g. 'deviation [um]'."
        )
    order = np.argsort(np.mod(cols["angle"], 2 * np.pi))
    return BallbarData(np.mod(cols["angle"], 2 * np.pi)[order], cols["deviation"][order],
                       file_r if file_r is not None else radius, src)

