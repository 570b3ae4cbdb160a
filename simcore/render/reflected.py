"""The reflected component: sunlight and Earth light that reached a diode after at least one reflection on the
spacecraft, path traced through a Mitsuba scene of the mesh's parts with their BSDFs (docs/renderer.md,
"Reflected")."""
from dataclasses import replace

import numpy as np

from scenes.materials import MaterialError, bsdf_dict, check_material, is_black
from simcore._llvm import host_array
from simcore.render.launch import _TEA_ROUNDS, SUN_ANGULAR_RADIUS_RAD
from simcore.render.albedo import cap_basis
from simcore.render.sampling import _REFLECTED
from simcore.render.windows import _WINDOW_KEY

_REFLECTED_SAMPLES0 = 256
# Path-tracer vertices leave the surface by this much along its normal (m): well above the float32
# spacing of body coordinates (~1e-8 m at 0.1 m), well below any feature of a 0.5 mm well wall
# (Mitsuba's own spawn_ray offsets by ~1e-4 of the coordinates plus 1e-4 units: 0.1 mm in metres).
_SPAWN_EPS_M = 2e-6
_RR_DEPTH = 3             # Russian roulette from the fourth path vertex on
_REFLECTED_LANES = 1 << 20  # reflected paths gathered over epochs before a wavefront is launched
# epochs whose reflected tasks join a wavefront at once, whatever Renderer.render's batch_epochs: a wavefront
# holds at most this many epochs' paths past _REFLECTED_LANES (simcore.pipeline.preflight.REFLECTED_BATCH_EPOCHS,
# the run's memory check, is the same number: tests/render/test_reflected.py)
REFLECTED_BATCH_EPOCHS = 64
# First direction of a reflected path: cells of each diode's hemisphere (zenith x azimuth) where probe rays
# meet the spacecraft get the samples (paths into empty sky carry nothing: ~95 % of cosine-drawn ones on the
# thesis layout), mixed with this share of cosine-weighted sampling so that every direction keeps a density
# (the estimator stays unbiased whatever the probes missed).
_HIT_NT, _HIT_NP, _HIT_PROBES, _HIT_COSINE = 45, 128, 4, 0.1
_MAX_MIRROR_PLANES = 32   # orientations of smooth-specular faces sampled toward the Sun's mirror image


class ReflectedLight:
    """The reflected paths (a mixin of :class:`simcore.render.renderer.Renderer`: reads ``max_depth``,
    ``_scene``, ``_diode_f32`` and the Earth lookup of :class:`simcore.render.albedo.EarthAlbedo`)."""

    # -- scene of the parts with their materials
    def _build_pt_scene(self, mesh):
        """Return the Mitsuba scene of the parts with their BSDFs (one mesh per part), or None when every
        part is 'black' (then nothing is path traced)."""
        if mesh is None or len(getattr(mesh, "faces", ())) == 0:
            return None
        meta = getattr(mesh, "metadata", {}) or {}
        nf = len(mesh.faces)
        if "materials" in meta and "parts" in meta:
            parts = [(name, meta["parts"][name], meta["materials"][name]) for name in meta["parts"]]
        else:
            parts = [("mesh", (0, nf), meta.get("material", "black"))]
        for name, _, spec in parts:
            check_material(spec, f"part {name!r}")
        self.materials = {name: spec for name, _, spec in parts}
        if all(is_black(spec) for _, _, spec in parts):
            return None
        mi = self._mi
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        shapes = {"type": "scene"}
        normals = []
        fn = np.asarray(mesh.face_normals, dtype=np.float64)
        for i, (name, (a, b), spec) in enumerate(parts):
            if b <= a:
                continue
            used, inv = np.unique(f[a:b], return_inverse=True)
            props = mi.Properties()
            try:
                props["bsdf"] = mi.load_dict(bsdf_dict(spec))
            except Exception as exc:          # Mitsuba's message names the bad parameter
                raise MaterialError(f"part {name!r}: Mitsuba cannot build the material {spec!r}: {exc}") from None
            if mi.has_flag(props["bsdf"].flags(), mi.BSDFFlags.DeltaReflection):
                normals.append(fn[a:b])
            m = mi.Mesh(f"part{i}", len(used), b - a, props=props)
            params = mi.traverse(m)
            params["vertex_positions"] = host_array(mi.Float, v[used])
            params["faces"] = host_array(mi.UInt32, inv)
            params.update()
            shapes[f"part{i}"] = m
        self._mirror_normals = _plane_normals(normals)
        return mi.load_dict(shapes)

    def _hit_table(self):
        """Return the proposal of the reflected paths' first direction: dict(pmf, cdf (K, NT NP) float32 as Dr.Jit
        arrays, beta (K,): the cosine-weighted share). Per diode, cells equal in azimuth and in zenith angle;
        a cell's weight is cos x solid angle x the largest share of probe rays (``_HIT_PROBES`` squared points
        on the diode toward the cell's centre) that meet the mesh in it and its 8 neighbours; a diode whose
        probes meet nothing samples cosine-weighted only (beta 1)."""
        mi = self._mi
        K = self.diodes.count
        th_e = np.linspace(0.0, 0.5 * np.pi, _HIT_NT + 1)
        th = 0.5 * (th_e[:-1] + th_e[1:])
        ph = (np.arange(_HIT_NP) + 0.5) * (2.0 * np.pi / _HIT_NP) - np.pi
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        local = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1).reshape(-1, 3)
        g = (np.arange(_HIT_PROBES) + 0.5) / _HIT_PROBES - 0.5
        fx, fy = [a.ravel() for a in np.meshgrid(g, g, indexing="ij")]
        omega = (np.cos(th_e[:-1]) - np.cos(th_e[1:]))[:, None] * np.full(_HIT_NP, 2.0 * np.pi / _HIT_NP)
        w_geo = (np.cos(th)[:, None] * omega).ravel()
        pmf = np.zeros((K, _HIT_NT * _HIT_NP))
        beta = np.ones(K)
        for k in range(K):
            d = local @ self.diodes.frames[k]
            o = (self.diodes.positions_m[k] + fx[:, None] * self._diode_f32["U"][k] + fy[:, None] * self._diode_f32["V"][k])
            oo = np.repeat(o, len(d), axis=0)
            dd = np.tile(d, (len(o), 1))
            hit = np.asarray(self._scene.ray_test(mi.Ray3f(self._v3(oo), self._v3(dd))).numpy(), float)
            h = hit.reshape(len(o), _HIT_NT, _HIT_NP).mean(axis=0)
            hp = np.pad(h, ((1, 1), (0, 0)), mode="edge")
            hd = np.max([np.roll(hp, s_, axis=1)[1 + r_:_HIT_NT + 1 + r_] for r_ in (-1, 0, 1) for s_ in (-1, 0, 1)], axis=0)
            w = w_geo * hd.ravel()
            if w.sum() > 0:
                pmf[k] = w / w.sum()
                beta[k] = _HIT_COSINE
        cdf = np.cumsum(pmf, axis=1)
        cdf[:, -1] = np.where(cdf[:, -1] > 0, 1.0, 0.0)
        return dict(pmf=host_array(mi.Float, pmf), cdf=host_array(mi.Float, cdf),
                    beta=beta, omega=omega.ravel(), th_e=th_e)

    # -- reflected kernel: paths from the diode off the spacecraft's BSDFs (docs/renderer.md)
    def _reflected_kernel(self, a):
        """Return the per-lane ``reflected`` irradiance (W/m^2) of tasks ``a`` (:class:`_Lanes`): a wavefront, one launch per
        path vertex, whose code does not depend on the depth (it is compiled once and reused); after each
        launch the paths still in flight are compacted (most leave the spacecraft at once)."""
        dr, mi = self._dr, self._mi
        a = self._with_indices(a)
        task, j = a.task, a.j
        n_lanes = dr.width(task)
        total = dr.zeros(mi.Float, n_lanes)
        lane = dr.arange(mi.UInt32, n_lanes)
        scene = self._pt
        D = self.max_depth
        n_pairs = 2 + 4 * D + 4                       # TEA calls per lane (2 floats each)
        a_sun = self.sun_angular_radius_rad if self.sun_angular_radius_rad > 0 else SUN_ANGULAR_RADIUS_RAD
        omc_max = 2.0 * np.sin(a_sun / 2) ** 2        # 1 - cos a
        p_sun = 1.0 / (2.0 * np.pi * omc_max)         # uniform in solid angle over the disc
        has_earth = a.has("earth")
        do_albedo = a.has("rot")
        ctx = mi.BSDFContext()

        def env():
            """Per-lane task data (gathered anew in each launch)."""
            g3 = lambda k: self._vec(a, k)  # noqa: E731
            v = dict(key=self._col(a, "key"), s=g3("sun"), pos=g3("pos"), E=self._col(a, "E"))
            # disc radiance: int L cos(d, s) dOmega = E  =>  L = E / (Omega (1 + cos a) / 2)
            v["L_sun"] = v["E"] * dr.opaque(mi.Float, 2.0 * p_sun / (2.0 - omc_max))
            if has_earth:
                v["c0"] = g3("earth")                 # Earth's centre from the diode's centre
            if do_albedo:
                v.update(s_e=g3("sun_e"), w=g3("w"), e1=g3("e1"), e2=g3("e2"),
                         E_e=self._col(a, "E_e"), xmax=self._col(a, "xmax"),
                         rot=[self._vec(a, "rot", k) for k in range(3)])
                v["p_earth"] = 1.0 / (2.0 * np.pi * v["xmax"])   # uniform in solid angle over the cap
            return v

        def rand(v, first_pair, n):
            """Return 2n uniform floats from the lane's TEA stream, pairs first_pair.. (opaque: one kernel)."""
            idx = j * n_pairs + dr.opaque(mi.UInt32, first_pair)
            out = []
            for i in range(n):
                x, y = mi.sample_tea_32(v["key"], idx + i, _TEA_ROUNDS)
                out += [mi.Float(x >> 8) * (1.0 / 16777216.0), mi.Float(y >> 8) * (1.0 / 16777216.0)]
            return out

        def earth_blocks(c, dd):
            b = dr.dot(dd, c)
            return (b > 0) & (dr.squared_norm(c - b * dd) < dr.opaque(mi.Float, self.earth_radius_m ** 2))

        def spawn(si, dd):
            nn = si.n
            return si.p + nn * dr.select(dr.dot(nn, dd) > 0, _SPAWN_EPS_M, -_SPAWN_EPS_M)

        def power(pa, pb):
            return dr.select(pa > 0, pa * pa / (pa * pa + pb * pb), 0.0)

        def in_disc(dd, axis):
            # |dd - axis|^2 = 2 (1 - cos): a float32 dot product near 1 errs by ~1e-7, 1 % of 1 - cos a
            return dr.squared_norm(dd - axis) <= dr.opaque(mi.Float, 2.0 * omc_max)

        def disc_dir(axis, u1, u2):
            omc = u1 * omc_max
            sin_t = dr.sqrt(dr.maximum(omc * (2.0 - omc), 0.0))
            phi = u2 * (2.0 * np.pi)
            b1, b2 = mi.coordinate_system(axis)
            return dr.normalize(axis * (1.0 - omc) + sin_t * (dr.cos(phi) * b1 + dr.sin(phi) * b2))

        planes = self._mirror_normals

        def p_spec(v, dd):
            """Density (1/sr) of the mirror-image strategy for diode directions dd."""
            cnt = mi.Float(0.0)
            for pl in planes:
                m_ = mi.Vector3f(*map(float, pl))
                cnt += dr.select(in_disc(dd, v["s"] - 2.0 * dr.dot(v["s"], m_) * m_), 1.0, 0.0)
            return cnt * (p_sun / len(planes))

        # ---- launch 0: the diode point, the first direction and the mirror-image strategy
        v = env()
        m = dr.maximum(self._col(a, "m"), 1)
        h = j >> 1
        row = h // m
        col = ((h - row * m) << 1) + (row & 1)
        r = rand(v, 0, 2)
        inv = self._col(a, "half_inv_m")
        fx = (mi.Float(col) + r[0] + r[1] - 1.0) * inv
        fy = (mi.Float(row) + r[0] - r[1]) * inv
        fx = fx - dr.floor(fx) - 0.5
        fy = fy - dr.floor(fy) - 0.5
        fr = [self._vec(a, "frame", k) for k in range(3)]
        o = v["pos"] + fx * self._vec(a, "U") + fy * self._vec(a, "V")
        # first direction: the hit-table proposal mixed with cosine-weighted sampling (_hit_table)
        B = _HIT_NT * _HIT_NP
        hit = self._hit
        kk = self._col(a, "k")
        beta = self._col(a, "beta")
        cos_edges = host_array(mi.Float, np.cos(hit["th_e"]))
        omega = host_array(mi.Float, hit["omega"])
        rx = rand(v, 5 + 4 * D, 1)
        loc = mi.warp.square_to_cosine_hemisphere(mi.Point2f(r[2], r[3]))
        lo = mi.UInt32(0)                   # (a scalar: it widens to the lanes' with the first select)
        step = 1 << int(np.ceil(np.log2(B)))
        while step >= 1:
            idx = dr.minimum(lo + (step - 1), B - 1)
            probe = dr.gather(mi.Float, hit["cdf"], kk * B + idx)
            lo = dr.select((probe <= r[2]) & (lo + step <= B), lo + step, lo)
            step //= 2
        b = dr.minimum(lo, B - 1)
        row, col = b // _HIT_NP, b % _HIT_NP
        c0_, c1_ = dr.gather(mi.Float, cos_edges, row), dr.gather(mi.Float, cos_edges, row + 1)
        ct = c0_ - r[3] * (c0_ - c1_)
        st_ = dr.sqrt(dr.maximum(1.0 - ct * ct, 0.0))
        phi_ = (mi.Float(col) + rx[1]) * (2.0 * np.pi / _HIT_NP) - np.pi
        use_cos = rx[0] < beta
        lx = dr.select(use_cos, loc.x, st_ * dr.cos(phi_))
        ly = dr.select(use_cos, loc.y, st_ * dr.sin(phi_))
        lz = dr.select(use_cos, loc.z, ct)
        d = dr.normalize(lx * fr[0] + ly * fr[1] + lz * fr[2])

        def pdf_dir(dd):
            """Density (1/sr) of the first-direction proposal for diode directions dd."""
            cz = dr.dot(fr[2], dd)
            th = dr.acos(dr.clip(cz, -1.0, 1.0))
            rw = mi.UInt32(dr.clip(mi.Int32(th * (_HIT_NT / (0.5 * np.pi))), 0, _HIT_NT - 1))
            cl = mi.UInt32(dr.clip(mi.Int32((dr.atan2(dr.dot(fr[1], dd), dr.dot(fr[0], dd)) + np.pi)
                                            * (_HIT_NP / (2.0 * np.pi))), 0, _HIT_NP - 1))
            cell = rw * _HIT_NP + cl
            tab = dr.gather(mi.Float, hit["pmf"], kk * B + cell) / dr.gather(mi.Float, omega, cell)
            return dr.select(cz > 0, beta * cz * (1.0 / np.pi) + (1.0 - beta) * tab, 0.0)

        pdf0 = pdf_dir(d)
        cos0 = dr.dot(fr[2], d)
        # the path's sums are radiances times cos / (pi pdf); x pi at the end: irradiance = E[L cos / pdf]
        thr0 = dr.select((pdf0 > 0) & (cos0 > 0), cos0 / (np.pi * dr.maximum(pdf0, 1e-30)), 0.0)
        o0 = o
        if self._win is not None:
            # a window over the diode: the first segment crosses it (directions stay; origin and weight change)
            uw = [mi.Float(x >> 8) * (1.0 / 16777216.0)
                  for x in mi.sample_tea_32(v["key"] ^ mi.UInt32(_WINDOW_KEY), j, _TEA_ROUNDS)]
            o0, tw = self._window_first_segment(scene, a, o, d, fx, fy, uw[0])
            thr0 = thr0 * tw
        acc = mi.Float(0.0)
        if planes is not None:
            # The Sun seen in a smooth mirror-like face (a delta lobe: no next-event estimate reaches it, and a
            # cosine-drawn direction meets the 0.5 deg image with probability ~1e-5): draw a plane
            # orientation, then a direction uniform over the Sun's mirror image in it, from the diode.
            P = len(planes)
            rs = rand(v, 2 + 4 * D, 3)
            pick = dr.minimum(mi.UInt32(rs[0] * P), P - 1)
            img = None
            for i, pl in enumerate(planes):
                m_ = mi.Vector3f(*map(float, pl))
                im = v["s"] - 2.0 * dr.dot(v["s"], m_) * m_
                img = im if img is None else dr.select(pick == i, im, img)
            dm = disc_dir(img, rs[1], rs[2])
            cos_m = dr.dot(fr[2], dm)
            on = cos_m > 0
            o_m, tw_m = o, mi.Float(1.0)
            if self._win is not None:
                o_m, tw_m = self._window_first_segment(scene, a, o, dm, fx, fy, uw[1])
            si_m = scene.ray_intersect(mi.Ray3f(o_m, dm), on)
            on &= si_m.is_valid()
            bs_m, w_m = si_m.bsdf().sample(ctx, si_m, rs[3], mi.Point2f(rs[4], rs[5]), on)
            dn_m = si_m.to_world(bs_m.wo)
            on &= mi.has_flag(bs_m.sampled_type, mi.BSDFFlags.Delta) & in_disc(dn_m, v["s"]) & (w_m[0] > 0)
            on &= ~scene.ray_test(mi.Ray3f(spawn(si_m, dn_m), dn_m), on)
            if has_earth:
                on &= ~earth_blocks(v["c0"] - (si_m.p - v["pos"]), dn_m)
            ps = p_spec(v, dm)
            # this estimates irradiance directly; the path's sum below is multiplied by pi at the end
            acc = dr.select(on, tw_m * w_m[0] * v["L_sun"] * cos_m / ps * power(ps, pdf_dir(dm)), 0.0) / np.pi
        st = dict(o=o0, d=d, thr=thr0, acc=acc, active=dr.full(mi.Bool, True, dr.width(task)),
                  pdf=mi.Float(0.0), delta=dr.full(mi.Bool, False, dr.width(task)), p=mi.Point3f(o),
                  pdf0=pdf0, d0=d)
        dr.eval(st)

        # ---- launches 1..D (+1): a vertex each; the escape of the previous vertex's sampled direction first
        for depth in range(D + 1):
            v = env()
            dv = dr.opaque(mi.UInt32, depth)
            active, thr, acc = st["active"], st["thr"], st["acc"]
            si = scene.ray_intersect(mi.Ray3f(st["o"], st["d"]), active)
            hit = si.is_valid()
            if depth > 0:
                # ... it left the spacecraft: the Sun's disc or the Earth, weighted against next-event estimates
                out = active & ~hit
                c = (v["c0"] - (st["p"] - v["pos"])) if has_earth else None
                in_sun = out & in_disc(st["d"], v["s"])
                if has_earth:
                    in_sun &= ~earth_blocks(c, st["d"])
                w_delta = mi.Float(1.0)
                if planes is not None:          # the mirror-image strategy also draws diode -> mirror -> Sun
                    w_delta = dr.select(dv == 1, power(st["pdf0"], p_spec(v, st["d0"])), 1.0)
                acc += dr.select(in_sun, thr * v["L_sun"] * dr.select(st["delta"], w_delta,
                                                                      power(st["pdf"], mi.Float(p_sun))), 0.0)
                if do_albedo:
                    hit_e, cos_sun, rho = self._earth_along(st["d"], c, v["s_e"], v["rot"], a.tables["refl"], a.tables.get("sea"))
                    ok = out & hit_e & (cos_sun > 0)
                    L_e = rho * v["E_e"] * cos_sun * (1.0 / np.pi)
                    acc += dr.select(ok, thr * L_e * dr.select(st["delta"], 1.0, power(st["pdf"], v["p_earth"])), 0.0)
            if depth == D:
                dr.scatter_add(total, acc, lane)
                break
            active &= hit
            c = (v["c0"] - (si.p - v["pos"])) if has_earth else None
            bsdf = si.bsdf()
            r = rand(v, 2 + 4 * depth, 4)
            # (a) the Sun: a point on the disc
            ds = disc_dir(v["s"], r[0], r[1])
            f, pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds), active)
            ok = active & (f[0] > 0)
            ok &= ~scene.ray_test(mi.Ray3f(spawn(si, ds), ds), ok)
            if has_earth:
                ok &= ~earth_blocks(c, ds)
            acc += dr.select(ok, thr * f[0] * v["L_sun"] / p_sun * power(mi.Float(p_sun), pdf), 0.0)
            # (b) the Earth: a direction uniform in its cap
            if do_albedo:
                de = self._cap_direction(v["w"], v["e1"], v["e2"], v["xmax"], r[2], r[3] * (2.0 * np.pi))
                hit_e, cos_sun, rho = self._earth_along(de, c, v["s_e"], v["rot"], a.tables["refl"], a.tables.get("sea"))
                f, pdf = bsdf.eval_pdf(ctx, si, si.to_local(de), active)
                ok = active & hit_e & (cos_sun > 0) & (f[0] > 0)
                ok &= ~scene.ray_test(mi.Ray3f(spawn(si, de), de), ok)
                L_e = rho * v["E_e"] * cos_sun * (1.0 / np.pi)
                acc += dr.select(ok, thr * f[0] * L_e / v["p_earth"] * power(v["p_earth"], pdf), 0.0)
            # continue by BSDF sampling; Russian roulette from the fourth vertex on
            bs, wgt = bsdf.sample(ctx, si, r[4], mi.Point2f(r[5], r[6]), active)
            dn = si.to_world(bs.wo)
            thr = dr.select(active, thr * wgt[0], 0.0)
            rr = active & (dv + 1 >= _RR_DEPTH)
            keep = dr.minimum(thr, 0.95)
            survive = ~rr | (r[7] < keep)
            thr = dr.select(rr, dr.select(survive, thr / dr.maximum(keep, 1e-12), 0.0), thr)
            active &= survive & (thr > 0)
            st.update(o=spawn(si, dn), d=dn, thr=thr, acc=acc, active=active, pdf=bs.pdf,
                      delta=mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta), p=si.p)
            dr.eval(st)
            # bank what the paths gathered at this vertex, keep the live ones
            dr.scatter_add(total, st["acc"], lane)
            keep_idx = dr.compress(active)
            if dr.width(keep_idx) == 0:
                break
            st = {k: dr.gather(type(x), x, keep_idx) for k, x in st.items()}
            lane, task, j = (dr.gather(mi.UInt32, x, keep_idx) for x in (lane, task, j))
            if dr.width(keep_idx) < 2:   # a 1-element array would be baked into the kernel as a literal
                pad = mi.UInt32([0, 0])
                st = {k: dr.gather(type(x), x, pad) for k, x in st.items()}
                st["active"] = mi.Bool([True, False])
                lane, task, j = (dr.gather(mi.UInt32, x, pad) for x in (lane, task, j))
            st["acc"] = dr.zeros(mi.Float, dr.width(lane))
            dr.eval(st, lane, task, j)
            a = replace(a, task=task, j=j)       # env() reads the live lanes' tasks
        # irradiance = int L cos dOmega = pi E[L] for directions drawn with density cos / pi
        return total * np.pi

    def _reflected_round(self, e_, k_, g_, sun, sun_e, earth_alb, rot, earth, E, E_e, plan, out, n_used):
        """Path-trace the ``reflected`` component of tasks (e_, k_) into ``out``: ``plan.n0`` samples each (one round,
        no target: a :class:`Sampling`)."""
        base = self._tasks(e_, k_, sun, earth, None)
        base["E"] = E[e_]
        base["beta"] = self._hit["beta"][k_]         # the first direction's cosine-weighted share (_hit_table)
        if earth_alb is not None:
            base["rot"] = rot[e_]
            base["sun_e"] = sun_e[e_]
            base["E_e"] = E_e[e_]
            _, w, e1, e2, base["xmax"] = cap_basis(base["earth"], self.earth_radius_m)
            base.update(w=w, e1=e1, e2=e2)
        m, se, dof, nr = self._rounds(self._reflected_kernel, base, _REFLECTED, g_, k_, plan)
        out["rm"][e_, k_], out["rse"][e_, k_], out["rdof"][e_, k_], n_used[e_, k_] = m, se, dof, nr


def _plane_normals(normals, max_planes=_MAX_MIRROR_PLANES):
    """Return the distinct orientations (P, 3) (sign ignored) of the faces of smooth-specular parts, or
    None when there are none or more than ``max_planes`` (curved mirrors: BSDF sampling alone)."""
    if not normals:
        return None
    n = np.concatenate(normals)
    n = n[np.isfinite(n).all(axis=1) & (np.linalg.norm(n, axis=1) > 0.5)]
    first = np.argmax(np.abs(n) > 1e-9, axis=1)
    n = n * np.sign(n[np.arange(len(n)), first])[:, None]
    uniq = np.unique(np.round(n, 6), axis=0)
    if not 0 < len(uniq) <= max_planes:
        return None
    return uniq / np.linalg.norm(uniq, axis=1, keepdims=True)
