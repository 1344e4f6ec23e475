"""`Record`: one experiment as named signals on one uniform time base."""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
from jaxtyping import Float

from .._misc import first_not_increasing
from ._units import ORIGINAL_UNITS_KEY, convert_units, parse_unit, to_si

# Heuristic: a measured time vector is accepted as uniform when every sample lies within
# 1e-3·dt of the grid t0 + k·dt. Real data-acquisition clocks (EMPS: 3e-5·dt) are far
# inside this; anything outside would shift samples by a visible fraction of a step.
DEFAULT_TIME_RTOL = 1e-3

_RESERVED = "t"


def _readonly(values: Any, *, name: str) -> np.ndarray:
    """Copy `values` into a private float64 array that nobody can write to."""
    array = np.asarray(values)
    if array.dtype == object or not (
        np.issubdtype(array.dtype, np.floating)
        or np.issubdtype(array.dtype, np.integer)
        or np.issubdtype(array.dtype, np.bool_)
    ):
        raise TypeError(
            f"Signal {name!r} has dtype {array.dtype}; signals must be real numbers. "
            "Convert it with np.asarray(values, dtype=float) (complex data: store the real "
            "and imaginary parts as two signals)."
        )
    owned = np.array(array, dtype=np.float64, copy=True)
    owned.setflags(write=False)
    return owned


def _check_finite(name: str, values: np.ndarray) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        index = int(np.argmax(bad))
        raise ValueError(
            f"Signal {name!r} has a non-finite value ({values[index]}) at sample {index} "
            f"({int(bad.sum())} non-finite samples in all). Remove or interpolate them before "
            "building the Record, e.g. with Record.slice or np.interp."
        )


def _check_name(name: Any) -> str:
    if not isinstance(name, str):
        raise TypeError(f"Signal names must be strings, got {name!r} ({type(name).__name__}).")
    if not name or name != name.strip():
        raise ValueError(
            f"Signal name {name!r} is empty or has surrounding spaces; use a non-empty name "
            "without leading or trailing whitespace."
        )
    if name == _RESERVED:
        raise ValueError(
            "The name 't' is reserved for the time base (Record.t); pass the time vector as "
            "t=... or give the signal another name."
        )
    return name


def _freeze_metadata(metadata: Mapping[str, Any] | None) -> Mapping[str, Any]:
    if metadata is None:
        return MappingProxyType({})
    if not isinstance(metadata, Mapping):
        raise TypeError(f"metadata must be a mapping (dict), got {type(metadata).__name__}.")
    frozen: dict[str, Any] = {}
    for key, value in metadata.items():
        if not isinstance(key, str):
            raise TypeError(f"metadata keys must be strings, got {key!r}.")
        if isinstance(value, np.ndarray):
            value = np.array(value, copy=True)
            value.setflags(write=False)
        else:
            value = copy.deepcopy(value)
        frozen[key] = value
    return MappingProxyType(frozen)


def _explain_time_defect(time: np.ndarray, steps: np.ndarray, index: int) -> None:
    """Two common causes of a time column that does not increase, each with its own fix
    (sorting would interleave concatenated runs; dropping repeated stamps would lose most
    rows of a time column printed with too few decimals)."""
    n = time.size
    positive = steps[steps > 0]
    typical = float(np.median(positive)) if positive.size else 0.0
    # a restart: after at least two increasing stamps, time falls back near its start
    falls = np.flatnonzero(steps < 0)
    restarts = falls[time[falls + 1] - time[0] < 0.5 * (time[falls] - time[0])]
    if index >= 2 and steps[index - 1] < 0 and restarts.size and typical > 0:
        at = [int(i) + 1 for i in restarts[:5]]
        raise ValueError(
            f"The time vector restarts at sample {at[0]} (t = {float(time[at[0]])!r} s after "
            f"t = {float(time[at[0] - 1])!r} s): the file holds {restarts.size + 1} runs one "
            f"after another (restarts at samples {at}{', ...' if restarts.size > 5 else ''}). "
            "Split it into one record per run at the restarts (Record.slice, or one file per "
            "run); do not sort the samples, which would interleave the runs."
        )
    repeats = int(np.sum(steps == 0))
    if repeats >= max(3, 0.1 * (n - 1)) and not np.any(steps < 0):
        dt = float((time[-1] - time[0]) / (n - 1))
        quantum = float(np.min(positive)) if positive.size else 0.0
        raise ValueError(
            f"The time vector repeats {repeats} of its {n} stamps: it was written with too "
            f"few decimals (steps of {quantum:g} s for a sampling period of about {dt:.6g} s). "
            f"Pass the sampling period instead of the time column (dt={dt:.6g}) or export "
            "the time with more decimals; do not drop the repeated stamps (that loses rows)."
        )


def _uniform_time_base(t: Any, n: int, rtol: float) -> tuple[float, float]:
    """Validate a measured time vector and return `(t0, dt)` of its uniform grid."""
    time = np.asarray(t)
    if time.dtype == object or not (
        np.issubdtype(time.dtype, np.floating) or np.issubdtype(time.dtype, np.integer)
    ):
        raise TypeError(f"The time vector must be real numbers, got dtype {time.dtype}.")
    time = np.asarray(time, dtype=np.float64)
    if time.ndim == 2 and 1 in time.shape:
        time = time.reshape(-1)
    if time.ndim != 1:
        raise ValueError(f"The time vector must be 1-D, got shape {time.shape}.")
    if time.shape[0] != n:
        raise ValueError(
            f"The time vector has {time.shape[0]} samples but the signals have {n}; "
            "all signals and the time vector must have the same length."
        )
    if n < 2:
        raise ValueError(
            "A time vector with fewer than 2 samples does not define a sampling period; "
            "pass dt=... instead of t=..."
        )
    bad = ~np.isfinite(time)
    if bad.any():
        index = int(np.argmax(bad))
        raise ValueError(
            f"The time vector has a non-finite value at sample {index}; remove that sample "
            "(from the signals too), or pass dt=... instead of t when the sampling is uniform."
        )
    index = first_not_increasing(time)
    if index is not None:
        _explain_time_defect(time, np.diff(time), index)
        raise ValueError(
            f"The time vector is not strictly increasing: t[{index}] = {float(time[index])!r} <= "
            f"t[{index - 1}] = {float(time[index - 1])!r}. Sort the samples by time and drop "
            "duplicated time stamps first."
        )
    t0 = float(time[0])
    dt = float((time[-1] - time[0]) / (n - 1))
    deviation = np.abs(time - (t0 + dt * np.arange(n)))
    off_grid = deviation > rtol * dt
    if off_grid.any():
        index = int(np.argmax(off_grid))
        raise ValueError(
            f"The time vector is not uniform: sample {index} (t = {float(time[index])!r} s) lies "
            f"{deviation[index] / dt:.3g}·dt off the uniform grid t0 + k·dt with "
            f"dt = {dt!r} s (tolerance {rtol:g}·dt). Resample onto a uniform grid with "
            "jaxvs.signal.resample first, or loosen time_rtol if the jitter is harmless."
        )
    return t0, dt


class Record:
    """One experiment: named real signals sampled on one uniform time base.

    A `Record` is an immutable I/O container (not a JAX pytree): it copies every array it
    is given into a private read-only float64 array, so neither the user nor jaxvs can
    change it afterwards, and it never aliases a writable user array. Methods that
    "change" a record return a new one.

    The time base is uniform, `t[k] = t0 + k·dt` [s]. A measured time vector is accepted
    when it is strictly increasing and every sample lies within `time_rtol·dt` of that
    grid; the grid (not the measured vector) is stored.

    **Arguments:**

    - `signals`: either a mapping `name -> 1-D array` of equal lengths, or one 2-D array
        of shape `[time, signal]` together with `names`.
    - `names`: the column names when `signals` is a 2-D array (must be absent otherwise).
    - `t`: measured time vector [s], one value per sample. Give either `t` or `dt`.
    - `dt`: sampling period [s], with the time of the first sample `t0` [s].
    - `t0`: time of the first sample [s] when `dt` is given (default 0).
    - `units`: optional mapping `name -> unit string`, e.g. `{"q": "m", "u": "N"}`.
    - `metadata`: optional mapping of anything else about the experiment (controller
        gains, operating point, source file …); it is deep-copied.
    - `time_rtol`: tolerance of the uniform-grid check, relative to `dt`.

    **Raises:**

    `ValueError` for length mismatch, duplicate names, NaN/inf samples, a non-increasing or
    non-uniform time vector; `TypeError` for non-numeric signals or names.
    """

    __slots__ = ("_signals", "_units", "_metadata", "_t0", "_dt", "_n", "_time")

    def __init__(
        self,
        signals: Mapping[str, Any] | Any,
        *,
        names: Iterable[str] | None = None,
        t: Any = None,
        dt: float | None = None,
        t0: float = 0.0,
        units: Mapping[str, str] | None = None,
        metadata: Mapping[str, Any] | None = None,
        time_rtol: float = DEFAULT_TIME_RTOL,
    ):
        if isinstance(signals, Record):
            raise TypeError("signals is already a Record; use its methods to derive new ones.")
        if isinstance(signals, Mapping):
            if names is not None:
                raise ValueError(
                    "names=... is only used with a 2-D array of signals; with a mapping the "
                    "keys are the names, so drop names=."
                )
            items = list(signals.items())
        else:
            array = np.asarray(signals)
            if array.ndim != 2:
                raise ValueError(
                    f"signals must be a mapping name -> 1-D array or a 2-D array [time, signal] "
                    f"with names=...; got an array of shape {array.shape}."
                )
            if names is None:
                raise ValueError(
                    "A 2-D array of signals needs names=[...] with one name per column."
                )
            names = list(names) if not isinstance(names, str) else [names]
            if len(names) != array.shape[1]:
                raise ValueError(
                    f"signals has {array.shape[1]} columns but {len(names)} names were given; "
                    "pass one name per column (the array is [time, signal])."
                )
            items = [(name, array[:, i]) for i, name in enumerate(names)]
        if not items:
            raise ValueError("A Record needs at least one signal.")

        data: dict[str, np.ndarray] = {}
        for name, values in items:
            name = _check_name(name)
            if name in data:
                raise ValueError(
                    f"Duplicate signal name {name!r}; every signal needs its own name."
                )
            array = _readonly(values, name=name)
            if array.ndim == 2 and 1 in array.shape:
                array = array.reshape(-1)  # MATLAB-style column or row vectors.
            if array.ndim != 1:
                raise ValueError(
                    f"Signal {name!r} has shape {array.shape}; each signal must be 1-D "
                    "(one value per sample). Split multi-channel data into named signals."
                )
            data[name] = array
        lengths = {name: values.shape[0] for name, values in data.items()}
        n = next(iter(lengths.values()))
        if any(length != n for length in lengths.values()):
            raise ValueError(
                f"Signals have different lengths {lengths}; all signals of a Record share one "
                "time base. Trim or resample them to the same samples."
            )
        if n == 0:
            raise ValueError("A Record needs at least one sample; the signals are empty.")
        for name, values in data.items():
            _check_finite(name, values)

        if not (isinstance(time_rtol, int | float) and time_rtol > 0):
            raise ValueError(f"time_rtol must be a positive number, got {time_rtol!r}.")
        if t is not None and dt is not None:
            raise ValueError(
                "Give either the time vector t=... or the sampling period dt=..., not both."
            )
        if t is None and dt is None:
            raise ValueError(
                "A Record needs a time base: pass the time vector t=... [s] or the sampling "
                "period dt=... [s] (with t0=...)."
            )
        if t is not None:
            t0, dt = _uniform_time_base(t, n, float(time_rtol))
        else:
            if isinstance(dt, bool | np.bool_) or isinstance(t0, bool | np.bool_):
                raise TypeError(
                    f"dt and t0 must be numbers [s], got dt={dt!r}, t0={t0!r} (a boolean would "
                    "be read as 1 s or 0 s). Pass the sampling period, e.g. dt=1e-3."
                )
            try:
                dt, t0 = float(dt), float(t0)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                raise ValueError(
                    f"dt must be a positive finite sampling period [s] and t0 a time [s]; got "
                    f"dt={dt!r}, t0={t0!r}. Pass numbers, e.g. dt=1e-3."
                ) from None
            if not (math.isfinite(dt) and dt > 0):
                raise ValueError(f"dt must be a positive finite sampling period [s], got {dt!r}.")
            if not math.isfinite(t0):
                raise ValueError(f"t0 must be finite, got {t0!r}.")
        end = t0 + dt * (n - 1)
        if not (math.isfinite(end) and math.isfinite(1.0 / dt)):
            raise ValueError(
                f"The time base t0={t0!r} s, dt={dt!r} s over {n} samples does not fit in "
                "float64 (the last time or the sampling frequency 1/dt is infinite); give dt "
                "and t0 in seconds (e.g. dt=1e-3 for 1 kHz)."
            )
        if n > 1 and not dt > 4 * np.spacing(max(abs(t0), abs(end))):
            # heuristic: 4 ulps keeps consecutive sample times distinct after rounding
            raise ValueError(
                f"The time base t0={t0!r} s is so large against dt={dt!r} s that consecutive "
                "sample times are equal in float64; subtract the start time (t0=0) or give "
                "dt and t0 in seconds."
            )

        unit_map: dict[str, str] = {}
        if units is not None:
            if not isinstance(units, Mapping):
                raise TypeError(f"units must be a mapping name -> str, got {type(units).__name__}.")
            for name, unit in units.items():
                if name not in data:
                    raise ValueError(
                        f"units given for unknown signal {name!r}; available signals: "
                        f"{list(data)}. Give units only for signals of the record."
                    )
                if unit is None:
                    continue
                if not isinstance(unit, str):
                    raise TypeError(f"The unit of {name!r} must be a string, got {unit!r}.")
                unit_map[name] = unit

        self._store(data, t0, dt, n, unit_map, _freeze_metadata(metadata))

    def _store(
        self,
        data: dict[str, np.ndarray],
        t0: float,
        dt: float,
        n: int,
        units: dict[str, str],
        metadata: Mapping[str, Any],
    ) -> None:
        """Set the validated contents of a new record (frozen: `object.__setattr__`) and its
        read-only time vector."""
        set_ = object.__setattr__
        set_(self, "_signals", data)
        set_(self, "_units", units)
        set_(self, "_metadata", metadata)
        set_(self, "_t0", t0)
        set_(self, "_dt", dt)
        set_(self, "_n", n)
        time = t0 + dt * np.arange(n, dtype=np.float64)
        time.setflags(write=False)
        set_(self, "_time", time)

    @classmethod
    def _trusted(
        cls,
        data: dict[str, np.ndarray],
        t0: float,
        dt: float,
        units: dict[str, str],
        metadata: Mapping[str, Any],
    ) -> Record:
        """Build a record from arrays that are already validated and read-only."""
        record = object.__new__(cls)
        n = next(iter(data.values())).shape[0]
        kept = {k: v for k, v in units.items() if k in data}
        record._store(data, float(t0), float(dt), n, kept, metadata)
        return record

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        # Pickling goes through the validating constructor, which re-freezes the arrays.
        return (
            _unpickle,
            (self._signals, self._t0, self._dt, self._units, dict(self._metadata)),
        )

    def __copy__(self) -> Record:
        return self  # immutable: a copy is the record itself

    def __deepcopy__(self, memo: dict[int, Any]) -> Record:
        return self

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(
            "Record is immutable; use with_signal, select, rename, slice or window to derive "
            "a new record."
        )

    def __delattr__(self, name: str) -> None:
        raise AttributeError("Record is immutable.")

    # --- time base -----------------------------------------------------------------------

    @property
    def t(self) -> Float[np.ndarray, " time"]:
        """Time vector `t0 + k·dt` [s] (read-only)."""
        return self._time.view()

    @property
    def t0(self) -> float:
        """Time of the first sample [s]."""
        return self._t0

    @property
    def dt(self) -> float:
        """Sampling period [s]."""
        return self._dt

    @property
    def fs(self) -> float:
        """Sampling frequency `1/dt` [Hz]."""
        return 1.0 / self._dt

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, `(len - 1)·dt` [s]."""
        return (self._n - 1) * self._dt

    def __len__(self) -> int:
        """Number of samples."""
        return self._n

    # --- signals -------------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        """Signal names in storage order."""
        return tuple(self._signals)

    @property
    def units(self) -> dict[str, str]:
        """Units of the signals that have one (a new dict each call)."""
        return dict(self._units)

    @property
    def metadata(self) -> Mapping[str, Any]:
        """Read-only view of the metadata."""
        return self._metadata

    def unit(self, name: str) -> str | None:
        """Unit of signal `name`, or `None` when it has none."""
        self._require([name])
        return self._units.get(name)

    def _require(self, names: Iterable[str]) -> list[str]:
        if isinstance(names, str):
            names = [names]
        names = list(names)
        for name in names:
            if not isinstance(name, str):
                raise TypeError(f"Signal names are strings, got {name!r}.")
        missing = [name for name in names if name not in self._signals]
        if missing:
            raise KeyError(
                f"No signal named {', '.join(map(repr, missing))} in this record; available "
                f"signals: {list(self._signals)}."
            )
        return names

    def __getitem__(self, name: str) -> Float[np.ndarray, " time"]:
        """The samples of signal `name` (a read-only array)."""
        if not isinstance(name, str):
            raise TypeError(
                f"Index a Record by signal name (a string), got {name!r}; use "
                "record.select([...]) for several signals and record.slice(start, stop) for "
                "samples."
            )
        self._require([name])
        return self._signals[name].view()

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._signals

    # A Record is neither a sequence of samples nor a mapping of signals; iterate over
    # `record.names` explicitly.
    __iter__ = None  # type: ignore[assignment]

    def select(self, names: Iterable[str] | str) -> Record:
        """A record with only the signals `names`, in that order.

        **Arguments:**

        - `names`: one name or a sequence of names.

        **Returns:**

        A new `Record` (same time base, units and metadata).

        **Raises:**

        `KeyError` listing the available signals when a name is missing; `ValueError` for
        an empty or repeated selection.
        """
        names = self._require(names)
        if not names:
            raise ValueError("select() needs at least one signal name.")
        if len(set(names)) != len(names):
            raise ValueError(f"select() got repeated names {names}; name each signal once.")
        data = {name: self._signals[name] for name in names}
        return Record._trusted(data, self._t0, self._dt, self._units, self._metadata)

    def rename(self, mapping: Mapping[str, str]) -> Record:
        """A record with signals renamed by `mapping` (old name -> new name).

        Units follow their signal. Unmentioned signals keep their names.

        **Raises:**

        `KeyError` for an unknown old name; `ValueError` when two signals would share a
        name or a new name is invalid.
        """
        if not isinstance(mapping, Mapping):
            raise TypeError("rename() takes a mapping old name -> new name.")
        self._require(list(mapping))
        data: dict[str, np.ndarray] = {}
        units: dict[str, str] = {}
        for name, values in self._signals.items():
            new = _check_name(mapping.get(name, name))
            if new in data:
                raise ValueError(
                    f"rename() would give two signals the name {new!r}; choose distinct names."
                )
            data[new] = values
            if name in self._units:
                units[new] = self._units[name]
        return Record._trusted(data, self._t0, self._dt, units, self._metadata)

    def slice(self, start: int | None = None, stop: int | None = None) -> Record:
        """Samples `start:stop` (Python slice semantics, negative indices allowed).

        **Returns:**

        A new `Record` whose time base starts at `t[start]`.

        **Raises:**

        `ValueError` when the slice is empty.
        """
        for value in (start, stop):
            if value is not None and not isinstance(value, int | np.integer):
                raise TypeError(f"slice() takes integer sample indices, got {value!r}.")
        begin, end, _ = slice(start, stop).indices(self._n)
        if end <= begin:
            raise ValueError(
                f"slice({start}, {stop}) selects no samples of a record with {self._n} "
                f"samples; give start < stop within 0..{self._n}."
            )
        data = {name: values[begin:end] for name, values in self._signals.items()}
        return Record._trusted(
            data, self._t0 + begin * self._dt, self._dt, self._units, self._metadata
        )

    def window(self, t_start: float | None = None, t_end: float | None = None) -> Record:
        """Samples with `t_start <= t < t_end` [s] (half-open, like `slice`).

        Sample times within `1e-9·dt` of a bound count as on it, so grid times can be given
        as decimals. `None` means the start or end of the record.

        **Raises:**

        `ValueError` when `t_end <= t_start` or no sample falls in the window.
        """
        eps = 1e-9 * self._dt
        begin = 0
        end = self._n
        if t_start is not None:
            begin = max(0, math.ceil((t_start - self._t0) / self._dt - 1e-9))
        if t_end is not None:
            end = min(self._n, math.ceil((t_end - self._t0) / self._dt - 1e-9))
        if t_start is not None and t_end is not None and t_end <= t_start + eps:
            raise ValueError(f"window({t_start}, {t_end}): t_end must be greater than t_start.")
        if end <= begin:
            raise ValueError(
                f"window({t_start}, {t_end}) holds no sample; the record spans "
                f"[{self._t0:g}, {self._t0 + self.duration:g}] s; choose times inside it."
            )
        return self.slice(begin, end)

    def to_array(self, names: Iterable[str] | None = None) -> Float[np.ndarray, "time signal"]:
        """The signals `names` (default: all, in order) as a new writable `[time, signal]`
        float64 array."""
        names = list(self._signals) if names is None else self._require(names)
        if not names:
            raise ValueError("to_array() needs at least one signal name.")
        return np.stack([self._signals[name] for name in names], axis=1)

    def with_signal(self, name: str, values: Any, unit: str | None = None) -> Record:
        """A record with signal `name` added, or replaced when it exists.

        **Arguments:**

        - `name`: the signal name.
        - `values`: one value per sample (copied).
        - `unit`: the unit of the new values; `None` gives the signal no unit (a replaced
            signal does not keep its old unit).

        **Returns:**

        A new `Record`; this one is unchanged.
        """
        name = _check_name(name)
        array = _readonly(values, name=name)
        if array.ndim == 2 and 1 in array.shape:
            array = array.reshape(-1)
        if array.shape != (self._n,):
            raise ValueError(
                f"Signal {name!r} has shape {array.shape} but the record has {self._n} "
                "samples; give one value per sample."
            )
        _check_finite(name, array)
        if unit is not None and not isinstance(unit, str):
            raise TypeError(f"unit must be a string or None, got {unit!r}.")
        data = dict(self._signals)
        data[name] = array
        units = dict(self._units)
        units.pop(name, None)
        if unit is not None:
            units[name] = unit
        return Record._trusted(data, self._t0, self._dt, units, self._metadata)

    def require_unit(self, name: str, unit: str) -> Record:
        """This record with signal `name` expressed in `unit`, or a clear refusal.

        Model families call this for the signals whose physical quantity they assume
        (`q` in m, `u` in N, `T_chassis` in °C …). A signal in another unit of the same
        quantity is converted (`mm` → `m`); one in a different quantity (`N` where `m` is
        expected) is refused. A signal without a unit is taken to be in `unit` already (the
        canonical names of docs/guides/contracts.md imply their units) and is labelled with it.

        **Arguments:**

        - `name`: the signal.
        - `unit`: the unit the caller computes in, e.g. `"m"`.

        **Returns:**

        A `Record` (this one when nothing changes); a converted signal's former unit is
        added to `metadata["original_units"]`.

        **Raises:**

        `KeyError` for a missing signal; `ValueError` naming the signal and both units when
        they measure different quantities or a unit is unknown.
        """
        self._require([name])
        if not isinstance(unit, str):
            raise TypeError(f"unit must be a string such as 'm', got {unit!r}.")
        current = self._units.get(name)
        if current is None:
            parse_unit(unit, name=name)
            units = dict(self._units)
            units[name] = unit
            return Record._trusted(dict(self._signals), self._t0, self._dt, units, self._metadata)
        if current == unit:
            return self
        values = convert_units(self._signals[name], current, unit, name=name, source="Record")
        record = self.with_signal(name, values, unit=unit)
        original = dict(self._metadata.get(ORIGINAL_UNITS_KEY) or {})
        original.setdefault(name, current)
        return record.with_metadata({ORIGINAL_UNITS_KEY: original})

    def with_metadata(self, metadata: Mapping[str, Any]) -> Record:
        """A record whose metadata is this record's updated with `metadata`."""
        merged = dict(self._metadata)
        merged.update(_freeze_metadata(metadata))
        return Record._trusted(
            dict(self._signals), self._t0, self._dt, self._units, _freeze_metadata(merged)
        )

    def __repr__(self) -> str:
        signals = ", ".join(
            f"{name} [{self._units[name]}]" if name in self._units else name
            for name in self._signals
        )
        text = (
            f"Record({self._n} samples, fs={self.fs:.6g} Hz, "
            f"t=[{self._t0:.6g}, {self._t0 + self.duration:.6g}] s, signals: {signals}"
        )
        if self._metadata:
            text += f"; metadata: {', '.join(self._metadata)}"
        return text + ")"


def _unpickle(
    signals: dict[str, np.ndarray],
    t0: float,
    dt: float,
    units: dict[str, str],
    metadata: dict[str, Any],
) -> Record:
    return Record(signals, dt=dt, t0=t0, units=units, metadata=metadata)


def si_record(record: Record, source: str = "") -> Record:
    """`record` with every signal that has a unit converted to SI (see the module doc).

    Converted signals' former units are added to `metadata["original_units"]`; a record
    that is already in SI is returned unchanged.
    """
    original = dict(record.metadata.get(ORIGINAL_UNITS_KEY) or {})
    units = record.units
    data = {}
    changed = False
    for name in record.names:
        values = record[name]
        unit = units.get(name)
        if unit:
            converted, si = to_si(values, unit, name=name, source=source)
            if si != unit:
                original.setdefault(name, unit)
                values, changed = converted, True
            units[name] = si
        data[name] = values
    if not changed:
        return record
    metadata = {**record.metadata, ORIGINAL_UNITS_KEY: original}
    return Record(data, dt=record.dt, t0=record.t0, units=units, metadata=metadata)
