"""The results page of ``sunsim reproduce``: README.md rendered from ``results.json`` alone.

Every figure on the page is either a value of the results dict (its dotted path is its source), a value
derived from such values (min, max, difference; the source names the inputs), or one of the thesis' own
numbers in :data:`THESIS` (the source cites the section, page and figure). :class:`Figures` formats each
one and records its source; ``render_page(results, marked=True)`` wraps every figure in ``⟦...⟧`` so a
test can prove that no digit on the page comes from anywhere else. A number derived from a run whose
analytic check failed carries the mark :data:`FAILED_MARK`.
"""
import math
import os

import numpy as np

# The thesis' numbers compared against (H. R. Haave, NTNU 2016; pages from its table of contents).
THESIS = {
    "t0": ("2016-07-02T00:00Z", "table 4.3, sec. 4.3 p. 70 (simulation start)"),
    "orbits_from_s": (1.8e4, "figs. 4.13-4.17 (the two orbits compared), sec. 4.3.3 p. 77"),
    "orbits_to_s": (2.8e4, "figs. 4.13-4.17 (the two orbits compared), sec. 4.3.3 p. 77"),
    "pinv_base_zenith_lo_deg": (18.0, "sec. 4.3.1 p. 71, fig. 4.6: smallest peak 'around 18 deg'"),
    "pinv_base_zenith_hi_deg": (25.0, "sec. 4.3.1 p. 71, fig. 4.6: largest zenith error 25 deg"),
    "pinv_base_azimuth_deg": (5.0, "sec. 4.3.1 p. 71, fig. 4.6: azimuth 'usually bellow 5 deg'"),
    "fov70_below_deg": (5.0, "sec. 4.3.1 p. 71, fig. 4.7: 'below 5 deg for major parts of an orbit'"),
    "wls_lower_deg": (5.0, "sec. 4.3.2 p. 74, figs. 4.10-4.11: peak 'reduced by approximately 5 deg'"),
    "as70_first_deg": (6.0, "sec. 4.3.3 p. 77, fig. 4.13: first orbit 'bellow 6 deg'"),
    "as70_second_deg": (8.0, "sec. 4.3.3 p. 77, fig. 4.13: second orbit 'bellow 8 deg'"),
    "as75_deg": (15.0, "sec. 4.3.3 p. 77, fig. 4.14: FOV 75 peak 'bellow 15 deg'"),
    "saswls_first_deg": (5.0, "sec. 4.3.4 p. 81, fig. 4.15: first orbit 'bellow 5 deg' (tilt 25, 30)"),
    "saswls_second_deg": (15.0, "sec. 4.3.4 p. 81, fig. 4.15: second-orbit peak 'around 15 deg'"),
    "sas_first_deg": (5.0, "sec. 4.3.4 p. 81, fig. 4.17: first orbit 'bellow 5 deg'"),
    "sas_second_deg": (6.25, "sec. 4.3.4 p. 81, fig. 4.17: second orbit 'bellow 6.25 deg'"),
}
# The thesis' bounds are read off its figures; a value up to this fraction above a bound is called
# "at the bound" (agreement within reading), further above "does not hold". A stated convention, the
# same for every claim.
READING_TOLERANCE = 0.05
FAILED_MARK = " **(check FAILED)**"
ESTIMATORS = ["pinv", "wls", "albedo_sun", "sun_albedo_sun_wls", "sun_albedo_sun", "smart_select"]
THESIS_FOUR = ESTIMATORS[:5]


def _finite(x):
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


class Figures:
    """Formats the page's figures and records where each comes from (see the module docstring)."""

    def __init__(self, results, marked=False):
        self.r = results
        self.marked = marked
        self.sources = []

    def failed(self, runs):
        """Return True when any of ``runs`` (configuration names, 'spin:CFG', 'map:NAME') failed its check."""
        for run in runs:
            if run.startswith("spin:"):
                c = self.r.get("spin", {}).get("configs", {}).get(run[5:], {})
            elif run.startswith("map:"):
                c = {"check_pass": self.r.get("cross_map_checks", {}).get(run[4:], {}).get("pass") is True}
            else:
                c = self.r["configs"].get(run, {})
            if c.get("check_pass") is False:
                return True
        return False

    def num(self, value, source, fmt="{:.2f}", runs=()):
        """Return ``value`` formatted (``-`` when missing or not finite), recording ``source``."""
        if isinstance(value, str):
            text = value
        elif not _finite(value):
            return "-"
        else:
            text = fmt.format(value)
        self.sources.append((text, source))
        if self.marked:
            text = f"⟦{text}⟧"
        return text + (FAILED_MARK if runs and self.failed(runs) else "")

    def get(self, path, default=None):
        """Return the value at dotted ``path`` of the results (list items by index), or ``default``."""
        node = self.r
        for key in path.split("."):
            if isinstance(node, list) and key.lstrip("-").isdigit() and -len(node) <= int(key) < len(node):
                node = node[int(key)]
            elif isinstance(node, dict) and key in node:
                node = node[key]
            else:
                return default
        return node

    def val(self, path, fmt="{:.2f}", runs=None):
        """Return the results value at ``path`` formatted; its runs default to the configuration in the path."""
        if runs is None:
            parts = path.split(".")
            runs = [parts[1]] if parts[0] == "configs" and len(parts) > 1 else ()
        return self.num(self.get(path), "results:" + path, fmt, runs)

    def thesis(self, key, fmt="{:g}"):
        """Return the thesis' number ``key`` of :data:`THESIS` formatted, its citation recorded."""
        value, cite = THESIS[key]
        return self.num(value, f"thesis: {cite}", fmt)

    def derived(self, value, how, paths, fmt="{:.2f}", runs=()):
        """Return a value computed from results values (``how`` of ``paths``) formatted."""
        return self.num(value, f"derived: {how} of " + ", ".join(paths), fmt, runs)


# ---------------------------------------------------------------------------------------------- helpers
def _orbit_peak(row, comp, orbit):
    """Return the per-orbit peak of ``comp`` in orbit number ``orbit`` and its list index (None if absent)."""
    if row is None or orbit not in row.get("orbits", []):
        return None, None
    i = row["orbits"].index(orbit)
    return row[f"{comp}_mean_peak_per_orbit_deg"][i], i


def thesis_orbits(results):
    """Return the orbit numbers holding the thesis' two orbits 1.8e4-2.8e4 s (from the run's period)."""
    period = results.get("period_s")
    if not _finite(period) or period <= 0:
        return []
    return sorted({int(THESIS["orbits_from_s"][0] // period), int(THESIS["orbits_to_s"][0] // period)})


def verdict_below(F, value_text, value, bound_key, what="", runs=()):
    """Return the verdict words for a thesis claim 'below the bound': holds / at the bound / does not hold
    (``runs``: the runs the value comes from, for the failed-check mark)."""
    bound = THESIS[bound_key][0]
    if not _finite(value):
        return "not in this span"
    if value <= bound:
        return f"holds{what}"
    excess = value - bound
    src = f"value {value_text} minus thesis {bound_key}"
    if value <= bound * (1 + READING_TOLERANCE):
        return (f"at the bound{what} ({F.num(excess, 'derived: ' + src, runs=runs)} deg above, within the "
                f"{F.num(100 * READING_TOLERANCE, 'stated convention READING_TOLERANCE', '{:g}')} % read off a figure)")
    return f"does not hold{what} ({F.num(excess, 'derived: ' + src, runs=runs)} deg above)"


def _agrees(value, bound):
    return _finite(value) and value <= bound * (1 + READING_TOLERANCE)


def _fmt_table(header, rows):
    return ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"] + ["| " + " | ".join(r) + " |" for r in rows]


# ---------------------------------------------------------------------------------------------- page
def render_page(results, figure_files=(), marked=False):
    """Return (markdown text of the results page, [(figure text, source)]) for a results dict."""
    F = Figures(results, marked)
    cfgs = list(results["configs"])
    win = F.val("settings.hanning_window", "{:d}")
    lines = [f"# The thesis' chapter-4 study, reproduced on rendered irradiance ({results['span']})", "",
             "Generated by `sunsim reproduce` from `results.json` (every number below comes from it or, for the "
             "thesis' own numbers, from `simcore.studies.reproduce_page.THESIS` with its citation). Settings: "
             f"ESTCube-1 (shipped TLE), start {F.val('start', '{}')}, {F.val('duration_s', '{:.0f}')} s at "
             f"{F.val('settings.step_s', '{:g}')} s, tumble {F.val('settings.spin_rate_deg_s', '{:g}')} deg/s about "
             f"({', '.join(F.val(f'settings.spin_axis.{i}', '{:g}') for i in range(3))}) normalised, "
             f"{F.val('settings.reflectivity', '{}')}, {F.val('settings.diode', '{}')} "
             f"(E_S0 = {F.val('settings.e_s0_w_m2', '{:g}')} W/m^2), Sun {F.val('settings.e_sun_w_m2', '{:g}')} W/m^2 "
             f"constant, no noise, diode {F.val('settings.dead_in_14_diode_layouts.0', '{:d}')} dead in the "
             "14-diode layouts, irradiance ray traced through the real wells, ramps and body "
             f"({F.val('settings.rel_se_direct', '{:.1%}')} / {F.val('settings.rel_se_albedo', '{:.1%}')} relative "
             "standard error, direct / albedo).", "",
             "The estimators follow the thesis: " + _choice_words(results) + " The project's own choices are "
             "shown as labelled variants below.", ""]
    lines += _check_section(F, results)
    lines += ["", f"## Peak of the Hanning-window ({win} samples) mean |zenith error| over the sunlit orbits [deg]", ""]
    lines += _fmt_table(["configuration"] + ESTIMATORS,
                        [[c] + [F.val(f"configs.{c}.{n}.zenith_mean_peak_deg") for n in ESTIMATORS] for c in cfgs])
    lines += ["", "## Sunlit angle error: mean / 95th percentile / max [deg]", ""]
    lines += _fmt_table(["configuration"] + ESTIMATORS,
                        [[c] + [" / ".join(F.val(f"configs.{c}.{n}.{k}") for k in ("mean_deg", "p95_deg", "max_deg"))
                                for n in ESTIMATORS] for c in cfgs])
    if cfgs:
        orbits = results["configs"][cfgs[0]]["sun_albedo_sun"].get("orbits", [])
        lines += ["", f"Per orbit (the thesis compares {F.thesis('orbits_from_s', '{:.0f}')}-"
                      f"{F.thesis('orbits_to_s', '{:.0f}')} s from {F.thesis('t0', '{}')}), the peak of the Hanning mean "
                      "|zenith error| of Sun-Albedo-Sun (Albedo-Sun start) [deg]:", ""]
        lines += _fmt_table(["configuration"] + [f"orbit {F.val(f'configs.{cfgs[0]}.sun_albedo_sun.orbits.{i}', '{:d}', ())}"
                                                 for i in range(len(orbits))],
                            [[c] + [F.val(f"configs.{c}.sun_albedo_sun.zenith_mean_peak_per_orbit_deg.{i}")
                                    for i in range(len(orbits))] for c in cfgs])
    lines += _variant_section(F, results, cfgs)
    lines += _aperture_section(F, results)
    if any("with_noise" in r for r in results["configs"].values()):
        lines += ["", "## With sensor noise (shot + Johnson, eqs. 2.26-2.28): sunlit mean angle error [deg]", ""]
        lines += _fmt_table(["configuration"] + THESIS_FOUR,
                            [[c] + [F.val(f"configs.{c}.with_noise.{n}") for n in THESIS_FOUR] for c in cfgs])
    spin = results.get("spin", {})
    if spin.get("configs"):
        lines += ["", f"## Second spin rate: {F.val('spin.rate_deg_s', '{:g}')} deg/s, the span `orbits`: "
                      "sunlit mean / p95 [deg]", ""]
        lines += _fmt_table(["configuration"] + ESTIMATORS,
                            [[c] + [" / ".join(F.val(f"spin.configs.{c}.{n}.{k}", runs=[f"spin:{c}"])
                                               for k in ("mean_deg", "p95_deg")) for n in ESTIMATORS]
                             for c in spin["configs"]])
    if results.get("cross_map"):
        runs = ["map:toms2005", "map:ceres2018-all"]
        lines += ["", "## On-board albedo prediction, cross-map (tilt20_fov70): sunlit mean / p95 / max [deg]", ""]
        lines += _fmt_table(["rendered with", "on-board map", "estimator", "mean", "p95", "max", "invalid"],
                            [[r["truth_map"], r["onboard_map"], r["estimator"]]
                             + [F.val(f"cross_map.{i}.{k}", runs=runs) for k in ("mean_deg", "p95_deg", "max_deg")]
                             + [F.val(f"cross_map.{i}.n_invalid", "{:d}", runs)]
                             for i, r in enumerate(results["cross_map"])])
    lines += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figure_files]
    lines += ["", *discussion(F, results)]
    return "\n".join(lines) + "\n", F.sources


def _choice_words(results):
    ch = results.get("thesis_choices", {})
    dead = ("the dead diode reads zero and the estimators are not told" if ch.get("announce_dead") is False
            else "the estimators are told which diode is dead")
    pinv = ("the pseudoinverse uses every diode with E_p >= E_S0 cos(FOV), zero readings included (at FOV "
            "ninety degrees: every diode)" if ch.get("pinv_keep_zero_readings") else
            "the pseudoinverse leaves out zero readings")
    return f"{dead}; {pinv}."


def _check_section(F, results):
    """The analytic check of every run: pass/fail and the check's scalar figures, whatever keys it holds."""
    runs = [(c, f"configs.{c}.check", c) for c in results["configs"]]
    runs += [(f"{c}, second spin", f"spin.configs.{c}.check", f"spin:{c}")
             for c in results.get("spin", {}).get("configs", {})]
    runs += [(f"tilt20_fov70, {m}", f"cross_map_checks.{m}", f"map:{m}") for m in results.get("cross_map_checks", {})
             if m != "toms2005"]
    keys = []
    for _, path, _ in runs:
        for k, v in (F.get(path) or {}).items():
            if k != "pass" and k not in keys and (v is None or isinstance(v, (bool, int, float, str))):
                keys.append(k)
    failed = [label for label, path, _ in runs if (F.get(path) or {}).get("pass") is not True]
    lines = ["## The analytic check of every run", "",
             "Each run's rendered irradiance is checked against the analytic model (`sunsim validate RUN`); "
             "the figures and the failed tests are the check's, as this version of sunsim computes it from the "
             "run file's arrays."]
    if failed:
        lines += ["", f"**{len(failed)} run(s) failed their check and were used anyway "
                      "(`--allow-failed-checks`): " + ", ".join(failed) + ".** Every number derived from them is "
                      f"marked{FAILED_MARK}."]
    rows = []
    for label, path, _ in runs:
        chk = F.get(path) or {}
        cells = [label, "pass" if chk.get("pass") is True else "**FAIL**"]
        cells.append(", ".join(f"{t['component']} {t['test']}" for t in chk.get("tests", [])
                               if isinstance(t, dict) and not t.get("passed", True)) or "-")
        for k in keys:
            v = chk.get(k)
            if isinstance(v, bool) or isinstance(v, str):
                cells.append(F.num(str(v), f"results:{path}.{k}"))
            elif isinstance(v, int):
                cells.append(F.num(v, f"results:{path}.{k}", "{:d}"))
            elif isinstance(v, float):
                cells.append(F.num(v, f"results:{path}.{k}", "{:.4g}"))
            else:
                cells.append("-")
        rows.append(cells)
    return lines + [""] + _fmt_table(["run", "check", "failed tests"] + keys, rows)


def _variant_section(F, results, cfgs):
    lines = []
    for key, var in results.get("variants", {}).items():
        vc = var.get("configs", {})
        names = [n for n in ESTIMATORS if any(n in vc.get(c, {}) for c in cfgs)]
        lines += ["", f"## Variant \"{var['label']}\": {var['words']}", "",
                  "Peak Hanning-mean |zenith error| / |azimuth error| over the span [deg], the thesis' way -> "
                  "this variant:", ""]
        rows = []
        for c in cfgs:
            if c not in vc:
                continue
            cells = [c]
            for n in names:
                a = [F.val(f"configs.{c}.{n}.{comp}_mean_peak_deg") for comp in ("zenith", "azimuth")]
                b = [F.val(f"variants.{key}.configs.{c}.{n}.{comp}_mean_peak_deg", runs=[c]) for comp in ("zenith", "azimuth")]
                cells.append(f"{a[0]} / {a[1]} -> {b[0]} / {b[1]}")
            rows.append(cells)
        lines += _fmt_table(["configuration"] + names, rows)
        lines += ["", _variant_shift_words(F, results, key, cfgs, names)]
    return lines


def variant_shift(results, key, cfgs, names):
    """Return (largest |variant - thesis' way| of any per-orbit zenith/azimuth peak, its (cfg, estimator, comp))."""
    best, where = None, None
    for c in cfgs:
        for n in names:
            for comp in ("zenith", "azimuth"):
                a = results["configs"].get(c, {}).get(n, {}).get(f"{comp}_mean_peak_per_orbit_deg")
                b = results["variants"][key]["configs"].get(c, {}).get(n, {}).get(f"{comp}_mean_peak_per_orbit_deg")
                if not a or not b:
                    continue
                d = np.abs(np.asarray(b, float) - np.asarray(a, float))
                if np.isfinite(d).any() and (best is None or np.nanmax(d) > best):
                    best, where = float(np.nanmax(d)), (c, n, comp)
    return best, where


def _variant_shift_words(F, results, key, cfgs, names):
    best, where = variant_shift(results, key, cfgs, names)
    if best is None:
        return "No estimator changes in this span."
    c, n, comp = where
    return (f"The largest change of a per-orbit peak: {F.derived(best, 'max |variant - thesis| per-orbit peaks', [f'variants.{key}.configs', 'configs'], runs=cfgs)} "
            f"deg ({c}, {n}, {comp}).")


def _aperture_section(F, results):
    am = results.get("aperture_models", {})
    if not am.get("configs"):
        return []
    est = am["estimator"]
    lines = ["", f"## Does the FOV-75 agreement need the body? {est} on three irradiance models", "",
             "The same orbit, attitude and Sun, the analytic irradiance with the thesis' aperture response "
             "(eq. 4.15, no body), with the square wells the renderer traces (no body), and with wells + body; "
             "peak Hanning-mean |zenith error| over the span [deg], and the rendered run beside them:", ""]
    models = list(am["labels"])
    rows = []
    for c in am["configs"]:
        rows.append([c, "the thesis' way"]
                    + [F.val(f"aperture_models.configs.{c}.{m}.zenith_mean_peak_deg", runs=[c]) for m in models]
                    + [F.val(f"configs.{c}.{est}.zenith_mean_peak_deg")])
        for key, var in am.get("variants", {}).items():
            if c in var:
                rows.append([c, results["variants"][key]["label"]]
                            + [F.val(f"aperture_models.variants.{key}.{c}.{m}.zenith_mean_peak_deg", runs=[c])
                               for m in models]
                            + [F.val(f"variants.{key}.configs.{c}.{est}.zenith_mean_peak_deg", runs=[c])])
    lines += _fmt_table(["configuration", "estimators"] + [am["labels"][m] for m in models] + ["rendered"], rows)
    return lines


def aperture_verdict(results, variant=None):
    """Return ({model: worst peak over the FOV-75 configurations}, agrees {model: bool}) for the thesis'
    Albedo-Sun FOV-75 bound (:data:`THESIS` 'as75_deg'), with the thesis' estimator choices or ``variant``'s."""
    am = results.get("aperture_models", {})
    rows = am.get("configs", {}) if variant is None else am.get("variants", {}).get(variant, {})
    worst = {}
    for m in am.get("labels", {}):
        vals = [r[m]["zenith_mean_peak_deg"] for r in rows.values() if m in r and _finite(r[m]["zenith_mean_peak_deg"])]
        worst[m] = max(vals) if vals else None
    bound = THESIS["as75_deg"][0]
    return worst, {m: _agrees(v, bound) for m, v in worst.items()}


def shadow_words(worst, agrees):
    """Return the verdict on the body's self-shadowing from the worst peaks per irradiance model."""
    no_body = [m for m in ("eq415", "wells") if m in agrees]
    if agrees.get("wells_body") and no_body and not any(agrees[m] for m in no_body):
        return ("the agreement holds only because of the body's self-shadowing: without the body "
                "(eq. 4.15 or wells alone) the bound is exceeded")
    if agrees.get("wells_body") and all(agrees[m] for m in no_body):
        return "it holds without the body too"
    if not agrees.get("wells_body") and any(agrees[m] for m in no_body):
        return "it would hold without the body's self-shadowing"
    return "the bound is exceeded with every irradiance model"


# ---------------------------------------------------------------------------------------------- discussion
def _worst(F, results, cfgs, est, comp="zenith"):
    """Return (text, value, cfg) of the largest whole-span peak of ``est`` over ``cfgs``."""
    vals = [(results["configs"][c][est][f"{comp}_mean_peak_deg"], c) for c in cfgs
            if c in results["configs"] and _finite(results["configs"][c][est][f"{comp}_mean_peak_deg"])]
    if not vals:
        return "-", None, None
    v, c = max(vals)
    return F.val(f"configs.{c}.{est}.{comp}_mean_peak_deg"), v, c


def discussion(F, results):
    """Return the discussion's lines: each thesis claim, this reproduction's numbers and a computed verdict."""
    R = results["configs"]
    fov70 = [c for c in R if c.endswith("_fov70")]
    fov75 = [c for c in R if c.endswith("_fov75")]
    orbits = thesis_orbits(results)
    first, second = (orbits + [None, None])[:2] if len(orbits) == 2 else (None, None)
    rows = []

    base = R.get("tilt0_fov90")
    if base:
        peaks = base["pinv"]["zenith_mean_peak_per_orbit_deg"]
        fin = [p for p in peaks if _finite(p)]
        lo, hi = (min(fin), max(fin)) if fin else (None, None)
        src = ["configs.tilt0_fov90.pinv.zenith_mean_peak_per_orbit_deg"]
        t_peak = base["pinv"].get("zenith_peak_t_s")
        where = ""
        if _finite(t_peak):
            where = (f"; the largest at {F.val('configs.tilt0_fov90.pinv.zenith_peak_t_s', '{:.0f}')} s, over "
                     f"{F.val('configs.tilt0_fov90.pinv.zenith_peak_lat_deg', '{:.1f}')} deg latitude, "
                     f"{F.val('configs.tilt0_fov90.pinv.zenith_peak_lon_deg', '{:.1f}')} deg longitude")
        ok = _finite(lo) and lo >= THESIS["pinv_base_zenith_lo_deg"][0] * (1 - READING_TOLERANCE) and \
            _agrees(hi, THESIS["pinv_base_zenith_hi_deg"][0])
        rows.append([f"Pseudoinverse, baseline: zenith peaks {F.thesis('pinv_base_zenith_lo_deg')}-"
                     f"{F.thesis('pinv_base_zenith_hi_deg')} deg over the day",
                     f"per-orbit peaks {F.derived(lo, 'min', src, runs=['tilt0_fov90'])}-"
                     f"{F.derived(hi, 'max', src, runs=['tilt0_fov90'])} deg{where}",
                     "within the thesis' range" if ok else "outside the thesis' range"])
        az = base["pinv"]["azimuth_mean_peak_deg"]
        azv = results.get("variants", {}).get("pinv_drops_zero_readings", {}).get("configs", {}).get("tilt0_fov90", {})
        rows.append([f"baseline azimuth error mostly below {F.thesis('pinv_base_azimuth_deg')} deg",
                     f"azimuth peak {F.val('configs.tilt0_fov90.pinv.azimuth_mean_peak_deg')} deg (pinv, the thesis' "
                     f"selection), {F.val('variants.pinv_drops_zero_readings.configs.tilt0_fov90.pinv.azimuth_mean_peak_deg', runs=['tilt0_fov90'])} "
                     f"deg when zero readings are dropped, {F.val('configs.tilt0_fov90.wls.azimuth_mean_peak_deg')} deg (WLS)",
                     verdict_below(F, "configs.tilt0_fov90.pinv.azimuth_mean_peak_deg", az, "pinv_base_azimuth_deg",
                                   runs=["tilt0_fov90"])
                     + ("" if not azv else "; with zero readings dropped: " + verdict_below(
                         F, "variants.pinv_drops_zero_readings...azimuth_mean_peak_deg",
                         azv.get("pinv", {}).get("azimuth_mean_peak_deg"), "pinv_base_azimuth_deg", runs=["tilt0_fov90"]))])
    if fov70:
        shares = [R[c]["pinv"]["share_below_5_deg"] for c in fov70]
        rows.append([f"FOV 70: error below {F.thesis('fov70_below_deg')} deg for most of the sunlit orbit",
                     "pinv below it during " + " / ".join(F.val(f"configs.{c}.pinv.share_below_5_deg", "{:.0%}") for c in fov70)
                     + f" of the sunlit time ({', '.join(fov70)})",
                     "reproduced" if all(_finite(s) and s > 0.5 for s in shares) else "not reproduced"])
    if fov70 and fov75:
        pairs = [(a, a.replace("_fov70", "_fov75")) for a in fov70 if a.replace("_fov70", "_fov75") in R]
        worse = all(R[b]["pinv"]["mean_deg"] > R[a]["pinv"]["mean_deg"] for a, b in pairs)
        rows.append(["FOV 75 much worse (more diodes see the Earth)",
                     "pinv sunlit mean / p95, FOV 70 -> FOV 75: " + "; ".join(
                         f"{F.val(f'configs.{a}.pinv.mean_deg')} / {F.val(f'configs.{a}.pinv.p95_deg')} -> "
                         f"{F.val(f'configs.{b}.pinv.mean_deg')} / {F.val(f'configs.{b}.pinv.p95_deg')}" for a, b in pairs),
                     "reproduced" if worse else "not reproduced: FOV 75 is not worse for every tilt"])
        spread_tilt = np.nanmax([np.ptp([R[c][n]["mean_deg"] for c in fov70]) for n in THESIS_FOUR])
        spread_fov = np.nanmin([abs(R[b]["pinv"]["mean_deg"] - R[a]["pinv"]["mean_deg"]) for a, b in pairs] or [np.nan])
        rows.append(["tilt barely matters",
                     f"at FOV 70 the sunlit means of any one estimator differ by at most "
                     f"{F.derived(spread_tilt, 'max over estimators of (max - min over tilts) of mean_deg', [f'configs.{c}' for c in fov70], runs=fov70)} "
                     f"deg between tilts; FOV 70 -> FOV 75 changes the pinv mean by at least "
                     f"{F.derived(spread_fov, 'min over tilts of |mean FOV 75 - mean FOV 70|', [f'configs.{c}' for c in fov70 + fov75], runs=fov70 + fov75)} deg",
                     "reproduced (tilt matters less than the FOV)" if spread_tilt < spread_fov else
                     "not in this span" if not (np.isfinite(spread_tilt) and np.isfinite(spread_fov)) else
                     "not reproduced (tilt matters as much as the FOV)"])
    if fov70:
        drops = [(R[c]["pinv"]["zenith_mean_peak_deg"] - R[c]["wls"]["zenith_mean_peak_deg"], c) for c in fov70]
        rows.append([f"WLS: zenith peak about {F.thesis('wls_lower_deg')} deg lower than pseudoinverse",
                     "worst-peak pinv - WLS: " + ", ".join(
                         f"{c} {F.derived(d, 'pinv - wls zenith_mean_peak_deg', [f'configs.{c}'], runs=[c])}" for d, c in drops) + " deg",
                     "WLS lower for every FOV-70 layout" if all(_finite(d) and d > 0 for d, _ in drops)
                     else "WLS not lower everywhere"])
        for est, k1, k2, which, label in (
                ("albedo_sun", "as70_first_deg", "as70_second_deg", fov70, "Albedo-Sun, FOV 70"),
                ("sun_albedo_sun_wls", "saswls_first_deg", "saswls_second_deg",
                 [c for c in fov70 if not c.startswith("tilt20")], "Sun-Albedo-Sun from WLS (tilt 25/30)"),
                ("sun_albedo_sun", "sas_first_deg", "sas_second_deg", fov70, "Sun-Albedo-Sun from Albedo-Sun")):
            cells, worst1, worst2 = [], [], []
            for c in which:
                p1, i1 = _orbit_peak(R[c][est], "zenith", first)
                p2, i2 = _orbit_peak(R[c][est], "zenith", second)
                t1 = "-" if i1 is None else F.val(f"configs.{c}.{est}.zenith_mean_peak_per_orbit_deg.{i1}")
                t2 = "-" if i2 is None else F.val(f"configs.{c}.{est}.zenith_mean_peak_per_orbit_deg.{i2}")
                cells.append(f"{c} {t1} / {t2}")
                worst1.append((p1, c, i1))
                worst2.append((p2, c, i2))
            w_text, w_val, _ = _worst(F, results, which, est)
            v1 = max((w for w in worst1 if _finite(w[0])), default=(None, None, None))
            v2 = max((w for w in worst2 if _finite(w[0])), default=(None, None, None))
            second_words = verdict_below(F, f"configs.{v2[1]}.{est}.zenith_mean_peak_per_orbit_deg", v2[0], k2, runs=which) \
                if k2 != "saswls_second_deg" else (
                    "peak " + ("about" if _finite(v2[0]) and abs(v2[0] - THESIS[k2][0]) <= THESIS[k2][0] * READING_TOLERANCE
                               else "not about") + " the thesis' value" if _finite(v2[0]) else "not in this span")
            rows.append([f"{label}: first orbit below {F.thesis(k1)} deg, second "
                         + ("peak about " if k2 == "saswls_second_deg" else "below ") + f"{F.thesis(k2)} deg",
                         "thesis' orbits first / second: " + "; ".join(cells) + f"; whole span at most {w_text} deg",
                         "first orbit: " + verdict_below(F, f"configs.{v1[1]}.{est}.zenith_mean_peak_per_orbit_deg", v1[0], k1,
                                                         runs=which)
                         + "; second: " + second_words])
    if fov75:
        rows.append(_fov75_row(F, results, fov75))
    if R:
        means = {n: np.nanmean([R[c][n]["mean_deg"] for c in R if _finite(R[c][n]["mean_deg"])] or [np.nan])
                 for n in THESIS_FOUR}
        best = min(means, key=lambda n: means[n] if np.isfinite(means[n]) else np.inf)
        rows.append(["Sun-Albedo-Sun from Albedo-Sun is the best of the four",
                     "sunlit mean over all configurations: " + ", ".join(
                         f"{n} {F.derived(means[n], 'mean over configurations of mean_deg', [f'configs.*.{n}.mean_deg'], runs=list(R))}"
                         for n in THESIS_FOUR) + " deg",
                     "reproduced" if best == "sun_albedo_sun" else f"not reproduced: {best} is best here"])

    lines = ["## Discussion: the thesis' claims (sec. 4.3) side by side with this reproduction", "",
             "Generated from `results.json`: each verdict is computed from the numbers beside it. The thesis' "
             "numbers are read off its figures, so a value up to "
             f"{F.num(100 * READING_TOLERANCE, 'stated convention READING_TOLERANCE', '{:g}')} % above a bound "
             "counts as at the bound. Orbits are numbered from the thesis' start "
             f"{F.thesis('t0', '{}')} (period {F.val('period_s', '{:.0f}')} s); its two orbits "
             f"{F.thesis('orbits_from_s', '{:.0f}')}-{F.thesis('orbits_to_s', '{:.0f}')} s are our orbits "
             + (" and ".join(F.derived(o, 'floor(thesis orbit times / period_s)', ['period_s'], '{:d}') for o in orbits)
                if orbits else "-") + ".", ""]
    lines += _fmt_table(["thesis", "this reproduction", "verdict"], rows)
    lines += ["", "### Differences, and why", "",
              "1. **When the worst orbits happen.** The thesis' exact TLE is unknown; the public ESTCube-1 set used "
              "here puts the polar passes over the brightest TOMS cells at other times of the day. Compare "
              "per-orbit envelopes and rankings, not clock times.",
              "2. **The tumble axis.** The thesis gives the rate, not the axis; a constant rate about a fixed "
              "axis keeps the Sun on one cone in the body frame all day, so another axis changes which diodes "
              "do the work. The second spin rate (table above) tests the rankings.",
              "3. **Real apertures instead of eq. 4.15, and the body.** The traced square well is not linear "
              "in the cosine between the FOV and the cut-off, and tilted diodes look past their panel's edge "
              "into the body. The table \"Does the FOV-75 agreement need the body?\" separates the two effects.",
              "4. **No estimate instead of a wrong one.** Where fewer than three diodes are left, an estimator "
              "returns `valid=False`; the error statistics exclude those epochs.",
              "5. **Pseudoinverse and WLS on the cube.** With FOV ninety degrees the thesis' threshold "
              "E_S0 cos(FOV) is zero; wherever all six faces are lit the weighted least-squares solution of "
              "opposite pairs is E+ - E- (`estimators.advanced`), which the smart selection builds on.", ""]
    inv = [(R[c]["sun_albedo_sun"]["n_invalid"], R[c]["sun_albedo_sun"]["n_sunlit"], c) for c in R
           if R[c]["sun_albedo_sun"]["n_sunlit"]]
    if inv:
        n, tot, c = max(inv)
        lines += [f"Sun-Albedo-Sun from Albedo-Sun returns no estimate on at most "
                  f"{F.val(f'configs.{c}.sun_albedo_sun.n_invalid', '{:d}')} of "
                  f"{F.val(f'configs.{c}.sun_albedo_sun.n_sunlit', '{:d}')} sunlit epochs ({c}).", ""]
    lines += _beyond(F, results)
    return lines


def _fov75_row(F, results, fov75):
    """The Albedo-Sun FOV-75 claim, with the verdict on whether it holds only because of the body's shadow."""
    R = results["configs"]
    w_text, w_val, _ = _worst(F, results, fov75, "albedo_sun")
    claim = f"Albedo-Sun, FOV 75: peak below {F.thesis('as75_deg')} deg"
    verdict = verdict_below(F, "max over FOV-75 configs of albedo_sun zenith_mean_peak_deg", w_val, "as75_deg",
                            runs=fov75)
    am = results.get("aperture_models", {})
    models = am.get("labels", {})
    ours = f"whole span at most {w_text} deg (rendered)"
    for variant in [None] + list(am.get("variants", {})):
        worst, agrees = aperture_verdict(results, variant)
        if not worst or all(v is None for v in worst.values()):
            continue
        name = "the thesis' way" if variant is None else results["variants"][variant]["label"]
        src = [f"aperture_models.{'configs' if variant is None else 'variants.' + variant}"]
        ours += f"; analytic, worst FOV-75 layout, {name}: " + ", ".join(
            f"{F.derived(worst[m], 'max over FOV-75 configs', src, runs=fov75)} deg with {models[m]}" for m in worst)
        verdict += f"; analytic, {name}: {shadow_words(worst, agrees)}"
    return [claim, ours, verdict]


def _beyond(F, results):
    R = results["configs"]
    lines = ["### Beyond the thesis", ""]
    base = R.get("tilt0_fov90")
    if base and "smart_select" in base:
        lines.append(f"- **Smart diode selection for the cube (its sec. 5.2):** sunlit mean error "
                     f"{F.val('configs.tilt0_fov90.wls.mean_deg')} deg (WLS) -> "
                     f"{F.val('configs.tilt0_fov90.smart_select.mean_deg')} deg; worst per-orbit peak "
                     f"{F.val('configs.tilt0_fov90.wls.zenith_mean_peak_deg')} -> "
                     f"{F.val('configs.tilt0_fov90.smart_select.zenith_mean_peak_deg')} deg.")
    cm = [(i, r) for i, r in enumerate(results.get("cross_map") or []) if "gain" in str(r.get("estimator", ""))]
    if cm:
        runs = ["map:toms2005", "map:ceres2018-all"]
        lines.append("- **Predicting the albedo on board** (Bhanderi model, the known orbit, a stale attitude, one "
                     "fitted gain), rendered with one map and predicted with the other: sunlit mean / p95 " + "; ".join(
                         f"{r['truth_map']} -> {r['onboard_map']} {F.val(f'cross_map.{i}.mean_deg', runs=runs)} / "
                         f"{F.val(f'cross_map.{i}.p95_deg', runs=runs)} deg" for i, r in cm) + ".")
    noisy = [(c, n) for c in R for n in THESIS_FOUR if _finite(R[c].get("with_noise", {}).get(n))]
    if noisy:
        d = max(abs(R[c]["with_noise"][n] - R[c][n]["mean_deg"]) for c, n in noisy)
        lines.append("- **Noise** (shot and Johnson, eqs. 2.26-2.28): the sunlit means with noise differ from "
                     f"those without by at most {F.derived(d, 'max |with_noise - mean_deg|', ['configs.*.with_noise', 'configs.*.*.mean_deg'], runs=list(R))} deg.")
    return lines


def write_page(results, page_folder):
    """Write README.md of ``results`` (see :func:`render_page`) into ``page_folder``, beside its figures."""
    figures = sorted(f for f in os.listdir(page_folder) if f.endswith(".png"))
    text, _ = render_page(results, figures)
    with open(os.path.join(page_folder, "README.md"), "w") as f:
        f.write(text)
