"""Parameter sweeps on Dask: configurations x start dates x spin rates x seeds (x cloud-weather seeds).

Every point of the sweep is an ordinary resumable run (:mod:`simcore.pipeline.run`)
writing its own file under ``<folder>/runs/``; Dask only schedules them. A
local cluster is started by default; give a scheduler address to scale out
(the workers need sunsim installed and the sweep folder on a shared file
system). Started again, a sweep skips finished runs and resumes unfinished
ones from their last chunk. The results land in one dataset,
``<folder>/sweep.nc``, with a ``run`` dimension (a ``step`` axis with ``t_s``, the
seconds since each run's start; diodes and steps padded with NaN to the
largest run). Cloud seeds (``clouds``, :mod:`simcore.environment.clouds`) are one more axis: one run per
realisation of the weather, so that error distributions over weather come out (``cloud_seed`` along
``run``).
"""
import dataclasses
import itertools
import json
import os

import numpy as np
import xarray as xr

from scenes.config import SatelliteConfig
from simcore.environment.epochs import Epochs

from simcore.pipeline.run import execute
from simcore.pipeline.runfile import open_run, write_netcdf
from simcore.pipeline.store import atomic_write, spec_digest


def sweep_points(base, configs, starts, spin_rates, seeds, folder, clouds=(None,)):
    """Return the RunOptions of every sweep point (their outputs under ``folder/runs``); ``clouds``: the
    cloud-weather seeds (None: the map as it is)."""
    points = []
    for config, start, rate, seed, cloud in itertools.product(configs, starts, spin_rates, seeds, clouds):
        opts = dataclasses.replace(base, config=config, start=start, spin_rate_deg_s=float(rate), seed=int(seed),
                                   clouds=None if cloud is None else int(cloud))
        name = f"{os.path.splitext(os.path.basename(config))[0]}_{spec_digest(opts.spec())}.nc"
        points.append(dataclasses.replace(opts, output=os.path.join(folder, "runs", name)))
    return points


def _run_point(opts):
    """Execute one sweep point (in a Dask worker) and return its output path and check report."""
    if os.path.exists(opts.output):
        return opts.output, json.loads(open_run(opts.output).attrs["check"])
    path, _, report = execute(opts, progress=False)
    return path, report


def run_sweep(points, *, scheduler=None, workers=2, log=print):
    """Run the sweep points on Dask; return their (path, report) in order."""
    from simcore.pipeline.cluster import run_tasks
    todo = [p for p in points if not os.path.exists(p.output)]
    log(f"sweep: {len(points)} runs, {len(points) - len(todo)} already finished")
    if not todo:
        return [_run_point(p) for p in points]

    def done(_, result):
        path, report = result
        log(f"  done {os.path.basename(path)}: check {'PASS' if report['pass'] else 'FAIL'}")
    run_tasks(_run_point, [(p,) for p in todo], scheduler=scheduler, workers=workers, on_done=done, what="run")
    return [_run_point(p) for p in points]


def combine(points, out_path):
    """Write the sweep's runs as one Dataset with a ``run`` dimension to ``out_path``; return it."""
    runs = [open_run(p.output) for p in points]
    k_max = max(r.sizes["diode"] for r in runs)
    n_max = max(r.sizes["time"] for r in runs)
    per_run = ("irradiance", "irradiance_se", "analytic", "analytic_reference", "illumination", "sun_dir_body",
               "normal_body", "fov_deg", "dead", "t_s")
    parts = []
    for r in runs:
        r = r.reset_coords("t_s")[[v for v in per_run if v in r or v == "t_s"]]
        r = r.drop_vars([c for c in ("time", "diode_name") if c in r.variables]).rename(time="step")
        parts.append(r.reindex(diode=np.arange(k_max)).assign_coords(step=np.arange(r.sizes["step"])))
    ds = xr.concat(parts, dim="run", join="outer").reindex(step=np.arange(n_max))
    ds.attrs = {}
    ds["dead"] = ds["dead"].fillna(1).astype(np.int8)   # a padded diode slot is no live diode
    reports = [json.loads(r.attrs["check"]) for r in runs]
    ds = ds.assign_coords(
        run=np.arange(len(points)),
        config=("run", np.array([r.attrs["configuration"] for r in runs], dtype=object)),
        start=("run", np.array([p.start for p in points], dtype=object)),
        spin_rate_deg_s=("run", np.array([p.spin_rate_deg_s for p in points])),
        seed=("run", np.array([p.seed for p in points])),
        **({"cloud_seed": ("run", np.array([p.clouds for p in points], dtype=np.uint64))}
           if all(p.clouds is not None for p in points) else {}),
        file=("run", np.array([os.path.basename(p.output) for p in points], dtype=object)),
    )
    ds["check_pass"] = ("run", np.array([int(r["pass"]) for r in reports], np.int8))
    ds["check_failed_tests"] = ("run", np.array([sum(not t["passed"] for t in r["tests"]) for r in reports]))
    ds.attrs.update({"title": "sunsim sweep", "runs": len(points),
                     "options": json.dumps(dataclasses.asdict(points[0]), default=str)})

    def write(tmp):
        write_netcdf(ds, tmp)
    atomic_write(out_path, write)
    return ds


def sweep(base, configs, starts, spin_rates, seeds, folder, *, clouds=(None,), scheduler=None, workers=2,
          log=print):
    """Run a whole sweep into ``folder`` and return (path of sweep.nc, Dataset); ``clouds``: cloud-weather
    seeds, one more axis (None: the map as it is)."""
    for name, values in (("configs", configs), ("starts", starts), ("spin rates", spin_rates), ("seeds", seeds),
                         ("cloud seeds", clouds)):
        if not values:
            raise ValueError(f"a sweep needs at least one value for {name}")
    for c in configs:          # fail here, with the user's words, rather than inside a worker
        SatelliteConfig.load(c)
    Epochs.from_any(list(starts))
    os.makedirs(os.path.join(folder, "runs"), exist_ok=True)
    points = sweep_points(base, configs, starts, spin_rates, seeds, folder, clouds=clouds)
    run_sweep(points, scheduler=scheduler, workers=workers, log=log)
    out = os.path.join(folder, "sweep.nc")
    if os.path.exists(out):
        os.remove(out)
    return out, combine(points, out)
