"""The one time representation inside sunsim: UTC as a two-part Julian date.

SGP4 (``sgp4_array(jd, fr)``), the IAU SOFA routines of pyerfa (time scales,
precession-nutation, Earth rotation) and the Sun ephemeris all take a
two-part Julian date, so an :class:`Epochs` carries exactly that: ``jd1``
(a day boundary, ``x.5``) and ``jd2`` (the fraction of the day, 0 <= jd2 < 1),
both float64 arrays of shape ``(N,)``. The split keeps ~1e-11 s resolution,
far below anything SGP4 or the sensor can resolve.

ISO-8601 strings, :class:`datetime.datetime` and :class:`numpy.datetime64`
are accepted at the edge (:meth:`Epochs.from_any`); naive datetimes and
strings without an offset are taken as UTC. Like sgp4's ``jday`` and numpy,
a UTC day is counted as 86 400 s when converting from calendar values;
leap seconds enter where they matter, in :meth:`Epochs.tt` (via erfa).
"""
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


def _parse_one(value):
    """Return numpy datetime64[ns] (UTC) for one edge value."""
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
        try:
            parsed = _dt.datetime.fromisoformat(text.replace("Z", "+00:00").replace("z", "+00:00"))
        except ValueError as exc:
            raise InvalidInputError(f"cannot read {value!r} as a UTC time ({exc}); give {_FORMATS}") from None
        if parsed.tzinfo is not None:
            parsed = parsed.astimezone(_dt.timezone.utc).replace(tzinfo=None)
        return np.datetime64(parsed, "ns")
    raise TypeError(f"cannot use {type(value).__name__} {value!r} as a time; give {_FORMATS}")


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
            return cls.from_datetime64(np.array([_parse_one(value)]))
        try:
            items = list(value)
        except TypeError:
            raise TypeError(f"cannot use {type(value).__name__} {value!r} as a time; give {_FORMATS}") from None
        return cls.from_datetime64(np.array([_parse_one(v) for v in items], dtype="datetime64[ns]"))

    @classmethod
    def from_datetime64(cls, values):
        """Return Epochs for numpy datetime64 values (UTC)."""
        ns = np.atleast_1d(np.asarray(values, dtype="datetime64[ns]"))
        if np.any(np.isnat(ns)):
            raise ValueError("got NaT (not-a-time); give real UTC instants")
        i = ns.astype(np.int64)
        days, rem = np.divmod(i, _NS_PER_DAY)
        return cls(JD_UNIX_EPOCH + days.astype(float), rem.astype(float) / _NS_PER_DAY)

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
        """Return these epochs shifted by ``seconds`` (scalar or (N,) array)."""
        return Epochs(self.jd1, self.jd2 + np.asarray(seconds, dtype=float) / SECONDS_PER_DAY)

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

    @property
    def datetime64(self):
        """Return the instants as numpy datetime64[ns] (UTC)."""
        days = np.round(self.jd1 - JD_UNIX_EPOCH).astype(np.int64)
        ns = np.round(self.jd2 * _NS_PER_DAY).astype(np.int64)
        return (days * _NS_PER_DAY + ns).astype("datetime64[ns]")

    def iso(self):
        """Return ISO-8601 strings with a trailing 'Z' (millisecond precision)."""
        return [str(t)[:23] + "Z" for t in self.datetime64.astype("datetime64[ms]")]

    def seconds_since(self, reference):
        """Return seconds (float, (N,)) elapsed since ``reference`` (86 400 s per day)."""
        ref = Epochs.from_any(reference)
        return ((self.jd1 - ref.jd1[0]) + (self.jd2 - ref.jd2[0])) * SECONDS_PER_DAY

    # ---- time scales ------------------------------------------------------
    def _erfa_utc(self):
        """Return (jd1, jd2) in erfa's UTC convention.

        Epochs count 86 400 s per day (like numpy and sgp4); erfa reads the
        fraction of a day that ends in a leap second as a share of 86 401 s.
        """
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year" past erfa's leap-second table
            y0, m0, d0, _ = erfa.jd2cal(self.jd1, 0.0)
            y1, m1, d1, _ = erfa.jd2cal(self.jd1 + 1.0, 0.0)
            leap = erfa.dat(y1, m1, d1, 0.0) - erfa.dat(y0, m0, d0, 0.0)
        return self.jd1, self.jd2 * SECONDS_PER_DAY / (SECONDS_PER_DAY + leap)

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
