"""Physical constants used across sunsim (SI units), with their sources."""

AU_M = 149_597_870_700.0            # IAU 2012 Resolution B2
R_EARTH_MEAN_M = 6_371_010.0        # Earth mean radius of the thesis (eq. 4.6) and the albedo toolbox
R_SUN_M = 695_700_000.0             # IAU 2015 Resolution B3 nominal solar radius
E_SUN_W_M2 = 1366.1                 # solar constant used by the thesis (sec. 2.3.2)
TSI_W_M2 = 1361.0                   # total solar irradiance at 1 AU: IAU 2015 Resolution B3 nominal value, from the
                                    # measured 1360.8 +- 0.5 W/m^2 at solar minimum (Kopp & Lean 2011, GRL 38, L01706)
E_SUN_TOOLBOX_W_M2 = 1366.9         # solar constant fixed in Bhanderi's MATLAB Earth Albedo Toolbox
OMEGA_EARTH_RAD_S = 7.292115146706979e-5  # Earth rotation rate, IERS conventions (2010)
BPW34_AREA_M2 = 7.02e-6             # BPW34 sensitive area (OSRAM data sheet; thesis table 3.2.3)
EQ415_CUTOFF_COS = 0.12             # thesis eq. 4.15: arccos(0.12) = 83.1 deg, light no longer reaches the diode
