"""A sweep of 8 small runs on a 2-worker local Dask cluster lands in one dataset, and resumes."""
import os

import numpy as np
import xarray as xr

from simcore.pipeline.options import RunOptions
from simcore.pipeline.sweep import sweep, sweep_points


def test_sweep_of_eight_runs_on_two_local_workers(tmp_path):
    base = RunOptions(duration_s=6, direct_samples=256, albedo_samples=256, rel_se_direct=None, rel_se_albedo=None,
                      chunk_epochs=3)
    args = (["tilt20_fov70", "tilt0_fov90"], ["2016-07-02T00:45:00Z", "2016-07-03T00:45:00Z"], [1.9, 0.5], [0])
    folder = str(tmp_path / "sw")
    path, ds = sweep(base, *args, folder, workers=2, log=lambda m: None)
    assert ds.sizes["run"] == 8 and ds.sizes["diode"] == 14 and ds.sizes["step"] == 6
    reopened = xr.load_dataset(path)
    assert sorted(set(reopened["config"].values)) == ["tilt0_fov90", "tilt20_fov70"]
    assert sorted(set(reopened["spin_rate_deg_s"].values)) == [0.5, 1.9]
    # The baseline has 6 diodes: slots 6..13 are padding (NaN irradiance, marked dead).
    base6 = reopened.where(reopened["config"] == "tilt0_fov90", drop=True)
    assert np.isnan(base6["irradiance"].sel(diode=slice(6, 13))).all()
    assert np.isfinite(base6["irradiance"].sel(diode=slice(0, 5))).all()
    # Each point is the run the same options give alone: file names are the options' digests.
    points = sweep_points(base, *args, folder)
    assert all(os.path.exists(p.output) for p in points)

    # An interrupted sweep: one run file lost; running again redoes only that one.
    os.remove(points[3].output)
    stamps = {p.output: os.path.getmtime(p.output) for p in points if os.path.exists(p.output)}
    path2, ds2 = sweep(base, *args, folder, workers=2, log=lambda m: None)
    assert all(os.path.getmtime(f) == t for f, t in stamps.items())
    np.testing.assert_array_equal(ds2["irradiance"].values, ds["irradiance"].values)
