"""The environment of a study: orbit, attitude, Sun and Earth geometry per epoch.

One call turns (orbit, epochs, attitude) into every time-tagged vector the
renderer, the analytic model and the estimators consume, in one place, so all
of them see the same instants and the same frames.
"""
from dataclasses import dataclass

import numpy as np

from simcore.environment import attitude as _attitude
from simcore.environment import eclipse, frames, sun
from simcore.constants import AU_M, R_EARTH_MEAN_M
from simcore.environment.epochs import Epochs
from simcore.environment.orbit import Orbit

DEFAULT_START = "2016-07-02T00:00:00Z"   # the thesis' simulation start (table 4.3)
DEFAULT_STEP_S = 1.0


@dataclass(frozen=True)
class StudyGeometry:
    """Time-tagged geometry of a study, arrays with time leading (N, ...), SI units."""

    epochs: Epochs
    t_s: np.ndarray                 # (N,) seconds since the first epoch
    r_sat_gcrs_m: np.ndarray        # (N, 3)
    v_sat_gcrs_m_s: np.ndarray      # (N, 3)
    r_sat_ecef_m: np.ndarray        # (N, 3)
    r_sun_gcrs_m: np.ndarray        # (N, 3) geocentric
    r_sun_ecef_m: np.ndarray        # (N, 3) geocentric
    R_ecef_from_gcrs: np.ndarray    # (N, 3, 3)
    R_gcrs_from_body: np.ndarray    # (N, 3, 3)
    illumination: np.ndarray        # (N,) visible fraction of the solar disc (conical shadow)
    sunlit_cylindrical: np.ndarray  # (N,) bool, thesis eqs. 4.6-4.10
    error_code: np.ndarray          # (N,) SGP4 error code, 0 = fine

    def __len__(self):
        return len(self.epochs)

    @property
    def R_ecef_from_body(self):
        """Return (N, 3, 3) rotations body -> ECEF (ITRS)."""
        return self.R_ecef_from_gcrs @ self.R_gcrs_from_body

    @property
    def R_body_from_gcrs(self):
        return np.swapaxes(self.R_gcrs_from_body, -1, -2)

    @property
    def sun_from_sat_gcrs_m(self):
        """Return (N, 3) the satellite -> Sun vector in GCRS (parallax included)."""
        return self.r_sun_gcrs_m - self.r_sat_gcrs_m

    @property
    def sun_dir_gcrs(self):
        """Return (N, 3) unit satellite -> Sun direction in GCRS."""
        v = self.sun_from_sat_gcrs_m
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    @property
    def sun_dir_body(self):
        """Return (N, 3) unit satellite -> Sun direction in the body frame."""
        return np.einsum("nij,nj->ni", self.R_body_from_gcrs, self.sun_dir_gcrs)

    @property
    def earth_center_body_m(self):
        """Return (N, 3) the Earth's centre in the body frame, satellite at the origin (metres)."""
        return -np.einsum("nij,nj->ni", self.R_body_from_gcrs, self.r_sat_gcrs_m)

    @property
    def sun_distance_scale(self):
        """Return (N,) (1 AU / |satellite -> Sun|)^2, the 1/r^2 factor on the solar constant."""
        return (AU_M / np.linalg.norm(self.sun_from_sat_gcrs_m, axis=-1)) ** 2

    @property
    def valid(self):
        """Return (N,) bool: the orbit state is usable (SGP4 reported no error)."""
        return self.error_code == 0


def compute_geometry(orbit=None, epochs=None, attitude=None, *, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0,
                     earth_radius_m=R_EARTH_MEAN_M):
    """Return the :class:`StudyGeometry` of ``orbit`` at ``epochs`` with ``attitude``.

    Defaults: the shipped ESTCube-1 TLE, one day from 2016-07-02T00:00Z at 1 s,
    and the thesis' tumble (1.9 deg/s, see :func:`simcore.environment.attitude.tumble`).
    """
    orbit = Orbit.default() if orbit is None else orbit
    epochs = Epochs.range(DEFAULT_START, 86400, DEFAULT_STEP_S) if epochs is None else Epochs.from_any(epochs)
    t_s = epochs.seconds_since(epochs[0])
    if attitude is None:
        attitude = _attitude.tumble(t_s)
    if len(attitude) != len(epochs):
        raise ValueError(f"the attitude history has {len(attitude)} epochs but the study has {len(epochs)}; "
                         "give one attitude per epoch (or resample it onto the study's epochs)")
    kw = dict(dut1_s=dut1_s, xp_rad=xp_rad, yp_rad=yp_rad)
    state = orbit.propagate(epochs, **kw)
    R_ecef_from_gcrs = frames.R_itrs_from_gcrs(epochs, **kw)
    r_sun_gcrs = sun.sun_position_gcrs_m(epochs)
    r_sun_ecef = np.einsum("nij,nj->ni", R_ecef_from_gcrs, r_sun_gcrs)
    ok = state.error_code == 0
    illum = np.full(len(epochs), np.nan)
    lit = np.zeros(len(epochs), dtype=bool)
    if ok.any():
        illum[ok] = eclipse.conical(state.r_gcrs_m[ok], r_sun_gcrs[ok], radius_m=earth_radius_m)
        lit[ok] = eclipse.cylindrical(state.r_gcrs_m[ok], r_sun_gcrs[ok], radius_m=earth_radius_m)
    return StudyGeometry(
        epochs=epochs, t_s=t_s,
        r_sat_gcrs_m=state.r_gcrs_m, v_sat_gcrs_m_s=state.v_gcrs_m_s, r_sat_ecef_m=state.r_ecef_m,
        r_sun_gcrs_m=r_sun_gcrs, r_sun_ecef_m=r_sun_ecef,
        R_ecef_from_gcrs=R_ecef_from_gcrs, R_gcrs_from_body=attitude.R_gcrs_from_body,
        illumination=illum, sunlit_cylindrical=lit, error_code=state.error_code,
    )


def orbital_period_s(orbit):
    """Return the orbit's period (s): a TLE's anomalistic period from its mean motion, an ephemeris's Keplerian
    period of its first state (``orbit.period_s``)."""
    return orbit.period_s


def eclipse_events(geometry):
    """Return a list of (kind, t_s) transitions: 'penumbra-entry', 'umbra-entry', 'umbra-exit', 'penumbra-exit'."""
    f = geometry.illumination
    t = geometry.t_s
    state = np.where(f >= 1.0, 2, np.where(f <= 0.0, 0, 1))
    events = []
    for i in np.flatnonzero(np.diff(state) != 0):
        a, b = state[i], state[i + 1]
        if a == 2 and b <= 1:
            events.append(("penumbra-entry", t[i + 1]))
        if a >= 1 and b == 0:
            events.append(("umbra-entry", t[i + 1]))
        if a == 0 and b >= 1:
            events.append(("umbra-exit", t[i + 1]))
        if a <= 1 and b == 2:
            events.append(("penumbra-exit", t[i + 1]))
    return events


def one_orbit_geometry(*, step_s=10.0, start=None, orbit=None):
    """Return the :class:`simcore.environment.geometry.StudyGeometry` of one orbital period (default ESTCube-1 from the thesis'
    start, thesis tumble) at ``step_s``."""
    orbit = Orbit.default() if orbit is None else orbit
    period = orbital_period_s(orbit)
    return compute_geometry(orbit, Epochs.range(DEFAULT_START if start is None else start, period, float(step_s)))
