"""Issue 31 item 5: scene files that parse but cannot be meant are refused in one line (scenes/sanity.py), and the
shipped configurations and examples stay silent.

The body of these scenes is a 100 x 100 x 227 mm box centred at the origin (the 2U default): its +y face lies
at y = 50 mm. A 20 mm cube centred at y = 60 mm touches that face; at y = 50 mm half of it (10 of 20 mm along y)
lies inside the body.
"""
import glob
import os

import pytest

from scenes.config import SatelliteConfig, list_configs
from simcore.cli import main

DIODES = """
[[diode]]
name = "a"
panel = "+x"
normal = [1, 0, 0]
at_mm = [0, 0]
fov_deg = 70
[[diode]]
name = "b"
panel = "-x"
normal = [-1, 0, 0]
at_mm = [0, 0]
fov_deg = 70
"""


def _cube(y_mm, extra=""):
    return f"""
[[part]]
name = "cube"
box_mm = [20.0, 20.0, 20.0]
translate_mm = [0.0, {y_mm}, 0.0]
material = "aluminium"
{extra}
"""


def _write(tmp_path, text, name="s.toml"):
    path = tmp_path / name
    path.write_text('name = "s"\n' + DIODES + text)
    return str(path)


@pytest.mark.parametrize("text, words", [
    (_cube(0.0), "100% of the part lies inside the body"),
    (_cube(50.0), "50% of the part lies inside the body"),        # 10 of 20 mm along y; 0.5 mm tolerance: 47.5 %
    (_cube(0.06), "is it in metres?"),                          # 60 mm written as 0.06
    (_cube(60.0, 'hinge = {axis = [1.0, 0.0, 0.0], point_mm = [0.0, 50.0, 0.0], angle_deg = 1e9}'),
     "hinge angle_deg = 1e+09 is beyond +-360 deg"),
    (_cube(60.0) + _cube(-60.0), "two parts share a name ('cube')"),
])
def test_an_implausible_scene_is_one_line_before_any_work(tmp_path, capsys, monkeypatch, text, words):
    monkeypatch.chdir(tmp_path)
    path = _write(tmp_path, text)
    assert main(["coverage", path, "--no-plot"]) == 2
    lines = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0], lines
    assert sorted(os.listdir(tmp_path)) == ["s.toml"]


def test_two_diodes_of_one_name_are_refused(tmp_path):
    path = tmp_path / "d.toml"
    path.write_text('name = "d"\n' + DIODES.replace('name = "b"', 'name = "a"'))
    with pytest.raises(Exception, match=r"two diodes share a name \('a'\)"):
        SatelliteConfig.load(str(path))


@pytest.mark.parametrize("y_mm", [60.0, 59.7, 75.0])
def test_a_part_touching_or_mounted_on_a_face_is_fine(tmp_path, y_mm):
    # 60: the cube's face on the body's; 59.7: 0.3 mm into it (CAD rounding, within the 0.5 mm tolerance)
    SatelliteConfig.load(_write(tmp_path, _cube(y_mm)))


def test_the_half_inside_share_is_the_volume_share(tmp_path):
    from scenes.sanity import OVERLAP_TOLERANCE_M, _overlap_share
    cfg = SatelliteConfig.from_dict({"name": "x", "diode": [{"name": "a", "panel": "+x", "normal": [1, 0, 0],
                                                              "at_mm": [0, 0], "fov_deg": 70}]})
    # the cube's y extent 40..60 mm; inside the body (less the tolerance) 40..49.5 mm: 9.5 of 20 mm
    from scenes.parts import build_part
    part = build_part(0, {"name": "c", "box_mm": [20, 20, 20], "translate_mm": [0, 50, 0]}, tmp_path, "t")
    expected = (50.0 - OVERLAP_TOLERANCE_M * 1e3 - 40.0) / 20.0
    assert abs(_overlap_share(part, cfg.body) - expected) < 1 / 16          # the grid's 16 cells a side


def test_the_shipped_scenes_stay_silent():
    here = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", "examples")
    for path in sorted(glob.glob(os.path.join(here, "*.toml"))):
        SatelliteConfig.load(path)
    for name in list_configs():
        SatelliteConfig.load(name)
        SatelliteConfig.load(name, extra_flat_diodes=True)
