"""Integrity of run files and of the chunks behind them.

A run file written by this sunsim carries a ``checksums`` attribute: a SHA-256 digest of each numeric variable
(its dtype, shape and bytes). :func:`verify_checksums` recomputes them when the file is opened, so a variable that
was zeroed, cut short or changed since it was written is refused in one line instead of being estimated. Files
written before the checksums existed are accepted with a note (nothing to compare with).

:func:`writer` names who writes a run's chunks (sunsim version, renderer variant): a partial run is resumed only
by the same writer (:class:`simcore.pipeline.store.ChunkStore`).
"""
import functools
import hashlib
import json
import os
import sys

import numpy as np

from simcore._version import __version__
from simcore.errors import InvalidInputError

CHECKSUMS_ATTR = "checksums"


def _digest(values):
    a = np.ascontiguousarray(values)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()[:32]


def _numeric(ds):
    return [name for name in sorted(ds.data_vars) if ds[name].dtype.kind in "biuf"]


def add_checksums(ds):
    """Set ``ds.attrs['checksums']`` (JSON: variable name -> digest of each numeric variable); return ``ds``."""
    ds.attrs[CHECKSUMS_ATTR] = json.dumps({name: _digest(ds[name].values) for name in _numeric(ds)}, sort_keys=True)
    return ds


def verify_checksums(ds, path, note=None):
    """Return ``ds`` if its variables match the checksums it carries; raise InvalidInputError naming the first
    that does not. A file without checksums (older sunsim) is returned after a note (``note``: a function of
    one line; default: printed on stderr)."""
    stored = ds.attrs.get(CHECKSUMS_ATTR)
    if stored is None:
        (note or (lambda m: print(m, file=sys.stderr)))(
            f"note: {path} carries no checksums (written by a sunsim before they were added): its variables "
            "are used unverified")
        return ds
    try:
        stored = json.loads(stored)
    except ValueError:
        raise InvalidInputError(f"{path}: its checksums attribute is unreadable, so the file cannot be verified; "
                                "render it again with the same 'sunsim run' command") from None
    for name, digest in sorted(stored.items()):
        if name not in ds:
            raise InvalidInputError(f"{path}: the variable {name} is missing although the file's checksums list it: "
                                    "the file is damaged; render it again with the same 'sunsim run' command")
        if _digest(ds[name].values) != digest:
            raise InvalidInputError(f"{path}: the variable {name} does not match its checksum (zeroed, cut short or "
                                    "changed since sunsim wrote it): the file is damaged; render it again with the "
                                    "same 'sunsim run' command")
    return ds


def size_bound(ds):
    """Return an upper bound (bytes) of ``ds`` written as netCDF-4 without compression: its arrays, its attributes
    and 8 KiB of HDF5 metadata per variable plus 64 KiB (a 4-epoch run file: 58 kB written, this bound 0.4 MB)."""
    attrs = sum(len(str(v)) for v in ds.attrs.values())
    return int(ds.nbytes) + attrs + 8192 * len(ds.variables) + 65536


def writer(study):
    """Return who writes ``study``'s chunks: {"sunsim": version, "variant": the Mitsuba variant it renders with}."""
    return {"sunsim": __version__, "variant": getattr(study, "variant", None)}


def software_versions():
    """Return the versions of sunsim and of the libraries that decide a run's numbers."""
    from simcore import _llvm
    drjit, mitsuba = _llvm.import_drjit(), _llvm.import_mitsuba()
    import platform
    import sgp4
    import erfa
    return {"sunsim": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "mitsuba": mitsuba.__version__, "drjit": drjit.__version__, "sgp4": sgp4.__version__,
            "pyerfa": erfa.__version__}


@functools.lru_cache(maxsize=1)
def git_commit():
    """Return the git commit sunsim runs from (with '-dirty' for local changes), or '' outside a checkout."""
    import subprocess
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        out = subprocess.run(["git", "-C", here, "describe", "--always", "--dirty", "--abbrev=12"],
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""
