"""ISO/TS 18571 rating: sub-scores against closed forms, DTW against a plain dynamic program,
grades at the thresholds."""

import math

import numpy as np
import pytest

from railval.core.errors import InvalidParameter
from railval.core.metrics import ISOParameters, grade, iso18571
from railval.core.metrics.iso18571 import (
    corridor_score,
    dtw_cost,
    dtw_magnitude_error,
    phase_score,
    slope_error,
    smoothed_slope,
)

FS = 1000.0
T = np.arange(1000) / FS


def pulse(t0=0.3, width=0.05):
    return np.exp(-((T - t0) / width) ** 2)


def naive_dtw(x, y, radius):
    n = len(x)
    d = np.full((n + 1, n + 1), np.inf)
    d[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, n + 1):
            if abs(i - j) < radius:
                d[i, j] = (x[i - 1] - y[j - 1]) ** 2 + min(d[i - 1, j - 1], d[i - 1, j], d[i, j - 1])
    return d[n, n]


@pytest.mark.parametrize(
    ("rating", "expected"),
    [(1.0, "excellent"), (0.9400001, "excellent"), (0.94, "good"), (0.8000001, "good"),
     (0.80, "fair"), (0.5800001, "fair"), (0.58, "poor"), (0.0, "poor")],
)
def test_grades_at_thresholds(rating, expected):
    assert grade(rating) == expected


def test_grade_rejects_out_of_range():
    with pytest.raises(InvalidParameter, match="rating"):
        grade(1.5)


def test_identical_curves_rate_one():
    r = iso18571(pulse(), pulse(), FS)
    assert (r.corridor, r.phase, r.magnitude, r.slope, r.rating) == (1.0, 1.0, 1.0, 1.0, 1.0)
    assert r.grade == "excellent"


@pytest.mark.parametrize("curve", [pulse(), 20 * T * np.exp(-20 * T), np.sin(9 * T) * np.exp(-3 * T)])
def test_negative_curve_rates_poor(curve):
    r = iso18571(curve, -curve, FS)
    assert r.rating < 0.45 and r.grade == "poor"
    assert r.magnitude == 0.0  # e_M > ε_M = 0.5 for a mirrored curve


def test_corridor_closed_form():
    ref = np.ones(50)
    # |diff| below the inner corridor (0.05) → 1; above the outer (0.5) → 0
    assert corridor_score(ref, ref + 0.04) == 1.0
    assert corridor_score(ref, ref + 0.6) == 0.0
    # midway 0.275: ((0.5 − 0.275)/(0.5 − 0.05))² = 0.25
    assert corridor_score(ref, ref + 0.275) == pytest.approx(0.25, rel=1e-12)
    # half the samples inside, half midway → 0.625
    comp = ref + np.r_[np.zeros(25), np.full(25, 0.275)]
    assert corridor_score(ref, comp) == pytest.approx(0.625, rel=1e-12)
    # custom half-widths and exponent: a0 = 0.1, b0 = 0.3, kz = 1, diff 0.2 → 0.5
    assert corridor_score(ref, ref + 0.2, a0=0.1, b0=0.3, kz=1) == pytest.approx(0.5, rel=1e-12)


@pytest.mark.parametrize("shift", [0, 13, -40, 150])
def test_phase_score_of_shifted_pulse(shift):
    ref = pulse(0.5, 0.04)
    comp = pulse(0.5 + shift / FS, 0.04)  # delayed by `shift` samples
    r = iso18571(ref, comp, FS)
    assert r.shift_samples == shift
    assert r.phase == pytest.approx(1 - abs(shift) / (0.2 * len(T)), abs=1e-12)
    # after the shift the pulses coincide (up to the truncated tail): magnitude and slope ≈ 1
    assert r.magnitude > 0.99 and r.slope > 0.99


def test_phase_score_bounds():
    assert phase_score(0, 100) == 1.0
    assert phase_score(20, 100) == 0.0  # |n| ≥ 0.2 N
    assert phase_score(10, 100, kp=2) == pytest.approx(0.25)


@pytest.mark.parametrize("k", [0.8, 1.1, 1.6, 2.5, 3.5])
def test_slope_score_of_scaled_curve(k):
    # C = k·T: smoothed slopes scale by k, e_S = |k − 1|, E_S = max(0, (2 − |k − 1|)/2)
    ref = np.sin(7 * T) + T
    assert slope_error(ref, k * ref, 1 / FS) == pytest.approx(abs(k - 1), rel=1e-12)
    r = iso18571(ref, k * ref, FS)
    assert r.slope == pytest.approx(max(0.0, (2 - abs(k - 1)) / 2), abs=1e-12)


def test_smoothed_slope_of_a_line_is_exact():
    x = 3.0 * T + 1.0
    np.testing.assert_allclose(smoothed_slope(x, 1 / FS), 3.0, rtol=1e-9)


@pytest.mark.parametrize("radius_frac", [0.05, 0.2, 1.0])
def test_dtw_matches_plain_dynamic_program(radius_frac):
    rng = np.random.default_rng(12)
    x, y = rng.normal(size=40), rng.normal(size=40)
    radius = 40 if radius_frac >= 1 else max(1, math.ceil(radius_frac * 40))
    assert dtw_cost(y, x, radius_frac) == pytest.approx(naive_dtw(x, y, radius), rel=1e-12)


def test_dtw_without_warping_is_pointwise_error():
    rng = np.random.default_rng(13)
    ref, comp = rng.normal(size=100), rng.normal(size=100)
    # window below 1/N → radius 1: the path is the diagonal
    e = dtw_magnitude_error(ref, comp, window=1e-6)
    assert e == pytest.approx(np.sum(np.abs(comp - ref)) / np.sum(np.abs(ref)), rel=1e-12)


def test_dtw_undoes_a_local_time_warp():
    # comparison = reference evaluated on a warped time axis that stays inside the band
    tau = T + 0.01 * np.sin(np.pi * T)
    ref, comp = pulse(0.4), np.exp(-((tau - 0.4) / 0.05) ** 2)
    assert dtw_magnitude_error(ref, comp, 0.1) < 0.05 < dtw_magnitude_error(ref, comp, 1e-6)


def test_parameters_validated():
    with pytest.raises(InvalidParameter, match="b0"):
        ISOParameters(a0=0.5, b0=0.4)
    with pytest.raises(InvalidParameter, match="weights"):
        ISOParameters(weights=(0.5, 0.5, 0.5, 0.5))
    with pytest.raises(InvalidParameter, match="max_shift"):
        ISOParameters(max_shift=1.0)


def test_custom_weights_change_rating():
    ref, comp = pulse(), 1.3 * pulse(0.31)
    r = iso18571(ref, comp, FS, ISOParameters(weights=(1.0, 0.0, 0.0, 0.0)))
    assert r.rating == pytest.approx(r.corridor, abs=1e-12)


def test_in_phase_periodic_curves_keep_zero_shift():
    # 50 Hz, c = 0.9·m with m a 1 Hz sine over 10 s: shifts by whole periods (±50 samples)
    # correlate to 1 up to ~1e-16 rounding noise; the old first-maximum rule chose −50
    # (E_P = 0.9). Zero shift must stay: E_P = 1 and the rating follows by hand.
    fs = 50.0
    t = np.arange(500) / fs
    m = np.sin(2 * np.pi * t)
    c = 0.9 * m
    r = iso18571(m, c, fs)
    assert r.shift_samples == 0 and r.phase == 1.0
    # corridor by hand: |c − m| = 0.1|m|, T_norm = max|m|, δ_i = 0.05 T_norm, δ_o = 0.5 T_norm
    tn = np.max(np.abs(m))
    diff = 0.1 * np.abs(m)
    z = np.mean(np.where(diff < 0.05 * tn, 1.0, ((0.5 * tn - diff) / (0.45 * tn)) ** 2))
    # slope: C' = 0.9 T' exactly → e_S = 0.1, E_S = (2 − 0.1)/2 = 0.95
    # magnitude: DTW on the unshifted curves (DTW itself is checked against a plain DP above)
    e_m = dtw_magnitude_error(m, c, 0.1)
    expected = 0.4 * z + 0.2 * 1.0 + 0.2 * (0.5 - e_m) / 0.5 + 0.2 * 0.95
    assert r.corridor == pytest.approx(z, rel=1e-12)
    assert r.slope == pytest.approx(0.95, rel=1e-12)
    assert r.rating == pytest.approx(expected, rel=1e-12)


def test_phase_shift_prefers_zero_unless_beaten_by_more_than_the_tolerance():
    from railval.core.metrics.iso18571 import phase_shift

    # two pulses 100 samples apart, equal heights: the comparison repeats the reference
    # shifted by one pulse spacing; a true improvement (pulse moved by 13) still wins
    ref = pulse(0.3, 0.03) + pulse(0.4, 0.03)
    assert phase_shift(ref, ref) == 0
    moved = pulse(0.313, 0.03) + pulse(0.413, 0.03)
    assert phase_shift(ref, moved) == 13
