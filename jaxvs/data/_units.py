"""Units of measured signals: parse them from headers and files, convert them to SI.

jaxvs computes in SI (docs/guides/refusals.md: "units written in headers or files are honoured by
conversion, never ignored"). Every loader passes the unit it finds through `to_si`, which

- converts lengths to m, forces to N, times to s, velocities to m/s, torques to N·m,
  pressures to Pa, angles to rad, angular velocities to rad/s, and every other quantity to
  its coherent SI unit;
- keeps two documented exceptions: temperatures go to °C (the thermal family works in °C,
  docs/guides/contracts.md; K and °F are converted with their offsets) and motor speeds given in
  rpm stay in rpm (the thermal family's `v_m [rpm]`);
- refuses a unit it cannot read, naming the column and the fix.

The original unit of every converted signal is kept in the record's metadata under
`"original_units"` (`{signal: unit as written}`).

Units are read by [pint](https://pint.readthedocs.io) (one shared registry), the
well-kept units library of the scientific Python stack.
"""

from __future__ import annotations

import functools
import re
from typing import Any

import numpy as np

__all__ = [
    "ORIGINAL_UNITS_KEY",
    "parse_header",
    "parse_unit",
    "si_unit",
    "to_si",
    "convert_units",
]

ORIGINAL_UNITS_KEY = "original_units"

# Spellings found in machine-tool files that pint does not know, mapped to pint's names.
_ALIASES = {
    "°C": "degC",
    "℃": "degC",
    "°F": "degF",
    "deg C": "degC",
    "grad C": "degC",
    "Grad C": "degC",
    "µm": "um",
    "μm": "um",
    "µs": "us",
    "μs": "us",
    "Nm": "N*m",
    "kNm": "kN*m",
    "U/min": "rpm",
    "1/min": "rpm",
    "min^-1": "rpm",
    "min-1": "rpm",
    "rev/min": "rpm",
    "inc": None,  # encoder increments: no physical unit, refused below with a hint
    "-": "",
    "1": "",
}

# Preferred SI spelling, by the dimensionality of the unit (checked in this order).
_PREFERRED = (
    "m",
    "kg",
    "s",
    "A",
    "degC",
    "m/s",
    "m/s^2",
    "m/s^3",
    "N",
    "N*m",
    "Pa",
    "W",
    "V",
    "Hz",
    "N/m",
    "N*s/m",
    "kg*m^2",
    "ohm",
    "N*m*s/rad",
)

# Angles are dimensionless in pint; radian-based units are recognised by name.
_ANGLE_UNITS = {"radian": "rad", "degree": "rad", "arcminute": "rad", "arcsecond": "rad"}


@functools.lru_cache(maxsize=1)
def _registry() -> Any:
    import pint

    registry = pint.UnitRegistry(autoconvert_offset_to_baseunit=True)
    return registry


def _normalise(text: str) -> str | None:
    text = text.strip()
    if text in _ALIASES:
        return _ALIASES[text]
    text = text.replace("²", "^2").replace("³", "^3").replace("·", "*").replace("°", "deg")
    text = text.replace("µ", "u").replace("μ", "u")
    return text


def parse_unit(text: str, *, name: str = "", source: str = "") -> Any:
    """The pint unit of `text`, or `None` for a dimensionless mark (`-`, `1`, empty).

    **Raises:**

    `ValueError` naming the signal, the source and the fix when the unit is unknown.
    """
    where = _where(name, source)
    if text.strip() == "g":
        # pint reads "g" as gram, accelerometer channels mean standard gravity: guessing
        # either could be silently wrong by a factor of ~10^4.
        raise ValueError(
            f"{where}unit 'g' is ambiguous (gram or standard gravity). Write 'g0' for "
            "standard gravity (9.80665 m/s^2) or 'gram' for mass."
        )
    normalised = _normalise(text)
    if normalised is None or normalised == "":
        if normalised is None:
            raise ValueError(
                f"{where}unit {text!r} is not a physical unit (encoder increments, raw "
                "counts). Scale the signal to a physical unit (e.g. m or rad) and write that "
                "unit, or remove the unit."
            )
        return None
    if re.fullmatch(r"[-+0-9.eE ]+", normalised):
        raise ValueError(
            f"{where}unit {text!r} is a number, not a unit; write the unit (e.g. 'mm') or "
            "remove the brackets."
        )
    import pint

    try:
        unit = _registry().parse_units(normalised)
    except (pint.errors.UndefinedUnitError, pint.errors.DefinitionSyntaxError, Exception):
        raise ValueError(
            f"{where}unknown unit {text!r}. Write a unit that pint reads (e.g. 'mm', 'kN', "
            "'ms', 'degC', 'rpm', 'm/s^2'), or remove the unit if the signal is already in SI."
        ) from None
    return unit


def _where(name: str, source: str) -> str:
    parts = []
    if source:
        parts.append(source)
    if name:
        parts.append(f"signal {name!r}")
    return (", ".join(parts) + ": ") if parts else ""


def _is_rpm(unit: Any) -> bool:
    registry = _registry()
    return unit == registry.parse_units("rpm") or str(unit) in (
        "revolutions_per_minute",
        "revolution / minute",
    )


# The SI unit of an angle, an angular velocity and an angular acceleration, by the
# dimensionality of the radian-based unit (a radian is dimensionless).
_ANGLE_SI = {"dimensionless": "rad", "1 / [time]": "rad/s", "1 / [time] ** 2": "rad/s^2"}


def _angle_si(unit: Any) -> str | None:
    """`"rad"`, `"rad/s"` or `"rad/s^2"` for an angle-based unit, else `None`."""
    names = str(unit)
    if not any(key in names for key in _ANGLE_UNITS) and "revolution" not in names:
        return None
    return _ANGLE_SI.get(str(unit.dimensionality))


def si_unit(text: str, *, name: str = "", source: str = "") -> str:
    """The SI unit jaxvs stores a signal written in unit `text` in (see the module doc)."""
    unit = parse_unit(text, name=name, source=source)
    return _target(unit, text)


def _target(unit: Any, text: str) -> str:
    if unit is None:
        return ""
    if _is_rpm(unit):
        return "rpm"
    angle = _angle_si(unit)
    if angle is not None:
        return angle
    if unit.dimensionless:
        # percent, ppm, ...: kept as written (a ratio has no SI unit to go to).
        return text.strip()
    registry = _registry()
    for preferred in _PREFERRED:
        if registry.parse_units(preferred).dimensionality == unit.dimensionality:
            return preferred
    quantity = (1.0 * unit).to_base_units()
    return f"{quantity.units:~C}"


def convert_units(
    values: Any, from_unit: str, to_unit: str, *, name: str = "", source: str = ""
) -> np.ndarray:
    """`values` in `from_unit` converted to `to_unit` (pint; offsets such as °F→°C honoured).

    **Raises:**

    `ValueError` naming the signal and the two units when they measure different things
    (e.g. `N` where `m` is expected), or when either unit is unknown.
    """
    import pint

    array = np.asarray(values, dtype=np.float64)
    source_unit = parse_unit(from_unit, name=name, source=source)
    target_unit = parse_unit(to_unit, name=name, source=source)
    if source_unit is None and target_unit is None:
        return array.copy()
    if source_unit is None or target_unit is None:
        raise ValueError(
            f"{_where(name, source)}unit {from_unit!r} cannot be converted to {to_unit!r}: one "
            "is dimensionless. Check the signal (is it the quantity you meant?) and its unit."
        )
    try:
        quantity = _registry().Quantity(array, source_unit).to(target_unit)
    except pint.errors.DimensionalityError:
        raise ValueError(
            f"{_where(name, source)}unit {from_unit!r} ({source_unit.dimensionality}) does not "
            f"measure the same quantity as {to_unit!r} ({target_unit.dimensionality}). Check "
            "that the column holds the signal you meant, or correct its unit."
        ) from None
    result = np.asarray(quantity.magnitude, dtype=np.float64)
    if result.shape != array.shape:  # pragma: no cover - pint keeps shapes
        result = np.broadcast_to(result, array.shape).copy()
    return result


def to_si(values: Any, unit: str, *, name: str = "", source: str = "") -> tuple[np.ndarray, str]:
    """Convert `values` written in `unit` to the SI unit jaxvs stores (module doc).

    **Arguments:**

    - `values`: the samples (any shape).
    - `unit`: the unit as written in the file (`"mm"`, `"kN"`, `"°C"`, `"rpm"` …).
    - `name`, `source`: the signal and the file, for error messages.

    **Returns:**

    `(converted values as float64, SI unit string)`; the unit is `""` for a dimensionless
    mark such as `-` or `1`.

    **Raises:**

    `ValueError` for an unknown unit (naming the signal, the file and the fix).
    """
    parsed = parse_unit(unit, name=name, source=source)
    target = _target(parsed, unit)
    array = np.asarray(values, dtype=np.float64)
    if parsed is None:
        return array.copy(), target
    if target == unit.strip() or parsed == parse_unit(target):
        # Already the SI unit (perhaps spelled differently, '°C' for 'degC'): kept as written.
        return array.copy(), unit.strip()
    if target == "rpm":
        return convert_units(array, unit, "rpm", name=name, source=source), "rpm"
    return convert_units(array, unit, target, name=name, source=source), target


_BRACKETS = re.compile(r"^\s*(?P<name>.*?)\s*\[(?P<unit>[^\[\]]*)\]\s*$")
_PARENS = re.compile(r"^\s*(?P<name>.*?)\s*\((?P<unit>[^()]*)\)\s*$")


def parse_header(cell: str) -> tuple[str, str | None]:
    """Split a column header into `(name, unit)`.

    Recognised: `name [unit]`; `name (unit)` when the parenthesised text reads as a unit
    (so `test (1)` or `speed (axis X)` stay names); `name/unit` when there is exactly one
    `/`, nothing but a unit on its right and the name on its left has no `/` or spaces
    around it (`q/mm`; `x/y` with an unknown `y` stays a name). `unit` is `None` when the
    header carries none.
    """
    text = cell.strip()
    match = _BRACKETS.match(text)
    if match and match.group("name"):
        return match.group("name"), match.group("unit").strip()
    match = _PARENS.match(text)
    if match and match.group("name"):
        candidate = match.group("unit").strip()
        if _reads_as_unit(candidate):
            return match.group("name"), candidate
    if text.count("/") == 1:
        name, unit = (part.strip() for part in text.split("/"))
        if name and unit and " " not in name and _reads_as_unit(unit):
            return name, unit
    return text, None


def _reads_as_unit(text: str) -> bool:
    if not text or re.fullmatch(r"[-+0-9.eE ]+", text):
        return False
    try:
        unit = parse_unit(text)
    except ValueError:
        return False
    return unit is not None
