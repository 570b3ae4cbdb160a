"""Tests of simcore.environment.eclipse against independent oracles.

* Thesis sec. 4.1.4, eqs. 4.6-4.9, coded literally here (theta vs theta_crit).
* Eclipse fraction of a circular orbit vs beta angle, cylindrical shadow:
  f = arccos( sqrt(h^2 + 2 R h) / ((R + h) cos beta) ) / pi for |beta| < beta*
  = arcsin(R / (R + h)), else 0 -- S. L. Rickman, "Introduction to Orbital
  Mechanics and Spacecraft Attitudes for Thermal Engineers", NASA TFAWS
  (2014), "eclipse fraction"; also Wertz & Larson, "Space Mission Analysis
  and Design" (3rd ed.), sec. 5.1. (Derivation: shadow iff r.s < 0 and
  r^2 (1 - cos^2 beta cos^2 u) < R^2 with r.s = r cos beta cos u.)
* Penumbra / umbra timing at beta = 0 from cone geometry: seen from the
  satellite the Earth-centre direction turns at the orbital rate n relative
  to the (fixed) Sun, so the penumbra (|c - b| < a) lasts 2a/n per passage
  with a = R_sun/AU; the umbra cone (half-angle (R_sun - R)/AU) is narrower
  than the cylinder, so the conical umbra is 2 (R_sun - R) / (AU n) shorter
  than the cylindrical shadow per orbit (Montenbruck & Gill, "Satellite
  Orbits", 2000, sec. 3.4.2, fig. 3.9).
* Conical fraction vs a brute-force quadrature: many directions inside the
  Sun's cone, each traced as a ray against the Earth sphere.
* Small-angle limit: Montenbruck & Gill eqs. 3.92-3.94 (planar circular
  segments), coded here from the book.
"""
import numpy as np
import pytest

from simcore.constants import AU_M, R_EARTH_MEAN_M, R_SUN_M
from simcore.environment.eclipse import conical, cylindrical

R = R_EARTH_MEAN_M
GM_EARTH = 3.986004418e14  # m^3/s^2, IERS Conventions (2010) table 1.1


def random_rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def circular_orbit(rng, h_m, beta_deg, u):
    """Satellite positions at argument u (from the Sun's in-plane projection) and the Sun position,
    in a randomly oriented frame (the shadow must not depend on the frame)."""
    Q = random_rotation(rng)
    e1, e2, normal = Q[:, 0], Q[:, 1], Q[:, 2]
    r = R + h_m
    r_sat = r * (np.cos(u)[:, None] * e1 + np.sin(u)[:, None] * e2)
    beta = np.radians(beta_deg)
    r_sun = AU_M * (np.cos(beta) * e1 + np.sin(beta) * normal)
    return r_sat, r_sun


def eclipse_fraction_closed_form(h_m, beta_deg):
    beta = np.radians(beta_deg)
    beta_star = np.arcsin(R / (R + h_m))
    if abs(beta) >= beta_star:
        return 0.0
    return np.arccos(np.sqrt(h_m**2 + 2 * R * h_m) / ((R + h_m) * np.cos(beta))) / np.pi


def sun_disc_quadrature(r_sat, r_sun, n=1500, tilt=0.3):
    """Return the unblocked fraction of the solar disc by tracing n^2 grid directions (independent oracle).

    Midpoint grid on the gnomonic (tangent) plane around the Sun's
    direction, weighted by the solid-angle Jacobian (1 + x^2 + y^2)^-3/2;
    the grid is turned by ``tilt`` rad so the Earth's limb is not aligned
    with its lines (aliasing).
    """
    d0 = r_sun - r_sat
    dist = np.linalg.norm(d0)
    d0 = d0 / dist
    t = np.tan(np.arcsin(R_SUN_M / dist))
    x = ((np.arange(n) + 0.5) / n * 2 - 1) * t
    X, Y = np.meshgrid(x, x, indexing="ij")
    inside = X * X + Y * Y < t * t
    X, Y = X[inside], Y[inside]
    w = (1 + X * X + Y * Y) ** -1.5
    helper = np.array([0.0, 0.0, 1.0]) if abs(d0[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(d0, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d0, e1)
    e1, e2 = np.cos(tilt) * e1 + np.sin(tilt) * e2, -np.sin(tilt) * e1 + np.cos(tilt) * e2
    d = d0 + X[:, None] * e1 + Y[:, None] * e2
    d /= np.linalg.norm(d, axis=1)[:, None]
    # Ray r_sat + s d hits the sphere |x| = R for some s > 0 (r_sat is outside the sphere).
    rd = d @ r_sat
    hit = (rd < 0) & (rd * rd - (r_sat @ r_sat - R * R) > 0)
    return 1.0 - np.sum(w * hit) / np.sum(w)


def montenbruck_gill_planar(a, b, c):
    """Unobscured fraction of the Sun from M&G eqs. 3.92-3.94 (planar discs), partial overlap only."""
    x = (c * c + a * a - b * b) / (2 * c)
    y = np.sqrt(a * a - x * x)
    area = a * a * np.arccos(x / a) + b * b * np.arccos((c - x) / b) - c * y
    return 1.0 - area / (np.pi * a * a)


def sun_at_angle(r_sat, c):
    """Sun position (1 AU from the satellite) with the Sun centre at angle c from the nadir, in the x-y plane."""
    nadir = -r_sat / np.linalg.norm(r_sat)
    perp = np.cross([0.0, 0.0, 1.0], nadir)
    perp /= np.linalg.norm(perp)
    return r_sat + AU_M * (np.cos(c) * nadir + np.sin(c) * perp)


# ---- cylindrical ----------------------------------------------------------

def test_cylinder_equals_thesis_theta_rule(rng):
    # Eqs. 4.6-4.9 literally, with the text's rule: zero Sun vector (shadow) when theta > theta_crit.
    n = 200_000
    r_sat = rng.normal(size=(n, 3))
    r_sat *= (rng.uniform(R + 1e3, 2.0 * R, n) / np.linalg.norm(r_sat, axis=1))[:, None]
    r_sun = rng.normal(size=(n, 3)) * AU_M
    d_sun = r_sun / np.linalg.norm(r_sun, axis=1)[:, None]
    dist = np.linalg.norm(r_sat, axis=1)
    theta_crit = np.arccos(R / dist)                                          # eq. 4.6
    theta = np.arcsin(-np.einsum("ij,ij->i", r_sat, d_sun) / dist)            # eq. 4.9
    thesis_lit = ~(theta > theta_crit)
    clear = np.abs(theta - theta_crit) > 1e-9  # leave out the boundary itself, where rounding decides
    got = cylindrical(r_sat, r_sun)
    assert got.dtype == bool and got.shape == (n,)
    np.testing.assert_array_equal(got[clear], thesis_lit[clear])
    assert 0.05 < np.mean(~got) < 0.5  # both outcomes well represented


def test_cylinder_simple_geometry():
    sun = np.array([AU_M, 0.0, 0.0])
    r = R + 700e3
    cases = {
        (r, 0.0, 0.0): True,              # sub-solar side
        (-r, 0.0, 0.0): False,            # straight behind the Earth
        (-r, 0.0, R - 1.0): False,        # behind, 1 m inside the cylinder
        (-r, 0.0, R + 1.0): True,         # behind, 1 m outside it
        (0.0, r, 0.0): True,              # terminator plane, beside the Earth
        (-1e9, 0.0, R - 1.0): False,      # the cylinder does not end (thesis: Sun at infinity)
    }
    pos = np.array(list(cases))
    np.testing.assert_array_equal(cylindrical(pos, sun), list(cases.values()))
    # Only the Sun's direction matters.
    np.testing.assert_array_equal(cylindrical(pos, sun * 1e-6), list(cases.values()))


@pytest.mark.parametrize("beta_deg", [0.0, 20.0, 40.0, 60.0, -35.0, 70.0])
def test_cylinder_eclipse_fraction_vs_beta_closed_form(rng, beta_deg):
    h = 700e3
    n = 1_000_000
    u = 2 * np.pi * (np.arange(n) + 0.5) / n
    r_sat, r_sun = circular_orbit(rng, h, beta_deg, u)
    got = np.mean(~cylindrical(r_sat, r_sun))
    expected = eclipse_fraction_closed_form(h, beta_deg)  # Rickman (NASA TFAWS 2014); SMAD sec. 5.1
    assert abs(got - expected) <= 3.0 / n  # two shadow edges, each at most one sample off
    if expected > 0:
        assert abs(got - expected) / expected < 1e-3
    else:
        assert got == 0.0  # beta = 70 deg > beta* = 64.3 deg at 700 km: no eclipse


# ---- conical --------------------------------------------------------------

def test_conical_limits():
    r_sat = np.array([[R + 700e3, 0, 0], [-(R + 700e3), 0, 0], [0, R + 700e3, 0]])
    nu = conical(r_sat, [AU_M, 0.0, 0.0])
    np.testing.assert_array_equal(nu, [1.0, 0.0, 1.0])


def test_conical_penumbra_and_umbra_durations_leo_beta0(rng):
    h = 700e3
    r = R + h
    n_rate = np.sqrt(GM_EARTH / r**3)                 # orbital angular rate, rad/s
    period = 2 * np.pi / n_rate
    dt = 0.01
    t = np.arange(0.0, period, dt)
    r_sat, r_sun = circular_orbit(rng, h, 0.0, n_rate * t)
    nu = conical(r_sat, r_sun)
    lit_cyl = cylindrical(r_sat, r_sun)

    penumbra_per_passage = np.sum((nu > 0) & (nu < 1)) * dt / 2
    expected_penumbra = 2 * R_SUN_M / AU_M / n_rate   # 2a/n: 0.533 deg of Sun over the limb at n
    assert 8.0 < expected_penumbra < 20.0             # "a few seconds" at 700 km: 8.76 s
    assert abs(penumbra_per_passage - expected_penumbra) < 0.03

    umbra = np.sum(nu == 0) * dt
    shadow_cyl = np.sum(~lit_cyl) * dt
    # Umbra cone half-angle (R_sun - R)/AU: narrower than the cylinder on both edges.
    expected_shortening = 2 * (R_SUN_M - R) / AU_M / n_rate  # 8.68 s
    assert abs((shadow_cyl - umbra) - expected_shortening) < 0.04
    # The cylinder's edge lies inside the penumbra: the Sun's centre is on the Earth's limb there.
    assert np.all(nu[lit_cyl & (nu < 1)] > 0.45)
    assert np.all(nu[~lit_cyl & (nu > 0)] < 0.55)


@pytest.mark.parametrize("offset", [-0.8, -0.4, 0.0, 0.4, 0.8])
def test_conical_matches_ray_traced_sun_disc(offset):
    r_sat = np.array([R + 700e3, 0.0, 0.0])
    a = R_SUN_M / AU_M
    b = np.arcsin(R / np.linalg.norm(r_sat))
    r_sun = sun_at_angle(r_sat, b + offset * a)  # the Sun's centre `offset` radii beyond the limb
    got = conical(r_sat, r_sun)
    assert got.shape == (1,)
    expected = sun_disc_quadrature(r_sat, r_sun)
    assert 0.05 < expected < 0.95
    assert abs(got[0] - expected) < 2e-5  # quadrature converges to ~5e-6 at n = 1500


def test_conical_matches_ray_traced_sun_disc_oblique(rng):
    # A generic 3-D geometry (random frame, beta = 40 deg orbit, a penumbra sample on it).
    h = 550e3
    u = np.linspace(np.pi - 0.5, np.pi, 200_001)
    r_sat, r_sun = circular_orbit(rng, h, 40.0, u)
    nu = conical(r_sat, r_sun)
    k = int(np.argmin(np.abs(nu - 0.3)))
    expected = sun_disc_quadrature(r_sat[k], r_sun)
    assert abs(nu[k] - expected) < 2e-5


@pytest.mark.parametrize("offset_b", [0.0, 0.5, 1.0, 3.0])
def test_conical_annular_far_from_earth(offset_b):
    # Beyond R / sin(a) ~ 1.37e9 m the Earth looks smaller than the Sun: at 3e9 m, b = 0.46 a.
    r_sat = np.array([-3e9, 0.0, 0.0])
    b = np.arcsin(R / 3e9)
    c = offset_b * b
    r_sun = sun_at_angle(r_sat, c)
    got = conical(r_sat, r_sun)[0]
    expected = sun_disc_quadrature(r_sat, r_sun, n=2000)
    assert abs(got - expected) < 2e-5
    a = np.arcsin(R_SUN_M / np.linalg.norm(r_sun - r_sat))
    if c <= a - b:  # the Earth's disc wholly inside the Sun's: annular, M&G's 1 - b^2/a^2 (sec. 3.4.2)
        assert abs(got - (1 - (b / a) ** 2)) < 1e-6
    else:           # offset 3: partly overlapping small discs, M&G's planar formula applies
        assert abs(got - montenbruck_gill_planar(a, b, c)) < 1e-6


def test_conical_small_angle_limit_is_montenbruck_gill():
    # Far away both discs are tiny and the sky is flat: M&G's planar formula is then exact.
    r_sat = np.array([-2e9, 0.0, 0.0])
    b = np.arcsin(R / 2e9)
    a_sun = R_SUN_M / AU_M
    for c in np.linspace(abs(a_sun - b) * 1.01, (a_sun + b) * 0.99, 9):
        r_sun = sun_at_angle(r_sat, c)
        a = np.arcsin(R_SUN_M / np.linalg.norm(r_sun - r_sat))
        assert abs(conical(r_sat, r_sun)[0] - montenbruck_gill_planar(a, b, c)) < 1e-6


def test_conical_vs_planar_formula_in_leo():
    # Seen from LEO the Earth is a 130 deg disc; the planar formula is then off by ~2e-4 of the Sun.
    r_sat = np.array([R + 700e3, 0.0, 0.0])
    b = np.arcsin(R / np.linalg.norm(r_sat))
    r_sun = sun_at_angle(r_sat, b)
    a = np.arcsin(R_SUN_M / np.linalg.norm(r_sun - r_sat))
    exact = sun_disc_quadrature(r_sat, r_sun)
    assert abs(conical(r_sat, r_sun)[0] - exact) < 2e-5
    assert abs(montenbruck_gill_planar(a, b, b) - exact) > 1e-4


def test_conical_is_monotonic_through_penumbra():
    r_sat = np.array([R + 700e3, 0.0, 0.0])
    b = np.arcsin(R / np.linalg.norm(r_sat))
    a = R_SUN_M / AU_M
    cs = np.linspace(b - 1.5 * a, b + 1.5 * a, 2001)
    nu = conical(np.tile(r_sat, (cs.size, 1)), np.array([sun_at_angle(r_sat, c) for c in cs]))
    assert np.all(np.diff(nu) >= 0)
    assert nu[0] == 0.0 and nu[-1] == 1.0


# ---- shapes and misuse ----------------------------------------------------

def test_shapes_broadcast_one_sun_over_n_positions():
    pos = np.tile([R + 700e3, 0.0, 0.0], (4, 1))
    assert cylindrical(pos, [AU_M, 0, 0]).shape == (4,)
    assert conical(pos, [[AU_M, 0, 0]]).shape == (4,)
    assert cylindrical(pos[0], [AU_M, 0, 0]).shape == (1,)
    assert conical(pos[0], np.tile([AU_M, 0, 0], (3, 1))).shape == (3,)


@pytest.mark.parametrize("func", [cylindrical, conical])
def test_bad_inputs_raise(func):
    good = np.array([R + 700e3, 0.0, 0.0])
    sun = np.array([AU_M, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"\(3,\) or \(N, 3\)"):
        func(np.ones((2, 2)), sun)
    with pytest.raises(ValueError, match=r"\(3,\) or \(N, 3\)"):
        func(good, np.ones(4))
    with pytest.raises(ValueError, match="non-finite"):
        func(np.array([good, [np.nan, 0, 0]]), sun)
    with pytest.raises(ValueError, match="non-finite"):
        func(good, [np.inf, 0, 0])
    with pytest.raises(ValueError, match=r"same N"):
        func(np.tile(good, (3, 1)), np.tile(sun, (2, 1)))
    with pytest.raises(ValueError, match=r"inside the Earth: \|r_sat_m\| = 7000 m"):
        func([7000.0, 0.0, 0.0], sun)  # km given as metres
    with pytest.raises(ValueError, match="zero vector"):
        func(good, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="radius_m"):
        func(good, sun, radius_m=-1.0)


def test_sunlit_is_the_whole_disc_visible():
    # One definition everywhere (evaluate, studies, pages): sunlit <=> the conical model sees all of
    # the solar disc; penumbra (0 < illumination < 1) and umbra are not sunlit.
    from simcore.environment.eclipse import sunlit
    np.testing.assert_array_equal(sunlit([1.0, 0.999999, 0.5, 0.0, np.nan]), [True, False, False, False, False])
