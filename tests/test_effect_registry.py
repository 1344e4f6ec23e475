"""The effect registry: every candidate effect of every diagnosis family, with the rules
the engine relies on, checked on one effect-free record of each family.

Each effect must be jit-compilable and vmappable (the engine calibrates all starting shapes
of a candidate in one vmapped call), equal the nominal model exactly at zero size (the
candidate starts from the nominal and the search compares the two), have a gradient that
agrees with central finite differences (Levenberg–Marquardt steps with it), and answer its
admissibility rule with `(bool, reason)`. `REGISTRY` is the list, like the model registry:
an effect class that is not in it fails `test_every_effect_is_registered`.

The records are the blind benchmark's effect-free plants (`benchmarks/blind_plants.py`),
built independently of the effect classes.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from benchmark_module import load_benchmark

from jaxvs.diagnosis import _drive, _thermal, _tmf
from jaxvs.diagnosis._base import AbstractEffect, Context, GapModel
from jaxvs.diagnosis._families import FAMILIES

jax.config.update("jax_enable_x64", True)
pytestmark = pytest.mark.slow  # about 2 minutes idle: three records, 17 effects compiled

RECORD = {
    "drive": "drive-free-1khz",
    "tmf": "tmf-free-5khz-force-channel",
    "thermal": "thermal-free-5s",
}


def _zero_size(e):
    return eqx.tree_at(lambda x: x.size, e, jnp.zeros_like(jnp.asarray(e.size)))


def _zero_tau(e):
    return eqx.tree_at(lambda x: x.tau, e, jnp.zeros_like(jnp.asarray(e.tau, float)))


def _no_limit(e):
    # a limit 10^6 times the largest recorded command is never reached
    return eqx.tree_at(lambda x: x.limit, e, 1e6 * jnp.asarray(e.quantiles[1][-1]))


def _no_events(arrays):
    return {**arrays, "events": jnp.zeros_like(arrays["events"])}


# effect class -> (family, how to make it nominal: on the effect, on the arrays)
REGISTRY = {
    _drive.CoulombEffect: ("drive", _zero_size, None),
    _drive.AsymmetricFrictionEffect: ("drive", _zero_size, None),
    _drive.StribeckEffect: ("drive", _zero_size, None),
    _drive.Backlash: ("drive", _zero_size, None),
    _drive.Resonance: ("drive", _zero_size, None),
    _drive.TimeDelay: ("drive", _zero_tau, None),
    _drive.PositionForceEffect: ("drive", _zero_size, None),
    _drive.ExternalForce: ("drive", None, _no_events),
    _drive.Saturation: ("drive", _no_limit, None),
    _thermal.Dynamics: ("thermal", _zero_tau, None),
    _thermal.AmbientTemperature: ("thermal", _zero_size, None),
    _thermal.CoolantTemperature: ("thermal", _zero_size, None),
    _thermal.SpeedNonlinearity: ("thermal", _zero_size, None),
    _tmf.TMFPositionEffect: ("tmf", _zero_size, None),
    _tmf.MissingMode: ("tmf", _zero_size, None),
    _tmf.SensorDelay: ("tmf", _zero_tau, None),
    _tmf.ProcessForce: ("tmf", _zero_size, None),
}


def _concrete_subclasses(cls):
    out = set()
    for sub in cls.__subclasses__():
        if not getattr(sub, "__abstractmethods__", None) and isinstance(
            getattr(sub, "name", None), str
        ):
            out.add(sub)
        out |= _concrete_subclasses(sub)
    return out


@pytest.fixture(scope="module")
def templates():
    """Per family: the prepared experiments, the initialised nominal model, the
    admissibility context and, per library entry, its first starting effect."""
    bp = load_benchmark("blind_plants")
    out = {}
    for family, case_name in RECORD.items():
        case = next(c for c in bp.cases() if c.name == case_name)
        cal, _, _ = bp.generate(case)
        fam = FAMILIES[family]()
        exps = [fam.prepare(r, f"{case_name} {i}") for i, r in enumerate(cal)]
        model = GapModel(fam.nominal(exps))
        pred = [np.asarray(model(e.jax_arrays())) for e in exps]
        res = [e.y - p for e, p in zip(exps, pred)]
        context = fam.admissibility_context(exps, model)
        effects = {}
        for entry in fam.library():
            assert entry.not_testable(exps) is None, (family, entry.name)
            e_exps = exps
            if entry.refresh is not None:
                e_exps = [entry.refresh(e, r) for e, r in zip(exps, res)]
            ctx = Context(model, e_exps, res, fam.options)
            effects[entry.name] = (entry.templates(ctx)[0], e_exps[0].jax_arrays())
        out[family] = (model, context, effects)
    return out


def _cases(templates):
    for family, (model, context, effects) in templates.items():
        for name, (effect, arrays) in effects.items():
            yield family, name, model, context, effect, arrays


def test_every_effect_is_registered(templates):
    found = _concrete_subclasses(AbstractEffect)
    assert found == set(REGISTRY), (
        f"not registered: {sorted(c.__name__ for c in found - set(REGISTRY))}; "
        f"registered but gone: {sorted(c.__name__ for c in set(REGISTRY) - found)}"
    )
    # every library entry's starting effects are registered classes of their family
    for family, name, *_, effect, _ in _cases(templates):
        assert type(effect) in REGISTRY, name
        assert REGISTRY[type(effect)][0] == family, name
        assert effect.name == name
    # and every registered class is in its family's library
    libraries = {
        f: {type(e) for _, e_a in t[2].items() for e in [e_a[0]]} for f, t in templates.items()
    }
    for cls, (family, *_) in REGISTRY.items():
        assert cls in libraries[family], cls.__name__


def _perturbed(effect, rng):
    """The effect with its float arrays moved by a few per cent (by 0.05 where an entry is
    zero), a generic point for the gradient and vmap checks."""
    arr, static = eqx.partition(effect, eqx.is_inexact_array)

    def move(x):
        scale = jnp.where(x == 0, 1.0, jnp.abs(x))
        return x + 0.05 * scale * jnp.asarray(rng.standard_normal(x.shape))

    return eqx.combine(jax.tree.map(move, arr), static)


def _predict(model, effect, arrays):
    return GapModel(model.nominal, (effect,))(arrays)


def test_zero_size_is_the_nominal_model(templates):
    for family, name, model, _, effect, arrays in _cases(templates):
        on_effect, on_arrays = REGISTRY[type(effect)][1:]
        zero = on_effect(effect) if on_effect else effect
        d = on_arrays(arrays) if on_arrays else arrays
        nominal = np.asarray(model.nominal(d))
        got = np.asarray(_predict(model, zero, d))
        scale = np.max(np.abs(nominal))
        np.testing.assert_allclose(got, nominal, rtol=0, atol=1e-9 * scale, err_msg=name)


def test_jit_and_vmap_agree_with_the_eager_prediction(templates):
    rng = np.random.default_rng(0)
    for family, name, model, _, effect, arrays in _cases(templates):
        a, b = effect, _perturbed(effect, rng)
        eager = [np.asarray(_predict(model, e, arrays)) for e in (a, b)]
        jitted = eqx.filter_jit(_predict)(model, b, arrays)
        np.testing.assert_allclose(
            np.asarray(jitted), eager[1], rtol=1e-10, atol=1e-12, err_msg=name
        )
        arr_a, static = eqx.partition(a, eqx.is_inexact_array)
        arr_b, _ = eqx.partition(b, eqx.is_inexact_array)
        stacked = jax.tree.map(lambda x, y: jnp.stack([x, y]), arr_a, arr_b)
        both = eqx.filter_vmap(
            lambda arr: _predict(model, eqx.combine(arr, static), arrays), axis_size=2
        )(stacked)
        for k in range(2):
            np.testing.assert_allclose(
                np.asarray(both[k]), eager[k], rtol=1e-10, atol=1e-12, err_msg=name
            )


def test_gradient_matches_finite_differences(templates):
    """The directional derivative of a random projection of the prediction along a random
    direction in the effect's parameters: forward-mode AD against central differences
    (steps 1e-4 and 5e-5 of each parameter's size, Richardson-extrapolated: truncation
    O(h^4)); agreement to 1e-5 relative plus the differences' rounding, 200 eps of the
    projection's root-sum-square / h (the elements' rounding errors are independent)."""
    rng = np.random.default_rng(1)
    for family, name, model, _, effect, arrays in _cases(templates):
        point = _perturbed(effect, rng)
        arr, static = eqx.partition(point, eqx.is_inexact_array)
        leaves, tree = jax.tree.flatten(arr)
        if not leaves:  # no calibrated parameter (the events' amplitudes are profiled out)
            assert isinstance(effect, _drive.ExternalForce), name
            continue
        w = jnp.asarray(rng.standard_normal(arrays["y"].shape))
        direction = [
            jnp.asarray(rng.standard_normal(x.shape)) * jnp.where(x == 0, 1.0, jnp.abs(x))
            for x in leaves
        ]

        def f(ls):
            e = eqx.combine(jax.tree.unflatten(tree, ls), static)
            return jnp.sum(w * _predict(model, e, arrays))

        _, ad = jax.jvp(f, (leaves,), (direction,))
        h = 1e-4

        def central(step):
            plus = f([x + step * d for x, d in zip(leaves, direction)])
            minus = f([x - step * d for x, d in zip(leaves, direction)])
            return (plus - minus) / (2 * step)

        fd = (4 * central(h / 2) - central(h)) / 3  # Richardson: truncation O(h^4)
        magnitude = float(jnp.sqrt(jnp.sum((w * _predict(model, point, arrays)) ** 2)))
        rounding = 200 * np.finfo(float).eps * magnitude / h
        # the check has power: the rounding allowance is far below the derivative
        assert rounding < 1e-3 * float(jnp.abs(ad)), (name, float(ad), rounding)
        assert float(jnp.abs(ad - fd)) <= 1e-5 * float(jnp.abs(ad)) + rounding, (
            name,
            float(ad),
            float(fd),
        )


def test_admissibility_answers_with_a_reason(templates):
    rng = np.random.default_rng(2)
    for family, name, _, context, effect, _ in _cases(templates):
        for e in (effect, _perturbed(effect, rng)):
            ok, reason = e.admissible(context)
            assert isinstance(ok, bool), name
            assert (reason is None) if ok else (isinstance(reason, str) and reason), name
        params = effect.parameters()
        assert all(isinstance(k, str) for k in params), name
        assert dataclasses.is_dataclass(context)
