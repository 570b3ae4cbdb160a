"""Which epochs a run renders, and with what attitude: regular grids, explicit (irregular) epochs, and
recorded attitude histories.

:func:`plan` turns a :class:`simcore.pipeline.options.RunOptions` into a :class:`RunPlan` (orbit, epochs,
attitude, the history if any, notes), one place for every rule:

* explicit epochs, irregular or not: ``opts.epochs`` (an :class:`Epochs`, in-process) or
  ``opts.times_file`` (one ISO-8601 UTC time per line, ``#`` comments; ``sunsim run --times``), strictly
  increasing; ``start``/``duration`` must then be left out;
* an attitude history with absolute times (sunsim's ``time_utc`` CSV, a GRAINS export, an OPS-SAT 2021 log;
  :func:`simcore.environment.telemetry.read_attitude_history`) and no ``start``/``duration``: the run
  renders at the history's own trusted sample times (:meth:`AttitudeHistory.sample_epochs`);
* a CCSDS orbit ephemeris (``opts.orbit_file``, :mod:`simcore.environment.ephemeris`) and neither of the
  above: the regular grid from ``start`` (default: the ephemeris's first epoch) for ``duration`` (default: to
  its last), the epochs in gaps between its segments left out; with any source of epochs, an epoch outside
  the ephemeris is refused (one line, its span and gaps named);
* otherwise the regular grid ``start + k step`` over ``[0, duration)``. ``start`` defaults to the history's
  first sample (or 2016-07-02T00:00Z without a history), ``duration`` to the rest of the history's span (or
  one orbit without one). A relative-time history (``t_s`` CSV) carries no date: it needs ``start``.

With a history, epochs of a regular grid outside its recorded span are refused (one line; explicit epochs
outside it, e.g. telemetry stamps half a second before the first attitude sample, are left out and counted);
epochs inside it where the attitude
is not trusted (gaps, jumps, frozen stretches: :mod:`simcore.environment.history`) are left out and counted
in a note, never interpolated across. A run at explicit epochs renders exactly those epochs, in one process,
whatever their spacing; the renderer's random numbers are keyed by the epoch's index in the run, so the
same epochs give the same numbers whether they came as a regular grid or as a list.
"""
import hashlib
from dataclasses import dataclass

import numpy as np

from simcore.environment import attitude as _attitude
from simcore.environment.epochs import Epochs
from simcore.environment.geometry import DEFAULT_START, compute_geometry, orbital_period_s
from simcore.environment.history import AttitudeHistory, read_text
from simcore.environment.orbit import Orbit
from simcore.errors import InvalidInputError

MAX_DURATION_S = 400 * 86400


@dataclass
class RunPlan:
    orbit: Orbit
    epochs: Epochs
    attitude: _attitude.Attitude
    history: AttitudeHistory = None
    notes: tuple = ()
    source: str = "regular"          # 'regular', 'times', 'attitude samples'


def read_times(path):
    """Return the Epochs in a times file: one ISO-8601 UTC time per line, blank lines and '#' comments ignored."""
    text = read_text(path, "times file")
    cells, where = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.split("#", 1)[0].strip()
        if s:
            cells.append(s)
            where.append(lineno)
    if not cells:
        raise InvalidInputError(f"{path}: no times found; give one ISO-8601 UTC time per line")
    values = []
    for lineno, cell in zip(where, cells):
        try:
            values.append(Epochs.from_any(cell).datetime64[0])
        except (InvalidInputError, TypeError, ValueError):
            raise InvalidInputError(f"{path}:{lineno}: cannot read {cell!r} as an ISO-8601 UTC time") from None
    epochs = Epochs.from_datetime64(np.array(values))
    check_increasing(epochs, f"the times in {path}")
    return epochs


def check_increasing(epochs, what):
    t = epochs.seconds_since(epochs[0])
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InvalidInputError(f"{what} must increase strictly: {epochs[i].iso()[0]} follows {epochs[i - 1].iso()[0]}")


def epochs_spec(epochs):
    """Return a JSON-able, exact description of in-process epochs (for the run's settings digest)."""
    h = hashlib.sha256(np.ascontiguousarray(epochs.jd1).tobytes() + np.ascontiguousarray(epochs.jd2).tobytes())
    return {"n": len(epochs), "first": epochs.iso()[0], "last": epochs.iso()[-1], "sha256": h.hexdigest()}


def history_spec(history):
    """Return a JSON-able, exact description of an in-process AttitudeHistory (for the settings digest)."""
    h = hashlib.sha256(np.ascontiguousarray(history.q_frame_from_body).tobytes())
    lim = history.limits
    return {"epochs": epochs_spec(history.epochs), "q_sha256": h.hexdigest(), "frame": history.frame,
            "limits": [lim.max_gap_s, lim.max_rate_deg_s, lim.min_frozen_s], "source": history.source}


def _history(opts):
    """Return the run's AttitudeHistory, or None (tumble or dynamics)."""
    given = getattr(opts, "attitude_history", None)
    if given is not None and opts.attitude_file:
        raise InvalidInputError("an attitude history and an attitude file were both given; give one")
    if given is not None:
        return given
    if not opts.attitude_file:
        return None
    from simcore.environment.telemetry import read_attitude_history
    return read_attitude_history(opts.attitude_file, start=opts.start, frame=getattr(opts, "attitude_frame", None),
                                 direction=getattr(opts, "attitude_direction", None))


def relative_times_csv(path):
    """Return True when ``path`` is sunsim's relative-time attitude CSV (header ``t_s,qw,qx,qy,qz``)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("utf-8", "replace")
    except OSError:
        return False
    rows = [r for r in head.splitlines() if r.strip() and not r.lstrip().startswith("#")]
    return bool(rows) and rows[0].replace(" ", "").lower().startswith("t_s")


def _explicit(opts):
    epochs, times_file = getattr(opts, "epochs", None), getattr(opts, "times_file", None)
    if epochs is not None and times_file:
        raise InvalidInputError("epochs were given twice (in-process epochs and a times file); give one")
    if epochs is None and not times_file:
        return None
    if opts.start is not None or opts.duration_s is not None:
        raise InvalidInputError("--times gives the epochs: leave out --start and --duration")
    if times_file:
        return read_times(times_file)
    epochs = Epochs.from_any(epochs)
    check_increasing(epochs, "the run's epochs")
    return epochs


def _regular(opts, start, duration):
    if opts.step_s is None or not opts.step_s > 0:
        raise InvalidInputError(f"--step must be a positive number of seconds, got {opts.step_s}")
    if not (np.isfinite(duration) and 0 < duration <= MAX_DURATION_S):
        raise InvalidInputError(f"--duration must be between 0 and 400 days in seconds, got {duration:g}")
    return Epochs.range(start, duration, opts.step_s)


def plan(opts):
    """Return the :class:`RunPlan` of ``opts`` (module docstring); raise one line for the first mistake."""
    if opts.attitude_file and opts.dynamics:
        raise InvalidInputError("--attitude and --dynamics both set the attitude; give one of them")
    orbit = study_orbit(opts)
    ephemeris = getattr(opts, "orbit_file", None) is not None
    explicit = _explicit(opts)
    history = _history(opts)
    notes, source = [], "regular"
    if history is not None and opts.dynamics:
        raise InvalidInputError("--attitude and --dynamics both set the attitude; give one of them")
    if explicit is not None:
        epochs, source = explicit, "times"
    elif history is not None and opts.start is None and opts.duration_s is None:
        epochs, source = history.sample_epochs(), "attitude samples"
        if len(epochs) == 0:
            raise InvalidInputError(f"{history.summary()}: no sample is trusted; nothing to render")
    elif history is not None:
        start = history.epochs[0] if opts.start is None else Epochs.from_any(opts.start)
        duration = (history.span_s() - start.seconds_since(history.epochs[0])[0]
                    if opts.duration_s is None else opts.duration_s)
        if duration <= 0:
            raise InvalidInputError(f"--start {start.iso()[0]} lies after the attitude history's end "
                                    f"{history.epochs.iso()[-1]}; give a start within it")
        epochs = _regular(opts, start, duration)
    elif ephemeris:             # the ephemeris's span (or the part asked for), the gaps between its segments left out
        if opts.step_s is None or not opts.step_s > 0:
            raise InvalidInputError(f"--step must be a positive number of seconds, got {opts.step_s}")
        d = opts.duration_s
        if d is not None and not (np.isfinite(d) and 0 < d <= MAX_DURATION_S):
            raise InvalidInputError(f"--duration must be between 0 and 400 days in seconds, got {d:g}")
        epochs = orbit.sample_epochs(opts.step_s, opts.start, opts.duration_s)
        if len(epochs) == 0:
            raise InvalidInputError(f"no epoch of the run lies inside the ephemeris {opts.orbit_file} "
                                    f"({orbit.describe_span()})")
    else:
        start = DEFAULT_START if opts.start is None else opts.start
        epochs = _regular(opts, start, orbital_period_s(orbit) if opts.duration_s is None else opts.duration_s)
    if ephemeris:
        orbit.require(epochs)       # epochs outside the ephemeris refused, its span in the message
    t_s = epochs.seconds_since(epochs[0])
    if history is not None:
        notes.append(history.summary())
        _, inside = history._locate(epochs)
        if not inside.all() and source == "times":
            # explicit epochs (e.g. telemetry stamps) may start before or end after the history: left out, counted
            notes.append(f"left out {int((~inside).sum())} of {len(epochs)} epochs outside the attitude history's "
                         f"span {history.epochs.iso()[0]} .. {history.epochs.iso()[-1]}")
            epochs = epochs[np.flatnonzero(inside)]
            if len(epochs) == 0:
                raise InvalidInputError("none of the given epochs lies within the attitude history's span")
        elif not inside.all():
            k = int(np.flatnonzero(~inside)[0])
            raise InvalidInputError(f"the attitude history {history.source or ''} spans {history.epochs.iso()[0]} .. "
                                    f"{history.epochs.iso()[-1]} but the run needs {epochs[k].iso()[0]} "
                                    f"({int((~inside).sum())} epochs outside); give a longer history or a shorter "
                                    "span".replace("  ", " "))
        ok = history.trusted(epochs)
        if not ok.any():
            raise InvalidInputError(f"none of the run's {len(epochs)} epochs has a trusted attitude ({history.summary()})")
        if not ok.all():
            notes.append(f"left out {int((~ok).sum())} of {len(epochs)} epochs without a trusted attitude (in a gap, "
                         "a jump or a frozen stretch of the history): not interpolated across")
            epochs = epochs[np.flatnonzero(ok)]
        attitude = history.attitude_at(epochs)
    elif opts.dynamics:
        from simcore.environment.dynamics import parse_inertia, propagate_torque_free
        axis = np.asarray(opts.spin_axis, dtype=float)
        w0 = np.radians(opts.spin_rate_deg_s) * axis / np.linalg.norm(axis)
        attitude, _ = propagate_torque_free(t_s, parse_inertia(opts.dynamics), w0)
    else:
        attitude = _attitude.tumble(t_s, rate_deg_s=opts.spin_rate_deg_s, axis_body=opts.spin_axis)
    return RunPlan(orbit, epochs, attitude, history, tuple(notes), source)


def study_orbit(opts):
    """Return the orbit ``opts`` name: a CCSDS OEM (``orbit_file``, :mod:`simcore.environment.ephemeris`), a TLE
    file, or the shipped TLE."""
    if getattr(opts, "orbit_file", None):
        if opts.tle is not None or opts.satellite is not None:
            raise InvalidInputError("--orbit (an ephemeris) and --tle/--satellite both give the orbit; give one")
        from simcore.environment.ephemeris import EphemerisOrbit
        return EphemerisOrbit.from_file(opts.orbit_file)
    return Orbit.default(opts.satellite) if opts.tle is None else Orbit.from_file(opts.tle, satellite=opts.satellite)


def eop_kwargs(opts):
    """Return compute_geometry's Earth-orientation keywords (dut1_s, xp_rad, yp_rad) of ``opts.eop`` = (UT1 - UTC in
    s, x_p and y_p in arcsec; IERS Bulletin A), all zero without it; raise one line for values out of range."""
    eop = getattr(opts, "eop", None)
    if eop is None:
        return {}
    try:
        dut1, xp, yp = (float(x) for x in eop)
    except (TypeError, ValueError):
        raise InvalidInputError(f"--eop needs three numbers: UT1 - UTC (s), x_p and y_p (arcsec); got {eop!r}") from None
    if not (np.isfinite([dut1, xp, yp]).all() and abs(dut1) <= 0.9 and abs(xp) <= 1.0 and abs(yp) <= 1.0):
        raise InvalidInputError(f"--eop {dut1:g} {xp:g} {yp:g}: UT1 - UTC stays within 0.9 s and the pole within 1 "
                                "arcsec (IERS Bulletin A gives both); check the units (seconds, arcseconds)")
    arcsec = np.pi / 180 / 3600
    return {"dut1_s": dut1, "xp_rad": xp * arcsec, "yp_rad": yp * arcsec}


def study_geometry(opts):
    """Return (orbit, attitude, geometry) of the orbit, epochs and attitude that ``opts`` describe (:func:`plan`),
    with the Earth orientation of ``opts.eop`` (:func:`eop_kwargs`)."""
    eop = eop_kwargs(opts)
    p = plan(opts)
    return p.orbit, p.attitude, compute_geometry(p.orbit, p.epochs, p.attitude, **eop)


_NEW_FIELDS = ("times_file", "epochs", "attitude_history", "attitude_frame", "attitude_direction")


def spec_fields(opts, d):
    """Edit the settings dict ``d`` of ``opts`` in place: the explicit-epoch and history fields only where set
    (runs without them keep the digest they always had), in-process objects by exact digests, and the
    start a run without a history or epochs always had."""
    for k in _NEW_FIELDS:
        if d.get(k) is None:
            d.pop(k, None)
    if getattr(opts, "epochs", None) is not None:
        d["epochs"] = epochs_spec(Epochs.from_any(opts.epochs))
    if getattr(opts, "attitude_history", None) is not None:
        d["attitude_history"] = history_spec(opts.attitude_history)
    if d.get("orbit_file") is None:                 # runs on a TLE keep the digest they always had
        d.pop("orbit_file", None)
    if d.get("start") is None and not (opts.attitude_file or "epochs" in d or "times_file" in d
                                       or "attitude_history" in d or "orbit_file" in d):
        d["start"] = DEFAULT_START


def explicit_options(kw, ds):
    """Return the RunOptions keywords ``kw`` read back from a run file, with in-process epochs restored from its
    time axis; refuse one made with an in-process AttitudeHistory (its samples are not in the file)."""
    if isinstance(kw.get("epochs"), dict):
        kw["epochs"] = Epochs.from_datetime64(ds["time"].values)
    if isinstance(kw.get("attitude_history"), dict):
        raise InvalidInputError("this run was made in-process with an AttitudeHistory object, whose samples the run "
                                "file does not hold; rerun it from its history (or from a history file)")
    return kw


def annotate(ds, plan):
    """Return the run Dataset ``ds`` with the origin of its epochs and attitude (``plan``: the run's
    :class:`RunPlan`) in its attributes."""
    ds.attrs["epochs_source"] = plan.source
    if plan.history is not None:
        ds.attrs["attitude_history"] = plan.history.summary()
        ds.attrs["attitude_frame"] = plan.history.frame
    return ds
