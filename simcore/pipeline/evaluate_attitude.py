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

The Sun vector's noise told to the filter (model-albedo Sun vector) has two parts:

- the sensor chain's own noise (shot, Johnson, ADC rounding: :meth:`simcore.sensor.chain.SensorChain.noise_std_w_m2`
  of each reading), propagated through the estimate's own least-squares fit at each epoch
  (:func:`estimators.advanced.model_albedo_direction_variance`): white;
- the on-board albedo model's error (map and Bhanderi's model against the Earth light the diodes
  see), :data:`ALBEDO_MODEL_ERROR_DEG` per axis, measured on a calibration run that is not the default
  orbit (:func:`albedo_model_error_deg`). It is correlated in time (it changes as the body turns and
  the orbit moves on: correlation time 1 / max(|rate|, mean motion), ~30 s at the thesis' 1.9 deg/s
  tumble, where the measured error's autocorrelation falls to 0.4 at 30 s), so it is not white
  noise but a first-order Gauss-Markov state of the filter (:class:`estimators.attitude.MEKF`'s
  ``colored_sigma_rad``): told as white noise it would be averaged over many updates as if
  independent and the filter would grow overconfident (NEES). The summary gives the NIS of the
  accepted Sun updates (2 dof, mean 2 when the noise told is the noise seen) beside the NEES.

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
SIGMA_SUN_DEG = {False: 2.0}   # Sun-vector noise told to the filter for Sun-Albedo-Sun (no on-board albedo)
# The on-board albedo model's error of the model-albedo Sun vector, per axis (deg): measured on a calibration
# run that is not the default orbit (another day, another orbit phase) by
#   sunsim run --start 2016-08-15T06:00:00Z -o /tmp/calib.nc
#   python -c "import xarray as x; from simcore.pipeline.evaluate_attitude import albedo_model_error_deg as f; \
#              print(f(x.open_dataset('/tmp/calib.nc'), '/tmp/calib.nc'))"
ALBEDO_MODEL_ERROR_DEG = 0.165
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
    ``temperature_k`` (N,), the gyro's readings ``omega_meas``, the true mean rate over each step
    ``omega_true`` and the filter's bias estimate ``bias_est`` (N, 3) rad/s (NaN before the start), the
    Sun vector ``s_hat`` (N, 3) with its white noise variance ``var_sun`` and NIS ``nis_sun`` (N,), and
    ``summary`` (JSON-able). ``thermal_compensation``: the gyro's bias
    temperature effect is compensated on board down to :data:`simcore.sensor.gyro.THERMAL_COMPENSATION_RESIDUAL`.
    """
    check_filter_run(ds, "mekf", path, initial_error_deg)       # one line for a run that cannot feed it
    from estimators.advanced import model_albedo_direction_variance, model_albedo_estimate
    from estimators.sun_vector import sun_albedo_sun_estimate
    from simcore.pipeline.evaluate import measure
    from simcore.sensor.gyro import GyroModel, board_temperature_k, filter_noise, gyro_spec, thermally_compensated
    from simcore.sensor.magnetometer import MagnetometerModel, field_gcrs_t, magnetometer_spec
    from simcore.environment.maps import named_map
    from simcore.radiometry.onboard import predict_albedo_effective
    from simcore.pipeline.run import PreparedRun
    from simcore.pipeline.runfile import options_of
    from simcore.sensor.chain import DIODES, SensorChain

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
    # The Sun-vector noise (see sun_vector_noise_note): derived = the chain's own noise, white, per epoch, plus
    # the on-board albedo model's error as a time-correlated state of the filter.
    derived = bool(onboard_albedo) and sigma_sun_deg is None
    sigma_sun = np.radians(SIGMA_SUN_DEG[False] if sigma_sun_deg is None else sigma_sun_deg)
    n_orbit = float(study.orbit.satrec.no_kozai) / 60.0          # mean motion, rad/s
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
    f = MEKF(q0, np.zeros(3), np.diag([sig0 ** 2] * 3 + [sigma_b0 ** 2] * 3), sigma_v=sigma_v, sigma_u=sigma_u,
             colored_sigma_rad=np.radians(ALBEDO_MODEL_ERROR_DEG) if derived else None)

    q_est = np.full((n, 4), np.nan)
    P_att = np.full((n, 3, 3), np.nan)
    sun_used = np.zeros(n, bool)
    mag_used = np.zeros(n, bool)
    nis_sun = np.full(n, np.nan)
    var_sun = np.full(n, np.nan)
    tau = np.full(n, np.nan)
    bias_est = np.full((n, 3), np.nan)
    chain_sigma = SensorChain(diode=diode, noise=True).noise_std_w_m2(irr)
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
            s_hat[a:b], s_ok[a:b], det = model_albedo_estimate(e_p[a:b], normals, pred, fit_gain=True,
                                                               return_details=True, **kw)
            var_sun[a:b] = model_albedo_direction_variance(normals, pred, s_hat[a:b], det["sun"], det["dark"],
                                                           chain_sigma[a:b], e_s0)
        else:
            s_hat[a:b], s_ok[a:b] = s_blind[a:b], v_blind[a:b]
        for k in range(a, b):
            # the albedo model's error decorrelates as the body turns (1 rad) or the orbit moves on, whichever first
            tau[k] = 1.0 / max(float(np.linalg.norm(omega[k] - f.bias)), n_orbit)
            f.predict(omega[k], dt, tau_s=tau[k] if derived else None)
            mag_used[k] = f.update_vector(mag[k], b_gcrs[k], sigma_mag[k])
            if sunlit[k] and s_ok[k] and valid[k] and (not derived or np.isfinite(var_sun[k])):
                sig = np.sqrt(var_sun[k]) if derived else sigma_sun
                sun_used[k] = f.update_vector(s_hat[k], sun_ref[k], sig, colored=derived)
                nis_sun[k] = f.last_nis
            q_est[k], P_att[k] = f.q, f.P[:3, :3]
            bias_est[k] = f.bias

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
        "nees_mean_sunlit": round(float(np.nanmean(ns[started & sunlit])), 3),
        "sun_nis_mean": round(float(np.mean(nis_sun[sun_used])), 3) if sun_used.any() else None,
        "sun_noise": {"model": "derived" if derived else "fixed",
                      "white_deg_median": round(float(np.degrees(np.sqrt(np.nanmedian(var_sun[sun_used])))), 4)
                      if derived and sun_used.any() else None,
                      "albedo_model_deg": ALBEDO_MODEL_ERROR_DEG if derived else None,
                      "correlation_time_s_median": round(float(np.nanmedian(tau[sun_used])), 1)
                      if derived and sun_used.any() else None,
                      "fixed_deg": None if derived else float(np.degrees(sigma_sun))},
        "nees_bounds_3dof_95": list(NEES_BOUNDS_3DOF),
        "time_to_converge_s": None if not np.isfinite(t_conv) else round(float(t_conv - t[k0]), 3),
        "converged_below_deg": converged_deg,
        "sun_updates": int(sun_used.sum()), "sun_rejected": int(np.sum(np.isfinite(nis_sun) & ~sun_used)),
        "sun_skipped": int(np.sum(sunlit & s_ok & valid & started & ~np.isfinite(nis_sun))),
        "mag_updates": int(mag_used.sum()), "mag_rejected": int(started.sum() - 1 - mag_used.sum()),
        "sunlit_epochs": int(np.sum(started & sunlit)), "eclipse_epochs": int(np.sum(started & eclipse)),
        "gyro_filter_noise": {"sigma_v_deg_s_rthz": float(np.degrees(sigma_v)),
                              "sigma_u_deg_s32": float(np.degrees(sigma_u)),
                              "sigma_b0_deg_s": float(np.degrees(sigma_b0))},
        "temperature_c": [round(float(temp.min() - 273.15), 2), round(float(temp.max() - 273.15), 2)],
    }
    return {"t_s": t, "q_est": q_est, "q_true": q_true, "error_body_deg": err_deg, "error_deg": total,
            "nees": ns, "sigma_deg": np.degrees(np.sqrt(np.diagonal(P_att, axis1=1, axis2=2))),
            "sunlit": sunlit, "eclipse": eclipse, "sun_used": sun_used, "s_hat": s_hat, "nis_sun": nis_sun, "var_sun": var_sun,
            "omega_meas": omega, "omega_true": w_true, "bias_est": bias_est, "mag_used": mag_used,
            "temperature_k": temp, "summary": summary}


def summary_lines(run, s):
    """Return the text report (lines) of :func:`run_mekf`'s summary ``s`` for run file ``run``."""
    out = []
    a = s["attitude_error_deg"]
    out.append(f"{run}: {s['configuration']}, MEKF with {s['gyro']} + {s['magnetometer']} + Sun sensor ({s['sun_vector']}), "
                   f"seed {s['seed']}, start {s['start']} at {s['start_s']:g} s")
    out.append(f"  attitude error [deg]   {'n':>6} {'mean':>7} {'p95':>7} {'max':>7}")
    for part in ("sunlit", "eclipse", "all"):
        r = a[part]
        if r["n"]:
            out.append(f"  {part:<22} {r['n']:>6} {r['mean']:>7.3f} {r['p95']:>7.3f} {r['max']:>7.3f}")
        else:
            out.append(f"  {part:<22} {0:>6}       -       -       -")
    out.append(f"  NEES in 95 % bounds: {s['nees_in_bounds']:.1%} (mean {s['nees_mean']}, sunlit {s['nees_mean_sunlit']}, "
                   f"3 dof); NIS of the Sun vector: mean {s['sun_nis_mean']} over the accepted updates (2 dof); "
                   f"converged (< {s['converged_below_deg']:g} deg for good) after {s['time_to_converge_s']} s")
    sn = s["sun_noise"]
    if sn["model"] == "derived":
        out.append(f"  Sun-vector noise told: the chain's own, white (median {sn['white_deg_median']} deg), and the on-board "
                   f"albedo model's error {sn['albedo_model_deg']} deg, correlated over ~{sn['correlation_time_s_median']} s "
                   "(a state of the filter)")
    else:
        out.append(f"  Sun-vector noise told: {sn['fixed_deg']:.3g} deg, white")
    out.append(f"  Sun updates {s['sun_updates']} (rejected {s['sun_rejected']}, no noise estimate {s['sun_skipped']}), "
                   f"magnetometer updates "
                   f"{s['mag_updates']} (rejected {s['mag_rejected']}); board {s['temperature_c'][0]}..{s['temperature_c'][1]} degC")
    return out


def albedo_model_error_deg(ds, path=None, *, onboard_map=None, diode="BPW34FS"):
    """Return the on-board albedo model's error of the model-albedo Sun vector, deg per axis, on run ``ds``.

    The rms over the sunlit epochs of the angle between the true Sun vector and
    :func:`estimators.advanced.model_albedo_estimate` (gain fit) on the run's readings without
    noise, with the albedo predicted on board (the on-board map, Bhanderi) *at the true
    attitude*, divided by sqrt(2) (the angle error has two perpendicular components): what is left
    is the error of the on-board albedo model (map and Bhanderi's model against the rendered Earth
    light) and of the cosine model of the direct light; no sensor noise, no attitude error.
    """
    from estimators.advanced import model_albedo_estimate
    from simcore.environment.maps import named_map
    from simcore.pipeline.evaluate import measure
    from simcore.pipeline.run import PreparedRun
    from simcore.pipeline.runfile import options_of
    from simcore.radiometry.onboard import predict_albedo_effective
    from simcore.sensor.chain import DIODES

    study = PreparedRun(options_of(ds, path or "run.nc"))
    geo = study.geometry
    e_s0 = DIODES[diode].e_s0_w_m2
    live = ~ds["dead"].values.astype(bool)
    e_p = measure(ds["irradiance"].sum("component").values, diode=diode, dead=np.flatnonzero(~live))
    board = named_map(onboard_map or _on_board_map_name(ds))
    pred = predict_albedo_effective(geo, geo.R_gcrs_from_body, study.config, board, e_s0_w_m2=e_s0)
    s_hat, ok = model_albedo_estimate(e_p, ds["normal_body"].values, pred, fit_gain=True, live=live, e_s0=e_s0,
                                      fov_deg=float(np.min(ds["fov_deg"].values)))
    s_true = np.einsum("nji,nj->ni", geo.R_gcrs_from_body, ds["sun_dir_gcrs"].values)
    use = ok & eclipse_sunlit(ds["illumination"].values.astype(float)) & ds["valid"].values.astype(bool)
    ang = np.arctan2(np.linalg.norm(np.cross(s_hat[use], s_true[use]), axis=1), np.sum(s_hat[use] * s_true[use], axis=1))
    return float(np.degrees(np.sqrt(np.mean(ang ** 2) / 2.0)))


def _rot(v):
    return quat_to_dcm(rotvec_to_quat(v))
