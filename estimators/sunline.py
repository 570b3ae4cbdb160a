"""Sun-line filters: an EKF and a UKF of the Sun vector and the body rate (Basilisk sunlineEKF / sunlineSuKF).

State ``x = (s, omega)``, six components, body frame: ``s`` the Sun vector in units of the
normal-Sun reading (|s| ~ 1; left free, as Basilisk's ``d``, so a common scale error of the
diodes does not bias its direction) and ``omega`` the body rate (rad/s).

Dynamics (Sun fixed in inertial space over a step, constant body rate plus a random walk):

    ds/dt = -omega x s,      d omega/dt = w_omega,   E[w_omega w_omega^T] = q_omega I delta(t)   (1)

propagated exactly over a step dt as the rotation of ``s`` by the angle -|omega| dt about
``omega`` (Rodrigues). Unlike Basilisk's sunlineEKF (state s and ds/dt) the rate itself is the
state, as in sunlineSuKF's switch formulation: its component along ``s`` is observed only
through the rotation of ``s`` over time (constant rate), the other two at once.
Discrete process noise of (1) to second order in dt, with ``[s x]`` the cross-product matrix:

    Q_ww = q_omega dt I,  Q_sw = q_omega dt^2 / 2 [s x],  Q_ss = q_omega dt^3 / 3 [s x][s x]^T + q_s dt I   (2)

Measurement of diode k (Basilisk sunlineEKF, ``G_i = n_i . d``), normalised by E_S0:

    y_k = n_k . s + v_k,   v_k ~ N(0, sigma_k^2),                                        (3)

used only for diodes whose reading is at least cos(FOV) ("they see the Sun", thesis sec.
4.3.1, Basilisk's ``sensorUseThresh``). Optional gyro: ``y_g = omega + v_g``.

Innovation test: with S = H P H^T + R, a diode whose normalised innovation
|nu_k| / sqrt(S_kk) exceeds ``gate_sigma`` is left out of that step's update (a faulty or
Earth-lit diode), the others update the state; ``rejected`` records it.

Everything is a pure function of arrays; :class:`SunlineEKF` and :class:`SunlineUKF` hold the
state (filterpy style: ``predict(dt)``, ``update(y, gyro_rad_s=None)``), and
:func:`run_sunline_filter` runs one over a time series.
"""
import numpy as np

STATE_DIM = 6


def _cross_matrix(v):
    """Return [v x] (..., 3, 3) with [v x] a = v x a."""
    v = np.asarray(v, dtype=float)
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def propagate_state(x, dt_s):
    """Return the state(s) (..., 6) after dt_s seconds of eq. (1) without noise: s rotated by -|omega| dt."""
    x = np.asarray(x, dtype=float)
    s, w = x[..., :3], x[..., 3:]
    rate = np.linalg.norm(w, axis=-1, keepdims=True)
    angle = rate * dt_s
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(rate > 0, w / np.where(rate > 0, rate, 1.0), 0.0)
    c, sn = np.cos(angle), np.sin(angle)
    # rotation by -angle about axis: s cos - (axis x s) sin + axis (axis . s)(1 - cos)
    s_new = s * c - np.cross(axis, s) * sn + axis * np.sum(axis * s, axis=-1, keepdims=True) * (1.0 - c)
    return np.concatenate([s_new, w], axis=-1)


def transition_matrix(x, dt_s, eps=1e-7):
    """Return the Jacobian (6, 6) of :func:`propagate_state` at x (central differences, exact to ~1e-9)."""
    x = np.asarray(x, dtype=float)
    pert = np.eye(STATE_DIM) * eps
    fp = propagate_state(x[None, :] + pert, dt_s)
    fm = propagate_state(x[None, :] - pert, dt_s)
    return ((fp - fm) / (2.0 * eps)).T


def process_noise(x, dt_s, q_rate, q_sun):
    """Return the discrete process noise Q (6, 6) of eq. (2) at state x for spectral densities
    ``q_rate`` (rad^2/s^3) and ``q_sun`` (1/s, normalised Sun-vector units)."""
    sx = _cross_matrix(np.asarray(x, dtype=float)[:3])
    q = np.zeros((STATE_DIM, STATE_DIM))
    q[:3, :3] = q_rate * dt_s ** 3 / 3.0 * sx @ sx.T + q_sun * dt_s * np.eye(3)
    q[:3, 3:] = q_rate * dt_s ** 2 / 2.0 * sx
    q[3:, :3] = q[:3, 3:].T
    q[3:, 3:] = q_rate * dt_s * np.eye(3)
    return q


def select_sun_diodes(y, fov_deg, live=None, use_threshold=0.0):
    """Return the mask (K,) of diodes whose normalised reading y (K,) is finite (and live) and at least
    max(cos(FOV), use_threshold) (Basilisk's ``sensorUseThresh``)."""
    y = np.asarray(y, dtype=float)
    sel = np.isfinite(y) & (y >= max(np.cos(np.radians(fov_deg)), use_threshold))
    if live is not None:
        sel &= np.asarray(live, bool)
    return sel


def _gate(nu, s_diag, gate_sigma):
    return np.abs(nu) <= gate_sigma * np.sqrt(s_diag)


def kalman_update(x, P, y, h, r_diag, gate_sigma=np.inf):
    """Return (x, P, accepted (M,), nis (M,)) after the linear-measurement update y = h x + v (Joseph form).

    ``h`` (M, 6), ``y`` (M,), ``r_diag`` (M,) measurement variances. Components whose normalised
    innovation exceeds ``gate_sigma`` are rejected first (``accepted`` False) and the update uses
    the rest. ``nis`` is nu_k^2 / S_kk of every component before the update.
    """
    nu = y - h @ x
    s = h @ P @ h.T + np.diag(r_diag)
    sd = np.diag(s)
    nis = nu * nu / sd
    acc = _gate(nu, sd, gate_sigma)
    if acc.any():
        ha, nua, ra = h[acc], nu[acc], r_diag[acc]
        sa = s[np.ix_(acc, acc)]
        k = np.linalg.solve(sa, ha @ P).T
        ikh = np.eye(STATE_DIM) - k @ ha
        x = x + k @ nua
        P = ikh @ P @ ikh.T + (k * ra) @ k.T
    return x, 0.5 * (P + P.T), acc, nis


def ekf_predict(x, P, dt_s, q_rate, q_sun):
    """Return (x, P) propagated by dt_s (eq. 1), P with the Jacobian of :func:`transition_matrix` and Q of eq. 2."""
    f = transition_matrix(x, dt_s)
    return propagate_state(x, dt_s), f @ P @ f.T + process_noise(x, dt_s, q_rate, q_sun)


def measurement_matrix(normals, sel):
    """Return H (M, 6) of eq. (3) for the selected diodes: rows (n_k, 0, 0, 0)."""
    n = np.asarray(normals, dtype=float)[np.asarray(sel, bool)]
    return np.hstack([n, np.zeros_like(n)])


def sigma_points(x, P, alpha=1.0, beta=2.0, kappa=0.0):
    """Return (points (2n+1, n), weights_mean, weights_cov) of the scaled unscented transform.

    lambda = alpha^2 (n + kappa) - n; points x, x +- columns of the Cholesky factor of
    (n + lambda) P (Julier & Uhlmann; Wan & van der Merwe 2000). The defaults (alpha 1, kappa 0)
    give lambda = 0: mean weights 1/(2n) on the 2n outer points and 0 on the centre, all
    covariance weights >= 0, so the predicted covariance stays positive semidefinite.
    """
    n = x.size
    lam = alpha ** 2 * (n + kappa) - n
    root = np.linalg.cholesky((n + lam) * P)
    pts = np.vstack([x, x + root.T, x - root.T])
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + (1.0 - alpha ** 2 + beta)
    return pts, wm, wc


def ukf_predict(x, P, dt_s, q_rate, q_sun):
    """Return (x, P) propagated by dt_s through the unscented transform of eq. (1) plus Q of eq. (2)."""
    pts, wm, wc = sigma_points(x, P)
    prop = propagate_state(pts, dt_s)
    xm = wm @ prop
    d = prop - xm
    return xm, (wc[:, None] * d).T @ d + process_noise(xm, dt_s, q_rate, q_sun)


def ukf_update(x, P, y, normals_sel, r_diag, gate_sigma=np.inf):
    """Return (x, P, accepted, nis): the unscented measurement update of eq. (3) for selected normals (M, 3).

    The measurement is predicted from the sigma points (2n+1 of them); the cross covariance
    gives the gain. Gating as in :func:`kalman_update`.
    """
    pts, wm, wc = sigma_points(x, P)
    z = pts[:, :3] @ np.asarray(normals_sel, dtype=float).T        # (2n+1, M)
    zm = wm @ z
    dz, dx = z - zm, pts - x
    s = (wc[:, None] * dz).T @ dz + np.diag(r_diag)
    pxz = (wc[:, None] * dx).T @ dz
    nu = y - zm
    sd = np.diag(s)
    nis = nu * nu / sd
    acc = _gate(nu, sd, gate_sigma)
    if acc.any():
        sa = s[np.ix_(acc, acc)]
        k = np.linalg.solve(sa, pxz[:, acc].T).T
        x = x + k @ nu[acc]
        P = P - k @ sa @ k.T
    return x, 0.5 * (P + P.T), acc, nis


class _SunlineFilter:
    """Shared state and bookkeeping of the two filters (see the module docstring for the model).

    Parameters
    ----------
    normals : (K, 3) diode normals, body frame (the rows of H, eq. 3).
    fov_deg : the diodes' FOV; readings >= cos(FOV) are used (:func:`select_sun_diodes`).
    use_threshold : a floor on the readings used (normalised), Basilisk's ``sensorUseThresh``; at
        FOV 90 cos(FOV) = 0 lets a dark diode's noise in, where eq. (3) would predict n . s < 0
        for a reading that cannot go below 0. Basilisk's scenarios use 5 sigma of the noise.
    x0, P0 : initial state (6,) = (s, omega [rad/s]) and covariance (6, 6).
    sigma_meas : scalar or (K,), standard deviation of each reading (normalised units): noise,
        quantisation and whatever the model n . s leaves out (the Earth's light).
    q_rate : spectral density of the rate random walk (rad^2/s^3, eq. 2). The default 1e-13 lets the
        rate wander by 0.001 deg/s per sqrt(hour): a near-constant tumble, with enough process noise
        to keep the rate covariance from collapsing.
    q_sun : extra Sun-vector process noise (1/s, eq. 2), 0 by default.
    gate_sigma : the innovation test's threshold in standard deviations (5: a 5.7e-7 false-alarm
        rate per reading for Gaussian innovations).
    gyro_sigma_rad_s : the gyro's white-noise standard deviation (rad/s), when a gyro is given to ``update``.
    live : (K,) bool, diodes known to work (others never used).
    """

    def __init__(self, normals, *, fov_deg, x0, P0, sigma_meas, q_rate=1e-13, q_sun=0.0, gate_sigma=5.0,
                 gyro_sigma_rad_s=None, live=None, use_threshold=0.0):
        self.normals = np.asarray(normals, dtype=float)
        if self.normals.ndim != 2 or self.normals.shape[1] != 3:
            raise ValueError(f"normals must be (K, 3) unit vectors in the body frame, got shape {self.normals.shape}")
        k = self.normals.shape[0]
        if not 0 < fov_deg <= 90:
            raise ValueError(f"fov_deg must lie in (0, 90], got {fov_deg}")
        self.fov_deg = float(fov_deg)
        if not (np.isfinite(use_threshold) and use_threshold >= 0):
            raise ValueError(f"use_threshold must be a reading >= 0 (normalised), got {use_threshold}")
        self.use_threshold = float(use_threshold)
        self.x = np.array(x0, dtype=float).reshape(STATE_DIM)
        self.P = np.array(P0, dtype=float).reshape(STATE_DIM, STATE_DIM)
        if not np.all(np.isfinite(self.P)) or np.any(np.linalg.eigvalsh(0.5 * (self.P + self.P.T)) <= 0):
            raise ValueError("P0 must be a finite symmetric positive-definite (6, 6) covariance")
        sig = np.broadcast_to(np.asarray(sigma_meas, dtype=float), (k,))
        if not np.all(np.isfinite(sig) & (sig > 0)):
            raise ValueError("sigma_meas must be > 0 (normalised units): the diodes' noise, quantisation and "
                             "unmodelled Earth light")
        self.r_diag = sig ** 2
        for name, v in (("q_rate", q_rate), ("q_sun", q_sun)):
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a spectral density >= 0, got {v}")
        if not gate_sigma > 0:
            raise ValueError(f"gate_sigma must be > 0 (in standard deviations of the innovation), got {gate_sigma}")
        self.q_rate, self.q_sun, self.gate_sigma = float(q_rate), float(q_sun), float(gate_sigma)
        if gyro_sigma_rad_s is not None and not gyro_sigma_rad_s > 0:
            raise ValueError(f"gyro_sigma_rad_s must be > 0 rad/s, got {gyro_sigma_rad_s}")
        self.gyro_sigma = gyro_sigma_rad_s
        self.live = None if live is None else np.asarray(live, bool)
        self.used = np.zeros(k, bool)
        self.rejected = np.zeros(k, bool)

    def update(self, y, gyro_rad_s=None):
        """Update with the normalised diode readings y (K,) (and a gyro rate (3,) rad/s when given)."""
        y = np.asarray(y, dtype=float)
        sel = select_sun_diodes(y, self.fov_deg, self.live, self.use_threshold)
        self.used = np.zeros(y.size, bool)
        self.rejected = np.zeros(y.size, bool)
        if sel.any():
            self.x, self.P, acc, _ = self._measurement_update(self.x, self.P, y[sel], sel)
            idx = np.flatnonzero(sel)
            self.used[idx[acc]] = True
            self.rejected[idx[~acc]] = True
        if gyro_rad_s is not None and self.gyro_sigma is not None and np.all(np.isfinite(gyro_rad_s)):
            h = np.hstack([np.zeros((3, 3)), np.eye(3)])
            self.x, self.P, _, _ = kalman_update(self.x, self.P, np.asarray(gyro_rad_s, float), h,
                                                 np.full(3, self.gyro_sigma ** 2))
        return self

    @property
    def sun_dir_body(self):
        """Return the unit Sun vector estimate (3,), body frame."""
        return self.x[:3] / np.linalg.norm(self.x[:3])

    @property
    def rate_rad_s(self):
        """Return the body-rate estimate (3,), rad/s, body frame."""
        return self.x[3:].copy()


class SunlineEKF(_SunlineFilter):
    """Extended Kalman filter of (s, omega): eqs. (1)-(3); ``predict(dt)``, ``update(y, gyro_rad_s)``."""

    def predict(self, dt_s):
        self.x, self.P = ekf_predict(self.x, self.P, dt_s, self.q_rate, self.q_sun)
        return self

    def _measurement_update(self, x, P, y, sel):
        return kalman_update(x, P, y, measurement_matrix(self.normals, sel), self.r_diag[sel], self.gate_sigma)


class SunlineUKF(_SunlineFilter):
    """Unscented Kalman filter of (s, omega): eqs. (1)-(3) through sigma points (Basilisk's sunlineSuKF family)."""

    def predict(self, dt_s):
        self.x, self.P = ukf_predict(self.x, self.P, dt_s, self.q_rate, self.q_sun)
        return self

    def _measurement_update(self, x, P, y, sel):
        return ukf_update(x, P, y, self.normals[sel], self.r_diag[sel], self.gate_sigma)


FILTERS = {"ekf": SunlineEKF, "ukf": SunlineUKF}


def run_sunline_filter(kind, y, normals, t_s, *, fov_deg, x0, P0, sigma_meas, gyro_rad_s=None, update_mask=None,
                       **kw):
    """Return the filter's history over a time series: a dict of arrays with time leading.

    ``kind`` 'ekf' or 'ukf'; ``y`` (N, K) normalised diode readings (E_p / E_S0, NaN = missing);
    ``t_s`` (N,) seconds; ``gyro_rad_s`` (N, 3) or None; ``update_mask`` (N,) bool or None: epochs whose
    diode readings update the filter (e.g. False in eclipse, where a diode lit by the Earth alone would
    pass the reading threshold; the gyro still updates); other keywords go to the filter class.
    Returns ``sun_dir_body`` (N, 3) unit, ``state`` (N, 6), ``P`` (N, 6, 6), ``rate_rad_s``
    (N, 3), ``used`` and ``rejected`` (N, K) bool (diodes taken / excluded by the innovation
    test at each step). The first sample updates the initial state without a prediction.
    """
    if kind not in FILTERS:
        raise ValueError(f"unknown sun-line filter {kind!r}; use one of {', '.join(FILTERS)}")
    y = np.asarray(y, dtype=float)
    t = np.asarray(t_s, dtype=float)
    if y.ndim != 2 or t.shape != (y.shape[0],):
        raise ValueError(f"y must be (N, K) and t_s (N,), got {y.shape} and {t.shape}")
    if gyro_rad_s is not None:
        gyro_rad_s = np.asarray(gyro_rad_s, dtype=float)
        if gyro_rad_s.shape != (y.shape[0], 3):
            raise ValueError(f"gyro_rad_s must be (N, 3) rad/s, got shape {gyro_rad_s.shape}")
    f = FILTERS[kind](normals, fov_deg=fov_deg, x0=x0, P0=P0, sigma_meas=sigma_meas, **kw)
    n, k = y.shape
    if update_mask is not None:
        update_mask = np.asarray(update_mask, bool)
        if update_mask.shape != (n,):
            raise ValueError(f"update_mask must be (N,) = ({n},) bool, got shape {update_mask.shape}")
        y = np.where(update_mask[:, None], y, np.nan)
    state = np.empty((n, STATE_DIM))
    cov = np.empty((n, STATE_DIM, STATE_DIM))
    used = np.zeros((n, k), bool)
    rejected = np.zeros((n, k), bool)
    for i in range(n):
        if i > 0:
            f.predict(t[i] - t[i - 1])
        f.update(y[i], None if gyro_rad_s is None else gyro_rad_s[i])
        state[i], cov[i], used[i], rejected[i] = f.x, f.P, f.used, f.rejected
    s = state[:, :3] / np.linalg.norm(state[:, :3], axis=1, keepdims=True)
    return {"sun_dir_body": s, "state": state, "P": cov, "rate_rad_s": state[:, 3:].copy(),
            "used": used, "rejected": rejected}


def nees(state, P, state_true):
    """Return the normalised estimation error squared (N,): e^T P^-1 e with e = state - state_true (N, 6)."""
    e = np.asarray(state, float) - np.asarray(state_true, float)
    return np.einsum("ni,ni->n", e, np.linalg.solve(P, e[:, :, None])[:, :, 0])


def rate_from_sun_vectors(sun_dir_body, t_s):
    """Return the body-rate component perpendicular to the Sun (N, 3), rad/s, from successive unit Sun vectors.

    With ds/dt = -omega x s (eq. 1) and |s| = 1, omega_perp = omega - (omega . s) s = (ds/dt) x s.
    ds/dt by central differences (one-sided at the ends and next to invalid estimates);
    NaN where a neighbour is NaN on both sides.
    """
    s = np.asarray(sun_dir_body, dtype=float)
    t = np.asarray(t_s, dtype=float)
    if s.ndim != 2 or s.shape[1] != 3 or t.shape != (s.shape[0],):
        raise ValueError(f"sun_dir_body must be (N, 3) and t_s (N,), got {s.shape} and {t.shape}")
    n = s.shape[0]
    ds = np.full_like(s, np.nan)
    if n >= 2:
        fwd = (s[1:] - s[:-1]) / (t[1:] - t[:-1])[:, None]        # (N-1, 3) between i and i+1
        central = np.full_like(s, np.nan)
        central[1:-1] = (s[2:] - s[:-2]) / (t[2:] - t[:-2])[:, None]
        ds = central
        back = np.vstack([np.full((1, 3), np.nan), fwd])            # derivative between i-1 and i
        ahead = np.vstack([fwd, np.full((1, 3), np.nan)])           # between i and i+1
        ds = np.where(np.isfinite(ds), ds, ahead)
        ds = np.where(np.isfinite(ds), ds, back)
    return np.cross(ds, s)


def perpendicular_rate(rate_rad_s, sun_dir_body):
    """Return the part (N, 3) of body rates (N, 3) perpendicular to unit Sun vectors (N, 3): the observable part."""
    w = np.asarray(rate_rad_s, float)
    s = np.asarray(sun_dir_body, float)
    return w - np.sum(w * s, axis=1, keepdims=True) * s
