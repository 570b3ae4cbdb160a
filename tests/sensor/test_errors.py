"""Basilisk's CSS error and fault models (simcore.sensor.errors): closed forms, fixed seeds, bad input.

Statistical checks compare an estimate with its closed form at 5 standard errors (two-sided
false-alarm rate 5.7e-7 per check, for a Gaussian estimate); each also shows that the same check
rejects a deliberately wrong input.
"""
import numpy as np
import pytest

from simcore.constants import E_SUN_W_M2
from simcore.sensor.chain import DIODES, SensorChain
from simcore.sensor.errors import (FAULT_KINDS, FAULT_NOISE_BOUND, Fault, SensorErrors, apply_errors,
                                   basilisk_response, bounded_random_walk, gauss_markov, kelly_fit, parse_faults,
                                   parse_sensor_errors)

Z = 5.0


# ---- noise processes -----------------------------------------------------------------------------
def test_gauss_markov_variance_and_correlation_time():
    # Closed form of a stationary first-order Gauss-Markov process: Var x_t = sigma^2,
    # corr(x_t, x_{t+lag}) = exp(-lag dt / tau). Estimated across 100 000 independent columns at two
    # fixed samples: SE(var) = sigma^2 sqrt(2/k), SE(rho) = (1 - rho^2) / sqrt(k) (Fisher).
    sigma, tau, dt, k = 0.02, 20.0, 1.0, 100_000
    x = gauss_markov(41, k, sigma, tau, dt, np.random.default_rng(11))
    var = x[40].var()
    assert abs(var - sigma ** 2) < Z * sigma ** 2 * np.sqrt(2.0 / k)
    for lag in (1, 10, 20, 40):
        rho = np.corrcoef(x[0], x[lag])[0, 1]
        expected = np.exp(-lag * dt / tau)
        se = (1 - expected ** 2) / np.sqrt(k)
        assert abs(rho - expected) < Z * se, (lag, rho, expected)
    # the same check rejects a wrong correlation time (tau = 10 s at lag 20: exp(-2) = 0.135)
    rho20 = np.corrcoef(x[0], x[20])[0, 1]
    assert abs(rho20 - np.exp(-2.0)) > Z * (1 - np.exp(-4.0)) / np.sqrt(k)


def test_gauss_markov_time_average_gives_the_correlation_time():
    # One long series: lag-1 autocorrelation phi = exp(-dt / tau), so tau = -dt / ln(phi).
    # SE(phi_hat) ~ sqrt((1 - phi^2) / n) for an AR(1) series (Box & Jenkins).
    sigma, tau, dt, n = 1.0, 50.0, 2.0, 400_000
    x = gauss_markov(n, 1, sigma, tau, dt, np.random.default_rng(3))[:, 0]
    phi = np.exp(-dt / tau)
    phi_hat = np.sum(x[1:] * x[:-1]) / np.sum(x[:-1] * x[:-1])
    assert abs(phi_hat - phi) < Z * np.sqrt((1 - phi ** 2) / n)
    tau_hat = -dt / np.log(phi_hat)
    assert tau_hat == pytest.approx(tau, rel=0.05)


def test_random_walk_never_leaves_its_bounds_in_a_million_steps():
    bound, step = 0.05, 0.01
    x = bounded_random_walk(10 ** 6, 1, step, bound, np.random.default_rng(1460))[:, 0]
    assert np.all(np.abs(x) <= bound)
    # it does explore the whole band (a walk stuck at 0 would also pass the line above)
    assert x.max() > 0.99 * bound and x.min() < -0.99 * bound
    # the unbounded walk of Basilisk issue #1460 (same draws, no clamp) leaves the band: the check bites
    unbounded = np.cumsum(np.random.default_rng(1460).standard_normal(10 ** 6) * step)
    assert np.any(np.abs(unbounded) > bound)


def test_random_walk_steps_have_the_given_standard_deviation():
    # away from the bounds every increment is one N(0, step^2) draw: SE(std) = step / sqrt(2 m)
    step = 0.01
    x = bounded_random_walk(200_000, 1, step, 1e3, np.random.default_rng(2))[:, 0]
    d = np.diff(x)
    assert abs(d.std() - step) < Z * step / np.sqrt(2 * d.size)


def test_white_noise_standard_deviation_and_bias():
    # u = 0.5 everywhere, bias 0.01, white 0.02: mean 0.51 (SE sigma/sqrt(n)), std 0.02 (SE sigma/sqrt(2n))
    n, k = 100_000, 3
    u = np.full((n, k), 0.5)
    out = apply_errors(u, np.arange(n, dtype=float), SensorErrors(bias=0.01, white=0.02, seed=7))
    for j in range(k):
        assert abs(out[:, j].mean() - 0.51) < Z * 0.02 / np.sqrt(n)
        assert abs(out[:, j].std() - 0.02) < Z * 0.02 / np.sqrt(2 * n)
    # columns are independent: correlation within Z / sqrt(n)
    assert abs(np.corrcoef(out[:, 0], out[:, 1])[0, 1]) < Z / np.sqrt(n)
    # a wrong sigma (0.021) is rejected by the same check
    assert abs(out[:, 0].std() - 0.021) > Z * 0.021 / np.sqrt(2 * n)


def test_same_seed_same_noise_other_seed_other_noise():
    u = np.full((100, 4), 0.3)
    t = np.arange(100.0)
    e = SensorErrors(white=0.01, gm_sigma=0.01, walk_sigma=0.001, walk_bound=0.01, seed=5)
    assert np.array_equal(apply_errors(u, t, e), apply_errors(u, t, e))
    assert not np.array_equal(apply_errors(u, t, e), apply_errors(u, t, SensorErrors(white=0.01, seed=6)))


def test_scale_factor_and_saturation_follow_basilisk_order():
    # sensed = clip((u + bias) (1 + scale), sat_min, sat_max)
    u = np.array([[0.0, 0.2, 0.9, 1.5]])
    out = apply_errors(u, np.array([0.0]), SensorErrors(bias=0.1, scale=0.5, sat_min=0.2, sat_max=1.6))
    np.testing.assert_allclose(out[0], np.clip((u[0] + 0.1) * 1.5, 0.2, 1.6), rtol=0, atol=1e-15)


def test_kelly_fit_closed_form():
    # Basilisk coarseSunSensor.cpp: kellyFit = 1 - exp(-c^kPower / kellyFactor)
    c = np.array([1.0, 0.5, 0.1, 0.0, -0.3])
    np.testing.assert_allclose(kelly_fit(c, 0.1, 2.0),
                               [1 - np.exp(-10.0), 1 - np.exp(-2.5), 1 - np.exp(-0.1), 0.0, 0.0], rtol=1e-14)
    np.testing.assert_array_equal(kelly_fit(c, 0.0), np.ones(5))        # kellyFactor 0: pure cosine
    with pytest.raises(ValueError, match="Kelly factor"):
        kelly_fit(c, -0.1)


def test_basilisk_response_cuts_at_the_fov():
    # value = c (1 - exp(-c^2 / kappa)) inside the FOV, 0 outside (coarseSunSensor.cpp computeTrueOutput)
    c = np.cos(np.radians([0.0, 30.0, 59.9, 60.1, 90.0, 120.0]))
    expected = np.where(c >= 0.5, c * (1 - np.exp(-c ** 2 / 0.2)), 0.0)
    np.testing.assert_allclose(basilisk_response(c, np.radians(60.0), 0.2), expected, rtol=1e-14)
    assert basilisk_response(c, np.radians(60.0))[3] == 0.0 and basilisk_response(c, np.radians(60.0))[2] > 0.5


# ---- faults ----------------------------------------------------------------------------------------
N, K, ONSET, DIODE = 200, 3, 120.0, 1
T = np.arange(N, dtype=float)
U = 0.5 + 0.3 * np.sin(T / 20.0)[:, None] * np.array([1.0, -1.0, 0.5])   # a smooth true signal, in 0.2 .. 0.8
ERR = SensorErrors(white=0.01, seed=9)


def _faulty(kind, end=None, errors=ERR):
    nominal = apply_errors(U, T, errors)
    faulty = apply_errors(U, T, errors, [Fault(DIODE, kind, ONSET, end)])
    on = T >= ONSET if end is None else (T >= ONSET) & (T < end)
    # before the onset, and on the other diodes, nothing changes (same draws)
    np.testing.assert_array_equal(faulty[~on], nominal[~on])
    np.testing.assert_array_equal(np.delete(faulty, DIODE, axis=1), np.delete(nominal, DIODE, axis=1))
    return nominal, faulty, on


def test_fault_off_reads_zero_from_its_onset():
    _, f, on = _faulty("OFF")
    assert np.all(f[on, DIODE] == 0.0)


def test_fault_stuck_max_reads_the_normal_sun_value_then_scale():
    _, f, on = _faulty("STUCK_MAX")
    assert np.all(f[on, DIODE] == 1.0)
    _, f, on = _faulty("STUCK_MAX", errors=SensorErrors(scale=0.1))       # Basilisk: scale after the fault
    assert np.allclose(f[on, DIODE], 1.1, rtol=0, atol=1e-15)


def test_fault_stuck_current_holds_the_last_value_before_the_onset():
    nominal, f, on = _faulty("STUCK_CURRENT")
    i0 = int(np.argmax(on))
    assert np.all(f[on, DIODE] == nominal[i0 - 1, DIODE])


def _fault_noise():
    # Basilisk's fault noise, drawn after the white noise from the same generator (apply_errors' order):
    # a walk of step 0.5 (Basilisk faultNoiseStd default, coarseSunSensor.cpp constructor; its 1.5x multiplier
    # was removed in December 2024, commit 93e7b05) clamped to +-2, then the saturation floor 0
    rng = np.random.default_rng(ERR.seed)
    rng.standard_normal((N, K))
    return np.clip(bounded_random_walk(N, K, 0.5, FAULT_NOISE_BOUND, rng)[:, DIODE], 0.0, None)


def test_fault_stuck_rand_holds_one_random_value():
    nominal, f, on = _faulty("STUCK_RAND")
    i0 = int(np.argmax(on))
    assert np.all(f[on, DIODE] == _fault_noise()[i0])


def test_fault_rand_reads_fresh_random_values():
    _, f, on = _faulty("RAND")
    fn = _fault_noise()
    np.testing.assert_array_equal(f[on, DIODE], fn[on])
    assert np.unique(fn).size > 10          # a process that changes (it spends long spells at its floor 0)


def test_fault_with_an_end_restores_the_nominal_reading():
    nominal, f, on = _faulty("OFF", end=150.0)
    assert np.all(f[on, DIODE] == 0.0)
    after = T >= 150.0
    np.testing.assert_array_equal(f[after], nominal[after])


def test_stuck_max_through_the_adc_reads_e_s0():
    # through sunsim's chain (eqs. 4.21-4.25) a STUCK_MAX diode reads E_S0 to within half an LSB
    sensed = apply_errors(U, T, SensorErrors(), [Fault(0, "STUCK_MAX", ONSET)])
    chain = SensorChain()
    e_p = chain.measure(sensed * E_SUN_W_M2)
    assert np.all(np.abs(e_p[T >= ONSET, 0] - DIODES["BPW34FS"].e_s0_w_m2) <= 0.5 * chain.lsb_w_m2 + 1e-9)


# ---- SPEC strings and bad input ------------------------------------------------------------------
def test_parse_sensor_errors_and_faults():
    e = parse_sensor_errors("white=0.01, gm=0.02:300, walk=0.002:0.05, bias=0.01, scale=-0.02, sat=0:1.2, "
                            "kelly=0.1, misalign=0.5, seed=4")
    assert (e.white, e.gm_sigma, e.gm_tau_s, e.walk_sigma, e.walk_bound) == (0.01, 0.02, 300.0, 0.002, 0.05)
    assert (e.bias, e.scale, e.sat_min, e.sat_max, e.kelly, e.kelly_power) == (0.01, -0.02, 0.0, 1.2, 0.1, 2.0)
    assert (e.misalign_deg, e.seed) == (0.5, 4)
    f = parse_faults("STUCK_MAX@3:2000; off@5:100-400")
    assert f == (Fault(3, "STUCK_MAX", 2000.0), Fault(5, "OFF", 100.0, 400.0))
    assert parse_faults("") == () and parse_sensor_errors(None) == SensorErrors()
    assert SensorErrors().kelly is None and parse_sensor_errors("kelly=0").kelly == 0.0   # traced vs Basilisk cosine
    assert set(FAULT_KINDS) == {"OFF", "STUCK_CURRENT", "STUCK_MAX", "STUCK_RAND", "RAND"}


def test_unknown_fault_name_is_a_one_line_error():
    with pytest.raises(ValueError, match=r"unknown fault 'STUCK_HIGH'; use one of OFF, STUCK_CURRENT") as e:
        parse_faults("STUCK_HIGH@2:100")
    assert "\n" not in str(e.value)


def test_fault_onset_outside_the_run_is_a_one_line_error():
    with pytest.raises(ValueError, match=r"onset 500 s lies outside the run \(0 .. 199 s") as e:
        apply_errors(U, T, faults=[Fault(1, "OFF", 500.0)])
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="diode 7 does not exist"):
        apply_errors(U, T, faults=[Fault(7, "OFF", 10.0)])


def test_negative_noise_is_a_one_line_error():
    for spec in ("white=-0.01", "gm=-0.02:300"):
        with pytest.raises(ValueError, match=r"must be >= 0 \(a standard deviation") as e:
            parse_sensor_errors(spec)
        assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="correlation time must be > 0"):
        parse_sensor_errors("gm=0.02:0")


def test_walk_bounds_below_zero_are_a_one_line_error():
    with pytest.raises(ValueError, match=r"the walk bound must be >= 0, got -0.1; give walk=STEP_SIGMA:BOUND") as e:
        parse_sensor_errors("walk=0.01:-0.1")
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="needs a bound > 0"):
        parse_sensor_errors("walk=0.01:0")
    with pytest.raises(ValueError, match="bound must be >= 0"):
        bounded_random_walk(10, 1, 0.1, -1.0, np.random.default_rng(0))


@pytest.mark.parametrize("spec, message", [
    ("white", "is not KEY=VALUE"), ("noise=0.1", "is not KEY=VALUE"), ("gm=0.1", "gm=SIGMA:TAU_S"),
    ("white=abc", "'abc' is not a number"), ("scale=-1", "scale must be > -1"), ("sat=1:0", "sat_min < sat_max"),
])
def test_malformed_sensor_error_specs(spec, message):
    with pytest.raises(ValueError, match=message):
        parse_sensor_errors(spec)


@pytest.mark.parametrize("spec, message", [
    ("STUCK_MAX", "is not KIND@DIODE:ONSET_S"), ("OFF@x:10", "is not KIND@DIODE:ONSET_S"),
    ("OFF@1:20-10", "must come after its onset"), ("OFF@1:abc", "'abc' is not a number"),
])
def test_malformed_fault_specs(spec, message):
    with pytest.raises(ValueError, match=message):
        parse_faults(spec)
