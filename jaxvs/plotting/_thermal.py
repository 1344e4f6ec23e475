"""Figures of the thermal virtual-sensor study: residual analysis (Fig. 10), correlation
matrix (Fig. 5), measured vs predicted target (Fig. 6, 8, 9)."""

from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np
import scipy.stats as st

from ..studies import ResidualAnalysis, residual_analysis

__all__ = ["correlation_plot", "prediction_plot", "residual_plot"]


def residual_plot(
    residuals: np.ndarray,
    *,
    t: np.ndarray | None = None,
    operating_point: np.ndarray | None = None,
    operating_point_label: str = "v_m [rpm]",
    analysis: ResidualAnalysis | None = None,
    unit: str = "K",
    title: str | None = None,
):
    """Residual analysis in four panels (study Fig. 10): residuals over time, histogram
    with the fitted normal density, autocorrelation with its confidence bounds, residuals
    against the operating point.

    **Arguments:**

    - `residuals`: `(n,)` measured minus predicted [`unit`].
    - `t`: `(n,)` times [s] (default: sample index); `operating_point`: `(n,)` e.g. the
      motor speed (default: the fourth panel shows residual vs predicted lag-1 residual).
    - `analysis`: a precomputed [`jaxvs.studies.ResidualAnalysis`][] (default: computed).

    **Returns:** the matplotlib `Figure`.
    """
    e = np.asarray(residuals, dtype=float)
    a = residual_analysis(e) if analysis is None else analysis
    x = np.arange(e.size) if t is None else np.asarray(t, dtype=float) / 3600.0
    fig, axs = plt.subplots(2, 2, figsize=(9.5, 6.5))
    ax = axs[0, 0]
    ax.plot(x, e, lw=0.6)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("sample" if t is None else "t [h]")
    ax.set_ylabel(f"residual [{unit}]")
    ax.set_title("residuals")
    ax = axs[0, 1]
    ax.hist(e, bins=50, density=True, alpha=0.7)
    grid = np.linspace(e.min(), e.max(), 200)
    ax.plot(grid, st.norm.pdf(grid, a.mean, a.std), "k-", lw=1.0, label="normal fit")
    ax.set_xlabel(f"residual [{unit}]")
    ax.set_title(f"histogram (normality p = {a.normality_pvalue:.2g})")
    ax.legend(fontsize="small")
    ax = axs[1, 0]
    ax.vlines(a.lags, 0, a.acf, lw=1.0)
    ax.axhline(a.bound, color="r", ls="--", lw=0.8)
    ax.axhline(-a.bound, color="r", ls="--", lw=0.8)
    ax.set_xlabel("lag [samples]")
    ax.set_ylabel("autocorrelation")
    ax.set_title(f"ACF, {100 * a.confidence:g} % bounds (Ljung-Box p = {a.ljung_box_pvalue:.2g})")
    ax = axs[1, 1]
    if operating_point is not None:
        ax.plot(np.asarray(operating_point, dtype=float), e, ".", ms=1.5, alpha=0.5)
        ax.set_xlabel(operating_point_label)
        ax.set_title("residual vs operating point")
    else:
        ax.plot(e[:-1], e[1:], ".", ms=1.5, alpha=0.5)
        ax.set_xlabel(f"residual(k) [{unit}]")
        ax.set_title("residual(k+1) vs residual(k)")
    ax.set_ylabel(f"residual [{unit}]")
    for ax in axs.flat:
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def correlation_plot(names: Sequence[str], R: np.ndarray, *, title: str | None = None):
    """Matrix of correlation coefficients (study Fig. 5), annotated with their values.

    **Arguments:** `names`: `(n,)` variable names; `R`: `(n, n)` correlation matrix (e.g.
    from [`jaxvs.studies.correlation_matrix`][]).

    **Returns:** the matplotlib `Figure`.
    """
    R = np.asarray(R, dtype=float)
    n = len(names)
    if R.shape != (n, n):
        raise ValueError(f"correlation_plot: R has shape {R.shape}; need ({n}, {n}).")
    fig, ax = plt.subplots(figsize=(0.55 * n + 2.5, 0.55 * n + 1.5))
    im = ax.imshow(R, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(n), names, rotation=60, ha="right", fontsize="small")
    ax.set_yticks(range(n), names, fontsize="small")
    for i in range(n):
        for j in range(n):
            if np.isfinite(R[i, j]):
                ax.text(j, i, f"{R[i, j]:.2f}", ha="center", va="center", fontsize=6)
    fig.colorbar(im, ax=ax, label="Pearson r")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def prediction_plot(
    t: np.ndarray,
    measured: np.ndarray,
    predictions: Mapping[str, np.ndarray],
    *,
    split: float | None = None,
    unit: str = "°C",
    label: str = "T_bearing",
    title: str | None = None,
):
    """Measured target and model predictions over time (study Fig. 6, 8, 9), with the
    residuals below.

    **Arguments:** `t`: `(n,)` times [s]; `measured`: `(n,)`; `predictions`: name ->
    `(n,)`; `split`: time [s] of the training/test boundary, drawn as a line.

    **Returns:** the matplotlib `Figure`.
    """
    h = np.asarray(t, dtype=float) / 3600.0
    y = np.asarray(measured, dtype=float)
    fig, (ax1, ax2) = plt.subplots(
        2, 1, sharex=True, figsize=(9, 5.5), gridspec_kw={"height_ratios": [2, 1]}
    )
    ax1.plot(h, y, "k-", lw=1.2, label="measured")
    for name, p in predictions.items():
        p = np.asarray(p, dtype=float)
        ax1.plot(h, p, lw=0.8, label=name)
        ax2.plot(h, y - p, lw=0.6, label=name)
    for ax in (ax1, ax2):
        if split is not None:
            ax.axvline(split / 3600.0, color="gray", ls="--", lw=0.8)
        ax.grid(True, alpha=0.3)
    ax1.set_ylabel(f"{label} [{unit}]")
    ax2.set_ylabel(f"residual [{'K' if unit == '°C' else unit}]")
    ax2.set_xlabel("t [h]")
    ax1.legend(fontsize="small")
    if title:
        ax1.set_title(title)
    fig.tight_layout()
    return fig
