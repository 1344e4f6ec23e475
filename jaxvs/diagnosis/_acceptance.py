"""The acceptance of an effect: one set of tests, used when an effect is added and when it
is tested again against the final model without it.

An effect earns its place when, on held-out experiments the calibration never saw,

1. its best fit is physically admissible (`effect.admissible`);
2. the held-out gap reduction has a moving-block bootstrap interval excluding zero;
3. it removes at least `min_shrink` of the held-out gap;
4. ΔBIC > `min_delta_bic`, with the effective sample size of the residual the model with
   the effect leaves, never below what the noise alone carries (the null records): a
   large effect partly explained leaves structure that must not discount its own
   evidence, so ΔBIC guards the complexity while the bootstrap and the null decide;
5. the held-out reduction exceeds what the same effect, from the same start, gains on the
   effect-free null records (`null_threshold`).

[`compare`][] computes the evidence of one model against another; [`rejection`][] names the
first test it fails (or `None`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.stats

from ._stats import bic_effective, block_length, effective_samples, gap_change_interval

__all__ = [
    "Evidence",
    "Thresholds",
    "compare",
    "evidence_samples",
    "noise_sample_share",
    "null_threshold",
    "rejection",
]


@dataclasses.dataclass(frozen=True)
class Thresholds:
    """The levels of the acceptance tests (`jaxvs.diagnose` documents each)."""

    min_shrink: float = 0.05
    min_delta_bic: float = 10.0
    n_boot: int = 300


@dataclasses.dataclass(frozen=True)
class Evidence:
    """What the held-out data and the information criterion say about a model with an
    effect (`after`) against the same model without it (`before`)."""

    gap_before: float
    gap_after: float
    shrink: float
    reduction_interval: tuple[float, float]
    shrink_interval: tuple[float, float]
    delta_bic: float

    @property
    def reduction(self) -> float:
        return self.gap_before - self.gap_after


def compare(
    before: np.ndarray,
    after: np.ndarray,
    target: np.ndarray,
    fit_before: tuple[float, int],
    fit_after: tuple[float, int, np.ndarray],
    *,
    noise_share: float,
    thresholds: Thresholds,
    seed: int,
) -> Evidence:
    """The evidence of the model that leaves the held-out residual `after` against the
    one that leaves `before` (`target`: the held-out measurements).

    - `fit_before`: `(calibration SSR, degrees of freedom)` of the model without the effect.
    - `fit_after`: the same of the model with it, and its calibration residual (whose
      effective sample size the ΔBIC uses, bounded below by `noise_share` of it).
    """
    g0, g1, shrink, d_int, s_int = gap_change_interval(
        before, after, target, length=block_length(before), n_boot=thresholds.n_boot, seed=seed
    )
    ssr0, dof0 = fit_before
    ssr1, dof1, r_cal = fit_after
    n_eff = evidence_samples(r_cal, noise_share)
    n = int(np.size(r_cal))
    dbic = bic_effective(ssr0, n, dof0, n_eff) - bic_effective(ssr1, n, dof1, n_eff)
    return Evidence(g0, g1, shrink, d_int, s_int, dbic)


def rejection(
    ev: Evidence,
    thresholds: Thresholds,
    *,
    admissible: tuple[bool, str | None] = (True, None),
    null: float | None = None,
) -> str | None:
    """The first acceptance test `ev` fails, or `None` when it passes them all.

    - `admissible`: the effect's physics verdict `(ok, reason)`.
    - `null`: the held-out reduction the effect must exceed on the null records; `None`
      skips that test (the null is run only for effects that pass the others).
    """
    ok, why = admissible
    if not ok:
        return f"inadmissible: {why}"
    if not ev.reduction_interval[0] > 0:
        return "held-out reduction not significant (bootstrap interval includes zero)"
    if ev.shrink < thresholds.min_shrink:
        return f"shrink below {thresholds.min_shrink:g}"
    if not ev.delta_bic > thresholds.min_delta_bic:
        return f"ΔBIC (effective sample size) not above {thresholds.min_delta_bic:g}"
    if null is not None and not ev.reduction > null:
        return f"held-out reduction {ev.reduction:.3g} not above the null threshold {null:.3g}"
    return None


def null_threshold(gains: Sequence[float], level: float, tested: int) -> float:
    """The held-out reduction a candidate must exceed: the `level` quantile of its gains on
    the null records, and, since several candidates face the null in one round, at
    least the normal tail quantile `mean + z·sd` at level `1 − (1 − level)/tested`
    (Bonferroni across the candidates tested; the few null records cannot resolve that
    tail empirically).

    A loss on a null record (a fit that made its held-out gap worse, e.g. one stuck in a
    local minimum away from the effect-free model) counts as no gain: such a fit is never
    accepted, so it is no false discovery, and its size must not widen the normal tail
    the candidate has to beat."""
    g = np.maximum(np.asarray([v for v in gains if np.isfinite(v)], float), 0.0)
    if g.size < 2:
        return float("inf")
    alpha = (1.0 - level) / max(int(tested), 1)
    z = float(scipy.stats.norm.ppf(1.0 - alpha))
    return max(float(np.quantile(g, level)), float(g.mean() + z * g.std(ddof=1)))


def noise_sample_share(null_residuals: Sequence[Sequence[np.ndarray]]) -> float:
    """The median share `N_eff / N` of independent samples in the residuals of the
    effect-free records (each record's experiments concatenated): the evidence one sample
    of the noise carries after the set-up's filters and loop. 0 without null records."""
    shares = []
    for rows in null_residuals:
        e = np.concatenate([np.asarray(r, float) for r in rows])
        if e.size >= 4:
            shares.append(effective_samples(e) / e.size)
    return float(np.median(shares)) if shares else 0.0


def evidence_samples(residual: np.ndarray, noise_share: float) -> float:
    """The effective sample size of the ΔBIC: that of the residual left by the model
    under test, but never below what the noise alone carries (`noise_share · N`, from the
    effect-free records). A candidate that removes a large share of a gap far above the
    floor leaves structure behind; that structure must not make its evidence smaller
    than that of a small effect leaving white noise."""
    n = np.size(residual)
    return float(max(effective_samples(residual), noise_share * n))
