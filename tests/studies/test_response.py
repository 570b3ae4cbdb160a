"""``sunsim response``: the traced angular response of a configuration's diodes.

Oracles: the cosine for a bare diode with nothing above it; the closed-form overlap of the well minus the
body box's shadow (simcore.shapes.occlusion.lit_fraction_with_box, exact polygon clipping) for a ramp diode
whose view the body cuts; Basilisk's response with a known Kelly factor for the fit.
"""
import json

import numpy as np
import pytest

from scenes.config import SatelliteConfig
from simcore.cli import main
from simcore.radiometry.analytic import BodyBox
from simcore.sensor.errors import basilisk_response
from simcore.shapes.occlusion import lit_fraction_with_box
from simcore.studies.response import fit_kelly, traced_response


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_bare_diode_on_the_top_face_reads_the_cosine(capsys):
    out = _json(capsys, ["response", "tilt0_fov90", "--diode", "4", "--step", "15", "--samples", "1024", "--json"])
    (d,) = out["diodes"]
    assert d["index"] == 4 and d["theta_deg"] == [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0]
    np.testing.assert_allclose(d["response"], np.cos(np.radians(d["theta_deg"])), atol=1e-6)
    assert d["reflected"] == [0.0] * 7                       # black surfaces reflect nothing
    assert d["kelly_factor"] == 0.0                         # the pure cosine fits best
    for key in ("response_se", "direct", "cosine", "eq415", "well", "kelly"):
        assert len(d[key]) == 7


def test_ramp_diode_traced_through_the_body_shadow_matches_the_box_model():
    cfg = SatelliteConfig.load("tilt20_fov70")
    (r,) = traced_response(cfg, diodes=[3], plane="y", step_deg=2.5, samples=4096)
    frame = np.asarray(cfg.frames)[3]
    th = np.radians(r.theta_deg)
    d = np.stack([np.zeros_like(th), np.sin(th), np.cos(th)], 1)
    box = BodyBox.from_config(cfg)
    ref = np.array([lit_fraction_with_box(cfg.diodes[3].aperture, frame, cfg.positions_m[3], x @ frame, box.half_m)
                    * x[2] for x in d])
    # the body hides part of the well's light somewhere in this sweep (else the test would not test it)
    assert np.max(r.well - ref) > 0.05
    # renderer's per-angle error: |traced - exact| within 4 standard errors (+1e-6 where both are exact);
    # over 37 angles a false alarm needs a 4-sigma draw (~2e-3 in all)
    assert np.all(np.abs(r.response - ref) <= 4 * r.response_se + 1e-6), np.c_[r.theta_deg, r.response, ref]


@pytest.mark.parametrize("kappa, scale", [(0.02, 1.0), (0.1, 1.0), (0.1, 0.923)])
def test_kelly_fit_recovers_a_known_factor_and_scale(kappa, scale):
    # Basilisk's model scaleFactor x cos x (1 - exp(-cos^2 / kappa)) inside the FOV, built with known values
    # (0.923: a bare diode under a glass of index 1.5 at normal incidence, 1 - 2 R with R = 0.04, roughly)
    theta = np.arange(0.0, 90.1, 2.5)
    resp = scale * basilisk_response(np.cos(np.radians(theta)), np.radians(80.0) - 1e-9, kappa)
    k, fov, rms, s = fit_kelly(theta, resp)
    assert k == pytest.approx(kappa, rel=1e-3) and s == pytest.approx(scale, rel=1e-6) and fov == 80.0 and rms < 1e-6
    # and a wrong curve is not fitted exactly: the cosine itself has no Kelly factor
    assert fit_kelly(theta, np.cos(np.radians(theta)))[0] == 0.0


@pytest.mark.parametrize("argv, words", [
    (["--diode", "14"], "--diode 14 does not exist"),
    (["--step", "0"], "--step must lie in (0, 45]"),
    (["--samples", "1000"], "--samples must be 4 m^2"),
    (["--map-step", "0.1"], "--map-step must lie in"),
    (["--plot", "out.txt"], "give a .png or .pdf"),
    (["--diode", "14", "--plot", "sub/x.png"], "--diode 14 does not exist"),     # the plot folder is not made
    (["--variant", "bogus", "--plot", "sub/x.png"], "--variant bogus is unknown"),  # (was a traceback + folder)
])
def test_bad_input_is_one_line_and_nothing_is_written(capsys, tmp_path, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    assert main(["response", "tilt20_fov70", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


def test_aluminium_wells_add_reflected_light_to_the_response():
    # The shipped example scenes/examples/tilt20_fov70_aluminium.toml: the same wells in bare aluminium. Their walls
    # reflect sunlight onto a ramp diode once the Sun is off its normal (the walls facing it are then lit); the
    # direct part is the black layout's.
    from pathlib import Path
    example = Path(__file__).resolve().parents[2] / "scenes" / "examples" / "tilt20_fov70_aluminium.toml"
    (alu,) = traced_response(str(example), diodes=[3], plane="y", step_deg=10, samples=1024, reflected_samples=1024)
    (black,) = traced_response("tilt20_fov70", diodes=[3], plane="y", step_deg=10, samples=1024)
    np.testing.assert_allclose(alu.direct, black.direct, atol=1e-9)
    assert np.all(black.reflected == 0)
    lit = (alu.theta_deg >= 20) & (alu.theta_deg <= 60)
    # reflected light is positive and resolved: > 3 standard errors at every lit angle (false alarm ~1e-3 each)
    se_r = np.sqrt(np.maximum(alu.response_se ** 2 - black.response_se ** 2, 0.0))
    assert np.all(alu.reflected[lit] > 3 * se_r[lit]), np.c_[alu.theta_deg, alu.reflected, se_r]
