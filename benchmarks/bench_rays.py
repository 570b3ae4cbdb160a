"""Benchmark this checkout's renderer against commit 6a3e1b9's (issue 32 item 3: fewer rays for the same accuracy):
ms and CPU ms per epoch at the default accuracies (0.2 % direct, 1 % albedo), rays per epoch, and the share of
diode-epochs meeting their target accuracy, each renderer in its own subprocess on the same epochs, alternating.

The old commit's tree is unpacked with ``git archive`` into a temporary folder and run with its PYTHONPATH and this
project's Python (the venv serves both). Geometry: ``bench_render.synthetic_orbit`` (tilt-20 / FOV-70 satellite,
TOMS 2005 reflectivity), the same seeds for both.

    .venv/bin/python benchmarks/bench_rays.py [--epochs N] [--repeat R] [--old COMMIT]

Last line: one JSON object (new / old ratios of wall and CPU time: issue 32 asks for at most 0.5).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OLD = "6a3e1b9"
TARGETS = dict(rel_se_direct=0.002, rel_se_albedo=0.01)
FLOOR = 0.01          # the renderer's default abs_se_floor_w_m2


def _renderer(cfg):
    """Return a Renderer for ``cfg`` by whichever API the tree on sys.path has (6a3e1b9: irradiance.Renderer)."""
    try:
        from simcore.render import Renderer
        from scenes.satellite import Satellite
        return Renderer.from_scene(Satellite(cfg))
    except ImportError:
        from scenes.meshes import build_satellite_mesh
        from simcore.render.irradiance import DiodeSurfaces, Renderer
        return Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg))


def worker(epochs, seeds):
    """Render ``epochs`` epochs of the synthetic orbit once per seed with the tree on sys.path; print one JSON line."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_render import synthetic_orbit
    from scenes.config import SatelliteConfig
    rend = _renderer(SatelliteConfig.load("tilt20_fov70"))
    sun, earth, rot = synthetic_orbit(epochs, 1.0)
    rend.render(sun[:64], earth[:64], rot[:64], seed=99, **TARGETS)          # compile the kernels
    wall = cpu = 0.0
    met_d, met_a, rays = [], [], []
    for seed in seeds:
        t0, c0 = time.perf_counter(), time.process_time()
        res = rend.render(sun, earth, rot, seed=seed, **TARGETS)
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        met_d.append(np.mean(res.direct_se_w_m2 <= np.maximum(TARGETS["rel_se_direct"] * res.direct_w_m2, FLOOR)))
        met_a.append(np.mean(res.albedo_se_w_m2 <= np.maximum(TARGETS["rel_se_albedo"] * res.albedo_w_m2, FLOOR)))
        rays.append((res.direct_samples.sum() + res.albedo_samples.sum()) / epochs)
    n = epochs * len(seeds)
    print(json.dumps(dict(ms=1e3 * wall / n, cpu_ms=1e3 * cpu / n, met_direct=float(np.mean(met_d)),
                          met_albedo=float(np.mean(met_a)), rays=float(np.mean(rays)))))


def _run(tree, epochs, seeds):
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, __file__, "--worker", "--epochs", str(epochs),
                          "--seeds", ",".join(map(str, seeds))], env=env, cwd=tree, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=500)
    ap.add_argument("--repeat", type=int, default=2, help="alternating rounds (new, old) per renderer")
    ap.add_argument("--old", default=OLD, help=f"the commit to compare against (default {OLD})")
    ap.add_argument("--seeds", default="1,2", help="seeds rendered per round (comma-separated)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    if args.worker:
        worker(args.epochs, seeds)
        return
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        old.mkdir()
        tar = subprocess.run(["git", "-C", str(ROOT), "archive", args.old], check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old)], input=tar, check=True)
        runs = {"new": [], "old": []}
        for _ in range(args.repeat):
            runs["new"].append(_run(ROOT, args.epochs, seeds))
            runs["old"].append(_run(old, args.epochs, seeds))
    med = {k: {f: float(np.median([r[f] for r in v])) for f in v[0]} for k, v in runs.items()}
    ratio = med["new"]["ms"] / med["old"]["ms"]
    cpu_ratio = med["new"]["cpu_ms"] / med["old"]["cpu_ms"]
    for k in ("old", "new"):
        m = med[k]
        print(f"{k:3s} ({args.old if k == 'old' else 'this checkout'}): {m['ms']:.3f} ms per epoch, CPU {m['cpu_ms']:.3f} "
              f"ms per epoch, {m['rays']:.0f} rays per epoch; targets met: direct {m['met_direct']:.4f}, "
              f"albedo {m['met_albedo']:.4f}")
    print(f"new / old: wall {ratio:.3f}, CPU {cpu_ratio:.3f} (issue 32: at most 0.5); {args.epochs} epochs x seeds "
          f"{seeds}, median of {args.repeat} alternating rounds; load average before {load0:.2f}")
    print(json.dumps(dict(bench="rays", old_commit=args.old, epochs=args.epochs, seeds=seeds, repeat=args.repeat,
                          load_average=round(load0, 2), wall_ratio=round(ratio, 4), cpu_ratio=round(cpu_ratio, 4),
                          new={k: round(v, 5) for k, v in med["new"].items()},
                          old={k: round(v, 5) for k, v in med["old"].items()},
                          met_no_lower=bool(med["new"]["met_direct"] >= med["old"]["met_direct"]
                                            and med["new"]["met_albedo"] >= med["old"]["met_albedo"]))))


if __name__ == "__main__":
    main()
