"""Tests of simcore.pipeline.spectral_check: the spectral Monte Carlo (directions x wavelengths, class shares and
class spectra, Mitsuba's llvm_ad_spectral) against the analytic model on the band maps.

Oracles: the band maps' own construction (simcore.radiometry.band, the mean of the cell spectra over S E must
be it), the closed-form effective wavelength int lambda S E / int S E (simcore.radiometry.spectral), and the
analytic albedo sum (simcore.radiometry.analytic, cells refined 3 x 3, its discretisation bound in z).
Fixed seeds; the agreement limits give a false-alarm rate of 1e-3 per comparison (spectral_check.limits).
"""
import numpy as np
import pytest

from simcore.radiometry.band import band_curve, band_maps_for_curve
from simcore.radiometry.spectral import NM_M, integral_of_product, solar_spectrum
from simcore.pipeline import spectral_check as sc

DIODES = ("BPW34FS", "SFH2430", "BPW34")
NORMALS = ("nadir", "45 anti-sun", "horizon side")


@pytest.fixture(scope="module")
def geometry():
    return sc.default_geometry(3)


@pytest.mark.parametrize("diode", DIODES)
def test_cell_spectra_band_mean_is_the_band_map(diode):
    # linearity: int S E rho(lambda, cell) / int S E = K R_clear (clear) and the CloudWeather mixture (all)
    curve, label = band_curve(diode)
    clear, all_sky = band_maps_for_curve(curve, label)
    assert np.max(np.abs(sc.cell_spectra("clear").band_mean(curve) - clear.values)) < 1e-12
    assert np.max(np.abs(sc.cell_spectra("all").band_mean(curve) - all_sky.values)) < 1e-12
    # ... and the flipped shares are a different map (the wrong input below is really wrong)
    assert np.max(np.abs(sc.cell_spectra("clear", flip_shares=True).band_mean(curve) - clear.values)) > 0.1


def test_mitsuba_spectral_samples_the_infrared_band():
    # Mitsuba's default wavelength sampling stops at 830 nm; the srf sensor reaches the BPV23F's 800-1136 nm
    curve, _ = band_curve("BPW34FS")
    u = (np.arange(4096) + 0.5) / 4096
    lam, w = sc.band_wavelengths_nm(curve, u)
    lo, hi = curve.wavelength_m[[0, -1]] / NM_M
    assert lam.shape == (4096, 4) and lam.min() >= lo - 1e-3 and lam.max() <= hi + 1e-3 and lam.max() > 1050
    e = solar_spectrum()
    e_band = integral_of_product(curve, e)
    centre_nm = integral_of_product(curve, e, weight_power=1) / e_band / NM_M
    # stratified samples: the mean wavelength and the mean weight to a fraction of a nm / percent
    assert abs(lam.mean() - centre_nm) < 0.5, (lam.mean(), centre_nm)
    assert abs(w.mean() / e_band - 1) < 2e-3


@pytest.mark.parametrize("diode, kind, seed", [("BPW34FS", "clear", 1), ("SFH2430", "all", 2),
                                               ("BPW34", "clear", 3)])
def test_spectral_estimate_agrees_with_band_map(geometry, diode, kind, seed):
    c = sc.compare(diode, kind=kind, normals=NORMALS, samples=1 << 14, seed=seed, geometry=geometry)
    assert c.n == 9 and np.all(c.se / c.reference < 0.03)          # a real test: a few percent per entry
    assert sc.agrees(c), (c.pooled_z, c.max_abs_z, c.z)


@pytest.mark.parametrize("wrong", [{"flip_shares": True}, {"sampling_diode": "BPW34"}])
def test_wrong_input_fails(geometry, wrong):
    # the same comparison with the class shares read north-south flipped, or the wavelengths drawn from
    # another diode's band, must fail the check
    c = sc.compare("BPW34FS", normals=NORMALS, samples=1 << 14, seed=1, geometry=geometry, **wrong)
    assert not sc.agrees(c) and abs(c.pooled_z) > 10, (c.pooled_z, c.max_abs_z)


def test_limits_false_alarm_rate():
    # half of 1e-3 on the pooled z (two-sided), half on the largest of n (Bonferroni)
    from scipy import stats
    pooled, largest = sc.limits(9)
    assert abs(2 * stats.norm.sf(pooled) - 5e-4) < 1e-9
    assert abs(9 * 2 * stats.norm.sf(largest) - 5e-4) < 1e-9


def test_spectral_variant_leaves_the_renderer_alone():
    # a second Mitsuba variant in one process: a mono render before and after a spectral estimate is identical
    from simcore._llvm import import_mitsuba
    from simcore.constants import BPW34_AREA_M2, R_EARTH_MEAN_M
    from simcore.render import DiodeSurfaces, Renderer
    from simcore.shapes.aperture import diode_frame
    a = float(np.sqrt(BPW34_AREA_M2))
    rend = Renderer(DiodeSurfaces(np.zeros((1, 3)), diode_frame(np.array([0.0, 0.0, -1.0]))[None], [a, a]),
                    reflectivity=np.full((180, 288), 0.3))
    args = ([[0.0, 0.6, 0.8]], [[0.0, 0.0, -(R_EARTH_MEAN_M + 700e3)]], np.eye(3)[None])
    before = rend.render(*args, seed=5, albedo_samples=256)
    sc.spectral_albedo([[0.0, 0.0, R_EARTH_MEAN_M + 700e3]], [[0.0, 0.0, 1.5e11]], [[0.0, 0.0, -1.0]],
                       band_curve("BPW34FS")[0], sc.cell_spectra("clear"), samples=256)
    assert import_mitsuba().variant() == rend.variant
    after = rend.render(*args, seed=5, albedo_samples=256)
    assert np.array_equal(before.albedo_w_m2, after.albedo_w_m2) and before.albedo_w_m2[0, 0] > 0
    assert np.array_equal(before.direct_w_m2, after.direct_w_m2)


def test_bad_input_says_what_is_expected():
    curve, _ = band_curve("BPW34FS")
    with pytest.raises(ValueError, match="normals_ecef"):
        sc.spectral_albedo(np.ones((2, 3)) * 7e6, np.ones((2, 3)) * 1.5e11, np.ones((3, 2)), curve,
                           sc.cell_spectra("clear"))
    with pytest.raises(ValueError, match="unknown normals"):
        sc.compare("BPW34FS", normals=("zenith",))
    with pytest.raises(ValueError, match="kind"):
        sc.cell_spectra("cloudy")


def test_cli_table_exit_status_and_refusals(capsys):
    import json
    from simcore.cli import main
    base = ["spectral-check", "--diode", "BPW34FS", "--epochs", "2", "--samples", "4096", "--json"]
    assert main(base) == 0
    row = json.loads(capsys.readouterr().out)["rows"][0]
    assert row["agrees"] and row["n"] == 10 and len(row["entries"]) == 10
    assert main(base + ["--flip-shares"]) == 1                # the wrong input on purpose: exit 1
    assert not json.loads(capsys.readouterr().out)["rows"][0]["agrees"]
    for bad, words in ((["--diode", "BPW43"], "no band for diode"), (["--epochs", "9"], "--epochs must be 1 to 8")):
        assert main(["spectral-check"] + bad) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err
