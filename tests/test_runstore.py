"""Crash-safe chunk storage: finished chunks survive, foreign partial runs are refused."""
import os

import numpy as np
import pytest

from simcore.pipeline.store import ChunkStore, atomic_write, check_writable, chunk_ranges


def test_chunks_resume_and_concatenate(tmp_path):
    out = str(tmp_path / "run.nc")
    spec = {"config": "tilt20_fov70", "seed": 1}
    store = ChunkStore(out, spec).open()
    ranges = chunk_ranges(10, 4)
    assert ranges == [(0, 4), (4, 8), (8, 10)]
    store.save(0, 4, {"x": np.arange(4.0)})
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
    ChunkStore(out, {"seed": 1}).open()
    with pytest.raises(ValueError, match="different settings"):
        ChunkStore(out, {"seed": 2}).open()


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
