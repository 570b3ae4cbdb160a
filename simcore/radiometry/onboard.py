"""What the satellite itself can compute: an on-board albedo prediction, and its honest evaluation.

The thesis' albedo-aware estimators (Albedo-Sun, Sun-Albedo-Sun, sec. 4.3.3-4.3.4)
estimate the Earth light from the readings alone. On board, more is known: the
orbit (TLE + clock -> SGP4 position), the Sun (ephemeris + clock) and, from the
attitude filter, the previous attitude. With an on-board reflectivity map the
Bhanderi model (:mod:`simcore.radiometry.analytic`) then *predicts* the albedo each diode
reads; :func:`estimators.advanced.model_albedo_estimate` subtracts it.

Honesty rules of this module:

- the attitude fed to the prediction is never the truth of the same epoch:
  :func:`previous_attitude` gives the attitude of ``lag_steps`` samples earlier
  (1 s stale while tumbling at 1.9 deg/s: 1.9 deg wrong), optionally rotated by
  a random error (a rotation vector with independent N(0, sigma^2) components
  in the body frame, so the RMS error angle is sigma sqrt(3)), seeded;
- the on-board map is not the map the "truth" irradiance was made with
  (:func:`simcore.studies.cross_map.evaluate_cross_map` predicts with TOMS 2005 what was made with
  CERES 2018 all-sky, and the reverse).
"""
import numpy as np

from simcore.radiometry import analytic
from simcore.constants import E_SUN_W_M2
from simcore.environment.earth import Earth
from simcore.environment.maps import as_map
from simcore.radiometry.band import resolve_map



def previous_attitude(R_gcrs_from_body, *, lag_steps=1, sigma_deg=0.0, seed=0):
    """Return the on-board attitude estimate R_gcrs_from_body (N, 3, 3): the attitude ``lag_steps`` samples earlier.

    Row n is ``R[n - lag_steps] @ Rot(omega_n)`` with ``omega_n`` a rotation vector (body frame)
    of independent N(0, (sigma_deg)^2) components, drawn from ``numpy.random.default_rng(seed)``.
    The first ``lag_steps`` rows have no earlier attitude and are NaN (the prediction there is
    NaN and the estimator flags those epochs invalid). ``lag_steps=0`` with ``sigma_deg=0`` is
    the truth and is refused: that would not be an on-board estimate.
    """
    R = np.asarray(R_gcrs_from_body, dtype=float)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R_gcrs_from_body must be (N, 3, 3) rotation matrices, got shape {R.shape}")
    if int(lag_steps) != lag_steps or lag_steps < 0:
        raise ValueError(f"lag_steps must be a non-negative integer number of samples, got {lag_steps}")
    if not (np.isfinite(sigma_deg) and sigma_deg >= 0):
        raise ValueError(f"sigma_deg must be a non-negative angle in degrees, got {sigma_deg}")
    lag = int(lag_steps)
    if lag == 0 and sigma_deg == 0:
        raise ValueError("lag_steps=0 and sigma_deg=0 would feed the true attitude to the on-board model; "
                         "give lag_steps >= 1 (the previous estimate) and/or an attitude error sigma_deg > 0")
    out = np.full_like(R, np.nan)
    if lag < R.shape[0]:
        out[lag:] = R[:R.shape[0] - lag]
    if sigma_deg > 0:
        rng = np.random.default_rng(seed)
        omega = rng.normal(0.0, np.radians(float(sigma_deg)), size=(R.shape[0], 3))
        out = out @ _rotation_matrices(omega)
    return out


def _rotation_matrices(omega):
    """Return the rotations (N, 3, 3) of rotation vectors omega (N, 3) (Rodrigues' formula)."""
    angle = np.linalg.norm(omega, axis=1)
    axis = omega / np.where(angle > 0, angle, 1.0)[:, None]
    kx = np.zeros((omega.shape[0], 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    kx = kx - np.swapaxes(kx, 1, 2)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)


def _geometry_arrays(geometry):
    names = ("r_sat_ecef_m", "r_sun_ecef_m", "R_ecef_from_gcrs")
    try:
        if isinstance(geometry, dict):
            arrs = [np.asarray(geometry[k], dtype=float) for k in names]
        else:
            arrs = [np.asarray(getattr(geometry, k), dtype=float) for k in names]
    except (KeyError, AttributeError):
        raise TypeError(f"geometry must be a simcore.environment.geometry.StudyGeometry or a dict with {names} (N-leading arrays, "
                        "ECEF metres and GCRS->ECEF rotations)") from None
    return arrs


def _diodes(diodes):
    if hasattr(diodes, "frames") and hasattr(diodes, "apertures"):
        return np.asarray(diodes.frames, dtype=float), list(diodes.apertures)
    try:
        frames, responses = diodes
    except (TypeError, ValueError):
        raise TypeError("diodes must be a scenes.config.SatelliteConfig or a tuple (frames (K, 3, 3), responses)") \
            from None
    return np.asarray(frames, dtype=float), responses


def on_board_earth(earth):
    """Return the on-board :class:`simcore.environment.earth.Earth`: ``earth`` itself, or the Earth of a map (a
    :class:`simcore.environment.maps.ReflectivityMap`, a name in :data:`simcore.environment.maps.MAP_NAMES` or a band
    map such as ``'band'``, :func:`simcore.radiometry.band.resolve_map`) without glint."""
    if isinstance(earth, Earth):
        return earth
    return Earth(resolve_map(earth) if isinstance(earth, str) else as_map(earth))


def predict_albedo_effective(geometry, R_gcrs_from_body_est, diodes, earth, *, e_s0_w_m2=188.1,
                             e_sun_w_m2=E_SUN_W_M2, backend="auto"):
    """Return the predicted albedo on each diode (N, K), effective W/m^2 (the units of E_p, eq. 4.25).

    ``geometry``: what the satellite knows from its TLE and clock, a
    :class:`simcore.environment.geometry.StudyGeometry` or a dict with ``r_sat_ecef_m``, ``r_sun_ecef_m`` (N, 3)
    and ``R_ecef_from_gcrs`` (N, 3, 3); ``R_gcrs_from_body_est`` (N, 3, 3): the on-board
    attitude estimate (e.g. :func:`previous_attitude`; NaN rows give NaN predictions);
    ``diodes``: a :class:`scenes.config.SatelliteConfig` or ``(frames (K, 3, 3), responses)``;
    ``earth``: the on-board Earth (:func:`on_board_earth`: an :class:`simcore.environment.earth.Earth`, or a map
    or a map's name). The Bhanderi sum of :func:`simcore.radiometry.analytic.diode_irradiance`
    (W/m^2 at the solar constant ``e_sun_w_m2``) is scaled by E_S0 / E_sun like the Earth
    light in the sensor chain (thesis sec. 4.2.1).
    """
    r_sat, r_sun, R_ecef_from_gcrs = _geometry_arrays(geometry)
    R_est = np.asarray(R_gcrs_from_body_est, dtype=float)
    n_ep = r_sat.shape[0]
    if R_est.shape != (n_ep, 3, 3):
        raise ValueError(f"R_gcrs_from_body_est must be (N, 3, 3) with N = {n_ep} (one per epoch of the "
                         f"geometry), got shape {R_est.shape}")
    frames, responses = _diodes(diodes)
    earth = on_board_earth(earth)
    out = np.full((n_ep, frames.shape[0]), np.nan)
    ok = np.all(np.isfinite(R_est), axis=(1, 2))
    if ok.any():
        R_ecef_from_body = R_ecef_from_gcrs[ok] @ R_est[ok]
        irr = analytic.diode_irradiance(r_sat[ok], r_sun[ok], R_ecef_from_body, frames, responses, earth=earth,
                                        e_sun_w_m2=e_sun_w_m2, eclipse=None, backend=backend)
        out[ok] = irr.albedo_w_m2 * (float(e_s0_w_m2) / float(e_sun_w_m2))
    return out
