"""Issue 13: the path-traced ``reflected`` component of simcore.render (simcore.render.reflected) against independent oracles.

Every Monte-Carlo assertion is a z-test |estimate - oracle| < 3.3 standard errors (the renderer's own
standard error from its pairs of samples per stratum): a false-alarm rate of 1e-3 per value for a normal
estimate; the file makes 23 such assertions, so by Bonferroni a correct renderer fails it with probability
< 2.3 %, and never with the fixed seeds used here (the results are bitwise reproducible). Each geometry has
a parametrised negative case: the same rendering compared with the oracle of a deliberately wrong input
(mirror edge, complex index, reflectance) must be rejected (|z| > 3.3), so the tests can fail.
"""
import numpy as np
import pytest
import trimesh
from scipy.integrate import quad

from scenes.config import SatelliteConfig
from scenes.meshes import build_satellite_mesh
from simcore.constants import R_EARTH_MEAN_M
from simcore.render import SUN_ANGULAR_RADIUS_RAD, DiodeSurfaces, Renderer

R = R_EARTH_MEAN_M
E = 1000.0                       # W/m^2: any value; the oracles scale with it
Z_MAX = 3.3                      # two-sided normal false-alarm rate 1e-3 per value


def _diode(side_m, normal_frame=np.eye(3)):
    """One square diode at the origin, frame rows (u, v, n) = ``normal_frame``."""
    return DiodeSurfaces(np.zeros((1, 3)), np.asarray(normal_frame, float)[None], [[side_m, side_m]])


def _quad(verts, material):
    m = trimesh.Trimesh(np.asarray(verts, float), [[0, 1, 2], [0, 2, 3]], process=False)
    m.metadata["material"] = material
    return m


def _z(res, expected):
    return (res.reflected_w_m2[0, 0] - expected) / res.reflected_se_w_m2[0, 0]


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor N = eta + i k from vacuum at incidence cos_i: the mean
    of |r_s|^2 and |r_p|^2 of the complex Fresnel equations (Born & Wolf, Principles of Optics, sec. 14.2)."""
    n2 = complex(eta, k) ** 2
    root = np.sqrt(n2 - (1 - cos_i * cos_i))
    rs = (cos_i - root) / (cos_i + root)
    rp = (n2 * cos_i - root) / (n2 * cos_i + root)
    return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)


def plate_corner_view_factor(a, b, c):
    """View factor from a differential plane element to a parallel a x b rectangle at distance c whose corner
    lies on the element's normal (Howell, A Catalog of Radiation Heat Transfer Configuration Factors,
    B-3; Siegel & Howell, Thermal Radiation Heat Transfer, app. C)."""
    A, B = a / c, b / c
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


# ------------------------------------------------------------------------------------------ mirror
# A vertical mirror plate in the plane x = X0 facing the diode (normal -x), y in [-1, 1] m, from height z_lo
# up to 1 m; a diode (10 mm square, frame = body axes) at the origin facing +z; the Sun at s with s_x < 0 so
# that it lights the mirror's face. The diode sees the Sun's image along s' = (-s_x, s_y, s_z) (s mirrored in
# the plane), through the mirror for the points (p_x, p_y) whose ray along s' meets the plate above z_lo:
# (X0 - p_x) s'_z / s'_x >= z_lo, i.e. p_x <= X0 - z_lo s'_x / s'_z. The irradiance of a uniform disc of
# total normal irradiance E is E cos(n, s') (the disc entirely above the horizon), so
#   reflected = E cos(n, s') x F(cos_i) x (lit share of the diode),  F = 1 for a perfect mirror.
X0, SIDE = 0.05, 0.01
SUN = np.array([-0.6, 0.0, 0.8])
IMAGE = SUN * [-1, 1, 1]


def _mirror_case(z_lo, material, variant):
    v = [[X0, -1.0, z_lo], [X0, -1.0, 1.0], [X0, 1.0, 1.0], [X0, 1.0, z_lo]]
    rend = Renderer(_diode(SIDE), _quad(v, material), e_sun_w_m2=E, sun_angular_radius_rad=SUN_ANGULAR_RADIUS_RAD,
                    variant=variant)
    return rend.render(SUN[None], seed=21, reflected_samples=4096)


def _lit_share(z_lo):
    cut = X0 - z_lo * IMAGE[0] / IMAGE[2]
    return float(np.clip((cut + SIDE / 2) / SIDE, 0.0, 1.0))


@pytest.mark.parametrize("z_lo, oracle_z_lo, agrees", [
    (0.0, 0.0, True),                                   # the whole diode sees the Sun's image
    (X0 * IMAGE[2] / IMAGE[0], X0 * IMAGE[2] / IMAGE[0], True),    # the edge's image cuts the diode in half
    (X0 * IMAGE[2] / IMAGE[0] + 0.002, X0 * IMAGE[2] / IMAGE[0] + 0.002, True),  # a quarter-ish share
    (X0 * IMAGE[2] / IMAGE[0], 0.0, False),             # negative: the oracle with the wrong mirror edge
])
def test_perfect_mirror_reflects_the_suns_image(z_lo, oracle_z_lo, agrees, variant):
    res = _mirror_case(z_lo, "mirror", variant=variant)
    expected = E * IMAGE[2] * _lit_share(oracle_z_lo)   # cos(n, s') = s'_z for n = +z
    assert 0.0 < _lit_share(z_lo) <= 1.0
    z = _z(res, expected)
    assert (abs(z) < Z_MAX) == agrees, (res.reflected_w_m2, res.reflected_se_w_m2, expected, z)
    # the mirror sits on the far side from the Sun: the direct Sun is untouched, E cos(n, s) (an exact
    # identity for a uniform disc wholly above the horizon; Monte Carlo over the disc)
    assert abs(res.direct_w_m2[0, 0] - E * SUN[2]) < Z_MAX * res.direct_se_w_m2[0, 0] + 1e-6 * E


@pytest.mark.parametrize("eta, k, oracle_k, agrees", [
    (1.2, 7.0, 7.0, True),
    (1.2, 7.0, 4.0, False),                             # negative: the oracle with the wrong extinction index
])
def test_smooth_conductor_reflects_its_fresnel_share(eta, k, oracle_k, agrees, variant):
    mat = {"type": "conductor", "eta": {"type": "uniform", "value": eta}, "k": {"type": "uniform", "value": k}}
    res = _mirror_case(0.0, mat, variant=variant)
    cos_i = -SUN[0]                                     # angle between the Sun and the mirror's normal (-x)
    expected = E * IMAGE[2] * fresnel_conductor(cos_i, eta, oracle_k)
    z = _z(res, expected)
    assert (abs(z) < Z_MAX) == agrees, (res.reflected_w_m2, res.reflected_se_w_m2, expected, z)


# ------------------------------------------------------------------------------------------ energy
# A Lambertian plate 2a x 2b at height H, parallel to a 1 mm diode facing +z, the Sun from below at angle
# theta to the plate's normal lighting its underside: the plate's radiance is rho E cos(theta) / pi and the
# diode reads rho E cos(theta) x F with F the view factor of the centred rectangle (four corner rectangles,
# plate_corner_view_factor). The diode's finite size changes F by O((1 mm / H)^2) = 4e-4 relative.
H, HA, HB = 0.05, 0.04, 0.03
SUN_BELOW = np.array([0.3, 0.0, -0.95]) / np.linalg.norm([0.3, 0.0, -0.95])


def _plate_case(rho, variant):
    v = [[-HA, -HB, H], [HA, -HB, H], [HA, HB, H], [-HA, HB, H]]
    mat = {"type": "diffuse", "reflectance": {"type": "uniform", "value": rho}}
    rend = Renderer(_diode(0.001), _quad(v, mat), e_sun_w_m2=E, variant=variant)
    return rend.render(SUN_BELOW[None], seed=5 + int(round(100 * rho)), reflected_samples=16384)   # independent per rho


def _plate_oracle(rho):
    return rho * E * (-SUN_BELOW[2]) * 4 * plate_corner_view_factor(HA, HB, H)


def test_view_factor_formula_against_direct_integration():
    # the catalogue formula against a 2-D quadrature of cos^2 / (pi r^2) over the corner rectangle
    val, _ = quad(lambda x: quad(lambda y: H * H / (np.pi * (x * x + y * y + H * H) ** 2), 0, HB)[0], 0, HA)
    assert plate_corner_view_factor(HA, HB, H) == pytest.approx(val, rel=1e-9)


@pytest.mark.parametrize("rho, oracle_rho, agrees", [
    (0.1, 0.1, True), (0.3, 0.3, True), (0.6, 0.6, True),
    (0.3, 0.33, False),                                 # negative: the oracle 10 % off in reflectance
])
def test_diffuse_plate_reflects_rho_e_cos_times_view_factor(rho, oracle_rho, agrees, variant):
    res = _plate_case(rho, variant=variant)
    z = _z(res, _plate_oracle(oracle_rho))
    assert (abs(z) < Z_MAX) == agrees, (res.reflected_w_m2, res.reflected_se_w_m2, _plate_oracle(oracle_rho), z)
    assert res.direct_w_m2[0, 0] == 0.0                 # the Sun is below the diode's horizon


def test_reflected_grows_with_reflectance(variant):
    vals = [_plate_case(rho, variant=variant) for rho in (0.1, 0.3, 0.6)]
    for lo, hi in zip(vals[:-1], vals[1:]):
        diff = hi.reflected_w_m2[0, 0] - lo.reflected_w_m2[0, 0]
        se = np.hypot(hi.reflected_se_w_m2[0, 0], lo.reflected_se_w_m2[0, 0])
        assert diff > Z_MAX * se, (diff, se)


def _nadir_plate_quadrature(h_m, rho, e_sun):
    """Irradiance (W/m^2) on a plate facing nadir at altitude h above a uniform Lambertian Earth of
    reflectance rho with the Sun at the zenith: 2 rho E R^2 int mu (H mu - R)(H - R mu) / d^4 dmu over the
    visible cap (tests/render/test_renderer.py's oracle, quoted there as 329.57 W/m^2 for 700 km, rho 0.3)."""
    Hh = R + h_m
    f = lambda mu: mu * (Hh * mu - R) * (Hh - R * mu) / (R * R + Hh * Hh - 2 * R * Hh * mu) ** 2  # noqa: E731
    val, _ = quad(f, R / Hh, 1.0, epsabs=0, epsrel=1e-12)
    return 2 * rho * e_sun * R * R * val


@pytest.mark.parametrize("gap, oracle_gap, agrees", [
    (0.02, 0.02, True),
    (0.02, 200e3, False),                               # negative: an Earth image 400 km farther off
])
def test_earth_seen_in_a_mirror_above_an_upward_diode(gap, oracle_gap, agrees, variant):
    # A diode facing away from the Earth (zenith) under a 20 x 20 m perfect mirror `gap` above it, the Sun at
    # the zenith (full phase below): the diode sees the Earth's mirror image, an Earth 2 gap farther away,
    # so it reads what a nadir plate reads at altitude h + 2 gap (the quadrature above), reached only
    # through the Earth term of the path tracer.
    h = 700e3
    v = [[-10.0, -10.0, gap], [10.0, -10.0, gap], [10.0, 10.0, gap], [-10.0, 10.0, gap]]
    rend = Renderer(_diode(0.002), _quad(v, "mirror"), reflectivity=np.full((180, 288), 0.3), e_sun_w_m2=E,
                    variant=variant)
    res = rend.render([[0.0, 0.0, 1.0]], [[0.0, 0.0, -(R + h)]], np.eye(3)[None], seed=3, reflected_samples=4096)
    expected = _nadir_plate_quadrature(h + 2 * oracle_gap, 0.3, E)
    z = _z(res, expected)
    assert (abs(z) < Z_MAX) == agrees, (res.reflected_w_m2, res.reflected_se_w_m2, expected, z)
    assert res.direct_w_m2[0, 0] == 0.0 and res.albedo_w_m2[0, 0] == 0.0   # the mirror hides the Sun; Earth below


@pytest.mark.parametrize("rho, agrees", [(1.0, True), (0.97, False)])
def test_furnace_lossless_plate_in_a_uniform_radiance_field(rho, agrees, variant):
    # "Lossless surfaces in a uniform radiance field give pi L": 100 m above a uniform white Earth (rho 1)
    # with the Sun at the zenith, the Earth's radiance is L = E / pi to 1.6e-5 over the visible cap (see
    # tests/render/test_renderer.py). A white Lambertian plate (rho 1, lossless) 1 mm above an upward diode, facing the
    # Earth, receives pi L sin^2(cap half-angle) and sends rho/pi of it back down: the diode reads
    # pi L sin^2(cap) F = E (R / (R + h))^2 F, F the plate's view factor (Howell B-3). Negative case: a plate
    # that loses 3 % (the oracle still says lossless) is rejected.
    h, gap, half = 100.0, 0.001, 0.5
    v = [[-half, -half, gap], [half, -half, gap], [half, half, gap], [-half, half, gap]]
    mat = {"type": "diffuse", "reflectance": {"type": "uniform", "value": rho}}
    rend = Renderer(_diode(0.0005), _quad(v, mat), reflectivity=np.ones((180, 288)), e_sun_w_m2=E, variant=variant)
    res = rend.render([[0.0, 0.0, 1.0]], [[0.0, 0.0, -(R + h)]], np.eye(3)[None], seed=4,
                      reflected_samples=4096)
    F = 4 * plate_corner_view_factor(half, half, gap)
    expected = E * (R / (R + h + gap)) ** 2 * F
    got, se = res.reflected_w_m2[0, 0], res.reflected_se_w_m2[0, 0]
    assert (abs(got - expected) < Z_MAX * se + 2e-5 * E) == agrees, (got, se, expected)


# ------------------------------------------------------------------------------------------ all black
def test_all_black_configuration_has_no_reflected_and_unchanged_direct_albedo(variant):
    cfg = SatelliteConfig.load("tilt20_fov70")
    mesh = build_satellite_mesh(cfg)
    plain = trimesh.Trimesh(mesh.vertices.copy(), mesh.faces.copy(), process=False)   # no materials at all
    ds = DiodeSurfaces.from_config(cfg)
    rng = np.random.default_rng(0)
    sun = rng.normal(size=(6, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    earth = -rng.normal(size=(6, 3))
    earth *= (R + 600e3) / np.linalg.norm(earth, axis=1, keepdims=True)
    rot = np.tile(np.eye(3), (6, 1, 1))
    kw = dict(seed=7, direct_samples=256, albedo_samples=128)
    a = Renderer(ds, mesh, variant=variant).render(sun, earth, rot, **kw)
    b = Renderer(ds, plain, variant=variant).render(sun, earth, rot, **kw)
    assert np.all(a.reflected_w_m2 == 0) and np.all(a.reflected_se_w_m2 == 0) and a.reflected_samples.sum() == 0
    assert np.array_equal(a.direct_w_m2, b.direct_w_m2) and np.array_equal(a.albedo_w_m2, b.albedo_w_m2)
    np.testing.assert_array_equal(a.total_w_m2, a.direct_w_m2 + a.albedo_w_m2)
    # materials add a component and change nothing else, bitwise; the reflected values do not depend on the
    # batch split (random numbers keyed by seed, epoch, diode, estimator)
    alu = build_satellite_mesh(SatelliteConfig.from_dict({"layout": {"pattern": "thesis14", "tilt_deg": 20,
                                                                     "fov_deg": 70},
                                                          "body": {"material": "aluminium"},
                                                          "mount": {"material": "aluminium"}}))
    rend = Renderer(ds, alu, max_depth=4, variant=variant)
    c = rend.render(sun, earth, rot, reflected_samples=64, **kw)
    d = rend.render(sun, earth, rot, reflected_samples=64, batch_epochs=2, **kw)
    assert np.array_equal(a.direct_w_m2, c.direct_w_m2) and np.array_equal(a.albedo_w_m2, c.albedo_w_m2)
    assert np.array_equal(c.reflected_w_m2, d.reflected_w_m2)
    assert np.all(c.reflected_w_m2 >= 0) and c.reflected_w_m2.max() > 0
    np.testing.assert_array_equal(c.total_w_m2, c.direct_w_m2 + c.albedo_w_m2 + c.reflected_w_m2)



def test_reflected_wavefronts_hold_at_most_the_run_checks_epochs_whatever_the_batch(variant, monkeypatch):
    # The run's memory check (simcore.pipeline.preflight) sizes a wavefront as REFLECTED_BATCH_EPOCHS epochs of
    # paths; with every sub-batch past _REFLECTED_LANES (1 lane), each wavefront is one sub-batch of those epochs,
    # in order, whatever batch_epochs (150 epochs in one batch of 256: wavefronts of 64, 64 and 22 epochs).
    import simcore.render.renderer as renderer_module
    from simcore.pipeline.preflight import REFLECTED_BATCH_EPOCHS as checked
    from simcore.render.reflected import REFLECTED_BATCH_EPOCHS
    assert REFLECTED_BATCH_EPOCHS == checked
    rend = Renderer(_diode(SIDE), _quad([[X0, -1.0, 0.0], [X0, -1.0, 1.0], [X0, 1.0, 1.0], [X0, 1.0, 0.0]], "mirror"),
                    variant=variant)
    waves = []
    monkeypatch.setattr(renderer_module, "_REFLECTED_LANES", 1)
    monkeypatch.setattr(rend, "_reflected_round", lambda e_, *a: waves.append(e_.copy()))
    rend.render(np.repeat(SUN[None], 150, axis=0), reflected_samples=16, batch_epochs=256)
    assert [len(w) for w in waves] == [64, 64, 22]
    assert np.array_equal(np.concatenate(waves), np.arange(150))

def test_bad_reflected_arguments(variant):
    rend = Renderer(_diode(0.001), _quad([[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], "mirror"), variant=variant)
    with pytest.raises(ValueError, match="reflected_samples must be 4 m"):
        rend.render([[0.0, 0.0, 1.0]], reflected_samples=90)
    with pytest.raises(ValueError, match="max_depth"):
        Renderer(_diode(0.001), max_depth=0, variant=variant)
    with pytest.raises(ValueError, match="unknown material 'chrome'"):
        Renderer(_diode(0.001), _quad([[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], "chrome"), variant=variant)


# ------------------------------------------------------------------------------------------ many bounces
# An integrating sphere: a Lambertian sphere of radius Rs and reflectance rho (an icosphere of 20480 facets,
# area 0.9997 of the sphere's) with a port (the cap within 30 deg of +z removed, area fraction
# f = (1 - cos 30 deg) / 2), the Sun at the zenith shining through the port (flux Phi = E pi (Rs sin 30 deg)^2
# onto the far wall). Every wall element irradiates every other one alike (cos1 cos2 / d^2 = 1 / (4 Rs^2) on a
# sphere), so after i reflections the wall's irradiance is rho Phi / A (rho (1 - f))^(i-1), A = 4 pi Rs^2,
# and with up to D reflections the diode on the wall (its normal along the inner normal, no direct Sun) reads
#   rho Phi / A  sum_{i<D} (rho (1 - f))^i        (Labsphere, "A Guide to Integrating Sphere Theory", eq. 8).
# This exercises the BSDF sampling, the depth limit and the Russian roulette (from the fourth vertex).
RS, PORT = 0.1, np.radians(30.0)


def _sphere_oracle(rho, depth):
    f = (1 - np.cos(PORT)) / 2
    phi = E * np.pi * (RS * np.sin(PORT)) ** 2
    return rho * phi / (4 * np.pi * RS ** 2) * sum((rho * (1 - f)) ** i for i in range(depth))


@pytest.mark.parametrize("rho, depth, oracle_rho, oracle_depth, agrees", [
    (0.5, 40, 0.5, 40, True),          # all bounces that matter ((rho (1 - f))^40 ~ 1e-12)
    (0.8, 40, 0.8, 40, True),
    (0.8, 2, 0.8, 2, True),            # the first two reflections only
    (0.8, 40, 0.8, 2, False),          # negative: the oracle stops too early
    (0.5, 40, 0.45, 40, False),        # negative: the oracle's reflectance 10 % low
])
def test_integrating_sphere(rho, depth, oracle_rho, oracle_depth, agrees, variant):
    sph = trimesh.creation.icosphere(subdivisions=5, radius=RS)
    c = sph.triangles_center
    m = trimesh.Trimesh(sph.vertices, sph.faces[c[:, 2] / np.linalg.norm(c, axis=1) < np.cos(PORT)], process=False)
    m.metadata["material"] = {"type": "diffuse", "reflectance": {"type": "uniform", "value": rho}}
    frame = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])      # n = -x: into the sphere
    ds = DiodeSurfaces(np.array([[RS - 2e-4, 0.0, 0.0]]), frame[None], [[0.002, 0.002]])
    res = Renderer(ds, m, e_sun_w_m2=E, max_depth=depth, variant=variant).render([[0.0, 0.0, 1.0]], seed=2,
                                                                 reflected_samples=65536)
    expected = _sphere_oracle(oracle_rho, oracle_depth)
    z = _z(res, expected)
    # facets: the polyhedron's area is 0.9997 of the sphere's; allow that 3e-4 relative besides the 3.3 se
    assert (abs(res.reflected_w_m2[0, 0] - expected) < Z_MAX * res.reflected_se_w_m2[0, 0] + 3e-4 * expected) == agrees, \
        (res.reflected_w_m2, res.reflected_se_w_m2, expected, z)
    assert res.direct_w_m2[0, 0] == 0.0


# ------------------------------------------------------------------------------------------ run file
def test_run_file_carries_reflected_unchecked(tmp_path):
    import subprocess
    import sys
    import xarray as xr
    (tmp_path / "alu.toml").write_text('[layout]\npattern = "thesis14"\ntilt_deg = 20\nfov_deg = 70\n'
                                       '[body]\nmaterial = "aluminium"\n[mount]\nmaterial = "aluminium"\n')
    tiny = ["--start", "2016-07-02T00:45:00Z", "--duration", "4", "--samples", "256", "256"]
    for cfg, out in (("alu.toml", "alu.nc"), ("tilt20_fov70", "black.nc")):
        r = subprocess.run([sys.executable, "-m", "simcore.cli", "run", "--config", cfg, *tiny, "-o", out],
                           capture_output=True, text=True, timeout=600, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    alu, black = xr.load_dataset(tmp_path / "alu.nc"), xr.load_dataset(tmp_path / "black.nc")
    for ds in (alu, black):
        assert list(ds["component"].values) == ["direct", "albedo", "reflected"]
        assert np.all(ds["analytic"].sel(component="reflected").values == 0)      # black analytic surfaces
        assert np.all(np.isnan(ds["analytic_reference"].sel(component="reflected").values))
    assert np.all(black["irradiance"].sel(component="reflected").values == 0)
    assert np.all(black["samples"].sel(component="reflected").values == 0)
    refl = alu["irradiance"].sel(component="reflected").values
    assert refl.max() > 0 and np.all(refl >= 0)
    v = subprocess.run([sys.executable, "-m", "simcore.cli", "validate", "alu.nc"], capture_output=True, text=True,
                       timeout=600, cwd=tmp_path)
    assert v.returncode == 0, v.stdout + v.stderr
    assert f"reflected: {int(np.count_nonzero(refl > 0))} diode-epochs" in v.stdout and "not checked" in v.stdout


def test_reflected_samples_reach_the_renderer_the_run_file_and_a_resume(tmp_path, monkeypatch):
    # Oracle: the number asked for. Every diode-epoch the path tracer visits traces exactly N paths (the run
    # file's `samples`), the run file's attributes carry N, a run at the default (256) keeps the settings
    # digest runs had before the option existed (no key in its options), and a partial run made with one N
    # refuses to be resumed with another, then resumes with its own to the numbers of an uninterrupted run.
    import json
    import subprocess
    import sys
    import xarray as xr
    from simcore.cli import build_parser, run_options
    from simcore.pipeline.run import PreparedRun
    from simcore.pipeline.store import ChunkStore

    (tmp_path / "alu.toml").write_text('[layout]\npattern = "thesis14"\ntilt_deg = 20\nfov_deg = 70\n'
                                       '[body]\nmaterial = "aluminium"\n[mount]\nmaterial = "aluminium"\n')
    tiny = ["run", "--config", "alu.toml", "--start", "2016-07-02T00:45:00Z", "--duration", "3",
            "--samples", "256", "256"]

    def sunsim(args):
        return subprocess.run([sys.executable, "-m", "simcore.cli", *args], capture_output=True, text=True,
                              timeout=600, cwd=tmp_path)

    for n, out in ((1024, "n1024.nc"), (256, "n256.nc")):
        r = sunsim(tiny + ([] if n == 256 else ["--reflected-samples", str(n)]) + ["-o", out])
        assert r.returncode == 0, r.stderr
        ds = xr.load_dataset(tmp_path / out)
        assert ds.attrs["reflected_samples"] == n
        counts = ds["samples"].sel(component="reflected").values
        assert set(np.unique(counts)) <= {0, n} and counts.max() == n
        assert (json.loads(ds.attrs["options"]).get("reflected_samples") == n) == (n != 256)
    # resume: one finished chunk of a run with 1024 paths, then the same output asked with the default
    monkeypatch.chdir(tmp_path)           # the command's relative paths, as the resuming command gives them
    opts = run_options(build_parser().parse_args(tiny + ["--reflected-samples", "1024", "--chunk", "1", "-o", "r.nc"]))
    store = ChunkStore(opts.output, opts.spec()).open()
    store.save(0, 1, PreparedRun(opts).render_chunk(0, 1))
    store.close()
    other = sunsim(tiny + ["-o", "r.nc"])
    assert other.returncode == 2 and "different settings" in other.stderr, other.stderr
    assert len(other.stderr.strip().splitlines()) == 1 and "Traceback" not in other.stderr
    same = sunsim(tiny + ["--reflected-samples", "1024", "-o", "r.nc"])
    assert same.returncode == 0 and "resuming: 1 of 3 epochs" in same.stderr, same.stderr
    a, b = xr.load_dataset(tmp_path / "r.nc"), xr.load_dataset(tmp_path / "n1024.nc")
    for name in ("irradiance", "irradiance_se", "samples"):
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


# ------------------------------------------------------------------------------------------ glossy
# A rough conductor plate (GGX alpha 0.2, eta 1.2 + 7i) 2a x 2b at height H above a 1 mm diode facing +z,
# the Sun from below lighting its underside. At a plate point x the radiance toward the diode (direction v,
# the Sun along s) is f(s, v) E cos_s with the microfacet BRDF f = F(v.h) D(h) G1(s) G1(v) / (4 cos_s cos_v)
# (Walter et al., EGSR 2007: GGX D eq. 33, Smith G1 eq. 34, separable G; F the conductor Fresnel above),
# and the diode reads int f E cos_s cos_d cos_p / r^2 dA over the plate (midpoint rule, 600 x 450 cells;
# the lobe spans centimetres, the cells 0.13 mm). Point Sun in the oracle: the 0.27 deg disc changes a
# lobe 11 deg wide by O((0.27/11)^2) = 6e-4 relative.
def _ggx_plate_oracle(alpha, eta, k, sun, a=0.04, b=0.03, h=0.05, n=(600, 450)):
    xs = (np.arange(n[0]) + 0.5) / n[0] * 2 * a - a
    ys = (np.arange(n[1]) + 0.5) / n[1] * 2 * b - b
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    p = np.stack([X, Y, np.full_like(X, h)], axis=-1)
    r = np.linalg.norm(p, axis=-1)
    v = -p / r[..., None]                                   # plate -> diode
    nrm = np.array([0.0, 0.0, -1.0])                        # the lit underside
    cs, cv = sun @ nrm, v @ nrm
    hv = sun + v
    hv /= np.linalg.norm(hv, axis=-1, keepdims=True)
    ch = hv @ nrm
    t2 = (1 - ch ** 2) / ch ** 2
    D = alpha ** 2 / (np.pi * ch ** 4 * (alpha ** 2 + t2) ** 2)
    g1 = lambda c: 2.0 / (1.0 + np.sqrt(1.0 + alpha ** 2 * (1 - c * c) / (c * c)))  # noqa: E731
    F = fresnel_conductor(np.einsum("...i,...i->...", v, hv), eta, k)
    f = F * D * g1(cs) * g1(cv) / (4 * cs * cv)
    cos_d, cos_p = h / r, h / r
    return float(np.sum(f * E * cs * cos_d * cos_p / r ** 2) * (2 * a / n[0]) * (2 * b / n[1]))


@pytest.mark.parametrize("alpha, oracle_alpha, agrees", [
    (0.2, 0.2, True),
    (0.2, 0.3, False),                                  # negative: the oracle with a rougher surface
])
def test_rough_conductor_plate_matches_microfacet_quadrature(alpha, oracle_alpha, agrees, variant):
    sun = np.array([0.3, 0.0, -0.95]) / np.linalg.norm([0.3, 0.0, -0.95])
    v = [[-0.04, -0.03, 0.05], [0.04, -0.03, 0.05], [0.04, 0.03, 0.05], [-0.04, 0.03, 0.05]]
    mat = {"type": "roughconductor", "distribution": "ggx", "alpha": alpha,
           "eta": {"type": "uniform", "value": 1.2}, "k": {"type": "uniform", "value": 7.0}}
    res = Renderer(_diode(0.001), _quad(v, mat), e_sun_w_m2=E, variant=variant).render(sun[None], seed=8,
                                                                                       reflected_samples=16384)
    expected = _ggx_plate_oracle(oracle_alpha, 1.2, 7.0, sun)
    z = _z(res, expected)
    assert (abs(z) < Z_MAX) == agrees, (res.reflected_w_m2, res.reflected_se_w_m2, expected, z)


# ------------------------------------------------------------------------------------------ another tracer
@pytest.mark.parametrize("reference, agrees", [
    ("fov70 bare Al (alpha 0.1) black floor", True),
    ("fov70 diffuse rho 0.5 black floor", False),       # negative: the other tracer with other walls
])
def test_well_walls_agree_with_the_source_side_wall_tracer(reference, agrees, variant):
    # Another implementation: the retired simcore/render/walls.py (commit 4277e88; its numbers recorded in
    # tests/oracles/walls_oracle_4277e88.py) traced the same well (FOV 70, eq. 4.15 design) from the opening toward the
    # diode (the adjoint direction) with its own sampling; walls of bare aluminium (GGX alpha 0.1, Mitsuba's
    # "Al"), black floor. Its `reflected` response to a unit collimated beam is what the path tracer reads
    # with E = 1 (its 0.27 deg disc blurs a response that varies over degrees).
    from tests.oracles.walls_oracle_4277e88 import ORACLE
    from simcore.shapes.aperture import WellAperture
    ap = WellAperture.design(70.0)
    ref = ORACLE[reference]
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [ap.opening_x_m / 2, ap.opening_y_m / 2]
    verts, faces = [], []
    for i in range(4):
        base = len(verts)
        verts += [[*corners[i], 0.0], [*corners[(i + 1) % 4], 0.0], [*corners[(i + 1) % 4], ap.height_m],
                  [*corners[i], ap.height_m]]
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    mesh = trimesh.Trimesh(np.array(verts), np.array(faces), process=False)
    mesh.metadata["material"] = {"type": "roughconductor", "material": "Al", "alpha": 0.1, "distribution": "ggx"}
    ds = DiodeSurfaces(np.zeros((1, 3)), np.eye(3)[None], [[ap.diode_x_m, ap.diode_y_m]], (ap,))
    d = np.array(ref["d_diode"])
    res = Renderer(ds, mesh, e_sun_w_m2=1.0, variant=variant).render(d, seed=1, reflected_samples=65536)
    z = (res.reflected_w_m2[:, 0] - ref["reflected"]) / np.hypot(res.reflected_se_w_m2[:, 0], ref["reflected_se"])
    assert bool(np.all(np.abs(z) < Z_MAX)) == agrees, z
