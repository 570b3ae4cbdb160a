"""The geomagnetic field along the orbit (IGRF via ``ppigrf``) and a three-axis magnetometer model.

The field: the International Geomagnetic Reference Field (IGRF-14 by default; the
coefficient files ship with ``ppigrf``), a spherical-harmonic model of the main field to
degree 13, evaluated at the satellite's geocentric position in ITRS (ECEF) and rotated into
GCRS. Units: tesla inside (the model and the data sheets use nT: converted at the edge).
The model's secular variation (~100 nT/yr) is evaluated at one date per call (the run's
middle epoch): over a day it changes the field by < 1 nT.

The magnetometer (body frame): ``b_meas = Q[(I + dS + M) b_true + b_0 + n]`` with white noise
``n`` of the data sheet's 1-sigma noise, and the residual bias, scale-factor and cross-axis
errors after calibration drawn once per seed from N(0, (3-sigma value / 3)^2) per axis;
``Q``: quantisation to the resolution. Specs in ``simcore/data/magnetometers.toml``.
"""
from dataclasses import dataclass

import numpy as np

from simcore.sensor.parts import PartSpec, find_part, load_parts

NT = 1e-9


def igrf_ecef_t(r_ecef_m, date, *, coeff_file=None):
    """Return the IGRF main field B (N, 3), tesla, ITRS (ECEF) axes, at positions ``r_ecef_m`` (N, 3) m.

    ``date``: a datetime (the model's epoch interpolation); ``coeff_file``: an ``.shc`` file
    (default: the newest IGRF shipped with ppigrf).
    """
    import ppigrf
    r = np.atleast_2d(np.asarray(r_ecef_m, dtype=float))
    if r.shape[1] != 3:
        raise ValueError(f"r_ecef_m must be (N, 3) metres, got shape {r.shape}")
    rn = np.linalg.norm(r, axis=1)
    theta = np.arccos(np.clip(r[:, 2] / rn, -1.0, 1.0))
    phi = np.arctan2(r[:, 1], r[:, 0])
    kw = {} if coeff_file is None else {"coeff_fn": coeff_file}
    br, bt, bp = ppigrf.igrf_gc(rn / 1e3, np.degrees(theta), np.degrees(phi), date, **kw)
    br, bt, bp = (np.asarray(x, dtype=float).reshape(-1) for x in (br, bt, bp))
    st, ct, sp, cp = np.sin(theta), np.cos(theta), np.sin(phi), np.cos(phi)
    r_hat = np.stack([st * cp, st * sp, ct], axis=1)
    t_hat = np.stack([ct * cp, ct * sp, -st], axis=1)
    p_hat = np.stack([-sp, cp, np.zeros_like(sp)], axis=1)
    return (br[:, None] * r_hat + bt[:, None] * t_hat + bp[:, None] * p_hat) * NT


def field_gcrs_t(epochs, r_sat_ecef_m, *, coeff_file=None):
    """Return the IGRF field (N, 3), tesla, GCRS axes, at the satellite along ``epochs`` (simcore.Epochs)."""
    from simcore.environment.frames import R_itrs_from_gcrs
    mid = epochs.datetime64[len(epochs) // 2].astype("datetime64[us]").item()
    b_ecef = igrf_ecef_t(r_sat_ecef_m, mid, coeff_file=coeff_file)
    return np.einsum("nji,nj->ni", R_itrs_from_gcrs(epochs), b_ecef)


@dataclass(frozen=True)
class MagnetometerSpec(PartSpec):
    """A three-axis magnetometer, SI (tesla); 3-sigma residuals after calibration."""

    noise_t: float
    resolution_t: float = 0.0
    bias_residual_t: float = 0.0
    scale_factor_residual: float = 0.0
    cross_axis: float = 0.0
    assumed: str = ""


_UNITS = {"noise_nt": ("noise_t", NT), "resolution_nt": ("resolution_t", NT),
          "bias_residual_nt": ("bias_residual_t", NT),
          "scale_factor_residual_pct": ("scale_factor_residual", 0.01), "cross_axis_pct": ("cross_axis", 0.01)}


def load_magnetometers():
    """Return {name: MagnetometerSpec} of the shipped table ``simcore/data/magnetometers.toml``."""
    return load_parts("magnetometers.toml", MagnetometerSpec, _UNITS)


def magnetometer_spec(name):
    """Return the MagnetometerSpec called ``name`` (case-insensitive), or raise a one-line error naming close matches."""
    return find_part(name, load_magnetometers(), "magnetometer")


class MagnetometerModel:
    """A magnetometer instance with its calibration residuals drawn once from ``seed``."""

    def __init__(self, spec, seed=0):
        self.spec = magnetometer_spec(spec) if isinstance(spec, str) else spec
        self.rng = np.random.default_rng(seed)
        s = self.spec
        self.bias_t = self.rng.normal(0.0, s.bias_residual_t / 3.0, 3)
        off = self.rng.normal(0.0, s.cross_axis / 3.0, (3, 3))
        np.fill_diagonal(off, 0.0)
        self.gain_matrix = np.eye(3) + np.diag(self.rng.normal(0.0, s.scale_factor_residual / 3.0, 3)) + off

    def measure(self, b_body_t):
        """Return readings (N, 3), tesla, body frame, of the true field ``b_body_t`` (N, 3)."""
        b = np.atleast_2d(np.asarray(b_body_t, dtype=float))
        out = b @ self.gain_matrix.T + self.bias_t + self.rng.normal(0.0, self.spec.noise_t, b.shape)
        q = self.spec.resolution_t
        return q * np.rint(out / q) if q > 0 else out
