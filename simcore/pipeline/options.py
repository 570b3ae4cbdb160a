"""The options of a run: :class:`RunOptions`, everything that decides its numbers (and where it goes), and
their settings digest (:meth:`RunOptions.spec`), which a finished file or a partial run is recognised by."""
import dataclasses
import hashlib
import os
from dataclasses import dataclass

from simcore._version import __version__
from simcore.constants import TSI_W_M2
from simcore.environment import attitude as _attitude
from simcore.environment.clouds import DEFAULT_SCALE_KM as CLOUD_SCALE_KM
from simcore.pipeline import schedule as _schedule
from simcore.pipeline.preflight import REFLECTED_SAMPLES


@dataclass
class RunOptions:
    """Everything that decides a run's numbers (and where it goes)."""

    config: str = "tilt20_fov70"
    tle: str = None
    satellite: str = None
    orbit_file: str = None            # CCSDS OEM (KVN or XML) instead of a TLE (simcore.environment.ephemeris)
    start: str = None                  # None: the attitude history's first sample, the ephemeris's first epoch,
                                       # else DEFAULT_START (schedule.py)
    duration_s: float = None          # None: the rest of the attitude history (or ephemeris), else one orbital period
    step_s: float = 1.0
    spin_rate_deg_s: float = _attitude.DEFAULT_TUMBLE_RATE_DEG_S
    spin_axis: tuple = (1.0, 1.0, 1.0)
    attitude_file: str = None          # attitude history file (environment.telemetry.read_attitude_history)
    attitude_frame: str = None         # its frame / direction where the file does not declare them
    attitude_direction: str = None
    attitude_history: object = None    # in-process AttitudeHistory (instead of attitude_file)
    times_file: str = None             # explicit epochs: one ISO-8601 UTC time per line (schedule.read_times)
    epochs: object = None              # explicit epochs in-process (an Epochs)
    dynamics: str = None               # inertia 'IXX,IYY,IZZ[,IXY,IXZ,IYZ]' kg m^2: torque-free Euler dynamics
    rel_se_direct: float = 0.002       # target relative standard errors (None: fixed sample counts)
    rel_se_albedo: float = 0.01
    direct_samples: int = 1024
    albedo_samples: int = 256
    reflected_samples: int = REFLECTED_SAMPLES    # paths per diode-epoch for the reflected component (4 m^2)
    dead: tuple = ()
    extra_flat_diodes: bool = False    # the two optional flat diodes on top and bottom (diodes 14, 15)
    variant: str = None
    seed: int = 0
    reflectivity: str = "toms2005"
    clouds: int = None                 # cloud-weather seed (simcore.environment.clouds); None: the map as it is
    cloud_scale_km: float = None       # the clouds' correlation length (None: clouds.DEFAULT_SCALE_KM)
    eop: tuple = None                  # Earth orientation (UT1 - UTC s, x_p arcsec, y_p arcsec), IERS Bulletin A; None: 0
    glint: float = None                # sea sun glint: wind speed m/s at 12.5 m (simcore.radiometry.glint); None: none
    sun_disc: bool = True              # finite solar disc: penumbra
    e_sun_w_m2: float = TSI_W_M2        # solar irradiance at 1 AU (the thesis: E_SUN_W_M2 = 1366.1)
    distance_scaling: bool = True      # x (1 AU / r_sun)^2 (the thesis: a constant, False)
    chunk_epochs: int = 512
    output: str = None                 # None: runs/default.nc, or the next free runs/default-N.nc (execute)
    fail_on_check: bool = True        # exit status 1 when the analytic check fails
    overwrite: bool = False            # replace an existing output made with other settings
    allow_bright_map: bool = False     # accept reflectivity above preflight.MAP_REFLECTIVITY_MAX

    def spec(self):
        """Return the JSON-able settings that determine the numbers (not where they go)."""
        d = dataclasses.asdict(self)
        for k in ("output", "fail_on_check", "chunk_epochs", "overwrite", "allow_bright_map"):
            d.pop(k)
        d["dead"] = sorted(int(i) for i in d["dead"])
        if d["clouds"] is None:         # runs without clouds keep the settings digest they always had
            d.pop("clouds")
            d.pop("cloud_scale_km")
        elif d["cloud_scale_km"] is None:   # the default length named or not: one run, one digest
            d["cloud_scale_km"] = CLOUD_SCALE_KM
        if d["glint"] is None:          # runs without glint keep the settings digest they always had
            d.pop("glint")
        if d["eop"] is None:            # runs without Earth-orientation data keep the digest they always had
            d.pop("eop")
        else:
            d["eop"] = [float(x) for x in d["eop"]]
        if d["reflected_samples"] == REFLECTED_SAMPLES:     # runs at the default keep the digest they always had
            d.pop("reflected_samples")
        d["spin_axis"] = [float(x) for x in d["spin_axis"]]
        _schedule.spec_fields(self, d)
        for k in ("config", "tle", "attitude_file", "times_file", "orbit_file"):
            v = d.get(k)
            if v and os.path.isfile(v):
                with open(v, "rb") as f:
                    d[k + "_sha256"] = hashlib.sha256(f.read()).hexdigest()
        d["sunsim_version"] = __version__
        return d

