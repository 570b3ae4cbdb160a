"""Torque-free rigid body: closed-form axisymmetric solution, conservation laws, input checks."""
import numpy as np
import pytest

from simcore.environment.attitude import quat_multiply, quat_conjugate, quat_to_matrix
from simcore.environment.dynamics import (axisymmetric_attitude, axisymmetric_rate, check_inertia, parse_inertia,
                              propagate_torque_free)


def _angle_between_rad(q1, q2):
    dq = quat_multiply(quat_conjugate(q1), q2)
    return 2.0 * np.arctan2(np.linalg.norm(dq[:, 1:], axis=1), np.abs(dq[:, 0]))


def test_axisymmetric_body_follows_the_closed_form():
    # Oracle: the closed-form torque-free axisymmetric solution (Wie, Space Vehicle Dynamics and
    # Control, sec. 6.4): w_z constant, (w_x, w_y) turning at lambda = (I3 - I1)/I1 w_z, the body
    # precessing about the fixed angular momentum at |h|/I1. A slender 2U-like body, 600 s.
    I1, I3 = 0.020, 0.006
    w0 = np.array([0.02, -0.01, 0.04])
    q0 = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
    t = np.arange(0.0, 600.0 + 1e-9, 1.0)
    att, w = propagate_torque_free(t, np.diag([I1, I1, I3]), w0, q0)
    assert w.shape == (t.size, 3) and att.q_gcrs_from_body.shape == (t.size, 4)
    np.testing.assert_allclose(w, axisymmetric_rate(t, I1, I3, w0), atol=1e-10)
    ref = axisymmetric_attitude(t, I1, I3, w0, q0)
    # RK4 at 0.1 s: local error ~ (|w| h)^5 ~ 1e-17 rad per step; 6000 steps stay far below 1e-9 rad.
    assert _angle_between_rad(att.q_gcrs_from_body, ref.q_gcrs_from_body).max() < 1e-9


def test_axisymmetric_closed_form_is_not_the_tumble():
    # The check above can fail: a wrong lambda (I1 and I3 swapped) misses the propagated rate by far.
    t = np.arange(0.0, 200.0, 1.0)
    w0 = np.array([0.02, -0.01, 0.04])
    _, w = propagate_torque_free(t, np.diag([0.02, 0.02, 0.006]), w0)
    assert np.abs(w - axisymmetric_rate(t, 0.006, 0.02, w0)).max() > 1e-3


def test_triaxial_body_conserves_energy_and_inertial_momentum():
    # Oracle: without torque T = 1/2 w.Jw and h_gcrs = R J w are constants of the motion
    # (Euler's equations). A general tensor with products of inertia, near the unstable middle axis.
    J = np.array([[0.0150, 0.0004, -0.0002], [0.0004, 0.0180, 0.0003], [-0.0002, 0.0003, 0.0060]])
    w0 = np.array([0.05, 0.002, 0.01])  # mostly about x, the intermediate axis: it tumbles over
    t = np.arange(0.0, 1200.0 + 1e-9, 2.0)
    att, w = propagate_torque_free(t, J, w0)
    energy = 0.5 * np.einsum("ni,ij,nj->n", w, J, w)
    h_gcrs = np.einsum("nij,nj->ni", quat_to_matrix(att.q_gcrs_from_body), w @ J.T)
    assert np.abs(energy / energy[0] - 1).max() < 1e-9
    assert np.abs(h_gcrs - h_gcrs[0]).max() / np.linalg.norm(h_gcrs[0]) < 1e-9
    # ... and the motion is not trivial: the body rate changes direction by tens of degrees.
    cosang = w @ w0 / np.linalg.norm(w, axis=1) / np.linalg.norm(w0)
    assert np.degrees(np.arccos(cosang.min())) > 20


def test_inertia_parsing_and_rejection():
    np.testing.assert_allclose(parse_inertia("0.02,0.02,0.006"), np.diag([0.02, 0.02, 0.006]))
    J = parse_inertia("0.02,0.021,0.006,0.001,0,0")
    assert J[0, 1] == J[1, 0] == 0.001
    with pytest.raises(ValueError, match="not positive definite"):
        parse_inertia("0.02,-0.02,0.006")
    with pytest.raises(ValueError, match="not symmetric"):
        check_inertia([[0.02, 0.001, 0], [0.0, 0.02, 0], [0, 0, 0.006]])
    with pytest.raises(ValueError, match="I1 \\+ I2 >= I3"):
        parse_inertia("0.001,0.001,0.01")
    with pytest.raises(ValueError, match="cannot read numbers"):
        parse_inertia("a,b,c")


def test_cli_rejects_an_inertia_that_is_not_positive_definite(tmp_path, capsys):
    from simcore.cli import main
    out = tmp_path / "r.nc"
    rc = main(["run", "--dynamics", "0.02,-0.02,0.006", "--duration", "10", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "not positive definite" in err[0] and "Traceback" not in err[0]
    assert not out.exists() and not (tmp_path / "r.nc.partial").exists()


def test_run_options_dynamics_drive_the_study_attitude():
    # sunsim run --dynamics: the study's attitude is the torque-free motion from --spin-rate about the
    # tumble axis; with a spherical inertia that is exactly the constant tumble (closed form).
    from simcore.environment.attitude import tumble
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.schedule import study_geometry
    _, att, _ = study_geometry(RunOptions(dynamics="0.02,0.02,0.02", duration_s=120.0))
    ref = tumble(att.t_s)
    assert _angle_between_rad(att.q_gcrs_from_body, ref.q_gcrs_from_body).max() < 1e-10
    _, att2, _ = study_geometry(RunOptions(dynamics="0.015,0.018,0.006", duration_s=120.0))
    assert _angle_between_rad(att2.q_gcrs_from_body, ref.q_gcrs_from_body).max() > np.radians(1)
    with pytest.raises(ValueError, match="--attitude and --dynamics"):
        study_geometry(RunOptions(dynamics="0.02,0.02,0.02", attitude_file="x.csv", duration_s=10.0))
