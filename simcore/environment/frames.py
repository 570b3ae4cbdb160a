"""Rotation matrices between TEME (SGP4), GCRS (the inertial "ECI") and ITRS (ECEF).

Every matrix is ``R_<to>_from_<from>`` with shape (N, 3, 3), ``v_to = R @ v_from``.
All Earth-orientation quantities come from pyerfa (the IAU SOFA routines,
IAU 2006 precession / IAU 2000A nutation); nothing here is a hand-written
series.

The chain
---------
``R3(a)`` below is the frame rotation about z, ``[[c, s, 0], [-s, c, 0], [0, 0, 1]]``.

* ITRS <- TEME, Vallado et al. 2006 ("Revisiting Spacetrack Report #3",
  AIAA 2006-6753, sec. on coordinate frames and appendix C):
  ``r_pef = R3(GMST82(UT1)) r_teme`` (erfa.gmst82, the IAU 1982 sidereal time
  SGP4 and the TLE fits are built on; no equation-of-equinoxes "kinematic"
  terms), then polar motion ``r_itrs = W r_pef`` with ``W = erfa.pom00(xp, yp, s')``.
  Velocities carry the Earth-rotation term (Vallado):
  ``v_itrs = W (R3(GMST82) v_teme - omega x r_pef)``, omega = 7.292115146706979e-5
  rad/s (IERS 2010 nominal; the length-of-day excess is ignored, < 2e-5 m/s).
* ITRS <- GCRS, IAU 2006/2000A, equinox based (equivalent to SOFA's
  ``c2t06a`` to well below a micrometre at 7000 km):
  ``R = W R3(GMST06(UT1, TT)) S(TT)`` with ``S = R3(EE06A) NPB06A`` the
  bias-precession-nutation matrix followed by the equation of the equinoxes.
* GCRS <- TEME. Our TEME definition: TEME is the frame that ``R3(GMST82)``
  turns into the pseudo-Earth-fixed frame, exactly as in the ITRS <- TEME
  step above (the definition Vallado 2006 uses to relate SGP4 output to the
  Earth and the one astropy adopts). Its z axis is the true (CIP) pole of
  date and its x axis lies in the true equator at the "mean equinox" of the
  1982 sidereal time. Going through the true-of-date (TOD) frame:
  ``r_tod = R3(-(GAST06 - GMST82)) r_teme`` and ``r_gcrs = NPB06A^T r_tod``, i.e.
  ``R_gcrs_from_teme = S^T R3(GMST82 - GMST06)``. The angle
  ``GAST06 - GMST82 = EE06A + (GMST06 - GMST82)`` is the equation of the
  equinoxes plus the 1982-to-2006 sidereal-time difference (-13 mas in
  2000, +31 mas in 2016, growing ~3 mas/yr from the IAU 2000 precession-rate
  correction). Using the bare "true equator, mean equinox" reading
  (``R3(-EE06A)`` only) would instead differ by that 31 mas = 1.05 m at
  7000 km in 2016. We chose the GMST82-tied definition because the TLE fits
  relate TEME to Earth-fixed sensors through GMST82, and because it makes the
  three frames consistent: ``R_itrs_from_gcrs @ R_gcrs_from_teme ==
  R_itrs_from_teme`` (to interpolation error), so the satellite's ECEF
  position and the Sun's ECEF position (computed via GCRS) agree.
  GCRS velocities are ``R_gcrs_from_teme @ v_teme``: the precession-nutation
  rate (~1e-11 rad/s) would add < 1e-4 m/s.

* EME2000 (J2000, mean equator and equinox of J2000.0) <- GCRS: the IAU 2006 frame bias, ``erfa.bp06``'s
  RB (23 mas); TOD (true equator and equinox of date) <- GCRS: ``erfa.pnm06a`` (bias-precession-nutation).
  Recorded attitudes may refer to either (:mod:`simcore.environment.history`).

Speed: the slowly varying part ``S(TT)`` (precession-nutation, bias and
equation of the equinoxes, ~1400 nutation terms per evaluation) is computed
with erfa on a coarse grid (``PN_GRID_STEP_S`` = 1 h) and interpolated with a
4-point (cubic) Lagrange interpolant per matrix element, then
re-orthonormalised. The largest short-period nutation term (13.66 d, 0.23")
leaves an interpolation error of ~1e-14 rad (far below 1 micrometre at
7000 km; tests/environment/test_frames.py bounds it against per-epoch erfa). The fast
parts, GMST82, GMST06 (= ERA + polynomial) and polar motion, are computed
exactly per epoch. If the grid would have as many nodes as epochs (sparse
epochs over a long span), everything is computed per epoch instead.

Earth-orientation defaults and the error they leave
---------------------------------------------------
``dut1_s`` (UT1 - UTC, s), ``xp_rad``, ``yp_rad`` (pole coordinates, rad) default to
0 because sunsim ships no IERS tables. Take them from IERS Bulletin A/B when
metre-level ITRS positions matter:

* |UT1 - UTC| <= 0.9 s: the Earth turns 465 m/s at the equator, so dUT1 = 0
  misplaces ITRS positions by up to ~420 m (0.9 s x 465 m/s) along the
  rotation direction at the equator (~0.9 s x 15"/s = 13.5" of Earth angle).
* polar motion |x_p|, |y_p| <~ 0.3" (1.5 urad): up to ~10 m at the surface,
  ~10 m at 7000 km.
* GCRS is independent of both (the TEME -> GCRS chain uses UT1 only through
  the ~mas GMST82-GMST06 difference).
For a coarse sun sensor (degree-level errors) these are irrelevant, but they
are documented so nobody mistakes the ITRS output for metre-grade.
"""
import erfa
import numpy as np

from simcore.constants import OMEGA_EARTH_RAD_S
from simcore.environment.epochs import Epochs

PN_GRID_STEP_S = 3600.0      # coarse grid for the precession-nutation part
_SECONDS_PER_DAY = 86400.0

FRAMES = ("teme", "gcrs", "itrs", "eme2000", "tod")
_ALIASES = {"teme": "teme", "gcrs": "gcrs", "gcrf": "gcrs", "itrs": "itrs", "ecef": "itrs",
            "eme2000": "eme2000", "j2000": "eme2000", "tod": "tod"}


# ---------------------------------------------------------------------------
# helpers
def _epochs(epochs):
    return Epochs.from_any(epochs)


def _R3(angle):
    """Return (N, 3, 3) frame rotations about z by ``angle`` (rad)."""
    angle = np.atleast_1d(np.asarray(angle, dtype=float))
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (3, 3))
    R[..., 0, 0] = c
    R[..., 0, 1] = s
    R[..., 1, 0] = -s
    R[..., 1, 1] = c
    R[..., 2, 2] = 1.0
    return R


def _T(R):
    return np.swapaxes(R, -1, -2)


def _eop(n, dut1_s, xp_rad, yp_rad):
    """Broadcast Earth-orientation parameters to (N,), with a clear error."""
    out = []
    for name, val in (("dut1_s", dut1_s), ("xp_rad", xp_rad), ("yp_rad", yp_rad)):
        arr = np.asarray(val, dtype=float)
        try:
            arr = np.broadcast_to(arr, (n,))
        except ValueError:
            raise ValueError(f"{name} must be a scalar or have one value per epoch ({n}); "
                             f"got shape {arr.shape}") from None
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got {val!r}")
        out.append(arr)
    if np.any(np.abs(out[0]) > 1.0):
        raise ValueError(f"dut1_s is UT1 - UTC in seconds and stays within +-0.9 s by definition; got {dut1_s!r}")
    if np.any(np.abs(out[1]) > 1e-4) or np.any(np.abs(out[2]) > 1e-4):
        raise ValueError("xp_rad / yp_rad are polar-motion angles in RADIANS (about 1e-6 rad = 0.2 arcsec); "
                         f"got xp_rad={xp_rad!r}, yp_rad={yp_rad!r} - convert arcsec with * 4.8481368e-6")
    return out


def _S_exact(tt1, tt2):
    """Return (N, 3, 3) S = R3(EE06A) NPB06A (GCRS -> IAU 2006 'true equator, mean equinox')."""
    with np.errstate(all="ignore"):
        npb = erfa.pnm06a(tt1, tt2)
        ee = erfa.ee06a(tt1, tt2)
    return _R3(ee) @ npb


def _orthonormalise(R):
    """Return the nearest rotations to the almost-orthonormal (N, 3, 3) ``R`` (two Newton steps)."""
    for _ in range(2):
        R = 1.5 * R - 0.5 * R @ _T(R) @ R
    return R


def _interp_cubic(x_grid, y_grid, x):
    """Return 4-point Lagrange (cubic) interpolation of y_grid (M, ...) at x (N,).

    ``x_grid`` is uniform; every ``x`` must lie within [x_grid[1], x_grid[-2]].
    """
    h = x_grid[1] - x_grid[0]
    u = (x - x_grid[0]) / h
    i = np.clip(np.floor(u).astype(np.int64), 1, len(x_grid) - 3)
    p = u - i                                  # in [0, 1)
    w_m1 = -p * (p - 1.0) * (p - 2.0) / 6.0
    w_0 = (p + 1.0) * (p - 1.0) * (p - 2.0) / 2.0
    w_1 = -(p + 1.0) * p * (p - 2.0) / 2.0
    w_2 = (p + 1.0) * p * (p - 1.0) / 6.0
    shape = (-1,) + (1,) * (y_grid.ndim - 1)
    return (w_m1.reshape(shape) * y_grid[i - 1] + w_0.reshape(shape) * y_grid[i]
            + w_1.reshape(shape) * y_grid[i + 1] + w_2.reshape(shape) * y_grid[i + 2])


def smooth_on_grid(func, tt1, tt2, step_s):
    """Return ``func(tt1, tt2)`` (N, ...) evaluated on a coarse TT grid and interpolated (cubic).

    ``func`` takes two-part TT Julian dates (M,) and returns an array (M, ...).
    Falls back to evaluating at every epoch when that is cheaper.
    """
    tt1 = np.asarray(tt1, dtype=float)
    tt2 = np.asarray(tt2, dtype=float)
    n = tt1.shape[0]
    ref1 = tt1[0]
    x = ((tt1 - ref1) + tt2) * _SECONDS_PER_DAY      # seconds from a day boundary, exact to ~1e-10 s
    lo, hi = float(x.min()), float(x.max())
    h = float(step_s)
    n_grid = int(np.ceil((hi - lo) / h)) + 4
    if n_grid >= n:
        return func(tt1, tt2)
    x_grid = lo - h + h * np.arange(n_grid)
    y_grid = func(np.full(n_grid, ref1), x_grid / _SECONDS_PER_DAY)
    return _interp_cubic(x_grid, y_grid, x)


def _S(epochs, exact=False):
    tt1, tt2 = epochs.tt()
    if exact:
        return _S_exact(tt1, tt2)
    return _orthonormalise(smooth_on_grid(_S_exact, tt1, tt2, PN_GRID_STEP_S))


def _sidereal(epochs, dut1_s):
    """Return (GMST82, GMST06) in rad, (N,) each, and TT (two-part)."""
    ut1 = epochs.ut1(dut1_s)
    tt = epochs.tt()
    with np.errstate(all="ignore"):
        return erfa.gmst82(*ut1), erfa.gmst06(ut1[0], ut1[1], tt[0], tt[1]), tt


def _W(tt, xp, yp):
    """Return (N, 3, 3) polar-motion matrices ITRS <- PEF/TIRS (erfa.pom00, s' = erfa.sp00)."""
    return erfa.pom00(xp, yp, erfa.sp00(*tt))


# ---------------------------------------------------------------------------
# matrices
def R_itrs_from_teme(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return (N, 3, 3) rotations TEME -> ITRS (ECEF): ``W R3(GMST82(UT1))`` (Vallado et al. 2006).

    ``dut1_s`` = UT1 - UTC (s), ``xp_rad``/``yp_rad`` polar motion (rad); see the
    module docstring for the error the zero defaults leave. Velocities need
    :func:`rv_itrs_from_teme` (Earth-rotation term).
    """
    epochs = _epochs(epochs)
    dut1, xp, yp = _eop(len(epochs), dut1_s, xp_rad, yp_rad)
    gmst82, _, tt = _sidereal(epochs, dut1)
    return _W(tt, xp, yp) @ _R3(gmst82)


def R_itrs_from_gcrs(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, *, exact=False):
    """Return (N, 3, 3) rotations GCRS -> ITRS (ECEF), IAU 2006/2000A: ``W R3(GMST06) R3(EE06A) NPB06A``.

    The precession-nutation part is interpolated from a 1-h grid unless
    ``exact=True`` (per-epoch erfa, ~50 us per epoch).
    """
    epochs = _epochs(epochs)
    dut1, xp, yp = _eop(len(epochs), dut1_s, xp_rad, yp_rad)
    _, gmst06, tt = _sidereal(epochs, dut1)
    return _W(tt, xp, yp) @ _R3(gmst06) @ _S(epochs, exact)


def R_gcrs_from_teme(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, *, exact=False):
    """Return (N, 3, 3) rotations TEME -> GCRS: ``NPB06A^T R3(-(GAST06 - GMST82))`` (see module docstring).

    Polar motion cancels out of this product (it is accepted, checked and
    unused, so all matrix functions share one signature); ``dut1_s`` changes
    the result only through the tiny GMST82 - GMST06 rate difference
    (< 1e-12 rad per second of dUT1).
    """
    epochs = _epochs(epochs)
    dut1, _, _ = _eop(len(epochs), dut1_s, xp_rad, yp_rad)
    gmst82, gmst06, _ = _sidereal(epochs, dut1)
    return _T(_S(epochs, exact)) @ _R3(gmst82 - gmst06)


def R_teme_from_gcrs(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, *, exact=False):
    """Return (N, 3, 3) rotations GCRS -> TEME (transpose of :func:`R_gcrs_from_teme`)."""
    return _T(R_gcrs_from_teme(epochs, dut1_s, xp_rad, yp_rad, exact=exact))


def R_teme_from_itrs(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return (N, 3, 3) rotations ITRS -> TEME (transpose of :func:`R_itrs_from_teme`)."""
    return _T(R_itrs_from_teme(epochs, dut1_s, xp_rad, yp_rad))


def R_gcrs_from_itrs(epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0, *, exact=False):
    """Return (N, 3, 3) rotations ITRS -> GCRS (transpose of :func:`R_itrs_from_gcrs`)."""
    return _T(R_itrs_from_gcrs(epochs, dut1_s, xp_rad, yp_rad, exact=exact))


def R_eme2000_from_gcrs(epochs):
    """Return (N, 3, 3) the frame bias GCRS -> EME2000 (mean equator and equinox of J2000.0), ``erfa.bp06``'s RB.

    The IAU 2006 frame bias: a constant rotation of ~23 mas (0.1 urad, 0.7 m at 7000 km) about axes near the
    x and y axes plus the 14.6 mas equinox offset (SOFA ``iauBp06``, note 5: "RB transforms vectors from GCRS
    to mean J2000.0 by applying frame bias"). The same for every epoch; shaped (N, 3, 3) like the others.
    """
    epochs = _epochs(epochs)
    rb, _, _ = erfa.bp06(2451545.0, 0.0)
    return np.broadcast_to(rb, (len(epochs), 3, 3)).copy()


def R_tod_from_gcrs(epochs, *, exact=False):
    """Return (N, 3, 3) rotations GCRS -> TOD (true equator and true equinox of date): ``erfa.pnm06a``.

    The classical bias-precession-nutation matrix, IAU 2006/2000A (SOFA ``iauPnm06a``): v_tod = NPB v_gcrs.
    Interpolated from the 1-h grid of the module docstring unless ``exact=True``.
    """
    epochs = _epochs(epochs)
    tt1, tt2 = epochs.tt()

    def npb(a, b):
        with np.errstate(all="ignore"):
            return erfa.pnm06a(a, b)
    if exact:
        return npb(tt1, tt2)
    return _orthonormalise(smooth_on_grid(npb, tt1, tt2, PN_GRID_STEP_S))


def R_gcrs_from(frame, epochs):
    """Return (N, 3, 3) rotations from the inertial ``frame`` ('gcrs', 'eme2000'/'j2000', 'teme', 'tod') to GCRS."""
    key = _frame_name(frame)
    epochs = _epochs(epochs)
    if key == "gcrs":
        return np.broadcast_to(np.eye(3), (len(epochs), 3, 3)).copy()
    if key == "eme2000":
        return _T(R_eme2000_from_gcrs(epochs))
    if key == "tod":
        return _T(R_tod_from_gcrs(epochs))
    if key == "teme":
        return R_gcrs_from_teme(epochs)
    raise ValueError(f"{frame!r} is not an inertial frame; give 'gcrs', 'eme2000', 'teme' or 'tod'")


# ---------------------------------------------------------------------------
# position + velocity
def _as_n3(name, a, n):
    a = np.asarray(a, dtype=float)
    if a.shape == (3,):
        a = np.broadcast_to(a, (n, 3))
    if a.shape != (n, 3):
        raise ValueError(f"{name} must have shape (N, 3) = ({n}, 3) with one row per epoch; got {a.shape}")
    return a


def _omega_cross(r):
    """Return omega x r for omega = (0, 0, OMEGA_EARTH) and r (N, 3)."""
    out = np.empty_like(r)
    out[:, 0] = -OMEGA_EARTH_RAD_S * r[:, 1]
    out[:, 1] = OMEGA_EARTH_RAD_S * r[:, 0]
    out[:, 2] = 0.0
    return out


def rv_itrs_from_teme(r_teme_m, v_teme_m_s, epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return (r_itrs_m, v_itrs_m_s), each (N, 3): TEME state -> ITRS state (Vallado 2006).

    ``v_itrs = W (R3(GMST82) v_teme - omega x r_pef)``.
    """
    epochs = _epochs(epochs)
    n = len(epochs)
    r = _as_n3("r_teme_m", r_teme_m, n)
    v = _as_n3("v_teme_m_s", v_teme_m_s, n)
    dut1, xp, yp = _eop(n, dut1_s, xp_rad, yp_rad)
    gmst82, _, tt = _sidereal(epochs, dut1)
    return _rv_itrs_from_teme(r, v, _R3(gmst82), _W(tt, xp, yp))


def _rv_itrs_from_teme(r, v, R3g, W):
    r_pef = np.einsum("nij,nj->ni", R3g, r)
    v_pef = np.einsum("nij,nj->ni", R3g, v) - _omega_cross(r_pef)
    return np.einsum("nij,nj->ni", W, r_pef), np.einsum("nij,nj->ni", W, v_pef)


def rv_teme_from_itrs(r_itrs_m, v_itrs_m_s, epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return (r_teme_m, v_teme_m_s), each (N, 3): ITRS state -> TEME state, the inverse of
    :func:`rv_itrs_from_teme` (``r_pef = W^T r_itrs``, ``v_teme = R3(-GMST82) (W^T v_itrs + omega x r_pef)``)."""
    epochs = _epochs(epochs)
    n = len(epochs)
    r = _as_n3("r_itrs_m", r_itrs_m, n)
    v = _as_n3("v_itrs_m_s", v_itrs_m_s, n)
    dut1, xp, yp = _eop(n, dut1_s, xp_rad, yp_rad)
    gmst82, _, tt = _sidereal(epochs, dut1)
    Wt, R3t = _T(_W(tt, xp, yp)), _T(_R3(gmst82))
    r_pef = np.einsum("nij,nj->ni", Wt, r)
    v_pef = np.einsum("nij,nj->ni", Wt, v) + _omega_cross(r_pef)
    return np.einsum("nij,nj->ni", R3t, r_pef), np.einsum("nij,nj->ni", R3t, v_pef)


def teme_to_all(r_teme_m, v_teme_m_s, epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return (r_gcrs_m, v_gcrs_m_s, r_itrs_m, v_itrs_m_s), each (N, 3), from a TEME state.

    One pass that shares the sidereal times between the two targets (used by
    :meth:`simcore.environment.orbit.Orbit.propagate`).
    """
    epochs = _epochs(epochs)
    n = len(epochs)
    r = _as_n3("r_teme_m", r_teme_m, n)
    v = _as_n3("v_teme_m_s", v_teme_m_s, n)
    dut1, xp, yp = _eop(n, dut1_s, xp_rad, yp_rad)
    gmst82, gmst06, tt = _sidereal(epochs, dut1)
    R3g = _R3(gmst82)
    r_itrs, v_itrs = _rv_itrs_from_teme(r, v, R3g, _W(tt, xp, yp))
    R_gt = _T(_S(epochs)) @ _R3(gmst82 - gmst06)
    r_gcrs = np.einsum("nij,nj->ni", R_gt, r)
    v_gcrs = np.einsum("nij,nj->ni", R_gt, v)
    return r_gcrs, v_gcrs, r_itrs, v_itrs


# ---------------------------------------------------------------------------
# generic
def _frame_name(name):
    key = str(name).strip().lower()
    if key not in _ALIASES:
        raise ValueError(f"unknown frame {name!r}; valid frames are 'teme', 'gcrs', 'itrs' "
                         "(alias 'ecef'), 'eme2000' (alias 'j2000'), 'tod'; 'gcrf' means 'gcrs'")
    return _ALIASES[key]


def R_between(from_frame, to_frame, epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return (N, 3, 3) rotations ``from_frame`` -> ``to_frame`` ('teme', 'gcrs', 'itrs'/'ecef', 'eme2000'/'j2000',
    'tod'); pairs with EME2000 or TOD go through GCRS."""
    a, b = _frame_name(from_frame), _frame_name(to_frame)
    epochs = _epochs(epochs)
    eop = dict(dut1_s=dut1_s, xp_rad=xp_rad, yp_rad=yp_rad)
    if a == b:
        _eop(len(epochs), dut1_s, xp_rad, yp_rad)
        return np.broadcast_to(np.eye(3), (len(epochs), 3, 3)).copy()
    table = {
        ("teme", "itrs"): lambda: R_itrs_from_teme(epochs, **eop),
        ("itrs", "teme"): lambda: R_teme_from_itrs(epochs, **eop),
        ("teme", "gcrs"): lambda: R_gcrs_from_teme(epochs, **eop),
        ("gcrs", "teme"): lambda: R_teme_from_gcrs(epochs, **eop),
        ("gcrs", "itrs"): lambda: R_itrs_from_gcrs(epochs, **eop),
        ("itrs", "gcrs"): lambda: R_gcrs_from_itrs(epochs, **eop),
    }
    if (a, b) in table:
        return table[(a, b)]()
    _eop(len(epochs), dut1_s, xp_rad, yp_rad)
    to_gcrs = R_gcrs_from(a, epochs) if a != "itrs" else R_gcrs_from_itrs(epochs, **eop)
    from_gcrs = _T(R_gcrs_from(b, epochs)) if b != "itrs" else R_itrs_from_gcrs(epochs, **eop)
    return from_gcrs @ to_gcrs


def rotate(vectors, from_frame, to_frame, epochs, dut1_s=0.0, xp_rad=0.0, yp_rad=0.0):
    """Return ``vectors`` (N, 3) (or (3,) broadcast to every epoch) rotated from ``from_frame`` to ``to_frame``.

    Frames: 'teme', 'gcrs', 'itrs' (alias 'ecef'), 'eme2000' (alias 'j2000'), 'tod'. This is a pure rotation
    (positions, directions); a velocity into or out of ITRS also needs the
    Earth-rotation term: use :func:`rv_itrs_from_teme`.
    """
    R = R_between(from_frame, to_frame, epochs, dut1_s, xp_rad, yp_rad)
    v = _as_n3("vectors", vectors, R.shape[0])
    return np.einsum("nij,nj->ni", R, v)
