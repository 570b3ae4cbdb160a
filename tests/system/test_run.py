"""The main job end to end: a killed run resumes to exactly the numbers of an uninterrupted one,
and user mistakes get one clear line and a non-zero exit, never a traceback."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import xarray as xr

SUNSIM = [sys.executable, "-m", "simcore.cli"]
# A short sunlit stretch (the default start is in eclipse), few samples: seconds per chunk.
SMALL = ["run", "--start", "2016-07-02T00:45:00Z", "--duration", "24", "--chunk", "4", "--samples", "256", "256"]


def _sunsim(args, **kw):
    return subprocess.run(SUNSIM + args, capture_output=True, text=True, timeout=600, **kw)


def test_killed_run_resumes_to_identical_numbers(tmp_path):
    # (the analytic check's verdict is not this test's business: with seed 0 the check's hint-free direct estimate
    # at epoch 16 of diode 2 reads > 4 standard errors high on 56-57 of 200 seeds, with TEA or SplitMix random
    # numbers alike, where 1024 samples miss a sliver of shadow the probes do not find; SplitMix's seed 0 is one)
    small = SMALL + ["--no-fail-on-check"]
    out = str(tmp_path / "killed.nc")
    log = open(tmp_path / "killed.log", "w+")
    proc = subprocess.Popen(SUNSIM + small + ["-o", out], stdout=subprocess.DEVNULL, stderr=log)
    partial = out + ".partial"
    deadline = time.time() + 300
    while time.time() < deadline:
        done = [f for f in os.listdir(partial)] if os.path.isdir(partial) else []
        if sum(f.startswith("chunk_") and f.endswith(".npz") for f in done) >= 2:
            break
        if proc.poll() is not None:
            log.seek(0)
            pytest.fail("the run finished before it could be killed: " + log.read()[-2000:])
        time.sleep(0.05)
    else:
        proc.kill()
        pytest.fail("no chunk was written within 300 s")
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    log.close()
    assert not os.path.exists(out), "a killed run must leave nothing under the final name"
    n_before = len([f for f in os.listdir(partial) if f.startswith("chunk_")])
    assert 2 <= n_before < 6

    resumed = _sunsim(small + ["-o", out])
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming" in resumed.stderr
    assert not os.path.exists(partial)

    whole = str(tmp_path / "whole.nc")
    straight = _sunsim(small + ["-o", whole])
    assert straight.returncode == 0, straight.stderr

    a, b = xr.load_dataset(out), xr.load_dataset(whole)
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert a.attrs["options"] == b.attrs["options"]
    assert float(a["irradiance"].sel(component="direct").max()) > 100  # sunlit: real numbers compared


@pytest.mark.parametrize("args, words", [
    (["run", "--config", "tilt20_fov7"], "did you mean"),
    (["run", "--start", "2016-02-30T00:00:00Z"], "day is out of range"),
    (["run", "--duration", "-5"], "--duration"),
    (["run", "--start", "1980-01-01T00:00:00Z"], "epoch of the TLE"),
    (["run", "-o", "/nonexistent-folder/x.nc"], "does not exist"),
    (["coverage", "tilt25_fov7O"], "did you mean"),
])
def test_user_mistakes_get_one_clear_line(args, words, tmp_path):
    r = _sunsim(args, cwd=tmp_path)      # never in the checkout: a default output would land in its runs/
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0], r.stderr


def test_corrupt_and_foreign_run_files_are_refused(tmp_path):
    junk = tmp_path / "junk.nc"
    junk.write_bytes(os.urandom(4096))
    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"x": ("t", np.arange(3.0))}).to_netcdf(foreign, engine="h5netcdf")
    for path, words in ((junk, "not a readable netCDF"), (foreign, "not a sunsim run file")):
        for cmd in ("validate", "estimate"):
            r = _sunsim([cmd, str(path)])
            assert r.returncode == 2 and "Traceback" not in r.stderr
            assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_user_attitude_history_drives_the_study(tmp_path):
    # A history holding the body at a fixed 90 deg turn about GCRS z: body x must point along GCRS y at
    # every epoch (the quaternion (cos 45, 0, 0, sin 45) rotates x onto y).
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import PreparedRun
    csv = tmp_path / "att.csv"
    q = [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]
    csv.write_text("t_s,qw,qx,qy,qz\n" + "".join(f"{t},{q[0]},{q[1]},{q[2]},{q[3]}\n" for t in (0.0, 100.0)))
    study = PreparedRun(RunOptions(start="2016-07-02T00:45:00Z", duration_s=50, attitude_file=str(csv),
                             output=str(tmp_path / "a.nc")))
    np.testing.assert_allclose(study.geometry.R_gcrs_from_body[:, :, 0], np.tile([0.0, 1.0, 0.0], (50, 1)), atol=1e-12)
    with pytest.raises(ValueError, match="outside|span"):
        PreparedRun(RunOptions(start="2016-07-02T00:45:00Z", duration_s=500, attitude_file=str(csv),
                               output=str(tmp_path / "b.nc")))
    # a relative-time history carries no date: without --start it is refused (it once rendered 2016-07-02 silently)
    with pytest.raises(ValueError, match="relative times .* give --start"):
        PreparedRun(RunOptions(duration_s=50, attitude_file=str(csv), output=str(tmp_path / "c.nc")))


def test_a_north_first_map_renders_the_same_earth_as_south_first(tmp_path):
    # Oracle: one physical Earth described in both row orders (lat_deg says which) must give the same
    # rendered and analytic albedo, sample for sample. Before the fix the renderer read row 0 of a
    # north-first map as the southern band and rendered a mirrored Earth.
    from simcore.environment.maps import named_map
    toms = named_map("toms2005")
    south = tmp_path / "south.npz"
    north = tmp_path / "north.npz"
    np.savez(south, reflectivity=toms.values, lat_deg=toms.lat_deg, lon_deg=toms.lon_deg)
    np.savez(north, reflectivity=toms.values[::-1], lat_deg=toms.lat_deg[::-1], lon_deg=toms.lon_deg)
    # A sunlit span over the northern hemisphere's asymmetric albedo (2016-07-02 05:40 UTC).
    base = ["run", "--start", "2016-07-02T05:40:00Z", "--duration", "12", "--samples", "256", "256"]
    out = {}
    for name, path in (("south", south), ("north", north)):
        res = _sunsim(base + ["--map", str(path), "-o", str(tmp_path / f"{name}.nc")])
        assert res.returncode in (0, 1), res.stderr
        with xr.open_dataset(tmp_path / f"{name}.nc") as ds:
            out[name] = (ds["irradiance"].sel(component="albedo").values, ds["analytic"].sel(component="albedo").values)
    assert np.nanmax(out["south"][0]) > 1.0                     # the span does see the Earth
    np.testing.assert_array_equal(out["north"][0], out["south"][0])
    np.testing.assert_allclose(out["north"][1], out["south"][1], rtol=1e-12, atol=1e-12)
    # and the mirrored Earth (north-first values read as south-first) is visibly another one
    mirrored = tmp_path / "mirrored.npz"
    np.savez(mirrored, reflectivity=toms.values[::-1], lat_deg=toms.lat_deg, lon_deg=toms.lon_deg)
    res = _sunsim(base + ["--map", str(mirrored), "-o", str(tmp_path / "mirrored.nc")])
    with xr.open_dataset(tmp_path / "mirrored.nc") as ds:
        m = ds["irradiance"].sel(component="albedo").values
    assert np.nanmax(np.abs(m - out["south"][0])) > 0.5


def test_default_solar_flux_is_the_measured_tsi_with_inverse_square_and_thesis_flux_stays_available(tmp_path):
    # Oracle: the irradiance of sunlight at the satellite is TSI x (1 AU / r)^2 with TSI = 1361 W/m^2
    # (IAU 2015 Resolution B3; Kopp & Lean 2011 measured 1360.8 +- 0.5) and r the Earth-Sun distance
    # from NREL's SPA (pvlib, an independent implementation; the satellite's parallax adds < 1e-4).
    # The thesis' Sun is a constant 1366.1 W/m^2 (sec. 2.3.2). Same seed: same rays, so the two
    # rendered direct irradiances differ by exactly that ratio, epoch by epoch.
    import pandas as pd
    from pvlib.solarposition import nrel_earthsun_distance
    base = ["run", "--start", "2016-07-02T05:40:00Z", "--duration", "6", "--samples", "256", "256"]
    assert _sunsim(base + ["-o", str(tmp_path / "phys.nc")]).returncode == 0
    assert _sunsim(base + ["--solar-flux", "thesis", "-o", str(tmp_path / "thesis.nc")]).returncode == 0
    with xr.open_dataset(tmp_path / "phys.nc") as p, xr.open_dataset(tmp_path / "thesis.nc") as t:
        assert p.attrs["e_sun_w_m2"] == 1361.0 and t.attrs["e_sun_w_m2"] == 1366.1
        times = pd.DatetimeIndex(p["time"].values).tz_localize("UTC")
        d_au = nrel_earthsun_distance(times).values
        expect = 1361.0 / d_au ** 2 / 1366.1                          # (N,) physical / thesis
        dp = p["irradiance"].sel(component="direct").values
        dt = t["irradiance"].sel(component="direct").values
        lit = dt > 10.0
        assert lit.sum() > 10
        ratio = dp[lit] / dt[lit]
        np.testing.assert_allclose(ratio, np.broadcast_to(expect[:, None], dp.shape)[lit], rtol=2e-4)
        assert abs((1.0 / d_au ** 2).mean() - 0.9674) < 0.001        # early July, near aphelion (1.0167 AU)


def test_an_attitude_file_with_another_time_origin_starts_at_the_run_start(tmp_path):
    # Attitude.from_file promises "any origin": rows at t = 1000 .. 1100 s describe the run's first 100 s.
    # The history turns about GCRS z at 0.01 rad/s from the identity, so body x must lie at the angle
    # 0.01 t in the GCRS x-y plane at run time t (SLERP is exact for a constant-rate turn about a fixed axis).
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import PreparedRun
    w = 0.01
    csv = tmp_path / "att.csv"
    rows = [(1000.0 + t, np.cos(w * t / 2), 0.0, 0.0, np.sin(w * t / 2)) for t in np.arange(0.0, 101.0, 10.0)]
    csv.write_text("t_s,qw,qx,qy,qz\n" + "".join(",".join(repr(float(x)) for x in r) + "\n" for r in rows))
    study = PreparedRun(RunOptions(start="2016-07-02T00:45:00Z", duration_s=50, attitude_file=str(csv)))
    t = np.arange(50.0)
    np.testing.assert_allclose(study.geometry.R_gcrs_from_body[:, :, 0],
                               np.column_stack([np.cos(w * t), np.sin(w * t), np.zeros(50)]), atol=1e-12)


def test_a_partial_run_of_an_older_chunk_layout_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    # A run interrupted after two chunks leaves them in OUT.partial; a chunk written by an older sunsim
    # (here: one array removed) must not be mixed with new ones: one line, exit 2, nothing rendered.
    from simcore import cli
    from simcore.pipeline import run as R
    from simcore.pipeline.runfile import CHUNK_ARRAYS
    out = str(tmp_path / "old.nc")
    real, calls = R.PreparedRun.render_chunk, []

    def stop_after_two(self, start, stop):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(start)
        data = real(self, start, stop)
        assert set(data) == set(CHUNK_ARRAYS)         # the layout the resume check expects
        return data
    monkeypatch.setattr(R.PreparedRun, "render_chunk", stop_after_two)
    assert cli.main(SMALL + ["-o", out]) != 0                # "sunsim: interrupted"
    chunks = sorted(f for f in os.listdir(out + ".partial") if f.startswith("chunk_"))
    assert len(chunks) == 2
    first = os.path.join(out + ".partial", chunks[0])
    with np.load(first) as z:
        arrays = {k: z[k] for k in z.files if k != "analytic_albedo_native_mesh"}
    with open(first, "wb") as f:
        np.savez(f, **arrays)
    calls.clear()
    capsys.readouterr()
    assert cli.main(SMALL + ["-o", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "older sunsim" in err[0] and "analytic_albedo_native_mesh" in err[0], err
    assert calls == [] and len(os.listdir(out + ".partial")) >= 2 and not os.path.exists(out)


def test_a_reader_that_stops_early_gets_no_traceback(tmp_path):
    # `sunsim validate RUN | head -1`: the pipe closes while sunsim still writes; it must stop quietly.
    # (Without the handler in simcore.cli.main this fails: BrokenPipeError traceback from print.)
    out = str(tmp_path / "tiny.nc")
    assert _sunsim(["run", "--start", "2016-07-02T00:45:00Z", "--duration", "4", "-o", out]).returncode == 0
    for args in (["validate", out], ["estimate", out]):
        proc = subprocess.Popen(SUNSIM + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        proc.stdout.close()                 # the reader goes away before sunsim writes (its start takes seconds)
        err = proc.stderr.read()
        proc.stderr.close()
        proc.wait(timeout=600)
        assert "Traceback" not in err and "BrokenPipeError" not in err, err
        assert proc.returncode == 141, (proc.returncode, err)    # stopped by the closed pipe, not another error
