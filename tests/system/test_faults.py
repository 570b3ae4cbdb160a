"""Issue 31, faults of the environment: a full disk, a partial run of another sunsim, Dask without workers or
with a dying one, Dask not installed. Each ends in one line (exit status 2) and keeps what was finished; a
rerun after the fault is gone resumes and gives the same bits as a run that never met it.

The full disk is a real one: a 2 MiB tmpfs mounted inside tmp_path (the tests run as root); where mounting is
not permitted the same test injects the fault instead (the chunk store's write raises ENOSPC after two chunks,
which is what the kernel's write does on a full disk) and says so in its name.
"""
import errno
import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

SUNSIM = [sys.executable, "-m", "simcore.cli"]
# 6 sunlit epochs in chunks of 2 (each chunk file 8172 bytes: two 4 KiB pages of tmpfs)
RUN = ["run", "--start", "2016-07-02T00:45:00Z", "--duration", "6", "--samples", "256", "256", "--chunk", "2"]
PAGE = 4096
# the run's own small files on the disk: the partial folder's spec.json and lock (a page each)
OWN_PAGES = 2


def _one_line(stderr):
    lines = [x for x in stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


@pytest.fixture
def small_disk(tmp_path):
    """Return (folder, fill(free_bytes), release()): a 2 MiB tmpfs, or None where mounting is not permitted."""
    disk = tmp_path / "disk"
    disk.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)], capture_output=True)
    if r.returncode != 0:
        yield None
        return
    ballast = disk / "ballast"

    def fill(free):
        st = os.statvfs(disk)
        ballast.write_bytes(b"\0" * (st.f_bavail * st.f_frsize - free))

    try:
        yield disk, fill, lambda: ballast.unlink()
    finally:
        subprocess.run(["umount", str(disk)], check=True)


# After two chunks, what a full disk's write does (used only where no tmpfs can be mounted).
_INJECT = ("import errno, sys\n"
           "import simcore.pipeline.store as st\n"
           "real, calls = st.ChunkStore.save, []\n"
           "def save(self, *a):\n"
           "    calls.append(1)\n"
           "    if len(calls) > 2:\n"
           "        raise OSError(errno.ENOSPC, 'No space left on device')\n"
           "    return real(self, *a)\n"
           "st.ChunkStore.save = save\n"
           "from simcore.cli import main\n"
           "sys.exit(main(sys.argv[1:]))\n")


def test_a_full_disk_during_a_chunk_keeps_the_chunks_and_a_rerun_resumes_bit_identically(tmp_path, small_disk,
                                                                                         capsys):
    if small_disk is None:        # no tmpfs here: the fault injected into the store's write instead
        folder, out = tmp_path, str(tmp_path / "r.nc")
        r = subprocess.run([sys.executable, "-c", _INJECT] + RUN + ["-o", out], capture_output=True, text=True,
                           cwd=tmp_path, timeout=600)
        release = lambda: None  # noqa: E731
    else:
        folder, fill, release = small_disk
        out = str(folder / "r.nc")
        fill((OWN_PAGES + 2 * 2) * PAGE)                 # room for two chunks of two pages, not the third
        r = subprocess.run(SUNSIM + RUN + ["-o", out], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert r.returncode == 2, (r.returncode, r.stderr)           # not a crash (SIGSEGV: -11) nor a traceback
    line = _one_line(r.stderr)
    assert "is full (No space left on device) while writing a chunk" in line
    assert "(4 of 6 epochs" in line and "run the same command again to resume" in line
    assert sorted(f for f in os.listdir(out + ".partial") if f.startswith("chunk_")) == [
        "chunk_000000000_000000002.npz", "chunk_000000002_000000004.npz"]
    assert not os.path.exists(out)
    release()
    from simcore.cli import main            # the resume and the run that never met the fault: in this process
    assert main(RUN + ["-o", out]) == 0
    assert "resuming: 4 of 6 epochs" in capsys.readouterr().err
    assert main(RUN + ["-o", str(tmp_path / "s.nc")]) == 0
    a, b = xr.load_dataset(out), xr.load_dataset(tmp_path / "s.nc")
    for name in ("irradiance", "irradiance_se", "samples", "analytic", "analytic_reference"):
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert not os.path.exists(out + ".partial")


@pytest.mark.slow
def test_a_full_disk_in_the_final_write_keeps_every_chunk(tmp_path, small_disk):
    from simcore.cli import main
    if small_disk is None:
        pytest.fail("this test needs a small file system: mount -t tmpfs must be permitted (it is, as root)")
    folder, fill, release = small_disk
    out = str(folder / "r.nc")
    fill((OWN_PAGES + 3 * 2 + 4) * PAGE)             # the three chunks fit, the ~73 kB run file does not
    r = subprocess.run(SUNSIM + RUN + ["-o", out], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert r.returncode == 2, (r.returncode, r.stderr)
    line = _one_line(r.stderr)
    assert "while writing the final file" in line and "(6 of 6 epochs" in line
    assert not os.path.exists(out)
    assert not [f for f in os.listdir(out + ".partial") if ".tmp-" in f]      # the half-written file is gone
    release()
    assert main(RUN + ["-o", out]) == 0                      # resumes: nothing left to render
    assert os.listdir(folder) == ["r.nc"]


def test_a_partial_run_of_another_sunsim_version_is_refused(tmp_path, capsys):
    import json
    from simcore.cli import build_parser, main, run_options
    from simcore.pipeline.run import PreparedRun
    from simcore.pipeline.store import ChunkStore
    out = str(tmp_path / "r.nc")
    opts = run_options(build_parser().parse_args(RUN + ["-o", out]))
    study = PreparedRun(opts)
    # what sunsim 0.9 would have left after one chunk of the same command
    spec = dict(opts.spec(), sunsim_version="0.9")
    store = ChunkStore(out, spec, writer={"sunsim": "0.9", "variant": "llvm_ad_mono"}).open()
    store.save(0, 2, study.render_chunk(0, 2))
    store.close()
    before = sorted(os.listdir(out + ".partial"))
    assert main(RUN + ["-o", out]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "chunks were written by sunsim 0.9" in line and "delete that folder" in line
    assert sorted(os.listdir(out + ".partial")) == before and not os.path.exists(out)
    # the same settings digest but another renderer variant: refused too (its chunks would be mixed)
    spec_file = os.path.join(out + ".partial", "spec.json")
    with open(spec_file, "w") as f:
        json.dump({"digest": ChunkStore(out, opts.spec()).digest, "spec": opts.spec(),
                   "writer": {"variant": "cuda_ad_mono"}}, f)
    assert main(RUN + ["-o", out]) == 2
    assert "written by the renderer variant cuda_ad_mono" in _one_line(capsys.readouterr().err)


# ---- Dask --------------------------------------------------------------------------------------------------
SWEEP = ["sweep", "--starts", "2016-07-02T00:45:00Z", "--duration", "4", "--samples", "256", "256"]


def test_a_scheduler_without_workers_is_one_line_not_a_hang(tmp_path, monkeypatch, capsys):
    from dask.distributed import LocalCluster
    import simcore.pipeline.cluster as cl
    from simcore.cli import main
    monkeypatch.setattr(cl, "NO_WORKER_WAIT_S", 3.0)
    monkeypatch.setattr(cl, "POLL_S", 0.5)
    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as empty:
        rc = main(SWEEP + ["--folder", str(tmp_path / "sw"), "--scheduler", empty.scheduler_address])
    assert rc == 2
    line = _one_line(capsys.readouterr().err)
    assert "has had no worker for 3 s" in line and "run the same command again to resume" in line


def _die():
    os._exit(3)


def test_a_worker_that_dies_is_one_line_after_the_retries():
    import dask
    from simcore.errors import ClusterError
    from simcore.pipeline.cluster import run_tasks
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with pytest.raises(ClusterError, match="a Dask worker died each time it ran the task"):
            run_tasks(_die, [()], workers=1)


@pytest.mark.parametrize("command", [SWEEP, ["attitude-study", "--span", "short", "--no-render"]])
def test_a_missing_dask_names_the_extra_before_any_work(tmp_path, monkeypatch, capsys, command):
    from simcore.cli import main
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, "distributed", None)      # what a plain `pip install .` leaves
    assert main(command) == 2
    line = _one_line(capsys.readouterr().err)
    assert "pip install 'sunsim[sweep]'" in line
    assert os.listdir(tmp_path) == []


def test_enospc_is_told_apart_from_other_write_errors(tmp_path):
    from simcore.pipeline.store import is_disk_full
    assert is_disk_full(OSError(errno.ENOSPC, "No space left on device"))
    assert is_disk_full(OSError(errno.EDQUOT, "Disk quota exceeded"))
    assert not is_disk_full(OSError(errno.EACCES, "Permission denied"), str(tmp_path))
    assert not is_disk_full(ValueError("no"))
