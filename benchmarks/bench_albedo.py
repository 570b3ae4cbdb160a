"""Benchmark: direct + albedo irradiance on the 14 diodes of tilt20_fov70 along 24 h of ESTCube-1 at 1 s.

86 400 epochs x 14 diodes, TOMS 2005 map, the well aperture of
``WellAperture.design(70)`` as every diode's response, cylindrical eclipse.
Target (issue "analytic albedo", item 4): < 20 s on the 2-core machine for
:func:`simcore.radiometry.analytic.diode_irradiance` (the geometry -- SGP4, frames,
Sun, tumble -- is timed separately, it is another module's benchmark).

For the ratio the same physics is also evaluated the plain way: per epoch,
numpy over the whole 180 x 288 grid (every cell weighted, masked, and passed
through ``WellAperture.response`` for each diode). That is timed on
``PLAIN_EPOCHS`` epochs spread over the day and extrapolated to 86 400; the
two results are compared on those epochs.

Run: .venv/bin/python benchmarks/bench_albedo.py
Last output line: one JSON object with the figures.
"""
import json
import time

import numpy as np

from simcore.radiometry.analytic import diode_irradiance
from simcore.shapes.aperture import WellAperture, diode_frame
from simcore.constants import E_SUN_W_M2
from simcore.environment.epochs import Epochs
from simcore.environment.maps import ReflectivityMap
from simcore.environment.geometry import compute_geometry

TARGET_S = 20.0
PLAIN_EPOCHS = 60


def tilt_normals(tilt_deg):
    """Return the 14 diode normals (14, 3) of the "tilt X" layout, SPEC sec. 5 (thesis sec. 3.2.4)."""
    x = float(tilt_deg)
    xy_panel = [(-1, -1), (0, +1), (+1, -1)]      # +-x panels: (s_az, s_el)
    yz_panel = [(-1, +1), (0, -1), (+1, +1)]      # +-y panels: the triangle inverted
    normals = []
    for phi_p, pattern in ((0, xy_panel), (90, yz_panel), (180, xy_panel), (270, yz_panel)):
        for s_az, s_el in pattern:
            az, el = np.radians(phi_p + s_az * x), np.radians(s_el * x)
            normals.append([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    normals += [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]
    return np.array(normals)


def plain_numpy(r_sat, r_sun, R_ecef_from_body, frames, aperture, refl):
    """Return (N, K) albedo irradiance, plain numpy, one epoch at a time over the full grid."""
    normals = refl.normals_ecef.reshape(-1, 3)
    centres = refl.centres_ecef_m.reshape(-1, 3)
    weights = refl.weights_m2.reshape(-1)
    out = np.zeros((len(r_sat), len(frames)))
    for n in range(len(r_sat)):
        s = r_sun[n] / np.linalg.norm(r_sun[n])
        v = r_sat[n] - centres
        d = np.linalg.norm(v, axis=1)
        cos_out = np.einsum("ij,ij->i", v, normals) / d
        cos_in = normals @ s
        w = E_SUN_W_M2 / np.pi * weights * np.maximum(cos_in, 0) * np.maximum(cos_out, 0) / d ** 2
        e_body = (-v / d[:, None]) @ R_ecef_from_body[n]          # rows: R^T e
        for k, f in enumerate(frames):
            out[n, k] = np.sum(w * aperture.response(e_body @ f.T))
    return out


def main():
    t0 = time.perf_counter()
    epochs = Epochs.range("2016-07-02T00:00:00Z", 86400, 1.0)
    geo = compute_geometry(epochs=epochs)
    R_ecef_from_body = geo.R_ecef_from_body
    t_geom = time.perf_counter() - t0

    frames = np.stack([diode_frame(n) for n in tilt_normals(20)])
    aperture = WellAperture.design(70)
    refl = ReflectivityMap.toms2005()
    refl.weights_m2, refl.normals_ecef   # noqa: B018  (build the cached map geometry outside the timing)

    # Warm-up: compiles the Dr.Jit kernel once (cached afterwards on disk and in memory).
    diode_irradiance(geo.r_sat_ecef_m[:64], geo.r_sun_ecef_m[:64], R_ecef_from_body[:64], frames, aperture)

    t1 = time.perf_counter()
    res = diode_irradiance(geo.r_sat_ecef_m, geo.r_sun_ecef_m, R_ecef_from_body, frames, aperture,
                           map=refl, eclipse="cylindrical")
    t_fast = time.perf_counter() - t1
    assert res.direct_w_m2.shape == (86400, 14) and np.all(np.isfinite(res.albedo_w_m2))

    pick = np.linspace(0, 86399, PLAIN_EPOCHS).astype(int)
    t2 = time.perf_counter()
    plain = plain_numpy(geo.r_sat_ecef_m[pick], geo.r_sun_ecef_m[pick], R_ecef_from_body[pick], frames,
                        aperture, refl)
    t_plain = (time.perf_counter() - t2) / PLAIN_EPOCHS * 86400
    scale = max(np.abs(plain).max(), 1e-30)
    agree = float(np.abs(plain - res.albedo_w_m2[pick]).max() / scale)

    print(f"geometry (SGP4, frames, Sun, tumble), 86400 epochs: {t_geom:.2f} s")
    print(f"diode_irradiance, 86400 epochs x 14 diodes, direct + albedo: {t_fast:.2f} s (target {TARGET_S} s)")
    print(f"plain full-grid per-epoch numpy, extrapolated from {PLAIN_EPOCHS} epochs: {t_plain:.1f} s")
    print(f"speed-up: {t_plain / t_fast:.1f}x; max |difference| / max albedo on those epochs: {agree:.2e}")
    print(f"albedo: mean {res.albedo_w_m2.mean():.3f} W/m^2, max {res.albedo_w_m2.max():.2f} W/m^2; "
          f"direct max {res.direct_w_m2.max():.1f} W/m^2; sunlit fraction {res.illuminated_fraction.mean():.3f}")
    print(json.dumps(dict(benchmark="bench_albedo", epochs=86400, diodes=14, map="TOMS 2005",
                          response="WellAperture.design(70)", seconds=round(t_fast, 3), target_s=TARGET_S,
                          ratio_to_target=round(t_fast / TARGET_S, 3), plain_numpy_s=round(t_plain, 2),
                          plain_over_fast=round(t_plain / t_fast, 2), plain_epochs_timed=PLAIN_EPOCHS,
                          max_rel_difference_vs_plain=agree, geometry_s=round(t_geom, 3))))


if __name__ == "__main__":
    main()
