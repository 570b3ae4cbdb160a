"""The renderer's inputs and outputs: the diodes' surfaces (:class:`DiodeSurfaces`) and the rendered irradiance
per epoch and diode (:class:`RenderResult`)."""
from dataclasses import dataclass, field

import numpy as np


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


@dataclass
class RenderResult:
    """Rendered irradiance per (epoch, diode), W/m^2 on the diode's sensitive area.

    ``direct_*``: the Sun seen directly; ``albedo_*``: sunlight reflected by the
    Earth; ``*_se_w_m2``: one standard error of the Monte-Carlo estimate;
    ``reflected_*``: Sun and Earth light that reached the diode after at least one reflection on
the spacecraft (exactly 0 when every part is 'black'); ``total_w_m2`` the sum of the three;
``*_dof``: the standard error's effective degrees of freedom (inf where
    it is exactly 0; see ``simcore.render.sampling.Rounds._round``); ``*_samples``: rays traced for each (epoch, diode) (0 where the value is
    exactly zero by geometry: Sun behind the diode, full eclipse, no sunlit Earth
    in view). ``valid`` (N,): False for epochs whose inputs were not finite
    (their values are NaN).
    """

    direct_w_m2: np.ndarray
    direct_se_w_m2: np.ndarray
    albedo_w_m2: np.ndarray
    albedo_se_w_m2: np.ndarray
    direct_samples: np.ndarray
    albedo_samples: np.ndarray
    valid: np.ndarray
    variant: str
    seed: int
    direct_dof: np.ndarray = None
    albedo_dof: np.ndarray = None
    info: dict = field(default_factory=dict)
    reflected_w_m2: np.ndarray = None
    reflected_se_w_m2: np.ndarray = None
    reflected_samples: np.ndarray = None
    reflected_dof: np.ndarray = None

    @property
    def total_w_m2(self):
        """Return direct + albedo + reflected (N, K), W/m^2."""
        tot = self.direct_w_m2 + self.albedo_w_m2
        return tot if self.reflected_w_m2 is None else tot + self.reflected_w_m2

    @property
    def rays(self):
        extra = 0 if self.reflected_samples is None else int(self.reflected_samples.sum())
        return int(self.direct_samples.sum() + self.albedo_samples.sum()) + extra
