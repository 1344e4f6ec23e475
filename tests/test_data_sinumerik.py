"""Sinumerik XML readers: the real frequency measurement, and trace / AST files written here.

The real file (`sinumerik/freq_trace.XML`) is checked against itself: the decoded
frequency vector is the uniform grid the header announces, the excitation is the
two-level PRBS the header describes, and H1 recomputed from the stored time series matches
the stored spectra. Trace and auto-tuning (AST) files are not shipped; the tests write
files in their published layout (see `jaxvs/data/_sinumerik.py`) with an independent
encoder and read them back.
"""

import struct
from pathlib import Path

import numpy as np
import pytest

from jaxvs.data import (
    FRFData,
    Record,
    decode_sinumerik_base85,
    load,
    load_frf,
    load_sinumerik,
    load_sinumerik_frf,
)
from jaxvs.signal import frf_h1

ALPHABET = "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ!#$`()*+-/:;=?@[]^_{|}~"


def encode(values, *, width=200) -> str:
    """Independent encoder: float64 big-endian → 32-bit words → 5 digits, zero word → '.'."""
    raw = struct.pack(f">{len(values)}d", *values)
    out = []
    for (word,) in struct.iter_unpack(">I", raw):
        if word == 0:
            out.append(".")
            continue
        digits = []
        for _ in range(5):
            word, digit = divmod(word, 85)
            digits.append(ALPHABET[digit])
        out.append("".join(reversed(digits)))
    text = "".join(out)
    return "\n".join(text[i : i + width] for i in range(0, len(text), width))


def numeric_array(name, values, *, complex_values=False) -> str:
    values = np.asarray(values)
    if complex_values:
        flat = np.column_stack([values.real, values.imag]).reshape(-1)
        kind = "ComplexNumber"
    else:
        flat = values.astype(float)
        kind = "double"
    return (
        f'<NumericArray satclassid="4" elementtype="{kind}" format="base85" name="{name}">'
        f'<unsigned_int name="m_length">{values.size}</unsigned_int>'
        f'<raw name="m_pNumberArray"><![CDATA[\n{encode(flat)}\n]]></raw></NumericArray>'
    )


# --- the number encoding -------------------------------------------------------------------


def test_decoder_round_trips_an_independent_encoder():
    rng = np.random.default_rng(0)
    values = np.concatenate([[0.0, 1.0, -2.5, 4000.0, 1e-300, -0.0], rng.standard_normal(50)])
    decoded = decode_sinumerik_base85(encode(values), count=values.size)
    # Bit-exact: the encoding is lossless (IEEE 754 words written as digits).
    np.testing.assert_array_equal(decoded.view(np.uint64), values.view(np.uint64))


@pytest.mark.parametrize(
    "text, match",
    [
        ("kJA`l149|~kG!", "incomplete group"),
        ("kJA`l149|~kG!p<I$!YV", "not in the Sinumerik base-85 alphabet"),
        ("kJA`l", "do not make whole float64"),
        ("~~~~~.", "exceeds 32 bits"),
    ],
)
def test_decoder_refuses_damaged_text(text, match):
    with pytest.raises(ValueError, match=match):
        decode_sinumerik_base85(text)


def test_decoder_checks_the_announced_count():
    with pytest.raises(ValueError, match="decoded 1 values but the file announces 2"):
        decode_sinumerik_base85(encode([1.0]), count=2)


# --- the real frequency measurement ----------------------------------------------------------


@pytest.fixture(scope="module")
def measurement(shared_data):
    path = shared_data / "sinumerik" / "freq_trace.XML"
    return path, load_sinumerik(path), load_sinumerik_frf(path)


def test_real_measurement_time_series(measurement):
    path, runs, _ = measurement
    assert len(runs) == 2  # two traversing directions
    for run in runs:
        assert isinstance(run, Record) and run.names == ("excitation", "response")
        assert len(run) == 2047  # one period of a PRBS of order 11 (2^11 - 1)
        assert run.dt == pytest.approx(125e-6, rel=1e-9) and run.t0 == 0.0
        assert run.units == {"excitation": "rad/s", "response": "rad/s"}
        meta = run.metadata
        assert meta["machine"] == "GLENNMACHINE0" and meta["prbs_order"] == 11
        # The excitation is binary: offset ± amplitude from the file's ExcitationSource
        # (4 ± 2 rpm in rad/s), up to the drive's setpoint quantisation (observed 1.0e-5
        # relative; 5e-5 leaves room, a wrong unit or level would be off by 10 % or more).
        levels = np.unique(np.abs(run["excitation"]))
        offset, amplitude = meta["excitation_offset"], meta["excitation_amplitude"]
        np.testing.assert_allclose(levels, [offset - amplitude, offset + amplitude], rtol=5e-5)
    # The second run traverses in the other direction.
    assert np.mean(runs[0]["response"]) > 0 > np.mean(runs[1]["response"])
    assert load(path)[0].names == ("excitation", "response")


def test_real_measurement_frequency_grid_and_coherence(measurement):
    _, _, frf = measurement
    assert isinstance(frf, FRFData) and frf.n_averages == 2
    # The decoded grid is the uniform 0..4000 Hz grid of 1023 bins (DC dropped): an
    # independent check of the decoder on real data (values to float64 rounding).
    np.testing.assert_allclose(frf.frequency, np.linspace(0, 4000, 1023)[1:], rtol=1e-12)
    assert frf.input_unit == frf.output_unit == "rad/s"
    c = np.asarray(frf.coherence)
    assert c.min() >= 0 and c.max() <= 1
    # The closed speed loop follows its setpoint at low frequency: |H| = 1 within 1 %.
    assert abs(abs(complex(frf.H[0])) - 1) < 0.01
    # ...and lags: the phase at 40 Hz is negative (the conj convention of the file).
    k = int(np.argmin(np.abs(np.asarray(frf.frequency) - 40)))
    assert np.angle(complex(frf.H[k])) < 0


def test_real_measurement_h1_recomputed_from_time_series(measurement):
    _, runs, stored = measurement
    x = np.stack([run["excitation"] for run in runs])
    y = np.stack([run["response"] for run in runs])
    # One PRBS period per run, no window: the periodic excitation needs no taper.
    recomputed = frf_h1(x, y, runs[0].fs, window="boxcar", nperseg=2047, records_axis=0)
    f = np.asarray(recomputed.frequency)
    fs, Hs, cs = (np.asarray(a) for a in (stored.frequency, stored.H, stored.coherence))
    # The CNC's grid is 4000/1022 Hz, ours 8000/2047 Hz: interpolate the stored response.
    Hi = np.interp(f, fs, Hs.real) + 1j * np.interp(f, fs, Hs.imag)
    ci = np.interp(f, fs, cs)
    H = np.asarray(recomputed.H)
    coherent = (f > 0) & (ci > 0.95)
    rel = np.abs(H - Hi) / np.abs(Hi)
    db = np.abs(20 * np.log10(np.abs(H) / np.abs(Hi)))
    deg = np.abs(np.angle(H / Hi, deg=True))
    # The CNC's spectral window/averaging is not in the file and the grids differ by
    # 0.15 %, so agreement is close but not exact; bounds are ~2x what was measured.
    below_100 = coherent & (f <= 100)
    assert below_100.sum() >= 20 and rel[below_100].max() < 0.01  # measured 0.77 %
    below_250 = coherent & (f <= 250)  # loop bandwidth and the first resonance
    assert np.median(rel[below_250]) < 0.01  # measured 0.54 %
    assert db[below_250].max() < 0.5 and deg[below_250].max() < 4.0  # 0.29 dB, 2.6 deg
    band = coherent & (f <= 550)  # the whole band where gamma^2 > 0.95
    assert np.median(rel[band]) < 0.02  # measured 1.3 %
    assert db[band].max() < 1.5 and deg[band].max() < 6.0  # measured 0.81 dB, 3.6 deg


def test_load_frf_dispatches_to_sinumerik(measurement):
    path, _, frf = measurement
    again = load_frf(path)
    np.testing.assert_array_equal(np.asarray(again.H), np.asarray(frf.H))


def test_truncated_real_file_is_refused(measurement, tmp_path):
    path = measurement[0]
    text = Path(path).read_bytes()
    cut = tmp_path / "cut.XML"
    cut.write_bytes(text[: len(text) // 2])
    with pytest.raises(ValueError, match="not well-formed XML.*truncated"):
        load_sinumerik(cut)
    # A damaged number array inside otherwise valid XML: one character removed.
    damaged = tmp_path / "damaged.XML"
    source = text.decode("latin-1")
    i = source.index("<![CDATA[") + 60  # inside the digits (past the leading indentation)
    damaged.write_bytes((source[:i] + source[i + 1 :]).encode("latin-1"))
    with pytest.raises(ValueError, match="node 61, time series 0: .*truncated or damaged"):
        load_sinumerik(damaged)


# --- trace files (published layout, written here) -------------------------------------------


def trace_xml(rows, signals) -> str:
    head = "".join(
        f'<dataSignal name="{name}" description="{desc}" key="k{i}"{unit}/>'
        for i, (name, desc, unit) in enumerate(signals)
    )
    recs = "".join(
        '<rec time="{}" {}/>'.format(t, " ".join(f'f{k + 1}="{v}"' for k, v in cells.items()))
        for t, cells in rows
    )
    return (
        '<?xml version="1.0" encoding="ISO-8859-1"?><trace><traceData><dataFrame>'
        f"{head}{recs}</dataFrame></traceData></trace>"
    )


def test_trace_signals_by_nc_path_and_separate_time_bases(tmp_path):
    dt_fast, n = 0.000125, 16
    t = np.arange(n) * dt_fast
    pos = np.sin(2 * np.pi * 50 * t)
    rows = []
    for k in range(n):
        cells = {0: repr(float(pos[k]))}
        # The second signal is recorded every 4th cycle (IPO vs servo); the others carry
        # the no-value sentinel, which is dropped, never filled in.
        cells[1] = repr(float(k)) if k % 4 == 0 else "9218868437227405312"
        rows.append((repr(float(t[k])), cells))
    signals = [
        ("/Nck/ServoData/actPositionEnc1[u1,1]", "position actual value", ' unit="mm"'),
        ("/Nck/SEMA/actFeedRate[u1,1]", "feed", ""),
    ]
    path = tmp_path / "trace.xml"
    path.write_text(trace_xml(rows, signals))
    records = load(path)
    assert len(records) == 2
    fast, slow = sorted(records, key=lambda r: r.dt)
    assert fast.names == ("/Nck/ServoData/actPositionEnc1[u1,1]",)
    assert fast.dt == pytest.approx(dt_fast, rel=1e-9)
    # mm in the descriptor -> m in the record (value / 1000).
    np.testing.assert_allclose(fast[fast.names[0]], pos / 1000, rtol=1e-15)
    assert fast.unit(fast.names[0]) == "m"
    assert slow.dt == pytest.approx(4 * dt_fast, rel=1e-9)
    np.testing.assert_array_equal(slow["/Nck/SEMA/actFeedRate[u1,1]"], [0.0, 4.0, 8.0, 12.0])
    with pytest.raises(ValueError, match="servo trace.*frf_h1"):
        load_frf(path)


def test_trace_errors(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text(trace_xml([("0.0", {0: "1"}), ("0.1", {2: "1"})], [("/a", "a", "")]))
    with pytest.raises(ValueError, match="column f3 but only 1 signals are declared"):
        load_sinumerik(bad)
    one = tmp_path / "one.xml"
    one.write_text(trace_xml([("0.0", {0: "1"})], [("/a", "a", "")]))
    with pytest.raises(ValueError, match="has 1 sample"):
        load_sinumerik(one)
    other = tmp_path / "other.xml"
    other.write_text("<?xml version='1.0'?><project><item/></project>")
    with pytest.raises(ValueError, match="not a Sinumerik frequency measurement, trace"):
        load_sinumerik(other)


# --- auto-tuning files (published layout, written here) --------------------------------------


def ast_xml(f, H, coherence) -> str:
    def regulator(rid, kp, tn, filters):
        items = "".join(
            '<PT2Filter name="m_LinkedList_node">'
            f'<boolean name="m_bFilterIsEnabled">{"true" if on else "false"}</boolean>'
            f'<float name="m_Frequency">{fr}</float><float name="m_DampingRatio">{d}</float>'
            "</PT2Filter>"
            for on, fr, d in filters
        )
        return (
            '<SpeedLoopRegulator name="m_listpSpeedLoopRegulators_Element">'
            f'<unsigned_int name="m_uRegulatorID">{rid}</unsigned_int>'
            f'<float name="m_dKpGain">{kp}</float><float name="m_dIntegralTime">{tn}</float>'
            '<boolean name="m_bUsingReferenceModel">true</boolean>'
            '<float name="m_dRefmod_freq">37.5</float>'
            '<float name="m_dRefmod_damping">0.7071</float>'
            '<float name="m_dRefmod_tdelay">0</float>'
            '<ConTimeFilterList name="m_CurrentFilters"><LinkedList name="m_LinkedList">'
            f"{items}</LinkedList></ConTimeFilterList>"
            '<ConTimeFilterList name="m_ConTimeFilterListActualSpeedFilters">'
            '<LinkedList name="m_LinkedList"/></ConTimeFilterList>'
            "</SpeedLoopRegulator>"
        )

    return (
        '<?xml version="1.0" encoding="ISO-8859-1"?>'
        '<DynamicModelAxisController satclassid="30">'
        '<string name="m_szAxisName">AX7</string>'
        '<string name="m_szPlatformName">TESTMACHINE</string>'
        '<string name="m_szInitTime">2024-01-02T02:12:04</string>'
        '<DynamicModelList name="m_PositionControllerList"><LinkedList name="m_DynModList">'
        '<DynamicModelPositionController840DSL name="m_DynamicModelBase_ListElement">'
        '<DynamicModelPositionControllerBase name="m_CommunicationTimesInfo">'
        '<float name="m_dActValDelayTime">0.00025</float></DynamicModelPositionControllerBase>'
        '<DynamicModelList name="m_SpeedControllerList"><LinkedList name="m_DynModList">'
        '<DynamicModelSpeedController840DSL name="m_DynamicModelBase_ListElement">'
        '<float name="m_dMotorInertia">0.076</float>'
        '<float name="m_dTotalInertia">0.1467</float>'
        '<boolean name="m_bMotorIsRotary">true</boolean>'
        '<NumericArray elementtype="double" format="CSV" name="m_estimatedMechPoles">'
        '<unsigned_int name="m_length">2</unsigned_int>'
        '<raw name="m_pNumberArray">59.5,1205.4</raw></NumericArray>'
        '<LinkedList name="m_listMechPlants"><PlantMeasRecord name="m_listMechPlants_el">'
        '<FrequencyResponseFunction name="m_pPlant">'
        f"{numeric_array('m_ValueVector', H, complex_values=True)}"
        f"{numeric_array('m_FrequencyVector', f)}</FrequencyResponseFunction>"
        '<FrequencyResponseFunction name="m_pMeasCoherence">'
        f"{numeric_array('m_ValueVector', coherence.astype(complex), complex_values=True)}"
        f"{numeric_array('m_FrequencyVector', f)}</FrequencyResponseFunction>"
        "</PlantMeasRecord></LinkedList>"
        '<LinkedList name="m_listpSpeedLoopRegulators">'
        f"{regulator(1, 25.45, 0.01, [(True, 1999.0, 0.7), (False, 1999.0, 0.7)])}"
        f"{regulator(2, 22.24, 0.035, [(True, 2000.0, 0.7071)])}"
        "</LinkedList></DynamicModelSpeedController840DSL></LinkedList></DynamicModelList>"
        "</DynamicModelPositionController840DSL></LinkedList></DynamicModelList>"
        "</DynamicModelAxisController>"
    )


def test_ast_plant_coherence_and_controller_settings(tmp_path):
    f = np.geomspace(0.5, 4000, 300)
    s = 2j * np.pi * f
    J, wn, zeta = 0.1467, 2 * np.pi * 270, 0.04
    H = (
        1
        / (J * s)
        * (s**2 + 2 * 0.03 * 0.7 * wn * s + (0.7 * wn) ** 2)
        / ((s**2 + 2 * zeta * wn * s + wn**2) * 0.49)
    )
    coherence = np.linspace(0.5, 1.0, f.size)
    path = tmp_path / "ast.xml"
    path.write_text(ast_xml(f, H, coherence))
    frf = load_frf(path)
    # Lossless encoding: the plant comes back bit for bit.
    np.testing.assert_array_equal(np.asarray(frf.frequency), f)
    np.testing.assert_array_equal(np.asarray(frf.H), H)
    np.testing.assert_array_equal(np.asarray(frf.coherence), coherence)
    assert (frf.input_unit, frf.output_unit) == ("N*m", "rad/s")
    meta = frf.metadata
    assert meta["axis_name"] == "AX7" and meta["machine"] == "TESTMACHINE"
    assert meta["speed_controller_ids"] == (1, 2) and meta["speed_controller_tuned"] == 2
    assert meta["speed_controller_2.Kp"] == 22.24 and meta["speed_controller_2.Tn"] == 0.035
    assert meta["speed_controller_2.reference_model"] is True
    # Only enabled filters are listed.
    assert meta["speed_controller_1.current_setpoint_filters"] == (("PT2", 1999.0, 0.7),)
    assert meta["estimated_poles_Hz"] == (59.5, 1205.4)
    assert meta["total_inertia"] == 0.1467 and meta["actual_value_delay_time"] == 0.00025
    with pytest.raises(ValueError, match="auto-tuning.*load_frf"):
        load(path)


def test_ast_without_plant_is_refused(tmp_path):
    path = tmp_path / "ast.xml"
    text = ast_xml(np.array([1.0, 2.0]), np.array([1.0 + 0j, 2.0]), np.array([1.0, 1.0]))
    path.write_text(text.replace('name="m_pPlant"', 'name="m_pOther"'))
    with pytest.raises(ValueError, match="holds no measured plant"):
        load_sinumerik_frf(path)
