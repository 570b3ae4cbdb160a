"""Rounds of samples per task: the sampling plan (:class:`Sampling`), one round traced and reduced to a mean, a
standard error and its degrees of freedom, and the two-stage rule that sizes a round to a target (docs/renderer.md)."""
from dataclasses import dataclass, replace

import numpy as np

from simcore.render.launch import _mix32, _pack, _take

# Estimators (part of the random-number key): the direct Sun, the albedo, the direct Sun without the
# analytic aperture split (the check's independent estimate).
_DIRECT, _ALBEDO, _DIRECT_PLAIN, _REFLECTED = 1, 2, 3, 4


@dataclass(frozen=True, eq=False)
class Sampling:
    """How an estimator samples its tasks (:meth:`Rounds._rounds`): ``seed``; ``n0`` (T,) or one count, the
    first round's samples per task; ``fac`` (T,) or one factor, lane units -> W/m^2; ``size``, the sample counts
    the estimator's stratification can take for requested ones; ``power``, the error falls as n^(-1/power);
    ``rel``, the target relative standard error (None: one round of ``n0``); ``floor``, the absolute one
    (W/m^2); ``cap``, the most samples per task; ``skip`` (T, 2), groups of the aperture split known to be empty;
    ``plain``, no aperture split; ``pilot``, the pilot round takes ``n0 // pilot`` samples; ``conf``, the pilot's
    standard error is raised by ``conf / sqrt(2 nu)`` of itself (nu its degrees of freedom) before it sizes the
    final round; ``settled`` (T,) bool or None, tasks whose estimate is known to have no variance (almost surely):
    they skip the pilot and take a final round of ``n0``, as a task whose pilot read none; ``group_b``, the aperture
    split's group B takes 1 / ``group_b`` of a round's samples and group A the rest (docs/renderer.md, "Aperture
    split")."""

    seed: int
    n0: object
    fac: object
    size: object
    power: float = 2.0
    rel: float = None
    floor: float = 0.0
    cap: object = None
    skip: object = None
    plain: bool = False
    pilot: int = 4
    conf: float = 0.0
    settled: object = None
    group_b: int = 5


class Rounds:
    """Rounds of samples (a mixin of :class:`simcore.render.renderer.Renderer`: reads ``control_variate``,
    ``_plain`` and :meth:`simcore.render.launch.Launcher._trace`)."""

    def _rounds(self, kernel, base, kind, g_, k_, plan):
        """Return (mean, standard error, effective degrees of freedom, samples) per task in ``base``, in lane units
        x ``plan.fac``, by the :class:`Sampling` ``plan`` (docs/renderer.md, "Rounds toward a target")."""
        base = _pack(base)
        n0 = np.broadcast_to(np.asarray(plan.n0, np.int64), (len(g_),))
        if plan.rel is None:
            return self._round(kernel, base, kind, g_, k_, plan, n0.copy(), 0)
        pilot = np.maximum(n0 // plan.pilot, 16)
        m, se, dof, n = np.zeros(len(g_)), np.zeros(len(g_)), np.full(len(g_), np.inf), pilot.astype(float)
        go = np.arange(len(g_)) if plan.settled is None else np.flatnonzero(~plan.settled)
        if len(go) == len(g_):
            m, se, dof, n = self._round(kernel, base, kind, g_, k_, plan, pilot, 0)
        elif len(go):                                   # the settled tasks read as a pilot with no variance
            sub = replace(plan, n0=n0[go], fac=_sub(plan.fac, go), skip=None if plan.skip is None else plan.skip[go])
            for a, b in zip((m, se, dof, n), self._round(kernel, _take(base, go), kind, g_[go], k_[go], sub,
                                                         pilot[go], 0)):
                a[go] = b
        # an upper confidence bound on the pilot's standard error (its relative spread is ~1 / sqrt(2 nu))
        need, want = _shortfall(m, se * (1.0 + plan.conf / np.sqrt(2.0 * np.maximum(dof, 1.0))), n, plan.rel,
                                plan.floor, plan.power)
        counts = np.clip(np.where(need, want, n0), n0, np.maximum(plan.cap, n0)).astype(np.int64)
        return self._round(kernel, base, kind, g_, k_, plan, counts, 1)

    def _round(self, kernel, base, kind, g_, k_, plan, counts, rnd):
        """Trace round ``rnd`` of ``counts`` (T,) samples for the tasks in ``base`` by the :class:`Sampling`
        ``plan``; return (mean, standard error, effective degrees of freedom, samples) per task, in lane units x
        ``plan.fac`` (docs/renderer.md, "One round: the split's groups and the standard error's degrees of
        freedom")."""
        T = len(g_)
        todo = np.arange(T)
        size, skip = plan.size, plan.skip
        if self.control_variate and not plan.plain:
            gb = plan.group_b
            na = size(np.maximum(counts * (gb - 1) // gb, 1))
            nb = size(np.maximum(counts // gb, 1))
            sa = np.zeros(T, bool) if skip is None else skip[:, 0]
            sb = np.zeros(T, bool) if skip is None else skip[:, 1]
            na = np.where(sb, size(counts), na)        # only A: give it the whole budget
            nb = np.where(sa, size(counts), nb)
            whole = self._plain[k_]                    # round wells: no split, the disc's control variate
            sa, sb = sa | whole, sb | whole
            parts = [(3, todo[whole], size(counts)[whole]), (1, todo[~sa], na[~sa]), (2, todo[~sb], nb[~sb])]
        else:
            parts = [(0, todo, size(counts))]
        idx = np.concatenate([p[1] for p in parts])
        lanes = np.concatenate([p[2] for p in parts]).astype(np.int64)
        mode = np.concatenate([np.full(len(p[1]), p[0]) for p in parts])
        t = _take(base, idx)
        t["key"] = _mix32(plan.seed, g_[idx], k_[idx], kind, rnd, mode)
        t["mode"] = mode
        t["m"] = _strata_param(kind != _ALBEDO, lanes)
        mean, var, var2 = _task_mean_var(self._trace(kernel, t, lanes), lanes)
        # each task's groups added in order (numpy.bincount, as numpy.add.at on zeros but ~10x faster)
        est, v, v2, nr = (np.bincount(idx, x, minlength=T) for x in (mean, var, var2, lanes))
        with np.errstate(divide="ignore", invalid="ignore"):
            dof = np.where(v2 > 0, v * v / np.where(v2 > 0, v2, 1.0), np.inf)
        return plan.fac * est, plan.fac * np.sqrt(v), dof, nr


def _sub(x, idx):
    """Return ``x`` (T,) at ``idx``, or ``x`` itself when it is one value."""
    return x[idx] if np.ndim(x) else x


def _direct_size(n):
    """Return the direct sample counts >= n (4 m^2, m >= 2) for requested counts n."""
    m = np.maximum(np.ceil(np.sqrt(np.asarray(n) / 4.0)), 2)
    return (4 * m * m).astype(np.int64)


def _albedo_size(n):
    """Return the albedo sample counts >= n (even, >= 4)."""
    return np.maximum(2 * np.ceil(np.asarray(n) / 2.0), 4).astype(np.int64)


def _strata_param(direct, counts):
    """Return the per-task stratification parameter the kernels read as t['m']: m for the
    direct (4 m^2 samples), the number of strata for the albedo (2 samples each)."""
    if direct:
        return np.round(np.sqrt(counts / 4.0))
    return counts / 2.0


def _task_mean_var(sums, counts):
    """Return the mean (T,), the variance of the mean (T,) and the sum of the squares of its strata's
    terms (T,; for the effective degrees of freedom) of tasks of ``counts`` samples each taken as strata of two
    samples (a, b), from ``sums`` (3, T): the sums of a + b, (a - b)^2 and (a - b)^4 over each task's strata
    (:meth:`simcore.render.launch.Launcher._trace`, float64)."""
    # a task's m strata all have the term (a - b)^2 / (4 m^2), so its sums divide once
    m = (counts // 2).astype(np.float64)
    return sums[0] / counts, sums[1] / (4.0 * m * m), sums[2] / (16.0 * m ** 4)


def _shortfall(mean, se, n, rel, floor, power):
    """Return (tasks above their target standard error, samples the target needs), from a round of
    ``n`` samples that gave ``mean`` and ``se``, assuming the error falls as n^(-1/power)."""
    target = np.maximum(rel * np.abs(mean), floor)
    need = se > target
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        want = 1.2 * n * (se / target) ** power
    want = np.nan_to_num(want, nan=1.0, posinf=1e18)
    return need, want
