"""Spectral albedo on bare diodes: Monte Carlo over directions AND wavelengths, the check of the band maps.

The band maps (:mod:`simcore.radiometry.band`) fold each CERES cell's spectrum into one band reflectance by
quadrature. This module never reads them: each cell has the spectral reflectance they imply,

    rho(lambda, cell) = a(cell) sum_c g_c(cell) rho_c(lambda) + b(cell),     g_c = f_c / rhobar_c,

with the class shares f_c (MCD12C1), the class TOA spectra rho_c, rhobar_c = int E rho_c / int E the
class's broadband reflectance, and per cell a the reflectance the shape scales (clear sky: R_clear; all
sky: the clear state's share (1 - f) R_clear,state, plus f R_ovc where a cell is brighter than thick
cloud) and b the grey part: the cloud's (f R_ovc x the cloud band factor) and the sea's specular reflection
(a f_water s, its water then weighted (1 - s): :func:`simcore.radiometry.sea_surface.specular_share`) --
:func:`cell_spectra`. Its
S E-weighted band mean is the band map's value exactly (linearity; :meth:`CellSpectra.band_mean`).

The estimator (:func:`spectral_albedo`) draws per lane a direction d uniformly in the cone the Earth fills
seen from the satellite (pdf 1 / (2 pi (1 - cos alpha)), sin alpha = R / |r_sat|), intersects the Earth, a
Mitsuba ``sphere``, draws four wavelengths from the diode's S(lambda) E(lambda) and accumulates

    mean_j[rho(lambda_j, cell) S(lambda_j) E(lambda_j) / p(lambda_j)] cos_sun / pi * max(0, n . d) / pdf(d)

whose expectation is the in-band albedo irradiance (weighted by the relative responsivity S, thesis
eq. 3.4; W/m^2): int S E dlambda times the band reflectance of each cell, i.e. what the band map gives when the analytic model
(:func:`simcore.radiometry.analytic.diode_irradiance`, cosine response) is run with the solar constant
``int S E`` (:func:`band_irradiance`).

Mitsuba's spectral variant (``llvm_ad_spectral``) represents the infrared bands: its default wavelength
sampling (``sample_rgb_spectrum``) covers only MI_CIE_MIN..MI_CIE_MAX = 360..830 nm, but a sensor's
``srf`` (here an ``irregular`` spectrum of S E) is sampled over its own nodes, e.g. 799-1136 nm for the
BPV23F (measured with mitsuba 3.9.1: ``Sensor.sample_wavelengths`` with the srf gave 803-1123 nm for
1000 stratified samples; without it 360.5-827.8 nm), and ``irregular`` spectra evaluate at any wavelength.
So the wavelengths come from ``Sensor.sample_wavelengths`` (four per lane, shifted: stratified) and the
class spectra, S and E are ``irregular`` textures. The srf's pdf is linear between the nodes of S and E
where S E is quadratic, so each wavelength is weighted S E / p (exact expectation, not the srf's integral).

Variants: Mitsuba's variant is process-global and the renderer (:mod:`simcore.render`) uses
``llvm_ad_mono``. Everything here runs inside :func:`_spectral_variant`, which sets ``llvm_ad_spectral`` and
restores the caller's variant afterwards (``mi.variant_context`` refuses when no variant was set; then the
spectral one stays, and a :class:`~simcore.render.Renderer` sets its own on every render anyway).
A mono render before and after a spectral estimate gives identical results (tests/pipeline/test_spectral_check.py).
"""
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from simcore import _llvm
from simcore.environment.clouds import CloudWeather
from simcore.environment.maps import named_map
from simcore.radiometry.band import CLOUD_BAND_FACTOR, class_fractions, class_toa_reflectance
from simcore.radiometry.sea_surface import specular_share
from simcore.radiometry.spectral import NM_M, integral_of_product, solar_spectrum

SPECTRAL_VARIANT = "llvm_ad_spectral"
KINDS = ("clear", "all")


@dataclass(frozen=True)
class CellSpectra:
    """Each map cell's spectral reflectance ``a sum_c g_c rho_c(lambda) + b`` (module docstring): the class
    spectra (``spectra``, :class:`~simcore.radiometry.spectral.Spectrum` each), the weights ``g``
    (n_class, n_lat, n_lon), ``a`` and ``b`` (n_lat, n_lon), south-first on the 1-deg CERES grid from
    longitude -180."""

    classes: tuple
    spectra: tuple
    g: np.ndarray
    a: np.ndarray
    b: np.ndarray
    name: str

    @property
    def shape(self):
        return self.a.shape

    def at(self, wavelength_m, rows, cols):
        """Return rho at ``wavelength_m`` in cells (``rows``, ``cols``) (numpy, broadcast together)."""
        lam = np.asarray(wavelength_m, dtype=float)
        shape_sum = sum(self.g[i][rows, cols] * s.at(lam) for i, s in enumerate(self.spectra))
        return self.a[rows, cols] * shape_sum + self.b[rows, cols]

    def band_mean(self, curve):
        """Return int S E rho / int S E per cell (n_lat, n_lon): what the band map of ``curve`` should hold."""
        e = solar_spectrum()
        e_band = integral_of_product(curve, e)
        k = np.array([integral_of_product(curve, e, s) / e_band for s in self.spectra])
        return self.a * np.tensordot(k, self.g, axes=1) + self.b


def cell_spectra(kind="clear", *, flip_shares=False):
    """Return the :class:`CellSpectra` behind the band maps of kind ``kind`` ('clear' or 'all', the
    CloudWeather mean); ``flip_shares`` reads the class shares north-south flipped (a deliberately wrong
    input, for the check's power)."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    classes, f_c = class_fractions()
    if flip_shares:
        f_c = f_c[:, ::-1, :]
    rho = class_toa_reflectance()
    e = solar_spectrum()
    e_all = integral_of_product(e)
    spectra = tuple(rho[c] for c in classes)
    rhobar = np.array([integral_of_product(e, s) / e_all for s in spectra])
    clear = named_map("ceres2018-clear")
    # the sea's grey specular share s of the clear-sky albedo (simcore.radiometry.sea_surface): of the water's
    # share f_w, the part (1 - s) has 6S's water spectrum, the part s is grey (added to b below)
    share, iw = specular_share(clear), classes.index("water")
    grey = f_c[iw] * share
    g = f_c / rhobar[:, None, None]
    g[iw] *= 1.0 - share
    if kind == "clear":
        a, b = clear.values, np.zeros(clear.shape)
    else:
        w = CloudWeather(clear, named_map("ceres2018-all"))
        f = w.cloud_fraction
        brighter = w.all_sky.values > w.overcast_albedo
        a = (1.0 - f) * w.clear_state + np.where(brighter, f * w.cloudy_state, 0.0)
        b = np.where(brighter, 0.0, f * CLOUD_BAND_FACTOR * w.cloudy_state)
    b = b + a * grey
    name = f"CERES 2018 {kind}-sky x class spectra" + (" (shares flipped N-S)" if flip_shares else "")
    return CellSpectra(tuple(classes), spectra, np.ascontiguousarray(g), np.asarray(a, float),
                       np.asarray(b, float), name)


def band_irradiance(curve):
    """Return int S E dlambda (W/m^2) of the relative sensitivity ``curve`` over the G173 AM0 spectrum."""
    return integral_of_product(curve, solar_spectrum())


@dataclass(frozen=True)
class SpectralEstimate:
    """In-band albedo irradiance on bare diodes (W/m^2, int S E rho weighted): ``mean_w_m2`` and its standard
    error ``se_w_m2``, (N, K), from ``samples`` direction samples (four wavelengths each) per entry."""

    mean_w_m2: np.ndarray
    se_w_m2: np.ndarray
    samples: int


@contextmanager
def _spectral_variant():
    """Run the block with Mitsuba's ``llvm_ad_spectral`` variant and restore the caller's (module docstring)."""
    mi = _llvm.import_mitsuba()
    previous = mi.variant()
    mi.set_variant(SPECTRAL_VARIANT)
    try:
        yield mi
    finally:
        if previous is not None:
            mi.set_variant(previous)


def _irregular(mi, wavelength_nm, values):
    return mi.load_dict({"type": "irregular", "wavelengths": ",".join(f"{x:.6f}" for x in wavelength_nm),
                         "values": ",".join(f"{v:.9g}" for v in values)})


def _nm(spectrum, scale=1.0):
    return spectrum.wavelength_m / NM_M, spectrum.value * scale


def _band_grid_nm(curve, e):
    """Return the union of the nodes of ``curve`` and ``e`` inside ``curve``'s range, nm."""
    w = np.unique(np.concatenate([curve.wavelength_m, e.wavelength_m]))
    w = w[(w >= curve.wavelength_m[0]) & (w <= curve.wavelength_m[-1])]
    return w / NM_M


def _band_sampler(mi, curve):
    """Return (sensor, srf, S, E): an ``irradiancemeter`` whose srf is the ``irregular`` spectrum S E on the
    nodes of both inside the band (W m^-2 nm^-1), and S and E as ``irregular`` spectra (current variant)."""
    e = solar_spectrum()
    grid = _band_grid_nm(curve, e)
    srf = _irregular(mi, grid, curve.at(grid * NM_M) * e.at(grid * NM_M) * NM_M)
    sensor = mi.load_dict({"type": "irradiancemeter", "srf": srf,
                           "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}})
    return sensor, srf, _irregular(mi, *_nm(curve)), _irregular(mi, *_nm(e, NM_M))


def _band_weight(dr, mi, sampler, ctx):
    """Return S E / p at ``ctx.wavelengths`` (W/m^2 per wavelength; 0 at a band end where S and p are 0)."""
    _, srf, s_tex, e_tex = sampler
    pdf = srf.pdf_spectrum(ctx)
    return dr.select(pdf > 0, s_tex.eval(ctx) * e_tex.eval(ctx) / dr.maximum(pdf, 1e-30), 0.0)


def spectral_albedo(r_sat_ecef_m, r_sun_ecef_m, normals_ecef, curve, spectra, *, samples=1 << 14, seed=0,
                    radius_m=None):
    """Return the :class:`SpectralEstimate` of the in-band albedo irradiance on bare (cosine) diodes of unit
    normals ``normals_ecef`` ((K, 3) or (N, K, 3), ECEF) at N epochs (``r_sat_ecef_m``, ``r_sun_ecef_m``:
    (N, 3) geocentric ECEF m), for the relative sensitivity ``curve`` and the cell spectra ``spectra``
    (:class:`CellSpectra`): Monte Carlo over directions and wavelengths (module docstring), ``samples``
    directions per diode-epoch, seeded by ``seed``. The Earth is a sphere of ``radius_m`` (default: the
    CERES map's), the Sun's rays parallel to the geocentric Sun direction (as the analytic model's)."""
    r_sat = np.atleast_2d(np.asarray(r_sat_ecef_m, float))
    r_sun = np.atleast_2d(np.asarray(r_sun_ecef_m, float))
    n_ep = r_sat.shape[0]
    if r_sat.shape != (n_ep, 3) or r_sun.shape != (n_ep, 3):
        raise ValueError(f"r_sat_ecef_m and r_sun_ecef_m must both be (N, 3), got {r_sat.shape} and {r_sun.shape}")
    normals = np.asarray(normals_ecef, float)
    if normals.ndim == 2:
        normals = np.broadcast_to(normals, (n_ep,) + normals.shape)
    if normals.ndim != 3 or normals.shape[0] != n_ep or normals.shape[2] != 3:
        raise ValueError(f"normals_ecef must be (K, 3) or ({n_ep}, K, 3), got {np.shape(normals_ecef)}")
    normals = normals / np.linalg.norm(normals, axis=2, keepdims=True)
    n_k, n_s = normals.shape[1], int(samples)
    if n_s < 2:
        raise ValueError(f"samples must be at least 2 (a standard error needs two), got {samples}")
    radius = float(named_map("ceres2018-clear").radius_m if radius_m is None else radius_m)
    dist = np.linalg.norm(r_sat, axis=1)
    if np.any(dist <= radius):
        raise ValueError("every satellite position must be above the Earth's surface")
    n_lat, n_lon = spectra.shape
    grid = _band_grid_nm(curve, solar_spectrum())
    cos_alpha = np.sqrt(1.0 - (radius / dist) ** 2)                          # the Earth's cone, per epoch
    rng = np.random.default_rng(seed)
    u = rng.random((3, n_ep * n_k * n_s), dtype=np.float32)
    # float32 1 - u can round to 0 and 1 exactly: keep the cone sample inside (0, 1)
    u = np.clip(u, np.float32(1e-7), np.float32(1.0 - 6e-8))

    dr = _llvm.import_drjit()
    with _spectral_variant() as mi:
        F, U = mi.Float, mi.UInt32
        sampler = _band_sampler(mi, curve)
        class_tex = [_irregular(mi, *_nm(s)) for s in spectra.spectra]
        scene = mi.load_dict({"type": "scene", "earth": {"type": "sphere", "center": [0.0, 0.0, 0.0],
                                                         "radius": radius}})

        lane = dr.arange(U, n_ep * n_k * n_s)
        entry = lane // n_s                     # (epoch, diode) entry, epoch-major
        epoch = entry // n_k

        def per_epoch(values):
            return dr.gather(F, _llvm.host_array(F, values), epoch)

        def per_entry(values):
            return dr.gather(F, _llvm.host_array(F, values), entry)

        sat = mi.Point3f(*(per_epoch(r_sat[:, i]) for i in range(3)))
        to_earth = mi.Vector3f(*(per_epoch(-r_sat[:, i] / dist) for i in range(3)))
        sun = mi.Vector3f(*(per_epoch(r_sun[:, i] / np.linalg.norm(r_sun, axis=1)) for i in range(3)))
        nrm = mi.Vector3f(*(per_entry(normals[:, :, i].reshape(-1)) for i in range(3)))
        cos_a = per_epoch(cos_alpha)
        d_local = mi.warp.square_to_uniform_cone(mi.Point2f(_llvm.host_array(F, u[0]), _llvm.host_array(F, u[1])),
                                                 cos_a)
        d = mi.Frame3f(to_earth).to_world(d_local)
        inv_pdf = 2.0 * dr.pi * (1.0 - cos_a)

        si = scene.ray_intersect(mi.Ray3f(sat, d))
        hit = si.is_valid()
        n_e = dr.normalize(si.p)                # outward normal of the sphere at the hit, from its centre
        cos_sun = dr.maximum(dr.dot(n_e, sun), 0.0)
        cos_d = dr.maximum(dr.dot(nrm, d), 0.0)
        lat = dr.asin(dr.clip(n_e.z, -1.0, 1.0)) * (180.0 / dr.pi)
        lon = dr.atan2(n_e.y, n_e.x) * (180.0 / dr.pi)
        row = dr.clip(U(dr.floor((lat + 90.0) * (n_lat / 180.0))), 0, n_lat - 1)
        col = dr.clip(U(dr.floor((lon + 180.0) * (n_lon / 360.0))), 0, n_lon - 1)
        cell = row * n_lon + col

        ctx = dr.zeros(mi.SurfaceInteraction3f)
        wavelengths, _ = sampler[0].sample_wavelengths(ctx, _llvm.host_array(F, u[2]))
        ctx.wavelengths = wavelengths
        weight = _band_weight(dr, mi, sampler, ctx)
        shape = dr.zeros(mi.UnpolarizedSpectrum)
        for i, tex in enumerate(class_tex):
            g_i = dr.gather(F, _llvm.host_array(F, spectra.g[i]), cell)
            shape += g_i * tex.eval(ctx)
        a = dr.gather(F, _llvm.host_array(F, spectra.a), cell)
        b = dr.gather(F, _llvm.host_array(F, spectra.b), cell)
        rho_w = (a * shape + b) * weight
        lam_mean = (rho_w[0] + rho_w[1] + rho_w[2] + rho_w[3]) * 0.25
        value = dr.select(hit, lam_mean * cos_sun * (1.0 / dr.pi) * cos_d * inv_pdf, 0.0)
        vals = np.array(value, dtype=np.float64).reshape(n_ep, n_k, n_s)
        lam = np.array(wavelengths[0])
        if lam.size and (lam.min() < grid[0] - 1e-3 or lam.max() > grid[-1] + 1e-3):
            raise RuntimeError(f"Mitsuba sampled wavelengths {lam.min():.1f}-{lam.max():.1f} nm outside the "
                               f"band {grid[0]:.1f}-{grid[-1]:.1f} nm")
    mean = vals.mean(axis=2)
    se = vals.std(axis=2, ddof=1) / np.sqrt(n_s)
    return SpectralEstimate(mean, se, n_s)


# ---------------------------------------------------------------------------------------------- the comparison
DEFAULT_START = "2016-07-02T00:45:00Z"      # the default orbit in sunlight (sub-satellite Sun zenith 13-65 deg)
DEFAULT_STEP_S = 300.0
SUNLIT_EPOCHS = 8           # 00:45 to 01:20 is sunlit (the satellite enters the Earth's shadow near 01:25)
# Diode normals in the local frame (x: horizontal toward the Sun's azimuth, y = z cross x, z: nadir)
NORMALS_LOCAL = {"nadir": (0.0, 0.0, 1.0),
                 "45 sunward": (np.sqrt(0.5), 0.0, np.sqrt(0.5)),
                 "45 anti-sun": (-np.sqrt(0.5), 0.0, np.sqrt(0.5)),
                 "horizon sunward": (1.0, 0.0, 0.0),
                 "horizon side": (0.0, 1.0, 0.0)}
REFINE = 3          # the analytic reference sums cells refined 3 x 3; its error bound from the native sum


def local_frames(r_sat_ecef_m, r_sun_ecef_m):
    """Return R_ecef_from_local (N, 3, 3): columns x (horizontal toward the Sun's azimuth), y = z cross x, z
    (nadir)."""
    z = -r_sat_ecef_m / np.linalg.norm(r_sat_ecef_m, axis=1, keepdims=True)
    s = r_sun_ecef_m / np.linalg.norm(r_sun_ecef_m, axis=1, keepdims=True)
    x = s - np.sum(s * z, axis=1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def default_geometry(n_epochs=6, start=DEFAULT_START, step_s=DEFAULT_STEP_S):
    """Return (r_sat_ecef_m, r_sun_ecef_m), (N, 3) each, of ``n_epochs`` epochs of the default orbit from
    ``start`` every ``step_s`` seconds."""
    from simcore.environment.epochs import Epochs
    from simcore.environment.geometry import compute_geometry
    from simcore.environment.orbit import Orbit
    g = compute_geometry(Orbit.default(), Epochs.range(start, (int(n_epochs) - 0.5) * step_s, step_s))
    return g.r_sat_ecef_m[:n_epochs], g.r_sun_ecef_m[:n_epochs]


def band_map_reference(r_sat_ecef_m, r_sun_ecef_m, R_ecef_from_local, normals_local, band_values, e_band_w_m2):
    """Return (albedo (N, K) W/m^2, its discretisation bound (N, K)): the analytic model with bare (cosine)
    diodes on the band map ``band_values`` (180 x 360 south-first), solar constant ``e_band_w_m2``, cells
    refined :data:`REFINE` x :data:`REFINE`; the bound is |native - refined| / (REFINE^2 - 1) (second order,
    as :func:`simcore.pipeline.check.discretisation_bound`)."""
    from simcore.environment.maps import ReflectivityMap
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.radiometry.response import CosineResponse
    from simcore.shapes.aperture import diode_frame
    band_map = ReflectivityMap.from_array(band_values)
    frames = np.stack([diode_frame(np.asarray(n, float)) for n in normals_local])
    out = []
    for f in (1, REFINE):
        res = diode_irradiance(r_sat_ecef_m, r_sun_ecef_m, R_ecef_from_local, frames, CosineResponse(),
                               map=band_map.refined(f), e_sun_w_m2=e_band_w_m2, eclipse=None, direct=False,
                               precision="double")
        out.append(res.albedo_w_m2)
    return out[1], np.abs(out[0] - out[1]) / (REFINE ** 2 - 1.0)


@dataclass(frozen=True)
class Comparison:
    """Spectral estimate vs the band map's analytic albedo, (N, K) each: ``spectral``, ``se``, ``reference``,
    ``disc`` (the reference's discretisation bound), ``z`` = (spectral - reference) / sqrt(se^2 + disc^2), NaN
    where both read an exact 0 (no sunlit Earth in the diode's half-space: nothing to compare)."""

    diode: str
    label: str
    normals: tuple
    spectral: np.ndarray
    se: np.ndarray
    reference: np.ndarray
    disc: np.ndarray
    z: np.ndarray

    @property
    def n(self):
        """Return the number of diode-epochs compared (finite z)."""
        return int(np.sum(np.isfinite(self.z)))

    @property
    def pooled_z(self):
        """Return sum z / sqrt(n) over the finite z: N(0, 1) when the estimates agree."""
        z = self.z[np.isfinite(self.z)]
        return float(np.sum(z) / np.sqrt(z.size)) if z.size else float("nan")

    @property
    def max_abs_z(self):
        z = self.z[np.isfinite(self.z)]
        return float(np.max(np.abs(z))) if z.size else float("nan")


def compare(diode="BPW34FS", *, kind="clear", n_epochs=6, samples=1 << 14, seed=0, normals=None,
            flip_shares=False, sampling_diode=None, geometry=None):
    """Return the :class:`Comparison` of :func:`spectral_albedo` (class shares and spectra) with the analytic
    model on ``diode``'s band map of ``kind`` ('clear' or 'all'), at ``n_epochs`` sunlit epochs of the default
    orbit (or ``geometry`` = (r_sat, r_sun)) for the normals ``normals`` (names of :data:`NORMALS_LOCAL`,
    default all). Deliberately wrong inputs: ``flip_shares`` (class shares read north-south flipped),
    ``sampling_diode`` (wavelengths drawn from another diode's band)."""
    from simcore.radiometry.band import band_curve
    curve, label = band_curve(diode)
    sample_curve = curve if sampling_diode is None else band_curve(sampling_diode)[0]
    names = tuple(NORMALS_LOCAL) if normals is None else tuple(normals)
    unknown = [n for n in names if n not in NORMALS_LOCAL]
    if unknown:
        raise ValueError(f"unknown normals {unknown}; choose from {list(NORMALS_LOCAL)}")
    n_local = np.array([NORMALS_LOCAL[n] for n in names])
    r_sat, r_sun = default_geometry(n_epochs) if geometry is None else geometry
    rot = local_frames(r_sat, r_sun)
    normals_ecef = np.einsum("nij,kj->nki", rot, n_local)
    truth = cell_spectra(kind)
    spectra = cell_spectra(kind, flip_shares=True) if flip_shares else truth
    e_band = band_irradiance(curve)
    est = spectral_albedo(r_sat, r_sun, normals_ecef, sample_curve, spectra, samples=samples, seed=seed)
    scale = e_band / band_irradiance(sample_curve)     # the wrong band's estimate in the right band's units
    ref, disc = band_map_reference(r_sat, r_sun, rot, n_local, truth.band_mean(curve), e_band)
    spec, se = est.mean_w_m2 * scale, est.se_w_m2 * scale
    var = se ** 2 + disc ** 2
    z = np.full(var.shape, np.nan)
    np.divide(spec - ref, np.sqrt(var), out=z, where=var > 0)
    return Comparison(str(diode), label, names, spec, se, ref, disc, z)


FALSE_ALARM = 1e-3      # the check's chance of failing when the estimates agree (half on the pooled z, half on the max)


def limits(n):
    """Return (pooled |z| limit, max |z| limit) for ``n`` entries: each side :data:`FALSE_ALARM` / 2 two-sided,
    the max by Bonferroni over the n entries."""
    from scipy import stats
    return float(stats.norm.isf(FALSE_ALARM / 4)), float(stats.norm.isf(FALSE_ALARM / 4 / max(int(n), 1)))


def agrees(comparison):
    """Return True when ``comparison``'s pooled and largest |z| are inside :func:`limits`."""
    pooled, largest = limits(comparison.n)
    return abs(comparison.pooled_z) < pooled and comparison.max_abs_z < largest


def band_wavelengths_nm(curve, u):
    """Return (wavelengths (n, 4) nm, weight (n, 4) W/m^2) that Mitsuba's ``llvm_ad_spectral`` sensor with the
    srf S E (``curve`` times G173) draws for the uniform numbers ``u`` (n,): four shifted wavelengths each, and
    S E / p (whose mean is int S E)."""
    dr = _llvm.import_drjit()
    with _spectral_variant() as mi:
        sampler = _band_sampler(mi, curve)
        ctx = dr.zeros(mi.SurfaceInteraction3f)
        wl, _ = sampler[0].sample_wavelengths(ctx, _llvm.host_array(mi.Float, u))
        ctx.wavelengths = wl
        w = _band_weight(dr, mi, sampler, ctx)
        return (np.stack([np.array(wl[i], float) for i in range(4)], axis=1),
                np.stack([np.array(w[i], float) for i in range(4)], axis=1))
