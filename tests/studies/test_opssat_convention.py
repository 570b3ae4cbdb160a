"""The quaternion convention and time scale of OPS-SAT's telemetry, shown with the shipped 2020 week
(simcore.studies.opssat_convention), and the cosine-law normal fit on synthetic readings."""
import numpy as np
import pytest

from simcore.environment.attitude import quat_conjugate, quat_to_matrix
from simcore.radiometry.normal_fit import CONVENTIONS, convention_fits, fit_normal
from simcore.studies import opssat_convention as oc

# Fitted by hand on the same week (shared data README, "What is known"): PD3 ~ +X, PD6 ~ -Z
README_NORMALS = {"PD3": (1.000, -0.001, 0.020), "PD6": (-0.015, -0.041, -0.999)}


@pytest.fixture(scope="module")
def evidence():
    return oc.evidence()


def _angle(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def test_only_scalar_first_frame_to_body_gives_axis_aligned_unit_normals(evidence):
    for name, rows in evidence["conventions"].items():
        good = [r for r in rows if r["off_axis_deg"] < 3 and abs(r["scale"] - 1) < 0.05
                and r["median_abs_residual"] < 0.05]
        assert [(r["scalar_first"], r["direction"]) for r in good] == [(True, "frame_to_body")], name
        assert _angle(good[0]["normal"], README_NORMALS[name]) < 2.0
        # the three wrong conventions miss the readings by a quarter of full Sun or more (median)
        assert min(r["median_abs_residual"] for r in rows if r is not good[0]) > 0.2


def test_time_stamps_are_utc_not_tai_or_tt(evidence):
    s = evidence["shifts"]
    assert s["+0"]["lit_in_predicted_shadow"] == 0
    assert s["+0"]["total"] < s["+37"]["total"] < s["+69.184"]["total"]
    assert s["+0"]["total"] < s["-37"]["total"]


def test_fit_normal_recovers_a_known_normal(rng):
    n_true = np.array([0.3, -0.2, 0.93])
    n_true /= np.linalg.norm(n_true)
    s = rng.normal(size=(400, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    y = 0.97 * np.clip(s @ n_true, 0, None) + rng.normal(0, 0.005, 400)
    y[::37] += 0.5                                   # outliers (an attitude jump): soft-L1 keeps them from steering
    normal, scale, res = fit_normal(s, y, y > 0.2)
    # 400 samples, noise 0.005: the normal's error ~ 0.005 / sqrt(~100) rad: 0.2 deg is > 5 sigma
    assert _angle(normal, n_true) < 0.2 and scale == pytest.approx(0.97, abs=0.005)
    assert np.isnan(res[y <= 0.2]).all()


def test_convention_fits_catches_a_wrong_convention(rng):
    # synthetic telemetry in OPS-SAT's convention: q rotates inertial vectors into the body
    q = rng.normal(size=(600, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    sun = np.array([0.3, 0.8, -0.52])
    sun /= np.linalg.norm(sun)
    s_body = np.einsum("nij,j->ni", quat_to_matrix(q), sun)
    y = np.clip(s_body @ [1.0, 0, 0], 0, None)
    fits = convention_fits(q, np.broadcast_to(sun, (600, 3)), y, y > 0.2)
    med = {(sf, d): f.median_abs_residual for _, sf, d, f in fits}
    assert med[(True, "frame_to_body")] < 1e-12
    assert min(v for k, v in med.items() if k != (True, "frame_to_body")) > 0.05
    # the same telemetry written as its conjugate (body_to_frame) is caught the other way round
    fits = convention_fits(quat_conjugate(q), np.broadcast_to(sun, (600, 3)), y, y > 0.2)
    assert min(fits, key=lambda f: f[3].median_abs_residual)[2] == "body_to_frame"
    assert len(CONVENTIONS) == 4
