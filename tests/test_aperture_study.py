"""Aperture studies: traced responses against closed forms, wall reflections, design, shadowing, sweep."""
import numpy as np
import pytest

from simcore.cli import main as cli_main
from simcore.environment.geometry import one_orbit_geometry
from simcore.studies import aperture as A
from simcore.shapes.aperture import WellAperture
from simcore.render.walls import TabulatedResponse, WallMaterial, trace_well

AP70 = WellAperture.design(70.0)   # FOV 70: opening 5.28 mm, height 0.48 mm (scenes/FORMAT.md)


def _grid(thetas, phis):
    t, p = np.meshgrid(thetas, phis, indexing="ij")
    return A.cut_directions(t.ravel(), p.ravel())


def _z(value, ref, se):
    return np.abs(value - ref) / np.where(se > 0, se, np.inf)


# ----------------------------------------------------------------------------- black walls

def test_traced_well_with_black_walls_equals_analytic_overlap():
    # Oracle: the exact overlap of the diode with the shifted opening (simcore.shapes.aperture, a closed form).
    d = _grid(np.arange(0.0, 90.0, 6.0), [0.0, 20.0, 45.0])
    tr = trace_well(AP70, d, WallMaterial.black(), rays=20_000, seed=1)
    exact = AP70.response(d)
    z = _z(tr.response, exact, tr.response_se)
    assert np.all(z < 3.0), (z.max(), d[np.argmax(z)])
    assert np.all(tr.reflected == 0.0)
    # no standard error means no light at all: then the overlap is 0 too
    assert np.all(exact[tr.response_se == 0] == 0.0)


def test_renderer_black_well_equals_analytic_overlap():
    # Oracle: as above; the renderer traces scenes.meshes's floor + well meshes (independent geometry code).
    th = np.arange(60.0, 86.0, 3.0)
    d = _grid(th, [0.0, 30.0, 45.0])
    resp, se = A.traced_black_response(AP70, d, samples=4096, seed=3)
    exact = AP70.response(d)
    partial = se > 0
    assert partial.sum() >= 10
    assert np.all(_z(resp, exact, se)[partial] < 3.0)
    # fully lit / fully dark directions carry no noise and must match to float32 precision
    assert np.allclose(resp[~partial], exact[~partial], atol=2e-6)


def test_bare_diode_traced_is_cosine():
    # Oracle: a bare diode reads cos(theta) exactly (Lambert's cosine law).
    bare = WellAperture.bare()
    d = _grid([0.0, 30.0, 60.0, 80.0], [0.0])
    tr = trace_well(bare, d, WallMaterial.aluminium(), rays=2000)
    assert np.allclose(tr.response, d[:, 2], rtol=1e-6)


# ----------------------------------------------------------------------------- reflecting walls

def _mirror_fraction(a, w, s, r, kmax=8):
    """1-D method of images: fraction of a diode [-a, a] lit through an opening [-w, w] shifted by s
    between mirror walls at +-w reflecting r per bounce: the unfolded floor is tiled by cells of width 2w;
    cell k is seen after |k| reflections and its copy of the diode is [2kw - a, 2kw + a]."""
    total = 0.0
    for k in range(-kmax, kmax + 1):
        lo = max(-w - s, 2 * k * w - a)
        hi = min(w - s, 2 * k * w + a)
        total += r ** abs(k) * max(hi - lo, 0.0)
    return total / (2 * a)


@pytest.mark.parametrize("r", [1.0, 0.5])
def test_mirror_walls_match_method_of_images(r):
    # Oracle: the kaleidoscope (method of images) closed form above; separable in u and v because a
    # specular reflection off a u wall flips only the u component.
    d = _grid([20.0, 60.0, 72.0, 78.0, 82.0, 85.0, 88.0], [0.0, 30.0, 45.0])
    tr = trace_well(AP70, d, WallMaterial.mirror(r), rays=20_000, seed=2, reflective_floor=False)
    a, w, h = AP70.diode_x_m / 2, AP70.opening_x_m / 2, AP70.height_m
    exact = np.array([dd[2] * _mirror_fraction(a, w, -h * dd[0] / dd[2], r)
                      * _mirror_fraction(a, w, -h * dd[1] / dd[2], r) for dd in d])
    z = np.abs(tr.response - exact) / np.maximum(tr.response_se, 1e-12)
    assert np.all((z < 3.0) | (np.abs(tr.response - exact) < 1e-6)), (z.max(), d[np.argmax(z)])
    # mirrors never send light back up: everything that enters reaches the floor
    assert np.all(tr.escaped == 0.0)


@pytest.mark.parametrize("floor", [True, False])
def test_every_path_is_accounted_for(floor):
    # Energy bookkeeping with lossless walls and no Russian roulette: the power entering the opening
    # (A_open d_n / A_diode, exact) ends up on the diode, the floor or back out of the opening.
    d = _grid([0.0, 45.0, 75.0, 84.0], [0.0, 45.0])
    tr = trace_well(AP70, d, WallMaterial.diffuse(1.0), rays=5000, seed=4, reflective_floor=floor,
                    rr_depth=10_000, max_bounces=400)
    assert np.allclose(tr.accounted, tr.entered, rtol=1e-5)
    assert np.allclose(tr.walls, 0.0, atol=1e-6)
    if floor:
        assert np.allclose(tr.floor, 0.0, atol=1e-6)
    assert np.all(tr.escaped[2:] > 0)        # light that hits a wall can come back out


@pytest.mark.parametrize("material", [WallMaterial.diffuse(1.0), WallMaterial.mirror(1.0)])
def test_white_furnace(material):
    # White furnace: with lossless walls and floor and a diode that counts every arrival and reflects it,
    # nothing absorbs, so under a uniform sky of radiance L the radiance is L everywhere in the well and
    # the diode irradiance is pi L: the hemispherical integral of the response is pi. Directions are drawn
    # cosine-weighted (pdf d_n / pi), so integral = pi * mean(response / d_n).
    rng = np.random.default_rng(7)
    u1, u2 = rng.random(4000), rng.random(4000)
    r, ph = np.sqrt(u1), 2 * np.pi * u2
    d = np.column_stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(1 - u1)])
    tr = trace_well(AP70, d, material, rays=16, seed=8, white_diode=True,
                    reflective_floor=material.kind == "diffuse")
    per_dir = tr.response / d[:, 2]
    est = np.pi * per_dir.mean()
    # total variance: between directions and within (the per-direction SEs)
    se = np.pi * per_dir.std(ddof=1) / np.sqrt(len(d))
    assert abs(est - np.pi) < 3 * se, (est, se)
    assert se < 0.03 * np.pi


def test_response_grows_monotonically_with_wall_reflectance():
    # Path by path, a diffuse wall multiplies the throughput by rho and (same seed) the sampled directions
    # do not depend on rho, so with no Russian roulette the estimate is non-decreasing in rho.
    d = _grid([0.0, 50.0, 70.0, 78.0, 83.0, 86.0], [0.0, 45.0])
    rhos = [0.0, 0.05, 0.2, 0.5, 0.9]
    resp = np.array([trace_well(AP70, d, WallMaterial.diffuse(rho), rays=5000, seed=5, rr_depth=100).response
                     for rho in rhos])
    assert np.all(np.diff(resp, axis=0) >= -1e-12)
    assert np.all(resp[-1, 1:] > resp[0, 1:])      # and it does grow where walls are in view
    # beyond the cut-off only reflected light reaches the diode
    beyond = np.degrees(np.arccos(d[:, 2])) > 85.2
    assert np.all(resp[0, beyond] == 0.0) and np.all(resp[-1, beyond] > 0.0)


def test_tabulated_response_is_symmetric_and_exact_for_black_walls():
    black = TabulatedResponse.trace(AP70, WallMaterial.black(), theta_step_deg=10, phi_step_deg=15, rays=200)
    d = np.random.default_rng(0).normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert np.array_equal(black.response(d), AP70.response(d))      # overlap + 0 reflected
    al = TabulatedResponse.trace(AP70, WallMaterial.aluminium(), theta_step_deg=10, phi_step_deg=15, rays=500)
    mirrored = d * np.array([-1.0, 1.0, 1.0])
    swapped = d[:, [1, 0, 2]]
    assert np.allclose(al.response(d), al.response(mirrored))
    assert np.allclose(al.response(d), al.response(swapped))
    assert np.all(al.response(d[d[:, 2] <= 0]) == 0.0)


def test_tabulated_response_works_in_the_albedo_sum():
    from simcore.radiometry.analytic import diode_irradiance
    tab = TabulatedResponse.trace(AP70, WallMaterial.aluminium(), theta_step_deg=15, phi_step_deg=45, rays=300)
    r_sat = np.array([[7.0e6, 0.0, 0.0]])
    r_sun = np.array([[1.5e11, 0.0, 0.0]])
    frames = np.array([[[0, 1, 0], [0, 0, 1], [-1, 0, 0]]], float)     # nadir-looking diode
    out_t = diode_irradiance(r_sat, r_sun, np.eye(3), frames, [tab], backend="numpy", direct=False)
    out_o = diode_irradiance(r_sat, r_sun, np.eye(3), frames, [AP70], backend="numpy", direct=False)
    assert out_t.albedo_w_m2.shape == (1, 1)
    assert out_t.albedo_w_m2[0, 0] >= out_o.albedo_w_m2[0, 0] > 0


def test_wall_material_misuse_raises():
    with pytest.raises(ValueError, match="unknown wall material"):
        WallMaterial("velvet")
    with pytest.raises(ValueError, match="reflectance"):
        WallMaterial.diffuse(1.5)
    with pytest.raises(ValueError, match="unit vectors"):
        trace_well(AP70, [[0.0, 0.0, 2.0]], WallMaterial.black())


# ----------------------------------------------------------------------------- figures and design

def test_response_angles_of_the_cosine():
    # Oracle: cos(theta) = 0.5 at 60 deg and 0.01 at arccos(0.01) = 89.427 deg.
    th = np.arange(0.0, 90.0001, 0.05)
    a = A.response_angles(th, np.cos(np.radians(th)))
    assert a[0.5] == pytest.approx(60.0, abs=1e-3)
    assert a[0.01] == pytest.approx(np.degrees(np.arccos(0.01)), abs=1e-3)


def test_eq415_and_overlap_differ_between_fov_and_cutoff():
    # Both are 1 x cos up to the FOV and 0 beyond the cut-off on the wall axis (same design), but between
    # them eq. 4.15 is linear in cos and the overlap linear in tan: they differ there, and by azimuth.
    from simcore.radiometry.response import Eq415Response
    eq = Eq415Response(70.0)
    th = np.array([30.0, 65.0, 75.0, 80.0, 84.0])
    axis = A.cut_directions(th, 0.0)
    diag = A.cut_directions(th, 45.0)
    assert np.allclose(AP70.response(axis)[:2], eq.response(axis)[:2])
    assert np.all(np.abs(AP70.response(axis)[2:4] - eq.response(axis)[2:4]) > 0.01)
    assert AP70.response(diag)[4] > 0 and eq.response(diag)[4] == 0       # the diagonal sees past 83.1 deg


def test_design_aperture_realises_fov_and_cutoff():
    # Oracle: the definition of the design (eq. 4.15 geometry): fully lit up to the FOV, dark beyond the cut-off.
    for fov, hmax, keep in [(70.0, None, "fov"), (75.0, 0.4e-3, "fov"), (60.0, 0.35e-3, "cutoff")]:
        des = A.design_aperture(fov, max_height_m=hmax, keep=keep)
        ap = des.aperture
        lit = lambda t: float(ap.lit_fraction(A.cut_directions([t], 0.0))[0])  # noqa: E731
        assert lit(des.fov_deg - 0.01) == pytest.approx(1.0)
        assert lit(des.fov_deg + 0.5) < 1.0
        assert lit(des.cutoff_deg + 0.01) == 0.0 and lit(des.cutoff_deg - 0.1) > 0.0
        if hmax is not None:
            assert des.height_limited and ap.height_m == pytest.approx(hmax)
            assert (des.fov_deg if keep == "fov" else des.cutoff_deg) == pytest.approx(
                fov if keep == "fov" else 83.1079, abs=1e-3)
    with pytest.raises(ValueError, match="cannot cut off"):
        A.design_aperture(70.0, max_height_m=0.3e-3, keep="cutoff")


# ----------------------------------------------------------------------------- shadowing and sweep

def test_self_shadowing_flat_diodes_see_no_body():
    # Oracle: a flat diode on a face of a convex box cannot see the box in its front hemisphere, and the
    # flat top/bottom diodes have no neighbours on their panels.
    rows = A.self_shadowing("tilt25_fov75", nside=4, samples=64)
    assert len(rows) == 14
    for r in rows[12:]:
        assert r["shadowed_fov_fraction"] == 0.0 and abs(r["response_loss"]) < 1e-6
    for r in rows[:12]:          # tilted diodes look past their panel: the body hides part of their FOV
        assert r["body_response_loss"] > 0.01
        # the traced body (mesh) and the closed-form box agree; neighbours add little
        assert abs(r["response_loss"] - r["body_response_loss"]) < 5e-3


def test_self_shadowing_traced_own_mount_matches_analytic_reference():
    # The renderer with diode k's own floor + well only reproduces the overlap (the black-wall check),
    # so both references give the same table.
    a = A.self_shadowing("tilt20_fov70", nside=2, samples=64)
    t = A.self_shadowing("tilt20_fov70", nside=2, samples=64, reference="traced")
    for ra, rt in zip(a, t):
        assert rt["fov_sr"] == pytest.approx(ra["fov_sr"])
        assert rt["response_loss"] == pytest.approx(ra["response_loss"], abs=1e-5)


def test_sweep_rows_and_shipped_layout():
    from scenes.config import SatelliteConfig
    from simcore.studies.coverage import coverage_fractions
    g = one_orbit_geometry(step_s=120.0)
    rows = A.sweep_apertures([None, 1.0], [25.0], [75.0], geometry=g)
    assert [r["feasible"] for r in rows] == [True, False]
    assert "clearance" in rows[1]["reason"] and np.isnan(rows[1]["albedo_fraction"])
    shipped = SatelliteConfig.load("tilt25_fov75", dead=[0])
    # the eq. 4.15 design row is the shipped configuration (independent path: the TOML file)
    assert rows[0]["green"] == coverage_fractions(shipped)["green"]
    assert rows[0]["opening_mm"] == pytest.approx(7.00, abs=0.01)      # scenes/FORMAT.md: FOV 75 -> 7.00 mm
    assert 0.05 < rows[0]["albedo_fraction"] < 0.5
    assert 0 < rows[0]["wls_mean_deg"] < 30 and 0 < rows[0]["albedo_sun_mean_deg"] < 30
    assert rows[0]["green_response"] >= rows[0]["green"] - 0.05


def test_sweep_command_writes_table_and_plot(tmp_path):
    import csv
    assert cli_main(["aperture-sweep", "--heights", "eq415", "--tilts", "20", "--fovs", "70", "--step", "300", "-o", str(tmp_path)]) == 0
    with open(tmp_path / "sweep.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1 and rows[0]["feasible"] == "True"
    # FORMAT.md: the FOV 70 design is 5.28 mm wide and 0.48 mm tall
    assert float(rows[0]["opening_mm"]) == pytest.approx(5.28, abs=0.01)
    assert float(rows[0]["height_mm"]) == pytest.approx(0.48, abs=0.005)
    assert (tmp_path / "sweep.png").stat().st_size > 10_000 and (tmp_path / "sweep.md").exists()
