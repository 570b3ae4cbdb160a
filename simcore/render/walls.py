"""Aperture walls that reflect: the angular response of a diode in a well with a BSDF, ray traced.

The renderer (:mod:`simcore.render.irradiance`) treats the satellite as a black
occluder. Real wells are anodised (matte black, a few % diffuse reflectance)
or bare aluminium (a rough conductor), and light reflected by their walls
reaches the diode. A diode's response to a far (collimated) source is a
function of the direction only, so it is traced here once per direction for
one well (:class:`simcore.shapes.aperture.WellAperture`), and tabulated
(:class:`TabulatedResponse`) for use wherever a response is needed (e.g. the
albedo sum of :func:`simcore.radiometry.analytic.diode_irradiance` with
``backend='numpy'``).

Estimator (traced from the source). In the diode frame (u, v, n) the well is
the prism ``|u| < w_x, |v| < w_y, 0 < n < h``; its floor (the plane n = 0)
holds the diode ``|u| < a_x, |v| < a_y``. Rays start at uniform points on the
opening (area ``A_open``), travel along ``-d``, and are followed through
reflections off the four walls (and the floor around the diode when
``reflective_floor``) with the material's BSDF (Mitsuba plugins, sampled with
``bsdf.sample``; the path throughput is multiplied by the sample weight
``f cos / pdf``). A path ends when it reaches the diode (absorbed and
counted), leaves through the opening (escaped), or is absorbed by a black
floor; after ``rr_depth`` bounces Russian roulette ends paths without bias.
With normal irradiance E on the opening the entering power is
``E A_open d_n``, so each ray carries ``A_open d_n / A_diode`` in response
units and the response is the mean over rays of that weight times the
throughput of the rays that reach the diode: a bare diode facing the beam
reads 1, and black walls give exactly ``WellAperture.response`` (the
0-bounce term, reported separately as ``direct``). Standard errors are the
sample standard deviation over the independent rays / sqrt(rays).

Geometry is traced in millimetres (Mitsuba offsets new rays by ~1e-4 of the
coordinates' magnitude plus 1e-4 units, too much for metres at this scale).
The walls are two-sided (``twosided`` BSDF) and their thickness does not
matter: rays are only ever inside the well.
"""
from dataclasses import dataclass

import numpy as np

from simcore import _llvm
from simcore.render.irradiance import choose_variant
from simcore.shapes.aperture import WellAperture

MM_PER_M = 1e3
_MAX_LANES = 1 << 21
_DIODE_EPS_MM = 1e-4     # hits within this of the floor plane count as on the floor/diode


@dataclass(frozen=True)
class WallMaterial:
    """The surface of a well's walls (and floor): a Mitsuba BSDF description.

    ``kind``: 'diffuse' (Lambertian, ``reflectance`` rho), 'roughconductor'
    (GGX microfacets, ``conductor`` a Mitsuba material name such as 'Al',
    roughness ``alpha``), or 'mirror' (smooth conductor with Fresnel factor 1
    times ``reflectance``: a perfect mirror for 1). Use the classmethods.
    """

    kind: str
    reflectance: float = 0.0
    alpha: float = 0.2
    conductor: str = "Al"
    label: str = ""

    def __post_init__(self):
        if self.kind not in ("diffuse", "roughconductor", "mirror"):
            raise ValueError(f"unknown wall material kind {self.kind!r}; use WallMaterial.black(), "
                             ".matte_black(), .diffuse(rho), .aluminium(alpha) or .mirror(r)")
        if self.kind in ("diffuse", "mirror") and not 0.0 <= float(self.reflectance) <= 1.0:
            raise ValueError(f"wall reflectance must lie in [0, 1], got {self.reflectance}")
        if self.kind == "roughconductor" and not 0.0 < float(self.alpha) <= 1.0:
            raise ValueError(f"rough-conductor alpha must lie in (0, 1], got {self.alpha} (0.1-0.3: bare machined Al)")

    @classmethod
    def black(cls):
        """Return ideal black walls (zero reflectance): the renderer's and the overlap model's walls."""
        return cls("diffuse", 0.0, label="black (rho 0)")

    @classmethod
    def matte_black(cls, rho=0.04):
        """Return matte-black walls: Lambertian with rho = 0.04 (black anodise / Aeroglaze Z306: 2-5 %)."""
        return cls("diffuse", float(rho), label=f"matte black (rho {rho:g})")

    @classmethod
    def diffuse(cls, rho):
        """Return Lambertian walls of reflectance ``rho`` (a user value)."""
        return cls("diffuse", float(rho), label=f"diffuse rho {rho:g}")

    @classmethod
    def aluminium(cls, alpha=0.2):
        """Return bare aluminium walls: a GGX rough conductor with Al's optical constants, roughness alpha."""
        return cls("roughconductor", alpha=float(alpha), conductor="Al", label=f"bare Al (alpha {alpha:g})")

    @classmethod
    def mirror(cls, r=1.0):
        """Return specular walls reflecting a fraction ``r`` at every angle (1: a perfect mirror)."""
        return cls("mirror", float(r), label=f"mirror r {r:g}")

    @property
    def is_black(self):
        return self.kind in ("diffuse", "mirror") and float(self.reflectance) == 0.0

    def bsdf_dict(self):
        """Return the Mitsuba BSDF dictionary (two-sided) of this material."""
        if self.kind == "diffuse":
            inner = {"type": "diffuse", "reflectance": {"type": "uniform", "value": float(self.reflectance)}}
        elif self.kind == "mirror":
            inner = {"type": "conductor", "material": "none",
                     "specular_reflectance": {"type": "uniform", "value": float(self.reflectance)}}
        else:
            inner = {"type": "roughconductor", "material": self.conductor, "alpha": float(self.alpha),
                     "distribution": "ggx"}
        return {"type": "twosided", "bsdf": inner}


@dataclass
class WellTrace:
    """Traced response of a diode in a well, per direction (M,), in response units
    (irradiance on the diode per unit irradiance normal to the rays; a bare diode facing the beam: 1).

    ``response`` = ``direct`` (light reaching the diode straight through the opening: the overlap
    model, ``WellAperture.response``) + ``reflected`` (after one or more wall/floor reflections).
    ``entered``: the power entering the opening in the same units (``A_open d_n / A_diode``, exact);
    it ends up in ``response`` + ``floor`` (absorbed by the floor around the diode) + ``walls``
    (absorbed by the walls) + ``escaped`` (back out through the opening); ``accounted`` is that sum as
    estimated (equal to ``entered`` within its standard error ``accounted_se``: energy is conserved).
    ``*_se``: one standard error; ``mean_bounces``: mean number of wall/floor hits per path.
    ``response_cv`` = the exact overlap + ``reflected``: the same expectation as ``response`` (the
    straight-through part IS the overlap, see the tests), with the noise of the reflections only
    (``response_cv_se`` = ``reflected_se``): use it for figures and tables.
    """

    d_diode: np.ndarray
    response: np.ndarray
    response_se: np.ndarray
    direct: np.ndarray
    direct_se: np.ndarray
    reflected: np.ndarray
    reflected_se: np.ndarray
    floor: np.ndarray
    walls: np.ndarray
    escaped: np.ndarray
    escaped_se: np.ndarray
    entered: np.ndarray
    accounted: np.ndarray
    accounted_se: np.ndarray
    response_cv: np.ndarray
    response_cv_se: np.ndarray
    rays: int
    material: WallMaterial
    mean_bounces: np.ndarray


def _unit_dirs(d):
    d = np.atleast_2d(np.asarray(d, dtype=float))
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must have shape (M, 3) in the diode frame (u, v, n), got {np.shape(d)}")
    n = np.linalg.norm(d, axis=1)
    if not np.allclose(n, 1.0, atol=1e-6):
        raise ValueError("directions must be unit vectors (diode frame u, v, n, pointing towards the source)")
    return d / n[:, None]


def _scene(mi, ap, material):
    """Return the Mitsuba scene of the well (mm): floor rectangle + 4 walls, all with the material."""
    T = mi.ScalarTransform4f
    wx, wy = ap.opening_x_m / 2 * MM_PER_M, ap.opening_y_m / 2 * MM_PER_M
    h = ap.height_m * MM_PER_M
    bsdf = material.bsdf_dict()
    shapes = {"type": "scene",
              "floor": {"type": "rectangle", "to_world": T().scale([wx, wy, 1.0]), "bsdf": bsdf}}
    if h > 0:
        shapes["wall_px"] = {"type": "rectangle", "bsdf": bsdf, "to_world":
                             T().translate([wx, 0.0, h / 2]) @ T().rotate([0, 1, 0], 90) @ T().scale([h / 2, wy, 1])}
        shapes["wall_mx"] = {"type": "rectangle", "bsdf": bsdf, "to_world":
                             T().translate([-wx, 0.0, h / 2]) @ T().rotate([0, 1, 0], 90) @ T().scale([h / 2, wy, 1])}
        shapes["wall_py"] = {"type": "rectangle", "bsdf": bsdf, "to_world":
                             T().translate([0.0, wy, h / 2]) @ T().rotate([1, 0, 0], 90) @ T().scale([wx, h / 2, 1])}
        shapes["wall_my"] = {"type": "rectangle", "bsdf": bsdf, "to_world":
                             T().translate([0.0, -wy, h / 2]) @ T().rotate([1, 0, 0], 90) @ T().scale([wx, h / 2, 1])}
    return mi.load_dict(shapes)


def _trace_lanes(mi, dr, scene, ap, dirs, rays, seed, lane0, reflective_floor, max_bounces, rr_depth,
                 white_diode=False):
    """Trace ``rays`` paths for each direction in ``dirs`` (m, 3); return per-lane numpy tallies."""
    m = dirs.shape[0]
    n = m * rays
    wx, wy = ap.opening_x_m / 2 * MM_PER_M, ap.opening_y_m / 2 * MM_PER_M
    ax, ay = ap.diode_x_m / 2 * MM_PER_M, ap.diode_y_m / 2 * MM_PER_M
    h = ap.height_m * MM_PER_M
    idx = dr.arange(mi.UInt32, n)
    task = idx // rays
    dx = dr.gather(mi.Float, _llvm.host_array(mi.Float, dirs[:, 0]), task)
    dy = dr.gather(mi.Float, _llvm.host_array(mi.Float, dirs[:, 1]), task)
    dz = dr.gather(mi.Float, _llvm.host_array(mi.Float, dirs[:, 2]), task)
    # one PCG32 stream per global lane index: results do not depend on how directions are batched
    state = (int(seed) * 0x9E3779B97F4A7C15 + 0x853C49E6748FEA9B) % (1 << 64)
    rng = mi.PCG32(size=n, initstate=mi.UInt64(state), initseq=dr.arange(mi.UInt64, n) + mi.UInt64(int(lane0)))
    # a point on the opening, the ray arriving there along -d (started just outside, above the rim)
    px = (2.0 * rng.next_float32() - 1.0) * wx
    py = (2.0 * rng.next_float32() - 1.0) * wy
    back = 1e-3 * (h + 1.0)
    o = mi.Point3f(px + back * dx, py + back * dy, h + back * dz)
    ray = mi.Ray3f(o, mi.Vector3f(-dx, -dy, -dz))
    thr = dr.ones(mi.Float, n)
    zeros = dr.zeros(mi.Float, n)
    direct, refl, floor, walls, esc, bounces = zeros, zeros, zeros, zeros, zeros, zeros
    active = dz > 0
    ctx = mi.BSDFContext()
    for depth in range(max_bounces + 1):
        si = scene.ray_intersect(ray, active)
        hit = active & si.is_valid()
        esc = dr.select(active & ~si.is_valid(), esc + thr, esc)
        on_floor = hit & (dr.abs(si.p.z) < _DIODE_EPS_MM)
        on_diode = on_floor & (dr.abs(si.p.x) <= ax) & (dr.abs(si.p.y) <= ay)
        if depth == 0:
            direct = dr.select(on_diode, thr, direct)
        else:
            refl = dr.select(on_diode, refl + thr, refl)
        go_on = hit & ~on_diode if not white_diode else hit
        if not reflective_floor:
            floor = dr.select(go_on & on_floor & ~on_diode, floor + thr, floor)
            go_on = go_on & (~on_floor | on_diode)
        if depth == max_bounces:
            # out of bounces: the remaining power is counted where the path stands (a black bounce)
            floor = dr.select(go_on & on_floor, floor + thr, floor)
            walls = dr.select(go_on & ~on_floor, walls + thr, walls)
            break
        bs, w = si.bsdf().sample(ctx, si, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()),
                                 go_on)
        w = dr.select(go_on & (bs.pdf > 0), w[0], 0.0)      # mono: a one-channel colour
        lost = thr * (1.0 - w)
        floor = dr.select(go_on & on_floor, floor + lost, floor)
        walls = dr.select(go_on & ~on_floor, walls + lost, walls)
        thr = dr.select(go_on, thr * w, thr)
        bounces = dr.select(go_on, bounces + 1.0, bounces)
        active = go_on & (thr > 0)
        if depth + 1 >= rr_depth:
            q = dr.minimum(dr.maximum(thr, 0.05), 0.95)
            survive = rng.next_float32() < q
            # a killed path's power is not lost: in expectation the survivors carry it (thr / q)
            active = active & survive
            thr = dr.select(active, thr / q, thr)
        ray = si.spawn_ray(si.to_world(bs.wo))
        dr.eval(direct, refl, floor, walls, esc, thr, active, ray.o, ray.d, bounces)
        if not dr.any(active):
            break
    return [np.asarray(x.numpy(), dtype=float).reshape(m, rays) for x in (direct, refl, floor, walls, esc, bounces)]


def trace_well(aperture, d_diode, material, *, rays=100_000, seed=0, reflective_floor=True,
               max_bounces=64, rr_depth=8, white_diode=False, variant=None):
    """Return a :class:`WellTrace`: the response of a diode in ``aperture`` (a WellAperture) with walls of
    ``material`` (a :class:`WallMaterial`) to collimated light from unit directions ``d_diode`` (M, 3)
    (diode frame u, v, n, towards the source), traced with ``rays`` paths per direction.

    ``reflective_floor``: the floor plate around the diode has the walls' material (True: one
    anodised/machined part) or is black. ``max_bounces`` caps a path (the remaining power is counted
    as absorbed where it stands); ``rr_depth``: Russian roulette from that bounce on. ``white_diode``
    (white-furnace tests only): the diode counts every arrival and then reflects it like the floor
    instead of absorbing it. ``variant``: the Mitsuba variant (None: the GPU one when a CUDA GPU works,
    else the CPU one, as :func:`simcore.render.irradiance.choose_variant`).
    """
    if not isinstance(aperture, WellAperture):
        raise TypeError(f"aperture must be a simcore.shapes.aperture.WellAperture, got {type(aperture).__name__}")
    if not isinstance(material, WallMaterial):
        raise TypeError("material must be a simcore.render.walls.WallMaterial (e.g. WallMaterial.matte_black())")
    dirs = _unit_dirs(d_diode)
    rays = int(rays)
    if rays < 16:
        raise ValueError(f"rays must be >= 16 per direction, got {rays}")
    variant = choose_variant(variant)
    dr, mi = _llvm.import_drjit(), _llvm.import_mitsuba()
    if mi.variant() != variant:
        mi.set_variant(variant)
    scene = _scene(mi, aperture, material)
    m = dirs.shape[0]
    per = max(2, _MAX_LANES // rays)
    tallies = [np.zeros((m, rays)) for _ in range(6)]
    for s in range(0, m, per):
        sl = slice(s, min(m, s + per))
        chunk = dirs[sl]
        pad = chunk.shape[0] < 2
        if pad:                                 # a width-1 array would be baked in as a literal
            chunk = np.vstack([chunk, chunk])
        out = _trace_lanes(mi, dr, scene, aperture, chunk, rays, seed, s * rays, reflective_floor,
                           int(max_bounces), int(rr_depth), bool(white_diode))
        for t, o in zip(tallies, out):
            t[sl] = o[:1] if pad else o
    front = dirs[:, 2] > 0
    entered = np.where(front, aperture.opening_x_m * aperture.opening_y_m * np.clip(dirs[:, 2], 0, None)
                       / aperture.diode_area_m2, 0.0)
    scale = entered[:, None]
    direct, refl, floor, walls, esc, bounces = tallies
    total = direct + refl

    def mean_se(x):
        v = x * scale
        return v.mean(axis=1), v.std(axis=1, ddof=1) / np.sqrt(rays)

    r, r_se = mean_se(total)
    dm, d_se = mean_se(direct)
    rf, rf_se = mean_se(refl)
    es, es_se = mean_se(esc)
    acc, acc_se = mean_se(total + floor + walls + esc)
    return WellTrace(d_diode=dirs, response=r, response_se=r_se, direct=dm, direct_se=d_se, reflected=rf,
                     reflected_se=rf_se, floor=(floor * scale).mean(axis=1), walls=(walls * scale).mean(axis=1),
                     escaped=es, escaped_se=es_se, entered=entered, accounted=acc, accounted_se=acc_se,
                     response_cv=aperture.response(dirs) + rf, response_cv_se=rf_se, rays=rays, material=material,
                     mean_bounces=bounces.mean(axis=1))


def octant_grid(theta_step_deg=2.0, phi_step_deg=7.5):
    """Return (theta_deg (T,), phi_deg (P,)) of a grid over one octant of a square well's symmetry:
    theta 0..90 deg from the normal, phi 0..45 deg from the u axis."""
    th = np.linspace(0.0, 90.0, int(round(90.0 / theta_step_deg)) + 1)
    ph = np.linspace(0.0, 45.0, int(round(45.0 / phi_step_deg)) + 1)
    return th, ph


def _dir_from_angles(theta_deg, phi_deg):
    t, p = np.broadcast_arrays(np.radians(theta_deg), np.radians(phi_deg))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


@dataclass(frozen=True)
class TabulatedResponse:
    """A well's response with reflecting walls: the exact overlap (``WellAperture.response``, the light
    that reaches the diode straight) plus the traced reflected part, tabulated on an octant grid
    (theta, phi) and interpolated bilinearly, folded by the square well's symmetry
    (|u|, |v|, and u <-> v when the well is square).

    ``response(d_diode)`` works like every response (:mod:`simcore.radiometry.response`), so it can be used with
    :func:`simcore.radiometry.analytic.diode_irradiance` (``backend='numpy'``).
    """

    aperture: WellAperture
    theta_deg: np.ndarray
    phi_deg: np.ndarray
    reflected: np.ndarray        # (T, P)
    reflected_se: np.ndarray     # (T, P)
    material: WallMaterial

    @classmethod
    def trace(cls, aperture, material, *, theta_step_deg=2.0, phi_step_deg=7.5, rays=20_000, seed=0,
              reflective_floor=True):
        """Return the table traced with :func:`trace_well` over :func:`octant_grid` (rays per node)."""
        if not np.isclose(aperture.opening_x_m, aperture.opening_y_m) or \
                not np.isclose(aperture.diode_x_m, aperture.diode_y_m):
            raise ValueError("TabulatedResponse folds directions by the symmetry of a SQUARE well over a square "
                             "diode; this aperture is rectangular")
        th, ph = octant_grid(theta_step_deg, phi_step_deg)
        d = _dir_from_angles(th[:, None], ph[None, :]).reshape(-1, 3)
        front = d[:, 2] > 1e-9
        refl = np.zeros(len(d))
        se = np.zeros(len(d))
        if front.any():
            tr = trace_well(aperture, d[front], material, rays=rays, seed=seed, reflective_floor=reflective_floor)
            refl[front], se[front] = tr.reflected, tr.reflected_se
        shape = (len(th), len(ph))
        return cls(aperture, th, ph, refl.reshape(shape), se.reshape(shape), material)

    def reflected_part(self, d_diode):
        """Return the interpolated reflected part of the response for unit directions (..., 3)."""
        d = np.asarray(d_diode, dtype=float)
        u, v, n = np.abs(d[..., 0]), np.abs(d[..., 1]), d[..., 2]
        lo, hi = np.minimum(u, v), np.maximum(u, v)
        theta = np.degrees(np.arccos(np.clip(n, -1.0, 1.0)))
        phi = np.degrees(np.arctan2(lo, hi))
        ti = np.clip(np.interp(theta, self.theta_deg, np.arange(len(self.theta_deg))), 0, len(self.theta_deg) - 1)
        pi_ = np.clip(np.interp(phi, self.phi_deg, np.arange(len(self.phi_deg))), 0, len(self.phi_deg) - 1)
        t0 = np.minimum(np.floor(ti).astype(int), len(self.theta_deg) - 2)
        p0 = np.minimum(np.floor(pi_).astype(int), len(self.phi_deg) - 2)
        ft, fp = ti - t0, pi_ - p0
        r = self.reflected
        val = ((1 - ft) * (1 - fp) * r[t0, p0] + ft * (1 - fp) * r[t0 + 1, p0]
               + (1 - ft) * fp * r[t0, p0 + 1] + ft * fp * r[t0 + 1, p0 + 1])
        return np.where(n > 0, val, 0.0)

    def response(self, d_diode):
        """Return the response (overlap + reflected part) for unit directions (..., 3) in the diode frame."""
        d = np.asarray(d_diode, dtype=float)
        if d.shape[-1:] != (3,):
            raise ValueError(f"directions must have shape (..., 3) in the diode frame (u, v, n), got {d.shape}")
        return self.aperture.response(d) + self.reflected_part(d)
