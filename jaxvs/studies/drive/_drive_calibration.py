r"""Simulation-based closed-loop calibration of a drive with its known controller.

A position-controlled axis cannot be identified in open loop (it has a pure integrator);
the data come from the closed loop, where the controller is known (gains in the
controller's parameter file, as in the EMPS `.mat` files). The model to calibrate is then
the whole closed loop -- a `jaxvs.models.DriveAxis` -- of which only the plant parameters
(mass, friction, stiffness, ...) are free, and it is simulated from the measured
reference (Gautier, Janot, Vandanjon, "A new closed-loop output error method for
parameter identification of robot dynamics", IEEE Trans. Control Syst. Technol. 21(2),
2013; Janot, Gautier, Brunot 2019, §4.1):

- **output error** (`criterion="output"`): `r = q_sim − q_meas`, the simulated and the
  measured position. Because the controller rejects the plant's dynamics, the position
  is only weakly sensitive to the parameters (the EMPS' simulated position is within
  0.01 % of the measured one whatever the friction);
- **input error** (`criterion="input"`, the default; the DIDIM method of Gautier et al.
  2013): `r = f_sim − f_meas`, the simulated and the measured drive force (the control
  input), which the controller makes carry the plant's dynamics.

Both go through `jaxvs.calibrate` (Levenberg–Marquardt, forward-mode Jacobians through
the simulation), so estimates come with covariance and confidence intervals.
"""

import dataclasses
import warnings
from typing import Any, Literal

import jax.numpy as jnp
import numpy as np

from ..._misc import options_object
from ...calibration import (
    CalibrateOptions,
    CalibrationResult,
    EquationError,
    ExcitationWarning,
    calibrate,
)
from ...data import Record
from ...models import DriveAxis

__all__ = ["DriveSignals", "calibrate_drive", "drive_residual"]

_CRITERIA = ("input", "output")


def _check_motion(q: np.ndarray, dt: float, min_speed: float) -> None:
    v = np.gradient(q, dt)
    n_pos = int(np.count_nonzero(v > min_speed))
    n_neg = int(np.count_nonzero(v < -min_speed))
    # heuristic: 1 % of the record moving each way (as idim_ls): with less, sign(v) is
    # nearly constant and the Coulomb force is collinear with a constant offset.
    needed = max(int(0.01 * q.shape[0]), 1)
    if n_pos < needed or n_neg < needed:
        warnings.warn(
            f"calibrate_drive: friction is not identifiable from this record: only {n_pos} "
            f"samples move in + direction and {n_neg} in − direction faster than "
            f"{min_speed:g} m/s (need >= {needed} each). Coulomb and viscous friction "
            "cannot be told apart from an offset or from the mass; move the axis back and "
            "forth (jaxvs.data.bang_bang / trapezoid), or fix the friction parameters with "
            "free=...",
            ExcitationWarning,
            stacklevel=3,
        )


def drive_residual(
    criterion: Literal["input", "output"] = "input", *, dt: float
) -> EquationError:
    """The residual of [`calibrate_drive`][] as a `jaxvs.calibration.EquationError`, to
    combine several experiments or criteria in `jaxvs.calibrate` yourself.

    Data: a mapping with `"r"` (reference [m]), `"q"` (position [m]), `"u"` (force [N]),
    `"q0"` (initial position [m]) and `"offset"` (command offset, same length as `r`).

    **Arguments:**

    - `criterion`: `"input"` (simulated − measured force [N]) or `"output"` (simulated −
      measured position [m]).
    - `dt`: sample time [s] of the data (a Python float: it fixes the simulation grid).
    """
    dt = float(dt)
    if criterion not in _CRITERIA:
        raise ValueError(
            f"drive_residual: criterion must be one of {_CRITERIA}; got {criterion!r}."
        )

    def fn(drive: DriveAxis, data: dict) -> Any:
        sim = drive.simulate(
            data["r"], dt, command_offset=data["offset"], q0=data["q0"], check=False
        )
        if criterion == "input":
            return sim.force - data["u"]
        return sim.position - data["q"]

    return EquationError(fn)


@dataclasses.dataclass(frozen=True)
class DriveSignals:
    """The signals of a drive record that [`calibrate_drive`][] uses: the `reference`,
    `position` and `force` names, and an optional `command_offset` added to the controller
    output (a signal name or an array)."""

    reference: str = "r"
    position: str = "q"
    force: str = "u"
    command_offset: str | np.ndarray | None = None


def calibrate_drive(
    drive: DriveAxis,
    record: Record,
    *,
    criterion: Literal["input", "output"] = "input",
    free: Any = None,
    signals: DriveSignals | None = None,
    min_speed: float = 1e-4,
    solver: Any = None,
    **options: Any,
) -> CalibrationResult:
    r"""Calibrate the plant of a closed-loop drive from one experiment, the controller known.

    The drive is simulated from the measured reference with its controller (gains,
    sampling, velocity filter, saturation as given) and the free parameters are fitted by
    Levenberg–Marquardt to the measured force (input error) or position (output error).
    See the module docstring for the two criteria.

    **Arguments:**

    - `drive`: the initial guess, a `jaxvs.models.DriveAxis` (e.g. from IDIM-LS estimates).
    - `record`: a `jaxvs.data.Record` with reference, position and force (e.g.
      `jaxvs.data.load_emps(...)`).
    - `criterion`: `"input"` (default) or `"output"`.
    - `free`: which parameters are calibrated (as for `jaxvs.calibrate`); default all
      parameters of the mechanics (mass, friction, stiffness, backlash), the controller
      and actuator fixed.
    - `signals`: which signals of `record` to use, a [`DriveSignals`][], or its fields as
      keywords: `reference`, `position`, `force` (signal names in `record`) and
      `command_offset` (optional signal added to the controller output: a name in the
      record or an array; e.g. the EMPS validation pulses in V).
    - `min_speed`: speed [m/s] above which a sample counts as moving (identifiability
      check of friction).
    - `solver`: passed to `jaxvs.calibrate`.
    - `**options`: besides the `signals` fields, the options of `jaxvs.calibrate`
      (`max_steps`, default 100 here; `throw`, `rtol`, `atol`, `covariance`,
      `confidence`).

    **Returns:**

    A `jaxvs.calibration.CalibrationResult` whose `.model` is the calibrated `DriveAxis`.

    **Raises:**

    `TypeError` for a model that is not a `DriveAxis` or a record that is not a `Record`;
    `ValueError` for missing signals. Warns `ExcitationWarning` when the record does not
    move both ways (friction not identifiable).
    """
    where = "calibrate_drive"
    names = {f.name for f in dataclasses.fields(DriveSignals)}
    chosen = {k: options.pop(k) for k in names & set(options)}
    sig = options_object(DriveSignals, signals, chosen, where, "signals")
    reference, position, force = sig.reference, sig.position, sig.force
    command_offset = sig.command_offset
    unknown = sorted(set(options) - set(CalibrateOptions.__annotations__))
    if unknown:
        raise TypeError(
            f"{where}: unknown option(s) {unknown}; the options are the signals "
            f"{sorted(names)} and those of jaxvs.calibrate "
            f"{sorted(CalibrateOptions.__annotations__)}."
        )
    options.setdefault("max_steps", 100)
    if not isinstance(drive, DriveAxis):
        raise TypeError(
            f"{where}: drive must be a jaxvs.models.DriveAxis; got {type(drive).__name__}."
        )
    if not isinstance(record, Record):
        raise TypeError(
            f"{where}: record must be a jaxvs.data.Record (e.g. from jaxvs.data.load_emps); got "
            f"{type(record).__name__}."
        )
    if criterion not in _CRITERIA:
        raise ValueError(f"{where}: criterion must be one of {_CRITERIA}; got {criterion!r}.")
    for name in (reference, position, force):
        if name not in record:
            raise ValueError(
                f"{where}: the record has no signal {name!r} (it has {list(record.names)}); "
                "pass reference=, position= or force= with the right names."
            )
    q = np.asarray(record[position], dtype=float)
    dt = float(record.dt)
    if isinstance(command_offset, str):
        if command_offset not in record:
            raise ValueError(f"{where}: the record has no signal {command_offset!r}.")
        offset = np.asarray(record[command_offset], dtype=float)
    elif command_offset is None:
        offset = np.zeros_like(q)
    else:
        offset = np.asarray(command_offset, dtype=float)
        if offset.shape != q.shape:
            raise ValueError(
                f"{where}: command_offset has shape {offset.shape}; the record has "
                f"{q.shape[0]} samples."
            )
    _check_motion(q, dt, min_speed)
    data = {
        "r": jnp.asarray(record[reference], dtype=float),
        "q": jnp.asarray(q),
        "u": jnp.asarray(record[force], dtype=float),
        "q0": jnp.asarray(q[0]),
        "offset": jnp.asarray(offset),
    }
    if free is None:
        free = lambda d: d.mechanics  # noqa: E731
    # the drive's own stability check needs concrete parameters: run it once here
    drive.check_stability()
    return calibrate(
        drive,
        data,
        drive_residual(criterion, dt=dt),
        solver,
        free=free,
        **options,
    )
