"""The on-board albedo prediction, evaluated honestly: truth made with one map, prediction with another.

See :mod:`simcore.radiometry.onboard` for the prediction and its honesty rules.
"""
import numpy as np

from estimators import ESTIMATORS
from estimators.advanced import model_albedo_estimate
from estimators.metrics import angle_error_deg
from scenes.config import SatelliteConfig
from simcore.environment import eclipse
from simcore.environment.attitude import tumble
from simcore.environment.epochs import Epochs
from simcore.environment.geometry import compute_geometry
from simcore.radiometry import analytic
from simcore.radiometry.band import resolve_map
from simcore.radiometry.onboard import predict_albedo_effective, previous_attitude
from simcore.sensor.chain import SensorChain


# row name -> name in estimators.ESTIMATORS, for the estimators that need no albedo prediction
_FROM_READINGS = {"wls": "wls", "sun_albedo_sun(wls)": "sun_albedo_sun_wls",
                  "sun_albedo_sun(albedo_sun)": "sun_albedo_sun", "smart_select": "smart_select"}


def _estimators(normals, fov_deg, e_s0, live):
    kw = dict(fov_deg=fov_deg, e_s0=e_s0, live=live)
    out = {row: (lambda e, a, f=ESTIMATORS[key]: f(e, normals, **kw)) for row, key in _FROM_READINGS.items()}
    out["model_albedo"] = lambda e, a: model_albedo_estimate(e, normals, a, fit_gain=False, **kw)
    out["model_albedo+gain"] = lambda e, a: model_albedo_estimate(e, normals, a, fit_gain=True, **kw)
    return out


def evaluate_cross_map(config="tilt20_fov70", *, start_s=18000, stop_s=28000, date="2016-07-02T00:00:00Z",
                       truth_maps=("ceres2018-all", "toms2005"), onboard_maps=("toms2005", "ceres2018-all"),
                       truth_irradiance=None, geometry=None, same_map=False, lag_steps=1, sigma_deg=0.0, seed=0,
                       diode="BPW34FS", dead=None, backend="auto", return_errors=False):
    """Return a table (list of dicts) of sunlit Sun-vector errors with truth and on-board albedo from different maps.

    One row per (truth map, on-board map, estimator): ``n_sunlit`` (sunlit epochs,
    :func:`simcore.environment.eclipse.sunlit`), ``n_invalid`` (sunlit epochs without an estimate),
    ``mean_deg``, ``p95_deg``, ``max_deg`` (over the sunlit valid epochs). Estimators: WLS
    (eq. 4.30), Sun-Albedo-Sun from WLS and from Albedo-Sun (thesis sec. 4.3.4),
    :func:`estimators.advanced.smart_select_estimate` (it needs no prediction; for a
    configuration without opposite diodes it is plain least squares on the Sun diodes),
    :func:`estimators.advanced.model_albedo_estimate` without and with the gain fit.

    The study: ``config`` (a shipped :class:`scenes.config.SatelliteConfig` name or object,
    ``dead`` overrides its dead diodes), the default ESTCube-1 TLE and 1.9 deg/s tumble of
    :func:`simcore.environment.geometry.compute_geometry`, 1 s steps from ``date`` + ``start_s`` to
    ``date`` + ``stop_s``, the noise-free sensor chain of ``diode``. The "truth" irradiance is
    the analytic direct + albedo irradiance (:func:`simcore.radiometry.analytic.diode_irradiance`) made
    with each of ``truth_maps``; or pass ``truth_irradiance`` = {map name: (N, K) total W/m^2
    at the full solar constant} (e.g. rendered) together with the ``geometry`` it was made
    for (then ``start_s``/``stop_s``/``date`` are not used; its first ``lag_steps`` samples,
    which have no previous attitude, are not evaluated). The on-board prediction uses
    each of ``onboard_maps`` that differs from the truth map (``same_map=True`` also adds the
    same map, where only the stale attitude is wrong) with the attitude of
    :func:`simcore.radiometry.onboard.previous_attitude` (``lag_steps``, ``sigma_deg``, ``seed``). Every estimator is
    told which diodes are dead (``live``).

    ``return_errors=True`` returns ``(rows, errors)`` with ``errors`` a dict: ``'t_s'`` (N,)
    seconds from ``date`` (NaN with ``truth_irradiance``), ``'sunlit'`` (N,) bool (the
    evaluated epochs) and, per row, ``(truth_map, onboard_map, estimator)`` -> the angle
    error (N,) in degrees (NaN where invalid), and ``'estimates'``: per row the estimated Sun
    direction (N, 3) in body axes (NaN where invalid). Map names may be band maps
    (:func:`simcore.radiometry.band.resolve_map`, e.g. ``'band'``).
    """
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
                                            map=resolve_map(name), backend=backend)
            truth[name] = irr.total_w_m2
    R_est = previous_attitude(geometry.R_gcrs_from_body, lag_steps=lag_steps, sigma_deg=sigma_deg, seed=seed)
    s_true = geometry.sun_dir_body
    # The first lag_steps samples have no previous attitude (with computed truth: the extra
    # leading samples); they are left out for every estimator alike.
    sunlit = eclipse.sunlit(geometry.illumination) & (np.arange(len(geometry)) >= lag_steps)
    live = cfg.live
    ests = _estimators(cfg.normals, float(fov[0]), e_s0, live)
    preds = {}
    rows = []
    errors = {"t_s": t_day_s if truth_irradiance is None else np.full(len(geometry), np.nan), "sunlit": sunlit,
              "estimates": {}}
    for t_name, e_total in truth.items():
        e_p = chain.measure(e_total)
        from_readings = {}                  # the estimators that need no prediction: once per truth
        for p_name in onboard_maps:
            if p_name == t_name and not same_map:
                continue
            if p_name not in preds:
                preds[p_name] = predict_albedo_effective(geometry, R_est, cfg, p_name, e_s0_w_m2=e_s0,
                                                         backend=backend)
            for est_name, f in ests.items():
                if est_name in _FROM_READINGS:
                    if est_name not in from_readings:
                        from_readings[est_name] = f(e_p, None)
                    s_hat, valid = from_readings[est_name]
                else:
                    s_hat, valid = f(e_p, preds[p_name])
                err = angle_error_deg(s_hat, s_true)
                errors[(t_name, p_name, est_name)] = err
                errors["estimates"][(t_name, p_name, est_name)] = np.where(valid[:, None], s_hat, np.nan)
                use = sunlit & np.isfinite(err)
                v = err[use]
                rows.append({"truth_map": t_name, "onboard_map": p_name, "estimator": est_name,
                             "n_sunlit": int(sunlit.sum()), "n_invalid": int(np.sum(sunlit & ~np.isfinite(err))),
                             "mean_deg": float(v.mean()) if v.size else float("nan"),
                             "p95_deg": float(np.percentile(v, 95.0)) if v.size else float("nan"),
                             "max_deg": float(v.max()) if v.size else float("nan")})
    return (rows, errors) if return_errors else rows
