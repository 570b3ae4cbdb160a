"""Benchmark a whole ``sunsim run`` process against the renderer alone, on the default study.

What ``sunsim run`` does by default (ESTCube-1 from 2016-07-02T00:00Z at 1 s, the tilt20_fov70 satellite, finite
solar disc, TOMS 2005, adaptive accuracy 0.2 % / 1 %), measured as the user runs it: the wall time of the whole
process ``python -m simcore.cli run --duration S -o FILE`` (what the ``sunsim`` entry point calls): start-up and
imports, orbit and geometry, the scene, the render, the analytic reference and its check, the netCDF file.
Beside it, the renderer alone, bench_render's way: in another fresh process the same study is prepared
(:class:`simcore.pipeline.run.PreparedRun`: orbit, geometry and maps, not timed), then the renderer is built and
``Renderer.render`` runs over the run's chunks, timed (the scene and kernel compilation included, as in the run).
Their ratio is what everything else costs on top of the rendering (issue 32: at most 1.2 over three orbits,
``--duration 17613``). Each round also times a one-epoch ``sunsim run`` (start-up and imports, the scene and its
tables, the file: what a run costs whatever its length), printed as a share of the renderer alone's time: the part
of the ratio that no per-epoch speed-up moves (a slight overstatement: the scene's build, ~0.3 s, is timed in both).
And it times the whole run again with its check's reference taken out, first all of it, then all but the analytic
model the file carries at every epoch (:data:`RUN_WITHOUT_CHECK`): the floors of the ratio that no cheaper check can
go below, and by difference what the file's analytic model and the check cost in the run.

    .venv/bin/python benchmarks/bench_run.py [--duration S] [--repeat N]

The two processes alternate ``--repeat`` times (renderer, run, renderer, run, ...), so that another process on a
shared machine slows both alike; the ratio is the median of the per-round ratios. Beside the wall times, their CPU
times (user + system, every thread): the whole ``sunsim run`` process's, and the renderer's over the same timed
part as its wall time. The renderer alone keeps both cores busy, so on a quiet machine the wall ratio follows the
CPU ratio; on a loaded one the CPU ratio is the figure that the other processes move least (issue 32: quote the
wall ratio only from a quiet machine). This script imports nothing of
simcore itself: both figures come from fresh processes. Last line: one JSON object.
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

THREE_ORBITS_S = 17613.0   # three orbital periods of the default study (ESTCube-1, 5871 s)
LIMIT = 1.2                # issue 32: whole run / renderer alone

# the renderer-alone process: the run's study, its renderer over the run's chunks, nothing else timed
RENDER_ALONE = """
import json, sys, time
from simcore.pipeline.options import RunOptions
from simcore.pipeline.run import PreparedRun
from simcore.pipeline.store import chunk_ranges
opts = RunOptions(duration_s={duration!r})
st = PreparedRun(opts)
g = st.geometry
t0, c0 = time.perf_counter(), time.process_time()
r = st.renderer          # the scene and the renderer built, as in the run (and its kernels compiled: below)
rays = 0
for start, stop in chunk_ranges(len(g), opts.chunk_epochs):
    sl = slice(start, stop)
    res = r.render(g.sun_dir_body[sl], g.earth_center_body_m[sl], g.R_ecef_from_body[sl], st.sun_scale(sl),
                   sun_dir_earth_body=st.earth_sun_dir_body(sl), earth_sun_scale=st.earth_sun_scale(sl),
                   seed=opts.seed, epoch_offset=start, direct_samples=opts.direct_samples,
                   albedo_samples=opts.albedo_samples, rel_se_direct=opts.rel_se_direct,
                   rel_se_albedo=opts.rel_se_albedo, reflected_samples=opts.reflected_samples)
    rays += res.rays
print(json.dumps({{"epochs": len(g), "render_s": time.perf_counter() - t0, "render_cpu_s": time.process_time() - c0,
                  "rays": int(rays)}}))
"""


# The run without its check (the floor of the ratio), in two steps, each the same ``sunsim run`` process with part
# of the check's reference answering zeros at once. "bare": no analytic reference at all, no unchecked-direct
# masks, no hint-free direct re-render (so no visibility tables either): start-up, geometry, the scene, the render
# and the file, as in the user's command. "model": as "bare", plus the analytic model the file carries at every
# epoch, its ``analytic`` variable (the direct Sun, and the albedo on the map's own cells with the body box),
# computed as in the run but without the check's traced shares that the run's albedo kernel sums beside it. Its
# check then fails (exit 1). Not product modes: measurements of what the model and the check cost.
RUN_WITHOUT_CHECK = """
import sys, types
import numpy as np
from simcore.pipeline import reference, run
MODE = {mode!r}
full = reference.CheckReference.analytic


def analytic(self, sl, reflectivity_map, direct=True, mesh=False, albedo=True, **kw):
    z = np.zeros((sl.stop - sl.start, self.config.n_diodes))
    out = types.SimpleNamespace(direct_w_m2=z, albedo_w_m2=z, albedo_box_w_m2=z, albedo_mesh_w_m2=z,
                                albedo_visibility_error_w_m2=z)
    if MODE == "model" and reflectivity_map is self.run.map:
        # the direct Sun as in the run; the albedo on the map's cells with the body box alone (the check's traced
        # shares, summed beside it in the run's kernel, left out)
        part = full(self, sl, reflectivity_map, direct=direct, albedo=albedo)
        out.direct_w_m2, out.albedo_box_w_m2 = part.direct_w_m2, part.albedo_w_m2
    return out


def unchecked(self, sl):
    z = np.zeros((sl.stop - sl.start, self.config.n_diodes), bool)
    return z, z


reference.CheckReference.analytic = analytic
reference.CheckReference.direct_unchecked = unchecked
run.plain_check_epochs = lambda seed, n: np.zeros(n, bool)
from simcore.cli import main
sys.exit(main(sys.argv[1:]))
"""


def render_alone(duration):
    """Return (epochs, wall seconds, CPU seconds of Renderer.render over the run's chunks) from a fresh process."""
    out = subprocess.run([sys.executable, "-c", RENDER_ALONE.format(duration=duration)], capture_output=True,
                         text=True, check=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    return r["epochs"], r["render_s"], r["render_cpu_s"]


def _children_cpu_s():
    """Return the CPU seconds (user + system) of this process's finished children so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def whole_run(duration, path, without=None):
    """Return (exit status, wall seconds, CPU seconds, the command's JSON report) of ``sunsim run`` as a fresh
    process; ``without`` "bare" or "model": with part of its check taken out (:data:`RUN_WITHOUT_CHECK`)."""
    cmd = ([sys.executable, "-m", "simcore.cli"] if without is None else
           [sys.executable, "-c", RUN_WITHOUT_CHECK.format(mode=without)])
    cmd += ["run", "--duration", str(duration), "-o", path, "--overwrite", "--json"]
    t0, c0 = time.perf_counter(), _children_cpu_s()
    p = subprocess.run(cmd, capture_output=True, text=True)
    dt, cpu = time.perf_counter() - t0, _children_cpu_s() - c0
    if p.returncode not in (0, 1):          # 1: the check failed (still a whole run; reported below)
        raise SystemExit(f"sunsim run failed (exit {p.returncode}):\n{p.stderr[-2000:]}")
    return p.returncode, dt, cpu, json.loads(p.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=THREE_ORBITS_S,
                    help="seconds of orbit (default %(default)s: three orbits)")
    ap.add_argument("--repeat", type=int, default=1, help="alternating rounds (default %(default)s)")
    a = ap.parse_args(argv)
    if a.repeat < 1 or not a.duration >= 1.0:
        ap.error(f"--repeat must be at least 1 and --duration at least 1 s (got {a.repeat} and {a.duration:g})")
    load0 = os.getloadavg()[0]
    rounds = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(a.repeat):
            n, t_render, c_render = render_alone(a.duration)
            rc, t_run, c_run, report = whole_run(a.duration, os.path.join(tmp, f"run{i}.nc"))
            t_fixed = whole_run(1.0, os.path.join(tmp, f"one{i}.nc"))[1]
            _, t_bare, c_bare, _ = whole_run(a.duration, os.path.join(tmp, f"bare{i}.nc"), "bare")
            _, t_model, c_model, _ = whole_run(a.duration, os.path.join(tmp, f"model{i}.nc"), "model")
            rounds.append(dict(render_s=t_render, run_s=t_run, ratio=t_run / t_render, exit=rc, fixed_s=t_fixed,
                               bare_s=t_bare, bare_ratio=t_bare / t_render, model_s=t_model,
                               model_ratio=t_model / t_render, bare_cpu_ratio=c_bare / c_render,
                               model_cpu_ratio=c_model / c_render, check_share=(t_run - t_model) / t_render,
                               model_share=(t_model - t_bare) / t_render,
                               render_cpu_s=c_render, run_cpu_s=c_run, cpu_ratio=c_run / c_render,
                               check=report["check"].get("verdict"), load=os.getloadavg()[0]))
            print(f"round {i + 1}/{a.repeat}: sunsim run {t_run:6.1f} s ({1e3 * t_run / n:.3f} ms per epoch, exit "
                  f"{rc}, check {rounds[-1]['check']}), renderer alone {t_render:6.1f} s "
                  f"({1e3 * t_render / n:.3f} ms per epoch): ratio {t_run / t_render:.3f}; CPU {c_run:.1f} s against "
                  f"{c_render:.1f} s: ratio {c_run / c_render:.3f}; a one-epoch run {t_fixed:.2f} s; without the "
                  f"check: bare {t_bare:.1f} s, ratio {t_bare / t_render:.3f} (CPU {c_bare / c_render:.3f}), with "
                  f"the file's analytic model {t_model:.1f} s, ratio {t_model / t_render:.3f} "
                  f"(CPU {c_model / c_render:.3f})", flush=True)
    med = {k: statistics.median(r[k] for r in rounds)
           for k in ("run_s", "render_s", "ratio", "run_cpu_s", "render_cpu_s", "cpu_ratio", "fixed_s", "bare_s",
                     "bare_ratio", "model_s", "model_ratio", "bare_cpu_ratio", "model_cpu_ratio", "check_share",
                     "model_share")}
    print(f"default study, {n} epochs x 14 diodes: median of {a.repeat}: sunsim run {1e3 * med['run_s'] / n:.3f} ms, "
          f"renderer alone {1e3 * med['render_s'] / n:.3f} ms per epoch, ratio {med['ratio']:.3f} (limit {LIMIT}); "
          f"CPU time {1e3 * med['run_cpu_s'] / n:.3f} against {1e3 * med['render_cpu_s'] / n:.3f} ms per epoch, ratio "
          f"{med['cpu_ratio']:.3f}; a one-epoch run {med['fixed_s']:.2f} s, "
          f"{med['fixed_s'] / med['render_s']:.3f} of the renderer alone's time (the fixed part of the ratio); "
          f"without the check: bare {med['bare_ratio']:.3f} (CPU {med['bare_cpu_ratio']:.3f}), with the file's "
          f"analytic model {med['model_ratio']:.3f} (CPU {med['model_cpu_ratio']:.3f}) "
          f"(each round's differences: the check costs {med['check_share']:.3f} of the renderer alone's time, the "
          f"analytic model {med['model_share']:.3f}); "
          f"load average (1 min) {load0:.2f} at the start on {os.cpu_count()} cores")
    print(json.dumps({"bench": "run", "epochs": n, "run_ms_per_epoch": round(1e3 * med["run_s"] / n, 4),
                      "render_ms_per_epoch": round(1e3 * med["render_s"] / n, 4), "ratio": round(med["ratio"], 3),
                      "run_cpu_ms_per_epoch": round(1e3 * med["run_cpu_s"] / n, 4),
                      "render_cpu_ms_per_epoch": round(1e3 * med["render_cpu_s"] / n, 4),
                      "cpu_ratio": round(med["cpu_ratio"], 3), "one_epoch_run_s": round(med["fixed_s"], 3),
                      "one_epoch_share": round(med["fixed_s"] / med["render_s"], 3),
                      "bare_ratio": round(med["bare_ratio"], 3), "model_ratio": round(med["model_ratio"], 3),
                      "bare_cpu_ratio": round(med["bare_cpu_ratio"], 3),
                      "model_cpu_ratio": round(med["model_cpu_ratio"], 3),
                      "check_share": round(med["check_share"], 3), "model_share": round(med["model_share"], 3),
                      "bare_ratios": [round(r["bare_ratio"], 3) for r in rounds],
                      "model_ratios": [round(r["model_ratio"], 3) for r in rounds],
                      "cpu_ratios": [round(r["cpu_ratio"], 3) for r in rounds],
                      "ratios": [round(r["ratio"], 3) for r in rounds], "checks": [r["check"] for r in rounds],
                      "limit": LIMIT, "meets_limit": bool(med["ratio"] <= LIMIT), "repeat": a.repeat,
                      "load_at_start": round(load0, 2), "load_after_rounds": [round(r["load"], 2) for r in rounds]}))


if __name__ == "__main__":
    main()
