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

# The 12 edges of a box as pairs of corner indices, corners indexed by bits (x, y, z) = (i & 1, i & 2, i & 4).
_EDGES = [(a, a | bit) for bit in (1, 2, 4) for a in range(8) if not a & bit]
_CORNER_SIGNS = [(1 if i & 1 else -1, 1 if i & 2 else -1, 1 if i & 4 else -1) for i in range(8)]


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


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


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


def _clip(poly, axis, bound, keep_below):
    """Clip a polygon (list of (x, y)) to the half-plane x[axis] <= bound (keep_below) or >= bound."""
    out = []
    m = len(poly)
    for i in range(m):
        a, b = poly[i], poly[(i + 1) % m]
        ina = a[axis] <= bound if keep_below else a[axis] >= bound
        inb = b[axis] <= bound if keep_below else b[axis] >= bound
        if ina:
            out.append(a)
        if ina != inb:
            t = (bound - a[axis]) / (b[axis] - a[axis])
            out.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
    return out


def _area(poly):
    if len(poly) < 3:
        return 0.0
    twice = 0.0
    for i in range(len(poly)):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % len(poly)]
        twice += x0 * y1 - x1 * y0
    return 0.5 * abs(twice)


def shadow_polygon(position_m, frame, d, half_m):
    """Return the box's shadow on the diode plane along ``d`` as a convex polygon, a list of (u, v)
    points about the diode's centre (empty when no part of the box is in front of the plane)."""
    p = [float(x) for x in position_m]
    u, v, n = ([float(x) for x in row] for row in frame)
    d = [float(x) for x in d]
    hx, hy, hz = (float(x) for x in half_m)
    corners = [(sx * hx, sy * hy, sz * hz) for sx, sy, sz in _CORNER_SIGNS]
    s = [_dot((c[0] - p[0], c[1] - p[1], c[2] - p[2]), n) for c in corners]   # height above the diode plane
    pts = [corners[i] for i in range(8) if s[i] >= 0]
    for a, b in _EDGES:
        if (s[a] > 0) != (s[b] > 0) and s[a] != s[b]:
            t = s[a] / (s[a] - s[b])
            ca, cb = corners[a], corners[b]
            pts.append((ca[0] + t * (cb[0] - ca[0]), ca[1] + t * (cb[1] - ca[1]), ca[2] + t * (cb[2] - ca[2])))
    if not pts:
        return []
    dn = _dot(d, n)
    out = []
    for y in pts:
        h = _dot((y[0] - p[0], y[1] - p[1], y[2] - p[2]), n) / dn
        x = (y[0] - h * d[0] - p[0], y[1] - h * d[1] - p[1], y[2] - h * d[2] - p[2])
        out.append((_dot(x, u), _dot(x, v)))
    return convex_hull(out)


def lit_fraction_with_box(aperture, frame, position_m, d_body, half_m):
    """Return the lit fraction (0..1) of one diode for one direction: its well's overlap minus the
    body box's shadow, exact."""
    u, v, n = frame
    d = d_body
    dn = float(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
    if dn <= 0:
        return 0.0
    du = float(d[0] * u[0] + d[1] * u[1] + d[2] * u[2])
    dv = float(d[0] * v[0] + d[1] * v[1] + d[2] * v[2])
    ax, ay = aperture.diode_x_m / 2, aperture.diode_y_m / 2
    wx, wy = aperture.opening_x_m / 2, aperture.opening_y_m / 2
    sx, sy = -aperture.height_m * du / dn, -aperture.height_m * dv / dn
    x0, x1 = max(-ax, sx - wx), min(ax, sx + wx)
    y0, y1 = max(-ay, sy - wy), min(ay, sy + wy)
    if x1 <= x0 or y1 <= y0:
        return 0.0
    lit = (x1 - x0) * (y1 - y0)
    poly = shadow_polygon(position_m, frame, d, half_m)
    if len(poly) >= 3:
        for axis, bound, below in ((0, x1, True), (0, x0, False), (1, y1, True), (1, y0, False)):
            poly = _clip(poly, axis, bound, below)
            if not poly:
                break
        lit -= _area(poly)
    return max(lit, 0.0) / (4 * ax * ay)


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
    own = np.stack([apertures[k].lit_fraction(d @ np.asarray(frames[k]).T) for k in range(K)], axis=1)
    vis[todo & (own <= 0)] = np.nan
    todo &= own > 0
    frame_l = [[[float(x) for x in row] for row in f] for f in frames]
    pos_l = [[float(x) for x in p] for p in positions_m]
    d_l = d.tolist()
    for n, k in zip(*np.nonzero(todo)):
        vis[n, k] = lit_fraction_with_box(apertures[k], frame_l[k], pos_l[k], d_l[n], half_m) / own[n, k]
    return vis
