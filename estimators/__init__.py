"""Sun-vector estimators: pure functions of diode irradiances and normals.

The thesis' four estimators (sec. 4.3) live in :mod:`estimators.sun_vector`, the error
metrics in :mod:`estimators.metrics`, the sun-line EKF / UKF of the Sun vector and body rate
(Basilisk's sunlineEKF / sunlineSuKF family) in :mod:`estimators.sunline`. Nothing here imports the renderer.
"""
from estimators.metrics import (angle_error_deg, hanning_mean_std, hanning_window, orbit_summary,
                                zenith_azimuth_error_deg)
from estimators.advanced import model_albedo_estimate, opposite_pairs, smart_select_estimate
from estimators.sun_vector import (albedo_sun_estimate, pinv_estimate, sun_albedo_sun_estimate,
                                   weighted_lsq, wls_estimate)
from estimators.sunline import SunlineEKF, SunlineUKF, rate_from_sun_vectors, run_sunline_filter

ESTIMATORS = {
    "pinv": pinv_estimate,
    "wls": wls_estimate,
    "albedo_sun": albedo_sun_estimate,
    "sun_albedo_sun": sun_albedo_sun_estimate,
    "smart_select": smart_select_estimate,
}

__all__ = ["ESTIMATORS", "albedo_sun_estimate", "model_albedo_estimate", "opposite_pairs", "smart_select_estimate", "angle_error_deg", "hanning_mean_std", "hanning_window",
           "orbit_summary", "pinv_estimate", "sun_albedo_sun_estimate", "weighted_lsq", "wls_estimate",
           "zenith_azimuth_error_deg", "SunlineEKF", "SunlineUKF", "rate_from_sun_vectors", "run_sunline_filter"]
