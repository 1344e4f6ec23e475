"""`simulate`: time response of linear models and families, in one vectorised call.

The engine runs the discretised real block-diagonal system (see `_discretise.py`) with a
**time-blocked** formulation instead of one sequential step per sample. With blocks of `K`
samples, the state `s_q` at the start of block `q` and the inputs `U_q` of the block,

    y_q     = U_q T + s_q O                       (Toeplitz of Markov parameters + free response)
    s_{q+1} = M s_q + U_q R,    M = Ad^K,         (block state recursion)

where `T[j, k] = h_{k-j}` (lower-triangular Toeplitz of the Markov parameters `h_0 = Dd`,
`h_i = C Ad^(i-1) Bd`), `O[:, k] = (C Ad^k)^T` and `R[k] = Ad^(K-1-k) Bd`
(cf. the "lifted" or block-processing form of a state-space filter, Mitra, *Digital Signal
Processing*, 4th ed., §8.9; Burrus, IEEE Trans. Audio Electroacoust. 20(4), 1972). The three
products are dense matrix products over all blocks at once; only the short recursion of the
block states remains, and it is solved by the same blocking applied to itself (fan-out `P`,
a scan of at most `_LMIN` steps at the top), so the number of sequential steps is
logarithmic in the signal length. The state recursion is the same as the sample-by-sample
one up to floating-point rounding.

Lanes (family members, or input experiments, each with its own tables) are processed in
groups of about `_GROUP_SAMPLES` samples under `jax.lax.map`: the intermediates of one group
stay small, which measured about twice as fast as one pass over all lanes
(benchmarks/simulate.py documents the variants and the limits on CPU).
"""

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._misc import check_finite, concrete
from ._base import AbstractLinearModel, check_model, map_batch
from ._discretise import (
    METHODS,
    DiscreteModalRealisation,
    Method,
    _check_dt,
    _check_method,
    discretise_realisation,
)
from ._realisation import ModalRealisation, from_dense

# Engine parameters (heuristics tuned on a 2-core x86 CPU, see benchmarks/simulate.py).
_K = 16  # samples per block (Toeplitz size)
_LMIN = 16  # the block-state recursion is a plain scan below this length
_GROUP_SAMPLES = 2**20  # samples (x channels) per lane group (heuristic, measured)


# ---------------------------------------------------------------------------------------
# 2x2-block algebra in component-major layout: matrices (..., 2, 2, nb), vectors (..., 2, nb)
# ---------------------------------------------------------------------------------------


def _bmm(a: Array, b: Array) -> Array:
    """Block-wise product of two block-diagonal matrices (elementwise over blocks)."""
    return (
        a[..., :, 0, None, :] * b[..., None, 0, :, :]
        + a[..., :, 1, None, :] * b[..., None, 1, :, :]
    )


def _bmv(m: Array, x: Array) -> Array:
    """Block-diagonal matrix times state vector."""
    return m[..., :, 0, :] * x[..., 0, None, :] + m[..., :, 1, :] * x[..., 1, None, :]


def _powers(a: Array, n: int) -> Array:
    """`[a^0, ..., a^n]` stacked on axis -4: `(..., n + 1, 2, 2, nb)`."""
    eye = jnp.broadcast_to(jnp.eye(2, dtype=a.dtype)[:, :, None], a.shape)

    def step(p, _):
        return _bmm(a, p), p

    _, out = jax.lax.scan(step, eye, None, length=n + 1)
    return jnp.moveaxis(out, 0, -4)


# ---------------------------------------------------------------------------------------
# Tables of the blocked formulation
# ---------------------------------------------------------------------------------------


def _tables(r: DiscreteModalRealisation, k: int) -> dict[str, Array]:
    """Block-processing matrices of a family flattened to lanes (leading axis).

    `r` has arrays `a (lane, block, 2, 2)`, `b (lane, block, 2, in)`, `c (lane, out, block,
    2)`, `d (lane, out, in)`. Returns `R (lane, K·in, 2·nb)`, `T (lane, K·in, K·out)`,
    `O (lane, 2·nb, K·out)` and `M = Ad^K (lane, 2, 2, nb)`; rows are ordered
    `(sample, input)` and columns `(sample, output)`, matching the time-major signal layout.
    """
    a = jnp.moveaxis(r.a, -3, -1)  # (L, 2, 2, nb)
    b = jnp.moveaxis(r.b, -3, -2)  # (L, 2, nb, in)
    c = jnp.moveaxis(r.c, -2, -1)  # (L, out, 2, nb)
    d = r.d  # (L, out, in)
    n_lanes, nb, m, p = a.shape[0], a.shape[-1], b.shape[-1], c.shape[1]
    pw = _powers(a, k)  # (L, K+1, 2, 2, nb)
    # R[k] = Ad^(K-1-k) Bd: (L, K, 2, nb, in)
    pr = pw[:, :k][:, ::-1]
    rr = pr[..., :, 0, :, None] * b[:, None, None, 0] + pr[..., :, 1, :, None] * b[:, None, None, 1]
    rr = jnp.moveaxis(rr, -1, 2).reshape(n_lanes, k * m, 2 * nb)
    # (C Ad^k)[o, col, blk]: (L, K, out, 2, nb)
    pk = pw[:, :k]
    ca = (
        c[:, None, :, 0, None, :] * pk[:, :, None, 0]
        + c[:, None, :, 1, None, :] * pk[:, :, None, 1]
    )
    # Markov parameters h_0 = Dd, h_i = C Ad^(i-1) Bd: (L, K, out, in)
    h1 = jnp.sum(ca[:, : k - 1, :, :, :, None] * b[:, None, None], axis=(3, 4))
    h = jnp.concatenate([d[:, None], h1], axis=1)
    obs = jnp.moveaxis(ca, (1, 2), (-2, -1)).reshape(n_lanes, 2 * nb, k * p)
    # Toeplitz T[(j, i), (k, o)] = h_{k-j}[o, i] for k >= j, else 0.
    jj, kk = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    lag = np.clip(kk - jj, 0, k - 1)
    toe = jnp.where(jnp.asarray(kk >= jj)[None, :, :, None, None], h[:, lag], 0.0)
    toe = jnp.transpose(toe, (0, 1, 4, 2, 3)).reshape(n_lanes, k * m, k * p)
    return {"R": rr, "T": toe, "O": obs, "M": pw[:, k]}


# ---------------------------------------------------------------------------------------
# Engine
# ---------------------------------------------------------------------------------------


def _bdot(v: Array, w: Array, v_lanes: bool, w_lanes: bool) -> Array:
    """`v (lane?, q, x) @ w (lane?, x, y)`, either side with or without its lane axis."""
    if v_lanes and w_lanes:
        return jnp.einsum("gqx,gxy->gqy", v, w)
    if v_lanes:
        return jnp.einsum("gqx,xy->gqy", v, w)
    if w_lanes:
        return jnp.einsum("qx,gxy->gqy", v, w)
    return jnp.einsum("qx,xy->qy", v, w)[None]


def _plan(n: int) -> tuple[int, ...]:
    """Fan-outs of the blocking levels for a block-state recursion of length `n`.

    Heuristic: at each level take the first of (4, 5, 6, 8, 3) that divides the current
    length (no padding copy), else 4 with padding; stop at `_LMIN` or fewer.
    """
    plan = []
    while n > _LMIN:
        p = next((c for c in (4, 5, 6, 8, 3) if n % c == 0), 4)
        plan.append(p)
        n = -(-n // p)
    return tuple(plan)


def _level_powers(m: Array, plan: tuple[int, ...]) -> tuple[tuple[Array, ...], Array]:
    """Powers `[M_l^0 .. M_l^P_l]` of `M_l = M^(P_0 ⋯ P_(l-1))` per level, and the top `M_L`."""
    out = []
    for p in plan:
        mp = _powers(m, p)
        out.append(mp)
        m = mp[..., p, :, :, :]
    return tuple(out), m


def _block_states(mps: tuple[Array, ...], mtop: Array, z: Array, s0: Array) -> tuple[Array, Array]:
    """States `s_i` of `s_{i+1} = M s_i + z_i` for `i = 0 .. L-1` (`s_0` given), and `s_L`.

    `z (g, L, 2, nb)`, `s0 (g, 2, nb)`; `mps[l] (g|1, P_l+1, 2, 2, nb)` are the powers of
    the level-`l` block matrix. Solved by blocking in chunks of `P`: the zero-state end of
    every chunk `Σ_p M^(P-1-p) z_p`, the chunk starts by the same recursion with `M^P`
    (recursively), then every state inside a chunk in closed form
    `M^p s_c + Σ_{j<p} M^(p-1-j) z_j` — independent expressions, so XLA has no sequential
    chain to fuse and recompute. A scan of at most `_LMIN` steps remains at the top.
    """
    g, n = z.shape[:2]
    if not mps:

        def step(s, zi):
            return _bmv(mtop, s) + zi, s

        s_end, states = jax.lax.scan(step, s0, jnp.moveaxis(z, 1, 0))
        return jnp.moveaxis(states, 0, 1), s_end
    P = mps[0].shape[-4] - 1
    n_pad = -(-n // P) * P
    zp = jnp.pad(z, ((0, 0), (0, n_pad - n), (0, 0), (0, 0))) if n_pad != n else z
    zr = zp.reshape(g, n_pad // P, P, *z.shape[2:])
    mp = mps[0][:, None]  # (g|1, 1, P+1, 2, 2, nb)
    zc = sum(_bmv(mp[:, :, P - 1 - p], zr[:, :, p]) for p in range(P))
    sc, s_end = _block_states(mps[1:], mtop, zc, s0)
    states = [sc] + [
        _bmv(mp[:, :, p], sc) + sum(_bmv(mp[:, :, p - 1 - j], zr[:, :, j]) for j in range(p))
        for p in range(1, P)
    ]
    return jnp.stack(states, axis=2).reshape(g, n_pad, *z.shape[2:])[:, :n], s_end


_MSG_NAN = "simulate: u contains NaN or inf; clean or interpolate the input signal first."
_MSG_MODEL = (
    "simulate: the model's parameters are NaN or inf; give finite parameters (a NaN usually "
    "comes from a failed fit or a division by zero upstream)."
)
_MSG_OVERFLOW = (
    "simulate: the response is not finite (overflow). The model is unstable, or the "
    "Euler/Heun step is unstable for this dt (dt·|λ| too large): use method='zoh' or "
    "'tustin', or a smaller dt."
)


class _Lanes(NamedTuple):
    """Static layout of one engine call: whether the tables (`tab`) and the input (`u`)
    carry a leading lane axis, the block length `k`, single-input and single-output
    shapes."""

    tab: bool
    u: bool
    k: int
    siso_in: bool
    siso_out: bool


class _Reduction(NamedTuple):
    """Reduce the output over time from sample `start` (`reduce`), against a target that
    carries the lane axis when `t_lanes` (see `_reduce`)."""

    reduce: bool = False
    t_lanes: bool = False
    start: int = 0


def _run_group(
    tab: dict[str, Any],
    u: Array,
    s0: Array,
    lanes: _Lanes,
    target: Array | None = None,
    red: _Reduction = _Reduction(),
) -> Array:
    """Simulate one group of lanes.

    With `reduce`, the group's output is reduced over time at once (see `_reduce`) and
    only the per-lane sums leave the group: the full output is never written out.

    `u (g?, N)` (single input) or `(g?, N, in)`, `s0 (g, 2, nb)`; returns `y (g, N)` (single
    output) or `(g, N, out)`. Raises (eqx.error_if) when the output is not finite; the input
    is only scanned for NaN/inf to word the message, i.e. off the fast path.
    """
    tab_lanes, u_lanes, k, siso_in, siso_out = lanes
    n = u.shape[-1] if siso_in else u.shape[-2]
    m = 1 if siso_in else u.shape[-1]
    g = s0.shape[0]
    nb = s0.shape[-1]
    q = -(-n // k)
    if q * k != n:  # causal: zeros appended at the end do not change earlier outputs
        pad = [(0, 0)] * (u.ndim - (1 if siso_in else 2)) + [(0, q * k - n)]
        u_p = jnp.pad(u, pad if siso_in else pad + [(0, 0)])
    else:
        u_p = u
    lead = u_p.shape[:-1] if siso_in else u_p.shape[:-2]
    v = u_p.reshape(*lead, q, k * m)
    lane = (lambda x: x) if tab_lanes else (lambda x: x[None])
    z = _bdot(v, tab["R"], u_lanes, tab_lanes).reshape(g, q, 2, nb)
    s, s_end = _block_states(tuple(map(lane, tab["MP"])), lane(tab["Mtop"]), z, s0)
    # NaN/inf anywhere in u reaches the final state (NaN·0 = NaN in every dot product), and
    # so does an overflow of the recursion: checking the small final state is enough. The
    # input itself is scanned only to word the message (off the fast path). The check is
    # an added zero so that the error sits on the path of y without copying y.
    bad = ~jnp.all(jnp.isfinite(s_end))
    bad_u = jax.lax.cond(bad, lambda: ~jnp.all(jnp.isfinite(v)), lambda: jnp.array(False))
    chk = eqx.error_if(jnp.zeros((), s.dtype), bad_u, _MSG_NAN)
    chk = eqx.error_if(chk, bad & ~bad_u, _MSG_OVERFLOW)
    y = _bdot(v, tab["T"], u_lanes, tab_lanes) + (
        _bdot(s.reshape(g, q, 2 * nb), tab["O"], True, tab_lanes) + chk
    )
    y = y.reshape(g, q * k) if siso_out else y.reshape(g, q * k, -1)
    y = y[:, :n] if q * k != n else y
    if red.reduce:
        return _reduce(y, target, red.t_lanes, red.start)
    return y


def _reduce(y: Array, target: Array | None, t_lanes: bool, start: int) -> Array:
    """Per-lane sums over time (from sample `start`) of one group's output `y (g, N[, out])`:
    `[Σy, Σy², Σ(y − ȳ)², Σt, Σ(t − t̄)², Σ(y − ȳ)(t − t̄), Σ(y − t)²]` on a last axis of 7
    (target terms 0 without a target). A lane's whole record lives in its group, so the
    centred sums are exact two-pass sums and errors are formed before squaring."""
    y = y[:, start:]
    n = y.shape[1]
    ym = jnp.sum(y, 1, keepdims=True) / n
    dy = y - ym
    zero = jnp.zeros(y.shape[:1] + y.shape[2:], y.dtype)
    out = [ym[:, 0] * n, jnp.sum(y * y, 1), jnp.sum(dy * dy, 1)]
    if target is None:
        return jnp.stack(out + [zero] * 4, -1)
    t = target[..., start:, :] if y.ndim == 3 else target[..., start:]
    t = t if t_lanes else t[None]
    tm = jnp.sum(t, -2 if y.ndim == 3 else -1, keepdims=True) / n
    dt_ = t - tm
    e = y - t
    return jnp.stack(
        out
        + [
            jnp.broadcast_to(tm[:, 0] * n, zero.shape),
            jnp.broadcast_to(jnp.sum(dt_ * dt_, 1), zero.shape),
            jnp.sum(dy * dt_, 1),
            jnp.sum(e * e, 1),
        ],
        -1,
    )


def _group_target(n_lanes: int, n_samples: int, channels: int) -> int:
    """Lanes per group so that one group's signals fill about `_GROUP_SAMPLES` (heuristic)."""
    return max(1, min(n_lanes, _GROUP_SAMPLES // max(1, n_samples * channels)))


def _engine(
    tab: dict[str, Any],
    u: Array,
    s0: Array,
    lanes: _Lanes,
    target: Array | None = None,
    red: _Reduction = _Reduction(),
) -> Array:
    """All lanes, in groups of `g` mapped with `jax.lax.map`.

    `tab` leaves carry a leading lane axis when `lanes.tab`, `u` when `lanes.u`; `s0`
    always has it. `g` is the largest divisor of the lane count below the cache target;
    for an awkward count (e.g. a large prime) full groups are mapped and the rest run as
    one group.
    """
    n_lanes = s0.shape[0]
    n = u.shape[-1] if lanes.siso_in else u.shape[-2]
    channels = (1 if lanes.siso_in else u.shape[-1]) + (tab["T"].shape[-1] // lanes.k)
    per_group = _group_target(n_lanes, n, channels)
    g = next(d for d in range(per_group, 0, -1) if n_lanes % d == 0)
    if g == n_lanes:
        return _run_group(tab, u, s0, lanes, target, red)
    if 4 * g < per_group:
        n_main = (n_lanes // per_group) * per_group
        head = _map_groups(tab, u, s0, (per_group, n_main), lanes, target, red)
        rest = slice(n_main, n_lanes)
        tail = _run_group(
            jax.tree_util.tree_map(lambda x: x[rest], tab) if lanes.tab else tab,
            u[rest] if lanes.u else u,
            s0[rest],
            lanes,
            None if target is None else (target[rest] if red.t_lanes else target),
            red,
        )
        return jnp.concatenate([head, tail], axis=0)
    return _map_groups(tab, u, s0, (g, n_lanes), lanes, target, red)


def _map_groups(tab, u, s0, groups, lanes: _Lanes, target=None, red=_Reduction()):
    """`jax.lax.map` over the first `n_used` lanes in groups of `g` (`groups = (g,
    n_used)`)."""
    g, n_used = groups
    n_groups = n_used // g
    t_lanes = target is not None and red.t_lanes

    def split(x):
        x = x if x.shape[0] == n_used else x[:n_used]
        return x.reshape(n_groups, g, *x.shape[1:])

    xs: dict[str, Any] = {"s0": split(s0)}
    if lanes.tab:
        xs["tab"] = jax.tree_util.tree_map(split, tab)
    if lanes.u:
        xs["u"] = split(u)
    if t_lanes:
        xs["target"] = split(target)

    def body(x):
        return _run_group(
            x["tab"] if lanes.tab else tab,
            x["u"] if lanes.u else u,
            x["s0"],
            lanes,
            x["target"] if t_lanes else target,
            red,
        )

    y = jax.lax.map(body, xs)
    return y.reshape(n_groups * g, *y.shape[2:])


# ---------------------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------------------


def _has_modal_coordinates(model: AbstractLinearModel) -> bool:
    """True when `model.to_state_space()` is its modal realisation (x0 needs no transform)."""
    return type(model).to_state_space is AbstractLinearModel.to_state_space


def _realisation_with_x0_map(model: AbstractLinearModel) -> tuple[ModalRealisation, Array]:
    """Modal realisation of a dense-state model plus `T` with `x_modal = T x_dense`.

    The identity is appended to `B` as `n` extra inputs: the modal form maps it with the
    same eigenvectors, pairing and balancing as the true inputs, so the extra columns of
    the realised `b` are the coordinate map `(block, 2, n)` of that very realisation.
    """
    ss = model.to_state_space()
    n, m = ss.B.shape[-2], ss.B.shape[-1]
    eye = jnp.eye(n, dtype=ss.B.dtype)
    aug = from_dense(
        ss.A,
        jnp.concatenate([ss.B, eye], axis=-1),
        ss.C,
        jnp.concatenate([ss.D, jnp.zeros((ss.D.shape[0], n), ss.D.dtype)], axis=-1),
    )
    r = ModalRealisation(aug.a, aug.b[..., :m], aug.c, aug.d[..., :m], n_states=aug.n_states)
    return r, aug.b[..., m:]


def _float_dtype(x: Array, who: str) -> Any:
    if jnp.iscomplexobj(x):
        raise TypeError(
            f"{who}: u must be real; got a complex array. Simulate the real and imaginary "
            "parts separately."
        )
    if not jnp.issubdtype(x.dtype, jnp.floating):
        return jnp.result_type(float)
    if jnp.finfo(x.dtype).bits < 32:
        return jnp.float32
    return x.dtype


def simulate(
    model: AbstractLinearModel,
    u: ArrayLike,
    dt: ArrayLike,
    *,
    method: Method = "zoh",
    x0: ArrayLike | None = None,
) -> Float[Array, "*batch time"] | Float[Array, "*batch time out"]:
    """Time response of a linear model, or of a whole family, to sampled inputs.

    `y[k] = C x[k] + D u[k]`, `x[0] = x0`, with the model discretised at sample time `dt`:

    - `"zoh"` (default): exact for inputs held constant over each sample (zero-order hold,
      matrix exponential of each 2x2 block of the modal realisation).
    - `"tustin"`: bilinear / trapezoidal rule (uses `u[k]` and `u[k+1]`).
    - `"euler"`: forward Euler, `x[k+1] = x[k] + dt (A x[k] + B u[k])`.
    - `"heun"`: explicit trapezoid predictor-corrector with `u[k]` and `u[k+1]` — the
      real-time integrators of the TMF study (Doerrer et al. 2022, §2.3). Euler and Heun
      are only stable for `dt |λ|` small enough for every pole `λ`.

    See [`discretise`][] for the formulas. The time stepping is blocked (see the module
    docstring): results equal the sample-by-sample recursion up to rounding.

    **Arguments:**

    - `model`: any jaxvs linear model. Parameters with leading batch axes make a family
      (e.g. one transmissibility per position of the other axis), simulated in one call.
    - `u`: inputs sampled every `dt`: `(*batch, time)` for a single-input model,
      `(*batch, time, in)` otherwise. Batch shapes combine as: unbatched model with
      batched inputs, batched model with one shared input `(time[, in])`, or equal batch
      shapes (member `i` gets input `i`). A float32 input simulates in float32 (the model
      is discretised in its own precision, then cast); integers are converted to the
      default float type.
    - `dt`: sample time [s], a positive scalar.
    - `method`: `"zoh"`, `"tustin"`, `"euler"` or `"heun"`.
    - `x0`: initial state `(n,)` or `(*batch, n)`, `n = model.order`, in the coordinates of
      `model.to_state_space()` (the modal realisation for `RationalTF` and `ModalModel`,
      the user's own `A, B, C, D` for `StateSpace`). Default: zeros.

    **Returns:**

    `(*batch, time)` for a single-output model, otherwise `(*batch, time, out)`, in the
    input's floating dtype.

    **Raises:**

    `ValueError`/`TypeError` at trace time for wrong shapes, an unknown method or a
    concrete non-positive `dt`; at run time (`eqx.error_if`, also under `jit`) when `u`
    contains NaN or inf, when a traced `dt` is not positive, or when the response
    overflows (an unstable model or an unstable Euler/Heun step).
    """
    u_flat, dt_arr, x0, batch, u_lanes = _checked(model, u, dt, method, x0, "simulate")
    # The engine parameters are part of the jit cache key (they are module-level
    # heuristics, read at trace time).
    config = (_K, _LMIN, _GROUP_SAMPLES)
    y = _simulate_flat(model, u_flat, dt_arr, x0, method, batch, u_lanes, config)
    return y.reshape(batch + y.shape[1:])


def _checked(model, u, dt, method, x0, who):
    """Validate the arguments of `simulate` / `simulate_metrics`; return the flattened
    input, `dt`, `x0`, the batch shape and whether the input has lanes."""
    check_model(model, who)
    _check_method(method, who)
    u = jnp.asarray(u)
    cdt = _float_dtype(u, who)
    u = u.astype(cdt)
    m = model.n_inputs
    if m == 1 and u.ndim >= 2 and u.shape[-1] == 1:
        # A column (time, 1) is time x inputs, as for multi-input models -- never a batch of
        # one-sample experiments.
        u = u[..., 0]
    core = 1 if m == 1 else 2
    if u.ndim < core:
        expected = "(*batch, time)" if m == 1 else f"(*batch, time, {m})"
        raise ValueError(
            f"{who}: u has shape {u.shape}; this model has {m} input(s), so u must be {expected}."
        )
    if m > 1 and u.shape[-1] != m:
        raise ValueError(
            f"{who}: u has shape {u.shape} but the model has {m} inputs; give u as "
            f"(*batch, time, {m}) with the inputs on the last axis."
        )
    n_time = u.shape[-core]
    if n_time < 1:
        raise ValueError(f"{who}: u has no samples (time axis of length 0).")
    u_batch = tuple(u.shape[: u.ndim - core])
    m_batch = tuple(model.batch_shape)
    if u_batch == m_batch or u_batch == () or m_batch == ():
        batch = u_batch if u_batch else m_batch
    else:
        raise ValueError(
            f"{who}: the model family has batch shape {m_batch} and u has batch shape "
            f"{u_batch}; they must be equal (member i gets input i), or one of them must "
            "be unbatched (one model for many inputs, or one input shared by the family). "
            "Broadcast explicitly with jnp.broadcast_to, or jax.vmap over the extra axes."
        )
    n = model.order
    if x0 is not None:
        x0 = jnp.asarray(x0)
        if jnp.iscomplexobj(x0):
            raise TypeError(f"{who}: x0 must be real.")
        x0 = check_finite(x0, f"{who}: x0", "Give a finite initial state (default: zeros).")
        if x0.shape not in ((n,), batch + (n,)):
            raise ValueError(
                f"{who}: x0 has shape {x0.shape}; expected ({n},) or {batch + (n,)} (the "
                f"model has {n} states in the coordinates of model.to_state_space())."
            )
    params = [concrete(x) for x in jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_array))]
    if any(p is not None and not np.isfinite(p).all() for p in params):
        raise ValueError(
            f"{who}: the model ({type(model).__name__}) has NaN or inf parameters; give finite "
            "parameters (a NaN usually comes from a failed fit or a division by zero upstream)."
        )
    dt_arr = _check_dt(dt, who)
    u_flat = u.reshape((-1,) + u.shape[-core:]) if u_batch else u
    return u_flat, dt_arr, x0, batch, bool(u_batch)


@eqx.filter_jit
def _simulate_flat(
    model,
    u,
    dt,
    x0,
    method,
    batch,
    u_lanes,
    config,
    target=None,
    red: _Reduction = _Reduction(),
):
    """Discretise, build tables and run the engine on flattened lanes (jitted); `red`:
    reduce the output over time (against `target`) instead of returning it."""
    # NaN/inf parameters are named as such (not reported as an unstable model), and caught
    # where they reach only the output (a NaN residue leaves the states finite).
    params = jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))
    if params:
        bad = ~jnp.all(jnp.stack([jnp.all(jnp.isfinite(p)) for p in params]))
        u = eqx.error_if(u, bad, _MSG_MODEL)
    cdt = u.dtype
    n_lanes = math.prod(batch)
    m_batch = tuple(model.batch_shape)
    if x0 is not None and not _has_modal_coordinates(model):

        def disc(mm):
            r, tmap = _realisation_with_x0_map(mm)
            return discretise_realisation(r, dt, method), tmap

        rd, tmap = map_batch(disc, model)
    else:
        rd = map_batch(lambda mm: discretise_realisation(mm.modal_realisation(), dt, method), model)
        tmap = None
    tab_lanes = m_batch != ()
    flat = (
        (lambda x: x.reshape((-1,) + x.shape[len(m_batch) :])) if tab_lanes else (lambda x: x[None])
    )
    rflat = DiscreteModalRealisation(
        flat(rd.a),
        flat(rd.b),
        flat(rd.c),
        flat(rd.d),
        flat(rd.b1),
        dt,
        method=method,
        n_states=rd.n_states,
    )
    m, p = rflat.b.shape[-1], rflat.c.shape[-3]
    siso_in, siso_out = m == 1, p == 1
    n_time = u.shape[-1] if siso_in else u.shape[-2]
    k = min(_K, n_time)
    tab = _tables(rflat, k)
    tab["MP"], tab["Mtop"] = _level_powers(tab["M"], _plan(-(-n_time // k)))
    del tab["M"]
    tab = jax.tree_util.tree_map(lambda x: x.astype(cdt) if tab_lanes else x[0].astype(cdt), tab)
    nb = rflat.a.shape[-3]
    # Initial state of the standard form: ξ0 = x0_modal - B1 u[0]  (all lanes).
    if x0 is None:
        x_modal = jnp.zeros((1, nb, 2), rflat.a.dtype)
    else:
        x0 = x0.astype(rflat.a.dtype)
        x0f = x0.reshape(-1, x0.shape[-1])  # (1 | L, n)
        if tmap is not None:
            tf = flat(tmap)  # (1 | L, block, 2, n)
            x_modal = jnp.sum(tf * x0f[:, None, None, :], axis=-1)
        else:
            x_pad = jnp.pad(x0f, ((0, 0), (0, 2 * nb - x0f.shape[-1])))
            x_modal = x_pad.reshape(-1, nb, 2)
    u_l = u if u_lanes else u[None]
    u0 = (u_l[:, 0, None] if siso_in else u_l[:, 0, :]).astype(rflat.a.dtype)  # (1|L, in)
    xi0 = x_modal - jnp.sum(rflat.b1 * u0[:, None, None, :], axis=-1)
    xi0 = jnp.broadcast_to(jnp.moveaxis(xi0, -1, -2), (n_lanes, 2, nb)).astype(cdt)
    target = None if target is None else target.astype(cdt)
    return _engine(tab, u, xi0, _Lanes(tab_lanes, u_lanes, k, siso_in, siso_out), target, red)


class SimulationMetrics(eqx.Module):
    """Per-member summaries of a simulated family, from [`simulate_metrics`][].

    Every field has the family's batch shape (plus the output axis for a multi-output
    model); the target fields are `None` when no target was given.

    - `n_samples`: number of samples reduced (`time − start`).
    - `mean`, `rms`, `std`: mean, root mean square and (population) standard deviation of
      the simulated output.
    - `rms_error`: `sqrt(mean((y − target)²))`; `sse`: `Σ (y − target)²` (the
      least-squares cost of an output-error fit, times 2).
    - `correlation`: Pearson correlation of `y` with the target.
    """

    n_samples: int = eqx.field(static=True)
    mean: Array
    rms: Array
    std: Array
    rms_error: Array | None = None
    sse: Array | None = None
    correlation: Array | None = None


def simulate_metrics(
    model: AbstractLinearModel,
    u: ArrayLike,
    dt: ArrayLike,
    target: ArrayLike | None = None,
    *,
    method: Method = "zoh",
    x0: ArrayLike | None = None,
    start: int = 0,
) -> SimulationMetrics:
    """Simulate a model or a whole family and reduce each member's output over time at
    once — RMS, error against a target, correlation, cost — without ever writing the full
    `(*batch, time)` output.

    Same engine, arguments and checks as [`simulate`][] (the results are those of
    `simulate` followed by the reduction, up to rounding); the lanes are simulated group by
    group and each group's output is reduced inside the group, so the memory written is
    that of one group, not of the family. Use it where a family is simulated only to be
    scored: model selection over a grid, a population's fitness, a multi-start's costs.

    **Arguments:**

    - `model`, `u`, `dt`, `method`, `x0`: as for [`simulate`][].
    - `target`: optional measured output, shaped like `simulate`'s result, or without the
      batch axes (one target shared by every member).
    - `start`: first sample reduced (skip an initial transient or an initialisation
      window), `0 <= start < time`.

    **Returns:**

    A [`SimulationMetrics`][] with one value per member (and output).

    **Raises:**

    As [`simulate`][]; `ValueError` when `target` has another shape or is not finite, or
    `start` is out of range.
    """
    who = "simulate_metrics"
    u_flat, dt_arr, x0, batch, u_lanes = _checked(model, u, dt, method, x0, who)
    multi = model.n_outputs > 1
    n_time = u_flat.shape[-2] if model.n_inputs > 1 else u_flat.shape[-1]
    if not (isinstance(start, (int, np.integer)) and 0 <= start < n_time):
        raise ValueError(
            f"{who}: start must be an int in [0, {n_time}) (the first sample reduced); got "
            f"{start!r}."
        )
    core = (n_time, model.n_outputs) if multi else (n_time,)
    t_lanes = False
    if target is not None:
        target = jnp.asarray(target)
        if target.shape not in (core, batch + core):
            raise ValueError(
                f"{who}: target has shape {target.shape}; give {batch + core} (one per member) "
                f"or {core} (shared by the family), shaped like simulate's output."
            )
        target = check_finite(target, f"{who}: target", "Give a finite measured output.")
        t_lanes = target.shape == batch + core and batch != ()
        if t_lanes:
            target = target.reshape((-1,) + core)
    config = (_K, _LMIN, _GROUP_SAMPLES)
    sums = _simulate_flat(
        model,
        u_flat,
        dt_arr,
        x0,
        method,
        batch,
        u_lanes,
        config,
        target,
        _Reduction(True, t_lanes, int(start)),
    )
    sums = sums.reshape(batch + sums.shape[1:])
    n = n_time - int(start)
    s = [sums[..., i] for i in range(7)]
    out = {
        "mean": s[0] / n,
        "rms": jnp.sqrt(s[1] / n),
        "std": jnp.sqrt(s[2] / n),
    }
    if target is not None:
        out["rms_error"] = jnp.sqrt(s[6] / n)
        out["sse"] = s[6]
        out["correlation"] = s[5] / jnp.sqrt(s[2] * s[4])
    return SimulationMetrics(n, **out)


__all__ = ["METHODS", "SimulationMetrics", "simulate", "simulate_metrics"]
