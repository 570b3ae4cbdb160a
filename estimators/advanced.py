"""Sun-vector estimators beyond the thesis (its sec. 5.2 "weak points"), vectorised over time.

Two estimators with the signature of :mod:`estimators.sun_vector`
(``E_p`` (N, K) effective W/m^2, ``normals`` (K, 3) body frame, ``fov_deg``,
``e_s0``, ``live``; returns unit ``s_hat`` (N, 3) body frame and ``valid`` (N,)):

:func:`smart_select_estimate` -- diode selection for configurations with
opposite diodes, above all the baseline "tilt 0 / FOV 90" cube (one bare
diode per face). The thesis names the missing "smart" selection for that
configuration as the clear weakness of its comparison (sec. 5.2). Every
opposite pair (n_j = -n_i) forms one channel; the Sun lights at most one
diode of a pair (their FOVs do not overlap for FOV <= 90 deg), so the
brighter diode b carries the Sun and the dimmer one d reads Earth light only.
Three ways to form the channel (``method``):

- ``'difference'``: E_i - E_j along n_i. For cosine diodes the Sun part is
  exactly E_S0 n_i . s whatever its sign, and albedo common to both faces (the
  Earth's limb seen edge-on by both) cancels; what remains is the net albedo
  flux along n_i. NB: for the cube, wherever all six diodes read > 0 this is
  *identical* to the thesis' WLS (eq. 4.30 with W = diag(E_p) gives
  x_i = (E_+^2 - E_-^2) / (E_+ + E_-) = E_+ - E_-), so it improves on WLS only
  where some diodes read 0.
- ``'brightest'``: E_b along n_b, the thesis' own suggestion (sec. 5.2) "the
  photodiode with most incident light and two linearly independent partners":
  for the cube, the three brightest mutually orthogonal faces. The albedo on
  the bright faces stays in; none is wrongly subtracted.
- ``'blend'`` (default): E_b - E_d^2 / E_b along n_b: the dim face's albedo is
  subtracted in proportion to its share E_d / E_b. When both faces are about
  equally bright the Sun is nearly perpendicular to the pair and both faces see
  the Earth edge-on (the albedo is common: subtract it, as 'difference'); when
  the bright face dominates, the dim face's Earth light is mostly not shared
  (keep the reading, as 'brightest').

Unpaired diodes (and a diode whose partner is dead or missing) are single
channels, used when they see the Sun (E_p >= E_S0 cos FOV, sec. 4.3.1, as in
eq. 4.27); a pair channel is used when either of its diodes sees the Sun. The
channels are solved by weighted least squares, weighted as in eq. 4.30 by the
reading of each channel's Sun-seeing diode, so on a configuration without
opposite diodes this is the thesis' WLS. Without Earth light all three
methods return the exact Sun vector wherever >= 3 non-coplanar channels are
used.

:func:`model_albedo_estimate` -- the albedo is not estimated from the
readings (Albedo-Sun, Sun-Albedo-Sun, eqs. 4.32-4.45) but *predicted on board*
from the orbit (TLE + clock), the previous attitude estimate and an on-board
reflectivity map with the Bhanderi model (:func:`simcore.radiometry.onboard.predict_albedo_effective`
computes that prediction; this function only sees measurements, normals and
the prediction). The prediction is subtracted and the Sun vector solved on the
diodes that still see the Sun. With ``fit_gain`` the level of the on-board map
is not trusted (TOMS is a 360 nm reflectivity, CERES a broadband all-sky
albedo; the diodes see neither exactly): the Sun vector S (3) and one albedo
gain k are fitted jointly by linear least squares,

    E_p,i = n_i . S + k a_i      for the diodes that see the Sun,
    E_p,i =           k a_i      for the diodes that surely do not,

(a_i the predicted albedo of diode i), diodes in between (the partly shaded
zone of the aperture between the FOV and the eq. 4.15 cut-off, where neither
line is exact) are left out, and the selection is repeated with the new
estimate a few times. "Surely not" is decided from the current Sun estimate:
angle(n_i, s_hat) > arccos(min(cos FOV, 0.12)) + ``margin_deg``
(0.12 = cos 83 deg, the eq. 4.15 cut-off). Where the readings carry
(almost) no information on k -- no predicted albedo on the selected diodes,
or an albedo pattern the Sun terms explain as well -- k is ``gain_default``;
k is kept within ``gain_bounds``, and S is always the best fit for the k used.
"""
import numpy as np

from estimators.sun_vector import RANK_RTOL, _inputs, _unit, weighted_lsq

EQ415_CUTOFF_COS = 0.12      # thesis eq. 4.15: no light reaches a diode beyond arccos(0.12) = 83 deg
PAIR_COS_TOL = 1e-6          # normals with n_i . n_j < -1 + tol form an opposite pair
GAIN_INFO_RTOL = 1e-3        # the gain is fitted only where >= 0.1 % of sum(a^2) is not explained by the Sun terms


# ---- (a) smart selection for opposite pairs ------------------------------------------------------
def opposite_pairs(normals):
    """Return the opposite diode pairs (P, 2) int, each (i, j) with n_i . n_j ~= -1, i < j, no diode twice."""
    h = np.asarray(normals, dtype=float)
    if h.ndim != 2 or h.shape[1] != 3:
        raise ValueError(f"normals must be an array (K, 3) of diode normals in the body frame, got shape {h.shape}")
    hu = h / np.linalg.norm(h, axis=1, keepdims=True)
    dots = hu @ hu.T
    used = np.zeros(h.shape[0], dtype=bool)
    pairs = []
    for i in range(h.shape[0]):
        if used[i]:
            continue
        cand = np.flatnonzero((dots[i] < -1.0 + PAIR_COS_TOL) & ~used)
        cand = cand[cand > i]
        if cand.size:
            j = int(cand[0])
            used[i] = used[j] = True
            pairs.append((i, j))
    return np.array(pairs, dtype=int).reshape(-1, 2)


def smart_select_estimate(e_p, normals, *, fov_deg, e_s0, live=None, method="blend", return_details=False):
    """Return the opposite-pair Sun-vector estimate s_hat (N, 3), body frame, unit, and valid (N,).

    Each opposite pair (i, j) is one channel (module docstring): ``method='difference'``
    reads E_i - E_j along n_i (albedo common to both faces cancels exactly);
    ``'brightest'`` reads the brighter diode E_b along its normal; ``'blend'`` (default)
    reads E_b - E_d^2 / E_b along n_b (E_d the dimmer diode). A pair channel is used
    where both diodes are usable and at least one reads >= E_S0 cos(FOV); a diode with no
    usable partner is a single channel used where it reads >= E_S0 cos(FOV) (sec. 4.3.1).
    The channels are solved by weighted least squares, s = (H_c^T W_c H_c)^-1 H_c^T W_c E_c
    with W_c the reading of each channel's Sun-seeing (brighter) diode (eqs. 4.28-4.30
    applied to the channels; for the cube the 3 channels make the system square and the
    weights drop out), and normalised. Noise-free cosine diodes without
    albedo give the exact Sun vector wherever >= 3 non-coplanar channels are used; for the
    baseline cube (tilt 0, FOV 90) that is wherever 3 faces see the Sun. Fewer channels,
    or coplanar ones: ``valid`` False, NaN.

    ``return_details=True`` adds a dict with ``n_channels`` (N,) int.
    """
    if method not in ("difference", "brightest", "blend"):
        raise ValueError(f"method must be 'difference', 'brightest' or 'blend', got {method!r}")
    e, h, thr, usable = _inputs(e_p, normals, fov_deg, e_s0, live)
    pairs = opposite_pairs(h)
    n_ep = e.shape[0]
    e0 = np.where(usable, e, 0.0)
    sees = usable & (e >= thr) & (e > 0)

    chan_n, chan_y, chan_w = [], [], []
    both = np.zeros((n_ep, h.shape[0]), dtype=bool)     # diode used through its pair at that epoch
    for i, j in pairs:
        ok = usable[:, i] & usable[:, j]
        both[:, i] = both[:, j] = ok
        use = ok & (sees[:, i] | sees[:, j])
        if method == "difference":
            chan_n.append(np.broadcast_to(h[i], (n_ep, 3)))
            chan_y.append(e0[:, i] - e0[:, j])
        else:
            bright_i = e0[:, i] >= e0[:, j]
            b, d = np.maximum(e0[:, i], e0[:, j]), np.minimum(e0[:, i], e0[:, j])
            chan_n.append(np.where(bright_i[:, None], h[i], h[j]))
            if method == "brightest":
                chan_y.append(b)
            else:
                chan_y.append(b - d * d / np.where(b > 0, b, 1.0))
        chan_w.append(np.where(use, np.maximum(e0[:, i], e0[:, j]), 0.0))
    for k in range(h.shape[0]):
        single = ~both[:, k]                             # unpaired, or its partner is not usable now
        chan_n.append(np.broadcast_to(h[k], (n_ep, 3)))
        chan_y.append(e0[:, k])
        chan_w.append(np.where(single & sees[:, k], e0[:, k], 0.0))
    cn = np.stack(chan_n, axis=1)                        # (N, C, 3) channel normals
    cy = np.stack(chan_y, axis=1)                        # (N, C)
    cw = np.stack(chan_w, axis=1)                        # (N, C) weights, 0 = not used
    x, ok = _batched_lsq(cn, cy, cw)
    s_hat, valid = _unit(x, ok)
    if return_details:
        return s_hat, valid, {"n_channels": np.sum(cw > 0, axis=1)}
    return s_hat, valid


def _batched_lsq(g, y, w):
    """Return x (N, 3) minimising sum_c w_c (g_c . x - y_c)^2 with per-epoch rows g (N, C, 3), and valid (N,).

    Valid where >= 3 rows have w > 0 and their directions span 3-D (same rank test as
    :func:`estimators.sun_vector.weighted_lsq`).
    """
    sel = w > 0
    gs = np.where(sel[:, :, None], g, 0.0)
    gram = np.einsum("nci,ncj->nij", gs, gs)
    m = np.einsum("nc,nci,ncj->nij", w, gs, gs)
    b = np.einsum("nc,nci,nc->ni", w, gs, np.where(sel, y, 0.0))
    tr = np.trace(gram, axis1=1, axis2=2)
    ok = (sel.sum(axis=1) >= 3) & (np.linalg.det(gram) > RANK_RTOL * tr ** 3)
    x = np.linalg.solve(np.where(ok[:, None, None], m, np.eye(3)), b[:, :, None])[:, :, 0]
    x[~ok] = np.nan
    return x, ok


# ---- (b) on-board albedo prediction -------------------------------------------------------------
def _prediction(e_alb_pred, shape):
    a = np.asarray(e_alb_pred, dtype=float)
    if a.ndim == 1:
        a = a[None, :]
    if a.shape != shape:
        raise ValueError(f"E_alb_pred must be the predicted albedo (N, K) = {shape} in the same effective "
                         f"W/m^2 as E_p (see simcore.radiometry.onboard.predict_albedo_effective), got shape "
                         f"{np.shape(e_alb_pred)}")
    return a


def model_albedo_estimate(e_p, normals, e_alb_pred, *, fov_deg, e_s0, live=None, fit_gain=True, n_iter=3,
                          margin_deg=5.0, gain_default=1.0, gain_bounds=(0.0, 4.0), return_details=False):
    """Return the Sun-vector estimate s_hat (N, 3), body frame, unit, and valid (N,) with predicted albedo removed.

    ``e_alb_pred`` (N, K): the albedo each diode is predicted to read, effective W/m^2 like
    ``E_p`` (NaN where no prediction exists: that diode is left out at that epoch).

    1. E_ps = E_p - E_alb_pred; the diodes with E_ps >= E_S0 cos(FOV) see the Sun and
       s = (H_s^T W_s H_s)^-1 H_s^T W_s E_ps with W_s = diag(E_ps) (eqs. 4.28-4.30 on E_ps).
       Without ``fit_gain`` this is the estimate.
    2. ``fit_gain``: ``n_iter`` times, with the current s_hat and k select
       - the Sun diodes: (E_p - k a >= E_S0 cos FOV, or angle(n, s_hat) < FOV - ``margin_deg``)
         and angle(n, s_hat) < min(FOV + margin, 90 deg - margin) (the second condition keeps
         out a diode whose n . S would be ~0 or negative where the true Sun part is 0,
         which the threshold alone cannot do at FOV 90 deg, where E_S0 cos FOV = 0);
       - the dark diodes: angle(n, s_hat) > arccos(min(cos FOV, 0.12)) + margin (beyond the
         eq. 4.15 cut-off: no direct Sun at all);
       (s_hat from step 1, or where step 1 found too few Sun diodes, the thesis' WLS on the
       raw readings, eq. 4.30), and solve
       min sum_sun (E_p - n.S - k a)^2 + sum_dark (E_p - k a)^2
       for (S, k) (unweighted linear least squares). Where less than ``GAIN_INFO_RTOL`` of
       sum(a^2) over the selected diodes is left unexplained by the Sun terms (k not
       determined), k = ``gain_default``; k is clipped to ``gain_bounds``; S is then the
       least-squares Sun vector for that k.

    Valid where >= 3 non-coplanar diodes see the Sun after the albedo removal
    (E_p - k a >= E_S0 cos FOV; for the gain fit, among its Sun diodes); an epoch whose
    later fit fails that keeps its last valid estimate.
    ``return_details=True`` adds a dict with ``gain`` (N,) (1 without ``fit_gain``),
    ``n_sun`` and ``n_dark`` (N,) int.
    """
    e, h, thr, usable = _inputs(e_p, normals, fov_deg, e_s0, live)
    a = _prediction(e_alb_pred, e.shape)
    lo, hi = (float(b) for b in gain_bounds)
    if not lo <= float(gain_default) <= hi:
        raise ValueError(f"gain_default {gain_default} must lie within gain_bounds {gain_bounds}")
    if int(n_iter) != n_iter or n_iter < 1:
        raise ValueError(f"n_iter must be a positive integer, got {n_iter}")
    usable = usable & np.isfinite(a)
    a0 = np.where(usable, a, 0.0)
    e0 = np.where(usable, e, 0.0)

    e_ps = e0 - a0
    sun = usable & (e_ps >= thr) & (e_ps > 0)
    x, ok = weighted_lsq(h, e_ps, np.where(sun, e_ps, 0.0))
    s_hat, valid = _unit(x, ok)
    k = np.ones(e.shape[0])
    n_dark = np.zeros(e.shape[0], dtype=int)
    if fit_gain:
        fov, margin = np.radians(float(fov_deg)), np.radians(float(margin_deg))
        cos_dark = np.cos(np.arccos(min(np.cos(fov), EQ415_CUTOFF_COS)) + margin)
        cos_sure = np.cos(max(fov - margin, 0.0))
        cos_edge = np.cos(min(fov + margin, np.pi / 2 - margin))
        k = np.full(e.shape[0], float(gain_default))
        # The geometric selection starts from step 1, or where that found too few Sun diodes,
        # from the thesis' WLS on the raw readings (eq. 4.30); only a fit that ends with >= 3
        # non-coplanar diodes *measured* to see the Sun (E_p - k a >= E_S0 cos FOV) counts.
        seed, have_seed = _unit(*weighted_lsq(h, e0, np.where(usable & (e0 >= thr) & (e0 > 0), e0, 0.0)))
        seed = np.where(valid[:, None], s_hat, seed)
        have_seed = have_seed | valid
        for _ in range(int(n_iter)):
            c = np.where(have_seed[:, None], np.nan_to_num(seed) @ h.T, np.nan)
            meas = (e0 - k[:, None] * a0 >= thr) & (e0 - k[:, None] * a0 > 0)
            sun = usable & np.where(have_seed[:, None], (meas | (c >= cos_sure)) & (c >= cos_edge), meas)
            dark = usable & ~sun & np.where(have_seed[:, None], c < cos_dark, True)
            s_raw, k_new, ok = _fit_sun_and_gain(h, e0, a0, sun, dark, float(gain_default), lo, hi)
            s_new, ok = _unit(s_raw, ok)
            ok &= _spans(h, sun & (e0 - k_new[:, None] * a0 >= thr) & (e0 - k_new[:, None] * a0 > 0))
            # an epoch whose new selection fails keeps its previous estimate
            s_hat = np.where(ok[:, None], s_new, s_hat)
            k = np.where(ok, k_new, k)
            n_dark = np.where(ok, dark.sum(axis=1), n_dark)
            valid = valid | ok
            seed = np.where(ok[:, None], s_new, seed)
            have_seed = have_seed | ok
    if return_details:
        dark_final = usable & ~sun & dark if fit_gain else np.zeros_like(sun)
        return s_hat, valid, {"gain": k, "n_sun": sun.sum(axis=1), "n_dark": n_dark, "sun": sun,
                              "dark": dark_final}
    return s_hat, valid


def _spans(h, sel):
    """Return (N,) bool: >= 3 selected normals spanning 3-D (the rank test of weighted_lsq)."""
    hh = (h[:, :, None] * h[:, None, :]).reshape(h.shape[0], 9)
    gram = (sel.astype(float) @ hh).reshape(-1, 3, 3)
    tr = np.trace(gram, axis1=1, axis2=2)
    return (sel.sum(axis=1) >= 3) & (np.linalg.det(gram) > RANK_RTOL * tr ** 3)


def _fit_sun_and_gain(h, e, a, sun, dark, k0, lo, hi):
    """Return S (N, 3), k (N,) and valid (N,) of the joint linear fit described in :func:`model_albedo_estimate`.

    Normal equations [[M_SS, m], [m^T, m_kk]] (S, k) = (b_S, b_k), solved by eliminating S:
    y = M_SS^-1 m, z = M_SS^-1 b_S, k = (b_k - m . z) / (m_kk - m . y) (the Schur complement
    is the information on k left after fitting S), then S = z - k y.
    """
    sun_f, sel_f = sun.astype(float), (sun | dark).astype(float)
    hh = (h[:, :, None] * h[:, None, :]).reshape(h.shape[0], 9)
    m_ss = (sun_f @ hh).reshape(-1, 3, 3)
    m_sk = (sun_f * a) @ h
    b_s = (sun_f * e) @ h
    m_kk = np.sum(sel_f * a * a, axis=1)
    b_k = np.sum(sel_f * a * e, axis=1)
    ok = _spans(h, sun)
    rhs = np.stack([m_sk, b_s], axis=2)                                 # (N, 3, 2)
    yz = np.linalg.solve(np.where(ok[:, None, None], m_ss, np.eye(3)), rhs)
    y, z = yz[:, :, 0], yz[:, :, 1]
    schur = m_kk - np.sum(m_sk * y, axis=1)
    informed = ok & (m_kk > 0) & (schur > GAIN_INFO_RTOL * m_kk)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(informed, (b_k - np.sum(m_sk * z, axis=1)) / np.where(informed, schur, 1.0), k0)
    k = np.clip(k, lo, hi)
    s_vec = z - k[:, None] * y
    s_vec[~ok] = np.nan
    return s_vec, k, ok


def model_albedo_direction_variance(normals, e_alb_pred, s_hat, sun, dark, sigma_e, sun_level, fit_gain=True):
    """Return the variance (N,) per perpendicular axis, rad^2, of :func:`model_albedo_estimate`'s Sun direction.

    First-order propagation of independent reading errors of standard deviation ``sigma_e``
    (N, K), effective W/m^2, through the least-squares fit the estimate made on its final
    selection (``return_details``: ``sun`` and ``dark`` (N, K) bool): rows [n_i, a_i] for the
    Sun diodes and [0, a_i] for the dark ones (the gain column only with ``fit_gain`` and where
    the readings determine the gain; elsewhere the gain is fixed and the fit is S alone on the Sun
    diodes). The unweighted fit x = (A^T A)^-1 A^T y has covariance
    (A^T A)^-1 A^T diag(sigma^2) A (A^T A)^-1; the unit vector s = S / |S| moves by the part of dS
    perpendicular to s over |S| = ``sun_level`` (the normal-Sun reading E_S0), so the variance per
    axis is half the trace of (I - s s^T) Cov(S) (I - s s^T) / |S|^2. NaN where fewer than three
    non-coplanar Sun diodes were used.
    """
    h = np.asarray(normals, dtype=float)
    a = np.nan_to_num(np.asarray(e_alb_pred, dtype=float))
    sun, dark = np.asarray(sun, bool), np.asarray(dark, bool) & bool(fit_gain)
    sig2 = np.asarray(sigma_e, dtype=float) ** 2
    s = np.nan_to_num(np.asarray(s_hat, dtype=float))
    perp = np.eye(3) - s[:, :, None] * s[:, None, :]

    def cov_s(cols):
        used = sun | dark if cols == 4 else sun
        A = np.zeros(a.shape + (cols,))
        A[:, :, :3] = np.where(sun[:, :, None], h[None], 0.0)
        if cols == 4:
            A[:, :, 3] = np.where(used, a, 0.0)
        M = np.einsum("nki,nkj->nij", A, A)
        ok = _spans(h, sun)
        if cols == 4:   # the gain is determined where the estimate fitted it (its Schur-complement test)
            m_ss = np.where(ok[:, None, None], M[:, :3, :3], np.eye(3))
            schur = M[:, 3, 3] - np.einsum("ni,ni->n", M[:, :3, 3], np.linalg.solve(m_ss, M[:, :3, 3:])[:, :, 0])
            ok = ok & (M[:, 3, 3] > 0) & (schur > GAIN_INFO_RTOL * M[:, 3, 3])
        Minv = np.linalg.inv(np.where(ok[:, None, None], M, np.eye(cols)))
        c = (Minv @ np.einsum("nki,nk,nkj->nij", A, np.where(used, sig2, 0.0), A) @ Minv)[:, :3, :3]
        return c, ok

    cov, ok = cov_s(3)
    if fit_gain:
        cov4, ok4 = cov_s(4)
        cov = np.where(ok4[:, None, None], cov4, cov)
    var = 0.5 * np.trace(perp @ cov @ perp, axis1=1, axis2=2) / float(sun_level) ** 2
    return np.where(ok, var, np.nan)
