"""The main job: render diode irradiance along an orbit, check it, store it.

:func:`prepare` checks every input and returns a :class:`PreparedRun` (configuration, geometry, maps, renderer);
:func:`execute` renders it in chunks of epochs, stores every finished chunk crash-safely
(:mod:`simcore.pipeline.store`), computes the check's reference beside each chunk
(:mod:`simcore.pipeline.reference`) and, once all are done, writes one self-describing run file
(:mod:`simcore.pipeline.runfile`) with the check's verdict. Killed and started again with the same options
(:mod:`simcore.pipeline.options`) it continues from its last finished chunk and ends with exactly the numbers of
an uninterrupted run (the renderer's random numbers are keyed by the global epoch index, not by the chunk).
"""
import concurrent.futures
import copy
import dataclasses
import functools
import json
import os
import sys

import numpy as np

from scenes.config import SatelliteConfig
from scenes.satellite import Satellite
from simcore.radiometry.glint import SunGlint, check_refine as glint_check_refine
from simcore.render import Renderer
from simcore.environment.earth import Earth

from simcore.environment import attitude as _attitude
from simcore.constants import AU_M, R_EARTH_MEAN_M, R_SUN_M
from simcore.errors import InvalidInputError, OutputError
from simcore.radiometry import band
from simcore.pipeline.check import PLAIN_CHECK_SAMPLES, plain_check_epochs
from simcore.pipeline.preflight import (attitude_times_note, check_map, check_numbers, check_run_resources,
                                       check_variant, map_for_diodes, reflected_ignored_note, tle_age_note)
from simcore.pipeline.reference import CheckReference
from simcore.pipeline.runfile import (CHUNK_ARRAYS, add_checksums, build_dataset, chunk_arrays_of, open_run,
                                      options_digest, options_of, size_bound, software_versions, write_netcdf,
                                      writer)
from simcore.pipeline.store import (ChunkStore, atomic_write, check_room, check_writable, chunk_ranges, is_disk_full,
                                    missing_ranges, spec_digest)
from simcore.environment.geometry import compute_geometry
from simcore.pipeline import schedule as _schedule

# The analytic reference for the albedo check uses cells refined 2 x 2; its estimated discretisation error
# (check.discretisation_bound, a third of |native - refined|) joins each diode-epoch's variance. On a sunlit
# 10 minutes of the default study the 3 x 3 bound was below 0.1 of the rendered standard error for 90 % of the
# diode-epochs (0.43 at 99 %); 2 x 2 makes it 2.25 times larger for ~55 % of the 3 x 3 cost.
CHECK_REFINE = 2
# Under cloud weather, 4 x 4. Where the body's or a mount's shadow crosses the Earth's disc, the cell-centre sum
# meets a step in the visibility: on a smooth map the cells along the edge err both ways and cancel, but a cloud
# realisation is two-state (overcast 0.7 beside an infrared sea of 0.013), the errors along the edge stop
# cancelling, and 2 x 2 is not yet where the sum converges smoothly (so native against 2 x 2 can agree by chance).
# Seen on tilt20_fov70's day under --map band --glint 7 --clouds 1: at 19:03:33Z, diode 1, the sums over cells
# refined 1, 2, 4, 8 read 2.501, 2.501, 2.632, 2.699 W/m^2 and six seeds of the renderer at 65,536 samples
# 2.687 +- 0.005; at five other such diode-epochs 8 x 8 and the renderer agree within 0.1 W/m^2 where 2 x 2 missed
# by 0.2-0.7. The check over that day: 2 x 2, 85 values beyond |z| = 4 against 35 expected (88 % of them where
# shadows cross the diode), FAIL; 4 x 4 with the same Richardson bound, 21, spread p = 1, PASS (a first-order
# bound, a third of |native - 4 x 4|, overstates the error: the spread test failed, p = 5e-25). At ~3x the
# refined sum's cost, only for cloud weather.
CHECK_REFINE_CLOUDS = 4


class PreparedRun:
    """A prepared run: configuration, geometry, scene and maps, ready to render chunks.

    ``variant``: the Mitsuba variant :func:`prepare` checked (the run file records the renderer's own once it is
    built); ``renderer``: a renderer to render with instead of the one built from the run on first use."""

    def __init__(self, opts, *, variant=None, renderer=None):
        self.opts = opts
        self.config = SatelliteConfig.load(opts.config, dead=list(opts.dead),
                                           extra_flat_diodes=True if opts.extra_flat_diodes else None)
        eop = _schedule.eop_kwargs(opts)
        self.plan = _schedule.plan(opts)
        self.orbit, self.attitude = self.plan.orbit, self.plan.attitude
        self.geometry = compute_geometry(self.orbit, self.plan.epochs, self.attitude, **eop)
        self.epochs = self.geometry.epochs
        self.clouds = None
        if getattr(opts, "clouds", None) is None:
            self.map = band.resolve_map(map_for_diodes(opts.reflectivity, self.config), getattr(opts, "glint", None))
        else:
            self.clouds = band.cloud_weather(map_for_diodes(opts.reflectivity, self.config), opts.cloud_scale_km,
                                             getattr(opts, "glint", None))
            self.map = self.clouds.realise(opts.clouds)
        self.glint = self._sea_glint()
        base, r_m = CHECK_REFINE if self.clouds is None else CHECK_REFINE_CLOUDS, self.geometry.r_sat_gcrs_m
        self.check_refine = base if self.glint is None else glint_check_refine(        # finer for a calm sea's spot
            self.glint.wind_m_s, np.linalg.norm(r_m, axis=1).min() - R_EARTH_MEAN_M, self.map.dlon_deg, base)
        self.map_refined = self.map.refined(self.check_refine)
        self._variant = variant
        self._renderer = renderer

    def _sea_glint(self):
        """Return the run's :class:`SunGlint` on the map's cells (its sea fraction in the map's row order), or None.

        The sea is GSHHG's less its annual ice (:func:`simcore.radiometry.sea_surface.open_sea_fraction`); under cloud
        weather the overcast cells' sea is hidden (a thick cloud deck reflects diffusely; its albedo is the map's),
        so glint comes from the clear sea only. A band map's sea leaves its specular part to it (band.resolve_map)."""
        wind = getattr(self.opts, "glint", None)
        if wind is None:
            return None
        from simcore.radiometry.sea_surface import open_sea_fraction
        sea = open_sea_fraction(self.map, band.sea_ice_share())
        if self.clouds is not None:
            sea = np.where(self.clouds.overcast(self.opts.clouds), 0.0, sea)
        return SunGlint(wind, sea=sea)

    @property
    def earth(self):
        """Return the run's :class:`Earth`: its map with the sea's glint (:meth:`_sea_glint`); made on each use
        (cheap), so that it always holds the run's current ``map``."""
        return Earth(self.map, self.glint)

    @functools.cached_property
    def satellite(self):
        """Return the run's :class:`Satellite`: the configuration's diodes, mesh and body box, each built once."""
        return Satellite(self.config)

    @property
    def sun_angular_radius_rad(self):
        """Return the Sun's apparent angular radius for this run (0 for a point Sun): from the mean
        satellite-Sun distance (it changes by < 0.05 % in a day; 1.7 % over a year)."""
        if not self.opts.sun_disc:
            return 0.0
        dist = np.linalg.norm(self.geometry.sun_from_sat_gcrs_m, axis=1)
        return float(np.arcsin(R_SUN_M / np.nanmean(dist)))

    @functools.cached_property
    def parts(self):
        """Return ``scenes.meshes.build_parts`` of the configuration (the renderer's mesh and the mounts rule)."""
        return self.satellite.parts

    @property
    def renderer(self):
        if self._renderer is None:
            self._renderer = Renderer.from_scene(
                self.satellite, self.earth, e_sun_w_m2=self.opts.e_sun_w_m2,
                sun_angular_radius_rad=self.sun_angular_radius_rad, variant=self.opts.variant)
        return self._renderer

    def earth_sun_dir_body(self, sl):
        """Return (n, 3) the unit Earth-centre -> Sun vector in body axes (what lights the Earth, as in the
        analytic model)."""
        g = self.geometry
        r = g.r_sun_ecef_m[sl]
        return np.einsum("nji,nj->ni", g.R_ecef_from_body[sl], r / np.linalg.norm(r, axis=1)[:, None])

    def earth_sun_scale(self, sl):
        """Return (n,) the factor on E_sun that lights the Earth: (1 AU / |r_sun|)^2 geocentric, or 1."""
        if not self.opts.distance_scaling:
            return np.ones(sl.stop - sl.start)
        return (AU_M / np.linalg.norm(self.geometry.r_sun_ecef_m[sl], axis=1)) ** 2

    def sun_scale(self, sl):
        g = self.geometry
        return g.sun_distance_scale[sl] if self.opts.distance_scaling else np.ones(sl.stop - sl.start)

    @property
    def variant(self):
        """Return the Mitsuba variant the run renders with: its renderer's once built, else the one :func:`prepare`
        checked (None for a run not prepared)."""
        return self._renderer.variant if self._renderer is not None else self._variant

    def with_renderer(self, renderer):
        """Return a copy of this run that renders with ``renderer`` (None: one built afresh from the copy's map
        and configuration on first use); the check's reference is built afresh with it."""
        new = copy.copy(self)
        new.__dict__.pop("reference", None)
        new._renderer = renderer
        return new

    @functools.cached_property
    def reference(self):
        """Return the check's reference of this run (:class:`simcore.pipeline.reference.CheckReference`)."""
        return CheckReference(self)

    @functools.cached_property
    def notes(self):
        """Return the run's warnings (list of str): the TLE's age, reflections not traced, relative attitude
        times, and the notes of the run's plan and configuration."""
        opts = self.opts
        notes = [tle_age_note(self.orbit, self.epochs), reflected_ignored_note(opts.reflected_samples, self.config)]
        if opts.attitude_file and _schedule.relative_times_csv(opts.attitude_file):
            notes.append(attitude_times_note(_attitude.Attitude.from_file(opts.attitude_file).t_s,
                                             opts.attitude_file))
        return [n for n in notes if n] + list(self.plan.notes) + list(self.config.notes)

    @functools.cached_property
    def worker(self):
        """Return the one worker thread that computes the direct reference (numpy, which releases the GIL
        in its loops, and the body box's shadow as a traced Dr.Jit kernel) and writes finished chunks while the
        main thread renders: on few cores it fills the core that the renderer's Python parts leave idle. It
        freezes nothing (a frozen function records in its own thread; see tests/render/test_freeze.py, the second
        thread's test); its Dr.Jit kernel runs between frozen calls (:data:`simcore._llvm.FROZEN_CALLS`)."""
        return concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="sunsim-worker")

    def render_chunk(self, start, stop):
        """Return the arrays of epochs [start, stop): rendered and analytic irradiance, and the check's
        second, hint-free direct estimate on its share of the epochs (NaN elsewhere)."""
        o, g, sl = self.opts, self.geometry, slice(start, stop)
        valid = g.valid[sl]
        direct_ref = self.worker.submit(self.reference.analytic, sl, self.map, albedo=False)
        args = (g.sun_dir_body[sl], g.earth_center_body_m[sl], g.R_ecef_from_body[sl], self.sun_scale(sl))
        res = self.renderer.render(
            *args, sun_dir_earth_body=self.earth_sun_dir_body(sl), earth_sun_scale=self.earth_sun_scale(sl),
            seed=o.seed, epoch_offset=start, direct_samples=o.direct_samples, albedo_samples=o.albedo_samples,
            rel_se_direct=o.rel_se_direct, rel_se_albedo=o.rel_se_albedo, reflected_samples=o.reflected_samples,
            progress=None)
        plain = np.full((stop - start, len(self.config.diodes), 3), np.nan)
        pick = np.flatnonzero(plain_check_epochs(o.seed, len(self.epochs))[sl])
        if len(pick):
            sub = self.renderer.render(*(a[pick] for a in args), seed=o.seed, epoch_index=start + pick,
                                       albedo=False, hint=False, reflected=False,
                                       direct_samples=max(o.direct_samples, PLAIN_CHECK_SAMPLES))
            plain[pick] = np.stack([sub.direct_w_m2, sub.direct_se_w_m2, sub.direct_dof], axis=-1)
        # box-only and traced shares (the traced shares' own error terms come from the refined cells below)
        native = self.reference.analytic(sl, self.map, direct=False, mesh=True, box_albedo=True, mesh_terms=False)
        native_albedo, native_mesh = native.albedo_box_w_m2, native.albedo_w_m2
        fine = self.reference.analytic(sl, self.map_refined, direct=False, mesh=True)
        native_direct = direct_ref.result().direct_w_m2
        unchecked, window_shadow = self.reference.direct_unchecked(sl)
        out = {
            "rendered": np.stack([res.direct_w_m2, res.albedo_w_m2, res.reflected_w_m2], axis=-1),
            "rendered_se": np.stack([res.direct_se_w_m2, res.albedo_se_w_m2, res.reflected_se_w_m2], axis=-1),
            "rendered_dof": np.stack([res.direct_dof, res.albedo_dof, res.reflected_dof], axis=-1),
            "samples": np.stack([res.direct_samples, res.albedo_samples, res.reflected_samples],
                                axis=-1).astype(np.int64),
            "direct_plain": plain,
            "analytic": np.stack([native_direct, native_albedo], axis=-1),
            "analytic_albedo_refined": fine.albedo_w_m2,
            "analytic_albedo_native_mesh": native_mesh,
            "albedo_mesh": fine.albedo_mesh_w_m2,
            "albedo_visibility_error": fine.albedo_visibility_error_w_m2,
            "direct_unchecked": unchecked,
            "direct_unchecked_window": window_shadow,
            "valid": valid & res.valid,
        }
        return out


DEFAULT_FOLDER = "runs"


def default_output(opts, folder=DEFAULT_FOLDER):
    """Return the output path of a run given no ``output``: ``folder/default.nc`` or ``default-N.nc``.

    The first of these that already holds this run (a finished file or a partial folder with identical
    settings) is reused, so the same command repeats and resumes; otherwise the first free name, so a
    run with other settings never collides with an earlier one.
    """
    digest = spec_digest(opts.spec())
    for i in range(1, 10000):
        path = os.path.join(folder, "default.nc" if i == 1 else f"default-{i}.nc")
        partial = ChunkStore(path, {}).folder
        if os.path.exists(path):
            if options_digest(path) == digest:
                return path
            continue
        if os.path.isdir(partial):
            if ChunkStore.stored_digest(path) in (digest, None):
                return path
            continue
        return path
    raise OutputError(f"{folder} holds 9999 default runs; give --output")


def prepare(opts):
    """Return a ready :class:`PreparedRun` of ``opts`` after every check of its inputs; raise a UserError (nothing
    written) for the first that fails. ``study.notes`` holds the warnings."""
    check_numbers(opts)
    variant = check_variant(opts.variant)
    study = PreparedRun(opts, variant=variant)
    check_map(study.map, getattr(opts, "allow_bright_map", False))
    if study.config.dead.all():
        raise InvalidInputError(f"all {study.config.n_diodes} diodes of {study.config.name} are dead (--dead "
                                f"{' '.join(map(str, np.flatnonzero(study.config.dead)))}); leave at least one alive")
    check_run_resources(opts, len(study.epochs), study.config.n_diodes,
                        reflected_traced=reflected_ignored_note(opts.reflected_samples, study.config) is None)
    return study


def execute(opts, *, progress=None, log=None):
    """Run (or resume) a study; return (output path, Dataset, check report).

    Every input is checked first (:func:`prepare`): a rejected run writes nothing. An
    output file made with identical settings is returned as it is (nothing rendered); one made with other
    settings is replaced only with ``opts.overwrite``.
    """
    log = log or (lambda msg: None)
    study = prepare(opts)
    for note in study.notes:
        log(f"warning: {note}")
    if opts.output is None:     # the study's options decide the numbers; the store says where they go
        os.makedirs(DEFAULT_FOLDER, exist_ok=True)
        opts = dataclasses.replace(opts, output=default_output(opts))
    check_writable(opts.output)
    finished = _finished(opts, log)
    if finished is not None:
        return finished
    store = ChunkStore(opts.output, opts.spec(), writer=writer(study)).open()
    try:
        # Another process may have finished this output while we waited for its lock.
        finished = _finished(opts, log)
        if finished is not None:
            store.close()
            if not store.done():
                store.remove()
            return finished
        return _render_and_write(study, store, progress, log)
    finally:
        store.close()


def _finished(opts, log):
    """Return (path, ds, report) of an existing output with identical settings; None if there is none;
    raise if one with other settings stands there (without ``overwrite``)."""
    if not os.path.exists(opts.output):
        return None
    same = options_digest(opts.output) == spec_digest(opts.spec())
    if same:
        log(f"{opts.output} is already finished with identical settings: nothing to render")
        ds = open_run(opts.output)
        return opts.output, ds, json.loads(ds.attrs["check"])
    if not opts.overwrite:
        raise OutputError(f"{opts.output} exists and was made with other settings; add --overwrite to replace "
                          "it, or choose another --output")
    return None


def _render_and_write(study, store, progress, log):
    opts = study.opts
    n = len(study.epochs)
    done = store.done()
    if done:
        missing = sorted(set(CHUNK_ARRAYS) - store.chunk_keys(*done[0]))
        if missing:
            raise InvalidInputError(f"{store.folder} holds a partial run written by an older sunsim (its chunks lack "
                                    f"{', '.join(missing)}); delete that folder to start this run afresh")
    todo = missing_ranges(n, opts.chunk_epochs, done)
    if done:
        log(f"resuming: {sum(b - a for a, b in done)} of {n} epochs already in {store.folder}")
    from tqdm import tqdm
    bar = tqdm(total=n, initial=sum(b - a for a, b in done), unit="epoch",
               disable=(not sys.stderr.isatty()) if progress is None else not progress, desc="rendering")
    try:
        return _write_chunks_and_file(study, store, todo, bar, n)
    except OSError as exc:
        if is_disk_full(exc, store.folder):
            covered = sum(b - a for a, b in store.done()) == n
            raise store.disk_full(exc, "writing the final file" if covered else "writing a chunk", n) from None
        raise


def _write_chunks_and_file(study, store, todo, bar, n):
    """Render and store the chunks ``todo``, then write the run file (``store.final_path``) from all of them;
    return (path, ds, report)."""
    pending = None          # the chunk being written by the worker thread while the next one renders
    try:
        for start, stop in todo:
            data = study.render_chunk(start, stop)
            if pending is not None:
                pending.result()
            pending = study.worker.submit(store.save, start, stop, data)
            bar.update(stop - start)
    finally:
        if pending is not None:
            concurrent.futures.wait([pending])     # a finished chunk is on disk before anything else happens
        bar.close()
    if pending is not None:
        pending.result()
    data = store.load_all(n)
    ds, report = build_dataset(study, data, study.variant)

    def write(tmp):
        write_netcdf(add_checksums(ds), tmp)
    check_room(store.folder, size_bound(ds))
    # The temporary file lies in the partial folder: a crash here leaves it where the resume cleans up.
    atomic_write(store.final_path, write, tmp_dir=store.folder)
    store.remove()
    return store.final_path, ds, report


def recompute_analytic(path, *, chunk=4096, log=None):
    """Recompute a run file's analytic model and check with this version of sunsim (the rendered numbers
    are kept); rewrite the file atomically and return the new check report."""
    ds = open_run(path)
    study = PreparedRun(options_of(ds, path))
    n = len(study.epochs)
    if n != ds.sizes["time"]:
        raise ValueError(f"{path}: its options give {n} epochs but it holds {ds.sizes['time']}; "
                         "it was not made by this command's options")
    native = np.zeros(ds["analytic"].shape[:2] + (2,))
    fine, native_mesh = np.zeros(ds["analytic"].shape[:2]), np.zeros(ds["analytic"].shape[:2])
    mesh, mesh_err = np.zeros(ds["analytic"].shape[:2]), np.zeros(ds["analytic"].shape[:2])
    unchecked, unchecked_window = np.zeros(mesh.shape, bool), np.zeros(mesh.shape, bool)
    for s, e in chunk_ranges(n, chunk):
        unchecked[s:e], unchecked_window[s:e] = study.reference.direct_unchecked(slice(s, e))
        a = study.reference.analytic(slice(s, e), study.map, mesh=True, box_albedo=True, mesh_terms=False)
        native[s:e, :, 0], native[s:e, :, 1], native_mesh[s:e] = a.direct_w_m2, a.albedo_box_w_m2, a.albedo_w_m2
        a = study.reference.analytic(slice(s, e), study.map_refined, direct=False, mesh=True)
        fine[s:e], mesh[s:e], mesh_err[s:e] = a.albedo_w_m2, a.albedo_mesh_w_m2, a.albedo_visibility_error_w_m2
        if log:
            log(f"analytic {e}/{n}")
    data = chunk_arrays_of(ds, ("rendered", "rendered_se", "rendered_dof", "direct_plain", "samples", "valid"))
    data.update({"analytic": native, "analytic_albedo_refined": fine, "analytic_albedo_native_mesh": native_mesh,
                 "albedo_mesh": mesh, "albedo_visibility_error": mesh_err, "direct_unchecked": unchecked,
                 "direct_unchecked_window": unchecked_window})
    new, report = build_dataset(study, data, ds.attrs.get("variant", ""))
    new.attrs["software"] = ds.attrs["software"]          # the rendering's versions
    new.attrs["analytic_recomputed_with"] = json.dumps(software_versions(), sort_keys=True)

    def write(tmp):
        write_netcdf(add_checksums(new), tmp)
    ds.close()
    atomic_write(path, write)
    return report
