"""The per-task sums that the device reduces from the lanes (Launcher._trace, Launcher._task_sums).

The oracle: numpy's float64 sums over the strata (a, b) of the same lane values, computed on the host from the
lane formula (exact in float32 on both sides), with the lanes past each task's count left out."""

import numpy as np
import pytest

from simcore.render import DiodeSurfaces, Renderer
from simcore.render import launch
from simcore.shapes.aperture import diode_frame

VARIANT = "llvm_ad_mono"


class _Probe(Renderer):
    """A renderer with a kernel whose lane values are known: (j mod 7) x + (j mod 4), in float32, ``j`` the lane's
    sample index in its task and ``x`` the task's field."""

    def _probe_kernel(self, a):
        mi = self._mi
        a = self._with_indices(a)
        return mi.Float(a.j % 7) * self._col(a, "x") + mi.Float(a.j & 3)


def _lane_values(x, n):
    j = np.arange(n)
    return (j % 7).astype(np.float32) * np.float32(x) + (j & 3).astype(np.float32)


def _oracle(x, counts):
    out = []
    for xi, n in zip(x, counts):
        v = _lane_values(xi, n).astype(np.float64)
        a, b = v[0::2], v[1::2]
        out.append([np.sum(a + b), np.sum((a - b) ** 2), np.sum((a - b) ** 4)])
    return np.array(out).T


@pytest.fixture(scope="module")
def probe():
    ds = DiodeSurfaces(np.zeros((1, 3)), diode_frame(np.array([0.0, 0.0, 1.0]))[None], [0.01, 0.01])
    return _Probe(ds, variant=VARIANT)


def _tasks(x):
    return dict(key=np.arange(len(x), dtype=np.uint32), x=np.asarray(x, np.float32))


def test_task_sums_match_the_strata_sums_of_the_lanes_within_each_count(probe):
    # counts off the packet size (their last packets padded with lanes that must not count) and on it
    counts = np.array([4, 18, 32, 100, 2, 1026, 16, 50])
    x = np.linspace(0.3, 2.9, len(counts))
    got = probe._trace(probe._probe_kernel, _tasks(x), counts)
    np.testing.assert_allclose(got, _oracle(x, counts), rtol=1e-13, atol=0)
    one = probe._trace(probe._probe_kernel, _tasks(x[3:4]), counts[3:4])       # a lone task (padded to two)
    np.testing.assert_allclose(one, _oracle(x[3:4], counts[3:4]), rtol=1e-13, atol=0)


def test_a_tasks_sums_do_not_depend_on_its_neighbours_or_the_launches(probe, monkeypatch):
    counts = np.array([1026, 34, 4000, 18, 640, 2])
    x = np.linspace(0.7, 1.9, len(counts))
    together = probe._trace(probe._probe_kernel, _tasks(x), counts)
    monkeypatch.setattr(launch, "_MAX_LANES", 1024)      # many launches, tasks spread over them
    split = probe._trace(probe._probe_kernel, _tasks(x), counts)
    alone = np.concatenate([probe._trace(probe._probe_kernel, _tasks(x[i:i + 1]), counts[i:i + 1])
                            for i in range(len(counts))], axis=1)
    np.testing.assert_array_equal(split, together)
    np.testing.assert_array_equal(alone, together)
