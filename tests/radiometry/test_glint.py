"""Ocean sun glint (issue 17 item 3): the Cox-Munk BRDF against closed forms and independent quadratures, the
analytic model against a quadrature of its own, the renderer against the analytic model, and runs with --glint."""
import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from simcore.errors import InvalidInputError
from simcore.radiometry import glint as gl

N_WATER = 1.33


def _fresnel_snell(theta_i_rad, n=N_WATER):
    """Unpolarised Fresnel reflectance from Snell's law and the s/p amplitude ratios (Born & Wolf sec. 1.5.2),
    written apart from the module's closed form."""
    ti = np.maximum(np.asarray(theta_i_rad, float), 1e-9)   # (0/0 at normal incidence: its limit below)
    tt = np.arcsin(np.sin(ti) / n)
    rs = np.sin(ti - tt) / np.sin(ti + tt)
    rp = np.tan(ti - tt) / np.tan(ti + tt)
    return np.where(ti > 1e-6, 0.5 * (rs ** 2 + rp ** 2), ((n - 1) / (n + 1)) ** 2)


def _smith_g(mu_i, mu_o, mss):
    """Return Smith's height-correlated shadowing-masking factor 1 / (1 + Lambda_i + Lambda_o) from Lambda's
    definition, not the module's erf form: 1 + Lambda(theta) = E[max(0, cos theta - sin theta z)] / cos theta, the
    mean area of the facets facing a direction over the mean surface's, with z the slope along the direction's
    azimuth, N(0, mss / 2) for Cox-Munk's isotropic slopes (Smith 1967): the normal partial expectation
    E[max(0, b - z)] = b Phi(b / tau) + tau phi(b / tau), b = cot theta, tau^2 = mss / 2."""
    from scipy.stats import norm
    tau = np.sqrt(mss / 2.0)

    def one_plus_lambda(mu):
        mu = np.clip(np.asarray(mu, float), 1e-5, 1.0)
        tan = np.sqrt(1.0 - mu * mu) / mu
        b = 1.0 / np.maximum(tan, 1e-300)
        return norm.cdf(b / tau) + tau * tan * norm.pdf(b / tau)
    return 1.0 / (one_plus_lambda(mu_i) + one_plus_lambda(mu_o) - 1.0)


def _hemispherical(theta_s_deg, mss, index=N_WATER, n_mu=1000, n_phi=1024):
    """Return integral over the upper hemisphere of f(s, v) cos(theta_v) d omega_v: Gauss-Legendre in
    cos(theta_v) times the midpoint rule in azimuth (the lobe is ~2 sigma = 20 deg wide at 7 m/s: hundreds
    of nodes across it)."""
    th = np.radians(theta_s_deg)
    s = np.array([np.sin(th), 0.0, np.cos(th)])
    x, w = np.polynomial.legendre.leggauss(n_mu)
    mu, w_mu = 0.5 * (x + 1.0), 0.5 * w
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    MU, PH = np.meshgrid(mu, phi, indexing="ij")
    st = np.sqrt(1 - MU ** 2)
    v = np.stack([st * np.cos(PH), st * np.sin(PH), MU], axis=-1)
    f = gl.brdf(np.array([0.0, 0.0, 1.0]), s, v, mss, index)
    return float(np.sum(f * MU * w_mu[:, None]) * (2 * np.pi / n_phi))


def _facet_average(theta_s_deg, mss, n=N_WATER, half_width_sigmas=8.0, m=1001):
    """Return the same albedo counted in slope space, without the BRDF: the mean over Cox-Munk's facets
    (Gaussian slopes, variance mss/2 per axis) of their Fresnel share at their own incidence angle times their
    area seen from the Sun per unit area of the mean surface, ((s . n_f) / cos beta) / cos theta_s, over the
    facets that face the Sun and mirror it above the horizon (midpoint rule on a slope grid)."""
    th = np.radians(theta_s_deg)
    s = np.array([np.sin(th), 0.0, np.cos(th)])
    half = half_width_sigmas * np.sqrt(mss / 2)
    z = (np.arange(m) + 0.5) / m * 2 * half - half
    zx, zy = np.meshgrid(z, z, indexing="ij")
    p = np.exp(-(zx ** 2 + zy ** 2) / mss) / (np.pi * mss)
    nf = np.stack([-zx, -zy, np.ones_like(zx)], axis=-1)
    nf /= np.linalg.norm(nf, axis=-1, keepdims=True)
    c = nf @ s
    r_z = 2 * c * nf[..., 2] - s[2]                  # the mirrored ray's vertical component
    ok = (c > 0) & (r_z > 0)
    cc = np.clip(c, 1e-12, 1.0)
    rho = _fresnel_snell(np.arccos(cc), n)
    area = (c / nf[..., 2]) / np.cos(th)
    g = _smith_g(np.cos(th), r_z, mss)             # hidden from the Sun or from the mirrored ray's observer
    return float(np.sum(np.where(ok, rho * area * p * g, 0.0)) * (2 * half / m) ** 2)


# ---- Fresnel ------------------------------------------------------------------------------------
def test_fresnel_normal_and_grazing():
    # ((n - 1)/(n + 1))^2 = (0.33/2.33)^2 = 0.020060 for n = 1.33 (normal incidence); 1 at grazing
    assert gl.fresnel_reflectance(1.0) == pytest.approx((0.33 / 2.33) ** 2, rel=1e-12)
    assert gl.fresnel_reflectance(1.0) == pytest.approx(0.02006, abs=5e-6)
    assert gl.fresnel_reflectance(0.0) == pytest.approx(1.0, abs=1e-12)
    # a wrong index fails the normal-incidence value: n = 1.5 gives 0.04
    assert gl.fresnel_reflectance(1.0, index=1.5) != pytest.approx(0.02006, abs=5e-6)


def test_fresnel_closed_form_equals_snell():
    th = np.radians(np.linspace(1.0, 89.0, 89))
    assert np.allclose(gl.fresnel_reflectance(np.cos(th)), _fresnel_snell(th), rtol=1e-10, atol=0)
    assert not np.allclose(gl.fresnel_reflectance(np.cos(th), index=1.5), _fresnel_snell(th), rtol=1e-3)


# ---- slope distribution -------------------------------------------------------------------------
def test_mean_square_slope_cox_munk():
    # Cox & Munk 1954 (J. Opt. Soc. Am. 44, 838), clean surface: sigma^2 = 0.003 + 5.12e-3 W
    assert gl.mean_square_slope(0.0) == pytest.approx(0.003)
    assert gl.mean_square_slope(7.0) == pytest.approx(0.003 + 0.00512 * 7)
    assert gl.mean_square_slope(10.0) == pytest.approx(0.0542)


@pytest.mark.parametrize("wind", [0.0, 2.0, 7.0, 14.0])
def test_slope_pdf_normalised(wind):
    mss = gl.mean_square_slope(wind)
    half, m = 10 * np.sqrt(mss), 2001
    z = (np.arange(m) + 0.5) / m * 2 * half - half
    zx, zy = np.meshgrid(z, z, indexing="ij")
    total = gl.slope_pdf(zx, zy, mss).sum() * (2 * half / m) ** 2
    assert total == pytest.approx(1.0, abs=1e-6)
    # and its variance per axis is sigma^2 / 2 (Cox & Munk's sigma^2 = sigma_u^2 + sigma_c^2)
    var_x = (gl.slope_pdf(zx, zy, mss) * zx ** 2).sum() * (2 * half / m) ** 2
    assert var_x == pytest.approx(mss / 2, rel=1e-6)


# ---- the BRDF ---------------------------------------------------------------------------------
def _dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v


def test_reciprocity():
    rng = np.random.default_rng(17)
    a, b = _dirs(rng, 5000), _dirs(rng, 5000)
    nz = np.array([0.0, 0.0, 1.0])
    mss = gl.mean_square_slope(7.0)
    fab, fba = gl.brdf(nz, a, b, mss), gl.brdf(nz, b, a, mss)
    assert np.all(fab >= 0) and np.count_nonzero(fab > 1e-3) > 100
    assert np.allclose(fab, fba, rtol=1e-12, atol=0)
    # the test catches a common slip: Fresnel at the Sun's zenith instead of the facet's local angle (s . h)
    def wrong(x, y):
        cos_h = np.sqrt(0.5 * (1 + np.sum(x * y, axis=1)))
        return gl.brdf(nz, x, y, mss) * gl.fresnel_reflectance(x[:, 2]) / gl.fresnel_reflectance(cos_h)
    assert not np.allclose(wrong(a, b), wrong(b, a), rtol=1e-12, atol=0)


def test_peak_at_the_specular_direction():
    mss = gl.mean_square_slope(7.0)
    for zen in (20.0, 40.0, 60.0):
        th = np.radians(zen)
        s = np.array([np.sin(th), 0.0, np.cos(th)])
        thv = np.radians(np.linspace(0.05, 89.95, 1799))
        phv = np.radians(np.linspace(-180, 180, 721))
        T, P = np.meshgrid(thv, phv, indexing="ij")
        v = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
        # the facets' share f cos(theta_v) / rho(local angle) is largest where the flat sea mirrors the Sun:
        # theta_v = theta_s, azimuth opposite (facet tilt beta = 0, where p / cos^4(beta) peaks for sigma^2 < 1/2)
        cos_h = np.sqrt(0.5 * (1 + v @ s))
        g = gl.brdf([0, 0, 1.0], s, v, mss) * np.cos(T) / _fresnel_snell(np.arccos(cos_h))
        i, j = np.unravel_index(np.argmax(g), g.shape)
        assert np.degrees(thv[i]) == pytest.approx(zen, abs=0.05)
        assert abs(abs(np.degrees(phv[j])) - 180.0) <= 0.5
        # f cos(theta_v) itself peaks in the same plane, farther from the zenith (Fresnel grows with the local angle)
        i, j = np.unravel_index(np.argmax(g * _fresnel_snell(np.arccos(cos_h))), g.shape)
        assert np.degrees(thv[i]) >= zen and abs(abs(np.degrees(phv[j])) - 180.0) <= 0.5
        # and its value there is rho(theta_s) / (4 pi sigma^2 cos theta_s) (beta = 0: p(0) = 1 / (pi sigma^2))
        spec = np.array([-np.sin(th), 0.0, np.cos(th)])
        expect = _fresnel_snell(th) / (4 * np.pi * mss * np.cos(th) ** 2) * _smith_g(np.cos(th), np.cos(th), mss)
        assert gl.brdf([0, 0, 1.0], s, spec, mss) == pytest.approx(expect, rel=1e-10)
        assert gl.brdf([0, 0, 1.0], s, spec, mss, index=1.5) != pytest.approx(expect, rel=1e-2)
        assert gl.brdf([0, 0, 1.0], s, spec, 0.003 + 0.0512 * 7) != pytest.approx(expect, rel=1e-2)


def test_zero_below_the_surface():
    mss = gl.mean_square_slope(7.0)
    up, down = np.array([0.3, 0.0, 0.954]), np.array([0.3, 0.0, -0.954])
    assert gl.brdf([0, 0, 1.0], up, down, mss) == 0.0
    assert gl.brdf([0, 0, 1.0], down, up, mss) == 0.0
    assert gl.reflected_cos2(-0.1, 0.5, 0.2, mss) == 0.0


@pytest.mark.parametrize("zen", [20.0, 40.0, 60.0])
def test_hemispherical_reflectance_is_fresnel_on_a_calm_sea(zen):
    # The criterion (2 %): integral f cos(theta_v) d omega_v against Fresnel's rho(theta_s) for n = 1.33
    # (closed form via Snell). It holds for a calm sea (W = 0, sigma^2 = 0.003: +0.1/+0.5/+0.9 %); with wind,
    # tilted facets raise the albedo (see the next test and the module docstring).
    a = _hemispherical(zen, gl.mean_square_slope(0.0))
    rho = float(_fresnel_snell(np.radians(zen)))
    assert a == pytest.approx(rho, rel=0.02)


def test_hemispherical_reflectance_fails_with_wrong_inputs():
    rho40 = float(_fresnel_snell(np.radians(40.0)))
    # sigma^2 with 0.0512 per m/s (ten times Cox-Munk's) at 2 m/s: +9 %
    assert _hemispherical(40.0, 0.003 + 0.0512 * 2) != pytest.approx(rho40, rel=0.02)
    # water index 1.5 instead of 1.33: the BRDF's Fresnel share is that of glass
    assert _hemispherical(40.0, gl.mean_square_slope(0.0), index=1.5) != pytest.approx(rho40, rel=0.02)


def test_hemispherical_reflectance_at_7_m_s_twenty_degrees():
    # the criterion at the wind the CLI examples use: holds at 20 deg (+1.4 %) and 60 (+0.7 %: the waves' masking
    # takes back what the tilted facets add), not at 40 (+6.8 %), where the facet average of the next test is right
    for zen in (20.0, 60.0):
        assert _hemispherical(zen, gl.mean_square_slope(7.0)) == pytest.approx(float(_fresnel_snell(np.radians(zen))),
                                                                                rel=0.02)


@pytest.mark.parametrize("wind", [2.0, 7.0, 14.0])
@pytest.mark.parametrize("zen", [20.0, 40.0, 60.0])
def test_hemispherical_reflectance_is_the_facet_average(zen, wind):
    # In direction space (the BRDF) and in slope space (facets, no BRDF): the same albedo, to the quadratures'
    # accuracy (0.3 %: the slope grid's edge at the horizon cut-off is a step, ~1e-4 of the sum)
    mss = gl.mean_square_slope(wind)
    assert _hemispherical(zen, mss) == pytest.approx(_facet_average(zen, mss), rel=3e-3)


def test_facet_average_fails_with_the_wrong_slope_law():
    mss = gl.mean_square_slope(7.0)
    assert _hemispherical(40.0, mss) != pytest.approx(_facet_average(40.0, 0.003 + 0.0512 * 7), rel=3e-3)


# ---- input ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "x"])
def test_bad_wind_is_a_user_error(bad):
    with pytest.raises(InvalidInputError, match="--glint"):
        gl.check_wind(bad)
    with pytest.raises(InvalidInputError):
        gl.SunGlint(bad)


def test_winds_beyond_hurricane_force_are_refused_and_a_calm_sea_is_accepted():
    with pytest.raises(InvalidInputError, match="above the 30 m/s"):
        gl.check_wind(30.01)
    assert gl.check_wind(0.0) == 0.0 and gl.check_wind(gl.MAX_WIND_M_S) == 30.0


@pytest.mark.parametrize("wind, altitude_km, cell_deg, base, want", [
    # spot half-width 2 sigma h against SPOT_CELLS = 3 sub-cells of 1.25 deg (139.0 km on the 6371.01 km sphere):
    (7.0, 665.0, 1.25, 2, 2),    # sigma^2 = 0.03884: 262 km >= 3 x 69.5 km at 2 x 2
    (0.0, 665.0, 1.25, 2, 8),    # sigma^2 = 0.003: 72.8 km; 3 x 34.7 km = 104 > 72.8 at 4 x 4, 52.1 at 8 x 8
    (1.0, 665.0, 1.25, 2, 4),    # 119.8 km: above 104 (4 x 4), below 208 (2 x 2)
    (1.0, 665.0, 1.25, 4, 4),    # cloud weather's 4 x 4 is the floor
])
def test_the_check_refines_until_the_glint_spot_spans_its_cells(wind, altitude_km, cell_deg, base, want):
    assert gl.check_refine(wind, altitude_km * 1e3, cell_deg, base) == want


CALM = ["--config", "tilt0_fov90", "--map", "uniform:0", "--start", "2016-07-02T15:27:00Z"]   # issue 33's calm sea
#       (the North Atlantic): at --glint 0 its check on 2 x 2 sub-cells failed albedo spread (p = 1.6e-262)


def test_a_calm_sea_run_checks_on_cells_that_resolve_its_spot():
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import PreparedRun
    opts = RunOptions(config="tilt0_fov90", reflectivity="uniform:0", start="2016-07-02T15:27:00Z", duration_s=2.0)
    assert PreparedRun(dataclasses.replace(opts, glint=0.0)).check_refine == 8     # was 2, as without glint
    assert PreparedRun(dataclasses.replace(opts, glint=7.0)).check_refine == 2
    assert PreparedRun(opts).check_refine == 2


@pytest.mark.slow
def test_the_calm_sea_run_passes_its_check(tmp_path):
    # issue 33's acceptance: the 600-s run at 0 m/s passes `sunsim validate` (~1 min here)
    r = _sunsim(["run", *CALM, "--glint", "0", "--duration", "600", "-o", "calm.nc"], tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    v = _sunsim(["validate", "calm.nc", "--json"], tmp_path)
    assert v.returncode == 0 and json.loads(v.stdout)["verdict"] == "PASS", v.stdout + v.stderr


def test_a_calm_sea_from_too_low_an_orbit_is_refused_with_the_wind_that_can_be_checked():
    # from 300 km at 0 m/s the spot's half-width is 2 sqrt(0.003) 300 km = 33 km: 16 x 16 sub-cells would be
    # needed; at 8 x 8 a spot of 3 x 17.4 km = 52.1 km needs sigma = 0.0869, sigma^2 = 0.00755: (0.00755 - 0.003) / 0.00512 = 0.89 m/s
    with pytest.raises(InvalidInputError, match=r"half-width ~33 km.*give 0\.9 m/s or more"):
        gl.check_refine(0.0, 300e3, 1.25, 2)
    assert gl.check_refine(0.9, 300e3, 1.25, 2) == 8


# ---- the analytic albedo model with glint (simcore.radiometry.analytic) -------------------------------------
R_M = 6371010.0         # simcore.constants.R_EARTH_MEAN_M, the maps' sphere
E_SUN = 1366.1


def _air_mass(mu):
    """Rozenberg (1966, *Twilight*, p. 159): 1 / (cos z + 0.025 exp(-11 cos z))."""
    mu = np.maximum(mu, 0.0)
    return 1.0 / (mu + 0.025 * np.exp(-11.0 * mu))


def _glint_quadrature(sun_unit, mss, index=N_WATER, altitude_m=665e3, n_g=800, n_psi=1440, tau=gl.GLINT_OPTICAL_DEPTH):
    """Return the glint irradiance (W/m^2) on a bare nadir-facing diode of a satellite over an ocean planet,
    integral of E_sun f(s, v) cos(theta_s) cos(theta_v) cos(theta_d) / d^2 dA over the visible sunlit sphere,
    by Gauss-Legendre in the central angle from the sub-satellite point and the midpoint rule in azimuth; f from
    its definition with the half vector (vectors, not the module's cosines) and Snell's Fresnel."""
    r = np.array([R_M + altitude_m, 0.0, 0.0])
    g_max = np.arccos(R_M / (R_M + altitude_m))
    x, w = np.polynomial.legendre.leggauss(n_g)
    g, w_g = 0.5 * g_max * (x + 1), 0.5 * g_max * w
    psi = (np.arange(n_psi) + 0.5) * (2 * np.pi / n_psi)
    G, P = np.meshgrid(g, psi, indexing="ij")
    nrm = np.stack([np.cos(G), np.sin(G) * np.cos(P), np.sin(G) * np.sin(P)], -1)
    vv = r - R_M * nrm
    d = np.linalg.norm(vv, axis=-1)
    v = vv / d[..., None]
    mu_i, mu_o = nrm @ sun_unit, np.sum(nrm * v, -1)
    h = sun_unit + v
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    cos_b = np.sum(nrm * h, -1)
    p = np.exp(-(1 / cos_b ** 2 - 1) / mss) / (np.pi * mss)
    f_mu_mu = (_fresnel_snell(np.arccos(np.clip(h @ sun_unit, 0, 1)), index) * p / (4 * cos_b ** 4)
               * _smith_g(np.clip(mu_i, 1e-5, 1), np.clip(mu_o, 1e-5, 1), mss)
               * np.exp(-tau * (_air_mass(mu_i) + _air_mass(mu_o))))      # seen through the air, both ways
    cos_d = np.maximum(v[..., 0], 0.0)           # diode normal -x; the direction to the cell is -v
    val = np.where((mu_i > 0) & (mu_o > 0), E_SUN * f_mu_mu * cos_d / d ** 2, 0.0) * R_M ** 2 * np.sin(G)
    return float(np.sum(val * w_g[:, None]) * (2 * np.pi / n_psi))


def _analytic_glint(sun_unit, wind, index=N_WATER, backend="numpy", altitude_m=665e3):
    from simcore.environment.maps import ReflectivityMap
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.radiometry.response import CosineResponse
    from simcore.shapes.aperture import diode_frame
    dark = ReflectivityMap.from_array(np.zeros((180, 288)))      # no diffuse light: the glint alone
    out = diode_irradiance(np.array([[R_M + altitude_m, 0, 0]]), 1.496e11 * sun_unit[None], np.eye(3),
                           diode_frame(np.array([-1.0, 0, 0]))[None], CosineResponse(), map=dark, backend=backend,
                           direct=False, e_sun_w_m2=E_SUN, glint=gl.SunGlint(wind, index, sea=np.ones((180, 288))))
    return float(out.albedo_w_m2[0, 0])


@pytest.mark.parametrize("zen", [10.0, 40.0, 60.0])
def test_analytic_glint_over_an_ocean_planet(zen):
    # The cells' centre rule against the quadrature: -1.3e-5 on the TOMS grid, -3.2e-6 on one of half the cell
    # size (the midpoint rule's h^2); 1e-4 leaves room for neither more nor a wrong term (next test)
    t = np.radians(zen)
    s = np.array([np.cos(t), np.sin(t), 0.0])
    q = _glint_quadrature(s, gl.mean_square_slope(7.0))
    assert q > 10.0                  # ~1.3 % of E_sun: the "1-2 % of E_sun on a nadir diode"
    assert _analytic_glint(s, 7.0) == pytest.approx(q, rel=1e-4)
    assert _analytic_glint(s, 7.0, backend="drjit") == pytest.approx(q, rel=1e-4)


def test_analytic_glint_fails_with_wrong_wind_or_index():
    t = np.radians(40.0)
    s = np.array([np.cos(t), np.sin(t), 0.0])
    q = _glint_quadrature(s, gl.mean_square_slope(7.0))
    assert _analytic_glint(s, 7.0) != pytest.approx(_glint_quadrature(s, 0.003 + 0.0512 * 7), rel=1e-2)
    assert _analytic_glint(s, 7.0, index=1.5) != pytest.approx(q, rel=1e-2)
    # the glint seen without the atmosphere on its paths (tau = 0): ~20 % brighter at 40 deg
    assert _analytic_glint(s, 7.0) != pytest.approx(_glint_quadrature(s, gl.mean_square_slope(7.0), tau=0.0), rel=1e-2)


def test_air_mass_closed_forms():
    # Rozenberg's formula: 1 overhead (to 1e-6: 0.025 exp(-11)), 2 at 60 deg, 40 along the horizon (his value)
    assert gl.air_mass(1.0) == pytest.approx(1.0, abs=1e-6)
    assert gl.air_mass(0.5) == pytest.approx(1.0 / (0.5 + 0.025 * np.exp(-5.5)), rel=1e-12)
    assert gl.air_mass(0.5) == pytest.approx(2.0, rel=5e-4)
    assert gl.air_mass(0.0) == pytest.approx(40.0, rel=1e-12)
    # the glint at the limb with the Sun just behind it (eclipse entry/exit) is the air's to remove: both paths
    # ~35 air masses long
    mss = gl.mean_square_slope(7.0)
    assert gl.reflected_cos2(0.0103, 0.0032, -0.9999, mss, tau=0.1) < 2e-3 * gl.reflected_cos2(0.0103, 0.0032, -0.9999,
                                                                                              mss)


def _orbit(rng, n=40, altitude_m=668e3):
    t = np.linspace(0, 5800, n)
    inc, ang = np.radians(98.0), 2 * np.pi * t / 5900
    r = (R_M + altitude_m) * np.stack([np.cos(ang), np.sin(ang) * np.cos(inc), np.sin(ang) * np.sin(inc)], axis=1)
    sun = np.array([0.6, -0.5, 0.3])
    q, rr = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(rr, axis1=1, axis2=2))[:, None, :]
    q = q * np.sign(np.linalg.det(q))[:, None, None]
    return r, np.broadcast_to(1.496e11 * sun / np.linalg.norm(sun), r.shape).copy(), q


def test_analytic_backends_agree_with_glint():
    # numpy (float64, the responses' own methods) and the Dr.Jit kernel on the TOMS map with GSHHG's sea; the
    # glint alone (with minus without) agrees too, and the kernel without glint is the one it always was
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.shapes.aperture import WellAperture, diode_frame
    rng = np.random.default_rng(3)
    r, s, rot = _orbit(rng)
    normals = rng.normal(size=(6, 3))
    frames = np.stack([diode_frame(n / np.linalg.norm(n)) for n in normals])
    ap = WellAperture.design(70)
    g = gl.SunGlint(7.0)
    kw = dict(direct=False)
    a = diode_irradiance(r, s, rot, frames, ap, backend="numpy", glint=g, **kw).albedo_w_m2
    b = diode_irradiance(r, s, rot, frames, ap, backend="drjit", precision="double", glint=g, **kw).albedo_w_m2
    c = diode_irradiance(r, s, rot, frames, ap, backend="drjit", glint=g, **kw).albedo_w_m2
    a0 = diode_irradiance(r, s, rot, frames, ap, backend="numpy", **kw).albedo_w_m2
    assert np.count_nonzero(a - a0 > 0.5) > 10              # the glint is there, W/m^2 on many diode-epochs
    np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(c, a, rtol=3e-4, atol=1e-3)     # float32 kernel: 1e-3 W/m^2 = 1e-6 E_sun
    b0 = diode_irradiance(r, s, rot, frames, ap, backend="drjit", precision="double", **kw).albedo_w_m2
    np.testing.assert_allclose(b - b0, a - a0, rtol=1e-8, atol=1e-9)


# ---- the renderer's glint against the analytic quadrature ------------------------------------------------------
def _glint_epochs():
    """Return (r_sat, r_sun, R_ecef_from_body, frames (N, 3, 3, 3)): 8 epochs, 665 km up, the Sun 15-55 deg from
    the zenith, random attitudes, three bare diodes each: facing nadir, and tilted 30 and 60 deg toward the Sun's
    azimuth (where the glint spot lies), so that every diode sees a strong glint. Six epochs over random places on
    an ocean planet, two over coasts on the real Earth (the Strait of Sicily, the Gulf of Guinea at Gabon)."""
    from simcore.shapes.aperture import diode_frame
    rng = np.random.default_rng(5)
    up = rng.normal(size=(8, 3))
    for i, (lat, lon) in ((6, (35.5, 13.0)), (7, (-1.0, 8.0))):
        la, lo = np.radians(lat), np.radians(lon)
        up[i] = [np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)]
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    zen = np.radians(np.r_[np.linspace(15, 55, 6), 25, 35])
    perp = np.cross(up, rng.normal(size=(8, 3)))
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    s = np.cos(zen)[:, None] * up + np.sin(zen)[:, None] * perp
    rot = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(8)])
    rot *= np.sign(np.linalg.det(rot))[:, None, None]
    frames = []
    for i in range(8):
        tilt = [np.radians(a) for a in (0, 30, 60)]
        dirs = [np.cos(t) * -up[i] + np.sin(t) * perp[i] for t in tilt]
        frames.append(np.stack([diode_frame(rot[i].T @ d) for d in dirs]))
    return (R_M + 665e3) * up, 1.496e11 * s, rot, np.stack(frames)


def _rendered_glint(wind, index, ocean_planet, i, geo):
    """Return (value, se) (3,) of the rendered glint alone (no diffuse map) on epoch ``i``'s bare diodes, W/m^2."""
    from simcore.render import DiodeSurfaces, Renderer
    r_sat, r_sun, rot, frames = geo
    sea = np.ones((180, 288)) if ocean_planet else None
    rend = Renderer(DiodeSurfaces(np.zeros((3, 3)), frames[i], np.array([2.65e-3, 2.65e-3])), None,
                    reflectivity=np.zeros((180, 288)), e_sun_w_m2=E_SUN, glint=gl.SunGlint(wind, index, sea=sea))
    to_sun = (r_sun[i] - r_sat[i]) / np.linalg.norm(r_sun[i] - r_sat[i])
    res = rend.render((rot[i].T @ to_sun)[None], (rot[i].T @ -r_sat[i])[None], rot[i][None],
                      sun_dir_earth_body=(rot[i].T @ r_sun[i] / np.linalg.norm(r_sun[i]))[None], seed=11 + i,
                      rel_se_albedo=0.002)
    return res.albedo_w_m2[0], res.albedo_se_w_m2[0]


def _analytic_glint_on(wind, index, ocean_planet, i, geo, refine=1):
    """Return the analytic glint (3,) W/m^2 of epoch ``i`` with the cells refined ``refine`` x ``refine``, each
    sub-cell keeping its TOMS cell's sea fraction (the renderer's sea: constant over each map cell)."""
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.radiometry.response import CosineResponse
    from simcore.environment.maps import ReflectivityMap
    from simcore.environment.water import ocean_fraction
    r_sat, r_sun, rot, frames = geo
    sea = np.ones((180, 288)) if ocean_planet else ocean_fraction(ReflectivityMap.from_array(np.zeros((180, 288))))
    sea = np.repeat(np.repeat(sea, refine, axis=0), refine, axis=1)
    return diode_irradiance(r_sat[i], r_sun[i], rot[i], frames[i], CosineResponse(),
                            map=ReflectivityMap.from_array(np.zeros(sea.shape)), direct=False, e_sun_w_m2=E_SUN,
                            glint=gl.SunGlint(wind, index, sea=sea), backend="numpy").albedo_w_m2[0]


def _analytic_glint_converged(wind, index, ocean_planet, i, geo):
    """Return the analytic glint of epoch ``i`` extrapolated to infinitely small cells: the cell-centre sum is
    second order in the cell size, so (4 A(h/8) - A(h/4)) / 3 (Richardson). Needed at coasts: there the sea
    fraction's steps between cells stop the errors of the centre rule on the glint spot from cancelling (the
    native TOMS cells read 5 % low on the Gabon epoch, 8 x 8 sub-cells 0.1 %); on an ocean planet the native
    cells are already 1.3e-5 from the integral (test_analytic_glint_over_an_ocean_planet)."""
    if ocean_planet:
        return _analytic_glint_on(wind, index, True, i, geo)
    return (4 * _analytic_glint_on(wind, index, False, i, geo, 8) - _analytic_glint_on(wind, index, False, i, geo, 4)) / 3


def _agrees(diff, se):
    """Return whether rendered - analytic ``diff`` agrees with 0 given the standard errors ``se``: the pooled z of
    the sum within 3 (false alarm 0.27 %) and each diode-epoch's within 4 (24 of them: 24 x 6.3e-5 = 0.15 %)."""
    pooled = diff.sum() / np.sqrt((se ** 2).sum())
    return abs(pooled) < 3 and np.all(np.abs(diff / se) < 4), pooled, np.abs(diff / se).max()


@pytest.fixture(scope="module")
def glint_renders():
    geo = _glint_epochs()
    out = [_rendered_glint(7.0, N_WATER, i < 6, i, geo) for i in range(8)]
    return geo, np.stack([o[0] for o in out]), np.stack([o[1] for o in out])


def test_rendered_glint_equals_the_analytic_quadrature(glint_renders):
    # Oracle: the analytic model's cell quadrature (on an ocean planet 1.3e-5 from the independent quadrature
    # above; at coasts extrapolated from refined cells), far below the renderer's 0.2 % standard error; fixed
    # seeds; false-alarm rate 0.4 % (see _agrees)
    geo, val, se = glint_renders
    ref = np.stack([_analytic_glint_converged(7.0, N_WATER, i < 6, i, geo) for i in range(8)])
    assert np.all(ref > 0.5)                 # a strong glint on every diode-epoch (W/m^2)
    ok, pooled, worst = _agrees(val - ref, se)
    assert ok, (pooled, worst)


@pytest.mark.parametrize("wind, index", [(2.0, N_WATER), (12.0, N_WATER), (7.0, 1.5)])
def test_rendered_glint_disagrees_with_a_wrong_analytic_glint(glint_renders, wind, index):
    geo, val, se = glint_renders
    ref = np.stack([_analytic_glint_converged(wind, index, i < 6, i, geo) for i in range(8)])
    assert not _agrees(val - ref, se)[0]


def test_rendered_glint_needs_the_same_sea(glint_renders):
    # the coastal epochs against an analytic model on an ocean planet: the land's missing glint shows
    geo, val, se = glint_renders
    ref = np.stack([_analytic_glint_on(7.0, N_WATER, True, i, geo) for i in (6, 7)])
    assert not _agrees(val[6:] - ref, se[6:])[0]


# ---- runs and the command line -----------------------------------------------------------------------------
SUNSIM = [sys.executable, "-m", "simcore.cli"]
SUNLIT = ["--start", "2016-07-02T00:45:00Z"]   # the default day's orbit, sunlit over the North Pacific (Sun 29-13 deg
#                                                from the zenith under the satellite): glint up to ~20 W/m^2


def _sunsim(args, cwd):
    return subprocess.run(SUNSIM + list(args), capture_output=True, text=True, timeout=600, cwd=cwd)


def _listing(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder) for d, ds, fs in os.walk(folder) for f in fs + ds)


def test_runs_without_glint_keep_their_settings_digest():
    from simcore.pipeline.options import RunOptions
    assert "glint" not in RunOptions().spec()
    assert RunOptions(glint=7.0).spec()["glint"] == 7.0


@pytest.mark.parametrize("maps", [[], ["--map", "ceres2018-all", "--clouds", "1"]])
def test_a_glint_run_passes_its_analytic_check_which_sees_the_glint(tmp_path, maps):
    r = _sunsim(["run", "--glint", "7", *maps, *SUNLIT, "--duration", "300", "-o", "g.nc"], tmp_path)
    assert r.returncode == 0, r.stderr
    v = _sunsim(["validate", "g.nc", "--json"], tmp_path)
    assert v.returncode == 0, v.stdout + v.stderr
    assert json.loads(v.stdout)["verdict"] == "PASS"
    import xarray as xr
    from simcore.pipeline.run import PreparedRun
    from simcore.pipeline.runfile import options_of
    ds = xr.load_dataset(tmp_path / "g.nc")
    assert ds.attrs["glint_wind_m_s"] == 7.0 and ds.attrs["glint_water_index"] == 1.33
    assert ds.attrs["glint_mean_square_slope"] == pytest.approx(0.003 + 0.00512 * 7)   # Cox & Munk 1954
    # the check's reference holds the glint: without it the rendered albedo sits far above the reference
    opts = options_of(ds, str(tmp_path / "g.nc"))
    study = PreparedRun(opts)
    bare = PreparedRun(dataclasses.replace(opts, glint=None))
    sl = slice(0, len(study.epochs))
    with_glint = study.reference.analytic(sl, study.map, direct=False).albedo_w_m2
    without = bare.reference.analytic(sl, bare.map, direct=False).albedo_w_m2
    assert (with_glint - without).max() > 5.0                                     # W/m^2
    rendered, se = ds["irradiance"].values[..., 1], ds["irradiance_se"].values[..., 1]
    ok = se > 0
    pooled = (rendered - without)[ok].sum() / np.sqrt((se[ok] ** 2).sum())
    assert pooled > 10                   # the check's bias test (|B| <= 3.9) would fail by far
    if maps:
        # under cloud weather the overcast cells' sea gives no glint
        over = study.clouds.overcast(1)
        assert np.all(study.glint.sea[over] == 0) and np.any(study.glint.sea[~over] == 1)


@pytest.mark.parametrize("value, why", [("-1", "must be a finite wind speed >= 0"), ("nan", "must be a finite"),
                                        ("inf", "must be a finite"), ("-0.5", "must be a finite"),
                                        ("31", "above the 30 m/s")])
def test_bad_wind_is_one_line_exit_2_and_writes_nothing(tmp_path, value, why):
    # 31 m/s: a sea-wide wind beyond hurricane force (glint.MAX_WIND_M_S)
    r = _sunsim(["run", *SUNLIT, "--duration", "4", "--glint", value], tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and "--glint WIND_M_S" in lines[0] and why in lines[0], r.stderr
    assert "Traceback" not in r.stderr and _listing(tmp_path) == []
