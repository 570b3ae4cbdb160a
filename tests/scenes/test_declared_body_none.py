"""[body] none = true (scenes/declared.py): a bare-diode study. The panels still place the diodes, but no body is
rendered and none shadows them. Oracle: a bare diode (fov 90) tilted 40 deg from the +z panel toward +x, with the
Sun 20 deg below that panel's plane on the +x side: the body box blocks the ray toward the Sun (it leaves the diode
a few mm above the top face and meets it within ~20 mm), so with the body the direct Sun is 0; without it the diode
reads the cosine law, E_n cos(incidence) with cos = sin 40 cos 20 - cos 40 sin 20 = 0.3420."""
import numpy as np
import pytest

from simcore.environment.attitude import matrix_to_quat
from simcore.environment.epochs import Epochs
from simcore.environment.geometry import compute_geometry
from simcore.environment.history import AttitudeHistory
from simcore.environment.orbit import Orbit
from simcore.pipeline.options import RunOptions
from simcore.pipeline.run import execute

START = "2016-07-02T00:45:00Z"
TOML = '''name = "bare"
{body}
[[diode]]
panel = "+z"
az_deg = 0.0
el_deg = 50.0
fov_deg = 90
'''


def _rotation_onto(a, b):
    """Return the rotation matrix turning unit a onto unit b (about a x b)."""
    v, c = np.cross(a, b), float(a @ b)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def test_no_body_leaves_the_cosine_law(tmp_path):
    e = Epochs.from_any(START) + np.array([0.0, 10.0])
    s_gcrs = compute_geometry(Orbit.default(), e).sun_dir_gcrs[0]
    s_body = np.array([np.cos(np.radians(20)), 0.0, -np.sin(np.radians(20))])
    q = matrix_to_quat(_rotation_onto(s_body, s_gcrs))[0]
    hist = AttitudeHistory(e, np.array([q, q]))
    out = {}
    for name, body in (("box", ""), ("none", "[body]\nnone = true")):
        cfg = tmp_path / f"{name}.toml"
        cfg.write_text(TOML.format(body=body))
        _, ds, report = execute(RunOptions(config=str(cfg), attitude_history=hist, rel_se_direct=None,
                                           rel_se_albedo=None, direct_samples=256, albedo_samples=256,
                                           output=str(tmp_path / f"{name}.nc")))
        assert report["pass"], (name, report)
        out[name] = ds
    cos_inc = np.sin(np.radians(40)) * np.cos(np.radians(20)) - np.cos(np.radians(40)) * np.sin(np.radians(20))
    assert cos_inc == pytest.approx(0.3420, abs=1e-4)
    np.testing.assert_allclose(out["none"]["sun_dir_body"].values, np.tile(s_body, (2, 1)), atol=2e-5)
    d_none = out["none"]["irradiance"].sel(component="direct").values[:, 0]
    se = out["none"]["irradiance_se"].sel(component="direct").values[:, 0]
    expect = out["none"]["sun_normal_irradiance"].values * cos_inc
    assert np.all(np.abs(d_none - expect) <= np.maximum(4 * se, 1e-6 * expect)), (d_none, expect, se)
    assert np.all(out["box"]["irradiance"].sel(component="direct").values[:, 0] == 0.0)
    # the mesh has no body; the diode's mount (ramp, floor plate) stays
    from scenes.config import SatelliteConfig
    from scenes.meshes import build_parts
    parts = build_parts(SatelliteConfig.load(tmp_path / "none.toml"))
    assert "body" not in parts and "ramp_0" in parts and "body" in build_parts(SatelliteConfig.load(tmp_path / "box.toml"))
