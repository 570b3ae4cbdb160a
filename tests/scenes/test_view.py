"""`sunsim view`: the camera's projection against Mitsuba, the caption's angles against independent
computations, the pictures' sizes and diode numbers (simcore.picture.view, simcore.picture.scene.Camera)."""
import subprocess
import sys
import warnings
from importlib.resources import files

import matplotlib.image
import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation

from scenes.config import SatelliteConfig
from simcore.picture.scene import Camera, PictureGeometry, load_scene, render_passes
from simcore.constants import R_EARTH_MEAN_M

SUNSIM = [sys.executable, "-m", "simcore.cli"]


def test_a_point_lands_on_the_pixel_mitsuba_draws_it_on():
    # Oracle: Mitsuba's own render. Three small emitting spheres (6 mm radius, ~1 m away: ~1.5 px wide)
    # at points spread over a non-square frame; the centroid of each bright blob is where Mitsuba puts
    # the point. A swapped or flipped axis, or a wrong field of view or aspect, moves a point by 5 px or
    # more here; 0.2 px bounds the Monte-Carlo noise of a blob's centroid at 256 samples per pixel.
    from simcore._llvm import import_mitsuba
    mi = import_mitsuba()
    import simcore.picture.scene  # noqa: F401  (sets the variant)

    cam = Camera((0.9, -0.4, 0.5), (0.05, 0.02, -0.03), (0.0, 0.0, 1.0), 40.0, 96, 64)
    points = np.array([[0.0, 0.0, 0.0], [0.10, 0.25, 0.10], [-0.15, -0.05, -0.12]])
    xy, depth = cam.project(points)
    assert np.all(depth > 0) and np.all((xy > 3) & (xy < [93, 61]))
    scene = {"type": "scene", "integrator": {"type": "direct"}, "sensor": cam.sensor_dict(256)}
    for i, p in enumerate(points):
        scene[f"s{i}"] = {"type": "sphere", "center": p.tolist(), "radius": 0.006,
                          "emitter": {"type": "area", "radiance": {"type": "uniform", "value": 1.0}}}
    loaded = mi.load_dict(scene)
    m = np.array(loaded.sensors()[0].world_transform().matrix)
    np.testing.assert_allclose(m[..., 0] if m.ndim == 3 else m, cam.to_world(), atol=1e-6)   # the matrix it uses
    img = np.array(mi.render(loaded, seed=1, spp=256))[..., 0]
    labels, n = ndimage.label(img > 0)
    assert n == 3
    rows, cols = np.indices(img.shape)
    for k in range(1, n + 1):
        w = np.where(labels == k, img, 0.0)
        c = np.array([(w * (cols + 0.5)).sum(), (w * (rows + 0.5)).sum()]) / w.sum()
        d = np.linalg.norm(xy - c, axis=1)
        assert d.min() < 0.2, (c, xy)


def _frame(v):
    """Two unit vectors completing ``v`` to a right-handed orthonormal triad (v, a, b)."""
    a = np.cross(v, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    return a, np.cross(v, a)


def test_caption_angles_closed_forms():
    # Oracles: closed forms of a hand-built geometry. Satellite 700 km over (35 N, 120 W); the Sun
    # 120 deg from the zenith, i.e. 30 deg below the horizontal, which from 700 km lies
    # acos(6371.01 / 7071.01) = 25.71 deg above the horizon's dip: 30 deg below the horizontal is
    # -30 + 25.71 = -4.29 deg over the limb. Body axes built at known angles to the Sun:
    # x at 40 deg, y at 90 deg, z = x cross y at 50 deg.
    from simcore.picture.view import sun_earth_angles

    lat, lon, h = np.radians(35.0), np.radians(-120.0), 700e3
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    a, b = _frame(up)
    sun = np.cos(np.radians(120.0)) * up + np.sin(np.radians(120.0)) * a
    s_a, s_b = _frame(sun)
    x_b = np.cos(np.radians(40.0)) * sun + np.sin(np.radians(40.0)) * s_a
    y_b = s_b
    g = PictureGeometry((R_EARTH_MEAN_M + h) * up, sun, np.stack([x_b, y_b, np.cross(x_b, y_b)]))
    cam = Camera(tuple(0.9 * (g.R_body_from_ecef @ up)), (0, 0, 0), tuple(g.R_body_from_ecef @ a), 30.0, 32, 18)
    out = sun_earth_angles(g, cam)
    dip = np.degrees(np.arccos(R_EARTH_MEAN_M / (R_EARTH_MEAN_M + h)))
    assert out["altitude_m"] == pytest.approx(700e3, abs=1e-6)
    assert out["sub_lat_deg"] == pytest.approx(35.0, abs=1e-9) and out["sub_lon_deg"] == pytest.approx(-120.0, abs=1e-9)
    assert out["sun_above_limb_deg"] == pytest.approx(-30.0 + dip, abs=1e-9)
    assert -30.0 + dip == pytest.approx(-4.29, abs=0.005)
    np.testing.assert_allclose(out["sun_to_body_axis_deg"], [40.0, 90.0, 50.0], atol=1e-9)
    assert out["view_off_nadir_deg"] == pytest.approx(0.0, abs=1e-6)   # a camera at the zenith looks straight down


def test_caption_angles_at_a_real_epoch_match_astropy():
    # Oracle: another implementation of the whole chain. astropy (its own Sun ephemeris and its
    # TEME -> GCRS) places ESTCube-1 (sgp4 on the shipped TLE) and the Sun at the view's default epoch;
    # the tumble is rebuilt with scipy's rotation vector (1.9 deg/s about (1,1,1)/sqrt 3 for 2400 s,
    # body aligned with GCRS at the run's start). Tolerance 0.01 deg: the thesis' Sun model accuracy
    # (SPEC sec. 2); astropy's apparent Sun differs from a geometric one by the 0.0057 deg aberration.
    from astropy.utils import iers
    iers.conf.auto_download = False
    import astropy.units as u
    from astropy.coordinates import GCRS, TEME, CartesianRepresentation, get_body
    from astropy.time import Time
    from sgp4.api import Satrec

    from simcore.picture.view import DEFAULT_VIEW_TIME, view_epoch, sun_earth_angles, wide_camera

    ve = view_epoch(DEFAULT_VIEW_TIME)
    got = sun_earth_angles(ve.geometry, wide_camera(ve.geometry, 32, 18))
    tle = [s for s in (files("simcore") / "data" / "estcube1_2016-07-27.tle").read_text().splitlines()
           if s.startswith(("1 ", "2 "))]
    t = Time(DEFAULT_VIEW_TIME.rstrip("Z"), scale="utc")
    err, r_km, _ = Satrec.twoline2rv(tle[0], tle[1]).sgp4(t.jd1, t.jd2)
    assert err == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")           # astropy's notes about IERS tables, none about accuracy here
        r = TEME(CartesianRepresentation(np.array(r_km) * u.km), obstime=t).transform_to(GCRS(obstime=t))
        r = r.cartesian.xyz.to(u.m).value
        sun = get_body("sun", t).cartesian.xyz.to(u.m).value
    s = (sun - r) / np.linalg.norm(sun - r)
    rn = np.linalg.norm(r)
    limb = np.degrees(np.arccos(-s @ r / rn) - np.arcsin(R_EARTH_MEAN_M / rn))
    R_gcrs_from_body = Rotation.from_rotvec(np.radians(1.9 * 2400.0) * np.ones(3) / np.sqrt(3)).as_matrix()
    body = np.degrees(np.arccos(R_gcrs_from_body.T @ s))
    assert got["altitude_m"] == pytest.approx(rn - R_EARTH_MEAN_M, abs=1.0)
    assert got["sun_above_limb_deg"] == pytest.approx(limb, abs=0.01)
    np.testing.assert_allclose(got["sun_to_body_axis_deg"], body, atol=0.01)
    # the wide view is built 30 deg above the local horizontal: 60 deg off nadir
    assert got["view_off_nadir_deg"] == pytest.approx(60.0, abs=1e-9)


@pytest.mark.parametrize("config, n", [("tilt0_fov90", 6), ("tilt20_fov70", 14)])
def test_the_close_up_numbers_every_diode(config, n):
    # Oracle: the configuration's diode count and indices (SPEC sec. 5): every diode is numbered in
    # at least one of the four panels, and only in panels it faces.
    from simcore.picture.view import DEFAULT_VIEW_TIME, close_up_cameras, _render_panel, view_epoch

    cfg = SatelliteConfig.load(config)
    ve = view_epoch(DEFAULT_VIEW_TIME)
    seen = []
    for label, cam in close_up_cameras(640, 360).items():
        panel = _render_panel(cfg, ve.geometry, cam, None, False, 1, 0, label)
        facing = {d.index for d in cfg.diodes if d.normal_body @ np.asarray(cam.origin_m) > 0}
        assert {k for k, _ in panel.labelled} <= facing
        seen += [k for k, _ in panel.labelled]
    assert sorted(set(seen)) == list(range(n))


def test_the_3u_close_up_crops_the_wings_so_its_diodes_stay_legible():
    # Oracles: the configuration's six face diodes (scenes/examples/cubesat3u_panels.toml), and a legibility
    # floor of 2 pixels for the 2.65 mm side of the diode each panel looks at nearly head-on, in the default
    # 960 x 540 picture (framed on the whole 0.7 m wing span, as before, it was 0.8 px); the wings reach 350 mm sideways, so the camera must stay
    # farther than that, and the 340.5 mm body must fit in the panel's height.
    from simcore.picture.view import DEFAULT_VIEW_TIME, close_up_cameras, close_up_framing, _render_panel, view_epoch

    cfg = SatelliteConfig.load(files("scenes") / "examples" / "cubesat3u_panels.toml")
    half, distance = close_up_framing(cfg)
    assert distance > 0.35
    cams = close_up_cameras(960, 540, half, distance)
    side_m = cfg.diodes[0].aperture.diode_x_m
    ve = view_epoch(DEFAULT_VIEW_TIME)
    seen = []
    for label, cam in cams.items():
        for d in cfg.diodes:
            if d.normal_body @ np.asarray(cam.origin_m) / distance > 0.8:      # the side face the panel looks at
                xy, _ = cam.project(d.position_body_m + np.outer([-0.5, 0.5], side_m * d.frame_body[0]))
                assert np.linalg.norm(xy[1] - xy[0]) >= 2.0, (label, d.index)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * np.asarray(
            cfg.body.size_m) / 2
        xy, _ = cam.project(corners)
        assert 0 <= xy[:, 1].min() and xy[:, 1].max() <= cam.height, label
        panel = _render_panel(cfg, ve.geometry, cam, None, False, 1, 0, label)
        seen += [k for k, _ in panel.labelled]
    assert sorted(set(seen)) == list(range(6))


@pytest.mark.parametrize("extra", [[], ["--close-up"], ["--map", "uniform:0.3", "--config", "tilt0_fov90"]])
def test_the_cli_writes_a_png_of_the_asked_size(tmp_path, extra):
    r = subprocess.run(SUNSIM + ["view", "--spp", "1", "--resolution", "120", "68", "-o", "v.png", "--json"] + extra,
                       cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    img = matplotlib.image.imread(tmp_path / "v.png")
    assert img.shape[:2] == (68, 120)
    assert img[..., :3].std() > 0.05          # not a blank frame


def test_coastlines_are_where_the_published_capes_are():
    # Oracle: published coordinates of capes and a strait (any atlas): Cape of Good Hope 34.357 S
    # 18.474 E, Cape Horn 55.979 S 67.275 W, Europa Point (Gibraltar) 36.110 N 5.345 W. The crude
    # GSHHG polygons simplify coasts to ~25 km, so a vertex lies within 0.5 deg of each; the middle
    # of the South Atlantic (40 S 25 W) is more than 5 deg from any coast (Tristan da Cunha: 14 deg).
    from simcore.environment.coastlines import coastlines_deg

    pts = np.concatenate(coastlines_deg())
    assert pts.shape[1] == 2 and np.all(np.abs(pts[:, 1]) <= 90) and np.all(np.abs(pts[:, 0]) <= 180)

    def nearest_deg(lat, lon):
        la, lo = np.radians(pts[:, 1]), np.radians(pts[:, 0])
        c = np.sin(la) * np.sin(np.radians(lat)) + np.cos(la) * np.cos(np.radians(lat)) * np.cos(lo - np.radians(lon))
        return float(np.degrees(np.arccos(np.clip(c, -1, 1))).min())

    for lat, lon in [(-34.357, 18.474), (-55.979, -67.275), (36.110, -5.345)]:
        assert nearest_deg(lat, lon) < 0.5
    assert nearest_deg(-40.0, -25.0) > 5.0
    assert np.min(pts[:, 1]) < -70.0       # Antarctica's shore (type 5) is there


def test_drawn_coastline_points_are_where_mitsuba_sees_them():
    # Oracle: Mitsuba's own camera ray and sphere intersection. Each drawn coastline vertex's pixel
    # position, handed back to Mitsuba's sensor, must hit the Earth at that vertex: within 200 m,
    # against ~1 km per pixel at the limb of this 320-px view; a wrong Earth rotation (a transposed
    # matrix, a longitude offset of one map cell) puts it tens to thousands of km away.
    from simcore._llvm import import_mitsuba
    mi = import_mitsuba()
    from simcore.picture.view import coastline_segments, view_epoch, wide_camera

    ve = view_epoch("2016-07-02T09:12:00Z")           # over Zambia: the East African coast in view
    cfg = SatelliteConfig.load("tilt0_fov90")
    cam = wide_camera(ve.geometry, 320, 180)
    from simcore.picture.scene import build_scene
    scene_dict, names, kinds, _ = build_scene(cfg, ve.geometry, camera=cam, spp=1)
    scene = load_scene(scene_dict)
    passes = render_passes(scene, names, kinds, 1)
    seg = coastline_segments(ve.geometry, cam, passes)
    assert len(seg) >= 5
    xy = seg[:, 0, :]
    sensor = scene.sensors()[0]
    rays, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(*(xy / [320, 180]).T.astype(np.float32)), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(rays)
    assert np.all(np.array(si.is_valid()))
    R = np.asarray(ve.geometry.R_body_from_ecef)
    hit_ecef = (np.array(si.p, dtype=float).T + R @ ve.geometry.r_sat_ecef_m) @ R
    # the same vertices straight from the data, on the 6371.01 km sphere
    from simcore.environment.coastlines import coastlines_deg, lonlat_to_ecef_m
    data = lonlat_to_ecef_m(np.concatenate(coastlines_deg()), R_EARTH_MEAN_M)
    d = np.linalg.norm(hit_ecef[:, None, :] - data[None, :, :], axis=2).min(axis=1)
    assert np.all(d < 200.0), d.max()


def test_an_attitude_file_sets_the_body_axes(tmp_path):
    # Oracle: astropy's Sun seen from ESTCube-1 (as above), with the body frame held on GCRS by an
    # identity attitude history: the Sun's angles to body +x, +y, +z are its angles to the GCRS axes.
    import astropy.units as u
    from astropy.coordinates import GCRS, TEME, CartesianRepresentation, get_body
    from astropy.time import Time
    from astropy.utils import iers
    from sgp4.api import Satrec
    iers.conf.auto_download = False

    from simcore.picture.view import view_epoch, sun_earth_angles

    (tmp_path / "att.csv").write_text("t_s,qw,qx,qy,qz\n0,1,0,0,0\n3600,1,0,0,0\n")
    ve = view_epoch("2016-07-02T00:30:00Z", start="2016-07-02T00:00:00Z", attitude_file=str(tmp_path / "att.csv"))
    got = sun_earth_angles(ve.geometry)["sun_to_body_axis_deg"]
    tle = [s for s in (files("simcore") / "data" / "estcube1_2016-07-27.tle").read_text().splitlines()
           if s.startswith(("1 ", "2 "))]
    t = Time("2016-07-02T00:30:00", scale="utc")
    _, r_km, _ = Satrec.twoline2rv(tle[0], tle[1]).sgp4(t.jd1, t.jd2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = TEME(CartesianRepresentation(np.array(r_km) * u.km), obstime=t).transform_to(GCRS(obstime=t))
        r = r.cartesian.xyz.to(u.m).value
        sun = get_body("sun", t).cartesian.xyz.to(u.m).value
    s = (sun - r) / np.linalg.norm(sun - r)
    np.testing.assert_allclose(got, np.degrees(np.arccos(s)), atol=0.01)
    with pytest.raises(ValueError, match="give a --time within the file"):
        view_epoch("2016-07-02T02:00:00Z", attitude_file=str(tmp_path / "att.csv"))
