"""sunsim's physics pipeline: time, orbit, frames, Sun, eclipse, attitude,
albedo, rendering, sensor chain.

Importing simcore points Dr.Jit at a working libLLVM before drjit can be
imported (see :mod:`simcore._llvm`); Mitsuba itself is loaded only when
something renders.
"""
from simcore import _llvm

_llvm.configure()

from simcore.albedo import albedo_cells  # noqa: E402
from simcore.analytic import BodyBox, diode_irradiance  # noqa: E402
from simcore.aperture import WellAperture, diode_frame  # noqa: E402
from simcore.attitude import Attitude, tumble  # noqa: E402
from simcore.coverage import coverage_fractions, coverage_map  # noqa: E402
from simcore.epochs import Epochs  # noqa: E402
from simcore.maps import ReflectivityMap  # noqa: E402
from simcore.orbit import Orbit, OrbitState, TLEError  # noqa: E402
from simcore.sensor import DIODES, SensorChain  # noqa: E402
from simcore.study import Geometry, compute_geometry  # noqa: E402

__version__ = "0.1.0"

__all__ = ["Attitude", "BodyBox", "DIODES", "Epochs", "Geometry", "Orbit", "OrbitState", "ReflectivityMap",
           "SensorChain", "TLEError", "WellAperture", "albedo_cells", "compute_geometry", "coverage_fractions",
           "coverage_map", "diode_frame", "diode_irradiance", "tumble", "__version__"]
