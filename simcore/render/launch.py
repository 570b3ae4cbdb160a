"""The renderer's shared base: Mitsuba variants, task lanes and launches (packets, ``drjit.freeze`` replay), the
random numbers (TEA, PCG32, the host's key hash), and the host-side helpers every estimator uses (docs/renderer.md)."""
import contextlib
from dataclasses import dataclass, replace
import gc
import os
import threading
import weakref

import numpy as np

from simcore import _llvm
from simcore._llvm import host_array, host_buffer, host_wrap
from simcore.constants import AU_M, R_SUN_M

SUN_ANGULAR_RADIUS_RAD = float(np.arcsin(R_SUN_M / AU_M))  # 0.2666 deg: the 0.53 deg disc at 1 AU

_VARIANTS = ("llvm_ad_mono", "cuda_ad_mono")
# Rounds of the TEA hash behind the reflected paths' random numbers and the cover glass's (the direct and albedo
# kernels draw theirs from _SPLITMIX, Launcher._rand). Mitsuba's default, 4, is meant for seeding: with it the two
# samples of a stratum (consecutive lanes) come out correlated and the pair estimate of the variance reads ~8 % low
# (albedo z spread 1.09 over 4200 diode-epochs; 1.025 with 8 rounds, 1.006 with 16, 0.995 with 32).
_TEA_ROUNDS = 32
# SplitMix64 (Steele, Lea & Flood 2014: the golden gamma and Stafford's Mix13 finaliser), behind the direct and
# albedo kernels' random numbers (Launcher._rand): a task's lanes are consecutive outputs of one SplitMix64 stream
# (a generator that passes BigCrush), and the state (key, j) x gamma is a bijection, so no two lanes share one. One
# multiply-xorshift chain of ~12 operations instead of 32 TEA rounds: 1.4-1.7 against 6.6-7.7 ns a lane (CPU time,
# 2^22 lanes of the albedo kernel's six numbers), over the ~16 000 lanes per epoch of bench_render's orbit.
_SPLITMIX = (0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB)
_MAX_LANES = 1 << 22      # lanes per launch (memory bound, ~100 MB of temporaries)
# Lanes: each task's rays start on a multiple of this (Dr.Jit's CPU packets and Embree's ray packets hold at most 16
# rays), so that no packet mixes two tasks' rays. Embree's packet traversal can decide a ray that grazes an edge
# differently with other rays beside it (seen: 1 lane of 28 224 flipped with the epochs batched together, moving its
# diode-epoch by 0.02 %); a task's values then depended on the batch, and a run resumed with another --chunk on them.
_PACKET = 16
# Variants whose direct, albedo and proposal kernels are recorded once and replayed (Launcher._run).
_FREEZE_VARIANTS = ("llvm_ad_mono",)


# --------------------------------------------------------------------------- variants

def _anchored(dr, lanes, values):
    """Return a kernel's per-lane ``values`` passed through a select on the lanes' counter (always true: a launch
    holds < 2^32 - 1 lanes; the values are unchanged), so that a result the tracer folds to a constant still has
    one value per lane of the launch (Launcher._run)."""
    return dr.select(lanes.lane != 0xFFFFFFFF, values, 0.0)


def _cuda_works():
    """Return True when Dr.Jit can use a CUDA device in this process."""
    dr = _llvm.import_drjit()
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # a broken driver is "no GPU" here
        return False


def choose_variant(requested=None):
    """Return the Mitsuba variant to render with: 'cuda_ad_mono' when a CUDA GPU works,
    else 'llvm_ad_mono'; ``requested`` forces one and raises if it cannot run here.

    Raises ``ValueError`` for an unknown variant, ``RuntimeError`` when a CUDA
    variant is requested without a working GPU, and
    ``simcore._llvm.LLVMNotFoundError`` (with the install hint) when no usable
    libLLVM exists: Dr.Jit's CPU backend is needed with either variant.
    """
    if requested is not None and requested not in _VARIANTS:
        raise ValueError(f"unknown render variant {requested!r}; use one of {_VARIANTS} "
                         "or None to pick the GPU when there is one")
    variant = "llvm_ad_mono"
    if requested in (None, "cuda_ad_mono"):
        _llvm.import_mitsuba()  # loads drjit's backends
        if _cuda_works():
            variant = "cuda_ad_mono"
        elif requested is not None:
            raise RuntimeError("variant 'cuda_ad_mono' was requested but no working CUDA GPU was found "
                               "(Dr.Jit reports no CUDA backend); use variant='llvm_ad_mono' or None "
                               "to render on the CPU")
    # Dr.Jit's CPU backend, whichever variant renders: the analytic model's and the body shadow's float64 kernels
    # (simcore.radiometry.analytic, simcore.shapes.occlusion) run on it on a GPU machine too. Without it the first
    # of them dies (SIGFPE, seen on an H100 with no libLLVM) instead of saying what is missing.
    _llvm.find_libllvm()
    dr = _llvm.import_drjit()
    if not dr.has_backend(dr.JitBackend.LLVM):
        raise _llvm.LLVMNotFoundError(
            f"Dr.Jit could not load the libLLVM at {os.environ.get(_llvm.ENV)!r} (its CPU backend runs the analytic "
            "model whichever variant renders). " + _llvm.INSTALL_HINT)
    return variant


# --------------------------------------------------------------------------- random numbers and lanes

def _mix32(*parts):
    """Return a uint32 hash of integer arrays (a chain of splitmix64's finaliser, ``_SPLITMIX``), broadcast together."""
    m = np.uint64(0xFFFFFFFFFFFFFFFF)
    g, c1, c2 = (np.uint64(c) for c in _SPLITMIX)
    h = np.zeros(np.broadcast(*[np.asarray(p) for p in parts]).shape, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for p in parts:
            h = (h ^ (np.asarray(p).astype(np.uint64) & m)) + g
            h = (h ^ (h >> np.uint64(30))) * c1
            h = (h ^ (h >> np.uint64(27))) * c2
            h = h ^ (h >> np.uint64(31))
    return (h & np.uint64(0xFFFFFFFF)).astype(np.uint32)


# set of tasks (Launcher._tables) and read at the task's "row" ("earth_corners": the albedo proposal's per epoch, on the
# device already, read at the task's "epoch_row"); every other field of a task dict is a column of _Lanes.f or _Lanes.u.
_TABLES = ("cdf", "pmf", "tedge", "tlevel", "earth_corners")


@dataclass
class _Lanes:
    """One launch's inputs as Dr.Jit arrays, for the kernels: the tasks' float fields packed row by row in one
    float32 array ``f`` (T rows of ``nf`` columns) and their integer fields in one uint32 array ``u`` (``nu``
    columns), ``layout`` naming the columns ((field, first column, width, in u), ...); ``tables`` the per-task
    tables (``_TABLES``), the renderer's own (reflectivity map, visibility table) and the task of each packet of
    lanes; ``lane`` the lanes' counter 0 .. n - 1 (with ``packet``, ``packet_lane`` and ``task_lane`` count the
    packets and the tasks); ``scene`` the occluders (or None); ``task`` and ``j``, the lane's
    task and sample index, are found in the kernel (Launcher._with_indices).

    Packed so that a launch costs two uploads (:func:`simcore._llvm.host_array`, ~24 us each) rather than one per
    field and column (~36 a launch). A dataclass so that ``drjit.freeze`` traverses it (Launcher._run): its
    arrays are the frozen kernels' inputs, and ``layout``, ``nf`` and ``nu`` (Python values) are part of the
    recording's key."""

    f: object
    u: object
    tables: dict
    layout: tuple
    nf: int
    nu: int
    lane: object
    scene: object = None
    task: object = None
    j: object = None
    packet_lane: object = None
    task_lane: object = None

    def column(self, name):
        """Return (first column, width, in u) of field ``name``."""
        for entry in self.layout:
            if entry[0] == name:
                return entry[1:]
        raise KeyError(name)

    def has(self, name):
        """Return whether the tasks carry field ``name``."""
        return any(entry[0] == name for entry in self.layout) or name in self.tables


def occluder_scene(mesh, mi):
    """Return a Mitsuba scene of a ``trimesh.Trimesh`` (body frame, metres, satellite at the origin) that only
    blocks rays (no materials), for ``scene.ray_test``; None for an empty mesh. ``mi``: the mitsuba module with
    its variant set."""
    if mesh is None or len(getattr(mesh, "faces", ())) == 0:
        return None
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    if not np.all(np.isfinite(v)):
        raise ValueError("occluder mesh has non-finite vertices")
    if np.abs(v).max() > 100.0:
        raise ValueError("occluder mesh spans more than 100 m from the body origin; it must be the "
                         "satellite in body axes, in metres, centred on the satellite")
    m = mi.Mesh("occluders", len(v), len(f), has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(m)
    params["vertex_positions"] = host_array(mi.Float, v)
    params["faces"] = host_array(mi.UInt32, f)
    params.update()
    return mi.load_dict({"type": "scene", "occluders": m})


class _DrOps:
    """Dr.Jit's functions under the names of simcore.shapes.aperture's array-library neutral formulas."""

    def __init__(self, dr):
        self.maximum, self.minimum, self.where = dr.maximum, dr.minimum, dr.select
        self.sqrt, self.asin, self.exp, self.erf = dr.sqrt, dr.asin, dr.exp, dr.erf


def rays_blocked(scene, origins, directions, mi):
    """Return (M,) bool: whether each ray (origins, unit directions (M, 3), body frame) meets the occluders of
    ``scene`` (:func:`occluder_scene`)."""
    o = np.asarray(origins, dtype=np.float32).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    ray = mi.Ray3f(mi.Point3f(*(host_array(mi.Float, o[:, i]) for i in range(3))),
                   mi.Vector3f(*(host_array(mi.Float, d[:, i]) for i in range(3))))
    return np.asarray(scene.ray_test(ray).numpy(), bool)


class Launcher:
    """The launch machinery of :class:`simcore.render.renderer.Renderer` (a mixin: it reads the renderer's
    ``_dr``, ``_mi``, ``variant``, ``_scene``, reflectivity and visibility tables and ``_kernel_state``)."""

    # -- helpers for Dr.Jit
    def _v3(self, arr):
        mi = self._mi
        a = np.asarray(arr, dtype=np.float32)
        return mi.Vector3f(*(host_array(mi.Float, a[:, i]) for i in range(3)))

    def _gather3(self, src, idx):
        dr, mi = self._dr, self._mi
        return mi.Vector3f(dr.gather(mi.Float, src.x, idx), dr.gather(mi.Float, src.y, idx),
                           dr.gather(mi.Float, src.z, idx))

    def _tables(self, t):
        """Return the tables (``_TABLES``) of the tasks ``t`` as Dr.Jit arrays (row-major, one row a task), uploaded
        once for all of them, and ``row`` (T,): each task's row, the column the kernels read the tables at
        (whatever round or launch the task's lanes fall in: a round repeats a task in two groups, and the tables
        are ~4 kB a task)."""
        if any(t.get(k) is not None and not isinstance(t[k], np.ndarray) for k in _TABLES):
            # (tables already uploaded: their rows are those of the tasks they were uploaded for, which a subset's
            # new row numbers would no longer match)
            raise ValueError("_tables takes the tasks' numpy tables, not tables already uploaded")
        out = {k: host_array(self._mi.Float, t[k]) for k in _TABLES if isinstance(t.get(k), np.ndarray)}
        out["row"] = np.arange(len(t["k"]), dtype=np.uint32)
        return out

    def _lanes(self, t, n_lanes, packet=None):
        """Return the :class:`_Lanes` of tasks ``t`` (a dict of per-task numpy fields, None where absent) for a
        launch of ``n_lanes`` lanes; ``packet``: the task of each packet of lanes (:meth:`_launches`).

        Integer fields (and ``m``, the strata parameter, which the kernels read as an integer) become uint32
        columns; ``m`` also gives the float columns ``inv_m`` (1 / m) and ``half_inv_m`` (0.5 / m), divided in
        float64 as the kernels' inputs always were; the rest float32 columns (rounded from float64 once, on
        assignment, as a separate upload of each field rounded them)."""
        dr, mi = self._dr, self._mi
        T = len(t["key"])
        tables = {k: v for k, v in t.items() if k in _TABLES and v is not None}   # uploaded once (_tables)
        rest = {k: np.asarray(v) for k, v in t.items()
                if v is not None and k not in _TABLES and k not in ("_f", "_u", "_packed")}
        if "m" in rest:
            m = rest.pop("m")
            rest.update(m=m.astype(np.uint32), inv_m=1.0 / m, half_inv_m=0.5 / m)
        # the fields not packed yet, then those packed once for all the rounds (_pack), side by side
        blocks = [_pack(rest, skip=())] + ([t] if "_packed" in t else [])
        layout, nf, nu = [], 0, 0
        for blk in blocks:
            layout += [(n_, c + (nu if i_ else nf), w, i_) for n_, c, w, i_ in blk["_packed"]]
            nf, nu = nf + blk["_f"].shape[1], nu + blk["_u"].shape[1]
        # filled in place in Dr.Jit-safe buffers and handed over without another copy (simcore._llvm.host_buffer)
        f, u = host_buffer(T * nf, np.float32), host_buffer(T * nu, np.uint32)
        np.concatenate([blk["_f"] for blk in blocks], axis=1, out=f.reshape(T, nf))
        np.concatenate([blk["_u"] for blk in blocks], axis=1, out=u.reshape(T, nu))
        tables["refl"] = self._refl_dr
        tables["refl_max"] = self._refl_max_dr
        if self._sea_dr is not None:
            tables["sea"] = self._sea_dr
            tables["sea_max"] = self._sea_max_dr
        if self._vis is not None:
            tables["vis"] = self._vis
        if packet is not None:
            # (a 1-element array would be a literal baked into the kernel: a lone packet gets an unread second)
            tables["packet"] = host_array(mi.UInt32, packet if len(packet) > 1 else np.concatenate([packet, packet]))
        # The lanes' counter, evaluated: the one array the kernels read lane by lane, which gives a frozen kernel
        # its launch size (_run)
        lane = dr.arange(mi.UInt32, n_lanes)
        dr.make_opaque(lane)
        counters = {}
        if packet is not None:                          # (the launch sizes of the task sums, _task_sums)
            counters = dict(packet_lane=dr.arange(mi.UInt32, len(packet)), task_lane=dr.arange(mi.UInt32, T))
            dr.make_opaque(*counters.values())
        return _Lanes(host_wrap(mi.Float, f), host_wrap(mi.UInt32, u), tables, tuple(layout), nf, nu, lane, self._scene,
                      **counters)

    def _run(self, kernel, lanes, *args, sums=False):
        """Return ``kernel(lanes, *args)`` (a Dr.Jit array), the direct, albedo and proposal kernels replayed from a
        ``drjit.freeze`` recording (:meth:`_replay`): traced once per layout of their inputs, then launched without
        tracing again (docs/renderer.md, "Why replaying a recording is sound"). ``sums``: return the values' sums per
        task instead (:meth:`_task_sums`, in the same recording; a kernel is always launched one way or the
        other)."""
        if kernel.__name__ == "_reflected_kernel":
            out = kernel(lanes, *args)
            return self._task_sums(lanes, out) if sums else out
        return self._replay(kernel.__name__, self._launch, kernel.__name__, sums, lanes, *args)

    def _launch(self, name, sums, lanes, *args):
        """Return kernel ``name``'s values (or their sums per packet: ``sums``) on ``lanes`` (:meth:`_run`)."""
        # a recording of a kernel folded to a constant would hand back a constant of the recorded launch's size:
        # anchored, it is a kernel whose size is the lanes'
        out = _anchored(self._dr, lanes, getattr(self, name)(lanes, *args))
        return self._task_sums(lanes, out) if sums else out

    def _task_sums(self, a, vals):
        """Return (3,) float64 Dr.Jit arrays, one value per task of :meth:`_trace`'s lanes ``a``: over the task's strata
        (a, b) (lanes 2h, 2h + 1 of it, ``vals`` the lanes' values) within its ``count`` samples, the sums of a + b,
        (a - b)^2 and (a - b)^4: added stratum by stratum within each packet of ``_PACKET`` lanes, then packet by
        packet, in order (a packet holds one task's lanes: the sums do not depend on the launch).

        The sums of :func:`simcore.render.sampling._task_mean_var`, reduced on the device, so that the host reads
        three values a task instead of one a lane."""
        dr, mi = self._dr, self._mi
        f64 = mi.Float64
        p = a.packet_lane
        pa = replace(a, task=dr.gather(mi.UInt32, a.tables["packet"], p))
        lane0 = p * _PACKET
        j0 = lane0 - self._col(pa, "first")            # the packet's first sample index in its task
        count = self._col(pa, "count")
        s = d2 = d4 = f64(0.0)
        for i in range(0, _PACKET, 2):
            x = f64(dr.gather(mi.Float, vals, lane0 + i))
            y = f64(dr.gather(mi.Float, vals, lane0 + (i + 1)))
            ok = j0 + i < count
            d = x - y
            dd = d * d
            s = s + dr.select(ok, x + y, 0.0)
            d2 = d2 + dr.select(ok, dd, 0.0)
            d4 = d4 + dr.select(ok, dd * dd, 0.0)
        dr.eval(s, d2, d4)
        ta = replace(a, task=a.task_lane)
        p0 = self._col(ta, "first") // _PACKET         # the task's first packet and its number of packets
        n = (self._col(ta, "count") + (_PACKET - 1)) // _PACKET

        def add(i, *acc):
            return (i + 1, *[x + dr.gather(f64, y, p0 + i) for x, y in zip(acc, (s, d2, d4))])
        _, *sums = dr.while_loop((mi.UInt32(0), f64(0.0), f64(0.0), f64(0.0)), lambda i, *acc: i < n, add)
        return tuple(sums)

    def _col(self, a, name, i=0):
        """Return column ``i`` of field ``name`` of the lanes' tasks (:class:`_Lanes`): mi.Float, or mi.UInt32 for
        an integer field."""
        dr, mi = self._dr, self._mi
        c, _, in_u = a.column(name)
        if in_u:
            return dr.gather(mi.UInt32, a.u, a.task * a.nu + (c + i))
        return dr.gather(mi.Float, a.f, a.task * a.nf + (c + i))

    def _vec(self, a, name, row=0):
        """Return the 3-vector ``row`` (columns 3 row .. 3 row + 2) of field ``name`` of the lanes' tasks."""
        return self._mi.Vector3f(*(self._col(a, name, 3 * row + i) for i in range(3)))

    def _rand(self, key, j, k):
        """Return 2k uniform [0, 1) floats per lane: the two 32-bit halves of SplitMix64's output at state (key, j)
        x gamma (``_SPLITMIX``: lane j of the task's stream), then 2k - 2 from a PCG32 generator that this 64-bit
        word seeds (its state; one multiply-add a number)."""
        mi = self._mi
        g, c1, c2 = _SPLITMIX
        x = ((mi.UInt64(key) << 32) | mi.UInt64(j)) * g
        x = (x ^ (x >> 30)) * c1
        x = (x ^ (x >> 27)) * c2
        x = x ^ (x >> 31)
        a, b = mi.UInt32(x >> 32), mi.UInt32(x & 0xFFFFFFFF)
        out = [mi.Float(a >> 8) * (1.0 / 16777216.0), mi.Float(b >> 8) * (1.0 / 16777216.0)]
        if k > 1:
            rng = mi.PCG32()
            rng.seed(initstate=x)
            out += [mi.Float(rng.next_uint32() >> 8) * (1.0 / 16777216.0) for _ in range(2 * k - 2)]
        return out

    def _blocked_by_mesh(self, a, o, d, active=True):
        """Return whether the ray from ``o`` along ``d`` meets the mesh (``a.scene``, :class:`_Lanes`); False for
        lanes not ``active`` (those whose value cannot depend on it: their rays are not traced)."""
        if a.scene is None:
            return self._mi.Bool(False)       # (a scalar, no array of a recorded launch's width)
        return a.scene.ray_test(self._mi.Ray3f(o, d), active)

    # -- lanes: task k owns counts[k] consecutive lanes (its samples), split into launches
    def _launches(self, counts):
        """Yield (task slice, the task of each packet of ``_PACKET`` lanes (np.uint32), each task's first lane
        (np.uint32)) per launch, for tasks of ``counts`` (T,) samples each, positive multiples of ``_PACKET``.

        Per packet rather than per lane: the kernels find a lane's task and sample index from these
        (:meth:`_with_indices`), so that the host builds 1/16 of the lanes' worth of indices."""
        if len(counts) and (counts.min() < 1 or np.any(counts % _PACKET)):
            raise ValueError(f"every task needs a positive multiple of {_PACKET} samples, got counts "
                             f"{counts.min()} .. {counts.max()}")
        ends = np.cumsum(counts)
        start = 0
        while start < len(counts):
            base = ends[start] - counts[start]
            stop = int(np.searchsorted(ends, base + _MAX_LANES, side="right"))
            stop = max(stop, start + 1)
            if stop == start + 1 and len(counts) > start + 1:
                stop = start + 2                  # keep >= 2 tasks: a 1-element array is a literal
            sl = slice(start, stop)
            c = counts[sl]                                    # (a launch holds < 2^32 lanes)
            yield sl, np.repeat(np.arange(len(c), dtype=np.uint32), c // _PACKET), (np.cumsum(c) - c).astype(np.uint32)
            start = stop

    def _with_indices(self, a):
        """Return the lanes ``a`` (:class:`_Lanes` of a :meth:`_trace` launch) with each lane's task and sample index
        (``task``, ``j``): the task of its packet (``tables['packet']``) and its offset from the task's first lane
        (column ``first``)."""
        dr, mi = self._dr, self._mi
        task = dr.gather(mi.UInt32, a.tables["packet"], a.lane >> int(np.log2(_PACKET)))
        a = replace(a, task=task)
        return replace(a, j=a.lane - self._col(a, "first"))

    def _trace(self, kernel, t, counts):
        """Return (3, T) float64: per task of ``t``, over its strata (a, b) (lanes 2h, 2h + 1 of its ``counts`` (T,)
        samples, ``kernel``'s values), the sums of a + b, (a - b)^2 and (a - b)^4 (:meth:`_task_sums`). The lanes are
        laid out task after task, each task's first lane on a multiple of ``_PACKET`` (its lanes past ``counts`` are
        traced but not summed)."""
        T = len(counts)
        if T < 2:                                 # a 1-element array would be baked in as a literal
            t = _pad2(t)
            return self._trace(kernel, t, np.concatenate([counts, [2]]))[:, :T]
        padded = -(-counts // _PACKET) * _PACKET
        out = []
        for sl, packet, first in self._launches(padded):
            sub = dict(_take(t, sl), first=first, count=counts[sl].astype(np.uint32))
            if sl.stop - sl.start < 2:
                sub = _pad2(sub)
            sums = self._run(kernel, self._lanes(sub, len(packet) * _PACKET, packet), sums=True)
            out.append(np.stack([s.numpy()[:sl.stop - sl.start] for s in sums]))
        return out[0] if len(out) == 1 else np.concatenate(out, axis=1)

    def _joined(self, parts, per):
        """Return the values of launches ``parts`` [(task slice, an array or a tuple of arrays of ``per`` values a
        task)] (:meth:`_trace_tasks`'s slices) as whole arrays over all their tasks: one launch's as they are, those of
        several scattered into one."""
        dr, mi = self._dr, self._mi
        first = parts[0][1]
        if len(parts) == 1:
            return first
        single = not isinstance(first, tuple)
        out = [dr.zeros(mi.Float, parts[-1][0].stop * per) for _ in ((first,) if single else first)]
        for sl, v in parts:
            at = dr.arange(mi.UInt32, sl.start * per, sl.stop * per)
            for whole, part in zip(out, (v,) if single else v):
                dr.scatter(whole, part, at)
        return out[0] if single else tuple(out)

    def _trace_tasks(self, kernel, t, n_points, **tables):
        """Yield (task slice, ``kernel(lanes, n_points)`` as a Dr.Jit array of the slice's tasks x ``n_points``
        values) for the tasks ``t`` (at least 2) in launches of bounded size; ``tables``: tables (``_TABLES``) already
        on the device, passed to every launch as they are."""
        T = len(t["key"])
        if T < 2:                                 # a 1-element array would be baked in as a literal
            raise ValueError("_trace_tasks needs at least 2 tasks (pad them: _pad2)")
        t = dict(t, **self._tables(t), **tables)
        per = max(2, _MAX_LANES // n_points)
        n = -(-T // per)
        edges = np.linspace(0, T, n + 1).round().astype(int)
        for a, b in zip(edges[:-1], edges[1:]):
            yield slice(a, b), self._run(kernel, self._lanes(_take(t, slice(a, b)), (b - a) * n_points), n_points)

    def _replay(self, name, method, *args):
        """Return ``method(*args)`` (a method of the renderer that computes on Dr.Jit arrays) replayed from its
        ``drjit.freeze`` recording ``name`` on the variants that record (``_FREEZE_VARIANTS``); traced at each call
        on the others."""
        if self.variant not in _FREEZE_VARIANTS:
            return method(*args)
        frozen = self._frozen.get(name)
        if frozen is None:
            # Weak references to the renderer: the wrappers it holds must not hold it, or it would die only in the
            # cycle collector, at any time, possibly inside another recording, where releasing its numpy-backed
            # arrays aborts the process (Dr.Jit 1.5: "enqueue_host_func(): this function cannot be recorded!").
            method_ref, state_ref = weakref.WeakMethod(method), weakref.WeakMethod(self._kernel_state)
            frozen = self._frozen[name] = self._dr.freeze(lambda *a: method_ref()(*a),
                                                          state_fn=lambda *a, **k: state_ref()(*a, **k))
        # No cycle collection while recording or replaying: garbage from elsewhere holding numpy-backed Dr.Jit
        # arrays, released inside the frozen call, would abort the process as above.
        with _no_cycle_collection(), _llvm.FROZEN_CALLS:    # (see _llvm.FROZEN_CALLS: another thread's Dr.Jit work)
            return frozen(*args)


_GC_GUARD = threading.Lock()
_GC_STATE = {"depth": 0, "was_enabled": False}


@contextlib.contextmanager
def _no_cycle_collection():
    """Switch Python's cycle collector off for the duration (Launcher._run's frozen calls), and back on when the last
    of the threads inside such a block leaves it, if it was on before the first entered (a plain disable/enable per
    call would let one thread's exit switch it on while another records)."""
    with _GC_GUARD:
        if _GC_STATE["depth"] == 0:
            _GC_STATE["was_enabled"] = gc.isenabled()
            gc.disable()
        _GC_STATE["depth"] += 1
    try:
        yield
    finally:
        with _GC_GUARD:
            _GC_STATE["depth"] -= 1
            if _GC_STATE["depth"] == 0 and _GC_STATE["was_enabled"]:
                gc.enable()


def _pack(t, skip=("m",)):
    """Return the task dict ``t`` with its numpy fields (but those in ``skip`` and the tables, ``_TABLES``) packed as
    the kernels read them (:meth:`Launcher._lanes`): ``_f`` (T, nf) float32 (rounded from float64 once, on
    assignment) and ``_u`` (T, nu) uint32 (integer fields), ``_packed`` naming their columns ((field, first column,
    width, in _u), ...). Packed once per estimator and batch (:meth:`Rounds._rounds`: ``m`` is set per round), a round
    takes its tasks' rows of two arrays (:func:`_take`) instead of every field's, and casts nothing."""
    T = len(next(v for v in t.values() if isinstance(v, np.ndarray)))
    out, cols, nf, nu = {}, [], 0, 0
    for name, v in t.items():
        if not isinstance(v, np.ndarray) or name in _TABLES or name in skip:
            out[name] = v
            continue
        integer = v.dtype.kind in "iub"
        v = v.reshape(T, -1)
        cols.append((name, nu if integer else nf, v.shape[1], integer, v))
        if integer:
            nu += v.shape[1]
        else:
            nf += v.shape[1]
    f, u = np.empty((T, nf), np.float32), np.empty((T, nu), np.uint32)
    for _, c, w, integer, v in cols:
        (u if integer else f)[:, c:c + w] = v
    return dict(out, _f=f, _u=u, _packed=tuple(col[:4] for col in cols))


def _pad2(t):
    """Return the task dict padded to >= 2 tasks (a 1-element Dr.Jit array would become a
    literal baked into the kernel, so every new value would compile a new kernel)."""
    if len(t["key"]) >= 2:
        return t
    return {k: (np.concatenate([v, v]) if isinstance(v, np.ndarray) else v) for k, v in t.items()}


def _take(t, idx):
    """Return the task dict ``t`` of the tasks ``idx`` (indices or a slice): its numpy fields indexed, the rest (None,
    and the tables uploaded once for all its tasks, Launcher._tables) as they are."""
    return {k: (v[idx] if isinstance(v, np.ndarray) else v) for k, v in t.items()}
