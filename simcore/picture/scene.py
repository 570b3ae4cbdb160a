"""The Mitsuba 3 scene of the satellite over the map-textured Earth (llvm_ad_mono), its camera, and a plain picture.

Render frame = body axes with the satellite at the origin (``docs/conventions.md``):
the Earth sphere (the map's radius, 6371.01 km) sits at ``-R_body_from_ecef @ r_sat_ecef_m``
and is turned by ``R_body_from_ecef`` so that its texture keeps the geography.
Mitsuba's sphere maps a local point to ``u = phi / 2 pi`` (phi from local +x
towards +y) and ``v = theta / pi`` (theta from local +z, the north pole), and its
bitmap texture puts ``v = 0`` at the first stored row. A reflectivity map (any
regular grid; TOMS: row 0 = SOUTH band, column 0 = longitude -179.375 deg) is
flipped north-up, and the sphere's local +x is turned to the western edge of the
map's column 0 (:func:`earth_to_world`), so texture column j is map column j: raw
values (some exceed 1 over ice, never clamped), nearest filtering. The Sun is a
``directional`` emitter whose ``direction`` is the propagation direction, minus the Sun vector.

:class:`Camera` is the pinhole camera handed to Mitsuba and its inverse, the projection that
places annotations (``simcore.picture.view``). :func:`picture` writes the plain radiometric picture (mono),
tone-mapped and tinted with a per-shape false colour; the annotated picture an engineer checks is
``simcore.picture.view.view_picture`` (``sunsim view``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import matplotlib.image

from scenes.config import SatelliteConfig
from scenes.meshes import build_parts
from scenes.satellite import Satellite

from simcore import _llvm
from simcore.environment.earth import Earth
from simcore.constants import R_EARTH_MEAN_M

VARIANT = "llvm_ad_mono"

# false colours (linear RGB multipliers) per part kind, applied to the mono radiance
_TINT = {"earth": (0.70, 0.85, 1.15), "body": (1.0, 1.0, 1.0), "ramp": (1.15, 0.95, 0.55),
         "floor": (0.9, 0.9, 0.9), "well": (0.9, 0.9, 0.9), "diode": (0.45, 0.6, 1.3)}
_REFLECTANCE = {"body": 0.4, "ramp": 0.45, "floor": 0.2, "well": 0.2, "diode": 0.05}


def _mi():
    mi = _llvm.import_mitsuba()

    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    return mi


@dataclass(frozen=True)
class PictureGeometry:
    """One epoch's geometry for a picture: satellite position and Sun direction (ECEF), attitude.

    ``r_sat_ecef_m`` (3,), ``sun_dir_ecef`` (3,) unit vector towards the Sun, ``R_body_from_ecef``
    (3, 3); ``camera_dir_body`` (3,) optional unit vector from the satellite towards the camera.
    """

    r_sat_ecef_m: np.ndarray
    sun_dir_ecef: np.ndarray
    R_body_from_ecef: np.ndarray
    camera_dir_body: np.ndarray | None = None


def _enu(lat_deg, lon_deg):
    """Return the rows (east, north, up) at a geodetic-sphere point, ECEF."""
    la, lo = np.radians(lat_deg), np.radians(lon_deg)
    up = np.array([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    east = np.array([-np.sin(lo), np.cos(lo), 0.0])
    return np.stack([east, np.cross(up, east), up])


def default_geometry(lat_deg=50.0, lon_deg=6.0, altitude_m=668e3):
    """Return a :class:`PictureGeometry`: the satellite 668 km over Europe, the Sun from the side.

    The Sun stands 30 deg above the local horizon in the east-north-east (Europe sunlit, the
    satellite lit from the side); the satellite's long axis (body z) lies level, pointing east,
    its +x panel turned 35 deg from the zenith towards the north so that the top side panels
    and the +z end face the camera; the camera hangs north of the satellite and looks south,
    down 33 deg, over the Alps and the Mediterranean to the Sahara and the Earth's limb.
    """
    east, north, up = _enu(lat_deg, lon_deg)
    r_sat = (R_EARTH_MEAN_M + altitude_m) * up
    sun = _direction(north, east, up, azimuth_deg=75.0, elevation_deg=30.0)
    z_b = east
    tilt = np.radians(35.0)
    x_b = np.cos(tilt) * up + np.sin(tilt) * north
    y_b = np.cross(z_b, x_b)
    R_body_from_ecef = np.stack([x_b, y_b, z_b])
    cam = _direction(north, east, up, azimuth_deg=20.0, elevation_deg=33.0)
    return PictureGeometry(r_sat, sun, R_body_from_ecef, R_body_from_ecef @ cam)


def _direction(north, east, up, azimuth_deg, elevation_deg):
    """Return the unit vector at an azimuth (from north towards east) and elevation, ECEF."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.cos(el) * (np.cos(az) * north + np.sin(az) * east) + np.sin(el) * up


def map_texture_array(reflectivity_map):
    """Return a map's reflectivity as Mitsuba's sphere texture (n_lat, n_lon): row 0 north, column 0 the map's own.

    Raw values, not clamped. Column 0 stays the map's western-most column: :func:`earth_to_world` turns
    the sphere about its polar axis so that the texture's u = 0 lies on that column's western edge.
    """
    return np.ascontiguousarray(np.asarray(reflectivity_map.values_south_first, float)[::-1])


def earth_to_world(R_body_from_ecef, r_sat_body_m, reflectivity_map):
    """Return the Earth sphere's 4 x 4 to_world (render frame, m): ECEF axes turned by the map's first column edge.

    Mitsuba's sphere puts u = 0 at its local +x; the local frame is ECEF rotated about z by the
    longitude of the map's western edge, so texture column j covers the map's column j exactly.
    """
    lon0 = np.radians(float(reflectivity_map.lon_edges_deg[0]))
    c, s = np.cos(lon0), np.sin(lon0)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    m = np.eye(4)
    m[:3, :3] = np.asarray(R_body_from_ecef, float) @ Rz
    m[:3, 3] = -np.asarray(r_sat_body_m, float)
    return m


def _mesh(mi, name, tm, reflectance):
    """Return a Mitsuba mesh (flat shaded, diffuse) from a trimesh in the render frame (m)."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "diffuse", "reflectance": {"type": "uniform", "value": float(reflectance)}})
    props["face_normals"] = True
    mesh = mi.Mesh(name, len(tm.vertices), len(tm.faces), props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = np.asarray(tm.vertices, dtype=np.float32).ravel()
    params["faces"] = np.asarray(tm.faces, dtype=np.uint32).ravel()
    params.update()
    return mesh


@dataclass(frozen=True)
class Camera:
    """A pinhole camera in the render frame (m): Mitsuba's ``perspective`` sensor with ``fov_axis = "x"``.

    ``to_world()`` is the matrix handed to Mitsuba; ``project()`` inverts it, so annotations land on
    the pixels Mitsuba draws (``tests/scenes/test_view.py`` renders small bright spheres to prove it).
    """

    origin_m: tuple
    target_m: tuple
    up: tuple
    fov_x_deg: float
    width: int
    height: int

    @property
    def look_dir(self):
        """Return the unit viewing direction (3,), render frame."""
        d = np.asarray(self.target_m, float) - np.asarray(self.origin_m, float)
        return d / np.linalg.norm(d)

    def to_world(self):
        """Return the camera's 4 x 4 to_world: columns (left, up, forward, origin), as Mitsuba's look_at builds it."""
        d = self.look_dir
        left = np.cross(np.asarray(self.up, float), d)
        if np.linalg.norm(left) < 1e-9:
            raise ValueError("the camera's up vector is parallel to its viewing direction; give another up")
        left /= np.linalg.norm(left)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, np.asarray(self.origin_m, float)
        return m

    def project(self, points_m):
        """Return (pixel xy (N, 2), depth_m (N,)) of render-frame points: x right, y down, pixel i spans [i, i + 1).

        Depth is along the viewing direction; points with depth <= 0 are behind the camera (their xy is NaN).
        """
        p = np.atleast_2d(np.asarray(points_m, float)) - np.asarray(self.origin_m, float)
        m = self.to_world()
        x, y, z = p @ m[:3, 0], p @ m[:3, 1], p @ m[:3, 2]
        tan_x = np.tan(np.radians(self.fov_x_deg) / 2.0)
        tan_y = tan_x * self.height / self.width
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(z > 0, 0.5 - 0.5 * x / (z * tan_x), np.nan)   # Mitsuba's film x runs to camera -x (left)
            v = np.where(z > 0, 0.5 - 0.5 * y / (z * tan_y), np.nan)
        return np.column_stack([u * self.width, v * self.height]), z

    def sensor_dict(self, spp):
        """Return Mitsuba's sensor dictionary for this camera at ``spp`` samples per pixel (luminance film)."""
        mi = _mi()
        return {
            "type": "perspective", "fov": float(self.fov_x_deg), "fov_axis": "x",
            "near_clip": 0.01, "far_clip": 2.0e7,
            "to_world": mi.ScalarTransform4f(self.to_world()),
            "sampler": {"type": "independent", "sample_count": int(spp)},
            "film": {"type": "hdrfilm", "width": int(self.width), "height": int(self.height),
                     "rfilter": {"type": "box"}, "pixel_format": "luminance"},
        }


def _default_camera(g, resolution, camera_distance_m, fov_deg):
    R = np.asarray(g.R_body_from_ecef, float)
    zenith_body = R @ np.asarray(g.r_sat_ecef_m, float)
    zenith_body /= np.linalg.norm(zenith_body)
    sun_body = R @ np.asarray(g.sun_dir_ecef, float)
    cam_dir = g.camera_dir_body
    if cam_dir is None:
        # look down 28 deg from a horizontal direction perpendicular to the Sun's horizontal bearing
        horiz = np.cross(zenith_body, sun_body)
        horiz = horiz / np.linalg.norm(horiz) if np.linalg.norm(horiz) > 1e-9 else np.cross(zenith_body, [1, 0, 0])
        cam_dir = np.cos(np.radians(28)) * horiz + np.sin(np.radians(28)) * zenith_body
    cam_dir = np.asarray(cam_dir, float) / np.linalg.norm(cam_dir)
    return Camera(tuple(camera_distance_m * cam_dir), (0.0, 0.0, 0.0), tuple(zenith_body), float(fov_deg),
                  int(resolution[0]), int(resolution[1]))


def build_scene(config, epoch_geometry=None, resolution=(960, 540), spp=64, camera_distance_m=1.0,
                fov_deg=36.0, max_depth=4, *, camera=None, earth=None, show_earth=True, fill_radiance=0.0):
    """Return (Mitsuba scene dict, shape ids, their part kinds, the :class:`Camera`) for a picture (render frame, m).

    ``config``: a :class:`scenes.config.SatelliteConfig` or a :class:`scenes.satellite.Satellite`;
    ``camera`` overrides the default one (28 deg above the horizontal, ``camera_distance_m`` away);
    ``earth``: a :class:`simcore.environment.earth.Earth` (its map textures the sphere of its radius with raw
    values; default the TOMS 2005 Earth); ``show_earth=False`` leaves it out (a close-up of the satellite
    alone); ``fill_radiance`` > 0 adds a uniform sky of that
    radiance (units of E_sun / pi) so that faces turned from the Sun stay legible.
    """
    mi = _mi()

    g = default_geometry() if epoch_geometry is None else epoch_geometry
    if isinstance(g, dict):
        g = PictureGeometry(**g)
    R = np.asarray(g.R_body_from_ecef, float)
    r_sat_body = R @ np.asarray(g.r_sat_ecef_m, float)
    sun_body = R @ np.asarray(g.sun_dir_ecef, float)
    sun_body = sun_body / np.linalg.norm(sun_body)
    if camera is None:
        camera = _default_camera(g, resolution, camera_distance_m, fov_deg)
    if earth is None:
        earth = Earth()
    if not isinstance(earth, Earth):
        raise TypeError(f"the picture's earth is a simcore.environment.earth.Earth, got {type(earth).__name__}")
    rmap = earth.map
    parts = (config.display_parts if isinstance(config, Satellite)
             else build_parts(config, include_diodes=True))
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth)},
        "sensor": camera.sensor_dict(spp),
        # irradiance pi W/m^2 makes a white Lambertian plate facing the Sun radiance 1 (display scale)
        "sun": {"type": "directional", "direction": (-sun_body).tolist(), "irradiance": float(np.pi)},
    }
    if fill_radiance > 0:
        scene["sky"] = {"type": "constant", "radiance": {"type": "uniform", "value": float(fill_radiance)}}
    names, kinds = [], []
    if show_earth:
        bitmap = mi.Bitmap(map_texture_array(rmap).astype(np.float32))
        scene["earth"] = {
            "type": "sphere", "radius": float(rmap.radius_m),
            "to_world": mi.ScalarTransform4f(earth_to_world(R, r_sat_body, rmap)),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "bitmap": bitmap, "raw": True,
                                                        "filter_type": "nearest"}},
        }
        names.append("earth")
        kinds.append("earth")
    for name, tm in parts.items():
        kind = name.split("_")[0]
        scene[name] = _mesh(mi, name, tm, _REFLECTANCE.get(kind, _REFLECTANCE["body"]))
        names.append(name)
        kinds.append(kind)
    return scene, names, kinds, camera


def load_scene(scene_dict):
    """Return the loaded Mitsuba scene, without the Earth sphere's spurious transform warnings.

    Mitsuba checks a sphere's to_world for shear and uneven scale with an absolute 1e-6 tolerance
    in float32, which a 6371 km radius always trips; the transform is a rotation times a uniform scale.
    """
    mi = _mi()
    logger = mi.logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)
    try:
        return mi.load_dict(scene_dict)
    finally:
        logger.set_log_level(level)


@dataclass(frozen=True)
class RenderPasses:
    """What one render gives a picture: radiance and, per pixel centre, the first shape hit.

    ``radiance`` (H, W) in units of E_sun / pi; ``name`` and ``kind`` (H, W) object arrays of the
    shape id and part kind ('' where the ray leaves the scene); ``hit_m`` and ``normal`` (H, W, 3)
    render-frame hit points and unit shading normals (NaN where nothing is hit).
    """

    radiance: np.ndarray
    name: np.ndarray
    kind: np.ndarray
    hit_m: np.ndarray
    normal: np.ndarray


def render_passes(scene, names, kinds, spp, seed=0):
    """Return the :class:`RenderPasses` of a loaded scene: a path-traced image plus one primary ray per pixel centre."""
    mi = _mi()
    sensor = scene.sensors()[0]
    w, h = (int(v) for v in sensor.film().size())
    radiance = np.array(mi.render(scene, seed=seed, spp=int(spp)))[..., 0]
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    pos = mi.Point2f(_llvm.host_array(mi.Float, (jj + 0.5) / w), _llvm.host_array(mi.Float, (ii + 0.5) / h))
    rays, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(rays)
    hit = np.array(si.is_valid())
    name = np.full(h * w, "", dtype=object)
    kind = np.full(h * w, "", dtype=object)
    by_id = dict(zip(names, kinds))
    for shape in scene.shapes():
        mask = np.array(si.shape == mi.ShapePtr(shape)) & hit
        name[mask] = shape.id()
        kind[mask] = by_id[shape.id()]
    p = np.array(si.p, dtype=float).T
    n = np.array(si.sh_frame.n, dtype=float).T
    p[~hit], n[~hit] = np.nan, np.nan
    return RenderPasses(radiance, name.reshape(h, w), kind.reshape(h, w), p.reshape(h, w, 3), n.reshape(h, w, 3))


@dataclass(frozen=True)
class Picture:
    """A rendered picture: the PNG path, the display image (H, W, 3) uint8 and masks per part kind."""

    path: str
    rgb: np.ndarray
    radiance: np.ndarray
    kind: np.ndarray  # (H, W) object array of part kinds ('' for background)

    @property
    def satellite_mask(self):
        """Return (H, W) True where the first hit is a part of the satellite."""
        return (self.kind != "") & (self.kind != "earth")


def picture(config, path_png, epoch_geometry=None, spp=64, resolution=(960, 540), camera_distance_m=1.0,
            fov_deg=36.0, seed=0, exposure=1.0):
    """Render the satellite over the Earth and write a plain (unannotated) PNG; return a :class:`Picture`.

    ``config``: a :class:`scenes.config.SatelliteConfig`, a :class:`scenes.satellite.Satellite` or a configuration
    name; ``epoch_geometry``:
    a :class:`PictureGeometry` or a dict of its fields (default :func:`default_geometry`);
    ``camera_distance_m`` from the satellite centre, ``fov_deg`` horizontal; ``exposure`` scales the
    display image only (1: a white plate facing the Sun is just white). ``Picture.radiance`` is
    the rendered radiance in units of E_sun / pi (the Sun's irradiance is pi). The annotated view
    an engineer checks is :func:`simcore.picture.view.view_picture`.
    """
    if not isinstance(config, (SatelliteConfig, Satellite)):
        config = SatelliteConfig.load(config)
    scene_dict, names, kinds, _ = build_scene(config, epoch_geometry, resolution, spp, camera_distance_m, fov_deg)
    passes = render_passes(load_scene(scene_dict), names, kinds, spp, seed)
    rgb = _tone_map(passes.radiance * float(exposure), passes.kind)
    matplotlib.image.imsave(str(path_png), rgb)
    return Picture(str(path_png), rgb, passes.radiance, passes.kind)


def _tone_map(radiance, kind):
    """Return an sRGB uint8 image (H, W, 3): false-colour tint per part, exposure 1, sRGB transfer curve."""
    tint = np.ones(radiance.shape + (3,))
    for k, c in _TINT.items():
        tint[kind == k] = c
    return srgb8(np.clip(radiance[..., None] * tint, 0.0, 1.0))


def srgb8(linear):
    """Return sRGB uint8 of linear values in 0..1 (the sRGB transfer curve)."""
    lin = np.clip(np.asarray(linear, float), 0.0, 1.0)
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(lin, 1 / 2.4) - 0.055)
    return (srgb * 255 + 0.5).astype(np.uint8)
