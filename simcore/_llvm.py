"""Find a libLLVM that Dr.Jit's CPU backend can use, before drjit is imported.

Dr.Jit loads libLLVM at run time. Debian 12's libLLVM 14 is refused as too
old and libLLVM 15 aborts on the first kernel ("Cannot select ...
fminimum"), so relying on whatever the loader finds crashes. We look, in
order, at: ``$DRJIT_LIBLLVM_PATH`` if the user set it; the library that the
``karellen-llvm-core`` wheel (a dependency) installs under ``sys.prefix``;
system libraries of version >= 16, newest first.

Every numpy array handed to Dr.Jit goes through :func:`host_array` (see the note there).
"""
import glob
import os
import re
import sys
import threading

import numpy as np

MIN_VERSION = 16
ENV = "DRJIT_LIBLLVM_PATH"

INSTALL_HINT = (
    "Install one with 'pip install karellen-llvm-core' (no root needed; "
    "sunsim's set-up does this) or 'apt-get install libllvm19', or point "
    f"{ENV} at a libLLVM.so of version >= {MIN_VERSION}."
)


class LLVMNotFoundError(RuntimeError):
    """No usable libLLVM for Dr.Jit's CPU (llvm_*) variants."""


def _version(path):
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else -1


def candidates():
    """Return candidate libLLVM paths, best first."""
    found = []
    for prefix in dict.fromkeys([sys.prefix, sys.base_prefix]):
        found += sorted(glob.glob(os.path.join(prefix, "lib", "libLLVM.so.*")),
                        key=_version, reverse=True)
    system = []
    for d in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu",
              "/usr/lib64", "/usr/lib", "/usr/local/lib"):
        system += glob.glob(os.path.join(d, "libLLVM*.so*"))
        system += glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*")
    system = [p for p in dict.fromkeys(system) if _version(p) >= MIN_VERSION]
    found += sorted(system, key=_version, reverse=True)
    return found


def find_libllvm():
    """Return the path of a usable libLLVM, or raise LLVMNotFoundError."""
    user = os.environ.get(ENV)
    if user:
        if not os.path.isfile(user):
            raise LLVMNotFoundError(f"{ENV}={user!r} is not a file. " + INSTALL_HINT)
        v = _version(user)
        if 0 <= v < MIN_VERSION:
            raise LLVMNotFoundError(
                f"{ENV}={user!r} is libLLVM {v}; Dr.Jit needs >= {MIN_VERSION} "
                "(14 is refused, 15 aborts on the first kernel). " + INSTALL_HINT)
        return user
    for path in candidates():
        if os.path.isfile(path):
            return path
    raise LLVMNotFoundError("No libLLVM >= %d found for Dr.Jit's CPU backend. %s"
                            % (MIN_VERSION, INSTALL_HINT))


def configure():
    """Set DRJIT_LIBLLVM_PATH for this process; return the path, or None.

    Never raises: a missing library only matters for the llvm_* variants, and
    the renderer raises LLVMNotFoundError with the hint when it needs one.
    """
    if "drjit" in sys.modules:
        return os.environ.get(ENV)
    try:
        path = find_libllvm()
    except LLVMNotFoundError:
        return None
    os.environ[ENV] = path
    return path


def import_drjit():
    """Return the ``drjit`` module, imported after :func:`configure` has pointed it at a working libLLVM.

    Every place in sunsim that uses Dr.Jit (or Mitsuba, which loads it) imports it through here,
    so importing sunsim itself configures nothing and loads nothing heavy.
    """
    configure()
    import drjit
    return drjit


# Dr.Jit 1.5 deadlocks when one thread calls a frozen function (``drjit.freeze``) while another runs Dr.Jit
# operations: the frozen call holds Dr.Jit's state while it calls back into Python to traverse its inputs (and
# waits for the interpreter's lock), and the other thread holds the interpreter's lock while it waits for
# Dr.Jit's state, spinning (seen once in ``sunsim run`` on a loaded 2-core machine: the render's frozen albedo
# proposal in the main thread, the direct reference's body-box kernel in the worker thread; both threads at
# 100 % CPU for minutes, no progress). Sections of Dr.Jit work that may run beside a frozen call in another
# thread hold this lock, and so do the frozen calls; Python's lock gives up the interpreter's while it waits.
FROZEN_CALLS = threading.RLock()


def import_mitsuba():
    """Return the ``mitsuba`` module, imported after :func:`configure` (see :func:`import_drjit`)."""
    configure()
    import mitsuba
    return mitsuba


# Dr.Jit (1.5) wraps a numpy array without copying it, and its CPU kernels read lane-wise inputs in whole SIMD
# packets, the last one past the array's end. From a buffer that is not 64-byte aligned those are unaligned
# loads, and where the buffer ends just before an unmapped page the last one crosses into it: SIGSEGV (seen as
# rare crashes of whole test runs; reproduced in tests/test_llvm.py). Every numpy array handed to Dr.Jit goes
# through :func:`host_array`, whose copy starts on a packet boundary and has slack after its end.
_PACKET_BYTES = 64
_NUMPY_TYPES = {"Float32": "float32", "Float64": "float64", "UInt32": "uint32", "Int32": "int32",
                "UInt64": "uint64", "Int64": "int64", "Bool": "bool"}
_DTYPES = {}    # Dr.Jit array type -> numpy dtype (the renderer calls host_array thousands of times a run)


def _dtype_of(cls):
    """Return the numpy dtype of the Dr.Jit array type ``cls``'s elements."""
    dtype = _DTYPES.get(cls)
    if dtype is None:
        dtype = _DTYPES[cls] = np.dtype(_NUMPY_TYPES[import_drjit().type_v(cls).name])
    return dtype


def host_array(cls, values):
    """Return the Dr.Jit array type ``cls`` (e.g. ``mi.Float``, ``drjit.llvm.UInt32``) holding a copy of the
    flattened ``values`` (converted to the type's dtype) in memory Dr.Jit's CPU kernels can read safely:
    64-byte aligned, with two packets of slack after its end (see the note above)."""
    dtype = _dtype_of(cls)
    a = np.asarray(values, dtype=dtype).reshape(-1)
    out = host_buffer(a.size, dtype)
    out[:] = a
    return cls(out)


def host_buffer(n, dtype):
    """Return an uninitialised numpy array of ``n`` elements of ``dtype`` in memory Dr.Jit's CPU kernels can read
    safely (64-byte aligned, two packets of slack after its end; the note above), to be filled in place and
    handed over by :func:`host_wrap` without another copy (e.g. lane index arrays of many MB)."""
    dtype = np.dtype(dtype)
    nbytes = int(n) * dtype.itemsize
    raw = np.empty(nbytes + 3 * _PACKET_BYTES, np.uint8)
    start = -raw.ctypes.data % _PACKET_BYTES
    return raw[start:start + nbytes].view(dtype)


def host_wrap(cls, buffer):
    """Return the Dr.Jit array type ``cls`` holding ``buffer``, an array from :func:`host_buffer` (of the type's
    dtype), without copying it."""
    raw = buffer.base
    if (buffer.dtype != _dtype_of(cls) or buffer.ctypes.data % _PACKET_BYTES
            or not isinstance(raw, np.ndarray) or raw.dtype != np.uint8
            or raw.ctypes.data + raw.nbytes < buffer.ctypes.data + buffer.nbytes + 2 * _PACKET_BYTES):
        raise ValueError("host_wrap takes an array from host_buffer (aligned, with slack) of the type's dtype")
    return cls(buffer)
