"""Fixtures shared by every test folder: a seeded generator, the bad-configuration check, and the render
variants the renderer tests run on (``variant``)."""
import functools

import numpy as np
import pytest


@functools.cache
def render_variants():
    """Return the Mitsuba variants the renderer tests run on: llvm_ad_mono always, and cuda_ad_mono as well where
    ``choose_variant`` picks it (Dr.Jit has a working CUDA device). Decided once, at collection."""
    from simcore.render import choose_variant
    return ("llvm_ad_mono",) + (("cuda_ad_mono",) if choose_variant() == "cuda_ad_mono" else ())


def pytest_generate_tests(metafunc):
    """A test that takes ``variant`` runs once per render variant this machine has (no GPU: once, on the CPU)."""
    if "variant" in metafunc.fixturenames:
        metafunc.parametrize("variant", render_variants())


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
