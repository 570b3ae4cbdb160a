"""The main job: render diode irradiance along an orbit, check it, store it.

:func:`execute` renders the study in chunks of epochs, stores every finished
chunk crash-safely (:mod:`simcore.runstore`), computes the analytic model
beside each chunk and, once all are done, writes one self-describing xarray
Dataset (netCDF) with the check's verdict. Killed and started again with the
same options it continues from its last finished chunk and ends with exactly
the numbers of an uninterrupted run (the renderer's random numbers are keyed
by the global epoch index, not by the chunk).
"""
import dataclasses
import hashlib
import json
import os
from pathlib import Path
import platform
import sys
from dataclasses import dataclass

import numpy as np

import simcore
from simcore import attitude as _attitude
from simcore import check as _check
from simcore.constants import E_SUN_W_M2, R_SUN_M
from simcore.epochs import Epochs
from simcore.maps import named_map
from simcore.runstore import ChunkStore, atomic_write, check_writable, chunk_ranges
from simcore.study import DEFAULT_START, compute_geometry, orbital_period_s

CHECK_REFINE = 3  # the analytic reference for the albedo check uses cells refined 3 x 3


@dataclass
class RunOptions:
    """Everything that decides a run's numbers (and where it goes)."""

    config: str = "tilt20_fov70"
    tle: str = None
    satellite: str = None
    start: str = DEFAULT_START
    duration_s: float = None          # None: one orbital period
    step_s: float = 1.0
    spin_rate_deg_s: float = _attitude.DEFAULT_TUMBLE_RATE_DEG_S
    spin_axis: tuple = (1.0, 1.0, 1.0)
    attitude_file: str = None          # CSV t_s,qw,qx,qy,qz (overrides the tumble)
    dynamics: str = None               # inertia 'IXX,IYY,IZZ[,IXY,IXZ,IYZ]' kg m^2: torque-free Euler dynamics
    rel_se_direct: float = 0.002       # target relative standard errors (None: fixed sample counts)
    rel_se_albedo: float = 0.01
    direct_samples: int = 1024
    albedo_samples: int = 256
    dead: tuple = ()
    extra_flat_diodes: bool = False    # the two optional flat diodes on top and bottom (diodes 14, 15)
    variant: str = None
    seed: int = 0
    reflectivity: str = "toms2005"
    sun_disc: bool = True              # finite solar disc: penumbra
    distance_scaling: bool = False     # thesis: constant solar constant
    chunk_epochs: int = 512
    output: str = "runs/default.nc"
    fail_on_check: bool = False

    def spec(self):
        """Return the JSON-able settings that determine the numbers (not where they go)."""
        d = dataclasses.asdict(self)
        for k in ("output", "fail_on_check", "chunk_epochs"):
            d.pop(k)
        d["dead"] = sorted(int(i) for i in d["dead"])
        d["spin_axis"] = [float(x) for x in d["spin_axis"]]
        for k in ("config", "tle", "attitude_file"):
            v = d[k]
            if v and os.path.isfile(v):
                with open(v, "rb") as f:
                    d[k + "_sha256"] = hashlib.sha256(f.read()).hexdigest()
        d["sunsim_version"] = simcore.__version__
        return d


def _refined(m, factor):
    from simcore.maps import ReflectivityMap
    v = np.repeat(np.repeat(m.values, factor, axis=0), factor, axis=1)
    lat = np.linspace(m.lat_edges_deg[0], m.lat_edges_deg[-1], v.shape[0] + 1)
    lon = np.linspace(m.lon_edges_deg[0], m.lon_edges_deg[-1], v.shape[1] + 1)
    return ReflectivityMap.from_array(v, 0.5 * (lat[1:] + lat[:-1]), 0.5 * (lon[1:] + lon[:-1]),
                                      name=f"{m.name} refined {factor}x{factor}")


def study_geometry(opts):
    """Return (orbit, attitude, geometry) of the orbit, time span and attitude that ``opts`` describe."""
    from simcore.orbit import Orbit
    if opts.step_s is None or not opts.step_s > 0:
        raise ValueError(f"--step must be a positive number of seconds, got {opts.step_s}")
    orbit = Orbit.default() if opts.tle is None else Orbit.from_file(opts.tle, satellite=opts.satellite)
    duration = orbital_period_s(orbit) if opts.duration_s is None else opts.duration_s
    if not (np.isfinite(duration) and 0 < duration <= 400 * 86400):
        raise ValueError(f"--duration must be between 0 and 400 days in seconds, got {duration}")
    epochs = Epochs.range(opts.start, duration, opts.step_s)
    t_s = epochs.seconds_since(epochs[0])
    if opts.attitude_file and opts.dynamics:
        raise ValueError("--attitude and --dynamics both set the attitude; give one of them")
    if opts.attitude_file:
        attitude = _attitude.Attitude.from_file(opts.attitude_file).resample(t_s)
    elif opts.dynamics:
        from simcore.dynamics import parse_inertia, propagate_torque_free
        axis = np.asarray(opts.spin_axis, dtype=float)
        w0 = np.radians(opts.spin_rate_deg_s) * axis / np.linalg.norm(axis)
        attitude, _ = propagate_torque_free(t_s, parse_inertia(opts.dynamics), w0)
    else:
        attitude = _attitude.tumble(t_s, rate_deg_s=opts.spin_rate_deg_s, axis_body=opts.spin_axis)
    return orbit, attitude, compute_geometry(orbit, epochs, attitude)


class Study:
    """A prepared run: configuration, geometry, scene and maps, ready to render chunks."""

    def __init__(self, opts):
        from scenes.config import SatelliteConfig
        self.opts = opts
        self.config = SatelliteConfig.load(opts.config, dead=list(opts.dead),
                                           extra_flat_diodes=True if opts.extra_flat_diodes else None)
        self.orbit, self.attitude, self.geometry = study_geometry(opts)
        self.epochs = self.geometry.epochs
        self.map = named_map(opts.reflectivity)
        self.map_refined = _refined(self.map, CHECK_REFINE)
        self._renderer = None

    @property
    def sun_angular_radius_rad(self):
        """Return the Sun's apparent angular radius for this run (0 for a point Sun): from the mean
        satellite-Sun distance (it changes by < 0.05 % in a day; 1.7 % over a year)."""
        if not self.opts.sun_disc:
            return 0.0
        dist = np.linalg.norm(self.geometry.sun_from_sat_gcrs_m, axis=1)
        return float(np.arcsin(R_SUN_M / np.nanmean(dist)))

    @property
    def renderer(self):
        if self._renderer is None:
            from scenes.geometry import build_satellite_mesh
            from simcore.render import DiodeSet, Renderer
            self._renderer = Renderer(
                DiodeSet.from_config(self.config), build_satellite_mesh(self.config),
                reflectivity=self.map.values, lon_west_deg=float(self.map.lon_edges_deg[0]),
                sun_angular_radius_rad=self.sun_angular_radius_rad, variant=self.opts.variant)
        return self._renderer

    def sun_scale(self, sl):
        g = self.geometry
        return g.sun_distance_scale[sl] if self.opts.distance_scaling else np.ones(sl.stop - sl.start)

    def analytic(self, sl, reflectivity_map, direct=True):
        from simcore.analytic import BodyBox, diode_irradiance
        g = self.geometry
        return diode_irradiance(g.r_sat_ecef_m[sl], g.r_sun_ecef_m[sl], g.R_ecef_from_body[sl],
                                self.config.frames, self.config.apertures, map=reflectivity_map,
                                e_sun_w_m2=E_SUN_W_M2, distance_scaling=self.opts.distance_scaling,
                                eclipse="conical" if self.opts.sun_disc else "cylindrical",
                                body=BodyBox.from_config(self.config),
                                sun_angular_radius_rad=self.sun_angular_radius_rad, direct=direct)

    def render_chunk(self, start, stop):
        """Return the arrays of epochs [start, stop): rendered and analytic irradiance."""
        o, g, sl = self.opts, self.geometry, slice(start, stop)
        valid = g.valid[sl]
        res = self.renderer.render(
            g.sun_dir_body[sl], g.earth_center_body_m[sl], g.R_ecef_from_body[sl], self.sun_scale(sl),
            seed=o.seed, epoch_offset=start, direct_samples=o.direct_samples, albedo_samples=o.albedo_samples,
            rel_se_direct=o.rel_se_direct, rel_se_albedo=o.rel_se_albedo, progress=None)
        native = self.analytic(sl, self.map)
        fine = self.analytic(sl, self.map_refined, direct=False)
        out = {
            "rendered": np.stack([res.direct_w_m2, res.albedo_w_m2], axis=-1),
            "rendered_se": np.stack([res.direct_se_w_m2, res.albedo_se_w_m2], axis=-1),
            "samples": np.stack([res.direct_samples, res.albedo_samples], axis=-1).astype(np.int64),
            "analytic": np.stack([native.direct_w_m2, native.albedo_w_m2], axis=-1),
            "analytic_albedo_refined": fine.albedo_w_m2,
            "valid": valid & res.valid,
        }
        return out


def _versions():
    import drjit
    import mitsuba
    import sgp4
    import erfa
    return {"sunsim": simcore.__version__, "python": platform.python_version(), "numpy": np.__version__,
            "mitsuba": mitsuba.__version__, "drjit": drjit.__version__, "sgp4": sgp4.__version__,
            "pyerfa": erfa.__version__}


def build_dataset(study, data, variant):
    """Return the run's xarray Dataset from the concatenated chunk arrays."""
    import xarray as xr
    o, g, cfg = study.opts, study.geometry, study.config
    n, k = data["rendered"].shape[:2]
    bound = _check.discretisation_bound(data["analytic"][..., 1], data["analytic_albedo_refined"], CHECK_REFINE)
    analytic = data["analytic"].copy()
    analytic_ref = np.stack([analytic[..., 0], data["analytic_albedo_refined"]], axis=-1)
    names = [d.name for d in cfg.diodes]
    W = "W m-2"
    coords = {
        "time": ("time", g.epochs.datetime64),
        "t_s": ("time", g.t_s, {"units": "s", "long_name": "seconds since the first epoch"}),
        "diode": ("diode", np.arange(k)),
        "diode_name": ("diode", np.array(names, dtype=object)),
        "component": ("component", np.array(["direct", "albedo"], dtype=object)),
        "xyz": ("xyz", np.array(["x", "y", "z"], dtype=object)),
        "quat": ("quat", np.array(["w", "x", "y", "z"], dtype=object)),
    }
    ds = xr.Dataset(
        {
            "irradiance": (("time", "diode", "component"), data["rendered"],
                           {"units": W, "long_name": "rendered irradiance on the diode's sensitive area"}),
            "irradiance_se": (("time", "diode", "component"), data["rendered_se"],
                              {"units": W, "long_name": "Monte-Carlo standard error of irradiance"}),
            "samples": (("time", "diode", "component"), data["samples"], {"long_name": "rays traced"}),
            "analytic": (("time", "diode", "component"), analytic,
                         {"units": W, "long_name": "analytic model: aperture overlap response (direct), "
                                                   "Bhanderi cell sum on the native map (albedo)"}),
            "analytic_reference": (("time", "diode", "component"), analytic_ref,
                                   {"units": W, "long_name": f"analytic reference of the check (albedo on the map "
                                                             f"refined {CHECK_REFINE}x{CHECK_REFINE})"}),
            "albedo_discretisation_bound": (("time", "diode"), bound, {"units": W}),
            "sun_dir_body": (("time", "xyz"), g.sun_dir_body, {"long_name": "unit satellite->Sun vector",
                                                                 "frame": "body"}),
            "sun_scale": ("time", study.sun_scale(slice(0, n)),
                          {"long_name": "factor on the solar constant (1, or (1 AU / r)^2 with distance scaling)"}),
            "sun_dir_gcrs": (("time", "xyz"), g.sun_dir_gcrs, {"long_name": "unit satellite->Sun vector", "frame": "GCRS"}),
            "r_sat_gcrs": (("time", "xyz"), g.r_sat_gcrs_m, {"units": "m", "frame": "GCRS"}),
            "r_sat_ecef": (("time", "xyz"), g.r_sat_ecef_m, {"units": "m", "frame": "ITRS"}),
            "illumination": ("time", g.illumination,
                             {"long_name": "visible fraction of the solar disc (conical Earth shadow)"}),
            "sunlit_cylindrical": ("time", g.sunlit_cylindrical.astype(np.int8),
                                   {"long_name": "sunlit under the thesis' cylindrical shadow (eqs. 4.6-4.10)"}),
            "q_gcrs_from_body": (("time", "quat"), study.attitude.q_gcrs_from_body,
                                 {"long_name": "attitude quaternion, scalar first, rotates body vectors into GCRS"}),
            "valid": ("time", data["valid"].astype(np.int8)),
            "normal_body": (("diode", "xyz"), cfg.normals, {"frame": "body"}),
            "fov_deg": ("diode", cfg.fov_deg, {"units": "deg", "long_name": "design field of view (eq. 4.15)"}),
            "dead": ("diode", cfg.dead.astype(np.int8)),
        },
        coords=coords,
    )
    tle = f"{study.orbit.line1}\n{study.orbit.line2}"
    cfg_text = Path(cfg.source).read_text() if cfg.source and os.path.isfile(cfg.source) else ""
    ds.attrs.update({
        "title": "sunsim diode irradiance run",
        "conventions": "time leads; frames named in each variable; SI units",
        "configuration": cfg.name,
        "configuration_toml": cfg_text,
        "satellite": study.orbit.name or "",
        "norad_id": int(study.orbit.norad_id),
        "tle": tle,
        "reflectivity_map": study.map.name,
        "seed": int(o.seed),
        "variant": variant,
        "options": json.dumps(o.spec(), sort_keys=True),
        "software": json.dumps(_versions(), sort_keys=True),
        "e_sun_w_m2": E_SUN_W_M2,
        "period_s": float(orbital_period_s(study.orbit)),
    })
    flags, report = check_run(ds)
    ds["albedo_z"] = (("time", "diode"), flags["albedo_z"],
                      {"long_name": "(rendered - analytic reference) / sqrt(se^2 + bound^2)"})
    ds["outlier"] = (("time", "diode", "component"), np.stack([flags["direct"], flags["albedo"]], axis=-1).astype(np.int8),
                     {"long_name": "1 where outside the analytic check's tolerance"})
    ds.attrs["check"] = json.dumps(report, sort_keys=True)
    ds.attrs["check_pass"] = int(report["pass"])
    return ds, report


def execute(opts, *, progress=None, log=None):
    """Run (or resume) a study; return (output path, Dataset, check report)."""
    log = log or (lambda msg: None)
    check_writable(opts.output)
    if os.path.exists(opts.output):
        raise FileExistsError(f"{opts.output} exists already; choose another --output or delete it")
    study = Study(opts)
    store = ChunkStore(opts.output, opts.spec()).open()
    ranges = chunk_ranges(len(study.epochs), opts.chunk_epochs)
    done = set(store.done())
    todo = [r for r in ranges if r not in done]
    if done:
        log(f"resuming: {len(done)} of {len(ranges)} chunks already in {store.folder}")
    from tqdm import tqdm
    bar = tqdm(total=len(study.epochs), initial=sum(b - a for a, b in done), unit="epoch",
               disable=(not sys.stderr.isatty()) if progress is None else not progress, desc="rendering")
    try:
        for start, stop in todo:
            store.save(start, stop, study.render_chunk(start, stop))
            bar.update(stop - start)
    finally:
        bar.close()
    data = store.load_all(len(study.epochs))
    from simcore.render import choose_variant
    variant = study._renderer.variant if study._renderer is not None else choose_variant(opts.variant)
    ds, report = build_dataset(study, data, variant)

    def write(tmp):
        ds.to_netcdf(tmp, engine="h5netcdf")
    atomic_write(opts.output, write)
    store.remove()
    return opts.output, ds, report


REQUIRED_VARIABLES = ("irradiance", "irradiance_se", "analytic", "analytic_reference", "albedo_discretisation_bound",
                      "sun_dir_body", "sun_scale", "normal_body", "dead", "illumination", "q_gcrs_from_body", "valid")


def open_run(path):
    """Return the Dataset of a finished run file, or raise ValueError saying why it is not one."""
    import xarray as xr
    if not os.path.exists(path):
        raise FileNotFoundError(f"no run file at {path}")
    if os.path.isdir(path):
        raise ValueError(f"{path} is a folder, not a run file (.nc); a folder ending in .partial is an "
                         "unfinished run: finish it by running the same 'sunsim run' command again")
    try:
        ds = xr.load_dataset(path, engine="h5netcdf")      # in memory, file closed
    except Exception as exc:  # h5py/netCDF raise many types for a corrupt file
        raise ValueError(f"{path} is not a readable netCDF run file ({type(exc).__name__}: {exc}); "
                         "was it written by 'sunsim run'?") from None
    missing = [v for v in REQUIRED_VARIABLES if v not in ds]
    if ds.attrs.get("title") != "sunsim diode irradiance run" or missing:
        raise ValueError(f"{path} is not a sunsim run file (missing {', '.join(missing) or 'its sunsim title'}); "
                         "give a file written by 'sunsim run'")
    return ds


def check_run(ds):
    """Return (flags, report): the analytic check recomputed from a run Dataset's arrays."""
    n, k = ds.sizes["time"], ds.sizes["diode"]
    cos_inc = np.clip(np.einsum("nj,kj->nk", ds["sun_dir_body"].values, ds["normal_body"].values), 0.0, None)
    scale = float(ds.attrs.get("e_sun_w_m2", E_SUN_W_M2)) * ds["sun_scale"].values[:, None]
    irr, se, ref = ds["irradiance"].values, ds["irradiance_se"].values, ds["analytic_reference"].values
    considered = np.broadcast_to(ds["valid"].values.astype(bool)[:, None], (n, k))
    return _check.compare(irr[..., 0], se[..., 0], ref[..., 0], irr[..., 1], se[..., 1], ref[..., 1],
                          ds["albedo_discretisation_bound"].values, scale * cos_inc, considered=considered)


def options_of(ds, path):
    """Return the RunOptions a run file was made with (from its 'options' attribute)."""
    spec = json.loads(ds.attrs["options"])
    names = {f.name for f in dataclasses.fields(RunOptions)}
    kw = {k: v for k, v in spec.items() if k in names}
    for k in ("dead", "spin_axis"):
        if k in kw:
            kw[k] = tuple(kw[k])
    return RunOptions(**kw, output=path)


def recompute_analytic(path, *, chunk=4096, log=None):
    """Recompute a run file's analytic model and check with this version of sunsim (the rendered numbers
    are kept); rewrite the file atomically and return the new check report."""
    ds = open_run(path)
    study = Study(options_of(ds, path))
    n = len(study.epochs)
    if n != ds.sizes["time"]:
        raise ValueError(f"{path}: its options give {n} epochs but it holds {ds.sizes['time']}; "
                         "it was not made by this command's options")
    native = np.zeros(ds["analytic"].shape)
    fine = np.zeros(ds["analytic"].shape[:2])
    for s, e in chunk_ranges(n, chunk):
        a = study.analytic(slice(s, e), study.map)
        native[s:e, :, 0], native[s:e, :, 1] = a.direct_w_m2, a.albedo_w_m2
        fine[s:e] = study.analytic(slice(s, e), study.map_refined, direct=False).albedo_w_m2
        if log:
            log(f"analytic {e}/{n}")
    data = {"rendered": ds["irradiance"].values, "rendered_se": ds["irradiance_se"].values,
            "samples": ds["samples"].values, "analytic": native, "analytic_albedo_refined": fine,
            "valid": ds["valid"].values.astype(bool)}
    new, report = build_dataset(study, data, ds.attrs.get("variant", ""))
    new.attrs["software"] = ds.attrs["software"]          # the rendering's versions
    new.attrs["analytic_recomputed_with"] = json.dumps(_versions(), sort_keys=True)

    def write(tmp):
        new.to_netcdf(tmp, engine="h5netcdf")
    ds.close()
    atomic_write(path, write)
    return report
