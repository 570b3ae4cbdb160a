"""Sun-line filters on traced irradiance (simcore.pipeline.evaluate_sunline, sunsim estimate --filter): a rendered span
of the default study with a STUCK_MAX diode injected in the middle, the JSON summary, bad input.

The span: 2016-07-02T00:35Z + 600 s at 1 s, tilt20_fov70, TOMS, seed 0, all sunlit (the orbit's
Sun phase runs from 1272 s to 5027 s after 00:00Z, see ``sunsim summary``).
"""
import json

import numpy as np
import pytest

from estimators.metrics import angle_error_deg
from simcore.cli import main
from simcore.pipeline.options import RunOptions
from simcore.pipeline.run import execute
from simcore.pipeline.runfile import open_run
from simcore.sensor.errors import Fault, SensorErrors
from simcore.pipeline.evaluate_sunline import filter_run, true_rate_body, true_signals

ONSET_S = 300.0
STUCK = 9          # a -y panel diode facing away from the Sun at the onset (asserted below)


@pytest.fixture(scope="module")
def run_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("sunline") / "span.nc"
    execute(RunOptions(start="2016-07-02T00:35:00Z", duration_s=600, output=str(path)), progress=False)
    return str(path)


@pytest.fixture(scope="module")
def ds(run_path):
    return open_run(run_path)


def test_true_rate_is_the_tumble(ds):
    # the run's attitude is the default tumble: 1.9 deg/s about (1, 1, 1)/sqrt(3) in the body frame
    w = true_rate_body(ds["q_gcrs_from_body"].values, ds["t_s"].values)
    np.testing.assert_allclose(w, np.radians(1.9) * np.ones((ds.sizes["time"], 3)) / np.sqrt(3), atol=1e-9)


@pytest.mark.parametrize("kind", ["sunline-ekf", "sunline-ukf"])
def test_stuck_max_is_excluded_within_10_s_and_the_error_recovers(ds, kind):
    t = ds["t_s"].values
    assert ds["illumination"].values.min() == 1.0                      # all sunlit
    cos_at_onset = ds["sun_dir_body"].values[np.argmin(np.abs(t - ONSET_S))] @ ds["normal_body"].values[STUCK]
    assert cos_at_onset < 0.3          # the stuck reading 1.0 is far from the truth at the onset
    base, s0 = filter_run(ds, kind, return_series=True)
    out, s1 = filter_run(ds, kind, faults=[Fault(STUCK, "STUCK_MAX", ONSET_S)], return_series=True)
    assert out["first_rejection_after_onset_s"][0] is not None
    assert out["first_rejection_after_onset_s"][0] <= 10.0
    # from then on the stuck diode is out whenever its reading is far from the truth
    truth = ds["irradiance"].values.sum(axis=-1)[:, STUCK] / ds.attrs["e_sun_w_m2"]
    far = (t >= ONSET_S + 10) & (np.abs(1.0 - truth) > 0.5)
    assert far.sum() > 100
    assert s1["rejected"][far, STUCK].all()
    # and the Sun-vector error returns within its no-fault p95: every sample from onset + 10 s on
    p95 = base["sun_error_deg"]["sunlit"]["p95"]
    err = angle_error_deg(s1["sun_dir_body"], s1["sun_true"])
    assert np.all(err[t >= ONSET_S + 10] <= p95), (err[t >= ONSET_S + 10].max(), p95)
    # WLS, which has no innovation test, is pulled far away by the same fault
    assert out["compare"]["wls"]["sun_error_deg"]["sunlit"]["max"] > 3 * p95


def test_cli_filter_json(run_path, capsys):
    rc = main(["estimate", run_path, "--filter", "sunline-ukf", "--faults", f"STUCK_MAX@{STUCK}:{ONSET_S:g}",
               "--sensor-errors", "white=0.005,gm=0.005:300,walk=0.001:0.01,seed=1", "--gyro-noise", "0.01", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["filter"] == "sunline-ukf"
    for block in (out["sun_error_deg"], out["rate_error_deg_s"]):
        assert set(block["sunlit"]) >= {"mean", "p95", "max"}
        assert block["sunlit"]["n"] == 600
    assert out["faults"] == [{"diode": STUCK, "kind": "STUCK_MAX", "onset_s": ONSET_S, "end_s": None}]
    assert out["sensor_errors"]["white"] == 0.005 and out["gyro_sigma_deg_s"] == 0.01
    assert {"wls", "sun_albedo_sun"} <= set(out["compare"])
    # with a gyro of 0.01 deg/s the rate error is of that order, not of the 1.9 deg/s tumble
    assert out["rate_error_full_deg_s"]["sunlit"]["p95"] < 0.05


def test_cli_filter_text(run_path, capsys):
    assert main(["estimate", run_path, "--filter", "sunline-ekf"]) == 0
    text = capsys.readouterr().out
    assert "sunline-ekf" in text and "wls" in text and "sun_albedo_sun" in text


@pytest.mark.parametrize("extra, message", [
    (["--faults", "STUCK_HIGH@2:100"], "unknown fault 'STUCK_HIGH'; use one of OFF, STUCK_CURRENT"),
    (["--faults", "OFF@2:900"], "onset 900 s lies outside the run (0 .. 599 s since its start)"),
    (["--sensor-errors", "white=-0.01"], "white must be >= 0"),
    (["--sensor-errors", "walk=0.001:-0.01"], "the walk bound must be >= 0, got -0.01"),
    (["--gyro-noise", "-0.1"], "--gyro-noise must be the gyro's noise standard deviation, > 0 deg/s"),
])
def test_cli_bad_input_is_one_line_exit_2(run_path, capsys, extra, message):
    rc = main(["estimate", run_path, "--filter", "sunline-ekf", *extra])
    captured = capsys.readouterr()
    assert rc == 2
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sunsim estimate: error:") and message in lines[0]
    assert "Traceback" not in captured.err


def test_cli_fault_without_filter_is_refused(run_path, capsys):
    assert main(["estimate", run_path, "--faults", "OFF@2:100"]) == 2
    assert "go with --filter" in capsys.readouterr().err


def test_misalignment_moves_the_direct_part_by_the_cosine_law(ds):
    # a diode well inside its FOV is fully lit: its direct irradiance is E_sun cos(theta), so turning its
    # normal from n to n' changes it by E_sun (n' - n) . s (closed form, independent of the aperture code)
    e = SensorErrors(misalign_deg=1.0, seed=3)
    u, normals_true = true_signals(ds, e)
    u0, normals_nom = true_signals(ds, SensorErrors())
    sun = ds["sun_dir_body"].values
    angle_true = np.degrees(np.arccos(np.clip(sun @ normals_true.T, -1, 1)))
    angle_nom = np.degrees(np.arccos(np.clip(sun @ normals_nom.T, -1, 1)))
    inside = (angle_true < 60) & (angle_nom < 60)
    assert inside.sum() > 1000
    sun_factor = (ds["sun_scale"].values * ds["illumination"].values)[:, None]    # 1 here; (1 AU / r)^2 if scaled
    expected = (sun @ (normals_true - normals_nom).T * sun_factor)[inside]
    np.testing.assert_allclose((u - u0)[inside], expected, atol=1e-12)
    # the angles moved by about a degree (Rayleigh, scale 1 deg: mean 1.25 deg)
    moved = np.degrees(np.arccos(np.clip(np.sum(normals_true * normals_nom, axis=1), -1, 1)))
    assert 0.1 < moved.mean() < 3.0



def test_basilisk_response_replaces_the_traced_direct_part(ds):
    # Basilisk coarseSunSensor.cpp computeTrueOutput: E_sun x (c if c >= cos(fov) else 0) x (1 - exp(-c^p / kappa))
    # x sunDistanceFactor x shadowFactor (our sun_scale and illumination: 1 and 1 in this span)
    e_sun = ds.attrs["e_sun_w_m2"] * (ds["sun_scale"].values * ds["illumination"].values)[:, None]
    sun, normals = ds["sun_dir_body"].values, ds["normal_body"].values
    c = sun @ normals.T
    cut = np.where(c >= np.cos(np.radians(70.0)), c, 0.0)
    irr = ds["irradiance"].values
    for kappa, fit in ((0.1, 1 - np.exp(-c ** 2 / 0.1)), (0.0, 1.0)):
        u, _ = true_signals(ds, SensorErrors(kelly=kappa))
        np.testing.assert_allclose(u * ds.attrs["e_sun_w_m2"], e_sun * cut * fit + irr[..., 1], rtol=1e-12,
                                   atol=1e-9)
    # against the traced optics: the same to the Monte-Carlo noise well inside the FOV, different at its edge
    # (the well lets light in up to 83 deg, Basilisk cuts at 70) -- the comparison this option is for
    u0, _ = true_signals(ds, SensorErrors(kelly=0.0))
    traced = irr.sum(axis=-1) / ds.attrs["e_sun_w_m2"]
    inner = c > np.cos(np.radians(60.0))
    edge = (c < np.cos(np.radians(72.0))) & (c > np.cos(np.radians(80.0)))
    assert np.abs(u0 - traced)[inner].max() < 0.01
    assert np.abs(u0 - traced)[edge].max() > 0.02


def test_user_alignment_moves_only_that_diode_by_the_cosine_law(ds):
    # Issue 33 item 6: align=DIODE:DTHETA:DPHI turns one diode as Basilisk's
    # setUnitDirectionVectorWithPerturbation; inside its FOV the direct part moves by E_sun (n' - n) . s.
    k = 2
    u, normals_true = true_signals(ds, SensorErrors(align=((k, 1.0, -0.5),)))
    u0, normals_nom = true_signals(ds, SensorErrors())
    n = normals_nom[k]
    theta, phi = np.arctan2(n[1], n[0]) + np.radians(1.0), np.arcsin(n[2]) + np.radians(-0.5)
    np.testing.assert_allclose(normals_true[k], [np.cos(phi) * np.cos(theta), np.cos(phi) * np.sin(theta),
                                                 np.sin(phi)], atol=1e-12)
    others = np.arange(len(normals_nom)) != k
    np.testing.assert_array_equal(u[:, others], u0[:, others])
    sun = ds["sun_dir_body"].values
    inside = (sun @ normals_true[k] > np.cos(np.radians(60))) & (sun @ n > np.cos(np.radians(60)))
    assert inside.sum() > 50
    sun_factor = ds["sun_scale"].values * ds["illumination"].values
    np.testing.assert_allclose((u - u0)[inside, k], (sun @ (normals_true[k] - n) * sun_factor)[inside], atol=1e-12)


def test_cli_use_threshold_and_process_noise_reach_the_filter(run_path, capsys):
    # Issue 33 item 6: Basilisk's sun-line filters take sensorUseThresh and the process noise as inputs.
    base = filter_run(open_run(run_path), "sunline-ekf")
    rc = main(["estimate", run_path, "--filter", "sunline-ekf", "--use-threshold", "0.45",
               "--process-noise", "1e-9:1e-5", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert (out["use_threshold"], out["q_rate"], out["q_sun"]) == (0.45, 1e-9, 1e-5)
    assert out["sun_error_deg"] != base["sun_error_deg"]
    assert base["q_rate"] == 1e-13 and base["use_threshold"] < 0.05     # the defaults: 5 sigma of the noise


@pytest.mark.parametrize("extra, message", [
    (["--filter", "sunline-ekf", "--process-noise", "1e-9:x"], "--process-noise '1e-9:x': give Q_RATE[:Q_SUN]"),
    (["--filter", "sunline-ekf", "--use-threshold", "1.5"], "--use-threshold must be a reading in [0, 1)"),
    (["--filter", "mekf", "--use-threshold", "0.3"], "--use-threshold only go with --filter sunline-ekf"),
])
def test_cli_bad_filter_tuning_is_one_line_exit_2(run_path, capsys, extra, message):
    assert main(["estimate", run_path, *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
