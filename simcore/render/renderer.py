"""The :class:`Renderer`: a satellite scene (diodes, occluder mesh, the Earth's reflectivity) that renders the
diodes' irradiance (W/m^2) along many epochs, composed of the estimators of this package (docs/renderer.md)."""
from dataclasses import dataclass

import numpy as np

from scenes.satellite import DiodeSurfaces
from simcore import _llvm
from simcore._llvm import host_array
from simcore.constants import E_SUN_W_M2, R_EARTH_MEAN_M
from simcore.environment.maps import named_map
from simcore.render.albedo import (_ALBEDO_CONF, _ALBEDO_GROUP_B, _ALBEDO_PILOT, _ALBEDO_POWER, _ALBEDO_STRATA0,
                                   EarthAlbedo, reach_levels, sunlit_earth_in_view)
from simcore.render.direct import _DIRECT_SAMPLES0, DirectSun, in_umbra
from simcore.render.launch import SUN_ANGULAR_RADIUS_RAD, Launcher, choose_variant, occluder_scene
from simcore.render.probes import Probes
from simcore.render.reflected import _REFLECTED_LANES, _REFLECTED_SAMPLES0, REFLECTED_BATCH_EPOCHS, ReflectedLight
from simcore.render.results import RenderResult
from simcore.render.sampling import Rounds, Sampling, _albedo_size, _direct_size
from simcore.render.split import ApertureSplit
from simcore.render.windows import CoverGlass, _window_params

# Epochs per batch of Renderer.render (the numbers do not depend on it): a batch costs ~40-60 launches and host work per
# round whatever its size, so larger batches spread them over more epochs (bench_rays' orbit, 600 epochs, under load:
# 1.51, 1.27, 1.25 ms per epoch at 64, 256, 512, host share 0.16, 0.12, 0.10; on a quiet machine 0.37, 0.36, 0.38 s
# the first 600 epochs after 64 of warm-up: a larger batch's first launches touch more fresh memory). 256: the
# gain of 512 without its first-touch cost and memory (docs/renderer.md, "Launches per batch"). The reflected tasks
# still gather REFLECTED_BATCH_EPOCHS at a time.
BATCH_EPOCHS = 256


class Renderer(Probes, ReflectedLight, EarthAlbedo, DirectSun, CoverGlass, ApertureSplit, Rounds, Launcher):
    """A satellite scene ready to render diode irradiance along many epochs.

    ``diodes``: a DiodeSurfaces; ``occluder_mesh``: a ``trimesh.Trimesh`` (body frame,
    metres) of everything that can block light (not the diodes' own surfaces), or
    None for bare diodes; ``reflectivity``: a (n_lat, n_lon) map on a regular
    latitude/longitude grid, row 0 the southern band, column 0 starting at
    ``lon_west_deg`` (default: the TOMS 2005 mean shipped in simcore/data);
    ``sun_angular_radius_rad``: 0 for a point Sun, ``SUN_ANGULAR_RADIUS_RAD`` for
    the 0.53 deg disc (penumbra, uniform disc: no limb darkening); ``variant``:
    see :func:`choose_variant`; ``threads``: Dr.Jit CPU threads (default: all);
    ``control_variate``: use the diodes' WellAperture for the aperture split
    (docs/renderer.md) when ``diodes.apertures`` is given; ``max_depth``: the most
    spacecraft vertices of a ``reflected`` path (docs/renderer.md); ``glint``: a
    :class:`simcore.radiometry.glint.SunGlint`, the sea's Cox-Munk glint added to the map's Lambertian
    reflectance on each cell's sea fraction (``glint.sea`` in the map's layout, or GSHHG's), in every kernel
    that looks the Earth up (None: no glint, and the kernels traced as without it). The mesh's materials:
    ``metadata['parts']`` (face ranges) with ``metadata['materials']`` (per part), or one
    ``metadata['material']`` for all of it (:mod:`scenes.materials`; default 'black').

    Building one traces a small visibility table per diode (1 x 2 deg, 3 x 3 probe
    rays from the part of the diode its well lights) that only shapes the albedo
    sampling.
    """

    def __init__(self, diodes, occluder_mesh=None, *, reflectivity=None, lon_west_deg=-180.0,
                 earth_radius_m=R_EARTH_MEAN_M, e_sun_w_m2=E_SUN_W_M2, sun_angular_radius_rad=0.0,
                 variant=None, threads=None, control_variate=True, max_depth=8, glint=None):
        if not isinstance(diodes, DiodeSurfaces):
            raise TypeError("diodes must be a scenes.satellite.DiodeSurfaces (positions_m, frames, sizes_m)")
        self.diodes = diodes
        self.variant = choose_variant(variant)
        dr, mi = _llvm.import_drjit(), _llvm.import_mitsuba()
        mi.set_variant(self.variant)
        if threads is not None:
            dr.set_thread_count(int(threads))
        self._dr, self._mi = dr, mi
        if reflectivity is None:
            reflectivity = named_map("toms2005").values
        refl = np.asarray(reflectivity, dtype=float)
        if refl.ndim != 2 or min(refl.shape) < 1 or not np.all(np.isfinite(refl)):
            raise ValueError(f"reflectivity must be a finite (n_lat, n_lon) map, got shape {refl.shape}")
        self.reflectivity = refl
        self.lon_west_rad = float(np.radians(lon_west_deg))
        self.earth_radius_m = float(earth_radius_m)
        self.e_sun_w_m2 = float(e_sun_w_m2)
        a = float(sun_angular_radius_rad)
        if not 0.0 <= a < 0.1:
            raise ValueError(f"sun_angular_radius_rad must lie in [0, 0.1) rad, got {a}; "
                             f"use 0 (point Sun) or SUN_ANGULAR_RADIUS_RAD ({SUN_ANGULAR_RADIUS_RAD:.5f})")
        self.sun_angular_radius_rad = a
        self._refl_dr = host_array(mi.Float, refl)
        self._glint, self._sea_dr, self._sea_max_dr = glint, None, None
        # the albedo proposal's bounds on the map within reach of a bin corner (reach_levels, _BOUND_SHARE)
        self._refl_max_dr = host_array(mi.Float, reach_levels(refl))
        if glint is not None:
            sea = self._sea_fraction(glint)
            self._sea_dr = host_array(mi.Float, sea)
            self._sea_max_dr = host_array(mi.Float, reach_levels(sea))
        self._scene = self._build_scene(occluder_mesh)
        if int(max_depth) < 1:
            raise ValueError(f"max_depth must be >= 1 spacecraft vertex, got {max_depth}")
        self.max_depth = int(max_depth)
        self._mirror_normals = None
        self.materials = {}          # part name -> material of the mesh's parts (_build_pt_scene)
        self._pt = self._build_pt_scene(occluder_mesh)
        self._diode_f32 = self._diode_arrays()
        # Aperture hint for the albedo sampling (WellAperture.rims: half diode x/y, half opening x/y and
        # height of the lower and the top rim); a bare diode (opening = diode, height 0) when unknown.
        aps = diodes.apertures
        half = diodes.sizes_m / 2
        if aps is None:
            zero = np.zeros((len(half), 1))
            self._ap_params = np.concatenate([half, half, zero, half, zero], axis=1)
        else:
            # the diode's own sides (where the points are sampled) with the well's opening
            self._ap_params = np.array([[hx, hy, *a.rims[2:]] for (hx, hy), a in zip(half, aps)])
        # the albedo proposal's: the exact lit rectangle of a square well, one holding the lit part of a round
        # well (CircularWell.hint_rims, a superset: unbiased); the split above takes one inside it (subset)
        self._ap_hint = self._ap_params if aps is None else np.array(
            [[hx, hy, *getattr(a, "hint_rims", a.rims)[2:]] for (hx, hy), a in zip(half, aps)])
        # Round wells (CircularWell: the lit part is not a rectangle): no split (one on a rectangle inside the lit
        # part would leave group B a sliver that few of its samples find, and a standard error that misses it)
        # but a control variate, mode 3 (_round_cv): each lane adds the closed-form lit fraction of the disc and
        # subtracts whether its point lies in the disc's lit part, so where the mesh is the analytic well the
        # lanes agree and the noise is that of what else shades the diode. (radius, height) m, 0 for others.
        self._plain = np.zeros(len(half), bool) if aps is None else np.array(
            [not getattr(a, "exact_rectangle", True) for a in aps])
        self._round_params = np.zeros((len(half), 2)) if aps is None else np.array(
            [[getattr(a, "radius_m", 0.0), a.height_m] for a in aps])
        self.control_variate = bool(control_variate) and aps is not None
        self._win = _window_params(diodes)
        self._vis = self._visibility_table()
        self._frozen = {}            # kernel name -> its drjit.freeze wrapper (_run)
        self._hit = None if self._pt is None else self._hit_table()

    @classmethod
    def from_scene(cls, satellite, earth=None, *, diodes=None, mesh=None, **render_options):
        """Return the renderer of ``satellite`` (a :class:`scenes.satellite.Satellite`: its diodes and occluder
        mesh) over ``earth`` (a :class:`simcore.environment.earth.Earth`: its map, radius and glint in the
        renderer's layout, :meth:`~simcore.environment.earth.Earth.renderer_layout`; None: the default Earth, TOMS
        2005 without glint). ``diodes``: indices of the diodes that receive light (None: all; the others stay in
        the mesh as occluders); ``mesh``: an occluder mesh instead of the satellite's (e.g. one diode's own well);
        ``render_options``: the other keywords of :class:`Renderer` (``e_sun_w_m2``, ``variant``, ...)."""
        surfaces = satellite.diodes if diodes is None else satellite.diodes.subset(diodes)
        layout = {} if earth is None else earth.renderer_layout()
        return cls(surfaces, satellite.mesh if mesh is None else mesh, **layout, **render_options)

    def _sea_fraction(self, glint):
        """Return the sea fraction (n_lat, n_lon) of the reflectivity map's cells (its layout: row 0 the southern
        band, column 0 from ``lon_west``): the glint's own (``glint.sea``) or GSHHG's."""
        if glint.sea is not None:
            if glint.sea.shape != self.reflectivity.shape:
                raise ValueError(f"the glint's sea fraction has shape {glint.sea.shape}, the map "
                                 f"{self.reflectivity.shape}")
            return glint.sea
        from simcore.environment.maps import ReflectivityMap
        from simcore.environment.water import ocean_fraction
        n_lat, n_lon = self.reflectivity.shape
        grid = ReflectivityMap.from_array(np.zeros((n_lat, n_lon)), None,
                                          np.degrees(self.lon_west_rad) + (np.arange(n_lon) + 0.5) * (360.0 / n_lon))
        return ocean_fraction(grid)

    # -- scene
    def _build_scene(self, mesh):
        return occluder_scene(mesh, self._mi)

    def _diode_arrays(self):
        d = self.diodes
        u = d.frames[:, 0] * d.sizes_m[:, :1]
        v = d.frames[:, 1] * d.sizes_m[:, 1:]
        return dict(pos=d.positions_m, U=u, V=v, n=d.frames[:, 2])

    def _kernel_state(self, *args, **kwargs):
        """Return the renderer's settings that shape the traced direct, albedo and proposal kernels (part of their
        frozen recordings' key, :meth:`_run`)."""
        return (self.variant, self.sun_angular_radius_rad, self.control_variate, self.earth_radius_m,
                self.lon_west_rad, self.reflectivity.shape, self._win is None,
                bool(self.control_variate and self._plain.any()),
                None if self._glint is None else (self._glint.mss, self._glint.index, self._glint.tau))

    # -- task assembly
    def _tasks(self, ep, dk, sun, earth, keys=None):
        dd = self._diode_f32
        t = dict(k=dk, pos=dd["pos"][dk], U=dd["U"][dk], V=dd["V"][dk], n=dd["n"][dk], sun=sun[ep],
                 frame=self.diodes.frames[dk], ap=self._ap_params[dk], ap_hint=self._ap_hint[dk],
                 round=self._round_params[dk])
        t["earth"] = None if earth is None else earth[ep] - dd["pos"][dk]
        if self._win is not None:
            t["win"] = self._win[dk]
        return t

    def render(self, sun_dir_body, earth_center_body_m=None, R_ecef_from_body=None, sun_scale=None, *,
               sun_dir_earth_body=None, earth_sun_scale=None, seed=0, epoch_offset=0, epoch_index=None, direct_samples=_DIRECT_SAMPLES0, albedo_samples=2 * _ALBEDO_STRATA0,
               rel_se_direct=None, rel_se_albedo=None, abs_se_floor_w_m2=0.01,
               max_direct_samples=1 << 17,
               max_albedo_samples=65536, albedo=True, hint=True, batch_epochs=BATCH_EPOCHS, progress=None,
               reflected=True, reflected_samples=_REFLECTED_SAMPLES0):
        """Return a :class:`RenderResult`: direct-Sun and albedo irradiance (N, K) in W/m^2 with
        standard errors.

        ``sun_dir_body`` (N, 3) unit satellite->Sun; ``earth_center_body_m`` (N, 3) the Earth's centre
        in body axes with the satellite at the origin (None: no Earth, no albedo);
        ``R_ecef_from_body`` (N, 3, 3) (needed for albedo); ``sun_scale`` (N,) multiplies E_sun
        (e.g. (1 AU / r_sun)^2; default 1). ``sun_dir_earth_body`` (N, 3) and ``earth_sun_scale`` (N,): the
        Sun's direction and scale that light the Earth (the analytic model's: as seen from the Earth's
        centre; default those of the satellite). ``direct_samples`` (4 m^2: 2 points in each of 2 m^2
        strata) per diode in the first round; ``albedo_samples`` (even) in the first round.
        ``rel_se_direct`` / ``rel_se_albedo``: target relative standard errors (e.g. 0.002, 0.01)
        met by further rounds for the diode-epochs above it (or above ``abs_se_floor_w_m2``),
        up to ``max_*_samples`` each. ``epoch_offset``: global index of the first epoch, so that a
        run rendered in pieces draws the same random numbers as in one go; ``epoch_index`` (N,) int: the
        global index of each epoch instead (for a scattered subset). ``albedo=False`` skips
        the albedo (zeros). ``hint=False``: the direct Sun without the analytic wells' aperture split
        (plain sampling of the diode, its own random numbers): an estimate that shares nothing with the
        analytic aperture model, for the check. ``batch_epochs``: epochs per wavefront (results do not depend on it).
        ``progress``: optional callable, called with the number of epochs done after each batch.
        ``reflected_samples`` (4 m^2) paths per diode-epoch for the ``reflected`` component (only when some
        part is not 'black'; ``reflected=False`` skips it: zeros; with ``albedo=False`` or no Earth it holds the
        reflected sunlight only).

        Per-epoch problems (non-finite inputs) give NaN rows and ``valid`` False; exact zeros
        (Sun behind the diode, full eclipse, no sunlit Earth in the diode's half-space) cost no
        rays and report 0 samples.
        """
        if self._mi.variant() != self.variant:     # someone switched Mitsuba's global variant
            self._mi.set_variant(self.variant)
        inp = self._epochs(sun_dir_body, earth_center_body_m, R_ecef_from_body, sun_scale, sun_dir_earth_body,
                           earth_sun_scale, epoch_index, albedo)
        plans = _plans(seed, direct_samples, albedo_samples, reflected_samples, rel_se_direct, rel_se_albedo,
                       abs_se_floor_w_m2, max_direct_samples, max_albedo_samples, hint)
        self._check_epochs(inp)
        N, K = len(inp.sun), self.diodes.count
        out = {k: np.zeros((N, K)) for k in ("dm", "dse", "am", "ase", "rm", "rse")}
        out.update(ddof=np.full((N, K), np.inf), adof=np.full((N, K), np.inf), rdof=np.full((N, K), np.inf))
        n_dir, n_alb, n_ref = (np.zeros((N, K), dtype=np.int64) for _ in range(3))
        do_reflected = bool(reflected) and self._pt is not None
        pending = []
        E = self.e_sun_w_m2 * inp.scale                              # (N,)
        E_e = self.e_sun_w_m2 * inp.scale_e                          # (N,) lighting the Earth
        cos_c = inp.sun @ self.diodes.frames[:, 2].T                # (N, K) float64
        for b0 in range(0, N, batch_epochs):
            eps = np.arange(b0, min(N, b0 + batch_epochs))
            ep, dk = [a.ravel() for a in np.meshgrid(eps, np.arange(K), indexing="ij")]
            g_ep = ep + int(epoch_offset) if inp.epoch_index is None else inp.epoch_index[ep]
            self._direct_batch(inp, ep, dk, g_ep, E, cos_c, plans["direct"], out, n_dir)
            if inp.do_albedo:
                self._albedo_batch(inp, ep, dk, g_ep, E_e, plans["albedo"], out, n_alb)
            # the reflected tasks gathered REFLECTED_BATCH_EPOCHS epochs at a time, whatever batch_epochs: a
            # wavefront then holds at most that many epochs past _REFLECTED_LANES lanes (the run's memory check)
            for r0 in range(0, len(eps), REFLECTED_BATCH_EPOCHS) if do_reflected else ():
                sub = slice(r0 * K, (r0 + REFLECTED_BATCH_EPOCHS) * K)
                pending.append(self._reflected_tasks(inp, ep[sub], dk[sub], g_ep[sub]))
                # the wavefront's launches cost ~10 ms each to trace whatever their width: gather many epochs
                if (sum(len(p[0]) for p in pending) * plans["reflected"].n0 >= _REFLECTED_LANES
                        or eps[min(len(eps), r0 + REFLECTED_BATCH_EPOCHS) - 1] == N - 1):
                    e_, k_, gg = (np.concatenate(x) for x in zip(*pending))
                    pending = []
                    if len(e_):
                        self._reflected_round(e_, k_, gg, inp.sun, inp.sun_e, inp.earth if inp.do_albedo else None,
                                              inp.rot, inp.earth, E, E_e, plans["reflected"], out, n_ref)
            if progress is not None:
                progress(len(eps))
        nan = ~inp.valid
        for k in out:
            out[k][nan] = np.nan
        return RenderResult(out["dm"], out["dse"], out["am"], out["ase"], n_dir, n_alb, inp.valid,
                            self.variant, int(seed), out["ddof"], out["adof"],
                            dict(sun_angular_radius_rad=self.sun_angular_radius_rad, e_sun_w_m2=self.e_sun_w_m2),
                            out["rm"], out["rse"], n_ref, out["rdof"])

    def _epochs(self, sun_dir_body, earth_center_body_m, R_ecef_from_body, sun_scale, sun_dir_earth_body,
                earth_sun_scale, epoch_index, albedo):
        """Return the :class:`_Epochs` of :meth:`render`'s per-epoch arguments, their shapes checked (the epochs'
        values are checked by :meth:`_check_epochs`)."""
        sun = np.atleast_2d(np.asarray(sun_dir_body, dtype=float))
        N = sun.shape[0]
        if sun.shape != (N, 3):
            raise ValueError(f"sun_dir_body must have shape (N, 3), got {np.shape(sun_dir_body)}")
        earth = None
        if earth_center_body_m is not None:
            earth = np.atleast_2d(np.asarray(earth_center_body_m, dtype=float))
            if earth.shape != (N, 3):
                raise ValueError(f"earth_center_body_m must have shape ({N}, 3) like sun_dir_body, "
                                 f"got {earth.shape}")
        do_albedo = bool(albedo) and earth is not None
        rot = None
        if do_albedo:
            if R_ecef_from_body is None:
                raise ValueError("albedo needs R_ecef_from_body (N, 3, 3) to find where on the Earth a ray "
                                 "lands; pass it, or albedo=False")
            rot = np.asarray(R_ecef_from_body, dtype=float).reshape(-1, 3, 3)
            if rot.shape != (N, 3, 3):
                raise ValueError(f"R_ecef_from_body must have shape ({N}, 3, 3), got {np.shape(R_ecef_from_body)}")
        if epoch_index is not None:
            epoch_index = np.asarray(epoch_index, dtype=np.int64).reshape(-1)
            if epoch_index.shape != (N,):
                raise ValueError(f"epoch_index must have shape ({N},), got {epoch_index.shape}")
        scale = np.ones(N) if sun_scale is None else np.broadcast_to(np.asarray(sun_scale, dtype=float), (N,))
        # The Earth is lit by the Sun as seen from its centre (the analytic model's convention, eq. 4.20):
        # by default the satellite's Sun, which differs by (satellite's distance from the Earth's centre) / AU.
        sun_e = sun if sun_dir_earth_body is None else np.atleast_2d(np.asarray(sun_dir_earth_body, dtype=float))
        if sun_e.shape != (N, 3):
            raise ValueError(f"sun_dir_earth_body must have shape ({N}, 3) like sun_dir_body, got {sun_e.shape}")
        scale_e = scale if earth_sun_scale is None else np.broadcast_to(np.asarray(earth_sun_scale, dtype=float), (N,))
        return _Epochs(sun, sun_e, earth, rot, scale, scale_e, epoch_index, do_albedo)

    def _check_epochs(self, inp):
        """Mark the epochs whose inputs are not finite (``inp.valid``) and give them harmless stand-ins (their
        values become NaN); raise for a satellite inside the Earth or a Sun vector that is not a unit vector."""
        valid = np.all(np.isfinite(inp.sun), axis=1) & np.isfinite(inp.scale)
        if inp.earth is not None:
            valid &= np.all(np.isfinite(inp.earth), axis=1)
            dist = np.linalg.norm(inp.earth, axis=1)
            inside = valid & (dist <= self.earth_radius_m)
            if np.any(inside):
                raise ValueError(f"the satellite is inside the Earth at epoch {int(np.argmax(inside))} "
                                 f"(|earth_center_body_m| = {dist[np.argmax(inside)]:.0f} m <= R = "
                                 f"{self.earth_radius_m:.0f} m); earth_center_body_m is the Earth's centre "
                                 "relative to the satellite, in metres")
        if inp.do_albedo:
            valid &= np.all(np.isfinite(inp.rot), axis=(1, 2))
        inp.valid = valid
        inp.sun = _unit(np.where(valid[:, None], inp.sun, [[0.0, 0.0, 1.0]]), "sun_dir_body")
        inp.sun_e = _unit(np.where(valid[:, None], inp.sun_e, [[0.0, 0.0, 1.0]]), "sun_dir_earth_body")
        if inp.earth is not None:
            inp.earth = np.where(valid[:, None], inp.earth, [[0.0, 0.0, -2.0 * self.earth_radius_m]])
        if inp.rot is not None:
            inp.rot = np.where(valid[:, None, None], inp.rot, np.eye(3))

    # -- each estimator's tasks of a batch of epochs: those whose value is not exactly 0 by geometry
    def _direct_batch(self, inp, ep, dk, g_ep, E, cos_c, plan, out, n_used):
        """Render the direct Sun of the tasks (epochs ``ep``, diodes ``dk``) facing the (disc of the) Sun and not
        in full umbra."""
        act = inp.valid[ep] & (cos_c[ep, dk] > -np.sin(self.sun_angular_radius_rad))
        if inp.earth is not None:
            act &= ~in_umbra(inp.earth[ep], inp.sun[ep], self.earth_radius_m, np.sin(self.sun_angular_radius_rad))
        if act.any():
            self._direct_rounds(ep[act], dk[act], g_ep[act], inp.sun, inp.earth, E, cos_c, plan, out, n_used)

    def _albedo_batch(self, inp, ep, dk, g_ep, E_e, plan, out, n_used):
        """Render the albedo of the tasks whose hemisphere meets the Earth's disc and a sunlit part of it."""
        c = inp.earth[ep]
        dist = np.linalg.norm(c, axis=1)
        w = c / dist[:, None]
        sin_cap = self.earth_radius_m / dist                        # sin of the cap half-angle
        n = self.diodes.frames[dk, 2]
        # angle(n, w) < 90 deg + cap half-angle  <=>  n . w > -sin(cap)
        sees = np.einsum("ti,ti->t", n, w) > -sin_cap
        act = inp.valid[ep] & sees & sunlit_earth_in_view(c, inp.sun_e[ep], self.earth_radius_m)
        if act.any():
            self._albedo_rounds(ep[act], dk[act], g_ep[act], inp.sun_e, inp.earth, inp.rot, E_e, plan, out, n_used)

    def _reflected_tasks(self, inp, ep, dk, g_ep):
        """Return (epochs, diodes, global epochs) of the reflected tasks: every task with sunlight on the
        satellite or a sunlit Earth in its sky."""
        act = inp.valid[ep].copy()
        if inp.earth is not None:
            c = inp.earth[ep]
            sunny = ~in_umbra(c, inp.sun[ep], self.earth_radius_m, np.sin(self.sun_angular_radius_rad))
            act &= sunny | (inp.do_albedo & sunlit_earth_in_view(c, inp.sun_e[ep], self.earth_radius_m))
        return ep[act], dk[act], g_ep[act]


def _unit(v, name):
    n = np.linalg.norm(v, axis=-1)
    bad = np.isfinite(n) & (np.abs(n - 1.0) > 1e-6)
    if np.any(bad):
        raise ValueError(f"{name} must hold unit vectors; epoch {int(np.argmax(bad))} has norm "
                         f"{n[np.argmax(bad)]:.9f}. Normalise it (satellite -> Sun, body frame)")
    return v / n[..., None]


@dataclass
class _Epochs:
    """:meth:`Renderer.render`'s per-epoch inputs (N epochs): unit Sun vectors (N, 3) seen from the satellite and
    lighting the Earth, the Earth's centre (N, 3) m or None, ``rot`` (N, 3, 3) or None (no albedo), the Sun's
    scales (N,), the global epoch indices or None; ``valid`` (N,) once checked (:meth:`Renderer._check_epochs`)."""

    sun: np.ndarray
    sun_e: np.ndarray
    earth: np.ndarray
    rot: np.ndarray
    scale: np.ndarray
    scale_e: np.ndarray
    epoch_index: np.ndarray
    do_albedo: bool
    valid: np.ndarray = None


def _plans(seed, direct_samples, albedo_samples, reflected_samples, rel_se_direct, rel_se_albedo, floor,
           max_direct_samples, max_albedo_samples, hint):
    """Return the :class:`Sampling` of each estimator ("direct", "albedo", "reflected") from
    :meth:`Renderer.render`'s arguments, checked (the direct and albedo rounds set their per-task factors)."""
    m0 = int(round(np.sqrt(int(direct_samples) / 4.0)))
    if m0 < 2 or 4 * m0 * m0 != int(direct_samples):
        raise ValueError(f"direct_samples must be 4 m^2 for an integer m >= 2 (2 points in each of "
                         f"2 m^2 strata), e.g. 1024 or 4096, got {direct_samples}")
    n0 = int(albedo_samples)
    if n0 < 4 or n0 % 2:
        raise ValueError(f"albedo_samples must be an even number >= 4 (2 per stratum), got {albedo_samples}")
    mr = int(round(np.sqrt(int(reflected_samples) / 4.0)))
    if mr < 2 or 4 * mr * mr != int(reflected_samples):
        raise ValueError(f"reflected_samples must be 4 m^2 for an integer m >= 2 (2 points in each of "
                         f"2 m^2 strata of the diode), e.g. 256 or 1024, got {reflected_samples}")
    for name, v in (("rel_se_direct", rel_se_direct), ("rel_se_albedo", rel_se_albedo)):
        if v is not None and not 0 < v < 1:
            raise ValueError(f"{name} must be a relative standard error in (0, 1), e.g. 0.002, got {v}")
    return dict(direct=Sampling(seed, 4 * m0 * m0, None, _direct_size, 4.0 / 3.0, rel_se_direct, floor,
                                max_direct_samples, plain=not hint),
                albedo=Sampling(seed, n0, None, _albedo_size, _ALBEDO_POWER, rel_se_albedo, floor, max_albedo_samples,
                                pilot=_ALBEDO_PILOT, conf=_ALBEDO_CONF, group_b=_ALBEDO_GROUP_B),
                reflected=Sampling(seed, 4 * mr * mr, 1.0, _direct_size, plain=True))


def render(satellite, earth, sun_dir_body, earth_center_body_m=None, R_ecef_from_body=None, sun_scale=None, *,
           sun_angular_radius_rad=0.0, variant=None, e_sun_w_m2=E_SUN_W_M2, **kwargs):
    """Return a :class:`RenderResult` (direct and albedo irradiance, W/m^2, (N, K)) for one call: the renderer of
    ``satellite`` over ``earth`` (:meth:`Renderer.from_scene`) and its :meth:`Renderer.render` (see both)."""
    r = Renderer.from_scene(satellite, earth, sun_angular_radius_rad=sun_angular_radius_rad, variant=variant,
                            e_sun_w_m2=e_sun_w_m2)
    return r.render(sun_dir_body, earth_center_body_m, R_ecef_from_body, sun_scale, **kwargs)
