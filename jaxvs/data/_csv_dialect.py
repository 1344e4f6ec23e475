"""Messages for CSV files written in another dialect than `load_csv` was told to read.

Spreadsheets in many locales save `;`-separated files with decimal commas (`0,5`), and
older ones in Latin-1/Windows-1252 rather than UTF-8. These helpers recognise each case
and name the option that reads the file (keyword and `jaxvs` command option).
"""

from __future__ import annotations

import re

__all__ = ["decimal_hint", "delimiter_hint", "encoding_error"]

_DECIMAL_COMMA = re.compile(r"^\s*[-+]?(\d+,\d*|,\d+)([eE][-+]?\d+)?\s*$")
_OPTIONS = {
    "delimiter": "--delimiter",
    "decimal": "--decimal",
    "encoding": "--encoding",
}


def _option(name: str, value: str) -> str:
    return f"{name}={value!r} (jaxvs commands: {_OPTIONS[name]} '{value}')"


def delimiter_hint(header_line: str, delimiter: str) -> str | None:
    """A fix when the header is one cell that another delimiter would split."""
    for other, word in ((";", "semicolon"), ("\t", "tab"), ("|", "bar"), (",", "comma")):
        if other != delimiter and header_line.count(other) >= 1:
            fix = _option("delimiter", other if other != "\t" else "\\t")
            also = ""
            if other == ";":
                also = ", and decimal=',' (--decimal ',') if its numbers use decimal commas"
            return (
                f"the header {header_line.strip()!r} is one column: the file looks "
                f"{word}-separated; pass {fix}{also}."
            )
    return None


_GROUPED = re.compile(r"^\s*[-+]?[1-9]\d{0,2}([,.' ]\d{3})+([.,]\d+)?\s*$")


def decimal_hint(cell: str, decimal: str) -> str | None:
    """A fix when a cell that failed to parse is a number with a decimal comma, or with
    thousands separators (`1,000` is either: both readings are named)."""
    if _GROUPED.match(cell) and not (decimal == "," and cell.count(",") == 1):
        return (
            "it looks like a number with thousands separators (digit grouping); export the "
            "numbers without grouping"
            + (
                f", or, if ',' is its decimal comma (1,000 = 1.0), pass {_option('decimal', ',')}"
                if decimal != "," and cell.count(",") == 1 and "." not in cell
                else ""
            )
            + "."
        )
    if decimal != "," and _DECIMAL_COMMA.match(cell):
        return f"it looks like a number with a decimal comma; pass {_option('decimal', ',')}."
    return None


def encoding_error(source: str, error: UnicodeDecodeError, data: bytes, encoding: str) -> str:
    """The message for a file that is not text in `encoding`."""
    line = data.count(b"\n", 0, error.start) + 1
    byte = data[error.start : error.start + 1].hex()
    binary = b"\x00" in data[:4096]
    if binary:
        return (
            f"{source} is not a text file (NUL bytes; byte 0x{byte} on line {line}); give "
            "a CSV text file, or the binary file with its own suffix (.npz, .mat, .h5, ...)."
        )
    return (
        f"{source} is not {encoding} text (byte 0x{byte} on line {line}); re-save it as "
        f"UTF-8 (spreadsheets: 'CSV UTF-8'), or pass {_option('encoding', 'latin-1')} "
        "if it was written in Latin-1/Windows-1252."
    )
