"""The rate question (issue 33 item 5): the estimated rate's error, raw / filtered / averaged, against closed forms."""
import numpy as np
import pytest

from simcore.studies.rate import (REQUIREMENT_DEG_S_RTHZ, averaged_rms, rate_errors, rate_page, white_noise_rms)


@pytest.mark.parametrize("dt, window", [(1.0, 1.0), (1.0, 10.0), (1.0, 60.0), (0.5, 10.0)])
def test_white_noise_averaged_over_a_window_has_rms_n_over_sqrt_t(dt, window):
    # White noise of density N sampled every dt has a per-sample sigma N / sqrt(dt); its mean over T has rms
    # N / sqrt(T) (closed form). 3 axes x >= 1000 blocks: the rms's relative standard error <= 1/sqrt(2 * 3000)
    # = 1.3 %; 6 % is >= 4.6 se (false alarm < 1e-5).
    density = 0.014
    rng = np.random.default_rng(1)
    n = int(1000 * window / dt) + 7
    err = rng.standard_normal((n, 3)) * density / np.sqrt(dt)
    assert averaged_rms(err, dt, window) == pytest.approx(float(white_noise_rms(density, window)), rel=0.06)


def test_a_constant_error_does_not_average_away():
    # the wrong input for the check above: a bias b stays b at every window, not b / sqrt(T)
    err = np.full((6000, 3), 0.01)
    assert averaged_rms(err, 1.0, 60.0) == pytest.approx(0.01, rel=1e-12)
    assert averaged_rms(err, 1.0, 60.0) != pytest.approx(float(white_noise_rms(0.01, 60.0)), rel=0.5)


def test_blocks_with_nan_are_dropped_and_short_series_give_nan():
    err = np.ones((100, 3))
    err[5] = np.nan
    assert averaged_rms(err, 1.0, 10.0) == pytest.approx(1.0)
    assert np.isnan(averaged_rms(err[:5], 1.0, 10.0))


def test_raw_filtered_averaged_from_a_filter_result():
    # reading = truth + bias + white noise (sigma 0.01 deg/s); the filter's bias estimate is the bias:
    # raw = sqrt(sigma^2 + bias^2) per axis, filtered = sigma, averaged over 100 s = sigma / 10.
    rng = np.random.default_rng(4)
    n, bias = 100000, np.radians([0.3, -0.4, 0.0])
    w_true = np.radians(1.9) * np.ones((n, 3)) / np.sqrt(3)
    noise = np.radians(0.01) * rng.standard_normal((n, 3))
    res = {"omega_true": w_true, "omega_meas": w_true + bias + noise, "bias_est": np.tile(bias, (n, 1))}
    res["bias_est"][:10] = np.nan                                     # before the filter's start
    out = rate_errors(res, 1.0, windows=(1, 100))
    assert out["raw_deg_s"] == pytest.approx(np.sqrt(0.01 ** 2 + (0.3 ** 2 + 0.4 ** 2) / 3), rel=0.01)
    assert out["filtered_deg_s"] == pytest.approx(0.01, rel=0.01)
    assert out["averaged_deg_s"][1] == pytest.approx(0.001, rel=0.06)
    assert out["equivalent_density_deg_s_rthz"][1] == pytest.approx(0.01, rel=0.06)


def test_rate_page_compares_with_the_requirement(tmp_path):
    from simcore.plots import plot_rate_error
    w = [1, 60]
    rows = {"G": {"raw_deg_s": 1.0, "filtered_deg_s": 0.02, "windows_s": w, "averaged_deg_s": [0.02, 0.0026],
                  "equivalent_density_deg_s_rthz": [0.02, 0.02], "data_sheet_density_deg_s_rthz": 0.014}}
    text = rate_page({"run": "r.nc", "configuration": "c", "seeds": [0], "requirement_deg_s_rthz": REQUIREMENT_DEG_S_RTHZ,
                      "gyros": rows})
    need = REQUIREMENT_DEG_S_RTHZ / np.sqrt(60)
    assert f"{need:.6f}" in text and f"| {0.0026 / need:.0f} |" in text
    plot_rate_error(rows, REQUIREMENT_DEG_S_RTHZ, tmp_path / "r.png")
    assert (tmp_path / "r.png").stat().st_size > 1000
