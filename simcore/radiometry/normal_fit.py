"""Fit a photodiode's normal and scale to its readings by the cosine law (direct Sun only).

:func:`fit_normal` solves ``reading ~ scale * (normal . sun_dir_body)`` over the chosen samples for the
vector ``m = scale * normal`` (linear least squares, then iteratively reweighted with soft-L1 weights
``1 / sqrt(1 + (r / f)^2)``, ``f`` = :data:`SOFT_L1_SCALE`, so that the few samples where the attitude
estimate jumps or albedo adds do not steer the fit), and returns the unit normal, the scale and the
residuals ``reading - max(0, m . s)`` at every sample (NaN outside the mask).

The samples to fit on are the caller's choice (``mask``): the cosine law without albedo holds where the
diode faces the Sun clearly (e.g. reading > 0.2 and the spacecraft sunlit); where it reads near zero
the Earth's albedo and the diode's field of view decide, not its normal.

:func:`convention_fits` fits the same readings under the four quaternion conventions (scalar first or
last, times ``R`` or ``R^T``) so that the data show which one is right (docs/attitude_history.md).
"""
from dataclasses import dataclass

import numpy as np

from simcore.environment.attitude import quat_to_matrix
from simcore.errors import InvalidInputError

SOFT_L1_SCALE = 0.02        # residual (fraction of full Sun) where the soft-L1 weight starts to fall
IRLS_ITERATIONS = 20


@dataclass(frozen=True)
class NormalFit:
    """A fitted normal: ``normal`` (3,) unit, ``scale``, ``residuals`` (N,) at every sample (NaN outside the
    mask), ``n`` samples used, their median |residual| and RMS residual."""

    normal: np.ndarray
    scale: float
    residuals: np.ndarray
    n: int
    median_abs_residual: float
    rms_residual: float

    def __iter__(self):          # normal, scale, residuals = fit_normal(...)
        return iter((self.normal, self.scale, self.residuals))


def fit_normal(sun_dir_body, reading, mask=None):
    """Return the :class:`NormalFit` of ``reading`` (N,) ~ scale * (normal . ``sun_dir_body`` (N, 3)) on ``mask``.

    ``mask`` (N,) bool selects the samples to fit on (default: every finite one); at least 3 with
    non-coplanar Sun directions are needed. Unpacks as ``normal, scale, residuals``.
    """
    s = np.asarray(sun_dir_body, dtype=float)
    y = np.asarray(reading, dtype=float)
    if s.ndim != 2 or s.shape[1] != 3 or y.shape != (s.shape[0],):
        raise InvalidInputError(f"fit_normal needs sun_dir_body (N, 3) and reading (N,); got {s.shape} and {y.shape}")
    m = np.ones(y.shape, bool) if mask is None else np.asarray(mask, bool)
    m = m & np.all(np.isfinite(s), axis=1) & np.isfinite(y)
    if m.sum() < 3 or np.linalg.matrix_rank(s[m]) < 3:
        raise InvalidInputError(f"fit_normal: {int(m.sum())} usable samples whose Sun directions do not span 3-D; "
                                "a normal needs the Sun seen from at least three independent directions")
    A, b = s[m], y[m]
    w = np.ones(b.shape)
    for _ in range(IRLS_ITERATIONS):
        sw = np.sqrt(w)
        vec, *_ = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)
        r = b - A @ vec
        w = 1.0 / np.sqrt(1.0 + (r / SOFT_L1_SCALE) ** 2)
    scale = float(np.linalg.norm(vec))
    normal = vec / scale
    res = np.full(y.shape, np.nan)
    res[m] = y[m] - np.clip(s[m] @ vec, 0.0, None)
    return NormalFit(normal, scale, res, int(m.sum()), float(np.median(np.abs(res[m]))),
                     float(np.sqrt(np.mean(res[m] ** 2))))


CONVENTIONS = (
    ("scalar first, v_body = R(q) v_inertial", True, "frame_to_body"),
    ("scalar first, v_inertial = R(q) v_body", True, "body_to_frame"),
    ("scalar last, v_body = R(q) v_inertial", False, "frame_to_body"),
    ("scalar last, v_inertial = R(q) v_body", False, "body_to_frame"),
)


def sun_in_body(q_recorded, sun_dir_inertial, scalar_first, direction):
    """Return (N, 3) the Sun's direction in body axes under one quaternion convention.

    ``q_recorded`` (N, 4) as recorded (not necessarily unit); ``direction`` 'frame_to_body' (v_body = R(q) v)
    or 'body_to_frame' (v = R(q) v_body, so v_body = R(q)^T v)."""
    q = np.asarray(q_recorded, dtype=float)
    if not scalar_first:
        q = q[:, [3, 0, 1, 2]]
    R = quat_to_matrix(q)
    if direction == "frame_to_body":
        return np.einsum("nij,nj->ni", R, sun_dir_inertial)
    return np.einsum("nji,nj->ni", R, sun_dir_inertial)


def convention_fits(q_recorded, sun_dir_inertial, reading, mask):
    """Return [(label, scalar_first, direction, NormalFit)] of the readings fitted under each of the four
    conventions (:data:`CONVENTIONS`): the right one gives a small residual, a scale near 1 and (for a
    diode mounted on a face) an axis-aligned normal."""
    return [(label, sf, d, fit_normal(sun_in_body(q_recorded, sun_dir_inertial, sf, d), reading, mask))
            for label, sf, d in CONVENTIONS]
