"""The package layout's contracts (pyproject.toml [tool.importlinter]): the pipeline's stages import one way, the
renderer never uses the analytic model it is checked against, estimators import nothing of simcore, scenes, Mitsuba
or Dr.Jit, benchmarks never the command line, no cycle among simcore's subpackages. Each contract is shown to bite:
the imports that once slipped through (issue 30 item 4), planted one at a time in a copy of the sources, break it."""
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
LINT = Path(sys.executable).with_name("lint-imports")
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
CONTRACTS = [c["name"] for c in CONFIG["contracts"]]
LAYERS = next(c for c in CONFIG["contracts"] if c["type"] == "layers")
STAGES = LAYERS["name"]
RENDERER = "The renderer never uses the analytic model it is checked against"
ESTIMATORS = "Estimators see only measurements and normals: they import nothing of simcore or scenes"
RAY_TRACER = "Estimators never touch the ray tracer: no mitsuba, no drjit"
BENCHMARKS = "Benchmarks time the library, never the command line"
ACYCLIC = "No cycle between the subpackages of simcore"


def _copy(tmp_path):
    """Copy the Python sources of the linted packages (not the data files) and pyproject.toml to ``tmp_path``."""
    def not_source(folder, names):
        return [n for n in names if n == "__pycache__" or (Path(folder, n).is_file() and not n.endswith(".py"))]
    for name in CONFIG["root_packages"]:
        shutil.copytree(ROOT / name, tmp_path / name, ignore=not_source)
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    return tmp_path


def _verdicts(cwd):
    """Run lint-imports in ``cwd``; return (exit status, {contract name: "KEPT" or "BROKEN"}, output)."""
    env = dict(os.environ, PYTHONPATH=str(cwd))
    res = subprocess.run([str(LINT), "--config", str(cwd / "pyproject.toml"), "--no-cache"], cwd=cwd, env=env,
                         capture_output=True, text=True)
    text = " ".join(res.stdout.split())  # the report wraps long contract names
    verdicts = {name: v for name in CONTRACTS for v in ("KEPT", "BROKEN") if f"{name} {v}" in text}
    return res.returncode, verdicts, res.stdout + res.stderr


def test_the_contracts_hold(tmp_path):
    rc, verdicts, out = _verdicts(_copy(tmp_path))
    assert rc == 0, out
    assert verdicts == dict.fromkeys(CONTRACTS, "KEPT"), out


def test_every_part_of_simcore_has_its_layer():
    # Oracle: the files on disk. A subpackage or module missing from the layers is free to import anything
    # (as scenes' picture modules, simcore/data and check_install once were); a layer naming nothing is a stale name.
    children = {f"simcore.{p.stem}" for p in (ROOT / "simcore").glob("*.py") if p.stem != "__init__"}
    children |= {f"simcore.{p.parent.name}" for p in (ROOT / "simcore").glob("*/__init__.py")}
    named = {m.strip() for layer in LAYERS["layers"] for m in layer.split("|")}
    assert children | {"scenes"} == named


@pytest.mark.parametrize("module, line, broken", [
    # the imports that slipped through
    ("simcore/radiometry/analytic.py", "import simcore.picture.view", {STAGES}),  # the check importing the picture
    ("estimators/sunline.py", "import mitsuba", {RAY_TRACER}),
    ("estimators/attitude.py", "import drjit as dr", {RAY_TRACER}),
    ("simcore/render/__init__.py", "from simcore.radiometry.analytic import diode_irradiance", {RENDERER}),
    ("simcore/data/band/build_band_data.py", "from simcore.pipeline import run", {STAGES}),
    ("benchmarks/bench_run.py", "from simcore.cli import main", {BENCHMARKS}),
    # the rest of the layers and the other contracts
    ("simcore/check_install.py", "from simcore.environment import epochs", {STAGES}),
    ("scenes/meshes.py", "from simcore.picture import scene", {STAGES}),
    ("simcore/environment/orbit.py", "import scenes.config", {STAGES}),
    ("simcore/environment/frames.py", "from simcore.radiometry import albedo", {STAGES, ACYCLIC}),  # a cycle
    ("simcore/shapes/aperture.py", "import scenes.config", {STAGES}),
    ("estimators/metrics.py", "from simcore.constants import AU_M", {ESTIMATORS}),
])
def test_a_wrong_import_breaks_its_contract(tmp_path, module, line, broken):
    root = _copy(tmp_path)
    path = root / module
    path.write_text(path.read_text() + f"\n{line}  # deliberately wrong\n")
    rc, verdicts, out = _verdicts(root)
    assert rc == 1, out
    assert verdicts == {name: "BROKEN" if name in broken else "KEPT" for name in CONTRACTS}, out
