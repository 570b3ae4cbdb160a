"""Extra parts of a satellite ([[part]]): meshes from files in their unit, boxes, hinged deployables, the
validation errors, and the check with parts the analytic model does not know.

Oracles: vertex bounds computed by hand from the stated placement; the run check's pass and the
count of diode-epochs the wings shade, and that the check fails when those are not left out.
"""
from pathlib import Path

import numpy as np
import pytest
import trimesh
import xarray as xr

from scenes.config import SatelliteConfig
from simcore.cli import main
from simcore.pipeline.runfile import check_run

EXAMPLES = Path(__file__).resolve().parents[2] / "scenes" / "examples"
BASE = """name = "t"
[layout]
pattern = "faces6"
tilt_deg = 0
fov_deg = 90
"""


def _config(tmp_path, parts_toml, mesh=None, fmt="stl"):
    if mesh is not None:
        mesh.export(str(tmp_path / f"part.{fmt}"))
    path = tmp_path / "sat.toml"
    path.write_text(BASE + parts_toml)
    return path


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "glb"])
def test_mesh_file_in_mm_is_placed_in_metres(tmp_path, fmt):
    # a 20 x 40 x 60 mm box centred at its origin, turned 90 deg about z, then moved 200 mm along +x
    box = trimesh.creation.box(extents=[20.0, 40.0, 60.0])
    path = _config(tmp_path, f"""[[part]]
name = "antenna"
file = "part.{fmt}"
unit = "mm"
rotate_deg = [0, 0, 90]
translate_mm = [200, 0, 0]
material = "aluminium"
""", box, fmt)
    (part,) = SatelliteConfig.load(path).parts
    # by hand: after 90 deg about z, x spans +-20 mm and y +-10 mm; then x += 200 mm
    np.testing.assert_allclose(part.vertices_m.min(axis=0), [0.180, -0.010, -0.030], atol=1e-9)
    np.testing.assert_allclose(part.vertices_m.max(axis=0), [0.220, 0.010, 0.030], atol=1e-9)
    assert part.name == "antenna" and part.material == "aluminium"


def test_hinged_wing_of_the_3u_example_deploys_where_computed_by_hand():
    cfg = SatelliteConfig.load(EXAMPLES / "cubesat3u_panels.toml")
    wing = {p.name: p for p in cfg.parts}["wing_+y"]
    # stowed: x +-48, y 50.5..52.5, z -129.75..170.25 mm; 90 deg about +x through (0, 50, 170.25):
    # (y, z) - hinge -> (-(z - 170.25), y - 50) + hinge: y 50..350, z 170.75..172.75
    np.testing.assert_allclose(wing.vertices_m.min(axis=0) * 1e3, [-48.0, 50.0, 170.75], atol=1e-9)
    np.testing.assert_allclose(wing.vertices_m.max(axis=0) * 1e3, [48.0, 350.0, 172.75], atol=1e-9)


@pytest.mark.parametrize("parts_toml, mesh, words", [
    ('[[part]]\nfile = "part.stl"\nunit = "mm"\n', "garbage", "cannot read the mesh file"),
    ('[[part]]\nfile = "missing.stl"\nunit = "mm"\n', None, "cannot read the mesh file"),
    ('[[part]]\nfile = "part.stl"\n', "box", "give the mesh file's unit"),
    ('[[part]]\nfile = "part.obj"\nunit = "mm"\n', "nan", "not finite"),
    ('[[part]]\nfile = "part.stl"\nunit = "m"\n', "box", "is its unit 'mm'?"),
    ('[[part]]\nbox_mm = [20, 20, 20]\ntranslate_mm = [51, 0, 0]\n', None, "lies inside part"),   # on the +x diode
    ('[[part]]\nbox_mm = [30, 30, 0.4]\ntranslate_mm = [0, 0, 115.5]\n', None, "faces into part"),  # 0.8 mm over +z
    ('[[part]]\nbox_mm = [10, 10, 10]\ntranslate_mm = [300, 0, 0]\nmaterial = "gold_leaf"\n', None,
     "unknown material 'gold_leaf'"),
    ('[[part]]\nname = "a"\nbox_mm = [10, 10, 10]\ntranslate_mm = [300, 0, 0]\n'
     '[[part]]\nname = "a"\nbox_mm = [10, 10, 10]\ntranslate_mm = [-300, 0, 0]\n', None, "two parts share a name"),
    ('[[part]]\nbox_mm = [10, 10, 10]\nhinge = {axis = [0, 0, 0], angle_deg = 90}\n', None, "hinge axis"),
    ('[[part]]\nbox_mm = [10, 10, 10]\ntranlate_mm = [300, 0, 0]\n', None, "did you mean 'translate_mm'"),
    ('[[part]]\nbox_mm = [10, 10, 10]\ntranslate_mm = [200000, 0, 0]\n', None, "reaches 200 m from the body"),
])
def test_bad_parts_are_one_line_errors_before_any_output(tmp_path, config_refused, parts_toml, mesh, words):
    if mesh == "garbage":
        (tmp_path / "part.stl").write_bytes(b"\x00\x01 not a mesh at all \xff" * 3)
    elif mesh == "box":                 # 300 x 300 x 300 mm: with unit "m" a 300 m part
        trimesh.creation.box(extents=[300.0, 300.0, 300.0]).export(str(tmp_path / "part.stl"))
    elif mesh == "nan":
        (tmp_path / "part.obj").write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    path = _config(tmp_path, parts_toml)
    config_refused(path, words)


def _passes_only_with_its_left_out_values(ds, unchecked):
    """Assert that the run ``ds`` passes its check, which counts the left-out direct values ``unchecked`` (time,
    diode), and fails the direct tests when they are put back in."""
    _, report = check_run(ds)
    assert report["pass"] and report["direct_unchecked"] == int(unchecked[ds["valid"].values.astype(bool)].sum())
    forged = ds.copy()
    forged["direct_unchecked"] = forged["direct_unchecked"] * 0
    _, bad = check_run(forged)
    assert not bad["pass"]
    assert any(t["component"] == "direct" and not t["passed"] for t in bad["tests"])


def test_3u_wings_shade_and_reflect_and_the_check_leaves_their_shadows_out(tmp_path, capsys):
    path = tmp_path / "u3.nc"
    rc = main(["run", "--config", str(EXAMPLES / "cubesat3u_panels.toml"), "--start", "2016-07-02T00:45:00Z",
               "--duration", "300", "-o", str(path)])
    assert rc == 0                                         # the check passes
    ds = xr.open_dataset(path)
    names = list(ds["diode_name"].values)
    refl = ds["irradiance"].sel(component="reflected").values
    se = ds["irradiance_se"].sel(component="reflected").values
    faced = [names.index("+y"), names.index("-y")]         # the diodes under the wings
    for k in faced:
        # light reflected by the wings, resolved: some epochs > 4 standard errors above 0
        assert np.any(refl[:, k] > 4 * se[:, k] + 1e-12), names[k]
    for k in (names.index("+x"), names.index("-x"), names.index("-z")):
        assert np.all(refl[:, k] == 0), names[k]            # these see no part of the spacecraft
    unchecked = ds["direct_unchecked"].values.astype(bool)
    assert unchecked[:, faced].any() and not unchecked[:, names.index("+x")].any()
    # Without leaving them out, the wing shadows (which the analytic model does not know) fail the direct check.
    _passes_only_with_its_left_out_values(ds, unchecked)
    # Recomputing the analytic model keeps the same left-out diode-epochs (it lost them once: then it failed)
    ds.close()
    assert main(["validate", str(path), "--recompute-analytic"]) == 0
    with xr.open_dataset(path) as again:
        np.testing.assert_array_equal(again["direct_unchecked"].values.astype(bool), unchecked)


def test_the_shipped_user_mesh_example_loads_from_its_stl_file():
    cfg = SatelliteConfig.load(EXAMPLES / "tilt0_fov90_baffle.toml")
    (baffle,) = cfg.parts
    # camera_baffle.stl: a tube of outer radius 15 mm, 40 mm tall, base at z = 0 (mm); moved to (15, 15, 113.5) mm
    np.testing.assert_allclose(baffle.vertices_m.min(axis=0) * 1e3, [0.0, 0.0, 113.5], atol=1e-4)
    np.testing.assert_allclose(baffle.vertices_m.max(axis=0) * 1e3, [30.0, 30.0, 153.5], atol=1e-4)
    assert baffle.material == "anodised_aluminium" and baffle.source.endswith("camera_baffle.stl")


# ------------------------------------------------------------------ diodes on a part (issue 13 item 2)
WING_DIODES = """
[[diode]]
name = "wing top"
part = "wing_+y"
at_mm = [10.0, 1.0, 100.0]
normal = [0.0, 1.0, 0.0]
fov_deg = 90

[[diode]]
name = "wing under"
part = "wing_+y"
at_mm = [-10.0, -1.0, 50.0]
normal = [0.0, -1.0, 0.0]
fov_deg = 70
"""


def _wing_config(tmp_path, diodes=WING_DIODES):
    path = tmp_path / "wings.toml"
    path.write_text((EXAMPLES / "cubesat3u_panels.toml").read_text() + diodes)
    return path


def test_a_diode_on_a_wing_moves_with_the_wing_as_computed_by_hand(tmp_path):
    cfg = SatelliteConfig.load(_wing_config(tmp_path, WING_DIODES + """
[[diode]]
name = "tilted"
part = "wing_+y"
at_mm = [30.0, 1.0, -100.0]
normal = [0.0, 0.9396926207859084, 0.3420201433256687]
fov_deg = 90
"""))
    top, under, tilted = cfg.diodes[6:]
    # wing_+y: box 96 x 2 x 300 mm about its centre, moved by (0, 51.5, 20.25) mm, then turned +90 deg about
    # x through (0, 50, 170.25) mm, which takes (x, y, z) to (x, 50 - (z - 170.25), 170.25 + (y - 50)): a
    # point (x, y, z) of the box goes to (x, 200 - z, 171.75 + y) mm and a direction (a, b, c) to (a, -c, b).
    # Its +y face (y = 1) looks up: the top diode's foot (10, 100, 172.75) mm, its sensitive surface on the
    # 0.5 mm floor plate (scenes/FORMAT.md [mount] floor_mm) at z = 173.25 mm, normal +z.
    np.testing.assert_allclose(top.position_body_m * 1e3, [10.0, 100.0, 173.25], atol=1e-9)
    np.testing.assert_allclose(top.normal_body, [0.0, 0.0, 1.0], atol=1e-12)
    # the -y face (y = -1) looks down: foot (-10, 150, 170.75) mm, the surface 0.5 mm below it
    np.testing.assert_allclose(under.position_body_m * 1e3, [-10.0, 150.0, 170.25], atol=1e-9)
    np.testing.assert_allclose(under.normal_body, [0.0, 0.0, -1.0], atol=1e-12)
    # (0, cos 20, sin 20) -> (0, -sin 20, cos 20): tilted 20 deg toward the hinge (-y), its foot (30, 300, 172.75)
    np.testing.assert_allclose(tilted.normal_body, [0.0, -0.3420201433256687, 0.9396926207859084], atol=1e-12)
    assert tilted.part == "wing_+y" and tilted.panel is None
    # no ramp: the floor's lowest corner stands on the wing's top face (z = 172.75 mm), above the foot's line
    bottom, _ = tilted.mount_corners_m(cfg.mount)
    assert bottom[:, 2].min() * 1e3 == pytest.approx(172.75, abs=1e-9)
    np.testing.assert_allclose(tilted.position_body_m[:2] * 1e3, [30.0, 300.0], atol=1.5)
    from scenes.meshes import build_parts
    names = build_parts(cfg)
    assert "floor_7" in names and "well_7" in names and "ramp_7" not in names and "ramp_0" in names


@pytest.mark.parametrize("diode_toml, words", [
    ('part = "wing_+z"\nat_mm = [0, 1, 0]\nnormal = [0, 1, 0]\n', "unknown part 'wing_+z'"),
    ('part = "wing_+y"\nat_mm = [0, 2, 0]\nnormal = [0, 1, 0]\n', "lies 1.00 mm from the surface of part 'wing_+y'"),
    ('part = "wing_+y"\nat_mm = [0, 1, 0]\nnormal = [0, -1, 0]\n', "points into part 'wing_+y'"),
    ('part = "wing_+y"\npanel = "+x"\nat_mm = [0, 1, 0]\nnormal = [0, 1, 0]\n', "not both"),
    ('part = "wing_+y"\nat_mm = [0, 1]\nnormal = [0, 1, 0]\n', "at_mm (on a part: [x, y, z] in mm"),
    # a chamfer cutting through the walls is refused on a part as on a panel (it loaded on a part once)
    ('part = "wing_+y"\nat_mm = [0, 1, 0]\nnormal = [0, 1, 0]\n'
     'well = {height_mm = 1.0, opening_mm = [5, 5], chamfer_mm = 1.0, chamfer_deg = 60}\n', "through the 0.5 mm wall"),
])
def test_bad_diodes_on_parts_are_one_line_errors_before_any_output(tmp_path, config_refused, diode_toml, words):
    path = _wing_config(tmp_path, "\n[[diode]]\nfov_deg = 90\n" + diode_toml)
    config_refused(path, words)


def test_diodes_on_a_wing_pass_the_check_and_their_own_wing_leaves_them_checked(tmp_path):
    path = tmp_path / "w.nc"
    rc = main(["run", "--config", str(_wing_config(tmp_path)), "--start", "2016-07-02T00:45:00Z",
               "--duration", "300", "-o", str(path)])
    assert rc == 0                                          # the analytic check passes
    ds = xr.open_dataset(path)
    unchecked = ds["direct_unchecked"].values.astype(bool)
    cos_sun = ds["sun_dir_body"].values @ ds["normal_body"].values.T
    lit = ds["irradiance"].sel(component="direct").values > 0
    for k in (6, 7):
        # Oracle, the geometry: nothing of the spacecraft rises above the top diode's plane (z = 173.25 mm; the
        # wings' tops are at 172.75) and nothing but the body's black box lies below the under diode's plane
        # (z = 170.25 mm, the body's top face), so a part can shade them only where the solar disc (radius
        # 0.27 deg) touches their own horizon, where their own wing cuts it.
        assert np.all(np.abs(cos_sun[unchecked[:, k], k]) < np.sin(np.radians(0.3))), k
        assert lit[:, k].sum() > 10 * unchecked[:, k].sum() + 10, k   # their direct light is checked


def test_the_body_box_shades_a_diode_on_a_wing_as_computed_by_hand(tmp_path):
    # The analytic model's body shadow on a diode off the body (scenes.config.body_side_normal picks the box
    # face plane the diode lies beyond). The "wing under" diode: centre (-10, 150, 170.25) mm, normal -z, a
    # FOV-70 well (opening 5.28 mm, height 0.48 mm; its walls vignette nothing below tan 2.7 off the normal).
    # Oracles by hand, the body box |x|, |y| <= 50 mm, |z| <= 170.25 mm:
    # d ~ (0, 1, -0.5): away from the body: clear (1); d ~ (0, -1, -0.5): meets the +y face at z = 120 mm,
    # wholly shadowed (0); d ~ (-0.4, -1, -0.5): the shadow edge, the face's x = -50 mm side, is the line
    # x + 0.4 (y - 50) = -50 mm on the diode's plane, through the diode's centre: half the square (0.5).
    from simcore.radiometry.analytic import BodyBox
    from simcore.shapes.occlusion import pair_visibility
    cfg = SatelliteConfig.load(_wing_config(tmp_path))
    k = 7
    d = np.array([[0.0, 1.0, -0.5], [0.0, -1.0, -0.5], [-0.4, -1.0, -0.5]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    box = BodyBox.from_config(cfg)
    vis = pair_visibility(cfg.apertures, cfg.frames, box.positions_m, box.panel_normals, [k] * 3, d, box.half_m)
    np.testing.assert_allclose(vis, [1.0, 0.0, 0.5], atol=1e-9)


MOUNT_SHADOW = """name = "mount_shadow"
[[diode]]
name = "bare"
panel = "+z"
normal = [0, 0, 1]
at_mm = [0.0, 0.0]
fov_deg = 90

[[diode]]
name = "tube"
panel = "+z"
normal = [0, 0, 1]
at_mm = [8.0, 0.0]
well = { height_mm = 8.0, opening_mm = [5.0, 5.0] }
"""


def _hits_box(origins, d, lo, hi):
    """Return (N,) bool: whether rays from each of ``origins`` (P, 3) along the unit directions ``d`` (N, 3) meet the
    axis-aligned box [lo, hi] at some t > 0 (slab test, any of the P origins)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo[None, None] - origins[None]) / d[:, None]
        t2 = (hi[None, None] - origins[None]) / d[:, None]
    t_in = np.nanmax(np.minimum(t1, t2), axis=2)
    t_out = np.nanmin(np.maximum(t1, t2), axis=2)
    return ((t_in <= t_out) & (t_out > 0)).any(axis=1)


def test_a_neighbours_mount_shading_a_diode_is_left_out_of_the_direct_check(tmp_path):
    # A bare diode flat at the centre of the +z face (2.65 mm square, surface 114.5 mm above the body's centre)
    # and 8 mm along +x a diode in a well 8 mm tall: its mount, by hand from the TOML (opening 5 mm, walls 0.5 mm,
    # floor 0.5 mm above a 0.5 mm base on the 113.5 mm face), is the box x 5..11, y -3..3, z 113.5..122.5 mm. The
    # analytic model knows the body box and each diode's own well, not a neighbour's mount: the bare diode's
    # direct Sun behind the tube read 0 against ~100 W/m^2 analytic and failed the check (-6329 sigma).
    path = tmp_path / "ms.toml"
    path.write_text(MOUNT_SHADOW)
    run = tmp_path / "ms.nc"
    assert main(["run", "--config", str(path), "--start", "2016-07-02T00:45:00Z", "--duration", "1800",
                 "--step", "5", "-o", str(run)]) == 0                      # the check passes
    ds = xr.open_dataset(run)
    unchecked = ds["direct_unchecked"].values.astype(bool)
    sun = ds["sun_dir_body"].values
    # Oracle, the geometry: rays toward the Sun's centre from the bare diode's corners and centre that meet the
    # tube's box: every such epoch is left out (the Sun is at most 0.27 deg from its centre: also the rim).
    f = np.array([-1.0, 0.0, 1.0]) * 1.3247e-3
    pts = np.array([[x, y, 114.5e-3] for x in f for y in f])
    shaded = _hits_box(pts, sun, np.array([5e-3, -3e-3, 114.5e-3]), np.array([11e-3, 3e-3, 122.5e-3]))
    shaded &= sun[:, 2] > 0
    assert shaded.sum() >= 20                                  # the segment does take the Sun behind the tube
    assert np.all(unchecked[shaded, 0])
    # ...and nothing is left out where the Sun lies on the far side (toward -x: nothing stands there), nor for
    # the diode in the tube (nothing rises above its well's rim)
    assert not unchecked[sun[:, 0] < -0.05, 0].any() and (sun[:, 0] < -0.05).sum() >= 20
    assert not unchecked[:, 1].any()
    # Without leaving them out, the neighbour's shadow (which the analytic model does not know) fails the check.
    _passes_only_with_its_left_out_values(ds, unchecked)
