"""The MEKF's Sun-vector noise (issue 33 item 4): the chain's own noise, its propagation to the Sun
direction, and the on-board albedo model's time-correlated error carried as a state of the filter."""
import numpy as np
import pytest

from estimators.advanced import model_albedo_direction_variance
from estimators.attitude import MEKF, attitude_error_body, nees, quat_to_dcm, rotvec_to_quat
from simcore.sensor.chain import SensorChain


def test_chain_noise_std_is_the_rounding_alone_without_noise():
    # Uniform rounding error over one count: LSB / sqrt(12) (closed form).
    chain = SensorChain(noise=False)
    assert chain.noise_std_w_m2(np.array([[0.0, 500.0, 1361.0]])) == pytest.approx(chain.lsb_w_m2 / np.sqrt(12.0))


def test_chain_noise_std_matches_the_chain_it_describes():
    # A wide bandwidth makes the shot noise ~2 counts, so the rounding is dithered and the reading's
    # spread is sqrt(shot^2 + Johnson^2 + LSB^2 / 12). 20 000 draws: the sample sd's relative standard
    # error is 1 / sqrt(2 n) = 0.5 %; 4 % is 8 standard errors (false alarm < 1e-14).
    e = np.full((20000, 1), 700.0)
    chain = SensorChain(noise=True, seed=3, bandwidth_hz=3e11)
    sd = chain.measure(e).std()
    assert sd == pytest.approx(float(chain.noise_std_w_m2(e[:1])[0, 0]), rel=0.04)
    # the wrong model (rounding only) is far off
    assert abs(sd / (chain.lsb_w_m2 / np.sqrt(12.0)) - 1) > 0.5


def test_direction_variance_closed_form_three_orthogonal_diodes():
    # Three orthogonal Sun diodes, no gain: S = E (identity rows), Cov(S) = sigma^2 I, so each of the
    # two directions perpendicular to s has variance sigma^2 / |S|^2 whatever s is.
    h = np.eye(3)
    s = np.array([[1.0, 2.0, 2.0]]) / 3.0
    sun = np.ones((1, 3), bool)
    var = model_albedo_direction_variance(h, np.zeros((1, 3)), s, sun, ~sun, np.full((1, 3), 0.5), 188.1,
                                          fit_gain=False)
    assert var[0] == pytest.approx((0.5 / 188.1) ** 2, rel=1e-12)


def test_direction_variance_with_gain_matches_monte_carlo_of_the_fit():
    # Five Sun diodes and two dark ones, joint (S, k) fit; Monte Carlo of the same linear fit.
    rng = np.random.default_rng(5)
    h = rng.normal(size=(7, 3))
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    s_true = np.array([0.3, 0.5, 0.81]) / np.linalg.norm([0.3, 0.5, 0.81])
    a = rng.uniform(5.0, 40.0, size=7)
    sun = np.array([1, 1, 1, 1, 1, 0, 0], bool)
    sigma = rng.uniform(0.5, 2.0, size=7)
    A = np.zeros((7, 4))
    A[sun, :3] = h[sun]
    A[:, 3] = a
    y0 = A @ np.r_[188.1 * s_true, 1.0]
    n = 40000
    x = np.linalg.lstsq(A, (y0[None] + rng.normal(size=(n, 7)) * sigma).T, rcond=None)[0].T
    d = x[:, :3] / np.linalg.norm(x[:, :3], axis=1, keepdims=True)
    perp = d - np.outer(d @ s_true, s_true)
    mc = np.mean(np.sum(perp ** 2, axis=1)) / 2
    var = model_albedo_direction_variance(h, a[None], s_true[None], sun[None], ~sun[None], sigma[None], 188.1)
    # n = 40 000: relative standard error of the mean of a chi-square(2)/2 ~ 1 / sqrt(n) = 0.5 %; 3 % = 6 se.
    assert var[0] == pytest.approx(mc, rel=0.03)


def _static_run(colored_filter, n=1500, seed=11):
    """A fixed attitude seen through a vector with a Gauss-Markov error (sigma_c, tau) plus white noise, and a
    second, clean-ish reference vector: return (NIS of the coloured vector over accepted updates, mean NEES)."""
    rng = np.random.default_rng(seed)
    dt, tau, sig_c, sig_w, sig_m = 1.0, 30.0, np.radians(0.2), np.radians(0.02), np.radians(1.0)
    phi = np.exp(-dt / tau)
    q_true = np.array([1.0, 0.0, 0.0, 0.0])
    r1, r2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.6, 0.8])
    kw = dict(colored_sigma_rad=sig_c) if colored_filter else {}
    f = MEKF(rotvec_to_quat(np.radians([1.0, -1.0, 0.5])), np.zeros(3), np.diag([np.radians(2.0) ** 2] * 3 + [1e-12] * 3),
             sigma_v=1e-5, sigma_u=1e-9, **kw)
    c = rng.normal(size=3) * sig_c
    nis, ns = [], []
    for k in range(n):
        c = phi * c + rng.normal(size=3) * sig_c * np.sqrt(1 - phi * phi)
        f.predict(np.zeros(3), dt, tau_s=tau if colored_filter else None)
        b2 = r2 + rng.normal(size=3) * sig_m
        f.update_vector(b2, r2, sig_m)
        b1 = r1 + c - (c @ r1) * r1 + rng.normal(size=3) * sig_w
        told = sig_w if colored_filter else np.hypot(sig_w, sig_c)
        if f.update_vector(b1, r1, told, colored=colored_filter):
            nis.append(f.last_nis)
        e = attitude_error_body(f.q, q_true)
        ns.append(nees(e, f.P[None, :3, :3])[0])
    return np.mean(nis), np.mean(ns[100:])


def test_colored_error_state_keeps_nis_and_nees():
    # The right model: NIS mean 2 (2 dof) and NEES mean 3 (3 dof). The innovations are nearly independent
    # (1400 of them: the NIS mean's standard error ~2/sqrt(1400) = 0.05, so +-30 % is 12 se). The attitude
    # error follows the coloured error, correlated over tau = 30 steps: ~50 independent samples, and
    # its chi-square(3) mean has a wide spread (4000 steps, seeds 0-3: 1.5-2.7), so the NEES is checked
    # for consistency within a factor 2.5 (1.2..7.5; 1500 steps, seeds 1-3 and 11: 1.5-4.9), against > 20 for the white-noise filter below.
    nis, nees_mean = _static_run(True)
    assert nis == pytest.approx(2.0, rel=0.3)
    assert 1.2 <= nees_mean <= 7.5


def test_white_noise_filter_fails_the_same_check():
    # The same data told as white noise of the total variance: the filter averages the correlated error
    # as if independent and is overconfident (NEES tens of times 3; 79 at 4000 steps).
    _, nees_mean = _static_run(False)
    assert nees_mean > 20.0
