"""A satellite's extra parts (``[[part]]`` tables, ``scenes/FORMAT.md``): a mesh file (STL, OBJ, PLY, GLB) in its
stated unit or a box, placed in the body frame (rotated, translated, turned about a hinge), and the checks that no
diode lies inside a part or looks straight into one."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.declared import MM, ConfigError, check_keys, vector3
from scenes.materials import DEFAULT as DEFAULT_MATERIAL, check_material

PART_KEYS = ("name", "file", "unit", "box_mm", "translate_mm", "rotate_deg", "hinge", "material")
HINGE_KEYS = ("axis", "point_mm", "angle_deg")
UNITS = {"mm": 1e-3, "m": 1.0}
# A part whose largest extent lies outside this range (metres, after its unit) is a unit mistake more often
# than a spacecraft: the smallest CubeSat appendages are millimetres, the largest deployed arrays ~20 m.
PART_EXTENT_RANGE_M = (1e-3, 20.0)


@dataclass(frozen=True, eq=False)
class Part:
    """An extra part of the satellite (antenna, deployed panel, camera baffle, a CAD export): a triangle mesh
    placed in the body frame (metres) and its surface material (:mod:`scenes.materials`)."""

    name: str
    vertices_m: np.ndarray
    faces: np.ndarray
    material: object = DEFAULT_MATERIAL
    source: str = ""
    # the placement: body = rotation @ own + translation_m, "own" being the part's coordinates (its file's, in
    # metres, or its box's); local_vertices_m the vertices there (diodes on the part are given in them)
    rotation: np.ndarray = None
    translation_m: np.ndarray = None
    local_vertices_m: np.ndarray = None

    def to_body(self, points_own_m):
        """Return points (M, 3) given in the part's own coordinates (m) in the body frame (m)."""
        return np.asarray(points_own_m, float) @ self.rotation.T + self.translation_m


def _rotation_xyz(angles_deg):
    """Return the rotation matrix of extrinsic rotations about the body x, then y, then z axes (deg)."""
    ax, ay, az = np.radians(np.asarray(angles_deg, float))
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _rotation_axis_angle(axis, angle_deg):
    """Return the rotation matrix by ``angle_deg`` about the unit ``axis`` (right hand, Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = np.radians(float(angle_deg))
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def build_part(index, table, base_dir, where):
    """Return the :class:`Part` of a ``[[part]]`` table: a mesh file (STL, OBJ, PLY, GLB: anything trimesh
    reads) in its stated unit, or a box ``box_mm``, rotated (``rotate_deg``, about body x then y then z),
    translated (``translate_mm``) and, for a deployable, turned about its ``hinge``."""
    import trimesh
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: parts are given as [[part]] tables")
    name = str(table.get("name", f"part{index}"))
    here = f"{where} [[part]] {name!r}"
    check_keys(table, PART_KEYS, here)
    if ("file" in table) == ("box_mm" in table):
        raise ConfigError(f"{here}: give either file = \"mesh.stl\" (with unit) or box_mm = [x, y, z], not "
                          f"{'both' if 'file' in table else 'neither'}")
    if "file" in table:
        unit = table.get("unit")
        if unit not in UNITS:
            raise ConfigError(f"{here}: give the mesh file's unit, unit = \"mm\" or unit = \"m\" (got {unit!r}); "
                              "CAD exports are usually in mm")
        path = Path(table["file"])
        if not path.is_absolute():
            path = Path(base_dir) / path
        try:
            mesh = trimesh.load(str(path), force="mesh", process=False)
        except Exception as exc:            # trimesh raises many kinds; the user needs the file and the reason
            raise ConfigError(f"{here}: cannot read the mesh file {str(path)!r} ({type(exc).__name__}: {exc}); "
                              "give an existing STL, OBJ, PLY or GLB file") from None
        verts = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), float)
        faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64)
        if len(faces) == 0:
            raise ConfigError(f"{here}: cannot read the mesh file {str(path)!r}: it holds no triangles (give an "
                              "STL, OBJ, PLY or GLB file of the part's surface)")
        if not np.all(np.isfinite(verts)):
            raise ConfigError(f"{here}: the mesh file {str(path)!r} has {int((~np.isfinite(verts)).any(axis=1).sum())} "
                              "vertices that are not finite (NaN or inf); repair the export")
        verts = verts * UNITS[unit]
        extent = float(np.max(verts.max(axis=0) - verts.min(axis=0)))
        lo, hi = PART_EXTENT_RANGE_M
        if not lo <= extent <= hi:
            other = "m" if unit == "mm" else "mm"
            raise ConfigError(f"{here}: the mesh spans {extent:.4g} m with unit = {unit!r}, implausible for a "
                              f"spacecraft part ({lo:g} to {hi:g} m); is its unit {other!r}?")
        source = str(path)
    else:
        size = vector3(table["box_mm"], f"{here} box_mm")
        if np.any(size <= 0):
            raise ConfigError(f"{here}: box_mm must be three positive lengths in mm, got {table['box_mm']!r}")
        box = trimesh.creation.box(extents=size * MM)
        verts, faces, source = np.asarray(box.vertices, float), np.asarray(box.faces, np.int64), "box"
    local = verts
    rotation = _rotation_xyz(vector3(table.get("rotate_deg", [0, 0, 0]), f"{here} rotate_deg"))
    translation = vector3(table.get("translate_mm", [0, 0, 0]), f"{here} translate_mm") * MM
    verts = verts @ rotation.T
    verts = verts + translation
    if "hinge" in table:
        hinge = table["hinge"]
        if not isinstance(hinge, dict):
            raise ConfigError(f"{here}: hinge = {{axis = [x, y, z], point_mm = [x, y, z], angle_deg = A}}")
        check_keys(hinge, HINGE_KEYS, f"{here} hinge")
        axis = vector3(hinge.get("axis"), f"{here} hinge axis")
        if np.linalg.norm(axis) == 0:
            raise ConfigError(f"{here}: the hinge axis must not be zero")
        point = vector3(hinge.get("point_mm", [0, 0, 0]), f"{here} hinge point_mm") * MM
        try:
            angle = float(hinge.get("angle_deg"))
        except (TypeError, ValueError):
            angle = np.nan
        if not np.isfinite(angle):
            raise ConfigError(f"{here}: the hinge needs angle_deg, a finite number of degrees (the deployed angle)")
        turn = _rotation_axis_angle(axis, angle)
        verts = (verts - point) @ turn.T + point
        rotation, translation = turn @ rotation, turn @ (translation - point) + point
    reach = float(np.max(np.linalg.norm(verts, axis=1)))
    if reach > PART_EXTENT_RANGE_M[1]:
        raise ConfigError(f"{here}: once placed, the part reaches {reach:.4g} m from the body centre, beyond the "
                          f"{PART_EXTENT_RANGE_M[1]:g} m a spacecraft part may; translate_mm and point_mm are in mm")
    material = check_material(table.get("material", DEFAULT_MATERIAL), f"{here} material")
    return Part(name=name, vertices_m=verts, faces=faces, material=material, source=source, rotation=rotation,
                translation_m=translation, local_vertices_m=local)


def ray_distances(vertices, faces, origins, dirs):
    """Return (R, F) the distance along each ray (origins, unit dirs (R, 3)) to each triangle (inf: missed),
    Moller-Trumbore, numpy (for validation: a few rays)."""
    v0, v1, v2 = (vertices[faces[:, i]] for i in range(3))
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(dirs[:, None], e2[None])                                   # (R, F, 3)
    det = np.einsum("rfj,fj->rf", p, e1)
    ok = np.abs(det) > 1e-18
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    tv = origins[:, None] - v0[None]
    u = np.einsum("rfj,rfj->rf", tv, p) * inv
    q = np.cross(tv, e1[None])
    w = np.einsum("rj,rfj->rf", dirs, q) * inv
    t = np.einsum("fj,rfj->rf", e2, q) * inv
    hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
    return np.where(hit, t, np.inf)


def validate_parts(parts, diodes):
    """Refuse a diode buried in a (closed) part and a diode looking straight into one
    (its normal meets a part within 1 mm)."""
    import trimesh
    centres = np.array([d.position_body_m for d in diodes])
    normals = np.array([d.normal_body for d in diodes])
    for part in parts:
        if trimesh.Trimesh(part.vertices_m, part.faces, process=False).is_watertight:
            # inside a closed surface: an odd number of crossings along any ray (a direction no face lines up with)
            probe = np.broadcast_to(np.array([0.5773, 0.5774, 0.5775]) / np.linalg.norm([0.5773, 0.5774, 0.5775]),
                                    centres.shape)
            crossings = np.isfinite(ray_distances(part.vertices_m, part.faces, centres, probe)).sum(axis=1)
            if np.any(crossings % 2 == 1):
                d = diodes[int(np.flatnonzero(crossings % 2 == 1)[0])]
                raise ConfigError(f"diode {d.index} ({d.name}) lies inside part {part.name!r}; move the part or "
                                  "the diode")
        near = ray_distances(part.vertices_m, part.faces, centres, normals).min(axis=1)
        if np.any(near < 1e-3):
            d = diodes[int(np.flatnonzero(near < 1e-3)[0])]
            raise ConfigError(f"diode {d.index} ({d.name}) faces into part {part.name!r} (its normal meets it "
                              "within 1 mm); turn the diode or move the part")
