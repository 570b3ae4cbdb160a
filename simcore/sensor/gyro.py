"""MEMS rate gyroscope model (thesis sec. 2.5, eq. 2.35) and the thesis' candidate parts (figs. 3.1-3.2).

One raw sample of axis rates, rad/s, body frame (thesis eq. 2.35, Grewal & Andrews eq. 2.36
without the g- and second-order terms, which the thesis judges minuscule in orbit):

    w_raw = Q[(I + dS + M) w + b_0 + c_T (T - 25 degC) + b_GM + b_RRW + n]

- ``n``: white rate noise (angle random walk) of density N from the data sheet
  ("rate noise density"), per raw sample N sqrt(f_s) at the sample rate f_s;
- ``b_GM``: bias instability as a first-order Gauss-Markov process (thesis sec. 2.5.3,
  after Nassar 2005) with correlation time ``bias_corr_time_s`` and a standard deviation
  chosen so that its Allan deviation peaks at the data sheet's bias instability
  (:func:`gm_sigma_for_bias_instability`);
- ``b_RRW``: rate random walk of coefficient K (none of the parts gives one: 0 unless set);
- ``b_0``: turn-on bias, ``c_T``: bias temperature coefficient, ``dS``: scale-factor
  error (diagonal), ``M``: misalignment / cross-axis coupling (off-diagonal): each drawn
  once per seed per axis from N(0, (data-sheet value / 3)^2), the data sheets' Max/Min being
  3 sigma (thesis sec. 3.1.1);
- ``T``: the gyro's temperature, e.g. :func:`board_temperature_k` from the eclipse history;
- ``Q``: quantisation to the resolution (deg/s per LSB on the smallest range).

The gyro samples at ``sample_rate_hz`` (100 Hz unless set); the on-board software averages
the raw samples within each estimator step, which is what :meth:`GyroModel.measure`
returns at the run's epochs (the true rate is held at its epoch value within a step).

The Allan variance closed forms used to check the model (IEEE Std 952-1997, annex C;
El-Sheimy et al. 2008): white rate noise N^2 / tau; rate random walk K^2 tau / 3;
first-order Gauss-Markov of variance s^2 and correlation time T_c:
(q^2 T_c^2 / tau) [1 - T_c / (2 tau) (3 - 4 e^(-tau/T_c) + e^(-2 tau/T_c))], q^2 = 2 s^2 / T_c.
"""
from dataclasses import dataclass

import numpy as np

from simcore.sensor.parts import PartSpec, find_part, load_parts

DEG = np.pi / 180.0
T_REF_K = 298.15                     # data-sheet reference temperature, 25 degC (thesis sec. 3.1.1)
DEFAULT_SAMPLE_RATE_HZ = 100.0       # on-board gyro sampling (the parts offer 100 Hz .. 2 kHz output rates)
DEFAULT_BIAS_CORR_TIME_S = 300.0     # Gauss-Markov correlation time of the bias instability (no data sheet gives it)

# The board's temperature cycle (thesis sec. 2.2, Compass-1 flight data, Scholz et al. 2010): inside
# electronics between about -5 and 25 degC over an orbit; the ADCS board fell 20 -> 0 degC in eclipse,
# at most 0.014 degC/s. A first-order lag toward 25 degC in sunlight and -5 degC in eclipse with
# tau = 30 K / 0.014 K/s ~ 2100 s reproduces that largest gradient.
THERMAL_SUNLIT_K = 298.15
THERMAL_ECLIPSE_K = 268.15
THERMAL_TAU_S = 2100.0

# On-board temperature compensation of the bias (the thesis' recommendation, sec. 3.1.2 and 5.1: a
# polynomial in the gyro's own temperature reading, calibrated on ground) leaves a fraction of the
# temperature effect. Niu et al. (2013), as cited in thesis sec. 2.5.1-2.5.2, cut the temperature-driven
# scale-factor error from 1.1 % to 0.15 % (0.14) and the misalignment from 0.6 % to 0.13 % (0.22) with
# third-order polynomials; the larger ratio, 0.22, is used for the bias temperature coefficient.
THERMAL_COMPENSATION_RESIDUAL = 0.22


@dataclass(frozen=True)
class GyroSpec(PartSpec):
    """Data-sheet values of a three-axis rate gyro, SI units (rad/s, rad/s/sqrt(Hz), K)."""

    noise_density_rad_s_rthz: float
    bias_instability_rad_s: float = 0.0
    bias_level_rad_s: float = 0.0          # turn-on bias, 3 sigma
    bias_temp_coeff_rad_s_k: float = 0.0   # 3 sigma
    scale_factor_error: float = 0.0        # fraction, 3 sigma
    cross_axis: float = 0.0                # fraction, 3 sigma
    resolution_rad_s: float = 0.0          # one LSB; 0 = no quantisation
    rate_random_walk_rad_s32: float = 0.0  # K, rad/s^(3/2)
    assumed: str = ""
    recommended: bool = False
    flown: bool = False


_UNITS = {
    "noise_density_deg_s_rthz": ("noise_density_rad_s_rthz", DEG),
    "bias_instability_deg_h": ("bias_instability_rad_s", DEG / 3600.0),
    "bias_level_deg_s": ("bias_level_rad_s", DEG),
    "bias_temp_coeff_deg_s_k": ("bias_temp_coeff_rad_s_k", DEG),
    "scale_factor_error_pct": ("scale_factor_error", 0.01),
    "cross_axis_pct": ("cross_axis", 0.01),
    "resolution_deg_s_lsb": ("resolution_rad_s", DEG),
    "rate_random_walk_deg_s32": ("rate_random_walk_rad_s32", DEG),
}


def load_gyros():
    """Return {name: GyroSpec} of the shipped table ``simcore/data/gyros.toml``."""
    return load_parts("gyros.toml", GyroSpec, _UNITS)


def thermally_compensated(spec, residual=THERMAL_COMPENSATION_RESIDUAL):
    """Return the GyroSpec seen after on-board temperature compensation: the bias temperature
    coefficient scaled by ``residual`` (the uncompensated fraction; see THERMAL_COMPENSATION_RESIDUAL)."""
    from dataclasses import replace
    if not 0 <= residual <= 1:
        raise ValueError(f"the compensation residual must be a fraction in [0, 1], got {residual}")
    return replace(spec, name=f"{spec.name} (temperature-compensated)",
                   bias_temp_coeff_rad_s_k=spec.bias_temp_coeff_rad_s_k * residual)


def gyro_spec(name):
    """Return the GyroSpec called ``name`` (case-insensitive), or raise a one-line error naming close matches."""
    return find_part(name, load_gyros(), "gyro")


# ---- Allan variance: closed forms and the estimator ----------------------------------------------
def gm_allan_variance(tau_s, sigma_b, corr_time_s):
    """Return the Allan variance (rad/s)^2 at ``tau_s`` of a first-order Gauss-Markov rate bias (IEEE 952)."""
    x = np.asarray(tau_s, dtype=float) / corr_time_s
    q2 = 2.0 * sigma_b ** 2 / corr_time_s
    return q2 * corr_time_s ** 2 / (x * corr_time_s) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))


def gm_sigma_for_bias_instability(bias_instability_rad_s, corr_time_s):
    """Return the Gauss-Markov sigma (rad/s) whose Allan deviation peaks at ``bias_instability_rad_s``."""
    x = np.geomspace(1e-2, 1e2, 4001)
    peak = np.sqrt(gm_allan_variance(x * corr_time_s, 1.0, corr_time_s).max())
    return float(bias_instability_rad_s) / peak


def allan_variance_model(tau_s, spec, bias_corr_time_s=DEFAULT_BIAS_CORR_TIME_S):
    """Return the model's Allan variance (rad/s)^2 at ``tau_s``: ARW + rate random walk + Gauss-Markov bias."""
    tau = np.asarray(tau_s, dtype=float)
    out = spec.noise_density_rad_s_rthz ** 2 / tau + spec.rate_random_walk_rad_s32 ** 2 * tau / 3.0
    if spec.bias_instability_rad_s > 0:
        s = gm_sigma_for_bias_instability(spec.bias_instability_rad_s, bias_corr_time_s)
        out = out + gm_allan_variance(tau, s, bias_corr_time_s)
    return out


def allan_deviation(rate, dt_s, m):
    """Return the overlapping Allan deviation (len(m),) of a rate series (N,) sampled every ``dt_s``,
    at cluster sizes ``m`` (tau = m dt_s); IEEE Std 952 eq. for the overlapping estimator."""
    y = np.asarray(rate, dtype=float)
    theta = np.concatenate([[0.0], np.cumsum(y) * dt_s])
    out = []
    for mm in np.atleast_1d(m).astype(int):
        tau = mm * dt_s
        d = theta[2 * mm:] - 2.0 * theta[mm:-mm] + theta[:-2 * mm]
        out.append(np.sqrt(np.mean(d ** 2) / (2.0 * tau ** 2)))
    return np.array(out)


# ---- temperature --------------------------------------------------------------------------------
def board_temperature_k(t_s, illumination, *, sunlit_k=THERMAL_SUNLIT_K, eclipse_k=THERMAL_ECLIPSE_K,
                        tau_s=THERMAL_TAU_S, t0_k=None):
    """Return the gyro board temperature (N,), K, along a run from its eclipse history.

    First-order lag toward ``sunlit_k`` + (``eclipse_k`` - ``sunlit_k``)(1 - illumination),
    integrated exactly for a forcing held over each step. ``illumination`` (N,): visible
    fraction of the solar disc (NaN counts as eclipse). Starts at ``t0_k`` (default: the
    run's mean equilibrium temperature, i.e. the orbit-average, so no start-up transient).
    """
    t = np.asarray(t_s, dtype=float)
    f = np.nan_to_num(np.asarray(illumination, dtype=float), nan=0.0)
    t_eq = eclipse_k + (sunlit_k - eclipse_k) * np.clip(f, 0.0, 1.0)
    temp = np.empty(t.size)
    temp[0] = float(np.mean(t_eq)) if t0_k is None else float(t0_k)
    decay = np.exp(-np.diff(t) / tau_s)
    for i in range(1, t.size):
        temp[i] = t_eq[i - 1] + (temp[i - 1] - t_eq[i - 1]) * decay[i - 1]
    return temp


# ---- the model ----------------------------------------------------------------------------------
class GyroModel:
    """A gyro instance: the data sheet's errors drawn once from ``seed``; :meth:`measure` makes readings.

    ``sample_rate_hz``: raw sampling rate (the readings are averages of the raw samples in
    each step); ``bias_corr_time_s``: correlation time of the bias instability.
    """

    def __init__(self, spec, seed=0, *, sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
                 bias_corr_time_s=DEFAULT_BIAS_CORR_TIME_S):
        self.spec = gyro_spec(spec) if isinstance(spec, str) else spec
        if not sample_rate_hz > 0:
            raise ValueError(f"sample_rate_hz must be > 0, got {sample_rate_hz}")
        self.sample_rate_hz = float(sample_rate_hz)
        self.bias_corr_time_s = float(bias_corr_time_s)
        self.rng = np.random.default_rng(seed)
        s = self.spec
        draw = lambda three_sigma, size=3: self.rng.normal(0.0, three_sigma / 3.0, size)  # noqa: E731
        self.bias_turn_on_rad_s = draw(s.bias_level_rad_s)
        self.bias_temp_coeff_rad_s_k = draw(s.bias_temp_coeff_rad_s_k)
        self.scale_factor = draw(s.scale_factor_error)
        off = draw(s.cross_axis, (3, 3))
        np.fill_diagonal(off, 0.0)
        self.misalignment = off
        self.sigma_gm_rad_s = (gm_sigma_for_bias_instability(s.bias_instability_rad_s, self.bias_corr_time_s)
                               if s.bias_instability_rad_s > 0 else 0.0)

    @property
    def gain_matrix(self):
        """Return (I + dS + M) (3, 3): true body rate -> sensed rate."""
        return np.eye(3) + np.diag(self.scale_factor) + self.misalignment

    def measure(self, t_s, w_true_body_rad_s, temperature_k=None, *, chunk=4096):
        """Return gyro readings (N, 3), rad/s, body frame, at epochs ``t_s`` (N,) evenly spaced.

        Each reading is the mean of the raw samples over the step before the epoch (the
        first: the step after it). ``w_true_body_rad_s`` (N, 3) or (3,); ``temperature_k``
        (N,) or None (25 degC: no temperature bias).
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if t.size < 2:
            raise ValueError("the gyro needs at least two epochs (a step) to sample")
        dt = np.diff(t)
        if not np.allclose(dt, dt[0], rtol=1e-9, atol=1e-9) or not dt[0] > 0:
            raise ValueError("the gyro model needs evenly spaced, increasing epochs")
        dt = float(dt[0])
        w = np.broadcast_to(np.asarray(w_true_body_rad_s, dtype=float), (t.size, 3))
        temp = np.full(t.size, T_REF_K) if temperature_k is None else np.asarray(temperature_k, dtype=float)
        n_raw = max(1, int(round(dt * self.sample_rate_hz)))
        s = self.spec
        # Slow biases, one value per step.
        bias = np.empty((t.size, 3))
        gm = self.rng.normal(0.0, self.sigma_gm_rad_s, 3)
        rrw = np.zeros(3)
        phi = np.exp(-dt / self.bias_corr_time_s)
        gm_step = self.sigma_gm_rad_s * np.sqrt(1.0 - phi ** 2)
        rrw_step = s.rate_random_walk_rad_s32 * np.sqrt(dt)
        draws = self.rng.normal(size=(t.size, 2, 3))
        for i in range(t.size):
            bias[i] = gm + rrw
            gm = phi * gm + gm_step * draws[i, 0]
            rrw = rrw + rrw_step * draws[i, 1]
        bias += self.bias_turn_on_rad_s + self.bias_temp_coeff_rad_s_k * (temp - T_REF_K)[:, None]
        clean = w @ self.gain_matrix.T + bias
        sigma_raw = s.noise_density_rad_s_rthz * np.sqrt(n_raw / dt)
        lsb = s.resolution_rad_s
        out = np.empty((t.size, 3))
        for a in range(0, t.size, chunk):
            b = min(a + chunk, t.size)
            raw = clean[a:b, None, :] + sigma_raw * self.rng.normal(size=(b - a, n_raw, 3))
            if lsb > 0:
                raw = lsb * np.rint(raw / lsb)
            out[a:b] = raw.mean(axis=1)
        return out


def filter_noise(spec, *, dt_s=1.0, bias_corr_time_s=DEFAULT_BIAS_CORR_TIME_S,
                 max_temp_rate_k_s=30.0 / THERMAL_TAU_S, thermal_tau_s=THERMAL_TAU_S):
    """Return (sigma_v, sigma_u, sigma_b0): the MEKF's gyro noise from the data sheet alone.

    sigma_v (rad/s/sqrt(Hz)): the angle random walk N; sigma_u (rad/s^(3/2)): the bias
    random walk that covers the rate random walk, the Gauss-Markov bias instability
    (q^2 = 2 s^2 / T_c) and the thermal drift (3-sigma coefficient / 3 times the largest
    temperature rate, held over the thermal time constant: q = (c dT/dt)^2 tau);
    sigma_b0 (rad/s): the initial bias uncertainty, turn-on bias (3 sigma / 3) and the
    temperature bias over a 15 K offset from 25 degC, added in quadrature.
    """
    s = spec
    q = s.rate_random_walk_rad_s32 ** 2
    if s.bias_instability_rad_s > 0:
        sig = gm_sigma_for_bias_instability(s.bias_instability_rad_s, bias_corr_time_s)
        q += 2.0 * sig ** 2 / bias_corr_time_s
    q += (s.bias_temp_coeff_rad_s_k / 3.0 * max_temp_rate_k_s) ** 2 * thermal_tau_s
    sigma_b0 = np.hypot(s.bias_level_rad_s / 3.0, s.bias_temp_coeff_rad_s_k / 3.0 * 15.0)
    return s.noise_density_rad_s_rthz, float(np.sqrt(q)), float(sigma_b0)
