"""Tests of the error metrics (estimators.metrics) against closed forms and hand-built data."""
import numpy as np
import pytest
from scipy.signal import windows

from estimators import angle_error_deg, hanning_mean_std, hanning_window, orbit_summary, zenith_azimuth_error_deg


def rotate(v, axis, angle):
    """Rodrigues' rotation of vectors v (N, 3) about unit axes (N, 3) by angles (N,)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=1, keepdims=True) * (1 - c)


def test_angle_error_of_known_rotations(rng):
    n = 500
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    # an axis perpendicular to v: rotating v about it by theta moves v by exactly theta
    axis = np.cross(v, rng.normal(size=(n, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    theta = np.concatenate([[0.0, 1e-9, 1e-6, np.pi - 1e-6, np.pi], rng.uniform(0, np.pi, n - 5)])
    w = rotate(v, axis, theta)
    np.testing.assert_allclose(angle_error_deg(w * 3.7, v), np.degrees(theta), rtol=0, atol=1e-9)
    out = angle_error_deg(np.array([[np.nan, np.nan, np.nan], [1.0, 0, 0]]), np.array([[0, 0, 1.0], [0, 1.0, 0]]))
    assert np.isnan(out[0]) and out[1] == pytest.approx(90.0, abs=1e-12)


def test_zenith_azimuth_errors():
    def sph(zen_deg, az_deg):
        z, a = np.radians(zen_deg), np.radians(az_deg)
        return np.stack([np.sin(z) * np.cos(a), np.sin(z) * np.sin(a), np.cos(z)], axis=-1)

    zt, at = np.array([30.0, 80.0, 120.0, 60.0]), np.array([10.0, 179.0, -170.0, -179.5])
    dz, da = np.array([2.0, -5.0, 0.5, 1.0]), np.array([3.0, 2.0, -15.0, -1.0])
    ez, ea = zenith_azimuth_error_deg(sph(zt + dz, at + da), sph(zt, at))
    np.testing.assert_allclose(ez, dz, atol=1e-10)
    # 179 + 2 = 181 -> -179 deg: the wrapped difference is +2, not -358
    np.testing.assert_allclose(ea, da, atol=1e-10)


def test_hanning_window_is_matlab_hanning():
    # MATLAB hanning(L) = hann(L + 2) without its two zero end points (MathWorks "hanning" reference);
    # scipy.signal.windows.hann is an independent implementation of hann.
    np.testing.assert_allclose(hanning_window(181), windows.hann(183)[1:-1], atol=1e-15)
    assert np.all(hanning_window(181) > 0)
    with pytest.raises(ValueError, match="odd"):
        hanning_window(180)


def test_hanning_mean_of_constant_is_the_constant():
    x = np.full(1000, 4.25)
    x[[10, 500, 501, 998]] = np.nan
    m, s = hanning_mean_std(x, 181)
    np.testing.assert_allclose(m, 4.25, rtol=1e-14)
    np.testing.assert_allclose(s, 0.0, atol=1e-6)


def dirichlet(w, half):
    """sum_{j=-M}^{M} cos(w j) = sin((M + 1/2) w) / sin(w / 2) (Dirichlet kernel), w = 0 -> 2M + 1."""
    w = np.asarray(w, dtype=float)
    return np.where(np.abs(np.sin(w / 2)) < 1e-15, 2 * half + 1, np.sin((half + 0.5) * w) / np.where(
        np.abs(np.sin(w / 2)) < 1e-15, 1.0, np.sin(w / 2)))


def hann_gain(w, length):
    """Normalised frequency response of the symmetric MATLAB-hanning window at angular frequency w.

    w_j = 1/2 + 1/2 cos(2 pi j / (L + 1)), j = -M..M, so sum_j w_j cos(w j) is a sum of three
    Dirichlet kernels (e.g. Harris 1978, Proc. IEEE 66(1), sec. IV.C, the Hann window as a sum of
    shifted kernels).
    """
    half = (length - 1) // 2
    big = 2 * np.pi / (length + 1)
    num = 0.5 * dirichlet(w, half) + 0.25 * dirichlet(w - big, half) + 0.25 * dirichlet(w + big, half)
    den = 0.5 * dirichlet(0.0, half) + 0.5 * dirichlet(big, half)
    return num / den


@pytest.mark.parametrize("period", [50.0, 181.0, 400.0, 5000.0])
def test_hanning_mean_of_sine_is_attenuated_by_the_window_response(period):
    length = 181
    half = (length - 1) // 2
    t = np.arange(3000)
    w = 2 * np.pi / period
    x = np.sin(w * t + 0.3)
    m, s = hanning_mean_std(x, length)
    inner = slice(half, t.size - half)
    g1, g2 = hann_gain(w, length), hann_gain(2 * w, length)
    # mean: a symmetric window multiplies a sinusoid by its (real) frequency response
    np.testing.assert_allclose(m[inner], g1 * x[inner], atol=1e-12)
    # variance: <sin^2> = 1/2 - 1/2 G(2w) cos(2 (w t + 0.3)), minus the squared mean
    var = 0.5 - 0.5 * g2 * np.cos(2 * (w * t + 0.3)) - (g1 * x) ** 2
    np.testing.assert_allclose(s[inner] ** 2, var[inner], atol=1e-11)


def test_hanning_mean_nan_aware_against_brute_force(rng):
    length = 21
    x = rng.normal(size=200) + 10.0
    x[rng.uniform(size=200) < 0.2] = np.nan
    x[100:130] = np.nan
    m, s = hanning_mean_std(x, length)
    w = windows.hann(length + 2)[1:-1]
    half = length // 2
    for t in range(200):
        idx = np.arange(t - half, t + half + 1)
        keep = (idx >= 0) & (idx < 200)
        wi, xi = w[keep], x[idx[keep]]
        good = np.isfinite(xi)
        if not good.any():
            assert np.isnan(m[t]) and np.isnan(s[t])
            continue
        mu = np.sum(wi[good] * xi[good]) / np.sum(wi[good])
        sd = np.sqrt(np.sum(wi[good] * (xi[good] - mu) ** 2) / np.sum(wi[good]))
        assert m[t] == pytest.approx(mu, abs=1e-12)
        assert s[t] == pytest.approx(sd, abs=1e-9)
    assert np.isnan(m[115])  # the middle of a 30-sample gap is wider than the window


def test_orbit_summary_on_hand_built_data():
    # orbit 0: sunlit values 0, 1, ..., 100 -> mean 50, max 100, and with linear interpolation
    # between order statistics the 95th percentile sits at rank 0.95 * 100 = 95 exactly -> 95.
    vals0 = np.arange(101.0)
    err = np.concatenate([vals0, [1e6, np.nan], [2.0, 4.0, np.nan], [7.0]])
    sunlit = np.concatenate([np.ones(101, bool), [False, True], [True, True, True], [False]])
    orbit = np.concatenate([np.zeros(101, int), [0, 0], [1, 1, 1], [2]])
    out = orbit_summary(err, sunlit, orbit)
    np.testing.assert_array_equal(out["orbit"], [0, 1, 2])
    np.testing.assert_array_equal(out["n"], [101, 2, 0])
    np.testing.assert_array_equal(out["n_invalid"], [1, 1, 0])
    assert out["mean_deg"][0] == 50.0 and out["max_deg"][0] == 100.0 and out["p95_deg"][0] == pytest.approx(95.0)
    # orbit 1: values 2, 4: mean 3, max 4, p95 = 2 + 0.95 * (4 - 2) = 3.9
    assert out["mean_deg"][1] == 3.0 and out["max_deg"][1] == 4.0 and out["p95_deg"][1] == pytest.approx(3.9)
    assert np.isnan(out["mean_deg"][2]) and np.isnan(out["p95_deg"][2]) and np.isnan(out["max_deg"][2])
    with pytest.raises(ValueError, match="same length"):
        orbit_summary(err, sunlit[:-1], orbit)


def test_hanning_of_a_series_shorter_than_the_window_keeps_its_length():
    # 20 samples under a 181-sample window: each output is the window-weighted mean of all 20
    # samples with the weights centred on that sample (direct sum as the oracle).
    from estimators.metrics import hanning_mean_std, hanning_window
    x = np.arange(20.0) ** 1.5
    mean, std = hanning_mean_std(x, window=181)
    assert mean.shape == std.shape == (20,)
    w = hanning_window(181)
    for t in (0, 7, 19):
        wt = w[90 + np.arange(20) - t]
        assert mean[t] == pytest.approx(np.sum(wt * x) / wt.sum(), rel=1e-12)
