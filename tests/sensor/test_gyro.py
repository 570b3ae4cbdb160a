"""The gyro model: Allan deviation against the closed forms, the data table, the thermal cycle."""
import numpy as np
import pytest

from simcore.sensor.gyro import (DEG, GyroModel, allan_deviation, allan_variance_model, board_temperature_k, gyro_spec,
                          load_gyros)

M_CLUSTERS = np.array([1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048])


def _tolerance(n_samples, m):
    # Relative standard deviation of an Allan deviation estimate from K = N/m independent clusters is
    # about 1/sqrt(2 (K - 1)) (IEEE Std 952, annex C); the overlapping estimator is tighter still.
    # 4 of those at each of 12 cluster sizes: a false alarm (Gaussian approximation) below 1e-3.
    return 4.0 / np.sqrt(2.0 * (n_samples / m - 1.0))


def _simulated_adev(spec_name, n=60000, seed=3, **kw):
    gyro = GyroModel(spec_name, seed=seed, **kw)
    t = np.arange(n, dtype=float)
    rate = gyro.measure(t, np.zeros(3))
    return gyro, allan_deviation(rate[:, 0] - rate[:, 0].mean(), 1.0, M_CLUSTERS)


@pytest.mark.parametrize("name", ["BMG160", "MPU-3300"])
def test_allan_deviation_matches_arw_and_bias_instability(name):
    # Oracle: the Allan variance closed forms (IEEE Std 952-1997 annex C): white rate noise N^2/tau
    # (N = the data sheet's rate noise density) plus the first-order Gauss-Markov bias whose
    # Allan deviation peaks at the data sheet's bias instability (15 deg/h, thesis fig. 3.1).
    gyro, adev = _simulated_adev(name)
    model = np.sqrt(allan_variance_model(M_CLUSTERS * 1.0, gyro.spec))
    tol = _tolerance(60000, M_CLUSTERS)
    assert np.all(np.abs(adev / model - 1.0) < tol), np.c_[M_CLUSTERS, adev / model, tol]
    # ARW read off the curve at tau = 1 s is the data sheet's density (short clusters: 0.6 % tolerance).
    assert abs(adev[0] / gyro.spec.noise_density_rad_s_rthz - 1) < tol[0] + 1e-2
    # Beyond 100 s the curve is the bias hump, peaking at the data sheet's bias instability
    # (the peak estimate, from >= 29 clusters, is good to ~ 15 %; ARW adds < 2 % there).
    peak = adev[M_CLUSTERS >= 128].max() / gyro.spec.bias_instability_rad_s
    assert 0.7 < peak < 1.3, peak


def test_allan_check_fails_on_a_wrong_noise_density():
    # The same comparison rejects a gyro simulated with half the data sheet's noise density.
    from dataclasses import replace
    spec = gyro_spec("BMG160")
    gyro = GyroModel(replace(spec, noise_density_rad_s_rthz=spec.noise_density_rad_s_rthz / 2), seed=3)
    rate = gyro.measure(np.arange(60000.0), np.zeros(3))
    adev = allan_deviation(rate[:, 0] - rate[:, 0].mean(), 1.0, M_CLUSTERS)
    model = np.sqrt(allan_variance_model(M_CLUSTERS * 1.0, spec))
    assert not np.all(np.abs(adev / model - 1.0) < _tolerance(60000, M_CLUSTERS))


def test_gyro_errors_scale_bias_and_temperature():
    # With noise-free parts the reading is exactly (I + dS + M) w + b0 + c_T (T - 25 degC), quantised.
    from dataclasses import replace
    spec = replace(gyro_spec("MPU-3300"), noise_density_rad_s_rthz=0.0, bias_instability_rad_s=0.0,
                   resolution_rad_s=0.0)
    g = GyroModel(spec, seed=1)
    t = np.arange(5.0)
    w = np.array([0.02, -0.01, 0.03])
    temp = np.array([298.15, 300.0, 310.0, 280.0, 270.0])
    out = g.measure(t, w, temp)
    expect = g.gain_matrix @ w + g.bias_turn_on_rad_s + g.bias_temp_coeff_rad_s_k * (temp - 298.15)[:, None]
    np.testing.assert_allclose(out, expect, rtol=1e-12, atol=1e-15)
    assert out.shape == (5, 3)
    # The draws are data-sheet sized: MPU-3300 cross-axis +-2 % (3 sigma), scale +-3 %.
    assert np.abs(g.misalignment).max() < 0.03 and np.abs(g.scale_factor).max() < 0.045


def test_quantisation_to_the_lsb():
    from dataclasses import replace
    spec = replace(gyro_spec("L3G4200D"), noise_density_rad_s_rthz=0.0, bias_instability_rad_s=0.0,
                   bias_level_rad_s=0.0, bias_temp_coeff_rad_s_k=0.0)
    g = GyroModel(spec, seed=0, sample_rate_hz=1.0)
    out = g.measure(np.arange(3.0), np.array([0.001, 0.0, 0.0]))
    lsb = 0.00875 * DEG  # 8.75 mdps/digit (L3G4200D data sheet)
    np.testing.assert_allclose(out[:, 0], lsb * np.rint(0.001 / lsb))


def test_table_holds_the_thesis_candidates_with_sources():
    g = load_gyros()
    for name in ("MPU-3300", "IMU160", "BMG160", "L3G4200D"):
        assert name in g and g[name].source
    # Values of thesis figs. 3.1-3.2 (deg/s/sqrt(Hz)).
    assert g["MPU-3300"].noise_density_rad_s_rthz == pytest.approx(0.005 * DEG)
    assert g["BMG160"].bias_temp_coeff_rad_s_k == pytest.approx(0.015 * DEG)
    assert {n for n, s in g.items() if s.recommended} == {"MPU-3300", "IMU160", "BMG160"}
    assert g["L3G4200D"].flown


def test_unknown_gyro_suggests_close_names():
    with pytest.raises(ValueError, match="unknown gyro 'BMG16'.*did you mean BMG160"):
        gyro_spec("BMG16")


def test_board_temperature_cycle():
    # Closed form of the first-order lag: from T0 with constant forcing T_eq, T = T_eq + (T0 - T_eq) e^(-t/tau).
    t = np.arange(0.0, 3000.0, 1.0)
    temp = board_temperature_k(t, np.zeros(t.size), t0_k=298.15)
    np.testing.assert_allclose(temp, 268.15 + 30.0 * np.exp(-t / 2100.0), rtol=1e-12)
    # Largest gradient 30 K / 2100 s = 0.0143 K/s: the Compass-1 ADCS board's 0.014 degC/s (thesis sec. 2.2).
    assert abs(np.abs(np.diff(temp)).max() - 0.014) < 0.0005


def test_thermal_compensation_leaves_the_stated_fraction():
    from simcore.sensor.gyro import THERMAL_COMPENSATION_RESIDUAL, filter_noise, thermally_compensated
    spec = gyro_spec("MPU-3300")
    comp = thermally_compensated(spec)
    assert comp.bias_temp_coeff_rad_s_k == pytest.approx(0.25 * DEG * THERMAL_COMPENSATION_RESIDUAL)
    assert comp.noise_density_rad_s_rthz == spec.noise_density_rad_s_rthz
    # The filter's bias random walk shrinks with it (thermal drift dominates the MPU-3300's).
    assert filter_noise(comp)[1] < 0.5 * filter_noise(spec)[1]
    with pytest.raises(ValueError, match="fraction"):
        thermally_compensated(spec, 1.5)
