"""The study commands of ``sunsim``: ``reproduce``, ``earth-study``, ``aperture-sweep`` and ``attitude-study``,
each one's options and what it prints (the command line adds them with :func:`add_study_parsers`)."""
import json
import sys

from simcore.commands.output import output_folder


def add_study_parsers(sub):
    """Add ``sunsim reproduce``, ``earth-study``, ``aperture-sweep`` and ``attitude-study`` to the subparsers."""
    rp = sub.add_parser("reproduce", help="the thesis' chapter-4 study on rendered irradiance, with a results page")
    _add_page_study_options(rp, folder="runs/thesis", page="FOLDER/page",
                            span_help="the whole day at 1 s, the thesis' two orbits 1.8e4-2.8e4 s, or a 600 s "
                                      "demonstration")
    rp.add_argument("--second-spin", type=float, default=0.5, metavar="DEG_S",
                    help="second tumble rate, rendered over the two orbits (default %(default)s)")
    rp.add_argument("--no-render", action="store_true", help="evaluate only the run files already there")
    rp.add_argument("--json", action="store_true")
    rp.set_defaults(func=cmd_reproduce)

    es = sub.add_parser("earth-study", help="the thesis' open question: Sun-vector error with the truth on the band "
                                            "map + glint + cloud weather, the on-board model on TOMS, CERES or the "
                                            "band map; a results page")
    _add_page_study_options(es, folder="runs/earth_band", page="FOLDER/earth_band",
                            span_help="the whole day at 1 s (as reproduce), 1e4 s from 05:00Z, or a 600 s "
                                      "demonstration")
    es.add_argument("--wind", type=float, default=7.0, metavar="M_S",
                    help="sea wind speed of the glint truths, m/s at 12.5 m (default %(default)s)")
    es.add_argument("--cloud-seeds", type=int, nargs="+", default=[1], metavar="SEED",
                    help="cloud-weather seeds: one truth C each (default 1)")
    es.add_argument("--json", action="store_true")
    es.set_defaults(func=cmd_earth_study)

    ap = sub.add_parser("aperture-sweep", help="aperture height x tilt x FOV -> coverage, albedo fraction seen, "
                                               "estimator error over an orbit")
    _add_aperture_sweep_options(ap)
    ap.add_argument("--json", action="store_true")
    ap.set_defaults(func=cmd_aperture_sweep)

    _add_attitude_study_parser(sub)


def cmd_reproduce(args):
    """The thesis' chapter-4 study on rendered irradiance: renders what is missing, writes the results page."""
    from simcore.studies.reproduce import refuse_existing_failed, reproduce
    log = (lambda m: print(m, file=sys.stderr))
    plan = {"span": args.span, "render": not args.no_render, "cross_map": args.span != "short",
            "second_spin": None if args.span == "short" else args.second_spin}
    if not args.allow_failed_checks:      # before any folder is made or anything rendered
        refuse_existing_failed(args.folder, **plan)
    output_folder(args.folder, "--folder")
    if args.page:
        output_folder(args.page, "--page")
    res = reproduce(args.folder, page_folder=args.page, log=log, noise=True,
                    allow_failed_checks=args.allow_failed_checks, **plan)
    page = args.page or f"{args.folder}/page"
    failed = [c for c, r in res["configs"].items() if not r["check_pass"]]
    if args.json:
        print(json.dumps({"page": page, "configs": list(res["configs"]), "checks_failed": failed}))
    else:
        print(f"results page: {page}/README.md ({len(res['configs'])} configurations, span {args.span})"
              + (f"; check FAILED, marked on the page: {', '.join(failed)}" if failed else ""))
    return 0


def cmd_earth_study(args):
    """The thesis' open question (sec. 5.2): Sun-vector error with a band-aware, glinting, cloudy Earth and
    the on-board model on TOMS, CERES or the band map; renders what is missing, writes the results page."""
    from simcore.studies.earth_band import check_inputs, earth_study, refuse_existing_failed
    log = (lambda m: print(m, file=sys.stderr))
    check_inputs(args.span, args.wind, args.cloud_seeds)          # before any folder is made
    plan = {"span": args.span, "wind_m_s": args.wind, "cloud_seeds": args.cloud_seeds}
    if not args.allow_failed_checks:      # before any folder is made or anything rendered
        refuse_existing_failed(args.folder, **plan)
    output_folder(args.folder, "--folder")
    if args.page:
        output_folder(args.page, "--page")
    res = earth_study(args.folder, page_folder=args.page, allow_failed_checks=args.allow_failed_checks, log=log,
                      **plan)
    page = args.page or f"{args.folder}/earth_band"
    failed = [label for label, r in res["runs"].items() if not r["check_pass"]]
    if args.json:
        print(json.dumps({"page": page, "runs": list(res["runs"]), "checks_failed": failed}))
        return 0
    from simcore.studies.earth_band_page import HEADLINE_ESTIMATOR, verdict
    print(f"results page: {page}/README.md ({len(res['runs'])} runs, span {args.span})"
          + (f"; check FAILED, marked on the page: {', '.join(failed)}" if failed else ""))
    for cfg in res["configs"]:
        toms, ceres, clouds, words = verdict(res, cfg)
        fmt = lambda x: "-" if x is None else f"{x:.2f}"  # noqa: E731
        print(f"  {cfg} ({HEADLINE_ESTIMATOR}), own RMS effect on the Sun estimate: TOMS instead of the band map "
              f"{fmt(toms)} deg, CERES {fmt(ceres)} deg, cloud weather {fmt(clouds)} deg: {words}")
    return 0


def _add_page_study_options(p, *, folder, page, span_help):
    """Add the options of a study with a results page: --span, --folder, --page, --allow-failed-checks."""
    p.add_argument("--span", choices=["day", "orbits", "short"], default="day", help=span_help)
    p.add_argument("--folder", default=folder, help="where the run files go (default %(default)s)")
    p.add_argument("--page", help=f"where the results page goes (default {page})")
    p.add_argument("--allow-failed-checks", action="store_true",
                   help="use runs whose analytic check failed (refused by default) and mark their numbers "
                        "'check FAILED' on the page")


def _none_or_float(text):
    return None if text.lower() in ("none", "eq415", "design") else float(text)


def _add_aperture_sweep_options(p):
    """Add the aperture sweep's options: --heights (mm; 'eq415' = the eq. 4.15 design), --tilts (deg),
    --fovs (deg), --step (s), --dead, -o/--out."""
    p.add_argument("--heights", nargs="+", type=_none_or_float, default=[0.3, 0.5, 1.0],
                   help="well heights in mm ('eq415': the eq. 4.15 design height for each FOV)")
    p.add_argument("--tilts", nargs="+", type=float, default=[20.0, 25.0, 30.0], help="ramp tilts in deg")
    p.add_argument("--fovs", nargs="+", type=float, default=[70.0, 75.0], help="FOVs in deg (full response up to it)")
    p.add_argument("--step", type=float, default=20.0, help="orbit sampling step in s (one orbit)")
    p.add_argument("--dead", nargs="*", type=int, default=[0], help="dead diode indices (thesis: 0)")
    p.add_argument("-o", "--out", required=True, help="output folder")


def cmd_aperture_sweep(args):
    """Aperture height x tilt x FOV -> coverage, albedo fraction, estimator errors over one orbit."""
    from simcore.studies.aperture import run_aperture_sweep
    rows = run_aperture_sweep(args.out, args.heights, args.tilts, args.fovs, step_s=args.step, dead=tuple(args.dead),
                              log=(lambda m: None) if args.json else (lambda m: print(m, file=sys.stderr)))
    if args.json:
        print(json.dumps({"out": args.out, "rows": len(rows)}))
    else:
        print(f"aperture sweep: {len(rows)} combinations; table and plot in {args.out} (sweep.md, sweep.csv, sweep.png)")
    return 0


def cmd_attitude_study(args):
    """MEKF per configuration x gyro x on-board albedo x seed on rendered runs, with a results page."""
    from simcore.studies.attitude import attitude_study, default_page
    log = (lambda m: print(m, file=sys.stderr))
    if args.rate:
        from simcore.studies.rate import rate_study
        page = rate_study(args.rate, args.page or "docs/attitude_study", gyros=args.gyros, seeds=args.seeds, log=log)
        print(f"rate section: {page}")
        return 0
    res = attitude_study(args.folder, span=args.span, configs=args.configs, gyros=args.gyros, seeds=args.seeds,
                         magnetometer=args.magnetometer, page_folder=args.page, render=not args.no_render,
                         scheduler=args.scheduler, workers=args.workers,
                         thermal_compensation=args.thermal_compensation, log=log)
    page = args.page or default_page(args.folder, args.span, args.thermal_compensation)
    if args.json:
        print(json.dumps({"page": page, "rows": len(res["rows"])}))
    else:
        print(f"results page: {page}/README.md ({len(res['rows'])} evaluations)")
    return 0


def _add_attitude_study_parser(sub):
    """Add ``sunsim attitude-study`` to the subparsers."""
    from simcore.studies.choices import CONFIGS, GYROS, SPANS
    p = sub.add_parser("attitude-study", help="attitude error per configuration x gyro (MEKF on rendered runs, "
                                              "seeds on Dask), with a results page")
    p.add_argument("--span", choices=list(SPANS), default="orbits",
                   help="the run files of 'sunsim reproduce' to use or render (default %(default)s)")
    p.add_argument("--folder", default="runs/thesis", help="run files (shared with sunsim reproduce)")
    p.add_argument("--page", help="results page folder (default FOLDER/attitude_SPAN[_compensated])")
    p.add_argument("--configs", nargs="+", default=list(CONFIGS), metavar="CONFIG")
    p.add_argument("--gyros", nargs="+", default=list(GYROS), metavar="NAME")
    p.add_argument("--magnetometer", default="HMC5883L", metavar="NAME")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], metavar="SEED")
    p.add_argument("--no-render", action="store_true", help="use only the run files already there")
    p.add_argument("--thermal-compensation", action="store_true",
                   help="gyro bias temperature effect compensated on board (to 22 %%)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, default=2, help="workers of the local cluster (default %(default)s)")
    p.add_argument("--rate", metavar="RUN.nc", help="only the rate section (simcore/studies/rate.py) from this run, "
                   "into PAGE (default docs/attitude_study): rate.md, rate_results.json, rate_error.png")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_attitude_study)
    return p
