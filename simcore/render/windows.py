"""Cover-glass windows over the diodes (:mod:`simcore.shapes.window`), traced per lane by the kernels and by the
probes (docs/renderer.md, "Windows")."""
import numpy as np

_WINDOW_KEY = 0x5BD1E995   # xor-ed into a lane's key: the window's own random numbers (the kernels' stay as they were)


def _window_params(diodes):
    """Return (K, 9) float64 [index, thickness, gap, half side u, half side v, absorption (1/m), diode side u,
    diode side v, has a window] per diode for :meth:`CoverGlass._through_window`, or None without windows."""
    if diodes.windows is None:
        return None
    out = np.zeros((diodes.count, 9))
    for k, w in enumerate(diodes.windows):
        if w is None:
            out[k] = [1.5, 1e-3, 0.0, 1e3, 1e3, 0.0, *diodes.sizes_m[k], 0.0]
        else:
            out[k] = [w.index, w.thickness_m, w.gap_m, w.size_m[0] / 2, w.size_m[1] / 2, w.absorption_per_m,
                      *diodes.sizes_m[k], 1.0]
    return out


class CoverGlass:
    """The windows (a mixin of :class:`simcore.render.renderer.Renderer`: reads ``diodes``, the lanes' field
    ``win`` and :meth:`simcore.render.probes.Probes._blocked_share_of`)."""

    # -- a window over the diode (simcore.shapes.window): one helper for the kernels
    def _window_exit(self, a, o, d, fx, fy, u):
        """Return (exit point, weight, length of the segment to the lower face, has a window) for light reaching
        the diode point ``o`` (at fractions ``fx``, ``fy`` of its sides) from unit directions ``d`` (body frame)
        through the task's window, one uniform ``u`` per lane: the slab's terms k = 0..K (K the last whose exit
        point stays in the footprint, closed form) carry c q^k per polarisation
        (:meth:`simcore.shapes.window.Window.terms`); k is drawn with probability proportional to the mean
        over s and p of that term (a polarisation by its share of the partial sum, then k from its truncated
        geometric law by inversion) and the weight is the partial sum (mean over s and p): unbiased, and
        exact whatever k is drawn when nothing shades the window. Tasks without a window: (o, 1, 0, False)."""
        dr = self._dr
        n_i, th, gap, hx, hy, alpha, sx, sy, has = (self._col(a, "win", i) for i in range(9))
        fr = [self._vec(a, "frame", k) for k in range(3)]
        du, dv, dn = dr.dot(fr[0], d), dr.dot(fr[1], d), dr.dot(fr[2], d)
        c = dr.maximum(dn, 1e-12)
        ct = dr.sqrt(dr.maximum(1.0 - (du * du + dv * dv) / (n_i * n_i), 0.0))     # cos theta_t
        rs = dr.square((c - n_i * ct) / (c + n_i * ct))
        rp = dr.square((ct - n_i * c) / (ct + n_i * c))
        att = dr.exp(-alpha * th / dr.maximum(ct, 1e-12))          # one pass through the slab
        g_c, inner = gap / c, th / (n_i * dr.maximum(ct, 1e-12))  # lateral walk per unit |d_uv|: to p1, per pass

        def k_axis(dx, half, x):
            # |dx| (gap / cos + (2k + 1) inner) <= half - sign(dx) x  (exit point inside the footprint)
            room = half - dr.select(dx > 0, x, -x)
            ad = dr.abs(dx)
            k = dr.floor(((room / dr.maximum(ad, 1e-20) - g_c) / inner - 1.0) * 0.5)
            return dr.select(ad > 1e-12, dr.minimum(k, 1e9), 1e9)

        K = dr.maximum(dr.minimum(k_axis(du, hx, fx * sx), k_axis(dv, hy, fy * sy)), -1.0)

        def partial(r):
            q = dr.maximum(dr.square(r * att), 1e-30)
            qK = dr.exp((K + 1.0) * dr.log(q))
            return q, qK, dr.square(1.0 - r) * att * (1.0 - qK) / (1.0 - q)

        qs, qKs, Ss = partial(rs)
        qp, qKp, Sp = partial(rp)
        tot = Ss + Sp
        ps = Ss / dr.maximum(tot, 1e-30)
        use_s = u < ps
        u2 = dr.select(use_s, u / dr.maximum(ps, 1e-30), (u - ps) / dr.maximum(1.0 - ps, 1e-30))
        u2 = dr.clip(u2, 0.0, 1.0 - 1.0 / 16777216.0)
        q, qK = dr.select(use_s, qs, qp), dr.select(use_s, qKs, qKp)
        k = dr.clip(dr.floor(dr.log(1.0 - u2 * (1.0 - qK)) / dr.log(q)), 0.0, dr.maximum(K, 0.0))
        win = has > 0.5
        lateral = d - dn * fr[2]
        exit_ = o + (g_c + (2.0 * k + 1.0) * inner) * lateral + (gap + th) * fr[2]
        weight = dr.select(win, dr.select(K >= 0.0, 0.5 * tot, 0.0), 1.0)
        return dr.select(win, exit_, o), weight, dr.select(win, g_c, 0.0), win

    def _through_window(self, a, o, d, fx, fy, u, active=True):
        """Return (exit point, weight, blocked) for light reaching the diode point ``o`` (at fractions ``fx``,
        ``fy`` of its sides) from unit directions ``d`` (body frame) through the task's window, one uniform
        ``u`` per lane (:meth:`_window_exit`): blocked when the mesh meets the segment from ``o`` to the
        window's lower face or the ray leaving the upper face at the drawn exit point along ``d``. Tasks
        without a window get (o, 1, the plain ray's test). Lanes not ``active`` trace neither ray (blocked False)."""
        exit_, weight, seg, win = self._window_exit(a, o, d, fx, fy, u)
        blocked = self._blocked_by_mesh(a, exit_, d, active)
        if a.scene is not None:
            mi = self._mi
            blocked |= a.scene.ray_test(mi.Ray3f(mi.Ray3f(o, d), seg), active & win & (seg > 0.0))
        return exit_, weight, blocked

    def _window_first_segment(self, scene, a, o, d, fx, fy, u):
        """Return (origin, weight) of a reflected path's first ray from the diode point ``o`` along ``d``: when
        nothing of the path-traced ``scene`` lies between ``o`` and the window's lower face, the light crossed
        the window: the ray starts at the drawn exit point of the upper face and the path carries the slab's
        weight (:meth:`_window_exit`); else (a well wall under the window) it starts at ``o`` with weight 1
        (what reaches that wall through the window is not attenuated by it: the window is traced on the
        diode's own first segment only)."""
        mi, dr = self._mi, self._dr
        exit_, weight, seg, win = self._window_exit(a, o, d, fx, fy, u)
        under = scene.ray_test(mi.Ray3f(mi.Ray3f(o, d), seg), win & (seg > 0.0))
        cross = win & ~under
        return dr.select(cross, exit_, o), dr.select(cross, weight, 1.0)

    # -- the probes' view through a window
    def _window_shift(self, k, win, d_body, term):
        """Return (M, 3) body-frame offsets from a point of diode ``k`` to where term ``term`` of the light toward
        directions ``d_body`` (M, 3) leaves the upper face of its window ``win`` (:meth:`Window.exit_offsets`)."""
        u, v, n = self.diodes.frames[k]
        first, step = win.exit_offsets(d_body @ self.diodes.frames[k].T)
        off = first + term * step
        return off[:, :1] * u + off[:, 1:] * v + (win.gap_m + win.thickness_m) * n

    def _window_visible_share(self, k, win, rect, d_body, grid, tail=1e-3, max_terms=12):
        """Return (M,): for diode ``k`` under the window ``win`` and M (lit rectangle (x0, x1, y0, y1) in fractions
        of the diode's sides, body-frame direction), the share of the light through the window that the mesh
        leaves visible: the slab's terms (:meth:`simcore.shapes.window.Window.terms`, mean over s and p), each
        over the part of the rectangle whose exit point for that term lies in the footprint (a rectangle) and
        traced from those exit points (``grid`` x ``grid`` points), weighted by its term and area, up to the
        term below ``tail`` of the first (at most ``max_terms``); 1 where no term reaches the diode."""
        local = d_body @ self.diodes.frames[k].T
        c, q = win.terms(local[:, 2])
        first, step = win.exit_offsets(local)
        size = self.diodes.sizes_m[k]
        half = np.array(win.size_m) / 2
        with np.errstate(divide="ignore"):
            n_terms = np.clip(np.ceil(np.log(tail) / np.log(np.clip(q.max(axis=1), 1e-300, 1 - 1e-12))), 1, max_terms)
        num, den = np.zeros(len(local)), np.zeros(len(local))
        for term in range(int(n_terms.max())):
            off = first + term * step                                                    # (M, 2) metres
            # the points whose exit lies in the footprint: |x size + off| <= half, per axis
            lo = np.maximum(rect[:, [0, 2]], (-half - off) / size)
            hi = np.minimum(rect[:, [1, 3]], (half - off) / size)
            area = np.prod(np.clip(hi - lo, 0.0, None), axis=1) * (term < n_terms)
            on = area > 0
            if not on.any():
                continue
            sub = np.column_stack([lo[on, 0], hi[on, 0], lo[on, 1], hi[on, 1]])
            blocked = self._blocked_share_of(np.full(int(on.sum()), k), sub, d_body[on], grid,
                                             self._window_shift(k, win, d_body[on], term))
            w = np.mean(c[on] * q[on] ** term, axis=1) * area[on]
            num[on] += w * (1.0 - blocked)
            den[on] += w
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
