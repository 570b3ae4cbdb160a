"""A recorded attitude history: absolute UTC times, a declared inertial frame and direction.

:class:`AttitudeHistory` holds quaternions as recorded (telemetry, another simulator, a CCSDS AEM) with
their UTC epochs, the inertial frame they refer to and the direction they rotate, and answers two
questions: where may the recorded attitude be trusted, and what is the attitude (``q_gcrs_from_body``,
the one convention of :mod:`simcore.environment.attitude`) at given epochs. Nothing is invented: an epoch
outside the recorded span or inside an untrusted interval is refused (:meth:`AttitudeHistory.attitude_at`)
or left out (:meth:`AttitudeHistory.trusted`, :meth:`AttitudeHistory.sample_epochs`), and counted.

Conventions
-----------
* ``frame``: one of :data:`FRAMES`, the inertial frame the quaternion refers to. GCRF (= GCRS axes here:
  the satellite's aberration-free inertial axes), EME2000 (= J2000, the mean equator and equinox of
  J2000.0: GCRS through the IAU 2006 frame bias, 23 mas), TEME (SGP4's frame) and TOD (true equator and
  equinox of date); converted to GCRS through :mod:`simcore.environment.frames` at each epoch. Between
  EME2000 and a frame of date the Sun's direction differs by ~0.29 deg in 2020 (precession).
* ``direction``: ``"body_to_frame"``: the quaternion rotates body vectors into the frame,
  ``v_frame = R(q) v_body`` (sunsim's own convention); ``"frame_to_body"``: ``v_body = R(q) v_frame``
  (e.g. OPS-SAT's ``O_Q_FB_FI_EST``, "frame body from frame inertial"). ``R(q)`` is the usual Hamilton
  matrix of a unit quaternion (:func:`simcore.environment.attitude.quat_to_matrix`).
* ``scalar_first``: ``(w, x, y, z)`` rows if True, ``(x, y, z, w)`` if False.
* Norms: recorded quaternions outside ``1 +- norm_tol`` are refused (the first such row named),
  inside normalised. Telemetry averaged over an interval is not exactly unit: its reader states its own
  tolerance.

Flags (per interval between consecutive samples; limits in :class:`HistoryLimits`, stated defaults)
----------------------------------------------------------------------------------------------------
* ``gap``: the samples are more than ``max(max_gap_s, 3 x the median step)`` apart (:data:`GAP_MEDIAN_FACTOR`):
  slerp across it would invent the attitude.
* ``jump``: the apparent rate (rotation angle between the samples / their time step) exceeds
  ``max_rate_deg_s``: one of the two is wrong, or the step is too coarse to interpolate.
* ``frozen``: the quaternion is the same bit for bit over at least ``min_frozen_s`` while the rest of the
  history moves (a stuck estimator or a held telemetry value). A history that holds one quaternion
  throughout is taken as an intended hold and not flagged; ``min_frozen_s=None`` switches the flag off.

A sample is trusted when at least one of its intervals is (a lone bad sample between two jumps is not);
an epoch strictly between two samples when its interval is. A one-sample history is trusted at that
sample only.
"""
import csv
import io
import os
from dataclasses import dataclass

import numpy as np

from simcore.environment import frames as _frames
from simcore.environment.attitude import Attitude, _slerp, matrix_to_quat, norm_outliers, quat_multiply
from simcore.environment.epochs import Epochs
from simcore.errors import InputNotFoundError, InvalidInputError

FRAMES = ("GCRF", "EME2000", "TEME", "TOD")
_FRAME_ALIASES = {"GCRF": "GCRF", "GCRS": "GCRF", "ICRF": "GCRF", "EME2000": "EME2000", "J2000": "EME2000",
                  "TEME": "TEME", "TOD": "TOD"}
_FRAME_KEY = {"GCRF": "gcrs", "EME2000": "eme2000", "TEME": "teme", "TOD": "tod"}
DIRECTIONS = ("body_to_frame", "frame_to_body")
# Times within this of the recorded span's ends count as inside it: the epochs' two-part Julian dates carry
# ~1e-11 s, and a run that spans exactly the history must not be refused for rounding.
SPAN_TOLERANCE_S = 1e-6
# sunsim's absolute-time attitude CSV (AttitudeHistory.from_csv / to_csv)
CSV_TIME_COLUMN = "time_utc"
# a gap is an interval longer than max(HistoryLimits.max_gap_s, this x the median step): a history sampled
# coarsely throughout (another simulator's 60-s output, two samples of a fixed attitude) is not all gaps
GAP_MEDIAN_FACTOR = 3.0
CSV_HEADERS = {(CSV_TIME_COLUMN, "qw", "qx", "qy", "qz"): True, (CSV_TIME_COLUMN, "qx", "qy", "qz", "qw"): False}


@dataclass(frozen=True)
class HistoryLimits:
    """The limits of :class:`AttitudeHistory`'s flags.

    ``max_gap_s`` = 30 s: three of OPS-SAT's 10 s steps; at the 2-5 deg/s a tumbling CubeSat turns, slerp
    across 30 s can miss a change of axis by tens of degrees (a history sampled more coarsely throughout gets
    3 x its median step instead: :data:`GAP_MEDIAN_FACTOR`). ``max_rate_deg_s`` = 10 deg/s: above any rate
    a coarse sun-sensor CubeSat keeps (OPS-SAT turns < 1 deg/s in 90 % of its steps; ~1 % of them read above
    10 deg/s: estimator jumps). ``min_frozen_s`` = 30 s: an estimate averaged over 10 s of a moving
    spacecraft does not repeat bit for bit for 3 steps. ``None`` switches a flag off.
    """

    max_gap_s: float = 30.0
    max_rate_deg_s: float = 10.0
    min_frozen_s: float = 30.0

    def __post_init__(self):
        for name in ("max_gap_s", "max_rate_deg_s", "min_frozen_s"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise InvalidInputError(f"attitude-history limit {name} must be a positive number (or None: off), "
                                        f"got {v!r}")


def frame_name(frame):
    """Return the canonical name (one of :data:`FRAMES`) of a declared frame, or raise InvalidInputError."""
    key = str(frame).strip().upper()
    if key not in _FRAME_ALIASES:
        raise InvalidInputError(f"unknown attitude frame {frame!r}; declare one of {', '.join(FRAMES)} "
                                "(aliases GCRS, J2000)")
    return _FRAME_ALIASES[key]


def direction_name(direction):
    """Return ``direction`` if it is one of :data:`DIRECTIONS`, else raise InvalidInputError."""
    d = str(direction).strip().lower()
    if d not in DIRECTIONS:
        raise InvalidInputError(f"unknown attitude direction {direction!r}; declare 'body_to_frame' "
                                "(v_frame = R(q) v_body) or 'frame_to_body' (v_body = R(q) v_frame)")
    return d


def _rotation_angle_deg(q0, q1):
    """Return (N,) the rotation angle in degrees between unit quaternions q0 and q1 (either sign).

    Twice the angle between the 4-vectors on the shorter arc, from chord lengths (accurate near 0)."""
    s = np.where(np.einsum("ij,ij->i", q0, q1) < 0, -1.0, 1.0)[:, None]
    return np.degrees(4.0 * np.arctan2(np.linalg.norm(q0 - s * q1, axis=1), np.linalg.norm(q0 + s * q1, axis=1)))


class AttitudeHistory:
    """A recorded attitude: absolute UTC times, a declared inertial frame and direction (module docstring)."""

    def __init__(self, epochs, q, *, frame="GCRF", direction="body_to_frame", scalar_first=True,
                 norm_tol=1e-3, limits=None, source="", dropped=None):
        self.source = str(source)
        where = f"{self.source}: " if self.source else ""
        try:
            epochs = Epochs.from_any(epochs)
        except (TypeError, ValueError) as exc:
            raise InvalidInputError(f"{where}attitude epochs unusable: {exc}") from None
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != 4 or q.shape[0] != len(epochs) or q.shape[0] == 0:
            raise InvalidInputError(f"{where}need one quaternion (4 values) per epoch: {len(epochs)} epochs, "
                                    f"quaternions of shape {q.shape}")
        self.frame = frame_name(frame)
        self.direction = direction_name(direction)
        self.limits = HistoryLimits() if limits is None else limits
        t = epochs.seconds_since(epochs[0])
        step = np.diff(t)
        if np.any(step <= 0):
            i = int(np.flatnonzero(step <= 0)[0])
            raise InvalidInputError(f"{where}attitude times must increase strictly: sample {i + 1} "
                                    f"({epochs[i + 1].iso()[0]}) does not follow sample {i} ({epochs[i].iso()[0]}); "
                                    "sort the history and drop duplicate times")
        if not np.all(np.isfinite(q)):
            i = int(np.flatnonzero(~np.all(np.isfinite(q), axis=1))[0])
            raise InvalidInputError(f"{where}attitude quaternion of sample {i} ({epochs[i].iso()[0]}) is not finite")
        norm, off = norm_outliers(q, norm_tol)
        if off.size:
            i = int(off[0])
            raise InvalidInputError(f"{where}attitude quaternion of sample {i} ({epochs[i].iso()[0]}) has norm "
                                    f"{norm[i]:.6g}, not 1 within {norm_tol:g} ({off.size} such samples): "
                                    "check the column order and scalar position, or leave such rows out")
        q = q / norm[:, None]
        if not scalar_first:
            q = q[:, [3, 0, 1, 2]]
        if self.direction == "frame_to_body":
            q = q * np.array([1.0, -1.0, -1.0, -1.0])          # the inverse rotation: v_frame = R(q*) v_body
        self.epochs = epochs
        self.t_s = t                                            # seconds since the first sample
        self.q_frame_from_body = q
        self.norm_recorded = norm
        self.dropped = dict(dropped or {})                      # rows a reader left out, by reason
        self._flags = self._compute_flags(step)

    # ---- flags -----------------------------------------------------------
    def _compute_flags(self, step):
        lim, q = self.limits, self.q_frame_from_body
        n = len(self.epochs)
        self.gap_limit_s = None if lim.max_gap_s is None else max(lim.max_gap_s, GAP_MEDIAN_FACTOR * np.median(step)) \
            if n > 1 else lim.max_gap_s
        gap = np.zeros(n - 1, bool) if lim.max_gap_s is None else step > self.gap_limit_s
        if n > 1:
            angle = _rotation_angle_deg(q[:-1], q[1:])
            rate = angle / step
        else:
            rate = np.zeros(0)
        jump = np.zeros(n - 1, bool) if lim.max_rate_deg_s is None else rate > lim.max_rate_deg_s
        frozen = np.zeros(n - 1, bool)
        # a history that holds one attitude throughout is an intended hold, not a stuck estimate
        if lim.min_frozen_s is not None and n > 1 and not np.all(q == q[0]):
            same = np.all(q[1:] == q[:-1], axis=1)
            i = 0
            while i < n - 1:
                if not same[i]:
                    i += 1
                    continue
                j = i
                while j < n - 1 and same[j]:
                    j += 1
                if self.t_s[j] - self.t_s[i] >= lim.min_frozen_s:
                    frozen[i:j] = True
                i = j
        ok = ~(gap | jump | frozen)
        if n == 1:
            sample_ok = np.ones(1, bool)
        else:
            sample_ok = np.zeros(n, bool)
            sample_ok[:-1] |= ok
            sample_ok[1:] |= ok
        return {"gap": gap, "jump": jump, "frozen": frozen, "trusted_interval": ok, "trusted_sample": sample_ok,
                "rate_deg_s": rate}

    def flags(self):
        """Return the per-interval flags ``gap``, ``jump``, ``frozen``, ``trusted_interval`` ((N-1,) bool),
        ``rate_deg_s`` (N-1,), ``trusted_sample`` (N,) and ``counts`` (a dict of ints, with the rows a reader
        left out under ``dropped_<reason>``)."""
        f = {k: v.copy() for k, v in self._flags.items()}
        f["counts"] = {"samples": len(self.epochs), "intervals": max(len(self.epochs) - 1, 0),
                       "gap": int(f["gap"].sum()), "jump": int(f["jump"].sum()), "frozen": int(f["frozen"].sum()),
                       "untrusted_samples": int((~f["trusted_sample"]).sum()),
                       **{f"dropped_{k}": int(v) for k, v in self.dropped.items()}}
        return f

    def summary(self):
        """Return one line that says what the history holds and what its flags left out."""
        c = self.flags()["counts"]
        lim = self.limits
        dropped = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in self.dropped.items() if v)
        return (f"attitude history {self.source or ''} {self.epochs.iso()[0]} .. {self.epochs.iso()[-1]}: "
                f"{c['samples']} samples ({self.frame}, {self.direction}); intervals flagged: {c['gap']} gaps "
                f"(> {self.gap_limit_s:g} s), {c['jump']} jumps (> {lim.max_rate_deg_s} deg/s), {c['frozen']} frozen "
                f"(same quaternion >= {lim.min_frozen_s} s); {c['untrusted_samples']} samples untrusted"
                + (f"; rows left out by the reader: {dropped}" if dropped else "")).replace("  ", " ")

    # ---- queries ---------------------------------------------------------
    def _locate(self, epochs):
        """Return (t (M,) s since the first sample, clipped into the span; inside (M,) bool)."""
        epochs = Epochs.from_any(epochs)
        t = epochs.seconds_since(self.epochs[0])
        inside = (t >= -SPAN_TOLERANCE_S) & (t <= self.t_s[-1] + SPAN_TOLERANCE_S)
        return np.clip(t, 0.0, self.t_s[-1]), inside

    def _interval(self, t):
        """Return (i, exact): the interval index of each t and whether t is (within tolerance) a sample."""
        n = len(self.epochs)
        if n == 1:
            return np.zeros(t.shape, np.int64), np.ones(t.shape, bool)
        j = np.clip(np.searchsorted(self.t_s, t), 0, n - 1)             # first sample >= t
        near = np.abs(self.t_s[j] - t) <= SPAN_TOLERANCE_S
        prev = np.clip(j - 1, 0, n - 1)
        near_prev = np.abs(self.t_s[prev] - t) <= SPAN_TOLERANCE_S
        exact = near | near_prev
        i = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, n - 2)
        return i, exact

    def trusted(self, epochs):
        """Return (M,) bool: the epochs inside the recorded span with a trusted attitude (module docstring)."""
        t, inside = self._locate(epochs)
        i, exact = self._interval(t)
        f = self._flags
        if len(self.epochs) == 1:
            return inside & (np.abs(t) <= SPAN_TOLERANCE_S) & exact
        sample = np.where(np.abs(self.t_s[np.clip(i + 1, 0, len(self.t_s) - 1)] - t) <= SPAN_TOLERANCE_S, i + 1, i)
        on_trusted_sample = exact & f["trusted_sample"][sample]
        return inside & (f["trusted_interval"][i] | on_trusted_sample)

    def q_frame_at(self, epochs):
        """Return (M, 4) ``q_frame_from_body`` at ``epochs`` by slerp (no trust check: :meth:`attitude_at`)."""
        t, _ = self._locate(epochs)
        if len(self.epochs) == 1:
            return np.repeat(self.q_frame_from_body, t.size, axis=0)
        i, _ = self._interval(t)
        f = (t - self.t_s[i]) / (self.t_s[i + 1] - self.t_s[i])
        return _slerp(self.q_frame_from_body[i], self.q_frame_from_body[i + 1], np.clip(f, 0.0, 1.0))

    def attitude_at(self, epochs):
        """Return the :class:`Attitude` (``q_gcrs_from_body``, ``t_s`` from the first of ``epochs``) at ``epochs``.

        Slerp in the declared frame between the neighbouring samples, then the frame's rotation to GCRS at
        each epoch. Raises InvalidInputError if any epoch lies outside the span or in an untrusted interval
        (:meth:`trusted` tells which: leave those out, never invent them).
        """
        epochs = Epochs.from_any(epochs)
        ok = self.trusted(epochs)
        if not ok.all():
            t, inside = self._locate(epochs)
            bad = np.flatnonzero(~ok)
            k = int(bad[0])
            why = ("outside the recorded span " + f"{self.epochs.iso()[0]} .. {self.epochs.iso()[-1]}"
                   if not inside[k] else "in an interval flagged as a gap, a jump or frozen")
            raise InvalidInputError(f"{len(bad)} of {len(epochs)} epochs have no trusted attitude in "
                                    f"{self.source or 'the attitude history'}, the first {epochs[k].iso()[0]} "
                                    f"({why}); leave them out (AttitudeHistory.trusted) or give a history "
                                    "that covers them")
        q_frame = self.q_frame_at(epochs)
        # the frame's rotation as a quaternion (near identity: w > 0), multiplied on: the slerp's sign stays
        q_gcrs_from_frame = matrix_to_quat(_frames.R_gcrs_from(_FRAME_KEY[self.frame], epochs), tol=1e-9)
        q = quat_multiply(q_gcrs_from_frame, q_frame)
        t = epochs.seconds_since(epochs[0])
        strictly = len(epochs) == 1 or bool(np.all(np.diff(t) > 0))
        return Attitude(q, t_s=t if strictly else None)

    def sample_epochs(self):
        """Return the recorded epochs whose attitude is trusted (:meth:`trusted`)."""
        keep = self._flags["trusted_sample"]
        return self.epochs[np.flatnonzero(keep)]

    def span_s(self):
        """Return the recorded span, seconds from the first to the last sample."""
        return float(self.t_s[-1])

    def __len__(self):
        return len(self.epochs)

    def __repr__(self):
        return (f"AttitudeHistory({len(self)} samples, {self.epochs.iso()[0]} .. {self.epochs.iso()[-1]}, "
                f"{self.frame}, {self.direction})")

    # ---- sunsim's CSV ------------------------------------------------------
    @classmethod
    def from_csv(cls, path, *, frame=None, direction=None, norm_tol=1e-3, limits=None):
        """Return the history in sunsim's absolute-time CSV.

        Format: ``# frame: GCRF|EME2000|TEME|TOD`` and ``# direction: body_to_frame|frame_to_body`` comment
        lines (optional: defaults GCRF and body_to_frame, sunsim's own convention; ``frame``/``direction``
        given here must agree with a declaration in the file), then the header ``time_utc,qw,qx,qy,qz``
        (or ``time_utc,qx,qy,qz,qw``: scalar last) and one row per sample, the time ISO-8601 UTC.
        """
        text = read_text(path, "attitude CSV")
        declared, rows, header, lines = {}, [], None, []
        for lineno, line in enumerate(csv.reader(io.StringIO(text, newline="")), start=1):
            if not line or not "".join(line).strip():
                continue
            if line[0].lstrip().startswith("#"):
                body = ",".join(line).lstrip()[1:].strip()
                if ":" in body:
                    k, v = (s.strip() for s in body.split(":", 1))
                    if k.lower() in ("frame", "direction"):
                        declared[k.lower()] = v
                continue
            cells = [c.strip() for c in line]
            if header is None:
                header = tuple(c.lower() for c in cells)
                if header not in CSV_HEADERS:
                    raise InvalidInputError(f"{path}:{lineno}: header must be time_utc,qw,qx,qy,qz (or "
                                            f"time_utc,qx,qy,qz,qw), got {','.join(cells)}")
                continue
            if len(cells) != 5:
                raise InvalidInputError(f"{path}:{lineno}: expected 5 values ({','.join(header)}), got {len(cells)}")
            try:
                rows.append([float(c) for c in cells[1:]])
            except ValueError:
                raise InvalidInputError(f"{path}:{lineno}: cannot read {','.join(cells[1:])} as numbers") from None
            lines.append((lineno, cells[0]))
        if header is None or not rows:
            raise InvalidInputError(f"{path}: no attitude rows found; expected a header time_utc,qw,qx,qy,qz and "
                                    "one row per sample")
        times = []
        for lineno, cell in lines:
            try:
                times.append(Epochs.from_any(cell).datetime64[0])
            except (InvalidInputError, TypeError, ValueError):
                raise InvalidInputError(f"{path}:{lineno}: cannot read {cell!r} as an ISO-8601 UTC time") from None
        for key, given in (("frame", frame), ("direction", direction)):
            if given is not None and key in declared:
                norm = frame_name if key == "frame" else direction_name
                if norm(given) != norm(declared[key]):
                    raise InvalidInputError(f"{path} declares {key} {declared[key]} but {given} was given; "
                                            "drop the option or fix the file")
        return cls(Epochs.from_datetime64(np.array(times)), np.array(rows),
                   frame=declared.get("frame", frame or "GCRF"),
                   direction=declared.get("direction", direction or "body_to_frame"),
                   scalar_first=CSV_HEADERS[header], norm_tol=norm_tol, limits=limits, source=os.fspath(path))

    def to_csv(self, path):
        """Write the history (all samples, as ``q_frame_from_body``, scalar first) in sunsim's CSV."""
        with open(path, "w") as fh:
            fh.write(f"# frame: {self.frame}\n# direction: body_to_frame\n{CSV_TIME_COLUMN},qw,qx,qy,qz\n")
            for iso, q in zip(self.epochs.datetime64.astype("datetime64[ns]"), self.q_frame_from_body):
                fh.write(f"{str(iso)}Z," + ",".join(f"{x:.17g}" for x in q) + "\n")


def read_text(path, what):
    """Return the UTF-8 text of ``path``; raise one clear line if it is missing, unreadable or binary."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except FileNotFoundError:
        raise InputNotFoundError(f"{what} {path} not found; give an existing file") from None
    except IsADirectoryError:
        raise InvalidInputError(f"{what} {path} is a folder; give a file") from None
    except OSError as exc:
        raise InvalidInputError(f"cannot read {what} {path}: {exc.strerror}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = None
    if text is None or "\x00" in text:
        article = "an" if what[:1].lower() in "aeiou" else "a"
        raise InvalidInputError(f"{path} is not {article} {what} (it holds binary data); give the text file")
    if not text.strip():
        raise InvalidInputError(f"{path} is empty; give a {what}")
    return text
