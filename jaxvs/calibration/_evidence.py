r"""Sparse selection of linear terms by Bayesian evidence, and its stability.

The model is `y = B β + Σ_{j ∈ S} X_j c_j + e`: base columns `B` that are always in
(the nominal model's Jacobian, an intercept), and groups of candidate columns `X_j`
(a term of one or more columns, e.g. a sine and a cosine of one pitch). The evidence of a
support `S` is the marginal likelihood of the linear-Gaussian model with **Zellner's
g-prior** on the candidate coefficients, `c ~ N(0, g σ² (X_Sᵀ X_S)⁻¹)` (columns made
orthogonal to `B` first), a flat prior on `β` and Jeffreys' prior on `σ²`. Its Bayes
factor against the base model has the closed form (Liang, Paulo, Molina, Clyde & Berger
2008, *JASA* 103(481), eq. 5, with the base columns in the role of the intercept)

    log BF(S) = (m − k_S)/2 · log(1 + g) − m/2 · log(1 + g · SSR_S / SSR_0),

`m = N − p_B` the observations left after the base, `k_S` the candidate columns in `S`.
`g = N` is the unit-information prior (Kass & Wasserman 1995): the evidence then behaves
like BIC but is exact for every `N`. An autocorrelated residual carries the information
of fewer samples: pass `n_eff` (e.g. `N/τ`, `τ` the integrated autocorrelation time) and
it replaces `N` in `m` and `g`.

- [`log_evidence`][]: the formula above.
- [`backward_elimination`][]: start from every group, remove the group whose removal
  raises the evidence most, stop when no removal raises it.
- [`stability_selection`][]: the elimination on resamples (e.g. moving-block bootstrap
  indices): the frequency with which each group is kept (Meinshausen & Bühlmann 2010,
  *JRSS B* 72(4), with elimination in place of the lasso).

Host-side NumPy: the work is on Gram matrices of a few dozen columns.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

__all__ = [
    "EvidenceSelection",
    "backward_elimination",
    "log_evidence",
    "stability_selection",
]


def log_evidence(ssr: float, ssr0: float, m: float, k: int, g: float) -> float:
    """Log Bayes factor of a support with `k` candidate columns and residual sum of
    squares `ssr` against the base model (`ssr0`), with `m` observations beyond the base
    and Zellner's g-prior of scale `g` (module doc)."""
    if ssr0 <= 0:
        return 0.0
    ratio = max(float(ssr) / float(ssr0), 1e-300)
    return float(0.5 * (m - k) * np.log1p(g) - 0.5 * m * np.log1p(g * ratio))


@dataclasses.dataclass(frozen=True)
class EvidenceSelection:
    """Result of [`backward_elimination`][].

    - `support`: indices of the groups kept, ascending.
    - `log_evidence`: log Bayes factor of the support against the base model.
    - `coefficients`: least-squares coefficients of the kept columns (in the units of
      the columns given, base columns profiled out), by group.
    - `path`: `(group removed, log evidence after)` of every elimination step.
    """

    support: tuple[int, ...]
    log_evidence: float
    coefficients: dict[int, np.ndarray]
    path: tuple[tuple[int, float], ...]


class _Gram:
    """Gram matrix of the candidate columns with the base projected out (the Schur
    complement), the columns scaled to unit norm for the conditioning; SSRs of any
    support from it."""

    def __init__(self, X, y, base, weights):
        X = np.asarray(X, float)
        y = np.asarray(y, float)
        w = np.ones(y.size) if weights is None else np.asarray(weights, float)
        A = np.column_stack([X, y])
        if base is not None and np.size(base):
            B = np.asarray(base, float).reshape(y.size, -1)
            bw = B * w[:, None]
            gbb = bw.T @ B
            gba = bw.T @ A
            gaa = (A * w[:, None]).T @ A
            jitter = 1e-12 * np.trace(gbb) / max(gbb.shape[0], 1)
            full = gaa - gba.T @ sla.solve(gbb + jitter * np.eye(gbb.shape[0]), gba, assume_a="pos")
        else:
            full = (A * w[:, None]).T @ A
        k = X.shape[1]
        d = np.sqrt(np.clip(np.diag(full)[:k], 1e-300, None))
        self.scale = d
        self.G = full[:k, :k] / np.outer(d, d)
        self.b = full[:k, k] / d
        self.yy = float(full[k, k])

    def solve(self, cols: np.ndarray) -> tuple[float, np.ndarray]:
        if cols.size == 0:
            return self.yy, np.zeros(0)
        g = self.G[np.ix_(cols, cols)]
        try:
            beta = sla.solve(g + 1e-14 * np.eye(cols.size), self.b[cols], assume_a="pos")
        except (np.linalg.LinAlgError, sla.LinAlgError):
            beta = np.linalg.lstsq(g, self.b[cols], rcond=1e-12)[0]  # collinear columns
        return max(self.yy - float(self.b[cols] @ beta), 0.0), beta / self.scale[cols]


def _columns(groups: Sequence[Sequence[int]], support) -> np.ndarray:
    if not support:
        return np.zeros(0, int)
    return np.concatenate([np.asarray(groups[j], int) for j in support])


def _eliminate(gram: _Gram, groups, m: float, g: float, margin: float = 0.0) -> EvidenceSelection:
    support = list(range(len(groups)))
    k_of = [len(gr) for gr in groups]
    ssr0 = gram.yy

    def ev(sup):
        ssr, _ = gram.solve(_columns(groups, sup))
        return log_evidence(ssr, ssr0, m, sum(k_of[j] for j in sup), g)

    current = ev(support)
    path = []
    while support:
        trials = [(ev([s for s in support if s != j]), j) for j in support]
        best, j = max(trials)
        if not best > current - margin:
            break
        support.remove(j)
        current = best
        path.append((j, best))
    _, beta = gram.solve(_columns(groups, support))
    coefs, i = {}, 0
    for j in support:
        coefs[j] = beta[i : i + k_of[j]]
        i += k_of[j]
    return EvidenceSelection(tuple(sorted(support)), float(current), coefs, tuple(path))


def _check(X, y, groups):
    X = np.asarray(X)
    if X.ndim != 2 or X.shape[0] != np.size(y):
        raise ValueError(
            f"evidence selection: X must be (n, k) with n = len(y) = {np.size(y)}; got {X.shape}."
        )
    flat = sorted(c for gr in groups for c in gr)
    if flat != list(range(X.shape[1])):
        raise ValueError(
            "evidence selection: groups must partition the columns of X exactly once; "
            f"got groups covering {flat} for {X.shape[1]} columns."
        )


def _setup(X, y, groups, base, n_eff, g):
    """The checked groups (default: one per column), the number of rows `n`, the effective
    sample size, the base's column count and the prior scale `g` (default `n_eff`)."""
    groups = [[j] for j in range(np.shape(X)[1])] if groups is None else [list(gr) for gr in groups]
    _check(X, y, groups)
    n = np.size(y)
    n_eff = float(n if n_eff is None else min(max(n_eff, 2.0), n))
    p_b = 0 if base is None else int(np.asarray(base).reshape(n, -1).shape[1])
    g = n_eff if g is None else float(g)
    return groups, n, n_eff, p_b, g


def backward_elimination(
    X,
    y,
    groups: Sequence[Sequence[int]] | None = None,
    *,
    base=None,
    n_eff: float | None = None,
    g: float | None = None,
    margin: float = 0.0,
) -> EvidenceSelection:
    """Backward elimination of groups of columns on the g-prior evidence (module doc).

    **Arguments:**

    - `X`: `(n, k)` candidate columns; `y`: `(n,)` target.
    - `groups`: a partition of the columns into terms (default: one column each).
    - `base`: `(n, p)` columns always in the model (profiled out), or `None`.
    - `n_eff`: effective number of samples (default `n`); `g`: the prior scale
        (default `n_eff`, the unit-information prior).
    - `margin`: a group stays only when it raises the log evidence by more than this
        (default 0; 5 is a Bayes factor of e⁵, the ΔBIC of 10 named effects must pass).
    """
    groups, n, n_eff, p_b, g = _setup(X, y, groups, base, n_eff, g)
    return _eliminate(_Gram(X, y, base, None), groups, n_eff - p_b, g, margin)


def stability_selection(
    X,
    y,
    groups: Sequence[Sequence[int]] | None = None,
    *,
    resamples: np.ndarray,
    base=None,
    n_eff: float | None = None,
    g: float | None = None,
    margin: float = 0.0,
) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """Backward elimination on each resample of the rows (`resamples`: `(R, n)` integer
    indices, e.g. a moving-block bootstrap). Returns the frequency with which each group
    is kept `(n_groups,)` and the supports of every resample."""
    groups, n, n_eff, p_b, g = _setup(X, y, groups, base, n_eff, g)
    resamples = np.asarray(resamples)
    counts = np.zeros(len(groups))
    supports = []
    for idx in resamples:
        w = np.bincount(idx, minlength=n).astype(float)
        sel = _eliminate(_Gram(X, y, base, w), groups, n_eff - p_b, g, margin)
        supports.append(sel.support)
        counts[list(sel.support)] += 1
    return counts / max(len(resamples), 1), supports
