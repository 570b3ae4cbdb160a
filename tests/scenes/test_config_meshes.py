"""Satellite configurations (scenes.config), their meshes (scenes.meshes) and the Mitsuba picture."""
from importlib.resources import files

import numpy as np
import pytest
import trimesh

from scenes.config import ConfigError, SatelliteConfig, list_configs
from scenes.meshes import PLUG_DEPTH_M, build_parts, build_satellite_mesh, diode_surfaces, export
from simcore.shapes.aperture import WellAperture, diode_frame

SHIPPED = ["tilt0_fov90", "tilt20_fov70", "tilt20_fov75", "tilt25_fov70", "tilt25_fov75", "tilt30_fov70",
           "tilt30_fov75"]
TILTED = SHIPPED[1:]
CLEARANCE_M = 9e-3  # thesis sec. 4.2.1: 9 mm launch-pod clearance above the panel


def _write(tmp_path, text, name="custom.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


# --- ray casting oracle: Moller-Trumbore on the raw triangles (trimesh's own ray module needs rtree) ---
def first_hit(mesh, origins, dirs):
    """Return the distance to the first triangle hit along each ray (inf when none)."""
    tri = np.asarray(mesh.triangles)
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    o, d = np.atleast_2d(origins)[:, None, :], np.atleast_2d(dirs)[:, None, :]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(all="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        v = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
        ok = (np.abs(det) > 1e-20) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-12)
    return np.where(ok, t, np.inf).min(axis=1)


# --- configurations ------------------------------------------------------------------------------
def test_shipped_names():
    assert set(SHIPPED) <= set(list_configs())


def test_spec_normals_tilt20_x_panel():
    # SPEC sec. 5 (thesis sec. 3.2.4), tilt 20, +x panel, (s_az, s_el) = (-1,-1), (0,+1), (+1,-1)
    cfg = SatelliteConfig.load("tilt20_fov70")
    expected = [(0.883022, -0.321394, -0.342020), (0.939693, 0.0, 0.342020), (0.883022, 0.321394, -0.342020)]
    assert np.allclose(cfg.normals[:3], expected, atol=1e-6)


@pytest.mark.parametrize("name", TILTED)
def test_spec_order_all_diodes(name):
    cfg = SatelliteConfig.load(name)
    X = np.radians(cfg.layout["tilt_deg"])
    assert cfg.n_diodes == 14
    # closed forms from SPEC sec. 5: n = (cos el cos az, cos el sin az, sin el), az = phi_p + s_az X, el = s_el X
    c2, cs, s = np.cos(X) ** 2, np.cos(X) * np.sin(X), np.sin(X)
    expected = np.array([
        (c2, -cs, -s), (np.cos(X), 0, s), (c2, cs, -s),            # +x: (-1,-1) (0,+1) (+1,-1)
        (cs, c2, s), (0, np.cos(X), -s), (-cs, c2, s),             # +y: (-1,+1) (0,-1) (+1,+1)
        (-c2, cs, -s), (-np.cos(X), 0, s), (-c2, -cs, -s),         # -x
        (-cs, -c2, s), (0, -np.cos(X), -s), (cs, -c2, s),          # -y
        (0, 0, 1), (0, 0, -1)])
    assert np.allclose(cfg.normals, expected, atol=1e-12)
    assert np.allclose(cfg.frames, [diode_frame(n) for n in expected], atol=1e-12)
    fov = cfg.layout["fov_deg"]
    assert all(d.aperture == WellAperture.design(fov) and d.fov_deg == fov for d in cfg.diodes)


def test_baseline():
    cfg = SatelliteConfig.load("tilt0_fov90")
    assert np.allclose(cfg.normals, [(1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)])
    assert all(d.aperture == WellAperture.bare() for d in cfg.diodes)
    assert np.all(cfg.fov_deg == 90.0)


def test_extra_flat_diodes_per_run_and_per_file(tmp_path):
    cfg = SatelliteConfig.load("tilt25_fov75", extra_flat_diodes=True)
    assert cfg.n_diodes == 16
    assert np.allclose(cfg.normals[14:], [(0, 0, 1), (0, 0, -1)])
    assert np.allclose(cfg.normals[:14], SatelliteConfig.load("tilt25_fov75").normals)
    path = _write(tmp_path, '[layout]\npattern = "thesis14"\ntilt_deg = 25\nfov_deg = 70\nextra_flat_diodes = true\n')
    assert SatelliteConfig.load(path).n_diodes == 16
    assert SatelliteConfig.load(path, extra_flat_diodes=False).n_diodes == 14


def test_dead():
    cfg = SatelliteConfig.load("tilt20_fov70")
    assert not cfg.dead.any()
    d0 = cfg.with_dead([0])
    assert d0.dead.tolist() == [True] + [False] * 13 and d0.live.sum() == 13
    assert SatelliteConfig.load("tilt20_fov70", dead=[0]).dead[0]
    with pytest.raises(ConfigError, match="out of range"):
        cfg.with_dead([14])


def test_explicit_diodes(tmp_path):
    path = _write(tmp_path, """
name = "two"
[[diode]]
name = "a"
panel = "+x"
az_deg = 10.0
el_deg = -20.0
at_mm = [10.0, -30.0]
fov_deg = 70
[[diode]]
name = "b"
panel = "-z"
normal = [0.0, 0.0, -1.0]
well = { height_mm = 1.0, opening_mm = [4.65, 4.65] }
""")
    cfg = SatelliteConfig.load(path)
    assert cfg.name == "two" and cfg.n_diodes == 2
    el, az = np.radians(-20), np.radians(10)
    assert np.allclose(cfg.normals[0], [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    # FOV of an explicit well: the whole diode stays lit while h tan(theta) <= (w - a) / 2
    a = np.sqrt(7.02)
    assert cfg.fov_deg[1] == pytest.approx(np.degrees(np.arctan((4.65 - a) / 2 / 1.0)), abs=1e-9)
    # the diode on the +x panel: its foot at (lateral y, along z) = (10, -30) mm, above x = 50 mm
    assert cfg.positions_m[0][1:] == pytest.approx([0.010, -0.030]) and cfg.positions_m[0][0] > 0.050


@pytest.mark.parametrize("text, match", [
    ('[layout]\npattern = "thesis14"\ntilt_dge = 20\nfov_deg = 70\n', r"tilt_dge.*did you mean 'tilt_deg'"),
    ('[layot]\npattern = "thesis14"\n', r"layot.*did you mean 'layout'"),
    ('[layout]\npattern = "thesis14"\ntilt_deg = 60\nfov_deg = 70\n', r"tilt_deg must lie in"),
    ('[layout]\npattern = "thesis14"\ntilt_deg = 20\nfov_deg = 0\n', r"fov_deg must lie in"),
    ('[layout]\npattern = "thesis14"\ntilt_deg = 20\nfov_deg = 86\n', r"cannot be realised"),
    ('[layout]\npattern = "thesis14"\ntilt_deg = 30\nfov_deg = 80\n', r"launch-pod clearance"),
    ('[layout]\npattern = "thesis15"\ntilt_deg = 30\nfov_deg = 70\n', r"did you mean 'thesis14'"),
    ('[[diode]]\npanel = "+x"\nnormal = [1.0, 0.1, 0.0]\nfov_deg = 70\n', r"not a unit vector"),
    ('[[diode]]\npanel = "+x"\nnormal = [1.0, 0.0, 0.0]\nat_mm = [45.0, 0.0]\nfov_deg = 70\n', r"outside the \+x panel"),
    ('[[diode]]\npanel = "+x"\nnormal = [1.0, 0.0, 0.0]\nat_mm = [0.0, 120.0]\nfov_deg = 70\n', r"outside the \+x panel"),
    ('[[diode]]\npanel = "+x"\nnormal = [0.0, 1.0, 0.0]\nfov_deg = 70\n', r"right panel"),
    ('[[diode]]\npanel = "+w"\nnormal = [1.0, 0.0, 0.0]\nfov_deg = 70\n', r"unknown panel"),
    ('[[diode]]\npanel = "+x"\nnormal = [1.0, 0.0, 0.0]\nfov_deg = 70\n'
     '[[diode]]\npanel = "+x"\nnormal = [1.0, 0.0, 0.0]\nat_mm = [3.0, 0.0]\nfov_deg = 70\n', r"overlap"),
    ('[[diode]]\npanel = "+x"\nnormal = [1.0, 0.0, 0.0]\nfov = 70\n', r"'fov'.*did you mean 'fov_deg'"),
])
def test_validation_errors(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        SatelliteConfig.load(_write(tmp_path, text))


def test_unknown_name_suggests():
    with pytest.raises(ConfigError, match=r"did you mean .*'tilt20_fov70'"):
        SatelliteConfig.load("tilt20_fov7")
    assert issubclass(ConfigError, ValueError)


# --- geometry ------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SHIPPED)
def test_parts_closed_and_within_clearance(name):
    cfg = SatelliteConfig.load(name, extra_flat_diodes=name != "tilt0_fov90")
    parts = build_parts(cfg)
    half = np.asarray(cfg.body.size_m) / 2
    for part_name, mesh in parts.items():
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, part_name
        if part_name == "body":
            assert np.allclose(mesh.bounds, [-half, half])
            continue
        k = int(part_name.split("_")[1])
        p = np.zeros(3)
        axis = "xyz".index(cfg.diodes[k].panel[1])
        p[axis] = 1.0 if cfg.diodes[k].panel[0] == "+" else -1.0
        height = mesh.vertices @ p - half[axis]
        assert height.min() >= -1e-12, part_name                      # nothing sinks into the body
        assert height.max() <= CLEARANCE_M, part_name                  # launch pod clearance
    occ = build_satellite_mesh(cfg)
    assert len(occ.faces) == sum(len(m.faces) for m in parts.values())
    assert set(occ.metadata["parts"]) == set(parts)


@pytest.mark.parametrize("name", ["tilt0_fov90", "tilt30_fov75"])
def test_diode_surface_is_a_hole_at_its_position(name):
    cfg = SatelliteConfig.load(name, extra_flat_diodes=name != "tilt0_fov90")
    occ = build_satellite_mesh(cfg)
    n, pos = cfg.normals, cfg.positions_m
    # down the normal onto the diode centre: the first surface is the black plug filling the floor's hole,
    # PLUG_DEPTH_M below the diode surface (the diode itself is not an occluder); without the plugs, the ramp's
    # top under the hole, floor_m below
    t = first_hit(occ, pos + 3e-3 * n, -n)
    assert np.allclose(t, 3e-3 + PLUG_DEPTH_M, atol=1e-9)
    parts = build_parts(cfg)
    bare = trimesh.util.concatenate([m for name, m in parts.items() if not name.startswith("plug_")])
    assert np.allclose(first_hit(bare, pos + 3e-3 * n, -n), 3e-3 + cfg.mount.floor_m, atol=1e-9)
    # straight out of the diode: open sky
    assert np.all(np.isinf(first_hit(occ, pos + 1e-9 * n, n)))
    surf = diode_surfaces(cfg)
    assert np.allclose(surf.vertices.reshape(-1, 4, 3).mean(axis=1), pos)
    assert np.allclose(surf.face_normals.reshape(-1, 2, 3), n[:, None, :])


def test_well_walls_along_frame_axes():
    cfg = SatelliteConfig.load("tilt25_fov75")
    parts = build_parts(cfg)
    for k in (0, 4, 12):
        allowed = np.vstack([cfg.frames[k], -cfg.frames[k]])
        for part in ("well", "floor"):
            normals = parts[f"{part}_{k}"].face_normals
            assert np.all(np.max(np.abs(normals @ allowed.T), axis=1) > 1 - 1e-9)
        inner = parts[f"well_{k}"].vertices - cfg.positions_m[k]
        local = inner @ cfg.frames[k].T
        ap = cfg.diodes[k].aperture
        assert np.isclose(local[:, 2].max(), ap.height_m)
        # the opening: the smallest |u| among wall vertices is the half opening
        assert np.isclose(np.abs(local[:, 0]).min(), ap.opening_x_m / 2)


@pytest.mark.parametrize("theta_deg, phi_deg", [(0, 0), (50, 0), (72, 0), (78, 90), (65, 45), (80, 30), (85, 0)])
def test_well_ray_cast_matches_overlap_area(theta_deg, phi_deg):
    # Oracle: the closed-form overlap of the aperture (simcore.shapes.aperture, thesis eq. 4.15 geometry);
    # the mesh is probed by casting rays from a grid of points on the diode through floor + well.
    cfg = SatelliteConfig.load("tilt25_fov70")
    parts = build_parts(cfg)
    k = 0
    ap, (u, v, n), c = cfg.diodes[k].aperture, cfg.frames[k], cfg.positions_m[k]
    mesh = trimesh.util.concatenate([parts[f"well_{k}"], parts[f"floor_{k}"]])
    N = 40
    g = (np.arange(N) + 0.5) / N - 0.5
    gu, gv = np.meshgrid(g * ap.diode_x_m, g * ap.diode_y_m)
    origins = c + gu.reshape(-1, 1) * u + gv.reshape(-1, 1) * v
    th, ph = np.radians(theta_deg), np.radians(phi_deg)
    d_local = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
    d = d_local @ np.array([u, v, n])
    lit = np.mean(np.isinf(first_hit(mesh, origins, np.broadcast_to(d, origins.shape))))
    expected = ap.lit_fraction(d_local)
    assert lit == pytest.approx(expected, abs=2.0 / N + 1e-12)


@pytest.mark.parametrize("name", TILTED)
def test_mounts_do_not_touch(name):
    cfg = SatelliteConfig.load(name, extra_flat_diodes=True)
    parts = build_parts(cfg)
    boxes = {}
    for k, d in enumerate(cfg.diodes):
        verts = np.vstack([m.vertices for key, m in parts.items() if key.endswith(f"_{k}")])
        boxes[k] = (d.panel, verts.min(axis=0), verts.max(axis=0))
    for i in boxes:
        for j in boxes:
            if i < j and boxes[i][0] == boxes[j][0]:
                gap = np.maximum(boxes[i][1] - boxes[j][2], boxes[j][1] - boxes[i][2])
                assert gap.max() > 1e-3, (i, j)


def test_export(tmp_path):
    cfg = SatelliteConfig.load("tilt20_fov70")
    ply = export(cfg, tmp_path / "sat.ply", include_diodes=False)
    back = trimesh.load(ply, process=False)
    assert len(back.faces) == len(build_satellite_mesh(cfg).faces)
    obj = export(cfg, tmp_path / "sat.obj")
    assert obj.stat().st_size > 1000


# --- Mitsuba picture -----------------------------------------------------------------------------
def test_picture_tiny(tmp_path):
    from simcore.picture.scene import picture

    pic = picture("tilt20_fov70", tmp_path / "sat.png", spp=4, resolution=(64, 36))
    assert (tmp_path / "sat.png").stat().st_size > 0
    assert pic.rgb.shape == (36, 64, 3)
    assert pic.satellite_mask.sum() > 50                       # the satellite is in view
    assert (pic.kind == "earth").sum() > 200                   # the Earth behind it
    assert np.all(np.isfinite(pic.radiance)) and pic.radiance[pic.satellite_mask].mean() > 0.05
    space = pic.radiance[pic.kind == ""]                       # empty space is black, but for
    assert space.size > 100 and np.mean(space > 0) < 0.1      # pixels straddling an edge


def test_earth_texture_orientation():
    # Oracle: the TOMS cell values at known places (data file, row 0 = south, column 0 = -179.375 deg);
    # a ray aimed at a cell centre must return exactly that cell's raw reflectivity.
    from simcore._llvm import import_mitsuba
    mi = import_mitsuba()

    from simcore.picture.scene import PictureGeometry, build_scene, load_scene
    from simcore.constants import R_EARTH_MEAN_M

    data = np.load(files("simcore") / "data" / "toms_2005_mean.npz")
    refl, lat, lon = data["reflectivity"], data["lat_deg"], data["lon_deg"]
    # an oblique attitude, to catch a transposed rotation
    R = trimesh.transformations.rotation_matrix(0.7, [0.3, -0.5, 0.8])[:3, :3]
    g = PictureGeometry(np.array([4e6, -3e6, 5.5e6]), np.array([1.0, 0, 0]), R)
    scene = load_scene(build_scene(SatelliteConfig.load("tilt0_fov90"), g, resolution=(4, 4), spp=1)[0])
    rng = np.random.default_rng(5)
    rows = np.r_[rng.integers(0, 180, 300), 0, 179, 162, 113]       # + poles, Greenland band, Sahara band
    cols = np.r_[rng.integers(0, 288, 300), 0, 287, 112, 152]       # 112: -39.4 deg, 152: +10.6 deg
    la, lo = np.radians(lat[rows]), np.radians(lon[cols])
    p = R_EARTH_MEAN_M * np.column_stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    o_body = (1.002 * p - g.r_sat_ecef_m) @ R.T
    d_body = -(p / np.linalg.norm(p, axis=1, keepdims=True)) @ R.T
    ray = mi.Ray3f(mi.Point3f(*o_body.T.astype(np.float32)), mi.Vector3f(*d_body.T.astype(np.float32)))
    si = scene.ray_intersect(ray)
    got = np.array(si.bsdf().eval_diffuse_reflectance(si))[0]
    assert np.all(np.array(si.is_valid()))
    assert np.allclose(got, refl[rows, cols], atol=1e-6)
    assert got[-2] > 0.9 and got[-1] < 0.2   # Greenland bright, Sahara dark (never clamped: some > 1)
    assert refl.max() > 1.0 and np.isclose(got.max(), refl[rows, cols].max())
