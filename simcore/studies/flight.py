"""Predicted photodiode readings against a satellite's flight telemetry (issue 29): ``sunsim flight-check``.

The comparison never fits: it renders the scene it is given at the telemetry's own (irregular) epochs, through the
same run machinery as ``sunsim run`` (:func:`simcore.pipeline.run.execute`, checked against the analytic model as
usual), and holds each diode's measured reading against the predicted one.

Definitions (issue 29, item 4):

- the **measured reading** is ``sin(theta)`` of the telemetry's diode "elevation" theta: the photocurrent over its
  full-Sun value at normal incidence (simcore/data/flight/opssat/README.md);
- the **predicted reading** is the rendered total irradiance (direct Sun + Earth albedo + the spacecraft's
  reflections) over the full-Sun irradiance at normal incidence at that epoch (``e_sun_w_m2 * sun_scale`` of the run
  file), i.e. after the diode's angular response, which the renderer traces (a bare diode: the cosine law);
- **residual** = measured - predicted; statistics on the samples with the spacecraft fully sunlit (the visible
  fraction of the solar disc 1) and a trusted attitude, where the reading is finite;
- **cos(incidence)** = the diode normal . the satellite->Sun unit vector, body frame; "Sun behind": cos < -0.2;
- **direct only**: the rendered direct component alone (the same scene's shadows, no Earth, no reflections);
- **uniform baseline**: the same diodes as plain cosines (no body) on a uniform Lambertian Earth, the one albedo per
  diode in 0, 0.05, ..., 1 whose median |residual| is the least on the data given (the baseline may fit; the
  prediction may not).
"""
from __future__ import annotations

import dataclasses
import hashlib
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simcore.errors import InputNotFoundError, InvalidInputError

REPO = Path(__file__).resolve().parents[2]
OPSSAT_DATA = REPO / "simcore" / "data" / "flight" / "opssat"
BIN_EDGES = (-1.0, -0.5, -0.2, 0.0, 0.1, 0.2, 0.3, 0.5, 0.7, 0.9, 1.0)
SUN_BEHIND_COS = -0.2
UNIFORM_ALBEDOS = tuple(round(0.05 * i, 2) for i in range(21))
DEFAULT_MAP = "ceres2018-all"
# The fit of a normal uses the sunlit samples that read at least this much (the Sun clearly in front of the diode,
# the albedo a small share that the fit models): the README's cosine law holds there within +-0.03.
FIT_MIN_READING = 0.2
# Attitude sanity check: among the sunlit samples that read at least CHECK_READING (the Sun well in front of the
# diode), the share whose predicted direct Sun is below CHECK_PREDICTED must stay under CHECK_MAX_SHARE. With the
# right convention the shipped week has none such (a few % of full Sun of attitude error cannot turn 0.5 into
# 0.1); with the quaternion's direction or scalar position wrong, the Sun lands anywhere: about half of them.
CHECK_READING, CHECK_PREDICTED, CHECK_MAX_SHARE = 0.5, 0.1, 0.2
# The marker line of a scene file above which the fit leaves the text as it is (scenes/examples/opssat.toml)
DIODE_MARKER = "# --- diodes: written by `sunsim flight-check opssat --fit` (everything below this line) ---"


@dataclass(frozen=True)
class Mount:
    """Where a diode of a flight scene sits (scenes/FORMAT.md: ``panel``, ``at_mm``); its normal is fitted."""
    panel: str
    at_mm: tuple


# OPS-SAT's six photodiodes: the faces the README's hand fit found (PD3 +X by the star tracker, PD6 -Z by the HD
# camera; PD1 +Z, PD4 +Y, PD5 -X, PD2 -Y on the 2021 logs); face centres (PD6 beside the camera): assumed, not
# published (scenes/examples/opssat.toml says so).
OPSSAT_MOUNTS = {"PD1": Mount("+z", (0.0, 0.0)), "PD2": Mount("-y", (0.0, 0.0)), "PD3": Mount("+x", (0.0, 0.0)),
                 "PD4": Mount("+y", (0.0, 0.0)), "PD5": Mount("-x", (0.0, 0.0)), "PD6": Mount("-z", (25.0, 25.0))}


@dataclass(frozen=True)
class Satellite:
    """A satellite ``sunsim flight-check`` knows: its scene and shipped telemetry (the defaults)."""
    name: str
    scene: Path
    pd: Path
    attitude: Path
    tle: Path
    logs: tuple          # telemetry logs with readings and quaternions in one file (the direct-Sun fit)
    logs_tle: Path
    mounts: dict


SATELLITES = {
    "opssat": Satellite(
        "opssat", REPO / "scenes" / "examples" / "opssat.toml",
        OPSSAT_DATA / "pd_theta_2020-11-15_to_21.csv", OPSSAT_DATA / "attitude_2020-11-15_to_21.csv",
        OPSSAT_DATA / "tle_2020-11-06.txt", tuple(sorted((OPSSAT_DATA / "logs_2021").glob("data_2021-*.csv"))),
        OPSSAT_DATA / "tle_2021-02-08.txt", OPSSAT_MOUNTS),
}


def satellite(name):
    """Return the :class:`Satellite` called ``name``; an unknown one is a one-line error naming the known ones."""
    if name not in SATELLITES:
        raise InvalidInputError(f"unknown satellite {name!r} for flight-check; known: {', '.join(SATELLITES)}")
    return SATELLITES[name]


# ---- telemetry --------------------------------------------------------------------------------------------------

@dataclass
class Telemetry:
    """Readings and the recorded attitude at the readings' epochs.

    ``epochs`` (N,): the reading epochs with a trusted attitude (the others are counted in ``dropped``, never
    interpolated across); ``readings``: diode name -> (N,) sin(theta), NaN where the reading is not valid;
    ``history``: the recorded :class:`simcore.environment.history.AttitudeHistory`."""
    epochs: object
    readings: dict
    history: object
    source: str
    dropped: int = 0
    total: int = 0

    @property
    def names(self):
        return list(self.readings)

    def select(self, mask):
        """Return the telemetry at the epochs where ``mask`` (N,) holds."""
        mask = np.asarray(mask, bool)
        return dataclasses.replace(self, epochs=self.epochs[np.flatnonzero(mask)],
                                   readings={k: v[mask] for k, v in self.readings.items()})


def _is_log(path):
    """Return True if ``path`` is an on-board log with readings and quaternions in one file (the 2021 format)."""
    with open(path, "r", errors="replace") as f:
        head = f.readline()
    return "CADC1002" in head and "CADC0884" in head


def load_telemetry(pd_path, attitude_path=None):
    """Return the :class:`Telemetry` of a reading file and an attitude file, or of a log holding both.

    ``pd_path``: the labelled PD file (``TIMESTAMP, PD3, PD6, ...``) with ``attitude_path`` the GRAINS attitude
    export, or a 2021-style on-board log (then ``attitude_path`` is None). Readings are converted to sin(theta);
    epochs without a trusted attitude are dropped and counted."""
    from simcore.environment import telemetry as tm
    for p in (pd_path, attitude_path):
        if p is not None and not os.path.isfile(p):
            raise InputNotFoundError(f"telemetry file {p} not found; give an existing file")
    if _is_log(pd_path):
        if attitude_path is not None:
            raise InvalidInputError(f"{pd_path} is an on-board log with its own quaternions; leave out --attitude")
        history, pd = tm.read_opssat_log_2021(pd_path)
    else:
        if attitude_path is None:
            raise InvalidInputError(f"{pd_path} holds readings only; give the attitude file with --attitude")
        pd = tm.read_opssat_pd(pd_path)
        history = tm.read_opssat_attitude(attitude_path)
    epochs = pd.epochs
    theta = {name: np.where(pd.usable[:, k], pd.theta_rad[:, k], np.nan) for k, name in enumerate(pd.names)}
    ok = history.trusted(epochs)
    if not ok.any():
        raise InvalidInputError(f"no reading of {pd_path} falls in a trusted stretch of the attitude history "
                                f"({history.source or attitude_path}); are they of the same days?")
    idx = np.flatnonzero(ok)
    readings = {name: np.sin(v[idx]) for name, v in theta.items()}
    return Telemetry(epochs[idx], readings, history, str(pd_path), dropped=int((~ok).sum()), total=len(ok))


# ---- the scene --------------------------------------------------------------------------------------------------

def scene_for(scene_path, names, folder):
    """Return the path of a scene holding only the diodes ``names`` of ``scene_path`` (a file in ``folder``), or
    ``scene_path`` itself when it has no fit marker or holds exactly those diodes.

    The telemetry reads some of the diodes (the 2020 week: PD3 and PD6); rendering the others would triple the
    work for nothing. The text above the marker (body, parts, materials) is kept as written."""
    text = Path(scene_path).read_text()
    if DIODE_MARKER not in text:
        return str(scene_path)
    head = text.split(DIODE_MARKER)[0]
    diodes = tomllib.loads(text).get("diode", [])
    have = [d.get("name") for d in diodes]
    missing = [n for n in names if n not in have]
    if missing:
        raise InvalidInputError(f"the scene {scene_path} has no diode named {', '.join(missing)} (it has "
                                f"{', '.join(map(str, have))}); run `sunsim flight-check ... --fit` or add them")
    if have == list(names):
        return str(scene_path)
    chosen = [d for d in diodes if d.get("name") in names]
    out = head + DIODE_MARKER + "\n" + "".join(_diode_table(d) for d in chosen)
    os.makedirs(folder, exist_ok=True)
    digest = hashlib.sha256(out.encode()).hexdigest()[:12]
    path = Path(folder) / f"{Path(scene_path).stem}_{'_'.join(names)}_{digest}.toml"
    if not path.exists():
        path.write_text(out)
    return str(path)


def _toml_value(v):
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return repr(float(v)) if isinstance(v, float) else str(v)


def _diode_table(d, comment=""):
    lines = ["", "[[diode]]" + (f"   # {comment}" if comment else "")]
    lines += [f"{k} = {_toml_value(v)}" for k, v in d.items()]
    return "\n".join(lines) + "\n"


def write_diode_block(scene_path, fitted, mounts, notes):
    """Rewrite the diodes of ``scene_path`` (everything below :data:`DIODE_MARKER`) with the fitted normals.

    ``fitted``: name -> unit normal (3,); ``mounts``: name -> :class:`Mount`; ``notes``: name -> a comment (what
    the fit used and found). Written with full float precision, so the normals are unit to ~1e-16."""
    text = Path(scene_path).read_text()
    if DIODE_MARKER not in text:
        raise InvalidInputError(f"{scene_path} has no line {DIODE_MARKER!r}: the fit writes the diodes below it; "
                                "add it at the end of the file")
    head = text.split(DIODE_MARKER)[0]
    blocks = []
    for name in sorted(fitted):
        n = np.asarray(fitted[name], float)
        n = n / np.linalg.norm(n)
        m = mounts[name]
        blocks.append(_diode_table({"name": name, "panel": m.panel, "normal": [float(x) for x in n],
                                    "at_mm": [float(x) for x in m.at_mm], "fov_deg": 90}, notes.get(name, "")))
    Path(scene_path).write_text(head + DIODE_MARKER + "\n" + "".join(blocks))


# ---- prediction through the run machinery -----------------------------------------------------------------------

@dataclass
class Prediction:
    """Rendered readings at the telemetry's epochs, in units of the full-Sun irradiance at normal incidence."""
    names: list
    total: np.ndarray        # (N, K) predicted reading: (direct + albedo + reflected) / E_normal
    direct: np.ndarray       # (N, K)
    albedo: np.ndarray       # (N, K)
    reflected: np.ndarray    # (N, K)
    se: np.ndarray           # (N, K) standard error of total (the render's, components independent)
    cos_incidence: np.ndarray  # (N, K)
    illumination: np.ndarray   # (N,)
    sun_body: np.ndarray       # (N, 3) unit satellite->Sun vector, body frame
    normals: np.ndarray      # (K, 3)
    uniform_unit: np.ndarray  # (N, K) plain cosine diodes: albedo of a uniform Earth of albedo 1, full Sun units
    cosine_direct: np.ndarray  # (N, K) plain cosine diodes: the direct Sun, full Sun units
    earth_view: np.ndarray   # (N, K) the uniform albedo-1 irradiance = the diode's view of the day-side Earth
    check: dict
    run_path: str


def run_options(telemetry, scene, tle, reflectivity, *, clouds=None, seed=0, folder="runs/flight-check",
                names=None):
    """Return the :class:`simcore.pipeline.options.RunOptions` that render ``scene`` at the telemetry's epochs with
    its recorded attitude (one process, every pass), writing under ``folder`` (an identical earlier run is reused)."""
    from simcore.pipeline.options import RunOptions
    names = list(names or telemetry.names)
    config = scene_for(scene, names, os.path.join(folder, "scenes"))
    return RunOptions(config=config, tle=str(tle), epochs=telemetry.epochs, attitude_history=telemetry.history,
                      reflectivity=reflectivity, clouds=clouds, seed=seed)


def predict(telemetry, scene, tle, reflectivity=DEFAULT_MAP, *, clouds=None, seed=0, folder="runs/flight-check",
            log=None):
    """Render ``scene`` at the telemetry's epochs and return the :class:`Prediction` of its diodes."""
    from simcore.pipeline import run as _run, schedule as _schedule
    opts = run_options(telemetry, scene, tle, reflectivity, clouds=clouds, seed=seed, folder=folder)
    os.makedirs(folder, exist_ok=True)
    opts = dataclasses.replace(opts, output=_run.default_output(opts, folder=folder), fail_on_check=False)
    path, ds, report = _run.execute(opts, log=log)
    names = [str(n) for n in ds["diode_name"].values]
    if names != telemetry.names:
        order = [names.index(n) for n in telemetry.names]
    else:
        order = list(range(len(names)))
    e_norm = float(ds.attrs["e_sun_w_m2"]) * ds["sun_scale"].values
    irr = ds["irradiance"].values[:, order, :] / e_norm[:, None, None]
    se = ds["irradiance_se"].values[:, order, :] / e_norm[:, None, None]
    normals = ds["normal_body"].values[order]
    sun_body = ds["sun_dir_body"].values
    _, _, geometry = _schedule.study_geometry(opts)
    cos_direct, unit = plain_cosine(geometry, normals)
    return Prediction(names=list(telemetry.names), total=irr.sum(axis=-1), direct=irr[..., 0], albedo=irr[..., 1],
                      reflected=irr[..., 2], se=np.sqrt((se ** 2).sum(axis=-1)),
                      cos_incidence=sun_body @ normals.T, illumination=ds["illumination"].values, sun_body=sun_body,
                      normals=normals,
                      uniform_unit=unit, cosine_direct=cos_direct, earth_view=unit, check=report, run_path=path)


def sample_arrays(telemetry, pred, uniform_albedo, model_key):
    """Return the per-sample arrays of the figures (:func:`simcore.studies.flight_page.comparison_figures`)."""
    out = {"time": telemetry.epochs.datetime64.astype("datetime64[ms]").astype(np.int64),
           "illumination": pred.illumination}
    for k, name in enumerate(pred.names):
        out[f"{name}/measured"] = telemetry.readings[name]
        out[f"{name}/{model_key}"] = pred.total[:, k]
        out[f"{name}/direct"] = pred.direct[:, k]
        out[f"{name}/cos"] = pred.cos_incidence[:, k]
        out[f"{name}/earth_view"] = pred.earth_view[:, k]
        out[f"{name}/uniform"] = pred.cosine_direct[:, k] + uniform_albedo[name] * pred.uniform_unit[:, k]
    return out


def plain_cosine(geometry, normals, reflectivity=None, response=None):
    """Return ((N, K) direct Sun, (N, K) albedo) of plain cosine diodes of ``normals`` (no body) in units of the
    full-Sun irradiance at normal incidence: the direct Sun with the conical eclipse, the albedo on
    ``reflectivity`` (None: a uniform Lambertian Earth of albedo 1, whose albedo irradiance scales linearly with
    the albedo: the uniform baseline at albedo a is ``direct + a * albedo``). ``response``: another angular
    response than the cosine (e.g. a :class:`simcore.shapes.aperture.WellAperture` limiting the field of view)."""
    from simcore.environment.maps import uniform_map
    from simcore.radiometry.analytic import diode_irradiance
    from simcore.radiometry.response import CosineResponse
    from simcore.shapes.aperture import diode_frame
    frames = np.stack([diode_frame(np.asarray(n, float) / np.linalg.norm(n)) for n in normals])
    g = geometry
    res = diode_irradiance(g.r_sat_ecef_m, g.r_sun_ecef_m, g.R_ecef_from_body, frames,
                           CosineResponse() if response is None else response,
                           map=uniform_map(1.0) if reflectivity is None else reflectivity, e_sun_w_m2=1.0,
                           distance_scaling=False, eclipse="conical", precision="double")
    return res.direct_w_m2, res.albedo_w_m2


# ---- the comparison ---------------------------------------------------------------------------------------------

def _median(x):
    return float(np.median(x)) if len(x) else None


def _round(x, nd=5):
    return None if x is None else round(float(x), nd)


def uniform_baseline(measured, cos_direct, unit):
    """Return (best albedo, its median |residual|) of the uniform baseline over :data:`UNIFORM_ALBEDOS`."""
    scores = [np.median(np.abs(measured - (cos_direct + a * unit))) for a in UNIFORM_ALBEDOS]
    i = int(np.argmin(scores))
    return UNIFORM_ALBEDOS[i], float(scores[i])


def attitude_check(measured, direct, sunlit):
    """Return the attitude sanity check of one diode: among the sunlit samples reading >= CHECK_READING, how many
    the prediction puts nearly dark (direct < CHECK_PREDICTED); ``pass`` while their share stays under
    CHECK_MAX_SHARE. A wrong quaternion convention fails it (tests/studies/test_flight.py)."""
    bright = sunlit & (measured >= CHECK_READING)
    n = int(bright.sum())
    miss = int((bright & (direct < CHECK_PREDICTED)).sum())
    return {"n": n, "dark_predicted": miss, "pass": bool(n == 0 or miss / n < CHECK_MAX_SHARE)}


def compare(telemetry, pred):
    """Return the comparison's JSON-able dict (``{"diodes": {name: {...}}, ...}``, the structure of issue 29)."""
    sunlit = pred.illumination >= 1.0
    out = {}
    for k, name in enumerate(pred.names):
        m = telemetry.readings[name]
        use = sunlit & np.isfinite(m)
        if not use.any():           # no valid sunlit reading of this diode (e.g. flagged invalid in a log)
            out[name] = {"n": 0, "median_abs_residual": None, "median_abs_residual_direct_only": None,
                         "median_abs_residual_uniform": None, "uniform_albedo": None,
                         "sun_behind_median_residual": None, "sun_behind_n": 0, "median_render_se": None,
                         "normal": [_round(x, 6) for x in pred.normals[k]],
                         "attitude_check": {"n": 0, "dark_predicted": 0, "pass": True}, "bins": [
                             {"lo": lo, "hi": hi, "n": 0, "median_residual": None,
                              "median_residual_direct_only": None, "median_residual_uniform": None,
                              "median_measured": None, "median_predicted": None}
                             for lo, hi in zip(BIN_EDGES[:-1], BIN_EDGES[1:])]}
            continue
        mu = m[use]
        res = mu - pred.total[use, k]
        res_direct = mu - pred.direct[use, k]
        a, uni = uniform_baseline(mu, pred.cosine_direct[use, k], pred.uniform_unit[use, k])
        res_uni = mu - (pred.cosine_direct[use, k] + a * pred.uniform_unit[use, k])
        cos = pred.cos_incidence[use, k]
        behind = cos < SUN_BEHIND_COS
        bins = []
        for i, (lo, hi) in enumerate(zip(BIN_EDGES[:-1], BIN_EDGES[1:])):
            inb = (cos >= lo) & ((cos < hi) if i < len(BIN_EDGES) - 2 else (cos <= hi))
            bins.append({"lo": lo, "hi": hi, "n": int(inb.sum()),
                         "median_residual": _round(_median(res[inb])),
                         "median_residual_direct_only": _round(_median(res_direct[inb])),
                         "median_residual_uniform": _round(_median(res_uni[inb])),
                         "median_measured": _round(_median(mu[inb])),
                         "median_predicted": _round(_median(pred.total[use, k][inb]))})
        se = pred.se[use, k]
        out[name] = {
            "n": int(use.sum()),
            "median_abs_residual": _round(np.median(np.abs(res))),
            "median_abs_residual_direct_only": _round(np.median(np.abs(res_direct))),
            "median_abs_residual_uniform": _round(uni),
            "uniform_albedo": a,
            "sun_behind_median_residual": _round(_median(res[behind])),
            "sun_behind_n": int(behind.sum()),
            "median_render_se": _round(np.median(se), 6),
            "normal": [_round(x, 6) for x in pred.normals[k]],
            "attitude_check": attitude_check(mu, pred.direct[use, k], np.ones(len(mu), bool)),
            "bins": bins,
        }
    return {"diodes": out,
            "samples": {"telemetry": telemetry.total, "trusted_attitude": len(telemetry.epochs),
                        "dropped_untrusted_attitude": telemetry.dropped, "sunlit": int(sunlit.sum())},
            "definitions": {"residual": "measured sin(theta) - predicted reading (total irradiance / full-Sun normal "
                                        "irradiance); samples: fully sunlit, trusted attitude, finite reading",
                            "sun_behind": f"cos(incidence) < {SUN_BEHIND_COS} and the spacecraft sunlit",
                            "bin_edges": list(BIN_EDGES),
                            "uniform": "plain cosine diodes on a uniform Lambertian Earth, best albedo of "
                                       "0, 0.05, ..., 1 per diode (fitted on the data given)"},
            "check_pass": bool(pred.check.get("pass", False)),
            "run": pred.run_path}


# ---- the fit of the normals -------------------------------------------------------------------------------------

# A fitted normal further than this from its mount's panel axis, or fitting worse than FIT_MAX_RESIDUAL, is not
# constrained by the data (the shipped 2021 logs' PD2: README "poorly constrained"): the scene keeps the panel's axis
FIT_MAX_OFF_AXIS_DEG = 20.0
FIT_MAX_RESIDUAL = 0.1
PANEL_AXES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0), "+z": (0, 0, 1), "-z": (0, 0, -1)}


def fit_normals(telemetry, tle, mounts, reflectivity=DEFAULT_MAP, iterations=3, albedo=True):
    """Return ({name: normal}, {name: info}) fitted on the telemetry by the cosine law
    (:func:`simcore.radiometry.normal_fit.fit_normal`: ``reading - extra ~ scale * normal . sun``, soft-L1) on the
    fully sunlit samples where ``reading - extra`` >= :data:`FIT_MIN_READING` (the direct Sun clearly in front:
    near the Earth a diode facing it reads up to ~0.2 of albedo alone). With ``albedo``, ``extra`` is the Earth's albedo on
    ``reflectivity`` seen by a plain cosine diode of the current normal (the analytic model; iterated from the
    mount's panel axis, the albedo depending on the normal only weakly); without, the direct Sun alone.
    A fit off its panel by more than FIT_MAX_OFF_AXIS_DEG or worse than FIT_MAX_RESIDUAL keeps the panel's axis
    (``info['constrained']`` False)."""
    from simcore.environment.geometry import compute_geometry
    from simcore.environment.orbit import Orbit
    from simcore.radiometry.band import resolve_map
    from simcore.radiometry.normal_fit import fit_normal
    orbit = Orbit.from_file(str(tle))
    g = compute_geometry(orbit, telemetry.epochs, telemetry.history.attitude_at(telemetry.epochs))
    lit = np.nan_to_num(g.illumination)
    refl = resolve_map(reflectivity) if albedo else None
    normals, info = {}, {}
    for name in telemetry.names:
        m = telemetry.readings[name]
        axis = np.array(PANEL_AXES[mounts[name].panel], float)
        n = axis
        extra = np.zeros(len(m))
        for _ in range(iterations if albedo else 1):
            if albedo:
                extra = plain_cosine(g, [n], refl)[1][:, 0]
            # the direct Sun's share clearly positive (the linear cosine law holds): the reading less the albedo
            mask = (lit >= 1.0) & np.isfinite(m) & (m - extra >= FIT_MIN_READING)
            fit = fit_normal(g.sun_dir_body, m - extra, mask)
            n = fit.normal
        off = float(np.degrees(np.arccos(np.clip(n @ axis, -1.0, 1.0))))
        ok = off <= FIT_MAX_OFF_AXIS_DEG and fit.median_abs_residual <= FIT_MAX_RESIDUAL
        normals[name] = n if ok else axis
        info[name] = {"n": fit.n, "scale": float(fit.scale), "median_abs_residual": fit.median_abs_residual,
                      "median_residual": float(np.nanmedian(fit.residuals)), "off_axis_deg": off,
                      "constrained": bool(ok), "fitted_normal": [float(x) for x in n]}
    return normals, info


def merge_logs(telemetries):
    """Return one :class:`Telemetry` of several (the 2021 logs), epochs in order (the diodes all logs share)."""
    from simcore.environment.epochs import Epochs
    names = [n for n in telemetries[0].names if all(n in t.readings for t in telemetries)]
    jd1 = np.concatenate([t.epochs.jd1 for t in telemetries])
    jd2 = np.concatenate([t.epochs.jd2 for t in telemetries])
    order = np.argsort(jd1 + jd2, kind="stable")
    readings = {n: np.concatenate([t.readings[n] for t in telemetries])[order] for n in names}
    return Telemetry(Epochs(jd1[order], jd2[order]), readings, _Histories([t.history for t in telemetries]),
                     ", ".join(t.source for t in telemetries),
                     dropped=sum(t.dropped for t in telemetries), total=sum(t.total for t in telemetries))


class _Histories:
    """Several recorded histories (one per log) answering ``attitude_at`` for epochs in any of them."""

    def __init__(self, histories):
        self.histories = histories

    def attitude_at(self, epochs):
        from simcore.environment.attitude import Attitude
        q = np.full((len(epochs), 4), np.nan)
        for h in self.histories:
            ok = h.trusted(epochs)
            if ok.any():
                q[ok] = h.attitude_at(epochs[np.flatnonzero(ok)]).q_gcrs_from_body
        return Attitude(q)
