"""Reflectivity maps: shipped loaders, user grids, cell geometry, bad input."""
import numpy as np
import pytest

from simcore.constants import R_EARTH_MEAN_M
from simcore.environment.maps import ReflectivityMap


@pytest.mark.parametrize("make", [
    ReflectivityMap.toms2005,
    lambda: ReflectivityMap.ceres2018("all"),
    lambda: ReflectivityMap.from_array(np.ones((7, 13))),
    lambda: ReflectivityMap.from_array(np.ones((90, 180)), lat_deg=np.arange(89.0, -90.0, -2.0),
                                       lon_deg=np.arange(1.0, 360.0, 2.0)),
])
def test_cell_areas_sum_to_the_sphere(make):
    # Reference: the area of a sphere, 4 pi R^2 (the zones tile it exactly).
    m = make()
    assert m.cell_area_m2.shape == m.shape
    assert m.cell_area_m2.sum() == pytest.approx(4 * np.pi * R_EARTH_MEAN_M ** 2, rel=1e-12)


def test_shipped_maps_layout():
    # simcore/data/README.md: row 0 south (-89.5), column 0 west (TOMS -179.375, CERES -179.5).
    t = ReflectivityMap.toms2005()
    assert t.shape == (180, 288) and t.lat_deg[0] == -89.5 and t.lon_deg[0] == -179.375
    assert t.is_toolbox_layout and t.south_first
    assert t.values.max() > 1.0          # TOMS exceeds 1 over ice: never clamped
    for kind in ("all", "clear"):
        c = ReflectivityMap.ceres2018(kind)
        assert c.shape == (180, 360) and c.lon_deg[0] == -179.5 and c.is_toolbox_layout
    assert ReflectivityMap.toms2005() is t  # loaded and its geometry built once


def test_geometry_of_a_cell():
    m = ReflectivityMap.from_array(np.ones((4, 8)))
    # Row 0 spans latitudes -90..-45: zone area 2 pi R^2 (1 - sin 45 deg), split over 8 columns.
    expected = 2 * np.pi * m.radius_m ** 2 * (1 - np.sin(np.radians(45))) / 8
    assert m.cell_area_m2[0, 0] == pytest.approx(expected, rel=1e-13)
    lat, lon = np.radians(m.lat_deg[2]), np.radians(m.lon_deg[5])
    np.testing.assert_allclose(m.normals_ecef[2, 5], [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon),
                                                     np.sin(lat)], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(m.centres_ecef_m, axis=-1), m.radius_m, rtol=1e-15)
    np.testing.assert_allclose(m.lat_edges_deg, [-90, -45, 0, 45, 90])
    np.testing.assert_allclose(m.lon_edges_deg, np.arange(-180, 181, 45))


def test_default_grid_and_user_metadata():
    m = ReflectivityMap.from_array(np.full((18, 36), 0.3))
    assert m.lat_deg[0] == -85.0 and m.lon_deg[0] == -175.0 and m.is_toolbox_layout
    north_first = ReflectivityMap.from_array(np.full((18, 36), 0.3), lat_deg=np.arange(85.0, -90.0, -10.0))
    assert not north_first.south_first and not north_first.is_toolbox_layout
    assert north_first.lat_edges_deg[0] == 90.0


def test_bad_maps_are_refused():
    with pytest.raises(ValueError, match="2-D array"):
        ReflectivityMap.from_array(np.ones(10))
    with pytest.raises(ValueError, match="one cell-centre latitude per row"):
        ReflectivityMap(np.ones((180, 288)), np.linspace(-89.5, 89.5, 180), np.linspace(-179.5, 179.5, 360))
    with pytest.raises(ValueError, match="non-finite"):
        ReflectivityMap.from_array(np.where(np.eye(18, 36) > 0, np.nan, 0.3))
    with pytest.raises(ValueError, match="negative"):
        ReflectivityMap.from_array(np.full((18, 36), -999.0))
    with pytest.raises(ValueError, match="tile latitudes"):
        ReflectivityMap.from_array(np.ones((10, 36)), lat_deg=np.arange(10) + 0.5)
    with pytest.raises(ValueError, match="equally spaced"):
        ReflectivityMap.from_array(np.ones((3, 4)), lat_deg=[-60, 0, 70])
    with pytest.raises(ValueError, match="tile 360"):
        ReflectivityMap.from_array(np.ones((18, 10)), lon_deg=np.arange(10) * 10.0)
    with pytest.raises(ValueError, match="kind='all'"):
        ReflectivityMap.ceres2018("cloudy")
