"""The design report: the content of `report.json` (docs/guides/design.md), `report.md`,
a self-contained `report.html`, the figures and `best.eqx`, written atomically."""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import shutil
import tempfile
from collections.abc import Callable
from typing import Any

import numpy as np

from ..._html import markdown_to_html, report_html
from ..._io import save_model
from ..._misc import json_safe

__all__ = ["SCHEMA_VERSION", "DesignReport"]

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


@dataclasses.dataclass
class DesignReport:
    """The result of [`jaxvs.design`][]: everything `report.json` holds, plus the best
    design as a ready virtual sensor and the held-out predictions behind the figures.

    **Fields (JSON, `content`):** `target`, `metric`, `designs` (ranked, best first: rank,
    structure, inputs, delays, hidden, validation {rmse, r2, mapd, rmse_interval},
    calibration, parameters, seconds, residual checks for the top 25), `best`,
    `baseline`, `candidates_evaluated`, `coverage`, `interrupted`, `input_ranking`,
    `forward_selection`, `data` (split, sparse-target resampling), `warnings`, `timing`.

    **Fields (Python only):** `best_model` (a `DesignedSensor`, `None` if no design could
    be fitted), `predictions` (rank -> `(time,)` prediction of the top 5 on all samples),
    `arrays` (`t`, `y`, `measured`, `role`, `raw_target`).
    """

    content: dict[str, Any]
    best_model: Any = None
    predictions: dict[int, np.ndarray] = dataclasses.field(default_factory=dict)
    arrays: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)

    def __getitem__(self, key: str) -> Any:
        return self.content[key]

    @property
    def designs(self) -> list[dict]:
        return self.content["designs"]

    @property
    def best(self) -> dict | None:
        return self.content["best"]

    def to_json(self) -> dict[str, Any]:
        """`report.json`: the content with its `schema_version`, JSON-ready."""
        return {"schema_version": SCHEMA_VERSION, **json_safe(self.content)}

    def to_markdown(self) -> str:
        c = self.content
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
        return report_html(self.to_markdown(), folder, f"jaxvs design: {self.content['target']}")

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
            if figures is not None and self.content["designs"]:
                self.content["figures"] = list(figures(self, tmp))
            if self.best_model is not None:
                save_model(
                    tmp / "best.eqx",
                    self.best_model,
                    metadata={"target": self.content["target"], "best": json_safe(self.best)},
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
