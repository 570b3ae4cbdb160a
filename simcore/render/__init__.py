"""The Monte-Carlo renderer (Mitsuba 3 / Dr.Jit): diode irradiance along an orbit with standard
errors (:mod:`simcore.render.irradiance`), reflections on the spacecraft (aperture walls included) path
traced. Dr.Jit's libLLVM is configured when a renderer is first built."""
from scenes.satellite import DiodeSurfaces  # noqa: F401,E402 (the renderer's input, at home in the data layer)
