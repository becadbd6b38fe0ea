"""Property tests (hypothesis) of the curve-comparison metrics."""

import numpy as np
import scipy.signal
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from railval.core.metrics import (
    area_validation_metric,
    compare,
    estimate_lag,
    iso18571,
    kolmogorov_smirnov,
    russell,
    sprague_geers,
)

SETTINGS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FS = 100.0


def smooth(seed, n, width=15):
    rng = np.random.default_rng(seed)
    x = np.convolve(rng.normal(size=n + 2 * width), np.hanning(width), mode="same")
    return x[width: width + n] + 0.1 * np.sin(np.arange(n) / 13.0)


seeds = st.integers(0, 2**31 - 1)
lengths = st.integers(64, 600)


@SETTINGS
@given(seed=seeds, n=lengths)
def test_identical_signals_agree_perfectly(seed, n):
    x = smooth(seed, n)
    sg = sprague_geers(x, x)
    assert abs(sg.M) < 1e-12 and sg.P < 1e-6
    ru = russell(x, x)
    assert abs(ru.RM) < 1e-12 and ru.RP < 1e-6
    assert kolmogorov_smirnov(x, x).D == 0.0
    assert area_validation_metric(x, x) == 0.0
    assert iso18571(x, x, FS).rating == 1.0


@SETTINGS
@given(seed=seeds, n=lengths, k=st.floats(0.05, 20.0))
def test_scaling_gives_sprague_geers_m_equal_k_minus_one(seed, n, k):
    x = smooth(seed, n)
    r = sprague_geers(x, k * x)
    assert abs(r.M - (k - 1)) < 1e-9 * max(1.0, k)
    assert r.P < 1e-6


@SETTINGS
@given(seed=seeds, n=st.integers(300, 1500), lag=st.integers(-150, 150))
def test_synchronisation_undoes_a_shift_within_the_window(seed, n, lag):
    base = smooth(seed, n + 400)
    m = base[200: 200 + n]
    c = base[200 - lag: 200 - lag + n]  # simulated delayed by `lag` samples
    assert estimate_lag(m, c, FS, max_lag_s=2.0).lag_samples == lag  # |lag| ≤ 150 < 200
    r = compare(m, c, FS, max_lag_s=2.0, families=["sprague_geers"])
    assert r.synced["sg_P"] < 1e-6 and abs(r.synced["sg_M"]) < 1e-12


@SETTINGS
@given(seed=seeds, phi=st.floats(0.95, 0.995), n=st.integers(1000, 4000))
def test_aware_pvalue_is_at_least_classical_for_autocorrelated_signals(seed, phi, n):
    rng = np.random.default_rng(seed)
    m = scipy.signal.lfilter([1.0], [1.0, -phi], rng.normal(size=n))
    c = scipy.signal.lfilter([1.0], [1.0, -phi], rng.normal(size=n))
    r = kolmogorov_smirnov(m, c)
    assert r.p_eff >= r.p
