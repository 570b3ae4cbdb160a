"""Crash-safe chunk storage: finished chunks survive, foreign partial runs are refused."""
import os
import subprocess
import sys

import numpy as np
import pytest

from simcore.pipeline.store import ChunkStore, atomic_write, check_writable, chunk_ranges, missing_ranges


def test_chunks_resume_and_concatenate(tmp_path):
    out = str(tmp_path / "run.nc")
    spec = {"config": "tilt20_fov70", "seed": 1}
    store = ChunkStore(out, spec).open()
    ranges = chunk_ranges(10, 4)
    assert ranges == [(0, 4), (4, 8), (8, 10)]
    store.save(0, 4, {"x": np.arange(4.0)})
    store.close()       # the first process ends (the kernel would drop its lock the same way)
    # A "new process" with the same spec sees the finished chunk and continues.
    again = ChunkStore(out, dict(spec)).open()
    assert again.done() == [(0, 4)]
    again.save(4, 8, {"x": np.arange(4.0, 8.0)})
    with pytest.raises(RuntimeError, match="covers epochs"):
        again.load_all(10)
    again.save(8, 10, {"x": np.arange(8.0, 10.0)})
    np.testing.assert_array_equal(again.load_all(10)["x"], np.arange(10.0))
    assert not os.path.exists(out)  # nothing under the final name until the run finishes


def test_a_partial_run_with_other_settings_is_refused(tmp_path):
    out = str(tmp_path / "run.nc")
    first = ChunkStore(out, {"seed": 1}).open()
    first.save(0, 4, {"x": np.arange(4.0)})
    first.close()
    with pytest.raises(ValueError, match="different settings"):
        ChunkStore(out, {"seed": 2}).open()


def test_a_partial_folder_without_chunks_is_taken_over(tmp_path):
    # Nothing finished, nothing to lose: a corrected command must not be refused by an empty folder.
    out = str(tmp_path / "run.nc")
    ChunkStore(out, {"seed": 1}).open().close()
    store = ChunkStore(out, {"seed": 2}).open()
    store.close()
    with open(os.path.join(store.folder, "spec.json")) as f:
        assert '"seed": 2' in f.read()


def test_a_second_owner_is_refused_while_the_first_holds_the_output(tmp_path):
    out = str(tmp_path / "run.nc")
    first = ChunkStore(out, {"seed": 1}).open()
    with pytest.raises(PermissionError, match="being written by another sunsim process"):
        ChunkStore(out, {"seed": 1}).open()
    first.close()
    ChunkStore(out, {"seed": 1}).open().remove()
    assert os.listdir(tmp_path) == []


def test_temporaries_left_by_a_crash_are_cleaned_on_resume(tmp_path):
    out = str(tmp_path / "run.nc")
    store = ChunkStore(out, {"seed": 1}).open()
    store.close()
    stray = os.path.join(store.folder, "run.nc.tmp-abc123")     # a final write killed half-way
    with open(stray, "w") as f:
        f.write("half")
    ChunkStore(out, {"seed": 1}).open().close()
    assert not os.path.exists(stray)


def test_missing_ranges_keep_chunks_of_another_size():
    assert missing_ranges(10, 4, []) == [(0, 4), (4, 8), (8, 10)]
    assert missing_ranges(10, 3, [(0, 4), (8, 10)]) == [(4, 7), (7, 8)]
    assert missing_ranges(10, 4, [(0, 4), (4, 8), (8, 10)]) == []


def test_files_get_the_users_umask(tmp_path):
    old = os.umask(0o027)
    try:
        atomic_write(str(tmp_path / "f.nc"), lambda tmp: open(tmp, "w").close())
    finally:
        os.umask(old)
    assert (os.stat(tmp_path / "f.nc").st_mode & 0o777) == 0o640   # 0666 & ~0027


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "final.nc"

    def boom(tmp):
        with open(tmp, "w") as f:
            f.write("half")
        raise RuntimeError("killed")
    with pytest.raises(RuntimeError):
        atomic_write(str(target), boom)
    assert os.listdir(tmp_path) == []


def test_unwritable_outputs_are_explained(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        check_writable(str(tmp_path / "no" / "such" / "run.nc"))
    with pytest.raises(IsADirectoryError, match="is a folder"):
        check_writable(str(tmp_path))
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        check_writable(str(afile / "run.nc"))
    # /proc accepts no new files, whatever the permission bits say (root passes os.access there).
    with pytest.raises(PermissionError, match="the folder /proc accepts no new files"):
        check_writable("/proc/x.nc")


def test_the_run_file_writer_writes_what_xarray_writes_without_importing_distributed(tmp_path):
    # the oracle: xarray's own Dataset.to_netcdf (engine h5netcdf), byte for byte; write_netcdf only skips its look
    # for a Dask scheduler, which imports dask.distributed (0.10 s of every run). In a fresh interpreter, because
    # another test may have imported distributed already.
    script = f"""
import sys
import numpy as np
import xarray as xr
from simcore.pipeline.runfile import add_checksums, write_netcdf
ds = xr.Dataset({{"rendered": (("time", "diode", "component"), np.arange(24.0).reshape(2, 4, 3)),
                 "valid": (("time", "diode"), np.ones((2, 4), bool)),
                 "name": ("diode", np.array(["a", "bb", "ccc", "d"], dtype=object))}},
                coords={{"time": np.array(["2016-07-02T00:00:00", "2016-07-02T00:00:01"], "datetime64[ns]")}},
                attrs={{"check": '{{"pass": true}}', "epochs": 2}})
write_netcdf(add_checksums(ds), {str(tmp_path / "ours.nc")!r})
assert "distributed" not in sys.modules, "write_netcdf imported dask.distributed"
ds.to_netcdf({str(tmp_path / "xarray.nc")!r}, engine="h5netcdf")
"""
    subprocess.run([sys.executable, "-c", script], check=True)
    assert (tmp_path / "ours.nc").read_bytes() == (tmp_path / "xarray.nc").read_bytes()
