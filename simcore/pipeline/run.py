"""The main job: render diode irradiance along an orbit, check it, store it.

:func:`execute` renders the study in chunks of epochs, stores every finished
chunk crash-safely (:mod:`simcore.pipeline.store`), computes the analytic model
beside each chunk and, once all are done, writes one self-describing xarray
Dataset (netCDF) with the check's verdict. Killed and started again with the
same options it continues from its last finished chunk and ends with exactly
the numbers of an uninterrupted run (the renderer's random numbers are keyed
by the global epoch index, not by the chunk).
"""
import concurrent.futures
import dataclasses
import functools
import datetime as _dt
import hashlib
import json
import os
from pathlib import Path
import shlex
import sys
from dataclasses import dataclass

import numpy as np
import xarray as xr

from scenes.config import SatelliteConfig, body_side_normal
from scenes.meshes import build_parts, build_satellite_mesh
from simcore.radiometry.analytic import BodyBox, DirectionVisibility, diode_irradiance, disc_directions
from simcore.radiometry.glint import SunGlint, check_refine as glint_check_refine
from simcore.shapes.aperture import CircularWell
from simcore.shapes.occlusion import box_hit
from simcore.shapes.window import WindowedWell
from simcore.render import DiodeSurfaces, Renderer, occluder_scene, rays_blocked, widen_cells

from simcore import _llvm
from simcore._version import __version__
from simcore.environment import attitude as _attitude
from simcore.pipeline import check as _check
from simcore.constants import AU_M, E_SUN_W_M2, R_EARTH_MEAN_M, R_SUN_M, TSI_W_M2
from simcore.errors import InputNotFoundError, InvalidInputError, OutputError
from simcore.radiometry import band
from simcore.environment.clouds import DEFAULT_SCALE_KM as CLOUD_SCALE_KM
from simcore.pipeline.preflight import (REFLECTED_SAMPLES, attitude_times_note, check_map, check_numbers,
                                       check_run_resources, check_variant, map_for_diodes, reflected_ignored_note,
                                       tle_age_note)
from simcore.pipeline.runfile import (add_checksums, git_commit as _git_commit, size_bound, verify_checksums,
                                      software_versions as _versions, writer as _writer)
from simcore.pipeline.store import (ChunkStore, atomic_write, check_room, check_writable, chunk_ranges, is_disk_full,
                                    missing_ranges, spec_digest)
from simcore.environment.geometry import compute_geometry, orbital_period_s
from simcore.pipeline import schedule as _schedule
from simcore.pipeline.schedule import study_geometry  # noqa: F401 (its old home: callers import it from here)

# The analytic reference for the albedo check uses cells refined 2 x 2; its estimated discretisation error
# (check.discretisation_bound, a third of |native - refined|) joins each diode-epoch's variance. On a sunlit
# 10 minutes of the default study the 3 x 3 bound was below 0.1 of the rendered standard error for 90 % of the
# diode-epochs (0.43 at 99 %); 2 x 2 makes it 2.25 times larger for ~55 % of the 3 x 3 cost.
CHECK_REFINE = 2
# Under cloud weather, 4 x 4. Where the body's or a mount's shadow crosses the Earth's disc, the cell-centre sum
# meets a step in the visibility: on a smooth map the cells along the edge err both ways and cancel, but a cloud
# realisation is two-state (overcast 0.7 beside an infrared sea of 0.013), the errors along the edge stop
# cancelling, and 2 x 2 is not yet where the sum converges smoothly (so native against 2 x 2 can agree by chance).
# Seen on tilt20_fov70's day under --map band --glint 7 --clouds 1: at 19:03:33Z, diode 1, the sums over cells
# refined 1, 2, 4, 8 read 2.501, 2.501, 2.632, 2.699 W/m^2 and six seeds of the renderer at 65,536 samples
# 2.687 +- 0.005; at five other such diode-epochs 8 x 8 and the renderer agree within 0.1 W/m^2 where 2 x 2 missed
# by 0.2-0.7. The check over that day: 2 x 2, 85 values beyond |z| = 4 against 35 expected (88 % of them where
# shadows cross the diode), FAIL; 4 x 4 with the same Richardson bound, 21, spread p = 1, PASS (a first-order
# bound, a third of |native - 4 x 4|, overstates the error: the spread test failed, p = 5e-25). At ~3x the
# refined sum's cost, only for cloud weather.
CHECK_REFINE_CLOUDS = 4


@dataclass
class RunOptions:
    """Everything that decides a run's numbers (and where it goes)."""

    config: str = "tilt20_fov70"
    tle: str = None
    satellite: str = None
    orbit_file: str = None            # CCSDS OEM (KVN or XML) instead of a TLE (simcore.environment.ephemeris)
    start: str = None                  # None: the attitude history's first sample, the ephemeris's first epoch,
                                       # else DEFAULT_START (schedule.py)
    duration_s: float = None          # None: the rest of the attitude history (or ephemeris), else one orbital period
    step_s: float = 1.0
    spin_rate_deg_s: float = _attitude.DEFAULT_TUMBLE_RATE_DEG_S
    spin_axis: tuple = (1.0, 1.0, 1.0)
    attitude_file: str = None          # attitude history file (environment.telemetry.read_attitude_history)
    attitude_frame: str = None         # its frame / direction where the file does not declare them
    attitude_direction: str = None
    attitude_history: object = None    # in-process AttitudeHistory (instead of attitude_file)
    times_file: str = None             # explicit epochs: one ISO-8601 UTC time per line (schedule.read_times)
    epochs: object = None              # explicit epochs in-process (an Epochs)
    dynamics: str = None               # inertia 'IXX,IYY,IZZ[,IXY,IXZ,IYZ]' kg m^2: torque-free Euler dynamics
    rel_se_direct: float = 0.002       # target relative standard errors (None: fixed sample counts)
    rel_se_albedo: float = 0.01
    direct_samples: int = 1024
    albedo_samples: int = 256
    reflected_samples: int = REFLECTED_SAMPLES    # paths per diode-epoch for the reflected component (4 m^2)
    dead: tuple = ()
    extra_flat_diodes: bool = False    # the two optional flat diodes on top and bottom (diodes 14, 15)
    variant: str = None
    seed: int = 0
    reflectivity: str = "toms2005"
    clouds: int = None                 # cloud-weather seed (simcore.environment.clouds); None: the map as it is
    cloud_scale_km: float = None       # the clouds' correlation length (None: clouds.DEFAULT_SCALE_KM)
    eop: tuple = None                  # Earth orientation (UT1 - UTC s, x_p arcsec, y_p arcsec), IERS Bulletin A; None: 0
    glint: float = None                # sea sun glint: wind speed m/s at 12.5 m (simcore.radiometry.glint); None: none
    sun_disc: bool = True              # finite solar disc: penumbra
    e_sun_w_m2: float = TSI_W_M2        # solar irradiance at 1 AU (the thesis: E_SUN_W_M2 = 1366.1)
    distance_scaling: bool = True      # x (1 AU / r_sun)^2 (the thesis: a constant, False)
    chunk_epochs: int = 512
    output: str = None                 # None: runs/default.nc, or the next free runs/default-N.nc (execute)
    fail_on_check: bool = True        # exit status 1 when the analytic check fails
    overwrite: bool = False            # replace an existing output made with other settings
    allow_bright_map: bool = False     # accept reflectivity above preflight.MAP_REFLECTIVITY_MAX

    def spec(self):
        """Return the JSON-able settings that determine the numbers (not where they go)."""
        d = dataclasses.asdict(self)
        for k in ("output", "fail_on_check", "chunk_epochs", "overwrite", "allow_bright_map"):
            d.pop(k)
        d["dead"] = sorted(int(i) for i in d["dead"])
        if d["clouds"] is None:         # runs without clouds keep the settings digest they always had
            d.pop("clouds")
            d.pop("cloud_scale_km")
        elif d["cloud_scale_km"] is None:   # the default length named or not: one run, one digest
            d["cloud_scale_km"] = CLOUD_SCALE_KM
        if d["glint"] is None:          # runs without glint keep the settings digest they always had
            d.pop("glint")
        if d["eop"] is None:            # runs without Earth-orientation data keep the digest they always had
            d.pop("eop")
        else:
            d["eop"] = [float(x) for x in d["eop"]]
        if d["reflected_samples"] == REFLECTED_SAMPLES:     # runs at the default keep the digest they always had
            d.pop("reflected_samples")
        d["spin_axis"] = [float(x) for x in d["spin_axis"]]
        _schedule.spec_fields(self, d)
        for k in ("config", "tle", "attitude_file", "times_file", "orbit_file"):
            v = d.get(k)
            if v and os.path.isfile(v):
                with open(v, "rb") as f:
                    d[k + "_sha256"] = hashlib.sha256(f.read()).hexdigest()
        d["sunsim_version"] = __version__
        return d


class PreparedRun:
    """A prepared run: configuration, geometry, scene and maps, ready to render chunks."""

    def __init__(self, opts):
        self.opts = opts
        self.config = SatelliteConfig.load(opts.config, dead=list(opts.dead),
                                           extra_flat_diodes=True if opts.extra_flat_diodes else None)
        eop = _schedule.eop_kwargs(opts)
        self.plan = _schedule.plan(opts)
        self.orbit, self.attitude = self.plan.orbit, self.plan.attitude
        self.geometry = compute_geometry(self.orbit, self.plan.epochs, self.attitude, **eop)
        self.epochs = self.geometry.epochs
        self.clouds = None
        if getattr(opts, "clouds", None) is None:
            self.map = band.resolve_map(map_for_diodes(opts.reflectivity, self.config), getattr(opts, "glint", None))
        else:
            self.clouds = band.cloud_weather(map_for_diodes(opts.reflectivity, self.config), opts.cloud_scale_km,
                                             getattr(opts, "glint", None))
            self.map = self.clouds.realise(opts.clouds)
        self.glint = self._sea_glint()
        base, r_m = CHECK_REFINE if self.clouds is None else CHECK_REFINE_CLOUDS, self.geometry.r_sat_gcrs_m
        self.check_refine = base if self.glint is None else glint_check_refine(        # finer for a calm sea's spot
            self.glint.wind_m_s, np.linalg.norm(r_m, axis=1).min() - R_EARTH_MEAN_M, self.map.dlon_deg, base)
        self.map_refined = self.map.refined(self.check_refine)
        self._renderer = None

    def _sea_glint(self):
        """Return the run's :class:`SunGlint` on the map's cells (its sea fraction in the map's row order), or None.

        The sea is GSHHG's less its annual ice (:func:`simcore.radiometry.sea_surface.open_sea_fraction`); under cloud
        weather the overcast cells' sea is hidden (a thick cloud deck reflects diffusely; its albedo is the map's),
        so glint comes from the clear sea only. A band map's sea leaves its specular part to it (band.resolve_map)."""
        wind = getattr(self.opts, "glint", None)
        if wind is None:
            return None
        from simcore.radiometry.sea_surface import open_sea_fraction
        sea = open_sea_fraction(self.map, band.sea_ice_share())
        if self.clouds is not None:
            sea = np.where(self.clouds.overcast(self.opts.clouds), 0.0, sea)
        return SunGlint(wind, sea=sea)

    def glint_on(self, reflectivity_map):
        """Return the run's glint for ``reflectivity_map`` (the run's map or :attr:`map_refined`: each sub-cell keeps
        its cell's sea fraction, as the renderer sees it), or None."""
        if self.glint is None:
            return None
        f = reflectivity_map.shape[0] // self.map.shape[0]
        sea = self.glint.sea if f == 1 else np.repeat(np.repeat(self.glint.sea, f, axis=0), f, axis=1)
        return SunGlint(self.glint.wind_m_s, self.glint.index, sea=sea, tau=self.glint.tau)

    @property
    def sun_angular_radius_rad(self):
        """Return the Sun's apparent angular radius for this run (0 for a point Sun): from the mean
        satellite-Sun distance (it changes by < 0.05 % in a day; 1.7 % over a year)."""
        if not self.opts.sun_disc:
            return 0.0
        dist = np.linalg.norm(self.geometry.sun_from_sat_gcrs_m, axis=1)
        return float(np.arcsin(R_SUN_M / np.nanmean(dist)))

    @functools.cached_property
    def _parts(self):
        """Return ``scenes.meshes.build_parts`` of the configuration (the renderer's mesh and the mounts rule)."""
        return build_parts(self.config)

    @property
    def renderer(self):
        if self._renderer is None:
            self._renderer = Renderer(
                DiodeSurfaces.from_config(self.config), build_satellite_mesh(self.config, self._parts),
                reflectivity=self.map.values_south_first, lon_west_deg=float(self.map.lon_edges_deg[0]),
                e_sun_w_m2=self.opts.e_sun_w_m2, sun_angular_radius_rad=self.sun_angular_radius_rad,
                variant=self.opts.variant, **self._renderer_glint())
        return self._renderer

    def _renderer_glint(self):
        """Return the renderer's glint keyword ({} without glint: the call as it always was); its sea south first."""
        if self.glint is None:
            return {}
        sea = self.glint.sea if self.map.south_first else self.glint.sea[::-1]
        return {"glint": SunGlint(self.glint.wind_m_s, self.glint.index, sea=sea, tau=self.glint.tau)}

    def earth_sun_dir_body(self, sl):
        """Return (n, 3) the unit Earth-centre -> Sun vector in body axes (what lights the Earth, as in the
        analytic model)."""
        g = self.geometry
        r = g.r_sun_ecef_m[sl]
        return np.einsum("nji,nj->ni", g.R_ecef_from_body[sl], r / np.linalg.norm(r, axis=1)[:, None])

    def earth_sun_scale(self, sl):
        """Return (n,) the factor on E_sun that lights the Earth: (1 AU / |r_sun|)^2 geocentric, or 1."""
        if not self.opts.distance_scaling:
            return np.ones(sl.stop - sl.start)
        return (AU_M / np.linalg.norm(self.geometry.r_sun_ecef_m[sl], axis=1)) ** 2

    def sun_scale(self, sl):
        g = self.geometry
        return g.sun_distance_scale[sl] if self.opts.distance_scaling else np.ones(sl.stop - sl.start)

    @functools.cached_property
    def _parts_scene(self):
        """Return the Mitsuba occluder scene of the configuration's extra parts ([[part]]) alone, or None."""
        if not self.config.parts:
            return None
        import trimesh
        self.renderer                                   # sets the Mitsuba variant
        mesh = trimesh.util.concatenate([trimesh.Trimesh(p.vertices_m, p.faces, process=False)
                                         for p in self.config.parts])
        return occluder_scene(mesh, _llvm.import_mitsuba())

    def _sun_disc_probes(self, sl):
        """Return (dirs (17, n, 3), s (n, 3), ok (n,), a): for the epochs of ``sl``, the unit body directions toward
        the Sun's centre and 16 points just outside its rim (at ``a``, its angular radius x 1.001, rad), the Sun's
        direction and which epochs are finite (the others get any direction, to be masked): the probes of the
        shadow rules below."""
        s = self.geometry.sun_dir_body[sl]
        ok = np.all(np.isfinite(s), axis=1)
        s = np.where(ok[:, None], s, [[0.0, 0.0, 1.0]])
        a = max(self.sun_angular_radius_rad, 1e-6) * 1.001
        ang = 2 * np.pi * np.arange(16) / 16
        offsets = np.vstack([[0.0, 0.0], a * np.column_stack([np.cos(ang), np.sin(ang)])])
        return disc_directions(s, offsets), s, ok, a

    def parts_shadow(self, sl):
        """Return (n, K) bool: the diode-epochs of ``sl`` whose direct Sun a part of the configuration other than
        the body box and the mounts ([[part]]: panels, antennas, user meshes) may block, which the analytic
        model does not know: a ray from any of 3 x 3 points over the diode toward the Sun's centre or 16 points
        on its rim meets such a part. The check leaves their direct Sun out (counted, with the reason)."""
        cfg = self.config
        n, K = sl.stop - sl.start, cfg.n_diodes
        if self._parts_scene is None:
            return np.zeros((n, K), bool)
        dirs, s, ok, a = self._sun_disc_probes(sl)
        dirs = np.swapaxes(dirs, 0, 1)                                                  # (n, 17, 3)
        f = np.linspace(-0.5, 0.5, 3)
        F = np.asarray(cfg.frames)
        sizes = np.array([[d.aperture.diode_x_m, d.aperture.diode_y_m] for d in cfg.diodes])
        U, V = sizes[:, :1] * F[:, 0], sizes[:, 1:] * F[:, 1]                           # (K, 3) each
        pts = (np.asarray(cfg.positions_m)[:, None, None] + f[None, :, None, None] * U[:, None, None]
               + f[None, None, :, None] * V[:, None, None]).reshape(K, 9, 3)
        # only pairs with part of the Sun in front of the diode can be lit, hence shaded
        e, k = np.nonzero((np.einsum("nj,kj->nk", s, F[:, 2]) > -a) & ok[:, None])
        out = np.zeros((n, K), bool)
        if e.size:
            o = np.broadcast_to(pts[k][:, :, None], (e.size, 9, 17, 3))
            d = np.broadcast_to(dirs[e][:, None], (e.size, 9, 17, 3))
            hit = rays_blocked(self._parts_scene, o.reshape(-1, 3), d.reshape(-1, 3), _llvm.import_mitsuba())
            out[e, k] = hit.reshape(e.size, 9 * 17).any(axis=1)
        return out

    @functools.cached_property
    def mount_shaded_directions(self):
        """Return (K, 90, 180) bool, or None where there is none: per diode, the cells of its direction grid
        (``Renderer.direction_grid``) in which another diode's mount (ramp, floor plate, well, plug) meets some of
        the probe rays of ``Renderer.blocked_share`` from the part of the diode its own well lights: a shadow the
        analytic direct model (the body box and the diode's own well) does not know. Widened by one cell all
        round, as :attr:`shaded_directions`. Only cells where the whole mesh blocks some probe are probed, each
        diode's against the others' mounts (its own well's walls, which its lit part's probes may graze at the
        horizon in float32, are the analytic model's)."""
        import trimesh
        if self.config.n_diodes < 2:
            return None
        where = np.nan_to_num(self.renderer.blocked_share(), nan=0.0) > 0    # (the renderer sets Mitsuba's variant)
        mi = _llvm.import_mitsuba()
        mounts = {name: m for name, m in self._parts.items() if name != "body" and not name.startswith("part_")}

        def hit(scene, where):
            return np.nan_to_num(self.renderer.probe_share(scene, where), nan=0.0) > 0
        # every mount first (one scene), then the diodes some probe met again without their own mount
        cell = hit(occluder_scene(trimesh.util.concatenate(list(mounts.values())), mi), where)
        for k in np.flatnonzero(cell.any(axis=(1, 2))):
            others = [m for name, m in mounts.items() if name.rsplit("_", 1)[1] != str(k)]
            only = np.zeros_like(cell)
            only[k] = cell[k]
            cell[k] = hit(occluder_scene(trimesh.util.concatenate(others), mi), only)[k]
        return widen_cells(cell) if cell.any() else None

    def mounts_shadow(self, sl):
        """Return (n, K) bool: the diode-epochs of ``sl`` whose direct Sun another diode's mount may block, which the
        analytic model does not know: the Sun's centre or one of 16 points on its rim lies in a cell of
        :attr:`mount_shaded_directions`. The check leaves their direct Sun out (counted, with the reason)."""
        cfg = self.config
        n, K = sl.stop - sl.start, cfg.n_diodes
        cells = self.mount_shaded_directions
        if cells is None:
            return np.zeros((n, K), bool)
        dirs, _, ok, _ = self._sun_disc_probes(sl)
        out = np.zeros((n, K), bool)
        for k, frame in enumerate(np.asarray(cfg.frames)):
            if not cells[k].any():
                continue
            local = dirs @ frame.T                                                      # (17, n, 3): u, v, n
            i, j = Renderer.direction_cell(local)
            out[:, k] = ((local[..., 2] > 0) & cells[k][i, j]).any(axis=0) & ok
        return out

    def round_well_shadow(self, sl):
        """Return (n, K) bool: the diode-epochs of ``sl`` of round wells (``CircularWell``) whose direct Sun the
        body box may shade: part of the solar disc at or below the plane of the diode's panel and part of it in
        front of the diode. The analytic model clips the box's shadow against a rectangular lit part only
        (simcore.shapes.occlusion), so the check leaves these out (counted, with the reason). Above the
        panel's plane no ray from the diode, which sits above the panel, can meet the box: the model is exact; a
        diode flat on its panel sees nothing below that plane."""
        g, cfg = self.geometry, self.config
        out = np.zeros((sl.stop - sl.start, cfg.n_diodes), bool)
        a = max(self.sun_angular_radius_rad, 1e-6) * 1.001
        s = g.sun_dir_body[sl]
        for k, d in enumerate(cfg.diodes):
            if not isinstance(d.aperture, CircularWell) or cfg.body.none:     # no body: the model is exact
                continue
            p = body_side_normal(d, cfg.body)       # its panel's normal (a diode on a part: the box face it lies beyond)
            # (a diode flat on its panel sees nothing below the panel's plane: never)
            if d.normal_body @ p < 1.0 - 1e-9:
                with np.errstate(invalid="ignore"):
                    out[:, k] = (s @ p < np.sin(a)) & (s @ d.normal_body > -np.sin(a))
        return out

    @functools.cached_property
    def visibility(self):
        """Return the ``DirectionVisibility`` of the check's albedo reference: in the cells of
        :attr:`shaded_directions`, the visible share of each diode traced against the mesh on a 0.25 x 0.5
        deg grid (and a 0.5 x 1 deg one for the quadrature's error), ``Renderer.visible_share``."""
        fine, half = self.renderer.visible_share(self.shaded_directions)
        return DirectionVisibility(self.shaded_directions, fine, half)

    @functools.cached_property
    def shaded_directions(self):
        """Return (K, 90, 180) bool: per diode, the directions of its 1 x 2 deg grid
        (``Renderer.direction_grid``) where the analytic model's picture of what shades the diode is not
        the mesh's: the traced probes of ``Renderer.blocked_share`` are not all what the body box at the
        diode's centre says (all blocked or all free), i.e. a shadow edge of the body crosses the diode or
        another part (rails, other diodes' mounts) shades it. Widened by one cell all round, so that an
        edge that passes between the cells' centres still marks the cells it crosses."""
        share = self.renderer.blocked_share()
        th, ph = self.renderer.direction_grid()
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        local = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1)
        box = BodyBox.from_config(self.config)
        out = np.zeros(share.shape, bool)
        for k, frame in enumerate(np.asarray(self.config.frames)):
            model = np.zeros(TH.shape) if box is None else box_hit(box.positions_m[k], local @ frame, box.half_m) * 1.0
            cell = np.isfinite(share[k]) & (share[k] != model)
            out[k] = widen_cells(cell)
        return out

    def analytic(self, sl, reflectivity_map, direct=True, mesh=False, albedo=True, box_albedo=False):
        """Return the analytic irradiance of epochs ``sl`` on ``reflectivity_map``; ``mesh``: the albedo with
        the traced :attr:`visibility` where shadows cross the diodes (the check's reference). The direct Sun
        alone (``albedo=False``) is numpy and the body box's shadow kernel (traced, never frozen): it may run in
        another thread while the renderer records and replays its frozen kernels (Dr.Jit records per thread)."""
        g = self.geometry
        out = diode_irradiance(g.r_sat_ecef_m[sl], g.r_sun_ecef_m[sl], g.R_ecef_from_body[sl],
                               self.config.frames, self.config.apertures, map=reflectivity_map,
                               e_sun_w_m2=self.opts.e_sun_w_m2, distance_scaling=self.opts.distance_scaling,
                               eclipse="conical" if self.opts.sun_disc else "cylindrical",
                               body=BodyBox.from_config(self.config),
                               sun_angular_radius_rad=self.sun_angular_radius_rad, direct=direct,
                               albedo=albedo, backend="auto" if albedo else "numpy",
                               visibility=self.visibility if mesh else None, box_albedo=box_albedo,
                               glint=self.glint_on(reflectivity_map))
        if any(w is not None for w in self.config.windows):
            self._windowed_analytic(out, sl, reflectivity_map, direct, mesh, albedo, box_albedo)
        return out

    def _windowed_analytic(self, res, sl, reflectivity_map, direct, mesh, albedo=True, box_albedo=False):
        """Replace in ``res`` (the analytic result of epochs ``sl``) the columns of the diodes under a window by
        the model with the window: each integrand times the slab's closed-form transmittance with its
        footprint (:class:`simcore.shapes.window.WindowedWell`). The direct Sun without the body box (where the
        box may shade such a diode, :meth:`window_shadow` leaves it out of the check), numpy only (it may run
        beside the renderer in the worker thread); the albedo with the box at the diode's centre, as for the
        other diodes, in the Dr.Jit kernel (``WindowedWell.kernel``)."""
        cfg, g = self.config, self.geometry
        idx = [k for k, w in enumerate(cfg.windows) if w is not None]
        resps = [WindowedWell(cfg.diodes[k].aperture, cfg.diodes[k].window) for k in idx]
        frames = np.asarray(cfg.frames)[idx]
        box = BodyBox.from_config(cfg)
        common = dict(map=reflectivity_map, e_sun_w_m2=self.opts.e_sun_w_m2,
                      distance_scaling=self.opts.distance_scaling,
                      eclipse="conical" if self.opts.sun_disc else "cylindrical",
                      sun_angular_radius_rad=self.sun_angular_radius_rad)
        args = (g.r_sat_ecef_m[sl], g.r_sun_ecef_m[sl], g.R_ecef_from_body[sl], frames, resps)
        if direct:
            res.direct_w_m2[:, idx] = diode_irradiance(*args, albedo=False, backend="numpy", **common).direct_w_m2
        if not albedo:
            return
        vis = None
        if mesh:
            v = self.visibility
            vis = DirectionVisibility(v.mask[idx], v.fine[idx], v.half[idx])
        alb = diode_irradiance(*args, direct=False, visibility=vis, **common, box_albedo=box_albedo,
                               body=box and BodyBox(box.half_m, box.positions_m[idx], box.panel_normals[idx]),
                               glint=self.glint_on(reflectivity_map))
        res.albedo_w_m2[:, idx] = alb.albedo_w_m2
        for name in ("albedo_mesh_w_m2", "albedo_visibility_error_w_m2", "albedo_box_w_m2"):
            if getattr(res, name) is not None:
                getattr(res, name)[:, idx] = getattr(alb, name)

    def direct_unchecked(self, sl):
        """Return ((n, K) bool, (n, K) bool): the diode-epochs of ``sl`` whose direct Sun the check leaves out
        (a part, another diode's mount, a window under the body's shadow or a round well under it may shade it: no
        exact reference), and those of them that are a window's."""
        window = self.window_shadow(sl)
        return self.parts_shadow(sl) | self.mounts_shadow(sl) | window | self.round_well_shadow(sl), window

    def window_shadow(self, sl):
        """Return (n, K) bool: the diode-epochs of ``sl`` with a window over the diode whose direct Sun the body box
        may shade: part of the solar disc (its centre or 16 rim points) lies in front of the diode and below its
        panel's plane. There the light leaves the window shifted along its path, which moves the box's shadow:
        the analytic model has no exact reference, and the check leaves that direct value out (counted)."""
        cfg = self.config
        n, K = sl.stop - sl.start, cfg.n_diodes
        out = np.zeros((n, K), bool)
        idx = [k for k, w in enumerate(cfg.windows) if w is not None]
        if not idx or cfg.body.none:            # no body ([body] none): nothing shades a window
            return out
        dirs, _, ok, _ = self._sun_disc_probes(sl)
        box = BodyBox.from_config(cfg)
        for k in idx:
            front = dirs @ cfg.diodes[k].normal_body > 0
            below = dirs @ box.panel_normals[k] < 0
            out[:, k] = (front & below).any(axis=0) & ok
        return out

    @functools.cached_property
    def worker(self):
        """Return the one worker thread that computes the direct reference (numpy, which releases the GIL
        in its loops, and the body box's shadow as a traced Dr.Jit kernel) and writes finished chunks while the
        main thread renders: on few cores it fills the core that the renderer's Python parts leave idle. It
        freezes nothing (a frozen function records in its own thread; see tests/test_render_freeze.py, the second
        thread's test); its Dr.Jit kernel runs between frozen calls (:data:`simcore._llvm.FROZEN_CALLS`)."""
        return concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="sunsim-worker")

    def render_chunk(self, start, stop):
        """Return the arrays of epochs [start, stop): rendered and analytic irradiance, and the check's
        second, hint-free direct estimate on its share of the epochs (NaN elsewhere)."""
        o, g, sl = self.opts, self.geometry, slice(start, stop)
        valid = g.valid[sl]
        direct_ref = self.worker.submit(self.analytic, sl, self.map, albedo=False)
        args = (g.sun_dir_body[sl], g.earth_center_body_m[sl], g.R_ecef_from_body[sl], self.sun_scale(sl))
        res = self.renderer.render(
            *args, sun_dir_earth_body=self.earth_sun_dir_body(sl), earth_sun_scale=self.earth_sun_scale(sl),
            seed=o.seed, epoch_offset=start, direct_samples=o.direct_samples, albedo_samples=o.albedo_samples,
            rel_se_direct=o.rel_se_direct, rel_se_albedo=o.rel_se_albedo, reflected_samples=o.reflected_samples,
            progress=None)
        plain = np.full((stop - start, len(self.config.diodes), 3), np.nan)
        pick = np.flatnonzero(plain_check_epochs(o.seed, len(self.epochs))[sl])
        if len(pick):
            sub = self.renderer.render(*(a[pick] for a in args), seed=o.seed, epoch_index=start + pick,
                                       albedo=False, hint=False, reflected=False,
                                       direct_samples=max(o.direct_samples, PLAIN_CHECK_SAMPLES))
            plain[pick] = np.stack([sub.direct_w_m2, sub.direct_se_w_m2, sub.direct_dof], axis=-1)
        native = self.analytic(sl, self.map, direct=False, mesh=True, box_albedo=True)  # box-only and traced shares
        native_albedo, native_mesh = native.albedo_box_w_m2, native.albedo_w_m2
        fine = self.analytic(sl, self.map_refined, direct=False, mesh=True)
        native_direct = direct_ref.result().direct_w_m2
        unchecked, window_shadow = self.direct_unchecked(sl)
        out = {
            "rendered": np.stack([res.direct_w_m2, res.albedo_w_m2, res.reflected_w_m2], axis=-1),
            "rendered_se": np.stack([res.direct_se_w_m2, res.albedo_se_w_m2, res.reflected_se_w_m2], axis=-1),
            "rendered_dof": np.stack([res.direct_dof, res.albedo_dof, res.reflected_dof], axis=-1),
            "samples": np.stack([res.direct_samples, res.albedo_samples, res.reflected_samples],
                                axis=-1).astype(np.int64),
            "direct_plain": plain,
            "analytic": np.stack([native_direct, native_albedo], axis=-1),
            "analytic_albedo_refined": fine.albedo_w_m2,
            "analytic_albedo_native_mesh": native_mesh,
            "albedo_mesh": fine.albedo_mesh_w_m2,
            "albedo_visibility_error": fine.albedo_visibility_error_w_m2,
            "direct_unchecked": unchecked,
            "direct_unchecked_window": window_shadow,
            "valid": valid & res.valid,
        }
        return out


# The arrays of a finished chunk (PreparedRun.render_chunk); a partial run whose chunks lack one was written
# by an older sunsim and cannot be resumed by this one
CHUNK_ARRAYS = ("rendered", "rendered_se", "rendered_dof", "samples", "direct_plain", "analytic",
                "analytic_albedo_refined", "analytic_albedo_native_mesh", "albedo_mesh", "albedo_visibility_error",
                "direct_unchecked", "direct_unchecked_window", "valid")

PLAIN_CHECK_SHARE = 0.125     # share of the epochs whose direct Sun is rendered again without the aperture hint
# ...with at least this many samples: with 64, a well's edge crosses a handful of strata and the hint-free
# estimate's standard error is unreliable (a 4-epoch run read 22 sigma off with seed 7)
PLAIN_CHECK_SAMPLES = 1024


def plain_check_epochs(seed, n):
    """Return (n,) bool: the epochs of a run whose direct Sun the check renders a second time without the
    analytic aperture hint (a random share PLAIN_CHECK_SHARE, fixed by the seed, so a resumed run picks the
    same ones)."""
    return np.random.default_rng([int(seed), 0x9E3779B9]).random(n) < PLAIN_CHECK_SHARE


def _tle_age_days(study):
    """Return the days from the TLE epoch to the run's first epoch (negative: before the epoch; NaN without a TLE)."""
    if not hasattr(study.orbit, "satrec"):
        return float("nan")
    sat = study.orbit.satrec
    return (study.epochs.jd1[0] - sat.jdsatepoch) + (study.epochs.jd2[0] - sat.jdsatepochF)


def _with_reflected(data):
    """Return the chunk arrays with a third, ``reflected`` component (zeros, exact) where they have only direct
    and albedo (run files written before the renderer traced reflections: all surfaces black)."""
    if data["rendered"].shape[-1] == 3:
        return data
    out = dict(data)
    for key, fill in (("rendered", 0.0), ("rendered_se", 0.0), ("rendered_dof", np.inf), ("samples", 0)):
        a = np.asarray(data[key])
        out[key] = np.concatenate([a, np.full(a.shape[:-1] + (1,), fill, dtype=a.dtype)], axis=-1)
    return out


def build_dataset(study, data, variant):
    """Return the run's xarray Dataset from the concatenated chunk arrays."""
    o, g, cfg = study.opts, study.geometry, study.config
    n, k = data["rendered"].shape[:2]
    data = _with_reflected(data)
    # Richardson: the same integrand (the traced visible shares where shadows cross the diodes) on the native
    # and the refined cells; the model's box-only albedo would fold the shares' effect into the estimate
    bound = _check.discretisation_bound(data["analytic_albedo_native_mesh"], data["analytic_albedo_refined"],
                                        study.check_refine)
    # the analytic model's surfaces are black: it reflects nothing; the check has no reference for it (NaN)
    analytic = np.concatenate([data["analytic"][..., :2], np.zeros((n, k, 1))], axis=-1)
    analytic_ref = np.stack([analytic[..., 0], data["analytic_albedo_refined"], np.full((n, k), np.nan)], axis=-1)
    names = [d.name for d in cfg.diodes]
    W = "W m-2"
    coords = {
        "time": ("time", g.epochs.datetime64, {"long_name": "epoch, UTC", "standard_name": "time",
                                               "time_zone": "UTC"}),
        "t_s": ("time", g.t_s, {"units": "s", "long_name": "seconds since the first epoch"}),
        "diode": ("diode", np.arange(k), {"units": "1", "long_name": "diode index"}),
        "diode_name": ("diode", np.array(names, dtype=object), {"long_name": "diode name in the configuration"}),
        "component": ("component", np.array(["direct", "albedo", "reflected"], dtype=object),
                      {"long_name": "irradiance component: direct Sun, Earth albedo, or Sun and Earth light "
                                    "reflected by the spacecraft (the total is their sum; reflected is not "
                                    "checked against the analytic model)"}),
        "xyz": ("xyz", np.array(["x", "y", "z"], dtype=object), {"long_name": "Cartesian axis"}),
        "statistic": ("statistic", np.array(["value", "se", "dof"], dtype=object),
                      {"long_name": "estimate, its standard error, their effective degrees of freedom"}),
        "quat": ("quat", np.array(["w", "x", "y", "z"], dtype=object),
                 {"long_name": "quaternion component, scalar first"}),
    }
    ds = xr.Dataset(
        {
            "irradiance": (("time", "diode", "component"), data["rendered"],
                           {"units": W, "long_name": "rendered irradiance on the diode's sensitive area"}),
            "irradiance_se": (("time", "diode", "component"), data["rendered_se"],
                              {"units": W, "long_name": "Monte-Carlo standard error of irradiance"}),
            "irradiance_dof": (("time", "diode", "component"), data["rendered_dof"],
                               {"units": "1", "long_name": "effective degrees of freedom of irradiance_se "
                                                          "(Satterthwaite; inf where the value is exact)"}),
            "direct_plain": (("time", "diode", "statistic"), data["direct_plain"],
                             {"units": W, "long_name": "the check's second direct-Sun estimate, rendered without the "
                                                       "analytic aperture hint on a random share of the epochs "
                                                       "(NaN elsewhere): value, standard error, degrees of freedom"}),
            "samples": (("time", "diode", "component"), data["samples"], {"units": "1", "long_name": "rays traced"}),
            "analytic": (("time", "diode", "component"), analytic,
                         {"units": W, "long_name": "analytic model: aperture overlap response (direct), "
                                                   "Bhanderi cell sum on the native map (albedo)"}),
            "analytic_reference": (("time", "diode", "component"), analytic_ref,
                                   {"units": W, "long_name": f"analytic reference of the check (albedo on the map "
                                                             f"refined {study.check_refine}x{study.check_refine})"}),
            "albedo_discretisation_bound": (("time", "diode"), bound,
                                            {"units": W, "long_name": "estimated cell-discretisation error of "
                                                                      "the refined analytic albedo"}),
            "albedo_mesh": (("time", "diode"), data["albedo_mesh"],
                            {"units": W, "long_name": "albedo of the check's reference arriving through directions "
                                                     "where shadows of the body or other parts cross the diode "
                                                     "(before their shadow; there the reference takes the visible "
                                                     "share traced against the mesh)"}),
            "albedo_visibility_error": (("time", "diode"), data["albedo_visibility_error"],
                                        {"units": W, "long_name": "estimated error of the reference's traced "
                                                                  "visible share (its grid made twice as coarse)"}),
            "direct_unchecked": (("time", "diode"), np.asarray(data["direct_unchecked"], np.int8),
                                 {"units": "1", "long_name": "1 where a part the analytic model does not know "
                                                             "([[part]]: panels, antennas, user meshes; another "
                                                             "diode's mount) may block the direct Sun: the check "
                                                             "leaves that direct value out"}),
            "direct_unchecked_window": (("time", "diode"), np.asarray(data["direct_unchecked_window"], np.int8),
                                        {"units": "1", "long_name": "1 where a diode under a window may be shaded "
                                                                    "by the body (its light leaves the window "
                                                                    "shifted): also in direct_unchecked"}),
            "sun_dir_body": (("time", "xyz"), g.sun_dir_body, {"units": "1", "long_name": "unit satellite->Sun vector",
                                                                 "frame": "body"}),
            "sun_scale": ("time", study.sun_scale(slice(0, n)),
                          {"units": "1", "long_name": "factor on the solar constant (1, or (1 AU / r)^2 with distance scaling)"}),
            "sun_dir_gcrs": (("time", "xyz"), g.sun_dir_gcrs, {"units": "1", "long_name": "unit satellite->Sun vector",
                                                               "frame": "GCRS"}),
            "r_sat_gcrs": (("time", "xyz"), g.r_sat_gcrs_m, {"units": "m", "long_name": "satellite position", "frame": "GCRS"}),
            "r_sat_ecef": (("time", "xyz"), g.r_sat_ecef_m, {"units": "m", "long_name": "satellite position", "frame": "ITRS"}),
            "illumination": ("time", g.illumination,
                             {"units": "1", "long_name": "visible fraction of the solar disc (conical Earth shadow)"}),
            "sunlit_cylindrical": ("time", g.sunlit_cylindrical.astype(np.int8),
                                   {"units": "1", "long_name": "1 where sunlit under the thesis' cylindrical shadow "
                                                               "(eqs. 4.6-4.10)"}),
            "q_gcrs_from_body": (("time", "quat"), study.attitude.q_gcrs_from_body,
                                 {"units": "1", "long_name": "attitude quaternion, scalar first, rotates body "
                                                             "vectors into GCRS"}),
            "valid": ("time", data["valid"].astype(np.int8),
                      {"units": "1", "long_name": "1 where the orbit and the rendering are valid"}),
            "normal_body": (("diode", "xyz"), cfg.normals, {"units": "1", "long_name": "diode normal",
                                                           "frame": "body"}),
            "fov_deg": ("diode", cfg.fov_deg, {"units": "deg", "long_name": "design field of view (eq. 4.15)"}),
            "dead": ("diode", cfg.dead.astype(np.int8), {"units": "1", "long_name": "1 for a dead diode"}),
        },
        coords=coords,
    )
    ds = _schedule.annotate(ds, study, n)
    tle = f"{study.orbit.line1}\n{study.orbit.line2}" if hasattr(study.orbit, "line1") else ""
    cfg_text = Path(cfg.source).read_text() if cfg.source and os.path.isfile(cfg.source) else ""
    ds.attrs.update({
        "title": "sunsim diode irradiance run",
        "conventions": "time leads; frames named in each variable; SI units",
        "configuration": cfg.name,
        "configuration_toml": cfg_text,
        "satellite": study.orbit.name or "",
        "norad_id": -1 if study.orbit.norad_id is None else int(study.orbit.norad_id),
        "tle": tle,
        "orbit_source": "TLE" if tle else f"CCSDS OEM {o.orbit_file} (sha256 {study.orbit.sha256})",
        "reflectivity_map": study.map.name,
        "seed": int(o.seed),
        "reflected_samples": int(o.reflected_samples),
        "variant": variant,
        "options": json.dumps(o.spec(), sort_keys=True),
        "software": json.dumps(_versions(), sort_keys=True),
        "e_sun_w_m2": study.opts.e_sun_w_m2,
        "period_s": float(orbital_period_s(study.orbit)),
        "tle_age_days": float(_tle_age_days(study)),
        "warnings": "\n".join(getattr(study, "notes", [])),
        "time_scale": "UTC",
        "created_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command_line": shlex.join([os.path.basename(sys.argv[0]) or "python"] + sys.argv[1:]),
        "sunsim_version": __version__ + (f" (git {_git_commit()})" if _git_commit() else ""),
    })
    if study.clouds is not None:
        ds.attrs.update(study.clouds.attrs(o.clouds))
    if study.glint is not None:
        ds.attrs.update(study.glint.attrs())
    flags, report = check_run(ds)
    ds["outlier"] = (("time", "diode", "component"), np.stack([flags["direct"], flags["albedo"],
                                                                     np.zeros_like(flags["direct"])],
                                                                    axis=-1).astype(np.int8),
                     {"units": "1", "long_name": "1 where the check's normal score |z| > 4 (or an exact value is off); "
                                                "reflected is not checked (always 0)"})
    ds.attrs["check"] = json.dumps(report, sort_keys=True)
    ds.attrs["check_pass"] = int(report["pass"])
    return ds, report


DEFAULT_FOLDER = "runs"


def default_output(opts, folder=DEFAULT_FOLDER):
    """Return the output path of a run given no ``output``: ``folder/default.nc`` or ``default-N.nc``.

    The first of these that already holds this run (a finished file or a partial folder with identical
    settings) is reused, so the same command repeats and resumes; otherwise the first free name, so a
    run with other settings never collides with an earlier one.
    """
    digest = spec_digest(opts.spec())
    for i in range(1, 10000):
        path = os.path.join(folder, "default.nc" if i == 1 else f"default-{i}.nc")
        partial = ChunkStore(path, {}).folder
        if os.path.exists(path):
            if _options_digest(path) == digest:
                return path
            continue
        if os.path.isdir(partial):
            if ChunkStore.stored_digest(path) in (digest, None):
                return path
            continue
        return path
    raise OutputError(f"{folder} holds 9999 default runs; give --output")


def _options_digest(path):
    """Return the settings digest of a finished run file, or None if it is not a readable run file."""
    import h5py
    try:
        with h5py.File(path, "r") as f:         # the attributes only: a day's run file holds ~1 GB of arrays
            options = f.attrs.get("options")
    except OSError:
        return None
    if options is None:
        return None
    return spec_digest(json.loads(options.decode() if isinstance(options, bytes) else str(options)))


def prepare(opts):
    """Return a ready :class:`simcore.pipeline.run.PreparedRun` of ``opts`` after every check of its inputs; raise a
    UserError (nothing written) for the first that fails. ``study.notes`` holds the warnings."""
    check_numbers(opts)
    variant = check_variant(opts.variant)
    study = PreparedRun(opts)
    check_map(study.map, getattr(opts, "allow_bright_map", False))
    if study.config.dead.all():
        raise InvalidInputError(f"all {study.config.n_diodes} diodes of {study.config.name} are dead (--dead "
                                f"{' '.join(map(str, np.flatnonzero(study.config.dead)))}); leave at least one alive")
    study.variant = variant
    notes = [tle_age_note(study.orbit, study.epochs), reflected_ignored_note(opts.reflected_samples, study.config)]
    check_run_resources(opts, len(study.epochs), study.config.n_diodes, reflected_traced=notes[1] is None)
    if opts.attitude_file and _schedule.relative_times_csv(opts.attitude_file):
        notes.append(attitude_times_note(_attitude.Attitude.from_file(opts.attitude_file).t_s, opts.attitude_file))
    study.notes = [n for n in notes if n] + list(study.plan.notes) + list(study.config.notes)
    return study


def execute(opts, *, progress=None, log=None):
    """Run (or resume) a study; return (output path, Dataset, check report).

    Every input is checked first (:func:`prepare`): a rejected run writes nothing. An
    output file made with identical settings is returned as it is (nothing rendered); one made with other
    settings is replaced only with ``opts.overwrite``.
    """
    log = log or (lambda msg: None)
    study = prepare(opts)
    for note in study.notes:
        log(f"warning: {note}")
    if opts.output is None:
        os.makedirs(DEFAULT_FOLDER, exist_ok=True)
        opts = dataclasses.replace(opts, output=default_output(opts))
        study.opts = opts
    check_writable(opts.output)
    finished = _finished(opts, log)
    if finished is not None:
        return finished
    store = ChunkStore(opts.output, opts.spec(), writer=_writer(study)).open()
    try:
        # Another process may have finished this output while we waited for its lock.
        finished = _finished(opts, log)
        if finished is not None:
            store.close()
            if not store.done():
                store.remove()
            return finished
        return _render_and_write(study, store, progress, log)
    finally:
        store.close()


def _finished(opts, log):
    """Return (path, ds, report) of an existing output with identical settings; None if there is none;
    raise if one with other settings stands there (without ``overwrite``)."""
    if not os.path.exists(opts.output):
        return None
    same = _options_digest(opts.output) == spec_digest(opts.spec())
    if same:
        log(f"{opts.output} is already finished with identical settings: nothing to render")
        ds = open_run(opts.output)
        return opts.output, ds, json.loads(ds.attrs["check"])
    if not opts.overwrite:
        raise OutputError(f"{opts.output} exists and was made with other settings; add --overwrite to replace "
                          "it, or choose another --output")
    return None


def _render_and_write(study, store, progress, log):
    opts = study.opts
    n = len(study.epochs)
    done = store.done()
    if done:
        missing = sorted(set(CHUNK_ARRAYS) - store.chunk_keys(*done[0]))
        if missing:
            raise InvalidInputError(f"{store.folder} holds a partial run written by an older sunsim (its chunks lack "
                                    f"{', '.join(missing)}); delete that folder to start this run afresh")
    todo = missing_ranges(n, opts.chunk_epochs, done)
    if done:
        log(f"resuming: {sum(b - a for a, b in done)} of {n} epochs already in {store.folder}")
    from tqdm import tqdm
    bar = tqdm(total=n, initial=sum(b - a for a, b in done), unit="epoch",
               disable=(not sys.stderr.isatty()) if progress is None else not progress, desc="rendering")
    try:
        return _write_chunks_and_file(study, store, todo, bar, n)
    except OSError as exc:
        if is_disk_full(exc, store.folder):
            covered = sum(b - a for a, b in store.done()) == n
            raise store.disk_full(exc, "writing the final file" if covered else "writing a chunk", n) from None
        raise


def _write_chunks_and_file(study, store, todo, bar, n):
    """Render and store the chunks ``todo``, then write the run file from all of them; return (path, ds, report)."""
    opts = study.opts
    pending = None          # the chunk being written by the worker thread while the next one renders
    try:
        for start, stop in todo:
            data = study.render_chunk(start, stop)
            if pending is not None:
                pending.result()
            pending = study.worker.submit(store.save, start, stop, data)
            bar.update(stop - start)
    finally:
        if pending is not None:
            concurrent.futures.wait([pending])     # a finished chunk is on disk before anything else happens
        bar.close()
    if pending is not None:
        pending.result()
    data = store.load_all(n)
    variant = study._renderer.variant if study._renderer is not None else study.variant
    ds, report = build_dataset(study, data, variant)

    def write(tmp):
        add_checksums(ds).to_netcdf(tmp, engine="h5netcdf")
    check_room(store.folder, size_bound(ds))
    # The temporary file lies in the partial folder: a crash here leaves it where the resume cleans up.
    atomic_write(opts.output, write, tmp_dir=store.folder)
    store.remove()
    return opts.output, ds, report


REQUIRED_VARIABLES = ("irradiance", "irradiance_se", "analytic", "analytic_reference", "albedo_discretisation_bound",
                      "sun_dir_body", "sun_scale", "normal_body", "dead", "illumination", "q_gcrs_from_body", "valid")


def open_run(path, note=None):
    """Return the Dataset of a finished run file, or raise a UserError saying why not (note: verify_checksums's)."""
    if not os.path.exists(path):
        raise InputNotFoundError(f"no run file at {path}")
    if os.path.isdir(path):
        raise InvalidInputError(f"{path} is a folder, not a run file (.nc); a folder ending in .partial is an "
                         "unfinished run: finish it by running the same 'sunsim run' command again")
    try:
        ds = xr.load_dataset(path, engine="h5netcdf")      # in memory, file closed
    except Exception as exc:  # h5py/netCDF raise many types for a corrupt file
        raise InvalidInputError(f"{path} is not a readable netCDF run file ({type(exc).__name__}: {exc}); "
                         "was it written by 'sunsim run'?") from None
    missing = [v for v in REQUIRED_VARIABLES if v not in ds]
    if ds.attrs.get("title") != "sunsim diode irradiance run" or missing:
        raise InvalidInputError(f"{path} is not a sunsim run file (missing {', '.join(missing) or 'its sunsim title'}); "
                         "give a file written by 'sunsim run'")
    return verify_checksums(ds, path, note)


def check_run(ds):
    """Return (flags, report): the analytic check (:mod:`simcore.pipeline.check`) recomputed from a run
    Dataset's arrays."""
    n, k = ds.sizes["time"], ds.sizes["diode"]
    cos_inc = np.clip(np.einsum("nj,kj->nk", ds["sun_dir_body"].values, ds["normal_body"].values), 0.0, None)
    scale = float(ds.attrs.get("e_sun_w_m2", E_SUN_W_M2)) * ds["sun_scale"].values[:, None]
    irr, se, ref = ds["irradiance"].values, ds["irradiance_se"].values, ds["analytic_reference"].values
    dof = ds["irradiance_dof"].values if "irradiance_dof" in ds else np.full(irr.shape, np.inf)
    valid = np.broadcast_to(ds["valid"].values.astype(bool)[:, None], (n, k))
    masked = lambda a: np.where(valid, a, np.nan)  # noqa: E731
    # the direct Sun where extra parts may shadow it: no analytic reference (reported as unchecked)
    parts = ds["direct_unchecked"].values.astype(bool) if "direct_unchecked" in ds else np.zeros((n, k), bool)
    masked_direct = lambda a: np.where(valid & ~parts, a, np.nan)  # noqa: E731
    bound = ds["albedo_discretisation_bound"].values
    samples = ds["samples"].values
    components = {
        "direct": (masked_direct(irr[..., 0]), se[..., 0], dof[..., 0], samples[..., 0], ref[..., 0], 0.0),
        "albedo": (masked(irr[..., 1]), se[..., 1], dof[..., 1], samples[..., 1], ref[..., 1], bound ** 2),
    }
    if "albedo_visibility_error" in ds:
        components["albedo"] = components["albedo"][:5] + (bound ** 2 + ds["albedo_visibility_error"].values ** 2,)
    if "direct_plain" in ds:
        plain = ds["direct_plain"].values
        # the hint-free estimate always takes the run's first-round count (no target accuracy)
        n_plain = max(json.loads(ds.attrs["options"]).get("direct_samples", 1024), PLAIN_CHECK_SAMPLES)
        components["direct_plain"] = (masked_direct(plain[..., 0]), plain[..., 1], plain[..., 2],
                                      np.where(samples[..., 0] > 0, n_plain, 0), ref[..., 0], 0.0)
    flags, report = _check.compare(components, k, scale, scale * cos_inc)
    if ds.sizes["component"] > 2:
        refl = masked(irr[..., 2])
        report["reflected_unchecked"] = int(np.count_nonzero(refl > 0))
    report["direct_unchecked"] = int(np.count_nonzero(parts & valid))
    if "direct_unchecked_window" in ds:
        report["direct_unchecked_window"] = int(np.count_nonzero(ds["direct_unchecked_window"].values.astype(bool)
                                                                 & valid))
    if "albedo_mesh" in ds:
        report["albedo_mesh_quadrature"] = int(np.count_nonzero((ds["albedo_mesh"].values > 0)
                                                                & (ref[..., 1] > _check.ALBEDO_FLOOR_W_M2) & valid))
    # In the Earth's shadow every value is 0 and agrees trivially: a span without Sun has checked nothing.
    report["sunlit_epochs"] = int(np.count_nonzero(ds["valid"].values.astype(bool) & (ds["illumination"].values > 0)))
    if report["sunlit_epochs"] == 0:
        report["pass"] = False
        report["verdict"] = "no sunlit data"
    else:
        report["verdict"] = "PASS" if report["pass"] else "FAIL"
    return flags, report


def options_of(ds, path):
    """Return the RunOptions a run file was made with (from its 'options' attribute)."""
    spec = json.loads(ds.attrs["options"])
    names = {f.name for f in dataclasses.fields(RunOptions)}
    kw = _schedule.explicit_options({k: v for k, v in spec.items() if k in names}, ds)
    for k in ("dead", "spin_axis"):
        if k in kw:
            kw[k] = tuple(kw[k])
    # files written before the solar flux was an option used the thesis' constant 1366.1 W/m^2
    kw.setdefault("e_sun_w_m2", E_SUN_W_M2)
    kw.setdefault("distance_scaling", False)
    return RunOptions(**kw, output=path)


def recompute_analytic(path, *, chunk=4096, log=None):
    """Recompute a run file's analytic model and check with this version of sunsim (the rendered numbers
    are kept); rewrite the file atomically and return the new check report."""
    ds = open_run(path)
    study = PreparedRun(options_of(ds, path))
    n = len(study.epochs)
    if n != ds.sizes["time"]:
        raise ValueError(f"{path}: its options give {n} epochs but it holds {ds.sizes['time']}; "
                         "it was not made by this command's options")
    native = np.zeros(ds["analytic"].shape[:2] + (2,))
    fine, native_mesh = np.zeros(ds["analytic"].shape[:2]), np.zeros(ds["analytic"].shape[:2])
    mesh, mesh_err = np.zeros(ds["analytic"].shape[:2]), np.zeros(ds["analytic"].shape[:2])
    unchecked, unchecked_window = np.zeros(mesh.shape, bool), np.zeros(mesh.shape, bool)
    for s, e in chunk_ranges(n, chunk):
        unchecked[s:e], unchecked_window[s:e] = study.direct_unchecked(slice(s, e))
        a = study.analytic(slice(s, e), study.map, mesh=True, box_albedo=True)
        native[s:e, :, 0], native[s:e, :, 1], native_mesh[s:e] = a.direct_w_m2, a.albedo_box_w_m2, a.albedo_w_m2
        a = study.analytic(slice(s, e), study.map_refined, direct=False, mesh=True)
        fine[s:e], mesh[s:e], mesh_err[s:e] = a.albedo_w_m2, a.albedo_mesh_w_m2, a.albedo_visibility_error_w_m2
        if log:
            log(f"analytic {e}/{n}")
    data = {"rendered": ds["irradiance"].values, "rendered_se": ds["irradiance_se"].values,
            "rendered_dof": (ds["irradiance_dof"].values if "irradiance_dof" in ds
                             else np.full(ds["irradiance"].shape, np.inf)),
            "direct_plain": (ds["direct_plain"].values if "direct_plain" in ds
                             else np.full((ds.sizes["time"], ds.sizes["diode"], 3), np.nan)),
            "samples": ds["samples"].values, "analytic": native, "analytic_albedo_refined": fine,
            "analytic_albedo_native_mesh": native_mesh, "albedo_mesh": mesh, "albedo_visibility_error": mesh_err,
            "direct_unchecked": unchecked, "direct_unchecked_window": unchecked_window,
            "valid": ds["valid"].values.astype(bool)}
    new, report = build_dataset(study, data, ds.attrs.get("variant", ""))
    new.attrs["software"] = ds.attrs["software"]          # the rendering's versions
    new.attrs["analytic_recomputed_with"] = json.dumps(_versions(), sort_keys=True)

    def write(tmp):
        add_checksums(new).to_netcdf(tmp, engine="h5netcdf")
    ds.close()
    atomic_write(path, write)
    return report
