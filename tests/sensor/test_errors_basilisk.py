"""Basilisk parity gaps closed (issue 33 item 6), each against Basilisk's documented behaviour.

Basilisk's CSS (src/simulation/sensors/coarseSunSensor/coarseSunSensor.cpp) and its GaussMarkov
utility (src/architecture/utilities/gauss_markov.cpp, computeNextState): x <- A x + sigma w, then
clamped to +-bound where bound > 0; the fault noise is a walk (A = 1) of step faultNoiseStd = 0.5
(constructor default) clamped to +-2; setUnitDirectionVectorWithPerturbation(dtheta, dphi) turns a
diode to azimuth theta + dtheta, elevation phi + dphi.
"""
import numpy as np
import pytest
from scipy.stats import norm

from simcore.errors import InvalidInputError
from simcore.sensor.errors import (FAULT_NOISE_BOUND, Fault, SensorErrors, apply_errors, basilisk_noise,
                                   parse_sensor_errors, perturbed_normal_rotations)

N, K = 20000, 3
T = np.arange(N, dtype=float)
U = np.full((N, K), 0.5)


def _rand_fault_steps(errors):
    """Return the RAND fault noise's steps from samples near 0 (|x| < 0.25, no saturation floor): a step reaches
    the +-2 clamp only beyond 1.75 = 3.5 steps' sigma (0.05 % of them, for step 0.5), so these are the walk's
    own steps."""
    sensed = apply_errors(U, T, errors, [Fault(1, "RAND", 0.0)])
    x = sensed[:, 1]
    return np.diff(x)[np.abs(x[:-1]) < 0.25]


def test_fault_walk_step_is_basilisks_default_and_settable():
    # Inside its bounds the walk's step is N(0, faultNoiseStd^2): 0.5 by default (the old 0.75 fails).
    # >= 1500 steps: the sample sd's relative standard error 1/sqrt(2 n) <= 1.8 %; 8 % >= 4.4 se (false alarm 1e-5).
    steps = _rand_fault_steps(SensorErrors(sat_min=-10.0, seed=2))
    assert steps.size > 1500
    assert steps.std() == pytest.approx(0.5, rel=0.08)
    steps = _rand_fault_steps(parse_sensor_errors("fault=0.2,sat=-10:10,seed=2"))
    assert steps.size > 1500 and steps.std() == pytest.approx(0.2, rel=0.08)


def test_clipped_white_noise_is_basilisks_walk_bounds_with_a_zero_propagation():
    # A = 0: each sample is sigma w clipped to +-bound, independent of the last. Closed forms: the share
    # at either bound is 2 (1 - Phi(bound / sigma)); the lag-1 correlation 0.
    sigma, bound = 0.3, 0.4
    e = parse_sensor_errors(f"clip={sigma}:{bound},sat=-10:10,seed=5")
    x = apply_errors(U, T, e)[:, 0] - 0.5
    assert np.all(np.abs(x) <= bound + 1e-12)
    share = np.mean(np.isclose(np.abs(x), bound, atol=1e-12))
    p = 2 * (1 - norm.cdf(bound / sigma))                       # 0.1824
    assert share == pytest.approx(p, abs=4 * np.sqrt(p * (1 - p) / N))      # 4 se: false alarm 6e-5
    assert abs(np.corrcoef(x[1:], x[:-1])[0, 1]) < 4 / np.sqrt(N)
    # the bounded walk (A = 1) with the same numbers is strongly correlated: not the same process
    walk = basilisk_noise(N, 1, sigma, bound, 1.0, np.random.default_rng(5))[:, 0]
    assert np.corrcoef(walk[1:], walk[:-1])[0, 1] > 0.5


def test_basilisk_noise_follows_compute_next_state_step_by_step():
    # x_i = clip(A x_{i-1} + sigma w_i, +-bound) with the generator's own draws, for A = 0.7.
    rng = np.random.default_rng(9)
    x = basilisk_noise(50, 1, 0.2, 0.25, 0.7, rng)[:, 0]
    w = np.random.default_rng(9).standard_normal(50) * 0.2
    ref, v = [], 0.0
    for wi in w:
        v = min(max(0.7 * v + wi, -0.25), 0.25)
        ref.append(v)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-15)


def test_align_turns_a_diode_as_basilisks_perturbation():
    # Basilisk: n' = (cos(phi + dphi) cos(theta + dtheta), cos(phi + dphi) sin(theta + dtheta), sin(phi + dphi))
    normals = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(0.3), np.sin(0.3)], [0.0, 0.0, 1.0]])
    rot = perturbed_normal_rotations(normals, ((1, 2.0, -1.5),))
    theta, phi = np.pi / 2 + np.radians(2.0), 0.3 + np.radians(-1.5)
    want = [np.cos(phi) * np.cos(theta), np.cos(phi) * np.sin(theta), np.sin(phi)]
    np.testing.assert_allclose(rot[1] @ normals[1], want, atol=1e-14)
    np.testing.assert_allclose(rot[1] @ rot[1].T, np.eye(3), atol=1e-14)
    np.testing.assert_array_equal(rot[[0, 2]], np.repeat(np.eye(3)[None], 2, axis=0))   # the others untouched
    e = parse_sensor_errors("align=1:2:-1.5,align=0:0.5:0")
    assert e.align == ((1.0, 2.0, -1.5), (0.0, 0.5, 0.0))


@pytest.mark.parametrize("spec, words", [
    ("clip=0.1", "clip=SIGMA:BOUND"),
    ("clip=0.1:0", "clipped noise needs a bound > 0"),
    ("fault=-0.5", "fault_step must be >= 0"),
    ("align=1:2", "align=DIODE:DTHETA_DEG:DPHI_DEG"),
    ("align=1:2:3,align=1:0:1", "align names a diode twice"),
])
def test_bad_parity_specs_say_what_to_give(spec, words):
    with pytest.raises(InvalidInputError, match=words):
        parse_sensor_errors(spec)


def test_align_on_a_missing_diode_is_refused():
    with pytest.raises(InvalidInputError, match="diode 7 does not exist"):
        perturbed_normal_rotations(np.eye(3), ((7, 1.0, 0.0),))


def test_errors_docstring_no_longer_claims_the_15_multiplier():
    import simcore.sensor.errors as m
    assert "multiplies ``senNoiseStd`` by 1.5" not in m.__doc__ and "1.00x" in m.__doc__
