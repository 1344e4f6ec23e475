"""Bad-input matrix, CLI rows: every sub-command of `jaxvs` against bad paths, options and
files (docs/guides/contracts.md, docs/guides/refusals.md).

A refusal is exit code 2 with exactly one line `jaxvs: error: ...` on stderr that names the
problem and the fix, no traceback, and nothing written. The rows run `jaxvs._cli.main`
in-process (the refusals come before any JAX work, so each takes milliseconds); a few rows
at the end run the real command in a subprocess to show that the process itself prints
one line and exits with 2.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from bad_input import Case, CliExit, run_case, run_cli

from jaxvs._cli import main

N = 1500  # samples: long enough for every family's checks, small enough to be instant
DT = 1e-3


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    # the in-process command must not point this test process's JAX at a cache folder
    monkeypatch.setenv("JAXVS_NO_CACHE", "1")


# --- files ----------------------------------------------------------------------------------


def _drive_columns(n: int = N, dt: float = DT) -> dict[str, np.ndarray]:
    t = np.arange(n) * dt
    q = 0.05 * np.sin(2 * np.pi * 1.0 * t) + 0.01 * np.sin(2 * np.pi * 7.0 * t)
    u = 50.0 * np.cos(2 * np.pi * 1.0 * t) + 5.0 * np.sin(2 * np.pi * 13.0 * t)
    return {"t": t, "q": q, "u": u, "r": q}


def _thermal_columns(n: int = N) -> dict[str, np.ndarray]:
    t = np.arange(n) * 1.0
    v = 1000 + 500 * np.sin(2 * np.pi * t / 300)
    return {
        "t": t,
        "T_chassis": 20 + 0.002 * v + 0.1 * np.sin(t / 50),
        "T_bearing": 22 + 0.003 * v,
        "v_m": v,
    }


def write_csv(
    path: Path,
    columns: dict[str, np.ndarray],
    *,
    sep: str = ",",
    decimal: str = ".",
    encoding: str = "utf-8",
    bom: bool = False,
    header: str | None = None,
) -> Path:
    names = list(columns)
    lines = [header if header is not None else sep.join(names)]
    for row in zip(*columns.values()):
        cells = [repr(float(v)) for v in row]
        if decimal != ".":
            cells = [c.replace(".", decimal) for c in cells]
            if decimal == sep:
                cells = [f'"{c}"' for c in cells]
        lines.append(sep.join(cells))
    data = ("\n".join(lines) + "\n").encode(encoding)
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + data)
    return path


def drive_csv(tmp: Path, name: str = "run.csv", **kw) -> Path:
    return write_csv(tmp / name, _drive_columns(), **kw)


def thermal_csv(tmp: Path, name: str = "run.csv", **kw) -> Path:
    return write_csv(tmp / name, _thermal_columns(), **kw)


# --- running the command --------------------------------------------------------------------


def run_main(
    args: list[str], cwd: Path, ok: tuple[int, ...] = (0,), *, strict: bool = True
) -> tuple[int, str, str]:
    """`jaxvs ARGS` in-process in `cwd`; raise `CliExit` for an exit code outside `ok`. A
    refusal (exit 2) must be exactly one line `jaxvs: error: ...` and write nothing."""
    before = sorted(p.name for p in cwd.iterdir())
    out, err = io.StringIO(), io.StringIO()
    old = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in args])
            except SystemExit as e:  # --help, --version
                code = int(e.code or 0)
    finally:
        os.chdir(old)
    stderr = err.getvalue()
    if code == 2 and strict:
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("jaxvs: error: "), stderr
        assert "Traceback" not in stderr
        after = sorted(p.name for p in cwd.iterdir())
        assert after == before, f"a refused command wrote {set(after) - set(before)}"
    if code not in ok:
        raise CliExit(code, stderr, out.getvalue())
    return code, out.getvalue(), stderr


def cli(make: Callable[[Path], list], ok: tuple[int, ...] = (0,)) -> Callable[[Path], object]:
    """A row's `run`: build the files and the arguments in the temporary folder, run."""
    return lambda tmp: run_main(make(tmp), tmp, ok)


def refused(id, entry, input, make, match, **kw) -> Case:
    return Case(
        id=id,
        area="cli",
        entry=entry,
        input=input,
        run=cli(make),
        exc=CliExit,
        match=match,
        exit_code=2,
        **kw,
    )


def _base(cmd: str, data: list, tmp: Path) -> list:
    if cmd == "diagnose":
        return ["diagnose", *data, "--family", "drive", "--out", tmp / "o"]
    if cmd == "check":
        return ["check", *data, "--family", "drive", "--out", tmp / "o"]
    return ["design", *data, "--target", "u", "--out", tmp / "o"]


CASES: list[Case] = []
DATA_COMMANDS = ("diagnose", "check", "design")


# --- paths, for every sub-command that reads data ---------------------------------------------
def _file(name: str, content: str | bytes) -> Callable[[Path], Path]:
    """A data file with exactly this content."""

    def make(tmp: Path) -> Path:
        (tmp / name).write_bytes(content if isinstance(content, bytes) else content.encode())
        return tmp / name

    return make


def _edited(edit: Callable[[str], str]) -> Callable[[Path], Path]:
    """The valid drive CSV with one edit of its text."""

    def make(tmp: Path) -> Path:
        p = drive_csv(tmp)
        p.write_text(edit(p.read_text()))
        return p

    return make


def _mkdir(tmp: Path, *names: str, file: str | None = None) -> Path:
    d = tmp.joinpath(*names)
    d.mkdir(parents=True)
    if file:
        (d / file).write_text("x")
    return d


def _a_file(tmp: Path) -> Path:
    (tmp / "f.txt").write_text("x")
    return tmp / "f.txt"


def _symlink(tmp: Path) -> Path:
    (tmp / "l.csv").symlink_to(tmp / "gone.csv")
    return tmp / "l.csv"


# (id, input, data file(s) maker, extra args or --out maker, match): --out defaults to tmp/o
_PER_COMMAND = [
    (
        "missing-file",
        "a data file that does not exist",
        lambda tmp: tmp / "nope.csv",
        None,
        r"nope\.csv: no such file.*check the path",
    ),
    (
        "missing-file-hint",
        "a misspelt data file next to real ones",
        lambda tmp: (drive_csv(tmp, "run1.csv"), tmp / "rnu1.csv")[1],
        None,
        r"no such file \(files there: run1\.csv\)",
    ),
    (
        "data-is-folder",
        "a folder given as data",
        lambda tmp: _mkdir(tmp, "d"),
        None,
        r"is a folder; give the data file\(s\) in it",
    ),
    (
        "empty-file",
        "an empty (0-byte) data file",
        _file("e.csv", ""),
        None,
        r"is empty \(0 bytes\); give the complete file",
    ),
    (
        "broken-symlink",
        "a symbolic link to a file that was deleted",
        _symlink,
        None,
        r"l\.csv.*broken symbolic link.*gone\.csv.*give the path of the real file",
    ),
    (
        "fifo",
        "a named pipe (FIFO) given as data (reading it would block forever)",
        lambda tmp: (os.mkfifo(tmp / "pipe.csv"), tmp / "pipe.csv")[1],
        None,
        r"pipe\.csv.*named pipe \(FIFO\), not a regular file.*save the data to a file",
    ),
    (
        "device",
        "/dev/zero given as data",
        lambda tmp: "/dev/zero",
        None,
        r"/dev/zero.*is a device, not a regular file.*save the data to a file",
    ),
    (
        "symlink-loop",
        "a symbolic link that points to itself",
        lambda tmp: ((tmp / "loop.csv").symlink_to("loop.csv"), tmp / "loop.csv")[1],
        None,
        r"loop\.csv.*symbolic link loop.*give the path of the real file",
    ),
    (
        "out-is-file",
        "--out naming an existing file",
        drive_csv,
        _a_file,
        r"--out .*f\.txt is a file, not a folder; give --out the name of a new folder",
    ),
    (
        "out-under-file",
        "--out inside a path whose parent is a file",
        drive_csv,
        lambda tmp: _a_file(tmp) / "sub",
        r"is a file, so no folder can be made under it; give --out the name of a new folder",
    ),
    (
        "out-unwritable",
        "--out in a place nobody can write (/proc)",
        drive_csv,
        lambda tmp: "/proc/jaxvs-report",
        r"cannot write in /proc.*in a folder you can write to",
    ),
    (
        "out-foreign-folder",
        "--out naming a non-empty folder that holds no jaxvs report",
        drive_csv,
        lambda tmp: _mkdir(tmp, "mine", file="notes.txt"),
        r"files \(notes\.txt\) that jaxvs did not write \(no \.jaxvs-report marker\).*new "
        r"folder.*never deletes files it did not write",
    ),
    (
        "out-holds-input",
        "--out naming the folder that holds the data file",
        lambda tmp: drive_csv(_mkdir(tmp, "d")),
        lambda tmp: tmp / "d",
        r"(holds the input file|jaxvs did not write).*new folder",
    ),
    (
        "out-empty-string",
        "--out ''",
        drive_csv,
        lambda tmp: "",
        r"--out is empty; give the name of a folder",
    ),
    (
        "unknown-flag",
        "an option that does not exist (--bogus)",
        drive_csv,
        ["--bogus"],
        r"unrecognized arguments: --bogus; see 'jaxvs \w+ --help'",
    ),
    (
        "semicolon-csv",
        "a ;-separated CSV with decimal commas",
        lambda tmp: drive_csv(tmp, sep=";", decimal=","),
        None,
        r"semicolon-separated; pass .*--delimiter ';'.*--decimal ','",
    ),
    (
        "decimal-comma",
        "a ;-separated CSV with decimal commas read with --delimiter ';' only",
        lambda tmp: drive_csv(tmp, sep=";", decimal=","),
        ["--delimiter", ";"],
        r"is not a number; it looks like a number with a decimal comma; pass .*--decimal ','",
    ),
    (
        "quoted-decimal-comma",
        'a comma-separated CSV with quoted decimal commas ("0,5")',
        lambda tmp: drive_csv(tmp, decimal=","),
        None,
        r"decimal comma; pass .*--decimal ','",
    ),
    (
        "latin1",
        "a CSV saved in Latin-1 (a header 'Température')",
        lambda tmp: write_csv(
            tmp / "l1.csv", {**_drive_columns(), "Température": np.zeros(N)}, encoding="latin-1"
        ),
        None,
        r"not utf-8 text \(byte 0xe9 on line 1\); re-save it as UTF-8.*--encoding",
    ),
    (
        "binary-as-csv",
        "a binary file named .csv",
        _file("b.csv", bytes(range(256)) * 4),
        None,
        r"not a text file.*give a CSV text file",
    ),
    (
        "truncated-csv",
        "a CSV cut off in the middle of its last row",
        _edited(lambda text: text[:-25]),
        None,
        r"ends inside a row.*looks truncated.*Export it again",
    ),
    (
        "header-only",
        "a CSV with a header and no rows",
        _file("h.csv", "t,q,u\n"),
        None,
        r"has a header but no data rows; add one row per sample",
    ),
    (
        "text-cell",
        "a CSV with a text cell ('n/a') among the numbers",
        _edited(lambda text: text.replace("\n0.01", "\nn/a", 1)),
        None,
        r"cell 'n/a' is not a number; every cell below the header must be numeric",
    ),
    (
        "no-time-column",
        "a CSV without a time column",
        lambda tmp: write_csv(
            tmp / "x.csv", {k: v for k, v in _drive_columns().items() if k != "t"}
        ),
        None,
        r"has no time column 't'.*Name the time column 't'",
    ),
    (
        "duplicate-column",
        "a CSV whose header names a column twice",
        lambda tmp: drive_csv(tmp, header="t,q,u,q"),
        None,
        r"column name 'q' appears twice",
    ),
    (
        "unsupported-suffix",
        "a .txt file",
        _file("d.txt", "t q u\n"),
        None,
        r"Unsupported file type '\.txt'.*supported suffixes",
    ),
]


def _per_command(cmd: str, data, extra) -> Callable[[Path], list]:
    def make(tmp: Path) -> list:
        args = _base(cmd, [data(tmp)], tmp)
        if callable(extra):
            return [*args[:-1], extra(tmp)]  # another --out
        return [*args, *(extra or [])]

    return make


for cmd in DATA_COMMANDS:
    for row_id, text, data, extra, match in _PER_COMMAND:
        CASES.append(
            refused(f"{cmd}-{row_id}", f"jaxvs {cmd}", text, _per_command(cmd, data, extra), match)
        )

# --- sub-command options ------------------------------------------------------------------------


def _opt(cmd: str, extra: list, data=drive_csv) -> Callable[[Path], list]:
    return lambda tmp: [*_base(cmd, [data(tmp)], tmp), *extra]


for value, label in (("0", "0"), ("-1", "-1"), ("two", "a word")):
    CASES.append(
        refused(
            f"diagnose-max-effects-{value}",
            "jaxvs diagnose",
            f"--max-effects {label}",
            _opt("diagnose", ["--max-effects", value]),
            r"--max-effects: expects an integer >= 1.*see 'jaxvs diagnose --help'",
        )
    )
for cmd in ("diagnose", "design"):
    for value in ("0", "1.5", "x"):
        CASES.append(
            refused(
                f"{cmd}-holdout-{value}",
                f"jaxvs {cmd}",
                f"--holdout {value}",
                _opt(cmd, ["--holdout", value]),
                r"--holdout: expects a number in \(0, 1\)",
            )
        )
for value in ("0", "-5", "nan", "inf"):
    CASES.append(
        refused(
            f"diagnose-cutoff-{value}",
            "jaxvs diagnose",
            f"--cutoff-hz {value}",
            _opt("diagnose", ["--cutoff-hz", value]),
            r"--cutoff-hz: expects a positive (finite )?number",
        )
    )
for cmd in ("diagnose", "check"):
    CASES += [
        refused(
            f"{cmd}-option-unknown-key",
            f"jaxvs {cmd}",
            "--option with a key the family does not know (cutof_hz=50)",
            _opt(cmd, ["--option", "cutof_hz=50"]),
            r"unknown option.*cutof_hz",
        ),
        refused(
            f"{cmd}-option-no-value",
            f"jaxvs {cmd}",
            "--option without '=' (novalue)",
            _opt(cmd, ["--option", "novalue"]),
            r"--option expects KEY=VALUE such as decimation=4",
        ),
        refused(
            f"{cmd}-option-no-key",
            f"jaxvs {cmd}",
            "--option =3",
            _opt(cmd, ["--option", "=3"]),
            r"--option expects KEY=VALUE",
        ),
        refused(
            f"{cmd}-option-empty-value",
            f"jaxvs {cmd}",
            "--option decimation=",
            _opt(cmd, ["--option", "decimation="]),
            r"--option expects KEY=VALUE",
        ),
        refused(
            f"{cmd}-option-twice",
            f"jaxvs {cmd}",
            "--option decimation=2 --option decimation=4",
            _opt(cmd, ["--option", "decimation=2", "--option", "decimation=4"]),
            r"--option decimation is given twice; keep one",
        ),
        refused(
            f"{cmd}-family-unknown",
            f"jaxvs {cmd}",
            "--family hydraulic",
            lambda tmp, cmd=cmd: [cmd, drive_csv(tmp), "--family", "hydraulic", "--out", "o"],
            r"--family: invalid choice: 'hydraulic' \(choose from",
        ),
        refused(
            f"{cmd}-family-missing",
            f"jaxvs {cmd}",
            "no --family",
            lambda tmp, cmd=cmd: [cmd, drive_csv(tmp), "--out", "o"],
            r"required: --family; see 'jaxvs \w+ --help'",
        ),
        refused(
            f"{cmd}-signals-missing",
            f"jaxvs {cmd}",
            "thermal records given to --family drive (no q, u)",
            _opt(cmd, [], data=thermal_csv),
            r"lacks the required signal.*Rename the columns",
        ),
    ]
for cmd in DATA_COMMANDS:
    CASES += [
        refused(
            f"{cmd}-delimiter-two-chars",
            f"jaxvs {cmd}",
            "--delimiter ';;'",
            _opt(cmd, ["--delimiter", ";;"]),
            r"--delimiter: expects one character such as ';'",
        ),
        refused(
            f"{cmd}-decimal-equals-delimiter",
            f"jaxvs {cmd}",
            "--decimal ',' with the default delimiter ','",
            _opt(cmd, ["--decimal", ","]),
            r"must be two different single characters, e.g. delimiter=';', decimal=','",
        ),
        refused(
            f"{cmd}-encoding-unknown",
            f"jaxvs {cmd}",
            "--encoding klingon",
            _opt(cmd, ["--encoding", "klingon"]),
            r"unknown encoding 'klingon'; use e.g. 'utf-8' or 'latin-1'",
        ),
    ]
CASES += [
    refused(
        "diagnose-out-missing",
        "jaxvs diagnose",
        "no --out",
        lambda tmp: ["diagnose", drive_csv(tmp), "--family", "drive"],
        r"required: --out; see 'jaxvs diagnose --help'",
    ),
    refused(
        "diagnose-order-0",
        "jaxvs diagnose",
        "--order 0",
        _opt("diagnose", ["--order", "0"]),
        r"--order: expects an integer >= 1",
    ),
    refused(
        "diagnose-seed-negative",
        "jaxvs diagnose",
        "--seed -1",
        _opt("diagnose", ["--seed", "-1"]),
        r"--seed: expects an integer >= 0",
    ),
    refused(
        "diagnose-validate-missing",
        "jaxvs diagnose",
        "--validate naming a file that does not exist",
        _opt("diagnose", ["--validate", "val.csv"]),
        r"--validate val\.csv: no such file",
    ),
    refused(
        "diagnose-mixed-sample-times",
        "jaxvs diagnose",
        "calibration at 1 kHz, validation at 2 kHz",
        lambda tmp: [
            *_base("diagnose", [drive_csv(tmp)], tmp),
            "--validate",
            write_csv(tmp / "fast.csv", _drive_columns(dt=5e-4)),
        ],
        r"share one sampling rate",
    ),
    refused(
        "diagnose-nan-column",
        "jaxvs diagnose",
        "a CSV whose force column is all nan",
        lambda tmp: _base(
            "diagnose",
            [write_csv(tmp / "n.csv", {**_drive_columns(), "u": np.full(N, np.nan)})],
            tmp,
        ),
        r"n\.csv'?: Signal 'u' has a non-finite value.*Remove or interpolate",
    ),
    refused(
        "design-out-missing",
        "jaxvs design",
        "no --out",
        lambda tmp: ["design", drive_csv(tmp), "--target", "u"],
        r"required: --out",
    ),
    refused(
        "design-target-missing",
        "jaxvs design",
        "no --target",
        lambda tmp: ["design", drive_csv(tmp), "--out", "o"],
        r"required: --target",
    ),
    refused(
        "design-target-unknown",
        "jaxvs design",
        "--target naming a signal the file lacks",
        lambda tmp: ["design", drive_csv(tmp), "--target", "T_bearing", "--out", "o"],
        r"no target signal 'T_bearing'.*Choose the target with --target",
    ),
    refused(
        "design-target-samples-missing",
        "jaxvs design",
        "--target-samples naming a file that does not exist",
        _opt("design", ["--target-samples", "s.csv"]),
        r"--target-samples s\.csv: no such file",
    ),
    refused(
        "design-hidden-zero",
        "jaxvs design",
        "--hidden 0",
        _opt("design", ["--hidden", "0"]),
        r"--hidden expects positive integers like 3,6,10",
    ),
    refused(
        "design-hidden-words",
        "jaxvs design",
        "--hidden a,b",
        _opt("design", ["--hidden", "a,b"]),
        r"--hidden expects positive integers like 3,6,10",
    ),
    refused(
        "design-inputs-empty",
        "jaxvs design",
        "--inputs ','",
        _opt("design", ["--inputs", ","]),
        r"--inputs is empty; give signal names",
    ),
    refused(
        "design-max-inputs-0",
        "jaxvs design",
        "--max-inputs 0",
        _opt("design", ["--max-inputs", "0"]),
        r"--max-inputs: expects an integer >= 1",
    ),
    refused(
        "design-max-delay-negative",
        "jaxvs design",
        "--max-delay -1",
        _opt("design", ["--max-delay", "-1"]),
        r"--max-delay: expects an integer >= 0",
    ),
    refused(
        "design-inits-0",
        "jaxvs design",
        "--inits 0",
        _opt("design", ["--inits", "0"]),
        r"--inits: expects an integer >= 1",
    ),
    refused(
        "design-budget-0",
        "jaxvs design",
        "--budget 0",
        _opt("design", ["--budget", "0"]),
        r"--budget: expects a positive finite number",
    ),
    refused(
        "design-budget-negative",
        "jaxvs design",
        "--budget -3",
        _opt("design", ["--budget", "-3"]),
        r"--budget: expects a positive finite number",
    ),
    refused(
        "check-data-missing",
        "jaxvs check",
        "no data file at all",
        lambda tmp: ["check", "--family", "drive"],
        r"required: data; see 'jaxvs check --help'",
    ),
    refused(
        "demo-out-is-file",
        "jaxvs demo",
        "--out naming an existing file",
        lambda tmp: ["demo", "--out", (tmp / "f", (tmp / "f").write_text("x"))[0]],
        r"is a file, not a folder; give --out the name of a new folder",
    ),
    refused(
        "demo-out-unwritable",
        "jaxvs demo",
        "--out in /proc",
        lambda tmp: ["demo", "--out", "/proc/jaxvs-demo"],
        r"cannot write in /proc",
    ),
    refused(
        "demo-out-foreign-folder",
        "jaxvs demo",
        "--out naming a folder of the user's own files",
        lambda tmp: [
            "demo",
            "--out",
            ((tmp / "m").mkdir(), (tmp / "m" / "a.py").write_text(""), tmp / "m")[2],
        ],
        r"folder with files \(a\.py\) that jaxvs did not write.*new folder",
    ),
    refused(
        "demo-positions-1",
        "jaxvs demo",
        "--positions 1",
        lambda tmp: ["demo", "--positions", "1", "--out", tmp / "o"],
        r"--positions: expects an integer >= 2",
    ),
    refused(
        "demo-positions-word",
        "jaxvs demo",
        "--positions many",
        lambda tmp: ["demo", "--positions", "many", "--out", tmp / "o"],
        r"--positions: expects an integer >= 2, got 'many'",
    ),
    refused(
        "no-command",
        "jaxvs",
        "no sub-command",
        lambda tmp: [],
        r"required: \{demo,diagnose,check,design\}",
    ),
    refused(
        "unknown-command",
        "jaxvs",
        "a sub-command that does not exist (diagnos)",
        lambda tmp: ["diagnos"],
        r"invalid choice: 'diagnos' \(choose from 'demo', 'diagnose'",
    ),
]

# --- borderline inputs that are legal ----------------------------------------------------------


def _check_report(expect_rows: int) -> Callable[[object], None]:
    def check(result) -> None:
        code, out, _ = result
        assert code in (0, 3), code  # an answer, not a refusal
        assert f"| {expect_rows} |" in out, out  # all rows were read (the record table)

    return check


def _legal(id, input, make, check, ok=(0, 3)) -> Case:
    return Case(
        id=id,
        area="cli",
        entry="jaxvs check",
        input=input,
        run=cli(make, ok),
        exc=None,
        check=check,
    )


CASES += [
    _legal(
        "check-bom-csv",
        "a UTF-8 CSV with a byte-order mark (Excel's 'CSV UTF-8')",
        lambda tmp: ["check", drive_csv(tmp, bom=True), "--family", "drive"],
        _check_report(N),
    ),
    _legal(
        "check-semicolon-decimal-comma-with-options",
        "a ;-separated decimal-comma CSV with --delimiter ';' --decimal ','",
        lambda tmp: [
            "check",
            drive_csv(tmp, sep=";", decimal=","),
            "--family",
            "drive",
            "--delimiter",
            ";",
            "--decimal",
            ",",
        ],
        _check_report(N),
    ),
    _legal(
        "check-latin1-with-encoding",
        "a Latin-1 CSV with --encoding latin-1",
        lambda tmp: [
            "check",
            write_csv(
                tmp / "l1.csv", {**_drive_columns(), "Température": np.zeros(N)}, encoding="latin-1"
            ),
            "--family",
            "drive",
            "--encoding",
            "latin-1",
        ],
        _check_report(N),
    ),
    _legal(
        "check-tab-separated-with-option",
        "a tab-separated file with --delimiter tab",
        lambda tmp: ["check", drive_csv(tmp, sep="\t"), "--family", "drive", "--delimiter", "\\t"],
        _check_report(N),
    ),
]


# --- the --out policy: only what jaxvs wrote is replaced ----------------------------------------


def _jaxvs_report(tmp: Path, name: str = "o") -> Path:
    """A report folder written by jaxvs itself (a real `jaxvs check` run)."""
    run_main(
        ["check", drive_csv(tmp, "first.csv"), "--family", "drive", "--out", tmp / name],
        tmp,
        ok=(0, 3),
    )
    return tmp / name


def _replaces_old_report(tmp: Path) -> list:
    old = _jaxvs_report(tmp)
    (old / "report.json").write_text("{}")  # jaxvs's own file, changed: still jaxvs's
    return ["check", drive_csv(tmp), "--family", "drive", "--out", old]


def _replaced(result) -> None:
    code, out, _ = result
    assert code in (0, 3)
    folder = Path(out.strip().splitlines()[-1].split("written: ")[1].split(",")[0]).parent
    assert json.loads((folder / "report.json").read_text())["family"] == "drive"
    assert (folder / ".jaxvs-report").is_file()  # the marker of the new report
    assert not [p for p in folder.parent.iterdir() if p.name.startswith(".o.")]  # no staging left


def _untouched(make: Callable[[Path], list], keep: str) -> Callable[[Path], object]:
    """Run the command; whatever it says, the user's file `keep` is still there, unchanged."""

    def run(tmp: Path) -> object:
        args = make(tmp)
        path = tmp / keep
        before = path.read_bytes() if path.is_file() else os.readlink(path)
        try:
            return run_main(args, tmp, strict=False)
        finally:
            after = path.read_bytes() if path.is_file() else os.readlink(path)
            assert after == before, f"{keep} was changed or removed"

    return run


def _foreign_report_json(tmp: Path) -> list:
    folder = _mkdir(tmp, "o", file="keep.txt")
    (folder / "report.json").write_text("{}")  # a name match is not a jaxvs report
    return ["check", drive_csv(tmp), "--family", "drive", "--out", folder]


def _report_plus_user_file(tmp: Path) -> list:
    folder = _jaxvs_report(tmp)
    (folder / "keep.txt").write_text("my notes")
    return ["check", drive_csv(tmp), "--family", "drive", "--out", folder]


def _symlinked_out(tmp: Path) -> list:
    real = _jaxvs_report(tmp, "real")
    (tmp / "o").symlink_to(real)
    return ["check", drive_csv(tmp), "--family", "drive", "--out", tmp / "o"]


def _locked_out(tmp: Path) -> list:
    from jaxvs._outdir import ReportFolder

    old = os.getcwd()
    os.chdir(tmp)
    try:
        holder = ReportFolder(tmp / "o")  # another run holds --out o
    finally:
        os.chdir(old)
    _HOLDERS.append(holder)
    return ["check", drive_csv(tmp), "--family", "drive", "--out", tmp / "o"]


_HOLDERS: list = []


def _with_holder_released(make):
    def run(tmp: Path) -> object:
        try:
            return run_main(make(tmp), tmp)
        finally:
            while _HOLDERS:
                _HOLDERS.pop().release()

    return run


def _dead_pid() -> int:
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _stale_partials(tmp: Path) -> list:
    dead = tmp / f".o.partial-{_dead_pid()}"
    dead.mkdir()
    (dead / "report.json").write_text("{")  # a half-written report of a killed run
    alive = tmp / f".o.partial-{os.getppid()}"  # a live process's: not ours to remove
    alive.mkdir()
    return ["check", drive_csv(tmp), "--family", "drive", "--out", tmp / "o"]


def _stale_cleaned(result) -> None:
    code, out, _ = result
    folder = Path(out.strip().splitlines()[-1].split("written: ")[1].split(",")[0]).parent
    left = sorted(p.name for p in folder.parent.iterdir() if p.name.startswith(".o."))
    assert left == [f".o.partial-{os.getppid()}"], left


CASES += [
    _legal(
        "check-out-with-older-report",
        "--out naming a folder that holds an earlier report written by jaxvs",
        _replaces_old_report,
        _replaced,
    ),
    Case(
        "check-out-report-json-not-by-jaxvs",
        "cli",
        "jaxvs check",
        "--out naming a folder of the user's that holds a report.json and keep.txt",
        _untouched(_foreign_report_json, "o/keep.txt"),
        exc=CliExit,
        exit_code=2,
        match=r"files \(keep\.txt, report\.json\) that jaxvs did not write.*new folder",
    ),
    Case(
        "check-out-report-plus-user-file",
        "cli",
        "jaxvs check",
        "--out naming an earlier jaxvs report into which the user put keep.txt",
        _untouched(_report_plus_user_file, "o/keep.txt"),
        exc=CliExit,
        exit_code=2,
        match=r"earlier jaxvs report and files added since \(keep\.txt\).*move them out",
    ),
    Case(
        "check-out-symlink",
        "cli",
        "jaxvs check",
        "--out naming a symbolic link to a report folder",
        _untouched(_symlinked_out, "o"),
        exc=CliExit,
        exit_code=2,
        match=r"is a symbolic link \(to .*real\).*name the folder the link points to",
    ),
    refused(
        "check-out-dot",
        "jaxvs check",
        "--out . (the current folder)",
        lambda tmp: ["check", drive_csv(tmp), "--family", "drive", "--out", "."],
        r"--out \. is the current folder.*give --out the name of a new folder",
    ),
    refused(
        "design-out-dot-dot",
        "jaxvs design",
        "--out .. (the parent folder)",
        lambda tmp: ["design", thermal_csv(tmp), "--target", "T_bearing", "--out", ".."],
        r"--out \.\. is the current folder, one of its parents.*new folder",
    ),
    Case(
        "check-out-used-by-another-run",
        "cli",
        "jaxvs check",
        "--out naming a folder another jaxvs run is writing",
        _with_holder_released(_locked_out),
        exc=CliExit,
        exit_code=2,
        match=r"being written by another jaxvs run \(process \d+\).*another folder",
    ),
    Case(
        "check-stale-partial-folders",
        "cli",
        "jaxvs check",
        "--out whose .o.partial-PID folders were left by a killed run (and one of a live process)",
        cli(_stale_partials, (0, 3)),
        exc=None,
        check=_stale_cleaned,
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)


def test_the_matrix_is_large():
    assert len(CASES) >= 80, len(CASES)


# --- the real process: one line, exit code 2, no traceback -----------------------------------


@pytest.mark.parametrize(
    "args, match",
    [
        (["diagnose", "nope.csv", "--family", "drive", "--out", "o"], r"no such file"),
        (["design", "run.csv", "--target", "u", "--out", "run.csv"], r"is a file"),
        (["check", "semi.csv", "--family", "drive"], r"--delimiter ';'"),
        (["diagnose", "run.csv", "--family", "drive", "--out", "o", "--max-effects", "0"], ">= 1"),
    ],
    ids=["missing-file", "out-is-file", "semicolon", "max-effects-0"],
)
def test_process_prints_one_line_and_exits_2(args, match, tmp_path):
    drive_csv(tmp_path)
    drive_csv(tmp_path, "semi.csv", sep=";")
    with pytest.raises(CliExit) as info:
        run_cli(args, tmp_path, timeout=120)
    assert info.value.code == 2
    lines = info.value.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxvs: error: "), info.value.stderr
    assert re.search(match, lines[0])
    assert not (tmp_path / "o").exists()


def test_debug_shows_the_traceback(tmp_path):
    with pytest.raises(CliExit) as info:
        args = ["check", drive_csv(tmp_path, sep=";"), "--family", "drive", "--debug"]
        run_main(args, tmp_path, strict=False)
    assert "Traceback" in info.value.stderr  # --debug: the traceback, then the one line
    assert info.value.stderr.strip().splitlines()[-1].startswith("jaxvs: error: ")
