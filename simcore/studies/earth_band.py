"""The thesis' open question (sec. 5.2) answered: Sun-vector error with a band-aware, glinting, cloudy Earth.

The thesis rendered its Earth with TOMS, a UV reflectivity map, and said so (sec. 5.2): "Earth
reflectivity is much higher over Oceans in the UV spectrum than it is in the spectral ranges where
suggested photodiodes measure light", and its annual-mean map has no clouds. ``sunsim earth-study``
renders, for the baseline cube (``tilt0_fov90``) and ``tilt20_fov70``, three truths through the normal
run machinery (each run checked against the analytic model):

- **A** ``--map band``: the CERES 2018 all-sky map seen in the BPW34FS band (:mod:`simcore.radiometry.band`),
  the band all-sky climatology, no glint, no weather;
- **B** A + ``--glint WIND``: Cox-Munk sun glint on the sea;
- **C** B + ``--clouds SEED``: one realisation of cloud weather whose mean over seeds is A's map, per seed.

Each truth feeds the noise-free sensor chain and the estimators of
:func:`simcore.studies.cross_map.evaluate_cross_map`: those that need no albedo model (WLS, Sun-Albedo-Sun,
smart selection; on-board map ``none``) and the on-board albedo prediction (``model_albedo`` with and
without a fitted gain) made with each of :data:`ONBOARD_MAPS` from a 1 s stale attitude. The decomposition
(:func:`effect`): the map's band error (C with TOMS or CERES on board against C with the band map on
board), glint's own effect (B against A) and the weather's own effect (C against B), both with the band
map on board; and the glint on the diode nearest nadir (:func:`glint_on_nadir_diode`). Settings follow
``sunsim reproduce`` (:func:`simcore.studies.reproduce.run_options`: the thesis' constant Sun, 1 s steps,
tumble 1.9 deg/s, diode 0 dead in the 14-diode layout). The page (:mod:`simcore.studies.earth_band_page`)
is rendered from the results dict alone, also written as ``results.json``.
"""
import dataclasses
import json
import math
import os

import numpy as np
from matplotlib.figure import Figure

from estimators.metrics import hanning_mean_std
from simcore.errors import InvalidInputError
from simcore.pipeline.run import PreparedRun, execute
from simcore.pipeline.runfile import open_run
from simcore.plots import save_figure
from simcore.radiometry import band
from simcore.radiometry.glint import check_wind
from simcore.studies.cross_map import evaluate_cross_map
from simcore.studies.earth_band_page import write_page
from simcore.studies.reproduce import (DAY_START, DIODE, SPANS, check_passed, read_check, refuse_failed,
                                       run_options as thesis_run_options)

CONFIGS = ("tilt0_fov90", "tilt20_fov70")
ONBOARD_MAPS = ("toms2005", "ceres2018-all", "band")
TRUTH_MAP = "band"
NO_MODEL = "none"                                  # the on-board map column of the estimators that need none
MODEL_ESTIMATORS = ("model_albedo", "model_albedo+gain")
DEFAULT_WIND_M_S = 7.0
DEFAULT_CLOUD_SEEDS = (1,)
HANNING_WINDOW = 181                               # samples, as the thesis' figures and the reproduction page
TRUTHS = {"A": "band all-sky climatology (no glint, no weather)", "B": "A + sun glint",
          "C": "B + cloud weather"}


def check_inputs(span, wind_m_s, cloud_seeds):
    """Raise a one-line InvalidInputError unless the span, wind and cloud seeds can make the study."""
    from simcore.environment.clouds import check_cloud_options
    if span not in SPANS:
        raise InvalidInputError(f"--span must be one of {', '.join(SPANS)}, got {span!r}")
    check_wind(wind_m_s, "--wind")
    seeds = list(cloud_seeds)
    if not seeds:
        raise InvalidInputError("--cloud-seeds needs at least one seed")
    if len(set(seeds)) != len(seeds):
        raise InvalidInputError(f"--cloud-seeds repeats a seed ({' '.join(map(str, seeds))}); give each once")
    for s in seeds:
        check_cloud_options(TRUTH_MAP, s, seed_option="--cloud-seeds")


def truth_keys(cloud_seeds):
    """Return the truth labels: 'A', 'B' and 'C<seed>' per cloud seed."""
    return ["A", "B"] + [f"C{s}" for s in cloud_seeds]


def run_options(config, folder, truth, *, span="day", wind_m_s=DEFAULT_WIND_M_S):
    """Return the RunOptions of truth ``truth`` ('A', 'B' or 'C<seed>') of ``config`` (file name encodes the
    settings; truth A's is the name ``sunsim reproduce`` would give a band run)."""
    kw = {}
    suffix = ""
    if truth != "A":
        kw["glint"] = float(wind_m_s)
        suffix += f"_glint{float(wind_m_s):g}"
    if truth.startswith("C"):
        kw["clouds"] = int(truth[1:])
        suffix += f"_clouds{int(truth[1:])}"
    opts = thesis_run_options(config, folder, span=span, reflectivity=TRUTH_MAP, **kw)
    return dataclasses.replace(opts, output=opts.output[:-len(".nc")] + suffix + ".nc")


def planned_runs(folder, *, span, wind_m_s, cloud_seeds):
    """Return [(label 'CONFIG:TRUTH', RunOptions)] of every run of the study."""
    return [(f"{c}:{t}", run_options(c, folder, t, span=span, wind_m_s=wind_m_s))
            for c in CONFIGS for t in truth_keys(cloud_seeds)]


def refuse_existing_failed(folder, *, span, wind_m_s, cloud_seeds):
    """Raise :class:`simcore.studies.reproduce.FailedCheckError` if a run file the study needs is already there
    with a failed check (called before anything is rendered or written)."""
    runs = planned_runs(folder, span=span, wind_m_s=wind_m_s, cloud_seeds=cloud_seeds)
    refuse_failed([(label, o.output) for label, o in runs
                   if os.path.exists(o.output) and not check_passed(read_check(o.output))], folder)


# ---------------------------------------------------------------------------------------------- statistics
def error_stats(err_deg, sunlit):
    """Return {n_sunlit, n_invalid, mean_deg, rms_deg, p95_deg, max_deg} of the angle errors ``err_deg`` (N,)
    over the ``sunlit`` (N,) epochs that have an estimate (NaN: none)."""
    err = np.asarray(err_deg, dtype=float)
    sunlit = np.asarray(sunlit, dtype=bool)
    v = err[sunlit & np.isfinite(err)]
    out = {"n_sunlit": int(sunlit.sum()), "n_invalid": int(np.sum(sunlit & ~np.isfinite(err)))}
    if v.size:
        out.update(mean_deg=float(v.mean()), rms_deg=float(np.sqrt(np.mean(v ** 2))),
                   p95_deg=float(np.percentile(v, 95.0)), max_deg=float(v.max()))
    else:
        out.update(mean_deg=float("nan"), rms_deg=float("nan"), p95_deg=float("nan"), max_deg=float("nan"))
    return out


def effect(err_with, err_without, s_with, s_without, sunlit):
    """Return one effect of the decomposition: the Sun-vector error with it and without it.

    ``err_*`` (N,) angle errors (deg), ``s_*`` (N, 3) the unit Sun estimates (NaN where invalid), ``sunlit``
    (N,) bool. The RMS errors are over the sunlit epochs where both estimates exist (the same epochs for
    both); ``rms_change_deg`` = with - without; ``quadrature_deg`` = sqrt(with^2 - without^2) where the
    effect adds error (0 where it removes some): what an independent error of that RMS would add;
    ``own_rms_deg`` / ``own_max_deg``: the RMS / largest angle between the two estimates at the same epoch,
    the effect itself whatever the other errors do."""
    e1, e0 = np.asarray(err_with, float), np.asarray(err_without, float)
    s1, s0 = np.asarray(s_with, float), np.asarray(s_without, float)
    use = np.asarray(sunlit, bool) & np.isfinite(e1) & np.isfinite(e0) & np.all(np.isfinite(s1), 1) \
        & np.all(np.isfinite(s0), 1)
    if not use.any():
        nan = float("nan")
        return {"n": 0, "rms_with_deg": nan, "rms_without_deg": nan, "rms_change_deg": nan, "quadrature_deg": nan,
                "own_rms_deg": nan, "own_max_deg": nan}
    r1, r0 = float(np.sqrt(np.mean(e1[use] ** 2))), float(np.sqrt(np.mean(e0[use] ** 2)))
    cos = np.clip(np.einsum("ij,ij->i", s1[use], s0[use]), -1.0, 1.0)
    own = np.degrees(np.arccos(cos))
    return {"n": int(use.sum()), "rms_with_deg": r1, "rms_without_deg": r0, "rms_change_deg": r1 - r0,
            "quadrature_deg": float(np.sqrt(max(r1 ** 2 - r0 ** 2, 0.0))),
            "own_rms_deg": float(np.sqrt(np.mean(own ** 2))), "own_max_deg": float(own.max())}


def decomposition(errors, estimates, sunlit, cloud_seeds):
    """Return {effect name: {estimator: :func:`effect`}} from per-row errors and estimates keyed
    (truth, on-board map, estimator) as :func:`evaluate`'s (model-free estimators under :data:`NO_MODEL`).

    Effects: ``map_<name>`` (C x <name> on board against C x band on board, model estimators), ``glint``
    (B against A) and ``clouds`` (C against B), the band map on board for the model estimators. The C
    truths of several seeds are pooled (their epochs concatenated, B repeated beside each)."""
    cs = [f"C{s}" for s in cloud_seeds]
    estimators = sorted({k[2] for k in errors})

    def pooled(truths, onboard, est):
        e = np.concatenate([errors[(t, onboard, est)] for t in truths])
        s = np.concatenate([estimates[(t, onboard, est)] for t in truths])
        return e, s
    lit = np.concatenate([sunlit] * len(cs))
    out = {}
    for m in ONBOARD_MAPS:
        if m == TRUTH_MAP:
            continue
        out[f"map_{m}"] = {}
        for est in MODEL_ESTIMATORS:
            if (cs[0], m, est) in errors:
                e1, s1 = pooled(cs, m, est)
                e0, s0 = pooled(cs, TRUTH_MAP, est)
                out[f"map_{m}"][est] = effect(e1, e0, s1, s0, lit)
    out["glint"], out["clouds"] = {}, {}
    for est in estimators:
        onboard = TRUTH_MAP if est in MODEL_ESTIMATORS else NO_MODEL
        if ("A", onboard, est) not in errors:
            continue
        out["glint"][est] = effect(errors[("B", onboard, est)], errors[("A", onboard, est)],
                                   estimates[("B", onboard, est)], estimates[("A", onboard, est)], sunlit)
        e_c, s_c = pooled(cs, onboard, est)
        e_b, s_b = pooled(["B"] * len(cs), onboard, est)
        out["clouds"][est] = effect(e_c, e_b, s_c, s_b, lit)
    return out


def glint_on_nadir_diode(glint_w_m2, normals_body, nadir_body, live, sunlit, e_sun_w_m2):
    """Return (k (N,) int, pct (N,)): per epoch the live diode whose normal is nearest the nadir direction
    ``nadir_body`` (N, 3, unit, body axes) and the glint irradiance ``glint_w_m2`` (N, K) on it in % of
    ``e_sun_w_m2`` (scalar or (N,)); NaN outside the ``sunlit`` (N,) epochs."""
    n = np.asarray(normals_body, float)
    cos = np.asarray(nadir_body, float) @ n.T                          # (N, K)
    cos = np.where(np.asarray(live, bool)[None, :], cos, -np.inf)
    k = np.argmax(cos, axis=1)
    g = np.take_along_axis(np.asarray(glint_w_m2, float), k[:, None], axis=1)[:, 0]
    pct = 100.0 * g / np.asarray(e_sun_w_m2, float)
    return k, np.where(np.asarray(sunlit, bool), pct, np.nan)


# ---------------------------------------------------------------------------------------------- evaluation
def _t_since_day_start(ds):
    return ds["t_s"].values + (ds["time"].values[0] - np.datetime64(DAY_START)) / np.timedelta64(1, "s")


def evaluate(config, runs, geometry, dead, cloud_seeds):
    """Return (table, errors, estimates, sunlit): ``table[truth][onboard][estimator]`` = :func:`error_stats`
    for the truths ``runs`` {truth: Dataset} of ``config`` on ``geometry``, and the per-row arrays keyed
    (truth, on-board map, estimator); the model-free estimators once, under :data:`NO_MODEL`."""
    truth = {t: ds["irradiance"].sum("component").values for t, ds in runs.items()}
    _, raw = evaluate_cross_map(config, truth_irradiance=truth, geometry=geometry, onboard_maps=ONBOARD_MAPS,
                                same_map=True, dead=list(dead), return_errors=True)
    sunlit = raw["sunlit"]
    errors, estimates, table = {}, {}, {}
    for key, err in raw.items():
        if not isinstance(key, tuple):
            continue
        t, m, est = key
        if est not in MODEL_ESTIMATORS:
            if m != ONBOARD_MAPS[0]:
                continue                     # the same numbers for every on-board map: listed once
            m = NO_MODEL
        errors[(t, m, est)] = err
        estimates[(t, m, est)] = raw["estimates"][key]
        table.setdefault(t, {}).setdefault(m, {})[est] = error_stats(err, sunlit)
    return table, errors, estimates, sunlit


def glint_summary(ds_a, ds_b, geometry, t_s):
    """Return the glint on the diode nearest nadir (B - A analytic albedo, noise-free; the rendered B - A and
    its standard error at the largest), in % of the run's E_sun, over the sunlit epochs."""
    r = geometry.r_sat_ecef_m
    nadir = -np.einsum("nji,nj->ni", geometry.R_ecef_from_body, r / np.linalg.norm(r, axis=1)[:, None])
    live = ~ds_b["dead"].values.astype(bool)
    sunlit = ds_b["illumination"].values > 0
    e_sun = float(ds_b.attrs["e_sun_w_m2"]) * ds_b["sun_scale"].values
    glint = ds_b["analytic"].values[..., 1] - ds_a["analytic"].values[..., 1]
    k, pct = glint_on_nadir_diode(glint, ds_b["normal_body"].values, nadir, live, sunlit, e_sun)
    if not np.isfinite(pct).any():
        return {}
    i = int(np.nanargmax(pct))
    rendered = ds_b["irradiance"].values[i, k[i], 1] - ds_a["irradiance"].values[i, k[i], 1]
    se = math.hypot(float(ds_b["irradiance_se"].values[i, k[i], 1]), float(ds_a["irradiance_se"].values[i, k[i], 1]))
    x, y, z = r[i]
    return {"max_pct": float(pct[i]), "mean_pct": float(np.nanmean(pct)),
            "p95_pct": float(np.nanpercentile(pct, 95.0)), "t_s": float(t_s[i]), "diode": int(k[i]),
            "lat_deg": float(np.degrees(np.arctan2(z, np.hypot(x, y)))), "lon_deg": float(np.degrees(np.arctan2(y, x))),
            "rendered_pct": float(100.0 * rendered / e_sun[i]), "rendered_se_pct": float(100.0 * se / e_sun[i])}


# ---------------------------------------------------------------------------------------------- figures
def _figure_errors(t_s, errors, sunlit, truth, config, path, estimator="model_albedo+gain"):
    """Hanning-mean Sun-vector error against time, one line per on-board map (and WLS, which needs none)."""
    fig = Figure(figsize=(11, 5))
    ax = fig.add_subplot()
    lines = [(f"on-board {m}, {estimator}", (truth, m, estimator)) for m in ONBOARD_MAPS]
    lines.append(("WLS (no model)", (truth, NO_MODEL, "wls")))
    for label, key in lines:
        if key in errors:
            hm, _ = hanning_mean_std(np.where(sunlit, errors[key], np.nan), window=HANNING_WINDOW)
            ax.plot(t_s / 3600.0, np.where(sunlit, hm, np.nan), lw=1.2, label=label)
    ax.set_xlabel("time since 2016-07-02T00:00Z [h]")
    ax.set_ylabel(f"Hanning mean ({HANNING_WINDOW} s) of the angle error [deg]")
    ax.set_title(f"{config}: truth {truth} ({TRUTHS[truth[0]]})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def _figure_bars(results, path, estimator="model_albedo+gain"):
    """RMS error per on-board map (truth C pooled) and the own RMS effect of each change, per configuration."""
    fig = Figure(figsize=(11, 5))
    ax = fig.add_subplot()
    labels = ([f"truth C,\non board {m}" for m in ONBOARD_MAPS]
              + [f"{m}\ninstead of band\n(own)" for m in ONBOARD_MAPS if m != TRUTH_MAP]
              + ["glint\n(own)", "cloud weather\n(own)"])
    width = 0.8 / max(len(results["configs"]), 1)
    for j, (cfg, r) in enumerate(results["configs"].items()):
        eff = r["effects"]
        vals = [eff[f"map_{m}"][estimator]["rms_with_deg"] for m in ONBOARD_MAPS if m != TRUTH_MAP]
        vals.append(eff[f"map_{ONBOARD_MAPS[0]}"][estimator]["rms_without_deg"])
        vals += [eff[f"map_{m}"][estimator]["own_rms_deg"] for m in ONBOARD_MAPS if m != TRUTH_MAP]
        vals += [eff["glint"][estimator]["own_rms_deg"], eff["clouds"][estimator]["own_rms_deg"]]
        ax.bar(np.arange(len(labels)) + (j - (len(results["configs"]) - 1) / 2) * width, vals, width, label=cfg)
    ax.set_xticks(np.arange(len(labels)), labels, fontsize=8)
    ax.set_ylabel(f"RMS [deg], {estimator}")
    ax.set_title("Sun-vector error per on-board map (truth C) and per effect")
    ax.grid(alpha=0.3, axis="y")
    ax.legend()
    fig.tight_layout()
    save_figure(fig, path)


# ---------------------------------------------------------------------------------------------- the study
def earth_study(folder, *, span="day", page_folder=None, wind_m_s=DEFAULT_WIND_M_S, cloud_seeds=DEFAULT_CLOUD_SEEDS,
                allow_failed_checks=False, log=print):
    """Render what is missing, evaluate every truth x on-board map x estimator and write the page; return
    the results dict.

    Bad input raises InvalidInputError before anything is written. A run whose analytic check failed
    stops the study with :class:`simcore.studies.reproduce.FailedCheckError` (existing files before anything
    is rendered, new ones before the page is written) unless ``allow_failed_checks``: then the page marks
    every number derived from it."""
    check_inputs(span, wind_m_s, cloud_seeds)
    cloud_seeds = [int(s) for s in cloud_seeds]
    page_folder = page_folder or os.path.join(folder, "earth_band")
    runs = planned_runs(folder, span=span, wind_m_s=wind_m_s, cloud_seeds=cloud_seeds)
    if not allow_failed_checks:
        refuse_existing_failed(folder, span=span, wind_m_s=wind_m_s, cloud_seeds=cloud_seeds)
    os.makedirs(folder, exist_ok=True)
    for _, o in runs:
        if not os.path.exists(o.output):
            log(f"rendering {os.path.basename(o.output)} ...")
            execute(o, log=log)
    checks = {label: read_check(o.output) for label, o in runs}
    if not allow_failed_checks:
        refuse_failed([(label, o.output) for label, o in runs if not check_passed(checks[label])], folder)
    os.makedirs(page_folder, exist_ok=True)

    o0 = runs[0][1]
    results = {"span": span, "start": SPANS[span][0], "duration_s": SPANS[span][1],
               "settings": {"step_s": o0.step_s, "spin_rate_deg_s": o0.spin_rate_deg_s, "diode": DIODE,
                            "e_sun_w_m2": o0.e_sun_w_m2, "wind_m_s": float(wind_m_s), "cloud_seeds": cloud_seeds,
                            "truth_map": TRUTH_MAP, "onboard_maps": list(ONBOARD_MAPS), "lag_steps": 1,
                            "hanning_window": HANNING_WINDOW},
               "truths": dict(TRUTHS), "allow_failed_checks": bool(allow_failed_checks),
               "runs": {label: {"file": os.path.basename(o.output), "check": checks[label],
                                "check_pass": check_passed(checks[label])} for label, o in runs},
               "headline": band.headline(DIODE), "configs": {}}
    for cfg in CONFIGS:
        opts = {t: run_options(cfg, folder, t, span=span, wind_m_s=wind_m_s) for t in truth_keys(cloud_seeds)}
        dss = {t: open_run(o.output) for t, o in opts.items()}
        log(f"evaluating {cfg} ...")
        geometry = PreparedRun(dataclasses.replace(opts["A"], output=None)).geometry
        t_s = _t_since_day_start(dss["A"])
        table, errors, estimates, sunlit = evaluate(cfg, dss, geometry, opts["A"].dead, cloud_seeds)
        results["configs"][cfg] = {"dead": [int(i) for i in opts["A"].dead], "period_s": float(dss["A"].attrs["period_s"]),
                                   "errors": table,
                                   "effects": decomposition(errors, estimates, sunlit, cloud_seeds),
                                   "glint_nadir": glint_summary(dss["A"], dss["B"], geometry, t_s)}
        _figure_errors(t_s, errors, sunlit, f"C{cloud_seeds[0]}", cfg, os.path.join(page_folder, f"errors_{cfg}.png"))
    _figure_bars(results, os.path.join(page_folder, "rms_by_map_and_effect.png"))
    with open(os.path.join(page_folder, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    write_page(results, page_folder)
    return results
