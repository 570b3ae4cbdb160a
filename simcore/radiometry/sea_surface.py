"""The sea's surface reflection in the CERES clear-sky albedo, and the sea ice that must not glint.

**Specular part of the sea's clear-sky albedo.** A CERES clear-sky albedo over the open sea is the light the
whole clear column sends back: the air's path radiance, the light leaving the water, and the reflection at the
water's surface. The band maps (:mod:`simcore.radiometry.band`) give each class a band ratio k_c from 6S; the
water's (6S ``ClearWater``: a Lambertian water-leaving spectrum, no surface reflection) describes the first two
alone: in an infrared band they are dark (k_water ~0.14 for the BPW34FS). The surface reflection is Fresnel's
reflection of the Sun off a rough sea, and water's refractive index moves by < 1 % between 400 and 1000 nm
(1.339-1.327, Hale & Querry 1973, Appl. Opt. 12, 555): it is spectrally grey and keeps its broadband level in
every band. So the sea's clear-sky albedo C is split into

    C = A_s + (C - A_s)          band map:  A_s + k_water (C - A_s)

with A_s the specular reflection of the direct Sun seen at the top of the atmosphere, averaged as CERES averages
(over the Sun's angles of a year, weighted by the insolation: CERES EBAF's albedo is the ratio of the reflected
to the incoming flux, each averaged over time)::

    A_s(lat) = sum over days and hours of mu_s a(mu_s)  /  sum of mu_s         (mu_s = cos of the Sun's zenith > 0)
    a(mu_s)  = integral over the view hemisphere of f(s, v) cos(theta_v) d omega_v

with f the glint's own Cox-Munk BRDF (:mod:`simcore.radiometry.glint`: unpolarised Fresnel of water, Smith's
shadowing, two-way direct transmittance of the air) at :data:`REFERENCE_WIND_M_S`. a(mu_s) is, on a calm sea,
the Fresnel reflectance of the flat sea (the measured albedos of Payne 1972, J. Atmos. Sci. 29, 959, and the
direct-beam surface albedo of Jin et al. 2004, Geophys. Res. Lett. 31, L22301, follow the same Fresnel curve, with
the waves' tilt at low Sun; ``tests/radiometry/test_sea_surface.py`` compares with Briegleb et al. 1986's fit to Payne's data);
at the equator A_s is ~0.024 of the ~0.09 CERES clear sea. The reflected *sky* light (~0.066 of the diffuse light,
Payne 1972) is left with the rest: it has the blue colour of the path radiance that 6S's ratio describes.

**With glint** (``--glint W``) the glint model renders the specular reflection itself, with its angles: the
band map's sea then keeps only the rest, ``k_water (C - A_s(W))`` with A_s at the glint's own wind, and the
glint adds A_s(W) back in the mean over the Sun's angles (``tests/radiometry/test_sea_surface.py``): nothing is counted
twice. What differs between the two runs is only *where* the specular light goes (a Lambertian share of the
cell's albedo against the glint spot).

**Sea ice** (annual, from the shipped maps: no sea-ice concentration installs from the package registries,
and the maps are annual means). Poleward of :data:`SEA_ICE_LAT_DEG` the share of a cell's sea that is ice is
the one that makes its CERES clear-sky albedo C the mixture of open sea and ice::

    ice = clip((C - rho_open(lat)) / (rho_ice - rho_open(lat)), 0, 1)

rho_ice the snow/ice class's broadband TOA reflectance (6S, ``simcore/data/band/``: 0.76) and rho_open(lat) the
open sea's own clear-sky albedo at that latitude, read off CERES: the 1st percentile of the all-sea cells
(GSHHG sea fraction > 0.99) of the rows at that |latitude| in either hemisphere (the darker of the two), held at
its 74.5-deg value poleward (the Norwegian and Barents Seas, ice-free all year under the North Atlantic
Current, set it: 0.21). An open sea brightens toward the poles (0.09 at the equator, 0.16 at 60 deg: the low
Sun), so a fixed water reference would call the open Norwegian Sea a quarter ice. CERES weights by the
insolation, so this is the sunlit, summer-heavy ice share, the one the glint, seen only in sunlight, needs:
over the GSHHG sea it totals ~6.5e6 km^2 in the north and ~7.8e6 in the south (printed by ``pytest -s
tests/radiometry/test_sea_surface.py -k sea_ice_share``), between the year's minimum and maximum extents (NSIDC Sea Ice
Index v3, Fetterer et al. 2017, doi:10.7265/N5K072F8). Seasonal masks need monthly data the project does not
ship. The band data's own water/snow_ice split (``build_band_data.py``, ``sea_ice``) used the 6S water
reflectance (0.054) as rho_open at every latitude, which finds ~1.8 times this ice (rebuilding it needs the
``band-build`` extra). The glint's sea is GSHHG's sea fraction times (1 - ice) (:func:`open_sea_fraction`).
"""
from functools import lru_cache

import numpy as np

from simcore.environment.maps import named_map
from simcore.environment.water import ocean_fraction
from simcore.radiometry.glint import GLINT_OPTICAL_DEPTH, mean_square_slope, reflected_cos2

# The wind of the sea's specular share without glint: the earth-study's glint wind (studies.earth_band), of the order
# of the global mean wind over the ice-free ocean (~7 m/s at 10 m); A_s at the equator is 0.0258 at 2 m/s, 0.0244
# at 7, 0.0229 at 14.
REFERENCE_WIND_M_S = 7.0
SEA_ICE_LAT_DEG = 45.0            # as build_band_data.SEA_ICE_LAT_DEG: equatorward of it no sea ice
OPEN_SEA_PERCENTILE = 1.0         # the open sea's albedo: the darkest 1 % of a row's all-sea cells
OPEN_SEA_MAX_LAT_DEG = 74.5       # poleward, the open-sea reference of this |latitude| (no row is ice-free beyond)
_OBLIQUITY_DEG = 23.44
_N_MU = 48                        # Sun cosines of the a(mu_s) table (Gauss-Legendre on 0..1)
_N_THETA, _N_PHI = 400, 240       # view zeniths (0..90 deg) x azimuths (0..180 deg, mirror-symmetric) of a(mu_s)


def _gauss01(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


@lru_cache(maxsize=8)
def specular_albedo_table(wind_m_s, tau=GLINT_OPTICAL_DEPTH):
    """Return (mu_s, a): the glint's hemispherical albedo a(mu_s) (module docstring; tau the air's optical depth
    on both paths, 0: the surface alone) at the Sun cosines mu_s of a Gauss-Legendre rule on 0..1, for the wind
    ``wind_m_s`` (m/s at 12.5 m)."""
    mss = float(mean_square_slope(wind_m_s))
    mu_s, _ = _gauss01(_N_MU)
    # view directions: midpoints in theta_v (0..90 deg) and in azimuth phi (0..180 deg: the BRDF is symmetric
    # about the Sun's plane); d omega = sin theta d theta d phi, x 2 for the other half
    th = (np.arange(_N_THETA) + 0.5) * (0.5 * np.pi / _N_THETA)
    ph = (np.arange(_N_PHI) + 0.5) * (np.pi / _N_PHI)
    cos_v, sin_v = np.cos(th)[:, None], np.sin(th)[:, None]
    d_omega = 2.0 * sin_v * (0.5 * np.pi / _N_THETA) * (np.pi / _N_PHI)
    out = np.empty(_N_MU)
    for i, mu in enumerate(mu_s):
        sin_s = np.sqrt(1.0 - mu * mu)
        cos_io = mu * cos_v + sin_s * sin_v * np.cos(ph)[None, :]   # s . v, the Sun at azimuth 0
        q = reflected_cos2(mu, cos_v, cos_io, mss, tau=tau)           # f cos(theta_s) cos(theta_v)
        out[i] = float(np.sum(q * d_omega)) / mu
    return mu_s, out


def _sun_cosines(lat_deg, n_days=73, n_hours=96):
    """Return mu_s (n_lat, n_days * n_hours) over a year at each latitude (clipped at 0 at night): declination
    23.44 deg x sin of the year's angle, hour angles uniform over the day."""
    decl = np.radians(_OBLIQUITY_DEG) * np.sin(2 * np.pi * (np.arange(n_days) + 0.5) / n_days)
    hour = 2 * np.pi * (np.arange(n_hours) + 0.5) / n_hours
    lat = np.radians(np.asarray(lat_deg, float))[:, None, None]
    mu = (np.sin(lat) * np.sin(decl)[None, :, None]
          + np.cos(lat) * np.cos(decl)[None, :, None] * np.cos(hour)[None, None, :])
    return np.maximum(mu, 0.0).reshape(lat.shape[0], -1)


@lru_cache(maxsize=16)
def _specular_by_latitude(lat_deg, wind_m_s, tau):
    mu_tab, a_tab = specular_albedo_table(wind_m_s, tau)
    mu = _sun_cosines(np.asarray(lat_deg))
    # a(mu) between the table's nodes: linear; below the first node (Sun < ~1.7 deg high, ~0.1 % of the
    # insolation) the first node's value
    a = np.interp(mu, mu_tab, a_tab)
    return np.sum(mu * a, axis=1) / np.sum(mu, axis=1)


def specular_albedo(lat_deg, wind_m_s=REFERENCE_WIND_M_S, tau=GLINT_OPTICAL_DEPTH):
    """Return A_s (module docstring): the insolation-weighted annual mean of the glint's albedo at each latitude
    ``lat_deg`` (deg, array), dimensionless: the specular share of a clear sea's CERES albedo."""
    return _specular_by_latitude(tuple(np.round(np.atleast_1d(lat_deg), 9)), float(wind_m_s), float(tau))


def specular_share(clear_map, glint_wind_m_s=None):
    """Return min(A_s / C, 1) in each cell of ``clear_map`` (the CERES clear-sky :class:`ReflectivityMap`, south-first
    rows): the grey specular share of its clear-sky albedo C, A_s at the glint's wind ``glint_wind_m_s`` (m/s) or,
    without glint (None), at :data:`REFERENCE_WIND_M_S`."""
    wind = REFERENCE_WIND_M_S if glint_wind_m_s is None else float(glint_wind_m_s)
    a_s = specular_albedo(clear_map.lat_deg, wind)[:, None]
    c = clear_map.values
    return np.where(c > 0, np.minimum(a_s / np.where(c > 0, c, 1.0), 1.0), 1.0)


def water_band_ratio(k_water, clear_map, glint_wind_m_s=None):
    """Return the water class's band ratio in each cell of ``clear_map`` (the CERES clear-sky
    :class:`ReflectivityMap`, south-first), from 6S's ratio ``k_water`` of the path and water-leaving light: without
    glint (``glint_wind_m_s`` None) k_water + (1 - k_water) s, the grey specular share s (:func:`specular_share`)
    kept; with glint at W, k_water (1 - s), the specular share left to the glint."""
    share = specular_share(clear_map, glint_wind_m_s)
    if glint_wind_m_s is None:
        return k_water + (1.0 - k_water) * share
    return k_water * (1.0 - share)


def open_sea_reference(clear, sea):
    """Return rho_open (n_lat,): the clear-sky albedo of an ice-free sea at each row's latitude (module docstring),
    from the CERES clear-sky map ``clear`` and its sea fraction ``sea``."""
    full = np.asarray(sea) > 0.99
    row_p1 = np.array([np.percentile(clear.values[i][full[i]], OPEN_SEA_PERCENTILE) if full[i].sum() > 5 else np.inf
                       for i in range(clear.shape[0])])
    a = np.round(np.abs(clear.lat_deg), 6)
    ref = np.array([row_p1[a == min(x, OPEN_SEA_MAX_LAT_DEG)].min() for x in a])
    if not np.all(np.isfinite(ref)):
        raise ValueError("the CERES map has a row without open sea equatorward of the reference latitude")
    return ref


def sea_ice_share(rho_ice):
    """Return the annual ice share of each CERES 1-deg cell's sea (180, 360), south-first, in [0, 1] (module
    docstring), for the ice's broadband TOA reflectance ``rho_ice``."""
    clear = named_map("ceres2018-clear")
    if not clear.south_first:
        raise ValueError("the CERES clear-sky map is south-first")
    ref = open_sea_reference(clear, ocean_fraction(clear))[:, None]
    share = np.clip((clear.values - ref) / (rho_ice - ref), 0.0, 1.0)
    return share * (np.abs(clear.lat_deg) > SEA_ICE_LAT_DEG)[:, None]


def on_grid(values_ceres, refl):
    """Return the CERES-grid field ``values_ceres`` (180, 360; south-first, 1 deg) on map ``refl``'s cells (its row
    order): each cell takes the CERES cell that holds its centre."""
    rows = np.clip(np.floor(np.asarray(refl.lat_deg) + 90.0).astype(int), 0, 179)
    cols = np.floor((np.asarray(refl.lon_deg) + 180.0) % 360.0).astype(int) % 360
    return values_ceres[rows][:, cols]


def open_sea_fraction(refl, ice_share):
    """Return the share of each cell of map ``refl`` that is open (ice-free) sea: GSHHG's sea fraction
    (:func:`simcore.environment.water.ocean_fraction`) times 1 - the ice share ``ice_share`` (CERES grid,
    :func:`sea_ice_share`) of the cell that holds its centre."""
    frac = ocean_fraction(refl) * (1.0 - on_grid(ice_share, refl))
    frac.setflags(write=False)
    return frac
