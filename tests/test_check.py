"""`jaxvs.check`: data quality and identifiability before calibration (small synthetic
records with known defects; the oracle is the defect that was built in)."""

import json

import numpy as np
import pytest

import jaxvs
from jaxvs._cli import main
from jaxvs.data import Record, save_csv


def drive_record(*, both_ways=True, clip=None, n=3000, fs=1000.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    # smooth multi-sine motion [m]; one-way: the same plus a ramp that dominates
    q = 0.01 * np.sin(2 * np.pi * 0.7 * t) + 0.004 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    if not both_ways:
        q = 0.2 * t + 0.0005 * np.sin(2 * np.pi * 3.1 * t)
    v = np.gradient(q, 1 / fs)
    a = np.gradient(v, 1 / fs)
    u = 95.0 * a + 200.0 * v - 3.0 + 0.5 * rng.standard_normal(n)  # M, Fv, offset (EMPS-like)
    if clip is not None:
        u = np.clip(u, -clip, clip)
    return Record({"q": q, "u": u}, dt=1 / fs, units={"q": "m", "u": "N"})


def thermal_record(*, collinear=False, n=400):
    t = np.arange(n) * 5.0
    tc = 20 + 8 * (1 - np.exp(-t / 900.0)) + 0.5 * np.sin(t / 300.0)
    vm = 3000 + 2000 * np.sin(t / 500.0) ** 2
    if collinear:
        vm = 100.0 * tc  # speed exactly proportional to the chassis temperature
    tb = 21 + 1.2 * (tc - 20) + 0.0004 * (vm - 3000)
    return Record({"T_chassis": tc, "T_bearing": tb, "v_m": vm}, dt=5.0)


def test_drive_with_motion_both_ways_is_identifiable():
    report = jaxvs.check(drive_record(), family="drive")
    assert report.ok and report.exit_code == 0, report.content["blocking"]
    ident = report.content["jacobian"]
    assert len(ident["singular_values"]) == 3 and not ident["unidentifiable"]
    rec = report.content["records"][0]
    assert rec["reversals"] >= 2 and 0.2 < rec["share_moving_positive"] < 0.8
    assert rec["fs"] == pytest.approx(1000.0)


def test_drive_moving_one_way_is_refused():
    report = jaxvs.check(drive_record(both_ways=False), family="drive")
    assert not report.ok and report.exit_code == 3
    assert any("one direction only" in b for b in report.content["blocking"])


def test_clipped_force_is_reported():
    report = jaxvs.check(drive_record(clip=20.0), family="drive")
    findings = report.content["warnings"] + report.content["blocking"]  # blocking above 20 %
    assert any("'u' sits at its minimum or maximum" in w for w in findings)
    assert report.content["records"][0]["signals"]["u"]["clipped_share"] > 0.01


def test_collinear_inputs_name_the_unidentifiable_combination():
    report = jaxvs.check(thermal_record(collinear=True), family="thermal", smoothing_s=0.0)
    assert not report.ok
    (combo,) = report.content["jacobian"]["unidentifiable"]
    # the chassis and speed coefficients trade off (and the intercept with them)
    assert len(combo["combination"]) >= 2
    assert any("not identifiable" in b for b in report.content["blocking"])
    ok = jaxvs.check(thermal_record(), family="thermal", smoothing_s=0.0)
    assert ok.ok, ok.content["blocking"]


def test_constant_input_is_blocking():
    rec = thermal_record()
    flat = rec.with_signal("T_chassis", np.full(len(rec), 25.0))
    report = jaxvs.check(flat, family="thermal")
    assert not report.ok
    assert any("'T_chassis' is constant" in b for b in report.content["blocking"])


def test_user_errors():
    with pytest.raises(ValueError, match="unknown family 'spindle'"):
        jaxvs.check(drive_record(), family="spindle")
    with pytest.raises(ValueError, match="lacks the required signal"):
        jaxvs.check(drive_record().rename({"u": "force"}), family="drive")


def test_cli_exit_codes_and_report(tmp_path):
    good, bad = tmp_path / "good.csv", tmp_path / "bad.csv"
    save_csv(thermal_record(), good)
    save_csv(thermal_record(collinear=True), bad)
    out = tmp_path / "report"
    opts = ["--option", "smoothing_s=0"]
    assert main(["check", str(good), "--family", "thermal", "--out", str(out), *opts]) == 0
    content = json.loads((out / "report.json").read_text())
    assert content["identifiable"] is True and (out / "report.md").exists()
    assert main(["check", str(bad), "--family", "thermal", *opts]) == 3
    assert main(["check", str(tmp_path / "missing.csv"), "--family", "thermal"]) == 2
    assert main(["check", str(good), "--family", "drive"]) == 2  # no q, u: user error


def test_signal_quality_tells_held_set_points_from_clipping():
    """A speed profile of held operating points sits at its extremes for long stretches
    by design (no warning); a sine of amplitude 2 clipped at ±1 sits there because of the
    clipping (warning; oracle: the share of samples where |2 sin| >= 1, 2/3)."""
    from jaxvs.data import signal_quality

    speed = np.repeat([0.0, 1500.0, 3000.0, 4500.0, 0.0, 3000.0], 100)
    force = 2.0 * np.sin(2 * np.pi * np.arange(600) / 100 + 0.1)
    clipped = np.clip(force, -1.0, 1.0)
    summary, blocking, warnings = signal_quality({"v_m": speed, "u": clipped}, name="r")
    assert not blocking
    assert summary["v_m"]["held_share"] > 0.9  # only the steps between levels differ
    assert not [w for w in warnings if "'v_m'" in w]
    # equal up to the samples where the sine crosses ±1 between two samples (tie rounding)
    assert summary["u"]["clipped_share"] == pytest.approx(np.mean(np.abs(force) >= 1.0), abs=0.01)
    assert [w for w in warnings if "'u' sits at its minimum or maximum" in w]
    _, blocking, _ = signal_quality({"u": np.ones(50)}, name="r", required=("u",))
    assert blocking == ["r: signal 'u' is constant; it carries no information."]
