"""Benchmark simcore.render (the Renderer): ms per epoch for the 14 diodes at the sample counts that reach
0.2 % (direct) and 1 % (albedo) relative standard error, and rays per second.

Geometry: the thesis' tilt-20 / FOV-70 satellite (scenes/tilt20_fov70.toml and its
mesh from scenes.meshes) on a synthetic circular orbit like ESTCube-1's (665 km,
inclination 98 deg, Sun 20 deg out of the orbit plane so that every orbit has an
eclipse), Earth turning under it, tumbling at 1.9 deg/s (thesis sec. 4.1) about a fixed
body axis; TOMS 2005 reflectivity. One orbit at 1 s steps by default: a sample of the
24 h run whose time it projects.

    .venv/bin/python benchmarks/bench_render.py [--epochs N] [--step-s S] [--threads T] [--material NAME]

``--material`` (e.g. aluminium, scenes/materials.py) gives the body and the mounts that surface: the
render then path-traces the ``reflected`` component too (``--reflected-samples`` per diode-epoch), and
the same epochs are timed again without it, so that its own cost is printed.

The same orbit then renders the issue-13 example ``scenes/examples/cubesat3u_panels.toml`` (a 3U body,
six bare face diodes, two solar-cell wings: shadows and the path-traced ``reflected`` component) at the
same accuracies, timed with and without the reflected light (target <= 4 ms per epoch, issue 13); its
figures are the JSON object's ``cubesat3u_panels`` entry (``--no-3u`` skips it).

The main render runs with Dr.Jit's kernel history on (``drjit.JitFlag.KernelHistory``): the host share of its
wall time is the time outside Dr.Jit's kernel execution (the history's ``execution_time`` of every launch,
replayed frozen kernels included, and Dr.Jit's own copies and fills), i.e. Python, numpy, tracing and launching
(issue 32: below 15 % on llvm_ad_mono). Other processes on the cores stretch the kernels more than the host's one
thread and so lower the share: it is a fair figure only on a quiet machine (``quiet`` in the JSON: load average
below ``QUIET_LOAD`` before the render), and says so otherwise. Then Embree's raw ``scene.ray_test`` (Mitsuba's occluder scene of the same mesh, as the renderer
builds it) traces the same number of rays as the render, from the diodes' centres in uniform random directions
over each diode's hemisphere, in launches of the renderer's size (``_MAX_LANES``), timed alone: the renderer's
share of that raw rate is printed (``--no-raw`` skips it).

Last line: one JSON object.
"""
import argparse
import json
import os
import time

import numpy as np

from simcore.constants import OMEGA_EARTH_RAD_S, R_EARTH_MEAN_M

MU_EARTH = 3.986004418e14  # m^3/s^2, IERS conventions (2010)


def _rot(axis, ang):
    """Return rotation matrices (N, 3, 3) by angles ``ang`` (N,) about the unit ``axis``."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    s, c = np.sin(ang)[:, None, None], np.cos(ang)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def synthetic_orbit(n, step_s, alt_m=665e3, inc_deg=98.0, beta_deg=20.0, spin_deg_s=1.9):
    """Return (sun_dir_body, earth_center_body_m, R_ecef_from_body) (N, 3), (N, 3), (N, 3, 3)."""
    t = np.arange(n) * step_s
    a = R_EARTH_MEAN_M + alt_m
    u = np.sqrt(MU_EARTH / a ** 3) * t
    inc = np.radians(inc_deg)
    r_eci = a * np.stack([np.cos(u), np.sin(u) * np.cos(inc), np.sin(u) * np.sin(inc)], axis=1)
    h = np.array([0.0, -np.sin(inc), np.cos(inc)])                 # orbit normal
    b = np.radians(beta_deg)
    s_eci = np.cos(b) * np.array([1.0, 0.0, 0.0]) + np.sin(b) * h   # Sun 20 deg off the plane
    s_eci /= np.linalg.norm(s_eci)
    R_ecef_from_eci = _rot([0, 0, 1], -OMEGA_EARTH_RAD_S * t)
    R_eci_from_body = _rot([0.3, -0.5, 0.81], np.radians(spin_deg_s) * t) @ _rot([1, 2, 3], np.array([0.7]))
    R_body_from_eci = np.swapaxes(R_eci_from_body, 1, 2)
    sun_body = R_body_from_eci @ s_eci
    earth_body = -np.einsum("nij,nj->ni", R_body_from_eci, r_eci)
    return sun_body, earth_body, R_ecef_from_eci @ R_eci_from_body


THREE_U_TARGET_MS = 4.0   # issue 13 acceptance: the 3U panels example, ms per epoch at the default accuracies
QUIET_LOAD = 0.5          # the 1-minute load average below which the host share is a quiet machine's


def bench_3u(sun, earth, rot, targets, *, variant=None, threads=None):
    """Return the 3U panels example's timings (dict, ms per epoch) on the given synthetic orbit."""
    from importlib.resources import files
    from scenes.satellite import Satellite
    from simcore.render import Renderer

    sat = Satellite.load(files("scenes") / "examples" / "cubesat3u_panels.toml")
    cfg, mesh = sat.config, sat.mesh             # the mesh is built before the clock starts
    t0 = time.perf_counter()
    rend = Renderer.from_scene(sat, variant=variant, threads=threads)
    rend.render(sun[:64], earth[:64], rot[:64], seed=99, **targets)     # compile the kernels
    warm_s = time.perf_counter() - t0
    n = len(sun)
    t0 = time.perf_counter()
    res = rend.render(sun, earth, rot, seed=1, **targets)
    ms = (time.perf_counter() - t0) / n * 1e3
    t0 = time.perf_counter()
    rend.render(sun, earth, rot, seed=1, reflected=False, **targets)
    ms_plain = (time.perf_counter() - t0) / n * 1e3
    r = res.reflected_w_m2
    lit = res.direct_w_m2 > 0
    print(f"cubesat3u_panels: {cfg.n_diodes} diodes, {len(cfg.parts)} parts, mesh {len(mesh.faces)} triangles: "
          f"{ms:.3f} ms per epoch (target <= {THREE_U_TARGET_MS:g}), of which the reflected light "
          f"{ms - ms_plain:.3f} ms ({targets['reflected_samples']} paths per diode-epoch); reflected mean "
          f"{np.nanmean(r):.3f} W/m^2, max {np.nanmax(r):.2f} W/m^2, on {np.mean(r > 0):.3f} of the diode-epochs; "
          f"sunlit diode-epochs {lit.mean():.3f}; warm-up {warm_s:.2f} s")
    return dict(ms_per_epoch=round(ms, 4), reflected_ms_per_epoch=round(ms - ms_plain, 4),
                ms_per_epoch_without_reflected=round(ms_plain, 4), diodes=cfg.n_diodes,
                rays_per_epoch=round(res.rays / n), reflected_mean_w_m2=round(float(np.nanmean(r)), 4),
                target_ms=THREE_U_TARGET_MS, meets_target=bool(ms <= THREE_U_TARGET_MS), warmup_s=round(warm_s, 2))


def host_share(history, wall_s):
    """Return (share of ``wall_s`` outside Dr.Jit's kernel execution, kernel seconds, launches) from a
    ``drjit.kernel_history()`` list (every entry: compiled kernels, and Dr.Jit's copies, fills and host functions,
    whose ``execution_time`` is theirs alone; one thread's kernels run one after another, so the sum does not
    count a moment twice)."""
    kernel_s = sum(k.get("execution_time", 0.0) for k in history) / 1e3
    return 1.0 - kernel_s / wall_s, kernel_s, len(history)


def raw_ray_test(mesh, diodes, n_rays, variant=None, seed=0):
    """Return (seconds, rays) of Embree's bare ``scene.ray_test`` on ``mesh`` for ``n_rays`` rays from the
    diodes' centres in uniform random directions over each one's hemisphere, in launches of the renderer's
    size; the rays are built before the timing (one launch's worth, traced again until ``n_rays``)."""
    from simcore._llvm import host_array, import_drjit, import_mitsuba
    from simcore.render.launch import _MAX_LANES, choose_variant, occluder_scene
    dr, mi = import_drjit(), import_mitsuba()
    mi.set_variant(choose_variant(variant))
    scene = occluder_scene(mesh, mi)
    per = min(int(n_rays), _MAX_LANES)
    rng = np.random.default_rng(seed)
    k = rng.integers(0, len(diodes.positions_m), per)
    d = rng.normal(size=(per, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = np.asarray(diodes.frames)[k, 2]
    d = np.where((np.einsum("ij,ij->i", d, n) < 0)[:, None], -d, d)      # into the diode's hemisphere
    o = np.asarray(diodes.positions_m)[k] + 1e-6 * n
    ray = mi.Ray3f(mi.Point3f(*(host_array(mi.Float, o[:, i]) for i in range(3))),
                   mi.Vector3f(*(host_array(mi.Float, d[:, i]) for i in range(3))))
    dr.eval(ray.o, ray.d)
    dr.eval(scene.ray_test(ray))             # (warm: compile the launch)
    dr.sync_thread()                         # (on the CPU, drjit.eval returns before its kernel has run)
    done, t0 = 0, time.perf_counter()
    while done < n_rays:
        m = min(per, int(n_rays) - done)
        r = ray if m == per else mi.Ray3f(dr.gather(mi.Point3f, ray.o, dr.arange(mi.UInt32, m)),
                                          dr.gather(mi.Vector3f, ray.d, dr.arange(mi.UInt32, m)))
        dr.eval(scene.ray_test(r))
        dr.sync_thread()
        done += m
    return time.perf_counter() - t0, done


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=5880, help="epochs to render (default: one orbit)")
    ap.add_argument("--step-s", type=float, default=1.0)
    ap.add_argument("--config", default="tilt20_fov70")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--variant", default=None)
    ap.add_argument("--material", default="black", help="surface of the body and mounts (default: black)")
    ap.add_argument("--reflected-samples", type=int, default=256)
    ap.add_argument("--no-3u", action="store_true", help="skip the 3U panels example (scenes/examples)")
    ap.add_argument("--no-raw", action="store_true", help="skip Embree's raw ray_test rate")
    args = ap.parse_args()

    from dataclasses import replace
    from scenes.config import SatelliteConfig
    from scenes.satellite import Satellite
    from simcore.render import Renderer    # (here: benchmarks/bench_rays.py imports synthetic_orbit in older trees)
    cfg = SatelliteConfig.load(args.config)
    if args.material != "black":
        cfg = replace(cfg, body=replace(cfg.body, material=args.material),
                      mount=replace(cfg.mount, material=args.material))
    sat = Satellite(cfg)
    mesh = sat.mesh
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    rend = Renderer.from_scene(sat, variant=args.variant, threads=args.threads)
    sun, earth, rot = synthetic_orbit(args.epochs, args.step_s)
    targets = dict(rel_se_direct=0.002, rel_se_albedo=0.01, reflected_samples=args.reflected_samples)
    rend.render(sun[:64], earth[:64], rot[:64], seed=99, **targets)     # compile the kernels
    warm_s = time.perf_counter() - t0

    dr = rend._dr
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        dr.kernel_history_clear()
        t0, c0 = time.perf_counter(), time.process_time()
        res = rend.render(sun, earth, rot, seed=1, **targets)
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        host, kernel_s, launches = host_share(dr.kernel_history(), dt)
    n, k = res.direct_w_m2.shape
    ms = dt / n * 1e3
    rays = res.rays
    extra = dict(host_share=round(host, 4), kernel_s=round(kernel_s, 3), launches=launches)
    floor = 0.01
    met_d = np.mean(res.direct_se_w_m2 <= np.maximum(0.002 * res.direct_w_m2, floor))
    met_a = np.mean(res.albedo_se_w_m2 <= np.maximum(0.01 * res.albedo_w_m2, floor))
    lit = res.direct_w_m2 > 0
    print(f"config {args.config}: {k} diodes, {n} epochs at {args.step_s} s, variant {res.variant}, "
          f"mesh {len(mesh.faces)} triangles")
    print(f"warm-up (scene + kernel compilation + 64 epochs): {warm_s:.2f} s")
    print(f"render: {dt:.2f} s = {ms:.3f} ms per epoch ({ms / k:.3f} ms per diode-epoch); "
          f"CPU time {cpu / n * 1e3:.3f} ms per epoch over {os.cpu_count()} cores "
          f"(load average before: {load0:.2f}: other processes share the cores)")
    print(f"rays: {rays / n:.0f} per epoch (direct {res.direct_samples.sum() / n:.0f}, "
          f"albedo {res.albedo_samples.sum() / n:.0f}); {rays / dt / 1e6:.2f} M rays/s")
    print(f"targets met (0.2 % direct, 1 % albedo, or se <= {floor} W/m^2): direct {met_d:.4f}, "
          f"albedo {met_a:.4f}; sunlit diode-epochs {lit.mean():.3f}")
    quiet = load0 < QUIET_LOAD
    print(f"host share of the render's wall time: {host:.3f} (Dr.Jit kernels {kernel_s:.2f} s of {dt:.2f} s, "
          f"{launches} launches: {1e3 * (dt - kernel_s) / max(launches, 1):.2f} ms outside kernels per launch)"
          + ("" if quiet else f"; NOT a quiet figure: load average {load0:.2f} >= {QUIET_LOAD} before the render, "
                               "other processes stretch the kernels and so lower the share"))
    extra["quiet"] = quiet
    if not args.no_raw:
        raw_s, raw_n = raw_ray_test(mesh, rend.diodes, rays, variant=res.variant)
        raw_rate = raw_n / raw_s
        print(f"Embree's raw ray_test, same mesh, {raw_n} rays from the diodes (random directions): "
              f"{raw_s:.2f} s = {raw_rate / 1e6:.2f} M rays/s; the renderer at {rays / dt / 1e6:.2f} M rays/s is "
              f"{rays / dt / raw_rate:.2f} of it")
        extra.update(raw_ray_test_rays_per_s=round(raw_rate), renderer_share_of_raw=round(rays / dt / raw_rate, 4))
    day_s = 86400 * ms / 1e3
    print(f"projected 24 h at 1 s: {day_s / 60:.1f} min (target <= 10 min, stretch <= 3 min)")
    if args.material != "black":
        t0 = time.perf_counter()
        rend.render(sun, earth, rot, seed=1, reflected=False, **targets)
        ms_refl = ms - (time.perf_counter() - t0) / n * 1e3
        r, se = res.reflected_w_m2, res.reflected_se_w_m2
        some = r > 0
        print(f"reflected ({args.material}): {ms_refl:.3f} ms per epoch of the {ms:.3f} "
              f"({args.reflected_samples} paths per diode-epoch); mean {np.nanmean(r):.2f} W/m^2, "
              f"max {np.nanmax(r):.1f} W/m^2, median se/value where > 0: {np.nanmedian(se[some] / r[some]):.2f}")
        extra.update(material=args.material, reflected_ms_per_epoch=round(ms_refl, 4),
                     reflected_samples_per_epoch=round(res.reflected_samples.sum() / n),
                     reflected_mean_w_m2=round(float(np.nanmean(r)), 3))
    if not args.no_3u:
        extra["cubesat3u_panels"] = bench_3u(sun, earth, rot, targets, variant=args.variant, threads=args.threads)
    print(json.dumps(dict(bench="render", config=args.config, variant=res.variant, epochs=n, diodes=k, **extra,
                          ms_per_epoch=round(ms, 4), cpu_ms_per_epoch=round(cpu / n * 1e3, 4),
                          load_average=round(load0, 2), rays_per_s=round(rays / dt), rays_per_epoch=round(rays / n),
                          direct_samples_per_epoch=round(res.direct_samples.sum() / n),
                          albedo_samples_per_epoch=round(res.albedo_samples.sum() / n),
                          target_met_direct=round(float(met_d), 5), target_met_albedo=round(float(met_a), 5),
                          warmup_s=round(warm_s, 2), projected_24h_min=round(day_s / 60, 2),
                          meets_10min=bool(day_s <= 600), meets_3min=bool(day_s <= 180))))


if __name__ == "__main__":
    main()
