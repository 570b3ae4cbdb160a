"""Coarse-Sun-sensor error and fault models as Basilisk defines them, on sunsim's diode signals.

Basilisk's ``coarseSunSensor`` works on a normalised signal, the diode's reading in units of
its normal-Sun reading ("cos value": 1.0 = the Sun on the normal, unit distance, no eclipse).
The same unit is used here: ``u = E_p / E_S0``, which for sunsim's chain equals
``E / E_sun`` of the irradiance on the diode (eqs. 4.16-4.19, 4.25). Every error amplitude
below (bias, noise standard deviations, walk bounds, saturation limits, fault values) is in
that unit, so a Basilisk user's ``senBias = 0.01`` is ``bias=0.01`` here.

Order of operations per sample (Basilisk ``CoarseSunSensor::UpdateState``):

1. true value ``u``: the traced direct + albedo irradiance / E_sun, the direct part optionally
   replaced by Basilisk's response model (below) and/or computed for a misaligned normal;
2. ``u + bias + n_gm + n_walk + n_white`` (:func:`gauss_markov`, :func:`bounded_random_walk`,
   white noise);
3. faults, from their onset to their end (:data:`FAULT_KINDS`);
4. scale factor ``x (1 + scale)``;
5. saturation to ``[sat_min, sat_max]``.

The result goes to sunsim's ADC (eqs. 4.21-4.25), which also clips at 0 and quantises.

Basilisk's response and its Kelly factor (``computeTrueOutput``): a diode reads
``c (1 - exp(-c^p / kappa))`` of the Sun for ``c = n . s >= cos(fov)`` and 0 beyond its FOV
(``kellyFactor`` kappa, ``kPower`` p, default 2; kappa = 0 is the pure cut-off cosine), times the
distance and shadow factors. The Kelly fit lowers the response at grazing incidence the way a
package or a cover does. With ``kelly`` set (:func:`basilisk_response`), sunsim's traced direct
irradiance, which sees the real well around each diode, is replaced by this model, so the two
optics can be compared on the same orbit; the traced albedo is kept.

Basilisk's noise process (``GaussMarkov::computeNextState``, rewritten in November 2024,
Basilisk 2.5 on): x <- A x + senNoiseStd w, w ~ N(0, 1), then clamped to +-walkBounds where
walkBounds > 0. ``senNoiseStd`` is used as given (the old 1.5x multiplier was removed in
December 2024, Basilisk commit 93e7b05; 2.12.1 measures 1.00x). The CSS's propagation A
(``setAMatrix``) is 1 by default, which makes it a bounded random walk: ``walk=STEP:BOUND`` here.
A = 0 (``setAMatrix([[0]])``) makes it white noise clipped at +-walkBounds: ``clip=SIGMA:BOUND``
here (:func:`basilisk_noise` covers both). The first-order Gauss-Markov process with a
correlation time (``gm=SIGMA:TAU``, :func:`gauss_markov`) is sunsim's own (Basilisk's A = phi
with its noise scaled by sqrt(1 - phi^2) gives the same process).

Misalignment: ``misalign=DEG`` turns every diode by a random small rotation (Rayleigh scale DEG);
``align=I:DTHETA:DPHI`` turns diode I as Basilisk's ``setUnitDirectionVectorWithPerturbation``
(azimuth theta about +z from +x, elevation phi from the x-y plane, both in deg, added to the
diode's nominal angles in the body frame), once per diode, several items allowed.

Fault kinds (Basilisk ``CSSFaultState``), each for one diode from ``onset_s`` until ``end_s``:

- ``OFF``: the diode reads 0;
- ``STUCK_CURRENT``: it keeps the value it read on the last sample before the onset;
- ``STUCK_MAX``: it reads 1.0 (the normal-Sun reading; then scale and saturation apply, as in
  Basilisk where ``sensedValue = 1.0`` precedes ``scaleSensorValues``);
- ``STUCK_RAND``: it keeps the fault-noise process's value at the onset;
- ``RAND``: it reads the fault-noise process every sample.

The fault-noise process is Basilisk's: a random walk clamped to +-2 with step standard
deviation ``faultNoiseStd`` (default 0.5, settable: ``fault=STEP``), started at 0 with the run.
"""
import re
from dataclasses import dataclass, fields

import numpy as np

from simcore.errors import InvalidInputError

FAULT_KINDS = ("OFF", "STUCK_CURRENT", "STUCK_MAX", "STUCK_RAND", "RAND")
FAULT_NOISE_STEP_SIGMA = 0.5    # Basilisk faultNoiseStd default (coarseSunSensor.cpp constructor; no 1.5x since 12/2024)
FAULT_NOISE_BOUND = 2.0         # Basilisk boundsFault (coarseSunSensor.cpp, Reset)


def kelly_fit(cos_theta, kelly_factor, k_power=2.0):
    """Return Basilisk's Kelly fit 1 - exp(-c^p / kappa) (unitless, same shape as ``cos_theta``).

    ``cos_theta`` is clipped at 0; ``kelly_factor`` kappa <= 1e-10 gives 1 (Basilisk's eps).
    Multiply the cosine response by it: response = c (1 - exp(-c^p / kappa)).
    """
    c = np.clip(np.asarray(cos_theta, dtype=float), 0.0, None)
    if not (np.isfinite(kelly_factor) and kelly_factor >= 0):
        raise InvalidInputError(f"the Kelly factor must be >= 0 (0 = pure cosine), got {kelly_factor}")
    if not (np.isfinite(k_power) and k_power > 0):
        raise InvalidInputError(f"the Kelly power must be > 0 (Basilisk's kPower, default 2), got {k_power}")
    if kelly_factor <= 1e-10:
        return np.ones_like(c)
    return 1.0 - np.exp(-c ** k_power / kelly_factor)


def basilisk_response(cos_theta, fov_rad, kelly_factor=0.0, k_power=2.0):
    """Return Basilisk's CSS angular response (unitless, shape of ``cos_theta``): c x Kelly fit inside the FOV, else 0.

    ``coarseSunSensor.cpp`` ``computeTrueOutput``: value = c if c >= cos(fov) else 0, then times
    1 - exp(-c^p / kappa) (:func:`kelly_fit`). ``fov_rad`` broadcasts against ``cos_theta``.
    """
    c = np.asarray(cos_theta, dtype=float)
    inside = c >= np.cos(np.asarray(fov_rad, dtype=float))
    return np.where(inside, c, 0.0) * kelly_fit(c, kelly_factor, k_power)


def gauss_markov(n, k, sigma, tau_s, dt_s, rng):
    """Return a first-order Gauss-Markov process (n, k), stationary, in the unit of ``sigma``.

    x_{i+1} = phi x_i + w_i with phi = exp(-dt / tau), w_i ~ N(0, sigma^2 (1 - phi^2)) and
    x_0 ~ N(0, sigma^2): variance sigma^2 at every sample and autocorrelation
    R(lag) = sigma^2 exp(-|lag| dt / tau) (the exact discretisation of dx/dt = -x / tau + w).
    Each of the k columns is independent.
    """
    if not (np.isfinite(sigma) and sigma >= 0):
        raise InvalidInputError(f"the Gauss-Markov standard deviation must be >= 0, got {sigma}")
    if not (np.isfinite(tau_s) and tau_s > 0):
        raise InvalidInputError(f"the Gauss-Markov correlation time must be > 0 s, got {tau_s}")
    phi = np.exp(-dt_s / tau_s)
    w = rng.standard_normal((n, k)) * sigma * np.sqrt(1.0 - phi * phi)
    x = np.empty((n, k))
    x[0] = rng.standard_normal(k) * sigma
    for i in range(1, n):
        x[i] = phi * x[i - 1] + w[i]
    return x


def basilisk_noise(n, k, sigma, bound, prop, rng):
    """Return Basilisk's GaussMarkov noise (n, k): x_i = clip(prop x_{i-1} + w_i, -bound, bound), x_{-1} = 0.

    ``GaussMarkov::computeNextState``: noise first, w_i ~ N(0, sigma^2), then the propagated state,
    then the clamp to +-``bound`` (``walkBounds``). ``prop`` = 1: :func:`bounded_random_walk`;
    ``prop`` = 0: white noise clipped at +-bound (a sample beyond it reads the bound).
    """
    if not (np.isfinite(prop) and -1.0 <= prop <= 1.0):
        raise InvalidInputError(f"the noise propagation (Basilisk's AMatrix) must lie in [-1, 1], got {prop}")
    if prop == 0.0:
        if not (np.isfinite(sigma) and sigma >= 0):
            raise InvalidInputError(f"the clipped noise's standard deviation must be >= 0, got {sigma}")
        if not (np.isfinite(bound) and bound > 0):
            raise InvalidInputError(f"the clipped noise's bound must be > 0, got {bound}")
        return np.clip(rng.standard_normal((n, k)) * sigma, -bound, bound)
    return bounded_random_walk(n, k, sigma, bound, rng, prop=prop)


def bounded_random_walk(n, k, step_sigma, bound, rng, x0=0.0, prop=1.0):
    """Return a random walk (n, k) clamped to [-bound, bound], in the unit of ``step_sigma``.

    x_{i+1} = clip(prop x_i + w_i, -bound, bound), w_i ~ N(0, step_sigma^2), x_0 = ``x0``: Basilisk's
    GaussMarkov with propMatrix = ``prop`` (1: the walk) and stateBounds = bound. Every sample lies
    within the bounds.
    """
    if not (np.isfinite(step_sigma) and step_sigma >= 0):
        raise InvalidInputError(f"the random-walk step standard deviation must be >= 0, got {step_sigma}")
    if not (np.isfinite(bound) and bound >= 0):
        raise InvalidInputError(f"the random-walk bound must be >= 0, got {bound}")
    w = rng.standard_normal((n, k)) * step_sigma
    x = np.empty((n, k))
    b = float(bound)
    start = min(max(float(x0), -b), b)
    for j in range(k):
        # a scalar loop per diode: the clamp makes each step depend on the last (~0.2 us a step)
        v, col = start, []
        for step in w[:, j].tolist():
            v = prop * v + step
            if v > b:
                v = b
            elif v < -b:
                v = -b
            col.append(v)
        x[:, j] = col
    return x


@dataclass(frozen=True)
class SensorErrors:
    """Per-diode error models (normalised units: 1.0 = the normal-Sun reading); see the module docstring.

    Every diode gets the same parameters and its own independent noise; ``seed`` fixes it all.
    """

    bias: float = 0.0              # constant bias added to every diode
    scale: float = 0.0             # relative scale-factor error: x (1 + scale)
    white: float = 0.0             # white-noise standard deviation per sample
    gm_sigma: float = 0.0          # first-order Gauss-Markov stationary standard deviation
    gm_tau_s: float = 300.0        # its correlation time (s)
    walk_sigma: float = 0.0        # bounded random walk: standard deviation of one step
    walk_bound: float = 0.0        # its bound (the walk stays within +-walk_bound)
    sat_min: float = 0.0           # saturation floor (Basilisk minOutput)
    sat_max: float = 1e6           # saturation ceiling (Basilisk maxOutput)
    kelly: float = None            # None: traced optics; a number: Basilisk's response, Kelly factor kappa
    kelly_power: float = 2.0       # Kelly power p (Basilisk kPower)
    misalign_deg: float = 0.0      # per-diode misalignment, Rayleigh scale of the angle (deg)
    clip_sigma: float = 0.0        # white noise clipped at +-clip_bound (Basilisk's walkBounds with AMatrix 0)
    clip_bound: float = 0.0
    fault_step: float = FAULT_NOISE_STEP_SIGMA   # the fault-noise walk's step (Basilisk faultNoiseStd)
    align: tuple = ()              # ((diode, dtheta_deg, dphi_deg), ...): Basilisk's per-diode perturbation
    seed: int = 0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "seed":
                if int(v) != v:
                    raise InvalidInputError(f"sensor errors: seed must be an integer, got {v}")
                continue
            if f.name == "kelly" and v is None:
                continue
            if f.name == "align":
                for item in v:
                    if len(item) != 3 or int(item[0]) != item[0] or item[0] < 0 or not np.all(np.isfinite(item)):
                        raise InvalidInputError(f"sensor errors: align needs (diode index >= 0, dtheta deg, dphi deg), "
                                                f"got {item}")
                diodes = [int(item[0]) for item in v]
                if len(set(diodes)) != len(diodes):
                    raise InvalidInputError(f"sensor errors: align names a diode twice ({diodes}); give each once")
                continue
            if not np.isfinite(v):
                raise InvalidInputError(f"sensor errors: {f.name} must be a finite number, got {v}")
        for name in ("white", "gm_sigma", "walk_sigma", "misalign_deg", "kelly", "clip_sigma", "fault_step"):
            if getattr(self, name) is not None and getattr(self, name) < 0:
                raise InvalidInputError(f"sensor errors: {name} must be >= 0 (a standard deviation or size), "
                                 f"got {getattr(self, name)}")
        if self.walk_bound < 0:
            raise InvalidInputError(f"sensor errors: the walk bound must be >= 0, got {self.walk_bound}; "
                             "give walk=STEP_SIGMA:BOUND with BOUND >= 0")
        if self.walk_sigma > 0 and self.walk_bound == 0:
            raise InvalidInputError("sensor errors: a random walk needs a bound > 0 (walk=STEP_SIGMA:BOUND)")
        if self.clip_sigma > 0 and not self.clip_bound > 0:
            raise InvalidInputError("sensor errors: clipped noise needs a bound > 0 (clip=SIGMA:BOUND)")
        if self.gm_tau_s <= 0:
            raise InvalidInputError(f"sensor errors: the Gauss-Markov correlation time must be > 0 s, got {self.gm_tau_s}")
        if self.scale <= -1:
            raise InvalidInputError(f"sensor errors: scale must be > -1 (a relative error), got {self.scale}")
        if self.sat_max <= self.sat_min:
            raise InvalidInputError(f"sensor errors: saturation needs sat_min < sat_max, got {self.sat_min}, {self.sat_max}")
        if self.kelly_power <= 0:
            raise InvalidInputError(f"sensor errors: the Kelly power must be > 0, got {self.kelly_power}")

    @property
    def noise_sigma(self):
        """Return the standard deviation of the summed noise processes at one sample (normalised units).

        sqrt(white^2 + gm_sigma^2 + clip_sigma^2) (the clipped noise's standard deviation is at most
        its sigma): the walk is bounded but not stationary, so it is left out (a filter should carry it
        as a bias or inflate its R by the user's judgement).
        """
        return float(np.sqrt(self.white ** 2 + self.gm_sigma ** 2 + self.clip_sigma ** 2))


@dataclass(frozen=True)
class Fault:
    """One diode's fault: ``kind`` (:data:`FAULT_KINDS`) from ``onset_s`` until ``end_s`` (None: to the end)."""

    diode: int
    kind: str
    onset_s: float
    end_s: float = None

    def __post_init__(self):
        if self.kind not in FAULT_KINDS:
            raise InvalidInputError(f"unknown fault {self.kind!r}; use one of {', '.join(FAULT_KINDS)}")
        if int(self.diode) != self.diode or self.diode < 0:
            raise InvalidInputError(f"a fault's diode must be an index >= 0, got {self.diode}")
        if not np.isfinite(self.onset_s):
            raise InvalidInputError(f"a fault's onset must be a time in seconds, got {self.onset_s}")
        if self.end_s is not None and not self.end_s > self.onset_s:
            raise InvalidInputError(f"a fault's end ({self.end_s} s) must come after its onset ({self.onset_s} s)")

    def active(self, t_s):
        """Return the mask (N,) of samples at which the fault is active: onset_s <= t < end_s."""
        t = np.asarray(t_s, dtype=float)
        on = t >= self.onset_s
        if self.end_s is not None:
            on &= t < self.end_s
        return on


def misalignment_rotations(k, sigma_rad, rng):
    """Return K small rotation matrices (K, 3, 3), body frame, each by a rotation vector with N(0, sigma^2) components.

    The same draw as :func:`simcore.sensor.chain.misaligned_normals` (one ``rng.normal(0, sigma, (K, 3))``),
    so ``R[k] @ n_k`` is the misaligned normal it returns for the same generator state; the angle
    between a true and a nominal normal is Rayleigh-distributed with scale sigma.
    """
    if not (np.isfinite(sigma_rad) and sigma_rad >= 0):
        raise InvalidInputError(f"the misalignment must be a non-negative angle, got {sigma_rad} rad")
    omega = rng.normal(0.0, sigma_rad, size=(k, 3))
    angle = np.linalg.norm(omega, axis=1)
    axis = np.where(angle[:, None] > 0, omega / np.where(angle > 0, angle, 1.0)[:, None], 0.0)
    kx = np.zeros((k, 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    kx = kx - np.transpose(kx, (0, 2, 1))
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * kx + (1.0 - c) * kx @ kx


def perturbed_normal_rotations(normals, align):
    """Return rotations (K, 3, 3) that turn each diode as Basilisk's ``setUnitDirectionVectorWithPerturbation``.

    ``align``: ((diode, dtheta_deg, dphi_deg), ...). Diode k's nominal normal n has azimuth
    theta = atan2(n_y, n_x) and elevation phi = asin(n_z) in the body frame; its perturbed normal is
    (cos(phi + dphi) cos(theta + dtheta), cos(phi + dphi) sin(theta + dtheta), sin(phi + dphi)), and
    the rotation is the smallest one taking n there (about n x n'), which turns the diode's whole
    frame and aperture with it. Diodes not named get the identity.
    """
    h = np.asarray(normals, dtype=float)
    rot = np.repeat(np.eye(3)[None], h.shape[0], axis=0)
    for diode, dtheta, dphi in align:
        k = int(diode)
        if not 0 <= k < h.shape[0]:
            raise InvalidInputError(f"align: diode {k} does not exist; this run has diodes 0..{h.shape[0] - 1}")
        n = h[k] / np.linalg.norm(h[k])
        theta = np.arctan2(n[1], n[0]) + np.radians(dtheta)
        phi = np.arcsin(np.clip(n[2], -1.0, 1.0)) + np.radians(dphi)
        m = np.array([np.cos(phi) * np.cos(theta), np.cos(phi) * np.sin(theta), np.sin(phi)])
        axis = np.cross(n, m)
        s, c = np.linalg.norm(axis), float(n @ m)
        if s < 1e-15:
            continue
        kx = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]]) / s
        rot[k] = np.eye(3) + s * kx + (1.0 - c) * kx @ kx
    return rot


def check_faults(faults, t_s, n_diodes):
    """Raise ValueError unless every fault names a diode 0..K-1 and starts inside the run's time span."""
    t = np.asarray(t_s, dtype=float)
    for f in faults:
        if not 0 <= f.diode < n_diodes:
            raise InvalidInputError(f"fault {f.kind}@{f.diode}: diode {f.diode} does not exist; this run has diodes "
                             f"0..{n_diodes - 1}")
        if not t[0] <= f.onset_s <= t[-1]:
            raise InvalidInputError(f"fault {f.kind}@{f.diode}: onset {f.onset_s:g} s lies outside the run "
                             f"({t[0]:g} .. {t[-1]:g} s since its start)")


def apply_errors(u_true, t_s, errors=None, faults=(), rng=None):
    """Return the sensed normalised signals (N, K) for true ones (N, K) (steps 2-5 of the module docstring).

    ``u_true`` in units of the normal-Sun reading, ``t_s`` (N,) seconds since the run's start at a
    constant step, ``errors`` a :class:`SensorErrors` (None: none), ``faults`` a sequence of
    :class:`Fault`. ``rng`` defaults to ``np.random.default_rng(errors.seed)``. The noise
    processes are drawn in a fixed order (white always, then Gauss-Markov, walk and fault noise when
    enabled), each (N, K): the same SPEC and seed give the same numbers.
    """
    u = np.array(u_true, dtype=float)
    if u.ndim != 2:
        raise InvalidInputError(f"signals must be (N, K) (time leads), got shape {u.shape}")
    n, k = u.shape
    t = np.asarray(t_s, dtype=float)
    if t.shape != (n,):
        raise InvalidInputError(f"t_s must be (N,) = ({n},), got shape {t.shape}")
    errors = errors or SensorErrors()
    faults = tuple(faults)
    check_faults(faults, t, k)
    rng = rng if rng is not None else np.random.default_rng(errors.seed)
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    sensed = u + errors.bias
    white = rng.standard_normal((n, k)) * errors.white
    if errors.white > 0:
        sensed += white
    if errors.gm_sigma > 0:
        sensed += gauss_markov(n, k, errors.gm_sigma, errors.gm_tau_s, dt, rng)
    if errors.walk_sigma > 0:
        sensed += bounded_random_walk(n, k, errors.walk_sigma, errors.walk_bound, rng)
    if errors.clip_sigma > 0:
        sensed += basilisk_noise(n, k, errors.clip_sigma, errors.clip_bound, 0.0, rng)
    if faults:
        fault_noise = bounded_random_walk(n, k, errors.fault_step, FAULT_NOISE_BOUND, rng)
        for f in faults:
            on = f.active(t)
            if not on.any():
                continue
            i0 = int(np.argmax(on))
            col = f.diode
            if f.kind == "OFF":
                sensed[on, col] = 0.0
            elif f.kind == "STUCK_MAX":
                sensed[on, col] = 1.0
            elif f.kind == "STUCK_CURRENT":
                # the last sensed value before the onset (Basilisk's pastValue); 0 at the first sample
                sensed[on, col] = sensed[i0 - 1, col] if i0 > 0 else 0.0
            elif f.kind == "STUCK_RAND":
                sensed[on, col] = fault_noise[i0, col]
            else:  # RAND
                sensed[on, col] = fault_noise[on, col]
    sensed *= 1.0 + errors.scale
    return np.clip(sensed, errors.sat_min, errors.sat_max)


# ---- SPEC strings (the CLI's --sensor-errors and --faults) -------------------------------------
_ERROR_KEYS = {
    "bias": ("bias",), "scale": ("scale",), "white": ("white",), "gm": ("gm_sigma", "gm_tau_s"),
    "walk": ("walk_sigma", "walk_bound"), "sat": ("sat_min", "sat_max"), "kelly": ("kelly", "kelly_power"),
    "misalign": ("misalign_deg",), "clip": ("clip_sigma", "clip_bound"), "fault": ("fault_step",),
    "align": ("diode", "dtheta", "dphi"), "seed": ("seed",),
}
SENSOR_ERRORS_HELP = ("comma-separated KEY=VALUE in units of the normal-Sun reading: bias=B, scale=S, white=SIGMA, "
                      "gm=SIGMA:TAU_S, walk=STEP_SIGMA:BOUND, clip=SIGMA:BOUND (white noise clipped at +-BOUND: "
                      "Basilisk's walkBounds with AMatrix 0), sat=MIN:MAX, kelly=KAPPA[:POWER] (Basilisk's response "
                      "in place of the traced optics; 0 = cut-off cosine), misalign=DEG (random), "
                      "align=DIODE:DTHETA_DEG:DPHI_DEG (one diode turned as Basilisk's azimuth/elevation perturbation; "
                      "repeatable), fault=STEP (the RAND faults' walk step, Basilisk faultNoiseStd, default 0.5), seed=N; "
                      "e.g. white=0.01,gm=0.02:300,walk=0.002:0.05")
FAULTS_HELP = ("semicolon-separated KIND@DIODE:ONSET_S[-END_S], KIND one of " + ", ".join(FAULT_KINDS)
               + "; e.g. STUCK_MAX@3:2000 or OFF@5:100-400")


def _number(text, what):
    try:
        return float(text)
    except ValueError:
        raise InvalidInputError(f"{what}: {text!r} is not a number") from None


def parse_sensor_errors(spec):
    """Return the :class:`SensorErrors` of a SPEC string (:data:`SENSOR_ERRORS_HELP`); '' or None: none."""
    if spec is None or not str(spec).strip():
        return SensorErrors()
    kw = {}
    for item in str(spec).split(","):
        item = item.strip()
        if not item:
            continue
        key, sep, value = item.partition("=")
        key = key.strip().lower()
        if not sep or key not in _ERROR_KEYS:
            raise InvalidInputError(f"--sensor-errors: {item!r} is not KEY=VALUE with KEY one of {', '.join(_ERROR_KEYS)}")
        names = _ERROR_KEYS[key]
        parts = value.split(":")
        optional_second = key == "kelly"
        if len(parts) != len(names) and not (optional_second and len(parts) == 1):
            form = {"gm": "gm=SIGMA:TAU_S", "walk": "walk=STEP_SIGMA:BOUND", "sat": "sat=MIN:MAX",
                    "kelly": "kelly=KAPPA[:POWER]", "clip": "clip=SIGMA:BOUND",
                    "align": "align=DIODE:DTHETA_DEG:DPHI_DEG"}.get(key, f"{key}=VALUE")
            raise InvalidInputError(f"--sensor-errors: {item!r} must be written {form}")
        if key == "align":
            kw["align"] = kw.get("align", ()) + (tuple(_number(x, "--sensor-errors align") for x in parts),)
            continue
        for name, part in zip(names, parts):
            kw[name] = _number(part, f"--sensor-errors {key}")
    if "seed" in kw:
        kw["seed"] = int(kw["seed"])
    try:
        return SensorErrors(**kw)
    except ValueError as exc:
        raise InvalidInputError(f"--sensor-errors: {str(exc).removeprefix('sensor errors: ')}") from None


_FAULT_RE = re.compile(r"^\s*([A-Za-z_]+)\s*@\s*(\d+)\s*:\s*([^-\s][^-]*?)\s*(?:-\s*(.+?))?\s*$")


def parse_faults(spec):
    """Return a tuple of :class:`Fault` from a SPEC string (:data:`FAULTS_HELP`); '' or None: none."""
    if spec is None or not str(spec).strip():
        return ()
    out = []
    for item in str(spec).split(";"):
        if not item.strip():
            continue
        m = _FAULT_RE.match(item)
        if not m:
            raise InvalidInputError(f"--faults: {item.strip()!r} is not KIND@DIODE:ONSET_S[-END_S] (e.g. STUCK_MAX@3:2000)")
        kind = m.group(1).upper()
        if kind not in FAULT_KINDS:
            raise InvalidInputError(f"--faults: unknown fault {m.group(1)!r}; use one of {', '.join(FAULT_KINDS)}")
        onset = _number(m.group(3), "--faults onset")
        end = _number(m.group(4), "--faults end") if m.group(4) else None
        try:
            out.append(Fault(int(m.group(2)), kind, onset, end))
        except ValueError as exc:
            raise InvalidInputError(f"--faults: {exc}") from None
    return tuple(out)
