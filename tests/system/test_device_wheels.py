"""The GPU machine's slimmed Mitsuba (benchmarks/device_wheels.py) keeps what a render loads.

The device tool's GPU machine takes at most 64 MiB per call, so ``device_wheels.py`` keeps of Mitsuba's wheel only
the two render variants and the BSDF and texture plugins. The oracles: Mitsuba's own list of its variants, and the
shared objects this process has mapped (``/proc/self/maps``) after Mitsuba built the BSDF of every material of
scenes/materials.py (in a fresh interpreter): a material added with a plugin the slimmed wheel drops fails here, not
on the lent GPU.
"""
import os
import runpy
import subprocess
import sys
from pathlib import Path

from simcore import _llvm

ROOT = Path(__file__).resolve().parents[2]
WHEELS = runpy.run_path(str(ROOT / "benchmarks" / "device_wheels.py"))
KEEPS = WHEELS["_mitsuba_keeps"]


def test_only_the_two_render_variants_are_kept():
    mi = _llvm.import_mitsuba()
    variants = mi.variants()
    assert set(WHEELS["KEEP_VARIANTS"]) <= set(variants)
    for v in variants:
        kept = KEEPS(f"mitsuba/{v}.cpython-312-x86_64-linux-gnu.so")
        assert kept == (v in WHEELS["KEEP_VARIANTS"]), v
    assert KEEPS("mitsuba/mitsuba_ext.cpython-312-x86_64-linux-gnu.so")   # not a variant: always kept
    assert KEEPS("mitsuba/libmitsuba.so") and KEEPS("mitsuba/libembree3.so") and KEEPS("mitsuba/__init__.py")


def test_every_plugin_a_material_loads_is_kept():
    # in a fresh interpreter: other tests (pictures: emitters, films, integrators) map plugins the benchmarks never use
    script = """
from scenes.materials import bsdf_dict, material_names
from simcore import _llvm
mi = _llvm.import_mitsuba()
mi.set_variant("llvm_ad_mono")
for name in material_names():
    mi.load_dict(bsdf_dict(name))
with open("/proc/self/maps") as maps:
    print(" ".join(sorted({line.split()[-1] for line in maps if "/mitsuba/plugins/" in line})))
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=ROOT)
    names = {os.path.basename(p).split(".")[0] for p in out.stdout.split()}
    assert {"diffuse", "twosided", "uniform", "roughconductor"} <= names   # the test saw the plugins it looks for
    assert all(KEEPS(f"mitsuba/plugins/{n}.so") for n in names), names - WHEELS["KEEP_PLUGINS"]
    assert not KEEPS("mitsuba/plugins/perspective.so")           # (the slimming does drop plugins)
