"""The typed reports write `report.json` exactly as the dictionary reports did, and read
a saved one back.

The oracle is `tests/data/reports/`: the `report.json` (stored without indentation) and
`report.md` that the dictionary reports wrote for six small runs — `jaxvs check` on a
drive record moving both ways and one moving one way only, `jaxvs diagnose` on that
one-way record (no verdict) and on a three-hour thermal record with a hidden heat
capacity (`max_effects=1`, `n_boot=50`, `n_null=4`, with two figure names set), `jaxvs
design` on an eight-hour thermal record (regression and lag, `max_delay=1`) and on data
without a varying input (refused). Each is read back with `from_json` and must write
the same JSON, key order included, and the same Markdown. The three fast runs are run
again and compared field by field (floats to 1e-12 relative, run times left out).

To regenerate after an intended change of the numbers or of the schema: run this file
as a script (`python tests/test_report_schema.py`); it rewrites the goldens of the
three fast runs (the others keep testing the reading back).
"""

import dataclasses
import json
import math
import pathlib
import subprocess
import sys

import pytest
from test_html_reports import drive_record  # the record the html report tests check

import jaxvs
from jaxvs.diagnosis._check import CheckReport
from jaxvs.diagnosis._report import DiagnosisReport, Verdict
from jaxvs.studies.design._report import DesignReport

GOLDEN = pathlib.Path(__file__).parent / "data" / "reports"
KINDS = {"check": CheckReport, "diagnose": DiagnosisReport, "design": DesignReport}
NAMES = sorted(p.stem for p in GOLDEN.glob("*.json"))


FAST_RUNS = {
    "check_drive": lambda: jaxvs.check(drive_record(), family="drive"),
    "check_drive_oneway": lambda: jaxvs.check(
        drive_record(both_ways=False, clip=20.0), family="drive"
    ),
    "diagnose_drive_oneway": lambda: jaxvs.diagnose(
        drive_record(both_ways=False, clip=20.0), family="drive"
    ),
}


def golden(name: str) -> dict:
    return json.loads((GOLDEN / f"{name}.json").read_text())


def differences(a, b, path="", skip=("timing", "seconds")) -> list[str]:
    """Where two JSON values differ: keys, lengths, strings, booleans and integers
    exactly, floats to 1e-12 relative; the run times (`skip`) are left out."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [] if list(a) == list(b) else [f"{path}: keys {list(a)} != {list(b)}"]
        for k in a.keys() & b.keys():
            if k not in skip:
                out += differences(a[k], b[k], f"{path}.{k}", skip)
        return out
    if isinstance(a, list) and isinstance(b, list):
        out = [] if len(a) == len(b) else [f"{path}: length {len(a)} != {len(b)}"]
        for i, (x, y) in enumerate(zip(a, b)):
            out += differences(x, y, f"{path}[{i}]", skip)
        return out
    if isinstance(a, float) or isinstance(b, float):
        numbers = all(isinstance(x, int | float) and not isinstance(x, bool) for x in (a, b))
        if numbers and math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0):
            return []
        return [f"{path}: {a!r} != {b!r}"]
    return [] if (type(a), a) == (type(b), b) else [f"{path}: {a!r} != {b!r}"]


@pytest.mark.parametrize("name", NAMES)
def test_saved_report_reads_back_and_writes_the_same_files(name):
    """`from_json(report.json)` writes the same `report.json` (key order included) and
    the same `report.md` as the dictionary report that wrote them."""
    data = golden(name)
    rep = KINDS[name.split("_")[0]].from_json(data)
    out = rep.to_json()
    assert json.dumps(out, indent=2) == json.dumps(data, indent=2)
    assert rep.to_markdown() == (GOLDEN / f"{name}.md").read_text()
    # and once more through the typed object: a fixed point
    assert KINDS[name.split("_")[0]].from_json(out).to_json() == out


@pytest.mark.parametrize("name", sorted(FAST_RUNS))
def test_report_json_is_what_the_dictionary_reports_wrote(name):
    """The typed reports of the same runs write the keys and values of the goldens."""
    out = json.loads(json.dumps(FAST_RUNS[name]().to_json()))
    assert differences(out, golden(name)) == []


def test_the_sections_are_typed_and_read_like_dictionaries():
    rep = DiagnosisReport.from_json(golden("diagnose_thermal"))
    v = rep.verdict
    assert isinstance(v, Verdict) and v.status == rep.status == "explained"
    # the dictionary access of earlier versions reads the typed fields
    assert rep["verdict"]["status"] == v["status"] == v.status
    assert rep.verdict["effects"] == v.effects == ["dynamics"]
    assert rep.gap["validation"] == rep.gap.validation == rep.content.gap.validation
    assert rep.content.get("discovered") is None and "where_after" in rep.content
    assert dict(rep.content) == {k: x for k, x in rep.to_json().items() if k != "schema_version"}
    assert repr(rep).splitlines()[1] == rep.status_line == v.status_line
    check = rep.content.check
    assert check.jacobian is not None and check.jacobian.condition >= 1.0
    assert check.jacobian["parameters"] == check.jacobian.parameters
    # frozen: a field cannot be reassigned; only the figures are set after the build
    with pytest.raises(dataclasses.FrozenInstanceError):
        rep.content.verdict = None
    with pytest.raises(TypeError, match="frozen"):
        rep.content["verdict"] = None
    rep.content["figures"] = ["a.png"]
    assert rep.to_json()["figures"] == ["a.png"] and list(rep.to_json())[-1] == "figures"


def test_a_report_without_verdict_and_a_refused_design_keep_their_keys():
    """No search, no `distortion`, `where_after`, `pruning`, `discovered`; a refused
    design has `not_identifiable` and no `bootstrap`; a design report without figures
    has no `figures` key."""
    rep = DiagnosisReport.from_json(golden("diagnose_drive_oneway"))
    assert rep.verdict is None and rep.status is None
    assert not {"distortion", "where_after", "pruning", "discovered"} & set(rep.to_json())
    assert rep.status_line.startswith("verdict: none")
    design = DesignReport.from_json(golden("design_refused"))
    assert design.designs == [] and design.best is None
    assert "no candidate input" in design["not_identifiable"]
    assert {"bootstrap", "figures"}.isdisjoint(design.to_json())
    assert CheckReport.from_json(golden("check_drive_oneway")).exit_code == 3


def test_a_newer_schema_is_refused():
    data = {**golden("check_drive"), "schema_version": 99}
    with pytest.raises(ValueError, match="schema_version 99.*upgrade jaxvs"):
        CheckReport.from_json(data)
    with pytest.raises(ValueError, match="upgrade jaxvs"):
        DiagnosisReport.from_json({**golden("diagnose_thermal"), "schema_version": 3})


def test_design_save_does_not_import_the_plotting(tmp_path):
    """The library does not draw: saving a design report without figures leaves
    `jaxvs.plotting` (and matplotlib) unimported."""
    code = (
        "import json, sys\n"
        "from jaxvs.studies.design._report import DesignReport\n"
        f"data = json.loads(open({str(GOLDEN / 'design_thermal.json')!r}).read())\n"
        f"DesignReport.from_json(data).save({str(tmp_path / 'out')!r})\n"
        "print(sorted(m for m in sys.modules if m.startswith(('jaxvs.plotting', 'matplotlib'))))\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"
    saved = json.loads((tmp_path / "out" / "report.json").read_text())
    assert saved == golden("design_thermal")


if __name__ == "__main__":  # rewrite the goldens of the fast runs
    import jax

    jax.config.update("jax_enable_x64", True)
    for name, run in FAST_RUNS.items():
        rep = run()
        text = json.dumps(rep.to_json(), separators=(",", ":"), ensure_ascii=False)
        (GOLDEN / f"{name}.json").write_text(text + "\n")
        (GOLDEN / f"{name}.md").write_text(rep.to_markdown())
