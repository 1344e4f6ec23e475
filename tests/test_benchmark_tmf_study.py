"""Smoke test of `benchmarks/tmf_study.py`: its cheap pieces on small inputs.

The benchmark's `--quick` mode takes 1.5-2.5 min on the shared 2-core machine (compiles of
the twin, route (a)/(b) fits, the family calibration), too long for a test; this runs its
analytic checks, the throughput comparison and the test-cycle command instead, each
against an independent oracle.
"""

import jax.numpy as jnp
import numpy as np
import pytest
from benchmark_module import load_benchmark

import jaxvs
from jaxvs.twins import MachineStructureTwin


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("tmf_study")


@pytest.mark.slow
def test_analytic_checks_match_closed_forms(bench):
    """The hand-derived closed forms agree with the chain's solve and exact TMF models to
    rounding (1e-12; measured ~1e-15)."""
    res = bench.analytic_checks(n_positions=4)
    for name, row in res["three_mass"]["rows"].items():
        for value in row.values():
            assert value < 1e-12, (name, row)
    assert "transmissibility_model" not in res["three_mass"]["rows"]["T_21^2"]  # improper
    assert res["twin"]["true_tmf_max_rel_error"] < 1e-12
    assert res["twin"]["tmf_model_max_rel_error"] < 1e-12


@pytest.mark.slow
def test_throughput_outputs_agree_and_discrete_responses(bench):
    """jaxvs and the scipy loop give the same outputs (rounding), and the benchmark's
    discrete frequency responses are those of the exact discrete models: ZOH against the
    steady-state response of `jaxvs.simulate` to a sampled sinusoid."""
    twin = MachineStructureTwin()
    models = twin.tmf_model(jnp.array([0.1, 0.5]))
    rng = np.random.default_rng(0)
    x_e = np.cumsum(rng.standard_normal((2, 600)), axis=-1) * 1e-6
    res = bench.throughput(models, x_e, repeats=1, heun=False)
    assert res["max_rel_difference"] < 1e-10
    assert res["positions"] == 2 and res["samples_per_position"] == 600
    # ZOH response at 80 Hz (integer number of periods in the tail): steady state of a
    # simulated sinusoid equals the discrete frequency response
    one = bench._one(models, 0)
    dt, f = bench.DT, 80.0
    k = np.arange(4000)
    y = np.asarray(jaxvs.simulate(one, jnp.asarray(np.cos(2 * np.pi * f * k * dt)), dt))
    tail = k[-1000:]
    h = bench.discrete_response(one, np.array([f]), dt, method="zoh")[0]
    want = np.real(h * np.exp(2j * np.pi * f * tail * dt))
    np.testing.assert_allclose(y[-1000:], want, atol=1e-6 * np.abs(h))
    # Tustin: the bilinear map of the continuous response (frequency warping)
    y_t = np.asarray(
        jaxvs.simulate(one, jnp.asarray(np.cos(2 * np.pi * f * k * dt)), dt, method="tustin")
    )
    h_t = bench.discrete_response(one, np.array([f]), dt, method="tustin")[0]
    want_t = np.real(h_t * np.exp(2j * np.pi * f * tail * dt))
    np.testing.assert_allclose(y_t[-1000:], want_t, atol=1e-6 * np.abs(h_t))


def test_cycle_command_and_band_rms(bench):
    cmd, info = bench.cycle_command(quick=True)
    assert np.all(np.isfinite(cmd)) and cmd.size == round(info["duration_s"] / bench.DT)
    assert cmd[0] == 0.0 and abs(cmd[-1]) < 1e-12  # starts and ends at rest
    # Parseval: the band RMS over all bands is the RMS
    x = np.random.default_rng(1).standard_normal(1001)
    parts = [bench._band_rms(x, bench.DT, *b) for b in bench._bands(bench.DT).values()]
    np.testing.assert_allclose(np.sqrt(np.sum(np.square(parts))), np.sqrt(np.mean(x**2)))
