"""The next experiment: two formulas that the record cannot tell apart (a force `c·v|v|`
seen only at speeds between 60 and 100 mm/s, where `v³` fits it nearly as well, at a
noise of 10 N), an excitation within the record's limits that separates them, and
discovery on the record with the proposed experiment added picks the true one.

The plant is written here: a carriage (10 kg, 60 N·s/m, 2 N offset) in a PD position
loop, integrated by a fourth-order Runge–Kutta at 1 kHz (nothing of jaxvs's models)."""

import numpy as np
import pytest

from jaxvs.calibration import log_evidence
from jaxvs.data import Record, split_blocks
from jaxvs.diagnosis import GapModel, discover
from jaxvs.diagnosis._drive import DriveFamily
from jaxvs.diagnosis._next_experiment import Limits, candidates

FS = 1000.0


def _plant(extra, r, noise, seed, M=10.0, Fv=60.0, off=2.0) -> Record:
    rng = np.random.default_rng(seed)
    n, h = r.size, 1 / FS
    wn = 2 * np.pi * 15
    kp, kd = M * wn**2, 2 * 0.7 * M * wn
    dr = np.gradient(r, h)

    def f(s, k):
        u = kp * (r[k] - s[0]) + kd * (dr[k] - s[1])
        return np.array([s[1], (u - Fv * s[1] - off - extra(s[1])) / M])

    out = np.zeros((n, 2))
    s = np.array([r[0], dr[0]])
    for k in range(n):
        out[k] = s
        k1 = f(s, k)
        k2 = f(s + h / 2 * k1, k)
        k3 = f(s + h / 2 * k2, k)
        k4 = f(s + h * k3, min(k + 1, n - 1))
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    x, v = out.T
    u = kp * (r - x) + kd * (dr - v) + noise * rng.normal(size=n)
    return Record({"q": np.round(x / 1e-6) * 1e-6, "u": u}, dt=h)


def _strokes(n):
    """Strokes back and forth at speeds between 60 and 100 mm/s (a narrow range)."""
    t = np.arange(n) / FS
    sq = np.tanh(8 * np.sin(2 * np.pi * t))
    return np.cumsum((0.08 + 0.02 * np.sin(2 * np.pi * t / 3.7)) * sq) / FS


def _true(v):
    return 2000.0 * v * abs(v)


def _split(records):
    fam = DriveFamily()
    cal, val = [], []
    for i, rec in enumerate(records):
        a, b = split_blocks(rec, (0.7, 0.3))
        cal.append(fam.prepare(a, f"cal {i}"))
        val.append(fam.prepare(b, f"val {i}"))
    return fam, cal, val


def _discover(records):
    fam, cal, val = _split(records)
    return discover(
        GapModel(fam.nominal(cal)), cal, val, family=fam, n_null=0, n_boot=20, n_stability=10
    )


def _log_ratio(records) -> float:
    """Log evidence of `v|v|` over `v³` on the prepared records, each beside the rigid
    axis's columns (`a`, `v`, 1), g-prior with g = N."""
    _, cal, val = _split(records)
    ex = cal + val
    a, v, y = (np.concatenate([e.arrays[k] for e in ex]) for k in ("a", "v", "y"))
    base = np.column_stack([a, v, np.ones_like(v)])
    n = y.size

    def ssr(cols):
        A = np.column_stack([base, *cols])
        r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
        return float(r @ r)

    s0 = ssr([])
    ev = [log_evidence(ssr([c]), s0, n - 3, 1, n) for c in (v * np.abs(v), v**3)]
    return ev[0] - ev[1]


def test_candidates_stay_within_the_limits():
    lim = Limits((-0.01, 0.03), 0.1, 5.0, None, (0.3, 50.0), 0.002, 6.0)
    cands = candidates(lim)
    assert {c[0] for c in cands} == {"sine", "trapezoid"}
    for _, _, t, x in cands:
        v = np.gradient(x, t)
        assert -0.01 - 1e-12 <= x.min() and x.max() <= 0.03 + 1e-12
        assert np.max(np.abs(v)) <= 0.1 * 1.02
        assert x[0] == 0.0 and abs(v[0]) <= 5.0 * 0.002  # from rest at the start position


@pytest.mark.slow
def test_the_next_experiment_separates_two_nearly_equal_formulas(tmp_path):
    record = _plant(_true, _strokes(10000), noise=10.0, seed=0)
    d = _discover([record])
    nxt = d.next_experiment
    assert nxt is not None, d.message
    assert set(nxt.formulas) == {"v|v|", "v^3"}
    assert abs(nxt.log_evidence_ratio) < np.log(10)
    # the two formulas disagree on the proposal at least 10 times more (mean square)
    # than on the record
    assert nxt.gain >= 10.0
    # ready to run: the CSV holds the reference; within the record's travel and speed
    path = d.save_next_experiment(tmp_path / "next.csv")
    t, q_ref = np.loadtxt(path, delimiter=",", skiprows=1).T
    lim = nxt.limits
    assert np.ptp(q_ref) <= lim["travel"][1] - lim["travel"][0]
    assert np.max(np.abs(np.gradient(q_ref, t))) <= 1.02 * lim["speed"]
    # run it on the plant
    t_new = np.arange(int(t[-1] * FS)) / FS
    r_new = np.interp(t_new, t, q_ref) + record["q"][0]
    new = _plant(_true, r_new, noise=10.0, seed=1)
    # the two formulas' evidence beside the rigid axis (mass, viscous, offset), by plain
    # least squares (g = N, no discount for correlated samples): the proposed experiment
    # adds more than a factor 10 for v|v| to what the record says (alone it says
    # little: at one speed both are nearly linear in v, which the viscous term takes)
    assert _log_ratio([record, new]) > _log_ratio([record]) + np.log(10)
