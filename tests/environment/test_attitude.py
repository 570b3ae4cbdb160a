"""Tests of simcore.environment.attitude.

Oracle: scipy.spatial.transform.Rotation / Slerp (an independent
implementation; SciPy stores quaternions SCALAR-LAST (x, y, z, w), so every
comparison reorders columns), and closed forms of rigid rotation about a
fixed axis (angle = rate * t, the axis is the rotation's fixed point).
"""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from simcore.environment.attitude import (DEFAULT_TUMBLE_AXIS, Attitude, matrix_to_quat, quat_conjugate, quat_multiply,
                              quat_normalize, quat_to_matrix, tumble)


def to_scipy(q_wxyz):
    return Rotation.from_quat(np.asarray(q_wxyz)[..., [1, 2, 3, 0]])


def from_scipy(rot):
    return rot.as_quat()[..., [3, 0, 1, 2]]


def random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def same_rotation(qa, qb, atol=1e-12):
    """q and -q are the same rotation."""
    return np.allclose(qa, qb, atol=atol) or np.allclose(qa, -qb, atol=atol)


# ---- quaternion helpers ---------------------------------------------------

def test_quat_to_matrix_matches_scipy(rng):
    q = random_quats(rng, 500)
    np.testing.assert_allclose(quat_to_matrix(q), to_scipy(q).as_matrix(), atol=1e-14)


def test_matrix_to_quat_matches_scipy_and_round_trips(rng):
    q = random_quats(rng, 500)
    # Include half-turns about x, y, z and a diagonal: every branch of Shepperd's method.
    half = np.array([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, 1, 1, 1] / np.sqrt(3), [1, 0, 0, 0]])
    q = np.vstack([q, half])
    R = to_scipy(q).as_matrix()
    got = matrix_to_quat(R)
    assert got.shape == (q.shape[0], 4)
    assert np.all(got[:, 0] >= 0)
    for a, b in zip(got, from_scipy(to_scipy(q))):
        assert same_rotation(a, b, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(got), R, atol=1e-14)


def test_quat_multiply_is_scipy_composition(rng):
    q1, q2 = random_quats(rng, 200), random_quats(rng, 200)
    expected = from_scipy(to_scipy(q1) * to_scipy(q2))  # scipy: r1 * r2 applies r2 first
    got = quat_multiply(q1, q2)
    for a, b in zip(got, expected):
        assert same_rotation(a, b, atol=1e-13)
    np.testing.assert_allclose(quat_to_matrix(got), quat_to_matrix(q1) @ quat_to_matrix(q2), atol=1e-14)
    np.testing.assert_allclose(quat_multiply(q1, quat_conjugate(q1)), np.tile([1.0, 0, 0, 0], (200, 1)),
                               atol=1e-15)


def test_shapes_one_and_n():
    assert quat_to_matrix([1.0, 0, 0, 0]).shape == (1, 3, 3)
    assert quat_to_matrix(np.tile([1.0, 0, 0, 0], (7, 1))).shape == (7, 3, 3)
    assert matrix_to_quat(np.eye(3)).shape == (1, 4)
    assert quat_normalize([2.0, 0, 0, 0]).shape == (1, 4)
    assert quat_multiply([1.0, 0, 0, 0], np.tile([0, 1.0, 0, 0], (3, 1))).shape == (3, 4)


@pytest.mark.parametrize("bad, match", [
    ([0.0, 0.0, 0.0, 0.0], "zero"),
    ([np.nan, 0.0, 0.0, 1.0], "not finite"),
    ([np.inf, 0.0, 0.0, 1.0], "not finite"),
    ([1.0, 0.0, 0.0], r"\(4,\) or \(N, 4\)"),
    (np.ones((2, 3, 4)), r"\(4,\) or \(N, 4\)"),
])
def test_quat_normalize_rejects_bad_input(bad, match):
    with pytest.raises(ValueError, match=match):
        quat_normalize(bad)


def test_matrix_to_quat_rejects_non_rotations():
    with pytest.raises(ValueError, match="not a proper rotation"):
        matrix_to_quat(np.diag([1.0, 1.0, -1.0]))  # reflection, det -1
    with pytest.raises(ValueError, match="not a proper rotation"):
        matrix_to_quat(2.0 * np.eye(3))
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        matrix_to_quat(np.eye(4))


# ---- tumble ---------------------------------------------------------------

def test_default_axis_is_the_unit_body_diagonal():
    np.testing.assert_allclose(DEFAULT_TUMBLE_AXIS, np.ones(3) / np.sqrt(3.0), rtol=0, atol=1e-16)


def test_tumble_angle_grows_at_the_rate(rng):
    t = np.linspace(0.0, 86400.0, 2001)  # one thesis day at 1.9 deg/s: 456 turns
    q0 = random_quats(rng, 1)[0]
    att = tumble(t, rate_deg_s=1.9, q0_gcrs_from_body=q0)
    R = att.R_gcrs_from_body
    rel = np.swapaxes(R[:1], 1, 2) @ R  # R(0)^T R(t) = Rot(axis, rate t)
    # Closed form: rotation angle = rate * t wrapped to [0, pi]; scipy measures it independently.
    angle = np.radians(1.9) * t
    wrapped = np.abs((angle + np.pi) % (2 * np.pi) - np.pi)
    np.testing.assert_allclose(Rotation.from_matrix(rel).magnitude(), wrapped, atol=1e-9)
    # ... about +axis for angles in (0, pi), about -axis in (pi, 2 pi).
    rotvec = Rotation.from_matrix(rel).as_rotvec()
    sign = np.sign(np.sin(angle))
    ok = np.abs(np.sin(angle)) > 1e-3
    np.testing.assert_allclose(rotvec[ok], (sign * wrapped)[ok, None] * DEFAULT_TUMBLE_AXIS, atol=1e-9)


def test_tumble_axis_is_fixed_in_both_frames(rng):
    axis = np.array([0.2, -0.5, 0.9])
    q0 = random_quats(rng, 1)[0]
    att = tumble(np.linspace(0, 1000, 301), rate_deg_s=-7.3, axis_body=axis, q0_gcrs_from_body=q0)
    unit = axis / np.linalg.norm(axis)
    axis_gcrs = att.to_gcrs(unit)
    np.testing.assert_allclose(axis_gcrs, np.tile(to_scipy(q0).apply(unit), (301, 1)), atol=1e-12)
    np.testing.assert_allclose(att.to_body(axis_gcrs), np.tile(unit, (301, 1)), atol=1e-12)


def test_tumble_starts_at_q0_and_matches_scipy_composition(rng):
    q0 = random_quats(rng, 1)[0]
    t = np.array([0.0, 10.0, 123.4])
    att = tumble(t, rate_deg_s=1.9, q0_gcrs_from_body=q0)
    spin = Rotation.from_rotvec(np.radians(1.9) * t[:, None] * DEFAULT_TUMBLE_AXIS)
    expected = (to_scipy(q0) * spin).as_matrix()  # R0 @ Rot(axis, rate t)
    np.testing.assert_allclose(att.R_gcrs_from_body, expected, atol=1e-13)
    assert same_rotation(att.q_gcrs_from_body[0], q0)


def test_tumble_shapes():
    one = tumble(0.0)
    assert len(one) == 1
    assert one.q_gcrs_from_body.shape == (1, 4)
    assert one.R_gcrs_from_body.shape == (1, 3, 3)
    many = tumble(np.arange(5.0))
    assert len(many) == 5
    assert many.R_gcrs_from_body.shape == (5, 3, 3)
    assert many.R_body_from_gcrs.shape == (5, 3, 3)
    assert many.to_body([1.0, 0, 0]).shape == (5, 3)
    assert many.to_gcrs(np.ones((5, 3))).shape == (5, 3)
    with pytest.raises(ValueError, match=r"\(5, 3\)"):
        many.to_body(np.ones((4, 3)))


def test_body_and_gcrs_transforms_are_inverse_and_match_scipy(rng):
    q = random_quats(rng, 50)
    att = Attitude(q)
    v = rng.normal(size=(50, 3))
    np.testing.assert_allclose(att.to_gcrs(v), to_scipy(q).apply(v), atol=1e-13)
    np.testing.assert_allclose(att.to_body(v), to_scipy(q).inv().apply(v), atol=1e-13)
    np.testing.assert_allclose(att.to_body(att.to_gcrs(v)), v, atol=1e-13)
    np.testing.assert_allclose(att.R_body_from_gcrs @ att.R_gcrs_from_body, np.tile(np.eye(3), (50, 1, 1)),
                               atol=1e-14)


# ---- user histories -------------------------------------------------------

def test_from_quaternions_scalar_last_matches_scipy(rng):
    q = random_quats(rng, 20)
    xyzw = to_scipy(q).as_quat()
    att = Attitude.from_quaternions(xyzw, scalar_first=False)
    np.testing.assert_allclose(att.R_gcrs_from_body, to_scipy(q).as_matrix(), atol=1e-14)


def test_from_quaternions_rejects_bad_histories(rng):
    with pytest.raises(ValueError, match="norm 2"):
        Attitude.from_quaternions([[2.0, 0, 0, 0]])
    with pytest.raises(ValueError, match="shape"):
        Attitude.from_quaternions(np.ones((3, 3)))
    with pytest.raises(ValueError, match="not finite"):
        Attitude.from_quaternions([[np.nan, 0, 0, 1.0]])
    with pytest.raises(ValueError, match="increase strictly"):
        Attitude.from_quaternions(random_quats(rng, 3), t_s=[0.0, 2.0, 1.0])
    # Rounding to 6 decimals (a typical file) is within the tolerance and gets normalised.
    att = Attitude.from_quaternions(np.round(random_quats(rng, 4), 6))
    np.testing.assert_allclose(np.linalg.norm(att.q_gcrs_from_body, axis=1), 1.0, atol=1e-15)


def test_file_round_trip_and_errors(tmp_path, rng):
    t = np.array([0.0, 0.5, 1.5, 10.0])
    att = Attitude(random_quats(rng, 4), t_s=t)
    path = tmp_path / "att.csv"
    att.to_file(path)
    back = Attitude.from_file(path)
    np.testing.assert_array_equal(back.t_s, t)
    np.testing.assert_allclose(back.q_gcrs_from_body, att.q_gcrs_from_body, atol=1e-16)

    hand = tmp_path / "hand.csv"
    hand.write_text("# written by hand\nt_s, qw, qx, qy, qz\n0,1,0,0,0\n\n2,0,1,0,0\n")
    got = Attitude.from_file(hand)
    np.testing.assert_array_equal(got.t_s, [0.0, 2.0])

    for text, match in [("time,qw,qx,qy,qz\n0,1,0,0,0\n", "header must be"),
                        ("t_s,qw,qx,qy,qz\n0,1,0,0\n", "expected 5 values"),
                        ("t_s,qw,qx,qy,qz\n0,1,a,0,0\n", "cannot read"),
                        ("t_s,qw,qx,qy,qz\n", "no attitude rows"),
                        ("t_s,qw,qx,qy,qz\n0,0,0,0,1.5\n", "norm 1.5")]:
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        with pytest.raises(ValueError, match=match):
            Attitude.from_file(bad)


def test_resample_reproduces_a_tumble_exactly():
    # SLERP between samples of a constant-rate, fixed-axis rotation is that
    # rotation itself (closed form), as long as a step turns < 180 deg.
    coarse = tumble(np.arange(0.0, 601.0, 20.0), rate_deg_s=1.9)  # 38 deg per sample
    fine_t = np.linspace(0.0, 600.0, 1777)
    got = coarse.resample(fine_t)
    np.testing.assert_allclose(got.R_gcrs_from_body, tumble(fine_t).R_gcrs_from_body, atol=1e-12)
    np.testing.assert_array_equal(got.t_s, fine_t)


def test_resample_matches_scipy_slerp(rng):
    t = np.sort(rng.uniform(0, 100, 12))
    q = random_quats(rng, 12)
    att = Attitude(q, t_s=t)
    query = np.sort(rng.uniform(t[0], t[-1], 300))
    expected = Slerp(t, to_scipy(q))(query).as_matrix()
    np.testing.assert_allclose(att.resample(query).R_gcrs_from_body, expected, atol=1e-12)
    # Exactly at the samples the history comes back.
    np.testing.assert_allclose(att.resample(t).R_gcrs_from_body, att.R_gcrs_from_body, atol=1e-14)


def test_resample_outside_span_raises(rng):
    att = Attitude(random_quats(rng, 3), t_s=[0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="spans 0.0 .. 2.0 s"):
        att.resample([0.5, 2.5])
    with pytest.raises(ValueError, match="no times"):
        Attitude(random_quats(rng, 3)).resample([0.5])
