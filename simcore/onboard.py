"""What the satellite itself can compute: an on-board albedo prediction, and its honest evaluation.

The thesis' albedo-aware estimators (Albedo-Sun, Sun-Albedo-Sun, sec. 4.3.3-4.3.4)
estimate the Earth light from the readings alone. On board, more is known: the
orbit (TLE + clock -> SGP4 position), the Sun (ephemeris + clock) and, from the
attitude filter, the previous attitude. With an on-board reflectivity map the
Bhanderi model (:mod:`simcore.analytic`) then *predicts* the albedo each diode
reads; :func:`estimators.advanced.model_albedo_estimate` subtracts it.

Honesty rules of this module:

- the attitude fed to the prediction is never the truth of the same epoch:
  :func:`previous_attitude` gives the attitude of ``lag_steps`` samples earlier
  (1 s stale while tumbling at 1.9 deg/s: 1.9 deg wrong), optionally rotated by
  a random error (a rotation vector with independent N(0, sigma^2) components
  in the body frame, so the RMS error angle is sigma sqrt(3)), seeded;
- the on-board map is not the map the "truth" irradiance was made with
  (:func:`evaluate_cross_map` predicts with TOMS 2005 what was made with
  CERES 2018 all-sky, and the reverse).
"""
import numpy as np

from simcore import analytic
from simcore.constants import E_SUN_W_M2
from simcore.maps import as_map, named_map



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
        raise TypeError(f"geometry must be a simcore.study.Geometry or a dict with {names} (N-leading arrays, "
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


def predict_albedo_effective(geometry, R_gcrs_from_body_est, diodes, reflectivity_map, *, e_s0_w_m2=188.1,
                             e_sun_w_m2=E_SUN_W_M2, backend="auto"):
    """Return the predicted albedo on each diode (N, K), effective W/m^2 (the units of E_p, eq. 4.25).

    ``geometry``: what the satellite knows from its TLE and clock, a
    :class:`simcore.study.Geometry` or a dict with ``r_sat_ecef_m``, ``r_sun_ecef_m`` (N, 3)
    and ``R_ecef_from_gcrs`` (N, 3, 3); ``R_gcrs_from_body_est`` (N, 3, 3): the on-board
    attitude estimate (e.g. :func:`previous_attitude`; NaN rows give NaN predictions);
    ``diodes``: a :class:`scenes.config.SatelliteConfig` or ``(frames (K, 3, 3), responses)``;
    ``reflectivity_map``: the on-board map (a :class:`simcore.maps.ReflectivityMap` or a name
    in :data:`simcore.maps.MAP_NAMES`). The Bhanderi sum of :func:`simcore.analytic.diode_irradiance`
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
    refl = named_map(reflectivity_map) if isinstance(reflectivity_map, str) else as_map(reflectivity_map)
    out = np.full((n_ep, frames.shape[0]), np.nan)
    ok = np.all(np.isfinite(R_est), axis=(1, 2))
    if ok.any():
        R_ecef_from_body = R_ecef_from_gcrs[ok] @ R_est[ok]
        irr = analytic.diode_irradiance(r_sat[ok], r_sun[ok], R_ecef_from_body, frames, responses, map=refl,
                                        e_sun_w_m2=e_sun_w_m2, eclipse=None, backend=backend)
        out[ok] = irr.albedo_w_m2 * (float(e_s0_w_m2) / float(e_sun_w_m2))
    return out


def _estimators(normals, fov_deg, e_s0, live):
    from estimators.advanced import model_albedo_estimate, smart_select_estimate
    from estimators.sun_vector import sun_albedo_sun_estimate, wls_estimate

    kw = dict(fov_deg=fov_deg, e_s0=e_s0, live=live)
    return {
        "wls": lambda e, a: wls_estimate(e, normals, **kw),
        "sun_albedo_sun(wls)": lambda e, a: sun_albedo_sun_estimate(e, normals, init="wls", **kw),
        "sun_albedo_sun(albedo_sun)": lambda e, a: sun_albedo_sun_estimate(e, normals, init="albedo_sun", **kw),
        "smart_select": lambda e, a: smart_select_estimate(e, normals, **kw),
        "model_albedo": lambda e, a: model_albedo_estimate(e, normals, a, fit_gain=False, **kw),
        "model_albedo+gain": lambda e, a: model_albedo_estimate(e, normals, a, fit_gain=True, **kw),
    }


def evaluate_cross_map(config="tilt20_fov70", *, start_s=18000, stop_s=28000, date="2016-07-02T00:00:00Z",
                       truth_maps=("ceres2018-all", "toms2005"), onboard_maps=("toms2005", "ceres2018-all"),
                       truth_irradiance=None, geometry=None, same_map=False, lag_steps=1, sigma_deg=0.0, seed=0,
                       diode="BPW34FS", dead=None, backend="auto", return_errors=False):
    """Return a table (list of dicts) of sunlit Sun-vector errors with truth and on-board albedo from different maps.

    One row per (truth map, on-board map, estimator): ``n_sunlit`` (epochs in the thesis'
    cylindrical sunlight, eqs. 4.6-4.10), ``n_invalid`` (sunlit epochs without an estimate),
    ``mean_deg``, ``p95_deg``, ``max_deg`` (over the sunlit valid epochs). Estimators: WLS
    (eq. 4.30), Sun-Albedo-Sun from WLS and from Albedo-Sun (thesis sec. 4.3.4),
    :func:`estimators.advanced.smart_select_estimate` (it needs no prediction; for a
    configuration without opposite diodes it is plain least squares on the Sun diodes),
    :func:`estimators.advanced.model_albedo_estimate` without and with the gain fit.

    The study: ``config`` (a shipped :class:`scenes.config.SatelliteConfig` name or object,
    ``dead`` overrides its dead diodes), the default ESTCube-1 TLE and 1.9 deg/s tumble of
    :func:`simcore.study.compute_geometry`, 1 s steps from ``date`` + ``start_s`` to
    ``date`` + ``stop_s``, the noise-free sensor chain of ``diode``. The "truth" irradiance is
    the analytic direct + albedo irradiance (:func:`simcore.analytic.diode_irradiance`) made
    with each of ``truth_maps``; or pass ``truth_irradiance`` = {map name: (N, K) total W/m^2
    at the full solar constant} (e.g. rendered) together with the ``geometry`` it was made
    for (then ``start_s``/``stop_s``/``date`` are not used; its first ``lag_steps`` samples,
    which have no previous attitude, are not evaluated). The on-board prediction uses
    each of ``onboard_maps`` that differs from the truth map (``same_map=True`` also adds the
    same map, where only the stale attitude is wrong) with the attitude of
    :func:`previous_attitude` (``lag_steps``, ``sigma_deg``, ``seed``). Every estimator is
    told which diodes are dead (``live``).

    ``return_errors=True`` returns ``(rows, errors)`` with ``errors`` a dict: ``'t_s'`` (N,)
    seconds from ``date`` (NaN with ``truth_irradiance``), ``'sunlit'`` (N,) bool (the
    evaluated epochs) and, per row, ``(truth_map, onboard_map, estimator)`` -> the angle
    error (N,) in degrees (NaN where invalid).
    """
    from estimators.metrics import angle_error_deg
    from scenes.config import SatelliteConfig
    from simcore.attitude import tumble
    from simcore.epochs import Epochs
    from simcore.sensor import SensorChain
    from simcore.study import compute_geometry

    cfg = SatelliteConfig.load(config) if isinstance(config, str) else config
    if dead is not None:
        cfg = cfg.with_dead(dead)
    fov = np.unique(cfg.fov_deg)
    if fov.size != 1:
        raise ValueError(f"the estimators take one FOV; {cfg.name} mixes FOVs {fov.tolist()}")
    chain = SensorChain(diode, dead=np.flatnonzero(cfg.dead).tolist())
    e_s0 = chain.diode.e_s0_w_m2
    if truth_irradiance is not None:
        if geometry is None:
            raise ValueError("truth_irradiance needs the geometry it was computed for (geometry=...)")
        truth = {k: np.asarray(v, dtype=float) for k, v in truth_irradiance.items()}
        for k, v in truth.items():
            if v.shape != (len(geometry), cfg.n_diodes):
                raise ValueError(f"truth_irradiance[{k!r}] must be (N, K) = ({len(geometry)}, {cfg.n_diodes}), "
                                 f"got {v.shape}")
    else:
        if not stop_s > start_s:
            raise ValueError(f"stop_s ({stop_s}) must be after start_s ({start_s})")
        # lag_steps extra samples before the window give its first epoch a previous attitude; the
        # tumble is timed from ``date`` (as in a whole-day run), not from the window's start.
        t_day_s = np.arange(float(start_s) - lag_steps, float(stop_s), 1.0)
        geometry = compute_geometry(epochs=Epochs.from_any(date) + t_day_s, attitude=tumble(t_day_s))
        truth = {}
        for name in truth_maps:
            irr = analytic.diode_irradiance(geometry.r_sat_ecef_m, geometry.r_sun_ecef_m,
                                            geometry.R_ecef_from_body, cfg.frames, list(cfg.apertures),
                                            map=named_map(name), backend=backend)
            truth[name] = irr.total_w_m2
    R_est = previous_attitude(geometry.R_gcrs_from_body, lag_steps=lag_steps, sigma_deg=sigma_deg, seed=seed)
    s_true = geometry.sun_dir_body
    # The first lag_steps samples have no previous attitude (with computed truth: the extra
    # leading samples); they are left out for every estimator alike.
    sunlit = np.asarray(geometry.sunlit_cylindrical, dtype=bool) & (np.arange(len(geometry)) >= lag_steps)
    live = cfg.live
    ests = _estimators(cfg.normals, float(fov[0]), e_s0, live)
    preds = {}
    rows = []
    errors = {"t_s": t_day_s if truth_irradiance is None else np.full(len(geometry), np.nan), "sunlit": sunlit}
    for t_name, e_total in truth.items():
        e_p = chain.measure(e_total)
        for p_name in onboard_maps:
            if p_name == t_name and not same_map:
                continue
            if p_name not in preds:
                preds[p_name] = predict_albedo_effective(geometry, R_est, cfg, p_name, e_s0_w_m2=e_s0,
                                                         backend=backend)
            for est_name, f in ests.items():
                s_hat, valid = f(e_p, preds[p_name])
                err = angle_error_deg(s_hat, s_true)
                errors[(t_name, p_name, est_name)] = err
                use = sunlit & np.isfinite(err)
                v = err[use]
                rows.append({"truth_map": t_name, "onboard_map": p_name, "estimator": est_name,
                             "n_sunlit": int(sunlit.sum()), "n_invalid": int(np.sum(sunlit & ~np.isfinite(err))),
                             "mean_deg": float(v.mean()) if v.size else float("nan"),
                             "p95_deg": float(np.percentile(v, 95.0)) if v.size else float("nan"),
                             "max_deg": float(v.max()) if v.size else float("nan")})
    return (rows, errors) if return_errors else rows
