"""``python -m simcore.check_install``: prove the ray-tracing stack works here."""
import sys


def main():
    from simcore import _llvm
    try:
        path = _llvm.find_libllvm()
    except _llvm.LLVMNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    dr, mi = _llvm.import_drjit(), _llvm.import_mitsuba()
    mi.set_variant("llvm_ad_mono")
    x = dr.arange(mi.Float, 4)
    total = float(dr.sum(x * x)[0]) if hasattr(dr.sum(x * x), "__len__") else float(dr.sum(x * x))
    if total != 14.0:
        print(f"error: Dr.Jit with {path} computed {total} instead of 14", file=sys.stderr)
        return 1
    print(f"sunsim: mitsuba {mi.__version__}, drjit {dr.__version__}, libLLVM {path}: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
