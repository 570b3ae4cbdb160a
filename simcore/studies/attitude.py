"""The thesis' further work answered: attitude error per configuration x gyro, with and without the
on-board albedo prediction, over seeds on Dask, and a results page.

``sunsim attitude-study`` uses (or renders) the run files of ``sunsim reproduce`` (same folder,
same file names: :func:`simcore.studies.reproduce.run_options`), runs :func:`simcore.pipeline.evaluate_attitude.run_mekf`
for every (configuration, gyro, on-board albedo yes/no, seed) as one Dask task (a local cluster by
default), and writes ``README.md``, ``results.json`` and figures to the page folder. Each finished
evaluation is kept in ``<page>/evaluations/``: started again, the study skips those and resumes. The seed
draws the gyro's and magnetometer's errors and all sensor noise; the spread over seeds is the
spread of one satellite's hardware draw, not of the rendering.
"""
import json
import os

import numpy as np

from simcore.plots import plot_attitude_bars, plot_mekf

from simcore.studies.choices import GYROS
from simcore.studies.reproduce import CONFIGS, SPANS, ensure_run, run_options


def default_page(folder, span, thermal_compensation=False):
    """Return the default results-page folder of a study."""
    return os.path.join(folder, f"attitude_{span}" + ("_compensated" if thermal_compensation else ""))


def _task(path, gyro, seed, onboard, magnetometer, thermal_compensation=False):
    """One evaluation (runs in a Dask worker): the MEKF summary of one run file."""
    from simcore.pipeline.evaluate_attitude import run_mekf
    from simcore.pipeline.runfile import open_run
    return run_mekf(open_run(path), path, gyro=gyro, magnetometer=magnetometer, seed=seed,
                    onboard_albedo=onboard, thermal_compensation=thermal_compensation)["summary"]


def _task_file(cache, task):
    path, gyro, seed, onboard, magnetometer, comp = task
    name = (f"{os.path.splitext(os.path.basename(path))[0]}_{gyro}_{magnetometer}_seed{seed}"
            f"_{'onboard' if onboard else 'blind'}{'_comp' if comp else ''}.json")
    return os.path.join(cache, name)


def _run_tasks(tasks, cache, *, scheduler=None, workers=2, log=print):
    """Run the evaluations on Dask; each finished one is kept in ``cache`` (a study started again skips it)."""
    from simcore.pipeline.cluster import run_tasks
    os.makedirs(cache, exist_ok=True)
    todo = [t for t in tasks if not os.path.exists(_task_file(cache, t))]
    log(f"  {len(tasks) - len(todo)} of {len(tasks)} evaluations already done")
    finished = []

    def done(task, summary):
        with open(_task_file(cache, task), "w") as f:
            json.dump(summary, f)
        finished.append(task)
        if len(finished) % 10 == 0 or len(finished) == len(todo):
            log(f"  {len(finished)}/{len(todo)} evaluations done")
    if todo:
        run_tasks(_task, todo, scheduler=scheduler, workers=workers, on_done=done, what="evaluation")
    out = {}
    for t in tasks:
        with open(_task_file(cache, t)) as f:
            out[t] = json.load(f)
    return out


def attitude_study(folder="runs/thesis", *, span="orbits", configs=CONFIGS, gyros=GYROS, seeds=(0, 1, 2),
                   magnetometer="HMC5883L", page_folder=None, render=True, scheduler=None, workers=2,
                   thermal_compensation=False, log=print):
    """Evaluate every combination, write the results page; return the results dict."""
    from simcore.sensor.gyro import gyro_spec
    from simcore.sensor.magnetometer import magnetometer_spec
    from scenes.config import SatelliteConfig
    from simcore.pipeline.preflight import check_seeds
    if span not in SPANS:
        raise ValueError(f"unknown span {span!r}; choose one of {', '.join(SPANS)}")
    gyros = [gyro_spec(g).name for g in gyros]
    magnetometer = magnetometer_spec(magnetometer).name
    for c in configs:
        SatelliteConfig.load(c)
    check_seeds(seeds, "--seeds")                      # before anything is rendered
    page_folder = page_folder or default_page(folder, span, thermal_compensation)
    os.makedirs(folder, exist_ok=True)
    os.makedirs(page_folder, exist_ok=True)
    paths = {}
    for c in configs:
        opts = run_options(c, folder, span=span)
        if not os.path.exists(opts.output) and not render:
            log(f"skipping {c}: no run file {opts.output} (render it, or drop --no-render)")
            continue
        ensure_run(opts, log=log)
        paths[c] = opts.output
    if not paths:
        raise ValueError(f"no run files in {folder} for span {span!r}; run without --no-render")
    # Seed-major order: stopped early, a study has whole seeds done (and resumes where it stopped).
    tasks = [(paths[c], g, int(s), onboard, magnetometer, thermal_compensation) for s in seeds for c in paths
             for g in gyros for onboard in (True, False)]
    log(f"attitude study: {len(tasks)} MEKF evaluations ({len(paths)} configurations x {len(gyros)} gyros x "
        f"2 Sun-vector modes x {len(seeds)} seeds) on Dask")
    summaries = _run_tasks(tasks, os.path.join(page_folder, "evaluations"), scheduler=scheduler, workers=workers,
                           log=log)
    rows = []
    for (path, g, s, onboard, _, _), summ in summaries.items():
        a = summ["attitude_error_deg"]
        rows.append({"config": summ["configuration"], "gyro": g, "seed": s, "onboard_albedo": onboard,
                     "sunlit_mean": a["sunlit"]["mean"], "sunlit_p95": a["sunlit"]["p95"],
                     "eclipse_mean": a["eclipse"]["mean"], "eclipse_p95": a["eclipse"]["p95"],
                     "eclipse_max": a["eclipse"]["max"], "nees_in_bounds": summ["nees_in_bounds"],
                     "time_to_converge_s": summ["time_to_converge_s"]})
    rows.sort(key=lambda r: (list(paths).index(r["config"]), gyros.index(r["gyro"]), not r["onboard_albedo"],
                             r["seed"]))
    results = {"span": span, "start": SPANS[span][0], "duration_s": SPANS[span][1], "seeds": list(seeds),
               "gyros": gyros, "magnetometer": magnetometer, "configs": list(paths), "rows": rows,
               "thermal_compensation": bool(thermal_compensation)}
    with open(os.path.join(page_folder, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    _figures(results, page_folder, paths, log)
    write_page(results, page_folder)
    return results


def _agg(rows, key):
    v = np.array([r[key] for r in rows if r[key] is not None], dtype=float)
    return (float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else 0.0) if v.size else (float("nan"), 0.0)


def _select(rows, **kw):
    return [r for r in rows if all(r[k] == v for k, v in kw.items())]


def _figures(results, page_folder, paths, log):
    rows, gyros, configs = results["rows"], results["gyros"], results["configs"]
    for key, label in (("sunlit_p95", "sunlit 95th percentile"), ("eclipse_p95", "eclipse 95th percentile")):
        if not any(r[key] is not None and r[key] > 0 for r in rows):
            log(f"  no {label} values (no such epochs in this span): no figure {key}.png")
            continue
        cells = {(c, g, onboard): _agg(_select(rows, config=c, gyro=g, onboard_albedo=onboard), key)
                 for c in configs for g in gyros for onboard in (True, False)}
        plot_attitude_bars(cells, configs, gyros, f"attitude error, {label} [deg]",
                           os.path.join(page_folder, f"{key}.png"))
    # One time series: the best-ranked FOV-70 layout, flown gyro vs recommended, seed 0, on-board albedo.
    from simcore.pipeline.evaluate_attitude import run_mekf
    from simcore.pipeline.runfile import open_run
    cfg = "tilt20_fov70" if "tilt20_fov70" in paths else configs[0]
    for g in dict.fromkeys([gyros[0], "BMG160" if "BMG160" in gyros else gyros[-1], gyros[-1]]):
        res = run_mekf(open_run(paths[cfg]), paths[cfg], gyro=g, magnetometer=results["magnetometer"], seed=0,
                       thermal_compensation=results["thermal_compensation"])
        sub = os.path.join(page_folder, f"series_{cfg}_{g}")
        plot_mekf(res, sub, title=f"{cfg}, {g}:")
        log(f"  figures {sub}")


def _cell(rows, key):
    m, s = _agg(rows, key)
    return "-" if not np.isfinite(m) else (f"{m:.2f} +- {s:.2f}" if s > 0 else f"{m:.2f}")


def write_page(results, page_folder):
    """Write README.md of the attitude study from its results dict."""
    rows, gyros, configs = results["rows"], results["gyros"], results["configs"]
    start, dur = results["start"], results["duration_s"]
    lines = [
        "# Attitude error per configuration and gyro (sunsim attitude-study)",
        "",
        f"Rendered irradiance ({results['span']}: {dur:g} s from {start}, 1 s steps, ESTCube-1, 1.9 deg/s tumble, "
        "TOMS 2005), sensor chain with shot and Johnson noise, the gyro of each column, an "
        f"{results['magnetometer']} magnetometer on the IGRF field, an MEKF (attitude + gyro bias). Sun vector: "
        "model-albedo estimator with the albedo predicted on board from the filter's own attitude "
        "(CERES 2018 all-sky map on board: not the rendering's map), or Sun-Albedo-Sun without a prediction. "
        f"Mean +- standard deviation over seeds {results['seeds']} (gyro/magnetometer error draws and noise), "
        "each seed one Dask task. Filter started by TRIAD at the first sunlit epoch; eclipse = not in full Sun "
        "(magnetometer + gyro only). Gyro bias temperature effect: "
        + ("compensated on board to 22 % (simcore.sensor.gyro.THERMAL_COMPENSATION_RESIDUAL)."
           if results.get("thermal_compensation") else "uncompensated (the data sheets' coefficients)."),
        "",
    ]
    for onboard in (True, False):
        lines += [f"## {'With' if onboard else 'Without'} the on-board albedo prediction", "",
                  "Sunlit mean / 95th percentile, eclipse 95th percentile of the attitude error [deg].", "",
                  "| configuration | " + " | ".join(gyros) + " |", "|---" * (len(gyros) + 1) + "|"]
        for c in configs:
            cells = []
            for g in gyros:
                sel = _select(rows, config=c, gyro=g, onboard_albedo=onboard)
                cells.append(f"{_cell(sel, 'sunlit_mean')} / {_cell(sel, 'sunlit_p95')} / {_cell(sel, 'eclipse_p95')}")
            lines.append(f"| {c} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Filter consistency", "",
              "Share of epochs with the attitude NEES inside the two-sided 95 % chi-square bounds (3 dof), "
              "with the on-board albedo prediction:", "",
              "| configuration | " + " | ".join(gyros) + " |", "|---" * (len(gyros) + 1) + "|"]
    for c in configs:
        lines.append(f"| {c} | " + " | ".join(_cell(_select(rows, config=c, gyro=g, onboard_albedo=True),
                                                      "nees_in_bounds") for g in gyros) + " |")
    lines += ["", "## Figures", ""]
    for key in ("sunlit_p95", "eclipse_p95"):
        if os.path.exists(os.path.join(page_folder, f"{key}.png")):
            lines += [f"![{key}]({key}.png)", ""]
    for d in sorted(os.listdir(page_folder)):
        if d.startswith("series_") and os.path.isdir(os.path.join(page_folder, d)):
            lines += [f"![{d}]({d}/attitude_error.png)", ""]
    discussion = os.path.join(page_folder, "discussion.md")   # hand-written, kept across regenerations
    if os.path.exists(discussion):
        with open(discussion) as f:
            lines += ["", f.read()]
    with open(os.path.join(page_folder, "README.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
