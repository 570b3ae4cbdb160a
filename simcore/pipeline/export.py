"""A run's readings and attitude out, for test benches and other simulators: ``sunsim export RUN.nc --format ...``.

* ``csv``: one row per epoch, per diode the rendered irradiance (direct, albedo, reflected and their total,
  W/m^2), the photocurrent (A) and the ADC counts of the sensor chain (:class:`simcore.sensor.chain.SensorChain`,
  built as ``sunsim estimate`` builds it: the run's total irradiance, the named diode part, optional noise with
  a seed), so that a hardware test bench can replay them.
* ``aem``: the run's attitude as a CCSDS AEM 2.0 (KVN): GCRF -> SC_BODY_1, A2B, scalar first
  (:func:`simcore.environment.ccsds.write_aem`).
* ``oem``: the run's orbit as a CCSDS OEM 2.0 (KVN, EME2000, Lagrange of degree 7) at the run's epochs, its TLE
  propagated again (the run file keeps positions, not velocities); ``sunsim run --orbit`` reads it back.
* ``basilisk``: the readings in the convention of Basilisk's ``coarseSunSensor`` (its ``CSSArraySensorMsg``
  ``CosValue``), so that a Basilisk simulation can replay sunsim's traced readings in place of its own.

Basilisk's convention (src/simulation/sensors/coarseSunSensor/coarseSunSensor.cpp, ``computeTrueOutput``;
src/simulation/environment/albedo/albedo.cpp, ``computeAlbedo``): a sensor reads
``cos(angle to the Sun) x (1 AU / r_sun)^2 x shadowFactor + albedoAtInstrument`` (times its scaleFactor,
1 here), where 1.0 is the Sun on the normal at 1 AU, and ``albedoAtInstrument`` is the Earth's light on the
sensor as a ratio to the solar flux *at the instrument* (not at 1 AU: Basilisk adds it without the distance
factor). So, with E the run's irradiance, E_1AU the run's solar irradiance at 1 AU (``e_sun_w_m2``) and
``sun_scale`` the run's factor on it ((1 AU / r)^2 with distance scaling, else 1):

    direct = E_direct / E_1AU                        (= cos x (1 AU / r)^2 x illumination for a bare diode)
    albedo = E_albedo / (E_1AU x sun_scale)          (Basilisk's albedoAtInstrument)
    reflected = E_reflected / E_1AU                  (sunlight the spacecraft reflects; Basilisk has none:
                                                      it scales with the Sun as the direct part does)
    cos_value = direct + albedo + reflected

sunsim's diodes are not bare: the values carry the aperture, the field-of-view cut, shadows and reflections
that the renderer traced, which is the point of replaying them.
"""
import csv
import os
import sys

import numpy as np

from simcore.environment import ccsds
from simcore.environment.epochs import Epochs
from simcore.errors import InvalidInputError
from simcore.pipeline.runfile import open_run
from simcore.pipeline.store import atomic_write, check_writable

FORMATS = ("csv", "aem", "oem", "basilisk")
SUFFIX = {"csv": "_readings.csv", "aem": ".aem", "oem": ".oem", "basilisk": "_basilisk.csv"}


# what a format reads beyond open_run's REQUIRED_VARIABLES: (variables, attributes)
NEEDS = {"csv": (("time", "t_s", "diode_name"), ()), "aem": (("time", "diode_name"), ()),
         "oem": (("time", "diode_name"), ()), "basilisk": (("time", "t_s", "diode_name"), ("e_sun_w_m2",))}


def check_contents(ds, run_path, fmt):
    """Raise InvalidInputError if the run Dataset ``ds`` lacks a variable or attribute that ``fmt`` writes (a file
    edited after sunsim wrote it, or written by an older sunsim without checksums to tell)."""
    variables, attrs = NEEDS[fmt]
    missing = [v for v in variables if v not in ds.variables] + [f"attribute {a}" for a in attrs if a not in ds.attrs]
    if missing:
        raise InvalidInputError(f"{run_path} lacks {', '.join(missing)}, which --format {fmt} needs; export a run "
                                "file as 'sunsim run' writes it (render it again)")


def default_output(run_path, fmt):
    """Return the export's path beside the run file: RUN_readings.csv, RUN.aem, RUN.oem or RUN_basilisk.csv."""
    stem = run_path[:-3] if run_path.endswith(".nc") else run_path
    return stem + SUFFIX[fmt]


def _components(ds):
    irr = ds["irradiance"]
    return {c: irr.sel(component=c).values for c in ("direct", "albedo", "reflected")}


def basilisk_values(ds):
    """Return {'direct', 'albedo', 'reflected', 'cos_value'}: (N, K) each, in Basilisk's CSS convention
    (module docstring) of a run Dataset."""
    e_1au = float(ds.attrs["e_sun_w_m2"])
    scale = ds["sun_scale"].values[:, None]
    c = _components(ds)
    out = {"direct": c["direct"] / e_1au, "albedo": c["albedo"] / (e_1au * scale),
           "reflected": c["reflected"] / e_1au}
    out["cos_value"] = out["direct"] + out["albedo"] + out["reflected"]
    return out


def readings(ds, *, diode="BPW34FS", noise=False, seed=0):
    """Return {'total', 'direct', 'albedo', 'reflected' (W/m^2), 'current_a', 'counts'}: (N, K) each, the run's
    irradiance through the sensor chain as ``sunsim estimate`` builds it (dead diodes read 0)."""
    from simcore.sensor.chain import DIODES, SensorChain
    if diode not in DIODES:
        raise InvalidInputError(f"--diode {diode} is unknown; use one of {', '.join(sorted(DIODES))}")
    if not 0 <= int(seed) < 2 ** 64:
        raise InvalidInputError(f"--seed must be a whole number from 0 to 2^64-1, got {seed}")
    c = _components(ds)
    total = c["direct"] + c["albedo"] + c["reflected"]
    dead = tuple(int(k) for k in np.flatnonzero(ds["dead"].values.astype(bool)))
    chain = SensorChain(diode=diode, dead=dead, noise=noise, seed=seed)
    current = chain.current_a(total)
    counts = chain.counts_from_current(current)
    if dead:
        counts[:, list(dead)] = 0.0
    return {"total": total, **c, "current_a": current, "counts": counts}


def _time_columns(ds):
    epochs = Epochs.from_datetime64(ds["time"].values)
    return {"time_utc": ccsds.format_epochs(epochs), "t_s": ds["t_s"].values,
            "valid": ds["valid"].values.astype(int), "illumination": ds["illumination"].values}


def _write_table(path, comments, columns):
    names = list(columns)
    n = len(next(iter(columns.values())))

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            for line in comments:
                fh.write(f"# {line}\n")
            w = csv.writer(fh)
            w.writerow(names)
            for i in range(n):
                w.writerow([_cell(columns[k][i]) for k in names])
    atomic_write(path, write)


def _cell(v):
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def _per_diode(columns, prefix, values):
    for k in range(values.shape[1]):
        columns[f"{prefix}_d{k}"] = values[:, k]


def _write_orbit(ds, path, head):
    from simcore.environment.ephemeris import write_orbit_oem
    from simcore.environment.orbit import Orbit
    lines = str(ds.attrs.get("tle", "")).splitlines()
    if len(lines) != 2:
        raise InvalidInputError(f"this run's orbit is not a TLE ({ds.attrs.get('orbit_source', 'unknown')}); its "
                                "ephemeris file is already the OEM to give 'sunsim run --orbit'")
    if ds.sizes["time"] < 8:
        raise InvalidInputError(f"the run has {ds.sizes['time']} epochs; an OEM interpolated with Lagrange of degree 7 "
                                "needs at least 8 states: export a longer run")
    orbit = Orbit.from_tle(*lines, name=ds.attrs.get("satellite") or None)
    atomic_write(path, lambda tmp: write_orbit_oem(tmp, orbit, Epochs.from_datetime64(ds["time"].values),
                                                   frame="EME2000", degree=7))


def export(run_path, fmt, output=None, *, diode="BPW34FS", noise=False, seed=0):
    """Write the run's export in ``fmt`` (:data:`FORMATS`) to ``output`` (default :func:`default_output`);
    return the path. Every input is checked before anything is written."""
    if fmt not in FORMATS:
        raise InvalidInputError(f"--format {fmt} is unknown; use one of {', '.join(FORMATS)}")
    notes = []                              # an older file's note printed only if the file is then used
    ds = open_run(run_path, note=notes.append)
    check_contents(ds, run_path, fmt)
    for line in notes:
        print(line, file=sys.stderr)
    path = output or default_output(os.fspath(run_path), fmt)
    check_writable(path)
    head = [f"sunsim export of {os.path.abspath(run_path)} ({ds.attrs.get('configuration', '')}, "
            f"{ds.sizes['time']} epochs x {ds.sizes['diode']} diodes)",
            f"diodes: {', '.join(str(n) for n in ds['diode_name'].values)}",
            "normals (body frame): " + "; ".join(" ".join(f"{x:.9f}" for x in n) for n in ds["normal_body"].values)]
    if fmt == "oem":
        _write_orbit(ds, path, head)
        return path
    if fmt == "aem":
        epochs = Epochs.from_datetime64(ds["time"].values)
        atomic_write(path, lambda tmp: ccsds.write_aem(
            tmp, epochs, ds["q_gcrs_from_body"].values, frame="GCRF", direction="body_to_frame",
            object_name=ds.attrs.get("satellite") or "SATELLITE",
            object_id=str(ds.attrs["norad_id"]) if int(ds.attrs.get("norad_id", -1)) >= 0 else "UNKNOWN", comment=head))
        return path
    cols = _time_columns(ds)
    if fmt == "csv":
        r = readings(ds, diode=diode, noise=noise, seed=seed)
        for prefix, key in (("E_W_m2", "total"), ("E_direct_W_m2", "direct"), ("E_albedo_W_m2", "albedo"),
                            ("E_reflected_W_m2", "reflected"), ("photocurrent_A", "current_a"),
                            ("adc_counts", "counts")):
            _per_diode(cols, prefix, r[key])
        head.append(f"sensor chain: diode {diode}, noise {'on, seed ' + str(seed) if noise else 'off'} "
                    "(simcore/sensor/chain.py; as 'sunsim estimate'); dead diodes read 0 counts")
    else:
        b = basilisk_values(ds)
        for key in ("cos_value", "direct", "albedo", "reflected"):
            _per_diode(cols, key, b[key])
        cols["sim_nanos"] = np.round(ds["t_s"].values * 1e9).astype(np.int64)
        head.append("Basilisk coarseSunSensor convention (CSSArraySensorMsg CosValue): 1.0 = the Sun on the normal at "
                    "1 AU; direct x (1 AU/r)^2 x shadow, albedo as a ratio to the solar flux at the instrument "
                    f"(simcore/pipeline/export.py); E at 1 AU = {float(ds.attrs['e_sun_w_m2']):g} W/m^2")
    _write_table(path, head, cols)
    return path
