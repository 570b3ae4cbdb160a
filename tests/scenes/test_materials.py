"""Issue 13 item 3: spacecraft materials by name, as Mitsuba BSDFs, and the configuration keys that choose them.

Each named material's reflectance at normal incidence is checked against the value its docstring cites
(closed forms: a Lambertian's albedo is its reflectance; a conductor's normal-incidence Fresnel reflectance
((n-1)^2 + k^2) / ((n+1)^2 + k^2)); a wrong name is one line and exit 2 from the command line.
"""
import subprocess
import sys

import numpy as np
import pytest

from scenes.config import SatelliteConfig
from scenes.materials import MATERIALS, MaterialError, bsdf_dict, check_material, is_black
from scenes.meshes import build_parts, build_satellite_mesh
from simcore import _llvm

FACES6 = {"layout": {"pattern": "faces6", "tilt_deg": 0, "fov_deg": 90}}


def _albedo_normal(spec, n=200_000, seed=1):
    """Return the directional albedo (mean BSDF sample weight) at normal incidence and its standard error."""
    mi = _llvm.import_mitsuba()
    mi.set_variant("llvm_ad_mono")
    dr = _llvm.import_drjit()
    bsdf = mi.load_dict(bsdf_dict(spec))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    rng = np.random.default_rng(seed)
    u = rng.random((3, n)).astype(np.float32)
    f = [_llvm.host_array(mi.Float, x) for x in u]     # docs/conventions.md: numpy reaches Dr.Jit only so
    _, w = bsdf.sample(mi.BSDFContext(), si, f[0], mi.Point2f(f[1], f[2]))
    w = np.asarray(w.numpy(), float).ravel()
    return w.mean(), w.std() / np.sqrt(n)


def _fresnel_conductor_normal(eta, k):
    """Normal-incidence reflectance of a conductor of complex index eta + i k (Born & Wolf, eq. 14.2 (16))."""
    return ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor N = eta + i k from vacuum at incidence cos_i: the mean
    of |r_s|^2 and |r_p|^2 of the complex Fresnel equations (Born & Wolf, sec. 14.2)."""
    n2 = complex(eta, k) ** 2
    c = np.asarray(cos_i, dtype=complex)
    root = np.sqrt(n2 - (1 - c * c))
    rs = (c - root) / (c + root)
    rp = (n2 * c - root) / (n2 * c + root)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def ggx_albedo_normal(alpha, eta, k, n=20000):
    """Directional albedo at normal incidence of a GGX microfacet conductor with the separable Smith
    shadowing G1(wi) G1(wo) (Walter et al., EGSR 2007, eqs. 20, 23, 34): int F D G / (4 cos_i) dw_o,
    by the midpoint rule in theta_o (azimuthally symmetric for wi = normal)."""
    th = (np.arange(n) + 0.5) * (0.5 * np.pi / n)
    h_t = th / 2                                   # half vector angle for wi = z
    t2 = np.tan(h_t) ** 2
    D = alpha ** 2 / (np.pi * np.cos(h_t) ** 4 * (alpha ** 2 + t2) ** 2)
    g1 = lambda tt: 2.0 / (1.0 + np.sqrt(1.0 + alpha ** 2 * tt))   # noqa: E731
    G = g1(0.0) * g1(np.tan(th) ** 2)
    F = fresnel_conductor(np.cos(h_t), eta, k)
    return float(np.sum(F * D * G / 4.0 * np.sin(th)) * 2 * np.pi * (0.5 * np.pi / n))


# Expected normal-incidence albedo, with its source; tolerance = 3.3 standard errors of the 200 000-sample
# estimate (false alarm 1e-3 per value).
@pytest.mark.parametrize("name, expected", [
    ("black", 0.0),                                        # ideal absorber
    ("black_paint", 0.05),                                 # Lambertian albedo = rho (Henninger 1984 value)
    ("mirror", 1.0),                                       # Fresnel factor 1
    ("aluminium", ggx_albedo_normal(0.1, 0.958, 6.69)),    # Rakic 1998 Al at 550 nm, GGX alpha 0.1
])
def test_named_material_reflectance_at_normal_incidence(name, expected):
    m, se = _albedo_normal(name)
    assert abs(m - expected) <= 3.3 * se + 1e-6, (name, m, se, expected)


def test_aluminium_fresnel_value_is_the_documented_one():
    # the docstring's 0.921 from Rakic's n, k (independent arithmetic)
    assert abs(_fresnel_conductor_normal(0.958, 6.69) - 0.921) < 5e-4
    assert abs(fresnel_conductor(1.0, 0.958, 6.69) - 0.921) < 5e-4


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_every_named_material_loads_and_conserves_energy(name):
    m, se = _albedo_normal(name, n=20_000)
    assert 0.0 <= m <= 1.0 + 3.3 * se


def test_wrong_albedo_is_caught():
    # negative case: the normal-incidence check above fails for a material that is not what it claims
    m, se = _albedo_normal({"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.08}})
    assert abs(m - 0.05) > 3.3 * se


def test_unknown_material_lists_the_names():
    with pytest.raises(MaterialError, match="use one of aluminium, anodised_aluminium, black, black_paint"):
        check_material("shiny")
    with pytest.raises(MaterialError, match="Mitsuba's BSDFs"):
        check_material({"type": "roughmetal"})
    assert check_material({"type": "roughconductor", "material": "Au"})["type"] == "roughconductor"


def test_config_materials_reach_the_parts():
    cfg = SatelliteConfig.from_dict({**FACES6, "body": {"material": "solar_cell"},
                                     "mount": {"material": {"type": "roughconductor", "alpha": 0.2}}})
    parts = build_parts(cfg)
    assert parts["body"].metadata["material"] == "solar_cell"
    assert parts["floor_0"].metadata["material"] == {"type": "roughconductor", "alpha": 0.2}
    mesh = build_satellite_mesh(cfg)
    assert set(mesh.metadata["materials"]) == set(mesh.metadata["parts"])


def test_default_is_black_everywhere():
    for name in ("tilt0_fov90", "tilt20_fov70"):
        mesh = build_satellite_mesh(SatelliteConfig.load(name))
        assert all(is_black(m) for m in mesh.metadata["materials"].values())


def test_unknown_material_on_the_command_line(tmp_path):
    (tmp_path / "bad.toml").write_text('[layout]\npattern = "faces6"\ntilt_deg = 0\nfov_deg = 90\n'
                                       '[mount]\nmaterial = "shiny_foil"\n')
    r = subprocess.run([sys.executable, "-m", "simcore.cli", "run", "--config", "bad.toml", "--out", "x.nc"],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "unknown material 'shiny_foil'" in lines[0] and "black_paint" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_expert_table_mitsuba_cannot_build_is_a_config_error(tmp_path):
    (tmp_path / "bad.toml").write_text('[layout]\npattern = "faces6"\ntilt_deg = 0\nfov_deg = 90\n'
                                       '[body]\nmaterial = {type = "roughconductor", alpha = "rough"}\n')
    r = subprocess.run([sys.executable, "-m", "simcore.cli", "run", "--config", "bad.toml", "--out", "x.nc"],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and 'Mitsuba cannot build the material' in lines[0] and '"alpha"' in lines[0], r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]
