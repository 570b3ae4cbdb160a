"""Apertures as scene geometry (issue 14 item 2): the diode plug, slits, chamfered rims and round holes, each
traced by the renderer against the closed-form overlap of the diode with the shifted opening(s)."""
import numpy as np
import pytest
import trimesh

from scenes.meshes import build_satellite_mesh
from simcore.pipeline.options import RunOptions
from simcore.pipeline.run import PreparedRun
from simcore.render import DiodeSurfaces, Renderer
from simcore.shapes.aperture import WellAperture
from simcore.studies import aperture as A
from tests.oracles.walls_oracle_4277e88 import ORACLE

AP75 = WellAperture.design(75.0)   # the well of tilt25_fov75 (FOV 75: opening 7.00 mm), the old tracer's cases


def _without_plugs(mesh):
    """Return the satellite mesh without its 'plug_k' parts (the mesh as it was before the plugs)."""
    keep = [n for n in mesh.metadata["parts"] if not n.startswith("plug_")]
    faces = np.concatenate([np.arange(*mesh.metadata["parts"][n]) for n in keep])
    out = trimesh.Trimesh(mesh.vertices, mesh.faces[faces], process=False)
    ranges, start = {}, 0
    for n in keep:
        a, b = mesh.metadata["parts"][n]
        ranges[n], start = (start, start + b - a), start + b - a
    out.metadata["parts"] = ranges
    out.metadata["materials"] = {n: mesh.metadata["materials"][n] for n in keep}
    return out


# ----------------------------------------------------------------------------- step 0: the diode plug

def test_plugs_are_black_and_change_no_all_black_render():
    # The plugs sit 1 um under the diode surfaces (scenes.meshes.PLUG_DEPTH_M), below every path the renderer
    # starts on a diode: with all parts black (no path tracer) nothing it traces can meet them, so the direct
    # and albedo irradiance of a run's chunk must be bit-identical with and without them (same seeds).
    study = PreparedRun(RunOptions(config="tilt20_fov70", start="2016-03-20T12:00:00", duration_s=60.0))
    mesh = build_satellite_mesh(study.config)
    plugs = [n for n in mesh.metadata["parts"] if n.startswith("plug_")]
    assert len(plugs) == study.config.n_diodes and all(mesh.metadata["materials"][n] == "black" for n in plugs)
    with_plugs = study.render_chunk(0, len(study.epochs))
    study = study.with_renderer(Renderer(
        DiodeSurfaces.from_config(study.config), _without_plugs(mesh), reflectivity=study.map.values_south_first,
        lon_west_deg=float(study.map.lon_edges_deg[0]), e_sun_w_m2=study.opts.e_sun_w_m2,
        sun_angular_radius_rad=study.sun_angular_radius_rad))
    without = study.render_chunk(0, len(study.epochs))
    lit = with_plugs["rendered"][..., :2]
    assert (lit[..., 0] > 0).sum() > 100 and (lit[..., 1] > 0).sum() > 100
    for key in ("rendered", "rendered_se", "samples", "direct_plain"):
        np.testing.assert_array_equal(with_plugs[key], without[key], err_msg=key)


def test_the_satellite_mesh_reproduces_the_old_wall_tracer_thanks_to_its_plug():
    # Oracle: the retired wall tracer's numbers (tests/oracles/walls_oracle_4277e88.py, simcore/render/walls.py at
    # 4277e88), which end every path that reaches the diode. The satellite mesh (body, ramp, floor, well, plug)
    # of the one-diode configuration, traced as `sunsim run` traces it, must agree on average: the mean of the
    # n = 80 z-scores within 4 / sqrt(n) (false-alarm rate 6e-5 per case). Without the plug, reflected paths
    # returning onto the diode fall through the floor's hole and come back off its sides: the response reads
    # 0.2-0.7 % high and the mean z lies beyond that bound in both cases (measured +0.58 and +0.88 with these
    # seeds).
    for case, material in [("series rho 0.9", {"type": "diffuse", "reflectance": 0.9}),
                           ("cut bare Al (alpha 0.2) phi 0", A.BARE_AL)]:
        c = ORACLE[case]
        assert c["reflective_floor"]                        # the record's floor plate reflects, as the mount's
        cfg = A.well_config(AP75, material)
        d = A.cut_directions(c["theta_deg"], c["phi_deg"])
        mesh = build_satellite_mesh(cfg)
        for m, plugged in [(mesh, True), (_without_plugs(mesh), False)]:
            r = Renderer(DiodeSurfaces.from_config(cfg), m, e_sun_w_m2=1.0, max_depth=64)
            res = r.render(d @ r.diodes.frames[0], None, direct_samples=1024, albedo=False, seed=13,
                           reflected_samples=65536)
            resp = res.direct_w_m2[:, 0] + res.reflected_w_m2[:, 0]
            se = np.hypot(np.hypot(res.direct_se_w_m2[:, 0], res.reflected_se_w_m2[:, 0]), c["response_se"])
            z = ((resp - np.asarray(c["response"])) / se)[se > 0]
            assert z.size == 80
            assert (abs(z.mean()) < 4.0 / np.sqrt(z.size)) == plugged, (case, plugged, z.mean())


# ----------------------------------------------------------------------------- step 1: chamfered rims and slits

# A hand-made chamfered well (mm): a 2 x 2 diode under a 3 x 3 opening, 1 high, its top 0.5 bevelled outward.
# Lower rim: half opening 1.5 at z = 0.5; top rim: half opening w' = 1.5 + 0.5 tan(alpha) at z = 1.
MM = 1e-3


def _hand_well(alpha_deg):
    return WellAperture(2 * MM, 2 * MM, 3 * MM, 3 * MM, 1 * MM, 0.5 * MM, alpha_deg)


def _along(tan_u, tan_v=0.0):
    """Return the unit direction (1, 3) with d_u / d_n = tan_u and d_v / d_n = tan_v."""
    d = np.array([[tan_u, tan_v, 1.0]])
    return d / np.linalg.norm(d)


# (alpha, tan(theta) along u, along v, lit fraction), worked by hand: the lit x-range of the diode [-1, 1] is
# [max(-1, -1.5 - 0.5 t, -w' - t), min(1, 1.5 - 0.5 t, w' - t)], and alike in y.
CHAMFER_CASES = [
    (45.0, 0.5, 0.0, 1.0),      # w' = 2: hi = min(1, 1.25, 1.5) = 1, fully lit
    (45.0, 1.5, 0.0, 0.75),     # hi = min(1, 0.75, 0.5) = 0.5, the top rim binds: (0.5 + 1) / 2
    (45.0, 2.0, 0.0, 0.5),      # hi = min(1, 0.5, 0) = 0
    (45.0, 3.0, 0.0, 0.0),      # hi = min(1, 0, -1) = -1 = lo: dark
    (45.0, 1.5, 1.5, 0.5625),   # 0.75 along both axes
    (45.0, -1.5, 0.0, 0.75),    # the mirror image
    (80.0, 2.0, 0.0, 0.75),     # w' = 1.5 + 0.5 x 5.6713 = 4.3356: hi = min(1, 0.5, 2.3356) = 0.5, the lower rim
    (80.0, 4.0, 0.0, 0.25),     # hi = min(1, -0.5, 0.3356) = -0.5, the lower rim: (-0.5 + 1) / 2
    (0.0, 1.5, 0.0, 0.5),       # no bevel: straight walls 1 high, hi = min(1, 0.75, 1.5 - 1.5) = 0
]


@pytest.mark.parametrize("alpha, tu, tv, expected", CHAMFER_CASES)
def test_chamfered_well_lit_fraction_hand_cases(alpha, tu, tv, expected):
    from simcore.radiometry import response as R
    from simcore.shapes.occlusion import lit_fraction_with_box
    ap = _hand_well(alpha)
    d = _along(tu, tv)
    assert ap.lit_fraction(d)[0] == pytest.approx(expected, abs=1e-12)
    # the analytic albedo sum's kernel form (lit fraction x cos) and the direct reference's body clipping (the
    # box 1 m below the diode: no shadow) share the two-rim geometry
    assert R.kernel(ap)(d[:, 0], d[:, 1], d[:, 2], R.NUMPY_OPS)[0] == pytest.approx(expected * d[0, 2], abs=1e-12)
    assert lit_fraction_with_box(ap, np.eye(3), [0.0, 0.0, 1.0], d[0], [MM, MM, MM]) == pytest.approx(expected,
                                                                                                       abs=1e-12)


def test_chamfered_well_body_clipping_matches_point_casting():
    # Oracle: a 400 x 400 grid of points on the diode, each lit when its ray passes inside both rims and misses
    # the box (slab test): the clipped area to the grid's resolution (a cell row along each edge: 4 / 400).
    from simcore.shapes.occlusion import lit_fraction_with_box
    ap = _hand_well(45.0)
    half_box = np.array([5.0, 5.0, 5.0]) * MM
    pos = np.array([0.0, 7.0 * MM, 3.5 * MM])     # the diode 2 mm beside the box's +y face, facing +z
    n_grid = 400
    g = ((np.arange(n_grid) + 0.5) / n_grid - 0.5) * 2 * MM
    X, Y = np.meshgrid(g, g, indexing="ij")
    for tu, tv in [(1.2, -1.0), (0.3, -1.5), (-1.0, -0.8)]:
        d = _along(tu, tv)[0]
        inside = np.ones(X.shape, bool)
        for half, z in [(1.5 * MM, 0.5 * MM), (2.0 * MM, 1.0 * MM)]:
            inside &= (np.abs(X + z * d[0] / d[2]) <= half) & (np.abs(Y + z * d[1] / d[2]) <= half)
        o = pos + np.stack([X, Y, np.zeros_like(X)], -1)
        with np.errstate(divide="ignore"):
            t1, t2 = (-half_box - o) / d, (half_box - o) / d
        hit = np.maximum(t1, t2).min(-1) >= np.maximum(np.minimum(t1, t2).max(-1), 0.0)
        expected = np.mean(inside & ~hit)
        got = lit_fraction_with_box(ap, np.eye(3), pos, d, half_box)
        assert 0.02 < got < ap.lit_fraction(d[None])[0] - 0.02, (tu, tv)      # the box shades part of it
        assert got == pytest.approx(expected, abs=4.0 / n_grid)


AP70 = WellAperture.design(70.0)     # FOV 70: opening 5.28 mm, height 0.48 mm (scenes/FORMAT.md)
# its top 0.3 mm bevelled at 45 deg: the top rim 5.88 mm wide (0.3 mm into each 0.5 mm wall)
CHAMFER70 = WellAperture(AP70.diode_x_m, AP70.diode_y_m, AP70.opening_x_m, AP70.opening_y_m, AP70.height_m,
                         0.3 * MM, 45.0)


def _grid(thetas, phis):
    t, p = np.meshgrid(thetas, phis, indexing="ij")
    return A.cut_directions(t.ravel(), p.ravel())


def _z(resp, exact, se):
    partial = se > 0
    return np.abs(resp - exact)[partial] / se[partial], partial


def test_traced_chamfered_well_is_the_two_rim_overlap():
    # Oracle: the closed-form two-rim overlap (hand-checked above); the renderer traces the bevelled wall mesh of
    # scenes.meshes through a configuration (well = {..., chamfer_mm = 0.3, chamfer_deg = 45}), sampling the whole
    # diode (no aperture hint). Each partly lit direction within 3 SE (two-sided false-alarm rate 0.27 % each; with
    # the fixed seed the outcome is reproducible).
    d = _grid(np.arange(66.0, 90.0, 1.5), [0.0, 30.0, 45.0])
    resp, se = A.traced_black_response(CHAMFER70, d, samples=16384, seed=4)
    exact = CHAMFER70.response(d)
    z, partial = _z(resp, exact, se)
    assert partial.sum() >= 15 and np.all(z < 3.0), z
    assert np.allclose(resp[~partial], exact[~partial], atol=2e-6)
    # the bevel lets in more light than the straight well at these angles: the test can tell them apart
    assert np.max(np.abs(CHAMFER70.response(d) - AP70.response(d))) > 0.02
    # negative: the closed form of a bevel at 30 deg (top rim 5.63 mm) is far from what the 45 deg mesh reads
    wrong = WellAperture(*[getattr(CHAMFER70, f) for f in ("diode_x_m", "diode_y_m", "opening_x_m", "opening_y_m",
                                                           "height_m", "chamfer_m")], 30.0)
    assert np.max(_z(resp, wrong.response(d), se)[0]) > 5.0
    # the renderer's aperture split (hint) uses the same two rims: no noise where the mesh is the analytic well
    hinted, hinted_se = A.traced_black_response(CHAMFER70, d, samples=1024, seed=4, control_variate=True)
    assert np.allclose(hinted, exact, atol=2e-6) and np.all(hinted_se == 0.0)


def test_traced_slit_is_the_rectangle_overlap():
    # A slit: a rectangular well of unequal sides (3.0 x 8.0 mm, 1.0 mm high over the 2.65 mm BPW34). Oracle:
    # WellAperture.response (closed form), traced through the configuration and its meshes, within 3 SE.
    slit = A.well_config(WellAperture(AP70.diode_x_m, AP70.diode_y_m, 3.0 * MM, 8.0 * MM, 1.0 * MM)).diodes[0].aperture
    assert (slit.opening_x_m, slit.opening_y_m) == (3.0 * MM, 8.0 * MM)
    d = _grid([10.0, 25.0, 40.0, 55.0, 70.0], [0.0, 45.0, 90.0])
    resp, se = A.traced_black_response(slit, d, samples=16384, seed=6)
    exact = slit.response(d)
    z, partial = _z(resp, exact, se)
    assert partial.sum() >= 8 and np.all(z < 3.0), z
    assert np.allclose(resp[~partial], exact[~partial], atol=2e-6)
    # across the slit (phi 0) it cuts off at atan((1.5 + 1.325) / 1) = 70.5 deg, along it (phi 90) it reaches
    # atan((4 + 1.325) / 1) = 79.4 deg: at 70 deg the slit is dark or nearly so across and half lit along
    th70 = np.isclose(np.degrees(np.arccos(d[:, 2])), 70.0)
    assert exact[th70 & np.isclose(d[:, 1], 0.0)][0] < 0.01 < exact[th70 & np.isclose(d[:, 0], 0.0, atol=1e-9)][0]


def test_chamfer_and_slit_configuration_keys():
    from scenes.config import ConfigError, SatelliteConfig

    def load(well, mount=None):
        return SatelliteConfig.from_dict({"name": "t", "mount": mount or {}, "diode": [
            {"name": "a", "panel": "+z", "normal": [0.0, 0.0, 1.0], "at_mm": [0.0, 0.0], "well": well}]})

    ap = load({"height_mm": 0.6, "opening_mm": [5.0, 5.0], "chamfer_mm": 0.3, "chamfer_deg": 45}).diodes[0].aperture
    assert (ap.chamfer_m, ap.chamfer_deg) == (0.3 * MM, 45.0)
    assert ap.rims[5] == pytest.approx(2.5 * MM + 0.3 * MM) and ap.rims[4] == pytest.approx(0.3 * MM)
    with pytest.raises(ConfigError, match="chamfer widens the opening by 0.520 mm.*wall_mm"):   # 0.3 tan 60
        load({"height_mm": 0.6, "opening_mm": [5.0, 5.0], "chamfer_mm": 0.3, "chamfer_deg": 60})
    with pytest.raises(ConfigError, match="did you mean 'chamfer_deg'"):
        load({"height_mm": 0.6, "opening_mm": [5.0, 5.0], "chamfer_mm": 0.3, "chamfer_dg": 45})
    with pytest.raises(ConfigError, match="chamfer"):
        load({"height_mm": 0.6, "opening_mm": [5.0, 5.0], "chamfer_mm": 0.8, "chamfer_deg": 10})
    with pytest.raises(ConfigError, match="at least as large as the diode"):           # a slit under 2.65 mm
        load({"height_mm": 1.0, "opening_mm": [1.0, 6.0]})


# ----------------------------------------------------------------------------- step 2: round holes

def _round_cfg(well, normal=(0.0, 0.0, 1.0), panel="+z"):
    from scenes.config import SatelliteConfig
    return SatelliteConfig.from_dict({"name": "t", "diode": [
        {"name": "a", "panel": panel, "normal": list(normal), "at_mm": [0.0, 0.0], "well": well}]})


ROUND = {"shape": "round", "diameter_mm": 4.4, "height_mm": 1.5}


def test_round_well_configuration_and_mesh():
    from scenes.config import ConfigError
    from scenes.meshes import ROUND_SIDES, build_parts
    from simcore.shapes.aperture import CircularWell
    cfg = _round_cfg(ROUND)
    ap = cfg.diodes[0].aperture
    assert isinstance(ap, CircularWell) and (ap.radius_m, ap.height_m) == (2.2 * MM, 1.5 * MM)
    # fully lit along u while the shifted circle holds the far corners: atan((sqrt(2.2^2 - 1.3248^2) - 1.3248) / 1.5)
    a = AP70.diode_x_m / 2 / MM
    assert cfg.diodes[0].fov_deg == pytest.approx(np.degrees(np.arctan((np.sqrt(2.2 ** 2 - a * a) - a) / 1.5)))
    well = build_parts(cfg)["well_0"]
    assert well.is_watertight and well.is_winding_consistent and len(well.faces) == 8 * ROUND_SIDES
    # a tube of the circles' areas: pi (r_out^2 - r_in^2) h, r_out = r + wall (0.5 mm)
    assert well.volume == pytest.approx(np.pi * ((2.7 * MM) ** 2 - (2.2 * MM) ** 2) * 1.5 * MM, rel=1e-9)
    for bad, msg in [({**ROUND, "diameter_mm": 3.0}, "must reach the diode's corners"),
                     ({**ROUND, "opening_mm": [5.0, 5.0]}, "a round well takes shape, height_mm, diameter_mm"),
                     ({"shape": "round", "diameter_mm": 4.4}, "needs height_mm"),
                     ({**ROUND, "shape": "hexagon"}, "shape is \"square\""),
                     ({**ROUND, "diametre_mm": 4.4}, "did you mean 'diameter_mm'")]:
        with pytest.raises(ConfigError, match=msg):
            _round_cfg(bad)


def test_traced_round_hole_is_the_closed_form_disc_overlap():
    # Issue 14's acceptance line: a circular hole over a diode, traced (the configuration's 1024-gon tube, plain
    # sampling of the diode: the renderer knows only the mesh) = the closed-form overlap of the diode with the
    # shifted circle (CircularWell, itself checked against quadrature in tests/shapes/test_aperture.py) within 3 SE at
    # each partly lit direction (false-alarm rate 0.27 % each, fixed seed); a hole 3 % wider is far off.
    from simcore.shapes.aperture import CircularWell
    cw = _round_cfg(ROUND).diodes[0].aperture
    d = _grid([5.0, 15.0, 25.0, 35.0, 45.0, 55.0, 62.0], [0.0, 20.0, 45.0])
    resp, se = A.traced_black_response(cw, d, samples=16384, seed=8)
    exact = cw.response(d)
    z, partial = _z(resp, exact, se)
    assert partial.sum() >= 15 and np.all(z < 3.0), z
    assert np.allclose(resp[~partial], exact[~partial], atol=2e-6)
    wider = CircularWell(cw.diode_x_m, cw.diode_y_m, 1.03 * cw.radius_m, cw.height_m)
    assert np.median(_z(resp, wider.response(d), se)[0]) > 5.0


def test_round_hole_control_variate_is_exact_for_its_well_and_unbiased_for_another():
    # The renderer's hint for a round well (Renderer._round_cv): with the well it describes, every lane reads the
    # closed form: the point-Sun response to float32, its standard error float32 rounding (< 1e-9). With a mesh
    # 3 % wider than the well it was told of, it must still read the mesh (unbiased: the wider hole's closed form
    # within 3 SE, false-alarm rate 0.27 % each, fixed seed), not the hint.
    from scenes.meshes import build_satellite_mesh
    from simcore.shapes.aperture import CircularWell
    cfg = _round_cfg(ROUND)
    cw = cfg.diodes[0].aperture
    d = _grid([5.0, 15.0, 25.0, 35.0, 45.0, 55.0, 62.0], [0.0, 20.0, 45.0])
    resp, se = A.traced_black_response(cw, d, samples=1024, seed=9, control_variate=True)
    assert np.allclose(resp, cw.response(d), rtol=1e-5, atol=2e-6) and np.all(se < 1e-9)
    wide_cfg = _round_cfg({**ROUND, "diameter_mm": 4.4 * 1.03})
    told = DiodeSurfaces(*(getattr(DiodeSurfaces.from_config(cfg), f) for f in ("positions_m", "frames", "sizes_m")),
                         (cw,))
    r = Renderer(told, build_satellite_mesh(wide_cfg), e_sun_w_m2=1.0)
    res = r.render(d @ cfg.frames[0], None, direct_samples=16384, albedo=False, seed=9)
    got, got_se = res.direct_w_m2[:, 0], res.direct_se_w_m2[:, 0]
    wide = CircularWell(cw.diode_x_m, cw.diode_y_m, 1.03 * cw.radius_m, cw.height_m).response(d)
    z, partial = _z(got, wide, got_se)
    assert partial.sum() >= 10 and np.all(z < 3.0), z
    assert np.max(np.abs(got - cw.response(d))) > 0.01


def test_round_hole_albedo_kernel_matches_numpy():
    # The analytic albedo sum through the Dr.Jit kernel form of the disc overlap (CircularWell.kernel, one formula
    # with the numpy closed form) equals the numpy backend (CircularWell.response) to float32 precision.
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.shapes.aperture import CircularWell
    cw = CircularWell(AP70.diode_x_m, AP70.diode_y_m, 2.2 * MM, 1.5 * MM)
    r_sat = np.array([[7.0e6, 0.0, 0.0], [0.0, 6.9e6, 1.0e6]])
    r_sun = np.array([[1.5e11, 0.0, 0.0], [1.0e11, 1.0e11, 0.0]])
    tilt = np.radians(50.0)        # looking 50 deg from nadir: the Earth's disc fills part of the well's view
    frames = np.array([[[0, 1, 0], [np.sin(tilt), 0, np.cos(tilt)], [-np.cos(tilt), 0, np.sin(tilt)]]], float)
    kw = dict(direct=False, precision="double")
    num = diode_irradiance(r_sat, r_sun, np.eye(3), frames, [cw], backend="numpy", **kw).albedo_w_m2
    drj = diode_irradiance(r_sat, r_sun, np.eye(3), frames, [cw], backend="drjit", **kw).albedo_w_m2
    assert np.all(num > 1.0)
    np.testing.assert_allclose(drj, num, rtol=1e-9)
    # and the kernel itself against the closed form on random directions, float64 numpy ops
    from simcore.radiometry import response as R
    dd = np.random.default_rng(2).normal(size=(2000, 3))
    dd /= np.linalg.norm(dd, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        k = R.kernel(cw)(dd[:, 0], dd[:, 1], dd[:, 2], R.NUMPY_OPS)
    np.testing.assert_allclose(k, cw.response(dd), atol=1e-12)


def test_round_wells_example_runs_and_passes_the_check(tmp_path):
    # The shipped example (scenes/examples/round_wells.toml): a sunlit 10 min, rendered and checked against the
    # analytic model (disc overlap; the tilted diodes' direct Sun left out where the body box may shade them).
    # The check's tests each have a false-alarm rate of 1e-3 (simcore.pipeline.check); fixed seed.
    from pathlib import Path
    from simcore.cli import main
    example = Path(__file__).resolve().parents[2] / "scenes" / "examples" / "round_wells.toml"
    out = tmp_path / "round.nc"
    assert main(["run", "--config", str(example), "--start", "2016-03-20T12:00:00", "--duration", "600",
                 "-o", str(out)]) == 0
    assert main(["validate", str(out)]) == 0
    import xarray as xr
    with xr.open_dataset(out) as ds:
        unchecked = ds["direct_unchecked"].values.astype(bool)
        assert unchecked.any() and not unchecked[:, [2, 4, 5]].any()     # only the tilted diodes (0, 1, 3)


def test_chamfered_and_slit_wells_run_and_pass_the_check(tmp_path):
    # Chamfered rims and slits, one per face, through `sunsim run` (a sunlit 10 min) and `sunsim validate`: the
    # analytic model's two-rim overlap, the renderer's hint and the body clipping share WellAperture.rims. Each
    # of the check's tests has a false-alarm rate of 1e-3 (simcore.pipeline.check); fixed seed.
    from simcore.cli import main
    wells = ["{ height_mm = 0.6, opening_mm = [5.0, 5.0], chamfer_mm = 0.3, chamfer_deg = 45 }",
             "{ height_mm = 1.0, opening_mm = [3.0, 8.0], chamfer_mm = 0.4, chamfer_deg = 30 }",
             "{ height_mm = 1.0, opening_mm = [8.0, 3.0] }",
             "{ height_mm = 0.5, opening_mm = [4.0, 6.0], chamfer_mm = 0.5, chamfer_deg = 20 }",
             "{ height_mm = 0.6, opening_mm = [5.0, 5.0], chamfer_mm = 0.6, chamfer_deg = 35 }",
             "{ height_mm = 0.48, opening_mm = [5.28, 5.28] }"]
    faces = [("+x", [1, 0, 0]), ("-x", [-1, 0, 0]), ("+y", [0, 1, 0]), ("-y", [0, -1, 0]), ("+z", [0, 0, 1]),
             ("-z", [0, 0, -1])]
    text = 'name = "faces6_chamfer"\n' + "".join(
        f'[[diode]]\nname = "{p}"\npanel = "{p}"\nnormal = {n}\nat_mm = [0.0, 0.0]\nwell = {w}\n'
        for (p, n), w in zip(faces, wells))
    (tmp_path / "chamfer6.toml").write_text(text)
    out = tmp_path / "run.nc"
    assert main(["run", "--config", str(tmp_path / "chamfer6.toml"), "--start", "2016-03-20T12:00:00",
                 "--duration", "600", "-o", str(out)]) == 0
    assert main(["validate", str(out)]) == 0
