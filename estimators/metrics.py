"""Error metrics of Sun-vector estimates (thesis sec. 4.3 figures): angles, smoothing, per-orbit summaries."""
import numpy as np


def _vectors(v, name):
    a = np.asarray(v, dtype=float)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be an array (N, 3) of vectors (time leads) or (3,), got shape {np.shape(v)}")
    return a


def angle_error_deg(s_hat, s_true):
    """Return the angle (N,) in degrees between estimated and true Sun vectors (any common frame).

    atan2(|a x b|, a . b), accurate at small and large angles; the vectors need not be unit.
    NaN where either vector is NaN (an invalid estimate).
    """
    a, b = _vectors(s_hat, "s_hat"), _vectors(s_true, "s_true")
    if a.shape != b.shape and a.shape[0] != 1 and b.shape[0] != 1:
        raise ValueError(f"s_hat {a.shape} and s_true {b.shape} must both be (N, 3) with the same N")
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def zenith_azimuth_error_deg(s_hat_inertial, s_true_inertial):
    """Return the signed zenith and azimuth errors (N,), (N,) in degrees of Sun vectors in the inertial frame.

    Zenith = polar angle from the inertial +z axis, atan2(sqrt(x^2 + y^2), z), in [0, 180];
    azimuth = atan2(y, x) in the xy plane. The errors are estimate minus truth; the azimuth
    error is wrapped to [-180, 180). Take ``np.abs`` for the thesis-style error plots
    (figs. 4.6-4.17 show error magnitudes). NaN where the estimate is NaN.
    """
    a, b = _vectors(s_hat_inertial, "s_hat_inertial"), _vectors(s_true_inertial, "s_true_inertial")

    def zen_az(v):
        return (np.degrees(np.arctan2(np.hypot(v[:, 0], v[:, 1]), v[:, 2])),
                np.degrees(np.arctan2(v[:, 1], v[:, 0])))

    za, aa = zen_az(a)
    zb, ab = zen_az(b)
    d_az = np.mod(aa - ab + 180.0, 360.0) - 180.0
    return za - zb, d_az


def hanning_window(window):
    """Return the symmetric Hanning window (window,) of MATLAB's ``hanning(L)``: all L weights > 0.

    w_n = 0.5 (1 - cos(2 pi n / (L + 1))), n = 1..L (the zero end points of ``hann``/``np.hanning``
    are dropped, so "a Hanning window of 181 samples" weighs 181 samples, as in thesis sec. 4.3).
    """
    if int(window) != window or window < 1 or window % 2 == 0:
        raise ValueError(f"the window length must be a positive odd integer so it can be centred, got {window}")
    n = np.arange(1, int(window) + 1)
    return 0.5 * (1.0 - np.cos(2.0 * np.pi * n / (window + 1)))


def hanning_mean_std(x, window=181):
    """Return the centred Hanning-weighted moving mean and standard deviation (N,), (N,) of x (N,).

    mean_t = sum_j w_j x_{t+j} / sum_j w_j over the window centred on t (MATLAB ``hanning``
    weights, see :func:`hanning_window`); std_t = sqrt(sum_j w_j (x_{t+j} - mean_t)^2 / sum_j w_j)
    (the weighted population standard deviation). NaN samples and samples beyond the ends of
    the series are dropped and the remaining weights renormalised; NaN where no sample is left.
    Thesis sec. 4.3: "mean and standard deviation ... over a Hanning window of 181 samples".
    """
    v = np.asarray(x, dtype=float)
    if v.ndim != 1:
        raise ValueError(f"x must be a 1-D time series (N,), got shape {v.shape}")
    w = hanning_window(window)
    lead = (w.size - 1) // 2

    def conv(a):
        # centred and cut to len(v) also when the series is shorter than the window
        return np.convolve(a, w, mode="full")[lead:lead + v.size]
    ok = np.isfinite(v)
    v0 = np.where(ok, v, 0.0)
    sw = conv(ok.astype(float))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = conv(v0) / sw
        # second moment about a per-window reference would be exact; the mean of the series
        # as reference already removes most of the cancellation for error time series
        ref = np.nanmean(v) if ok.any() else 0.0
        d0 = np.where(ok, v - ref, 0.0)
        m2 = conv(d0 * d0) / sw
        var = m2 - (mean - ref) ** 2
    empty = sw <= 0.5 * w.min()
    mean[empty] = np.nan
    std = np.sqrt(np.clip(var, 0.0, None))
    std[empty] = np.nan
    return mean, std


def orbit_summary(err_deg, sunlit, orbit_index):
    """Return per-orbit statistics of an error series, over sunlit samples with a finite error.

    ``err_deg`` (N,) degrees (NaN = invalid estimate), ``sunlit`` (N,) bool, ``orbit_index``
    (N,) int (e.g. from the ascending-node crossings). Returns a dict of arrays (M,), one per
    distinct orbit index in increasing order: ``orbit``, ``n`` (samples used), ``n_invalid``
    (sunlit samples with a NaN error), ``mean_deg``, ``p95_deg`` (95th percentile, linear
    interpolation between order statistics, numpy's default), ``max_deg``; NaN where n = 0.
    """
    e = np.asarray(err_deg, dtype=float)
    lit = np.asarray(sunlit, dtype=bool)
    orb = np.asarray(orbit_index)
    if not (e.ndim == 1 and e.shape == lit.shape == orb.shape):
        raise ValueError(f"err_deg, sunlit and orbit_index must be 1-D arrays of the same length N, "
                         f"got shapes {e.shape}, {lit.shape}, {orb.shape}")
    orbits = np.unique(orb)
    out = {k: np.full(orbits.shape, np.nan) for k in ("mean_deg", "p95_deg", "max_deg")}
    out["orbit"] = orbits
    out["n"] = np.zeros(orbits.shape, dtype=int)
    out["n_invalid"] = np.zeros(orbits.shape, dtype=int)
    for i, o in enumerate(orbits):
        in_o = (orb == o) & lit
        vals = e[in_o & np.isfinite(e)]
        out["n"][i] = vals.size
        out["n_invalid"][i] = int(np.sum(in_o & ~np.isfinite(e)))
        if vals.size:
            out["mean_deg"][i] = vals.mean()
            out["p95_deg"][i] = np.percentile(vals, 95.0)
            out["max_deg"][i] = vals.max()
    return out
