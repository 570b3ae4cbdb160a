"""Band-aware Earth maps: the CERES 2018 clear-sky and all-sky albedo seen through a photodiode's band.

The shipped maps are broadband (CERES: the whole solar spectrum) or UV (TOMS: ~360 nm), but a photodiode
converts only its band: an infrared (daylight-filter) diode sees dark oceans and bright vegetation. For a
diode's relative spectral sensitivity S(lambda) and the ASTM G173 AM0 spectrum E(lambda), each land-cover
class c with clear-sky top-of-atmosphere reflectance rho_c(lambda) (6S over the class's surface spectrum;
``simcore/data/band/``, provenance in its README.md) has the band ratio

    k_c = [int S E rho_c / int S E] / [int E rho_c / int E]           (band reflectance / broadband reflectance)

and a cell with class shares f_c (MODIS MCD12C1 2019, per 1-deg CERES cell) the band factor
K = sum_c f_c k_c. The water's k (6S ``ClearWater``: path and water-leaving light, no surface reflection) is
made per cell by :func:`simcore.radiometry.sea_surface.water_band_ratio`: the sea's grey specular reflection,
part of CERES' albedo, keeps its broadband level (or, for a run with ``--glint``, is left to the glint). The band
maps are

    R_b,clear = K R_clear
    R_b,all   = (1 - f) K R_clear,state + f R_b,overcast

with the cloud fraction f and the two states of :class:`~simcore.environment.clouds.CloudWeather` (the
broadband pair's): a thick cloud's band reflectance is ``k_cloud`` x 0.70 (:data:`CLOUD_BAND_FACTOR`:
grey), a cell brighter than thick cloud (the Antarctic plateau) keeps its surface's factor K. With a flat
responsivity every k is 1 and both maps are the CERES pair again (to rounding).

Diodes: a shipped curve (:func:`simcore.radiometry.spectral.responsivity`) is used as it is; for the thesis'
OSRAM diodes with no citable curve a documented proxy stands in (:data:`PROXIES`). The maps are computed
at run time (numpy, ~20 ms) and cached: no per-diode files.
"""
import difflib
from functools import lru_cache
from importlib import resources

import numpy as np

from simcore.environment.clouds import BAND_ALL_SKY, BAND_CLEAR_SKY, OVERCAST_ALBEDO, CloudWeather
from simcore.environment.maps import ReflectivityMap, named_map
from simcore.errors import InvalidInputError
from simcore.radiometry import sea_surface
from simcore.radiometry.spectral import NM_M, Spectrum, diode_curves, integral_of_product, responsivity, \
    solar_spectrum

BAND_FOLDER = "band"
TOA_FILE = "toa_reflectance.csv"
FRACTIONS_FILE = "class_fractions.npz"
PHOTOPIC_FILE = "cie1924_photopic.csv"
DEFAULT_DIODE = "BPW34FS"            # the thesis' and the sensor chain's default diode
PHOTOPIC = "CIE1924-V"
# Diodes without a citable curve -> the curve that stands in for their band, and why (README.md).
PROXIES = {
    "BPW34FS": ("BPV23F", "OSRAM BPW 34 FS, Si PIN with daylight filter (~780-1100 nm): no citable curve; "
                          "Vishay BPV23F, Si PIN with daylight filter, stands in"),
    "BPW34FAS": ("BPV23F", "OSRAM BPW 34 FAS, Si PIN with daylight filter (~730-1100 nm): no citable curve; "
                           "Vishay BPV23F, Si PIN with daylight filter, stands in"),
    "SFH2430": (PHOTOPIC, "OSRAM SFH 2430, 'V-lambda characteristics': no citable curve; the CIE 1924 "
                          "photopic luminous efficiency V(lambda) it is made to follow stands in"),
}
# Thick water clouds are close to grey below 1.1 um: liquid water hardly absorbs there (imaginary index
# < 1e-6 up to ~1 um, Hale & Querry 1973, Appl. Opt. 12, 555, table 1), so a conservative-scattering deck
# reflects alike across the band; no citable band factor was found, so the overcast state is grey.
CLOUD_BAND_FACTOR = 1.0


def _read(filename):
    return resources.files("simcore").joinpath("data", BAND_FOLDER, filename).read_text()


def _table(filename):
    """Return (column names, data rows) of a shipped band CSV ('#' lines are comments)."""
    rows = [ln for ln in _read(filename).splitlines() if ln.strip() and not ln.startswith("#")]
    return rows[0].split(","), np.array([[float(x) for x in ln.split(",")] for ln in rows[1:]])


def _comments(filename):
    return " ".join(ln.lstrip("# ").strip() for ln in _read(filename).splitlines() if ln.startswith("#"))


@lru_cache(maxsize=1)
def class_toa_reflectance():
    """Return {class: :class:`Spectrum`} of each land-cover class's clear-sky TOA reflectance (dimensionless)."""
    names, data = _table(TOA_FILE)
    src = _comments(TOA_FILE)
    return {n: Spectrum(n, data[:, 0] * NM_M, data[:, i], "1", src) for i, n in enumerate(names) if i > 0}


@lru_cache(maxsize=1)
def class_fractions():
    """Return (classes, fractions): the class names and their shares of each CERES cell (n_class, 180, 360),
    south-first rows as the CERES maps, summing to 1 in every cell."""
    with resources.files("simcore").joinpath("data", BAND_FOLDER, FRACTIONS_FILE).open("rb") as f, \
            np.load(f) as d:
        f_c = d["pixel_counts"] / float(d["pixels_per_cell"])
        classes = tuple(str(c) for c in d["classes"])
    f_c.setflags(write=False)
    return classes, f_c


def band_diodes():
    """Return the diodes that have a band (a shipped curve or a proxy), sorted."""
    return tuple(sorted(set(diode_curves()) | set(PROXIES)))


def band_curve(diode):
    """Return (S_rel :class:`Spectrum`, label) of diode ``diode``'s band: its shipped curve, or its proxy's
    (:data:`PROXIES`, the label saying so). An unknown diode is an InvalidInputError naming those with a band."""
    key = str(diode).upper()
    shipped = {n.upper(): n for n in diode_curves()}
    if key in shipped:
        return responsivity(shipped[key]), shipped[key]
    if key in PROXIES:
        proxy = PROXIES[key][0]
        if proxy == PHOTOPIC:
            names, data = _table(PHOTOPIC_FILE)
            curve = Spectrum(PHOTOPIC, data[:, 0] * NM_M, data[:, 1], "1", _comments(PHOTOPIC_FILE))
        else:
            curve = responsivity(proxy)
        return curve, f"{key} (proxy: {proxy})"
    close = difflib.get_close_matches(key, band_diodes(), n=2, cutoff=0.5)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    raise InvalidInputError(f"no band for diode {diode!r}: {hint}band maps exist for {', '.join(band_diodes())} "
                            f"(--map band:DIODE)")


def band_ratio(curve, rho):
    """Return k = [int S E rho / int S E] / [int E rho / int E] (dimensionless): the band reflectance over the
    broadband reflectance of the TOA reflectance ``rho`` for the relative spectral sensitivity ``curve``
    (both :class:`Spectrum`), E the G173 AM0 spectrum (280-4000 nm)."""
    e = solar_spectrum()
    e_band = integral_of_product(curve, e)
    if not e_band > 0:
        raise InvalidInputError(f"the curve {curve.name!r} sees none of the solar spectrum (280-4000 nm)")
    return (integral_of_product(curve, e, rho) / e_band) / broadband_reflectance(rho)


def class_band_ratios(curve):
    """Return {class: k_c} (:func:`band_ratio`) of each land-cover class for the sensitivity ``curve``."""
    return {c: band_ratio(curve, rho) for c, rho in class_toa_reflectance().items()}


def band_factor(curve, glint_wind_m_s=None):
    """Return K = sum_c f_c k_c (180, 360), south-first: each CERES cell's band over broadband clear-sky factor,
    the water's k per cell (:func:`simcore.radiometry.sea_surface.water_band_ratio`: with the sea's specular
    reflection, or without it for a run whose glint at ``glint_wind_m_s`` m/s adds it)."""
    classes, f_c = class_fractions()
    k = class_band_ratios(curve)
    k_water = sea_surface.water_band_ratio(k["water"], named_map("ceres2018-clear"), glint_wind_m_s)
    return sum((k_water if c == "water" else k[c]) * f_c[i] for i, c in enumerate(classes))


def broadband_reflectance(rho):
    """Return the AM0-weighted broadband mean of the TOA reflectance ``rho`` (:class:`Spectrum`), dimensionless."""
    e = solar_spectrum()
    return integral_of_product(e, rho) / integral_of_product(e)


@lru_cache(maxsize=1)
def sea_ice_share():
    """Return the annual ice share of each CERES cell's sea (180, 360), south-first
    (:func:`simcore.radiometry.sea_surface.sea_ice_share`, the ice's reflectance that of the snow/ice class)."""
    share = sea_surface.sea_ice_share(broadband_reflectance(class_toa_reflectance()["snow_ice"]))
    share.setflags(write=False)
    return share


def band_maps_for_curve(curve, label, glint_wind_m_s=None):
    """Return (clear, all-sky) :class:`ReflectivityMap` of the CERES 2018 pair seen through ``curve``
    (module docstring), named after ``label``; ``glint_wind_m_s``: the wind of a run's glint, whose specular
    reflection the maps' sea then leaves out (None: kept, a run without glint)."""
    clear, all_sky = named_map("ceres2018-clear"), named_map("ceres2018-all")
    if not (clear.south_first and clear.shape == (180, 360)):
        raise ValueError("the band factors are on the CERES grid, south-first 180 x 360")
    k_map = band_factor(curve, glint_wind_m_s)
    w = CloudWeather(clear, all_sky)
    f = w.cloud_fraction
    brighter = all_sky.values > w.overcast_albedo
    cloudy = np.where(brighter, k_map * w.cloudy_state, CLOUD_BAND_FACTOR * w.cloudy_state)
    all_b = (1.0 - f) * (k_map * w.clear_state) + f * cloudy
    src = "CERES 2018 x class band ratios, simcore/data/band" + (
        "" if glint_wind_m_s is None else f"; sea without its specular part, left to the {glint_wind_m_s:g} m/s glint")
    return (ReflectivityMap(k_map * clear.values, clear.lat_deg, clear.lon_deg, name=f"band {label} clear-sky ({src})"),
            ReflectivityMap(all_b, clear.lat_deg, clear.lon_deg, name=f"band {label} all-sky ({src})"))


@lru_cache(maxsize=8)
def band_maps(diode=DEFAULT_DIODE, glint_wind_m_s=None):
    """Return (clear, all-sky) band maps of diode ``diode`` (its curve or its proxy's, :func:`band_curve`); for a run
    with glint at ``glint_wind_m_s`` m/s, the sea without its specular part (:func:`band_maps_for_curve`)."""
    curve, label = band_curve(diode)
    return band_maps_for_curve(curve, label, glint_wind_m_s)


def parse_map_name(name):
    """Return (kind 'clear' or 'all', diode) for a band map name ('band', 'band-clear', 'band:DIODE',
    'band-clear:DIODE'; '_' may stand for '-'), or None for any other map name."""
    key = str(name).replace("_", "-")
    head, _, diode = key.partition(":")
    if head not in (BAND_ALL_SKY, BAND_CLEAR_SKY):
        return None
    if _ and not diode:
        raise InvalidInputError(f"--map {name} names no diode: give one after the colon, e.g. band:BPV23F "
                                f"({', '.join(band_diodes())}), or write band for the {DEFAULT_DIODE}")
    return ("clear" if head == BAND_CLEAR_SKY else "all"), (diode or DEFAULT_DIODE)


def check_map_name(name):
    """Raise InvalidInputError if ``name`` is a band map of a diode without a band (no file is read)."""
    parsed = parse_map_name(name)
    if parsed is not None:
        band_curve(parsed[1])


def resolve_map(name, glint_wind_m_s=None):
    """Return the :class:`ReflectivityMap` called ``name``: a band map (:func:`parse_map_name`; for a run with glint
    at ``glint_wind_m_s`` m/s its sea without the specular part) or any map
    :func:`simcore.environment.maps.named_map` knows."""
    parsed = parse_map_name(name)
    if parsed is None:
        return named_map(name)
    kind, diode = parsed
    clear, all_sky = band_maps(diode.upper(), _wind_key(glint_wind_m_s))
    return clear if kind == "clear" else all_sky


def _wind_key(glint_wind_m_s):
    return None if glint_wind_m_s is None else float(glint_wind_m_s)


def cloud_weather(name, scale_km=None, glint_wind_m_s=None):
    """Return the :class:`CloudWeather` whose mean is the all-sky map ``name`` ('ceres2018-all' or a band
    all-sky map, whose overcast state is in-band: 0.70 x the cloud band factor; with glint at ``glint_wind_m_s``
    m/s its sea without the specular part)."""
    parsed = parse_map_name(name)
    if parsed is None:
        return CloudWeather.for_map(name, scale_km)
    from simcore.environment.clouds import DEFAULT_SCALE_KM, check_cloud_options
    check_cloud_options(name, 0, scale_km)
    clear, all_sky = band_maps(parsed[1].upper(), _wind_key(glint_wind_m_s))
    km = DEFAULT_SCALE_KM if scale_km is None else float(scale_km)
    return CloudWeather(clear, all_sky, scale_m=km * 1e3, overcast_albedo=OVERCAST_ALBEDO * CLOUD_BAND_FACTOR)


# Places for the headline numbers (lat, lon of a CERES cell's south-west corner + 0.5): open sea, rain forest,
# desert, ice sheet, and the class whose "pure" cells (share > 0.9) make each surface type's map-wide mean.
HEADLINE_PLACES = {"ocean (0.5N 150.5W)": ((0.5, -150.5), "water"), "vegetation (3.5S 62.5W)": ((-3.5, -62.5), "forest"),
                   "Sahara (23.5N 10.5E)": ((23.5, 10.5), "barren"), "snow (75.5N 40.5W)": ((75.5, -40.5), "snow_ice")}


def shifted(curve, shift_nm):
    """Return ``curve`` moved by ``shift_nm`` along wavelength (a band edge's uncertainty)."""
    return Spectrum(f"{curve.name} {shift_nm:+g} nm", curve.wavelength_m + shift_nm * NM_M, curve.value, curve.unit,
                    curve.source)


def headline(diode=DEFAULT_DIODE):
    """Return a dict of the issue's headline numbers for ``diode``: band clear-sky TOA reflectance and CERES
    clear-sky at four places, the area-weighted band all-sky over TOMS 2005 ratio - 1 over cells of one class
    (share > 0.9), and the class ratios with the band moved by -50 / +50 nm."""
    curve, label = band_curve(diode)
    clear_b, all_b = band_maps(str(diode).upper())
    clear = named_map("ceres2018-clear")
    toms = named_map("toms2005")
    # TOMS (1 x 1.25 deg) onto the CERES grid: the TOMS cell holding each CERES cell's centre
    cols = np.floor((clear.lon_deg - toms.lon_edges_deg[0]) / toms.dlon_deg).astype(int) % toms.n_lon
    rows = np.floor((clear.lat_deg + 90.0) / toms.dlat_deg).astype(int)
    toms_on = toms.values_south_first[rows][:, cols]
    classes, f_c = class_fractions()
    area = clear.cell_area_m2
    out = {"diode": label, "places": {}, "band_vs_toms": {}, "ratios": class_band_ratios(curve),
           "ratios_shift_-50nm": class_band_ratios(shifted(curve, -50.0)),
           "ratios_shift_+50nm": class_band_ratios(shifted(curve, 50.0))}
    for name, ((lat, lon), _) in HEADLINE_PLACES.items():
        r, c = int(np.floor(lat + 90.0)), int(np.floor(lon + 180.0))
        out["places"][name] = {"band_clear": float(clear_b.values[r, c]), "ceres_clear": float(clear.values[r, c]),
                               "toms": float(toms_on[r, c])}
    for cls in classes:
        pure = f_c[classes.index(cls)] > 0.9
        if pure.any():
            out["band_vs_toms"][cls] = float(np.sum(all_b.values * area * pure) / np.sum(toms_on * area * pure) - 1)
    return out
