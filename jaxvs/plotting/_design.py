"""Figures of a design report: held-out prediction against measurement for the top
designs, held-out score against complexity, and the input ranking."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["plot_design"]

_COLOURS = {"regression": "C0", "lag": "C1", "arx": "C2", "mlp": "C3", "tdnn": "C4"}


def design_predictions_plot(report, top: int = 3):
    """Held-out target (measured samples as dots, resampled target as a line for a
    sparse target) and the predictions of the `top` designs."""
    a = report.arrays
    V = a["role"] == 2
    t = a["t"][V]
    x = (t - t[0]) / 3600.0 if t.size and (t[-1] - t[0]) > 7200 else t - t[0]
    unit = "h" if t.size and (t[-1] - t[0]) > 7200 else "s"
    fig, ax = plt.subplots(figsize=(9, 3.8))
    meas = a["measured"][V]
    if not np.all(meas):
        ax.plot(x, a["y"][V], color="0.7", lw=1, label="resampled target")
        ax.plot(x[meas], a["raw_target"][V][meas], "k.", ms=3, label="measured")
    else:
        ax.plot(x, a["y"][V], "k", lw=1, label="measured")
    for rank in sorted(report.predictions)[:top]:
        d = report.designs[rank - 1]
        ax.plot(
            x,
            report.predictions[rank][V],
            lw=1.2,
            label=f"#{rank} {d['structure']} ({', '.join(d['inputs'])}), "
            f"RMSE {d['validation']['rmse']:.3g}",
        )
    ax.set_xlabel(f"held-out time [{unit}]")
    ax.set_ylabel(report.content["target"])
    ax.legend(fontsize=7)
    ax.set_title("Held-out prediction of the top designs")
    fig.tight_layout()
    return fig


def design_complexity_plot(report):
    """Held-out RMSE (with its bootstrap interval) against the number of parameters,
    coloured by structure; the suggested design is circled."""
    fig, ax = plt.subplots(figsize=(7, 4.2))
    seen = set()
    for d in report.designs:
        s = d["structure"]
        lo, hi = d["validation"]["rmse_interval"]
        r = d["validation"]["rmse"]
        ax.errorbar(
            d["parameters"],
            r,
            yerr=[[r - lo], [hi - r]],
            fmt="o",
            ms=3,
            color=_COLOURS.get(s, "k"),
            alpha=0.5,
            lw=0.6,
            label=s if s not in seen else None,
        )
        seen.add(s)
    b = report.best
    ax.plot(
        b["parameters"], b["validation"]["rmse"], "o", ms=12, mfc="none", mec="k", label="suggested"
    )
    base = (report.content["baseline"].get("validation") or {}).get("rmse")
    if base is not None:
        ax.axhline(base, color="0.5", ls="--", lw=0.8, label="baseline (1-input regression)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("parameters")
    ax.set_ylabel("held-out RMSE")
    ax.set_title("Score against complexity")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def input_ranking_plot(report):
    """|correlation| and |partial correlation| with the target per candidate input."""
    rows = [r for r in report.content["input_ranking"] if r["correlation"] is not None]
    names = [r["name"] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 0.4 * len(rows) + 1.5))
    y = np.arange(len(rows))
    ax.barh(y - 0.2, [abs(r["correlation"]) for r in rows], 0.4, label="|correlation|")
    ax.barh(
        y + 0.2, [abs(r["partial_correlation"]) for r in rows], 0.4, label="|partial correlation|"
    )
    sel = report.content["forward_selection"]["selected"]
    ax.set_yticks(y, [n + (" ✓" if n in sel else "") for n in names])
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_title("Input ranking (✓: chosen by forward selection)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_design(report, out) -> list[str]:
    """Write the figures of a design report as PNG files into `out`.

    **Arguments:** `report`: a `jaxvs.studies.design.DesignReport`; `out`: folder (created).

    **Returns:** the file names written (relative to `out`).
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = []
    for fname, draw in (
        ("heldout_prediction.png", design_predictions_plot),
        ("score_vs_complexity.png", design_complexity_plot),
        ("input_ranking.png", input_ranking_plot),
    ):
        fig = draw(report)
        fig.savefig(out / fname, dpi=110, bbox_inches="tight")
        plt.close(fig)
        names.append(fname)
    return names
