"""Benchmark a whole ``sunsim run`` against the renderer alone, on the default study.

What ``sunsim run`` does by default (ESTCube-1, one orbit at 1 s from 2016-07-02T00:00Z, the
tilt20_fov70 satellite, finite solar disc, TOMS 2005, adaptive accuracy 0.2 % / 1 %): render,
the analytic reference and check, and the netCDF file, timed through the command itself
(``simcore.cli.main``). Beside it, in the same process and on the same study, the renderer
alone: building it and rendering every chunk, nothing else. Their ratio is what the check,
the orbit set-up and the writing cost on top of the rendering.

    .venv/bin/python benchmarks/bench_run.py [--duration S] [--repeat N]

Last line: one JSON object with run_ms_per_epoch, render_ms_per_epoch and ratio, and the machine's
1-minute load average when it started. On a shared 2-core machine another process on the cores moves
the ratio by up to +-0.4 from one measurement to the next (it slows one figure and not the other):
``--repeat N`` makes the same measurement N times, each in a fresh process (both figures as cold as
in one), and its last line holds the medians (the ratio: the median of the N ratios) and every ratio.

Imports are in neither figure: simcore's, Mitsuba's and Dr.Jit's happen before the timing, and so do the
ones xarray makes lazily when the run builds and writes its dataset (with dask installed, as by the test
and sweep extras, xarray imports dask and distributed to look for dask arrays and schedulers: ~0.65 s once
per process, 0.11 ms per epoch of a one-orbit run, that a plain install does not pay). The benchmark makes
them first by writing a two-value dataset the way the run writes its file, and prints how long they took.
"""
import argparse
import contextlib
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from simcore.cli import build_parser, main, run_options
from simcore.pipeline.run import PreparedRun
from simcore.pipeline.store import chunk_ranges


def main_bench(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=None, help="seconds of orbit (default: one period)")
    ap.add_argument("--repeat", type=int, default=1, help="measurements, each in a fresh process (default 1)")
    a = ap.parse_args(argv)
    if a.repeat > 1:
        return repeated(a)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t_imports = lazy_imports(tmp)
        run_args = ["run", "-o", os.path.join(tmp, "run.nc")]
        if a.duration is not None:
            run_args += ["--duration", str(a.duration)]
        opts = run_options(build_parser().parse_args(run_args))
        # the renderer alone (its scene and visibility tables included), chunk by chunk as the run does
        t0 = time.perf_counter()
        st = PreparedRun(opts)
        t1 = time.perf_counter()
        g = st.geometry
        for start, stop in chunk_ranges(len(g), opts.chunk_epochs):
            sl = slice(start, stop)
            st.renderer.render(g.sun_dir_body[sl], g.earth_center_body_m[sl], g.R_ecef_from_body[sl],
                               st.sun_scale(sl), sun_dir_earth_body=st.earth_sun_dir_body(sl),
                               earth_sun_scale=st.earth_sun_scale(sl), seed=opts.seed, epoch_offset=start,
                               direct_samples=opts.direct_samples, albedo_samples=opts.albedo_samples,
                               rel_se_direct=opts.rel_se_direct, rel_se_albedo=opts.rel_se_albedo)
        t_render = time.perf_counter() - t1
        n = len(g)
        # the whole command
        t2 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()) as out:
            rc = main(run_args)
        t_run = time.perf_counter() - t2
    print(f"default study: {n} epochs x 14 diodes (set-up of the study {t1 - t0:.1f} s, not in either figure)")
    print(f"sunsim run:      {t_run:7.1f} s = {1e3 * t_run / n:6.2f} ms per epoch (exit {rc}; "
          f"{out.getvalue().splitlines()[2].strip() if len(out.getvalue().splitlines()) > 2 else ''})")
    print(f"renderer alone:  {t_render:7.1f} s = {1e3 * t_render / n:6.2f} ms per epoch")
    print(f"ratio run / render: {t_run / t_render:.2f}")
    print(f"load average (1 min) at the start: {load_before:.2f} on {os.cpu_count()} cores; "
          f"xarray's lazy imports {t_imports:.2f} s, before both")
    print(json.dumps({"epochs": n, "run_ms_per_epoch": round(1e3 * t_run / n, 3),
                      "render_ms_per_epoch": round(1e3 * t_render / n, 3), "ratio": round(t_run / t_render, 3),
                      "load_at_start": round(load_before, 2)}))


def lazy_imports(tmp):
    """Return the seconds it takes to make the imports xarray makes lazily the first time it builds and writes a
    dataset (see the module's docstring), made here by writing a two-value dataset as the run writes its file."""
    import numpy as np
    import xarray as xr
    t0 = time.perf_counter()
    xr.Dataset({"x": ("t", np.zeros(2))}).to_netcdf(os.path.join(tmp, "imports.nc"), engine="h5netcdf")
    return time.perf_counter() - t0


def repeated(a):
    """Make the measurement ``a.repeat`` times, each in a fresh process; print each and the medians."""
    results = []
    for i in range(a.repeat):
        cmd = [sys.executable, os.path.abspath(__file__)]
        cmd += [] if a.duration is None else ["--duration", str(a.duration)]
        out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
        results.append(json.loads(out.strip().splitlines()[-1]))
        print(f"measurement {i + 1}/{a.repeat}: " + " | ".join(out.strip().splitlines()[1:4]), flush=True)
    med = {k: statistics.median(r[k] for r in results) for k in ("run_ms_per_epoch", "render_ms_per_epoch", "ratio")}
    print(f"median of {a.repeat}: sunsim run {med['run_ms_per_epoch']:.2f} ms, renderer alone "
          f"{med['render_ms_per_epoch']:.2f} ms per epoch, ratio {med['ratio']:.2f} "
          f"(ratios {', '.join(format(r['ratio'], '.2f') for r in results)})")
    print(json.dumps({"epochs": results[0]["epochs"], **{k: round(v, 3) for k, v in med.items()},
                      "ratios": [r["ratio"] for r in results], "load_at_start": [r["load_at_start"] for r in results],
                      "repeat": a.repeat}))


if __name__ == "__main__":
    main_bench()
