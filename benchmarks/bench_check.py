"""Where a ``sunsim run``'s time goes beside the renderer: each piece of a run's chunk timed alone, in turn.

The default study (as ``sunsim run``), epochs [--first, --first + --epochs) in the run's chunks; per chunk, one
after another in the main thread (no overlap, so each figure is that piece's own cost): the render, the check's
hint-free direct re-render of its share of the epochs, the direct-Sun reference (numpy and the body box's Dr.Jit
kernel; in the run it goes to the worker thread), the albedo on the native cells and on the refined cells (Dr.Jit
kernels), the unchecked-direct masks; once: the visibility tables. Each piece's share of the render's time is
printed: what the run costs on top of the renderer (issue 32 item 2), in CPU time (user + system of the whole
process, every thread: Dr.Jit's and Embree's workers included) and in wall time. The renderer alone keeps both
cores busy, so in a run every CPU-second the check spends is wall time; on a shared machine the CPU time is the
figure that does not move with the other processes' load.

    .venv/bin/python benchmarks/bench_check.py [--epochs N] [--first I]

Last line: one JSON object (CPU and wall seconds per piece).
"""
import argparse
import json
import os
import time


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=2048, help="epochs to time (default %(default)s)")
    ap.add_argument("--first", type=int, default=2048,
                    help="first epoch (default %(default)s: sunlit, 34 min into the default run)")
    a = ap.parse_args(argv)
    import numpy as np
    from simcore.pipeline.check import PLAIN_CHECK_SAMPLES, plain_check_epochs
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import PreparedRun
    load0 = os.getloadavg()[0]
    o = RunOptions(duration_s=float(a.first + a.epochs))
    st = PreparedRun(o)
    g = st.geometry
    T, C = {}, {}

    def timed(name, f, *args, **kw):
        t0, c0 = time.perf_counter(), time.process_time()
        out = f(*args, **kw)
        C[name] = C.get(name, 0.0) + time.process_time() - c0
        T[name] = T.get(name, 0.0) + time.perf_counter() - t0
        return out
    timed("renderer (scene, tables)", lambda: st.renderer)
    timed("visibility tables (once)", lambda: st.reference.visibility)
    for start in range(a.first, a.first + a.epochs, o.chunk_epochs):
        sl = slice(start, min(start + o.chunk_epochs, a.first + a.epochs))
        args = (g.sun_dir_body[sl], g.earth_center_body_m[sl], g.R_ecef_from_body[sl], st.sun_scale(sl))
        timed("render", st.renderer.render, *args, sun_dir_earth_body=st.earth_sun_dir_body(sl),
              earth_sun_scale=st.earth_sun_scale(sl), seed=o.seed, epoch_offset=start,
              direct_samples=o.direct_samples, albedo_samples=o.albedo_samples, rel_se_direct=o.rel_se_direct,
              rel_se_albedo=o.rel_se_albedo, reflected_samples=o.reflected_samples)
        pick = np.flatnonzero(plain_check_epochs(o.seed, len(st.epochs))[sl])
        if len(pick):
            timed("hint-free direct re-render", st.renderer.render, *(x[pick] for x in args), seed=o.seed,
                  epoch_index=sl.start + pick, albedo=False, hint=False, reflected=False,
                  direct_samples=max(o.direct_samples, PLAIN_CHECK_SAMPLES))
        timed("direct reference", st.reference.analytic, sl, st.map, albedo=False)
        timed("albedo, native cells", st.reference.analytic, sl, st.map, direct=False, mesh=True, box_albedo=True,
              mesh_terms=False)
        timed(f"albedo, cells refined {st.check_refine}x{st.check_refine}", st.reference.analytic, sl, st.map_refined,
              direct=False, mesh=True)
        timed("unchecked-direct masks", st.reference.direct_unchecked, sl)
    r, rc = T["render"], C["render"]
    print(f"default study, epochs {a.first}..{a.first + a.epochs} (sunlit {np.mean(g.illumination[a.first:a.first + a.epochs] > 0):.2f}), "
          f"chunks of {o.chunk_epochs}; load average (1 min) {load0:.2f} on {os.cpu_count()} cores")
    print(f"  {'piece':<32} {'CPU s':>8} {'x render':>9}   {'wall s':>8} {'x render':>9}")
    for k, v in T.items():
        print(f"  {k:<32} {C[k]:8.2f} {C[k] / rc:9.3f}   {v:8.2f} {v / r:9.3f}")
    print(json.dumps({"bench": "check", "first": a.first, "epochs": a.epochs, "load_at_start": round(load0, 2),
                      "load_at_end": round(os.getloadavg()[0], 2),
                      "cpu_seconds": {k: round(v, 3) for k, v in C.items()},
                      "seconds": {k: round(v, 3) for k, v in T.items()}}))


if __name__ == "__main__":
    main()
