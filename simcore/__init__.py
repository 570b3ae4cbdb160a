"""sunsim's physics pipeline, one stage per subpackage, data flowing one way:

``environment`` (time, TLE orbit, frames, Sun, eclipse, attitude, Earth maps, study geometry)
-> ``scenes`` (the satellite) -> ``radiometry`` (analytic albedo and diode irradiance, the check)
and ``render`` (Monte-Carlo irradiance) -> ``sensor`` (photodiode chain) -> ``estimators``
-> ``pipeline`` (runs, the check's verdict, evaluation, sweeps) -> ``studies`` -> ``plots``, ``cli``.

This module re-exports the supported names (skyfield's ``api`` in spirit), each loaded on first
use (PEP 562), so that ``import simcore`` stays cheap and importing one stage (e.g. ``scenes``,
which builds on ``simcore.shapes``) never drags in the stages above it. Dr.Jit and Mitsuba are
loaded, their libLLVM configured, only where they are first used (:func:`simcore._llvm.import_drjit`).
"""
from simcore._version import __version__

# supported name -> the module that defines it
_EXPORTS = {
    # environment: time, orbit, attitude, Earth maps, the per-epoch study geometry
    "Epochs": "simcore.environment.epochs",
    "Orbit": "simcore.environment.orbit", "OrbitState": "simcore.environment.orbit",
    "TLEError": "simcore.environment.orbit",
    "Attitude": "simcore.environment.attitude", "tumble": "simcore.environment.attitude",
    "ReflectivityMap": "simcore.environment.maps", "named_map": "simcore.environment.maps",
    "Earth": "simcore.environment.earth",
    "StudyGeometry": "simcore.environment.geometry", "compute_geometry": "simcore.environment.geometry",
    # the satellite
    "SatelliteConfig": "scenes.config", "Satellite": "scenes.satellite",
    "WellAperture": "simcore.shapes.aperture", "diode_frame": "simcore.shapes.aperture",
    # analytic model and renderer
    "albedo_cells": "simcore.radiometry.albedo",
    "BodyBox": "scenes.satellite", "diode_irradiance": "simcore.radiometry.analytic",
    "DiodeSurfaces": "scenes.satellite", "Renderer": "simcore.render",
    # sensor chain
    "DIODES": "simcore.sensor.chain", "SensorChain": "simcore.sensor.chain",
    # runs
    "RunOptions": "simcore.pipeline.options", "execute": "simcore.pipeline.run", "open_run": "simcore.pipeline.runfile",
    "check_run": "simcore.pipeline.runfile",
    "run_errors": "simcore.pipeline.evaluate", "evaluate_run": "simcore.pipeline.evaluate",
    # studies
    "coverage_fractions": "simcore.studies.coverage", "coverage_map": "simcore.studies.coverage",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'simcore' has no attribute {name!r}")
    import importlib
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
