"""Units in headers and files are converted to SI on load, and refused when unknown."""

import h5py
import numpy as np
import pytest

from jaxvs.data import (
    ORIGINAL_UNITS_KEY,
    Record,
    load,
    load_csv,
    load_hdf5,
    parse_header,
    si_unit,
    to_si,
)

# Unit conversions are exact decimal scalings done in float64: 1e-15 relative is rounding.
RTOL = 1e-15


def write_csv(tmp_path, header, rows, name="m.csv"):
    path = tmp_path / name
    lines = [",".join(header)] + [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_csv_header_units_are_converted_to_si(tmp_path):
    t_ms = np.arange(6) * 0.5  # ms
    q_mm = np.array([0.0, 1.5, 3.0, 2.0, -1.0, 0.25])
    f_kn = np.array([1.0, -2.0, 0.5, 0.0, 3.0, 1.0])
    temp = np.array([20.0, 20.5, 21.0, 21.5, 22.0, 22.5])
    path = write_csv(
        tmp_path,
        ["t [ms]", "q [mm]", "F [kN]", "T [degC]"],
        np.column_stack([t_ms, q_mm, f_kn, temp]),
    )
    record = load_csv(path)
    # mm -> m is value/1000, kN -> N is value*1000, ms -> s is value/1000.
    np.testing.assert_allclose(record["q"], q_mm / 1000, rtol=RTOL)
    np.testing.assert_allclose(record["F"], f_kn * 1000, rtol=RTOL)
    np.testing.assert_allclose(record.t, t_ms / 1000, rtol=1e-12, atol=1e-18)
    assert record.dt == pytest.approx(0.5e-3, rel=1e-12)
    # Temperatures stay in °C (the thermal family's unit), unchanged.
    np.testing.assert_array_equal(record["T"], temp)
    assert record.units == {"q": "m", "F": "N", "T": "degC"}
    assert record.metadata[ORIGINAL_UNITS_KEY] == {"t": "ms", "q": "mm", "F": "kN"}


def test_kelvin_and_fahrenheit_become_celsius_and_rpm_stays_rpm(tmp_path):
    path = write_csv(
        tmp_path,
        ["t", "T1 [K]", "T2 [degF]", "v_m [rpm]", "w [deg/s]"],
        [[0, 293.15, 212.0, 1500.0, 180.0], [1, 300.15, 32.0, 3000.0, 90.0]],
    )
    record = load_csv(path)
    # Offsets: 293.15 K = 20 °C, 212 °F = 100 °C, 32 °F = 0 °C (definitions of the scales).
    np.testing.assert_allclose(record["T1"], [20.0, 27.0], atol=1e-12)
    np.testing.assert_allclose(record["T2"], [100.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(record["v_m"], [1500.0, 3000.0])
    np.testing.assert_allclose(record["w"], [np.pi, np.pi / 2], rtol=RTOL)
    assert record.units == {"T1": "degC", "T2": "degC", "v_m": "rpm", "w": "rad/s"}


@pytest.mark.parametrize(
    "cell, expected",
    [
        ("q [mm]", ("q", "mm")),
        ("q (mm)", ("q", "mm")),
        ("q/mm", ("q", "mm")),
        ("T [°C]", ("T", "°C")),
        ("q", ("q", None)),
        ("test space (1)", ("test space (1)", None)),  # a number is no unit
        ("speed (axis X)", ("speed (axis X)", None)),  # not a unit: part of the name
        ("a/b/c", ("a/b/c", None)),  # ambiguous: two slashes
        ("x/yz_unknown", ("x/yz_unknown", None)),  # right side is no unit
    ],
)
def test_parse_header(cell, expected):
    assert parse_header(cell) == expected


def test_parenthesised_and_slashed_units_in_csv(tmp_path):
    path = write_csv(tmp_path, ["t (s)", "q (um)", "v/mm/min"], [[0, 1.0, 60.0], [1, 2.0, 120.0]])
    record = load_csv(path)
    np.testing.assert_allclose(record["q"], [1e-6, 2e-6], rtol=RTOL)
    # "v/mm/min" has two slashes: it is a name, not "v" in mm/min (ambiguous is never guessed).
    assert "v/mm/min" in record.names and record.unit("v/mm/min") is None


def test_unknown_unit_is_refused_naming_column_and_fix(tmp_path):
    path = write_csv(tmp_path, ["t", "q [blorps]"], [[0, 1.0], [1, 2.0]])
    with pytest.raises(ValueError, match=r"signal 'q': unknown unit 'blorps'.*pint reads"):
        load_csv(path)


def test_raw_counts_are_refused(tmp_path):
    path = write_csv(tmp_path, ["t", "enc [inc]"], [[0, 1.0], [1, 2.0]])
    with pytest.raises(ValueError, match="not a physical unit.*Scale the signal"):
        load(path)


def test_time_column_in_a_non_time_unit_is_refused(tmp_path):
    path = write_csv(tmp_path, ["t [N]", "q"], [[0, 1.0], [1, 2.0]])
    with pytest.raises(ValueError, match="'N' .*does not measure the same quantity as 's'"):
        load_csv(path)


def test_hdf5_unit_attributes_are_converted(tmp_path):
    path = tmp_path / "u.h5"
    with h5py.File(path, "w") as handle:
        handle.create_dataset("t", data=np.arange(4) * 2.0).attrs["unit"] = "ms"
        handle.create_dataset("q", data=np.arange(4.0)).attrs["unit"] = "mm"
        handle.create_dataset("u", data=np.ones(4)).attrs["units"] = "kN"
    record = load_hdf5(path)
    np.testing.assert_allclose(record["q"], np.arange(4.0) / 1000, rtol=RTOL)
    np.testing.assert_allclose(record["u"], 1000.0 * np.ones(4), rtol=RTOL)
    assert record.dt == pytest.approx(2e-3, rel=1e-12)
    assert record.metadata[ORIGINAL_UNITS_KEY] == {"t": "ms", "q": "mm", "u": "kN"}


def test_npz_units_are_converted(tmp_path):
    path = tmp_path / "u.npz"
    np.savez(
        path,
        t=np.arange(3.0),
        q=np.array([1.0, 2.0, 3.0]),
        jaxvs_units=np.array('{"q": "mm"}'),
    )
    record = load(path)
    np.testing.assert_allclose(record["q"], [1e-3, 2e-3, 3e-3], rtol=RTOL)
    assert record.unit("q") == "m"


def test_si_records_round_trip_without_original_units(tmp_path):
    record = Record({"q": np.arange(3.0)}, dt=0.1, units={"q": "m"})
    path = tmp_path / "r.csv"
    from jaxvs.data import save_csv

    save_csv(record, path)
    back = load_csv(path)
    # Nothing was converted, so no "original_units" entry appears in the metadata.
    assert ORIGINAL_UNITS_KEY not in back.metadata and back.units == {"q": "m"}


def test_require_unit_converts_compatible_and_refuses_other_quantities():
    record = Record(
        {"q": np.array([1.0, 2.0]), "u": np.array([3.0, 4.0])}, dt=1.0, units={"q": "mm", "u": "N"}
    )
    in_m = record.require_unit("q", "m")
    np.testing.assert_allclose(in_m["q"], [1e-3, 2e-3], rtol=RTOL)
    assert in_m.unit("q") == "m" and in_m.metadata[ORIGINAL_UNITS_KEY] == {"q": "mm"}
    assert in_m.require_unit("q", "m") is in_m
    with pytest.raises(
        ValueError,
        match=r"signal 'u': unit 'N' .*does not measure the same "
        r"quantity as 'm'",
    ):
        record.require_unit("u", "m")
    with pytest.raises(KeyError, match="No signal named 'x'"):
        record.require_unit("x", "m")
    with pytest.raises(ValueError, match="unknown unit 'mx'"):
        record.require_unit("q", "mx")


def test_require_unit_labels_a_signal_without_unit():
    record = Record({"q": np.array([1.0, 2.0])}, dt=1.0)
    labelled = record.require_unit("q", "m")
    np.testing.assert_array_equal(labelled["q"], record["q"])
    assert labelled.unit("q") == "m"


def test_to_si_and_si_unit():
    values, unit = to_si([1.0, 2.0], "N/mm", name="k")
    np.testing.assert_allclose(values, [1e3, 2e3], rtol=RTOL)
    assert unit == "N/m"
    assert si_unit("kN*m") == "N*m" and si_unit("mm/min") == "m/s" and si_unit("-") == ""


def test_ambiguous_g_is_refused_and_g0_is_gravity(tmp_path):
    path = write_csv(tmp_path, ["t", "acc [g]"], [[0, 1.0], [1, 2.0]])
    with pytest.raises(ValueError, match="'g' is ambiguous.*'g0'"):
        load_csv(path)
    path = write_csv(tmp_path, ["t", "acc [g0]"], [[0, 1.0], [1, 2.0]], name="g0.csv")
    # Standard gravity is 9.80665 m/s^2 by definition (CGPM 1901).
    np.testing.assert_allclose(load_csv(path)["acc"], [9.80665, 19.6133], rtol=1e-15)
