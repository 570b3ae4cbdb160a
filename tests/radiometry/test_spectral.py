"""Spectral package data and band-integrated irradiance (simcore.radiometry.spectral), against independent
oracles: pvlib's copy of ASTM G173, closed-form integrals, the Vishay BPW34 data sheet's own numbers."""
import numpy as np
import pytest

from simcore.errors import InvalidInputError, UserError
from simcore.radiometry import spectral as sp

NM = 1e-9
H_J_S, C_M_S, Q_C = 6.62607015e-34, 299792458.0, 1.602176634e-19     # SI 2019 exact


def _flat(lo_nm, hi_nm, value=1.0, n=2):
    w = np.linspace(lo_nm, hi_nm, n) * NM
    return sp.Spectrum("flat", w, np.full(n, float(value)), "1", "test")


# --- the solar spectrum --------------------------------------------------------------------------------

def test_shipped_etr_is_pvlibs_astm_g173_value_for_value():
    # Oracle: pvlib-python's own loader of its ASTMG173.csv (the NREL tables of ASTM G173-03), an
    # implementation independent of ours; pvlib is a test extra in pyproject.toml.
    from pvlib.spectrum import get_reference_spectra
    ref = get_reference_spectra(standard="ASTM G173-03")["extraterrestrial"]
    e = sp.solar_spectrum()
    assert e.wavelength_m.shape == (2002,)                                  # ASTM G173-03 sec. 1.1: 2002 rows
    np.testing.assert_allclose(e.wavelength_m / NM, ref.index.to_numpy(), rtol=1e-15, atol=0)   # 280 .. 4000 nm
    np.testing.assert_allclose(e.value * NM, ref.to_numpy(), rtol=1e-15, atol=0)


def test_whole_etr_table_integral_matches_an_independent_trapezoid():
    # A linear-between-samples spectrum integrates to the trapezoid rule on its own samples, exactly;
    # numpy.trapezoid on pvlib's data is the independent implementation. The table covers 280-4000 nm
    # only, so it holds 1347.9 W/m^2 of the 1366.1 W/m^2 solar constant its SMARTS spectrum is scaled to
    # (thesis sec. 2.3.2): the 18 W/m^2 (1.3 %) beyond 4000 nm and below 280 nm are not tabulated.
    from pvlib.spectrum import get_reference_spectra
    ref = get_reference_spectra(standard="ASTM G173-03")["extraterrestrial"]
    total = sp.integral_of_product(sp.solar_spectrum())
    assert total == pytest.approx(np.trapezoid(ref.to_numpy(), ref.index.to_numpy()), rel=1e-12)
    assert 1366.1 * (1 - 0.02) < total < 1366.1


def test_flat_responsivity_gives_the_whole_spectrum_and_any_band_of_it():
    e = sp.solar_spectrum()
    whole = sp.integral_of_product(e)
    assert sp.integral_of_product(_flat(280, 4000), e) == pytest.approx(whole, rel=1e-13)
    assert sp.integral_of_product(_flat(100, 9000), e) == pytest.approx(whole, rel=1e-13)   # wider than the table
    # a band between two table knots: the trapezoid rule on the table's samples inside it
    w_nm, v = e.wavelength_m / NM, e.value * NM
    inside = (w_nm >= 400) & (w_nm <= 1100)
    assert sp.integral_of_product(_flat(400, 1100), e) == pytest.approx(
        np.trapezoid(v[inside], w_nm[inside]), rel=1e-12)


# --- the integrator ------------------------------------------------------------------------------------

def test_product_integrals_are_exact_for_piecewise_linear_data():
    # closed forms on [0, 1] m: integral x * x = 1/3; integral x * (1 - x) = 1/6; integral x * x * x = 1/4
    up = sp.Spectrum("up", np.array([0.0, 1.0]), np.array([0.0, 1.0]), "1", "test")
    down = sp.Spectrum("down", np.array([0.0, 1.0]), np.array([1.0, 0.0]), "1", "test")
    assert sp.integral_of_product(up, up) == pytest.approx(1 / 3, rel=1e-15)
    assert sp.integral_of_product(up, down) == pytest.approx(1 / 6, rel=1e-15)
    assert sp.integral_of_product(up, up, weight_power=1) == pytest.approx(1 / 4, rel=1e-15)
    # grids that do not share knots: a tent (peak 1 at 0.5) times a ramp sampled elsewhere; exact value by
    # splitting at 0.5: integral_0^0.5 2x * x dx + integral_0.5^1 2(1-x) * x dx = 1/12 + 1/6 = 1/4
    tent = sp.Spectrum("tent", np.array([0.0, 0.5, 1.0]), np.array([0.0, 1.0, 0.0]), "1", "test")
    ramp = sp.Spectrum("ramp", np.array([0.0, 0.3, 0.9, 1.0]), np.array([0.0, 0.3, 0.9, 1.0]), "1", "test")
    assert sp.integral_of_product(tent, ramp) == pytest.approx(0.25, rel=1e-14)
    # no overlap: nothing is converted
    assert sp.integral_of_product(_flat(100, 200), _flat(300, 400)) == 0.0


def test_resampling_a_curve_conserves_its_area_and_its_band_irradiance():
    s = sp.responsivity("BPW34")
    area = sp.integral_of_product(s)
    assert area == pytest.approx(np.trapezoid(s.value, s.wavelength_m), rel=1e-13)   # trapezoid on its samples
    fine_w = np.unique(np.concatenate([s.wavelength_m, np.linspace(s.wavelength_m[0], s.wavelength_m[-1], 7919)]))
    fine = sp.Spectrum("fine", fine_w, s.at(fine_w), "1", "resampled")
    assert sp.integral_of_product(fine) == pytest.approx(area, rel=1e-13)
    e = sp.solar_spectrum()
    assert sp.integral_of_product(fine, e) == pytest.approx(sp.integral_of_product(s, e), rel=1e-13)


def test_effective_wavelength_and_photocurrent_closed_forms():
    # flat spectrum, flat band 700-900 nm: the band centre 800 nm, E_S0 = E_lambda * 200 nm
    e_flat = sp.Spectrum("flat E", np.array([200.0, 2000.0]) * NM, np.array([1.5e9, 1.5e9]), "W m^-2 m^-1", "test")
    band = _flat(700, 900)
    assert sp.integral_of_product(band, e_flat) == pytest.approx(1.5e9 * 200 * NM, rel=1e-14)
    assert sp.integral_of_product(band, e_flat, weight_power=1) / sp.integral_of_product(band, e_flat) == \
        pytest.approx(800 * NM, rel=1e-14)


# --- the shipped diode curve: Vishay BPW34, data sheet doc. 81521 rev. 2.1 (23-Aug-11) ---------------

def test_bpw34_curve_peaks_where_its_data_sheet_says():
    s = sp.responsivity("BPW34")
    w_nm = s.wavelength_m / NM
    # Axis normalisation of fig. 7: the drawn maximum is 1.0 to the figure's line width (0.001 of the axis)
    assert s.value.max() == pytest.approx(1.0, abs=0.005)
    # Data sheet p. 2: "Wavelength of peak sensitivity lambda_p 900 nm". The drawn curve is flat-topped
    # (within 1 % of its maximum over ~890-945 nm), so its argmax is ill-defined to tens of nm; the test is
    # that 900 nm lies inside that flat top and that the flat top is narrower than the 430-1100 nm band.
    top = w_nm[s.value >= 0.99 * s.value.max()]
    assert top.min() <= 900 <= top.max()
    assert top.max() - top.min() < 80


def test_bpw34_ten_percent_band_is_the_data_sheets():
    # Data sheet pp. 1-2: "Range of spectral bandwidth lambda_0.1: 430 to 1100 nm" (S_rel = 0.1), given to
    # 10 nm: the lower crossing is within 5 nm of 430 nm; fig. 7 ends at 1098.6 nm still above 0.1, so
    # the upper crossing lies at or beyond the curve's end, within 5 nm of 1100 nm.
    s = sp.responsivity("BPW34")
    w_nm = s.wavelength_m / NM
    lower = w_nm[np.argmax(s.value >= 0.1)]
    assert abs(lower - 430) <= 5
    assert s.value[-1] >= 0.1 and abs(w_nm[-1] - 1100) <= 5
    assert np.all(s.value[(w_nm > lower) & (w_nm < w_nm[-1])] >= 0.1)


def test_bpw34_curve_with_the_data_sheets_responsivity_never_beats_one_electron_per_photon():
    # Data sheet p. 2: short-circuit current I_k = 47 uA at E_e = 1 mW/cm^2, lambda = 950 nm, on the radiant
    # sensitive area of 7.5 mm^2 (p. 1): R(950 nm) = 47e-6 / (10 * 7.5e-6) = 0.627 A/W, so
    # R(lambda) = R(950) * S_rel(lambda) / S_rel(950). A quantum efficiency R h c / (q lambda) above 1 at any
    # wavelength would mean a wrongly scaled or shifted curve.
    s = sp.responsivity("BPW34")
    r950 = 47e-6 / (10.0 * 7.5e-6)
    r = r950 * s.value / s.at(950 * NM)
    qe = r * H_J_S * C_M_S / (Q_C * s.wavelength_m)
    assert qe.max() < 1.0
    assert qe.max() > 0.7          # a silicon PIN diode near its peak (thesis sec. 2.4.1: Si 200-1100 nm)


def test_bpw34_band_integrated_values_are_consistent():
    e_s0 = sp.band_irradiance_w_m2("BPW34")
    total = sp.integral_of_product(sp.solar_spectrum())
    # bounds by construction of S_rel <= 1 and its support 401-1099 nm: E_S0 is at most the spectrum's
    # irradiance in that band, and at least S_rel's minimum over 500-1000 nm times the irradiance there
    s = sp.responsivity("BPW34")
    e = sp.solar_spectrum()
    band = sp.integral_of_product(_flat(s.wavelength_m[0] / NM, s.wavelength_m[-1] / NM), e)
    w_nm = s.wavelength_m / NM
    floor = s.value[(w_nm >= 500) & (w_nm <= 1000)].min() * sp.integral_of_product(_flat(500, 1000), e)
    assert floor < e_s0 < band
    assert sp.in_band_fraction("BPW34") == pytest.approx(e_s0 / total, rel=1e-15)
    lam = sp.effective_wavelength_m("BPW34")
    assert s.wavelength_m[0] < lam < s.wavelength_m[-1]
    assert sp.photocurrent_density_a_m2("BPW34", 0.6) == pytest.approx(0.6 * e_s0, rel=1e-15)


# --- the shipped diode curve: Vishay BPV23F, data sheet doc. 81510 rev. 1.8 (24-Aug-11) ---------------

def test_bpv23f_curve_peaks_where_its_data_sheet_says():
    s = sp.responsivity("BPV23F")
    w_nm = s.wavelength_m / NM
    assert s.value.max() == pytest.approx(1.0, abs=0.005)                  # fig. 6 axis normalisation
    # Data sheet p. 2: "Wavelength of peak sensitivity lambda_p 950 nm"; the drawn top is flat (within 1 %
    # of its maximum over ~925-962 nm): 950 nm must lie inside it.
    top = w_nm[s.value >= 0.99 * s.value.max()]
    assert top.min() <= 950 <= top.max()
    assert top.max() - top.min() < 60


def test_bpv23f_curve_matches_the_data_sheets_absolute_sensitivities():
    # Data sheet p. 2, "Absolute spectral sensitivity" at V_R = 5 V: s(870 nm) = 0.35 A/W, s(950 nm) = 0.6 A/W.
    # As printed, 0.35 is good to +-0.005 and 0.6 to +-0.05, so s(870)/s(950) lies in [0.345/0.65, 0.355/0.55];
    # the figure's S_rel(870) / S_rel(950) must fall inside.
    s = sp.responsivity("BPV23F")
    ratio = s.at(870 * NM) / s.at(950 * NM)
    assert 0.345 / 0.65 <= ratio <= 0.355 / 0.55
    # ... and 0.6 A/W at 950 nm with this curve's shape never exceeds one electron per photon
    r = 0.6 * s.value / s.at(950 * NM)
    assert np.max(r * H_J_S * C_M_S / (Q_C * s.wavelength_m)) < 1.0


def test_bpv23f_band_integrated_irradiance_is_the_thesis_e_s0():
    # Thesis table 3.2.3: E_S0 = 154.1 W/m^2 for the BPV23F, the trapezoid sum of S_R(lambda) E(lambda) over a
    # hand digitisation (WebPlotDigitizer, fig. 3.4) of the same data-sheet figure and a SMARTS 2.95 AM0
    # spectrum at 1366.1 W/m^2 (fig. 2.1) -- the Gueymard spectrum that ASTM G173's Etr column also
    # tabulates, so the G173 table is used as it is (not rescaled: its missing 18 W/m^2 lie outside
    # 280-4000 nm, where this diode sees nothing).
    # Tolerance: a hand digitisation of a 135 x 124 pt plot is good to about one click, 0.5 % of each axis:
    # 2 nm in wavelength (changes this E_S0 by 0.42 %), 0.006 offset in S_rel (1.06 %) and a 0.5 % scale
    # error (0.5 %); their root sum of squares is 1.25 %, so 1.3 %.
    assert sp.band_irradiance_w_m2("BPV23F") == pytest.approx(154.1, rel=0.013)
    lam = sp.effective_wavelength_m("BPV23F")
    s = sp.responsivity("BPV23F")
    assert s.wavelength_m[0] < lam < s.wavelength_m[-1]


# --- user errors ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["BPW34FS", "SFH2430", "BPW34FAS"])
def test_thesis_diodes_without_a_citable_curve_say_so(name):
    with pytest.raises(InvalidInputError, match=f"no citable tabulated curve of the {name}.*README"):
        sp.responsivity(name)


def test_unknown_diode_and_bad_responsivity_are_user_errors():
    with pytest.raises(UserError, match="did you mean BPW34"):
        sp.responsivity("BPW43")
    assert sp.responsivity("bpw34").name == "BPW34"                         # case-insensitive
    with pytest.raises(InvalidInputError, match="positive number of A/W"):
        sp.photocurrent_density_a_m2("BPW34", -0.6)
    assert sp.diode_curves() == ("BPV23F", "BPW34")
