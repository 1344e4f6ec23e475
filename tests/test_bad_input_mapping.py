"""Bad-input matrix, a user's own column names: `jaxvs.data.rename_signals`, `signals=` of
`jaxvs.diagnose` / `jaxvs.check`, and `--signal NAME=COLUMN` / `--time COLUMN` of the
command line. A file written with its own names ("時間 (s)", "Position [mm]", "Torque") is
read without rewriting it; a missing canonical signal's error lists the file's columns and
shows the mapping."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bad_input import Case, CliExit, run_case
from test_bad_input_cli import DT, N, _drive_columns, run_main, write_csv

import jaxvs
from jaxvs.data import load_renamed, rename_signals

# the drive columns under a user's names, the position in mm
_OWN = ["時間 (s)", "Position [mm]", "Torque [N]", "Sollwert [mm]"]


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    monkeypatch.setenv("JAXVS_NO_CACHE", "1")  # the in-process command: no cache folder


def own_csv(tmp: Path) -> Path:
    c = _drive_columns()
    columns = {"time": c["t"], "q": 1e3 * c["q"], "u": c["u"], "r": 1e3 * c["r"]}
    return write_csv(tmp / "own.csv", columns, header=",".join(_OWN))


def own_record(tmp: Path) -> jaxvs.data.Record:
    return jaxvs.data.load(own_csv(tmp), dt=DT)  # time read as a signal: "時間" [s]


MAPPING = {"q": "Position", "u": "Torque [N]", "r": "Sollwert"}


def _python(id, input, run, exc=ValueError, match="", check=None) -> Case:
    entry = "jaxvs.data.rename_signals" if "rename" in id else "jaxvs.diagnose"
    return Case(id=id, area="mapping", entry=entry, input=input, run=run, exc=exc,
                match=match, check=check)


def _cli(id, input, args, match) -> Case:
    return Case(
        id=id,
        area="cli",
        entry="jaxvs check",
        input=input,
        run=lambda tmp: run_main(["check", own_csv(tmp), "--family", "drive", *args], tmp),
        exc=CliExit,
        match=match,
        exit_code=2,
    )


def _mapped(record) -> None:
    # the columns under the canonical names, the position converted from mm, the time axis
    # from the user's time column
    expect = _drive_columns()
    assert set(record.names) >= {"q", "u", "r"}
    np.testing.assert_allclose(record["q"], expect["q"], rtol=1e-12)
    np.testing.assert_allclose(record.t, expect["t"], rtol=0, atol=1e-12)
    assert record.units["q"] == "m"


def _checked(result) -> None:
    code, out, _ = result
    assert code in (0, 3), code  # an answer, not a refusal
    assert f"| {N} |" in out, out  # every row was read


CASES: list[Case] = [
    _python(
        "rename-column-absent",
        "a mapping to a column the record does not hold",
        lambda tmp: rename_signals(own_record(tmp), {"q": "Pos"}),
        match=r"'Pos' mapped to 'q' is not in the data; its columns are \['時間', 'Position'",
    ),
    _python(
        "rename-column-twice",
        "one column mapped to two names",
        lambda tmp: rename_signals(own_record(tmp), {"q": "Position", "r": "Position [mm]"}),
        match=r"column 'Position \[mm\]' is mapped twice.*map each column to one name",
    ),
    _python(
        "rename-name-taken",
        "a new name that another column already has",
        lambda tmp: rename_signals(own_record(tmp), {"Torque": "Position"}),
        match=r"two columns would be named 'Torque'.*Map that one to another name",
    ),
    _python(
        "rename-not-a-mapping",
        "signals given as a list of names",
        lambda tmp: rename_signals(own_record(tmp), ["q", "u"]),
        exc=TypeError,
        match=r"signals must be a mapping \{canonical name: column name\}",
    ),
    _python(
        "rename-time-not-time",
        "a position column given as the time column",
        lambda tmp: rename_signals(own_record(tmp), MAPPING, time="Torque"),
        match=r"time column 'Torque' is in 'N', not a time",
    ),
    _python(
        "rename-own-names",
        "a record with its own column names and a separate time column",
        lambda tmp: rename_signals(own_record(tmp), MAPPING, time="時間 (s)"),
        exc=None,
        check=_mapped,
    ),
    _python(
        "load-renamed-own-names",
        "a CSV file with its own column names, the time column '時間 (s)'",
        lambda tmp: load_renamed(own_csv(tmp), {**MAPPING, "t": "時間 (s)"}),
        exc=None,
        check=_mapped,
    ),
    _python(
        "diagnose-own-time-unmapped",
        "a CSV whose time column is '時間 (s)', no mapping",
        lambda tmp: jaxvs.diagnose(own_csv(tmp), family="drive"),
        match=r"no time column 't'; columns found: .*'時間'.*signals=\{'t': '<column>'\}.*"
        r"--time <column>",
    ),
    _python(
        "diagnose-own-names-unmapped",
        "a CSV with its own column names, only the time column mapped",
        lambda tmp: jaxvs.diagnose(own_csv(tmp), family="drive", signals={"t": "時間"}),
        match=r"lacks the required signal\(s\) \['q', 'u'\].*columns are.*'Position'.*"
        r"signals=\{'q': '<column>'.*--signal q=<column>",
    ),
    _cli(
        "check-own-names-unmapped",
        "a CSV with its own column names and no --signal",
        ["--time", "時間"],
        r"lacks the required signal.*'Position'.*--signal q=<column>",
    ),
    _cli(
        "check-signal-no-equals",
        "--signal q (no column)",
        ["--signal", "q", "--time", "時間"],
        r"--signal expects NAME=COLUMN such as q=Position",
    ),
    _cli(
        "check-signal-absent-column",
        "--signal q=Pos, a column the file does not have",
        ["--signal", "q=Pos", "--signal", "u=Torque", "--time", "時間"],
        r"own\.csv: .*'Pos' mapped to 'q' is not in the data; its columns are",
    ),
    _cli(
        "check-signal-twice",
        "--signal q=... given twice",
        ["--signal", "q=Position", "--signal", "q=Torque", "--time", "時間"],
        r"--signal q is given twice; keep one",
    ),
    _cli(
        "check-time-twice",
        "--time and --signal t=... together",
        ["--signal", "t=時間", "--time", "時間"],
        r"--time names the time column once",
    ),
    Case(
        id="check-own-names-mapped",
        area="cli",
        entry="jaxvs check",
        input="--signal q=Position --signal u=Torque --time 時間 on a file with its own names",
        run=lambda tmp: run_main(
            ["check", own_csv(tmp), "--family", "drive", "--signal", "q=Position",
             "--signal", "u=Torque [N]", "--signal", "r=Sollwert", "--time", "時間 (s)"],
            tmp,
            ok=(0, 3),
        ),
        exc=None,
        check=_checked,
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)


def test_check_signals_equals_renamed_record(tmp_path):
    # `signals=` of the Python face is the same as renaming the record first
    rec = rename_signals(own_record(tmp_path), MAPPING, time="時間")
    a = jaxvs.check(rec, family="drive").content
    b = jaxvs.check(own_csv(tmp_path), family="drive", signals={**MAPPING, "t": "時間"}).content
    assert a["blocking"] == b["blocking"] and a["warnings"] == b["warnings"]
