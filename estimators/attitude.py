"""Attitude from vector measurements: TRIAD, Davenport's q-method, QUEST, and a multiplicative EKF.

Pure functions on arrays (nothing from simcore). Conventions as in the rest of sunsim:
quaternions scalar first (w, x, y, z), Hamilton product; the attitude is
``q_ref_from_body`` (``R_ref_from_body``: ``v_ref = R @ v_body``), the reference frame being
the inertial one in which the reference vectors are given (GCRS in sunsim). Time leads:
N epochs give (N, 3) vectors and (N, 4) quaternions.

- :func:`triad`: Black (1964) / Shuster & Oh (1981) TRIAD from two vector pairs, the first
  one (the more accurate) exactly matched.
- :func:`q_method`: Davenport's q-method: the eigenvector of the largest eigenvalue of the
  4 x 4 K matrix solves Wahba's problem (Markley & Crassidis, Fundamentals of Spacecraft
  Attitude Determination and Control, 2014, eqs. 5.17-5.21; hereafter M&C).
- :func:`quest`: Shuster's QUEST (M&C sec. 5.3.3): the largest eigenvalue by Newton's method
  on the characteristic equation, then the Gibbs vector; the same optimum as the q-method.
- :class:`MEKF`: the multiplicative extended Kalman filter of attitude and gyro bias (M&C
  sec. 6.2; Lefferts, Markley & Shuster 1982): a body-frame rotation-vector attitude error
  ``R_true = R_est Exp(dtheta)``, gyro model ``w = w_true + b + n_v``, ``db/dt = n_u``
  (Farrenkopf), discrete process noise of M&C eq. 6.93, unit-vector measurements with
  covariance ``sigma^2 I`` (Shuster's QUEST measurement model, M&C eq. 5.31) on the two
  components perpendicular to the predicted vector, and innovation gating: a measurement
  whose normalised innovation squared exceeds the chi-square 0.9999 quantile (2 degrees of
  freedom) is rejected.
"""
import numpy as np

CHI2_2DOF_GATE_99_99 = 18.420681   # chi-square 2 dof, 0.9999 quantile: -2 ln(1e-4) (closed form for 2 dof)


# ---- small quaternion / rotation helpers (scalar first, Hamilton) --------------------------------
def quat_mul(a, b):
    """Return the Hamilton product a * b (..., 4), scalar first."""
    w1, x1, y1, z1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    w2, x2, y2, z2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=-1)


def quat_to_dcm(q):
    """Return rotation matrices (..., 3, 3) ``R_ref_from_body`` of unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)], axis=-2)


def dcm_to_quat(R):
    """Return unit quaternions (N, 4), w >= 0, of rotation matrices (N, 3, 3) (via the q-method's K
    matrix of the rotation itself: robust for any angle)."""
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    # The quaternion of R is the top eigenvector of Bar-Itzhack's symmetric 4 x 4 matrix.
    K = np.empty((R.shape[0], 4, 4))
    tr = np.trace(R, axis1=1, axis2=2)
    K[:, 0, 0] = tr
    K[:, 0, 1:] = K[:, 1:, 0] = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0],
                                           R[:, 1, 0] - R[:, 0, 1]], axis=1)
    K[:, 1:, 1:] = R + np.swapaxes(R, 1, 2) - tr[:, None, None] * np.eye(3)
    _, vecs = np.linalg.eigh(K)
    q = vecs[:, :, -1]
    return np.where(q[:, :1] < 0, -q, q)


def rotvec_to_quat(v):
    """Return unit quaternions (..., 4) of rotation vectors (..., 3), rad."""
    v = np.asarray(v, dtype=float)
    ang = np.linalg.norm(v, axis=-1, keepdims=True)
    s = np.where(ang > 1e-12, np.sin(0.5 * ang) / np.where(ang > 0, ang, 1.0), 0.5)
    return np.concatenate([np.cos(0.5 * ang), s * v], axis=-1)


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ---- static solutions ------------------------------------------------------------------------------
def triad(b1_body, b2_body, r1_ref, r2_ref):
    """Return R_ref_from_body (N, 3, 3) by TRIAD from two body/reference vector pairs (N, 3) each.

    The first pair is matched exactly; the second fixes the rotation about it. Rows with
    (nearly) parallel vectors (angle < 1e-6 rad) give NaN.
    """
    b1, b2, r1, r2 = (np.atleast_2d(_unit(v)) for v in (b1_body, b2_body, r1_ref, r2_ref))
    bx, rx = np.cross(b1, b2), np.cross(r1, r2)
    bad = (np.linalg.norm(bx, axis=1) < 1e-6) | (np.linalg.norm(rx, axis=1) < 1e-6)
    bx, rx = _unit(bx), _unit(rx)
    Mb = np.stack([b1, bx, np.cross(b1, bx)], axis=2)       # columns
    Mr = np.stack([r1, rx, np.cross(r1, rx)], axis=2)
    R = Mr @ np.swapaxes(Mb, 1, 2)
    R[bad] = np.nan
    return R


def _attitude_profile(b_body, r_ref, weights):
    b = np.asarray(b_body, dtype=float)
    r = np.asarray(r_ref, dtype=float)
    if b.ndim == 2:
        b, r = b[None], r[None]
    w = np.broadcast_to(np.asarray(weights, dtype=float), b.shape[:2])
    # Wahba's attitude matrix A maps reference to body: b = A r; B = sum w b r^T (M&C eq. 5.8).
    return np.einsum("nm,nmi,nmj->nij", w, _unit(b), _unit(r)), w


def _K_matrix(B):
    S = B + np.swapaxes(B, 1, 2)
    z = np.stack([B[:, 1, 2] - B[:, 2, 1], B[:, 2, 0] - B[:, 0, 2], B[:, 0, 1] - B[:, 1, 0]], axis=1)
    tr = np.trace(B, axis1=1, axis2=2)
    K = np.empty((B.shape[0], 4, 4))
    # Scalar-first ordering of M&C eq. 5.17 (they put the scalar last).
    K[:, 0, 0] = tr
    K[:, 0, 1:] = K[:, 1:, 0] = z
    K[:, 1:, 1:] = S - tr[:, None, None] * np.eye(3)
    return K


def _adjugate(M):
    """Return the adjugate (N, 4, 4) of matrices (N, 4, 4) from cofactors (no inverse: fine when singular)."""
    adj = np.empty_like(M)
    for i in range(4):
        for j in range(4):
            minor = np.delete(np.delete(M, i, axis=1), j, axis=2)
            adj[:, j, i] = (-1) ** (i + j) * np.linalg.det(minor)
    return adj


def _conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def q_method(b_body, r_ref, weights=1.0):
    """Return q_ref_from_body (N, 4) solving Wahba's problem by Davenport's q-method.

    ``b_body``, ``r_ref``: (N, M, 3) (or (M, 3)) matched body and reference vectors;
    ``weights`` (M,) or (N, M), e.g. 1 / sigma^2.
    """
    B, _ = _attitude_profile(b_body, r_ref, weights)
    _, vecs = np.linalg.eigh(_K_matrix(B))
    # M&C's quaternion of the passive A = R_ref_from_body^T has the components of the Hamilton
    # quaternion of R_ref_from_body itself.
    q = vecs[:, :, -1]
    return np.where(q[:, :1] < 0, -q, q)


def quest(b_body, r_ref, weights=1.0, iterations=5):
    """Return q_ref_from_body (N, 4) by Shuster's QUEST (M&C sec. 5.3.3): Newton on the characteristic
    polynomial of K from lambda_0 = sum of weights, then the optimal quaternion of that eigenvalue."""
    B, w = _attitude_profile(b_body, r_ref, weights)
    K = _K_matrix(B)
    lam = w.sum(axis=1)
    for _ in range(iterations):
        # Newton step on f = det(K - lambda I): f' = -trace(adj(K - lambda I)).
        M = K - lam[:, None, None] * np.eye(4)
        f = np.linalg.det(M)
        df = -np.trace(_adjugate(M), axis1=1, axis2=2)
        lam = lam - f / np.where(df != 0, df, 1.0)
    # The eigenvector: the column of adj(K - lambda I) with the largest norm (stable near any angle).
    adj = _adjugate(K - lam[:, None, None] * np.eye(4))
    col = np.argmax(np.linalg.norm(adj, axis=1), axis=1)
    q = _unit(adj[np.arange(adj.shape[0]), :, col])       # as in q_method: q_ref_from_body
    return np.where(q[:, :1] < 0, -q, q)


# ---- the filter -------------------------------------------------------------------------------------
class MEKF:
    """Multiplicative EKF of attitude ``q_ref_from_body`` and gyro bias ``bias_rad_s`` (body frame).

    Error state x = (dtheta (3, rad, body frame), db (3, rad/s)), covariance ``P`` (6, 6).
    ``sigma_v``: gyro angle random walk, rad/s/sqrt(Hz); ``sigma_u``: bias random walk,
    rad/s^(3/2); ``gate``: the innovation-gating threshold on the normalised innovation squared
    (default: chi-square 2 dof at 0.9999).

    ``colored_sigma_rad``: the state is augmented by a time-correlated error ``c`` (3, body
    frame, rad) of one vector measurement (measurement noise coloured in time, handled by
    state augmentation: Bryson & Henrikson 1968; Gelb, Applied Optimal Estimation, 1974,
    sec. 4.5): a first-order Gauss-Markov process of standard deviation ``colored_sigma_rad``
    per axis and correlation time ``tau_s`` (given to :meth:`predict`), fused by
    ``update_vector(..., colored=True)``, which then reads b_meas = b_true + c + white noise.
    A white-noise filter would average the correlated error over many updates as if it were
    independent and grow overconfident; the augmented filter carries it, so both the
    innovations (NIS) and the attitude errors (NEES) keep their chi-square means. ``P`` is then
    (9, 9); :attr:`colored` holds c's estimate.
    """

    def __init__(self, q0_ref_from_body, bias0_rad_s, P0, *, sigma_v, sigma_u, gate=CHI2_2DOF_GATE_99_99,
                 colored_sigma_rad=None):
        self.q = _unit(np.asarray(q0_ref_from_body, dtype=float).reshape(4))
        self.bias = np.asarray(bias0_rad_s, dtype=float).reshape(3).copy()
        P = np.asarray(P0, dtype=float).reshape(6, 6).copy()
        self.sigma_v, self.sigma_u, self.gate = float(sigma_v), float(sigma_u), float(gate)
        self.colored_sigma = None if colored_sigma_rad is None else float(colored_sigma_rad)
        if self.colored_sigma is not None:
            if not (np.isfinite(self.colored_sigma) and self.colored_sigma > 0):
                raise ValueError(f"colored_sigma_rad must be a positive angle in rad, got {colored_sigma_rad}")
            P = np.block([[P, np.zeros((6, 3))], [np.zeros((3, 6)), self.colored_sigma ** 2 * np.eye(3)]])
        self.P = P
        self.colored = np.zeros(3)
        self.last_nis = np.nan

    @property
    def R_ref_from_body(self):
        return quat_to_dcm(self.q)

    def predict(self, omega_meas_rad_s, dt_s, tau_s=None):
        """Propagate over ``dt_s`` with the gyro's mean rate over the step (body frame, rad/s).

        ``tau_s``: the correlation time of the coloured measurement error (needed with
        ``colored_sigma_rad``): c decays by phi = exp(-dt/tau) and gains variance sigma^2 (1 - phi^2).
        """
        w = np.asarray(omega_meas_rad_s, dtype=float) - self.bias
        dq = rotvec_to_quat(w * dt_s)
        self.q = _unit(quat_mul(self.q, dq))
        # Transition of the body-frame error: dtheta' = -[w x] dtheta - db (exact rotation for the first block).
        m = self.P.shape[0]
        Phi = np.eye(m)
        Phi[:3, :3] = quat_to_dcm(dq).T
        Phi[:3, 3:6] = -np.eye(3) * dt_s
        sv2, su2 = self.sigma_v ** 2, self.sigma_u ** 2
        Q = np.zeros((m, m))
        Q[:3, :3] = (sv2 * dt_s + su2 * dt_s ** 3 / 3.0) * np.eye(3)
        Q[:3, 3:6] = Q[3:6, :3] = -(su2 * dt_s ** 2 / 2.0) * np.eye(3)
        Q[3:6, 3:6] = su2 * dt_s * np.eye(3)
        if self.colored_sigma is not None:
            if tau_s is None or not (tau_s > 0):
                raise ValueError(f"a filter with a coloured measurement error needs its correlation time tau_s > 0, "
                                 f"got {tau_s}")
            phi = float(np.exp(-dt_s / tau_s))
            Phi[6:, 6:] = phi * np.eye(3)
            Q[6:, 6:] = self.colored_sigma ** 2 * (1.0 - phi * phi) * np.eye(3)
            self.colored = phi * self.colored
        self.P = Phi @ self.P @ Phi.T + Q

    def update_vector(self, b_meas_body, r_ref, sigma_rad, colored=False):
        """Fuse one unit-vector measurement; return True if accepted by the innovation gate.

        Only the two components perpendicular to the predicted vector carry attitude
        information (a unit vector has two degrees of freedom; the component along it is
        second order in the error, cos(angle) - 1, and would make a large but correct
        innovation look like an outlier): the update uses those two, with noise sigma^2 each
        (Shuster's QUEST measurement model, M&C eq. 5.31, restricted to its range).
        ``colored``: the measurement carries the augmented coloured error c besides its white
        noise ``sigma_rad`` (b_meas = b_true + c_perp). :attr:`last_nis` holds the normalised
        innovation squared (2 dof) of the last call.
        """
        if colored and self.colored_sigma is None:
            raise ValueError("colored=True needs a filter made with colored_sigma_rad")
        b_meas = _unit(b_meas_body)
        b_pred = self.R_ref_from_body.T @ _unit(r_ref)
        # An orthonormal basis (e1, e2) of the plane perpendicular to b_pred.
        helper = np.eye(3)[int(np.argmin(np.abs(b_pred)))]
        e1 = _unit(np.cross(b_pred, helper))
        E = np.stack([e1, np.cross(b_pred, e1)])             # (2, 3)
        m = self.P.shape[0]
        H = np.zeros((2, m))
        H[:, :3] = E @ _skew(b_pred)
        nu = E @ b_meas
        if colored:
            H[:, 6:] = E
            nu = nu - E @ self.colored
        S = H @ self.P @ H.T + (sigma_rad ** 2) * np.eye(2)
        nis = float(nu @ np.linalg.solve(S, nu))
        self.last_nis = nis
        if not np.isfinite(nis) or nis > self.gate:
            return False
        K = np.linalg.solve(S, H @ self.P).T
        dx = K @ nu
        I_KH = np.eye(m) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + (sigma_rad ** 2) * K @ K.T     # Joseph form
        self.P = 0.5 * (self.P + self.P.T)
        self.q = _unit(quat_mul(self.q, rotvec_to_quat(dx[:3])))
        self.bias = self.bias + dx[3:6]
        if m > 6:
            self.colored = self.colored + dx[6:]
        return True


# ---- metrics -----------------------------------------------------------------------------------------
def attitude_error_body(q_est_ref_from_body, q_true_ref_from_body):
    """Return the attitude error rotation vectors (N, 3), rad, body frame: R_true = R_est Exp(e)."""
    dq = quat_mul(_conj(np.atleast_2d(q_est_ref_from_body)), np.atleast_2d(q_true_ref_from_body))
    dq = np.where(dq[:, :1] < 0, -dq, dq)
    vn = np.linalg.norm(dq[:, 1:], axis=1)
    ang = 2.0 * np.arctan2(vn, dq[:, 0])
    return dq[:, 1:] * np.where(vn > 0, ang / np.where(vn > 0, vn, 1.0), 2.0)[:, None]


def nees(error_state, P):
    """Return the normalised estimation error squared (N,) of errors (N, n) with covariances (N, n, n)."""
    e = np.asarray(error_state, dtype=float)
    return np.einsum("ni,ni->n", e, np.linalg.solve(P, e[..., None])[..., 0])


def time_to_converge_s(t_s, error_deg, threshold_deg):
    """Return the first time after which ``error_deg`` stays at or below ``threshold_deg`` (NaN: never)."""
    e = np.asarray(error_deg, dtype=float)
    above = np.flatnonzero(~(e <= threshold_deg))
    if above.size == 0:
        return float(t_s[0])
    if above[-1] == e.size - 1:
        return float("nan")
    return float(t_s[above[-1] + 1])
