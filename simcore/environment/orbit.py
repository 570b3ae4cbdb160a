"""The satellite's orbit: a validated TLE propagated with SGP4 (the sgp4 array API).

:class:`Orbit` holds one two-line element set (TLE) and its ``sgp4.api.Satrec``;
:meth:`Orbit.propagate` returns an :class:`OrbitState` with positions and
velocities in TEME (SGP4's own frame), GCRS and ITRS (ECEF), see
:mod:`simcore.environment.frames` for the frame chain and its accuracy.

Per-epoch problems are flagged, not raised: rows with a nonzero SGP4 error
code (1-6, e.g. 6 = the orbit has decayed) are NaN, and ``stale`` marks
epochs more than ``max_age_days`` from the TLE epoch (SGP4's error grows by
roughly 1-3 km per day away from the epoch). Asking for an epoch more than
:data:`MAX_SPAN_DAYS` (10 years) from the TLE epoch is a mistake (probably the
wrong TLE or the wrong date) and raises ``ValueError``.
"""
import importlib.resources
import os
import re
from dataclasses import dataclass

import numpy as np
from sgp4.api import SGP4_ERRORS, Satrec

from simcore.environment import frames
from simcore.errors import InputNotFoundError, InvalidInputError
from simcore.environment.epochs import Epochs

DEFAULT_TLE = "estcube1_2016-07-27.tle"
MAX_SPAN_DAYS = 3650.0       # beyond this a TLE is meaningless: raise
DEFAULT_MAX_AGE_DAYS = 30.0  # beyond this flag epochs as stale
TLE_LINE_LENGTH = 69

_FLOAT = r"[ +-]?(\d+\.?\d*|\.\d+)"


class TLEError(InvalidInputError):
    """A two-line element set that cannot be used (format, checksum, SGP4 initialisation)."""


class TLENotFoundError(InputNotFoundError):
    """A TLE file that does not exist."""


def error_message(code):
    """Return sgp4's explanation of an SGP4 error code (0 = no error)."""
    code = int(code)
    if code == 0:
        return "no error"
    return SGP4_ERRORS.get(code, f"unknown SGP4 error code {code}")


def tle_checksum(line):
    """Return the TLE checksum of ``line``: digits summed, '-' counts 1, over columns 1-68, mod 10."""
    total = 0
    for ch in line[:68]:
        if ch.isdigit():
            total += int(ch)
        elif ch == "-":
            total += 1
    return total % 10


def _check_field(line_no, line, start, stop, what, pattern, where):
    """Raise TLEError unless columns start..stop (1-based, inclusive, blanks stripped) match ``pattern``."""
    text = line[start - 1:stop]
    if not re.fullmatch(pattern, text.strip()):
        raise TLEError(f"{where}line {line_no} columns {start}-{stop} ({what}) should be a number, "
                       f"got {text!r}; is this really a TLE?")


def validate_tle(line1, line2, *, verify_checksum=True, where=""):
    """Return (line1, line2) stripped of line ends after checking their format.

    Raises :class:`TLEError` naming the line and what is wrong: a line that is
    not a TLE line, a truncated or over-long line (expected 69 characters), a
    bad checksum (expected vs found), different satellite numbers on the two
    lines, or unreadable numeric fields.
    """
    if not isinstance(line1, str) or not isinstance(line2, str):
        raise TLEError(f"{where}TLE lines must be strings, got {type(line1).__name__} and {type(line2).__name__}")
    lines = [line1.rstrip("\r\n").rstrip(), line2.rstrip("\r\n").rstrip()]
    for no, line in enumerate(lines, start=1):
        if not line.startswith(f"{no} "):
            raise TLEError(f"{where}this is not a TLE: line {no} must start with '{no} ' "
                           f"(got {line[:20]!r}...); a TLE is two 69-character lines, optionally "
                           "preceded by a name line")
        if len(line) != TLE_LINE_LENGTH:
            what = "truncated" if len(line) < TLE_LINE_LENGTH else "too long"
            raise TLEError(f"{where}TLE line {no} is {what}: expected {TLE_LINE_LENGTH} characters, "
                           f"got {len(line)}: {line!r}")
    l1, l2 = lines
    _check_field(1, l1, 19, 32, "epoch YYDDD.DDDDDDDD", r"\d{1,5}\.\d*", where)
    _check_field(2, l2, 9, 16, "inclination, deg", _FLOAT, where)
    _check_field(2, l2, 18, 25, "right ascension of the node, deg", _FLOAT, where)
    _check_field(2, l2, 27, 33, "eccentricity, decimal point assumed", r"\d{7}", where)
    _check_field(2, l2, 35, 42, "argument of perigee, deg", _FLOAT, where)
    _check_field(2, l2, 44, 51, "mean anomaly, deg", _FLOAT, where)
    _check_field(2, l2, 53, 63, "mean motion, rev/day", _FLOAT, where)
    if verify_checksum:
        for no, line in ((1, l1), (2, l2)):
            found = line[68]
            expected = tle_checksum(line)
            if found != str(expected):
                raise TLEError(f"{where}TLE line {no} fails its checksum: expected {expected} (from columns "
                               f"1-68), found {found!r} in column 69. The line is corrupted or was edited; "
                               "fetch the TLE again (an edited line needs its checksum recomputed: the sum of its "
                               "digits, each '-' counting 1, modulo 10)")
    if l1[2:7] != l2[2:7]:
        raise TLEError(f"{where}the two TLE lines belong to different satellites: line 1 has satellite "
                       f"number {l1[2:7].strip()!r}, line 2 has {l2[2:7].strip()!r}")
    return l1, l2


@dataclass(frozen=True)
class OrbitState:
    """Satellite states at N epochs (SI units, time leading); rows with ``error_code != 0`` are NaN."""

    epochs: Epochs
    r_teme_m: np.ndarray    # (N, 3)
    v_teme_m_s: np.ndarray  # (N, 3)
    r_gcrs_m: np.ndarray    # (N, 3)
    v_gcrs_m_s: np.ndarray  # (N, 3)
    r_ecef_m: np.ndarray    # (N, 3) ITRS
    v_ecef_m_s: np.ndarray  # (N, 3) ITRS, Earth-rotation term included
    error_code: np.ndarray  # (N,) int, SGP4 error code, 0 = fine (see error_message)
    age_days: np.ndarray    # (N,) epoch - TLE epoch, days
    stale: np.ndarray       # (N,) bool, |age_days| > max_age_days

    def __len__(self):
        return len(self.epochs)

    @property
    def valid(self):
        """Return (N,) bool: SGP4 reported no error at that epoch."""
        return self.error_code == 0


class Orbit:
    """One satellite's TLE and its SGP4 propagator."""

    def __init__(self, line1, line2, name=None, *, verify_checksum=True, _where=""):
        l1, l2 = validate_tle(line1, line2, verify_checksum=verify_checksum, where=_where)
        satrec = Satrec.twoline2rv(l1, l2)
        if satrec.error != 0:
            raise TLEError(f"{_where}SGP4 cannot initialise this TLE (error code {satrec.error}: "
                           f"{error_message(satrec.error)}); the elements are not a valid orbit")
        self._line1, self._line2, self._satrec = l1, l2, satrec
        self._name = None if name is None else (str(name).strip() or None)

    # ---- constructors -------------------------------------------------
    @classmethod
    def from_tle(cls, line1, line2, name=None, *, verify_checksum=True):
        """Return the Orbit of one TLE (two 69-character lines); raise :class:`TLEError` if it is bad."""
        return cls(line1, line2, name, verify_checksum=verify_checksum)

    @classmethod
    def from_file(cls, path, satellite=None):
        """Return the Orbit of a 2- or 3-line TLE file.

        A file with several satellites needs ``satellite``: a name
        (case-insensitive) or a NORAD catalogue number.
        """
        path = os.fspath(path)
        try:
            with open(path, "rb") as f:
                raw = f.read()
        except OSError as exc:
            if isinstance(exc, FileNotFoundError):
                raise TLENotFoundError(f"TLE file {path} not found; give an existing 2- or 3-line TLE file") from None
            raise TLEError(f"cannot read TLE file {path!r}: {exc.strerror}") from None
        return cls._from_text(raw, path, satellite)

    @classmethod
    def default(cls, satellite=None):
        """Return the shipped ESTCube-1 orbit (NORAD 39161, TLE epoch 2016-07-27, ``data/estcube1_2016-07-27.tle``);
        ``satellite`` (a name or NORAD id), when given, must name it."""
        res = importlib.resources.files("simcore") / "data" / DEFAULT_TLE
        return cls._from_text(res.read_bytes(), str(res), satellite)

    @classmethod
    def _from_text(cls, raw, path, satellite):
        if b"\x00" in raw:
            raise TLEError(f"{path!r} is not a TLE file (it holds binary data); give a text file "
                           "with two 69-character lines per satellite")
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                raise TLEError(f"{path!r} is not a TLE file (not ASCII text); give a text file "
                               "with two 69-character lines per satellite") from None
        entries = _split_tle_text(text, path)
        if satellite is None:
            if len(entries) > 1:
                listing = ", ".join(f"{e[0] or '(no name)'} [{e[1][2:7].strip()}]" for e in entries)
                raise TLEError(f"{path!r} holds {len(entries)} satellites; choose one by name or NORAD id "
                               f"(--satellite): {listing}")
            chosen = entries[0]
        else:
            chosen = _choose(entries, satellite, path)
        name, l1, l2, lineno = chosen
        return cls(l1, l2, name, _where=f"{path}:{lineno}: ")

    # ---- properties ---------------------------------------------------
    @property
    def satrec(self):
        """Return the ``sgp4.api.Satrec`` of this TLE."""
        return self._satrec

    @property
    def line1(self):
        return self._line1

    @property
    def line2(self):
        return self._line2

    @property
    def name(self):
        """Return the satellite name (from a 3-line TLE), or the NORAD id as text when there is none."""
        return self._name if self._name is not None else str(self.norad_id)

    @property
    def norad_id(self):
        """Return the NORAD catalogue number (int)."""
        return int(self._satrec.satnum)

    @property
    def period_s(self):
        """Return the anomalistic period (s) from the TLE's mean motion."""
        return 2 * np.pi / self._satrec.no_kozai * 60.0

    @property
    def epoch(self):
        """Return the TLE epoch (UTC) as a one-element :class:`Epochs`."""
        return Epochs(self._satrec.jdsatepoch, self._satrec.jdsatepochF)

    def __repr__(self):
        return f"Orbit(name={self.name!r}, norad_id={self.norad_id}, epoch={self.epoch.iso()[0]})"

    # ---- propagation --------------------------------------------------
    def propagate(self, times, *, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, max_age_days=DEFAULT_MAX_AGE_DAYS):
        """Return the :class:`OrbitState` at ``times`` (anything :meth:`Epochs.from_any` accepts).

        SGP4 via ``Satrec.sgp4_array``; TEME -> GCRS / ITRS via
        :mod:`simcore.environment.frames` with the Earth-orientation parameters ``dut1_s``
        (UT1 - UTC, s), ``xp_rad``, ``yp_rad`` (polar motion, rad). Rows with an
        SGP4 error are NaN (``error_code`` says why); ``stale`` flags epochs
        more than ``max_age_days`` from the TLE epoch. Raises ``ValueError`` for
        epochs more than 10 years from the TLE epoch.
        """
        epochs = Epochs.from_any(times)
        if not (max_age_days > 0):
            raise ValueError(f"max_age_days must be a positive number of days, got {max_age_days!r}")
        sat = self._satrec
        # SGP4 runs on the time elapsed since the TLE epoch: SI seconds, leap seconds included (Epochs).
        age = epochs.seconds_since(self.epoch) / 86400.0
        worst = int(np.argmax(np.abs(age)))
        if abs(age[worst]) > MAX_SPAN_DAYS:
            raise InvalidInputError(
                f"requested time {epochs[worst].iso()[0]} is {age[worst]:+.0f} days from the epoch of the TLE of "
                f"{self.name} ({self.epoch.iso()[0]}); SGP4 is meaningless that far ({MAX_SPAN_DAYS:.0f} days "
                "at most, and it drifts 1-3 km per day): use a TLE from near the requested time")
        err, r_km, v_km_s = sat.sgp4_array(np.full(age.shape, sat.jdsatepoch), sat.jdsatepochF + age)
        err = np.asarray(err, dtype=np.int64)
        bad = err != 0
        r = np.asarray(r_km, dtype=float) * 1e3
        v = np.asarray(v_km_s, dtype=float) * 1e3
        r[bad] = np.nan
        v[bad] = np.nan
        r_gcrs, v_gcrs, r_itrs, v_itrs = frames.teme_to_all(r, v, epochs, dut1_s, xp_rad, yp_rad)
        return OrbitState(epochs=epochs, r_teme_m=r, v_teme_m_s=v, r_gcrs_m=r_gcrs, v_gcrs_m_s=v_gcrs,
                          r_ecef_m=r_itrs, v_ecef_m_s=v_itrs, error_code=err, age_days=age,
                          stale=np.abs(age) > max_age_days)


def _split_tle_text(text, path):
    """Return [(name or None, line1, line2, file line number of line 1)] from TLE text."""
    lines = text.splitlines()
    entries = []
    pending_name = None
    i = 0
    while i < len(lines):
        line = lines[i].rstrip()
        if not line.strip():
            i += 1
            continue
        if line.startswith("1 "):
            if i + 1 >= len(lines) or not lines[i + 1].startswith("2 "):
                raise TLEError(f"{path}:{i + 1}: TLE line 1 is not followed by a line 2 (a line starting '2 '); "
                               "the file is truncated or not a TLE file")
            entries.append((pending_name, line, lines[i + 1].rstrip(), i + 1))
            pending_name = None
            i += 2
            continue
        if line.startswith("2 "):
            raise TLEError(f"{path}:{i + 1}: TLE line 2 without a line 1 before it; is this a TLE file?")
        if pending_name is not None:
            raise TLEError(f"{path}:{i + 1}: this is not a TLE file: expected lines starting '1 ' and '2 ' "
                           f"(optionally after one name line), got {pending_name[:30]!r} then {line[:30]!r}")
        name = line.strip()
        if name.startswith("0 "):          # Space-Track 3LE name lines
            name = name[2:].strip()
        pending_name = name
        i += 1
    if not entries:
        raise TLEError(f"{path!r} is not a TLE file: found no pair of lines starting '1 ' and '2 ' "
                       "(a TLE is two 69-character lines, optionally preceded by a name line)")
    return entries


def _choose(entries, satellite, path):
    key = str(satellite).strip()
    matches = []
    for e in entries:
        name, l1 = e[0], e[1]
        if name is not None and name.strip().lower() == key.lower():
            matches.append(e)
        elif key.isdigit() and l1[2:7].strip().isdigit() and int(l1[2:7]) == int(key):
            matches.append(e)
        elif l1[2:7].strip().upper() == key.upper():   # alpha-5 catalogue numbers
            matches.append(e)
    if not matches:
        listing = ", ".join(f"{e[0] or '(no name)'} [{e[1][2:7].strip()}]" for e in entries)
        raise TLEError(f"no satellite {satellite!r} in {path!r}; it holds: {listing}")
    if len(matches) > 1:
        raise TLEError(f"{len(matches)} entries in {path!r} match {satellite!r} (lines "
                       f"{', '.join(str(m[3]) for m in matches)}); use a file with one TLE per satellite")
    return matches[0]
