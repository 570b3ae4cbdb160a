"""IGRF along the orbit and the magnetometer model."""
import datetime

import erfa
import numpy as np
import pytest

from simcore.sensor.magnetometer import MagnetometerModel, igrf_ecef_t, load_magnetometers, magnetometer_spec

# Published values: NOAA NCEI geomagnetic calculator, model IGRF2020 (IGRF-13), 2020-01-01, 5 km above
# the WGS84 ellipsoid (the reference grid shipped with ppigrf's tests, test/data/2020-01-01/b_e.csv and
# b_z.csv; Z positive down). (lat deg, lon deg, B_east nT, B_down nT)
NOAA_IGRF13_2020 = [
    (80.0, -179.0, -50.2, 57586.4),
    (80.0, 0.0, -151.6, 54497.7),
    (80.0, 90.0, 1881.7, 58247.8),
    (80.0, -53.0, -3000.2, 55420.9),
]


@pytest.mark.parametrize("lat, lon, b_east, b_down", NOAA_IGRF13_2020)
def test_igrf_against_noaa_calculator(lat, lon, b_east, b_down):
    import importlib.resources
    igrf13 = str(importlib.resources.files("ppigrf").joinpath("IGRF13.shc"))
    la, lo = np.radians(lat), np.radians(lon)
    r = erfa.gd2gc(1, lo, la, 5000.0)                        # WGS84 geodetic -> ECEF, metres
    b = igrf_ecef_t(r[None, :], datetime.datetime(2020, 1, 1), coeff_file=igrf13)[0] / 1e-9
    east = np.array([-np.sin(lo), np.cos(lo), 0.0])
    up = np.array([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    # The calculator prints 0.1 nT; ppigrf's own test allows 1 nT at this date (no time interpolation).
    assert b @ east == pytest.approx(b_east, abs=1.0)
    assert -(b @ up) == pytest.approx(b_down, abs=1.0)


def test_field_shapes_and_magnitude_in_leo():
    # A dipole-dominated field: at 665 km it lies between ~18 000 and ~55 000 nT everywhere.
    rng = np.random.default_rng(0)
    v = rng.normal(size=(500, 3))
    r = 7036e3 * v / np.linalg.norm(v, axis=1, keepdims=True)
    b = igrf_ecef_t(r, datetime.datetime(2016, 7, 2))
    assert b.shape == (500, 3)
    mag = np.linalg.norm(b, axis=1) / 1e-9
    assert 15000 < mag.min() and mag.max() < 56000


def test_magnetometer_noise_bias_and_quantisation():
    spec = magnetometer_spec("rm3100")
    m = MagnetometerModel(spec, seed=2)
    b = np.tile([20000e-9, -5000e-9, 30000e-9], (20000, 1))
    out = m.measure(b)
    resid = out - (b @ m.gain_matrix.T + m.bias_t)
    # White noise of the data sheet's 15 nT (1 sigma; quantisation at 13 nT adds 13^2/12 in variance):
    # the sample standard deviation of 20000 draws is good to 0.5 %; 2 % is > 4 standard errors.
    expect = np.sqrt(15.0 ** 2 + 13.0 ** 2 / 12.0)
    assert np.std(resid / 1e-9, axis=0) == pytest.approx([expect] * 3, rel=0.02)
    np.testing.assert_allclose(out / 13e-9, np.rint(out / 13e-9), atol=1e-6)


def test_unknown_magnetometer_suggests_close_names():
    assert set(load_magnetometers()) >= {"HMC5883L", "RM3100", "LIS3MDL"}
    with pytest.raises(ValueError, match="unknown magnetometer 'HMC5883'.*did you mean HMC5883L"):
        magnetometer_spec("HMC5883")
