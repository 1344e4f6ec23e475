"""Conversions between jaxvs linear models and `scipy.signal` / python-control systems.

Users arrive with systems built in `scipy.signal` (`lti`, `TransferFunction`,
`StateSpace`, `ZerosPolesGain`) or python-control (`TransferFunction`, `StateSpace`,
`FrequencyResponseData`) and leave with calibrated jaxvs models they want to analyse
there. These functions translate in both directions on the host (numpy in, numpy out);
they are not traced by `jax.jit`. A family (a model with leading batch axes) converts to
a (nested) list of systems, one per member.

python-control is imported lazily, so jaxvs does not depend on it at run time.
"""

from __future__ import annotations

import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...data import FRFData
from .._base import AbstractLinearModel
from ._convert import to_rational
from ._rational import RationalTF
from ._statespace import StateSpace

__all__ = ["from_control", "from_scipy", "to_control", "to_scipy"]

_SCIPY_FORMS = ("auto", "tf", "ss", "zpk")
_CONTROL_FORMS = ("auto", "tf", "ss")


def _concrete(model: Any, who: str) -> None:
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model)):
        raise TypeError(
            f"{who}: conversions to other libraries run on concrete values; call it outside "
            "jax.jit / jax.vmap / jax.grad."
        )


def _members(model: Any) -> list:
    """A batched model (or FRFData) as a nested list of unbatched members."""
    shape = model.batch_shape
    if shape == ():
        return model

    def index(tree, i):
        return jax.tree_util.tree_map(lambda x: x[i], tree)

    def rec(tree, dims):
        if not dims:
            return tree
        return [rec(index(tree, i), dims[1:]) for i in range(dims[0])]

    if isinstance(model, FRFData):
        # the frequency grid is shared by the family; index H (and coherence) only
        def rec_frf(H, C, dims):
            if not dims:
                # the member keeps the family's grid, labels and metadata
                member = eqx.tree_at(lambda d: d.H, model, H)
                return member if C is None else eqx.tree_at(lambda d: d.coherence, member, C)
            return [rec_frf(H[i], None if C is None else C[i], dims[1:]) for i in range(dims[0])]

        return rec_frf(model.H, model.coherence, shape)
    return rec(model, shape)


def _map_members(fn, model: Any) -> Any:
    members = _members(model)

    def rec(x):
        return [rec(m) for m in x] if isinstance(x, list) else fn(x)

    return rec(members)


def _check_model(model: Any, who: str) -> None:
    if not isinstance(model, AbstractLinearModel):
        raise TypeError(
            f"{who}: expected a jaxvs linear model (RationalTF, ModalModel, StateSpace, ...); "
            f"got {type(model).__name__}. For a GridFamily or SmoothFamily convert "
            "family.at(positions)."
        )
    _concrete(model, who)


def _np(x: Any) -> np.ndarray:
    return np.asarray(x)


def _strip(c: np.ndarray) -> np.ndarray:
    """Leading zero coefficients removed (keeps at least one)."""
    nz = np.flatnonzero(c != 0)
    return c[nz[0] :] if nz.size else c[-1:]


def _tf_coefficients(model: AbstractLinearModel, who: str) -> tuple[np.ndarray, np.ndarray]:
    if not model.is_siso:
        raise ValueError(
            f"{who}: a transfer function (form='tf'/'zpk') needs a SISO model; this one has "
            f"{model.n_outputs} outputs and {model.n_inputs} inputs. Use form='ss'."
        )
    if isinstance(model, RationalTF):
        return _strip(_np(model.num)), _np(model.den)
    tf = to_rational(model)
    num, den = _np(tf.num), _np(tf.den)
    # heuristic: a strictly proper model's leading numerator coefficients come out of
    # to_rational as rounding noise; drop those below 64 eps of the largest coefficient
    # in scaled frequency s / w0 (w0 = |a_n / a_0|^(1/n)), as scipy would (with a warning).
    n = den.shape[0] - 1
    w0 = abs(den[-1] / den[0]) ** (1.0 / n) if den[-1] != 0 else 1.0
    scaled = np.abs(num) * w0 ** np.arange(n, -1, -1, dtype=float)
    noise = scaled <= 64 * np.finfo(num.dtype).eps * scaled.max()
    lead = int(np.argmin(noise)) if not noise.all() else n
    return num[lead:], den


@eqx.filter_jit
def _to_state_space(model: AbstractLinearModel) -> StateSpace:
    return model.to_state_space()


def _ss_matrices(model: AbstractLinearModel) -> tuple[np.ndarray, ...]:
    ss = model if isinstance(model, StateSpace) else _to_state_space(model)
    return tuple(_np(x) for x in (ss.A, ss.B, ss.C, ss.D))


# ---------------------------------------------------------------------------------------
# scipy.signal
# ---------------------------------------------------------------------------------------


def _to_scipy_one(model: AbstractLinearModel, form: str) -> Any:
    import scipy.signal as sig

    if form == "auto":
        form = "tf" if isinstance(model, RationalTF) else "ss"
    if form == "ss":
        return sig.StateSpace(*_ss_matrices(model))
    num, den = _tf_coefficients(model, "to_scipy")
    if form == "tf":
        return sig.TransferFunction(num, den)
    z, p, k = sig.tf2zpk(num, den)
    return sig.ZerosPolesGain(z, p, k)


def to_scipy(model: AbstractLinearModel, *, form: str = "auto") -> Any:
    """A jaxvs linear model as a continuous-time `scipy.signal` system.

    **Arguments:**

    - `model`: a jaxvs linear model (`RationalTF`, `ModalModel`, `StateSpace`, ...).
      A family (leading batch axes) gives a list (nested for several batch axes) with one
      system per member.
    - `form`: `"tf"` (`scipy.signal.TransferFunction`), `"zpk"` (`ZerosPolesGain`),
      `"ss"` (`StateSpace`, the model's real block-modal realisation unless it is a
      `StateSpace` already) or `"auto"`: `"tf"` for a `RationalTF`, `"ss"` otherwise.
      `"tf"` and `"zpk"` need a SISO model.

    **Returns:**

    A `scipy.signal.lti` subclass instance (time unit: seconds, frequencies in rad/s), or a
    list of them for a family.

    **Example:**

    ```python
    sys = jaxvs.to_scipy(jaxvs.RationalTF([1.0], [1.0, 2.0, 100.0]))
    w, mag, phase = sys.bode()
    ```
    """
    if form not in _SCIPY_FORMS:
        raise ValueError(f"to_scipy: form must be one of {_SCIPY_FORMS}; got {form!r}.")
    _check_model(model, "to_scipy")
    return _map_members(functools.partial(_to_scipy_one, form=form), model)


def from_scipy(system: Any) -> AbstractLinearModel:
    """A continuous-time `scipy.signal` system as a jaxvs linear model.

    - `TransferFunction` (SISO) and `ZerosPolesGain` → [`RationalTF`][jaxvs.models.RationalTF]
      (coefficients highest power first, as in scipy); a single-input multi-output
      `TransferFunction` → [`StateSpace`][jaxvs.models.StateSpace].
    - `StateSpace` → [`StateSpace`][jaxvs.models.StateSpace] with the same `A, B, C, D`.
    - a plain `lti(...)` call returns one of the above and converts the same way.

    **Arguments:**

    - `system`: a continuous-time `scipy.signal.lti` instance (or a list of them, which
      gives a list of models).

    **Returns:**

    A jaxvs linear model (arrays in the default floating dtype).

    **Raises:**

    `TypeError` for a discrete-time system (`dlti`) or another object; `ValueError` for an
    improper transfer function (more zeros than poles) or complex coefficients.
    """
    import scipy.signal as sig

    if isinstance(system, list):
        return [from_scipy(s) for s in system]  # type: ignore[return-value]
    if isinstance(system, sig.dlti):
        raise TypeError(
            "from_scipy: jaxvs models are continuous-time; got a discrete-time system "
            f"(dt = {getattr(system, 'dt', None)}). Convert it to continuous time first, e.g. "
            "with a Tustin inverse, or identify a continuous model from its data."
        )
    if not isinstance(system, sig.lti):
        raise TypeError(
            "from_scipy: expected a scipy.signal TransferFunction, ZerosPolesGain, StateSpace "
            f"or lti; got {type(system).__name__}. For python-control use from_control."
        )
    if isinstance(system, sig.StateSpace):
        return StateSpace(system.A, system.B, system.C, system.D)
    if isinstance(system, sig.ZerosPolesGain):
        num, den = sig.zpk2tf(system.zeros, system.poles, system.gain)
        if np.iscomplexobj(num) or np.iscomplexobj(den):
            if (
                np.max(np.abs(np.imag(num)), initial=0.0) > 0
                or np.max(np.abs(np.imag(den)), initial=0.0) > 0
            ):
                raise ValueError(
                    "from_scipy: the zeros/poles are not closed under complex conjugation, so "
                    "the transfer function has complex coefficients; jaxvs models are real."
                )
            num, den = np.real(num), np.real(den)
        return _rational(np.atleast_1d(num), np.atleast_1d(den), "from_scipy")
    # TransferFunction
    num = np.atleast_2d(np.asarray(system.num))
    den = np.asarray(system.den)
    if num.shape[0] == 1:
        return _rational(num[0], den, "from_scipy")
    return from_scipy(system.to_ss())


def _rational(num: np.ndarray, den: np.ndarray, who: str) -> RationalTF:
    num, den = np.atleast_1d(np.asarray(num)), _strip(np.atleast_1d(np.asarray(den)))
    if len(_strip(num)) > len(den):
        raise ValueError(
            f"{who}: improper transfer function (numerator order {len(_strip(num)) - 1} > "
            f"denominator order {len(den) - 1}); jaxvs models are proper."
        )
    if len(num) > len(den):
        num = num[len(num) - len(den) :]
    if len(den) < 2:
        raise ValueError(
            f"{who}: a static gain (denominator of order 0) has no dynamics; jaxvs models "
            "have at least one pole. Multiply the signal by the gain instead."
        )
    return RationalTF(jnp.asarray(num), jnp.asarray(den))


# ---------------------------------------------------------------------------------------
# python-control
# ---------------------------------------------------------------------------------------


def _import_control(who: str):
    try:
        import control
    except ImportError as e:  # pragma: no cover - control is in the dev extra
        raise ImportError(
            f"{who} needs python-control: pip install 'control>=0.10.1' (it is in jaxvs's "
            "dev extra: pip install 'jaxvs[dev]')."
        ) from e
    return control


def _frf_to_control(frf: FRFData, control) -> Any:
    omega = 2 * np.pi * _np(frf.frequency)
    H = _np(frf.H)
    if frf.io_shape:
        response = np.moveaxis(H, 0, -1)  # (out, in, freq)
    else:
        response = H
    return control.FrequencyResponseData(response, omega)


def _to_control_one(model: Any, form: str, control) -> Any:
    if isinstance(model, FRFData):
        return _frf_to_control(model, control)
    if form == "auto":
        form = "tf" if isinstance(model, RationalTF) else "ss"
    if form == "ss":
        return control.StateSpace(*_ss_matrices(model))
    num, den = _tf_coefficients(model, "to_control")
    return control.TransferFunction(num, den)


def to_control(model: AbstractLinearModel | FRFData, *, form: str = "auto") -> Any:
    """A jaxvs linear model or FRF as a python-control system.

    **Arguments:**

    - `model`: a jaxvs linear model, or an [`FRFData`][jaxvs.data.FRFData] (a measured or
      estimated FRF). A family (leading batch axes) gives a (nested) list, one per member.
    - `form`: for models, `"tf"` (`control.TransferFunction`, SISO only), `"ss"`
      (`control.StateSpace`, the block-modal realisation unless the model is a
      `StateSpace`) or `"auto"` (`"tf"` for a `RationalTF`, `"ss"` otherwise). Ignored
      for FRF data, which always become `control.FrequencyResponseData`.

    **Returns:**

    A python-control `TransferFunction`, `StateSpace` or `FrequencyResponseData` (its
    `omega` in rad/s = 2π × `FRFData.frequency` [Hz]; response shape `(out, in, freq)`
    for a MIMO FRF), or a list of them.

    **Example:**

    ```python
    import control
    sys = jaxvs.to_control(jaxvs.RationalTF([1.0], [1.0, 2.0, 100.0]))
    control.bode_plot(sys)
    back = jaxvs.from_control(sys)        # RationalTF again
    ```

    **Raises:**

    `ImportError` with an install hint when python-control is missing.
    """
    control = _import_control("to_control")
    if form not in _CONTROL_FORMS:
        raise ValueError(f"to_control: form must be one of {_CONTROL_FORMS}; got {form!r}.")
    if isinstance(model, FRFData):
        _concrete(model, "to_control")
    else:
        _check_model(model, "to_control")
    return _map_members(functools.partial(_to_control_one, form=form, control=control), model)


def from_control(
    system: Any,
    *,
    kind: str = "frf",
    input_unit: str = "",
    output_unit: str = "",
) -> AbstractLinearModel | FRFData:
    """A python-control system as a jaxvs model, or its FRD as [`FRFData`][jaxvs.data.FRFData].

    - `control.TransferFunction` (SISO) → [`RationalTF`][jaxvs.models.RationalTF]; a MIMO
      transfer function → [`StateSpace`][jaxvs.models.StateSpace] through `control.ss` (which
      needs slycot for MIMO systems).
    - `control.StateSpace` → [`StateSpace`][jaxvs.models.StateSpace] with the same matrices.
    - `control.FrequencyResponseData` → `FRFData` on the frequencies `omega / 2π` [Hz],
      SISO `H (freq,)` or MIMO `H (freq, out, in)`.

    **Arguments:**

    - `system`: a continuous-time python-control system (or a list of them).
    - `kind`, `input_unit`, `output_unit`: stored on the `FRFData` made from an FRD (see
      `FRFData`); python-control does not carry them.

    **Returns:**

    A jaxvs linear model or an `FRFData`.

    **Raises:**

    `TypeError` for a discrete-time system or an unknown object; `ValueError` for an FRD
    with negative or unsorted frequencies.
    """
    control = _import_control("from_control")
    if isinstance(system, list):
        return [  # type: ignore[return-value]
            from_control(s, kind=kind, input_unit=input_unit, output_unit=output_unit)
            for s in system
        ]
    if isinstance(system, control.FrequencyResponseData):
        omega = np.asarray(system.omega, dtype=float)
        # (out, in, freq); `fresp` is deprecated in favour of `frdata` in control >= 0.10.1
        frdata = getattr(system, "frdata", None)
        response = np.asarray(system.fresp if frdata is None else frdata)
        response = response.reshape(system.noutputs, system.ninputs, omega.shape[0])
        f = omega / (2 * np.pi)
        if response.shape[0] == 1 and response.shape[1] == 1:
            H = response[0, 0]
        else:
            H = np.moveaxis(response, -1, 0)
        return FRFData(
            jnp.asarray(f),
            jnp.asarray(H),
            kind=kind,
            input_unit=input_unit,
            output_unit=output_unit,
            io_shape=() if H.ndim == 1 else tuple(H.shape[1:]),
        )
    if not isinstance(system, control.InputOutputSystem) or "dt" not in dir(system):
        raise TypeError(
            "from_control: expected a python-control TransferFunction, StateSpace or "
            f"FrequencyResponseData; got {type(system).__name__}. For scipy use from_scipy."
        )
    if system.dt not in (0, None):
        raise TypeError(
            "from_control: jaxvs models are continuous-time; got a discrete-time system "
            f"(dt = {system.dt}). Use control.d2c-style conversion (e.g. sample_system's "
            "inverse) first, or identify a continuous model."
        )
    if isinstance(system, control.StateSpace):
        return StateSpace(system.A, system.B, system.C, system.D)
    if isinstance(system, control.TransferFunction):
        if system.ninputs == 1 and system.noutputs == 1:
            num, den = np.asarray(system.num[0][0]), np.asarray(system.den[0][0])
            return _rational(num, den, "from_control")
        try:
            ss = control.ss(system)
        except Exception as e:
            raise ValueError(
                "from_control: converting a MIMO TransferFunction to state space failed in "
                f"python-control ({type(e).__name__}: {e}); install slycot, or convert each "
                "channel system[i, j] separately."
            ) from e
        return StateSpace(ss.A, ss.B, ss.C, ss.D)
    raise TypeError(
        f"from_control: cannot convert a {type(system).__name__}; give a TransferFunction, "
        "StateSpace or FrequencyResponseData."
    )
