"""The annotated scene picture an engineer checks (``sunsim view``): Mitsuba renders, matplotlib labels.

Two views of one epoch of a study (orbit from the TLE, the run's default tumble, Sun):

- the *wide* view: the satellite 0.9 m from a camera that stands 30 deg above the local
  horizontal, 50 deg in azimuth from the Sun, so the view is 60 deg off nadir; the Earth behind
  it coloured by the reflectivity map in use (sunlit side in the colour bar's colours, night side
  dimmed to 40 %) with the coastlines white on black (:mod:`simcore.environment.coastlines`), the
  Earth's limb near the top;
- the *close-up*: the satellite alone (no Earth), four panels side by side, each side panel
  nearly head-on (+-x from 25 deg above, +-y from 25 deg below), so every ramp, well and diode shows.

Mitsuba (``llvm_ad_mono``) path-traces the scene lit by the Sun (and, for legibility only, a
uniform sky of radiance 0.3 E_sun / pi); each satellite part is drawn in its material colour
times the rendered shading (radiance / the part's reflectance). Diode numbers are placed at the
diode centres projected with :meth:`simcore.picture.scene.Camera.project`, the inverse of the camera
handed to Mitsuba. The picture is for looking at, not a radiometric product.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.config import SatelliteConfig
from scenes.meshes import diode_surfaces
from simcore.picture.scene import (_REFLECTANCE, Camera, PictureGeometry, build_scene, load_scene,
                                   render_passes, srgb8)
from simcore.constants import R_EARTH_MEAN_M
from simcore.environment.coastlines import coastlines_deg, lonlat_to_ecef_m
from simcore.environment.earth import Earth

# the view's default instant: 40 min into the default run (2016-07-02T00:00Z), ESTCube-1 in sunlight
DEFAULT_VIEW_TIME = "2016-07-02T00:40:00Z"
FILL_RADIANCE = 0.3       # uniform sky, units of E_sun / pi: faces turned from the Sun stay readable
NIGHT_DIM = 0.4           # the Earth's night side: the colour-map colour times this
WIDE_ELEVATION_DEG = 30.0  # camera above the satellite's local horizontal: the view is 60 deg off nadir
WIDE_AZIMUTH_FROM_SUN_DEG = 50.0
WIDE_DISTANCE_M, WIDE_FOV_DEG = 0.9, 36.0
CLOSE_DISTANCE_M = 0.75
CLOSE_HALF_SIZE_M = (0.085, 0.15)   # what each close-up panel must show around the centre: width, height
CLOSE_PART_REACH = 1.5   # the close-up frames parts up to this multiple of the body's half extents, crops beyond
# each side panel nearly head-on, from 25 deg above (+-x) or below (+-y), so the top and bottom show too
CLOSE_DIRECTIONS = {"+x, above": (0.906, 0.0, 0.423), "+y, below": (0.0, 0.906, -0.423),
                    "-x, above": (-0.906, 0.0, 0.423), "-y, below": (0.0, -0.906, -0.423)}

# display colours (linear RGB) of the part kinds; a kind not listed (a user mesh's part) is drawn as "other"
MATERIAL_RGB = {
    "body": ((0.72, 0.73, 0.76), "body"),
    "ramp": ((0.90, 0.45, 0.05), "ramps"),
    "floor": ((0.45, 0.15, 0.60), "mount floors"),
    "well": ((0.10, 0.10, 0.11), "aperture wells"),
    "diode": ((0.10, 0.40, 1.00), "diodes (sensitive area)"),
}
OTHER_RGB = (0.85, 0.25, 0.65)
SUN_COLOUR = "#ff3b1f"
WINDOW_COLOUR = "#9fd8ff"   # cover glasses: light-blue translucent slabs drawn over the render (not traced here)


@dataclass(frozen=True)
class ViewEpoch:
    """One epoch of a study for the picture: its :class:`PictureGeometry` and what the caption names."""

    geometry: PictureGeometry
    epoch_iso: str
    satellite: str
    illumination: float      # visible fraction of the solar disc (conical shadow), 0 in umbra


def view_epoch(time=DEFAULT_VIEW_TIME, *, tle=None, satellite=None, start="2016-07-02T00:00:00Z",
               spin_rate_deg_s=1.9, attitude_file=None):
    """Return the :class:`ViewEpoch` at ``time`` (ISO UTC) of the study ``sunsim run`` makes with the same options.

    The attitude is the run's default tumble about the body diagonal, started aligned with GCRS at
    ``start`` (the run's ``--start``), or an attitude history (CSV ``t_s,qw,qx,qy,qz``) whose first
    row is ``start``, as ``sunsim run --attitude``; the Sun direction is from the satellite (parallax included).
    """
    from simcore.environment.attitude import Attitude, tumble
    from simcore.errors import InvalidInputError
    from simcore.environment.epochs import Epochs
    from simcore.environment.geometry import compute_geometry
    from simcore.environment.orbit import Orbit

    epochs = Epochs.from_any(time)
    t0 = Epochs.from_any(start)
    if len(epochs) != 1:
        raise ValueError("view_epoch() takes one time")
    orbit = Orbit.default(satellite) if tle is None else Orbit.from_file(tle, satellite=satellite)
    t_s = epochs.seconds_since(t0)
    if attitude_file is None:
        attitude = tumble(t_s, rate_deg_s=spin_rate_deg_s)
    else:
        history = Attitude.from_file(attitude_file)
        span = history.t_s[-1] - history.t_s[0]
        if not 0.0 <= t_s[0] <= span:
            raise InvalidInputError(f"the attitude file {attitude_file} spans {span:g} s from the start {start}, but "
                                    f"the picture's time is {t_s[0]:g} s after it; give a --time within the file")
        attitude = history.resample(history.t_s[0] + t_s)
    g = compute_geometry(orbit, epochs, attitude)
    R_ecef_from_body = g.R_ecef_from_body[0]
    sun_ecef = g.R_ecef_from_gcrs[0] @ g.sun_dir_gcrs[0]
    pg = PictureGeometry(np.asarray(g.r_sat_ecef_m[0], float), sun_ecef, R_ecef_from_body.T)
    return ViewEpoch(pg, epochs.iso()[0], orbit.name, float(g.illumination[0]))


def sun_earth_angles(g, camera=None):
    """Return the caption's numbers (degrees, metres) of a :class:`PictureGeometry` and, optionally, the view's camera.

    ``altitude_m`` over the sphere of radius 6371.01 km; ``sub_lat_deg``/``sub_lon_deg`` geocentric;
    ``sun_to_body_axis_deg`` the angles between the Sun direction and body +x, +y, +z;
    ``sun_above_limb_deg`` the Sun's elevation over the Earth's limb seen from the satellite
    (angle from nadir minus the Earth's angular radius; < 0: behind the Earth);
    ``view_off_nadir_deg`` the angle between the camera's viewing direction and nadir.
    """
    r = np.asarray(g.r_sat_ecef_m, float)
    rn = float(np.linalg.norm(r))
    nadir = -r / rn
    sun = np.asarray(g.sun_dir_ecef, float)
    sun = sun / np.linalg.norm(sun)
    sun_body = np.asarray(g.R_body_from_ecef, float) @ sun
    out = {
        "altitude_m": rn - R_EARTH_MEAN_M,
        "sub_lat_deg": float(np.degrees(np.arcsin(r[2] / rn))),
        "sub_lon_deg": float(np.degrees(np.arctan2(r[1], r[0]))),
        "sun_to_body_axis_deg": np.degrees(np.arccos(np.clip(sun_body, -1.0, 1.0))),
        "sun_above_limb_deg": float(np.degrees(np.arccos(np.clip(sun @ nadir, -1.0, 1.0))
                                               - np.arcsin(R_EARTH_MEAN_M / rn))),
    }
    if camera is not None:
        nadir_body = np.asarray(g.R_body_from_ecef, float) @ nadir
        # atan2(|a x b|, a . b): well conditioned at 0 deg, where acos of a dot product one ulp below 1 is
        # already 1.2e-6 deg (a camera looking straight down)
        look = np.asarray(camera.look_dir, float)
        out["view_off_nadir_deg"] = float(np.degrees(np.arctan2(np.linalg.norm(np.cross(look, nadir_body)),
                                                                look @ nadir_body)))
    return out


def wide_camera(g, width, height):
    """Return the wide view's :class:`Camera` (render frame): 30 deg above the horizontal, 50 deg from the Sun's bearing."""
    R = np.asarray(g.R_body_from_ecef, float)
    zenith = R @ (np.asarray(g.r_sat_ecef_m, float) / np.linalg.norm(g.r_sat_ecef_m))
    sun = R @ np.asarray(g.sun_dir_ecef, float)
    horiz = sun - (sun @ zenith) * zenith
    if np.linalg.norm(horiz) < 1e-6:      # the Sun at the zenith or nadir: any bearing will do
        horiz = np.cross(zenith, [1.0, 0.0, 0.0] if abs(zenith[0]) < 0.9 else [0.0, 1.0, 0.0])
    horiz /= np.linalg.norm(horiz)
    a = np.radians(WIDE_AZIMUTH_FROM_SUN_DEG)
    bearing = np.cos(a) * horiz + np.sin(a) * np.cross(zenith, horiz)
    e = np.radians(WIDE_ELEVATION_DEG)
    c = np.cos(e) * bearing + np.sin(e) * zenith
    return Camera(tuple(WIDE_DISTANCE_M * c), (0.0, 0.0, 0.0), tuple(zenith), WIDE_FOV_DEG, int(width), int(height))


def close_up_cameras(width, height, half_size_m=CLOSE_HALF_SIZE_M, distance_m=CLOSE_DISTANCE_M):
    """Return {label: :class:`Camera`} of the close-up's four panels side by side (width split in four), body z up,
    each showing ``half_size_m`` (width, height) around the centre from ``distance_m``."""
    n = len(CLOSE_DIRECTIONS)
    widths = [width // n + (1 if i < width % n else 0) for i in range(n)]
    cams = {}
    for (label, d), w in zip(CLOSE_DIRECTIONS.items(), widths):
        d = np.asarray(d, float) / np.linalg.norm(d)
        w = max(int(w), 1)
        tan_x = max(half_size_m[0], half_size_m[1] * w / height) / distance_m
        cams[label] = Camera(tuple(distance_m * d), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0),
                             float(np.degrees(2 * np.arctan(tan_x))), w, int(height))
    return cams


def close_up_framing(config):
    """Return (half_size_m (width, height), distance_m) of the close-up's panels for a configuration.

    Framed on the body and the parts near it (an antenna, a baffle); a part reaching further than
    ``CLOSE_PART_REACH`` x the body's half extents (a deployed wing) is cropped at that reach, so that
    the body, and the diodes on it, fill the panel instead of shrinking to a few pixels beside the
    wings; a diode on a part is kept in view. The camera stays outside every part: 3 x the farthest
    reach from the centre.
    """
    body_half = np.asarray(config.body.size_m) / 2.0
    pts = [body_half] + [np.minimum(np.abs(p.vertices_m), CLOSE_PART_REACH * body_half) for p in config.parts]
    pts += [np.abs(d.position_body_m) + 0.01 for d in config.diodes if d.part is not None]   # diodes on parts too
    ext = np.vstack(pts).max(axis=0)
    # seen 25 deg from the horizontal, the satellite spans ext_z cos 25 + ext_xy sin 25 above and below the
    # centre; it fills 72 % of the panel's height, leaving room for the legend, the panel titles and the caption
    # (the 2U body, narrow panels framed by its width, fills 65 %)
    sin_e = abs(next(iter(CLOSE_DIRECTIONS.values()))[2])
    tall = (ext[2] * np.sqrt(1.0 - sin_e ** 2) + max(ext[0], ext[1]) * sin_e) / 0.72
    half = (max(CLOSE_HALF_SIZE_M[0], 1.15 * float(max(ext[0], ext[1]))), max(CLOSE_HALF_SIZE_M[1], float(tall)))
    reach = np.vstack([body_half] + [np.abs(p.vertices_m) for p in config.parts]).max()
    return half, max(CLOSE_DISTANCE_M, 3.0 * float(reach))


def _earth_rgb(passes, g, rmap):
    """Return (H, W, 3) linear RGB of the Earth pixels: the map's colour, dimmed on the night side; and the mask."""
    import matplotlib

    mask = passes.kind == "earth"
    R = np.asarray(g.R_body_from_ecef, float)
    r_sat_body = R @ np.asarray(g.r_sat_ecef_m, float)
    p_ecef = (passes.hit_m[mask] + r_sat_body) @ R          # R^T (p - Earth centre), row vectors
    p_ecef /= np.linalg.norm(p_ecef, axis=1, keepdims=True)
    lat = np.degrees(np.arcsin(np.clip(p_ecef[:, 2], -1, 1)))
    lon = np.degrees(np.arctan2(p_ecef[:, 1], p_ecef[:, 0]))
    values = np.asarray(rmap.values_south_first, float)
    row = np.clip(np.floor((lat + 90.0) / rmap.dlat_deg).astype(int), 0, rmap.n_lat - 1)
    col = np.clip(np.floor(np.mod(lon - rmap.lon_edges_deg[0], 360.0) / rmap.dlon_deg).astype(int), 0, rmap.n_lon - 1)
    cmap, norm = _earth_colour_map(rmap)
    rgb = np.asarray(cmap(norm(values[row, col])))[:, :3]
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)   # colour map is sRGB
    day = p_ecef @ np.asarray(g.sun_dir_ecef, float) > 0.0
    lin[~day] *= NIGHT_DIM
    out = np.zeros(mask.shape + (3,))
    out[mask] = lin
    return out, mask


def _earth_colour_map(rmap):
    import matplotlib

    top = max(1.0, float(np.ceil(np.max(rmap.values) * 10.0) / 10.0))
    return matplotlib.colormaps["viridis"], matplotlib.colors.Normalize(0.0, top)


def _material_name(material):
    """Return a short name of a material (scenes.materials: a name, or a Mitsuba BSDF table)."""
    return material if isinstance(material, str) else f"Mitsuba {material.get('type', 'BSDF')}"


def _legend_label(kind, config):
    """Return the legend label of a kind of part, with the material the configuration gives it (the display
    colour tells the kinds apart; the material is what the renderer reflects light with)."""
    if kind == "body":
        return f"body ({_material_name(config.body.material)})"
    if kind in ("ramp", "floor", "well"):
        return f"{MATERIAL_RGB[kind][1]} ({_material_name(config.mount.material)})"
    if kind in MATERIAL_RGB:
        return MATERIAL_RGB[kind][1]
    parts = [p for p in config.parts if kind in ("part", f"part_{p.name}")]
    if parts:
        return "parts: " + ", ".join(f"{p.name} ({_material_name(p.material)})" for p in parts)
    return kind


def _satellite_rgb(passes):
    """Return (H, W, 3) linear RGB of the satellite pixels: material colour x rendered shading; and the mask."""
    mask = (passes.kind != "") & (passes.kind != "earth")
    out = np.zeros(passes.kind.shape + (3,))
    for kind in np.unique(passes.kind[mask]):
        sel = passes.kind == kind
        colour = np.asarray(MATERIAL_RGB.get(kind, (OTHER_RGB,))[0])
        shade = np.clip(passes.radiance[sel] / _REFLECTANCE.get(kind, _REFLECTANCE["body"]), 0.0, 1.0)
        out[sel] = shade[:, None] * colour
    return out, mask


@dataclass(frozen=True)
class Panel:
    """One rendered panel of a view: its camera, render passes, sRGB image (H, W, 3) and the diodes labelled."""

    label: str
    camera: Camera
    passes: object
    rgb: np.ndarray
    labelled: tuple


def _render_panel(config, g, camera, earth, show_earth, spp, seed, label):
    earth = Earth() if earth is None else earth
    rmap = earth.map
    scene_dict, names, kinds, _ = build_scene(config, g, camera=camera, earth=earth, show_earth=show_earth,
                                              fill_radiance=FILL_RADIANCE, spp=spp)
    passes = render_passes(load_scene(scene_dict), names, kinds, spp, seed)
    sat, _ = _satellite_rgb(passes)
    lin = sat
    if show_earth:
        ground, _ = _earth_rgb(passes, g, rmap)
        lin = lin + ground
    return Panel(label, camera, passes, srgb8(lin), visible_diodes(config, camera, passes))


def window_outlines(config, camera):
    """Return [(diode index, pixel polygon (M, 2))]: the outline of each diode's window (its slab's eight corners
    projected, convex hull) that faces the camera (windows behind the body's far side are not drawn)."""
    from scipy.spatial import ConvexHull
    out = []
    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    for d in config.diodes:
        w = d.window
        if w is None:
            continue
        u, v, n = d.frame_body
        base = d.position_body_m + w.gap_m * n
        if (np.asarray(camera.origin_m) - base) @ n <= 0:
            continue
        ring = base + sq[:, :1] * (w.size_m[0] / 2) * u + sq[:, 1:] * (w.size_m[1] / 2) * v
        xy, depth = camera.project(np.vstack([ring, ring + w.thickness_m * n]))
        if not np.all(depth > 0):
            continue
        out.append((d.index, xy[ConvexHull(xy).vertices]))
    return out


def visible_diodes(config, camera, passes, radius_px=4):
    """Return (index, pixel xy of the label) of the diodes the camera sees, in index order.

    A diode is seen when it faces the camera and, within ``radius_px`` of its projected centre,
    the first hit is that diode's sensitive square, well, floor or ramp (a ramp may hide the well's mouth).
    """
    surf = diode_surfaces(config)
    h, w = passes.name.shape
    out = []
    for d in config.diodes:
        k = d.index
        centre = surf.vertices[4 * k:4 * k + 4].mean(axis=0)
        if (np.asarray(camera.origin_m) - centre) @ d.normal_body <= 0:
            continue
        xy, depth = camera.project(centre)
        if not depth[0] > 0:
            continue
        i, j = int(np.floor(xy[0, 1])), int(np.floor(xy[0, 0]))
        if not (0 <= i < h and 0 <= j < w):
            continue
        near = passes.name[max(0, i - radius_px):i + radius_px + 1, max(0, j - radius_px):j + radius_px + 1]
        if np.isin(near, [f"diode_{k}", f"well_{k}", f"floor_{k}", f"ramp_{k}"]).any():
            out.append((k, camera.project(centre + 0.012 * d.normal_body)[0][0]))
    return tuple(out)


def coastline_segments(g, camera, passes, radius_m=R_EARTH_MEAN_M):
    """Return the visible coastline as (M, 2, 2) pixel segments (x right, y down) of the camera's image.

    A coastline point is visible when it faces the camera (in front of the Earth's limb) and the
    first hit at its pixel is the Earth (not the satellite). Segments along the date line, where
    the data cut polygons in two, are not coastline and are left out.
    """
    R = np.asarray(g.R_body_from_ecef, float)
    centre = -R @ np.asarray(g.r_sat_ecef_m, float)
    origin = np.asarray(camera.origin_m, float)
    h, w = passes.kind.shape
    out = []
    for line in coastlines_deg():
        p = lonlat_to_ecef_m(line, radius_m) @ R.T + centre
        xy, depth = camera.project(p)
        ok = ((origin - p) * (p - centre)).sum(axis=1) > 0.0
        ok &= depth > 0
        ok &= np.all(np.isfinite(xy), axis=1) & (xy[:, 0] >= 0) & (xy[:, 0] < w) & (xy[:, 1] >= 0) & (xy[:, 1] < h)
        j = np.clip(np.floor(np.nan_to_num(xy[:, 0])).astype(int), 0, w - 1)
        i = np.clip(np.floor(np.nan_to_num(xy[:, 1])).astype(int), 0, h - 1)
        ok &= passes.kind[i, j] == "earth"
        seg = ok[:-1] & ok[1:] & ~((np.abs(line[:-1, 0]) > 179.9) & (np.abs(line[1:, 0]) > 179.9))
        if seg.any():
            out.append(np.stack([xy[:-1][seg], xy[1:][seg]], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2, 2))


def _arrow(ax, camera, vec_body, length_m, colour, text, fs, dashed=False, dx=0.0):
    """Draw a 3-D arrow from the satellite centre along ``vec_body``, projected; a marker when it points at the camera."""
    from matplotlib import patheffects

    v = np.asarray(vec_body, float) / np.linalg.norm(vec_body)
    dist = float(np.linalg.norm(camera.origin_m))
    toward = v @ (np.asarray(camera.origin_m) / dist)
    length = min(length_m, 0.6 * dist / max(toward, 1e-6)) if toward > 0 else length_m
    (x0, y0), (x1, y1) = camera.project(np.zeros(3))[0][0], camera.project(length * v)[0][0]
    # keep the head inside the frame (matplotlib drops an annotation whose head is outside)
    # room for the label beside the head, and for the legend (top) and the two-line caption (bottom)
    px = fs * 100.0 / 72.0                        # one font size in pixels at the figure's 100 dpi
    mx = 0.15 * camera.width
    scale = 1.0
    for lo, hi, a0, a1 in ((mx, camera.width - mx, x0, x1), (2.0 * px, camera.height - 4.0 * px, y0, y1)):
        if a1 > hi and a1 != a0:
            scale = min(scale, (hi - a0) / (a1 - a0))
        if a1 < lo and a1 != a0:
            scale = min(scale, (lo - a0) / (a1 - a0))
    scale = max(scale, 0.0)
    x1, y1 = x0 + scale * (x1 - x0) + dx, y0 + scale * (y1 - y0)
    x0 = x0 + dx
    stroke = [patheffects.withStroke(linewidth=max(1.0, fs / 4), foreground="black")]
    ax.annotate("", xy=(x1, y1), xytext=(x0, y0), annotation_clip=False,
                arrowprops=dict(arrowstyle="-|>", color=colour, lw=max(1.0, fs / 6), ls="--" if dashed else "-",
                                mutation_scale=fs * 1.2, path_effects=stroke))
    right = x1 >= x0
    ax.text(x1, y1, f" {text}" if right else f"{text} ", color=colour, clip_on=False, fontsize=fs, fontweight="bold",
            ha="left" if right else "right", va="center", path_effects=stroke)


def view_picture(config, path_png, view_epoch_, *, close_up=False, earth=None, resolution=(960, 540),
                 spp=64, seed=0):
    """Render and annotate the view; write a PNG of exactly ``resolution`` pixels and return its :class:`Panel` list.

    ``config``: a :class:`SatelliteConfig` or a name; ``view_epoch_``: a :class:`ViewEpoch`;
    ``earth``: a :class:`simcore.environment.earth.Earth` (default the TOMS 2005 Earth), its map shown with a
    colour bar; ``close_up`` draws the satellite alone from four sides (:func:`close_up_framing`).
    """
    from matplotlib import patheffects
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colorbar import ColorbarBase
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    if not isinstance(config, SatelliteConfig):
        config = SatelliteConfig.load(config)
    earth = Earth() if earth is None else earth
    rmap = earth.map
    g = view_epoch_.geometry
    width, height = int(resolution[0]), int(resolution[1])
    if close_up:
        cams = close_up_cameras(width, height, *close_up_framing(config))
    else:
        cams = {"": wide_camera(g, width, height)}
    panels = [_render_panel(config, g, cam, earth, not close_up, spp, seed, label) for label, cam in cams.items()]

    dpi = 100.0
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor="black")
    FigureCanvasAgg(fig)
    fs = max(4.0, height / 50.0)
    stroke = [patheffects.withStroke(linewidth=max(1.0, fs / 4), foreground="black")]
    R = np.asarray(g.R_body_from_ecef, float)
    sun_body = R @ np.asarray(g.sun_dir_ecef, float)
    nadir_body = -R @ (np.asarray(g.r_sat_ecef_m, float) / np.linalg.norm(g.r_sat_ecef_m))
    eclipsed = view_epoch_.illumination <= 0.0
    x0 = 0
    for p in panels:
        w = p.camera.width
        ax = fig.add_axes((x0 / width, 0.0, w / width, 1.0))
        x0 += w
        ax.imshow(p.rgb, extent=(0, w, height, 0), interpolation="nearest")
        ax.set_xlim(0, w)
        ax.set_ylim(height, 0)
        ax.set_axis_off()
        if not close_up:
            from matplotlib.collections import LineCollection
            lw = max(0.5, fs / 14)
            ax.add_collection(LineCollection(coastline_segments(g, p.camera, p.passes, rmap.radius_m),
                                             colors="white", linewidths=lw, path_effects=[
                                                 patheffects.withStroke(linewidth=2.5 * lw, foreground="black")]))
    # annotations on one transparent overlay, so a label near a panel's edge is not covered by the next panel
    ov = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ov.set_xlim(0, width)
    ov.set_ylim(height, 0)
    ov.set_axis_off()
    ov.patch.set_alpha(0.0)
    dx = 0
    windows = False
    for p in panels:
        for _, poly in window_outlines(config, p.camera):
            from matplotlib.patches import Polygon
            ov.add_patch(Polygon(poly + [dx, 0], closed=True, facecolor=WINDOW_COLOUR, alpha=0.35,
                                 edgecolor=WINDOW_COLOUR, linewidth=max(0.5, fs / 12)))
            windows = True
        dx += p.camera.width
    dx = 0
    for p in panels:
        # diode numbers above the arrows (zorder): an arrow from the centre passes over a face-centre diode
        for k, (x, y) in p.labelled:
            ov.text(x + dx, y, str(k), color="white", fontsize=fs, fontweight="bold", ha="center", va="center",
                    path_effects=stroke, zorder=4)
        length = 0.2 if not close_up else 0.17
        _arrow(ov, p.camera, sun_body, length, SUN_COLOUR, "Sun (eclipsed)" if eclipsed else "Sun", fs,
               dashed=eclipsed, dx=dx)
        if close_up:
            _arrow(ov, p.camera, nadir_body, 0.15, "#40c0ff", "nadir", fs, dx=dx)
            ov.text(dx + p.camera.width / 2, 0.10 * height, f"from {p.label}", color="white", fontsize=fs,
                    ha="center", va="top", path_effects=stroke)
        dx += p.camera.width
    a = sun_earth_angles(g, panels[0].camera)
    sx, sy, sz = a["sun_to_body_axis_deg"]
    ns, ew = ("N" if a["sub_lat_deg"] >= 0 else "S"), ("E" if a["sub_lon_deg"] >= 0 else "W")
    view = (f"view {a['view_off_nadir_deg']:.0f}\N{DEGREE SIGN} off nadir" if not close_up
            else "close-up, no Earth")
    light = "in the Earth's shadow" if eclipsed else (
        "sunlit" if view_epoch_.illumination >= 1.0 else f"penumbra, {view_epoch_.illumination:.0%} of the disc")
    caption = (f"{config.name}  |  {view_epoch_.satellite}  |  {view_epoch_.epoch_iso} UTC  |  "
               f"altitude {a['altitude_m'] / 1e3:.1f} km over {abs(a['sub_lat_deg']):.1f}\N{DEGREE SIGN}{ns} "
               f"{abs(a['sub_lon_deg']):.1f}\N{DEGREE SIGN}{ew}  |  {view}\n"
               f"Sun {a['sun_above_limb_deg']:+.1f}\N{DEGREE SIGN} over the Earth's limb ({light})  |  "
               f"Sun to body +x {sx:.1f}\N{DEGREE SIGN}, +y {sy:.1f}\N{DEGREE SIGN}, +z {sz:.1f}\N{DEGREE SIGN}")
    fig.text(0.005, 0.005, caption, color="white", fontsize=fs * 0.9, ha="left", va="bottom",
             bbox=dict(facecolor="black", alpha=0.6, edgecolor="none", pad=2))
    kinds = [k for k in MATERIAL_RGB if any((p.passes.kind == k).any() for p in panels)]
    others = sorted({k for p in panels for k in np.unique(p.passes.kind)} - set(MATERIAL_RGB) - {"", "earth"})
    handles = [Patch(color=srgb8(MATERIAL_RGB[k][0]) / 255.0, label=_legend_label(k, config)) for k in kinds]
    handles += [Patch(color=srgb8(OTHER_RGB) / 255.0, label=_legend_label(k, config)) for k in others]
    if windows:
        idx = sorted({w.index for w in config.windows if w is not None})
        handles.append(Patch(facecolor=WINDOW_COLOUR, edgecolor=WINDOW_COLOUR,
                             label="cover glass" + ("es, n " if len(idx) > 1 else ", n ") + "/".join(f"{i:g}" for i in idx)))
    if handles:
        leg = fig.legend(handles=handles, loc="upper center" if close_up else "upper left", fontsize=fs * 0.8,
                         ncol=len(handles) if close_up else 1, frameon=True, framealpha=0.6,
                         facecolor="black", edgecolor="none", labelcolor="white", borderaxespad=0.3,
                         handlelength=1.0)
        leg.set_zorder(5)
    if not close_up:
        cmap, norm = _earth_colour_map(rmap)
        cax = fig.add_axes((0.955, 0.32, 0.012, 0.55))
        cb = ColorbarBase(cax, cmap=cmap, norm=norm, orientation="vertical")
        cb.ax.tick_params(labelsize=fs * 0.75, colors="white")
        cb.outline.set_edgecolor("white")
        cb.set_label(f"Earth: {rmap.name} reflectivity\n(night side dimmed; coastlines white on black)", color="white", fontsize=fs * 0.8)
        cb.ax.yaxis.set_label_position("left")
    fig.savefig(str(path_png), dpi=dpi, facecolor="black")
    return panels
