"""The renderer's frozen kernels (drjit.freeze, simcore.render.launch.Launcher._run) give what tracing gives.

The oracle is Dr.Jit's ordinary path: the same kernels traced anew at every launch (freezing switched off with
``JitFlag.KernelFreezing``). A replay runs the recorded kernels on new inputs of other sizes (other epochs, task
counts, sample counts), so the two agree bit for bit only if every input the values depend on reaches the
recording as an input and the launch sizes follow the inputs, which is what this checks.

Only the variants in ``_FREEZE_VARIANTS`` record: llvm_ad_mono, which these tests pin, so that a GPU machine checks
it too. cuda_ad_mono traces every launch: on an H100 (2026-11-25) its replay, switched on for the purpose, passed
these tests bit for bit, but rendered no faster (bench_render 0.448 against 0.461 ms per epoch: the GPU path's time
is the host's, 0.46 ms of CPU per epoch), so it stays off.
"""

import gc

import numpy as np
import pytest

from scenes.config import SatelliteConfig
from scenes.meshes import build_satellite_mesh
from simcore._llvm import import_drjit
from simcore.render import SUN_ANGULAR_RADIUS_RAD, DiodeSurfaces, Renderer

VARIANT = "llvm_ad_mono"       # the variant that records and replays

_ARRAYS = ("direct_w_m2", "direct_se_w_m2", "direct_samples", "direct_dof",
           "albedo_w_m2", "albedo_se_w_m2", "albedo_samples", "albedo_dof")


@pytest.fixture(autouse=True)
def _no_garbage_from_earlier_tests():
    """Collect earlier tests' cyclic garbage before each test: drjit.freeze keys a recording on every Mitsuba Shape
    alive in the process (the registry it traverses with a scene among the inputs), so an earlier test's renderer
    dying in the cycle collector between two launches of this test's renderer makes it record its kernels anew:
    the likely cause of ``_direct_kernel`` "recorded twice" seen once in a full-suite run (the registry's part is
    reproduced by test_another_renderer_built_between_launches_changes_no_value)."""
    gc.collect()


def _epochs(n, seed):
    """Return (sun (n, 3), Earth's centre (n, 3) m, R_ecef_from_body (n, 3, 3)): random attitudes, 700 km up."""
    rng = np.random.default_rng(seed)
    sun = rng.normal(size=(n, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    down = rng.normal(size=(n, 3))
    down /= np.linalg.norm(down, axis=1, keepdims=True)
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    return sun, 7.07e6 * down, q


def _render(cfg, frozen, sun, earth, rot, **kw):
    """Return (RenderResult, Renderer) of ``cfg`` rendered with freezing on or off (``glint``, a Sun radius: the
    Renderer's)."""
    dr = import_drjit()
    flag = dr.flag(dr.JitFlag.KernelFreezing)
    dr.set_flag(dr.JitFlag.KernelFreezing, frozen)
    try:
        rend = Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT,
                        sun_angular_radius_rad=kw.pop("sun_angular_radius_rad", 0.0), glint=kw.pop("glint", None))
        res = rend.render(sun, earth, rot, **kw)
    finally:
        dr.set_flag(dr.JitFlag.KernelFreezing, flag)
    return res, rend


@pytest.mark.parametrize("disc", [0.0, SUN_ANGULAR_RADIUS_RAD])
def test_frozen_kernels_equal_traced_ones_bit_for_bit(disc):
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(40, seed=3)
    # 8 epochs a batch with target accuracies: launches of many sizes (tasks, samples) per kernel
    kw = dict(seed=7, batch_epochs=8, rel_se_direct=0.002, rel_se_albedo=0.01, sun_angular_radius_rad=disc)
    got, rend = _render(cfg, True, sun, earth, rot, **dict(kw))
    ref, traced = _render(cfg, False, sun, earth, rot, **dict(kw))
    # each kernel recorded once and replayed for every later launch (else this would compare tracing with itself);
    # the reference traced every launch (recorded nothing)
    assert {k: f.n_recordings for k, f in rend._frozen.items()} == {
        "_direct_kernel": 1, "_albedo_kernel": 1, "_earth_corners": 1, "_proposal_kernel": 1, "_proposal_tables": 1}
    assert all(f.n_recordings == 0 for f in traced._frozen.values())
    assert np.all(got.direct_samples[got.direct_w_m2 > 0] > 0) and got.albedo_samples.sum() > 0
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)


def test_another_renderer_built_between_launches_changes_no_value():
    # drjit.freeze's key holds every Mitsuba Shape alive (its registry, traversed with the occluders' scene): a
    # renderer built between two renders of another makes the latter record its kernels anew. The recordings stay
    # sound: the values are those of tracing every launch, bit for bit.
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(16, seed=5)
    kw = dict(seed=3, batch_epochs=8, direct_samples=256, albedo_samples=64)
    rend = Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT)
    first = rend.render(sun[:8], earth[:8], rot[:8], **kw)
    other = Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT)
    second = rend.render(sun[8:], earth[8:], rot[8:], epoch_offset=8, **kw)
    assert rend._frozen["_direct_kernel"].n_recordings == 2 and other is not None
    ref, _ = _render(cfg, False, sun, earth, rot, **dict(kw))
    for name in _ARRAYS:
        got = np.concatenate([getattr(first, name), getattr(second, name)])
        np.testing.assert_array_equal(got, getattr(ref, name), err_msg=name)


def test_frozen_kernels_with_windows_and_round_wells_and_the_plain_estimate():
    # the kernels' other code paths: a cover glass over each diode, round wells (the disc control variate), and
    # hint=False (no aperture split); each a layout of its own inputs, recorded and replayed as such
    cfg = SatelliteConfig.from_dict({"layout": {"pattern": "thesis14", "tilt_deg": 20, "fov_deg": 70, "window": {
        "index": 1.5, "thickness_mm": 0.5, "gap_mm": 0.5, "size_mm": [6.5, 6.5]}}})
    sun, earth, rot = _epochs(24, seed=5)
    kw = dict(seed=2, batch_epochs=6, direct_samples=256, albedo_samples=64)
    got, rend = _render(cfg, True, sun, earth, rot, **dict(kw))
    ref, _ = _render(cfg, False, sun, earth, rot, **dict(kw))
    # each kernel recorded once and replayed for the later launches (else this compares tracing with tracing)
    assert rend._frozen and all(f.n_recordings == 1 for f in rend._frozen.values())
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    from importlib.resources import files
    rw = SatelliteConfig.load(files("scenes") / "examples" / "round_wells.toml")
    got, _ = _render(rw, True, sun, earth, rot, hint=False, **dict(kw))
    ref, _ = _render(rw, False, sun, earth, rot, hint=False, **dict(kw))
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    got, _ = _render(rw, True, sun, earth, rot, **dict(kw))
    ref, _ = _render(rw, False, sun, earth, rot, **dict(kw))
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)


def test_a_renderer_with_other_settings_records_its_own_kernels():
    # the renderer's settings that shape the traced code are part of the recordings' key (Renderer._kernel_state):
    # changing one on a renderer that has recorded its kernels records them anew, and the values follow
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(16, seed=11)
    kw = dict(seed=4, batch_epochs=8, direct_samples=256, albedo_samples=64)
    rend = Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT)
    rend.render(sun, earth, rot, **kw)
    rend.sun_angular_radius_rad = SUN_ANGULAR_RADIUS_RAD
    got = rend.render(sun, earth, rot, **kw)
    assert rend._frozen["_direct_kernel"].n_recordings == 2
    ref, _ = _render(cfg, False, sun, earth, rot, sun_angular_radius_rad=SUN_ANGULAR_RADIUS_RAD, **dict(kw))
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)


def test_one_renderer_through_the_calls_of_a_run_gives_the_traced_values():
    # sunsim run calls one renderer chunk after chunk, each time the full render and then the check's hint-free
    # direct estimate on a subset of epochs (epoch_index, albedo=False, hint=False, reflected=False, more samples);
    # a study without the Earth renders the direct Sun alone; and a renderer's map may start at another longitude.
    # Every call on the frozen renderer gives what a renderer tracing every launch gives, bit for bit.
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(24, seed=13)
    dr = import_drjit()
    flag = dr.flag(dr.JitFlag.KernelFreezing)
    results = {}
    try:
        for frozen in (True, False):
            dr.set_flag(dr.JitFlag.KernelFreezing, frozen)
            rend = Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT,
                            sun_angular_radius_rad=SUN_ANGULAR_RADIUS_RAD)
            out = []
            for start in (0, 12):
                sl = slice(start, start + 12)
                out.append(rend.render(sun[sl], earth[sl], rot[sl], seed=5, epoch_offset=start, batch_epochs=8,
                                       rel_se_direct=0.002, rel_se_albedo=0.01))
                pick = np.array([1, 4, 9])
                out.append(rend.render(sun[sl][pick], earth[sl][pick], rot[sl][pick], seed=5,
                                       epoch_index=start + pick, albedo=False, hint=False, reflected=False,
                                       direct_samples=1024))
            out.append(rend.render(sun, seed=6, direct_samples=256))                # no Earth
            rend.lon_west_rad += 0.3
            out.append(rend.render(sun, earth, rot, seed=7, direct_samples=144, albedo_samples=64))
            results[frozen] = out
            if frozen:
                counts = {k: f.n_recordings for k, f in rend._frozen.items()}
    finally:
        dr.set_flag(dr.JitFlag.KernelFreezing, flag)
    # replayed, not recorded at every call: the direct kernel once per layout of its inputs (with the Earth,
    # without), the albedo and proposal kernels once and again after the map's longitude changed
    assert counts["_direct_kernel"] <= 4 and counts["_albedo_kernel"] == 2 and counts["_proposal_kernel"] == 2
    assert counts["_earth_corners"] == 2
    for i, (got, ref) in enumerate(zip(results[True], results[False])):
        for name in _ARRAYS:
            g, r = getattr(got, name), getattr(ref, name)
            if g is None and r is None:
                continue
            np.testing.assert_array_equal(g, r, err_msg=f"call {i}: {name}")


def test_a_kernel_whose_lanes_are_all_constant_follows_the_launch_size():
    # A bare diode and no mesh, point Sun: every direct lane reads 1 and the tracer folds the kernel's result to a
    # constant; replayed for a batch of another size it must still have that batch's lanes (Renderer._run anchors
    # it on the lanes' counter). The oracle: E_sun cos(theta) exactly (a bare plate), and the traced kernels.
    from simcore.constants import E_SUN_W_M2
    from simcore.shapes.aperture import diode_frame
    ds = DiodeSurfaces(np.zeros((1, 3)), diode_frame(np.array([0.0, 0.0, 1.0]))[None], [0.01, 0.01])
    th = np.radians(np.arange(0, 90))
    sun = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=1)
    rend = Renderer(ds, variant=VARIANT)
    got = rend.render(sun, batch_epochs=64)                    # batches of 64 and 26 epochs
    assert rend._frozen["_direct_kernel"].n_recordings == 1
    np.testing.assert_allclose(got.direct_w_m2[:, 0], E_SUN_W_M2 * np.cos(th), rtol=1e-6, atol=0)


def test_a_constant_kernel_traced_at_every_launch_still_has_its_lanes(monkeypatch, variant):
    # A variant that traces every launch (not in _FREEZE_VARIANTS; cuda_ad_mono) anchors the result on the lanes'
    # counter too: unanchored, the folded constant came back as one value for a launch's 1024 lanes (IndexError in
    # _task_mean_var, seen on an H100). Here the CPU variant is made to trace every launch. Oracle as above.
    from simcore.constants import E_SUN_W_M2
    from simcore.render import launch
    from simcore.shapes.aperture import diode_frame
    monkeypatch.setattr(launch, "_FREEZE_VARIANTS", ())
    ds = DiodeSurfaces(np.zeros((1, 3)), diode_frame(np.array([0.0, 0.0, 1.0]))[None], [0.01, 0.01])
    th = np.radians(np.arange(0, 90))
    sun = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=1)
    rend = Renderer(ds, variant=variant)
    got = rend.render(sun, batch_epochs=64)
    assert rend._frozen == {}
    np.testing.assert_allclose(got.direct_w_m2[:, 0], E_SUN_W_M2 * np.cos(th), rtol=1e-6, atol=0)


def test_a_dropped_renderer_is_freed_at_once():
    # The frozen wrappers hold the renderer weakly: were it in a reference cycle, only the cycle collector would
    # free it, at any time, possibly inside another frozen recording, where releasing its numpy-backed Dr.Jit
    # arrays aborts the process (Dr.Jit 1.5, "enqueue_host_func(): this function cannot be recorded!").
    import gc
    import weakref
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(8, seed=1)
    enabled = gc.isenabled()
    gc.disable()
    try:
        rend = Renderer(DiodeSurfaces.from_config(cfg), build_satellite_mesh(cfg), variant=VARIANT)
        rend.render(sun, earth, rot, direct_samples=64, albedo_samples=16)
        assert len(rend._frozen) == 5
        ref = weakref.ref(rend)
        del rend
        assert ref() is None
    finally:
        if enabled:
            gc.enable()


def test_a_second_thread_tracing_kernels_beside_a_recording_changes_nothing():
    # sunsim run computes the direct-Sun reference (the body box's shadow, a Dr.Jit kernel traced at every call:
    # simcore.shapes.occlusion) in its worker thread while the main thread records and replays the renderer's
    # frozen kernels. Dr.Jit records in the recording thread's own state; this checks that neither side sees the
    # other's work: the render recorded beside the other thread, and each box result, equal those computed alone,
    # bit for bit.
    import threading

    from simcore.shapes.occlusion import lit_fractions_with_box
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(40, seed=11)
    kw = dict(seed=5, batch_epochs=8, rel_se_direct=0.002, rel_se_albedo=0.01)
    rng = np.random.default_rng(4)
    k = rng.integers(0, 12, 5000)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    box = (np.array([a.rims for a in cfg.apertures])[k], np.asarray(cfg.frames)[k], np.asarray(cfg.positions_m)[k],
           d, np.asarray(cfg.body.size_m) / 2)
    alone = lit_fractions_with_box(*box)
    assert 0.01 < np.mean((alone > 0) & (alone < 1))        # shadows that cross the wells: the kernel's area
    ref, _ = _render(cfg, True, sun, earth, rot, **dict(kw))
    beside, stop, failed = [], threading.Event(), []

    def worker():
        try:
            while not stop.is_set():
                beside.append(lit_fractions_with_box(*box))
        except BaseException as e:       # (reported below: an exception in a thread would pass silently)
            failed.append(e)
    t = threading.Thread(target=worker)
    t.start()
    try:
        got, rend = _render(cfg, True, sun, earth, rot, **dict(kw))
    finally:
        stop.set()
        t.join()
    assert not failed, failed
    assert len(beside) >= 2 and {f.n_recordings for f in rend._frozen.values()} == {1}
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    for b in beside:
        np.testing.assert_array_equal(b, alone)


def test_frozen_kernels_with_glint_and_another_wind():
    # the glint's sea table reaches the kernels through _Lanes and its wind and index are in _kernel_state: a
    # renderer with glint replays what tracing gives, and one whose wind changes after recording records anew
    from simcore.radiometry.glint import SunGlint
    cfg = SatelliteConfig.load("tilt20_fov70")
    sun, earth, rot = _epochs(24, seed=13)
    kw = dict(seed=5, batch_epochs=8, direct_samples=256, albedo_samples=64)
    got, rend = _render(cfg, True, sun, earth, rot, glint=SunGlint(7.0), **dict(kw))
    assert rend._frozen["_albedo_kernel"].n_recordings == 1
    # (another wind at once: building other renderers in between can make a recording start anew by itself)
    rend._glint = SunGlint(2.0)
    got2 = rend.render(sun, earth, rot, **dict(kw))
    assert rend._frozen["_albedo_kernel"].n_recordings == 2
    ref, _ = _render(cfg, False, sun, earth, rot, glint=SunGlint(7.0), **dict(kw))
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    ref2, _ = _render(cfg, False, sun, earth, rot, glint=SunGlint(2.0), **dict(kw))
    for name in _ARRAYS:
        np.testing.assert_array_equal(getattr(got2, name), getattr(ref2, name), err_msg=name)
    plain, _ = _render(cfg, True, sun, earth, rot, glint=None, **dict(kw))
    assert np.any(got.albedo_w_m2 != plain.albedo_w_m2)          # the glint is there
