"""The analytic direct Sun on each diode: the aperture response times the body box's visibility, averaged over
the solar disc (and the part of it the Earth leaves visible), on (epoch, diode) pairs.

The quadratures and where each applies (13 points where the response is smooth over the disc; 37 equal-area
points; 397 where a kink crosses the disc; a Gauss-Legendre x azimuth product rule where the box's shadow edge
reaches only the disc's rim) are described at
:func:`_direct_response`; :func:`simcore.radiometry.analytic.diode_irradiance` is the entry point.
"""
import numpy as np

from simcore.radiometry import response as _resp
from simcore.shapes.occlusion import disc_box_shadow, pair_visibility, row_dot


def solar_disc_offsets(radius_rad, rings=3):
    """Return (M, 2) tangent-plane offsets (rad) and (M,) equal weights covering the solar disc in
    equal-area cells: the centre and rings of 6, 12, 18 ... points (1 + 3 r (r + 1) in all)."""
    total = 1 + 3 * rings * (rings + 1)
    edge2 = [(1 + 3 * i * (i + 1)) / total for i in range(rings + 1)]   # squared ring boundaries / r^2
    pts = [(0.0, 0.0)]
    for i in range(1, rings + 1):
        rad = radius_rad * np.sqrt(0.5 * (edge2[i - 1] + edge2[i]))     # the middle of the annulus by area
        m = 6 * i
        ang = 2 * np.pi * (np.arange(m) + 0.5 * (i % 2)) / m
        pts += list(zip(rad * np.cos(ang), rad * np.sin(ang)))
    return np.array(pts)


def disc_directions(sun_body, offsets):
    """Return (M, N, 3) unit directions across the solar disc around each Sun direction (N, 3)."""
    s = sun_body
    helper = np.where(np.abs(s[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(s, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(s, e1)
    d = s[None] + offsets[:, :1, None] * e1[None] + offsets[:, 1:, None] * e2[None]
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def _disc_sum(w, x):
    """Return (T,): sum over m of ``w[m] * x[m]`` ((M, T) each, or ``w`` (M,)), added point by point in order: each
    pair's rounding is independent of how many pairs there are (numpy's ``einsum`` fuses some products into its sums
    by their place in a SIMD packet, and a reduction of one column sums pairwise), so that a diode-epoch's reference
    does not depend on its chunk (a resumed run reads the same numbers)."""
    w = np.asarray(w)
    w = w[:, None] if w.ndim == 1 else w
    acc = w[0] * x[0]
    for m in range(1, len(x)):
        acc = acc + w[m] * x[m]
    return acc


def smooth_disc_rule(radius_rad, rings=3):
    """Return (13, 2) tangent-plane offsets (rad) and (13,) weights (sum 1): the centre and two rings of six points
    (at 0 and 30 deg) with the same moments up to degree 7 as the ``rings`` equal-area rings of
    :func:`solar_disc_offsets`: their means of r^2, r^4, r^6 and r^6 cos(6 phi) (the other moments up to degree 7
    vanish for both by their six-fold symmetry). On a response smooth over the disc it gives the rings' average to
    O(a^8) of its eighth derivatives (a the radius; docs/validation.md)."""
    off = solar_disc_offsets(radius_rad, rings)
    r2 = np.sum(off ** 2, axis=1)
    m2, m4 = float(np.mean(r2)), float(np.mean(r2 ** 2))
    c6 = float(np.mean(r2 ** 3 * np.cos(6.0 * np.arctan2(off[:, 1], off[:, 0]))))
    p, q = 0.5 * (float(np.mean(r2 ** 3)) + c6), 0.5 * (float(np.mean(r2 ** 3)) - c6)   # W x^3, W' y^3
    # with X = 1 / x, Y = 1 / y (x, y the rings' r^2): p X^2 + q Y^2 = m2 and p X + q Y = m4, Y = (m4 - p X) / q
    roots = np.roots([p + p * p / q, -2.0 * p * m4 / q, m4 * m4 / q - m2]).real
    X = roots.max()
    Y = (m4 - p * X) / q
    x, y = 1.0 / X, 1.0 / Y
    wa, wb = p * X ** 3 / 6.0, q * Y ** 3 / 6.0
    ang = np.pi / 3.0 * np.arange(6)
    off = np.vstack([[0.0, 0.0], np.sqrt(x) * np.column_stack([np.cos(ang), np.sin(ang)]),
                     np.sqrt(y) * np.column_stack([np.cos(ang + np.pi / 6), np.sin(ang + np.pi / 6)])])
    return off, np.r_[1.0 - 6.0 * (wa + wb), np.full(6, wa), np.full(6, wb)]


def _kink_planes(frames, resps):
    """Return (K, P, 3): per diode, body-frame normals c of the planes c . d = 0 along which a
    :class:`simcore.shapes.aperture.WellAperture`'s response has a kink: its horizon (n) and, along each wall
    axis, every value of d_u / d_n (d_v / d_n) at which two of the lit rectangle's bounds
    (:func:`simcore.shapes.aperture.lit_rectangle`: the diode's side and each rim's shifted side, linear in it)
    meet, whichever of them binds there. Between them the response is a rational function of d, smooth. Rows of
    other responses are NaN (no smooth rule for them); short rows repeat their last plane."""
    rows = []
    for f, r in zip(np.asarray(frames, float), resps):
        if type(r) is not _resp.WellAperture:
            rows.append(np.full((1, 3), np.nan))
            continue
        hdx, hdy, ox1, oy1, h1, ox2, oy2, h2 = r.rims
        planes = [f[2]]
        for axis, (hd, o1, o2) in ((f[0], (hdx, ox1, ox2)), (f[1], (hdy, oy1, oy2))):
            lower = [(-hd, 0.0), (-o1, -h1), (-o2, -h2)]             # a + b t, t = d_u / d_n (d_v / d_n)
            upper = [(hd, 0.0), (o1, -h1), (o2, -h2)]
            pairs = [(p, q) for i, p in enumerate(lower) for q in lower[i + 1:]]
            pairs += [(p, q) for i, p in enumerate(upper) for q in upper[i + 1:]]
            pairs += [(p, q) for p in lower for q in upper]
            ties = {(a2 - a1) / (b1 - b2) for (a1, b1), (a2, b2) in pairs if b1 != b2}
            planes += [axis - t * f[2] for t in sorted(ties)]
        planes = np.array(planes)
        rows.append(planes / np.linalg.norm(planes, axis=1, keepdims=True))
    out = np.empty((len(rows), max(len(r) for r in rows), 3))
    for k, r in enumerate(rows):
        out[k] = r[-1]
        out[k, :len(r)] = r
    return out


# The smooth rule's difference from the 37 points grows as (a / d_n)^8 toward the diode's horizon (its derivatives
# as 1 / d_n^k): it is used from d_n >= 0.25 on, where that is < 1e-13 of the response (docs/validation.md).
_SMOOTH_MIN_COS = 0.25


def _smooth_pairs(sun, diode, planes, radius_rad, min_cos=_SMOOTH_MIN_COS):
    """Return (T,) bool: the pairs (Sun direction ``sun[t]`` (T, 3), diode ``diode[t]``) whose disc (every
    direction within ``radius_rad`` of the Sun's centre) lies wholly in front of the diode and crosses none of
    its kink planes (``planes`` (K, P, 3), unit normals, :func:`_kink_planes`): a plane c . d = 0 meets the
    disc iff |s . c| <= sin(radius); and whose centre has d_n > ``min_cos`` (-inf: any; ``planes`` then need not
    start with the horizon's)."""
    sc = row_dot(planes[diode], sun[:, None])
    with np.errstate(invalid="ignore"):
        clear = (np.abs(sc) > np.sin(radius_rad) * (1.0 + 1e-9) + 1e-12).all(axis=1)
    return clear if min_cos == -np.inf else clear & (sc[:, 0] > min_cos)


# Responses known to read exactly 0 for every direction with d_n <= 0 (behind the diode's plane): for these the
# direct Sun is evaluated only where part of the solar disc lies in front of the diode.
_DARK_BEHIND = (_resp.CosineResponse, _resp.ReflectionResponse, _resp.Eq415Response, _resp.WellAperture,
                _resp.CircularWell)
_WELLS = (_resp.WellAperture, _resp.CircularWell)


def _disc_sample(sun_body, sun_angular_radius_rad, rings, earth_body_m=None, radius_m=None):
    """Return (dirs (M, N, 3), weights (M, N), partial_earth (N,)): the solar-disc quadrature points around
    each Sun direction, their weights (over the part the Earth leaves visible, normalised, divided by the
    points' mean cos(alpha)) and whether the Earth's limb crosses the disc's points."""
    offsets = solar_disc_offsets(sun_angular_radius_rad, rings) if sun_angular_radius_rad > 0 else np.zeros((1, 2))
    dirs = disc_directions(sun_body, offsets)
    weights = np.ones(dirs.shape[:2])                                      # (M, N)
    if earth_body_m is not None and len(dirs) > 1:
        along = row_dot(dirs, earth_body_m[None])
        miss2 = row_dot(earth_body_m, earth_body_m)[None] - along ** 2
        weights = ~((along > 0) & (miss2 < radius_m ** 2))
        weights = np.where(weights.any(axis=0), weights, True).astype(float)   # umbra by points: plain mean
    partial_earth = (weights != weights[:1]).any(axis=0) if len(dirs) > 1 else np.zeros(weights.shape[1], bool)
    # E_sun is the irradiance normal to the Sun's centre, int L cos(alpha) dOmega over the disc: the
    # responses' plain mean over the disc points carries their mean cos(alpha) ~ 1 - a^2/4, divided out.
    mean_cos_alpha = float(np.mean(1.0 / np.sqrt(1.0 + np.sum(offsets ** 2, axis=1))))
    return dirs, weights / weights.sum(axis=0) / mean_cos_alpha, partial_earth


def _pair_response(resps, frames, diode, d):
    """Return (lit, response), (M, T) each: the response of diode ``diode[t]`` toward the body-frame
    directions ``d[:, t]`` (M, T, 3), and the lit fraction of its well (NaN for diodes without a well of
    some height: their response has no full-light edge)."""
    lit = np.full(d.shape[:2], np.nan)
    resp = np.empty(d.shape[:2])
    for k in np.unique(diode):
        t = np.flatnonzero(diode == k)
        dk = row_dot(d[:, t, None], frames[k])                  # (M, t, 3): the directions in the diode's frame
        r = resps[k]
        if isinstance(r, _WELLS):
            lit_k = r.lit_fraction(dk)
            resp[:, t] = lit_k * np.clip(dk[..., 2], 0.0, None)          # = WellAperture.response, sharing lit
            if r.height_m > 0:
                lit[:, t] = lit_k
        else:
            resp[:, t] = r.response(dk)
    return lit, resp


def _disc_mean(dirs, weights, resp, diode, frames, resps, body, rings, rim=None, below=None, replaced=None):
    """Return ((T,), (T,) bool): the weighted mean over the disc points of each (epoch, diode) pair, ``dirs``
    (M, T, 3), ``weights`` and ``resp`` (M, T), diode ``diode[t]``, times the body box's visibility; and
    whether the box's shadow edge reaches only the disc's ``rim`` (directions (R, T, 3), if given): the
    centre and six points of the outermost ring agree, the rim's points do not (a sliver none of the M
    points can see); (T,) the box's visibility where all those probes agree on it (NaN elsewhere); and
    whether they saw the edge cross the disc's interior. ``below`` (T,) bool, if given: the pairs with some
    of ``dirs`` or ``rim`` possibly below the diode's panel plane; the others' directions all read 1 (what
    :func:`pair_visibility` gives above the plane), without asking it. ``replaced`` (T,) bool, if given: the pairs
    whose mean the caller replaces wherever the probes see the box's edge cross the disc (their mean there is
    then the probes' visibility times the response, not traced point by point)."""
    m, n = resp.shape
    if body is None:
        return _disc_sum(weights, resp), np.zeros(n, bool), np.ones(n), np.zeros(n, bool)

    def vis(k, d):
        return pair_visibility(resps, frames, body.positions_m, body.panel_normals, k, d, body.half_m)

    def vis_pairs(cols, d):
        # (P, T) visibility of the directions d (P, T, 3) of pairs ``cols``: 1 for the pairs above the panel
        v = np.ones(d.shape[:2])
        if below is not None:
            cols = cols[below[cols]]
        if cols.size:
            v[:, cols] = vis(np.tile(diode[cols], len(d)), d[:, cols].reshape(-1, 3)).reshape(len(d), len(cols))
        return v

    def crossing(v_probe):
        undefined = np.isnan(v_probe).any(axis=0)
        lo = np.where(np.isnan(v_probe), np.inf, v_probe).min(axis=0)
        hi = np.where(np.isnan(v_probe), -np.inf, v_probe).max(axis=0)
        seen = np.isfinite(lo)
        return seen, lo, hi, (seen & (hi > lo)) | (seen & (lo > 0) & (lo < 1)) | undefined
    # The box's shadow edge crosses the solar disc only for a few diode-epochs: find them from the
    # centre and six points spread around the outermost ring (6 r points), and average over the whole
    # disc there alone. Where the well lets no light through, visibility is undefined (NaN).
    n_ring = 6 * rings
    probe = [0] + list(range(m - n_ring, m, max(rings, 1))) if m > 1 else [0]
    # Without rim probes (the 397 points, where nearly every pair the box may shade has its edge across the disc)
    # every point is traced at once, the probes among them: one kernel call, the same numbers.
    v_full = vis_pairs(np.arange(n), dirs) if rim is None and m > 1 else None
    v_probe = v_full[probe] if v_full is not None else vis_pairs(np.arange(n), dirs[probe] if rim is None else
                                                                 np.concatenate([dirs[probe], rim]))
    seen, lo, hi, cross = crossing(v_probe[:len(probe)])
    edge = (resp > 0).any(axis=0) & cross
    rim_only = np.zeros(n, bool)
    if rim is not None:
        # (probes where the well itself is dark say nothing of the box)
        s_all, lo_all, hi_all, _ = crossing(v_probe)
        rim_only = ~edge & (hi_all > 0) & s_all & ((hi_all > lo_all) | ((lo_all > 0) & (lo_all < 1)))
    v_all = np.broadcast_to(np.where(seen, lo, 1.0), resp.shape).copy()
    traced = edge if replaced is None else edge & ~replaced
    if traced.any() and m > 1:
        cols = np.flatnonzero(traced)                      # every disc point of the edge pairs, in one batch
        v_all[:, cols] = (vis_pairs(cols, dirs) if v_full is None else v_full)[:, cols]
    mean = _disc_sum(weights, resp * np.nan_to_num(v_all, nan=1.0))
    # where every probe agrees, the box's visibility over the whole disc (1 where undefined)
    steady = np.where(~(edge | rim_only) & seen, lo, np.nan) if rim is not None else np.full(n, np.nan)
    return mean, rim_only & (m > 1), steady, edge & (m > 1)


def _below_panel(sun_body, ep, diode, body, radius_rad):
    """Return (T,) bool, or None without a body: the (epoch ``ep[t]``, diode ``diode[t]``) pairs with some
    direction within ``radius_rad`` of the Sun's centre at or below the plane of the diode's panel, where the
    body box may shade it. A direction (s + o) / |s + o| (o across s, |o| <= the radius) has d . p >= (s . p -
    |o| |p|) / |s + o| > 0 for the others: :func:`pair_visibility` reads exactly 1 along it."""
    if body is None:
        return None
    p = np.asarray(body.panel_normals, float)[diode]
    return row_dot(sun_body[ep], p) <= (radius_rad + 1e-9) * np.linalg.norm(p, axis=1)


# The body box's shadow edge across only the solar disc's rim, or the diode's horizon across the disc:
# Gauss-Legendre in the disc's area coordinate (r/a)^2 x equally spaced azimuths. A shadow that leaves a
# sliver of the rim lit (depth 1 % of the radius, 0.1 % of the disc) falls between the equal-area rings'
# points (the outermost of 11 rings sits at 0.98 of the radius); the outermost of 16 Gauss nodes sits at
# 0.9973, and 64 azimuths resolve a sliver 16 deg wide. (Edges across the disc's interior take the 397
# points of the kinks: the box's polygons make 1024 points cost ~9 ms a pair.)
_EDGE_RADIAL, _EDGE_AZIMUTHS = 16, 64


def _polar_disc_offsets(radius_rad, n_r=_EDGE_RADIAL, n_phi=_EDGE_AZIMUTHS):
    """Return (M, 2) tangent-plane offsets (rad) and (M,) weights (sum 1) of a product quadrature over a
    uniform disc: Gauss-Legendre in (r / radius)^2 (the area coordinate) times ``n_phi`` azimuths."""
    x, w = np.polynomial.legendre.leggauss(n_r)
    r = radius_rad * np.sqrt(0.5 * (x + 1.0))
    ph = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    off = np.stack([np.outer(r, np.cos(ph)).ravel(), np.outer(r, np.sin(ph)).ravel()], axis=1)
    return off, np.repeat(0.5 * w, n_phi) / n_phi


def _edge_mean(sun_body, radius_rad, diode, frames, resps, body, steady=None):
    """Return (T,): the disc mean of the response times the body box's visibility (if ``body``) for
    (sun_body[t], diode[t]) pairs by the product quadrature of :func:`_polar_disc_offsets` (a disc the Earth
    does not cut); ``steady`` (T,): the visibility where it is known not to vary over the disc (NaN: trace
    it at every point)."""
    off, w = _polar_disc_offsets(radius_rad)
    d = disc_directions(sun_body, off)                                       # (M, T, 3)
    cos_alpha = 1.0 / np.sqrt(1.0 + np.sum(off ** 2, axis=1))
    wt = np.broadcast_to((w / w.sum() / float(np.sum(w * cos_alpha)))[:, None], d.shape[:2])
    resp = _pair_response(resps, frames, diode, d)[1]
    out = _disc_sum(wt, resp)
    if body is None:
        return out
    # the box's visibility point by point only where the probes did not agree on one value
    steady = np.full(len(diode), np.nan) if steady is None else np.asarray(steady, float)
    out = out * np.where(np.isnan(steady), 1.0, steady)
    t = np.flatnonzero(np.isnan(steady))
    if t.size:
        # The box's edge reaches only the rim (the centre and the outer ring's probes agree): the points
        # inside 0.85 of the radius take the centre's visibility, the outer ones are traced one by one.
        outer = np.flatnonzero(np.hypot(off[:, 0], off[:, 1]) >= 0.85 * radius_rad)
        inner = np.setdiff1d(np.arange(len(d)), outer)
        v = np.empty((len(d), t.size))
        probe = np.concatenate([d[0, t] * 0 + sun_body[t], d[outer][:, t].reshape(-1, 3)])     # one kernel call
        vp = pair_visibility(resps, frames, body.positions_m, body.panel_normals, np.tile(diode[t], len(outer) + 1),
                             probe, body.half_m)
        v[inner] = vp[:t.size][None]
        v[outer] = vp[t.size:].reshape(len(outer), t.size)
        out[t] = _disc_sum(wt[:, t], resp[:, t] * np.nan_to_num(v, nan=1.0))
    return out


def _direct_response(sun_body, frames, resps, body, sun_angular_radius_rad, earth_body_m=None, radius_m=None,
                     rings=3, refine_rings=11):
    """Return the direct-Sun response (N, K): the aperture response, times the body box's visibility,
    averaged over the solar disc when it has a radius (its shadow edges are then soft, as traced).

    With ``earth_body_m`` (N, 3), the Earth's centre seen from the satellite in body axes, the
    average runs over the part of the disc the Earth leaves visible (penumbra: the Earth's limb and an
    aperture edge can cut the same disc); the caller multiplies by the exact visible fraction.

    The disc is sampled by ``rings`` equal-area rings (37 points); where the response has a kink
    inside the disc (the diode's horizon or the well's cut-off or full-light edge crosses it) the
    average is taken again with ``refine_rings`` (397 points); where the body box's shadow edge reaches
    only the disc's rim (32 probes there disagree, the centre and outer ring agree) or the diode's horizon
    crosses it, and the Earth does not, with the product quadrature of :func:`_polar_disc_offsets` (1024
    points reaching 0.997 of the radius).

    The work runs on (epoch, diode) pairs: only those with part of the disc in front of the diode
    (the others read exactly 0 for the responses of :mod:`simcore.radiometry.response` and wells), and
    the 397-point average only on the pairs with a kink. Before all that, pairs the body box hides whole over the
    whole disc read 0 (:func:`simcore.shapes.occlusion.disc_box_shadow`), and pairs whose well response is smooth
    over it (:func:`_smooth_pairs`), with no box shadow and no Earth limb across it, take the 13 points of
    :func:`smooth_disc_rule` (d_n >= :data:`_SMOOTH_MIN_COS`) or the 37 points alone.
    """
    # (a round well's box visibility is that of the square inscribed in its rim, CircularWell.rims: exact where
    # the box cannot shade the diode, the Sun above its panel's plane; elsewhere the check leaves it out,
    # simcore.pipeline.reference.CheckReference.round_well_shadow)
    if body is not None and not all(isinstance(r, _WELLS) for r in resps):
        raise TypeError("body occlusion of the direct Sun needs the diodes' WellAperture or CircularWell responses")
    n_ep, K = sun_body.shape[0], len(frames)
    out = np.zeros((n_ep, K))
    # Every disc point d has d . n <= (s . n + a) / |s + offset| for the disc's angular radius a.
    in_front = row_dot(sun_body[:, None], frames[None, :, 2]) > -(sun_angular_radius_rad + 1e-6)
    in_front |= np.array([not isinstance(r, _DARK_BEHIND) for r in resps])[None]
    diode, ep = np.nonzero(in_front.T)
    if ep.size == 0:
        return out
    a = sun_angular_radius_rad
    cut = np.zeros(n_ep, bool)
    if earth_body_m is not None:
        # where the Earth's limb cuts the disc too, the rules of the kinks below (unchanged) weigh the points
        dist = np.linalg.norm(earth_body_m, axis=1)
        sep = np.arccos(np.clip(row_dot(sun_body, earth_body_m) / dist, -1.0, 1.0))
        limb = np.arcsin(np.minimum(radius_m / dist, 1.0))
        cut = np.abs(sep - limb) < a
    below = _below_panel(sun_body, ep, diode, body, a)
    if a > 0 and rings >= 2:                # (one ring has no 13-point rule of its moments)
        off, w = smooth_disc_rule(a, rings)
        reach = max(a, float(np.max(np.hypot(off[:, 0], off[:, 1]))))   # (its outer ring: 1.007 a)
        planes = _kink_planes(frames, resps)
        # A well that lets no light through at one point of the disc in front of the diode (its centre, or where
        # the horizon crosses the disc, a point 0.999 a toward the normal), with none of its kink planes but the
        # horizon across the disc, lets none through at any point of the disc in front of it: 0, box or not.
        dark = _smooth_pairs(sun_body[ep], diode, planes[:, 1:], reach, -np.inf) & np.isfinite(planes[diode, 0, 0])
        if dark.any():
            s, n = sun_body[ep[dark]], frames[diode[dark], 2]
            sn = row_dot(s, n)
            perp = n - sn[:, None] * s
            norm = np.linalg.norm(perp, axis=1)
            b = 0.999 * a
            at = np.where((sn > 0)[:, None], s, np.cos(b) * s + np.sin(b) * perp / np.maximum(norm, 1e-300)[:, None])
            dark[dark] = (row_dot(at, n) > 0) & (_pair_response(resps, frames, diode[dark], at[None])[1][0] == 0)
            ep, diode, below = ep[~dark], diode[~dark], None if below is None else below[~dark]
        boxed = np.zeros(ep.size, bool)
        if body is not None:
            # Where the box hides the whole diode from the whole disc the response is 0 (rectangular wells); where it
            # hides none of it, the smooth rule below may take the pair (the others keep the box's probes: their
            # visibility's rounding, 1 +- 1e-12, may send a kink across the disc to the 397 points).
            half_diodes = np.array([[r.diode_x_m / 2, r.diode_y_m / 2] for r in resps])
            shade = disc_box_shadow(sun_body[ep], diode, frames, half_diodes, body.positions_m, body.panel_normals,
                                    body.half_m, reach)
            # (round wells keep the model's inscribed square, CircularWell.rims: the check leaves them out there)
            shade[~np.isfinite(planes[diode, 0, 0])] = 0
            keep = shade != 1
            ep, diode, below, shade = ep[keep], diode[keep], below[keep], shade[keep]
            boxed = _below_panel(sun_body, ep, diode, body, reach) & (shade != -1)
        # A disc the Earth leaves whole, where the box cannot shade the diode and over which the well's response is
        # smooth: the 13-point rule of the 37 points' moments (:func:`smooth_disc_rule`).
        smooth = _smooth_pairs(sun_body[ep], diode, planes, reach, 0.0) & ~boxed
        if earth_body_m is not None:
            smooth &= (sep > limb + reach * (1.0 + 1e-9) + 1e-12)[ep]     # no point of the rules behind the Earth
        fast = smooth & (row_dot(sun_body[ep], planes[diode, 0]) > _SMOOTH_MIN_COS)   # (planes[:, 0]: the horizon's)
        if fast.any():
            f_ep, f_k = ep[fast], diode[fast]
            resp7 = _pair_response(resps, frames, f_k, disc_directions(sun_body[f_ep], off))[1]
            out[f_ep, f_k] = _disc_sum(w, resp7) / float(w @ (1.0 / np.sqrt(1.0 + np.sum(off ** 2, axis=1))))
        plain = smooth & ~fast
        if plain.any():
            # smooth, but nearer the horizon: the 37 points alone (what the steps below give them: no kink to find)
            p_ep, p_k = ep[plain], diode[plain]
            rows, at = np.unique(p_ep, return_inverse=True)
            dirs, weights, _ = _disc_sample(sun_body[rows], a, rings)
            d = dirs[:, at]
            out[p_ep, p_k] = _disc_sum(weights[:, at], _pair_response(resps, frames, p_k, d)[1])
        ep, diode = ep[~smooth], diode[~smooth]
        below = None if below is None else below[~smooth]
        if ep.size == 0:
            return out
    rows, at = np.unique(ep, return_inverse=True)
    dirs, weights, pe = _disc_sample(sun_body[rows], a, rings, None if earth_body_m is None else earth_body_m[rows],
                                     radius_m)
    partial_earth = np.zeros(n_ep, bool)
    partial_earth[rows] = pe
    d = dirs[:, at]
    lit, resp = _pair_response(resps, frames, diode, d)
    edge_probe = None
    if len(dirs) > 1:
        ang = 2.0 * np.pi * np.arange(32) / 32
        edge_probe = disc_directions(sun_body[ep], 0.999 * a * np.column_stack([np.cos(ang), np.sin(ang)]))
    out[ep, diode], edge, steady, inside = _disc_mean(d, weights[:, at], resp, diode, frames, resps, body, rings,
                                                      edge_probe, below,
                                                      ~cut[ep] if len(dirs) > 1 and refine_rings > rings else None)
    if len(dirs) == 1 or refine_rings <= rings:
        return out
    # The diode's own horizon across the disc: a sliver of the disc above it can lie beyond every point of
    # the 397-point rule (rendered 5e-4 W/m^2 where it gave 0, 5 standard errors, on a bare tilt0_fov90 day).
    horizon = np.abs(row_dot(sun_body[ep], frames[diode, 2])) < np.sin(sun_angular_radius_rad)
    edge |= horizon & (edge | ~np.isnan(steady) | (body is None))   # (an edge across the interior: 37 points)
    edge &= ~cut[ep]
    if edge.any():
        # the body's shadow edge across the disc: the product quadrature (:data:`_EDGE_RADIAL`)
        e_ep, e_k = ep[edge], diode[edge]
        out[e_ep, e_k] = _edge_mean(sun_body[e_ep], sun_angular_radius_rad, e_k, frames, resps, body,
                                    np.where(horizon, steady, np.nan)[edge])
        ep, diode, lit, resp, inside = ep[~edge], diode[~edge], lit[:, ~edge], resp[:, ~edge], inside[~edge]
        below = None if below is None else below[~edge]
    # Kinks: probe the disc's very edge too (the quadrature rings stop short of it).
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = disc_directions(sun_body[ep], sun_angular_radius_rad * np.column_stack([np.cos(ang), np.sin(ang)]))
    lit_rim, resp_rim = _pair_response(resps, frames, diode, rim)
    lit_any = (resp > 0).any(axis=0) | (resp_rim > 0).any(axis=0)
    kink = lit_any & ((resp == 0).any(axis=0) | (resp_rim == 0).any(axis=0) | partial_earth[ep])
    kink |= inside & ~cut[ep]   # the box's edge across a clear disc's interior: 397 points (1024: ~9 ms a pair)
    # the well's full-light edge
    full = (lit == 1).any(axis=0) | (lit_rim == 1).any(axis=0)
    kink |= full & ((lit < 1).any(axis=0) | (lit_rim < 1).any(axis=0))
    if not kink.any():
        return out
    ep, diode, below = ep[kink], diode[kink], None if below is None else below[kink]
    rows, at = np.unique(ep, return_inverse=True)
    fine_dirs, fine_weights, _ = _disc_sample(sun_body[rows], sun_angular_radius_rad, refine_rings,
                                              None if earth_body_m is None else earth_body_m[rows], radius_m)
    d = fine_dirs[:, at]
    out[ep, diode] = _disc_mean(d, fine_weights[:, at], _pair_response(resps, frames, diode, d)[1], diode,
                                frames, resps, body, refine_rings,
                                below=below)[0]
    return out
