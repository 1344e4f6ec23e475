"""Generate the docs page "What jaxvs refuses" from the bad-input matrix.

The matrix is the parametrised tests `tests/test_bad_input_*.py` (row format in
`tests/bad_input.py`): every row records its outcome -- refused (with the message) or handled
correctly -- as one JSON line when `JAXVS_MATRIX_OUT` is set. This script runs those tests
with the variable set (or reads a JSONL file given with `--jsonl`), and writes

- `docs/guides/refusals.md`: the counts, then per area a table case | input | message;
- the counts, as one cell of the headline table of `README.md`, between the markers
  `<!-- refusals:start -->` and `<!-- refusals:end -->` (with `--readme`).

Counts: *refused with a message* (the row's exception and a message naming the problem and
the fix), *handled correctly* (a legal borderline input and a check of the answer),
*silently wrong* (a failed row: a result where a refusal was due, a wrong answer or an
unhelpful message) and *crashes* (a row whose test errored, e.g. another exception type).

Usage (from the repository root):

    python docs/gen_refusals.py                 # run the matrix, write the page
    python docs/gen_refusals.py --readme        # ... and update the README counts
    python docs/gen_refusals.py --jsonl m.jsonl # from recorded rows (no test run)
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "guides" / "refusals.md"
README = ROOT / "README.md"
START, END = "<!-- refusals:start -->", "<!-- refusals:end -->"

# Display order and titles of the areas (others follow alphabetically).
AREAS = {
    "loaders": "Loading files",
    "record": "Records, splits and FRF data",
    "units": "Units",
    "excitation": "Excitation signals",
    "signal": "Signal processing",
    "models": "Model constructors",
    "simulate": "Simulation",
    "calibration": "Calibration and fitting",
    "modelfiles": "Model files",
    "check": "Checks and design",
    "cli": "Command line",
}


def run_matrix(jsonl: Path, junit: Path) -> int:
    """Run every `tests/test_bad_input_*.py` with the recorder on; the pytest exit code."""
    files = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_bad_input_*.py"))
    env = dict(os.environ, JAXVS_MATRIX_OUT=str(jsonl))
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:randomly", f"--junitxml={junit}"]
    return subprocess.run([*cmd, *files], cwd=ROOT, env=env).returncode


def junit_outcomes(junit: Path) -> dict[str, str]:
    """`{row id: "failed" | "crashed"}` of the rows whose test did not pass."""
    out: dict[str, str] = {}
    if not junit.exists():
        return out
    for case in ET.parse(junit).getroot().iter("testcase"):
        match = re.search(r"\[(.*)\]$", case.get("name", ""))
        if match is None:
            continue
        if case.find("failure") is not None:
            # A failed row: an assertion of the row (no refusal, wrong message, wrong
            # answer) is "silently wrong"; any other exception is a crash.
            message = case.find("failure").get("message", "")  # type: ignore[union-attr]
            out[match.group(1)] = "failed" if message.startswith("AssertionError") else "crashed"
        elif case.find("error") is not None:
            out[match.group(1)] = "crashed"
    return out


def clean_message(message: str) -> str:
    """The user-facing sentence of an error (equinox prefixes runtime errors under jit
    with a stack note; the message proper is its last paragraph)."""
    if "EquinoxRuntimeError: " in message:
        message = message.split("EquinoxRuntimeError: ", 1)[1].split("\n\n---", 1)[0]
    return " ".join(message.split())


def cell(text: str, limit: int = 400) -> str:
    text = clean_message(text)
    if len(text) > limit:
        text = text[: limit - 1].rstrip() + "…"
    # Paths of temporary folders say nothing to a reader.
    text = re.sub(r"/tmp/[^\s'\"]*/", "…/", text)
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    # Markdown would read `*` and `_` pairs as emphasis and `[x](y)` as links.
    text = text.replace("*", "\\*").replace("_", "\\_").replace("[", "\\[")
    return text.replace("|", "\\|").replace("\n", " ")


def read_rows(jsonl: Path) -> list[dict]:
    rows: dict[str, dict] = {}
    for line in jsonl.read_text(encoding="utf-8").splitlines():
        if line.strip():
            row = json.loads(line)
            rows[row["id"]] = row  # a re-run row replaces the earlier one
    return list(rows.values())


def counts(rows: list[dict], bad: dict[str, str]) -> dict[str, int]:
    c = Counter(row["outcome"] for row in rows)
    failed = sum(1 for v in bad.values() if v == "failed")
    crashed = sum(1 for v in bad.values() if v == "crashed")
    total = len(rows) + failed + crashed
    return {
        "total": total,
        "refused": c["refused"],
        "handled": c["handled"],
        "silently_wrong": failed,
        "crashes": crashed,
    }


def percent(part: int, whole: int) -> str:
    return f"{100 * part / whole:.1f} %" if whole else "-"


def page(rows: list[dict], bad: dict[str, str]) -> str:
    n = counts(rows, bad)
    lines = [
        "# What jaxvs refuses",
        "",
        "jaxvs checks what it is given: a bad file, array or option is refused",
        "with a message that names the problem and the fix, never turned into a silently wrong",
        "answer; a borderline input that is legal is handled correctly. This page lists every",
        "row of the bad-input matrix, the parametrised tests `tests/test_bad_input_*.py`, with",
        "the message jaxvs gave. It is generated by `docs/gen_refusals.py` from a run of those",
        "tests (they run in CI, so every message below is checked on every change).",
        "",
        "| outcome | rows | share |",
        "|---|---:|---:|",
        f"| refused with a message naming problem and fix | {n['refused']} | "
        f"{percent(n['refused'], n['total'])} |",
        f"| borderline input handled correctly | {n['handled']} | "
        f"{percent(n['handled'], n['total'])} |",
        f"| silently wrong (failed rows) | {n['silently_wrong']} | "
        f"{percent(n['silently_wrong'], n['total'])} |",
        f"| crashes | {n['crashes']} | {percent(n['crashes'], n['total'])} |",
        f"| **total** | **{n['total']}** | |",
        "",
        f"Of the {n['total'] - n['handled']} inputs that must be refused, {n['refused']} "
        f"({percent(n['refused'], n['total'] - n['handled'])}) are refused with a message that "
        "names the problem and the fix (each row pins both with a regular expression).",
        "",
        "Loaders are also fuzzed (`tests/test_fuzz_loaders.py`, hypothesis): random bytes,",
        "truncations, overwritten bytes and cell edits of valid CSV, NPZ, MAT, HDF5 and UFF",
        "files either load exactly what the file holds or raise a `ValueError` naming the file.",
        "",
    ]
    by_area: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        by_area[row["area"]].append(row)
    order = [a for a in AREAS if a in by_area] + sorted(a for a in by_area if a not in AREAS)
    for area in order:
        group = sorted(by_area[area], key=lambda r: (r["entry"], r["id"]))
        refused = sum(r["outcome"] == "refused" for r in group)
        lines += [
            f"## {AREAS.get(area, area.capitalize())}",
            "",
            f"{len(group)} rows: {refused} refused, {len(group) - refused} handled correctly.",
            "",
            "| case | entry point | input | message |",
            "|---|---|---|---|",
        ]
        for r in group:
            message = cell(r["message"]) if r["outcome"] == "refused" else "*(handled correctly)*"
            lines.append(f"| `{r['id']}` | `{r['entry']}` | {cell(r['input'], 200)} | {message} |")
        lines.append("")
    if bad:
        lines += ["## Rows that failed in this run", ""]
        lines += [f"- `{k}`: {v}" for k, v in sorted(bad.items())]
        lines.append("")
    return "\n".join(lines)


def readme_paragraph(rows: list[dict], bad: dict[str, str]) -> str:
    """The counts as one table cell, between the markers in the README's headline table."""
    n = counts(rows, bad)
    return (
        f"{START}{n['refused']} of {n['total'] - n['handled']} bad inputs refused with a message "
        f"naming the problem and the fix ({percent(n['refused'], n['total'] - n['handled'])}), "
        f"{n['handled']} borderline inputs handled correctly, {n['silently_wrong']} silently "
        f"wrong, {n['crashes']} crashes{END}"
    )


def update_readme(text: str) -> None:
    readme = README.read_text(encoding="utf-8")
    if START in readme and END in readme:
        readme = re.sub(re.escape(START) + r".*?" + re.escape(END), text, readme, flags=re.S)
    else:
        raise SystemExit(f"{README}: the markers {START} ... {END} are missing; put them in a cell")
    README.write_text(readme, encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jsonl", type=Path, help="recorded rows (skip running the tests)")
    parser.add_argument("--junit", type=Path, help="pytest junit XML of that run (failures)")
    parser.add_argument("--readme", action="store_true", help="also update README.md")
    parser.add_argument("--out", type=Path, default=PAGE, help="the page to write")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        jsonl, junit = args.jsonl, args.junit
        if jsonl is None:
            jsonl, junit = Path(tmp) / "matrix.jsonl", Path(tmp) / "junit.xml"
            run_matrix(jsonl, junit)
        rows = read_rows(jsonl)
        bad = junit_outcomes(junit) if junit is not None else {}
    args.out.write_text(page(rows, bad), encoding="utf-8")
    if args.readme:
        update_readme(readme_paragraph(rows, bad))
    n = counts(rows, bad)
    print(f"{args.out}: " + ", ".join(f"{k} {v}" for k, v in n.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
