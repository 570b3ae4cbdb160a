"""Tests of scenes.satellite.Satellite (one configuration, its views built once) and Renderer.from_scene."""
import numpy as np
import pytest

from scenes.config import SatelliteConfig
from scenes.meshes import build_parts, build_satellite_mesh
from scenes.satellite import BodyBox, DiodeSurfaces, Satellite
from simcore.constants import R_EARTH_MEAN_M
from simcore.environment.earth import Earth
from simcore.environment.maps import ReflectivityMap
from simcore.radiometry.glint import SunGlint
from simcore.picture.scene import build_scene


@pytest.fixture(scope="module")
def sat():
    return Satellite.load("tilt20_fov70")


def test_diodes_are_the_configurations_and_built_once(sat):
    cfg = sat.config
    ds = sat.diodes
    assert ds is sat.diodes                                  # cached
    assert ds.count == cfg.n_diodes == 14
    np.testing.assert_array_equal(ds.positions_m, np.asarray(cfg.positions_m))
    np.testing.assert_array_equal(ds.frames, np.asarray(cfg.frames))
    np.testing.assert_array_equal(ds.sizes_m, [[d.aperture.diode_x_m, d.aperture.diode_y_m] for d in cfg.diodes])
    assert ds.apertures == tuple(d.aperture for d in cfg.diodes)


def test_the_renderer_and_the_analytic_model_name_the_data_layer_classes():
    from simcore.radiometry import analytic
    import simcore.render as render_pkg
    assert render_pkg.DiodeSurfaces is DiodeSurfaces
    assert analytic.BodyBox is BodyBox


def test_body_box_is_the_body_and_each_diode_lies_beyond_its_panel(sat):
    box = sat.body_box
    assert box is sat.body_box
    assert box.half_m == tuple(float(s) / 2 for s in sat.config.body.size_m)
    for p, n in zip(box.positions_m, box.panel_normals):
        axis = int(np.argmax(np.abs(n)))
        assert abs(n[axis]) == 1.0 and np.count_nonzero(n) == 1          # an outward face normal of the box
        assert p[axis] * n[axis] >= box.half_m[axis]                     # the diode sits outside that face


def test_no_body_gives_no_box():
    cfg = SatelliteConfig.from_dict({"name": "bare", "body": {"none": True},
                                     "diode": [{"panel": "+z", "az_deg": 0.0, "el_deg": 50.0, "fov_deg": 90}]})
    assert Satellite(cfg).body_box is None


def test_mesh_holds_every_part_once(sat):
    mesh = sat.mesh
    assert mesh is sat.mesh and sat.parts is sat.parts
    parts = build_parts(sat.config)
    assert len(mesh.faces) == sum(len(p.faces) for p in parts.values())
    assert set(mesh.metadata["parts"]) == set(parts)
    with pytest.raises(TypeError, match="SatelliteConfig"):
        Satellite("tilt20_fov70")


def test_picture_scene_takes_the_satellite_and_an_earth(sat):
    m = ReflectivityMap.from_array(np.full((18, 36), 0.25), radius_m=6.3e6)
    scene, names, kinds, _ = build_scene(sat, resolution=(4, 4), spp=1, earth=Earth(m))
    assert scene["earth"]["radius"] == 6.3e6
    assert {f"diode_{k}" for k in range(14)} <= set(names) and "body" in kinds
    assert sat.display_parts is sat.display_parts and set(names) == {"earth"} | set(sat.display_parts)
    with pytest.raises(TypeError, match="Earth"):
        build_scene(sat, resolution=(4, 4), spp=1, earth=m)      # a map is not an Earth: one way to give it


def _rotations(n, seed):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


def test_from_scene_renders_bit_identically_to_the_hand_assembly(sat):
    from simcore.render import Renderer
    rng = np.random.default_rng(3)
    # a north-first map whose column 0 starts at 175 W, with a glint on a sea given in the map's own row order
    lat = np.arange(89.5, -90.0, -1.0)
    lon = -175.0 + (np.arange(288) + 0.5) * 1.25
    refl = rng.uniform(0.0, 0.8, (180, 288))
    sea = rng.uniform(0.0, 1.0, (180, 288))
    earth = Earth(ReflectivityMap.from_array(refl, lat, lon), SunGlint(6.0, sea=sea))
    hand = Renderer(DiodeSurfaces.from_config(sat.config), build_satellite_mesh(sat.config),
                    reflectivity=refl[::-1], lon_west_deg=-175.0, earth_radius_m=R_EARTH_MEAN_M, e_sun_w_m2=1361.0,
                    glint=SunGlint(6.0, sea=sea[::-1]))
    built = Renderer.from_scene(sat, earth, e_sun_w_m2=1361.0)
    rot = _rotations(3, 5)
    nadir = rng.normal(size=(3, 3))
    nadir /= np.linalg.norm(nadir, axis=1, keepdims=True)
    sun = -0.3 * nadir + rng.normal(size=(3, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    args = (sun, nadir * (R_EARTH_MEAN_M + 650e3), rot)
    kw = dict(seed=4, direct_samples=256, albedo_samples=256)
    a, b = hand.render(*args, **kw), built.render(*args, **kw)
    assert np.nanmax(a.albedo_w_m2) > 0
    for name in ("direct_w_m2", "direct_se_w_m2", "albedo_w_m2", "albedo_se_w_m2"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_from_scene_diodes_picks_the_lit_diodes_and_keeps_the_mesh(sat):
    from simcore.render import Renderer, render
    one = Renderer.from_scene(sat, diodes=[3], e_sun_w_m2=1.0)
    assert one.diodes.count == 1
    np.testing.assert_array_equal(one.diodes.positions_m[0], sat.config.positions_m[3])
    n = sat.config.frames[3][2]
    res = one.render(n[None], None, direct_samples=256, albedo=False, seed=1)
    assert res.direct_w_m2[0, 0] == pytest.approx(1.0, rel=1e-6)        # normal incidence, nothing in the way
    whole = render(sat, None, n[None], direct_samples=256, albedo=False, seed=1, e_sun_w_m2=1.0)
    assert whole.direct_w_m2[0, 3] == pytest.approx(1.0, rel=1e-6)
