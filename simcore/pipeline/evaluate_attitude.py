"""Attitude determination on a run file: gyro + magnetometer + the Sun sensor in an MEKF.

:func:`run_mekf` takes a rendered run (:mod:`simcore.pipeline.run`) and simulates what the satellite
would measure and estimate:

- gyro readings (:mod:`simcore.sensor.gyro`) of the true body rate (the mean rate over each step,
  from consecutive attitude quaternions of the run), with the board temperature of the orbital
  thermal cycle driven by the run's eclipse history (:func:`simcore.sensor.gyro.board_temperature_k`);
- magnetometer readings (:mod:`simcore.sensor.magnetometer`) of the IGRF field at the satellite;
- the diode readings of the sensor chain (:mod:`simcore.sensor.chain`, shot and Johnson noise on)
  from the rendered direct + albedo irradiance, turned into a Sun vector by
  :func:`estimators.advanced.model_albedo_estimate` (with the gain fit) with the albedo
  *predicted on board from the filter's own attitude estimate*: every ``block`` epochs the
  filter's current state is propagated with the gyro readings alone over the next block, the
  Bhanderi model (:func:`simcore.radiometry.onboard.predict_albedo_effective`) predicts each diode's albedo
  for those attitudes with the on-board map, and the estimator subtracts it. The on-board map
  is by default not the map the run was rendered with (TOMS 2005 <-> CERES 2018 all-sky). The
  true attitude never enters the estimate. With ``onboard_albedo=False`` the Sun vector comes
  from the thesis' best estimator that needs no prediction (Sun-Albedo-Sun from Albedo-Sun);
- an :class:`estimators.attitude.MEKF` (attitude + gyro bias), tuned from the data sheets
  (:func:`simcore.sensor.gyro.filter_noise`), fusing the magnetometer always and the Sun vector only
  in full sunlight (the satellite knows its eclipses from the orbit and the ephemeris), both
  gated. In eclipse: magnetometer + gyro only.

The filter starts at the first sunlit epoch from TRIAD (Sun vector first, field second), or,
with ``initial_error_deg``, from the true attitude rotated by that angle about a random axis
(to show convergence). Epochs before the start carry NaN.
"""
import numpy as np

from simcore.errors import InvalidInputError
from simcore.pipeline.preflight import check_filter_run

from simcore.environment.eclipse import sunlit as eclipse_sunlit
from estimators.attitude import (MEKF, attitude_error_body, dcm_to_quat, nees, quat_mul, quat_to_dcm, rotvec_to_quat,
                                 time_to_converge_s, triad)

# chi-square 3 dof, two-sided 95 % bounds (Abramowitz & Stegun table 26.8; scipy.stats.chi2.ppf(0.025 / 0.975, 3))
NEES_BOUNDS_3DOF = (0.2158, 9.3484)
SIGMA_SUN_DEG = {True: 0.5, False: 2.0}   # Sun-vector noise told to the filter (model-albedo / Sun-Albedo-Sun)
CONVERGED_DEG = 5.0
DEFAULT_GYRO = "L3G4200D"                 # the gyro flown on the NUTS ADCS prototype (thesis sec. 3.1.2)
DEFAULT_MAGNETOMETER = "HMC5883L"


def _true_rates(q, dt):
    """Return the mean body rate (N, 3), rad/s, over each step ending at each epoch (the first: the next step)."""
    d = quat_mul(q[:-1] * np.array([1.0, -1.0, -1.0, -1.0]), q[1:])
    d = np.where(d[:, :1] < 0, -d, d)
    vn = np.linalg.norm(d[:, 1:], axis=1)
    ang = 2.0 * np.arctan2(vn, d[:, 0])
    rv = d[:, 1:] * np.where(vn > 0, ang / np.where(vn > 0, vn, 1.0), 2.0)[:, None]
    w = rv / dt
    return np.concatenate([w[:1], w], axis=0)


def _stats(v):
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"n": 0, "mean": None, "p95": None, "max": None}
    return {"n": int(v.size), "mean": round(float(v.mean()), 4), "p95": round(float(np.percentile(v, 95)), 4),
            "max": round(float(v.max()), 4)}


def _on_board_map_name(ds):
    name = str(ds.attrs.get("reflectivity_map", "")).lower()
    if "ceres" in name:
        return "toms2005"
    return "ceres2018-all"


def run_mekf(ds, path=None, *, gyro=DEFAULT_GYRO, magnetometer=DEFAULT_MAGNETOMETER, seed=0, onboard_albedo=True,
             onboard_map=None, diode="BPW34FS", block=10, initial_error_deg=None, sigma_sun_deg=None,
             converged_deg=CONVERGED_DEG, thermal_compensation=False):
    """Return a dict of time series (N-leading arrays) and a summary of the MEKF on run Dataset ``ds``.

    Keys: ``t_s`` (N,), ``q_est`` / ``q_true`` (N, 4) q_gcrs_from_body, ``error_body_deg`` (N, 3)
    body-frame attitude error (rotation vector, deg), ``error_deg`` (N,) its norm, ``nees`` (N,)
    attitude NEES (3 dof), ``sigma_deg`` (N, 3) the filter's 1-sigma per body axis, ``sunlit``
    and ``eclipse`` (N,) bool, ``sun_used`` / ``mag_used`` (N,) bool (accepted by the gate),
    ``temperature_k`` (N,), and ``summary`` (JSON-able). ``thermal_compensation``: the gyro's bias
    temperature effect is compensated on board down to :data:`simcore.sensor.gyro.THERMAL_COMPENSATION_RESIDUAL`.
    """
    check_filter_run(ds, "mekf", path, initial_error_deg)       # one line for a run that cannot feed it
    from estimators.advanced import model_albedo_estimate
    from estimators.sun_vector import sun_albedo_sun_estimate
    from simcore.pipeline.evaluate import measure
    from simcore.sensor.gyro import GyroModel, board_temperature_k, filter_noise, gyro_spec, thermally_compensated
    from simcore.sensor.magnetometer import MagnetometerModel, field_gcrs_t, magnetometer_spec
    from simcore.environment.maps import named_map
    from simcore.radiometry.onboard import predict_albedo_effective
    from simcore.pipeline.run import PreparedRun, options_of
    from simcore.sensor.chain import DIODES

    gspec, mspec = gyro_spec(gyro), magnetometer_spec(magnetometer)
    if thermal_compensation:
        gspec = thermally_compensated(gspec)
    if diode not in DIODES:
        raise InvalidInputError(f"unknown diode {diode!r}; known: {', '.join(DIODES)}")
    if not (isinstance(block, int) and block >= 1):
        raise ValueError(f"block must be a positive number of epochs, got {block}")
    study = PreparedRun(options_of(ds, path or "run.nc"))
    geo = study.geometry
    n = ds.sizes["time"]
    if len(geo) != n:
        raise ValueError(f"{path}: its options give {len(geo)} epochs but it holds {n}; it was not made by "
                         "'sunsim run' with these options")
    t = ds["t_s"].values.astype(float)
    dt = np.diff(t)
    if n < 2 or not np.allclose(dt, dt[0]):
        raise ValueError("the attitude filter needs a run with at least two evenly spaced epochs")
    dt = float(dt[0])
    cfg = study.config
    q_true = ds["q_gcrs_from_body"].values
    R_true = geo.R_gcrs_from_body
    illum = ds["illumination"].values.astype(float)
    sunlit = eclipse_sunlit(illum)
    eclipse = ~sunlit
    valid = ds["valid"].values.astype(bool)

    # --- what the satellite measures -------------------------------------------------------------
    temp = board_temperature_k(t, illum)
    w_true = _true_rates(q_true, dt)
    gyro_model = GyroModel(gspec, seed=seed)
    omega = gyro_model.measure(t, w_true, temp)
    b_gcrs = field_gcrs_t(geo.epochs, geo.r_sat_ecef_m)
    b_body = np.einsum("nji,nj->ni", R_true, b_gcrs)
    mag = MagnetometerModel(mspec, seed=seed + 1).measure(b_body)
    sigma_mag = np.hypot(mspec.noise_t, mspec.bias_residual_t / 3.0) / np.linalg.norm(mag, axis=1)
    irr = ds["irradiance"].sum("component").values
    live = ~ds["dead"].values.astype(bool)
    normals = ds["normal_body"].values
    fov = float(np.min(ds["fov_deg"].values))
    e_s0 = DIODES[diode].e_s0_w_m2
    e_p = measure(irr, diode=diode, dead=np.flatnonzero(~live), noise=True, seed=seed + 2)
    sun_ref = ds["sun_dir_gcrs"].values
    kw = dict(fov_deg=fov, e_s0=e_s0, live=live)
    s_blind, v_blind = sun_albedo_sun_estimate(e_p, normals, init="albedo_sun", **kw)
    sigma_sun = np.radians(SIGMA_SUN_DEG[bool(onboard_albedo)] if sigma_sun_deg is None else sigma_sun_deg)
    map_name = onboard_map or _on_board_map_name(ds)
    board_map = named_map(map_name) if onboard_albedo else None

    # --- the filter ---------------------------------------------------------------------------------
    sigma_v, sigma_u, sigma_b0 = filter_noise(gspec, dt_s=dt)
    rng = np.random.default_rng(seed + 3)
    if initial_error_deg is not None:
        k0 = 0
        axis = rng.normal(size=3)
        q0 = dcm_to_quat(R_true[0] @ _rot(np.radians(initial_error_deg) * axis / np.linalg.norm(axis)))[0]
        sig0 = max(np.radians(initial_error_deg), np.radians(5.0))
    else:
        ok = np.flatnonzero(sunlit & v_blind & valid)
        if ok.size == 0:
            raise ValueError("the run has no sunlit epoch with a Sun vector: the filter cannot start by TRIAD; "
                             "give initial_error_deg to start from a perturbed truth")
        k0 = int(ok[0])
        q0 = dcm_to_quat(triad(s_blind[k0], mag[k0], sun_ref[k0], b_gcrs[k0]))[0]
        sig0 = np.radians(10.0)
    f = MEKF(q0, np.zeros(3), np.diag([sig0 ** 2] * 3 + [sigma_b0 ** 2] * 3), sigma_v=sigma_v, sigma_u=sigma_u)

    q_est = np.full((n, 4), np.nan)
    P_att = np.full((n, 3, 3), np.nan)
    sun_used = np.zeros(n, bool)
    mag_used = np.zeros(n, bool)
    s_hat = np.full((n, 3), np.nan)
    s_ok = np.zeros(n, bool)
    q_est[k0], P_att[k0] = f.q, f.P[:3, :3]
    geo_arrays = {"r_sat_ecef_m": geo.r_sat_ecef_m, "r_sun_ecef_m": geo.r_sun_ecef_m,
                  "R_ecef_from_gcrs": geo.R_ecef_from_gcrs}
    for a in range(k0 + 1, n, block):
        b = min(a + block, n)
        if onboard_albedo:
            # The filter's own attitude over the block: its state now, propagated by the gyro alone.
            q_pred = np.empty((b - a, 4))
            q = f.q
            for i, k in enumerate(range(a, b)):
                q = quat_mul(q, rotvec_to_quat((omega[k] - f.bias) * dt))
                q_pred[i] = q
            pad = block - (b - a)            # a fixed block size keeps the model's compiled kernel
            idx = np.r_[np.arange(a, b), np.full(pad, b - 1)]
            Rp = quat_to_dcm(np.concatenate([q_pred, np.repeat(q_pred[-1:], pad, axis=0)]))
            pred = predict_albedo_effective({k: v[idx] for k, v in geo_arrays.items()}, Rp, cfg, board_map,
                                            e_s0_w_m2=e_s0)[:b - a]
            s_hat[a:b], s_ok[a:b] = model_albedo_estimate(e_p[a:b], normals, pred, fit_gain=True, **kw)
        else:
            s_hat[a:b], s_ok[a:b] = s_blind[a:b], v_blind[a:b]
        for k in range(a, b):
            f.predict(omega[k], dt)
            mag_used[k] = f.update_vector(mag[k], b_gcrs[k], sigma_mag[k])
            if sunlit[k] and s_ok[k] and valid[k]:
                sun_used[k] = f.update_vector(s_hat[k], sun_ref[k], sigma_sun)
            q_est[k], P_att[k] = f.q, f.P[:3, :3]

    # --- metrics ----------------------------------------------------------------------------------------
    started = np.arange(n) >= k0
    err = np.full((n, 3), np.nan)
    err[started] = attitude_error_body(q_est[started], q_true[started])
    err_deg = np.degrees(err)
    total = np.linalg.norm(err_deg, axis=1)
    ns = np.full(n, np.nan)
    ns[started] = nees(err[started], P_att[started])
    in_bounds = (ns >= NEES_BOUNDS_3DOF[0]) & (ns <= NEES_BOUNDS_3DOF[1])
    t_conv = time_to_converge_s(t[started], total[started], converged_deg)
    summary = {
        "filter": "mekf", "gyro": gspec.name, "thermal_compensation": bool(thermal_compensation), "magnetometer": mspec.name, "seed": int(seed), "diode": diode,
        "configuration": ds.attrs.get("configuration"),
        "sun_vector": "model_albedo+gain (on-board albedo from the filter's attitude)" if onboard_albedo
        else "sun_albedo_sun (no on-board albedo)",
        "onboard_map": map_name if onboard_albedo else None,
        "start_s": float(t[k0]), "start": "perturbed truth" if initial_error_deg is not None else "TRIAD",
        "initial_error_deg": round(float(total[k0]), 3),
        "attitude_error_deg": {"sunlit": _stats(total[started & sunlit]),
                               "eclipse": _stats(total[started & eclipse]),
                               "all": _stats(total[started])},
        "attitude_error_per_axis_deg": {
            part: {ax: _stats(np.abs(err_deg[m, i])) for i, ax in enumerate("xyz")}
            for part, m in (("sunlit", started & sunlit), ("eclipse", started & eclipse))},
        "nees_in_bounds": round(float(np.mean(in_bounds[started])), 4),
        "nees_mean": round(float(np.nanmean(ns[started])), 3),
        "nees_bounds_3dof_95": list(NEES_BOUNDS_3DOF),
        "time_to_converge_s": None if not np.isfinite(t_conv) else round(float(t_conv - t[k0]), 3),
        "converged_below_deg": converged_deg,
        "sun_updates": int(sun_used.sum()), "sun_rejected": int(np.sum(sunlit & s_ok & valid & started) - sun_used.sum()),
        "mag_updates": int(mag_used.sum()), "mag_rejected": int(started.sum() - 1 - mag_used.sum()),
        "sunlit_epochs": int(np.sum(started & sunlit)), "eclipse_epochs": int(np.sum(started & eclipse)),
        "gyro_filter_noise": {"sigma_v_deg_s_rthz": float(np.degrees(sigma_v)),
                              "sigma_u_deg_s32": float(np.degrees(sigma_u)),
                              "sigma_b0_deg_s": float(np.degrees(sigma_b0))},
        "temperature_c": [round(float(temp.min() - 273.15), 2), round(float(temp.max() - 273.15), 2)],
    }
    return {"t_s": t, "q_est": q_est, "q_true": q_true, "error_body_deg": err_deg, "error_deg": total,
            "nees": ns, "sigma_deg": np.degrees(np.sqrt(np.diagonal(P_att, axis1=1, axis2=2))),
            "sunlit": sunlit, "eclipse": eclipse, "sun_used": sun_used, "mag_used": mag_used,
            "temperature_k": temp, "summary": summary}


def _rot(v):
    return quat_to_dcm(rotvec_to_quat(v))
