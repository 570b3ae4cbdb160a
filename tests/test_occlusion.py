"""Body-box occlusion in closed form, against brute-force counting over points of the diode."""
import numpy as np
import pytest

from scenes.config import SatelliteConfig, panel_axes
from simcore.radiometry.analytic import solar_disc_offsets
from simcore.shapes.occlusion import box_hit, direct_visibility, lit_fraction_with_box


def _segment_hits_box(o, d, half):
    # Independent oracle: march the ray in small steps and test containment (no slab algebra).
    t = np.linspace(0.0, 1.0, 4001)[:, None]   # 1 m of ray, 0.25 mm steps
    p = o[None, :] + t * d[None, :]
    return bool(np.any(np.all(np.abs(p) <= half, axis=1)))


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
