"""An orbit from a CCSDS Orbit Ephemeris Message: interpolated states with the interface of the SGP4 orbit.

:class:`EphemerisOrbit` is what ``sunsim run --orbit FILE.oem`` flies. Like
:class:`simcore.environment.orbit.Orbit` it has :meth:`EphemerisOrbit.propagate` (an
:class:`~simcore.environment.orbit.OrbitState` in TEME, GCRS and ITRS), ``name``, ``epoch`` and
``period_s``; it has no TLE (``satrec`` is absent).

Interpolation, as each segment declares (CCSDS 502.0-B-2 sec. 5.2.4, ``INTERPOLATION`` and
``INTERPOLATION_DEGREE``; undeclared: Lagrange of degree :data:`simcore.environment.ccsds.DEFAULT_DEGREE`):

* LAGRANGE, degree n: the polynomial through the n + 1 states nearest the epoch (the window
  centred on it, shifted inward at a segment's ends), for positions and, separately, velocities;
* HERMITE, degree n: the osculating polynomial through positions and velocities of m = (n + 1) / 2
  (rounded up) states, so of degree 2m - 1 >= n; velocities are its derivative;
* LINEAR: Lagrange of degree 1.

Time runs in TAI seconds (a leap second inside the span does not bend the interpolation). The
interpolation happens in the message's frame; the states are then rotated into TEME (EME2000 and
GCRF through :func:`simcore.environment.frames.R_between`, ITRF through
:func:`simcore.environment.frames.rv_teme_from_itrs`, Earth-rotation term included) and from there
into GCRS and ITRS exactly as the SGP4 orbit's are (:func:`simcore.environment.frames.teme_to_all`).

An ITRF ephemeris needs Earth-orientation data to be placed in inertial space: without them
(``dut1_s`` = 0, no polar motion) its inertial positions are up to ~400 m off along track
(0.9 s x 465 m/s); pass IERS Bulletin A values as ``dut1_s``, ``xp_rad``, ``yp_rad`` (the same options
as every frame conversion). The inertial frames need none.

Epochs outside every segment are refused (:meth:`EphemerisOrbit.require`, the span and the gaps
in the message); a segment is never interpolated across its ends, so a gap between segments (or
a manoeuvre boundary) is honoured: :meth:`EphemerisOrbit.sample_epochs` leaves it out.
"""
import hashlib
import os

import numpy as np
from scipy.interpolate import KroghInterpolator

from simcore.environment import ccsds, frames
from simcore.environment.epochs import Epochs
from simcore.environment.orbit import OrbitState
from simcore.errors import InvalidInputError

MU_EARTH_M3_S2 = 3.986004418e14     # IERS 2010 conventions (TT-compatible GM), for the period only


def _tai_seconds(epochs, ref):
    """Return TAI seconds of ``epochs`` since the TAI instant ``ref`` (two-part JD)."""
    t1, t2 = epochs.tai()
    return ((t1 - ref[0]) + (t2 - ref[1])) * 86400.0


class _Piece:
    """One OEM segment ready to interpolate: TAI seconds, states in metres, the method and its points."""

    def __init__(self, seg, ref):
        m = seg.meta
        self.frame = ccsds.OEM_FRAMES[m["REF_FRAME"].strip().upper()]
        self.method = m.get("INTERPOLATION", "LAGRANGE").strip().upper()
        degree = int(m.get("INTERPOLATION_DEGREE", ccsds.DEFAULT_DEGREE if self.method != "LINEAR" else 1))
        if self.method == "LINEAR":
            self.method, degree = "LAGRANGE", 1
        self.degree = degree
        n = len(seg.epochs)
        points = degree + 1 if self.method == "LAGRANGE" else -(-(degree + 1) // 2)
        self.points = max(2, min(points, n))
        self.t = _tai_seconds(seg.epochs, ref)
        self.r = seg.values[:, :3] * 1e3
        self.v = seg.values[:, 3:6] * 1e3
        first = seg.epochs[0] if seg.useable_start is None else seg.useable_start
        last = seg.epochs[-1] if seg.useable_stop is None else seg.useable_stop
        self.lo = max(self.t[0], _tai_seconds(first, ref)[0])
        self.hi = min(self.t[-1], _tai_seconds(last, ref)[0])
        self.first_utc, self.last_utc = first, last

    def covers(self, t):
        return (t >= self.lo - 1e-6) & (t <= self.hi + 1e-6)

    def interpolate(self, t):
        """Return (r, v), each (M, 3), in the segment's frame at TAI seconds ``t`` (M,) inside it."""
        n, k = len(self.t), self.points
        i = np.searchsorted(self.t, t)
        start = np.clip(i - k // 2, 0, n - k)
        r = np.empty((len(t), 3))
        v = np.empty((len(t), 3))
        for s in np.unique(start):
            sel = start == s
            x = self.t[s:s + k]
            c, h = x.mean(), max(x[-1] - x[0], 1e-9)
            u = (t[sel] - c) / h                            # scaled time: a well-conditioned polynomial
            xu = (x - c) / h
            if self.method == "LAGRANGE":
                r[sel] = KroghInterpolator(xu, self.r[s:s + k])(u)
                v[sel] = KroghInterpolator(xu, self.v[s:s + k])(u)
            else:                                           # Hermite: repeated nodes carry the derivatives
                xx = np.repeat(xu, 2)
                yy = np.empty((2 * k, 3))
                yy[0::2] = self.r[s:s + k]
                yy[1::2] = self.v[s:s + k] * h              # d r / d u = v dt/du
                poly = KroghInterpolator(xx, yy)
                r[sel] = poly(u)
                v[sel] = poly.derivative(u) / h
        return r, v


class EphemerisOrbit:
    """The orbit of one object from an OEM: interpolated, segment by segment, with the SGP4 orbit's interface."""

    def __init__(self, message, sha256=""):
        if message.kind != "OEM":
            raise ValueError("EphemerisOrbit needs an OEM message")
        names = {s.meta["OBJECT_NAME"].strip() for s in message.segments}
        ids = {s.meta["OBJECT_ID"].strip() for s in message.segments}
        if len(names) > 1 or len(ids) > 1:
            raise ccsds.CCSDSError(f"{message.path}: the OEM holds several objects ({', '.join(sorted(names))}); "
                                   "give a file with one object's ephemeris")
        self.message = message
        self.path = message.path
        self.sha256 = sha256
        self._name, self.object_id = names.pop(), ids.pop()
        first = message.segments[0].epochs[0]
        self._ref = first.tai()
        self._ref = (self._ref[0][0], self._ref[1][0])
        self.pieces = [_Piece(s, self._ref) for s in message.segments]

    @classmethod
    def from_file(cls, path):
        """Return the EphemerisOrbit of an OEM file (KVN or XML); raise a one-line error if it cannot be used."""
        msg = ccsds.read_message(path, "OEM")
        with open(os.fspath(path), "rb") as fh:
            digest = hashlib.sha256(fh.read()).hexdigest()
        return cls(msg, digest)

    # ---- what the run reads of an orbit --------------------------------
    @property
    def name(self):
        return self._name

    @property
    def norad_id(self):
        """Return the NORAD number when OBJECT_ID is one (digits), else None (OEMs use COSPAR ids)."""
        return int(self.object_id) if self.object_id.isdigit() else None

    @property
    def epoch(self):
        """Return the first usable epoch (UTC), one element."""
        return self.pieces[0].first_utc

    @property
    def span(self):
        """Return (first, last) usable UTC epochs of the ephemeris, one element each."""
        return self.pieces[0].first_utc, self.pieces[-1].last_utc

    @property
    def period_s(self):
        """Return the Keplerian period (s) of the first usable state in GCRS (vis-viva semi-major axis, GM of IERS
        2010; inertial, so an ITRF ephemeris's Earth-relative velocity is not mistaken for the orbital one)."""
        st = self.propagate(self.epoch)
        r, v = np.linalg.norm(st.r_gcrs_m[0]), np.linalg.norm(st.v_gcrs_m_s[0])
        a = 1.0 / (2.0 / r - v * v / MU_EARTH_M3_S2)
        return float(2 * np.pi * np.sqrt(a ** 3 / MU_EARTH_M3_S2))

    def describe_span(self):
        """Return the span and its gaps as text, for messages."""
        a, b = self.span
        text = f"{a.iso()[0]} .. {b.iso()[0]}"
        gaps = [f"{p.last_utc.iso()[0]} .. {q.first_utc.iso()[0]}" for p, q in zip(self.pieces, self.pieces[1:])
                if q.lo - p.hi > 1e-6]
        return text + (f" with gaps {'; '.join(gaps)}" if gaps else "")

    def __repr__(self):
        return f"EphemerisOrbit(name={self.name!r}, {len(self.pieces)} segments, {self.describe_span()})"

    def covered(self, epochs):
        """Return (N,) bool: the epoch lies inside a segment's usable span."""
        t = _tai_seconds(Epochs.from_any(epochs), self._ref)
        out = np.zeros(t.shape, dtype=bool)
        for p in self.pieces:
            out |= p.covers(t)
        return out

    def require(self, epochs, what="the run"):
        """Raise InvalidInputError unless every epoch lies inside a segment (the message names the span)."""
        ok = self.covered(epochs)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            raise InvalidInputError(f"{what} needs the orbit at {Epochs.from_any(epochs).iso()[i]} "
                                    f"({int((~ok).sum())} epochs uncovered) but the ephemeris {self.path} covers "
                                    f"{self.describe_span()}; choose --start/--duration inside it (or leave "
                                    "both out to cover the whole ephemeris)")

    def sample_epochs(self, step_s, start=None, duration_s=None):
        """Return epochs every ``step_s`` from ``start`` (default: the first usable epoch) for ``duration_s``
        (default: to the last usable epoch, inclusive), leaving out those in gaps between segments."""
        first, last = self.span
        start = first if start is None else Epochs.from_any(start)
        if duration_s is None:
            span = float(last.seconds_since(start)[0])
            duration_s = (np.floor(span / step_s + 1e-9) + 0.5) * step_s      # the last step at or before the end
            if span < 0:
                raise InvalidInputError(f"--start {start.iso()[0]} is at or after the end of the ephemeris "
                                        f"{self.path} ({self.describe_span()})")
        epochs = Epochs.range(start, duration_s, step_s)
        inside = self.covered(epochs)
        span_ok = (epochs.seconds_since(first) >= -1e-6) & (epochs.seconds_since(last) <= 1e-6)
        if not span_ok.all():
            self.require(epochs)
        return epochs[np.flatnonzero(inside)]

    def propagate(self, times, *, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, max_age_days=None):
        """Return the :class:`~simcore.environment.orbit.OrbitState` at ``times``; refuses uncovered epochs.

        ``max_age_days`` is accepted for the SGP4 orbit's signature and unused (an ephemeris does not age).
        """
        epochs = Epochs.from_any(times)
        self.require(epochs)
        t = _tai_seconds(epochs, self._ref)
        n = len(epochs)
        r_teme, v_teme = np.empty((n, 3)), np.empty((n, 3))
        done = np.zeros(n, dtype=bool)
        eop = dict(dut1_s=dut1_s, xp_rad=xp_rad, yp_rad=yp_rad)
        for p in self.pieces:
            sel = p.covers(t) & ~done       # a boundary epoch shared by two segments: the earlier one
            if not sel.any():
                continue
            done |= sel
            r, v = p.interpolate(t[sel])
            ep = epochs[np.flatnonzero(sel)]
            if p.frame == "itrs":
                dut1, xp, yp = (np.broadcast_to(np.asarray(x, float), (n,))[sel] for x in (dut1_s, xp_rad, yp_rad))
                r_teme[sel], v_teme[sel] = frames.rv_teme_from_itrs(r, v, ep, dut1, xp, yp)
            else:
                R = frames.R_between(p.frame, "teme", ep)
                r_teme[sel] = np.einsum("nij,nj->ni", R, r)
                v_teme[sel] = np.einsum("nij,nj->ni", R, v)
        r_gcrs, v_gcrs, r_itrs, v_itrs = frames.teme_to_all(r_teme, v_teme, epochs, **eop)
        zeros = np.zeros(n)
        return OrbitState(epochs=epochs, r_teme_m=r_teme, v_teme_m_s=v_teme, r_gcrs_m=r_gcrs, v_gcrs_m_s=v_gcrs,
                          r_ecef_m=r_itrs, v_ecef_m_s=v_itrs, error_code=np.zeros(n, dtype=np.int64),
                          age_days=zeros, stale=np.zeros(n, dtype=bool))


def write_orbit_oem(path, orbit, epochs, *, frame="EME2000", degree=7, interpolation="LAGRANGE", **eop):
    """Write ``orbit`` (an SGP4 :class:`~simcore.environment.orbit.Orbit` or an EphemerisOrbit) at ``epochs``
    as an OEM in ``frame`` (EME2000, GCRF, TEME or ITRF; ``eop``: dut1_s, xp_rad, yp_rad)."""
    epochs = Epochs.from_any(epochs)
    state = orbit.propagate(epochs, **eop)
    if not np.all(state.error_code == 0):
        i = int(np.flatnonzero(state.error_code != 0)[0])
        raise InvalidInputError(f"the orbit has no state at {epochs.iso()[i]} (SGP4 error {state.error_code[i]}); "
                                "choose epochs where it propagates")
    target = ccsds.OEM_FRAMES[frame]
    if target == "itrs":
        r, v = state.r_ecef_m, state.v_ecef_m_s
    elif target == "teme":
        r, v = state.r_teme_m, state.v_teme_m_s
    else:
        R = frames.R_between("gcrs", target, epochs, **eop)
        r, v = np.einsum("nij,nj->ni", R, state.r_gcrs_m), np.einsum("nij,nj->ni", R, state.v_gcrs_m_s)
    norad = getattr(orbit, "norad_id", None)
    ccsds.write_oem(path, epochs, r, v, frame=frame, object_name=orbit.name,
                    object_id=str(norad) if norad is not None else getattr(orbit, "object_id", "UNKNOWN"),
                    interpolation=interpolation, degree=degree,
                    comment=[f"written by sunsim from {orbit!r}"])
