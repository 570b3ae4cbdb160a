"""Issue 11: every user mistake gets one line on stderr and exit status 2, before anything is written,
and the corrected command then succeeds; honest inputs; a real bug keeps its traceback.

Each case runs the command line in a fresh temporary working directory (never the checkout) and checks
that a rejected command leaves that directory exactly as it found it. The corrected commands render a
few sunlit epochs with few samples: seconds each.
"""
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

SUNSIM = [sys.executable, "-m", "simcore.cli"]
# Four sunlit epochs (the default start is in eclipse), the smallest sample counts the renderer takes.
TINY = ["--start", "2016-07-02T00:45:00Z", "--duration", "4", "--samples", "256", "256"]


# What a command-line user cannot type: a keyword argument (verify_checksum=False) or a call (quat_normalize()).
PYTHON_CALL = re.compile(r"\b[a-z][a-z_]*=[\w'\"]|[a-z_]\(\)")


def _sunsim(args, cwd, **kw):
    return subprocess.run(SUNSIM + list(args), capture_output=True, text=True, timeout=600, cwd=cwd, **kw)


def _listing(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder) for d, ds, fs in os.walk(folder) for f in fs + ds)


def _one_line_error(r, words):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1, r.stderr
    assert words in lines[0], lines[0]
    return lines[0]


def _case(tmp_path, bad, good, words):
    """Run the mistaken command (one line, exit 2, nothing left behind), then the corrected one (exit 0)."""
    before = _listing(tmp_path)
    line = _one_line_error(_sunsim(bad, tmp_path), words)
    assert _listing(tmp_path) == before, "a rejected command must leave nothing behind"
    ok = _sunsim(good, tmp_path)
    assert ok.returncode == 0, ok.stderr
    return line


def _cuda_works():
    from simcore.render.launch import _cuda_works
    return _cuda_works()        # imports Dr.Jit through simcore._llvm, its libLLVM set first


# ---- item 3 and 5: every argument checked before the output path is touched ------------------------------
@pytest.mark.parametrize("bad, good, words", [
    (["--samples", "0", "0"], ["--samples", "256", "256"], "--samples DIRECT must be 4 m^2"),
    (["--samples", "-4", "-4"], ["--samples", "256", "256"], "--samples DIRECT must be 4 m^2"),
    (["--samples", "256", "255"], ["--samples", "256", "256"], "--samples ALBEDO must be an even number"),
    (["--samples", "16", "4"], ["--samples", "256", "256"], "below 256 the standard errors are not reliable"),
    (["--reflected-samples", "0"], ["--reflected-samples", "256"], "--reflected-samples must be 4 m^2"),
    (["--reflected-samples", "100"], ["--reflected-samples", "576"], "--reflected-samples must be 4 m^2"),
    (["--reflected-samples", "64"], ["--reflected-samples", "1024"], "below 256 the standard errors are not reliable"),
    (["--seed", str(2 ** 64)], ["--seed", str(2 ** 64 - 1)], "--seed must be a whole number from 0 to 2^64-1"),
    (["--seed", "-1"], ["--seed", "1"], "--seed must be a whole number from 0 to 2^64-1"),
    (["--config", "tilt20_fov7"], ["--config", "tilt20_fov70"], "did you mean"),
    (["--map", "missing.npz"], ["--map", "toms2005"], "reflectivity map file missing.npz not found"),
    (["--map", "toms"], ["--map", "toms2005"], "did you mean toms2005"),
    (["--step", "10", "--duration", "5"], ["--step", "1", "--duration", "5"], "--step (10 s) is longer than --duration"),
    (["--satellite", "ISS"], ["--satellite", "39161"], "no satellite 'ISS'"),
    (["--dead"] + [str(i) for i in range(14)], ["--dead", "0"], "all 14 diodes of tilt20_fov70 are dead"),
    (["--chunk", "0"], ["--chunk", "2"], "--chunk must be a positive number"),
    (["--start", "yesterday"], ["--start", "2016-07-02T00:45:00Z"], "--start 'yesterday' is not a UTC time"),
    (["-o", "/proc/x.nc"], ["-o", "x.nc"], "cannot write /proc/x.nc"),
    (["-o", "no/such/folder/x.nc"], ["-o", "x.nc"], "does not exist"),
])
def test_a_rejected_run_leaves_nothing_and_the_corrected_one_succeeds(tmp_path, bad, good, words):
    # The mistaken option comes after TINY, so it overrides TINY's value of the same option.
    line = _case(tmp_path, ["run"] + TINY + bad, ["run"] + TINY + good, words)
    assert not PYTHON_CALL.search(line), "no Python keyword arguments or calls in a CLI message"


def test_an_impossible_accuracy_is_one_line(tmp_path):
    base = ["run", "--start", "2016-07-02T00:45:00Z", "--duration", "4"]     # --accuracy applies without --samples
    _case(tmp_path, base + ["--accuracy", "0", "0"], base + ["--accuracy", "0.05", "0.2"],
          "--accuracy DIRECT must be a relative standard error")


def test_a_cuda_variant_without_a_gpu_is_one_line(tmp_path):
    if _cuda_works():
        pytest.skip("this machine has a working CUDA GPU: --variant cuda_ad_mono is then valid")
    _case(tmp_path, ["run"] + TINY + ["--variant", "cuda_ad_mono"], ["run"] + TINY + ["--variant", "llvm_ad_mono"],
          "--variant cuda_ad_mono needs a working CUDA GPU")


def test_a_binary_attitude_file_is_one_line(tmp_path):
    (tmp_path / "att.bin").write_bytes(bytes(range(256)) * 4)
    (tmp_path / "att.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0,0,0\n")
    _case(tmp_path, ["run"] + TINY + ["--attitude", "att.bin"], ["run"] + TINY + ["--attitude", "att.csv"],
          "att.bin is not an attitude CSV file (it holds binary data)")


def test_a_missing_attitude_file_is_not_found(tmp_path):
    (tmp_path / "att.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0,0,0\n")
    _case(tmp_path, ["run"] + TINY + ["--attitude", "nope.csv"], ["run"] + TINY + ["--attitude", "att.csv"],
          "attitude file nope.csv not found")


def test_an_unnormalised_attitude_suggests_no_python_call(tmp_path):
    (tmp_path / "bad.csv").write_text("t_s,qw,qx,qy,qz\n0,2,0,0,0\n10,2,0,0,0\n")
    (tmp_path / "att.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0,0,0\n")
    line = _case(tmp_path, ["run"] + TINY + ["--attitude", "bad.csv"], ["run"] + TINY + ["--attitude", "att.csv"],
                 "has norm 2")
    assert "quat_normalize" not in line and not PYTHON_CALL.search(line)


def test_a_tle_checksum_error_suggests_no_python_keyword(tmp_path):
    # ESTCube-1's shipped TLE with the last digit of line 2 changed from 6 to 7: the checksum fails.
    l1 = "1 39161U 13021C   16209.16355149  .00000281  00000-0  53050-4 0  9997"
    l2 = "2 39161  98.0494 293.0813 0011107  99.1953 261.0497 14.71695995172946"
    (tmp_path / "bad.tle").write_text(f"{l1}\n{l2[:-1]}7\n")
    (tmp_path / "good.tle").write_text(f"{l1}\n{l2}\n")
    line = _case(tmp_path, ["run"] + TINY + ["--tle", "bad.tle"], ["run"] + TINY + ["--tle", "good.tle"],
                 "fails its checksum")
    assert "verify_checksum" not in line and not PYTHON_CALL.search(line)
    # the check itself catches the messages of before (issue 11)
    assert PYTHON_CALL.search("(or pass verify_checksum=False if you edited it on purpose)")
    assert PYTHON_CALL.search("or normalise deliberately with quat_normalize()")


@pytest.mark.parametrize("bad, good, words", [
    (["--spp", "0"], ["--spp", "1"], "--spp must be a positive number"),
    (["--resolution", "0", "0"], ["--resolution", "16", "9"], "--resolution W H must be whole pixels"),
    (["--time", "2016-13-02"], ["--time", "2016-07-02T01:00:00Z"], "cannot read '2016-13-02' as a UTC time"),
    (["--map", "toms"], ["--map", "toms2005"], "did you mean toms2005?"),
    (["--close-up", "--map", "uniform:0.3"], ["--close-up"], "--close-up leaves out"),
    (["--config", "tilt0_fov90"], ["--config", "tilt20_fov70"], "two configurations given"),
])
def test_view_mistakes_are_one_line(tmp_path, bad, good, words):
    base = ["view", "tilt20_fov70", "-o", "pic.png", "--spp", "1", "--resolution", "16", "9"]
    _case(tmp_path, base + bad, base + good, words)
    assert (tmp_path / "pic.png").stat().st_size > 0


def test_an_uncreatable_figure_folder_is_one_line(tmp_path):
    _case(tmp_path, ["coverage", "tilt0_fov90", "--plot-dir", "/proc/cov"], ["coverage", "tilt0_fov90", "--plot-dir", "cov"],
          "cannot create the folder /proc/cov")
    assert os.listdir(tmp_path / "cov") == ["coverage_tilt0_fov90.png"]


def test_a_sweep_is_checked_before_any_worker_starts(tmp_path):
    base = ["sweep", "--starts", "2016-07-02T00:45:00Z", "--duration", "4", "--workers", "1", "--folder", "sw"]
    _case(tmp_path, base + ["--samples", "0", "0"], base + ["--samples", "256", "256"], "--samples DIRECT must be 4 m^2")
    assert (tmp_path / "sw" / "sweep.nc").exists()

def test_a_sweeps_reflected_samples_are_checked_before_any_worker_starts(tmp_path):
    base = ["sweep", "--starts", "2016-07-02T00:45:00Z", "--duration", "4", "--workers", "1", "--folder", "sw"]
    _one_line_error(_sunsim(base + ["--reflected-samples", "-4"], tmp_path), "--reflected-samples must be 4 m^2")
    assert _listing(tmp_path) == []


# ---- item 6: honest inputs ----------------------------------------------------------------------------
def test_a_map_far_above_one_needs_an_explicit_flag(tmp_path):
    from simcore.environment.maps import named_map
    toms = named_map("toms2005")
    np.savez(tmp_path / "x10.npz", reflectivity=10 * toms.values)     # a map scaled by mistake
    line = _case(tmp_path, ["run"] + TINY + ["--map", "x10.npz"],
                 ["run"] + TINY + ["--map", "x10.npz", "--allow-bright-map"], "--allow-bright-map")
    assert "reaches 10.74" in line           # 10 x the TOMS 2005 maximum, 1.07398 (the shipped file)
    # The shipped maps themselves pass (TOMS 2005's ice reaches 1.07).
    from simcore.pipeline.preflight import check_map
    check_map(toms)


def test_a_start_far_from_the_tle_epoch_is_a_warning_with_the_sgp4_error(tmp_path):
    from simcore.environment.orbit import Orbit
    from simcore.environment.epochs import Epochs
    from simcore.pipeline.preflight import tle_age_note
    # The default study starts 25.16 days before its TLE's epoch (16209.16355149 = 2016-07-27T03:55:30.8Z,
    # line 1 columns 19-32): no warning, and the run file states the age.
    orbit = Orbit.default()
    assert tle_age_note(orbit, Epochs.from_any(["2016-07-02T00:00:00Z"])) is None
    r = _sunsim(["run", "--start", "2016-09-30T00:45:00Z", "--duration", "4", "--samples", "256", "256",
                 "-o", "late.nc"], tmp_path)
    assert r.returncode == 0, r.stderr
    # 2016-09-30T00:45Z - 2016-07-27T03:55:30.848Z = 64 d 20 h 49 min 29.152 s = 64.8677 days
    assert "warning: the span reaches +64.9 days from the epoch of the TLE" in r.stderr
    assert "1-3 km per day" in r.stderr
    ds = xr.load_dataset(tmp_path / "late.nc")
    assert abs(ds.attrs["tle_age_days"] - 64.86770) < 1e-5 and "1-3 km per day" in ds.attrs["warnings"]


def test_a_span_entirely_in_eclipse_says_no_sunlit_data(tmp_path):
    # 2016-07-02T00:00Z is in the Earth's umbra until 1263 s (sunsim summary's eclipse events; the
    # beta-angle 8.9 deg orbit spends 35.7 % in umbra).
    r = _sunsim(["run", "--duration", "20", "--samples", "256", "256", "-o", "dark.nc"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "analytic check: no sunlit data" in r.stdout and "PASS" not in r.stdout
    v = _sunsim(["validate", "dark.nc"], tmp_path)
    assert v.returncode == 1 and "no sunlit data" in v.stdout and "PASS" not in v.stdout and "nan" not in v.stdout
    e = _sunsim(["estimate", "dark.nc"], tmp_path)
    assert e.returncode == 1 and "no sunlit data" in e.stdout and "nan" not in e.stdout


# ---- item 2: a second plain run succeeds ----------------------------------------------------------------
def test_default_outputs_repeat_and_never_collide(tmp_path):
    first = _sunsim(["run"] + TINY, tmp_path)
    assert first.returncode == 0, first.stderr
    again = _sunsim(["run"] + TINY, tmp_path)
    assert again.returncode == 0 and "already finished with identical settings" in again.stderr
    other = _sunsim(["run"] + TINY + ["--seed", "7"], tmp_path)
    assert other.returncode == 0 and "runs/default-2.nc" in other.stdout
    assert sorted(os.listdir(tmp_path / "runs")) == ["default-2.nc", "default.nc"]
    # An explicit output made with other settings is replaced only on request.
    clash = _sunsim(["run"] + TINY + ["--seed", "8", "-o", "runs/default.nc"], tmp_path)
    _one_line_error(clash, "exists and was made with other settings; add --overwrite")
    assert _sunsim(["run"] + TINY + ["--seed", "8", "-o", "runs/default.nc", "--overwrite"], tmp_path).returncode == 0
    assert xr.load_dataset(tmp_path / "runs" / "default.nc").attrs["seed"] == 8


# ---- item 3: resume with another --chunk; a crash in the final write -------------------------------------
SMALL = ["run", "--start", "2016-07-02T00:45:00Z", "--duration", "12", "--samples", "256", "256"]


def test_a_resume_with_another_chunk_size_renders_only_the_rest(tmp_path):
    from simcore.cli import build_parser, run_options
    from simcore.pipeline.run import PreparedRun
    from simcore.pipeline.store import ChunkStore
    out = str(tmp_path / "r.nc")
    opts = run_options(build_parser().parse_args(SMALL + ["--chunk", "5", "-o", out]))
    study = PreparedRun(opts)
    store = ChunkStore(out, opts.spec()).open()
    store.save(0, 5, study.render_chunk(0, 5))            # what a run killed after one chunk of 5 leaves
    store.close()
    resumed = _sunsim(SMALL + ["--chunk", "4", "-o", out], tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming: 5 of 12 epochs" in resumed.stderr
    straight = _sunsim(SMALL + ["-o", str(tmp_path / "s.nc")], tmp_path)
    assert straight.returncode == 0, straight.stderr
    a, b = xr.load_dataset(out), xr.load_dataset(tmp_path / "s.nc")
    for name in ("irradiance", "irradiance_se", "samples", "analytic"):
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert sorted(os.listdir(tmp_path)) == ["r.nc", "s.nc"]


def test_a_crash_in_the_final_write_leaves_nothing_a_resume_does_not_clean(tmp_path):
    # The process dies (os._exit, like SIGKILL: no clean-up handlers) just before the final rename.
    crash = ("import os, sys\n"
             "import simcore.pipeline.store as rs\n"
             "real = rs.os.replace\n"
             "def dying(src, dst):\n"
             "    if dst.endswith('r.nc'):\n"
             "        os._exit(9)\n"
             "    real(src, dst)\n"
             "rs.os.replace = dying\n"
             "from simcore.cli import main\n"
             "main(sys.argv[1:])\n")
    r = subprocess.run([sys.executable, "-c", crash] + SMALL + ["-o", "r.nc"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 9, r.stderr
    assert os.listdir(tmp_path) == ["r.nc.partial"]          # the temporary lies inside the partial folder
    assert any(".tmp-" in f for f in os.listdir(tmp_path / "r.nc.partial"))
    again = _sunsim(SMALL + ["-o", "r.nc"], tmp_path)
    assert again.returncode == 0, again.stderr
    assert os.listdir(tmp_path) == ["r.nc"]


# ---- item 4: a lock on the output ------------------------------------------------------------------------
def test_a_second_process_on_the_same_output_is_refused_while_the_first_runs(tmp_path):
    # The first process is this test, holding the output the way a running 'sunsim run' does (a killed
    # owner's lock vanishes with it: tests/system/test_run.py's resume after SIGKILL goes through the same lock).
    from simcore.cli import build_parser, run_options
    from simcore.pipeline.store import ChunkStore
    args = ["run"] + TINY + ["-o", "r.nc"]
    opts = run_options(build_parser().parse_args(args))
    first = ChunkStore(str(tmp_path / "r.nc"), opts.spec()).open()
    before = _listing(tmp_path)
    line = _one_line_error(_sunsim(args, tmp_path), "r.nc is being written by another sunsim process")
    assert f"(pid {os.getpid()})" in line
    assert _listing(tmp_path) == before
    first.close()
    later = _sunsim(args, tmp_path)                      # the same command once the first has ended
    assert later.returncode == 0, later.stderr
    assert os.listdir(tmp_path) == ["r.nc"]


# ---- item 5: a real bug keeps its traceback; --debug shows a user error's --------------------------------
def test_a_real_bug_keeps_its_traceback(monkeypatch):
    import simcore.pipeline.run
    from simcore import cli

    def broken(*a, **k):
        raise ValueError("an internal bug")
    monkeypatch.setattr(simcore.pipeline.run, "execute", broken)
    with pytest.raises(ValueError, match="an internal bug"):
        cli.main(["run"])


def test_debug_shows_the_traceback_of_a_user_error(tmp_path):
    r = _sunsim(["run", "--config", "tilt20_fov7", "--debug"], tmp_path)
    assert r.returncode == 1 and "Traceback" in r.stderr and "ConfigError" in r.stderr


# ---- item 7: run files users can trust ------------------------------------------------------------------
def test_run_files_describe_themselves(tmp_path):
    old = os.umask(0o022)
    try:
        r = _sunsim(["run"] + TINY + ["-o", "r.nc"], tmp_path)
    finally:
        os.umask(old)
    assert r.returncode == 0, r.stderr
    assert (os.stat(tmp_path / "r.nc").st_mode & 0o777) == 0o644       # 0666 & ~0022, not mkstemp's 0600
    ds = xr.load_dataset(tmp_path / "r.nc")
    for name, var in ds.variables.items():
        assert "long_name" in var.attrs, name
        if var.dtype.kind in "fiu":
            assert "units" in var.attrs, name
    assert "UTC" in ds["time"].attrs["long_name"] and ds.attrs["time_scale"] == "UTC"
    assert ds.attrs["command_line"].endswith("run " + " ".join(TINY) + " -o r.nc")
    import simcore
    assert ds.attrs["sunsim_version"].startswith(simcore.__version__)
    created = np.datetime64(ds.attrs["created_utc"].rstrip("Z"))
    assert abs(created - np.datetime64("now")) < np.timedelta64(600, "s")
    assert abs(ds.attrs["tle_age_days"] - (-25.16355149 + 45 / 1440)) < 1e-6   # 00:45 after 2016-07-02
