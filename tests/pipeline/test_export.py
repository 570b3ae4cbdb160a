"""``sunsim export``: the readings CSV against the thesis' sensor-chain equations written out here, the AEM read
back to the run's attitude, the Basilisk values against coarseSunSensor's formula; bad input gets one line."""
import csv

import numpy as np
import pytest
import xarray as xr

from simcore.cli import main
from simcore.environment import ccsds
from simcore.environment.epochs import Epochs
from simcore.sensor.chain import DIODES


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import execute
    path = tmp_path_factory.mktemp("export") / "run.nc"
    execute(RunOptions(start="2016-07-02T00:45:00Z", duration_s=80, step_s=10.0, rel_se_direct=None,
                       rel_se_albedo=None, direct_samples=256, albedo_samples=256, dead=(4,), output=str(path)))
    return str(path)


def _table(path):
    with open(path) as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    return rows


def test_readings_csv_follows_the_sensor_chain_equations(run_file, tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert main(["export", run_file, "--format", "csv", "-o", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    rows = _table(out)
    ds = xr.load_dataset(run_file)
    e = ds.irradiance.sum("component").values
    assert len(rows) == ds.sizes["time"] == 8
    d = DIODES["BPW34FS"]
    # thesis eqs. 4.16-4.19 and 4.24: I = R A E_S0 E / 1366.1 W/m^2 + I_D (25 degC, no errors); counts =
    # round(I R_F (2^11 - 1) / 1 V), R_F = 500 ohm, clipped to 0 .. 2047; a dead diode reads 0
    current = d.responsivity_a_w * d.area_m2 * d.e_s0_w_m2 * e / 1366.1 + d.dark_current_a
    counts = np.clip(np.rint(current * 500.0 * 2047 / 1.0), 0, 2047)
    counts[:, 4] = 0
    for i, row in enumerate(rows):
        assert row["time_utc"] == ccsds.format_epochs(Epochs.from_datetime64(ds.time.values))[i]
        for k in range(ds.sizes["diode"]):
            assert float(row[f"E_W_m2_d{k}"]) == e[i, k]
            assert float(row[f"adc_counts_d{k}"]) == counts[i, k]
            if k != 4:
                assert float(row[f"photocurrent_A_d{k}"]) == pytest.approx(current[i, k], rel=1e-12)
    assert counts.max() > 500                                           # sunlit: real readings compared


def test_aem_export_reads_back_to_the_run_attitude(run_file, tmp_path):
    out = tmp_path / "a.aem"
    assert main(["export", run_file, "--format", "aem", "-o", str(out)]) == 0
    ds = xr.load_dataset(run_file)
    ep = Epochs.from_datetime64(ds.time.values)
    got = ccsds.read_aem(out).attitude_at(ep).q_gcrs_from_body
    want = ds.q_gcrs_from_body.values
    sign = np.sign(np.sum(got * want, axis=1))[:, None]
    np.testing.assert_allclose(got * sign, want, atol=1e-12)


def test_basilisk_export_is_coarse_sun_sensors_convention(run_file, tmp_path):
    # coarseSunSensor.cpp: cos x (1 AU / r)^2 x shadow + albedoAtInstrument, the albedo a ratio to the solar flux
    # at the instrument (albedo.cpp): with the run's E_1AU and sun_scale = (1 AU / r)^2
    out = tmp_path / "b.csv"
    assert main(["export", run_file, "--format", "basilisk", "-o", str(out)]) == 0
    ds = xr.load_dataset(run_file)
    e1, scale = float(ds.attrs["e_sun_w_m2"]), ds.sun_scale.values
    irr = ds.irradiance
    rows = _table(out)
    for i, row in enumerate(rows):
        for k in range(ds.sizes["diode"]):
            direct = float(irr[i, k].sel(component="direct")) / e1
            alb = float(irr[i, k].sel(component="albedo")) / (e1 * scale[i])
            refl = float(irr[i, k].sel(component="reflected")) / e1
            assert float(row[f"cos_value_d{k}"]) == pytest.approx(direct + alb + refl, rel=1e-14, abs=1e-300)
        assert int(row["sim_nanos"]) == round(float(ds.t_s[i]) * 1e9)
    # a diode facing the Sun at 1 AU reads ~1 (the run: July, 1.0167 AU, so ~0.967)
    assert 0.9 < max(float(r[f"cos_value_d{k}"]) for r in rows for k in range(ds.sizes["diode"])) < 1.05


def test_oem_export_reads_back_to_the_run_orbit(run_file, tmp_path):
    from simcore.environment.ephemeris import EphemerisOrbit
    out = tmp_path / "o.oem"
    assert main(["export", run_file, "--format", "oem", "-o", str(out)]) == 0
    ds = xr.load_dataset(run_file)
    st = EphemerisOrbit.from_file(out).propagate(Epochs.from_datetime64(ds.time.values))
    np.testing.assert_allclose(st.r_gcrs_m, ds.r_sat_gcrs.values, atol=1e-6)     # at its nodes: the states


def test_bad_export_input_gets_one_line(run_file, tmp_path, capsys):
    junk = tmp_path / "junk.nc"
    junk.write_text("not a run")
    assert main(["export", str(junk), "--format", "csv"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a readable netCDF run file" in err
    assert main(["export", run_file, "--format", "aem", "-o", str(tmp_path / "no" / "x.aem")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "does not exist" in err
    assert main(["export", run_file, "--format", "csv", "--diode", "XYZ", "-o", str(tmp_path / "x.csv")]) == 2
    assert "--diode XYZ is unknown" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()
