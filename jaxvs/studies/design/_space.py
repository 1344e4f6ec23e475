"""The design space: ranking of candidate inputs (correlation, partial correlation and the
study's relevance/redundancy criterion), greedy forward selection with held-out scoring,
and the enumeration of candidate designs.

Linear structures come plain and with the squares of their inputs (a quadratic static
nonlinearity). Forward selection scores a subset by the blocked cross-validation error
(contiguous folds of the calibration data) of a cheap linear model that can follow the
thermal dynamics: least squares on the inputs and their squares filtered by a first-order
lag, the time constant profiled on a grid that includes the static case. An input joins
only when it lowers that held-out error by at least 2 % and significantly (paired
moving-block bootstrap, 95 %): a distractor correlated with an input already chosen
explains nothing new on held-out data and stays out, however high its correlation with
the target.
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import scipy.signal as ss

from ...signal import block_bootstrap_means, block_length
from ..thermal import rank_inputs
from ._search import Candidate

__all__ = ["candidates", "forward_selection", "input_ranking"]


def input_ranking(U: np.ndarray, y: np.ndarray, names: list[str]) -> list[dict]:
    """Correlation, partial correlation (given all other candidates) and the relevance /
    redundancy ranking of `jaxvs.studies.rank_inputs`, on training samples."""
    ok = [j for j in range(U.shape[1]) if np.ptp(U[:, j]) > 0]
    data = {names[j]: U[:, j] for j in ok}
    data["__target__"] = y
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ranks = rank_inputs(data, "__target__", [names[j] for j in ok]) if ok else []
    Z = np.column_stack([y] + [U[:, j] for j in ok])
    R = np.corrcoef(Z, rowvar=False)
    P = np.linalg.pinv(R)
    partial = {
        names[j]: float(-P[0, 1 + k] / np.sqrt(P[0, 0] * P[1 + k, 1 + k])) for k, j in enumerate(ok)
    }
    corr = {names[j]: float(R[0, 1 + k]) for k, j in enumerate(ok)}
    out = [
        {
            "name": r.name,
            "correlation": corr[r.name],
            "partial_correlation": partial[r.name],
            "relevance_redundancy_score": r.score,
            "redundant": bool(r.redundant),
        }
        for r in ranks
    ]
    out += [
        {
            "name": names[j],
            "correlation": None,
            "partial_correlation": None,
            "relevance_redundancy_score": None,
            "redundant": None,
            "constant": True,
        }
        for j in range(U.shape[1])
        if j not in ok
    ]
    return out


def _lag_bank(U: np.ndarray, starts: np.ndarray, a_grid: np.ndarray) -> np.ndarray:
    """`(grid, time, input)`: inputs through first-order lags `a`, steady start per
    experiment (`a = 0`: the inputs themselves)."""
    bounds = np.flatnonzero(starts).tolist() + [U.shape[0]]
    out = np.empty((a_grid.size,) + U.shape)
    for g, a in enumerate(a_grid):
        for s, e in zip(bounds[:-1], bounds[1:]):
            x = U[s:e]
            out[g, s:e] = ss.lfilter([1 - a], [1, -a], x, axis=0, zi=a * x[:1])[0]
    return out


def forward_selection(
    U: np.ndarray,
    y: np.ndarray,
    role: np.ndarray,
    measured: np.ndarray,
    starts: np.ndarray,
    names: list[str],
    dt: float,
    *,
    max_inputs: int,
    folds: int = 4,
    seed: int = 0,
) -> tuple[list[int], list[dict]]:
    """Greedy forward selection of inputs scored by blocked cross-validation on the
    calibration data (`folds` contiguous blocks; the held-out data are never used).

    **Returns:** `(pool, steps)`: input indices (the selected ones in the order chosen,
    then the best rejected ones, up to `max_inputs`), and per step the stopping-block RMSE
    of every tried input and whether the best was accepted.
    """
    cal = np.flatnonzero((role == 0) | (role == 1))
    n_T = int(np.sum(role == 0))
    tau = np.geomspace(2 * dt, max(n_T * dt / 2, 4 * dt), 40)
    a_grid = np.concatenate([[0.0], np.exp(-dt / tau)])
    m = U.shape[1]
    # each input with its square (a static nonlinearity such as friction heat ∝ n^α)
    Z = _lag_bank(np.concatenate([U, U**2], axis=1), starts, a_grid)[:, cal]
    yc, mc = y[cal], measured[cal]
    # contiguous folds of the calibration samples (blocked cross-validation)
    fold = np.minimum((np.arange(cal.size) * folds) // cal.size, folds - 1)
    scored = mc

    def score(sub: list[int]) -> tuple[float, np.ndarray]:
        sub = list(sub) + [m + j for j in sub]
        e = np.empty(cal.size)
        for k in range(folds):
            tr, te = fold != k, fold == k
            best_sse, best_w, best_g = np.inf, None, 0
            for g in range(a_grid.size):
                A = np.column_stack([Z[g][tr][:, sub], np.ones(int(tr.sum()))])
                w, *_ = np.linalg.lstsq(A, yc[tr], rcond=None)
                sse = np.sum((A @ w - yc[tr]) ** 2)
                if sse < best_sse:
                    best_sse, best_w, best_g = sse, w, g
            e[te] = np.column_stack([Z[best_g][te][:, sub], np.ones(int(te.sum()))]) @ best_w
        e = (e - yc)[scored]
        return float(np.sqrt(np.mean(e**2))), e

    chosen: list[int] = []
    current = (yc - yc.mean())[scored]
    cur_rmse = float(np.sqrt(np.mean(current**2)))
    steps: list[dict] = []
    usable = [j for j in range(U.shape[1]) if np.ptp(U[cal, j]) > 0]
    last_tried: dict[int, float] = {}
    block = block_length(current)
    while len(chosen) < max_inputs:
        rest = [j for j in usable if j not in chosen]
        if not rest:
            break
        tried = {j: score(chosen + [j]) for j in rest}
        last_tried = {j: r for j, (r, _) in tried.items()}
        j = min(tried, key=lambda k: tried[k][0])
        r, e = tried[j]
        pair = np.stack([current**2, e**2])
        reps = block_bootstrap_means(pair, block, 400, np.random.default_rng(seed))
        p_better = float(np.mean(reps[1] < reps[0]))
        accept = (r < 0.98 * cur_rmse) and p_better >= 0.95
        steps.append(
            {
                "tried": {names[k]: v for k, v in last_tried.items()},
                "best": names[j],
                "rmse_before": cur_rmse,
                "rmse_after": r,
                "p_better": p_better,
                "accepted": bool(accept),
            }
        )
        if not accept:
            break
        chosen.append(j)
        current, cur_rmse = e, r
    pool = list(chosen)
    for j in sorted(last_tried, key=last_tried.get):
        if len(pool) >= max_inputs:
            break
        if j not in pool:
            pool.append(j)
    if not pool and usable:
        pool = [usable[0]]
    return pool, steps


def candidates(
    n_pool: int,
    *,
    structures: tuple[str, ...],
    hidden: tuple[int, ...],
    delay_sets: tuple[tuple[int, ...], ...],
    arx_orders: tuple[int, ...] = (1, 2),
) -> dict[str, list[Candidate]]:
    """Candidate designs per group (structure, or network hidden size), the subsets of the
    pool ordered by size then by pool rank (the greedy order), so that a budget cut keeps
    the most promising ones."""
    subsets = [s for k in range(1, n_pool + 1) for s in itertools.combinations(range(n_pool), k)]
    subsets.sort(key=lambda s: (len(s), s))
    groups: dict[str, list[Candidate]] = {}
    both = (False, True)
    if "regression" in structures:
        groups["regression"] = [
            Candidate("regression", s, (0,), quadratic=q) for q in both for s in subsets
        ]
    if "lag" in structures:
        groups["lag"] = [Candidate("lag", s, (0,), quadratic=q) for q in both for s in subsets]
    if "arx" in structures:
        groups["arx"] = [
            Candidate("arx", s, d, na=na, quadratic=q)
            for q in both
            for s in subsets
            for d in delay_sets
            for na in arx_orders
        ]
    for h in hidden:
        net = []
        for s in subsets:
            if "mlp" in structures:
                net.append(Candidate("mlp", s, (0,), hidden=h))
            if "tdnn" in structures:
                net += [Candidate("tdnn", s, d, hidden=h) for d in delay_sets if d != (0,)]
        if net:
            groups[f"network h={h}"] = net
    return groups
