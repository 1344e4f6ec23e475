"""The gap report: the content of `report.json` (docs/guides/contracts.md), `report.md` and the
self-contained `report.html`."""

from __future__ import annotations

import dataclasses
import json
import pathlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._html import markdown_to_html, report_html
from .._json_section import JsonSection, ReportContent, section_json
from .._misc import json_safe
from ._base import Experiment, GapModel
from ._check import CheckContent
from ._gapmap import GapCell
from ._verdict import status_line

__all__ = [
    "SCHEMA_VERSION",
    "DataSummary",
    "DiagnosisContent",
    "DiagnosisReport",
    "ExperimentSize",
    "Gap",
    "Nominal",
    "Timing",
    "Verdict",
]

SCHEMA_VERSION = 2
"""`schema_version` of the diagnosis `report.json`: raised when a key is removed or changes
meaning (2: `verdict.status`, and `verdict.adequate` true only for that state); keys added
leave it unchanged."""


def _float(value: Any) -> float | None:
    """A float read back from `report.json` (non-finite ones are written as null)."""
    return None if value is None else float(value)


@dataclasses.dataclass(frozen=True)
class Gap(JsonSection):
    """The nominal model's gap: the metric, its value on the calibration and the
    validation experiments, the noise floor (the gap a perfect model leaves: the
    measurement noise, and the same from the white-noise estimate alone), the held-out
    gaps of the effect-free records of the null, and the target signal."""

    metric: str = "nrmse"
    calibration: float | None = None
    validation: float | None = None
    noise_floor: float | None = None
    noise_floor_white: float | None = None
    null_gaps: list[float] = dataclasses.field(default_factory=list)
    target: str | None = None

    def _json(self) -> dict[str, Any]:
        return {
            "metric": self.metric,
            "calibration": self.calibration,
            "validation": self.validation,
            "noise_floor": self.noise_floor,
            "noise_floor_white": self.noise_floor_white,
            "null_gaps": list(self.null_gaps),
            "target": self.target,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Gap:
        return cls(
            metric=data.get("metric", "nrmse"),
            calibration=_float(data.get("calibration")),
            validation=_float(data.get("validation")),
            noise_floor=_float(data.get("noise_floor")),
            noise_floor_white=_float(data.get("noise_floor_white")),
            null_gaps=list(data.get("null_gaps") or []),
            target=data.get("target"),
        )


@dataclasses.dataclass(frozen=True)
class Verdict(JsonSection):
    """What the search concludes: `status` (`adequate`, `explained`,
    `partly_explained` or `unexplained`; `None` in reports written before the states),
    the effects accepted in the order added and those of the final model, the `primary`
    one, the final model's validation and calibration gaps, the `shrink` of the held-out
    gap with its 95 % bootstrap interval, the remaining gap over the noise floor,
    `adequate` (true only for `adequate`), the `remainder` against the null (`gap`,
    `over_floor`, `null_p95`, `within_null`, `where`, ...), `searched` (false when the
    nominal model's gap already lay within the null and no candidate was tried), the
    final model's `parameters` (nominal and per effect) and the `status_line`."""

    status: str | None = None
    effects: list[str] = dataclasses.field(default_factory=list)
    final_effects: list[str] = dataclasses.field(default_factory=list)
    primary: str | None = None
    validation_gap: float | None = None
    calibration_gap: float | None = None
    shrink: float | None = None
    shrink_interval: list[float] = dataclasses.field(default_factory=list)
    remaining_over_noise: float | None = None
    adequate: bool | None = None
    remainder: dict[str, Any] | None = None
    searched: bool | None = None
    parameters: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)
    status_line: str | None = None

    def _json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "effects": list(self.effects),
            "final_effects": list(self.final_effects),
            "primary": self.primary,
            "validation_gap": self.validation_gap,
            "calibration_gap": self.calibration_gap,
            "shrink": self.shrink,
            "shrink_interval": list(self.shrink_interval),
            "remaining_over_noise": self.remaining_over_noise,
            "adequate": self.adequate,
            "remainder": self.remainder,
            "searched": self.searched,
            "parameters": self.parameters,
            "status_line": self.status_line,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Verdict:
        return cls(
            status=data.get("status"),
            effects=list(data.get("effects") or []),
            final_effects=list(data.get("final_effects") or []),
            primary=data.get("primary"),
            validation_gap=_float(data.get("validation_gap")),
            calibration_gap=_float(data.get("calibration_gap")),
            shrink=_float(data.get("shrink")),
            shrink_interval=list(data.get("shrink_interval") or []),
            remaining_over_noise=_float(data.get("remaining_over_noise")),
            adequate=data.get("adequate"),
            remainder=data.get("remainder"),
            searched=data.get("searched"),
            parameters=dict(data.get("parameters") or {}),
            status_line=data.get("status_line"),
        )


@dataclasses.dataclass(frozen=True)
class Nominal(JsonSection):
    """The nominal model in words and its calibrated parameters."""

    model: str
    parameters: dict[str, Any] = dataclasses.field(default_factory=dict)

    def _json(self) -> dict[str, Any]:
        return {"model": self.model, "parameters": self.parameters}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Nominal:
        return cls(model=data["model"], parameters=dict(data.get("parameters") or {}))


@dataclasses.dataclass(frozen=True)
class ExperimentSize(JsonSection):
    """An experiment of the diagnosis: its name and its number of samples."""

    name: str
    samples: int

    def _json(self) -> dict[str, Any]:
        return {"name": self.name, "samples": self.samples}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ExperimentSize:
        return cls(name=data["name"], samples=int(data["samples"]))


@dataclasses.dataclass(frozen=True)
class DataSummary(JsonSection):
    """The experiments of the diagnosis (prepared ones when the search ran), how the
    held-out ones were chosen and, when the search ran, the family's settings (`None`
    otherwise: the key is then left out)."""

    calibration: list[ExperimentSize] = dataclasses.field(default_factory=list)
    validation: list[ExperimentSize] = dataclasses.field(default_factory=list)
    holdout: str = ""
    options: dict[str, int | float | str] | None = None

    def _json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "calibration": [e._json() for e in self.calibration],
            "validation": [e._json() for e in self.validation],
            "holdout": self.holdout,
        }
        if self.options is not None:
            out["options"] = dict(self.options)
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DataSummary:
        opts = data.get("options")
        return cls(
            calibration=[ExperimentSize.from_json(e) for e in data.get("calibration", [])],
            validation=[ExperimentSize.from_json(e) for e in data.get("validation", [])],
            holdout=data.get("holdout", ""),
            options=None if opts is None else dict(opts),
        )


@dataclasses.dataclass(frozen=True)
class Timing(JsonSection):
    """The run time of the diagnosis."""

    seconds: float

    def _json(self) -> dict[str, Any]:
        return {"seconds": self.seconds}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Timing:
        return cls(seconds=float(data["seconds"]))


_UNSEARCHED_ORDER = ("check", "warnings", "family", "gap", "where", "candidates", "verdict")


@dataclasses.dataclass(frozen=True)
class DiagnosisContent(ReportContent):
    """The content of the diagnosis `report.json`, typed (docs/guides/contracts.md).

    `to_json()` writes `report.json` (with `schema_version`): `_json()` is the one place
    its keys are written. `from_json` reads a saved one back. A report without a
    `verdict` (the records cannot identify the nominal model) ran no search: it has no
    `distortion`, `where_after`, `pruning` or `discovered` key. `figures` (the figure
    files of the report folder) is written when set.

    Reads like the dictionary it writes (`content["verdict"]["status"]`), for
    compatibility; `content["figures"] = names` sets the figures, the one field filled
    after the report is built (by whoever draws them).
    """

    family: str
    gap: Gap | None = None
    not_identifiable: str | None = None
    distortion: dict[str, Any] | None = None
    check: CheckContent | None = None
    warnings: list[str] = dataclasses.field(default_factory=list)
    where: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    where_after: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    candidates: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    verdict: Verdict | None = None
    nominal: Nominal | None = None
    data: DataSummary | None = None
    rounds: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    pruning: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    timing: Timing | None = None
    discovered: dict[str, Any] | None = None
    figures: list[str] | None = None

    def _json(self) -> dict[str, Any]:
        searched = self.verdict is not None
        out: dict[str, Any] = {
            "family": self.family,
            "gap": section_json(self.gap),
            "not_identifiable": self.not_identifiable,
        }
        if searched:
            out["distortion"] = self.distortion
        out["check"] = section_json(self.check)
        out["warnings"] = list(self.warnings)
        out["where"] = list(self.where)
        if searched:
            out["where_after"] = list(self.where_after)
        out["candidates"] = list(self.candidates)
        out["verdict"] = section_json(self.verdict)
        out["nominal"] = section_json(self.nominal)
        out["data"] = section_json(self.data)
        out["rounds"] = list(self.rounds)
        if searched:
            out["pruning"] = list(self.pruning)
        out["timing"] = section_json(self.timing)
        if searched:
            out["discovered"] = self.discovered
        if self.figures is not None:
            out["figures"] = list(self.figures)
        if not searched:  # the key order these reports have always been written in
            out = {k: out[k] for k in _UNSEARCHED_ORDER if k in out} | out
        return out

    def to_json(self) -> dict[str, Any]:
        """`report.json`: the content with its `schema_version`, JSON-ready."""
        return {"schema_version": SCHEMA_VERSION, **json_safe(self._json())}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DiagnosisContent:
        """The content of a saved `report.json` (reports of earlier versions too: the
        keys they lack are read as missing)."""
        written = data.get("schema_version", SCHEMA_VERSION)
        if not isinstance(written, int) or written > SCHEMA_VERSION:
            raise ValueError(
                f"this diagnosis report.json has schema_version {written!r}, newer than "
                f"the {SCHEMA_VERSION} this version of jaxvs reads; upgrade jaxvs to read it."
            )

        def typed(key, kind):
            value = data.get(key)
            return None if value is None else kind.from_json(value)

        figures = data.get("figures")
        return cls(
            family=data["family"],
            gap=typed("gap", Gap),
            not_identifiable=data.get("not_identifiable"),
            distortion=data.get("distortion"),
            check=typed("check", CheckContent),
            warnings=list(data.get("warnings") or []),
            where=list(data.get("where") or []),
            where_after=list(data.get("where_after") or []),
            candidates=list(data.get("candidates") or []),
            verdict=typed("verdict", Verdict),
            nominal=typed("nominal", Nominal),
            data=typed("data", DataSummary),
            rounds=list(data.get("rounds") or []),
            pruning=list(data.get("pruning") or []),
            timing=typed("timing", Timing),
            discovered=data.get("discovered"),
            figures=None if figures is None else list(figures),
        )


@dataclasses.dataclass(frozen=True)
class DiagnosisReport:
    """The result of `jaxvs.diagnose`: `content` (a `DiagnosisContent`, the typed
    `report.json`), plus the models, experiments and predictions behind it (for figures
    and further work).

    **Fields (JSON, `content`):** `family`, `gap` (`metric`, `calibration`,
    `validation`, `noise_floor`), `where` (significant gap-map cells, most concentrated
    first), `candidates` (best first; each with `admissible`, `reason`, `null_p95`,
    `null_threshold`, `rejected_by`), `verdict` (`status`: `adequate`, `explained`,
    `partly_explained` or `unexplained`; `status_line`; `effects` in the order added,
    `final_effects`, `primary`, `validation_gap`, `shrink`, `shrink_interval`, `adequate`
    (true only for `adequate`), `remainder` (`gap`, `over_floor`, `null_p95`,
    `within_null`, `where`: the strongest cells of the final residual's gap map with
    their share and test); `None` when the record cannot identify the nominal model),
    `distortion` (records that repeat their excitation: the noise measured from period to
    period and the nonlinear distortion level, a finding when above the noise), `not_identifiable` (the
    reason, or `None`), `nominal`, `data`, `rounds`, `pruning` (every effect of the final
    model tested against the final model without it: `effect`, `effects`, `gap_without`,
    `gap_with`, `reduction`, `reduction_interval`, `shrink`, `delta_bic`,
    `null_threshold`, `kept`, `rejected_by`), `discovered` (the JSON of the discovery),
    `timing`. `to_json()` writes them; `from_json` reads a saved `report.json` back.
    The sections are read as attributes (`report.verdict.status`) or, for
    compatibility, like the dictionaries they write (`report["verdict"]["status"]`,
    `report.verdict["effects"]`).

    **Fields (Python only):** `nominal_model`, `final_model` (`GapModel`s),
    `calibration`, `validation` (`Experiment`s), `predictions` (per experiment, nominal
    and final), `cells` (the whole gap map), `discovered` (the `Discovery` of an effect
    outside the library, when it ran).

    `DiagnosisReport(content)` also takes the content as a dictionary (`report.json`'s).
    """

    content: DiagnosisContent
    nominal_model: GapModel | None = dataclasses.field(default=None, repr=False, compare=False)
    final_model: GapModel | None = dataclasses.field(default=None, repr=False, compare=False)
    calibration: list[Experiment] = dataclasses.field(
        default_factory=list, repr=False, compare=False
    )
    validation: list[Experiment] = dataclasses.field(
        default_factory=list, repr=False, compare=False
    )
    predictions: dict[str, list[np.ndarray]] = dataclasses.field(
        default_factory=dict, repr=False, compare=False
    )
    cells: list[GapCell] = dataclasses.field(default_factory=list, repr=False, compare=False)
    discovered: Any = dataclasses.field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.content, DiagnosisContent):
            object.__setattr__(self, "content", DiagnosisContent.from_json(self.content))

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DiagnosisReport:
        """A report read back from its `report.json` (the JSON only: no models,
        experiments or predictions)."""
        return cls(DiagnosisContent.from_json(data))

    # compatibility: the report reads like the dictionary of `report.json`
    def __getitem__(self, key: str) -> Any:
        return self.content[key]

    @property
    def family(self) -> str:
        return self.content.family

    @property
    def gap(self) -> Gap | None:
        return self.content.gap

    @property
    def where(self) -> list[dict[str, Any]]:
        return self.content.where

    @property
    def candidates(self) -> list[dict[str, Any]]:
        return self.content.candidates

    @property
    def verdict(self) -> Verdict | None:
        return self.content.verdict

    @property
    def status(self) -> str | None:
        """`adequate`, `explained`, `partly_explained`, `unexplained`, or `None` (no
        verdict: the record cannot identify the nominal model)."""
        v = self.content.verdict
        return None if v is None else v.status

    @property
    def status_line(self) -> str:
        """The verdict in one line (printed first by the report and the CLI)."""
        return status_line(section_json(self.content.verdict), self.content.not_identifiable)

    def __repr__(self) -> str:
        c = self.content
        g = c.gap
        lines = [f"DiagnosisReport(family={c.family!r})", self.status_line]
        if g is not None:
            lines.append(
                f"held-out gap {_num(g.validation)} (nominal), noise floor "
                f"{_num(g.noise_floor)}; report.to_markdown() for the whole report"
            )
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """The report as a JSON-ready dictionary (the schema of docs/guides/contracts.md),
        with its `schema_version`; the one place `report.json` is written from."""
        return self.content.to_json()

    def _header(self) -> list[str]:
        """The title, the status line (the verdict first) and the nominal model."""
        c = self.content._json()
        return [
            f"# Sim-to-real gap diagnosis — family `{c['family']}`",
            "",
            f"**{self.status_line}**",
            "",
            f"Nominal model: {c['nominal']['model']}.",
            "",
        ]

    def to_markdown(self) -> str:
        c = self.content._json()
        if c.get("not_identifiable"):
            return "\n".join(
                [
                    *self._header(),
                    "## Not identifiable: no verdict",
                    "",
                    f"{c['not_identifiable'].rstrip('.')}.",
                    "",
                    *_warnings_markdown(c),
                ]
            )
        g = c["gap"]
        v = c["verdict"]
        pct = lambda x: "—" if _num(x) == "—" else f"{100 * x:.2f} %"
        lines = [
            *self._header(),
            *_warnings_markdown(c),
            "## Verdict",
            "",
        ]
        status = v.get("status")
        if v["effects"]:
            lines.append(
                f"Missing effect(s), in the order added: **{', '.join(v['effects'])}**. "
                f"Validation gap {pct(g['validation'])} → {pct(v['validation_gap'])} "
                f"(shrink {v['shrink']:.2f}, 95 % interval "
                f"[{v['shrink_interval'][0]:.2f}, {v['shrink_interval'][1]:.2f}]); "
                f"noise floor {pct(g['noise_floor'])}."
            )
        elif status == "unexplained":
            lines.append(
                "No candidate effect passed (an admissible fit whose held-out gap reduction "
                "has a bootstrap interval excluding zero and exceeds what it gains on "
                "effect-free records of the same set-up), yet the held-out gap is above "
                "what the nominal model leaves on those records: the record shows an effect "
                f"that is not in the library. Validation gap {pct(g['validation'])}, noise "
                f"floor {pct(g['noise_floor'])}."
            )
        elif v.get("searched") is False:
            lines.append(
                "The nominal model's held-out gap already lies within what it leaves on "
                "effect-free records of the same set-up (the null), so no candidate effect was "
                "tried: with nothing to explain, trying the whole library could only find "
                "chance improvements. The nominal model is adequate up to the noise floor. "
                f"Validation gap {pct(g['validation'])}, noise floor {pct(g['noise_floor'])}."
            )
        else:
            lines.append(
                "No candidate effect passed (an admissible fit whose held-out gap reduction "
                "has a bootstrap interval excluding zero and exceeds what it gains on "
                "effect-free records of the same set-up) and the held-out gap lies within "
                "what the nominal model leaves on those records: the nominal model is "
                f"adequate up to the noise floor. Validation gap {pct(g['validation'])}, "
                f"noise floor {pct(g['noise_floor'])}."
            )
        lines += _remainder_markdown(v)
        lines += _distortion_markdown(c.get("distortion"))
        lines += _discovered_markdown(c.get("discovered"))
        lines += [
            "",
            "## Gap (metric: normalised RMS error of the target)",
            "",
            "| data | nominal | final |",
            "|---|---|---|",
            f"| calibration | {pct(g['calibration'])} | {pct(v.get('calibration_gap'))} |",
            f"| validation | {pct(g['validation'])} | {pct(v['validation_gap'])} |",
            f"| noise floor | {pct(g['noise_floor'])} | |",
            "",
            "## Where the gap lies (significant cells, FDR 5 %)",
            "",
            "| axis | cell | share of gap | share of samples | gap before | gap after |",
            "|---|---|---|---|---|---|",
        ]
        for w in c["where"]:
            lines.append(
                f"| {w['axis']} | {w['label']} | {w['share']:.2f} | {w['fraction']:.2f} | "
                f"{pct(w.get('gap'))} | {pct(w.get('gap_after'))} |"
            )
        if not c["where"]:
            lines.append("| — | no cell concentrates the gap significantly | | | | |")
        if c.get("where_after"):
            lines += [
                "",
                "## Where the remaining gap lies (final model, significant cells)",
                "",
                "| axis | cell | share of gap | share of samples | gap |",
                "|---|---|---|---|---|",
            ]
            for w in c["where_after"]:
                lines.append(
                    f"| {w['axis']} | {w['label']} | {w['share']:.2f} | {w['fraction']:.2f} | "
                    f"{pct(w.get('gap'))} |"
                )
        lines += [
            "",
            "## Candidate effects (best first)",
            "",
            "| effect | testable | signature | validation gap | shrink [95 % CI] | ΔBIC | "
            "null 95 % | admissible | accepted | parameters |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for k in c["candidates"]:
            if not k["testable"]:
                lines.append(f"| {k['effect']} | no: {k['reason']} | | | | | | | no | |")
                continue
            ci = k.get("shrink_interval")
            shr = (
                f"{k['shrink']:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]"
                if k.get("shrink") is not None and ci
                else "—"
            )
            par = ", ".join(
                f"{n} = {_num(v, '.4g')}" for n, v in (k.get("parameters") or {}).items()
            )
            dbic = _num(k.get("delta_bic"), ".1f")
            null = pct(k.get("null_p95"))
            adm = "yes" if k.get("admissible") else f"no: {k.get('reason')}"
            if k.get("admissible") is None:
                adm = "—"
            acc = "**yes**" if k["accepted"] else f"no ({k.get('rejected_by') or 'not tried'})"
            lines.append(
                f"| {k['effect']} | yes | {_num(k['signature'], '.3f')} | {pct(k.get('validation_gap'))} | "
                f"{shr} | {dbic} | {null} | {adm} | {acc} | {par} |"
            )
        lines += _rounds_markdown(c.get("rounds") or [])
        lines += _pruning_markdown(c.get("pruning") or [])
        lines += ["", f"Run time: {c['timing']['seconds']:.1f} s.", ""]
        if c.get("figures"):
            lines += ["## Figures", ""] + [f"![{f}]({f})" for f in c["figures"]] + [""]
        return "\n".join(lines)

    def to_html(self, folder: str | pathlib.Path | None = None) -> str:
        """`report.html`: the Markdown report as one self-contained page, the figures
        listed in `content.figures` embedded from `folder`, each search round
        collapsible."""
        return report_html(self.to_markdown(), folder, f"jaxvs diagnose — {self.content.family}")

    def _repr_html_(self) -> str:
        return markdown_to_html(self.to_markdown())

    def save(self, out: str | pathlib.Path) -> pathlib.Path:
        """Write `report.json`, `report.md` and `report.html` to the folder `out`
        (created; figures already in it are embedded in `report.html`)."""
        out = pathlib.Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.json").write_text(json.dumps(self.to_json(), indent=2) + "\n")
        (out / "report.md").write_text(self.to_markdown())
        (out / "report.html").write_text(self.to_html(out))
        if self.discovered is not None:  # the reference signal of the proposed experiment
            self.discovered.save_next_experiment(out / "next_experiment.csv")
        return out


def _num(value: Any, fmt: str = ".3g") -> str:
    """A number for a report cell; "—" for a missing or non-finite one."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "—"
    return format(value, fmt)


def _remainder_markdown(v: dict[str, Any]) -> list[str]:
    """The remainder against the floor and the null and, above the null, where it lies."""
    rem = v.get("remainder")
    if not rem:
        return []
    over = _num(rem.get("over_floor"))
    p95 = _num(rem.get("null_p95_over_floor"))
    bound = _num(rem.get("threshold_over_floor"))
    tol = rem.get("tolerance")
    lines = [
        "",
        f"Remaining held-out gap: {over}× the noise floor; the null's 95th percentile is "
        f"{p95}×, the bound with the noise level's uncertainty "
        f"({'—' if tol is None else f'{100 * tol:.0f} %'}) {bound}× (state "
        f"`{v.get('status')}`, {'within' if rem.get('within_null') else 'above'} the null).",
    ]
    if rem.get("where"):
        lines += [
            "",
            "### Where the remainder lies",
            "",
            "| axis | cell | share of remainder | share of samples | p-value |",
            "|---|---|---|---|---|",
        ]
        for w in rem["where"]:
            lines.append(
                f"| {w['axis']} | {w['label']} | {w['share']:.2f} | {w['fraction']:.2f} | "
                f"{w['p_value']:.2g} |"
            )
        lines += ["", f"Test: {rem['where'][0]['test']}."]
    elif not rem.get("within_null"):
        lines += ["", "No time window or operating point concentrates the remainder."]
    return lines


def _distortion_markdown(d: dict[str, Any] | None) -> list[str]:
    """The noise measured from repeated periods and the nonlinear distortion level."""
    if not d or not d.get("available"):
        return []
    lines = [
        "",
        "### Measured noise and nonlinear distortion (repeated periods)",
        "",
        f"{d['periods']} period(s) of {d['period_samples']} samples of `{d['input']}` in "
        f"{d['realisations']} realisation(s); {d['method']}: noise "
        f"{100 * d['noise_level']:.3g} %, distortion {100 * d['distortion_level']:.3g} % of "
        f"the RMS of `{d['output']}` ({_num(d['distortion_over_noise'])}× the noise).",
    ]
    if d.get("finding"):
        lines += ["", f"**Finding: {d['finding']}.**"]
    return lines


def _warnings_markdown(c: dict[str, Any]) -> list[str]:
    """The non-blocking findings of `jaxvs check` on the calibration data."""
    if not c.get("warnings"):
        return []
    return ["## Warnings (jaxvs check)", ""] + [f"- {w}" for w in c["warnings"]] + [""]


def _rounds_markdown(rounds: list[dict[str, Any]]) -> list[str]:
    """One `###` section per round of the greedy search (collapsible in `report.html`):
    every candidate tried, its held-out gap and why it passed or not."""
    if not rounds:
        return []
    lines = ["", "## Search rounds", ""]
    for h in rounds:
        tried = h.get("tried") or {}
        passing = [e for e, t in tried.items() if t.get("passes")]
        gap = h.get("gap_before")
        lines += [
            f"### Round {h.get('round', '?')}: gap before "
            f"{'—' if gap is None else f'{100 * gap:.2f} %'}, {len(tried)} candidate(s) tried, "
            f"{len(passing)} passing, {_num(h.get('seconds'), '.1f')} s",
            "",
        ]
        if not tried:
            lines += ["No candidate was tried in this round.", ""]
            continue
        lines += [
            "| effect | validation gap | shrink | ΔBIC | null threshold | admissible | passes | "
            "parameters |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for effect, t in tried.items():
            vg = t.get("validation_gap")
            par = ", ".join(
                f"{n} = {_num(v, '.4g')}" for n, v in (t.get("parameters") or {}).items()
            )
            adm = t.get("admissible")
            adm = "—" if adm is None else ("yes" if adm else f"no: {t.get('reason')}")
            passes = "yes" if t.get("passes") else f"no ({t.get('rejected_by') or 'not tested'})"
            lines.append(
                f"| {effect} | {'—' if vg is None else f'{100 * vg:.2f} %'} | "
                f"{_num(t.get('shrink'), '.2f')} | {_num(t.get('delta_bic'), '.1f')} | "
                f"{_num(t.get('null_threshold'))} | {adm} | {passes} | {par} |"
            )
        lines.append("")
    return lines


def _pruning_markdown(pruning: list[dict[str, Any]]) -> list[str]:
    """The backward-elimination tests: each accepted effect against the final model
    without it."""
    if not pruning:
        return []
    lines = [
        "",
        "## Every effect against the final model without it",
        "",
        "| effect | model | gap without → with | reduction [95 % CI] | ΔBIC | kept |",
        "|---|---|---|---|---|---|",
    ]
    for p in pruning:
        lo, hi = p["reduction_interval"]
        kept = "**yes**" if p["kept"] else f"no: {p['rejected_by']}"
        lines.append(
            f"| {p['effect']} | {', '.join(p['effects'])} | {100 * p['gap_without']:.2f} % → "
            f"{100 * p['gap_with']:.2f} % | {100 * p['reduction']:.3f} % "
            f"[{100 * lo:.3f}, {100 * hi:.3f}] | {_num(p['delta_bic'], '.1f')} | {kept} |"
        )
    return lines


def _discovered_markdown(d: dict[str, Any] | None) -> list[str]:
    """The discovery section: what the flexible term and the formula found, in words."""
    if not d:
        return []
    lines = ["", "## Discovery (an effect outside the library)", "", str(d.get("message", ""))]
    if d.get("fired") and d.get("formula"):
        lines += ["", f"Formula: `{d['formula']}`" + (" (accepted)" if d.get("found") else "")]
        if d.get("shrink") is not None:
            lines.append(
                f"Held-out shrink {d['shrink']:.2f}; share of what the flexible term removes "
                f"{d.get('share') or 0:.2f}; nearest named effect: {d.get('nearest_effect')}."
            )
    rival, nxt = d.get("rival"), d.get("next_experiment")
    if rival:
        lines += [
            "",
            f"A rival formula is almost as probable: `{rival.get('rival')}` (log evidence of "
            f"the kept one over it {_num(rival.get('log_evidence_ratio'))}).",
        ]
    if nxt:
        pars = ", ".join(f"{k} {_num(v)}" for k, v in (nxt.get("parameters") or {}).items())
        lines += [
            "",
            f"Next experiment to tell them apart: a {nxt.get('kind')} of `{nxt.get('signal')}` "
            f"({pars}); the two formulas disagree {_num(nxt.get('gain'))} times more on it "
            "than on the records (`next_experiment.csv`, a reference signal within the "
            "records' travel, speed and force).",
        ]
    return lines
