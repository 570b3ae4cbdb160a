"""The Earth albedo estimator and its proposal (radiance x diode cosine x aperture x visibility at the bins of the
Earth's cap, the map bounded within reach of each bin), and the Earth seen along a direction, which the reflected
paths share (docs/renderer.md, "Earth albedo")."""
from dataclasses import replace

import numpy as np

from simcore.radiometry import glint as _glint
from simcore._llvm import host_array
from simcore.render.launch import _DrOps, _pad2
from simcore.render.probes import _VIS_NP, _VIS_NT
from simcore.render.sampling import _ALBEDO

_DEFENSIVE = 0.02         # share of uniform-in-solid-angle sampling in the albedo proposal
_N_T, _N_P = 16, 32       # albedo proposal bins: radial x azimuth (_N_P a power of 2)
_ALBEDO_STRATA0 = 128
# Radial bins of the albedo proposal: edges 40 % of the way from equal solid angle to equal
# ground (central) angle; the Sun's cosine at the bin corners widened by ~half a bin.
_EDGE_MIX, _MARGIN_SCALE = 0.4, 1.0
# The albedo proposal's reflectivity at a bin corner is at least this share of the largest reflectivity within
# reach of the bins that touch the corner (reach_levels, corner_reach): a bright cell between dark corners (cloud
# over an infrared-dark sea: 54x) then costs an importance ratio of at most 1 / _BOUND_SHARE times the geometric
# factor's, instead of the cells' contrast (heavy tails: the rare bright samples carry the mean, and when a seed
# misses them both the estimate and its standard error come out low). Not 1 (a strict bound): the bins near any
# bright cell would all read it, the proposal would go flat over a dark sea with scattered clouds and no longer
# favour the bins that hold them (albedo samples to reach 1 %, --map band --clouds 1 from 2016-07-02 00:45Z:
# 8353 at 0.25, 11775 at 0.5, 18472 at 1; TOMS 2005 bench: +0 %, +1 %, +16 %; synthetic dark map with
# 0.5-2 % bright cells at 256 samples: more |z| > 4 at 0.5 and 1 than at 0.25).
_BOUND_SHARE = 0.25
# With the sea's glint the share is 1, a strict bound (the map's and the sea's largest within reach, the glint's
# BRDF at the corner). A quarter under-weights both a clear sea's glint between overcast corners (the corner's own
# sea is 0 there, and the glint outshines the cloud: pi f of a few at oblique geometry against 0.7) and a cloud
# beside the glint's bright bins, which now compete for the samples instead of a dark sea; the rare samples that
# hit them carry the mean (2 minutes of --map band --glint 7 --clouds 1 from 2016-07-02T16:44Z, tilt20_fov70,
# seeds 2, 3, 4, 6: |z| > 4 on 7, 8, 4, 6 of 711 diode-epochs at a quarter, 1, 1, 4, 4 with the map's share 1
# alone, 0, 0, 1, 0 with the glint's share 1 alone, 0, 0, 0, 0 with both; expected 0.05).
_BOUND_SHARE_GLINT = 1.0
# Rounds toward the albedo's target (Rounds._rounds, docs/renderer.md "Rounds toward a target"): the pilot takes
# n0 / _ALBEDO_PILOT samples; its standard error, raised by _ALBEDO_CONF / sqrt(2 nu) of itself, sizes the final
# round with the error falling as n^(-1/_ALBEDO_POWER). Stratified in the CDF and the bin's azimuth, the albedo's error
# falls faster than n^(-1/2): n^(-0.75) to n^(-0.77) from pilot to final round on bench_render's orbit (TOMS 2005,
# 500 epochs; n^(-0.62) before the azimuth was stratified; docs/renderer.md, "Fewer rays for the same accuracy").
# _ALBEDO_CONF 0.65 since group B's 1/10 (below) left more of a round to group A; 0.75 before.
_ALBEDO_PILOT, _ALBEDO_CONF, _ALBEDO_POWER = 2, 0.65, 4.0 / 3.0
# The aperture split's group B takes 1 / _ALBEDO_GROUP_B of an albedo round's samples, group A the rest (the direct's:
# 1 / 5). Where the mesh's well is the analytic one group B reads exactly 0 (every task of bench_render's orbit: 20 %
# of the albedo's lanes), so its variance is group A's alone: with 9/10 rather than 4/5 of a round, the rule reaches a
# target with ~8/9 of the samples and group A's as many as before (docs/renderer.md, "Fewer rays for the same
# accuracy").
_ALBEDO_GROUP_B = 10


class EarthAlbedo:
    """The Earth's albedo (a mixin of :class:`simcore.render.renderer.Renderer`: reads ``earth_radius_m``,
    ``reflectivity``, ``lon_west_rad`` and ``_glint``)."""

    # -- albedo kernel
    def _albedo_kernel(self, a):
        dr, mi = self._dr, self._mi
        a = self._with_indices(a)
        j = a.j
        B = _N_T * _N_P
        h = j >> 1
        key = self._col(a, "key")
        r = self._rand(key, j, 3)
        inv_m = self._col(a, "inv_m")
        u = (mi.Float(h) + r[0]) * inv_m
        # Bin by search in the task's inclusive CDF (count of entries <= u): four-way steps, whose three probes are
        # independent (the CDF is sorted: the count of them <= u is the quarter u falls in), then a two-way one;
        # the same bin as a binary search, in 5 dependent gathers instead of 9
        cdf = a.tables["cdf"]
        row = self._col(a, "row")                   # the task's row of the tables
        base = row * B
        lo, n = mi.UInt32(0), B                     # (u lies in entries lo .. lo + n - 1)
        while n >= 4:
            n //= 4
            at = base + lo + (n - 1)
            lo = lo + n * sum(dr.select(dr.gather(mi.Float, cdf, at + i * n) <= u, mi.UInt32(1), mi.UInt32(0))
                              for i in range(3))
        if n == 2:
            lo = dr.select(dr.gather(mi.Float, cdf, base + lo) <= u, lo + 1, lo)
        b = dr.minimum(lo, B - 1)
        pmf = dr.gather(mi.Float, a.tables["pmf"], base + b)
        # the azimuth within the bin: u's place in the bin's CDF interval (uniform in [0, 1) and independent of
        # the bin), so that the strata of u stratify the bin's azimuth too (r[2] is drawn but not used)
        c_hi = dr.gather(mi.Float, cdf, base + b)
        c_lo = dr.select(b > 0, dr.gather(mi.Float, cdf, base + dr.maximum(b, 1) - 1), 0.0)
        az = dr.clip((u - c_lo) / dr.maximum(c_hi - c_lo, 1e-30), 0.0, 1.0 - 2.0 ** -24)
        bt = b >> int(np.log2(_N_P))
        bp = b & (_N_P - 1)
        xmax = self._col(a, "xmax")
        edges = a.tables["tedge"]
        t0 = dr.gather(mi.Float, edges, row * (_N_T + 1) + bt)
        dt = dr.gather(mi.Float, edges, row * (_N_T + 1) + bt + 1) - t0
        g3 = lambda k: self._vec(a, k)  # noqa: E731
        d = self._cap_direction(g3("w"), g3("e1"), g3("e2"), xmax, t0 + dt * r[1],
                                (mi.Float(bp) + az) * (2.0 * np.pi / _N_P))
        fx, fy, wgt = self._split_point(a, d, r[3] - 0.5, r[4] - 0.5)
        o = g3("pos") + fx * g3("U") + fy * g3("V")
        cos_d = dr.dot(g3("n"), d)
        rot = [self._vec(a, "rot", k) for k in range(3)]
        hit, cos_sun, rho = self._earth_along(d, g3("earth"), g3("sun"), rot, a.tables["refl"], a.tables.get("sea"))
        ok = hit & (cos_sun > 0) & (cos_d > 0)
        # (the rays of lanes that read 0 whatever they meet are not traced)
        if self._win is None:
            blocked = self._blocked_by_mesh(a, o, d, ok & (wgt > 0))
        else:
            o, tw, blocked = self._through_window(a, o, d, fx, fy, r[5], ok & (wgt > 0))
            wgt = wgt * tw
        f = dr.select(blocked, 0.0, wgt) + self._round_cv(a, d, fx, fy)
        # f / q with q = pmf_b / Omega_b, Omega_b = 2 pi xmax dt / N_P; L = rho E cos_sun / pi
        return dr.select(ok, f * rho * cos_sun * cos_d * (2.0 / _N_P) * xmax * dt / pmf, 0.0)

    # -- the Earth seen along a direction: shared by the albedo kernel, its proposal and the reflected paths
    def _earth_along(self, d, c, s, rot, refl, sea=None, bound=None):
        """Return (hit, cos of the Sun at the Earth point, reflectivity there) for unit
        directions ``d`` from a point at ``-c`` from the Earth's centre (body axes); ``refl``: the reflectivity
        map as a Dr.Jit array (the renderer's, passed in so that frozen kernels see it as an input). With the
        renderer's glint, ``sea`` its sea fraction table (likewise): the reflectivity is then the Lambertian
        one that gives the same radiance toward -d, ``rho + pi sea f(s, -d)`` (L = rho E cos_sun / pi + sea E f
        cos_sun; f the Cox-Munk BRDF, :mod:`simcore.radiometry.glint`).

        ``bound``: (the map's :func:`reach_levels` table, the sea fraction's or None, each lane's level (UInt32)):
        the reflectivity is then followed by its bound at that level, the glint's BRDF taken at the point itself
        (smooth over a bin: a lobe tens of degrees wide) on the sea fraction's bound."""
        dr, mi = self._dr, self._mi
        nlat, nlon = self.reflectivity.shape
        R = self.earth_radius_m
        # Stable with the satellite at the origin: x_e = -perp - sqrt(R^2 - |perp|^2) d.
        bb = dr.dot(d, c)
        perp = c - bb * d
        q = dr.opaque(mi.Float, R * R) - dr.squared_norm(perp)
        hit = (bb > 0) & (q > 0)
        xe = -perp - dr.sqrt(dr.maximum(q, 0.0)) * d
        cos_sun = dr.dot(xe, s) * (1.0 / R)
        ex, ey, ez = dr.dot(rot[0], xe), dr.dot(rot[1], xe), dr.dot(rot[2], xe)
        lat = dr.atan2(ez, dr.sqrt(ex * ex + ey * ey))
        lon = dr.atan2(ey, ex)
        row = dr.clip(mi.Int32(dr.floor((lat + 0.5 * np.pi) * (nlat / np.pi))), 0, nlat - 1)
        col = mi.Int32(dr.floor((lon - self.lon_west_rad) * (nlon / (2.0 * np.pi))))
        col = dr.select(col < 0, col + nlon, col)
        col = dr.clip(dr.select(col >= nlon, col - nlon, col), 0, nlon - 1)
        cell = mi.UInt32(row * nlon + col)
        rho = dr.gather(mi.Float, refl, cell)
        if bound is not None:
            at = bound[2] * (nlat * nlon) + cell
            rho_max = dr.gather(mi.Float, bound[0], at)
        if sea is not None:
            g = self._glint
            cos_view = -dr.dot(xe, d) * (1.0 / R)
            q = _glint.reflected_cos2(cos_sun, cos_view, -dr.dot(s, d), g.mss, g.index, _DrOps(dr), g.tau)
            # f = q / (cos_sun cos_view); the floor only where q is 0 or the lane is dropped (cos_sun <= 0)
            f = q / dr.maximum(cos_sun * cos_view, 1e-12)
            rho = rho + np.pi * dr.gather(mi.Float, sea, cell) * f
            if bound is not None:
                rho_max = rho_max + np.pi * dr.gather(mi.Float, bound[1], at) * f
        if bound is not None:
            return hit, cos_sun, rho, rho_max
        return hit, cos_sun, rho

    def _cap_direction(self, w, e1, e2, xmax, t01, phi):
        """Return the unit direction at fraction ``t01`` of the cap's solid angle (counted from
        nadir ``w``) and azimuth ``phi`` about nadir."""
        dr = self._dr
        x = t01 * xmax                                    # 1 - cos(angle from nadir)
        sin_t = dr.sqrt(dr.maximum(x * (2.0 - x), 0.0))
        return dr.normalize((1.0 - x) * w + sin_t * (dr.cos(phi) * e1 + dr.sin(phi) * e2))

    # -- the albedo proposal: radiance x diode cosine x aperture fraction at bin corners/centres
    def _corner_direction(self, a, i, n_points):
        """Return (task of lane ``i``, the bin corner's index within its task, its unit direction) for lanes of
        ``n_points`` corners a task (the cap's fields of :class:`_Lanes` ``a``)."""
        dr, mi = self._dr, self._mi
        task = i // n_points
        a = replace(a, task=task)
        p = i - task * n_points
        it = p // (_N_P + 1)                             # bin corners: (N_T + 1) x (N_P + 1)
        ip = p - it * (_N_P + 1)
        ring = self._col(a, "row") * (_N_T + 1) + it
        t01 = dr.gather(mi.Float, a.tables["tedge"], ring)
        phi = mi.Float(ip) * (2.0 * np.pi / _N_P)
        g3 = lambda k: self._vec(a, k)  # noqa: E731
        return a, p, ring, self._cap_direction(g3("w"), g3("e1"), g3("e2"), self._col(a, "xmax"), t01, phi)

    def _earth_corners(self, a, n_points):
        """Return the Earth's factor of the proposal's weights (T n_points,) at the bins' corners of epochs ``a``
        (:class:`_Lanes`, one row an epoch, the cap seen from the satellite's origin): the bounded reflectivity
        times the Sun's widened cosine, or -1 where the corner's direction misses the Earth or its sunlit side
        (:meth:`_proposal_kernel` reads it per task)."""
        dr, mi = self._dr, self._mi
        a, _, ring, d = self._corner_direction(a, a.lane, n_points)
        g3 = lambda k: self._vec(a, k)  # noqa: E731
        rot = [self._vec(a, "rot", k) for k in range(3)]
        # the map's bound over the ground of every bin that touches this corner (tlevel: _albedo_proposal)
        level = mi.UInt32(dr.gather(mi.Float, a.tables["tlevel"], ring))
        hit, cos_sun, rho, rho_max = self._earth_along(d, g3("earth"), g3("sun"), rot, a.tables["refl"],
                                                       a.tables.get("sea"),
                                                       (a.tables["refl_max"], a.tables.get("sea_max"), level))
        rho = dr.maximum(dr.abs(rho), (_BOUND_SHARE if self._glint is None else _BOUND_SHARE_GLINT) * rho_max)
        # cos_sun widened by ~half a bin on the ground, so that bins the terminator crosses
        # between their corners keep their weight
        cos_sun = cos_sun + self._col(a, "margin")
        return dr.select(hit & (cos_sun > 0), rho * cos_sun, -1.0)

    def _proposal_kernel(self, a, n_points):
        """Return the proposal's weights (T n_points,) at the bins' corners of tasks ``a`` (:class:`_Lanes`
        whose ``j`` counts the lanes 0 .. T n_points - 1, ``n_points`` per task): the Earth's factor of the task's
        epoch (table ``earth_corners``, :meth:`_earth_corners`, at row ``epoch_row``) times the diode's cosine,
        its well's lit fraction and the visibility of the rest of the satellite."""
        dr, mi = self._dr, self._mi
        a, p, _, d = self._corner_direction(a, a.lane, n_points)
        g3 = lambda k: self._vec(a, k)  # noqa: E731
        e = dr.gather(mi.Float, a.tables["earth_corners"], self._col(a, "epoch_row") * n_points + p)
        lit = self._well_rect(a, d, "ap_hint")[4]
        dn = dr.dot(g3("n"), d)
        ok = ~(e < 0) & (dn > 0)                         # (a NaN factor passes, as a NaN corner did)
        f = e * dn * lit
        if "vis" in a.tables:
            # what the rest of the satellite hides from this diode (_visibility_table)
            fr = [self._vec(a, "frame", k) for k in range(2)]
            row = dr.clip(mi.Int32(dr.acos(dr.clip(dn, -1.0, 1.0)) * (_VIS_NT / (0.5 * np.pi))), 0, _VIS_NT - 1)
            col = mi.Int32((dr.atan2(dr.dot(fr[1], d), dr.dot(fr[0], d)) + np.pi) * (_VIS_NP / (2.0 * np.pi)))
            col = dr.clip(col, 0, _VIS_NP - 1)
            k = mi.Int32(self._col(a, "k"))
            f *= dr.gather(mi.Float, a.tables["vis"], mi.UInt32((k * _VIS_NT + row) * _VIS_NP + col))
        return dr.select(ok, f, 0.0)

    def _albedo_proposal(self, t, e_, sun, earth, rot):
        """Return per-task cap basis and bin CDF/PMF for the albedo sampling of tasks ``t`` (epochs ``e_`` of the
        per-epoch ``sun``, ``earth`` and ``rot``): numpy fields, and ``pmf`` and ``cdf`` as Dr.Jit arrays (float32, a
        row of ``_N_T _N_P`` bins per task, rows in ``t``'s order; :meth:`_proposal_tables`).

        The cap, its bins and the Earth's factor of the weights are the epoch's, seen from the satellite's origin
        (a diode's millimetres move the cap by ~1e-10 rad, below float32's resolution of a direction; the albedo
        kernel traces from the diode's point whatever cap it samples): computed once per epoch, not per diode."""
        dr, mi = self._dr, self._mi
        ue, inv = np.unique(e_, return_inverse=True)
        R = self.earth_radius_m
        dist, w, e1, e2, xmax = cap_basis(earth[ue], R)
        # Radial bin edges between equal solid angle and equal central angle g from the
        # sub-satellite point (equal solid angle alone makes the bins near the limb span ~15 deg
        # of ground, where the terminator hides between corners), as fractions t of the cap's
        # solid angle: tan(theta) = R sin g / (d - R cos g).
        g_max = np.arccos(np.clip(R / dist, -1.0, 1.0))
        g = g_max[:, None] * np.linspace(0.0, 1.0, _N_T + 1)[None, :]
        theta = np.arctan2(R * np.sin(g), dist[:, None] - R * np.cos(g))
        tedge = 2.0 * np.sin(theta / 2) ** 2 / xmax[:, None]
        tedge = _EDGE_MIX * tedge + (1 - _EDGE_MIX) * np.linspace(0.0, 1.0, _N_T + 1)[None, :]
        tedge[:, 0], tedge[:, -1] = 0.0, 1.0
        margin = _MARGIN_SCALE * np.sin(0.5 * np.maximum(g_max / _N_T, 2 * np.pi * np.sin(g_max) / _N_P))
        n_points = (_N_T + 1) * (_N_P + 1)
        tlevel = reach_level(corner_reach(tedge, xmax, dist / R), self.reflectivity.shape[0])
        cap = dict(w=w, e1=e1, e2=e2, xmax=xmax, tedge=tedge)
        U = len(ue)
        epochs = _pad2(dict(cap, key=np.zeros(U, np.uint32), k=np.zeros(U, np.int64), earth=earth[ue], sun=sun[ue],
                            rot=rot[ue], margin=margin, tlevel=tlevel.astype(np.float32)))
        earth_corners = self._joined(list(self._trace_tasks(self._earth_corners, epochs, n_points)), n_points)
        prop = {k: v[inv] for k, v in cap.items()}              # the tasks' own copies of their epoch's cap
        t = _pad2(dict(t, epoch_row=inv.astype(np.uint32), **prop))
        omega = np.diff(t["tedge"], axis=1) / _N_P              # (T, N_T): a bin's solid angle / the cap's
        B = _N_T * _N_P
        parts = []
        for sl, f in self._trace_tasks(self._proposal_kernel, t, n_points, earth_corners=earth_corners):
            n = sl.stop - sl.start
            bins, tasks = dr.arange(mi.UInt32, n * B), dr.arange(mi.UInt32, n)
            dr.make_opaque(bins, tasks)
            parts.append((sl, self._replay("_proposal_tables", self._proposal_tables, f,
                                           host_array(mi.Float64, omega[sl]), bins, tasks)))
        pmf, cdf = self._joined(parts, B)
        return dict(prop, pmf=pmf, cdf=cdf)

    def _proposal_tables(self, f, omega, bins, tasks):
        """Return the proposal's PMF and CDF (float32, a row of ``_N_T _N_P`` bins per task) from ``f``, the
        proposal's weights at the bins' corners (:meth:`_proposal_kernel`, ``(_N_T + 1) (_N_P + 1)`` per task), and
        ``omega`` (float64, ``_N_T`` per task: a bin's solid angle / the cap's, by ring); ``bins`` and ``tasks`` count
        the bins and the tasks.

        A bin's weight is its corners' largest (not times its solid angle: docs/renderer.md, "Fewer rays for the same
        accuracy"); the PMF mixes the weights, normalised, with ``_DEFENSIVE`` of ``omega`` (``omega`` alone for a task
        without weight, or with a NaN); the CDF is its running sum in float64 over the task's bins, divided by the
        last. Computed as numpy would, bit for bit: float32 weights summed pairwise as ``numpy.sum`` sums 512 values
        (blocks of 128 in eight interleaved partial sums), the running sum in order.

        Both tables are this recording's own outputs, written in place: scattered into tables passed in (and held by
        the caller), Dr.Jit copied them whole at each launch (2 x 2.4 MB a batch of 256 epochs, ~5 % of the render)."""
        dr, mi = self._dr, self._mi
        B, NP1 = _N_T * _N_P, _N_P + 1
        task, b = bins // B, bins % B
        bt, bp = b // _N_P, b % _N_P
        c = task * ((_N_T + 1) * NP1) + bt * NP1 + bp
        v = [dr.gather(mi.Float, f, c + k) for k in (0, NP1, 1, NP1 + 1)]
        w = dr.maximum(dr.maximum(v[0], v[1]), dr.maximum(v[2], v[3]))
        # a NaN corner makes its bin's weight NaN, as numpy.maximum does, so that its task's total is NaN and the task
        # falls back on omega alone (drjit.maximum keeps NaN on the CPU, LLVM's fmaximum; CUDA's max.f32 drops it)
        w = dr.select(dr.isnan(v[0]) | dr.isnan(v[1]) | dr.isnan(v[2]) | dr.isnan(v[3]), np.nan, w)
        om = dr.gather(mi.Float64, omega, task * _N_T + bt)
        dr.eval(w)
        # the weights' total per task, in numpy's pairwise order for 512 values
        base = tasks * B
        blocks = []
        for blk in range(B // 128):
            k0 = base + blk * 128
            r = [dr.gather(mi.Float, w, k0 + j) for j in range(8)]
            _, *r = dr.while_loop((mi.UInt32(1), *r), lambda i, *r: i < 16,
                                  lambda i, *r: (i + 1, *[r[j] + dr.gather(mi.Float, w, k0 + i * 8 + j)
                                                          for j in range(8)]))
            blocks.append(((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7])))
        while len(blocks) > 1:
            blocks = [blocks[i] + blocks[i + 1] for i in range(0, len(blocks), 2)]
        tot = blocks[0]
        dr.eval(tot)

        def share(w_, om_, tot_):
            """A bin's probability (float64) from its weight and its task's total weight (float32, divided as numpy
            divides float32 arrays) and its solid angle."""
            return dr.select(tot_ > 0, mi.Float64(w_ * (1 - _DEFENSIVE) / dr.select(tot_ > 0, tot_, 1.0))
                             + _DEFENSIVE * om_, om_)

        def share_at(i):
            """Bin ``i``'s probability of each task (the running sums': recomputed, not stored in float64)."""
            om_i = dr.gather(mi.Float64, omega, tasks * _N_T + i // _N_P)
            return share(dr.gather(mi.Float, w, base + i), om_i, tot)
        # (cdf: a kernel's output of its own, every element of which the running sum below overwrites)
        pmf, cdf = mi.Float(share(w, om, dr.gather(mi.Float, tot, task))), mi.Float(om)
        dr.eval(pmf, cdf)
        # the running sum, twice: its total, then each bin's share of it
        cond = lambda i, s: i < B  # noqa: E731
        _, total = dr.while_loop((mi.UInt32(0), mi.Float64(0.0)), cond, lambda i, s: (i + 1, s + share_at(i)))

        def step(i, s):
            s = s + share_at(i)
            dr.scatter(cdf, dr.select(i == B - 1, 1.0, mi.Float(s / total)), base + i)
            return i + 1, s
        dr.while_loop((mi.UInt32(0), mi.Float64(0.0)), cond, step)
        return pmf, cdf

    def _albedo_rounds(self, e_, k_, g_, sun, earth, rot, E, plan, out, n_used):
        """Render the albedo of tasks (epochs ``e_``, diodes ``k_``) into ``out`` by the :class:`Sampling` ``plan``
        (its per-task factor set here)."""
        base = self._tasks(e_, k_, sun, earth, None)
        base["rot"] = rot[e_]
        base.update(self._albedo_proposal(dict(base, key=np.zeros(len(e_), np.uint32)), e_, sun, earth, rot))
        # (pmf and cdf are on the device already, one row a task of base)
        base.update(self._tables({k: v for k, v in base.items() if k not in ("pmf", "cdf")}))
        m, se, dof, n = self._rounds(self._albedo_kernel, base, _ALBEDO, g_, k_, replace(plan, fac=E[e_]))
        out["am"][e_, k_], out["ase"][e_, k_], out["adof"][e_, k_], n_used[e_, k_] = m, se, dof, n


def cap_basis(c, R):
    """Return (distance (T,), nadir ``w``, ``e1``, ``e2`` (T, 3), ``xmax`` (T,)) of the Earth's cap (radius ``R``) seen
    from points with the Earth's centre at ``c`` (T, 3): ``w`` toward the centre, ``e1`` and ``e2`` across it
    (``e2 = w x e1``), ``xmax`` one minus the cosine of the cap's half-angle."""
    dist = np.linalg.norm(c, axis=-1)
    w = c / dist[:, None]
    # 1 - cos(cap half-angle) = (R/d)^2 / (1 + cos): no cancellation for a distant Earth
    xmax = (R / dist) ** 2 / (1.0 + np.sqrt(np.clip(1.0 - (R / dist) ** 2, 0.0, None)))
    ref = np.where(np.abs(w[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(ref, w)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return dist, w, e1, np.cross(w, e1), xmax


def sunlit_earth_in_view(c, s_e, R):
    """Return (T,) bool: whether some sunlit part of the Earth (radius ``R``, centre at ``c`` (T, 3) m, lit from unit
    ``s_e`` (T, 3)) is in view: angle(zenith, s_e) < 90 deg + acos(R / d)."""
    dist = np.linalg.norm(c, axis=1)
    lam = np.arccos(np.clip(R / dist, -1, 1))
    return np.einsum("ti,ti->t", -c / dist[:, None], s_e) > np.cos(np.minimum(np.pi / 2 + lam, np.pi))


def reach_levels(values):
    """Return the flat (L n_lat n_lon,) float32 bounds of ``|values|`` (a regular (n_lat, n_lon) latitude/longitude map,
    row 0 the southern band, longitude wrapping round) within reach on the sphere: level ``l``, at each cell, the
    largest over every cell that holds a point within ground (central) angle ``r_l = 2^l`` cell heights of a point of
    the cell; the last level reaches pi (the map's maximum). The cells taken are a superset, so each is a bound:
    rows within ``2^l`` rows; columns within ``asin(sin r / cos phi)`` of longitude, ``phi`` the cell's poleward edge
    (the widest a circle of radius r about a point of the cell spans), and the whole latitude circle where the reach
    passes a pole."""
    a = np.abs(np.asarray(values, dtype=float))
    nlat, nlon = a.shape
    dlat, dlon = np.pi / nlat, 2.0 * np.pi / nlon
    pole = np.maximum(np.abs(-0.5 * np.pi + np.arange(nlat) * dlat), np.abs(-0.5 * np.pi + np.arange(1, nlat + 1) * dlat))
    rows = np.arange(nlat)
    j = np.arange(nlon)
    out = []
    band = a
    for lev in range(reach_level(np.pi, nlat) + 1):
        # rows i - 2^l .. i + 2^l: the union of the previous level's bands about i -+ 2^(l-1) (about i -+ 1 from the
        # map itself for level 0), clipped at the poles
        h = 1 << max(lev - 1, 0)
        lo, hi = band[np.clip(rows - h, 0, nlat - 1)], band[np.clip(rows + h, 0, nlat - 1)]
        band = np.maximum(np.maximum(lo, hi), a) if lev == 0 else np.maximum(lo, hi)
        r = dlat * (1 << lev)
        with np.errstate(invalid="ignore"):
            half = np.arcsin(np.clip(np.sin(min(r, 0.5 * np.pi)) / np.cos(pole), 0.0, 1.0))
        w = np.ceil(half / dlon - 1e-9).astype(np.int64)
        full = (pole + r >= 0.5 * np.pi) | (2 * w + 1 >= nlon)
        # circular window maxima along each row by doubling: run[k][:, j] = max over columns j .. j + 2^k - 1
        n = np.where(full, 1, 2 * w + 1)
        k = np.floor(np.log2(n)).astype(np.int64)
        run = [band]
        for _ in range(int(k.max())):
            step = 1 << (len(run) - 1)
            run.append(np.maximum(run[-1], np.roll(run[-1], -step, axis=1)))
        run = np.stack(run)
        first = (j[None, :] - np.where(full, 0, w)[:, None]) % nlon
        second = (first + (n - (1 << k))[:, None]) % nlon
        lev_max = np.maximum(run[k[:, None], rows[:, None], first], run[k[:, None], rows[:, None], second])
        out.append(np.where(full[:, None], band.max(axis=1, keepdims=True), lev_max))
    return np.stack(out).astype(np.float32).ravel()


def reach_level(reach_rad, n_lat):
    """Return the :func:`reach_levels` level (int array) whose reach covers ground angles ``reach_rad`` on a map of
    ``n_lat`` rows: the smallest ``l`` with ``2^l pi / n_lat >= reach``, 0 for reaches within one cell height."""
    ratio = np.maximum(np.asarray(reach_rad, dtype=float) * (n_lat / np.pi) * (1 + 1e-6), 1.0)
    return np.ceil(np.log2(ratio) - 1e-12).astype(np.int64)


def corner_reach(tedge, xmax, d_over_r):
    """Return (T, N_T + 1) the ground angle (rad) from each ring of the albedo proposal's bin corners to the farthest
    ground point of the bins that touch a corner there: rings ``tedge`` (T, N_T + 1) (fractions of the cap's solid
    angle ``2 pi xmax``, from nadir), the satellite at ``d_over_r`` Earth radii from the centre. A bin's ground is
    the points between its rings' ground angles g within its azimuth (the direction's azimuth about nadir is the
    point's about the sub-satellite point); the farthest from the corner lies at a ring next to the corner's and
    one bin's azimuth away (the distance along a ring grows with azimuth, along a meridian arc shorter than pi it
    peaks at an end)."""
    x = np.asarray(tedge, dtype=float) * np.asarray(xmax, dtype=float)[:, None]   # 1 - cos(nadir angle)
    sin_t = np.sqrt(np.clip(x * (2.0 - x), 0.0, None))
    cos_t = 1.0 - x
    dd = np.asarray(d_over_r, dtype=float)[:, None]
    # range to the near-side point, in Earth radii, and its ground angle from the sub-satellite point
    s = dd * cos_t - np.sqrt(np.clip(1.0 - (dd * sin_t) ** 2, 0.0, None))
    g = np.arctan2(s * sin_t, dd - s * cos_t)
    cos_g, sin_g = np.cos(g), np.sin(g)
    lo = lambda v: np.concatenate([v[:, :1], v[:, :-1]], axis=1)  # noqa: E731  (the ring inside, and outside)
    hi = lambda v: np.concatenate([v[:, 1:], v[:, -1:]], axis=1)  # noqa: E731
    cos_p = np.cos(2.0 * np.pi / _N_P)
    far = lambda c2, s2: np.arccos(np.clip(cos_g * c2 + sin_g * s2 * cos_p, -1.0, 1.0))  # noqa: E731
    return np.maximum(far(lo(cos_g), lo(sin_g)), far(hi(cos_g), hi(sin_g)))
