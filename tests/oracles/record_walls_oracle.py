"""Record tests/oracles/walls_oracle_4277e88.py again: the retired wall tracer's numbers, traced anew.

The tracer (simcore/render/walls.py) is no longer in the tree. This script takes the whole package as it was at
commit 4277e88 from git (``git archive`` into a temporary folder), traces the oracle's cases there in a
subprocess (this same file with ``--trace``, the recording code of commit 0894aa2, which imports only that old
tree), and writes the data module from the JSON it returns. Run from a git checkout, any branch:

    .venv/bin/python tests/oracles/record_walls_oracle.py OUTDIR                      # every case (~11 min, 2 cores)
    .venv/bin/python tests/oracles/record_walls_oracle.py OUTDIR --cases fov70        # cases whose name has "fov70"
    .venv/bin/python tests/oracles/record_walls_oracle.py OUTDIR --reformat           # no tracing: the stored file

It writes OUTDIR/walls_oracle_4277e88.py (never into the checkout unless asked to) and then compares it with the
stored module: the whole text when every case was traced, else each traced case's values; exit status 1 when
they differ. ``--reformat`` writes the stored module's own numbers through the same formatter (a check of the
formatter alone). Values are written with 10 significant digits.
"""
import argparse
import json
import os
import pprint
import runpy
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

COMMIT = "4277e88"                           # the commit whose simcore/render/walls.py traced the oracle
HERE = Path(__file__).resolve().parent
STORED = HERE / "walls_oracle_4277e88.py"
WIDTH = 117                                  # the data module's line width

HEADER = '''"""The retired wall tracer's numbers: the independent oracle of the aperture study's wall reflections.

Recorded by tests/oracles/record_walls_oracle.py (the recorder of commit 0894aa2, restored: it traces in a copy
of the tree at commit 4277e88) with simcore/render/walls.py at commit 4277e88 (Mitsuba variant llvm_ad_mono, 2 CPU
cores), before that separate tracer was removed for the renderer's path tracer
(simcore.studies.aperture.wall_response). It followed rays from uniform points on the well's opening along the
beam through BSDF-sampled wall and floor reflections to the diode (the adjoint of the path tracer, which starts on
the diode), with its own random numbers (PCG32), Russian roulette and estimator. Each case names its rays per
direction and seed ("provenance"); values are the response to a unit collimated beam (a bare diode facing it
reads 1) with standard errors (the sample standard deviation over the rays / sqrt(rays)).

Cases (materials are the Mitsuba BSDF dicts the old tracer used, two-sided):

* ``cut <material> phi <phi>``: the section-1 cuts of notebooks/aperture_study.ipynb, tilt25_fov75 well
  (WellAperture.design(75.0)), floor plate of the walls' material; ``response`` = exact overlap +
  ``reflected`` (``response_se`` = ``reflected_se``: the overlap has no noise).
* ``series rho <rho>``: Lambertian walls and floor (section 3), wall axis, no Russian roulette.
* ``albedo table``: A.wall_albedo_effect rows (one orbit at 60 s, tilt25_fov75, diode 0 dead), the
  table traced in 16 independent batches (seeds 0..15); ``*_se`` their standard deviation / 4.
* ``fov70 <material> black floor``: tests/render/test_reflected.py's well (WellAperture.design(70.0)), black
  floor, four directions ``d_diode`` (diode frame).
"""
'''


# --------------------------------------------------------------------------- tracing (runs in the old tree)

def trace(path, wanted):
    """Trace the cases whose names contain one of ``wanted`` (all when empty) with the tree of commit 4277e88 on
    sys.path, and write them as JSON to ``path``: the recording of tests/oracles/record_walls_oracle.py at 0894aa2."""
    import time

    import numpy as np

    from scenes.config import SatelliteConfig
    from simcore import _llvm
    from simcore.environment.geometry import one_orbit_geometry
    from simcore.render.walls import TabulatedResponse, WallMaterial, trace_well
    from simcore.shapes.aperture import WellAperture
    from simcore.studies import aperture as A

    CUT_RAYS, SERIES_RAYS, TABLE_RAYS, TABLE_BATCHES, REFL_RAYS = 1_000_000, 500_000, 25_000, 16, 4_000_000

    def _l(x):
        return np.asarray(x, float).tolist()

    def _variant():
        return _llvm.import_mitsuba().variant()

    def want(name):
        return not wanted or any(w in name for w in wanted)

    out = {"provenance": f"simcore/render/walls.py at commit {COMMIT}", "cases": {}}
    cfg = SatelliteConfig.load("tilt25_fov75", dead=[0])
    ap = cfg.apertures[0]
    theta = np.concatenate([np.arange(0.0, 60.0, 3.0), np.arange(60.0, 90.0, 0.5)])
    t0 = time.perf_counter()
    # section 1: cuts along the wall axis and the diagonal (A.angular_cuts: trace_well defaults)
    for mat in (WallMaterial.matte_black(0.04), WallMaterial.aluminium(0.2)):
        for phi in (0.0, 45.0):
            name = f"cut {mat.label} phi {phi:g}"
            if not want(name):
                continue
            d = A.cut_directions(theta, phi)
            tr = trace_well(ap, d, mat, rays=CUT_RAYS, seed=0)
            out["cases"][name] = dict(
                well="tilt25_fov75", material=mat.bsdf_dict(), phi_deg=phi, theta_deg=_l(theta), rays=CUT_RAYS,
                seed=0, reflective_floor=True, rr_depth=8, max_bounces=64, variant=_variant(),
                overlap=_l(ap.response(d)), reflected=_l(tr.reflected), reflected_se=_l(tr.reflected_se),
                response=_l(tr.response_cv), response_se=_l(tr.response_cv_se))
            print(f"{name}: {time.perf_counter() - t0:.0f} s", flush=True)
    # section 3: reflectance series (A.reflectance_series: no Russian roulette)
    d = A.cut_directions(theta, 0.0)
    for rho in (0.05, 0.2, 0.5, 0.9):
        name = f"series rho {rho:g}"
        if not want(name):
            continue
        mat = WallMaterial.diffuse(rho)
        tr = trace_well(ap, d, mat, rays=SERIES_RAYS, seed=0, rr_depth=10_000)
        out["cases"][name] = dict(
            well="tilt25_fov75", material=mat.bsdf_dict(), phi_deg=0.0, theta_deg=_l(theta), rays=SERIES_RAYS,
            seed=0, reflective_floor=True, rr_depth=10_000, max_bounces=64, variant=_variant(),
            overlap=_l(ap.response(d)), reflected=_l(tr.reflected), reflected_se=_l(tr.reflected_se),
            response=_l(tr.response_cv), response_se=_l(tr.response_cv_se))
        print(f"{name}: {time.perf_counter() - t0:.0f} s", flush=True)
    # section 3: albedo and direct Sun along one orbit (A.wall_albedo_effect), in independent batches (seeds)
    # so that every row gets a standard error: the row is linear in the table, the pooled value is the mean
    if want("albedo table"):
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
    # tests/render/test_reflected.py: FOV 70 design, walls of bare Al (GGX alpha 0.1), black floor
    ap70 = WellAperture.design(70.0)
    zen, az = np.radians([30, 50, 65, 75]), np.radians([0, 0, 30, 45])
    d = np.stack([np.sin(zen) * np.cos(az), np.sin(zen) * np.sin(az), np.cos(zen)], 1)
    for mat in (WallMaterial.aluminium(0.1), WallMaterial.diffuse(0.5)):
        name = f"fov70 {mat.label} black floor"
        if not want(name):
            continue
        tr = trace_well(ap70, d, mat, rays=REFL_RAYS, seed=1, reflective_floor=False)
        out["cases"][name] = dict(
            well="WellAperture.design(70.0)", material=mat.bsdf_dict(), d_diode=d.tolist(), rays=REFL_RAYS, seed=1,
            reflective_floor=False, rr_depth=8, max_bounces=64, variant=_variant(), reflected=_l(tr.reflected),
            reflected_se=_l(tr.reflected_se))
        print(f"{name}: {time.perf_counter() - t0:.0f} s", flush=True)
    with open(path, "w") as fh:
        json.dump(out, fh, indent=1)


# --------------------------------------------------------------------------- the data module (current tree)

def _number(x):
    """A number as the module writes it: ints as they are, floats to 10 significant digits (zero as 0.0)."""
    if isinstance(x, bool):
        return repr(x)
    if isinstance(x, int):
        return str(x)
    return "0.0" if x == 0 else f"{x:.10g}"


def _scalar(x):
    return repr(x) if isinstance(x, (str, bool)) else _number(x)


def _flat_list(prefix, values):
    """``prefix[v0, v1, ...],`` wrapped at WIDTH, continuation lines indented by 12."""
    items = [_number(v) for v in values]
    tokens = [f"{s}," for s in items[:-1]] + [f"{items[-1]}],"] if items else ["],"]
    lines, line = [], prefix + "[" + tokens[0]
    for tok in tokens[1:]:
        if len(line) + 1 + len(tok) > WIDTH:
            lines.append(line)
            line = " " * 12 + tok
        else:
            line += " " + tok
    lines.append(line)
    return lines


def _value(prefix, key, value):
    """The lines of ``"key": value,`` at ``prefix`` (the key's indentation)."""
    head = f"{prefix}{json.dumps(key)}: "
    if isinstance(value, dict):
        text = pprint.pformat(value, width=WIDTH - len(head), sort_dicts=False).split("\n")
        text[-1] += ","
        return [head + text[0]] + [" " * len(head) + t for t in text[1:]]
    if isinstance(value, list) and value and isinstance(value[0], list):
        return [head + "["] + [f"{prefix}    [{', '.join(_number(v) for v in row)}]," for row in value] + \
            [f"{prefix}],"]
    if isinstance(value, list) and value and isinstance(value[0], dict):
        lines = [head + "["]
        for row in value:
            lines.append(f"{prefix}    {{")
            for k, v in row.items():
                lines += _value(prefix + " " * 8, k, v)
            lines.append(f"{prefix}    }},")
        return lines + [f"{prefix}],"]
    if isinstance(value, list):
        return _flat_list(head, value)
    return [head + _scalar(value) + ","]


def _provenance(top, case):
    if "rays_per_node" in case:
        return f"{top}, rays {case['rays_per_node']} per node, seeds {case['seeds'][0]}..{case['seeds'][-1]}"
    return f"{top}, rays {case['rays']}, seed {case['seed']}"


def module_text(recorded):
    """Return the data module's text for ``recorded`` (the JSON that ``trace`` writes)."""
    lines = HEADER.rstrip("\n").split("\n") + ["", "ORACLE = {"]
    for name, case in recorded["cases"].items():
        lines.append(f"    {json.dumps(name)}: {{")
        lines.append(f'        "provenance": {json.dumps(_provenance(recorded["provenance"], case))},')
        for k, v in case.items():
            lines += _value(" " * 8, k, v)
        lines.append("    },")
    return "\n".join(lines + ["}"]) + "\n"


def _stored_as_recorded():
    """The stored module's cases in the shape ``trace`` writes (provenance back at the top)."""
    oracle = runpy.run_path(str(STORED))["ORACLE"]
    cases = {name: {k: v for k, v in case.items() if k != "provenance"} for name, case in oracle.items()}
    return {"provenance": f"simcore/render/walls.py at commit {COMMIT}", "cases": cases}


def _old_tree(folder):
    """Extract the package at COMMIT (git archive) into ``folder``; return its path."""
    root = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=HERE, capture_output=True, text=True,
                          check=True).stdout.strip()
    tar = Path(folder) / "tree.tar"
    subprocess.run(["git", "archive", "-o", str(tar), COMMIT, "simcore", "scenes", "estimators"], cwd=root,
                   check=True)
    tree = Path(folder) / COMMIT
    with tarfile.open(tar) as t:
        t.extractall(tree, filter="data")
    return tree


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir", help="folder for walls_oracle_4277e88.py (and the traced JSON)")
    ap.add_argument("--cases", nargs="*", default=[], help="trace only the cases whose name contains one of these")
    ap.add_argument("--reformat", action="store_true", help="no tracing: write the stored numbers")
    ap.add_argument("--trace", metavar="JSON", help=argparse.SUPPRESS)    # inside the old tree
    args = ap.parse_args(argv)
    if args.trace:
        trace(args.trace, args.cases)
        return 0
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    stored = _stored_as_recorded()
    if args.reformat:
        recorded = stored
    else:
        with tempfile.TemporaryDirectory() as tmp:
            tree = _old_tree(tmp)
            env = dict(os.environ, PYTHONPATH=str(tree))
            subprocess.run([sys.executable, str(Path(__file__).resolve()), str(out), "--trace",
                            str(out / "walls_oracle.json"), "--cases", *args.cases], cwd=tree, env=env, check=True)
        recorded = json.loads((out / "walls_oracle.json").read_text())
    text = module_text(recorded)
    target = out / STORED.name
    target.write_text(text)
    if set(recorded["cases"]) == set(stored["cases"]):
        same = text == STORED.read_text()
        print(f"{target}: {'identical to' if same else 'DIFFERS from'} {STORED}")
        return 0 if same else 1
    # a subset: each traced case's values (as written, 10 digits) against the stored ones
    new = runpy.run_path(str(target))["ORACLE"]
    old = runpy.run_path(str(STORED))["ORACLE"]
    bad = [name for name in new if new[name] != old[name]]
    for name in new:
        print(f"{name}: {'DIFFERS' if name in bad else 'equal to the stored case'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
