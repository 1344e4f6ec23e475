"""Bode diagrams of the position loop from simulated white-noise and swept-sine runs (H1
estimate) against the linearised closed loop, lumped vs distributed ball screw."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxvs.data import swept_sine, white_noise
from jaxvs.models import BallScrew, DriveAxis, PositionLoop, VelocityLoop, ViscousFriction
from jaxvs.signal import frf_h1

DT = 1e-3
N = 8192


@pytest.fixture(scope="module")
def drive():
    screw = BallScrew(0.8, 0.025, 0.01, nut_stiffness=2e8, bearing_stiffness=4e8)
    mech = screw.lumped_axis(1.5e-4, 150.0, ViscousFriction(300.0), damping=2e-4)
    # 154 kg motor side + 150 kg table, resonance 145 Hz; the velocity loop (kv / m ≈ 160
    # 1/s) stays well below it
    return DriveAxis(mech, PositionLoop(30.0), VelocityLoop(5e4, 20.0))


def test_h1_of_periodic_white_noise_matches_linearised_loop(drive):
    period = N // 2
    r1 = white_noise(period, DT, bandwidth=200.0, rms=1e-5, seed=3)  # periodic by design
    res = drive.simulate(jnp.asarray(np.tile(r1, 2)), DT, rtol=1e-10, atol=1e-15)
    y = np.asarray(res.position)[period:]  # steady state: the second period
    est = frf_h1(r1, y, 1 / DT, window="boxcar", nperseg=period, detrend="none")
    f = np.asarray(est.frequency)
    band = (f >= 1.0) & (f <= 80.0)
    H = np.asarray(est.H)[band]
    # oracle: the linearised closed loop times the first-order hold of the simulation's
    # linear interpolation between samples, sinc²(f dt) (zero phase); aliasing of
    # G(j(ω + k ωs)) is below 1e-6 relative here. One exact period: no leakage,
    # coherence 1; what is left is the solver's rtol.
    G = np.asarray(drive.frequency_response(2 * np.pi * f[band])) * np.sinc(f[band] * DT) ** 2
    np.testing.assert_allclose(H, G, rtol=1e-5)


def test_h1_of_swept_sine_matches_linearised_loop(drive):
    r = swept_sine((N, DT), 0.5, 200.0, method="logarithmic", amplitude=1e-5)
    res = drive.simulate(jnp.asarray(r), DT, rtol=1e-10, atol=1e-15)
    est = frf_h1(r, np.asarray(res.position), 1 / DT, nperseg=2048)
    f = np.asarray(est.frequency)
    band = (f >= 2.0) & (f <= 40.0)
    H = np.asarray(est.H)[band]
    G = np.asarray(drive.frequency_response(2 * np.pi * f[band]))
    # a sweep is not periodic: Welch segments cut through transients (leakage) and the
    # sweep is fast at low frequency; 6 % in magnitude and 0.1 rad cover that
    np.testing.assert_allclose(np.abs(H), np.abs(G), rtol=0.06)
    np.testing.assert_allclose(np.angle(H / G), 0.0, atol=0.1)


def test_lumped_and_distributed_screw_share_the_first_resonance():
    screw = BallScrew(0.8, 0.025, 0.01, nut_stiffness=2e8, bearing_stiffness=4e8)
    lumped = screw.lumped_axis(1.5e-4, 150.0)
    dist = screw.distributed_axis(1.5e-4, 150.0, n_segments=12)
    w_l = np.asarray(lumped.normal_modes().omega_n)
    w_d = np.asarray(dist.normal_modes().omega_n)
    # the lumped model puts the whole screw inertia on the motor side; the distributed one
    # spreads it along the shaft, which stiffens the first mode slightly (a few %) and adds
    # the shaft's torsional modes far above it
    assert abs(w_d[1] - w_l[1]) / w_l[1] < 0.05
    assert w_d[2] > 5 * w_d[1]
