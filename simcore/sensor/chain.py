"""The photodiode sensor chain: irradiance -> photocurrent -> ADC counts -> irradiance.

Thesis 2.4.1 (eqs. 2.19-2.32), 3.2.2-3.2.3 (eqs. 3.1-3.7) and 4.2 (eqs. 4.13-4.25).

The renderer and the analytic albedo model give the irradiance ``E`` on each
diode in W/m^2 computed with the full solar constant E_sun = 1366.1 W/m^2.
A diode converts only the part of the spectrum it is sensitive to: its
*effective* normal-Sun irradiance is E_S0 (thesis table 3.2.3; 188.1 W/m^2
for the BPW34FS). The thesis scales the Sun input to E_S0 and "the reflected
light is scaled down by the same amount" (sec. 4.2.1), so the photocurrent is

    I_P = R * A * E_S0 * (E / E_sun) * (1 + TC (T - T_ref)) * (1 + delta_k)   (eqs. 3.6, 4.16-4.19)

plus the dark current I_D, plus (optionally) Gaussian shot and Johnson noise
(eqs. 2.26-2.28). A transimpedance amplifier (R_F = 500 ohm, eq. 4.21) and an
ideal 12-bit ADC over -1..1 V, of which 0..1 V = 0 .. 2^11 - 1 counts are used
(eq. 4.24), digitise it; eq. 4.25 turns counts back into the diode's
effective irradiance E_p, so a diode facing the Sun reads E_p ~= E_S0 and the
estimators' threshold E_S0 cos(FOV) (sec. 4.3.1) applies directly.

Choices (the thesis leaves them open):

- Quantiser: round to the nearest count (``np.rint``, halves to even), the
  behaviour of an ideal mid-tread quantiser; the thesis only says "idealized
  12-bit ADC quantizer".
- Saturation: counts are clipped to 0 .. 2^(bits-1) - 1. Negative currents
  (noise on a dark diode) read 0.
- Dead diodes read exactly 0 counts, hence E_p = 0: below every threshold, so
  the estimators see them as "not seeing the Sun". Pass ``live`` to an
  estimator to also keep them out of its albedo fits.
- Eq. 4.25 uses the nominal conversion factor K_R = R * A at T_ref (eq. 3.6):
  the on-board software knows neither the temperature drift nor the per-diode
  scale-factor errors, so those appear as errors in E_p, as they would in flight.
- Counts are returned as float64 holding whole numbers so that NaN (a
  per-sample problem upstream, e.g. a failed render) propagates.
"""
from dataclasses import dataclass

import numpy as np

from simcore.constants import BPW34_AREA_M2, E_SUN_W_M2

Q_E_C = 1.602176634e-19        # elementary charge, SI 2019 exact
K_B_J_K = 1.380649e-23         # Boltzmann constant, SI 2019 exact
T_REF_K = 298.15               # data-sheet reference temperature, 25 degC (thesis 4.2.1: R_max "given for 25")
C_F_FARAD = 1e-9               # feedback capacitor installed with the AD8617 (thesis 4.2.2)


@dataclass(frozen=True)
class PhotodiodeSpec:
    """A photodiode's data-sheet values used by the sensor chain (SI units)."""

    name: str
    responsivity_a_w: float       # peak spectral responsivity R_lambda,max (A/W)
    area_m2: float                # radiant sensitive area A (m^2)
    e_s0_w_m2: float              # effective normal-Sun irradiance E_S0 (W/m^2, thesis table 3.2.3)
    temp_coeff_per_k: float       # temperature coefficient of the photocurrent TC_I (1/K, eq. 2.29)
    dark_current_a: float         # dark current I_D (A)
    shunt_resistance_ohm: float   # shunt resistance R_sh (ohm, eq. 2.28)

    def __post_init__(self):
        for name in ("responsivity_a_w", "area_m2", "e_s0_w_m2", "shunt_resistance_ohm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"diode {self.name!r}: {name} must be a positive finite number, got {v}")
        if not (np.isfinite(self.dark_current_a) and self.dark_current_a >= 0):
            raise ValueError(f"diode {self.name!r}: dark_current_a must be >= 0 A, got {self.dark_current_a}")

    @property
    def k_r_a_per_w_m2(self):
        """Return the nominal conversion factor K_R = R A (A per W/m^2, eq. 3.6 at T_ref)."""
        return self.responsivity_a_w * self.area_m2

    @property
    def i_sun_a(self):
        """Return the photocurrent at normal Sun, I_theta0 = R A E_S0 (A, eqs. 4.16-4.18)."""
        return self.k_r_a_per_w_m2 * self.e_s0_w_m2


# Sources, per value:
#   [T]  the thesis (table 3.2.3 for E_S0; sec. 3.2.3 for R and TC of BPW34FS and SFH2430;
#        eq. 4.18 for the BPW34FS area).
#   [D]  typical data-sheet value, NOT given in the thesis: OSRAM BPW 34 family (2.65 x 2.65 mm chip,
#        7.02 mm^2; dark current 2 nA typ. at V_R = 10 V) and Vishay BPV23F (4.4 mm^2, 2 nA typ.).
#   [A]  assumption where neither gives a value: a responsivity typical of a Si PIN diode near its
#        900 nm peak, and R_sh = 100 Mohm, the geometric middle of the 10 Mohm .. 1000 Mohm range the
#        thesis quotes for silicon PIN diodes (sec. 3.2.3, after the OSI application note).
# The dark current is the reverse-bias data-sheet value; in photovoltaic mode (V_A ~ 0, eq. 2.31)
# it is far smaller, so this is a conservative upper value (2 nA is 0.002 LSB with R_F = 500 ohm).
DIODES = {
    "BPW34FS": PhotodiodeSpec(
        name="BPW34FS",
        responsivity_a_w=0.7,              # [T] sec. 3.2.3 and eq. 4.18
        area_m2=BPW34_AREA_M2,             # [T] eq. 4.18, 7.02 mm^2
        e_s0_w_m2=188.1,                   # [T] table 3.2.3
        temp_coeff_per_k=0.03e-2,          # [T] sec. 3.2.3, 0.03 %/K
        dark_current_a=2e-9,               # [D]
        shunt_resistance_ohm=100e6,        # [A]
    ),
    "SFH2430": PhotodiodeSpec(
        name="SFH2430",
        responsivity_a_w=0.17,             # [T] sec. 3.2.3
        area_m2=BPW34_AREA_M2,             # [D] same package and chip size as the BPW34 (thesis 3.2.3)
        e_s0_w_m2=425.9,                   # [T] table 3.2.3
        temp_coeff_per_k=0.16e-2,          # [T] sec. 3.2.3, 0.16 %/K
        dark_current_a=2e-9,               # [D]
        shunt_resistance_ohm=100e6,        # [A]
    ),
    "BPW34FAS": PhotodiodeSpec(
        name="BPW34FAS",
        responsivity_a_w=0.65,             # [A] Si PIN near 880 nm with a daylight-cut filter
        area_m2=BPW34_AREA_M2,             # [D] BPW 34 chip
        e_s0_w_m2=234.3,                   # [T] table 3.2.3
        temp_coeff_per_k=0.03e-2,          # [A] taken equal to the BPW34FS (same chip, other filter)
        dark_current_a=2e-9,               # [D]
        shunt_resistance_ohm=100e6,        # [A]
    ),
    "BPV23F": PhotodiodeSpec(
        name="BPV23F",
        responsivity_a_w=0.6,              # [A] Si PIN near its 950 nm peak
        area_m2=4.4e-6,                    # [D] Vishay BPV23F, 4.4 mm^2
        e_s0_w_m2=154.1,                   # [T] table 3.2.3
        temp_coeff_per_k=0.1e-2,           # [A] upper end of the 0.03-0.1 %/K range of thesis eq. 2.29
        dark_current_a=2e-9,               # [D]
        shunt_resistance_ohm=100e6,        # [A]
    ),
}


def misaligned_normals(normals, sigma_rad, rng):
    """Return unit diode normals (K, 3), body frame, each rotated by a small random rotation.

    Each normal is turned by the rotation vector ``omega`` with independent
    N(0, sigma_rad^2) components (body frame). Only the part of ``omega``
    perpendicular to the normal moves it, so the angle between the true and
    the misaligned normal is Rayleigh-distributed with scale ``sigma_rad``
    (mean sigma sqrt(pi/2)). Use the result to compute the irradiance
    upstream (renderer / analytic model) while the estimators keep the
    nominal normals.
    """
    n = np.asarray(normals, dtype=float)
    if n.ndim != 2 or n.shape[1] != 3:
        raise ValueError(f"normals must be an array (K, 3) of unit vectors in the body frame, got shape {n.shape}")
    if not np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6):
        raise ValueError("normals must be unit vectors; normalise them before calling misaligned_normals")
    if not (np.isfinite(sigma_rad) and sigma_rad >= 0):
        raise ValueError(f"sigma_rad must be a non-negative angle in radians, got {sigma_rad}")
    if not isinstance(rng, np.random.Generator):
        raise TypeError("rng must be a numpy Generator, e.g. np.random.default_rng(seed)")
    omega = rng.normal(0.0, sigma_rad, size=n.shape)
    angle = np.linalg.norm(omega, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(angle > 0, omega / np.where(angle > 0, angle, 1.0), 0.0)
    # Rodrigues' rotation formula
    c, s = np.cos(angle), np.sin(angle)
    out = n * c + np.cross(axis, n) * s + axis * np.sum(axis * n, axis=1, keepdims=True) * (1 - c)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


class SensorChain:
    """A bank of identical photodiodes, each with its transimpedance amplifier and ADC channel.

    Parameters
    ----------
    diode : str or PhotodiodeSpec
        A key of :data:`DIODES` or a :class:`PhotodiodeSpec`.
    r_f_ohm : float
        Transimpedance (feedback) resistance R_F (eq. 4.21; 500 ohm in the thesis).
    adc_bits : int
        ADC resolution over -V_fs..V_fs; 0..V_fs spans 0 .. 2^(bits-1) - 1 counts (eq. 4.24).
    v_full_scale : float
        ADC full-scale voltage (1 V on the UC3C, thesis 4.2.2).
    bandwidth_hz : float or None
        Noise bandwidth Delta f of eqs. 2.27-2.28. None: the installed amplifier's
        bandwidth f_op = 1 / (2 pi R_F C_F) with C_F = 1 nF (eq. 4.23, ~318 kHz;
        the thesis has no anti-aliasing filter, so the ADC sees all of it).
    temperature_k : float or array (N, 1), (1, K) or (N, K)
        Diode temperature in K; drives the responsivity drift (eq. 2.29, about T_ref = 25 degC)
        and the Johnson noise (eq. 2.28).
    noise : bool
        Add shot and Johnson noise (eqs. 2.26-2.28), drawn from a numpy Generator seeded with ``seed``.
    seed : int or None
        Seed of the noise generator; each call draws fresh noise from it.
    scale_errors : array (K,) or None
        Per-diode relative scale-factor errors delta_k (current x (1 + delta_k)).
    dead : iterable of int
        Indices of dead diodes; they read 0 counts.
    """

    def __init__(self, diode="BPW34FS", r_f_ohm=500.0, adc_bits=12, v_full_scale=1.0, bandwidth_hz=None,
                 temperature_k=T_REF_K, noise=False, seed=None, scale_errors=None, dead=()):
        if isinstance(diode, str):
            if diode not in DIODES:
                raise ValueError(f"unknown diode {diode!r}; choose one of {sorted(DIODES)} or pass a PhotodiodeSpec")
            diode = DIODES[diode]
        if not isinstance(diode, PhotodiodeSpec):
            raise TypeError(f"diode must be a name in {sorted(DIODES)} or a PhotodiodeSpec, got {type(diode).__name__}")
        self.diode = diode
        if not (np.isfinite(r_f_ohm) and r_f_ohm > 0):
            raise ValueError(f"r_f_ohm must be a positive resistance in ohm, got {r_f_ohm}")
        self.r_f_ohm = float(r_f_ohm)
        if int(adc_bits) != adc_bits or not 2 <= adc_bits <= 32:
            raise ValueError(f"adc_bits must be an integer in 2..32, got {adc_bits}")
        self.adc_bits = int(adc_bits)
        if not (np.isfinite(v_full_scale) and v_full_scale > 0):
            raise ValueError(f"v_full_scale must be a positive voltage, got {v_full_scale}")
        self.v_full_scale = float(v_full_scale)
        if bandwidth_hz is None:
            bandwidth_hz = 1.0 / (2.0 * np.pi * self.r_f_ohm * C_F_FARAD)
        if not (np.isfinite(bandwidth_hz) and bandwidth_hz > 0):
            raise ValueError(f"bandwidth_hz must be a positive frequency in Hz, got {bandwidth_hz}")
        self.bandwidth_hz = float(bandwidth_hz)
        t = np.asarray(temperature_k, dtype=float)
        if not np.all(np.isfinite(t) & (t > 0)):
            raise ValueError("temperature_k must be a positive absolute temperature in kelvin")
        if t.ndim not in (0, 2):
            raise ValueError(f"temperature_k must be a scalar or 2-D: (N, 1) per epoch, (1, K) per diode or (N, K); "
                             f"got shape {t.shape} (reshape a time series with t[:, None])")
        self.temperature_k = t
        self.noise = bool(noise)
        self.rng = np.random.default_rng(seed)
        self.scale_errors = None if scale_errors is None else np.asarray(scale_errors, dtype=float)
        if self.scale_errors is not None and (self.scale_errors.ndim != 1 or not np.all(self.scale_errors > -1)):
            raise ValueError("scale_errors must be a 1-D array (K,) of relative errors, each > -1")
        self.dead = tuple(int(k) for k in dead)

    @property
    def count_max(self):
        """Return the largest ADC reading, 2^(bits-1) - 1 (counts, eq. 4.24)."""
        return float(2 ** (self.adc_bits - 1) - 1)

    @property
    def counts_per_a(self):
        """Return the ADC gain R_F (2^(bits-1) - 1) / V_fs (counts per ampere, eq. 4.24)."""
        return self.r_f_ohm * self.count_max / self.v_full_scale

    def _check_e(self, e_w_m2):
        e = np.asarray(e_w_m2, dtype=float)
        if e.ndim == 1:
            e = e[None, :]
        if e.ndim != 2:
            raise ValueError(f"irradiance must be (N, K) W/m^2 (time leads) or (K,), got shape {np.shape(e_w_m2)}")
        if np.any(e < 0):
            raise ValueError("irradiance must be >= 0 W/m^2; a negative value means an upstream bug "
                             "(clip Monte-Carlo estimates before the sensor chain only if that is intended)")
        k = e.shape[1]
        if self.scale_errors is not None and self.scale_errors.shape[0] != k:
            raise ValueError(f"scale_errors has {self.scale_errors.shape[0]} entries but the irradiance has K = {k} diodes")
        if any(not 0 <= d < k for d in self.dead):
            raise ValueError(f"dead diode indices {self.dead} must lie in 0..{k - 1} for K = {k} diodes")
        if self.temperature_k.ndim == 2 and np.broadcast_shapes(self.temperature_k.shape, e.shape) != e.shape:
            raise ValueError(f"temperature_k of shape {self.temperature_k.shape} does not broadcast to the "
                             f"irradiance's (N, K) = {e.shape}")
        return e

    def current_a(self, e_w_m2):
        """Return the diode output currents (N, K) in A for irradiance (N, K) W/m^2 at full solar scale.

        I = R A E_S0 (E / E_sun) (1 + TC (T - T_ref)) (1 + delta_k) + I_D (eqs. 2.29-2.30,
        3.6, 4.16-4.19), plus zero-mean Gaussian noise of standard deviation
        sqrt(2 q (I_P + I_D) df + 4 k_B T df / R_sh) when ``noise`` (eqs. 2.26-2.28).
        Dead diodes give 0 A.
        """
        e = self._check_e(e_w_m2)
        d = self.diode
        t = np.broadcast_to(self.temperature_k, e.shape)
        i_p = d.k_r_a_per_w_m2 * d.e_s0_w_m2 * (e / E_SUN_W_M2) * (1.0 + d.temp_coeff_per_k * (t - T_REF_K))
        if self.scale_errors is not None:
            i_p = i_p * (1.0 + self.scale_errors)
        i = i_p + d.dark_current_a
        if self.noise:
            var = (2.0 * Q_E_C * np.clip(i, 0.0, None) * self.bandwidth_hz
                   + 4.0 * K_B_J_K * t * self.bandwidth_hz / d.shunt_resistance_ohm)
            i = i + self.rng.standard_normal(e.shape) * np.sqrt(np.nan_to_num(var))
        if self.dead:
            i = i.copy()
            i[:, list(self.dead)] = 0.0
        return i

    def noise_std_w_m2(self, e_w_m2):
        """Return the standard deviation (N, K) of a reading E_p, effective W/m^2, for irradiance (N, K) W/m^2.

        The chain's own noise in the units of eq. 4.25: the shot and Johnson current noise of
        :meth:`current_a` (eqs. 2.26-2.28) and the ADC's rounding (uniform over one count: LSB / sqrt(12)),
        divided by the gain from current to E_p. Without ``noise`` only the rounding is left.
        """
        e = self._check_e(e_w_m2)
        d = self.diode
        t = np.broadcast_to(self.temperature_k, e.shape)
        i = d.k_r_a_per_w_m2 * d.e_s0_w_m2 * (e / E_SUN_W_M2) * (1.0 + d.temp_coeff_per_k * (t - T_REF_K))
        i = i + d.dark_current_a
        var_i = 0.0
        if self.noise:
            var_i = (2.0 * Q_E_C * np.clip(i, 0.0, None) * self.bandwidth_hz
                     + 4.0 * K_B_J_K * t * self.bandwidth_hz / d.shunt_resistance_ohm)
        var_counts = var_i * self.counts_per_a ** 2 + 1.0 / 12.0
        return np.sqrt(var_counts) * self.lsb_w_m2

    def counts_from_current(self, current_a):
        """Return ADC counts (N, K), whole numbers as float64, for currents (N, K) A (eq. 4.24).

        counts = round(I R_F (2^(bits-1) - 1) / V_fs), clipped to 0 .. 2^(bits-1) - 1; NaN stays NaN.
        """
        c = np.rint(np.asarray(current_a, dtype=float) * self.counts_per_a)
        return np.clip(c, 0.0, self.count_max)

    def counts(self, e_w_m2):
        """Return ADC counts (N, K) for irradiance (N, K) W/m^2 (eqs. 4.19, 4.21, 4.24); dead diodes read 0."""
        c = self.counts_from_current(self.current_a(e_w_m2))
        if self.dead:
            c[:, list(self.dead)] = 0.0
        return c

    def irradiance_from_counts(self, counts):
        """Return the measured effective irradiance E_p (N, K) in W/m^2 from ADC counts (eq. 4.25).

        E_p = counts / (R_F (2^(bits-1) - 1) / V_fs K_R) with the nominal K_R = R A (eq. 3.6), so
        normal Sun reads E_p ~= E_S0.
        """
        return np.asarray(counts, dtype=float) / (self.counts_per_a * self.diode.k_r_a_per_w_m2)

    @property
    def lsb_w_m2(self):
        """Return one ADC count expressed as effective irradiance (W/m^2, eq. 4.25)."""
        return float(self.irradiance_from_counts(1.0))

    def measure(self, e_w_m2):
        """Return the measured effective irradiance E_p (N, K) in W/m^2 for irradiance (N, K) W/m^2.

        The whole chain: eqs. 4.16-4.19 (current), 4.24 (counts), 4.25 (back to irradiance).
        """
        return self.irradiance_from_counts(self.counts(e_w_m2))
