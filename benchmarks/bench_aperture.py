"""Benchmark of the aperture studies: wall-reflection paths per second, the whole-sphere black-well map,
the self-shadowing of one configuration and the default sweep. Last line: one JSON object.

    .venv/bin/python benchmarks/bench_aperture.py [--rays 200000] [--variant llvm_ad_mono]
"""
import argparse
import json
import os
import time

import numpy as np

from simcore.studies import aperture as A
from simcore.shapes.aperture import WellAperture
from simcore.render.walls import WallMaterial, trace_well


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--rays", type=int, default=200_000, help="paths per direction for the wall tracer")
    p.add_argument("--variant", default=None, help="Mitsuba variant for the wall tracer (default: GPU if any)")
    args = p.parse_args()
    from simcore.render.irradiance import choose_variant
    args.variant = choose_variant(args.variant)
    ap = WellAperture.design(75.0)
    d = A.cut_directions(np.arange(0.0, 90.0, 5.0), 0.0)
    trace_well(ap, d[:2], WallMaterial.aluminium(), rays=1000, variant=args.variant)        # warm-up (JIT)
    t0 = time.perf_counter()
    tr = trace_well(ap, d, WallMaterial.aluminium(), rays=args.rays, variant=args.variant)
    dt_walls = time.perf_counter() - t0
    paths = len(d) * args.rays
    print(f"wall tracer (bare Al): {paths} paths in {dt_walls:.2f} s = {paths / dt_walls / 1e6:.2f} M paths/s, "
          f"{tr.mean_bounces.mean():.2f} surface hits per path")
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
