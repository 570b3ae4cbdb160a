"""Issue 31: a catalogue of bad inputs for every command. Each case: exit status 2, one line on stderr saying
what is wrong (and what to do), nothing written or left behind, no work started before the check.

The commands run in this process (``simcore.cli.main``) in an empty temporary working folder; "work" is a
tripwire on each command's expensive step (rendering, filtering, Dask, the studies): a check that came after
it fails the test with "work started". Run files are rendered once per module (a few sunlit epochs).
"""
import json
import os
import shutil

import h5py
import numpy as np
import pytest

from simcore.cli import main

START = ["--start", "2016-07-02T00:45:00Z"]
TINY = START + ["--duration", "4", "--samples", "256", "256"]
PANELS = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", "examples", "cubesat3u_panels.toml")
TLE1 = "1 39161U 13021C   16209.16355149  .00000281  00000-0  53050-4 0  9997"
TLE2 = "2 39161  98.0494 293.0813 0011107  99.1953 261.0497 14.71695995172946"


# ---- fixtures: run files and input files ------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Run files: good (4 sunlit epochs), one (1 epoch), dark (20 epochs in the Earth's shadow) and corrupted
    copies of good; the input files of the other cases."""
    d = tmp_path_factory.mktemp("runs")
    cwd = os.getcwd()
    os.chdir(d)
    # one row a second, written in milliseconds: read as seconds, 1000 s apart (a warning, stored)
    (d / "att_ms.csv").write_text("t_s,qw,qx,qy,qz\n" + "\n".join(f"{1000 * i},1,0,0,0" for i in range(10)) + "\n")
    try:
        # --reflected-samples on the all-black tilt20_fov70: ignored, a warning (stored)
        assert main(["run"] + TINY + ["--reflected-samples", "1024", "-o", "good.nc"]) == 0
        assert main(["run"] + START + ["--duration", "1", "--samples", "256", "256", "--attitude", "att_ms.csv",
                     "-o", "one.nc"]) == 0
        assert main(["run", "--duration", "20", "--samples", "256", "256", "-o", "dark.nc"]) == 0
    finally:
        os.chdir(cwd)
    good = d / "good.nc"
    shutil.copy(good, d / "zeroed.nc")
    with h5py.File(d / "zeroed.nc", "r+") as f:              # a variable zeroed after sunsim wrote it
        f["irradiance"][...] = 0.0
    shutil.copy(good, d / "short.nc")
    with h5py.File(d / "short.nc", "r+") as f:               # a variable cut short: its second half lost
        a = f["irradiance"][...]
        a[a.shape[0] // 2:] = 0.0
        f["irradiance"][...] = a
    raw = good.read_bytes()
    (d / "truncated.nc").write_bytes(raw[: len(raw) // 2])   # the file cut short
    (d / "empty.nc").write_bytes(b"")
    (d / "binary.nc").write_bytes(bytes(range(256)) * 16)
    (d / "text.nc").write_text("irradiance,time\n1,2\n")
    (d / "folder.nc").mkdir()
    # input files of run / view / summary
    (d / "att.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0,0,0\n")
    (d / "att_empty.csv").write_text("")
    (d / "att_header.csv").write_text("t_s,qw,qx,qy,qz\n")
    (d / "att_cut.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0")
    (d / "att_nan.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\nnan,1,0,0,0\n")
    (d / "att_back.csv").write_text("t_s,qw,qx,qy,qz\n10,1,0,0,0\n0,1,0,0,0\n")
    (d / "att.bin").write_bytes(bytes(range(256)) * 4)
    (d / "tle_empty.tle").write_text("")
    (d / "tle_cut.tle").write_text(f"{TLE1}\n{TLE2[:40]}\n")
    (d / "tle_one.tle").write_text(f"{TLE1}\n")
    (d / "tle.bin").write_bytes(bytes(range(256)) * 4)
    (d / "cfg_empty.toml").write_text("")
    (d / "cfg_bad.toml").write_text("name = \n[body\n")
    (d / "cfg.bin").write_bytes(bytes(range(256)) * 4)
    (d / "map_empty.npz").write_bytes(b"")
    (d / "map_bad.npz").write_bytes(b"PK\x03\x04 not really a zip")
    np.savez(d / "map_nan.npz", reflectivity=np.full((180, 288), np.nan))
    np.savez(d / "map_neg.npz", reflectivity=np.full((180, 288), -0.3))
    _later_inputs(d)
    import xarray as xr
    for name, drop in (("no_t_s", "t_s"), ("no_diode_name", "diode_name"), ("no_e_sun", None)):
        ds = xr.load_dataset(good)          # an older run file (no checksums) that lacks what a format needs
        del ds.attrs["checksums"]
        ds = ds.drop_vars(drop) if drop else ds
        if drop is None:
            del ds.attrs["e_sun_w_m2"]
        ds.to_netcdf(d / f"{name}.nc", engine="h5netcdf")
    return d


def _later_inputs(d):
    """Input files of the commands and options that came after the first catalogue (issues 29 and 34): the
    flight-check's telemetry cut, emptied, made binary or moved to other days; --times files; absolute-time
    attitude CSVs and AEMs; results folders of --page."""
    from simcore.environment.telemetry import OPSSAT_ATTITUDE, OPSSAT_PD
    pd, att = OPSSAT_PD.read_text().splitlines(), OPSSAT_ATTITUDE.read_text().splitlines()
    (d / "pd_empty.csv").write_text("")
    (d / "pd.bin").write_bytes(bytes(range(256)) * 8)
    (d / "pd_header.csv").write_text(pd[0] + "\n")
    (d / "pd_cut.csv").write_text("\n".join(pd[:50]) + "\n" + pd[50][:10])
    # the same readings a year earlier: no reading falls in the attitude history
    (d / "pd_2019.csv").write_text("\n".join([pd[0]] + [r.replace("2020-", "2019-", 1) for r in pd[1:200]]) + "\n")
    (d / "grains_empty.csv").write_text("")
    (d / "grains.bin").write_bytes(bytes(range(256)) * 8)
    (d / "grains_cut.csv").write_text("\n".join(att[:200]) + "\n" + att[200][:12])
    (d / "grains_header.csv").write_text("\n".join(att[:12]) + "\n")
    t0, t1 = "2016-07-02T00:45:00Z", "2016-07-02T00:45:10Z"
    (d / "times.txt").write_text(f"{t0}\n{t1}\n")
    (d / "times_empty.txt").write_text("# no times\n")
    (d / "times_back.txt").write_text(f"{t1}\n{t0}\n")
    (d / "times_twice.txt").write_text(f"{t0}\n{t0}\n")
    (d / "times_words.txt").write_text(f"{t0}\nyesterday\n")
    (d / "times_seconds.txt").write_text("0\n10\n")
    (d / "times.bin").write_bytes(bytes(range(256)) * 4)
    head = "time_utc,qw,qx,qy,qz\n"
    (d / "abs.csv").write_text(f"{head}{t0},1,0,0,0\n{t1},1,0,0,0\n")
    (d / "abs_short_row.csv").write_text(f"{head}{t0},1,0,0,0\n{t1},1,0,0\n")
    (d / "abs_word.csv").write_text(f"{head}{t0},1,0,0,0\nsoon,1,0,0,0\n")
    (d / "abs_norm.csv").write_text(f"{head}{t0},1,0,0,0\n{t1},2,0,0,0\n")
    (d / "abs_nan.csv").write_text(f"{head}{t0},1,0,0,0\n{t1},nan,0,0,0\n")
    (d / "abs_back.csv").write_text(f"{head}{t1},1,0,0,0\n{t0},1,0,0,0\n")
    (d / "abs_itrf.csv").write_text(f"# frame: ITRF\n{head}{t0},1,0,0,0\n{t1},1,0,0,0\n")
    (d / "abs_sideways.csv").write_text(f"# direction: sideways\n{head}{t0},1,0,0,0\n{t1},1,0,0,0\n")
    aem = ("CCSDS_AEM_VERS = 1.0\nCREATION_DATE = 2020-01-01T00:00:00\nORIGINATOR = X\nMETA_START\nOBJECT_NAME = S\n"
           "OBJECT_ID = 1\nCENTER_NAME = EARTH\nREF_FRAME_A = EME2000\nREF_FRAME_B = SC_BODY_1\nATTITUDE_DIR = A2B\n"
           "TIME_SYSTEM = UTC\nSTART_TIME = 2016-07-02T00:45:00\nSTOP_TIME = 2016-07-02T00:45:10\n"
           "ATTITUDE_TYPE = QUATERNION\nMETA_STOP\nDATA_START\n2016-07-02T00:45:00 0 0 0 1\n")
    (d / "aem_cut.aem").write_text(aem + "2016-07-02T00:45:10 0 0")
    (d / "aem_empty.aem").write_text("")
    (d / "aem_header.aem").write_text("CCSDS_AEM_VERS = 1.0\nMETA_START\n")
    for name, text in (("page_bin", bytes(range(256)) * 8), ("page_json", b'{"models": '), ("page_keys", b"{}")):
        (d / name).mkdir()
        (d / name / "results.json").write_bytes(text)
    (d / "page_npz").mkdir()
    shutil.copy(os.path.join(os.path.dirname(__file__), "..", "..", "docs", "flight_opssat", "results.json"),
                d / "page_npz" / "results.json")
    (d / "page_npz" / "samples.npz").write_bytes(b"PK\x03\x04 not really a zip")


@pytest.fixture
def tripwire(monkeypatch):
    """Make each command's work fail the test if it starts."""
    def started(*a, **k):
        raise AssertionError("work started before the bad input was refused")
    import simcore.picture.view
    import simcore.pipeline.cluster
    import simcore.pipeline.evaluate
    import simcore.pipeline.evaluate_sunline
    import simcore.pipeline.run
    import simcore.pipeline.sweep
    import simcore.pipeline.spectral_check
    import simcore.studies.attitude
    import simcore.studies.coverage
    import simcore.studies.earth_band
    import simcore.studies.reproduce
    import simcore.studies.response
    import simcore.pipeline.export
    import simcore.studies.flight
    import simcore.studies.flight_page
    from estimators import attitude as mekf
    for module, name in [(simcore.pipeline.run.PreparedRun, "render_chunk"), (simcore.picture.view, "view_picture"),
                         (simcore.pipeline.cluster, "run_tasks"), (simcore.pipeline.evaluate, "evaluate_run"),
                         (simcore.pipeline.evaluate_sunline, "run_sunline_filter"), (mekf.MEKF, "__init__"),
                         (simcore.pipeline.sweep, "sweep"), (simcore.pipeline.spectral_check, "compare"),
                         (simcore.studies.attitude, "ensure_run"), (simcore.studies.coverage, "coverage_fractions"),
                         (simcore.studies.earth_band, "earth_study"), (simcore.studies.reproduce, "reproduce"),
                         (simcore.studies.response, "traced_response"), (simcore.studies.flight, "predict"),
                         (simcore.studies.flight, "fit_normals"), (simcore.studies.flight_page, "run_study"),
                         (simcore.studies.flight_page, "render_page"),
                         (simcore.studies.flight_page, "comparison_figures"),
                         (simcore.pipeline.export, "atomic_write")]:
        monkeypatch.setattr(module, name, started)


def _listing(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder) for d, ds, fs in os.walk(folder) for f in fs + ds)


def _refused(argv, words, runs, capsys, monkeypatch):
    """Run ``argv`` (RUNS/ in it names the run fixture's folder) in an empty folder: exit 2, one line, nothing left."""
    work = runs.parent / f"cwd-{abs(hash(tuple(argv))) % 10 ** 12}"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir()
    monkeypatch.chdir(work)
    argv = [a.replace("RUNS/", str(runs) + "/") for a in argv]
    before = _listing(runs)
    capsys.readouterr()
    try:
        rc = main(argv)
    except SystemExit as exc:           # argparse
        rc = exc.code
    out = capsys.readouterr()
    lines = [x for x in out.err.splitlines() if x.strip()]
    assert rc == 2, (rc, out.err)
    assert len(lines) == 1, out.err
    assert words in lines[0], lines[0]
    assert _listing(work) == [], "a refused command must leave nothing behind"
    assert _listing(runs) == before
    return lines[0]


RUN = ["run"] + TINY
TIMES = ["run", "--samples", "256", "256", "--times"]
FLIGHT = ["flight-check", "opssat"]
_OPSSAT = os.path.join(os.path.dirname(__file__), "..", "..", "simcore", "data", "flight", "opssat")
PD = os.path.join(_OPSSAT, "pd_theta_2020-11-15_to_21.csv")
GRAINS = os.path.join(_OPSSAT, "attitude_2020-11-15_to_21.csv")
BAD = [
    # ---- run: numbers, units, seeds, sample counts, conflicts
    (RUN + ["--duration", "nan"], "--duration must be a positive number of seconds"),
    (RUN + ["--duration", "inf"], "--duration must be a positive number of seconds"),
    (RUN + ["--duration", "-5"], "--duration must be a positive number of seconds"),
    (RUN + ["--duration", "1e12"], "--duration must be at most 400 days"),
    (RUN + ["--step", "0"], "--step must be a positive number of seconds"),
    (RUN + ["--step", "nan"], "--step must be a positive number of seconds"),
    (RUN + ["--seed", "-1"], "--seed must be a whole number from 0 to 2^64-1"),
    (RUN + ["--seed", str(2 ** 64)], "--seed must be a whole number from 0 to 2^64-1"),
    (RUN + ["--samples", "0", "0"], "--samples DIRECT must be 4 m^2"),
    (RUN + ["--samples", "4" + "0" * 18, "256"], "--samples DIRECT"),
    (["run"] + START + ["--accuracy", "nan", "0.01"], "--accuracy DIRECT must be a relative standard error"),
    (RUN + ["--accuracy", "0.01", "0.01"], "--accuracy and --samples both set the sample counts"),
    (RUN + ["--reflected-samples", "-4"], "--reflected-samples must be 4 m^2"),
    (RUN + ["--config", PANELS, "--reflected-samples", "1000000000000"], "beyond this machine's"),
    (RUN + ["--spin-rate", "nan"], "--spin-rate must be a finite number of deg/s"),
    (RUN + ["--spin-rate", "1e4"], "--spin-rate 10000 deg/s is faster than 360 deg/s"),
    (RUN + ["--glint", "1e6"], "--glint WIND_M_S 1e+06 m/s is above the 30 m/s"),
    (RUN + ["--glint", "-1"], "--glint WIND_M_S must be a finite wind speed >= 0"),
    (RUN + ["--glint", "nan"], "--glint WIND_M_S must be a finite wind speed >= 0"),
    (RUN + ["--attitude", "RUNS/att.csv", "--dynamics", "0.1,0.2,0.3"], "--attitude and --dynamics both set"),
    (RUN + ["--attitude", "RUNS/att.csv", "--spin-rate", "5"], "--spin-rate 5 has no effect with --attitude"),
    (RUN + ["--dynamics", "0.1,0.2"], "--dynamics"),
    (RUN + ["--dynamics", "-1,2,3"], "--dynamics"),
    (RUN + ["--chunk", "0"], "--chunk must be a positive number"),
    (RUN + ["--clouds", "-1", "--map", "ceres2018-all"], "--clouds"),
    (RUN + ["--cloud-scale-km", "500"], "--cloud-scale-km sets the size of cloud weather"),
    (RUN + ["--clouds", "1", "--map", "ceres2018-all", "--cloud-scale-km", "1e9"], "--cloud-scale-km"),
    (RUN + ["--dead", "99"], "99"),
    # ---- run: names
    (RUN + ["--config", "tilt20_fov7"], "did you mean"),
    (RUN + ["--map", "toms"], "did you mean toms2005"),
    (RUN + ["--map", "band:BPW3"], "BPW3"),
    (RUN + ["--variant", "llvm_ad_rgb"], "invalid choice"),
    (RUN + ["--satellite", "ISS"], "no satellite 'ISS'"),
    (RUN + ["--start", "yesterday"], "--start 'yesterday' is not a UTC time"),
    (RUN + ["--solar-flux", "tesis"], "did you mean 'thesis'"),
    # ---- run: input files
    (RUN + ["--attitude", "RUNS/nope.csv"], "attitude file"),
    (RUN + ["--attitude", "RUNS/att_empty.csv"], "att_empty.csv"),
    (RUN + ["--attitude", "RUNS/att_header.csv"], "att_header.csv"),
    (RUN + ["--attitude", "RUNS/att_cut.csv"], "att_cut.csv"),
    (RUN + ["--attitude", "RUNS/att_nan.csv"], "att_nan.csv"),
    (RUN + ["--attitude", "RUNS/att_back.csv"], "att_back.csv"),
    (RUN + ["--attitude", "RUNS/att.bin"], "holds binary data"),
    (RUN + ["--tle", "RUNS/nope.tle"], "nope.tle"),
    (RUN + ["--tle", "RUNS/tle_empty.tle"], "tle_empty.tle"),
    (RUN + ["--tle", "RUNS/tle_cut.tle"], "tle_cut.tle"),
    (RUN + ["--tle", "RUNS/tle_one.tle"], "tle_one.tle"),
    (RUN + ["--tle", "RUNS/tle.bin"], "tle.bin"),
    (RUN + ["--config", "RUNS/cfg_empty.toml"], "cfg_empty.toml"),
    (RUN + ["--config", "RUNS/cfg_bad.toml"], "not valid TOML"),
    (RUN + ["--config", "RUNS/cfg.bin"], "cfg.bin"),
    (RUN + ["--map", "RUNS/map_empty.npz"], "map_empty.npz"),
    (RUN + ["--map", "RUNS/map_bad.npz"], "map_bad.npz"),
    (RUN + ["--map", "RUNS/map_nan.npz"], "map_nan.npz"),
    (RUN + ["--map", "RUNS/map_neg.npz"], "map_neg.npz"),
    # ---- run: outputs
    (RUN + ["-o", "/proc/x.nc"], "cannot write /proc/x.nc"),
    (RUN + ["-o", "/sys/x.nc"], "cannot write /sys/x.nc"),
    (RUN + ["-o", "no/such/x.nc"], "does not exist"),
    (RUN + ["-o", "RUNS/folder.nc"], "is a folder"),
    # ---- validate
    (["validate", "RUNS/nope.nc"], "no run file at"),
    (["validate", "RUNS/empty.nc"], "is not a readable netCDF run file"),
    (["validate", "RUNS/binary.nc"], "is not a readable netCDF run file"),
    (["validate", "RUNS/text.nc"], "is not a readable netCDF run file"),
    (["validate", "RUNS/truncated.nc"], "is not a readable netCDF run file"),
    (["validate", "RUNS/folder.nc"], "is a folder, not a run file"),
    (["validate", "RUNS/zeroed.nc"], "the variable irradiance does not match its checksum"),
    (["validate", "RUNS/short.nc"], "the variable irradiance does not match its checksum"),
    (["validate", "RUNS/zeroed.nc", "--recompute-analytic"], "does not match its checksum"),
    # ---- estimate, every filter
    *[(["estimate", "RUNS/good.nc"] + f + ["--seed", s], "--seed must be a whole number from 0 to 2^64-1")
      for f in ([], ["--filter", "sunline-ekf"], ["--filter", "sunline-ukf"], ["--filter", "mekf"])
      for s in ("-1", str(2 ** 64))],
    *[(["estimate", "RUNS/zeroed.nc"] + f, "does not match its checksum")
      for f in ([], ["--filter", "sunline-ekf"], ["--filter", "sunline-ukf"], ["--filter", "mekf"])],
    *[(["estimate", "RUNS/one.nc", "--filter", f], "holds 1 epoch") for f in ("sunline-ekf", "sunline-ukf", "mekf")],
    *[(["estimate", "RUNS/dark.nc", "--filter", f], "has no sunlit epoch")
      for f in ("sunline-ekf", "sunline-ukf", "mekf")],
    (["estimate", "RUNS/empty.nc", "--filter", "mekf"], "is not a readable netCDF run file"),
    (["estimate", "RUNS/good.nc", "--diode", "BPW34F"], "--diode BPW34F is unknown"),
    (["estimate", "RUNS/good.nc", "--filter", "mekf", "--gyro", "ADIS1646"], "ADIS1646"),
    (["estimate", "RUNS/good.nc", "--filter", "mekf", "--magnetometer", "HMC588"], "HMC588"),
    (["estimate", "RUNS/good.nc", "--filter", "mekf", "--initial-error", "200"], "--initial-error must be an angle"),
    (["estimate", "RUNS/good.nc", "--filter", "mekf", "--initial-error", "nan"], "--initial-error must be an angle"),
    (["estimate", "RUNS/good.nc", "--filter", "sunline-ekf", "--gyro-noise", "-1"], "--gyro-noise"),
    (["estimate", "RUNS/good.nc", "--filter", "sunline-ekf", "--gyro-noise", "nan"], "--gyro-noise"),
    (["estimate", "RUNS/good.nc", "--filter", "sunline-ekf", "--faults", "garbage"], "--faults"),
    (["estimate", "RUNS/good.nc", "--filter", "sunline-ekf", "--sensor-errors", "garbage"], "--sensor-errors"),
    (["estimate", "RUNS/good.nc", "--gyro", "ADIS16460"], "only go with --filter mekf"),
    (["estimate", "RUNS/good.nc", "--filter", "mekf", "--faults", "x"], "only go with --filter sunline-ekf"),
    (["estimate", "RUNS/good.nc", "--filter", "mekff"], "did you mean 'mekf'"),
    (["estimate", "RUNS/good.nc", "--plots", "/proc/plots"], "/proc/plots"),
    # ---- attitude-study
    (["attitude-study", "--seeds", "-1"], "--seeds must be a whole number from 0 to 2^64-1"),
    (["attitude-study", "--seeds", str(2 ** 64)], "--seeds must be a whole number"),
    (["attitude-study", "--span", "short", "--workers", "0", "--no-render"], "--workers must be a whole number"),
    (["attitude-study", "--workers", "-2"], "--workers must be a whole number"),
    (["attitude-study", "--workers", "100000"], "--workers must be a whole number"),
    (["attitude-study", "--gyros", "ADIS1646"], "ADIS1646"),
    (["attitude-study", "--magnetometer", "HMC588"], "HMC588"),
    (["attitude-study", "--configs", "tilt20_fov7"], "did you mean"),
    (["attitude-study", "--span", "shrt"], "did you mean 'short'"),
    (["attitude-study", "--folder", "/proc/x"], "/proc/x"),
    (["attitude-study", "--page", "/proc/x"], "/proc/x"),
    # ---- earth-study
    (["earth-study", "--wind", "100"], "--wind 100 m/s is above the 30 m/s"),
    (["earth-study", "--wind", "-1"], "--wind"),
    (["earth-study", "--wind", "nan"], "--wind"),
    (["earth-study", "--cloud-seeds", "-1"], "--cloud-seeds must be a whole number"),
    (["earth-study", "--cloud-seeds", "1", "1"], "--cloud-seeds repeats a seed"),
    (["earth-study", "--span", "dy"], "did you mean 'day'"),
    (["earth-study", "--folder", "/proc/x"], "/proc/x"),
    # ---- reproduce
    (["reproduce", "--second-spin", "nan"], "--second-spin must be a finite number"),
    (["reproduce", "--second-spin", "1e4"], "--second-spin 10000 deg/s is faster"),
    (["reproduce", "--folder", "/proc/x"], "/proc/x"),
    (["reproduce", "--page", "/proc/x"], "/proc/x"),
    # ---- sweep
    (["sweep", "--seeds", "-1"], "--seeds must be a whole number"),
    (["sweep", "--workers", "0"], "--workers must be a whole number"),
    (["sweep", "--spin-rates", "nan"], "--spin-rates must be a finite number"),
    (["sweep", "--spin-rates", "1e5"], "--spin-rates 100000 deg/s is faster"),
    (["sweep", "--configs", "tilt20_fov7"], "did you mean"),
    (["sweep", "--starts", "yesterday"], "yesterday"),
    (["sweep", "--samples", "0", "0"], "--samples DIRECT must be 4 m^2"),
    (["sweep", "--duration", "nan"], "--duration"),
    (["sweep", "--clouds", "-1", "--map", "ceres2018-all"], "--clouds"),
    (["sweep", "--folder", "/proc/x"], "/proc/x"),
    # ---- coverage
    (["coverage", "tilt20_fov7"], "did you mean"),
    (["coverage", "tilt20_fov70", "--dead", "99"], "99"),
    (["coverage", "tilt20_fov70", "--plot-dir", "/proc/cov"], "cannot create the folder /proc/cov"),
    (["coverage", "RUNS/cfg.bin"], "cfg.bin"),
    # ---- view
    (["view", "tilt20_fov70", "--spp", "9000"], "beyond Dr.Jit's limit of 2^32-1"),
    (["view", "tilt20_fov70", "--spp", "0"], "--spp must be a positive number"),
    (["view", "tilt20_fov70", "--resolution", "0", "0"], "--resolution W H must be whole pixels"),
    (["view", "tilt20_fov70", "--resolution", "20000", "10"], "--resolution W H must be whole pixels"),
    (["view", "tilt20_fov70", "--seed", "-1"], "--seed must be a whole number"),
    (["view", "tilt20_fov70", "--time", "2016-13-02"], "2016-13-02"),
    (["view", "tilt20_fov70", "--attitude", "RUNS/att.csv", "--spin-rate", "5"], "--spin-rate 5 has no effect"),
    (["view", "tilt20_fov70", "--spin-rate", "nan"], "--spin-rate must be a finite number"),
    (["view", "tilt20_fov70", "-o", "x.jpg"], "the picture is a PNG"),
    (["view", "tilt20_fov70", "-o", "/proc/x.png"], "cannot write /proc/x.png"),
    (["view", "tilt20_fov70", "--map", "toms"], "did you mean toms2005"),
    (["view", "tilt20_fov7"], "did you mean"),
    (["view", "tilt20_fov70", "--close-up", "--clouds", "1"], "--close-up leaves out"),
    (["view", "tilt20_fov70", "--tle", "RUNS/tle.bin"], "tle.bin"),
    # ---- response
    (["response", "tilt20_fov70", "--diode", "99"], "99"),
    (["response", "tilt20_fov70", "--step", "0"], "--step"),
    (["response", "tilt20_fov70", "--step", "nan"], "--step"),
    (["response", "tilt20_fov70", "--samples", "3"], "--samples"),
    (["response", "tilt20_fov70", "--seed", "-1"], "--seed must be a whole number"),
    (["response", "tilt20_fov70", "--samples", "4000000000000"], "--samples 4000000000000 traces up to"),
    (["response", "tilt20_fov70", "--plot", "x.txt"], "give a .png or .pdf file name"),
    (["response", "tilt20_fov70", "--map-step", "0"], "--map-step"),
    (["response", "tilt20_fov70", "--variant", "cuda_rgb"], "--variant"),
    (["response", "tilt20_fov7"], "did you mean"),
    (["response", "tilt20_fov70", "--plot", "/proc/x.png"], "/proc"),
    # ---- spectral-check
    (["spectral-check", "--epochs", "0"], "--epochs must be 1 to"),
    (["spectral-check", "--samples", "10"], "--samples must be at least 64"),
    (["spectral-check", "--seed", "-1"], "--seed must be a whole number"),
    (["spectral-check", "--seed", str(2 ** 64 - 1)], "--seed (+1 for each further --diode)"),
    (["spectral-check", "--diode", "BPW3"], "BPW3"),
    (["spectral-check", "--samples", "100000000000"], "--samples 100000000000 traces up to"),
    # ---- summary
    (["summary", "--duration", "nan"], "--duration"),
    (["summary", "--step", "0"], "--step must be a positive number"),
    (["summary", "--start", "bogus"], "bogus"),
    (["summary", "--spin-rate", "1e4"], "faster than 360 deg/s"),
    (["summary", "--tle", "RUNS/tle.bin"], "tle.bin"),
    (["summary", "--tle", "RUNS/tle_empty.tle"], "tle_empty.tle"),
    (["summary", "--satellite", "ISS"], "no satellite 'ISS'"),
    # ---- flight-check (issue 29): telemetry files, the run's inputs, modes, output folders
    *[(FLIGHT + ["--pd", f"RUNS/{f}", "--attitude", GRAINS], words) for f, words in (
        ("nope.csv", "--pd"), ("pd_empty.csv", "is empty"), ("pd.bin", "holds binary data"),
        ("pd_header.csv", "no photodiode rows"), ("pd_cut.csv", "is the file truncated?"),
        ("pd_2019.csv", "are they of the same days?"), ("att.csv", "header must start TIMESTAMP,PD3,PD6"))],
    *[(FLIGHT + ["--pd", PD, "--attitude", f"RUNS/{f}"], words) for f, words in (
        ("nope.csv", "not found"), ("grains_empty.csv", "is empty"), ("grains.bin", "holds binary data"),
        ("grains_cut.csv", "is the file truncated?"), ("grains_header.csv", "truncated"),
        ("abs.csv", "not a GRAINS export"))],
    (FLIGHT + ["--pd", PD], "holds readings only; give its attitude history with --attitude"),
    (FLIGHT + ["--attitude", GRAINS], "--attitude without --pd"),
    (FLIGHT + ["--tle", "RUNS/nope.tle"], "not found"),
    (FLIGHT + ["--tle", "RUNS/tle_empty.tle"], "is not a TLE file"),
    (FLIGHT + ["--tle", "RUNS/tle.bin"], "holds binary data"),
    (FLIGHT + ["--config", "RUNS/cfg_empty.toml"], "no diodes"),
    (FLIGHT + ["--config", "RUNS/cfg_bad.toml"], "not valid TOML"),
    (FLIGHT + ["--config", "RUNS/cfg.bin"], "cfg.bin"),
    (FLIGHT + ["--map", "toms"], "did you mean toms2005"),
    (FLIGHT + ["--map", "RUNS/map_nan.npz"], "map_nan.npz"),
    (FLIGHT + ["--clouds", "-1"], "--clouds takes a cloud-weather seed"),
    (FLIGHT + ["--seed", "-1"], "--seed must be a whole number"),
    (FLIGHT + ["--plots", "/proc/plots"], "choose another --plots"),
    (FLIGHT + ["--study", "/proc/study"], "choose another --study"),
    (FLIGHT + ["--runs", "/proc/runs"], "choose another --runs"),
    (FLIGHT + ["--plots", "RUNS/att.csv"], "is a file"),
    (FLIGHT + ["--fit", "--pd", PD], "--fit calibrates on the shipped telemetry only"),
    (FLIGHT + ["--fit", "--study", "s"], "--fit ignores --study"),
    (FLIGHT + ["--study", "s", "--clouds", "1"], "--study ignores --clouds"),
    (FLIGHT + ["--study", "s", "--page", "s"], "ignores --study"),
    (FLIGHT + ["--page", "RUNS/nope"], "results.json not found; make it with"),
    (FLIGHT + ["--page", "RUNS/page_bin"], "is not a results file"),
    (FLIGHT + ["--page", "RUNS/page_json"], "is not a results file"),
    (FLIGHT + ["--page", "RUNS/page_keys"], "is not a flight-check results file (no title"),
    (FLIGHT + ["--page", "RUNS/page_npz"], "is not a readable samples file"),
    (FLIGHT + ["--page", "/proc/page"], "choose another --page"),
    (["flight-check", "opsat"], "did you mean 'opssat'"),
    (["flight-check", "ISS"], "invalid choice: 'ISS' (choose from 'opssat')"),
    # ---- export (issue 34)
    (["export", "RUNS/nope.nc", "--format", "csv"], "no run file at"),
    (["export", "RUNS/binary.nc", "--format", "csv"], "is not a readable netCDF run file"),
    (["export", "RUNS/truncated.nc", "--format", "aem"], "is not a readable netCDF run file"),
    (["export", "RUNS/folder.nc", "--format", "aem"], "is a folder, not a run file"),
    (["export", "RUNS/zeroed.nc", "--format", "csv"], "does not match its checksum"),
    (["export", "RUNS/good.nc", "--format", "cvs"], "did you mean 'csv'"),
    (["export", "RUNS/good.nc"], "the following arguments are required: --format"),
    (["export", "RUNS/good.nc", "--format", "oem"], "needs at least 8 states"),
    (["export", "RUNS/good.nc", "--format", "csv", "-o", "/proc/x.csv"], "cannot write /proc/x.csv"),
    (["export", "RUNS/good.nc", "--format", "csv", "-o", "no/such/x.csv"], "does not exist"),
    (["export", "RUNS/good.nc", "--format", "csv", "-o", "RUNS/folder.nc"], "is a folder"),
    (["export", "RUNS/good.nc", "--format", "csv", "--diode", "BPW3"], "--diode BPW3 is unknown"),
    (["export", "RUNS/good.nc", "--format", "csv", "--seed", "-1"], "--seed must be a whole number"),
    (["export", "RUNS/good.nc", "--format", "aem", "--noise"], "--format aem ignores them"),
    (["export", "RUNS/no_t_s.nc", "--format", "basilisk"], "lacks t_s, which --format basilisk needs"),
    (["export", "RUNS/no_diode_name.nc", "--format", "csv"], "lacks diode_name, which --format csv needs"),
    (["export", "RUNS/no_e_sun.nc", "--format", "basilisk"], "lacks attribute e_sun_w_m2"),
    # ---- run --times (issue 29)
    *[(TIMES + [f"RUNS/{f}"], words) for f, words in (
        ("nope.txt", "not found"), ("times_empty.txt", "no times found"), ("times.bin", "holds binary data"),
        ("times_back.txt", "must increase strictly"), ("times_twice.txt", "must increase strictly"),
        ("times_words.txt", ":2: cannot read 'yesterday' as an ISO-8601 UTC time"),
        ("times_seconds.txt", ":1: cannot read '0' as an ISO-8601 UTC time"))],
    (TIMES + ["RUNS/times.txt"] + START, "--times gives the epochs: leave out --start and --duration"),
    (TIMES + ["RUNS/times.txt", "--duration", "10"], "--times gives the epochs"),
    (TIMES + ["RUNS/times.txt", "--step", "10"], "--step 10 has no effect with --times"),
    # ---- run --attitude histories (issues 29 and 34)
    *[(["run", "--samples", "256", "256", "--attitude", f"RUNS/{f}"], words) for f, words in (
        ("abs_short_row.csv", ":3: expected 5 values"), ("abs_word.csv", ":3: cannot read 'soon'"),
        ("abs_norm.csv", "has norm 2, not 1"), ("abs_nan.csv", "is not finite"),
        ("abs_back.csv", "attitude times must increase strictly"), ("abs_itrf.csv", "unknown attitude frame 'ITRF'"),
        ("abs_sideways.csv", "unknown attitude direction 'sideways'"), ("aem_empty.aem", "is empty"),
        ("aem_header.aem", "the AEM header lacks"), ("aem_cut.aem", ":18: data line with 2 numbers"))],
    (["run", "--attitude", "RUNS/abs.csv", "--step", "5"], "--step 5 has no effect: without --start or --duration"),
    (RUN + ["--attitude", "RUNS/aem_cut.aem", "--attitude-frame", "GCRF"], "declares its frame and direction"),
    (RUN + ["--attitude", "RUNS/abs.csv", "--attitude-frame", "GCFR"], "did you mean 'GCRF'"),
    (RUN + ["--attitude", "RUNS/abs.csv", "--attitude-frame", "ITRF"], "(choose from 'GCRF', 'EME2000', 'TEME', 'TOD')"),
    (RUN + ["--attitude", "RUNS/abs.csv", "--attitude-direction", "body2frame"], "did you mean 'body_to_frame'"),
    (RUN + ["--attitude-frame", "TEME"], "--attitude-frame TEME declares the convention of an --attitude file"),
    (RUN + ["--attitude-direction", "frame_to_body"], "--attitude-direction frame_to_body declares"),
    # ---- run --eop, --orbit (issue 34; malformed OEMs: tests/environment/test_ccsds_oem.py)
    *[(RUN + ["--eop"] + v.split(), "UT1 - UTC stays within 0.9 s and the pole within 1 arcsec")
      for v in ("nan 0 0", "0 inf 0", "5 0 0", "0.1 3 0", "0.1 0 -400")],
    (RUN + ["--eop", "0.1", "0"], "expected 3 arguments"),
    (RUN + ["--orbit", "RUNS/nope.oem"], "not found"),
    (RUN + ["--orbit", "RUNS/att.bin"], "holds binary data"),
    (RUN + ["--orbit", "RUNS/times.txt", "--tle", "RUNS/tle_one.tle"], "--orbit (an ephemeris) and --tle"),
    (RUN + ["--orbit", "RUNS/times.txt", "--satellite", "ESTCUBE 1"], "--orbit (an ephemeris) and --tle"),
    # ---- any command: unknown command and option
    (["rnu"], "did you mean 'run'"),
    (["run", "--sed", "1"], "unrecognized arguments"),
]


@pytest.mark.parametrize("argv, words", BAD, ids=[" ".join(a)[:80] for a, _ in BAD])
def test_a_bad_input_is_one_line_before_any_work(argv, words, runs, capsys, monkeypatch, tripwire):
    _refused(argv, words, runs, capsys, monkeypatch)


def test_the_catalogue_fails_on_the_old_handling(runs, capsys, monkeypatch, tripwire):
    """The catalogue's checks catch the old failures: a traceback (a plain ValueError), a second line, a file
    left behind, work started."""
    import simcore.pipeline.arguments as arguments
    monkeypatch.setitem(arguments._CHECKS, "estimate", lambda args: None)      # the seed check gone
    with pytest.raises(AssertionError, match="work started"):
        _refused(["estimate", "RUNS/good.nc", "--seed", "-1"], "--seed", runs, capsys, monkeypatch)
    from simcore.errors import InvalidInputError

    def old_run(args):                      # pipeline/run.py's plain ValueError of before: a traceback
        raise ValueError("--attitude and --dynamics both set the attitude; give one of them")
    monkeypatch.setitem(arguments._CHECKS, "run", old_run)
    with pytest.raises(ValueError):
        _refused(RUN + ["--attitude", "RUNS/att.csv", "--dynamics", "0.1,0.2,0.3"], "both set", runs, capsys,
                 monkeypatch)

    def two_lines(args):                    # a note on a line of its own before the error
        print("note: something", file=__import__("sys").stderr)
        raise InvalidInputError("--seed must be a whole number")
    monkeypatch.setitem(arguments._CHECKS, "run", two_lines)
    with pytest.raises(AssertionError, match="note: something"):
        _refused(RUN + ["--seed", "-1"], "--seed", runs, capsys, monkeypatch)

    def leaves_a_file(args):                # the output folder made before the check
        os.makedirs("runs")
        raise InvalidInputError("--seed must be a whole number")
    monkeypatch.setitem(arguments._CHECKS, "run", leaves_a_file)
    with pytest.raises(AssertionError, match="leave nothing behind"):
        _refused(RUN + ["--seed", "-1"], "--seed", runs, capsys, monkeypatch)


def test_the_flight_check_catalogue_fails_on_the_old_handling(runs, capsys, monkeypatch, tripwire):
    """Without the flight-check's argument checks, an unwritable --plots folder is found only after the render
    (work started); without the model inputs read first, a bad --tle leaves the runs folder behind."""
    import simcore.pipeline.arguments as arguments
    import simcore.pipeline.preflight as preflight
    monkeypatch.setitem(arguments._CHECKS, "flight-check", lambda args: None)
    with pytest.raises(AssertionError, match="work started"):
        _refused(FLIGHT + ["--plots", "/proc/plots"], "--plots", runs, capsys, monkeypatch)
    monkeypatch.undo()                       # the tripwire's predict gone too: predict makes its folder first
    monkeypatch.setattr(preflight, "check_model_inputs", lambda *a, **k: None)
    with pytest.raises(AssertionError, match="leave nothing behind"):
        _refused(FLIGHT + ["--tle", "RUNS/tle.bin"], "tle.bin", runs, capsys, monkeypatch)


def test_an_old_run_file_without_checksums_is_used_with_a_note(runs, tmp_path, capsys):
    import xarray as xr
    ds = xr.load_dataset(runs / "good.nc")
    del ds.attrs["checksums"]
    ds.to_netcdf(tmp_path / "old.nc", engine="h5netcdf")
    capsys.readouterr()
    assert main(["validate", str(tmp_path / "old.nc")]) == 0
    err = capsys.readouterr().err
    assert "carries no checksums" in err and "used unverified" in err


def test_a_checksum_covers_every_numeric_variable(runs):
    import xarray as xr
    ds = xr.load_dataset(runs / "good.nc")
    sums = json.loads(ds.attrs["checksums"])
    numeric = sorted(n for n in ds.data_vars if ds[n].dtype.kind in "biuf")
    assert sorted(sums) == numeric and "irradiance" in sums and "q_gcrs_from_body" in sums


# ---- accepted with a warning, printed and stored (issue item 5) -----------------------------------------------
def test_attitude_times_in_milliseconds_are_a_stored_warning(runs):
    import xarray as xr
    warnings = xr.load_dataset(runs / "one.nc").attrs["warnings"]
    assert "the attitude file att_ms.csv has rows 1000 s apart" in warnings and "divide them by 1000" in warnings
    from simcore.pipeline.preflight import attitude_times_note
    assert attitude_times_note(np.arange(10.0), "a.csv") is None                # rows 1 s apart: seconds
    assert attitude_times_note(np.arange(10.0) * 100.5, "a.csv") is None        # slow but not whole: seconds
    assert attitude_times_note(1.467e12 + np.arange(10.0), "a.csv") is not None  # Unix time in ms


def test_reflected_samples_on_an_all_black_layout_are_a_stored_warning(runs):
    import xarray as xr
    warnings = xr.load_dataset(runs / "good.nc").attrs["warnings"]
    assert "--reflected-samples 1024 is ignored: every surface of tilt20_fov70 is black" in warnings


def test_the_warnings_are_printed_too(tmp_path, capsys, monkeypatch):
    from simcore.pipeline import run
    monkeypatch.setattr(run.PreparedRun, "render_chunk", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt))
    monkeypatch.chdir(tmp_path)
    assert main(["run"] + TINY + ["--reflected-samples", "1024", "-o", "r.nc"]) == 130      # stopped at the render
    assert "warning: --reflected-samples 1024 is ignored" in capsys.readouterr().err


def test_the_reflected_bound_is_the_measured_memory():
    from simcore.pipeline.preflight import check_reflected_resources, REFLECTED_BYTES_PER_LANE
    from simcore.errors import InvalidInputError
    # 64 epochs x 6 diodes x 4e6 paths x 64 B = 98 GB: refused on a 23 GB machine, accepted with 128 GB
    with pytest.raises(InvalidInputError, match="at most 1004004 here"):
        check_reflected_resources(4_000_000, 100, 6, memory_bytes=23 * 2 ** 30)
    check_reflected_resources(4_000_000, 100, 6, memory_bytes=128 * 2 ** 30)
    assert REFLECTED_BYTES_PER_LANE * 4.8e7 > (2361196 - 375044) * 1024        # the measurement it rests on
