"""The design report: the content of `report.json` (docs/guides/design.md), `report.md`,
a self-contained `report.html`, the figures and `best.eqx`, written atomically."""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import shutil
import tempfile
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..._html import markdown_to_html, report_html
from ..._io import save_model
from ..._json_section import ReportContent
from ..._misc import json_safe

__all__ = ["SCHEMA_VERSION", "DesignContent", "DesignReport"]

SCHEMA_VERSION = 1
"""`schema_version` of the design `report.json` (raised when a key is removed or changes
meaning)."""


def _fmt(v: Any, nd: int = 4) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.{nd}g}"
    return str(v)


def _describe(d: dict) -> str:
    delays = ", ".join(f"{k}{list(v) if list(v) != [0] else ''}" for k, v in d["delays"].items())
    extra = ", quadratic" if d.get("quadratic") else ""
    if d.get("hidden"):
        extra = f", {d['hidden']} hidden"
    if d.get("order"):
        extra += f", order {d['order']}"
    if d.get("time_constant_s"):
        extra += f", τ = {d['time_constant_s']:.4g} s"
    return f"{d['structure']} ({delays}{extra})"


@dataclasses.dataclass(frozen=True)
class DesignContent(ReportContent):
    """The content of the design `report.json`, typed (docs/guides/design.md).

    `target`, `metric`, `designs` (ranked, best first: rank, structure, inputs, delays,
    hidden, validation {rmse, r2, mapd, rmse_interval}, calibration, parameters,
    seconds, residual checks for the top 25), `best` (the first design, `None` without
    one), `baseline`, `best_rank_by_structure` and `bootstrap` (when designs were
    ranked), `not_identifiable` (why no design is suggested, when none is),
    `candidates_evaluated`, `coverage`, `interrupted`, `input_ranking`,
    `forward_selection`, `data` (split, sparse-target resampling), `warnings`, `check`,
    `timing` and `figures` (the figure files, when drawn). A field that is `None` where
    the list says "when" is left out of the JSON.

    `to_json()` writes `report.json` (with `schema_version`): `_json()` is the one place
    its keys are written; `from_json` reads a saved one back. Reads like the dictionary
    it writes (`content["best"]["validation"]`), for compatibility;
    `content["figures"] = names` sets the figures, the one field filled after the report
    is built.
    """

    target: str
    metric: str = "rmse"
    designs: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    best: dict[str, Any] | None = None
    baseline: dict[str, Any] = dataclasses.field(default_factory=dict)
    best_rank_by_structure: dict[str, int] | None = None
    bootstrap: dict[str, Any] | None = None
    not_identifiable: str | None = None
    candidates_evaluated: int = 0
    coverage: dict[str, Any] = dataclasses.field(default_factory=dict)
    interrupted: bool = False
    input_ranking: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    forward_selection: dict[str, Any] = dataclasses.field(default_factory=dict)
    data: dict[str, Any] = dataclasses.field(default_factory=dict)
    warnings: list[str] = dataclasses.field(default_factory=list)
    check: dict[str, Any] | None = None
    timing: dict[str, Any] = dataclasses.field(default_factory=dict)
    figures: list[str] | None = None

    def _json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "target": self.target,
            "metric": self.metric,
            "designs": list(self.designs),
            "best": self.best,
            "baseline": self.baseline,
        }
        if self.best_rank_by_structure is not None:
            out["best_rank_by_structure"] = self.best_rank_by_structure
        if self.bootstrap is not None:
            out["bootstrap"] = self.bootstrap
        if self.not_identifiable is not None:
            out["not_identifiable"] = self.not_identifiable
        out |= {
            "candidates_evaluated": self.candidates_evaluated,
            "coverage": self.coverage,
            "interrupted": self.interrupted,
            "input_ranking": list(self.input_ranking),
            "forward_selection": self.forward_selection,
            "data": self.data,
            "warnings": list(self.warnings),
            "check": self.check,
            "timing": self.timing,
        }
        if self.figures is not None:
            out["figures"] = list(self.figures)
        return out

    def to_json(self) -> dict[str, Any]:
        """`report.json`: the content with its `schema_version`, JSON-ready."""
        return {"schema_version": SCHEMA_VERSION, **json_safe(self._json())}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DesignContent:
        """The content of a saved `report.json` (or the dictionary a design builds)."""
        written = data.get("schema_version", SCHEMA_VERSION)
        if not isinstance(written, int) or written > SCHEMA_VERSION:
            raise ValueError(
                f"this design report.json has schema_version {written!r}, newer than the "
                f"{SCHEMA_VERSION} this version of jaxvs reads; upgrade jaxvs to read it."
            )
        figures = data.get("figures")
        return cls(
            target=data["target"],
            metric=data.get("metric", "rmse"),
            designs=list(data.get("designs") or []),
            best=data.get("best"),
            baseline=dict(data.get("baseline") or {}),
            best_rank_by_structure=data.get("best_rank_by_structure"),
            bootstrap=data.get("bootstrap"),
            not_identifiable=data.get("not_identifiable"),
            candidates_evaluated=int(data.get("candidates_evaluated", 0)),
            coverage=dict(data.get("coverage") or {}),
            interrupted=bool(data.get("interrupted", False)),
            input_ranking=list(data.get("input_ranking") or []),
            forward_selection=dict(data.get("forward_selection") or {}),
            data=dict(data.get("data") or {}),
            warnings=list(data.get("warnings") or []),
            check=data.get("check"),
            timing=dict(data.get("timing") or {}),
            figures=None if figures is None else list(figures),
        )


@dataclasses.dataclass(frozen=True)
class DesignReport:
    """The result of [`jaxvs.design`][]: `content` (a `DesignContent`, the typed
    `report.json`), plus the best design as a ready virtual sensor and the held-out
    predictions behind the figures.

    **Fields (JSON, `content`):** `target`, `metric`, `designs` (ranked, best first: rank,
    structure, inputs, delays, hidden, validation {rmse, r2, mapd, rmse_interval},
    calibration, parameters, seconds, residual checks for the top 25), `best`,
    `baseline`, `candidates_evaluated`, `coverage`, `interrupted`, `input_ranking`,
    `forward_selection`, `data` (split, sparse-target resampling), `warnings`, `timing`.
    `to_json()` writes them; `from_json` reads a saved `report.json` back;
    `report["key"]` reads a field like the dictionary of `report.json` (compatibility).

    **Fields (Python only):** `best_model` (a `DesignedSensor`, `None` if no design could
    be fitted), `predictions` (rank -> `(time,)` prediction of the top 5 on all samples),
    `arrays` (`t`, `y`, `measured`, `role`, `raw_target`).

    `DesignReport(content=...)` also takes the content as a dictionary.
    """

    content: DesignContent
    best_model: Any = dataclasses.field(default=None, repr=False, compare=False)
    predictions: dict[int, np.ndarray] = dataclasses.field(
        default_factory=dict, repr=False, compare=False
    )
    arrays: dict[str, np.ndarray] = dataclasses.field(
        default_factory=dict, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if not isinstance(self.content, DesignContent):
            object.__setattr__(self, "content", DesignContent.from_json(self.content))

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DesignReport:
        """A report read back from its `report.json` (the JSON only: no model or
        predictions)."""
        return cls(DesignContent.from_json(data))

    def __getitem__(self, key: str) -> Any:
        return self.content[key]

    @property
    def designs(self) -> list[dict]:
        return self.content.designs

    @property
    def best(self) -> dict | None:
        return self.content.best

    def to_json(self) -> dict[str, Any]:
        """`report.json`: the content with its `schema_version`, JSON-ready."""
        return self.content.to_json()

    def to_markdown(self) -> str:
        c = self.content._json()
        lines = [f"# Virtual-sensor design: {c['target']}", ""]
        d = c["data"]
        lines += [
            f"{d['experiments']} experiment(s), {d['samples']} samples every {d['dt']:.4g} s. "
            f"Held out: {d['holdout']}; {d['stopping_block']}.",
            "",
        ]
        if d.get("sparse_target"):
            s = d["sparse_target"]
            lines += [
                f"**Sparse target**: {s['measured_samples']} measurements on a grid of "
                f"{s['grid_samples']} samples, resampled by {s['method']} "
                f"({s['segments']} segments; the laws miss the measurements by "
                f"{s['law_rmse_at_measurements']:.3g} RMS). Designs are trained on the "
                f"resampled target and scored on the {s['scored_on']}.",
                "",
            ]
        for w in c["warnings"]:
            lines += [f"> **Warning:** {w}", ""]
        cov = c["coverage"]
        lines += [
            f"Evaluated {cov['evaluated']} of {cov['total']} candidate designs"
            + (f" (stopped by {cov['stopped_by']})" if cov["stopped_by"] else "")
            + f" in {c['timing']['seconds']:.1f} s.",
            "",
        ]
        if c.get("not_identifiable"):
            lines += [f"**No design suggested:** {c['not_identifiable']}", ""]
        if c["designs"]:
            b = c["best"]
            bv = b["validation"]
            lines += [
                "## Suggestion",
                "",
                f"**{_describe(b)}** on {', '.join(b['inputs'])}: held-out RMSE "
                f"{bv['rmse']:.4g} (95 % interval {_fmt(bv['rmse_interval'][0])}"
                f"–{_fmt(bv['rmse_interval'][1])}), R² {_fmt(bv['r2'])}, "
                f"MAPD {_fmt(b['validation']['mapd'], 3)} %, {b['parameters']} parameters. "
                f"Baseline (regression on {', '.join(c['baseline']['inputs'])}): RMSE "
                f"{_fmt((c['baseline']['validation'] or {}).get('rmse'))}.",
                "",
            ]
            if b.get("preferred_over"):
                p = b["preferred_over"]
                lines += [
                    f"Preferred over a {p['structure']} design with {p['parameters']} "
                    f"parameters and RMSE {p['rmse']:.4g}: {p['reason']}.",
                    "",
                ]
            lines += [
                "These are suggestions: check the residual columns and the figures before "
                "you deploy one.",
                "",
                "## Ranked designs (top 15)",
                "",
                "| rank | design | inputs | params | held-out RMSE [95 %] | R² | MAPD % | "
                "calib. RMSE | white | largest input xcorr |",
                "|---:|---|---|---:|---|---:|---:|---:|---|---|",
            ]
            for e in c["designs"][:15]:
                v = e["validation"]
                r = e.get("residuals", {})
                xc = {k: x for k, x in (r.get("input_xcorr") or {}).items() if x is not None}
                big = max(xc, key=xc.get) if xc else None
                lines.append(
                    f"| {e['rank']} | {_describe(e)} | {', '.join(e['inputs'])} | "
                    f"{e['parameters']} | {v['rmse']:.4g} "
                    f"[{_fmt(v['rmse_interval'][0])}, {_fmt(v['rmse_interval'][1])}] | "
                    f"{_fmt(v['r2'])} | {_fmt(v['mapd'], 3)} | {_fmt(e['calibration']['rmse'])} | "
                    f"{'yes' if r.get('white') else 'no' if r.get('white') is False else '–'} | "
                    + (f"{big} {xc[big]:.2f}" if big else "–")
                    + " |"
                )
            lines.append("")
            lines += ["## Best design per structure", ""]
            lines += ["| structure | rank | held-out RMSE | params |", "|---|---:|---:|---:|"]
            for s, rank in c["best_rank_by_structure"].items():
                e = c["designs"][rank - 1]
                lines.append(
                    f"| {s} | {rank} | {e['validation']['rmse']:.4g} | {e['parameters']} |"
                )
            lines.append("")
        lines += [
            "## Inputs",
            "",
            "| input | correlation | partial corr. | mRMR score | redundant | selected |",
            "|---|---:|---:|---:|---|---|",
        ]
        for r in c["input_ranking"]:
            lines.append(
                f"| {r['name']} | {_fmt(r['correlation'], 3)} | "
                f"{_fmt(r['partial_correlation'], 3)} | "
                f"{_fmt(r['relevance_redundancy_score'], 3)} | {r['redundant']} | "
                f"{'yes' if r.get('selected') else 'pool' if r.get('in_pool') else ''} |"
            )
        lines.append("")
        lines.append(
            "Forward selection (blocked cross-validation RMSE on the calibration data, "
            "normalised target):"
        )
        lines.append("")
        for k, s in enumerate(c["forward_selection"]["steps"], start=1):
            lines.append(
                f"{k}. best {s['best']}: {s['rmse_before']:.4g} -> {s['rmse_after']:.4g} "
                f"(P(better) = {s['p_better']:.2f}) {'accepted' if s['accepted'] else 'rejected'}"
            )
        lines.append("")
        if c.get("figures"):
            lines += ["## Figures", ""] + [f"![{f}]({f})" for f in c["figures"]] + [""]
        return "\n".join(lines)

    def to_html(self, folder: pathlib.Path | None = None) -> str:
        """A self-contained HTML page: the markdown report with the figures in `folder`
        embedded."""
        return report_html(self.to_markdown(), folder, f"jaxvs design: {self.content.target}")

    def _repr_html_(self) -> str:
        return markdown_to_html(self.to_markdown())

    def save(
        self,
        out: str | os.PathLike,
        *,
        figures: Callable[[DesignReport, pathlib.Path], list[str]] | None = None,
    ) -> pathlib.Path:
        """Write `report.json`, `report.md`, `report.html` and `best.eqx` (the best
        design, for `jaxvs.load_model`) to the folder `out`, atomically: into a temporary
        folder beside it, then renamed (an existing `out` is replaced only once the new one
        is complete).

        **Arguments:**

        - `out`: the report folder.
        - `figures`: draws the figures into the folder and returns their file names, e.g.
          `jaxvs.plotting.plot_design`; they are embedded in `report.html`. Without it the
          report has no figures (the library does not draw; plotting is its caller's).
        """
        if isinstance(figures, bool) or not (figures is None or callable(figures)):
            raise TypeError(
                f"figures must be a drawing function such as jaxvs.plotting.plot_design or "
                f"None, got {figures!r}; for the figures write `from jaxvs.plotting import "
                "plot_design` and report.save(out, figures=plot_design)."
            )
        out = pathlib.Path(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = pathlib.Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
        try:
            if figures is not None and self.content.designs:
                self.content["figures"] = list(figures(self, tmp))
            if self.best_model is not None:
                save_model(
                    tmp / "best.eqx",
                    self.best_model,
                    metadata={"target": self.content.target, "best": json_safe(self.best)},
                )
            (tmp / "report.json").write_text(json.dumps(self.to_json(), indent=2) + "\n")
            (tmp / "report.md").write_text(self.to_markdown())
            (tmp / "report.html").write_text(self.to_html(tmp))
            if out.exists():
                old = pathlib.Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
                os.rename(out, old / "x")
                os.rename(tmp, out)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.rename(tmp, out)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return out
