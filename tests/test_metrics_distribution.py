"""KS, effective sample size, area validation metric and Anderson–Darling against scipy and
hand computations."""

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from railval.core.errors import InvalidParameter
from railval.core.metrics import (
    anderson_darling,
    area_validation_metric,
    autocorrelation,
    effective_sample_size,
    kolmogorov_smirnov,
    ks_pvalue,
)


def _ar1(phi, n, rng):
    e = rng.normal(size=n)
    return scipy.signal.lfilter([1.0], [1.0, -phi], e)


def test_ks_matches_scipy():
    rng = np.random.default_rng(3)
    m, c = rng.normal(size=800), rng.normal(0.2, 1.1, size=600)
    ref = scipy.stats.ks_2samp(m, c)
    r = kolmogorov_smirnov(m, c)
    assert r.D == pytest.approx(ref.statistic, abs=0)
    assert r.p == pytest.approx(ref.pvalue, rel=1e-12)


def test_ks_pvalue_with_nominal_sizes_equals_scipy_asymp():
    rng = np.random.default_rng(4)
    m, c = rng.normal(size=700), rng.normal(0.1, 1.0, size=900)
    ref = scipy.stats.ks_2samp(m, c, method="asymp")
    assert ks_pvalue(ref.statistic, 700, 900) == pytest.approx(ref.pvalue, rel=1e-12)


def test_autocorrelation_matches_direct_sum():
    rng = np.random.default_rng(5)
    x = rng.normal(size=64)
    d = x - x.mean()
    direct = np.array([np.dot(d[: 64 - k], d[k:]) for k in range(10)]) / np.dot(d, d)
    np.testing.assert_allclose(autocorrelation(x, 9), direct, rtol=1e-10, atol=1e-12)
    # with the mean removed, 1 + 2 Σ_{k≥1} ρ_k = 0 exactly: why the n_eff sum is truncated
    assert 1 + 2 * autocorrelation(x)[1:].sum() == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("method", ["bartlett", "ar1"])
def test_effective_sample_size_of_ar1(method):
    # AR(1) with φ: theoretical n_eff = n (1 − φ)/(1 + φ) for both estimators (Bartlett's sum
    # Σ φ^k is geometric). 20 % tolerance: sampling error of ρ_k at n = 20 000.
    rng = np.random.default_rng(6)
    phi, n = 0.9, 20_000
    x = _ar1(phi, n, rng)
    expected = n * (1 - phi) / (1 + phi)
    assert effective_sample_size(x, method) == pytest.approx(expected, rel=0.2)


def test_effective_sample_size_of_white_noise_is_near_n():
    rng = np.random.default_rng(7)
    x = rng.normal(size=5000)
    assert effective_sample_size(x) == pytest.approx(5000, rel=0.1)
    assert effective_sample_size(x) <= 5000


def test_effective_sample_size_unknown_method():
    with pytest.raises(InvalidParameter, match="n_eff method"):
        effective_sample_size(np.arange(10.0), "geyer")


def test_aware_pvalue_exceeds_classical_for_autocorrelated_signals():
    rng = np.random.default_rng(8)
    m, c = _ar1(0.98, 4000, rng), _ar1(0.98, 4000, rng)
    r = kolmogorov_smirnov(m, c)
    assert r.n_eff_measured < 400 and r.n_eff_simulated < 400
    assert r.p_eff > r.p
    assert r.p < 1e-6  # the classical test "rejects" two realisations of one process


def test_area_metric_matches_wasserstein_and_hand_values():
    rng = np.random.default_rng(9)
    m, c = rng.normal(size=500), rng.gamma(2.0, size=300)
    assert area_validation_metric(m, c) == pytest.approx(scipy.stats.wasserstein_distance(m, c), rel=1e-12)
    # hand: F_m steps 0→½ at 0, →1 at 1; F_c at 2 and 3. |F_m − F_c| = ½ on [0,1), 1 on [1,2),
    # ½ on [2,3): area = ½ + 1 + ½ = 2
    assert area_validation_metric([0.0, 1.0], [2.0, 3.0]) == pytest.approx(2.0, abs=1e-15)
    # a shift of the whole distribution by a gives area |a| (in the signal's unit)
    assert area_validation_metric(m, m + 0.37) == pytest.approx(0.37, rel=1e-12)


def test_anderson_darling_matches_scipy_and_flags_capped_pvalues():
    rng = np.random.default_rng(10)
    m, c = rng.normal(size=300), rng.normal(1.0, 1.0, size=300)
    with pytest.warns(UserWarning, match="p-value"):
        ref = scipy.stats.anderson_ksamp([m, c], variant="midrank")
    r = anderson_darling(m, c)
    assert r.statistic == pytest.approx(ref.statistic, rel=1e-12)
    assert r.p == pytest.approx(0.001) and r.p_capped  # clearly different: floored
    same = anderson_darling(m, m[::-1].copy())
    assert same.p == pytest.approx(0.25) and same.p_capped


def test_anderson_darling_uncapped_pvalue_is_inside_table_range():
    rng = np.random.default_rng(11)
    m, c = rng.normal(size=400), rng.normal(0.17, 1.0, size=400)
    r = anderson_darling(m, c)
    ref = scipy.stats.anderson_ksamp([m, c], variant="midrank")
    assert not r.p_capped
    assert 0.001 < r.p < 0.25
    assert r.p == pytest.approx(ref.pvalue, rel=1e-12)
