"""The analytic check's reference of a prepared run: the analytic irradiance and the direct-Sun masks.

:class:`CheckReference` holds what :mod:`simcore.pipeline.check` compares the rendered irradiance with: the
analytic model of the run's epochs (the albedo with the visible shares traced against the mesh where shadows
cross a diode) and the diode-epochs whose direct Sun has no exact reference (parts, other diodes' mounts,
windows and round wells under the body's shadow), which the check leaves out and counts. The job
(:class:`simcore.pipeline.run.PreparedRun`) builds it from the prepared run.
"""
import functools

import numpy as np

from scenes.config import body_side_normal
from simcore import _llvm
from simcore.radiometry.analytic import BodyBox, DirectionVisibility, diode_irradiance
from simcore.radiometry.analytic_direct import disc_directions
from simcore.render import Renderer, occluder_scene, rays_blocked, widen_cells
from simcore.shapes.aperture import CircularWell
from simcore.shapes.occlusion import box_hit
from simcore.shapes.window import WindowedWell


class CheckReference:
    """The check's reference of a prepared run (``run``: a :class:`simcore.pipeline.run.PreparedRun`)."""

    def __init__(self, run):
        self.run = run
        self.opts, self.config, self.geometry = run.opts, run.config, run.geometry
        self.sun_angular_radius_rad = run.sun_angular_radius_rad
        self.body_box = run.satellite.body_box
        self._parts = run.parts

    @property
    def earth(self):
        """Return the run's :class:`simcore.environment.earth.Earth` (its current map and glint)."""
        return self.run.earth

    @property
    def renderer(self):
        """Return the run's renderer (its probes trace the mesh; building it sets Mitsuba's variant)."""
        return self.run.renderer

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
        box = self.body_box
        out = np.zeros(share.shape, bool)
        for k, frame in enumerate(np.asarray(self.config.frames)):
            model = np.zeros(TH.shape) if box is None else box_hit(box.positions_m[k], local @ frame, box.half_m) * 1.0
            cell = np.isfinite(share[k]) & (share[k] != model)
            out[k] = widen_cells(cell)
        return out

    def analytic(self, sl, reflectivity_map, direct=True, mesh=False, albedo=True, box_albedo=False, mesh_terms=True):
        """Return the analytic irradiance of epochs ``sl`` on ``reflectivity_map``; ``mesh``: the albedo with
        the traced :attr:`visibility` where shadows cross the diodes (the check's reference; ``mesh_terms``:
        also its ``albedo_mesh_w_m2`` and ``albedo_visibility_error_w_m2``, :func:`diode_irradiance`). The direct Sun
        alone (``albedo=False``) is numpy and the body box's shadow kernel (traced, never frozen): it may run in
        another thread while the renderer records and replays its frozen kernels (Dr.Jit records per thread)."""
        g = self.geometry
        out = diode_irradiance(g.r_sat_ecef_m[sl], g.r_sun_ecef_m[sl], g.R_ecef_from_body[sl],
                               self.config.frames, self.config.apertures, earth=self.earth.on_grid(reflectivity_map),
                               e_sun_w_m2=self.opts.e_sun_w_m2, distance_scaling=self.opts.distance_scaling,
                               eclipse="conical" if self.opts.sun_disc else "cylindrical",
                               body=self.body_box,
                               sun_angular_radius_rad=self.sun_angular_radius_rad, direct=direct,
                               albedo=albedo, backend="auto" if albedo else "numpy",
                               visibility=self.visibility if mesh else None, box_albedo=box_albedo,
                               mesh_terms=mesh_terms)
        if any(w is not None for w in self.config.windows):
            self._windowed_analytic(out, sl, reflectivity_map, direct, mesh, albedo, box_albedo, mesh_terms)
        return out

    def _windowed_analytic(self, res, sl, reflectivity_map, direct, mesh, albedo=True, box_albedo=False,
                           mesh_terms=True):
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
        box = self.body_box
        common = dict(earth=self.earth.on_grid(reflectivity_map), e_sun_w_m2=self.opts.e_sun_w_m2,
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
                               mesh_terms=mesh_terms,
                               body=box and BodyBox(box.half_m, box.positions_m[idx], box.panel_normals[idx]))
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
        box = self.body_box
        for k in idx:
            front = dirs @ cfg.diodes[k].normal_body > 0
            below = dirs @ box.panel_normals[k] < 0
            out[:, k] = (front & below).any(axis=0) & ok
        return out

