"""The analytic check of rendered irradiance (every epoch, every diode).

* Direct Sun: the rendered value must lie within ``max(0.5 % of E_sun cos, 3 sigma)``
  of the analytic aperture response (exact for the traced well), where cos is
  the incidence on the diode. An unbiased estimate with standard error sigma
  still leaves a band of half-width ``tol`` with probability erfc(tol / (sigma
  sqrt 2)) (0.27 % where 3 sigma sets the band: grazing incidence, partial
  shadows); the verdict asks the outlier count to be consistent with the sum of
  these probabilities: a Poisson tail probability of at least 1e-3.
* Albedo: ``z = (rendered - analytic) / sqrt(sigma^2 + delta^2)``, with the
  analytic Bhanderi sum on a map refined by ``factor`` x ``factor`` (the same
  piecewise-constant reflectivity, so it converges to the integral the renderer
  samples) and ``delta`` its remaining cell-discretisation error, estimated from
  the difference to the native grid as ``|A_native - A_refined| / (factor^2 - 1)``
  (the cell-centre sum is second order in the cell size: Richardson). Over
  diode-epochs with albedo above ``albedo_floor_w_m2`` the z-scores should be
  N(0, 1): mean |z| ~ 0.80, and |z| > 4 in ~6e-5 of them.
"""
import math

import numpy as np

DIRECT_REL_TOL = 0.005      # of E_sun cos(incidence)
DIRECT_SIGMAS = 3.0
ALBEDO_FLOOR_W_M2 = 1.0
ALBEDO_Z_OUTLIER = 4.0
MEAN_ABS_Z_MAX = 1.0
DIRECT_ABS_FLOOR_W_M2 = 1e-9       # values this close are equal (e.g. 1e-14 against an exact 0)
OUTLIER_SHARE_MAX = 0.003


def poisson_tail(k, lam):
    """Return P(N >= k) for N ~ Poisson(lam)."""
    if k <= 0:
        return 1.0
    term, below = math.exp(-lam), 0.0
    for i in range(k):
        below += term
        term *= lam / (i + 1)
    return max(0.0, 1.0 - below)


def discretisation_bound(albedo_native, albedo_refined, factor):
    """Return the estimated cell-discretisation error of the refined analytic albedo (W/m^2)."""
    return np.abs(np.asarray(albedo_native) - np.asarray(albedo_refined)) / (factor ** 2 - 1.0)


def compare(direct, direct_se, direct_ref, albedo, albedo_se, albedo_ref, albedo_bound, e_sun_cos, *,
            considered=None):
    """Return (flags, report): per diode-epoch outlier flags for 'direct' and 'albedo' (bool (N, K)),
    and a summary dict of the check's figures and verdict.

    ``e_sun_cos`` (N, K): E_sun x the cosine of incidence on each diode (the scale of the 0.5 %
    direct tolerance). ``considered`` (N, K) bool: diode-epochs that take part (default: all finite).
    """
    direct, direct_se, direct_ref = map(np.asarray, (direct, direct_se, direct_ref))
    albedo, albedo_se, albedo_ref, albedo_bound = map(np.asarray, (albedo, albedo_se, albedo_ref, albedo_bound))
    finite = np.isfinite(direct) & np.isfinite(direct_ref) & np.isfinite(albedo) & np.isfinite(albedo_ref)
    use = finite if considered is None else (finite & np.asarray(considered, bool))

    band = DIRECT_REL_TOL * np.asarray(e_sun_cos)
    tol = np.maximum(np.maximum(band, DIRECT_SIGMAS * direct_se), DIRECT_ABS_FLOOR_W_M2)
    d_err = np.abs(direct - direct_ref)
    direct_bad = use & (d_err > tol)
    # Expected number of chance exceedances of unbiased normal estimates (only sigma > 0 contributes).
    ratio = np.where(use & (direct_se > 0), tol / np.where(direct_se > 0, direct_se, 1.0), np.inf)
    near = ratio[ratio < 10.0]
    chance = float(sum(math.erfc(x / math.sqrt(2.0)) for x in near))
    sig = np.sqrt(albedo_se ** 2 + albedo_bound ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sig > 0, (albedo - albedo_ref) / sig, 0.0)
    lit = use & (albedo_ref > ALBEDO_FLOOR_W_M2)
    albedo_bad = lit & (np.abs(z) > ALBEDO_Z_OUTLIER)
    zl = np.abs(z[lit])
    n_direct = int(use.sum())
    n_albedo = int(lit.sum())
    mean_abs_z = float(zl.mean()) if zl.size else float("nan")
    share_out = float((zl > ALBEDO_Z_OUTLIER).mean()) if zl.size else 0.0
    report = {
        "direct_checked": n_direct,
        "direct_outliers": int(direct_bad.sum()),
        "direct_worst_abs_w_m2": float(d_err[use].max()) if n_direct else 0.0,
        "albedo_checked": n_albedo,
        "albedo_mean_abs_z": mean_abs_z,
        "albedo_share_abs_z_gt_4": share_out,
        "albedo_outliers": int(albedo_bad.sum()),
        "albedo_max_abs_z": float(zl.max()) if zl.size else 0.0,
    }
    report["direct_outliers_expected_by_chance"] = chance
    report["direct_pass"] = bool(poisson_tail(report["direct_outliers"], chance) >= 1e-3)
    report["albedo_pass"] = bool(n_albedo == 0 or (mean_abs_z < MEAN_ABS_Z_MAX and share_out < OUTLIER_SHARE_MAX))
    report["pass"] = bool(report["direct_pass"] and report["albedo_pass"])
    return {"direct": direct_bad, "albedo": albedo_bad, "albedo_z": z}, report
