"""sunsim estimate --filter mekf: the acceptance on the default orbit, and user mistakes."""
import json

import numpy as np
import pytest

from simcore.cli import main


@pytest.mark.parametrize("args, words", [
    (["--filter", "mekf", "--gyro", "BMG16"], ["unknown gyro 'BMG16'", "did you mean BMG160"]),
    (["--filter", "mekf", "--gyro", "mpu3300"], ["unknown gyro", "did you mean MPU-3300"]),
    (["--filter", "mekf", "--magnetometer", "HMC5833L"], ["unknown magnetometer", "did you mean HMC5883L"]),
    (["--gyro", "BMG160"], ["add --filter mekf"]),
])
def test_unknown_sensor_names_get_one_line_before_any_work(tmp_path, capsys, args, words):
    # The run file does not even exist: the names are checked first.
    rc = main(["estimate", str(tmp_path / "missing.nc")] + args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "Traceback" not in err[0]
    for w in words:
        assert w in err[0], err[0]


def test_unknown_filter_is_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["estimate", "x.nc", "--filter", "mekff"])
    assert exc.value.code == 2 and "invalid choice: 'mekff'" in capsys.readouterr().err


@pytest.fixture(scope="module")
def default_orbit(tmp_path_factory):
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import execute
    path, _, _ = execute(RunOptions(output=str(tmp_path_factory.mktemp("mekf") / "orbit.nc")), progress=False)
    return path


def test_default_orbit_mekf_with_bmg160_meets_the_issue_targets(default_orbit, capsys, tmp_path):
    # Issue 16's acceptance: `sunsim run` (default orbit) then
    # `sunsim estimate RUN --filter mekf --gyro BMG160 --json`: sunlit mean <= 1 deg, p95 <= 2 deg,
    # eclipse p95 <= 5 deg (targets of the issue; RAX flew 0.5 deg 1 sigma with the same sensor set).
    rc = main(["estimate", default_orbit, "--filter", "mekf", "--gyro", "BMG160", "--json",
               "--plots", str(tmp_path / "plots")])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    a = out["attitude_error_deg"]
    assert a["sunlit"]["n"] > 3000 and a["eclipse"]["n"] > 500
    assert a["sunlit"]["mean"] <= 1.0 and a["sunlit"]["p95"] <= 2.0
    assert a["eclipse"]["p95"] <= 5.0
    assert 0.0 <= out["nees_in_bounds"] <= 1.0
    assert out["sun_updates"] > 3000 and out["mag_updates"] > 4000
    # Issue 33 item 4: the Sun-vector noise derived (chain + on-board albedo model, coloured): the NIS of the
    # accepted Sun updates within 30 % of 2 (2 dof) and the sunlit NEES within 30 % of 3 (3 dof). The told
    # 0.5 deg white noise before gave NIS 0.16-0.23.
    assert out["sun_noise"]["model"] == "derived"
    assert out["sun_nis_mean"] == pytest.approx(2.0, rel=0.3)
    assert out["nees_mean_sunlit"] == pytest.approx(3.0, rel=0.3)
    assert all((tmp_path / "plots" / f).exists() for f in ("attitude_error.png", "nees.png"))


def test_mekf_on_rendered_data_converges_from_30_deg(default_orbit):
    from simcore.pipeline.evaluate_attitude import run_mekf
    from simcore.pipeline.runfile import open_run
    res = run_mekf(open_run(default_orbit), default_orbit, gyro="BMG160", initial_error_deg=30.0)
    assert res["summary"]["initial_error_deg"] == pytest.approx(30.0, abs=1e-6)
    t_conv = res["summary"]["time_to_converge_s"]
    assert t_conv is not None and t_conv < 1800.0      # starts in eclipse: magnetometer + gyro bring it in
    e = res["error_deg"]
    assert np.nanmedian(e[res["t_s"] > 2000]) < 1.0
    # The filter never saw the truth: its estimate is not the truth either.
    assert np.nanmin(e) > 0
