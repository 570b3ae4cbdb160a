"""The Monte-Carlo renderer (Mitsuba 3 / Dr.Jit): diode irradiance along an orbit with standard
errors (:mod:`simcore.render.irradiance`) and the wall-reflection tracer of apertures
(:mod:`simcore.render.walls`). Dr.Jit's libLLVM is configured when a renderer is first built."""
