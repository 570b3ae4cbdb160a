"""Attitude of the satellite: quaternion helpers, the thesis' tumble, user histories.

Conventions (docs/conventions.md): quaternions are scalar-first
``(w, x, y, z)`` with the Hamilton product; ``q_gcrs_from_body`` rotates
body-frame vectors into GCRS, ``v_gcrs = R_gcrs_from_body @ v_body``. Time
leads: N epochs give ``(N, 4)`` quaternions and ``(N, 3, 3)`` matrices.

The thesis' simulations (sec. 4.3) tumble the satellite at a constant
1.9 deg/s but do not give the axis; :data:`DEFAULT_TUMBLE_AXIS` is the body
diagonal (1, 1, 1)/sqrt(3), which, unlike a face normal, sweeps every face
(and so every diode) past the Sun and the Earth. It is a parameter.

A measured or externally simulated attitude enters via
:meth:`Attitude.from_quaternions` or :meth:`Attitude.from_file`, and is
brought onto the simulation's epochs by :meth:`Attitude.resample` (SLERP).
"""
import csv
import io
import os

import numpy as np

from simcore.errors import InputNotFoundError, InvalidInputError

DEFAULT_TUMBLE_AXIS = np.full(3, 1.0 / np.sqrt(3.0))
DEFAULT_TUMBLE_AXIS.setflags(write=False)  # a shared default argument: keep it immutable
DEFAULT_TUMBLE_RATE_DEG_S = 1.9  # thesis sec. 4.3
ATTITUDE_CSV_HEADER = ("t_s", "qw", "qx", "qy", "qz")


def _as_quats(q, name="q"):
    """Return ``q`` as float64 (N, 4), or raise ValueError."""
    arr = np.asarray(q, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 4 or arr.shape[0] == 0:
        raise ValueError(f"{name} must be a quaternion (4,) or (N, 4), scalar first (w, x, y, z); "
                         f"got shape {np.shape(q)}")
    return arr


def quat_normalize(q):
    """Return unit quaternions (N, 4), scalar first; raise on zero or non-finite input."""
    q = _as_quats(q)
    if not np.all(np.isfinite(q)):
        bad = np.flatnonzero(~np.all(np.isfinite(q), axis=1))
        raise ValueError(f"quaternion rows {bad[:10].tolist()} are not finite; a rotation needs four finite numbers")
    norm = np.linalg.norm(q, axis=1)
    if np.any(norm == 0):
        bad = np.flatnonzero(norm == 0)
        raise ValueError(f"quaternion rows {bad[:10].tolist()} are zero; a zero quaternion is no rotation")
    return q / norm[:, None]


def norm_outliers(q, tol):
    """Return (norms (N,), indices of the rows of ``q`` (N, 4) whose norm is not 1 within ``tol``)."""
    norm = np.linalg.norm(q, axis=1)
    return norm, np.flatnonzero(np.abs(norm - 1.0) > tol)


def quat_multiply(q1, q2):
    """Return the Hamilton product q1 * q2, (N, 4) scalar first (rotation q2 first, then q1)."""
    a, b = np.broadcast_arrays(_as_quats(q1, "q1"), _as_quats(q2, "q2"))
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ], axis=1)


def quat_conjugate(q):
    """Return the conjugate (inverse for unit q), (N, 4) scalar first."""
    return _as_quats(q) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q):
    """Return rotation matrices (N, 3, 3) of quaternions (N, 4) or (4,), scalar first, Hamilton.

    ``R @ v`` equals the quaternion rotation ``q v q*``. The input is
    normalised first (:func:`quat_normalize`).
    """
    w, x, y, z = quat_normalize(q).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def matrix_to_quat(R, tol=1e-6):
    """Return unit quaternions (N, 4), scalar first with w >= 0, of rotation matrices (N, 3, 3) or (3, 3).

    Shepperd's method (J. Guidance Control 1, 223, 1978): the largest of
    w^2, x^2, y^2, z^2 is taken from the trace/diagonal and the others from
    off-diagonal sums, so no division by a small number. ``R`` must be a
    proper rotation: ``|R R^T - I|`` and ``|det R - 1|`` within ``tol``.
    """
    R = np.asarray(R, dtype=float)
    if R.ndim == 2:
        R = R[None]
    if R.ndim != 3 or R.shape[1:] != (3, 3) or R.shape[0] == 0:
        raise ValueError(f"R must be a rotation matrix (3, 3) or a stack (N, 3, 3); got shape {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError("R has non-finite entries")
    ortho = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = (ortho > tol) | (np.abs(det - 1.0) > tol)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"R[{i}] is not a proper rotation (|R R^T - I| = {ortho[i]:.3g}, det = {det[i]:.6g}, "
                         f"tolerance {tol}); orthonormalise it first (e.g. via SVD)")
    tr = np.trace(R, axis1=1, axis2=2)
    diag = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    pick = np.argmax(diag, axis=1)
    q = np.empty((R.shape[0], 4))
    r = R
    # Case 0: w largest.
    m = pick == 0
    s = np.sqrt(1.0 + tr[m]) * 2.0  # 4 w
    q[m] = np.stack([0.25 * s, (r[m, 2, 1] - r[m, 1, 2]) / s, (r[m, 0, 2] - r[m, 2, 0]) / s,
                     (r[m, 1, 0] - r[m, 0, 1]) / s], axis=1)
    m = pick == 1
    s = np.sqrt(1.0 + r[m, 0, 0] - r[m, 1, 1] - r[m, 2, 2]) * 2.0  # 4 x
    q[m] = np.stack([(r[m, 2, 1] - r[m, 1, 2]) / s, 0.25 * s, (r[m, 0, 1] + r[m, 1, 0]) / s,
                     (r[m, 0, 2] + r[m, 2, 0]) / s], axis=1)
    m = pick == 2
    s = np.sqrt(1.0 - r[m, 0, 0] + r[m, 1, 1] - r[m, 2, 2]) * 2.0  # 4 y
    q[m] = np.stack([(r[m, 0, 2] - r[m, 2, 0]) / s, (r[m, 0, 1] + r[m, 1, 0]) / s, 0.25 * s,
                     (r[m, 1, 2] + r[m, 2, 1]) / s], axis=1)
    m = pick == 3
    s = np.sqrt(1.0 - r[m, 0, 0] - r[m, 1, 1] + r[m, 2, 2]) * 2.0  # 4 z
    q[m] = np.stack([(r[m, 1, 0] - r[m, 0, 1]) / s, (r[m, 0, 2] + r[m, 2, 0]) / s,
                     (r[m, 1, 2] + r[m, 2, 1]) / s, 0.25 * s], axis=1)
    q = quat_normalize(q)
    return np.where(q[:, :1] < 0, -q, q)


def axis_angle_to_quat(axis, angle_rad):
    """Return unit quaternions (N, 4) of right-handed rotations by ``angle_rad`` (N,) about ``axis`` (3,)."""
    axis = np.asarray(axis, dtype=float)
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.linalg.norm(axis) > 0:
        raise ValueError(f"axis must be a finite, non-zero 3-vector; got {axis!r}")
    axis = axis / np.linalg.norm(axis)
    half = 0.5 * np.atleast_1d(np.asarray(angle_rad, dtype=float))
    return np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * axis[None, :]], axis=1)


def _slerp(q0, q1, f):
    """Return unit quaternions (N, 4) a fraction f (N,) of the way from q0 to q1 on the shorter arc."""
    dot = np.einsum("ij,ij->i", q0, q1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    # Angle between the 4-vectors from chord lengths: accurate for tiny and large angles.
    omega = 2.0 * np.arctan2(np.linalg.norm(q0 - q1, axis=1), np.linalg.norm(q0 + q1, axis=1))
    sin_omega = np.sin(omega)
    tiny = sin_omega < 1e-12
    safe = np.where(tiny, 1.0, sin_omega)
    w0 = np.where(tiny, 1.0 - f, np.sin((1.0 - f) * omega) / safe)
    w1 = np.where(tiny, f, np.sin(f * omega) / safe)
    return quat_normalize(w0[:, None] * q0 + w1[:, None] * q1)


class Attitude:
    """Orientation of the body frame in GCRS at N epochs: ``q_gcrs_from_body`` (N, 4), scalar first.

    ``t_s`` (N,), optional, are the epochs in seconds (from any origin the
    caller chooses, e.g. the start of the run); they are needed only by
    :meth:`resample` and must then increase strictly.
    """

    __slots__ = ("q_gcrs_from_body", "t_s")

    def __init__(self, q_gcrs_from_body, t_s=None, norm_tol=1e-3):
        q = _as_quats(q_gcrs_from_body, "q_gcrs_from_body")
        if not np.all(np.isfinite(q)):
            bad = np.flatnonzero(~np.all(np.isfinite(q), axis=1))
            raise ValueError(f"attitude quaternions in rows {bad[:10].tolist()} are not finite")
        norm, off = norm_outliers(q, norm_tol)
        if off.size:
            i = int(off[0])
            raise ValueError(f"attitude quaternion row {i} has norm {norm[i]:.6g}, not 1 within {norm_tol} "
                             f"({off.size} such rows); check the column order and the scalar-first/last "
                             "convention, or normalise the quaternions deliberately before using them")
        q = q / norm[:, None]
        if t_s is not None:
            t_s = np.atleast_1d(np.asarray(t_s, dtype=float))
            if t_s.shape != (q.shape[0],):
                raise ValueError(f"t_s must have shape ({q.shape[0]},) to match the quaternions; got {t_s.shape}")
            if not np.all(np.isfinite(t_s)):
                raise ValueError("t_s has non-finite values")
            if np.any(np.diff(t_s) <= 0):
                i = int(np.flatnonzero(np.diff(t_s) <= 0)[0])
                raise ValueError(f"t_s must increase strictly; t_s[{i + 1}] = {t_s[i + 1]} follows {t_s[i]}; "
                                 "sort the history and drop duplicate epochs")
        self.q_gcrs_from_body = q
        self.t_s = t_s

    # ---- constructors -------------------------------------------------
    @classmethod
    def from_quaternions(cls, q, scalar_first=True, *, t_s=None, norm_tol=1e-3):
        """Return the Attitude of a user-supplied history q (N, 4) of GCRS-from-body quaternions.

        ``scalar_first=False`` accepts (x, y, z, w) rows (the SciPy/ROS
        order). Each quaternion must have norm 1 within ``norm_tol`` (a
        looser norm means a wrong column order or units, not rounding) and
        is then normalised. ``t_s`` (N,), seconds, strictly increasing,
        is needed only to :meth:`resample` the history.
        """
        q = _as_quats(q)
        if not scalar_first:
            q = q[:, [3, 0, 1, 2]]
        return cls(q, t_s=t_s, norm_tol=norm_tol)

    @classmethod
    def from_file(cls, path, norm_tol=1e-3):
        """Return the Attitude history stored in a CSV file (times in ``t_s``).

        Format: comma-separated, first non-comment line the header
        ``t_s,qw,qx,qy,qz``, then one row per epoch: time in seconds
        (strictly increasing, any origin: ``sunsim run --attitude`` takes the
        first row as the run's start) and the scalar-first quaternion
        ``q_gcrs_from_body``. Lines starting with ``#`` and blank lines are
        ignored.
        """
        path = os.fspath(path)
        try:
            with open(path, "rb") as fh:
                raw = fh.read()
        except FileNotFoundError:
            raise InputNotFoundError(f"attitude file {path} not found; give an existing CSV file "
                                     f"({','.join(ATTITUDE_CSV_HEADER)})") from None
        except OSError as exc:
            raise InvalidInputError(f"cannot read attitude file {path}: {exc.strerror}") from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            text = None
        if text is None or "\x00" in text:
            raise InvalidInputError(f"{path} is not an attitude CSV file (it holds binary data); give a text "
                                    f"file with the header {','.join(ATTITUDE_CSV_HEADER)}")
        rows = []
        header = None
        for lineno, line in enumerate(csv.reader(io.StringIO(text, newline="")), start=1):
            if not line or not "".join(line).strip() or line[0].lstrip().startswith("#"):
                continue
            cells = [c.strip() for c in line]
            if header is None:
                header = tuple(cells)
                if header != ATTITUDE_CSV_HEADER:
                    raise InvalidInputError(f"{path}:{lineno}: header must be {','.join(ATTITUDE_CSV_HEADER)}, "
                                            f"got {','.join(cells)}")
                continue
            if len(cells) != 5:
                raise InvalidInputError(f"{path}:{lineno}: expected 5 values (t_s,qw,qx,qy,qz), got {len(cells)}")
            try:
                rows.append([float(c) for c in cells])
            except ValueError:
                raise InvalidInputError(f"{path}:{lineno}: cannot read {','.join(cells)} as numbers") from None
        if header is None or not rows:
            raise InvalidInputError(f"{path}: no attitude rows found; expected a header "
                                    f"{','.join(ATTITUDE_CSV_HEADER)} and one row per epoch")
        data = np.array(rows)
        try:
            return cls(data[:, 1:], t_s=data[:, 0], norm_tol=norm_tol)
        except ValueError as exc:
            raise InvalidInputError(f"{path}: {exc}") from None

    def to_file(self, path):
        """Write the history as CSV (``t_s,qw,qx,qy,qz``) readable by :meth:`from_file`."""
        if self.t_s is None:
            raise ValueError("this Attitude has no times (t_s); build it with t_s to write a file")
        data = np.column_stack([self.t_s, self.q_gcrs_from_body])
        np.savetxt(path, data, delimiter=",", header=",".join(ATTITUDE_CSV_HEADER), comments="", fmt="%.17g")

    # ---- views --------------------------------------------------------
    def __len__(self):
        return self.q_gcrs_from_body.shape[0]

    def __repr__(self):
        span = "" if self.t_s is None else f", t_s {self.t_s[0]:g}..{self.t_s[-1]:g} s"
        return f"Attitude({len(self)} epochs{span})"

    @property
    def R_gcrs_from_body(self):
        """Rotation matrices (N, 3, 3): ``v_gcrs = R @ v_body``."""
        return quat_to_matrix(self.q_gcrs_from_body)

    @property
    def R_body_from_gcrs(self):
        """Rotation matrices (N, 3, 3): ``v_body = R @ v_gcrs`` (transpose of R_gcrs_from_body)."""
        return np.swapaxes(self.R_gcrs_from_body, 1, 2)

    def _vectors(self, v, name):
        v = np.asarray(v, dtype=float)
        if v.ndim == 1:
            v = v[None, :]
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] not in (1, len(self)):
            raise ValueError(f"{name} must have shape (3,), (1, 3) or ({len(self)}, 3); got {np.shape(v)}")
        return v

    def to_body(self, v_gcrs):
        """Return the vectors in the body frame, (N, 3), of GCRS vectors (N, 3) or one (3,)."""
        return np.einsum("nji,nj->ni", self.R_gcrs_from_body, self._vectors(v_gcrs, "v_gcrs"))

    def to_gcrs(self, v_body):
        """Return the vectors in GCRS, (N, 3), of body vectors (N, 3) or one (3,)."""
        return np.einsum("nij,nj->ni", self.R_gcrs_from_body, self._vectors(v_body, "v_body"))

    def resample(self, t_s):
        """Return the Attitude at times ``t_s`` (M,) by SLERP between this history's samples.

        Spherical linear interpolation on the shorter arc between the two
        neighbouring samples: exact for a constant-rate rotation about a
        fixed axis turning less than 180 deg between samples. Times must lie
        within the history's span (no extrapolation).
        """
        if self.t_s is None:
            raise ValueError("this Attitude has no times (t_s); build it with t_s (e.g. from_file) to resample")
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if t.ndim != 1 or not np.all(np.isfinite(t)):
            raise ValueError(f"t_s must be finite times (M,) in seconds; got shape {t.shape}")
        lo, hi = self.t_s[0], self.t_s[-1]
        out = (t < lo) | (t > hi)
        if np.any(out):
            i = int(np.flatnonzero(out)[0])
            raise ValueError(f"cannot resample at t = {t[i]} s: the attitude history spans {lo} .. {hi} s "
                             f"({int(out.sum())} requested times outside); supply a longer history")
        if len(self) == 1:
            return Attitude(np.repeat(self.q_gcrs_from_body, t.size, axis=0), t_s=None if t.size > 1 else t)
        i = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, len(self) - 2)
        f = (t - self.t_s[i]) / (self.t_s[i + 1] - self.t_s[i])
        q = _slerp(self.q_gcrs_from_body[i], self.q_gcrs_from_body[i + 1], f)
        strictly = t.size == 1 or np.all(np.diff(t) > 0)
        return Attitude(q, t_s=t if strictly else None)


def tumble(seconds, rate_deg_s=DEFAULT_TUMBLE_RATE_DEG_S, axis_body=DEFAULT_TUMBLE_AXIS,
           q0_gcrs_from_body=(1.0, 0.0, 0.0, 0.0)):
    """Return the Attitude (N epochs) of a constant-rate tumble about a fixed axis at ``seconds`` (N,).

    ``R_gcrs_from_body(t) = R0 @ Rot(axis_body, rate * t)``: the body turns
    at ``rate_deg_s`` about ``axis_body`` (right-handed), which is the same
    line in the body frame and, as ``R0 @ axis_body``, fixed in GCRS
    (torque-free rotation about a principal axis). ``seconds`` are counted
    from the epoch where the attitude is ``q0_gcrs_from_body``. Defaults:
    1.9 deg/s (thesis sec. 4.3) about the body diagonal (1, 1, 1)/sqrt(3)
    (the thesis gives no axis; see the module docstring).
    """
    t = np.atleast_1d(np.asarray(seconds, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"seconds must be finite times (N,) in seconds; got shape {t.shape}")
    rate = float(rate_deg_s)
    if not np.isfinite(rate):
        raise ValueError(f"rate_deg_s must be finite, got {rate_deg_s}")
    q0 = quat_normalize(q0_gcrs_from_body)
    if q0.shape[0] != 1:
        raise ValueError(f"q0_gcrs_from_body must be one quaternion (4,); got shape {np.shape(q0_gcrs_from_body)}")
    q_spin = axis_angle_to_quat(axis_body, np.radians(rate) * t)
    q = quat_multiply(q0, q_spin)
    strictly = t.size == 1 or np.all(np.diff(t) > 0)
    return Attitude(q, t_s=t if strictly else None)
