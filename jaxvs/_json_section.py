"""The base of the typed reports: frozen dataclasses whose `_json()` is the one place a
section's JSON keys are written, and which read like the dictionaries they write."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

from ._misc import json_safe

__all__ = ["JsonSection", "ReportContent", "section_json"]


class JsonSection(Mapping):
    """A section of a report as a frozen dataclass with typed fields.

    `_json()` writes the section's keys in order with the values as held (non-finite
    floats included): the one place its part of the schema is written. `to_json()` is
    that dictionary JSON-ready (NumPy scalars to Python, non-finite floats to `None`).

    For compatibility with the dictionary reports of earlier versions, a section reads
    like the dictionary `_json()` writes: `section["key"]`, `section.get("key")`,
    `"key" in section`, `dict(section)`.
    """

    def _json(self) -> dict[str, Any]:
        raise NotImplementedError

    def to_json(self) -> dict[str, Any]:
        """The section as a JSON-ready dictionary."""
        return json_safe(self._json())

    # compatibility: the section reads like the dictionary it writes
    def __getitem__(self, key: str) -> Any:
        return self._json()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._json())

    def __len__(self) -> int:
        return len(self._json())


class ReportContent(JsonSection):
    """A whole report's content: frozen like its sections, but for its `figures`, which
    whoever draws them sets after the report is built."""

    def __setitem__(self, key: str, value: Any) -> None:
        """`content["figures"] = names`: the figures drawn after the report was built
        (compatibility; the other fields are frozen)."""
        if key != "figures":
            raise TypeError(
                f"the report's content is frozen: {key!r} cannot be set; build a new one "
                "with dataclasses.replace(content, ...) (only 'figures' is set after the "
                "report is built, by whoever draws them)."
            )
        object.__setattr__(self, "figures", None if value is None else list(value))


def section_json(value: JsonSection | None) -> dict[str, Any] | None:
    """A section's `_json()`, `None` for a missing section."""
    return None if value is None else value._json()
