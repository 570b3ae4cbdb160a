"""Earth reflectivity maps on regular latitude/longitude grids, with their cell geometry.

A :class:`ReflectivityMap` holds the reflectivity of each cell, ``values``
of shape ``(n_lat, n_lon)``, and the cell-centre latitudes and longitudes
(degrees) that say where each row and column lies. The shipped maps follow
``simcore/data/README.md``: row 0 is the SOUTH band, column 0 the western-most
cell (TOMS 180 x 288, 1 x 1.25 deg; CERES 180 x 360, 1 x 1 deg). A user map may
have any resolution and either latitude order (south-first or north-first);
it must tile the whole globe, because every part of the sunlit Earth reflects
towards the satellite and a missing part would silently count as black.

The geometry of the sphere of radius ``radius_m`` (default the thesis' and
the albedo toolbox's mean Earth radius, 6371.01 km) is computed once per map
and cached: cell areas (exact spherical zones), unit outward normals at the
cell centres and the centres themselves, in ECEF (ITRS) axes:
``n = (cos lat cos lon, cos lat sin lon, sin lat)``.

Cell area of the band between latitudes ``lat_lo`` and ``lat_hi``
(equivalently polar angles ``theta +- dtheta/2``, SPEC sec. 3 and the
toolbox's ``cellarea.m``)::

    A = R^2 * dlon * (sin(lat_hi) - sin(lat_lo))

Values are used as they are: TOMS exceeds 1.0 over some ice and is never
clamped. Negative or non-finite values are rejected.
"""
import difflib
from dataclasses import dataclass
from functools import cached_property, lru_cache
from importlib import resources

import os
import zipfile

import numpy as np

from simcore.constants import R_EARTH_MEAN_M
from simcore.errors import InputNotFoundError, InvalidInputError

# Relative tolerance (of one grid step) for "regularly spaced" and "covers the globe".
_GRID_RTOL = 1e-6


def _data_path(name):
    return resources.files("simcore").joinpath("data", name)


def _regular_step(name, centres_deg):
    """Return the signed constant step of ``centres_deg`` or raise ValueError."""
    if centres_deg.size < 2:
        raise ValueError(f"{name} needs at least 2 cell centres to define a grid, got {centres_deg.size}")
    steps = np.diff(centres_deg)
    step = float(np.mean(steps))
    if step == 0 or not np.all(np.abs(steps - step) <= _GRID_RTOL * abs(step) + 1e-9):
        raise ValueError(f"{name} must be equally spaced cell centres (a regular grid); steps range "
                         f"{steps.min():.9g} .. {steps.max():.9g} deg. Resample the map onto a regular grid first")
    return step


@dataclass(frozen=True, eq=False)
class ReflectivityMap:
    """Reflectivity (unitless, >= 0) on a regular global lat/lon grid, shape (n_lat, n_lon)."""

    values: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    name: str = "user"
    radius_m: float = R_EARTH_MEAN_M

    def __post_init__(self):
        values = np.array(self.values, dtype=float)
        if values.ndim != 2:
            raise ValueError(f"a reflectivity map must be a 2-D array (n_lat, n_lon), got shape {values.shape}")
        n_lat, n_lon = values.shape
        lat = np.array(self.lat_deg, dtype=float).reshape(-1)
        lon = np.array(self.lon_deg, dtype=float).reshape(-1)
        if lat.size != n_lat or lon.size != n_lon:
            raise ValueError(f"the map has shape {values.shape} (n_lat, n_lon) but got {lat.size} latitudes and "
                             f"{lon.size} longitudes; give one cell-centre latitude per row and one longitude "
                             "per column (or transpose the map)")
        if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon))):
            raise ValueError("the map's cell-centre latitudes/longitudes must be finite degrees")
        bad = ~np.isfinite(values)
        if np.any(bad):
            r, c = np.argwhere(bad)[0]
            raise ValueError(f"the reflectivity map has {int(bad.sum())} non-finite (NaN/inf) cells, the first at "
                             f"row {r}, column {c}; fill them (e.g. with a climatology) before using the map")
        neg = values < 0
        if np.any(neg):
            r, c = np.argwhere(neg)[0]
            raise ValueError(f"the reflectivity map has {int(neg.sum())} negative cells (e.g. {values[r, c]:.6g} at "
                             f"row {r}, column {c}); reflectivity must be >= 0 (check for fill values such as -999)")
        dlat = _regular_step("lat_deg", lat)
        dlon = _regular_step("lon_deg", lon)
        if dlon < 0:
            raise ValueError("lon_deg must increase from west to east (column 0 the western-most cell)")
        tol = _GRID_RTOL * abs(dlat) + 1e-9
        lo, hi = min(lat[0], lat[-1]) - abs(dlat) / 2, max(lat[0], lat[-1]) + abs(dlat) / 2
        if abs(lo + 90.0) > tol or abs(hi - 90.0) > tol:
            raise ValueError(f"the map's rows must tile latitudes -90..90 deg (cell centres at +-(90 - step/2)); "
                             f"they cover {lo:.9g}..{hi:.9g} deg. The albedo needs the whole Earth")
        if abs(n_lon * dlon - 360.0) > _GRID_RTOL * dlon * n_lon + 1e-9:
            raise ValueError(f"the map's columns must tile 360 deg of longitude; {n_lon} x {dlon:.9g} deg = "
                             f"{n_lon * dlon:.9g} deg")
        radius = float(self.radius_m)
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"radius_m must be a positive length in metres, got {self.radius_m}")
        values.setflags(write=False)
        lat.setflags(write=False)
        lon.setflags(write=False)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "lat_deg", lat)
        object.__setattr__(self, "lon_deg", lon)
        object.__setattr__(self, "radius_m", radius)

    # ---- constructors -------------------------------------------------
    @classmethod
    def from_array(cls, values, lat_deg=None, lon_deg=None, *, name="user", radius_m=R_EARTH_MEAN_M):
        """Return a map of ``values`` (n_lat, n_lon) on a regular global grid.

        Without ``lat_deg``/``lon_deg`` the grid is the shipped maps' layout:
        row 0 the southern-most band (centre ``-90 + dlat/2``), column 0 the
        western-most cell (centre ``-180 + dlon/2``).
        """
        arr = np.asarray(values, dtype=float)
        if arr.ndim != 2:
            raise ValueError(f"a reflectivity map must be a 2-D array (n_lat, n_lon), got shape {arr.shape}")
        n_lat, n_lon = arr.shape
        if lat_deg is None:
            lat_deg = -90.0 + (np.arange(n_lat) + 0.5) * (180.0 / n_lat)
        if lon_deg is None:
            lon_deg = -180.0 + (np.arange(n_lon) + 0.5) * (360.0 / n_lon)
        return cls(arr, lat_deg, lon_deg, name=name, radius_m=radius_m)

    @classmethod
    def toms2005(cls):
        """Return the shipped TOMS 2005 annual-mean reflectivity map (180 x 288, ~360 nm)."""
        return _toms2005()

    @classmethod
    def ceres2018(cls, kind="all"):
        """Return the shipped CERES 2018 annual shortwave albedo map (180 x 360), ``kind`` 'all' or 'clear' sky."""
        if kind not in ("all", "clear"):
            raise ValueError(f"CERES 2018 maps come as kind='all' (all-sky) or kind='clear' (clear-sky), got {kind!r}")
        return _ceres2018(kind)

    def refined(self, factor):
        """Return this Earth on a grid ``factor`` times finer each way: every cell split into ``factor`` x ``factor``
        sub-cells of its own value (the cell sums' quadrature at a finer step, the same reflectivity)."""
        v = np.repeat(np.repeat(self.values, factor, axis=0), factor, axis=1)
        lat = np.linspace(self.lat_edges_deg[0], self.lat_edges_deg[-1], v.shape[0] + 1)
        lon = np.linspace(self.lon_edges_deg[0], self.lon_edges_deg[-1], v.shape[1] + 1)
        return ReflectivityMap.from_array(v, 0.5 * (lat[1:] + lat[:-1]), 0.5 * (lon[1:] + lon[:-1]),
                                          name=f"{self.name} refined {factor}x{factor}", radius_m=self.radius_m)

    # ---- grid ------------------------------------------------------------
    @property
    def shape(self):
        return self.values.shape

    @property
    def n_lat(self):
        return self.values.shape[0]

    @property
    def n_lon(self):
        return self.values.shape[1]

    @cached_property
    def dlat_deg(self):
        """Return the (positive) latitude step in degrees."""
        return 180.0 / self.n_lat

    @cached_property
    def dlon_deg(self):
        """Return the longitude step in degrees."""
        return 360.0 / self.n_lon

    @property
    def values_south_first(self):
        """Return ``values`` with row 0 the southern-most band, whatever the map's own row order:
        the layout the renderer's texture lookup uses (column 0 stays the western-most cell)."""
        return self.values if self.lat_deg[-1] > self.lat_deg[0] else self.values[::-1]

    @cached_property
    def lat_edges_deg(self):
        """Return the (n_lat + 1) band edges in degrees, in row order."""
        sign = 1.0 if self.lat_deg[-1] > self.lat_deg[0] else -1.0
        return np.clip(np.concatenate([self.lat_deg - sign * self.dlat_deg / 2,
                                       self.lat_deg[-1:] + sign * self.dlat_deg / 2]), -90.0, 90.0)

    @cached_property
    def lon_edges_deg(self):
        """Return the (n_lon + 1) column edges in degrees (west to east)."""
        return np.concatenate([self.lon_deg - self.dlon_deg / 2, self.lon_deg[-1:] + self.dlon_deg / 2])

    @cached_property
    def south_first(self):
        """Return True when row 0 is the southern-most band."""
        return bool(self.lat_deg[-1] > self.lat_deg[0])

    @cached_property
    def row_area_m2(self):
        """Return the area of one cell of each row (n_lat,), m^2 (exact spherical zone / n_lon)."""
        e = np.radians(self.lat_edges_deg)
        return self.radius_m ** 2 * np.radians(self.dlon_deg) * np.abs(np.sin(e[1:]) - np.sin(e[:-1]))

    @cached_property
    def cell_area_m2(self):
        """Return the cell areas (n_lat, n_lon), m^2."""
        return np.broadcast_to(self.row_area_m2[:, None], self.shape)

    @cached_property
    def normals_ecef(self):
        """Return the unit outward normals at the cell centres (n_lat, n_lon, 3), ECEF."""
        lat = np.radians(self.lat_deg)[:, None]
        lon = np.radians(self.lon_deg)[None, :]
        n = np.stack(np.broadcast_arrays(np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon),
                                         np.sin(lat) + 0.0 * lon), axis=-1)
        n.setflags(write=False)
        return n

    @cached_property
    def centres_ecef_m(self):
        """Return the cell centres on the sphere (n_lat, n_lon, 3), ECEF metres."""
        c = self.radius_m * self.normals_ecef
        c.setflags(write=False)
        return c

    @cached_property
    def weights_m2(self):
        """Return reflectivity x cell area (n_lat, n_lon), m^2: the reflecting area of each cell."""
        w = self.values * self.row_area_m2[:, None]
        w.setflags(write=False)
        return w

    @cached_property
    def is_toolbox_layout(self):
        """Return True when the grid is the albedo toolbox's: south-first rows, column 0 centred at -180 + dlon/2."""
        tol = 1e-9 + _GRID_RTOL * self.dlon_deg
        return bool(self.south_first
                    and abs(self.lat_deg[0] - (-90.0 + self.dlat_deg / 2)) <= tol
                    and abs(self.lon_deg[0] - (-180.0 + self.dlon_deg / 2)) <= tol)

    def __repr__(self):
        return (f"ReflectivityMap({self.name!r}, {self.n_lat} x {self.n_lon}, "
                f"{self.dlat_deg:g} x {self.dlon_deg:g} deg, radius {self.radius_m:.6g} m)")


@lru_cache(maxsize=1)
def _toms2005():
    with np.load(_data_path("toms_2005_mean.npz")) as d:
        return ReflectivityMap(d["reflectivity"], d["lat_deg"], d["lon_deg"], name="TOMS 2005 annual mean")


@lru_cache(maxsize=2)
def _ceres2018(kind):
    with np.load(_data_path(f"ceres_2018_{kind}.npz")) as d:
        return ReflectivityMap(d["reflectivity"], d["lat_deg"], d["lon_deg"], name=f"CERES 2018 {kind}-sky")


MAP_NAMES = ("toms2005", "ceres2018-all", "ceres2018-clear")


def uniform_map(albedo):
    """Return a uniform map (TOMS grid, 180 x 288) of reflectivity ``albedo`` everywhere.

    The comparison with Basilisk's albedo module in its ALBEDO_AVG mode, which gives the whole
    Earth one average albedo (e.g. 0.3); ``albedo`` a number or its text, >= 0.
    """
    try:
        value = float(albedo)
    except (TypeError, ValueError):
        raise InvalidInputError(f"uniform:{albedo} needs a number: the mean albedo, e.g. uniform:0.3") from None
    if not (np.isfinite(value) and value >= 0):
        raise InvalidInputError(f"a uniform map's albedo must be a finite number >= 0 (e.g. uniform:0.3), got {albedo}")
    return ReflectivityMap.from_array(np.full((180, 288), value), name=f"uniform {value:g}")


def named_map(name):
    """Return the shipped map called ``name`` (:data:`MAP_NAMES`; '_' may stand for '-'), a uniform map
    ``uniform:A`` (:func:`uniform_map`) or one read from a .npz file holding ``reflectivity`` (and
    optionally ``lat_deg``, ``lon_deg`` cell centres)."""
    key = str(name).replace("_", "-")
    if key == "toms2005":
        return ReflectivityMap.toms2005()
    if key in ("ceres2018-all", "ceres2018-clear"):
        return ReflectivityMap.ceres2018(key.split("-")[1])
    if key.startswith("uniform:"):
        return uniform_map(key.split(":", 1)[1])
    if str(name).endswith(".npz"):
        if not os.path.isfile(name):
            raise InputNotFoundError(f"reflectivity map file {name} not found; give an existing .npz file or one "
                                     f"of {', '.join(MAP_NAMES)}")
        try:
            with open(name, "rb") as fh, np.load(fh) as z:     # closed also where numpy refuses the file
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise InvalidInputError(f"{name} is not a readable .npz map ({exc}); save the map as "
                                    "numpy.savez(path, reflectivity=..., lat_deg=..., lon_deg=...)") from None
        if "reflectivity" not in arrays:
            raise InvalidInputError(f"{name} has no 'reflectivity' array; save the map as numpy.savez(path, "
                                    "reflectivity=..., lat_deg=..., lon_deg=...)")
        try:
            return ReflectivityMap.from_array(arrays["reflectivity"], arrays.get("lat_deg"), arrays.get("lon_deg"),
                                              name=str(name))
        except ValueError as exc:
            raise InvalidInputError(f"{name}: {exc}") from None
    close = difflib.get_close_matches(key, MAP_NAMES, n=1)
    hint = f"did you mean {close[0]}? " if close else ""
    raise InvalidInputError(f"unknown reflectivity map {name!r}; {hint}use one of {', '.join(MAP_NAMES)}, "
                            "uniform:ALBEDO or a .npz file")


def as_map(reflectivity):
    """Return a :class:`ReflectivityMap`: ``None`` -> TOMS 2005, a map as is, an array via ``from_array``."""
    if reflectivity is None:
        return ReflectivityMap.toms2005()
    if isinstance(reflectivity, ReflectivityMap):
        return reflectivity
    return ReflectivityMap.from_array(reflectivity)
