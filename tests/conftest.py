import numpy as np
import pytest


@pytest.fixture
def rng():
    return np.random.default_rng(20160702)


@pytest.fixture
def config_refused(tmp_path, capsys, monkeypatch):
    """Return a check: ``sunsim run --config PATH`` (10 s, from tmp_path) exits 2 with one stderr line that
    contains ``words`` and writes nothing; used by every bad-configuration test."""
    from simcore.cli import main

    def check(path, words):
        out = tmp_path / "out"
        monkeypatch.chdir(tmp_path)
        assert main(["run", "--config", str(path), "--duration", "10", "-o", str(out / "r.nc")]) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err
        assert not out.exists()
    return check
