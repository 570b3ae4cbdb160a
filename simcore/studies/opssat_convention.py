"""OPS-SAT's attitude quaternion convention and time scale, shown with the shipped 2020 week.

``python -m simcore.studies.opssat_convention`` prints three tables (docs/attitude_history.md):

1. PD3 and PD6 fitted by the cosine law (:func:`simcore.radiometry.normal_fit.fit_normal`) on the sunlit
   samples where the diode reads > :data:`FIT_MIN_READING` of full Sun (the direct Sun dominates there:
   the Earth's albedo adds at most ~0.14), under each of the four conventions (scalar first or last,
   ``R`` or ``R^T``). The right one gives axis-aligned unit-scale normals with a small residual.
2. Under that convention, the same fit with the quaternion's inertial frame taken as GCRF, EME2000, TOD or
   TEME (the Sun's direction differs by up to 0.3 deg between them).
3. The time stamps taken as UTC shifted by -69 .. +69 s (TT - UTC = 69.184 s, TAI - UTC = 37 s in 2020):
   the Sun and the orbit at ``stamp - shift``: where the model says the spacecraft is in the Earth's
   shadow but a diode reads > 0.2, or says sunlit with the diode facing the Sun (predicted > 0.3) and it
   reads < 0.02, the shift is wrong. A 9-16-day-old TLE places the spacecraft within a few seconds
   along track, so such counts resolve shifts of tens of seconds. The cosine-law fit refitted at each shift
   is printed beside them: it does not decide (the Sun turns only 0.015 deg in 37 s, and the shift changes
   which samples count as sunlit, so the residuals are not of the same samples); the eclipse edges do.
"""
import argparse
import json

import numpy as np

from simcore.environment import eclipse, frames, sun
from simcore.environment.attitude import quat_conjugate
from simcore.environment.orbit import Orbit
from simcore.environment.telemetry import (OPSSAT_ATTITUDE, OPSSAT_PD, OPSSAT_TLE, read_opssat_attitude,
                                           read_opssat_pd)
from simcore.radiometry.normal_fit import convention_fits, fit_normal, sun_in_body

FIT_MIN_READING = 0.2
SUNLIT_MIN = 0.999                   # visible fraction of the solar disc
SHIFTS_S = (-69.184, -37.0, -30.0, -10.0, -5.0, 0.0, 5.0, 10.0, 30.0, 37.0, 69.184)
FRAMES_TRIED = ("GCRF", "EME2000", "TOD", "TEME")
_KEY = {"GCRF": "gcrs", "EME2000": "eme2000", "TOD": "tod", "TEME": "teme"}


def axis_angle_deg(normal):
    """Return (angle in deg to the nearest body axis, that axis as '+X' .. '-Z')."""
    k = int(np.argmax(np.abs(normal)))
    sign = "+" if normal[k] > 0 else "-"
    return float(np.degrees(np.arccos(min(1.0, abs(normal[k]))))), sign + "XYZ"[k]


def load(pd_path=OPSSAT_PD, attitude_path=OPSSAT_ATTITUDE, tle_path=OPSSAT_TLE):
    """Return a dict of the week's arrays at the readings' epochs where the attitude is trusted."""
    pd = read_opssat_pd(pd_path)
    hist = read_opssat_attitude(attitude_path)
    ok = hist.trusted(pd.epochs)
    epochs = pd.epochs[np.flatnonzero(ok)]
    # the quaternion as recorded (frame_to_body: the history holds its conjugate), slerped to the readings
    q_recorded = quat_conjugate(hist.q_frame_at(epochs))
    return {"pd": pd, "history": hist, "keep": ok, "epochs": epochs, "q": q_recorded,
            "reading": pd.reading[ok], "usable": pd.usable[ok], "orbit": Orbit.from_file(tle_path)}


def sun_geometry(data, frame="EME2000", shift_s=0.0):
    """Return (unit satellite->Sun direction in ``frame`` (N, 3), illumination (N,)) at stamp - shift_s."""
    epochs = data["epochs"] + (-shift_s)
    r_sat = data["orbit"].propagate(epochs).r_gcrs_m
    r_sun = sun.sun_position_gcrs_m(epochs)
    d = r_sun - r_sat
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = np.einsum("nij,nj->ni", frames.R_between("gcrs", _KEY[frame], epochs), d)
    return d, eclipse.conical(r_sat, r_sun)


def evidence(data=None):
    """Return the three tables of the module docstring as a JSON-able dict."""
    data = load() if data is None else data
    out = {"samples": int(data["keep"].sum()), "left_out_untrusted_attitude": int((~data["keep"]).sum()),
           "conventions": {}, "frames": {}, "shifts": {}}
    s_eme, illum = sun_geometry(data, "EME2000")
    lit = illum >= SUNLIT_MIN
    for k, name in enumerate(data["pd"].names):
        y, use = data["reading"][:, k], data["usable"][:, k]
        mask = lit & use & (y > FIT_MIN_READING)
        rows = []
        for label, sf, d, fit in convention_fits(data["q"], s_eme, y, mask):
            ang, axis = axis_angle_deg(fit.normal)
            rows.append({"convention": label, "scalar_first": sf, "direction": d, "normal": fit.normal.round(4).tolist(),
                         "scale": round(fit.scale, 4), "nearest_axis": axis, "off_axis_deg": round(ang, 2),
                         "median_abs_residual": round(fit.median_abs_residual, 4), "n": fit.n})
        out["conventions"][name] = rows
        out["frames"][name] = {}
        for frame in FRAMES_TRIED:
            s, _ = sun_geometry(data, frame)
            fit = fit_normal(sun_in_body(data["q"], s, True, "frame_to_body"), y, mask)
            out["frames"][name][frame] = {"median_abs_residual": round(fit.median_abs_residual, 5),
                                          "rms_residual": round(fit.rms_residual, 5),
                                          "off_axis_deg": round(axis_angle_deg(fit.normal)[0], 3)}
    fits = {}
    for k, name in enumerate(data["pd"].names):
        y, use = data["reading"][:, k], data["usable"][:, k]
        fits[name] = fit_normal(sun_in_body(data["q"], s_eme, True, "frame_to_body"), y,
                                lit & use & (y > FIT_MIN_READING))
    for shift in SHIFTS_S:
        s, il = sun_geometry(data, "EME2000", shift)
        s_body = sun_in_body(data["q"], s, True, "frame_to_body")
        lit_in_shadow, dark_in_sun = 0, 0
        for k, name in enumerate(data["pd"].names):
            y, use = data["reading"][:, k], data["usable"][:, k]
            pred = fits[name].scale * np.clip(s_body @ fits[name].normal, 0, None)
            lit_in_shadow += int(np.count_nonzero(use & (il == 0) & (y > FIT_MIN_READING)))
            dark_in_sun += int(np.count_nonzero(use & (il >= SUNLIT_MIN) & (pred > 0.3) & (y < 0.02)))
        # the cosine-law fit itself, refitted at the shifted time: the Sun turns 1 deg/day in inertial axes, so it
        # hardly tells (37 s: 0.015 deg); the eclipse edges (7.6 km/s along track) do
        refit = {name: round(fit_normal(s_body, data["reading"][:, k], (il >= SUNLIT_MIN) & data["usable"][:, k]
                                        & (data["reading"][:, k] > FIT_MIN_READING)).median_abs_residual, 5)
                 for k, name in enumerate(data["pd"].names)}
        out["shifts"][f"{shift:+g}"] = {"lit_in_predicted_shadow": lit_in_shadow,
                                        "dark_in_predicted_sun": dark_in_sun, "total": lit_in_shadow + dark_in_sun,
                                        "refit_median_abs_residual": refit}
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m simcore.studies.opssat_convention", description=__doc__.split("\n")[0])
    p.add_argument("--json", action="store_true", help="print the tables as JSON")
    args = p.parse_args(argv)
    ev = evidence()
    if args.json:
        print(json.dumps(ev, indent=1))
        return 0
    print(f"OPS-SAT 2020 week: {ev['samples']} readings with a trusted attitude "
          f"({ev['left_out_untrusted_attitude']} left out: gap, jump or frozen attitude)")
    print("\n1. cosine-law fit under each convention (EME2000; sunlit; reading > 0.2)")
    for name, rows in ev["conventions"].items():
        for r in rows:
            print(f"  {name}  {r['convention']:<40} normal {r['normal']}  scale {r['scale']:.3f}  "
                  f"{r['off_axis_deg']:6.2f} deg off {r['nearest_axis']}  median|res| {r['median_abs_residual']:.4f}"
                  f"  n={r['n']}")
    print("\n2. the quaternion's frame (scalar first, v_body = R(q) v_inertial)")
    for name, rows in ev["frames"].items():
        print("  " + name + "  " + "  ".join(f"{f}: median|res| {r['median_abs_residual']:.5f} rms {r['rms_residual']:.5f}"
                                             for f, r in rows.items()))
    print("\n3. time stamps as UTC + shift: readings that contradict the predicted eclipse (PD3 + PD6)")
    for shift, r in ev["shifts"].items():
        print(f"  shift {shift:>8} s: {r['lit_in_predicted_shadow']:4d} lit in predicted shadow, "
              f"{r['dark_in_predicted_sun']:4d} dark in predicted Sun, total {r['total']:3d}; refitted median|res| "
              + ", ".join(f"{k} {v:.5f}" for k, v in r["refit_median_abs_residual"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
