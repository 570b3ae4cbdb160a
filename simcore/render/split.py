"""The aperture split and the round wells' control variate, shared by the direct and albedo kernels: where the
diode's analytic well lets the light through (docs/renderer.md, "Aperture split")."""
from simcore.render.launch import _DrOps
from simcore.shapes.aperture import disc_rectangle_overlap, lit_rectangle_of


class ApertureSplit:
    """The aperture split (a mixin of :class:`simcore.render.renderer.Renderer`: reads ``control_variate``,
    ``_plain`` and the lanes' fields ``frame``, ``ap``, ``ap_hint``, ``round`` and ``mode``)."""

    # -- where the analytic well lets light through (aperture split, see _rounds)
    def _well_rect(self, a, d, key="ap"):
        """Return (x0, x1, y0, y1, lit) for unit directions ``d``: the rectangle of the diode
        (fractions of its sides, centred, so within [-1/2, 1/2]) whose rays toward ``d`` leave
        through the opening of the diode's analytic well (``simcore.shapes.aperture.WellAperture``
        geometry: the opening shifted by -h tan along each wall axis), and its area fraction,
        the lit fraction. ``key``: "ap" (the split's and the probes' rectangle) or "ap_hint" (the albedo
        proposal's)."""
        dr = self._dr
        fr = [self._vec(a, "frame", k) for k in range(3)]
        du, dv, dn = dr.dot(fr[0], d), dr.dot(fr[1], d), dr.dot(fr[2], d)
        rims = [self._col(a, key, k) for k in range(8)]  # half diode; half opening and height of the lower and top rims
        return lit_rectangle_of(rims, du, dv, dn, maximum=dr.maximum, minimum=dr.minimum, where=dr.select)

    def _split_point(self, a, d, fx, fy):
        """Return (fx, fy, weight) of the diode point for a lane of mode 0 (plain: the point as
        drawn, weight 1), 1 (inside the analytic well's lit rectangle: the point mapped into it,
        weight = its area) or 2 (the rest: the point as drawn, weight 0 inside the rectangle)."""
        dr, mi = self._dr, self._mi
        if not self.control_variate:
            return fx, fy, mi.Float(1.0)
        mode = self._col(a, "mode")
        x0, x1, y0, y1, lit = self._well_rect(a, d)
        in_a = mode == 1
        gx = dr.select(in_a, x0 + (x1 - x0) * (fx + 0.5), fx)
        gy = dr.select(in_a, y0 + (y1 - y0) * (fy + 0.5), fy)
        inside = (lit > 0) & (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
        wgt = dr.select(in_a, lit, dr.select((mode == 2) & inside, 0.0, 1.0))
        return gx, gy, wgt

    def _round_cv(self, a, d, fx, fy):
        """Return the control variate of a round well's lanes (mode 3; 0 for the others): the closed-form lit
        fraction of the diode through the rim's disc toward ``d`` (CircularWell, the Dr.Jit form of
        simcore.shapes.aperture.disc_rectangle_overlap) minus 1 where the lane's diode point (fx, fy) lies in
        that lit part. Its mean over the diode is 0 for any ``d``, so the estimate stays unbiased whatever the
        mesh; the lane's traced 1 or 0 and this term cancel where the mesh is the analytic well."""
        dr, mi = self._dr, self._mi
        if not (self.control_variate and self._plain.any()):
            return 0.0                      # no round well: the kernels stay as they were
        mode = self._col(a, "mode")
        ax, ay = self._col(a, "ap", 0), self._col(a, "ap", 1)                # half diode sides, m
        r, h = self._col(a, "round", 0), self._col(a, "round", 1)
        fr = [self._vec(a, "frame", k) for k in range(3)]
        du, dv, dn = dr.dot(fr[0], d), dr.dot(fr[1], d), dr.dot(fr[2], d)
        inv = 1.0 / dr.maximum(dn, 1e-12)
        sx, sy = h * du * inv, h * dv * inv                                   # the ray's offset at the rim
        px, py = 2.0 * ax * fx + sx, 2.0 * ay * fy + sy
        inside = px * px + py * py <= r * r
        # the lit fraction, in units of the half side ax and in float64 (the closed form's differences of disc
        # segments cancel: float32 would leave ~1e-7 where the disc lights nothing); within 1e-9 of 0 or 1 it
        # is 0 or 1 (as the rectangles' exact zeros and ones: at most 1.4e-6 W/m^2)
        F = mi.Float64
        s = 1.0 / F(ax)
        area = disc_rectangle_overlap(F(-sx) * s, F(-sy) * s, dr.maximum(F(r) * s, 1e-6), -1.0, 1.0, -F(ay) * s,
                                      F(ay) * s, ops=_DrOps(dr))
        lit = area / (4.0 * F(ay) * s)
        lit = mi.Float(dr.select(lit < 1e-9, 0.0, dr.select(lit > 1.0 - 1e-9, 1.0, lit)))
        return dr.select((mode == 3) & (dn > 0), lit - dr.select(inside, 1.0, 0.0), 0.0)
