"""What a configuration declares (scenes/declared.py): normals written to a few digits are normalised with a
note the run prints and stores; a diode type decides the band of --map band, and "unknown" refuses it."""
import numpy as np
import pytest

from scenes.config import ConfigError, SatelliteConfig
from simcore.errors import InvalidInputError
from simcore.pipeline.preflight import map_for_diodes

# OPS-SAT's PD6 normal as the shared data's README gives it, to three digits: norm 0.99995 (not unit to 1e-5)
PD6 = "[-0.015, -0.041, -0.999]"


def _cfg(tmp_path, normal="[0.0, 0.0, -1.0]", extra=""):
    p = tmp_path / "c.toml"
    p.write_text(f'{extra}\n[[diode]]\npanel = "-z"\nnormal = {normal}\nfov_deg = 70\n')
    return SatelliteConfig.load(p)


def test_a_three_digit_normal_is_normalised_with_a_note(tmp_path):
    cfg = _cfg(tmp_path, PD6)
    n = np.array([-0.015, -0.041, -0.999])
    np.testing.assert_allclose(cfg.normals[0], n / np.linalg.norm(n), atol=1e-15)
    assert len(cfg.notes) == 1 and "normalised" in cfg.notes[0] and "0.99995" in cfg.notes[0]
    assert _cfg(tmp_path).notes == ()                                    # an exact normal: no note
    with pytest.raises(ConfigError, match="not a unit vector .* more than 0.002"):
        _cfg(tmp_path, "[0.0, 0.0, -0.99]")


def test_the_note_reaches_the_run(tmp_path):
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.run import prepare
    cfg = _cfg(tmp_path, PD6)
    study = prepare(RunOptions(config=cfg.source, start="2016-07-02T00:45:00Z", duration_s=2))
    assert any("normalised" in n for n in study.notes)


def test_diode_type_decides_the_band_map(tmp_path):
    known = _cfg(tmp_path, extra='diode_type = "bpv23f"')
    assert known.diode_type == "BPV23F"
    assert map_for_diodes("band", known) == "band:BPV23F" and map_for_diodes("band-clear", known) == "band-clear:BPV23F"
    assert map_for_diodes("band:SFH2430", known) == "band:SFH2430"       # a named diode wins
    unknown = _cfg(tmp_path, extra='diode_type = "unknown"')
    with pytest.raises(InvalidInputError) as exc:
        map_for_diodes("band", unknown)
    assert "declares diode_type = \"unknown\"" in str(exc.value) and "\n" not in str(exc.value)
    for name in ("band:BPW34FS", "ceres2018-all", "toms2005", "uniform:0.3"):
        assert map_for_diodes(name, unknown) == name
    assert map_for_diodes("band", _cfg(tmp_path)) == "band"              # undeclared: BPW34FS as always
    with pytest.raises(ConfigError, match="diode_type must be"):
        _cfg(tmp_path, extra="diode_type = 3")
