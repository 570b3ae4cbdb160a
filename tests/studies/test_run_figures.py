"""Issue 11 item 9: figures land beside their run (or in runs/), never in the current directory; their
titles say what produced them; the estimator error plots of one run share one y range."""
import os
import subprocess
import sys

import numpy as np
import pytest

from simcore.plots import shared_error_ylim

SUNSIM = [sys.executable, "-m", "simcore.cli"]


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    # 60 sunlit s of the default study, one dead diode, few samples.
    folder = tmp_path_factory.mktemp("fig")
    r = subprocess.run(SUNSIM + ["run", "--start", "2016-07-02T00:45:00Z", "--duration", "60", "--samples", "256", "256",
                                 "--dead", "3", "-o", "r.nc"], cwd=folder, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return folder / "r.nc"


def test_error_plots_land_beside_the_run_with_one_range_and_telling_titles(run_file, tmp_path):
    import xarray as xr
    from simcore.pipeline.evaluate import evaluate_run
    from simcore.studies.run_figures import default_plot_folder, write_error_plots
    ds = xr.load_dataset(run_file)
    errs, _, extra = evaluate_run(ds, noise=True)
    figs = write_error_plots(ds, errs, extra["sunlit"], default_plot_folder(run_file), noise=True)
    assert {os.path.basename(p) for p, _ in figs} == {f"error_{k}.png" for k in errs}
    assert all(os.path.dirname(p) == str(run_file.parent / "r_plots") for p, _ in figs)
    ylims = {fig.axes[0].get_ylim() for _, fig in figs}
    assert len(ylims) == 1
    titles = {os.path.basename(p): fig.get_suptitle() for p, fig in figs}
    t = titles["error_sun_albedo_sun.png"]
    for words in ("tilt20_fov70", "dead diodes 3", "Sun-Albedo-Sun, started from Albedo-Sun", "with sensor noise",
                  "2016-07-02T00:45:00Z .. 2016-07-02T00:45:59Z (59 s)"):
        assert words in t, t
    assert "pseudoinverse" in titles["error_pinv.png"]


def test_estimate_plots_default_beside_the_run_file(run_file, tmp_path):
    r = subprocess.run(SUNSIM + ["estimate", str(run_file), "--plots"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    assert os.listdir(tmp_path) == []
    assert "error_pinv.png" in os.listdir(run_file.parent / "r_plots")


def test_coverage_maps_go_to_runs_not_the_current_directory(tmp_path):
    r = subprocess.run(SUNSIM + ["coverage", "tilt0_fov90"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert os.listdir(tmp_path) == ["runs"] and os.listdir(tmp_path / "runs") == ["coverage_tilt0_fov90.png"]


def test_shared_range_covers_the_worst_estimator():
    sunlit = np.ones(1000, bool)
    a, b = np.linspace(0, 1, 1000), np.linspace(0, 10, 1000)
    lo, top = shared_error_ylim({"a": a, "b": b}, sunlit)
    # 1.15 x the 99.5th percentile of b (linear interpolation: 9.95)
    assert lo == 0.0 and top == pytest.approx(1.15 * 9.95)


def test_view_pictures_go_to_runs_not_the_current_directory(tmp_path):
    r = subprocess.run(SUNSIM + ["view", "tilt20_fov70", "--spp", "1", "--resolution", "16", "9"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert os.listdir(tmp_path) == ["runs"] and os.listdir(tmp_path / "runs") == ["scene_tilt20_fov70.png"]
