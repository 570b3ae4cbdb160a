"""The thesis' chapter-4 study reproduced on rendered irradiance, and what goes beyond it.

``sunsim reproduce`` renders (or reuses) one run per configuration, runs the
sensor chain and every estimator on it, and writes a results page
(``README.md`` with tables and thesis-style figures, ``results.json``) to a
folder. Settings follow the thesis (table 4.3, SPEC sec. 7): ESTCube-1, start
2016-07-02T00:00Z, 1 s steps, tumbling 1.9 deg/s, TOMS 2005, BPW34FS, no
noise; the +x diode at (s_az, s_el) = (-1, -1) dead in the 14-diode layouts.
The span is the whole day (``day``) or the thesis' two orbits 1.8e4-2.8e4 s
(``orbits``).
"""
import dataclasses
import json
import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from simcore.plots import plot_estimator_error, save_figure
from simcore.studies.cross_map import evaluate_cross_map

from estimators.metrics import hanning_mean_std
from simcore.constants import E_SUN_W_M2
from simcore.pipeline.evaluate import run_errors
from simcore.pipeline.run import RunOptions, PreparedRun, execute, open_run

CONFIGS = ("tilt0_fov90", "tilt20_fov70", "tilt20_fov75", "tilt25_fov70", "tilt25_fov75", "tilt30_fov70",
           "tilt30_fov75")
SPANS = {"day": ("2016-07-02T00:00:00Z", 86400.0), "orbits": ("2016-07-02T05:00:00Z", 10000.0),
         "short": ("2016-07-02T00:45:00Z", 600.0)}   # "short": a demonstration that runs in a minute


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


def summarise(errs, sunlit, t_s, period_s, window=181):
    """Return per-estimator figures: sunlit mean/p95/max angle error, and per orbit the peak of the
    Hanning-window mean of the absolute inertial zenith and azimuth errors (thesis figs. 4.6-4.17)."""
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
               "share_below_5_deg": stat(lambda x: np.mean(x < 5.0), a)}
        for comp in ("zenith", "azimuth"):
            hm, _ = hanning_mean_std(np.where(sunlit, np.abs(e[f"{comp}_deg"]), np.nan), window=window)
            hm = np.where(sunlit, hm, np.nan)
            peaks = [stat(np.max, hm[orbit == o]) for o in np.unique(orbit)]
            row[f"{comp}_mean_peak_per_orbit_deg"] = peaks
            row[f"{comp}_mean_peak_deg"] = stat(np.max, np.array(peaks))
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


def reproduce(folder, *, span="day", page_folder=None, log=print, render=True, second_spin=0.5,
              cross_map=True, noise=True):
    """Render what is missing, evaluate everything and write the results page; return the results dict."""
    page_folder = page_folder or os.path.join(folder, "page")
    os.makedirs(folder, exist_ok=True)
    os.makedirs(page_folder, exist_ok=True)
    results = {"span": span, "start": SPANS[span][0], "duration_s": SPANS[span][1], "configs": {}}
    zen, lit, t_ref = {}, {}, None
    for cfg in CONFIGS:
        opts = run_options(cfg, folder, span=span)
        if not render and not os.path.exists(opts.output):
            log(f"skipping {cfg}: {opts.output} missing")
            continue
        ds = ensure_run(opts, log=log)
        errs, sunlit, _ = run_errors(ds, smart_select=True)
        t = ds["t_s"].values + (ds["time"].values[0] - np.datetime64("2016-07-02T00:00:00")) / np.timedelta64(1, "s")
        res = summarise(errs, sunlit, t, float(ds.attrs["period_s"]))
        res["check"] = json.loads(ds.attrs["check"])
        if noise:
            errs_n, _, _ = run_errors(ds, noise=True, seed=1)
            res["with_noise"] = {k: v["mean_deg"] for k, v in summarise(errs_n, sunlit, t, float(ds.attrs["period_s"])).items()}
        results["configs"][cfg] = res
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
            if not render and not os.path.exists(opts.output):
                continue
            ds = ensure_run(opts, log=log)
            errs, sunlit, _ = run_errors(ds, smart_select=True)
            t = ds["t_s"].values
            results["spin"]["configs"][cfg] = {k: {kk: v[kk] for kk in ("mean_deg", "p95_deg", "max_deg")}
                                               for k, v in summarise(errs, sunlit, t, float(ds.attrs["period_s"])).items()}
    if cross_map:
        results["cross_map"] = cross_map_rows(folder, span=span, render=render, log=log)
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


def _fmt(x):
    return "-" if x is None or not np.isfinite(x) else f"{x:.2f}"


def write_page(results, page_folder):
    """Write README.md with the tables and figures of ``results`` (see :func:`reproduce`)."""
    names = ["pinv", "wls", "albedo_sun", "sun_albedo_sun_wls", "sun_albedo_sun", "smart_select"]
    cfgs = list(results["configs"])
    lines = [f"# The thesis' chapter-4 study, reproduced on rendered irradiance ({results['span']})", "",
             "Generated by `sunsim reproduce`. Settings: ESTCube-1 (shipped TLE), start "
             f"{results['start']}, {results['duration_s']:.0f} s at 1 s, tumble 1.9 deg/s about (1,1,1)/sqrt 3, "
             "TOMS 2005, BPW34FS (E_S0 = 188.1 W/m^2), no noise, diode 0 dead in the 14-diode layouts, "
             "irradiance ray traced through the real wells, ramps and body (0.2 % / 1 % standard error).", "",
             "## Peak of the Hanning-window (181 samples) mean |zenith error| over the sunlit orbits [deg]", "",
             "| configuration | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for c in cfgs:
        r = results["configs"][c]
        lines.append(f"| {c} | " + " | ".join(_fmt(r.get(n, {}).get("zenith_mean_peak_deg")) for n in names) + " |")
    lines += ["", "## Sunlit angle error: mean / 95th percentile / max [deg]", "",
              "| configuration | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for c in cfgs:
        r = results["configs"][c]
        cells = []
        for n in names:
            x = r.get(n)
            cells.append("-" if x is None else f"{_fmt(x['mean_deg'])} / {_fmt(x['p95_deg'])} / {_fmt(x['max_deg'])}")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    lines += ["", "Per orbit (the thesis compares orbits 1.8e4-2.8e4 s), the peak of the Hanning mean "
              "|zenith error| of Sun-Albedo-Sun (Albedo-Sun start) [deg]:", "",
              "| configuration | " + " | ".join(f"orbit {i}" for i in range(len(
                  next(iter(results["configs"].values()))["sun_albedo_sun"]["zenith_mean_peak_per_orbit_deg"]))) + " |"]
    lines.append("|---" * (1 + len(next(iter(results["configs"].values()))["sun_albedo_sun"]["zenith_mean_peak_per_orbit_deg"])) + "|")
    for c in cfgs:
        p = results["configs"][c]["sun_albedo_sun"]["zenith_mean_peak_per_orbit_deg"]
        lines.append(f"| {c} | " + " | ".join(_fmt(x) for x in p) + " |")
    if any("with_noise" in r for r in results["configs"].values()):
        lines += ["", "## With sensor noise (shot + Johnson, eqs. 2.26-2.28): sunlit mean angle error [deg]", "",
                  "| configuration | " + " | ".join(names[:5]) + " |", "|---" * 6 + "|"]
        for c in cfgs:
            wn = results["configs"][c].get("with_noise", {})
            lines.append(f"| {c} | " + " | ".join(_fmt(wn.get(n)) for n in names[:5]) + " |")
    spin = results.get("spin", {})
    if spin.get("configs"):
        lines += ["", f"## Second spin rate: {spin['rate_deg_s']} deg/s, orbits 1.8e4-2.8e4 s: sunlit mean / p95 [deg]", "",
                  "| configuration | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
        for c, r in spin["configs"].items():
            lines.append(f"| {c} | " + " | ".join("-" if n not in r else f"{_fmt(r[n]['mean_deg'])} / {_fmt(r[n]['p95_deg'])}"
                                                  for n in names) + " |")
    if results.get("cross_map"):
        lines += ["", "## On-board albedo prediction, cross-map (tilt20_fov70): sunlit mean / p95 / max [deg]", "",
                  "| rendered with | on-board map | estimator | mean | p95 | max | invalid |", "|---" * 7 + "|"]
        for r in results["cross_map"]:
            lines.append(f"| {r['truth_map']} | {r['onboard_map']} | {r['estimator']} | {_fmt(r['mean_deg'])} | "
                         f"{_fmt(r['p95_deg'])} | {_fmt(r['max_deg'])} | {r['n_invalid']} |")
    lines += ["", "## Figures", ""]
    for f in sorted(os.listdir(page_folder)):
        if f.endswith(".png"):
            lines.append(f"![{f}]({f})")
    discussion = os.path.join(page_folder, "discussion.md")   # hand-written, kept across regenerations
    if os.path.exists(discussion):
        lines += ["", Path(discussion).read_text()]
    with open(os.path.join(page_folder, "README.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
