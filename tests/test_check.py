"""The analytic check's verdicts, on synthetic numbers with known statistics."""
import numpy as np
import pytest

from simcore.pipeline.check import compare


def _case(rng, n, se, band_scale):
    ref = rng.uniform(10, 1000, (n, 4))
    e_cos = ref * band_scale
    direct = ref + rng.normal(size=ref.shape) * se
    alb_ref = rng.uniform(2, 300, (n, 4))
    alb_se = 0.01 * alb_ref
    albedo = alb_ref + rng.normal(size=ref.shape) * alb_se
    return direct, np.full(ref.shape, se), ref, albedo, alb_se, alb_ref, np.zeros(ref.shape), e_cos


def test_gaussian_noise_passes_and_bias_fails(rng):
    # Unbiased normal errors at the stated sigma: 3-sigma exceedances happen (0.27 %) and are allowed
    # where 3 sigma sets the band; mean |z| of N(0, 1) is sqrt(2/pi) = 0.798.
    args = _case(rng, 20000, se=1.0, band_scale=1e-6)     # the 3-sigma band dominates everywhere
    flags, rep = compare(*args)
    assert rep["direct_outliers"] > 0 and rep["direct_pass"]
    assert abs(rep["albedo_mean_abs_z"] - np.sqrt(2 / np.pi)) < 0.02 and rep["albedo_pass"]
    biased = list(args)
    biased[0] = args[0] + 2.0                             # a 2-sigma bias: far more than chance
    assert not compare(*biased)[1]["direct_pass"]
    biased = list(args)
    biased[3] = args[3] * 1.03                            # albedo 3 % high with 1 % sigma
    assert not compare(*biased)[1]["albedo_pass"]


def test_any_outlier_where_the_half_percent_band_rules_fails(rng):
    args = list(_case(rng, 1000, se=1e-6, band_scale=1.0))   # band = 0.5 % of the value dominates
    assert compare(*args)[1]["direct_pass"]
    args[0] = args[0].copy()
    args[0][5, 2] = args[2][5, 2] * 1.006
    flags, rep = compare(*args)
    assert not rep["direct_pass"] and flags["direct"][5, 2]


def test_poisson_tail_against_closed_forms():
    from simcore.pipeline.check import poisson_tail
    # P(N >= 1) = 1 - exp(-lam); P(N >= 2) = 1 - exp(-lam) (1 + lam)   (Poisson pmf)
    assert poisson_tail(1, 0.3) == pytest.approx(1 - np.exp(-0.3))
    assert poisson_tail(2, 2.0) == pytest.approx(1 - np.exp(-2.0) * 3.0)
    assert poisson_tail(0, 5.0) == 1.0
