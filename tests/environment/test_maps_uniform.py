"""The average-albedo map ``uniform:A`` (Basilisk's ALBEDO_AVG): a uniform Lambertian Earth."""
import numpy as np
import pytest

from simcore.radiometry.albedo import reflected_power_w
from simcore.constants import R_EARTH_MEAN_M
from simcore.environment.maps import named_map


def test_uniform_map_reflects_a_e_sun_pi_r2():
    # a sphere intercepts E_sun pi R^2 and a uniform Lambertian one of albedo A returns A times that;
    # the cell sum is a midpoint quadrature: error of order (cell size in rad)^2 (as in test_albedo)
    m = named_map("uniform:0.3")
    assert m.shape == (180, 288) and np.all(m.values == 0.3)
    p = reflected_power_w(1.496e11 * np.array([0.3, -0.5, 0.8]) / np.sqrt(0.98), m, e_sun_w_m2=1366.1)
    assert p == pytest.approx(0.3 * 1366.1 * np.pi * R_EARTH_MEAN_M ** 2, rel=np.radians(1.25) ** 2)


@pytest.mark.parametrize("name, message", [
    ("uniform:abc", "uniform:abc needs a number"), ("uniform:-0.3", "must be a finite number >= 0"),
    ("uniform:", "needs a number"), ("uniform:nan", "must be a finite number >= 0"),
])
def test_bad_uniform_map(name, message):
    with pytest.raises(ValueError, match=message):
        named_map(name)
