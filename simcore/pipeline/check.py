"""The analytic check of rendered irradiance: statistical tests with a stated false-alarm rate.

Every diode-epoch of a run gives, per component, a difference ``d = rendered -
reference`` and its variance ``v = se^2 (+ delta^2)``: the renderer's standard
error squared (an unbiased estimate of the variance of its stratified mean,
computed from samples that never decided how many samples to take), plus, for
the albedo, the square of the reference's own estimated cell-discretisation
error ``delta``. Three components are checked:

* ``direct``: the direct Sun as rendered (with the analytic wells' aperture
  split, ``simcore.render``), against the analytic aperture response
  with the body's shadow and the solar-disc quadrature;
* ``direct_plain``: on a random share of the epochs, the direct Sun rendered a
  second time without the analytic aperture hint and with its own random
  numbers: an estimate that shares nothing with the analytic model, so a wrong
  aperture response or body shadow shows here whatever the hinted estimate does;
* ``albedo``: against the Bhanderi cell sum on the map refined ``factor`` x
  ``factor`` (see :func:`discretisation_bound`). Where shadows of the body or of
  other parts of the satellite cross a diode (directions where traced probe rays
  disagree with the body box held at the diode's centre), the cell sum takes the
  diode's visible share traced against the mesh instead, a deterministic
  quadrature whose estimated error joins the variance
  (``simcore.radiometry.analytic.DirectionVisibility``; run file
  ``albedo_mesh``, ``albedo_visibility_error``).

The fourth rendered component, ``reflected`` (sunlight and Earth light reflected
by the spacecraft's own non-black surfaces onto a diode), is NOT checked: the
analytic model's surfaces are black, so it has no reference for it; the report
counts the diode-epochs that carry some (``reflected_unchecked``), and the path
tracer is tested against closed forms in tests/render/test_reflected.py.

For each component four families of tests, over the diode-epochs whose
standard error is positive. The others are tested one by one: a value the
renderer did not sample (exactly zero by geometry) must equal the reference to
float32 arithmetic (``EXACT_REL_TOL``); a direct value whose ``n`` samples all
read the same (zero standard error: a sliver of light every sample missed, or
a fully lit diode under a point Sun) may differ from the reference by at most
``E_sun ln(1 / alpha) / n`` (a lane reads between 0 and E_sun: the chance that
n samples all miss a part worth more than this is below alpha).

1. bias, overall: ``B = sum d / sqrt(sum v)`` is N(0, 1) when the rendering is
   unbiased (the sum of many independent differences, whatever each one's
   distribution);
2. bias, per diode: the same over each diode's epochs (a wrong aperture or a
   diode-specific shadow), Bonferroni over the diodes;
3. spread: with z the normal score of ``t = d / sqrt(v)`` under Student's t with
   the standard error's effective degrees of freedom (Satterthwaite), half of
   the z lie within +-0.6745 when the standard errors are right: the count
   inside is Binomial(n, 1/2), exactly, whatever a few heavy tails do. The
   degrees of freedom are estimates themselves, so the null allows any value
   between the estimate and infinity (the test fails only when both ends
   fail on the same side). Errors 20 % too small or too large, a mirrored map,
   a rotated attitude all move it. The pooled z spread ``sqrt(sum d^2 / sum v)``
   is reported beside it;
4. tails: the count of |z| > 4 against Binomial(n, 6.33e-5).

The hint-free direct estimate has no tails test (:func:`families`). The run's
false-alarm rate is ``ALPHA_RUN = 1e-3``, split equally over the 11 families
(Bonferroni; the families are not independent, so the true rate is at most
this). Each test is reported with its statistic, threshold and
p-value; the run passes when every test does.
"""
import math

import numpy as np
from scipy import special

ALPHA_RUN = 1e-3            # false-alarm rate of the whole check, per run
COMPONENTS = ("direct", "direct_plain", "albedo")
FAMILIES = ("bias", "bias_per_diode", "spread", "tails")


def families(component):
    """Return the test families of a component: all four, but no tails test of the hint-free direct
    estimate (its 1024 samples cross a well's edge in a handful of strata, so its standard error is
    heavy-tailed: the default orbit gives 4 of 2640 beyond |z| = 4, where N(0, 1) expects 0.17; its
    bias and spread tests are what it is for)."""
    return FAMILIES[:3] if component == "direct_plain" else FAMILIES


# The distributions' tails straight from scipy.special, the functions scipy.stats' norm, t and binom evaluate
# (bit for bit their values): importing scipy.stats would add ~0.3 s of CPU to every run's start-up.
def _norm_sf(x):
    """Return P(Z > x) for Z ~ N(0, 1) (scipy.stats.norm.sf)."""
    return special.ndtr(-np.asarray(x, dtype=float))


def _norm_isf(q):
    """Return x with P(Z > x) = q for Z ~ N(0, 1) (scipy.stats.norm.isf; +0.0 at q = 1/2, as it)."""
    return 0.0 - special.ndtri(np.asarray(q, dtype=float))


def _t_sf(x, dof):
    """Return P(T > x) for T ~ Student's t with ``dof`` degrees of freedom (scipy.stats.t.sf)."""
    return special.stdtr(dof, -np.asarray(x, dtype=float))


Z_TAIL = 4.0
Z_QUARTILE = float(_norm_isf(0.25))            # 0.6745: half of N(0, 1) lies within
P_TAIL = float(2.0 * _norm_sf(Z_TAIL))        # 6.33e-5: P(|z| > 4) for z ~ N(0, 1)
EXACT_REL_TOL = 1e-5        # exact values (zero standard error): float32 arithmetic, of E_sun cos(incidence)
EXACT_ABS_TOL_W_M2 = 1e-9   # values this close are equal (e.g. 1e-14 against an exact 0)
ALBEDO_FLOOR_W_M2 = 1.0     # albedo diode-epochs checked: reference above this

PLAIN_CHECK_SHARE = 0.125     # share of the epochs whose direct Sun is rendered again without the aperture hint
# ...with at least this many samples: with 64, a well's edge crosses a handful of strata and the hint-free
# estimate's standard error is unreliable (a 4-epoch run read 22 sigma off with seed 7)
PLAIN_CHECK_SAMPLES = 1024


def plain_check_epochs(seed, n):
    """Return (n,) bool: the epochs of a run whose direct Sun the check renders a second time without the
    analytic aperture hint (a random share PLAIN_CHECK_SHARE, fixed by the seed, so a resumed run picks the
    same ones)."""
    return np.random.default_rng([int(seed), 0x9E3779B9]).random(n) < PLAIN_CHECK_SHARE


def discretisation_bound(albedo_native, albedo_refined, factor):
    """Return the estimated cell-discretisation error of the refined analytic albedo (W/m^2).

    The cell-centre sum is second order in the cell size (Richardson), so the refined sum's
    error is about ``|A_native - A_refined| / (factor^2 - 1)``. Both sums must be of the same
    integrand (the same visible shares where shadows cross the diodes): a native sum with the
    body box alone would add the shares' effect to the estimate, inflating the variance and
    making the z-scores too narrow (the spread test failed on two day runs that way with 2 x 2).
    """
    return np.abs(np.asarray(albedo_native) - np.asarray(albedo_refined)) / (factor ** 2 - 1.0)


def normal_scores(diff, var, dof):
    """Return the normal scores of ``t = diff / sqrt(var)`` under Student's t with ``dof`` degrees of
    freedom (inf: t itself), i.e. Phi^-1(F_t(t)): N(0, 1) when t follows that t distribution."""
    diff, var, dof = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (diff, var, dof)))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = diff / np.sqrt(var)
    z = t.copy()
    fin = np.isfinite(dof) & np.isfinite(t)
    if np.any(fin):
        nu = np.maximum(dof[fin], 1.0)
        # Both tails through the survival function, so that |z| up to ~38 keeps its precision.
        p = _t_sf(np.abs(t[fin]), nu)
        z[fin] = np.sign(t[fin]) * _norm_isf(p)
    return z


def _threshold(alpha):
    """Return the two-sided N(0, 1) threshold of size ``alpha``."""
    return float(_norm_isf(alpha / 2.0))


def binomial_tail(k, n, p):
    """Return P(X >= k) for X ~ Binomial(n, p): the regularised incomplete beta function I_p(k, n - k + 1), as
    scipy.stats.binom.sf(k - 1, n, p) evaluates it."""
    if k <= 0:
        return 1.0
    return 0.0 if k > n else float(np.clip(special.betainc(k, n - k + 1.0, p), 0.0, 1.0))


def _component_tests(name, diff, var, z, diode, n_diodes, alpha):
    """Return the list of test dicts of one component (arrays over its stochastic diode-epochs; ``z`` their
    normal scores, :func:`normal_scores`)."""
    tests = []
    n = diff.size
    thr = _threshold(alpha)
    if n == 0:
        return [dict(component=name, test=f, n=0, statistic=None, threshold=None, p_value=None, passed=True,
                     note="nothing to test") for f in families(name)]
    sv = float(var.sum())
    b = float(diff.sum() / math.sqrt(sv)) if sv > 0 else 0.0
    tests.append(dict(component=name, test="bias", n=n, statistic=b, threshold=thr,
                      p_value=float(2 * _norm_sf(abs(b))), passed=abs(b) <= thr,
                      note=f"mean difference {diff.mean():+.4g} W/m^2, {b / math.sqrt(n):+.4f} sigma per diode-epoch"))
    per = []
    worst = (0.0, -1)
    live = [k for k in range(n_diodes) if np.any(diode == k)]
    thr_k = _threshold(alpha / max(len(live), 1))
    for k in live:
        sel = diode == k
        vk = float(var[sel].sum())
        bk = float(diff[sel].sum() / math.sqrt(vk)) if vk > 0 else 0.0
        per.append(bk)
        if abs(bk) > abs(worst[0]):
            worst = (bk, k)
    tests.append(dict(component=name, test="bias_per_diode", n=len(live), statistic=worst[0], threshold=thr_k,
                      p_value=float(min(1.0, len(live) * 2 * _norm_sf(abs(worst[0])))),
                      passed=abs(worst[0]) <= thr_k, note=f"worst diode {worst[1]}",
                      per_diode={int(k): float(x) for k, x in zip(live, per)}))
    # The degrees of freedom are themselves estimated (Satterthwaite's from the same strata reads low
    # when few strata carry the variance): the null is "half within +-0.6745 for some nu between the
    # estimate and infinity". The share moves monotonically with nu, so the p-value is the larger of
    # the two ends', and 1 where they lie on either side of 1/2.
    shares, p_ends = [], []
    for zz in (z, diff / np.sqrt(var)):
        inner = int(np.count_nonzero(np.abs(zz) < Z_QUARTILE))
        shares.append(inner / n)
        p_ends.append(min(1.0, 2.0 * min(binomial_tail(inner, n, 0.5), binomial_tail(n - inner, n, 0.5))))
    bracket = (shares[0] - 0.5) * (shares[1] - 0.5) <= 0
    p_spread = 1.0 if bracket else max(p_ends)
    pooled = math.sqrt(float((diff * diff).sum()) / sv) if sv > 0 else float("nan")
    tests.append(dict(component=name, test="spread", n=n, statistic=shares[0], threshold=None, p_value=p_spread,
                      passed=p_spread >= alpha,
                      note=f"share of |z| < {Z_QUARTILE:.4f}: {shares[0]:.4f} with the estimated degrees of "
                           f"freedom, {shares[1]:.4f} with infinitely many (N(0, 1): 0.5); pooled z spread "
                           f"{pooled:.4f}"))
    if "tails" in families(name):
        k_out = int(np.count_nonzero(np.abs(z) > Z_TAIL))
        p_tail = binomial_tail(k_out, n, P_TAIL)
        tests.append(dict(component=name, test="tails", n=n, statistic=k_out, threshold=None, p_value=p_tail,
                          passed=p_tail >= alpha,
                          note=f"|z| > {Z_TAIL:g}: {k_out}, expected {n * P_TAIL:.2f}; max |z| "
                               f"{float(np.abs(z).max()):.2f}"))
    return tests


def compare(components, n_diodes, e_sun, e_sun_cos, *, alpha=ALPHA_RUN):
    """Return (flags, report): per diode-epoch |z| > 4 flags per component (bool (N, K)) and the check's
    report: every test with its statistic, threshold and p-value, and the verdict.

    ``components``: dict name -> (rendered, se, dof, samples, reference, extra_var) arrays (N, K) (NaN
    where not rendered or not considered; ``extra_var`` the reference's own variance, e.g. delta^2, or 0).
    ``e_sun`` (N, 1) and ``e_sun_cos`` (N, K): E_sun, and x the cosine of incidence on each diode.
    """
    alpha_family = alpha / sum(len(families(c)) for c in components)
    report = {"alpha_run": alpha, "alpha_per_test_family": alpha_family, "tests": []}
    flags = {}
    for name, (x, se, dof, samples, ref, extra) in components.items():
        x, se, dof, samples, ref = (np.asarray(a, dtype=float) for a in (x, se, dof, samples, ref))
        extra = np.broadcast_to(np.asarray(extra, dtype=float), x.shape)
        diode_idx = np.broadcast_to(np.arange(x.shape[1]), x.shape)
        use = np.isfinite(x) & np.isfinite(ref) & np.isfinite(se)
        if name == "albedo":
            use &= ref > ALBEDO_FLOOR_W_M2
        exact = use & (se == 0)
        stoch = use & (se > 0)
        d = x - ref
        var = se ** 2 + extra
        with np.errstate(divide="ignore", invalid="ignore"):
            dof_tot = np.where(np.isfinite(dof) & (se > 0), var ** 2 / (se ** 4 / np.where(dof > 0, dof, 1.0)),
                               np.inf)
        tol = np.maximum(EXACT_REL_TOL * np.abs(np.asarray(e_sun_cos, dtype=float)), EXACT_ABS_TOL_W_M2) \
            + np.sqrt(extra)
        if name != "albedo":       # all n samples alike: what they may all have missed (docstring)
            with np.errstate(divide="ignore"):
                tol = tol + np.where(samples > 0, np.asarray(e_sun, dtype=float) * math.log(1.0 / alpha_family)
                                     / np.maximum(samples, 1.0), 0.0)
        exact_bad = exact & (np.abs(d) > tol)
        report["tests"].append(dict(component=name, test="exact", n=int(exact.sum()),
                                    statistic=int(exact_bad.sum()), threshold=0, p_value=None,
                                    passed=not exact_bad.any(),
                                    note="values with zero standard error off by more than float32 "
                                         "arithmetic (or what all their samples may have missed)"))
        z = np.zeros(x.shape)
        z[stoch] = normal_scores(d[stoch], var[stoch], dof_tot[stoch])
        report["tests"] += _component_tests(name, d[stoch], var[stoch], z[stoch], diode_idx[stoch],
                                            x.shape[1], alpha_family)
        flags[name] = (stoch & (np.abs(z) > Z_TAIL)) | exact_bad
        report[f"{name}_checked"] = int(use.sum())
    report["pass"] = bool(all(t["passed"] for t in report["tests"]))
    return flags, report


def describe(report):
    """Return the check report as printable lines: one per test with its statistic and threshold."""
    lines = [f"check: false-alarm rate {report['alpha_run']:g} per run ({report['alpha_per_test_family']:.2g} "
             f"per test family)"]
    if "albedo_mesh_quadrature" in report:
        lines.append(f"  albedo: {report.get('albedo_checked', 0)} diode-epochs checked, "
                     f"{report['albedo_mesh_quadrature']} of them with light through directions where shadows of "
                     f"the body or other parts cross the diode (there the reference takes the diode's visible "
                     f"share traced against the mesh, a deterministic quadrature)")
    if report.get("direct_unchecked"):
        win = report.get("direct_unchecked_window", 0)
        other = report["direct_unchecked"] - win
        reasons = ([f"{other} where a part the analytic model does not know ([[part]]: panels, antennas, user "
                    f"meshes; another diode's mount) may shade the Sun, or the body box a round well's diode (its "
                    f"shadow is clipped against rectangles only)"] if other > 0 else []) + \
                  ([f"{win} where the body may shade a diode under a window (the light leaves the window shifted: "
                    f"no exact reference)"] if win else [])
        lines.append(f"  direct: {report['direct_unchecked']} diode-epochs left out: {'; '.join(reasons)}")
    if report.get("reflected_unchecked"):
        lines.append(f"  reflected: {report['reflected_unchecked']} diode-epochs with light reflected by the "
                     f"spacecraft, not checked (the analytic model's surfaces are black; the path tracer's own "
                     f"tests check it against closed forms)")
    for t in report["tests"]:
        stat = t["statistic"]
        if t["test"] in ("bias", "bias_per_diode") and stat is not None:
            s = f"|{stat:+.3f}| <= {t['threshold']:.3f}"
        elif t["test"] == "spread" and stat is not None:
            s = f"p = {t['p_value']:.3g} >= {report['alpha_per_test_family']:.2g}"
        elif t["test"] == "tails" and stat is not None:
            s = f"P(>= {stat}) = {t['p_value']:.3g} >= {report['alpha_per_test_family']:.2g}"
        elif t["test"] == "exact":
            s = f"{stat} off of {t['n']}"
        else:
            s = "-"
        lines.append(f"  {'ok  ' if t['passed'] else 'FAIL'} {t['component']:<12} {t['test']:<15} n={t['n']:<7} "
                     f"{s}   ({t['note']})")
    lines.append(f"check: {'PASS' if report['pass'] else 'FAIL'}")
    return lines
