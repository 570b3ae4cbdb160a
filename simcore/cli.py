"""The ``sunsim`` command line."""
import json
import os
import sys

import numpy as np

from simcore._version import __version__
from simcore.commands.output import output_folder
from simcore.commands.studies import add_study_parsers
from simcore.constants import E_SUN_W_M2
from simcore.errors import InvalidInputError, UserError
from simcore.pipeline.arguments import NotedGiven, OneLineParser

DEFAULT_TLE_HELP = "TLE file (2- or 3-line; default: the shipped ESTCube-1 set, epoch 2016-07-27)"


def _add_orbit_options(p, ephemeris=False):
    p.add_argument("--tle", metavar="FILE", help=DEFAULT_TLE_HELP)
    p.add_argument("--satellite", metavar="NAME_OR_ID", help="satellite in a multi-satellite TLE file")
    if ephemeris:
        p.add_argument("--orbit", metavar="FILE.oem", help="a CCSDS orbit ephemeris (OEM, KVN or XML) instead of a "
                       "TLE; without --start/--duration the run covers its span (docs/ccsds.md)")
        p.add_argument("--eop", nargs=3, type=float, metavar=("DUT1_S", "XP_ARCSEC", "YP_ARCSEC"),
                       help="Earth orientation from IERS Bulletin A (UT1 - UTC, pole x, y); default 0: Earth-fixed "
                            "positions (an ITRF ephemeris) are then up to ~400 m off")
    p.add_argument("--start", default=None, help="first epoch, ISO-8601 UTC (default: 2016-07-02T00:00:00Z, or "
                                                 "the first sample of an --attitude history with absolute times"
                                                 + (", or the first epoch of an --orbit ephemeris)" if ephemeris else ")"))
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="seconds to simulate (default: one orbital period, or the rest of an --attitude history)")
    p.add_argument("--step", type=float, default=1.0, metavar="S", action=NotedGiven,
                   help="seconds between epochs (default: %(default)s)")
    p.add_argument("--spin-rate", type=float, default=1.9, metavar="DEG_S", action=NotedGiven,
                   help="tumble rate about the body diagonal (default: %(default)s deg/s, thesis)")


def _geometry(args):
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.schedule import study_geometry
    orbit, _, geometry = study_geometry(RunOptions(tle=args.tle, satellite=args.satellite, start=args.start,
                                                   duration_s=args.duration, step_s=args.step,
                                                   spin_rate_deg_s=args.spin_rate))
    return orbit, geometry


def cmd_summary(args):
    """Orbit / Sun / eclipse summary of a study (what `run` shows before rendering)."""
    from simcore.constants import R_EARTH_MEAN_M
    from simcore.environment.eclipse import sunlit
    from simcore.environment.geometry import eclipse_events, orbital_period_s
    orbit, g = _geometry(args)
    alt_km = (np.linalg.norm(g.r_sat_gcrs_m, axis=1) - R_EARTH_MEAN_M) / 1e3
    events = eclipse_events(g)
    pen = []
    for (k1, t1), (k2, t2) in zip(events, events[1:]):
        if (k1, k2) in (("penumbra-entry", "umbra-entry"), ("umbra-exit", "penumbra-exit")):
            pen.append(t2 - t1)
    orbit_normal = np.cross(g.r_sat_gcrs_m[0], g.v_sat_gcrs_m_s[0])
    orbit_normal /= np.linalg.norm(orbit_normal)
    beta_deg = float(np.degrees(np.arcsin(orbit_normal @ g.sun_dir_gcrs[0])))
    out = {
        "satellite": orbit.name, "norad_id": orbit.norad_id, "tle_epoch": orbit.epoch.iso()[0],
        "start": g.epochs.iso()[0], "end": g.epochs.iso()[-1], "epochs": len(g), "step_s": args.step,
        "period_s": round(orbital_period_s(orbit), 1),
        "altitude_km": [round(float(np.nanmin(alt_km)), 1), round(float(np.nanmax(alt_km)), 1)],
        "beta_angle_deg": round(beta_deg, 2),
        "sunlit_fraction": round(float(np.nanmean(sunlit(g.illumination))), 4),
        "umbra_fraction": round(float(np.nanmean(g.illumination <= 0.0)), 4),
        "penumbra_durations_s": [round(float(p), 1) for p in pen],
        "eclipse_events": [(k, round(float(t), 1)) for k, t in events],
        "sgp4_errors": int(np.count_nonzero(g.error_code)),
    }
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"{out['satellite']} (NORAD {out['norad_id']}), TLE epoch {out['tle_epoch']}")
    print(f"  {out['start']} .. {out['end']}: {out['epochs']} epochs at {args.step:g} s, period {out['period_s']} s")
    print(f"  altitude {out['altitude_km'][0]} .. {out['altitude_km'][1]} km, beta angle {out['beta_angle_deg']} deg")
    print(f"  sunlit {out['sunlit_fraction']:.1%}, umbra {out['umbra_fraction']:.1%}, "
          f"penumbra passages {', '.join(f'{p:.0f} s' for p in pen) or 'none'}")
    for k, t in out["eclipse_events"]:
        print(f"    {t:8.1f} s  {k}")
    return 0


def _add_render_options(p):
    p.add_argument("--config", default="tilt20_fov70", metavar="NAME_OR_TOML",
                   help="satellite configuration: a shipped name (tilt0_fov90, tilt{20,25,30}_fov{70,75}) "
                        "or a .toml file (scenes/FORMAT.md); default %(default)s")
    from simcore.pipeline.run_args import add_attitude_options
    add_attitude_options(p)
    p.add_argument("--dynamics", metavar="INERTIA",
                   help="torque-free Euler dynamics instead of the constant tumble, starting at --spin-rate about "
                        "the body diagonal; INERTIA in kg m^2: 'IXX,IYY,IZZ' or 'IXX,IYY,IZZ,IXY,IXZ,IYZ'")
    p.add_argument("--accuracy", nargs=2, type=float, metavar=("DIRECT", "ALBEDO"), default=(0.002, 0.01),
                   action=NotedGiven, help="target relative standard errors of direct and albedo irradiance (default 0.002 0.01)")
    p.add_argument("--samples", nargs=2, type=int, metavar=("DIRECT", "ALBEDO"),
                   help="fixed samples per diode-epoch instead of --accuracy (direct: a power of 4)")
    _add_reflected_samples(p)
    p.add_argument("--dead", type=int, nargs="*", default=[], metavar="I", help="dead diode indices")
    p.add_argument("--extra-flat", action="store_true",
                   help="add the two optional flat diodes on top and bottom (14-diode layouts)")
    p.add_argument("--map", default="toms2005", help="reflectivity map: toms2005, ceres2018-all, "
                   "ceres2018-clear, band[:DIODE] / band-clear[:DIODE] (CERES 2018 all-sky / clear-sky seen in the "
                   "diode's band, default diode BPW34FS; simcore/radiometry/band.py), uniform:ALBEDO (one mean "
                   "albedo, as Basilisk's ALBEDO_AVG, e.g. uniform:0.3) or a .npz file (default %(default)s)")
    _add_cloud_options(p)
    p.add_argument("--glint", type=float, metavar="WIND_M_S",
                   help="ocean sun glint: a Cox-Munk rough-sea BRDF (wind speed at 12.5 m, m/s, e.g. 7) on the sea "
                        "part of each map cell (GSHHG coastlines), added to the map's diffuse reflectivity, in the "
                        "render and in the analytic check (simcore/radiometry/glint.py)")
    p.add_argument("--point-sun", action="store_true", help="a point Sun (no penumbra) instead of the 0.53 deg disc")
    p.add_argument("--solar-flux", choices=["physical", "thesis"], default="physical",
                   help="physical: 1361 W/m^2 at 1 AU (IAU 2015 B3, Kopp & Lean 2011) x (1 AU / r_sun)^2; "
                        "thesis: a constant 1366.1 W/m^2 (default %(default)s)")
    p.add_argument("--variant", choices=["llvm_ad_mono", "cuda_ad_mono"],
                   help="Mitsuba variant (default: cuda_ad_mono when a GPU works, else llvm_ad_mono)")
    p.add_argument("--seed", type=int, default=0, help="random seed, 0 .. 2^64-1 (same seed, same numbers)")
    p.add_argument("--chunk", type=int, default=512, metavar="EPOCHS",
                   help="epochs per stored chunk (not part of the result: a resume may use another)")
    p.add_argument("-o", "--output", default=None, metavar="FILE.nc",
                   help="output netCDF file (default: runs/default.nc; a run with other settings gets the next "
                        "free runs/default-N.nc, the same settings find their earlier file)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --output made with other settings")
    p.add_argument("--allow-bright-map", action="store_true",
                   help="accept a reflectivity map with values above 1.2 (the shipped maps peak at 1.07)")


def _add_reflected_samples(p):
    """Add --reflected-samples: paths per diode-epoch for the reflected component."""
    from simcore.pipeline.preflight import REFLECTED_SAMPLES
    p.add_argument("--reflected-samples", type=int, default=REFLECTED_SAMPLES, metavar="N",
                   help="paths per diode-epoch for the light the spacecraft's non-black surfaces reflect onto the "
                        "diodes: 4 m^2 for a whole m >= 8 (256, 576, 1024, ...; default %(default)s); more paths, "
                        "smaller standard errors of the reflected component")


def _add_cloud_options(p, many=False):
    """Add --clouds (one seed, or with ``many`` a list: a sweep axis) and --cloud-scale-km."""
    from simcore.environment.clouds import DEFAULT_SCALE_KM
    p.add_argument("--clouds", type=int, nargs="+" if many else None, metavar="SEED",
                   help="cloud weather: the map becomes one random realisation (seed"
                        + ("s: one run each" if many else "") + ") of clear and overcast cells whose mean over "
                        "seeds is the all-sky map; needs --map ceres2018-all or band[:DIODE] (simcore/environment/clouds.py)")
    p.add_argument("--cloud-scale-km", type=float, metavar="KM",
                   help=f"correlation length of the cloud field, 200..5000 km (default {DEFAULT_SCALE_KM:g}: "
                        "cloud systems ~1600 km across)")


def run_options(args):
    """Return the simcore.pipeline.options.RunOptions of parsed ``run`` arguments."""
    from simcore.pipeline.options import RunOptions
    samples = args.samples
    return RunOptions(
        config=args.config, tle=args.tle, satellite=args.satellite, orbit_file=args.orbit, eop=args.eop, start=args.start,
        duration_s=args.duration,
        step_s=args.step, spin_rate_deg_s=args.spin_rate, attitude_file=args.attitude, dynamics=args.dynamics,
        attitude_frame=args.attitude_frame, attitude_direction=args.attitude_direction, times_file=args.times,
        rel_se_direct=None if samples else args.accuracy[0], rel_se_albedo=None if samples else args.accuracy[1],
        direct_samples=samples[0] if samples else 1024, albedo_samples=samples[1] if samples else 256,
        reflected_samples=args.reflected_samples, dead=tuple(args.dead), extra_flat_diodes=args.extra_flat, variant=args.variant, seed=args.seed, reflectivity=args.map,
        clouds=args.clouds, cloud_scale_km=args.cloud_scale_km, glint=getattr(args, "glint", None),
        sun_disc=not args.point_sun, chunk_epochs=args.chunk, output=args.output,
        **(dict(e_sun_w_m2=E_SUN_W_M2, distance_scaling=False) if args.solar_flux == "thesis" else {}),
        fail_on_check=args.fail_on_check, overwrite=args.overwrite, allow_bright_map=args.allow_bright_map)


def cmd_run(args):
    """Render a study, check it against the analytic model, write the netCDF file."""
    import os
    import time
    from simcore.pipeline.run import execute
    opts = run_options(args)
    t0 = time.perf_counter()
    path, ds, report = execute(opts, log=lambda m: print(m, file=sys.stderr))
    elapsed = time.perf_counter() - t0
    out = {"output": os.path.abspath(path), "configuration": ds.attrs["configuration"],
           "epochs": int(ds.sizes["time"]), "diodes": int(ds.sizes["diode"]), "seconds": round(elapsed, 1),
           "variant": ds.attrs["variant"], "check": report}
    if args.json:
        print(json.dumps(out))
    else:
        irr = ds.irradiance
        print(f"sunsim run: {out['configuration']}, {out['epochs']} epochs x {out['diodes']} diodes "
              f"in {elapsed:.1f} s ({ds.attrs['variant']})")
        print(f"  mean irradiance: direct {float(irr.sel(component='direct').mean()):.1f} W/m^2, "
              f"albedo {float(irr.sel(component='albedo').mean()):.1f} W/m^2, "
              f"reflected {float(irr.sel(component='reflected').mean()):.1f} W/m^2")
        if report.get("verdict") == "no sunlit data":
            print("  analytic check: no sunlit data (the whole span is in the Earth's shadow; nothing to compare: "
                  "choose another --start or a longer --duration)")
        else:
            from simcore.pipeline.check import describe
            failed = [f"{t['component']} {t['test']}" for t in report["tests"] if not t["passed"]]
            print(f"  analytic check: {'PASS' if report['pass'] else 'FAIL (' + ', '.join(failed) + ')'}; "
                  f"{len(report['tests'])} tests at a false-alarm rate {report['alpha_run']:g} per run "
                  f"('sunsim validate {path}' prints each)")
            if not report["pass"] and not args.json:
                print("\n".join("  " + line for line in describe(report)[1:-1]))
        print(f"  output: {out['output']}")
        print(f"  open it: xarray.open_dataset({path!r})")
    if report.get("verdict") == "FAIL" and args.fail_on_check:      # "no sunlit data" checked nothing: exit 0
        print("sunsim run: the analytic check failed (exit status 1); the run file is kept. "
              "--no-fail-on-check exits 0 anyway", file=sys.stderr)
        return 1
    return 0


def cmd_coverage(args):
    """HEALPix coverage fractions (thesis figs. 3.7-3.13) and a Mollweide map per configuration."""
    import os
    from scenes.config import SatelliteConfig
    from simcore.studies.coverage import coverage_fractions, plot_coverage
    results = []
    for name in args.configs:
        cfg = SatelliteConfig.load(name, dead=args.dead)
        frac = coverage_fractions(cfg)
        png = None
        if not args.no_plot:
            output_folder(args.plot_dir, "--plot-dir")
            png = os.path.join(args.plot_dir, f"coverage_{cfg.name}" + (f"_dead{'-'.join(map(str, args.dead))}" if args.dead else "") + ".png")
            plot_coverage(cfg, png)
        results.append({"config": cfg.name, "dead": [int(i) for i in args.dead],
                        **{k: round(float(v), 4) for k, v in frac.items()}, "map": png})
    for r in results:
        if args.json:
            print(json.dumps(r))
        else:
            print(f"{r['config']:>14}  dead {r['dead'] or '-'}:  red {r['red']:.4f}  yellow {r['yellow']:.4f}  "
                  f"green {r['green']:.4f}" + (f"   map: {r['map']}" if r["map"] else ""))
    return 0


def cmd_response(args):
    """The traced angular response of a configuration's diodes, beside cosine, eq. 4.15 and a fitted Kelly curve."""
    from pathlib import Path
    from simcore.errors import InvalidInputError
    from scenes.config import SatelliteConfig
    from simcore.studies.response import check_request, format_table, traced_response
    from simcore.pipeline.preflight import check_variant
    if args.plot is not None and Path(args.plot).suffix.lower() not in (".png", ".pdf"):
        raise InvalidInputError(f"--plot {args.plot}: give a .png or .pdf file name")
    cfg = SatelliteConfig.load(args.config)
    check_request(cfg, args.diode, args.plane, args.step, args.samples, args.map_step)   # before any output
    check_variant(args.variant)
    if args.plot is not None:
        output_folder(str(Path(args.plot).parent), "--plot")
    resp = traced_response(cfg, diodes=args.diode, plane=args.plane, step_deg=args.step,
                           samples=args.samples, seed=args.seed, variant=args.variant, map_step_deg=args.map_step)
    if args.plot is not None:
        from simcore.plots import plot_angular_response, plot_response_hemisphere
        base = Path(args.plot)
        for r in resp:
            one = base if len(resp) == 1 else base.with_name(f"{base.stem}_d{r.index}{base.suffix}")
            plot_angular_response(r.theta_deg, {"traced": r.response, "cos": r.cosine, "eq. 4.15": r.eq415,
                                                ("well overlap" if cfg.diodes[r.index].window is None
                                                 else "well + window, closed form"): r.well,
                                                f"Kelly {r.kelly_factor:.3g}, scale {r.kelly_scale:.3g}": r.kelly},
                                  errors={"traced": r.response_se}, fov_deg=None, cutoff_deg=None,
                                  title=f"diode {r.index} ({r.name}), Sun in its {r.plane}-n plane", path=one,
                                  ylabel="irradiance / E_sun (a bare diode facing the Sun: 1) [-]")
            if r.map_response is not None:
                plot_response_hemisphere(r.map_theta_deg, r.map_phi_deg, r.map_response,
                                         title=f"diode {r.index} ({r.name}): traced response",
                                         path=one.with_name(f"{one.stem}_map{one.suffix}"),
                                         label="irradiance / E_sun [-]")
    if args.json:
        print(json.dumps({"config": args.config, "diodes": [r.as_dict() for r in resp]}))
    else:
        print(format_table(resp))
    return 0


def cmd_view(args):
    """Render the annotated scene picture: the CubeSat at one epoch, over the Earth coloured by its reflectivity."""
    from scenes.config import SatelliteConfig
    from simcore.picture.view import view_epoch, view_picture
    from simcore.environment.earth import Earth
    from simcore.environment.epochs import Epochs
    from simcore.pipeline.store import check_writable
    from simcore.radiometry import band
    config = args.config or args.config_pos or "tilt20_fov70"      # options checked: simcore.pipeline.arguments
    w, h = args.resolution
    cfg = SatelliteConfig.load(config)
    if args.clouds is None:
        rmap = band.resolve_map(args.map or "toms2005")
    else:
        from simcore.environment.clouds import check_cloud_options
        check_cloud_options(args.map or "toms2005", args.clouds, args.cloud_scale_km)
        rmap = band.cloud_weather(args.map, args.cloud_scale_km).realise(args.clouds)
    Epochs.from_any(args.time)
    ve = view_epoch(args.time, tle=args.tle, satellite=args.satellite, start=args.start,
                    spin_rate_deg_s=args.spin_rate, attitude_file=args.attitude)
    if not np.all(np.isfinite(ve.geometry.r_sat_ecef_m)):
        raise InvalidInputError(f"SGP4 cannot place the satellite at {args.time} (the orbit has decayed or the TLE "
                                "is too far from that date); give a --time nearer the TLE epoch")
    if args.output is None:
        os.makedirs("runs", exist_ok=True)
        args.output = os.path.join("runs", f"scene_{cfg.name}" + ("_close" if args.close_up else "") + ".png")
    check_writable(args.output)
    view_picture(cfg, args.output, ve, close_up=args.close_up, earth=Earth(rmap), resolution=(w, h),
                 spp=args.spp, seed=args.seed)
    print(json.dumps({"config": cfg.name, "time": ve.epoch_iso, "picture": str(args.output)}) if args.json
          else f"picture: {args.output}")
    return 0


def cmd_export(args):
    """``sunsim export RUN.nc --format csv|aem|oem|basilisk``: readings, attitude, orbit or Basilisk values."""
    from simcore.pipeline.export import export
    print(export(args.run, args.format, args.output, diode=args.diode, noise=args.noise, seed=args.seed))
    return 0


def cmd_validate(args):
    """The rendered-vs-analytic report of a run file; exit status 1 outside tolerance."""
    from simcore.pipeline.run import recompute_analytic
    from simcore.pipeline.runfile import check_run, open_run
    if args.recompute_analytic:
        recompute_analytic(args.run, log=None if args.json else (lambda m: print(m, file=sys.stderr)))
    ds = open_run(args.run)
    flags, report = check_run(ds)
    if args.json:
        print(json.dumps({"run": args.run, **report}))
    elif report["verdict"] == "no sunlit data":
        print(f"{args.run}: {ds.attrs.get('configuration')}, {ds.sizes['time']} epochs x {ds.sizes['diode']} diodes")
        print("  verdict: no sunlit data (the whole span is in the Earth's shadow: nothing was checked)")
    else:
        from simcore.pipeline.check import describe
        print(f"{args.run}: {ds.attrs.get('configuration')}, {ds.sizes['time']} epochs x {ds.sizes['diode']} diodes")
        print("\n".join("  " + line for line in describe(report)))
        print("  verdict: " + ("PASS" if report["pass"] else "FAIL"))
    return 0 if report["pass"] else 1




def _mekf_filter(args):
    """``sunsim estimate RUN.nc --filter mekf``: print the attitude-error summary (or JSON); exit status 0."""
    from simcore.pipeline.evaluate_attitude import DEFAULT_GYRO, DEFAULT_MAGNETOMETER, run_mekf, summary_lines
    from simcore.pipeline.runfile import open_run
    from simcore.plots import plot_mekf
    from simcore.sensor.gyro import gyro_spec
    from simcore.sensor.magnetometer import magnetometer_spec
    gyro = gyro_spec(args.gyro or DEFAULT_GYRO).name                 # name checks before any work
    mag = magnetometer_spec(args.magnetometer or DEFAULT_MAGNETOMETER).name
    ds = open_run(args.run)
    res = run_mekf(ds, args.run, gyro=gyro, magnetometer=mag, seed=args.seed, diode=args.diode,
                   onboard_albedo=not args.no_onboard_albedo, initial_error_deg=args.initial_error,
                   thermal_compensation=args.thermal_compensation)
    s = res["summary"]
    if args.plots:
        s["plots"] = plot_mekf(res, output_folder(args.plots, "--plots folder"), title=f"{s['configuration']}, {gyro}:")
    if args.json:
        print(json.dumps({"run": args.run, **s}))
        return 0
    print("\n".join(summary_lines(args.run, s)))
    if args.plots:
        print(f"  plots: {', '.join(s['plots'])}")
    return 0


def _sunline_filter(args):
    """``sunsim estimate RUN.nc --filter sunline-ekf|sunline-ukf``: a sun-line filter
    (simcore.pipeline.evaluate_sunline) over a run file; print its summary (or JSON)."""
    from simcore.pipeline.evaluate_sunline import filter_run, parse_process_noise
    from simcore.pipeline.runfile import open_run
    from simcore.sensor.errors import check_faults, parse_faults, parse_sensor_errors
    errors, faults = parse_sensor_errors(args.sensor_errors), parse_faults(args.faults)
    q_rate, q_sun = parse_process_noise(args.process_noise or "1e-13:0")
    if args.use_threshold is not None and not 0 <= args.use_threshold < 1:
        raise UserError(f"--use-threshold must be a reading in [0, 1) of the normal-Sun reading, got {args.use_threshold}")
    if args.gyro_noise is not None and not args.gyro_noise > 0:
        raise UserError(f"--gyro-noise must be the gyro's noise standard deviation, > 0 deg/s; got {args.gyro_noise}")
    ds = open_run(args.run)
    check_faults(faults, ds["t_s"].values, ds.sizes["diode"])
    return _print_filter_summary(args, filter_run(ds, args.filter, diode=args.diode, errors=errors, faults=faults,
                                                  noise=args.noise, seed=args.seed, q_rate=q_rate, q_sun=q_sun,
                                                  use_threshold=args.use_threshold, gyro_sigma_deg_s=args.gyro_noise))


# sunsim estimate --filter NAME: one table, one entry per filter
ESTIMATE_FILTERS = {"sunline-ekf": _sunline_filter, "sunline-ukf": _sunline_filter, "mekf": _mekf_filter}
# the options that belong to each kind of filter
_FILTER_OPTIONS = {
    "sunline": ("--faults", "--sensor-errors", "--gyro-noise", "--use-threshold", "--process-noise"),
    "mekf": ("--gyro", "--magnetometer", "--no-onboard-albedo", "--thermal-compensation", "--initial-error"),
}


def _print_filter_summary(args, out):
    if args.json:
        print(json.dumps({"run": args.run, **out}))
        return 0
    from simcore.pipeline.evaluate_sunline import summary_lines
    print("\n".join(summary_lines(args.run, out)))
    return 0


def _check_filter_options(args):
    """Raise the user's mistake when a filter's options come without that filter."""
    given = {"--faults": args.faults, "--sensor-errors": args.sensor_errors, "--gyro-noise": args.gyro_noise,
             "--use-threshold": args.use_threshold, "--process-noise": args.process_noise,
             "--gyro": args.gyro, "--magnetometer": args.magnetometer, "--no-onboard-albedo": args.no_onboard_albedo,
             "--thermal-compensation": args.thermal_compensation, "--initial-error": args.initial_error}
    kind = None if not args.filter else ("mekf" if args.filter == "mekf" else "sunline")
    for k, opts in _FILTER_OPTIONS.items():
        used = [o for o in opts if given[o] not in (None, False)]
        if used and k != kind:
            want = "mekf" if k == "mekf" else "sunline-ekf"
            also = "" if k == "mekf" else " (or sunline-ukf)"
            raise UserError(f"{', '.join(used)} only go with --filter {want}{also}: add --filter {want}")


def _add_mekf_options(p):
    """Add the MEKF's options to the ``sunsim estimate`` parser."""
    from simcore.pipeline.evaluate_attitude import DEFAULT_GYRO, DEFAULT_MAGNETOMETER
    p.add_argument("--gyro", metavar="NAME", help=f"gyro for --filter mekf (default {DEFAULT_GYRO}, the flown one; "
                   "table: simcore/data/gyros.toml)")
    p.add_argument("--magnetometer", metavar="NAME", help=f"magnetometer for --filter mekf (default "
                   f"{DEFAULT_MAGNETOMETER}; table: simcore/data/magnetometers.toml)")
    p.add_argument("--no-onboard-albedo", action="store_true",
                   help="--filter mekf: Sun vector by Sun-Albedo-Sun instead of the on-board albedo prediction")
    p.add_argument("--thermal-compensation", action="store_true",
                   help="--filter mekf: the gyro bias's temperature effect compensated on board (to 22 %%)")
    p.add_argument("--initial-error", type=float, metavar="DEG",
                   help="--filter mekf: start from the true attitude rotated by DEG instead of TRIAD")




def cmd_estimate(args):
    """Sensor chain + the thesis' estimators on a run: error table (and plots)."""
    _check_filter_options(args)
    if args.filter:
        return ESTIMATE_FILTERS[args.filter](args)
    from simcore.pipeline.evaluate import evaluate_run
    from simcore.pipeline.runfile import open_run
    from simcore.sensor.chain import DIODES
    if args.diode not in DIODES:
        raise InvalidInputError(f"--diode {args.diode} is unknown; use one of {', '.join(sorted(DIODES))}")
    ds = open_run(args.run)
    from simcore.environment.eclipse import sunlit
    if not np.any(sunlit(ds["illumination"].values)):
        msg = "no sunlit data (the whole span is in the Earth's shadow: no Sun vector to estimate)"
        print(json.dumps({"run": args.run, "table": [], "verdict": "no sunlit data"}) if args.json
              else f"{args.run}: {ds.attrs.get('configuration')}: {msg}")
        return 1
    if args.plots is not None:
        from simcore.studies.run_figures import default_plot_folder, write_error_plots
        args.plots = output_folder(args.plots or default_plot_folder(args.run), "--plots folder")
    errs, table, extra = evaluate_run(ds, diode=args.diode, noise=args.noise, seed=args.seed)
    if args.plots is not None:
        write_error_plots(ds, errs, extra["sunlit"], args.plots, noise=args.noise)
    if args.json:
        print(json.dumps({"run": args.run, "table": table}))
        return 0
    print(f"{args.run}: {ds.attrs.get('configuration')}, sunlit Sun-vector angle error [deg]"
          + (" (with sensor noise)" if args.noise else " (noise-free sensor chain)"))
    print(f"  {'estimator':<20} {'orbit':>5} {'n':>6} {'invalid':>7} {'mean':>7} {'p95':>7} {'max':>7}")
    for r in table:
        print(f"  {r['estimator']:<20} {str(r['orbit']):>5} {r['n']:>6} {r['n_invalid']:>7} "
              f"{r['mean_deg']:>7.2f} {r['p95_deg']:>7.2f} {r['max_deg']:>7.2f}")
    if args.plots:
        print(f"  plots: {args.plots}/error_*.png")
    return 0


def cmd_sweep(args):
    """Configurations x start dates x spin rates x seeds on Dask, into one dataset."""
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.sweep import sweep
    samples = args.samples
    base = RunOptions(tle=args.tle, satellite=args.satellite, duration_s=args.duration, step_s=args.step,
                      rel_se_direct=None if samples else args.accuracy[0],
                      rel_se_albedo=None if samples else args.accuracy[1],
                      direct_samples=samples[0] if samples else 1024, albedo_samples=samples[1] if samples else 256,
                      reflected_samples=args.reflected_samples, reflectivity=args.map, cloud_scale_km=args.cloud_scale_km, sun_disc=not args.point_sun,
                      chunk_epochs=args.chunk)
    clouds = args.clouds or [None]
    log = (lambda m: None) if args.json else print
    # Every point's numbers, dates and configuration are checked here, not in a Dask worker hours later.
    from scenes.config import SatelliteConfig
    from simcore.pipeline.preflight import check_numbers
    from simcore.pipeline.sweep import sweep_points
    for cfg in args.configs:
        SatelliteConfig.load(cfg)
    for point in sweep_points(base, args.configs[:1], args.starts, args.spin_rates, args.seeds, args.folder,
                              clouds=clouds):
        check_numbers(point)
    output_folder(args.folder, "--folder")
    path, ds = sweep(base, args.configs, args.starts, args.spin_rates, args.seeds, args.folder, clouds=clouds,
                     scheduler=args.scheduler, workers=args.workers, log=log)
    passed = int(ds["check_pass"].values.sum())
    out = {"sweep": path, "runs": int(ds.sizes["run"]), "checks_passed": passed}
    print(json.dumps(out) if args.json else f"sweep: {out['runs']} runs in {path}; analytic check passed in "
          f"{passed} of {out['runs']} (see 'sunsim validate' on the files in runs/)")
    return 0


def _sensor_errors_help(name):
    from simcore.sensor import errors as sensor_errors
    return getattr(sensor_errors, name).replace("%", "%%")


def cmd_spectral_check(args):
    """Spectral Monte Carlo (directions x wavelengths) vs the analytic albedo on each diode's band map: z table."""
    from simcore.pipeline import spectral_check as sc
    if not 1 <= args.epochs <= sc.SUNLIT_EPOCHS:
        raise InvalidInputError(f"--epochs must be 1 to {sc.SUNLIT_EPOCHS} (the default orbit is sunlit for "
                                f"{sc.SUNLIT_EPOCHS} epochs {sc.DEFAULT_STEP_S:g} s apart from {sc.DEFAULT_START}), "
                                f"got {args.epochs}")
    if args.samples < 64:
        raise InvalidInputError(f"--samples must be at least 64 directions per diode-epoch, got {args.samples}")
    wrong = {"flip_shares": args.flip_shares, "sampling_diode": args.sampling_diode}
    geometry = sc.default_geometry(args.epochs)
    rows = []
    for i, diode in enumerate(args.diode):
        c = sc.compare(diode, kind=args.map, n_epochs=args.epochs, samples=args.samples, seed=args.seed + i,
                       geometry=geometry, **wrong)
        pooled, largest = sc.limits(c.n)
        rows.append({"diode": c.label, "map": args.map, "n": c.n, "pooled_z": round(c.pooled_z, 3),
                     "max_abs_z": round(c.max_abs_z, 3), "pooled_limit": round(pooled, 3),
                     "max_limit": round(largest, 3), "median_rel_se": float(np.nanmedian(c.se / c.reference)),
                     "agrees": sc.agrees(c),
                     "entries": [{"epoch": int(n), "normal": c.normals[k], "spectral_w_m2": float(c.spectral[n, k]),
                                  "se_w_m2": float(c.se[n, k]), "band_map_w_m2": float(c.reference[n, k]),
                                  "z": float(c.z[n, k])} for n in range(c.z.shape[0]) for k in range(c.z.shape[1])]})
    if args.json:
        print(json.dumps({"wrong_input": {k: v for k, v in wrong.items() if v}, "rows": rows}))
    else:
        note = "".join([" WRONG INPUT: class shares flipped north-south." if args.flip_shares else "",
                        f" WRONG INPUT: wavelengths from {args.sampling_diode}'s band." if args.sampling_diode else ""])
        print(f"spectral check: Monte Carlo over directions and wavelengths (Mitsuba {sc.SPECTRAL_VARIANT}, srf = S E, "
              f"class shares x class spectra) vs the analytic albedo on the band map ({sc.REFINE}x{sc.REFINE} refined), "
              f"{args.epochs} epochs from {sc.DEFAULT_START} every {sc.DEFAULT_STEP_S:g} s x {len(sc.NORMALS_LOCAL)} "
              f"bare diode normals, {args.samples} directions x 4 wavelengths each; in-band W/m^2.{note}")
        print(f"{'diode':<26} {'map':<5} {'n':>3} {'pooled z':>9} {'max |z|':>8} {'limits':>12} {'rel SE':>7}  verdict")
        for r in rows:
            print(f"{r['diode']:<26} {r['map']:<5} {r['n']:>3} {r['pooled_z']:>9.2f} {r['max_abs_z']:>8.2f} "
                  f"{r['pooled_limit']:>5.2f}/{r['max_limit']:<6.2f} {r['median_rel_se']:>7.4f}  "
                  f"{'agrees' if r['agrees'] else 'DIFFERS'}")
            if args.verbose:
                for e in r["entries"]:
                    print(f"    epoch {e['epoch']} {e['normal']:<16} spectral {e['spectral_w_m2']:9.4f} "
                          f"+- {e['se_w_m2']:.4f}  band map {e['band_map_w_m2']:9.4f}  z {e['z']:6.2f}")
        print(f"limits: |pooled z| and max |z| at a false-alarm rate of {sc.FALSE_ALARM:g} per diode")
    return 0 if all(r["agrees"] for r in rows) else 1


def _add_spectral_check_parser(sub):
    """Add ``sunsim spectral-check`` to the subparsers."""
    from simcore.radiometry.band import DEFAULT_DIODE
    p = sub.add_parser("spectral-check", help="spectral Monte Carlo (Mitsuba llvm_ad_spectral, the diode's band) "
                                              "vs the band maps: z table (exit 1 when they differ)")
    p.add_argument("--diode", nargs="+", default=[DEFAULT_DIODE, "SFH2430", "BPW34"], metavar="D",
                   help="diodes with a band (default: %(default)s)")
    p.add_argument("--map", choices=["clear", "all"], default="clear", help="band map kind (default %(default)s)")
    p.add_argument("--epochs", type=int, default=6, help="sunlit epochs of the default orbit (default %(default)s)")
    p.add_argument("--samples", type=int, default=1 << 16, help="directions per diode-epoch (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first diode (the next ones: +1, +2, ...)")
    p.add_argument("--flip-shares", action="store_true", help="WRONG INPUT on purpose: class shares read "
                                                              "north-south flipped (the check must fail)")
    p.add_argument("--sampling-diode", metavar="D", help="WRONG INPUT on purpose: draw the wavelengths from this "
                                                          "diode's band (the check must fail)")
    p.add_argument("-v", "--verbose", action="store_true", help="one line per diode-epoch and normal")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_spectral_check)
    return p


def build_parser():
    p = OneLineParser(prog="sunsim", description="Ray-traced CubeSat coarse sun sensor simulator.")
    p.add_argument("--version", action="version", version=f"sunsim {__version__}")
    p.add_argument("--debug", action="store_true",
                   help="show the full traceback of a user error too (accepted anywhere on the line)")
    sub = p.add_subparsers(dest="command")

    r = sub.add_parser("run", help="the main job: render a study (default: ESTCube-1, 2016-07-02, tilt20_fov70, "
                                   "one orbit at 1 s), check it, write netCDF")
    _add_orbit_options(r, ephemeris=True)
    _add_render_options(r)
    r.add_argument("--fail-on-check", dest="fail_on_check", action="store_true", default=True,
                   help="exit status 1 when the analytic check fails (the default; kept for older scripts)")
    r.add_argument("--no-fail-on-check", dest="fail_on_check", action="store_false",
                   help="exit status 0 even when the analytic check fails (default: 1; the file is written either way)")
    r.add_argument("--json", action="store_true", help="machine-readable output")
    r.set_defaults(func=cmd_run)

    c = sub.add_parser("coverage", help="HEALPix coverage fractions red/yellow/green and a Mollweide map")
    c.add_argument("configs", nargs="+", metavar="CONFIG", help="configuration names or .toml files")
    c.add_argument("--dead", type=int, nargs="*", default=[], metavar="I", help="dead diode indices")
    c.add_argument("--plot-dir", default="runs", help="folder for the map PNGs (default: %(default)s)")
    c.add_argument("--no-plot", action="store_true", help="fractions only")
    c.add_argument("--json", action="store_true", help="one JSON object per configuration")
    c.set_defaults(func=cmd_coverage)

    v = sub.add_parser("view", help="an annotated picture of the scene at one epoch: materials in colour, diodes "
                                    "numbered, the Sun's direction, the Earth coloured by its reflectivity map")
    v.add_argument("config_pos", nargs="?", metavar="CONFIG", help="configuration (same as --config)")
    v.add_argument("--config", metavar="NAME_OR_TOML",
                   help="a shipped configuration name or a .toml file (default tilt20_fov70)")
    v.add_argument("--time", default="2016-07-02T00:40:00Z", metavar="ISO",
                   help="UTC epoch of the picture (default %(default)s: 40 min into the default run, in sunlight)")
    v.add_argument("--close-up", action="store_true",
                   help="the satellite alone (no Earth) from two opposite sides, so every diode number shows")
    v.add_argument("--map", default=None, help="reflectivity map colouring the Earth, as for `run` (default toms2005)")
    _add_cloud_options(v)
    v.add_argument("--tle", metavar="FILE", help=DEFAULT_TLE_HELP)
    v.add_argument("--satellite", metavar="NAME_OR_ID", help="satellite in a multi-satellite TLE file")
    v.add_argument("--start", default="2016-07-02T00:00:00Z",
                   help="the run's start, where its tumble begins aligned with GCRS (default: %(default)s)")
    v.add_argument("--spin-rate", type=float, default=1.9, metavar="DEG_S", action=NotedGiven,
                   help="tumble rate about the body diagonal (default: %(default)s deg/s, thesis)")
    v.add_argument("--attitude", metavar="CSV", help="attitude history t_s,qw,qx,qy,qz whose first row is --start "
                                                      "(overrides the tumble), as for `run`")
    v.add_argument("-o", "--output", default=None, metavar="FILE.png",
                   help="PNG file (default runs/scene_CONFIG.png, runs/scene_CONFIG_close.png with --close-up)")
    v.add_argument("--spp", type=int, default=64, help="samples per pixel (default %(default)s)")
    v.add_argument("--resolution", type=int, nargs=2, default=(960, 540), metavar=("W", "H"),
                   help="picture size in pixels (default 960 540)")
    v.add_argument("--seed", type=int, default=0, help="random seed of the render")
    v.add_argument("--json", action="store_true")
    v.set_defaults(func=cmd_view)

    rs = sub.add_parser("response", help="the traced angular response of each diode (Sun swept from its normal to "
                                          "90 deg) beside cosine, eq. 4.15 and a fitted Basilisk Kelly curve")
    rs.add_argument("config", metavar="CONFIG", help="a shipped configuration name or a .toml file")
    rs.add_argument("--diode", type=int, nargs="+", metavar="K", help="diode indices (default: all)")
    rs.add_argument("--plane", default="x", choices=("x", "y"),
                    help="sweep in the diode's u-n (x) or v-n (y) plane (default %(default)s)")
    rs.add_argument("--step", type=float, default=5.0, metavar="DEG", help="angle step (default %(default)s deg)")
    rs.add_argument("--samples", type=int, default=4096, metavar="N",
                    help="direct-Sun samples per diode and angle, 4 m^2 (default %(default)s)")
    rs.add_argument("--map-step", type=float, default=None, metavar="DEG",
                    help="also the response over the whole hemisphere on this grid (e.g. 3)")
    rs.add_argument("--plot", metavar="FILE.png", help="plot per diode (FILE_dK.png for several; _map for the map)")
    rs.add_argument("--seed", type=int, default=0, help="random seed")
    rs.add_argument("--variant", default=None, help="Mitsuba variant (default: llvm_ad_mono, CUDA when asked)")
    rs.add_argument("--json", action="store_true", help='one JSON object: {"diodes": [{"index", "theta_deg", '
                                                         '"response", "response_se", "reflected", ...}]}')
    rs.set_defaults(func=cmd_response)

    va = sub.add_parser("validate", help="rendered-vs-analytic report of a run file (exit 1 outside tolerance)")
    va.add_argument("run", metavar="RUN.nc")
    va.add_argument("--recompute-analytic", action="store_true",
                    help="recompute the analytic model with this sunsim first (keeps the rendered numbers)")
    va.add_argument("--json", action="store_true")
    va.set_defaults(func=cmd_validate)

    ex = sub.add_parser("export", help="a run's readings (csv: irradiance, photocurrent, ADC counts), attitude (aem), "
                                       "orbit (oem) or Basilisk CSS values (basilisk) to a file (docs/ccsds.md)")
    ex.add_argument("run", metavar="RUN.nc")
    ex.add_argument("--format", required=True, choices=["csv", "aem", "oem", "basilisk"])
    ex.add_argument("-o", "--output", metavar="FILE", help="default: beside RUN.nc (_readings.csv, .aem, .oem, "
                    "_basilisk.csv)")
    ex.add_argument("--diode", default="BPW34FS", help="csv: the photodiode part of the sensor chain (default %(default)s)")
    ex.add_argument("--noise", action="store_true", help="csv: shot and Johnson noise in the sensor chain")
    ex.add_argument("--seed", type=int, default=0, help="csv: seed of the noise (default %(default)s)")
    ex.set_defaults(func=cmd_export)

    e = sub.add_parser("estimate", help="sensor chain + the thesis' estimators on a run file: error table")
    e.add_argument("run", metavar="RUN.nc")
    e.add_argument("--diode", default="BPW34FS", help="diode type (BPW34FS, SFH2430, BPW34FAS, BPV23F)")
    e.add_argument("--noise", action="store_true", help="shot and Johnson noise in the sensor chain")
    e.add_argument("--seed", type=int, default=0, help="noise seed")
    e.add_argument("--plots", metavar="DIR", nargs="?", const="",
                   help="write error plots (PNG, one y range for all estimators) to DIR (default: RUN_plots/ "
                        "beside the run file)")
    e.add_argument("--filter", choices=sorted(ESTIMATE_FILTERS),
                   help="run a filter instead of the thesis' estimators: sunline-ekf|sunline-ukf (Sun vector and "
                        "body rate; WLS and Sun-Albedo-Sun listed beside it) or mekf (attitude from gyro, "
                        "magnetometer and Sun sensor; sensor noise on)")
    e.add_argument("--faults", metavar="SPEC", help=_sensor_errors_help("FAULTS_HELP"))
    e.add_argument("--sensor-errors", metavar="SPEC", help=_sensor_errors_help("SENSOR_ERRORS_HELP"))
    e.add_argument("--gyro-noise", type=float, metavar="DEG_S",
                   help="give a sun-line filter a gyro: the run's true body rate plus white noise of this standard "
                        "deviation")
    e.add_argument("--use-threshold", type=float, metavar="U", help="sun-line filters: readings used from U up "
                   "(normal-Sun units, Basilisk's sensorUseThresh; default 5 sigma of the noise)")
    e.add_argument("--process-noise", metavar="Q_RATE[:Q_SUN]", help="sun-line filters: rate random walk "
                   "(rad^2/s^3) and Sun-vector process noise (1/s), default 1e-13:0")
    _add_mekf_options(e)
    e.add_argument("--json", action="store_true")
    e.set_defaults(func=cmd_estimate)

    w = sub.add_parser("sweep", help="configurations x start dates x spin rates x seeds (x cloud seeds) on Dask, "
                                     "into one dataset")
    w.add_argument("--configs", nargs="+", default=["tilt20_fov70"], metavar="CONFIG")
    w.add_argument("--starts", nargs="+", default=["2016-07-02T00:00:00Z"], metavar="ISO")
    w.add_argument("--spin-rates", nargs="+", type=float, default=[1.9], metavar="DEG_S")
    w.add_argument("--seeds", nargs="+", type=int, default=[0], metavar="SEED")
    w.add_argument("--duration", type=float, default=None, metavar="S", help="seconds per run (default: one orbit)")
    w.add_argument("--step", type=float, default=1.0, metavar="S")
    w.add_argument("--tle", metavar="FILE", help=DEFAULT_TLE_HELP)
    w.add_argument("--satellite", metavar="NAME_OR_ID")
    w.add_argument("--accuracy", nargs=2, type=float, metavar=("DIRECT", "ALBEDO"), default=(0.002, 0.01))
    w.add_argument("--samples", nargs=2, type=int, metavar=("DIRECT", "ALBEDO"))
    _add_reflected_samples(w)
    w.add_argument("--map", default="toms2005")
    _add_cloud_options(w, many=True)
    w.add_argument("--point-sun", action="store_true")
    w.add_argument("--chunk", type=int, default=512, metavar="EPOCHS")
    w.add_argument("--folder", default="runs/sweep", help="where the runs and sweep.nc go (default %(default)s)")
    w.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (default: a local cluster)")
    w.add_argument("--workers", type=int, default=2, help="workers of the local cluster (default %(default)s)")
    w.add_argument("--json", action="store_true")
    w.set_defaults(func=cmd_sweep)

    add_study_parsers(sub)
    _add_spectral_check_parser(sub)
    from simcore.studies.flight_cli import add_parser as _add_flight_check_parser
    _add_flight_check_parser(sub)

    s = sub.add_parser("summary", help="orbit, Sun and eclipse summary of a study (no rendering)")
    _add_orbit_options(s)
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_summary)
    return p


def main(argv=None):
    """Run the sunsim command line; return the exit status (2: a user mistake, told in one line)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # --debug is accepted anywhere on the line, so a failing command can be repeated with it appended.
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        args = parser.parse_args(["run"] + argv)
    try:
        from simcore.pipeline.arguments import check_arguments
        return args.func(check_arguments(args))          # every command's options checked before any work
    except UserError as exc:
        if debug:
            raise
        print(f"sunsim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sunsim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of stdout went away (``sunsim validate RUN | head``): stop quietly, as other Unix tools do;
        # stdout now points at /dev/null so that the interpreter's final flush does not fail again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
