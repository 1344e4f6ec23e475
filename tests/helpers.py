"""Shared test utilities: tree comparison and registries of models for parametrised tests."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxvs


def tree_allclose(x, y, *, rtol=1e-5, atol=1e-8) -> bool:
    lx, tx = jax.tree_util.tree_flatten(x)
    ly, ty = jax.tree_util.tree_flatten(y)
    if tx != ty:
        return False
    return all(
        np.allclose(np.asarray(a), np.asarray(b), rtol=rtol, atol=atol) for a, b in zip(lx, ly)
    )


def random_modal(rng: np.random.Generator, n_modes: int = 4, *, f_lo=5.0, f_hi=500.0):
    """Random stable lightly damped modal model, modes log-spread in [f_lo, f_hi] Hz."""
    f = np.sort(np.exp(rng.uniform(np.log(f_lo), np.log(f_hi), n_modes)))
    w = 2 * np.pi * f
    z = rng.uniform(0.01, 0.2, n_modes)
    r = rng.normal(size=n_modes) * w**2 / n_modes
    return jaxvs.ModalModel(jnp.asarray(w), jnp.asarray(z), jnp.asarray(r))


def random_rational(rng: np.random.Generator, order: int = 8, *, proper_equal: bool = True):
    """Random stable RationalTF of the given order from a random modal model."""
    m = random_modal(rng, order // 2)
    ss = m.to_state_space()
    import scipy.signal as sig

    num, den = sig.ss2tf(np.asarray(ss.A), np.asarray(ss.B), np.asarray(ss.C), np.asarray(ss.D))
    num = num[0]
    if proper_equal:
        num = num + rng.normal() * den
    return jaxvs.RationalTF(jnp.asarray(num), jnp.asarray(den))


# Registries: every linear model family, as (name, factory(rng)) pairs.
LINEAR_MODELS = [
    ("rational", lambda rng: random_rational(rng, 8)),
    (
        "rational_odd",
        lambda rng: jaxvs.RationalTF(jnp.array([1.0, 2.0, 3.0]), jnp.array([1.0, 6.0, 11.0, 6.0])),
    ),
    ("modal", lambda rng: random_modal(rng, 4)),
    (
        "modal_complex",
        lambda rng: jaxvs.ModalModel(
            jnp.array([30.0, 400.0]),
            jnp.array([0.05, 0.1]),
            jnp.array([1.0 + 2.0j, -3.0 + 0.5j]) * 1e3,
        ),
    ),
    ("statespace", lambda rng: random_modal(rng, 3).to_state_space()),
]
