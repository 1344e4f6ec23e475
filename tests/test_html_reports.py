"""`report.html` of `jaxvs diagnose`, `jaxvs design` and `jaxvs check`, the notebooks'
`_repr_html_`, and the check that diagnose and design run first.

The HTML is parsed with the standard library's parser; the oracles are the report's own
files: every figure `report.md` references must be embedded byte for byte, every table
of `report.md` must be an HTML table with the same number of rows, and nothing may point
outside the file.
"""

import base64
import json
import re
from html.parser import HTMLParser

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import jaxvs
from jaxvs._cli import main
from jaxvs._html import figure, markdown_to_html, table
from jaxvs.data import Record, save_csv
from jaxvs.studies.design import DesignDataWarning
from jaxvs.twins import SpindleThermalTwin


class Page(HTMLParser):
    """What a browser would load: images, tables (rows of cell texts), collapsible
    sections, and every attribute that could fetch something."""

    def __init__(self, text: str):
        super().__init__()
        self.images: list[str] = []
        self.tables: list[list[list[str]]] = []
        self.details = 0
        self.summaries: list[str] = []
        self.fetching: list[tuple[str, str, str]] = []
        self.tags: set[str] = set()
        self._cell: list[str] | None = None
        self._row: list[str] | None = None
        self._summary: list[str] | None = None
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        self.tags.add(tag)
        for name, value in attrs:
            if name in ("src", "href", "data", "poster", "srcset", "action") and value:
                self.fetching.append((tag, name, value))
        if tag == "img":
            self.images.append(dict(attrs).get("src", ""))
        elif tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "details":
            self.details += 1
        elif tag == "summary":
            self._summary = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[-1].append(self._row)
            self._row = None
        elif tag == "summary" and self._summary is not None:
            self.summaries.append("".join(self._summary).strip())
            self._summary = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        if self._summary is not None:
            self._summary.append(data)


def markdown_tables(md: str) -> list[int]:
    """Body rows of each pipe table of a Markdown report (header and rule not counted)."""
    counts, run = [], 0
    for line in md.splitlines() + [""]:
        if line.startswith("|"):
            run += 1
        elif run:
            counts.append(run - 2)
            run = 0
    return counts


def assert_self_contained_report(folder, *, rounds=None):
    md = (folder / "report.md").read_text()
    page = Page((folder / "report.html").read_text())
    # every figure the Markdown references is embedded as the very PNG file
    figures = re.findall(r"!\[[^]]*\]\(([^)]+)\)", md)
    embedded = [base64.b64decode(s.split(",", 1)[1]) for s in page.images]
    for name in figures:
        assert (folder / name).read_bytes() in embedded, name
    assert len(page.images) == len(figures)
    # every table of the Markdown is there, populated, with no NaN where a number goes
    assert [len(t) - 1 for t in page.tables] == markdown_tables(md)
    for t in page.tables:
        assert len(t) >= 2, t  # a header and at least one row
        for row in t[1:]:
            for cell in row:
                assert not re.search(r"\b(nan|inf)\b", cell, re.I), (row, cell)
    # nothing is fetched from elsewhere: images are data: URIs, no scripts or stylesheets
    assert not {"script", "link", "iframe", "object", "embed"} & page.tags
    for tag, attr, value in page.fetching:
        assert value.startswith("data:image/png;base64,"), (tag, attr, value[:60])
    if rounds is not None:
        assert page.details == len(rounds) >= 1
        assert all(s.startswith(f"Round {r['round']}") for s, r in zip(page.summaries, rounds))
    return page


# ------------------------------------------------------------------------- diagnose


@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory):
    """A small thermal diagnosis (3 h at 5 s, a hidden heat capacity) with its figures."""
    from jaxvs.plotting import plot_diagnosis

    rec = SpindleThermalTwin(effects={"dynamics": 600.0}).experiment(
        jr.key(11), duration=3 * 3600.0
    )
    rep = jaxvs.diagnose(rec, family="thermal", max_effects=1, n_boot=50, n_null=4)
    out = tmp_path_factory.mktemp("diagnose")
    rep.content["figures"] = plot_diagnosis(rep, out)
    rep.save(out)
    return rep, out


@pytest.mark.slow
def test_diagnose_report_html(diagnosis):
    rep, out = diagnosis
    assert rep.verdict["effects"] == ["dynamics"]  # the report has a verdict to show
    content = json.loads((out / "report.json").read_text())
    page = assert_self_contained_report(out, rounds=content["rounds"])
    assert len(page.images) == 5  # the verdict, gap map, signatures, before/after, spectra
    # the candidates table holds the JSON's candidates, best first
    cand = next(t for t in page.tables if t[0][0] == "effect" and "testable" in t[0])
    assert [r[0] for r in cand[1:]] == [c["effect"] for c in content["candidates"]]
    # the notebook view: the same tables, no figures, no page shell
    nb = Page(rep._repr_html_())
    assert not nb.images and len(nb.tables) == len(page.tables) and "html" not in nb.tags


# ------------------------------------------------------------------------- design


@pytest.fixture(scope="module")
def design_report(tmp_path_factory):
    rec = SpindleThermalTwin(effects={"dynamics": 240.0}).experiment(
        jr.key(3), duration=8 * 3600.0, dt=60.0
    )
    rep = jaxvs.design(
        rec,
        target="T_bearing",
        inputs=["T_chassis", "v_m"],
        structures=("regression", "lag"),
        max_delay=1,
        progress=False,
    )
    from jaxvs.plotting import plot_design

    return rep, rep.save(tmp_path_factory.mktemp("design") / "out", figures=plot_design)


def test_design_report_html(design_report):
    rep, out = design_report
    assert rep.content["figures"]
    assert "check" in rep.content and not rep.content["check"]["blocking"]
    page = assert_self_contained_report(out)
    ranked = next(t for t in page.tables if t[0][:2] == ["rank", "design"])
    assert len(ranked) - 1 == min(15, len(rep.designs))
    assert float(ranked[1][4].split()[0]) == pytest.approx(rep.best["validation"]["rmse"], 1e-3)
    nb = Page(rep._repr_html_())
    assert not nb.images and len(nb.tables) == len(page.tables)


def test_design_refuses_data_without_a_varying_input(tmp_path):
    """Check first: no candidate input varies -> no search, `not_identifiable`, exit 3."""
    t = np.arange(400) * 30.0
    rec = Record(
        {
            "T_bearing": 20 + np.sin(t / 900.0),
            "v_m": np.full(t.size, 3000.0),
            "T_air": np.full(t.size, 21.0),
        },
        t=t,
    )
    with pytest.warns(DesignDataWarning, match="no change of operating point"):
        rep = jaxvs.design(rec, target="T_bearing", progress=False)
    assert rep.designs == [] and rep.best_model is None
    assert "no candidate input" in rep.content["not_identifiable"]
    path = save_csv(rec, tmp_path / "flat.csv")
    argv = ["design", str(path), "--target", "T_bearing", "--out", str(tmp_path / "o"), "--quiet"]
    with pytest.warns(DesignDataWarning):
        assert main(argv) == 3
    html = (tmp_path / "o" / "report.html").read_text()
    assert "no candidate input" in html


# ------------------------------------------------------------------------- check


def drive_record(*, both_ways=True, n=3000, fs=1000.0, clip=150.0):
    rng = np.random.default_rng(0)
    t = np.arange(n) / fs
    q = 0.01 * np.sin(2 * np.pi * 0.7 * t) + 0.004 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    if not both_ways:
        q = 0.2 * t + 0.0005 * np.sin(2 * np.pi * 3.1 * t)
    v = np.gradient(q, 1 / fs)
    u = 95.0 * np.gradient(v, 1 / fs) + 200.0 * v - 3.0 + 0.5 * rng.standard_normal(n)
    # a clipped force: a warning in the report while a few % of the samples sit at the
    # limit (9 % at 150 N), blocking when most of them do (one way at 20 N: 86 %)
    u = np.clip(u, -clip, clip)
    return Record({"q": q, "u": u}, dt=1 / fs, units={"q": "m", "u": "N"})


def test_check_report_html(tmp_path):
    path = save_csv(drive_record(), tmp_path / "run.csv")
    assert main(["check", str(path), "--family", "drive", "--out", str(tmp_path / "c")]) == 0
    page = assert_self_contained_report(tmp_path / "c")
    content = json.loads((tmp_path / "c" / "report.json").read_text())
    records = next(t for t in page.tables if t[0][0] == "record" and "samples" in t[0])
    assert records[1][1] == str(content["records"][0]["samples"]) == "3000"
    # the clipping warning of the JSON is in the page as a list item
    assert content["warnings"] and "sits at its minimum or maximum" in content["warnings"][0]
    assert "sits at its minimum or maximum" in (tmp_path / "c" / "report.html").read_text()
    nb = Page(jaxvs.check(drive_record(), family="drive")._repr_html_())
    assert len(nb.tables) == len(page.tables)


def test_diagnose_runs_the_check_first(tmp_path):
    """A drive moving one way only: the check blocks, diagnose writes no verdict, exit 3,
    the check's reason in report.json, report.md and report.html."""
    rep = jaxvs.diagnose(drive_record(both_ways=False, clip=20.0), family="drive")
    assert rep.content["verdict"] is None
    assert rep.content["not_identifiable"].startswith("jaxvs check:")
    assert "one direction only" in rep.content["not_identifiable"]
    assert rep.content["check"]["blocking"]
    path = save_csv(drive_record(both_ways=False, clip=20.0), tmp_path / "oneway.csv")
    out = tmp_path / "d"
    assert main(["diagnose", str(path), "--family", "drive", "--out", str(out), "--quiet"]) == 3
    content = json.loads((out / "report.json").read_text())
    assert content["verdict"] is None and "one direction only" in content["not_identifiable"]
    for name in ("report.md", "report.html"):
        assert "one direction only" in (out / name).read_text()
    # the clipped force (86 % at the limit) blocks too, beside the one-way motion
    assert "minimum or maximum" in content["not_identifiable"]


# ------------------------------------------------------------------------- building blocks


def test_repr_html_of_results():
    omega = np.linspace(1.0, 100.0, 200)
    H = 1.0 / ((1j * omega) ** 2 + 2 * 0.1 * 30 * (1j * omega) + 30.0**2)
    model, fit = jaxvs.fit_rational(omega, H, (0, 2))
    page = Page(fit._repr_html_())
    rows = dict((r[0], r[1]) for r in page.tables[0][1:])
    assert float(rows["relative error"]) == pytest.approx(float(fit.relative_error), rel=1e-3)
    assert "successful" in rows["result"]
    from jaxvs.calibration import EquationError
    from jaxvs.models import FirstOrder

    t = np.linspace(0, 4, 80)
    y = 2.0 + 3.0 * (1 - np.exp(-t / 0.7))
    guess = FirstOrder(T0=jnp.asarray(1.0), k=jnp.asarray(1.0), T1=jnp.asarray(1.0))
    curve = EquationError(lambda m, d: m(d["t"]) - d["y"])
    res = jaxvs.calibrate(guess, {"t": t, "y": y}, curve)
    page = Page(res._repr_html_())
    body = page.tables[0][1:]
    assert len(body) == 3
    values = [float(r[1]) for r in body]
    assert values == pytest.approx([2.0, 3.0, 0.7], rel=1e-3)  # 4 significant digits shown


def test_building_blocks():
    assert Page(table(("a", "b"), [(1, float("nan")), ("x", None)])).tables == [
        [["a", "b"], ["1", "—"], ["x", "—"]]
    ]
    with pytest.raises(ValueError, match="expected PNG"):
        figure(b"GIF89a")
    html = markdown_to_html("# T\n\n![f](absent.png)\n", folder=".")
    assert "figure absent.png is missing" in html
    sections = Page(
        markdown_to_html("## A\n\n### Round 1\n\ntext\n\n### Round 2\n\n| x |\n|---|\n| 1 |\n")
    )
    assert sections.details == 2 and sections.summaries == ["Round 1", "Round 2"]
