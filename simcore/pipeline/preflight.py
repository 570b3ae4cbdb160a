"""Checks of a run's options that must all pass before anything is written.

:func:`simcore.pipeline.run.prepare` turns :class:`simcore.pipeline.options.RunOptions` into a ready
:class:`simcore.pipeline.run.PreparedRun` or raises a :class:`~simcore.errors.UserError`
naming the option and what to do. It reads the configuration, TLE,
attitude file and reflectivity map, computes the geometry and asks Dr.Jit
whether the requested variant runs here — and touches no output path, so a
rejected command leaves nothing behind. What is allowed but questionable
(a start far from the TLE epoch) comes back as notes for the log and the run
file's attributes.
"""
import math
import os

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
    check_spin_rate(opts.spin_rate_deg_s)
    if getattr(opts, "attitude_file", None) and getattr(opts, "dynamics", None):
        raise InvalidInputError("--attitude and --dynamics both set the attitude; give one of them")
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
        check_glint(opts.glint)


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


def check_model_inputs(config, tle, map_name, clouds=None):
    """Read the scene ``config``, the TLE file ``tle`` and the reflectivity map ``map_name`` (with its cloud
    weather seed ``clouds``) as a run would; raise the readers' one-line UserError for the first that is wrong.
    For the commands that read other inputs (telemetry) and make folders before their runs start: the run's own
    checks (:func:`simcore.pipeline.run.prepare`) then only repeat what has passed here."""
    from scenes.config import SatelliteConfig
    from simcore.environment.orbit import Orbit
    from simcore.radiometry import band
    config = SatelliteConfig.load(config)
    Orbit.from_file(tle)
    check_band(map_name)
    name = map_for_diodes(map_name, config)
    if clouds is None:
        check_map(band.resolve_map(name, None))
    else:
        from simcore.environment.clouds import check_cloud_options
        check_cloud_options(name, clouds, None)
    return config


def check_variant(variant):
    """Return the Mitsuba variant a run will use; raise InvalidInputError if ``variant`` cannot run here."""
    from simcore.render import launch as render
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
    """Return a warning (str) when the span reaches more than 30 days from the TLE epoch, else None (also for
    an orbit without a TLE: an ephemeris does not age)."""
    if not hasattr(orbit, "satrec"):
        return None
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

# ---- seeds, rates, winds: the limits every command shares --------------------------------------------------------
# The winds: simcore.radiometry.glint.MAX_WIND_M_S (check_glint below).
# The fastest spin a CubeSat is designed for: ESTCube-1 was to spin up to one turn a second (360 deg/s) to deploy
# its electric-sail tether (Slavinskis et al. 2015). Faster rates are a unit mistake (rpm, rad/s given as deg/s...).
SPIN_MAX_DEG_S = 360.0


def check_seed(value, option="--seed"):
    """Raise InvalidInputError unless ``value`` is a whole number 0 .. 2^64-1 (numpy's and the renderer's seeds)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) <= MAX_SEED:
        raise InvalidInputError(f"{option} must be a whole number from 0 to 2^64-1 ({MAX_SEED}), got {value}")


def check_seeds(values, option):
    """check_seed for each of ``values``, and at least one of them."""
    if values is not None and len(values) == 0:
        raise InvalidInputError(f"{option} needs at least one seed")
    for v in values or ():
        check_seed(v, option)


def check_glint(wind_m_s, option="--glint WIND_M_S"):
    """Return the wind speed (m/s) of a sea glint option, or raise InvalidInputError naming ``option``: negative, not
    finite, or above the limit of :func:`simcore.radiometry.glint.check_wind` (one place for the rule)."""
    from simcore.radiometry.glint import check_wind
    return check_wind(wind_m_s, option)


def check_spin_rate(rate_deg_s, option="--spin-rate"):
    """Raise InvalidInputError unless ``rate_deg_s`` is a finite rate of at most SPIN_MAX_DEG_S in magnitude."""
    if not math.isfinite(rate_deg_s):
        raise InvalidInputError(f"{option} must be a finite number of deg/s, got {rate_deg_s}")
    if abs(rate_deg_s) > SPIN_MAX_DEG_S:
        raise InvalidInputError(f"{option} {rate_deg_s:g} deg/s is faster than {SPIN_MAX_DEG_S:g} deg/s (one turn a "
                                "second, the fastest spin a CubeSat is built for); the rate is in deg/s")


# ---- resources: what the machine can hold, checked before Dr.Jit is asked ------------------------------------
# Dr.Jit sizes its arrays with 32-bit unsigned integers: a wavefront of 2^32 lanes or more wraps around and crashes
# the process (SIGSEGV; seen with `sunsim view --spp 9000` at 960 x 540: 4.67e9 lanes).
MAX_LANES = 2 ** 32 - 1
# Memory of one lane of the reflected-light wavefront, measured: tilt20_fov70 ... cubesat3u_panels, 2 epochs x 6
# diodes x 4e6 paths (4.8e7 lanes) peaked at 2.36 GB against 0.38 GB at 256 paths (/usr/bin/time -v): 41 bytes a
# lane; 64 with room for Dr.Jit's pools.
REFLECTED_BYTES_PER_LANE = 64
# epochs gathered into one reflected wavefront at most (simcore.render.Renderer.render's batch_epochs)
REFLECTED_BATCH_EPOCHS = 64


def available_memory_bytes():
    """Return the memory this process may still use (MemAvailable of /proc/meminfo; else the physical memory)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_view_size(width, height, spp):
    """Raise InvalidInputError unless a picture of ``width`` x ``height`` pixels at ``spp`` samples per pixel fits
    in one Dr.Jit wavefront (MAX_LANES)."""
    lanes = int(width) * int(height) * int(spp)
    if lanes > MAX_LANES:
        most = MAX_LANES // (int(width) * int(height))
        raise InvalidInputError(f"--spp {spp} at {width} x {height} pixels asks for {lanes:.3g} samples in one render, "
                                f"beyond Dr.Jit's limit of 2^32-1 ({MAX_LANES:.3g}): give --spp {most} or fewer at "
                                "this --resolution, or a smaller --resolution")


def check_wave_resources(option, n_paths, n_epochs, n_diodes, memory_bytes=None):
    """Raise InvalidInputError unless a wavefront of ``n_paths`` per diode-epoch (``option``'s value; up to
    REFLECTED_BATCH_EPOCHS epochs x ``n_diodes`` at once) fits in Dr.Jit's lanes and in the available memory."""
    tasks = min(int(n_epochs), REFLECTED_BATCH_EPOCHS) * int(n_diodes)
    lanes = tasks * int(n_paths)
    memory = available_memory_bytes() if memory_bytes is None else memory_bytes
    need = lanes * REFLECTED_BYTES_PER_LANE
    if lanes > MAX_LANES or need > memory:
        m = math.isqrt(max(min(MAX_LANES, memory // REFLECTED_BYTES_PER_LANE) // tasks, 0) // 4)
        most = f"at most {4 * m * m} here" if m >= 8 else f"this layout cannot afford even the smallest, {MIN_SAMPLES}"
        raise InvalidInputError(f"{option} {n_paths} traces up to {lanes:.3g} paths at once ({tasks // n_diodes} "
                                f"epochs x {n_diodes} diodes x {n_paths}), ~{need / 2 ** 30:.3g} GiB at "
                                f"{REFLECTED_BYTES_PER_LANE} bytes a path, beyond this machine's "
                                f"{memory / 2 ** 30:.3g} GiB available or Dr.Jit's 2^32 lanes: {most}")


def check_run_resources(opts, n_epochs, n_diodes, reflected_traced=True):
    """check_wave_resources of a run's fixed --samples (none with --accuracy: the renderer caps those) and, where the
    reflected component is traced, of its --reflected-samples."""
    waves = [] if opts.rel_se_direct else [("--samples DIRECT", opts.direct_samples),
                                           ("--samples ALBEDO", opts.albedo_samples)]
    for option, n in waves + ([("--reflected-samples", opts.reflected_samples)] if reflected_traced else []):
        check_wave_resources(option, n, n_epochs, n_diodes)


def check_reflected_resources(n_paths, n_epochs, n_diodes, memory_bytes=None):
    """check_wave_resources of --reflected-samples."""
    check_wave_resources("--reflected-samples", n_paths, n_epochs, n_diodes, memory_bytes)


def reflected_ignored_note(n_paths, config):
    """Return a warning (str) when --reflected-samples is set on a layout whose surfaces are all black (nothing
    reflects, so nothing is path traced), else None."""
    from scenes.materials import is_black
    if n_paths == REFLECTED_SAMPLES:
        return None
    surfaces = [config.body.material, config.mount.material] + [p.material for p in config.parts]
    if all(is_black(m) for m in surfaces):
        return (f"--reflected-samples {n_paths} is ignored: every surface of {config.name} is black, so nothing "
                "reflects and no path is traced")
    return None


# ---- attitude files ---------------------------------------------------------------------------------------------
# Rows this far apart (median, "seconds") on whole numbers look like milliseconds read as seconds: attitude
# telemetry and simulations are sampled at 0.1-10 s; 100 s between attitude samples cannot follow any tumble.
ATTITUDE_MS_STEP_S = 100.0
# Times this large are Unix times in milliseconds (Unix time in seconds reaches 1e11 in the year 5138).
ATTITUDE_MS_ABSOLUTE = 1e11


def attitude_times_note(t_s, path):
    """Return a warning (str) when an attitude file's times look like milliseconds although the column is
    t_s (seconds), else None."""
    t = np.asarray(t_s, dtype=float)
    if len(t) < 2:
        return None
    step = float(np.median(np.diff(t)))
    whole = bool(np.all(t == np.round(t)))
    if (step >= ATTITUDE_MS_STEP_S and whole) or float(np.max(np.abs(t))) >= ATTITUDE_MS_ABSOLUTE:
        return (f"the attitude file {path} has rows {step:g} s apart (median) on whole numbers, as milliseconds "
                f"would be: its t_s column is read as seconds; if the times are in ms, divide them by 1000")
    return None


# ---- dask --------------------------------------------------------------------------------------------------------
def require_dask(command):
    """Raise MissingExtraError unless Dask's distributed scheduler can be imported."""
    from simcore.errors import MissingExtraError
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError as exc:
        raise MissingExtraError(f"sunsim {command} runs on Dask, which is not installed ({exc.name or 'dask'} is "
                                "missing): pip install 'sunsim[sweep]'") from None


def check_workers(workers, scheduler):
    """Raise InvalidInputError unless a local cluster of ``workers`` can be started (no ``scheduler`` given)."""
    if scheduler:
        return
    most = 4 * (os.cpu_count() or 1)
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or not 1 <= workers <= most:
        raise InvalidInputError(f"--workers must be a whole number from 1 to {most} (4 per CPU core here), got "
                                f"{workers}; or give --scheduler ADDRESS of a running Dask cluster")


# ---- run files given to the estimators -----------------------------------------------------------------------
def check_filter_run(ds, name, path=None, initial_error_deg=None):
    """Raise InvalidInputError unless run Dataset ``ds`` can feed filter ``name`` ('mekf', 'sunline-ekf', ...): at
    least two epochs (a filter propagates from one to the next) and, to start from a Sun vector, a sunlit one."""
    from simcore.environment.eclipse import sunlit
    where = path or "the run"
    n = int(ds.sizes["time"])
    if n < 2:
        raise InvalidInputError(f"{where} holds {n} epoch: --filter {name} propagates from epoch to epoch and needs "
                                "at least 2; render a longer --duration (or use the estimators without --filter)")
    if np.any(sunlit(ds["illumination"].values)):
        return
    if name == "mekf" and initial_error_deg is None:
        raise InvalidInputError(f"{where} has no sunlit epoch (the whole span is in the Earth's shadow): the MEKF "
                                "starts by TRIAD from the Sun vector; give --initial-error DEG to start from a "
                                "perturbed truth, or a run with sunlight (another --start or a longer --duration)")
    if name != "mekf":
        raise InvalidInputError(f"{where} has no sunlit epoch (the whole span is in the Earth's shadow): --filter "
                                f"{name} has no Sun vector to follow; render a span with sunlight (another --start "
                                "or a longer --duration)")


# ---- output folders ------------------------------------------------------------------------------------------
def check_output_folder(folder, option):
    """Raise OutputError unless ``folder`` exists and takes new files, or can be created (its nearest existing
    parent takes new files); nothing is created (a probe file is made and removed)."""
    import tempfile
    from simcore.errors import OutputError
    path = os.path.abspath(folder)
    existing = path
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise OutputError(f"cannot create the folder {folder} ({existing} is a file); choose another {option}")
    try:
        fd, probe = tempfile.mkstemp(prefix=".sunsim-probe-", dir=existing)
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise OutputError(f"cannot create the folder {folder} ({existing}: {why}); choose another {option}") from None
    os.close(fd)
    os.remove(probe)
