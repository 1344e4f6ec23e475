"""Siemens Sinumerik XML files: frequency measurements, servo traces and auto-tuning (AST).

Sinumerik Operate saves three kinds of XML file that matter for drive identification:

| file | written by | jaxvs reads |
|---|---|---|
| frequency measurement (root `ResponseTestCustom`, a `m_MeasurementSignalNodeList`) | "Setup/Optimize" → measurement, saved | excitation/response time series → `Record`s (`load_sinumerik`), averaged spectra → `FRFData` (`load_sinumerik_frf`) |
| servo trace (a `traceData` element with a `dataFrame`) | "Diagnostics" → trace, saved | every signal of the frame, named by its NC path → `Record`s |
| auto-tuning result (root `DynamicModelAxisController`) | "Auto servo tuning", save result | the measured speed-loop plant with its coherence → `FRFData`, the speed-controller settings → its metadata |

**Number encoding.** Numeric arrays (`<NumericArray format="base85">`) are stored as text
in a base-85 code that differs from the standard ASCII85 in its alphabet
`0-9 a-z A-Z !#$`()*+-/:;=?@[]^_{|}~` (digit value = position) and in its zero marker: each
big-endian 32-bit word is five digits (most significant first), and a word that is zero is
written as a single `.`. A float64 is two words, high word first (IEEE 754 big-endian); a
`ComplexNumber` element is two float64, real then imaginary. Line breaks and spaces inside
the CDATA are wrapping only. `format="CSV"` arrays are comma-separated decimals.

**What was verified on a real file.** The shared measurement
`sinumerik/freq_trace.XML` (Sinumerik Operate 4.7, E. Rhodén's Trace-Tools, MIT) was read
completely: the decoded frequency vector is exactly `linspace(0, 4000, 1023)` Hz, both
excitation series are two-level (a PRBS of order 11, 2047 samples at 125 µs, levels
offset ± amplitude of the file's `ExcitationSource`), and H1 recomputed from the time
series agrees with the stored spectra (see `tests/test_data_sinumerik.py`). The stored
cross spectrum is `X·conj(Y)` (the conjugate of Bendat & Piersol's `S_xy`): the response
is `conj(cross)/S_xx`, which makes the measured closed speed loop lag, as it must.

**What was not verified.** No real trace or AST file is shipped. The trace layout
(`traceDisplaySetup`/`signals`, `traceData`/`dataFrame` with `dataSignal` descriptors and
`rec time="…" f1="…"` rows, the "no value" sentinel ≥ 9.2e18) and the AST layout
(`DynamicModelPositionController840DSL` → `m_SpeedControllerList` → `m_listMechPlants` →
`FrequencyResponseFunction m_pPlant` / `m_pMeasCoherence`, `m_listpSpeedLoopRegulators`
with `m_dKpGain`, `m_dIntegralTime`, reference model and filter lists) follow public
parsers and a public AST file (Rhodén, Trace-Tools and Sinumerik-Ctrl, 2023–2024). The
AST plant's units (torque → motor speed, SI: N·m and rad/s for rotary motors, N and m/s
for linear motors) follow Rhodén's report that the file stores SI values; they are not
checked against a drive.
"""

from __future__ import annotations

import os
import re
import struct
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from ._frf import FRFData
from ._paths import existing_file
from ._record import DEFAULT_TIME_RTOL, Record, si_record

__all__ = [
    "decode_sinumerik_base85",
    "load_sinumerik",
    "load_sinumerik_frf",
    "sinumerik_kind",
]

SINUMERIK_ALPHABET = (
    "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ!#$`()*+-/:;=?@[]^_{|}~"
)
_DIGIT = {char: value for value, char in enumerate(SINUMERIK_ALPHABET)}
# A trace cell at or above this value is the "no sample" sentinel (the int64 reading of
# the float +inf bit pattern 0x7FF0000000000000 ≈ 9.2188e18).
_NO_VALUE = 9.2e18

PathLike = str | os.PathLike[str]


# --- number encoding -------------------------------------------------------------------


def decode_sinumerik_base85(
    text: str, *, count: int | None = None, complex_values: bool = False, what: str = "array"
) -> np.ndarray:
    """Decode a Sinumerik `format="base85"` number array (see the module doc).

    **Arguments:**

    - `text`: the CDATA text (whitespace is ignored).
    - `count`: the expected number of values (`m_length`), checked when given.
    - `complex_values`: the array holds `ComplexNumber` elements (pairs of float64).
    - `what`: a label for error messages.

    **Returns:**

    A float64 (or complex128) array.

    **Raises:**

    `ValueError` for a character outside the alphabet, a truncated group, a word above
    2³²−1, an odd number of words, or a count different from `count`.
    """
    compact = re.sub(r"\s+", "", text or "")
    words: list[int] = []
    i = 0
    n = len(compact)
    while i < n:
        char = compact[i]
        if char == ".":
            words.append(0)
            i += 1
            continue
        group = compact[i : i + 5]
        if len(group) < 5 or "." in group:
            raise ValueError(
                f"{what}: base-85 text ends in an incomplete group {group!r} at character {i}; "
                "the file is truncated or was edited. Save the measurement again."
            )
        value = 0
        for c in group:
            digit = _DIGIT.get(c)
            if digit is None:
                raise ValueError(
                    f"{what}: character {c!r} at position {i} is not in the Sinumerik base-85 "
                    "alphabet; the file is damaged or not a Sinumerik number array."
                )
            value = value * 85 + digit
        if value > 0xFFFFFFFF:
            raise ValueError(
                f"{what}: group {group!r} exceeds 32 bits; the file is truncated or damaged. "
                "Save the measurement again."
            )
        words.append(value)
        i += 5
    if len(words) % 2:
        raise ValueError(
            f"{what}: {len(words)} 32-bit words do not make whole float64 values; the file is "
            "truncated or damaged."
        )
    raw = struct.pack(f">{len(words)}I", *words)
    values = np.frombuffer(raw, dtype=">f8").astype(np.float64)
    if complex_values:
        if values.size % 2:
            raise ValueError(f"{what}: an odd number of float64 cannot be complex pairs.")
        values = values[0::2] + 1j * values[1::2]
    if count is not None and values.size != count:
        raise ValueError(
            f"{what}: decoded {values.size} values but the file announces {count}; the file is "
            "truncated or damaged. Save the measurement again."
        )
    return values


# --- XML helpers -------------------------------------------------------------------------


def _parse(path: PathLike) -> tuple[Path, ET.Element]:
    file = existing_file(path)
    try:
        root = ET.parse(file).getroot()
    except ET.ParseError as error:
        raise ValueError(
            f"{str(file)!r} is not well-formed XML ({error}); the file is truncated or not a "
            "Sinumerik XML file. Save it again from Sinumerik Operate."
        ) from None
    return file, root


def sinumerik_kind(root: ET.Element) -> str | None:
    """`"frequency_measurement"`, `"trace"`, `"ast"` or `None` for an XML root element."""
    if root.find(".//traceData") is not None or root.tag == "traceData":
        return "trace"
    if (
        root.tag == "DynamicModelAxisController"
        or root.find(".//DynamicModelPositionController840DSL") is not None
    ):
        return "ast"
    if _named(root, "LinkedList", "m_MeasurementSignalNodeList") is not None:
        return "frequency_measurement"
    return None


def _named(elem: ET.Element, tag: str, name: str, *, deep: bool = False) -> ET.Element | None:
    items = elem.iter(tag) if deep else elem.findall(tag)
    for item in items:
        if item.get("name") == name:
            return item
    return None


def _scalar(elem: ET.Element | None, name: str, default: Any = None) -> Any:
    """The typed value of the direct child of `elem` with attribute `name`."""
    if elem is None:
        return default
    for child in elem:
        if child.get("name") != name:
            continue
        text = (child.text or "").strip()
        if child.tag in ("float",):
            return float(text)
        if child.tag in ("unsigned_int", "integer"):
            return int(text)
        if child.tag == "boolean":
            return text.lower() == "true"
        return text
    return default


def _array(elem: ET.Element, what: str) -> np.ndarray:
    """The values of a `NumericArray` element."""
    count = _scalar(elem, "m_length")
    raw = _named(elem, "raw", "m_pNumberArray")
    text = raw.text if raw is not None else ""
    fmt = elem.get("format", "base85")
    complex_values = elem.get("elementtype") == "ComplexNumber"
    if fmt == "CSV":
        cells = [cell for cell in (text or "").replace("\n", "").split(",") if cell.strip()]
        try:
            values = np.array([float(cell) for cell in cells], dtype=np.float64)
        except ValueError:
            raise ValueError(f"{what}: a CSV number array holds a non-number.") from None
        if count is not None and values.size != count * (2 if complex_values else 1):
            raise ValueError(f"{what}: {values.size} values, the file announces {count}.")
        if complex_values:
            values = values[0::2] + 1j * values[1::2]
        return values
    if fmt != "base85":
        raise ValueError(
            f"{what}: number format {fmt!r} is unknown (jaxvs reads 'base85' and 'CSV'); "
            "please report the file's Sinumerik version."
        )
    return decode_sinumerik_base85(
        text or "", count=count, complex_values=complex_values, what=what
    )


def _hashable(value: Any) -> Any:
    if isinstance(value, list | tuple):
        return tuple(_hashable(v) for v in value)
    if isinstance(value, np.ndarray):
        return tuple(_hashable(v) for v in value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


# --- frequency measurement -----------------------------------------------------------


def _signal_nodes(root: ET.Element, source: str) -> list[ET.Element]:
    node_list = _named(root, "LinkedList", "m_MeasurementSignalNodeList")
    nodes = [] if node_list is None else list(node_list.findall("PlatformSignalNode"))
    if len(nodes) < 2:
        raise ValueError(
            f"{source} holds {len(nodes)} measured signal node(s); a frequency measurement "
            "needs an excitation and a response node. Save the measurement with 'time series "
            "data' enabled."
        )
    return nodes


def _io_nodes(root: ET.Element, nodes: list[ET.Element], source: str) -> tuple[ET.Element, ...]:
    primary = _named(root, "LinkedList", "m_listPrimaryFreqRespSigNodeData")
    pair = None if primary is None else primary.find("PrimaryFreqRespSigNodeData")
    if pair is None:
        raise ValueError(
            f"{source} does not say which signal is the excitation "
            "(m_listPrimaryFreqRespSigNodeData is missing); this variant is not supported."
        )
    by_uid = {_scalar(node, "m_iUniqueInstanceId"): node for node in nodes}
    u_in = _scalar(pair, "m_iInputSigNodeUniqueInstanceID")
    u_out = _scalar(pair, "m_iOutputSigNodeUniqueInstanceID")
    if u_in not in by_uid or u_out not in by_uid:
        raise ValueError(
            f"{source}: the excitation/response instances ({u_in}, {u_out}) are not among the "
            f"signal nodes {sorted(by_uid)}; the file is damaged."
        )
    return by_uid[u_in], by_uid[u_out]


def _time_series(node: ET.Element, source: str) -> list[tuple[np.ndarray, float, float]]:
    series = []
    ts_list = _named(node, "LinkedList", "m_TimeSeriesList")
    for k, ts in enumerate([] if ts_list is None else ts_list.findall("TimeSeries")):
        array = _named(ts, "NumericArray", "m_ValueVector")
        what = f"{source}, node {_scalar(node, 'm_uNodeId')}, time series {k}"
        if array is None:
            raise ValueError(f"{what}: no m_ValueVector; the file is damaged.")
        values = _array(array, what)
        start = _scalar(ts, "m_TimeVector.start")
        end = _scalar(ts, "m_TimeVector.end")
        length = _scalar(ts, "m_TimeVector.length")
        if start is None or end is None or length is None:
            raise ValueError(f"{what}: the time vector (start, end, length) is missing.")
        if length != values.size or length < 2:
            raise ValueError(
                f"{what}: the time vector has {length} samples but the values {values.size}."
            )
        series.append((values, float(start), (float(end) - float(start)) / (length - 1)))
    return series


def _measurement_metadata(root: ET.Element, file: Path) -> dict[str, Any]:
    platform = _named(root, "SatPlatformDetails", "m_platformDetailsMeas")
    stamp = _named(root, "SatTimeStamp", "m_timeStampMeas")
    excitation = root.find(".//ExcitationSource")
    condition = root.find(".//ResponseTestCondition")
    amplitude = offset = None
    if excitation is not None:
        cond = excitation.find(".//ExcitationSourceCondition")
        amplitude = _scalar(cond, "m_dExcitationAmplitude")
        offset = _scalar(cond, "m_dOffsetAmplitude")
    meta = {
        "source": "Sinumerik frequency measurement",
        "file": file.name,
        "machine": _scalar(platform, "m_strPlatformID"),
        "date": _scalar(stamp, "Date"),
        "time_of_day": _scalar(stamp, "Time"),
        "axis": _scalar(root, "m_uAxis"),
        "control_loop_type": _scalar(root, "m_eControlLoopType"),
        "injection_point": _scalar(root, "m_eInjectionPoint_rtc"),
        "waveform_type": _scalar(root, "m_eWaveformType"),
        "process_update_time": _scalar(root, "m_dProcessUpdateTime"),
        "prbs_order": _scalar(excitation, "m_uPrbsOrder"),
        "closed_loop": _scalar(excitation, "m_bClosedLoop"),
        "excitation_amplitude": amplitude,
        "excitation_offset": offset,
        "motor_to_axis_ratio": _scalar(excitation, "m_dMotorToAxisRatio"),
        "motor_force_constant": _scalar(excitation, "m_dMotorForceConstant"),
        "number_of_averages": _scalar(condition, "m_uNumberOfAverages"),
        "bandwidth": _scalar(condition, "m_dBandwidth"),
        "sampling_interval": _scalar(condition, "m_dSamplingInterval"),
    }
    return {key: value for key, value in meta.items() if value is not None}


def _speed_unit(root: ET.Element, node: ET.Element) -> str | None:
    # m_eSignalUnits = 0 with the speed loop (m_eControlLoopType = 2) stores motor speeds in
    # rad/s: on the shared file the excitation levels are offset ± amplitude of the
    # ExcitationSource (4 ± 2 rpm written as 0.419 ± 0.209 rad/s) and the dynamic limit
    # 314.16 is 3000 rpm in rad/s. Other combinations are left without a unit.
    if _scalar(node, "m_eSignalUnits") == 0 and _scalar(root, "m_eControlLoopType") == 2:
        return "rad/s"
    return None


def _load_measurement(file: Path, root: ET.Element, time_rtol: float) -> list[Record]:
    source = f"Sinumerik frequency measurement {str(file)!r}"
    nodes = _signal_nodes(root, source)
    node_in, node_out = _io_nodes(root, nodes, source)
    series_in = _time_series(node_in, source)
    series_out = _time_series(node_out, source)
    if not series_in or len(series_in) != len(series_out):
        raise ValueError(
            f"{source}: {len(series_in)} excitation and {len(series_out)} response time series; "
            "save the measurement with 'time series data' enabled (m_bSaveTimeSeriesDataToXML)."
        )
    expected_dt = _scalar(root.find(".//ResponseTestCondition"), "m_dSamplingInterval")
    meta = _measurement_metadata(root, file)
    meta["excitation_node"] = _scalar(node_in, "m_uNodeId")
    meta["response_node"] = _scalar(node_out, "m_uNodeId")
    units = {}
    for signal, node in (("excitation", node_in), ("response", node_out)):
        unit = _speed_unit(root, node)
        if unit:
            units[signal] = unit
    records = []
    for run, ((x, t0x, dtx), (y, t0y, dty)) in enumerate(zip(series_in, series_out)):
        if x.size != y.size or abs(dtx - dty) > time_rtol * dtx or abs(t0x - t0y) > 0.5 * dtx:
            raise ValueError(
                f"{source}, run {run}: excitation ({x.size} samples, dt={dtx!r} s) and response "
                f"({y.size} samples, dt={dty!r} s) do not share a time base; jaxvs does not "
                "resample them silently."
            )
        if expected_dt is not None and abs(dtx - expected_dt) > time_rtol * expected_dt:
            raise ValueError(
                f"{source}, run {run}: the time vector gives dt={dtx!r} s but the test condition "
                f"says {expected_dt!r} s; the file is inconsistent."
            )
        records.append(
            Record(
                {"excitation": x, "response": y},
                dt=dtx,
                t0=t0x,
                units=units,
                metadata={**meta, "run": run},
            )
        )
    return records


def _cross_spectrum(node: ET.Element, partner: int | None, source: str) -> tuple[np.ndarray, ...]:
    """`(frequency, values, n_averages)` of a node's auto (partner None) or cross spectrum."""
    if partner is None:
        info = _named(node, "SigNodeCrossSpectrumInfo", "m_autospectrumInfo")
    else:
        info = None
        cross_list = _named(node, "LinkedList", "m_crossSpecInfoList")
        for item in [] if cross_list is None else cross_list.findall("SigNodeCrossSpectrumInfo"):
            if _scalar(item, "m_uSignodeId") == partner:
                info = item
    what = f"{source}, node {_scalar(node, 'm_uNodeId')}"
    if info is None:
        raise ValueError(
            f"{what}: no {'auto' if partner is None else 'cross'} spectrum; save the "
            "measurement with 'frequency spectrum data' enabled."
        )
    spectrum = info.find("CrossSpectrum")
    values = _named(spectrum, "NumericArray", "m_ValueVector") if spectrum is not None else None
    freq = _named(spectrum, "NumericArray", "m_FrequencyVector") if spectrum is not None else None
    if values is None or freq is None:
        raise ValueError(f"{what}: the spectrum has no values or no frequency vector.")
    return (
        _array(freq, what + " frequencies"),
        _array(values, what + " spectrum"),
        _scalar(info, "m_uNumSpectraInAvg"),
    )


def _measurement_frf(file: Path, root: ET.Element) -> FRFData:
    source = f"Sinumerik frequency measurement {str(file)!r}"
    nodes = _signal_nodes(root, source)
    node_in, node_out = _io_nodes(root, nodes, source)
    f_xx, s_xx, n_avg = _cross_spectrum(node_in, None, source)
    f_yy, s_yy, _ = _cross_spectrum(node_out, None, source)
    f_xy, s_xy, _ = _cross_spectrum(node_out, _scalar(node_in, "m_uNodeId"), source)
    if not (f_xx.shape == f_yy.shape == f_xy.shape and np.allclose(f_xx, f_xy)):
        raise ValueError(f"{source}: the spectra are on different frequency grids.")
    sxx = np.real(s_xx)
    syy = np.real(s_yy)
    # The DC bin holds the products of the offsets, not a dynamic response; bins without
    # excitation power (sxx = 0) have no estimate.
    keep = (f_xx > 0) & (sxx > 0)
    sxy = np.conj(s_xy[keep])  # stored as X·conj(Y) (module doc)
    H = sxy / sxx[keep]
    coherence = np.clip(np.abs(sxy) ** 2 / (sxx[keep] * syy[keep]), 0.0, 1.0)
    meta = _measurement_metadata(root, file)
    meta.update(
        estimator="H1",
        excitation_node=_scalar(node_in, "m_uNodeId"),
        response_node=_scalar(node_out, "m_uNodeId"),
    )
    unit_in = _speed_unit(root, node_in) or ""
    unit_out = _speed_unit(root, node_out) or ""
    return FRFData(
        f_xx[keep],
        H,
        coherence=coherence,
        n_averages=int(n_avg) if n_avg else None,
        input_unit=unit_in,
        output_unit=unit_out,
        metadata={key: _hashable(value) for key, value in meta.items()},
    )


# --- servo trace -------------------------------------------------------------------------


def _load_trace(file: Path, root: ET.Element, time_rtol: float) -> list[Record]:
    source = f"Sinumerik trace {str(file)!r}"
    trace = root if root.tag == "traceData" else root.find(".//traceData")
    frame = None if trace is None else trace.find("dataFrame")
    if frame is None:
        raise ValueError(f"{source} has no traceData/dataFrame element; not a servo trace.")
    descriptors = frame.findall("dataSignal")
    if not descriptors:
        raise ValueError(f"{source}: the data frame declares no dataSignal; nothing to read.")
    names = []
    for k, desc in enumerate(descriptors):
        name = (desc.get("name") or desc.get("description") or f"f{k + 1}").strip()
        if name in names:
            name = f"{name} ({k + 1})"
        names.append(name)
    times: list[list[float]] = [[] for _ in names]
    values: list[list[float]] = [[] for _ in names]
    for row, rec in enumerate(frame.iter("rec")):
        try:
            time = float(rec.get("time", "nan"))
        except ValueError:
            raise ValueError(f"{source}, record {row}: time {rec.get('time')!r} is no number.")
        if not np.isfinite(time):
            raise ValueError(f"{source}, record {row} has no valid 'time' attribute.")
        for key, text in rec.attrib.items():
            if not re.fullmatch(r"f\d+", key):
                continue
            index = int(key[1:]) - 1
            if not 0 <= index < len(names):
                raise ValueError(
                    f"{source}, record {row}: column {key} but only {len(names)} signals are "
                    "declared; the file is damaged."
                )
            try:
                value = float(text)
            except ValueError:
                raise ValueError(
                    f"{source}, record {row}, signal {names[index]!r}: {text!r} is no number."
                ) from None
            if value >= _NO_VALUE:
                continue  # the "no sample in this cycle" sentinel
            times[index].append(time)
            values[index].append(value)
    groups: dict[tuple, list[int]] = {}
    for index, t in enumerate(times):
        if len(t) < 2:
            raise ValueError(
                f"{source}: signal {names[index]!r} has {len(t)} sample(s); a trace signal "
                "needs at least two."
            )
        groups.setdefault(tuple(np.round(np.asarray(t), 12)), []).append(index)
    records = []
    for key, members in groups.items():
        t = np.asarray(key)
        units = {}
        for i in members:
            unit = descriptors[i].get("unit")
            if unit:
                units[names[i]] = unit
        meta = {
            "source": "Sinumerik trace",
            "file": file.name,
            "descriptions": {names[i]: descriptors[i].get("description", "") for i in members},
        }
        try:
            records.append(
                Record(
                    {names[i]: np.asarray(values[i]) for i in members},
                    t=t,
                    units=units,
                    metadata=meta,
                    time_rtol=time_rtol,
                )
            )
        except ValueError as error:
            raise ValueError(f"{source}, signals {[names[i] for i in members]}: {error}") from None
    return [si_record(record, source) for record in records]


# --- auto servo tuning -------------------------------------------------------------------


def _filters(regulator: ET.Element, list_name: str) -> tuple:
    filters = _named(regulator, "ConTimeFilterList", list_name)
    out = []
    linked = None if filters is None else filters.find("LinkedList")
    for item in [] if linked is None else list(linked):
        if not _scalar(item, "m_bFilterIsEnabled", False):
            continue
        if item.tag == "PT1Filter":
            out.append(("PT1", _scalar(item, "m_dTimeConst")))
        elif item.tag == "PT2Filter":
            out.append(("PT2", _scalar(item, "m_Frequency"), _scalar(item, "m_DampingRatio")))
        elif item.tag == "SecondOrderFilter":
            out.append(
                (
                    "second_order",
                    _scalar(item, "m_NumeratorFrequency"),
                    _scalar(item, "m_NumeratorDampingRatio"),
                    _scalar(item, "m_DenominatorFrequency"),
                    _scalar(item, "m_DenominatorDampingRatio"),
                )
            )
        else:
            out.append((item.tag,))
    return tuple(out)


def _ast_frf(file: Path, root: ET.Element, index: int) -> FRFData:
    source = f"Sinumerik auto-tuning file {str(file)!r}"
    position = root.find(".//DynamicModelPositionController840DSL")
    speed_list = (
        None if position is None else _named(position, "DynamicModelList", "m_SpeedControllerList")
    )
    if speed_list is None:
        raise ValueError(
            f"{source} has no speed-controller model (m_SpeedControllerList); this AST variant "
            "is not supported."
        )
    plants = [
        rec
        for rec in speed_list.iter("PlantMeasRecord")
        if _named(rec, "FrequencyResponseFunction", "m_pPlant") is not None
    ]
    if not plants:
        raise ValueError(f"{source} holds no measured plant (m_pPlant); run the AST measurement.")
    if not -len(plants) <= index < len(plants):
        raise ValueError(f"{source} holds {len(plants)} plant measurement(s); index={index}.")
    record = plants[index]
    plant = _named(record, "FrequencyResponseFunction", "m_pPlant")
    values = _named(plant, "NumericArray", "m_ValueVector")
    freq = _named(plant, "NumericArray", "m_FrequencyVector")
    if values is None or freq is None:
        raise ValueError(f"{source}: the plant has no values or no frequency vector.")
    f = _array(freq, source + " plant frequencies")
    H = _array(values, source + " plant")
    if f.shape != H.shape:
        raise ValueError(f"{source}: {f.size} frequencies for {H.size} plant values.")
    coherence = None
    coh = _named(record, "FrequencyResponseFunction", "m_pMeasCoherence")
    if coh is not None:
        c = np.real(_array(_named(coh, "NumericArray", "m_ValueVector"), source + " coherence"))
        if c.shape == f.shape:
            coherence = np.clip(c, 0.0, 1.0)
    keep = f > 0
    controller = speed_list.find(".//*[@name='m_listpSpeedLoopRegulators']")
    meta: dict[str, Any] = {
        "source": "Sinumerik auto servo tuning",
        "file": file.name,
        "axis_name": _scalar(root, "m_szAxisName"),
        "machine": _scalar(root, "m_szPlatformName"),
        "time_stamp": _scalar(root, "m_szInitTime"),
        "plant_index": index,
        "plant_count": len(plants),
    }
    model = None
    for elem in speed_list.iter():
        if _scalar(elem, "m_dTotalInertia") is not None:
            model = elem
            break
    if model is not None:
        meta["motor_inertia"] = _scalar(model, "m_dMotorInertia")
        meta["total_inertia"] = _scalar(model, "m_dTotalInertia")
        meta["speed_controller_update_time"] = _scalar(model, "m_dUpdateTimeSeconds")
        for name, key in (
            ("m_estimatedMechPoles", "estimated_poles_Hz"),
            ("m_estimatedMechZeros", "estimated_zeros_Hz"),
        ):
            arr = _named(model, "NumericArray", name)
            if arr is not None:
                meta[key] = tuple(float(v) for v in np.real(_array(arr, f"{source} {name}")))
    timing = _named(position, "DynamicModelPositionControllerBase", "m_CommunicationTimesInfo")
    if timing is not None:
        meta["actual_value_delay_time"] = _scalar(timing, "m_dActValDelayTime")
    ids = []
    for reg in [] if controller is None else controller.findall("SpeedLoopRegulator"):
        rid = _scalar(reg, "m_uRegulatorID", len(ids) + 1)
        ids.append(rid)
        prefix = f"speed_controller_{rid}"
        meta[f"{prefix}.Kp"] = _scalar(reg, "m_dKpGain")
        meta[f"{prefix}.Tn"] = _scalar(reg, "m_dIntegralTime")
        meta[f"{prefix}.reference_model"] = _scalar(reg, "m_bUsingReferenceModel")
        meta[f"{prefix}.reference_model_frequency"] = _scalar(reg, "m_dRefmod_freq")
        meta[f"{prefix}.reference_model_damping"] = _scalar(reg, "m_dRefmod_damping")
        meta[f"{prefix}.reference_model_delay"] = _scalar(reg, "m_dRefmod_tdelay")
        meta[f"{prefix}.current_setpoint_filters"] = _filters(reg, "m_CurrentFilters")
        meta[f"{prefix}.actual_speed_filters"] = _filters(
            reg, "m_ConTimeFilterListActualSpeedFilters"
        )
    meta["speed_controller_ids"] = tuple(ids)
    if ids:
        meta["speed_controller_tuned"] = ids[-1]
    rotary = _scalar(model, "m_bMotorIsRotary", True) if model is not None else True
    return FRFData(
        f[keep],
        H[keep],
        coherence=None if coherence is None else coherence[keep],
        input_unit="N*m" if rotary else "N",
        output_unit="rad/s" if rotary else "m/s",
        metadata={k: _hashable(v) for k, v in meta.items() if v is not None},
    )


# --- public entry points -------------------------------------------------------------------


def load_sinumerik(path: PathLike, *, time_rtol: float = DEFAULT_TIME_RTOL) -> list[Record]:
    """Time series of a Sinumerik frequency-measurement or trace XML file.

    - **Frequency measurement**: one `Record` per measurement run (the two traversing
      directions of a standard measurement are two runs), each with the signals
      `excitation` and `response` (which is which comes from the file's
      `m_listPrimaryFreqRespSigNodeData`), the sampling period and start time of the file's
      time vector, and the measurement settings (machine, axis, PRBS order, excitation
      amplitude and offset, averages, …) as metadata. Speed-loop measurements
      (`m_eControlLoopType = 2`) carry motor speeds in rad/s (module doc).
    - **Servo trace**: one `Record` per time base (signals recorded in different cycles
      get separate records, never resampled), signals named by their NC path.

    **Arguments:**

    - `path`: the XML file (only read).
    - `time_rtol`: tolerance of the uniform-time check, relative to the sampling period.

    **Returns:**

    A list of `Record`s.

    **Raises:**

    `FileNotFoundError`; `ValueError` naming the file and the fix for a truncated or
    damaged file, an auto-tuning file (use `load_sinumerik_frf`), an XML file of another
    kind, or series that do not share a time base.
    """
    file, root = _parse(path)
    kind = sinumerik_kind(root)
    if kind == "frequency_measurement":
        return _load_measurement(file, root, time_rtol)
    if kind == "trace":
        return _load_trace(file, root, time_rtol)
    if kind == "ast":
        raise ValueError(
            f"{str(file)!r} is a Sinumerik auto-tuning (AST) result; it holds a frequency "
            "response, not time series. Read it with jaxvs.data.load_frf (or "
            "load_sinumerik_frf)."
        )
    raise ValueError(
        f"{str(file)!r} is XML but not a Sinumerik frequency measurement, trace or auto-tuning "
        f"file (root element <{root.tag}>). Save the file from Sinumerik Operate, or convert it "
        "to CSV."
    )


def load_sinumerik_frf(path: PathLike, *, index: int = 0) -> FRFData:
    """The frequency response stored in a Sinumerik frequency-measurement or AST XML file.

    - **Frequency measurement**: H1 = `conj(S_cross)/S_xx` from the averaged spectra the
      file stores, with the ordinary coherence `|S_cross|²/(S_xx·S_yy)`, `n_averages` from
      the file (one spectrum per run), the DC bin dropped.
    - **Auto-tuning (AST) result**: the measured mechanical plant (torque → motor speed,
      `m_pPlant`) of plant record `index`, its coherence (`m_pMeasCoherence`), and the
      speed-controller settings as metadata: for each regulator `i` in the file
      (`speed_controller_ids`, the last one is the tuned result), `speed_controller_i.Kp`
      [N·m·s/rad], `.Tn` [s], `.reference_model` and its frequency [Hz], damping and
      delay [s], and the enabled `.current_setpoint_filters` / `.actual_speed_filters` as
      tuples (`("PT2", f [Hz], ζ)`, `("PT1", T [s])`, `("second_order", fn, ζn, fd, ζd)`);
      also the inertias [kg·m²] and the estimated mechanical poles/zeros [Hz].

    **Arguments:**

    - `path`: the XML file (only read).
    - `index`: which plant measurement of an AST file (default the first).

    **Returns:**

    An `FRFData` (frequencies in Hz).

    **Raises:**

    `ValueError` naming the file and the fix for a trace file (no FRF), a truncated or
    damaged file, or an unsupported variant.
    """
    file, root = _parse(path)
    kind = sinumerik_kind(root)
    if kind == "frequency_measurement":
        return _measurement_frf(file, root)
    if kind == "ast":
        return _ast_frf(file, root, index)
    if kind == "trace":
        raise ValueError(
            f"{str(file)!r} is a Sinumerik servo trace: it holds time series, not a frequency "
            "response. Load it with jaxvs.data.load and estimate the FRF with "
            "jaxvs.signal.frf_h1."
        )
    raise ValueError(
        f"{str(file)!r} is XML but not a Sinumerik frequency measurement or auto-tuning file "
        f"(root element <{root.tag}>)."
    )
