"""Tests of the photodiode sensor chain (simcore.sensor.chain) against the thesis' closed forms."""
import dataclasses

import numpy as np
import pytest

from simcore.sensor.chain import DIODES, T_REF_K, PhotodiodeSpec, SensorChain, misaligned_normals

E_SUN = 1366.1            # thesis sec. 2.3.2, the solar constant the irradiance is computed with
Q_E = 1.602176634e-19     # CODATA 2018 / SI 2019 exact elementary charge
K_B = 1.380649e-23        # CODATA 2018 / SI 2019 exact Boltzmann constant


def no_dark(name="BPW34FS"):
    return dataclasses.replace(DIODES[name], dark_current_a=0.0)


def test_diode_table_matches_thesis_table_3_2_3():
    # E_S0 from thesis table 3.2.3; R and TC from sec. 3.2.3; area from eq. 4.18
    assert DIODES["BPW34FS"].e_s0_w_m2 == 188.1
    assert DIODES["SFH2430"].e_s0_w_m2 == 425.9
    assert DIODES["BPW34FAS"].e_s0_w_m2 == 234.3
    assert DIODES["BPV23F"].e_s0_w_m2 == 154.1
    assert DIODES["BPW34FS"].responsivity_a_w == 0.7 and DIODES["SFH2430"].responsivity_a_w == 0.17
    assert DIODES["BPW34FS"].area_m2 == 7.02e-6
    assert DIODES["BPW34FS"].temp_coeff_per_k == pytest.approx(0.0003)
    assert DIODES["SFH2430"].temp_coeff_per_k == pytest.approx(0.0016)


def test_normal_sun_current_is_0_924_ma():
    # thesis eq. 4.18: 0.924 mA = 0.7 A/W * 7.02e-6 m^2 * 188.1 W/m^2
    chain = SensorChain(diode=no_dark())
    i = chain.current_a(np.array([[E_SUN]]))
    assert i.shape == (1, 1)
    assert i[0, 0] == pytest.approx(0.7 * 7.02e-6 * 188.1, rel=1e-14)
    assert round(i[0, 0] * 1e3, 3) == 0.924
    # the dark current adds on top (eq. 2.30 + I_D)
    chain_d = SensorChain()
    assert chain_d.current_a([E_SUN])[0, 0] - i[0, 0] == pytest.approx(DIODES["BPW34FS"].dark_current_a, rel=1e-6)


def test_reflected_light_scaled_like_sunlight():
    # thesis 4.2.1: "The reflected light is scaled down by the same amount" -> I proportional to E
    chain = SensorChain(diode=no_dark())
    e = np.array([[E_SUN, 0.3 * E_SUN, 0.0, 17.0]])
    i = chain.current_a(e)
    np.testing.assert_allclose(i, 0.7 * 7.02e-6 * 188.1 * e / E_SUN, rtol=1e-14, atol=0)


def test_counts_follow_eq_4_24_exactly():
    # eq. 4.24: counts = I * 500 * (2^11 - 1), rounded to the nearest count
    chain = SensorChain()
    gain = 500.0 * 2047.0
    k = np.arange(0, 2048)
    i = (k / gain)[None, :]
    np.testing.assert_array_equal(chain.counts_from_current(i), k[None, :].astype(float))
    # 0.5 mA -> 0.5e-3 * 500 * 2047 = 511.75 -> 512; 0.2 mA -> 204.7 -> 205; 1 uA -> 1.0235 -> 1
    np.testing.assert_array_equal(chain.counts_from_current([[0.5e-3, 0.2e-3, 1e-6]]), [[512.0, 205.0, 1.0]])


def test_saturation_and_negative_currents():
    chain = SensorChain()
    # 1 V / 500 ohm = 2 mA is full scale: 2047 counts; more saturates; negative reads 0
    np.testing.assert_array_equal(chain.counts_from_current([[2e-3, 3e-3, 1.0, -1e-4]]), [[2047.0, 2047.0, 2047.0, 0.0]])
    assert chain.counts([[10 * E_SUN]])[0, 0] == 2047.0


def test_round_trip_within_one_lsb(rng):
    # eq. 4.25 inverts eq. 4.24 with K_R = R A: E_p = E_S0 E / E_sun up to quantisation
    chain = SensorChain()
    e = rng.uniform(0.0, 1.5 * E_SUN, size=(2000, 14))
    e_p = chain.measure(e)
    lsb = 1.0 / (500 * 2047 * 0.7 * 7.02e-6)     # one count in W/m^2 from eq. 4.25
    assert chain.lsb_w_m2 == pytest.approx(lsb, rel=1e-12)
    assert np.max(np.abs(e_p - 188.1 * e / E_SUN)) <= lsb
    # the quantiser rounds: the error is within half a count plus the 2 nA dark current (0.002 count)
    assert np.max(np.abs(e_p - 188.1 * e / E_SUN)) <= lsb * (0.5 + 0.003)
    # normal Sun reads E_S0 (the estimators' threshold scale, thesis 4.3.1)
    assert abs(chain.measure([[E_SUN]])[0, 0] - 188.1) <= lsb


def test_dead_diodes_read_zero(rng):
    chain = SensorChain(dead=(0, 3), noise=True, seed=1)
    e = rng.uniform(0.0, E_SUN, size=(50, 6))
    c = chain.counts(e)
    assert np.all(c[:, [0, 3]] == 0.0)
    assert np.all(chain.measure(e)[:, [0, 3]] == 0.0)
    assert np.all(c[:, [1, 2, 4, 5]][e[:, [1, 2, 4, 5]] > 10] > 0)
    with pytest.raises(ValueError, match="dead diode"):
        SensorChain(dead=(7,)).counts(e)


def test_temperature_and_scale_errors():
    # eq. 2.29 / 3.6: I = R A E_S0 (E/E_sun) (1 + TC (T - T_ref)) (1 + delta_k)
    d = no_dark("SFH2430")
    delta = np.array([0.0, 0.05, -0.02])
    chain = SensorChain(diode=d, temperature_k=T_REF_K + 40.0, scale_errors=delta)
    i = chain.current_a(np.full((1, 3), E_SUN))
    expect = 0.17 * 7.02e-6 * 425.9 * (1 + 0.0016 * 40.0) * (1 + delta)
    np.testing.assert_allclose(i[0], expect, rtol=1e-13)


def _variance_z(x, sigma2):
    # z-score of a sample variance; for Gaussian samples var(s^2) = 2 sigma^4 / (n - 1)
    n = x.size
    return (np.var(x, ddof=1) - sigma2) / (sigma2 * np.sqrt(2.0 / (n - 1)))


@pytest.mark.parametrize("e, temp_k, bandwidth", [(E_SUN, T_REF_K, 3.18e5),     # shot-noise dominated
                                                  (0.0, T_REF_K, 3.18e5),       # Johnson-noise dominated
                                                  (0.0, 350.0, 1e3),
                                                  (0.2 * E_SUN, 330.0, 1e6)])
def test_noise_standard_deviation_matches_eqs_2_26_to_2_28(e, temp_k, bandwidth):
    d = DIODES["BPW34FS"]
    n = 40_000
    chain = SensorChain(noise=True, seed=12345, bandwidth_hz=bandwidth, temperature_k=temp_k)
    i = chain.current_a(np.full((n, 1), e))[:, 0]
    i_mean = d.responsivity_a_w * d.area_m2 * d.e_s0_w_m2 * e / E_SUN * (1 + d.temp_coeff_per_k * (temp_k - T_REF_K)) \
        + d.dark_current_a
    # eqs. 2.26-2.28: I_tn^2 = 2 q (I_P + I_D) df + 4 k_B T df / R_sh
    sigma2 = 2 * Q_E * i_mean * bandwidth + 4 * K_B * temp_k * bandwidth / d.shunt_resistance_ohm
    assert abs(_variance_z(i, sigma2)) < 4.0
    assert abs((i.mean() - i_mean) / np.sqrt(sigma2 / n)) < 4.0


def test_noise_is_reproducible_with_a_seed():
    e = np.full((10, 3), 500.0)
    a = SensorChain(noise=True, seed=7).current_a(e)
    b = SensorChain(noise=True, seed=7).current_a(e)
    np.testing.assert_array_equal(a, b)
    assert np.all(np.std(a, axis=0) > 0)


def test_default_bandwidth_is_eq_4_23():
    # eq. 4.23: f_op = 1 / (2 pi R_F C_F), R_F = 500 ohm, C_F = 1 nF (thesis 4.2.2)
    assert SensorChain().bandwidth_hz == pytest.approx(1 / (2 * np.pi * 500 * 1e-9), rel=1e-12)


def test_shapes_and_nan():
    chain = SensorChain()
    assert chain.measure(np.zeros(6)).shape == (1, 6)
    assert chain.measure(np.zeros((5, 14))).shape == (5, 14)
    out = chain.measure([[np.nan, 100.0]])
    assert np.isnan(out[0, 0]) and np.isfinite(out[0, 1])


def test_misuse_raises():
    with pytest.raises(ValueError, match="unknown diode"):
        SensorChain(diode="BPW99")
    with pytest.raises(ValueError, match=">= 0 W/m"):
        SensorChain().counts([[-1.0]])
    with pytest.raises(ValueError, match=r"\(N, K\)"):
        SensorChain().counts(np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="scale_errors"):
        SensorChain(scale_errors=[0.1, 0.2]).counts(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="positive"):
        PhotodiodeSpec("x", -0.7, 1e-6, 100.0, 0.0, 0.0, 1e8)


def test_misaligned_normals_rayleigh_statistics():
    rng = np.random.default_rng(99)
    k = 20_000
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    sigma = np.radians(0.5)
    m = misaligned_normals(n, sigma, rng)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1.0, atol=1e-14)
    ang = np.arctan2(np.linalg.norm(np.cross(n, m), axis=1), np.sum(n * m, axis=1))
    # a rotation vector with iid N(0, sigma^2) components tilts a vector by a Rayleigh(sigma) angle:
    # mean sigma sqrt(pi/2), variance (4 - pi)/2 sigma^2 (standard Rayleigh moments)
    mean, sd = sigma * np.sqrt(np.pi / 2), sigma * np.sqrt((4 - np.pi) / 2)
    assert abs((ang.mean() - mean) / (sd / np.sqrt(k))) < 4.0
    np.testing.assert_allclose(misaligned_normals(n[:5], 0.0, rng), n[:5], rtol=0, atol=1e-15)


def test_temperature_time_series_must_be_2d():
    # a (N,) series would broadcast along the diodes when N == K: refuse it and say how to reshape
    with pytest.raises(ValueError, match=r"t\[:, None\]"):
        SensorChain(temperature_k=np.full(6, 300.0))
    t = np.array([[T_REF_K], [T_REF_K + 10.0]])
    i = SensorChain(diode=no_dark(), temperature_k=t).current_a(np.full((2, 3), E_SUN))
    np.testing.assert_allclose(i[1] / i[0], 1 + 0.0003 * 10.0, rtol=1e-13)
