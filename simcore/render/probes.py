"""Probe rays over each diode's hemisphere: the visibility table that shapes the albedo sampling, and the shares
of a diode's lit part that the mesh blocks or leaves visible, which the check compares with the analytic model."""
import numpy as np

from simcore._llvm import host_array
from simcore.shapes.aperture import lit_rectangle_of

_VIS_NT, _VIS_NP = 90, 180  # visibility table over each diode's hemisphere (1 x 2 deg cells)


class Probes:
    """The direction grid and its probes (a mixin of :class:`simcore.render.renderer.Renderer`)."""

    def _visibility_table(self):
        """Return the (K * _VIS_NT * _VIS_NP,) table (Dr.Jit Float) that shapes the albedo sampling: per
        diode and direction of :meth:`direction_grid`, the largest share of the diode's lit part the mesh
        leaves visible (1 - :meth:`blocked_share`, 1 where the well lights nothing) over the cell and its
        eight neighbours, so that a direction seen past a shadow's edge by part of the diode keeps its
        weight. None without an occluder mesh."""
        if self._scene is None:
            return None
        vis = 1.0 - np.nan_to_num(self.blocked_share(), nan=0.0)
        return host_array(self._mi.Float, widen_cells(vis))

    def direction_grid(self):
        """Return (theta, phi) (_VIS_NT,), (_VIS_NP,) rad: the cell centres of the 1 x 2 deg direction grid
        of :meth:`blocked_share` (angle from the diode normal 0..90 deg, azimuth from u -180..180 deg)."""
        th = (np.arange(_VIS_NT) + 0.5) * (0.5 * np.pi / _VIS_NT)
        ph = (np.arange(_VIS_NP) + 0.5) * (2.0 * np.pi / _VIS_NP) - np.pi
        return th, ph

    @staticmethod
    def direction_cell(local):
        """Return (row, column) int arrays (...): the cell of :meth:`direction_grid` holding each unit direction
        ``local`` (..., 3) given in a diode's frame (u, v, n); directions behind the diode take row _VIS_NT - 1."""
        theta = np.arccos(np.clip(local[..., 2], -1.0, 1.0))
        row = np.minimum((theta * (_VIS_NT / (0.5 * np.pi))).astype(int), _VIS_NT - 1)
        col = ((np.arctan2(local[..., 1], local[..., 0]) + np.pi) * (_VIS_NP / (2.0 * np.pi))).astype(int) % _VIS_NP
        return row, col

    def blocked_share(self):
        """Return (K, 90, 180) (computed once): per diode and direction of its 1 x 2 deg grid (:meth:`direction_grid`), the
        share of 3 x 3 probe rays from the part of the diode its own analytic well lights (inset 1e-3 of
        the side) toward the cell's centre that the mesh blocks (body, rails, other diodes' mounts: what
        the diode's own well does not hold); NaN where the well lights nothing. Zeros without a mesh.

        The check compares it with the analytic model's picture of the same directions to tell which
        albedo diode-epochs its reference covers (``simcore.pipeline.run``)."""
        if getattr(self, "_blocked", None) is None:
            self._blocked = self.probe_share(self._scene)
        return self._blocked

    def probe_share(self, scene, where=None):
        """Return (K, 90, 180): the share of :meth:`blocked_share`'s probe rays that the occluder ``scene``
        (:func:`occluder_scene`; None: nothing) blocks, in the cells of ``where`` (K, 90, 180) bool (default:
        all), 0 in the others; NaN where the diode's own well lights nothing (zeros for a diode with no cell
        in ``where``: not computed)."""
        K = self.diodes.count
        th, ph = self.direction_grid()
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        local = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1)    # (NT, NP, 3)
        out = np.zeros((K, _VIS_NT, _VIS_NP))
        jobs = []
        for k in range(K):
            if where is not None and not where[k].any():
                continue
            if self.control_variate:
                x0, x1, y0, y1, lit = lit_rectangle_of(self._ap_params[k], local[..., 0], local[..., 1], local[..., 2])
            else:
                x0, y0 = np.full(TH.shape, -0.5), np.full(TH.shape, -0.5)
                x1, y1, lit = -x0, -y0, np.ones(TH.shape)
            ok = (lit > 0) & (x1 - x0 > 2e-3) & (y1 - y0 > 2e-3)
            out[k][~ok] = np.nan
            if where is not None:
                ok &= where[k]
            if scene is not None and ok.any():
                jobs.append((k, ok, np.stack([x0[ok], x1[ok], y0[ok], y1[ok]], -1), local[ok] @ self.diodes.frames[k]))
        if jobs:
            blocked = self._blocked_share_of(
                np.concatenate([np.full(int(job[1].sum()), job[0]) for job in jobs]), np.concatenate([job[2] for job in jobs]),
                np.concatenate([job[3] for job in jobs]), [1e-3, 0.5, 1.0 - 1e-3], scene=scene)
            start = 0
            for k, ok, rect, d_body in jobs:
                n = int(ok.sum())
                out[k][ok] = blocked[start:start + n]
                start += n
                win = None if self.diodes.windows is None else self.diodes.windows[k]
                if win is not None:
                    # under a window the light leaves its upper face shifted toward the source: probe from the
                    # first term's exit points too, so that a shadow the shift moves is marked as well
                    shift = self._window_shift(k, win, d_body, 0)
                    out[k][ok] = 0.5 * (out[k][ok] + self._blocked_share_of(
                        np.full(n, k), rect, d_body, [1e-3, 0.5, 1.0 - 1e-3], shift, scene=scene))
        return out

    def visible_share(self, mask, sub=4, points=8):
        """Return (fine, half): per diode, inside the cells of ``mask`` ((K, 90, 180) bool on the grid of
        :meth:`direction_grid`), the share of the part of the diode its own analytic well lights that the
        mesh leaves visible toward each cell's centre, on grids ``sub`` and ``sub / 2`` times finer
        ((K, 90 sub, 180 sub) and (K, 45 sub, 90 sub); NaN outside the mask). A deterministic quadrature:
        ``points`` x ``points`` midpoints of the lit part per direction (for
        ``simcore.radiometry.analytic.DirectionVisibility``), traced in one launch for every diode and
        both grids (the points are made and their hits averaged in the kernel)."""
        K = self.diodes.count
        mask = np.asarray(mask, bool)
        jobs, out = [], []
        for s_ in (sub, sub // 2):
            nt, nph = _VIS_NT * s_, _VIS_NP * s_
            share = np.full((K, nt, nph), np.nan)
            fine_mask = np.repeat(np.repeat(mask, s_, axis=1), s_, axis=2)
            th = (np.arange(nt) + 0.5) * (0.5 * np.pi / nt)
            ph = (np.arange(nph) + 0.5) * (2.0 * np.pi / nph) - np.pi
            for k in range(K):
                i, j = np.nonzero(fine_mask[k])
                if not len(i):
                    continue
                local = np.stack([np.sin(th[i]) * np.cos(ph[j]), np.sin(th[i]) * np.sin(ph[j]), np.cos(th[i])], -1)
                if self.control_variate:
                    x0, x1, y0, y1, lit = lit_rectangle_of(self._ap_params[k], local[:, 0], local[:, 1], local[:, 2])
                else:
                    x0, y0 = np.full(len(i), -0.5), np.full(len(i), -0.5)
                    x1, y1, lit = -x0, -y0, np.ones(len(i))
                jobs.append((share, k, i, j, lit, np.stack([x0, x1, y0, y1], -1), local @ self.diodes.frames[k]))
            out.append(share)
        if not jobs:
            return tuple(out)
        if self._scene is None:
            free = np.ones(sum(len(job[2]) for job in jobs))
        else:
            free = 1.0 - self._blocked_share_of(
                np.concatenate([np.full(len(job[2]), job[1]) for job in jobs]), np.concatenate([job[5] for job in jobs]),
                np.concatenate([job[6] for job in jobs]), (np.arange(points) + 0.5) / points)
        start = 0
        for share, k, i, j, lit, rect, d_body in jobs:
            f = free[start:start + len(i)]
            win = None if self.diodes.windows is None else self.diodes.windows[k]
            if win is not None and self._scene is not None:
                f = self._window_visible_share(k, win, rect, d_body, (np.arange(points) + 0.5) / points)
            share[k, i, j] = np.where(lit > 0, f, 0.0)
            start += len(i)
        return tuple(out)

    def _blocked_share_of(self, diode, rect, d_body, grid, shift=None, scene=None):
        """Return (M,): for M (diode index, lit rectangle (x0, x1, y0, y1) in fractions of the diode's sides,
        centred, body-frame direction) the share of the rectangle's points at fractions ``grid`` (P,) of its
        sides along x times the same along y (P x P points) whose ray toward the direction the mesh blocks;
        one Dr.Jit launch, the points made and their hits summed in the kernel. ``shift`` (M, 3): body-frame
        offsets of the rays' origins from those points (where the light leaves a window's upper face). ``scene``:
        the occluders (default: the mesh's)."""
        dr, mi = self._dr, self._mi
        P = len(grid)
        P2 = P * P
        lane = dr.arange(mi.UInt32, len(diode) * P2)
        m = lane // P2
        q = lane - m * P2
        g = host_array(mi.Float, np.asarray(grid, dtype=float))
        gx = dr.gather(mi.Float, g, q // P)
        gy = dr.gather(mi.Float, g, q % P)
        r = [dr.gather(mi.Float, host_array(mi.Float, rect[:, c]), m) for c in range(4)]
        fx = r[0] + (r[1] - r[0]) * gx
        fy = r[2] + (r[3] - r[2]) * gy
        kk = dr.gather(mi.UInt32, host_array(mi.UInt32, diode.astype(np.uint32)), m)
        f = self._diode_f32
        o = (self._gather3(self._v3(f["pos"]), kk) + fx * self._gather3(self._v3(f["U"]), kk)
             + fy * self._gather3(self._v3(f["V"]), kk))
        if shift is not None:
            o = o + self._gather3(self._v3(shift), m)
        d = self._gather3(self._v3(d_body), m)
        hit = (self._scene if scene is None else scene).ray_test(mi.Ray3f(o, d))
        blocked = dr.block_sum(dr.select(hit, 1.0, 0.0), P2)
        return np.asarray(blocked.numpy(), dtype=float) / P2


def widen_cells(a):
    """Return ``a`` (..., rows, columns) of direction-grid cells (:meth:`Renderer.direction_grid`) with each cell the
    largest of itself and its neighbours one row and one column away (bool: any of them), azimuth wrapping round:
    so that an edge passing between the cells' centres still marks the cells it crosses."""
    grown = a.copy()
    grown[..., 1:, :] = np.maximum(grown[..., 1:, :], a[..., :-1, :])
    grown[..., :-1, :] = np.maximum(grown[..., :-1, :], a[..., 1:, :])
    return np.maximum(grown, np.maximum(np.roll(grown, 1, axis=-1), np.roll(grown, -1, axis=-1)))
