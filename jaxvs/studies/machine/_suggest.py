"""Test-plan suggestion: which extra test most reduces the worst volumetric uncertainty
(Fisher information of each candidate, all candidates in one vectorised evaluation)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...models import CartesianMachine
from ._calibration import prior_scale
from ._parameters import _assert_tests, parameters, plan_jacobian, with_parameters

__all__ = ["suggest_test"]


def _grid(machine: CartesianMachine, n: int):
    span = np.asarray(machine.travel)
    axes = [np.linspace(lo, hi, n) for lo, hi in span]
    return jnp.asarray(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3))


@eqx.filter_jit
def _criterion(F0, Fc, G):
    cov = jnp.linalg.inv(F0[None] + Fc)
    var = jnp.einsum("gip,cpq,giq->cg", G, cov, G)
    return jnp.sqrt(jnp.max(var, axis=1)), jnp.sqrt(jnp.mean(var, axis=1))


def suggest_test(
    machine: CartesianMachine,
    plan,
    candidates,
    *,
    prior=(10e-6, 50e-6),
    grid: int = 5,
) -> list[dict]:
    r"""Rank candidate tests by how much each, added to `plan`, reduces the worst
    uncertainty of the volumetric error over the working volume.

    The information of a plan is `F = JᵀJ` (`J` the whitened sensitivity of its readings
    to the parameters, [`plan_jacobian`][]) plus a weak zero-mean prior
    `diag(1/σ_prior²)` so that a plan that cannot yet separate every component still has
    a finite covariance `F⁻¹`. For each candidate `c` the covariance `(F + F_c)⁻¹` is
    mapped to the volumetric error `E(q)` at a `grid³` grid of the volume; the criterion
    is the largest standard deviation of `E` (an E-optimal design in the units that matter
    for the part, Atkinson, Donev, Tobias, *Optimum Experimental Designs*, 2007, §10).
    All candidates' sensitivities come from one Jacobian over all their points, and all
    their criteria from one batched inverse.

    **Arguments:** `machine` (nominal or calibrated); `plan`, the current tests (may be
    empty); `candidates`, tests to choose from; `prior`, `(σ_translation [m], σ_angle
    [rad])`; `grid`, points per axis.

    **Returns:** `[{"test": label, "index": i, "worst_std": m, "rms_std": m}]`, best first,
    preceded by the plan alone as `{"test": "(current plan)", "index": -1, ...}`.
    """
    candidates = _assert_tests(candidates)
    plan = list(plan)
    for t in plan + candidates:
        t.check(machine)
    theta = parameters(machine)
    F0 = jnp.diag(1.0 / prior_scale(machine, prior) ** 2)
    if plan:
        J0 = plan_jacobian(machine, _assert_tests(plan))
        F0 = F0 + J0.T @ J0
    # one Jacobian for all candidates (one evaluation of the chain over all their
    # points), split into each candidate's rows
    J = plan_jacobian(machine, candidates)
    sizes = [int(np.prod(eqx.filter_eval_shape(t.predict, machine).shape)) for t in candidates]
    bounds = np.cumsum([0] + sizes)
    Fc = [J[i:j].T @ J[i:j] for i, j in zip(bounds[:-1], bounds[1:])]
    Fc = jnp.stack([jnp.zeros_like(F0)] + Fc)
    q = _grid(machine, grid)
    G = jax.jacfwd(
        lambda th: (lambda m: m.tool_point(q) - q - m.tool_offset)(with_parameters(machine, th))
    )(theta)
    worst, rms = (np.asarray(v) for v in _criterion(F0, Fc, G))
    rows = [
        {
            "test": "(current plan)",
            "index": -1,
            "worst_std": float(worst[0]),
            "rms_std": float(rms[0]),
        }
    ]
    order = np.argsort(worst[1:])
    rows += [
        {
            "test": candidates[i].label,
            "index": int(i),
            "worst_std": float(worst[1 + i]),
            "rms_std": float(rms[1 + i]),
        }
        for i in order
    ]
    return rows
