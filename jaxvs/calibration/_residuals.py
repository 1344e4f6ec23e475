"""Residuals of a calibration: what "the model fits the experiment" means, as a vector.

A residual is a small `eqx.Module` with two methods:

- `prepare(data)` (plain Python, runs once before the solve): turns the user's data
  object -- a `jaxvs.data.Record`, a `jaxvs.data.FRFData`, a mapping of arrays -- into a
  validated pytree of arrays. Shape errors raise `ValueError`/`TypeError` here; values
  (NaN/inf) are checked eagerly when concrete and with `eqx.error_if` under `jit`.
- `__call__(model, data)` (pure, runs inside the solver): the real residual vector, one
  entry per measured value, already weighted. Complex errors are returned as real and
  imaginary parts.
- `is_unstable(model)` (optional): whether the initial guess cannot be used, e.g. an
  unstable linear model for a time-domain residual (default: never).

User callbacks follow optimistix: a function of `(model, data)`, data passed as an
argument rather than captured in a closure.
"""

import abc
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, PyTree

from .._misc import as_real, check_finite, concrete, expm
from ..data import Record
from ..models import AbstractLinearModel, AbstractModel, frequency_response, map_batch, simulate

__all__ = [
    "AbstractResidual",
    "EquationError",
    "ExcitationWarning",
    "FrequencyError",
    "Joint",
    "PredictionError",
    "SimulationError",
]


_METHODS = ("zoh", "tustin", "euler", "heun")


class ExcitationWarning(UserWarning):
    """The experiment's input does not excite the dynamics to be calibrated."""


# ----------------------------------------------------------------------------- helpers


def _check_finite(x: Array, name: str, where: str) -> Array:
    fix = (
        "Remove or interpolate the bad samples (e.g. Record.slice / np.interp), or select "
        "a clean frequency band (FRFData.select)."
    )
    return check_finite(x, f"{where}: data {name!r}", fix)


def _contains(data: Any, name: str) -> bool:
    """`name in data` for containers with named signals (Records, mappings)."""
    try:
        return name in data
    except TypeError:  # not a container
        return False


def _attributes(data: Any) -> set[str]:
    """Public data attributes of a container object (e.g. `FRFData.omega`)."""
    return {n for n in dir(data) if not n.startswith("_")}


def _has(data: Any, name: str) -> bool:
    if isinstance(data, Mapping):
        return name in data
    return _contains(data, name) or name in _attributes(data)


def _lookup(data: Any, name: str, where: str) -> Any:
    """`data[name]` for mappings and Records (signals), else the attribute `data.name`."""
    if isinstance(data, Mapping) and name in data or _contains(data, name):
        return data[name]
    if not isinstance(data, Mapping) and name in _attributes(data):
        return getattr(data, name)
    have = list(data.keys()) if isinstance(data, Mapping) else getattr(data, "names", None)
    raise ValueError(
        f"{where}: the data have no signal {name!r}"
        + (f" (they have {list(have)})" if have is not None else "")
        + ". Rename the signal, or tell the residual its name (e.g. "
        f"{where}(inputs='force', outputs='q'))."
    )


def _as_float_array(x: Any, name: str, where: str) -> Array:
    return as_real(x, f"{where}: signal {name!r}")


def _signals(data: Any, names: str | tuple[str, ...], where: str) -> Array:
    """One signal `(time,)` or several stacked as `(time, signal)`."""
    if isinstance(names, str):
        return _as_float_array(_lookup(data, names, where), names, where)
    cols = [_as_float_array(_lookup(data, n, where), n, where) for n in names]
    return jnp.stack(cols, axis=-1)


def _sample_time(data: Any, where: str) -> Any:
    """The sample time [s]: `data.dt`/`data["dt"]`, or from a uniform time vector `t`."""
    if _has(data, "dt"):
        dt = _lookup(data, "dt", where)
    elif _has(data, "t"):
        t = _lookup(data, "t", where)
        tc = concrete(t)
        if tc is None:
            raise ValueError(
                f"{where}: under jit/vmap give the sample time as data['dt'], not only 't'."
            )
        if tc.ndim != 1 or tc.shape[0] < 2:
            raise ValueError(f"{where}: time vector 't' must be 1-D with >= 2 samples.")
        steps = np.diff(tc)
        dt = float((tc[-1] - tc[0]) / (tc.shape[0] - 1))
        # heuristic: the same 1e-3·dt tolerance as jaxvs.data.Record's uniform-time check
        if not np.all(np.abs(steps - dt) <= 1e-3 * abs(dt)) or dt <= 0:
            raise ValueError(
                f"{where}: time vector 't' is not uniform and increasing; resample it "
                "first (jaxvs.signal) or give 'dt'."
            )
    else:
        raise ValueError(f"{where}: the data need a sample time 'dt' [s] (or a time vector 't').")
    dtc = concrete(dt)
    if dtc is not None:
        if dtc.shape != () or not np.isfinite(dtc) or dtc <= 0:
            raise ValueError(
                f"{where}: the sample time dt must be a positive finite scalar; got {dtc}."
            )
        return float(dtc)
    return dt


def _warn_if_constant(u: Array, names: str | tuple[str, ...], where: str) -> None:
    uc = concrete(u)
    if uc is None or uc.size == 0:
        return
    span = np.atleast_1d(np.ptp(uc, axis=0))
    scale = np.atleast_1d(np.maximum(np.max(np.abs(uc), axis=0), np.finfo(float).tiny))
    # heuristic: an input whose range is below 1e-12 of its size carries no information.
    flat = (span <= 1e-12 * scale).tolist()
    cols = [names] if isinstance(names, str) else list(names)
    constant = [c for c, f in zip(cols, flat) if f]
    if constant:
        warnings.warn(
            f"{where}: input {', '.join(map(repr, constant))} is constant. Apart from the "
            "start-up transient (a step, if the record starts at rest) it excites only the "
            "static gain, so time constants, frequencies and damping are poorly or not at "
            "all identifiable. Use an exciting input: a PRBS, swept sine or white noise "
            "(jaxvs.data.prbs / swept_sine / white_noise), or steps between levels.",
            ExcitationWarning,
            stacklevel=4,
        )


def _linear_unstable(model: AbstractLinearModel) -> Bool[Array, ""]:
    """Any pole in the open right half-plane, from the 2x2 blocks of the modal realisation:
    a real 2x2 block has an eigenvalue with positive real part iff its trace is > 0 or its
    determinant is < 0 (marginal poles -- integrators, undamped modes -- are accepted)."""
    a = map_batch(lambda m: m.modal_realisation().a, model)
    tr = a[..., 0, 0] + a[..., 1, 1]
    det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    return jnp.any((tr > 0) | (det < 0))


def _real_vector(r: Any) -> Float[Array, " residual"]:
    """Flatten any pytree of residual arrays to one real vector (complex -> re, im)."""
    parts = []
    for leaf in jax.tree_util.tree_leaves(r):
        leaf = jnp.asarray(leaf)
        if jnp.iscomplexobj(leaf):
            parts += [jnp.real(leaf).ravel(), jnp.imag(leaf).ravel()]
        else:
            parts.append(leaf.ravel())
    if not parts:
        raise ValueError("The residual function returned no arrays.")
    return jnp.concatenate(parts)


# ----------------------------------------------------------------------------- interface


class AbstractResidual(eqx.Module):
    """A residual: `prepare(data)` once, then `residual(model, data)` -> real vector."""

    def prepare(self, data: Any) -> PyTree[Array]:
        """Validate `data` and return it as a pytree of arrays (default: unchanged)."""
        return data

    @abc.abstractmethod
    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        """Real residual vector of `model` on the prepared `data`."""

    def is_unstable(self, model: Any) -> Bool[Array, ""]:
        """Whether `model` is an unusable (unstable) initial guess for this residual."""
        return jnp.asarray(False)


# ----------------------------------------------------------------------------- time domain


class _AbstractTimeResidual(AbstractResidual):
    """Shared preparation of input/output time series."""

    fn: eqx.AbstractVar[Callable | None]
    inputs: eqx.AbstractVar[str | tuple[str, ...]]
    outputs: eqx.AbstractVar[str | tuple[str, ...]]
    skip: eqx.AbstractVar[int]

    def prepare(self, data: Any) -> dict[str, Any]:
        where = type(self).__name__
        if isinstance(data, list | tuple):
            raise TypeError(
                f"{where}: got a {type(data).__name__} of data; pass several experiments to "
                "calibrate as a list, which pairs each with this residual."
            )
        u = _signals(data, self.inputs, where)
        y = _signals(data, self.outputs, where)
        dt = _sample_time(data, where)
        if u.ndim == 0 or y.ndim == 0 or u.shape[0] != y.shape[0]:
            raise ValueError(
                f"{where}: input {self.inputs!r} {u.shape} and output {self.outputs!r} "
                f"{y.shape} must have the same number of samples (time axis first)."
            )
        if not 0 <= self.skip < y.shape[0]:
            raise ValueError(
                f"{where}: skip={self.skip} leaves no samples of the {y.shape[0]} measured."
            )
        u = _check_finite(u, str(self.inputs), where)
        y = _check_finite(y, str(self.outputs), where)
        _warn_if_constant(u, self.inputs, where)
        prepared = {"u": u, "y": y, "dt": dt}
        if _has(data, "x0"):
            prepared["x0"] = jnp.asarray(_lookup(data, "x0", where))
        return prepared

    def is_unstable(self, model: Any) -> Bool[Array, ""]:
        if self.fn is None and isinstance(model, AbstractLinearModel):
            return _linear_unstable(model)
        return jnp.asarray(False)

    def _compare(self, y_hat: Array, y: Array, start: int) -> Array:
        if y_hat.shape != y.shape:
            raise ValueError(
                f"{type(self).__name__}: the model predicts shape {y_hat.shape} but the "
                f"measured output has shape {y.shape}; check the number of outputs, or "
                "reshape the prediction in your `fn`."
            )
        return (y_hat - y)[start:].ravel()


class SimulationError(_AbstractTimeResidual):
    r"""Output (simulation) error: simulate the model on the measured input from rest and
    compare with the measured output, `r_k = ŷ_k - y_k` for `k >= skip`.

    This is the output-error criterion of system identification (Ljung, *System
    Identification*, 2nd ed., 1999, §4.2, the output-error structure): unbiased under
    white output noise, but the residual is a nonlinear function of every dynamic
    parameter.

    **Arguments:**

    - `fn`: optional `fn(model, data) -> ŷ` giving the simulated output (`data` is the
      prepared dict with `"u"`, `"y"`, `"dt"`). Default: `jaxvs.simulate(model, u, dt,
      method=method)` for linear models, otherwise `model.predict(u, dt)` of any
      [`jaxvs.models.AbstractModel`][] (derive your module from it, e.g. a diffrax ODE
      solve).
    - `inputs`, `outputs`: signal name(s) in the data (default `"u"` and `"y"`); a tuple
      of names stacks them as `(time, signal)`.
    - `method`: discretisation of `jaxvs.simulate` (`"zoh"`, `"tustin"`, `"euler"`,
      `"heun"`).
    - `skip`: number of initial samples excluded, e.g. an unmodelled start-up transient.

    Data: a `jaxvs.data.Record` or a mapping with the signals, and the sample time `dt`
    [s] (or a uniform time vector `t`); optionally `x0` for `model.simulate`-style models.
    """

    fn: Callable | None
    inputs: str | tuple[str, ...] = eqx.field(static=True)
    outputs: str | tuple[str, ...] = eqx.field(static=True)
    skip: int = eqx.field(static=True)
    method: str = eqx.field(static=True)

    def __init__(
        self,
        fn: Callable | None = None,
        *,
        inputs: str | tuple[str, ...] = "u",
        outputs: str | tuple[str, ...] = "y",
        method: Literal["zoh", "tustin", "euler", "heun"] = "zoh",
        skip: int = 0,
    ):
        if method not in _METHODS:
            raise ValueError(
                f"SimulationError: unknown method {method!r}; choose one of {_METHODS}."
            )
        self.fn, self.inputs, self.outputs, self.skip = fn, inputs, outputs, int(skip)
        self.method = method

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        if self.fn is not None:
            y_hat = self.fn(model, data)
        elif isinstance(model, AbstractLinearModel):
            y_hat = simulate(model, data["u"], data["dt"], method=self.method)
        elif isinstance(model, AbstractModel):
            y_hat = model.predict(data["u"], data["dt"])
        else:
            raise TypeError(
                f"SimulationError: do not know how to simulate a {type(model).__name__}. "
                "Give fn=lambda model, data: ... (returning the simulated output), or "
                "derive the module from jaxvs.models.AbstractModel and implement "
                "predict(u, dt)."
            )
        return self._compare(jnp.asarray(y_hat), data["y"], self.skip)


def _faddeev_leverrier(a: Float[Array, "n n"]) -> Float[Array, " n1"]:
    """Characteristic polynomial `det(zI - A)` (highest power first, monic).

    Faddeev-LeVerrier recursion (Gantmacher, *The Theory of Matrices*, Vol. 1, ch. IV):
    `M_k = A M_{k-1} + c_{k-1} I`, `c_k = -tr(A M_k) / k`. Matrix products only, so it is
    differentiable everywhere (unlike eigenvalues at repeated roots). Used on discrete
    matrices with spectral radius <= 1, where it keeps its digits at the orders here.
    """
    n = a.shape[0]
    eye = jnp.eye(n, dtype=a.dtype)
    coeffs = [jnp.ones((), a.dtype)]
    m = jnp.zeros_like(a)
    for k in range(1, n + 1):
        m = a @ m + coeffs[-1] * eye
        coeffs.append(-jnp.trace(a @ m) / k)
    return jnp.stack(coeffs)


def _arx_form(model: AbstractLinearModel, dt: Any) -> tuple[Array, Array]:
    """`(a, b)` of the ZOH-discretised SISO model `B(q⁻¹)/A(q⁻¹)`, `a_0 = 1`.

    ZOH: `exp([[A, B], [0, 0]] dt) = [[A_d, B_d], [0, I]]` (Van Loan, "Computing
    integrals involving the matrix exponential", IEEE Trans. Autom. Control 23, 1978).
    `A(z)` is the characteristic polynomial of `A_d`; `B` follows from the Markov
    parameters `h_0 = D`, `h_k = C A_d^{k-1} B_d` through `B(q⁻¹) = A(q⁻¹) H(q⁻¹)`
    truncated at degree `n`.
    """
    ss = model.to_state_space()
    A, B, C, D = ss.A, ss.B, ss.C, ss.D
    n = A.shape[0]
    aug = jnp.zeros((n + 1, n + 1), A.dtype).at[:n, :n].set(A).at[:n, n:].set(B)
    e = expm(aug * dt)
    ad, bd = e[:n, :n], e[:n, n:]
    a = _faddeev_leverrier(ad)
    h = [D[0, 0]]
    x = bd
    for _ in range(n):
        h.append((C @ x)[0, 0])
        x = ad @ x
    h = jnp.stack(h)
    b = jnp.stack([jnp.sum(a[: j + 1] * h[j::-1]) for j in range(n + 1)])
    return a, b


class PredictionError(_AbstractTimeResidual):
    r"""One-step-ahead prediction error, `r_k = ŷ(k | k-1) - y_k`.

    **What "one step" means for a continuous-time model.** A linear model is first
    discretised exactly for piecewise-constant inputs (zero-order hold at the data's `dt`),
    `y_k = B(q⁻¹)/A(q⁻¹) u_k`, `A(q⁻¹) = 1 + a_1 q⁻¹ + ... + a_n q⁻ⁿ`. The one-step-ahead
    predictor is then that of the ARX (equation-error) noise structure, which uses the
    *measured* past outputs (Ljung 1999, §4.2, the ARX predictor `ŷ = B u + (1 - A) y`):

        ŷ(k | k-1) = -a_1 y_{k-1} - ... - a_n y_{k-n} + b_0 u_k + ... + b_n u_{k-n}.

    The residual starts at `k = max(skip, n)` so that every prediction has its `n` past
    samples. It is cheap and nearly convex, but biased under output noise -- use
    [`SimulationError`][] for the final estimate and this one for initialisation or for
    models that are themselves predictors (NARX / time-delay networks).

    **Arguments:**

    - `fn`: optional `fn(model, data) -> ŷ` (same shape as `y`, `ŷ_k` a prediction from
      data before `k`). Default: the discretised ARX predictor above for SISO linear
      models; other models give `fn`.
    - `inputs`, `outputs`, `skip`: as for [`SimulationError`][].
    """

    fn: Callable | None
    inputs: str | tuple[str, ...] = eqx.field(static=True)
    outputs: str | tuple[str, ...] = eqx.field(static=True)
    skip: int = eqx.field(static=True)

    def __init__(
        self,
        fn: Callable | None = None,
        *,
        inputs: str | tuple[str, ...] = "u",
        outputs: str | tuple[str, ...] = "y",
        skip: int = 0,
    ):
        self.fn, self.inputs, self.outputs, self.skip = fn, inputs, outputs, int(skip)

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        u, y = data["u"], data["y"]
        start = self.skip
        if self.fn is not None:
            y_hat = self.fn(model, data)
        elif isinstance(model, AbstractLinearModel):
            if not model.is_siso or u.ndim != 1 or y.ndim != 1:
                raise ValueError(
                    "PredictionError: the built-in predictor is for SISO linear models "
                    "with 1-D u and y; give fn=... for other models."
                )
            a, b = _arx_form(model, data["dt"])
            n = a.shape[0] - 1
            if y.shape[0] <= n + self.skip:
                raise ValueError(
                    f"PredictionError: {y.shape[0]} samples are too few for a predictor of "
                    f"order {n} (it needs {n} past samples); record more data."
                )
            # ŷ_k = Σ_j b_j u_{k-j} - Σ_{i>=1} a_i y_{k-i}, zero before the record (k < n is
            # then excluded from the residual).
            t = y.shape[0]
            conv_b = jnp.convolve(u, b)[:t]
            conv_a = jnp.convolve(y, a)[:t] - y  # Σ_{i>=1} a_i y_{k-i}
            y_hat = conv_b - conv_a
            start = max(self.skip, n)
        else:
            raise TypeError(
                f"PredictionError: {type(model).__name__} has no built-in one-step predictor "
                "(only linear models have); give fn=lambda model, data: ... returning the "
                "one-step-ahead prediction of data['y']."
            )
        return self._compare(jnp.asarray(y_hat), y, start)


# ----------------------------------------------------------------------------- frequency


class FrequencyError(AbstractResidual):
    r"""Complex frequency-response error `w(ω) (G(jω) - H(ω))`, as real and imaginary parts.

    **Arguments:**

    - `fn`: optional `fn(model, data) -> G` (complex, shaped like `H`; `data["omega"]`
      [rad/s]). Default: `jaxvs.frequency_response(model, omega)` for linear models,
      otherwise `model.frequency_response(omega)`.
    - `weighting`:
        - `None` (default): `w = 1` (absolute error, dominated by resonance peaks);
        - `"relative"`: `w = 1/|H|` (relative error, every decade counts);
        - `"coherence"`: `w = sqrt(γ² / (1 - γ²)) / |H|`, i.e. one over the standard
          deviation of an H1 estimate up to a constant (Bendat & Piersol, *Random Data*,
          4th ed., 2010, ch. 9: `σ(|H|)/|H| ≈ sqrt((1 - γ²) / (2 n γ²))`); needs the
          data's coherence. γ² is clipped to `1 - 1e-6` (heuristic: a perfect coherence
          would give an infinite weight).

    Data: a `jaxvs.data.FRFData`, or a mapping with `"omega"` [rad/s] (or `"frequency"`
    [Hz]) and complex `"H"` `(freq,)` / `(freq, out, in)`; optionally `"coherence"` and
    `"weights"` (real, shaped like `H`, multiplied into `w`).
    """

    fn: Callable | None = None
    weighting: Literal["relative", "coherence"] | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if self.weighting not in (None, "relative", "coherence"):
            raise ValueError(
                f"FrequencyError: weighting must be None, 'relative' or 'coherence'; got "
                f"{self.weighting!r}."
            )

    def prepare(self, data: Any) -> dict[str, Array]:
        where = "FrequencyError"
        if isinstance(data, list | tuple):
            raise TypeError(
                f"{where}: got a {type(data).__name__}; give an FRFData or a mapping with "
                "'omega' and 'H'. Several experiments go to calibrate as a list."
            )
        if _has(data, "omega"):
            omega = _as_float_array(_lookup(data, "omega", where), "omega", where)
        elif _has(data, "frequency"):
            omega = (
                2 * jnp.pi * _as_float_array(_lookup(data, "frequency", where), "frequency", where)
            )
        else:
            raise ValueError(f"{where}: the data need 'omega' [rad/s] or 'frequency' [Hz].")
        H = jnp.asarray(_lookup(data, "H", where))
        if not jnp.iscomplexobj(H):
            H = H.astype(jnp.result_type(H.dtype, jnp.complex64, float))
        if omega.ndim != 1 or H.ndim not in (1, 3) or H.shape[0] != omega.shape[0]:
            raise ValueError(
                f"{where}: omega {omega.shape} and H {H.shape} do not match; expected omega "
                "(freq,) and H (freq,) or (freq, out, in). Calibrate families with "
                "calibrate_family."
            )
        omega = _check_finite(omega, "omega", where)
        H = _check_finite(H, "H", where)
        w = jnp.ones(H.shape, omega.dtype)
        if self.weighting is not None:
            mag = jnp.abs(H)
            magc = concrete(mag)
            if magc is not None and np.any(magc == 0):
                raise ValueError(
                    f"{where}: weighting={self.weighting!r} divides by |H|, which is 0 at "
                    "some frequencies; drop those frequencies or use weighting=None."
                )
            w = w / mag
        if self.weighting == "coherence":
            coh = _lookup(data, "coherence", where) if _has(data, "coherence") else None
            if coh is None:
                raise ValueError(
                    f"{where}: weighting='coherence' needs the data's coherence; estimate "
                    "the FRF with jaxvs.signal (which returns it) or choose another weighting."
                )
            coh = jnp.clip(jnp.asarray(coh, omega.dtype), 0.0, 1.0 - 1e-6)
            if coh.shape != H.shape:
                raise ValueError(f"{where}: coherence {coh.shape} must have H's shape {H.shape}.")
            w = w * jnp.sqrt(coh / (1 - coh))
        if _has(data, "weights"):
            uw = _as_float_array(_lookup(data, "weights", where), "weights", where)
            if uw.shape != H.shape:
                raise ValueError(f"{where}: weights {uw.shape} must have H's shape {H.shape}.")
            w = w * _check_finite(uw, "weights", where)
        return {"omega": omega, "H": H, "w": w}

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        omega, H = data["omega"], data["H"]
        if self.fn is not None:
            G = self.fn(model, data)
        elif isinstance(model, AbstractLinearModel):
            G = frequency_response(model, omega)
        else:
            raise TypeError(
                f"FrequencyError: {type(model).__name__} is not a jaxvs linear model; give "
                "fn=lambda model, data: ... returning its complex response at data['omega']."
            )
        G = jnp.asarray(G)
        if G.shape != H.shape:
            raise ValueError(
                f"FrequencyError: the model's response has shape {G.shape} but the data H "
                f"has {H.shape}; match the model's inputs/outputs to the measured FRF."
            )
        e = data["w"] * (G - H)
        return jnp.concatenate([jnp.real(e).ravel(), jnp.imag(e).ravel()])


# ----------------------------------------------------------------------------- user / joint


class EquationError(AbstractResidual):
    r"""Equation error from a user function: `r = fn(model, data)` (any pytree of real or
    complex arrays, flattened; complex as real and imaginary parts).

    The natural residual of inverse-dynamics identification, e.g. the rigid axis
    `r = M q̈ + Fv q̇ + Fc sign(q̇) + offset - u` evaluated on filtered measured signals
    (Gautier & Khalil's IDIM-LS, as in the EMPS benchmark), which is linear in the
    parameters and needs no simulation; or any curve fit `r = f(t; θ) - y`.

    **Arguments:**

    - `fn`: `fn(model, data) -> residuals`; `data` is passed through `prepare` unchanged
      except that its arrays are checked for NaN/inf.
    """

    fn: Callable

    def prepare(self, data: Any) -> PyTree:
        def check(path, x):
            if eqx.is_array_like(x) and not isinstance(x, bool | int | str):
                arr = jnp.asarray(x)
                if jnp.issubdtype(arr.dtype, jnp.inexact):
                    return _check_finite(arr, jax.tree_util.keystr(path) or "data", "EquationError")
            return x

        if isinstance(data, Record):
            data = {"t": data.t, "dt": data.dt, **{n: data[n] for n in data.names}}
        return jax.tree_util.tree_map_with_path(check, data)

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        return _real_vector(self.fn(model, data))


class Joint(AbstractResidual):
    r"""Several residuals of the same model stacked into one problem, each weighted:
    `r = [w_1 r_1(model, data_1), ..., w_m r_m(model, data_m)]`.

    Use it for several experiments (one residual each) or several domains of the same
    parameters (time and frequency). With weights `w_i = 1/σ_i` (the noise level of each
    block) the stacked residual is homoscedastic and the covariance of `calibrate` is
    the maximum-likelihood one.

    **Arguments:**

    - `residuals`: a sequence of residuals; the data are then a list of the same length.
    - `weights`: `None` (all 1), a sequence of scalars or arrays (broadcast against each
      block's residual vector), or `"size"`: `w_i = 1/sqrt(N_i)` so that each block
      counts by its mean square, whatever its number of samples `N_i`.
    """

    residuals: tuple[AbstractResidual, ...]
    weights: Any

    def __init__(self, residuals: Sequence[AbstractResidual], weights: Any = None):
        residuals = tuple(residuals)
        if not residuals or not all(isinstance(r, AbstractResidual) for r in residuals):
            raise TypeError(
                "Joint: give a non-empty sequence of residuals (SimulationError, "
                "FrequencyError, EquationError, ...)."
            )
        if weights is not None and not isinstance(weights, str):
            weights = tuple(weights)
            if len(weights) != len(residuals):
                raise ValueError(
                    f"Joint: {len(weights)} weights for {len(residuals)} residuals; give one "
                    "weight per residual."
                )
            weights = tuple(jnp.asarray(w) for w in weights)
        elif isinstance(weights, str) and weights != "size":
            raise ValueError(f"Joint: weights must be None, a sequence or 'size'; got {weights!r}.")
        self.residuals, self.weights = residuals, weights

    def prepare(self, data: Any) -> tuple:
        if not isinstance(data, list | tuple) or len(data) != len(self.residuals):
            n = len(data) if isinstance(data, list | tuple) else "one"
            raise ValueError(
                f"Joint: {len(self.residuals)} residuals need a list of "
                f"{len(self.residuals)} data objects (one per residual); got {n}."
            )
        return tuple(r.prepare(d) for r, d in zip(self.residuals, data))

    def is_unstable(self, model: Any) -> Bool[Array, ""]:
        return jnp.any(jnp.stack([r.is_unstable(model) for r in self.residuals]))

    def __call__(self, model: Any, data: PyTree) -> Float[Array, " residual"]:
        blocks = []
        for i, (res, d) in enumerate(zip(self.residuals, data)):
            r = res(model, d)
            if self.weights == "size":
                r = r / jnp.sqrt(r.shape[0])
            elif self.weights is not None:
                w = self.weights[i]
                if w.ndim > 0 and w.shape != r.shape:
                    raise ValueError(
                        f"Joint: weight {i} has shape {w.shape} but residual {i} has "
                        f"{r.shape}; give a scalar or one weight per residual entry."
                    )
                r = r * w
            blocks.append(r)
        return jnp.concatenate(blocks)
