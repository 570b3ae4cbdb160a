"""Monte-Carlo irradiance on every diode (W/m^2): direct Sun and Earth albedo, ray traced.

The render frame is the body frame with the SATELLITE AT THE ORIGIN, so that
millimetre apertures keep their float32 precision while the Earth sits
7000 km away (docs/conventions.md). Per epoch the caller gives the unit Sun
vector in body axes, the Earth's centre in body axes (``-R_body_from_ecef @
r_sat_ecef``), the rotation ``R_ecef_from_body`` (to look the Earth's
reflectivity up by latitude and longitude) and an irradiance scale for the
Sun-Earth distance. The satellite's occluders (body, rails, ramps, aperture
walls; not the diodes' own surfaces) are one triangle mesh that Mitsuba's
``scene.ray_test`` traces; rays start on the diode surface with no offset.

Both estimators are plain Dr.Jit functions over a wavefront of lanes
(diode-epoch task x sample), many epochs per launch:

* Direct Sun (next-event estimation). Each diode is cut into 2 m^2 strata
  (squares turned 45 deg to the diode's sides, so that the aperture walls'
  shadow edges cut many strata obliquely) with two random points per
  stratum; from each point a shadow ray goes toward the Sun (or toward a point
  drawn uniformly on the solar disc, which gives the penumbra). The mesh or
  the Earth (analytic ray-sphere test per lane) can block it. Irradiance =
  E_sun * scale * cos(incidence) * unblocked fraction: a bare diode reads
  E_sun cos(theta) exactly, with zero variance. The two points per stratum
  give an unbiased standard error of the stratified estimate.
* Earth albedo. The Earth is a Lambertian sphere of radius R whose
  reflectance ``rho`` comes from a regular latitude/longitude map (row 0 the
  southern band, never clamped): radiance ``L = rho E_sun max(0, n_e . s) / pi``
  (the Sun's visibility at an Earth point is ``n_e . s > 0`` on a sphere).
  ``int L cos(theta_d) V dOmega`` over the Earth's disc as seen from the
  satellite is sampled in direction space: the spherical cap is cut into
  16 x 32 bins (radial x azimuth), each bin gets a probability proportional
  to the largest value at its corners of radiance x diode cosine x analytic
  aperture fraction (when the diode's WellAperture is known) x a visibility
  table of the rest of the satellite, the reflectivity at a corner raised to at
  least a share (``_BOUND_SHARE``; all of it with the sea's glint) of the map's largest within reach of the bins
  around it (a bright cell between dark corners keeps a weight: ``reach_levels``),
  mixed with 2 % uniform in solid angle so
  that every bin keeps a positive probability (the estimator stays unbiased
  whatever the mesh does). The bin is drawn by stratified inversion of its CDF
  (two samples per stratum again), the direction uniformly within it; a ray
  from a point on the diode toward it is tested against the mesh.

Aperture split (when the diodes' ``WellAperture`` are given): ~4/5 of a
task's samples are drawn on the part of the diode that the analytic well lets
the light reach (weighted by its area), ~1/5 on the whole diode counted only
outside that part. Both are traced against the full mesh, so the sum is
unbiased whatever the mesh; when the mesh's well is the analytic one, the
aperture itself adds no noise and only the body, rails, neighbours and Earth
do (see ``Renderer._rounds``). ``control_variate=False`` turns it off.

Reflected (issue 13): sunlight and Earth light that reached the diode after at least one
reflection on the spacecraft, when some part of the occluder mesh has a material other than
'black' (``mesh.metadata['materials']`` per part, :mod:`scenes.materials`). Those parts become
one Mitsuba scene (``mi.load_dict``) of per-part meshes with their BSDFs, path traced: from
points on the diode (the direct estimator's diamond strata, two points each) a first direction
drawn from a table of the diode's hemisphere that favours the cells where probe rays meet the
spacecraft (``Renderer._hit_table``; on the thesis layout only ~5 % of cosine-weighted directions
do), mixed with 10 % cosine-weighted sampling so that every direction keeps a density, the path
weighted by cos / (pi pdf); a path that hits the spacecraft continues by BSDF
sampling (``bsdf.sample``) up to ``max_depth`` vertices, Russian roulette from the fourth, and
at every vertex estimates (a) the Sun: a point drawn uniformly on the finite solar disc, shadow
ray against the mesh and the Earth, ``bsdf.eval`` for it, and (b) the Earth's albedo: a
direction drawn uniformly in solid angle over the Earth's cap (``_cap_direction``; simple, and
costs variance where a small sunlit crescent fills little of the cap), radiance
``rho E cos_sun / pi`` (``_earth_along``) where the mesh does not block it. A BSDF-sampled
direction that leaves the spacecraft and meets the Sun's disc or the Earth adds their radiance
too, the two strategies combined by the power heuristic (Veach 1997, ch. 9), which is what lets
smooth glass and mirrors (delta lobes: BSDF sampling only) reflect the Sun. Paths that leave
the spacecraft at once add nothing (that light is ``direct`` / ``albedo``). The disc is always
finite here (``SUN_ANGULAR_RADIUS_RAD`` when the renderer's Sun is a point): a mirror's image of
a point Sun would be a delta that no sampling meets. All-black scenes build none of this and
report ``reflected`` exactly 0 at no cost.

Windows (issue 14; ``DiodeSurfaces.windows``, :mod:`simcore.shapes.window`): a cover glass over a diode is
traced per lane by ``Renderer._window_exit``: the slab's k-th term (k internal round trips) leaves its upper
face at a closed-form point; k is drawn among the terms whose exit stays in the footprint in proportion to
their Fresnel weight (mean over the s and p polarisations, each exact), the lane carries their sum, and the
segment from the diode to the window and the ray on from the exit point are traced (direct and albedo; the
first segment of a reflected path likewise). The window is no occluder or reflector itself. Without windows
none of this code runs: the kernels are the ones before windows existed.

Sums are formed per (epoch, diode) in float64 in numpy from the per-lane
float32 values. Random numbers come from ``mi.sample_tea_32`` keyed by
(seed, global epoch index, diode, estimator, round, group) and the lane's sample index (the direct and
albedo kernels draw their further numbers from a PCG32 generator that it seeds): a given seed gives
bitwise identical results whatever the batch split, so a resumed run
reproduces (``epoch_offset``). With target accuracies (``rel_se_direct``,
``rel_se_albedo``) the diode-epochs that have not reached them (nor the
absolute floor ``abs_se_floor_w_m2``) get further rounds of samples, up to a
cap.

Launches: a launch's task fields go to the kernels packed in two arrays (``_Lanes``), and the direct, albedo
and proposal kernels are ``drjit.freeze`` recordings, traced once and replayed (``Renderer._run``, which says
why that is sound): every array a kernel reads must therefore reach it through its ``_Lanes`` (never a numpy
array or a Dr.Jit array held elsewhere), and a renderer setting that changes the traced code belongs in
``Renderer._kernel_state``. The values are bit for bit those of tracing every launch (tests/test_render_freeze.py).
"""
import contextlib
from dataclasses import dataclass, field, replace
import gc
import os
import threading
import weakref

import numpy as np

from scenes.materials import MaterialError, bsdf_dict, check_material, is_black
from scenes.satellite import DiodeSurfaces  # noqa: F401 (the renderer's input; its home is the data layer)
from simcore import _llvm
from simcore._llvm import host_array, host_buffer, host_wrap
from simcore.constants import AU_M, E_SUN_W_M2, R_EARTH_MEAN_M, R_SUN_M
from simcore.environment.maps import named_map
from simcore.radiometry import glint as _glint
from simcore.shapes.aperture import disc_rectangle_overlap, lit_rectangle_of

SUN_ANGULAR_RADIUS_RAD = float(np.arcsin(R_SUN_M / AU_M))  # 0.2666 deg: the 0.53 deg disc at 1 AU

_VARIANTS = ("llvm_ad_mono", "cuda_ad_mono")
_DEFENSIVE = 0.02         # share of uniform-in-solid-angle sampling in the albedo proposal
_N_T, _N_P = 16, 32       # albedo proposal bins: radial x azimuth (_N_P a power of 2)
_DIRECT_SAMPLES0 = 1024
_ALBEDO_STRATA0 = 128
_VIS_NT, _VIS_NP = 90, 180  # visibility table over each diode's hemisphere (1 x 2 deg cells)
# Radial bins of the albedo proposal: edges 40 % of the way from equal solid angle to equal
# ground (central) angle; the Sun's cosine at the bin corners widened by ~half a bin.
_EDGE_MIX, _MARGIN_SCALE = 0.4, 1.0
# The albedo proposal's reflectivity at a bin corner is at least this share of the largest reflectivity within
# reach of the bins that touch the corner (reach_levels, corner_reach): a bright cell between dark corners (cloud
# over an infrared-dark sea: 54x) then costs an importance ratio of at most 1 / _BOUND_SHARE times the geometric
# factor's, instead of the cells' contrast (heavy tails: the rare bright samples carry the mean, and when a seed
# misses them both the estimate and its standard error come out low). Not 1 (a strict bound): the bins near any
# bright cell would all read it, the proposal would go flat over a dark sea with scattered clouds and no longer
# favour the bins that hold them (albedo samples to reach 1 %, --map band --clouds 1 from 2016-07-02 00:45Z:
# 8353 at 0.25, 11775 at 0.5, 18472 at 1; TOMS 2005 bench: +0 %, +1 %, +16 %; synthetic dark map with
# 0.5-2 % bright cells at 256 samples: more |z| > 4 at 0.5 and 1 than at 0.25).
_BOUND_SHARE = 0.25
# With the sea's glint the share is 1, a strict bound (the map's and the sea's largest within reach, the glint's
# BRDF at the corner). A quarter under-weights both a clear sea's glint between overcast corners (the corner's own
# sea is 0 there, and the glint outshines the cloud: pi f of a few at oblique geometry against 0.7) and a cloud
# beside the glint's bright bins, which now compete for the samples instead of a dark sea; the rare samples that
# hit them carry the mean (2 minutes of --map band --glint 7 --clouds 1 from 2016-07-02T16:44Z, tilt20_fov70,
# seeds 2, 3, 4, 6: |z| > 4 on 7, 8, 4, 6 of 711 diode-epochs at a quarter, 1, 1, 4, 4 with the map's share 1
# alone, 0, 0, 1, 0 with the glint's share 1 alone, 0, 0, 0, 0 with both; expected 0.05).
_BOUND_SHARE_GLINT = 1.0
# Estimators (part of the random-number key): the direct Sun, the albedo, the direct Sun without the
# analytic aperture split (the check's independent estimate).
_DIRECT, _ALBEDO, _DIRECT_PLAIN, _REFLECTED = 1, 2, 3, 4
_REFLECTED_SAMPLES0 = 256
# Path-tracer vertices leave the surface by this much along its normal (m): well above the float32
# spacing of body coordinates (~1e-8 m at 0.1 m), well below any feature of a 0.5 mm well wall
# (Mitsuba's own spawn_ray offsets by ~1e-4 of the coordinates plus 1e-4 units: 0.1 mm in metres).
_SPAWN_EPS_M = 2e-6
_RR_DEPTH = 3             # Russian roulette from the fourth path vertex on
_REFLECTED_LANES = 1 << 20  # reflected paths gathered over epochs before a wavefront is launched
# First direction of a reflected path: cells of each diode's hemisphere (zenith x azimuth) where probe rays
# meet the spacecraft get the samples (paths into empty sky carry nothing: ~95 % of cosine-drawn ones on the
# thesis layout), mixed with this share of cosine-weighted sampling so that every direction keeps a density
# (the estimator stays unbiased whatever the probes missed).
_HIT_NT, _HIT_NP, _HIT_PROBES, _HIT_COSINE = 45, 128, 4, 0.1
_MAX_MIRROR_PLANES = 32   # orientations of smooth-specular faces sampled toward the Sun's mirror image
# Rounds of the TEA hash behind every random number (in the direct and albedo kernels: behind a lane's first two
# and the PCG32 state that supplies the rest, Renderer._rand). Mitsuba's default, 4, is meant for seeding: with it
# the two samples of a stratum (consecutive lanes) come out correlated and the pair estimate of the
# variance reads ~8 % low (albedo z spread 1.09 over 4200 diode-epochs; 1.025 with 8 rounds, 1.006 with
# 16, 0.995 with 32).
_TEA_ROUNDS = 32
_MAX_LANES = 1 << 22      # lanes per launch (memory bound, ~100 MB of temporaries)
# Direct-Sun tasks that something besides the diode's own well shadows in part (Renderer._partly_blocked):
# probe rays toward the disc's centre and this many points on its rim, and this many times the samples.
_PROBE_RIM = 32
_EDGE_BOOST = 16
# Lanes: each task's rays start on a multiple of this (Dr.Jit's CPU packets and Embree's ray packets hold at most 16
# rays), so that no packet mixes two tasks' rays. Embree's packet traversal can decide a ray that grazes an edge
# differently with other rays beside it (seen: 1 lane of 28 224 flipped with the epochs batched together, moving its
# diode-epoch by 0.02 %); a task's values then depended on the batch, and a run resumed with another --chunk on them.
_PACKET = 16
# Variants whose direct, albedo and proposal kernels are recorded once and replayed (Renderer._run).
_FREEZE_VARIANTS = ("llvm_ad_mono",)
_WINDOW_KEY = 0x5BD1E995   # xor-ed into a lane's key: the window's own random numbers (the kernels' stay as they were)


# --------------------------------------------------------------------------- variants

def _anchored(dr, lanes, values):
    """Return a kernel's per-lane ``values`` passed through a select on the lanes' counter (always true: a launch
    holds < 2^32 - 1 lanes; the values are unchanged), so that a result the tracer folds to a constant still has
    one value per lane of the launch (Renderer._run)."""
    return dr.select(lanes.lane != 0xFFFFFFFF, values, 0.0)


def _cuda_works():
    """Return True when Dr.Jit can use a CUDA device in this process."""
    dr = _llvm.import_drjit()
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # a broken driver is "no GPU" here
        return False


def choose_variant(requested=None):
    """Return the Mitsuba variant to render with: 'cuda_ad_mono' when a CUDA GPU works,
    else 'llvm_ad_mono'; ``requested`` forces one and raises if it cannot run here.

    Raises ``ValueError`` for an unknown variant, ``RuntimeError`` when a CUDA
    variant is requested without a working GPU, and
    ``simcore._llvm.LLVMNotFoundError`` (with the install hint) when no usable
    libLLVM exists: Dr.Jit's CPU backend is needed with either variant.
    """
    if requested is not None and requested not in _VARIANTS:
        raise ValueError(f"unknown render variant {requested!r}; use one of {_VARIANTS} "
                         "or None to pick the GPU when there is one")
    variant = "llvm_ad_mono"
    if requested in (None, "cuda_ad_mono"):
        _llvm.import_mitsuba()  # loads drjit's backends
        if _cuda_works():
            variant = "cuda_ad_mono"
        elif requested is not None:
            raise RuntimeError("variant 'cuda_ad_mono' was requested but no working CUDA GPU was found "
                               "(Dr.Jit reports no CUDA backend); use variant='llvm_ad_mono' or None "
                               "to render on the CPU")
    # Dr.Jit's CPU backend, whichever variant renders: the analytic model's and the body shadow's float64 kernels
    # (simcore.radiometry.analytic, simcore.shapes.occlusion) run on it on a GPU machine too. Without it the first
    # of them dies (SIGFPE, seen on an H100 with no libLLVM) instead of saying what is missing.
    _llvm.find_libllvm()
    dr = _llvm.import_drjit()
    if not dr.has_backend(dr.JitBackend.LLVM):
        raise _llvm.LLVMNotFoundError(
            f"Dr.Jit could not load the libLLVM at {os.environ.get(_llvm.ENV)!r} (its CPU backend runs the analytic "
            "model whichever variant renders). " + _llvm.INSTALL_HINT)
    return variant


# --------------------------------------------------------------------------- inputs

@dataclass
class RenderResult:
    """Rendered irradiance per (epoch, diode), W/m^2 on the diode's sensitive area.

    ``direct_*``: the Sun seen directly; ``albedo_*``: sunlight reflected by the
    Earth; ``*_se_w_m2``: one standard error of the Monte-Carlo estimate;
    ``reflected_*``: Sun and Earth light that reached the diode after at least one reflection on
the spacecraft (exactly 0 when every part is 'black'); ``total_w_m2`` the sum of the three;
``*_dof``: the standard error's effective degrees of freedom (inf where
    it is exactly 0; see ``Renderer._round``); ``*_samples``: rays traced for each (epoch, diode) (0 where the value is
    exactly zero by geometry: Sun behind the diode, full eclipse, no sunlit Earth
    in view). ``valid`` (N,): False for epochs whose inputs were not finite
    (their values are NaN).
    """

    direct_w_m2: np.ndarray
    direct_se_w_m2: np.ndarray
    albedo_w_m2: np.ndarray
    albedo_se_w_m2: np.ndarray
    direct_samples: np.ndarray
    albedo_samples: np.ndarray
    valid: np.ndarray
    variant: str
    seed: int
    direct_dof: np.ndarray = None
    albedo_dof: np.ndarray = None
    info: dict = field(default_factory=dict)
    reflected_w_m2: np.ndarray = None
    reflected_se_w_m2: np.ndarray = None
    reflected_samples: np.ndarray = None
    reflected_dof: np.ndarray = None

    @property
    def total_w_m2(self):
        """Return direct + albedo + reflected (N, K), W/m^2."""
        tot = self.direct_w_m2 + self.albedo_w_m2
        return tot if self.reflected_w_m2 is None else tot + self.reflected_w_m2

    @property
    def rays(self):
        extra = 0 if self.reflected_samples is None else int(self.reflected_samples.sum())
        return int(self.direct_samples.sum() + self.albedo_samples.sum()) + extra


def _mix32(*parts):
    """Return a uint32 hash of integer arrays (splitmix64 chain), broadcast together."""
    m = np.uint64(0xFFFFFFFFFFFFFFFF)
    h = np.zeros(np.broadcast(*[np.asarray(p) for p in parts]).shape, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for p in parts:
            h = (h ^ (np.asarray(p).astype(np.uint64) & m)) + np.uint64(0x9E3779B97F4A7C15)
            h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            h = h ^ (h >> np.uint64(31))
    return (h & np.uint64(0xFFFFFFFF)).astype(np.uint32)


def _unit(v, name):
    n = np.linalg.norm(v, axis=-1)
    bad = np.isfinite(n) & (np.abs(n - 1.0) > 1e-6)
    if np.any(bad):
        raise ValueError(f"{name} must hold unit vectors; epoch {int(np.argmax(bad))} has norm "
                         f"{n[np.argmax(bad)]:.9f}. Normalise it (satellite -> Sun, body frame)")
    return v / n[..., None]


# Per-task fields that the kernels read at other indices than the lane's task (bins, bin edges): uploaded once for a
# set of tasks (Renderer._tables) and read at the task's "row"; every other field of a task dict is a column of
# _Lanes.f or _Lanes.u.
_TABLES = ("cdf", "pmf", "tedge", "tlevel")


@dataclass
class _Lanes:
    """One launch's inputs as Dr.Jit arrays, for the kernels: the tasks' float fields packed row by row in one
    float32 array ``f`` (T rows of ``nf`` columns) and their integer fields in one uint32 array ``u`` (``nu``
    columns), ``layout`` naming the columns ((field, first column, width, in u), ...); ``tables`` the per-task
    tables (``_TABLES``), the renderer's own (reflectivity map, visibility table) and the task of each packet of
    lanes; ``lane`` the lanes' counter 0 .. n - 1; ``scene`` the occluders (or None); ``task`` and ``j``, the lane's
    task and sample index, are found in the kernel (Renderer._with_indices).

    Packed so that a launch costs two uploads (:func:`simcore._llvm.host_array`, ~24 us each) rather than one per
    field and column (~36 a launch). A dataclass so that ``drjit.freeze`` traverses it (Renderer._run): its
    arrays are the frozen kernels' inputs, and ``layout``, ``nf`` and ``nu`` (Python values) are part of the
    recording's key."""

    f: object
    u: object
    tables: dict
    layout: tuple
    nf: int
    nu: int
    lane: object
    scene: object = None
    task: object = None
    j: object = None

    def column(self, name):
        """Return (first column, width, in u) of field ``name``."""
        for entry in self.layout:
            if entry[0] == name:
                return entry[1:]
        raise KeyError(name)

    def has(self, name):
        """Return whether the tasks carry field ``name``."""
        return any(entry[0] == name for entry in self.layout) or name in self.tables


# --------------------------------------------------------------------------- renderer

def occluder_scene(mesh, mi):
    """Return a Mitsuba scene of a ``trimesh.Trimesh`` (body frame, metres, satellite at the origin) that only
    blocks rays (no materials), for ``scene.ray_test``; None for an empty mesh. ``mi``: the mitsuba module with
    its variant set."""
    if mesh is None or len(getattr(mesh, "faces", ())) == 0:
        return None
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    if not np.all(np.isfinite(v)):
        raise ValueError("occluder mesh has non-finite vertices")
    if np.abs(v).max() > 100.0:
        raise ValueError("occluder mesh spans more than 100 m from the body origin; it must be the "
                         "satellite in body axes, in metres, centred on the satellite")
    m = mi.Mesh("occluders", len(v), len(f), has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(m)
    params["vertex_positions"] = host_array(mi.Float, v)
    params["faces"] = host_array(mi.UInt32, f)
    params.update()
    return mi.load_dict({"type": "scene", "occluders": m})


class _DrOps:
    """Dr.Jit's functions under the names of simcore.shapes.aperture's array-library neutral formulas."""

    def __init__(self, dr):
        self.maximum, self.minimum, self.where = dr.maximum, dr.minimum, dr.select
        self.sqrt, self.asin, self.exp, self.erf = dr.sqrt, dr.asin, dr.exp, dr.erf


def rays_blocked(scene, origins, directions, mi):
    """Return (M,) bool: whether each ray (origins, unit directions (M, 3), body frame) meets the occluders of
    ``scene`` (:func:`occluder_scene`)."""
    o = np.asarray(origins, dtype=np.float32).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    ray = mi.Ray3f(mi.Point3f(*(host_array(mi.Float, o[:, i]) for i in range(3))),
                   mi.Vector3f(*(host_array(mi.Float, d[:, i]) for i in range(3))))
    return np.asarray(scene.ray_test(ray).numpy(), bool)


class Renderer:
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
    (module docstring) when ``diodes.apertures`` is given; ``max_depth``: the most
    spacecraft vertices of a ``reflected`` path (module docstring); ``glint``: a
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
            raise TypeError("diodes must be a simcore.render.irradiance.DiodeSurfaces (positions_m, frames, sizes_m)")
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

    def _build_pt_scene(self, mesh):
        """Return the Mitsuba scene of the parts with their BSDFs (one mesh per part), or None when every
        part is 'black' (then nothing is path traced)."""
        if mesh is None or len(getattr(mesh, "faces", ())) == 0:
            return None
        meta = getattr(mesh, "metadata", {}) or {}
        nf = len(mesh.faces)
        if "materials" in meta and "parts" in meta:
            parts = [(name, meta["parts"][name], meta["materials"][name]) for name in meta["parts"]]
        else:
            parts = [("mesh", (0, nf), meta.get("material", "black"))]
        for name, _, spec in parts:
            check_material(spec, f"part {name!r}")
        self.materials = {name: spec for name, _, spec in parts}
        if all(is_black(spec) for _, _, spec in parts):
            return None
        mi = self._mi
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        shapes = {"type": "scene"}
        normals = []
        fn = np.asarray(mesh.face_normals, dtype=np.float64)
        for i, (name, (a, b), spec) in enumerate(parts):
            if b <= a:
                continue
            used, inv = np.unique(f[a:b], return_inverse=True)
            props = mi.Properties()
            try:
                props["bsdf"] = mi.load_dict(bsdf_dict(spec))
            except Exception as exc:          # Mitsuba's message names the bad parameter
                raise MaterialError(f"part {name!r}: Mitsuba cannot build the material {spec!r}: {exc}") from None
            if mi.has_flag(props["bsdf"].flags(), mi.BSDFFlags.DeltaReflection):
                normals.append(fn[a:b])
            m = mi.Mesh(f"part{i}", len(used), b - a, props=props)
            params = mi.traverse(m)
            params["vertex_positions"] = host_array(mi.Float, v[used])
            params["faces"] = host_array(mi.UInt32, inv)
            params.update()
            shapes[f"part{i}"] = m
        self._mirror_normals = _plane_normals(normals)
        return mi.load_dict(shapes)

    def _hit_table(self):
        """Return the proposal of the reflected paths' first direction: dict(pmf, cdf (K, NT NP) float32 as Dr.Jit
        arrays, beta (K,): the cosine-weighted share). Per diode, cells equal in azimuth and in zenith angle;
        a cell's weight is cos x solid angle x the largest share of probe rays (``_HIT_PROBES`` squared points
        on the diode toward the cell's centre) that meet the mesh in it and its 8 neighbours; a diode whose
        probes meet nothing samples cosine-weighted only (beta 1)."""
        mi = self._mi
        K = self.diodes.count
        th_e = np.linspace(0.0, 0.5 * np.pi, _HIT_NT + 1)
        th = 0.5 * (th_e[:-1] + th_e[1:])
        ph = (np.arange(_HIT_NP) + 0.5) * (2.0 * np.pi / _HIT_NP) - np.pi
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        local = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1).reshape(-1, 3)
        g = (np.arange(_HIT_PROBES) + 0.5) / _HIT_PROBES - 0.5
        fx, fy = [a.ravel() for a in np.meshgrid(g, g, indexing="ij")]
        omega = (np.cos(th_e[:-1]) - np.cos(th_e[1:]))[:, None] * np.full(_HIT_NP, 2.0 * np.pi / _HIT_NP)
        w_geo = (np.cos(th)[:, None] * omega).ravel()
        pmf = np.zeros((K, _HIT_NT * _HIT_NP))
        beta = np.ones(K)
        for k in range(K):
            d = local @ self.diodes.frames[k]
            o = (self.diodes.positions_m[k] + fx[:, None] * self._diode_f32["U"][k] + fy[:, None] * self._diode_f32["V"][k])
            oo = np.repeat(o, len(d), axis=0)
            dd = np.tile(d, (len(o), 1))
            hit = np.asarray(self._scene.ray_test(mi.Ray3f(self._v3(oo), self._v3(dd))).numpy(), float)
            h = hit.reshape(len(o), _HIT_NT, _HIT_NP).mean(axis=0)
            hp = np.pad(h, ((1, 1), (0, 0)), mode="edge")
            hd = np.max([np.roll(hp, s_, axis=1)[1 + r_:_HIT_NT + 1 + r_] for r_ in (-1, 0, 1) for s_ in (-1, 0, 1)], axis=0)
            w = w_geo * hd.ravel()
            if w.sum() > 0:
                pmf[k] = w / w.sum()
                beta[k] = _HIT_COSINE
        cdf = np.cumsum(pmf, axis=1)
        cdf[:, -1] = np.where(cdf[:, -1] > 0, 1.0, 0.0)
        return dict(pmf=host_array(mi.Float, pmf), cdf=host_array(mi.Float, cdf),
                    beta=beta, omega=omega.ravel(), th_e=th_e)

    def _diode_arrays(self):
        d = self.diodes
        u = d.frames[:, 0] * d.sizes_m[:, :1]
        v = d.frames[:, 1] * d.sizes_m[:, 1:]
        return dict(pos=d.positions_m, U=u, V=v, n=d.frames[:, 2])

    # -- helpers for Dr.Jit
    def _v3(self, arr):
        mi = self._mi
        a = np.asarray(arr, dtype=np.float32)
        return mi.Vector3f(*(host_array(mi.Float, a[:, i]) for i in range(3)))

    def _gather3(self, src, idx):
        dr, mi = self._dr, self._mi
        return mi.Vector3f(dr.gather(mi.Float, src.x, idx), dr.gather(mi.Float, src.y, idx),
                           dr.gather(mi.Float, src.z, idx))

    def _tables(self, t):
        """Return the tables (``_TABLES``) of the tasks ``t`` as Dr.Jit arrays (row-major, one row a task), uploaded
        once for all of them, and ``row`` (T,): each task's row, the column the kernels read the tables at
        (whatever round or launch the task's lanes fall in: a round repeats a task in two groups, and the tables
        are ~4 kB a task)."""
        if any(t.get(k) is not None and not isinstance(t[k], np.ndarray) for k in _TABLES):
            # (tables already uploaded: their rows are those of the tasks they were uploaded for, which a subset's
            # new row numbers would no longer match)
            raise ValueError("_tables takes the tasks' numpy tables, not tables already uploaded")
        out = {k: host_array(self._mi.Float, t[k]) for k in _TABLES if isinstance(t.get(k), np.ndarray)}
        out["row"] = np.arange(len(t["k"]), dtype=np.uint32)
        return out

    def _lanes(self, t, n_lanes, packet=None):
        """Return the :class:`_Lanes` of tasks ``t`` (a dict of per-task numpy fields, None where absent) for a
        launch of ``n_lanes`` lanes; ``packet``: the task of each packet of lanes (:meth:`_launches`).

        Integer fields (and ``m``, the strata parameter, which the kernels read as an integer) become uint32
        columns; ``m`` also gives the float columns ``inv_m`` (1 / m) and ``half_inv_m`` (0.5 / m), divided in
        float64 as the kernels' inputs always were; the rest float32 columns (rounded from float64 once, on
        assignment, as a separate upload of each field rounded them)."""
        dr, mi = self._dr, self._mi
        T = len(t["key"])
        layout, tables, fields = [], {}, []
        nf = nu = 0
        for name, v in t.items():
            if v is None:
                continue
            if name in _TABLES:
                tables[name] = v                    # uploaded once for all the tasks (_tables)
                continue
            v = np.asarray(v)
            if name == "m":
                parts = [(name, v.astype(np.uint32), True), ("inv_m", 1.0 / v, False), ("half_inv_m", 0.5 / v, False)]
            else:
                parts = [(name, v, v.dtype.kind in "iub")]
            for name_, v_, integer in parts:
                v_ = v_.reshape(T, -1)
                layout.append((name_, nu if integer else nf, v_.shape[1], integer))
                fields.append(v_)
                if integer:
                    nu += v_.shape[1]
                else:
                    nf += v_.shape[1]
        # filled in place in Dr.Jit-safe buffers and handed over without another copy (simcore._llvm.host_buffer)
        f, u = host_buffer(T * nf, np.float32), host_buffer(T * nu, np.uint32)
        f2, u2 = f.reshape(T, nf), u.reshape(T, nu)
        for (_, c, w, integer), v in zip(layout, fields):
            (u2 if integer else f2)[:, c:c + w] = v
        tables["refl"] = self._refl_dr
        tables["refl_max"] = self._refl_max_dr
        if self._sea_dr is not None:
            tables["sea"] = self._sea_dr
            tables["sea_max"] = self._sea_max_dr
        if self._vis is not None:
            tables["vis"] = self._vis
        if packet is not None:
            # (a 1-element array would be a literal baked into the kernel: a lone packet gets an unread second)
            tables["packet"] = host_array(mi.UInt32, packet if len(packet) > 1 else np.concatenate([packet, packet]))
        # The lanes' counter, evaluated: the one array the kernels read lane by lane, which gives a frozen kernel
        # its launch size (_run)
        lane = dr.arange(mi.UInt32, n_lanes)
        dr.make_opaque(lane)
        return _Lanes(host_wrap(mi.Float, f), host_wrap(mi.UInt32, u), tables, tuple(layout), nf, nu, lane, self._scene)

    def _run(self, kernel, lanes, *args):
        """Return ``kernel(lanes, *args)`` (a Dr.Jit array), the direct, albedo and proposal kernels replayed from a
        ``drjit.freeze`` recording: traced once per layout of their inputs, then launched without tracing again.

        Sound here because everything a launch's values depend on reaches the kernel as a traversed input: the
        tasks' fields, tables and lane indices are the arrays of ``lanes`` (a :class:`_Lanes`: its ``layout``,
        ``nf``, ``nu`` and the Python ``args`` are part of the recording's key, so a task dict with other fields
        records anew), the occluders are ``lanes.scene``, and the renderer's own settings that shape the traced
        code are ``_kernel_state`` (also part of the key). The launch size follows the lanes' counter
        (``lanes.lane``: the only array the kernels read lane by lane; all else is gathered), and no kernel reads a
        size or an element into Python. The reflected kernel is not frozen: its wavefront compacts the live paths
        (``drjit.compress``), whose count depends on the data, and would record anew at every call. Variants not in
        ``_FREEZE_VARIANTS`` trace every launch.

        Either way the result passes through :func:`_anchored`: where the tracer folds a kernel's result to a
        constant (a bare diode and no mesh: every lane reads 1), it would otherwise come back as one value instead
        of the launch's lanes (seen on cuda_ad_mono, which traced every launch unanchored)."""
        if kernel.__name__ == "_reflected_kernel":
            return kernel(lanes, *args)
        if self.variant not in _FREEZE_VARIANTS:
            return _anchored(self._dr, lanes, kernel(lanes, *args))
        frozen = self._frozen.get(kernel.__name__)
        if frozen is None:
            dr = self._dr
            # Weak references to the renderer: the wrappers it holds must not hold it, or it would die only in the
            # cycle collector, at any time, possibly inside another recording, where releasing its numpy-backed
            # arrays aborts the process (Dr.Jit 1.5: "enqueue_host_func(): this function cannot be recorded!").
            kernel_ref, state_ref = weakref.WeakMethod(kernel), weakref.WeakMethod(self._kernel_state)

            def anchored(lanes, *args):
                # a recording of a kernel folded to a constant would hand back a constant of the recorded launch's
                # size: anchored, it is a kernel whose size is the lanes'
                return _anchored(dr, lanes, kernel_ref()(lanes, *args))
            frozen = self._frozen[kernel.__name__] = dr.freeze(
                anchored, state_fn=lambda *a, **k: state_ref()(*a, **k))
        # No cycle collection while recording or replaying: garbage from elsewhere holding numpy-backed Dr.Jit
        # arrays, released inside the frozen call, would abort the process as above.
        with _no_cycle_collection(), _llvm.FROZEN_CALLS:    # (see _llvm.FROZEN_CALLS: another thread's Dr.Jit work)
            return frozen(lanes, *args)

    def _kernel_state(self, *args, **kwargs):
        """Return the renderer's settings that shape the traced direct, albedo and proposal kernels (part of their
        frozen recordings' key, :meth:`_run`)."""
        return (self.variant, self.sun_angular_radius_rad, self.control_variate, self.earth_radius_m,
                self.lon_west_rad, self.reflectivity.shape, self._win is None,
                bool(self.control_variate and self._plain.any()),
                None if self._glint is None else (self._glint.mss, self._glint.index, self._glint.tau))

    def _col(self, a, name, i=0):
        """Return column ``i`` of field ``name`` of the lanes' tasks (:class:`_Lanes`): mi.Float, or mi.UInt32 for
        an integer field."""
        dr, mi = self._dr, self._mi
        c, _, in_u = a.column(name)
        if in_u:
            return dr.gather(mi.UInt32, a.u, a.task * a.nu + (c + i))
        return dr.gather(mi.Float, a.f, a.task * a.nf + (c + i))

    def _vec(self, a, name, row=0):
        """Return the 3-vector ``row`` (columns 3 row .. 3 row + 2) of field ``name`` of the lanes' tasks."""
        return self._mi.Vector3f(*(self._col(a, name, 3 * row + i) for i in range(3)))

    def _rand(self, key, j, k):
        """Return 2k uniform [0, 1) floats per lane: the two of TEA(key, j*k) (``_TEA_ROUNDS`` rounds: the lane's
        numbers independent of its neighbours'), then 2k - 2 from a PCG32 generator that those two 32-bit words
        seed (its state; one multiply-add a number instead of ~30 rounds of TEA)."""
        mi = self._mi
        a, b = mi.sample_tea_32(key, j * k, _TEA_ROUNDS)
        out = [mi.Float(a >> 8) * (1.0 / 16777216.0), mi.Float(b >> 8) * (1.0 / 16777216.0)]
        if k > 1:
            rng = mi.PCG32()
            rng.seed(initstate=(mi.UInt64(a) << 32) | mi.UInt64(b))
            out += [mi.Float(rng.next_uint32() >> 8) * (1.0 / 16777216.0) for _ in range(2 * k - 2)]
        return out

    def _blocked_by_mesh(self, a, o, d, active=True):
        """Return whether the ray from ``o`` along ``d`` meets the mesh (``a.scene``, :class:`_Lanes`); False for
        lanes not ``active`` (those whose value cannot depend on it: their rays are not traced)."""
        if a.scene is None:
            return self._mi.Bool(False)       # (a scalar, no array of a recorded launch's width)
        return a.scene.ray_test(self._mi.Ray3f(o, d), active)

    # -- lanes: task k owns counts[k] consecutive lanes (its samples), split into launches
    def _launches(self, counts):
        """Yield (task slice, the task of each packet of ``_PACKET`` lanes (np.uint32), each task's first lane
        (np.uint32)) per launch, for tasks of ``counts`` (T,) samples each, positive multiples of ``_PACKET``.

        Per packet rather than per lane: the kernels find a lane's task and sample index from these
        (:meth:`_with_indices`), so that the host builds 1/16 of the lanes' worth of indices."""
        if len(counts) and (counts.min() < 1 or np.any(counts % _PACKET)):
            raise ValueError(f"every task needs a positive multiple of {_PACKET} samples, got counts "
                             f"{counts.min()} .. {counts.max()}")
        ends = np.cumsum(counts)
        start = 0
        while start < len(counts):
            base = ends[start] - counts[start]
            stop = int(np.searchsorted(ends, base + _MAX_LANES, side="right"))
            stop = max(stop, start + 1)
            if stop == start + 1 and len(counts) > start + 1:
                stop = start + 2                  # keep >= 2 tasks: a 1-element array is a literal
            sl = slice(start, stop)
            c = counts[sl]                                    # (a launch holds < 2^32 lanes)
            yield sl, np.repeat(np.arange(len(c), dtype=np.uint32), c // _PACKET), (np.cumsum(c) - c).astype(np.uint32)
            start = stop

    def _with_indices(self, a):
        """Return the lanes ``a`` (:class:`_Lanes` of a :meth:`_trace` launch) with each lane's task and sample index
        (``task``, ``j``): the task of its packet (``tables['packet']``) and its offset from the task's first lane
        (column ``first``)."""
        dr, mi = self._dr, self._mi
        task = dr.gather(mi.UInt32, a.tables["packet"], a.lane >> int(np.log2(_PACKET)))
        a = replace(a, task=task)
        return replace(a, j=a.lane - self._col(a, "first"))

    def _trace(self, kernel, t, counts):
        """Return the per-lane values (sum(counts),) float32 of ``kernel`` over tasks ``t`` (their lanes laid out task
        after task, each task's first lane on a multiple of ``_PACKET``)."""
        T = len(counts)
        if T < 2:                                 # a 1-element array would be baked in as a literal
            t = _pad2(t)
            return self._trace(kernel, t, np.concatenate([counts, [2]]))[:int(counts.sum())]
        # each task's lanes start on a packet boundary (the extra lanes, samples past its count, are dropped)
        padded = -(-counts // _PACKET) * _PACKET
        out = []
        for sl, packet, first in self._launches(padded):
            sub = dict(_take(t, sl), first=first)
            if sl.stop - sl.start < 2:
                sub = _pad2(sub)
            out.append(self._run(kernel, self._lanes(sub, len(packet) * _PACKET, packet)).numpy())
        vals = out[0] if len(out) == 1 else np.concatenate(out)
        if np.array_equal(padded, counts):
            return vals
        return vals[np.repeat(np.tile([True, False], len(counts)), np.column_stack([counts, padded - counts]).ravel())]

    # -- where the analytic well lets light through (aperture split, see _rounds)
    def _well_rect(self, a, d, key="ap"):
        """Return (x0, x1, y0, y1, lit) for unit directions ``d``: the rectangle of the diode
        (fractions of its sides, centred, so within [-1/2, 1/2]) whose rays toward ``d`` leave
        through the opening of the diode's analytic well (``simcore.shapes.aperture.WellAperture``
        geometry: the opening shifted by -h tan along each wall axis), and its area fraction,
        the lit fraction. ``key``: "ap" (the split's and the probes' rectangle) or "ap_hint" (the albedo
        proposal's)."""
        dr, mi = self._dr, self._mi
        fr = [self._vec(a, "frame", k) for k in range(3)]
        du, dv, dn = dr.dot(fr[0], d), dr.dot(fr[1], d), dr.dot(fr[2], d)
        rims = [self._col(a, key, k) for k in range(8)]  # half diode; half opening and height of the lower and top rims
        return lit_rectangle_of(rims, du, dv, dn, maximum=dr.maximum, minimum=dr.minimum, where=dr.select)

    def _split_point(self, a, d, fx, fy):
        """Return (fx, fy, weight) of the diode point for a lane of mode 0 (plain: the point as
        drawn, weight 1), 1 (inside the analytic well's lit rectangle: the point mapped into it,
        weight = its area) or 2 (the rest: the point as drawn, weight 0 inside the rectangle)."""
        dr, mi = self._dr, self._mi
        if not self.control_variate:
            return fx, fy, mi.Float(1.0)
        mode = self._col(a, "mode")
        x0, x1, y0, y1, lit = self._well_rect(a, d)
        in_a = mode == 1
        gx = dr.select(in_a, x0 + (x1 - x0) * (fx + 0.5), fx)
        gy = dr.select(in_a, y0 + (y1 - y0) * (fy + 0.5), fy)
        inside = (lit > 0) & (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
        wgt = dr.select(in_a, lit, dr.select((mode == 2) & inside, 0.0, 1.0))
        return gx, gy, wgt

    # -- a window over the diode (simcore.shapes.window): one helper for the kernels
    def _window_exit(self, a, o, d, fx, fy, u):
        """Return (exit point, weight, length of the segment to the lower face, has a window) for light reaching
        the diode point ``o`` (at fractions ``fx``, ``fy`` of its sides) from unit directions ``d`` (body frame)
        through the task's window, one uniform ``u`` per lane: the slab's terms k = 0..K (K the last whose exit
        point stays in the footprint, closed form) carry c q^k per polarisation
        (:meth:`simcore.shapes.window.Window.terms`); k is drawn with probability proportional to the mean
        over s and p of that term (a polarisation by its share of the partial sum, then k from its truncated
        geometric law by inversion) and the weight is the partial sum (mean over s and p): unbiased, and
        exact whatever k is drawn when nothing shades the window. Tasks without a window: (o, 1, 0, False)."""
        dr, mi = self._dr, self._mi
        n_i, th, gap, hx, hy, alpha, sx, sy, has = (self._col(a, "win", i) for i in range(9))
        fr = [self._vec(a, "frame", k) for k in range(3)]
        du, dv, dn = dr.dot(fr[0], d), dr.dot(fr[1], d), dr.dot(fr[2], d)
        c = dr.maximum(dn, 1e-12)
        ct = dr.sqrt(dr.maximum(1.0 - (du * du + dv * dv) / (n_i * n_i), 0.0))     # cos theta_t
        rs = dr.square((c - n_i * ct) / (c + n_i * ct))
        rp = dr.square((ct - n_i * c) / (ct + n_i * c))
        att = dr.exp(-alpha * th / dr.maximum(ct, 1e-12))          # one pass through the slab
        g_c, inner = gap / c, th / (n_i * dr.maximum(ct, 1e-12))  # lateral walk per unit |d_uv|: to p1, per pass

        def k_axis(dx, half, x):
            # |dx| (gap / cos + (2k + 1) inner) <= half - sign(dx) x  (exit point inside the footprint)
            room = half - dr.select(dx > 0, x, -x)
            ad = dr.abs(dx)
            k = dr.floor(((room / dr.maximum(ad, 1e-20) - g_c) / inner - 1.0) * 0.5)
            return dr.select(ad > 1e-12, dr.minimum(k, 1e9), 1e9)

        K = dr.maximum(dr.minimum(k_axis(du, hx, fx * sx), k_axis(dv, hy, fy * sy)), -1.0)

        def partial(r):
            q = dr.maximum(dr.square(r * att), 1e-30)
            qK = dr.exp((K + 1.0) * dr.log(q))
            return q, qK, dr.square(1.0 - r) * att * (1.0 - qK) / (1.0 - q)

        qs, qKs, Ss = partial(rs)
        qp, qKp, Sp = partial(rp)
        tot = Ss + Sp
        ps = Ss / dr.maximum(tot, 1e-30)
        use_s = u < ps
        u2 = dr.select(use_s, u / dr.maximum(ps, 1e-30), (u - ps) / dr.maximum(1.0 - ps, 1e-30))
        u2 = dr.clip(u2, 0.0, 1.0 - 1.0 / 16777216.0)
        q, qK = dr.select(use_s, qs, qp), dr.select(use_s, qKs, qKp)
        k = dr.clip(dr.floor(dr.log(1.0 - u2 * (1.0 - qK)) / dr.log(q)), 0.0, dr.maximum(K, 0.0))
        win = has > 0.5
        lateral = d - dn * fr[2]
        exit_ = o + (g_c + (2.0 * k + 1.0) * inner) * lateral + (gap + th) * fr[2]
        weight = dr.select(win, dr.select(K >= 0.0, 0.5 * tot, 0.0), 1.0)
        return dr.select(win, exit_, o), weight, dr.select(win, g_c, 0.0), win

    def _through_window(self, a, o, d, fx, fy, u, active=True):
        """Return (exit point, weight, blocked) for light reaching the diode point ``o`` (at fractions ``fx``,
        ``fy`` of its sides) from unit directions ``d`` (body frame) through the task's window, one uniform
        ``u`` per lane (:meth:`_window_exit`): blocked when the mesh meets the segment from ``o`` to the
        window's lower face or the ray leaving the upper face at the drawn exit point along ``d``. Tasks
        without a window get (o, 1, the plain ray's test). Lanes not ``active`` trace neither ray (blocked False)."""
        exit_, weight, seg, win = self._window_exit(a, o, d, fx, fy, u)
        blocked = self._blocked_by_mesh(a, exit_, d, active)
        if a.scene is not None:
            mi = self._mi
            blocked |= a.scene.ray_test(mi.Ray3f(mi.Ray3f(o, d), seg), active & win & (seg > 0.0))
        return exit_, weight, blocked

    def _window_first_segment(self, scene, a, o, d, fx, fy, u):
        """Return (origin, weight) of a reflected path's first ray from the diode point ``o`` along ``d``: when
        nothing of the path-traced ``scene`` lies between ``o`` and the window's lower face, the light crossed
        the window: the ray starts at the drawn exit point of the upper face and the path carries the slab's
        weight (:meth:`_window_exit`); else (a well wall under the window) it starts at ``o`` with weight 1
        (what reaches that wall through the window is not attenuated by it: the window is traced on the
        diode's own first segment only)."""
        mi, dr = self._mi, self._dr
        exit_, weight, seg, win = self._window_exit(a, o, d, fx, fy, u)
        under = scene.ray_test(mi.Ray3f(mi.Ray3f(o, d), seg), win & (seg > 0.0))
        cross = win & ~under
        return dr.select(cross, exit_, o), dr.select(cross, weight, 1.0)

    def _round_cv(self, a, d, fx, fy):
        """Return the control variate of a round well's lanes (mode 3; 0 for the others): the closed-form lit
        fraction of the diode through the rim's disc toward ``d`` (CircularWell, the Dr.Jit form of
        simcore.shapes.aperture.disc_rectangle_overlap) minus 1 where the lane's diode point (fx, fy) lies in
        that lit part. Its mean over the diode is 0 for any ``d``, so the estimate stays unbiased whatever the
        mesh; the lane's traced 1 or 0 and this term cancel where the mesh is the analytic well."""
        dr, mi = self._dr, self._mi
        if not (self.control_variate and self._plain.any()):
            return 0.0                      # no round well: the kernels stay as they were
        mode = self._col(a, "mode")
        ax, ay = self._col(a, "ap", 0), self._col(a, "ap", 1)                # half diode sides, m
        r, h = self._col(a, "round", 0), self._col(a, "round", 1)
        fr = [self._vec(a, "frame", k) for k in range(3)]
        du, dv, dn = dr.dot(fr[0], d), dr.dot(fr[1], d), dr.dot(fr[2], d)
        inv = 1.0 / dr.maximum(dn, 1e-12)
        sx, sy = h * du * inv, h * dv * inv                                   # the ray's offset at the rim
        px, py = 2.0 * ax * fx + sx, 2.0 * ay * fy + sy
        inside = px * px + py * py <= r * r
        # the lit fraction, in units of the half side ax and in float64 (the closed form's differences of disc
        # segments cancel: float32 would leave ~1e-7 where the disc lights nothing); within 1e-9 of 0 or 1 it
        # is 0 or 1 (as the rectangles' exact zeros and ones: at most 1.4e-6 W/m^2)
        F = mi.Float64
        s = 1.0 / F(ax)
        area = disc_rectangle_overlap(F(-sx) * s, F(-sy) * s, dr.maximum(F(r) * s, 1e-6), -1.0, 1.0, -F(ay) * s,
                                      F(ay) * s, ops=_DrOps(dr))
        lit = area / (4.0 * F(ay) * s)
        lit = mi.Float(dr.select(lit < 1e-9, 0.0, dr.select(lit > 1.0 - 1e-9, 1.0, lit)))
        return dr.select((mode == 3) & (dn > 0), lit - dr.select(inside, 1.0, 0.0), 0.0)

    # -- direct Sun kernel
    def _direct_kernel(self, a):
        dr, mi = self._dr, self._mi
        a = self._with_indices(a)
        task, j = a.task, a.j
        # Strata: the 2 m^2 diamonds (squares turned 45 deg) around the points (k, l) / 2m of
        # the unit torus with k + l even, so that the aperture walls' edges, parallel to the
        # diode's sides, cut many strata obliquely instead of one row of them.
        # (max: lanes past the end of the last SIMD packet gather 0, and x86 traps on x / 0)
        m = dr.maximum(self._col(a, "m"), 1)
        h = j >> 1
        row = h // m
        col = ((h - row * m) << 1) + (row & 1)
        key = self._col(a, "key")
        r = self._rand(key, j, 2)
        inv = self._col(a, "half_inv_m")
        fx = (mi.Float(col) + r[0] + r[1] - 1.0) * inv
        fy = (mi.Float(row) + r[0] - r[1]) * inv
        fx = fx - dr.floor(fx) - 0.5
        fy = fy - dr.floor(fy) - 0.5
        s = self._vec(a, "sun")
        if self.sun_angular_radius_rad > 0:
            # Uniform in solid angle over the disc: 1 - cos a = xi * (1 - cos a_max).
            omc = r[2] * dr.opaque(mi.Float, 2.0 * np.sin(self.sun_angular_radius_rad / 2) ** 2)
            sin_a = dr.sqrt(dr.maximum(omc * (2.0 - omc), 0.0))
            phi = r[3] * (2.0 * np.pi)
            e1, e2 = mi.coordinate_system(s)
            d = dr.normalize(s * (1.0 - omc) + sin_a * (dr.cos(phi) * e1 + dr.sin(phi) * e2))
        else:
            d = s
        fx, fy, wgt = self._split_point(a, d, fx, fy)
        o = self._vec(a, "pos") + fx * self._vec(a, "U") + fy * self._vec(a, "V")
        # (the rays of lanes that read 0 whatever they meet are not traced)
        traced = wgt > 0
        behind_earth = None
        if a.has("earth"):
            c = self._vec(a, "earth")
            b = dr.dot(d, c)
            perp = c - b * d
            behind_earth = (b > 0) & (dr.squared_norm(perp) < dr.opaque(mi.Float, self.earth_radius_m ** 2))
            traced &= ~behind_earth
        if self.sun_angular_radius_rad > 0:
            cos_nd = dr.dot(self._vec(a, "n"), d)
            traced &= cos_nd > 0
        if self._win is None:
            blocked = self._blocked_by_mesh(a, o, d, traced)
        else:
            a_, _ = mi.sample_tea_32(key ^ mi.UInt32(_WINDOW_KEY), j, _TEA_ROUNDS)
            o, tw, blocked = self._through_window(a, o, d, fx, fy, mi.Float(a_ >> 8) * (1.0 / 16777216.0), traced)
            wgt = wgt * tw
        cv = self._round_cv(a, d, fx, fy)
        if behind_earth is not None:
            blocked |= behind_earth
            cv = dr.select(behind_earth, 0.0, cv)
        val = dr.select(blocked, 0.0, wgt) + cv
        if self.sun_angular_radius_rad > 0:
            val = val * dr.maximum(cos_nd, 0.0)
        return val

    # -- albedo kernel
    def _albedo_kernel(self, a):
        dr, mi = self._dr, self._mi
        a = self._with_indices(a)
        task, j = a.task, a.j
        B = _N_T * _N_P
        h = j >> 1
        key = self._col(a, "key")
        r = self._rand(key, j, 3)
        inv_m = self._col(a, "inv_m")
        u = (mi.Float(h) + r[0]) * inv_m
        # Bin by binary search in the task's inclusive CDF (count of entries <= u).
        cdf = a.tables["cdf"]
        row = self._col(a, "row")                   # the task's row of the tables
        base = row * B
        lo = mi.UInt32(0)                   # (a scalar: it widens to the lanes' with the first select)
        step = B // 2
        while step >= 1:
            probe = dr.gather(mi.Float, cdf, base + lo + (step - 1))
            lo = dr.select(probe <= u, lo + step, lo)
            step //= 2
        b = dr.minimum(lo, B - 1)
        pmf = dr.gather(mi.Float, a.tables["pmf"], base + b)
        bt = b >> int(np.log2(_N_P))
        bp = b & (_N_P - 1)
        xmax = self._col(a, "xmax")
        edges = a.tables["tedge"]
        t0 = dr.gather(mi.Float, edges, row * (_N_T + 1) + bt)
        dt = dr.gather(mi.Float, edges, row * (_N_T + 1) + bt + 1) - t0
        g3 = lambda k: self._vec(a, k)  # noqa: E731
        d = self._cap_direction(g3("w"), g3("e1"), g3("e2"), xmax, t0 + dt * r[1],
                                (mi.Float(bp) + r[2]) * (2.0 * np.pi / _N_P))
        fx, fy, wgt = self._split_point(a, d, r[3] - 0.5, r[4] - 0.5)
        o = g3("pos") + fx * g3("U") + fy * g3("V")
        cos_d = dr.dot(g3("n"), d)
        rot = [self._vec(a, "rot", k) for k in range(3)]
        hit, cos_sun, rho = self._earth_along(d, g3("earth"), g3("sun"), rot, a.tables["refl"], a.tables.get("sea"))
        ok = hit & (cos_sun > 0) & (cos_d > 0)
        # (the rays of lanes that read 0 whatever they meet are not traced)
        if self._win is None:
            blocked = self._blocked_by_mesh(a, o, d, ok & (wgt > 0))
        else:
            o, tw, blocked = self._through_window(a, o, d, fx, fy, r[5], ok & (wgt > 0))
            wgt = wgt * tw
        f = dr.select(blocked, 0.0, wgt) + self._round_cv(a, d, fx, fy)
        # f / q with q = pmf_b / Omega_b, Omega_b = 2 pi xmax dt / N_P; L = rho E cos_sun / pi
        return dr.select(ok, f * rho * cos_sun * cos_d * (2.0 / _N_P) * xmax * dt / pmf, 0.0)

    # -- reflected kernel: paths from the diode off the spacecraft's BSDFs (module docstring)
    def _reflected_kernel(self, a):
        """Return the per-lane ``reflected`` irradiance (W/m^2) of tasks ``a`` (:class:`_Lanes`): a wavefront, one launch per
        path vertex, whose code does not depend on the depth (it is compiled once and reused); after each
        launch the paths still in flight are compacted (most leave the spacecraft at once)."""
        dr, mi = self._dr, self._mi
        a = self._with_indices(a)
        task, j = a.task, a.j
        n_lanes = dr.width(task)
        total = dr.zeros(mi.Float, n_lanes)
        lane = dr.arange(mi.UInt32, n_lanes)
        scene = self._pt
        D = self.max_depth
        n_pairs = 2 + 4 * D + 4                       # TEA calls per lane (2 floats each)
        a_sun = self.sun_angular_radius_rad if self.sun_angular_radius_rad > 0 else SUN_ANGULAR_RADIUS_RAD
        omc_max = 2.0 * np.sin(a_sun / 2) ** 2        # 1 - cos a
        p_sun = 1.0 / (2.0 * np.pi * omc_max)         # uniform in solid angle over the disc
        has_earth = a.has("earth")
        do_albedo = a.has("rot")
        ctx = mi.BSDFContext()

        def env():
            """Per-lane task data (gathered anew in each launch)."""
            g3 = lambda k: self._vec(a, k)  # noqa: E731
            v = dict(key=self._col(a, "key"), s=g3("sun"), pos=g3("pos"), E=self._col(a, "E"))
            # disc radiance: int L cos(d, s) dOmega = E  =>  L = E / (Omega (1 + cos a) / 2)
            v["L_sun"] = v["E"] * dr.opaque(mi.Float, 2.0 * p_sun / (2.0 - omc_max))
            if has_earth:
                v["c0"] = g3("earth")                 # Earth's centre from the diode's centre
            if do_albedo:
                v.update(s_e=g3("sun_e"), w=g3("w"), e1=g3("e1"), e2=g3("e2"),
                         E_e=self._col(a, "E_e"), xmax=self._col(a, "xmax"),
                         rot=[self._vec(a, "rot", k) for k in range(3)])
                v["p_earth"] = 1.0 / (2.0 * np.pi * v["xmax"])   # uniform in solid angle over the cap
            return v

        def rand(v, first_pair, n):
            """Return 2n uniform floats from the lane's TEA stream, pairs first_pair.. (opaque: one kernel)."""
            idx = j * n_pairs + dr.opaque(mi.UInt32, first_pair)
            out = []
            for i in range(n):
                x, y = mi.sample_tea_32(v["key"], idx + i, _TEA_ROUNDS)
                out += [mi.Float(x >> 8) * (1.0 / 16777216.0), mi.Float(y >> 8) * (1.0 / 16777216.0)]
            return out

        def earth_blocks(c, dd):
            b = dr.dot(dd, c)
            return (b > 0) & (dr.squared_norm(c - b * dd) < dr.opaque(mi.Float, self.earth_radius_m ** 2))

        def spawn(si, dd):
            nn = si.n
            return si.p + nn * dr.select(dr.dot(nn, dd) > 0, _SPAWN_EPS_M, -_SPAWN_EPS_M)

        def power(pa, pb):
            return dr.select(pa > 0, pa * pa / (pa * pa + pb * pb), 0.0)

        def in_disc(dd, axis):
            # |dd - axis|^2 = 2 (1 - cos): a float32 dot product near 1 errs by ~1e-7, 1 % of 1 - cos a
            return dr.squared_norm(dd - axis) <= dr.opaque(mi.Float, 2.0 * omc_max)

        def disc_dir(axis, u1, u2):
            omc = u1 * omc_max
            sin_t = dr.sqrt(dr.maximum(omc * (2.0 - omc), 0.0))
            phi = u2 * (2.0 * np.pi)
            b1, b2 = mi.coordinate_system(axis)
            return dr.normalize(axis * (1.0 - omc) + sin_t * (dr.cos(phi) * b1 + dr.sin(phi) * b2))

        planes = self._mirror_normals

        def p_spec(v, dd):
            """Density (1/sr) of the mirror-image strategy for diode directions dd."""
            cnt = mi.Float(0.0)
            for pl in planes:
                m_ = mi.Vector3f(*map(float, pl))
                cnt += dr.select(in_disc(dd, v["s"] - 2.0 * dr.dot(v["s"], m_) * m_), 1.0, 0.0)
            return cnt * (p_sun / len(planes))

        # ---- launch 0: the diode point, the first direction and the mirror-image strategy
        v = env()
        m = dr.maximum(self._col(a, "m"), 1)
        h = j >> 1
        row = h // m
        col = ((h - row * m) << 1) + (row & 1)
        r = rand(v, 0, 2)
        inv = self._col(a, "half_inv_m")
        fx = (mi.Float(col) + r[0] + r[1] - 1.0) * inv
        fy = (mi.Float(row) + r[0] - r[1]) * inv
        fx = fx - dr.floor(fx) - 0.5
        fy = fy - dr.floor(fy) - 0.5
        fr = [self._vec(a, "frame", k) for k in range(3)]
        o = v["pos"] + fx * self._vec(a, "U") + fy * self._vec(a, "V")
        # first direction: the hit-table proposal mixed with cosine-weighted sampling (_hit_table)
        B = _HIT_NT * _HIT_NP
        hit = self._hit
        kk = self._col(a, "k")
        beta = self._col(a, "beta")
        cos_edges = host_array(mi.Float, np.cos(hit["th_e"]))
        omega = host_array(mi.Float, hit["omega"])
        rx = rand(v, 5 + 4 * D, 1)
        loc = mi.warp.square_to_cosine_hemisphere(mi.Point2f(r[2], r[3]))
        lo = mi.UInt32(0)                   # (a scalar: it widens to the lanes' with the first select)
        step = 1 << int(np.ceil(np.log2(B)))
        while step >= 1:
            idx = dr.minimum(lo + (step - 1), B - 1)
            probe = dr.gather(mi.Float, hit["cdf"], kk * B + idx)
            lo = dr.select((probe <= r[2]) & (lo + step <= B), lo + step, lo)
            step //= 2
        b = dr.minimum(lo, B - 1)
        row, col = b // _HIT_NP, b % _HIT_NP
        c0_, c1_ = dr.gather(mi.Float, cos_edges, row), dr.gather(mi.Float, cos_edges, row + 1)
        ct = c0_ - r[3] * (c0_ - c1_)
        st_ = dr.sqrt(dr.maximum(1.0 - ct * ct, 0.0))
        phi_ = (mi.Float(col) + rx[1]) * (2.0 * np.pi / _HIT_NP) - np.pi
        use_cos = rx[0] < beta
        lx = dr.select(use_cos, loc.x, st_ * dr.cos(phi_))
        ly = dr.select(use_cos, loc.y, st_ * dr.sin(phi_))
        lz = dr.select(use_cos, loc.z, ct)
        d = dr.normalize(lx * fr[0] + ly * fr[1] + lz * fr[2])

        def pdf_dir(dd):
            """Density (1/sr) of the first-direction proposal for diode directions dd."""
            cz = dr.dot(fr[2], dd)
            th = dr.acos(dr.clip(cz, -1.0, 1.0))
            rw = mi.UInt32(dr.clip(mi.Int32(th * (_HIT_NT / (0.5 * np.pi))), 0, _HIT_NT - 1))
            cl = mi.UInt32(dr.clip(mi.Int32((dr.atan2(dr.dot(fr[1], dd), dr.dot(fr[0], dd)) + np.pi)
                                            * (_HIT_NP / (2.0 * np.pi))), 0, _HIT_NP - 1))
            cell = rw * _HIT_NP + cl
            tab = dr.gather(mi.Float, hit["pmf"], kk * B + cell) / dr.gather(mi.Float, omega, cell)
            return dr.select(cz > 0, beta * cz * (1.0 / np.pi) + (1.0 - beta) * tab, 0.0)

        pdf0 = pdf_dir(d)
        cos0 = dr.dot(fr[2], d)
        # the path's sums are radiances times cos / (pi pdf); x pi at the end: irradiance = E[L cos / pdf]
        thr0 = dr.select((pdf0 > 0) & (cos0 > 0), cos0 / (np.pi * dr.maximum(pdf0, 1e-30)), 0.0)
        o0 = o
        if self._win is not None:
            # a window over the diode: the first segment crosses it (directions stay; origin and weight change)
            uw = [mi.Float(x >> 8) * (1.0 / 16777216.0)
                  for x in mi.sample_tea_32(v["key"] ^ mi.UInt32(_WINDOW_KEY), j, _TEA_ROUNDS)]
            o0, tw = self._window_first_segment(scene, a, o, d, fx, fy, uw[0])
            thr0 = thr0 * tw
        acc = mi.Float(0.0)
        if planes is not None:
            # The Sun seen in a smooth mirror-like face (a delta lobe: no next-event estimate reaches it, and a
            # cosine-drawn direction meets the 0.5 deg image with probability ~1e-5): draw a plane
            # orientation, then a direction uniform over the Sun's mirror image in it, from the diode.
            P = len(planes)
            rs = rand(v, 2 + 4 * D, 3)
            pick = dr.minimum(mi.UInt32(rs[0] * P), P - 1)
            img = None
            for i, pl in enumerate(planes):
                m_ = mi.Vector3f(*map(float, pl))
                im = v["s"] - 2.0 * dr.dot(v["s"], m_) * m_
                img = im if img is None else dr.select(pick == i, im, img)
            dm = disc_dir(img, rs[1], rs[2])
            cos_m = dr.dot(fr[2], dm)
            on = cos_m > 0
            o_m, tw_m = o, mi.Float(1.0)
            if self._win is not None:
                o_m, tw_m = self._window_first_segment(scene, a, o, dm, fx, fy, uw[1])
            si_m = scene.ray_intersect(mi.Ray3f(o_m, dm), on)
            on &= si_m.is_valid()
            bs_m, w_m = si_m.bsdf().sample(ctx, si_m, rs[3], mi.Point2f(rs[4], rs[5]), on)
            dn_m = si_m.to_world(bs_m.wo)
            on &= mi.has_flag(bs_m.sampled_type, mi.BSDFFlags.Delta) & in_disc(dn_m, v["s"]) & (w_m[0] > 0)
            on &= ~scene.ray_test(mi.Ray3f(spawn(si_m, dn_m), dn_m), on)
            if has_earth:
                on &= ~earth_blocks(v["c0"] - (si_m.p - v["pos"]), dn_m)
            ps = p_spec(v, dm)
            # this estimates irradiance directly; the path's sum below is multiplied by pi at the end
            acc = dr.select(on, tw_m * w_m[0] * v["L_sun"] * cos_m / ps * power(ps, pdf_dir(dm)), 0.0) / np.pi
        st = dict(o=o0, d=d, thr=thr0, acc=acc, active=dr.full(mi.Bool, True, dr.width(task)),
                  pdf=mi.Float(0.0), delta=dr.full(mi.Bool, False, dr.width(task)), p=mi.Point3f(o),
                  pdf0=pdf0, d0=d)
        dr.eval(st)

        # ---- launches 1..D (+1): a vertex each; the escape of the previous vertex's sampled direction first
        for depth in range(D + 1):
            v = env()
            dv = dr.opaque(mi.UInt32, depth)
            active, thr, acc = st["active"], st["thr"], st["acc"]
            si = scene.ray_intersect(mi.Ray3f(st["o"], st["d"]), active)
            hit = si.is_valid()
            if depth > 0:
                # ... it left the spacecraft: the Sun's disc or the Earth, weighted against next-event estimates
                out = active & ~hit
                c = (v["c0"] - (st["p"] - v["pos"])) if has_earth else None
                in_sun = out & in_disc(st["d"], v["s"])
                if has_earth:
                    in_sun &= ~earth_blocks(c, st["d"])
                w_delta = mi.Float(1.0)
                if planes is not None:          # the mirror-image strategy also draws diode -> mirror -> Sun
                    w_delta = dr.select(dv == 1, power(st["pdf0"], p_spec(v, st["d0"])), 1.0)
                acc += dr.select(in_sun, thr * v["L_sun"] * dr.select(st["delta"], w_delta,
                                                                      power(st["pdf"], mi.Float(p_sun))), 0.0)
                if do_albedo:
                    hit_e, cos_sun, rho = self._earth_along(st["d"], c, v["s_e"], v["rot"], a.tables["refl"], a.tables.get("sea"))
                    ok = out & hit_e & (cos_sun > 0)
                    L_e = rho * v["E_e"] * cos_sun * (1.0 / np.pi)
                    acc += dr.select(ok, thr * L_e * dr.select(st["delta"], 1.0, power(st["pdf"], v["p_earth"])), 0.0)
            if depth == D:
                dr.scatter_add(total, acc, lane)
                break
            active &= hit
            c = (v["c0"] - (si.p - v["pos"])) if has_earth else None
            bsdf = si.bsdf()
            r = rand(v, 2 + 4 * depth, 4)
            # (a) the Sun: a point on the disc
            ds = disc_dir(v["s"], r[0], r[1])
            f, pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds), active)
            ok = active & (f[0] > 0)
            ok &= ~scene.ray_test(mi.Ray3f(spawn(si, ds), ds), ok)
            if has_earth:
                ok &= ~earth_blocks(c, ds)
            acc += dr.select(ok, thr * f[0] * v["L_sun"] / p_sun * power(mi.Float(p_sun), pdf), 0.0)
            # (b) the Earth: a direction uniform in its cap
            if do_albedo:
                de = self._cap_direction(v["w"], v["e1"], v["e2"], v["xmax"], r[2], r[3] * (2.0 * np.pi))
                hit_e, cos_sun, rho = self._earth_along(de, c, v["s_e"], v["rot"], a.tables["refl"], a.tables.get("sea"))
                f, pdf = bsdf.eval_pdf(ctx, si, si.to_local(de), active)
                ok = active & hit_e & (cos_sun > 0) & (f[0] > 0)
                ok &= ~scene.ray_test(mi.Ray3f(spawn(si, de), de), ok)
                L_e = rho * v["E_e"] * cos_sun * (1.0 / np.pi)
                acc += dr.select(ok, thr * f[0] * L_e / v["p_earth"] * power(v["p_earth"], pdf), 0.0)
            # continue by BSDF sampling; Russian roulette from the fourth vertex on
            bs, wgt = bsdf.sample(ctx, si, r[4], mi.Point2f(r[5], r[6]), active)
            dn = si.to_world(bs.wo)
            thr = dr.select(active, thr * wgt[0], 0.0)
            rr = active & (dv + 1 >= _RR_DEPTH)
            keep = dr.minimum(thr, 0.95)
            survive = ~rr | (r[7] < keep)
            thr = dr.select(rr, dr.select(survive, thr / dr.maximum(keep, 1e-12), 0.0), thr)
            active &= survive & (thr > 0)
            st.update(o=spawn(si, dn), d=dn, thr=thr, acc=acc, active=active, pdf=bs.pdf,
                      delta=mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta), p=si.p)
            dr.eval(st)
            # bank what the paths gathered at this vertex, keep the live ones
            dr.scatter_add(total, st["acc"], lane)
            keep_idx = dr.compress(active)
            if dr.width(keep_idx) == 0:
                break
            st = {k: dr.gather(type(x), x, keep_idx) for k, x in st.items()}
            lane, task, j = (dr.gather(mi.UInt32, x, keep_idx) for x in (lane, task, j))
            if dr.width(keep_idx) < 2:   # a 1-element array would be baked into the kernel as a literal
                pad = mi.UInt32([0, 0])
                st = {k: dr.gather(type(x), x, pad) for k, x in st.items()}
                st["active"] = mi.Bool([True, False])
                lane, task, j = (dr.gather(mi.UInt32, x, pad) for x in (lane, task, j))
            st["acc"] = dr.zeros(mi.Float, dr.width(lane))
            dr.eval(st, lane, task, j)
            a = replace(a, task=task, j=j)       # env() reads the live lanes' tasks
        # irradiance = int L cos dOmega = pi E[L] for directions drawn with density cos / pi
        return total * np.pi

    # -- the Earth seen along a direction: shared by the albedo kernel and its proposal
    def _earth_along(self, d, c, s, rot, refl, sea=None, bound=None):
        """Return (hit, cos of the Sun at the Earth point, reflectivity there) for unit
        directions ``d`` from a point at ``-c`` from the Earth's centre (body axes); ``refl``: the reflectivity
        map as a Dr.Jit array (the renderer's, passed in so that frozen kernels see it as an input). With the
        renderer's glint, ``sea`` its sea fraction table (likewise): the reflectivity is then the Lambertian
        one that gives the same radiance toward -d, ``rho + pi sea f(s, -d)`` (L = rho E cos_sun / pi + sea E f
        cos_sun; f the Cox-Munk BRDF, :mod:`simcore.radiometry.glint`).

        ``bound``: (the map's :func:`reach_levels` table, the sea fraction's or None, each lane's level (UInt32)):
        the reflectivity is then followed by its bound at that level, the glint's BRDF taken at the point itself
        (smooth over a bin: a lobe tens of degrees wide) on the sea fraction's bound."""
        dr, mi = self._dr, self._mi
        nlat, nlon = self.reflectivity.shape
        R = self.earth_radius_m
        # Stable with the satellite at the origin: x_e = -perp - sqrt(R^2 - |perp|^2) d.
        bb = dr.dot(d, c)
        perp = c - bb * d
        q = dr.opaque(mi.Float, R * R) - dr.squared_norm(perp)
        hit = (bb > 0) & (q > 0)
        xe = -perp - dr.sqrt(dr.maximum(q, 0.0)) * d
        cos_sun = dr.dot(xe, s) * (1.0 / R)
        ex, ey, ez = dr.dot(rot[0], xe), dr.dot(rot[1], xe), dr.dot(rot[2], xe)
        lat = dr.atan2(ez, dr.sqrt(ex * ex + ey * ey))
        lon = dr.atan2(ey, ex)
        row = dr.clip(mi.Int32(dr.floor((lat + 0.5 * np.pi) * (nlat / np.pi))), 0, nlat - 1)
        col = mi.Int32(dr.floor((lon - self.lon_west_rad) * (nlon / (2.0 * np.pi))))
        col = dr.select(col < 0, col + nlon, col)
        col = dr.clip(dr.select(col >= nlon, col - nlon, col), 0, nlon - 1)
        cell = mi.UInt32(row * nlon + col)
        rho = dr.gather(mi.Float, refl, cell)
        if bound is not None:
            at = bound[2] * (nlat * nlon) + cell
            rho_max = dr.gather(mi.Float, bound[0], at)
        if sea is not None:
            g = self._glint
            cos_view = -dr.dot(xe, d) * (1.0 / R)
            q = _glint.reflected_cos2(cos_sun, cos_view, -dr.dot(s, d), g.mss, g.index, _DrOps(dr), g.tau)
            # f = q / (cos_sun cos_view); the floor only where q is 0 or the lane is dropped (cos_sun <= 0)
            f = q / dr.maximum(cos_sun * cos_view, 1e-12)
            rho = rho + np.pi * dr.gather(mi.Float, sea, cell) * f
            if bound is not None:
                rho_max = rho_max + np.pi * dr.gather(mi.Float, bound[1], at) * f
        if bound is not None:
            return hit, cos_sun, rho, rho_max
        return hit, cos_sun, rho

    def _cap_direction(self, w, e1, e2, xmax, t01, phi):
        """Return the unit direction at fraction ``t01`` of the cap's solid angle (counted from
        nadir ``w``) and azimuth ``phi`` about nadir."""
        dr = self._dr
        x = t01 * xmax                                    # 1 - cos(angle from nadir)
        sin_t = dr.sqrt(dr.maximum(x * (2.0 - x), 0.0))
        return dr.normalize((1.0 - x) * w + sin_t * (dr.cos(phi) * e1 + dr.sin(phi) * e2))

    # -- the albedo proposal: radiance x diode cosine x aperture fraction at bin corners/centres
    def _proposal_kernel(self, a, n_points):
        """Return the proposal's weights (T n_points,) at the bins' corners of tasks ``a`` (:class:`_Lanes`
        whose ``j`` counts the lanes 0 .. T n_points - 1, ``n_points`` per task)."""
        dr, mi = self._dr, self._mi
        i = a.lane
        task = i // n_points
        a = replace(a, task=task)
        p = i - task * n_points
        it = p // (_N_P + 1)                             # bin corners: (N_T + 1) x (N_P + 1)
        ip = p - it * (_N_P + 1)
        ring = self._col(a, "row") * (_N_T + 1) + it
        t01 = dr.gather(mi.Float, a.tables["tedge"], ring)
        phi = mi.Float(ip) * (2.0 * np.pi / _N_P)
        g3 = lambda k: self._vec(a, k)  # noqa: E731
        d = self._cap_direction(g3("w"), g3("e1"), g3("e2"), self._col(a, "xmax"), t01, phi)
        rot = [self._vec(a, "rot", k) for k in range(3)]
        # the map's bound over the ground of every bin that touches this corner (tlevel: _albedo_proposal)
        level = mi.UInt32(dr.gather(mi.Float, a.tables["tlevel"], ring))
        hit, cos_sun, rho, rho_max = self._earth_along(d, g3("earth"), g3("sun"), rot, a.tables["refl"],
                                                       a.tables.get("sea"),
                                                       (a.tables["refl_max"], a.tables.get("sea_max"), level))
        rho = dr.maximum(dr.abs(rho), (_BOUND_SHARE if self._glint is None else _BOUND_SHARE_GLINT) * rho_max)
        lit = self._well_rect(a, d, "ap_hint")[4]
        dn = dr.dot(g3("n"), d)
        # cos_sun widened by ~half a bin on the ground, so that bins the terminator crosses
        # between their corners keep their weight
        cos_sun = cos_sun + self._col(a, "margin")
        ok = hit & (cos_sun > 0) & (dn > 0)
        f = rho * cos_sun * dn * lit
        if "vis" in a.tables:
            # what the rest of the satellite hides from this diode (_visibility_table)
            fr = [self._vec(a, "frame", k) for k in range(2)]
            row = dr.clip(mi.Int32(dr.acos(dr.clip(dn, -1.0, 1.0)) * (_VIS_NT / (0.5 * np.pi))), 0, _VIS_NT - 1)
            col = mi.Int32((dr.atan2(dr.dot(fr[1], d), dr.dot(fr[0], d)) + np.pi) * (_VIS_NP / (2.0 * np.pi)))
            col = dr.clip(col, 0, _VIS_NP - 1)
            k = mi.Int32(self._col(a, "k"))
            f *= dr.gather(mi.Float, a.tables["vis"], mi.UInt32((k * _VIS_NT + row) * _VIS_NP + col))
        return dr.select(ok, f, 0.0)

    def _visibility_table(self):
        """Return the (K * _VIS_NT * _VIS_NP,) table (Dr.Jit Float) that shapes the albedo sampling: per
        diode and direction of :meth:`direction_grid`, the largest share of the diode's lit part the mesh
        leaves visible (1 - :meth:`blocked_share`, 1 where the well lights nothing) over the cell and its
        eight neighbours, so that a direction seen past a shadow's edge by part of the diode keeps its
        weight. None without an occluder mesh."""
        if self._scene is None:
            return None
        vis = 1.0 - np.nan_to_num(self.blocked_share(), nan=0.0)
        return host_array(self._mi.Float, widen_cells(vis))

    def direction_grid(self):
        """Return (theta, phi) (_VIS_NT,), (_VIS_NP,) rad: the cell centres of the 1 x 2 deg direction grid
        of :meth:`blocked_share` (angle from the diode normal 0..90 deg, azimuth from u -180..180 deg)."""
        th = (np.arange(_VIS_NT) + 0.5) * (0.5 * np.pi / _VIS_NT)
        ph = (np.arange(_VIS_NP) + 0.5) * (2.0 * np.pi / _VIS_NP) - np.pi
        return th, ph

    @staticmethod
    def direction_cell(local):
        """Return (row, column) int arrays (...): the cell of :meth:`direction_grid` holding each unit direction
        ``local`` (..., 3) given in a diode's frame (u, v, n); directions behind the diode take row _VIS_NT - 1."""
        theta = np.arccos(np.clip(local[..., 2], -1.0, 1.0))
        row = np.minimum((theta * (_VIS_NT / (0.5 * np.pi))).astype(int), _VIS_NT - 1)
        col = ((np.arctan2(local[..., 1], local[..., 0]) + np.pi) * (_VIS_NP / (2.0 * np.pi))).astype(int) % _VIS_NP
        return row, col

    def blocked_share(self):
        """Return (K, 90, 180) (computed once): per diode and direction of its 1 x 2 deg grid (:meth:`direction_grid`), the
        share of 3 x 3 probe rays from the part of the diode its own analytic well lights (inset 1e-3 of
        the side) toward the cell's centre that the mesh blocks (body, rails, other diodes' mounts: what
        the diode's own well does not hold); NaN where the well lights nothing. Zeros without a mesh.

        The check compares it with the analytic model's picture of the same directions to tell which
        albedo diode-epochs its reference covers (``simcore.pipeline.run``)."""
        if getattr(self, "_blocked", None) is None:
            self._blocked = self.probe_share(self._scene)
        return self._blocked

    def probe_share(self, scene, where=None):
        """Return (K, 90, 180): the share of :meth:`blocked_share`'s probe rays that the occluder ``scene``
        (:func:`occluder_scene`; None: nothing) blocks, in the cells of ``where`` (K, 90, 180) bool (default:
        all), 0 in the others; NaN where the diode's own well lights nothing (zeros for a diode with no cell
        in ``where``: not computed)."""
        K = self.diodes.count
        th, ph = self.direction_grid()
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        local = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1)    # (NT, NP, 3)
        out = np.zeros((K, _VIS_NT, _VIS_NP))
        jobs = []
        for k in range(K):
            if where is not None and not where[k].any():
                continue
            if self.control_variate:
                x0, x1, y0, y1, lit = lit_rectangle_of(self._ap_params[k], local[..., 0], local[..., 1], local[..., 2])
            else:
                x0, y0 = np.full(TH.shape, -0.5), np.full(TH.shape, -0.5)
                x1, y1, lit = -x0, -y0, np.ones(TH.shape)
            ok = (lit > 0) & (x1 - x0 > 2e-3) & (y1 - y0 > 2e-3)
            out[k][~ok] = np.nan
            if where is not None:
                ok &= where[k]
            if scene is not None and ok.any():
                jobs.append((k, ok, np.stack([x0[ok], x1[ok], y0[ok], y1[ok]], -1), local[ok] @ self.diodes.frames[k]))
        if jobs:
            blocked = self._blocked_share_of(
                np.concatenate([np.full(int(job[1].sum()), job[0]) for job in jobs]), np.concatenate([job[2] for job in jobs]),
                np.concatenate([job[3] for job in jobs]), [1e-3, 0.5, 1.0 - 1e-3], scene=scene)
            start = 0
            for k, ok, rect, d_body in jobs:
                n = int(ok.sum())
                out[k][ok] = blocked[start:start + n]
                start += n
                win = None if self.diodes.windows is None else self.diodes.windows[k]
                if win is not None:
                    # under a window the light leaves its upper face shifted toward the source: probe from the
                    # first term's exit points too, so that a shadow the shift moves is marked as well
                    shift = self._window_shift(k, win, d_body, 0)
                    out[k][ok] = 0.5 * (out[k][ok] + self._blocked_share_of(
                        np.full(n, k), rect, d_body, [1e-3, 0.5, 1.0 - 1e-3], shift, scene=scene))
        return out

    def visible_share(self, mask, sub=4, points=8):
        """Return (fine, half): per diode, inside the cells of ``mask`` ((K, 90, 180) bool on the grid of
        :meth:`direction_grid`), the share of the part of the diode its own analytic well lights that the
        mesh leaves visible toward each cell's centre, on grids ``sub`` and ``sub / 2`` times finer
        ((K, 90 sub, 180 sub) and (K, 45 sub, 90 sub); NaN outside the mask). A deterministic quadrature:
        ``points`` x ``points`` midpoints of the lit part per direction (for
        ``simcore.radiometry.analytic.DirectionVisibility``), traced in one launch for every diode and
        both grids (the points are made and their hits averaged in the kernel)."""
        K = self.diodes.count
        mask = np.asarray(mask, bool)
        jobs, out = [], []
        for s_ in (sub, sub // 2):
            nt, nph = _VIS_NT * s_, _VIS_NP * s_
            share = np.full((K, nt, nph), np.nan)
            fine_mask = np.repeat(np.repeat(mask, s_, axis=1), s_, axis=2)
            th = (np.arange(nt) + 0.5) * (0.5 * np.pi / nt)
            ph = (np.arange(nph) + 0.5) * (2.0 * np.pi / nph) - np.pi
            for k in range(K):
                i, j = np.nonzero(fine_mask[k])
                if not len(i):
                    continue
                local = np.stack([np.sin(th[i]) * np.cos(ph[j]), np.sin(th[i]) * np.sin(ph[j]), np.cos(th[i])], -1)
                if self.control_variate:
                    x0, x1, y0, y1, lit = lit_rectangle_of(self._ap_params[k], local[:, 0], local[:, 1], local[:, 2])
                else:
                    x0, y0 = np.full(len(i), -0.5), np.full(len(i), -0.5)
                    x1, y1, lit = -x0, -y0, np.ones(len(i))
                jobs.append((share, k, i, j, lit, np.stack([x0, x1, y0, y1], -1), local @ self.diodes.frames[k]))
            out.append(share)
        if not jobs:
            return tuple(out)
        if self._scene is None:
            free = np.ones(sum(len(job[2]) for job in jobs))
        else:
            free = 1.0 - self._blocked_share_of(
                np.concatenate([np.full(len(job[2]), job[1]) for job in jobs]), np.concatenate([job[5] for job in jobs]),
                np.concatenate([job[6] for job in jobs]), (np.arange(points) + 0.5) / points)
        start = 0
        for share, k, i, j, lit, rect, d_body in jobs:
            f = free[start:start + len(i)]
            win = None if self.diodes.windows is None else self.diodes.windows[k]
            if win is not None and self._scene is not None:
                f = self._window_visible_share(k, win, rect, d_body, (np.arange(points) + 0.5) / points)
            share[k, i, j] = np.where(lit > 0, f, 0.0)
            start += len(i)
        return tuple(out)

    def _window_shift(self, k, win, d_body, term):
        """Return (M, 3) body-frame offsets from a point of diode ``k`` to where term ``term`` of the light toward
        directions ``d_body`` (M, 3) leaves the upper face of its window ``win`` (:meth:`Window.exit_offsets`)."""
        u, v, n = self.diodes.frames[k]
        first, step = win.exit_offsets(d_body @ self.diodes.frames[k].T)
        off = first + term * step
        return off[:, :1] * u + off[:, 1:] * v + (win.gap_m + win.thickness_m) * n

    def _window_visible_share(self, k, win, rect, d_body, grid, tail=1e-3, max_terms=12):
        """Return (M,): for diode ``k`` under the window ``win`` and M (lit rectangle (x0, x1, y0, y1) in fractions
        of the diode's sides, body-frame direction), the share of the light through the window that the mesh
        leaves visible: the slab's terms (:meth:`simcore.shapes.window.Window.terms`, mean over s and p), each
        over the part of the rectangle whose exit point for that term lies in the footprint (a rectangle) and
        traced from those exit points (``grid`` x ``grid`` points), weighted by its term and area, up to the
        term below ``tail`` of the first (at most ``max_terms``); 1 where no term reaches the diode."""
        local = d_body @ self.diodes.frames[k].T
        c, q = win.terms(local[:, 2])
        first, step = win.exit_offsets(local)
        size = self.diodes.sizes_m[k]
        half = np.array(win.size_m) / 2
        with np.errstate(divide="ignore"):
            n_terms = np.clip(np.ceil(np.log(tail) / np.log(np.clip(q.max(axis=1), 1e-300, 1 - 1e-12))), 1, max_terms)
        num, den = np.zeros(len(local)), np.zeros(len(local))
        for term in range(int(n_terms.max())):
            off = first + term * step                                                    # (M, 2) metres
            # the points whose exit lies in the footprint: |x size + off| <= half, per axis
            lo = np.maximum(rect[:, [0, 2]], (-half - off) / size)
            hi = np.minimum(rect[:, [1, 3]], (half - off) / size)
            area = np.prod(np.clip(hi - lo, 0.0, None), axis=1) * (term < n_terms)
            on = area > 0
            if not on.any():
                continue
            sub = np.column_stack([lo[on, 0], hi[on, 0], lo[on, 1], hi[on, 1]])
            blocked = self._blocked_share_of(np.full(int(on.sum()), k), sub, d_body[on], grid,
                                             self._window_shift(k, win, d_body[on], term))
            w = np.mean(c[on] * q[on] ** term, axis=1) * area[on]
            num[on] += w * (1.0 - blocked)
            den[on] += w
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)

    def _blocked_share_of(self, diode, rect, d_body, grid, shift=None, scene=None):
        """Return (M,): for M (diode index, lit rectangle (x0, x1, y0, y1) in fractions of the diode's sides,
        centred, body-frame direction) the share of the rectangle's points at fractions ``grid`` (P,) of its
        sides along x times the same along y (P x P points) whose ray toward the direction the mesh blocks;
        one Dr.Jit launch, the points made and their hits summed in the kernel. ``shift`` (M, 3): body-frame
        offsets of the rays' origins from those points (where the light leaves a window's upper face). ``scene``:
        the occluders (default: the mesh's)."""
        dr, mi = self._dr, self._mi
        P = len(grid)
        P2 = P * P
        lane = dr.arange(mi.UInt32, len(diode) * P2)
        m = lane // P2
        q = lane - m * P2
        g = host_array(mi.Float, np.asarray(grid, dtype=float))
        gx = dr.gather(mi.Float, g, q // P)
        gy = dr.gather(mi.Float, g, q % P)
        r = [dr.gather(mi.Float, host_array(mi.Float, rect[:, c]), m) for c in range(4)]
        fx = r[0] + (r[1] - r[0]) * gx
        fy = r[2] + (r[3] - r[2]) * gy
        kk = dr.gather(mi.UInt32, host_array(mi.UInt32, diode.astype(np.uint32)), m)
        f = self._diode_f32
        o = (self._gather3(self._v3(f["pos"]), kk) + fx * self._gather3(self._v3(f["U"]), kk)
             + fy * self._gather3(self._v3(f["V"]), kk))
        if shift is not None:
            o = o + self._gather3(self._v3(shift), m)
        d = self._gather3(self._v3(d_body), m)
        hit = (self._scene if scene is None else scene).ray_test(mi.Ray3f(o, d))
        blocked = dr.block_sum(dr.select(hit, 1.0, 0.0), P2)
        return np.asarray(blocked.numpy(), dtype=float) / P2

    def _albedo_proposal(self, t):
        """Return per-task cap basis and bin CDF/PMF for the albedo sampling of tasks ``t``."""
        R = self.earth_radius_m
        earth = t["earth"]
        dist = np.linalg.norm(earth, axis=-1)
        w = earth / dist[:, None]
        # 1 - cos(cap half-angle) = (R/d)^2 / (1 + cos): no cancellation for a distant Earth
        xmax = (R / dist) ** 2 / (1.0 + np.sqrt(np.clip(1.0 - (R / dist) ** 2, 0.0, None)))
        ref = np.where(np.abs(w[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        e1 = np.cross(ref, w)
        e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
        e2 = np.cross(w, e1)
        # Radial bin edges between equal solid angle and equal central angle g from the
        # sub-satellite point (equal solid angle alone makes the bins near the limb span ~15 deg
        # of ground, where the terminator hides between corners), as fractions t of the cap's
        # solid angle: tan(theta) = R sin g / (d - R cos g).
        g_max = np.arccos(np.clip(R / dist, -1.0, 1.0))
        g = g_max[:, None] * np.linspace(0.0, 1.0, _N_T + 1)[None, :]
        theta = np.arctan2(R * np.sin(g), dist[:, None] - R * np.cos(g))
        tedge = 2.0 * np.sin(theta / 2) ** 2 / xmax[:, None]
        tedge = _EDGE_MIX * tedge + (1 - _EDGE_MIX) * np.linspace(0.0, 1.0, _N_T + 1)[None, :]
        tedge[:, 0], tedge[:, -1] = 0.0, 1.0
        margin = _MARGIN_SCALE * np.sin(0.5 * np.maximum(g_max / _N_T, 2 * np.pi * np.sin(g_max) / _N_P))
        prop = dict(w=w, e1=e1, e2=e2, xmax=xmax, tedge=tedge, margin=margin)
        n_points = (_N_T + 1) * (_N_P + 1)
        tlevel = reach_level(corner_reach(tedge, xmax, dist / R), self.reflectivity.shape[0])
        f = self._trace_tasks(self._proposal_kernel, dict(t, tlevel=tlevel.astype(np.float32), **prop), n_points)
        fc = f.reshape(-1, _N_T + 1, _N_P + 1)
        corner = np.maximum(fc[:, :-1, :-1], fc[:, 1:, :-1])
        np.maximum(corner, np.maximum(fc[:, :-1, 1:], fc[:, 1:, 1:]), out=corner)
        wbin = corner.reshape(len(f), -1)
        tot = wbin.sum(axis=1, keepdims=True)
        omega = np.diff(tedge, axis=1) / _N_P                   # (T, N_T): a bin's solid angle / the cap's
        # (1 - D) wbin / tot + D omega where the proposal has weight, omega alone where it has none
        pmf = np.empty(wbin.shape)
        a = (1 - _DEFENSIVE) * wbin
        a /= np.where(tot > 0, tot, 1.0)
        np.add(a.reshape(-1, _N_T, _N_P), (_DEFENSIVE * omega)[:, :, None], out=pmf.reshape(-1, _N_T, _N_P))
        empty = ~(tot[:, 0] > 0)                            # (NaN too: the uniform fallback, as before)
        if empty.any():
            pmf[empty] = np.repeat(omega[empty], _N_P, axis=1)
        cdf = np.cumsum(pmf, axis=1)
        cdf /= cdf[:, -1:]
        cdf[:, -1] = 1.0
        return dict(prop, pmf=pmf.astype(np.float32), cdf=cdf.astype(np.float32))

    def _trace_tasks(self, kernel, t, n_points):
        """Return ``kernel(lanes, n_points)`` (T, n_points) for the tasks ``t`` in launches of bounded size."""
        T = len(t["key"])
        if T < 2:
            return self._trace_tasks(kernel, _pad2(t), n_points)[:T]
        t = dict(t, **self._tables(t))
        per = max(2, _MAX_LANES // n_points)
        n = -(-T // per)
        edges = np.linspace(0, T, n + 1).round().astype(int)
        out = []
        for a, b in zip(edges[:-1], edges[1:]):
            lanes = self._lanes(_take(t, slice(a, b)), (b - a) * n_points)
            out.append(self._run(kernel, lanes, n_points).numpy().reshape(b - a, n_points))
        return np.concatenate(out)

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
               max_albedo_samples=65536, albedo=True, hint=True, batch_epochs=64, progress=None,
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

        valid = np.all(np.isfinite(sun), axis=1) & np.isfinite(scale)
        if earth is not None:
            valid &= np.all(np.isfinite(earth), axis=1)
            dist = np.linalg.norm(earth, axis=1)
            inside = valid & (dist <= self.earth_radius_m)
            if np.any(inside):
                raise ValueError(f"the satellite is inside the Earth at epoch {int(np.argmax(inside))} "
                                 f"(|earth_center_body_m| = {dist[np.argmax(inside)]:.0f} m <= R = "
                                 f"{self.earth_radius_m:.0f} m); earth_center_body_m is the Earth's centre "
                                 "relative to the satellite, in metres")
        if do_albedo:
            valid &= np.all(np.isfinite(rot), axis=(1, 2))
        sun = np.where(valid[:, None], sun, [[0.0, 0.0, 1.0]])
        sun = _unit(sun, "sun_dir_body")
        sun_e = _unit(np.where(valid[:, None], sun_e, [[0.0, 0.0, 1.0]]), "sun_dir_earth_body")
        if earth is not None:
            earth = np.where(valid[:, None], earth, [[0.0, 0.0, -2.0 * self.earth_radius_m]])
        if rot is not None:
            rot = np.where(valid[:, None, None], rot, np.eye(3))

        K = self.diodes.count
        out = {k: np.zeros((N, K)) for k in ("dm", "dse", "am", "ase", "rm", "rse")}
        out.update(ddof=np.full((N, K), np.inf), adof=np.full((N, K), np.inf), rdof=np.full((N, K), np.inf))
        n_ref = np.zeros((N, K), dtype=np.int64)
        do_reflected = bool(reflected) and self._pt is not None
        pending = []
        n_dir = np.zeros((N, K), dtype=np.int64)
        n_alb = np.zeros((N, K), dtype=np.int64)
        E = self.e_sun_w_m2 * scale                                  # (N,)
        E_e = self.e_sun_w_m2 * scale_e                              # (N,) lighting the Earth
        cos_c = sun @ self.diodes.frames[:, 2].T                    # (N, K) float64
        R = self.earth_radius_m
        sin_a = np.sin(self.sun_angular_radius_rad)
        for b0 in range(0, N, batch_epochs):
            eps = np.arange(b0, min(N, b0 + batch_epochs))
            ep, dk = [a.ravel() for a in np.meshgrid(eps, np.arange(K), indexing="ij")]
            g_ep = ep + int(epoch_offset) if epoch_index is None else epoch_index[ep]
            # ---- direct Sun: tasks facing the (disc of the) Sun and not in full umbra
            act = valid[ep] & (cos_c[ep, dk] > -sin_a)
            if earth is not None:
                c = earth[ep]
                bb = np.einsum("ti,ti->t", c, sun[ep])
                perp = np.linalg.norm(c - bb[:, None] * sun[ep], axis=1)
                umbra = (bb > 0) & (perp < R - np.linalg.norm(c, axis=1) * sin_a - 10.0)
                act &= ~umbra
            e_, k_ = ep[act], dk[act]
            if len(e_):
                self._direct_rounds(e_, k_, g_ep[act], sun, earth, E, cos_c, seed, 4 * m0 * m0, rel_se_direct,
                                    abs_se_floor_w_m2, max_direct_samples, out, n_dir,
                                    not hint)
            # ---- albedo: tasks whose hemisphere meets the Earth's disc and a sunlit part of it
            if do_albedo:
                c = earth[ep]
                dist = np.linalg.norm(c, axis=1)
                w = c / dist[:, None]
                sin_cap = R / dist                                   # sin of the cap half-angle
                n = self.diodes.frames[dk, 2]
                # angle(n, w) < 90 deg + cap half-angle  <=>  n . w > -sin(cap)
                sees = np.einsum("ti,ti->t", n, w) > -sin_cap
                # sunlit Earth in view: angle(zenith, s) < 90 deg + acos(R/d)
                lam = np.arccos(np.clip(R / dist, -1, 1))
                lit = np.einsum("ti,ti->t", -w, sun_e[ep]) > np.cos(np.minimum(np.pi / 2 + lam, np.pi))
                act = valid[ep] & sees & lit
                e_, k_ = ep[act], dk[act]
                if len(e_):
                    self._albedo_rounds(e_, k_, g_ep[act], sun_e, earth, rot, E_e, seed, n0, rel_se_albedo,
                                        abs_se_floor_w_m2, max_albedo_samples, out, n_alb)
            # ---- reflected: every task with sunlight on the satellite or a sunlit Earth in its sky
            if do_reflected:
                act = valid[ep].copy()
                if earth is not None:
                    c = earth[ep]
                    dist = np.linalg.norm(c, axis=1)
                    bb = np.einsum("ti,ti->t", c, sun[ep])
                    perp = np.linalg.norm(c - bb[:, None] * sun[ep], axis=1)
                    sunny = ~((bb > 0) & (perp < R - dist * sin_a - 10.0))
                    lam = np.arccos(np.clip(R / dist, -1, 1))
                    lit = np.einsum("ti,ti->t", -c / dist[:, None], sun_e[ep]) > np.cos(np.minimum(np.pi / 2 + lam, np.pi))
                    act &= sunny | (do_albedo & lit)
                pending.append((ep[act], dk[act], g_ep[act]))
                # the wavefront's launches cost ~10 ms each to trace whatever their width: gather many epochs
                if sum(len(p[0]) for p in pending) * 4 * mr * mr >= _REFLECTED_LANES or eps[-1] == N - 1:
                    e_, k_, gg = (np.concatenate(x) for x in zip(*pending))
                    pending = []
                    if len(e_):
                        self._reflected_round(e_, k_, gg, sun, sun_e, earth if do_albedo else None, rot,
                                              earth, E, E_e, seed, 4 * mr * mr, out, n_ref)
            if progress is not None:
                progress(len(eps))
        nan = ~valid
        for k in out:
            out[k][nan] = np.nan
        return RenderResult(out["dm"], out["dse"], out["am"], out["ase"], n_dir, n_alb, valid,
                            self.variant, int(seed), out["ddof"], out["adof"],
                            dict(sun_angular_radius_rad=self.sun_angular_radius_rad, e_sun_w_m2=self.e_sun_w_m2),
                            out["rm"], out["rse"], n_ref, out["rdof"])

    def _rounds(self, kernel, base, kind, g_, k_, seed, n0, rel, floor, cap, fac, size, power, skip=None,
                plain=False):
        """Return (mean, standard error, effective degrees of freedom, samples) per task in ``base``,
        in lane units x fac.

        Without a target (``rel`` None) one round of ``n0`` samples per task. With one, two
        stages: a pilot round of ``n0 // 4`` samples sizes each task's count (enough to reach
        the target with the error falling as n^(-1/power), between ``n0`` and ``cap``), and a
        fresh, independent round of that count gives the value and its standard error. The
        pilot is then dropped, so the decision to take more samples never shares samples with
        the estimate it sizes (a stopping rule fed by the estimate's own samples reads low where
        it stopped early and high where it went on).
        """
        n0 = np.broadcast_to(np.asarray(n0, np.int64), (len(g_),))
        if rel is None:
            return self._round(kernel, base, kind, g_, k_, seed, n0.copy(), 0, fac, size, skip, plain)
        pilot = np.maximum(n0 // 4, 16)
        m, se, _, n = self._round(kernel, base, kind, g_, k_, seed, pilot, 0, fac, size, skip, plain)
        need, want = _shortfall(m, se, n, rel, floor, power)
        counts = np.clip(np.where(need, want, n0), n0, np.maximum(cap, n0)).astype(np.int64)
        return self._round(kernel, base, kind, g_, k_, seed, counts, 1, fac, size, skip, plain)

    def _round(self, kernel, base, kind, g_, k_, seed, counts, rnd, fac, size, skip, plain=False):
        """Trace one round of ``counts`` (T,) samples for the tasks in ``base``; return (mean, standard
        error, effective degrees of freedom, samples) per task, in lane units x fac.

        With an analytic well per diode (``control_variate``, unless ``plain``), each task's samples
        are split into group A, ~4/5 of them, drawn on the part of the diode that the analytic well
        lights (``_well_rect``, weight = its area), and group B, ~1/5, drawn on the whole diode but
        counted only outside that part. Both are traced against the full mesh, so the sum is
        unbiased whatever the mesh; when the mesh's well is the analytic one, group B reads 0
        and group A varies only where the body, rails or the Earth cut into the lit part.
        ``skip`` (T, 2) marks groups known to be empty (point Sun, lit fraction 0 or 1).

        The variance of the stratified mean is the sum of the strata's terms ``(a - b)^2 / 4``
        (two samples a, b per stratum), each a one-degree-of-freedom estimate; few strata carry
        the variance where a shadow edge or a bright patch crosses only some of them, so the
        standard error has ``nu = (sum q)^2 / sum q^2`` effective degrees of freedom
        (Satterthwaite 1946) and ``(estimate - truth) / se`` follows Student's t with ``nu``.
        """
        T = len(g_)
        todo = np.arange(T)
        if self.control_variate and not plain:
            na = size(np.maximum(counts * 4 // 5, 1))
            nb = size(np.maximum(counts // 5, 1))
            sa = np.zeros(T, bool) if skip is None else skip[:, 0]
            sb = np.zeros(T, bool) if skip is None else skip[:, 1]
            na = np.where(sb, size(counts), na)        # only A: give it the whole budget
            nb = np.where(sa, size(counts), nb)
            whole = self._plain[k_]                    # round wells: no split, the disc's control variate
            sa, sb = sa | whole, sb | whole
            parts = [(3, todo[whole], size(counts)[whole]), (1, todo[~sa], na[~sa]), (2, todo[~sb], nb[~sb])]
        else:
            parts = [(0, todo, size(counts))]
        idx = np.concatenate([p[1] for p in parts])
        lanes = np.concatenate([p[2] for p in parts]).astype(np.int64)
        mode = np.concatenate([np.full(len(p[1]), p[0]) for p in parts])
        t = _take(base, idx)
        t["key"] = _mix32(seed, g_[idx], k_[idx], kind, rnd, mode)
        t["mode"] = mode
        t["m"] = _strata_param(kind != _ALBEDO, lanes)
        mean, var, var2 = _task_mean_var(self._trace(kernel, t, lanes), lanes)
        est, v, v2, nr = np.zeros(T), np.zeros(T), np.zeros(T), np.zeros(T)
        np.add.at(est, idx, mean)
        np.add.at(v, idx, var)
        np.add.at(v2, idx, var2)
        np.add.at(nr, idx, lanes)
        with np.errstate(divide="ignore", invalid="ignore"):
            dof = np.where(v2 > 0, v * v / np.where(v2 > 0, v2, 1.0), np.inf)
        return fac * est, fac * np.sqrt(v), dof, nr

    def _direct_rounds(self, e_, k_, g_, sun, earth, E, cos_c, seed, n0, rel, floor, cap, out, n_used, plain):
        base = self._tasks(e_, k_, sun, earth, None)
        disc = self.sun_angular_radius_rad > 0
        # lane mean -> W/m^2. With the disc, lanes read cos(n, d) for directions d uniform in solid angle
        # over the disc, whose mean is cos(n, s) (1 + cos a) / 2, while the irradiance of a uniform disc of
        # total E is E cos(n, s) exactly: hence the factor 2 / (1 + cos a).
        fac = E[e_] * (2.0 / (1.0 + np.cos(self.sun_angular_radius_rad)) if disc else cos_c[e_, k_])
        skip = None
        if self.control_variate and not disc and not plain:
            lit = self._lit_fraction(k_, sun[e_])
            skip = np.stack([lit <= 0.0, lit >= 1.0], axis=1)
        if not plain:
            n0 = np.where(self._partly_blocked(base, e_, sun, earth), n0 * _EDGE_BOOST, n0)
        m, se, dof, n = self._rounds(self._direct_kernel, base, _DIRECT_PLAIN if plain else _DIRECT, g_, k_, seed, n0, rel, floor,
                                     cap, fac, _direct_size, 4.0 / 3.0, skip, plain)
        out["dm"][e_, k_], out["dse"][e_, k_], out["ddof"][e_, k_], n_used[e_, k_] = m, se, dof, n

    def _albedo_rounds(self, e_, k_, g_, sun, earth, rot, E, seed, n0, rel, floor, cap, out, n_used):
        base = self._tasks(e_, k_, sun, earth, None)
        base["rot"] = rot[e_]
        base.update(self._albedo_proposal(dict(base, key=np.zeros(len(e_), np.uint32))))
        base.update(self._tables(base))
        m, se, dof, n = self._rounds(self._albedo_kernel, base, _ALBEDO, g_, k_, seed, n0, rel, floor, cap, E[e_],
                                     _albedo_size, 2.0)
        out["am"][e_, k_], out["ase"][e_, k_], out["adof"][e_, k_], n_used[e_, k_] = m, se, dof, n

    def _reflected_round(self, e_, k_, g_, sun, sun_e, earth_alb, rot, earth, E, E_e, seed, n, out, n_used):
        """Path-trace ``n`` samples of the ``reflected`` component for tasks (e_, k_) into ``out``."""
        base = self._tasks(e_, k_, sun, earth, None)
        base["E"] = E[e_]
        base["beta"] = self._hit["beta"][k_]         # the first direction's cosine-weighted share (_hit_table)
        if earth_alb is not None:
            base["rot"] = rot[e_]
            base["sun_e"] = sun_e[e_]
            base["E_e"] = E_e[e_]
            c = base["earth"]
            dist = np.linalg.norm(c, axis=1)
            w = c / dist[:, None]
            R = self.earth_radius_m
            base["xmax"] = (R / dist) ** 2 / (1.0 + np.sqrt(np.clip(1.0 - (R / dist) ** 2, 0.0, None)))
            ref = np.where(np.abs(w[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
            e1 = np.cross(ref, w)
            e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
            base.update(w=w, e1=e1, e2=np.cross(w, e1))
        m, se, dof, nr = self._round(self._reflected_kernel, base, _REFLECTED, g_, k_, seed,
                                     np.full(len(e_), n, np.int64), 0, 1.0, _direct_size, None, plain=True)
        out["rm"][e_, k_], out["rse"][e_, k_], out["rdof"][e_, k_], n_used[e_, k_] = m, se, dof, nr

    def _partly_blocked(self, base, e_, sun, earth):
        """Return (T,) bool: the direct-Sun tasks whose light something other than the diode's own analytic
        well blocks in part: the Earth's limb across the solar disc, or the mesh (body, rails, neighbours)
        across the lit part of the diode, found by probe rays from its corners and centre toward the disc's
        centre and rim (``_PROBE_RIM`` points).

        Such a shadow can be a sliver of (point on the diode) x (point on the disc) worth 0.1 % of the
        light: a round of ~1000 samples then misses it outright often enough (a few % of such tasks) to
        read 10 standard errors high, because a standard error estimated from the samples cannot see
        light that none of them met. These tasks get ``_EDGE_BOOST`` times the samples.
        """
        T = len(e_)
        a = self.sun_angular_radius_rad
        s = sun[e_]
        out = np.zeros(T, bool)
        if earth is not None and a > 0:
            c = base["earth"]
            dist = np.linalg.norm(c, axis=1)
            theta = np.arccos(np.clip(np.einsum("ti,ti->t", s, c) / dist, -1.0, 1.0))
            rho = np.arcsin(np.minimum(self.earth_radius_m / dist, 1.0))
            out |= np.abs(theta - rho) < a
        if self._scene is None:
            return out
        if a > 0:
            helper = np.where(np.abs(s[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
            e1 = np.cross(s, helper)
            e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
            e2 = np.cross(s, e1)
            ang = 2.0 * np.pi * np.arange(_PROBE_RIM) / _PROBE_RIM
            off = np.tan(0.999 * a) * np.stack([np.cos(ang), np.sin(ang)], axis=1)
            dirs = s[:, None] + off[None, :, :1] * e1[:, None] + off[None, :, 1:] * e2[:, None]
            dirs = np.concatenate([s[:, None], dirs / np.linalg.norm(dirs, axis=2, keepdims=True)], axis=1)
        else:
            dirs = s[:, None]
        D = dirs.shape[1]
        fr = base["frame"]                                             # (T, 3, 3) rows u, v, n
        dd = np.einsum("tij,tdj->tdi", fr, dirs)
        ap = base["ap"]
        if self.control_variate:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                x0, x1, y0, y1, lit = lit_rectangle_of([ap[:, None, i] for i in range(8)],
                                                       dd[..., 0], dd[..., 1], dd[..., 2])
        else:
            x0, y0 = np.full((T, D), -0.5), np.full((T, D), -0.5)
            x1, y1 = -x0, -y0
            lit = (dd[..., 2] > 0).astype(float)
        # corners inset by 1e-4 of the side (points on a wall's foot are not what this looks for), centre
        inset = 1e-4
        fx = np.stack([x0 + inset, x1 - inset, x0 + inset, x1 - inset, 0.5 * (x0 + x1)], axis=2)
        fy = np.stack([y0 + inset, y0 + inset, y1 - inset, y1 - inset, 0.5 * (y0 + y1)], axis=2)
        P = fx.shape[2]
        o = (base["pos"][:, None, None] + fx[..., None] * base["U"][:, None, None]
             + fy[..., None] * base["V"][:, None, None])
        d = np.broadcast_to(dirs[:, :, None], o.shape)
        mi = self._mi
        if self._win is not None:
            # under a window the light leaves its upper face shifted toward the source: probe from the first
            # term's exit points as well (tasks without a window: the same points twice)
            w = base["win"]
            n_i, th, gap, has = w[:, None, 0], w[:, None, 1], w[:, None, 2], w[:, None, 8] > 0.5
            dn = np.maximum(dd[..., 2], 1e-12)
            ct = np.sqrt(np.maximum(1.0 - (dd[..., 0] ** 2 + dd[..., 1] ** 2) / n_i ** 2, 1e-24))
            reach = np.where(has, gap / dn + th / (n_i * ct), 0.0)                                  # (T, D)
            shift = ((reach * dd[..., 0])[..., None] * fr[:, None, 0] + (reach * dd[..., 1])[..., None] * fr[:, None, 1]
                     + np.where(has, gap + th, 0.0)[..., None] * fr[:, None, 2])
            o = np.concatenate([o, o + shift[:, :, None]], axis=2)
            d = np.concatenate([d, d], axis=2)
            P = 2 * P
        # each task's rays padded to whole packets (_PACKET) with copies of its last one
        n = D * P
        pad = np.minimum(np.arange(-(-n // _PACKET) * _PACKET), n - 1)
        o, d = o.reshape(T, n, 3)[:, pad], d.reshape(T, n, 3)[:, pad]
        ray = mi.Ray3f(self._v3(o.reshape(-1, 3)), self._v3(d.reshape(-1, 3)))
        blocked = np.asarray(self._scene.ray_test(ray).numpy(), bool).reshape(T, len(pad))[:, :n].reshape(T, D, P)
        seen = np.broadcast_to(((lit > 0) & (x1 - x0 > 2 * inset) & (y1 - y0 > 2 * inset))[..., None], blocked.shape)
        some = (blocked & seen).any(axis=(1, 2))
        free = (~blocked & seen).any(axis=(1, 2))
        return out | (some & free)

    def _lit_fraction(self, k_, d_body):
        """Return the analytic wells' lit fractions (T,) for diodes k_ and body directions (T, 3)."""
        ap = self._ap_params[k_]
        dd = np.einsum("tij,tj->ti", self.diodes.frames[k_], d_body)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return lit_rectangle_of(ap.T, dd[:, 0], dd[:, 1], dd[:, 2])[4]


def reach_levels(values):
    """Return the flat (L n_lat n_lon,) float32 bounds of ``|values|`` (a regular (n_lat, n_lon) latitude/longitude map,
    row 0 the southern band, longitude wrapping round) within reach on the sphere: level ``l``, at each cell, the
    largest over every cell that holds a point within ground (central) angle ``r_l = 2^l`` cell heights of a point of
    the cell; the last level reaches pi (the map's maximum). The cells taken are a superset, so each is a bound:
    rows within ``2^l`` rows; columns within ``asin(sin r / cos phi)`` of longitude, ``phi`` the cell's poleward edge
    (the widest a circle of radius r about a point of the cell spans), and the whole latitude circle where the reach
    passes a pole."""
    a = np.abs(np.asarray(values, dtype=float))
    nlat, nlon = a.shape
    dlat, dlon = np.pi / nlat, 2.0 * np.pi / nlon
    pole = np.maximum(np.abs(-0.5 * np.pi + np.arange(nlat) * dlat), np.abs(-0.5 * np.pi + np.arange(1, nlat + 1) * dlat))
    rows = np.arange(nlat)
    j = np.arange(nlon)
    out = []
    band = a
    for lev in range(reach_level(np.pi, nlat) + 1):
        # rows i - 2^l .. i + 2^l: the union of the previous level's bands about i -+ 2^(l-1) (about i -+ 1 from the
        # map itself for level 0), clipped at the poles
        h = 1 << max(lev - 1, 0)
        lo, hi = band[np.clip(rows - h, 0, nlat - 1)], band[np.clip(rows + h, 0, nlat - 1)]
        band = np.maximum(np.maximum(lo, hi), a) if lev == 0 else np.maximum(lo, hi)
        r = dlat * (1 << lev)
        with np.errstate(invalid="ignore"):
            half = np.arcsin(np.clip(np.sin(min(r, 0.5 * np.pi)) / np.cos(pole), 0.0, 1.0))
        w = np.ceil(half / dlon - 1e-9).astype(np.int64)
        full = (pole + r >= 0.5 * np.pi) | (2 * w + 1 >= nlon)
        # circular window maxima along each row by doubling: run[k][:, j] = max over columns j .. j + 2^k - 1
        n = np.where(full, 1, 2 * w + 1)
        k = np.floor(np.log2(n)).astype(np.int64)
        run = [band]
        for _ in range(int(k.max())):
            step = 1 << (len(run) - 1)
            run.append(np.maximum(run[-1], np.roll(run[-1], -step, axis=1)))
        run = np.stack(run)
        first = (j[None, :] - np.where(full, 0, w)[:, None]) % nlon
        second = (first + (n - (1 << k))[:, None]) % nlon
        lev_max = np.maximum(run[k[:, None], rows[:, None], first], run[k[:, None], rows[:, None], second])
        out.append(np.where(full[:, None], band.max(axis=1, keepdims=True), lev_max))
    return np.stack(out).astype(np.float32).ravel()


def reach_level(reach_rad, n_lat):
    """Return the :func:`reach_levels` level (int array) whose reach covers ground angles ``reach_rad`` on a map of
    ``n_lat`` rows: the smallest ``l`` with ``2^l pi / n_lat >= reach``, 0 for reaches within one cell height."""
    ratio = np.maximum(np.asarray(reach_rad, dtype=float) * (n_lat / np.pi) * (1 + 1e-6), 1.0)
    return np.ceil(np.log2(ratio) - 1e-12).astype(np.int64)


def corner_reach(tedge, xmax, d_over_r):
    """Return (T, N_T + 1) the ground angle (rad) from each ring of the albedo proposal's bin corners to the farthest
    ground point of the bins that touch a corner there: rings ``tedge`` (T, N_T + 1) (fractions of the cap's solid
    angle ``2 pi xmax``, from nadir), the satellite at ``d_over_r`` Earth radii from the centre. A bin's ground is
    the points between its rings' ground angles g within its azimuth (the direction's azimuth about nadir is the
    point's about the sub-satellite point); the farthest from the corner lies at a ring next to the corner's and
    one bin's azimuth away (the distance along a ring grows with azimuth, along a meridian arc shorter than pi it
    peaks at an end)."""
    x = np.asarray(tedge, dtype=float) * np.asarray(xmax, dtype=float)[:, None]   # 1 - cos(nadir angle)
    sin_t = np.sqrt(np.clip(x * (2.0 - x), 0.0, None))
    cos_t = 1.0 - x
    dd = np.asarray(d_over_r, dtype=float)[:, None]
    # range to the near-side point, in Earth radii, and its ground angle from the sub-satellite point
    s = dd * cos_t - np.sqrt(np.clip(1.0 - (dd * sin_t) ** 2, 0.0, None))
    g = np.arctan2(s * sin_t, dd - s * cos_t)
    lo = np.concatenate([g[:, :1], g[:, :-1]], axis=1)
    hi = np.concatenate([g[:, 1:], g[:, -1:]], axis=1)
    cos_p = np.cos(2.0 * np.pi / _N_P)
    far = lambda g2: np.arccos(np.clip(np.cos(g) * np.cos(g2) + np.sin(g) * np.sin(g2) * cos_p, -1.0, 1.0))  # noqa: E731
    return np.maximum(far(lo), far(hi))


def widen_cells(a):
    """Return ``a`` (..., rows, columns) of direction-grid cells (:meth:`Renderer.direction_grid`) with each cell the
    largest of itself and its neighbours one row and one column away (bool: any of them), azimuth wrapping round:
    so that an edge passing between the cells' centres still marks the cells it crosses."""
    grown = a.copy()
    grown[..., 1:, :] = np.maximum(grown[..., 1:, :], a[..., :-1, :])
    grown[..., :-1, :] = np.maximum(grown[..., :-1, :], a[..., 1:, :])
    return np.maximum(grown, np.maximum(np.roll(grown, 1, axis=-1), np.roll(grown, -1, axis=-1)))


def _plane_normals(normals, max_planes=_MAX_MIRROR_PLANES):
    """Return the distinct orientations (P, 3) (sign ignored) of the faces of smooth-specular parts, or
    None when there are none or more than ``max_planes`` (curved mirrors: BSDF sampling alone)."""
    if not normals:
        return None
    n = np.concatenate(normals)
    n = n[np.isfinite(n).all(axis=1) & (np.linalg.norm(n, axis=1) > 0.5)]
    first = np.argmax(np.abs(n) > 1e-9, axis=1)
    n = n * np.sign(n[np.arange(len(n)), first])[:, None]
    uniq = np.unique(np.round(n, 6), axis=0)
    if not 0 < len(uniq) <= max_planes:
        return None
    return uniq / np.linalg.norm(uniq, axis=1, keepdims=True)


def _window_params(diodes):
    """Return (K, 9) float64 [index, thickness, gap, half side u, half side v, absorption (1/m), diode side u,
    diode side v, has a window] per diode for :meth:`Renderer._through_window`, or None without windows."""
    if diodes.windows is None:
        return None
    out = np.zeros((diodes.count, 9))
    for k, w in enumerate(diodes.windows):
        if w is None:
            out[k] = [1.5, 1e-3, 0.0, 1e3, 1e3, 0.0, *diodes.sizes_m[k], 0.0]
        else:
            out[k] = [w.index, w.thickness_m, w.gap_m, w.size_m[0] / 2, w.size_m[1] / 2, w.absorption_per_m,
                      *diodes.sizes_m[k], 1.0]
    return out


def _direct_size(n):
    """Return the direct sample counts >= n (4 m^2, m >= 2) for requested counts n."""
    m = np.maximum(np.ceil(np.sqrt(np.asarray(n) / 4.0)), 2)
    return (4 * m * m).astype(np.int64)


def _albedo_size(n):
    """Return the albedo sample counts >= n (even, >= 4)."""
    return np.maximum(2 * np.ceil(np.asarray(n) / 2.0), 4).astype(np.int64)


def _strata_param(direct, counts):
    """Return the per-task stratification parameter the kernels read as t['m']: m for the
    direct (4 m^2 samples), the number of strata for the albedo (2 samples each)."""
    if direct:
        return np.round(np.sqrt(counts / 4.0))
    return counts / 2.0


_GC_GUARD = threading.Lock()
_GC_STATE = {"depth": 0, "was_enabled": False}


@contextlib.contextmanager
def _no_cycle_collection():
    """Switch Python's cycle collector off for the duration (Renderer._run's frozen calls), and back on when the last
    of the threads inside such a block leaves it, if it was on before the first entered (a plain disable/enable per
    call would let one thread's exit switch it on while another records)."""
    with _GC_GUARD:
        if _GC_STATE["depth"] == 0:
            _GC_STATE["was_enabled"] = gc.isenabled()
            gc.disable()
        _GC_STATE["depth"] += 1
    try:
        yield
    finally:
        with _GC_GUARD:
            _GC_STATE["depth"] -= 1
            if _GC_STATE["depth"] == 0 and _GC_STATE["was_enabled"]:
                gc.enable()


def _task_mean_var(vals, counts):
    """Return the mean (T,), the variance of the mean (T,) and the sum of the squares of its strata's
    terms (T,; for the effective degrees of freedom) of per-lane values laid out task after task
    (``counts`` each) as strata of two samples (float64)."""
    # per stratum (a, b): the sum a + b and the squared difference (a - b)^2, in float64; a task's m strata all
    # have the term (a - b)^2 / (4 m^2), so its sums divide once (the same as summing lane by lane to ~1e-16)
    first = (np.cumsum(counts) - counts) // 2
    a, b = vals[0::2], vals[1::2]
    d2 = np.subtract(a, b, dtype=np.float64)
    d2 *= d2
    m = (counts // 2).astype(np.float64)
    mean = np.add.reduceat(np.add(a, b, dtype=np.float64), first) / counts
    var = np.add.reduceat(d2, first) / (4.0 * m * m)
    d2 *= d2
    return mean, var, np.add.reduceat(d2, first) / (16.0 * m ** 4)


def _pad2(t):
    """Return the task dict padded to >= 2 tasks (a 1-element Dr.Jit array would become a
    literal baked into the kernel, so every new value would compile a new kernel)."""
    if len(t["key"]) >= 2:
        return t
    return {k: (np.concatenate([v, v]) if isinstance(v, np.ndarray) else v) for k, v in t.items()}


def _take(t, idx):
    """Return the task dict ``t`` of the tasks ``idx`` (indices or a slice): its numpy fields indexed, the rest (None,
    and the tables uploaded once for all its tasks, Renderer._tables) as they are."""
    return {k: (v[idx] if isinstance(v, np.ndarray) else v) for k, v in t.items()}


def _shortfall(mean, se, n, rel, floor, power):
    """Return (tasks above their target standard error, samples the target needs), from a round of
    ``n`` samples that gave ``mean`` and ``se``, assuming the error falls as n^(-1/power)."""
    target = np.maximum(rel * np.abs(mean), floor)
    need = se > target
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        want = 1.2 * n * (se / target) ** power
    want = np.nan_to_num(want, nan=1.0, posinf=1e18)
    return need, want


def render(satellite, earth, sun_dir_body, earth_center_body_m=None, R_ecef_from_body=None, sun_scale=None, *,
           sun_angular_radius_rad=0.0, variant=None, e_sun_w_m2=E_SUN_W_M2, **kwargs):
    """Return a :class:`RenderResult` (direct and albedo irradiance, W/m^2, (N, K)) for one call: the renderer of
    ``satellite`` over ``earth`` (:meth:`Renderer.from_scene`) and its :meth:`Renderer.render` (see both)."""
    r = Renderer.from_scene(satellite, earth, sun_angular_radius_rad=sun_angular_radius_rad, variant=variant,
                            e_sun_w_m2=e_sun_w_m2)
    return r.render(sun_dir_body, earth_center_body_m, R_ecef_from_body, sun_scale, **kwargs)
