"""The Basilisk export against Basilisk itself: coarseSunSensor and the albedo module (bsk on PyPI) driven on the same
states as sunsim, for bare cosine diodes (direct Sun + albedo on a uniform Earth of albedo 0.3).

Slow tier: Basilisk is not a sunsim dependency (``bsk`` pins sgp4 == 2.25 and matplotlib <= 3.10.9, which would
hold sunsim's own versions back). Run it in an environment that has Basilisk and sunsim's dependencies, e.g.
(docs/ccsds.md)::

    python3 -m venv /tmp/bskenv && /tmp/bskenv/bin/pip install bsk
    PYTHONPATH=$PWD:/path/to/sunsim/venv/lib/python3.11/site-packages \\
        /tmp/bskenv/bin/python -m pytest -m slow tests/pipeline/test_export_basilisk.py -q -s
"""
import numpy as np
import pytest
import xarray as xr

from simcore.constants import AU_M
from simcore.environment.maps import uniform_map
from simcore.pipeline.export import basilisk_values
from simcore.pipeline.options import RunOptions
from simcore.pipeline.schedule import study_geometry
from simcore.radiometry.albedo import albedo_cells

E_1AU = 1361.0                    # sunsim's physical flux and Basilisk's SOLAR_FLUX_EARTH
ALBEDO = 0.3
NORMALS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [0.6, 0, -0.8]], float)
# Basilisk's Earth (astroConstants.h): REQ_EARTH = 6378.1366 km, RP_EARTH = 6356.7519 km
REQ_M, RP_M = 6378136.6, 6356751.9


def _sunsim_side(g, refl):
    """sunsim's bare cosine diodes: direct = E_1AU (1 AU / r)^2 x illumination x max(0, n . s); albedo = the
    Bhanderi cell sum (simcore.radiometry.albedo) seen through each diode's cosine."""
    scale = g.sun_distance_scale
    direct = E_1AU * scale[:, None] * g.illumination[:, None] * np.maximum(g.sun_dir_body @ NORMALS.T, 0.0)
    albedo = np.zeros_like(direct)
    cell_pos = refl.radius_m * refl.normals_ecef.reshape(-1, 3)
    for i in range(len(g.epochs)):
        cells = albedo_cells(g.r_sat_ecef_m[i], g.r_sun_ecef_m[i], refl, e_sun_w_m2=E_1AU,
                             distance_scaling=True).ravel()
        u = cell_pos - g.r_sat_ecef_m[i]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        n_ecef = NORMALS @ g.R_ecef_from_body[i].T
        albedo[i] = np.sum(cells[:, None] * np.maximum(u @ n_ecef.T, 0.0), axis=0)
    irr = np.stack([direct, albedo, np.zeros_like(direct)], axis=-1)
    ds = xr.Dataset({"irradiance": (("time", "diode", "component"), irr), "sun_scale": ("time", scale)},
                    coords={"component": ["direct", "albedo", "reflected"]}, attrs={"e_sun_w_m2": E_1AU})
    return ds, cells_used(g, refl)


def cells_used(g, refl):
    """(n_lat,) bool: the latitude rows of the map that light the satellite at some epoch."""
    rows = np.zeros(refl.shape[0], bool)
    for i in range(len(g.epochs)):
        c = albedo_cells(g.r_sat_ecef_m[i], g.r_sun_ecef_m[i], refl, e_sun_w_m2=E_1AU, distance_scaling=True)
        rows |= np.any(c > 0, axis=1)
    return rows


def _basilisk_side(g):
    from Basilisk.architecture import messaging
    from Basilisk.simulation import albedo, coarseSunSensor
    from Basilisk.utilities import RigidBodyKinematics as rbk
    sun_msg, sc_msg, ecl_msg, earth_msg = (messaging.SpicePlanetStateMsg(), messaging.SCStatesMsg(),
                                           messaging.EclipseMsg(), messaging.SpicePlanetStateMsg())
    alb = albedo.Albedo()
    alb.spacecraftStateInMsg.subscribeTo(sc_msg)
    alb.sunPositionInMsg.subscribeTo(sun_msg)
    alb.addPlanetandAlbedoAverageModel(earth_msg, ALBEDO, 180, 288)       # sunsim's uniform map: 180 x 288 cells
    sensors = []
    for n in NORMALS:
        alb.addInstrumentConfig(np.pi / 2, list(n), [0.0, 0.0, 0.0])
        css = coarseSunSensor.CoarseSunSensor()
        css.fov, css.nHat_B, css.scaleFactor, css.kellyFactor = np.pi / 2, list(n), 1.0, 0.0
        css.maxOutput, css.minOutput = 1e9, -1e9
        css.sunInMsg.subscribeTo(sun_msg)
        css.stateInMsg.subscribeTo(sc_msg)
        css.sunEclipseInMsg.subscribeTo(ecl_msg)
        sensors.append(css)
    n_t, k = len(g.epochs), len(NORMALS)
    direct, albedo_ratio = np.zeros((n_t, k)), np.zeros((n_t, k))
    for i in range(n_t):
        t = int(i * 1e9)
        sun = messaging.SpicePlanetStateMsgPayload()
        sun.PositionVector, sun.PlanetName = list(g.r_sun_gcrs_m[i]), "sun"
        earth = messaging.SpicePlanetStateMsgPayload()
        earth.PositionVector, earth.PlanetName = [0.0, 0.0, 0.0], "earth"
        earth.J20002Pfix = g.R_ecef_from_gcrs[i].tolist()            # [PN]: inertial (GCRS here) -> Earth-fixed
        sc = messaging.SCStatesMsgPayload()
        sc.r_BN_N, sc.sigma_BN = list(g.r_sat_gcrs_m[i]), list(rbk.C2MRP(g.R_body_from_gcrs[i]))     # [BN]
        ecl = messaging.EclipseMsgPayload()
        ecl.illuminationFactor = float(g.illumination[i])
        for msg, payload in ((sun_msg, sun), (earth_msg, earth), (sc_msg, sc), (ecl_msg, ecl)):
            msg.write(payload, t)
        if i == 0:
            alb.Reset(0)
            for css in sensors:
                css.Reset(0)
        alb.UpdateState(t)
        for j, css in enumerate(sensors):
            css.UpdateState(t)
            direct[i, j] = css.sensedValue
            albedo_ratio[i, j] = alb.albOutMsgs[j].read().albedoAtInstrument
    return direct, albedo_ratio


def _basilisk_area_ratio(refl):
    """(n_lat,) Basilisk's cell area over sunsim's: Basilisk's grid (planetRadiationBase.cpp, PlanetGrid::initialize)
    puts each cell's centre at its geodetic latitude but takes its area between the authalic latitudes of its
    bounds on the authalic sphere; sunsim's cells are spherical. The known difference of the two albedo models."""
    e = np.sqrt(1 - RP_M ** 2 / REQ_M ** 2)
    e2, e4, e6 = e ** 2, e ** 4, e ** 6
    r_a = np.sqrt(REQ_M ** 2 * 0.5 * (1 + (1 - e2) / (2 * e) * np.log((1 + e) / (1 - e))))
    t = (e2 / 3 + 31 * e4 / 180 + 59 * e6 / 560, 17 * e4 / 360 + 61 * e6 / 1260, 383 * e6 / 45360)
    lat = np.radians(refl.lat_deg)
    dlat = np.pi / len(lat)

    def authalic(x):
        return x - (t[0] * np.sin(2 * x) - t[1] * np.sin(4 * x) + t[2] * np.sin(6 * x))
    ratio = (r_a ** 2 * np.abs(np.sin(authalic(lat + dlat / 2)) - np.sin(authalic(lat - dlat / 2)))
             / (refl.radius_m ** 2 * np.abs(np.sin(lat + dlat / 2) - np.sin(lat - dlat / 2))))
    return ratio


@pytest.mark.slow
def test_basilisk_export_matches_coarse_sun_sensor_and_its_albedo_module():
    _, _, g = study_geometry(RunOptions(start="2016-07-02T00:40:00Z", duration_s=600, step_s=60.0))
    refl = uniform_map(ALBEDO)
    ds, rows = _sunsim_side(g, refl)
    ours = basilisk_values(ds)
    bsk_direct, bsk_albedo = _basilisk_side(g)
    d_err = np.max(np.abs(ours["direct"] - bsk_direct))
    lit = ours["albedo"] > 1e-3
    ratio = bsk_albedo[lit] / ours["albedo"][lit]
    area = _basilisk_area_ratio(refl)[rows]
    print(f"\ndirect: max |sunsim export - Basilisk coarseSunSensor| = {d_err:.3g} (cosine units) over "
          f"{bsk_direct.size} diode-epochs, largest value {bsk_direct.max():.4f}")
    print(f"albedo: Basilisk albedoAtInstrument / sunsim export over {lit.sum()} diode-epochs: "
          f"{ratio.min():.5f} .. {ratio.max():.5f} (median {np.median(ratio):.5f}); Basilisk's cell-area ratio "
          f"over the latitude rows in view: {area.min():.5f} .. {area.max():.5f}")
    assert bsk_direct.max() > 0.5 and lit.sum() > 10                 # sunlit diodes, real numbers
    assert d_err < 1e-6
    # The albedo agrees up to the two models' known difference: a weighted mean of Basilisk's per-cell area
    # ratio lies between its extremes over the cells in view. The slack 1e-4: the Sun's direction seen from a
    # cell (Basilisk) or from the Earth's centre (sunsim) differs by <= R_earth / r_sun = 4.3e-5 rad.
    assert np.all(ratio >= area.min() - 1e-4) and np.all(ratio <= area.max() + 1e-4)
