"""Aperture geometry studies: traced angular responses, aperture design, wall reflections,
self-shadowing and a height x tilt x FOV sweep.

What each part answers (the models it compares):

* :func:`traced_black_response` -- the response of one diode in its well with black
  walls, ray traced by :class:`simcore.render.Renderer` (the floor and well meshes of
  :func:`scenes.meshes.mount_meshes`), for any set of directions; compared with the
  analytic overlap (:meth:`simcore.shapes.aperture.WellAperture.response`) and with thesis
  eq. 4.15 (:class:`simcore.radiometry.response.Eq415Response`) by :func:`angular_cuts`,
  :func:`response_map` and :func:`response_angles` (the 50 % / 1 % angles).
* :func:`design_aperture` -- opening and height from a target FOV, cut-off, diode area
  and height limit.
* :func:`wall_response` -- walls (and the floor plate) of any material (:mod:`scenes.materials`
  names or Mitsuba BSDF dicts: matte black, bare aluminium, a user value), path traced by the
  renderer's ``reflected`` component (:func:`well_renderer`); :func:`angular_cuts`,
  :func:`reflectance_series` and :func:`wall_albedo_effect` (a :class:`TabulatedResponse` of it in the
  albedo sum of :func:`simcore.radiometry.analytic.diode_irradiance` along an orbit).
* :func:`self_shadowing` -- per diode, the part of its field of view that the body,
  the ramps and the neighbouring mounts shadow (traced with the full satellite mesh)
  against its own well alone.
* :func:`sweep_apertures` -- well height x tilt x FOV -> coverage (green fraction),
  albedo fraction seen and estimator errors over one orbit; :func:`run_aperture_sweep`
  writes the table and plots (``sunsim aperture-sweep``).

Where eq. 4.15 and the real well differ: eq. 4.15 is a function of the incidence
angle only, ``A = C (C - c0)/(cos FOV - c0)`` between FOV and the 83.1 deg cut-off
(C = cos theta). A square well's lit fraction is the product of two 1-D overlaps
``(1 - max(0, h|tan_u| - g)/a)`` along its wall axes (g = (w - a)/2), so (i) along an axis it
falls linearly in ``tan`` (not in ``cos``) from the FOV to the cut-off, and (ii) it depends on
azimuth: towards the diagonal the shift along each wall axis is smaller (x cos 45 deg), so the diode
stays fully lit up to ``atan(sqrt 2 tan FOV)`` (79.2 deg for FOV 75) and light reaches it up to
``atan(sqrt 2 tan cutoff)`` (85.1 deg). Eq. 4.15 ignores azimuth and reads below the real (black)
well everywhere between FOV and cut-off: by up to 0.034 of normal incidence on the wall axis and
0.097 on the diagonal (FOV 75, near 79 deg), and zero on the diagonal where the diode still sees.
"""
import csv
from dataclasses import dataclass, field
from pathlib import Path

import healpy as hp
import numpy as np
import trimesh

from scenes.config import LAYOUT_DEFAULTS, ConfigError, SatelliteConfig, expand_layout, list_configs
from scenes.materials import check_material
from scenes.meshes import mount_meshes
from scenes.satellite import Satellite
from simcore.constants import BPW34_AREA_M2
from simcore.environment.eclipse import sunlit
from simcore.environment.geometry import one_orbit_geometry
from simcore.pipeline.evaluate import error_table, errors, measure, run_estimators
from simcore.plots import plot_sweep
from simcore.radiometry.analytic import diode_irradiance
from simcore.radiometry.response import Eq415Response
from simcore.render import Renderer
from simcore.sensor.chain import DIODES
from simcore.shapes.aperture import EQ415_CUTOFF_DEG, CircularWell, WellAperture
from simcore.shapes.occlusion import direct_visibility
from simcore.shapes.window import WindowedWell
from simcore.studies.coverage import CLASSES, coverage_classes, coverage_fractions, pixel_directions

MM = 1e-3
DEFAULT_LEVELS = (0.5, 0.01)


# ----------------------------------------------------------------------------- directions

def cut_directions(theta_deg, phi_deg):
    """Return unit directions (M, 3) in the diode frame (u, v, n) at incidence ``theta_deg`` (M,)
    from the normal and azimuth ``phi_deg`` (scalar or (M,)) from the u axis (a wall axis; 45: diagonal)."""
    t = np.radians(np.asarray(theta_deg, dtype=float))
    p = np.radians(np.broadcast_to(np.asarray(phi_deg, dtype=float), t.shape))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def healpix_directions(nside=16):
    """Return HEALPix pixel centres (12 nside^2, 3) (RING order), unit vectors; with the diode frame
    as the coordinate frame the pole is the diode normal."""
    return np.array(hp.pix2vec(int(nside), np.arange(hp.nside2npix(int(nside))))).T


# ----------------------------------------------------------------------------- traced black well

def well_config(aperture, material="black"):
    """Return a one-diode :class:`scenes.config.SatelliteConfig` holding ``aperture`` flat on the +z panel
    (its diode frame is the body frame: u = x, v = y, n = z), its mount (floor plate and well walls) of
    ``material`` (a :mod:`scenes.materials` name or a Mitsuba BSDF dict). The diode must be the square BPW34."""
    side = float(np.sqrt(BPW34_AREA_M2))
    if not (np.isclose(aperture.diode_x_m, side) and np.isclose(aperture.diode_y_m, side)):
        raise ValueError("the traced well uses the configuration format, whose diode is the square BPW34 "
                         f"({side / MM:.3f} mm); got {aperture.diode_x_m / MM:.3f} x {aperture.diode_y_m / MM:.3f} mm. "
                         "Give a WellAperture over the BPW34 (WellAperture.design or the configuration's apertures)")
    if isinstance(aperture, CircularWell):
        well = {"shape": "round", "diameter_mm": 2.0 * aperture.radius_m / MM, "height_mm": aperture.height_m / MM}
    else:
        well = {"height_mm": aperture.height_m / MM,
                "opening_mm": [aperture.opening_x_m / MM, aperture.opening_y_m / MM]}
    if getattr(aperture, "chamfer_m", 0.0) > 0:
        well.update(chamfer_mm=aperture.chamfer_m / MM, chamfer_deg=aperture.chamfer_deg)
    return SatelliteConfig.from_dict({"name": "single_well", "mount": {"material": material}, "diode": [
        {"name": "well", "panel": "+z", "normal": [0.0, 0.0, 1.0], "at_mm": [0.0, 0.0], "well": well}]})


def traced_black_response(aperture, d_diode, *, samples=4096, seed=0, control_variate=False, variant=None):
    """Return (response (M,), standard error (M,)): the diode's response in its black-walled well for
    unit directions ``d_diode`` (M, 3) (diode frame), ray traced by :class:`simcore.render.Renderer`
    against the well's floor and wall meshes (:func:`scenes.meshes.mount_meshes`).

    ``samples``: direct samples per direction (4 m^2, see ``Renderer.render``). ``control_variate``:
    False (default) samples the whole diode, so the traced value is an independent check of the
    overlap model; True uses the renderer's aperture split (zero noise where the mesh is the analytic well).
    """
    d = np.atleast_2d(np.asarray(d_diode, dtype=float))
    cfg = well_config(aperture)
    parts = mount_meshes(cfg, 0)
    mesh = trimesh.util.concatenate([parts[k] for k in ("floor", "well") if k in parts])
    r = Renderer.from_scene(Satellite(cfg), mesh=mesh, e_sun_w_m2=1.0, control_variate=control_variate,
                            variant=variant)
    sun_body = d @ cfg.frames[0]
    res = r.render(sun_body, None, direct_samples=int(samples), albedo=False, seed=int(seed))
    return res.direct_w_m2[:, 0], res.direct_se_w_m2[:, 0]


# ----------------------------------------------------------------------------- walls that reflect (path tracer)

# The wall materials of the study (Mitsuba BSDF dicts, scenes.materials): anodised / painted matte black
# (Lambertian 4 %: black anodise, Aeroglaze Z306 reflect 2-5 %) and bare machined aluminium (GGX rough
# conductor with Mitsuba's tabulated optical constants of Al, roughness 0.2). Any name of
# scenes.materials.MATERIALS or any other Mitsuba BSDF dict works too.
MATTE_BLACK = {"type": "diffuse", "reflectance": 0.04}
BARE_AL = {"type": "roughconductor", "material": "Al", "alpha": 0.2, "distribution": "ggx"}
WALL_MATERIALS = {"matte black 0.04": MATTE_BLACK, "bare Al alpha 0.2": BARE_AL}
_WALL_MAX_DEPTH = 64      # path vertices: the shallow well returns few paths after a handful (Russian roulette)


def material_label(spec):
    """Return a short name of a wall material: the name itself, or the dict's type and parameters."""
    if isinstance(spec, str):
        return spec
    words = [str(spec.get("type", "?"))]
    for k, v in spec.items():
        if k == "type":
            continue
        if isinstance(v, dict) and set(v) == {"type", "value"}:
            v = v["value"]
        words.append(f"{k} {v:g}" if isinstance(v, (int, float)) else f"{k} {v}")
    return " ".join(words)


def _named_materials(materials):
    """Return [(label, spec)] of a mapping {label: spec} or a sequence of specs (checked)."""
    items = list(materials.items()) if isinstance(materials, dict) else [(material_label(m), m) for m in materials]
    return [(label, check_material(spec, f"wall material {label!r}")) for label, spec in items]


def _unit_directions(d_diode):
    d = np.atleast_2d(np.asarray(d_diode, dtype=float))
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must have shape (M, 3) in the diode frame (u, v, n), got {np.shape(d_diode)}")
    if not np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6):
        raise ValueError("directions must be unit vectors (diode frame u, v, n, pointing towards the source)")
    return d


@dataclass
class WallResponse:
    """A diode's response in its well with reflecting walls, per direction (M,), in response units
    (irradiance on the diode per unit irradiance normal to the Sun's rays: a bare diode facing the Sun
    reads 1), traced by the renderer's path tracer.

    ``response`` = ``direct`` (the light that reaches the diode straight through the opening: exactly the
    overlap model, ``WellAperture.response``, through the renderer's aperture split) + ``reflected`` (after
    one or more reflections on the walls and the floor plate around the diode); ``*_se``: one standard error.
    """

    d_diode: np.ndarray
    response: np.ndarray
    response_se: np.ndarray
    direct: np.ndarray
    direct_se: np.ndarray
    reflected: np.ndarray
    reflected_se: np.ndarray
    material: object
    floor_material: object
    samples: int
    seed: int


def well_renderer(aperture, material, floor_material=None, *, variant=None, max_depth=_WALL_MAX_DEPTH):
    """Return a :class:`simcore.render.Renderer` (E_sun = 1, point Sun for the direct part) of the
    diode of :func:`well_config` with its floor plate and well walls as meshes (:func:`scenes.meshes.mount_meshes`):
    the walls of ``material`` and the floor of ``floor_material`` (None: the walls' material: one part)."""
    cfg = well_config(aperture, material)
    floor = material if floor_material is None else check_material(floor_material, "floor material")
    parts = mount_meshes(cfg, 0)
    # the plug (scenes.meshes): the diode absorbs what comes back onto it
    names = [k for k in ("floor", "well", "plug") if k in parts]
    mesh = trimesh.util.concatenate([parts[k] for k in names])
    ranges, start = {}, 0
    for k in names:
        ranges[k] = (start, start + len(parts[k].faces))
        start = ranges[k][1]
    mesh.metadata["parts"] = ranges
    mesh.metadata["materials"] = {"floor": floor, "well": cfg.mount.material, "plug": parts["plug"].metadata["material"]}
    return Renderer.from_scene(Satellite(cfg), mesh=mesh, e_sun_w_m2=1.0, variant=variant, max_depth=max_depth)


def wall_response(aperture, d_diode, material, *, samples=16384, seed=0, floor_material=None, variant=None,
                  renderer=None):
    """Return a :class:`WallResponse`: the response of the BPW34 in ``aperture`` (a WellAperture) whose walls and
    floor plate are of ``material`` (a :mod:`scenes.materials` name or a Mitsuba BSDF dict, e.g.
    ``{"type": "diffuse", "reflectance": 0.04}``) to the Sun along unit directions ``d_diode`` (M, 3) (diode
    frame u, v, n, towards the Sun): (direct + reflected) / E_sun, path traced by
    :class:`simcore.render.Renderer` with ``samples`` reflected paths per direction (4 m^2) and
    ``seed``. Directions behind the diode (d_n <= 0) read 0 at no cost. ``floor_material``: the floor
    plate's own material (None: the walls'). ``renderer``: one from :func:`well_renderer` to reuse.
    """
    d = _unit_directions(d_diode)
    check_material(material, "wall material")
    floor = material if floor_material is None else floor_material
    if renderer is not None and (renderer.materials.get("well") != material or renderer.materials.get("floor") != floor):
        raise ValueError(f"the renderer's walls and floor are {renderer.materials.get('well')!r} and "
                         f"{renderer.materials.get('floor')!r}, not the {material!r} and {floor!r} asked for: pass "
                         "the renderer well_renderer made for these materials, or none")
    r = well_renderer(aperture, material, floor_material, variant=variant) if renderer is None else renderer
    m = len(d)
    out = {k: np.zeros(m) for k in ("direct", "direct_se", "reflected", "reflected_se")}
    front = d[:, 2] > 0
    if front.any():
        res = r.render(d[front] @ r.diodes.frames[0], None, direct_samples=1024, albedo=False, seed=int(seed),
                       reflected_samples=int(samples))
        out["direct"][front], out["direct_se"][front] = res.direct_w_m2[:, 0], res.direct_se_w_m2[:, 0]
        out["reflected"][front], out["reflected_se"][front] = res.reflected_w_m2[:, 0], res.reflected_se_w_m2[:, 0]
    return WallResponse(d, out["direct"] + out["reflected"], np.hypot(out["direct_se"], out["reflected_se"]),
                        out["direct"], out["direct_se"], out["reflected"], out["reflected_se"], material, floor,
                        int(samples), int(seed))


def octant_grid(theta_step_deg=2.0, phi_step_deg=7.5):
    """Return (theta_deg (T,), phi_deg (P,)) of a grid over one octant of a square well's symmetry:
    theta 0..90 deg from the normal, phi 0..45 deg from the u axis."""
    th = np.linspace(0.0, 90.0, int(round(90.0 / theta_step_deg)) + 1)
    ph = np.linspace(0.0, 45.0, int(round(45.0 / phi_step_deg)) + 1)
    return th, ph


@dataclass(frozen=True)
class TabulatedResponse:
    """A well's response with reflecting walls: the exact overlap (``WellAperture.response``, the light
    that reaches the diode straight) plus the path-traced reflected part (:func:`wall_response`), tabulated
    on an octant grid (theta, phi) and interpolated bilinearly, folded by the square well's symmetry
    (|u|, |v|, and u <-> v).

    ``response(d_diode)`` works like every response (:mod:`simcore.radiometry.response`), so it can be used
    with :func:`simcore.radiometry.analytic.diode_irradiance` (``backend='numpy'``).
    """

    aperture: WellAperture
    theta_deg: np.ndarray
    phi_deg: np.ndarray
    reflected: np.ndarray        # (T, P)
    reflected_se: np.ndarray     # (T, P)
    material: object

    @classmethod
    def trace(cls, aperture, material, *, theta_step_deg=2.0, phi_step_deg=7.5, samples=4096, seed=0,
              renderer=None):
        """Return the table traced with :func:`wall_response` over :func:`octant_grid` (``samples`` per node)."""
        if not np.isclose(aperture.opening_x_m, aperture.opening_y_m) or \
                not np.isclose(aperture.diode_x_m, aperture.diode_y_m):
            raise ValueError("TabulatedResponse folds directions by the symmetry of a SQUARE well over a square "
                             "diode; this aperture is rectangular")
        th, ph = octant_grid(theta_step_deg, phi_step_deg)
        d = cut_directions(*(a.ravel() for a in np.meshgrid(th, ph, indexing="ij")))
        w = wall_response(aperture, d, material, samples=samples, seed=seed, renderer=renderer)
        shape = (len(th), len(ph))
        return cls(aperture, th, ph, w.reflected.reshape(shape), w.reflected_se.reshape(shape), material)

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


# ----------------------------------------------------------------------------- response figures

def response_angles(theta_deg, response_rel, levels=DEFAULT_LEVELS):
    """Return {level: angle_deg}: the largest incidence angle at which a response cut (relative to
    normal incidence, sampled at increasing ``theta_deg``) still reaches ``level`` (e.g. 0.5 and
    0.01: the 50 % and 1 % response angles), interpolated linearly; NaN if never reached."""
    th = np.asarray(theta_deg, dtype=float)
    r = np.asarray(response_rel, dtype=float)
    if th.shape != r.shape or th.ndim != 1 or np.any(np.diff(th) <= 0):
        raise ValueError("theta_deg must be increasing and response_rel the same shape (M,)")
    out = {}
    for lev in levels:
        above = np.flatnonzero(r >= lev)
        if above.size == 0:
            out[lev] = float("nan")
            continue
        i = above[-1]
        if i == len(th) - 1:
            out[lev] = float(th[i])
            continue
        r0, r1 = r[i], r[i + 1]
        out[lev] = float(th[i] + (th[i + 1] - th[i]) * (r0 - lev) / (r0 - r1))
    return out


def analytic_angles(aperture, phi_deg=0.0, levels=DEFAULT_LEVELS, step_deg=0.01):
    """Return {level: angle_deg} of the analytic overlap response along azimuth ``phi_deg`` (fine grid)."""
    th = np.arange(0.0, 90.0, step_deg)
    return response_angles(th, aperture.response(cut_directions(th, phi_deg)), levels)


def eq415_angles(fov_deg, levels=DEFAULT_LEVELS, step_deg=0.01):
    """Return {level: angle_deg} of thesis eq. 4.15 with FOV ``fov_deg`` (any azimuth)."""
    th = np.arange(0.0, 90.0, step_deg)
    return response_angles(th, Eq415Response(fov_deg).response(cut_directions(th, 0.0)), levels)


@dataclass
class CutStudy:
    """Angular response cuts of one aperture: ``curves[phi]`` maps a model name to (M,) responses
    relative to normal incidence at ``theta_deg``; ``errors[phi]`` the standard errors of traced
    curves; ``angles`` rows {phi_deg, model, level, angle_deg}."""

    aperture: WellAperture
    fov_deg: float
    theta_deg: np.ndarray
    curves: dict
    errors: dict
    angles: list = field(default_factory=list)


def angular_cuts(aperture, *, fov_deg=None, theta_deg=None, phi_deg=(0.0, 45.0), materials=(), samples=4096,
                 wall_samples=16384, seed=0, levels=DEFAULT_LEVELS):
    """Return a :class:`CutStudy`: response cuts of ``aperture`` along azimuths ``phi_deg`` (``theta_deg``
    increasing, from 0; the 50 % / 1 % angles of every curve are interpolated on that same grid, so
    use a fine grid near the cut-off) with the
    traced black well (renderer), the analytic overlap, eq. 4.15 (``fov_deg``, default: the angle up to
    which the diode is fully lit along the wall axes), cos theta, and the well with walls of each material in
    ``materials`` (a mapping {label: material} or a sequence of materials: :mod:`scenes.materials` names or
    Mitsuba BSDF dicts; :func:`wall_response` with ``wall_samples`` paths per direction: the exact overlap
    plus the path-traced reflections). Curve names: 'traced black', 'overlap', 'eq. 4.15', 'cos' and each
    material's label."""
    th = np.arange(0.0, 90.0, 2.5) if theta_deg is None else np.asarray(theta_deg, dtype=float)
    if fov_deg is None:
        fov_deg = float(np.degrees(np.arctan2((aperture.opening_x_m - aperture.diode_x_m) / 2, aperture.height_m)))
    named = _named_materials(materials)
    renderers = {label: well_renderer(aperture, spec) for label, spec in named}
    eq = Eq415Response(fov_deg)
    curves, errs, angles = {}, {}, []
    for phi in phi_deg:
        d = cut_directions(th, phi)
        c, e = {}, {}
        tb, tb_se = traced_black_response(aperture, d, samples=samples, seed=seed)
        c["traced black"], e["traced black"] = tb, tb_se
        c["overlap"] = aperture.response(d)
        c["eq. 4.15"] = eq.response(d)
        c["cos"] = np.clip(d[:, 2], 0, None)
        for label, spec in named:
            w = wall_response(aperture, d, spec, samples=wall_samples, seed=seed, renderer=renderers[label])
            c[label], e[label] = w.response, w.response_se
        for name, y in c.items():
            a = response_angles(th, y, levels)
            for lev in levels:
                angles.append({"phi_deg": float(phi), "model": name, "level": lev, "angle_deg": a[lev]})
        curves[float(phi)], errs[float(phi)] = c, e
    return CutStudy(aperture, float(fov_deg), th, curves, errs, angles)


@dataclass
class ResponseMap:
    """A diode's response over the sphere: HEALPix directions ``d_diode`` (P, 3) (diode frame, pole =
    normal), the traced response and its standard error, the analytic overlap and eq. 4.15."""

    nside: int
    d_diode: np.ndarray
    traced: np.ndarray
    traced_se: np.ndarray
    overlap: np.ndarray
    eq415: np.ndarray
    label: str

    @property
    def z_score(self):
        """Return (traced - overlap) / SE where SE > 0 (0 elsewhere): the black-wall check per direction."""
        diff = self.traced - self.overlap
        return np.where(self.traced_se > 0, diff / np.where(self.traced_se > 0, self.traced_se, 1.0), 0.0)


def response_map(aperture, *, nside=16, fov_deg=None, material=None, samples=1024, wall_samples=4096, seed=0):
    """Return a :class:`ResponseMap` over the whole sphere (HEALPix ``nside``): black walls traced by the
    renderer (``material`` None) or the well with walls of ``material`` (:func:`wall_response`)."""
    d = healpix_directions(nside)
    front = d[:, 2] > 0
    tr, se = np.zeros(len(d)), np.zeros(len(d))
    if material is None:
        tr[front], se[front] = traced_black_response(aperture, d[front], samples=samples, seed=seed)
        label = "traced, black walls"
    else:
        w = wall_response(aperture, d[front], material, samples=wall_samples, seed=seed)
        tr[front], se[front] = w.response, w.response_se
        label = f"traced, {material_label(material)}"
    if fov_deg is None:
        fov_deg = float(np.degrees(np.arctan2((aperture.opening_x_m - aperture.diode_x_m) / 2, aperture.height_m)))
    return ResponseMap(int(nside), d, tr, se, aperture.response(d), Eq415Response(fov_deg).response(d), label)


# ----------------------------------------------------------------------------- design

@dataclass(frozen=True)
class ApertureDesign:
    """A designed well: the aperture, the FOV (full response along the wall axes) and cut-off it
    realises (axis and diagonal), whether the height limit bound it, and its response angles
    {(phi_deg, level): angle_deg} (analytic overlap, exact for black walls)."""

    aperture: WellAperture
    fov_deg: float
    cutoff_deg: float
    cutoff_diagonal_deg: float
    height_limited: bool
    angles: dict

    @property
    def opening_mm(self):
        return self.aperture.opening_x_m / MM

    @property
    def height_mm(self):
        return self.aperture.height_m / MM


def design_aperture(fov_deg, *, cutoff_deg=EQ415_CUTOFF_DEG, diode_area_m2=BPW34_AREA_M2, max_height_m=None,
                    keep="fov", levels=DEFAULT_LEVELS):
    """Return an :class:`ApertureDesign`: the square well over a square diode of ``diode_area_m2`` that
    lights the whole diode up to ``fov_deg`` along the wall axes and none of it beyond ``cutoff_deg``
    (eq. 4.15: ``w - a = 2 h tan FOV``, ``w + a = 2 h tan cutoff``), within ``max_height_m``.

    The two angles fix ``h = a / (tan cutoff - tan FOV)``; when that exceeds the height limit the well
    is made ``max_height_m`` tall and ``keep`` says which angle survives: 'fov' (the opening still gives
    full response to the FOV; the cut-off moves out) or 'cutoff' (no light beyond the cut-off; the
    fully lit range shrinks).
    """
    if keep not in ("fov", "cutoff"):
        raise ValueError(f"keep must be 'fov' or 'cutoff', got {keep!r}")
    ap = WellAperture.design(fov_deg, cutoff_deg, diode_area_m2)
    a = ap.diode_x_m
    limited = max_height_m is not None and ap.height_m > float(max_height_m)
    if limited:
        h = float(max_height_m)
        if not h > 0:
            raise ValueError(f"max_height_m must be > 0, got {max_height_m}")
        if keep == "fov":
            w = a + 2 * h * np.tan(np.radians(fov_deg))
        else:
            w = 2 * h * np.tan(np.radians(cutoff_deg)) - a
            if w < a:
                raise ValueError(f"a well {h / MM:.3f} mm tall cannot cut off at {cutoff_deg} deg over a "
                                 f"{a / MM:.3f} mm diode (it would need an opening smaller than the diode); "
                                 "raise max_height_m or use keep='fov'")
        ap = WellAperture(a, a, float(w), float(w), h)
    h, w = ap.height_m, ap.opening_x_m
    fov = float(np.degrees(np.arctan2((w - a) / 2, h))) if h > 0 else 90.0
    cut = float(np.degrees(np.arctan2((w + a) / 2, h))) if h > 0 else 90.0
    cut_diag = float(np.degrees(np.arctan(np.sqrt(2.0) * (w + a) / (2 * h)))) if h > 0 else 90.0
    angles = {}
    for phi in (0.0, 45.0):
        for lev, ang in analytic_angles(ap, phi, levels).items():
            angles[(phi, lev)] = ang
    return ApertureDesign(ap, fov, cut, cut_diag, bool(limited), angles)


# ----------------------------------------------------------------------------- wall reflections and albedo



def wall_albedo_effect(config, materials, *, geometry=None, step_s=20.0, dead=(0,), theta_step_deg=3.0,
                       phi_step_deg=9.0, samples=4096, seed=0, batches=8):
    """Return (rows, tables): rows {material, albedo_mean_w_m2, albedo_ratio, direct_mean_w_m2, direct_ratio,
    response_60/75/83/86deg_axis, and each one's ``_se``} comparing, over the sunlit part of one orbit (live
    diodes of ``config``), the Earth albedo and direct Sun picked up with reflecting walls against black walls
    (the overlap model); tables {label: :class:`TabulatedResponse`}. ``materials``: a mapping {label: material}
    or a sequence of materials (:mod:`scenes.materials` names or Mitsuba BSDF dicts).

    Both use the numpy backend of :func:`simcore.radiometry.analytic.diode_irradiance` with the body box for
    the albedo; the direct Sun without the box (its exact box clipping needs the overlap model). Each material's
    table is traced in ``batches`` independent parts (seeds ``seed * batches + b``, ``samples`` paths per node
    each): every row value is linear in the table, so the value is the mean over the parts (that of the pooled
    table) and its standard error their standard deviation / sqrt(batches)."""
    cfg = _as_config(config)
    aps = cfg.apertures
    if len({(a.opening_x_m, a.height_m) for a in aps}) != 1:
        raise ValueError("wall_albedo_effect tabulates one well; this configuration mixes wells")
    if int(batches) < 2:
        raise ValueError(f"batches must be >= 2 (their spread gives the standard errors), got {batches}")
    named = _named_materials(materials)
    ap = aps[0]
    g = one_orbit_geometry(step_s=step_s) if geometry is None else geometry
    lit = sunlit(g.illumination)
    live = np.ones(cfg.n_diodes, bool)
    live[list(dead)] = False
    body = Satellite(cfg).body_box
    args = (g.r_sat_ecef_m[lit], g.r_sun_ecef_m[lit], g.R_ecef_from_body[lit], cfg.frames)

    def values(resp):
        alb = diode_irradiance(*args, [resp] * cfg.n_diodes, backend="numpy", body=body, direct=False)
        dr_ = diode_irradiance(*args, [resp] * cfg.n_diodes, backend="numpy", albedo=False)
        v = {"albedo_mean_w_m2": float(alb.albedo_w_m2[:, live].mean()),
             "direct_mean_w_m2": float(dr_.direct_w_m2[:, live].mean())}
        for t in (60, 75, 83, 86):
            v[f"response_{t}deg_axis"] = float(resp.response(cut_directions([t], 0.0))[0])
        return v

    black = values(ap)
    a0, d0 = black["albedo_mean_w_m2"], black["direct_mean_w_m2"]
    rows = [{"material": "black (overlap model)", **black, "albedo_ratio": 1.0, "direct_ratio": 1.0}]
    tables = {}
    for label, spec in named:
        r = well_renderer(ap, spec)
        parts, runs = [], []
        for b in range(int(batches)):
            tab = TabulatedResponse.trace(ap, spec, theta_step_deg=theta_step_deg, phi_step_deg=phi_step_deg,
                                          samples=samples, seed=int(seed) * int(batches) + b, renderer=r)
            parts.append(tab)
            v = values(tab)
            v["albedo_ratio"], v["direct_ratio"] = v["albedo_mean_w_m2"] / a0, v["direct_mean_w_m2"] / d0
            runs.append(v)
        n = len(parts)
        tables[label] = TabulatedResponse(ap, parts[0].theta_deg, parts[0].phi_deg,
                                          np.mean([t.reflected for t in parts], axis=0),
                                          np.sqrt(np.sum([t.reflected_se ** 2 for t in parts], axis=0)) / n, spec)
        row = {"material": label}
        for k in runs[0]:
            x = np.array([v[k] for v in runs])
            row[k], row[k + "_se"] = float(x.mean()), float(x.std(ddof=1) / np.sqrt(n))
        rows.append(row)
    return rows, tables


# ----------------------------------------------------------------------------- self-shadowing

def _as_config(config):
    return config if isinstance(config, SatelliteConfig) else SatelliteConfig.load(config)


def self_shadowing(config, *, nside=8, samples=64, seed=0, loss_threshold=0.01, min_response=1e-6,
                   reference="analytic", variant=None):
    """Return rows (one per diode) of the shadowing of each diode's field of view by the rest of the
    satellite: traced with the full mesh (:func:`scenes.meshes.build_satellite_mesh`: body, ramps,
    floors, wells of all diodes) over HEALPix directions (``nside``) against its own well alone (the
    analytic overlap, which the black-wall tracing of the well reproduces, see the tests; or, with
    ``reference='traced'``, the renderer with only diode k's own floor + well,
    :func:`scenes.meshes.mount_meshes`).

    Columns: ``fov_sr`` (solid angle where the own-well response > ``min_response``: directions in the
    diode plane, response ~1e-17, do not count), ``shadowed_fov_fraction``
    (share of it where the traced response is more than ``loss_threshold`` and 3 SE below the own
    well's), ``body_fov_fraction`` (the same for the body box alone, closed form,
    :func:`simcore.shapes.occlusion.direct_visibility`), ``response_loss`` (response-weighted loss: 1 -
    sum traced / sum own over the sphere), ``body_response_loss`` (box alone) and
    ``neighbour_response_loss`` (the rest: ramps and other mounts).
    """
    cfg = _as_config(config)
    sat = Satellite(cfg)
    d = healpix_directions(nside)
    pix_sr = 4 * np.pi / len(d)
    frames = cfg.frames
    # each diode's own optics: its well, under its window when it has one (simcore.shapes.window)
    own = np.stack([(a if w is None else WindowedWell(a, w)).response(d @ f.T)
                    for a, w, f in zip(cfg.apertures, cfg.windows, frames)], axis=1)      # (P, K)
    if reference == "traced":
        for k in range(cfg.n_diodes):
            parts = mount_meshes(cfg, k)
            mesh_k = trimesh.util.concatenate([parts[p] for p in ("floor", "well") if p in parts])
            rk = Renderer.from_scene(sat, diodes=[k], mesh=mesh_k, e_sun_w_m2=1.0, variant=variant)
            own[:, k] = rk.render(d, None, direct_samples=int(samples), albedo=False, seed=int(seed)).direct_w_m2[:, 0]
    elif reference != "analytic":
        raise ValueError(f"reference must be 'analytic' or 'traced', got {reference!r}")
    r = Renderer.from_scene(sat, e_sun_w_m2=1.0, variant=variant)
    res = r.render(d, None, direct_samples=int(samples), albedo=False, seed=int(seed))
    full, se = res.direct_w_m2, res.direct_se_w_m2
    box = sat.body_box
    vis_box = direct_visibility(cfg.apertures, frames, box.positions_m, box.panel_normals, d, box.half_m)
    # the box's visibility is NaN where the well itself lets no light through (own response 0)
    body_resp = np.where(own > 0, own * np.nan_to_num(vis_box, nan=0.0), 0.0)
    rows = []
    for k, dio in enumerate(cfg.diodes):
        inside = own[:, k] > min_response
        loss = own[:, k] - full[:, k]
        shadowed = inside & (loss > loss_threshold * own[:, k]) & (loss > 3 * se[:, k])
        body_sh = inside & (own[:, k] - body_resp[:, k] > loss_threshold * own[:, k])
        tot = own[:, k].sum()
        rows.append({"config": cfg.name, "diode": k, "name": dio.name, "fov_sr": float(inside.sum() * pix_sr),
                     "shadowed_fov_fraction": float(shadowed.sum() / max(inside.sum(), 1)),
                     "body_fov_fraction": float(body_sh.sum() / max(inside.sum(), 1)),
                     "response_loss": float(1 - full[:, k].sum() / tot),
                     "response_loss_se": float(np.sqrt((se[:, k] ** 2).sum()) / tot),
                     "body_response_loss": float(1 - body_resp[:, k].sum() / tot),
                     "neighbour_response_loss": float((body_resp[:, k].sum() - full[:, k].sum()) / tot)})
    return rows


def self_shadowing_table(configs=None, **kw):
    """Return the rows of :func:`self_shadowing` for every configuration in ``configs``
    (default: all shipped, :func:`scenes.config.list_configs`)."""
    rows = []
    for name in (list_configs() if configs is None else configs):
        rows += self_shadowing(name, **kw)
    return rows


# ----------------------------------------------------------------------------- sweep

def sweep_config(tilt_deg, fov_deg, height_mm=None, *, name=None):
    """Return the 14-diode thesis layout (:mod:`scenes.config`, pattern 'thesis14') with ``tilt_deg`` and
    every diode in a well of ``height_mm`` whose opening gives full response up to ``fov_deg`` along the
    wall axes (``w = a + 2 h tan FOV``); ``height_mm`` None: the eq. 4.15 design (cut-off 83.1 deg).
    Raises :class:`scenes.config.ConfigError` when the mounts do not fit (clearance, panel, overlap)."""
    tables = expand_layout({**LAYOUT_DEFAULTS, "pattern": "thesis14", "tilt_deg": float(tilt_deg),
                             "fov_deg": float(fov_deg)})
    if height_mm is not None:
        a = float(np.sqrt(BPW34_AREA_M2)) / MM
        w = a + 2 * float(height_mm) * np.tan(np.radians(fov_deg))
        for t in tables:
            t["well"] = {"height_mm": float(height_mm), "opening_mm": [float(w), float(w)]}
    name = name or f"tilt{tilt_deg:g}_fov{fov_deg:g}_h{'eq415' if height_mm is None else f'{height_mm:g}'}"
    return SatelliteConfig.from_dict({"name": name, "diode": tables})


def response_coverage(config, *, dead=(0,), level=0.01, nside=16):
    """Return the coverage fractions {'red', 'yellow', 'green'} counting, per HEALPix direction, the live
    diodes whose real response (the well's overlap x the body box's visibility, black walls) reaches
    ``level`` of normal incidence, instead of the nominal FOV cone of
    :func:`simcore.studies.coverage.coverage_fractions` (thesis sec. 3.2.4). ``config``: a name, a
    ``SatelliteConfig`` or a :class:`scenes.satellite.Satellite`."""
    sat = config if isinstance(config, Satellite) else Satellite(_as_config(config))
    cfg = sat.config
    d = pixel_directions(nside)
    resp = np.stack([a.response(d @ f.T) for a, f in zip(cfg.apertures, cfg.frames)], axis=1)
    box = sat.body_box
    vis = direct_visibility(cfg.apertures, cfg.frames, box.positions_m, box.panel_normals, d, box.half_m)
    resp = np.where(resp > 0, resp * np.nan_to_num(vis, nan=0.0), 0.0)      # NaN: the well itself is dark
    live = ~np.asarray(cfg.dead, bool)
    live[list(dead)] = False
    cls = coverage_classes(np.sum(resp[:, live] >= level, axis=1))
    return {name: float(np.mean(cls == k)) for k, name in enumerate(CLASSES)}


SWEEP_COLUMNS = ("height_mm", "tilt_deg", "fov_deg", "opening_mm", "cutoff_deg", "cutoff_diag_deg",
                 "mount_height_mm", "green", "yellow", "red", "green_response", "albedo_fraction")


def sweep_apertures(heights_mm=(0.3, 0.5, 1.0), tilts_deg=(20.0, 25.0, 30.0), fovs_deg=(70.0, 75.0), *,
                    dead=(0,), step_s=20.0, geometry=None, diode="BPW34FS", estimators=("wls", "albedo_sun"),
                    progress=None):
    """Return the sweep table (list of dict rows, one per height x tilt x FOV) of the 14-diode layout
    (:func:`sweep_config`; a height None means the eq. 4.15 design):

    ``green``/``yellow``/``red``: coverage fractions (:func:`simcore.studies.coverage.coverage_fractions`, ``dead``:
    nominal FOV cones, the same for every height); ``green_response``: the green fraction counting the diodes
    whose real response reaches 1 % (:func:`response_coverage`: it sees the height through the cut-off);
    ``albedo_fraction``: albedo / (direct + albedo) summed over the live diodes and the sunlit epochs of one
    orbit (analytic model with the body box, :func:`simcore.radiometry.analytic.diode_irradiance`);
    ``<estimator>_mean_deg`` / ``_p95_deg``: sunlit angle errors of the estimators over that orbit
    (sensor chain :func:`simcore.pipeline.evaluate.measure`, no noise). Mounts that do not fit give
    ``feasible`` False, the reason, and NaN metrics.
    """
    g = one_orbit_geometry(step_s=step_s) if geometry is None else geometry
    lit_epochs = sunlit(g.illumination)
    rows = []
    combos = [(h, t, f) for h in heights_mm for t in tilts_deg for f in fovs_deg]
    for i, (h, tilt, fov) in enumerate(combos):
        row = {"height_mm": float("nan") if h is None else float(h), "tilt_deg": float(tilt), "fov_deg": float(fov)}
        try:
            cfg = sweep_config(tilt, fov, h)
        except ConfigError as exc:
            for c in SWEEP_COLUMNS[3:]:
                row[c] = float("nan")
            row.update({"feasible": False, "reason": str(exc).split(";")[0]})
            for e in estimators:
                row[f"{e}_mean_deg"] = row[f"{e}_p95_deg"] = float("nan")
            rows.append(row)
            if progress is not None:
                progress(i + 1, len(combos))
            continue
        ap = cfg.apertures[0]
        a = ap.diode_x_m
        row.update({"height_mm": ap.height_m / MM, "opening_mm": ap.opening_x_m / MM,
                    "cutoff_deg": float(np.degrees(np.arctan2((ap.opening_x_m + a) / 2, ap.height_m))),
                    "cutoff_diag_deg": float(np.degrees(np.arctan(np.sqrt(2) * (ap.opening_x_m + a)
                                                                  / 2 / ap.height_m))),
                    "mount_height_mm": float(cfg.mount_heights_m().max() / MM), "feasible": True, "reason": ""})
        row.update(coverage_fractions(cfg, dead=dead))
        sat = Satellite(cfg)
        row["green_response"] = response_coverage(sat, dead=dead)["green"]
        irr = diode_irradiance(g.r_sat_ecef_m, g.r_sun_ecef_m, g.R_ecef_from_body, cfg.frames, list(cfg.apertures),
                               body=sat.body_box)
        live = np.ones(cfg.n_diodes, bool)
        live[list(dead)] = False
        alb = irr.albedo_w_m2[lit_epochs][:, live].sum()
        row["albedo_fraction"] = float(alb / irr.total_w_m2[lit_epochs][:, live].sum())
        e_p = measure(irr.total_w_m2, diode=diode, dead=dead)
        est = run_estimators(e_p, cfg.normals, float(fov), e_s0=DIODES[diode].e_s0_w_m2, live=live,
                             which=estimators)
        table = error_table(errors(est, g.sun_dir_body), lit_epochs)
        for t in table:
            row[f"{t['estimator']}_mean_deg"] = t["mean_deg"]
            row[f"{t['estimator']}_p95_deg"] = t["p95_deg"]
        rows.append(row)
        if progress is not None:
            progress(i + 1, len(combos))
    return rows




def format_table(rows, columns=None, floatfmt="{:.3g}"):
    """Return a Markdown table of dict rows (``columns``: the keys to show, default all of the first row)."""
    if not rows:
        return ""
    cols = list(columns or rows[0].keys())

    def fmt(v):
        if isinstance(v, (float, np.floating)):
            return floatfmt.format(v)
        return str(v)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in cols) + " |" for r in rows]
    return "\n".join(lines)


def run_aperture_sweep(out_dir, heights_mm=(0.3, 0.5, 1.0), tilts_deg=(20.0, 25.0, 30.0), fovs_deg=(70.0, 75.0),
                       *, step_s=20.0, dead=(0,), log=print):
    """Run :func:`sweep_apertures` and write ``sweep.csv``, ``sweep.md`` and ``sweep.png`` into ``out_dir``;
    return the rows. The command-line entry point (``sunsim aperture-sweep``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = sweep_apertures(heights_mm, tilts_deg, fovs_deg, step_s=step_s, dead=dead,
                           progress=lambda i, n: log(f"aperture sweep: {i}/{n}"))
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "sweep.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    (out / "sweep.md").write_text(format_table(rows, [k for k in keys if k != "reason"]) + "\n")
    plot_sweep(rows, out / "sweep.png")
    log(f"wrote {out / 'sweep.csv'}, {out / 'sweep.md'}, {out / 'sweep.png'}")
    return rows


# ----------------------------------------------------------------------------- wall reflectance series

def reflectance_series(aperture, rhos=(0.0, 0.05, 0.2, 0.5, 0.9), *, theta_deg=None, phi_deg=0.0, samples=4096,
                       seed=0, levels=DEFAULT_LEVELS):
    """Return {'theta_deg', 'rho', 'response' (R, M), 'response_se' (R, M), 'angles' rows, 'overlap'}: the
    response cut along ``phi_deg`` (:func:`wall_response`: the exact overlap plus the path-traced reflections,
    ``samples`` paths per direction) with Lambertian walls and floor plate of each reflectance in ``rhos``
    (the same seed for each)."""
    th = np.arange(0.0, 90.0, 2.0) if theta_deg is None else np.asarray(theta_deg, dtype=float)
    d = cut_directions(th, phi_deg)
    resp, se, angles = [], [], []
    for rho in rhos:
        w = wall_response(aperture, d, {"type": "diffuse", "reflectance": float(rho)}, samples=samples, seed=seed)
        resp.append(w.response)
        se.append(w.response_se)
        for lev, ang in response_angles(th, w.response, levels).items():
            angles.append({"rho": float(rho), "level": lev, "angle_deg": ang})
    return {"theta_deg": th, "phi_deg": float(phi_deg), "rho": np.asarray(rhos, float), "response": np.array(resp),
            "response_se": np.array(se), "angles": angles, "overlap": aperture.response(d)}
