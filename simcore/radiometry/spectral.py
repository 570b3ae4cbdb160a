"""Spectral data shipped with sunsim and the solar irradiance a photodiode converts (thesis eqs. 3.1-3.5).

A photodiode does not turn all of the Sun's 1366 W/m^2 into current: with the
relative spectral sensitivity S_rel(lambda) = R(lambda) / R_max of its data
sheet (eq. 2.23), the photocurrent at normal incidence is

    I_theta0 = R_max * A * integral S_rel(lambda) E(lambda) dlambda = R_max * A * E_S0     (eqs. 3.4-3.5)

so the *band-integrated* (effective) irradiance E_S0 is the irradiance the
diode "sees" (thesis table 3.2.3; :mod:`simcore.sensor.chain` uses the
thesis' values). This module computes it from the package data in
``simcore/data/spectra/`` (provenance of every curve in its README.md):

* the relative spectral sensitivity of each diode whose curve could be traced
  to its data sheet (:func:`responsivity`, :func:`diode_curves`);
* the ASTM G173-03 extraterrestrial (AM0) solar spectrum (:func:`solar_spectrum`).

Every tabulated quantity is a :class:`Spectrum`: linear between its samples,
zero outside them. Integrals of products of spectra are exact for such
piecewise-linear data (two-point Gauss-Legendre on the union of the sample
grids, exact up to cubic integrands), so resampling a curve onto a finer grid
never changes an integral. SI inside: wavelengths in m, spectral irradiance in
W m^-2 m^-1; the CSV files use nm as their sources do.
"""
import difflib
from dataclasses import dataclass
from importlib import resources

import numpy as np

from simcore.errors import InvalidInputError

SOLAR_FILE = "astm_g173_etr.csv"
NM_M = 1e-9

# The thesis' diodes (table 3.2.3; simcore.sensor.chain.DIODES) for which no citable tabulated curve
# was found: named in the error for them so the user learns why (see simcore/data/spectra/README.md).
NOT_SHIPPED = ("BPW34FS", "SFH2430", "BPW34FAS")

# Gauss-Legendre, two nodes on [0, 1]: exact for polynomials up to degree 3 (a product of up to
# three linear factors in one interval, e.g. lambda * S_rel * E for the effective wavelength).
_GL_T = 0.5 + np.array([-0.5, 0.5]) / np.sqrt(3.0)


@dataclass(frozen=True)
class Spectrum:
    """A tabulated spectral quantity: ``value`` at ``wavelength_m`` (m, strictly increasing), linear between
    samples and zero outside them; ``unit`` names the unit of ``value``, ``source`` where it comes from."""

    name: str
    wavelength_m: np.ndarray
    value: np.ndarray
    unit: str
    source: str

    def __post_init__(self):
        w = np.array(self.wavelength_m, dtype=float)          # own copies: frozen below, the caller's stay free
        v = np.array(self.value, dtype=float)
        if w.ndim != 1 or v.shape != w.shape or w.size < 2:
            raise ValueError(f"spectrum {self.name!r}: wavelength_m and value must be 1-D arrays of the same "
                             f"length >= 2, got shapes {w.shape} and {v.shape}")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(v)) and np.all(np.diff(w) > 0)):
            raise ValueError(f"spectrum {self.name!r}: wavelengths must be finite and strictly increasing "
                             "and values finite")
        w.flags.writeable = False
        v.flags.writeable = False
        object.__setattr__(self, "wavelength_m", w)
        object.__setattr__(self, "value", v)

    def at(self, wavelength_m):
        """Return the value at ``wavelength_m`` (m, any shape): linear between samples, 0 outside them."""
        return np.interp(wavelength_m, self.wavelength_m, self.value, left=0.0, right=0.0)


def _read_csv(filename):
    """Return (first column, second column) of ``simcore/data/spectra/<filename>`` ('#' lines are comments)."""
    text = resources.files("simcore").joinpath("data", "spectra", filename).read_text()
    rows = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    data = np.array([[float(x) for x in ln.split(",")] for ln in rows[1:]])   # rows[0]: the column names
    return data[:, 0], data[:, 1]


def _source(filename):
    """Return the comment header of a shipped CSV file, joined into one line."""
    text = resources.files("simcore").joinpath("data", "spectra", filename).read_text()
    return " ".join(ln.lstrip("# ").strip() for ln in text.splitlines() if ln.startswith("#"))


def diode_curves():
    """Return the names of the diodes whose relative spectral sensitivity is shipped (sorted)."""
    files = resources.files("simcore").joinpath("data", "spectra").iterdir()
    return tuple(sorted(f.name[:-4] for f in files if f.name.endswith(".csv") and f.name != SOLAR_FILE))


def responsivity(name):
    """Return the relative spectral sensitivity S_rel(lambda) = R(lambda) / R_max (eq. 2.23) of diode ``name``
    (case-insensitive) as a :class:`Spectrum` (dimensionless, wavelength in m).

    Raises :class:`~simcore.errors.InvalidInputError` for a diode whose curve is not shipped, saying which are.
    """
    shipped = {n.upper(): n for n in diode_curves()}
    key = str(name).upper()
    if key not in shipped:
        if key in NOT_SHIPPED:
            why = (f"no citable tabulated curve of the {key} was found, so none is shipped "
                   "(see simcore/data/spectra/README.md)")
        else:
            close = difflib.get_close_matches(key, list(shipped), n=3, cutoff=0.4)
            why = "unknown diode" + (f"; did you mean {', '.join(shipped[c] for c in close)}?" if close else "")
        raise InvalidInputError(f"no spectral responsivity for {name!r}: {why}; shipped curves: "
                                f"{', '.join(shipped.values())}")
    filename = shipped[key] + ".csv"
    w_nm, s = _read_csv(filename)
    return Spectrum(shipped[key], w_nm * NM_M, s, "1", _source(filename))


def solar_spectrum():
    """Return the ASTM G173-03 extraterrestrial solar spectral irradiance at 1 AU as a :class:`Spectrum`
    (W m^-2 m^-1, wavelength 280 nm .. 4000 nm in m)."""
    w_nm, e = _read_csv(SOLAR_FILE)
    return Spectrum("ASTM G173-03 extraterrestrial", w_nm * NM_M, e / NM_M, "W m^-2 m^-1", _source(SOLAR_FILE))


def integral_of_product(*spectra, weight_power=0):
    """Return the integral over wavelength (m) of the product of ``spectra`` times lambda^weight_power
    (lambda in m), each spectrum linear between its samples and zero outside them.

    The integral runs over the wavelengths all spectra cover and is exact for piecewise-linear data
    (two-point Gauss-Legendre on the union of the sample grids, degree <= 3): at most three factors
    counting lambda when ``weight_power`` is 1.
    """
    if not spectra:
        raise ValueError("integral_of_product needs at least one spectrum")
    if weight_power not in (0, 1) or len(spectra) + weight_power > 3:
        raise ValueError("integral_of_product is exact for at most three linear factors (lambda counts as one)")
    lo = max(s.wavelength_m[0] for s in spectra)
    hi = min(s.wavelength_m[-1] for s in spectra)
    if not hi > lo:
        return 0.0
    knots = np.unique(np.concatenate([[lo, hi]] + [s.wavelength_m for s in spectra]))
    knots = knots[(knots >= lo) & (knots <= hi)]
    h = np.diff(knots)
    # interior points of each interval only: the zero outside a curve's range never enters
    x = knots[:-1, None] + h[:, None] * _GL_T[None, :]
    f = np.ones_like(x)
    for s in spectra:
        f = f * s.at(x)
    if weight_power:
        f = f * x
    return float(np.sum(0.5 * h * f.sum(axis=1)))


def band_irradiance_w_m2(name, spectrum=None):
    """Return E_S0 = integral S_rel(lambda) E(lambda) dlambda (W/m^2, eq. 3.4): the solar irradiance at normal
    incidence weighted by diode ``name``'s relative spectral sensitivity; ``spectrum`` defaults to
    :func:`solar_spectrum` (AM0 at 1 AU)."""
    e = solar_spectrum() if spectrum is None else spectrum
    return integral_of_product(responsivity(name), e)


def in_band_fraction(name, spectrum=None):
    """Return E_S0 / integral E(lambda) dlambda (dimensionless): the share of the spectrum's irradiance that
    diode ``name`` converts at its peak responsivity (the integral over the spectrum's tabulated range)."""
    e = solar_spectrum() if spectrum is None else spectrum
    return band_irradiance_w_m2(name, e) / integral_of_product(e)


def effective_wavelength_m(name, spectrum=None):
    """Return the responsivity-weighted mean wavelength of the converted light (m):
    integral lambda S_rel E dlambda / integral S_rel E dlambda, the diode's effective band centre."""
    e = solar_spectrum() if spectrum is None else spectrum
    s = responsivity(name)
    return integral_of_product(s, e, weight_power=1) / integral_of_product(s, e)


def photocurrent_density_a_m2(name, peak_responsivity_a_w, spectrum=None):
    """Return the short-circuit photocurrent per unit sensitive area at normal Sun, R_max * E_S0 (A/m^2,
    eqs. 3.4-3.5 with C_T = 1), for the data sheet's peak responsivity ``peak_responsivity_a_w`` (A/W)."""
    r = float(peak_responsivity_a_w)
    if not (np.isfinite(r) and r > 0):
        raise InvalidInputError(f"peak responsivity must be a positive number of A/W (data sheet), got {r}")
    return r * band_irradiance_w_m2(name, spectrum)
