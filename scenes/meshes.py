"""Triangle meshes of a satellite configuration (trimesh), body frame, metres.

Parts (see :mod:`scenes.config` for how a mount is placed):

- ``body``: the 2U envelope, a box ``size_m`` centred at the origin (z the long
  axis). Its side faces are the panels; the corner rails (8.5 mm) lie inside
  the envelope and are kept free of mounts by the configuration's validation,
  so they add no surface of their own.
- ``ramp_k``: a convex prism from the panel up to the underside of diode k's
  floor; its top face is perpendicular to the diode normal (the tilt).
- ``floor_k``: an opaque square plate, top flush with the diode surface, with a
  hole exactly the diode's size (the diode surface itself is no occluder: the
  renderer starts rays on it).
- ``well_k``: the hollow square well, straight walls ``mount.wall_m`` thick
  from the diode surface up to ``aperture.height_m``; its inner cross-section is
  the aperture's opening and its walls run along the diode frame's u and v axes
  (:func:`simcore.shapes.aperture.diode_frame`); a chamfered well's top ``chamfer_m``
  widens outward to the top rim (:attr:`simcore.shapes.aperture.WellAperture.rims`).
  A round well (:class:`simcore.shapes.aperture.CircularWell`) is a round tube, ``ROUND_SIDES``-gons
  of the circles' areas, inner radius the rim's, on the square floor plate. Absent for a bare diode (height 0).
- ``plug_k``: the diode's own absorbing body, a black block filling the floor's hole from
  ``PLUG_DEPTH_M`` under the diode surface down to the floor's underside. The renderer starts its paths
  on the diode surface, which is not in the mesh; light coming back onto the diode (reflected by walls,
  parts or the body) ends on the plug instead of falling through the hole onto the ramp and the hole's
  sides. Material 'black' whatever the mount's.
- ``part_NAME``: each extra part of the configuration (``[[part]]``: a mesh file or a box, placed and
  hinged, :class:`scenes.parts.Part`), as given (not necessarily closed).
- ``diode_k`` (only in :func:`build_parts` with ``include_diodes=True`` and in
  :func:`diode_surfaces`): the sensitive square, facing along the normal.

Every part is a closed, consistently outward-oriented mesh (the diode squares
excepted); parts touch but do not overlap. Each part's ``metadata['material']`` is its
surface material (:mod:`scenes.materials`: ``[body] material`` for the body,
``[mount] material`` for ramps, floors and wells; plugs and diode squares 'black').
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from scenes.config import SatelliteConfig, panel_axes
from simcore.shapes.aperture import CircularWell

# The plug's top under the diode surface: below the path tracer's 2 um spawn offset (paths leaving the diode
# start above it), far above float32 resolution at the satellite's scale (~1e-8 m at 0.1 m).
PLUG_DEPTH_M = 1e-6

_SQUARE = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)  # counter-clockwise in (u, v)


def _to_body(local, frame, centre):
    """Map points (M, 3) in the diode frame (u, v, n coordinates) to the body frame."""
    return centre + local @ frame


def _square_ring(outer_half, inner_half, n0, n1, inner_levels=()):
    """Return (vertices, faces) of a closed square ring prism in local (u, v, n) coordinates.

    ``outer_half``/``inner_half``: (hx, hy) half sides; the solid spans n0..n1 along n. ``inner_levels``:
    further (n, (hx, hy)) of the hole above n0 in rising n, the last at n1 (a chamfer: the hole widening
    toward the top); none: the hole is ``inner_half`` from n0 to n1.
    """
    levels = [(n0, np.asarray(inner_half))] + [(n, np.asarray(h)) for n, h in inner_levels]
    if len(levels) == 1:
        levels.append((n1, np.asarray(inner_half)))
    o = _SQUARE * outer_half
    verts = [np.column_stack([o, np.full(4, n0)]), np.column_stack([o, np.full(4, n1)])]
    verts += [np.column_stack([_SQUARE * h, np.full(4, n)]) for n, h in levels]
    verts = np.vstack(verts)
    o0, o1, i0, i1 = 0, 4, 8, 8 + 4 * (len(levels) - 1)
    faces = []
    for a in range(4):
        b = (a + 1) % 4
        faces += [[o0 + a, o0 + b, o1 + b], [o0 + a, o1 + b, o1 + a]]      # outer wall, outward
        for lo in range(i0, i1, 4):                                        # inner wall, facing the hole
            faces += [[lo + a, lo + 4 + b, lo + b], [lo + a, lo + 4 + a, lo + 4 + b]]
        faces += [[o1 + a, o1 + b, i1 + b], [o1 + a, i1 + b, i1 + a],      # top ring, +n
                  [o0 + a, i0 + b, o0 + b], [o0 + a, i0 + a, i0 + b]]      # bottom ring, -n
    return verts, np.array(faces)


def _ring_mesh(outer_half, inner_half, n0, n1, frame, centre, inner_levels=()):
    verts, faces = _square_ring(np.asarray(outer_half), np.asarray(inner_half), n0, n1, inner_levels)
    return trimesh.Trimesh(_to_body(verts, frame, centre), faces, process=True)


# Sides of the polygon that stands for a round well's circle (scenes.config: well = {shape = "round", ...}). Its
# vertices lie at ROUND_RADIUS_FACTOR x the radius, so that its area is the circle's; its edge then strays from
# the circle by at most r (pi / N)^2 / 3 = 3.1e-6 r (7 nm for r = 2.2 mm, below float32 at the satellite's
# scale), so the lit area differs from the closed-form disc overlap (simcore.shapes.aperture.CircularWell) by
# under (the arc inside the diode, <= 2 pi r) x 3.1e-6 r: 1.3e-5 of a BPW34 for r = 2.2 mm.
ROUND_SIDES = 1024
ROUND_RADIUS_FACTOR = float(np.sqrt(2.0 * np.pi / (ROUND_SIDES * np.sin(2.0 * np.pi / ROUND_SIDES))))


def _tube(r_in, r_out, n0, n1, sides=ROUND_SIDES):
    """Return (vertices, faces) of a closed round tube (inner and outer walls: ``sides``-gons of area
    pi r^2) spanning n0..n1 along n, in local (u, v, n) coordinates."""
    ang = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.column_stack([np.cos(ang), np.sin(ang)]) * ROUND_RADIUS_FACTOR
    verts = np.vstack([np.column_stack([ring * r, np.full(sides, n)]) for r, n in
                       [(r_out, n0), (r_in, n0), (r_out, n1), (r_in, n1)]])
    o0, i0, o1, i1 = 0, sides, 2 * sides, 3 * sides
    a = np.arange(sides)
    b = (a + 1) % sides
    faces = np.vstack([np.column_stack(f) for f in [
        (o0 + a, o0 + b, o1 + b), (o0 + a, o1 + b, o1 + a),         # outer wall, outward
        (i0 + a, i1 + b, i0 + b), (i0 + a, i1 + a, i1 + b),         # inner wall, facing the hole
        (o1 + a, o1 + b, i1 + b), (o1 + a, i1 + b, i1 + a),         # top ring, +n
        (o0 + a, i0 + b, o0 + b), (o0 + a, i0 + a, i0 + b)]])       # bottom ring, -n
    return verts, faces


def body_mesh(config):
    """Return the body envelope box (body frame, m)."""
    return trimesh.creation.box(extents=np.asarray(config.body.size_m))


def mount_meshes(config, k):
    """Return {'ramp', 'floor', 'well', 'plug'} meshes of diode k's mount (body frame, m); 'well' absent when
    bare. The plug's ``metadata['material']`` is 'black' (the others take the mount's material)."""
    d, m, body = config.diodes[k], config.mount, config.body
    ap, frame, centre = d.aperture, d.frame_body, d.position_body_m
    outer = np.array([ap.opening_x_m, ap.opening_y_m]) / 2.0 + m.wall_m
    parts = {}
    if d.part is None:              # a diode on a part stands on the part's surface: no ramp
        p, _, _ = panel_axes(d.panel)
        bottom, _ = d.mount_corners_m(m)
        panel_offset = p @ body.panel_centre_m(d.panel)
        foot = bottom - np.outer(bottom @ p - panel_offset, p)
        ramp = trimesh.convex.convex_hull(np.vstack([bottom, foot]))
        if ramp.volume > 1e-15:
            parts["ramp"] = ramp
    parts["floor"] = _ring_mesh(outer, [ap.diode_x_m / 2.0, ap.diode_y_m / 2.0], -m.floor_m, 0.0, frame, centre)
    if ap.height_m > 0 and isinstance(ap, CircularWell):
        verts, faces = _tube(ap.radius_m, ap.radius_m + m.wall_m, 0.0, ap.height_m)
        parts["well"] = trimesh.Trimesh(_to_body(verts, frame, centre), faces, process=True)
    elif ap.height_m > 0:
        _, _, wx, wy, h_low, tx, ty, h_top = ap.rims
        bevel = [(h_low, (wx, wy)), (h_top, (tx, ty))] if (tx, ty) != (wx, wy) and h_top > h_low else ()
        parts["well"] = _ring_mesh(outer, [wx, wy], 0.0, ap.height_m, frame, centre, bevel)
    half_diode = np.array([ap.diode_x_m, ap.diode_y_m]) / 2.0
    plug_local = np.column_stack([np.vstack([_SQUARE * half_diode] * 2),
                                  np.repeat([-m.floor_m, -PLUG_DEPTH_M], 4)])
    parts["plug"] = trimesh.convex.convex_hull(_to_body(plug_local, frame, centre))
    parts["plug"].metadata["material"] = "black"
    return parts


def diode_surfaces(config):
    """Return the diodes' sensitive squares as one mesh (2 faces per diode, in index order), body frame, m.

    Face normals point along the diode normals. Not an occluder: for pictures and checks only.
    """
    verts, faces = [], []
    for k, d in enumerate(config.diodes):
        half = np.array([d.aperture.diode_x_m, d.aperture.diode_y_m]) / 2.0
        local = np.column_stack([_SQUARE * half, np.zeros(4)])
        verts.append(_to_body(local, d.frame_body, d.position_body_m))
        faces += [[4 * k, 4 * k + 1, 4 * k + 2], [4 * k, 4 * k + 2, 4 * k + 3]]
    return trimesh.Trimesh(np.vstack(verts), np.array(faces), process=False)


def build_parts(config, include_diodes=False):
    """Return the named parts {'body', 'ramp_k', 'floor_k', 'well_k', 'plug_k', 'part_NAME'[, 'diode_k']} (body
    frame, m)."""
    if not isinstance(config, SatelliteConfig):
        config = SatelliteConfig.load(config)
    parts = {}
    if not config.body.none:                     # [body] none = true: bare diodes, no body
        parts["body"] = body_mesh(config)
        parts["body"].metadata["material"] = config.body.material
    for k in range(config.n_diodes):
        for name, mesh in mount_meshes(config, k).items():
            mesh.metadata.setdefault("material", config.mount.material)
            parts[f"{name}_{k}"] = mesh
    for part in config.parts:
        mesh = trimesh.Trimesh(part.vertices_m, part.faces, process=False)
        mesh.metadata["material"] = part.material
        parts[f"part_{part.name}"] = mesh
    if include_diodes:
        surf = diode_surfaces(config)
        for k in range(config.n_diodes):
            parts[f"diode_{k}"] = trimesh.Trimesh(surf.vertices[4 * k:4 * k + 4], surf.faces[2 * k:2 * k + 2] - 4 * k,
                                                  process=False)
            parts[f"diode_{k}"].metadata["material"] = "black"
    return parts


def build_satellite_mesh(config, parts=None):
    """Return the satellite's occluder (body, ramps, floors, wells, plugs, parts) as one mesh, body frame, metres.

    ``mesh.metadata['parts']`` maps each part name to its (first, stop) face range and
    ``mesh.metadata['materials']`` to its material (the renderer path-traces the parts that are
    not 'black'). The diodes' sensitive surfaces are NOT included (see :func:`diode_surfaces`).
    ``parts``: :func:`build_parts` of ``config`` when the caller has it already.
    """
    parts = build_parts(config) if parts is None else parts
    ranges, start = {}, 0
    for name, mesh in parts.items():
        ranges[name] = (start, start + len(mesh.faces))
        start += len(mesh.faces)
    mesh = trimesh.util.concatenate(list(parts.values()))
    mesh.metadata["parts"] = ranges
    mesh.metadata["materials"] = {name: part.metadata["material"] for name, part in parts.items()}
    return mesh


def export(config, path, include_diodes=True):
    """Write the satellite mesh (metres, body frame) to ``path`` and return the path.

    ``.obj``/``.glb``/``.gltf``: a scene with one named geometry per part; ``.ply``/``.stl``/other
    trimesh formats: one merged mesh. ``include_diodes`` adds the sensitive squares.
    """
    path = Path(path)
    parts = build_parts(config, include_diodes=include_diodes)
    if path.suffix.lower() in (".obj", ".glb", ".gltf"):
        trimesh.Scene({name: mesh for name, mesh in parts.items()}).export(str(path))
    else:
        trimesh.util.concatenate(list(parts.values())).export(str(path))
    return path
