"""Training of the thermal study's virtual sensors: least-squares regression on bias-free
inputs, and Levenberg-Marquardt (MATLAB `trainlm`) or Adam training of the networks.

`train_lm` is a `trainlm` clone that runs *all* epochs in one jitted `while_loop`:

1. the Gauss-Newton normal equations `JᵀJ`, `Jᵀe` of all weights. For the two-layer
   perceptron they are assembled from the Kronecker structure of the Jacobian rows
   (`[d ⊗ x̃, h̃]`, see `Perceptron.normal_equations`) over symmetric upper triangles, in
   cache-sized chunks, without forming `J` (about 3× fewer flops than `JᵀJ` for the
   study's TDNN); for other modules from the batched Jacobian (a `vmap` of per-sample
   reverse-mode gradients);
2. the damped step `(JᵀJ + μ I) δ = -Jᵀe` by Cholesky -- jaxvs's one Levenberg-Marquardt
   (`jaxvs.calibration.lm_solve`) with trainlm's `MarquardtDamping` --, with `μ`
   multiplied by `mu_inc` until the step reduces the MSE and by `mu_dec` after a
   successful step (Hagan &
   Menhaj 1994, "Training feedforward networks with the Marquardt algorithm", IEEE TNN
   5(6); MATLAB `trainlm` defaults `mu = 1e-3, mu_dec = 0.1, mu_inc = 10, mu_max = 1e10`);
3. early stopping on a validation block: training stops after `max_fail` consecutive
   epochs without a new best validation MSE, and the best-validation weights are returned.

Inputs and target are normalised to [-1, 1] by their training ranges (`mapminmax`)
before training; the normalisation is stored in the network.
"""

import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, ArrayLike, Float, Int

from ..._misc import input_columns, timed_call
from ...calibration import (
    RESULTS,
    AbstractLMMonitor,
    ExcitationWarning,
    LMState,
    MarquardtDamping,
    lm_init,
    lm_solve,
)
from ...models import BiasFreeRegression, Perceptron

__all__ = [
    "STOP_REASONS",
    "TrainResult",
    "TrainlmOptions",
    "fit_regression",
    "normalise_network",
    "train_adam",
    "train_lm",
]

STOP_REASONS: tuple[str, ...] = (
    "max_epochs",
    "validation_stop",
    "mu_max",
    "min_grad",
    "goal",
)
_MAX_EPOCHS, _VAL_STOP, _MU_MAX, _MIN_GRAD, _GOAL = range(5)
_NO_LIMIT = np.iinfo(np.int32).max  # trial steps of one epoch: bounded by mu_max instead


class TrainResult(eqx.Module):
    """The outcome of [`train_lm`][] or [`train_adam`][].

    **Fields:**

    - `model`: the trained network (best validation epoch when a validation block was
      given, else the last epoch).
    - `train_mse`: `(max_epochs + 1,)` training MSE [target unit²] after each epoch (index 0:
      initial weights); NaN after the last epoch run.
    - `val_mse`: the same on the validation block (NaN without one).
    - `epochs`: number of epochs run; `best_epoch`: the epoch whose weights are returned.
    - `stop`: index into [`STOP_REASONS`][] (`stop_reason` gives the name).
    - `stats`: `compile_time`, `run_time` [s] (measured outside `jit`).
    """

    model: Any
    train_mse: Float[Array, " epoch"]
    val_mse: Float[Array, " epoch"]
    epochs: Int[Array, ""]
    best_epoch: Int[Array, ""]
    stop: Int[Array, ""]
    stats: dict[str, Any]

    @property
    def stop_reason(self) -> str:
        return STOP_REASONS[int(self.stop)]

    @property
    def result(self) -> RESULTS:
        """Why training stopped, as a code of jaxvs's one `RESULTS` enumeration
        (`max_steps_reached` for the epoch budget, `validation_stop`, `damping_limit`,
        `gradient_small`, `goal_reached`)."""
        codes = (
            RESULTS.max_steps_reached,
            RESULTS.validation_stop,
            RESULTS.damping_limit,
            RESULTS.gradient_small,
            RESULTS.goal_reached,
        )
        out = codes[0]
        for i, code in enumerate(codes[1:], start=1):
            out = RESULTS.where(self.stop == i, code, out)
        return out

    @property
    def time_per_epoch(self) -> float:
        """Run time divided by the epochs run [s]."""
        return float(self.stats["run_time"]) / max(int(self.epochs), 1)


# ----------------------------------------------------------------------------- helpers


def _as_xy(u: Any, y: Any, n_inputs: int, where: str) -> tuple[Array, Array]:
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    u = input_columns(u, n_inputs, where)
    if y.ndim != 1 or y.shape[0] != u.shape[0]:
        raise ValueError(
            f"{where}: the target must be 1-D with one value per input row ({u.shape[0]}); "
            f"got shape {y.shape}."
        )
    for name, a in (("inputs", u), ("target", y)):
        bad = ~np.isfinite(a)
        if bad.any():
            raise ValueError(
                f"{where}: the {name} have {int(bad.sum())} NaN/inf values (missing samples). "
                "Resample the target onto the input grid first "
                "(jaxvs.studies.resample_sparse) or cut the record."
            )
    return jnp.asarray(u), jnp.asarray(y)


def _warn_constant(u: np.ndarray, where: str) -> None:
    span = np.ptp(np.asarray(u), axis=0)
    for i in np.flatnonzero(span == 0):
        warnings.warn(
            f"{where}: input column {i} is constant over the training data: it carries no "
            "information and its weights are not identified. Drop it from the inputs.",
            ExcitationWarning,
            stacklevel=3,
        )


def normalise_network(net: Any, u: Any, y: Any) -> Any:
    """`net` with its input/output normalisation set from data (MATLAB `mapminmax`):
    every input column and the target are mapped from their `[min, max]` to [-1, 1]."""
    u, y = _as_xy(u, y, net.n_inputs, "normalise_network")
    lo, hi = jnp.min(u, axis=0), jnp.max(u, axis=0)
    half = (hi - lo) / 2
    ylo, yhi = jnp.min(y), jnp.max(y)
    yhalf = (yhi - ylo) / 2
    return eqx.tree_at(
        lambda m: (m.u_offset, m.u_scale, m.y_offset, m.y_scale),
        net,
        (
            (lo + hi) / 2,
            jnp.where(half > 0, half, 1.0),
            (ylo + yhi) / 2,
            jnp.where(yhalf > 0, yhalf, 1.0),
        ),
    )


def _prepare(net, u, y, validation, normalise, where):
    """The trainers' common arguments: the (normalised) network, the training and validation
    features and normalised targets, and whether a validation set was given."""
    u, y = _as_xy(u, y, net.n_inputs, where)
    _warn_constant(np.asarray(u), where)
    if validation is not None:
        if not (isinstance(validation, tuple | list) and len(validation) == 2):
            raise TypeError(f"{where}: validation must be a pair (u_val, y_val).")
        uv, yv = _as_xy(validation[0], validation[1], net.n_inputs, where + " (validation)")
    else:
        uv, yv = u[: net.max_delay + 1], y[: net.max_delay + 1]  # dummy, unused
    if normalise:
        net = normalise_network(net, u, y)
    X = net.features(u)
    yn = (y - net.y_offset) / net.y_scale
    Xv = net.features(uv)
    yvn = (yv - net.y_offset) / net.y_scale
    return net, X, yn, Xv, yvn, jnp.asarray(validation is not None)


def _split(net):
    params, static = eqx.partition(net.perceptron, eqx.is_inexact_array)
    theta, unravel = ravel_pytree(params)
    return theta, unravel, static


def _train(impl, args) -> TrainResult:
    """Run a compiled trainer (`_lm_impl`, `_adam_impl`) and time it."""
    out, t_compile, t_run = timed_call(impl, *args)
    model, train_mse, val_mse, epochs, best_epoch, stop = out
    return TrainResult(
        model=model,
        train_mse=train_mse,
        val_mse=val_mse,
        epochs=epochs,
        best_epoch=best_epoch,
        stop=stop,
        stats={"compile_time": t_compile, "run_time": t_run},
    )


# ----------------------------------------------------------------------------- LM


class _LMState(eqx.Module):
    lm: LMState
    epoch: Array
    train_hist: Array
    val_hist: Array
    best_theta: Array
    best_val: Array
    best_epoch: Array
    fails: Array
    stop: Array
    running: Array


class TrainlmOptions(eqx.Module):
    """The damping and gradient settings of [`train_lm`][], with MATLAB `trainlm`'s names
    and defaults: the initial damping `mu`, its factors `mu_dec` after a successful and
    `mu_inc` after a failed step, the damping `mu_max` at which training stops, and the
    gradient norm `min_grad` (of the normalised MSE) below which it stops."""

    mu: float = 1e-3
    mu_dec: float = 0.1
    mu_inc: float = 10.0
    mu_max: float = 1e10
    min_grad: float = 1e-7

    def __check_init__(self):
        mu, dec, inc, mu_max = self.mu, self.mu_dec, self.mu_inc, self.mu_max
        if isinstance(mu, jax.Array):  # the traced copy inside the compiled trainer
            return
        if not (0 < dec < 1 < inc and mu > 0 and mu_max > mu):
            raise ValueError(
                "train_lm: need mu > 0, 0 < mu_dec < 1 < mu_inc and mu_max > mu (trainlm: "
                "1e-3, 0.1, 10, 1e10)."
            )


class _UntilAccepted(AbstractLMMonitor):
    """trainlm's epoch: trial steps with growing damping until one reduces the error or
    the damping passes `mu_max`."""

    mu_max: Array

    def init(self, state, args):
        return jnp.asarray(False)

    def update(self, watch, old, new, args):
        return new.cost < old.cost

    def running(self, watch, state, args):
        return (~watch) & (state.mu <= self.mu_max)


def _lm_impl(data, max_epochs, max_fail, goal, gram_dtype, options: TrainlmOptions):
    net, X, yn, Xv, yvn, has_val = data
    theta0, unravel, static = _split(net)
    scale2 = net.y_scale**2
    n = X.shape[0]

    def predict(theta, x):
        return eqx.combine(unravel(theta), static)(x)

    def outputs(theta, XX):
        return jax.vmap(lambda x: predict(theta, x))(XX)

    def mse(theta, XX, yy):
        e = outputs(theta, XX) - yy
        return jnp.mean(e**2)

    gram = theta0.dtype if gram_dtype is None else gram_dtype

    # Gauss-Newton normal equations: the perceptron's structured form (JᵀJ from the
    # Kronecker structure of its Jacobian rows, chunked, J never formed), or for other
    # modules the batched Jacobian of per-sample reverse-mode gradients. JᵀJ is the
    # dominant cost; gram_dtype=float32 halves it at ~1e-7 relative accuracy of the
    # Gauss-Newton matrix, while the Cholesky solve and the accept test stay in the data's
    # precision.
    if isinstance(net.perceptron, Perceptron):

        def normal_equations(theta, e):
            return eqx.combine(unravel(theta), static).normal_equations(X, e, dtype=gram)

    else:
        jac = jax.vmap(jax.grad(predict), in_axes=(None, 0))

        def normal_equations(theta, e):
            J = jac(theta, X)
            Jg = J.astype(gram)
            return (Jg.T @ Jg).astype(J.dtype), J.T @ e

    # The one LM (jaxvs.calibration.lm_solve) with trainlm's damping: trials are
    # judged by the cheap cost; the normal equations are formed once per accepted step.
    def cost(theta, _):
        return 0.5 * jnp.sum((outputs(theta, X) - yn) ** 2)

    def evaluate(theta, _):
        e = outputs(theta, X) - yn
        jtj, jtr = normal_equations(theta, e)
        return 0.5 * jnp.sum(e**2), jtj, jtr

    damping = MarquardtDamping(options.mu_dec, options.mu_inc)
    lm0 = lm_init(evaluate, theta0, None, 0.0, options.mu)
    mse0 = 2.0 * lm0.cost / n
    val0 = jnp.where(has_val, mse(theta0, Xv, yvn), jnp.nan)
    hist = jnp.full((max_epochs + 1,), jnp.nan, theta0.dtype)
    s0 = _LMState(
        lm=lm0,
        epoch=jnp.asarray(0),
        train_hist=hist.at[0].set(mse0 * scale2),
        val_hist=hist.at[0].set(val0 * scale2),
        best_theta=theta0,
        best_val=jnp.where(has_val, val0, jnp.inf),
        best_epoch=jnp.asarray(0),
        fails=jnp.asarray(0),
        stop=jnp.asarray(_MAX_EPOCHS),
        running=jnp.asarray(max_epochs > 0) & (mse0 * scale2 > goal),
    )

    def epoch(s: _LMState) -> _LMState:
        grad_norm = jnp.linalg.norm(2.0 * s.lm.jtr / n)

        # trainlm's epoch: trial steps of the one LM driver until one reduces the error.
        # (`rtol = 0`: no convergence test; the epoch loop below applies trainlm's stops.)
        lm, ok = lm_solve(
            evaluate,
            eqx.tree_at(lambda st: st.converged, s.lm, jnp.asarray(False)),
            None,
            max_steps=_NO_LIMIT,
            rtol=0.0,
            damping=damping,
            cost=cost,
            monitor=_UntilAccepted(options.mu_max),
        )
        m = 2.0 * lm.cost / n
        k = s.epoch + 1
        v = jnp.where(has_val, mse(lm.theta, Xv, yvn), jnp.nan)
        better = has_val & (v < s.best_val)
        fails = jnp.where(better, 0, s.fails + 1)
        best_theta = jnp.where(better | ~has_val, lm.theta, s.best_theta)
        best_val = jnp.where(better, v, s.best_val)
        best_epoch = jnp.where(better | ~has_val, k, s.best_epoch)
        stop = jnp.where(
            m * scale2 <= goal,
            _GOAL,
            jnp.where(
                ~ok,
                _MU_MAX,
                jnp.where(
                    grad_norm < options.min_grad,
                    _MIN_GRAD,
                    jnp.where(has_val & (fails >= max_fail), _VAL_STOP, _MAX_EPOCHS),
                ),
            ),
        )
        running = (stop == _MAX_EPOCHS) & (k < max_epochs)
        return _LMState(
            lm=lm,
            epoch=k,
            train_hist=s.train_hist.at[k].set(m * scale2),
            val_hist=s.val_hist.at[k].set(v * scale2),
            best_theta=best_theta,
            best_val=best_val,
            best_epoch=best_epoch,
            fails=fails,
            stop=stop,
            running=running,
        )

    # trainlm's epochs (each one LM solve until a step is accepted) with their stopping
    # rules and the early stopping on the validation block.
    s = jax.lax.while_loop(lambda s: s.running, epoch, s0)
    trained = eqx.tree_at(lambda m: m.perceptron, net, eqx.combine(unravel(s.best_theta), static))
    return trained, s.train_hist, s.val_hist, s.epoch, s.best_epoch, s.stop


def train_lm(
    net: Any,
    u: Float[ArrayLike, "time input"],
    y: Float[ArrayLike, " time"],
    *,
    validation: tuple[ArrayLike, ArrayLike] | None = None,
    max_epochs: int = 1000,
    max_fail: int = 6,
    goal: float = 0.0,
    normalise: bool = True,
    gram_dtype: Any = None,
    options: TrainlmOptions = TrainlmOptions(),
) -> TrainResult:
    """Train all weights of a network by Levenberg-Marquardt (a MATLAB `trainlm` clone).

    **Arguments:**

    - `net`: a [`jaxvs.models.StaticNetwork`][] or [`jaxvs.models.TimeDelayNetwork`][].
    - `u`: `(time, input)` training inputs; `y`: `(time,)` training target.
    - `validation`: `(u_val, y_val)`, a contiguous validation block for early stopping
      (MATLAB's `max_fail` rule); without it training runs to another stop criterion.
    - `max_epochs`, `max_fail`: as `trainlm`.
    - `goal`: stop when the training MSE [target unit²] reaches it.
    - `normalise`: set the network's input/output normalisation from the training data
      first (`mapminmax`); `False` keeps the network's own.
    - `gram_dtype`: dtype in which `JᵀJ` is accumulated (default: the data's); e.g.
      `jnp.float32` under float64 halves the dominant cost of an epoch.
    - `options`: trainlm's damping and gradient settings ([`TrainlmOptions`][]).

    **Returns:**

    A [`TrainResult`][] (all epochs run in one compiled loop; `stats` holds compile and
    run time).

    **Raises / warns:** `ValueError` for shape mismatch or NaN samples;
    `ExcitationWarning` for a constant input column.
    """
    if not (isinstance(max_epochs, int) and max_epochs >= 0):
        raise ValueError(f"train_lm: max_epochs must be an int >= 0, got {max_epochs!r}.")
    if not (isinstance(max_fail, int) and max_fail >= 1):
        raise ValueError(f"train_lm: max_fail must be an int >= 1, got {max_fail!r}.")
    if not isinstance(options, TrainlmOptions):
        raise TypeError(f"train_lm: options must be a TrainlmOptions; got {options!r}.")
    data = _prepare(net, u, y, validation, normalise, "train_lm")
    f = jnp.result_type(float)
    traced = TrainlmOptions(
        mu=jnp.asarray(options.mu, f),
        mu_dec=float(options.mu_dec),  # static: the damping policy is part of the compiled loop
        mu_inc=float(options.mu_inc),
        mu_max=jnp.asarray(options.mu_max, f),
        min_grad=jnp.asarray(options.min_grad, f),
    )
    gram = None if gram_dtype is None else jnp.dtype(gram_dtype)
    args = (data, max_epochs, max_fail, jnp.asarray(goal, f), gram, traced)
    return _train(_lm_impl, args)


# ----------------------------------------------------------------------------- Adam


def _adam_impl(net, X, yn, Xv, yvn, has_val, epochs, learning_rate, goal):
    theta0, unravel, static = _split(net)
    scale2 = net.y_scale**2
    opt = optax.adam(learning_rate)

    def mse(theta, XX, yy):
        model = eqx.combine(unravel(theta), static)
        return jnp.mean((jax.vmap(model)(XX) - yy) ** 2)

    # One gradient evaluation per epoch: the loss of `value_and_grad` at the current
    # weights is the training MSE of the previous epoch, so it is recorded one step late
    # and the last epoch's MSE is evaluated once after the loop.
    def step(carry, _):
        theta, state, best_theta, best_val, best_epoch, k, done = carry
        m, g = jax.value_and_grad(mse)(theta, X, yn)
        done = done | (m * scale2 <= goal)
        upd, state2 = opt.update(g, state, theta)
        theta2 = jnp.where(done, theta, optax.apply_updates(theta, upd))
        state = jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), state, state2)
        k2 = jnp.where(done, k, k + 1)
        v = jnp.where(has_val & ~done, mse(theta2, Xv, yvn), jnp.nan)
        better = has_val & (v < best_val) & ~done
        best_theta = jnp.where(better | (~has_val & ~done), theta2, best_theta)
        best_val = jnp.where(better, v, best_val)
        best_epoch = jnp.where(better | (~has_val & ~done), k2, best_epoch)
        rec = (m * scale2, v * scale2)  # (MSE before this step, validation MSE after it)
        return (theta2, state, best_theta, best_val, best_epoch, k2, done), rec

    v0 = jnp.where(has_val, mse(theta0, Xv, yvn), jnp.nan)
    carry0 = (
        theta0,
        opt.init(theta0),
        theta0,
        jnp.where(has_val, v0, jnp.inf),
        jnp.asarray(0),
        jnp.asarray(0),
        jnp.asarray(False),
    )
    carry, (m_before, vh) = jax.lax.scan(step, carry0, None, length=epochs)
    theta, _, best_theta, _, best_epoch, k, done = carry
    m_last = mse(theta, X, yn) * scale2
    # th[i] = MSE after i epochs; epochs not run (goal reached) are NaN
    th = jnp.concatenate([m_before, jnp.atleast_1d(m_last)])
    th = jnp.where(jnp.arange(epochs + 1) <= k, th, jnp.nan)
    vh = jnp.concatenate([jnp.atleast_1d(v0 * scale2), vh])
    trained = eqx.tree_at(lambda m: m.perceptron, net, eqx.combine(unravel(best_theta), static))
    done = done | (m_last <= goal)
    stop = jnp.where(done, _GOAL, _MAX_EPOCHS)
    return trained, th, vh, k, best_epoch, stop


def train_adam(
    net: Any,
    u: Float[ArrayLike, "time input"],
    y: Float[ArrayLike, " time"],
    *,
    validation: tuple[ArrayLike, ArrayLike] | None = None,
    epochs: int = 1000,
    learning_rate: float = 1e-2,
    goal: float = 0.0,
    normalise: bool = True,
) -> TrainResult:
    """Train all weights of a network by full-batch Adam (optax), for comparison with LM.

    **Arguments:** as [`train_lm`][]; `epochs` full-batch steps of `optax.adam(learning_rate)`
    on the normalised MSE. With a validation block the best-validation weights are
    returned (no early stop: all `epochs` run unless `goal` is reached).

    **Returns:** a [`TrainResult`][].
    """
    if not (isinstance(epochs, int) and epochs >= 1):
        raise ValueError(f"train_adam: epochs must be an int >= 1, got {epochs!r}.")
    data = _prepare(net, u, y, validation, normalise, "train_adam")
    f = jnp.result_type(float)
    args = (
        *data,
        epochs,
        float(learning_rate),
        jnp.asarray(goal, f),
    )
    return _train(_adam_impl, args)


# ----------------------------------------------------------------------------- regression


def fit_regression(
    u: Float[ArrayLike, "time input"],
    y: Float[ArrayLike, " time"],
    *,
    bias: Float[ArrayLike, " input"] | None = None,
) -> BiasFreeRegression:
    """Least-squares linear regression on bias-free inputs (study eq. 2-3).

    **Arguments:**

    - `u`: `(time, input)` inputs (e.g. `T_chassis` [°C] and `v_m` [rpm]).
    - `y`: `(time,)` target (e.g. `T_bearing` [°C]).
    - `bias`: `(input,)` input biases; default: the minimum of each input series (the
      study's choice: 19.8 °C and 496 rpm).

    **Returns:**

    A [`jaxvs.models.BiasFreeRegression`][] `y ≈ intercept + coef · (u - bias)`.

    **Raises / warns:** `ValueError` for shape mismatch or NaN; `ExcitationWarning` for a
    constant input column (its coefficient is then set to 0).
    """
    u = np.asarray(u, dtype=float)
    n_in = 1 if u.ndim == 1 else u.shape[1] if u.ndim == 2 else -1
    uj, yj = _as_xy(u, y, n_in, "fit_regression")
    u, y = np.asarray(uj), np.asarray(yj)
    _warn_constant(u, "fit_regression")
    b = u.min(axis=0) if bias is None else np.broadcast_to(np.asarray(bias, float), (n_in,))
    X = np.column_stack([np.ones(u.shape[0]), u - b])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    return BiasFreeRegression(coef[1:], coef[0], b)
