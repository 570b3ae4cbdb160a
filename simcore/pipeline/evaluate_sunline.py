"""From a run file to sun-line filter results: error and fault models, EKF / UKF, WLS beside them.

The traced irradiance of a run (:mod:`simcore.pipeline.run`) goes through Basilisk's CSS error and fault
models (:mod:`simcore.sensor.errors`), sunsim's ADC (:class:`simcore.sensor.chain.SensorChain`,
eqs. 4.21-4.25), and then into the sun-line filters of :mod:`estimators.sunline` and, on the very
same readings, the thesis' WLS and Sun-Albedo-Sun estimators. :func:`filter_run` returns the JSON
summary that ``sunsim estimate RUN.nc --filter sunline-ekf|sunline-ukf`` prints.

The filters start at the first sunlit epoch with a valid WLS estimate (from it, with zero rate)
and take diode readings only in full Sun (illumination = 1, from the run's orbit and eclipse
model, which flight software has too): in eclipse and penumbra they only propagate, because a
diode lit by the Earth alone would pass the reading threshold (every lit diode does at FOV 90).

Errors are taken over the sunlit epochs (illumination = 1):

- ``sun_error_deg``: angle between the estimated and the true Sun vector (body frame);
- ``rate_error_deg_s``: |omega_hat_perp - omega_perp|, the body-rate component perpendicular to
  the true Sun vector, the part every Sun-only estimator can see at one instant (for WLS from
  successive estimates, :func:`estimators.sunline.rate_from_sun_vectors`); the filters also give
  ``rate_error_full_deg_s``, the whole vector.

The true body rate comes from the run's attitude quaternions (successive samples, exact for the
constant-rate tumble). The filters' measurement noise ``sigma_meas`` (normalised units, 1.0 =
the normal-Sun reading) defaults to the root sum of squares of the error models' noise, the ADC
quantisation (LSB^2 / 12) and :data:`EARTH_LIGHT_SIGMA`, an allowance for the Earth's reflected
light, which the sun-line measurement model (n . s) does not contain.
"""
import json
import tomllib

import numpy as np

from estimators import sun_albedo_sun_estimate, wls_estimate
from estimators.metrics import angle_error_deg
from estimators.sunline import perpendicular_rate, rate_from_sun_vectors, run_sunline_filter
from simcore.environment import eclipse
from simcore.environment.attitude import quat_conjugate, quat_multiply
from simcore.errors import InvalidInputError
from simcore.pipeline.preflight import check_filter_run
from simcore.constants import E_SUN_W_M2
from simcore.sensor.chain import DIODES, SensorChain
from simcore.sensor.errors import (apply_errors, basilisk_response, check_faults, misalignment_rotations,
                                   perturbed_normal_rotations, SensorErrors)

# Allowance (1 sigma, normalised units) for the Earth light on a Sun-seeing diode, which the
# sun-line measurement model leaves out: 0.05 E_S0 = 9.4 W/m^2 effective for the BPW34FS, about
# the albedo irradiance (68 W/m^2 at full scale) on a diode that sees the Earth well inside its FOV
# at 665 km (see the run files' albedo component); larger Earth light is gated out.
EARTH_LIGHT_SIGMA = 0.05
USE_THRESHOLD_SIGMAS = 5.0        # readings used from 5 sigma of the noise up (Basilisk scenarios' sensorUseThresh)
INIT_POS_VAR = 0.25               # initial variance of each Sun-vector component (normalised units^2)
INIT_RATE_SIGMA_RAD_S = np.radians(2.0)   # initial rate standard deviation per axis (2 deg/s)

FILTER_KINDS = {"sunline-ekf": "ekf", "sunline-ukf": "ukf"}


def true_rate_body(q_gcrs_from_body, t_s):
    """Return the body rate (N, 3), rad/s, body frame, from scalar-first attitude quaternions (N, 4).

    omega between samples i and i+1 = rotation vector of conj(q_i) q_{i+1} / dt (the body-frame
    increment, exact for a constant rate), assigned to the middle and interpolated back to the samples
    (the last sample repeats the last interval).
    """
    q = np.asarray(q_gcrs_from_body, dtype=float)
    t = np.asarray(t_s, dtype=float)
    dq = quat_multiply(quat_conjugate(q[:-1]), q[1:])
    dq = dq * np.sign(np.where(dq[:, :1] == 0, 1.0, dq[:, :1]))
    vec = dq[:, 1:]
    sin_half = np.linalg.norm(vec, axis=1)
    angle = 2.0 * np.arctan2(sin_half, dq[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(sin_half[:, None] > 0, vec / np.where(sin_half > 0, sin_half, 1.0)[:, None], 0.0)
    w_mid = axis * (angle / np.diff(t))[:, None]
    w = np.empty((t.size, 3))
    w[0] = w_mid[0]
    w[-1] = w_mid[-1]
    w[1:-1] = 0.5 * (w_mid[:-1] + w_mid[1:])
    return w


def _config_of(ds):
    from scenes.config import SatelliteConfig
    extra = json.loads(ds.attrs["options"]).get("extra_flat_diodes") if "options" in ds.attrs else None
    cfg = SatelliteConfig.from_dict(tomllib.loads(ds.attrs["configuration_toml"]),
                                    source=ds.attrs.get("configuration", ""), extra_flat_diodes=extra or None)
    if cfg.normals.shape != ds["normal_body"].shape or not np.allclose(cfg.normals, ds["normal_body"].values,
                                                                        atol=1e-9):
        raise InvalidInputError("the run file's configuration text does not rebuild its diode normals; "
                         "misalignment needs the apertures of the run (re-run it with this sunsim)")
    return cfg


def true_signals(ds, errors):
    """Return the true normalised signals (N, K) (irradiance / E_sun) of a run, with the misalignment and
    Basilisk's response (``errors.kelly``) applied to the direct part, and the true normals (K, 3).

    Misalignment: a diode's true frame is its nominal frame turned by the user's perturbation
    (``errors.align``, :func:`simcore.sensor.errors.perturbed_normal_rotations`) and then by a small random
    rotation (:func:`simcore.sensor.errors.misalignment_rotations`, seeded by ``errors.seed``). Its direct
    irradiance becomes the traced one plus E_sun s_scale illumination (r_true - r_nominal), with r
    the aperture's exact response (:meth:`simcore.shapes.aperture.WellAperture.response`) to the Sun
    centre; the traced albedo is kept (a misalignment of a degree changes the Earth's place in a
    70-90 deg field of view by as much, a small part of a slowly varying signal).
    Basilisk's response (``errors.kelly`` not None): the direct part becomes E_sun s_scale illumination
    x :func:`~simcore.sensor.errors.basilisk_response` of the cosine c on the true normal, with each
    diode's design FOV as Basilisk's ``fov`` (Basilisk's shadowFactor is our illumination).
    """
    irr = ds["irradiance"].values
    direct, albedo = irr[..., 0].copy(), irr[..., 1]
    sun = ds["sun_dir_body"].values
    normals = ds["normal_body"].values
    e_sun = float(ds.attrs.get("e_sun_w_m2", E_SUN_W_M2))
    if errors.misalign_deg > 0 or errors.align:
        cfg = _config_of(ds)
        rot = misalignment_rotations(len(normals), np.radians(errors.misalign_deg),
                                     np.random.default_rng([errors.seed, 1]))
        rot = rot @ perturbed_normal_rotations(normals, errors.align)   # the user's turn first, the random one on top
        frames = cfg.frames
        frames_true = np.einsum("kij,klj->kli", rot, frames)     # rows rotated: (R u, R v, R n)
        scale = e_sun * ds["sun_scale"].values * ds["illumination"].values
        for k, ap in enumerate(cfg.apertures):
            r_nom = ap.response(sun @ frames[k].T)
            r_true = ap.response(sun @ frames_true[k].T)
            direct[:, k] = np.clip(direct[:, k] + scale * (r_true - r_nom), 0.0, None)
        normals = frames_true[:, 2, :]
    if errors.kelly is not None:
        fov = np.radians(ds["fov_deg"].values)[None, :]
        light = (ds["sun_scale"].values * ds["illumination"].values)[:, None]
        direct = e_sun * light * basilisk_response(sun @ normals.T, fov, errors.kelly, errors.kelly_power)
    reflected = irr[..., 2] if irr.shape[-1] > 2 else 0.0   # light the spacecraft reflects, as rendered
    return (direct + albedo + reflected) / e_sun, normals


def sensed_readings(ds, *, diode="BPW34FS", errors=None, faults=(), noise=False, seed=0):
    """Return the measured effective irradiance E_p (N, K), W/m^2, of a run with error models and faults.

    true_signals -> :func:`simcore.sensor.errors.apply_errors` -> sunsim's chain from the
    irradiance u E_sun (shot/Johnson noise with ``noise``, ADC, eq. 4.25); dead diodes read 0.
    """
    errors = errors or SensorErrors()
    u, _ = true_signals(ds, errors)
    sensed = apply_errors(u, ds["t_s"].values, errors, faults)
    e_sun = float(ds.attrs.get("e_sun_w_m2", E_SUN_W_M2))
    dead = np.flatnonzero(ds["dead"].values.astype(bool))
    chain = SensorChain(diode=diode, dead=tuple(dead), noise=noise, seed=seed)
    return chain.measure(np.clip(sensed, 0.0, None) * e_sun), chain


def _stats(err, sunlit):
    e = np.asarray(err, float)[sunlit]
    ok = np.isfinite(e)
    if not ok.any():
        return {"n": 0, "n_invalid": int(e.size), "mean": None, "p95": None, "max": None}
    v = e[ok]
    return {"n": int(v.size), "n_invalid": int(e.size - v.size), "mean": round(float(v.mean()), 4),
            "p95": round(float(np.percentile(v, 95.0)), 4), "max": round(float(v.max()), 4)}


def parse_process_noise(text):
    """Return (q_rate, q_sun) of the CLI's ``--process-noise Q_RATE[:Q_SUN]`` (rad^2/s^3, 1/s), each >= 0."""
    parts = str(text).split(":")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) not in (1, 2) or not all(np.isfinite(v) and v >= 0 for v in vals):
        raise InvalidInputError(f"--process-noise {text!r}: give Q_RATE[:Q_SUN], numbers >= 0 (the rate random walk's "
                                "density in rad^2/s^3 and the Sun vector's in 1/s; default 1e-13:0)")
    return vals[0], (vals[1] if len(vals) == 2 else 0.0)


def filter_run(ds, kind, *, diode="BPW34FS", errors=None, faults=(), noise=False, seed=0, sigma_meas=None,
               gate_sigma=5.0, gyro_sigma_deg_s=None, q_rate=1e-13, q_sun=0.0, use_threshold=None,
               return_series=False):
    """Return the JSON summary (dict) of a sun-line filter on a run Dataset, WLS and Sun-Albedo-Sun beside it.

    ``kind`` 'sunline-ekf' or 'sunline-ukf' (or 'ekf' / 'ukf'); ``errors`` a
    :class:`~simcore.sensor.errors.SensorErrors`; ``faults`` a sequence of
    :class:`~simcore.sensor.errors.Fault`; ``gyro_sigma_deg_s``: feed a gyro reading the true rate
    plus white noise of that standard deviation (deg/s); ``sigma_meas`` the filters' diode noise
    (normalised; default in the module docstring); ``use_threshold``: readings used from this value up
    (normalised, Basilisk's ``sensorUseThresh``; default :data:`USE_THRESHOLD_SIGMAS` times the noise);
    ``q_rate``, ``q_sun``: the process noise (:func:`estimators.sunline.process_noise`). Start and eclipse: the module docstring. ``return_series=True`` also returns a dict of the
    time series (estimates, rejections, true values).
    """
    check_filter_run(ds, kind)       # one line for a run that cannot feed it
    filt = FILTER_KINDS.get(kind, kind)
    if filt not in ("ekf", "ukf"):
        raise InvalidInputError(f"unknown filter {kind!r}; use one of {', '.join(FILTER_KINDS)}")
    errors = errors or SensorErrors()
    faults = tuple(faults)
    t = ds["t_s"].values
    normals = ds["normal_body"].values
    check_faults(faults, t, len(normals))
    if gyro_sigma_deg_s is not None and not gyro_sigma_deg_s > 0:
        raise InvalidInputError(f"the gyro noise must be > 0 deg/s, got {gyro_sigma_deg_s}")
    if use_threshold is not None and not (np.isfinite(use_threshold) and 0 <= use_threshold < 1):
        raise InvalidInputError(f"the use threshold must be a reading in [0, 1) of the normal-Sun reading, got "
                                f"{use_threshold}")
    if not all(np.isfinite(q) and q >= 0 for q in (q_rate, q_sun)):
        raise InvalidInputError(f"the process noise must be >= 0, got q_rate {q_rate}, q_sun {q_sun}")
    e_p, chain = sensed_readings(ds, diode=diode, errors=errors, faults=faults, noise=noise, seed=seed)
    e_s0 = DIODES[diode].e_s0_w_m2 if isinstance(diode, str) else diode.e_s0_w_m2
    fov = float(np.min(ds["fov_deg"].values))
    live = ~ds["dead"].values.astype(bool)
    sun_true = ds["sun_dir_body"].values
    sunlit = eclipse.sunlit(ds["illumination"].values)
    w_true = true_rate_body(ds["q_gcrs_from_body"].values, t)
    w_perp_true = perpendicular_rate(w_true, sun_true)

    wls, wls_ok = wls_estimate(e_p, normals, fov_deg=fov, e_s0=e_s0, live=live)
    sas, _ = sun_albedo_sun_estimate(e_p, normals, fov_deg=fov, e_s0=e_s0, live=live)
    start_ok = wls_ok & sunlit
    if not start_ok.any():
        raise InvalidInputError("no sunlit epoch of this run has a valid WLS estimate to start the filter from "
                         "(is the whole run in eclipse?)")
    i0 = int(np.argmax(start_ok))
    lsb = chain.lsb_w_m2 / e_s0
    sigma_noise = float(np.sqrt(errors.noise_sigma ** 2 + lsb ** 2 / 12.0))
    if sigma_meas is None:
        sigma_meas = float(np.hypot(sigma_noise, EARTH_LIGHT_SIGMA))
    gyro = None
    if gyro_sigma_deg_s is not None:
        rng = np.random.default_rng([seed, 2])
        gyro = w_true + rng.standard_normal(w_true.shape) * np.radians(gyro_sigma_deg_s)
    p0 = np.diag([INIT_POS_VAR] * 3 + [INIT_RATE_SIGMA_RAD_S ** 2] * 3)
    res = run_sunline_filter(filt, e_p[i0:] / e_s0, normals, t[i0:], fov_deg=fov,
                             x0=np.concatenate([wls[i0], np.zeros(3)]), P0=p0, sigma_meas=sigma_meas,
                             gyro_rad_s=None if gyro is None else gyro[i0:], gate_sigma=gate_sigma,
                             update_mask=sunlit[i0:],
                             use_threshold=USE_THRESHOLD_SIGMAS * sigma_noise if use_threshold is None else use_threshold,
                             gyro_sigma_rad_s=None if gyro_sigma_deg_s is None else np.radians(gyro_sigma_deg_s),
                             q_rate=q_rate, q_sun=q_sun, live=live)
    n, k = e_p.shape
    s_hat = np.full((n, 3), np.nan)
    w_hat = np.full((n, 3), np.nan)
    rejected = np.zeros((n, k), bool)
    s_hat[i0:], w_hat[i0:], rejected[i0:] = res["sun_dir_body"], res["rate_rad_s"], res["rejected"]

    def rate_err(w):
        return np.degrees(np.linalg.norm(perpendicular_rate(w, sun_true) - w_perp_true, axis=1))

    wls_rate = rate_from_sun_vectors(wls, t)
    name = {"ekf": "sunline-ekf", "ukf": "sunline-ukf"}[filt]
    out = {
        "run": ds.attrs.get("configuration"), "filter": name, "diode": diode if isinstance(diode, str) else diode.name,
        "epochs": int(n), "sunlit_epochs": int(sunlit.sum()), "filter_start_s": float(t[i0]),
        "sigma_meas": round(sigma_meas, 5), "gate_sigma": gate_sigma,
        "use_threshold": round(float(USE_THRESHOLD_SIGMAS * sigma_noise if use_threshold is None else use_threshold), 6),
        "q_rate": q_rate, "q_sun": q_sun,
        "gyro_sigma_deg_s": gyro_sigma_deg_s,
        "sensor_errors": {f: getattr(errors, f) for f in errors.__dataclass_fields__},
        "faults": [{"diode": f.diode, "kind": f.kind, "onset_s": f.onset_s, "end_s": f.end_s} for f in faults],
        "sun_error_deg": {"sunlit": _stats(angle_error_deg(s_hat, sun_true), sunlit)},
        "rate_error_deg_s": {"sunlit": _stats(rate_err(w_hat), sunlit)},
        "rate_error_full_deg_s": {"sunlit": _stats(np.degrees(np.linalg.norm(w_hat - w_true, axis=1)), sunlit)},
        "rejected_epochs_per_diode": rejected.sum(axis=0).tolist(),
        "compare": {
            "wls": {"sun_error_deg": {"sunlit": _stats(angle_error_deg(wls, sun_true), sunlit)},
                    "rate_error_deg_s": {"sunlit": _stats(rate_err(wls_rate), sunlit)}},
            "sun_albedo_sun": {"sun_error_deg": {"sunlit": _stats(angle_error_deg(sas, sun_true), sunlit)}},
        },
    }
    first = []
    for f in faults:
        after = np.flatnonzero((t >= f.onset_s) & rejected[:, f.diode])
        first.append(None if after.size == 0 else round(float(t[after[0]] - f.onset_s), 3))
    out["first_rejection_after_onset_s"] = first
    if return_series:
        series = {"t_s": t, "sun_dir_body": s_hat, "rate_rad_s": w_hat, "rejected": rejected, "e_p": e_p,
                  "wls": wls, "sun_albedo_sun": sas, "sun_true": sun_true, "rate_true": w_true, "sunlit": sunlit}
        return out, series
    return out


def summary_lines(run, out):
    """Return the text report (lines) of :func:`filter_run`'s summary ``out`` for run file ``run``."""
    lines = []
    lines.append(f"{run}: {out.get('run')}, {out['filter']} (use threshold {out['use_threshold']:g}, process noise "
                 f"{out['q_rate']:g}:{out['q_sun']:g}), sunlit errors (mean / p95 / max)")
    rows = [(out["filter"], out["sun_error_deg"], out.get("rate_error_deg_s"))]
    rows += [(name, c["sun_error_deg"], c.get("rate_error_deg_s")) for name, c in out.get("compare", {}).items()]
    for name, sun, rate in rows:
        s = sun["sunlit"]
        line = f"  {name:<16} Sun {s['mean']} / {s['p95']} / {s['max']} deg"
        if rate:
            r = rate["sunlit"]
            line += f";  rate (perpendicular to the Sun) {r['mean']} / {r['p95']} / {r['max']} deg/s"
        lines.append(line)
    for f, dt in zip(out.get("faults", []), out.get("first_rejection_after_onset_s", [])):
        lines.append(f"  fault {f['kind']} on diode {f['diode']} at {f['onset_s']:g} s: "
                     + ("never rejected" if dt is None else f"first rejected {dt:g} s after its onset"))
    return lines
