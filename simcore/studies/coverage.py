"""Redundancy coverage of the attitude sphere: how many live diodes see each direction.

Thesis sec. 3.2.4 (figures 3.7-3.13): the sphere of directions in the body
frame is cut into equal-area HEALPix pixels (Gorski et al. 2005; nside 16 =
3072 pixels, pole on body z). A diode "sees" a pixel when the angle between
the pixel centre and the diode normal is below ``FOV - 0.01 deg`` (the margin
stands for mounting and data-sheet uncertainty, and makes the FOV 90 baseline
show lines of red pixels on the panel planes). Each pixel is coloured red
(<= 2 live diodes see it), yellow (exactly 3) or green (>= 4).
"""

import healpy as hp
import numpy as np

from simcore.plots import plot_coverage_map

NSIDE = 16
FOV_MARGIN_DEG = 0.01
CLASSES = ("red", "yellow", "green")


def _normals_fov_dead(config_or_normals, fov_deg, dead):
    """Return (normals (K, 3), fov (K,) deg, live (K,) bool) from a configuration or normals."""
    if hasattr(config_or_normals, "normals"):
        normals = np.asarray(config_or_normals.normals, dtype=float)
        fov = np.asarray(config_or_normals.fov_deg if fov_deg is None else fov_deg, dtype=float)
        cfg_dead = np.asarray(getattr(config_or_normals, "dead", np.zeros(len(normals), bool)), dtype=bool)
    else:
        normals = np.asarray(config_or_normals, dtype=float)
        if fov_deg is None:
            raise ValueError("give fov_deg (a scalar or one per diode) together with bare normals")
        fov = np.asarray(fov_deg, dtype=float)
        cfg_dead = np.zeros(len(normals), bool)
    if normals.ndim != 2 or normals.shape[1] != 3:
        raise ValueError(f"diode normals must have shape (K, 3), got {normals.shape}")
    norms = np.linalg.norm(normals, axis=1)
    if not np.allclose(norms, 1.0, atol=1e-6):
        raise ValueError(f"diode normals must be unit vectors; norms are {np.round(norms, 6).tolist()}")
    fov = np.broadcast_to(fov, (len(normals),)).astype(float)
    if np.any((fov <= 0) | (fov > 180)):
        raise ValueError(f"FOV must lie in (0, 180] deg, got {fov.tolist()}")
    live = ~cfg_dead
    dead_idx = np.asarray(dead, dtype=int).ravel()
    if np.any((dead_idx < 0) | (dead_idx >= len(normals))):
        raise ValueError(f"dead diode indices {dead_idx.tolist()} out of range 0..{len(normals) - 1}")
    live[dead_idx] = False
    return normals, fov, live


def pixel_directions(nside=NSIDE):
    """Return the HEALPix pixel centres (12 nside^2, 3), unit vectors in the body frame (RING order)."""


    return np.array(hp.pix2vec(nside, np.arange(hp.nside2npix(nside)))).T


def coverage_map(config_or_normals, fov_deg=None, dead=(), nside=NSIDE):
    """Return the number of live diodes that see each HEALPix pixel centre (12 nside^2,) int, RING order.

    ``config_or_normals``: a :class:`scenes.config.SatelliteConfig` (its normals, per-diode FOV and
    dead mask) or unit normals (K, 3) in the body frame; ``fov_deg`` overrides the FOV (scalar or (K,));
    ``dead``: extra dead diode indices. A diode sees a pixel when the angle to its normal is below
    ``fov - 0.01 deg`` (thesis sec. 3.2.4).
    """
    normals, fov, live = _normals_fov_dead(config_or_normals, fov_deg, dead)
    dirs = pixel_directions(nside)
    angle_deg = np.degrees(np.arccos(np.clip(dirs @ normals[live].T, -1.0, 1.0)))
    return np.sum(angle_deg < fov[live] - FOV_MARGIN_DEG, axis=1)


def coverage_classes(counts):
    """Return the class per pixel: 0 red (<= 2 diodes), 1 yellow (3), 2 green (>= 4)."""
    counts = np.asarray(counts)
    return np.where(counts <= 2, 0, np.where(counts == 3, 1, 2))


def coverage_fractions(config_or_normals, fov_deg=None, dead=(), nside=NSIDE):
    """Return the fractions of the sphere {'red', 'yellow', 'green'} (equal-area pixels; sum 1).

    Same arguments as :func:`coverage_map`; thesis figures 3.8-3.13 use the 14-diode
    configurations with ``dead=[0]``.
    """
    cls = coverage_classes(coverage_map(config_or_normals, fov_deg, dead, nside))
    return {name: float(np.mean(cls == k)) for k, name in enumerate(CLASSES)}


def plot_coverage(config_or_normals, path, fov_deg=None, dead=(), nside=NSIDE, title=None):
    """Write a Mollweide map of the coverage classes (body frame, pole = body z; PNG or PDF by suffix)
    and return its path. Diode normals are marked: live ones with their index, dead ones as crosses."""
    normals, fov, live = _normals_fov_dead(config_or_normals, fov_deg, dead)
    counts = coverage_map(config_or_normals, fov_deg, dead, nside)
    if title is None:
        title = getattr(config_or_normals, "name", f"{len(normals)} diodes")
    plot_coverage_map(counts, title=title, normals_body=normals, dead=np.flatnonzero(~live), path=path)
    return path
