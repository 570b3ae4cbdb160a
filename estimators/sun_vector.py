"""The thesis' four Sun-vector estimators (sec. 4.3, eqs. 4.27-4.45), vectorised over time.

Every estimator is ``f(E_p, normals, *, fov_deg, e_s0, ...) -> (s_hat, valid)``:

- ``E_p`` (N, K): measured effective irradiance per diode, W/m^2 (eq. 4.25), N epochs;
  a (K,) array is one epoch. NaN marks a missing measurement (that diode is left out
  of every fit at that epoch).
- ``normals`` (K, 3): diode normals in the body frame (the rows of H).
- ``fov_deg``: the FOV limit; a diode "sees the Sun" when E_p >= E_S0 cos(FOV) (sec. 4.3.1).
- ``e_s0``: the effective normal-Sun irradiance E_S0 of the diode type (W/m^2, table 3.2.3).
- ``live`` (K,) bool, optional: diodes known to be working. The thesis' estimators know
  nothing of dead diodes (a dead one reads 0 and so takes part in the albedo fits as a
  zero measurement); the default ``None`` reproduces that. Diodes with ``live=False``
  are left out of every fit.
- returns ``s_hat`` (N, 3) unit Sun vectors in the body frame and ``valid`` (N,) bool.
  Where fewer than 3 diodes are selected, or their normals are (numerically) coplanar,
  ``valid`` is False and ``s_hat`` is NaN — never a silent zero vector.

Each least-squares solve is a masked, weighted normal-equation system
(H^T W H) x = H^T W y built for all epochs at once and solved with a batched
``np.linalg.solve`` over (N, 3, 3). The rank test uses the unweighted Gram
matrix G = sum_k n_k n_k^T of the selected normals: accepted when
det(G) > ``RANK_RTOL`` trace(G)^3. Since det = l1 l2 l3 <= l3 trace^2 for the
eigenvalues l1 >= l2 >= l3 >= 0, this guarantees l3 / l1 > ``RANK_RTOL``,
and it is far above the rounding noise of det (~1e-16 trace^3).
"""
import numpy as np

RANK_RTOL = 1e-9   # det(G) / trace(G)^3 of the selected normals' Gram matrix below this = rank < 3
ZERO_THRESHOLD_W_M2 = 1e-9   # |E_S0 cos(FOV)| below this is FOV = 90 deg (cos 90 deg rounds to 6e-17, not 0)


def _inputs(e_p, normals, fov_deg, e_s0, live):
    e = np.asarray(e_p, dtype=float)
    if e.ndim == 1:
        e = e[None, :]
    h = np.asarray(normals, dtype=float)
    if h.ndim != 2 or h.shape[1] != 3:
        raise ValueError(f"normals must be an array (K, 3) of diode normals in the body frame, got shape {h.shape}")
    if e.ndim != 2 or e.shape[1] != h.shape[0]:
        raise ValueError(f"E_p must be (N, K) W/m^2 with K = {h.shape[0]} (one column per normal), "
                         f"got shape {np.shape(e_p)}")
    if not 0 < float(fov_deg) <= 90:
        raise ValueError(f"fov_deg must lie in (0, 90] degrees, got {fov_deg}")
    if not (np.isfinite(e_s0) and e_s0 > 0):
        raise ValueError(f"e_s0 must be the diode's effective normal-Sun irradiance in W/m^2 (> 0), got {e_s0}")
    usable = np.isfinite(e)
    if live is not None:
        lv = np.asarray(live, dtype=bool)
        if lv.shape != (h.shape[0],):
            raise ValueError(f"live must be a bool array (K,) = ({h.shape[0]},), got shape {lv.shape}")
        usable = usable & lv[None, :]
    threshold = float(e_s0) * np.cos(np.radians(float(fov_deg)))
    return e, h, threshold, usable


def weighted_lsq(h, y, w):
    """Return the weighted least-squares solutions x (N, 3) of H x = y and a validity flag (N,).

    Solves (H^T W H) x = H^T W y per epoch with W = diag(w_n); ``w`` (N, K) >= 0, a zero
    weight leaves a diode out. ``h`` (K, 3), ``y`` (N, K) (NaN allowed where w = 0).
    Valid where >= 3 diodes have w > 0 and their normals span 3-D (see the module docstring);
    invalid epochs return NaN.
    """
    h, y, w = np.asarray(h, dtype=float), np.asarray(y, dtype=float), np.asarray(w, dtype=float)
    if h.ndim != 2 or h.shape[1] != 3 or y.ndim != 2 or w.shape != y.shape or y.shape[1] != h.shape[0]:
        raise ValueError(f"weighted_lsq needs h (K, 3), y (N, K) and w (N, K); got {h.shape}, {y.shape}, {w.shape}")
    sel = w > 0
    y0 = np.where(sel, y, 0.0)
    w0 = np.where(sel, w, 0.0)
    n_ep, k = w.shape
    hh = (h[:, :, None] * h[:, None, :]).reshape(k, 9)          # (K, 9) outer products n n^T
    gram = (sel.astype(float) @ hh).reshape(n_ep, 3, 3)          # unweighted, for the rank test
    m = (w0 @ hh).reshape(n_ep, 3, 3)                            # H^T W H
    b = (w0 * y0) @ h                                            # (N, 3) H^T W y
    tr = np.trace(gram, axis1=1, axis2=2)
    ok = (sel.sum(axis=1) >= 3) & (np.linalg.det(gram) > RANK_RTOL * tr ** 3)
    m_safe = np.where(ok[:, None, None], m, np.eye(3))
    x = np.linalg.solve(m_safe, b[:, :, None])[:, :, 0]
    x[~ok] = np.nan
    return x, ok


def _unit(x, ok):
    norm = np.linalg.norm(x, axis=1)
    ok = ok & (norm > 0)
    s = np.full_like(x, np.nan)
    s[ok] = x[ok] / norm[ok, None]
    return s, ok


def _sun_wls(e_ps_all, h, threshold, usable, weighted=True, keep_zero_readings=False):
    """Select the diodes with E_ps >= threshold and solve eq. 4.27 (unweighted) or 4.30 (W = diag(E_ps)).

    Zero readings are left out unless ``keep_zero_readings`` (then a threshold of E_S0 cos(90 deg),
    zero up to rounding, counts as 0: every reading E_ps >= 0 is selected)."""
    if keep_zero_readings:
        sel = usable & (e_ps_all >= (0.0 if abs(threshold) < ZERO_THRESHOLD_W_M2 else threshold))
    else:
        sel = usable & (e_ps_all >= threshold) & (e_ps_all > 0)
    w = np.where(sel, e_ps_all if weighted else 1.0, 0.0)
    return weighted_lsq(h, e_ps_all, w)


def pinv_estimate(e_p, normals, *, fov_deg, e_s0, live=None, keep_zero_readings=False):
    """Return the pseudoinverse Sun-vector estimate s_hat (N, 3), body frame, unit, and valid (N,) (eq. 4.27).

    Diodes with E_p >= E_S0 cos(FOV) "see the Sun" (sec. 4.3.1); with H_s their normals and
    E_ps their readings, s = (H_s^T H_s)^-1 H_s^T E_ps, normalised. Zero readings are left out
    by default. With ``keep_zero_readings=True`` the selection is E_p >= E_S0 cos(FOV) as
    printed: for FOV = 90 deg that is every diode with E_p >= 0, zeros included, the thesis'
    "pseudo inverse without choosing photodiodes" for the baseline (secs. 4.3.1, 5.1).
    At FOV < 90 deg the threshold is above 0 and the two selections are the same.
    """
    e, h, thr, usable = _inputs(e_p, normals, fov_deg, e_s0, live)
    return _unit(*_sun_wls(e, h, thr, usable, weighted=False, keep_zero_readings=keep_zero_readings))


def wls_estimate(e_p, normals, *, fov_deg, e_s0, live=None):
    """Return the weighted least-squares Sun-vector estimate s_hat (N, 3), body frame, unit, and valid (N,).

    Eqs. 4.28-4.30: same selection as :func:`pinv_estimate`, weights W_s = diag(E_ps):
    s = (H_s^T W_s H_s)^-1 H_s^T W_s E_ps, normalised.
    """
    e, h, thr, usable = _inputs(e_p, normals, fov_deg, e_s0, live)
    return _unit(*_sun_wls(e, h, thr, usable, weighted=True))


def _albedo_vector(e_pa_all, h, sel, weighting):
    """Fit the albedo vector a (N, 3) to the selected readings; a = 0 where the fit is not determined."""
    if weighting == "none":
        w = np.where(sel, 1.0, 0.0)
    elif weighting == "direct":
        w = np.where(sel, e_pa_all, 0.0)
    elif weighting == "inverse":
        with np.errstate(divide="ignore"):
            w = np.where(sel, 1.0 / np.where(sel, e_pa_all, 1.0), 0.0)
    else:
        raise ValueError(f"albedo weighting must be 'none', 'direct' or 'inverse', got {weighting!r}")
    a, ok = weighted_lsq(h, e_pa_all, w)
    a[~ok] = 0.0
    return a, ok


def _details(s_hat, valid, a, a_ok, e_pa_hat, e_ps_hat):
    return s_hat, valid, {"albedo_body": a, "albedo_valid": a_ok,
                          "e_pa_hat_w_m2": e_pa_hat, "e_ps_hat_w_m2": e_ps_hat}


def albedo_sun_estimate(e_p, normals, *, fov_deg, e_s0, live=None, albedo_weighting="none",
                        return_details=False):
    """Return the Albedo-Sun estimate s_hat (N, 3), body frame, unit, and valid (N,) (eqs. 4.32-4.36).

    1. Albedo diodes: E_p < E_S0 cos(FOV) (the complement of the Sun set, dark diodes
       reading 0 included, as in the thesis). Fit an albedo vector a = (H_a^T W_a H_a)^-1
       H_a^T W_a E_pa (eq. 4.32) with ``albedo_weighting``:
       'none' (W_a = I, eq. 4.32 as printed), 'direct' (diag(E_pa)) or
       'inverse' (diag(E_pa)^-1, the variant the thesis uses to initialise
       Sun-Albedo-Sun, sec. 4.3.4). For 'inverse' only diodes with E_pa > 0 take part
       (a zero reading would get an infinite weight).
    2. E_pa_hat = max(0, H a) on every diode (eq. 4.33, "constrained to values above zero");
       E_ps_hat = E_p - E_pa_hat (eq. 4.34).
    3. Re-select the diodes with E_ps_hat >= E_S0 cos(FOV) and solve the weighted LSQ with
       W_s = diag(E_ps) (eqs. 4.35-4.36).

    Where the albedo fit is not determined (fewer than 3 albedo diodes, or coplanar
    normals: the thesis' (H_a^T H_a)^-1 does not exist) we take a = 0, so the estimate
    falls back to :func:`wls_estimate`; ``details['albedo_valid']`` says where.
    ``return_details=True`` adds a third element, a dict with ``albedo_body`` (N, 3) W/m^2,
    ``albedo_valid`` (N,), ``e_pa_hat_w_m2`` and ``e_ps_hat_w_m2`` (N, K).
    """
    e, h, thr, usable = _inputs(e_p, normals, fov_deg, e_s0, live)
    sel_a = usable & (e < thr)
    if albedo_weighting == "inverse":
        sel_a &= e > 0
    a, a_ok = _albedo_vector(e, h, sel_a, albedo_weighting)
    e_pa_hat = np.clip(a @ h.T, 0.0, None)
    e_ps_hat = e - e_pa_hat
    s_hat, valid = _unit(*_sun_wls(e_ps_hat, h, thr, usable, weighted=True))
    if return_details:
        return _details(s_hat, valid, a, a_ok, e_pa_hat, e_ps_hat)
    return s_hat, valid


def sun_albedo_sun_estimate(e_p, normals, *, fov_deg, e_s0, live=None, init="albedo_sun",
                            return_details=False):
    """Return the Sun-Albedo-Sun estimate s_hat (N, 3), body frame, unit, and valid (N,) (eqs. 4.38-4.45).

    1. Initial estimate s0: ``init='wls'`` (:func:`wls_estimate`, the thesis' first run),
       ``init='albedo_sun'`` (:func:`albedo_sun_estimate` with diag(E_a)^-1 albedo weighting,
       the thesis' best run, fig. 4.17), or an array (N, 3) of initial Sun vectors in the
       body frame (any length; the thesis' SunAlbSunVectorEsti takes s0 as input, eq. 4.46).
    2. s_hat0 = E_S0 s0 / |s0| (eq. 4.38); predicted Sun part E_ps_hat = max(0, H s_hat0) (eq. 4.39).
    3. Remainder E_pa_hat = max(0, E_p - E_ps_hat) (eq. 4.40); the albedo diodes are those with
       a remainder above zero (any diode, Sun-seeing or not, as the thesis writes it).
       a = (H_a^T W_a H_a)^-1 H_a^T W_a E_pa with W_a = diag(E_pa) (eqs. 4.41-4.42);
       E_pa_hat = max(0, H a).
    4. E_ps_hat = E_p - E_pa_hat (eq. 4.43); diodes with E_ps_hat >= E_S0 cos(FOV) are
       re-selected and s = (H_s^T W_s H_s)^-1 H_s^T W_s E_ps with W_s = diag(E_ps) (eqs. 4.44-4.45).

    Where the initial estimate is invalid the result is invalid (NaN). Where the albedo fit
    is not determined, a = 0 and step 4 reduces to :func:`wls_estimate` on E_p.
    ``return_details`` as in :func:`albedo_sun_estimate`.
    """
    e, h, thr, usable = _inputs(e_p, normals, fov_deg, e_s0, live)
    if isinstance(init, str) and init == "wls":
        s0, ok0 = _unit(*_sun_wls(e, h, thr, usable, weighted=True))
    elif isinstance(init, str) and init == "albedo_sun":
        s0, ok0 = albedo_sun_estimate(e, h, fov_deg=fov_deg, e_s0=e_s0, live=live, albedo_weighting="inverse")
    elif not isinstance(init, str):
        s0 = np.asarray(init, dtype=float)
        if s0.ndim == 1:
            s0 = s0[None, :]
        if s0.shape != (e.shape[0], 3):
            raise ValueError(f"an initial estimate must be an array (N, 3) = ({e.shape[0]}, 3) of Sun vectors "
                             f"in the body frame, got shape {np.shape(init)}")
        s0, ok0 = _unit(np.where(np.isfinite(s0), s0, 0.0), np.all(np.isfinite(s0), axis=1))
    else:
        raise ValueError(f"init must be 'wls', 'albedo_sun' or an array (N, 3) of initial Sun vectors, got {init!r}")
    s0_scaled = float(e_s0) * np.where(ok0[:, None], s0, 0.0)
    e_ps_hat0 = np.clip(s0_scaled @ h.T, 0.0, None)
    rem = np.clip(e - e_ps_hat0, 0.0, None)
    sel_a = usable & ok0[:, None] & (rem > 0)
    a, a_ok = _albedo_vector(rem, h, sel_a, "direct")
    e_pa_hat = np.clip(a @ h.T, 0.0, None)
    e_ps_hat = e - e_pa_hat
    x, ok = _sun_wls(e_ps_hat, h, thr, usable & ok0[:, None], weighted=True)
    s_hat, valid = _unit(x, ok & ok0)
    if return_details:
        return _details(s_hat, valid, a, a_ok, e_pa_hat, e_ps_hat)
    return s_hat, valid
