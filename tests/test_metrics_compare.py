"""Synchronisation, common grid, ``compare`` / ``compare_signalsets`` and the registry."""

import json

import numpy as np
import pytest

from railval.core.errors import InvalidParameter, InvalidSignal, NotFound
from railval.core.metrics import (
    FAMILIES,
    METRICS,
    apply_lag,
    common_grid,
    compare,
    compare_signalsets,
    estimate_lag,
    metric_names,
    registry_table,
    sprague_geers,
)
from railval.core.types import SignalSet

FS = 100.0


def smooth_noise(n, seed, pad=0):
    rng = np.random.default_rng(seed)
    x = np.convolve(rng.normal(size=n + pad + 40), np.hanning(21), mode="same")
    return x[20: 20 + n + pad]


@pytest.mark.parametrize("lag", [0, 7, -23, 150])
def test_estimate_lag_recovers_integer_delay(lag):
    base = smooth_noise(2000, 1, pad=400)
    m = base[200:2200]
    c = base[200 - lag: 2200 - lag]  # c[i] = m[i − lag]: simulated delayed by `lag`
    r = estimate_lag(m, c, FS, max_lag_s=2.0)
    assert r.lag_samples == lag and r.lag_s == pytest.approx(lag / FS)
    ms, cs = apply_lag(m, c, r.lag_samples)
    np.testing.assert_array_equal(ms, cs)


def test_lag_outside_window_is_flagged():
    base = smooth_noise(2000, 2, pad=600)
    m, c = base[300:2300], base[0:2000]  # lag 300 samples = 3 s > 2 s window
    r = estimate_lag(m, c, FS, max_lag_s=2.0)
    assert abs(r.lag_samples) <= 200
    assert r.max_lag_samples == 200


def test_subsample_refinement_of_fractional_delay():
    t = np.arange(4000) / 1000.0
    m = np.sin(2 * np.pi * 3 * t) + 0.5 * np.sin(2 * np.pi * 7.3 * t)
    delay = 0.0123  # s = 12.3 samples
    c = np.sin(2 * np.pi * 3 * (t - delay)) + 0.5 * np.sin(2 * np.pi * 7.3 * (t - delay))
    r = estimate_lag(m, c, 1000.0, max_lag_s=0.05, subsample=True)
    assert r.refined and r.lag_s == pytest.approx(delay, abs=0.05e-3)
    assert estimate_lag(m, c, 1000.0, max_lag_s=0.05).lag_samples == 12


def test_sync_parameters_validated():
    with pytest.raises(InvalidParameter, match="max_lag_s"):
        estimate_lag(np.ones(10), np.ones(10), FS, max_lag_s=-1)
    with pytest.raises(InvalidParameter, match="fs"):
        estimate_lag(np.ones(10), np.ones(10), 0.0)


def test_common_grid_resamples_and_says_so():
    t_m = np.arange(1000) / 100.0
    t_c = 0.05 + np.arange(2000) / 200.0
    g = common_grid(np.sin(t_m), np.sin(t_c), 100.0, 200.0, t0_simulated=0.05)
    assert g.resampled and "linear interpolation" in g.note
    assert g.fs == 100.0 and g.t0 == pytest.approx(0.05)
    np.testing.assert_allclose(g.simulated, g.measured, atol=2e-5)  # linear interp error ≤ h²/8
    same = common_grid(np.ones(10), np.ones(12), 100.0)
    assert not same.resampled and same.truncated and len(same) == 10


def test_common_grid_without_overlap_raises():
    with pytest.raises(InvalidSignal, match="overlap"):
        common_grid(np.ones(10), np.ones(10), 10.0, t0_simulated=5.0)


def test_compare_reports_raw_and_synced():
    base = smooth_noise(3000, 3, pad=100)
    m = base[50:3050]
    c = 1.2 * base[10:3010]  # gain 1.2, delay 40 samples = 0.4 s
    r = compare(m, c, FS, unit="kN")
    assert r.lag_s == pytest.approx(0.4)
    assert r.raw["sg_M"] == pytest.approx(sprague_geers(m, c).M)
    assert r.raw["sg_P"] > 0.05
    assert r.synced["sg_P"] == pytest.approx(0.0, abs=1e-6)
    assert r.synced["sg_M"] == pytest.approx(0.2, abs=1e-9)
    assert r.n == 3000 and r.n_synced == 2960
    d = r.to_dict()
    json.dumps(d, allow_nan=False)
    assert set(d["raw"]) == set(metric_names()) == set(d["synced"])
    assert d["lag_s"] == pytest.approx(0.4)
    table = r.to_pandas()
    assert table.loc["area", "unit"] == "kN" and list(table.columns) == ["label", "unit", "raw", "synced"]


def test_compare_family_selection():
    m = smooth_noise(500, 4)
    r = compare(m, 0.9 * m, FS, families=["sprague_geers", "area"])
    assert set(r.raw) == {"sg_M", "sg_P", "sg_C", "area"}
    with pytest.raises(InvalidParameter, match="unknown metric family"):
        compare(m, m, FS, families=["nope"])


def _signalset(fs, n, channels, t0=0.0):
    t = t0 + np.arange(n) / fs
    return SignalSet(fs=fs, time_s=t, distance_m=t * 20.0, channels=channels)


def test_compare_signalsets_rows_per_channel():
    n = 4000
    fs = 200.0
    t = np.arange(n + 200) / fs
    y = np.sin(2 * np.pi * 0.5 * t) + 0.3 * np.sin(2 * np.pi * 2.1 * t)
    q = 50 + 5 * np.sin(2 * np.pi * 1.3 * t)
    meas = _signalset(fs, n, {"Y_w1L": y[100:100 + n], "Q_w1L": q[100:100 + n],
                              "ay_cb_b1": np.zeros(n)})
    sim = _signalset(fs, n, {"Y_w1L": 1.1 * y[80:80 + n], "Q_w1L": q[100:100 + n],
                             "ay_cb_b1": np.zeros(n), "Y_w2L": y[:n]})
    df = compare_signalsets(meas, sim, families=["sprague_geers", "ks"])
    assert list(df["channel"]) == ["Y_w1L", "Q_w1L", "ay_cb_b1"]
    row = df.set_index("channel").loc["Y_w1L"]
    assert row["lag_s"] == pytest.approx(0.1) and row["error"] == ""
    assert row["sg_P_sync"] < 0.01 < row["sg_P"]
    assert row["sg_M_sync"] == pytest.approx(0.1, abs=0.01)  # 20 Hz low-pass leaves it unchanged
    zero = df.set_index("channel").loc["ay_cb_b1"]
    assert "identically zero" in zero["error"] and np.isnan(zero["sg_M"])
    with pytest.raises(NotFound, match="Y_w2L"):
        compare_signalsets(meas, sim, channels=["Y_w2L"])


def test_compare_signalsets_resamples_simulation():
    fs_m, fs_c, n = 200.0, 500.0, 4000
    tm = np.arange(n) / fs_m
    tc = np.arange(int(n * fs_c / fs_m)) / fs_c
    meas = _signalset(fs_m, n, {"Y_w1L": np.sin(2 * np.pi * 0.7 * tm)})
    sim = _signalset(fs_c, tc.size, {"Y_w1L": np.sin(2 * np.pi * 0.7 * tc)})
    df = compare_signalsets(meas, sim, families=["sprague_geers"])
    assert bool(df.loc[0, "resampled"])
    assert df.loc[0, "sg_C"] < 1e-3


def test_registry_is_complete_and_consistent():
    names = [m for f in FAMILIES.values() for m in f.metrics]
    assert sorted(names) == sorted(METRICS)
    for info in METRICS.values():
        assert info.family in FAMILIES and info.source and info.description and info.range
    rows = registry_table()
    json.dumps(rows)
    assert {r["name"] for r in rows} == set(METRICS)


def test_lowpass_other_cutoff_matches_scipy_and_en_cutoff_uses_en_filter():
    import scipy.signal

    from railval.core import filters
    from railval.core.metrics import lowpass

    rng = np.random.default_rng(20)
    x = rng.normal(size=(2, 3000))
    sos = scipy.signal.butter(4, 5.0, btype="lowpass", fs=200.0, output="sos")
    np.testing.assert_allclose(lowpass(x, 200.0, 5.0), scipy.signal.sosfiltfilt(sos, x, axis=-1),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(lowpass(x, 200.0, 20.0), filters.filtfilt_rows(x, 200.0, "lowpass", 4))
    with pytest.raises(InvalidParameter, match="cut-off"):
        lowpass(x, 200.0, 150.0)


@pytest.mark.parametrize(("f0", "amp"), [(1.0, 1.0), (1.0, 0.9), (0.5, 1.3), (2.0, 0.8)])
def test_in_phase_periodic_pair_keeps_lag_zero(f0, amp):
    # c = A·m, periodic, 20 s at 200 Hz: every whole-period lag correlates to 1 up to
    # rounding noise; the tie rule keeps lag 0 and nothing is trimmed (the old first-maximum
    # rule returned −400 samples = the −2 s bound for f0 = 1 Hz)
    fs = 200.0
    t = np.arange(int(20 * fs)) / fs
    m = np.sin(2 * np.pi * f0 * t) + 0.3 * np.sin(2 * np.pi * 3 * f0 * t + 0.4)
    c = amp * m
    r = estimate_lag(m, c, fs, max_lag_s=2.0)
    assert r.lag_samples == 0 and not r.at_bound and r.reliable
    res = compare(m, c, fs, families=["sprague_geers"])
    assert res.n_synced == res.n == t.size
    assert res.synced == res.raw
    assert res.raw["sg_M"] == pytest.approx(amp - 1, abs=1e-12)


def test_best_lag_index_prefers_smallest_lag_within_tolerance():
    from railval.core.metrics.sync import best_lag_index

    lags = np.arange(-3, 4)
    rho = np.array([0.9, 1.0, 0.2, 1.0 - 1e-12, 0.3, 1.0 + 5e-10, 0.1])
    assert lags[best_lag_index(lags, rho)] == 0  # all three maxima lie within 1e-9
    assert lags[best_lag_index(lags, rho, tol=0.0)] == 2  # strict: the largest
    rho2 = np.array([0.9, 1.0, 0.2, 0.5, 0.3, 1.0, 0.1])
    assert lags[best_lag_index(lags, rho2)] == -2  # −k before +k


def test_lag_near_the_search_bound_is_flagged_unreliable():
    base = smooth_noise(2000, 3, pad=400)
    m = base[200:2200]
    for lag, reliable in ((150, True), (189, True), (191, False), (-195, False)):
        c = base[200 - lag: 2200 - lag]
        r = estimate_lag(m, c, FS, max_lag_s=2.0)  # K = 200; 5 % of K = 10 samples
        assert r.lag_samples == lag
        assert r.reliable is reliable and r.near_bound is (not reliable)
        d = compare(m, c, FS, families=["sprague_geers"]).to_dict()
        assert d["lag_reliable"] is reliable and d["lag_near_bound"] is (not reliable)
        assert any("unreliable" in n for n in d["notes"]) is (not reliable)
