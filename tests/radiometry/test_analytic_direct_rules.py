"""The direct reference's short cuts, each against an independent oracle: the 13-point rule of smooth pairs (the 37
equal-area points' moments, a closed form for a bare diode, a 4921-point rule), the kink planes that decide where it
applies (the lit rectangle's binding bounds at dense disc points) and the body box's shadow over a whole disc
decided in closed form (slab tests of rays from points all over the diode toward points all over the disc)."""
import numpy as np
import pytest

from scenes.config import SatelliteConfig
from simcore.radiometry.analytic import BodyBox
from simcore.radiometry.analytic_direct import (_direct_response, _kink_planes, _smooth_pairs, disc_directions,
                                                smooth_disc_rule, solar_disc_offsets)
from simcore.shapes.aperture import WellAperture, diode_frame, lit_rectangle_of
from simcore.shapes.occlusion import box_hit, disc_box_shadow

SUN_RADIUS = 4.65e-3


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("radius", [SUN_RADIUS, 0.02])
def test_the_smooth_rule_has_the_37_points_moments_up_to_degree_7(radius):
    off, w = smooth_disc_rule(radius)
    ring = solar_disc_offsets(radius, 3)
    assert off.shape == (13, 2) and np.all(w > 0) and abs(w.sum() - 1) < 1e-15
    assert np.max(np.hypot(*off.T)) < 1.01 * radius
    differ = 0
    for i in range(9):
        for j in range(9 - i):
            mine = np.sum(w * off[:, 0] ** i * off[:, 1] ** j) / radius ** (i + j)
            theirs = np.mean(ring[:, 0] ** i * ring[:, 1] ** j) / radius ** (i + j)
            if i + j <= 7:
                assert abs(mine - theirs) < 1e-13, (i, j)
            else:
                differ += abs(mine - theirs) > 1e-4
    assert differ > 0                                   # degree 8 is where they part


def test_a_bare_diode_reads_the_cosine_of_the_suns_centre(rng):
    # Closed form: a bare diode's response d . n averaged over the disc with the model's weights (points d =
    # (s + o) / |s + o|, |o| <= a, the mean divided by that of cos alpha = 1 / |s + o|) is s . n exactly, the
    # offsets' terms cancelling in pairs.
    K = 6
    frames = np.array([diode_frame(n) for n in _unit(rng.normal(size=(K, 3)))])
    resps = [WellAperture.bare()] * K
    sun = _unit(rng.normal(size=(400, 3)))
    got = _direct_response(sun, frames, resps, None, SUN_RADIUS)
    cos = sun @ frames[:, 2].T
    clear = cos > 2 * SUN_RADIUS
    assert clear.sum() > 300
    np.testing.assert_allclose(got[clear], cos[clear], rtol=1e-14, atol=0)
    e, k = np.nonzero(clear)
    assert np.mean(_smooth_pairs(sun[e], k, _kink_planes(frames, resps), SUN_RADIUS)) > 0.5     # the 13 points' path


def _binding(params, dd):
    """Return (..., 5) int: which bound binds on each side of the lit rectangle (argmax / argmin over the diode's
    side and the rims' shifted sides) and whether it is empty, at diode-frame directions ``dd``."""
    hdx, hdy, ox1, oy1, h1, ox2, oy2, h2 = params
    tu, tv = dd[..., 0] / dd[..., 2], dd[..., 1] / dd[..., 2]
    lo_x = np.argmax(np.stack([np.full_like(tu, -hdx), -ox1 - h1 * tu, -ox2 - h2 * tu]), axis=0)
    hi_x = np.argmin(np.stack([np.full_like(tu, hdx), ox1 - h1 * tu, ox2 - h2 * tu]), axis=0)
    lo_y = np.argmax(np.stack([np.full_like(tv, -hdy), -oy1 - h1 * tv, -oy2 - h2 * tv]), axis=0)
    hi_y = np.argmin(np.stack([np.full_like(tv, hdy), oy1 - h1 * tv, oy2 - h2 * tv]), axis=0)
    empty = lit_rectangle_of(params, dd[..., 0], dd[..., 1], dd[..., 2])[4] <= 0
    return np.stack([lo_x, hi_x, lo_y, hi_y, empty], axis=-1)


@pytest.mark.parametrize("config", ["tilt20_fov70", "tilt25_fov75"])
def test_smooth_pairs_see_one_piece_of_the_response_over_the_whole_disc(config, rng):
    cfg = SatelliteConfig.load(config)
    frames, resps = np.asarray(cfg.frames), list(cfg.apertures)
    # chamfered wells too (two rims): the bounds of the lower and the top rim cross inside the field of view
    resps[1] = WellAperture(1.6e-3, 1.6e-3, 3.0e-3, 2.6e-3, 1.2e-3, chamfer_m=0.4e-3, chamfer_deg=40.0)
    K = len(frames)
    # Sun directions within a few disc radii of every kink plane of every diode, and random ones
    planes = _kink_planes(frames, resps)
    sun, diode = [], []
    for k in range(K):
        for c in planes[k]:
            d = _unit(rng.normal(size=(30, 3)))
            d = _unit(d - np.outer(d @ c, c))
            sun.append(_unit(d + rng.uniform(-4, 4, (30, 1)) * SUN_RADIUS * c))
            diode.append(np.full(30, k))
    sun.append(_unit(rng.normal(size=(2000, 3))))
    diode.append(rng.integers(0, K, 2000))
    sun, diode = np.concatenate(sun), np.concatenate(diode)
    front = np.einsum("tj,tj->t", sun, frames[diode, 2]) > 0.05
    sun, diode = sun[front], diode[front]
    off, _ = smooth_disc_rule(SUN_RADIUS)
    reach = float(np.max(np.hypot(*off.T)))
    smooth = _smooth_pairs(sun, diode, planes, reach, 0.0)
    # the oracle: 4921 equal-area points and 256 on the rim at the rule's reach, each one's binding bounds
    ang = 2 * np.pi * np.arange(256) / 256
    dense = np.concatenate([solar_disc_offsets(reach, 40), reach * np.column_stack([np.cos(ang), np.sin(ang)])])
    one_piece = np.empty(len(sun), bool)
    for k in range(K):
        t = np.flatnonzero(diode == k)
        dd = disc_directions(sun[t], dense) @ frames[k].T                      # (M, T, 3)
        b = _binding(resps[k].rims, dd)
        one_piece[t] = (b == b[:1]).all(axis=(0, 2))
    assert not (smooth & ~one_piece).any()
    assert smooth.sum() > 500 and (~one_piece).sum() > 200          # both kinds were there
    # A well dark at the disc's centre with no kink plane but the horizon across the disc is dark at every point of
    # the disc in front of the diode (the pairs _direct_response sets to 0 without more ado).
    pre = _smooth_pairs(sun, diode, planes[:, 1:], reach, -np.inf)
    dark_everywhere = np.empty(len(sun), bool)
    centre_dark = np.empty(len(sun), bool)
    for k in range(K):
        t = np.flatnonzero(diode == k)
        centre_dark[t] = resps[k].response(sun[t] @ frames[k].T) == 0
        dark_everywhere[t] = (resps[k].response(disc_directions(sun[t], dense) @ frames[k].T) == 0).all(axis=0)
    assert not (pre & centre_dark & ~dark_everywhere).any()
    assert (pre & centre_dark).sum() > 50 and (centre_dark & ~dark_everywhere).sum() > 20


@pytest.mark.parametrize("config", ["tilt20_fov70", "tilt25_fov75"])
def test_the_smooth_rule_against_the_37_points_and_a_dense_rule(config, rng):
    cfg = SatelliteConfig.load(config)
    frames, resps = np.asarray(cfg.frames), cfg.apertures
    K = len(frames)
    sun = _unit(rng.normal(size=(3000, 3)))
    got = _direct_response(sun, frames, resps, None, SUN_RADIUS)
    e, k = np.nonzero(np.ones((len(sun), K), bool))
    off, w = smooth_disc_rule(SUN_RADIUS)
    taken = _smooth_pairs(sun[e], k, _kink_planes(frames, resps), float(np.max(np.hypot(*off.T))))
    assert taken.sum() > 2000 and np.mean(got[e[taken], k[taken]] > 0.05) > 0.9
    e, k = e[taken], k[taken]
    for rings, tol in ((3, 1e-13), (40, 2e-8)):
        # the 37 equal-area points (the rule's moments: the same numbers to O(a^8)); 4921 points (the 37 points'
        # own error on a smooth response: their mean r^2 is 0.49963 a^2 for the disc's 0.5 a^2; the response's
        # second derivatives over its value stay below ~1 / d_n^2 <= 16: 3.7e-4 x 2.2e-5 / 4 x 16 ~ 3e-8)
        o = solar_disc_offsets(SUN_RADIUS, rings)
        ref = np.empty(len(e))
        for kk in range(K):
            t = np.flatnonzero(k == kk)
            ref[t] = resps[kk].response(disc_directions(sun[e[t]], o) @ frames[kk].T).mean(axis=0)
        ref /= np.mean(1 / np.sqrt(1 + np.sum(o ** 2, axis=1)))
        np.testing.assert_allclose(got[e, k], ref, rtol=tol, atol=0, err_msg=f"{rings} rings")


def _diode_rays_hit(cfg, body, sun, diode, reach):
    """Return ((T,) bool all, (T,) bool any): whether every / some ray from 7 x 7 points over the diode (corners
    included) toward 37 disc points and 32 on its rim at ``reach`` meets the box (slab test)."""
    f = np.linspace(-0.5, 0.5, 7)
    ang = 2 * np.pi * np.arange(32) / 32
    dirs = disc_directions(sun, np.concatenate([solar_disc_offsets(reach, 3),
                                                reach * np.column_stack([np.cos(ang), np.sin(ang)])]))   # (M, T, 3)
    frames = np.asarray(cfg.frames)
    all_, any_ = np.ones(len(sun), bool), np.zeros(len(sun), bool)
    for x in f:
        for y in f:
            ap = [cfg.apertures[k] for k in diode]
            sx = np.array([a.diode_x_m for a in ap]) * x
            sy = np.array([a.diode_y_m for a in ap]) * y
            o = body.positions_m[diode] + sx[:, None] * frames[diode, 0] + sy[:, None] * frames[diode, 1]
            hit = box_hit(np.broadcast_to(o, dirs.shape), dirs, np.asarray(body.half_m))
            all_ &= hit.all(axis=0)
            any_ |= hit.any(axis=0)
    return all_, any_


@pytest.mark.parametrize("config", ["tilt20_fov70", "tilt25_fov75"])
def test_the_box_shadow_over_a_whole_disc_against_rays(config, rng):
    cfg = SatelliteConfig.load(config)
    body = BodyBox.from_config(cfg)
    frames = np.asarray(cfg.frames)
    K = len(frames)
    half_diodes = np.array([[a.diode_x_m / 2, a.diode_y_m / 2] for a in cfg.apertures])
    # Sun directions below each diode's panel, in front of the diode
    diode = rng.integers(0, K, 20000)
    sun = _unit(rng.normal(size=(20000, 3)))
    keep = (np.einsum("tj,tj->t", sun, body.panel_normals[diode]) < 0) & (np.einsum("tj,tj->t", sun, frames[diode, 2]) > 0)
    sun, diode = sun[keep][:1500], diode[keep][:1500]
    reach = 1.007 * SUN_RADIUS
    cls = disc_box_shadow(sun, diode, frames, half_diodes, body.positions_m, body.panel_normals, body.half_m, reach)
    every, some = _diode_rays_hit(cfg, body, sun, diode, reach)
    assert every[cls == 1].all() and not some[cls == -1].any()
    assert (cls == 1).sum() > 200 and (cls == -1).sum() > 10 and (cls == 0).sum() > 10
    assert (some & ~every)[cls == 0].sum() > 5             # the undecided ones include shadow edges
    # where the diode is not over its panel's face (here moved beyond the box's side) nothing is decided
    moved = body.positions_m + 0.2 * np.sign(body.positions_m) * (1 - np.abs(body.panel_normals))
    assert not disc_box_shadow(sun, diode, frames, half_diodes, moved, body.panel_normals, body.half_m, reach).any()


def test_discs_across_a_wells_horizon_read_0_only_where_every_point_is_dark(rng):
    # The short cut sets such pairs to 0 from one point of the disc in front of the diode; the oracle: 4921 points
    # and 256 on the rim, each one's response (a well's, its lit rectangle's closed form).
    cfg = SatelliteConfig.load("tilt20_fov70")
    frames, resps = np.asarray(cfg.frames), list(cfg.apertures)
    resps[2] = resps[9] = WellAperture.bare()                            # lit up to the horizon
    sun, diode = [], []
    for k in range(len(frames)):
        u, v, n = frames[k]
        az = rng.uniform(0, 2 * np.pi, 60)
        p = np.pi / 2 + rng.uniform(-1.5, 1.5, 60) * SUN_RADIUS
        sun.append(np.sin(p)[:, None] * (np.cos(az)[:, None] * u + np.sin(az)[:, None] * v) + np.cos(p)[:, None] * n)
        diode.append(np.full(60, k))
    sun, diode = _unit(np.concatenate(sun)), np.concatenate(diode)
    got = _direct_response(sun, frames, resps, None, SUN_RADIUS)[np.arange(len(sun)), diode]
    ang = 2 * np.pi * np.arange(256) / 256
    dense = np.concatenate([solar_disc_offsets(SUN_RADIUS, 40), SUN_RADIUS * np.column_stack([np.cos(ang), np.sin(ang)])])
    lit_somewhere = np.empty(len(sun), bool)
    for k in range(len(frames)):
        t = np.flatnonzero(diode == k)
        lit_somewhere[t] = (resps[k].response(disc_directions(sun[t], dense) @ frames[k].T) > 0).any(axis=0)
    assert np.all(got[~lit_somewhere] == 0) and np.all(got[lit_somewhere] > 0)
    assert (~lit_somewhere).sum() > 200 and lit_somewhere.sum() > 20
