"""Angular responses: cosine, eq. 2.32, eq. 4.15, the well aperture and their kernel forms."""
import numpy as np
import pytest

from simcore._llvm import import_drjit
from simcore.shapes.aperture import WellAperture
from simcore.radiometry.response import (NUMPY_OPS, CosineResponse, Eq415Response, ReflectionResponse, check_response,
                              kernel)


def _dir(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack(np.broadcast_arrays(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)), axis=-1)


def test_cosine():
    th = np.array([0.0, 30.0, 60.0, 89.0, 90.0, 120.0, 180.0])
    np.testing.assert_allclose(CosineResponse().response(_dir(th, 33.0)),
                               np.maximum(np.cos(np.radians(th)), 0), atol=1e-15)


def test_reflection_eq_2_32():
    # Thesis eq. 2.32, I = (I_max - I_0) cos + I_0, and fig. 3.3's a = I_max - I_0 = 1, b = I_0 = -0.2:
    # normalised by I_max = 0.8 the response is (cos - 0.2) / 0.8, dark below cos = 0.2.
    r = ReflectionResponse.from_currents(0.8, -0.2)
    assert r.i0_ratio == pytest.approx(-0.25)
    th = np.array([0.0, 40.0, 75.0, 79.0, 85.0, 100.0])
    c = np.cos(np.radians(th))
    expected = np.where(c > 0, np.maximum((c - 0.2) / 0.8, 0.0), 0.0)
    np.testing.assert_allclose(r.response(_dir(th)), expected, atol=1e-15)
    assert r.response(_dir(0.0)) == pytest.approx(1.0)          # normalised at normal incidence
    # A positive I_0 (light reflected onto the diode) keeps a floor until grazing incidence.
    assert ReflectionResponse(0.1).response(_dir(89.999)) == pytest.approx(0.1, abs=1e-4)
    assert ReflectionResponse(0.1).response(_dir(90.001)) == 0.0
    assert ReflectionResponse(0.0).response(_dir(60.0)) == pytest.approx(0.5)   # i0 = 0: the cosine


@pytest.mark.parametrize("fov", [70.0, 75.0])
def test_eq_4_15_breakpoints(fov):
    r = Eq415Response(fov)
    cf = np.cos(np.radians(fov))
    # C >= cos(FOV): A = C; at C = cos(FOV) both branches give C.
    assert r.response(_dir(fov)) == pytest.approx(cf, rel=1e-12)
    assert r.response(_dir(fov + 1e-9)) == pytest.approx(cf, rel=1e-8)
    assert r.response(_dir(30.0)) == pytest.approx(np.cos(np.radians(30.0)))
    # 83.1 deg = arccos(0.12): A -> 0, and 0 beyond.
    cut = np.degrees(np.arccos(0.12))
    assert r.response(_dir(cut)) == pytest.approx(0.0, abs=1e-12)
    assert r.response(_dir(cut - 1e-9)) == pytest.approx(0.0, abs=1e-9)
    assert r.response(_dir(cut + 0.1)) == 0.0
    # In between: C (C - 0.12) / (cos(FOV) - 0.12), eq. 4.15 middle case.
    c = np.cos(np.radians(78.0))
    assert r.response(_dir(78.0)) == pytest.approx(c * (c - 0.12) / (cf - 0.12), rel=1e-12)


def _brute_force_lit_cos(ap, d, n=600):
    """Lit fraction x cos by tracing n x n points of the diode towards d and testing the opening's plane.

    Independent of the overlap formula: a point (x, y) on the diode reaches the rim plane z = h at
    (x, y) + h (d_u, d_v) / d_n and gets light when that lies inside the opening.
    """
    if d[2] <= 0:
        return 0.0
    g = (np.arange(n) + 0.5) / n - 0.5
    x, y = np.meshgrid(g * ap.diode_x_m, g * ap.diode_y_m, indexing="ij")
    xs, ys = x + ap.height_m * d[0] / d[2], y + ap.height_m * d[1] / d[2]
    inside = (np.abs(xs) <= ap.opening_x_m / 2) & (np.abs(ys) <= ap.opening_y_m / 2)
    return inside.mean() * d[2]


@pytest.mark.parametrize("ap", [WellAperture.design(70), WellAperture(2e-3, 3e-3, 4e-3, 3.5e-3, 1.5e-3)])
def test_aperture_response_against_brute_force(ap, rng):
    dirs = [_dir(th, ph) for th, ph in [(0, 0), (50, 10), (72, 0), (75, 45), (80, 200), (82, 300), (85, 0)]]
    dirs += [_dir(np.degrees(np.arccos(rng.uniform(0.05, 1))), rng.uniform(0, 360)) for _ in range(6)]
    kern = kernel(ap)
    for d in dirs:
        bf = _brute_force_lit_cos(ap, d)
        # Grid quadrature of a rectangle: error below ~2 cells' worth of edge, 2 / 600 of the area.
        assert ap.response(d) == pytest.approx(bf, abs=4e-3 * d[2] + 1e-12)
        assert kern(d[0], d[1], d[2], NUMPY_OPS) == pytest.approx(ap.response(d), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("resp", [CosineResponse(), ReflectionResponse(-0.25), ReflectionResponse(0.15),
                                  Eq415Response(70), WellAperture.design(75)])
def test_kernel_forms_match_the_numpy_responses(resp, rng):
    # The kernel form feeds the Dr.Jit path of simcore.radiometry.analytic; it must be the same function.
    dr = import_drjit()
    from drjit.llvm import Float64

    from simcore.radiometry.analytic import _DrJitOps

    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    ref = resp.response(d)
    k = kernel(resp)
    np.testing.assert_allclose(k(d[:, 0], d[:, 1], d[:, 2], NUMPY_OPS), ref, rtol=1e-12, atol=1e-15)
    du, dv, dn = (Float64(np.ascontiguousarray(d[:, i])) for i in range(3))
    got = k(du, dv, dn, _DrJitOps(dr, 1e-300)).numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)


def test_bad_responses():
    with pytest.raises(ValueError, match="i0_ratio"):
        ReflectionResponse(1.5)
    with pytest.raises(ValueError, match="fov_deg"):
        Eq415Response(95)
    with pytest.raises(ValueError, match="cutoff_cos"):
        Eq415Response(85, cutoff_cos=0.12)
    with pytest.raises(TypeError, match="response"):
        check_response(object())
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        CosineResponse().response(np.ones((4, 2)))
