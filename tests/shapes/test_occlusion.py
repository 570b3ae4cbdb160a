"""Body-box occlusion in closed form, against brute-force counting over points of the diode."""
import numpy as np
import pytest

from scenes.config import SatelliteConfig, panel_axes
from simcore.radiometry.analytic_direct import solar_disc_offsets
from simcore.shapes.occlusion import box_hit, direct_visibility, lit_fraction_with_box


def _segment_hits_box(o, d, half):
    # Independent oracle: march the ray in small steps and test containment (no slab algebra).
    t = np.linspace(0.0, 1.0, 4001)[:, None]   # 1 m of ray, 0.25 mm steps
    p = o[None, :] + t * d[None, :]
    return bool(np.any(np.all(np.abs(p) <= half, axis=1)))


# ---- an independent exact construction (hull of the projected box, then rectangle clipping), as it
# stood in simcore.shapes.occlusion before the half-plane formulation replaced it
_EDGES = [(a, a | bit) for bit in (1, 2, 4) for a in range(8) if not a & bit]
_CORNER_SIGNS = [(1 if i & 1 else -1, 1 if i & 2 else -1, 1 if i & 4 else -1) for i in range(8)]



def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _hull(points):
    """Return the convex hull (counter-clockwise) of 2-D points, a list of (x, y), by scipy's Qhull."""
    from scipy.spatial import ConvexHull, QhullError
    pts = np.unique(np.round(np.array(points, float), 15), axis=0)
    if len(pts) < 3:
        return [tuple(p) for p in pts]
    try:
        hull = ConvexHull(pts)
    except QhullError:          # all points on one line: no area
        return []
    return [tuple(pts[i]) for i in hull.vertices]


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
    return _hull(out)


def _hull_clip_lit(aperture, frame, position_m, d_body, half_m):
    """Return the lit fraction by the other exact construction: the shadow as the convex hull of the
    projected corners and plane crossings of the box, clipped to the lit rectangle (scalar floats)."""
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


def test_box_hit_agrees_with_marching(rng):
    half = np.array([0.05, 0.05, 0.1135])
    for _ in range(300):
        o = rng.uniform(-0.2, 0.2, 3)
        if np.all(np.abs(o) <= half):
            continue
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        assert box_hit(o, d, half) == _segment_hits_box(o, d, half)


def _brute_lit(ap, frame, pos, d, half, n=300):
    u, v, nrm = frame
    g = (np.arange(n) + 0.5) / n - 0.5
    x, y = np.meshgrid(g * ap.diode_x_m, g * ap.diode_y_m, indexing="ij")
    dn = d @ nrm
    sx, sy = -ap.height_m * (d @ u) / dn, -ap.height_m * (d @ v) / dn
    in_open = (np.abs(x - sx) <= ap.opening_x_m / 2) & (np.abs(y - sy) <= ap.opening_y_m / 2)
    pts = pos + x.reshape(-1, 1) * u + y.reshape(-1, 1) * v
    blocked = box_hit(pts, np.broadcast_to(d, pts.shape), half).reshape(x.shape)
    return float((in_open & ~blocked).mean())


def test_exact_shadow_area_matches_point_count(rng):
    # tilt20_fov70: diodes on the side panels look past their panel's edge into the body.
    cfg = SatelliteConfig.load("tilt20_fov70")
    half = np.asarray(cfg.body.size_m) / 2
    checked = 0
    for k in range(12):
        dio = cfg.diodes[k]
        p = panel_axes(dio.panel)[0]
        for _ in range(400):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            if d @ dio.normal_body <= 0.13 or d @ p >= 0:
                continue
            exact = lit_fraction_with_box(dio.aperture, dio.frame_body, dio.position_body_m, d, half)
            brute = _brute_lit(dio.aperture, dio.frame_body, dio.position_body_m, d, half)
            assert exact == pytest.approx(brute, abs=4.0 / 300)   # one grid row of the 300 x 300 count
            checked += 1
    assert checked > 100


def test_directions_above_the_panel_are_never_blocked():
    cfg = SatelliteConfig.load("tilt25_fov75")
    d = np.array([[1.0, 0.2, 0.1]]) / np.linalg.norm([1.0, 0.2, 0.1])
    normals = np.array([panel_axes(x.panel)[0] for x in cfg.diodes])
    vis = direct_visibility(cfg.apertures, cfg.frames, cfg.positions_m, normals, d, np.asarray(cfg.body.size_m) / 2)
    assert np.all(vis[0, normals @ d[0] > 0] == 1.0)


def test_solar_disc_points_are_centred_and_inside_the_disc():
    r = np.radians(0.2666)
    off = solar_disc_offsets(r)
    assert off.shape == (37, 2)
    np.testing.assert_allclose(off.mean(axis=0), 0.0, atol=1e-15)
    assert np.all(np.hypot(off[:, 0], off[:, 1]) < r)
    # Equal-area cells: the mean squared radius of a uniform disc is r^2/2 (within the ring quadrature).
    assert np.mean(np.sum(off ** 2, axis=1)) == pytest.approx(r ** 2 / 2, rel=0.03)


def test_half_plane_shadow_equals_the_hull_construction(rng):
    # Oracle: the hull-and-clip construction above (another algorithm, same exact geometry), to 1e-12
    # of the diode area, over random wells, tilts, positions around the box and directions: every
    # shape of shadow (none, partial, whole, box straddling the diode plane, grazing directions).
    from simcore.shapes.aperture import WellAperture, diode_frame
    half = np.array([0.05, 0.05, 0.1135])
    n_cases = 0
    for _ in range(3000):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        frame = diode_frame(normal)
        face = rng.integers(3)
        pos = rng.uniform(-1.3, 1.3, 3) * half
        pos[face] = np.sign(rng.normal()) * half[face] * rng.uniform(1.0, 1.5)
        a = rng.uniform(1e-3, 4e-3)
        ap = WellAperture(a, a, a * rng.uniform(1, 3), a * rng.uniform(1, 3), rng.uniform(0, 3e-3))
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        if d @ normal <= 1e-3:
            continue
        ours = lit_fraction_with_box(ap, frame, pos, d, half)
        theirs = _hull_clip_lit(ap, [list(r) for r in frame], list(pos), list(d), half)
        assert ours == pytest.approx(theirs, abs=1e-12)
        n_cases += 1
    assert n_cases > 1000


def test_half_plane_shadow_fails_on_a_wrong_box():
    # The comparison above can fail: a box 1 % larger casts a measurably larger shadow. The
    # directions: the first of a fixed grid where the true box shadows part of the lit well.
    cfg = SatelliteConfig.load("tilt20_fov70")
    half = np.asarray(cfg.body.size_m) / 2
    found = 0
    for dio in cfg.diodes[:12]:
        frame = [list(r) for r in dio.frame_body]
        for th in np.radians(np.arange(40.0, 84.0, 2.0)):
            for ph in np.radians(np.arange(0.0, 360.0, 15.0)):
                d = np.cos(th) * dio.frame_body[2] + np.sin(th) * (np.cos(ph) * dio.frame_body[0]
                                                                   + np.sin(ph) * dio.frame_body[1])
                right = _hull_clip_lit(dio.aperture, frame, list(dio.position_body_m), list(d), half)
                own = float(dio.aperture.lit_fraction(dio.frame_body @ d))
                if 0.05 < right < own - 0.05:
                    wrong = lit_fraction_with_box(dio.aperture, dio.frame_body, dio.position_body_m, d, half * 1.01)
                    assert abs(wrong - right) > 1e-4
                    found += 1
    assert found > 10


def test_shadow_edges_on_the_wells_edges():
    # Shadow edges that fall exactly on (or within rounding of) an edge of the lit rectangle, or on each other:
    # a diode whose side lies in the plane of a box face, Sun directions with zero components (the box's faces
    # then project to lines parallel to the rectangle's sides, several of the shadow's half-planes coincide).
    # Dyadic sizes make the coincidences exact. Oracle: the hull-and-clip construction above, to 1e-12.
    from simcore.shapes.aperture import WellAperture
    a = 2.0 ** -10
    half = np.array([0.0625, 0.0625, 0.125])
    ap = WellAperture(2 * a, 2 * a, 2 * a, 2 * a, 0.0)
    frame = np.eye(3)                                   # u = x, v = y, n = z
    n_partial = 0
    for py in (0.0625 - a, 0.0625, 0.0625 + a, 0.0625 - 2 * a, 0.0):
        for px in (0.0625 + a, 0.0625 + 2 * a, 0.07):
            pos = np.array([px, py, 0.0])
            for d in ([-0.6, 0.0, 0.8], [-0.6, -0.0, 0.8], [-0.8, 0.0, 0.6], [-0.48, -0.36, 0.8],
                      [-0.48, 0.36, 0.8], [0.0, -0.6, 0.8], [-1.0, 0.0, 2.0 ** -20], [-0.6, 1e-17, 0.8]):
                d = np.array(d) / np.linalg.norm(d)
                ours = lit_fraction_with_box(ap, frame, pos, d, half)
                theirs = _hull_clip_lit(ap, [list(r) for r in frame], list(pos), list(d), half)
                assert ours == pytest.approx(theirs, abs=1e-12), (px, py, d)
                n_partial += 0.0 < theirs < 1.0
    assert n_partial >= 10
