"""Choice of virtual-sensor inputs: correlation matrix of all measured variables (study
Fig. 5) and a ranking of candidate inputs by relevance to the target and redundancy with
the inputs already chosen (a greedy max-relevance min-redundancy rule on |Pearson r|,
Peng, Long & Ding 2005, IEEE TPAMI 27(8), with correlation in place of mutual
information).
"""

import warnings
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from ...calibration import ExcitationWarning
from ...data import Record

__all__ = ["InputRank", "correlation_matrix", "rank_inputs"]


def _columns(data: Any, names: Sequence[str] | None, where: str) -> tuple[list[str], np.ndarray]:
    if isinstance(data, Record):
        available = list(data.names)
        get = lambda n: data[n]
    elif isinstance(data, Mapping):
        available = [k for k in data if k != "t"]
        get = lambda n: data[n]
    else:
        raise TypeError(f"{where}: give a jaxvs.data.Record or a mapping name -> 1-D array.")
    names = available if names is None else list(names)
    missing = [n for n in names if n not in available]
    if missing:
        raise ValueError(f"{where}: no signal(s) {missing}; the data have {available}.")
    cols = [np.asarray(get(n), dtype=float) for n in names]
    lengths = {c.shape for c in cols}
    if len(lengths) != 1 or cols[0].ndim != 1:
        raise ValueError(f"{where}: all signals must be 1-D of the same length; got {lengths}.")
    X = np.column_stack(cols)
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{where}: NaN/inf in the signals; resample or cut the record first.")
    return names, X


def correlation_matrix(
    data: Record | Mapping[str, Any], names: Sequence[str] | None = None
) -> tuple[tuple[str, ...], np.ndarray]:
    """Pearson correlation coefficients between measured variables (study Fig. 5).

    **Arguments:**

    - `data`: a `jaxvs.data.Record` or a mapping name -> `(time,)` array.
    - `names`: the variables, in order (default: all signals).

    **Returns:**

    `(names, R)` with `R` the `(n, n)` correlation matrix; rows and columns of a constant
    signal are NaN (with an `ExcitationWarning`: it carries no information).
    """
    names, X = _columns(data, names, "correlation_matrix")
    sd = X.std(axis=0)
    for n, s in zip(names, sd):
        if s == 0:
            warnings.warn(
                f"correlation_matrix: signal {n!r} is constant; its correlations are undefined "
                "(NaN). Drop it from the candidate inputs.",
                ExcitationWarning,
                stacklevel=2,
            )
    Z = (X - X.mean(axis=0)) / np.where(sd > 0, sd, np.nan)
    R = (Z.T @ Z) / X.shape[0]
    return tuple(names), R


class InputRank(NamedTuple):
    """One candidate input in the ranking of [`rank_inputs`][].

    - `name`; `relevance`: |r| with the target; `redundancy`: largest |r| with an input
      ranked before it (0 for the first); `score`: `relevance - mean |r|` with the inputs
      ranked before it (the greedy criterion); `redundant`: `redundancy > max_redundancy`.
    """

    name: str
    relevance: float
    redundancy: float
    score: float
    redundant: bool


def rank_inputs(
    data: Record | Mapping[str, Any],
    target: str,
    candidates: Sequence[str] | None = None,
    *,
    max_redundancy: float = 0.95,
) -> list[InputRank]:
    """Rank candidate inputs by relevance to the target and redundancy with each other.

    Greedy: the first input is the one most correlated with the target; each next one
    maximises `|r(x, target)| - mean_{s chosen} |r(x, s)|`. An input whose correlation
    with an earlier one exceeds `max_redundancy` is flagged redundant (the study drops
    such variables, §3.3.2).

    **Arguments:**

    - `data`: a Record or mapping of signals; `target`: the target's name.
    - `candidates`: candidate inputs (default: every other signal; constant signals are
      skipped with an `ExcitationWarning`).
    - `max_redundancy`: |r| above which a candidate counts as redundant.

    **Returns:** a list of [`InputRank`][], best first.
    """
    all_names = list(data.names) if isinstance(data, Record) else [k for k in data if k != "t"]
    if target not in all_names:
        raise ValueError(f"rank_inputs: no target signal {target!r}; the data have {all_names}.")
    if candidates is None:
        candidates = [n for n in all_names if n != target]
    candidates = [c for c in candidates if c != target]
    if not candidates:
        raise ValueError("rank_inputs: no candidate inputs besides the target.")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        names, R = correlation_matrix(data, [target, *candidates])
    for w in caught:
        if issubclass(w.category, ExcitationWarning) and f"'{target}'" in str(w.message):
            raise ValueError(f"rank_inputs: the target {target!r} is constant; nothing to rank.")
        warnings.warn(w.message, w.category, stacklevel=2)
    A = np.abs(R)
    rel = A[0, 1:]
    cand = [i for i in range(len(candidates)) if np.isfinite(rel[i])]
    chosen: list[int] = []
    out: list[InputRank] = []
    while cand:
        if chosen:
            red_mean = np.array([A[1 + i, [1 + j for j in chosen]].mean() for i in cand])
            red_max = np.array([A[1 + i, [1 + j for j in chosen]].max() for i in cand])
        else:
            red_mean = np.zeros(len(cand))
            red_max = np.zeros(len(cand))
        score = rel[cand] - red_mean
        k = int(np.argmax(score))
        i = cand.pop(k)
        chosen.append(i)
        out.append(
            InputRank(
                name=candidates[i],
                relevance=float(rel[i]),
                redundancy=float(red_max[k]),
                score=float(score[k]),
                redundant=bool(red_max[k] > max_redundancy),
            )
        )
    return out
