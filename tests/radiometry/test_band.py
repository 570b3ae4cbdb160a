"""Band-aware Earth maps (simcore.radiometry.band, issue 17 item 2): the CERES 2018 pair seen through a
photodiode's band.

Oracles: the shipped CERES 2018 maps themselves (a flat responsivity must give them back); pvlib's own copy of
the ASTM G173 table integrated here by the trapezoid rule (a closed-form band ratio); geography (atlases: which
class covers the Sahara, the Amazon, Greenland, Antarctica, the open Pacific); the GSHHG sea fraction of
simcore.environment.water (an independent land mask) and NOAA's 70.9 % ocean share; the red edge of green
vegetation (chlorophyll absorbs red, leaves scatter near-infrared: Gates et al. 1965, Appl. Opt. 4, 11).
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from simcore.environment.clouds import CloudWeather
from simcore.environment.maps import named_map
from simcore.environment.water import ocean_fraction
from simcore.errors import InvalidInputError
from simcore.radiometry import band, sea_surface
from simcore.radiometry.spectral import Spectrum

NM = 1e-9
SUNSIM = [sys.executable, "-m", "simcore.cli"]
CLEAR, ALL = named_map("ceres2018-clear"), named_map("ceres2018-all")


def _flat(lo_nm, hi_nm):
    return Spectrum("flat", np.array([lo_nm, hi_nm]) * NM, np.ones(2), "1", "test")


def _cell(lat, lon):
    """Return (row, column) of the CERES cell (south-first, 1 deg) holding latitude/longitude ``lat``, ``lon``."""
    return int(np.floor(lat + 90.0)), int(np.floor(lon + 180.0))


def test_a_flat_responsivity_over_the_solar_spectrum_gives_the_ceres_pair_back():
    curve = _flat(280.0, 4000.0)                       # the G173 table's whole range
    k = band.class_band_ratios(curve)
    assert all(abs(v - 1.0) < 1e-12 for v in k.values()), k
    clear, all_sky = band.band_maps_for_curve(curve, "flat")
    np.testing.assert_allclose(clear.values, CLEAR.values, rtol=1e-12, atol=0)
    np.testing.assert_allclose(all_sky.values, ALL.values, rtol=1e-12, atol=1e-15)
    # a band that is not the whole spectrum is not CERES
    visible, _ = band.band_maps_for_curve(_flat(400.0, 700.0), "visible")
    assert np.max(np.abs(visible.values - CLEAR.values)) > 0.05


def test_a_band_ratio_of_a_step_reflectance_is_its_closed_form():
    import pvlib
    etr = pvlib.spectrum.get_reference_spectra(standard="ASTM G173-03")["extraterrestrial"]
    nm, e = etr.index.to_numpy(float), etr.to_numpy(float)
    # TOA reflectance 0.1 up to 700 nm, 0.5 from 701 nm (linear between): an idealised red edge
    rho = Spectrum("step", np.array([280.0, 700.0, 701.0, 4000.0]) * NM, np.array([0.1, 0.1, 0.5, 0.5]), "1", "t")
    broadband = np.trapezoid(np.interp(nm, [280, 700, 701, 4000], [0.1, 0.1, 0.5, 0.5]) * e, nm) / np.trapezoid(e, nm)
    # a band inside the bright part sees 0.5 exactly; the ratio is 0.5 over the broadband mean (the trapezoid
    # misses only the curvature of rho x E in the 700-701 nm interval where both change: ~1e-6 of the mean)
    assert band.band_ratio(_flat(800.0, 1000.0), rho) == pytest.approx(0.5 / broadband, rel=1e-5)
    assert band.band_ratio(_flat(400.0, 600.0), rho) == pytest.approx(0.1 / broadband, rel=1e-5)


def test_class_shares_sit_where_the_atlas_puts_them_north_up_and_south_down():
    classes, f = band.class_fractions()
    assert f.shape == (len(classes), 180, 360)
    np.testing.assert_allclose(f.sum(axis=0), 1.0, rtol=0, atol=1e-12)

    def share(name, lat, lon):
        return f[(classes.index(name),) + _cell(lat, lon)]
    assert share("water", 0.5, -150.5) == 1.0                   # open equatorial Pacific
    assert share("barren", 23.5, 10.5) > 0.95                   # central Sahara (north)
    assert share("barren", -25.5, 135.5) + share("shrubland", -25.5, 135.5) > 0.9   # central Australia (south)
    assert share("forest", -3.5, -62.5) > 0.9                   # Amazon rain forest
    assert share("snow_ice", 75.5, -40.5) == 1.0                # Greenland ice sheet (north)
    assert share("snow_ice", -80.5, 0.5) == 1.0                 # Antarctica (south)


def test_the_land_covers_water_agrees_with_the_gshhg_sea():
    classes, f = band.class_fractions()
    a = CLEAR.cell_area_m2
    sea = ocean_fraction(CLEAR)
    low = np.broadcast_to(np.abs(CLEAR.lat_deg)[:, None] < 45.0, a.shape)     # no sea ice moved to snow_ice there
    water = f[classes.index("water")]
    # MODIS water holds the lakes too (~0.5 % of the Earth, all lakes together), GSHHG crude cuts coasts
    # straight: the area-weighted shares agree to 1 % of the area between 45 S and 45 N...
    assert abs(np.sum((water - sea) * a * low) / np.sum(a * low)) < 0.01
    # ...and the whole globe's water + snow/ice on the sea is NOAA's 70.9 % ocean (Eakins & Sharman 2010) to 1.5 %
    on_sea = water + f[classes.index("snow_ice")] * sea
    assert abs(np.sum(on_sea * a) / np.sum(a) - 0.709) < 0.015


def test_infrared_band_darkens_the_sea_and_brightens_vegetation_and_the_visible_band_does_the_opposite():
    ir = band.class_band_ratios(band.band_curve("BPW34FS")[0])       # proxy: the BPV23F curve
    eye = band.class_band_ratios(band.band_curve("SFH2430")[0])      # proxy: CIE 1924 V(lambda)
    assert ir["water"] < 0.3 < 1.5 < ir["forest"]
    assert eye["forest"] < 0.7 < 1.3 < eye["water"]
    # a cell's band factor is its classes' ratios weighted by their shares, the water's with the sea's grey
    # specular share A_s / C of the cell's CERES clear-sky albedo C kept at its broadband level (sea_surface)
    classes, f = band.class_fractions()
    k = band.band_factor(band.band_curve("BPW34FS")[0])

    def water(r, c):
        share = sea_surface.specular_albedo([CLEAR.lat_deg[r]])[0] / CLEAR.values[r, c]
        return ir["water"] + (1.0 - ir["water"]) * share
    r, c = _cell(0.5, -150.5)
    assert k[r, c] == pytest.approx(water(r, c), rel=1e-12)
    r, c = _cell(-3.5, -62.5)
    assert k[r, c] == pytest.approx(sum(f[i, r, c] * (water(r, c) if n == "water" else ir[n])
                                        for i, n in enumerate(classes)), rel=1e-12)


def test_cloud_weather_on_the_band_pair_has_its_mean_and_the_broadband_clouds():
    w = band.cloud_weather("band:BPV23F")
    clear, all_sky = band.band_maps("BPV23F")
    np.testing.assert_allclose(w.expected_values(), all_sky.values, rtol=0, atol=1e-15)
    broad = CloudWeather.for_map("ceres2018-all")
    # where the band's overcast state is brighter than its clear state (most cells) the cloud fraction is the
    # broadband one, so a seed puts its clouds on the same cells
    same = np.abs(w.cloud_fraction - broad.cloud_fraction) < 1e-12
    assert same.mean() > 0.95
    assert np.array_equal(w.overcast(3)[same], broad.overcast(3)[same])


@pytest.mark.parametrize("name, words", [
    ("band:FOO", "band maps exist for BPV23F, BPW34, BPW34FAS, BPW34FS, SFH2430"),
    ("band:", "names no diode"),
])
def test_a_band_map_of_an_unknown_diode_is_a_user_error(name, words):
    with pytest.raises(InvalidInputError, match=words):
        band.check_map_name(name)


@pytest.mark.parametrize("args, words", [
    (["--map", "band:BPW35"], "no band for diode 'BPW35'"),
    (["--map", "band-clear", "--clouds", "1"], "has none"),
])
def test_bad_band_input_is_one_line_exit_2_and_writes_nothing(tmp_path, args, words):
    r = subprocess.run(SUNSIM + ["run", "--start", "2016-07-02T00:45:00Z", "--duration", "4", *args, "-o", "x.nc"],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert os.listdir(tmp_path) == []
