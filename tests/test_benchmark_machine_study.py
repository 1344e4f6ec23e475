"""The three-axis machine study (`benchmarks/machine_study.py`) in CI at a reduced size: its
contour-error measure, its paths and its three-drive simulation against independent
oracles. The whole study (calibration, 50³ map, suggestion, contouring) takes about four
minutes on 2 cores; `make bench` runs it at full size (degree 4, a 20 s path)."""

import jax
import numpy as np
import pytest
from benchmark_module import load_benchmark


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("machine_study")


def test_contour_error_is_the_distance_to_the_path(bench):
    """Points scattered around a unit circle given as a 2000-segment polyline: the
    measure equals the exact distance to the circle up to the polyline's chord sag
    (1 - cos(pi / 2000) = 1.2e-6)."""
    t = np.linspace(0.0, 2 * np.pi, 2001)
    path = np.stack([np.cos(t), np.sin(t), 0 * t], 1)
    path = np.concatenate([np.repeat(path[:1], 50, 0), path])  # at rest at the start
    rng = np.random.default_rng(0)
    th = rng.uniform(0, 2 * np.pi, 400)
    r = 1 + rng.uniform(-1e-3, 1e-3, 400)
    pts = np.stack([r * np.cos(th), r * np.sin(th), rng.uniform(-1e-3, 1e-3, 400)], 1)
    exact = np.hypot(r - 1, pts[:, 2])
    sag = 1 - np.cos(np.pi / 2000)
    np.testing.assert_array_less(np.abs(bench._contour_error(pts, path) - exact), sag + 1e-12)


def test_paths_have_their_feed_and_shape(bench):
    dt = 1e-3
    feed = 2000.0 / 60e3  # m/s
    cone = bench.cone_frustum(feed, dt)
    z = cone[:, 2] - cone[0, 2]
    radius = np.hypot(cone[:, 0] - 0.25, cone[:, 1] - 0.2)
    # ISO 10791-7 frustum: the radius shrinks with height at the 15° half angle
    np.testing.assert_allclose(radius, 0.06 - z * np.tan(np.deg2rad(15)), atol=1e-12)
    helix = bench.helix(feed, dt)
    speed = np.linalg.norm(np.diff(helix, axis=0), axis=1) / dt
    moving = speed > 0
    np.testing.assert_allclose(np.median(speed[moving]), feed, rtol=1e-3)


def test_three_drives_agree_with_an_independent_solve_ivp(bench):
    """The one-call simulation of the three drives against a `solve_ivp` loop over a NumPy
    right-hand side written separately (RK45, rtol 1e-7): the axis positions agree to
    0.01 µm over a 0.5 s path (measured 4e-4 µm over 4 s)."""
    jax.config.update("jax_enable_x64", True)
    truth = bench.machine(bench.thesis_errors(2))
    res = bench.simulation_speed(truth, 0.5)
    assert res["samples"] == 501
    assert res["max_abs_axis_difference_um"] < 0.01, res
