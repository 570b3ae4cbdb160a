"""The Bhanderi albedo model: radiometric identities, the MATLAB toolbox's own outputs, bad input."""
import numpy as np
import pytest
from scipy.integrate import quad

from simcore.radiometry.albedo import _matlab_round, albedo_cells, reflected_power_w
from simcore.constants import AU_M, R_EARTH_MEAN_M
from simcore.environment.maps import ReflectivityMap

R = R_EARTH_MEAN_M
E_SUN = 1366.1
RHO = 0.3
SUN_DIST = 1.496e11


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def uniform(shape=(180, 288), rho=RHO):
    return ReflectivityMap.from_array(np.full(shape, rho))


def lambert_cap_irradiance(r_m, rho=RHO, e_sun=E_SUN, radius=R):
    """Irradiance at distance r above a uniform Lambertian sphere with the Sun behind the observer.

    Derived independently of the cell model: with mu = cos(gamma) of a surface point at angle gamma
    from the sub-observer point, incidence cos = mu, the point -> observer vector v has
    |v|^2 = r^2 + R^2 - 2 r R mu and v . n = r mu - R, so
    E = rho E_sun / pi * 2 pi R^2 * int_{R/r}^{1} mu (r mu - R) / |v|^3 dmu   (scipy quad).
    """
    def f(mu):
        return mu * (r_m * mu - radius) / (r_m ** 2 + radius ** 2 - 2 * r_m * radius * mu) ** 1.5

    return rho * e_sun / np.pi * 2 * np.pi * radius ** 2 * quad(f, radius / r_m, 1, epsabs=0, epsrel=1e-12)[0]


def lambert_phase_law(d_m, a_rad, rho=RHO, e_sun=E_SUN, radius=R):
    """Far-field irradiance of a Lambertian sphere at phase angle a (e.g. Russell 1916; Sobolev 1975):
    E = (2/3) rho E_sun (R/d)^2 [sin a + (pi - a) cos a] / pi."""
    return 2 / 3 * rho * e_sun * (radius / d_m) ** 2 * (np.sin(a_rad) + (np.pi - a_rad) * np.cos(a_rad)) / np.pi


# ---- physical mode: identities -------------------------------------------------------------
@pytest.mark.parametrize("shape", [(180, 288), (180, 360), (36, 72)])
def test_uniform_earth_reflects_rho_e_pi_r2(shape):
    # A sphere intercepts E_sun pi R^2; a uniform reflector returns rho times that. The cell sum is a
    # midpoint quadrature of the sunlit hemisphere: error of order (cell size in rad)^2.
    m = uniform(shape)
    tol = np.radians(max(m.dlat_deg, m.dlon_deg)) ** 2
    for s in ([1.0, 0.0, 0.0], [0.3, -0.5, 0.8], [0.0, 0.0, -1.0]):
        p = reflected_power_w(SUN_DIST * _unit(s), m, e_sun_w_m2=E_SUN)
        assert p == pytest.approx(RHO * E_SUN * np.pi * R ** 2, rel=tol)


@pytest.mark.parametrize("altitude_m", [668e3, 2000e3, 39 * R])
def test_full_phase_matches_the_lambert_cap_integral(altitude_m, rng):
    # Sun behind the satellite: every visible cell is lit; reference: the 1-D integral above.
    m = uniform()
    for _ in range(3):
        u = _unit(rng.normal(size=3))
        e = albedo_cells((R + altitude_m) * u, SUN_DIST * u, m).sum()
        assert e == pytest.approx(lambert_cap_irradiance(R + altitude_m), rel=1e-4)


@pytest.mark.parametrize("phase_deg", [0, 30, 60, 90, 120, 150])
def test_far_field_follows_the_lambert_phase_law(phase_deg):
    # The phase law is the limit d -> infinity; at finite d the nearer half of the disc is brighter:
    # at zero phase the correction is (3/4) R/d (expand the cap integral above to first order in R/d),
    # i.e. 1.9 % at 40 R and growing towards crescent phases. At 3000 R it is below 0.3 % for these phases.
    m = uniform()
    a = np.radians(phase_deg)
    d = 3000 * R
    sat = d * _unit([0.2, -0.9, 0.4])
    perp = _unit(np.cross(sat, [0.0, 0.0, 1.0]))
    sun = SUN_DIST * (np.cos(a) * _unit(sat) + np.sin(a) * perp)
    e = albedo_cells(sat, sun, m).sum()
    assert e == pytest.approx(lambert_phase_law(d, a), rel=5e-3)


def test_at_40_earth_radii_the_phase_law_is_off_by_three_quarters_r_over_d():
    # First-order finite-distance correction at zero phase, derived in the test above: E/E_law - 1 = 0.75 R/d.
    m = uniform()
    d = 40 * R
    u = _unit([1.0, 2.0, 3.0])
    e = albedo_cells(d * u, SUN_DIST * u, m).sum()
    assert e / lambert_phase_law(d, 0.0) - 1 == pytest.approx(0.75 / 40, abs=1e-3)


def test_deep_umbra_sees_no_sunlit_cell():
    toms = ReflectivityMap.toms2005()
    sun = SUN_DIST * _unit([0.3, 0.9, -0.1])
    sat = -(R + 668e3) * _unit(sun)       # anti-solar point: every visible cell is on the night side
    assert np.all(albedo_cells(sat, sun, toms) == 0.0)
    assert np.all(albedo_cells(sat, sun, toms, toolbox_compatible=True) == 0.0)


def test_rotations_of_the_grid_leave_the_result_unchanged(rng):
    # Exact symmetries of a regular grid: turning everything about z by whole columns shifts the map
    # by that many columns; mirroring z -> -z flips the rows.
    m = uniform()
    sat = (R + 900e3) * _unit(rng.normal(size=3))
    sun = SUN_DIST * _unit(rng.normal(size=3) + _unit(sat))
    base = albedo_cells(sat, sun, m)
    k = 37
    ang = np.radians(k * m.dlon_deg)
    Rz = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    np.testing.assert_allclose(albedo_cells(Rz @ sat, Rz @ sun, m), np.roll(base, k, axis=1),
                               rtol=1e-9, atol=1e-12 * base.max())
    flip = np.diag([1.0, 1.0, -1.0])
    np.testing.assert_allclose(albedo_cells(flip @ sat, flip @ sun, m), base[::-1], rtol=1e-9,
                               atol=1e-12 * base.max())


def test_arbitrary_rotation_changes_a_uniform_total_only_at_grid_accuracy(rng):
    m = uniform()
    sat = (R + 668e3) * _unit([0.1, 0.7, 0.6])
    sun = SUN_DIST * _unit([0.8, 0.5, 0.1])
    base = albedo_cells(sat, sun, m).sum()
    for _ in range(3):
        q, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q * np.sign(np.linalg.det(q))
        assert albedo_cells(q @ sat, q @ sun, m).sum() == pytest.approx(base, rel=2e-3)


def test_user_map_orientation_and_resolution():
    # The same physical Earth described north-first gives the same cells, flipped.
    toms = ReflectivityMap.toms2005()
    flipped = ReflectivityMap.from_array(toms.values[::-1], lat_deg=toms.lat_deg[::-1], lon_deg=toms.lon_deg)
    sat = (R + 700e3) * _unit([0.4, -0.3, 0.8])
    sun = SUN_DIST * _unit([0.9, 0.1, 0.5])
    np.testing.assert_allclose(albedo_cells(sat, sun, flipped), albedo_cells(sat, sun, toms)[::-1], rtol=1e-12)
    ceres = albedo_cells(sat, sun, ReflectivityMap.ceres2018("clear"))
    assert ceres.shape == (180, 360) and ceres.sum() > 0
    assert albedo_cells(sat, sun, np.full((45, 90), 0.2)).shape == (45, 90)


def test_default_map_and_solar_constant_options():
    sat = (R + 700e3) * _unit([0.4, -0.3, 0.8])
    sun = SUN_DIST * _unit([0.9, 0.1, 0.5])
    base = albedo_cells(sat, sun)
    np.testing.assert_array_equal(base, albedo_cells(sat, sun, ReflectivityMap.toms2005()))
    np.testing.assert_allclose(albedo_cells(sat, sun, e_sun_w_m2=1000.0), base * 1000.0 / 1366.1, rtol=1e-12)
    scaled = albedo_cells(sat, sun, distance_scaling=True)
    np.testing.assert_allclose(scaled, base * (AU_M / SUN_DIST) ** 2, rtol=1e-12)


# ---- toolbox mode -----------------------------------------------------------------------------
# Reference outputs of the ORIGINAL MATLAB toolbox (albedo.m v1.28, AM0 = 1366.9) on the TOMS 2005 mean
# map (ga050101-051231.mat, identical to simcore/data/toms_2005_mean.npz), as stored by
# RoboticExplorationLab/EarthAlbedo.jl in test/test_files/earth_alb_std.jld2 and earth_alb_extra.jld2
# (variables cell_albs_mat / cell_albs_mats, computed in MATLAB; the Julia port tests against them).
# Per case: sum over cells, number of non-zero cells, and (row, column, value) of four cells, 0-based
# indices in the map's layout (MATLAB's (i, j) minus 1).
MATLAB_CASES = [
    ((0, 0, 8e6), (0, 1e9, 0), 56.79230473270984, 5120,
     [(169, 220, 0.03431552110224125), (143, 144, 6.764126281697792e-06), (161, 147, 0.0018730181627206663),
      (179, 249, 0.0003415263298026883)]),
    ((0, 0, 1e7), (0, 0, 1e9), 407.97593148442473, 14400,
     [(165, 100, 0.07762650083422686), (130, 0, 0.0004390123229603277), (155, 0, 0.03461351695556184),
      (179, 287, 0.00449775948237782)]),
    ((0, 1e8, 0), (0, 0, 1e9), 0.3913900390180194, 11238,
     [(125, 205, 0.00016282944724118473), (90, 147, 3.605693468460618e-11), (130, 261, 5.181118768551354e-05),
      (175, 244, 3.343354404458495e-09)]),
    ((5e7, 0, 0), (0, 0, 1e9), 1.2571045856319767, 9990,
     [(136, 150, 0.0004654818654589194), (90, 78, 1.18674165205859e-07), (128, 82, 2.3598113715408766e-05),
      (172, 153, 1.0576681618600959e-07)]),
    ((-1e6, 1e7, 1e8), (1e10, 1e5, 0), 0.386527782265023, 12379,
     [(137, 154, 0.00011787628989765987), (88, 199, 8.08096708114986e-09), (136, 208, 1.6735527596334312e-05),
      (179, 212, 6.34434842785121e-08)]),
    ((-1e7, -1e7, -1e7), (-2e8, 3300, 9e9), 0.7807936703451078, 2407,
     [(98, 35, 0.0009719093938372187), (89, 0, 2.2365175848406403e-05), (102, 22, 0.0006035334121342882),
      (122, 43, 5.701927273746902e-06)]),
    # Satellite and Sun in the same direction: the cells beyond 90 deg of the sub-solar CELL keep
    # cos(pi/2) = 6.1e-17 of their flux (toolbox quirk 7), hence values like 4.9e-28.
    ((0, 1e9, 0), (0, 1e9, 0), 0.010460904529315217, 25504,
     [(85, 224, 2.5448555292757362e-06), (0, 182, 4.887359822109595e-28), (90, 144, 4.913198639225324e-13),
      (179, 249, 1.1519099868784026e-13)]),
    ((0, 1e9, 0), (0, -1e9, 0), 0.0, 0, []),
]


@pytest.mark.parametrize("sat, sun, total, nonzero, cells", MATLAB_CASES)
def test_toolbox_mode_reproduces_the_matlab_toolbox(sat, sun, total, nonzero, cells):
    a = albedo_cells(np.array(sat, float), np.array(sun, float), toolbox_compatible=True)
    assert a.shape == (180, 288)
    assert int(np.count_nonzero(a)) == nonzero          # the same cell set, cell for cell in count
    assert a.sum() == pytest.approx(total, rel=1e-12, abs=0)
    for i, j, value in cells:
        assert a[i, j] == pytest.approx(value, rel=1e-12)


def test_toolbox_leo_shortcut_on_a_unit_sun_vector():
    # earthfov.m: "if satsph(3) < CONST.EMR, satsph(3) = satsph(3) + CONST.EMR" -- a unit Sun vector
    # gets a sunlit cap of acos(EMR / (EMR + 1)) = 0.03 deg: only the cell right under it. Put the Sun
    # and the satellite over the centre of cell (120, 150): that single cell is its own sub-solar cell
    # (cos(phi_in) = 1) and is seen at nadir (cos(phi_out) = 1), so albedo.m gives
    # 1366.9 * A * rho / (pi * (r - EMR)^2).
    toms = ReflectivityMap.toms2005()
    lat, lon = np.radians(toms.lat_deg[120]), np.radians(toms.lon_deg[150])
    u = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    r = 7000e3
    a = albedo_cells(r * u, u, toms, toolbox_compatible=True)
    assert np.count_nonzero(a) == 1
    emr = 6371.01e3
    area = emr ** 2 * np.radians(1.25) * (np.sin(lat + np.radians(0.5)) - np.sin(lat - np.radians(0.5)))
    assert a[120, 150] == pytest.approx(1366.9 * area * toms.values[120, 150] / (np.pi * (r - emr) ** 2), rel=1e-9)


def test_toolbox_and_physical_modes_agree_roughly_in_leo():
    # Same model, different quirks: sub-solar cell instead of the Sun, 1366.9 vs 1366.1 W/m^2.
    sat = (R + 668e3) * _unit([0.3, 0.4, 0.5])
    sun = SUN_DIST * _unit([0.6, 0.2, 0.3])
    tb = albedo_cells(sat, sun, toolbox_compatible=True).sum()
    ph = albedo_cells(sat, sun).sum()
    assert tb == pytest.approx(ph, rel=0.02)


def test_matlab_round_is_half_away_from_zero():
    # MATLAB documentation of round: "rounds half away from zero" (numpy rounds half to even).
    assert [_matlab_round(x) for x in (0.5, 1.5, 2.5, -0.5, -2.5, 2.4999999999999996)] == [1, 2, 3, -1, -3, 2]
    assert _matlab_round(0.49999999999999994) == 0   # floor(x + 0.5) would give 1


def test_toolbox_mode_refuses_what_the_toolbox_cannot_do():
    sat, sun = np.array([0, 0, 8e6]), np.array([0, 1e9, 0])
    with pytest.raises(ValueError, match="fixes E_sun"):
        albedo_cells(sat, sun, toolbox_compatible=True, e_sun_w_m2=1361.0)
    shifted = ReflectivityMap.from_array(np.full((18, 36), 0.3), lon_deg=np.arange(36) * 10.0 + 5)
    with pytest.raises(ValueError, match="toolbox's layout"):
        albedo_cells(sat, sun, shifted, toolbox_compatible=True)


# ---- bad input: one test each ------------------------------------------------------------------
@pytest.mark.parametrize("toolbox", [False, True])
def test_satellite_inside_the_earth(toolbox):
    with pytest.raises(ValueError, match="inside the Earth"):
        albedo_cells(np.array([0.0, 0.0, 6000e3]), np.array([SUN_DIST, 0, 0]), toolbox_compatible=toolbox)


def test_non_finite_vectors():
    with pytest.raises(ValueError, match="non-finite"):
        albedo_cells(np.array([np.nan, 0.0, 7e6]), np.array([SUN_DIST, 0, 0]))
    with pytest.raises(ValueError, match="non-finite"):
        albedo_cells(np.array([0.0, 0.0, 7e6]), np.array([np.inf, 0, 0]))
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        albedo_cells(np.zeros((2, 3)), np.array([SUN_DIST, 0, 0]))


def test_map_of_the_wrong_shape():
    with pytest.raises(ValueError, match="2-D array"):
        albedo_cells(np.array([0, 0, 7e6]), np.array([SUN_DIST, 0, 0]), np.ones((180, 288, 1)))


def test_map_with_negative_or_nan_values():
    bad = np.full((180, 288), 0.3)
    bad[10, 20] = -0.1
    with pytest.raises(ValueError, match="negative"):
        albedo_cells(np.array([0, 0, 7e6]), np.array([SUN_DIST, 0, 0]), bad)
    bad[10, 20] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        albedo_cells(np.array([0, 0, 7e6]), np.array([SUN_DIST, 0, 0]), bad)


@pytest.mark.parametrize("toolbox", [False, True])
def test_sun_at_the_earth_centre(toolbox):
    with pytest.raises(ValueError, match="Earth's centre"):
        albedo_cells(np.array([0, 0, 7e6]), np.zeros(3), toolbox_compatible=toolbox)
