"""Tests of the estimators beyond the thesis (estimators.advanced) and the on-board albedo model (simcore.radiometry.onboard).

Oracles: noise-free readings built here from the thesis' sensor model (cosine diodes, the
eq. 4.15 FOV response, effective irradiance E_S0, sec. 4.2.1) plus synthetic albedo whose
value is known by construction; the conditions for exactness are derived in the comments.
The on-board prediction is checked against the closed-form irradiance of a uniformly
reflecting Lambertian Earth at full phase, integrated here with scipy.
"""
import numpy as np
import pytest
from scipy.integrate import quad

from estimators.advanced import model_albedo_estimate, opposite_pairs, smart_select_estimate
from estimators.metrics import angle_error_deg
from estimators.sun_vector import wls_estimate

E_S0 = 188.1          # BPW34FS effective normal-Sun irradiance, thesis table 3.2.3
CUBE = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])  # SPEC sec. 5 order
EQ415_C0 = 0.12       # thesis eq. 4.15 cut-off cosine


def tilted_normals(tilt_deg):
    """Return the 14 normals of thesis config "tilt X" (SPEC sec. 5: panels +x, +y, -x, -y, then top, bottom)."""
    x = np.radians(tilt_deg)
    rows = []
    for phi_deg, pattern in [(0, [(-1, -1), (0, 1), (1, -1)]), (90, [(-1, 1), (0, -1), (1, 1)]),
                             (180, [(-1, -1), (0, 1), (1, -1)]), (270, [(-1, 1), (0, -1), (1, 1)])]:
        for s_az, s_el in pattern:
            az, el = np.radians(phi_deg) + s_az * x, s_el * x
            rows.append([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return np.array(rows + [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])


def eq415(c, fov_deg):
    """Thesis eq. 4.15 response to the cosine c (FOV 90: the plain clipped cosine)."""
    cf = np.cos(np.radians(fov_deg))
    if fov_deg >= 90:
        return np.clip(c, 0.0, None)
    return np.where(c >= cf, c, np.where(c >= EQ415_C0, c * (c - EQ415_C0) / (cf - EQ415_C0), 0.0))


def random_dirs(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rank3(normals_sel):
    return np.linalg.matrix_rank(normals_sel, tol=1e-6) == 3


# ---- (a) smart selection -------------------------------------------------------------------
def test_opposite_pairs_of_the_cube_and_of_tilt20():
    np.testing.assert_array_equal(opposite_pairs(CUBE), [[0, 2], [1, 3], [4, 5]])
    np.testing.assert_array_equal(opposite_pairs(tilted_normals(20)), [[12, 13]])   # only top/bottom


@pytest.mark.parametrize("method", ["difference", "brightest", "blend"])
def test_smart_select_exact_without_albedo_on_the_cube(rng, method):
    s = random_dirs(rng, 500)
    # Directions in the coordinate planes / on the axes: only 2 or 1 faces see the Sun.
    s[:5] = [[1, 0, 0], [0, -1, 0], [0.6, 0.8, 0], [0, 0.6, -0.8], [-0.8, 0, 0.6]]
    e = E_S0 * eq415(s @ CUBE.T, 90.0)
    s_hat, valid = smart_select_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0, method=method)
    n_seeing = np.sum(s @ CUBE.T > 0, axis=1)       # faces lit by the Sun (closed form)
    np.testing.assert_array_equal(valid, n_seeing >= 3)
    assert n_seeing[5:].min() == 3                  # random directions are generic
    np.testing.assert_allclose(s_hat[valid], s[valid], atol=1e-12)
    assert np.all(np.isnan(s_hat[~valid]))


def test_smart_select_exact_without_albedo_on_tilt20_fov70(rng):
    h = tilted_normals(20)
    live = np.ones(14, bool)
    live[[0, 1, 12]] = False          # dead diodes leave gaps in the 3-diode coverage (and unpair -z)
    s = random_dirs(rng, 2000)
    e = E_S0 * eq415(s @ h.T, 70.0) * live
    s_hat, valid = smart_select_estimate(e, h, fov_deg=70.0, e_s0=E_S0, live=live)
    # A diode sees the Sun (reads >= E_S0 cos FOV) iff the Sun is within its FOV cone (eq. 4.15).
    sees = (s @ h.T >= np.cos(np.radians(70.0))) & live
    expected = np.array([sees[i].sum() >= 3 and rank3(h[sees[i]]) for i in range(len(s))])
    np.testing.assert_array_equal(valid, expected)
    assert expected.any() and not expected.all()
    np.testing.assert_allclose(s_hat[valid], s[valid], atol=1e-12)


def test_difference_cancels_albedo_common_to_opposite_faces(rng):
    s = random_dirs(rng, 300)
    direct = E_S0 * eq415(s @ CUBE.T, 90.0)
    common = rng.uniform(0.0, 60.0, size=(300, 3))          # per axis, the same on both faces
    e = direct + common[:, [0, 1, 0, 1, 2, 2]]
    s_hat, valid = smart_select_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0, method="difference")
    assert valid.all()     # every face reads > 0 = E_S0 cos 90: every pair channel is used
    np.testing.assert_allclose(s_hat, s, atol=1e-12)
    # The other channels keep part of it, so this is a real test of the cancellation.
    s_b, _ = smart_select_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0, method="brightest")
    assert np.median(angle_error_deg(s_b, s)) > 1.0


def test_difference_equals_thesis_wls_on_the_cube_when_all_faces_read(rng):
    # Eq. 4.30 with W = diag(E): H^T W H = diag(E_+ + E_-), H^T W E = (E_+^2 - E_-^2) per axis,
    # so x = E_+ - E_-: the difference channel IS the thesis' WLS for the cube.
    e = rng.uniform(1.0, 200.0, size=(100, 6))
    s_d, _ = smart_select_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0, method="difference")
    s_w, _ = wls_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0)
    np.testing.assert_allclose(s_d, s_w, atol=1e-12)


def test_smart_select_is_thesis_wls_without_opposite_diodes(rng):
    h = tilted_normals(20)[:12]                     # the side panels only: no opposite pair
    e = rng.uniform(0.0, 200.0, size=(300, 12))
    s_a, v_a = smart_select_estimate(e, h, fov_deg=70.0, e_s0=E_S0)
    s_b, v_b = wls_estimate(e, h, fov_deg=70.0, e_s0=E_S0)
    np.testing.assert_array_equal(v_a, v_b)
    np.testing.assert_allclose(s_a[v_a], s_b[v_b], atol=1e-12)


def test_blend_channel_value():
    # One epoch, Sun (0.6, 0.48, 0.64), albedo 20 on -x only: channel x = b - d^2/b.
    s = np.array([0.6, 0.48, 0.64])
    e = E_S0 * np.clip(CUBE @ s, 0, None)
    e[2] += 20.0
    b, d = E_S0 * 0.6, 20.0
    expected = np.array([b - d * d / b, E_S0 * 0.48, E_S0 * 0.64])
    s_hat, valid = smart_select_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0, method="blend")
    assert valid[0]
    np.testing.assert_allclose(s_hat[0], expected / np.linalg.norm(expected), atol=1e-12)


def test_smart_select_dead_partner_becomes_single_channel(rng):
    s = random_dirs(rng, 400)
    e = E_S0 * eq415(s @ CUBE.T, 90.0)
    live = np.array([True, True, False, True, True, True])   # -x dead
    e[:, 2] = 0.0
    s_hat, valid = smart_select_estimate(e, CUBE, fov_deg=90.0, e_s0=E_S0, live=live, method="difference")
    # With -x dead, the x component is known only where +x sees the Sun.
    expected = (s[:, 0] > 0)
    np.testing.assert_array_equal(valid, expected)
    np.testing.assert_allclose(s_hat[valid], s[valid], atol=1e-12)


def test_smart_select_shapes_and_misuse():
    s_hat, valid = smart_select_estimate(E_S0 * np.array([0.6, 0.48, 0, 0, 0.64, 0]), CUBE, fov_deg=90.0,
                                         e_s0=E_S0)
    assert s_hat.shape == (1, 3) and valid.shape == (1,)
    with pytest.raises(ValueError, match="method"):
        smart_select_estimate(np.ones((2, 6)), CUBE, fov_deg=90.0, e_s0=E_S0, method="best")


# ---- (b) model-albedo estimator -----------------------------------------------------------
def synthetic(rng, h, fov_deg, n):
    """Return Sun vectors, direct readings (eq. 4.15) and an arbitrary known albedo (N, K) >= 0."""
    s = random_dirs(rng, n)
    direct = E_S0 * eq415(s @ h.T, fov_deg)
    albedo = rng.uniform(0.0, 50.0, size=direct.shape) * (rng.uniform(size=direct.shape) < 0.7)
    return s, direct, albedo


def expected_valid(s, h, fov_deg, live=None):
    sees = s @ h.T >= np.cos(np.radians(fov_deg))
    if live is not None:
        sees &= live
    return np.array([sees[i].sum() >= 3 and rank3(h[sees[i]]) for i in range(len(s))])


@pytest.mark.parametrize("fit_gain", [False, True])
def test_model_albedo_exact_with_perfect_prediction(rng, fit_gain):
    h = tilted_normals(20)
    s, direct, albedo = synthetic(rng, h, 70.0, 1500)
    s_hat, valid = model_albedo_estimate(direct + albedo, h, albedo, fov_deg=70.0, e_s0=E_S0, fit_gain=fit_gain)
    # After exact removal the readings are eq. 4.15 direct light: the Sun diodes are those within the FOV.
    exp = expected_valid(s, h, 70.0)
    np.testing.assert_array_equal(valid, exp)
    np.testing.assert_allclose(s_hat[valid], s[valid], atol=1e-9)


@pytest.mark.parametrize("k_true", [0.5, 1.7])
def test_model_albedo_fits_an_unknown_gain(rng, k_true):
    h = tilted_normals(20)
    s, direct, albedo = synthetic(rng, h, 70.0, 1500)
    pred = albedo / k_true                       # the on-board map is off by the factor k_true
    e = direct + albedo
    s_hat, valid, det = model_albedo_estimate(e, h, pred, fov_deg=70.0, e_s0=E_S0, fit_gain=True, n_iter=4,
                                              return_details=True)
    exp = expected_valid(s, h, 70.0)
    # The gain is identifiable where the dark diodes (beyond the cut-off + margin) carry predicted
    # albedo that the Sun terms cannot explain; demand exactness there.
    ok = valid & exp & (det["n_dark"] >= 1)
    assert ok.mean() > 0.8
    np.testing.assert_allclose(det["gain"][ok], k_true, rtol=1e-9)
    np.testing.assert_allclose(s_hat[ok], s[ok], atol=1e-9)
    # Without the gain fit the same data give a visibly wrong Sun vector.
    s_ng, _ = model_albedo_estimate(e, h, pred, fov_deg=70.0, e_s0=E_S0, fit_gain=False)
    assert np.nanmean(angle_error_deg(s_ng[ok], s[ok])) > 0.5


def test_model_albedo_invalid_where_too_few_diodes_see_the_sun(rng):
    h = tilted_normals(20)
    live = np.ones(14, bool)
    live[0] = False                               # the thesis' dead diode
    s, direct, albedo = synthetic(rng, h, 70.0, 1500)
    direct[:, 0] = 0.0
    for fit_gain in (False, True):
        s_hat, valid = model_albedo_estimate(direct + albedo, h, albedo, fov_deg=70.0, e_s0=E_S0, live=live,
                                             fit_gain=fit_gain)
        exp = expected_valid(s, h, 70.0, live)
        assert (~exp).sum() > 10
        np.testing.assert_array_equal(valid, exp)
        assert np.all(np.isnan(s_hat[~valid]))
        np.testing.assert_allclose(s_hat[valid], s[valid], atol=1e-9)


def test_model_albedo_without_prediction_is_invalid():
    h = tilted_normals(20)
    e = E_S0 * eq415(h @ np.array([0.6, 0.0, 0.8]), 70.0)
    pred = np.full((1, 14), np.nan)
    s_hat, valid = model_albedo_estimate(e, h, pred, fov_deg=70.0, e_s0=E_S0)
    assert not valid[0] and np.all(np.isnan(s_hat))
    with pytest.raises(ValueError, match="E_alb_pred"):
        model_albedo_estimate(e, h, np.zeros((1, 13)), fov_deg=70.0, e_s0=E_S0)


def test_model_albedo_exact_on_the_cube_with_gain(rng):
    # FOV 90: the threshold E_S0 cos 90 = 0 cannot separate; the geometric selection must.
    s, direct, albedo = synthetic(rng, CUBE, 90.0, 800)
    s_hat, valid = model_albedo_estimate(direct + albedo, CUBE, albedo / 1.3, fov_deg=90.0, e_s0=E_S0)
    # Exact where 3 faces see the Sun clearly and a face clearly away from it carries albedo: 15 deg
    # from the selection boundaries (the margin, 5 deg, plus the error of the gain-free first step).
    c = s @ CUBE.T
    clear = np.sum(c > np.sin(np.radians(15.0)), axis=1) == 3
    # The three Sun faces fix S exactly and tell nothing about k; k is fitted only where the dark
    # faces carry more than GAIN_INFO_RTOL (1e-3) of the sum of a^2 -- ask for 1e-2.
    a2 = (albedo / 1.3) ** 2
    dark_alb = np.sum(np.where(c < -np.sin(np.radians(15.0)), a2, 0.0), axis=1) > 1e-2 * a2.sum(axis=1)
    ok = clear & dark_alb
    assert ok.mean() > 0.2 and valid[ok].all()
    np.testing.assert_allclose(s_hat[ok], s[ok], atol=1e-9)


# ---- on-board prediction ---------------------------------------------------------------------
def test_previous_attitude_is_stale_and_seeded():
    from simcore.radiometry.onboard import previous_attitude
    rng = np.random.default_rng(1)
    q = rng.normal(size=(4000, 4))
    from simcore.environment.attitude import quat_to_matrix
    R = quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))
    R1 = previous_attitude(R, lag_steps=1)
    assert np.all(np.isnan(R1[0]))
    np.testing.assert_array_equal(R1[1:], R[:-1])
    with pytest.raises(ValueError, match="true attitude"):
        previous_attitude(R, lag_steps=0)
    sigma = 2.0
    a = previous_attitude(R, lag_steps=0, sigma_deg=sigma, seed=7)
    b = previous_attitude(R, lag_steps=0, sigma_deg=sigma, seed=7)
    np.testing.assert_array_equal(a, b)
    # Error angle^2 = |omega|^2 ~ sigma^2 chi^2_3: mean 3 sigma^2, variance 6 sigma^4.
    rel = np.einsum("nji,njk->nik", R, a)
    ang = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
    sig = np.radians(sigma)
    z = (np.mean(ang ** 2) - 3 * sig ** 2) / np.sqrt(6 * sig ** 4 / len(ang))
    assert abs(z) < 4


def lambert_full_phase_nadir_plate(rho, r, radius):
    """Irradiance (per unit E_sun) on a nadir-facing plate at distance r from a Lambertian sphere, Sun behind.

    E/E_sun = (rho/pi) int cos(i) cos(e) cos(p) / d^2 dA over the visible cap; with the Sun at the
    sub-satellite point the incidence angle i is the central angle g; d^2 = R^2 + r^2 - 2 R r cos g,
    cos e = (r cos g - R)/d, cos p = (r - R cos g)/d, dA = 2 pi R^2 sin g dg, g in [0, acos(R/r)].
    """
    def f(g):
        d2 = radius ** 2 + r ** 2 - 2 * radius * r * np.cos(g)
        d = np.sqrt(d2)
        return (np.cos(g) * (r * np.cos(g) - radius) / d * (r - radius * np.cos(g)) / d / d2
                * 2 * np.pi * radius ** 2 * np.sin(g))
    val, _ = quad(f, 0.0, np.arccos(radius / r), epsabs=0, epsrel=1e-12, limit=200)
    return rho / np.pi * val


def test_lambert_oracle_far_field_is_the_geometric_albedo():
    # Far away, a Lambertian sphere at full phase has geometric albedo p = 2/3 rho (e.g. Russell 1916;
    # Seager, "Exoplanet Atmospheres", 2010, eq. 3.39): E/E_sun = p (R/r)^2; the leading finite-distance
    # correction is O(R/r).
    radius = 6371.01e3
    ratio = lambert_full_phase_nadir_plate(1.0, 1000 * radius, radius) / (2 / 3 * 1e-6)
    assert abs(ratio - 1) < 2e-3


def test_predict_albedo_matches_lambert_sphere_closed_form():
    from simcore.shapes.aperture import WellAperture, diode_frame
    from simcore.constants import AU_M, R_EARTH_MEAN_M
    from simcore.environment.maps import ReflectivityMap
    from simcore.radiometry.onboard import predict_albedo_effective

    rho = 0.3
    refl = ReflectivityMap.from_array(np.full((180, 360), rho))
    r = R_EARTH_MEAN_M + 665e3
    geo = {"r_sat_ecef_m": np.array([[r, 0.0, 0.0]]), "r_sun_ecef_m": np.array([[AU_M, 0.0, 0.0]]),
           "R_ecef_from_gcrs": np.eye(3)[None]}
    frames = np.stack([diode_frame([-1.0, 0.0, 0.0]), diode_frame([0.0, 0.0, 1.0])])   # nadir, and edge-on
    pred = predict_albedo_effective(geo, np.eye(3)[None], (frames, WellAperture.bare()), refl, e_s0_w_m2=E_S0)
    expected = E_S0 * lambert_full_phase_nadir_plate(rho, r, refl.radius_m)
    assert pred.shape == (1, 2)
    # 1 x 1 deg cells evaluated at their centres: agreement to 1e-4 (the smooth integrand makes the
    # midpoint sum converge fast; the cap edge contributes ~cos(i) cos(e) ~ 0)
    np.testing.assert_allclose(pred[0, 0], expected, rtol=1e-4)
    assert 0 < pred[0, 1] < pred[0, 0]


def test_predict_albedo_nan_attitude_gives_nan_row():
    from simcore.shapes.aperture import WellAperture, diode_frame
    from simcore.constants import AU_M, R_EARTH_MEAN_M
    from simcore.radiometry.onboard import predict_albedo_effective

    r = R_EARTH_MEAN_M + 665e3
    geo = {"r_sat_ecef_m": np.array([[r, 0, 0], [r, 0, 0]]), "r_sun_ecef_m": np.array([[AU_M, 0, 0]] * 2),
           "R_ecef_from_gcrs": np.stack([np.eye(3)] * 2)}
    R_est = np.stack([np.full((3, 3), np.nan), np.eye(3)])
    pred = predict_albedo_effective(geo, R_est, (diode_frame([-1.0, 0, 0])[None], WellAperture.bare()),
                                    "toms2005")
    assert np.isnan(pred[0]).all() and np.isfinite(pred[1]).all() and pred[1, 0] > 0


def test_evaluate_cross_map_table_on_a_short_window():
    from simcore.studies.cross_map import evaluate_cross_map
    rows, errors = evaluate_cross_map("tilt20_fov70", start_s=20000, stop_s=20030, return_errors=True)
    assert len(rows) == 2 * 6          # two (truth, on-board) pairings x six estimators
    keys = {"truth_map", "onboard_map", "estimator", "n_sunlit", "n_invalid", "mean_deg", "p95_deg", "max_deg"}
    np.testing.assert_array_equal(errors["t_s"], np.arange(19999.0, 20030.0))   # one leading sample (lag 1 s)
    assert not errors["sunlit"][0]
    for row in rows:
        assert set(row) == keys and row["truth_map"] != row["onboard_map"]
        assert row["n_sunlit"] == errors["sunlit"].sum() <= 30
        err = errors[(row["truth_map"], row["onboard_map"], row["estimator"])]
        assert err.shape == (31,)
        if row["n_sunlit"] > row["n_invalid"]:
            np.testing.assert_allclose(row["mean_deg"], np.nanmean(err[errors["sunlit"]]))
