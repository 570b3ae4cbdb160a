#!/usr/bin/env bash
# The GPU figure of issue 32 item 5, on the GPU machine the device tool sometimes lends (benchmarks/README.md, "The
# GPU figure: how to take it"; the wheels from benchmarks/device_wheels.py). Two calls, the second at once after the
# first, while the machine stays warm (its /tmp lives only that long):
#   a: installs .whl/a (Mitsuba, Dr.Jit, sgp4, pyerfa, trimesh, h5netcdf) into /tmp/sunsim-site; prints the GPU;
#   b: adds .whl/b (libLLVM: Dr.Jit's CPU backend, which the renderer needs with either variant), then runs
#      bench_render.py on cuda_ad_mono and on llvm_ad_mono with all the machine's cores, then bench_run.py (the
#      whole run against the renderer alone, on cuda_ad_mono); each output also in $OUT.
set -euo pipefail
part=${1:?usage: bash benchmarks/device_bench.sh a|b}
SITE=/tmp/sunsim-site
OUT=${OUT:-/tmp/sunsim-out}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
if [ "$part" = a ] || [ "$part" = b ]; then
    if ! ls .whl/"$part"/*.whl > /dev/null 2>&1; then
        echo "no wheels in .whl/$part: run 'python benchmarks/device_wheels.py' first, and carry .whl/$part" >&2
        exit 2
    fi
fi
case $part in
a)
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$SITE" .whl/a/*.whl
    PYTHONPATH=$SITE python3 -c "import drjit, mitsuba, sys; print('python', sys.version.split()[0], '/ mitsuba',
mitsuba.__version__, '/ drjit', drjit.__version__)" | tee "$OUT/versions.txt"
    (nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv || echo "nvidia-smi failed") \
        | tee "$OUT/gpu.txt"
    echo "part a done: call part b now, while this machine is warm"
    ;;
b)
    if [ ! -d "$SITE/mitsuba" ]; then
        echo "part a's installation is gone (this is a fresh machine): call part a again, then part b at once" >&2
        exit 2
    fi
    # the wheel's lib/ (libLLVM, and the libc++ its RUNPATH $ORIGIN/../lib/x86_64-unknown-linux-gnu names) unpacked
    # as pip would put it under a prefix, with the libc++ sonames a wheel cannot carry as links
    llvm=$(python3 - .whl/b/karellen_llvm_core-*.whl <<'PY'
import os, sys, zipfile
root = "/tmp/sunsim-llvm"
with zipfile.ZipFile(sys.argv[1]) as z:
    for name in z.namelist():
        head, sep, rest = name.partition(".data/data/lib/")
        if sep and not name.endswith("/"):
            path = os.path.join(root, "lib", rest)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "wb") as f:
                f.write(z.read(name))
sub = os.path.join(root, "lib", "x86_64-unknown-linux-gnu")
for f in os.listdir(sub):
    if f.endswith(".so.1.0") and not os.path.exists(os.path.join(sub, f[:-2])):
        os.symlink(f, os.path.join(sub, f[:-2]))
print(next(os.path.join(root, "lib", f) for f in os.listdir(os.path.join(root, "lib")) if f.startswith("libLLVM.so.")))
PY
)
    export DRJIT_LIBLLVM_PATH=$llvm PYTHONPATH=$SITE:$PWD
    echo "cores: $(nproc); libLLVM: $llvm" | tee "$OUT/machine.txt"
    python3 benchmarks/bench_render.py --variant cuda_ad_mono 2>&1 | tee "$OUT/bench_render_cuda_ad_mono.txt"
    python3 benchmarks/bench_render.py --variant llvm_ad_mono 2>&1 | tee "$OUT/bench_render_llvm_ad_mono.txt"
    # the whole run against the renderer alone, on the variant a run picks there (cuda_ad_mono)
    python3 benchmarks/bench_run.py --repeat 1 2>&1 | tee "$OUT/bench_run.txt"
    ;;
*)
    echo "usage: bash benchmarks/device_bench.sh a|b" >&2
    exit 2
    ;;
esac
