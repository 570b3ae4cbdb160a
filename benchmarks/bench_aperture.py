"""Benchmark of the aperture studies: wall-reflection paths per second (the renderer's path tracer in one
well, bare aluminium), the whole-sphere black-well map, the self-shadowing of one configuration and the
default sweep. Last line: one JSON object.

    .venv/bin/python benchmarks/bench_aperture.py [--samples 65536] [--variant llvm_ad_mono]
"""
import argparse
import json
import os
import time

import numpy as np

from simcore.studies import aperture as A
from simcore.shapes.aperture import WellAperture


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--samples", type=int, default=65536, help="reflected paths per direction (4 m^2)")
    p.add_argument("--variant", default=None, help="Mitsuba variant (default: GPU if any)")
    args = p.parse_args()
    from simcore.render import choose_variant
    args.variant = choose_variant(args.variant)
    ap = WellAperture.design(75.0)
    d = A.cut_directions(np.arange(0.0, 90.0, 5.0), 0.0)
    rend = A.well_renderer(ap, A.BARE_AL, variant=args.variant)
    A.wall_response(ap, d[:2], A.BARE_AL, samples=1024, renderer=rend)        # warm-up (JIT)
    t0 = time.perf_counter()
    w = A.wall_response(ap, d, A.BARE_AL, samples=args.samples, renderer=rend)
    dt_walls = time.perf_counter() - t0
    paths = len(d) * args.samples
    print(f"wall path tracer (bare Al): {paths} paths in {dt_walls:.2f} s = {paths / dt_walls / 1e6:.2f} M paths/s; "
          f"largest reflected SE {w.reflected_se.max():.2e}")
    t0 = time.perf_counter()
    rmap = A.response_map(ap, nside=16, samples=1024)
    dt_map = time.perf_counter() - t0
    z = rmap.z_score[rmap.traced_se > 0]
    print(f"black-well map nside 16 (3072 directions): {dt_map:.2f} s; z mean {z.mean():+.3f} std {z.std():.3f}")
    t0 = time.perf_counter()
    A.self_shadowing("tilt30_fov75", nside=16)
    dt_sh = time.perf_counter() - t0
    print(f"self-shadowing tilt30_fov75, nside 16: {dt_sh:.2f} s")
    t0 = time.perf_counter()
    rows = A.sweep_apertures()
    dt_sw = time.perf_counter() - t0
    print(f"default sweep ({len(rows)} combinations, one orbit at 20 s): {dt_sw:.2f} s")
    print(json.dumps(dict(bench="aperture", cores=os.cpu_count(), variant=args.variant,
                          wall_paths_per_s=round(paths / dt_walls), wall_trace_s=round(dt_walls, 3),
                          map_nside16_s=round(dt_map, 3), map_z_mean=round(float(z.mean()), 4),
                          map_z_std=round(float(z.std()), 4), self_shadowing_nside16_s=round(dt_sh, 3),
                          sweep_default_s=round(dt_sw, 3), sweep_rows=len(rows))))


if __name__ == "__main__":
    main()
