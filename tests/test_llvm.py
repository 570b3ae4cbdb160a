"""numpy arrays handed to Dr.Jit: the crash that killed whole test runs, and the guard against it.

Dr.Jit 1.5 wraps a numpy array without copying it, and its CPU kernels read a lane-wise input in whole SIMD
packets, the last one past the array's end. Where the array's buffer is not 64-byte aligned and ends just
before an unmapped page, that last (unaligned, 64-byte) load faults. The full test suite died this way about
once in three runs (kernel log: ``segfault at <page start> ... error 4``, the same offset into a JIT kernel each
time). Each case runs in a fresh interpreter, so that the crash it provokes is a return code, not a dead run.
"""
import subprocess
import sys
import textwrap

# A float32 array of 1004 ones (4016 bytes: a whole number neither of 8-lane AVX2 nor of 16-lane AVX-512
# packets, so the last packet overruns on either CPU; 1000 ones overran only with AVX-512 and read cleanly on
# AVX2 machines) placed so that it ends exactly at a page boundary with no access to the page after it, its start
# 16 bytes off a 64-byte boundary (as numpy's 16-byte-aligned buffers may be); a Dr.Jit kernel then reads it
# directly (not by gather).
_SCRIPT = textwrap.dedent("""
    import ctypes, mmap, sys
    import numpy as np
    from simcore import _llvm
    dr, mi = _llvm.import_drjit(), _llvm.import_mitsuba()
    mi.set_variant("llvm_ad_mono")
    page = mmap.PAGESIZE
    buf = mmap.mmap(-1, 2 * page, prot=mmap.PROT_READ | mmap.PROT_WRITE)
    addr = ctypes.addressof(ctypes.c_char.from_buffer(buf))
    assert ctypes.CDLL(None).mprotect(ctypes.c_void_p(addr + page), page, 0) == 0
    a = np.frombuffer(buf, dtype=np.float32, count=1004, offset=page - 4016)
    a[:] = 1.0
    assert a.ctypes.data % 64 == 16
    f = mi.Float(a) if sys.argv[1] == "plain" else _llvm.host_array(mi.Float, a)
    print(dr.sum(2.0 * f + 1.0)[0])
""")


def _run(mode, tmp_path):
    script = tmp_path / "overread.py"
    script.write_text(_SCRIPT)
    return subprocess.run([sys.executable, str(script), mode], capture_output=True, text=True, timeout=300)


def test_host_array_survives_a_buffer_that_ends_at_an_unmapped_page(tmp_path):
    r = _run("host_array", tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert float(r.stdout.split()[-1]) == 3012.0             # sum of 2 x 1 + 1 over 1004 lanes


def test_the_plain_conversion_reads_past_the_end(tmp_path):
    """The hazard itself (Dr.Jit 1.5): the same buffer wrapped directly dies with SIGSEGV. Should a later Dr.Jit
    mask its last packet, this fails and host_array's copy can go."""
    r = _run("plain", tmp_path)
    assert r.returncode == -11, (r.returncode, r.stdout, r.stderr[-500:])


def test_host_array_copies_values_and_types():
    import numpy as np
    from simcore import _llvm
    dr, mi = _llvm.import_drjit(), _llvm.import_mitsuba()
    mi.set_variant("llvm_ad_mono")
    from drjit.llvm import Float64, UInt32
    src = np.arange(37, dtype=np.float64).reshape(37, 1) * 0.5      # any shape, any dtype: flattened, converted
    f = _llvm.host_array(mi.Float, src)
    src[:] = -1.0                                                    # a copy: later changes do not reach it
    np.testing.assert_array_equal(f.numpy(), np.arange(37, dtype=np.float32) * 0.5)
    np.testing.assert_array_equal(_llvm.host_array(Float64, [0.1, 0.2]).numpy(), [0.1, 0.2])
    np.testing.assert_array_equal(_llvm.host_array(UInt32, np.array([3, 4])).numpy(), [3, 4])
    assert len(_llvm.host_array(mi.Float, np.zeros(0))) == 0


def test_host_buffer_is_aligned_with_slack_and_host_wrap_refuses_other_arrays():
    import numpy as np
    import pytest
    from simcore import _llvm
    dr, mi = _llvm.import_drjit(), _llvm.import_mitsuba()
    mi.set_variant("llvm_ad_mono")
    from drjit.llvm import UInt32
    for n in (1, 7, 1000, 4097):
        b = _llvm.host_buffer(n, np.uint32)
        assert b.shape == (n,) and b.dtype == np.uint32 and b.ctypes.data % 64 == 0
        # two 64-byte packets of the same allocation after the end (what a kernel's last packet may read)
        assert b.base.ctypes.data + b.base.nbytes >= b.ctypes.data + b.nbytes + 128
        b[:] = np.arange(n, dtype=np.uint32) * 3
        w = _llvm.host_wrap(UInt32, b)
        assert np.array_equal(np.asarray((w + 1).numpy()), np.arange(n) * 3 + 1)
    with pytest.raises(ValueError, match="host_buffer"):
        _llvm.host_wrap(UInt32, np.arange(10, dtype=np.uint32))                 # not from host_buffer
    with pytest.raises(ValueError, match="dtype"):
        _llvm.host_wrap(mi.Float, _llvm.host_buffer(10, np.uint32))            # wrong type
