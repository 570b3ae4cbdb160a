"""AttitudeHistory (simcore.environment.history): conventions against known rotations, frames against
published constants, slerp against closed-form rotations, and the gap / jump / frozen flags on synthetic
histories."""
import erfa
import numpy as np
import pytest

from simcore.environment import frames
from simcore.environment.attitude import axis_angle_to_quat, tumble
from simcore.environment.epochs import Epochs
from simcore.environment.history import AttitudeHistory, HistoryLimits
from simcore.errors import InvalidInputError

T0 = "2020-11-15T00:00:00Z"
C = np.sqrt(0.5)
# 90 deg right-handed about z: x -> y, y -> -x (the textbook matrix)
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _one(q, **kw):
    e = Epochs.from_any([T0, "2020-11-15T00:00:10Z"])
    return AttitudeHistory(e, np.array([q, q]), limits=HistoryLimits(min_frozen_s=None), **kw)


@pytest.mark.parametrize("scalar_first,row", [(True, (C, 0, 0, C)), (False, (0, 0, C, C))])
@pytest.mark.parametrize("direction,expected", [("body_to_frame", RZ90), ("frame_to_body", RZ90.T)])
def test_known_rotation_each_convention(scalar_first, row, direction, expected):
    h = _one(row, scalar_first=scalar_first, direction=direction)
    R = h.attitude_at(h.epochs[:1]).R_gcrs_from_body[0]
    np.testing.assert_allclose(R, expected, atol=1e-15)
    # body x in GCRS: +y when the quaternion turns body into frame, -y when it turns frame into body
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1 if direction == "body_to_frame" else -1, 0], atol=1e-15)


def test_scalar_position_misread_is_another_rotation():
    # a scalar-first row (cos 45, 0, 0, sin 45) read as scalar last: x = w = sqrt(1/2): 90 deg about x
    h = _one((C, 0, 0, C), scalar_first=False)
    R = h.attitude_at(h.epochs[:1]).R_gcrs_from_body[0]
    np.testing.assert_allclose(R, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-15)


def test_frame_bias_and_precession_match_published_values():
    e = Epochs.from_any(["2020-11-15T12:00:00Z"])
    # IERS Conventions 2010, sec. 5.4.4: xi0 = -16.617 mas, eta0 = -6.819 mas, dalpha0 = -14.6 mas: |bias| = 23.1 mas
    B = frames.R_eme2000_from_gcrs(e)[0]
    angle_mas = np.degrees(np.arccos((np.trace(B) - 1) / 2)) * 3.6e6
    assert angle_mas == pytest.approx(np.sqrt(16.617 ** 2 + 6.819 ** 2 + 14.6 ** 2), abs=0.5)
    np.testing.assert_allclose(frames.R_gcrs_from("j2000", e)[0], erfa.bp06(2451545.0, 0.0)[0].T, atol=1e-15)
    # TOD vs EME2000 on 2020-11-15: general precession 5028.8"/century (IAU 2006) x 20.87 yr = 0.2915 deg,
    # plus nutation (|dpsi| < 17.2", |deps| < 9.2": < 0.005 deg)
    P = frames.R_between("eme2000", "tod", e)[0]
    angle = np.degrees(np.arccos((np.trace(P) - 1) / 2))
    assert angle == pytest.approx(5028.8 / 3600 * 0.2087, abs=0.006)
    # TEME and TOD share the true pole and differ by the equation of the equinoxes (erfa.ee06a; the
    # GMST82 - GMST06 part of the TEME definition is ~0.03")
    D = frames.R_between("teme", "tod", e)[0]
    assert D[2, 2] == pytest.approx(1.0, abs=1e-15)
    ee_arcsec = np.degrees(erfa.ee06a(*e.tt())[0]) * 3600
    assert abs(np.degrees(np.arctan2(D[0, 1], D[0, 0]))) * 3600 == pytest.approx(abs(ee_arcsec), abs=0.1)
    # interpolated TOD against per-epoch erfa.pnm06a
    tt = e.tt()
    np.testing.assert_allclose(frames.R_tod_from_gcrs(e, exact=True)[0], erfa.pnm06a(*tt)[0], atol=1e-15)


def test_declared_frame_is_applied():
    e = Epochs.range(T0, 100, 10)
    q = axis_angle_to_quat([0, 0, 1], np.radians(0.5) * np.arange(10))
    for frame, key in (("EME2000", "eme2000"), ("TOD", "tod"), ("TEME", "teme"), ("GCRF", "gcrs")):
        h = AttitudeHistory(e, q, frame=frame)
        R = h.attitude_at(e).R_gcrs_from_body
        from simcore.environment.attitude import quat_to_matrix
        np.testing.assert_allclose(R, frames.R_between(key, "gcrs", e) @ quat_to_matrix(q), atol=1e-13)


def test_slerp_exact_for_constant_rate_rotation():
    # a constant-rate rotation about a fixed axis is a great circle: slerp between 10-s samples is exact
    t = np.arange(0, 101, 10.0)
    e = Epochs.from_any(T0) + t
    ref = tumble(t, rate_deg_s=3.0)
    h = AttitudeHistory(e, ref.q_gcrs_from_body)
    mid = np.arange(5, 96, 10.0) + 0.37
    got = h.attitude_at(Epochs.from_any(T0) + mid).R_gcrs_from_body
    np.testing.assert_allclose(got, tumble(mid, rate_deg_s=3.0).R_gcrs_from_body, atol=1e-12)


def _tumbling(n=30, step=10.0, rate=1.0):
    t = step * np.arange(n)
    return Epochs.from_any(T0) + t, tumble(t, rate_deg_s=rate).q_gcrs_from_body


def test_gap_flagged_and_not_interpolated():
    e, q = _tumbling()
    keep = np.r_[0:10, 14:30]                       # samples 10..13 missing: 50 s between samples 9 and 14
    h = AttitudeHistory(e[keep], q[keep])
    f = h.flags()
    assert f["gap"].tolist() == [i == 9 for i in range(25)] and f["counts"]["gap"] == 1
    inside = Epochs.from_any(T0) + np.array([85.0, 120.0, 145.0])
    assert h.trusted(inside).tolist() == [True, False, True]
    with pytest.raises(InvalidInputError) as exc:
        h.attitude_at(inside)
    assert "1 of 3 epochs" in str(exc.value) and "\n" not in str(exc.value)
    # a longer limit accepts it
    assert AttitudeHistory(e[keep], q[keep], limits=HistoryLimits(max_gap_s=60)).trusted(inside).all()


def test_jump_flags_the_lone_bad_sample():
    e, q = _tumbling()
    q = q.copy()
    q[12] = axis_angle_to_quat([1, 0, 0], [np.pi])[0]      # 180 deg away: 18 deg/s apparent
    h = AttitudeHistory(e, q)
    f = h.flags()
    assert np.flatnonzero(f["jump"]).tolist() == [11, 12]
    assert np.flatnonzero(~f["trusted_sample"]).tolist() == [12]
    assert len(h.sample_epochs()) == 29 and f["counts"]["untrusted_samples"] == 1
    # 1 deg/s tumble: 10 deg per step, well under the 10 deg/s limit elsewhere
    assert f["rate_deg_s"][0] == pytest.approx(1.0, rel=1e-9)


def test_frozen_stretch_flagged_at_its_stated_length():
    e, q = _tumbling()
    q = q.copy()
    q[5:10] = q[5]          # the same quaternion bit for bit for 40 s (samples 5..9)
    q[20:23] = q[20]        # for 20 s: under the 30-s limit
    h = AttitudeHistory(e, q)
    f = h.flags()
    assert np.flatnonzero(f["frozen"]).tolist() == [5, 6, 7, 8]
    assert np.flatnonzero(~f["trusted_sample"]).tolist() == [6, 7, 8]
    assert not AttitudeHistory(e, q, limits=HistoryLimits(min_frozen_s=None)).flags()["frozen"].any()


def test_span_ends_without_float_refusal():
    e, q = _tumbling(n=93, step=10.0)                 # 920 s
    h = AttitudeHistory(e, q)
    ends = Epochs.from_any(T0) + np.array([0.0, 920.0])
    # the end reached through a different sum of floats
    ends2 = (Epochs.from_any(T0) + 0.1) + np.array([-0.1, 919.9])
    assert h.trusted(ends).all() and h.trusted(ends2).all()
    h.attitude_at(ends2)
    assert not h.trusted(Epochs.from_any(T0) + np.array([-1.0, 921.0])).any()


def test_norms_and_order_refused_with_one_line():
    e = Epochs.range(T0, 30, 10)
    with pytest.raises(InvalidInputError, match="sample 1 .* norm 0.9"):
        AttitudeHistory(e, [[1, 0, 0, 0], [0.9, 0, 0, 0], [1, 0, 0, 0]])
    AttitudeHistory(e, [[1, 0, 0, 0], [0.9, 0, 0, 0], [1, 0, 0, 0]], norm_tol=0.15)
    with pytest.raises(InvalidInputError, match="increase strictly"):
        AttitudeHistory(Epochs.from_any([T0, T0]), [[1, 0, 0, 0]] * 2)
    with pytest.raises(InvalidInputError, match="unknown attitude frame"):
        AttitudeHistory(e, [[1, 0, 0, 0]] * 3, frame="ECEF")
    with pytest.raises(InvalidInputError, match="unknown attitude direction"):
        AttitudeHistory(e, [[1, 0, 0, 0]] * 3, direction="inertial_to_body")


def test_csv_round_trip_and_declarations(tmp_path):
    e, q = _tumbling(n=5)
    h = AttitudeHistory(e, q, frame="TEME")
    p = tmp_path / "h.csv"
    h.to_csv(p)
    back = AttitudeHistory.from_csv(p)
    assert back.frame == "TEME" and back.epochs == h.epochs
    np.testing.assert_allclose(back.q_frame_from_body, h.q_frame_from_body, atol=1e-16)
    # scalar last and frame_to_body declared in the file
    rows = "\n".join(f"{iso},{x[1]:.17g},{x[2]:.17g},{x[3]:.17g},{x[0]:.17g}" for iso, x in zip(e.iso(), q * [1, -1, -1, -1]))
    p2 = tmp_path / "h2.csv"
    p2.write_text(f"# frame: TEME\n# direction: frame_to_body\ntime_utc,qx,qy,qz,qw\n{rows}\n")
    np.testing.assert_allclose(AttitudeHistory.from_csv(p2).q_frame_from_body, q, atol=1e-15)
    with pytest.raises(InvalidInputError, match="declares frame TEME"):
        AttitudeHistory.from_csv(p2, frame="GCRF")
    p3 = tmp_path / "bad.csv"
    p3.write_text("time_utc,qw,qx,qy,qz\n2020-11-15 25:00:00,1,0,0,0\n")
    with pytest.raises(InvalidInputError, match="ISO-8601"):
        AttitudeHistory.from_csv(p3)


def test_a_coarse_history_is_not_all_gaps():
    # another simulator's output every 60 s: the gap limit is 3 x the median step (180 s), so only the 240-s hole
    t = np.r_[0.0:600.0:60.0, 840.0:1200.0:60.0]
    e = Epochs.from_any(T0) + t
    h = AttitudeHistory(e, tumble(t, rate_deg_s=0.1).q_gcrs_from_body)
    assert np.flatnonzero(h.flags()["gap"]).tolist() == [9] and h.gap_limit_s == 180.0
    # a fixed attitude given by two samples 100 s apart: a hold, neither a gap nor frozen
    two = AttitudeHistory(Epochs.from_any(T0) + np.array([0.0, 100.0]), [[1.0, 0, 0, 0]] * 2)
    assert two.trusted(Epochs.from_any(T0) + np.array([0.0, 50.0, 100.0])).all()
