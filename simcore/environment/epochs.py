"""The one time representation inside sunsim: UTC as a two-part Julian date.

SGP4 (``sgp4_array(jd, fr)``), the IAU SOFA routines of pyerfa (time scales,
precession-nutation, Earth rotation) and the Sun ephemeris all take a
two-part Julian date, so an :class:`Epochs` carries exactly that: ``jd1``
(a day boundary, ``x.5``) and ``jd2`` (the fraction of the day, 0 <= jd2 < 1),
both float64 arrays of shape ``(N,)``. The split keeps ~1e-11 s resolution,
far below anything SGP4 or the sensor can resolve.

ISO-8601 strings, :class:`datetime.datetime` and :class:`numpy.datetime64`
are accepted at the edge (:meth:`Epochs.from_any`); naive datetimes and
strings without an offset are taken as UTC.

Leap seconds: the pair is in SOFA/erfa's UTC convention (``erfa.dtf2d``): the
fraction ``jd2`` is a share of *that day's* length, 86 401 s on a day that ends
in a leap second, so ``23:59:60.x`` on such a day is an instant of its own,
one SI second after 23:59:59.x and one before the next day's 00:00:00.x. On
every other day this is the ordinary 86 400-s Julian date. An ISO string with
second 60 is accepted on a day with a leap second (erfa's table) and refused
on any other. Arithmetic (:meth:`Epochs.__add__`, :meth:`Epochs.seconds_since`)
counts SI seconds, so a span that holds a leap second is one second longer in
UTC labels than its SI length suggests. numpy's datetime64 has no leap second:
:attr:`Epochs.datetime64` shows an instant inside one as the last nanosecond of
its day (the run file's ``t_s`` keeps the SI seconds).
"""
import re
import datetime as _dt
import warnings

import erfa
import numpy as np

from simcore.errors import InvalidInputError

JD_UNIX_EPOCH = 2440587.5  # 1970-01-01T00:00:00 UTC
SECONDS_PER_DAY = 86400.0
_NS_PER_DAY = 86_400_000_000_000

_FORMATS = ("an ISO-8601 string such as '2016-07-02T00:00:00Z', a "
            "datetime.datetime, a numpy.datetime64, or a list/array of these")


_LEAP_SECOND = re.compile(r"^(?P<head>.*[T ]\d{2}:\d{2}):60(?P<frac>[.,]\d+)?(?P<tail>.*)$")


def _leap_second(value, text):
    """Return (jd1, jd2) of an ISO string whose seconds field is 60 (a leap second), or refuse it."""
    m = _LEAP_SECOND.match(text)
    frac = float("0" + m["frac"].replace(",", ".")) if m["frac"] else 0.0
    try:   # second 59 of the same minute, to read the date and the offset with the standard parser
        before = _dt.datetime.fromisoformat((m["head"] + ":59" + m["tail"]).replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError as exc:
        raise InvalidInputError(f"cannot read {value!r} as a UTC time ({exc}); give {_FORMATS}") from None
    if before.tzinfo is not None:
        before = before.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", erfa.ErfaWarning)
        jd1, jd2 = erfa.dtf2d("UTC", before.year, before.month, before.day, before.hour, before.minute, 60.0 + frac)
    if any("after end of day" in str(w.message) for w in caught):
        if _leap_s(np.array([jd1]))[0] > 0:
            raise InvalidInputError(f"{value!r}: UTC {before.date()} ends in a leap second, but second 60 exists only "
                                    "as 23:59:60 UTC; give a second in 0..59 or 23:59:60")
        raise InvalidInputError(
            f"{value!r}: UTC {before.date()} has no leap second (second 60 exists only as 23:59:60 UTC at the end "
            "of a day with a leap second, e.g. 2016-12-31; IERS Bulletin C); give a second in 0..59")
    return float(jd1), float(jd2)


def _parse_one(value):
    """Return numpy datetime64[ns] (UTC) for one edge value, or (jd1, jd2) for a leap second."""
    if isinstance(value, np.datetime64):
        if np.isnat(value):
            raise ValueError("got NaT (not-a-time); give a real UTC instant")
        return value.astype("datetime64[ns]")
    if isinstance(value, _dt.datetime):
        if value.tzinfo is not None:
            value = value.astimezone(_dt.timezone.utc).replace(tzinfo=None)
        return np.datetime64(value, "ns")
    if isinstance(value, _dt.date):
        return np.datetime64(value, "ns")
    if isinstance(value, str):
        text = value.strip()
        if _LEAP_SECOND.match(text):
            return _leap_second(value, text)
        try:
            parsed = _dt.datetime.fromisoformat(text.replace("Z", "+00:00").replace("z", "+00:00"))
        except ValueError as exc:
            raise InvalidInputError(f"cannot read {value!r} as a UTC time ({exc}); give {_FORMATS}") from None
        if parsed.tzinfo is not None:
            parsed = parsed.astimezone(_dt.timezone.utc).replace(tzinfo=None)
        return np.datetime64(parsed, "ns")
    raise TypeError(f"cannot use {type(value).__name__} {value!r} as a time; give {_FORMATS}")


def _tai_minus_utc_at_0h(jd1):
    """Return TAI - UTC (s, erfa's table) at 0h UTC of the days starting at ``jd1`` (x.5)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year" past erfa's leap-second table
        y, m, d, _ = erfa.jd2cal(np.asarray(jd1, dtype=float), 0.0)
        return erfa.dat(y, m, d, 0.0)


def _leap_s(jd1):
    """Return the leap second (s; 1 on a day that ends in one, else 0) of the days starting at ``jd1``."""
    jd1 = np.asarray(jd1, dtype=float)
    return _tai_minus_utc_at_0h(jd1 + 1.0) - _tai_minus_utc_at_0h(jd1)


def _day_length_s(jd1):
    """Return the length (SI s) of the UTC days starting at ``jd1``: 86 400, or 86 401 with a leap second."""
    return SECONDS_PER_DAY + _leap_s(jd1)


def _leap_between(jd1_a, jd1_b):
    """Return where the days from ``jd1_a`` to ``jd1_b`` (either order, both included) hold a leap second."""
    lo, hi = np.minimum(jd1_a, jd1_b), np.maximum(jd1_a, jd1_b)
    return _tai_minus_utc_at_0h(hi + 1.0) != _tai_minus_utc_at_0h(lo)


class Epochs:
    """UTC instants, shape (N,), stored as a two-part Julian date ``jd1 + jd2``."""

    __slots__ = ("jd1", "jd2")

    def __init__(self, jd1, jd2=0.0):
        jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, dtype=float)),
                                       np.atleast_1d(np.asarray(jd2, dtype=float)))
        if jd1.ndim != 1:
            raise ValueError(f"Epochs are one-dimensional; got shape {jd1.shape}")
        if not (np.all(np.isfinite(jd1)) and np.all(np.isfinite(jd2))):
            raise ValueError("Epochs got a non-finite Julian date")
        # Normalise: jd1 on a day boundary (x.5), 0 <= jd2 < 1. Whole days move
        # between the parts exactly, so the split loses nothing.
        day1 = np.floor(jd1 - 0.5)
        frac1 = jd1 - 0.5 - day1
        total_frac = frac1 + jd2
        carry = np.floor(total_frac)
        self.jd1 = day1 + carry + 0.5
        self.jd2 = total_frac - carry

    # ---- constructors -------------------------------------------------
    @classmethod
    def from_any(cls, value):
        """Return Epochs for an edge value (string, datetime, datetime64, sequence, Epochs)."""
        if isinstance(value, Epochs):
            return value
        if isinstance(value, np.ndarray) and np.issubdtype(value.dtype, np.datetime64):
            return cls.from_datetime64(value)
        if isinstance(value, (str, _dt.datetime, _dt.date, np.datetime64)):
            items = [value]
        else:
            try:
                items = list(value)
            except TypeError:
                raise TypeError(f"cannot use {type(value).__name__} {value!r} as a time; give {_FORMATS}") from None
        parsed = [_parse_one(v) for v in items]
        leap = [i for i, p in enumerate(parsed) if isinstance(p, tuple)]
        if not leap:
            return cls.from_datetime64(np.array(parsed, dtype="datetime64[ns]"))
        plain = [i for i in range(len(parsed)) if i not in leap]
        jd1, jd2 = np.empty(len(parsed)), np.empty(len(parsed))
        if plain:
            e = cls.from_datetime64(np.array([parsed[i] for i in plain], dtype="datetime64[ns]"))
            jd1[plain], jd2[plain] = e.jd1, e.jd2
        jd1[leap], jd2[leap] = zip(*(parsed[i] for i in leap))
        return cls(jd1, jd2)

    @classmethod
    def from_datetime64(cls, values):
        """Return Epochs for numpy datetime64 values (UTC)."""
        ns = np.atleast_1d(np.asarray(values, dtype="datetime64[ns]"))
        if np.any(np.isnat(ns)):
            raise ValueError("got NaT (not-a-time); give real UTC instants")
        i = ns.astype(np.int64)
        days, rem = np.divmod(i, _NS_PER_DAY)
        jd1 = JD_UNIX_EPOCH + days.astype(float)
        # numpy counts 86 400 s in every day; on a day with a leap second the share of the day is of 86 401 s.
        return cls(jd1, rem.astype(float) / (_NS_PER_DAY + _leap_s(jd1) * 1e9))

    @classmethod
    def range(cls, start, duration_s, step_s):
        """Return epochs ``start, start + step, ...`` covering ``[0, duration_s)``."""
        duration_s, step_s = float(duration_s), float(step_s)
        if not np.isfinite(step_s) or step_s <= 0:
            raise InvalidInputError(f"step must be a positive number of seconds, got {step_s}")
        if not np.isfinite(duration_s) or duration_s <= 0:
            raise InvalidInputError(f"duration must be a positive number of seconds, got {duration_s}")
        n = int(np.ceil(duration_s / step_s - 1e-9))
        start = cls.from_any(start)
        if len(start) != 1:
            raise ValueError("range() needs a single start time")
        return start + np.arange(n) * step_s

    # ---- views ----------------------------------------------------------
    def __len__(self):
        return self.jd1.shape[0]

    def __getitem__(self, index):
        return Epochs(np.atleast_1d(self.jd1[index]), np.atleast_1d(self.jd2[index]))

    def __add__(self, seconds):
        """Return these epochs shifted by ``seconds`` (SI seconds, scalar or (N,) array), across leap seconds."""
        seconds = np.asarray(seconds, dtype=float)
        plain = Epochs(self.jd1, self.jd2 + seconds / SECONDS_PER_DAY)
        jd1, s = np.broadcast_arrays(self.jd1, self.jd2 * _day_length_s(self.jd1) + seconds)
        touched = _leap_between(jd1, plain.jd1)
        if not touched.any():
            return plain                  # no leap second on the way: the exact 86 400-s arithmetic
        # Walk day by day from the start day: s is the SI seconds since its 0h.
        day, s = jd1[touched].copy(), s[touched].copy()
        for _ in range(int(np.max(np.abs(s))) // 86399 + 3):
            length = _day_length_s(day)
            fwd, back = s >= length, s < 0
            if not (fwd.any() or back.any()):
                break
            s = np.where(fwd, s - length, s)
            day = np.where(fwd, day + 1.0, day)
            s = np.where(back, s + _day_length_s(day - 1.0), s)
            day = np.where(back, day - 1.0, day)
        jd1_out, jd2_out = plain.jd1.copy(), plain.jd2.copy()
        jd1_out[touched], jd2_out[touched] = day, s / _day_length_s(day)
        return Epochs(jd1_out, jd2_out)

    def __eq__(self, other):
        return (isinstance(other, Epochs) and len(self) == len(other)
                and bool(np.all(self.jd1 == other.jd1) and np.all(self.jd2 == other.jd2)))

    def __repr__(self):
        iso = self.iso()
        body = ", ".join(iso) if len(iso) <= 3 else f"{iso[0]}, ..., {iso[-1]}"
        return f"Epochs([{body}], n={len(self)})"

    @property
    def jd(self):
        """Return the one-part UTC Julian date (loses ~20 us; for display)."""
        return self.jd1 + self.jd2

    def _seconds_of_day(self):
        return self.jd2 * _day_length_s(self.jd1)

    @property
    def datetime64(self):
        """Return the instants as numpy datetime64[ns] (UTC; an instant inside a leap second, which numpy
        cannot show, as the last nanosecond of its day)."""
        days = np.round(self.jd1 - JD_UNIX_EPOCH).astype(np.int64)
        ns = np.minimum(np.round(self._seconds_of_day() * 1e9), _NS_PER_DAY - 1).astype(np.int64)
        return (days * _NS_PER_DAY + ns).astype("datetime64[ns]")

    def iso(self):
        """Return ISO-8601 strings with a trailing 'Z' (millisecond precision; a leap second as 23:59:60.xxx)."""
        out = [str(t)[:23] + "Z" for t in self.datetime64.astype("datetime64[ms]")]
        sod = self._seconds_of_day()
        for i in np.flatnonzero(sod >= SECONDS_PER_DAY):
            ms = min(int(np.floor((sod[i] - SECONDS_PER_DAY) * 1000.0 + 1e-6)), 999)
            out[i] = f"{out[i][:17]}60.{ms:03d}Z"
        return out

    def seconds_since(self, reference):
        """Return SI seconds (float, (N,)) elapsed since ``reference`` (leap seconds counted)."""
        ref = Epochs.from_any(reference)
        plain = ((self.jd1 - ref.jd1[0]) + (self.jd2 - ref.jd2[0])) * SECONDS_PER_DAY
        touched = _leap_between(np.broadcast_to(ref.jd1[:1], self.jd1.shape), self.jd1)
        if not touched.any():
            return plain
        # whole days of 86 400 s, the seconds within each day, and the leap seconds TAI - UTC gained in between
        exact = ((self.jd1 - ref.jd1[0]) * SECONDS_PER_DAY + (self._seconds_of_day() - ref._seconds_of_day()[0])
                 + (_tai_minus_utc_at_0h(self.jd1) - _tai_minus_utc_at_0h(ref.jd1[:1])))
        return np.where(touched, exact, plain)

    # ---- time scales ------------------------------------------------------
    def _erfa_utc(self):
        """Return (jd1, jd2) in erfa's UTC convention: the pair itself (see the module's note)."""
        return self.jd1, self.jd2

    def tai(self):
        """Return TAI as a two-part Julian date (leap seconds from erfa's table)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            return erfa.utctai(*self._erfa_utc())

    def tt(self):
        """Return TT as a two-part Julian date."""
        return erfa.taitt(*self.tai())

    def ut1(self, dut1_s=0.0):
        """Return UT1 = UTC + dut1_s as a two-part Julian date."""
        dut1 = np.broadcast_to(np.asarray(dut1_s, dtype=float), self.jd1.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            return erfa.utcut1(*self._erfa_utc(), dut1)
