"""UFF (universal file) datasets 58/55/151/164 through pyuff.

Oracles: the measured pyuff FRFs and pyFRF impact records from ../shared/data (values must
survive a write/read cycle bit for bit in binary 58b, to 12 significant digits in ASCII),
pyuff's own reader on the files jaxvs writes, and files written directly with pyuff (not
through jaxvs) read back by jaxvs.
"""

import numpy as np
import pytest
import pyuff

from jaxvs.data import (
    FRFData,
    Record,
    load_uff_frf,
    load_uff_modes,
    load_uff_record,
    save_uff,
    uff_datasets,
)

# ASCII 58 writes `%20.11e`: 12 significant digits, so a relative error <= 5e-12.
ASCII_RTOL = 6e-12


def measured_frf(shared_data):
    files = [shared_data / "pyuff_frf" / f"meas_point_{k}.txt" for k in (1, 2, 3)]
    H = np.stack([np.loadtxt(f, dtype=complex) for f in files], axis=1)[:, None, :]
    # accelerometer at point 1, roving hammer at points 1-3 (data README)
    meta = {"outputs": ("1+Z",), "inputs": ("1-Z", "2-Z", "3-Z")}
    return FRFData(
        np.arange(1001.0),
        H,
        kind="accelerance",
        input_unit="N",
        output_unit="m/s^2",
        metadata=meta,
    )


def write_with_pyuff(path, sets):
    if path.exists():
        path.unlink()
    pyuff.UFF(str(path)).write_sets(sets, mode="add")  # ASCII: pyuff closes its files
    return path


def frf_set(H, f, rsp=1, ref=1, *, func_type=4, num_unit="m/s^2", den_unit="N", **kw):
    return pyuff.prepare_58(
        func_type=func_type,
        rsp_node=rsp,
        rsp_dir=3,
        ref_node=ref,
        ref_dir=3,
        abscissa_spacing=1,
        abscissa_spec_data_type=18,
        ordinate_spec_data_type=kw.pop("num_spec", 12),
        orddenom_spec_data_type=kw.pop("den_spec", 13),
        abscissa_axis_units_lab=kw.pop("x_unit", "Hz"),
        ordinate_axis_units_lab=num_unit,
        orddenom_axis_units_lab=den_unit,
        data=H,
        x=f,
        **kw,
    )


@pytest.mark.parametrize("binary", [True, False])
def test_measured_frfs_round_trip(tmp_path, shared_data, binary):
    frf = measured_frf(shared_data)
    path = save_uff(tmp_path / "frf.uff", frf, binary=binary)
    back = load_uff_frf(path)
    assert back.io_shape == (1, 3) and back.kind == "accelerance"
    assert (back.input_unit, back.output_unit) == ("N", "m/s^2")
    assert back.metadata["inputs"] == ("1-Z", "2-Z", "3-Z")
    np.testing.assert_array_equal(back.frequency, frf.frequency)
    if binary:
        np.testing.assert_array_equal(back.H, frf.H)
    else:
        np.testing.assert_allclose(back.H, frf.H, rtol=ASCII_RTOL)
    # oracle: pyuff's own reader sees the three FRFs with the right DOFs
    sets = [s for s in pyuff.UFF(str(path)).read_sets() if s["type"] == 58]
    assert [(s["rsp_node"], s["ref_node"], s["ref_dir"]) for s in sets] == [
        (1, 1, -3),
        (1, 2, -3),
        (1, 3, -3),
    ]
    np.testing.assert_allclose(sets[2]["data"], frf.H[:, 0, 2], rtol=ASCII_RTOL)
    inventory = uff_datasets(path)
    assert [d["type"] for d in inventory] == [151, 58, 58, 58]
    assert inventory[3]["reference"] == "3-Z"


def test_layouts_and_coherence(tmp_path, shared_data):
    frf = measured_frf(shared_data)
    batch = load_uff_frf(save_uff(tmp_path / "a.uff", frf), layout="batch")
    assert batch.batch_shape == (3,) and batch.is_siso
    np.testing.assert_array_equal(batch.H, np.moveaxis(frf.H[:, 0, :], -1, 0))
    assert batch.metadata["dofs"][1] == ("1+Z", "2-Z")
    siso = load_uff_frf(save_uff(tmp_path / "b.uff", frf), index=[2])
    assert siso.is_siso
    np.testing.assert_array_equal(siso.H, frf.H[:, 0, 1])
    # a SISO FRF with coherence: both round trip
    rng = np.random.default_rng(0)
    coh = rng.uniform(0.2, 1.0, 1001)
    one = FRFData(frf.frequency, frf.H[:, 0, 0], coherence=coh, kind="accelerance")
    back = load_uff_frf(save_uff(tmp_path / "c.uff", one))
    np.testing.assert_array_equal(back.coherence, coh)
    np.testing.assert_array_equal(back.H, one.H)
    # a family written as n FRFs reads back with layout="batch"
    fam = FRFData(frf.frequency, np.moveaxis(frf.H[:, 0, :], -1, 0), kind="transmissibility")
    back = load_uff_frf(save_uff(tmp_path / "d.uff", fam), layout="batch")
    assert back.kind == "transmissibility"
    np.testing.assert_array_equal(back.H, fam.H)


def test_impact_records_round_trip(tmp_path, shared_data):
    data = np.load(shared_data / "pyFRF_impact" / "measurements_1.npy")
    rec = Record({"force": data[1], "acc": data[2]}, t=data[0], units={"force": "N", "acc": "g"})
    back = load_uff_record(save_uff(tmp_path / "hit.uff", rec))
    # the label "g" is written as is and read back as standard gravity, in SI
    assert back.names == ("force", "acc") and back.units == {"force": "N", "acc": "m/s^2"}
    assert back.metadata["original_units"] == {"acc": "g"}
    assert back.dt == rec.dt and back.t0 == rec.t0  # 3.90625e-05 s is exact in the header
    np.testing.assert_allclose(back["acc"], rec["acc"] * 9.80665, rtol=1e-15)  # one product
    np.testing.assert_array_equal(back["force"], rec["force"])


def test_record_with_inexact_sampling_period(tmp_path):
    # dt = 1/3000 s does not fit the header's 6 digits: written point by point instead
    rec = Record({"x": np.sin(np.arange(300) / 7.0)}, dt=1 / 3000, t0=0.25)
    back = load_uff_record(save_uff(tmp_path / "r.uff", rec))
    np.testing.assert_allclose(back.t, rec.t, rtol=1e-15)
    assert abs(back.dt - rec.dt) < 1e-15 * rec.dt * 10
    np.testing.assert_array_equal(back["x"], rec["x"])


def test_file_written_by_pyuff_with_header_units_and_modes(tmp_path):
    """A file as a modal test system writes it: 151, 164, time records without unit
    labels (units from the specific data types) and 55 mode shapes."""
    t = np.arange(64) * 0.5e-3
    sets = [
        pyuff.prepare_151(
            model_name="beam", description="impact test", db_app="tester", program="tester"
        ),
        pyuff.prepare_164(
            units_code=1,
            units_description="SI",
            length=1.0,
            force=1.0,
            temp=1.0,
            temp_offset=273.15,
        ),
    ]
    for node, spec, values in ((1, 13, np.cos(t)), (4, 12, np.sin(t))):
        sets.append(
            pyuff.prepare_58(
                func_type=1,
                rsp_node=node,
                rsp_dir=3,
                ref_node=0,
                ref_dir=0,
                abscissa_spacing=1,
                abscissa_spec_data_type=17,
                ordinate_spec_data_type=spec,
                orddenom_spec_data_type=0,
                data=values,
                x=t,
            )
        )
    shapes = np.array([[1.0, 0.5, 0.0], [0.2, -1.0, 0.3]])
    for k, (f_hz, zeta) in enumerate(((12.5, 0.01), (48.0, 0.02))):
        sets.append(
            pyuff.prepare_55(
                model_type=1,
                analysis_type=2,
                data_ch=2,
                spec_data_type=8,
                load_case=1,
                mode_n=k + 1,
                freq=f_hz,
                modal_m=1.0,
                modal_damp_vis=zeta,
                modal_damp_his=0.0,
                node_nums=np.array([1, 2]),
                r1=shapes[:, 0] * (k + 1),
                r2=shapes[:, 1] * (k + 1),
                r3=shapes[:, 2] * (k + 1),
            )
        )
    path = write_with_pyuff(tmp_path / "test.unv", sets)
    rec = load_uff_record(path)
    assert rec.names == ("1+Z", "4+Z")
    assert rec.units == {"1+Z": "N", "4+Z": "m/s^2"}  # SI units of data types 13 and 12
    assert rec.metadata["uff_model_name"] == "beam"
    assert rec.metadata["uff_unit_factors"] == (1.0, 1.0, 1.0, 273.15)
    np.testing.assert_allclose(rec["4+Z"], np.sin(t), rtol=ASCII_RTOL, atol=1e-15)
    assert rec.dt == 0.5e-3
    modes = load_uff_modes(path)
    np.testing.assert_array_equal(modes["frequency"], [12.5, 48.0])
    np.testing.assert_array_equal(modes["damping"], [0.01, 0.02])
    assert modes["shapes"].shape == (2, 2, 3)
    np.testing.assert_allclose(modes["shapes"][1].real, 2 * shapes, rtol=ASCII_RTOL)
    np.testing.assert_array_equal(modes["nodes"], [1, 2])
    with pytest.raises(ValueError, match="no FRF"):
        load_uff_frf(path)


# ----------------------------------------------------------------------------- bad input


def test_unsupported_dataset_types(tmp_path):
    f = np.arange(1.0, 11.0)
    sets = [
        pyuff.prepare_15(
            node_nums=[1, 2],
            def_cs=[0, 0],
            disp_cs=[0, 0],
            color=[1, 1],
            x=[0.0, 1.0],
            y=[0.0, 0.0],
            z=[0.0, 0.0],
        ),
        frf_set(np.ones(10) * (1 + 1j), f),
    ]
    path = write_with_pyuff(tmp_path / "geo.uff", sets)
    with pytest.raises(ValueError, match=r"dataset type\(s\) \[15\] are not supported"):
        load_uff_frf(path)
    assert load_uff_frf(path, skip_unsupported=True).is_siso
    spectra = write_with_pyuff(
        tmp_path / "spec.uff",
        [frf_set(np.ones(10) + 0j, f, func_type=2), frf_set(np.ones(10) + 0j, f)],
    )
    with pytest.raises(ValueError, match=r"function type\(s\) 2 \(auto spectrum\)"):
        load_uff_frf(spectra)
    assert load_uff_frf(spectra, skip_unsupported=True).is_siso


def test_inconsistent_units_and_grids(tmp_path):
    f = np.arange(1.0, 11.0)
    H = np.ones(10) * (1 + 1j)
    mixed = write_with_pyuff(
        tmp_path / "mixed.uff", [frf_set(H, f, 1), frf_set(H, f, 2, num_unit="mm")]
    )
    with pytest.raises(ValueError, match="inconsistent units: dataset 1 .* in m per N"):
        load_uff_frf(mixed)
    assert load_uff_frf(mixed, index=[1]).output_unit == "m"
    kinds = write_with_pyuff(
        tmp_path / "kinds.uff", [frf_set(H, f, 1), frf_set(H, f, 2, num_spec=8, num_unit="m/s^2")]
    )
    with pytest.raises(ValueError, match="inconsistent units"):
        load_uff_frf(kinds)
    grids = write_with_pyuff(tmp_path / "grids.uff", [frf_set(H, f, 1), frf_set(H, f * 2, 2)])
    with pytest.raises(ValueError, match="another frequency grid"):
        load_uff_frf(grids)
    rad = write_with_pyuff(tmp_path / "rad.uff", [frf_set(H, f, 1, x_unit="rad/s")])
    with pytest.raises(ValueError, match="frequency axis in 'rad/s'"):
        load_uff_frf(rad)
    partial = write_with_pyuff(tmp_path / "partial.uff", [frf_set(H, f, 1, 1), frf_set(H, f, 2, 2)])
    with pytest.raises(ValueError, match="layout='mimo' needs every"):
        load_uff_frf(partial, layout="mimo")
    assert load_uff_frf(partial).batch_shape == (2,)  # auto falls back to a batch
    with pytest.raises(ValueError, match="no time response"):
        load_uff_record(partial)


def test_writer_and_reader_input_checks(tmp_path):
    with pytest.raises(ValueError, match="not uniform"):
        save_uff(tmp_path / "x.uff", FRFData(np.array([1.0, 2.0, 4.0]), np.ones(3)))
    with pytest.raises(TypeError, match="Record or FRFData"):
        save_uff(tmp_path / "x.uff", {"x": np.ones(3)})
    with pytest.raises(FileNotFoundError):
        load_uff_frf(tmp_path / "missing.uff")
    bad = tmp_path / "bad.uff"
    bad.write_text("this is not a universal file\n")
    with pytest.raises(ValueError):
        load_uff_frf(bad)
    with pytest.raises(ValueError, match="layout must be"):
        load_uff_frf(bad, layout="grid")


def test_units_map_to_si(tmp_path):
    """Unit labels through the units handling (g, m/s2, mm, kN) and unlabelled axes
    through a 164 unit system (mm, N: length factor 1000), into SI, with the file's units
    in the metadata; a g-per-N accelerance and an m/s^2-per-N one load as one FRFData.
    Oracle: the values written, scaled by the unit definitions."""
    f = np.arange(1.0, 11.0)
    H = (1 + 1j) * np.linspace(1.0, 2.0, 10)
    frfs = write_with_pyuff(
        tmp_path / "g.uff",
        [frf_set(H, f, 1, num_unit="g"), frf_set(H, f, 2, num_unit="m/s2", den_unit="kN")],
    )
    frf = load_uff_frf(frfs, layout="batch")
    assert (frf.output_unit, frf.input_unit) == ("m/s^2", "N")
    np.testing.assert_allclose(frf.H[0], H * 9.80665, rtol=ASCII_RTOL)
    np.testing.assert_allclose(frf.H[1], H / 1000.0, rtol=ASCII_RTOL)
    assert dict(frf.metadata["original_units"]) == {
        "dataset 0": "g per N",
        "dataset 1": "m/s2 per kN",
    }
    t = np.arange(32) * 1e-3
    sets = [
        pyuff.prepare_164(
            units_code=5, units_description="mm-N", length=1000.0, force=1.0, temp=1.0,
            temp_offset=273.15,
        ),
    ]  # fmt: skip
    for node, spec, label in ((1, 8, "NONE"), (2, 12, "NONE"), (3, 8, "mm"), (4, 12, "EU")):
        sets.append(
            pyuff.prepare_58(
                func_type=1, rsp_node=node, rsp_dir=3, ref_node=0, ref_dir=0,
                abscissa_spacing=1, abscissa_spec_data_type=17, ordinate_spec_data_type=spec,
                orddenom_spec_data_type=0, ordinate_axis_units_lab=label,
                data=np.cos(t) + node, x=t,
            )
        )  # fmt: skip
    rec = load_uff_record(write_with_pyuff(tmp_path / "mm.unv", sets))
    assert rec.units == {"1+Z": "m", "2+Z": "m/s^2", "3+Z": "m", "4+Z": ""}
    for node in (1, 2, 3):  # mm, mm/s^2 (164 system) and a "mm" label: / 1000
        np.testing.assert_allclose(rec[f"{node}+Z"], (np.cos(t) + node) / 1000, rtol=ASCII_RTOL)
    np.testing.assert_allclose(rec["4+Z"], np.cos(t) + 4, rtol=ASCII_RTOL)  # EU: as written
    assert rec.metadata["original_units"] == {
        "1+Z": "m in UFF 164 unit system 5",
        "2+Z": "m/s^2 in UFF 164 unit system 5",
        "3+Z": "mm",
        "4+Z": "EU",
    }
    bad = sets[:1] + [dict(sets[1], ordinate_axis_units_lab="bananas")]
    with pytest.raises(ValueError, match="unknown unit 'bananas'"):
        load_uff_record(write_with_pyuff(tmp_path / "bad.unv", bad))
