"""Sun-vector estimators: pure functions of diode irradiances and normals.

The thesis' four estimators (sec. 4.3) live in :mod:`estimators.sun_vector`, the error
metrics in :mod:`estimators.metrics`, the sun-line EKF / UKF of the Sun vector and body rate
(Basilisk's sunlineEKF / sunlineSuKF family) in :mod:`estimators.sunline`. Nothing here imports the renderer.
"""
from functools import partial

from estimators.metrics import (angle_error_deg, hanning_mean_std, hanning_window, orbit_summary,
                                zenith_azimuth_error_deg)
from estimators.advanced import model_albedo_estimate, opposite_pairs, smart_select_estimate
from estimators.sun_vector import (albedo_sun_estimate, pinv_estimate, sun_albedo_sun_estimate,
                                   weighted_lsq, wls_estimate)
from estimators.sunline import SunlineEKF, SunlineUKF, rate_from_sun_vectors, run_sunline_filter

# The one registry: name -> estimator taking (e_p, normals, *, fov_deg, e_s0, live).
ESTIMATORS = {
    "pinv": pinv_estimate,
    "wls": wls_estimate,
    "albedo_sun": albedo_sun_estimate,
    "sun_albedo_sun_wls": partial(sun_albedo_sun_estimate, init="wls"),
    "sun_albedo_sun": partial(sun_albedo_sun_estimate, init="albedo_sun"),
    "smart_select": smart_select_estimate,
}
# The thesis' four (sec. 4.3), Sun-Albedo-Sun from both starts.
THESIS_ESTIMATORS = ("pinv", "wls", "albedo_sun", "sun_albedo_sun_wls", "sun_albedo_sun")

__all__ = ["ESTIMATORS", "THESIS_ESTIMATORS", "albedo_sun_estimate", "model_albedo_estimate", "opposite_pairs", "smart_select_estimate", "angle_error_deg", "hanning_mean_std", "hanning_window",
           "orbit_summary", "pinv_estimate", "sun_albedo_sun_estimate", "weighted_lsq", "wls_estimate",
           "zenith_azimuth_error_deg", "SunlineEKF", "SunlineUKF", "rate_from_sun_vectors", "run_sunline_filter"]
