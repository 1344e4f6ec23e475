"""Which error combinations a test plan can separate: the singular values of the plan's
whitened sensitivity matrix and its null directions, in the form of `jaxvs check`."""

import json
import math

import equinox as eqx
import numpy as np

from ...models import COMPONENTS, CartesianMachine
from ._parameters import _assert_tests, parameter_names, plan_jacobian

__all__ = ["IdentifiabilityReport", "identifiability"]

# the threshold of `jaxvs check`: below 1e-6 of the largest column-scaled singular value a
# float64 least-squares estimate of that combination is noise (heuristic)
SINGULAR_RTOL = 1e-6


class IdentifiabilityReport(eqx.Module):
    """What a test plan identifies.

    **Fields** (`content`, JSON-ready, the `jacobian` section of `jaxvs check`):

    - `parameters`: names of the calibrated parameters (`EXX[P1]` … `B_Z`).
    - `singular_values`: of the column-scaled whitened Jacobian, largest first.
    - `condition`: their ratio (∞ when rank deficient).
    - `rank`: number of singular values above `1e-6` of the largest.
    - `unidentifiable`: `[{"relative": σ/σ_max, "combination": {name: weight}}]`, each a
      direction of the parameters the plan cannot see (weights scaled to max 1, entries
      below 0.05 left out).
    - `components`: `{component: "identified" | "not identified"}` for the 21 components
      and the reversal values (not identified: a parameter of it lies in a null
      direction with a weight above 1e-3).
    - `plan`: the tests' labels; `n_readings`.
    """

    content: dict = eqx.field(static=True)

    @property
    def identified(self) -> bool:
        return not self.content["unidentifiable"]

    @property
    def unidentified_components(self) -> list[str]:
        return [c for c, v in self.content["components"].items() if v != "identified"]

    def to_markdown(self) -> str:
        c = self.content
        lines = [
            "## Identifiability of the test plan",
            "",
            f"{len(c['plan'])} tests, {c['n_readings']} readings, {len(c['parameters'])} "
            f"parameters, rank {c['rank']}.",
            "",
            "Singular values of the column-scaled Jacobian (largest first): "
            + ", ".join(f"{s:.3g}" for s in c["singular_values"]),
            "",
            f"Condition number: {c['condition']:.3g}.",
        ]
        bad = self.unidentified_components
        lines.append(
            "",
        )
        lines.append(
            "All components identified."
            if not bad
            else f"Not identified: {', '.join(bad)}."
        )
        for combo in c["unidentifiable"]:
            terms = " + ".join(f"{w:+.3f}·{n}" for n, w in combo["combination"].items())
            lines.append(f"- not identifiable: {terms} (σ/σ_max = {combo['relative']:.2g})")
        return "\n".join(lines) + "\n"

    def to_json(self) -> str:
        return json.dumps(self.content, indent=2)


def identifiability(machine: CartesianMachine, tests) -> IdentifiabilityReport:
    """Identifiability of the 21 components (and the reversal values) from a test plan.

    The readings are linear in the error coefficients to first order, so the plan's
    whitened Jacobian at `machine` (the nominal machine, or a calibrated one) tells which
    parameter combinations it determines: the SVD of the column-scaled Jacobian, as
    `jaxvs check` reports it, with every right-singular vector whose singular value is
    below `1e-6` of the largest listed as an unidentifiable combination.

    **Arguments:** `machine`, a `CartesianMachine`; `tests`, the plan (a list of tests).

    **Returns:** an [`IdentifiabilityReport`][].

    **Raises:** `ValueError` when the plan sees none of the parameters.
    """
    tests = _assert_tests(tests)
    for t in tests:
        t.check(machine)
    J = np.asarray(plan_jacobian(machine, tests))
    names = parameter_names(machine)
    scale = np.linalg.norm(J, axis=0)
    if not np.any(scale > 0):
        raise ValueError(
            "identifiability: the test plan identifies nothing (its readings do not depend on "
            "any of the 21 error components); add laser, straightness, angular, ball-bar or "
            "diagonal tests that move the axes."
        )
    # heuristic: a column below 1e-9 of the largest is rounding of a parameter the plan does
    # not see (e.g. a linear term removed by a straightness optic's alignment); column
    # scaling would blow it up to look identified
    unseen = scale <= 1e-9 * scale.max()
    J = np.where(unseen, 0.0, J)
    scale[unseen] = 1.0
    _, s, vt = np.linalg.svd(J / scale, full_matrices=True)
    s_full = np.zeros(len(names))
    s_full[: s.size] = s
    smax = float(s_full[0])
    rel = s_full / smax
    null = rel < SINGULAR_RTOL
    content = {
        "plan": [t.label for t in tests],
        "n_readings": int(J.shape[0]),
        "parameters": names,
        "singular_values": [float(v) for v in s_full],
        "condition": float(s_full[0] / s_full[-1]) if s_full[-1] > 0 else math.inf,
        "rank": int(np.sum(~null)),
        "unidentifiable": [],
        "components": {},
    }
    for k in np.flatnonzero(null):
        direction = vt[k] / np.max(np.abs(vt[k]))
        combo = {n: float(w) for n, w in zip(names, direction) if abs(w) > 0.05}
        content["unidentifiable"].append({"relative": float(rel[k]), "combination": combo})
    weight = np.sum(vt[null] ** 2, axis=0) if null.any() else np.zeros(len(names))
    for comp in list(COMPONENTS) + ["B_X", "B_Y", "B_Z"]:
        idx = [i for i, n in enumerate(names) if n == comp or n.startswith(comp + "[")]
        content["components"][comp] = (
            "not identified" if np.any(weight[idx] > 1e-3) else "identified"
        )
    return IdentifiabilityReport(content)
