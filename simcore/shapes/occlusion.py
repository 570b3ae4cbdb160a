"""Occlusion of a diode by the satellite body, in closed form (no ray tracing).

The body is a box of half extents ``half_m`` centred on the body origin; a
diode sits outside it, on a panel, tilted on its ramp. A ray from a point on
the diode toward ``d`` can only hit the box after crossing the panel plane,
so only directions below that plane (``d . p < 0``, p the panel's outward
normal) can be blocked; tilted diodes look that far past the panel edge
(e.g. 90-103 deg from the panel normal for tilt 20 and the 83 deg cut-off).

For the direct Sun the lit area of a diode is computed exactly: the set of
diode-plane points whose ray toward ``d`` hits the box is the projection
along ``d`` of the part of the box in front of the diode plane, a convex
polygon; it is clipped against the lit rectangle of the well (the diode
square intersected with the opening shifted by ``-h (d_u, d_v)/d_n``, see
:mod:`simcore.shapes.aperture`) and its area subtracted. For albedo the centre of
the diode stands for the whole diode (a slab test per Earth cell), which is
exact to first order for the straight shadow edges of a box.

Mounts of other diodes (ramps, wells) are not modelled here: only the
renderer sees them.
"""
import numpy as np

from simcore.shapes.aperture import lit_rectangle_of



def box_hit(origins, dirs, half_m):
    """Return True where the ray ``origin + t dir`` (t > 0) hits the box [-half, half] (slab test), bool (...)."""
    o = np.asarray(origins, dtype=float)
    d = np.asarray(dirs, dtype=float)
    h = np.asarray(half_m, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (-h - o) * inv
        t2 = (h - o) * inv
    # A zero direction component: inside the slab for all t, or never.
    inside = np.abs(o) <= h
    lo = np.where(d == 0, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    hi = np.where(d == 0, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    t_in = lo.max(axis=-1)
    t_out = hi.min(axis=-1)
    return (t_in <= t_out) & (t_out > 0)


def convex_hull(points):
    """Return the convex hull (counter-clockwise) of 2-D points, a list of (x, y) (Andrew's monotone chain)."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _clip_half_plane(poly, count, a, b, c):
    """Return (poly, count) of convex polygons (T, V, 2) with ``count`` (T,) vertices each, clipped to
    the half-planes ``a x + b y <= c`` (T,) (Sutherland-Hodgman, all polygons at once; those the
    half-plane holds whole, most of them, are left as they are)."""
    T, V = poly.shape[:2]
    idx = np.arange(V)[None, :]
    valid = idx < count[:, None]
    f = a[:, None] * poly[..., 0] + b[:, None] * poly[..., 1] - c[:, None]
    rows = np.flatnonzero((valid & (f > 0)).any(axis=1))
    if rows.size == 0:
        return poly, count
    p0, f0, ok, n = poly[rows], f[rows], valid[rows], count[rows]
    nxt = np.where(idx + 1 < n[:, None], idx + 1, 0)
    p1 = np.take_along_axis(p0, nxt[..., None], axis=1)
    f1 = np.take_along_axis(f0, nxt, axis=1)
    keep = ok & (f0 <= 0)
    cut = ok & ((f0 <= 0) != (f1 <= 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(cut, f0 / np.where(cut, f0 - f1, 1.0), 0.0)
    cand = np.stack([p0, p0 + s[..., None] * (p1 - p0)], axis=2).reshape(len(rows), 2 * V, 2)
    mask = np.stack([keep, cut], axis=2).reshape(len(rows), 2 * V)
    slot = np.cumsum(mask, axis=1) - 1                       # where each kept point goes, in order
    width = V + 1                                            # a convex clip adds at most one vertex
    out = np.zeros((T, width, 2))
    out[:, :V] = poly
    clipped = np.zeros((len(rows), width + 1, 2))
    r, k = np.nonzero(mask)
    clipped[r, slot[r, k]] = cand[r, k]
    out[rows] = clipped[:, :width]
    count = count.copy()
    count[rows] = mask.sum(axis=1)
    return out, count


def _polygon_area(poly, count):
    """Return the areas (T,) of polygons (T, V, 2) with ``count`` vertices each (shoelace; 0 below 3)."""
    V = poly.shape[1]
    idx = np.arange(V)[None, :]
    nxt = np.where(idx + 1 < count[:, None], idx + 1, 0)
    p1 = np.take_along_axis(poly, nxt[..., None], axis=1)
    cross = np.where(idx < count[:, None], poly[..., 0] * p1[..., 1] - p1[..., 0] * poly[..., 1], 0.0)
    return np.where(count >= 3, 0.5 * np.abs(cross.sum(axis=1)), 0.0)


def lit_fractions_with_box(aperture_params, frames, positions_m, d_body, half_m):
    """Return the lit fractions (T,) of T diodes, each toward its own direction: the well's overlap
    minus the body box's shadow, exact.

    ``aperture_params`` (T, 8): :attr:`simcore.shapes.aperture.WellAperture.rims` of each diode (half
    diode sides, half opening sides and height of the lower and the top rim, m; (T, 5): one rim);
    ``frames`` (T, 3, 3) rows (u, v, n); ``positions_m`` (T, 3) diode centres; ``d_body`` (T, 3)
    unit directions toward the source; ``half_m`` the box's half extents (body frame, centred).

    A point ``x = (X, Y)`` of the diode plane is shadowed when its ray ``p + X u + Y v + t d`` meets
    the box at some ``t >= 0``. Each face of the box and the plane itself (``t >= 0``) bound ``t`` from
    one side by a linear function of ``x``; eliminating ``t`` (Fourier-Motzkin) leaves the shadow as
    the intersection of the 12 half-planes "every lower bound <= every upper bound". The lit
    rectangle of the well is clipped by them and its area is the shadowed part.
    """
    ap = np.asarray(aperture_params, float)
    F = np.asarray(frames, float)
    p = np.asarray(positions_m, float)
    d = np.asarray(d_body, float)
    half = np.asarray(half_m, float)
    T = len(d)
    u, v, n = F[:, 0], F[:, 1], F[:, 2]
    du, dv, dn = (np.einsum("tj,tj->t", d, w) for w in (u, v, n))
    ax, ay = ap.T[:2]
    front = dn > 0
    x0, x1, y0, y1 = -ax, ax, -ay, ay
    for wx, wy, h in (ap.T[2:5], ap.T[5:8]) if ap.shape[1] > 5 else (ap.T[2:5],):     # each rim, shifted
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = np.where(front, -h * du / np.where(front, dn, 1.0), 0.0)
            sy = np.where(front, -h * dv / np.where(front, dn, 1.0), 0.0)
        x0, x1 = np.maximum(x0, sx - wx), np.minimum(x1, sx + wx)
        y0, y1 = np.maximum(y0, sy - wy), np.minimum(y1, sy + wy)
    lit = np.where(front, np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None), 0.0)
    poly = np.stack([np.stack([x0, y0], 1), np.stack([x1, y0], 1), np.stack([x1, y1], 1), np.stack([x0, y1], 1)], 1)
    count = np.where(lit > 0, 4, 0)
    # Constraints alpha X + beta Y + gamma t <= c on (X, Y, t): the box's faces +-e_k (the face the
    # direction runs toward bounds t from above, gamma >= 0; its opposite from below), and t >= 0.
    s = np.where(d >= 0, 1.0, -1.0)                                     # (T, 3)
    upper = [(s[:, k] * u[:, k], s[:, k] * v[:, k], s[:, k] * d[:, k], half[k] - s[:, k] * p[:, k]) for k in range(3)]
    lower = [(-s[:, k] * u[:, k], -s[:, k] * v[:, k], -s[:, k] * d[:, k], half[k] + s[:, k] * p[:, k])
             for k in range(3)]
    zero = np.zeros(T)
    lower.append((zero, zero, -np.where(front, dn, 1.0), zero))
    # gi <= 0: t >= (ci - ai X - bi Y) / gi;  gj >= 0: t <= (cj - aj X - bj Y) / gj. A face's bound against
    # its opposite face's (i == j) reads 0 X + 0 Y <= 2 half |d_k| exactly (the products cancel bit for bit):
    # it holds everywhere and is left out.
    planes = [(ai * gj - aj * gi, bi * gj - bj * gi, ci * gj - cj * gi)
              for i, (ai, bi, gi, ci) in enumerate(lower) for j, (aj, bj, gj, cj) in enumerate(upper) if i != j]
    # Most lit rectangles lie wholly outside the shadow (a half-plane excludes all four corners: nothing to
    # clip) or wholly inside it (every half-plane holds all four: the whole rectangle is shadowed); only
    # the others, which a shadow edge crosses, are clipped.
    holds_all, excludes_all = lit > 0, lit <= 0
    for a, b, c in planes:     # the largest and smallest of a X + b Y over the rectangle's corners
        ax0, ax1, by0, by1 = a * x0, a * x1, b * y0, b * y1
        holds_all &= np.maximum(ax0, ax1) + np.maximum(by0, by1) <= c
        excludes_all |= np.minimum(ax0, ax1) + np.minimum(by0, by1) > c
    shadow = np.where(holds_all, lit, 0.0)
    todo = np.flatnonzero(~holds_all & ~excludes_all)
    if todo.size:
        poly, count = poly[todo], count[todo]
        for a, b, c in planes:
            poly, count = _clip_half_plane(poly, count, a[todo], b[todo], c[todo])
        shadow[todo] = _polygon_area(poly, count)
    return np.where(front, np.clip(lit - shadow, 0.0, None) / (4 * ax * ay), 0.0)


def lit_fraction_with_box(aperture, frame, position_m, d_body, half_m):
    """Return the lit fraction (0..1) of one diode for one direction: its well's overlap minus the
    body box's shadow, exact (:func:`lit_fractions_with_box` for one)."""
    params = [aperture.rims]
    return float(lit_fractions_with_box(params, [frame], [position_m], [d_body], half_m)[0])


def _aperture_params(apertures):
    """Return (K, 8): :attr:`simcore.shapes.aperture.WellAperture.rims` of each aperture (m)."""
    return np.array([a.rims for a in apertures])


def _visibility_below(params, frames, positions_m, d, half_m):
    """Return (T,): lit fraction with the box over the well's own lit fraction for T diodes (``params``
    (T, 8), ``frames`` (T, 3, 3), ``positions_m`` (T, 3)) each toward its own direction ``d`` (T, 3) below
    its panel and in front of it; NaN where the well itself lets no light through."""
    dd = np.einsum("tij,tj->ti", frames, d)                     # the directions in the diode frames
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        own = lit_rectangle_of(params.T, dd[:, 0], dd[:, 1], dd[:, 2])[4]
    vis = np.full(len(d), np.nan)
    lit = own > 0
    vis[lit] = lit_fractions_with_box(params[lit], frames[lit], positions_m[lit], d[lit], half_m) / own[lit]
    return vis


def direct_visibility(apertures, frames, positions_m, panel_normals, d_body, half_m, only=None):
    """Return (N, K): lit fraction with the body box over the well's own lit fraction (1 where the box
    blocks nothing, 0 where it hides the whole lit area), for unit Sun directions ``d_body`` (N, 3);
    ``only`` (N, K) bool restricts the work to those pairs (the others read 1). NaN where the body
    could block but the well itself lets no light through (the ratio is undefined there)."""
    d = np.atleast_2d(np.asarray(d_body, float))
    N, K = d.shape[0], len(frames)
    vis = np.ones((N, K))
    below = d @ np.asarray(panel_normals, float).T < 0          # only these can meet the body
    front = np.einsum("nj,kj->nk", d, np.asarray(frames)[:, 2]) > 0
    todo = below & front if only is None else below & front & only
    if not todo.any():
        return vis
    n_idx, k_idx = np.nonzero(todo)
    frames = np.asarray(frames, float)
    vis[n_idx, k_idx] = _visibility_below(_aperture_params(apertures)[k_idx], frames[k_idx],
                                          np.asarray(positions_m, float)[k_idx], d[n_idx], half_m)
    return vis


def pair_visibility(apertures, frames, positions_m, panel_normals, diode, d_body, half_m):
    """Return (T,): the visibility of :func:`direct_visibility` for T (diode, direction) pairs, diode
    ``diode[t]`` (index into the K ``apertures``, ``frames``, ``positions_m``, ``panel_normals``) toward the
    unit direction ``d_body[t]`` (body frame); 1 where the box cannot block, NaN where the well is dark."""
    d = np.asarray(d_body, float).reshape(-1, 3)
    k = np.asarray(diode, dtype=np.int64).reshape(-1)
    frames = np.asarray(frames, float)
    vis = np.ones(len(d))
    below = np.einsum("tj,tj->t", d, np.asarray(panel_normals, float)[k]) < 0
    front = np.einsum("tj,tj->t", d, frames[k, 2]) > 0
    t = np.flatnonzero(below & front)
    if t.size:
        vis[t] = _visibility_below(_aperture_params(apertures)[k[t]], frames[k[t]],
                                   np.asarray(positions_m, float)[k[t]], d[t], half_m)
    return vis
