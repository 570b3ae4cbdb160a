"""The well aperture: design rule of eq. 4.15 and the exact overlap response."""
import numpy as np
import pytest

from scipy.integrate import quad

from simcore.shapes.aperture import CircularWell, WellAperture, diode_frame, disc_rectangle_overlap


def _dir(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@pytest.mark.parametrize("fov", [70.0, 75.0])
def test_design_realises_fov_and_cutoff(fov):
    # Thesis eq. 4.15: full response (A = C) up to the FOV, no light beyond arccos(0.12) = 83.1 deg.
    ap = WellAperture.design(fov)
    assert ap.diode_area_m2 == pytest.approx(7.02e-6, rel=1e-12)  # BPW34 sensitive area
    for phi in (0.0, 90.0, 180.0, 270.0):  # along both wall axes, both ways
        assert ap.lit_fraction(_dir(fov - 1e-6, phi)) == pytest.approx(1.0)
        assert ap.lit_fraction(_dir(fov + 0.5, phi)) < 1.0
        assert ap.lit_fraction(_dir(np.degrees(np.arccos(0.12)) - 1e-6, phi)) == pytest.approx(0.0, abs=1e-6)
        assert ap.lit_fraction(_dir(np.degrees(np.arccos(0.12)) + 1e-3, phi)) == 0.0
    # Closed form along an axis between FOV and cut-off: overlap length (a + w)/2 - h tan(theta) over a.
    th = np.radians(78.0)
    expected = ((ap.diode_x_m + ap.opening_x_m) / 2 - ap.height_m * np.tan(th)) / ap.diode_x_m
    assert ap.lit_fraction(_dir(78.0)) == pytest.approx(expected, rel=1e-12)


def test_separable_overlap_at_a_diagonal():
    # For a square well the lit area is the product of the two 1-D overlaps (the shifted opening is a
    # rectangle): check at azimuth 45 deg against a brute-force count over a 2000 x 2000 grid on the diode.
    ap = WellAperture(2e-3, 2e-3, 4e-3, 3e-3, 1e-3)
    d = _dir(60.0, 35.0)
    shift = -ap.height_m * d[:2] / d[2]
    g = (np.arange(2000) + 0.5) / 2000 - 0.5
    x, y = np.meshgrid(g * ap.diode_x_m, g * ap.diode_y_m, indexing="ij")
    inside = (np.abs(x - shift[0]) <= ap.opening_x_m / 2) & (np.abs(y - shift[1]) <= ap.opening_y_m / 2)
    assert ap.lit_fraction(d) == pytest.approx(inside.mean(), abs=1e-3)


def test_bare_diode_is_a_cosine():
    ap = WellAperture.bare()
    th = np.linspace(0, 89.9, 50)
    d = np.stack([_dir(t, 17.0) for t in th])
    np.testing.assert_allclose(ap.response(d), np.cos(np.radians(th)), rtol=1e-12)
    assert ap.response(_dir(120.0)) == 0.0


def test_diode_frame_is_right_handed_and_horizontal():
    n = np.array([0.883022, -0.321394, -0.342020])  # SPEC sec. 5, tilt 20, +x panel, diode 0
    f = diode_frame(n / np.linalg.norm(n))
    np.testing.assert_allclose(f @ f.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(f) == pytest.approx(1.0)
    assert f[0, 2] == pytest.approx(0.0, abs=1e-12)  # u is horizontal (no body-z component)
    np.testing.assert_allclose(diode_frame([0, 0, 1.0])[0], [1, 0, 0])


@pytest.mark.parametrize("kwargs, match", [
    (dict(fov_deg=95), "FOV must lie"),
    (dict(fov_deg=70, cutoff_deg=60), "cut-off angle"),
])
def test_design_rejects_impossible_requests(kwargs, match):
    with pytest.raises(ValueError, match=match):
        WellAperture.design(**kwargs)


def test_bad_geometry_and_normals():
    with pytest.raises(ValueError, match="opening must be at least"):
        WellAperture(3e-3, 3e-3, 2e-3, 2e-3, 1e-3)
    with pytest.raises(ValueError, match="positive length"):
        WellAperture(-1e-3, 3e-3, 4e-3, 4e-3, 1e-3)
    with pytest.raises(ValueError, match="unit vector"):
        diode_frame([1.0, 1.0, 0.0])


# ---- the round well: the disc-rectangle overlap in closed form

def _overlap_by_quadrature(cx, cy, r, x0, x1, y0, y1):
    """Independent oracle: the chord length of the disc inside [y0, y1], integrated over x by adaptive
    quadrature (scipy.integrate.quad, breakpoints at the disc's edges)."""
    def chord(x):
        s = np.sqrt(max(r * r - (x - cx) ** 2, 0.0))
        return max(min(y1, cy + s) - max(y0, cy - s), 0.0)
    lo, hi = max(x0, cx - r), min(x1, cx + r)
    if hi <= lo:
        return 0.0
    pts = [p for p in (cx - np.sqrt(max(r * r - (y - cy) ** 2, 0.0)) for y in (y0, y1)) if lo < p < hi]
    pts += [p for p in (cx + np.sqrt(max(r * r - (y - cy) ** 2, 0.0)) for y in (y0, y1)) if lo < p < hi]
    return quad(chord, lo, hi, points=sorted(set(pts)) or None, epsabs=1e-13, epsrel=1e-11, limit=200)[0]


def test_disc_rectangle_overlap_exact_cases():
    r = 1.3
    assert disc_rectangle_overlap(0.0, 0.0, r, -5, 5, -5, 5) == pytest.approx(np.pi * r * r, rel=1e-14)   # whole disc
    assert disc_rectangle_overlap(0.0, 0.0, r, 0, 5, -5, 5) == pytest.approx(np.pi * r * r / 2, rel=1e-14)  # half
    assert disc_rectangle_overlap(0.0, 0.0, r, -5, 0, -5, 0) == pytest.approx(np.pi * r * r / 4, rel=1e-14)  # quadrant
    assert disc_rectangle_overlap(0.2, -0.1, 10.0, -1, 1, -2, 0.5) == pytest.approx(2 * 2.5, rel=1e-14)   # rect inside
    assert disc_rectangle_overlap(3.0, 0.0, 1.0, -1, 1, -1, 1) == 0.0                                    # disjoint
    # circular segment of height r/2 (cut at x = r/2): r^2 (theta - sin theta) / 2 with theta = 2 acos(1/2)
    th = 2 * np.arccos(0.5)
    assert disc_rectangle_overlap(0.0, 0.0, r, r / 2, 9, -9, 9) == pytest.approx(r * r * (th - np.sin(th)) / 2,
                                                                                rel=1e-13)


def test_disc_rectangle_overlap_matches_quadrature():
    rng = np.random.default_rng(5)
    for _ in range(300):
        cx, cy = rng.uniform(-1.5, 1.5, 2)
        r = rng.uniform(0.2, 2.0)
        x0, y0 = rng.uniform(-1.5, 0.5, 2)
        x1, y1 = x0 + rng.uniform(0.05, 2.0), y0 + rng.uniform(0.05, 2.0)
        got = float(disc_rectangle_overlap(cx, cy, r, x0, x1, y0, y1))
        assert got == pytest.approx(_overlap_by_quadrature(cx, cy, r, x0, x1, y0, y1), abs=1e-9), (cx, cy, r, x0, x1, y0, y1)


def test_circular_well_lit_fraction():
    a = 2.65e-3
    well = CircularWell(a, a, 2.5e-3, 1.5e-3)
    assert well.lit_fraction([0.0, 0.0, 1.0]) == pytest.approx(1.0)                 # the rim contains the diode
    assert well.lit_fraction([0.0, 0.0, -1.0]) == 0.0
    # along u at theta: the rim's circle shifted by h tan(theta); oracle: the quadrature above
    th = np.radians(40.0)
    d = [np.sin(th), 0.0, np.cos(th)]
    want = _overlap_by_quadrature(-1.5e-3 * np.tan(th), 0.0, 2.5e-3, -a / 2, a / 2, -a / 2, a / 2) / a ** 2
    assert well.lit_fraction(d) == pytest.approx(want, rel=1e-9)
    assert well.response(d) == pytest.approx(want * np.cos(th), rel=1e-9)
    with pytest.raises(ValueError, match="must reach the diode's corners"):
        CircularWell(a, a, 1.5e-3, 1e-3)
