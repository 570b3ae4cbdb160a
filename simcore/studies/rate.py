"""The thesis' rate question: how good is the body rate the controller gets, against its requirement?

Haave (2016) sec. 3.1.2: the only requirement known for the gyro is Westgard's (2015) controller
simulation (1 s steps): the largest rate noise density it could handle was
:data:`REQUIREMENT_DEG_S_RTHZ` = 0.0002 deg/s/sqrt(Hz). Every gyro of the thesis' tables is
12-150x noisier than that on its data sheet; this study measures what the estimated rate's error
is in the MEKF (:func:`simcore.pipeline.evaluate_attitude.run_mekf`), per gyro:

- raw: the gyro's reading minus the true mean rate over each step (noise, turn-on bias, its
  temperature drift, scale and cross-axis errors);
- filtered: the reading less the MEKF's bias estimate (what the controller would be given);
- averaged: the filtered error averaged over windows of T seconds (non-overlapping blocks), as a
  controller that low-passes its rate input would see it.

A white noise of density N averaged over T has rms N / sqrt(T) (:func:`white_noise_rms`; the
convention of the filter's sigma_v and of the data sheets' angle random walk); the requirement,
read the same way, is :data:`REQUIREMENT_DEG_S_RTHZ` / sqrt(T). The figure draws each gyro's rms
error against T beside that line; a gyro meets the requirement at T where its curve lies below.

``sunsim attitude-study --rate RUN.nc`` writes ``rate.md``, ``rate_results.json`` and
``rate_error.png`` into the page folder from one run file (the default orbit: ``sunsim run``).
"""
import json
import os

import numpy as np

from simcore.plots import plot_rate_error

REQUIREMENT_DEG_S_RTHZ = 0.0002      # Haave (2016) sec. 3.1.2, from Westgard (2015): 1 s steps
WINDOWS_S = (1, 2, 5, 10, 20, 60, 120, 300, 600)
GYROS = ("MPU-3300", "IMU160", "BMG160", "L3G4200D")


def white_noise_rms(density, window_s):
    """Return the rms of white noise of density ``density`` (unit/sqrt(Hz)) averaged over ``window_s`` seconds."""
    return np.asarray(density, dtype=float) / np.sqrt(np.asarray(window_s, dtype=float))


def averaged_rms(err, dt_s, window_s):
    """Return the rms per axis (over axes and blocks) of ``err`` (N, 3) averaged over non-overlapping windows.

    Each window holds round(window_s / dt_s) consecutive samples (at least one); the last partial
    block and blocks with a NaN sample are dropped. NaN when no block is left.
    """
    e = np.asarray(err, dtype=float)
    m = max(int(round(float(window_s) / float(dt_s))), 1)
    nb = e.shape[0] // m
    if nb == 0:
        return float("nan")
    blocks = e[:nb * m].reshape(nb, m, -1).mean(axis=1)
    blocks = blocks[np.all(np.isfinite(blocks), axis=1)]
    return float(np.sqrt(np.mean(blocks ** 2))) if blocks.size else float("nan")


def rate_errors(res, dt_s, windows=WINDOWS_S):
    """Return the rate errors (deg/s) of one :func:`run_mekf` result ``res``: raw, filtered, averaged over ``windows``.

    Over the epochs from the filter's start (its bias estimate exists); rms per axis.
    """
    started = np.all(np.isfinite(res["bias_est"]), axis=1)
    raw = np.degrees(res["omega_meas"] - res["omega_true"])[started]
    filt = np.degrees(res["omega_meas"] - res["bias_est"] - res["omega_true"])[started]
    avg = [averaged_rms(filt, dt_s, w) for w in windows]
    return {"raw_deg_s": float(np.sqrt(np.mean(raw ** 2))), "filtered_deg_s": float(np.sqrt(np.mean(filt ** 2))),
            "windows_s": list(windows), "averaged_deg_s": avg,
            "equivalent_density_deg_s_rthz": [a * np.sqrt(w) for a, w in zip(avg, windows)]}


def rate_study(run_path, page_folder, *, gyros=GYROS, seeds=(0,), log=print):
    """Run the MEKF per gyro and seed on ``run_path`` and write the rate section into ``page_folder``; return its path."""
    from simcore.pipeline.evaluate_attitude import run_mekf
    from simcore.pipeline.runfile import open_run
    from simcore.sensor.gyro import gyro_spec
    specs = {g: gyro_spec(g) for g in gyros}                      # names checked before any work
    ds = open_run(run_path)
    dt = float(np.median(np.diff(ds["t_s"].values)))
    rows = {}
    for g in gyros:
        per_seed = []
        for seed in seeds:
            log(f"  {g} seed {seed}")
            per_seed.append(rate_errors(run_mekf(ds, run_path, gyro=g, seed=int(seed)), dt))
        rows[g] = {k: (np.mean([r[k] for r in per_seed], axis=0).tolist() if isinstance(per_seed[0][k], list)
                       else float(np.mean([r[k] for r in per_seed])))
                   for k in per_seed[0]}
        rows[g]["data_sheet_density_deg_s_rthz"] = float(np.degrees(specs[g].noise_density_rad_s_rthz))
    os.makedirs(page_folder, exist_ok=True)
    result = {"run": os.path.basename(run_path), "configuration": ds.attrs.get("configuration"), "seeds": list(seeds),
              "requirement_deg_s_rthz": REQUIREMENT_DEG_S_RTHZ, "gyros": rows}
    with open(os.path.join(page_folder, "rate_results.json"), "w") as fh:
        json.dump(result, fh, indent=1)
    plot_rate_error(rows, REQUIREMENT_DEG_S_RTHZ, os.path.join(page_folder, "rate_error.png"))
    path = os.path.join(page_folder, "rate.md")
    with open(path, "w") as fh:
        fh.write(rate_page(result))
    return path


def rate_page(result):
    """Return the Markdown of the rate section from its results (``rate_results.json``)."""
    req = result["requirement_deg_s_rthz"]
    rows = result["gyros"]
    w = rows[next(iter(rows))]["windows_s"]
    i60 = w.index(60) if 60 in w else len(w) - 1
    out = ["# The estimated body rate against the thesis' requirement (sunsim attitude-study --rate)", "",
           f"Run `{result['run']}` ({result['configuration']}, the default orbit of `sunsim run`), MEKF of "
           f"`sunsim estimate --filter mekf` per gyro, seeds {result['seeds']} (mean). Requirement: the largest rate "
           f"noise density Westgard's (2015) controller handled, {req} deg/s/sqrt(Hz) at 1 s steps (Haave 2016 sec. "
           f"3.1.2); averaged over T seconds that is {req} / sqrt(T) deg/s. Errors are rms per axis from the filter's "
           "start (sunlit and eclipse); the computation is simcore/studies/rate.py, tested against white noise "
           "averaged over a window (tests/studies/test_rate.py).", "",
           "| gyro | data sheet density [deg/s/sqrt(Hz)] | raw [deg/s] | filtered [deg/s] | "
           f"averaged {w[i60]:g} s [deg/s] | requirement at {w[i60]:g} s [deg/s] | factor over it |",
           "|---|---|---|---|---|---|---|"]
    for g, r in rows.items():
        need = req / np.sqrt(w[i60])
        out.append(f"| {g} | {r['data_sheet_density_deg_s_rthz']:g} | {r['raw_deg_s']:.4f} | {r['filtered_deg_s']:.4f} "
                   f"| {r['averaged_deg_s'][i60]:.5f} | {need:.6f} | {r['averaged_deg_s'][i60] / need:.0f} |")
    factor = {g: [a / (req / np.sqrt(t)) for a, t in zip(r["averaged_deg_s"], w)] for g, r in rows.items()}
    best = min(rows, key=lambda g: factor[g][i60])
    meets = [g for g in rows if min(factor[g]) <= 1.0]
    lo, hi = min(min(f) for f in factor.values()), max(max(f) for f in factor.values())
    out += ["", "![rate error](rate_error.png)", "",
            "In words: " + ("no listed gyro gives the controller the rate it needs, raw, filtered or averaged over any "
                            "window up to {:g} s: the error lies {:.0f} to {:.0f} times above the requirement's line. "
                            .format(w[-1], lo, hi) if not meets else
                            f"{', '.join(meets)} reach the requirement's line at some window. ") +
            "The bias the MEKF removes is most of the raw error; what is left is the gyro's own noise and the residual "
            "of its bias drift (the temperature cycle of the orbit). Averaging lowers it about as 1 / sqrt(T) while "
            "the white noise dominates, then more slowly (the dotted lines are each data sheet's white noise alone). "
            f"The best at {w[i60]:g} s is the {best}, {factor[best][i60]:.0f} times above the line. Either the "
            "controller is made tolerant of a rate noise some hundred times the one it was designed for, or it is fed "
            "a better rate (a better gyro, or the attitude filter's rate over long windows).", ""]
    return "\n".join(out)
