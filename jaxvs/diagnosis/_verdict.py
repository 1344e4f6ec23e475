"""The verdict's state: is the remaining held-out gap noise, and did named effects close it?

Four states (`verdict.status`):

- `adequate`: no effect accepted and the remaining held-out gap lies within the null's
  distribution (below the 95th percentile of the held-out gaps the calibrated nominal
  model leaves on the effect-free records of the same set-up, widened by the uncertainty
  of the noise level those records are drawn with);
- `explained`: effects accepted and the remainder within the null;
- `partly_explained`: effects accepted, the remainder above the null;
- `unexplained`: nothing accepted, the remainder above the null.

Only `adequate` sets `verdict.adequate`. For the last two the verdict says how large the
remainder is against the noise floor and where it lies: the strongest cells of the gap map
drawn on the final model's residual (time windows, operating points; circular-shift
permutation test with Benjamini–Hochberg control), each with its share of the remaining
gap, its share of the samples and its p-value.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["STATES", "decide", "null_bound", "status_line"]

# the relative uncertainty of the noise level the null records are drawn with (`decide`)
TOLERANCE = 0.25

STATES = ("adequate", "explained", "partly_explained", "unexplained")

# the test behind every cell of `remainder.where`
CELL_TEST = "circular-shift permutation of the residual energy, Benjamini–Hochberg FDR"


def null_quantile(null_gaps: Sequence[float], level: float = 0.95) -> float:
    """The `level` quantile of the null records' held-out gaps (`inf` without a null)."""
    g = np.asarray([v for v in null_gaps if np.isfinite(v)], float)
    return float(np.quantile(g, level)) if g.size else float("inf")


def null_bound(
    null_gaps: Sequence[float], level: float = 0.95, tolerance: float = TOLERANCE
) -> float:
    """The largest held-out gap that lies within the null: `(1 + tolerance)` times the
    null's `level` quantile (`decide` explains the tolerance). A nominal model whose gap
    is below it is `adequate`, and the search tries no candidate on it."""
    return (1.0 + tolerance) * null_quantile(null_gaps, level)


def decide(
    accepted: Sequence[str],
    remaining_gap: float,
    null_gaps: Sequence[float],
    noise_floor: float,
    cells_after: Sequence[dict[str, Any]] = (),
    *,
    level: float = 0.95,
    tolerance: float = TOLERANCE,
    fdr: float = 0.05,
    n_cells: int = 5,
) -> dict[str, Any]:
    """The verdict's state and, above the null, where the remainder lies.

    - `accepted`: the effects the search accepted.
    - `remaining_gap`: the final model's held-out gap (nrmse).
    - `null_gaps`: the nominal model's held-out gaps on the effect-free null records.
    - `cells_after`: the gap map of the final residual (`GapCell.to_json()` dicts).

    - `tolerance`: the relative uncertainty of the noise level the null records are drawn
      with. The null reproduces the noise at the level estimated from the record, so its
      spread holds the record-to-record variation but not the error of that estimate
      (its spread across records of one set-up is about 25 % of the level); a remainder
      counts as above the null when it exceeds `(1 + tolerance)` times the null's
      `level` quantile.

    Returns `{"status", "adequate", "remainder"}`; `remainder` holds `gap`, `noise_floor`,
    `over_floor`, `null_p95`, `threshold`, `within_null`, `level`, `tolerance` and `where`
    (the strongest significant cells, most concentrated first; empty when the remainder is
    within the null).
    """
    p95 = null_quantile(null_gaps, level)
    threshold = null_bound(null_gaps, level, tolerance)
    within = bool(np.isfinite(remaining_gap) and remaining_gap <= threshold)
    if accepted:
        status = "explained" if within else "partly_explained"
    else:
        status = "adequate" if within else "unexplained"
    where = []
    if not within:
        sig = [c for c in cells_after if c.get("significant") and c.get("axis") != "frequency"]
        sig.sort(key=lambda c: -(c["share"] - c["fraction"]))
        for c in sig[:n_cells]:
            where.append(
                {
                    "axis": c["axis"],
                    "label": c["label"],
                    "range": c.get("range"),
                    "share": c["share"],
                    "fraction": c["fraction"],
                    "enrichment": c.get("enrichment"),
                    "gap": c.get("gap"),
                    "p_value": c["p_value"],
                    "test": f"{CELL_TEST} {100 * fdr:g} %",
                }
            )
    remainder = {
        "gap": remaining_gap,
        "noise_floor": noise_floor,
        "over_floor": remaining_gap / noise_floor if noise_floor > 0 else None,
        "null_p95": p95,
        "null_p95_over_floor": p95 / noise_floor if noise_floor > 0 else None,
        "threshold": threshold,
        "threshold_over_floor": threshold / noise_floor if noise_floor > 0 else None,
        "within_null": within,
        "level": level,
        "tolerance": tolerance,
        "where": where,
    }
    return {"status": status, "adequate": status == "adequate", "remainder": remainder}


def status_line(verdict: dict[str, Any] | None, not_identifiable: str | None = None) -> str:
    """One line that says the verdict first: its state, the effects, the remainder against
    the floor and, above the null, where it lies."""
    if verdict is None:
        return f"verdict: none (not identifiable: {(not_identifiable or '').rstrip('.')})"
    status = verdict.get("status")
    rem = verdict.get("remainder") or {}
    ratio = rem.get("over_floor")
    p95r = rem.get("threshold_over_floor", rem.get("null_p95_over_floor"))
    size = f"{ratio:.3g}× the noise floor" if ratio is not None else "no noise floor"
    null = f"null bound {p95r:.3g}×" if p95r is not None and np.isfinite(p95r) else "no null"
    effects = ", ".join(verdict.get("effects") or [])
    where = rem.get("where") or []
    lies = "; ".join(
        f"{w['label']} (share {w['share']:.2f}, p = {w['p_value']:.2g})" for w in where[:3]
    )
    lies = f"; it lies in {lies}" if lies else "; no cell concentrates it"
    if status == "adequate":
        return f"verdict: adequate — no effect needed; remaining gap {size} ({null})"
    if status == "explained":
        return f"verdict: explained by {effects}; remaining gap {size}, within the null ({null})"
    if status == "partly_explained":
        return (
            f"verdict: partly explained by {effects}; remaining gap {size}, above the null "
            f"({null}){lies}"
        )
    if status == "unexplained":
        return (
            f"verdict: unexplained — no library effect closes the gap; remaining gap {size}, "
            f"above the null ({null}){lies}"
        )
    # a report written before the states existed
    return "verdict: " + (f"effects {effects}" if effects else "no effect accepted")
