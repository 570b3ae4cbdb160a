"""Crash-safe, resumable storage for chunked batch runs.

A run writing ``out.nc`` keeps its finished chunks in ``out.nc.partial/``:
``spec.json`` (everything that determines the numbers) and one
``chunk_<start>_<stop>.npz`` per finished chunk, each written to a temporary
name and renamed into place, so a chunk file is complete or absent, never
half-written. Started again with the same spec, the run skips finished
chunks; with a different spec it refuses (and says so) rather than mixing
results (a partial folder without any finished chunk holds nothing to lose
and is taken over). The final file is written inside the partial folder and
renamed over ``out.nc`` (atomic on one file system), then the partial folder
is removed: no partial or corrupt file ever stands under the final name, and
a temporary file left by a crash lies in the partial folder, which the next
run cleans.

While a run owns the folder it holds an exclusive ``flock`` on
``out.nc.partial/lock``: a second process asking for the same output is
refused with a message instead of writing the same chunks. The kernel drops
the lock when the owner dies, so a killed run never blocks its resume.
"""
import errno
import fcntl
import hashlib
import json
import os
import re
import shutil
import tempfile

import numpy as np

from simcore.errors import InvalidInputError, OutputError, OutputFolderMissingError, OutputIsAFolderError

# errno values of a file system that has no room left: no space (ENOSPC), the user's quota (EDQUOT)
_FULL = (errno.ENOSPC, errno.EDQUOT)


class DiskFullError(OutputError):
    """The output's file system filled up during a run: the finished chunks are kept, a rerun resumes."""


def is_disk_full(exc, folder=None):
    """Return True if ``exc`` says that the file system has no room left: an OSError of errno ENOSPC or EDQUOT,
    or (HDF5 reports a failed write without the errno) an OSError while ``folder``'s file system has < 1 MiB free."""
    if not isinstance(exc, OSError):
        return False
    if exc.errno in _FULL:
        return True
    if folder is None or exc.errno not in (None, 0, errno.EIO):
        return False
    try:
        st = os.statvfs(folder)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < 1 << 20


def check_room(folder, nbytes):
    """Raise OSError(ENOSPC) if ``folder``'s file system has fewer than ``nbytes`` free: asked before an HDF5 file
    is written, because HDF5 meeting a full disk mid-file leaves its library in a state that crashes at exit."""
    st = os.statvfs(folder)
    if st.f_bavail * st.f_frsize < nbytes:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _bytes(folder):
    """Return the size of the files in ``folder`` (bytes)."""
    total = 0
    for name in os.listdir(folder) if os.path.isdir(folder) else ():
        try:
            total += os.path.getsize(os.path.join(folder, name))
        except OSError:
            pass
    return total


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


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write(path, write, tmp_dir=None):
    """Call ``write(tmp_path)`` then rename tmp over ``path`` (fsynced); the file gets the user's umask.

    ``tmp_dir`` (default: the folder of ``path``) must be on the same file system as ``path``.
    """
    folder = os.path.dirname(os.path.abspath(path)) or "."
    fd, tmp = tempfile.mkstemp(prefix=os.path.basename(path) + ".tmp-", dir=tmp_dir or folder)
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        # mkstemp creates 0600; a result file is as readable as any file the user creates.
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
        _fsync_dir(folder)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def check_writable(path):
    """Raise an :class:`~simcore.errors.UserError` saying why ``path`` cannot be written, or return None.

    The check creates and removes a probe file in the folder: permission
    bits alone do not tell (root, read-only mounts, ``/proc``).
    """
    folder = os.path.dirname(os.path.abspath(path)) or "."
    if not os.path.isdir(folder):
        raise OutputFolderMissingError(f"cannot write {path}: the folder {folder} does not exist; create it or "
                                       "choose another --output")
    if os.path.isdir(path):
        raise OutputIsAFolderError(f"cannot write {path}: it is a folder; give a file name such as run.nc")
    try:
        fd, probe = tempfile.mkstemp(prefix=".sunsim-probe-", dir=folder)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: the folder {folder} accepts no new files "
                          f"({exc.strerror or exc}); choose another --output") from None
    os.close(fd)
    os.remove(probe)


class ChunkStore:
    """Finished chunks of one run, kept beside its final output file."""

    def __init__(self, final_path, spec, writer=None):
        self.final_path = final_path
        self.folder = final_path + ".partial"
        self.spec = spec
        self.digest = spec_digest(spec)
        # who writes the chunks ({"sunsim": version, "variant": the renderer's}): not part of the settings, but a
        # resume must not mix chunks of two writers
        self.writer = writer

    def open(self):
        """Create or reopen the partial folder and lock it; raise if another process holds it or it
        belongs to a different run."""
        check_writable(self.final_path)
        self._lock()
        try:
            self._clean_temporaries()
            spec_file = os.path.join(self.folder, "spec.json")
            if os.path.exists(spec_file):
                try:
                    with open(spec_file) as f:
                        old = json.load(f)
                except ValueError:          # cut short or overwritten: whose chunks these are is unknown
                    old = {"digest": None}
                    if self.done():
                        raise InvalidInputError(f"{spec_file} is unreadable, so the chunks beside it cannot be "
                                                "told apart from another run's; delete that folder (or choose "
                                                "another --output) to start afresh") from None
                if self.done():
                    self._refuse_other_writer(old)
                if old.get("digest") == self.digest:
                    return self
                if self.done():
                    raise InvalidInputError(
                        f"{self.folder} holds a partial run made with different settings; resume it with its "
                        "original command, or delete that folder (or choose another --output) to start afresh")
            payload = json.dumps({"digest": self.digest, "spec": self.spec, "writer": self.writer}, sort_keys=True,
                                 indent=1, default=str)

            def write(tmp):
                with open(tmp, "w") as f:
                    f.write(payload)
            atomic_write(spec_file, write)
        except BaseException:
            self.close()
            raise
        return self

    def _refuse_other_writer(self, old):
        """Raise InvalidInputError if the partial run's chunks were written by another sunsim version or renderer
        variant (``old``: its spec.json): a resume would splice two programs' numbers into one file."""
        theirs = dict(old.get("writer") or {})
        theirs.setdefault("sunsim", (old.get("spec") or {}).get("sunsim_version"))
        ours = dict(self.writer or {})
        ours.setdefault("sunsim", self.spec.get("sunsim_version"))
        for key, what in (("sunsim", "sunsim"), ("variant", "the renderer variant")):
            if theirs.get(key) and ours.get(key) and theirs[key] != ours[key]:
                raise InvalidInputError(
                    f"{self.folder} holds a partial run whose chunks were written by {what} {theirs[key]} (this is "
                    f"{ours[key]}); they cannot be mixed with this one's: finish it with {what} {theirs[key]}, or "
                    "delete that folder (or choose another --output) to start afresh")

    def disk_full(self, exc, doing, n_total):
        """Return the one-line DiskFullError of a full disk met while ``doing`` (what was being written)."""
        done = self.done()
        kept = sum(b - a for a, b in done)
        return DiskFullError(
            f"the disk holding {self.final_path} is full ({exc.strerror or exc}) while {doing}: the {len(done)} "
            f"finished chunk(s) ({kept} of {n_total} epochs, {_bytes(self.folder) / 1e6:.2g} MB) are safe in "
            f"{self.folder}; free space (df -h {os.path.dirname(os.path.abspath(self.final_path))}) and run the same "
            "command again to resume")

    @staticmethod
    def stored_digest(final_path):
        """Return the settings digest of the partial run of ``final_path`` (None if it has none)."""
        try:
            with open(os.path.join(final_path + ".partial", "spec.json")) as f:
                return json.load(f).get("digest")
        except (OSError, ValueError):
            return None

    def _lock(self):
        """Take the exclusive lock of the partial folder (created if needed); raise OutputError if held."""
        lock_path = os.path.join(self.folder, "lock")
        for _ in range(10):
            os.makedirs(self.folder, exist_ok=True)
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                if exc.errno not in (errno.EAGAIN, errno.EACCES):
                    os.close(fd)
                    raise
                owner = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
                os.close(fd)
                raise OutputError(f"{self.final_path} is being written by another sunsim process (pid {owner}); "
                                  "wait for it to finish or choose another --output") from None
            # The owner before us may have finished and removed the folder while we waited on its lock
            # file: then our lock is on a deleted file, and we start over on a fresh one.
            try:
                same = os.stat(lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, str(os.getpid()).encode())
                self._lock_fd = fd
                return
            os.close(fd)
        raise OutputError(f"{self.final_path}: cannot lock {lock_path}; another process keeps recreating it")

    def _clean_temporaries(self):
        for name in os.listdir(self.folder):
            if ".tmp-" in name:
                os.remove(os.path.join(self.folder, name))

    def close(self):
        """Release the lock (the folder stays, for a resume)."""
        fd, self._lock_fd = getattr(self, "_lock_fd", None), None
        if fd is not None:
            os.close(fd)

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

    def chunk_keys(self, start, stop):
        """Return the set of array names in the finished chunk [start, stop)."""
        with np.load(os.path.join(self.folder, f"chunk_{start:09d}_{stop:09d}.npz")) as z:
            return set(z.files)

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
        """Delete the partial folder (the run is finished) and release the lock."""
        shutil.rmtree(self.folder, ignore_errors=True)
        self.close()


def chunk_ranges(n_total, chunk):
    """Return [(start, stop), ...] covering range(n_total) in chunks of ``chunk``."""
    if chunk <= 0:
        raise InvalidInputError(f"chunk size must be positive, got {chunk}")
    return [(s, min(s + chunk, n_total)) for s in range(0, n_total, chunk)]


def missing_ranges(n_total, chunk, done):
    """Return the chunks of at most ``chunk`` epochs that cover what ``done`` (start, stop) ranges do not.

    Finished chunks of any size are kept, so a run resumed with another chunk size renders only the gaps.
    """
    covered = np.zeros(n_total, dtype=bool)
    for a, b in done:
        covered[a:b] = True
    out = []
    edges = np.flatnonzero(np.diff(np.concatenate([[1], covered.astype(np.int8), [1]])))
    for a, b in zip(edges[::2], edges[1::2]):
        out += [(int(a) + s, int(a) + e) for s, e in chunk_ranges(int(b - a), chunk)]
    return out
