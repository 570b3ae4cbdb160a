"""The analytic check's statistics on synthetic numbers with known distributions: its false-alarm rate
is at most the stated one, and it catches small biases, wrong standard errors and single gross errors."""
import numpy as np
import pytest
from scipy import stats

from simcore.pipeline.check import ALPHA_RUN, P_TAIL, binomial_tail, compare, describe, normal_scores


def _components(rng, n=400, k=6, *, dof=np.inf, bias=0.0, se_scale=1.0):
    """Return (components, e_sun, e_sun_cos) of one synthetic run: references, relative standard errors of
    0.3-1 % (as the target accuracies make them), rendered values ref (1 + bias) + N(0, se^2); with a
    finite ``dof`` the reported error is itself estimated, se sqrt(chi2_dof / dof), so that
    (rendered - ref) / reported follows Student's t with ``dof`` (as the renderer's does)."""
    out = {}
    for name in ("direct", "direct_plain", "albedo"):
        ref = rng.uniform(5.0, 1000.0, (n, k))
        se = ref * 10 ** rng.uniform(-2.5, -2.0, (n, k))
        x = ref * (1 + bias) + rng.normal(size=(n, k)) * se
        if np.isfinite(dof):
            se = se * np.sqrt(rng.chisquare(dof, size=(n, k)) / dof)
        samples = np.full((n, k), 1024)
        out[name] = (x, se * se_scale, np.full((n, k), dof), samples, ref, 0.0)
    e_sun = np.full((n, 1), 1361.0)
    return out, e_sun, np.full((n, k), 1000.0)


def _passes(components, e_sun, e_cos):
    return compare(components, e_cos.shape[1], e_sun, e_cos)[1]["pass"]


def test_false_alarm_rate_is_at_most_the_stated_one():
    # Size: 3000 runs with unbiased normal errors and right standard errors. Bonferroni over the 11 test
    # families bounds the rate by ALPHA_RUN = 1e-3, so at most Binomial(3000, 1e-3) failures: P(>= 10)
    # = 1.1e-3 (scipy), the limit below; the test can fail only if the design's size is wrong.
    rng = np.random.default_rng(12)
    fails = sum(not _passes(*_components(rng, n=60, k=4)) for _ in range(3000))
    assert binomial_tail(10, 3000, ALPHA_RUN) < 2e-3
    assert fails < 10, fails


def test_student_t_errors_with_their_degrees_of_freedom_keep_the_size():
    # Heavy-tailed t = (estimate - truth) / se with 6 degrees of freedom, stated as such: the tails
    # test uses the normal scores Phi^-1(F_t6(t)), the bias and spread tests only sums of d and se^2.
    rng = np.random.default_rng(13)
    fails = 0
    for _ in range(400):
        fails += not _passes(*_components(rng, n=200, k=4, dof=6.0))
    # Binomial(400, 1e-3): P(>= 3) = 7.8e-3
    assert fails < 3, fails


@pytest.mark.parametrize("bias", [+0.002, -0.002])
def test_a_small_uniform_bias_fails(bias):
    # 0.2 % on values whose standard errors are 0.3-1 %: 2400 diode-epochs per component.
    rng = np.random.default_rng(14)
    comps, e_sun, e_cos = _components(rng, bias=bias)
    rep = compare(comps, 6, e_sun, e_cos)[1]
    assert not rep["pass"]
    assert {t["test"] for t in rep["tests"] if not t["passed"]} & {"bias", "bias_per_diode"}
    assert _passes(*_components(np.random.default_rng(14)))           # the same run unbiased passes


@pytest.mark.parametrize("scale", [0.8, 1.25])
def test_standard_errors_20_percent_off_fail_the_spread_test(scale):
    rng = np.random.default_rng(15)
    comps, e_sun, e_cos = _components(rng, se_scale=scale)
    rep = compare(comps, 6, e_sun, e_cos)[1]
    assert not rep["pass"]
    assert any(t["test"] == "spread" and not t["passed"] for t in rep["tests"])


def test_one_diode_off_fails_its_per_diode_bias_and_is_named():
    rng = np.random.default_rng(16)
    comps, e_sun, e_cos = _components(rng)
    x, se, dof, s, ref, e = comps["direct_plain"]
    x = x.copy()
    x[:, 3] += 3.0 * se[:, 3]                 # diode 3 reads 3 sigma high at every epoch
    comps["direct_plain"] = (x, se, dof, s, ref, e)
    rep = compare(comps, 6, e_sun, e_cos)[1]
    failed = [t for t in rep["tests"] if not t["passed"]]
    assert ("direct_plain", "bias_per_diode") in [(t["component"], t["test"]) for t in failed]
    per = [t for t in rep["tests"] if t["component"] == "direct_plain" and t["test"] == "bias_per_diode"][0]
    assert per["note"] == "worst diode 3"


def test_six_gross_errors_fail_the_tails_test_and_are_flagged():
    rng = np.random.default_rng(17)
    comps, e_sun, e_cos = _components(rng)
    x, se, dof, s, ref, e = comps["albedo"]
    x = x.copy()
    bad = [(5, 1), (77, 2), (301, 4), (12, 0), (150, 5), (222, 3)]
    for i, j in bad:
        x[i, j] = ref[i, j] + 12 * se[i, j]
    comps["albedo"] = (x, se, dof, s, ref, e)
    flags, rep = compare(comps, 6, e_sun, e_cos)
    # 6 beyond |z| = 4 where N(0, 1) expects 2400 x 6.3e-5 = 0.15: P(>= 6) = 1.4e-8
    assert any(t["component"] == "albedo" and t["test"] == "tails" and not t["passed"] for t in rep["tests"])
    assert all(flags["albedo"][i, j] for i, j in bad)


def test_exact_values_must_match_and_unsampled_slivers_are_bounded():
    rng = np.random.default_rng(18)
    comps, e_sun, e_cos = _components(rng, n=50)
    x, se, dof, s, ref, e = comps["direct"]
    x, se, s = x.copy(), se.copy(), s.copy()
    se[0, 0], s[0, 0], x[0, 0] = 0.0, 0, ref[0, 0]                 # exact by geometry (no samples)
    se[1, 0], s[1, 0], x[1, 0] = 0.0, 1024, 0.0                    # all 1024 samples missed a sliver...
    ref[1, 0] = 0.005                                             # ...worth 0.005 W/m^2: possible
    comps["direct"] = (x, se, dof, s, ref, e)
    assert compare(comps, 6, e_sun, e_cos)[1]["pass"]
    x[0, 0] = ref[0, 0] * (1 + 1e-4)                              # an exact value 1e-4 off
    assert not compare(comps, 6, e_sun, e_cos)[1]["pass"]
    x[0, 0] = ref[0, 0]
    ref[1, 0] = 100.0                   # all 1024 samples missed 100 W/m^2: > E ln(1/alpha) / n = 12.6
    assert not compare(comps, 6, e_sun, e_cos)[1]["pass"]


def test_normal_scores_and_binomial_tail_against_closed_forms():
    # Phi^-1(F_t(t; nu)): t at the t6 97.5 % point maps to the normal's 97.5 % point, 1.95996.
    t975 = stats.t.ppf(0.975, 6)
    np.testing.assert_allclose(normal_scores([t975, -t975], 1.0, 6.0), [1.959964, -1.959964], atol=1e-6)
    np.testing.assert_allclose(normal_scores([1.5], 4.0, np.inf), [0.75])
    # P(|z| > 4) for N(0, 1): 2 (1 - Phi(4)) = 6.334e-5 (Abramowitz & Stegun table 26.1)
    assert P_TAIL == pytest.approx(6.334e-5, rel=1e-3)
    # Binomial(10, 0.5): P(X >= 9) = (10 + 1) / 1024
    assert binomial_tail(9, 10, 0.5) == pytest.approx(11 / 1024)


def test_the_tails_from_scipy_special_are_scipy_stats_bit_for_bit():
    # The check takes the normal, Student's t and binomial tails from scipy.special (scipy.stats costs ~0.3 s of
    # CPU to import in every run); oracle: scipy.stats itself, value for value, exactly (a run's check report and
    # flags unchanged), over the arguments the check meets: scores to |t| ~ 40, degrees of freedom 1-1e4,
    # binomial counts over the whole range (k = 0 and k > n included) at p = 1/2 and the tails' P(|z| > 4).
    from simcore.pipeline.check import _norm_isf, _norm_sf, _t_sf
    rng = np.random.default_rng(3)
    x = np.concatenate([np.abs(rng.standard_t(3, 20000)) * 3, [0.0, 1e-300, 4.0, 38.0, 40.0]])
    nu = np.concatenate([rng.uniform(1.0, 1e4, x.size - 5), [1.0, 2.0, 6.0, 50.0, 1e4]])
    assert np.array_equal(_t_sf(x, nu), stats.t.sf(x, nu))
    assert np.array_equal(_norm_sf(x), stats.norm.sf(x))
    q = np.concatenate([rng.uniform(0.0, 1.0, 20000), 10.0 ** -rng.uniform(1, 300, 2000), [0.0, 0.25, 0.5, 1.0]])
    a, b = _norm_isf(q), stats.norm.isf(q)
    assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))
    for n in [1, 2, 7, 100, 1001, 16384, 246582]:
        for k in np.unique(np.concatenate([np.arange(-1, 30), rng.integers(0, n + 2, 40), [n // 2, n, n + 1]])):
            for p in (0.5, P_TAIL):
                assert binomial_tail(int(k), n, p) == float(stats.binom.sf(k - 1, n, p)), (k, n, p)


def test_describe_prints_each_test_with_statistic_and_threshold():
    rng = np.random.default_rng(19)
    comps, e_sun, e_cos = _components(rng, n=50)
    rep = compare(comps, 6, e_sun, e_cos)[1]
    lines = describe(rep)
    assert len(lines) == len(rep["tests"]) + 2
    assert any("bias" in ln and "<=" in ln for ln in lines) and lines[-1] == "check: PASS"
