"""The vectorised search: every candidate of one structure is padded to a common shape
(masked inputs and delays) and fitted together.

- Linear structures (static regression, first-order lag, ARX) are least-squares problems
  that share their data: one Gram matrix of all padded features is formed once, and each
  candidate solves its masked normal equations (one `vmap`). The lag's time constant is
  profiled on a logarithmic grid (the lag is linear in its other parameters).
- Networks (static MLP and TDNN of one hidden size) are trained by Levenberg-Marquardt,
  all candidates and all their initialisations in one `vmap`-ed call of the one LM driver
  [`jaxvs.calibration.lm_solve_family`][] (work compaction by `batched_while`), with the
  perceptron's structured normal equations (`Perceptron.normal_equations`). A masked
  feature keeps its weights at zero (their rows of `JᵀJ` and `Jᵀr` are masked, so the
  damped step leaves them). Since the data are shared and only the weights are batched,
  XLA folds the member axis into the matrix products: one large product per step
  instead of one small one per candidate. Training stops early on the stopping block
  (MATLAB's `max_fail` rule) and returns the weights of its best epoch.
"""

from __future__ import annotations

import functools
import time
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jax.flatten_util import ravel_pytree

from ...calibration import AbstractLMMonitor, BatchSchedule, lm_solve_family
from ...models import Perceptron

__all__ = [
    "Candidate",
    "GroupResult",
    "NetworkTraining",
    "fit_linear_group",
    "train_network_group",
]


class Candidate(NamedTuple):
    """One design: `structure`, `subset` (indices into the input pool), `delays` (the
    delays [samples] of every chosen input), `hidden` (networks), `na` (ARX order) and
    `quadratic` (linear structures: the squares `u_i(k)²` of the chosen inputs join the
    features, a Hammerstein-type static nonlinearity such as friction heat `∝ n^α`)."""

    structure: str
    subset: tuple[int, ...]
    delays: tuple[int, ...]
    hidden: int | None = None
    na: int | None = None
    quadratic: bool = False


class GroupResult(NamedTuple):
    """Fitted candidates of one group: `pred` `(candidate, time)` normalised predictions
    (NaN for a failed/unstable one), `params` per candidate (padded), `status` texts,
    `seconds` of the whole group (run, then compile), `members` trained."""

    pred: np.ndarray
    params: list[Any]
    status: list[str]
    run_seconds: float
    compile_seconds: float
    members: int


def feature_mask(c: Candidate, n_pool: int, dmax: int, squares: bool = True) -> np.ndarray:
    """Mask of the padded features `[u_i(k-d) for i, d] + [u_i(k)² for i]` (the squares
    only with `squares=True`)."""
    m = np.zeros((n_pool, dmax + 1))
    q = np.zeros(n_pool)
    for i in c.subset:
        m[i, list(c.delays)] = 1.0
        q[i] = 1.0 if c.quadratic else 0.0
    return np.concatenate([m.ravel(), q]) if squares else m.ravel()


def _solve(G, r, mask, ridge):
    """Masked normal equations: masked unknowns are 0, the others solve `G w = r` on the
    unmasked block (relative ridge `ridge` for rank-deficient blocks)."""
    d = jnp.diagonal(G)
    mm = mask[:, None] * mask[None, :]
    Gm = G * mm + jnp.diag(1.0 - mask) + jnp.diag(ridge * jnp.where(d > 0, d, 1.0) * mask)
    return jnp.linalg.solve(Gm, r * mask)


def _lag_filter(X, starts, a):
    """`z(k) = a z(k-1) + (1-a) x(k)` per column, restarted in steady state at `starts`;
    `a`: `(grid,)` -> `(grid, time, feature)`."""

    def step(z, xr):
        x, r = xr
        z = jnp.where(r, x[None, :], a[:, None] * z + (1 - a)[:, None] * x[None, :])
        return z, z

    z0 = jnp.zeros((a.shape[0], X.shape[1]), X.dtype)
    return jnp.moveaxis(jax.lax.scan(step, z0, (X, starts))[1], 0, 1)


@eqx.filter_jit
def _linear_impl(X, y, starts, train, masks, ridge):
    A = jnp.concatenate([X, jnp.ones((X.shape[0], 1), X.dtype)], axis=1)
    At = A * train[:, None]
    G, r = At.T @ A, At.T @ y
    M = jnp.concatenate([masks, jnp.ones((masks.shape[0], 1), X.dtype)], axis=1)
    W = jax.vmap(lambda m: _solve(G, r, m, ridge))(M)
    return W, (A @ W.T).T


@eqx.filter_jit
def _lag_impl(X, y, starts, train, masks, a_grid, ridge):
    Z = _lag_filter(X, starts, a_grid)  # (grid, time, feature)
    A = jnp.concatenate([Z, jnp.ones(Z.shape[:2] + (1,), X.dtype)], axis=2)
    At = A * train[None, :, None]
    G = jnp.einsum("gti,gtj->gij", At, A)
    r = jnp.einsum("gti,t->gi", At, y)
    yy = jnp.sum(train * y**2)
    M = jnp.concatenate([masks, jnp.ones((masks.shape[0], 1), X.dtype)], axis=1)
    W = jax.vmap(lambda m: jax.vmap(lambda Gg, rg: _solve(Gg, rg, m, ridge))(G, r))(M)
    sse = yy - 2 * jnp.einsum("dgi,gi->dg", W, r) + jnp.einsum("dgi,gij,dgj->dg", W, G, W)
    best = jnp.argmin(sse, axis=1)
    Wb = jnp.take_along_axis(W, best[:, None, None], axis=1)[:, 0]
    pred = jnp.einsum("dti,di->dt", A[best], Wb)
    return a_grid[best], Wb, pred


@eqx.filter_jit
def _arx_impl(X, Ylag, y, starts, train, masks, ridge):
    A = jnp.concatenate([X, Ylag, jnp.ones((X.shape[0], 1), X.dtype)], axis=1)
    At = A * train[:, None]
    G, r = At.T @ A, At.T @ y
    W = jax.vmap(lambda m: _solve(G, r, m, ridge))(masks)
    F = X.shape[1]
    a = W[:, F : F + 2]
    v = X @ W[:, :F].T + W[:, -1][None, :]  # (time, candidate)
    ss = 1.0 / (1.0 - a[:, 0] - a[:, 1])

    def step(h, vr):
        vk, rk = vr
        h = jnp.where(rk, (ss * vk)[:, None] * jnp.ones((1, 2), X.dtype), h)
        yk = a[:, 0] * h[:, 0] + a[:, 1] * h[:, 1] + vk
        return jnp.stack([yk, h[:, 0]], axis=1), yk

    _, pred = jax.lax.scan(step, jnp.zeros((W.shape[0], 2), X.dtype), (v, starts))
    # stable iff both roots of z² - a1 z - a2 lie inside the unit circle (Jury)
    stable = (jnp.abs(a[:, 1]) < 1) & (1 - a[:, 0] - a[:, 1] > 1e-9) & (1 + a[:, 0] - a[:, 1] > 0)
    return W, pred.T, stable


def fit_linear_group(
    structure: str,
    cands: list[Candidate],
    X: np.ndarray,
    y: np.ndarray,
    starts: np.ndarray,
    train: np.ndarray,
    n_pool: int,
    dmax: int,
    dt: float,
) -> GroupResult:
    """Fit all candidates of one linear structure (`regression`, `lag` or `arx`) at once.

    `X` `(time, pool·(dmax+2))` normalised padded features (delayed copies, then
    squares), `y` normalised target, `starts` experiment starts, `train` `(time,)` 1.0 on
    training samples."""
    t0 = time.perf_counter()  # the setup counts: the loop reference pays it per candidate
    masks = jnp.asarray(np.stack([feature_mask(c, n_pool, dmax) for c in cands]))
    Xj, yj, sj, tj = (jnp.asarray(v) for v in (X, y, starts, train.astype(float)))
    ridge = 1e-10
    if structure == "regression":
        W, pred = map(np.asarray, _linear_impl(Xj, yj, sj, tj, masks, ridge))
        params = [{"w": np.asarray(W[i, :-1]), "b": float(W[i, -1])} for i in range(len(cands))]
        status = ["ok"] * len(cands)
    elif structure == "lag":
        # time constants from 2 samples to half the training span, 40 per decade-ish grid
        span = max(float(train.sum()) * dt, 20 * dt)
        tau = np.geomspace(2 * dt, span / 2, 48)
        a_grid = jnp.asarray(np.exp(-dt / tau))
        a, W, pred = map(np.asarray, _lag_impl(Xj, yj, sj, tj, masks, a_grid, ridge))
        params = [
            {"a": float(a[i]), "w": np.asarray(W[i, :-1]), "b": float(W[i, -1])}
            for i in range(len(cands))
        ]
        status = ["ok"] * len(cands)
    elif structure == "arx":
        Ylag = delayed_target(y, starts)
        na_mask = np.array([[1.0, 1.0 if c.na == 2 else 0.0, 1.0] for c in cands])
        M = jnp.concatenate([masks, jnp.asarray(na_mask)], axis=1)
        W, pred, stable = map(np.asarray, _arx_impl(Xj, jnp.asarray(Ylag), yj, sj, tj, M, ridge))
        F = X.shape[1]
        params = [
            {
                "a": np.asarray(W[i, F : F + (c.na or 1)]),
                "w": np.asarray(W[i, :F]),
                "b": float(W[i, -1]),
            }
            for i, c in enumerate(cands)
        ]
        status = ["ok" if s else "unstable" for s in stable]
        pred = np.where(stable[:, None], pred, np.nan)
    else:  # pragma: no cover - internal
        raise ValueError(structure)
    elapsed = time.perf_counter() - t0
    pred = np.asarray(pred)
    status = [s if np.all(np.isfinite(p)) else "failed" for s, p in zip(status, pred)]
    return GroupResult(pred, params, status, elapsed, 0.0, len(cands))


def delayed_target(y: np.ndarray, starts: np.ndarray) -> np.ndarray:
    n = y.shape[0]
    first = np.maximum.accumulate(np.where(starts, np.arange(n), 0))
    k = np.arange(n)
    return np.column_stack([y[np.maximum(k - 1, first)], y[np.maximum(k - 2, first)]])


# ----------------------------------------------------------------------------- networks


class NetworkTraining(eqx.Module):
    """How each network is trained: at most `max_steps` Levenberg-Marquardt steps, stopped
    after `max_fail` accepted steps that do not lower the stopping block's error
    (MATLAB's `max_fail` rule)."""

    max_steps: int = eqx.field(static=True, default=100)
    max_fail: int = eqx.field(static=True, default=6)


class _EarlyStopping(AbstractLMMonitor):
    """The best parameters on the stopping block; stop after `max_fail` accepted steps
    without improvement."""

    forward: Any
    XS: jax.Array
    yS: jax.Array
    max_fail: int = eqx.field(static=True)

    def _val(self, theta):
        e = self.forward(theta, self.XS) - self.yS
        return jnp.mean(e**2)

    def init(self, state, args):
        return state.theta, self._val(state.theta), jnp.asarray(0)

    def update(self, watch, old, new, args):
        best_theta, best_val, fails = watch
        accepted = new.cost < old.cost
        v = self._val(new.theta)
        better = accepted & (v < best_val)
        return (
            jnp.where(better, new.theta, best_theta),
            jnp.where(better, v, best_val),
            jnp.where(better, 0, fails + accepted.astype(fails.dtype)),
        )

    def running(self, watch, state, args):
        return watch[2] < self.max_fail


def init_members(keys, fmasks, n_features: int, hidden: int):
    """Initial perceptrons (Nguyen-Widrow as `Perceptron`, scaled to the active features)
    raveled to `(member, weight)`, and their weight masks."""

    def one(key, fm):
        p = Perceptron(n_features, hidden, key=key)
        n_act = jnp.maximum(jnp.sum(fm), 1.0)
        beta = 0.7 * hidden ** (1.0 / n_act)
        W1 = p.W1 * fm[None, :]
        W1 = beta * W1 / jnp.maximum(jnp.linalg.norm(W1, axis=1, keepdims=True), 1e-12)
        p = eqx.tree_at(
            lambda q: (q.W1, q.b1), p, (W1, p.b1 / (0.7 * hidden ** (1.0 / n_features)) * beta)
        )
        theta, _ = ravel_pytree(p)
        pm = jnp.concatenate(
            [(jnp.ones((hidden, 1)) * fm[None, :]).ravel(), jnp.ones(2 * hidden + 1)]
        ).astype(theta.dtype)
        return theta, pm

    return jax.vmap(one)(keys, fmasks)


def _net_problem(n_features: int, hidden: int, dtype):
    template = Perceptron(n_features, hidden, key=jr.key(0), dtype=dtype)
    _, unravel = ravel_pytree(template)

    def forward(theta, X):
        p = unravel(theta)
        return jnp.tanh(X @ p.W1.T + p.b1) @ p.W2 + p.b2

    def evaluate(theta, args):
        pm, X, y = args
        p = unravel(theta)
        e = jnp.tanh(X @ p.W1.T + p.b1) @ p.W2 + p.b2 - y
        G, g = p.normal_equations(X, e, chunk=_CHUNK)
        return 0.5 * jnp.dot(e, e), G * pm[:, None] * pm[None, :], g * pm

    return forward, evaluate


# batched_while work compaction (heuristic): a first sweep of `first_steps` LM steps for
# blocks of `block` members, then the `tail_block` still-running members `block_steps`
# steps at a time.
_SCHEDULE = BatchSchedule(block=16, first_steps=10, tail_block=16, block_steps=5)
_CHUNK = 256


@functools.partial(jax.jit, static_argnames=("shape", "training"))
def _train_jit(theta0, pm, data, shape: tuple[int, int], training: NetworkTraining):
    """Train the members `theta0` (masks `pm`) on `data = (XT, yT, XS, yS)`; `shape`:
    `(n_features, hidden)`."""
    XT, yT, XS, yS = data
    forward, evaluate = _net_problem(*shape, theta0.dtype)
    lm, (best_theta, best_val, _) = lm_solve_family(
        lambda theta, a: evaluate(theta, (a, XT, yT)),
        theta0,
        pm,
        max_steps=training.max_steps,
        rtol=1e-7,
        schedule=_SCHEDULE,
        feasible=lambda th: jnp.asarray(True),
        monitor=_EarlyStopping(forward, XS, yS, training.max_fail),
    )
    return best_theta, best_val, lm.num_steps


@eqx.filter_jit
def _predict_impl(thetas, X, n_features, hidden):
    forward, _ = _net_problem(n_features, hidden, thetas.dtype)
    return jax.vmap(lambda th: forward(th, X))(thetas)


def train_network_group(
    cands: list[Candidate],
    X: np.ndarray,
    y: np.ndarray,
    role: np.ndarray,
    n_pool: int,
    dmax: int,
    *,
    inits: int,
    key,
    training: NetworkTraining = NetworkTraining(),
    loop: bool = False,
) -> GroupResult:
    """Train all network candidates of one hidden size, `inits` initialisations each, in
    one batched LM call (or, with `loop=True`, one member after another with the same
    compiled trainer: the reference the benchmark times against). The initialisation
    with the lowest stopping-block error is kept per candidate."""
    hidden = cands[0].hidden
    X = X[:, : n_pool * (dmax + 1)]  # networks: no square features (they are nonlinear)
    F = X.shape[1]
    fm = np.repeat(
        np.stack([feature_mask(c, n_pool, dmax, squares=False) for c in cands]), inits, axis=0
    )
    keys = jr.split(key, fm.shape[0])
    theta0, pm = init_members(keys, jnp.asarray(fm), F, hidden)
    Xj = jnp.asarray(X)
    T, S = role == 0, role == 1
    XT, yT, XS, yS = Xj[T], jnp.asarray(y[T]), Xj[S], jnp.asarray(y[S])
    data = (XT, yT, XS, yS)
    opts = dict(shape=(F, hidden), training=training)
    # compile first (reported apart), then run
    t0 = time.perf_counter()
    if loop:
        comp = _train_jit.lower(theta0[:1], pm[:1], data, **opts).compile()
    else:
        comp = _train_jit.lower(theta0, pm, data, **opts).compile()
    t1 = time.perf_counter()
    if loop:
        outs = [
            jax.block_until_ready(comp(theta0[i : i + 1], pm[i : i + 1], data))
            for i in range(theta0.shape[0])
        ]
        best = jnp.concatenate([o[0] for o in outs])
        bval = jnp.concatenate([o[1] for o in outs])
    else:
        best, bval, _ = jax.block_until_ready(comp(theta0, pm, data))
    t2 = time.perf_counter()
    bval = np.asarray(bval).reshape(len(cands), inits)
    bval = np.where(np.isfinite(bval), bval, np.inf)
    pick = np.argmin(bval, axis=1)
    idx = np.arange(len(cands)) * inits + pick
    thetas = best[jnp.asarray(idx)]
    pred = np.asarray(_predict_impl(thetas, Xj, F, hidden))
    params = [
        {"theta": np.asarray(thetas[i]), "hidden": hidden, "n_features": F}
        for i in range(len(cands))
    ]
    status = ["ok" if np.all(np.isfinite(p)) else "failed" for p in pred]
    return GroupResult(pred, params, status, t2 - t1, t1 - t0, fm.shape[0])


def perceptron_from(theta: np.ndarray, n_features: int, hidden: int) -> Perceptron:
    template = Perceptron(n_features, hidden, key=jr.key(0), dtype=jnp.asarray(theta).dtype)
    _, unravel = ravel_pytree(template)
    return unravel(jnp.asarray(theta))
