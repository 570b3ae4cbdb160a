"""The OPS-SAT flight comparison's results page (issue 29 items 5 and 6): ``sunsim flight-check opssat --study DIR``
renders the models into ``DIR/results.json`` (+ ``DIR/samples.npz``, the per-sample arrays of the figures);
``sunsim flight-check opssat --page DIR`` writes ``DIR/README.md`` and its figures from those two files alone.

Models compared on the same samples (:func:`simcore.studies.flight.compare`'s definitions): the direct Sun only
(rendered, the scene's own shadows), the best uniform albedo (plain cosines; fitted), + the Earth's albedo on TOMS
2005, CERES 2018 all-sky, the band map and CERES under cloud weather (a few seeds), each without and with the
spacecraft's reflections (the rendered ``reflected`` component of the arrays' solar cells).

Uncertainty (item 6), on the analytic model (plain cosine diodes, CERES all-sky: no render, the same geometry): the
attitude perturbed by random rotations of a stated size, the orbit shifted along track by the TLE's plausible age
error, and the diode's response (a bare cosine against one under a cover glass). Each is stated as the change of
the median |residual| it makes.

Every number on the page is a value of ``results.json`` (``render_page(results, marked=True)`` wraps each in
``⟦...⟧``; tests/studies/test_flight.py proves no other digit is on the page but the fixed words listed there).
"""
import datetime as _dt
import json
import os
from pathlib import Path
import zipfile

import numpy as np

from simcore.errors import InputNotFoundError, InvalidInputError

CLOUD_SEEDS = (1, 2, 3)
MAPS = (("toms2005", "TOMS 2005", None), ("ceres2018-all", "CERES 2018 all-sky", None), ("band:BPW34FS", "band map (a BPW34FS band assumed)", None))
ATTITUDE_SIGMAS_DEG = (1.0, 3.0)         # per-axis rms of the random rotation
ATTITUDE_SEEDS = (0, 1, 2)
# The along-track error of a TLE 9-16 days old: SGP4 position errors grow by ~1-3 km per day for a LEO TLE
# (assumed, typical of published SGP4 accuracy studies); 16 days x 2.5 km/day = 40 km = ~5.3 s at 7.6 km/s.
TLE_SHIFT_S = 5.3
COVER_GLASS_INDEX = 1.5
WELL_FOV_DEG = 70.0          # an unknown field of view: the diode in a well fully lit to 70 deg (eq. 4.15 design)
PD6_RANGE = (0.1, 0.5)
FIGURES = ("time_series.png", "residual_vs_cos.png", "residual_vs_earth_view.png")


# ---- the study --------------------------------------------------------------------------------------------------

def _summary(measured, predicted, cos, use):
    """Return {median_abs_residual, sun_behind_median_residual, bins [...]} of one model on one diode."""
    from simcore.studies.flight import BIN_EDGES, SUN_BEHIND_COS
    r = (measured - predicted)[use]
    c = cos[use]
    bins = []
    for i, (lo, hi) in enumerate(zip(BIN_EDGES[:-1], BIN_EDGES[1:])):
        inb = (c >= lo) & ((c < hi) if i < len(BIN_EDGES) - 2 else (c <= hi))
        bins.append(round(float(np.median(r[inb])), 5) if inb.any() else None)
    behind = c < SUN_BEHIND_COS
    mid = (c >= PD6_RANGE[0]) & (c < PD6_RANGE[1])
    return {"median_abs_residual": round(float(np.median(np.abs(r))), 5),
            "sun_behind_median_residual": round(float(np.median(r[behind])), 5) if behind.any() else None,
            "sun_behind_median_abs_residual": round(float(np.median(np.abs(r[behind]))), 5) if behind.any() else None,
            "mid_median_residual": round(float(np.median(r[mid])), 5) if mid.any() else None,
            "bins": bins}


def _shown(path):
    """Return ``path`` relative to the repository where it lies inside it (the page names no machine's folders)."""
    from simcore.studies.flight import REPO
    p = os.path.abspath(str(path))
    return os.path.relpath(p, REPO) if p.startswith(str(REPO) + os.sep) else str(path)


def run_study(folder, sat, pd, attitude, tle, scene, *, runs="runs/flight-check", log=None):
    """Render every model on the telemetry, compute the uncertainty estimates, write ``folder/results.json`` and
    ``folder/samples.npz``; return the results file's path."""
    from simcore.studies import flight as F
    log = log or (lambda m: None)
    os.makedirs(folder, exist_ok=True)
    tel = F.load_telemetry(pd, attitude)
    names = tel.names
    models, arrays, checks = {}, {}, {}
    default = None
    variants = [(m, label, None) for m, label, _ in MAPS] + \
               [("ceres2018-all", f"CERES all-sky, cloud weather seed {s}", s) for s in CLOUD_SEEDS]
    for key, label, clouds in variants:
        log(f"flight-check study: rendering {label}")
        pred = F.predict(tel, scene, tle, key, clouds=clouds, folder=runs, log=log)
        tag = key if clouds is None else f"{key}+clouds{clouds}"
        checks[tag] = {"pass": bool(pred.check.get("pass", False)), "run": _shown(pred.run_path)}
        sunlit = pred.illumination >= 1.0
        if default is None or key == F.DEFAULT_MAP and clouds is None:
            default = pred
        for k, name in enumerate(names):
            m = tel.readings[name]
            use = sunlit & np.isfinite(m)
            cos = pred.cos_incidence[:, k]
            models.setdefault(name, {})
            if "direct" not in models[name]:
                models[name]["direct"] = {"label": "direct Sun only", **_summary(m, pred.direct[:, k], cos, use)}
                a, _ = F.uniform_baseline(m[use], pred.cosine_direct[use, k], pred.uniform_unit[use, k])
                models[name]["uniform"] = {"label": "uniform albedo (plain cosine, fitted)", "albedo": a,
                                           **_summary(m, pred.cosine_direct[:, k] + a * pred.uniform_unit[:, k],
                                                      cos, use)}
                models[name]["n"] = int(use.sum())
            models[name][tag] = {"label": f"+ albedo, {label}",
                                 **_summary(m, pred.direct[:, k] + pred.albedo[:, k], cos, use)}
            models[name][tag + "+reflections"] = {"label": f"+ albedo, {label}, + reflections",
                                                  **_summary(m, pred.total[:, k], cos, use),
                                                  "reflected_max": round(float(np.max(pred.reflected[use, k])), 6)}
            arrays[f"{name}/{tag}"] = pred.total[:, k]
    pred = default
    uni = {name: models[name]["uniform"]["albedo"] for name in names}
    arrays.update({k: v for k, v in F.sample_arrays(tel, pred, uni, "ceres2018-all").items()
                   if not k.endswith("/ceres2018-all")})
    best = {name: min((t for t in models[name] if t not in ("n", "direct", "uniform")),
                      key=lambda t: models[name][t]["median_abs_residual"]) for name in names}
    results = {
        "title": "OPS-SAT photodiodes: sunsim's prediction against flight telemetry",
        "created_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "inputs": {k: _shown(v) for k, v in (("pd", pd), ("attitude", attitude), ("tle", tle), ("scene", scene))},
        "samples": F.compare(tel, pred)["samples"],
        "normals": {name: [round(float(x), 6) for x in pred.normals[k]] for k, name in enumerate(names)},
        "bin_edges": list(F.BIN_EDGES),
        "models": models, "best": best, "checks": checks,
        "uncertainty": uncertainty(tel, tle, pred, names),
        "pd6": pd6_evidence(tel, pred, names),
        "commands": {"study": f"sunsim flight-check {sat.name} --study {folder}",
                     "page": f"sunsim flight-check {sat.name} --page {folder}",
                     "default": f"sunsim flight-check {sat.name} --json"},
    }
    path = Path(folder) / "results.json"
    path.write_text(json.dumps(results, indent=1, sort_keys=False) + "\n")
    np.savez_compressed(Path(folder) / "samples.npz", **arrays)
    return str(path)


def _analytic(tel, tle, normals, *, attitude=None, shift_s=0.0, reflectivity="ceres2018-all", response=None):
    """Return (N, K) predicted readings of plain cosine diodes + the analytic albedo on ``reflectivity``, and
    (N,) the illumination: the model the uncertainty estimates perturb (no render)."""
    from simcore.environment.geometry import compute_geometry
    from simcore.environment.orbit import Orbit
    from simcore.radiometry.band import resolve_map
    from simcore.studies.flight import plain_cosine
    att = tel.history.attitude_at(tel.epochs) if attitude is None else attitude
    g = compute_geometry(Orbit.from_file(str(tle)), tel.epochs + shift_s if shift_s else tel.epochs, att)
    direct, alb = plain_cosine(g, normals, resolve_map(reflectivity), response)
    return direct, alb, np.nan_to_num(g.illumination), g.sun_dir_body


def _perturbed(att, sigma_deg, seed):
    """Return ``att`` turned by a random rotation per epoch: rotation vector ~ N(0, sigma^2) per body axis."""
    from simcore.environment.attitude import Attitude, quat_multiply
    rng = np.random.default_rng(seed)
    v = rng.normal(0.0, np.radians(sigma_deg), (len(att.q_gcrs_from_body), 3))
    ang = np.linalg.norm(v, axis=1)
    dq = np.concatenate([np.cos(ang / 2)[:, None], np.sin(ang / 2)[:, None] * v / ang[:, None]], axis=1)
    return Attitude(quat_multiply(att.q_gcrs_from_body, dq))


def uncertainty(tel, tle, pred, names):
    """Return what the attitude error, the TLE's age and the diode's response can do to the median |residual|
    (the analytic model, plain cosines on CERES all-sky; module docstring)."""
    from simcore.shapes.window import Window
    base_d, base_a, lit, sun_body = _analytic(tel, tle, pred.normals)
    use0 = lit >= 1.0

    def med(predicted, k):
        m = tel.readings[names[k]]
        ok = use0 & np.isfinite(m)
        return float(np.median(np.abs(m[ok] - predicted[ok])))

    out = {"model": "plain cosine diodes + analytic albedo on CERES 2018 all-sky", "diodes": {}}
    att = tel.history.attitude_at(tel.epochs)
    pert = {s: [_analytic(tel, tle, pred.normals, attitude=_perturbed(att, s, seed)) for seed in ATTITUDE_SEEDS]
            for s in ATTITUDE_SIGMAS_DEG}
    shifted = [_analytic(tel, tle, pred.normals, shift_s=d) for d in (-TLE_SHIFT_S, TLE_SHIFT_S)]
    glass = Window(COVER_GLASS_INDEX, 1e-3, 0.0, (0.01, 0.01))
    from simcore.shapes.aperture import WellAperture
    well = _analytic(tel, tle, pred.normals, response=WellAperture.design(WELL_FOV_DEG))
    for k, name in enumerate(names):
        base = med(base_d[:, k] + base_a[:, k], k)
        d = {"median_abs_residual": round(base, 5)}
        for s, runs in pert.items():
            d[f"attitude_{s:g}deg"] = round(float(np.mean([med(r[0][:, k] + r[1][:, k], k) for r in runs])) - base, 5)
        d["tle_age"] = round(max(abs(med(r[0][:, k] + r[1][:, k], k) - base) for r in shifted), 5)
        cos = np.clip(sun_body @ pred.normals[k], 1e-9, 1.0)
        ratio = glass.transmittance(cos) / glass.transmittance(1.0)
        d["cover_glass"] = round(med(base_d[:, k] * ratio + base_a[:, k], k) - base, 5)
        d["fov_well"] = round(med(well[0][:, k] + well[1][:, k], k) - base, 5)
        out["diodes"][name] = d
    out["attitude_sigmas_deg"] = list(ATTITUDE_SIGMAS_DEG)
    out["tle_shift_s"] = TLE_SHIFT_S
    out["cover_glass_index"] = COVER_GLASS_INDEX
    out["well_fov_deg"] = WELL_FOV_DEG
    return out


def pd6_evidence(tel, pred, names):
    """Return the evidence on each diode's reading below the cosine law at cos(incidence) 0.1-0.5: the median
    residual of the plain cosine, of the rendered direct Sun (the scene's shadows), of a cover-glass response, and
    split by the Sun's azimuth about the normal (a shadow falls from one side; a response is the same all round)."""
    from simcore.shapes.aperture import diode_frame
    from simcore.shapes.window import Window
    glass = Window(COVER_GLASS_INDEX, 1e-3, 0.0, (0.01, 0.01))
    sunlit = pred.illumination >= 1.0
    out = {}
    for k, name in enumerate(names):
        m = tel.readings[name]
        cos = pred.cos_incidence[:, k]
        mid = sunlit & np.isfinite(m) & (cos >= PD6_RANGE[0]) & (cos < PD6_RANGE[1])
        ratio = glass.transmittance(np.clip(cos, 1e-9, 1.0)) / glass.transmittance(1.0)
        d = {"n": int(mid.sum()),
             "plain_cosine": round(float(np.median((m - pred.cosine_direct[:, k])[mid])), 5),
             "rendered_direct": round(float(np.median((m - pred.direct[:, k])[mid])), 5),
             "rendered_total": round(float(np.median((m - pred.total[:, k])[mid])), 5),
             "cover_glass_total": round(float(np.median((m - pred.direct[:, k] * ratio - pred.albedo[:, k]
                                                         - pred.reflected[:, k])[mid])), 5)}
        f = diode_frame(pred.normals[k])
        az = np.degrees(np.arctan2(pred.sun_body @ f[1], pred.sun_body @ f[0])) % 360.0
        quads = []
        for lo in (0, 90, 180, 270):
            q = mid & (az >= lo) & (az < lo + 90)
            quads.append({"from_deg": lo, "n": int(q.sum()),
                          "median_residual": round(float(np.median((m - pred.total[:, k])[q])), 5) if q.any() else None})
        d["azimuth"] = quads
        out[name] = d
    return out


# ---- figures ----------------------------------------------------------------------------------------------------

def comparison_figures(arrays, names, folder, model_key="ceres2018-all"):
    """Write the comparison's figures into ``folder`` from per-sample arrays (``samples.npz``'s keys); return
    their file names."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from simcore.studies.flight import SUN_BEHIND_COS
    os.makedirs(folder, exist_ok=True)
    t = np.asarray(arrays["time"]).astype("datetime64[ms]")
    t_h = (t - t[0]).astype(float) / 3.6e6
    lit = np.asarray(arrays["illumination"]) >= 1.0
    # a few orbits: the first 5 h of data
    win = t_h <= t_h[0] + 5.0
    fig = Figure(figsize=(11, 3.2 * len(names)))
    FigureCanvasAgg(fig)
    for i, name in enumerate(names):
        ax = fig.add_subplot(len(names), 1, i + 1)
        ax.plot(t_h[win], arrays[f"{name}/measured"][win], ".", ms=2.5, color="k", label="measured sin(theta)")
        ax.plot(t_h[win], arrays[f"{name}/{model_key}"][win], ".", ms=2, color="#1f5fa8",
                label=f"predicted ({model_key} + reflections)")
        ax.plot(t_h[win], arrays[f"{name}/direct"][win], ".", ms=1.2, color="#e08a00", label="direct Sun only")
        ax.set_ylabel(f"{name} reading (full Sun)")
        ax.set_xlabel(f"hours since {str(t[0])[:19]} UTC (gaps: no telemetry)")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, FIGURES[0]), dpi=110)
    fig = Figure(figsize=(11, 4))
    FigureCanvasAgg(fig)
    for i, name in enumerate(names):
        ax = fig.add_subplot(1, len(names), i + 1)
        m = arrays[f"{name}/measured"]
        cos = arrays[f"{name}/cos"]
        use = lit & np.isfinite(m)
        for key, colour, label in (("direct", "#e08a00", "direct only"), ("uniform", "0.5", "uniform (fitted)"),
                                   (model_key, "#1f5fa8", model_key)):
            r = m - arrays[f"{name}/{key}"]
            ax.plot(cos[use], r[use], ".", ms=1, color=colour, alpha=0.25)
            edges = np.linspace(-1, 1, 41)
            mids, meds = [], []
            for lo, hi in zip(edges[:-1], edges[1:]):
                b = use & (cos >= lo) & (cos < hi)
                if b.sum() >= 5:
                    mids.append(0.5 * (lo + hi))
                    meds.append(np.median(r[b]))
            ax.plot(mids, meds, "-", color=colour, lw=2, label=f"{label} (binned median)")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylim(-0.15, 0.15)
        ax.set_xlabel("cos(incidence)")
        ax.set_ylabel(f"{name}: measured - predicted (full Sun)")
        ax.legend(fontsize=7, loc="lower left")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, FIGURES[1]), dpi=110)
    fig = Figure(figsize=(11, 4))
    FigureCanvasAgg(fig)
    for i, name in enumerate(names):
        ax = fig.add_subplot(1, len(names), i + 1)
        m = arrays[f"{name}/measured"]
        cos = arrays[f"{name}/cos"]
        view = arrays[f"{name}/earth_view"]
        use = lit & np.isfinite(m) & (cos < SUN_BEHIND_COS)
        ax.plot(view[use], m[use], ".", ms=2, color="k", alpha=0.4, label="measured (Sun behind)")
        ax.plot(view[use], arrays[f"{name}/{model_key}"][use], ".", ms=2, color="#1f5fa8", alpha=0.4,
                label=f"predicted ({model_key})")
        ax.set_xlabel("diode's view of the day-side Earth (albedo-1 irradiance, full Sun)")
        ax.set_ylabel(f"{name} reading, Sun behind (cos < {SUN_BEHIND_COS:g})")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, FIGURES[2]), dpi=110)
    return list(FIGURES)


# ---- the page ---------------------------------------------------------------------------------------------------

class _Values:
    """Formats values of the results dict by their dotted path; ``marked`` wraps each in ⟦...⟧ (the test's proof
    that every number on the page is one of ``results.json``'s)."""

    def __init__(self, results, marked=False):
        self.results, self.marked = results, marked

    def get(self, path):
        v = self.results
        for part in path.split("."):
            v = v[int(part)] if isinstance(v, list) else v[part]
        return v

    def __call__(self, path_or_value, fmt="{:.4f}"):
        v = self.get(path_or_value) if isinstance(path_or_value, str) else path_or_value
        text = "–" if v is None else (fmt.format(v) if not isinstance(v, str) else v)
        return f"⟦{text}⟧" if self.marked and v is not None else text


def _pct(a, b):
    """Return 100 (b - a) / b: how much lower a is than b, in % of b."""
    return 100.0 * (b - a) / b


def render_page(results, marked=False):
    """Return the page's Markdown text, every number a value of ``results`` (or derived from such values)."""
    V = _Values(results, marked)
    names = list(results["models"])
    lines = [f"# {results['title']}", "",
             "Issue 29 items 5 and 6. Generated from `results.json` (and the figures from `samples.npz`) by",
             f"`{results['commands']['page']}`; the results file by `{results['commands']['study']}`. "
             "Definitions as `sunsim flight-check` (simcore/studies/flight.py): residual = measured sin(theta) - "
             "predicted reading (total irradiance / full-Sun normal irradiance), on the fully sunlit samples with a "
             "trusted attitude; \"Sun behind\": cos(incidence) < -0.2; no model is fitted but the uniform baseline's "
             "one albedo per diode.", ""]
    s = results["samples"]
    lines += [f"Telemetry: {V('samples.telemetry', '{:d}')} readings, {V('samples.trusted_attitude', '{:d}')} with a "
              f"trusted attitude ({V('samples.dropped_untrusted_attitude', '{:d}')} dropped), "
              f"{V('samples.sunlit', '{:d}')} sunlit. Inputs: `{results['inputs']['pd']}`, "
              f"`{results['inputs']['attitude']}`, `{results['inputs']['tle']}`, scene `{results['inputs']['scene']}`.",
              ""]
    # verdict
    lines += ["## Verdict", ""]
    for name in names:
        m = results["models"][name]
        best = results["best"][name]
        b, d, u = (m[best]["median_abs_residual"], m["direct"]["median_abs_residual"],
                   m["uniform"]["median_abs_residual"])
        lines.append(f"- **{name}**: the flight data prefer *{m[best]['label']}* (median |residual| "
                     f"{V(f'models.{name}.{best}.median_abs_residual')}), {V(_pct(b, d), '{:.0f}')} % below the direct "
                     f"Sun alone ({V(f'models.{name}.direct.median_abs_residual')}) and {V(_pct(b, u), '{:.0f}')} % "
                     f"{'below' if b <= u else 'above'} the best uniform albedo "
                     f"({V(f'models.{name}.uniform.median_abs_residual')} at albedo "
                     f"{V(f'models.{name}.uniform.albedo', '{:g}')}, fitted on these data). With the Sun behind the "
                     f"diode the median residual goes from {V(f'models.{name}.direct.sun_behind_median_residual')} "
                     f"(direct only: the albedo the data show) to {V(f'models.{name}.{best}.sun_behind_median_residual')}.")
    for name in names:
        m = results["models"][name]
        clouds = [t for t in m if "clouds" in t and t.endswith("+reflections")]
        cvals = [m[t]["median_abs_residual"] for t in clouds]
        lo, hi = clouds[int(np.argmin(cvals))], clouds[int(np.argmax(cvals))]
        refl = max((m[t].get("reflected_max", 0.0) for t in m if t.endswith("+reflections")))
        rkey = next(t for t in m if t.endswith("+reflections") and m[t].get("reflected_max", 0.0) == refl)
        lines.append(f"- {name}, the other models: TOMS 2005 {V(f'models.{name}.toms2005+reflections.median_abs_residual')}"
                     f" (uniform {V(f'models.{name}.uniform.median_abs_residual')}); the band map "
                     f"{V(f'models.{name}.band:BPW34FS+reflections.median_abs_residual')} against CERES all-sky "
                     f"{V(f'models.{name}.ceres2018-all+reflections.median_abs_residual')}; cloud weather "
                     f"{V(f'models.{name}.{lo}.median_abs_residual')} to {V(f'models.{name}.{hi}.median_abs_residual')}"
                     " (random realisations whose mean is the all-sky map, not those days' clouds: each adds "
                     "clouds where there were none, so the mean map does better); the spacecraft's reflections: at "
                     f"most {V(f'models.{name}.{rkey}.reflected_max', '{:.2g}')} of full Sun (the assumed arrays lie "
                     "outside the diode's view).")
    lines.append("")
    lines += ["What is left: near grazing incidence (cos 0-0.1) PD3 reads "
              f"{V('models.PD3.ceres2018-all+reflections.bins.3', '{:+.3f}')} above the prediction, and from cos 0.1 "
              f"to 0.5 both diodes read below it (PD3 {V('models.PD3.ceres2018-all+reflections.mid_median_residual', '{:+.3f}')}, "
              f"PD6 {V('models.PD6.ceres2018-all+reflections.mid_median_residual', '{:+.3f}')}), where the albedo "
              "can only add: the diodes' response and field of view and the attitude estimate, not the Earth "
              "(below). " + _default_words(results, V), ""]
    lines += ["## Models (median residual, fraction of full Sun)", "",
              "| diode | model | median \\|res\\| | Sun behind: median res | Sun behind: median \\|res\\| | "
              "cos 0.1-0.5: median res |", "|---|---|---|---|---|---|"]
    for name in names:
        for key, row in results["models"][name].items():
            if key == "n":
                continue
            p = f"models.{name}.{key}"
            label = row["label"] + (f" {V(p + '.albedo', '{:g}')}" if key == "uniform" else "")
            lines.append(f"| {name} | {label} | {V(p + '.median_abs_residual')} | "
                         f"{V(p + '.sun_behind_median_residual')} | {V(p + '.sun_behind_median_abs_residual')} | "
                         f"{V(p + '.mid_median_residual')} |")
    lines.append("")
    edges = results["bin_edges"]
    lines += ["## Median residual by cos(incidence)", "",
              "| diode | model | " + " | ".join(f"{V(f'bin_edges.{i}', '{:g}')}..{V(f'bin_edges.{i + 1}', '{:g}')}"
                                                for i in range(len(edges) - 1)) + " |",
              "|---|---|" + "---|" * (len(edges) - 1)]
    for name in names:
        for key in ("direct", "uniform", "ceres2018-all+reflections"):
            if key not in results["models"][name]:
                continue
            lines.append(f"| {name} | {results['models'][name][key]['label']} | " + " | ".join(
                V(f"models.{name}.{key}.bins.{i}", "{:+.3f}") for i in range(len(edges) - 1)) + " |")
    lines.append("")
    lines += ["## Reading below the cosine law at cos(incidence) 0.1-0.5", "",
              "Median residual there (negative: the diode reads less than predicted). A shadow of the arrays or the "
              "body would be in the rendered direct Sun (the scene's geometry) and would fall from one side; a "
              "response that is not a cosine (e.g. a cover glass' Fresnel loss) is the same all round; a random "
              "attitude error averages out where the cosine is straight.", "",
              "| diode | n | plain cosine | rendered direct | rendered total | cover glass (n = "
              f"{V('uncertainty.cover_glass_index', '{:g}')}) + albedo | Sun azimuth, deg: " + " / ".join(
                  f"{V(f'pd6.{names[0]}.azimuth.{i}.from_deg', '{:g}')}+" for i in range(4)) + " |",
              "|---|---|---|---|---|---|---|"]
    for name in names:
        p = f"pd6.{name}"
        az = " / ".join(V(f"{p}.azimuth.{i}.median_residual", "{:+.3f}") for i in range(4))
        lines.append(f"| {name} | {V(p + '.n', '{:d}')} | {V(p + '.plain_cosine', '{:+.4f}')} | "
                     f"{V(p + '.rendered_direct', '{:+.4f}')} | {V(p + '.rendered_total', '{:+.4f}')} | "
                     f"{V(p + '.cover_glass_total', '{:+.4f}')} | {az} |")
    lines += ["", _pd6_words(results, V), ""]
    u = results["uncertainty"]
    lines += ["## Uncertainty", "",
              f"On the analytic model ({u['model']}), the change of the median |residual| each source can make:", "",
              "| diode | median \\|res\\| | attitude " + " | attitude ".join(
                  f"{V(f'uncertainty.attitude_sigmas_deg.{i}', '{:g}')} deg rms" for i in range(len(u["attitude_sigmas_deg"])))
              + f" | TLE age (orbit +-{V('uncertainty.tle_shift_s', '{:g}')} s along track) | cover glass response "
              f"| field of view {V('uncertainty.well_fov_deg', '{:g}')} deg (a well) |",
              "|---|---|" + "---|" * (len(u["attitude_sigmas_deg"]) + 3)]
    for name in names:
        p = f"uncertainty.diodes.{name}"
        lines.append(f"| {name} | {V(p + '.median_abs_residual')} | " + " | ".join(
            V(f"{p}.attitude_{s:g}deg", "{:+.4f}") for s in u["attitude_sigmas_deg"])
            + f" | {V(p + '.tle_age', '{:+.4f}')} | {V(p + '.cover_glass', '{:+.4f}')} | "
              f"{V(p + '.fov_well', '{:+.4f}')} |")
    lines += ["", "The attitude is the coarse ADCS's own estimate (probably from these diodes and a magnetometer): "
              "its error is not known; the rows show what a random error of that size would add. The TLE is 9-16 "
              "days old; the shift is its plausible along-track error (simcore/studies/flight_page.py). The diodes' "
              "type, response and field of view are not published: the cover-glass row is one plausible non-cosine "
              "response, the well one plausible field of view (its walls cut the Earth's light from near the horizon).", ""]
    lines += ["## Figures", "",
              "![measured and predicted readings over a few orbits](time_series.png)", "",
              "![residual against cos(incidence): direct only, uniform (fitted), CERES + reflections]"
              "(residual_vs_cos.png)", "",
              "![Sun behind the diode: reading against the diode's view of the day-side Earth]"
              "(residual_vs_earth_view.png)", ""]
    lines += ["## Checks", "", "Every run was checked against the analytic model as `sunsim run` is:", ""]
    for key, c in results["checks"].items():
        lines.append(f"- {key}: {'PASS' if c['pass'] else 'FAIL'} (`{c['run']}`)")
    lines.append("")
    return "\n".join(lines)


def _default_words(results, V):
    """Return the sentence on the default map: CERES all-sky, and how far it is from each diode's best model."""
    parts = []
    for name, m in results["models"].items():
        best = results["best"][name]
        gap = m["ceres2018-all+reflections"]["median_abs_residual"] - m[best]["median_abs_residual"]
        parts.append(f"{name} {V(gap, '{:.4f}')}" + (" (the best)" if gap == 0 else f" behind {m[best]['label']}"))
    return ("The default map of `sunsim flight-check` is CERES 2018 all-sky; its median |residual| is the best's plus "
            + ", ".join(parts) + ".")


def _pd6_words(results, V):
    """Return the words on the PD6 question, chosen by the numbers (each quoted from the results)."""
    p = results["pd6"].get("PD6")
    if p is None:
        return ""
    words = [f"PD6 at cos 0.1-0.5: {V('pd6.PD6.plain_cosine', '{:+.4f}')} against the plain cosine."]
    if abs(p["rendered_direct"] - p["plain_cosine"]) < 0.005:
        words.append("The scene's arrays and body do not shade it there (the rendered direct Sun differs from the "
                     "plain cosine by under 0.005): no modelled shadow explains it.")
    else:
        words.append(f"The scene's shadows change it to {V('pd6.PD6.rendered_direct', '{:+.4f}')}.")
    az = [q["median_residual"] for q in p["azimuth"] if q["median_residual"] is not None]
    vals = [np.nan if q["median_residual"] is None else q["median_residual"] for q in p["azimuth"]]
    i_lo, i_hi = int(np.nanargmin(vals)), int(np.nanargmax(vals))
    if az and max(az) < 0:
        words.append("It is below the cosine from every side of the diode (all four azimuth quadrants negative), "
                     f"but by different amounts ({V(f'pd6.PD6.azimuth.{i_lo}.median_residual', '{:+.3f}')} to "
                     f"{V(f'pd6.PD6.azimuth.{i_hi}.median_residual', '{:+.3f}')}): a loss all round (a response "
                     "below the cosine) with something that depends on the Sun's side on top (an unmodelled "
                     "structure, or an attitude error with a preferred direction).")
    elif az:
        words.append("It depends on the side the Sun comes from (the azimuth quadrants differ in sign): a shadow "
                     "is possible.")
    if p["cover_glass_total"] > 0 > p["rendered_total"]:
        words.append(f"A cover glass of index {V('uncertainty.cover_glass_index', '{:g}')} (Fresnel loss at large "
                     f"incidence) over-corrects it: {V('pd6.PD6.cover_glass_total', '{:+.4f}')} from "
                     f"{V('pd6.PD6.rendered_total', '{:+.4f}')}. The truth lies between a bare cosine and such a "
                     "glass: a response somewhat below the cosine at large incidence fits the sign and size; the data "
                     "cannot tell it from an attitude error of a few degrees (the table below).")
    elif abs(p["cover_glass_total"]) < abs(p["rendered_total"]):
        words.append(f"A cover-glass response brings the median to {V('pd6.PD6.cover_glass_total', '{:+.4f}')} from "
                     f"{V('pd6.PD6.rendered_total', '{:+.4f}')}: the data favour a response below the cosine at "
                     "large incidence.")
    else:
        words.append("A cover-glass response does not bring it closer to zero.")
    return " ".join(words)


# the top-level entries of results.json that the page reads (written by run_study)
RESULTS_KEYS = ("title", "commands", "inputs", "models", "best", "checks", "uncertainty", "pd6")


def write_page(folder):
    """Write ``folder/README.md`` and the figures from ``folder/results.json`` and ``folder/samples.npz``."""
    path = Path(folder) / "results.json"
    if not path.is_file():
        raise InputNotFoundError(f"{path} not found; make it with `sunsim flight-check opssat --study {folder}`")
    redo = f"make it again with `sunsim flight-check opssat --study {folder}`"
    try:
        results = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"{path} is not a results file ({exc}); {redo}") from None
    missing = [k for k in RESULTS_KEYS if k not in results] if isinstance(results, dict) else list(RESULTS_KEYS)
    if missing:
        raise InvalidInputError(f"{path} is not a flight-check results file (no {', '.join(missing)}); {redo}")
    npz = Path(folder) / "samples.npz"
    if npz.is_file():
        try:
            with open(npz, "rb") as fh, np.load(fh) as z:      # the file closed also where numpy refuses it
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise InvalidInputError(f"{npz} is not a readable samples file ({type(exc).__name__}: {exc}); "
                                    f"{redo}") from None
        comparison_figures(arrays, list(results["models"]), folder,
                           model_key="ceres2018-all" if f"{next(iter(results['models']))}/ceres2018-all" in arrays
                           else "ceres2018-all")
    out = Path(folder) / "README.md"
    out.write_text(render_page(results))
    return str(out)
