"""The package layout's contracts (pyproject.toml [tool.importlinter]): the pipeline's stages import
one way, estimators import nothing of simcore or scenes, no cycle among simcore's subpackages."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(cwd):
    env = dict(os.environ, PYTHONPATH=str(cwd))
    return subprocess.run([str(LINT), "--config", str(cwd / "pyproject.toml"), "--no-cache"], cwd=cwd, env=env,
                          capture_output=True, text=True)


def _copy(tmp_path):
    for name in ("simcore", "scenes", "estimators"):
        shutil.copytree(ROOT / name, tmp_path / name, ignore=shutil.ignore_patterns("data", "__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    return tmp_path


def test_import_contracts_hold(tmp_path):
    res = _lint(_copy(tmp_path))
    assert res.returncode == 0, res.stdout + res.stderr
    assert "3 kept, 0 broken" in res.stdout


@pytest.mark.parametrize("module, line", [
    ("simcore/environment/orbit.py", "from simcore.pipeline import run"),     # a lower stage importing an upper one
    ("estimators/metrics.py", "from simcore.constants import AU_M"),          # an estimator importing simcore
    ("simcore/shapes/aperture.py", "import scenes.config"),                  # geometry importing the scenes above it
])
def test_a_wrong_import_breaks_a_contract(tmp_path, module, line):
    root = _copy(tmp_path)
    path = root / module
    path.write_text(path.read_text() + f"\n{line}  # deliberately wrong\n")
    res = _lint(root)
    assert res.returncode == 1 and "BROKEN" in res.stdout, res.stdout + res.stderr
