"""Angular responses of a diode: irradiance on it per unit irradiance normal to the rays.

Every response is a small object with ``response(d_diode)``: for unit
directions towards the source, ``d_diode`` (..., 3) in the diode frame
(u, v, n) of :func:`simcore.shapes.aperture.diode_frame`, it returns the factor
(..., ) that turns the irradiance normal to the rays into the irradiance on
the diode (W/m^2 on its sensitive area). A bare ideal diode gives cos(theta).

* :class:`CosineResponse` -- the ideal (Lambertian) diode, ``max(0, n . d)``.
* :class:`ReflectionResponse` -- thesis eq. 2.32 (Ortega et al. 2010), the
  package's reflection losses ``I = (I_max - I_0) cos(theta) + I_0``.
* :class:`Eq415Response` -- thesis eq. 4.15, the linear FOV cut-off.
* :class:`simcore.shapes.aperture.WellAperture` (and ``CircularWell``, a round hole) -- the real aperture: the exact
  overlap of the diode with the well's opening projected along ``d``, times
  cos(theta) -- the geometry the renderer traces. Used as it is.

Each response also has a kernel form (:func:`kernel`) written with generic
``maximum/minimum/where`` so that :mod:`simcore.radiometry.analytic` can evaluate it
on numpy or Dr.Jit arrays; the tests check the two forms agree.
"""
from dataclasses import dataclass

import numpy as np

from simcore.shapes.aperture import CircularWell, WellAperture
from simcore.constants import EQ415_CUTOFF_COS


def _erf(x):
    from scipy.special import erf
    return erf(x)


class _NumpyOps:
    """Array operations used by the response kernels, numpy flavour."""

    maximum = staticmethod(np.maximum)
    minimum = staticmethod(np.minimum)
    where = staticmethod(np.where)
    sqrt, exp, log, floor = staticmethod(np.sqrt), staticmethod(np.exp), staticmethod(np.log), staticmethod(np.floor)
    asin = staticmethod(np.arcsin)
    erf = staticmethod(_erf)
    tiny = 1e-300


NUMPY_OPS = _NumpyOps()


def _as_dirs(d_diode):
    d = np.asarray(d_diode, dtype=float)
    if d.shape[-1:] != (3,):
        raise ValueError(f"directions must have shape (..., 3) in the diode frame (u, v, n), got {d.shape}")
    return d


@dataclass(frozen=True)
class CosineResponse:
    """The ideal diode: response = max(0, cos(theta)) (thesis eq. 2.20)."""

    def response(self, d_diode):
        """Return max(0, d_n) for unit directions (..., 3) in the diode frame."""
        return np.maximum(_as_dirs(d_diode)[..., 2], 0.0)

    def kernel(self, du, dv, dn, ops):
        return ops.maximum(dn, 0.0)


@dataclass(frozen=True)
class ReflectionResponse:
    """Thesis eq. 2.32, ``I = (I_max - I_0) cos(theta) + I_0``, normalised to 1 at normal incidence.

    ``i0_ratio`` = I_0 / I_max. The response is ``(1 - i0_ratio) cos + i0_ratio``
    for cos > 0, never negative, and 0 from behind. The thesis' fig. 3.3
    draws the reflection case with ``a = I_max - I_0 = 1`` and ``b = I_0 = -0.2``,
    i.e. ``i0_ratio = -0.2 / 0.8 = -0.25``: a diode that loses light to
    reflection at grazing incidence and goes dark below cos = 0.2 (78.5 deg).
    """

    i0_ratio: float

    def __post_init__(self):
        r = float(self.i0_ratio)
        if not (np.isfinite(r) and r < 1):
            raise ValueError(f"i0_ratio = I_0/I_max must be finite and < 1 (the response must grow with cos), got {r}")
        object.__setattr__(self, "i0_ratio", r)

    @classmethod
    def from_currents(cls, i_max, i_0):
        """Return the response of eq. 2.32 for the currents I_max (at normal incidence) and I_0."""
        return cls(float(i_0) / float(i_max))

    def response(self, d_diode):
        """Return the eq. 2.32 response for unit directions (..., 3) in the diode frame."""
        d = _as_dirs(d_diode)
        return self.kernel(d[..., 0], d[..., 1], d[..., 2], NUMPY_OPS)

    def kernel(self, du, dv, dn, ops):
        r = self.i0_ratio
        return ops.where(dn > 0, ops.maximum((1.0 - r) * dn + r, 0.0), 0.0)


@dataclass(frozen=True)
class Eq415Response:
    """Thesis eq. 4.15: the FOV limit of an aperture, linear in the cosine C = n . d.

    ``A = C`` for ``C >= cos(FOV)``; ``A = C (C - c0)/(cos(FOV) - c0)`` for
    ``cos(FOV) > C >= c0``; ``A = 0`` below ``c0`` (``cutoff_cos``, 0.12 in the
    thesis: arccos 0.12 = 83.1 deg, where light no longer reaches the diode).
    """

    fov_deg: float
    cutoff_cos: float = EQ415_CUTOFF_COS

    def __post_init__(self):
        fov = float(self.fov_deg)
        c0 = float(self.cutoff_cos)
        if not 0 < fov < 90:
            raise ValueError(f"fov_deg must lie in (0, 90) deg, got {self.fov_deg}")
        if not 0 <= c0 < np.cos(np.radians(fov)):
            raise ValueError(f"cutoff_cos must lie in [0, cos(FOV) = {np.cos(np.radians(fov)):.4f}), got {c0}")
        object.__setattr__(self, "fov_deg", fov)
        object.__setattr__(self, "cutoff_cos", c0)

    @property
    def cos_fov(self):
        return float(np.cos(np.radians(self.fov_deg)))

    def response(self, d_diode):
        """Return the eq. 4.15 response for unit directions (..., 3) in the diode frame."""
        d = _as_dirs(d_diode)
        return self.kernel(d[..., 0], d[..., 1], d[..., 2], NUMPY_OPS)

    def kernel(self, du, dv, dn, ops):
        cf, c0 = self.cos_fov, self.cutoff_cos
        ramp = dn * (dn - c0) * (1.0 / (cf - c0))
        return ops.where(dn >= cf, dn, ops.where(dn >= c0, ramp, 0.0))


def _well_kernel(ap: WellAperture):
    """Return the kernel of a :class:`WellAperture`: lit fraction x cos, the overlap of aperture.py in
    homogeneous form (multiplied through by d_n so no division is needed), with both rims of a chamfer."""
    ax, ay = ap.diode_x_m / 2, ap.diode_y_m / 2
    wx, wy = ap.opening_x_m / 2, ap.opening_y_m / 2
    h = ap.height_m - ap.chamfer_m
    tx, ty, th = ap.rims[5:8]
    chamfered = (tx, ty, th) != (wx, wy, h)
    scale = 1.0 / (ap.diode_x_m * ap.diode_y_m)

    def kernel(du, dv, dn, ops):
        # overlap of [-a, a] with [-w - s, w - s], s = h du/dn, times dn (dn > 0)
        hx, hy = h * du, h * dv
        hi_x, lo_x = ops.minimum(ax * dn, wx * dn - hx), ops.maximum(-ax * dn, -wx * dn - hx)
        hi_y, lo_y = ops.minimum(ay * dn, wy * dn - hy), ops.maximum(-ay * dn, -wy * dn - hy)
        if chamfered:      # ... and with the top rim's [-w' - s', w' - s'] (WellAperture.rims)
            hi_x, lo_x = ops.minimum(hi_x, tx * dn - th * du), ops.maximum(lo_x, -tx * dn - th * du)
            hi_y, lo_y = ops.minimum(hi_y, ty * dn - th * dv), ops.maximum(lo_y, -ty * dn - th * dv)
        lx = ops.maximum(hi_x - lo_x, 0.0)
        ly = ops.maximum(hi_y - lo_y, 0.0)
        # lit fraction x cos = (lx/dn)(ly/dn)/(4 a_x a_y) x dn = lx ly / (dn (4 a_x a_y))
        return ops.where(dn > 0, lx * ly * scale / ops.maximum(dn, ops.tiny), 0.0)

    return kernel


def kernel(resp):
    """Return ``f(du, dv, dn, ops)``, the response of ``resp`` on generic arrays (numpy or Dr.Jit)."""
    if isinstance(resp, WellAperture):
        return _well_kernel(resp)
    if hasattr(resp, "kernel"):
        return resp.kernel
    raise TypeError(f"{type(resp).__name__} has no kernel form; use CosineResponse, ReflectionResponse, "
                    "Eq415Response or simcore.shapes.aperture.WellAperture (or any object with "
                    "response(d_diode) together with backend='numpy')")


def check_response(resp):
    """Return ``resp`` if it has a ``response(d_diode)`` method, else raise TypeError."""
    if not callable(getattr(resp, "response", None)):
        raise TypeError(f"an angular response needs a response(d_diode) method; got {type(resp).__name__}. "
                        "Use CosineResponse(), ReflectionResponse(i0_ratio), Eq415Response(fov_deg) or "
                        "simcore.shapes.aperture.WellAperture.design(fov_deg)")
    return resp
