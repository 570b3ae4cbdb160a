"""The checks of a parsed command line, per command, before the command does anything.

:func:`check_arguments` is called by :func:`simcore.cli.main` on argparse's namespace before the command's
function runs. It refuses (one :class:`~simcore.errors.UserError`) what can be told from the options alone:
seeds, rates, winds, picture sizes, conflicting options, worker counts, a missing optional dependency.
Checks that need the files read or the geometry computed run in :func:`simcore.pipeline.run.prepare` and the
other pipeline entry points, all through the functions of :mod:`simcore.pipeline.preflight`.
"""
import argparse
import difflib
import re
import sys

from simcore.errors import InvalidInputError
from simcore.pipeline import preflight

# the largest picture side `sunsim view` draws (pixels)
VIEW_MAX_SIDE = 16384


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (what is wrong, a close match for a mistyped choice or
    command, where the help is) instead of the usage block and the error."""

    def error(self, message):
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = re.findall(r"'([^']*)'", m.group(2))
            close = difflib.get_close_matches(m.group(1), choices, n=1, cutoff=0.6)
            message += f"; did you mean '{close[0]}'?" if close else ""
        print(f"{self.prog}: error: {message}; see '{self.prog} --help'", file=sys.stderr)
        sys.exit(2)


class NotedGiven(argparse.Action):
    """argparse's plain store, noting that the option was given (``args.<dest>_given``): a value the user typed
    can then be told from the default (--spin-rate next to --attitude)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        setattr(namespace, self.dest + "_given", True)


def _spin_rate(args):
    """Refuse --spin-rate next to --attitude (the file gives the attitude: the rate would be ignored); check the
    rate."""
    if getattr(args, "spin_rate_given", False) and getattr(args, "attitude", None):
        raise InvalidInputError(f"--spin-rate {args.spin_rate:g} has no effect with --attitude {args.attitude} (the "
                                "file gives the attitude); drop --spin-rate")
    if hasattr(args, "spin_rate"):
        preflight.check_spin_rate(args.spin_rate)


def _run(args):
    _spin_rate(args)
    if args.attitude and args.dynamics:
        raise InvalidInputError("--attitude and --dynamics both set the attitude; give one of them")
    if getattr(args, "accuracy_given", False) and args.samples:
        raise InvalidInputError("--accuracy and --samples both set the sample counts (a target accuracy, or fixed "
                                "counts); give one of them")
    if getattr(args, "times", None) and getattr(args, "step_given", False):
        raise InvalidInputError(f"--step {args.step:g} has no effect with --times {args.times} (the file gives the "
                                "epochs); drop --step")
    if (args.attitude and getattr(args, "step_given", False) and args.start is None and args.duration is None
            and not getattr(args, "times", None)):
        from simcore.pipeline.schedule import relative_times_csv
        if not relative_times_csv(args.attitude):
            raise InvalidInputError(f"--step {args.step:g} has no effect: without --start or --duration the run renders "
                                    f"at the attitude history's own samples ({args.attitude}); drop --step, or give "
                                    "--start/--duration for a regular grid at that step")
    for option in ("attitude_frame", "attitude_direction"):
        if getattr(args, option, None) and not args.attitude:
            raise InvalidInputError(f"--{option.replace('_', '-')} {getattr(args, option)} declares the convention of "
                                    "an --attitude file, and none is given; add --attitude FILE or drop it")
    if args.dynamics:
        from simcore.environment.dynamics import parse_inertia
        parse_inertia(args.dynamics)


def _view(args):
    _spin_rate(args)
    preflight.check_seed(args.seed)
    if args.config_pos and args.config and args.config_pos != args.config:
        raise InvalidInputError(f"two configurations given ({args.config_pos} and --config {args.config}); give one")
    if args.spp < 1:
        raise InvalidInputError(f"--spp must be a positive number of samples per pixel, got {args.spp}")
    w, h = args.resolution
    if not (1 <= w <= VIEW_MAX_SIDE and 1 <= h <= VIEW_MAX_SIDE):
        raise InvalidInputError(f"--resolution W H must be whole pixels from 1 to {VIEW_MAX_SIDE}, got {w} {h}")
    preflight.check_view_size(w, h, args.spp)
    if args.close_up and args.map is not None:
        raise InvalidInputError("--map colours the Earth, which --close-up leaves out; drop one of them")
    if args.close_up and args.clouds is not None:
        raise InvalidInputError("--clouds colours the Earth, which --close-up leaves out; drop one of them")
    if args.output is not None and not args.output.lower().endswith(".png"):
        raise InvalidInputError(f"-o {args.output}: the picture is a PNG; give a file name ending in .png")
    if args.clouds is None and args.cloud_scale_km is not None:
        raise InvalidInputError("--cloud-scale-km sets the size of cloud weather, which needs --clouds SEED; "
                                "add --clouds or drop --cloud-scale-km")


def _estimate(args):
    preflight.check_seed(args.seed)
    if args.plots:
        preflight.check_output_folder(args.plots, "--plots folder")
    if args.initial_error is not None and not 0 <= args.initial_error <= 180:
        raise InvalidInputError(f"--initial-error must be an angle between 0 and 180 deg, got {args.initial_error}")


def _sweep(args):
    preflight.check_workers(args.workers, args.scheduler)
    preflight.check_seeds(args.seeds, "--seeds")
    if args.clouds is not None:                 # the same words as run's --clouds (one rule: environment.clouds)
        from simcore.environment.clouds import check_cloud_seed
        for seed in args.clouds:
            check_cloud_seed(seed)
    preflight.check_output_folder(args.folder, "--folder")
    for rate in args.spin_rates:
        preflight.check_spin_rate(rate, "--spin-rates")
    preflight.require_dask("sweep")


def _attitude_study(args):
    preflight.check_workers(args.workers, args.scheduler)
    preflight.check_seeds(args.seeds, "--seeds")
    _folders(args)
    preflight.require_dask("attitude-study")


def _folders(args):
    """The --folder and --page of a study with a results page: creatable and writable."""
    preflight.check_output_folder(args.folder, "--folder")
    if args.page:
        preflight.check_output_folder(args.page, "--page")


def _earth_study(args):
    preflight.check_seeds(args.cloud_seeds, "--cloud-seeds")
    preflight.check_glint(args.wind, "--wind")
    _folders(args)


def _reproduce(args):
    preflight.check_spin_rate(args.second_spin, "--second-spin")
    _folders(args)


def _coverage(args):
    if not args.no_plot:
        preflight.check_output_folder(args.plot_dir, "--plot-dir")


def _response(args):
    import math
    preflight.check_seed(args.seed)
    if math.isfinite(args.step) and args.step > 0 and args.samples > 0:     # else: check_request says why
        # one wavefront: every angle of the sweep (90 deg / step + 1) of one diode at a time
        preflight.check_wave_resources("--samples", args.samples, int(90 / args.step) + 1, 1)


def _spectral_check(args):
    from simcore.radiometry.band import band_curve
    preflight.check_seed(args.seed)
    preflight.check_seed(args.seed + len(args.diode) - 1, "--seed (+1 for each further --diode)")
    for diode in args.diode:
        band_curve(diode)
    if args.samples > 0:
        from simcore.pipeline.spectral_check import NORMALS_LOCAL
        preflight.check_wave_resources("--samples", args.samples, args.epochs, len(NORMALS_LOCAL))


def _flight_check(args):
    """--page writes the page from DIR/results.json alone, --fit calibrates on the shipped telemetry, --study
    renders its own list of maps: an option the mode would ignore is refused; the seed and every output folder
    are checked."""
    given = [o for o, v in (("--fit", args.fit), ("--study", args.study), ("--pd", args.pd),
                            ("--attitude", args.attitude), ("--tle", args.tle), ("--config", args.config),
                            ("--plots", args.plots), ("--json", args.json), ("--clouds", args.clouds is not None))
             if v]
    if args.page and given:
        raise InvalidInputError(f"--page writes the page from {args.page}/results.json only and ignores "
                                f"{', '.join(given)}; make the results with --study first, then run --page alone")
    for mode, ignored in (("--fit", ("--study", "--plots", "--clouds")), ("--study", ("--plots", "--clouds"))):
        extra = [o for o in ignored if o in given]
        if mode in given and extra:
            raise InvalidInputError(f"{mode} ignores {', '.join(extra)}; drop {'it' if len(extra) == 1 else 'them'} "
                                    f"or run {mode} as a command of its own")
    preflight.check_seed(args.seed)
    for option in ("plots", "study", "page"):
        if getattr(args, option):
            preflight.check_output_folder(getattr(args, option), f"--{option}")
    if not args.page:
        preflight.check_output_folder(args.runs, "--runs")


def _export(args):
    """The sensor chain's options only shape the csv format's readings: refused with another format."""
    preflight.check_seed(args.seed)
    chain = [o for o, v in (("--diode", args.diode != "BPW34FS"), ("--noise", args.noise), ("--seed", args.seed != 0))
             if v]
    if args.format != "csv" and chain:
        raise InvalidInputError(f"{', '.join(chain)} shape the sensor chain's readings of --format csv only; "
                                f"--format {args.format} ignores them: drop them")


_CHECKS = {"flight-check": _flight_check, "export": _export, "run": _run, "summary": _spin_rate, "view": _view, "estimate": _estimate, "sweep": _sweep,
           "attitude-study": _attitude_study, "earth-study": _earth_study, "reproduce": _reproduce,
           "coverage": _coverage,
           "response": _response, "spectral-check": _spectral_check}


def check_arguments(args):
    """Return ``args`` (argparse's namespace of one command) after the checks of its command; raise a UserError
    for the first that fails. Nothing has been read, written or started yet."""
    check = _CHECKS.get(getattr(args, "command", None))
    if check is not None:
        check(args)
    return args
