"""The family options of `diagnose` and `check`, checked against their type and range.

A family reads its options where it needs them (`int(...)`, `x or default`, a truth
test), so an option of the wrong type or out of range would otherwise be rounded, replaced
by its default or read as `True` without a word (`decimation=0`, `decimation=2.5`,
`controller_taps=-1`, `zoh_force=maybe`). Every value is checked here first, at the entry
points, and normalised (a command-line `zoh_force=false` is the boolean `False`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["OPTION_SPECS", "validate_options"]

# family -> option -> (kind, low, high, what it is); bounds inclusive, None: unbounded.
OPTION_SPECS: dict[str, dict[str, tuple[str, float | None, float | None, str]]] = {
    "drive": {
        "cutoff_hz": ("float>0", None, None, "low-pass cut-off [Hz]"),
        "filter_order": ("int", 1, 12, "Butterworth order of the low-pass"),
        "decimation": ("int", 1, None, "keep every n-th sample after filtering"),
        "friction_sharpness": ("float>0", None, None, "smooth-sign width / peak velocity"),
        "zoh_force": ("bool", None, None, "the force is zero-order held by the drive"),
        "controller_taps": ("int", 1, 512, "taps of the identified controller"),
        "mass": ("float", 0.0, None, "moving mass [kg] when the record does not excite it"),
    },
    "tmf": {
        "order": ("int", 1, 40, "order of the TMF"),
        "coherence": ("float", 0.0, 1.0, "least coherence of a used frequency"),
        "fir_taps": ("int", 1, 100_000, "taps of the FIR estimate"),
    },
    "thermal": {
        "smoothing_s": ("float", 0.0, None, "smoothing window [s] (0: none)"),
        "speed_change_s": ("float>0", None, None, "window of a speed change [s]"),
    },
}

_TRUE = {"true", "yes", "on", "1"}
_FALSE = {"false", "no", "off", "0"}


def _bad(who: str, key: str, value: Any, expected: str, what: str) -> ValueError:
    return ValueError(
        f"{who}: option {key}={value!r} must be {expected} ({key}: {what}); give such a "
        "value, or leave the option out for its default."
    )


def validate_options(
    family: str, options: dict[str, Any], who: str, keys: tuple[str, ...] | None = None
) -> dict[str, Any]:
    """`options` checked against the family's option `keys` and `OPTION_SPECS[family]`,
    and normalised."""
    specs = OPTION_SPECS.get(family, {})
    keys = tuple(specs) if keys is None else keys
    unknown = sorted(set(options) - set(keys))
    if unknown:
        raise ValueError(
            f"{who}(family={family!r}): unknown option(s) {unknown}; the {family} family "
            f"takes {list(keys)}."
        )
    out = dict(options)
    for key, value in options.items():
        if key not in specs or value is None:
            continue
        kind, lo, hi, what = specs[key]
        if kind == "bool":
            text = str(value).strip().lower()
            if isinstance(value, bool | np.bool_):
                out[key] = bool(value)
            elif text in _TRUE | _FALSE and not isinstance(value, float):
                out[key] = text in _TRUE
            else:
                raise _bad(who, key, value, "true or false", what)
            continue
        if kind == "int":
            ok = not isinstance(value, bool) and (
                isinstance(value, int | np.integer)
                or (isinstance(value, float | np.floating) and float(value).is_integer())
            )
            rng = f"an integer >= {lo}" + (f" and <= {hi}" if hi is not None else "")
            if not ok or (lo is not None and value < lo) or (hi is not None and value > hi):
                raise _bad(who, key, value, rng, what)
            out[key] = int(value)
            continue
        ok = not isinstance(value, bool) and isinstance(value, int | float | np.number)
        ok = ok and math.isfinite(float(value))
        if kind == "float>0":
            ok, rng = ok and float(value) > 0, "a positive finite number"
        else:
            rng = f"a number in [{lo}, {hi if hi is not None else 'inf'}]"
            ok = ok and (lo is None or float(value) >= lo) and (hi is None or float(value) <= hi)
        if not ok:
            raise _bad(who, key, value, rng, what)
        out[key] = float(value)
    return out
