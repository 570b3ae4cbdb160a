"""Prepare the wheels that the GPU machine lacks, for ``benchmarks/device_bench.sh`` (issue 32 item 5).

The GPU machine that the device tool sometimes lends (an NVIDIA H200 with 16 CPU cores; ../.library/device) runs
Python 3.12 with numpy, scipy, pandas, xarray, h5py, tqdm and matplotlib, reaches no network, and takes at most
64 MiB per call: the checkout and the carried wheels together. This script downloads, for CPython 3.12 on
manylinux x86-64, the versions this environment runs of what that machine lacks (mitsuba, drjit, the libLLVM
wheel that Dr.Jit's CPU backend needs with either variant, sgp4, pyerfa, trimesh, h5netcdf), keeps of Mitsuba only
what the renderer uses (the variants ``llvm_ad_mono`` and ``cuda_ad_mono``, the BSDF and texture plugins), and
splits them into two folders, each with the checkout under the limit: ``.whl/a`` (Mitsuba and the small ones)
and ``.whl/b`` (libLLVM). The two device calls that use them are printed at the end (benchmarks/README.md, "The
GPU figure: how to take it").

    .venv/bin/python benchmarks/device_wheels.py

It needs the package index (pip download); run it where the checkout is, before the GPU is lent.
"""
import argparse
import importlib.metadata
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile

PYTHON = "3.12"          # the GPU machine's python3
PLATFORMS = ("manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64",
             "manylinux_2_5_x86_64", "manylinux1_x86_64")
PART_A = ("mitsuba", "drjit", "sgp4", "pyerfa", "trimesh", "h5netcdf")
PART_B = ("karellen-llvm-core",)
KEEP_VARIANTS = ("llvm_ad_mono", "cuda_ad_mono")
# Mitsuba's plugins that a render loads: the BSDFs (scenes/materials.py and [[part]] tables) and their textures.
# The rest (integrators, emitters, sensors, films, filters, samplers, shapes loaded from files, media) the renderer
# never instantiates: it builds its meshes in memory and traces rays itself.
KEEP_PLUGINS = {"diffuse", "plastic", "roughplastic", "pplastic", "conductor", "roughconductor", "dielectric",
                "roughdielectric", "thindielectric", "twosided", "null", "mask", "blendbsdf", "bumpmap", "normalmap",
                "principled", "principledthin", "measured", "hair", "uniform", "srgb", "d65", "bitmap",
                "checkerboard", "blackbody", "irregular", "regular", "rawconstant", "mesh_attribute"}
LIMIT_BYTES = 64 * 2 ** 20
DEST = ".whl"             # in the checkout (git ignores it): device_bench.sh reads .whl/a and .whl/b


def checkout_bytes(root):
    """Return the bytes that travel with a device call besides the carried folders: tracked files and untracked
    ones git does not ignore."""
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=root,
                         capture_output=True, check=True).stdout
    return sum(os.path.getsize(os.path.join(root, p)) for p in out.decode().split("\0") if p and
               os.path.isfile(os.path.join(root, p)))


def download(names, dest, kept):
    """Download the cp312 wheels of ``names`` at this environment's versions into ``dest``; return their paths.
    On failure, exit with a line that says ``kept`` (the part's folder) was left as it was."""
    pins = []
    for name in names:
        try:
            pins.append(f"{name}=={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            pins.append(name)
    cmd = [sys.executable, "-m", "pip", "download", "-q", "--no-deps", "--only-binary=:all:", "--python-version",
           PYTHON, "--implementation", "cp", "-d", dest, *(a for p in PLATFORMS for a in ("--platform", p)), *pins]
    if subprocess.run(cmd).returncode:
        raise SystemExit(f"pip could not download {' '.join(pins)} (above: why; this script needs the package "
                         f"index): {kept} was left as it was")
    return sorted(os.path.join(dest, f) for f in os.listdir(dest) if f.endswith(".whl"))


def _mitsuba_keeps(name):
    """Return whether the file ``name`` of Mitsuba's wheel is kept."""
    base = os.path.basename(name)
    if name.startswith("mitsuba/plugins/"):
        return base.split(".")[0] in KEEP_PLUGINS
    if name.startswith("mitsuba/") and name.count("/") == 1 and ".cpython-" in base:
        module = base.split(".")[0]
        variant_module = module.split("_", 1)[0] in ("scalar", "llvm", "cuda")
        return not variant_module or module in KEEP_VARIANTS
    for variant in ("scalar_", "llvm_", "cuda_"):      # the variants' stub folders
        if name.startswith(f"mitsuba/{variant}") and not any(name.startswith(f"mitsuba/{v}") for v in KEEP_VARIANTS):
            return False
    return True


def slim_mitsuba(path):
    """Rewrite Mitsuba's wheel ``path`` with only what :func:`_mitsuba_keeps` keeps (its RECORD to match)."""
    tmp = path + ".tmp"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as dst:
        kept = [i for i in src.infolist() if _mitsuba_keeps(i.filename)]
        names = {i.filename for i in kept}
        for info in kept:
            data = src.read(info)
            if info.filename.endswith(".dist-info/RECORD"):
                lines = [ln for ln in data.decode().splitlines() if ln.split(",")[0] in names]
                data = ("\n".join(lines) + "\n").encode()
            dst.writestr(info, data, compress_type=zipfile.ZIP_DEFLATED, compresslevel=9)
    os.replace(tmp, path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.parse_args(argv)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    dest = os.path.join(root, DEST)
    tree = checkout_bytes(root)
    for part, names in (("a", PART_A), ("b", PART_B)):
        folder = os.path.join(dest, part)
        with tempfile.TemporaryDirectory() as tmp:
            wheels = download(names, tmp, f"{DEST}/{part}")    # (a failed one leaves the folder as it was)
            for wheel in wheels:
                if os.path.basename(wheel).startswith("mitsuba-"):
                    slim_mitsuba(wheel)
            shutil.rmtree(folder, ignore_errors=True)
            os.makedirs(folder)
            for wheel in wheels:
                shutil.move(wheel, folder)
        size = sum(os.path.getsize(os.path.join(folder, f)) for f in os.listdir(folder))
        total = size + tree
        print(f"{DEST}/{part}: {len(os.listdir(folder))} wheels, {size / 2 ** 20:.1f} MiB; with the checkout "
              f"({tree / 2 ** 20:.1f} MiB) {total / 2 ** 20:.1f} of {LIMIT_BYTES / 2 ** 20:.0f} MiB")
        if total > LIMIT_BYTES:
            raise SystemExit(f"{DEST}/{part} and the checkout exceed the device call's 64 MiB: carry less")
    print(f"then, on the lent GPU machine (the device tool's run), one call right after the other (the first one's "
          f"installation lives only while the machine stays warm):\n"
          f"  run(command='bash benchmarks/device_bench.sh a', carry=['{DEST}/a'], timeout_s=300)\n"
          f"  run(command='bash benchmarks/device_bench.sh b', carry=['{DEST}/b'], timeout_s=600)")


if __name__ == "__main__":
    main()
