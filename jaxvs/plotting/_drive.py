"""Figures of drive studies: ball-bar polar plot, Bode of the control loops, CWT scalogram."""

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np

from ._bode import bode_plot


def ballbar_plot(
    results,
    *,
    labels: Sequence[str] | None = None,
    magnification: float | None = None,
    title: str | None = None,
    ax=None,
):
    """Polar ball-bar plot: the radial deviation `ΔR(θ)` around the nominal circle, as the
    ball-bar software draws it (ISO 230-4).

    The nominal circle is drawn at radius 1 and `ΔR` is scaled by `magnification` (default:
    the largest deviation becomes 0.5 of the radius), so shapes (reversal spikes, ellipses)
    stay visible at micrometre scale; the scale is written in the title.

    **Arguments:**

    - `results`: a `jaxvs.models.BallbarResult` or a sequence of them (same radius).
    - `labels`: legend label per result.
    - `magnification`: plotted radius `1 + magnification · ΔR / R`.
    - `title`: figure title.
    - `ax`: optional polar axes.

    **Returns:**

    The matplotlib `Figure`.
    """
    if not isinstance(results, list | tuple):
        results = [results]
    if ax is None:
        fig, ax = plt.subplots(subplot_kw={"projection": "polar"}, figsize=(5.5, 5.5))
    else:
        fig = ax.figure
    R = results[0].radius
    dmax = max(float(np.max(np.abs(np.asarray(r.radial_error)))) for r in results)
    if magnification is None:
        magnification = 0.5 * R / dmax if dmax > 0 else 1.0
    th = np.linspace(0, 2 * np.pi, 361)
    ax.plot(th, np.ones_like(th), "k:", lw=0.8, label="nominal")
    for i, r in enumerate(results):
        theta = np.asarray(r.theta)
        order = np.argsort(theta)
        rad = 1 + magnification * np.asarray(r.radial_error)[order] / R
        label = labels[i] if labels is not None else None
        ax.plot(theta[order], rad, lw=1.2, label=label)
    ax.set_ylim(0, 1.6)
    ax.set_yticklabels([])
    scale = 1e6 * R / magnification  # µm per unit of plotted radius
    ax.set_title(
        (title + "\n" if title else "")
        + f"R = {1e3 * R:g} mm; ±{0.5 * scale:.3g} µm per half radius"
    )
    if labels is not None:
        ax.legend(loc="lower left", bbox_to_anchor=(-0.1, -0.15), fontsize=8)
    return fig


def loop_bode_plot(drive, frequency_hz, *, measured=None, measured_label="measured",
                   title=None):
    """Bode diagram of a drive's closed position loop `q/r` from its linearisation, with
    optional estimated FRFs (e.g. H1 from a simulated or measured swept-sine run) on top.

    **Arguments:**

    - `drive`: a `jaxvs.models.DriveAxis`.
    - `frequency_hz`: `(freq,)` frequencies [Hz].
    - `measured`: optional `(freq_hz, H)` pair or a sequence of them.
    - `measured_label`: legend label(s) of the measured curves.
    - `title`: figure title.

    **Returns:**

    The matplotlib `Figure`.
    """
    f = np.asarray(frequency_hz, dtype=float)
    H = np.asarray(drive.frequency_response(2 * np.pi * f))
    fig = bode_plot(f, [H], labels=["linearised q/r"], styles=["k-"], title=title,
                    magnitude_unit="m/m")
    if measured is not None:
        pairs = [measured] if isinstance(measured, tuple) else list(measured)
        names = [measured_label] if isinstance(measured_label, str) else list(measured_label)
        ax_mag, ax_ph = fig.axes[0], fig.axes[1]
        for (fm, Hm), name in zip(pairs, names):
            fm, Hm = np.asarray(fm), np.asarray(Hm)
            ax_mag.semilogx(fm, 20 * np.log10(np.abs(Hm)), ".", ms=3, label=name)
            ax_ph.semilogx(fm, np.degrees(np.angle(Hm)), ".", ms=3, label=name)
        ax_mag.legend(fontsize=8)
    return fig


def scalogram_plot(t, frequency_hz, coefficients, *, ridge_hz=None, title=None, ax=None):
    """Modulus of a CWT (`jaxvs.signal.cwt_morlet`) over time and frequency, in dB of its
    maximum, with an optional ridge.

    **Arguments:**

    - `t`: `(time,)` [s]; `frequency_hz`: `(freq,)` [Hz].
    - `coefficients`: `(freq, time)` complex CWT.
    - `ridge_hz`: optional `(time,)` ridge frequency [Hz].
    - `title`, `ax`: figure title, optional axes.

    **Returns:**

    The matplotlib `Figure`.
    """
    W = np.abs(np.asarray(coefficients))
    db = 20 * np.log10(W / W.max() + 1e-12)
    if ax is None:
        fig, ax = plt.subplots(figsize=(7, 3.5))
    else:
        fig = ax.figure
    mesh = ax.pcolormesh(np.asarray(t), np.asarray(frequency_hz), db, shading="auto",
                         vmin=-60, vmax=0, cmap="viridis")
    if ridge_hz is not None:
        ax.plot(np.asarray(t), np.asarray(ridge_hz), "w--", lw=1, label="ridge")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("frequency [Hz]")
    if title:
        ax.set_title(title)
    fig.colorbar(mesh, ax=ax, label="|W| [dB of max]")
    return fig
