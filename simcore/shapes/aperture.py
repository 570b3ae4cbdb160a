"""The aperture of a diode: a square diode at the bottom of a rectangular well.

The one geometry shared by the scene builder (walls as meshes), the renderer
(which traces them) and the analytic model (which uses the closed-form
overlap below), so all three describe the same object.

Diode frame: rows ``(u, v, n)`` of a (3, 3) matrix in the body frame; ``n``
is the diode normal, ``u`` and ``v`` run along the diode's edges and the
well's walls. The diode (sides ``diode_x_m`` x ``diode_y_m``, along u and v)
lies centred on the floor of the well; the well's straight walls rise along
``n`` to ``height_m`` above the diode surface and its opening is
``opening_x_m`` x ``opening_y_m``, centred on the diode. Light from unit
direction ``d`` (diode frame, ``d_n > 0``) passes the opening and reaches the
diode plane shifted by ``-height * (d_u/d_n, d_v/d_n)``, so the lit fraction
of the diode is the overlap of the diode with the opening shifted that way.
The opening's prism is convex and contains the diode, so no wall below the
rim can block a ray that entered the opening: the overlap is exact.

A chamfer (``chamfer_m``, ``chamfer_deg``: a knife-edge or countersunk rim) bevels
the top ``c`` of the walls outward at ``alpha`` from the normal: the half opening
is ``w/2`` up to ``h - c`` and ``w/2 + (z - h + c) tan(alpha)`` above. The prism
stays convex, and a ray's offset from a wall is linear in ``z`` on each of the two
pieces, so a ray from the diode is inside for all ``z`` iff it is inside at the
lower rim (``z = h - c``) and at the top rim (``z = h``): the lit part is the
intersection of the diode with the two shifted rims, a rectangle
(:func:`lit_rectangle` with ``top``, :attr:`WellAperture.rims`). A slit is a
well of unequal sides (opening at least the diode's size along each).

A well realises a thesis-style FOV (eq. 4.15) when the whole diode is lit up
to ``fov`` along each wall axis and no light reaches it beyond ``cutoff``
(83 deg in the thesis): ``w - a = 2 h tan(fov)`` and ``w + a = 2 h tan(cutoff)``.
"""
from dataclasses import dataclass

import numpy as np

from simcore.constants import BPW34_AREA_M2, EQ415_CUTOFF_COS

EQ415_CUTOFF_DEG = float(np.degrees(np.arccos(EQ415_CUTOFF_COS)))


def lit_rectangle(half_diode_x, half_diode_y, half_open_x, half_open_y, height, du, dv, dn, *, top=None,
                  maximum=np.maximum, minimum=np.minimum, where=np.where):
    """Return (x0, x1, y0, y1, lit) for directions with diode-frame components (du, dv, dn): the
    rectangle of the diode (fractions of its sides, centred, so within [-1/2, 1/2]) whose rays
    toward the direction leave through the well's opening (the opening shifted by -h tan along
    each wall axis), and its area fraction, the lit fraction (0 where dn <= 0).

    ``top``: an optional second rim (half_open_x, half_open_y, height) the rays must also pass, e.g.
    the top of a chamfer (:attr:`WellAperture.rims`); the lit rectangle is the intersection of the
    diode with both shifted rims. Array-library neutral: numpy by default; the renderer passes Dr.Jit's
    maximum, minimum and select, so the analytic model and the renderer share this one geometry.
    """
    inv_n = 1.0 / maximum(dn, 1e-12)
    sx, sy = height * du * inv_n, height * dv * inv_n
    lo_x, hi_x = maximum(-half_diode_x, -half_open_x - sx), minimum(half_diode_x, half_open_x - sx)
    lo_y, hi_y = maximum(-half_diode_y, -half_open_y - sy), minimum(half_diode_y, half_open_y - sy)
    if top is not None:
        top_x, top_y, top_h = top
        tx, ty = top_h * du * inv_n, top_h * dv * inv_n
        lo_x, hi_x = maximum(lo_x, -top_x - tx), minimum(hi_x, top_x - tx)
        lo_y, hi_y = maximum(lo_y, -top_y - ty), minimum(hi_y, top_y - ty)
    x0, x1 = lo_x / (2.0 * half_diode_x), hi_x / (2.0 * half_diode_x)
    y0, y1 = lo_y / (2.0 * half_diode_y), hi_y / (2.0 * half_diode_y)
    lit = where(dn > 0, maximum(x1 - x0, 0.0) * maximum(y1 - y0, 0.0), 0.0)
    return x0, x1, y0, y1, lit


def lit_rectangle_of(params, du, dv, dn, **ops):
    """Return :func:`lit_rectangle` for an aperture's 8 parameters ``params`` (a sequence: half diode
    x, y, half opening x, y and height of the lower rim, then of the top rim; :attr:`WellAperture.rims`,
    or its columns for many diodes; 5 parameters: one rim)."""
    p = list(params)
    return lit_rectangle(*p[:5], du, dv, dn, top=p[5:8] if len(p) > 5 else None, **ops)


@dataclass(frozen=True)
class WellAperture:
    """A rectangular well of straight walls, optionally chamfered at the top, over a rectangular diode (metres)."""

    diode_x_m: float
    diode_y_m: float
    opening_x_m: float
    opening_y_m: float
    height_m: float
    chamfer_m: float = 0.0
    chamfer_deg: float = 0.0

    def __post_init__(self):
        for name in ("diode_x_m", "diode_y_m", "opening_x_m", "opening_y_m"):
            if not (getattr(self, name) > 0 and np.isfinite(getattr(self, name))):
                raise ValueError(f"aperture {name} must be a positive length in metres, got {getattr(self, name)}")
        if not (self.height_m >= 0 and np.isfinite(self.height_m)):
            raise ValueError(f"aperture height_m must be >= 0 metres, got {self.height_m}")
        if self.opening_x_m < self.diode_x_m or self.opening_y_m < self.diode_y_m:
            raise ValueError("the well's opening must be at least as large as the diode it sits over "
                             f"(opening {self.opening_x_m} x {self.opening_y_m} m, "
                             f"diode {self.diode_x_m} x {self.diode_y_m} m)")
        if not (0.0 <= self.chamfer_m <= self.height_m and np.isfinite(self.chamfer_m)):
            raise ValueError(f"the chamfer ({self.chamfer_m} m) must lie between 0 and the well's height "
                             f"({self.height_m} m)")
        if not (0.0 <= self.chamfer_deg < 90.0):
            raise ValueError(f"the chamfer angle must lie in [0, 90) deg from the diode normal, got {self.chamfer_deg}")

    @property
    def rims(self):
        """Return the 8 parameters of the geometry (m): half diode x, y; the straight walls' half opening x, y and
        their top (the lower rim, height - chamfer); the top rim's half opening x, y (widened by chamfer x
        tan(chamfer_deg) on each side) and its height. For a well without chamfer both rims are the same."""
        widen = self.chamfer_m * float(np.tan(np.radians(self.chamfer_deg)))
        wx, wy = self.opening_x_m / 2, self.opening_y_m / 2
        return (self.diode_x_m / 2, self.diode_y_m / 2, wx, wy, self.height_m - self.chamfer_m,
                wx + widen, wy + widen, self.height_m)

    exact_rectangle = True      # the lit part is the rectangle of rims: the renderer's aperture split is exact

    @property
    def hint_rims(self):
        """Return :attr:`rims`: the renderer's albedo hint is the exact lit rectangle."""
        return self.rims

    @classmethod
    def bare(cls, diode_area_m2=BPW34_AREA_M2):
        """Return a square diode with no well (pure cosine response)."""
        a = float(np.sqrt(diode_area_m2))
        return cls(a, a, a, a, 0.0)

    @classmethod
    def design(cls, fov_deg, cutoff_deg=EQ415_CUTOFF_DEG, diode_area_m2=BPW34_AREA_M2):
        """Return the square well fully lighting a square diode up to ``fov_deg``
        along the wall axes and cutting it off at ``cutoff_deg`` (eq. 4.15)."""
        fov, cut = np.radians(float(fov_deg)), np.radians(float(cutoff_deg))
        if not 0 < fov < np.pi / 2:
            raise ValueError(f"FOV must lie in (0, 90) deg, got {fov_deg}")
        if not fov < cut < np.pi / 2:
            raise ValueError(f"cut-off angle must lie between the FOV ({fov_deg} deg) and 90 deg, got {cutoff_deg}")
        a = float(np.sqrt(diode_area_m2))
        h = a / (np.tan(cut) - np.tan(fov))
        w = a + 2.0 * h * np.tan(fov)
        return cls(a, a, float(w), float(w), float(h))

    @property
    def diode_area_m2(self):
        return self.diode_x_m * self.diode_y_m

    def lit_fraction(self, d_diode):
        """Return the lit fraction of the diode (0..1) for unit directions ``d_diode`` (..., 3)
        towards the source, in the diode frame (u, v, n)."""
        d = np.asarray(d_diode, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return lit_rectangle_of(self.rims, d[..., 0], d[..., 1], d[..., 2])[4]

    def response(self, d_diode):
        """Return the angular response (lit fraction x cos incidence) for directions (..., 3)
        in the diode frame: irradiance on the diode per unit normal irradiance."""
        d = np.asarray(d_diode, dtype=float)
        return self.lit_fraction(d) * np.clip(d[..., 2], 0.0, None)


class _NumpyOps:
    """numpy's functions under the names the array-library neutral formulas below use."""
    maximum, minimum, where, sqrt, asin = np.maximum, np.minimum, np.where, np.sqrt, np.arcsin


def _disc_quadrant_area(a, b, r, ops=_NumpyOps):
    """Return the area of the disc of radius ``r`` centred at the origin with x <= a and y <= b (closed
    form, arrays broadcast): the integral over x <= a of the chord length below y = b, piecewise in the
    antiderivative S(x) = (x sqrt(r^2 - x^2) + r^2 asin(x / r)) / 2 of the half chord.

    Array-library neutral: ``ops`` gives maximum, minimum, where, sqrt and asin (numpy by default; the
    analytic albedo sum passes Dr.Jit's), so the closed form and its kernel form are one formula."""
    mx, mn, where = ops.maximum, ops.minimum, ops.where

    def clip(x, lo, hi):
        return mn(mx(x, lo), hi)

    def S(x):
        x = clip(x, -r, r)
        return 0.5 * (x * ops.sqrt(mx(r * r - x * x, 0.0)) + r * r * ops.asin(clip(x / r, -1.0, 1.0)))

    s_lo = -0.25 * np.pi * r * r                               # S(-r)
    hi = clip(a, -r, r)                                        # x runs over [-r, hi]
    c = ops.sqrt(mx(r * r - b * b, 0.0))                       # |x| <= c: the chord straddles y = b
    # |x| <= c: the chord's part below b has length b + s(x) (for either sign of b)
    lo_in, hi_in = -c, mn(c, hi)
    inner = where(hi_in > lo_in, b * (hi_in - lo_in) + S(hi_in) - S(lo_in), 0.0)
    # |x| > c: the whole chord (2 s(x)) when b >= 0, none of it when b < 0
    left = 2.0 * (S(mn(hi, -c)) - s_lo)
    right = where(hi > c, 2.0 * (S(hi) - S(c)), 0.0)
    outer = where(b >= 0, left + right, 0.0)
    return inner + outer


def disc_rectangle_overlap(cx, cy, r, x0, x1, y0, y1, ops=None):
    """Return the area of the disc of centre (cx, cy) and radius ``r`` > 0 inside the rectangle [x0, x1] x
    [y0, y1] (closed form, any units, arrays broadcast; 0 for an empty rectangle). ``ops``: None for numpy
    arrays, or an object with maximum, minimum, where, sqrt and asin (e.g. Dr.Jit's) for a rectangle known
    not to be empty."""
    if ops is None:
        cx, cy, r, x0, x1, y0, y1 = np.broadcast_arrays(*(np.asarray(v, dtype=float)
                                                          for v in (cx, cy, r, x0, x1, y0, y1)))
    q = (lambda a, b, rr: _disc_quadrant_area(a, b, rr)) if ops is None else \
        (lambda a, b, rr: _disc_quadrant_area(a, b, rr, ops))
    area = q(x1 - cx, y1 - cy, r) - q(x0 - cx, y1 - cy, r) - q(x1 - cx, y0 - cy, r) + q(x0 - cx, y0 - cy, r)
    if ops is not None:
        return ops.maximum(area, 0.0)
    return np.where((x1 > x0) & (y1 > y0), np.maximum(area, 0.0), 0.0)


@dataclass(frozen=True)
class CircularWell:
    """A round well (a straight cylinder of radius ``radius_m``, ``height_m`` high) over a rectangular diode
    (metres), centred on it. The cylinder contains the diode, so, as for :class:`WellAperture`, only its rim
    limits the light: a ray from the diode toward ``d`` leaves through the rim's circle shifted by
    ``-height * (d_u/d_n, d_v/d_n)``, and the lit fraction is the diode's overlap with that disc
    (:func:`disc_rectangle_overlap`), exact."""

    diode_x_m: float
    diode_y_m: float
    radius_m: float
    height_m: float

    def __post_init__(self):
        for name in ("diode_x_m", "diode_y_m", "radius_m"):
            if not (getattr(self, name) > 0 and np.isfinite(getattr(self, name))):
                raise ValueError(f"circular well {name} must be a positive length in metres, got {getattr(self, name)}")
        if not (self.height_m >= 0 and np.isfinite(self.height_m)):
            raise ValueError(f"circular well height_m must be >= 0 metres, got {self.height_m}")
        if self.radius_m < 0.5 * np.hypot(self.diode_x_m, self.diode_y_m):
            raise ValueError(f"a circular well's radius ({self.radius_m} m) must reach the diode's corners "
                             f"(half diagonal {0.5 * np.hypot(self.diode_x_m, self.diode_y_m):.6g} m): the "
                             "cylinder must contain the diode")

    @property
    def diode_area_m2(self):
        return self.diode_x_m * self.diode_y_m

    exact_rectangle = False     # the lit part is not a rectangle: the renderer samples its diode plainly

    @property
    def opening_x_m(self):
        """The rim's diameter (m): the side of the square around it (the mount's floor plate and footprint)."""
        return 2.0 * self.radius_m

    opening_y_m = opening_x_m

    @property
    def rims(self):
        """Return the 8 parameters of :attr:`WellAperture.rims` for the square inscribed in the rim (half side
        r / sqrt 2, same height): its lit rectangle lies inside the disc's lit part (the cylinder is convex
        and contains the diode), so the renderer's probe rays from it (what shades the diode besides its own
        well) meet none of the well's own walls."""
        w = self.radius_m / np.sqrt(2.0)
        return (self.diode_x_m / 2, self.diode_y_m / 2, w, w, self.height_m, w, w, self.height_m)

    @property
    def hint_rims(self):
        """Return :attr:`rims` for the square circumscribed about the rim (half side r): its lit rectangle
        holds the disc's lit part, a superset for the albedo sampling's proposal (unbiased)."""
        r = self.radius_m
        return (self.diode_x_m / 2, self.diode_y_m / 2, r, r, self.height_m, r, r, self.height_m)

    def kernel(self, du, dv, dn, ops):
        """Return the response (lit fraction x cos) on generic arrays (numpy or Dr.Jit through ``ops``: maximum,
        minimum, where, tiny, sqrt, asin): :func:`disc_rectangle_overlap` of the diode with the rim's disc
        shifted by -h (du, dv) / dn, over the diode's area, times dn; 0 from behind."""
        inv = 1.0 / ops.maximum(dn, ops.tiny)
        cx, cy = -self.height_m * du * inv, -self.height_m * dv * inv
        hx, hy = self.diode_x_m / 2, self.diode_y_m / 2
        area = disc_rectangle_overlap(cx, cy, self.radius_m, -hx, hx, -hy, hy, ops=ops)
        return ops.where(dn > 0, area * (1.0 / self.diode_area_m2) * dn, 0.0)

    def lit_fraction(self, d_diode):
        """Return the lit fraction of the diode (0..1) for unit directions ``d_diode`` (..., 3) towards the
        source, in the diode frame (u, v, n); 0 from behind."""
        d = np.asarray(d_diode, dtype=float)
        dn = d[..., 2]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = np.where(dn > 0, 1.0 / np.where(dn > 0, dn, 1.0), 0.0)
            cx, cy = -self.height_m * d[..., 0] * inv, -self.height_m * d[..., 1] * inv
        hx, hy = self.diode_x_m / 2, self.diode_y_m / 2
        area = disc_rectangle_overlap(cx, cy, self.radius_m, -hx, hx, -hy, hy)
        return np.where(dn > 0, area / self.diode_area_m2, 0.0)

    def response(self, d_diode):
        """Return the angular response (lit fraction x cos incidence) for directions (..., 3) in the
        diode frame: irradiance on the diode per unit normal irradiance."""
        d = np.asarray(d_diode, dtype=float)
        return self.lit_fraction(d) * np.clip(d[..., 2], 0.0, None)


def diode_frame(normal_body):
    """Return the (3, 3) diode frame (rows u, v, n) for a unit normal in the body frame.

    ``u`` is horizontal (perpendicular to the body z axis), ``u = z x n``
    normalised; for a normal along +-z, ``u`` is the body x axis. ``v = n x u``.
    """
    n = np.asarray(normal_body, dtype=float)
    norm = np.linalg.norm(n)
    if not np.isclose(norm, 1.0, atol=1e-6):
        raise ValueError(f"a diode normal must be a unit vector, got {n.tolist()} (norm {norm:.6f})")
    u = np.cross([0.0, 0.0, 1.0], n)
    if np.linalg.norm(u) < 1e-9:
        u = np.array([1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return np.stack([u, v, n])
