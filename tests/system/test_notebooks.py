"""Every notebook in notebooks/ executes from top to bottom without an error.

Each notebook runs in a fresh kernel (nbclient) with a temporary working
directory, so anything it writes by relative path stays out of the repository,
and with a time limit per cell. A failing cell fails the test with that cell's
source and traceback. Warnings raised inside the notebook only reach the
kernel's own output (a separate process); they do not fail this test.

A notebook too long for the default run sets ``"sunsim": {"slow": true}`` in
its notebook metadata; it is then marked ``slow`` (run with ``-m slow``).
"""
import json
import re
from pathlib import Path

import pytest

NOTEBOOK_DIR = Path(__file__).resolve().parents[2] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
CELL_TIMEOUT_S = 300
ANSI_ESCAPE = re.compile(r"\x1b\[[0-9;]*m")  # the kernel colours its tracebacks


def _param(path):
    with open(path, encoding="utf-8") as fh:
        slow = bool(json.load(fh).get("metadata", {}).get("sunsim", {}).get("slow", False))
    return pytest.param(path, id=path.name, marks=[pytest.mark.slow] if slow else [])


@pytest.mark.parametrize("path", [_param(p) for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    from nbclient.exceptions import CellExecutionError, CellTimeoutError

    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    try:
        client.execute()
    except (CellExecutionError, CellTimeoutError) as exc:
        # the message carries the cell's source and traceback; add which cell it was
        ran = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and c.get("execution_count") is not None]
        where = f"cell {ran[-1]} (0-based, markdown cells counted)" if ran else "its first code cell"
        pytest.fail(f"{path.name} failed in {where}: {type(exc).__name__}\n{ANSI_ESCAPE.sub('', str(exc))}",
                    pytrace=False)
    assert not any(o.get("output_type") == "error" for c in nb.cells for o in c.get("outputs", [])), \
        f"{path.name}: a cell reported an error without raising"


def test_notebooks_are_stored_without_outputs():
    """Notebooks are kept small in the repository: no stored outputs or execution counts."""
    nbformat = pytest.importorskip("nbformat")
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        dirty = [i for i, c in enumerate(nb.cells)
                 if c.cell_type == "code" and (c.get("outputs") or c.get("execution_count") is not None)]
        assert not dirty, f"{path.name}: cells {dirty} carry outputs; clear them before committing"
