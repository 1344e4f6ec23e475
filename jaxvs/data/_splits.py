"""Calibration/validation splits that respect time: contiguous blocks or whole experiments.

Random sample-wise splits leak information between calibration and validation in dynamic
models (neighbouring samples are correlated), so jaxvs never offers them (docs/guides/contracts.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from ._record import Record


class Split(NamedTuple):
    """Experiments used to calibrate a model and experiments held out to validate it."""

    calibration: tuple[Record, ...]
    validation: tuple[Record, ...]


def split_blocks(
    record: Record,
    fractions: Sequence[float] = (0.7, 0.3),
    *,
    min_samples: int = 2,
) -> tuple[Record, ...]:
    """Cut one record into contiguous blocks in time order.

    Block `i` holds about `fractions[i]·len(record)` samples (boundaries are rounded to the
    nearest sample); every sample belongs to exactly one block. The thermal study's 70/30
    split is `calibration, validation = split_blocks(record)`.

    **Arguments:**

    - `record`: the experiment to cut.
    - `fractions`: positive fractions, at least two, summing to 1.
    - `min_samples`: the fewest samples a block may have (e.g. the model order + 1).

    **Returns:**

    A tuple of `Record`s, one per fraction, each with its own time base (`t0` of its first
    sample).

    **Raises:**

    `ValueError` when the fractions are not positive, fewer than two or do not sum to 1,
    or when a block would be shorter than `min_samples`.
    """
    if not isinstance(record, Record):
        raise TypeError(
            f"split_blocks() takes a Record, got {type(record).__name__}; build one with "
            "jaxvs.data.Record({name: values}, dt=...) or load it with jaxvs.data.load."
        )
    fractions = [float(f) for f in fractions]
    if len(fractions) < 2:
        raise ValueError(f"split_blocks() needs at least two fractions, got {fractions}.")
    if any(not (math.isfinite(f) and f > 0) for f in fractions):
        raise ValueError(f"Every fraction must be positive, got {fractions}.")
    total = math.fsum(fractions)
    if abs(total - 1.0) > 1e-9:
        raise ValueError(
            f"The fractions {fractions} sum to {total:.12g}, not 1; e.g. use (0.7, 0.3)."
        )
    if not (isinstance(min_samples, int) and min_samples >= 1):
        raise ValueError(f"min_samples must be a positive integer, got {min_samples!r}.")
    n = len(record)
    edges = [0]
    cumulative = 0.0
    for fraction in fractions[:-1]:
        cumulative += fraction
        edges.append(round(cumulative * n))
    edges.append(n)
    sizes = [stop - start for start, stop in zip(edges[:-1], edges[1:])]
    if min(sizes) < min_samples:
        raise ValueError(
            f"Splitting {n} samples by {fractions} gives blocks of {sizes} samples; every "
            f"block needs at least {min_samples}. Use a longer record or larger fractions."
        )
    return tuple(record.slice(start, stop) for start, stop in zip(edges[:-1], edges[1:]))


def split_experiments(
    records: Sequence[Record],
    validation: int | Sequence[int] = -1,
) -> Split:
    """Hold out whole experiments for validation.

    **Arguments:**

    - `records`: the experiments, at least two.
    - `validation`: index, or indices, of the experiments to hold out (negative indices
        count from the end; default: the last one).

    **Returns:**

    A `Split`: the remaining experiments in their original order as `calibration`, the
    held-out ones in the order given as `validation`.

    **Raises:**

    `ValueError` for fewer than two records, an out-of-range or repeated index, or a
    selection that holds out every experiment (or none).
    """
    records = tuple(records)
    for i, record in enumerate(records):
        if not isinstance(record, Record):
            raise TypeError(f"records[{i}] is a {type(record).__name__}, not a Record.")
    n = len(records)
    if n < 2:
        raise ValueError(
            f"Holding out whole experiments needs at least two records, got {n}; for one "
            "record use split_blocks(record) to hold out a contiguous block."
        )
    indices = [validation] if isinstance(validation, int) else list(validation)
    if not indices:
        raise ValueError("validation selects no experiment; give at least one index.")
    normalised = []
    for index in indices:
        if not isinstance(index, int):
            raise TypeError(f"validation indices must be integers, got {index!r}.")
        if not -n <= index < n:
            raise ValueError(
                f"validation index {index} is out of range for {n} records; use an index "
                f"in {-n}..{n - 1}."
            )
        normalised.append(index % n)
    if len(set(normalised)) != len(normalised):
        raise ValueError(f"validation repeats an experiment: {indices}.")
    if len(normalised) == n:
        raise ValueError("validation holds out every experiment; keep at least one to calibrate.")
    held_out = set(normalised)
    return Split(
        calibration=tuple(r for i, r in enumerate(records) if i not in held_out),
        validation=tuple(records[i] for i in normalised),
    )
