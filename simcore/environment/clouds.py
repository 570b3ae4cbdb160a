"""Cloud weather: one random, spatially correlated realisation of the Earth's reflectivity per seed,
whose average over seeds is the all-sky climatology, cell for cell.

An annual-mean albedo map is what no satellite ever sees: on any day a cell is either under a cloud
system or clear. :class:`CloudWeather` turns a pair of climatologies of the same grid, the clear-sky
and the all-sky mean (shipped: CERES 2018, ``ceres2018-clear`` / ``ceres2018-all``), into "weather":

* Each cell is either **clear**, reflecting its clear-sky mean ``R_clear``, or **overcast** by a thick
  cloud of broadband top-of-atmosphere albedo ``R_ovc`` (:data:`OVERCAST_ALBEDO` = 0.70: in the limit of
  thick clouds, observed TOA albedos do not exceed 0.7 -- Cess et al. 1996, J. Geophys. Res. 101(D18),
  23299-23309, abstract; CERES deep convective clouds, the thickest there are, absorb ~25 % of the
  sunlight -- Hu et al. 2004, IEEE TGRS 42(11), 2594-2599 --, so their albedo is at most ~0.75).
* The cell's probability of being overcast is the cloud fraction that makes the mixture's mean the
  all-sky value exactly, ``f = (R_all - R_clear) / (R_ovc - R_clear)``, so
  ``E[R] = (1 - f) R_clear + f R_ovc = R_all``. Where that fraction leaves [0, 1] the states are chosen
  per cell so that the mean still is ``R_all`` exactly: where ``R_all > R_ovc`` (344 of CERES 2018's
  cells, all on the Antarctic plateau, 74.5-88.5 S, up to 0.712: snow brighter than thick cloud) the
  cloudy state is ``R_all`` itself and ``f = 1``; where ``R_all <= R_clear`` (447 of CERES 2018's 64 800 cells: 398 poleward of
  55 deg over snow and sea ice, the other 49 over bright deserts and their coasts -- Sahara, Arabia,
  Namib, Thar --, by up to 0.11: broken clouds darken a bright surface -- Welch & Wielicki 1989,
  J. Atmos. Sci. 46, 1384-1395 --, and the clear-sky mean samples other days than the all-sky one)
  the pair says nothing about the weather, and the cell keeps ``R_all`` (``f = 0``, its
  clear state being ``R_all``). ``f`` is an *effective thick-cloud* fraction: real cover is larger
  (about 0.6-0.7 of the globe, ISCCP/MODIS) because many clouds are thin; CERES 2018 gives a mean
  ``f`` of 0.28 (area-weighted, :attr:`CloudWeather.mean_cloud_fraction`). A binary thick/clear
  mixture is the most variable weather between these bounds with the climatology's mean: a pessimistic case for a
  Sun sensor, not a typical one.
* Which cells are overcast comes from one isotropic Gaussian random field ``g`` on the sphere, unit
  variance, with a Gaussian angular power spectrum ``C_l ~ exp(-l (l + 1) theta_L^2 / 2)``,
  ``theta_L = L / R_earth``: the heat kernel of the sphere, whose correlation at great-circle distance
  ``d`` is ``rho(d) = exp(-d^2 / (2 L^2))`` to relative order ``theta_L^2`` (exactly
  ``sum_l (2l+1) C_l P_l(cos(d/R)) / sum_l (2l+1) C_l``, :meth:`CloudWeather.correlation`). A cell is
  overcast where ``g > Phi^-1(1 - f)`` (``Phi`` the standard normal distribution), which happens with
  probability ``f`` exactly, whatever ``L``: neighbouring cells are overcast together, as cloud systems
  are, and the mean over seeds stays the climatology.
* The correlation length ``L`` (:data:`DEFAULT_SCALE_KM` = 500 km, ``--cloud-scale-km``) sets the size
  of the cloud systems. By Rice's formula (S. O. Rice 1945, Bell Syst. Tech. J. 24, 46-156: a stationary Gaussian
  process crosses its mean (1 / pi) sqrt(-rho''(0)) times per unit length) a field with this
  correlation crosses its median 1 / (pi L) times per unit length, so at
  f = 1/2 cloudy and clear stretches along a great circle average ``pi L`` = 1570 km: the horizontal scale of
  synoptic systems, "about 1,000-2,000 km" (R. G. Barry & A. M. Carleton, *Synoptic and Dynamic
  Climatology*, Routledge 2001). Allowed: 200 to 5000 km (below, the synthesis grid would need 50
  million pixels -- nside 2048 -- and the map's 111 km cells would draw the systems only a few cells
  across; above, one system covers the whole disc a low orbit sees, some 5600 km across from 665 km).

The field is synthesised with healpy from spherical-harmonic coefficients drawn by a numpy Generator
seeded only by the cloud seed (healpy's own ``synalm``/``synfast`` draw from numpy's global random
state, so they are not used): a seed gives the same map on any machine, independent of the run's
``--seed``. Each map cell takes the field at the nearest pixel of a HEALPix grid fine enough that its
pixels lie within ``L / 25`` of the cell centres (so the marginal at every cell is exactly N(0, 1) and
the correlation between cells is the spectrum's at distances off by at most ``2 L / 25``).

What is not modelled: cloud types and partial cover within a cell, the clouds' own angular
reflectance (the map stays Lambertian, as the albedo model is), the daily cycle, and any change of
the weather during a run (one realisation is frozen for the whole span, the Earth turning beneath it:
for a run of a few orbits a fair picture, for a day a crude one).
"""
import json
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from simcore.constants import R_EARTH_MEAN_M
from simcore.environment.maps import ReflectivityMap
from simcore.errors import InvalidInputError

OVERCAST_ALBEDO = 0.70          # thick-cloud broadband TOA albedo: Cess et al. 1996 (module docstring)
DEFAULT_SCALE_KM = 500.0        # correlation length: pi L ~ 1570 km, a synoptic system (module docstring)
SCALE_RANGE_KM = (200.0, 5000.0)
MAX_SEED = 2 ** 64 - 1
# The all-sky maps that have a clear-sky partner on the same grid: all-sky name -> clear-sky name.
CLOUD_PAIRS = {"ceres2018-all": "ceres2018-clear"}
# The band maps of a diode (simcore.radiometry.band) pair the same way: 'band[:DIODE]' -> 'band-clear[:DIODE]'.
BAND_ALL_SKY, BAND_CLEAR_SKY = "band", "band-clear"
# Fixed entropy that keeps the cloud seeds' random streams apart from every other use of a seed.
_STREAM = 0x636C6F756473        # "clouds"
# Coefficients beyond lmax carry less than this share of the field's variance (they are left out, and
# the variance used for normalising is that of the coefficients kept: the marginal stays exactly N(0, 1)).
_SPECTRUM_TAIL = 1e-14
_PIXEL_SHARE = 25               # HEALPix pixels lie within L / _PIXEL_SHARE of the map's cell centres


def clear_sky_partner(map_name):
    """Return the name of the clear-sky map paired with the all-sky map ``map_name``; raise
    InvalidInputError (a user mistake) when it has none."""
    key = str(map_name).replace("_", "-")
    if key in CLOUD_PAIRS:
        return CLOUD_PAIRS[key]
    head, colon, diode = key.partition(":")
    if head == BAND_ALL_SKY:        # a diode's band pair (simcore.radiometry.band), which checks the diode
        return BAND_CLEAR_SKY + colon + diode
    raise InvalidInputError(
        f"--clouds needs an all-sky map with a clear-sky partner, and --map {map_name} has none: cloud weather "
        f"is drawn between the clear-sky and all-sky climatologies so that its mean is the all-sky map; use "
        f"--map {' or '.join(CLOUD_PAIRS)} or {BAND_ALL_SKY}[:DIODE]")


def check_cloud_seed(seed, option="--clouds"):
    """Raise InvalidInputError unless ``seed`` is a cloud-weather seed (a whole number 0 .. 2^64-1)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) <= MAX_SEED:
        raise InvalidInputError(f"{option} takes a cloud-weather seed, a whole number from 0 to 2^64-1, got {seed}")


def check_cloud_options(map_name, seed, scale_km=None, seed_option="--clouds"):
    """Raise InvalidInputError unless ``seed`` (0 .. 2^64-1), ``scale_km`` (None: the default, or
    200..5000 km) and the map ``map_name`` can make cloud weather; ``seed_option`` names the seed's option in
    the message."""
    check_cloud_seed(seed, seed_option)
    if scale_km is not None:
        lo, hi = SCALE_RANGE_KM
        try:
            ok = lo <= float(scale_km) <= hi
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise InvalidInputError(f"--cloud-scale-km must be a correlation length from {lo:g} to {hi:g} km "
                                    f"(default {DEFAULT_SCALE_KM:g}), got {scale_km}")
    clear_sky_partner(map_name)


@dataclass(frozen=True, eq=False)
class CloudWeather:
    """The cloud-weather model between a clear-sky and an all-sky map of one grid (module docstring)."""

    clear: ReflectivityMap
    all_sky: ReflectivityMap
    scale_m: float = DEFAULT_SCALE_KM * 1e3
    overcast_albedo: float = OVERCAST_ALBEDO

    def __post_init__(self):
        if self.clear.shape != self.all_sky.shape or not (
                np.allclose(self.clear.lat_deg, self.all_sky.lat_deg)
                and np.allclose(self.clear.lon_deg, self.all_sky.lon_deg)):
            raise ValueError(f"the clear-sky map {self.clear!r} and the all-sky map {self.all_sky!r} must share "
                             "one grid (same cell centres)")
        if not (np.isfinite(self.scale_m) and self.scale_m > 0):
            raise ValueError(f"scale_m must be a positive correlation length in metres, got {self.scale_m}")
        if not 0 < self.overcast_albedo <= 1:
            raise ValueError(f"overcast_albedo must be in (0, 1], got {self.overcast_albedo}")

    @classmethod
    def for_map(cls, map_name, scale_km=None):
        """Return the model whose mean is the shipped all-sky map ``map_name`` (e.g. 'ceres2018-all'),
        correlation length ``scale_km`` (None: :data:`DEFAULT_SCALE_KM`); a map without a clear-sky
        partner or a length outside 200..5000 km is a user mistake (InvalidInputError)."""
        from simcore.environment.maps import named_map
        check_cloud_options(map_name, 0, scale_km)
        km = DEFAULT_SCALE_KM if scale_km is None else float(scale_km)
        return cls(named_map(clear_sky_partner(map_name)), named_map(map_name), scale_m=km * 1e3)

    # ---- the two states of each cell and its cloud fraction -----------------------------------------
    @cached_property
    def clear_state(self):
        """Return the reflectivity of each cell when clear (n_lat, n_lon): ``min(R_clear, R_all)``."""
        return np.minimum(self.clear.values, self.all_sky.values)

    @cached_property
    def cloudy_state(self):
        """Return the reflectivity of each cell when overcast (n_lat, n_lon): ``max(R_ovc, R_all)``."""
        return np.maximum(self.overcast_albedo, self.all_sky.values)

    @cached_property
    def cloud_fraction(self):
        """Return the probability that each cell is overcast (n_lat, n_lon), in [0, 1]: the one that makes
        the mixture's mean the all-sky value."""
        lo, hi, r = self.clear_state, self.cloudy_state, self.all_sky.values
        span = hi - lo
        f = np.divide(r - lo, span, out=np.zeros_like(r), where=span > 0)
        return np.clip(f, 0.0, 1.0)

    def expected_values(self):
        """Return the mean reflectivity over all realisations (n_lat, n_lon): the all-sky map by construction."""
        f = self.cloud_fraction
        return (1.0 - f) * self.clear_state + f * self.cloudy_state

    @cached_property
    def mean_cloud_fraction(self):
        """Return the area-weighted mean of :attr:`cloud_fraction` over the globe (unitless)."""
        w = self.all_sky.cell_area_m2
        return float(np.sum(self.cloud_fraction * w) / np.sum(w))

    # ---- the Gaussian random field ---------------------------------------------------------------
    @property
    def scale_rad(self):
        """Return the correlation length as an angle on the sphere (rad): L / R_earth."""
        return self.scale_m / R_EARTH_MEAN_M

    @cached_property
    def spectrum(self):
        """Return the angular power spectrum C_l, l = 0..lmax, of the unit-variance field:
        ``exp(-l (l + 1) theta_L^2 / 2)`` normalised so that ``sum (2l+1) C_l / (4 pi) = 1``."""
        t2 = self.scale_rad ** 2
        # (2l+1) exp(-l(l+1) t2/2) falls below the tail share of its sum well before this l
        l_top = int(np.ceil(np.sqrt(2.0 * -np.log(_SPECTRUM_TAIL) / t2) + 10))
        ell = np.arange(l_top + 1)
        shape = np.exp(-ell * (ell + 1) * t2 / 2.0)
        weight = (2 * ell + 1) * shape
        tail = np.cumsum(weight[::-1])[::-1] / weight.sum()       # share of the variance at l and above
        lmax = max(int(np.argmax(tail < _SPECTRUM_TAIL)) - 1, 1)
        cl = shape[:lmax + 1]
        return cl * (4.0 * np.pi / np.sum((2 * ell[:lmax + 1] + 1) * cl))

    @property
    def lmax(self):
        """Return the highest multipole of the field."""
        return len(self.spectrum) - 1

    @cached_property
    def nside(self):
        """Return the HEALPix resolution on which the field is synthesised: the coarsest (>= 64) whose
        pixels lie within L / 25 of any point."""
        import healpy as hp
        nside = 64
        while hp.max_pixrad(nside) > self.scale_rad / _PIXEL_SHARE:
            nside *= 2
        return nside

    def correlation(self, distance_m):
        """Return the field's correlation at great-circle distance ``distance_m`` (any shape):
        ``sum (2l+1) C_l P_l(cos(d / R)) / sum (2l+1) C_l`` (the addition theorem)."""
        from numpy.polynomial import legendre
        cl = self.spectrum
        ell = np.arange(len(cl))
        x = np.cos(np.asarray(distance_m, dtype=float) / R_EARTH_MEAN_M)
        return legendre.legval(x, (2 * ell + 1) * cl) / np.sum((2 * ell + 1) * cl)

    def _rng(self, seed):
        check_cloud_seed(seed)
        return np.random.default_rng(np.random.SeedSequence([int(seed), _STREAM]))

    def field_healpix(self, seed):
        """Return the unit-variance Gaussian field of cloud seed ``seed`` on the HEALPix grid
        (:attr:`nside`, RING order), shape (12 nside^2,)."""
        import healpy as hp
        rng = self._rng(seed)
        lmax = self.lmax
        ell, m = hp.Alm.getlm(lmax)
        # a real field: a_l0 real with variance C_l; for m > 0 real and imaginary parts each C_l / 2
        sd = np.sqrt(self.spectrum[ell] * np.where(m == 0, 1.0, 0.5))
        re = rng.standard_normal(ell.size)
        im = rng.standard_normal(ell.size)
        alm = (sd * re + 1j * np.where(m == 0, 0.0, sd * im)).astype(np.complex128)
        return hp.alm2map(alm, self.nside, lmax=lmax, mmax=lmax, pixwin=False)

    @cached_property
    def cell_pixels(self):
        """Return the HEALPix pixel (:attr:`nside`, RING) nearest to each cell centre (n_lat, n_lon)."""
        import healpy as hp
        lat = np.radians(self.all_sky.lat_deg)[:, None]
        lon = np.radians(self.all_sky.lon_deg)[None, :]
        theta, phi = np.broadcast_arrays(np.pi / 2 - lat, np.mod(lon, 2 * np.pi))
        return hp.ang2pix(self.nside, theta, phi)

    def field(self, seed):
        """Return the unit-variance Gaussian field of cloud seed ``seed`` at the map's cells (n_lat, n_lon)."""
        return self.field_healpix(seed)[self.cell_pixels]

    def overcast(self, seed):
        """Return (n_lat, n_lon) bool: the cells that are overcast in realisation ``seed``
        (``g > Phi^-1(1 - f)``, probability ``f`` each)."""
        from scipy.special import ndtri
        with np.errstate(divide="ignore"):
            threshold = -ndtri(self.cloud_fraction)        # = Phi^-1(1 - f); +inf where f = 0, -inf where f = 1
        return self.field(seed) > threshold

    def realise(self, seed):
        """Return the reflectivity map (the all-sky map's grid) of cloud-weather realisation ``seed``."""
        values = np.where(self.overcast(seed), self.cloudy_state, self.clear_state)
        return ReflectivityMap(values, self.all_sky.lat_deg, self.all_sky.lon_deg,
                               name=f"{self.all_sky.name}, cloud weather seed {int(seed)} "
                                    f"(L {self.scale_m / 1e3:g} km)", radius_m=self.all_sky.radius_m)

    def describe(self, seed):
        """Return the model's parameters for realisation ``seed`` as a JSON-able dict (a run file's attrs)."""
        return {"model": "binary clear / thick-cloud cells, overcast where an isotropic Gaussian random field "
                         "(Gaussian angular power spectrum) exceeds the quantile of the cell's cloud fraction "
                         "f = (all - clear) / (overcast - clear); mean over seeds = the all-sky map",
                "seed": int(seed), "scale_km": self.scale_m / 1e3, "overcast_albedo": self.overcast_albedo,
                "clear_sky_map": self.clear.name, "all_sky_map": self.all_sky.name,
                "lmax": self.lmax, "nside": self.nside,
                "mean_cloud_fraction": round(self.mean_cloud_fraction, 6)}

    def attrs(self, seed):
        """Return netCDF attributes recording realisation ``seed`` and the model (str and numbers only)."""
        d = self.describe(seed)
        return {"cloud_seed": d["seed"], "cloud_scale_km": d["scale_km"],
                "cloud_overcast_albedo": d["overcast_albedo"], "cloud_model": json.dumps(d, sort_keys=True)}
