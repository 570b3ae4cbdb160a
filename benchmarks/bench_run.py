"""Benchmark a whole ``sunsim run`` against the renderer alone, on the default study.

What ``sunsim run`` does by default (ESTCube-1, one orbit at 1 s from 2016-07-02T00:00Z, the
tilt20_fov70 satellite, finite solar disc, TOMS 2005, adaptive accuracy 0.2 % / 1 %): render,
the analytic reference and check, and the netCDF file, timed through the command itself
(``simcore.cli.main``). Beside it, in the same process and on the same study, the renderer
alone: building it and rendering every chunk, nothing else. Their ratio is what the check,
the orbit set-up and the writing cost on top of the rendering.

    .venv/bin/python benchmarks/bench_run.py [--duration S]

Last line: one JSON object with run_ms_per_epoch, render_ms_per_epoch and ratio.
"""
import argparse
import contextlib
import io
import json
import os
import tempfile
import time

from simcore.cli import build_parser, main, run_options
from simcore.pipeline.run import PreparedRun
from simcore.pipeline.store import chunk_ranges


def main_bench(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=None, help="seconds of orbit (default: one period)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
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
    print(json.dumps({"epochs": n, "run_ms_per_epoch": round(1e3 * t_run / n, 3),
                      "render_ms_per_epoch": round(1e3 * t_render / n, 3), "ratio": round(t_run / t_render, 3)}))


if __name__ == "__main__":
    main_bench()
