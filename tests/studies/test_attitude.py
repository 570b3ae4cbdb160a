"""sunsim attitude-study on a short span: Dask tasks, the page, the tables."""
import json

from simcore.cli import main


def test_attitude_study_short_span_writes_the_page(tmp_path, capsys):
    rc = main(["attitude-study", "--span", "short", "--folder", str(tmp_path), "--configs", "tilt20_fov70",
               "--gyros", "BMG160", "L3G4200D", "--seeds", "0", "1", "--workers", "1", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rows"] == 1 * 2 * 2 * 2
    page = tmp_path / "attitude_short"
    res = json.loads((page / "results.json").read_text())
    assert {r["gyro"] for r in res["rows"]} == {"BMG160", "L3G4200D"}
    text = (page / "README.md").read_text()
    assert "| tilt20_fov70 |" in text and "With the on-board albedo prediction" in text
    assert (page / "sunlit_p95.png").exists() and (page / "series_tilt20_fov70_BMG160" / "attitude_error.png").exists()
    # Two seeds draw two different gyros: the rows differ.
    a = [r["sunlit_mean"] for r in res["rows"] if r["gyro"] == "BMG160" and r["onboard_albedo"]]
    assert len(a) == 2 and a[0] != a[1]


def test_attitude_study_rejects_an_unknown_gyro_before_rendering(tmp_path, capsys):
    rc = main(["attitude-study", "--span", "short", "--folder", str(tmp_path), "--gyros", "BMG-160"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "did you mean BMG160" in err[0]
    assert not any(tmp_path.iterdir())
