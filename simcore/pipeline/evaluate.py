"""From diode irradiance to Sun-vector errors: sensor chain, estimators, metrics.

The glue between what a run stores (irradiance per diode, the true Sun vector,
the attitude) and what users judge a design by (the angle error of each
estimator, sunlit, per orbit). Estimators only see measurements and normals.
"""
import numpy as np

from estimators import ESTIMATORS, THESIS_ESTIMATORS
from estimators.metrics import angle_error_deg, orbit_summary, zenith_azimuth_error_deg
from simcore.environment import eclipse
from simcore.environment.attitude import quat_to_matrix
from simcore.sensor.chain import DIODES, SensorChain


def measure(irradiance_w_m2, *, diode="BPW34FS", dead=(), noise=False, seed=0, **sensor_kw):
    """Return the measured effective irradiance E_p (N, K) (eqs. 4.16-4.25) of irradiance (N, K) W/m^2."""
    chain = SensorChain(diode=diode, dead=tuple(int(i) for i in dead), noise=noise, seed=seed, **sensor_kw)
    return chain.measure(np.asarray(irradiance_w_m2, dtype=float))


def run_estimators(e_p, normals, fov_deg, *, e_s0, live=None, which=None, pinv_keep_zero_readings=False):
    """Return {name: (s_hat (N, 3), valid (N,))} for the thesis' estimators (or ``which`` of them).

    ``pinv_keep_zero_readings``: the pseudoinverse selects every E_p >= E_S0 cos(FOV), zeros included
    (at FOV 90 deg the thesis' "without choosing photodiodes"; :func:`estimators.pinv_estimate`)."""
    out = {}
    for name in THESIS_ESTIMATORS:
        if which is not None and name not in which:
            continue
        kw = {"keep_zero_readings": True} if name == "pinv" and pinv_keep_zero_readings else {}
        out[name] = ESTIMATORS[name](e_p, normals, fov_deg=fov_deg, e_s0=e_s0, live=live, **kw)
    return out


def errors(estimates, sun_dir_body_true, R_gcrs_from_body=None):
    """Return {name: dict(angle_deg, zenith_deg, azimuth_deg, valid)} for estimates {name: (s_hat, valid)}.

    Zenith/azimuth errors are taken in the inertial frame (thesis sec. 4.3) when the attitude is given.
    """
    out = {}
    for name, (s_hat, valid) in estimates.items():
        e = {"angle_deg": angle_error_deg(s_hat, sun_dir_body_true), "valid": np.asarray(valid, bool)}
        if R_gcrs_from_body is not None:
            s_i = np.einsum("nij,nj->ni", R_gcrs_from_body, s_hat)
            t_i = np.einsum("nij,nj->ni", R_gcrs_from_body, sun_dir_body_true)
            e["zenith_deg"], e["azimuth_deg"] = zenith_azimuth_error_deg(s_i, t_i)
        out[name] = e
    return out


def error_table(errs, sunlit, orbit_index=None):
    """Return rows {estimator, orbit, n, n_invalid, mean_deg, p95_deg, max_deg} over sunlit epochs:
    all orbits together ('all'), and per orbit when ``orbit_index`` (N,) is given."""
    rows = []
    sunlit = np.asarray(sunlit, bool)
    keys = ("n", "n_invalid", "mean_deg", "p95_deg", "max_deg")

    def add(name, summary, label=None):
        for i, orbit in enumerate(summary["orbit"]):
            rows.append({"estimator": name, "orbit": label if label is not None else int(orbit),
                         **{k: summary[k][i].item() for k in keys}})
    for name, e in errs.items():
        add(name, orbit_summary(e["angle_deg"], sunlit, np.zeros(sunlit.size, int)), "all")
        if orbit_index is not None:
            add(name, orbit_summary(e["angle_deg"], sunlit, orbit_index))
    return rows


def run_errors(ds, *, diode="BPW34FS", noise=False, seed=0, which=None, smart_select=False,
               announce_dead=True, pinv_keep_zero_readings=False, irradiance_w_m2=None):
    """Return (errs, sunlit, extras) for a run Dataset (:mod:`simcore.pipeline.run`): rendered direct + albedo
    through the sensor chain into the thesis' estimators (plus ``smart_select`` for opposite diode pairs),
    errors against the true Sun vector (:func:`errors`); ``sunlit`` (N,) is the full-Sun mask.

    ``announce_dead``: the estimators are told which diodes are dead (``live``) and leave them out;
    False is the thesis' way (a dead diode reads 0, unannounced). ``pinv_keep_zero_readings``: see
    :func:`run_estimators`. ``irradiance_w_m2`` (N, K): evaluate this irradiance instead of the
    rendered one (e.g. an analytic model on the run's geometry)."""
    irr = ds["irradiance"].sum("component").values if irradiance_w_m2 is None else np.asarray(irradiance_w_m2)
    live = ~ds["dead"].values.astype(bool)
    normals = ds["normal_body"].values
    fov = float(np.min(ds["fov_deg"].values)) if "fov_deg" in ds else 90.0
    e_s0 = DIODES[diode].e_s0_w_m2
    e_p = measure(irr, diode=diode, dead=np.flatnonzero(~live), noise=noise, seed=seed)
    told = live if announce_dead else None
    est = run_estimators(e_p, normals, fov, e_s0=e_s0, live=told, which=which,
                         pinv_keep_zero_readings=pinv_keep_zero_readings)
    if smart_select:
        est["smart_select"] = ESTIMATORS["smart_select"](e_p, normals, fov_deg=fov, e_s0=e_s0, live=told)
    R = quat_to_matrix(ds["q_gcrs_from_body"].values)
    sunlit = eclipse.sunlit(ds["illumination"].values)
    return errors(est, ds["sun_dir_body"].values, R), sunlit, {"e_p": e_p, "estimates": est}


def evaluate_run(ds, *, diode="BPW34FS", noise=False, seed=0, which=None):
    """Return (errs, table, extras) for a run Dataset: :func:`run_errors` and its :func:`error_table`
    (sunlit, all orbits together and per orbit when the run spans more than one)."""
    errs, sunlit, extras = run_errors(ds, diode=diode, noise=noise, seed=seed, which=which)
    t = ds["t_s"].values
    period = float(ds.attrs.get("period_s", 0) or 0)
    orbit = (t // period).astype(int) if period > 0 and t[-1] >= period else None
    return errs, error_table(errs, sunlit, orbit), {**extras, "sunlit": sunlit}
