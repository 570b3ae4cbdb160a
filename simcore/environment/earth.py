"""The Earth a run sees: its reflectivity map, radius and sea, and the sea's sun glint, in one object.

:class:`Earth` is what the renderer (``Renderer.from_scene``), the analytic model
(``diode_irradiance(earth=...)``), the on-board model and the picture take. Its map keeps its own
orientation (:class:`simcore.environment.maps.ReflectivityMap`: either row order, column 0 the western-most
cell from ``lon_west_deg``); the sea fraction and the glint's sea are in the map's row order, and
:meth:`Earth.renderer_layout` gives the renderer all of them south first.
"""
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from simcore.environment.maps import ReflectivityMap, as_map


@dataclass(frozen=True, eq=False)
class Earth:
    """A reflecting Earth: ``map`` (a :class:`ReflectivityMap`, or what :func:`simcore.environment.maps.as_map`
    takes: None for TOMS 2005, a south-first array) and ``glint`` (a :class:`simcore.radiometry.glint.SunGlint`
    whose ``sea`` is None, GSHHG's, or on the map's grid and row order; None: no glint)."""

    map: ReflectivityMap = None
    glint: object = None

    def __post_init__(self):
        object.__setattr__(self, "map", as_map(self.map))
        sea = getattr(self.glint, "sea", None)
        if sea is not None and np.shape(sea) != self.map.shape:
            raise ValueError(f"the glint's sea fraction has shape {np.shape(sea)}, the map {self.map.shape}")

    @property
    def radius_m(self):
        """The sphere's radius (m): the map's."""
        return self.map.radius_m

    @property
    def lon_west_deg(self):
        """The western edge of the map's column 0 (deg)."""
        return float(self.map.lon_edges_deg[0])

    @cached_property
    def sea_fraction(self):
        """The sea fraction of the map's cells (n_lat, n_lon) in the map's row order, as the glint sees it
        (its own sea, or GSHHG's), or None without glint."""
        return None if self.glint is None else self.glint.sea_fraction(self.map)

    def renderer_layout(self):
        """Return the renderer's Earth keywords: ``reflectivity`` (row 0 the southern band), ``lon_west_deg``,
        ``earth_radius_m`` and, with glint, ``glint`` whose sea is in that same row order."""
        out = {"reflectivity": self.map.values_south_first, "lon_west_deg": self.lon_west_deg,
               "earth_radius_m": self.radius_m}
        if self.glint is not None:
            sea = self.sea_fraction if self.map.south_first else self.sea_fraction[::-1]
            out["glint"] = replace(self.glint, sea=sea)
        return out

    def on_grid(self, grid):
        """Return this Earth on ``grid``, a map with this map's geography split ``f`` x ``f`` finer
        (:meth:`ReflectivityMap.refined`; f = 1: ``grid`` itself): each sub-cell keeps its cell's sea fraction."""
        f = grid.shape[0] // self.map.shape[0]
        if f < 1 or grid.shape != (f * self.map.shape[0], f * self.map.shape[1]):
            raise ValueError(f"a map of shape {grid.shape} is no refinement of this Earth's {self.map.shape}")
        if self.glint is None or self.glint.sea is None:
            return Earth(grid, self.glint)
        sea = self.glint.sea if f == 1 else np.repeat(np.repeat(self.glint.sea, f, axis=0), f, axis=1)
        return Earth(grid, replace(self.glint, sea=sea))

    def refined(self, factor):
        """Return this Earth on its map refined ``factor`` x ``factor`` (:meth:`on_grid`)."""
        return self.on_grid(self.map.refined(factor))
