"""Torque-free rigid-body attitude dynamics: Euler's equations and quaternion kinematics.

The thesis' runs (sec. 4.3) tumble the satellite at a constant rate about a
fixed axis (:func:`simcore.environment.attitude.tumble`, still the default). A real
CubeSat with an inertia tensor J tumbles about a fixed axis only when that
axis is a principal axis; otherwise the body rate nutates. This module
integrates

    J dw/dt = -w x (J w)                          (Euler's equations, no torque)
    dq/dt   = 1/2 q * (0, w)                      (Hamilton product, q = q_gcrs_from_body)

with the classical fourth-order Runge-Kutta method on a fixed inner step
(``max_step_s``, 0.1 s by default: at 2 deg/s the local error per step is
~(0.0035 rad)^5, far below what any sensor sees), renormalising q after
every step. Checked (tests/environment/test_dynamics.py) against the closed-form
axisymmetric solution (body rate precessing about the symmetry axis at
lambda = (I3 - I1)/I1 * w3) and the conservation of rotational energy and of
the angular momentum in the inertial frame.

Units: J in kg m^2, rates in rad/s in the body frame, time in seconds.
"""
import numpy as np

from simcore.errors import InvalidInputError

from simcore.environment.attitude import Attitude, quat_multiply, quat_normalize

INERTIA_HELP = ("inertia tensor in kg m^2: 'IXX,IYY,IZZ' (principal axes = body axes) or "
                "'IXX,IYY,IZZ,IXY,IXZ,IYZ'")


def parse_inertia(text):
    """Return the inertia tensor J (3, 3), kg m^2, body frame, of 'IXX,IYY,IZZ[,IXY,IXZ,IYZ]'.

    Raises ValueError (a message saying what is wrong and what to give) when the
    text is not 3 or 6 numbers or the tensor is not symmetric positive definite.
    """
    parts = [p for p in str(text).replace(" ", ",").split(",") if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise InvalidInputError(f"--dynamics {text!r}: cannot read numbers; give the {INERTIA_HELP}") from None
    if len(vals) == 3:
        J = np.diag(vals)
    elif len(vals) == 6:
        ixx, iyy, izz, ixy, ixz, iyz = vals
        J = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    else:
        raise InvalidInputError(f"--dynamics {text!r}: {len(vals)} numbers; give the {INERTIA_HELP}")
    return check_inertia(J)


def check_inertia(J):
    """Return J (3, 3) as float if it is a physical inertia tensor, else raise ValueError.

    Physical: finite, symmetric, positive definite, and its principal moments
    obey the triangle inequality I_a + I_b >= I_c (a real mass distribution).
    """
    J = np.asarray(J, dtype=float)
    if J.shape != (3, 3) or not np.all(np.isfinite(J)):
        raise InvalidInputError(f"the inertia tensor must be a finite 3 x 3 matrix in kg m^2, got shape {J.shape}")
    if not np.allclose(J, J.T, rtol=1e-12, atol=1e-15 * np.abs(J).max()):
        raise InvalidInputError(f"the inertia tensor is not symmetric ({J.tolist()}); give IXX,IYY,IZZ,IXY,IXZ,IYZ "
                         "so the products of inertia appear once")
    moments = np.linalg.eigvalsh(J)
    if not moments[0] > 0:
        raise InvalidInputError(f"the inertia tensor is not positive definite (principal moments {moments.tolist()} "
                         "kg m^2); every principal moment of a real body is > 0 (a 2U CubeSat: ~0.01-0.02)")
    if moments[0] + moments[1] < moments[2] * (1 - 1e-12):
        raise InvalidInputError(f"the principal moments {moments.tolist()} kg m^2 violate I1 + I2 >= I3: no real body "
                         "has this inertia; check the units and the diagonal")
    return J


def euler_rate_derivative(J, J_inv, w_body_rad_s):
    """Return dw/dt (N, 3), rad/s^2, body frame, of Euler's torque-free equations J dw/dt = -w x Jw."""
    w = np.atleast_2d(w_body_rad_s)
    return -np.cross(w, w @ J.T) @ J_inv.T


def _quat_derivative(q, w):
    """Return dq/dt (N, 4) = 1/2 q * (0, w) for q_gcrs_from_body and body rates w (N, 3)."""
    return 0.5 * quat_multiply(q, np.concatenate([np.zeros((w.shape[0], 1)), w], axis=1))


def propagate_torque_free(t_s, J, w0_body_rad_s, q0_gcrs_from_body=(1.0, 0.0, 0.0, 0.0), *, max_step_s=0.1):
    """Return (Attitude at ``t_s`` (N,), body rates w_body_rad_s (N, 3)) of a torque-free rigid body.

    ``t_s`` strictly increasing seconds with the initial state at ``t_s[0]``;
    ``J`` (3, 3) kg m^2 body frame (checked by :func:`check_inertia`);
    ``w0_body_rad_s`` (3,) the initial body rate; ``q0_gcrs_from_body`` the
    initial attitude. RK4 on the coupled (q, w) state with inner steps no
    longer than ``max_step_s``.
    """
    J = check_inertia(J)
    J_inv = np.linalg.inv(J)
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError("t_s must be finite, strictly increasing seconds (N,)")
    w = np.asarray(w0_body_rad_s, dtype=float).reshape(1, 3)
    if not np.all(np.isfinite(w)):
        raise ValueError(f"the initial body rate must be finite, got {w0_body_rad_s}")
    q = quat_normalize(q0_gcrs_from_body)
    if not max_step_s > 0:
        raise ValueError(f"max_step_s must be > 0, got {max_step_s}")

    def f(q_, w_):
        return _quat_derivative(q_, w_), euler_rate_derivative(J, J_inv, w_)

    qs = np.empty((t.size, 4))
    ws = np.empty((t.size, 3))
    qs[0], ws[0] = q[0], w[0]
    for i in range(1, t.size):
        span = t[i] - t[i - 1]
        n = int(np.ceil(span / max_step_s - 1e-9))
        h = span / n
        for _ in range(n):
            k1q, k1w = f(q, w)
            k2q, k2w = f(q + 0.5 * h * k1q, w + 0.5 * h * k1w)
            k3q, k3w = f(q + 0.5 * h * k2q, w + 0.5 * h * k2w)
            k4q, k4w = f(q + h * k3q, w + h * k3w)
            q = q + h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)
            w = w + h / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w)
            q = q / np.linalg.norm(q)
        qs[i], ws[i] = q[0], w[0]
    qs = np.where(qs[:, :1] < 0, -qs, qs)
    return Attitude(qs, t_s=t), ws


def axisymmetric_rate(t_s, I_transverse, I_axial, w0_body_rad_s):
    """Return the closed-form body rate (N, 3), rad/s, of a torque-free axisymmetric body (symmetry axis z).

    w_z is constant; (w_x, w_y) turns about body z at lambda = (I_axial -
    I_transverse) / I_transverse * w_z: w_x' = -lambda w_y, w_y' = lambda w_x
    (Wie, Space Vehicle Dynamics and Control, 2nd ed., sec. 6.4).
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    w0 = np.asarray(w0_body_rad_s, dtype=float)
    lam = (I_axial - I_transverse) / I_transverse * w0[2]
    c, s = np.cos(lam * (t - t[0])), np.sin(lam * (t - t[0]))
    return np.stack([w0[0] * c - w0[1] * s, w0[0] * s + w0[1] * c, np.full_like(t, w0[2])], axis=1)


def axisymmetric_attitude(t_s, I_transverse, I_axial, w0_body_rad_s, q0_gcrs_from_body=(1.0, 0.0, 0.0, 0.0)):
    """Return the closed-form Attitude (N epochs) of a torque-free axisymmetric body (symmetry axis body z).

    The body rate splits into w = h_body / I_transverse - lambda z: a precession
    about the inertial angular momentum h at |h| / I_transverse and a spin
    -lambda about body z (:func:`axisymmetric_rate`), so
    q(t) = Rot(h_gcrs, |h| t / I_transverse) * q0 * Rot(z, -lambda t).
    """
    from simcore.environment.attitude import axis_angle_to_quat, quat_to_matrix
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    dt = t - t[0]
    w0 = np.asarray(w0_body_rad_s, dtype=float)
    q0 = quat_normalize(q0_gcrs_from_body)
    h_body = np.array([I_transverse * w0[0], I_transverse * w0[1], I_axial * w0[2]])
    h_gcrs = quat_to_matrix(q0)[0] @ h_body
    lam = (I_axial - I_transverse) / I_transverse * w0[2]
    q_prec = axis_angle_to_quat(h_gcrs, np.linalg.norm(h_body) / I_transverse * dt)
    q_spin = axis_angle_to_quat([0.0, 0.0, 1.0], -lam * dt)
    q = quat_multiply(quat_multiply(q_prec, q0), q_spin)
    return Attitude(np.where(q[:, :1] < 0, -q, q), t_s=t)
