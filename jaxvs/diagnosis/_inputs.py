"""The records of `jaxvs diagnose` and `jaxvs check`, read and checked the same way: files or
`Record`s under the user's own column names, the family's signals, one sampling rate, and
a run that fits in memory."""

from __future__ import annotations

import pathlib
from typing import Any

import numpy as np

from ..data import Record, load_renamed, rename_signals, require_signals
from ._base import AbstractFamily

__all__ = [
    "CHECK_VALUES",
    "SEARCH_VALUES",
    "check_int",
    "check_sampling",
    "check_signals",
    "memory_check",
    "records",
]


def records(
    data: Any, role: str, signals: Any = None, who: str = "diagnose"
) -> list[tuple[Record, str]]:
    if data is None:
        return []
    items = list(data) if isinstance(data, list | tuple) else [data]
    if not items:
        raise ValueError(f"{who}: no {role} experiments given.")
    out = []
    for i, item in enumerate(items):
        if isinstance(item, Record):
            name = str(item.metadata.get("name") or item.metadata.get("file") or f"{role} {i + 1}")
            item = rename_signals(item, signals) if signals else item
            out.append((item, pathlib.Path(name).name))
        elif isinstance(item, str | pathlib.Path):
            loaded = load_renamed(item, signals)
            # A file with several time bases or runs (Sinumerik, TwinCAT, TDMS, MDF) gives
            # one experiment per record.
            recs = loaded if isinstance(loaded, list) else [loaded]
            base = pathlib.Path(item).name
            for k, rec in enumerate(recs):
                out.append((rec, base if len(recs) == 1 else f"{base}[{k}]"))
        else:
            raise TypeError(
                f"{who}: {role} experiment {i + 1} is a {type(item).__name__}; give a "
                "jaxvs.data.Record or a path to a CSV, NPZ, MAT or HDF5 file."
            )
    return out


def check_signals(
    fam: AbstractFamily, recs: list[tuple[Record, str]], who: str = "diagnose"
) -> None:
    for rec, name in recs:
        missing = [s for s in fam.required if s not in rec.names]
        base = name.split("[")[0]
        apart = [  # the file holds it, in a record of another length (a channel cut short)
            (s, other, n2)
            for s in missing
            for other, n2 in recs
            if n2 != name and n2.split("[")[0] == base and s in other.names
        ]
        if apart:
            s, other, n2 = apart[0]
            raise ValueError(
                f"{who}(family={fam.name!r}): in {base!r} the channel {s!r} has {len(other)} "
                f"samples but {list(rec.names)} have {len(rec)} (a channel shorter than the "
                "others, so the file was read as separate records); cut the channels to a "
                f"common length (Record.slice(0, {min(len(other), len(rec))})) and merge them, "
                "or export the recording again with all channels complete."
            )
        where = f"{who}(family={fam.name!r})"
        require_signals(rec, fam.required, where=where, name=name, optional=fam.optional)


def check_int(name: str, value: Any, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"diagnose: {name} must be an integer >= {minimum}; got {value!r}.")


def check_sampling(recs: list[tuple[Record, str]]) -> None:
    """All experiments must share one sampling rate: the analysis filters, the delays and
    the null are built for one sample time; a record at another rate would show its
    resampling as an effect."""
    dts = [(float(r.dt), n) for r, n in recs]
    dt0, n0 = dts[0]
    for dt, n in dts[1:]:
        if abs(dt - dt0) > 1e-6 * dt0:
            raise ValueError(
                f"diagnose: experiment {n!r} is sampled at {1 / dt:g} Hz, {n0!r} at "
                f"{1 / dt0:g} Hz; all experiments must share one sampling rate. Resample "
                "them to a common rate first and say so in your report."
            )


# heuristics: float64 working values per recorded sample, the search's first round from a
# drive record of 2·10^6 samples whose first round asked for 12 GB (an upper bound for
# families that decimate less), the check's Jacobian and quality measures a tenth of it
SEARCH_VALUES = 750
CHECK_VALUES = 75


def memory_check(fam: AbstractFamily, n: int, who: str, values_per_sample: int) -> None:
    """Refuse a run whose largest step would not fit in memory, before it starts."""
    from .._memory import guard

    guard(
        8.0 * values_per_sample * n,
        f"{who}: the {fam.name} family's {'search' if who == 'diagnose' else 'check'} on "
        f"{n} samples",
        "Decimate the records (jaxvs.signal.decimate) or slice them to the stretch that "
        "matters (Record.slice); a few 10^4 samples per experiment are usually enough.",
    )


