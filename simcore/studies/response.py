"""The traced angular response of each diode of a configuration (``sunsim response``).

For a Sun at angle theta from a diode's normal, swept in the diode's u-n ("x") or v-n ("y") plane from 0
to 90 deg, the renderer traces the direct irradiance on the diode through the whole satellite (its own well,
its neighbours' mounts, the body), with no Earth: the response is that irradiance over E_sun (a point
Sun at 1 AU), with its standard error. Beside it: the bare cosine, the thesis' eq. 4.15 for the diode's FOV,
the well's closed-form overlap (:meth:`simcore.shapes.aperture.WellAperture.response`, which ignores the
rest of the satellite; under a cover glass, :class:`simcore.shapes.window.WindowedWell`: the slab's Fresnel
transmittance per polarisation with its footprint, the light it refracts counted as direct) and Basilisk's response ``c (1 - exp(-c^2 / kappa))`` inside a cut-off FOV with the
Kelly factor kappa fitted to the traced curve (:func:`simcore.sensor.errors.basilisk_response`), so that a
Basilisk user can carry the traced optics over. ``map`` adds the response over the diode's whole
hemisphere (angle from the normal x azimuth from u).

``reflected`` is the sunlight reaching the diode after at least one reflection on the spacecraft, path traced
off the parts' materials (:mod:`scenes.materials`; exactly 0 where every surface is ``black``), and ``response``
is direct + reflected, its standard error the two combined.
"""
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from scenes.config import SatelliteConfig
from scenes.satellite import Satellite
from simcore.constants import EQ415_CUTOFF_COS
from simcore.errors import InvalidInputError
from simcore.radiometry.response import Eq415Response
from simcore.render import Renderer
from simcore.sensor.errors import basilisk_response
from simcore.shapes.window import WindowedWell

PLANES = ("x", "y")


@dataclass
class DiodeResponse:
    """The traced response of one diode along one plane (angles in degrees, responses unitless)."""

    index: int
    name: str
    plane: str
    theta_deg: np.ndarray
    response: np.ndarray
    response_se: np.ndarray
    direct: np.ndarray
    reflected: np.ndarray
    cosine: np.ndarray
    eq415: np.ndarray
    well: np.ndarray
    kelly_factor: float
    kelly_fov_deg: float
    kelly: np.ndarray
    kelly_rms: float
    kelly_scale: float = 1.0
    map_theta_deg: np.ndarray = None
    map_phi_deg: np.ndarray = None
    map_response: np.ndarray = None

    def as_dict(self):
        """Return the JSON form (lists of floats)."""
        out = {"index": self.index, "name": self.name, "plane": self.plane}
        for key in ("theta_deg", "response", "response_se", "direct", "reflected", "cosine", "eq415", "well",
                    "kelly"):
            out[key] = [float(x) for x in getattr(self, key)]
        out.update(kelly_factor=self.kelly_factor, kelly_scale=self.kelly_scale, kelly_fov_deg=self.kelly_fov_deg,
                   kelly_rms=self.kelly_rms)
        if self.map_response is not None:
            out["map"] = {"theta_deg": [float(x) for x in self.map_theta_deg],
                          "phi_deg": [float(x) for x in self.map_phi_deg],
                          "response": [[float(x) for x in row] for row in self.map_response]}
        return out


def _plane_directions(theta_deg, plane):
    """Return (M, 3) unit directions in the diode frame (u, v, n) at ``theta_deg`` from n toward u or v."""
    th = np.radians(theta_deg)
    d = np.zeros((len(th), 3))
    d[:, 0 if plane == "x" else 1] = np.sin(th)
    d[:, 2] = np.cos(th)
    return d


def fit_kelly(theta_deg, response, k_power=2.0):
    """Return (kappa, fov_deg, rms, scale): Basilisk's Kelly factor and its scale factor (the response at normal
    incidence, Basilisk's ``scaleFactor`` in units of E_sun: below 1 under a cover glass) fitted by least squares
    to a response curve (unitless, over ``theta_deg``), its FOV the first angle where the response reaches 0
    (90 deg if it never does), and the rms residual. kappa = 0 means the scaled cosine fits best."""
    theta_deg, response = np.asarray(theta_deg, float), np.asarray(response, float)
    dark = np.flatnonzero((response <= 0) & (theta_deg > 0))
    fov = float(theta_deg[dark[0]]) if dark.size else 90.0
    # Basilisk cuts at c >= cos(fov): put the cut just short of the first dark angle
    fov_cut = np.radians(fov) - 1e-9
    c = np.cos(np.radians(theta_deg))

    def fit(kappa):
        """Return (mean square residual, scale) with the scale that is best for this kappa (linear in it)."""
        b = basilisk_response(c, fov_cut, kappa, k_power)
        bb = float(np.dot(b, b))
        scale = float(np.dot(b, response) / bb) if bb > 0 else 1.0
        return float(np.mean((scale * b - response) ** 2)), scale

    res = minimize_scalar(lambda log_k: fit(np.exp(log_k))[0], bounds=(np.log(1e-6), np.log(10.0)),
                          method="bounded", options={"xatol": 1e-6})
    k = float(np.exp(res.x))
    (best, scale), (pure, pure_scale) = fit(k), fit(0.0)
    if pure <= best:
        return 0.0, fov, float(np.sqrt(pure)), pure_scale
    return k, fov, float(np.sqrt(best)), scale


def check_request(cfg, diodes, plane, step_deg, samples, map_step_deg):
    """Return the diode indices of a response request, or raise a one-line InvalidInputError."""
    if plane not in PLANES:
        raise InvalidInputError(f"--plane must be x (the diode's u-n plane) or y (its v-n plane), got {plane!r}")
    if not (np.isfinite(step_deg) and 0 < step_deg <= 45):
        raise InvalidInputError(f"--step must lie in (0, 45] deg, got {step_deg}")
    if map_step_deg is not None and not (np.isfinite(map_step_deg) and 0.5 <= map_step_deg <= 30):
        raise InvalidInputError(f"--map-step must lie in [0.5, 30] deg, got {map_step_deg}")
    m = int(round(np.sqrt(samples / 4))) if isinstance(samples, (int, np.integer)) and samples > 0 else 0
    if m < 2 or 4 * m * m != samples:
        raise InvalidInputError(f"--samples must be 4 m^2 for an integer m >= 2 (2 points in each of 2 m^2 strata of "
                                f"the diode), e.g. 1024 or 4096; got {samples}")
    k = cfg.n_diodes
    idx = list(range(k)) if not diodes else [int(i) for i in diodes]
    bad = [i for i in idx if not 0 <= i < k]
    if bad:
        raise InvalidInputError(f"--diode {bad[0]} does not exist: {cfg.name} has diodes 0..{k - 1}")
    return idx


def traced_response(config, diodes=None, plane="x", step_deg=5.0, samples=4096, seed=0, variant=None,
                    map_step_deg=None, reflected_samples=1024):
    """Return [DiodeResponse] of the diodes ``diodes`` (indices; None: all) of a configuration (a name, a
    path or a ``SatelliteConfig``): the traced response every ``step_deg`` from 0 to 90 deg in ``plane``
    ('x' or 'y' of each diode's frame), ``samples`` direct-Sun samples per diode and angle; with
    ``map_step_deg``, also the response over the diode's hemisphere on that grid; ``reflected_samples``
    (4 m^2) paths per diode and angle for the light the spacecraft reflects (when some part is not black)."""
    cfg = config if isinstance(config, SatelliteConfig) else SatelliteConfig.load(config)
    idx = check_request(cfg, diodes, plane, float(step_deg), samples, map_step_deg)
    sat = Satellite(cfg)
    theta = np.arange(0.0, 90.0 + 1e-9, float(step_deg))
    d_local = _plane_directions(theta, plane)
    out = []
    for k in idx:
        # one diode at a time receives light (its own Sun sweep); every part of the satellite still blocks it
        j = 0
        rend = Renderer.from_scene(sat, diodes=[k], e_sun_w_m2=1.0, variant=variant)
        ds = rend.diodes
        frame = ds.frames[j]
        res = rend.render(d_local @ frame, seed=seed, direct_samples=int(samples), albedo=False,
                          reflected_samples=reflected_samples)
        direct, reflected = res.direct_w_m2[:, j], res.reflected_w_m2[:, j]
        se = np.hypot(res.direct_se_w_m2[:, j], res.reflected_se_w_m2[:, j])
        total = direct + reflected
        ap = ds.apertures[j]
        fov = float(cfg.fov_deg[k])
        kappa, kfov, rms, kscale = fit_kelly(theta, total)
        r = DiodeResponse(
            index=k, name=cfg.diodes[k].name, plane=plane, theta_deg=theta, response=total, response_se=se,
            direct=direct, reflected=reflected, cosine=np.cos(np.radians(theta)),
            eq415=(Eq415Response(fov).response(d_local) if np.cos(np.radians(fov)) > EQ415_CUTOFF_COS
                   else np.clip(d_local[:, 2], 0.0, None)),      # eq. 4.15 needs a FOV below its cut-off
            well=_closed_form(ap, cfg.diodes[k].window).response(d_local), kelly_factor=kappa, kelly_fov_deg=kfov,
            kelly=kscale * basilisk_response(np.cos(np.radians(theta)), np.radians(kfov) - 1e-9, kappa), kelly_rms=rms,
            kelly_scale=kscale)
        if map_step_deg is not None:
            mt = np.arange(0.5 * map_step_deg, 90.0, map_step_deg)
            mp = np.arange(-180.0 + 0.5 * map_step_deg, 180.0, map_step_deg)
            TH, PH = np.meshgrid(np.radians(mt), np.radians(mp), indexing="ij")
            dm = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1).reshape(-1, 3)
            m_map = max(2, int(round(np.sqrt(samples / 4))) // 2)          # a quarter of the samples
            mres = rend.render(dm @ frame, seed=seed + 1, direct_samples=4 * m_map * m_map, albedo=False,
                               reflected_samples=reflected_samples)
            r.map_theta_deg, r.map_phi_deg = mt, mp
            r.map_response = (mres.direct_w_m2[:, j] + mres.reflected_w_m2[:, j]).reshape(TH.shape)
        out.append(r)
    return out


def _closed_form(well, window):
    """Return the closed-form response of a diode's well, under its window when it has one."""
    return well if window is None else WindowedWell(well, window)


def format_table(responses):
    """Return the text table of :func:`traced_response`'s results."""
    lines = []
    for r in responses:
        lines.append(f"diode {r.index} ({r.name}), Sun swept in its {r.plane}-n plane; Kelly factor {r.kelly_factor:.4g}, "
                     f"scale {r.kelly_scale:.4g}, inside {r.kelly_fov_deg:g} deg (rms {r.kelly_rms:.2g})")
        lines.append("  theta   response  +-se        cosine   eq.4.15  well     Kelly")
        for i, th in enumerate(r.theta_deg):
            lines.append(f"  {th:5.1f}   {r.response[i]:.5f}  {r.response_se[i]:.1e}   {r.cosine[i]:.5f}  "
                         f"{r.eq415[i]:.5f}  {r.well[i]:.5f}  {r.kelly[i]:.5f}")
    return "\n".join(lines)
