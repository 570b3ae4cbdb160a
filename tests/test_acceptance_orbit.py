"""Issue 4's acceptance, as a test: one full ESTCube-1 orbit (2016-07-02, 1 s, tilt20_fov70) rendered
with seed 0 and checked against the independent analytic model on every diode-epoch."""
import numpy as np

from simcore.pipeline.run import RunOptions, check_run, execute


def test_one_full_orbit_passes_the_analytic_check(tmp_path):
    path, ds, _ = execute(RunOptions(output=str(tmp_path / "orbit.nc")), progress=False)
    assert ds.sizes["time"] == 5871 and ds.sizes["diode"] == 14      # one anomalistic period at 1 s
    flags, report = check_run(ds)
    # Direct Sun: every diode-epoch within max(0.5 % of E_sun cos, 3 sigma) of the exact aperture + body
    # model, up to what the standard errors predict by chance.
    assert report["direct_checked"] > 80000
    assert report["direct_outliers"] <= report["direct_outliers_expected_by_chance"] + 3
    # Albedo: z-scores against the refined Bhanderi sum consistent with N(0, 1): mean |z| < 1 and under
    # 0.3 % beyond 4 (for N(0, 1): 0.80 and 0.006 %), over diode-epochs above 1 W/m^2.
    assert report["albedo_checked"] > 30000
    assert report["albedo_mean_abs_z"] < 1.0 and report["albedo_share_abs_z_gt_4"] < 0.003
    assert report["pass"]
    # It is a sunlit, albedo-rich orbit: the check compared real numbers.
    irr = ds["irradiance"].values
    assert irr[..., 0].max() > 1300 and np.median(irr[..., 1][irr[..., 1] > 0]) > 5
