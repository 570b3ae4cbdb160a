"""Checks of a run's options that must all pass before anything is written.

:func:`simcore.pipeline.run.prepare` turns :class:`simcore.pipeline.run.RunOptions` into a ready
:class:`simcore.pipeline.run.PreparedRun` or raises a :class:`~simcore.errors.UserError`
naming the option and what to do. It reads the configuration, TLE,
attitude file and reflectivity map, computes the geometry and asks Dr.Jit
whether the requested variant runs here — and touches no output path, so a
rejected command leaves nothing behind. What is allowed but questionable
(a start far from the TLE epoch) comes back as notes for the log and the run
file's attributes.
"""
import math

import numpy as np

from simcore import _llvm
from simcore.errors import InvalidInputError

MAX_SEED = 2 ** 64 - 1            # the renderer hashes the seed as an unsigned 64-bit integer
# The brightest cell of the shipped maps is TOMS 2005's 1.074 (ice sheets; CERES 2018 peaks at 0.71). A map
# above this is almost surely in percent or scaled by mistake: 10x the TOMS map gives ~1700 W/m^2 of albedo.
MAP_REFLECTIVITY_MAX = 1.2
TLE_AGE_WARN_DAYS = 30.0
# SGP4's position error growth away from the TLE epoch in low Earth orbit: the usual rule of thumb of 1-3 km per
# day (the figure simcore.environment.orbit uses too). An order of magnitude for the warning, not a covariance.
SGP4_KM_PER_DAY = (1.0, 3.0)


# Fewest samples per diode-epoch a run may ask for. Below, few strata carry the variance and the
# standard errors are unreliable: with 16 direct and 4 albedo samples a 10-minute run fails the check's
# spread and tails tests, and with 64 and 64 one 4-epoch run in 20 seeds fails its per-diode bias test
# (5.1 sigma); with 256 and 256, 16 seeds of it all pass.
MIN_SAMPLES = 256
# Paths per diode-epoch for the reflected component unless --reflected-samples says otherwise: the renderer's
# default, 2 points in each of 128 strata of the diode (4 m^2 with m = 8, the fewest MIN_SAMPLES allows).
REFLECTED_SAMPLES = 256

def _positive(value, option, what="a positive number"):
    if value is None or not (isinstance(value, (int, float, np.number)) and math.isfinite(value) and value > 0):
        raise InvalidInputError(f"{option} must be {what}, got {value}")


def check_numbers(opts):
    """Raise InvalidInputError for an impossible number or date among ``opts``' settings (no files read)."""
    from simcore.environment.epochs import Epochs
    if isinstance(opts.start, str):
        try:
            Epochs.from_any(opts.start)
        except InvalidInputError as exc:
            reason = str(exc).split("(", 1)[1].split(")", 1)[0] if "(" in str(exc) else "unreadable"
            raise InvalidInputError(f"--start {opts.start!r} is not a UTC time ({reason}); give ISO-8601 such as "
                                    "2016-07-02T00:00:00Z") from None
    _positive(opts.step_s, "--step", "a positive number of seconds")
    if opts.duration_s is not None:
        _positive(opts.duration_s, "--duration", "a positive number of seconds")
        if opts.duration_s > 400 * 86400:
            raise InvalidInputError(f"--duration must be at most 400 days (34560000 s), got {opts.duration_s}")
        if opts.step_s > opts.duration_s:
            raise InvalidInputError(f"--step ({opts.step_s:g} s) is longer than --duration ({opts.duration_s:g} s); "
                                    "give a step at most as long as the span")
    if not math.isfinite(opts.spin_rate_deg_s):
        raise InvalidInputError(f"--spin-rate must be a finite number of deg/s, got {opts.spin_rate_deg_s}")
    for value, which in ((opts.rel_se_direct, "DIRECT"), (opts.rel_se_albedo, "ALBEDO")):
        if value is not None and not (math.isfinite(value) and 0 < value < 1):
            raise InvalidInputError(f"--accuracy {which} must be a relative standard error between 0 and 1 "
                                    f"(e.g. 0.002 0.01), got {value:g}")
    if opts.rel_se_direct is None or opts.rel_se_albedo is None:
        m = math.isqrt(max(int(opts.direct_samples), 0) // 4)
        if int(opts.direct_samples) != opts.direct_samples or m < 8 or 4 * m * m != opts.direct_samples:
            raise InvalidInputError(f"--samples DIRECT must be 4 m^2 for a whole m >= 8 (256, 1024, 4096, ...: below "
                                    f"{MIN_SAMPLES} the standard errors are not reliable), got {opts.direct_samples}")
        if (int(opts.albedo_samples) != opts.albedo_samples or opts.albedo_samples < MIN_SAMPLES
                or opts.albedo_samples % 2):
            raise InvalidInputError(f"--samples ALBEDO must be an even number >= {MIN_SAMPLES} (below that the "
                                    f"standard errors are not reliable), got {opts.albedo_samples}")
    check_reflected_samples(getattr(opts, "reflected_samples", MIN_SAMPLES))
    if int(opts.seed) != opts.seed or not 0 <= int(opts.seed) <= MAX_SEED:
        raise InvalidInputError(f"--seed must be a whole number from 0 to 2^64-1 ({MAX_SEED}), got {opts.seed}")
    if int(opts.chunk_epochs) != opts.chunk_epochs or opts.chunk_epochs < 1:
        raise InvalidInputError(f"--chunk must be a positive number of epochs, got {opts.chunk_epochs}")
    check_band(opts.reflectivity)
    check_clouds(opts)
    if getattr(opts, "glint", None) is not None:
        from simcore.radiometry.glint import check_wind
        check_wind(opts.glint)


def check_reflected_samples(n):
    """Raise InvalidInputError unless ``n`` paths per diode-epoch can carry the reflected component: 4 m^2 for a
    whole m >= 8 (2 paths in each of 2 m^2 strata of the diode; at least MIN_SAMPLES, as direct and albedo)."""
    m = math.isqrt(n // 4) if isinstance(n, (int, np.integer)) and n > 0 else 0
    if m < 8 or 4 * m * m != n:
        raise InvalidInputError(f"--reflected-samples must be 4 m^2 for a whole m >= 8 (256, 576, 1024, 4096, ...: "
                                f"2 paths in each of 2 m^2 strata of the diode; below {MIN_SAMPLES} the standard "
                                f"errors are not reliable), got {n}")


def check_band(map_name):
    """Raise InvalidInputError if ``map_name`` is a band map ('band[:DIODE]') of a diode that has no band."""
    from simcore.radiometry.band import check_map_name
    check_map_name(map_name)


def check_clouds(opts):
    """Raise InvalidInputError unless ``opts``' cloud weather (seed, correlation length, map) can be made."""
    from simcore.environment.clouds import check_cloud_options
    clouds, scale_km = getattr(opts, "clouds", None), getattr(opts, "cloud_scale_km", None)
    if clouds is None:
        if scale_km is not None:
            raise InvalidInputError("--cloud-scale-km sets the size of cloud weather, which needs --clouds SEED; "
                                    "add --clouds or drop --cloud-scale-km")
        return
    check_cloud_options(opts.reflectivity, clouds, scale_km)


def check_variant(variant):
    """Return the Mitsuba variant a run will use; raise InvalidInputError if ``variant`` cannot run here."""
    from simcore.render import irradiance as render
    if variant is not None and variant not in render._VARIANTS:
        raise InvalidInputError(f"--variant {variant} is unknown; use one of {', '.join(render._VARIANTS)}")
    try:
        return render.choose_variant(variant)
    except RuntimeError as exc:
        if variant == "cuda_ad_mono" and not isinstance(exc, _llvm.LLVMNotFoundError):
            raise InvalidInputError("--variant cuda_ad_mono needs a working CUDA GPU and none was found here; "
                                    "use --variant llvm_ad_mono or leave --variant out") from None
        raise


def check_map(reflectivity_map, allow_bright_map=False):
    """Raise InvalidInputError if a reflectivity map holds values no real surface reflects."""
    top = float(np.max(reflectivity_map.values))
    if top > MAP_REFLECTIVITY_MAX and not allow_bright_map:
        raise InvalidInputError(
            f"the reflectivity map {reflectivity_map.name} reaches {top:.4g}, above {MAP_REFLECTIVITY_MAX} (the "
            "brightest shipped map, TOMS 2005, peaks at 1.07 over ice): is it in percent or scaled? Fix the map, "
            "or pass --allow-bright-map to use it as it is")


def tle_age_note(orbit, epochs):
    """Return a warning (str) when the span reaches more than 30 days from the TLE epoch, else None."""
    age = np.asarray(epochs.jd1 - orbit.satrec.jdsatepoch + (epochs.jd2 - orbit.satrec.jdsatepochF))
    worst = float(age[np.argmax(np.abs(age))])
    if abs(worst) <= TLE_AGE_WARN_DAYS:
        return None
    lo, hi = (abs(worst) * k for k in SGP4_KM_PER_DAY)
    return (f"the span reaches {worst:+.1f} days from the epoch of the TLE ({orbit.epoch.iso()[0]}); SGP4 position "
            f"errors grow by about {SGP4_KM_PER_DAY[0]:g}-{SGP4_KM_PER_DAY[1]:g} km per day from the epoch, "
            f"~{lo:.0f}-{hi:.0f} km here: use a TLE from near the start when the date matters")


def map_for_diodes(map_name, config):
    """Return the map name to resolve for ``config``'s diodes: ``--map band`` / ``band-clear`` without a diode
    takes the configuration's declared ``diode_type`` (scenes/declared.py); an "unknown" type refuses it (one
    line: assume a part with band:DIODE, or take a broadband map). Other names are returned as they are."""
    from simcore.radiometry.band import parse_map_name
    head = str(map_name).replace("_", "-")
    declared = getattr(config, "diode_type", None)
    if ":" in head or parse_map_name(map_name) is None or declared is None:
        return map_name
    if declared == "unknown":
        raise InvalidInputError(f"--map {map_name} sees the Earth in the diodes' spectral band, but {config.name} "
                                "declares diode_type = \"unknown\": give --map band:DIODE to assume a part, or a "
                                "broadband map (ceres2018-all, toms2005)")
    return f"{map_name}:{declared}"

