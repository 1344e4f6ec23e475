"""The verdict's four states, the evidence of a large effect partly explained, and the
noise and nonlinear distortion measured on records that repeat.

Oracles: the states' definitions on hand-made null distributions; the
effective sample size of an AR(1) noise `(1 − ρ)/(1 + ρ)·N` (Box, Jenkins & Reinsel);
the period-to-period variance of a known noise; a static cubic's distortion against a
linear system's.
"""

import math

import numpy as np
import pytest

from jaxvs.data import Record
from jaxvs.diagnosis._acceptance import evidence_samples, noise_sample_share
from jaxvs.diagnosis._distortion import nonlinear_distortion
from jaxvs.diagnosis._report import DiagnosisReport
from jaxvs.diagnosis._stats import bic_effective, effective_samples
from jaxvs.diagnosis._tmf import TMFFamily, record_noise
from jaxvs.diagnosis._verdict import decide, status_line

NULL = [0.010 + 0.0002 * k for k in range(19)]  # held-out gaps of 19 null records
P95 = float(np.quantile(NULL, 0.95))
CELLS = [
    {"axis": "time", "label": "t = 8–10 s", "share": 0.55, "fraction": 0.1,
     "enrichment": 5.5, "p_value": 0.001, "significant": True, "gap": 0.2},
    {"axis": "operating_point", "label": "speed in [0.1, 0.3]", "share": 0.4,
     "fraction": 0.25, "enrichment": 1.6, "p_value": 0.004, "significant": True, "gap": 0.1},
    {"axis": "frequency", "label": "1–2 Hz", "share": 0.9, "fraction": 0.05,
     "enrichment": 18.0, "p_value": 1e-9, "significant": True, "gap": None},
    {"axis": "time", "label": "t = 0–2 s", "share": 0.3, "fraction": 0.1,
     "enrichment": 3.0, "p_value": 0.3, "significant": False, "gap": 0.05},
]  # fmt: skip


@pytest.mark.parametrize(
    "accepted, gap, status",
    [
        ([], 0.9 * P95, "adequate"),
        (["coulomb_friction"], 0.9 * P95, "explained"),
        (["coulomb_friction"], 3.0 * P95, "partly_explained"),
        ([], 3.0 * P95, "unexplained"),
    ],
)
def test_the_four_states_and_where_the_remainder_lies(accepted, gap, status):
    v = decide(accepted, gap, NULL, noise_floor=0.011, cells_after=CELLS, tolerance=0.25)
    assert v["status"] == status
    assert v["adequate"] is (status == "adequate")
    rem = v["remainder"]
    assert rem["null_p95"] == pytest.approx(P95)
    assert rem["threshold"] == pytest.approx(1.25 * P95)
    assert rem["over_floor"] == pytest.approx(gap / 0.011)
    if status in ("adequate", "explained"):
        assert rem["within_null"] and rem["where"] == []
    else:
        # significant time / operating-point cells only, most concentrated first, each
        # with its share and its test
        assert not rem["within_null"]
        assert [w["label"] for w in rem["where"]] == ["t = 8–10 s", "speed in [0.1, 0.3]"]
        assert rem["where"][0]["share"] == 0.55 and rem["where"][0]["p_value"] == 0.001
        assert "permutation" in rem["where"][0]["test"]
    line = status_line({"effects": accepted, "status": status, **v})
    assert line.startswith(f"verdict: {status.replace('_', ' ')}")
    if status == "unexplained":
        assert "t = 8–10 s (share 0.55, p = 0.001)" in line


def test_the_bound_is_the_null_quantile_widened_by_the_tolerance():
    # just inside and just outside (1 + tolerance) × the 95th percentile
    assert decide([], 1.24 * P95, NULL, 0.011)["status"] == "adequate"
    assert decide([], 1.26 * P95, NULL, 0.011)["status"] == "unexplained"
    assert decide([], 1.01 * P95, NULL, 0.011, tolerance=0.0)["status"] == "unexplained"
    # without a null nothing is above it
    assert decide([], 5.0, [], 0.011)["status"] == "adequate"


def test_report_says_the_state_first_and_old_reports_still_render():
    v = decide([], 3 * P95, NULL, 0.011, CELLS)
    verdict = {
        "effects": [],
        "final_effects": [],
        "primary": None,
        "validation_gap": 3 * P95,
        "calibration_gap": 0.03,
        "shrink": 0.0,
        "shrink_interval": [0.0, 0.0],
        "remaining_over_noise": 3 * P95 / 0.011,
        "parameters": {},
        **v,
    }
    verdict["status_line"] = status_line(verdict)
    content = {
        "family": "drive",
        "gap": {"metric": "nrmse", "calibration": 0.03, "validation": 3 * P95,
                "noise_floor": 0.011},
        "where": [],
        "candidates": [],
        "verdict": verdict,
        "nominal": {"model": "rigid axis"},
        "timing": {"seconds": 1.0},
    }  # fmt: skip
    rep = DiagnosisReport(content)
    md = rep.to_markdown().splitlines()
    assert md[2] == f"**{rep.status_line}**" and rep.status_line.startswith("verdict: unexplained")
    assert "### Where the remainder lies" in md
    assert repr(rep).splitlines()[1] == rep.status_line
    assert rep.status == "unexplained"
    # a report written before the states (no status, no remainder) still renders
    old = {**verdict}
    for k in ("status", "remainder", "status_line", "adequate"):
        old.pop(k)
    rep_old = DiagnosisReport({**content, "verdict": old})
    assert rep_old.status is None
    assert rep_old.status_line == "verdict: no effect accepted"
    assert "## Verdict" in rep_old.to_markdown()
    # no verdict at all: the record did not identify the model
    assert status_line(None, "one direction only").startswith("verdict: none")


def _ar1(rng, n, rho):
    w = rng.standard_normal(n)
    e = np.empty(n)
    e[0] = w[0]
    for i in range(1, n):
        e[i] = rho * e[i - 1] + math.sqrt(1 - rho * rho) * w[i]
    return e


def test_a_large_effect_partly_explained_keeps_its_evidence():
    # A gap 18× the floor; a candidate removes 57 % of it and leaves a slow structure
    # (a period of 4000 samples) on top of white noise. The residual's own correlation
    # time counts the 8000 samples as a handful, so the old ΔBIC rejected the candidate;
    # the noise's sample share (white: 1) bounds the evidence from below.
    rng = np.random.default_rng(0)
    n = 8000
    noise = rng.standard_normal(n)
    slow = np.sin(2 * np.pi * np.arange(n) / 4000)
    gap_before = 18.0
    r0 = noise + gap_before * slow * math.sqrt(2)
    r1 = noise + 0.43 * gap_before * slow * math.sqrt(2)
    ssr0, ssr1 = float(r0 @ r0), float(r1 @ r1)
    n_old = effective_samples(r1)
    assert n_old < 20  # the structure left behind, not the noise
    share = noise_sample_share([[rng.standard_normal(n)] for _ in range(5)])
    assert share == pytest.approx(1.0, abs=0.1)
    n_new = evidence_samples(r1, share)
    assert n_new == pytest.approx(n, rel=0.1)
    dbic = lambda ne: bic_effective(ssr0, n, 3, ne) - bic_effective(ssr1, n, 5, ne)  # noqa: E731
    assert dbic(n_old) < 10 < dbic(n_new)
    # a coloured noise keeps its own discount: AR(1) with ρ = 0.9 carries (1 − ρ)/(1 + ρ)
    # of the samples (0.053; within 30 % from five 8000-sample records)
    share_ar = noise_sample_share([[_ar1(rng, n, 0.9)] for _ in range(5)])
    assert share_ar == pytest.approx(0.1 / 1.9, rel=0.3)


def _tmf_record(rng, x_e, cubic: float, sigma: float, dt: float) -> Record:
    # a lightly damped mode between x_e and x_t (scipy), an optional cubic sensor error
    import scipy.signal as ss

    om, z = 2 * np.pi * 40.0, 0.03
    b, a, _ = ss.cont2discrete(([om * om], [1, 2 * z * om, om * om]), dt, method="zoh")
    x_t = ss.lfilter(np.ravel(b), a, x_e)
    d = x_t - x_t.mean()
    x_t = x_t + cubic * d**3 / np.var(d) + sigma * rng.standard_normal(x_t.size)
    return Record({"x_e": x_e, "x_t": x_t}, dt=dt)


def _multisine(rng, n_period, periods, dt):
    k = np.arange(1, 60)
    t = np.arange(n_period) * dt
    phi = rng.uniform(0, 2 * np.pi, k.size)
    one = np.sum(np.cos(2 * np.pi * np.outer(t, k) / (n_period * dt) + phi), axis=1)
    return 1e-5 * np.tile(one / np.std(one), periods)


def test_repeated_periods_measure_the_noise_and_show_a_nonlinearity():
    rng = np.random.default_rng(3)
    dt, n_period, periods, sigma = 1e-3, 500, 8, 2e-8
    fam = TMFFamily()
    x_e = _multisine(rng, n_period, periods, dt)
    lin = fam.prepare(_tmf_record(rng, x_e, 0.0, sigma, dt), "linear")
    cub = fam.prepare(_tmf_record(rng, x_e, 0.05, sigma, dt), "cubic")
    # the noise floor from the period-to-period variation: the true σ² within 15 %
    # (5 × 500 degrees of freedom after the first period), also with the cubic error in
    # the record: a nonlinearity cannot hide in it
    for exp in (lin, cub):
        var, rho = record_noise(exp, [], 150)
        assert var == pytest.approx(sigma**2, rel=0.15)
        assert rho < 0.1
        assert exp.noise_var == pytest.approx(sigma**2, rel=0.15)
    d_lin = nonlinear_distortion("tmf", [lin])
    d_cub = nonlinear_distortion("tmf", [cub])
    assert d_lin["available"] and d_lin["periods"] >= periods - 3
    assert d_lin["period_samples"] == n_period and d_lin["realisations"] == 1
    assert d_lin["finding"] is None and d_lin["distortion_over_noise"] < 1.0
    assert d_cub["distortion_over_noise"] > 5.0
    assert "nonlinearity" in d_cub["finding"]
    # two realisations (new phases): the distortion from their spread
    x_e2 = _multisine(rng, n_period, periods, dt)
    cub2 = fam.prepare(_tmf_record(rng, x_e2, 0.05, sigma, dt), "cubic 2")
    d2 = nonlinear_distortion("tmf", [cub, cub2])
    assert d2["realisations"] == 2 and d2["distortion_over_noise"] > 5.0
    # a record that does not repeat has nothing to say; a family without a periodic
    # excitation neither
    rand = fam.prepare(_tmf_record(rng, 1e-5 * rng.standard_normal(3000), 0.0, sigma, dt), "r")
    assert nonlinear_distortion("tmf", [rand])["available"] is False
    assert nonlinear_distortion("thermal", [rand])["available"] is False


def test_report_json_carries_its_schema_version(tmp_path):
    """Every report's `to_json()` is `content` plus `schema_version` (an integer): a
    report built from a dictionary writes every key it was given with the same value (and
    the rest of the schema)."""
    from jaxvs.diagnosis._check import CHECK_SCHEMA_VERSION, CheckReport
    from jaxvs.diagnosis._report import SCHEMA_VERSION
    from jaxvs.studies.design._report import SCHEMA_VERSION as DESIGN_SCHEMA_VERSION

    content = {"family": "drive", "verdict": None, "not_identifiable": "one direction only",
               "nominal": {"model": "rigid axis", "parameters": {}}, "gap": None}  # fmt: skip
    out = DiagnosisReport(content).to_json()
    assert out.pop("schema_version") == SCHEMA_VERSION == 2
    assert {k: out[k] for k in content} == content
    check = CheckReport({"family": "drive", "identifiable": False, "records": []})
    assert check.to_json() == {"schema_version": CHECK_SCHEMA_VERSION, **check.content}
    assert isinstance(DESIGN_SCHEMA_VERSION, int)
