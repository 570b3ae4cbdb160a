"""The direct Sun estimator: next-event estimation from stratified points on the diode toward the Sun's disc,
blocked by the mesh or the Earth (docs/renderer.md, "Direct Sun")."""
from dataclasses import replace

import numpy as np

from simcore.render.launch import _PACKET, _TEA_ROUNDS
from simcore.render.sampling import _DIRECT, _DIRECT_PLAIN, _direct_size
from simcore.render.windows import _WINDOW_KEY
from simcore.shapes.aperture import lit_rectangle_of

_DIRECT_SAMPLES0 = 1024
# Direct-Sun tasks that something besides the diode's own well shadows in part (DirectSun._partly_blocked):
# probe rays toward the disc's centre and this many points on its rim, and this many times the samples.
_PROBE_RIM = 32
_EDGE_BOOST = 16
# With a target, the settled direct tasks (no shadow but the analytic well's: no variance almost surely) take the
# fewest samples n >= _SETTLED_LANE_SE / rel_se_direct (at most direct_samples): one lane in n that a sliver the
# probes missed makes differ from the rest gives a relative standard error of ~1 / n to 1.25 / n with the split's
# weights, so such a lane still leaves the task within its target (0.2 %: 676 samples instead of 1024;
# docs/renderer.md, "Fewer rays for the same accuracy").
_SETTLED_LANE_SE = 1.25


class DirectSun:
    """The direct Sun (a mixin of :class:`simcore.render.renderer.Renderer`)."""

    # -- direct Sun kernel
    def _direct_kernel(self, a):
        dr, mi = self._dr, self._mi
        a = self._with_indices(a)
        j = a.j
        # Strata: the 2 m^2 diamonds (squares turned 45 deg) around the points (k, l) / 2m of
        # the unit torus with k + l even, so that the aperture walls' edges, parallel to the
        # diode's sides, cut many strata obliquely instead of one row of them.
        # (max: lanes past the end of the last SIMD packet gather 0, and x86 traps on x / 0)
        m = dr.maximum(self._col(a, "m"), 1)
        h = j >> 1
        row = h // m
        col = ((h - row * m) << 1) + (row & 1)
        key = self._col(a, "key")
        r = self._rand(key, j, 2)
        inv = self._col(a, "half_inv_m")
        fx = (mi.Float(col) + r[0] + r[1] - 1.0) * inv
        fy = (mi.Float(row) + r[0] - r[1]) * inv
        fx = fx - dr.floor(fx) - 0.5
        fy = fy - dr.floor(fy) - 0.5
        s = self._vec(a, "sun")
        if self.sun_angular_radius_rad > 0:
            # Uniform in solid angle over the disc: 1 - cos a = xi * (1 - cos a_max).
            omc = r[2] * dr.opaque(mi.Float, 2.0 * np.sin(self.sun_angular_radius_rad / 2) ** 2)
            sin_a = dr.sqrt(dr.maximum(omc * (2.0 - omc), 0.0))
            phi = r[3] * (2.0 * np.pi)
            e1, e2 = mi.coordinate_system(s)
            d = dr.normalize(s * (1.0 - omc) + sin_a * (dr.cos(phi) * e1 + dr.sin(phi) * e2))
        else:
            d = s
        fx, fy, wgt = self._split_point(a, d, fx, fy)
        o = self._vec(a, "pos") + fx * self._vec(a, "U") + fy * self._vec(a, "V")
        # (the rays of lanes that read 0 whatever they meet are not traced)
        traced = wgt > 0
        behind_earth = None
        if a.has("earth"):
            c = self._vec(a, "earth")
            b = dr.dot(d, c)
            perp = c - b * d
            behind_earth = (b > 0) & (dr.squared_norm(perp) < dr.opaque(mi.Float, self.earth_radius_m ** 2))
            traced &= ~behind_earth
        if self.sun_angular_radius_rad > 0:
            cos_nd = dr.dot(self._vec(a, "n"), d)
            traced &= cos_nd > 0
        if self._win is None:
            blocked = self._blocked_by_mesh(a, o, d, traced)
        else:
            a_, _ = mi.sample_tea_32(key ^ mi.UInt32(_WINDOW_KEY), j, _TEA_ROUNDS)
            o, tw, blocked = self._through_window(a, o, d, fx, fy, mi.Float(a_ >> 8) * (1.0 / 16777216.0), traced)
            wgt = wgt * tw
        cv = self._round_cv(a, d, fx, fy)
        if behind_earth is not None:
            blocked |= behind_earth
            cv = dr.select(behind_earth, 0.0, cv)
        val = dr.select(blocked, 0.0, wgt) + cv
        if self.sun_angular_radius_rad > 0:
            val = val * dr.maximum(cos_nd, 0.0)
        return val

    def _direct_rounds(self, e_, k_, g_, sun, earth, E, cos_c, plan, out, n_used):
        """Render the direct Sun of tasks (epochs ``e_``, diodes ``k_``) into ``out`` by the :class:`Sampling`
        ``plan`` (its per-task factor, skipped groups and counts set here)."""
        plain, n0 = plan.plain, plan.n0
        base = self._tasks(e_, k_, sun, earth, None)
        disc = self.sun_angular_radius_rad > 0
        # lane mean -> W/m^2. With the disc, lanes read cos(n, d) for directions d uniform in solid angle
        # over the disc, whose mean is cos(n, s) (1 + cos a) / 2, while the irradiance of a uniform disc of
        # total E is E cos(n, s) exactly: hence the factor 2 / (1 + cos a).
        fac = E[e_] * (2.0 / (1.0 + np.cos(self.sun_angular_radius_rad)) if disc else cos_c[e_, k_])
        skip = None
        if self.control_variate and not disc and not plain:
            lit = self._lit_fraction(k_, sun[e_])
            skip = np.stack([lit <= 0.0, lit >= 1.0], axis=1)
        settled = None
        if not plain:
            edge = self._partly_blocked(base, e_, sun, earth)
            n0 = np.where(edge, n0 * _EDGE_BOOST, n0)
            if self.control_variate:
                # the analytic well is the only shadow the probes found: the split's estimate has (almost surely)
                # no variance, so no pilot sizes its round (Rounds._rounds)
                settled = ~edge
                if plan.rel is not None:
                    n0 = np.where(settled, np.minimum(n0, _direct_size(_SETTLED_LANE_SE / plan.rel)), n0)
        m, se, dof, n = self._rounds(self._direct_kernel, base, _DIRECT_PLAIN if plain else _DIRECT, g_, k_,
                                     replace(plan, n0=n0, fac=fac, skip=skip, settled=settled))
        out["dm"][e_, k_], out["dse"][e_, k_], out["ddof"][e_, k_], n_used[e_, k_] = m, se, dof, n

    def _partly_blocked(self, base, e_, sun, earth):
        """Return (T,) bool: the direct-Sun tasks whose light something other than the diode's own analytic well
        blocks in part: the Earth's limb across the solar disc, or the mesh (body, rails, neighbours) across the lit
        part of the diode, found by probe rays from its corners and centre toward the disc's centre and rim
        (``_PROBE_RIM`` points) (docs/renderer.md, "Partly blocked direct tasks")."""
        T = len(e_)
        a = self.sun_angular_radius_rad
        s = sun[e_]
        out = np.zeros(T, bool)
        if earth is not None and a > 0:
            c = base["earth"]
            dist = np.linalg.norm(c, axis=1)
            theta = np.arccos(np.clip(np.einsum("ti,ti->t", s, c) / dist, -1.0, 1.0))
            rho = np.arcsin(np.minimum(self.earth_radius_m / dist, 1.0))
            out |= np.abs(theta - rho) < a
        if self._scene is None:
            return out
        if a > 0:
            helper = np.where(np.abs(s[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
            e1 = np.cross(s, helper)
            e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
            e2 = np.cross(s, e1)
            ang = 2.0 * np.pi * np.arange(_PROBE_RIM) / _PROBE_RIM
            off = np.tan(0.999 * a) * np.stack([np.cos(ang), np.sin(ang)], axis=1)
            dirs = s[:, None] + off[None, :, :1] * e1[:, None] + off[None, :, 1:] * e2[:, None]
            dirs = np.concatenate([s[:, None], dirs / np.linalg.norm(dirs, axis=2, keepdims=True)], axis=1)
        else:
            dirs = s[:, None]
        D = dirs.shape[1]
        fr = base["frame"]                                             # (T, 3, 3) rows u, v, n
        dd = np.einsum("tij,tdj->tdi", fr, dirs)
        ap = base["ap"]
        if self.control_variate:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                x0, x1, y0, y1, lit = lit_rectangle_of([ap[:, None, i] for i in range(8)],
                                                       dd[..., 0], dd[..., 1], dd[..., 2])
        else:
            x0, y0 = np.full((T, D), -0.5), np.full((T, D), -0.5)
            x1, y1 = -x0, -y0
            lit = (dd[..., 2] > 0).astype(float)
        # corners inset by 1e-4 of the side (points on a wall's foot are not what this looks for), centre
        inset = 1e-4
        fx = np.stack([x0 + inset, x1 - inset, x0 + inset, x1 - inset, 0.5 * (x0 + x1)], axis=2)
        fy = np.stack([y0 + inset, y0 + inset, y1 - inset, y1 - inset, 0.5 * (y0 + y1)], axis=2)
        P = fx.shape[2]
        o = (base["pos"][:, None, None] + fx[..., None] * base["U"][:, None, None]
             + fy[..., None] * base["V"][:, None, None])
        d = np.broadcast_to(dirs[:, :, None], o.shape)
        mi = self._mi
        if self._win is not None:
            # under a window the light leaves its upper face shifted toward the source: probe from the first
            # term's exit points as well (tasks without a window: the same points twice)
            w = base["win"]
            n_i, th, gap, has = w[:, None, 0], w[:, None, 1], w[:, None, 2], w[:, None, 8] > 0.5
            dn = np.maximum(dd[..., 2], 1e-12)
            ct = np.sqrt(np.maximum(1.0 - (dd[..., 0] ** 2 + dd[..., 1] ** 2) / n_i ** 2, 1e-24))
            reach = np.where(has, gap / dn + th / (n_i * ct), 0.0)                                  # (T, D)
            shift = ((reach * dd[..., 0])[..., None] * fr[:, None, 0] + (reach * dd[..., 1])[..., None] * fr[:, None, 1]
                     + np.where(has, gap + th, 0.0)[..., None] * fr[:, None, 2])
            o = np.concatenate([o, o + shift[:, :, None]], axis=2)
            d = np.concatenate([d, d], axis=2)
            P = 2 * P
        # each task's rays padded to whole packets (_PACKET) with copies of its last one
        n = D * P
        pad = np.minimum(np.arange(-(-n // _PACKET) * _PACKET), n - 1)
        o, d = o.reshape(T, n, 3)[:, pad], d.reshape(T, n, 3)[:, pad]
        ray = mi.Ray3f(self._v3(o.reshape(-1, 3)), self._v3(d.reshape(-1, 3)))
        blocked = np.asarray(self._scene.ray_test(ray).numpy(), bool).reshape(T, len(pad))[:, :n].reshape(T, D, P)
        seen = np.broadcast_to(((lit > 0) & (x1 - x0 > 2 * inset) & (y1 - y0 > 2 * inset))[..., None], blocked.shape)
        some = (blocked & seen).any(axis=(1, 2))
        free = (~blocked & seen).any(axis=(1, 2))
        return out | (some & free)

    def _lit_fraction(self, k_, d_body):
        """Return the analytic wells' lit fractions (T,) for diodes k_ and body directions (T, 3)."""
        ap = self._ap_params[k_]
        dd = np.einsum("tij,tj->ti", self.diodes.frames[k_], d_body)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return lit_rectangle_of(ap.T, dd[:, 0], dd[:, 1], dd[:, 2])[4]


def in_umbra(c, s, R, sin_a):
    """Return (T,) bool: whether a satellite with the Earth's centre at ``c`` (T, 3) m sees no part of the Sun's disc
    (radius ``asin(sin_a)``) toward unit ``s`` (T, 3) past the Earth of radius ``R`` (10 m of margin)."""
    bb = np.einsum("ti,ti->t", c, s)
    perp = np.linalg.norm(c - bb[:, None] * s, axis=1)
    return (bb > 0) & (perp < R - np.linalg.norm(c, axis=1) * sin_a - 10.0)
