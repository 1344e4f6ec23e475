"""The figure of discovery: the flexible term over the slot input that carries the gap,
with the discovered formula drawn over it."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["plot_discovered"]


def plot_discovered(discovered, ax=None):
    """Draw the flexible term of a [`Discovered`][jaxvs.diagnosis.Discovered] against
    its input: the partial residual (the residual of the model without the term plus the
    term, grey), the flexible term (black) and the formula's contribution (red, when a
    formula was fitted). The title says what was found ("no formula found" when none).

    **Returns:** the matplotlib axes.
    """
    shape = getattr(discovered, "shape", None) or {}
    if not shape:
        raise ValueError(
            "plot_discovered: this result has no flexible term to draw (discovery did not "
            f"fire: {discovered.message}). Plot a result whose `fired` is True."
        )
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    x = np.asarray(shape["x"])
    order = np.argsort(x)
    flex = np.asarray(shape["flexible"])
    part = np.asarray(shape["partial"])
    # the partial residual: the flexible term plus what it leaves
    ax.plot(x, part - np.mean(part) + np.mean(flex), ".", ms=1.5, color="0.7", label="residual")
    # the term's net contribution depends a little on the other inputs too: its mean
    # over bins of the input, as a line
    edges = np.unique(np.quantile(x, np.linspace(0, 1, 61)))
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(edges.size - 2, 0))
    xb = np.array([x[which == b].mean() for b in np.unique(which)])
    fb = np.array([flex[which == b].mean() for b in np.unique(which)])
    ax.plot(x[order], flex[order], ".", ms=1, color="0.35", alpha=0.3)
    ax.plot(xb, fb, "-", color="k", lw=1.8, label="flexible term")
    if "formula" in shape and discovered.formula is not None:
        f = np.asarray(shape["formula"])
        f = f - np.mean(f) + np.mean(flex)
        ax.plot(x, f, ".", ms=2, color="C3", label=f"formula: {discovered.formula}")
    ax.set_xlabel(shape["label"])
    ax.set_ylabel(shape.get("ylabel", "additional force [N]"))
    verdict = "formula found" if discovered.found else "no formula found"
    if discovered.found and discovered.named_instead:
        verdict = f"library effect {discovered.nearest_effect}"
    ax.set_title(f"{discovered.slot}: {verdict}", fontsize=10)
    ax.legend(fontsize=7, loc="best", markerscale=4)
    return ax
