"""The albedo proposal's PMF and CDF, built on the device (EarthAlbedo._proposal_tables), are numpy's bit for bit.

The oracle: the tables' definition written in numpy (a bin's weight the largest of its four corners, the weights
normalised by their float32 sum and mixed with the defensive share of the bins' solid angles, the uniform fallback
for a task without weight, the float64 running sum divided by its last value), on random corner weights."""

import numpy as np
import pytest

from scenes.config import SatelliteConfig
from scenes.meshes import build_satellite_mesh
from simcore._llvm import host_array
from simcore.render import DiodeSurfaces, Renderer
from simcore.render import launch
from simcore.render.albedo import _DEFENSIVE, _N_P, _N_T

VARIANT = "llvm_ad_mono"
B = _N_T * _N_P


def _numpy_tables(f, tedge):
    fc = f.reshape(-1, _N_T + 1, _N_P + 1)
    corner = np.maximum(np.maximum(fc[:, :-1, :-1], fc[:, 1:, :-1]), np.maximum(fc[:, :-1, 1:], fc[:, 1:, 1:]))
    wbin = corner.reshape(len(fc), -1)
    tot = wbin.sum(axis=1, keepdims=True)
    omega = np.diff(tedge, axis=1) / _N_P
    a = (1 - _DEFENSIVE) * wbin
    a /= np.where(tot > 0, tot, 1.0)
    pmf = (a.reshape(-1, _N_T, _N_P) + (_DEFENSIVE * omega)[:, :, None]).reshape(len(fc), -1)
    empty = ~(tot[:, 0] > 0)
    pmf[empty] = np.repeat(omega[empty], _N_P, axis=1)
    cdf = np.cumsum(pmf, axis=1)
    cdf /= cdf[:, -1:]
    cdf[:, -1] = 1.0
    return pmf.astype(np.float32), cdf.astype(np.float32)


@pytest.fixture(scope="module")
def rend():
    cfg = SatelliteConfig.load("tilt20_fov70")
    return Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT)


def test_device_tables_are_numpys_bit_for_bit(rend):
    dr, mi = rend._dr, rend._mi
    rng = np.random.default_rng(5)
    T = 37
    f = (rng.random((T, (_N_T + 1) * (_N_P + 1))) ** 6 * rng.lognormal(0, 3, (T, 1))).astype(np.float32)
    f[f < 0.05] = 0.0                                # dark corners
    f[[4, 20]] = 0.0                                 # tasks without weight: the uniform fallback
    f[9, 100], f[11, 0], f[13, -1] = np.nan, np.nan, np.nan     # NaN corners: inside, and at either end
    tedge = np.sort(rng.random((T, _N_T + 1)), axis=1)
    tedge[:, 0], tedge[:, -1] = 0.0, 1.0
    bins, tasks = dr.arange(mi.UInt32, T * B), dr.arange(mi.UInt32, T)
    dr.make_opaque(bins, tasks)
    pmf, cdf = rend._replay("_proposal_tables", rend._proposal_tables, host_array(mi.Float, f),
                            host_array(mi.Float64, np.diff(tedge, axis=1) / _N_P), bins, tasks)
    with np.errstate(invalid="ignore"):
        want_pmf, want_cdf = _numpy_tables(f, tedge)
    for k in (9, 11, 13):                            # (numpy's uniform fallback)
        assert np.array_equal(want_pmf[k], np.repeat(np.diff(tedge[k]) / _N_P, _N_P).astype(np.float32))
    np.testing.assert_array_equal(pmf.numpy().reshape(T, B), want_pmf)
    np.testing.assert_array_equal(cdf.numpy().reshape(T, B), want_cdf)


def test_the_tables_do_not_depend_on_the_launches(rend, monkeypatch):
    # The proposal of real tasks, in one launch and in launches of 3 tasks or epochs (their tables put together at
    # offsets)
    rng = np.random.default_rng(2)
    n = 9
    sun = rng.normal(size=(n, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    down = rng.normal(size=(n, 3))
    earth = 7.07e6 * down / np.linalg.norm(down, axis=1, keepdims=True)
    rot, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    ep, dk = np.arange(n) // 2, np.arange(n) % rend.diodes.count       # (tasks sharing epochs: their Earth's factor)
    t = rend._tasks(ep, dk, sun, earth)
    t.update(rot=rot[ep], key=np.zeros(n, np.uint32))
    one = rend._albedo_proposal(t, ep, sun, earth, rot)
    monkeypatch.setattr(launch, "_MAX_LANES", 3 * (_N_T + 1) * (_N_P + 1))
    split = rend._albedo_proposal(t, ep, sun, earth, rot)
    for k in ("pmf", "cdf"):
        assert one[k].numpy().any()
        np.testing.assert_array_equal(split[k].numpy(), one[k].numpy())
