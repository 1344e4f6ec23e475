"""Where the gap lies: a map of the residual over time windows, frequency bands and
operating points, with significance that respects autocorrelation and controls false
discoveries across cells.

For a cell `c` (a set of samples: a time window, velocity reversals, a speed or position
bin, a direction, the samples where some recorded signal is "on") the statistic is the
*enrichment* `share_c / fraction_c`: the part of the squared gap (above the noise floor)
that falls in the cell, divided by the part of the samples it holds. Under the null
hypothesis "the gap does not depend on the cell" the residual can be shifted in time
against the cell mask: circular shifts by at least one block length keep the residual's
autocorrelation and the mask's structure while breaking their alignment (a circular
block permutation). The p-value of each cell is the share of all such shifts with an
enrichment at least as large (computed exactly, for every shift at once, by FFT
cross-correlation); Benjamini–Hochberg at `q` then controls the false discovery rate across
all cells of all axes.

Frequency bands compare the residual's Welch spectrum with the noise floor: in a band of
`m` bins from `K` averaged segments, a white noise of level `S₀` gives a band mean
distributed as `S₀ χ²_{2Km}/(2Km)`, so the p-value of "more than noise" is the χ² tail.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import scipy.signal as ss
import scipy.stats as st

from ._base import Experiment
from ._stats import benjamini_hochberg, block_length

__all__ = ["GapCell", "gap_map"]


@dataclasses.dataclass
class GapCell:
    axis: str  # "time" | "frequency" | "position" | "operating_point"
    label: str
    range: tuple[float, float] | None
    share: float  # share of the squared gap above noise in this cell
    fraction: float  # share of the samples (or of the band) the cell covers
    enrichment: float
    p_value: float
    significant: bool = False
    gap: float | None = None  # nrmse inside the cell

    def to_json(self) -> dict:
        return {
            "axis": self.axis,
            "label": self.label,
            "range": list(self.range) if self.range is not None else None,
            "share": self.share,
            "fraction": self.fraction,
            "enrichment": self.enrichment,
            "p_value": self.p_value,
            "significant": self.significant,
            "gap": self.gap,
        }


def _bins(x: np.ndarray, k: int) -> list[tuple[float, float]]:
    qs = np.quantile(x, np.linspace(0, 1, k + 1))
    edges = np.unique(qs)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


def _axis_of(label: str) -> str:
    low = label.lower()
    if "position" in low:
        return "position"
    return "operating_point"


def gap_map(
    experiments: Sequence[Experiment],
    residuals: Sequence[np.ndarray],
    *,
    n_time: int = 20,
    n_bins: int = 4,
    q: float = 0.05,
    seed: int = 0,
) -> list[GapCell]:
    """All cells of the gap map of `residuals` on `experiments`, significance included.

    Sorted by excess share (`share − fraction`), most concentrated first.
    """
    e = np.concatenate([np.asarray(r, float) for r in residuals])
    y = np.concatenate([x.y for x in experiments])
    noise = np.concatenate([np.full(x.n, x.noise_var) for x in experiments])
    energy = np.maximum(e * e - noise, 0.0)
    total = float(energy.sum())
    n = e.size
    if total <= 0 or n < 16:
        return []
    L = block_length(e)
    t = np.concatenate([x.t for x in experiments])
    names = np.concatenate([np.full(x.n, i) for i, x in enumerate(experiments)])

    masks: list[tuple[str, str, tuple[float, float] | None, np.ndarray]] = []
    # time windows: per experiment, n_time equal windows
    for i, x in enumerate(experiments):
        k = max(1, min(n_time, x.n // max(L, 1)))
        edges = np.linspace(x.t[0], x.t[-1], k + 1)
        for a, b in zip(edges[:-1], edges[1:]):
            m = (names == i) & (t >= a) & (t <= b)
            lab = (
                f"{x.name}: t = {a:.4g}–{b:.4g} s"
                if len(experiments) > 1
                else f"t = {a:.4g}–{b:.4g} s"
            )
            masks.append(("time", lab, (float(a), float(b)), m))
    # named operating-point cells
    keys = sorted({k for x in experiments for k in x.masks})
    for k in keys:
        m = np.concatenate(
            [
                np.asarray(x.masks[k], bool) if k in x.masks else np.zeros(x.n, bool)
                for x in experiments
            ]
        )
        if 0 < m.sum() < n:
            masks.append((_axis_of(k), k, None, m))
    # binned continuous operating points
    okeys = sorted({k for x in experiments for k in x.ops})
    for k in okeys:
        if not all(k in x.ops for x in experiments):
            continue
        v = np.concatenate([np.asarray(x.ops[k], float) for x in experiments])
        if np.ptp(v) <= 0:
            continue
        for a, b in _bins(v, n_bins):
            m = (v >= a) & (v <= b)
            if 0 < m.sum() < n:
                masks.append((_axis_of(k), f"{k} in [{a:.4g}, {b:.4g}]", (a, b), m))
    # per experiment, when there are several
    if len(experiments) > 1:
        for i, x in enumerate(experiments):
            masks.append(("operating_point", f"experiment {x.name}", None, names == i))

    cells: list[GapCell] = []
    M = np.stack([m for *_, m in masks]).astype(float)  # (cells, n)
    frac = M.mean(axis=1)
    share = (M @ energy) / total
    enr = share / np.maximum(frac, 1e-12)
    # exact circular-shift null: the energy in each cell for every shift at once (FFT
    # cross-correlation), restricted to shifts of at least one block length
    fe = np.fft.rfft(energy)
    fm = np.fft.rfft(M, axis=1)
    null = np.fft.irfft(np.conj(fm) * fe[None, :], n, axis=1) / total  # (cells, shift)
    shifts = np.arange(n)
    admissible = (shifts >= L) & (shifts <= n - L)
    if admissible.sum() < 20:
        admissible = shifts > 0
    null = null[:, admissible] / np.maximum(frac, 1e-12)[:, None]
    pvals = (1.0 + (null >= enr[:, None] - 1e-12).sum(axis=1)) / (admissible.sum() + 1.0)
    for (axis, lab, rng_, m), f, sh, en, p in zip(masks, frac, share, enr, pvals):
        ym = y[m.astype(bool)]
        em = e[m.astype(bool)]
        g = (
            float(np.sqrt(np.mean(em**2)) / max(np.sqrt(np.mean(ym**2)), 1e-300))
            if em.size
            else None
        )
        cells.append(GapCell(axis, lab, rng_, float(sh), float(f), float(en), float(p), gap=g))

    cells += _frequency_cells(experiments, residuals)
    sig = benjamini_hochberg([c.p_value for c in cells], q)
    for c, s_ in zip(cells, sig):
        c.significant = bool(s_) and c.enrichment > 1.0
    cells.sort(key=lambda c: -(c.share - c.fraction))
    return cells


def _frequency_cells(
    experiments: Sequence[Experiment], residuals: Sequence[np.ndarray]
) -> list[GapCell]:
    dt = experiments[0].dt
    fs = 1.0 / dt
    nper = int(min(min(x.n for x in experiments), 512))
    if nper < 32:
        return []
    p_sum, k_seg, f = None, 0, None
    s0 = 0.0
    for x, r in zip(experiments, residuals):
        f, p = ss.welch(np.asarray(r) - np.mean(r), fs=fs, nperseg=nper)
        segs = max(1, 2 * x.n // nper - 1)
        p_sum = p * segs if p_sum is None else p_sum + p * segs
        k_seg += segs
        s0 += x.noise_var / (fs / 2) * segs  # white noise of variance σ² → one-sided S0 = σ²/(fs/2)
    pxx = p_sum / k_seg
    s0 = s0 / k_seg
    total = float(np.sum(np.maximum(pxx - s0, 0.0)))
    if total <= 0:
        return []
    f_lo = max(f[1], fs / nper)
    edges = [0.0]
    edge = f_lo
    while edge < fs / 2:
        edges.append(edge)
        edge *= 2
    edges.append(fs / 2)
    cells = []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (f >= a) & (f < b) if b < fs / 2 else (f >= a) & (f <= b)
        m = int(sel.sum())
        if m == 0:
            continue
        band = float(np.sum(np.maximum(pxx[sel] - s0, 0.0)))
        ratio = float(np.mean(pxx[sel]) / max(s0, 1e-300))
        dof = 2 * k_seg * m
        p = float(st.chi2.sf(ratio * dof, dof)) if s0 > 0 else 0.0
        frac = m / f.size
        share = band / total
        cells.append(
            GapCell(
                "frequency",
                f"{a:.3g}–{b:.3g} Hz ({ratio:.3g}× the noise level)",
                (float(a), float(b)),
                share,
                frac,
                share / max(frac, 1e-12),
                max(p, 1e-300) if math.isfinite(p) else 1.0,
                gap=None,
            )
        )
    return cells
