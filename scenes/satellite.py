"""One satellite and the views the simulator builds from its configuration, each built once.

:class:`Satellite` wraps a :class:`scenes.config.SatelliteConfig` and gives the renderer's diode surfaces
(:class:`DiodeSurfaces`), its occluder mesh (:func:`scenes.meshes.build_satellite_mesh`), the analytic
model's body box (:class:`BodyBox`) and the picture's parts (the picture layer, :func:`simcore.picture.scene.build_scene`,
makes the Mitsuba scene from a Satellite).
The two plain data classes live here, below the renderer and the analytic model that use them.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from scenes.config import SatelliteConfig, body_side_normal
from scenes.meshes import build_parts, build_satellite_mesh


@dataclass(frozen=True)
class DiodeSurfaces:
    """K rectangular diodes in the body frame (metres).

    ``positions_m`` (K, 3): centre of each sensitive surface; ``frames`` (K, 3, 3):
    rows (u, v, n), n the outward normal; ``sizes_m`` (K, 2): sides along u and v.
    ``apertures``: optional sequence of K ``simcore.shapes.aperture.WellAperture`` used only
    to shape the albedo sampling (the traced mesh decides what is blocked). ``windows``: optional
    sequence of K ``simcore.shapes.window.Window`` or None (a cover glass over the diode, traced per
    sample: :meth:`simcore.render.windows.CoverGlass._through_window`); None, or all None: no window anywhere (the kernels
    then run exactly the code they ran before windows existed).
    """

    positions_m: np.ndarray
    frames: np.ndarray
    sizes_m: np.ndarray
    apertures: tuple = None
    windows: tuple = None

    def __post_init__(self):
        p = np.asarray(self.positions_m, dtype=float)
        f = np.asarray(self.frames, dtype=float)
        s = np.asarray(self.sizes_m, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"diode positions_m must have shape (K, 3), got {p.shape}")
        k = p.shape[0]
        if f.shape != (k, 3, 3):
            raise ValueError(f"diode frames must have shape ({k}, 3, 3) (rows u, v, n), got {f.shape}")
        if s.shape == (2,):
            s = np.broadcast_to(s, (k, 2)).copy()
        if s.shape != (k, 2) or not np.all(s > 0):
            raise ValueError(f"diode sizes_m must be positive with shape ({k}, 2) or (2,), got {s.shape}")
        err = np.abs(np.einsum("kij,klj->kil", f, f) - np.eye(3)).max() if k else 0.0
        if err > 1e-6:
            raise ValueError(f"diode frames must be orthonormal (rows u, v, n); worst deviation {err:.2e}")
        if not (np.all(np.isfinite(p))):
            raise ValueError("diode positions_m must be finite")
        if self.apertures is not None and len(self.apertures) != k:
            raise ValueError(f"apertures must list one WellAperture per diode ({k}), got {len(self.apertures)}")
        object.__setattr__(self, "positions_m", p)
        object.__setattr__(self, "frames", f)
        object.__setattr__(self, "sizes_m", s)
        if self.apertures is not None:
            object.__setattr__(self, "apertures", tuple(self.apertures))
        if self.windows is not None:
            if len(self.windows) != k:
                raise ValueError(f"windows must list one Window or None per diode ({k}), got {len(self.windows)}")
            object.__setattr__(self, "windows", None if all(w is None for w in self.windows)
                               else tuple(self.windows))

    @property
    def count(self):
        return self.positions_m.shape[0]

    @classmethod
    def from_config(cls, config):
        """Return the DiodeSurfaces of a ``scenes.config.SatelliteConfig`` (its ``positions_m``,
        ``frames`` and ``aperture`` — one WellAperture shared by all diodes or one per diode)."""
        frames = np.asarray(config.frames, dtype=float)
        ap = getattr(config, "apertures", None)
        if ap is None:
            ap = config.aperture
        aps = tuple(ap) if isinstance(ap, (list, tuple)) else (ap,) * frames.shape[0]
        sizes = np.array([[a.diode_x_m, a.diode_y_m] for a in aps])
        return cls(np.asarray(config.positions_m, dtype=float), frames, sizes, aps,
                   getattr(config, "windows", None))

    def subset(self, idx):
        """Return the DiodeSurfaces of the diodes ``idx`` (indices), in that order."""
        idx = list(idx)
        return DiodeSurfaces(self.positions_m[idx], self.frames[idx], self.sizes_m[idx],
                             None if self.apertures is None else [self.apertures[i] for i in idx],
                             None if self.windows is None else [self.windows[i] for i in idx])



@dataclass(frozen=True)
class BodyBox:
    """The satellite body as an occluding box: half extents (3,) and the diodes' centres (K, 3),
    body frame, metres; ``panel_normals`` (K, 3) the outward normals of the panels they sit on."""

    half_m: tuple
    positions_m: np.ndarray
    panel_normals: np.ndarray

    @classmethod
    def from_config(cls, config):
        """Return the body box of a ``scenes.config.SatelliteConfig``, or None where it has no body ([body] none)."""
        if getattr(config.body, "none", False):
            return None
        return cls(tuple(float(x) / 2 for x in config.body.size_m), np.asarray(config.positions_m, float),
                   np.array([body_side_normal(d, config.body) for d in config.diodes], float))



class Satellite:
    """A satellite configuration with its views, each built on first use and kept: ``diodes``
    (:class:`DiodeSurfaces`), ``parts`` (:func:`scenes.meshes.build_parts`), ``mesh`` (the occluder mesh of
    those parts), ``body_box`` (:class:`BodyBox`, None without a body) and ``display_parts`` (the picture's parts)."""

    def __init__(self, config):
        if not isinstance(config, SatelliteConfig):
            raise TypeError(f"a Satellite is made from a scenes.config.SatelliteConfig, got {type(config).__name__}")
        self.config = config

    @classmethod
    def load(cls, name_or_path, **kwargs):
        """Return the Satellite of a configuration name or path (``SatelliteConfig.load`` and its keywords)."""
        return cls(SatelliteConfig.load(name_or_path, **kwargs))

    def __repr__(self):
        return f"Satellite({self.config.name!r}, {self.config.n_diodes} diodes)"

    @cached_property
    def diodes(self):
        """The renderer's diode surfaces (:meth:`DiodeSurfaces.from_config`)."""
        return DiodeSurfaces.from_config(self.config)

    @cached_property
    def parts(self):
        """The occluding parts by name (:func:`scenes.meshes.build_parts`): the mesh's and the mounts' rule."""
        return build_parts(self.config)

    @cached_property
    def mesh(self):
        """The occluder mesh (body, ramps, floors, wells, plugs, parts; not the diodes), body frame, metres."""
        return build_satellite_mesh(self.config, self.parts)

    @cached_property
    def display_parts(self):
        """The picture's parts by name: the occluding parts and each diode's surface (``build_parts(...,
        include_diodes=True)``)."""
        return build_parts(self.config, include_diodes=True)

    @cached_property
    def body_box(self):
        """The body as the analytic model's occluding box (:meth:`BodyBox.from_config`), None without a body."""
        return BodyBox.from_config(self.config)
