"""`jaxvs.check`: can these records support the family's nominal model?

Before any calibration, look at the data the way a control engineer would (Isaac Sim's
identification workflow does the same before it solves): the time base, clipping and
quantisation, the band the excitation covers against the band of the model, the coherence
between input and output, for drives motion in both directions, and finally the
singular values of the nominal model's Jacobian on these records — the parameter
combinations the records cannot identify.

Blocking findings (exit code 3 of `jaxvs check`): a family's preprocessing refuses the
records (too short, no motion, constant input), drives that move in one direction only,
or a Jacobian whose smallest column-scaled singular value is below `1e-6` of the largest
(heuristic: at that conditioning float64 least squares loses ten digits, so the
combination's estimate is noise) or below the family's own `singular_rtol` (the drive
family's `1e-3`, the threshold its diagnosis refuses at). Everything else is reported as
a warning, and so are the family's `nominal_warnings` (a drive record that does not
excite the inertia: the mass is fixed and the diagnosis goes on).
"""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._html import markdown_to_html, report_html
from .._json_section import JsonSection, section_json
from .._misc import json_safe, require_x64
from ..data import Record, signal_quality
from ._base import GapModel, NotIdentifiable, unwrap
from ._families import FAMILIES
from ._inputs import CHECK_VALUES, check_signals, memory_check, records
from ._options import validate_options

__all__ = [
    "CHECK_SCHEMA_VERSION",
    "CheckContent",
    "CheckReport",
    "Jacobian",
    "Unidentifiable",
    "check",
]

CHECK_SCHEMA_VERSION = 1
"""`schema_version` of the check's `report.json` (raised when a key is removed or changes
meaning)."""

# heuristics, each documented where it is used
_COHERENCE_MIN = 0.5


@dataclasses.dataclass(frozen=True)
class Unidentifiable(JsonSection):
    """A parameter combination the records cannot identify: its singular value relative
    to the largest and the combination (parameter -> weight, the largest weight 1)."""

    relative: float
    combination: dict[str, float]

    def _json(self) -> dict[str, Any]:
        return {"relative": self.relative, "combination": dict(self.combination)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Unidentifiable:
        return cls(relative=_float(data["relative"]), combination=dict(data["combination"]))


@dataclasses.dataclass(frozen=True)
class Jacobian(JsonSection):
    """The singular values of the nominal model's column-scaled Jacobian on the records:
    the parameter names (one per column), the singular values (largest first), the
    condition number (infinite for a singular Jacobian) and the combinations below the
    threshold."""

    parameters: list[str]
    singular_values: list[float]
    condition: float
    unidentifiable: list[Unidentifiable] = dataclasses.field(default_factory=list)

    def _json(self) -> dict[str, Any]:
        return {
            "parameters": list(self.parameters),
            "singular_values": list(self.singular_values),
            "condition": self.condition,
            "unidentifiable": [u._json() for u in self.unidentifiable],
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Jacobian:
        return cls(
            parameters=list(data["parameters"]),
            singular_values=[_float(v) for v in data["singular_values"]],
            # `report.json` writes an infinite condition number as null
            condition=_float(data["condition"], math.inf),
            unidentifiable=[Unidentifiable.from_json(u) for u in data.get("unidentifiable", [])],
        )


@dataclasses.dataclass(frozen=True)
class CheckContent(JsonSection):
    """The content of the check's `report.json`, typed: `family`, `nominal` (the nominal
    model in words), `records` (per record: `name`, `samples`, `fs`, `duration`,
    `signals` (clipping share and quantisation step per signal) and, where measured,
    `excitation_band_hz`, `median_coherence_in_band`, `share_moving_positive`,
    `reversals`), `blocking`, `warnings`, `jacobian` (a `Jacobian`, `None` when the
    nominal model could not be fitted) and `identifiable`.

    `to_json()` writes `report.json` (with `schema_version`); `from_json` reads it back.
    """

    family: str
    nominal: str = ""
    records: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    blocking: list[str] = dataclasses.field(default_factory=list)
    warnings: list[str] = dataclasses.field(default_factory=list)
    jacobian: Jacobian | None = None
    identifiable: bool = False

    def _json(self) -> dict[str, Any]:
        return {
            "family": self.family,
            "nominal": self.nominal,
            "records": list(self.records),
            "blocking": list(self.blocking),
            "warnings": list(self.warnings),
            "jacobian": section_json(self.jacobian),
            "identifiable": self.identifiable,
        }

    def to_json(self) -> dict[str, Any]:
        """`report.json`: the content with its `schema_version`, JSON-ready."""
        return {"schema_version": CHECK_SCHEMA_VERSION, **json_safe(self._json())}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> CheckContent:
        """The content of a check's `report.json` (or of the `check` section of a
        diagnosis report)."""
        _check_schema(data, CHECK_SCHEMA_VERSION, "check")
        jac = data.get("jacobian")
        return cls(
            family=data["family"],
            nominal=data.get("nominal", ""),
            records=list(data.get("records", [])),
            blocking=list(data.get("blocking", [])),
            warnings=list(data.get("warnings", [])),
            jacobian=None if jac is None else Jacobian.from_json(jac),
            identifiable=bool(data.get("identifiable", False)),
        )


def _float(value: Any, missing: float = math.nan) -> float:
    """A float read back from `report.json`, where non-finite ones are written as null."""
    return missing if value is None else float(value)


def _check_schema(data: Mapping[str, Any], version: int, what: str) -> None:
    written = data.get("schema_version", version)
    if not isinstance(written, int) or written > version:
        raise ValueError(
            f"this {what} report.json has schema_version {written!r}, newer than the "
            f"{version} this version of jaxvs reads; upgrade jaxvs to read it."
        )


@dataclasses.dataclass(frozen=True)
class CheckReport:
    """What `jaxvs.check` found: `content` (a `CheckContent`, the typed `report.json`),
    `ok`, `to_json`, `to_markdown`, `to_html`, `save(folder)` (writes `report.json`,
    `report.md` and `report.html`), and, when the check got that far, the prepared
    `experiments` and the nominal model's initial fit `nominal_model` (`jaxvs.diagnose`
    goes on from them instead of preparing them again).

    `CheckReport(content)` also takes the content as a dictionary (`report.json`'s),
    and `content["key"]` reads it like one (compatibility)."""

    content: CheckContent
    experiments: list[Any] | None = dataclasses.field(default=None, repr=False, compare=False)
    nominal_model: Any = dataclasses.field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.content, CheckContent):
            object.__setattr__(self, "content", CheckContent.from_json(self.content))

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> CheckReport:
        """A check report read back from its `report.json` (no experiments or model)."""
        return cls(CheckContent.from_json(data))

    def to_json(self) -> dict[str, Any]:
        """`report.json`: the content with its `schema_version`, JSON-ready."""
        return self.content.to_json()

    @property
    def ok(self) -> bool:
        """Whether the records can support the family's nominal model (exit code 0)."""
        return bool(self.content.identifiable)

    @property
    def exit_code(self) -> int:
        return 0 if self.ok else 3

    def to_markdown(self) -> str:
        c = self.content
        verdict = "can" if self.ok else "**cannot**"
        lines = [
            f"# jaxvs check — {c.family}",
            "",
            f"The records {verdict} support the nominal model ({c.nominal}).",
            "",
        ]
        if c.blocking:
            lines += ["## Blocking", ""] + [f"- {b}" for b in c.blocking] + [""]
        if c.warnings:
            lines += ["## Warnings", ""] + [f"- {w}" for w in c.warnings] + [""]
        lines += [
            "## Records",
            "",
            "| record | samples | fs [Hz] | duration [s] | excitation band [Hz] |",
            "|---|---|---|---|---|",
        ]
        for r in c.records:
            band = r.get("excitation_band_hz")
            band_text = "—" if band is None else f"{band[0]:.3g}–{band[1]:.3g}"
            lines.append(
                f"| {r['name']} | {r['samples']} | {r['fs']:.6g} | {r['duration']:.4g} | "
                f"{band_text} |"
            )
        lines += [
            "",
            "| record | signal | clipped share | quantisation step / std |",
            "|---|---|---|---|",
        ]
        for r in c.records:
            for sig, q in r["signals"].items():
                lines.append(
                    f"| {r['name']} | {sig} | {100 * q['clipped_share']:.2f} % | "
                    f"{_fmt(q['quantisation_step_over_std'])} |"
                )
        ident = c.jacobian
        if ident:
            lines += [
                "",
                "## Identifiability of the nominal model",
                "",
                "Singular values of the column-scaled Jacobian (largest first): "
                + ", ".join(f"{s:.3g}" for s in ident.singular_values),
                "",
                f"Condition number: {_fmt(ident.condition)}.",
            ]
            for combo in ident.unidentifiable:
                terms = " + ".join(f"{w:+.3f}·{n}" for n, w in combo.combination.items())
                lines.append(f"- not identifiable: {terms} (σ/σ_max = {combo.relative:.2g})")
        return "\n".join(lines) + "\n"

    def to_html(self) -> str:
        """`report.html`: the Markdown report as one self-contained page."""
        return report_html(self.to_markdown(), None, f"jaxvs check — {self.content.family}")

    def _repr_html_(self) -> str:
        return markdown_to_html(self.to_markdown())

    def save(self, folder: str | pathlib.Path) -> pathlib.Path:
        """Write `report.json`, `report.md` and `report.html` to `folder` (created)."""
        out = pathlib.Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.json").write_text(json.dumps(self.to_json(), indent=2) + "\n")
        (out / "report.md").write_text(self.to_markdown())
        (out / "report.html").write_text(self.to_html())
        return out

    def __repr__(self) -> str:
        return f"CheckReport(family={self.content.family!r}, ok={self.ok})"


def _fmt(value: float) -> str:
    """A ratio for the report: "∞" for an infinite one (a constant signal, a singular
    Jacobian), "—" for one `report.json` holds as null."""
    if value is None:
        return "—"
    return "∞" if math.isinf(value) else f"{value:.3g}"


# --- data quality ------------------------------------------------------------------------


def _excitation_band(x: np.ndarray, fs: float) -> tuple[float, float] | None:
    """Frequencies holding 5 % and 95 % of the AC power of `x` (Welch PSD)."""
    import scipy.signal as ss

    x = np.asarray(x, float) - np.mean(x)
    if not np.any(x):
        return None
    f, p = ss.welch(x, fs=fs, nperseg=min(x.size, 1024))
    cum = np.cumsum(p[1:])
    if cum[-1] <= 0:
        return None
    cum /= cum[-1]
    return float(f[1:][np.searchsorted(cum, 0.05)]), float(f[1:][np.searchsorted(cum, 0.95)])


_INPUTS = {"drive": "u", "tmf": "x_e", "thermal": "T_chassis"}
_OUTPUTS = {"drive": "q", "tmf": "x_t", "thermal": "T_bearing"}
_NOT_JUDGED = {"drive": ("r",), "tmf": ("y",), "thermal": ()}
_LIVE = {"drive": ("u",), "tmf": (), "thermal": ()}  # see signal_quality(live=...)


def _record_quality(record: Record, name: str, family: str) -> tuple[dict, list[str], list[str]]:
    fam = FAMILIES[family]
    summary: dict[str, Any] = {
        "name": name,
        "samples": len(record),
        "fs": record.fs,
        "duration": record.duration,
        "signals": {},
    }
    # clipping and quantisation are properties of sensors and amplifiers: a commanded
    # reference (`r`, whose dwell at the end of a move is by design) and a per-record
    # setting (the other axis' position `y` of a TMF record) are not judged
    signals = fam.required + tuple(
        s for s in fam.optional if s in record and s not in _NOT_JUDGED[family]
    )
    summary["signals"], blocking, warnings = signal_quality(
        {s: record[s] for s in signals if s != "t"},
        name=name,
        required=fam.required,
        live=_LIVE[family],
    )
    u = _INPUTS[family]
    if u in record and np.ptp(record[u]) > 0:
        summary["excitation_band_hz"] = _excitation_band(record[u], record.fs)
    y = _OUTPUTS[family]
    if family in ("tmf", "drive") and u in record and y in record:
        from ..signal import coherence

        n = len(record)
        if n >= 64 and np.ptp(record[u]) > 0 and np.ptp(record[y]) > 0:
            f, c = coherence(
                np.asarray(record[u]), np.asarray(record[y]), record.fs, nperseg=min(n // 4, 1024)
            )
            f, c = np.asarray(f), np.asarray(c).reshape(-1)
            band = summary.get("excitation_band_hz")
            sel = (f > 0) if band is None else (f >= band[0]) & (f <= band[1])
            med = float(np.median(c[sel])) if sel.any() else float("nan")
            summary["median_coherence_in_band"] = med
            if family == "tmf" and med < _COHERENCE_MIN:
                warnings.append(
                    f"{name}: median coherence {med:.2f} between {u!r} and {y!r} in the "
                    "excitation band; the TMF estimate will be noisy — average more data."
                )
    if family == "drive" and "q" in record:
        v = np.gradient(np.asarray(record["q"], float), record.dt)
        vmax = float(np.max(np.abs(v)))
        moving = np.abs(v) > 0.05 * vmax if vmax > 0 else np.zeros(v.size, bool)
        pos = float(np.mean(v[moving] > 0)) if moving.any() else 0.0
        signs = np.sign(v[moving])
        reversals = int(np.sum(signs[1:] != signs[:-1])) if signs.size > 1 else 0
        summary["share_moving_positive"] = pos
        summary["reversals"] = reversals
        if vmax == 0:
            blocking.append(f"{name}: the axis does not move (q is constant).")
        elif pos < 0.05 or pos > 0.95:
            blocking.append(
                f"{name}: the axis moves in one direction only ({100 * pos:.0f} % of the moving "
                "samples forward); viscous friction and the force offset cannot be told apart. "
                "Record motion in both directions."
            )
    return summary, blocking, warnings


# --- identifiability ---------------------------------------------------------------------


def _parameter_names(nominal: eqx.Module) -> list[str]:
    params = eqx.filter(nominal, eqx.is_inexact_array)
    names = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(params)[0]:
        base = jax.tree_util.keystr(path).lstrip(".")
        size = int(np.size(leaf))
        names += [base] if size == 1 else [f"{base}[{i}]" for i in range(size)]
    return names


def _jacobian_report(
    nominal: eqx.Module, experiments: Sequence[Any], rtol: float = 1e-6
) -> Jacobian:
    params, static = eqx.partition(nominal, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(params)

    def predict(theta, arrays):
        model = GapModel(eqx.combine(unravel(theta), static))
        return jnp.concatenate([model(a) for a in arrays])

    # one compiled program (op-by-op differentiation through the simulation's scan would
    # compile every primitive on its own, several times slower)
    jacobian = jax.jit(jax.jacfwd(predict))
    J = np.asarray(jacobian(flat, [e.jax_arrays() for e in experiments]))
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    _, s, vt = np.linalg.svd(J / scale, full_matrices=False)
    names = _parameter_names(nominal)
    smax = float(s[0]) if s.size else 0.0
    unidentifiable = []
    for k, sv in enumerate(s):
        rel = sv / smax if smax > 0 else 0.0
        if rel < rtol:
            direction = vt[k] / np.max(np.abs(vt[k]))
            combo = {n: float(w) for n, w in zip(names, direction) if abs(w) > 0.05}
            unidentifiable.append(Unidentifiable(relative=float(rel), combination=combo))
    return Jacobian(
        parameters=names,
        singular_values=[float(v) for v in s],
        condition=float(s[0] / s[-1]) if s.size and s[-1] > 0 else math.inf,
        unidentifiable=unidentifiable,
    )


def check(
    data: Any, *, family: str, signals: Mapping[str, str] | None = None, **options: Any
) -> CheckReport:
    """Data-quality and identifiability check of records for a family's nominal model.

    **Arguments:**

    - `data`: a `Record`, a path, or a list of them (several experiments).
    - `family`: `"drive"`, `"tmf"` or `"thermal"`.
    - `signals`: the user's own column names mapped onto the canonical ones,
      `{"q": "Position", "u": "Torque", "t": "Time"}` (`jaxvs.data.rename_signals`).
    - `options`: family options as for `jaxvs.diagnose` (e.g. `cutoff_hz`, `order`).

    **Returns:**

    A `CheckReport`: `ok` is `True` when the records can support the family's nominal
    model; `content` holds per-record findings (sample rate, duration, clipping share and
    quantisation step per signal, excitation band, coherence, drive motion directions and
    reversals), the blocking findings and warnings, and the nominal model's Jacobian
    singular values with the parameter combinations the records cannot identify.

    **Raises:**

    `ValueError` for an unknown family, missing signals or unreadable files (user errors,
    exit code 2 of `jaxvs check`).
    """
    require_x64("check", "the nominal model's calibration and its Jacobian")
    if family not in FAMILIES:
        raise ValueError(f"check: unknown family {family!r}; choose one of {sorted(FAMILIES)}.")
    recs = records(data, "calibration", signals, "check")
    fam = FAMILIES[family](
        **validate_options(family, options, "check", FAMILIES[family].option_keys)
    )
    check_signals(fam, recs, "check")
    memory_check(fam, sum(len(r) for r, _ in recs), "check", CHECK_VALUES)
    return check_records(fam, recs)


def check_records(
    fam: Any, recs: Sequence[tuple[Record, str]], *, raise_value_errors: bool = False
) -> CheckReport:
    """`check` on records already read and given their names (`jaxvs.diagnose` calls it
    before any calibration); `fam` is the family instance with its options. With
    `raise_value_errors`, a `ValueError` of the family's preprocessing (a bad option, a
    user error) is raised instead of being reported as blocking."""
    family = fam.name
    blocking: list[str] = []
    warnings: list[str] = []
    summaries = []
    for record, name in recs:
        summary, b, w = _record_quality(record, name, family)
        summaries.append(summary)
        blocking += b
        warnings += w
    rates = {round(r.fs, 9) for r, _ in recs}
    if len(rates) > 1:
        warnings.append(
            f"the records have different sample rates {sorted(rates)} Hz; they are "
            "calibrated jointly but never resampled — check that this is intended."
        )
    experiments: list[Any] | None = None
    initial = None
    jacobian: Jacobian | None = None
    try:
        experiments = [fam.prepare(record, name) for record, name in recs]
        initial = fam.nominal(experiments)
        nominal = unwrap(initial)
    except NotIdentifiable as error:
        blocking.append(f"the nominal model is not identifiable: {error}")
    except ValueError as error:
        if raise_value_errors:
            raise
        blocking.append(f"the family's preprocessing refuses the records: {error}")
    else:
        # a family states its own threshold and what to record for each parameter, so
        # that `jaxvs check` refuses exactly what the diagnosis refuses; parameters the
        # family fixed (a mass a friction rig does not excite) are no Jacobian column,
        # and the fixing is a warning
        warnings += list(fam.nominal_warnings(experiments))
        jacobian = _jacobian_report(nominal, experiments, fam.singular_rtol)
        advice = fam.record_advice
        for combo in jacobian.unidentifiable:
            weights = combo.combination
            terms = ", ".join(f"{n} ({w:+.2f})" for n, w in weights.items())
            worst = max(weights, key=lambda n: abs(weights[n]))
            todo = f" To identify {worst}: {advice[worst]}." if worst in advice else ""
            blocking.append(
                f"the nominal model's parameter combination of {terms} is not identifiable "
                f"from these records (singular value {combo.relative:.1e} of the "
                f"largest).{todo}"
            )
    content = CheckContent(
        family=family,
        nominal=fam.describe_nominal() or family,
        records=summaries,
        blocking=blocking,
        warnings=warnings,
        jacobian=jacobian,
        identifiable=not blocking,
    )
    if initial is None:
        return CheckReport(content)
    return CheckReport(content, experiments=experiments, nominal_model=initial)
