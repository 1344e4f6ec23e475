"""The measurement's noise and the nonlinear distortion of records that repeat.

When the excitation of a record repeats in whole periods (a periodic reference of a
drive, a multisine shaker signal of a TMF), the noise is measured, not modelled: it is
what changes from period to period. Several such records with the same period are
realisations, and what changes from realisation to realisation beyond the noise is
nonlinear distortion (`jaxvs.signal.best_linear_approximation`, Pintelon & Schoukens).
With one realisation, the distortion shows at the lines the excitation leaves empty. A
distortion above the noise is a finding -- a nonlinearity of the set-up -- never part of
the noise floor.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..signal import best_linear_approximation, find_period, settled_periods
from ._base import Experiment

__all__ = ["PAIRS", "nonlinear_distortion"]

# the excitation and the response each family's records repeat in
PAIRS = {"drive": ("r", "u"), "tmf": ("x_e", "x_t")}


def nonlinear_distortion(family: str, experiments: Sequence[Experiment]) -> dict[str, Any]:
    """The noise and distortion levels of the records that repeat, as a share of the
    response's RMS (the gap's unit). `{"available": False, "reason": ...}` when no record
    has at least two whole periods of its excitation."""
    pair = PAIRS.get(family)
    if pair is None:
        return {"available": False, "reason": f"the {family} family has no periodic excitation"}
    u_name, y_name = pair
    groups: dict[int, list[tuple[np.ndarray, np.ndarray, str]]] = {}
    for e in experiments:
        rec = e.source
        if rec is None or u_name not in rec.names or y_name not in rec.names:
            continue
        u = np.asarray(rec[u_name], float)
        y = np.asarray(rec[y_name], float)
        period = find_period(u, rtol=1e-3)
        if period is None:
            continue
        groups.setdefault(period, []).append((u, y, e.name))
    if not groups:
        return {
            "available": False,
            "reason": f"no record repeats its excitation {u_name!r} in two whole periods",
        }
    # the period most records share; its records are the realisations
    period, group = max(groups.items(), key=lambda kv: (len(kv[1]), -kv[0]))
    n_per = min(u.size // period for u, _, _ in group)
    # the leading periods that hold the transient, the most any record needs
    skip = max(settled_periods(y[: n_per * period], period) for _, y, _ in group)
    p = n_per - skip
    if p < 2:
        return {"available": False, "reason": "fewer than 2 settled periods"}
    cut = slice(skip * period, (skip + p) * period)
    uu = np.stack([u[cut].reshape(p, period) for u, _, _ in group])
    yy = np.stack([y[cut].reshape(p, period) for _, y, _ in group])
    try:
        bla = best_linear_approximation(uu - uu.mean(), yy - yy.mean())
    except ValueError as err:
        return {"available": False, "reason": str(err)}
    scale = float(np.sqrt(np.mean(yy**2)))
    noise = bla.noise_level / scale if scale > 0 else float("nan")
    dist = bla.distortion_level / scale if scale > 0 else float("nan")
    ratio = dist / noise if noise > 0 else float("inf")
    finding = None
    if ratio > 1.0:
        finding = (
            f"a nonlinearity: the response's distortion ({100 * dist:.3g} % of its RMS) is "
            f"{ratio:.3g}× the measurement noise ({100 * noise:.3g} %); it is a finding, "
            "not part of the noise floor"
        )
    return {
        "available": True,
        "input": u_name,
        "output": y_name,
        "period_samples": int(period),
        "periods": int(p),
        "realisations": int(bla.realisations),
        "records": [name for _, _, name in group],
        "method": (
            "realisation-to-realisation spread of the best linear approximation"
            if bla.realisations >= 2
            else "output power at the lines the excitation leaves empty"
        ),
        "noise_level": noise,
        "distortion_level": dist,
        "distortion_over_noise": ratio,
        "finding": finding,
    }
