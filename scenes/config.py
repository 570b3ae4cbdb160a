"""Satellite configurations as data: TOML files expanded to diodes in the body frame.

A configuration is a 2U CubeSat body plus a list of photodiodes, each with a
unit normal, a mounting panel, a position on that panel, a tilting ramp and a
well aperture (:class:`simcore.shapes.aperture.WellAperture`). The shipped files are
the thesis' layouts (sec. 3.2.4, figures 3.7-3.13); the format is described
in ``scenes/FORMAT.md`` so users can write their own.

Geometry of one mount (all in the body frame, see ``docs/conventions.md``):
the diode's sensitive surface is a square centred at ``position_body_m`` with
edges along the diode frame's ``u``, ``v`` axes (``diode_frame(normal)``).
Around it lies an opaque floor plate (``floor_mm`` thick, top flush with the
diode surface) and on it the well's straight walls (``wall_mm`` thick, up to
``aperture.height_m`` above the diode surface). Under the floor a ramp (a
convex prism) carries the assembly down to the panel; the diode centre is
lifted along the panel normal just enough that the lowest corner of the floor
sits ``base_mm`` above the panel. The total height of the mount above the
panel must fit in the launch pod's clearance (9 mm for NUTS, thesis sec. 4.2.1).
Extra parts (``[[part]]``) are built by :mod:`scenes.parts`, the small rules of a declaration (keys, lengths
in mm, normals) are :mod:`scenes.declared`'s.
"""
from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from simcore.shapes.aperture import EQ415_CUTOFF_DEG, CircularWell, WellAperture, diode_frame
from simcore.constants import BPW34_AREA_M2
from simcore.shapes.occlusion import convex_hull
from simcore.shapes.window import INDEX_RANGE, Window
from scenes.declared import MM, ConfigError, body_none as _flag, check_keys, diode_type, unit_normal, vector3
from scenes.materials import DEFAULT as DEFAULT_MATERIAL, check_material
from scenes.parts import build_part, validate_parts
from scenes.sanity import check_scene

CONFIG_DIR = Path(__file__).resolve().parent

# Body defaults: a 2U CubeSat envelope (CubeSat Design Specification rev. 14:
# 100 x 100 x 227 mm, 8.5 mm square rails) and the NUTS launch-pod clearance
# (thesis sec. 4.2.1: 9 mm from the panel surface to the pod interior).
BODY_DEFAULTS = {"size_mm": [100.0, 100.0, 227.0], "rail_mm": 8.5, "clearance_mm": 9.0, "material": "black",
                 "none": False}
MOUNT_DEFAULTS = {"wall_mm": 0.5, "floor_mm": 0.5, "base_mm": 0.5, "material": "black"}
LAYOUT_DEFAULTS = {"pattern": None, "tilt_deg": None, "fov_deg": None, "extra_flat_diodes": False,
                   "triangle_mm": [22.0, 40.0], "extra_offset_mm": 25.0, "window": None}
DIODE_KEYS = ("name", "panel", "part", "normal", "az_deg", "el_deg", "at_mm", "fov_deg", "well", "window")
WINDOW_KEYS = ("index", "thickness_mm", "gap_mm", "size_mm", "absorption_per_mm")
# A diode on a part sits on the part's surface: its at_mm may miss the surface by this much (CAD rounding)
ON_SURFACE_TOLERANCE_M = 0.5e-3
WELL_KEYS = ("height_mm", "opening_mm", "chamfer_mm", "chamfer_deg", "shape", "diameter_mm")
ROUND_WELL_KEYS = ("shape", "height_mm", "diameter_mm")
WELL_REQUIRED = ("height_mm", "opening_mm")
TOP_KEYS = ("name", "description", "dead", "body", "mount", "layout", "diode", "part", "diode_type")
PATTERNS = ("faces6", "thesis14")
TILT_RANGE_DEG = (0.0, 45.0)
PANELS = ("+x", "+y", "-x", "-y", "+z", "-z")

# SPEC sec. 5 / thesis sec. 3.2.4: panel azimuth and the (s_az, s_el) triangle of each side panel.
_SIDE_PANELS = (("+x", 0.0), ("+y", 90.0), ("-x", 180.0), ("-y", 270.0))
_TRIANGLE = {"+x": ((-1, -1), (0, +1), (+1, -1)), "-x": ((-1, -1), (0, +1), (+1, -1)),
             "+y": ((-1, +1), (0, -1), (+1, +1)), "-y": ((-1, +1), (0, -1), (+1, +1))}


def list_configs():
    """Return the names of the shipped configurations (sorted), usable with :meth:`SatelliteConfig.load`."""
    return sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))



def _merged(table, defaults, where):
    table = {} if table is None else table
    if not isinstance(table, dict):
        raise ConfigError(f"[{where}] must be a table, got {table!r}")
    check_keys(table, tuple(defaults), f"[{where}]")
    return {**defaults, **table}


def panel_axes(panel):
    """Return (p, t, a): the panel's outward unit normal and its in-plane (lateral, along) axes, body frame.

    Side panels: ``a`` is body z, ``t = z x p``. Top/bottom: ``t`` is body x, ``a = p x t``.
    Always ``t x a = p``.
    """
    if panel not in PANELS:
        close = difflib.get_close_matches(str(panel), PANELS, n=2, cutoff=0.3)
        raise ConfigError(f"unknown panel {panel!r}; use one of {', '.join(PANELS)}"
                          + (f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""))
    axis = "xyz".index(panel[1])
    p = np.zeros(3)
    p[axis] = 1.0 if panel[0] == "+" else -1.0
    if axis < 2:
        a = np.array([0.0, 0.0, 1.0])
        t = np.cross(a, p)
    else:
        t = np.array([1.0, 0.0, 0.0])
        a = np.cross(p, t)
    return p, t, a


def normal_from_az_el(az_deg, el_deg):
    """Return the unit normal (body frame) for azimuth from +x toward +y and elevation toward +z (SPEC sec. 5)."""
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


@dataclass(frozen=True)
class Mount:
    """Mechanical parameters shared by all diode mounts of a configuration (metres)."""

    wall_m: float
    floor_m: float
    base_m: float
    material: object = DEFAULT_MATERIAL  # of the ramps, floors and wells (scenes.materials)


@dataclass(frozen=True)
class Body:
    """The satellite envelope (metres), centred at the body origin, z the long axis."""

    size_m: tuple
    rail_m: float
    clearance_m: float
    material: object = DEFAULT_MATERIAL  # scenes.materials: a name or a Mitsuba BSDF dict
    none: bool = False    # [body] none = true: the panels place the diodes, but no body is rendered or shadows

    def panel_centre_m(self, panel):
        """Return the centre of a panel's outer surface (body frame, m)."""
        p, _, _ = panel_axes(panel)
        return p * (np.abs(p) @ np.asarray(self.size_m)) / 2.0

    def panel_half_extent_m(self, panel):
        """Return the usable half extents (lateral, along) of a panel between the rails (m)."""
        _, t, a = panel_axes(panel)
        size = np.asarray(self.size_m)
        half_t = np.abs(t) @ size / 2.0 - self.rail_m
        # the rails run the full length of the side panels, so only the top/bottom lose them along a
        half_a = np.abs(a) @ size / 2.0 - (self.rail_m if panel[1] == "z" else 0.0)
        return np.array([half_t, half_a])


@dataclass(frozen=True, eq=False)
class MountedDiode:
    """One photodiode: identity, orientation, position and aperture (body frame, SI)."""

    index: int
    name: str
    normal_body: np.ndarray
    frame_body: np.ndarray
    position_body_m: np.ndarray
    aperture: WellAperture  # or CircularWell (a round well)
    fov_deg: float
    panel: str        # None for a diode on a part
    at_m: np.ndarray  # (lateral, along) position of the mount's foot on the panel, metres; on a part: (x, y, z) in
    #                   the part's own coordinates
    part: str = None  # the [[part]] it sits on (instead of a panel)
    surface_normal_body: np.ndarray = None   # on a part: the outward normal of the part's surface under it
    window: Window = None  # a cover glass / filter over the diode (simcore.shapes.window), or None
    note: str = ""         # e.g. a normal written to a few digits, normalised (scenes/declared.py)

    def mount_corners_m(self, mount):
        """Return (floor_bottom (4, 3), wall_top (4, 3)) outer corners of the mount (body frame, m).

        Corners run (-u,-v), (+u,-v), (+u,+v), (-u,+v) around the outer square of side
        ``opening + 2 wall``.
        """
        return _mount_corners(self.frame_body, self.position_body_m, self.aperture, mount)


def _outer_half_m(aperture, mount):
    return np.array([aperture.opening_x_m, aperture.opening_y_m]) / 2.0 + mount.wall_m


def _mount_corners(frame, centre, aperture, mount):
    u, v, n = frame
    hx, hy = _outer_half_m(aperture, mount)
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    sq = signs[:, :1] * hx * u + signs[:, 1:] * hy * v
    return centre + sq - mount.floor_m * n, centre + sq + aperture.height_m * n


def _place(frame, panel, at_m, aperture, body, mount):
    """Return the diode surface centre (body frame, m): the lowest floor corner sits base_m above the panel."""
    p, t, a = panel_axes(panel)
    foot = body.panel_centre_m(panel) + at_m[0] * t + at_m[1] * a
    u, v, n = frame
    hx, hy = _outer_half_m(aperture, mount)
    lift = mount.base_m + hx * abs(u @ p) + hy * abs(v @ p) + mount.floor_m * (n @ p)
    return foot + lift * p


def _round_well(well, fov_deg, where):
    """Return (CircularWell, fov_deg) for a diode's well = {shape = "round", diameter_mm, height_mm}."""
    extra = sorted(set(well) - set(ROUND_WELL_KEYS))
    if extra:
        raise ConfigError(f"{where}: a round well takes {', '.join(ROUND_WELL_KEYS)}, not {', '.join(extra)}")
    missing = [k for k in ROUND_WELL_KEYS if k not in well]
    if missing:
        raise ConfigError(f"{where}: the round well needs {', '.join(missing)} (mm)")
    side = float(np.sqrt(BPW34_AREA_M2))
    try:
        aperture = CircularWell(side, side, float(well["diameter_mm"]) * MM / 2.0, float(well["height_mm"]) * MM)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: invalid round well {well!r}: {exc} (the BPW34's diagonal is "
                          f"{side * np.sqrt(2.0) / MM:.2f} mm)") from None
    # fully lit along a wall axis while the shifted circle still holds the diode's far corners
    r, a = aperture.radius_m, side / 2.0
    full = 90.0 if aperture.height_m == 0 else float(np.degrees(np.arctan2(np.sqrt(r * r - a * a) - a,
                                                                           aperture.height_m)))
    return aperture, (full if fov_deg is None else float(fov_deg))


def _check_chamfer(aperture, mount, where):
    """Raise a one-line ConfigError when a well's chamfer would cut through its walls (a panel's or a part's diode)."""
    widen_m = aperture.rims[5] - aperture.rims[2]
    if widen_m >= mount.wall_m:
        raise ConfigError(f"{where}: the well's chamfer widens the opening by {widen_m / MM:.3f} mm on each side, "
                          f"through the {mount.wall_m / MM:g} mm wall; make chamfer_mm x tan(chamfer_deg) smaller "
                          "than [mount] wall_mm")


def _aperture_for(fov_deg, well, where):
    """Return (WellAperture, fov_deg) for a diode: designed from the FOV (eq. 4.15) or an explicit well."""
    if well is not None:
        if not isinstance(well, dict):
            raise ConfigError(f"{where}: 'well' must be a table {{height_mm = ..., opening_mm = [x, y]}}")
        check_keys(well, WELL_KEYS, f"{where} well")
        if well.get("shape", "square") == "round":
            return _round_well(well, fov_deg, where)
        if well.get("shape", "square") != "square" or "diameter_mm" in well:
            raise ConfigError(f"{where}: a well's shape is \"square\" (the default: opening_mm = [x, y]) or \"round\" "
                              f"(diameter_mm), got shape = {well.get('shape', 'square')!r}"
                              + (" with diameter_mm" if "diameter_mm" in well else ""))
        missing = [k for k in WELL_REQUIRED if k not in well]
        if missing:
            raise ConfigError(f"{where}: the well needs {', '.join(missing)} (mm)")
        side = float(np.sqrt(BPW34_AREA_M2))
        try:
            ox, oy = (float(x) * MM for x in well["opening_mm"])
            aperture = WellAperture(side, side, ox, oy, float(well["height_mm"]) * MM,
                                    float(well.get("chamfer_mm", 0.0)) * MM, float(well.get("chamfer_deg", 0.0)))
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: invalid well {well!r}: {exc}") from None
        if aperture.height_m == 0:
            full_deg = 90.0
        else:
            _, _, wx, wy, h_low, tx, ty, h_top = aperture.rims       # fully lit while inside both rims
            full_deg = float(np.degrees(min(np.arctan2(min(wx, wy) - side / 2.0, h_low),
                                            np.arctan2(min(tx, ty) - side / 2.0, h_top))))
        return aperture, (full_deg if fov_deg is None else float(fov_deg))
    if fov_deg is None:
        raise ConfigError(f"{where}: give fov_deg (or an explicit well)")
    fov = float(fov_deg)
    if not 0.0 < fov <= 90.0:
        raise ConfigError(f"{where}: fov_deg must lie in (0, 90] deg, got {fov_deg}")
    if fov == 90.0:
        return WellAperture.bare(), fov
    if fov >= EQ415_CUTOFF_DEG:
        raise ConfigError(f"{where}: an FOV of {fov} deg cannot be realised by a well that cuts light off at "
                          f"{EQ415_CUTOFF_DEG:.2f} deg (eq. 4.15); use fov_deg < {EQ415_CUTOFF_DEG:.2f} or 90 (bare diode)")
    return WellAperture.design(fov), fov


def _sign(s):
    return "0" if s == 0 else f"{s:+d}"


def expand_layout(layout, where="[layout]"):
    """Return the diode tables of a parametric layout (SPEC sec. 5), in the shipped index order."""
    pattern = layout["pattern"]
    if pattern is None:
        raise ConfigError(f"{where}: give pattern = one of {', '.join(map(repr, PATTERNS))}")
    if pattern not in PATTERNS:
        close = difflib.get_close_matches(str(pattern), PATTERNS, n=1, cutoff=0.3)
        raise ConfigError(f"{where}: unknown pattern {pattern!r}; use one of {', '.join(PATTERNS)}"
                          + (f" (did you mean {close[0]!r}?)" if close else ""))
    tilt, fov = layout["tilt_deg"], layout["fov_deg"]
    if tilt is None or fov is None:
        raise ConfigError(f"{where}: pattern {pattern!r} needs tilt_deg and fov_deg")
    tilt = float(tilt)
    if not TILT_RANGE_DEG[0] <= tilt <= TILT_RANGE_DEG[1]:
        raise ConfigError(f"{where}: tilt_deg must lie in [{TILT_RANGE_DEG[0]:g}, {TILT_RANGE_DEG[1]:g}] deg, got {tilt}")
    if pattern == "faces6" and tilt != 0.0:
        raise ConfigError(f"{where}: pattern 'faces6' mounts the diodes flat (tilt_deg = 0), got {tilt}; "
                          "use pattern 'thesis14' for tilted diodes")
    try:
        lat_mm, along_mm = (float(x) for x in layout["triangle_mm"])
        float(layout["extra_offset_mm"])
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: triangle_mm must be [lateral, along] in mm and extra_offset_mm a number, "
                          f"got {layout['triangle_mm']!r} and {layout['extra_offset_mm']!r}") from None
    tables = []
    for panel, phi in _SIDE_PANELS:
        triples = ((0, 0),) if pattern == "faces6" else _TRIANGLE[panel]
        for s_az, s_el in triples:
            name = panel if pattern == "faces6" else f"{panel}[{_sign(s_az)},{_sign(s_el)}]"
            tables.append({"name": name, "panel": panel, "az_deg": phi + s_az * tilt, "el_deg": s_el * tilt,
                           "at_mm": [s_az * lat_mm, s_el * along_mm], "fov_deg": fov})
    for panel, z in (("+z", 1.0), ("-z", -1.0)):
        tables.append({"name": panel, "panel": panel, "normal": [0.0, 0.0, z], "at_mm": [0.0, 0.0], "fov_deg": fov})
    if layout["extra_flat_diodes"]:
        off = float(layout["extra_offset_mm"])
        for panel, z in (("+z", 1.0), ("-z", -1.0)):
            tables.append({"name": f"{panel}#2", "panel": panel, "normal": [0.0, 0.0, z], "at_mm": [0.0, off],
                           "fov_deg": fov})
    if layout.get("window") is not None:
        for t in tables:
            t["window"] = layout["window"]
    return tables


def _point_triangle_distances(point, triangles):
    """Return (distance (F,), unit normal (F, 3)) from a point (3,) to each triangle (F, 3, 3) and the
    triangles' normals (by their winding; zero for a degenerate triangle)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    n = np.cross(b - a, c - a)
    size = np.linalg.norm(n, axis=1)
    ok = size > 0
    unit = n / np.where(ok, size, 1.0)[:, None]
    height = np.einsum("fj,fj->f", point - a, unit)
    q = point - height[:, None] * unit                       # the point projected onto each triangle's plane
    inside = ok.copy()
    for x, y in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("fj,fj->f", np.cross(y - x, q - x), n) >= 0

    def to_segment(x, y):
        e = y - x
        t = np.clip(np.einsum("fj,fj->f", point - x, e) / np.maximum(np.einsum("fj,fj->f", e, e), 1e-300), 0, 1)
        return np.linalg.norm(point - (x + t[:, None] * e), axis=1)
    edge = np.minimum(np.minimum(to_segment(a, b), to_segment(b, c)), to_segment(c, a))
    return np.where(inside, np.abs(height), edge), unit


def _build_part_diode(where, table, part, mount, aperture):
    """Return (normal, surface normal, centre) in the body frame and the point (m, the part's own coordinates)
    of a diode on a part: at ``at_mm`` on the part's surface, its ``normal`` in the part's coordinates; its
    floor plate (and well) stand on the surface, no ramp: the lowest corner of the floor touches it."""
    if "az_deg" in table or "el_deg" in table:
        raise ConfigError(f"{where}: on a part, give the normal as normal = [x, y, z] in the part's own "
                          "coordinates (az_deg/el_deg are for panels)")
    if "normal" not in table:
        raise ConfigError(f"{where}: give normal = [x, y, z], the diode's normal in part {part.name!r}'s own "
                          "coordinates (as in its file or box)")
    n, note = unit_normal(vector3(table["normal"], f"{where} normal"), where)
    at = vector3(table.get("at_mm"), f"{where} at_mm (on a part: [x, y, z] in mm, the part's own coordinates)") * MM
    tri = part.local_vertices_m[part.faces]
    dist, unit = _point_triangle_distances(at, tri)
    near = np.flatnonzero(dist <= dist.min() + 1e-9)
    best = near[np.argmax(unit[near] @ n)]                   # at an edge: the face the normal leans out of
    if dist[best] > ON_SURFACE_TOLERANCE_M:
        raise ConfigError(f"{where}: at_mm = {np.round(at / MM, 3).tolist()} lies {dist[best] / MM:.2f} mm from the "
                          f"surface of part {part.name!r} (at most {ON_SURFACE_TOLERANCE_M / MM:g} mm); give a point "
                          "on its surface in the part's own coordinates (as in its file or box, before rotate_deg, "
                          "translate_mm and hinge)")
    surface = unit[best]
    if n @ surface <= 0:
        raise ConfigError(f"{where}: the normal {n.tolist()} points into part {part.name!r} (its surface there "
                          f"faces {np.round(surface, 4).tolist()}, part coordinates); turn the diode outward")
    foot = at - (at - tri[best, 0]) @ surface * surface        # the point moved onto the surface's plane
    normal_b, surface_b = part.rotation @ n, part.rotation @ surface
    frame = diode_frame(normal_b / np.linalg.norm(normal_b))
    u, v, nb = frame
    hx, hy = _outer_half_m(aperture, mount)
    lift = hx * abs(u @ surface_b) + hy * abs(v @ surface_b) + mount.floor_m * (nb @ surface_b)
    centre = part.to_body(foot[None])[0] + lift * surface_b
    return frame, surface_b, centre, at


def _build_diode(index, table, body, mount, parts=()):
    where = f"diode {index} ({table.get('name', 'unnamed')})"
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: each [[diode]] must be a table")
    check_keys(table, DIODE_KEYS, where)
    if "part" in table:
        if "panel" in table:
            raise ConfigError(f"{where}: give either panel (a face of the body) or part (a [[part]] by name), not both")
        names = [p.name for p in parts]
        if table["part"] not in names:
            close = difflib.get_close_matches(str(table["part"]), names, n=2, cutoff=0.5)
            raise ConfigError(f"{where}: unknown part {table['part']!r}; "
                              + (f"the parts are {', '.join(map(repr, names))}" if names else "no [[part]] is given")
                              + (f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""))
        part = parts[names.index(table["part"])]
        aperture, fov = _aperture_for(table.get("fov_deg"), table.get("well"), where)
        _check_chamfer(aperture, mount, where)
        window = _window_for(table.get("window"), aperture, where)
        frame, surface, centre, at = _build_part_diode(where, table, part, mount, aperture)
        for arr in (frame, surface, centre, at):
            arr.flags.writeable = False
        return MountedDiode(index=index, name=str(table.get("name", f"d{index}")), normal_body=frame[2],
                            frame_body=frame, position_body_m=centre, aperture=aperture, fov_deg=fov, panel=None,
                            at_m=at, part=part.name, surface_normal_body=surface, window=window,
                            note=unit_normal(vector3(table["normal"], f"{where} normal"), where)[1])
    panel = table.get("panel")
    if panel is None:
        raise ConfigError(f"{where}: give the mounting panel, one of {', '.join(PANELS)} (or part = a [[part]]'s name)")
    p, _, _ = panel_axes(panel)
    note = ""
    if "normal" in table:
        if "az_deg" in table or "el_deg" in table:
            raise ConfigError(f"{where}: give either 'normal' or 'az_deg'/'el_deg', not both")
        n = np.asarray(table["normal"], dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)):
            raise ConfigError(f"{where}: normal must be 3 finite numbers (body frame), got {table['normal']!r}")
        n, note = unit_normal(n, where)
    elif "az_deg" in table and "el_deg" in table:
        n = normal_from_az_el(float(table["az_deg"]), float(table["el_deg"]))
    else:
        raise ConfigError(f"{where}: give 'normal = [x, y, z]' or both 'az_deg' and 'el_deg'")
    tilt_deg = float(np.degrees(np.arccos(np.clip(n @ p, -1.0, 1.0))))
    if tilt_deg > TILT_RANGE_DEG[1] + 1e-9:
        raise ConfigError(f"{where}: the normal is tilted {tilt_deg:.2f} deg from the {panel} panel's normal; "
                          f"a ramp can tilt a diode by at most {TILT_RANGE_DEG[1]:g} deg - "
                          "is the diode on the right panel?")
    at = np.asarray(table.get("at_mm", [0.0, 0.0]), dtype=float)
    if at.shape != (2,) or not np.all(np.isfinite(at)):
        raise ConfigError(f"{where}: at_mm must be [lateral, along] in mm on the panel, got {table.get('at_mm')!r}")
    aperture, fov = _aperture_for(table.get("fov_deg"), table.get("well"), where)
    window = _window_for(table.get("window"), aperture, where)
    _check_chamfer(aperture, mount, where)
    frame = diode_frame(n)
    at_m = at * MM
    centre = _place(frame, panel, at_m, aperture, body, mount)
    for arr in (n, frame, at_m, centre):
        arr.flags.writeable = False
    return MountedDiode(index=index, name=str(table.get("name", f"d{index}")), normal_body=n, frame_body=frame,
                 position_body_m=centre, aperture=aperture, fov_deg=fov, panel=panel, at_m=at_m, window=window,
                 note=note)


def _window_for(table, aperture, where):
    """Return the :class:`simcore.shapes.window.Window` of a diode's ``window`` table (None without one), or raise
    a one-line ConfigError: keys, finite numbers, index in (1, 4], thickness > 0, gap >= 0 and on or above the
    well's rim, a footprint that covers the well's opening (hence the diode), absorption >= 0."""
    if table is None:
        return None
    w = f"{where} window"
    if not isinstance(table, dict):
        raise ConfigError(f"{w}: give a table {{index = 1.5, thickness_mm = 1.0, gap_mm = 0.5, size_mm = [40, 40]}}")
    check_keys(table, WINDOW_KEYS, w)
    missing = [k for k in WINDOW_KEYS[:4] if k not in table]
    if missing:
        raise ConfigError(f"{w}: give {', '.join(missing)} (index, thickness_mm, gap_mm, size_mm = [u, v]; "
                          "absorption_per_mm is optional, default 0)")
    try:
        vals = {k: float(table[k]) for k in ("index", "thickness_mm", "gap_mm")}
        vals["absorption_per_mm"] = float(table.get("absorption_per_mm", 0.0))
        size = [float(x) for x in table["size_mm"]]
    except (TypeError, ValueError):
        raise ConfigError(f"{w}: index, thickness_mm, gap_mm and absorption_per_mm must be numbers and size_mm "
                          f"two numbers [u, v] in mm; got {table!r}") from None
    if len(size) != 2 or not np.all(np.isfinite([*vals.values(), *size])):
        raise ConfigError(f"{w}: every value must be a finite number and size_mm two of them [u, v]; got {table!r}")
    lo, hi = INDEX_RANGE
    if not lo < vals["index"] <= hi:
        raise ConfigError(f"{w}: index must lie in ({lo:g}, {hi:g}] (glass 1.5, sapphire 1.77), got {vals['index']:g}")
    if vals["thickness_mm"] <= 0:
        raise ConfigError(f"{w}: thickness_mm must be > 0, got {vals['thickness_mm']:g}")
    if vals["gap_mm"] < 0:
        raise ConfigError(f"{w}: gap_mm (diode surface to the window's lower face) must be >= 0, got {vals['gap_mm']:g}")
    if vals["gap_mm"] * MM < aperture.height_m - 1e-12:
        raise ConfigError(f"{w}: gap_mm {vals['gap_mm']:g} puts the window inside the diode's well "
                          f"({aperture.height_m / MM:.4f} mm tall); the window sits on or above the well's rim: "
                          f"use gap_mm >= {np.ceil(aperture.height_m / MM * 1e3) / 1e3:.3f}")
    if vals["absorption_per_mm"] < 0:
        raise ConfigError(f"{w}: absorption_per_mm must be >= 0 (1/mm), got {vals['absorption_per_mm']:g}")
    if isinstance(aperture, CircularWell):
        raise ConfigError(f"{w}: a window over a round well is not modelled (the check's closed form is for "
                          "rectangular wells); use a square well (opening_mm) under the window")
    need = (2 * aperture.rims[5] / MM, 2 * aperture.rims[6] / MM)     # the top rim (a chamfer widens it)
    if size[0] < need[0] - 1e-9 or size[1] < need[1] - 1e-9:
        raise ConfigError(f"{w}: size_mm {size} does not cover the diode's "
                          f"{'well opening' if aperture.height_m > 0 else 'sensitive area'} "
                          f"({need[0]:.3f} x {need[1]:.3f} mm); give size_mm at least that large")
    return Window(index=vals["index"], thickness_m=vals["thickness_mm"] * MM, gap_m=vals["gap_mm"] * MM,
                  size_m=(size[0] * MM, size[1] * MM), absorption_per_m=vals["absorption_per_mm"] / MM)


def _footprint(diode, body, mount):
    """Return the convex footprint of a mount on its panel, (M, 2) panel coordinates (m), counter-clockwise."""
    _, t, a = panel_axes(diode.panel)
    bottom, top = diode.mount_corners_m(mount)
    pts = np.vstack([bottom, top]) - body.panel_centre_m(diode.panel)
    return np.array(convex_hull([tuple(p) for p in np.round(np.column_stack([pts @ t, pts @ a]), 12)]))


def _convex_overlap(poly_a, poly_b):
    """Return True when two convex polygons overlap with positive area (separating-axis test)."""
    for poly in (poly_a, poly_b):
        edges = np.roll(poly, -1, axis=0) - poly
        for e in edges:
            axis = np.array([-e[1], e[0]])
            pa, pb = poly_a @ axis, poly_b @ axis
            if pa.max() <= pb.min() + 1e-12 or pb.max() <= pa.min() + 1e-12:
                return False
    return True


def mount_height_m(diode, body, mount):
    """Return the height of a diode's mount (ramp + floor + well, and its window) above its panel, or above the
    part's surface for a diode on a part (m)."""
    bottom, top = diode.mount_corners_m(mount)
    pts = [bottom, top]
    if diode.window is not None:
        u, v, n = diode.frame_body
        w = diode.window
        hx, hy = np.array(w.size_m) / 2
        sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
        pts.append(diode.position_body_m + (w.gap_m + w.thickness_m) * n + sq[:, :1] * hx * u + sq[:, 1:] * hy * v)
    if diode.part is not None:
        p = diode.surface_normal_body
        return float(np.max((np.vstack(pts) - bottom[np.argmin(bottom @ p)]) @ p))
    p, _, _ = panel_axes(diode.panel)
    return float(np.max((np.vstack(pts) - body.panel_centre_m(diode.panel)) @ p))


def body_side_normal(diode, body):
    """Return the unit normal (3,) of a plane the body box lies behind as seen from the diode: directions with
    a non-negative component along it cannot meet the body. A panel diode: its panel's outward normal; a
    diode on a part: the body axis along which it lies farthest beyond the box's face plane."""
    if diode.part is None:
        return panel_axes(diode.panel)[0]
    beyond = np.abs(diode.position_body_m) - np.asarray(body.size_m) / 2.0
    axis = int(np.argmax(beyond))
    out = np.zeros(3)
    out[axis] = np.sign(diode.position_body_m[axis])
    return out


def _validate_mounts(diodes, body, mount):
    prints = []
    for d in diodes:
        if d.part is not None:          # on a part: no panel, no launch-pod clearance of the body's faces
            continue
        height = mount_height_m(d, body, mount)
        if height > body.clearance_m + 1e-12:
            raise ConfigError(
                f"diode {d.index} ({d.name}): its ramp and well{' and window' if d.window is not None else ''} rise "
                f"{height / MM:.2f} mm above the {d.panel} panel, "
                f"more than the {body.clearance_m / MM:g} mm launch-pod clearance; the FOV {d.fov_deg:g} deg needs a "
                f"well {d.aperture.height_m / MM:.2f} mm tall and {d.aperture.opening_x_m / MM:.2f} mm wide - "
                "choose " + ("a lower or thinner window (gap_mm, thickness_mm), " if d.window is not None else "")
                + "a smaller FOV or tilt, thinner walls, or raise body.clearance_mm")
        fp = _footprint(d, body, mount)
        half = body.panel_half_extent_m(d.panel)
        if np.any(np.abs(fp) > half + 1e-12):
            raise ConfigError(
                f"diode {d.index} ({d.name}): its mount (foot at {np.round(d.at_m / MM, 3).tolist()} mm) reaches "
                f"outside the {d.panel} panel area between the rails (|lateral| <= {half[0] / MM:g} mm, "
                f"|along| <= {half[1] / MM:g} mm); move at_mm towards the panel centre")
        for other, ofp in prints:
            if other.panel == d.panel and _convex_overlap(fp, ofp):
                raise ConfigError(f"diodes {other.index} ({other.name}) and {d.index} ({d.name}) overlap on the "
                                  f"{d.panel} panel; move one of them (at_mm) apart")
        prints.append((d, fp))
    _validate_windows(diodes, body)


def _validate_windows(diodes, body):
    """Refuse two windows that overlap in their panel's plane (two slabs cannot share the space above it); diodes
    on parts are not compared."""
    shapes = []
    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    for d in diodes:
        if d.window is None or d.part is not None:
            continue
        _, t, a = panel_axes(d.panel)
        u, v, _ = d.frame_body
        hx, hy = np.array(d.window.size_m) / 2
        pts = d.position_body_m + sq[:, :1] * hx * u + sq[:, 1:] * hy * v - body.panel_centre_m(d.panel)
        poly = np.array(convex_hull([tuple(p) for p in np.round(np.column_stack([pts @ t, pts @ a]), 12)]))
        for other, opoly in shapes:
            if other.panel == d.panel and _convex_overlap(poly, opoly):
                raise ConfigError(f"the windows of diodes {other.index} ({other.name}) and {d.index} ({d.name}) overlap "
                                  f"on the {d.panel} panel; give them smaller size_mm or move the diodes apart")
        shapes.append((d, poly))


@dataclass(frozen=True, eq=False)
class SatelliteConfig:
    """A satellite: body, mounts and diodes (body frame, SI); ``dead`` marks failed diodes."""

    name: str
    description: str
    body: Body
    mount: Mount
    diodes: tuple
    dead: np.ndarray
    layout: dict = field(default_factory=dict)
    source: str = ""
    parts: tuple = ()
    diode_type: str = None   # the diodes' part (band of --map band), "unknown", or None: BPW34FS (declared.py)

    @property
    def notes(self):
        """Return the notes of loading this configuration (normals normalised, ...): the run prints and stores them."""
        return tuple(d.note for d in self.diodes if d.note)

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def load(cls, name_or_path, *, extra_flat_diodes=None, dead=None):
        """Return the configuration of a shipped name (``list_configs()``) or a path to a .toml file.

        ``extra_flat_diodes`` (per run) overrides the file's ``[layout] extra_flat_diodes``;
        ``dead`` (indices) overrides the file's ``dead`` list.
        """
        text = str(name_or_path)
        path = Path(text)
        if path.suffix.lower() != ".toml" and not path.exists():
            path = CONFIG_DIR / f"{text}.toml"
            if not path.exists():
                names = list_configs()
                close = difflib.get_close_matches(text, names, n=3, cutoff=0.5)
                raise ConfigError(f"unknown configuration {text!r}"
                                  + (f"; did you mean {', '.join(map(repr, close))}?" if close else "")
                                  + f" Shipped: {', '.join(names)}; or give a path to a .toml file")
        if not path.is_file():
            raise ConfigError(f"configuration file {str(path)!r} does not exist; give a shipped name "
                              f"({', '.join(list_configs())}) or an existing .toml path")
        try:
            data = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}: not valid TOML ({exc})") from None
        data.setdefault("name", path.stem)
        return cls.from_dict(data, source=str(path), extra_flat_diodes=extra_flat_diodes, dead=dead)

    @classmethod
    def from_dict(cls, data, *, source="", extra_flat_diodes=None, dead=None):
        """Return the configuration described by a dict with the TOML file's structure (scenes/FORMAT.md)."""
        where = source or "configuration"
        check_keys(data, TOP_KEYS, where)
        bd = _merged(data.get("body"), BODY_DEFAULTS, "body")
        size = np.asarray(bd["size_mm"], dtype=float)
        if size.shape != (3,) or np.any(size <= 0):
            raise ConfigError(f"[body] size_mm must be three positive lengths (x, y, z) in mm, got {bd['size_mm']!r}")
        body = Body(size_m=tuple(size * MM), rail_m=float(bd["rail_mm"]) * MM,
                    clearance_m=float(bd["clearance_mm"]) * MM,
                    material=check_material(bd["material"], f"{where} [body] material"), none=_flag(bd["none"], where))
        md = _merged(data.get("mount"), MOUNT_DEFAULTS, "mount")
        if not (md["wall_mm"] > 0 and md["floor_mm"] > 0 and md["base_mm"] >= 0):
            raise ConfigError(f"[mount] wall_mm and floor_mm must be > 0 and base_mm >= 0, got {md}")
        mount = Mount(wall_m=float(md["wall_mm"]) * MM, floor_m=float(md["floor_mm"]) * MM,
                      base_m=float(md["base_mm"]) * MM,
                      material=check_material(md["material"], f"{where} [mount] material"))
        tables = []
        layout = {}
        if "layout" in data:
            layout = _merged(data["layout"], LAYOUT_DEFAULTS, "layout")
            if extra_flat_diodes is not None:
                layout["extra_flat_diodes"] = bool(extra_flat_diodes)
            tables += expand_layout(layout)
        elif extra_flat_diodes:
            raise ConfigError(f"{where}: extra_flat_diodes needs a [layout]; add the flat diodes as [[diode]] entries")
        explicit = data.get("diode", [])
        if not isinstance(explicit, list):
            raise ConfigError(f"{where}: diodes are given as [[diode]] tables")
        tables += explicit
        if not tables:
            raise ConfigError(f"{where}: no diodes; give a [layout] or [[diode]] tables (see scenes/FORMAT.md)")
        part_tables = data.get("part", [])
        if not isinstance(part_tables, list):
            raise ConfigError(f"{where}: parts are given as [[part]] tables")
        base_dir = Path(source).parent if source else Path.cwd()
        parts = tuple(build_part(i, t, base_dir, where) for i, t in enumerate(part_tables))
        diodes = tuple(_build_diode(i, t, body, mount, parts) for i, t in enumerate(tables))
        _validate_mounts(diodes, body, mount)
        validate_parts(parts, diodes)
        check_scene(parts, part_tables, diodes, body, where)      # names, hinges, parts in the body
        cfg = cls(name=str(data.get("name", "custom")), description=str(data.get("description", "")), body=body,
                  mount=mount, diodes=diodes, dead=np.zeros(len(diodes), bool), layout=layout, source=source,
                  parts=parts, diode_type=diode_type(data.get("diode_type"), where))
        return cfg.with_dead(data.get("dead", []) if dead is None else dead)

    def with_dead(self, indices):
        """Return a copy whose dead diodes are exactly ``indices`` (e.g. ``[0]``, the thesis' dead diode)."""
        raw = np.asarray([] if indices is None else indices)
        if raw.dtype == bool:
            if raw.shape != (len(self.diodes),):
                raise ConfigError(f"a dead mask must have one entry per diode ({len(self.diodes)}), got shape {raw.shape}")
            raw = np.flatnonzero(raw)
        idx = raw.astype(int).ravel()
        bad = idx[(idx < 0) | (idx >= len(self.diodes))]
        if bad.size:
            raise ConfigError(f"dead diode index {bad.tolist()} out of range: {self.name} has diodes 0..{len(self.diodes) - 1}")
        mask = np.zeros(len(self.diodes), bool)
        mask[idx] = True
        return replace(self, dead=mask)

    # --- arrays -------------------------------------------------------------------------------
    @property
    def n_diodes(self):
        return len(self.diodes)

    @property
    def normals(self):
        """Unit diode normals (K, 3), body frame."""
        return np.array([d.normal_body for d in self.diodes])

    @property
    def frames(self):
        """Diode frames (K, 3, 3), rows (u, v, n) in the body frame."""
        return np.array([d.frame_body for d in self.diodes])

    @property
    def positions_m(self):
        """Centres of the diodes' sensitive surfaces (K, 3), body frame, m."""
        return np.array([d.position_body_m for d in self.diodes])

    @property
    def fov_deg(self):
        """Per-diode FOV (K,), degrees."""
        return np.array([d.fov_deg for d in self.diodes])

    @property
    def live(self):
        """Mask (K,) of working diodes."""
        return ~self.dead

    @property
    def apertures(self):
        return tuple(d.aperture for d in self.diodes)

    @property
    def windows(self):
        """Return the diodes' windows (K,) (:class:`simcore.shapes.window.Window` or None each)."""
        return tuple(d.window for d in self.diodes)

    def mount_heights_m(self):
        """Return the height of every mount above its panel (K,), m."""
        return np.array([mount_height_m(d, self.body, self.mount) for d in self.diodes])

    def __repr__(self):
        dead = np.flatnonzero(self.dead).tolist()
        return f"SatelliteConfig({self.name!r}, {self.n_diodes} diodes, dead={dead})"
