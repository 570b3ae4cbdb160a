"""The studies' named choices: the thesis configurations, the spans of the day and the gyros.

Kept apart from the studies themselves (which import the run machinery, xarray, matplotlib and the
renderer's scenes) so that the command line can offer them as choices without importing any of that:
``sunsim --help`` builds every subcommand's parser.
"""
CONFIGS = ("tilt0_fov90", "tilt20_fov70", "tilt20_fov75", "tilt25_fov70", "tilt25_fov75", "tilt30_fov70",
           "tilt30_fov75")
SPANS = {"day": ("2016-07-02T00:00:00Z", 86400.0), "orbits": ("2016-07-02T05:00:00Z", 10000.0),
         "short": ("2016-07-02T00:45:00Z", 600.0)}   # "short": a demonstration that runs in a minute
GYROS = ("MPU-3300", "IMU160", "BMG160", "L3G4200D")   # the thesis' recommendation and the flown part
