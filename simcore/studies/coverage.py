"""Redundancy coverage of the attitude sphere: how many live diodes see each direction.

Thesis sec. 3.2.4 (figures 3.7-3.13): the sphere of directions in the body
frame is cut into equal-area HEALPix pixels (Gorski et al. 2005; nside 16 =
3072 pixels, pole on body z). A diode "sees" a pixel when the angle between
the pixel centre and the diode normal is below ``FOV - FOV_MARGIN_DEG``. Each
pixel is coloured red (<= 2 live diodes see it), yellow (exactly 3) or green
(>= 4).

The counting rule follows the thesis' words: a pixel counts when diodes have
"that area center within its field of view", with the acceptance reduced "a
tiny bit less than given FOV" for mounting and data-sheet uncertainty (which
is what draws the lines of red pixels on the panel planes of fig. 3.7). The
thesis never prints the reduction; its captions bracket it. With this
geometry, pixel centres lie exactly on the cone (fig. 3.7: the margin must
be > 0), 0.00521 deg inside a FOV-75 cone (7 centres of fig. 3.12, which the
caption counts as unseen: margin > 0.00521 deg) and 0.01020 deg inside a
FOV-70 cone (8 centres of fig. 3.13, counted as seen: margin < 0.01020 deg);
the next centres inside a cone lie 0.0144 deg in (fig. 3.11), and centres
outside a cone never count. Every margin in (0.00521, 0.01020) deg gives the
same six maps and none outside does, so the margin is not a tuning knob but
the thesis' unprinted parameter, known to that interval; ``FOV_MARGIN_DEG``
is its centre, 0.0077 deg, 0.0025 deg from either tie (tests/studies/test_coverage.py
recomputes the interval from the captions).

A rule without any margin does not reproduce the captions: the bare centre
test (margin -> 0) counts the 7 centres of fig. 3.12 as seen (yellow 0.0501,
caption 0.0508), and counting a pixel when the cone covers more than half of
its area (tie-free, and exactly the red lines of fig. 3.7 by symmetry; area
fractions from nested HEALPix sub-pixels down to nside 32768, each known to
+-0.0008, every decision but the symmetric ties at least 0.0024 from 1/2)
reproduces figs. 3.7 and 3.9-3.13 but gives fig. 3.8 yellow 0.0674 against
the caption's 0.0667: the HEALPix pixels at |z| = 2/3 (the polar-cap
boundary) have centres 0.21 deg inside a tilt-20 cone but only 41.6 % of
their area inside it, and the thesis, counting centres, coloured them as
seen.
"""

import healpy as hp
import numpy as np

from simcore.plots import plot_coverage_map

NSIDE = 16
FOV_MARGIN_DEG = 0.0077  # the centre of (0.00521, 0.01020) deg, the margins that give all six captions
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
    ``fov - FOV_MARGIN_DEG`` (thesis sec. 3.2.4; the module docstring says where the margin comes from).
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
