"""The ``sunsim`` command line."""
import argparse
import json
import sys

import numpy as np

import simcore

DEFAULT_TLE_HELP = "TLE file (2- or 3-line; default: the shipped ESTCube-1 set, epoch 2016-07-27)"


class UserError(Exception):
    """A mistake in what the user asked for: printed as one line, exit status 2."""


def _orbit(args):
    from simcore.orbit import Orbit
    if args.tle is None:
        return Orbit.default()
    return Orbit.from_file(args.tle, satellite=args.satellite)


def _add_orbit_options(p):
    p.add_argument("--tle", metavar="FILE", help=DEFAULT_TLE_HELP)
    p.add_argument("--satellite", metavar="NAME_OR_ID", help="satellite in a multi-satellite TLE file")
    p.add_argument("--start", default="2016-07-02T00:00:00Z", help="first epoch, ISO-8601 UTC (default: %(default)s)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="seconds to simulate (default: one orbital period)")
    p.add_argument("--step", type=float, default=1.0, metavar="S", help="seconds between epochs (default: %(default)s)")
    p.add_argument("--spin-rate", type=float, default=1.9, metavar="DEG_S",
                   help="tumble rate about the body diagonal (default: %(default)s deg/s, thesis)")


def _geometry(args):
    from simcore import attitude
    from simcore.epochs import Epochs
    from simcore.study import compute_geometry, orbital_period_s
    orbit = _orbit(args)
    duration = orbital_period_s(orbit) if args.duration is None else args.duration
    epochs = Epochs.range(args.start, duration, args.step)
    att = attitude.tumble(epochs.seconds_since(epochs[0]), rate_deg_s=args.spin_rate)
    return orbit, compute_geometry(orbit, epochs, att)


def cmd_summary(args):
    """Orbit / Sun / eclipse summary of a study (what `run` shows before rendering)."""
    from simcore.constants import R_EARTH_MEAN_M
    from simcore.study import eclipse_events, orbital_period_s
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
        "sunlit_fraction": round(float(np.nanmean(g.illumination >= 1.0)), 4),
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


def build_parser():
    p = argparse.ArgumentParser(prog="sunsim", description="Ray-traced CubeSat coarse sun sensor simulator.")
    p.add_argument("--version", action="version", version=f"sunsim {simcore.__version__}")
    sub = p.add_subparsers(dest="command")

    s = sub.add_parser("summary", help="orbit, Sun and eclipse summary of a study")
    _add_orbit_options(s)
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_summary)

    r = sub.add_parser("run", help="the main job: the default study (currently its orbit/Sun/eclipse summary)")
    _add_orbit_options(r)
    r.add_argument("--json", action="store_true", help="machine-readable output")
    r.set_defaults(func=cmd_summary)
    return p


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        args = parser.parse_args(["run"] + list(argv or []))
    try:
        return args.func(args)
    except (UserError, ValueError, TypeError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"sunsim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sunsim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
