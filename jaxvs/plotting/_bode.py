"""Bode diagrams of models, families and measured FRFs."""

from collections.abc import Sequence

import matplotlib
import matplotlib.pyplot as plt
import numpy as np


def bode_plot(
    frequency_hz: np.ndarray,
    responses: Sequence[np.ndarray] | np.ndarray,
    *,
    labels: Sequence[str] | None = None,
    styles: Sequence[str] | None = None,
    title: str | None = None,
    magnitude_unit: str = "",
    db: bool = True,
    colour_by: np.ndarray | None = None,
    colour_label: str | None = None,
    ax=None,
):
    """Magnitude and phase of one or several complex responses against frequency.

    **Arguments:**

    - `frequency_hz`: `(freq,)` frequencies [Hz] (log axis).
    - `responses`: a `(freq,)` complex array, a sequence of them, or a `(n, freq)` array
      (a family: drawn as a fan of curves, coloured by `colour_by` if given).
    - `labels`, `styles`: legend labels and matplotlib format strings per curve.
    - `magnitude_unit`: unit shown on the magnitude axis (e.g. "m/m" for a TMF).
    - `db`: magnitude in dB (20 log10) or linear on a log axis.
    - `colour_by`: `(n,)` values (e.g. the other axis' position [m]) mapped to colour.
    - `ax`: optional pair of axes `(ax_mag, ax_phase)` to draw into.

    **Returns:**

    The matplotlib `Figure`.
    """
    f = np.asarray(frequency_hz, dtype=float)
    if isinstance(responses, np.ndarray) or hasattr(responses, "shape"):
        arr = np.asarray(responses)
        curves = [arr] if arr.ndim == 1 else list(arr.reshape(-1, arr.shape[-1]))
    else:
        curves = [np.asarray(r) for r in responses]
    for c in curves:
        if c.shape != f.shape:
            raise ValueError(
                f"bode_plot: a response has shape {c.shape} but frequency_hz has {f.shape}; "
                "pass SISO responses (freq,) or a family (n, freq)."
            )
    if ax is None:
        fig, (ax_m, ax_p) = plt.subplots(2, 1, sharex=True, figsize=(7.5, 5.5))
    else:
        ax_m, ax_p = ax
        fig = ax_m.figure
    cmap = plt.get_cmap("viridis")
    norm = None
    if colour_by is not None:
        colour_by = np.asarray(colour_by, dtype=float)
        norm = matplotlib.colors.Normalize(colour_by.min(), colour_by.max())
    for i, c in enumerate(curves):
        kw = {}
        if labels is not None and i < len(labels):
            kw["label"] = labels[i]
        if norm is not None:
            kw["color"] = cmap(norm(colour_by[i]))
            kw["lw"] = 1.0
        fmt = styles[i] if styles is not None and i < len(styles) else "-"
        mag = np.abs(c)
        if db:
            ax_m.semilogx(f, 20 * np.log10(np.maximum(mag, 1e-300)), fmt, **kw)
        else:
            ax_m.loglog(f, mag, fmt, **kw)
        ax_p.semilogx(
            f, np.degrees(np.angle(c)), fmt, **{k: v for k, v in kw.items() if k != "label"}
        )
    unit = f" [{magnitude_unit}]" if magnitude_unit else ""
    ax_m.set_ylabel(("magnitude [dB]" if db else "magnitude") + unit)
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("frequency [Hz]")
    ax_p.set_yticks([-180, -90, 0, 90, 180])
    for a in (ax_m, ax_p):
        a.grid(True, which="both", alpha=0.3)
    if labels is not None:
        ax_m.legend(fontsize="small")
    if norm is not None:
        sm = matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap)
        fig.colorbar(sm, ax=[ax_m, ax_p], label=colour_label or "")
    if title:
        ax_m.set_title(title)
    return fig
