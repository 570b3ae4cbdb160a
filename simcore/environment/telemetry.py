"""Readers for recorded flight telemetry, the files exactly as published: ESA OPS-SAT's (shipped in
``simcore/data/flight/opssat/``, provenance in its README.md).

Every reader refuses a file it cannot read faithfully with one clear line (:class:`InvalidInputError`),
before anything is computed, and counts every row it leaves out (never invents one). Times are UTC (the
files do not say; the Sun-direction fit of ``python -m simcore.studies.opssat_convention`` checks it).

* :func:`read_opssat_attitude`: the GRAINS export (``O_Q_FB_FI_EST``). 18 header lines, then the column
  line ``# DATE TIME,CADC1002 ...,CADC1005 ...`` and rows ``YYYY-MM-DD HH:MM:SS.fff,q0,q1,q2,q3``. The
  header's time window and sample counts describe the whole original export, not the rows present (the
  shipped file is cut to a week): they are reported (:attr:`AttitudeHistory.header`), never checked
  against the rows. The quaternions are averages over 10 s, so not exactly unit (norms 0.956-1.000 in the
  shipped week): normalised within :data:`OPSSAT_NORM_TOL`, refused beyond it. Rows of zeros mean "no
  data": left out and counted. Convention (shown with the data, docs/attitude_history.md): scalar first,
  ``v_body = R(q) v_inertial`` (direction ``frame_to_body``).
* :func:`read_opssat_pd`: the labelled photodiode file ``TIMESTAMP,PD3,PD6,...`` (theta in rad; the
  ``*_STATE`` columns are another project's fault labels and are ignored). Decisions: values in
  ``[-NEGATIVE_TOL_RAD, 0)`` (3 in the shipped week, down to -0.0020) are clipped to 0 (a dark diode's
  offset); below that refused. Values within ``SATURATION_TOL_RAD`` of pi/2 (80 in the shipped week,
  printed 1.5708, all PD3 but one) are flagged ``saturated``: the on-board asin(I / I_ref) clipped at I >= I_ref,
  so the true reading is only known to be >= 1; they are left out of comparisons (``usable`` False),
  counted.
* :func:`read_opssat_log_2021`: the 2021 on-board logs. The header lacks its first cell (every name sits
  one column left of its data, with a trailing empty cell), the first column is the Unix time in ms,
  ``x`` = not yet acquired. PD(k+1) = ``CADC0884 + 2k`` (theta, rad), its validity flag ``CADC0885 + 2k``
  (``true``/``false``), the quaternion ``CADC1002..1005`` (same convention as the GRAINS export). The log
  samples every 5 s while the quaternion's components are updated separately: rows that repeat the
  previous quaternion bit for bit are the same estimate held, left out of the history (counted as
  ``repeated``), except the last row of a value held ``min_frozen_s`` or longer (the history then flags
  that stretch ``frozen``); rows whose components changed only in part mix two estimates (``torn``, most rows:
  kept and normalised where their norm is within the tolerance, left out and counted as
  ``torn_off_norm`` beyond it; an untorn row beyond it is refused).
"""
import csv
import io
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simcore.environment.attitude import norm_outliers
from simcore.environment.epochs import Epochs
from simcore.environment.history import AttitudeHistory, HistoryLimits, read_text
from simcore.errors import InputNotFoundError, InvalidInputError

OPSSAT_DIR = Path(__file__).resolve().parent.parent / "data" / "flight" / "opssat"
OPSSAT_ATTITUDE = OPSSAT_DIR / "attitude_2020-11-15_to_21.csv"
OPSSAT_PD = OPSSAT_DIR / "pd_theta_2020-11-15_to_21.csv"
OPSSAT_TLE = OPSSAT_DIR / "tle_2020-11-06.txt"
OPSSAT_TLE_2021 = OPSSAT_DIR / "tle_2021-02-08.txt"
OPSSAT_LOGS_2021 = OPSSAT_DIR / "logs_2021"

# OPS-SAT's quaternion convention, shown with the 2020 week (simcore.studies.opssat_convention)
OPSSAT_DIRECTION = "frame_to_body"
OPSSAT_SCALAR_FIRST = True
# The inertial frame is not published; the Sun-direction fit cannot tell EME2000 from a frame of date
# (0.29 deg) beyond doubt (docs/attitude_history.md): EME2000, the usual frame of an on-board estimator.
OPSSAT_FRAME = "EME2000"
# 10-s averages of a turning quaternion are shorter than 1; the shipped week's shortest is 0.956. Beyond
# 5 % the row is not an average of nearby attitudes but a wrong value (or column order).
OPSSAT_NORM_TOL = 0.05

GRAINS_FIRST_LINE = "# Exported Parameter(s) from GRAINS"
GRAINS_HEADER_LINES = 18
GRAINS_QUATERNION = ("CADC1002", "CADC1003", "CADC1004", "CADC1005")
NEGATIVE_TOL_RAD = 0.01         # theta in [-0.01, 0): clipped to 0 (the shipped week's lowest: -0.00196)
# theta within this of pi/2: saturated (the labelled file prints 6 digits: pi/2 as 1.5708, 3.7e-6 above it;
# the next lower value in the shipped week is 1.51989)
SATURATION_TOL_RAD = 1e-5
LOG_2021_PD = tuple(f"CADC{884 + 2 * k:04d}" for k in range(6))
LOG_2021_PD_VALID = tuple(f"CADC{885 + 2 * k:04d}" for k in range(6))
LOG_2021_QUATERNION = GRAINS_QUATERNION


@dataclass
class DiodeReadings:
    """Photodiode readings at UTC epochs: theta (rad) as recorded and the reading sin(theta).

    ``reading`` is sin(theta): the photocurrent over its full-Sun value at normal incidence (NaN where not
    acquired). ``usable`` is False where the value is missing, saturated or (2021 logs) flagged invalid:
    leave those out of comparisons. ``counts`` says how many of each.
    """

    epochs: Epochs
    names: tuple
    theta_rad: np.ndarray           # (N, K), NaN where not acquired
    saturated: np.ndarray           # (N, K) bool
    flag_valid: np.ndarray          # (N, K) bool: the on-board validity flag (all True where none is logged)
    source: str = ""
    counts: dict = field(default_factory=dict)

    @property
    def reading(self):
        """Return (N, K) sin(theta), the photocurrent over its full-Sun value at normal incidence."""
        return np.sin(self.theta_rad)

    @property
    def usable(self):
        """Return (N, K) bool: acquired, not saturated, flagged valid."""
        return np.isfinite(self.theta_rad) & ~self.saturated & self.flag_valid

    def column(self, name):
        """Return the index of diode ``name`` (e.g. 'PD3')."""
        if name not in self.names:
            raise InvalidInputError(f"{self.source}: no diode {name!r}; it holds {', '.join(self.names)}")
        return self.names.index(name)


def _theta(values, names, where):
    """Return (theta, saturated, counts) after the documented clipping and saturation rules."""
    v = np.array(values, dtype=float)
    low = v < -NEGATIVE_TOL_RAD
    high = v > np.pi / 2 + SATURATION_TOL_RAD
    for bad, what in ((low, f"below -{NEGATIVE_TOL_RAD} rad"), (high, "above pi/2")):
        if np.any(bad):
            i, k = (int(a[0]) for a in np.nonzero(bad))
            raise InvalidInputError(f"{where[i]}: {names[k]} = {v[i, k]:.6g} rad is {what}; a sun-elevation "
                                    "theta lies in [0, pi/2]: is this the right column or unit?")
    negative = np.isfinite(v) & (v < 0)
    saturated = np.isfinite(v) & (np.abs(v - np.pi / 2) <= SATURATION_TOL_RAD)
    counts = {f"clipped_negative_{n}": int(negative[:, k].sum()) for k, n in enumerate(names)}
    counts.update({f"saturated_{n}": int(saturated[:, k].sum()) for k, n in enumerate(names)})
    return np.where(negative, 0.0, v), saturated, counts


def _check_increasing(epochs, where, path):
    t = epochs.seconds_since(epochs[0])
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InvalidInputError(f"{where[i]}: time {epochs[i].iso()[0]} does not follow {epochs[i - 1].iso()[0]} "
                                f"({bad.size} such rows in {path}); times must increase strictly")


def _datetime(cell, where):
    """Return datetime64[ns] of 'YYYY-MM-DD HH:MM:SS[.fff]' (UTC), or raise one line."""
    try:
        t = np.datetime64(cell.strip().replace(" ", "T"), "ns")
    except ValueError:
        t = None
    if t is None or np.isnat(t) or len(cell.strip()) < 19:
        raise InvalidInputError(f"{where}: cannot read {cell!r} as a UTC time YYYY-MM-DD HH:MM:SS[.fff]")
    return t


def _number(cell, where, what):
    try:
        x = float(cell)
    except ValueError:
        x = None
    if x is None or not np.isfinite(x):
        raise InvalidInputError(f"{where}: cannot read {cell!r} as a number ({what})")
    return x


def read_grains_header(lines, path):
    """Return a dict of the GRAINS header (parameter list, time window, sample counts) and the index of the
    column line; raise if the file is not a GRAINS export."""
    if not lines or lines[0].strip() != GRAINS_FIRST_LINE:
        first = lines[0].strip()[:60] if lines else ""
        raise InvalidInputError(f"{path}:1: not a GRAINS export (first line {first!r}, expected "
                                f"{GRAINS_FIRST_LINE!r})")
    if len(lines) <= GRAINS_HEADER_LINES:
        raise InvalidInputError(f"{path}: truncated: {len(lines)} lines, but a GRAINS export has "
                                f"{GRAINS_HEADER_LINES} header lines, a column line and data rows")
    head = [ln.strip() for ln in lines[:GRAINS_HEADER_LINES]]
    info = {"parameters": head[2], "note": "the time window and counts describe the whole original export, "
                                           "not the rows present (never checked against them)"}
    for label, key in (("# Time Window Start", "window_start"), ("# Time Window End", "window_end"),
                       ("# Number of samples", "samples")):
        for i, ln in enumerate(head[:-1]):
            if ln.startswith(label):
                info[key] = head[i + 1]
    col = lines[GRAINS_HEADER_LINES].strip()
    cells = [c.strip() for c in col.lstrip("#").split(",")]
    if not col.startswith("#") or cells[0] != "DATE TIME" or len(cells) != 5 \
            or tuple(c.split(" ")[0] for c in cells[1:]) != GRAINS_QUATERNION:
        raise InvalidInputError(f"{path}:{GRAINS_HEADER_LINES + 1}: wrong column line {col[:80]!r}; expected "
                                f"'# DATE TIME,' and the quaternion {', '.join(GRAINS_QUATERNION)}")
    return info


def read_opssat_attitude(path=OPSSAT_ATTITUDE, *, frame=OPSSAT_FRAME, limits=None):
    """Return the :class:`AttitudeHistory` of an OPS-SAT GRAINS attitude export (module docstring).

    ``history.header`` holds the export's header (reported, not checked); ``history.dropped['zero_rows']``
    counts the "no data" rows left out."""
    path = os.fspath(path)
    text = read_text(path, "GRAINS attitude export")
    lines = text.splitlines()
    header = read_grains_header(lines, path)
    times, q, where, zeros = [], [], [], 0
    for lineno, line in enumerate(lines[GRAINS_HEADER_LINES + 1:], start=GRAINS_HEADER_LINES + 2):
        if not line.strip():
            continue
        cells = line.split(",")
        loc = f"{path}:{lineno}"
        if len(cells) != 5:
            raise InvalidInputError(f"{loc}: expected 5 values (DATE TIME and 4 quaternion components), "
                                    f"got {len(cells)}; is the file truncated?")
        row = [_number(c, loc, "quaternion component") for c in cells[1:]]
        if not any(row):
            zeros += 1
            continue
        times.append(_datetime(cells[0], loc))
        q.append(row)
        where.append(loc)
    if not q:
        raise InvalidInputError(f"{path}: no attitude rows (after {zeros} rows of zeros = no data)")
    epochs = Epochs.from_datetime64(np.array(times))
    _check_increasing(epochs, where, path)
    q = np.array(q)
    _check_norms(q, where, OPSSAT_NORM_TOL)
    hist = AttitudeHistory(epochs, q, frame=frame, direction=OPSSAT_DIRECTION, scalar_first=OPSSAT_SCALAR_FIRST,
                           norm_tol=OPSSAT_NORM_TOL, limits=limits, source=path, dropped={"zero_rows": zeros})
    hist.header = header
    return hist


def _check_norms(q, where, tol):
    norm, off = norm_outliers(q, tol)
    if off.size:
        i = int(off[0])
        raise InvalidInputError(f"{where[i]}: quaternion norm {norm[i]:.4g} is not 1 within {tol:g} "
                                f"({off.size} such rows): not a 10-s average of attitudes; wrong column?")


def read_opssat_pd(path=OPSSAT_PD):
    """Return the :class:`DiodeReadings` (PD3, PD6) of the labelled OPS-SAT photodiode file (module docstring)."""
    path = os.fspath(path)
    text = read_text(path, "photodiode CSV")
    rows = list(csv.reader(io.StringIO(text, newline="")))
    head = [c.strip() for c in rows[0]] if rows else []
    if head[:3] != ["TIMESTAMP", "PD3", "PD6"]:
        raise InvalidInputError(f"{path}:1: header must start TIMESTAMP,PD3,PD6 (the labelled OPS-SAT file), "
                                f"got {','.join(head[:3])[:60]!r}")
    times, vals, where = [], [], []
    for lineno, cells in enumerate(rows[1:], start=2):
        if not cells or not "".join(cells).strip():
            continue
        loc = f"{path}:{lineno}"
        if len(cells) != len(head):
            raise InvalidInputError(f"{loc}: expected {len(head)} values, got {len(cells)}; is the file truncated?")
        times.append(_datetime(cells[0], loc))
        vals.append([_number(c, loc, n) for c, n in zip(cells[1:3], head[1:3])])
        where.append(loc)
    if not vals:
        raise InvalidInputError(f"{path}: no photodiode rows after the header")
    epochs = Epochs.from_datetime64(np.array(times))
    _check_increasing(epochs, where, path)
    theta, sat, counts = _theta(vals, ("PD3", "PD6"), where)
    counts["rows"] = len(vals)
    return DiodeReadings(epochs, ("PD3", "PD6"), theta, sat, np.ones(theta.shape, bool), source=path, counts=counts)


def read_opssat_log_2021(path, *, frame=OPSSAT_FRAME, limits=None):
    """Return (AttitudeHistory, DiodeReadings PD1..PD6) of one OPS-SAT 2021 on-board log (module docstring)."""
    path = os.fspath(path)
    text = read_text(path, "OPS-SAT 2021 log")
    rows = list(csv.reader(io.StringIO(text, newline="")))
    head = [c.strip() for c in rows[0]] if rows else []
    needed = LOG_2021_PD + LOG_2021_PD_VALID + LOG_2021_QUATERNION
    if not head or head[0] != "CADC0884" or any(n not in head for n in needed):
        raise InvalidInputError(f"{path}:1: not an OPS-SAT 2021 log header (expected it to start with CADC0884 "
                                f"and hold {', '.join(LOG_2021_PD)}, their flags and {', '.join(LOG_2021_QUATERNION)})")
    names = head[:-1] if head[-1] == "" else head
    width = len(names) + 1                         # the time column has no name: names sit one column left
    col = {n: i + 1 for i, n in enumerate(names)}
    times, theta, flags, quat, where = [], [], [], [], []
    for lineno, cells in enumerate(rows[1:], start=2):
        if not cells or not "".join(cells).strip():
            continue
        loc = f"{path}:{lineno}"
        if len(cells) != width:
            raise InvalidInputError(f"{loc}: expected {width} values (Unix ms and {len(names)} parameters), "
                                    f"got {len(cells)}; is the file truncated?")
        try:
            ms = int(cells[0])
        except ValueError:
            raise InvalidInputError(f"{loc}: cannot read {cells[0]!r} as a Unix time in ms") from None
        times.append(np.datetime64(ms, "ms").astype("datetime64[ns]"))

        def num(name):
            c = cells[col[name]].strip()
            return np.nan if c == "x" else _number(c, loc, name)

        def flag(name):
            c = cells[col[name]].strip().lower()
            if c not in ("true", "false", "x"):
                raise InvalidInputError(f"{loc}: validity flag {name} = {c!r}; expected true, false or x")
            return c == "true"
        theta.append([num(n) for n in LOG_2021_PD])
        flags.append([flag(n) for n in LOG_2021_PD_VALID])
        quat.append([num(n) for n in LOG_2021_QUATERNION])
        where.append(loc)
    if not times:
        raise InvalidInputError(f"{path}: no rows after the header")
    epochs = Epochs.from_datetime64(np.array(times))
    _check_increasing(epochs, where, path)
    pd_names = tuple(f"PD{k + 1}" for k in range(6))
    th, sat, counts = _theta(theta, pd_names, where)
    counts["rows"] = len(times)
    counts["not_acquired"] = int(np.isnan(th).sum())
    readings = DiodeReadings(epochs, pd_names, th, sat, np.array(flags, bool), source=path, counts=counts)
    q = np.array(quat)
    missing = ~np.all(np.isfinite(q), axis=1)
    zero = ~missing & ~np.any(np.nan_to_num(q) != 0, axis=1)
    keep = ~missing & ~zero
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        raise InvalidInputError(f"{path}: no row holds an acquired quaternion ({', '.join(LOG_2021_QUATERNION)})")
    qk = q[idx]
    changed = np.ones(len(idx), bool)
    changed[1:] = np.any(qk[1:] != qk[:-1], axis=1)
    part = np.zeros(len(idx), bool)
    part[1:] = changed[1:] & np.any(qk[1:] == qk[:-1], axis=1)
    # a held value lasting min_frozen_s or more keeps its last row too, so the history flags it frozen
    lim = limits if limits is not None else HistoryLimits()
    run = np.cumsum(changed) - 1
    last = np.r_[run[1:] != run[:-1], True]
    t_k = epochs.seconds_since(epochs[0])[idx]
    first_t = t_k[changed][run]
    held = last & ~changed & (lim.min_frozen_s is not None) & (t_k - first_t >= (lim.min_frozen_s or np.inf))
    changed = changed | held
    # a torn row mixes two estimates: beyond the tolerance it is left out (counted); an untorn one is refused
    norm = np.linalg.norm(qk, axis=1)
    torn_off = part & (np.abs(norm - 1.0) > OPSSAT_NORM_TOL)
    idx_new = idx[changed & ~torn_off]
    _check_norms(q[idx_new], [where[i] for i in idx_new], OPSSAT_NORM_TOL)
    dropped = {"not_acquired": int(missing.sum()), "zero_rows": int(zero.sum()),
               "repeated": int((~changed).sum()), "torn_off_norm": int(torn_off.sum())}
    hist = AttitudeHistory(epochs[idx_new], q[idx_new], frame=frame, direction=OPSSAT_DIRECTION,
                           scalar_first=OPSSAT_SCALAR_FIRST, norm_tol=OPSSAT_NORM_TOL, limits=limits, source=path,
                           dropped=dropped)
    hist.torn = int(part.sum())
    return hist, readings


def read_attitude_history(path, *, start=None, frame=None, direction=None, limits=None):
    """Return an :class:`AttitudeHistory` of any attitude file sunsim reads, told by its content.

    * a GRAINS export or an OPS-SAT 2021 log (their own convention; ``frame`` overrides OPSSAT_FRAME);
    * sunsim's absolute-time CSV (``time_utc,...``, :meth:`AttitudeHistory.from_csv`);
    * the relative-time CSV ``t_s,qw,qx,qy,qz`` (``q_gcrs_from_body`` unless ``frame``/``direction`` say
      otherwise): it carries no date, so ``start`` (its first row's UTC time) is required.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputNotFoundError(f"attitude file {path} not found; give an existing file")
    text = read_text(path, "attitude CSV file")
    first = next((ln.strip() for ln in text.splitlines() if ln.strip()), "")
    if first == GRAINS_FIRST_LINE:
        _no_direction(direction, path, "GRAINS export")
        return read_opssat_attitude(path, frame=frame or OPSSAT_FRAME, limits=limits)
    if first.startswith("CADC0884"):
        _no_direction(direction, path, "OPS-SAT 2021 log")
        return read_opssat_log_2021(path, frame=frame or OPSSAT_FRAME, limits=limits)[0]
    data = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if data and data[0].lower().startswith("time_utc"):
        return AttitudeHistory.from_csv(path, frame=frame, direction=direction, limits=limits)
    if data and data[0].replace(" ", "").lower().startswith("t_s"):
        if start is None:
            raise InvalidInputError(f"{path} holds relative times (t_s) and no date: give --start (the UTC time of "
                                    "its first row), or write the history with absolute times (time_utc column)")
        from simcore.environment.attitude import Attitude
        att = Attitude.from_file(path)
        epochs = Epochs.from_any(start) + (att.t_s - att.t_s[0])
        return AttitudeHistory(epochs, att.q_gcrs_from_body, frame=frame or "GCRF",
                               direction=direction or "body_to_frame", limits=limits, source=path)
    raise InvalidInputError(f"{path}: not an attitude file sunsim reads (a time_utc,qw,qx,qy,qz or t_s,qw,qx,qy,qz "
                            f"CSV, a GRAINS export or an OPS-SAT 2021 log); first line {first[:60]!r}")


def _no_direction(direction, path, what):
    if direction is not None and direction != OPSSAT_DIRECTION:
        raise InvalidInputError(f"{path} is an {what}, whose quaternion is {OPSSAT_DIRECTION} (shown with the data); "
                                f"drop the direction option")
