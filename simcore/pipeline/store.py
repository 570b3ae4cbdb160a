"""Crash-safe, resumable storage for chunked batch runs.

A run writing ``out.nc`` keeps its finished chunks in ``out.nc.partial/``:
``spec.json`` (everything that determines the numbers) and one
``chunk_<start>_<stop>.npz`` per finished chunk, each written to a temporary
name and renamed into place, so a chunk file is complete or absent, never
half-written. Started again with the same spec, the run skips finished
chunks; with a different spec it refuses (and says so) rather than mixing
results. The final file is written as ``out.nc.tmp-<pid>`` and renamed over
``out.nc`` (atomic on one file system), then the partial folder is removed:
no partial or corrupt file ever stands under the final name.
"""
import hashlib
import json
import os
import re
import shutil
import tempfile

import numpy as np

_CHUNK = re.compile(r"^chunk_(\d{9})_(\d{9})\.npz$")


def spec_digest(spec):
    """Return a short stable hash of a JSON-serialisable spec."""
    text = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _fsync_dir(path):
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write(path, write):
    """Call ``write(tmp_path)`` then rename tmp over ``path`` (same folder, fsynced)."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    fd, tmp = tempfile.mkstemp(prefix=os.path.basename(path) + ".tmp-", dir=folder)
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
        _fsync_dir(folder)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def check_writable(path):
    """Raise PermissionError/FileNotFoundError with a clear message if ``path`` cannot be written."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"cannot write {path}: the folder {folder} does not exist; create it or choose another --output")
    if not os.access(folder, os.W_OK):
        raise PermissionError(f"cannot write {path}: the folder {folder} is not writable; choose another --output")
    if os.path.isdir(path):
        raise IsADirectoryError(f"cannot write {path}: it is a folder; give a file name such as run.nc")


class ChunkStore:
    """Finished chunks of one run, kept beside its final output file."""

    def __init__(self, final_path, spec):
        self.final_path = final_path
        self.folder = final_path + ".partial"
        self.spec = spec
        self.digest = spec_digest(spec)

    def open(self):
        """Create or reopen the partial folder; raise if it belongs to a different run."""
        check_writable(self.final_path)
        spec_file = os.path.join(self.folder, "spec.json")
        if os.path.isdir(self.folder) and os.path.exists(spec_file):
            with open(spec_file) as f:
                old = json.load(f)
            if old.get("digest") != self.digest:
                raise ValueError(
                    f"{self.folder} holds a partial run made with different settings; resume it with its original "
                    "command, or delete that folder (or choose another --output) to start afresh")
            return self
        os.makedirs(self.folder, exist_ok=True)
        payload = json.dumps({"digest": self.digest, "spec": self.spec}, sort_keys=True, indent=1, default=str)

        def write(tmp):
            with open(tmp, "w") as f:
                f.write(payload)
        atomic_write(spec_file, write)
        return self

    def done(self):
        """Return sorted (start, stop) index ranges of the finished chunks."""
        if not os.path.isdir(self.folder):
            return []
        out = []
        for name in os.listdir(self.folder):
            m = _CHUNK.match(name)
            if m:
                out.append((int(m.group(1)), int(m.group(2))))
        return sorted(out)

    def save(self, start, stop, arrays):
        """Store one finished chunk (a dict of numpy arrays) atomically."""
        path = os.path.join(self.folder, f"chunk_{start:09d}_{stop:09d}.npz")

        def write(tmp):
            with open(tmp, "wb") as f:
                np.savez(f, **arrays)
        atomic_write(path, write)

    def load_all(self, n_total):
        """Return the finished chunks concatenated along the first axis; raise if any range is missing."""
        parts, expect = [], 0
        for start, stop in self.done():
            if start != expect:
                raise RuntimeError(f"chunk [{expect}, {start}) is missing from {self.folder}")
            with np.load(os.path.join(self.folder, f"chunk_{start:09d}_{stop:09d}.npz")) as z:
                parts.append({k: z[k] for k in z.files})
            expect = stop
        if expect != n_total:
            raise RuntimeError(f"{self.folder} covers epochs [0, {expect}) of {n_total}")
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def remove(self):
        shutil.rmtree(self.folder, ignore_errors=True)


def chunk_ranges(n_total, chunk):
    """Return [(start, stop), ...] covering range(n_total) in chunks of ``chunk``."""
    if chunk <= 0:
        raise ValueError(f"chunk size must be positive, got {chunk}")
    return [(s, min(s + chunk, n_total)) for s in range(0, n_total, chunk)]
