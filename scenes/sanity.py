"""Checks of a scene file for what parses but cannot be meant: duplicate names, a part in the body, a hinge
turned many times over, lengths that look like metres where the format asks for millimetres.

:func:`check_scene` runs at the end of :meth:`scenes.config.SatelliteConfig.from_dict`, so every command that
loads a configuration refuses such a file with one line before any work. Touching and mounting faces are fine
(a part may lie flat against a face: the shipped examples do), so the body's interior is taken
``OVERLAP_TOLERANCE_M`` in from its faces.
"""
import numpy as np

from simcore.errors import InvalidInputError

# A part may reach this far into the body (metres) before it counts as inside it: CAD rounding of a part mounted
# flat on a face, well below the 2 mm of a solar-panel wing or the 0.5 mm walls of a diode's mount.
OVERLAP_TOLERANCE_M = 0.5e-3
# A deployed hinge turns at most a full turn either way; beyond that the angle is a typo (or radians x 1e3 ...).
HINGE_MAX_DEG = 360.0
# Grid points per axis over a closed part's bounding box for its overlap with the body (16^3 = 4096 probes: a part
# half inside the body has ~2000 of them there; a sliver thinner than 1/16 of the part's extent may slip through).
_GRID = 16


class SceneError(InvalidInputError):
    """A scene file that parses but describes something that cannot be meant."""


def _duplicate(names):
    seen = set()
    for n in names:
        if n in seen:
            return n
        seen.add(n)
    return None


def _inside_body(points, body):
    """Return (P,) bool: the points (body frame, m) deeper than OVERLAP_TOLERANCE_M inside the body's box."""
    half = np.asarray(body.size_m, dtype=float) / 2.0 - OVERLAP_TOLERANCE_M
    return np.all(np.abs(points) < half, axis=-1)


def _in_part(points, part):
    """Return (P,) bool: the points inside a closed part (an odd number of crossings along a direction no face
    lines up with), in slices of 512 points."""
    from scenes.parts import ray_distances
    d = np.array([0.5773, 0.5774, 0.5775]) / np.linalg.norm([0.5773, 0.5774, 0.5775])
    out = [np.isfinite(ray_distances(part.vertices_m, part.faces, p, np.broadcast_to(d, p.shape))).sum(axis=1) % 2
           == 1 for p in np.array_split(points, max(1, len(points) // 512))]
    return np.concatenate(out)


def _overlap_share(part, body):
    """Return the share (0..1) of a part inside the body: of a closed mesh's volume (grid probes over its bounding
    box, kept where they are inside the part), else of its vertices and face centres."""
    import trimesh
    v, f = part.vertices_m, part.faces
    probes = np.concatenate([v, v[f].mean(axis=1)])
    share = float(_inside_body(probes, body).mean())
    if trimesh.Trimesh(v, f, process=False).is_watertight:
        lo, hi = v.min(axis=0), v.max(axis=0)
        axes = [lo[i] + (np.arange(_GRID) + 0.5) * (hi[i] - lo[i]) / _GRID for i in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        in_body = _inside_body(grid, body)
        if np.any(in_body):            # only then the (slower) parity test over the whole grid
            in_part = _in_part(grid, part)
            share = max(share, float((in_part & in_body).sum()) / max(int(in_part.sum()), 1))
    return share


def _metres_hint(table):
    t = np.asarray(table.get("translate_mm", [0.0, 0.0, 0.0]), dtype=float)
    if t.shape == (3,) and 0 < np.max(np.abs(t)) < 1.0:
        return (f" translate_mm = {t.tolist()} is under 1 mm: is it in metres? translate_mm is in millimetres "
                f"(x 1000: {np.round(t * 1000, 3).tolist()})")
    return ""


def check_scene(parts, part_tables, diodes, body, where):
    """Raise SceneError for duplicate diode or part names, a hinge beyond +-360 deg, or a part whose volume
    overlaps the body's interior (with a hint when its translate_mm looks like metres)."""
    for kind, names in (("diodes", [d.name for d in diodes]), ("parts", [p.name for p in parts])):
        dup = _duplicate(names)
        if dup is not None:
            table = "[[diode]]" if kind == "diodes" else "[[part]]"
            raise SceneError(f"{where}: two {kind} share a name ({dup!r}); give each {table} its own name (names "
                             "label the run file's columns and the pictures)")
    for part, table in zip(parts, part_tables):
        hinge = table.get("hinge") if isinstance(table, dict) else None
        if isinstance(hinge, dict):
            angle = float(hinge.get("angle_deg"))
            if abs(angle) > HINGE_MAX_DEG:
                raise SceneError(f"{where} [[part]] {part.name!r}: hinge angle_deg = {angle:g} is beyond "
                                 f"+-{HINGE_MAX_DEG:g} deg; give the deployed angle in degrees (e.g. 90)")
        share = _overlap_share(part, body)
        if share > 0:
            raise SceneError(f"{where} [[part]] {part.name!r}: {share:.0%} of the part lies inside the body (deeper "
                             f"than {OVERLAP_TOLERANCE_M * 1e3:g} mm behind its faces); place it outside, against a "
                             f"face at most.{_metres_hint(table)}")
