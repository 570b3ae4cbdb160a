"""Earth albedo at the satellite: the Bhanderi cell model, physical and toolbox-exact.

The Earth is a sphere divided into the cells of a reflectivity map
(:mod:`simcore.environment.maps`). Each cell c (centre p_c, outward normal n_c, area A_c,
reflectivity rho_c) is a Lambertian reflector; at the satellite it gives the
irradiance (SPEC sec. 3; thesis sec. 2.3.4 and 4.1.5, Bhanderi & Bak 2005)::

    E_c = E_sun * rho_c * A_c * max(0, s . n_c) * max(0, u_c . n_c) / (pi * d_c^2)

with s the unit vector to the Sun, u_c the unit vector from the cell to the
satellite and d_c that distance. :func:`albedo_cells` returns the map of E_c.

Two modes
---------
*Physical* (default): s is the true geocentric Sun direction, a cell counts
when its centre is sunlit (``s . n_c > 0``) and seen from the satellite
(``u_c . n_c > 0``), ``E_sun`` is configurable (default 1366.1 W/m^2, thesis
sec. 2.3.2) and optionally scaled by ``(1 AU / |r_sun|)^2``; the sphere's
radius is the map's. Only cells whose centre lies in the satellite's
spherical cap (``r_sat . n_c > R``) are evaluated.

*Toolbox-compatible* (``toolbox_compatible=True``) reproduces D. D. V.
Bhanderi's MATLAB Earth Albedo Toolbox (2006; ``albedo.m`` v1.28,
``earthfov.m`` v1.15, ``gridangle.m`` v1.3, ``cellarea.m`` v1.7,
``idx2rad.m`` v1.5, ``rad2idx.m`` v1.5, as vendored unchanged e.g. in
RoboticExplorationLab/EarthAlbedo.jl ``test/matlab_src``) operation for
operation. Its quirks, each with the line it comes from:

1. ``CONST.EMR = 6371.01e3; CONST.AM0 = 1366.9;`` (albedo.m) -- a sphere of
   radius 6371.01 km and E_sun fixed at 1366.9 W/m^2, no 1/r^2 scaling.
2. ``if norm(sat) < CONST.EMR, error(...)`` -- a satellite exactly on the
   surface is accepted, one below it refused.
3. ``[satsph(1) satsph(2) satsph(3)] = cart2sph(...)``, ``satsph(2) =
   pi/2 - satsph(2)`` -- azimuth ``atan2(y, x)`` in [-pi, pi], polar angle
   ``pi/2 - atan2(z, hypot(x, y))``, radius ``hypot(hypot(x, y), z)``
   (MATLAB's cart2sph).
4. ``idx2rad``: ``phi = pi-dy/2-(i-1)*dy; theta = (j-1)*dx-pi+dx/2`` with
   ``dx = 2*pi/sx``, ``dy = pi/sy`` and 1-based i, j -- row 1 is the polar
   angle ``pi - dy/2`` (the SOUTH band), column 1 the longitude
   ``-pi + dx/2``. So the toolbox's layout is the shipped maps' layout.
5. ``rad2idx``: ``i = round((pi-dy/2-phi)/dy)+1; j = round((theta+pi-dx/2)/dx)+1``
   with MATLAB's ``round`` (half away from zero) and ``if i == 0, i = 1``
   (same for j). The Sun is replaced by this cell ("sub-solar cell"); i and
   j may reach ``sy + 1`` / ``sx + 1`` (Sun exactly over the north pole or
   at azimuth +pi); the index is only fed back to ``idx2rad``, never used
   to read the map, so that is harmless and reproduced.
6. ``earthfov``: a cell is visible from a body at spherical position
   (theta0, phi0, r) when ``acos(sin(phi0)*sin(phi)*cos(theta0-theta) +
   cos(phi0)*cos(phi)) <= acos(EMR/r)`` for the cell CENTRE (non-strict).
   It is applied to the satellite AND to the true Sun position (not the
   sub-solar cell): "sunlit" means the centre is inside the Sun's
   (slightly smaller than hemispherical) cap. ``if satsph(3) < CONST.EMR,
   satsph(3) = satsph(3) + CONST.EMR`` ("LEO shortcut") adds one Earth
   radius to a body closer than the surface -- this happens to the Sun
   when it is given as a short (e.g. unit) vector, and is reproduced.
   MATLAB's ``acos`` of an argument just above 1 is complex with real part
   0 and ``<=`` compares real parts, so the argument is clipped to [-1, 1].
7. ``gridangle(i,j,sun_i,sun_j)``: the incidence angle is the angle between
   the cell centre and the sub-solar CELL centre (quirk 5), same formula as
   6; ``if phi_in > pi/2, phi_in = pi/2`` so a "sunlit" cell beyond 90 deg
   from the sub-solar cell still contributes ``cos(pi/2) = 6.1e-17`` of its
   flux (reproduced: such cells are non-zero but negligible).
8. ``cellarea``: ``A = EMR^2*dtheta*(cos(phimin)-cos(phimax))`` with
   ``dphi = (180/sy)*d2r``, ``dtheta = (360/sx)*d2r``, ``d2r = pi/180``.
9. ``E_in = irad*cellarea*cos(phi_in)``; ``grid = sph2cart(theta, pi/2-phi, EMR)``;
   ``satdist = norm(sat-grid)``; ``phi_out = acos(((sat-grid)/satdist)'*grid/norm(grid))``;
   ``P_out = E_in*refl.data(i,j)*cos(phi_out)/(pi*satdist^2)`` -- evaluated
   here in the same order of floating-point operations.

The map must be in the toolbox's layout (quirk 4: south-first, column 0 at
``-180 + dlon/2``); any resolution works, as in the toolbox.
"""
import math

import numpy as np

from simcore.constants import AU_M, E_SUN_TOOLBOX_W_M2, E_SUN_W_M2
from simcore.environment.maps import ReflectivityMap, as_map

TOOLBOX_EARTH_RADIUS_M = 6371.01e3   # albedo.m, earthfov.m, cellarea.m: CONST.EMR


def _vector(name, value):
    """Return ``value`` as a finite float64 (3,) vector or raise ValueError."""
    v = np.asarray(value, dtype=float)
    if v.size == 3 and v.ndim <= 2:
        v = v.reshape(3)                           # row or column vectors, as the toolbox accepts
    if v.shape != (3,):
        raise ValueError(f"{name} must be one ECEF position of shape (3,) in metres, got shape {v.shape}; "
                         "for many epochs use simcore.radiometry.analytic.diode_irradiance")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} has non-finite components {v.tolist()}; give a finite ECEF position in metres")
    return v


def albedo_cells(sat_ecef_m, sun_ecef_m, reflectivity=None, *, toolbox_compatible=False,
                 e_sun_w_m2=None, distance_scaling=False):
    """Return the irradiance at the satellite reflected by each map cell, W/m^2, shape (n_lat, n_lon).

    ``sat_ecef_m``, ``sun_ecef_m``: geocentric positions (3,), metres, ECEF.
    ``reflectivity``: None (the shipped TOMS 2005 annual mean), a
    :class:`~simcore.environment.maps.ReflectivityMap`, or an (n_lat, n_lon) array on the
    default global south-first grid. The result has the map's layout.

    Physical mode (default): true Sun direction, ``e_sun_w_m2`` (default
    1366.1 W/m^2), times ``(1 AU / |sun|)^2`` when ``distance_scaling``.
    ``toolbox_compatible=True``: the MATLAB Earth Albedo Toolbox exactly
    (module docstring); E_sun is then fixed at 1366.9 W/m^2.
    """
    refl = as_map(reflectivity)
    sat = _vector("sat_ecef_m", sat_ecef_m)
    sun = _vector("sun_ecef_m", sun_ecef_m)
    if not np.any(sun != 0):
        raise ValueError("sun_ecef_m is the zero vector (the Sun at the Earth's centre); give the geocentric "
                         "Sun position in metres, e.g. from simcore.environment.sun")
    if toolbox_compatible:
        if e_sun_w_m2 is not None or distance_scaling:
            raise ValueError("toolbox_compatible=True fixes E_sun at 1366.9 W/m^2 with no distance scaling, as the "
                             "MATLAB toolbox does; drop e_sun_w_m2/distance_scaling or use the physical mode")
        return toolbox_albedo(sat, sun, refl)
    e_sun = E_SUN_W_M2 if e_sun_w_m2 is None else float(e_sun_w_m2)
    if not (np.isfinite(e_sun) and e_sun >= 0):
        raise ValueError(f"e_sun_w_m2 must be a finite irradiance >= 0 W/m^2, got {e_sun_w_m2}")
    return physical_albedo(sat, sun, refl, e_sun_w_m2=e_sun, distance_scaling=distance_scaling)


def reflected_power_w(sun_ecef_m, reflectivity=None, *, e_sun_w_m2=None, distance_scaling=False):
    """Return the total power reflected by the sunlit cells, W: sum_c E_sun rho_c A_c max(0, s . n_c).

    Physical mode; a Lambertian cell sends ``E_sun rho A cos(incidence)`` into
    its hemisphere, which :func:`albedo_cells` distributes as ``cos / (pi d^2)``.
    """
    refl = as_map(reflectivity)
    sun = _vector("sun_ecef_m", sun_ecef_m)
    if np.linalg.norm(sun) <= refl.radius_m:
        raise ValueError("sun_ecef_m must lie outside the Earth; give the geocentric Sun position in metres")
    e_sun = float(sun_irradiance_w_m2(sun, E_SUN_W_M2 if e_sun_w_m2 is None else e_sun_w_m2, distance_scaling))
    cos_in = refl.normals_ecef @ (sun / np.linalg.norm(sun))
    return float(e_sun * np.sum(refl.weights_m2 * np.maximum(cos_in, 0.0)))


def check_geometry(r_sat_m, r_sun_m, radius_m):
    """Raise ValueError for a satellite inside the sphere or a Sun at (or inside) it; inputs (N, 3)."""
    dist = np.linalg.norm(r_sat_m, axis=-1)
    inside = dist < radius_m
    if np.any(inside):
        i = int(np.flatnonzero(np.atleast_1d(inside))[0])
        raise ValueError(f"the satellite is inside the Earth: |r_sat| = {np.atleast_1d(dist)[i]:.6g} m < "
                         f"R = {radius_m:.6g} m (epoch {i}); check the units (metres, not km) and the frame")
    sun = np.linalg.norm(r_sun_m, axis=-1)
    if np.any(sun <= radius_m):
        raise ValueError(f"the Sun position has |r_sun| = {np.min(sun):.6g} m, not outside the Earth; give the "
                         "geocentric Sun position in metres (not a unit vector), e.g. from simcore.environment.sun")


def sun_irradiance_w_m2(r_sun_m, e_sun_w_m2=E_SUN_W_M2, distance_scaling=False):
    """Return the solar irradiance (W/m^2): E_sun, times (1 AU / |r_sun|)^2 when ``distance_scaling``."""
    if not distance_scaling:
        return np.full(np.shape(r_sun_m)[:-1], float(e_sun_w_m2))
    return float(e_sun_w_m2) * (AU_M / np.linalg.norm(r_sun_m, axis=-1)) ** 2


def physical_albedo(sat, sun, refl: ReflectivityMap, *, e_sun_w_m2=E_SUN_W_M2, distance_scaling=False):
    """Return the physical-mode cell irradiances (n_lat, n_lon), W/m^2 (see :func:`albedo_cells`)."""
    R = refl.radius_m
    check_geometry(sat, sun, R)
    e_sun = float(sun_irradiance_w_m2(sun, e_sun_w_m2, distance_scaling))
    s = sun / np.linalg.norm(sun)
    normals = refl.normals_ecef.reshape(-1, 3)
    # Visible cell centres lie in the cap r_sat . n > R; sunlit ones have s . n > 0.
    cand = np.flatnonzero((normals @ sat > R) & (normals @ s > 0))
    out = np.zeros(refl.values.size)
    if cand.size:
        n = normals[cand]
        v = sat - R * n                              # cell -> satellite
        d2 = np.einsum("ij,ij->i", v, v)
        cos_out = np.einsum("ij,ij->i", v, n) / np.sqrt(d2)
        cos_in = n @ s
        out[cand] = (e_sun / np.pi) * refl.weights_m2.reshape(-1)[cand] * cos_in * np.maximum(cos_out, 0.0) / d2
    return out.reshape(refl.shape)


# ---- the MATLAB toolbox, operation for operation ------------------------------
def _matlab_round(x):
    """Return MATLAB's round (half away from zero) of a float."""
    t = math.trunc(x)
    frac = x - t                                   # exact in binary floating point
    if frac >= 0.5:
        return t + 1
    if frac <= -0.5:
        return t - 1
    return t


def _cart2sph(v):
    """Return MATLAB cart2sph(x, y, z) as (azimuth, elevation, r)."""
    x, y, z = (float(c) for c in v)
    hypotxy = math.hypot(x, y)
    return math.atan2(y, x), math.atan2(z, hypotxy), math.hypot(hypotxy, z)


def _rad2idx(theta, phi, sy, sx):
    """Return the toolbox's 1-based (i, j) cell of azimuth ``theta`` and polar angle ``phi`` (rad2idx.m)."""
    dx = 2 * math.pi / sx
    dy = math.pi / sy
    i = _matlab_round((math.pi - dy / 2 - phi) / dy) + 1
    j = _matlab_round((theta + math.pi - dx / 2) / dx) + 1
    return (1 if i == 0 else i), (1 if j == 0 else j)


def _idx2rad(i, j, sy, sx):
    """Return the toolbox's (theta, phi) of 1-based indices (idx2rad.m); arrays or scalars."""
    dx = 2 * np.pi / sx
    dy = np.pi / sy
    phi = np.pi - dy / 2 - (i - 1) * dy
    theta = (j - 1) * dx - np.pi + dx / 2
    return theta, phi


def _acos_real(x):
    """Return the real part of MATLAB's acos (complex outside [-1, 1])."""
    return np.arccos(np.clip(x, -1.0, 1.0))


def _earthfov(theta0, phi0, r, sy, sx):
    """Return the toolbox's visibility mask (sy, sx) of cell centres from (theta0, phi0, r) (earthfov.m)."""
    if r < TOOLBOX_EARTH_RADIUS_M:                 # the "LEO shortcut"
        r = r + TOOLBOX_EARTH_RADIUS_M
    i = np.arange(1, sy + 1, dtype=float)[:, None]
    j = np.arange(1, sx + 1, dtype=float)[None, :]
    theta, phi = _idx2rad(i, j, sy, sx)
    rho = math.acos(TOOLBOX_EARTH_RADIUS_M / r)
    rd = _acos_real(math.sin(phi0) * np.sin(phi) * np.cos(theta0 - theta) + math.cos(phi0) * np.cos(phi))
    return rd <= rho


def toolbox_albedo(sat, sun, refl: ReflectivityMap):
    """Return the MATLAB Earth Albedo Toolbox's ``albedo(sat, sun, refl)`` (n_lat, n_lon), W/m^2.

    ``sat``, ``sun``: (3,) ECEF metres. See the module docstring for each quirk.
    """
    if not refl.is_toolbox_layout:
        raise ValueError(f"toolbox_compatible=True needs a map in the toolbox's layout (row 0 the southern band, "
                         f"column 0 centred at -180 + dlon/2); {refl!r} has lat {refl.lat_deg[0]:g}.., "
                         f"lon {refl.lon_deg[0]:g}..; reorder it, or use the physical mode")
    emr = TOOLBOX_EARTH_RADIUS_M
    if math.sqrt(float(sat @ sat)) < emr:
        raise ValueError(f"the satellite is inside the Earth (|sat| = {np.linalg.norm(sat):.6g} m < "
                         f"{emr:.6g} m; the toolbox's 'The satellite has crashed into Earth!'); "
                         "check the units (metres) and the frame")
    sy, sx = refl.shape
    sat_az, sat_el, sat_r = _cart2sph(sat)
    sun_az, sun_el, sun_r = _cart2sph(sun)
    sat_phi = math.pi / 2 - sat_el
    sun_phi = math.pi / 2 - sun_el

    # MATLAB gives inf/NaN silently (a satellite exactly on the surface, over a cell centre).
    with np.errstate(divide="ignore", invalid="ignore"):
        return _toolbox_cells(sat, sy, sx, sat_az, sat_phi, sat_r, sun_az, sun_phi, sun_r, refl.values)


def _toolbox_cells(sat, sy, sx, sat_az, sat_phi, sat_r, sun_az, sun_phi, sun_r, values):
    """Return albedo.m's loop body over the union of the two earthfov masks, vectorised (quirks 5-9)."""
    emr = TOOLBOX_EARTH_RADIUS_M
    sun_i, sun_j = _rad2idx(sun_az, sun_phi, sy, sx)
    union = _earthfov(sat_az, sat_phi, sat_r, sy, sx) & _earthfov(sun_az, sun_phi, sun_r, sy, sx)
    rows, cols = np.nonzero(union)
    out = np.zeros((sy, sx))
    if rows.size == 0:
        return out
    i = rows + 1.0
    j = cols + 1.0
    theta, phi = _idx2rad(i, j, sy, sx)

    # gridangle(i, j, sun_i, sun_j, sy, sx)
    theta2, phi2 = _idx2rad(float(sun_i), float(sun_j), sy, sx)
    phi_in = _acos_real(np.sin(phi) * math.sin(phi2) * np.cos(theta - theta2) + np.cos(phi) * math.cos(phi2))
    phi_in = np.where(phi_in > np.pi / 2, np.pi / 2, phi_in)

    # cellarea(i, j, sy, sx)
    d2r = np.pi / 180
    dphi = (180 / sy) * d2r
    dtheta = (360 / sx) * d2r
    area = emr ** 2 * dtheta * (np.cos(phi - dphi / 2) - np.cos(phi + dphi / 2))

    e_in = E_SUN_TOOLBOX_W_M2 * area * np.cos(phi_in)

    # sph2cart(grid_theta, pi/2 - grid_phi, EMR)
    elev = np.pi / 2 - phi
    gz = emr * np.sin(elev)
    rcoselev = emr * np.cos(elev)
    gx = rcoselev * np.cos(theta)
    gy = rcoselev * np.sin(theta)

    vx, vy, vz = sat[0] - gx, sat[1] - gy, sat[2] - gz
    satdist = np.sqrt(vx * vx + vy * vy + vz * vz)
    gnorm = np.sqrt(gx * gx + gy * gy + gz * gz)
    phi_out = _acos_real(((vx / satdist) * gx + (vy / satdist) * gy + (vz / satdist) * gz) / gnorm)
    out[rows, cols] = e_in * values[rows, cols] * np.cos(phi_out) / (np.pi * satdist ** 2)
    return out
