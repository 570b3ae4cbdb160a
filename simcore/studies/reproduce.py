"""The thesis' chapter-4 study reproduced on rendered irradiance, and what goes beyond it.

``sunsim reproduce`` renders (or reuses) one run per configuration, runs the
sensor chain and every estimator on it, and writes a results page
(``README.md`` with tables and thesis-style figures, ``results.json``) to a
folder. Settings follow the thesis (table 4.3, SPEC sec. 7): ESTCube-1, start
2016-07-02T00:00Z, 1 s steps, tumbling 1.9 deg/s, TOMS 2005, BPW34FS, no
noise; the +x diode at (s_az, s_el) = (-1, -1) dead in the 14-diode layouts.
The span is the whole day (``day``) or the thesis' two orbits 1.8e4-2.8e4 s
(``orbits``).

The estimators follow the thesis where the project chose differently (:data:`THESIS_CHOICES`); the
project's choices are evaluated beside them as labelled :data:`VARIANTS`. For the FOV-75 layouts the
Albedo-Sun errors are also computed on the analytic irradiance with the thesis' eq. 4.15 response, with the
wells alone and with wells + body (:data:`APERTURE_MODELS`), so the page can say whether an agreement
with the thesis rests on the body's self-shadowing. Runs whose analytic check failed are refused unless
``allow_failed_checks``; the page (:mod:`simcore.studies.reproduce_page`) is rendered from the results
dict alone, which is also written as ``results.json``.
"""
import dataclasses
import json
import os

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from simcore.plots import plot_estimator_error, save_figure
from simcore.studies.cross_map import evaluate_cross_map
from simcore.studies.reproduce_page import write_page

from estimators.metrics import hanning_mean_std
from simcore.constants import E_SUN_W_M2
from simcore.errors import InvalidInputError
from simcore.pipeline.evaluate import run_errors
from simcore.pipeline.options import RunOptions
from simcore.pipeline.run import PreparedRun, execute
from simcore.pipeline.runfile import open_run
from simcore.pipeline.store import chunk_ranges
from simcore.radiometry.analytic import diode_irradiance
from simcore.radiometry.response import Eq415Response
from simcore.sensor.chain import DIODES
from simcore.studies.choices import CONFIGS, SPANS

CROSS_MAP_CONFIG = "tilt20_fov70"                    # the on-board albedo prediction across maps
DAY_START = "2016-07-02T00:00:00"                    # the thesis' t = 0 (table 4.3)
DIODE = "BPW34FS"
HANNING_WINDOW = 181                                 # samples, the thesis' centred Hanning window (figs. 4.6-4.17)

# The thesis' own choices, the page's default (sec. 4.3): its dead diode reads 0 and the estimators are not
# told (sec. 3.2.4: "one photodiode is set as dead"), and its baseline pseudoinverse uses every diode with
# E_p >= E_S0 cos(90 deg) = 0 ("the pseudo inverse without choosing photodiodes", secs. 4.3.1, 5.1).
THESIS_CHOICES = {"announce_dead": False, "pinv_keep_zero_readings": True}
# The project's choices, each shown on the page as a labelled variant beside the thesis' way.
VARIANTS = {
    "dead_announced": {
        "label": "dead diode announced",
        "words": "the estimators are told which diode is dead and leave it out (the project's choice; the "
                 "thesis' dead diode reads zero, unannounced)",
        "options": {"announce_dead": True, "pinv_keep_zero_readings": True}},
    "pinv_drops_zero_readings": {
        "label": "pseudoinverse drops zero readings",
        "words": "the pseudoinverse leaves out diodes reading zero (the project's choice; the thesis' baseline uses "
                 "every diode, zero readings included)",
        "options": {"announce_dead": False, "pinv_keep_zero_readings": False}, "which": ("pinv",)},
}
# The irradiance models compared for the Albedo-Sun FOV-75 claim (item: does the agreement need the body?).
APERTURE_MODELS = {"eq415": "eq. 4.15, no body (the thesis' model)", "wells": "square wells, no body",
                   "wells_body": "square wells + body (analytic)"}
APERTURE_MODEL_ESTIMATOR = "albedo_sun"


def run_options(config, folder, *, span="day", spin_rate_deg_s=1.9, reflectivity="toms2005", **kw):
    """Return the RunOptions of one configuration of the study (file name encodes the settings)."""
    start, duration = SPANS[span]
    dead = () if config == "tilt0_fov90" else (0,)
    name = f"{config}_{span}_spin{spin_rate_deg_s:g}_{reflectivity}.nc"
    # the thesis' Sun: a constant 1366.1 W/m^2, no 1/r^2
    return RunOptions(config=config, start=start, duration_s=duration, spin_rate_deg_s=spin_rate_deg_s,
                      reflectivity=reflectivity, dead=dead, output=os.path.join(folder, name),
                      e_sun_w_m2=E_SUN_W_M2, distance_scaling=False, **kw)


def ensure_run(opts, log=print):
    """Return the Dataset of ``opts``' run, rendering it first (resumably) if its file is missing."""
    if not os.path.exists(opts.output):
        log(f"rendering {os.path.basename(opts.output)} ...")
        execute(opts, log=log)
    return open_run(opts.output)


class FailedCheckError(InvalidInputError):
    """Run files whose analytic check failed were asked to feed the results page."""


def read_check(path):
    """Return the analytic check of a run file as this version of sunsim makes it from the file's arrays
    (:func:`simcore.pipeline.runfile.check_run`; the ``check`` attribute the file was written with may come
    from an older check)."""
    from simcore.pipeline.runfile import check_run, open_run
    return check_run(open_run(path))[1]


def check_passed(check):
    """Return True when a check dict says it passed (a missing or non-boolean 'pass' is a failure)."""
    return check.get("pass") is True


def refuse_failed(failed, folder):
    """Raise :class:`FailedCheckError` naming the runs ``failed`` [(label, path)], if there are any."""
    if failed:
        names = ", ".join(f"{label} ({os.path.basename(path)})" for label, path in failed)
        raise FailedCheckError(f"the analytic check failed for {names} in {folder}; see 'sunsim validate FILE', "
                               "re-render those runs, or add --allow-failed-checks to build the page anyway "
                               "with their numbers marked 'check FAILED'")


def planned_runs(folder, *, span, second_spin, cross_map, render):
    """Return [(label, RunOptions)] of every run the page needs (the study's, the second spin's, the cross-map's)."""
    runs = [(cfg, run_options(cfg, folder, span=span)) for cfg in CONFIGS]
    if second_spin:
        runs += [(f"{cfg} at {second_spin:g} deg/s", run_options(cfg, folder, span="orbits", spin_rate_deg_s=second_spin))
                 for cfg in CONFIGS]
    if cross_map:
        runs.append((f"{CROSS_MAP_CONFIG} with ceres2018-all",
                     run_options(CROSS_MAP_CONFIG, folder, span=span, reflectivity="ceres2018-all")))
    return [(label, o) for label, o in runs if render or os.path.exists(o.output)]


def refuse_existing_failed(folder, *, span, second_spin, cross_map, render):
    """Raise :class:`FailedCheckError` if any run file the page needs is already there with a failed check
    (called before anything is rendered or written)."""
    runs = planned_runs(folder, span=span, second_spin=second_spin, cross_map=cross_map, render=render)
    refuse_failed([(label, o.output) for label, o in runs
                   if os.path.exists(o.output) and not check_passed(read_check(o.output))], folder)


def summarise(errs, sunlit, t_s, period_s, window=None, r_sat_ecef_m=None):
    """Return per-estimator figures: sunlit mean/p95/max angle error, and per orbit the peak of the
    Hanning-window mean of the absolute inertial zenith and azimuth errors (thesis figs. 4.6-4.17).

    ``t_s`` (N,) counts from the thesis' t = 0 (2016-07-02T00:00Z), so orbit o spans
    [o period_s, (o + 1) period_s); ``orbits`` lists the orbit numbers of the per-orbit lists. With
    ``r_sat_ecef_m`` (N, 3), the time (s) and geocentric latitude/longitude (deg) of the largest Hanning-mean
    zenith error are added."""
    window = HANNING_WINDOW if window is None else window
    orbit = (t_s // period_s).astype(int)

    def stat(fn, x):
        x = x[np.isfinite(x)]
        return float(fn(x)) if x.size else float("nan")
    out = {}
    for name, e in errs.items():
        a = np.where(sunlit, e["angle_deg"], np.nan)
        row = {"n_sunlit": int(sunlit.sum()), "n_invalid": int((sunlit & ~np.isfinite(a)).sum()),
               "mean_deg": stat(np.mean, a), "p95_deg": stat(lambda x: np.percentile(x, 95), a),
               "max_deg": stat(np.max, a),
               "share_below_5_deg": stat(lambda x: np.mean(x < 5.0), a),
               "orbits": [int(o) for o in np.unique(orbit)]}
        for comp in ("zenith", "azimuth"):
            hm, _ = hanning_mean_std(np.where(sunlit, np.abs(e[f"{comp}_deg"]), np.nan), window=window)
            hm = np.where(sunlit, hm, np.nan)
            peaks = [stat(np.max, hm[orbit == o]) for o in np.unique(orbit)]
            row[f"{comp}_mean_peak_per_orbit_deg"] = peaks
            row[f"{comp}_mean_peak_deg"] = stat(np.max, np.array(peaks))
            if comp == "zenith" and r_sat_ecef_m is not None and np.isfinite(hm).any():
                i = int(np.nanargmax(hm))
                x, y, z = r_sat_ecef_m[i]
                row["zenith_peak_t_s"] = float(t_s[i])
                row["zenith_peak_lat_deg"] = float(np.degrees(np.arctan2(z, np.hypot(x, y))))
                row["zenith_peak_lon_deg"] = float(np.degrees(np.arctan2(y, x)))
        out[name] = row
    return out


def _figure_means(t_s, series, title, path, sunlit):
    """Hanning-mean |zenith error| of several configurations against time (thesis figs. 4.6-4.17)."""
    fig = Figure(figsize=(11, 5.5))
    ax = fig.add_subplot()
    for label, z in series.items():
        hm, _ = hanning_mean_std(np.where(sunlit[label], np.abs(z), np.nan))
        ax.plot(t_s / 1e4, np.where(sunlit[label], hm, np.nan), lw=1.2, label=label)
    ax.set_xlabel("time since 2016-07-02T00:00Z [1e4 s]")
    ax.set_ylabel("Hanning mean of |zenith error| [deg]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(ncol=4, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12))
    fig.tight_layout()
    save_figure(fig, path)


def _t_since_day_start(ds):
    return ds["t_s"].values + (ds["time"].values[0] - np.datetime64(DAY_START)) / np.timedelta64(1, "s")


def aperture_model_irradiance(opts, model, *, chunk=4096, study=None):
    """Return the analytic irradiance (N, K) W/m^2 (direct + albedo) of ``opts``' run with the diodes'
    response ``model``: 'eq415' (thesis eq. 4.15 at each diode's FOV, no body) or 'wells' (the square wells
    the renderer traces, no body); the same orbit, attitude, Sun disc, eclipse and map as the run
    (``study``: its :class:`PreparedRun`, if already built)."""
    study = PreparedRun(opts) if study is None else study
    if model == "eq415":
        responses = [Eq415Response(d.fov_deg) for d in study.config.diodes]
    elif model == "wells":
        responses = study.config.apertures
    else:
        raise ValueError(f"model must be 'eq415' or 'wells', got {model!r}")
    g, n = study.geometry, len(study.epochs)
    out = np.zeros((n, len(responses)))
    for s, e in chunk_ranges(n, chunk):
        sl = slice(s, e)
        out[sl] = diode_irradiance(g.r_sat_ecef_m[sl], g.r_sun_ecef_m[sl], g.R_ecef_from_body[sl],
                                   study.config.frames, responses, map=study.map, e_sun_w_m2=opts.e_sun_w_m2,
                                   distance_scaling=opts.distance_scaling,
                                   eclipse="conical" if opts.sun_disc else "cylindrical", body=None,
                                   sun_angular_radius_rad=study.sun_angular_radius_rad).total_w_m2
    return out


def aperture_models(ds, opts, t_s):
    """Return ({model: summary row}, {variant: {model: summary row}}) of :data:`APERTURE_MODEL_ESTIMATOR` on
    the irradiance models of :data:`APERTURE_MODELS` for the geometry of run ``ds``: with the thesis'
    estimator choices, and with those of the variant 'dead_announced' (the estimators' view of the dead
    diode changes how much the body's shadow matters)."""
    study = PreparedRun(opts)
    irr = {m: aperture_model_irradiance(opts, m, study=study) for m in ("eq415", "wells")}
    irr["wells_body"] = ds["analytic"].sum("component").values

    def rows(options):
        out = {}
        for m, e in irr.items():
            errs, sunlit, _ = run_errors(ds, which=(APERTURE_MODEL_ESTIMATOR,), irradiance_w_m2=e, **options)
            out[m] = summarise(errs, sunlit, t_s, float(ds.attrs["period_s"]))[APERTURE_MODEL_ESTIMATOR]
        return out
    return rows(THESIS_CHOICES), {"dead_announced": rows(VARIANTS["dead_announced"]["options"])}


def reproduce(folder, *, span="day", page_folder=None, log=print, render=True, second_spin=0.5,
              cross_map=True, noise=True, allow_failed_checks=False):
    """Render what is missing, evaluate everything and write the results page; return the results dict.

    The estimators follow the thesis (:data:`THESIS_CHOICES`); the project's choices are evaluated beside
    them as :data:`VARIANTS`. A run whose analytic check failed stops the study with
    :class:`FailedCheckError` (existing files before anything is rendered, new ones before the page is
    written) unless ``allow_failed_checks``: then the page marks every number derived from it."""
    page_folder = page_folder or os.path.join(folder, "page")
    runs = planned_runs(folder, span=span, second_spin=second_spin, cross_map=cross_map, render=render)
    if not allow_failed_checks:
        refuse_existing_failed(folder, span=span, second_spin=second_spin, cross_map=cross_map, render=render)
    os.makedirs(folder, exist_ok=True)
    for _, o in runs:
        if not os.path.exists(o.output):
            log(f"rendering {os.path.basename(o.output)} ...")
            execute(o, log=log)
    checks = {o.output: read_check(o.output) for _, o in runs}
    if not allow_failed_checks:
        refuse_failed([(label, o.output) for label, o in runs if not check_passed(checks[o.output])], folder)
    os.makedirs(page_folder, exist_ok=True)

    e_s0 = DIODES[DIODE].e_s0_w_m2
    o0 = run_options(CONFIGS[0], folder, span=span)
    results = {"span": span, "start": SPANS[span][0], "duration_s": SPANS[span][1],
               "settings": {"step_s": o0.step_s, "spin_rate_deg_s": o0.spin_rate_deg_s,
                            "spin_axis": list(o0.spin_axis), "reflectivity": o0.reflectivity, "diode": DIODE,
                            "e_s0_w_m2": e_s0, "e_sun_w_m2": o0.e_sun_w_m2, "rel_se_direct": o0.rel_se_direct,
                            "rel_se_albedo": o0.rel_se_albedo, "dead_in_14_diode_layouts": [0],
                            "hanning_window": HANNING_WINDOW},
               "thesis_choices": dict(THESIS_CHOICES), "allow_failed_checks": bool(allow_failed_checks),
               "configs": {},
               "variants": {k: {"label": v["label"], "words": v["words"], "configs": {}} for k, v in VARIANTS.items()},
               "aperture_models": {"estimator": APERTURE_MODEL_ESTIMATOR, "labels": dict(APERTURE_MODELS),
                                   "configs": {}}}
    zen, lit, t_ref = {}, {}, None
    for cfg in CONFIGS:
        opts = run_options(cfg, folder, span=span)
        if opts.output not in checks:
            log(f"skipping {cfg}: {opts.output} missing")
            continue
        ds = open_run(opts.output)
        t = _t_since_day_start(ds)
        period = float(ds.attrs["period_s"])
        results.setdefault("period_s", period)
        errs, sunlit, _ = run_errors(ds, smart_select=True, **THESIS_CHOICES)
        res = summarise(errs, sunlit, t, period, r_sat_ecef_m=ds["r_sat_ecef"].values)
        res["check"] = checks[opts.output]
        res["check_pass"] = check_passed(res["check"])
        if noise:
            errs_n, _, _ = run_errors(ds, noise=True, seed=1, **THESIS_CHOICES)
            res["with_noise"] = {k: v["mean_deg"] for k, v in summarise(errs_n, sunlit, t, period).items()}
        results["configs"][cfg] = res
        for key, v in VARIANTS.items():
            errs_v, _, _ = run_errors(ds, smart_select="which" not in v, which=v.get("which"), **v["options"])
            results["variants"][key]["configs"][cfg] = summarise(errs_v, sunlit, t, period)
        if cfg.endswith("_fov75"):
            am = results["aperture_models"]
            am["configs"][cfg], by_variant = aperture_models(ds, opts, t)
            for key, rows in by_variant.items():
                am.setdefault("variants", {}).setdefault(key, {})[cfg] = rows
        for name in errs:
            zen.setdefault(name, {})[cfg] = errs[name]["zenith_deg"]
        lit[cfg], t_ref = sunlit, t
        if cfg in ("tilt0_fov90", "tilt25_fov70"):
            for name in ("pinv", "sun_albedo_sun"):
                plot_estimator_error(t, np.abs(errs[name]["zenith_deg"]), sunlit=sunlit,
                                     title=f"{cfg}, {name}: |zenith error| (inertial)",
                                     ylabel="|zenith error| [deg]", path=os.path.join(page_folder, f"{cfg}_{name}.png"))
    if t_ref is not None:
        for name, series in zen.items():
            _figure_means(t_ref, series, f"{name}: all configurations", os.path.join(page_folder, f"means_{name}.png"), lit)

    if second_spin:
        results["spin"] = {"rate_deg_s": second_spin, "configs": {}}
        for cfg in CONFIGS:
            opts = run_options(cfg, folder, span="orbits", spin_rate_deg_s=second_spin)
            if opts.output not in checks:
                continue
            ds = open_run(opts.output)
            errs, sunlit, _ = run_errors(ds, smart_select=True, **THESIS_CHOICES)
            row = {k: {kk: v[kk] for kk in ("mean_deg", "p95_deg", "max_deg")}
                   for k, v in summarise(errs, sunlit, _t_since_day_start(ds), float(ds.attrs["period_s"])).items()}
            row["check"] = checks[opts.output]
            row["check_pass"] = check_passed(row["check"])
            results["spin"]["configs"][cfg] = row
    if cross_map:
        paths = {m: run_options(CROSS_MAP_CONFIG, folder, span=span, reflectivity=m).output
                 for m in ("toms2005", "ceres2018-all")}
        if all(p in checks for p in paths.values()):
            results["cross_map"] = cross_map_rows(folder, span=span, render=False, log=log)
            results["cross_map_checks"] = {m: checks[p] for m, p in paths.items()}
    with open(os.path.join(page_folder, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    write_page(results, page_folder)
    return results



def cross_map_rows(folder, *, span="day", config="tilt20_fov70", render=True, log=print):
    """Return the cross-map table of the on-board albedo estimator: truth rendered with CERES 2018 and
    TOMS 2005, on-board prediction from the other map (and the thesis estimators beside it)."""
    truth, geometry = {}, None
    for m in ("toms2005", "ceres2018-all"):
        opts = run_options(config, folder, span=span, reflectivity=m)
        if not render and not os.path.exists(opts.output):
            return []
        ds = ensure_run(opts, log=log)
        truth[m] = ds["irradiance"].sum("component").values
        if geometry is None:
            geometry = PreparedRun(dataclasses.replace(opts)).geometry
    rows = evaluate_cross_map(config, truth_irradiance=truth, geometry=geometry,
                              truth_maps=("ceres2018-all", "toms2005"), onboard_maps=("toms2005", "ceres2018-all"),
                              dead=[0])
    return [{k: (float(v) if isinstance(v, (np.floating, float)) else v) for k, v in r.items()} for r in rows]
