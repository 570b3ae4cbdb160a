"""Analytic diode irradiance along an orbit: direct Sun + Earth albedo, N epochs x K diodes.

The reference the renderer is checked against. For each epoch n and diode k
(diode frame ``F_k``, rows (u, v, n) in the body frame; attitude
``R_ecef_from_body``)::

    direct[n, k] = E_sun * lit[n] * A_k(F_k R^T s_n)
    albedo[n, k] = sum_c E_c(n) * A_k(F_k R^T e_c(n))

with s_n the unit vector from the satellite to the Sun, lit[n] the eclipse
factor (:mod:`simcore.environment.eclipse`; the thesis' cylinder by default, sec. 4.1.4),
E_c the Bhanderi cell irradiance of :mod:`simcore.radiometry.albedo` (physical mode),
e_c the unit vector from the satellite to cell c and A_k the diode's angular
response (:mod:`simcore.radiometry.response`: cosine, eq. 2.32, eq. 4.15, or the well
aperture of :mod:`simcore.shapes.aperture`). The eclipse dims the direct Sun only;
the albedo needs no factor: from inside the shadow cylinder no sunlit cell
centre is visible (its edge is the horizon ray grazing the terminator), and
in a penumbra the visible sunlit cells do light the satellite.

Speed (issue item 4): only cells visible from the satellite and sunlit are
evaluated. Per epoch and map row, the visible cap (``r_sat . n > R``) and the
sunlit hemisphere (``s . n > 0``) are each an arc of longitude, found in
closed form; their intersection is at most two runs of consecutive columns.
Each run is one lane of a Dr.Jit LLVM kernel (multi-threaded, SIMD, one
fused kernel per batch of epochs) that loops over its columns and
accumulates the K diode sums in registers; the runs of an epoch are added up
afterwards. ``backend='numpy'`` evaluates the same cells with numpy in
float64 and the responses' own ``response()`` methods (any response object
works there); it is the cross-check of the kernel.
"""
from dataclasses import dataclass
import functools

import numpy as np

from scenes.satellite import BodyBox  # noqa: F401 (the model's body occluder; its home is the data layer)

from simcore import _llvm
from simcore.environment import eclipse as _eclipse
from simcore.radiometry import glint as _glint
from simcore.radiometry import response as _resp
from simcore.radiometry.albedo import check_geometry, sun_irradiance_w_m2
from simcore.radiometry.analytic_direct import _DARK_BEHIND, _direct_response
from simcore.constants import E_SUN_W_M2, R_SUN_M
from simcore.environment.maps import as_map
from simcore.shapes.occlusion import box_hit

_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class AnalyticIrradiance:
    """Irradiance on each diode, W/m^2 on its sensitive area: direct Sun and Earth albedo, (N, K) each."""

    direct_w_m2: np.ndarray
    albedo_w_m2: np.ndarray
    illuminated_fraction: np.ndarray  # (N,), the eclipse factor applied to the direct Sun
    # With a DirectionVisibility (diode_irradiance's ``visibility``), (N, K) each: the albedo arriving
    # through the directions it covers (before their shadow), and the estimated error of its quadrature
    albedo_mesh_w_m2: np.ndarray = None
    albedo_visibility_error_w_m2: np.ndarray = None
    # ... and the albedo with the body box alone deciding everywhere (what the model gives without it)
    albedo_box_w_m2: np.ndarray = None

    @property
    def total_w_m2(self):
        """Return direct + albedo, (N, K) W/m^2."""
        return self.direct_w_m2 + self.albedo_w_m2

    def __getitem__(self, key):
        return getattr(self, key)

    def keys(self):
        return ("direct_w_m2", "albedo_w_m2", "illuminated_fraction")


@dataclass(frozen=True)
class DirectionVisibility:
    """What the satellite's own parts leave of each diode's view, where this model's body box is not
    enough: per diode a mask (K, n_theta, n_phi) over directions in its frame (rows: angle from the
    normal over 0..90 deg, columns: azimuth from u over -180..180 deg) of the cells where shadows of
    the body or of other parts cross the diode, and inside them the visible share of the diode's lit
    part (0..1) on a grid ``sub`` times finer (``fine``, (K, n_theta sub, n_phi sub)) and on one half as
    fine (``half``, for the error of the quadrature), e.g. from
    ``simcore.render.Renderer.visible_share``. The albedo from marked cells is the well's
    response times the fine share (nearest cell); elsewhere the body box at the diode's centre decides.
    """

    mask: np.ndarray
    fine: np.ndarray
    half: np.ndarray

    def __post_init__(self):
        m = np.asarray(self.mask, bool)
        K, nt, nph = m.shape
        sub = self.fine.shape[1] // nt
        if (sub < 2 or sub % 2 or self.fine.shape != (K, nt * sub, nph * sub)
                or self.half.shape != (K, nt * sub // 2, nph * sub // 2)):
            raise ValueError(f"DirectionVisibility: fine must be (K, n_theta sub, n_phi sub) with an even sub and "
                             f"half (K, n_theta sub/2, n_phi sub/2); got mask {m.shape}, fine {self.fine.shape}, "
                             f"half {self.half.shape}")
        object.__setattr__(self, "mask", m)

    @functools.cached_property
    def compact(self):
        """Return (slots (K, n_theta n_phi) uint32, fine (S + 1, sub, sub), half (S + 1, sub/2, sub/2), sub): per
        diode and cell 0 where unmarked, else the marked cell's slot in ``fine`` and ``half``, which hold the
        visible shares inside the S marked cells only (NaN read as 0; slot 0 is all 0). A lookup reads ~2 % of the full
        tables' memory, so the albedo kernel's gathers stay in cache."""
        K, nt, nph = self.mask.shape
        sub = self.fine.shape[1] // nt
        k, i, j = np.nonzero(self.mask)
        slots = np.zeros((K, nt * nph), np.uint32)
        slots[k, i * nph + j] = np.arange(1, len(k) + 1, dtype=np.uint32)
        h = sub // 2
        fine = np.zeros((len(k) + 1, sub, sub))
        half = np.zeros((len(k) + 1, h, h))
        fine[1:] = np.nan_to_num(self.fine.reshape(K, nt, sub, nph, sub)[k, i, :, j, :])
        half[1:] = np.nan_to_num(self.half.reshape(K, nt, h, nph, h)[k, i, :, j, :])
        return slots, fine, half, sub

    def kernel_bounds(self, frames, body_box):
        """Return (marked, marked_cos, panel bounds), what the albedo kernel tests before it looks a direction up,
        kept per diode frames and body box (a run asks for the same ones chunk after chunk): per diode whether any
        cell is marked, the cosine of the upper edge of its first marked row, widened by one fine row for float32
        rounding of the angle (1.0 where nothing is marked), and :func:`_marked_panel_bounds`."""
        key = (np.asarray(frames, float).tobytes(), None if body_box is None else
               (tuple(map(float, body_box.half_m)), np.asarray(body_box.positions_m, float).tobytes(),
                np.asarray(body_box.panel_normals, float).tobytes()))
        cache = self.__dict__.setdefault("_kernel_bounds", {})
        if key not in cache:
            K, nt, _ = self.mask.shape
            sub = self.compact[3]
            first_row = np.array([np.argmax(m.any(axis=1)) if m.any() else 0 for m in self.mask])
            cos = np.minimum(np.cos(np.maximum(first_row * sub - 1, 0) * (0.5 * np.pi / (nt * sub))), 1.0)
            cache[key] = (self.mask.reshape(K, -1).any(axis=1), cos.tolist(),
                          _marked_panel_bounds(self.mask, frames, body_box))
        return cache[key]


def _fine_index(d_diode, nt, nph, sub):
    """Return (fi, fj): the row (angle from the normal, 0..90 deg) and column (azimuth from u, -180..180
    deg) of directions (..., 3) in a diode frame on the grid ``sub`` times finer than (nt, nph) cells; the
    coarse cell is (fi // sub, fj // sub), the half-fine one (fi // (sub/2), ...). Directions behind the
    diode fall in the last row."""
    th = np.arccos(np.clip(d_diode[..., 2], 0.0, 1.0))
    fi = np.minimum((th * (2.0 * nt * sub / np.pi)).astype(np.int64), nt * sub - 1)
    ph = np.arctan2(d_diode[..., 1], d_diode[..., 0])
    fj = np.minimum(((ph + np.pi) * (nph * sub / _TWO_PI)).astype(np.int64), nph * sub - 1)
    return fi, fj


# ---- input checks ---------------------------------------------------------------------
def _rows(name, value, n=None):
    arr = np.asarray(value, dtype=float)
    if arr.shape == (3,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (or (3,)) in metres, ECEF; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        raise ValueError(f"{name} has non-finite rows {bad[:10].tolist()}; drop or fill those epochs first")
    return arr


def _rotations(value, n):
    R = np.asarray(value, dtype=float)
    if R.shape == (3, 3):
        R = np.broadcast_to(R, (n, 3, 3))
    if R.shape != (n, 3, 3):
        raise ValueError(f"R_ecef_from_body must have shape (N, 3, 3) with N = {n} (or (3, 3)); got {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError("R_ecef_from_body has non-finite entries")
    err = np.abs(np.einsum("nij,nkj->nik", R, R) - np.eye(3)).max()
    if err > 1e-6:
        raise ValueError(f"R_ecef_from_body must be rotation matrices (R R^T = I); worst deviation {err:.3g}")
    return R


def _frames(value):
    F = np.asarray(value, dtype=float)
    if F.shape == (3, 3):
        F = F[None]
    if F.ndim != 3 or F.shape[1:] != (3, 3) or F.shape[0] == 0:
        raise ValueError(f"diode_frames_body must have shape (K, 3, 3) (rows u, v, n of each diode, "
                         f"see simcore.shapes.aperture.diode_frame); got {F.shape}")
    if not np.all(np.isfinite(F)):
        raise ValueError("diode_frames_body has non-finite entries")
    err = np.abs(np.einsum("kij,klj->kil", F, F) - np.eye(3)).max()
    if err > 1e-6:
        raise ValueError(f"each diode frame must have orthonormal rows (u, v, n); worst deviation {err:.3g}")
    return F


def _responses(responses, k):
    if isinstance(responses, (list, tuple)):
        if len(responses) != k:
            raise ValueError(f"got {len(responses)} responses for {k} diodes; give one response or one per diode")
        return [_resp.check_response(r) for r in responses]
    return [_resp.check_response(responses)] * k


# ---- which cells: per epoch and row, runs of columns ------------------------------------
def _arc(sin_lat, cos_lat, sin_c, cos_c, threshold):
    """Return the half-width (rad) of the longitude arc where sin_lat sin_c + cos_lat cos_c cos(dlon) > threshold.

    -1 means empty, >= pi the full circle.
    """
    den = cos_lat * cos_c
    num = threshold - sin_lat * sin_c
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(den > 1e-300, num / np.where(den > 1e-300, den, 1.0), np.where(num < 0, -np.inf, np.inf))
    return np.where(q <= -1.0, np.pi, np.where(q >= 1.0, -1.0, np.arccos(np.clip(q, -1.0, 1.0))))


def _columns(start, length, full, lon0, dlon, n_lon):
    """Return (first column mod n_lon, count) of column centres strictly inside the arc [start, start + length]."""
    x0 = (start - lon0) / dlon
    x1 = x0 + length / dlon
    first = np.floor(x0) + 1.0
    count = np.clip(np.ceil(x1) - 1.0 - first + 1.0, 0.0, n_lon)
    count = np.where(length > 0, count, 0.0)
    first = np.where(full, 0.0, first)
    count = np.where(full, float(n_lon), count)
    return np.mod(first, n_lon).astype(np.int64), count.astype(np.int64)


def cell_runs(r_sat_m, sun_unit, refl):
    """Return (rows, first, count), each (N, W, 2): the runs of consecutive columns of row ``rows`` whose
    cell centres are visible from the satellite and sunlit (count 0 for unused slots)."""
    rows, first, count = _runs(r_sat_m, sun_unit, refl)
    return np.stack([rows, rows], axis=-1), np.moveaxis(first, 0, -1), np.moveaxis(count, 0, -1)


def _runs(r_sat_m, sun_unit, refl):
    """Return :func:`cell_runs` as the albedo kernel takes it: rows (N, W), first and count (2, N, W), piece first."""
    R = refl.radius_m
    r = np.linalg.norm(r_sat_m, axis=1)
    sat_unit = r_sat_m / r[:, None]
    cos_rho = R / r
    rho = np.arccos(np.clip(cos_rho, -1.0, 1.0))
    lat_s = np.arcsin(np.clip(sat_unit[:, 2], -1.0, 1.0))
    lon_s = np.arctan2(sat_unit[:, 1], sat_unit[:, 0])
    lat_sun = np.arcsin(np.clip(sun_unit[:, 2], -1.0, 1.0))
    lon_sun = np.arctan2(sun_unit[:, 1], sun_unit[:, 0])

    # Rows whose centre latitude lies within rho of the sub-satellite latitude (others cannot be visible).
    lat0, step = np.radians(refl.lat_deg[0]), np.radians(refl.lat_deg[1] - refl.lat_deg[0])
    lo = (np.maximum(lat_s - rho, -np.pi / 2) - lat0) / step
    hi = (np.minimum(lat_s + rho, np.pi / 2) - lat0) / step
    i_min = np.clip(np.floor(np.minimum(lo, hi)), 0, refl.n_lat - 1).astype(np.int64)
    i_max = np.clip(np.ceil(np.maximum(lo, hi)), 0, refl.n_lat - 1).astype(np.int64)
    width = int(np.max(i_max - i_min)) + 1
    rows = i_min[:, None] + np.arange(width)[None, :]
    valid = rows <= i_max[:, None]
    rows = np.minimum(rows, refl.n_lat - 1)
    lat = np.radians(refl.lat_deg)[rows]
    sl, cl = np.sin(lat), np.cos(lat)

    a_vis = _arc(sl, cl, np.sin(lat_s)[:, None], np.cos(lat_s)[:, None], cos_rho[:, None])
    a_sun = _arc(sl, cl, np.sin(lat_sun)[:, None], np.cos(lat_sun)[:, None], 0.0)
    a_vis = np.where(valid, a_vis, -1.0)
    full_a, full_b = a_vis >= np.pi, a_sun >= np.pi
    len_a = np.where(a_vis > 0, 2 * np.minimum(a_vis, np.pi), 0.0)
    len_b = np.where(a_sun > 0, 2 * np.minimum(a_sun, np.pi), 0.0)
    a0 = lon_s[:, None] - a_vis
    b0 = lon_sun[:, None] - a_sun
    # Intersection of two arcs: B relative to A's start; at most two pieces.
    t = np.mod(b0 - a0, _TWO_PI)
    p1_start, p1_len = a0 + t, np.clip(np.minimum(t + len_b, len_a) - t, 0.0, None)
    p2_start, p2_len = a0, np.clip(np.minimum(t + len_b - _TWO_PI, len_a), 0.0, None)
    # Full circles: the intersection is simply the other arc.
    p1_start = np.where(full_a, b0, np.where(full_b, a0, p1_start))
    p1_len = np.where(full_a, len_b, np.where(full_b, len_a, p1_len))
    p2_len = np.where(full_a | full_b, 0.0, p2_len)
    p1_full = full_a & full_b
    empty = (len_a <= 0) | (len_b <= 0)
    p1_len = np.where(empty, 0.0, p1_len)
    p2_len = np.where(empty, 0.0, p2_len)

    lon0, dlon, n_lon = np.radians(refl.lon_deg[0]), np.radians(refl.dlon_deg), refl.n_lon
    f1, c1 = _columns(p1_start, p1_len, p1_full, lon0, dlon, n_lon)
    f2, c2 = _columns(p2_start, p2_len, np.zeros_like(p1_full), lon0, dlon, n_lon)
    return rows, np.stack([f1, f2]), np.stack([c1, c2])


def _glint_terms(glint, refl):
    """Return (sigma^2, water index, optical depth, pi x sea area of each cell (n_lat, n_lon) m^2) of ``glint`` (a
    :class:`~simcore.radiometry.glint.SunGlint`) on map ``refl``: the albedo sums' glint terms.

    The map's reflectivity is read as the diffuse (Lambertian) part of each cell and the glint is added on its
    sea fraction: a cell's weight ``rho A mu_i mu_o / d^2`` (times E_sun / pi) gains
    ``pi s A f(s, v) mu_i mu_o / d^2`` (times the same E_sun / pi), s the sea fraction; f at the cell's centre."""
    sea = glint.sea_fraction(refl)
    return glint.mss, glint.index, glint.tau, np.pi * sea * refl.row_area_m2[:, None]


# ---- the albedo sums ---------------------------------------------------------------------
def _albedo_numpy(r_sat, sun_unit, R_body_from_ecef, frames, responses, refl, body=None, visibility=None,
                  box_sum=True, glint=None, share_sums=True):  # (box_sum: one bincount here; always returned)
    """Return sum_c w_c A_k(...) (N, K) without the E_sun/pi factor, float64 numpy; with ``visibility`` (a
    :class:`DirectionVisibility`) also the same sum with its half-fine share, the sum of the well's
    response over its marked cells alone and the sum with the body box alone deciding everywhere (else
    None, None, None). ``glint``: None, or (sigma^2, water index, optical depth, pi x sea area of each cell (n_lat, n_lon) m^2)
    (:func:`_glint_terms`): each cell's weight gains its sea's glint."""
    n_ep, K = r_sat.shape[0], frames.shape[0]
    out = np.zeros((n_ep, K))
    alt = None if visibility is None else np.zeros((n_ep, K))
    band = None if visibility is None else np.zeros((n_ep, K))
    box_only = None if visibility is None else np.zeros((n_ep, K))
    rows, first, count = cell_runs(r_sat, sun_unit, refl)
    cnt = count.reshape(-1)
    if cnt.sum() == 0:
        return out, alt, band, box_only
    ep = np.repeat(np.repeat(np.arange(n_ep), rows.shape[1] * 2), cnt)
    row = np.repeat(rows.reshape(-1), cnt)
    offs = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    col = (np.repeat(first.reshape(-1), cnt) + offs) % refl.n_lon
    n = refl.normals_ecef[row, col]
    v = r_sat[ep] - refl.radius_m * n                          # cell -> satellite
    d2 = np.einsum("ij,ij->i", v, v)
    inv_d = 1.0 / np.sqrt(d2)
    cos_out = np.einsum("ij,ij->i", v, n) * inv_d
    cos_in = np.einsum("ij,ij->i", sun_unit[ep], n)
    w = refl.weights_m2[row, col] * np.maximum(cos_in, 0.0) * np.maximum(cos_out, 0.0) * inv_d ** 2
    if glint is not None:
        mss, index, tau, sea = glint
        cos_io = np.einsum("ij,ij->i", sun_unit[ep], v) * inv_d
        w = w + sea[row, col] * _glint.reflected_cos2(cos_in, cos_out, cos_io, mss, index, tau=tau) * inv_d ** 2
    e_body = np.einsum("nij,nj->ni", R_body_from_ecef[ep], -v * inv_d[:, None])
    comp = None if visibility is None else visibility.compact
    for k in range(K):
        d_diode = e_body @ frames[k].T
        a0 = responses[k].response(d_diode)
        a = a0 if body is None else np.where(box_hit(body.positions_m[k], e_body, body.half_m), 0.0, a0)
        if comp is not None:
            slots, fine, half, sub = comp
            nt, nph = visibility.mask.shape[1:]
            fi, fj = _fine_index(d_diode, nt, nph, sub)
            s_ = slots[k][(fi // sub) * nph + fj // sub].astype(np.int64)
            mark = s_ > 0
            band[:, k] = np.bincount(ep, weights=w * a0 * mark, minlength=n_ep)
            box_only[:, k] = np.bincount(ep, weights=w * a, minlength=n_ep)
            a_alt = np.where(mark, a0 * half[s_, (fi % sub) // 2, (fj % sub) // 2], a)
            a = np.where(mark, a0 * fine[s_, fi % sub, fj % sub], a)
            alt[:, k] = np.bincount(ep, weights=w * a_alt, minlength=n_ep)
        out[:, k] = np.bincount(ep, weights=w * a, minlength=n_ep)
    return (out, alt, band, box_only) if share_sums else (out, None, None, box_only)


_LANE_BUCKET = 8        # the albedo kernel's lanes: runs whose lengths differ by less than this count as one length


def _well_cutoff_cos(resp, margin=1e-4):
    """Return c >= 0 with the response of ``resp`` exactly 0 (in the kernel's float32) wherever d_n <= c: for a
    rectangular well (:class:`~simcore.radiometry.response.WellAperture`), each rim (half opening w, height h > 0)
    lights the diode (half side a) only where |d_u| < T_x d_n and |d_v| < T_y d_n, T = (w + a) / h, so d_n > 1 /
    sqrt(1 + T_x^2 + T_y^2) with each T the smaller of its rims'; less ``margin``, which leaves |d_u| or |d_v|
    ~1e-3 beyond its bound (float32 errs ~1e-7). 0 (behind the diode) for any other response or no rim."""
    if not isinstance(resp, _resp.WellAperture):
        return 0.0
    ax, ay, wx, wy, h, tx, ty, th = resp.rims
    rims = [(x, y, z) for x, y, z in ((wx, wy, h), (tx, ty, th)) if z > 0]
    if not rims:
        return 0.0
    kx = min((x + ax) / z for x, _, z in rims)
    ky = min((y + ay) / z for _, y, z in rims)
    return max(float(1.0 / np.sqrt(1.0 + kx * kx + ky * ky)) - margin, 0.0)


class _DrJitOps:
    def __init__(self, dr, tiny):
        self.maximum = dr.maximum
        self.minimum = dr.minimum
        self.where = dr.select
        self.sqrt, self.exp, self.log, self.floor = dr.sqrt, dr.exp, dr.log, dr.floor   # (the window's kernel)
        self.tiny = tiny
        self.asin, self.erf = dr.asin, dr.erf


def _albedo_drjit(r_sat, sun_unit, R_body_from_ecef, frames, responses, refl, precision, body_box=None,
                  visibility=None, box_sum=True, glint=None, share_sums=True):
    """Return sum_c w_c A_k(...) (N, K) without the E_sun/pi factor from one Dr.Jit LLVM kernel, and the
    three sums of :func:`_albedo_numpy` for ``visibility`` (else None, None, None; the box-only one None
    unless ``box_sum``, the half-fine share's and the marked cells' None unless ``share_sums``: accumulators
    fewer in the kernel); ``glint`` as in :func:`_albedo_numpy` (None: the kernel is traced as it was without
    glint)."""
    dr = _llvm.import_drjit()
    from drjit.llvm import Float, Float64, UInt32

    F = Float if precision == "single" else Float64
    n_ep, K = r_sat.shape[0], frames.shape[0]
    rows, first, count = _runs(r_sat, sun_unit, refl)
    W = rows.shape[1]
    # One lane per run of columns (piece, epoch, row) that holds cells, the lanes ordered by run length in steps
    # of _LANE_BUCKET columns (longest first), and within a step by epoch (then piece and row), so that the lanes
    # of a SIMD packet loop about as long as each other (71 % of the packets' lane-iterations did work in the
    # plain (piece, epoch, row) order on the default study's refined cells) and mostly share an epoch: one
    # attitude, neighbouring rows, so that the kernel's branches (a diode facing away, the body box, the traced
    # visible shares) go the same way across a packet. Ordered by exact length, a packet held lanes of many
    # epochs: the kernels took ~10 % (refined cells, with the shares) and ~5-9 % (native cells) more CPU time.
    # Each lane sums its own run in the same order whatever its place, and an epoch's lanes' sums are added in
    # (piece, row) order (below): the sums are bit for bit the same whatever the lanes' order or the chunk.
    n_all = 2 * n_ep * W
    runs = count.reshape(-1)
    lane_epoch = np.arange(n_all) // W % n_ep
    order = np.lexsort((lane_epoch, -((runs + _LANE_BUCKET - 1) // _LANE_BUCKET)))
    order = order[:max(int(np.count_nonzero(runs)), 2)]       # (empty runs last; >= 2 lanes: no literal)
    lane_row = _llvm.host_array(UInt32, rows.reshape(-1)[order % (n_ep * W)])
    lane_first = _llvm.host_array(UInt32, first.reshape(-1)[order])
    lane_count = _llvm.host_array(UInt32, runs[order])
    n_lanes = len(order)
    lane_ep = _llvm.host_array(UInt32, lane_epoch[order])

    def table(a):
        return _llvm.host_array(F, a)

    def per_epoch(a):
        return dr.gather(F, table(a), lane_ep)

    sx, sy, sz = (per_epoch(r_sat[:, i]) for i in range(3))
    ux, uy, uz = (per_epoch(sun_unit[:, i]) for i in range(3))
    M = [per_epoch(R_body_from_ecef[:, i, j]) for i in range(3) for j in range(3)]
    lat = np.radians(refl.lat_deg)
    slat = dr.gather(F, table(np.sin(lat)), lane_row)
    clat = dr.gather(F, table(np.cos(lat)), lane_row)
    lon = np.radians(refl.lon_deg)
    cos_lon, sin_lon = table(np.cos(lon)), table(np.sin(lon))
    weights = table(refl.weights_m2)
    if glint is not None:
        g_mss, g_index, g_tau, g_sea = float(glint[0]), float(glint[1]), float(glint[2]), table(glint[3])
    radius = float(refl.radius_m)
    n_lon = refl.n_lon
    fr = frames.tolist()
    ops = _DrJitOps(dr, 1e-30 if precision == "single" else 1e-300)
    kernels = [_resp.kernel(r) for r in responses]
    dark_behind = [isinstance(r, _DARK_BEHIND) for r in responses]
    front_cos = [_well_cutoff_cos(r) for r in responses]
    base = lane_row * n_lon
    # A diode centred on or beyond its panel's face (the panel normal a body axis) meets the box only along
    # directions below the panel's plane: along the others the slab test's exit along that axis is at t <= 0
    # (exactly, also for a direction in the plane). A packet of lanes that all look above it skips the test.
    box_above = [None] * K
    box_face = [None] * K
    if body_box is not None:
        for k in range(K):
            pn = np.asarray(body_box.panel_normals[k], float)
            beyond = pn @ np.asarray(body_box.positions_m[k], float) >= np.abs(pn) @ np.asarray(body_box.half_m, float)
            if np.count_nonzero(pn) == 1 and beyond:
                box_above[k] = pn.tolist()
                box_face[k] = _face_test(body_box.positions_m[k], body_box.half_m, pn)

    def _diode_term(k, a0, wt, bx, by, bz, du, dv, dn, acc, *more):
        a = a0
        if body_box is not None:
            if box_above[k] is None:
                a = _box_term(k, a0, bx, by, bz)
            else:
                pn = box_above[k]
                a = dr.if_stmt(args=(k, a0, bx, by, bz), cond=pn[0] * bx + pn[1] * by + pn[2] * bz < 0.0,
                               true_fn=_box_term if box_face[k] is None else _face_term, false_fn=lambda k, a0, *_: a0)
        if comp is None:
            return (acc + wt * a,)
        shares, box = (more[:2], more[2:]) if share_sums else ((), more)
        box = [b + wt * a for b in box]
        if marked[k]:
            # the marked cells lie beyond the diode's first marked row (angle from the normal): a packet of
            # lanes nearer the normal skips the angles and lookups (a branch in the kernel)
            cond = dn < marked_cos[k]
            if marked_dot[k] is not None:
                q, top, bottom, axis = marked_dot[k]
                if axis is None:
                    height = q[0] * du + q[1] * dv + q[2] * dn
                    cond &= (height < top) & (height > bottom)
                else:
                    # the panel's normal is a body axis: q . d is (bx, by, bz)'s component along it, read without
                    # arithmetic (it and the float32 q . d differ by ~1e-7, far inside the bounds' 1e-4 margin)
                    c = (bx, by, bz)[axis % 3]
                    cond &= (c < top) & (c > bottom) if axis < 3 else (c > -top) & (c < -bottom)
            *shares, a = dr.if_stmt(args=(k, a0, a, wt, du, dv, dn, *shares), cond=cond,
                                    true_fn=_marked_share, false_fn=_unmarked_share)
        elif share_sums:
            shares = (shares[0], shares[1] + wt * a)
        return (acc + wt * a, *shares, *box)

    def _face_term(k, a0, bx, by, bz):
        # below the panel's plane: where the ray crosses the face's plane (_face_test), clearly inside the face
        # (hit: 0) or clearly outside it (a0) without the slab test's six divisions; the slab test near its edges
        i, s, dist, others = box_face[k]
        d = (bx, by, bz)
        t = dist / (-s * d[i])
        inside, outside = None, None
        for j, p, lo, hi in others:
            c = dr.abs(p + t * d[j])
            inside = c < lo if inside is None else inside & (c < lo)
            outside = c > hi if outside is None else outside | (c > hi)
        return dr.if_stmt(args=(k, a0, dr.select(inside, 0.0, a0), bx, by, bz), cond=~(inside | outside),
                          true_fn=lambda k, a0, _, bx, by, bz: _box_term(k, a0, bx, by, bz),
                          false_fn=lambda k, a0, a, *_: a)

    def _box_term(k, a0, bx, by, bz):
        # the response with the body box's slab test from the diode's centre
        return dr.select(_box_hit_dr(dr, body_box.positions_m[k], (bx, by, bz), body_box.half_m), 0.0, a0)

    def _marked_share(k, a0, a, wt, du, dv, dn, *shares):
        # the cells of _fine_index: theta from the normal, azimuth from u
        th = dr.acos(dr.clip(dn, 0.0, 1.0))
        ph = dr.atan2(dv, du) + np.pi
        fi = dr.minimum(UInt32(th * (2.0 * nt * sub / np.pi)), nt * sub - 1)
        fj = dr.minimum(UInt32(ph * (nph * sub / _TWO_PI)), nph * sub - 1)
        slot = dr.gather(UInt32, slots, (fi // sub) * nph + fj // sub + k * nt * nph)
        mark = slot > 0
        ri, rj = fi % sub, fj % sub
        f_share = dr.gather(F, fine, slot * (sub * sub) + ri * sub + rj, mark)
        if not shares:
            return (dr.select(mark, a0 * f_share, a),)
        part, alt = shares
        h_share = dr.gather(F, half, slot * (h * h) + (ri // 2) * h + rj // 2, mark)
        return (part + wt * dr.select(mark, a0, 0.0), alt + wt * dr.select(mark, a0 * h_share, a),
                dr.select(mark, a0 * f_share, a))

    def _unmarked_share(k, a0, a, wt, du, dv, dn, *shares):
        return (shares[0], shares[1] + wt * a, a) if shares else (a,)

    def _no_term(wt, bx, by, bz, du, dv, dn, *acc):
        return acc

    def _seen_term(k, wt, bx, by, bz, du, dv, dn, *acc):
        # (no branch on a0 > 0 here: behind a well's cut-off the branch around this term skips it already; with
        # that branch the kernels took 3-6 % more time. A lane with a0 = 0 adds +0.0 to each sum: the same bits)
        return _diode_term(k, kernels[k](du, dv, dn, ops), wt, bx, by, bz, du, dv, dn, *acc)

    def cond(t, *acc):
        return t < lane_count

    def body(t, *acc):
        j = lane_first + t
        j = dr.select(j >= n_lon, j - n_lon, j)
        cj, sj = dr.gather(F, cos_lon, j), dr.gather(F, sin_lon, j)
        w = dr.gather(F, weights, base + j)
        nx, ny, nz = clat * cj, clat * sj, slat
        vx, vy, vz = sx - radius * nx, sy - radius * ny, sz - radius * nz
        inv_d = dr.rsqrt(vx * vx + vy * vy + vz * vz)
        cos_out = (vx * nx + vy * ny + vz * nz) * inv_d
        cos_in = ux * nx + uy * ny + uz * nz
        wt = w * dr.maximum(cos_in, 0.0) * dr.maximum(cos_out, 0.0) * inv_d * inv_d
        if glint is not None:
            cos_io = (ux * vx + uy * vy + uz * vz) * inv_d
            wt = wt + dr.gather(F, g_sea, base + j) * _glint.reflected_cos2(cos_in, cos_out, cos_io, g_mss, g_index,
                                                                          ops, g_tau) * inv_d * inv_d
        ex, ey, ez = -vx * inv_d, -vy * inv_d, -vz * inv_d
        bx = M[0] * ex + M[1] * ey + M[2] * ez
        by = M[3] * ex + M[4] * ey + M[5] * ez
        bz = M[6] * ex + M[7] * ey + M[8] * ez
        groups = [[] for _ in range(n_acc // K)]      # the accumulators, diode by diode: acc, (part, alt), (box)
        for k in range(K):
            f = fr[k]
            du = f[0][0] * bx + f[0][1] * by + f[0][2] * bz
            dv = f[1][0] * bx + f[1][1] * by + f[1][2] * bz
            dn = f[2][0] * bx + f[2][1] * by + f[2][2] * bz
            state = (wt, bx, by, bz, du, dv, dn, *(acc[g * K + k] for g in range(len(groups))))
            if dark_behind[k]:
                # the response is exactly 0 behind the diode, and beyond a well's cut-off (_well_cutoff_cos): a
                # packet of lanes that all look at such cells skips the response too (a branch in the kernel)
                out = dr.if_stmt(args=state, cond=dn > front_cos[k], true_fn=functools.partial(_seen_term, k),
                                 false_fn=_no_term)
            else:
                out = _seen_term(k, *state)
            for g, x in zip(groups, out):
                g.append(x)
        return (t + 1, *(x for g in groups for x in g))

    comp = None if visibility is None else visibility.compact
    n_acc = K if comp is None else (1 + 2 * bool(share_sums) + bool(box_sum)) * K
    if comp is not None:
        nt, nph = visibility.mask.shape[1:]
        sub, h = comp[3], comp[3] // 2
        marked, marked_cos, marked_dot = visibility.kernel_bounds(frames, body_box)
        slots = _llvm.host_array(UInt32, comp[0])
        fine, half = table(comp[1]), table(comp[2])
    state = (dr.zeros(UInt32, n_lanes), *[dr.zeros(F, n_lanes) for _ in range(n_acc)])
    # (without Dr.Jit's loop-invariant pass: the marked shares' sums of diodes with no marked cell stay 0, and that
    # pass would trace the body a second time to fold them, ~3 ms a refined call; the sums are the same)
    with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
        _, *acc = dr.while_loop(state=state, cond=cond, body=body)
    dr.eval(*acc)
    # An epoch's runs added one by one in (piece, row) order (the empty runs that pad an epoch to the chunk's widest
    # add exact zeros, where numpy's pairwise sum would group the runs by the chunk's width), so that an epoch's sum
    # does not depend on its chunk (a resumed run reads the same numbers): the lanes go to (piece, row, epoch) order,
    # each (piece, row) a contiguous slab of epochs.
    piece, rest = np.divmod(order, n_ep * W)
    slot = piece * (W * n_ep) + rest % W * n_ep + rest // W
    runs = np.zeros((n_acc, 2 * W, n_ep))
    flat = runs.reshape(n_acc, -1)
    for k in range(n_acc):
        flat[k, slot] = np.asarray(acc[k].numpy(), dtype=np.float64)
    total = runs[:, 0].copy()
    for r in range(1, 2 * W):
        total += runs[:, r]
    sums = total.T
    if comp is None:
        return sums, None, None, None
    box = sums[:, -K:] if box_sum else None
    if not share_sums:
        return sums[:, :K], None, None, box
    return sums[:, :K], sums[:, 2 * K:3 * K], sums[:, K:2 * K], box


def _unit_axis(normal):
    """Return i (0, 1, 2) where ``normal`` is exactly +e_i, i + 3 where it is exactly -e_i, else None."""
    n = [float(x) for x in normal]
    for i in range(3):
        if abs(n[i]) == 1.0 and n[(i + 1) % 3] == 0.0 and n[(i + 2) % 3] == 0.0:
            return i if n[i] > 0 else i + 3
    return None


def _marked_panel_bounds(mask, frames, body_box):
    """Return per diode None or (q, top, bottom, axis): ``q`` (3,) its panel's outward normal in the diode frame
    (``axis``: :func:`_unit_axis` of it in the body frame, or None) and ``top``, ``bottom`` bounds on q . d over
    every direction d of its marked cells (``mask`` (K, n_theta, n_phi), the cells of
    :class:`DirectionVisibility`): the kernel looks a direction up only where bottom < q . d < top. The marked
    cells are where shadows of the body, rails and mounts cross the diode, near its panel's plane; most Earth cells
    a tilted diode sees lie well above it (on the default study 13 % of the lookups of the angle-from-the-normal
    bound alone are left), and those well below it in the body's full shadow (the lower bound leaves ~17 % of the
    remaining packets' lookups out). Each cell's centre plus or minus its half-diagonal (no point of the cell is
    farther from the centre, and q . d moves by at most that angle in radians) and 1e-4 for the kernel's float32
    angles: a looked-up cell is never skipped. None without a body box (no panel normals) or a marked cell."""
    K, nt, nph = mask.shape
    if body_box is None:
        return [None] * K
    th = (np.arange(nt) + 0.5) * (0.5 * np.pi / nt)
    ph = -np.pi + (np.arange(nph) + 0.5) * (_TWO_PI / nph)
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    centres = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1)
    half_diagonal = 0.5 * np.hypot(0.5 * np.pi / nt, _TWO_PI / nph)
    out = []
    for k in range(K):
        if not mask[k].any():
            out.append(None)
            continue
        q = frames[k] @ np.asarray(body_box.panel_normals[k], float)
        height = centres[mask[k]] @ q
        out.append((q.tolist(), float(height.max()) + half_diagonal + 1e-4, float(height.min()) - half_diagonal - 1e-4,
                    _unit_axis(body_box.panel_normals[k])))
    return out


def _face_test(position, half, normal, margin=1e-5):
    """Return (i, s, dist, others) for a diode centred at ``position`` beyond the face of the box [-half, half]
    whose outward normal is ``normal`` (s e_i), or None where it does not lie inside the box's other two slabs by
    more than m = ``margin`` (max half + max |position|): ``dist`` = s position_i - half_i >= 0, and per other axis
    j (j, position_j, half_j - m, half_j + m). A ray from the diode toward d with s d_i < 0 crosses the face's
    plane at t = dist / (-s d_i); it meets the box if both |position_j + t d_j| < half_j and misses it if one
    exceeds half_j. m (1.7e-6 m on the default body) is ~50 times what float32 rounding moves those crossings and
    the slab test's times (a few 1e-8 of the box's size), so that the slab test (:func:`_box_hit_dr`) answers the
    same wherever this test is clear; between the bounds the kernel asks it."""
    pos, half, n = (np.asarray(x, float) for x in (position, half, normal))
    margin = margin * float(half.max() + np.abs(pos).max())
    i = int(np.flatnonzero(n)[0])
    s = float(np.sign(n[i]))
    others = [j for j in range(3) if j != i]
    if any(abs(pos[j]) >= half[j] - margin for j in others):
        return None
    return i, s, float(s * pos[i] - half[i]), [(j, float(pos[j]), float(half[j] - margin), float(half[j] + margin))
                                               for j in others]


def _box_hit_dr(dr, origin, d, half):
    """Slab test in a Dr.Jit kernel: does the ray origin + t d (t > 0) hit the box [-half, half]?
    ``origin`` and ``half`` are Python floats (baked into the kernel), ``d`` Dr.Jit arrays."""
    t_in, t_out = None, None
    for o, di, h in zip(map(float, origin), d, map(float, half)):
        safe = dr.select(dr.abs(di) > 1e-12, di, 1e-12)
        t1, t2 = (-h - o) / safe, (h - o) / safe
        lo, hi = dr.minimum(t1, t2), dr.maximum(t1, t2)
        t_in = lo if t_in is None else dr.maximum(t_in, lo)
        t_out = hi if t_out is None else dr.minimum(t_out, hi)
    return (t_in <= t_out) & (t_out > 0)


# ---- public entry point ---------------------------------------------------------------------
def diode_irradiance(r_sat_ecef_m, r_sun_ecef_m, R_ecef_from_body, diode_frames_body, responses, *,
                     map=None, e_sun_w_m2=E_SUN_W_M2, distance_scaling=False, eclipse="cylindrical",
                     albedo=True, backend="auto", precision="single", batch_epochs=4096, body=None,
                     sun_angular_radius_rad=0.0, direct=True, visibility=None, box_albedo=False, glint=None,
                     earth=None, mesh_terms=True):
    """Return the direct-Sun and albedo irradiance on K diodes at N epochs, W/m^2, as :class:`AnalyticIrradiance`.

    ``r_sat_ecef_m``, ``r_sun_ecef_m``: (N, 3) (or (3,)) geocentric ECEF metres;
    ``e_sun_w_m2``: solar constant, times (1 AU / distance)^2 when ``distance_scaling``;
    ``R_ecef_from_body``: (N, 3, 3) (or (3, 3)); ``diode_frames_body``: (K, 3, 3),
    rows (u, v, n) of each diode in the body frame; ``responses``: one response
    for all diodes or K of them (:mod:`simcore.radiometry.response`,
    :class:`simcore.shapes.aperture.WellAperture`). ``map``: reflectivity map (None:
    TOMS 2005). ``eclipse``: 'cylindrical' (thesis sec. 4.1.4), 'conical'
    (penumbra) or None; it dims the direct Sun only. ``albedo=False`` skips
    the Earth. ``backend``: 'drjit' (LLVM kernel, ``precision`` 'single' or
    'double'), 'numpy' (float64, any response object) or 'auto' (drjit when
    every response has a kernel form). ``body``: a :class:`BodyBox`, the
    satellite body as an occluder (:mod:`simcore.shapes.occlusion`): exact for the
    direct Sun (needs well apertures as responses), the diode centre for albedo.
    ``sun_angular_radius_rad``: > 0 averages the direct response over the solar
    disc (37 equal-area points), as a renderer with a finite Sun sees it.
    ``direct=False`` skips the direct Sun (zeros), e.g. for an albedo-only reference.
    ``visibility``: a :class:`DirectionVisibility`: the albedo from the directions it marks is the
    well's response times the visible share it gives (the body box decides elsewhere);
    ``albedo_mesh_w_m2`` is then the albedo through those directions before their shadow, and
    ``albedo_visibility_error_w_m2`` the difference its half-fine share makes (the quadrature's error),
    and, with ``box_albedo``, ``albedo_box_w_m2`` the albedo without it (the body box deciding everywhere),
    from the same pass; ``mesh_terms=False`` leaves ``albedo_mesh_w_m2`` and ``albedo_visibility_error_w_m2`` out
    (None; two sums per diode fewer in the kernel).
    ``glint``: a :class:`simcore.radiometry.glint.SunGlint`: the sea's Cox-Munk glint on each cell's sea
    fraction, added to the map's (diffuse) reflectivity (:func:`_glint_terms`); None: none.
    ``earth``: a :class:`simcore.environment.earth.Earth`, the map and the glint in one (instead of ``map`` and
    ``glint``).
    """
    if earth is not None:
        if map is not None or glint is not None:
            raise ValueError("give the Earth either as earth= or as map= and glint=, not both")
        map, glint = earth.map, earth.glint
    r_sat = _rows("r_sat_ecef_m", r_sat_ecef_m)
    r_sun = _rows("r_sun_ecef_m", r_sun_ecef_m)
    if r_sun.shape[0] == 1 and r_sat.shape[0] > 1:
        r_sun = np.broadcast_to(r_sun, r_sat.shape)
    if r_sun.shape != r_sat.shape:
        raise ValueError(f"r_sat_ecef_m has {r_sat.shape[0]} epochs and r_sun_ecef_m {r_sun.shape[0]}; "
                         "give both with the same N (or the Sun as one (3,) vector)")
    n_ep = r_sat.shape[0]
    R = _rotations(R_ecef_from_body, n_ep)
    frames = _frames(diode_frames_body)
    resps = _responses(responses, frames.shape[0])
    refl = as_map(map)
    if eclipse not in ("cylindrical", "conical", None):
        raise ValueError(f"eclipse must be 'cylindrical', 'conical' or None, got {eclipse!r}")
    if precision not in ("single", "double"):
        raise ValueError(f"precision must be 'single' or 'double', got {precision!r}")
    if backend not in ("auto", "drjit", "numpy"):
        raise ValueError(f"backend must be 'auto', 'drjit' or 'numpy', got {backend!r}")
    if backend == "auto":
        backend = "drjit" if all(isinstance(r, _resp.WellAperture) or hasattr(r, "kernel") for r in resps) \
            else "numpy"
    if backend == "drjit":
        for r in resps:
            _resp.kernel(r)          # raises TypeError for a response without a kernel form
    check_geometry(r_sat, r_sun, refl.radius_m)
    e_sun = sun_irradiance_w_m2(r_sun, e_sun_w_m2, distance_scaling)

    # Direct Sun: satellite -> Sun direction, eclipse factor.
    if eclipse == "cylindrical":
        lit = _eclipse.cylindrical(r_sat, r_sun, refl.radius_m).astype(float)
    elif eclipse == "conical":
        lit = np.asarray(_eclipse.conical(r_sat, r_sun, refl.radius_m, R_SUN_M), dtype=float)
    else:
        lit = np.ones(n_ep)
    to_sun = r_sun - r_sat
    to_sun = to_sun / np.linalg.norm(to_sun, axis=1)[:, None]
    R_body_from_ecef = np.ascontiguousarray(np.swapaxes(R, 1, 2))
    sun_body = np.einsum("nij,nj->ni", R_body_from_ecef, to_sun)
    earth_body = np.einsum("nij,nj->ni", R_body_from_ecef, -r_sat) if eclipse == "conical" else None
    response = np.zeros((n_ep, frames.shape[0]))
    on = np.flatnonzero(lit > 0) if direct else np.zeros(0, int)     # in the Earth's umbra the direct Sun is 0
    if on.size:
        response[on] = _direct_response(sun_body[on], frames, resps, body, sun_angular_radius_rad,
                                        None if earth_body is None else earth_body[on], refl.radius_m)
    # 1/r^2 for the direct Sun over the satellite -> Sun distance; the Earth's cells use the geocentric one.
    e_direct = sun_irradiance_w_m2(r_sun - r_sat, e_sun_w_m2, distance_scaling)
    direct = response * (e_direct * lit)[:, None]

    alb = np.zeros((n_ep, frames.shape[0]))
    if visibility is not None and visibility.mask.shape[0] != frames.shape[0]:
        raise ValueError(f"visibility is for {visibility.mask.shape[0]} diodes, not {frames.shape[0]}")
    alb_alt = None if visibility is None or not mesh_terms else np.zeros_like(alb)
    alb_band = None if visibility is None or not mesh_terms else np.zeros_like(alb)
    alb_box = None if visibility is None or not box_albedo else np.zeros_like(alb)
    if albedo:
        sun_unit = r_sun / np.linalg.norm(r_sun, axis=1)[:, None]
        terms = None if glint is None else _glint_terms(glint, refl)
        batch = max(1, int(batch_epochs))
        if backend == "numpy":
            batch = min(batch, 256)      # numpy holds every (epoch, cell) pair of a batch in memory
        for s in range(0, n_ep, batch):
            sl = slice(s, min(n_ep, s + batch))
            fn = _albedo_drjit if backend == "drjit" else _albedo_numpy
            extra = (precision,) if backend == "drjit" else ()
            alb[sl], alt, band, box_only = fn(r_sat[sl], sun_unit[sl], R_body_from_ecef[sl], frames, resps, refl,
                                              *extra, body, visibility, box_albedo,
                                              **({} if glint is None else {"glint": terms}), share_sums=mesh_terms)
            if alb_alt is not None:
                alb_alt[sl], alb_band[sl] = alt, band
            if alb_box is not None:
                alb_box[sl] = box_only
        alb *= (e_sun / np.pi)[:, None]
        if alb_alt is not None:
            alb_alt *= (e_sun / np.pi)[:, None]
            alb_band *= (e_sun / np.pi)[:, None]
        if alb_box is not None:
            alb_box *= (e_sun / np.pi)[:, None]
    err = None if alb_alt is None else np.abs(alb - alb_alt)
    return AnalyticIrradiance(direct_w_m2=direct, albedo_w_m2=alb, illuminated_fraction=lit,
                              albedo_mesh_w_m2=alb_band, albedo_visibility_error_w_m2=err, albedo_box_w_m2=alb_box)
