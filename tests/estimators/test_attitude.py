"""TRIAD, q-method, QUEST and the MEKF (estimators/attitude.py) on synthetic truth."""
import numpy as np
import pytest

from estimators.attitude import (MEKF, attitude_error_body, dcm_to_quat, nees, q_method, quat_to_dcm, quest,
                                 rotvec_to_quat, time_to_converge_s, triad)
from simcore.environment.attitude import matrix_to_quat, quat_to_matrix, tumble

# chi-square quantiles, 6 degrees of freedom (Abramowitz & Stegun table 26.8; scipy.stats.chi2.ppf):
CHI2_6_025, CHI2_6_975 = 1.2373, 14.4494


def _random_attitudes(n, seed):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0, -q, q)


def test_static_solutions_recover_an_exact_attitude():
    # Oracle: simcore.environment.attitude's independent quaternion <-> matrix conversions (Shepperd's method).
    q = _random_attitudes(20, 0)
    R = quat_to_matrix(q)
    r = np.random.default_rng(1).normal(size=(20, 3, 3))
    r /= np.linalg.norm(r, axis=2, keepdims=True)
    b = np.einsum("nji,nmj->nmi", R, r)                     # body vectors: R^T r
    np.testing.assert_allclose(triad(b[:, 0], b[:, 1], r[:, 0], r[:, 1]), R, atol=1e-12)
    np.testing.assert_allclose(q_method(b, r), q, atol=1e-12)
    np.testing.assert_allclose(quest(b, r), q, atol=1e-9)
    np.testing.assert_allclose(dcm_to_quat(R), matrix_to_quat(R), atol=1e-12)
    np.testing.assert_allclose(quat_to_dcm(q), R, atol=1e-14)


def test_q_method_and_quest_agree_on_noisy_vectors_and_beat_triad_on_the_second_vector():
    # Wahba's optimum is unique: q-method (eigen-decomposition) and QUEST (Newton) give the same quaternion.
    rng = np.random.default_rng(2)
    q = _random_attitudes(200, 3)
    R = quat_to_matrix(q)
    r = rng.normal(size=(200, 2, 3))
    r /= np.linalg.norm(r, axis=2, keepdims=True)
    b = np.einsum("nji,nmj->nmi", R, r) + rng.normal(0, 0.01, (200, 2, 3))
    qm, qq = q_method(b, r, [1.0, 1.0]), quest(b, r, [1.0, 1.0])
    assert np.degrees(np.linalg.norm(attitude_error_body(qm, qq), axis=1)).max() < 1e-6
    err_q = np.linalg.norm(attitude_error_body(qm, q), axis=1)
    err_t = np.linalg.norm(attitude_error_body(dcm_to_quat(triad(b[:, 0], b[:, 1], r[:, 0], r[:, 1])), q), axis=1)
    # With equally noisy vectors, the optimal weighting beats TRIAD (which trusts the first vector fully).
    assert np.sqrt(np.mean(err_q ** 2)) < np.sqrt(np.mean(err_t ** 2))


def _scenario(n=3000, seed=0, sigma_v=0.01 * np.pi / 180, sigma_u=1e-5 * np.pi / 180, sigma_vec=(0.5, 1.0),
              bias_deg_s=0.3):
    """Truth: the 1.9 deg/s tumble; a fixed Sun direction and a field direction turning twice per orbit.
    Measurements drawn exactly from the filter's model (a noise-only scenario)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    att = tumble(t)
    q_true = att.q_gcrs_from_body
    w_true = np.radians(1.9) * np.full((n, 3), 1 / np.sqrt(3))
    bias = np.radians(bias_deg_s) * np.array([1.0, -0.5, 0.3]) + np.cumsum(
        sigma_u * rng.normal(size=(n, 3)), axis=0)
    gyro = w_true + bias + sigma_v * rng.normal(size=(n, 3))
    sun = np.tile([0.3, 0.8, 0.52], (n, 1))
    ang = 2 * np.pi * t / 2950.0
    mag = np.stack([np.cos(ang), 0.5 * np.sin(ang), 0.8 * np.sin(ang)], axis=1)
    refs = [sun / np.linalg.norm(sun, axis=1, keepdims=True), mag / np.linalg.norm(mag, axis=1, keepdims=True)]
    meas = []
    for r, s in zip(refs, np.radians(sigma_vec)):
        b = att.to_body(r)
        # A small random rotation with N(0, s^2) components perpendicular to the vector.
        e = rng.normal(0, s, (n, 3))
        e -= np.einsum("ni,ni->n", e, b)[:, None] * b
        meas.append(np.einsum("nij,nj->ni", quat_to_matrix(rotvec_to_quat(e)), b))
    return t, q_true, bias, gyro, refs, meas


def _run_filter(t, q0, gyro, refs, meas, sigma_vec_deg, P0, sigma_v, sigma_u, told_sigma_deg=None):
    told = np.radians(sigma_vec_deg if told_sigma_deg is None else told_sigma_deg)
    f = MEKF(q0, np.zeros(3), P0, sigma_v=sigma_v, sigma_u=sigma_u)
    qs, bs, Ps = [f.q], [f.bias], [f.P]
    for k in range(1, t.size):
        f.predict(gyro[k], t[k] - t[k - 1])
        for r, m, s in zip(refs, meas, told):
            f.update_vector(m[k], r[k], s)
        qs.append(f.q), bs.append(f.bias), Ps.append(f.P)
    return np.array(qs), np.array(bs), np.array(Ps)


def test_mekf_converges_from_30_deg_and_its_nees_is_consistent():
    sigma_v, sigma_u = np.radians(0.01), np.radians(1e-5)
    t, q_true, bias, gyro, refs, meas = _scenario(sigma_v=sigma_v, sigma_u=sigma_u)
    # Start 30 deg off about an oblique axis, with no bias knowledge; P0 says so (30 deg, 0.5 deg/s, 1 sigma).
    axis = np.array([0.2, -0.7, 0.4]) / np.linalg.norm([0.2, -0.7, 0.4])
    q0 = quat_to_matrix(q_true[0])[0]
    q0 = matrix_to_quat(q0 @ quat_to_matrix(rotvec_to_quat(np.radians(30) * axis))[0])[0]
    P0 = np.diag([np.radians(30) ** 2] * 3 + [np.radians(0.5) ** 2] * 3)
    qs, bs, Ps = _run_filter(t, q0, gyro, refs, meas, (0.5, 1.0), P0, sigma_v, sigma_u)
    err = attitude_error_body(qs, q_true)
    err_deg = np.degrees(np.linalg.norm(err, axis=1))
    assert err_deg[0] == pytest.approx(30.0, abs=1e-6)
    t_conv = time_to_converge_s(t, err_deg, 1.0)
    assert t_conv < 120.0, t_conv
    # NEES of (attitude, bias) against the two-sided 95 % chi-square bounds, 6 dof: in bounds >= 90 % of
    # the time after convergence (a consistent filter: ~95 %; the bound leaves room for the serial
    # correlation of one run).
    x = np.concatenate([err, bias - bs], axis=1)
    e = nees(x, Ps)[t >= t_conv]
    inside = np.mean((e >= CHI2_6_025) & (e <= CHI2_6_975))
    assert inside >= 0.90, inside
    # Its mean is the state dimension (6) for a consistent filter: within 25 %.
    assert 4.5 < e.mean() < 7.5, e.mean()


def test_nees_check_fails_for_an_overconfident_filter():
    # Deliberately wrong: the filter is told the vector noise is 5x smaller than it is.
    sigma_v, sigma_u = np.radians(0.01), np.radians(1e-5)
    t, q_true, bias, gyro, refs, meas = _scenario(sigma_v=sigma_v, sigma_u=sigma_u, seed=1)
    P0 = np.diag([np.radians(1) ** 2] * 3 + [np.radians(0.5) ** 2] * 3)
    qs, bs, Ps = _run_filter(t, q_true[0], gyro, refs, meas, (0.5, 1.0), P0, sigma_v, sigma_u,
                             told_sigma_deg=(0.1, 0.2))
    x = np.concatenate([attitude_error_body(qs, q_true), bias - bs], axis=1)
    e = nees(x, Ps)[t >= 300]
    assert np.mean((e >= CHI2_6_025) & (e <= CHI2_6_975)) < 0.9


def test_innovation_gate_rejects_an_outlier():
    q = _random_attitudes(1, 5)[0]
    f = MEKF(q, np.zeros(3), np.diag([np.radians(1) ** 2] * 3 + [1e-6] * 3), sigma_v=1e-4, sigma_u=1e-6)
    r = np.array([1.0, 0.0, 0.0])
    b_true = quat_to_dcm(q).T @ r
    wrong = quat_to_dcm(rotvec_to_quat(np.radians([0, 0, 20.0]))) @ b_true   # 20 deg off, sigma 1 deg
    assert not f.update_vector(wrong, r, np.radians(1.0))
    np.testing.assert_allclose(f.q, q)
    assert f.update_vector(b_true, r, np.radians(1.0))


def test_time_to_converge():
    t = np.arange(6.0)
    assert time_to_converge_s(t, [30, 5, 0.5, 3, 0.4, 0.2], 1.0) == 4.0
    assert np.isnan(time_to_converge_s(t, [30, 5, 0.5, 3, 0.4, 2], 1.0))
