"""Figures of a sim-to-real gap diagnosis: the verdict against the null, gap map, residual
against the signature regressors, before/after overlays, residual spectra, and the noise /
nonlinear-distortion split of a best linear approximation."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np
import scipy.signal as ss

__all__ = ["plot_bla", "plot_diagnosis", "plot_verdict"]

_STATE_COLOURS = {
    "adequate": "C2",
    "explained": "C0",
    "partly_explained": "C1",
    "unexplained": "C3",
}


def _validation_slices(report):
    ncal = len(report.calibration)
    exps = report.validation
    nom = report.predictions["nominal"][ncal:]
    fin = report.predictions["final"][ncal:]
    return exps, nom, fin


def plot_gap_map(report, ax=None):
    """Bars of the most concentrated gap-map cells: share of the gap vs share of samples."""
    cells = [c for c in report.cells if c.axis != "frequency"][:12]
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 0.35 * max(len(cells), 4) + 1.2))
    yy = np.arange(len(cells))[::-1]
    ax.barh(yy + 0.2, [c.share for c in cells], height=0.4, label="share of the gap", color="C3")
    ax.barh(yy - 0.2, [c.fraction for c in cells], height=0.4, label="share of samples", color="C7")
    ax.set_yticks(yy, [("* " if c.significant else "") + c.label for c in cells], fontsize=8)
    ax.set_xlabel("share")
    ax.set_title("Where the gap lies (nominal model; * significant at FDR 5 %)")
    ax.legend(loc="lower right", fontsize=8)
    return ax


def plot_signatures(report, fig=None):
    """Residual of the nominal and final models against each operating-point variable."""
    exps = report.calibration + report.validation
    keys = sorted({k for e in exps for k in e.ops})[:4]
    if fig is None:
        fig = plt.figure(figsize=(4 * max(len(keys), 1), 3.4))
    for j, k in enumerate(keys):
        ax = fig.add_subplot(1, max(len(keys), 1), j + 1)
        x = np.concatenate([np.asarray(e.ops[k]) for e in exps if k in e.ops])
        for name, col in (("nominal", "C3"), ("final", "C0")):
            r = np.concatenate(
                [e.y - p for e, p in zip(exps, report.predictions[name]) if k in e.ops]
            )
            step = max(1, x.size // 4000)
            ax.plot(x[::step], r[::step], ".", ms=1.5, alpha=0.4, color=col, label=name)
            edges = np.quantile(x, np.linspace(0, 1, 26))
            idx = np.clip(np.searchsorted(edges, x) - 1, 0, 24)
            mean = [r[idx == i].mean() if np.any(idx == i) else np.nan for i in range(25)]
            ax.plot(0.5 * (edges[1:] + edges[:-1]), mean, "-", color=col, lw=2)
        ax.set_xlabel(k)
        ax.set_ylabel("residual")
        if j == 0:
            ax.legend(fontsize=8, markerscale=5)
    fig.suptitle("Residual against the signature regressors")
    fig.tight_layout()
    return fig


def plot_before_after(report, fig=None):
    """Measured target and the nominal / final predictions on the first validation
    experiment, with the residuals below."""
    exps, _, _ = _validation_slices(report)
    ncal = len(report.calibration)
    e = exps[0]
    p0 = report.predictions["nominal"][ncal]
    p1 = report.predictions["final"][ncal]
    if fig is None:
        fig = plt.figure(figsize=(10, 5.5))
    a1 = fig.add_subplot(2, 1, 1)
    a1.plot(e.t, e.y, color="k", lw=0.8, label="measured")
    a1.plot(e.t, p0, color="C3", lw=0.8, label="nominal")
    a1.plot(e.t, p1, color="C0", lw=0.8, label="with effects")
    a1.set_ylabel(report.gap.get("target", "target"))
    a1.legend(fontsize=8, loc="upper right")
    a1.set_title(f"Validation experiment {e.name}")
    a2 = fig.add_subplot(2, 1, 2, sharex=a1)
    a2.plot(e.t, e.y - p0, color="C3", lw=0.6, label="nominal residual")
    a2.plot(e.t, e.y - p1, color="C0", lw=0.6, label="final residual")
    for k, m in e.masks.items():
        if k.endswith(" on"):
            a2.fill_between(
                e.t,
                0,
                1,
                where=np.asarray(m),
                color="C2",
                alpha=0.15,
                transform=a2.get_xaxis_transform(),
                label=k,
            )
    a2.set_xlabel("time [s]")
    a2.set_ylabel("residual")
    a2.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return fig


def plot_spectra(report, ax=None):
    """Welch spectra of the validation residuals before and after, with the noise floor."""
    exps, _, _ = _validation_slices(report)
    ncal = len(report.calibration)
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    fs = 1.0 / exps[0].dt
    for name, col in (("nominal", "C3"), ("final", "C0")):
        r = np.concatenate([e.y - p for e, p in zip(exps, report.predictions[name][ncal:])])
        f, p = ss.welch(r - r.mean(), fs=fs, nperseg=min(r.size, 1024))
        ax.loglog(f[1:], p[1:], color=col, label=f"{name} residual")
    s0 = np.mean([e.noise_var for e in exps]) / (fs / 2)
    ax.axhline(s0, color="k", ls="--", lw=1, label="noise floor")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD [unit²/Hz]")
    ax.set_title("Residual spectra (validation)")
    ax.legend(fontsize=8)
    return ax


def plot_verdict(report, ax=None, *, title: str | None = None):
    """The verdict's state: the held-out gaps the nominal model leaves on the effect-free
    null records (dots), the bound of the null (its 95th percentile widened by the noise
    level's uncertainty, dashed), the nominal model's held-out gap and the remainder after
    the accepted effects (the marker coloured by the state), all in units of the noise
    floor.

    **Arguments:** `report` a `DiagnosisReport`; `ax` a matplotlib axis (created when
    `None`); `title` (default: the state and the effects).

    **Returns:** the axis.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.5, 2.6))
    g, v = report.gap, report.verdict
    rem = v.get("remainder") or {}
    floor = g["noise_floor"] or 1.0
    null = np.asarray(g.get("null_gaps") or [], float) / floor
    rng = np.random.default_rng(0)
    ax.scatter(null, 0.1 * rng.uniform(-1, 1, null.size), s=14, color="C7", label="null records")
    if rem.get("threshold_over_floor") is not None:
        ax.axvline(rem["threshold_over_floor"], color="k", ls="--", lw=1, label="null bound")
    state = v.get("status") or "adequate"
    col = _STATE_COLOURS.get(state, "k")
    nominal = g["validation"] / floor
    final = v["validation_gap"] / floor
    if v.get("effects"):
        ax.scatter([nominal], [0.0], marker="o", s=60, facecolors="none", edgecolors=col,
                   label="nominal model")  # fmt: skip
        ax.annotate("", (final, 0.0), (nominal, 0.0),
                    arrowprops={"arrowstyle": "->", "color": col})  # fmt: skip
    ax.scatter([final], [0.0], marker="D", s=60, color=col, label="remaining gap")
    ax.set_xscale("log")
    lo = min([0.8, *null.tolist(), final])
    hi = max([2.0, nominal, final, rem.get("threshold_over_floor") or 1.0]) * 1.5
    ax.set_xlim(lo * 0.8, hi)
    ax.set_ylim(-0.5, 0.5)
    ax.set_yticks([])
    ax.set_xlabel("held-out gap / noise floor")
    effects = ", ".join(v.get("effects") or []) or "no effect"
    ax.set_title(title or f"{state.replace('_', ' ')} ({effects})", color=col, fontsize=10)
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    return ax


def plot_bla(bla, fs: float = 1.0, ax=None):
    """A best linear approximation's split of what it does not explain: the output's
    power at the excited lines (the BLA), the noise (from period to period) and the
    nonlinear distortion (from realisation to realisation, or at the lines the excitation
    leaves empty), per DFT line of one period.

    **Arguments:** `bla` a `jaxvs.signal.BLA`; `fs` the sampling rate [Hz] (1: lines in
    cycles per sample); `ax` a matplotlib axis.

    **Returns:** the axis.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    n = bla.period_samples
    k_all = np.arange(bla.y_noise_var.size)
    f_all = k_all * fs / n
    lines = bla.lines
    f = lines * fs / n
    db = lambda x: 10 * np.log10(np.maximum(np.asarray(x, float), 1e-300))  # noqa: E731
    # the lines not excited where the output's power stands above its noise
    free = ~np.isin(k_all, lines) & (k_all > 0) & (bla.y_excess > bla.y_noise_var / bla.periods)
    ax.plot(f_all[free], db(bla.y_excess[free]), ".", color="C1", ms=3,
            label="output at lines not excited (above the noise)")  # fmt: skip
    ax.plot(f, db(bla.y_noise_var[lines]), "-", color="C7", lw=1, label="noise (period to period)")
    if np.isfinite(bla.y_distortion_var).any():
        ax.plot(f, db(bla.y_distortion_var), "-", color="C3", lw=1.5,
                label="nonlinear distortion (realisations)")  # fmt: skip
    low = float(np.min(db(bla.y_noise_var[lines])))
    ax.set_ylim(bottom=low - 15.0)
    ax.set_xlabel("frequency [Hz]" if fs != 1.0 else "frequency [cycles/sample]")
    ax.set_ylabel("power per line [dB]")
    ax.set_title(
        f"noise {bla.noise_level:.3g}, distortion {bla.distortion_level:.3g} "
        f"({bla.realisations} realisation(s) × {bla.periods} periods)",
        fontsize=10,
    )
    ax.legend(fontsize=8)
    return ax


def plot_diagnosis(report, out) -> list[str]:
    """Write the figures of a diagnosis report (five, and the discovered term's shape
    when discovery fired) as PNG files into `out`.

    **Arguments:**

    - `report`: a `jaxvs.diagnosis.DiagnosisReport`.
    - `out`: folder (created).

    **Returns:** the file names written (relative to `out`).
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = []
    for fname, draw in (
        ("verdict.png", lambda: plot_verdict(report).figure),
        ("gap_map.png", lambda: plot_gap_map(report).figure),
        ("residual_signatures.png", lambda: plot_signatures(report)),
        ("before_after.png", lambda: plot_before_after(report)),
        ("residual_spectra.png", lambda: plot_spectra(report).figure),
    ):
        fig = draw()
        fig.savefig(out / fname, dpi=110, bbox_inches="tight")
        plt.close(fig)
        names.append(fname)
    found = getattr(report, "discovered", None)
    if found is not None and getattr(found, "shape", None):
        from ._discover import plot_discovered

        fig = plot_discovered(found).figure
        fig.savefig(out / "discovered.png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        names.append("discovered.png")
    return names
