"""Universal File Format (UFF / UNV) datasets through pyuff: time records and FRFs.

UFF is the common export format of modal test systems (Siemens Testlab, m+p, Brüel &
Kjær, ...). jaxvs reads

- dataset **58** (function at a nodal DOF): time responses (function type 1) into a
  [`Record`][jaxvs.data.Record]; frequency response functions (type 4),
  transmissibilities (type 5) and their coherences (type 6) into an
  [`FRFData`][jaxvs.data.FRFData];
- dataset **151** (header: model name, description, creating program) and **164**
  (unit system) into the metadata;
- units: unit labels through jaxvs's units handling and unlabelled axes through the 164
  unit system's factors, into SI (the file's units in `metadata["original_units"]`);
- dataset **55** (data at nodes: mode shapes with frequencies and damping) with
  [`load_uff_modes`][jaxvs.data.load_uff_modes].

and writes records and FRFs back as dataset 58 (binary 58b by default, which is exact).
Reference: the UFF dataset descriptions of the Structural Dynamics Research Lab,
University of Cincinnati (reproduced in pyuff's `get_structure_58()` etc.).
"""

from __future__ import annotations

import gc
import os
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._frf import FRFData
from ._paths import existing_file
from ._record import Record
from ._units import ORIGINAL_UNITS_KEY, to_si

__all__ = ["load_uff_frf", "load_uff_modes", "load_uff_record", "save_uff", "uff_datasets"]

SUPPORTED_DATASETS = (55, 58, 151, 164)
_FUNC_TIME, _FUNC_FRF, _FUNC_TRANSMISSIBILITY, _FUNC_COHERENCE = 1, 4, 5, 6
_FUNC_NAMES = {
    0: "general or unknown",
    1: "time response",
    2: "auto spectrum",
    3: "cross spectrum",
    4: "frequency response function",
    5: "transmissibility",
    6: "coherence",
    7: "auto correlation",
    8: "cross correlation",
    9: "power spectral density",
    10: "energy spectral density",
    11: "probability density function",
    12: "spectrum",
    13: "cumulative frequency distribution",
    14: "peaks valley",
    15: "stress/cycles",
    16: "strain/cycles",
    17: "orbit",
    18: "mode indicator function",
    19: "force pattern",
    20: "partial power",
    21: "partial coherence",
    22: "eigenvalue",
    23: "eigenvector",
    24: "shock response spectrum",
    25: "finite impulse response filter",
    26: "multiple coherence",
    27: "order function",
}
# Specific data types (record 8-10, field 1) and their SI units.
_SPEC_UNITS = {
    8: "m",  # displacement
    11: "m/s",  # velocity
    12: "m/s^2",  # acceleration
    13: "N",  # excitation force
    9: "N",  # reaction force
    15: "Pa",  # pressure
    5: "degC",  # temperature
    17: "s",  # time
    18: "Hz",  # frequency
}
_KIND_SPEC = {"receptance": 8, "mobility": 11, "accelerance": 12}
_DIRS = {
    0: "",
    1: "+X",
    2: "+Y",
    3: "+Z",
    -1: "-X",
    -2: "-Y",
    -3: "-Z",
    4: "+RX",
    5: "+RY",
    6: "+RZ",
}
_TIME_UNITS = ("s", "sec", "seconds", "second")
_FREQ_UNITS = ("hz", "1/s")


def _pyuff():
    try:
        import pyuff
    except ImportError as e:  # pragma: no cover - pyuff is a dependency
        raise ImportError("UFF files need pyuff: pip install 'pyuff>=2.4'.") from e
    return pyuff


def _label(x: Any) -> str:
    s = str(x).strip() if x is not None else ""
    return "" if s.upper() == "NONE" else s


def _read(path: str | os.PathLike) -> tuple[Path, list[dict]]:
    path = existing_file(path)
    pyuff = _pyuff()
    try:
        uff = pyuff.UFF(str(path))
        n = uff.get_n_sets()
        sets = uff.read_sets() if n else []
    except Exception as e:
        raise ValueError(
            f"{path}: pyuff could not read this file as UFF ({e}). Check that it is a "
            "universal file (.uff/.unv); binary 58b files from some vendors need "
            "pyuff.fix_58b first."
        ) from e
    if isinstance(sets, dict):
        sets = [sets]
    types = [int(t) for t in uff.get_set_types()]
    for s, t in zip(sets, types):
        s.setdefault("type", t)
    if not sets:
        raise ValueError(
            f"{path}: the file holds no UFF dataset (no block between '    -1' lines); check "
            "that it is a universal file (.uff/.unv) and complete."
        )
    _check_complete(path, sets)
    return path, sets


def _delimiters(data: bytes) -> int:
    """The number of `    -1` dataset delimiters in `data` (pyuff's rule: the tag ends the
    line, the file, or is padded with blanks to column 80)."""
    count, at = 0, data.find(b"    -1")
    while at != -1:
        rest = data[at + 6 : at + 80]
        if not rest or rest[:1] in (b"\n", b"\r") or rest == b" " * 74:
            count += 1
        at = data.find(b"    -1", at + 1)
    return count


def _check_complete(path: Path, sets: list[dict]) -> None:
    """Refuse a file that pyuff read only in part: an unterminated (truncated) dataset, or
    a dataset 58 with fewer or more values than its header announces (a data line that is
    not numbers is skipped by pyuff)."""
    if _delimiters(path.read_bytes()) % 2:
        raise ValueError(
            f"{path}: the file ends inside dataset {len(sets)} (0-based; its closing '    -1' "
            "line is missing): it is truncated. Export or copy the file again."
        )
    for i, s in enumerate(sets):
        if int(s["type"]) != 58 or "num_pts" not in s or "data" not in s:
            continue
        expected, found = int(s["num_pts"]), len(np.asarray(s["data"]).reshape(-1))
        if found != expected:
            raise ValueError(
                f"{path}: dataset {i} announces {expected} values but {found} could be read "
                "(a data line is missing, truncated or not numeric). Repair or export the "
                "file again."
            )


def uff_datasets(path: str | os.PathLike) -> list[dict[str, Any]]:
    """A short inventory of the datasets in a UFF file (without reading their data arrays).

    **Returns:**

    One dict per dataset, in file order: `index`, `type` (UFF dataset number), and for
    dataset 58 `function` (e.g. `"frequency response function"`), `response`
    (node and direction, e.g. `"1+Z"`), `reference`, `id1`.
    """
    path = Path(path)
    pyuff = _pyuff()
    uff = pyuff.UFF(str(path))
    types = [int(t) for t in uff.get_set_types()]
    out = []
    for i, t in enumerate(types):
        entry: dict[str, Any] = {"index": i, "type": t}
        if t == 58:
            d = uff.read_sets(i, header_only=True)
            entry.update(
                function=_FUNC_NAMES.get(int(d["func_type"]), str(d["func_type"])),
                response=_dof(d, "rsp"),
                reference=_dof(d, "ref"),
                id1=_label(d.get("id1")),
            )
        out.append(entry)
    return out


def _dof(d: dict, which: str) -> str:
    return f"{int(d[which + '_node'])}{_DIRS.get(int(d[which + '_dir']), str(d[which + '_dir']))}"


def _check_types(path: Path, sets: list[dict], skip_unsupported: bool) -> None:
    bad = sorted({int(s["type"]) for s in sets} - set(SUPPORTED_DATASETS))
    if bad and not skip_unsupported:
        raise ValueError(
            f"{path}: UFF dataset type(s) {bad} are not supported by jaxvs (it reads "
            f"{list(SUPPORTED_DATASETS)}: 58 functions, 55 data at nodes, 151 header, 164 "
            "units). Pass skip_unsupported=True to ignore them (e.g. geometry 2411/15/82)."
        )


def _metadata(path: Path, sets: list[dict]) -> dict[str, Any]:
    meta: dict[str, Any] = {"source": str(path)}
    for s in sets:
        t = int(s["type"])
        if t == 151:
            for key in ("model_name", "description", "db_app", "program", "date_db_created"):
                if _label(s.get(key)):
                    meta[f"uff_{key}"] = _label(s.get(key))
        elif t == 164:
            meta["uff_units_code"] = int(s.get("units_code", 0))
            if _label(s.get("units_description")):
                meta["uff_units_description"] = _label(s.get("units_description"))
            meta["uff_unit_factors"] = tuple(
                float(s.get(k, 1.0)) for k in ("length", "force", "temp", "temp_offset")
            )
    return meta


def _si_units(meta: dict) -> bool:
    factors = meta.get("uff_unit_factors")
    return factors is None or tuple(factors[:2]) == (1.0, 1.0)


def _unit(d: dict, axis: str, meta: dict) -> str:
    label = _label(d.get(f"{axis}_axis_units_lab"))
    if label:
        return label
    spec = int(d.get(f"{axis}_spec_data_type", 0) or 0)
    return _SPEC_UNITS.get(spec, "") if _si_units(meta) else ""


# Specific data types whose unit a 164 unit system scales, and the SI value per file
# unit as a function of the 164 factors (length, force): UFF 164 gives "factors for
# converting universal file units to SI: divide by the factor".
_SPEC_SCALE = {
    8: lambda length, force: 1.0 / length,  # displacement
    11: lambda length, force: 1.0 / length,  # velocity (time is always s)
    12: lambda length, force: 1.0 / length,  # acceleration
    9: lambda length, force: 1.0 / force,  # reaction force
    13: lambda length, force: 1.0 / force,  # excitation force
    15: lambda length, force: length**2 / force,  # pressure
}


def _si_scale(d: dict, axis: str, meta: dict, name: str, path: Path) -> tuple[float, str, str]:
    """`(factor, SI unit, unit in the file)` of one axis of a 58 dataset: a value times
    `factor` is in the SI unit.

    A unit label goes through jaxvs's units handling: `g` on an ordinate is standard
    gravity (UFF ordinates are accelerometer channels, never masses), `m/s2` is m/s^2,
    `EU` (engineering units) stays unconverted. An unlabelled axis of a known specific
    data type takes the 164 unit system's factors. A label that is no unit is refused, as
    in every jaxvs reader."""
    label = _label(d.get(f"{axis}_axis_units_lab"))
    if label.upper() in ("EU", "E.U."):
        # "engineering units": the file does not say which; kept as written, unconverted
        # (pint would read "EU" as the enzyme unit)
        return 1.0, "", label
    if label:
        # UFF writers' spellings: "g" for standard gravity, "m/s2" for m/s^2
        text = "g0" if label == "g" else re.sub(r"(?<=[A-Za-z])([23])\b", r"^\1", label)
        one, si = to_si(np.array([0.0, 1.0]), text, name=name, source=str(path))
        return float(one[1] - one[0]), si, label
    spec = int(d.get(f"{axis}_spec_data_type", 0) or 0)
    unit = _SPEC_UNITS.get(spec, "")
    if _si_units(meta) or spec not in _SPEC_SCALE:
        return 1.0, unit if _si_units(meta) else "", unit
    length, force = meta["uff_unit_factors"][:2]
    code = meta.get("uff_units_code", "?")
    return _SPEC_SCALE[spec](length, force), unit, f"{unit} in UFF 164 unit system {code}"


def _check_abscissa(path: Path, picked, meta: dict, allowed, axis: str, unit_si: str) -> None:
    """Refuse an abscissa in another unit than jaxvs's (s for time, Hz for frequency)."""
    for i, s in picked:
        unit = _unit(s, "abscissa", meta)
        if unit and unit.lower() not in allowed:
            raise ValueError(
                f"{path}: dataset {i} has its {axis} axis in {unit!r}; jaxvs uses {unit_si}. "
                f"Re-export the file with the abscissa in {unit_si}."
            )


def _select(sets: list[dict], index: Sequence[int] | None, path: Path) -> list[tuple[int, dict]]:
    numbered = list(enumerate(sets))
    if index is None:
        return numbered
    index = list(index)
    bad = [i for i in index if not 0 <= i < len(sets)]
    if bad:
        raise ValueError(
            f"{path}: dataset index {bad} out of range (the file has {len(sets)}); use "
            f"indices 0..{len(sets) - 1} (see jaxvs.data.uff_datasets)."
        )
    return [numbered[i] for i in index]


def _functions(path: Path, sets, index, skip_unsupported, wanted: tuple[int, ...], what: str):
    _check_types(path, sets, skip_unsupported)
    chosen = [(i, s) for i, s in _select(sets, index, path) if int(s["type"]) == 58]
    funcs = {int(s["func_type"]) for _, s in chosen}
    other = sorted(
        funcs - set(wanted) - {_FUNC_TIME, _FUNC_FRF, _FUNC_TRANSMISSIBILITY, _FUNC_COHERENCE}
    )
    if other and not skip_unsupported:
        names = [f"{f} ({_FUNC_NAMES.get(f, '?')})" for f in other]
        raise ValueError(
            f"{path}: dataset-58 function type(s) {', '.join(names)} are not supported; jaxvs "
            "reads time responses (1), FRFs (4), transmissibilities (5) and coherences (6). "
            "Pass skip_unsupported=True to ignore them, or index=[...] to pick datasets."
        )
    picked = [(i, s) for i, s in chosen if int(s["func_type"]) in wanted]
    if not picked:
        found = sorted({_FUNC_NAMES.get(f, str(f)) for f in funcs}) or ["no dataset 58"]
        other = "load_uff_frf" if what == "time response" else "load_uff_record"
        raise ValueError(
            f"{path}: no {what} in the file (found: {', '.join(found)}); read the "
            f"datasets it holds with {other} (or jaxvs.data.load / load_frf)."
        )
    return picked


def _same_grid(path: Path, picked, axis_name: str) -> np.ndarray:
    x0 = np.asarray(picked[0][1]["x"], dtype=float)
    for i, s in picked[1:]:
        x = np.asarray(s["x"], dtype=float)
        if x.shape != x0.shape or not np.allclose(x, x0, rtol=1e-9, atol=0):
            raise ValueError(
                f"{path}: dataset {i} has another {axis_name} grid ({x.shape[0]} points "
                f"{x[0]:g}..{x[-1]:g}) than dataset {picked[0][0]} ({x0.shape[0]} points "
                f"{x0[0]:g}..{x0[-1]:g}); load them separately with index=[...]."
            )
    return x0


def load_uff_record(
    path: str | os.PathLike,
    *,
    index: Sequence[int] | None = None,
    skip_unsupported: bool = False,
) -> Record:
    """Read the time responses (dataset 58, function type 1) of a UFF file into a `Record`.

    Every time-response dataset becomes one signal. Its name is the dataset's ID line 1
    when those are unique, else the response DOF (`"3+Z"`); its unit is the ordinate
    unit label, or the SI unit of its specific data type (acceleration `m/s^2`, force `N`,
    ...). All signals must share one time grid.

    **Arguments:**

    - `path`: the `.uff` / `.unv` file (ASCII or binary 58b).
    - `index`: optional dataset positions (0-based, in file order) to read; default all.
    - `skip_unsupported`: ignore datasets jaxvs does not read instead of raising.

    **Returns:**

    A [`Record`][jaxvs.data.Record] with `t0`, `dt` from the abscissa [s]; metadata with
    `source`, the 151 header and 164 unit system when present, and `uff_dofs`
    (response/reference DOF of each signal).

    **Raises:**

    `ValueError` for unsupported dataset or function types (unless skipped), no time
    response, signals on different time grids, or a time axis not in seconds.
    """
    path, sets = _read(path)
    meta = _metadata(path, sets)
    picked = _functions(path, sets, index, skip_unsupported, (_FUNC_TIME,), "time response")
    _check_abscissa(path, picked, meta, _TIME_UNITS, "time", "s")
    t = _same_grid(path, picked, "time")
    ids = [_label(s.get("id1")) for _, s in picked]
    if all(ids) and len(set(ids)) == len(ids):
        names = ids
    else:
        names = [_dof(s, "rsp") for _, s in picked]
        if len(set(names)) != len(names):
            names = [f"{n}#{i}" for n, (i, _) in zip(names, picked)]
    signals, units, original = {}, {}, {}
    for n, (_, s) in zip(names, picked):
        factor, units[n], written = _si_scale(s, "ordinate", meta, n, path)
        signals[n] = np.asarray(s["data"], dtype=float) * factor
        if written != units[n]:
            original[n] = written
    if original:
        meta[ORIGINAL_UNITS_KEY] = original
    meta["uff_dofs"] = {n: (_dof(s, "rsp"), _dof(s, "ref")) for n, (_, s) in zip(names, picked)}
    if t.shape[0] < 2:
        raise ValueError(f"{path}: a time record needs at least 2 samples.")
    dt = float(picked[0][1].get("abscissa_inc") or (t[1] - t[0]))
    source = f"UFF file {str(path)!r}"
    try:
        if not int(picked[0][1].get("abscissa_spacing", 1)):
            record = Record(signals, t=t, units=units, metadata=meta)
        else:
            record = Record(signals, dt=dt, t0=float(t[0]), units=units, metadata=meta)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None
    return record


def _kind(s: dict) -> str:
    if int(s["func_type"]) == _FUNC_TRANSMISSIBILITY:
        return "transmissibility"
    num = int(s.get("ordinate_spec_data_type", 0) or 0)
    den = int(s.get("orddenom_spec_data_type", 0) or 0)
    if den in (9, 13):
        for kind, spec in _KIND_SPEC.items():
            if num == spec:
                return kind
    if num == den and num in (8, 11, 12):
        return "transmissibility"
    return "frf"


def load_uff_frf(
    path: str | os.PathLike,
    *,
    index: Sequence[int] | None = None,
    layout: str = "auto",
    skip_unsupported: bool = False,
) -> FRFData:
    """Read the FRFs (dataset 58, function types 4 and 5) of a UFF file into an `FRFData`.

    Coherence datasets (function type 6) of the same response/reference DOFs are attached
    as `coherence`. The kind (`"accelerance"`, `"mobility"`, `"receptance"`,
    `"transmissibility"` or `"frf"`) comes from the function type and the specific data
    types of numerator and denominator; the units from the ordinate (numerator) and
    ordinate-denominator unit labels, or the SI units of their specific data types.

    **Arguments:**

    - `path`: the `.uff` / `.unv` file (ASCII or binary 58b).
    - `index`: optional dataset positions (0-based, in file order) to read.
    - `layout`: how several FRFs are arranged: `"mimo"` -- `H (freq, out, in)` over the
      distinct response DOFs (outputs) and reference DOFs (inputs), in order of first
      appearance, which needs every pair exactly once (e.g. a roving-hammer test: 1 out x
      n in); `"batch"` -- `H (n, freq)`, one FRF per dataset in file order; `"auto"`
      (default) -- SISO for one FRF, else `"mimo"` when the pairs form a full grid, else
      `"batch"`.
    - `skip_unsupported`: ignore datasets jaxvs does not read instead of raising.

    **Returns:**

    An [`FRFData`][jaxvs.data.FRFData] on the file's frequency grid [Hz]; metadata with
    `source`, `outputs` and `inputs` (DOF labels, MIMO) or `dofs` (batch), and the
    151/164 information.

    **Raises:**

    `ValueError` for unsupported dataset or function types (unless skipped), no FRF,
    FRFs on different frequency grids, an abscissa not in Hz, or **inconsistent units**
    (FRFs of one file with different numerator or denominator units or kinds: load them
    separately with `index=`).
    """
    if layout not in ("auto", "mimo", "batch"):
        raise ValueError(f"load_uff_frf: layout must be 'auto', 'mimo' or 'batch'; got {layout!r}.")
    path, sets = _read(path)
    meta = _metadata(path, sets)
    wanted = (_FUNC_FRF, _FUNC_TRANSMISSIBILITY, _FUNC_COHERENCE)
    picked = _functions(path, sets, index, skip_unsupported, wanted, "FRF")
    frfs = [(i, s) for i, s in picked if int(s["func_type"]) != _FUNC_COHERENCE]
    cohs = [(i, s) for i, s in picked if int(s["func_type"]) == _FUNC_COHERENCE]
    if not frfs:
        raise ValueError(f"{path}: only coherences, no FRF (function type 4 or 5) in the file.")
    _check_abscissa(path, frfs, meta, _FREQ_UNITS, "frequency", "Hz")
    f = _same_grid(path, picked, "frequency")
    described, factors, original = [], [], {}
    for i, s in frfs:
        fo, out_u, out_w = _si_scale(s, "ordinate", meta, f"dataset {i} numerator", path)
        fi, in_u, in_w = _si_scale(s, "orddenom", meta, f"dataset {i} denominator", path)
        described.append((i, out_u, in_u, _kind(s)))
        factors.append(fo / fi)
        if (out_w, in_w) != (out_u, in_u):
            original[f"dataset {i}"] = f"{out_w or '?'} per {in_w or '?'}"
    if original:
        meta[ORIGINAL_UNITS_KEY] = original
    first = described[0]
    for d in described[1:]:
        if d[1:] != first[1:]:
            raise ValueError(
                f"{path}: inconsistent units: dataset {d[0]} is a {d[3]} in {d[1] or '?'} per "
                f"{d[2] or '?'} but dataset {first[0]} a {first[3]} in {first[1] or '?'} per "
                f"{first[2] or '?'}. One FRFData has one unit; convert them to the same unit, "
                "or load them separately with index=[...]."
            )
    _, out_unit, in_unit, kind = first
    coh_by_pair = {(_dof(s, "rsp"), _dof(s, "ref")): np.asarray(s["data"]).real for _, s in cohs}
    pairs = [(_dof(s, "rsp"), _dof(s, "ref")) for _, s in frfs]
    outs = list(dict.fromkeys(p[0] for p in pairs))
    ins = list(dict.fromkeys(p[1] for p in pairs))
    full = len(set(pairs)) == len(pairs) == len(outs) * len(ins)
    if layout == "mimo" and not full:
        raise ValueError(
            f"{path}: layout='mimo' needs every (response, reference) pair once; the file has "
            f"{len(pairs)} FRFs over {len(outs)} responses x {len(ins)} references. Use "
            "layout='batch'."
        )
    data = [np.asarray(s["data"], dtype=complex) * k for (_, s), k in zip(frfs, factors)]
    coh_list = [coh_by_pair.get(p) for p in pairs]
    has_coh = all(c is not None for c in coh_list)
    if len(frfs) == 1 and layout != "batch":
        H, C, io = data[0], coh_list[0] if has_coh else None, ()
        meta.update(outputs=tuple(outs), inputs=tuple(ins))
    elif layout == "batch" or not full:
        H = np.stack(data)
        C = np.stack(coh_list) if has_coh else None
        io = ()
        meta["dofs"] = tuple(pairs)
    else:
        H = np.zeros((f.shape[0], len(outs), len(ins)), complex)
        C = np.zeros(H.shape) if has_coh else None
        for p, h, c in zip(pairs, data, coh_list):
            H[:, outs.index(p[0]), ins.index(p[1])] = h
            if C is not None:
                C[:, outs.index(p[0]), ins.index(p[1])] = c
        io = (len(outs), len(ins))
        meta.update(outputs=tuple(outs), inputs=tuple(ins))
    if C is not None:
        # heuristic: coherences written in single precision may exceed 1 by rounding
        C = np.clip(C, 0.0, 1.0)
    return FRFData(
        f,
        H,
        coherence=C,
        input_unit=in_unit,
        output_unit=out_unit,
        kind=kind,
        metadata={k: _hashable(v) for k, v in meta.items()},
        io_shape=io,
    )


def _hashable(v: Any) -> Any:
    if isinstance(v, dict):
        return tuple((k, _hashable(x)) for k, x in v.items())
    if isinstance(v, list):
        return tuple(_hashable(x) for x in v)
    return v


def load_uff_modes(
    path: str | os.PathLike, *, skip_unsupported: bool = False
) -> dict[str, np.ndarray]:
    """Read mode shapes (dataset 55, data at nodes) of a UFF file.

    **Returns:**

    A dict of numpy arrays, one entry per mode in file order: `frequency` [Hz] (from the
    eigenvalue for complex modes: `|λ| / 2π`), `damping` (viscous damping ratio [-];
    `-Re λ / |λ|` for complex modes), `eigenvalue` (complex [rad/s]; NaN for normal
    modes), `modal_mass` (NaN when absent), `nodes` `(node,)` node numbers, and `shapes`
    `(mode, node, dof)` (complex; `dof` = 3 translations or 6 with rotations).

    **Raises:**

    `ValueError` when the file holds no mode-shape dataset (analysis types 2, 3 or 7),
    when modes are given on different node sets, or for unsupported dataset types.
    """
    path, sets = _read(path)
    _check_types(path, sets, skip_unsupported)
    modes = [
        s for s in sets if int(s["type"]) == 55 and int(s.get("analysis_type", 0)) in (2, 3, 7)
    ]
    if not modes:
        raise ValueError(
            f"{path}: no mode shapes (dataset 55 of analysis type normal mode 2 or complex "
            "eigenvalue 3/7) in the file."
        )
    nodes = np.asarray(modes[0]["node_nums"], dtype=int)
    freq, damp, eig, mass, shapes = [], [], [], [], []
    for k, s in enumerate(modes):
        if not np.array_equal(np.asarray(s["node_nums"], dtype=int), nodes):
            raise ValueError(
                f"{path}: mode {k} is given on other nodes than mode 0; give every mode on "
                "the same node set."
            )
        n_dof = 6 if "r4" in s else 3
        shapes.append(np.stack([np.asarray(s[f"r{j}"]) for j in range(1, n_dof + 1)], axis=-1))
        if int(s["analysis_type"]) == 2:
            freq.append(float(s["freq"]))
            damp.append(float(s.get("modal_damp_vis", 0.0)))
            eig.append(np.nan + 0j)
            mass.append(float(s.get("modal_m", np.nan)))
        else:
            lam = complex(s["eig"])
            freq.append(abs(lam) / (2 * np.pi))
            damp.append(-lam.real / abs(lam))
            eig.append(lam)
            mass.append(np.nan)
    if len({sh.shape for sh in shapes}) != 1:
        raise ValueError(f"{path}: modes have different numbers of DOFs per node.")
    return {
        "frequency": np.asarray(freq),
        "damping": np.asarray(damp),
        "eigenvalue": np.asarray(eig),
        "modal_mass": np.asarray(mass),
        "nodes": nodes,
        "shapes": np.stack(shapes).astype(complex),
    }


# ----------------------------------------------------------------------------- writing


def _dir_code(label: str) -> tuple[int, int]:
    """`"3+Z"` -> (3, 3); a plain number -> (n, 0)."""
    for code, suffix in sorted(_DIRS.items(), key=lambda kv: -len(kv[1])):
        if suffix and label.endswith(suffix):
            return int(label[: -len(suffix)]), code
    return int(label), 0


def _even(x0: float, dx: float) -> int:
    """1 when the header's `%13.5e` fields hold `x0` and `dx` exactly (even spacing), else 0:
    the abscissa is then written point by point (exact in binary 58b)."""
    return int(float(f"{x0:13.5e}") == x0 and float(f"{dx:13.5e}") == dx)


def _header151(meta: dict) -> dict:
    pyuff = _pyuff()
    return pyuff.prepare_151(
        model_name=str(meta.get("uff_model_name", "jaxvs export"))[:80],
        description=str(meta.get("uff_description", "written by jaxvs.data.save_uff"))[:80],
        db_app="jaxvs",
        program="jaxvs",
        return_full_dict=False,
    )


def save_uff(path: str | os.PathLike, data: Record | FRFData, *, binary: bool = True) -> Path:
    """Write a `Record` or an `FRFData` as a UFF file (a 151 header and 58 datasets).

    - `Record`: one time-response dataset per signal (ID line 1 = the signal name,
      ordinate unit label = its unit, response node = its position).
    - `FRFData`: one FRF dataset per (output, input) pair -- response node `out + 1`,
      reference node `in + 1`, or the DOFs in `metadata["outputs"/"inputs"]` from
      [`load_uff_frf`][jaxvs.data.load_uff_frf] -- plus one coherence dataset each when
      the FRF has a coherence. A family `(n, freq)` is written as `n` FRFs with response
      nodes `1..n` and reads back with `layout="batch"`. Transmissibilities are written
      as FRFs whose numerator and denominator have the same specific data type.

    **Arguments:**

    - `path`: the file to create (overwritten).
    - `data`: the record or FRF.
    - `binary`: write binary 58b (exact float64) instead of ASCII (12 significant
      digits, `%20.11e`). The abscissa is written as `x0 + k dx` when the header's
      `%13.5e` fields hold `x0` and `dx` exactly (e.g. 1 Hz lines, 25.6 kHz sampling),
      otherwise point by point (exact in binary, 6 digits in ASCII).

    **Returns:**

    The path written.

    **Raises:**

    `ValueError` for a non-uniform frequency grid (dataset 58 stores `f0 + k df`).
    """
    if not isinstance(data, (Record, FRFData)):
        raise TypeError(
            f"save_uff: expected a jaxvs.data.Record or FRFData; got {type(data).__name__}."
        )
    pyuff = _pyuff()
    path = Path(path)
    b = 1 if binary else 0
    sets = [_header151(dict(data.metadata))]
    if isinstance(data, Record):
        t = data.t
        even = _even(data.t0, data.dt)
        for k, name in enumerate(data.names):
            sets.append(
                pyuff.prepare_58(
                    binary=b,
                    id1=name[:80],
                    func_type=_FUNC_TIME,
                    rsp_node=k + 1,
                    rsp_dir=0,
                    ref_node=0,
                    ref_dir=0,
                    abscissa_spacing=even,
                    abscissa_spec_data_type=17,
                    abscissa_axis_units_lab="s",
                    ordinate_spec_data_type=0,
                    orddenom_spec_data_type=0,
                    ordinate_axis_units_lab=(data.units.get(name, "") or "NONE")[:20],
                    data=np.asarray(data[name], dtype=float),
                    x=np.asarray(t, dtype=float),
                    return_full_dict=False,
                )
            )
    else:
        f = np.asarray(data.frequency, dtype=float)
        if f.shape[0] > 1 and not np.allclose(np.diff(f), f[1] - f[0], rtol=1e-9, atol=0):
            raise ValueError(
                "save_uff: dataset 58 stores an even frequency grid f0 + k df; this FRF's "
                "grid is not uniform. Interpolate it onto a uniform grid first."
            )
        H = np.asarray(data.H)
        C = None if data.coherence is None else np.asarray(data.coherence)
        meta = dict(data.metadata)
        entries = []  # (response label, reference label, H, C)
        if data.io_shape:
            if len(data.batch_shape):
                raise ValueError(
                    "save_uff: a MIMO FRF family has no UFF layout; write each member."
                )
            outs = meta.get("outputs") or tuple(f"{o + 1}" for o in range(data.n_outputs))
            ins = meta.get("inputs") or tuple(f"{i + 1}" for i in range(data.n_inputs))
            for o in range(data.n_outputs):
                for i in range(data.n_inputs):
                    c = None if C is None else C[:, o, i]
                    entries.append((outs[o], ins[i], H[:, o, i], c))
        else:
            flat = H.reshape(-1, H.shape[-1])
            cflat = None if C is None else C.reshape(-1, C.shape[-1])
            if flat.shape[0] == 1:
                outs, ins = meta.get("outputs") or ("1",), meta.get("inputs") or ("1",)
                entries.append((outs[0], ins[0], flat[0], None if cflat is None else cflat[0]))
            else:
                dofs = meta.get("dofs") or tuple((f"{k + 1}", "1") for k in range(flat.shape[0]))
                for k in range(flat.shape[0]):
                    c = None if cflat is None else cflat[k]
                    entries.append((dofs[k][0], dofs[k][1], flat[k], c))
        even = _even(float(f[0]), float(f[1] - f[0])) if f.shape[0] > 1 else 1
        num_spec = _KIND_SPEC.get(data.kind, 12 if data.kind == "transmissibility" else 0)
        den_spec = {"transmissibility": num_spec, "frf": 0}.get(data.kind, 13)
        for rsp, ref, h, c in entries:
            (rn, rd), (fn, fd) = _dir_code(rsp), _dir_code(ref)
            for func, values, labels in (
                (_FUNC_FRF, h, (data.output_unit, data.input_unit)),
                (_FUNC_COHERENCE, c, ("", "")),
            ):
                if values is None:
                    continue
                is_frf = func == _FUNC_FRF
                sets.append(
                    pyuff.prepare_58(
                        binary=b,
                        id1=("FRF" if is_frf else "coherence") + f" {rsp}/{ref}",
                        func_type=func,
                        rsp_node=rn,
                        rsp_dir=rd,
                        ref_node=fn,
                        ref_dir=fd,
                        abscissa_spacing=even,
                        abscissa_spec_data_type=18,
                        abscissa_axis_units_lab="Hz",
                        ordinate_spec_data_type=num_spec if is_frf else 0,
                        orddenom_spec_data_type=den_spec if is_frf else 0,
                        ordinate_axis_units_lab=(labels[0] or "NONE")[:20],
                        orddenom_axis_units_lab=(labels[1] or "NONE")[:20],
                        data=np.asarray(values, dtype=complex if is_frf else float),
                        x=f,
                        return_full_dict=False,
                    )
                )
    if path.exists():
        path.unlink()
    with warnings.catch_warnings():
        # pyuff's binary-58 writer reopens the file and leaves the handle to the garbage
        # collector (a ResourceWarning); the data are complete once write_sets returns.
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(path)).write_sets(sets, mode="add")
        gc.collect()
    return path
