"""The geocentric Sun: apparent position in GCRS and ITRS (ECEF), metres.

Ephemeris: ``erfa.epv00`` (the SOFA Earth position/velocity series, Earth
heliocentric and barycentric, BCRS axes = ICRS; heliocentric position error
3.7 km RMS, 11.2 km max over 1900-2100 vs JPL DE405, i.e. < 0.016" in
direction: far better than the thesis' 0.01 deg model).

What "the Sun position" means here (a sun sensor sees *light*):

* light time: the light reaching the Earth at ``t`` left the Sun at ``t - tau``,
  ``tau = |r| / c`` ~ 499 s. The Sun's barycentric position is taken at that
  retarded time (the Sun moves ~10 m/s about the barycentre, so this moves it
  ~5 km: 7e-9 rad, negligible but free);
* annual aberration: the observer moves ~30 km/s about the barycentre, so the
  light arrives from a direction displaced by up to 20.5" (0.0057 deg) toward
  the direction of motion (``erfa.ab``, relativistic). That apparent
  direction is what a sun sensor on a body moving with the Earth measures,
  and also the axis of the Earth's shadow in the geocentric frame, so it is
  applied by default (``aberration=True``); the distance is the light-time
  distance. The satellite's own orbital velocity (~7.5 km/s, up to 5") is
  not included (a per-satellite, sub-0.002-deg effect, far below sensor
  accuracy), nor the parallax: callers form ``r_sun - r_sat`` themselves.

Speed: the ephemeris is evaluated on a coarse TT grid (``SUN_GRID_STEP_S`` =
1 h) and interpolated with a cubic (4-point Lagrange) per component; the
Sun's geocentric motion (1 deg/day plus the 4670 km monthly wobble of the
Earth about the Earth-Moon barycentre) leaves an interpolation error below
1e-9 deg, bounded against per-epoch evaluation in tests/environment/test_sun.py.
"""
import erfa
import numpy as np

from simcore.environment import frames
from simcore.constants import AU_M
from simcore.environment.epochs import Epochs

SUN_GRID_STEP_S = 3600.0
C_AU_PER_DAY = 299_792_458.0 * 86400.0 / AU_M   # speed of light, au/day


def _sun_gcrs_au(tt1, tt2, aberration=True):
    """Return (N, 3) apparent geocentric Sun position (au, GCRS axes) at TT ``tt1 + tt2``."""
    pvh, pvb = erfa.epv00(tt1, tt2)
    e_helio, e_bary = pvh["p"], pvb["p"]
    sun_bary = e_bary - e_helio
    sun_bary_vel = pvb["v"] - pvh["v"]
    tau_days = np.linalg.norm(e_helio, axis=-1) / C_AU_PER_DAY
    # Sun at the retarded time t - tau (one iteration is exact to < 1 mm: tau changes < 1e-6 s).
    p = sun_bary - tau_days[:, None] * sun_bary_vel - e_bary
    tau_days = np.linalg.norm(p, axis=-1) / C_AU_PER_DAY
    p = sun_bary - tau_days[:, None] * sun_bary_vel - e_bary
    if not aberration:
        return p
    dist = np.linalg.norm(p, axis=-1)
    v_c = pvb["v"] / C_AU_PER_DAY
    bm1 = np.sqrt(1.0 - np.sum(v_c * v_c, axis=-1))
    u = erfa.ab(p / dist[:, None], v_c, dist, bm1)
    return u * dist[:, None]


def sun_position_gcrs_m(epochs, *, aberration=True, exact=False):
    """Return (N, 3) the apparent geocentric Sun position in GCRS, metres (light time + annual aberration).

    ``epochs``: anything :meth:`Epochs.from_any` accepts. ``exact=True``
    evaluates the ephemeris at every epoch instead of on the 1-h grid.
    """
    epochs = Epochs.from_any(epochs)
    tt1, tt2 = epochs.tt()
    if exact:
        return _sun_gcrs_au(tt1, tt2, aberration) * AU_M
    return frames.smooth_on_grid(lambda a, b: _sun_gcrs_au(a, b, aberration), tt1, tt2, SUN_GRID_STEP_S) * AU_M


def sun_position_ecef_m(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, *, aberration=True):
    """Return (N, 3) the apparent geocentric Sun position in ITRS (ECEF), metres.

    GCRS -> ITRS with :func:`simcore.environment.frames.R_itrs_from_gcrs` (``dut1_s`` =
    UT1 - UTC in s, polar motion in rad; the zero defaults rotate the Sun's
    longitude by at most 0.9 s x 15"/s = 13.5", see :mod:`simcore.environment.frames`).
    """
    epochs = Epochs.from_any(epochs)
    R = frames.R_itrs_from_gcrs(epochs, dut1_s, xp_rad, yp_rad)
    return np.einsum("nij,nj->ni", R, sun_position_gcrs_m(epochs, aberration=aberration))


def sun_direction_gcrs(epochs, *, aberration=True):
    """Return (N, 3) unit vectors from the Earth's centre toward the apparent Sun, GCRS."""
    r = sun_position_gcrs_m(epochs, aberration=aberration)
    return r / np.linalg.norm(r, axis=-1, keepdims=True)
