"""A cover glass or filter window over a diode: a plane-parallel dielectric slab, exact to the Fresnel law.

Geometry (diode frame, rows (u, v, n); metres): the slab is parallel to the diode, centred on its normal
axis, its lower face ``gap_m`` above the diode surface, ``thickness_m`` thick, its sides ``size_m`` along
u and v. Light reaching a diode point p from the unit direction d (toward the source, ``d_n = cos theta >
0``) went, traced backwards: straight from p to the lower face (meets it at p1), refracted into the glass
(Snell: ``sin theta_t = sin theta / n``), up to the upper face, k round trips between the faces (each adds
``2 t tan theta_t`` of lateral walk along d's lateral direction), refracted out of the upper face and on
along d (a parallel slab gives back the incoming direction). Term k leaves the upper face at

    p + (gap tan theta + (2 k + 1) t tan theta_t) * lateral(d) + (gap + t) n

and carries, per polarisation, ``(1 - R)^2 R^(2k) a^(2k+1)`` of the light, R the Fresnel reflectance for
that polarisation at theta (the same at every face: the two media swap, reciprocity), a = exp(-alpha t /
cos theta_t) the single-pass absorption. The s and p polarisations keep one plane of incidence through all
faces, so two scalar weights are exact; the Sun is unpolarised: the mean over s and p. Over k = 0..inf
the sum is the slab's transmittance ``(1 - R)^2 a / (1 - R^2 a^2)`` per polarisation, ``(1 - R) / (1 + R)``
without absorption (Born & Wolf, Principles of Optics, 7th ed., sec. 1.5 and 1.6; incoherent multiple
reflections). The window's edge faces are black (as mounted windows are): a term whose exit point lies
outside the footprint contributes nothing.

:class:`WindowedWell` is the closed-form angular response of a diode in a well under such a window (the
analytic model's reference): per term, the part of the well's lit rectangle whose exit point stays in the
footprint is a rectangle overlap. The renderer traces the same slab per sample
(``simcore.render.windows``).
"""
from dataclasses import dataclass

import numpy as np

INDEX_RANGE = (1.0, 4.0)            # (exclusive, inclusive): glasses 1.4-1.9, sapphire 1.77, germanium 4.0
_TAIL = 1e-17                       # terms below this share of the first are dropped (double precision)
# The kernel form (WindowedWell.kernel) sums the terms that the footprint cuts in part up to this many past the
# last whole one: what it leaves out is below q^KERNEL_PARTIAL_TERMS of the light, q = (R a)^2 (< 1e-4 of it
# below 84 deg incidence for n = 1.5: R_s = 0.56 there), and only where the footprint's edge takes some terms.
KERNEL_PARTIAL_TERMS = 16


def fresnel_reflectance(cos_i, n):
    """Return (R_s, R_p): the Fresnel power reflectances for light from air (index 1) meeting a medium of
    index ``n`` at incidence cos_i (arrays), s (TE) and p (TM) polarisation; the same for light leaving the
    medium at the refracted angle (Born & Wolf sec. 1.5.2, eqs. 20-21 squared)."""
    c = np.clip(np.asarray(cos_i, float), 0.0, 1.0)
    s_t = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / n
    c_t = np.sqrt(np.maximum(1.0 - s_t * s_t, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = np.where(c > 0, ((c - n * c_t) / (c + n * c_t)) ** 2, 1.0)
        rp = np.where(c > 0, ((c_t - n * c) / (c_t + n * c)) ** 2, 1.0)
    return rs, rp


@dataclass(frozen=True)
class Window:
    """A plane-parallel window over a diode (module docstring): refractive ``index`` (> 1), ``thickness_m``,
    ``gap_m`` (diode surface to the lower face), ``size_m`` (sides along u and v) and ``absorption_per_m``
    (the glass' absorption coefficient alpha, 1/m)."""

    index: float
    thickness_m: float
    gap_m: float
    size_m: tuple
    absorption_per_m: float = 0.0

    def __post_init__(self):
        size = tuple(float(x) for x in self.size_m)
        vals = (self.index, self.thickness_m, self.gap_m, *size, self.absorption_per_m)
        if len(size) != 2 or not all(np.isfinite(vals)):
            raise ValueError(f"a window needs finite numbers and two sides, got {self}")
        if not (INDEX_RANGE[0] < self.index <= INDEX_RANGE[1] and self.thickness_m > 0 and self.gap_m >= 0
                and min(size) > 0 and self.absorption_per_m >= 0):
            raise ValueError(f"a window needs index in (1, 4], thickness > 0, gap >= 0, sides > 0 and "
                             f"absorption >= 0; got {self}")
        object.__setattr__(self, "size_m", size)

    def terms(self, cos_theta):
        """Return (c, q) (..., 2) for s and p: term k of the slab carries ``c q^k`` of the light arriving at
        angle theta (cos_theta > 0): c = (1 - R)^2 a, q = R^2 a^2 (module docstring)."""
        c = np.asarray(cos_theta, float)
        rs, rp = fresnel_reflectance(c, self.index)
        r = np.stack([rs, rp], axis=-1)
        s_t = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / self.index
        c_t = np.sqrt(np.maximum(1.0 - s_t * s_t, 0.0))
        a = np.exp(-self.absorption_per_m * self.thickness_m / c_t)[..., None]
        return (1.0 - r) ** 2 * a, (r * a) ** 2

    def transmittance(self, cos_theta):
        """Return the transmittance (...,) of the infinite slab for unpolarised light at angle theta: the mean
        over s and p of c / (1 - q), = (1 - R) / (1 + R) each without absorption."""
        c, q = self.terms(cos_theta)
        return np.mean(_geometric(c, q, 0.0), axis=-1)

    def exit_offsets(self, d_diode):
        """Return (first, step) (..., 2) metres in the diode's (u, v): term k of the slab leaves the upper face
        at p + first + k step (lateral; module docstring) for unit directions ``d_diode`` (..., 3), d_n > 0."""
        d = np.asarray(d_diode, float)
        dn = np.maximum(d[..., 2], 1e-300)
        s_t = np.sqrt(np.maximum(1.0 - dn * dn, 0.0)) / self.index
        c_t = np.sqrt(np.maximum(1.0 - s_t * s_t, 0.0))
        # lateral(d) tan theta = d_uv / d_n; inside: d_uv / (n cos theta_t)
        inner = self.thickness_m / (self.index * c_t)
        first = d[..., :2] * (self.gap_m / dn + inner)[..., None]
        return first, d[..., :2] * (2.0 * inner)[..., None]


def _geometric(c, q, q_end):
    """Return c (1 - q_end) / (1 - q), the sum of c q^k up to the term before q_end = q^(K+1); 0 where q = 1
    (grazing incidence: R = 1, c = 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(q < 1.0, c * (1.0 - q_end) / np.where(q < 1.0, 1.0 - q, 1.0), 0.0)


def _overlap(lo, hi, off, half):
    """Return the length of [lo, hi] inside [-half - off, half - off] (arrays)."""
    return np.maximum(np.minimum(hi, half - off) - np.maximum(lo, -half - off), 0.0)


@dataclass(frozen=True)
class WindowedWell:
    """The angular response of a diode in a well (``well``: a :class:`simcore.shapes.aperture.WellAperture`)
    under a ``window`` (:class:`Window`, its lower face on or above the well's rim), closed form: irradiance on
    the diode per unit normal irradiance, for unit directions in the diode frame."""

    well: object
    window: Window

    def response(self, d_diode):
        """Return sum over the slab's terms k of c q^k (mean over s, p) x the share of the diode that the well
        lights and whose k-th exit point lies in the window's footprint, x cos theta; (...,) for directions
        (..., 3) in the diode frame (0 behind the diode)."""
        from simcore.shapes.aperture import lit_rectangle_of
        w = self.well
        d = np.asarray(d_diode, float)
        shape = d.shape[:-1]
        d = d.reshape(-1, 3)
        out = np.zeros(len(d))
        front = d[:, 2] > 0
        if not front.any():
            return out.reshape(shape)
        d = d[front]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x0, x1, y0, y1, lit = lit_rectangle_of(w.rims, d[:, 0], d[:, 1], d[:, 2])    # a chamfer's top rim too
        # the lit rectangle in metres (u, v)
        lo = np.stack([x0 * w.diode_x_m, y0 * w.diode_y_m], -1)
        hi = np.stack([x1 * w.diode_x_m, y1 * w.diode_y_m], -1)
        half = np.array(self.window.size_m) / 2
        first, step = self.window.exit_offsets(d)
        c, q = self.window.terms(d[:, 2])                                    # (T, 2)
        area = w.diode_x_m * w.diode_y_m
        # Terms 0..kf keep the whole lit rectangle in the footprint, terms >= ke none of it (per axis, from
        # the footprint's edge on the side the exit points walk toward); the terms between: overlaps.
        sgn = np.sign(step)
        astep = np.abs(step)
        room_full = half - np.where(sgn > 0, hi, -lo) - np.abs(first)
        room_none = half - np.where(sgn > 0, lo, -hi) - np.abs(first)
        with np.errstate(divide="ignore", invalid="ignore"):
            kf_ax = np.where(astep > 0, np.floor(room_full / astep), np.where(room_full >= 0, np.inf, -1.0))
            ke_ax = np.where(astep > 0, np.floor(room_none / astep) + 1.0, np.where(room_none > 0, np.inf, 0.0))
        kf = np.maximum(np.min(kf_ax, axis=1), -1.0)                          # (T,)
        ke = np.maximum(np.min(ke_ax, axis=1), 0.0)
        lit_ok = lit > 0
        # full terms: c (1 - q^(kf+1)) / (1 - q) x lit
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            qk = np.where(np.isinf(kf)[:, None], 0.0, q ** (kf + 1.0)[:, None])
        full = np.mean(_geometric(c, q, qk), axis=1) * lit
        # partial terms kf+1 .. ke-1, until the terms fall below _TAIL of the first
        start = kf + 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            qmax = np.minimum(q.max(axis=1), 1.0 - 1e-16)
            n_tail = np.where(qmax > 0, np.ceil(np.log(_TAIL) / np.log(np.maximum(qmax, 1e-300))), 1)
            span = ke - start
            n_part = np.where(np.isfinite(span), np.clip(span, 0, None), 0)
        n_part = np.minimum(n_part, n_tail).astype(np.int64)
        part = np.zeros(len(d))
        for j in range(int(n_part.max(initial=0))):
            on = (j < n_part) & lit_ok
            if not on.any():
                continue
            k = start[on] + j
            off = first[on] + k[:, None] * step[on]
            lx = _overlap(lo[on, 0], hi[on, 0], off[:, 0], half[0])
            ly = _overlap(lo[on, 1], hi[on, 1], off[:, 1], half[1])
            part[on] += np.mean(c[on] * q[on] ** k[:, None], axis=1) * lx * ly / area
        out[front] = np.where(lit_ok, full + part, 0.0) * d[:, 2]
        return out.reshape(shape)

    def kernel(self, du, dv, dn, ops):
        """Return :meth:`response` on generic arrays (numpy or Dr.Jit; ``ops`` supplies maximum, minimum, where,
        sqrt, exp, log, floor and tiny, as :mod:`simcore.radiometry.response`'s kernels take them), for the
        analytic model's Dr.Jit albedo kernel: the same closed form with at most :data:`KERNEL_PARTIAL_TERMS`
        terms that the footprint cuts in part."""
        w, win = self.well, self.window
        n, t, gap = win.index, win.thickness_m, win.gap_m
        hu, hv = win.size_m[0] / 2, win.size_m[1] / 2
        mx, mn, where = ops.maximum, ops.minimum, ops.where
        c = mx(dn, 1e-12)
        inv = 1.0 / c
        # the well's lit rectangle (both rims of a chamfered well), metres along u and v
        from simcore.shapes.aperture import lit_rectangle_of
        x0, x1, y0, y1, lit = lit_rectangle_of(w.rims, du, dv, dn, maximum=mx, minimum=mn, where=where)
        x0, x1, y0, y1 = x0 * w.diode_x_m, x1 * w.diode_x_m, y0 * w.diode_y_m, y1 * w.diode_y_m
        ct = ops.sqrt(mx(1.0 - (du * du + dv * dv) * (1.0 / (n * n)), 1e-12))        # cos theta_t
        a = ops.exp(-win.absorption_per_m * t / ct)
        inner = t / (n * ct)
        fu, fv = du * (gap * inv + inner), dv * (gap * inv + inner)               # first exit offset
        su, sv = 2.0 * du * inner, 2.0 * dv * inner                               # per round trip

        def k_full(step, first, lo, hi, half):
            astep = mx(step, -step)
            room = half - where(step > 0, hi, -lo) - mx(first, -first)
            return where(astep > 1e-20, ops.floor(room / mx(astep, 1e-20)), where(room >= 0, 1e9, -1.0))

        kf = mx(mn(k_full(su, fu, x0, x1, hu), k_full(sv, fv, y0, y1, hv)), -1.0)
        total = 0.0
        for r in ((c - n * ct) / (c + n * ct), (ct - n * c) / (ct + n * c)):
            r = r * r
            q = mx(r * r * a * a, 1e-30)
            cc = (1.0 - r) * (1.0 - r) * a
            qk = ops.exp((kf + 1.0) * ops.log(q))                                   # q^(kf + 1)
            part = cc * (1.0 - qk) / mx(1.0 - q, ops.tiny) * lit
            for j in range(KERNEL_PARTIAL_TERMS):
                k = kf + 1.0 + j
                ou, ov = fu + k * su, fv + k * sv
                lx = mx(mn(x1, hu - ou) - mx(x0, -hu - ou), 0.0)
                ly = mx(mn(y1, hv - ov) - mx(y0, -hv - ov), 0.0)
                part = part + cc * qk * lx * ly * (1.0 / (w.diode_x_m * w.diode_y_m))
                qk = qk * q
            total = total + 0.5 * part
        return where(dn > 0, total * dn, 0.0)

