"""What the drive family refuses, and what it fixes with a warning instead.

A record is refused only when the calibrated rigid-axis parameters are not identifiable
(the axis does not move, moves one way only, or the column-scaled Jacobian of the
calibrated parameters is rank-deficient); one velocity reversal suffices, and a mass the
record does not excite is fixed (at zero or the `mass` option) with a warning that
`jaxvs check` and the diagnosis report both carry. Oracles: records built here with
numpy whose excitation is known by construction, and the least-squares fit of the
remaining parameters (`np.linalg.lstsq`).
"""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxvs
from jaxvs.data import Record
from jaxvs.diagnosis._base import GapModel
from jaxvs.diagnosis._drive import (
    DriveFamily,
    RigidNominal,
    jacobian_refusal,
    mass_not_excited,
)


def _gates(rec, **options):
    """`jaxvs check`'s verdict and the diagnosis' own gate on the same calibration data."""
    fam = DriveFamily(**options)
    exp = fam.prepare(rec, "record")
    nominal = fam.nominal([exp])
    why = fam.identifiability([exp], GapModel(nominal))
    warnings = fam.nominal_warnings([exp])
    return jaxvs.check(rec, family="drive", **options), warnings, nominal, why


def out_and_back(n=4000, fs=1000.0, seed=0):
    """One move out and one back (a single velocity reversal): quintic profiles of 50 mm,
    a 20 kg axis with viscous friction, offset and Coulomb friction."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    s = np.clip((t - 0.2) / 1.5, 0, 1)
    back = np.clip((t - 2.2) / 1.5, 0, 1)
    q = 0.05 * (s**3 * (10 - 15 * s + 6 * s**2) - back**3 * (10 - 15 * back + 6 * back**2))
    v = np.gradient(q, 1 / fs)
    a = np.gradient(v, 1 / fs)
    u = 20 * a + 60 * v + 2 + 15 * np.tanh(v / 1e-3) + 0.3 * rng.standard_normal(n)
    return Record({"q": np.round(q / 1e-6) * 1e-6, "u": u}, dt=1 / fs)


def friction_rig(n=6000, fs=500.0, seed=1):
    """A quasi-static friction rig: a 0.5 Hz stroke of ±20 mm against 800 N of dry
    friction, the load cell between actuator and friction element (no inertia in the
    measured force), 5 N of noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    q = 0.02 * np.sin(2 * np.pi * 0.5 * t)
    v = np.gradient(q, 1 / fs)
    u = 800 * np.tanh(v / 2e-3) + 5 * rng.standard_normal(n)
    return Record({"q": q, "u": u}, dt=1 / fs)


def test_one_reversal_suffices():
    v = np.gradient(np.asarray(out_and_back()["q"]))
    fast = v[np.abs(v) > 0.05 * np.abs(v).max()]
    assert np.sum(np.diff(np.sign(fast)) != 0) == 1  # one reversal by construction
    check, _, nominal, why = _gates(out_and_back())
    assert why is None and check.ok, check.content["blocking"]
    assert float(nominal.M) == pytest.approx(20.0, rel=0.05)  # the mass stays calibrated


def test_an_unexcited_mass_is_fixed_with_a_warning_not_refused():
    rec = friction_rig()
    check, warnings, nominal, why = _gates(rec)
    assert why is None and check.ok, check.content["blocking"]
    assert isinstance(nominal.M, float) and nominal.M == 0.0  # fixed: no calibrated leaf
    # the remaining parameters are the least-squares fit without the inertia
    exp = DriveFamily().prepare(rec, "rig")
    phi = np.stack([exp.arrays["v"], np.ones(exp.n)], -1)
    (fv, off), *_ = np.linalg.lstsq(phi, exp.y, rcond=None)
    assert float(nominal.Fv) == pytest.approx(fv, rel=1e-9)
    assert float(nominal.offset) == pytest.approx(off, rel=1e-6, abs=1e-9)
    # the same warning in `jaxvs check` and in what the diagnosis reports (its check)
    (warning,) = warnings
    assert "the inertia is not excited" in warning and "fixed at 0 kg" in warning
    assert warning in check.content["warnings"]
    assert "mass" in check.to_markdown()
    # the Jacobian has no mass column: only Fv and the offset are calibrated
    assert check.content["jacobian"]["parameters"] == ["Fv", "offset"]


def test_a_stated_mass_is_used_when_the_record_does_not_excite_it():
    _, warnings, nominal, why = _gates(friction_rig(), mass=12.5)
    assert why is None and nominal.M == 12.5
    assert "fixed at 12.5 kg (the mass option)" in warnings[0]
    # an excited mass is calibrated, the option is not used
    _, warnings, nominal, _ = _gates(out_and_back(), mass=12.5)
    assert not isinstance(nominal.M, float) and not warnings


def test_mass_excitation_oracle():
    fam = DriveFamily()
    assert mass_not_excited([fam.prepare(out_and_back(), "x")]) is None
    why = mass_not_excited([fam.prepare(friction_rig(), "x")])
    assert why is not None and "M =" in why


def test_a_rank_deficient_jacobian_names_the_parameter_and_what_to_record():
    # constant speed: the viscous friction and the offset are one column (the direction
    # rule refuses such a record first; the Jacobian test names the parameters)
    rec = Record({"q": 0.01 * np.arange(3000) / 1000.0, "u": np.full(3000, 30.0)}, dt=1e-3)
    fam = DriveFamily()
    exp = fam.prepare(rec, "ramp")
    # a fixed mass, Fv and the offset calibrated
    nominal = RigidNominal(0.0, jnp.asarray(50.0), jnp.asarray(0.0))
    why = jacobian_refusal([exp], nominal)
    assert why is not None and "Fv and offset cannot be told apart" in why
    assert "is the least determined: record" in why  # names it and what to record
    assert "one direction" in fam.identifiability([exp], GapModel(nominal))
    check = jaxvs.check(rec, family="drive")
    assert not check.ok


def test_still_and_one_way_records_are_still_refused():
    n = 3000
    ramp = Record({"q": 0.01 * np.arange(n) / 1000.0, "u": np.full(n, 30.0)}, dt=1e-3)
    check, _, nominal, why = _gates(ramp)
    assert why is not None and "one direction" in why and not check.ok
