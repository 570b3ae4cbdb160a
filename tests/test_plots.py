"""Tests of simcore.plots: files are written, maps land where the conventions put them, the
Hanning band of a constant is that constant, and misuse raises a message that teaches."""
import healpy as hp
import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.image import AxesImage, imread

from simcore import plots


def _written(path):
    return path.exists() and path.stat().st_size > 0


def _colour_centroid(png, ax, fig, rgb, tol=0.06):
    """Return the centroid (fx, fy) of the pixels of colour ``rgb`` inside ``ax``, as fractions of the
    axes box measured from its lower-left corner (x right, y up), and how many pixels matched."""
    img = imread(png)[..., :3]
    scale = plots.PNG_DPI / fig.dpi
    bb = ax.get_window_extent()
    x0, x1, y0, y1 = bb.x0 * scale, bb.x1 * scale, bb.y0 * scale, bb.y1 * scale
    h = img.shape[0]
    match = np.all(np.abs(img - np.asarray(rgb)[None, None, :]) < tol, axis=-1)
    rows, cols = np.nonzero(match)
    y_up = h - rows  # image rows count down from the top, display y counts up from the bottom
    inside = (cols >= x0) & (cols <= x1) & (y_up >= y0) & (y_up <= y1)
    fx = (cols[inside].mean() - x0) / (x1 - x0)
    fy = (y_up[inside].mean() - y0) / (y1 - y0)
    return fx, fy, int(inside.sum())


# ----------------------------------------------------------------------------- save_figure

def test_save_figure_suffixes(tmp_path):
    fig = plots.plot_angular_response(np.array([0.0, 45.0, 90.0]), {"cos": np.array([1.0, 0.7071, 0.0])})
    both = plots.save_figure(fig, tmp_path / "sub" / "resp")
    assert [p.name for p in both] == ["resp.png", "resp.pdf"]
    assert all(_written(p) for p in both)
    assert imread(both[0]).shape[:2] == (int(round(6.0 * plots.PNG_DPI)), int(round(10.0 * plots.PNG_DPI)))
    assert both[1].read_bytes()[:5] == b"%PDF-"
    only = plots.save_figure(fig, tmp_path / "one.PNG")
    assert [p.name for p in only] == ["one.PNG"] and _written(only[0])
    with pytest.raises(ValueError, match=r"\.png or \.pdf"):
        plots.save_figure(fig, tmp_path / "resp.svgz")


def test_figures_do_not_touch_pyplot_or_the_backend(tmp_path):
    import matplotlib.pyplot as plt  # imported only to check that no pyplot figure is opened

    backend = matplotlib.get_backend()
    before = plt.get_fignums()
    fig = plots.plot_estimator_error(np.arange(50.0), np.ones(50), window=11, path=tmp_path / "e.png")
    assert isinstance(fig, Figure)
    assert matplotlib.get_backend() == backend
    assert plt.get_fignums() == before


# ----------------------------------------------------------------------------- diode irradiance

def test_diode_irradiance_small_multiples_write_png_and_pdf(tmp_path, rng):
    t = np.arange(0.0, 600.0, 5.0)
    k = 3
    direct = 1366.1 * np.clip(np.cos(t[:, None] / 60.0 + np.arange(k)), 0.0, None)
    albedo = 80.0 * np.clip(np.sin(t[:, None] / 90.0 + np.arange(k)), 0.0, None)
    illum = np.where(t > 400.0, 0.0, 1.0)
    illum[(t > 390.0) & (t <= 400.0)] = 0.5
    fig = plots.plot_diode_irradiance(
        t, direct + rng.normal(size=direct.shape), albedo, direct_se=np.ones_like(direct),
        albedo_se=np.ones_like(albedo), analytic_direct=direct, analytic_albedo=albedo,
        diode_names=["+x", "+y", "-x"], illumination=illum, title="test", path=tmp_path / "irr")
    assert _written(tmp_path / "irr.png") and _written(tmp_path / "irr.pdf")
    panels = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
    assert [ax.get_title(loc="left") for ax in panels] == ["+x", "+y", "-x"]
    assert all(ax.get_ylim()[0] <= 0.0 for ax in panels)


def test_diode_irradiance_many_diodes_use_two_panels(tmp_path):
    t = np.arange(0.0, 100.0)
    sig = np.ones((100, 20))
    fig = plots.plot_diode_irradiance(t, sig, 0.1 * sig, path=tmp_path / "irr20.png")
    assert len(fig.axes) == 2 and _written(tmp_path / "irr20.png")


def test_diode_irradiance_rejects_mismatched_shapes():
    t = np.arange(10.0)
    with pytest.raises(ValueError, match=r"albedo must be diode signals \(10, 3\)"):
        plots.plot_diode_irradiance(t, np.ones((10, 3)), np.ones((10, 2)))
    with pytest.raises(ValueError, match="one name per column"):
        plots.plot_diode_irradiance(t, np.ones((10, 3)), np.ones((10, 3)), diode_names=["a", "b"])


# ----------------------------------------------------------------------------- estimator error

@pytest.mark.parametrize("n", [600, 20])  # 20: a series shorter than the 181-sample window
def test_hanning_band_of_a_constant_is_flat_at_that_constant(tmp_path, n):
    # Oracle: a weighted mean of a constant is the constant and its weighted STD is zero
    # (any normalised weights, so also the thesis' Hanning window of 181 samples).
    fig = plots.plot_estimator_error(np.arange(n, dtype=float), np.full(n, 3.25), path=tmp_path / "err")
    assert _written(tmp_path / "err.png") and _written(tmp_path / "err.pdf")
    ax = fig.axes[0]
    mean = next(a for a in ax.get_lines() if a.get_gid() == "mean:error")
    band = next(c for c in ax.collections if c.get_gid() == "band:error")
    np.testing.assert_allclose(mean.get_ydata(), 3.25, rtol=0, atol=1e-12)
    verts = np.concatenate([p.vertices for p in band.get_paths()])
    np.testing.assert_allclose(verts[:, 1], 3.25, rtol=0, atol=1e-9)
    assert ax.get_ylim()[0] == 0.0 and ax.get_ylim()[1] > 3.25


def test_estimator_error_blanks_eclipse_and_accepts_a_dict(tmp_path, rng):
    n = 1000
    t = np.arange(n, dtype=float)
    sunlit = np.ones(n, bool)
    sunlit[400:600] = False
    errs = {"pinv": np.abs(rng.normal(5.0, 1.0, n)), "wls": np.abs(rng.normal(3.0, 1.0, n))}
    errs["pinv"][100:110] = np.nan  # no estimate while sunlit
    fig = plots.plot_estimator_error(t, errs, sunlit=sunlit, title="two", path=tmp_path / "err2.png")
    assert _written(tmp_path / "err2.png")
    ax = fig.axes[0]
    for name in errs:
        y = next(a for a in ax.get_lines() if a.get_gid() == f"mean:{name}").get_ydata()
        assert np.all(np.isnan(y[400:600])) and np.all(np.isfinite(y[:400]))
    # the caller's arrays are left as they were
    assert np.isfinite(errs["wls"][450])


def test_estimator_error_rejects_bad_input():
    with pytest.raises(ValueError, match=r"1-D time series \(5,\)"):
        plots.plot_estimator_error(np.arange(5.0), np.ones(4))
    with pytest.raises(ValueError, match="sunlit must be a bool array"):
        plots.plot_estimator_error(np.arange(5.0), np.ones(5), sunlit=np.ones(4, bool), window=3)
    with pytest.raises(ValueError, match="time_unit"):
        plots.plot_estimator_error(np.arange(5.0), np.ones(5), window=3, time_unit="days")


# ----------------------------------------------------------------------------- albedo cells

def _one_bright_block(n_lat=180, n_lon=360):
    """A south-first 1 x 1 deg map, zero except a 10 x 10 deg block centred on (lat +60, lon +30)."""
    lat = -90.0 + (np.arange(n_lat) + 0.5) * 180.0 / n_lat
    lon = -180.0 + (np.arange(n_lon) + 0.5) * 360.0 / n_lon
    cells = np.zeros((n_lat, n_lon))
    cells[np.ix_(np.abs(lat - 60.0) < 5.0, np.abs(lon - 30.0) < 5.0)] = 2.0
    return cells, lat, lon


@pytest.mark.parametrize("north_first", [False, True])
def test_albedo_cells_land_north_east_where_they_are(tmp_path, north_first):
    cells, lat, lon = _one_bright_block()
    if north_first:  # the same map given with row 0 the NORTH band must draw the same picture
        cells, lat = cells[::-1], lat[::-1]
    png = tmp_path / "alb.png"
    fig = plots.plot_albedo_cells(cells, lat_deg=lat, lon_deg=lon, scale="linear", path=png)
    ax = fig.axes[0]
    img = next(a for a in ax.get_children() if isinstance(a, AxesImage))
    assert img.origin == "lower"
    np.testing.assert_allclose(img.get_extent(), [-180.0, 180.0, -90.0, 90.0])
    # the brightest colour of the linear scale is the top of the colormap
    top = matplotlib.colormaps["plasma"](1.0)[:3]
    fx, fy, count = _colour_centroid(png, ax, fig, top)
    assert count > 100
    # oracle: equirectangular, lon -180..180 left to right, lat -90..90 bottom to top:
    # (lat 60, lon 30) sits at x = 210/360, y = 150/180 of the axes box (upper-right quadrant)
    assert abs(fx - 210.0 / 360.0) < 0.01 and abs(fy - 150.0 / 180.0) < 0.015


def test_albedo_cells_log_scale_marks_and_background(tmp_path):
    cells, lat, lon = _one_bright_block(90, 180)
    cells[cells > 0] = np.linspace(1e-6, 3.0, int(np.sum(cells > 0)))
    fig = plots.plot_albedo_cells(cells, sat_lat_lon_deg=(55.0, 25.0), sub_solar_lat_lon_deg=(10.0, 390.0),
                                  background=np.full(cells.shape, 0.3), path=tmp_path / "alb_log")
    assert _written(tmp_path / "alb_log.png") and _written(tmp_path / "alb_log.pdf")
    ax = fig.axes[0]
    images = [a for a in ax.get_children() if isinstance(a, AxesImage)]
    assert len(images) == 2  # the background and the cells
    # zero cells are masked (transparent), so the background shows through
    assert np.ma.getmaskarray(images[1].get_array()).sum() == np.sum(cells == 0)
    markers = [(ln.get_xdata()[0], ln.get_ydata()[0]) for ln in ax.get_lines()]
    assert (25.0, 55.0) in markers and (30.0, 10.0) in markers  # lon 390 deg wraps to 30 deg


def test_albedo_cells_in_eclipse_and_bad_input(tmp_path):
    fig = plots.plot_albedo_cells(np.zeros((18, 36)), path=tmp_path / "dark.png")
    assert _written(tmp_path / "dark.png") and "0 lit cells" in fig.get_suptitle()
    with pytest.raises(ValueError, match="negative irradiance"):
        plots.plot_albedo_cells(-np.ones((18, 36)))
    with pytest.raises(ValueError, match=r"lat_deg has 10 cell centres"):
        plots.plot_albedo_cells(np.ones((18, 36)), lat_deg=np.arange(10.0))
    with pytest.raises(ValueError, match="scale must be"):
        plots.plot_albedo_cells(np.ones((18, 36)), scale="sqrt")


# ----------------------------------------------------------------------------- angular response

def test_angular_response_writes_and_marks_fov_and_cutoff(tmp_path):
    theta = np.arange(0.0, 91.0, 5.0)
    cos = np.cos(np.radians(theta))
    traced = cos * (theta < 70.0)
    fig = plots.plot_angular_response(theta, {"ray traced": traced, "cos": cos}, fov_deg=70.0,
                                      errors={"ray traced": np.full(theta.size, 0.01)}, path=tmp_path / "ang")
    assert _written(tmp_path / "ang.png") and _written(tmp_path / "ang.pdf")
    ax = fig.axes[0]
    vertical = sorted(ln.get_xdata()[0] for ln in ax.get_lines() if np.ptp(ln.get_xdata()) == 0
                      and len(ln.get_xdata()) == 2)
    assert vertical == [70.0, 83.1]
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert sorted(labels) == ["cos", "ray traced ($\\pm$2 SE)"]
    with pytest.raises(ValueError, match="no curve of that name"):
        plots.plot_angular_response(theta, {"cos": cos}, errors={"traced": cos})


# ----------------------------------------------------------------------------- coverage map

def test_coverage_fractions_in_the_title(tmp_path):
    counts = np.arange(3072) % 5  # classes red (0, 1, 2), yellow (3), green (4)
    fig = plots.plot_coverage_map(counts, title="pattern", path=tmp_path / "cov")
    assert _written(tmp_path / "cov.png") and _written(tmp_path / "cov.pdf")
    # counted by hand: 3072 = 5 * 614 + 2, so residues 0 and 1 occur 615 times, 2..4 614 times
    red, yellow, green = (615 + 615 + 614) / 3072, 614 / 3072, 614 / 3072
    text = fig.get_suptitle()
    assert text.startswith("pattern\n")
    assert f"red {red:.4f}" in text and f"yellow {yellow:.4f}" in text and f"green {green:.4f}" in text


def test_coverage_map_orientation(tmp_path):
    nside = 16
    theta, phi = hp.pix2ang(nside, np.arange(hp.nside2npix(nside)))
    az = np.degrees(np.arctan2(np.sin(phi), np.cos(phi)))
    el = 90.0 - np.degrees(theta)
    # green patch around azimuth +90 deg (body +y), elevation +45 deg; red elsewhere
    counts = np.where((np.abs(az - 90.0) < 30.0) & (np.abs(el - 45.0) < 20.0), 4, 0)
    normals = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    png = tmp_path / "cov.png"
    fig = plots.plot_coverage_map(counts, normals_body=normals, dead=[1], path=png)
    ax = fig.axes[0]
    fx, fy, count = _colour_centroid(png, ax, fig, matplotlib.colors.to_rgb(plots.COVERAGE_COLOURS[2]))
    assert count > 200
    # oracle: Mollweide with azimuth increasing to the right (as coverage.plot_coverage, flip="geo"):
    # +y (azimuth 90) is right of centre, positive elevation above the equator
    assert fx > 0.6 and fy > 0.6
    with pytest.raises(ValueError, match="HEALPix map"):
        plots.plot_coverage_map(np.zeros(3000))
    with pytest.raises(ValueError, match="dead indices"):
        plots.plot_coverage_map(counts, normals_body=normals, dead=[2])
