"""The layout's size limits (issue 30): no Python module of the product over 900 lines, none of the renderer's
over 600, so that no module grows back into a manual. A module that outgrows its limit is split by what it does
(docs/layout.md), not by raising the number here."""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LIMITS = [("simcore", 900), ("scenes", 900), ("estimators", 900), ("simcore/render", 600)]


def _too_long(folder, limit, root=ROOT):
    out = []
    for path in sorted((root / folder).rglob("*.py")):
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > limit:
            out.append(f"{path.relative_to(root).as_posix()}: {n} lines")
    return out


@pytest.mark.parametrize("folder, limit", LIMITS)
def test_no_module_over_its_limit(folder, limit):
    assert (ROOT / folder).is_dir()
    assert _too_long(folder, limit) == [], f"modules over {limit} lines in {folder}/"


def test_the_limit_sees_a_long_module(tmp_path):
    # the check itself on a planted 901-line module
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "long.py").write_text("x = 1\n" * 901)
    (tmp_path / "pkg" / "short.py").write_text("x = 1\n" * 900)
    assert _too_long("pkg", 900, tmp_path) == ["pkg/long.py: 901 lines"]
