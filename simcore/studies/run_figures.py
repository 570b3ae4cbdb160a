"""Figures of one run file: estimator error plots that a reader can compare and understand alone.

Every plot of a run shares one y range (:func:`simcore.plots.shared_error_ylim`) and says in its title
what produced it: the configuration, the dead diodes, the estimator in words, the sensor noise and the
time span. By default the figures go into a folder beside the run file, never the current directory.
"""
import os

import numpy as np

# The thesis' estimators (sec. 4.3, simcore.pipeline.evaluate.THESIS_ESTIMATORS) in words.
ESTIMATOR_WORDS = {
    "pinv": "pseudoinverse (least squares, eq. 4.29)",
    "wls": "weighted least squares",
    "albedo_sun": "Albedo-Sun",
    "sun_albedo_sun_wls": "Sun-Albedo-Sun, started from weighted least squares",
    "sun_albedo_sun": "Sun-Albedo-Sun, started from Albedo-Sun",
    "smart_select": "smart selection of opposite diodes",
}


def default_plot_folder(run_path):
    """Return the folder for a run file's figures: ``<run without .nc>_plots`` beside it."""
    return os.path.splitext(os.fspath(run_path))[0] + "_plots"


def span_words(ds):
    """Return the run's time span in words: first and last epoch (UTC) and its length."""
    t0, t1 = (np.datetime_as_string(ds["time"].values[i], unit="s") for i in (0, -1))
    length_s = float(ds["t_s"].values[-1] - ds["t_s"].values[0])
    length = f"{length_s / 3600:.2f} h" if length_s >= 3600 else f"{length_s:.0f} s"
    return f"{t0}Z .. {t1}Z ({length})"


def error_plot_title(ds, name, noise):
    """Return the two-line title of estimator ``name``'s error plot for run Dataset ``ds``."""
    dead = np.flatnonzero(ds["dead"].values).tolist()
    dead_words = f"dead diodes {', '.join(map(str, dead))}" if dead else "no dead diode"
    return (f"{ds.attrs.get('configuration', '?')}, {dead_words}: {ESTIMATOR_WORDS.get(name, name)}\n"
            f"{'with sensor noise (shot, Johnson)' if noise else 'noise-free sensor chain'}, {span_words(ds)}")


def write_error_plots(ds, errs, sunlit, folder, *, noise):
    """Write one PNG per estimator into ``folder``; return [(path, Figure)], all with one y range."""
    from simcore.plots import plot_estimator_error, shared_error_ylim
    os.makedirs(folder, exist_ok=True)
    ylim = shared_error_ylim({k: e["angle_deg"] for k, e in errs.items()}, sunlit)
    t = ds["t_s"].values
    out = []
    for name, e in errs.items():
        path = os.path.join(folder, f"error_{name}.png")
        fig = plot_estimator_error(t, e["angle_deg"], sunlit=sunlit, title=error_plot_title(ds, name, noise),
                                   path=path, ylim=ylim)
        out.append((path, fig))
    return out
