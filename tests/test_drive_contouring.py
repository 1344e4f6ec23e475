"""XY contouring and the ball-bar test against closed forms: lag circle, servo-mismatch
ellipse, squareness ellipse, lookup tables, reversal spikes."""

import numpy as np
import pytest

from jaxvs.models import (
    CoulombViscousFriction,
    DriveAxis,
    GeometricErrors,
    PositionLoop,
    RigidAxis,
    VelocityLoop,
    ViscousFriction,
    XYTable,
    ballbar_test,
    circle_path,
)

M, FV, KV = 10.0, 50.0, 2000.0
R, FEED, DT = 0.05, 0.05, 1e-3


def _axis(kp, fc=0.0, ki=0.0):
    friction = CoulombViscousFriction(fc, FV) if fc else ViscousFriction(FV)
    return DriveAxis(RigidAxis(M, friction), PositionLoop(kp), VelocityLoop(KV, ki))


def _G(kp, w):
    """Closed loop q/r of the rigid P–P cascade: kp kv / (m s² + (kv + Fv) s + kp kv)."""
    s = 1j * w
    return kp * KV / (M * s**2 + (KV + FV) * s + kp * KV)


def test_lag_circle_and_servo_mismatch_ellipse():
    w = FEED / R
    same = ballbar_test(XYTable(_axis(40.0), _axis(40.0)), R, FEED, DT)
    # identical linear axes in steady state: a circle of radius R |G(jω)|
    expect = R * (abs(_G(40.0, w)) - 1)
    # the reference is interpolated linearly between samples: chords sag by up to
    # R (ω dt)² / 8 = 6e-9 m inside the circle
    np.testing.assert_allclose(same.radial_error, expect, rtol=0, atol=1e-8)
    # mismatched gains: X = R|Gx| cos(ωt + φx), Y = R|Gy| sin(ωt + φy), an ellipse
    mis = ballbar_test(XYTable(_axis(40.0), _axis(25.0)), R, FEED, DT)
    gx, gy = _G(40.0, w), _G(25.0, w)
    lead = np.pi / 2  # circle_path's default lead-in
    phase = w * np.asarray(mis.t) - lead
    X = R * abs(gx) * np.cos(phase + np.angle(gx))
    Y = R * abs(gy) * np.sin(phase + np.angle(gy))
    # the start-up transient has decayed to < 1e-9 m after the lead-in (poles ≥ 25 1/s);
    # chord sag of the interpolated reference as above
    np.testing.assert_allclose(mis.radial_error, np.hypot(X, Y) - R, atol=1e-8)
    e, th = np.asarray(mis.radial_error), np.asarray(mis.theta)
    # the slower Y axis lags: the ellipse's long axis is at 135°/315°, short at 45°/225°
    assert np.degrees(th[np.argmax(e)]) % 180 == pytest.approx(135, abs=10)
    assert np.degrees(th[np.argmin(e)]) % 180 == pytest.approx(45, abs=10)


def test_geometric_errors_lookup_and_squareness():
    ge = GeometricErrors(
        positioning_x=([0.0, 0.1], [0.0, 2e-5]),
        straightness_x=([0.0, 0.1], [1e-6, -1e-6]),
        squareness=1e-4,
    )
    X, Y = ge(np.array([0.05]), np.array([0.02]))
    # δxx(0.05) = 1e-5 (linear table), α y = 2e-6; δyx(0.05) = 0
    assert float(X[0]) == pytest.approx(0.05 + 1e-5 + 2e-6, rel=1e-12)
    assert float(Y[0]) == pytest.approx(0.02, rel=1e-12)
    # squareness alone on a perfect circle: ΔR ≈ (R α / 2) sin 2θ to first order in α
    alpha = 2e-4
    _, x, y, theta = circle_path(R, FEED, DT, lead=0.0)
    X, Y = GeometricErrors(squareness=alpha)(x, y)
    dR = np.hypot(np.asarray(X), np.asarray(Y)) - R
    np.testing.assert_allclose(dR, R * alpha / 2 * np.sin(2 * theta), atol=R * alpha**2)


def test_reversal_spikes_with_coulomb_friction():
    # a PI velocity loop integrates the friction out between reversals (a P loop would
    # leave a following error Fc / (kp kv) that flips sign at every reversal)
    axis = _axis(40.0, 20.0, 100.0)
    res = ballbar_test(XYTable(axis, axis), R, FEED, DT)
    e = np.asarray(res.radial_error)
    th = np.degrees(np.asarray(res.theta))
    dev = np.abs(e - np.median(e))
    # an axis reverses at each quadrant (X at 0°/180°, Y at 90°/270°); the spikes follow
    # it within the loop's lag (here < 20° of travel)
    spikes = th[dev > 0.5 * dev.max()]
    quadrants = np.array([0, 90, 180, 270])
    dist = np.min(np.abs((spikes[:, None] - quadrants + 180) % 360 - 180), axis=1)
    assert np.all(dist < 20)
    # away from the reversals the friction is a constant force, rejected by the loop
    assert dev.max() > 20 * np.median(dev)


def test_bad_input():
    with pytest.raises(ValueError, match="too coarse"):
        circle_path(0.01, 10.0, 1e-3)
    with pytest.raises(ValueError, match="increasing"):
        GeometricErrors(positioning_x=([0.1, 0.0], [0.0, 1e-6]))
    with pytest.raises(TypeError, match="DriveAxis"):
        XYTable("x", _axis(40.0))
