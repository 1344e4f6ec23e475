"""Self-contained HTML for the reports people open (`report.html` of `jaxvs diagnose`,
`jaxvs design` and `jaxvs check`) and for the `_repr_html_` of results in notebooks.

One set of building blocks: a page shell with its own small stylesheet, a table from rows,
an embedded figure (a PNG as a base64 `data:` URI), a collapsible `<details>` section, and
`markdown_to_html`, which turns the subset of Markdown the reports write into HTML using
those blocks. A page written here references nothing outside itself (no external CSS,
script, font or image), so it reads offline, in a mail attachment or an archive.
"""

from __future__ import annotations

import base64
import html
import math
import pathlib
import re
from collections.abc import Iterable, Sequence
from typing import Any

__all__ = [
    "details",
    "figure",
    "markdown_to_html",
    "page",
    "report_html",
    "table",
]

_STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;max-width:72em;
margin:1.5em auto;padding:0 1em;color:#1b1f24;line-height:1.45}
h1{font-size:1.6em;border-bottom:2px solid #2b6cb0;padding-bottom:.2em}
h2{font-size:1.25em;margin-top:1.6em;color:#2b6cb0}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em}
th,td{border:1px solid #d0d7de;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f0f4f8}
tr:nth-child(even) td{background:#fafbfc}
td.num{text-align:right;font-variant-numeric:tabular-nums}
details{border:1px solid #d0d7de;border-radius:4px;margin:.5em 0;padding:.2em .8em}
summary{cursor:pointer;font-weight:600;padding:.2em 0}
figure{margin:1em 0}
figure img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.85em;color:#57606a}
blockquote{border-left:4px solid #d29922;margin:.6em 0;padding:.2em .8em;background:#fff8e5}
code{background:#f0f2f4;padding:0 .25em;border-radius:3px}
.missing{color:#b42318}
"""

_BLOCK = re.compile(r"^(#|\||!\[|- |\d+\. |>)")
_NUMBER = re.compile(r"^[\s\-+−]*[\d.]+(e[+-]?\d+)?\s*(%|s)?$|^—$|^–$")


def _inline(text: str) -> str:
    """Escape `text` and render the inline Markdown the reports use: `**bold**`, `` `code` ``."""
    out = html.escape(text, quote=False)
    out = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", out)
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", out)


def _cell(value: Any) -> tuple[str, bool]:
    """Text of a table cell and whether it is a number (right-aligned)."""
    if value is None:
        return "—", True
    if isinstance(value, bool):
        return ("yes" if value else "no"), False
    if isinstance(value, int):
        return str(value), True
    if isinstance(value, float):
        return ("—" if not math.isfinite(value) else f"{value:.4g}"), True
    text = str(value)
    return text, bool(_NUMBER.match(text))


def table(header: Sequence[Any], rows: Iterable[Sequence[Any]], *, markup: bool = True) -> str:
    """An HTML table.

    **Arguments:**

    - `header`: the column titles.
    - `rows`: one sequence of cells per row; `None` and non-finite floats show as "—",
      floats with 4 significant digits, numbers right-aligned.
    - `markup`: render `**bold**` and `` `code` `` inside text cells.

    **Returns:** the `<table>` element as a string.
    """
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = []
    for row in rows:
        cells = []
        for value in row:
            text, numeric = _cell(value)
            text = _inline(text) if markup else html.escape(text)
            cells.append(f'<td class="num">{text}</td>' if numeric else f"<td>{text}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def figure(png: bytes | str | pathlib.Path, caption: str = "") -> str:
    """A figure embedded in the page: the PNG bytes (or the file they are in) as a
    base64 `data:` URI, with an optional caption."""
    data = png if isinstance(png, bytes) else pathlib.Path(png).read_bytes()
    if not data.startswith(b"\x89PNG"):
        raise ValueError("figure: expected PNG data (a file written by matplotlib's savefig).")
    uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    alt = html.escape(caption or "figure")
    cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
    return f'<figure><img src="{uri}" alt="{alt}">{cap}</figure>'


def details(summary: str, body: str, *, open: bool = False) -> str:
    """A collapsible section: `summary` (plain text) always shown, `body` (HTML) on click."""
    flag = " open" if open else ""
    return f"<details{flag}><summary>{_inline(summary)}</summary>{body}</details>"


def page(title: str, body: str) -> str:
    """A whole HTML document around `body` with the reports' inline stylesheet."""
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width,initial-scale=1">'
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>"
        f"<body>\n{body}\n</body></html>\n"
    )


def _split_row(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def markdown_to_html(markdown: str, folder: str | pathlib.Path | None = None) -> str:
    """HTML of the Markdown subset the reports write.

    Headings `#`, `##` become `<h1>`, `<h2>`; a `###` heading opens a collapsible
    `<details>` section that runs to the next heading (the rounds of a search); pipe
    tables become `table`s; `![name](file)` embeds the PNG `folder/file` (a note in red
    when `folder` is `None` or the file is absent); `- ` and `1. ` lists, `> ` quotes and
    paragraphs with `**bold**` and `` `code` ``.

    **Arguments:**

    - `markdown`: the report's Markdown.
    - `folder`: where the figures the Markdown references lie, or `None` to leave
      figures out (the notebook view).

    **Returns:** the body HTML (no page shell; see `page`).
    """
    lines = markdown.splitlines()
    out: list[str] = []
    section: list[str] | None = None  # body of an open <details>
    summary = ""
    i = 0

    def emit(text: str) -> None:
        (section if section is not None else out).append(text)

    def close_section() -> None:
        nonlocal section
        if section is not None:
            out.append(details(summary, "".join(section)))
            section = None

    while i < len(lines):
        line = lines[i]
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            text = line[level:].strip()
            close_section()
            if level >= 3:
                section, summary = [], text
            else:
                out.append(f"<h{level}>{_inline(text)}</h{level}>")
            i += 1
        elif line.startswith("|"):
            block = []
            while i < len(lines) and lines[i].startswith("|"):
                block.append(_split_row(lines[i]))
                i += 1
            rows = [r for r in block if not set("".join(r)) <= set("-: ")]
            emit(table(rows[0], rows[1:]) if rows else "")
        elif line.startswith("!["):
            m = re.match(r"!\[(.*?)\]\((.*?)\)", line)
            name = m.group(2) if m else line
            caption = m.group(1) if m else ""
            path = None if folder is None else pathlib.Path(folder) / name
            if path is not None and path.is_file():
                emit(figure(path, caption))
            elif folder is not None:
                emit(f'<p class="missing">figure {html.escape(name)} is missing.</p>')
            i += 1
        elif re.match(r"^(- |\d+\. )", line):
            ordered = not line.startswith("- ")
            items = []
            while i < len(lines) and re.match(r"^(- |\d+\. )", lines[i]):
                items.append(re.sub(r"^(- |\d+\. )", "", lines[i]))
                i += 1
            tag = "ol" if ordered else "ul"
            emit(f"<{tag}>" + "".join(f"<li>{_inline(x)}</li>" for x in items) + f"</{tag}>")
        elif line.startswith(">"):
            quote = []
            while i < len(lines) and lines[i].startswith(">"):
                quote.append(lines[i].lstrip("> "))
                i += 1
            emit(f"<blockquote>{_inline(' '.join(quote))}</blockquote>")
        elif line.strip():
            para = []
            while i < len(lines) and lines[i].strip() and not _BLOCK.match(lines[i]):
                para.append(lines[i].strip())
                i += 1
            emit(f"<p>{_inline(' '.join(para))}</p>")
        else:
            i += 1
    close_section()
    return "\n".join(out)


def report_html(markdown: str, folder: str | pathlib.Path | None, title: str) -> str:
    """The self-contained `report.html` of a report: its Markdown as HTML, the figures in
    `folder` embedded, in the page shell."""
    return page(title, markdown_to_html(markdown, folder))
