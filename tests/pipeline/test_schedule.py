"""Runs at explicit, irregular epochs and runs driven by a recorded attitude history (simcore.pipeline.schedule):
the same epochs give the same numbers however they are given, a killed irregular run resumes to identical
numbers, untrusted attitude is left out (never interpolated), and mistakes get one line."""
import numpy as np
import pytest
import xarray as xr

from simcore import cli
from simcore.environment.attitude import tumble
from simcore.environment.epochs import Epochs
from simcore.environment.history import AttitudeHistory
from simcore.pipeline import run as R
from simcore.pipeline.options import RunOptions
from simcore.pipeline.run import PreparedRun, execute

START = "2016-07-02T00:45:00Z"            # sunlit (tests/system/test_run.py's SMALL)
FAST = dict(rel_se_direct=None, rel_se_albedo=None, direct_samples=256, albedo_samples=256, seed=5)
ARRAYS = ("irradiance", "irradiance_se", "irradiance_dof", "samples", "analytic", "analytic_reference",
          "direct_plain", "sun_dir_body", "q_gcrs_from_body", "valid", "sun_normal_irradiance")


def _same(a, b, idx_a=slice(None), idx_b=slice(None), rtol=0.0):
    for v in ARRAYS:
        if rtol:
            np.testing.assert_allclose(a[v].values[idx_a], b[v].values[idx_b], rtol=rtol, atol=1e-9, err_msg=v)
        else:
            np.testing.assert_array_equal(a[v].values[idx_a], b[v].values[idx_b], err_msg=v)


@pytest.fixture(scope="module")
def regular(tmp_path_factory):
    out = tmp_path_factory.mktemp("reg") / "regular.nc"
    _, ds, report = execute(RunOptions(start=START, duration_s=6, output=str(out), **FAST))
    assert report["pass"]
    return ds


def test_explicit_epochs_equal_the_regular_run_bit_for_bit(regular, tmp_path):
    grid = Epochs.range(START, 6, 1.0)
    _, ds, report = execute(RunOptions(epochs=grid, output=str(tmp_path / "e.nc"), **FAST))
    assert report["pass"] and ds.attrs["epochs_source"] == "times"
    _same(ds, regular)


def test_irregular_epochs_render_in_one_run_and_match_where_their_index_coincides(regular, tmp_path):
    # epochs 0 and 1 of the regular run, then irregular ones (2.5 s, 7.25 s, 31 s): one run. The renderer's random
    # numbers are keyed by the epoch's index in the run: where the index and the epoch coincide they are the
    # regular run's draws; elsewhere other draws (agreeing within the standard errors). Not bit for bit: the
    # epochs come from ISO strings (1e-12 s from the grid's sums) and the precession-nutation and Sun series are
    # evaluated per epoch for 5 epochs but interpolated on a 1-h grid for 6 (frames.smooth_on_grid, ~1e-14 rad):
    # the geometry differs at 1e-9 relative, the float32 render at 1e-7, the degrees of freedom at 2e-6.
    t = np.array([0.0, 1.0, 2.5, 7.25, 31.0])
    times = tmp_path / "times.txt"
    times.write_text("# irregular\n" + "\n".join((Epochs.from_any(START) + t).iso()) + "\n")
    assert cli.main(["run", "--times", str(times), "--samples", "256", "256", "--seed", "5",
                     "-o", str(tmp_path / "i.nc")]) == 0
    with xr.open_dataset(tmp_path / "i.nc") as ds:
        np.testing.assert_allclose(ds["t_s"].values, t, atol=1e-6)
        _same(ds.load(), regular, slice(0, 2), slice(0, 2), rtol=1e-5)
        assert ds.attrs["check_pass"] == 1


def test_a_killed_irregular_run_resumes_to_identical_numbers(tmp_path, monkeypatch):
    epochs = Epochs.from_any(START) + np.array([0.0, 3.0, 4.5, 20.0, 21.0, 50.0])
    opts = RunOptions(epochs=epochs, chunk_epochs=2, output=str(tmp_path / "k.nc"), **FAST)
    _, whole, _ = execute(RunOptions(epochs=epochs, chunk_epochs=6, output=str(tmp_path / "w.nc"), **FAST))
    real, calls = R.PreparedRun.render_chunk, []

    def stop_after_one(self, start, stop):
        if calls:
            raise KeyboardInterrupt
        calls.append(start)
        return real(self, start, stop)
    monkeypatch.setattr(R.PreparedRun, "render_chunk", stop_after_one)
    with pytest.raises(KeyboardInterrupt):
        execute(opts)
    monkeypatch.setattr(R.PreparedRun, "render_chunk", real)
    log = []
    _, resumed, _ = execute(opts, log=log.append)
    assert any("resuming: 2 of 6" in m for m in log), log
    _same(resumed, whole)


def _history_csv(path, t, q, frame="GCRF"):
    AttitudeHistory(Epochs.from_any(START) + t, q, frame=frame).to_csv(path)


def test_an_absolute_history_alone_sets_the_epochs_and_gaps_are_left_out(tmp_path, capsys):
    # samples every 2 s from START, none between 6 s and 46 s (a 40-s gap): without --start/--duration the run
    # renders at the trusted samples, never inside the gap
    t = np.r_[0.0:8.0:2.0, 46.0:50.0:2.0]
    q = tumble(t, rate_deg_s=1.0).q_gcrs_from_body
    p = tmp_path / "h.csv"
    _history_csv(p, t, q)
    study = PreparedRun(RunOptions(attitude_file=str(p), output=str(tmp_path / "x.nc")))
    np.testing.assert_allclose(study.geometry.t_s, t - t[0], atol=1e-6)
    # a regular grid over the span leaves the gap out (counted), not interpolated
    study = PreparedRun(RunOptions(attitude_file=str(p), step_s=1.0, duration_s=48.0))
    kept = study.geometry.t_s
    assert kept.size == 7 + 2 and not np.any((kept > 6.5) & (kept < 45.5))
    assert any("left out 39 of 48 epochs" in n for n in study.plan.notes)
    # rendered: the file says where the epochs came from and what full Sun is
    assert cli.main(["run", "--attitude", str(p), "--samples", "256", "256", "-o", str(tmp_path / "h.nc")]) == 0
    with xr.open_dataset(tmp_path / "h.nc") as ds:
        assert ds.sizes["time"] == 6 and ds.attrs["epochs_source"] == "attitude samples"
        assert "1 gaps" in ds.attrs["attitude_history"]
        # 1361 W/m^2 x (1 AU / r)^2 in sunlight: early July r = 1.0167 AU (aphelion; pvlib's NREL SPA gives
        # 1.01668 on 2016-07-02), the satellite's parallax < 1e-4
        lit = ds["illumination"].values == 1
        assert lit.all()
        np.testing.assert_allclose(ds["sun_normal_irradiance"].values, 1361.0 / 1.01668 ** 2, rtol=2e-4)


def test_a_history_spanning_exactly_the_run_and_its_span_as_default_duration(tmp_path):
    t = np.arange(0.0, 926.0, 5.0)                   # 0 .. 925 s
    q = tumble(t, rate_deg_s=1.0).q_gcrs_from_body
    rel = tmp_path / "rel.csv"
    rel.write_text("t_s,qw,qx,qy,qz\n" + "".join(f"{a!r},{b!r},{c!r},{d!r},{e!r}\n" for a, (b, c, d, e)
                                               in zip((t + 0.1).tolist(), q.tolist())))
    study = PreparedRun(RunOptions(start=START, duration_s=925.0, step_s=5.0, attitude_file=str(rel)))
    assert len(study.epochs) == 185
    study = PreparedRun(RunOptions(start=START, step_s=5.0, attitude_file=str(rel)))   # no --duration: the span
    assert len(study.epochs) == 185 and study.geometry.t_s[-1] == pytest.approx(920.0)


def test_frame_declared_on_the_command_line(tmp_path):
    t = np.arange(0.0, 20.0, 5.0)
    q = np.tile([1.0, 0, 0, 0], (4, 1))
    rel = tmp_path / "rel.csv"
    rel.write_text("t_s,qw,qx,qy,qz\n" + "".join(f"{a},1,0,0,0\n" for a in t))
    from simcore.environment import frames
    study = PreparedRun(RunOptions(start=START, attitude_file=str(rel), attitude_frame="TOD"))
    e = study.epochs
    np.testing.assert_allclose(study.geometry.R_gcrs_from_body, frames.R_between("tod", "gcrs", e), atol=1e-12)
    assert q.shape == (4, 4)


@pytest.mark.parametrize("args,words", [
    (["--attitude", "rel.csv"], "relative times (t_s) and no date: give --start"),
    (["--times", "times.txt", "--start", START], "leave out --start and --duration"),
    (["--times", "bad.txt"], "bad.txt:2: cannot read 'yesterday'"),
    (["--times", "back.txt"], "must increase strictly"),
])
def test_mistakes_are_one_line(tmp_path, monkeypatch, capsys, args, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rel.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n10,1,0,0,0\n")
    (tmp_path / "times.txt").write_text(START + "\n")
    (tmp_path / "bad.txt").write_text(START + "\nyesterday\n")
    (tmp_path / "back.txt").write_text("2016-07-02T00:45:10Z\n" + START + "\n")
    assert cli.main(["run"] + args + ["--samples", "256", "256", "-o", "o.nc"]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "o.nc").exists()


def test_run_help_states_the_quaternion_convention(capsys):
    with pytest.raises(SystemExit):
        cli.main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "scalar first, in GCRF, and rotates body vectors into the frame (v_frame = R(q) v_body)" in text
    assert "--attitude-frame {GCRF,EME2000,TEME,TOD}" in text and "frame_to_body: v_body = R(q) v_frame" in text


def test_in_process_history_at_the_telemetrys_own_times():
    # what `flight-check` does: the OPS-SAT week's attitude, rendered at the photodiode stamps where it is trusted
    from simcore.environment.telemetry import OPSSAT_TLE, read_opssat_attitude, read_opssat_pd
    from simcore.pipeline.schedule import plan
    from simcore.pipeline.store import spec_digest
    h = read_opssat_attitude()
    pd = read_opssat_pd()
    keep = h.trusted(pd.epochs)
    first_day = np.flatnonzero(keep)[:200]
    opts = RunOptions(config="tilt0_fov90", tle=str(OPSSAT_TLE), attitude_history=h, epochs=pd.epochs[first_day])
    p = plan(opts)
    assert len(p.epochs) == 200 and p.source == "times" and p.notes == (h.summary(),)
    # the rendered attitude is the history's, in GCRS: the recorded quaternion is EME2000 -> body
    from simcore.environment import frames
    from simcore.environment.attitude import quat_to_matrix
    R_body_from_eme = quat_to_matrix(h.q_frame_at(p.epochs)).transpose(0, 2, 1)
    np.testing.assert_allclose(p.attitude.R_body_from_gcrs,
                               R_body_from_eme @ frames.R_between("gcrs", "eme2000", p.epochs), atol=1e-12)
    # untrusted stamps are left out and counted, never interpolated
    p2 = plan(RunOptions(tle=str(OPSSAT_TLE), attitude_history=h, epochs=pd.epochs[:400]))
    left = int((~keep[:400]).sum())
    assert left > 1 and len(p2.epochs) == 400 - left
    # the first stamp, 00:34:04, comes 0.529 s before the first attitude sample: outside the span, left out
    assert p2.notes[1].startswith("left out 1 of 400 epochs outside the attitude history's span")
    assert p2.notes[2].startswith(f"left out {left - 1} of 399 epochs without a trusted attitude")
    # the settings digest follows the history's content and the epochs
    d1 = spec_digest(opts.spec())
    other = AttitudeHistory(h.epochs, h.q_frame_from_body[:, [0, 1, 3, 2]], frame=h.frame, source=h.source)
    import dataclasses
    assert spec_digest(dataclasses.replace(opts, attitude_history=other).spec()) != d1
    assert spec_digest(dataclasses.replace(opts, epochs=pd.epochs[first_day[:-1]]).spec()) != d1


def test_the_check_reference_of_an_epoch_does_not_depend_on_its_chunk():
    # A resumed run must read the numbers an unbroken one does (test above), so each epoch's analytic reference must
    # not depend on which epochs share its chunk: bit for bit, whole span against chunks of 7 and of 1. Before the
    # direct reference's sums and dot products were written out term by term (shapes.occlusion.row_dot), numpy's
    # einsum and matmul rounded 14 of these 4200 direct values differently in chunks of 7 (at 7e92237); before the
    # albedo kernel's runs were added as a running sum, 3 albedo values differed in chunks of 1.
    st = PreparedRun(RunOptions(start=START, duration_s=300.0, seed=1))
    n = len(st.epochs)
    whole = st.reference.analytic(slice(0, n), st.map_refined, mesh=True)
    for size in (7, 1):
        parts = [st.reference.analytic(slice(i, min(i + size, n)), st.map_refined, mesh=True) for i in range(0, n, size)]
        for name in ("direct_w_m2", "albedo_w_m2"):
            np.testing.assert_array_equal(np.vstack([getattr(p, name) for p in parts]), getattr(whole, name),
                                          err_msg=f"{name}, chunks of {size}")
