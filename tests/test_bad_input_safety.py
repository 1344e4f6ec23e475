"""Bad-input matrix, safety rows: model files that name code, runs that would not fit in
memory, option values of the wrong type or range, a validation that cannot validate, and
channels that cannot carry the model (row format in `tests/bad_input.py`).

Model-file rows craft `.eqx` headers by hand; memory rows set a small `--max-memory` (or
ask for delays the records cannot hold), so they are refused in milliseconds, before any
JAX work, as a run on a real machine would be refused before it grew.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import jax
import numpy as np
import pytest
from bad_input import Case, run_case
from test_bad_input_cli import (
    N,
    _drive_columns,
    drive_csv,
    refused,
    run_main,
    thermal_csv,
    write_csv,
)

import jaxvs

# the design rows' short thermal record triggers the held-out-data warning before the refusal
pytestmark = pytest.mark.filterwarnings("ignore:design. the held-out data")

# --- model files ------------------------------------------------------------------------------


def _eqx(tmp: Path, change=None, obj=None) -> Path:
    jax.config.update("jax_enable_x64", True)
    obj = obj if obj is not None else {"m": jaxvs.models.FirstOrder(20.0, 5.0, 30.0)}
    path = jaxvs.save_model(tmp / "m.eqx", obj)
    if change is None:
        return path
    raw = path.read_bytes()
    magic, rest = raw.split(b"\n", 1)
    n, rest = rest.split(b"\n", 1)
    header = json.loads(rest[: int(n)])
    change(header)
    blob = json.dumps(header).encode()
    path.write_bytes(magic + b"\n" + b"%d\n" % len(blob) + blob + rest[int(n) :])
    return path


def _names(entry: str, ref: str):
    def change(header):
        tree = header["tree"]["__dict__"]
        if entry == "__class__":
            tree["m"]["__class__"] = ref
        else:
            tree["f"] = {entry: ref}

    return change


def _model_file(id, text, change, match, **kw) -> Case:
    return Case(
        id=id,
        area="modelfiles",
        entry="jaxvs.load_model",
        input=text,
        run=lambda tmp: jaxvs.load_model(_eqx(tmp, change)),
        exc=jaxvs.IncompatibleFileError,
        match=match,
        **kw,
    )


# fmt: off
_NOT_RUN = r"not a jaxvs model (function|class|type).*Nothing of it was run.*like="

CASES: list[Case] = [
    _model_file("eqx-function-os-system", ".eqx header naming os:system as a function",
                _names("__function__", "os:system"), r"'os:system'.*" + _NOT_RUN),
    _model_file("eqx-function-builtins-eval", ".eqx header naming builtins:eval",
                _names("__function__", "builtins:eval"), r"'builtins:eval'.*" + _NOT_RUN),
    _model_file("eqx-class-subprocess-popen", ".eqx header naming subprocess:Popen as a class",
                _names("__class__", "subprocess:Popen"), r"subprocess:Popen.*" + _NOT_RUN),
    _model_file("eqx-type-subprocess-run", ".eqx header naming subprocess:run as a type",
                _names("__type__", "subprocess:run"), r"subprocess:run.*" + _NOT_RUN),
    _model_file("eqx-attribute-path", ".eqx header reaching os.system through a jaxvs module "
                "(jaxvs._io:os.system)", _names("__function__", "jaxvs._io:os.system"),
                _NOT_RUN),
    _model_file("eqx-jaxvs-function", ".eqx header naming a jaxvs function that writes files "
                "(jaxvs:save_model)", _names("__function__", "jaxvs:save_model"), _NOT_RUN),
    _model_file("eqx-huge-array", ".eqx header declaring a 10^12-value array",
                lambda h: h["leaves"][0].update(shape=[10**6, 10**6]),
                r"m\.eqx.*arrays would take 80000000000\d\d bytes but the file has \d+.*"
                r"save_model"),
    _model_file("eqx-object-array", ".eqx header declaring an array of Python objects",
                lambda h: h["leaves"][0].update(dtype="object"),
                r"m\.eqx has a damaged header.*save_model"),
    Case("eqx-fifo", "modelfiles", "jaxvs.load_model", "a named pipe called m.eqx",
         lambda tmp: (os.mkfifo(tmp / "m.eqx"), jaxvs.load_model(tmp / "m.eqx")),
         match=r"named pipe \(FIFO\), not a regular file", timeout=30),
    Case("eqx-registry-round-trip", "modelfiles", "jaxvs.load_model",
         "a file naming jax.nn.tanh and jaxvs classes (what save_model writes)",
         lambda tmp: jaxvs.load_model(_eqx(tmp, obj={
             "m": jaxvs.models.FirstOrder(20.0, 5.0, 30.0), "f": jax.nn.tanh})),
         exc=None, check=lambda back: (
             None if back["f"] is jax.nn.tanh and float(back["m"].T1) == 30.0
             else pytest.fail(f"loaded {back}"))),
]

# --- the physical-range rule of the model constructors -----------------------------------------

M = jaxvs.models
_MOTOR = dict(inductance=1e-3, torque_constant=0.1, back_emf_constant=0.1, inertia=1e-4)
CASES += [
    Case(f"model-{ident}", "models", f"jaxvs.models.{ident.split('-')[0]}", text, run,
         match=match + r".*cannot be negative.*Give its magnitude")
    for ident, text, run, match in [
        ("ViscousFriction-negative", "ViscousFriction(-200)",
         lambda tmp: M.ViscousFriction(-200.0), r"ViscousFriction: Fv must be >= 0 N·s/m"),
        ("CoulombFriction-negative", "CoulombFriction(-20)",
         lambda tmp: M.CoulombFriction(-20.0), r"CoulombFriction: Fc must be >= 0 N"),
        ("DCMotor-negative-resistance", "DCMotor(resistance=-1, ...)",
         lambda tmp: M.DCMotor(-1.0, **_MOTOR), r"DCMotor: resistance must be > 0 Ω"),
        ("FirstOrder-negative-T1", "FirstOrder(20, 5, T1=-300)",
         lambda tmp: M.FirstOrder(20.0, 5.0, -300.0), r"FirstOrder: T1 must be > 0 s"),
    ]
]

# --- options of diagnose and check ------------------------------------------------------------


def _record() -> jaxvs.data.Record:
    cols = _drive_columns()
    return jaxvs.data.Record({k: v for k, v in cols.items() if k != "t"}, t=cols["t"])


_BAD_OPTIONS = [
    ("decimation=0", r"decimation=0 must be an integer >= 1"),
    ("decimation=2.5", r"decimation=2\.5 must be an integer >= 1"),
    ("controller_taps=-1", r"controller_taps=-1 must be an integer >= 1"),
    ("zoh_force=maybe", r"zoh_force='maybe' must be true or false"),
    ("cutoff_hz=-5", r"cutoff_hz=-5 must be a positive finite number"),
    ("friction_sharpness=nan", r"friction_sharpness=nan must be a positive finite number"),
]

for cmd in ("diagnose", "check"):
    for option, match in _BAD_OPTIONS:
        CASES.append(
            refused(
                f"{cmd}-option-{option}",
                f"jaxvs {cmd}",
                f"--option {option}",
                lambda tmp, cmd=cmd, option=option: [
                    cmd, drive_csv(tmp), "--family", "drive", "--out", tmp / "o",
                    "--option", option,
                ],
                match + r".*give such a value, or leave the option out",
            )
        )
CASES += [
    refused("check-option-tmf-coherence", "jaxvs check", "--family tmf --option coherence=2",
            lambda tmp: ["check", drive_csv(tmp), "--family", "tmf", "--option",
                         "coherence=2"],
            r"coherence=2 must be a number in \[0\.0, 1\.0\]"),
    Case("check-python-message-says-check", "check", "jaxvs.check",
         "jaxvs.check(record, family='drive', zoh_force='maybe')",
         lambda tmp: jaxvs.check(_record(), family="drive", zoh_force="maybe"),
         match=r"^check: option zoh_force='maybe' must be true or false"),
    Case("check-python-unknown-option-says-check", "check", "jaxvs.check",
         "jaxvs.check(record, family='drive', order=4) (a tmf option)",
         lambda tmp: jaxvs.check(_record(), family="drive", order=4),
         match=r"^check\(family='drive'\): unknown option\(s\) \['order'\]; the drive family "
               r"takes"),
    Case("check-python-missing-signal-says-check", "check", "jaxvs.check",
         "jaxvs.check of a record without the force u",
         lambda tmp: jaxvs.check(jaxvs.data.Record({"q": _drive_columns()["q"]}, dt=1e-3),
                                 family="drive"),
         match=r"^check\(family='drive'\): experiment .* lacks the required signal\(s\) \['u'\]"),
]

# --- validation that cannot validate -----------------------------------------------------------


def _mm(tmp: Path) -> Path:
    cols = _drive_columns()
    cols["q"] = cols["q"] * 1000.0  # millimetres, the header says nothing
    cols["r"] = cols["r"] * 1000.0
    return write_csv(tmp / "val_mm.csv", cols)


CASES += [
    refused("diagnose-validate-is-calibration", "jaxvs diagnose",
            "--validate naming the calibration file again",
            lambda tmp: ["diagnose", drive_csv(tmp), "--validate", tmp / "run.csv", "--family",
                         "drive", "--out", tmp / "o"],
            r"validation record 'run\.csv' holds the same samples as the calibration record "
            r"'run\.csv'.*Give another experiment as validation, or none"),
    refused("diagnose-validate-in-mm", "jaxvs diagnose",
            "--validate file in mm without a unit in its header (calibration in m)",
            lambda tmp: ["diagnose", drive_csv(tmp), "--validate", _mm(tmp), "--family",
                         "drive", "--out", tmp / "o"],
            r"signal 'q' spans .* in the validation record.*\(1e\+03 times as much\).*"
            r"different units.*Put the unit in each file's header"),
]

# --- channels that cannot carry the model (exit 3, a finding) ----------------------------------


def _channel(edit):
    def make(tmp: Path) -> list:
        cols = _drive_columns()
        cols["u"] = edit(cols["u"])
        return ["check", write_csv(tmp / "run.csv", cols), "--family", "drive"]

    return make


def _finding(pattern: str):
    def check(result) -> None:
        code, out, _ = result
        assert code == 3, (code, out)
        assert re.search(pattern, out, flags=re.S), out

    return check


def _channel_case(id, text, edit, pattern) -> Case:
    return Case(id=id, area="check", entry="jaxvs check", input=text,
                run=lambda tmp: run_main(_channel(edit)(tmp), tmp, ok=(0, 3)),
                exc=None, check=_finding(pattern))


CASES += [
    _channel_case("check-force-frozen", "a force channel frozen at one value for its last half",
                  lambda u: np.r_[u[: N // 2], np.full(N - N // 2, u[N // 2])],
                  r"holds one value over the last or first 50 %.*frozen sensor"),
    _channel_case("check-force-constant", "a force channel stuck at a constant",
                  lambda u: np.full_like(u, 5.0), r"'u' is constant"),
    _channel_case("check-force-clipped", "a force channel clipped at +-20 N (most samples)",
                  lambda u: np.clip(u, -20.0, 20.0), r"clipped or saturated channel"),
    _channel_case("check-force-three-levels", "a force channel with three values (-1, 0, 1)",
                  lambda u: np.sign(np.round(u / 30.0)),
                  r"takes only 3 distinct values \(quantised to nothing"),
]

# --- memory guard -----------------------------------------------------------------------------

CASES += [
    refused("design-max-delay-100000", "jaxvs design",
            "--max-delay 100000 on a record of 1500 samples",
            lambda tmp: ["design", thermal_csv(tmp), "--target", "T_bearing", "--out",
                         tmp / "o", "--max-delay", "100000", "--no-figures"],
            r"max_delay=100000 samples is not below a quarter of the 1500 samples.*"
            r"below 375.*decimate"),
    refused("design-over-max-memory", "jaxvs design",
            "--max-delay 300 with --max-memory 10M",
            lambda tmp: ["design", thermal_csv(tmp), "--target", "T_bearing", "--out",
                         tmp / "o", "--max-delay", "300", "--max-memory", "10M",
                         "--no-figures"],
            r"would need about [\d.]+ GB of memory, more than the limit of 0\.00977 GB "
            r"\(set by --max-memory\).*Lower max_delay.*decimate.*slice"),
    refused("diagnose-over-max-memory", "jaxvs diagnose", "--max-memory 1M on 1500 samples",
            lambda tmp: ["diagnose", drive_csv(tmp), "--family", "drive", "--out", tmp / "o",
                         "--max-memory", "1M"],
            r"diagnose: the drive family's search on 1500 samples would need about .* GB of "
            r"memory.*--max-memory.*Decimate the records.*slice"),
    refused("check-over-max-memory", "jaxvs check", "--max-memory 100K on 1500 samples",
            lambda tmp: ["check", drive_csv(tmp), "--family", "drive", "--max-memory", "100K"],
            r"check: the drive family's check on 1500 samples would need about.*Decimate"),
    refused("check-max-memory-word", "jaxvs check", "--max-memory lots",
            lambda tmp: ["check", drive_csv(tmp), "--family", "drive", "--max-memory", "lots"],
            r"--max-memory: expects a memory size such as 8G"),
]


def test_memory_limit_default_is_the_machine(monkeypatch):
    """Without --max-memory the limit is 80 % of the available memory (oracle: the value
    /proc/meminfo gives, read here independently)."""
    from jaxvs import _memory

    with open("/proc/meminfo") as f:
        avail = next(int(x.split()[1]) * 1024 for x in f if x.startswith("MemAvailable:"))
    assert abs(_memory.available_bytes() - avail) < 0.2 * avail  # memory moves meanwhile
    with pytest.raises(_memory.MemoryEstimateError, match="available on this machine"):
        _memory.guard(2.0 * avail, "a step", "Make it smaller.")
    _memory.guard(0.1 * avail, "a step", "Make it smaller.")  # fits: nothing raised
    assert _memory.parse_size("2.5GB") == 2.5 * 2**30 and _memory.parse_size("512m") == 2**29


# fmt: on


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)


def test_rows_cover_every_class():
    areas = {c.area for c in CASES}
    assert {"modelfiles", "models", "check", "cli"} <= areas
    assert len(CASES) >= 40
