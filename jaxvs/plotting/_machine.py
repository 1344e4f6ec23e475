"""Figures of the three-axis machine: the 21 geometric error components, and the
volumetric error over the working volume before and after compensation."""

import matplotlib.pyplot as plt
import numpy as np

from ..models import COMPONENTS
from ..studies.machine import component_curves

_UNIT = {"m": ("µm", 1e6), "rad": ("µrad", 1e6)}


def machine_errors_plot(machine, *, calibration=None, truth=None, title=None):
    """The 21 components (ISO 230-1 names) on a 7 × 3 grid over their axis' travel: for
    each axis X, Y, Z its positioning, two straightness and three angular errors, and
    the three squareness errors in the last row.

    **Arguments:** `machine`, a `jaxvs.models.CartesianMachine`; `calibration`, a
    `jaxvs.studies.machine.MachineCalibration` (its estimate drawn with the 95 % band);
    `truth`, a machine drawn dashed for comparison; `title`.

    **Returns:** the matplotlib `Figure`.
    """
    fig, axes = plt.subplots(7, 3, figsize=(10, 14), sharex="col")
    q, curves = component_curves(machine)
    q, curves = np.asarray(q), np.asarray(curves)
    grid = {}
    for col, a in enumerate("XYZ"):
        others = [c for c in "XYZ" if c != a]
        names = [f"E{a}{a}", f"E{others[0]}{a}", f"E{others[1]}{a}", f"EA{a}", f"EB{a}",
                 f"EC{a}"]
        for row, n in enumerate(names):
            grid[n] = (row, col)
    for col, n in enumerate(COMPONENTS[18:]):
        grid[n] = (6, col)
    for i, name in enumerate(COMPONENTS):
        row, col = grid[name]
        ax = axes[row, col]
        axis = "XYZ".index(name[-1])
        x = 1e3 * q[axis]
        unit, k = _UNIT["rad" if (name[1] in "ABC") else "m"]
        ax.plot(x, k * curves[i], label="model")
        if truth is not None:
            ax.plot(x, k * np.asarray(component_curves(truth)[1][i]), "k--", lw=1, label="true")
        if calibration is not None:
            est = k * np.asarray(calibration.curves[i])
            half = k * calibration.quantile * np.asarray(calibration.std[i])
            ax.plot(x, est, "C1", label="calibrated")
            ax.fill_between(x, est - half, est + half, color="C1", alpha=0.25, lw=0)
        ax.set_title(name, fontsize=9)
        ax.set_ylabel(unit, fontsize=8)
        ax.tick_params(labelsize=7)
        if row == 6 or (row == 5 and name[-1] != "X"):
            ax.set_xlabel(f"{name[-1]} position [mm]", fontsize=8)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title or "The 21 geometric error components (ISO 230-1)")
    fig.tight_layout()
    return fig


def volumetric_error_plot(q, before, after=None, *, title=None):
    """The magnitude of the volumetric error on a grid: each point coloured by `|E|`
    [µm], before (and after) compensation.

    **Arguments:** `q` `(..., 3)` commanded positions [m]; `before`, `after` `(..., 3)`
    errors [m] (from `jaxvs.studies.machine.compensated_error`); `title`.

    **Returns:** the matplotlib `Figure`.
    """
    q = np.asarray(q).reshape(-1, 3)
    panels = [("before compensation", before)] + ([("after", after)] if after is not None else [])
    fig = plt.figure(figsize=(5.5 * len(panels), 4.5))
    for k, (label, e) in enumerate(panels):
        mag = 1e6 * np.linalg.norm(np.asarray(e).reshape(-1, 3), axis=1)
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        sc = ax.scatter(*(1e3 * q.T), c=mag, s=6, cmap="viridis")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_zlabel("z [mm]")
        ax.set_title(f"{label}: max {mag.max():.2g} µm")
        fig.colorbar(sc, ax=ax, shrink=0.6, label="|E| [µm]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
