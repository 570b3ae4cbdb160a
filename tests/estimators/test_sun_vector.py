"""Tests of the thesis' Sun-vector estimators (estimators.sun_vector, thesis sec. 4.3).

Oracles: noise-free measurements built from the thesis' own sensor model (eq. 4.15 response,
effective irradiance E_S0, sec. 4.2.1) and a linear albedo vector (eq. 4.33), for the
mounting configurations of thesis 3.2.4 rebuilt here from SPEC sec. 5. The conditions under
which each estimator must be exact are derived in the comments from eqs. 4.27-4.45.
"""
import numpy as np
import pytest

from estimators import (ESTIMATORS, albedo_sun_estimate, pinv_estimate, sun_albedo_sun_estimate,
                        weighted_lsq, wls_estimate)

E_S0 = 188.1   # BPW34FS effective irradiance, thesis table 3.2.3


def tilted_normals(tilt_deg):
    """Return the 14 diode normals of thesis config "tilt X" (SPEC sec. 5): +x, +y, -x, -y panels, top, bottom."""
    x = np.radians(tilt_deg)
    xs = [(-1, -1), (0, +1), (+1, -1)]
    ys = [(-1, +1), (0, -1), (+1, +1)]
    rows = []
    for phi_deg, pattern in [(0, xs), (90, ys), (180, xs), (270, ys)]:
        for s_az, s_el in pattern:
            az, el = np.radians(phi_deg) + s_az * x, s_el * x
            rows.append([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    rows += [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]
    return np.array(rows)


BASELINE = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
CONFIGS = [("baseline", BASELINE, 90.0)] + [(f"tilt{t}_fov{f}", tilted_normals(t), float(f))
                                            for t in (20, 25, 30) for f in (70, 75)]


def test_config_helper_matches_spec_numbers():
    # SPEC sec. 5 prints the tilt-20 +x panel normals to 6 decimals
    np.testing.assert_allclose(tilted_normals(20)[:3], [[0.883022, -0.321394, -0.342020],
                                                        [0.939693, 0.0, 0.342020],
                                                        [0.883022, 0.321394, -0.342020]], atol=1e-6)


def response(c, fov_deg):
    """Thesis eq. 4.15: the approximate aperture response A(C), C = n . s."""
    cf = np.cos(np.radians(fov_deg))
    return np.where(c >= cf, c, np.where(c >= 0.12, c * (c - 0.12) / (cf - 0.12), 0.0))


def random_dirs(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rank3(normals_subset):
    return len(normals_subset) >= 3 and np.linalg.matrix_rank(normals_subset) == 3


def rank3_rows(h, mask):
    """Per epoch: do the normals selected by mask (N, K) span 3-D? (numpy's SVD rank; zeroed rows add nothing)"""
    return np.linalg.matrix_rank(h[None, :, :] * mask[:, :, None]) == 3


def expected_valid(h, s, fov_deg):
    """Where >= 3 diodes with non-coplanar normals see the Sun within the FOV (C >= cos FOV)."""
    c = s @ h.T
    sees = c >= np.cos(np.radians(fov_deg))
    return rank3_rows(h, sees), c


def direct_only(h, s, fov_deg):
    return E_S0 * response(s @ h.T, fov_deg)


EXACT_ALWAYS = {
    "pinv": pinv_estimate,
    "wls": wls_estimate,
    # eq. 4.38-4.45 from an exact initial estimate: H s_hat0 = E_S0 C >= E_p on every diode, so the
    # remainder (eq. 4.40) is <= 0 everywhere, no albedo diode is left, a = 0 and step 4 is WLS.
    "sas_from_wls": lambda e, h, **kw: sun_albedo_sun_estimate(e, h, init="wls", **kw),
}


@pytest.mark.parametrize("name, h, fov", CONFIGS, ids=[c[0] for c in CONFIGS])
@pytest.mark.parametrize("est", sorted(EXACT_ALWAYS))
def test_exact_from_direct_sunlight(name, h, fov, est):
    s = random_dirs(3000, seed=42)
    e_p = direct_only(h, s, fov)
    s_hat, valid = EXACT_ALWAYS[est](e_p, h, fov_deg=fov, e_s0=E_S0)
    want, _ = expected_valid(h, s, fov)
    assert s_hat.shape == (3000, 3) and valid.shape == (3000,) and valid.dtype == bool
    np.testing.assert_array_equal(valid, want)
    assert want.mean() > 0.3          # the test exercises many valid epochs
    assert np.max(np.abs(s_hat[valid] - s[valid])) < 1e-9
    assert np.all(np.isnan(s_hat[~valid]))


@pytest.mark.parametrize("name, h, fov", CONFIGS, ids=[c[0] for c in CONFIGS])
@pytest.mark.parametrize("est", ["albedo_sun", "albedo_sun_inverse", "sas_from_albedo_sun"])
def test_albedo_estimators_exact_without_partially_shaded_diodes(name, h, fov, est):
    # Albedo-Sun (eq. 4.32) fits the albedo to every diode below E_S0 cos(FOV). With direct light
    # only, these read exactly 0 unless a diode lies in the aperture's roll-off zone
    # (0.12 <= C < cos FOV, eq. 4.15); the thesis names those "slivers" as its noise source
    # (sec. 4.3.3). Without slivers the albedo fit is a = 0 and the result is WLS: exact.
    s = random_dirs(6000, seed=7)
    c = s @ h.T
    no_sliver = ~np.any((c >= 0.12) & (c < np.cos(np.radians(fov))), axis=1)
    s, c = s[no_sliver], c[no_sliver]
    e_p = E_S0 * response(c, fov)
    fn = {"albedo_sun": lambda e: albedo_sun_estimate(e, h, fov_deg=fov, e_s0=E_S0),
          "albedo_sun_inverse": lambda e: albedo_sun_estimate(e, h, fov_deg=fov, e_s0=E_S0,
                                                              albedo_weighting="inverse"),
          "sas_from_albedo_sun": lambda e: sun_albedo_sun_estimate(e, h, fov_deg=fov, e_s0=E_S0,
                                                                   init="albedo_sun")}[est]
    s_hat, valid = fn(e_p)
    want, _ = expected_valid(h, s, fov)
    np.testing.assert_array_equal(valid, want)
    assert want.sum() > 100
    assert np.max(np.abs(s_hat[valid] - s[valid])) < 1e-9


def albedo_scene(h, fov, n, seed, a_max):
    """Random Sun directions and albedo vectors a (W/m^2, effective units), mostly anti-sunward,
    and measurements E_p = E_S0 A(n.s) + max(0, n.a) (eqs. 4.15, 4.33)."""
    s = random_dirs(n, seed)
    rng = np.random.default_rng(seed + 10_000)   # a stream independent of the Sun directions
    u = -s + 0.6 * rng.normal(size=(n, 3))
    a = rng.uniform(2.0, a_max, size=(n, 1)) * u / np.linalg.norm(u, axis=1, keepdims=True)
    c = s @ h.T
    alb = np.clip(a @ h.T, 0.0, None)
    return s, a, c, E_S0 * response(c, fov) + alb


@pytest.mark.parametrize("weighting", ["none", "direct", "inverse"])
@pytest.mark.parametrize("tilt, fov", [(20, 70), (30, 75)])
def test_albedo_sun_recovers_a_known_albedo_vector(tilt, fov, weighting):
    # Derivation from eqs. 4.32-4.36. With E_p = E_S0 A(C) + max(0, n.a) the estimate is exact when
    #  (i)   no diode is in the roll-off zone (A = C or A = 0, eq. 4.15),
    #  (ii)  every albedo diode (E_p < E_S0 cos FOV; for the inverse weighting also E_p > 0) reads
    #        exactly n.a, i.e. n.a >= 0 there, and those normals span 3-D: eq. 4.32 is then a
    #        consistent system and returns a exactly for any positive weights;
    #  (iii) the Sun diodes (C >= cos FOV) span 3-D; with a_max below E_S0 cos FOV no albedo alone
    #        lifts a diode over the threshold, so the re-selection of eq. 4.34 is exactly them.
    h = tilted_normals(tilt)
    cf = np.cos(np.radians(fov))
    thr = E_S0 * cf
    s, a, c, e_p = albedo_scene(h, fov, 40_000, seed=tilt + fov, a_max=0.9 * thr)
    na = a @ h.T
    sel_a = (e_p < thr) & ((e_p > 0) if weighting == "inverse" else True)
    ok = ~np.any((c >= 0.12) & (c < cf), axis=1)
    ok &= ~np.any(sel_a & (na < 0), axis=1)
    ok &= rank3_rows(h, sel_a) & rank3_rows(h, c >= cf)
    assert ok.sum() >= 30, "the scene generator must produce enough cases meeting the conditions"
    s_hat, valid, det = albedo_sun_estimate(e_p[ok], h, fov_deg=fov, e_s0=E_S0, albedo_weighting=weighting,
                                            return_details=True)
    assert np.all(valid) and np.all(det["albedo_valid"])
    np.testing.assert_allclose(det["albedo_body"], a[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(s_hat, s[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(det["e_pa_hat_w_m2"], np.clip(na[ok], 0, None), rtol=0, atol=1e-9)
    # non-trivial: albedo falls on Sun diodes in some of these cases, and plain WLS is off there
    s_wls, _ = wls_estimate(e_p[ok], h, fov_deg=fov, e_s0=E_S0)
    assert np.max(np.abs(s_wls - s[ok])) > 1e-3


@pytest.mark.parametrize("tilt, fov", [(25, 70), (20, 75)])
def test_sun_albedo_sun_recovers_albedo_from_an_exact_initial_estimate(tilt, fov):
    # Derivation from eqs. 4.38-4.45 with s0 = s: the predicted Sun part is E_S0 max(0, C) (eq. 4.39),
    # the remainder r = E_p - E_S0 max(0, C) (eq. 4.40) equals n.a on the Sun diodes and on diodes
    # with C <= 0, and E_S0 (A - C) + max(0, n.a) on diodes with 0 < C < cos FOV. Exact when every
    # such diode has r <= 0 (dropped), the diodes with r > 0 span 3-D (eq. 4.42 consistent), and the
    # Sun diodes span 3-D; the re-selection (eq. 4.43) then finds exactly E_S0 A(C).
    h = tilted_normals(tilt)
    cf = np.cos(np.radians(fov))
    thr = E_S0 * cf
    s, a, c, e_p = albedo_scene(h, fov, 20_000, seed=3 * tilt + fov, a_max=0.9 * thr)
    r = e_p - E_S0 * np.clip(c, 0.0, None)
    mid = (c > 0) & (c < cf)
    ok = ~np.any(mid & (r > 0), axis=1)
    ok &= rank3_rows(h, r > 0) & rank3_rows(h, c >= cf)
    assert ok.sum() >= 30
    s_hat, valid, det = sun_albedo_sun_estimate(e_p[ok], h, fov_deg=fov, e_s0=E_S0, init=s[ok] * 3.0,
                                                return_details=True)
    assert np.all(valid)
    np.testing.assert_allclose(det["albedo_body"], a[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(s_hat, s[ok], rtol=0, atol=1e-9)
    s_wls, _ = wls_estimate(e_p[ok], h, fov_deg=fov, e_s0=E_S0)
    assert np.max(np.abs(s_wls - s[ok])) > 1e-3


def test_too_few_or_coplanar_diodes_give_nan_not_zero():
    # baseline, Sun along +x: only one diode sees it
    for fn in ESTIMATORS.values():
        s_hat, valid = fn(E_S0 * np.array([1.0, 0, 0, 0, 0, 0]), BASELINE, fov_deg=90.0, e_s0=E_S0)
        assert s_hat.shape == (1, 3) and not valid[0] and np.all(np.isnan(s_hat))
    # four diodes whose normals lie in the x-z plane all see the Sun: rank 2
    h = np.array([[np.cos(t), 0.0, np.sin(t)] for t in np.radians([-30, -10, 10, 30])])
    s = np.array([1.0, 0.0, 0.0])
    s_hat, valid = pinv_estimate(E_S0 * (h @ s), h, fov_deg=70, e_s0=E_S0)
    assert not valid[0] and np.all(np.isnan(s_hat))


def test_dead_diode_and_live_mask():
    h = tilted_normals(30)
    s = random_dirs(3000, seed=11)
    e_p = direct_only(h, s, 70)
    e_p[:, 0] = 0.0       # the thesis' dead diode reads 0 (SPEC sec. 5)
    sees = (s @ h.T) >= np.cos(np.radians(70))
    sees[:, 0] = False
    want = rank3_rows(h, sees)
    for live in (None, np.arange(14) != 0):
        s_hat, valid = wls_estimate(e_p, h, fov_deg=70, e_s0=E_S0, live=live)
        np.testing.assert_array_equal(valid, want)
        assert np.max(np.abs(s_hat[valid] - s[valid])) < 1e-9
    # a NaN reading is left out of the fit the same way
    e_nan = e_p.copy()
    e_nan[:, 0] = np.nan
    s_hat, valid = pinv_estimate(e_nan, h, fov_deg=70, e_s0=E_S0)
    np.testing.assert_array_equal(valid, want)


def test_weighted_lsq_matches_lstsq(rng):
    # independent oracle: numpy's SVD least squares on sqrt(W)-scaled rows, epoch by epoch
    h = tilted_normals(25)
    y = rng.normal(size=(50, 14))
    w = rng.uniform(0.1, 3.0, size=(50, 14)) * (rng.uniform(size=(50, 14)) > 0.4)
    x, ok = weighted_lsq(h, y, w)
    for i in range(50):
        m = w[i] > 0
        if ok[i]:
            sw = np.sqrt(w[i, m])[:, None]
            ref = np.linalg.lstsq(h[m] * sw, y[i, m] * sw[:, 0], rcond=None)[0]
            np.testing.assert_allclose(x[i], ref, atol=1e-10)
        else:
            assert not rank3(h[m]) and np.all(np.isnan(x[i]))


def test_misuse_raises():
    with pytest.raises(ValueError, match="K = 6"):
        wls_estimate(np.zeros((3, 5)), BASELINE, fov_deg=70, e_s0=E_S0)
    with pytest.raises(ValueError, match="fov_deg"):
        wls_estimate(np.zeros((3, 6)), BASELINE, fov_deg=120, e_s0=E_S0)
    with pytest.raises(ValueError, match="init"):
        sun_albedo_sun_estimate(np.zeros((3, 6)), BASELINE, fov_deg=70, e_s0=E_S0, init="lsq")
    with pytest.raises(ValueError, match="weighting"):
        albedo_sun_estimate(np.zeros((3, 6)), BASELINE, fov_deg=70, e_s0=E_S0, albedo_weighting="sqrt")


def test_pinv_keep_zero_readings_on_the_cube():
    # The thesis' baseline pseudoinverse "without choosing photodiodes" (secs. 4.3.1, 5.1): at FOV 90 deg
    # the threshold E_S0 cos(90 deg) is 0, so every diode with E_p >= 0 takes part, zeros included.
    # Cube +x, +y, -x, -y, +z, -z; readings: +x E1, +y E2, -x 0, -y beta (Earth light only), +z E3, -z 0.
    # Closed forms of eq. 4.27, (H^T H)^-1 H^T E:
    #   zeros dropped (rows +x, +y, -y, +z): H^T H = diag(1, 2, 1) -> x = (E1, (E2 - beta)/2, E3);
    #   zeros kept (all six rows):           H^T H = 2 I           -> x = (E1, E2 - beta, E3)/2.
    h = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    e1, e2, e3, beta = 120.0, 80.0, 60.0, 30.0
    e_p = np.array([[e1, e2, 0.0, beta, e3, 0.0]])
    unit = lambda v: np.asarray(v) / np.linalg.norm(v)
    s_drop, ok_drop = pinv_estimate(e_p, h, fov_deg=90, e_s0=E_S0)
    s_keep, ok_keep = pinv_estimate(e_p, h, fov_deg=90, e_s0=E_S0, keep_zero_readings=True)
    assert ok_drop[0] and ok_keep[0]
    np.testing.assert_allclose(s_drop[0], unit([e1, (e2 - beta) / 2, e3]), atol=1e-12)
    np.testing.assert_allclose(s_keep[0], unit([e1, e2 - beta, e3]), atol=1e-12)
    # below FOV 90 deg the threshold E_S0 cos(FOV) > 0 excludes zeros either way: the same estimate
    h14 = tilted_normals(20)
    e14 = direct_only(h14, random_dirs(500, seed=3), 70)
    a, va = pinv_estimate(e14, h14, fov_deg=70, e_s0=E_S0)
    b, vb = pinv_estimate(e14, h14, fov_deg=70, e_s0=E_S0, keep_zero_readings=True)
    np.testing.assert_array_equal(va, vb)
    np.testing.assert_array_equal(a[va], b[vb])
