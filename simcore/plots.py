"""Figures of a run: diode irradiance, estimator error, albedo cells, aperture response, coverage.

Every function takes plain numpy arrays (no renderer, no run object), builds a
:class:`matplotlib.figure.Figure` on its own Agg canvas (no pyplot state, the
user's backend is left alone), returns it, and writes it when ``path`` is given
(see :func:`save_figure`: ``.png`` at 150 dpi, ``.pdf``, or both for a path
without suffix).

Style follows the thesis' chapter 4 figures: time series of the angle error with
the centred Hanning-window (181 samples) mean and mean +- STD (figs. 4.6-4.17),
diode irradiance in W/m^2 (fig. 4.8), equal-area coverage maps in red / yellow /
green (figs. 3.7-3.13). Maps follow docs/conventions.md: row 0 is the SOUTH band,
column 0 the western-most cell.
"""
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import BoundaryNorm, ListedColormap, LogNorm, Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.patheffects import withStroke
from matplotlib.transforms import blended_transform_factory
from matplotlib.tri import Triangulation

from estimators.metrics import hanning_mean_std
from simcore.shapes.aperture import EQ415_CUTOFF_DEG

PNG_DPI = 150
COVERAGE_COLOURS = ("#d62728", "#ffd21f", "#2ca02c")  # red <= 2, yellow 3, green >= 4 (thesis figs. 3.7-3.13)
DIRECT_COLOUR = "#e08a00"   # sunlight
ALBEDO_COLOUR = "#1f5fa8"   # Earth-reflected light
UMBRA_COLOUR = "0.55"
PENUMBRA_COLOUR = "0.80"
_TIME_UNITS = {"s": 1.0, "min": 60.0, "h": 3600.0}


# ----------------------------------------------------------------------------- helpers

def _figure(width_in, height_in):
    """Return a new Figure with its own Agg canvas and constrained layout (no pyplot involved)."""
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path):
    """Write ``fig`` and return the list of written paths: ``.png`` (150 dpi), ``.pdf``, or both.

    A path without suffix (``out/irradiance``) writes ``out/irradiance.png`` and
    ``out/irradiance.pdf``. Parent folders are created.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == "":
        targets = [p.with_name(p.name + ".png"), p.with_name(p.name + ".pdf")]
    elif suffix in (".png", ".pdf"):
        targets = [p]
    else:
        raise ValueError(f"cannot tell the format of {str(path)!r}: end the path with .png or .pdf, "
                         f"or give it no suffix to write both")
    written = []
    for target in targets:
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.suffix.lower() == ".png":
            fig.savefig(target, dpi=PNG_DPI, metadata={"Software": "sunsim"})
        else:
            # no creation date: the same figure gives the same PDF bytes
            fig.savefig(target, metadata={"Creator": "sunsim", "CreationDate": None})
        written.append(target)
    return written


def _finish(fig, path):
    if path is not None:
        save_figure(fig, path)
    return fig


def _series(name, value, n=None):
    a = np.asarray(value, dtype=float)
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"({n},)" if n is not None else "(N,)"
        raise ValueError(f"{name} must be a 1-D time series {want}, got shape {a.shape}")
    return a


def _signals(name, value, n, k=None):
    """Return an (N, K) float array from (N, K) or (N,) input, checking N (and K)."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] != n or (k is not None and a.shape[1] != k):
        want = f"({n}, {k})" if k is not None else f"({n}, K)"
        raise ValueError(f"{name} must be diode signals {want} (time leads, one column per diode), "
                         f"got shape {np.shape(value)}")
    return a


def _time_axis(t_s, time_unit):
    """Return (t scaled, axis label) choosing s / min / h from the span unless ``time_unit`` is given."""
    if not np.any(np.isfinite(t_s)):
        raise ValueError("t_s has no finite time: give the sample times (N,) in seconds, N >= 1")
    if time_unit is None:
        span = float(np.nanmax(t_s) - np.nanmin(t_s))
        time_unit = "s" if span <= 1200.0 else ("min" if span <= 6 * 3600.0 else "h")
    if time_unit not in _TIME_UNITS:
        raise ValueError(f"time_unit must be one of {sorted(_TIME_UNITS)} or None (automatic), got {time_unit!r}")
    return t_s / _TIME_UNITS[time_unit], f"Time [{time_unit}]"


def _runs(mask):
    """Return (start, stop) index pairs (stop exclusive) of the runs of True in a 1-D bool array."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _shade(ax, x, mask, colour, alpha):
    """Shade the x spans where mask is True (edges half-way between samples); return True if any."""
    runs = _runs(mask)
    for i0, i1 in runs:
        left = x[i0] - 0.5 * (x[i0] - x[i0 - 1]) if i0 > 0 else x[i0]
        right = x[i1 - 1] + 0.5 * (x[i1] - x[i1 - 1]) if i1 < len(x) else x[i1 - 1]
        ax.axvspan(left, right, color=colour, alpha=alpha, lw=0, zorder=0)
    return bool(runs)


def _shade_illumination(ax, x, illumination):
    """Grey spans: umbra (illumination 0) darker, penumbra (0 < f < 1) lighter; return legend handles."""
    handles = []
    if illumination is None:
        return handles
    f = illumination
    umbra = np.isfinite(f) & (f <= 0.0)
    penumbra = np.isfinite(f) & (f > 0.0) & (f < 1.0 - 1e-9)
    if _shade(ax, x, umbra, UMBRA_COLOUR, 0.35):
        handles.append(Patch(color=UMBRA_COLOUR, alpha=0.35, lw=0, label="umbra"))
    if _shade(ax, x, penumbra, PENUMBRA_COLOUR, 0.45):
        handles.append(Patch(color=PENUMBRA_COLOUR, alpha=0.45, lw=0, label="penumbra"))
    return handles


# ----------------------------------------------------------------------------- diode irradiance

def plot_diode_irradiance(t_s, direct, albedo, *, direct_se=None, albedo_se=None, analytic_direct=None,
                          analytic_albedo=None, diode_names=None, illumination=None, time_unit=None,
                          title=None, path=None):
    """Return a Figure of the irradiance on each diode over time, W/m^2: direct Sun and Earth albedo.

    ``t_s`` (N,) seconds; ``direct``, ``albedo`` (N, K) rendered irradiance on each diode
    (W/m^2, power on the sensitive area / area); ``*_se`` (N, K) their Monte-Carlo standard
    errors, drawn as +-2 SE bands; ``analytic_*`` (N, K) the analytic check, drawn as thin
    dashed lines over the rendered ones; ``illumination`` (N,) the lit fraction of the Sun
    disc (0 umbra, 1 full Sun), shaded grey where below 1. With K <= 16 each diode gets its
    own small panel (shared axes); with more, two stacked panels (direct, albedo).
    ``time_unit``: 's', 'min', 'h' or None (chosen from the span).
    """
    t = _series("t_s", t_s)
    n = t.size
    dir_ = _signals("direct", direct, n)
    k = dir_.shape[1]
    alb = _signals("albedo", albedo, n, k)
    opt = {}
    for name, value in (("direct_se", direct_se), ("albedo_se", albedo_se),
                        ("analytic_direct", analytic_direct), ("analytic_albedo", analytic_albedo)):
        opt[name] = None if value is None else _signals(name, value, n, k)
    illum = None if illumination is None else _series("illumination", illumination, n)
    if diode_names is None:
        diode_names = [f"diode {i}" for i in range(k)]
    diode_names = [str(s) for s in diode_names]
    if len(diode_names) != k:
        raise ValueError(f"diode_names has {len(diode_names)} names for {k} diodes; give one name per column")
    x, xlabel = _time_axis(t, time_unit)

    parts = [("direct", dir_, opt["direct_se"], opt["analytic_direct"], DIRECT_COLOUR, "direct Sun"),
             ("albedo", alb, opt["albedo_se"], opt["analytic_albedo"], ALBEDO_COLOUR, "Earth albedo")]
    all_values = np.concatenate([a.ravel() for a in (dir_, alb, *(v for v in opt.values() if v is not None))])
    all_values = all_values[np.isfinite(all_values)]
    nonneg = all_values.size == 0 or all_values.min() >= 0.0

    if k <= 16:
        ncols = 1 if k == 1 else (2 if k <= 8 else 3)
        nrows = -(-k // ncols)
        fig = _figure(10.0 if ncols > 1 else 9.0, 1.0 + 1.75 * nrows if nrows > 1 else 4.5)
        axes = fig.subplots(nrows, ncols, sharex=True, sharey=True, squeeze=False).ravel()
        for i, ax in enumerate(axes):
            if i >= k:
                ax.set_axis_off()
                continue
            shade_handles = _shade_illumination(ax, x, illum)
            for _, y, se, ana, colour, _label in parts:
                if se is not None:
                    ax.fill_between(x, y[:, i] - 2 * se[:, i], y[:, i] + 2 * se[:, i], color=colour,
                                    alpha=0.25, lw=0, zorder=1)
                ax.plot(x, y[:, i], color=colour, lw=1.6, zorder=2)
                if ana is not None:
                    ax.plot(x, ana[:, i], color="k", lw=0.7, ls=(0, (4, 2.5)), zorder=3)
            ax.set_title(diode_names[i], fontsize=9, loc="left", pad=3)
            ax.grid(True, lw=0.4, alpha=0.5)
            ax.tick_params(labelsize=8)
            # the x labels of panels above an empty slot would otherwise be hidden by sharex
            if i + ncols >= k:
                ax.tick_params(labelbottom=True)
                ax.set_xlabel(xlabel, fontsize=10)
        if n > 1:
            axes[0].set_xlim(x[0], x[-1])
        if nonneg:
            axes[0].set_ylim(bottom=0.0)
        fig.supylabel("Irradiance on diode [W/m$^2$]", fontsize=10)
    else:
        fig = _figure(10.0, 7.0)
        axes = fig.subplots(2, 1, sharex=True)
        cmap = _diode_colours(k)
        for ax, (_, y, se, ana, _colour, label) in zip(axes, parts):
            shade_handles = _shade_illumination(ax, x, illum)
            for i in range(k):
                if se is not None:
                    ax.fill_between(x, y[:, i] - 2 * se[:, i], y[:, i] + 2 * se[:, i], color=cmap[i],
                                    alpha=0.2, lw=0, zorder=1)
                ax.plot(x, y[:, i], color=cmap[i], lw=1.1, zorder=2, label=diode_names[i])
                if ana is not None:
                    ax.plot(x, ana[:, i], color="k", lw=0.6, ls=(0, (4, 2)), zorder=3)
            ax.set_ylabel(f"{label}\nirradiance [W/m$^2$]")
            ax.grid(True, lw=0.4, alpha=0.5)
            if nonneg:
                ax.set_ylim(bottom=0.0)
        axes[-1].set_xlabel(xlabel)
        if n > 1:
            axes[0].set_xlim(x[0], x[-1])
        axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0),
                       fontsize=7, ncol=2 if k > 20 else 1, frameon=False)

    handles = []
    for _, y, se, ana, colour, label in parts:
        handles.append(Line2D([], [], color=colour if k <= 16 else "0.3", lw=1.4, label=f"{label} (rendered)"))
        if se is not None:
            handles.append(Patch(color=colour if k <= 16 else "0.3", alpha=0.25, lw=0, label=f"{label} $\\pm$2 SE"))
    if opt["analytic_direct"] is not None or opt["analytic_albedo"] is not None:
        handles.append(Line2D([], [], color="k", lw=0.7, ls=(0, (4, 2.5)), label="analytic"))
    handles.extend(shade_handles)
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles) if len(handles) <= 5 else
               -(-len(handles) // 2), fontsize=9, frameon=False)
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return _finish(fig, path)


def _diode_colours(k):
    cmap = colormaps["turbo"]
    return [cmap(0.05 + 0.9 * i / max(k - 1, 1)) for i in range(k)]


# ----------------------------------------------------------------------------- estimator error

def plot_estimator_error(t_s, err_deg, *, window=181, sunlit=None, path=None, title=None,
                         ylabel="Sun vector angle error [deg]", time_unit=None, ylim=None):
    """Return a Figure of the estimator angle error (deg) over time, with Hanning-window mean and mean +- STD.

    As thesis figs. 4.6-4.17: the raw error as dots (one per sample), the centred Hanning-window
    (``window`` samples, 181 in the thesis) mean as a thick line and mean +- STD as a band
    (:func:`estimators.metrics.hanning_mean_std`). ``err_deg`` is one series (N,) or a dict
    name -> (N,) drawn in one axes. ``sunlit`` (N,) bool: eclipse samples are shaded grey and
    left blank (errors there are dropped before smoothing). Sunlit samples with no estimate
    (NaN) are ticked along the bottom. When a few raw samples would squash the axis they
    are clipped at the top and counted in a note. ``ylim`` (bottom, top) fixes the range, e.g.
    one range for all the estimators of a run (:func:`shared_error_ylim`). The mean line and band carry the gids
    ``"mean:<name>"`` and ``"band:<name>"`` (name ``"error"`` for a single series).
    """
    t = _series("t_s", t_s)
    n = t.size
    series = dict(err_deg) if isinstance(err_deg, dict) else {"error": err_deg}
    if not series:
        raise ValueError("err_deg is an empty dict; give at least one error series (N,) in degrees")
    series = {str(name): _series(f"err_deg[{name!r}]", v, n).copy() for name, v in series.items()}
    lit = None
    if sunlit is not None:
        lit = np.asarray(sunlit)
        if lit.shape != (n,):
            raise ValueError(f"sunlit must be a bool array ({n},) (True where the Sun is visible), "
                             f"got shape {lit.shape}")
        lit = lit.astype(bool)
    x, xlabel = _time_axis(t, time_unit)

    fig = _figure(10.0, 6.0)
    ax = fig.subplots()
    handles, extra = [], []
    if lit is not None and _shade(ax, x, ~lit, UMBRA_COLOUR, 0.3):
        extra.append(Patch(color=UMBRA_COLOUR, alpha=0.3, lw=0, label="eclipse"))

    single = len(series) == 1
    palette = ["#1f5fa8", "#d62728", "#2ca02c", "#9467bd", "#e08a00", "#17becf", "#8c564b", "#e377c2"]
    raw_all, top_stats = [], 0.0
    tick_tf = blended_transform_factory(ax.transData, ax.transAxes)
    for j, (name, e) in enumerate(series.items()):
        colour = palette[j % len(palette)]
        invalid = ~np.isfinite(e) if lit is None else (~np.isfinite(e) & lit)
        if lit is not None:
            e[~lit] = np.nan
        mean, std = hanning_mean_std(e, window=window)
        if lit is not None:
            mean[~lit] = np.nan
            std[~lit] = np.nan
        label = "" if single else f"{name}: "
        ax.plot(x, e, ls="none", marker=".", ms=2.0, mew=0, color="0.35" if single else colour,
                alpha=0.6 if single else 0.35, zorder=1, rasterized=True)
        ax.fill_between(x, mean - std, mean + std, color=colour, alpha=0.22, lw=0, zorder=2, gid=f"band:{name}")
        ax.plot(x, mean, color=colour, lw=2.0, zorder=3, gid=f"mean:{name}")
        if single:
            handles[:0] = [Line2D([], [], ls="none", marker=".", ms=5, color="0.35", label="error (each sample)"),
                           Line2D([], [], color=colour, lw=2.0, label=f"mean (Hanning, {window} samples)"),
                           Patch(color=colour, alpha=0.22, lw=0, label="mean $\\pm$ STD")]
        else:
            handles.append(Line2D([], [], color=colour, lw=2.0, label=f"{label}mean $\\pm$ STD"))
        if invalid.any():
            ax.plot(x[invalid], np.full(invalid.sum(), 0.012 + 0.02 * j), ls="none", marker="|", ms=6,
                    color=colour if not single else "#d62728", transform=tick_tf, zorder=4, clip_on=False)
            handles.append(Line2D([], [], ls="none", marker="|", ms=8, color=colour if not single else "#d62728",
                                  label=f"{label}no estimate ({int(invalid.sum())} sunlit samples)"))
        raw_all.append(e[np.isfinite(e)])
        if np.isfinite(mean + std).any():
            top_stats = max(top_stats, float(np.nanmax(mean + std)))
    raw = np.concatenate(raw_all)
    if not single:
        handles.insert(0, Line2D([], [], ls="none", marker=".", ms=5, color="0.45", label="error (each sample, dots)"))
    handles += extra

    if raw.size and ylim is not None:
        above = int(np.sum(raw > ylim[1]))
        if above:
            ax.text(0.995, 0.985, f"{above} samples above the axis (max {float(raw.max()):.1f} deg)",
                    transform=ax.transAxes, ha="right", va="top", fontsize=8, color="0.3")
        ax.set_ylim(*ylim)
    elif raw.size:
        lo = min(0.0, float(raw.min()))
        robust = max(top_stats, float(np.percentile(raw, 99.5)))
        hi = float(raw.max())
        if robust > 0 and hi > 1.5 * robust:
            top = 1.15 * robust
            above = int(np.sum(raw > top))
            ax.text(0.995, 0.985, f"{above} samples above the axis (max {hi:.1f} deg)", transform=ax.transAxes,
                    ha="right", va="top", fontsize=8, color="0.3")
        else:
            top = hi * 1.1 if hi > 0 else 1.0
        ax.set_ylim(lo if lo < 0 else 0.0, top)
    else:
        ax.set_ylim(0.0, 1.0)
        ax.text(0.5, 0.5, "no sunlit sample with an estimate", transform=ax.transAxes, ha="center",
                va="center", fontsize=12, color="0.2")
    if n > 1:
        ax.set_xlim(x[0], x[-1])
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.4, alpha=0.5)
    long_labels = sum(len(h.get_label()) for h in handles) > 110
    fig.legend(handles=handles, loc="outside lower center", ncol=3 if long_labels else len(handles), fontsize=9,
               frameon=False)
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return _finish(fig, path)


# ----------------------------------------------------------------------------- albedo cells

def _grid_centres(name, given, count, lo):
    if given is None:
        step = (-2 * lo) / count
        return lo + (np.arange(count) + 0.5) * step
    c = np.asarray(given, dtype=float).reshape(-1)
    if c.size != count:
        raise ValueError(f"{name} has {c.size} cell centres but the map has {count} along that axis")
    if count > 1:
        d = np.diff(c)
        if not (np.all(d > 0) or np.all(d < 0)) or not np.allclose(d, d[0], rtol=1e-6, atol=1e-9):
            raise ValueError(f"{name} must be regularly spaced, monotonic cell centres in degrees")
    return c


def _extent(centres):
    step = abs(centres[1] - centres[0]) if centres.size > 1 else 1.0
    return min(centres[0], centres[-1]) - step / 2, max(centres[0], centres[-1]) + step / 2


def _wrap_lon(lon):
    return (np.asarray(lon, dtype=float) + 180.0) % 360.0 - 180.0


def plot_albedo_cells(cells, *, lat_deg=None, lon_deg=None, sat_lat_lon_deg=None, sub_solar_lat_lon_deg=None,
                      background=None, scale="log", title=None, path=None):
    """Return a Figure of the albedo irradiance at the satellite contributed by each map cell, W/m^2, on a world map.

    ``cells`` (n_lat, n_lon) W/m^2 (e.g. :func:`simcore.radiometry.albedo.albedo_cells`), row 0 the
    SOUTH band and column 0 the western-most cell unless ``lat_deg``/``lon_deg`` (cell
    centres) say otherwise. Equirectangular, north up, east right. ``scale``: 'log'
    (4 decades below the brightest cell; fainter cells take the lowest colour) or 'linear'.
    Zero cells are transparent, showing ``background`` (n_lat, n_lon), e.g. the
    reflectivity map, faintly in grey (no coastlines: the reflectivity gives the geography).
    ``sat_lat_lon_deg`` / ``sub_solar_lat_lon_deg``: (lat, lon) of the satellite nadir and
    the sub-solar point, marked.
    """
    c = np.asarray(cells, dtype=float)
    if c.ndim != 2:
        raise ValueError(f"cells must be a map (n_lat, n_lon) in W/m^2, got shape {c.shape}")
    if np.any(c[np.isfinite(c)] < 0):
        raise ValueError("cells has negative irradiance; give the per-cell albedo irradiance (>= 0 W/m^2)")
    if scale not in ("log", "linear"):
        raise ValueError(f"scale must be 'log' or 'linear', got {scale!r}")
    n_lat, n_lon = c.shape
    lat = _grid_centres("lat_deg", lat_deg, n_lat, -90.0)
    lon = _grid_centres("lon_deg", lon_deg, n_lon, -180.0)
    bg = None
    if background is not None:
        bg = np.asarray(background, dtype=float)
        if bg.shape != c.shape:
            raise ValueError(f"background must have the cells' shape {c.shape}, got {bg.shape}")
    # imshow with origin='lower' puts row 0 at the bottom: make row 0 the southern-most, column 0 the western-most
    if n_lat > 1 and lat[0] > lat[-1]:
        c, lat = c[::-1], lat[::-1]
        bg = None if bg is None else bg[::-1]
    if n_lon > 1 and lon[0] > lon[-1]:
        c, lon = c[:, ::-1], lon[::-1]
        bg = None if bg is None else bg[:, ::-1]
    extent = [*_extent(lon), *_extent(lat)]

    fig = _figure(10.0, 5.3)
    ax = fig.subplots()
    ax.set_facecolor("white")
    if bg is not None:
        finite = bg[np.isfinite(bg)]
        vmax = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
        ax.imshow(np.ma.masked_invalid(bg), origin="lower", extent=extent, cmap="Greys_r", vmin=0.0, vmax=vmax,
                  alpha=0.45, interpolation="nearest", aspect="equal", zorder=0)
    base = colormaps["plasma"]
    cmap = base.with_extremes(bad=(1.0, 1.0, 1.0, 0.0), under=base(0.0))
    positive = c[np.isfinite(c) & (c > 0)]
    total = float(np.nansum(c))
    if positive.size:
        vmax = float(positive.max())
        if scale == "log":
            vmin = max(float(positive.min()), vmax * 1e-4)
            if vmin >= vmax:
                vmin = vmax / 10.0
            norm = LogNorm(vmin=vmin, vmax=vmax, clip=False)
            extend = "min" if positive.min() < vmin else "neither"
        else:
            norm = Normalize(vmin=0.0, vmax=vmax)
            extend = "neither"
        img = ax.imshow(np.ma.masked_where(~(np.isfinite(c) & (c > 0)), c), origin="lower", extent=extent,
                        cmap=cmap, norm=norm, interpolation="nearest", aspect="equal", zorder=1)
        cb = fig.colorbar(img, ax=ax, extend=extend, shrink=0.8, pad=0.02, aspect=25)
        cb.set_label("Albedo irradiance at the satellite per cell [W/m$^2$]")
    else:
        ax.text(0.5, 0.5, "no sunlit cell in view of the satellite", transform=ax.transAxes, ha="center",
                va="center", fontsize=12, color="0.2",
                bbox=dict(boxstyle="round", facecolor="white", edgecolor="0.6"))
    handles = []
    for value, name, style in ((sat_lat_lon_deg, "satellite nadir",
                                dict(marker="o", ms=9, mfc="#00c8ff", mec="k", mew=1.2)),
                               (sub_solar_lat_lon_deg, "sub-solar point",
                                dict(marker="*", ms=15, mfc="#ffe600", mec="k", mew=1.0))):
        if value is None:
            continue
        ll = np.asarray(value, dtype=float).reshape(-1)
        if ll.shape != (2,) or not (-90.0 <= ll[0] <= 90.0):
            raise ValueError(f"{name} must be (lat_deg, lon_deg) with lat in [-90, 90], got {value!r}")
        ax.plot(_wrap_lon(ll[1]), ll[0], ls="none", zorder=5, **style)
        handles.append(Line2D([], [], ls="none", label=f"{name} ({ll[0]:.1f}°, {_wrap_lon(ll[1]):.1f}°)", **style))
    if bg is not None:
        handles.append(Patch(facecolor="0.75", edgecolor="0.5", lw=0.5, label="reflectivity (background, grey)"))
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_xticks(np.arange(-180, 181, 30))
    ax.set_yticks(np.arange(-90, 91, 30))
    ax.set_xlabel("Longitude [deg] (east positive)")
    ax.set_ylabel("Latitude [deg]")
    ax.grid(True, lw=0.4, color="0.4", alpha=0.4)
    ax.tick_params(labelsize=9)
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9, frameon=False)
    head = title if title is not None else "Earth albedo seen from the satellite, per map cell"
    fig.suptitle(f"{head}\nsum over cells {total:.1f} W/m$^2$, {positive.size} lit cells in view", fontsize=11)
    return _finish(fig, path)


# ----------------------------------------------------------------------------- angular response

def plot_angular_response(theta_deg, curves, *, fov_deg=None, cutoff_deg=83.1, errors=None, title=None,
                          path=None, ylabel="Response relative to normal incidence [-]"):
    """Return a Figure of aperture angular response cuts: response relative to normal incidence vs angle (deg).

    ``theta_deg`` (M,) incidence angles; ``curves`` dict name -> (M,) responses relative to
    normal incidence (e.g. ray traced, eq. 4.15, the analytic overlap, cos theta). Curves
    with an entry in ``errors`` (dict name -> (M,) standard errors, e.g. Monte Carlo) are
    drawn as points with +-2 SE error bars, the others as lines. Vertical lines mark the
    FOV (``fov_deg``) and the cut-off (``cutoff_deg``, eq. 4.15: 83.1 deg; None hides it).
    """
    th = _series("theta_deg", theta_deg)
    m = th.size
    if not isinstance(curves, dict) or not curves:
        raise ValueError("curves must be a non-empty dict name -> response (M,) relative to normal incidence")
    errors = {} if errors is None else dict(errors)
    unknown = set(errors) - set(curves)
    if unknown:
        raise ValueError(f"errors has entries {sorted(map(str, unknown))} with no curve of that name in curves")
    fig = _figure(10.0, 6.0)
    ax = fig.subplots()
    order = np.argsort(th)
    line_styles = ["-", (0, (6, 2)), (0, (2, 1.5)), (0, (6, 2, 1.5, 2)), (0, (1, 1))]
    line_colours = ["k", "#e08a00", "#1f5fa8", "#2ca02c", "#9467bd", "#8c564b"]
    point_colours = ["#d62728", "#17becf", "#e377c2"]
    n_line = n_point = 0
    for name, y in curves.items():
        y = _series(f"curves[{name!r}]", y, m)[order]
        if name in errors:
            se = _series(f"errors[{name!r}]", errors[name], m)[order]
            colour = point_colours[n_point % len(point_colours)]
            ax.errorbar(th[order], y, yerr=2.0 * se, ls="none", marker="o", ms=4, color=colour, ecolor=colour,
                        elinewidth=1.0, capsize=2.5, zorder=4, label=f"{name} ($\\pm$2 SE)")
            n_point += 1
        else:
            ax.plot(th[order], y, ls=line_styles[n_line % len(line_styles)],
                    color=line_colours[n_line % len(line_colours)], lw=1.6, zorder=3, label=str(name))
            n_line += 1
    tf = blended_transform_factory(ax.transData, ax.transAxes)
    for value, label in ((fov_deg, "FOV"), (cutoff_deg, "cut-off")):
        if value is None:
            continue
        v = float(value)
        for s in ((-1.0, 1.0) if th.min() < 0 else (1.0,)):
            ax.axvline(s * v, color="0.35", lw=1.0, ls=(0, (3, 3)), zorder=1)
            ax.text(s * v, 0.99, f" {label} {v:g}°", transform=tf, rotation=90, va="top",
                    ha="right" if s > 0 else "left", fontsize=9, color="0.25")
    ax.set_xlim(th.min(), th.max())
    ymax = max(1.05, float(np.nanmax([np.nanmax(np.asarray(v, float)) for v in curves.values()])) * 1.05)
    ax.set_ylim(0.0, ymax)
    ax.set_xlabel("Incidence angle $\\theta$ from the diode normal [deg]")
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.4, alpha=0.5)
    fig.legend(loc="outside lower center", ncol=min(len(curves), 5), fontsize=9, frameon=False)
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return _finish(fig, path)


# ----------------------------------------------------------------------------- coverage map

def plot_coverage_map(counts, *, title=None, normals_body=None, dead=(), path=None):
    """Return a Figure of the redundancy coverage of the body-frame sphere: Mollweide map, red/yellow/green.

    ``counts`` (12 nside^2,) HEALPix RING-order counts of live diodes that see each pixel
    (:func:`simcore.studies.coverage.coverage_map`). Red: <= 2 diodes, yellow: 3, green: >= 4
    (thesis figs. 3.7-3.13); the equal-area fractions go in the title. Map centre = body +x,
    pole = body +z, azimuth (from +x towards +y) increasing to the right. ``normals_body``
    (K, 3) optionally marks the diode normals (index labels), ``dead`` indices as crosses.
    """
    import healpy as hp

    cnt = np.asarray(counts)
    if cnt.ndim != 1 or not hp.isnpixok(cnt.size):
        raise ValueError(f"counts must be a HEALPix map (12 nside^2,) in RING order, e.g. 3072 pixels for "
                         f"nside 16; got shape {cnt.shape}")
    if not np.all(np.isfinite(cnt)) or np.any(cnt < 0):
        raise ValueError("counts must be non-negative diode counts per pixel")
    nside = hp.npix2nside(cnt.size)
    cls = np.where(cnt <= 2, 0, np.where(cnt == 3, 1, 2))
    frac = [float(np.mean(cls == j)) for j in range(3)]

    # a fine lon/lat raster, each cell coloured by the HEALPix pixel containing its centre
    n_lon, n_lat = 720, 360
    lon_e = np.linspace(-np.pi, np.pi, n_lon + 1)
    lat_e = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 1)
    lon_c = 0.5 * (lon_e[1:] + lon_e[:-1])
    lat_c = 0.5 * (lat_e[1:] + lat_e[:-1])
    LON, LAT = np.meshgrid(lon_c, lat_c)
    pix = hp.ang2pix(nside, np.pi / 2 - LAT, np.mod(LON, 2 * np.pi))
    grid = cls[pix]

    fig = _figure(10.0, 6.0)
    ax = fig.add_subplot(projection="mollweide")
    cmap = ListedColormap(list(COVERAGE_COLOURS))
    ax.pcolormesh(lon_e, lat_e, grid, cmap=cmap, norm=BoundaryNorm([-0.5, 0.5, 1.5, 2.5], 3), shading="flat",
                  rasterized=True, zorder=0)
    ax.grid(True, color="0.15", lw=0.5, alpha=0.45)
    ax.set_xticks(np.radians(np.arange(-150, 151, 30)))
    ax.set_yticks(np.radians(np.arange(-60, 61, 30)))
    ax.tick_params(labelsize=8)
    # longitude labels sit on the map itself: a white halo keeps them readable on every colour
    for lab in ax.get_xticklabels():
        lab.set_path_effects([withStroke(linewidth=2.5, foreground="white")])
    ax.set_xlabel("Azimuth in the body frame, from +x towards +y [deg]")
    ax.set_ylabel("Elevation above the body xy plane [deg]")
    handles = [Patch(color=COVERAGE_COLOURS[0], label=f"$\\leq$ 2 diodes  {frac[0]:.4f}"),
               Patch(color=COVERAGE_COLOURS[1], label=f"3 diodes  {frac[1]:.4f}"),
               Patch(color=COVERAGE_COLOURS[2], label=f"$\\geq$ 4 diodes  {frac[2]:.4f}")]
    if normals_body is not None:
        nb = np.asarray(normals_body, dtype=float)
        if nb.ndim != 2 or nb.shape[1] != 3:
            raise ValueError(f"normals_body must be diode normals (K, 3) in the body frame, got shape {nb.shape}")
        dead_idx = set(int(i) for i in np.atleast_1d(np.asarray(dead, dtype=int)))
        if any(i < 0 or i >= len(nb) for i in dead_idx):
            raise ValueError(f"dead indices {sorted(dead_idx)} out of range 0..{len(nb) - 1}")
        u = nb / np.linalg.norm(nb, axis=1, keepdims=True)
        az = np.arctan2(u[:, 1], u[:, 0])
        el = np.arcsin(np.clip(u[:, 2], -1.0, 1.0))
        for i in range(len(u)):
            if i in dead_idx:
                ax.plot(az[i], el[i], ls="none", marker="x", ms=9, mew=2.0, color="k", zorder=3)
            else:
                ax.plot(az[i], el[i], ls="none", marker="o", ms=5, color="k", zorder=3)
            ax.annotate(str(i), (az[i], el[i]), xytext=(4, 3), textcoords="offset points", fontsize=8, zorder=4)
        handles.append(Line2D([], [], ls="none", marker="o", ms=5, color="k", label="diode normal"))
        if dead_idx:
            handles.append(Line2D([], [], ls="none", marker="x", ms=8, mew=2.0, color="k", label="dead diode"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9, frameon=False)
    head = f"{title}\n" if title is not None else ""
    fig.suptitle(f"{head}red {frac[0]:.4f}   yellow {frac[1]:.4f}   green {frac[2]:.4f}"
                 f"   (HEALPix nside {nside}, equal-area fractions)", fontsize=11)
    return _finish(fig, path)


def shared_error_ylim(err_deg, sunlit=None):
    """Return one (0, top) range in degrees for the error plots of several estimators of one run.

    ``top`` is 1.15 x the largest 99.5th percentile of the sunlit finite errors (so a few outliers of
    one estimator do not squash all the plots; :func:`plot_estimator_error` counts what is cut)."""
    tops = []
    for e in err_deg.values():
        e = np.asarray(e, dtype=float)
        if sunlit is not None:
            e = e[np.asarray(sunlit, bool)]
        e = e[np.isfinite(e)]
        if e.size:
            tops.append(float(np.percentile(e, 99.5)))
    top = 1.15 * max(tops) if tops and max(tops) > 0 else 1.0
    return 0.0, top


__all__ = ["plot_albedo_cells", "plot_angular_response", "plot_coverage_map", "plot_diode_irradiance",
           "plot_attitude_bars", "plot_estimator_error", "plot_mekf", "save_figure", "shared_error_ylim"]


# ----------------------------------------------------------------------------- aperture studies

def plot_cuts(study, path=None, zoom_from_deg=None):
    """Return a list of Figures (one per azimuth) of a :class:`CutStudy` with
    :func:`simcore.plots.plot_angular_response`; ``zoom_from_deg`` (e.g. 60) draws only the angles from
    there on; ``path`` (e.g. 'out/cut') writes ``path_phi<phi>.png``."""
    figs = []
    keep = np.ones(study.theta_deg.shape, bool) if zoom_from_deg is None else study.theta_deg >= zoom_from_deg
    for phi, c in study.curves.items():
        p = None if path is None else f"{path}_phi{phi:g}.png"
        where = "wall axis" if phi == 0 else ("diagonal" if phi == 45 else f"azimuth {phi:g} deg")
        figs.append(plot_angular_response(study.theta_deg[keep], {k: v[keep] for k, v in c.items()},
                                          fov_deg=study.fov_deg, cutoff_deg=EQ415_CUTOFF_DEG,
                                          errors={k: v[keep] for k, v in study.errors[phi].items()}, path=p,
                                          title=f"Angular response along the {where} (phi = {phi:g} deg)"))
    return figs


def plot_response_map(rmap, path=None):
    """Return a Figure: the traced response over the diode's hemisphere (polar plot: radius = incidence
    angle, angle = azimuth from the u wall axis), traced - overlap in standard errors, and eq. 4.15 -
    overlap; ``path`` writes it (.png/.pdf)."""
    d = rmap.d_diode
    keep = d[:, 2] > -0.05
    th = np.degrees(np.arccos(np.clip(d[keep, 2], -1, 1)))
    ph = np.arctan2(d[keep, 1], d[keep, 0])
    x, y = th * np.cos(ph), th * np.sin(ph)
    tri = Triangulation(x, y)
    fig = Figure(figsize=(13.5, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3)
    panels = [(rmap.traced[keep], f"{rmap.label}: response", "viridis", (0, 1)),
              (rmap.z_score[keep], "(traced - overlap) / SE", "coolwarm", (-4, 4)),
              ((rmap.eq415 - rmap.overlap)[keep], "eq. 4.15 - overlap", "coolwarm", None)]
    for ax, (val, title, cmap, lim) in zip(axes, panels):
        if lim is None:
            m = float(np.max(np.abs(val))) or 1.0
            lim = (-m, m)
        pc = ax.tripcolor(tri, val, shading="gouraud", cmap=cmap, vmin=lim[0], vmax=lim[1])
        for r in (30, 60, 90):
            t = np.linspace(0, 2 * np.pi, 200)
            ax.plot(r * np.cos(t), r * np.sin(t), color="0.3", lw=0.5)
        ax.plot([-90, 90], [0, 0], color="0.3", lw=0.4)
        ax.plot([0, 0], [-90, 90], color="0.3", lw=0.4)
        ax.set_aspect("equal")
        ax.set_xlim(-95, 95)
        ax.set_ylim(-95, 95)
        ax.set_xlabel("theta cos(phi) [deg] (u wall axis)")
        ax.set_ylabel("theta sin(phi) [deg] (v wall axis)")
        ax.set_title(title, fontsize=10)
        fig.colorbar(pc, ax=ax, shrink=0.8)
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_response_hemisphere(theta_deg, phi_deg, response, *, title=None, path=None,
                             label="response relative to normal incidence [-]"):
    """Return a Figure of a response over a diode's hemisphere: polar map, radius = angle from the normal
    (``theta_deg``, (T,) cell centres), angle = azimuth from the diode's u axis (``phi_deg``, (P,));
    ``response`` (T, P) relative to normal incidence."""
    th, ph = _series("theta_deg", theta_deg), _series("phi_deg", phi_deg)
    r = np.asarray(response, float)
    if r.shape != (th.size, ph.size):
        raise ValueError(f"response must have shape ({th.size}, {ph.size}) (theta x phi), got {r.shape}")
    fig = _figure(6.4, 5.6)
    ax = fig.add_subplot(projection="polar")
    dth, dph = (th[1] - th[0]) if th.size > 1 else 90.0, (ph[1] - ph[0]) if ph.size > 1 else 360.0
    t_edges = np.r_[th - dth / 2, th[-1] + dth / 2]
    p_edges = np.radians(np.r_[ph - dph / 2, ph[-1] + dph / 2])
    pc = ax.pcolormesh(p_edges, t_edges, r, cmap="viridis", vmin=0.0, vmax=1.0, shading="flat")
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90], ["30°", "60°", "90°"], fontsize=8)
    ax.set_xlabel("azimuth from the diode's u axis; radius: angle from its normal", fontsize=9)
    fig.colorbar(pc, ax=ax, shrink=0.8, label=label)
    if title is not None:
        ax.set_title(title, fontsize=10)
    return _finish(fig, path)


def plot_sweep(rows, path=None, estimators=("wls", "albedo_sun")):
    """Return a Figure of a sweep table: green fraction, albedo fraction and the estimators' mean sunlit
    errors against the well height, one line per (tilt, FOV); ``path`` writes it."""
    metrics = [("green", "coverage: green fraction (FOV cones) [-]"),
               ("green_response", "coverage: green fraction (response >= 1 %) [-]"),
               ("albedo_fraction", "albedo / total, sunlit [-]")]
    metrics += [(f"{e}_mean_deg", f"{e}: mean sunlit error [deg]") for e in estimators]
    metrics += [(f"{e}_p95_deg", f"{e}: p95 sunlit error [deg]") for e in estimators]
    fig = Figure(figsize=(4.2 * ((len(metrics) + 1) // 2), 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, (len(metrics) + 1) // 2, squeeze=False).T.ravel()
    keys = sorted({(r["tilt_deg"], r["fov_deg"]) for r in rows})
    colours = ["#1f5fa8", "#e08a00", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#17becf", "#7f7f7f"]
    for ax, (col, label) in zip(axes, metrics):
        for j, (tilt, fov) in enumerate(keys):
            sel = sorted((r for r in rows if (r["tilt_deg"], r["fov_deg"]) == (tilt, fov) and r.get("feasible")),
                         key=lambda r: r["height_mm"])
            if not sel:
                continue
            ax.plot([r["height_mm"] for r in sel], [r.get(col, np.nan) for r in sel], marker="o",
                    color=colours[j % len(colours)], ls="-" if fov == keys[0][1] else "--",
                    label=f"tilt {tilt:g}, FOV {fov:g}")
        ax.set_xlabel("well height [mm]")
        ax.set_ylabel(label)
        ax.grid(True, lw=0.4, alpha=0.5)
    for ax in axes[len(metrics):]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6), fontsize=9, frameon=False)
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_reflectance_series(series, path=None):
    """Return a Figure: response cuts for each wall reflectance (left) and their excess over black walls
    with +-2 SE bands (right, log scale); ``path`` writes it."""
    th = series["theta_deg"]
    fig = Figure(figsize=(11.5, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot(th, series["overlap"], color="k", lw=2.5, alpha=0.35, label="analytic overlap (black)")
    for rho, r, se in zip(series["rho"], series["response"], series["response_se"]):
        line, = ax1.plot(th, r, lw=1.3, label=f"rho {rho:g}")
        if rho > 0:
            ex = r - series["overlap"]
            ax2.plot(th, np.where(ex > 0, ex, np.nan), color=line.get_color(), lw=1.3, label=f"rho {rho:g}")
            ax2.fill_between(th, np.maximum(ex - 2 * se, 1e-6), ex + 2 * se, color=line.get_color(), alpha=0.2)
    ax1.set_ylabel("response relative to normal incidence [-]")
    ax2.set_ylabel("response - black-wall overlap [-]")
    ax2.set_yscale("log")
    ax2.set_ylim(1e-5, 1)
    for ax in (ax1, ax2):
        ax.set_xlabel(f"incidence angle [deg] (azimuth {series['phi_deg']:g} deg)")
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.axvline(EQ415_CUTOFF_DEG, color="0.4", ls=":", lw=1)
        ax.legend(fontsize=8)
    if path is not None:
        save_figure(fig, path)
    return fig


# ----------------------------------------------------------------------------- attitude filter

def plot_mekf(res, folder, title=""):
    """Write ``attitude_error.png`` (the MEKF's attitude error per body axis with its own 3 sigma, and the
    total, eclipse shaded) and ``nees.png`` (NEES with its 95 % chi-square bounds) into ``folder``;
    return their paths. ``res``: :func:`simcore.pipeline.evaluate_attitude.run_mekf`'s result."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    t = res["t_s"]
    fig = _figure(10, 9)
    axes = fig.subplots(4, 1, sharex=True)
    for i, ax in enumerate(axes[:3]):
        ax.plot(t, res["error_body_deg"][:, i], lw=0.6, label="error")
        ax.plot(t, 3 * res["sigma_deg"][:, i], "k--", lw=0.6, label="+-3 sigma (filter)")
        ax.plot(t, -3 * res["sigma_deg"][:, i], "k--", lw=0.6)
        ax.set_ylabel(f"body {'xyz'[i]} [deg]")
        ax.set_ylim(-5, 5)
    axes[3].semilogy(t, res["error_deg"], lw=0.6)
    axes[3].set_ylabel("total [deg]")
    axes[3].set_xlabel("time since start [s]")
    for ax in axes:
        ax.fill_between(t, 0, 1, where=res["eclipse"], color="0.85", transform=ax.get_xaxis_transform(), lw=0)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(f"{title} attitude error (grey: eclipse)")
    paths = save_figure(fig, folder / "attitude_error.png")
    fig = _figure(10, 3.5)
    ax = fig.subplots()
    ax.semilogy(t, res["nees"], lw=0.5)
    for b in res["summary"]["nees_bounds_3dof_95"]:
        ax.axhline(b, color="k", ls="--", lw=0.8)
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("NEES (3 dof)")
    ax.set_title(f"{title} NEES, in 95 % bounds {res['summary']['nees_in_bounds']:.1%} of the time")
    paths += save_figure(fig, folder / "nees.png")
    return [str(p) for p in paths]


def plot_attitude_bars(cells, configs, gyros, ylabel, path=None):
    """Return a Figure of bars per configuration and gyro, with and without the on-board albedo prediction
    (two panels, log scale): ``cells`` {(config, gyro, onboard): (mean over seeds, spread)}; ``path`` writes it."""
    fig = _figure(12, 4)
    axes = fig.subplots(1, 2, sharey=True)
    x = np.arange(len(configs))
    w = 0.8 / len(gyros)
    for ax, onboard in zip(axes, (True, False)):
        for i, g in enumerate(gyros):
            m = [cells[(c, g, onboard)] for c in configs]
            ax.bar(x + (i - (len(gyros) - 1) / 2) * w, [a for a, _ in m], w, yerr=[s for _, s in m],
                   label=g, capsize=2)
        ax.set_xticks(x, configs, rotation=30, ha="right")
        ax.set_title(("with" if onboard else "without") + " on-board albedo prediction")
        ax.set_yscale("log")
    axes[0].set_ylabel(ylabel)
    axes[0].legend(fontsize=8)
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_rate_error(rows, requirement_deg_s_rthz, path=None):
    """Return a Figure of the estimated rate's rms error against the averaging window per gyro (log-log), with
    the raw and filtered errors at the first window and the requirement N_req / sqrt(T); ``path`` writes it."""
    fig = _figure(7, 4.5)
    ax = fig.subplots()
    for i, (g, r) in enumerate(rows.items()):
        w = np.asarray(r["windows_s"], dtype=float)
        line, = ax.plot(w, r["averaged_deg_s"], "o-", label=f"{g}: filtered, averaged over T")
        ax.plot([w[0] * 0.7], [r["raw_deg_s"]], "v", color=line.get_color(),
                label="raw reading (bias in)" if i == 0 else None)
        ax.plot(w, r["data_sheet_density_deg_s_rthz"] / np.sqrt(w), ":", color=line.get_color(), lw=1,
                label="data sheet's white noise alone" if i == 0 else None)
    w = np.asarray(next(iter(rows.values()))["windows_s"], dtype=float)
    ax.plot(w, requirement_deg_s_rthz / np.sqrt(w), "k-", lw=2, label="requirement 0.0002 / sqrt(T) (thesis 3.1.2)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging window T [s]")
    ax.set_ylabel("rms rate error per axis [deg/s]")
    ax.set_title("estimated body rate against the controller's requirement")
    ax.legend(fontsize=7)
    if path is not None:
        save_figure(fig, path)
    return fig
