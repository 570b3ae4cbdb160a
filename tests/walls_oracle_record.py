"""Record the old wall tracer's numbers (simcore/render/walls.py at commit 4277e88) as the independent oracle
of the aperture study's wall reflections, before that tracer is retired for the renderer's path tracer.

Writes one JSON file (argument 1) with the cases of notebooks/aperture_study.ipynb (section 1 cuts, section 3
reflectance series and albedo table) and of tests/test_reflected.py's well-walls comparison; every value with
its standard error, the rays per direction, the seed and the Mitsuba variant. Run from the repository root:

    .venv/bin/python tests/walls_oracle_record.py /tmp/walls_oracle.json
"""
import json
import subprocess
import sys
import time

import numpy as np

from scenes.config import SatelliteConfig
from simcore.environment.geometry import one_orbit_geometry
from simcore.render.walls import TabulatedResponse, WallMaterial, trace_well
from simcore.shapes.aperture import WellAperture
from simcore.studies import aperture as A

CUT_RAYS, SERIES_RAYS, TABLE_RAYS, TABLE_BATCHES, REFL_RAYS = 1_000_000, 500_000, 25_000, 16, 4_000_000


def _l(x):
    return np.asarray(x, float).tolist()


def main(path):
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    out = {"provenance": f"simcore/render/walls.py at commit {commit}", "cases": {}}
    cfg = SatelliteConfig.load("tilt25_fov75", dead=[0])
    ap = cfg.apertures[0]
    theta = np.concatenate([np.arange(0.0, 60.0, 3.0), np.arange(60.0, 90.0, 0.5)])
    t0 = time.perf_counter()
    # section 1: cuts along the wall axis and the diagonal (A.angular_cuts: trace_well defaults)
    for mat in (WallMaterial.matte_black(0.04), WallMaterial.aluminium(0.2)):
        for phi in (0.0, 45.0):
            d = A.cut_directions(theta, phi)
            tr = trace_well(ap, d, mat, rays=CUT_RAYS, seed=0)
            out["cases"][f"cut {mat.label} phi {phi:g}"] = dict(
                well="tilt25_fov75", material=mat.bsdf_dict(), phi_deg=phi, theta_deg=_l(theta), rays=CUT_RAYS,
                seed=0, reflective_floor=True, rr_depth=8, max_bounces=64, variant=_variant(),
                overlap=_l(ap.response(d)), reflected=_l(tr.reflected), reflected_se=_l(tr.reflected_se),
                response=_l(tr.response_cv), response_se=_l(tr.response_cv_se))
            print(f"cut {mat.label} phi {phi:g}: {time.perf_counter() - t0:.0f} s", flush=True)
    # section 3: reflectance series (A.reflectance_series: no Russian roulette)
    d = A.cut_directions(theta, 0.0)
    for rho in (0.05, 0.2, 0.5, 0.9):
        mat = WallMaterial.diffuse(rho)
        tr = trace_well(ap, d, mat, rays=SERIES_RAYS, seed=0, rr_depth=10_000)
        out["cases"][f"series rho {rho:g}"] = dict(
            well="tilt25_fov75", material=mat.bsdf_dict(), phi_deg=0.0, theta_deg=_l(theta), rays=SERIES_RAYS,
            seed=0, reflective_floor=True, rr_depth=10_000, max_bounces=64, variant=_variant(),
            overlap=_l(ap.response(d)), reflected=_l(tr.reflected), reflected_se=_l(tr.reflected_se),
            response=_l(tr.response_cv), response_se=_l(tr.response_cv_se))
        print(f"series rho {rho:g}: {time.perf_counter() - t0:.0f} s", flush=True)
    # section 3: albedo and direct Sun along one orbit (A.wall_albedo_effect), in independent batches (seeds)
    # so that every row gets a standard error: the row is linear in the table, the pooled value is the mean
    geo = one_orbit_geometry(step_s=60.0)
    mats = (WallMaterial.matte_black(0.04), WallMaterial.diffuse(0.2), WallMaterial.aluminium(0.2))
    batches = []
    for b in range(TABLE_BATCHES):
        tables = {m.label: TabulatedResponse.trace(ap, m, theta_step_deg=3.0, phi_step_deg=9.0, rays=TABLE_RAYS,
                                                   seed=b) for m in mats}
        rows, _ = A.wall_albedo_effect(cfg, mats, geometry=geo, tables=tables)
        batches.append(rows)
        print(f"albedo batch {b}: {time.perf_counter() - t0:.0f} s", flush=True)
    table = []
    for i, row in enumerate(batches[0]):
        r = {"material": row["material"]}
        for k, v in row.items():
            if k == "material":
                continue
            vals = np.array([bt[i][k] for bt in batches])
            r[k] = float(vals.mean())
            r[k + "_se"] = float(vals.std(ddof=1) / np.sqrt(len(vals)))
        table.append(r)
    out["cases"]["albedo table"] = dict(
        config="tilt25_fov75", dead=[0], geometry="one_orbit_geometry(step_s=60.0)", theta_step_deg=3.0,
        phi_step_deg=9.0, rays_per_node=TABLE_RAYS * TABLE_BATCHES, batches=TABLE_BATCHES,
        seeds=list(range(TABLE_BATCHES)), reflective_floor=True, rr_depth=8, variant=_variant(),
        se="standard deviation over the batches / sqrt(batches)",
        materials={m.label: m.bsdf_dict() for m in mats}, rows=table)
    # tests/test_reflected.py: FOV 70 design, walls of bare Al (GGX alpha 0.1), black floor
    ap70 = WellAperture.design(70.0)
    zen, az = np.radians([30, 50, 65, 75]), np.radians([0, 0, 30, 45])
    d = np.stack([np.sin(zen) * np.cos(az), np.sin(zen) * np.sin(az), np.cos(zen)], 1)
    for mat in (WallMaterial.aluminium(0.1), WallMaterial.diffuse(0.5)):
        tr = trace_well(ap70, d, mat, rays=REFL_RAYS, seed=1, reflective_floor=False)
        out["cases"][f"fov70 {mat.label} black floor"] = dict(
            well="WellAperture.design(70.0)", material=mat.bsdf_dict(), d_diode=d.tolist(), rays=REFL_RAYS, seed=1,
            reflective_floor=False, rr_depth=8, max_bounces=64, variant=_variant(), reflected=_l(tr.reflected),
            reflected_se=_l(tr.reflected_se))
        print(f"fov70 {mat.label}: {time.perf_counter() - t0:.0f} s", flush=True)
    with open(path, "w") as fh:
        json.dump(out, fh, indent=1)


def _variant():
    from simcore import _llvm
    return _llvm.import_mitsuba().variant()


if __name__ == "__main__":
    main(sys.argv[1])
