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
polygon; the area of its intersection with the lit rectangle of the well (the
diode square intersected with the opening shifted by ``-h (d_u, d_v)/d_n``, see
:mod:`simcore.shapes.aperture`) is subtracted, taken by Green's theorem in a
Dr.Jit kernel (float64). For albedo the centre of
the diode stands for the whole diode (a slab test per Earth cell), which is
exact to first order for the straight shadow edges of a box.

Over a whole solar disc, :func:`disc_box_shadow` decides in closed form where
the box hides all of a diode or none of it (a diode over its panel's face).

Mounts of other diodes (ramps, wells) are not modelled here: only the
renderer sees them.
"""
import numpy as np

from simcore import _llvm
from simcore.shapes.aperture import lit_rectangle_of



def row_dot(a, b):
    """Return the dot products of ``a`` and ``b`` (broadcast) along their last axis (3), term by term in the order x,
    y, z: each value's rounding is independent of the array's size and of its place in it (numpy's ``einsum`` and
    ``@`` may fuse a multiply and an add or block the work by the array's size), so that the check's reference of a
    diode-epoch does not depend on the chunk it is computed in (a resumed run reads the same numbers)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


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


def _lit_with_box_kernel(table, n_rims, d):
    """Return Dr.Jit Float64 (T,): the lit fraction of T (diode, direction) pairs with the body box's shadow taken
    out (:func:`lit_fractions_with_box`), from one Dr.Jit kernel.
    ``table(c)``: column ``c`` of each pair's diode row (2 + 3 ``n_rims`` aperture parameters, then the frame
    rows u, v, n, the position and the box's half extents, 3 each); ``d`` (3,) the directions' components."""
    dr = _llvm.import_drjit()
    from drjit.llvm import Float64 as F
    n_ap = 2 + 3 * n_rims
    ax, ay = table(0), table(1)
    u, v, n, p, half = ([table(n_ap + 3 * r + i) for i in range(3)] for r in range(5))
    du = d[0] * u[0] + d[1] * u[1] + d[2] * u[2]
    dv = d[0] * v[0] + d[1] * v[1] + d[2] * v[2]
    dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
    front = dn > 0
    inv_n = 1.0 / dr.select(front, dn, 1.0)
    x0, x1, y0, y1 = -ax, ax, -ay, ay
    for r in range(n_rims):                                     # each rim, shifted along the direction
        wx, wy, h = table(2 + 3 * r), table(3 + 3 * r), table(4 + 3 * r)
        sx, sy = -h * du * inv_n, -h * dv * inv_n
        x0, x1 = dr.maximum(x0, sx - wx), dr.minimum(x1, sx + wx)
        y0, y1 = dr.maximum(y0, sy - wy), dr.minimum(y1, sy + wy)
    lit = dr.select(front, dr.maximum(x1 - x0, 0.0) * dr.maximum(y1 - y0, 0.0), 0.0)
    # Constraints alpha X + beta Y + gamma t <= c on (X, Y, t): the box's faces +-e_k (the face the direction runs
    # toward bounds t from above, gamma >= 0; its opposite from below), and t >= 0.
    s = [dr.select(d[k] >= 0, 1.0, -1.0) for k in range(3)]
    upper = [(s[k] * u[k], s[k] * v[k], s[k] * d[k], half[k] - s[k] * p[k]) for k in range(3)]
    lower = [(-s[k] * u[k], -s[k] * v[k], -s[k] * d[k], half[k] + s[k] * p[k]) for k in range(3)]
    lower.append((F(0.0), F(0.0), -dr.select(front, dn, 1.0), F(0.0)))
    # gi <= 0: t >= (ci - ai X - bi Y) / gi;  gj >= 0: t <= (cj - aj X - bj Y) / gj. A face's bound against its
    # opposite face's (i == j) reads 0 X + 0 Y <= 2 half |d_k| exactly (the products cancel): it holds everywhere.
    planes = [(ai * gj - aj * gi, bi * gj - bj * gi, ci * gj - cj * gi)
              for i, (ai, bi, gi, ci) in enumerate(lower) for j, (aj, bj, gj, cj) in enumerate(upper) if i != j]
    # Most lit rectangles lie wholly outside the shadow (a half-plane excludes all four corners) or wholly inside
    # it (every half-plane holds all four); only packets of lanes with others, which a shadow edge crosses, take
    # the area.
    holds_all, excludes_all = lit > 0, lit <= 0
    for a, b, c in planes:     # the largest and smallest of a X + b Y over the rectangle's corners
        ax0, ax1, by0, by1 = a * x0, a * x1, b * y0, b * y1
        holds_all &= dr.maximum(ax0, ax1) + dr.maximum(by0, by1) <= c
        excludes_all |= dr.minimum(ax0, ax1) + dr.minimum(by0, by1) > c
    crossed = dr.if_stmt(args=(x0, x1, y0, y1, *[x for pl in planes for x in pl]), cond=~holds_all & ~excludes_all,
                         true_fn=_bounded_area, false_fn=lambda *_: F(0.0))
    shadow = dr.select(holds_all, lit, crossed)
    return dr.select(front, dr.maximum(lit - shadow, 0.0) / (4 * ax * ay), 0.0)


def _bounded_area(x0, x1, y0, y1, *planes):
    """Return the area of the rectangle [x0, x1] x [y0, y1] cut by the half-planes a X + b Y <= c (``planes``:
    a, b, c of each in turn), a convex polygon, by Green's theorem over its boundary (Dr.Jit arrays).

    The part of line i (a_i X + b_i Y = c_i, the interior on the left of e_i = (-b_i, a_i)) inside every other
    half-plane is p_i + t e_i, p_i = c_i (a_i, b_i) / (a_i^2 + b_i^2), for t in [t0, t1], an interval whose ends
    are a max and a min over the other lines; that edge adds (x dy - y dx) / 2 = (t1 - t0) cross(p_i, e_i) / 2
    = c_i (t1 - t0) / 2 to the area. No vertex list is built, so nothing is compacted."""
    dr = _llvm.import_drjit()
    from drjit.llvm import Float64 as F
    one, zero = F(1.0), F(0.0)
    lines = [(one, zero, x1), (-one, zero, -x0), (zero, one, y1), (zero, -one, -y0)]
    lines += [planes[i:i + 3] for i in range(0, len(planes), 3)]
    norm = [dr.sqrt(a * a + b * b) for a, b, _ in lines]
    # each line's signed distance from the origin (+-inf for a "line" 0 X + 0 Y <= c: everywhere or nowhere)
    offset = [dr.select(r > 0, c / dr.select(r > 0, r, 1.0), dr.select(c >= 0, dr.inf, -dr.inf))
              for (_, _, c), r in zip(lines, norm)]
    area = F(0.0)
    for i, (ai, bi, ci) in enumerate(lines):
        q = ai * ai + bi * bi
        k = ci / dr.select(q > 0, q, 1.0)
        t0, t1 = F(-dr.inf), F(dr.inf)
        empty = q <= 0
        for j, (aj, bj, cj) in enumerate(lines):
            if j == i:
                continue
            g = ai * bj - aj * bi                  # a_j . e_i
            dot = ai * aj + bi * bj
            # Lines within 1e-9 rad of parallel are taken as parallel (moving the area by at most ~1e-9 of the
            # rectangle's): the other half-plane holds all of line i or none of it, decided by comparing the two
            # distances, the same numbers from either side, so a line met twice counts once (the inner one, or
            # the earlier of two equal ones) and a strip's two sides count both or neither. (Cut where they
            # cross instead, two nearly equal lines would split their common edge at two points computed apart.)
            par = dr.abs(g) <= 1e-9 * norm[i] * norm[j]
            bound = (cj - dot * k) / dr.select(par, 1.0, g)    # (c_j - a_j . p_i) / (a_j . e_i)
            t1 = dr.select(~par & (g > 0), dr.minimum(t1, bound), t1)
            t0 = dr.select(~par & (g < 0), dr.maximum(t0, bound), t0)
            keep = dr.select(dot > 0, (offset[j] > offset[i]) | ((offset[j] == offset[i]) & (j > i)),
                             offset[i] + offset[j] >= 0)
            empty |= par & ~keep
        area += dr.select(~empty & (t1 > t0), 0.5 * ci * (t1 - t0), 0.0)
    return area


def _box_pairs(table, diode, d):
    """Return (T,) numpy: :func:`_lit_with_box_kernel` for T pairs, diode ``diode[t]`` (a row of ``table`` (K, C):
    the kernel's columns) toward the direction ``d[t]`` (T, 3)."""
    T = len(d)
    if T == 0:
        return np.zeros(0)
    if T == 1:                       # (a one-lane array would be folded into the kernel as a literal)
        return _box_pairs(table, np.repeat(diode, 2), np.repeat(d, 2, axis=0))[:1]
    dr = _llvm.import_drjit()
    from drjit.llvm import Float64, UInt32
    n_cols = table.shape[1]
    with _llvm.FROZEN_CALLS:        # it may run in a worker thread beside the renderer's frozen kernels
        rows = _llvm.host_array(Float64, table)
        row = _llvm.host_array(UInt32, diode) * n_cols      # the kernel's code depends on neither T nor K
        dirs = _llvm.host_array(Float64, d)
        lane = dr.arange(UInt32, T) * 3
        with_box = _lit_with_box_kernel(lambda c: dr.gather(Float64, rows, row + c), (n_cols - 17) // 3,
                                        [dr.gather(Float64, dirs, lane + i) for i in range(3)])
        dr.eval(with_box)
        out = np.asarray(with_box.numpy(), dtype=float)
        del rows, row, dirs, lane, with_box           # their Dr.Jit variables released under the lock too
    return out


def _table(aperture_params, frames, positions_m, half_m):
    """Return (K, C): the rows :func:`_lit_with_box_kernel` reads for K diodes."""
    ap = np.asarray(aperture_params, float).reshape(len(frames), -1)
    K = len(ap)
    return np.concatenate([ap, np.asarray(frames, float).reshape(K, 9), np.asarray(positions_m, float).reshape(K, 3),
                           np.broadcast_to(np.asarray(half_m, float), (K, 3))], axis=1)


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
    the intersection of the 12 half-planes "every lower bound <= every upper bound" (9 of them: a face's
    bound against its opposite face's holds everywhere). The shadowed part of the well's lit rectangle
    is the convex polygon those and the rectangle's sides bound; its area is taken by Green's theorem
    (:func:`_bounded_area`), in one Dr.Jit kernel (float64) over all T.
    """
    d = np.asarray(d_body, float).reshape(-1, 3)
    table = _table(aperture_params, frames, positions_m, half_m)
    return _box_pairs(table, np.arange(len(d)), d)


def lit_fraction_with_box(aperture, frame, position_m, d_body, half_m):
    """Return the lit fraction (0..1) of one diode for one direction: its well's overlap minus the
    body box's shadow, exact (:func:`lit_fractions_with_box` for one)."""
    params = [aperture.rims]
    return float(lit_fractions_with_box(params, [frame], [position_m], [d_body], half_m)[0])


def _aperture_params(apertures):
    """Return (K, 8): :attr:`simcore.shapes.aperture.WellAperture.rims` of each aperture (m)."""
    return np.array([a.rims for a in apertures])


def _visibility_below(table, diode, d):
    """Return (T,): lit fraction with the box over the well's own lit fraction for T pairs, diode ``diode[t]`` (a
    row of ``table``, :func:`_table`) toward the direction ``d[t]`` (T, 3) below its panel and in front of it; NaN
    where the well itself lets no light through (the box's kernel runs on the others alone)."""
    n_ap = table.shape[1] - 15
    dd = row_dot(table[diode, n_ap:n_ap + 9].reshape(-1, 3, 3), d[:, None]).T   # the directions in the diode frames
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):    # (contiguous rows: faster, the same numbers)
        own = lit_rectangle_of(np.ascontiguousarray(table[diode, :n_ap].T), *np.ascontiguousarray(dd))[4]
    vis = np.full(len(d), np.nan)
    lit = np.flatnonzero(own > 0)
    vis[lit] = _box_pairs(table, diode[lit], d[lit]) / own[lit]
    return vis


def direct_visibility(apertures, frames, positions_m, panel_normals, d_body, half_m, only=None):
    """Return (N, K): lit fraction with the body box over the well's own lit fraction (1 where the box
    blocks nothing, 0 where it hides the whole lit area), for unit Sun directions ``d_body`` (N, 3);
    ``only`` (N, K) bool restricts the work to those pairs (the others read 1). NaN where the body
    could block but the well itself lets no light through (the ratio is undefined there)."""
    d = np.atleast_2d(np.asarray(d_body, float))
    N, K = d.shape[0], len(frames)
    vis = np.ones((N, K))
    below = row_dot(d[:, None], np.asarray(panel_normals, float)[None]) < 0          # only these can meet the body
    front = row_dot(d[:, None], np.asarray(frames)[None, :, 2]) > 0
    todo = below & front if only is None else below & front & only
    if not todo.any():
        return vis
    n_idx, k_idx = np.nonzero(todo)
    vis[n_idx, k_idx] = _visibility_below(_table(_aperture_params(apertures), frames, positions_m, half_m), k_idx,
                                          d[n_idx])
    return vis


def pair_visibility(apertures, frames, positions_m, panel_normals, diode, d_body, half_m):
    """Return (T,): the visibility of :func:`direct_visibility` for T (diode, direction) pairs, diode
    ``diode[t]`` (index into the K ``apertures``, ``frames``, ``positions_m``, ``panel_normals``) toward the
    unit direction ``d_body[t]`` (body frame); 1 where the box cannot block, NaN where the well is dark."""
    d = np.asarray(d_body, float).reshape(-1, 3)
    k = np.asarray(diode, dtype=np.int64).reshape(-1)
    frames = np.asarray(frames, float)
    vis = np.ones(len(d))
    below = row_dot(d, np.asarray(panel_normals, float)[k]) < 0
    front = row_dot(d, frames[k, 2]) > 0
    t = np.flatnonzero(below & front)
    if t.size:
        vis[t] = _visibility_below(_table(_aperture_params(apertures), frames, positions_m, half_m), k[t], d[t])
    return vis


def disc_box_shadow(sun, diode, frames, half_diodes, positions_m, panel_normals, half_m, reach_rad):
    """Return (T,) int8 for T (Sun direction ``sun[t]`` (T, 3), diode ``diode[t]``) pairs: 1 where the body box
    hides the whole diode from every direction within ``reach_rad`` of the Sun's centre, -1 where it hides none of
    it from any, 0 where this cannot tell (the box's kernel decides there).

    ``frames`` (K, 3, 3) rows (u, v, n), ``half_diodes`` (K, 2) the diodes' half sides along u and v,
    ``positions_m`` (K, 3) their centres, ``panel_normals`` (K, 3) their panels' outward normals, ``half_m`` the
    box's half extents. It applies where the panel's normal is a box axis (the face p . Y = half_p), every corner
    of the diode lies above that face and within its sides, and every direction of the disc runs below the face's
    plane: a ray from such a point X toward d then meets the box iff it crosses the face's plane within the face
    (it stays outside the box until it reaches the plane; a side it crossed outward it does not cross back), at
    C = X + h d / (-d . p) (h the height of X above the face): affine in X, so the diode's rays all cross within
    the face iff its four corners' do, and none do where all four cross beyond one side of it. Over the disc
    (|d - s| <= delta = 2 sin(reach / 2)) C moves by at most 2 h delta / ((-s . p - delta)(-s . p)) from the
    centre's; a corner counts as within (beyond) the face only with that margin."""
    s = np.asarray(sun, float).reshape(-1, 3)
    k = np.asarray(diode, dtype=np.int64).reshape(-1)
    out = np.zeros(len(s), np.int8)
    frames = np.asarray(frames, float)
    normals = np.asarray(panel_normals, float)
    half = np.asarray(half_m, float)
    axis = np.argmax(np.abs(normals), axis=1)
    sign = np.sign(normals[np.arange(len(normals)), axis])
    hd = np.asarray(half_diodes, float)
    corners = (np.asarray(positions_m, float)[:, None]
               + np.array([-1, 1, -1, 1])[None, :, None] * hd[:, None, :1] * frames[:, None, 0]
               + np.array([-1, -1, 1, 1])[None, :, None] * hd[:, None, 1:] * frames[:, None, 1])   # (K, 4, 3)
    height = sign[:, None] * corners[np.arange(len(axis)), :, axis] - half[axis][:, None]            # (K, 4)
    lateral = np.ones((len(axis), 3), bool)
    lateral[np.arange(len(axis)), axis] = False
    within = np.all(np.where(lateral[:, None], np.abs(corners) <= half, True), axis=(1, 2))
    ok = (np.abs(np.abs(normals[np.arange(len(axis)), axis]) - 1.0) < 1e-12) & (height > 0).all(axis=1) & within
    delta = 2.0 * np.sin(0.5 * reach_rad)
    sp = -row_dot(s, normals[k])               # -s . p
    t = np.flatnonzero(ok[k] & (sp > 2.0 * delta))
    if t.size == 0:
        return out
    kt, st, spt = k[t], s[t], sp[t]
    h = height[kt]                                                          # (T, 4)
    cross = corners[kt] + (h / spt[:, None])[..., None] * st[:, None]       # (T, 4, 3)
    margin = (2.0 * h * delta / ((spt - delta) * spt)[:, None])[..., None] + 1e-9
    lat = lateral[kt][:, None]                                              # (T, 1, 3)
    inside = np.all(np.where(lat, np.abs(cross) + margin < half, True), axis=(1, 2))
    beyond = np.any(np.all(np.where(lat, cross - margin > half, False), axis=1)
                    | np.all(np.where(lat, -cross - margin > half, False), axis=1), axis=1)
    out[t] = np.where(inside, 1, np.where(beyond, -1, 0))
    return out
