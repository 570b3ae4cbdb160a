"""The renderer's output: the rendered irradiance per epoch and diode (:class:`RenderResult`); its input, the
diodes' surfaces, is :class:`scenes.satellite.DiodeSurfaces`."""
from dataclasses import dataclass, field

import numpy as np


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
