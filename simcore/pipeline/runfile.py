"""The run file: its schema, declared once, how it is built, read, checked and kept intact.

:data:`VARIABLES` declares each variable of the netCDF file a run writes (dims, units, description, the chunk
array it stores) and :data:`CHUNK_ARRAYS` the arrays of a finished chunk (:class:`simcore.pipeline.store.ChunkStore`);
:func:`build_dataset` writes them, :func:`open_run`, :func:`check_run` and :func:`options_of` read them.

A run file written by this sunsim carries a ``checksums`` attribute: a SHA-256 digest of each numeric variable
(its dtype, shape and bytes). :func:`verify_checksums` recomputes them when the file is opened, so a variable that
was zeroed, cut short or changed since it was written is refused in one line instead of being estimated. Files
written before the checksums existed are accepted with a note (nothing to compare with).

:func:`writer` names who writes a run's chunks (sunsim version, renderer variant): a partial run is resumed only
by the same writer.
"""
import dataclasses
import datetime as _dt
import functools
import hashlib
import json
import os
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from simcore._version import __version__
from simcore.constants import E_SUN_W_M2
from simcore.environment.geometry import orbital_period_s
from simcore.errors import InputNotFoundError, InvalidInputError
from simcore.pipeline import check as _check
from simcore.pipeline import schedule as _schedule
from simcore.pipeline.options import RunOptions
from simcore.pipeline.store import spec_digest

TITLE = "sunsim diode irradiance run"      # the title attribute every run file carries


@dataclass(frozen=True)
class Variable:
    """One variable of the run file."""

    dims: tuple
    units: str
    long_name: str              # may name ``{refine}``: the check's refinement of the map's cells
    frame: str = None
    chunk: str = None           # the chunk array (CHUNK_ARRAYS) it stores as it is; None: build_dataset computes it
    flag: bool = False          # 0/1, stored as int8
    required: bool = False      # every run file holds it: open_run refuses a file without it
    absent: float = None        # what a file written before the variable existed reads as (None: not readable)

    def attrs(self, **fields):
        """Return the variable's netCDF attributes (``fields``: the values the long name names)."""
        out = {"units": self.units, "long_name": self.long_name.format(**fields) if fields else self.long_name}
        if self.frame is not None:
            out["frame"] = self.frame
        return out


W = "W m-2"
TDC = ("time", "diode", "component")
VARIABLES = {
    "irradiance": Variable(TDC, W, "rendered irradiance on the diode's sensitive area", chunk="rendered",
                           required=True),
    "irradiance_se": Variable(TDC, W, "Monte-Carlo standard error of irradiance", chunk="rendered_se", required=True),
    "irradiance_dof": Variable(TDC, "1", "effective degrees of freedom of irradiance_se (Satterthwaite; inf where the "
                                         "value is exact)", chunk="rendered_dof", absent=np.inf),
    "direct_plain": Variable(("time", "diode", "statistic"), W, "the check's second direct-Sun estimate, rendered "
                             "without the analytic aperture hint on a random share of the epochs (NaN elsewhere): "
                             "value, standard error, degrees of freedom", chunk="direct_plain", absent=np.nan),
    "samples": Variable(TDC, "1", "rays traced", chunk="samples"),
    "analytic": Variable(TDC, W, "analytic model: aperture overlap response (direct), Bhanderi cell sum on the native "
                                 "map (albedo)", required=True),
    "analytic_reference": Variable(TDC, W, "analytic reference of the check (albedo on the map refined "
                                           "{refine}x{refine})", required=True),
    "albedo_discretisation_bound": Variable(("time", "diode"), W, "estimated cell-discretisation error of the refined "
                                                                  "analytic albedo", required=True),
    "albedo_mesh": Variable(("time", "diode"), W, "albedo of the check's reference arriving through directions where "
                            "shadows of the body or other parts cross the diode (before their shadow; there the "
                            "reference takes the visible share traced against the mesh)", chunk="albedo_mesh"),
    "albedo_visibility_error": Variable(("time", "diode"), W, "estimated error of the reference's traced visible share "
                                        "(its grid made twice as coarse)", chunk="albedo_visibility_error"),
    "direct_unchecked": Variable(("time", "diode"), "1", "1 where a part the analytic model does not know ([[part]]: "
                                 "panels, antennas, user meshes; another diode's mount) may block the direct Sun: the "
                                 "check leaves that direct value out", chunk="direct_unchecked", flag=True, absent=0),
    "direct_unchecked_window": Variable(("time", "diode"), "1", "1 where a diode under a window may be shaded by the "
                                        "body (its light leaves the window shifted): also in direct_unchecked",
                                        chunk="direct_unchecked_window", flag=True),
    "sun_dir_body": Variable(("time", "xyz"), "1", "unit satellite->Sun vector", "body", required=True),
    "sun_scale": Variable(("time",), "1", "factor on the solar constant (1, or (1 AU / r)^2 with distance scaling)",
                          required=True),
    "sun_dir_gcrs": Variable(("time", "xyz"), "1", "unit satellite->Sun vector", "GCRS"),
    "r_sat_gcrs": Variable(("time", "xyz"), "m", "satellite position", "GCRS"),
    "r_sat_ecef": Variable(("time", "xyz"), "m", "satellite position", "ITRS"),
    "illumination": Variable(("time",), "1", "visible fraction of the solar disc (conical Earth shadow)",
                             required=True),
    "sunlit_cylindrical": Variable(("time",), "1", "1 where sunlit under the thesis' cylindrical shadow "
                                                   "(eqs. 4.6-4.10)", flag=True),
    "q_gcrs_from_body": Variable(("time", "quat"), "1", "attitude quaternion, scalar first, rotates body vectors into "
                                                        "GCRS", required=True),
    "valid": Variable(("time",), "1", "1 where the orbit and the rendering are valid", chunk="valid", flag=True,
                      required=True),
    "normal_body": Variable(("diode", "xyz"), "1", "diode normal", "body", required=True),
    "fov_deg": Variable(("diode",), "deg", "design field of view (eq. 4.15)"),
    "dead": Variable(("diode",), "1", "1 for a dead diode", flag=True, required=True),
    "sun_normal_irradiance": Variable(("time",), W, "full-Sun irradiance at normal incidence at the satellite: "
                                      "e_sun_w_m2 x sun_scale (distance) x illumination (visible share of the solar "
                                      "disc); a diode's reading over full Sun is its irradiance over this"),
    "outlier": Variable(TDC, "1", "1 where the check's normal score |z| > 4 (or an exact value is off); reflected is "
                                  "not checked (always 0)", flag=True),
}
REQUIRED_VARIABLES = tuple(name for name, v in VARIABLES.items() if v.required)

# The labelled axes: name -> (labels, long name)
LABELS = {
    "component": (("direct", "albedo", "reflected"), "irradiance component: direct Sun, Earth albedo, or Sun and "
                  "Earth light reflected by the spacecraft (the total is their sum; reflected is not checked against "
                  "the analytic model)"),
    "xyz": (("x", "y", "z"), "Cartesian axis"),
    "statistic": (("value", "se", "dof"), "estimate, its standard error, their effective degrees of freedom"),
    "quat": (("w", "x", "y", "z"), "quaternion component, scalar first"),
}

# The arrays of a finished chunk (PreparedRun.render_chunk), n epochs x K diodes; a partial run whose chunks lack
# one was written by an older sunsim and cannot be resumed by this one
CHUNK_ARRAYS = {
    "rendered": "(n, K, 3) rendered direct, albedo and reflected irradiance",
    "rendered_se": "(n, K, 3) their standard errors",
    "rendered_dof": "(n, K, 3) their effective degrees of freedom",
    "samples": "(n, K, 3) rays traced",
    "direct_plain": "(n, K, 3) the hint-free direct estimate: value, standard error, degrees of freedom",
    "analytic": "(n, K, 2) the analytic direct Sun and the box-only albedo on the native map",
    "analytic_albedo_refined": "(n, K) the reference albedo on the refined map",
    "analytic_albedo_native_mesh": "(n, K) the albedo with the traced visible shares on the native map",
    "albedo_mesh": "(n, K) the reference albedo through directions where shadows cross the diode",
    "albedo_visibility_error": "(n, K) the estimated error of the traced visible shares",
    "direct_unchecked": "(n, K) bool: direct Sun without an exact reference",
    "direct_unchecked_window": "(n, K) bool: of them, a window's",
    "valid": "(n,) bool: orbit and rendering valid",
}


def values(ds, name):
    """Return the values of the run file variable ``name`` in ``ds``; for a file written before the variable
    existed, its ``absent`` value in its shape."""
    v = VARIABLES[name]
    if name in ds or v.absent is None:
        return ds[name].values
    return np.full(tuple(ds.sizes[d] if d in ds.sizes else len(LABELS[d][0]) for d in v.dims), v.absent)


def chunk_arrays_of(ds, names):
    """Return the chunk arrays ``names`` read back from the run Dataset ``ds`` (the variables that store them)."""
    stored = {v.chunk: name for name, v in VARIABLES.items() if v.chunk}
    return {c: values(ds, stored[c]).astype(bool) if VARIABLES[stored[c]].flag else values(ds, stored[c])
            for c in names}


CHECKSUMS_ATTR = "checksums"


def _digest(values):
    a = np.ascontiguousarray(values)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()[:32]


def _numeric(ds):
    return [name for name in sorted(ds.data_vars) if ds[name].dtype.kind in "biuf"]


def add_checksums(ds):
    """Set ``ds.attrs['checksums']`` (JSON: variable name -> digest of each numeric variable); return ``ds``."""
    ds.attrs[CHECKSUMS_ATTR] = json.dumps({name: _digest(ds[name].values) for name in _numeric(ds)}, sort_keys=True)
    return ds


def verify_checksums(ds, path, note=None):
    """Return ``ds`` if its variables match the checksums it carries; raise InvalidInputError naming the first
    that does not. A file without checksums (older sunsim) is returned after a note (``note``: a function of
    one line; default: printed on stderr)."""
    stored = ds.attrs.get(CHECKSUMS_ATTR)
    if stored is None:
        (note or (lambda m: print(m, file=sys.stderr)))(
            f"note: {path} carries no checksums (written by a sunsim before they were added): its variables "
            "are used unverified")
        return ds
    try:
        stored = json.loads(stored)
    except ValueError:
        raise InvalidInputError(f"{path}: its checksums attribute is unreadable, so the file cannot be verified; "
                                "render it again with the same 'sunsim run' command") from None
    for name, digest in sorted(stored.items()):
        if name not in ds:
            raise InvalidInputError(f"{path}: the variable {name} is missing although the file's checksums list it: "
                                    "the file is damaged; render it again with the same 'sunsim run' command")
        if _digest(ds[name].values) != digest:
            raise InvalidInputError(f"{path}: the variable {name} does not match its checksum (zeroed, cut short or "
                                    "changed since sunsim wrote it): the file is damaged; render it again with the "
                                    "same 'sunsim run' command")
    return ds


def write_netcdf(ds, path):
    """Write ``ds`` to ``path`` as netCDF-4 (h5netcdf): the bytes of ``ds.to_netcdf(path, engine="h5netcdf")``
    without its look for a Dask scheduler, which imports dask.distributed (0.10 s of every run) to choose a
    lock: the arrays here are numpy, written by this thread, under xarray's HDF5 lock as that call takes it."""
    from xarray.backends import H5NetCDFStore
    from xarray.backends.locks import HDF5_LOCK
    store = H5NetCDFStore.open(path, mode="w", lock=HDF5_LOCK)
    try:
        ds.dump_to_store(store)
    finally:
        store.close()


def size_bound(ds):
    """Return an upper bound (bytes) of ``ds`` written as netCDF-4 without compression: its arrays, its attributes
    and 8 KiB of HDF5 metadata per variable plus 64 KiB (a 4-epoch run file: 58 kB written, this bound 0.4 MB)."""
    attrs = sum(len(str(v)) for v in ds.attrs.values())
    return int(ds.nbytes) + attrs + 8192 * len(ds.variables) + 65536


def writer(study):
    """Return who writes ``study``'s chunks: {"sunsim": version, "variant": the Mitsuba variant it renders with}."""
    return {"sunsim": __version__, "variant": study.variant}


def software_versions():
    """Return the versions of sunsim and of the libraries that decide a run's numbers."""
    from simcore import _llvm
    drjit, mitsuba = _llvm.import_drjit(), _llvm.import_mitsuba()
    import platform
    import sgp4
    import erfa
    return {"sunsim": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "mitsuba": mitsuba.__version__, "drjit": drjit.__version__, "sgp4": sgp4.__version__,
            "pyerfa": erfa.__version__}


@functools.lru_cache(maxsize=1)
def git_commit():
    """Return the git commit sunsim runs from (with '-dirty' for local changes), or '' outside a checkout."""
    import subprocess
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        out = subprocess.run(["git", "-C", here, "describe", "--always", "--dirty", "--abbrev=12"],
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _tle_age_days(study):
    """Return the days from the TLE epoch to the run's first epoch (negative: before the epoch; NaN without a TLE)."""
    if not hasattr(study.orbit, "satrec"):
        return float("nan")
    sat = study.orbit.satrec
    return (study.epochs.jd1[0] - sat.jdsatepoch) + (study.epochs.jd2[0] - sat.jdsatepochF)


def _with_reflected(data):
    """Return the chunk arrays with a third, ``reflected`` component (zeros, exact) where they have only direct
    and albedo (run files written before the renderer traced reflections: all surfaces black)."""
    if data["rendered"].shape[-1] == 3:
        return data
    out = dict(data)
    for key, fill in (("rendered", 0.0), ("rendered_se", 0.0), ("rendered_dof", np.inf), ("samples", 0)):
        a = np.asarray(data[key])
        out[key] = np.concatenate([a, np.full(a.shape[:-1] + (1,), fill, dtype=a.dtype)], axis=-1)
    return out


def _variable(name, value, **fields):
    """Return the (dims, values, attributes) of the run file variable ``name`` holding ``value``."""
    v = VARIABLES[name]
    return v.dims, np.asarray(value, np.int8) if v.flag else value, v.attrs(**fields)


def build_dataset(study, data, variant):
    """Return (the run's xarray Dataset, its check report) from the concatenated chunk arrays ``data`` of the
    prepared run ``study`` (:class:`simcore.pipeline.run.PreparedRun`)."""
    o, g, cfg = study.opts, study.geometry, study.config
    n, k = data["rendered"].shape[:2]
    data = _with_reflected(data)
    # Richardson: the same integrand (the traced visible shares where shadows cross the diodes) on the native
    # and the refined cells; the model's box-only albedo would fold the shares' effect into the estimate
    bound = _check.discretisation_bound(data["analytic_albedo_native_mesh"], data["analytic_albedo_refined"],
                                        study.check_refine)
    # the analytic model's surfaces are black: it reflects nothing; the check has no reference for it (NaN)
    analytic = np.concatenate([data["analytic"][..., :2], np.zeros((n, k, 1))], axis=-1)
    analytic_ref = np.stack([analytic[..., 0], data["analytic_albedo_refined"], np.full((n, k), np.nan)], axis=-1)
    scale = study.sun_scale(slice(0, n))
    vals = {name: data[v.chunk] for name, v in VARIABLES.items() if v.chunk}
    vals.update({
        "analytic": analytic, "analytic_reference": analytic_ref, "albedo_discretisation_bound": bound,
        "sun_dir_body": g.sun_dir_body, "sun_scale": scale, "sun_dir_gcrs": g.sun_dir_gcrs,
        "r_sat_gcrs": g.r_sat_gcrs_m, "r_sat_ecef": g.r_sat_ecef_m, "illumination": g.illumination,
        "sunlit_cylindrical": g.sunlit_cylindrical, "q_gcrs_from_body": study.attitude.q_gcrs_from_body,
        "normal_body": cfg.normals, "fov_deg": cfg.fov_deg, "dead": cfg.dead,
        "sun_normal_irradiance": o.e_sun_w_m2 * scale * g.illumination,
    })
    coords = {
        "time": ("time", g.epochs.datetime64, {"long_name": "epoch, UTC", "standard_name": "time",
                                               "time_zone": "UTC"}),
        "t_s": ("time", g.t_s, {"units": "s", "long_name": "seconds since the first epoch"}),
        "diode": ("diode", np.arange(k), {"units": "1", "long_name": "diode index"}),
        "diode_name": ("diode", np.array([d.name for d in cfg.diodes], dtype=object),
                       {"long_name": "diode name in the configuration"}),
        **{dim: (dim, np.array(labels, dtype=object), {"long_name": text}) for dim, (labels, text) in LABELS.items()},
    }
    ds = xr.Dataset({name: _variable(name, vals[name], refine=study.check_refine)
                     for name in VARIABLES if name != "outlier"}, coords=coords)
    ds = _schedule.annotate(ds, study.plan)
    tle = f"{study.orbit.line1}\n{study.orbit.line2}" if hasattr(study.orbit, "line1") else ""
    cfg_text = Path(cfg.source).read_text() if cfg.source and os.path.isfile(cfg.source) else ""
    ds.attrs.update({
        "title": TITLE,
        "conventions": "time leads; frames named in each variable; SI units",
        "configuration": cfg.name,
        "configuration_toml": cfg_text,
        "satellite": study.orbit.name or "",
        "norad_id": -1 if study.orbit.norad_id is None else int(study.orbit.norad_id),
        "tle": tle,
        "orbit_source": "TLE" if tle else f"CCSDS OEM {o.orbit_file} (sha256 {study.orbit.sha256})",
        "reflectivity_map": study.map.name,
        "seed": int(o.seed),
        "reflected_samples": int(o.reflected_samples),
        "variant": variant,
        "options": json.dumps(o.spec(), sort_keys=True),
        "software": json.dumps(software_versions(), sort_keys=True),
        "e_sun_w_m2": study.opts.e_sun_w_m2,
        "period_s": float(orbital_period_s(study.orbit)),
        "tle_age_days": float(_tle_age_days(study)),
        "warnings": "\n".join(study.notes),
        "time_scale": "UTC",
        "created_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command_line": shlex.join([os.path.basename(sys.argv[0]) or "python"] + sys.argv[1:]),
        "sunsim_version": __version__ + (f" (git {git_commit()})" if git_commit() else ""),
    })
    if study.clouds is not None:
        ds.attrs.update(study.clouds.attrs(o.clouds))
    if study.glint is not None:
        ds.attrs.update(study.glint.attrs())
    flags, report = check_run(ds)
    ds["outlier"] = _variable("outlier", np.stack([flags["direct"], flags["albedo"], np.zeros_like(flags["direct"])],
                                                  axis=-1))
    ds.attrs["check"] = json.dumps(report, sort_keys=True)
    ds.attrs["check_pass"] = int(report["pass"])
    return ds, report


def options_digest(path):
    """Return the settings digest of a finished run file, or None if it is not a readable run file."""
    import h5py
    try:
        with h5py.File(path, "r") as f:         # the attributes only: a day's run file holds ~1 GB of arrays
            options = f.attrs.get("options")
    except OSError:
        return None
    if options is None:
        return None
    return spec_digest(json.loads(options.decode() if isinstance(options, bytes) else str(options)))


def open_run(path, note=None):
    """Return the Dataset of a finished run file, or raise a UserError saying why not (note: verify_checksums's)."""
    if not os.path.exists(path):
        raise InputNotFoundError(f"no run file at {path}")
    if os.path.isdir(path):
        raise InvalidInputError(f"{path} is a folder, not a run file (.nc); a folder ending in .partial is an "
                         "unfinished run: finish it by running the same 'sunsim run' command again")
    try:
        ds = xr.load_dataset(path, engine="h5netcdf")      # in memory, file closed
    except Exception as exc:  # h5py/netCDF raise many types for a corrupt file
        raise InvalidInputError(f"{path} is not a readable netCDF run file ({type(exc).__name__}: {exc}); "
                         "was it written by 'sunsim run'?") from None
    missing = [v for v in REQUIRED_VARIABLES if v not in ds]
    if ds.attrs.get("title") != TITLE or missing:
        raise InvalidInputError(f"{path} is not a sunsim run file (missing {', '.join(missing) or 'its sunsim title'}); "
                         "give a file written by 'sunsim run'")
    return verify_checksums(ds, path, note)


def check_run(ds):
    """Return (flags, report): the analytic check (:mod:`simcore.pipeline.check`) recomputed from a run
    Dataset's arrays."""
    n, k = ds.sizes["time"], ds.sizes["diode"]
    cos_inc = np.clip(np.einsum("nj,kj->nk", ds["sun_dir_body"].values, ds["normal_body"].values), 0.0, None)
    scale = float(ds.attrs.get("e_sun_w_m2", E_SUN_W_M2)) * ds["sun_scale"].values[:, None]
    irr, se, ref = ds["irradiance"].values, ds["irradiance_se"].values, ds["analytic_reference"].values
    dof = values(ds, "irradiance_dof")
    valid = np.broadcast_to(ds["valid"].values.astype(bool)[:, None], (n, k))
    masked = lambda a: np.where(valid, a, np.nan)  # noqa: E731
    # the direct Sun where extra parts may shadow it: no analytic reference (reported as unchecked)
    parts = values(ds, "direct_unchecked").astype(bool)
    masked_direct = lambda a: np.where(valid & ~parts, a, np.nan)  # noqa: E731
    bound = ds["albedo_discretisation_bound"].values
    samples = ds["samples"].values
    components = {
        "direct": (masked_direct(irr[..., 0]), se[..., 0], dof[..., 0], samples[..., 0], ref[..., 0], 0.0),
        "albedo": (masked(irr[..., 1]), se[..., 1], dof[..., 1], samples[..., 1], ref[..., 1], bound ** 2),
    }
    if "albedo_visibility_error" in ds:
        components["albedo"] = components["albedo"][:5] + (bound ** 2 + ds["albedo_visibility_error"].values ** 2,)
    if "direct_plain" in ds:
        plain = ds["direct_plain"].values
        # the hint-free estimate always takes the run's first-round count (no target accuracy)
        n_plain = max(json.loads(ds.attrs["options"]).get("direct_samples", 1024), _check.PLAIN_CHECK_SAMPLES)
        components["direct_plain"] = (masked_direct(plain[..., 0]), plain[..., 1], plain[..., 2],
                                      np.where(samples[..., 0] > 0, n_plain, 0), ref[..., 0], 0.0)
    flags, report = _check.compare(components, k, scale, scale * cos_inc)
    if ds.sizes["component"] > 2:
        refl = masked(irr[..., 2])
        report["reflected_unchecked"] = int(np.count_nonzero(refl > 0))
    report["direct_unchecked"] = int(np.count_nonzero(parts & valid))
    if "direct_unchecked_window" in ds:
        report["direct_unchecked_window"] = int(np.count_nonzero(ds["direct_unchecked_window"].values.astype(bool)
                                                                 & valid))
    if "albedo_mesh" in ds:
        report["albedo_mesh_quadrature"] = int(np.count_nonzero((ds["albedo_mesh"].values > 0)
                                                                & (ref[..., 1] > _check.ALBEDO_FLOOR_W_M2) & valid))
    # In the Earth's shadow every value is 0 and agrees trivially: a span without Sun has checked nothing.
    report["sunlit_epochs"] = int(np.count_nonzero(ds["valid"].values.astype(bool) & (ds["illumination"].values > 0)))
    if report["sunlit_epochs"] == 0:
        report["pass"] = False
        report["verdict"] = "no sunlit data"
    else:
        report["verdict"] = "PASS" if report["pass"] else "FAIL"
    return flags, report


def options_of(ds, path):
    """Return the RunOptions a run file was made with (from its 'options' attribute)."""
    spec = json.loads(ds.attrs["options"])
    names = {f.name for f in dataclasses.fields(RunOptions)}
    kw = _schedule.explicit_options({k: v for k, v in spec.items() if k in names}, ds)
    for k in ("dead", "spin_axis"):
        if k in kw:
            kw[k] = tuple(kw[k])
    # files written before the solar flux was an option used the thesis' constant 1366.1 W/m^2
    kw.setdefault("e_sun_w_m2", E_SUN_W_M2)
    kw.setdefault("distance_scaling", False)
    return RunOptions(**kw, output=path)
