"""Ocean sun glint: the Cox-Munk rough-sea BRDF (1/sr), numpy and the kernels' array libraries alike.

The sea is a surface of flat facets whose slopes ``(z_x, z_y)`` follow Cox & Munk's isotropic Gaussian
(C. Cox and W. Munk, "Measurement of the roughness of the sea surface from photographs of the sun's
glitter", J. Opt. Soc. Am. 44, 838-850, 1954; their fit for a clean sea surface)::

    p(z_x, z_y) = exp(-(z_x^2 + z_y^2) / sigma^2) / (pi sigma^2),   sigma^2 = 0.003 + 0.00512 W

with W the wind speed (m/s) at 12.5 m above the sea; ``integral p dz_x dz_y = 1`` over the slope plane.
Sunlight reaches the satellite only off the facets whose normal is the half vector ``h`` of the unit
directions to the Sun ``s`` and to the observer ``v``; a facet reflects the unpolarised Fresnel share
``rho(s . h)`` of water (index 1.33; the unpolarised closed form of Cook & Torrance 1982, ACM Trans. Graph. 1, 7;
``((n - 1)/(n + 1))^2 = 0.0201`` at normal incidence, 1 at grazing). The BRDF in its standard form (as in the
6S code's sun-glint routine, Vermote et al. 1997, there with Cox & Munk's anisotropic slopes; Nakajima &
Tanaka 1983, J. Quant. Spectrosc. Radiat. Transfer 29, 521, with their shadowing factor set to 1; Zhang & Wang
2010, Opt. Express 18)::

    f(s, v) = rho(s . h) p(tan beta) / (4 cos^4(beta) cos(theta_s) cos(theta_v))

with beta the facet's tilt (``cos beta = n . h``) and theta_s, theta_v the zeniths of the Sun and the
observer over the mean surface (normal ``n``). It is reciprocal, f(s, v) = f(v, s).

Facets hidden by their neighbours, from the Sun (shadowing) or from the observer (masking), reflect nothing
seen: Smith's height-correlated factor for these Gaussian slopes (B. G. Smith 1967, IEEE Trans. Antennas
Propag. 15, 668; the height-correlated form, E. Heitz 2014, J. Comput. Graph. Tech. 3(2), 48, eq. 99; Cox-Munk's
slopes are Beckmann's distribution with alpha^2 = sigma^2, B. Walter et al. 2007, EGSR, eq. 27)::

    G = 1 / (1 + Lambda(theta_s) + Lambda(theta_v)),
    Lambda(theta) = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2,   a = cot(theta) / sigma

multiplies f. It is 1 to ~1e-17 for the Sun at 40 deg and 7 m/s (a = 6) and goes to 0 toward either horizon:
without it f cos(theta_s) cos(theta_v) stays finite there, and a sea at the terminator seen at the limb with
the Sun just behind it (the satellite at eclipse entry or exit) would glint as brightly as at noon, in a sliver
of cells no sampling could find. Seen from space, the glint has also crossed the atmosphere twice: the runs take
its direct transmittance on both paths (:func:`air_mass`, :data:`GLINT_OPTICAL_DEPTH`, ``SunGlint.tau``), which
removes the rest of that sliver (both paths ~35 air masses long). No multiple reflections. The albedo of this surface,
``integral f cos(theta_v) d omega_v``, is then the mean over the facets the observer is not masked from of their
Fresnel share weighted by their area seen from the Sun (``tests/radiometry/test_glint.py`` checks that identity in slope
space). It equals the flat sea's Fresnel reflectance ``rho(cos theta_s)`` to 1 % only on a calm sea: at W = 0
(sigma^2 = 0.003) +0.1/+0.5/+0.9 % at 20/40/60 deg solar zenith; with wind, tilted facets see the Sun at larger
local angles, where water reflects more (at 7 m/s, 40 deg: some +7 %). Neither are whitecaps, the light
scattered inside the water nor the sky's reflection modelled: the glint is the specular part of the sea alone,
meant to be added to a map whose reflectivity holds the diffuse rest (:mod:`simcore.radiometry.analytic`).

All three cosines are enough: with ``c = s . v``, ``s . h = sqrt((1 + c)/2)`` and
``n . h = (cos theta_s + cos theta_v) / (2 s . h)``, so :func:`reflected_cos2` is written in them with
generic ``sqrt/exp/erf/maximum/where`` (``ops``) and serves the numpy backend, the analytic Dr.Jit kernel and
the renderer alike.
"""
from dataclasses import dataclass
import math

import numpy as np

from simcore.constants import R_EARTH_MEAN_M
from simcore.errors import InvalidInputError
from simcore.radiometry.response import NUMPY_OPS

WATER_INDEX = 1.33             # refractive index of sea water in the visible and near infrared
MSS_OFFSET = 0.003             # Cox & Munk (1954) clean surface: sigma^2 = 0.003 + 0.00512 W
MSS_PER_WIND_S_M = 0.00512     # per m/s of wind at 12.5 m
# Extinction optical depth of a clear atmosphere on the glint's two direct paths (Sun -> sea -> satellite), near
# 800 nm: Rayleigh 0.021 (Hansen & Travis 1974, Space Sci. Rev. 16, 527, eq. 2.29: 0.008569 lambda^-4 (1 + 0.0113
# lambda^-2 + 0.00013 lambda^-4), lambda in um) plus maritime aerosol ~0.08 (AOT 0.1 at 550 nm, the 6S settings of
# simcore/data/band/, Angstrom exponent 0.5). The map's reflectivity is top-of-atmosphere already; the glint is a
# surface reflection, seen through the air twice.
GLINT_OPTICAL_DEPTH = 0.1
# Facet tilts with cos(beta) below this reflect nothing the kernels could resolve (tan^2 beta > 1e6: the slope
# density is exp(-1e6 / sigma^2) = 0); the floor keeps 1/cos^4 finite in float32.
_COS_BETA_FLOOR = 1e-3


# The winds a run accepts (:func:`check_wind`): any calm sea (its check refined to resolve the spot,
# :func:`check_refine`), up to MAX_WIND_M_S: beyond it the sea is not one Cox-Munk surface but storm foam and spray
# (hurricane force begins at 32.7 m/s, Beaufort 12), and Cox-Munk's linear slope law (fitted on ~1-14 m/s, their
# fig. 7) is far beyond its data.
MAX_WIND_M_S = 30.0
# The analytic check's reference sums the glint at cell centres: the spot must span several of its cells. The spot's
# half-width on the ground is ~2 sigma h (the facet tilts that reach the observer, sigma the rms slope, h the
# altitude). Seen on tilt0_fov90 600-s spans from 665 km with cells of 1.25 deg refined 2, 4 or 8 (issue 33): a
# spot of 1.7 and 2.2 refined cells failed `sunsim validate` (1 and 2 m/s from 17:05Z, 0 m/s refined 4 from
# 15:27Z), 2.6 passed (3 m/s from 17:05Z), 3.5 and 4.2 passed (1 m/s refined 4, 0 m/s refined 8).
SPOT_CELLS = 3.0
MAX_CHECK_REFINE = 8           # 64 sub-cells a cell: the check's sums grow with them (a calm sea's run only)


def _wind(wind_m_s, option):
    """Return ``wind_m_s`` as a float, m/s, or raise InvalidInputError unless it is a finite speed >= 0."""
    try:
        w = float(wind_m_s)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{option} needs the wind speed in m/s (e.g. 7), got {wind_m_s!r}") from None
    if not math.isfinite(w) or w < 0:
        raise InvalidInputError(f"{option} must be a finite wind speed >= 0 m/s (Cox-Munk's fit spans about "
                                f"1-14 m/s; e.g. 7), got {wind_m_s}")
    return w


def check_wind(wind_m_s, option="--glint WIND_M_S"):
    """Return the wind of a run's glint ``wind_m_s`` as a float, m/s, or raise a one-line InvalidInputError (naming
    ``option``) unless it is a finite speed in 0..MAX_WIND_M_S (why: the constant's comment)."""
    w = _wind(wind_m_s, option)
    if w > MAX_WIND_M_S:
        raise InvalidInputError(
            f"{option} {w:g} m/s is above the {MAX_WIND_M_S:g} m/s a run accepts: a sea-wide wind beyond hurricane "
            f"force is not physical, and Cox-Munk's slope law (fitted up to ~14 m/s) does not describe storm foam; "
            f"give {MAX_WIND_M_S:g} m/s or less")
    return w


def check_refine(wind_m_s, altitude_m, cell_deg, base):
    """Return the analytic check's refinement for a glint at ``wind_m_s`` seen from ``altitude_m`` (the run's lowest)
    on map cells ``cell_deg`` wide (in longitude, their larger side on the shipped grids): the smallest of base,
    2 base, 4 base ... whose sub-cells the spot's half-width 2 sigma h spans SPOT_CELLS times (the constant's
    comment). A calm sea from a low orbit that would need more than MAX_CHECK_REFINE is a one-line
    InvalidInputError with the wind that can be checked."""
    cell_m = math.radians(cell_deg) * R_EARTH_MEAN_M
    factor = int(base)
    while 2.0 * math.sqrt(float(mean_square_slope(wind_m_s))) * altitude_m * factor < SPOT_CELLS * cell_m:
        factor *= 2
    if factor > MAX_CHECK_REFINE:
        sigma = SPOT_CELLS * cell_m / (2.0 * altitude_m * MAX_CHECK_REFINE)
        w_min = max(sigma * sigma - MSS_OFFSET, 0.0) / MSS_PER_WIND_S_M
        raise InvalidInputError(
            f"--glint WIND_M_S {wind_m_s:g} m/s from {altitude_m / 1e3:.0f} km: the glint spot (half-width "
            f"~{2 * math.sqrt(float(mean_square_slope(wind_m_s))) * altitude_m / 1e3:.0f} km) is too small "
            f"for the analytic check's reference cells even refined {MAX_CHECK_REFINE} x {MAX_CHECK_REFINE}; give "
            f"{math.ceil(w_min * 10) / 10:g} m/s or more at this altitude")
    return factor


def mean_square_slope(wind_m_s):
    """Return Cox & Munk's mean square slope sigma^2 (unitless) of the sea at wind ``wind_m_s`` (m/s, 12.5 m)."""
    return MSS_OFFSET + MSS_PER_WIND_S_M * np.asarray(wind_m_s, dtype=float)


def fresnel_reflectance(cos_incidence, index=WATER_INDEX, ops=NUMPY_OPS):
    """Return the unpolarised Fresnel reflectance (unitless) of a dielectric of relative ``index`` for light
    arriving at ``cos_incidence`` from the outside (Cook & Torrance 1982's closed form, the mean of the s and
    p shares)."""
    c = cos_incidence
    g = ops.sqrt(ops.maximum(index * index - 1.0 + c * c, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def slope_pdf(z_x, z_y, mss):
    """Return Cox & Munk's isotropic slope density p(z_x, z_y) (per unit slope^2) at mean square slope ``mss``."""
    z2 = np.asarray(z_x, float) ** 2 + np.asarray(z_y, float) ** 2
    return np.exp(-z2 / mss) / (np.pi * mss)


def air_mass(cos_zenith, ops=NUMPY_OPS):
    """Return the relative air mass of a path at ``cos_zenith`` from the zenith (1 overhead, 40 along the horizon):
    Rozenberg's m = 1 / (cos z + 0.025 exp(-11 cos z)) (G. V. Rozenberg 1966, *Twilight*, Plenum, p. 159), the
    plane-parallel 1 / cos z with the curved atmosphere's finite path toward the horizon."""
    c = ops.maximum(cos_zenith, 0.0)
    return 1.0 / (c + 0.025 * ops.exp(-11.0 * c))


def reflected_cos2(cos_in, cos_out, cos_io, mss, index=WATER_INDEX, ops=NUMPY_OPS, tau=0.0):
    """Return f(s, v) cos(theta_s) cos(theta_v) (1/sr): the glint BRDF times both zenith cosines, from the cosines
    of the Sun's zenith ``cos_in``, the observer's ``cos_out`` (over the mean surface) and the angle between the
    two directions ``cos_io`` (= s . v); 0 where either lies below the surface. Finite everywhere (the form the
    albedo sums need: the cosines cancel the BRDF's 1/cos poles). ``tau``: the atmosphere's extinction optical
    depth on both direct paths (:data:`GLINT_OPTICAL_DEPTH` for the glint at the top of the atmosphere): the
    value times exp(-tau (m(theta_s) + m(theta_v))), :func:`air_mass`; 0: the surface's BRDF alone."""
    cos_h = ops.sqrt(ops.maximum(0.5 * (1.0 + cos_io), 0.0))
    cos_beta = ops.maximum((cos_in + cos_out) / ops.maximum(2.0 * cos_h, _COS_BETA_FLOOR), _COS_BETA_FLOOR)
    c2 = cos_beta * cos_beta
    tan2 = (1.0 - c2) / c2
    q = fresnel_reflectance(cos_h, index, ops) * ops.exp(-tan2 / mss) / ((4.0 * np.pi * mss) * c2 * c2)
    q = q / (1.0 + smith_lambda(cos_in, mss, ops) + smith_lambda(cos_out, mss, ops))
    if tau:
        q = q * ops.exp(-tau * (air_mass(cos_in, ops) + air_mass(cos_out, ops)))
    return ops.where((cos_in > 0.0) & (cos_out > 0.0), q, 0.0)


def smith_lambda(cos_theta, mss, ops=NUMPY_OPS):
    """Return Smith's Lambda(theta) >= 0 of Cox & Munk's Gaussian slopes of mean square slope ``mss`` for a direction
    at ``cos_theta`` from the mean surface's normal (module docstring): 0 toward the zenith, growing as cot(theta)
    / sigma toward the horizon (where the floor of the cosine keeps it finite: ~3e4 at 7 m/s)."""
    c = ops.minimum(ops.maximum(cos_theta, 1e-5), 1.0)
    a = c / ops.sqrt(ops.maximum(mss * (1.0 - c * c), 1e-30))
    # erfc(a) = 1 - erf(a); both terms vanish for large a (Lambda < 1e-8 beyond a = 4): the clamp takes the rounding
    return ops.maximum(0.5 * (ops.exp(-a * a) / (a * math.sqrt(math.pi)) - (1.0 - ops.erf(a))), 0.0)


def brdf(normal, to_sun, to_observer, mss, index=WATER_INDEX):
    """Return the glint BRDF f(s, v) (1/sr) for unit vectors (..., 3): the mean surface's ``normal``, the
    directions ``to_sun`` and ``to_observer``; 0 where either lies below the surface."""
    n, s, v = (np.asarray(a, float) for a in (normal, to_sun, to_observer))
    mu_i, mu_o = np.sum(n * s, axis=-1), np.sum(n * v, axis=-1)
    q = reflected_cos2(mu_i, mu_o, np.sum(s * v, axis=-1), mss, index)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((mu_i > 0) & (mu_o > 0), q / (mu_i * mu_o), 0.0)


@dataclass(frozen=True, eq=False)
class SunGlint:
    """The sea's sun glint of a run: wind speed ``wind_m_s`` (m/s at 12.5 m), water index ``index`` and where the sea
    is: ``sea`` None for GSHHG's (:func:`simcore.environment.water.ocean_fraction` of the map), or the sea fraction
    of each cell (n_lat, n_lon) in [0, 1] on the map's grid and row order (e.g. 1 everywhere: an ocean planet);
    ``tau`` the atmosphere's optical depth on the glint's paths (:func:`reflected_cos2`)."""

    wind_m_s: float
    index: float = WATER_INDEX
    sea: object = None
    tau: float = GLINT_OPTICAL_DEPTH

    def __post_init__(self):
        object.__setattr__(self, "wind_m_s", _wind(self.wind_m_s, "the glint's wind"))
        if not (math.isfinite(self.index) and self.index > 1.0):
            raise ValueError(f"the water's refractive index must be a finite number > 1, got {self.index}")
        if not (math.isfinite(self.tau) and self.tau >= 0.0):
            raise ValueError(f"the atmosphere's optical depth must be a finite number >= 0, got {self.tau}")
        if self.sea is not None:
            sea = np.array(self.sea, dtype=float)
            if sea.ndim != 2 or not np.all((sea >= 0) & (sea <= 1)):
                raise ValueError("sea must be a (n_lat, n_lon) array of fractions in [0, 1] on the map's grid")
            sea.setflags(write=False)
            object.__setattr__(self, "sea", sea)

    def sea_fraction(self, refl):
        """Return the sea fraction (n_lat, n_lon) of map ``refl``'s cells, in its row order."""
        if self.sea is None:
            from simcore.environment.water import ocean_fraction
            return ocean_fraction(refl)
        if self.sea.shape != refl.shape:
            raise ValueError(f"the glint's sea fraction has shape {self.sea.shape}, the map {refl.shape}")
        return self.sea

    @property
    def mss(self):
        """Return the mean square slope sigma^2 (unitless) of Cox & Munk at this wind."""
        return float(mean_square_slope(self.wind_m_s))

    def attrs(self):
        """Return the run file's attributes that say which glint it rendered."""
        return {"glint_model": "Cox-Munk 1954 isotropic slopes, unpolarised Fresnel, Smith shadowing and masking, "
                               "two-way direct transmittance of the atmosphere; added to the map's diffuse "
                               "reflectivity on each cell's open sea fraction (GSHHG less the annual sea ice "
                               "from CERES; none under the overcast cells of cloud weather)",
                "glint_wind_m_s": self.wind_m_s, "glint_water_index": self.index,
                "glint_mean_square_slope": self.mss, "glint_optical_depth": self.tau}
