"""TwinCAT Scope exports (real files, four variants), TDMS and MDF (written here with npTDMS
and asammdf, read back)."""

import numpy as np
import pytest

from jaxvs.data import (
    ORIGINAL_UNITS_KEY,
    Record,
    is_twincat_scope,
    load,
    load_frf,
    load_mdf,
    load_tdms,
    load_twincat_scope,
)

VARIANTS = [
    "tc3_scope_3_4_3145_3-default.csv",
    "tc3_scope_3_4_3145_3-DecimalMark_,.csv",
    "tc3_scope_3_4_3145_3-Seperator_2.csv",
    "tc3_scope_3_4_3145_3_noOS.csv",
]


@pytest.fixture(scope="module")
def scope_dir(shared_data):
    return shared_data / "twincat_scope"


def parse_nos_column(path, value_col, time_col):
    """Independent oracle: the noOS export read with plain string splitting."""
    lines = path.read_text(encoding="utf-8-sig").splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("0.0;"))
    rows = [line.split(";") for line in lines[first:] if line.strip()]
    return (
        np.array([float(r[time_col]) for r in rows]),
        np.array([float(r[value_col]) for r in rows]),
    )


@pytest.mark.parametrize("variant", VARIANTS)
def test_every_scope_variant_gives_the_same_channels(scope_dir, variant):
    records = load_twincat_scope(scope_dir / variant)
    by_dt = {round(r.dt * 1e4): r for r in records}
    # 1 ms channels always; the 0.2 ms oversampling channel and the 5 ms free-sampled
    # channel (time offset -3 ms) stay separate records, never resampled.
    expected = {10} if variant.endswith("noOS.csv") else {2, 10, 50}
    assert set(by_dt) == expected
    main = by_dt[10]
    assert len(main) == 1000 and main.t0 == 0.0 and main.dt == pytest.approx(1e-3, rel=1e-12)
    # The test recording counts milliseconds: var_REAL64 = 0, 1, 2, ... in every variant
    # (decimal comma, other separator).
    np.testing.assert_array_equal(main["var_REAL64"], np.arange(1000.0))
    ms = np.arange(1000.0)
    if variant == "tc3_scope_3_4_3145_3-default.csv":
        # This export holds the raw PLC values (its header cannot say so): as exported...
        np.testing.assert_array_equal(main["func_scaled"], ms)
        # ...and with the header's scaling applied they equal the scaled exports.
        main = {
            round(r.dt * 1e4): r for r in load_twincat_scope(scope_dir / variant, scaling="apply")
        }[10]
    # ScaleFactor -1, Offset 1: 1 - t; unit scaling -10, +10 in dV, then dV -> V (/10).
    np.testing.assert_array_equal(main["func_scaled"], 1.0 - ms)
    np.testing.assert_allclose(main["func_units_scaled"], (10 - 10 * ms) / 10, rtol=1e-15)
    assert main.unit("func_units_scaled") == "V"
    assert main.metadata[ORIGINAL_UNITS_KEY] == {"func_units_scaled": "dV"}
    assert main.metadata["channels"]["var_REAL64"]["symbol"] == "MAIN.var_LREAL"
    if 50 in by_dt:
        free = by_dt[50]
        assert free.t0 == pytest.approx(-3e-3, abs=1e-12) and len(free) == 201
        assert len(by_dt[2]) == 4996
    assert is_twincat_scope(scope_dir / variant)
    loaded = load(scope_dir / variant)
    assert isinstance(loaded, Record if variant.endswith("noOS.csv") else list)


def test_scope_values_match_an_independent_parse(scope_dir):
    path = scope_dir / "tc3_scope_3_4_3145_3_noOS.csv"
    record = load_twincat_scope(path)[0]
    # var_INT8 is the 2nd channel: time column 2, value column 3 (wraps at 127).
    t, values = parse_nos_column(path, 3, 2)
    np.testing.assert_array_equal(record["var_INT8"], values)
    np.testing.assert_allclose(record.t, t / 1000, rtol=1e-12, atol=1e-15)
    assert values.min() < 0  # the int8 counter wrapped: a real oracle, not a ramp


def test_truncated_scope_export_is_refused(scope_dir, tmp_path):
    text = (scope_dir / "tc3_scope_3_4_3145_3-default.csv").read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(text[: len(text) // 3])
    with pytest.raises(ValueError, match="export spans 0.999 s.*truncated"):
        load(cut)


def test_scope_channel_with_jittered_time_is_refused(scope_dir, tmp_path):
    lines = (scope_dir / "tc3_scope_3_4_3145_3_noOS.csv").read_text(encoding="utf-8-sig")
    rows = lines.splitlines()
    k = next(i for i, line in enumerate(rows) if line.startswith("500;"))
    cells = rows[k].split(";")
    cells[0] = "500.6"  # var_BIT's own time column: one sample 0.6 ms late
    rows[k] = ";".join(cells)
    bad = tmp_path / "jitter.csv"
    bad.write_text("\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(
        ValueError, match="channel 'var_BIT' has time stamps that are not uniform .*not resampled"
    ):
        load_twincat_scope(bad)


def test_scope_unknown_variant_and_plain_csv(tmp_path):
    with pytest.raises(ValueError, match="scaling must be 'as_exported' or 'apply'"):
        load_twincat_scope(tmp_path / "x.csv", scaling="raw")
    odd = tmp_path / "odd.csv"
    odd.write_text("Name\tx\nSampleTime[ms]\tfast\n\nName\tx\n1\tabc\n")
    with pytest.raises(ValueError, match="cannot be parsed|no channel|truncated"):
        load_twincat_scope(odd)
    plain = tmp_path / "plain.csv"
    plain.write_text("t,q\n0,1\n1,2\n")
    with pytest.raises(ValueError, match="does not start like a TwinCAT Scope text export"):
        load_twincat_scope(plain)
    assert not is_twincat_scope(plain)
    with pytest.raises(ValueError, match="holds time series, not a frequency response"):
        load_frf(plain)


def test_scope_channel_selection(scope_dir):
    records = load_twincat_scope(scope_dir / VARIANTS[0], names=["var_INT16", "func_OS"])
    assert sorted(n for r in records for n in r.names) == ["func_OS", "var_INT16"]
    with pytest.raises(KeyError, match="no channel \\['nope'\\]"):
        load_twincat_scope(scope_dir / VARIANTS[0], names=["nope"])


# --- TDMS -------------------------------------------------------------------------------------


def write_tdms(path, channels, root_props=None):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    objects = [RootObject(properties=root_props or {})]
    groups = sorted({g for g, *_ in channels})
    objects += [GroupObject(g) for g in groups]
    objects += [ChannelObject(g, name, data, properties=props) for g, name, data, props in channels]
    with TdmsWriter(str(path)) as writer:
        writer.write_segment(objects)


def test_tdms_round_trip_values_units_and_sample_time(tmp_path):
    rng = np.random.default_rng(3)
    q = rng.standard_normal(500)
    force = rng.standard_normal(500)
    temp = 20 + rng.standard_normal(50)
    path = tmp_path / "bench.tdms"
    wf = {"wf_increment": 1e-3, "wf_start_offset": 0.5}
    write_tdms(
        path,
        [
            ("drive", "q", q, {"unit_string": "mm", **wf}),
            ("drive", "u", force, {"unit_string": "kN", **wf}),
            ("thermal", "T", temp, {"unit_string": "degC", "wf_increment": 0.1}),
        ],
        root_props={"operator": "bench 3"},
    )
    records = load_tdms(path)
    fast, slow = records  # two time bases: 1 ms and 100 ms, not resampled
    assert fast.names == ("q", "u") and fast.dt == pytest.approx(1e-3, rel=1e-12)
    assert fast.t0 == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(fast["q"], q / 1000, rtol=1e-15)  # mm -> m
    np.testing.assert_allclose(fast["u"], force * 1000, rtol=1e-15)  # kN -> N
    assert fast.units == {"q": "m", "u": "N"}
    assert fast.metadata["operator"] == "bench 3"
    np.testing.assert_array_equal(slow["T"], temp)
    assert slow.dt == pytest.approx(0.1, rel=1e-12) and slow.unit("T") == "degC"
    assert isinstance(load(path), list)


def test_tdms_with_time_channel_and_errors(tmp_path):
    t = np.arange(20) * 2e-3
    path = tmp_path / "tc.tdms"
    write_tdms(path, [("g", "time", t * 1000, {"unit_string": "ms"}), ("g", "x", np.sin(t), {})])
    record = load(path)
    assert record.dt == pytest.approx(2e-3, rel=1e-9)
    np.testing.assert_array_equal(record["x"], np.sin(t))
    # Jittered time channel: refused, not resampled.
    jitter = t.copy()
    jitter[7] += 0.5e-3
    bad = tmp_path / "jitter.tdms"
    write_tdms(bad, [("g", "time", jitter, {}), ("g", "x", np.sin(t), {})])
    with pytest.raises(
        ValueError, match="channel 'x' has time stamps that are not uniform.*not resampled"
    ):
        load_tdms(bad)
    notime = tmp_path / "notime.tdms"
    write_tdms(notime, [("g", "x", np.ones(5), {})])
    with pytest.raises(ValueError, match="no waveform timing.*add a time channel"):
        load_tdms(notime)
    trunc = tmp_path / "trunc.tdms"
    trunc.write_bytes(path.read_bytes()[:40])
    with pytest.raises(ValueError, match="cannot be read as TDMS.*truncated"):
        load(trunc)
    badunit = tmp_path / "badunit.tdms"
    write_tdms(
        badunit,
        [("g", "x", np.ones(5), {"unit_string": "furlongs_per_blorp", "wf_increment": 0.1})],
    )
    with pytest.raises(ValueError, match="signal 'x': unknown unit"):
        load_tdms(badunit)


# --- MDF --------------------------------------------------------------------------------------


def write_mdf(path, groups):
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    for signals in groups:
        mdf.append([Signal(v, t, name=n, unit=u) for n, t, v, u in signals])
    mdf.save(str(path), overwrite=True)
    mdf.close()


def test_mdf_round_trip_values_units_and_sample_time(tmp_path):
    rng = np.random.default_rng(4)
    t1 = 0.25 + np.arange(400) * 5e-4
    t2 = np.arange(30) * 0.2
    q = rng.standard_normal(400)
    v = rng.standard_normal(400)
    temp = 300 + rng.standard_normal(30)
    path = tmp_path / "drive.mf4"
    write_mdf(path, [[("q", t1, q, "mm"), ("v", t1, v, "mm/s")], [("T", t2, temp, "K")]])
    fast, slow = load_mdf(path)
    assert fast.names == ("q", "v") and fast.dt == pytest.approx(5e-4, rel=1e-9)
    assert fast.t0 == pytest.approx(0.25, abs=1e-12)
    np.testing.assert_allclose(fast["q"], q / 1000, rtol=1e-15)
    np.testing.assert_allclose(fast["v"], v / 1000, rtol=1e-15)
    # Kelvin -> °C: minus 273.15 (offset conversion), 1e-12 absolute is float64 rounding.
    np.testing.assert_allclose(slow["T"], temp - 273.15, atol=1e-12)
    assert slow.unit("T") == "degC" and slow.metadata[ORIGINAL_UNITS_KEY] == {"T": "K"}
    assert [r.names for r in load(path)] == [("q", "v"), ("T",)]


def test_mdf_errors(tmp_path):
    t = np.array([0.0, 0.01, 0.02, 0.035, 0.04])
    path = tmp_path / "async.mf4"
    write_mdf(path, [[("can_speed", t, np.ones(5), "rpm")]])
    with pytest.raises(
        ValueError, match="channel 'can_speed' has time stamps that are not uniform.*not resampled"
    ):
        load_mdf(path)
    good = tmp_path / "good.mf4"
    write_mdf(good, [[("x", np.arange(10) * 0.1, np.ones(10), "")]])
    trunc = tmp_path / "trunc.mf4"
    trunc.write_bytes(good.read_bytes()[:100])
    with pytest.raises(ValueError, match="cannot be read as MDF.*truncated"):
        load_mdf(trunc)
    with pytest.raises(KeyError, match="no channel"):
        load_mdf(good, names=["y"])
