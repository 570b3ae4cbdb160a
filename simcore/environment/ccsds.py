"""CCSDS Navigation Data Messages: Orbit and Attitude Ephemeris Messages (OEM, AEM), read and written.

Standards: CCSDS 502.0-B-2/-B-3 (Orbit Data Messages: OEM versions 1.0, 2.0, 3.0) and CCSDS
504.0-B-1/-B-2 (Attitude Data Messages: AEM versions 1.0, 2.0); both in the KVN text form
(``KEY = value`` lines, ``META_START``/``META_STOP`` blocks, one data line per epoch) and in the
NDM/XML form (``<oem>``/``<aem>`` with ``<segment><metadata>...<data>``). Why sunsim carries its own
reader rather than a library: docs/ccsds.md.

What is accepted, and what is refused with one line naming the file, the line and what to change:

* the header's version keyword (``CCSDS_OEM_VERS`` / ``CCSDS_AEM_VERS``: 1.0, 2.0 or 3.0/2.0),
  ``CREATION_DATE`` and ``ORIGINATOR``; each segment's ``OBJECT_NAME``, ``OBJECT_ID``, ``CENTER_NAME``
  (OEM: EARTH only), the frame(s), ``TIME_SYSTEM``, ``START_TIME``, ``STOP_TIME``;
* frames :data:`OEM_FRAMES` (EME2000/J2000, GCRF, TEME, ITRF and its realisations: every ITRF is
  treated as ITRS, differences of a few cm); time systems :data:`TIME_SYSTEMS`;
* epochs strictly increasing within a segment, inside ``START_TIME .. STOP_TIME``, segments in order
  (one may start where the previous stops: a manoeuvre boundary);
* AEM: ``ATTITUDE_TYPE`` QUATERNION (and QUATERNION/DERIVATIVE, QUATERNION/RATE, QUATERNION/ANGVEL,
  whose rates are read past: sunsim interpolates the quaternions), with ``QUATERNION_TYPE`` FIRST or
  LAST and ``ATTITUDE_DIR`` A2B or B2A as declared; Euler angles and spin representations are refused.
  Quaternion norms must be 1 within :data:`QUATERNION_NORM_TOL`.

The AEM direction convention. CCSDS 504.0-B-1 (annex on rotations) defines the quaternion of
``A2B`` as the one whose direction-cosine matrix transforms the coordinates of a vector from frame A
to frame B, ``v_B = M(q) v_A`` with ``M(q) = (qc^2 - |e|^2) I + 2 e e^T - 2 qc [e x]`` (e = (Q1, Q2,
Q3), qc the scalar): the "passive" matrix, which is the transpose of the Hamilton rotation matrix
R(q) sunsim uses (:func:`simcore.environment.attitude.quat_to_matrix`). So an A2B quaternion, read
in sunsim's convention, rotates B vectors into A: with A the inertial frame and B the body,
``v_inertial = R(q) v_body`` (sunsim's ``q_frame_from_body`` as it stands); B2A is its conjugate.
Orekit reads AEMs the same way (its ``Rotation`` is the passive one).

Times: every epoch is turned into UTC (:class:`simcore.environment.epochs.Epochs`) through erfa's
time scales (TAI: the leap-second table; TT = TAI + 32.184 s; GPS = TAI - 19 s).
"""
import datetime as _dt
import os
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import erfa
import numpy as np

from simcore.environment.attitude import norm_outliers
from simcore.environment.epochs import Epochs
from simcore.environment.history import AttitudeHistory, read_text
from simcore.errors import InvalidInputError

VERSIONS = {"OEM": ("1.0", "2.0", "3.0"), "AEM": ("1.0", "2.0")}
TIME_SYSTEMS = ("UTC", "TAI", "TT", "GPS")
# CCSDS/SANA frame names -> sunsim's frames (simcore.environment.frames)
OEM_FRAMES = {"EME2000": "eme2000", "J2000": "eme2000", "GCRF": "gcrs", "TEME": "teme", "ITRF": "itrs",
              "ITRF-93": "itrs", "ITRF-97": "itrs", "ITRF2000": "itrs", "ITRF2005": "itrs", "ITRF2008": "itrs",
              "ITRF2014": "itrs", "ITRF2020": "itrs", "ITRF1993": "itrs", "ITRF1997": "itrs"}
# the AttitudeHistory's frame names (simcore.environment.history)
AEM_FRAMES = {"EME2000": "EME2000", "J2000": "EME2000", "GCRF": "GCRF", "ICRF": "GCRF", "TEME": "TEME", "TOD": "TOD"}
INTERPOLATIONS = ("LAGRANGE", "HERMITE", "LINEAR")
QUATERNION_TYPES = ("QUATERNION", "QUATERNION/DERIVATIVE", "QUATERNION/RATE", "QUATERNION/ANGVEL")
QUATERNION_NORM_TOL = 1e-3
DEFAULT_DEGREE = 7            # when a segment declares no INTERPOLATION_DEGREE

_HEADER_REQUIRED = ("CREATION_DATE", "ORIGINATOR")
_META_REQUIRED = {"OEM": ("OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "REF_FRAME", "TIME_SYSTEM", "START_TIME",
                          "STOP_TIME"),
                  "AEM": ("OBJECT_NAME", "OBJECT_ID", "REF_FRAME_A", "REF_FRAME_B", "TIME_SYSTEM", "START_TIME",
                          "STOP_TIME", "ATTITUDE_TYPE")}
_KEY_RE = re.compile(r"^([A-Z][A-Z0-9_]*)\s*=\s*(.*?)\s*$")
_UNITS_RE = re.compile(r"\s*\[[^\]]*\]\s*$")
_EPOCH_RE = re.compile(r"^(\d{4})-(?:(\d{2})-(\d{2})|(\d{3}))T(\d{2}):(\d{2}):(\d{2}(?:\.\d*)?)Z?$")
_OEM_XML_FIELDS = ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT", "X_DDOT", "Y_DDOT", "Z_DDOT")


class CCSDSError(InvalidInputError):
    """A CCSDS message sunsim cannot use (format, missing keyword, unknown frame or time system, bad data)."""


@dataclass
class Segment:
    """One segment of a message: its metadata (keyword -> text), epochs (UTC) and data rows."""

    meta: dict
    epochs: Epochs
    values: np.ndarray              # (N, k): OEM km, km/s (km/s^2); AEM as written (quaternion order as declared)
    lines: list                     # (N,) the file line of each row (0 in XML)
    start: Epochs = None            # START_TIME / STOP_TIME, USEABLE_* (UTC)
    stop: Epochs = None
    useable_start: Epochs = None
    useable_stop: Epochs = None


@dataclass
class Message:
    """A parsed OEM or AEM: kind, version, header keywords and segments."""

    kind: str
    version: str
    header: dict
    segments: list = field(default_factory=list)
    path: str = ""


# ---------------------------------------------------------------------------
# times
def parse_epochs(texts, time_system, where=""):
    """Return the UTC :class:`Epochs` of CCSDS epoch strings (``YYYY-MM-DDThh:mm:ss[.f]`` or
    ``YYYY-DDDThh:mm:ss[.f]``) in ``time_system`` (:data:`TIME_SYSTEMS`)."""
    ts = str(time_system).strip().upper()
    if ts not in TIME_SYSTEMS:
        raise CCSDSError(f"{where}unknown TIME_SYSTEM {time_system!r}; sunsim reads {', '.join(TIME_SYSTEMS)}")
    fields = np.empty((len(texts), 6))
    for i, text in enumerate(texts):
        m = _EPOCH_RE.match(str(text).strip())
        if m is None:
            raise CCSDSError(f"{where}cannot read the epoch {text!r}; CCSDS epochs read YYYY-MM-DDThh:mm:ss.fff "
                             "or YYYY-DDDThh:mm:ss.fff")
        y, mo, d, doy, h, mi, s = m.groups()
        if doy is not None:
            day = _dt.date(int(y), 1, 1) + _dt.timedelta(days=int(doy) - 1)
            mo, d = day.month, day.day
        fields[i] = (int(y), int(mo), int(d), int(h), int(mi), float(s))
    if ts != "UTC":
        # to UTC through erfa: TAI (GPS + 19 s, TT - 32.184 s, both exact) -> UTC with the leap-second table
        sec = fields[:, 5] + (19.0 if ts == "GPS" else 0.0) - (32.184 if ts == "TT" else 0.0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            try:
                j1, j2 = erfa.dtf2d("TAI", *(fields[:, k].astype(np.int32) for k in range(5)),
                                    np.zeros(len(texts)))
            except erfa.ErfaError as exc:
                raise CCSDSError(f"{where}an epoch is not a calendar date ({exc})") from None
            iy, im, iday, hmsf = erfa.d2dtf("UTC", 9, *erfa.taiutc(j1, j2 + sec / 86400.0))
        fields = np.column_stack([iy, im, iday, hmsf["h"], hmsf["m"], hmsf["s"] + hmsf["f"] * 1e-9])
    try:
        days = np.array([np.datetime64(f"{int(a):04d}-{int(b):02d}-{int(c):02d}", "ns") for a, b, c in fields[:, :3]])
    except ValueError as exc:
        raise CCSDSError(f"{where}an epoch is not a calendar date ({exc})") from None
    ns = (fields[:, 3].astype(np.int64) * 3600 + fields[:, 4].astype(np.int64) * 60) * 1_000_000_000 \
        + np.round(fields[:, 5] * 1e9).astype(np.int64)
    return Epochs.from_datetime64(days + ns.astype("timedelta64[ns]"))


def format_epochs(epochs):
    """Return CCSDS UTC epoch strings ``YYYY-MM-DDThh:mm:ss.fffffffff`` (ns) of ``epochs``."""
    return [str(t) for t in Epochs.from_any(epochs).datetime64.astype("datetime64[ns]")]


# ---------------------------------------------------------------------------
# reading: KVN and XML into a Message
def read_message(path, kind):
    """Return the :class:`Message` of a CCSDS ``kind`` ('OEM' or 'AEM') file, KVN or XML (found by content)."""
    path = os.fspath(path)
    text = read_text(path, f"CCSDS {kind} (KVN or XML)")
    if text.lstrip().startswith("<"):
        msg = _parse_xml(text, path, kind)
    else:
        msg = _parse_kvn(text, path, kind)
    for seg in msg.segments:
        _check_segment(seg, msg)
    for a, b in zip(msg.segments, msg.segments[1:]):
        if b.epochs.seconds_since(a.epochs[-1])[0] < 0:
            raise CCSDSError(f"{_where(path, b.lines[0])}segment starting {b.epochs.iso()[0]} overlaps the one before "
                             f"(it ends {a.epochs.iso()[-1]}); segments must follow in time order")
    return msg


def _where(path, line):
    """Return 'path:line: ' (or 'path: ' where the line is unknown, as in XML) for a message."""
    return f"{path}:{line}: " if line else f"{path}: "


def _check_header(header, version, path, kind):
    if version is None:
        raise CCSDSError(f"{path}: not a CCSDS {kind}: it declares no version (the first keyword must be "
                         f"CCSDS_{kind}_VERS; in XML the root's version attribute)")
    if version not in VERSIONS[kind]:
        raise CCSDSError(f"{path}: CCSDS_{kind}_VERS = {version} is not a version sunsim reads "
                         f"({', '.join(VERSIONS[kind])})")
    for key in _HEADER_REQUIRED:
        if key not in header:
            raise CCSDSError(f"{path}: the {kind} header lacks {key}, a required keyword (CCSDS_{kind}_VERS, "
                             "CREATION_DATE, ORIGINATOR)")


def _parse_kvn(text, path, kind):
    vers_key = f"CCSDS_{kind}_VERS"
    header, version, segments = {}, None, []
    meta, rows, lines, state = None, [], [], "header"
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("COMMENT"):
            continue
        if line == "META_START":
            if state == "header":
                _check_header(header, version, path, kind)
            elif meta is not None:
                segments.append((meta, rows, lines))
            meta, rows, lines, state = {"_line": lineno}, [], [], "meta"
            continue
        if line == "META_STOP":
            if state != "meta":
                raise CCSDSError(f"{path}:{lineno}: META_STOP without META_START")
            state = "data"
            continue
        if line in ("COVARIANCE_START", "DATA_START"):
            state = "covariance" if line == "COVARIANCE_START" else "data"
            continue
        if line in ("COVARIANCE_STOP", "DATA_STOP"):
            state = "data"
            continue
        if state == "covariance":
            continue
        m = _KEY_RE.match(line)
        if state in ("header", "meta"):
            if m is None:
                where = "header" if state == "header" else "metadata"
                raise CCSDSError(f"{path}:{lineno}: expected KEY = value in the {where}, got {line[:60]!r}")
            key, value = m.group(1), _UNITS_RE.sub("", m.group(2))
            if state == "header":
                if not header and version is None and key != vers_key:
                    raise CCSDSError(f"{path}:{lineno}: not a CCSDS {kind}: the first keyword must be {vers_key}, "
                                     f"got {key}")
                if key == vers_key:
                    version = value
                else:
                    header[key] = value
            else:
                meta[key] = value
            continue
        if m is not None:
            raise CCSDSError(f"{path}:{lineno}: keyword {m.group(1)} among the data lines; a new segment starts "
                             "with META_START")
        parts = line.split()
        try:
            rows.append((parts[0], [float(x) for x in parts[1:]]))
        except ValueError:
            raise CCSDSError(f"{path}:{lineno}: cannot read {line[:60]!r} as an epoch and numbers") from None
        lines.append(lineno)
    if state == "header":
        _check_header(header, version, path, kind)
        raise CCSDSError(f"{path}: the {kind} has no segment (META_START ... META_STOP and data lines)")
    if state == "meta":
        raise CCSDSError(f"{path}: the metadata block starting on line {meta['_line']} has no META_STOP")
    segments.append((meta, rows, lines))
    return _build(kind, version, header, segments, path)


def _strip_ns(tag):
    return tag.rsplit("}", 1)[-1]


def _children(el, name):
    return [c for c in el if _strip_ns(c.tag) == name]


def _parse_xml(text, path, kind):
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise CCSDSError(f"{path}: not well-formed XML ({exc})") from None
    if _strip_ns(root.tag).lower() != kind.lower():
        raise CCSDSError(f"{path}: the XML root is <{_strip_ns(root.tag)}>, not <{kind.lower()}>: not a CCSDS {kind}")
    version = root.get("version")
    hdr = _children(root, "header")
    header = {}
    if hdr:
        header = {_strip_ns(c.tag): (c.text or "").strip() for c in hdr[0] if _strip_ns(c.tag) != "COMMENT"}
    _check_header(header, version, path, kind)
    bodies = _children(root, "body")
    segments = []
    for seg in (bodies[0] if bodies else []):
        md = _children(seg, "metadata")
        meta = {"_line": 0}
        if md:
            meta.update({_strip_ns(c.tag): (c.text or "").strip() for c in md[0] if _strip_ns(c.tag) != "COMMENT"})
        rows = []
        for data in _children(seg, "data"):
            for rec in data:
                tag = _strip_ns(rec.tag)
                if tag == "stateVector":
                    rows.append(_xml_state(rec, path))
                elif tag == "attitudeState":
                    rows.append(_xml_attitude(rec, meta, path))
        segments.append((meta, rows, [0] * len(rows)))
    if not segments:
        raise CCSDSError(f"{path}: the {kind} has no <segment> in its <body>")
    return _build(kind, version, header, segments, path)


def _leaves(el):
    return {_strip_ns(c.tag): (c.text or "").strip() for c in el.iter() if len(c) == 0}


def _xml_state(rec, path):
    leaf = _leaves(rec)
    names = [n for n in _OEM_XML_FIELDS if n in leaf]
    if "EPOCH" not in leaf or names[:6] != list(_OEM_XML_FIELDS[:6]):
        raise CCSDSError(f"{path}: a <stateVector> lacks EPOCH or one of X Y Z X_DOT Y_DOT Z_DOT")
    try:
        return leaf["EPOCH"], [float(leaf[n]) for n in names]
    except ValueError:
        raise CCSDSError(f"{path}: a <stateVector> at {leaf['EPOCH']} holds a value that is not a number") from None


def _xml_attitude(rec, meta, path):
    leaf = _leaves(rec)
    if "EPOCH" not in leaf or not all(k in leaf for k in ("Q1", "Q2", "Q3", "QC")):
        raise CCSDSError(f"{path}: an <attitudeState> lacks EPOCH or a quaternion Q1 Q2 Q3 QC (sunsim reads "
                         "quaternion AEMs)")
    # XML names the scalar: write the row in the order QUATERNION_TYPE declares (FIRST when undeclared)
    order = ("QC", "Q1", "Q2", "Q3") if meta.get("QUATERNION_TYPE", "FIRST").upper() != "LAST" else \
        ("Q1", "Q2", "Q3", "QC")
    meta.setdefault("QUATERNION_TYPE", "FIRST")
    try:
        return leaf["EPOCH"], [float(leaf[k]) for k in order]
    except ValueError:
        raise CCSDSError(f"{path}: an <attitudeState> at {leaf['EPOCH']} holds a value that is not a number") from None


def _build(kind, version, header, raw_segments, path):
    msg = Message(kind=kind, version=version, header=header, path=path)
    for meta, rows, lines in raw_segments:
        line0 = meta.pop("_line", 0)
        where = _where(path, line0)
        for key in _META_REQUIRED[kind]:
            if key not in meta:
                raise CCSDSError(f"{where}the segment's metadata lacks {key}, a required keyword "
                                 f"({', '.join(_META_REQUIRED[kind])})")
        if not rows:
            raise CCSDSError(f"{where}the segment has no data lines")
        ts = meta["TIME_SYSTEM"]
        epochs = parse_epochs([r[0] for r in rows], ts, where)
        widths = {len(r[1]) for r in rows}
        if len(widths) != 1:
            i = next(i for i, r in enumerate(rows) if len(r[1]) != len(rows[0][1]))
            where_row = _where(path, lines[i]) if lines[i] else where
            raise CCSDSError(f"{where_row}data line with {len(rows[i][1])} numbers after the epoch where the "
                             f"segment's first has {len(rows[0][1])}")
        seg = Segment(meta=meta, epochs=epochs, values=np.array([r[1] for r in rows], dtype=float), lines=lines)
        seg.start, seg.stop = (parse_epochs([meta[k]], ts, where) for k in ("START_TIME", "STOP_TIME"))
        for k in ("USEABLE_START_TIME", "USEABLE_STOP_TIME"):
            if k in meta:
                setattr(seg, k.lower().replace("_time", ""), parse_epochs([meta[k]], ts, where))
        msg.segments.append(seg)
    return msg


def _check_segment(seg, msg):
    path = msg.path
    t = seg.epochs.seconds_since(seg.epochs[0])
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0]) + 1
        where = _where(path, seg.lines[i])
        raise CCSDSError(f"{where}epoch {seg.epochs.iso()[i]} does not come after {seg.epochs.iso()[i - 1]}; "
                         "epochs must increase strictly within a segment")
    lo = seg.epochs.seconds_since(seg.start)
    hi = seg.epochs.seconds_since(seg.stop)
    out = (lo < -1e-6) | (hi > 1e-6)
    if np.any(out):
        i = int(np.flatnonzero(out)[0])
        where = _where(path, seg.lines[i])
        raise CCSDSError(f"{where}epoch {seg.epochs.iso()[i]} lies outside the segment's START_TIME .. STOP_TIME "
                         f"({seg.meta['START_TIME']} .. {seg.meta['STOP_TIME']})")
    if msg.kind == "OEM":
        _check_oem_segment(seg, path)
    else:
        _check_aem_segment(seg, path)


def _check_oem_segment(seg, path):
    m = seg.meta
    where = _where(path, seg.lines[0])
    if m["CENTER_NAME"].strip().upper() != "EARTH":
        raise CCSDSError(f"{where}CENTER_NAME = {m['CENTER_NAME']}: sunsim flies Earth orbits only (EARTH)")
    frame = m["REF_FRAME"].strip().upper()
    if frame not in OEM_FRAMES:
        raise CCSDSError(f"{where}unknown REF_FRAME {m['REF_FRAME']!r}; sunsim reads {', '.join(OEM_FRAMES)}")
    if seg.values.shape[1] not in (6, 9):
        raise CCSDSError(f"{where}OEM data lines hold an epoch and 6 (X Y Z X_DOT Y_DOT Z_DOT) or 9 numbers "
                         f"(with accelerations); found {seg.values.shape[1]}")
    method = m.get("INTERPOLATION", "LAGRANGE").strip().upper()
    if method not in INTERPOLATIONS:
        raise CCSDSError(f"{where}INTERPOLATION = {m['INTERPOLATION']}: sunsim interpolates with "
                         f"{', '.join(INTERPOLATIONS)}")
    deg = m.get("INTERPOLATION_DEGREE", str(DEFAULT_DEGREE if method != "LINEAR" else 1))
    if not re.fullmatch(r"\d+", deg.strip()) or int(deg) < 1:
        raise CCSDSError(f"{where}INTERPOLATION_DEGREE = {deg!r} is not a whole number >= 1")
    if len(seg.epochs) < 2:
        raise CCSDSError(f"{where}a segment needs at least two states to interpolate between; found one")


def _check_aem_segment(seg, path):
    m = seg.meta
    where = _where(path, seg.lines[0])
    atype = m["ATTITUDE_TYPE"].strip().upper()
    if atype not in QUATERNION_TYPES:
        raise CCSDSError(f"{where}ATTITUDE_TYPE = {m['ATTITUDE_TYPE']}: sunsim reads quaternion AEMs "
                         f"({', '.join(QUATERNION_TYPES)}); convert Euler angles or spin states to quaternions")
    qt = m.get("QUATERNION_TYPE", "").strip().upper()
    if qt not in ("FIRST", "LAST"):
        raise CCSDSError(f"{where}QUATERNION_TYPE = {qt or '(missing)'}: declare FIRST or LAST (where the scalar "
                         "part stands); sunsim does not guess")
    if m.get("ATTITUDE_DIR", "").strip().upper() not in ("A2B", "B2A"):
        raise CCSDSError(f"{where}ATTITUDE_DIR = {m.get('ATTITUDE_DIR') or '(missing)'}: declare A2B or B2A; "
                         "sunsim does not guess the rotation's direction")
    aem_frames(m, where)
    if seg.values.shape[1] < 4:
        raise CCSDSError(f"{where}AEM quaternion lines hold an epoch and at least 4 numbers; found "
                         f"{seg.values.shape[1]}")
    norm, off = norm_outliers(seg.values[:, :4], QUATERNION_NORM_TOL)
    if off.size:
        i = int(off[0])
        raise CCSDSError(f"{_where(path, seg.lines[i])}the quaternion at {seg.epochs.iso()[i]} has norm {norm[i]:.6g}, "
                         f"not 1 within {QUATERNION_NORM_TOL:g} ({off.size} such rows); check QUATERNION_TYPE and the "
                         "columns")


def aem_frames(meta, where=""):
    """Return (inertial frame name of the AttitudeHistory, body_is_b) from an AEM segment's REF_FRAME_A/B."""
    a, b = meta["REF_FRAME_A"].strip().upper(), meta["REF_FRAME_B"].strip().upper()
    body_a, body_b = a.startswith("SC_BODY"), b.startswith("SC_BODY")
    if body_a == body_b:
        raise CCSDSError(f"{where}REF_FRAME_A = {a}, REF_FRAME_B = {b}: sunsim needs one spacecraft body frame "
                         f"(SC_BODY_n) and one inertial frame ({', '.join(AEM_FRAMES)})")
    inertial = b if body_a else a
    if inertial not in AEM_FRAMES:
        raise CCSDSError(f"{where}unknown reference frame {inertial!r}; sunsim reads attitudes relative to "
                         f"{', '.join(AEM_FRAMES)}")
    return AEM_FRAMES[inertial], body_b


def aem_quaternions(seg):
    """Return (q (N, 4) scalar first, sunsim's direction 'body_to_frame' or 'frame_to_body') of an AEM segment.

    See the module docstring: with A inertial and B the body, A2B gives ``v_frame = R(q) v_body``.
    """
    q = seg.values[:, :4]
    if seg.meta["QUATERNION_TYPE"].strip().upper() == "LAST":
        q = q[:, [3, 0, 1, 2]]
    _, body_is_b = aem_frames(seg.meta)
    a2b = seg.meta["ATTITUDE_DIR"].strip().upper() == "A2B"
    # passive A2B = Hamilton rotation of B vectors into A; body B: body -> frame
    return q.copy(), "body_to_frame" if a2b == body_is_b else "frame_to_body"


def read_aem(path, *, limits=None):
    """Return the :class:`~simcore.environment.history.AttitudeHistory` of a CCSDS AEM (KVN or XML).

    Every segment's quaternions are turned into sunsim's ``body_to_frame`` as declared (module docstring),
    samples outside a segment's USEABLE_START_TIME .. USEABLE_STOP_TIME are left out (counted), and where a
    segment starts at the epoch the previous one stops (a manoeuvre boundary) the later segment's sample is
    kept. All segments must refer to one inertial frame. The history interpolates by slerp whatever
    INTERPOLATION_METHOD the message declares (as for every recorded attitude in sunsim), and flags gaps,
    jumps and frozen stretches with ``limits`` (:class:`~simcore.environment.history.HistoryLimits`).
    """
    msg = read_message(path, "AEM")
    frames_seen = {aem_frames(s.meta)[0] for s in msg.segments}
    if len(frames_seen) > 1:
        raise CCSDSError(f"{msg.path}: the AEM's segments refer to different frames ({', '.join(sorted(frames_seen))});"
                         " give one frame for the whole history")
    times, quats, outside, boundary = [], [], 0, 0
    for seg in msg.segments:
        q, direction = aem_quaternions(seg)
        if direction == "frame_to_body":
            q = q * np.array([1.0, -1.0, -1.0, -1.0])
        keep = np.ones(len(seg.epochs), bool)
        if seg.useable_start is not None:
            keep &= seg.epochs.seconds_since(seg.useable_start) >= -1e-6
        if seg.useable_stop is not None:
            keep &= seg.epochs.seconds_since(seg.useable_stop) <= 1e-6
        outside += int((~keep).sum())
        ep = seg.epochs[np.flatnonzero(keep)]
        if times and len(ep) and ep.seconds_since(times[-1][-1])[0] <= 1e-9:
            times[-1], quats[-1] = times[-1][:-1], quats[-1][:-1]          # the boundary: the later segment's
            boundary += 1
        times.append(ep.datetime64)
        quats.append(q[keep])
    epochs = Epochs.from_datetime64(np.concatenate(times))
    if len(epochs) == 0:
        raise CCSDSError(f"{msg.path}: no sample lies inside the segments' USEABLE_START_TIME .. USEABLE_STOP_TIME")
    return AttitudeHistory(epochs, np.concatenate(quats), frame=frames_seen.pop(), direction="body_to_frame",
                           norm_tol=QUATERNION_NORM_TOL, limits=limits, source=msg.path,
                           dropped={"outside_useable_span": outside, "segment_boundary_duplicates": boundary})


def is_aem(text):
    """Return True if ``text`` looks like a CCSDS AEM (KVN version line or an ``<aem>`` XML root)."""
    head = text.lstrip()[:4000]
    if head.startswith("CCSDS_AEM_VERS"):
        return True
    return head.startswith("<") and re.search(r"<(\w+:)?aem[\s>]", head) is not None


# ---------------------------------------------------------------------------
# writing (KVN)
def _header(kind, version, originator, comment):
    created = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")
    out = [f"CCSDS_{kind}_VERS = {version}"]
    out += [f"COMMENT {c}" for c in comment]
    out += [f"CREATION_DATE = {created}", f"ORIGINATOR = {originator}", ""]
    return out


def write_oem(path, epochs, r_m, v_m_s, *, frame="EME2000", object_name="SATELLITE", object_id="UNKNOWN",
              interpolation="LAGRANGE", degree=7, originator="sunsim", comment=()):
    """Write one-segment OEM 2.0 (KVN) of states ``r_m``, ``v_m_s`` (N, 3), given in ``frame`` (a CCSDS name
    from :data:`OEM_FRAMES`), at UTC ``epochs``; km and km/s with 16 significant digits (sub-micrometre)."""
    epochs = Epochs.from_any(epochs)
    if frame not in OEM_FRAMES:
        raise ValueError(f"frame must be one of {', '.join(OEM_FRAMES)}; got {frame!r}")
    iso = format_epochs(epochs)
    lines = _header("OEM", "2.0", originator, comment)
    lines += ["META_START", f"OBJECT_NAME = {object_name}", f"OBJECT_ID = {object_id}", "CENTER_NAME = EARTH",
              f"REF_FRAME = {frame}", "TIME_SYSTEM = UTC", f"START_TIME = {iso[0]}", f"STOP_TIME = {iso[-1]}",
              f"INTERPOLATION = {interpolation}", f"INTERPOLATION_DEGREE = {int(degree)}", "META_STOP", ""]
    r_km, v_km_s = np.asarray(r_m, float) / 1e3, np.asarray(v_m_s, float) / 1e3
    for t, r, v in zip(iso, r_km, v_km_s):
        lines.append(t + " " + " ".join(f"{x:.16e}" for x in (*r, *v)))
    _write(path, lines)


def write_aem(path, epochs, q, *, frame="GCRF", direction="body_to_frame", object_name="SATELLITE",
              object_id="UNKNOWN", degree=1, originator="sunsim", comment=()):
    """Write one-segment AEM 2.0 (KVN) quaternions ``q`` (N, 4) scalar first, in sunsim's ``direction``
    ('body_to_frame': v_frame = R(q) v_body), REF_FRAME_A = ``frame``, REF_FRAME_B = SC_BODY_1, A2B,
    QUATERNION_TYPE = FIRST (module docstring: A2B is then q as it stands)."""
    epochs = Epochs.from_any(epochs)
    q = np.asarray(q, dtype=float)
    if direction == "frame_to_body":
        q = q * np.array([1.0, -1.0, -1.0, -1.0])
    elif direction != "body_to_frame":
        raise ValueError(f"direction must be 'body_to_frame' or 'frame_to_body'; got {direction!r}")
    iso = format_epochs(epochs)
    lines = _header("AEM", "2.0", originator, comment)
    lines += ["META_START", f"OBJECT_NAME = {object_name}", f"OBJECT_ID = {object_id}", "CENTER_NAME = EARTH",
              f"REF_FRAME_A = {frame}", "REF_FRAME_B = SC_BODY_1", "ATTITUDE_DIR = A2B", "TIME_SYSTEM = UTC",
              f"START_TIME = {iso[0]}", f"STOP_TIME = {iso[-1]}", "ATTITUDE_TYPE = QUATERNION",
              "QUATERNION_TYPE = FIRST", "INTERPOLATION_METHOD = LINEAR", f"INTERPOLATION_DEGREE = {int(degree)}",
              "META_STOP", "", "DATA_START"]
    for t, row in zip(iso, q):
        lines.append(t + " " + " ".join(f"{x:.16e}" for x in row))
    lines.append("DATA_STOP")
    _write(path, lines)


def _write(path, lines):
    with open(os.fspath(path), "w", encoding="ascii") as fh:
        fh.write("\n".join(lines) + "\n")
