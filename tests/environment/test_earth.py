"""Tests of simcore.environment.earth.Earth: one Earth, its renderer layout and its refinement, taken alike by
the analytic model, the on-board model and the renderer."""
import numpy as np
import pytest

from simcore.environment.earth import Earth
from simcore.environment.maps import ReflectivityMap
from simcore.radiometry.glint import SunGlint

N_LAT, N_LON = 18, 36
DLAT, DLON = 180.0 / N_LAT, 360.0 / N_LON
LON_WEST = -170.0            # column 0 from 170 W: not the shipped maps' -180


def _north_first_earth():
    """Return an Earth on a north-first 10 x 10 deg map whose column 0 starts at 170 W, every cell's reflectivity
    and sea fraction a distinct function of its centre's latitude and longitude."""
    lat = np.arange(90.0 - DLAT / 2, -90.0, -DLAT)                       # row 0 the northern band
    lon = LON_WEST + (np.arange(N_LON) + 0.5) * DLON
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    refl = 0.2 + 0.001 * la + 0.0001 * lo + 0.5
    sea = np.clip(0.5 + la / 200.0 + np.sin(np.radians(lo)) / 4, 0.0, 1.0)
    m = ReflectivityMap.from_array(refl, lat_deg=lat, lon_deg=lon, radius_m=6.4e6)
    return Earth(m, SunGlint(7.0, sea=sea)), refl, sea


def _read_at(values, lat_centres, lon_centres, lat, lon):
    """Return ``values`` (on the given cell centres) at the cell holding (lat, lon): an independent lookup."""
    i = int(np.argmin(np.abs(lat_centres - lat)))
    j = int(np.argmin(np.abs(((lon_centres - lon) + 180.0) % 360.0 - 180.0)))
    return values[i, j]


def test_renderer_layout_reads_the_map_and_the_sea_at_the_same_place():
    earth, refl, sea = _north_first_earth()
    lay = earth.renderer_layout()
    assert lay["lon_west_deg"] == pytest.approx(LON_WEST) and lay["earth_radius_m"] == 6.4e6
    lat_c = np.arange(90.0 - DLAT / 2, -90.0, -DLAT)
    lon_c = LON_WEST + (np.arange(N_LON) + 0.5) * DLON
    for i, j in [(0, 0), (3, 7), (N_LAT - 1, N_LON - 1), (9, 20)]:
        # the renderer's convention: row 0 the southern band, column 0 from lon_west
        lat = -90.0 + (i + 0.5) * DLAT
        lon = lay["lon_west_deg"] + (j + 0.5) * DLON
        assert lay["reflectivity"][i, j] == _read_at(refl, lat_c, lon_c, lat, lon)
        assert lay["glint"].sea[i, j] == _read_at(sea, lat_c, lon_c, lat, lon)
    assert lay["glint"].wind_m_s == 7.0 and lay["glint"].index == earth.glint.index


def test_without_glint_the_layout_has_no_glint_and_the_default_earth_is_toms():
    earth = Earth()
    assert earth.map is ReflectivityMap.toms2005() and earth.glint is None and earth.sea_fraction is None
    lay = earth.renderer_layout()
    assert "glint" not in lay and lay["reflectivity"] is earth.map.values_south_first


def test_on_grid_keeps_each_cells_sea_on_its_sub_cells():
    earth, _, sea = _north_first_earth()
    fine = earth.refined(3)
    assert fine.map.shape == (3 * N_LAT, 3 * N_LON)
    assert fine.glint.sea[7, 10] == sea[7 // 3, 10 // 3] and fine.glint.sea[53, 107] == sea[17, 35]
    np.testing.assert_array_equal(earth.on_grid(earth.map).glint.sea, sea)
    with pytest.raises(ValueError, match="no refinement"):
        earth.on_grid(ReflectivityMap.from_array(np.zeros((20, 36))))


def test_a_sea_of_another_shape_is_refused():
    with pytest.raises(ValueError, match="sea fraction has shape"):
        Earth(ReflectivityMap.from_array(np.zeros((18, 36))), SunGlint(5.0, sea=np.zeros((180, 288))))


def test_analytic_model_takes_the_earth_as_map_and_glint():
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.radiometry.response import CosineResponse
    from simcore.shapes.aperture import diode_frame
    earth, _, _ = _north_first_earth()
    r_sat = np.array([[6.4e6 + 700e3, 0.0, 0.0]])
    r_sun = np.array([[1.496e11, 2e10, 3e10]])
    frames = np.stack([diode_frame(np.array(n, float)) for n in ([-1.0, 0, 0], [-0.8, 0.6, 0.0])])
    args = (r_sat, r_sun, np.eye(3), frames, CosineResponse())
    kw = dict(direct=False, backend="numpy")
    by_earth = diode_irradiance(*args, earth=earth, **kw).albedo_w_m2
    by_parts = diode_irradiance(*args, map=earth.map, glint=earth.glint, **kw).albedo_w_m2
    np.testing.assert_array_equal(by_earth, by_parts)
    assert np.all(by_earth > 0)
    with pytest.raises(ValueError, match="not both"):
        diode_irradiance(*args, earth=earth, map=earth.map, **kw)


def test_on_board_model_takes_an_earth_or_a_map():
    from simcore.radiometry.onboard import on_board_earth, predict_albedo_effective
    from simcore.radiometry.response import CosineResponse
    from simcore.shapes.aperture import diode_frame
    m = ReflectivityMap.toms2005()
    assert on_board_earth("toms2005").map is m and on_board_earth(m).glint is None
    geo = {"r_sat_ecef_m": np.array([[7.0e6, 0.0, 0.0]]), "r_sun_ecef_m": np.array([[1.496e11, 0.0, 0.0]]),
           "R_ecef_from_gcrs": np.eye(3)[None]}
    diodes = (diode_frame(np.array([-1.0, 0.0, 0.0]))[None], CosineResponse())
    by_map = predict_albedo_effective(geo, np.eye(3)[None], diodes, m, backend="numpy")
    by_earth = predict_albedo_effective(geo, np.eye(3)[None], diodes, Earth(m), backend="numpy")
    np.testing.assert_array_equal(by_map, by_earth)
    assert by_map[0, 0] > 0
