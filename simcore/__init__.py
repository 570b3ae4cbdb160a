"""sunsim's physics pipeline: time, orbit, frames, Sun, eclipse, attitude,
albedo, scenes, rendering, sensor chain.

Importing simcore points Dr.Jit at a working libLLVM before drjit can be
imported (see :mod:`simcore._llvm`).
"""
from simcore import _llvm

_llvm.configure()

from simcore.epochs import Epochs  # noqa: E402

__version__ = "0.1.0"

__all__ = ["Epochs", "__version__"]
