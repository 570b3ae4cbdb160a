"""Earth shadow on the satellite: the thesis' cylinder and the exact conical shadow.

Both functions are frame-agnostic: ``r_sat_m`` and ``r_sun_m`` are
geocentric positions in metres, expressed in the SAME frame (GCRS, TEME or
ITRS all work, the geometry is a rigid-motion invariant), shape ``(N, 3)`` or
``(3,)``. A single ``(3,)`` vector (or a ``(1, 3)`` row) broadcasts against
``N`` rows of the other argument, e.g. a fixed Sun along an orbit. The Earth
is a sphere of radius ``radius_m`` (default the thesis' mean radius
6371.01 km, eq. 4.6), the Sun a sphere of radius ``sun_radius_m``.

* :func:`cylindrical` -- the thesis' shadow test (sec. 4.1.4, eqs. 4.6-4.10):
  a Sun at infinity, the shadow a cylinder of radius R behind the Earth;
  illuminated or not.
* :func:`conical` -- the illuminated fraction of the solar disc (0 in the
  umbra, 1 in full sunlight, in between in the penumbra, or an annular
  eclipse far from the Earth), from the exact overlap of the Earth's and the
  Sun's discs on the satellite's sky.

Inputs are checked: a wrong shape or non-finite value is misuse and raises
:class:`ValueError`, as does a satellite at or below the Earth's surface
(a decayed or mis-framed orbit: the shadow is then undefined).
"""
import numpy as np

from simcore.constants import R_EARTH_MEAN_M, R_SUN_M


def sunlit(illumination):
    """Return (N,) bool: the epochs sunsim calls sunlit, where the whole solar disc is visible
    (``illumination`` >= 1, the conical model's visible fraction of the disc; penumbra is not sunlit).

    The one definition used by every evaluation, study and results page, so that one run gives one
    set of sunlit statistics everywhere (the thesis' cylindrical shadow, eqs. 4.6-4.10, is stored
    beside it as ``sunlit_cylindrical`` for comparison only).
    """
    return np.asarray(illumination, dtype=float) >= 1.0


def _as_rows(name, value):
    """Return ``value`` as float64 (M, 3) with M >= 1, or raise ValueError."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1 and arr.shape == (3,):
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] == 0:
        raise ValueError(f"{name} must be a position of shape (3,) or (N, 3) in metres, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        raise ValueError(f"{name} has non-finite values in rows {bad[:10].tolist()}"
                         f"{' ...' if bad.size > 10 else ''}; drop or fill those epochs first "
                         "(e.g. SGP4 error rows) before computing the shadow")
    return arr


def _prepare(r_sat_m, r_sun_m, radius_m):
    """Return broadcast (N, 3) satellite and Sun positions and the checked radius."""
    radius_m = float(radius_m)
    if not (np.isfinite(radius_m) and radius_m > 0):
        raise ValueError(f"radius_m must be a positive, finite length in metres, got {radius_m}")
    r_sat = _as_rows("r_sat_m", r_sat_m)
    r_sun = _as_rows("r_sun_m", r_sun_m)
    try:
        r_sat, r_sun = np.broadcast_arrays(r_sat, r_sun)
    except ValueError:
        raise ValueError(f"r_sat_m has {r_sat.shape[0]} rows and r_sun_m {r_sun.shape[0]}; give both with "
                         "the same N epochs, or one of them as a single (3,) vector") from None
    dist = np.linalg.norm(r_sat, axis=1)
    inside = dist <= radius_m
    if np.any(inside):
        i = int(np.flatnonzero(inside)[0])
        raise ValueError(f"the satellite is inside the Earth: |r_sat_m| = {dist[i]:.6g} m <= radius_m = "
                         f"{radius_m:.6g} m at row {i} ({int(inside.sum())} such rows); check the units "
                         "(metres, not km) and that the orbit has not decayed")
    sun_norm = np.linalg.norm(r_sun, axis=1)
    if np.any(sun_norm == 0):
        raise ValueError("r_sun_m has a zero vector; give the geocentric Sun position in metres")
    return r_sat, r_sun, dist, sun_norm, radius_m


def cylindrical(r_sat_m, r_sun_m, radius_m=R_EARTH_MEAN_M):
    """Return True where the satellite is sunlit under the cylindrical shadow, bool (N,) (eqs. 4.6-4.10).

    The thesis (sec. 4.1.4) defines, with ``d = r_sun / |r_sun|``::

        theta_crit = arccos(R / |r_sat|)                      (4.6)
        h          = -r_sat . d = |r_sat| sin(theta)          (4.7, 4.8)
        theta      = arcsin(-r_sat . d / |r_sat|)             (4.9)

    i.e. ``theta`` in [-90, 90] deg is the elevation of the satellite behind
    the terminator plane (positive on the night side). The text says the Sun
    vector is set to zero "when theta is larger than theta_crit"; eq. 4.10 as
    printed has its two cases swapped (it would light the night side), so
    the text is the rule used here: **shadow iff theta > theta_crit**.

    That rule is exactly the true cylinder test. ``theta > theta_crit >= 0``
    requires ``theta > 0``, i.e. ``r_sat . d < 0`` (behind the Earth), and for
    ``theta, theta_crit`` in [0, 90] deg, where cos is decreasing,
    ``theta > theta_crit <=> |r_sat| cos(theta) < R``; ``|r_sat| cos(theta)``
    is the distance of the satellite from the Earth-Sun line. So it is
    evaluated here in that algebraically equivalent, well-conditioned form::

        shadow  <=>  r_sat . d < 0  and  |r_sat|^2 - (r_sat . d)^2 < R^2

    (no arcsin/arccos near +-1). On the boundary (distance exactly R) the
    satellite counts as sunlit, as the thesis' strict inequality says. Only
    the Sun's direction enters: the Sun is at infinity and a point, so there
    is no penumbra -- see :func:`conical` for that.

    Parameters
    ----------
    r_sat_m, r_sun_m : array_like, (N, 3) or (3,)
        Geocentric satellite and Sun positions, metres, same frame.
    radius_m : float
        Radius of the shadowing sphere (default the thesis' EMR, 6371.01 km).
    """
    r_sat, r_sun, dist, sun_norm, radius_m = _prepare(r_sat_m, r_sun_m, radius_m)
    d_sun = r_sun / sun_norm[:, None]
    along = np.einsum("ij,ij->i", r_sat, d_sun)
    # |r|^2 - (r.d)^2 as the squared norm of the perpendicular part avoids cancellation.
    perp = r_sat - along[:, None] * d_sun
    perp2 = np.einsum("ij,ij->i", perp, perp)
    shadow = (along < 0.0) & (perp2 < radius_m * radius_m)
    return ~shadow


def _half_angle(s, x, y, z):
    """Return the spherical-triangle angle opposite side x (rad), by the half-angle formula.

    ``tan(A/2) = sqrt(sin(s-y) sin(s-z) / (sin s sin(s-x)))``, ``s`` the half
    perimeter: well conditioned for angles near 0 and pi, unlike arccos of
    the law of cosines.
    """
    num = np.sqrt(np.clip(np.sin(s - y) * np.sin(s - z), 0.0, None))
    den = np.sqrt(np.clip(np.sin(s) * np.sin(s - x), 0.0, None))
    return 2.0 * np.arctan2(num, den)


def _cap_overlap_sr(a, b, c):
    """Return the solid angle (sr) shared by two spherical caps of angular radii a, b
    whose centres are c apart, for partial overlap |a - b| < c < a + b <= pi.

    Gauss-Bonnet on the lens bounded by the two small circles; with alpha,
    beta the angles at the two centres and E the spherical excess of the
    triangle (centre_a, centre_b, crossing point)::

        A = 2 (pi - P - alpha cos a - beta cos b)
          = 4 alpha sin^2(a/2) + 4 beta sin^2(b/2) - 2 E

    (P the angle at the crossing point, alpha + beta + P = pi + E). The
    second form has no cancellation for tiny caps; its small-angle limit is
    the planar circular-segment formula a^2 alpha + b^2 beta - c y of
    Montenbruck & Gill (2000), eq. 3.94.
    """
    s = 0.5 * (a + b + c)
    alpha = _half_angle(s, b, a, c)  # at the centre of cap a, opposite side b
    beta = _half_angle(s, a, b, c)   # at the centre of cap b, opposite side a
    # L'Huilier: tan(E/4) = sqrt(tan(s/2) tan((s-a)/2) tan((s-b)/2) tan((s-c)/2))
    prod = np.tan(0.5 * s) * np.tan(0.5 * (s - a)) * np.tan(0.5 * (s - b)) * np.tan(0.5 * (s - c))
    excess = 4.0 * np.arctan(np.sqrt(np.clip(prod, 0.0, None)))
    return 4.0 * alpha * np.sin(0.5 * a) ** 2 + 4.0 * beta * np.sin(0.5 * b) ** 2 - 2.0 * excess


def conical(r_sat_m, r_sun_m, radius_m=R_EARTH_MEAN_M, sun_radius_m=R_SUN_M):
    """Return the illuminated fraction of the solar disc seen from the satellite, float (N,) in [0, 1].

    The conical (umbra/penumbra) shadow model of Montenbruck & Gill,
    "Satellite Orbits" (Springer 2000), sec. 3.4.2: from the satellite the
    Sun and the Earth are discs of apparent angular radii::

        a = arcsin(R_sun / |r_sun - r_sat|)      (Sun)
        b = arcsin(R / |r_sat|)                 (Earth)

    whose centres are ``c`` apart (angle between ``-r_sat`` and
    ``r_sun - r_sat``). With ``A`` the solid angle of the Sun's disc hidden
    by the Earth's, the fraction is ``nu = 1 - A / (2 pi (1 - cos a))``:

    * ``c >= a + b``: no overlap, ``nu = 1`` (full sunlight);
    * ``c <= b - a``: the Sun is wholly behind the Earth, ``nu = 0`` (umbra);
    * ``c <= a - b``: the Earth lies inside the Sun's disc (annular eclipse,
      only beyond ~1.37e9 m where the Earth looks smaller than the Sun),
      ``nu = 1 - sin^2(b/2) / sin^2(a/2)``;
    * otherwise the discs partly overlap (penumbra).

    The discs are the exact tangent cones of two spheres, i.e. spherical
    caps, and their overlap is computed EXACTLY on the sphere
    (:func:`_cap_overlap_sr`). Montenbruck & Gill's eqs. 3.92-3.94 use the
    planar circular-segment formula with the same a, b, c, which is its
    small-angle limit; seen from LEO the Earth's disc is ~130 deg wide
    (b ~ 64 deg at 700 km), and the planar formula then misstates the
    penumbral fraction by up to ~2e-4 of the disc (the Earth's limb is
    less curved on the sphere than a planar circle of radius b). The solar disc is taken as uniformly bright (no limb
    darkening) and the Earth as an airless sphere (no refraction).

    Parameters
    ----------
    r_sat_m, r_sun_m : array_like, (N, 3) or (3,)
        Geocentric satellite and Sun positions, metres, same frame.
    radius_m : float
        Radius of the Earth sphere (default the thesis' EMR, 6371.01 km).
    sun_radius_m : float
        Solar radius (default IAU 2015 nominal, 695 700 km).
    """
    r_sat, r_sun, dist, _, radius_m = _prepare(r_sat_m, r_sun_m, radius_m)
    sun_radius_m = float(sun_radius_m)
    if not (np.isfinite(sun_radius_m) and sun_radius_m > 0):
        raise ValueError(f"sun_radius_m must be a positive, finite length in metres, got {sun_radius_m}")
    to_sun = r_sun - r_sat
    sun_dist = np.linalg.norm(to_sun, axis=1)
    if np.any(sun_dist <= sun_radius_m):
        i = int(np.flatnonzero(sun_dist <= sun_radius_m)[0])
        raise ValueError(f"the satellite is inside the Sun (distance {sun_dist[i]:.6g} m <= sun_radius_m "
                         f"at row {i}); r_sun_m must be the geocentric Sun position in metres")
    a = np.arcsin(sun_radius_m / sun_dist)
    b = np.arcsin(radius_m / dist)
    # Angle between -r_sat and to_sun by atan2: accurate at all separations.
    cross = np.cross(-r_sat, to_sun)
    c = np.arctan2(np.linalg.norm(cross, axis=1), np.einsum("ij,ij->i", -r_sat, to_sun))

    sun_cap = 4.0 * np.sin(0.5 * a) ** 2  # solid angle / (pi), 2 pi (1 - cos a) = 4 pi sin^2(a/2)
    hidden = np.zeros_like(a)
    umbra = c <= b - a
    annular = c <= a - b
    partial = ~umbra & ~annular & (c < a + b)
    hidden[umbra] = sun_cap[umbra]
    hidden[annular] = 4.0 * np.sin(0.5 * b[annular]) ** 2
    if np.any(partial):
        hidden[partial] = _cap_overlap_sr(a[partial], b[partial], c[partial]) / np.pi
    return np.clip(1.0 - hidden / sun_cap, 0.0, 1.0)
