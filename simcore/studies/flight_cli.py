"""``sunsim flight-check SATELLITE``: its options and what it prints (the command line keeps one line for it).

Without ``--fit`` it predicts and compares (:mod:`simcore.studies.flight`); with ``--fit`` it calibrates the diode
normals on the shipped telemetry and writes the scene's diode block; ``--study DIR`` renders the results page's
variants into ``DIR/results.json`` and ``--page DIR`` writes the page from that file
(:mod:`simcore.studies.flight_page`).
"""
import json
import os

import numpy as np

from simcore.errors import InvalidInputError


def add_parser(sub):
    """Add ``sunsim flight-check`` to the command line's subparsers ``sub``."""
    p = sub.add_parser("flight-check", help="predicted photodiode readings against a satellite's flight telemetry "
                                            "(OPS-SAT), never fitted; --fit calibrates the scene's diodes")
    add_arguments(p)
    p.set_defaults(func=main)
    return p


def add_arguments(p):
    """Add the options of ``sunsim flight-check`` to the parser ``p``."""
    from simcore.studies.flight import DEFAULT_MAP, SATELLITES
    p.add_argument("satellite", choices=sorted(SATELLITES), help="the satellite (its scene and shipped telemetry)")
    p.add_argument("--pd", metavar="FILE", help="photodiode readings (the labelled PD file; or a 2021-style "
                                                "on-board log holding readings and quaternions; default: the "
                                                "shipped 2020 week)")
    p.add_argument("--attitude", metavar="FILE", help="attitude history (the GRAINS export; default: the shipped "
                                                      "2020 week's, none with a log)")
    p.add_argument("--tle", metavar="FILE", help="TLE of the telemetry's days (default: the shipped 2020-11-06 set)")
    p.add_argument("--config", metavar="SCENE", help="the satellite's scene (default scenes/examples/opssat.toml)")
    p.add_argument("--map", default=DEFAULT_MAP, help="reflectivity map of the prediction (default %(default)s: "
                                                      "the best on the shipped week, docs/flight_opssat/)")
    p.add_argument("--clouds", type=int, metavar="SEED", help="cloud weather (a realisation of --map)")
    p.add_argument("--seed", type=int, default=0, help="renderer seed (default %(default)s)")
    p.add_argument("--runs", default="runs/flight-check", metavar="DIR",
                   help="where the run files go (an identical earlier run is reused; default %(default)s)")
    p.add_argument("--json", action="store_true", help="print the comparison as JSON")
    p.add_argument("--plots", metavar="DIR", help="write the comparison's figures into DIR")
    p.add_argument("--fit", action="store_true",
                   help="calibrate the diode normals on the shipped telemetry (2020 week with the albedo on "
                        "--map; the 2021 logs by the direct Sun alone) and write the scene's diode block")
    p.add_argument("--study", metavar="DIR", help="render the results page's variants and write DIR/results.json")
    p.add_argument("--page", metavar="DIR", help="write the results page DIR/README.md (+ figures) from "
                                                 "DIR/results.json")


def _paths(args):
    from simcore.studies.flight import satellite
    sat = satellite(args.satellite)
    if args.pd is None and args.attitude is not None:
        raise InvalidInputError("--attitude without --pd: give the readings of the same days with --pd")
    pd = args.pd or str(sat.pd)
    from simcore.studies.flight import _is_log
    if not os.path.isfile(pd):
        from simcore.errors import InputNotFoundError
        raise InputNotFoundError(f"--pd {pd} not found; give an existing file")
    attitude = args.attitude if args.pd else str(sat.attitude)
    if args.pd and args.attitude is None and not _is_log(pd):
        raise InvalidInputError(f"--pd {pd} holds readings only; give its attitude history with --attitude")
    tle = args.tle or str(sat.tle)
    scene = args.config or str(sat.scene)
    for what, path in (("--tle", tle), ("--config", scene)):
        if not os.path.isfile(path):
            from simcore.errors import InputNotFoundError
            raise InputNotFoundError(f"{what} {path} not found; give an existing file")
    from simcore.pipeline.preflight import check_model_inputs
    check_model_inputs(scene, tle, args.map, args.clouds)      # before the telemetry is read or a folder made
    return sat, pd, attitude, tle, scene


def main(args):
    """Run ``sunsim flight-check``; return the exit status (1 where the attitude check or the run's check fails)."""
    from simcore.studies import flight as F
    if args.page:
        from simcore.studies.flight_page import write_page
        path = write_page(args.page)
        print(f"sunsim flight-check: page {path}")
        return 0
    if args.fit and (args.pd or args.attitude or args.tle):
        raise InvalidInputError("--fit calibrates on the shipped telemetry only (the 2020 week and the 2021 logs); "
                                "leave out --pd/--attitude/--tle (they are for testing the prediction)")
    sat, pd, attitude, tle, scene = _paths(args)
    if args.fit:
        return _fit(args, sat, pd, attitude, tle, scene)
    if args.study:
        from simcore.studies.flight_page import run_study
        path = run_study(args.study, sat, pd, attitude, tle, scene, runs=args.runs, log=print)
        print(f"sunsim flight-check: results {path}; write the page with "
              f"`sunsim flight-check {sat.name} --page {args.study}`")
        return 0
    tel = F.load_telemetry(pd, None if F._is_log(pd) else attitude)
    pred = F.predict(tel, scene, tle, args.map, clouds=args.clouds, seed=args.seed, folder=args.runs)
    out = F.compare(tel, pred)
    out["inputs"] = {"pd": pd, "attitude": None if F._is_log(pd) else attitude, "tle": tle, "scene": scene,
                     "map": args.map, "clouds": args.clouds, "seed": args.seed}
    if args.plots:
        from simcore.studies.flight_page import comparison_figures
        arrays = F.sample_arrays(tel, pred, {n: d["uniform_albedo"] for n, d in out["diodes"].items()}, args.map)
        out["plots"] = [os.path.join(args.plots, f) for f in comparison_figures(arrays, tel.names, args.plots,
                                                                                  model_key=args.map)]
    ok = out["check_pass"] and all(d["attitude_check"]["pass"] for d in out["diodes"].values())
    if args.json:
        print(json.dumps(out))
    else:
        _print(out)
    return 0 if ok else 1


def _print(out):
    s = out["samples"]
    print(f"sunsim flight-check: {s['trusted_attitude']} of {s['telemetry']} readings with a trusted attitude, "
          f"{s['sunlit']} sunlit; run {out['run']} (analytic check {'PASS' if out['check_pass'] else 'FAIL'})")
    print(f"  {'diode':6} {'n':>6} {'median |res|':>13} {'direct only':>12} {'uniform':>8} {'albedo':>7} "
          f"{'sun behind':>11}")
    for name, d in out["diodes"].items():
        if not d["n"]:
            print(f"  {name:6} {0:6d}   (no valid sunlit reading)")
            continue
        print(f"  {name:6} {d['n']:6d} {d['median_abs_residual']:13.4f} {d['median_abs_residual_direct_only']:12.4f} "
              f"{d['median_abs_residual_uniform']:8.4f} {d['uniform_albedo']:7.2f} "
              f"{d['sun_behind_median_residual'] if d['sun_behind_median_residual'] is not None else float('nan'):11.4f}")
        c = d["attitude_check"]
        if not c["pass"]:
            print(f"  {name}: attitude check FAILED: {c['dark_predicted']} of {c['n']} readings >= 0.5 are "
                  "predicted nearly dark: is the quaternion's convention (direction, scalar first/last, frame) right?")
    print("  cos(incidence) bins: median residual (model / direct only / uniform)")
    for name, d in out["diodes"].items():
        cells = [f"[{b['lo']:g},{b['hi']:g}) n={b['n']}: "
                 + "/".join("-" if b[k] is None else f"{b[k]:+.3f}" for k in
                            ("median_residual", "median_residual_direct_only", "median_residual_uniform"))
                 for b in d["bins"] if b["n"]]
        if cells:
            print(f"  {name}: " + "; ".join(cells))


def _fit(args, sat, pd, attitude, tle, scene):
    """Fit the normals on the shipped data only, write the scene's diode block, print the fit's residuals."""
    from simcore.studies import flight as F
    week = F.load_telemetry(pd, attitude)
    normals, info = F.fit_normals(week, tle, sat.mounts, args.map)
    logs = F.merge_logs([F.load_telemetry(p) for p in sat.logs])
    others = [n for n in logs.names if n not in normals]
    logs = F.Telemetry(logs.epochs, {n: logs.readings[n] for n in others}, logs.history, logs.source,
                       logs.dropped, logs.total)
    n2, info2 = F.fit_normals(logs, sat.logs_tle, sat.mounts, albedo=False)
    notes = {}
    for src, (fitted, inf) in (("the 2020 week, direct Sun + albedo on " + args.map, (normals, info)),
                               ("the 2021 logs, direct Sun alone", (n2, info2))):
        for name in fitted:
            i = inf[name]
            notes[name] = (f"fitted on {src}: {i['n']} samples, scale {i['scale']:.3f}, median |res| "
                           f"{i['median_abs_residual']:.4f}" if i["constrained"] else
                           f"NOT constrained by {src} (fit {i['off_axis_deg']:.0f} deg off its panel, median |res| "
                           f"{i['median_abs_residual']:.3f}): the panel's axis")
    normals.update(n2)
    info.update(info2)
    F.write_diode_block(scene, normals, sat.mounts, notes)
    out = {name: {"normal": [round(float(x), 6) for x in normals[name]],
                  **{k: (round(v, 5) if isinstance(v, float) else v) for k, v in info[name].items()
                     if k != "fitted_normal"}}
           for name in sorted(normals)}
    if args.json:
        print(json.dumps({"scene": scene, "fit": out}))
        return 0
    print(f"sunsim flight-check --fit: wrote the diode block of {scene}")
    print(f"  {'diode':6} {'normal (body)':>30} {'off axis':>9} {'scale':>6} {'n':>6} {'median |res|':>13} "
          f"{'median res':>11}")
    for name, d in out.items():
        nrm = ", ".join(f"{x:+.4f}" for x in d["normal"])
        print(f"  {name:6} {nrm:>30} {d['off_axis_deg']:7.2f} deg {d['scale']:6.3f} {d['n']:6d} "
              f"{d['median_abs_residual']:13.4f} {d['median_residual']:+11.4f}"
              + ("" if d["constrained"] else "  not constrained: the panel's axis written"))
    return 0
