"""EN 14363 processing (core.en14363): hand-computed values for every quantity, the
distance-based sliding mean against an independent integration, batch = per-section, and the
whole chain against a straightforward scipy implementation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate
import scipy.signal

from railval.core.en14363 import (
    QUANTILE_METHOD,
    evaluate_batch,
    evaluate_section,
    percentile,
    sliding_mean_distance,
)
from railval.core.errors import InvalidSignal
from railval.core.filters import BANDPASS_HZ, design
from railval.core.types import WHEEL_POSITIONS, SectionInfo, SignalSet

FS = 200.0


def _bp_gain(f, order=4, fs=FS):
    """Forward–backward amplitude gain of the band-pass (see tests/test_filters.py)."""
    w1, w2 = (np.tan(np.pi * x / fs) for x in BANDPASS_HZ)
    w = np.tan(np.pi * f / fs)
    x = (w * w - w1 * w2) / (w * (w2 - w1))
    return 1.0 / (1.0 + x ** (2 * order))


# ---------------------------------------------------------------- hand-computed section
# 40 s at 200 Hz, constant 20 m/s → distance 0.1 m per sample. Evaluated 299.95–499.95 m:
# samples k = 3000 … 4999 (n = 2000), 15 s run-in and run-out (the band-pass settles in
# ≈ 2.4 s, the low-pass in ≈ 0.1 s, so the low-frequency test signals pass unchanged).
# inverted-CDF percentiles of 2000 sorted samples: 0.15 % → rank ceil(3) = 3 (index 2),
# 50 % → rank 1000 (index 999), 99.85 % → rank ceil(1997) = 1997 (index 1996).
N = 8000
K = np.arange(N)
T = K / FS
D = 0.1 * K
SEC = SectionInfo("H1", 400.0, 100.0, 72.0, 3, 299.95, 499.95)


def _hand_set() -> SignalSet:
    ch = {
        "Y_w1L": -40.0 + 2.0 * T,          # ramp: −10 … +9.99 kN in the evaluated part
        "Q_w1L": 80.0 + 0.5 * T,
        "Y_w1R": np.full(N, 12.0),
        "Q_w1R": np.full(N, 60.0),
        "ay_cb_b1": 0.5 * np.sin(2 * np.pi * 2.0 * T),   # 2 Hz, 100 samples per period
        "ay_cb_b2": np.zeros(N),
        "az_cb_b1": 0.3 * np.cos(2 * np.pi * 1.0 * T),   # 1 Hz, 200 samples per period
        "az_cb_b2": np.zeros(N),
    }
    return SignalSet(FS, T.copy(), D.copy(), ch)


@pytest.fixture(scope="module")
def hand():
    return evaluate_section(_hand_set(), SEC)


def test_y_quantities_by_hand(hand):
    # median index 999 → k = 3999, t = 19.995 s: −40 + 39.99 = −0.01 kN (sign kept)
    assert hand[("Y_qst", "w1L")] == pytest.approx(-0.01, abs=1e-9)
    # 0.15 %: k = 3002 → −40 + 30.02 = −9.98; 99.85 %: k = 4996 → −40 + 49.96 = 9.96
    assert hand[("Y_max", "w1L")] == pytest.approx(9.98, abs=1e-9)
    assert hand[("Y_qst", "w1R")] == pytest.approx(12.0, abs=1e-9)
    assert hand[("Y_max", "w1R")] == pytest.approx(12.0, abs=1e-9)


def test_q_quantities_by_hand(hand):
    assert hand[("Q_qst", "w1L")] == pytest.approx(80.0 + 0.5 * 19.995, abs=1e-9)
    assert hand[("Q_max", "w1L")] == pytest.approx(80.0 + 0.5 * 24.98, abs=1e-9)
    assert hand[("Q_qst", "w1R")] == pytest.approx(60.0, abs=1e-9)
    assert hand[("Q_max", "w1R")] == pytest.approx(60.0, abs=1e-9)


def test_yq_quantities_by_hand(hand):
    # Y/Q of w1L increases monotonically (d/dt ∝ 2·Q − 0.5·Y = 180 > 0): median at k = 3999
    assert hand[("YQ_qst", "w1L")] == pytest.approx(-0.01 / (80.0 + 0.5 * 19.995), abs=1e-12)
    assert hand[("YQ_qst", "w1R")] == pytest.approx(0.2, abs=1e-12)
    assert hand[("YQ_max", "w1R")] == pytest.approx(0.2, abs=1e-12)
    # YQ_max of w1L: sliding means by numerical quadrature of the ratio over x (independent)
    ratio = lambda x: (-40.0 + 2.0 * x / 20) / (80.0 + 0.5 * x / 20)
    centres = 300.95 + 0.5 * np.arange(397)
    means = np.array([scipy.integrate.quad(ratio, c - 1, c + 1)[0] / 2 for c in centres])
    # 397 centres: 0.15 % → rank ceil(0.5955) = 1, 99.85 % → rank 397
    expected = max(abs(means.min()), abs(means.max()))
    assert hand[("YQ_max", "w1L")] == pytest.approx(expected, rel=1e-7)


def test_sumy_quantities_by_hand(hand):
    # ΣY_1 = Y_w1L + Y_w1R = −28 + 2t = −28 + 0.1·x: median at t = 19.995 s → 11.99 kN
    assert hand[("SumY_qst", "ws1")] == pytest.approx(11.99, abs=1e-9)
    # sliding mean of a linear function = value at the centre; centres 300.95 … 498.95 m
    # → extremes −28 + 30.095 = 2.095 and −28 + 49.895 = 21.895 kN
    assert hand[("SumY_max", "ws1")] == pytest.approx(21.895, abs=1e-9)


def test_acceleration_quantities_by_hand(hand):
    g2, g1 = _bp_gain(2.0), _bp_gain(1.0)
    # 20 whole periods of a sampled sine: rms = A/√2 exactly; 99.85 % value is a crest (1.0).
    # Tolerance 1e-6: the band-pass poles lie close to z = 1 (0.4 Hz at 200 Hz), so rounding
    # of the SOS coefficients moves the realised gain by ~1e-8 from the closed form.
    assert hand[("ay_rms", "b1")] == pytest.approx(0.5 * g2 / np.sqrt(2), rel=1e-6)
    assert hand[("ay_max", "b1")] == pytest.approx(0.5 * g2, rel=1e-6)
    assert hand[("az_rms", "b1")] == pytest.approx(0.3 * g1 / np.sqrt(2), rel=1e-6)
    assert hand[("az_max", "b1")] == pytest.approx(0.3 * g1, rel=1e-6)
    assert hand[("ay_rms", "b2")] == 0.0 and hand[("az_max", "b2")] == 0.0


def test_keys_provenance_and_no_warning(hand):
    assert set(hand) == {
        (q, p) for q in ("Y_qst", "Y_max", "Q_qst", "Q_max", "YQ_qst", "YQ_max")
        for p in ("w1L", "w1R")} | {("SumY_qst", "ws1"), ("SumY_max", "ws1")} | {
        (q, b) for q in ("ay_rms", "az_rms", "ay_max", "az_max") for b in ("b1", "b2")}
    steps = hand.provenance[("YQ_max", "w1L")]
    assert steps[0].startswith("Butterworth low-pass 20 Hz, order 4")
    assert any("sliding mean over 2 m every 0.5 m" in s for s in steps)
    assert any(QUANTILE_METHOD in s for s in steps)
    assert "band-pass 0.4–10 Hz" in hand.provenance[("ay_rms", "b1")][0]
    assert "2000 samples" in hand.provenance[("Y_qst", "w1L")][-3]
    assert hand.warnings == []
    doc = hand.to_dict()
    assert doc["section"] == "H1" and len(doc["values"]) == len(hand)
    assert set(hand.to_pandas().columns) >= {"quantity", "position", "value", "unit"}


def test_short_run_in_warns():
    sec = SectionInfo("H2", 0.0, 0.0, 72.0, 1, 20.0, 499.95)  # 1 s run-in
    out = evaluate_section(_hand_set(), sec)
    assert any("run-in" in w and "band-pass" in w and "section H2" in w for w in out.warnings)
    assert not any("low-pass" in w for w in out.warnings)  # 1 s > low-pass settling 0.1 s


def test_percentile_definition_is_inverse_empirical_cdf():
    x = np.array([5.0, 1.0, 4.0, 2.0, 3.0, 6.0])
    # F_n jumps by 1/6 per sample; the 50 % value is the smallest x with F_n(x) ≥ 0.5 → 3
    assert percentile(x, 0.5) == 3.0
    assert percentile(x, 0.9985) == 6.0 and percentile(x, 0.0015) == 1.0


# ---------------------------------------------------------------- sliding mean on distance
def test_sliding_mean_variable_speed_against_quadrature():
    rng = np.random.default_rng(3)
    n = 1500
    speed = 15.0 + 10.0 * np.sin(np.linspace(0, 3 * np.pi, n)) ** 2   # 15–25 m/s
    dist = np.concatenate([[0.0], np.cumsum(speed[1:] / FS)])
    values = rng.standard_normal((2, n)).cumsum(axis=1)
    centres, means = sliding_mean_distance(values, dist, 20.0, 90.0)
    assert centres[0] == 21.0 and centres[-1] <= 89.0 and np.allclose(np.diff(centres), 0.5)
    for row in range(2):
        f = lambda x, r=row: np.interp(x, dist, values[r])
        for j in range(0, centres.size, 17):
            c = centres[j]
            pts = dist[(dist > c - 1) & (dist < c + 1)]
            ref = scipy.integrate.quad(f, c - 1, c + 1, points=pts, limit=200)[0] / 2.0
            assert means[row, j] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_sliding_mean_range_errors():
    d = np.linspace(0, 10, 101)
    with pytest.raises(InvalidSignal, match="shorter than the 2.0 m sliding window"):
        sliding_mean_distance(np.ones(101), d, 3.0, 4.5)
    with pytest.raises(InvalidSignal, match="exceeds the distance axis"):
        sliding_mean_distance(np.ones(101), d, 3.0, 12.0)


# ---------------------------------------------------------------- against a scipy chain
def _random_set(seed: int, n: int, speed_scatter: float = 0.1) -> SignalSet:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    v = 20.0 * (1 + speed_scatter * np.sin(2 * np.pi * t / 17.0))
    d = np.concatenate([[0.0], np.cumsum(v[1:] / FS)])
    ch = {}
    for p in WHEEL_POSITIONS:
        ch[f"Y_{p}"] = 10 * rng.standard_normal() + 3 * rng.standard_normal(n)
        ch[f"Q_{p}"] = 75 + 5 * rng.standard_normal(n)
    for k in ("ay", "az"):
        for b in ("b1", "b2"):
            ch[f"{k}_cb_{b}"] = 0.3 * rng.standard_normal(n)
    return SignalSet(FS, t, d, ch)


def _reference_values(ss: SignalSet, sec: SectionInfo) -> dict:
    """Straightforward chain: scipy sosfiltfilt per channel, np.quantile per value, sliding
    mean by dense resampling on a 1 mm distance grid (trapezoid)."""
    lp = design(FS, "lowpass", 4).sos
    bp = design(FS, "bandpass", 4).sos
    f = {c: scipy.signal.sosfiltfilt(bp if "_cb_" in c else lp, x) for c, x in ss.channels.items()}
    m = (ss.distance_m >= sec.eval_start_m) & (ss.distance_m <= sec.eval_end_m)

    def q(x, p):
        return np.quantile(x, p, method="inverted_cdf")

    def slide(x):
        centres = np.arange(sec.eval_start_m + 1, sec.eval_end_m - 1 + 1e-9, 0.5)
        out = []
        for c in centres:
            grid = np.linspace(c - 1, c + 1, 2001)
            out.append(scipy.integrate.trapezoid(np.interp(grid, ss.distance_m, x), grid) / 2)
        return np.array(out)

    out = {}
    for p in WHEEL_POSITIONS:
        y, qq = f[f"Y_{p}"], f[f"Q_{p}"]
        out[("Y_qst", p)] = q(y[m], 0.5)
        out[("Y_max", p)] = max(abs(q(y[m], 0.0015)), abs(q(y[m], 0.9985)))
        out[("Q_qst", p)] = q(qq[m], 0.5)
        out[("Q_max", p)] = q(qq[m], 0.9985)
        out[("YQ_qst", p)] = q((y / qq)[m], 0.5)
        s = slide(y / qq)
        out[("YQ_max", p)] = max(abs(q(s, 0.0015)), abs(q(s, 0.9985)))
    for w in range(1, 5):
        sy = f[f"Y_w{w}L"] + f[f"Y_w{w}R"]
        out[("SumY_qst", f"ws{w}")] = q(sy[m], 0.5)
        s = slide(sy)
        out[("SumY_max", f"ws{w}")] = max(abs(q(s, 0.0015)), abs(q(s, 0.9985)))
    for k in ("ay", "az"):
        for b in ("b1", "b2"):
            x = f[f"{k}_cb_{b}"][m]
            out[(f"{k}_rms", b)] = np.sqrt(np.mean(x**2))
            out[(f"{k}_max", b)] = max(abs(q(x, 0.0015)), abs(q(x, 0.9985)))
    return out


def test_chain_equals_straightforward_scipy_chain():
    ss = _random_set(1, 6000)
    sec = SectionInfo("R1", 500.0, 120.0, 72.0, 3, 200.0, 380.0)
    got = evaluate_section(ss, sec)
    ref = _reference_values(ss, sec)
    assert set(got) == set(ref)
    for key, val in ref.items():
        # sliding means: the 1 mm trapezoid reference is exact to ~1e-7 of the signal scale
        tol = 1e-6 if key[0] in ("YQ_max", "SumY_max") else 1e-10
        assert got[key] == pytest.approx(val, rel=tol, abs=tol), key


def test_batch_equals_per_section():
    sets = [_random_set(s, n) for s, n in ((2, 5000), (3, 5000), (4, 6200))]
    secs = [SectionInfo(f"B{i}", 0.0, 0.0, 72.0, 1, 150.0, 300.0 + 10 * i) for i in range(3)]
    batch = evaluate_batch(sets, secs)
    for ss, sec, got in zip(sets, secs, batch):
        single = evaluate_section(ss, sec)
        assert got.section_id == sec.id
        assert dict(got) == dict(single)


@pytest.mark.parametrize("mutate,match", [
    (lambda ss, sec: (ss, SectionInfo("E", 0, 0, 1, 1, 100.0, 1e6)), "exceeds the recorded"),
    (lambda ss, sec: (SignalSet(ss.fs, ss.time_s, ss.distance_m[::-1].copy(), ss.channels),
                      sec), "strictly increasing"),
    (lambda ss, sec: (SignalSet(ss.fs, ss.time_s, ss.distance_m,
                                {**ss.channels, "Y_w2L": np.r_[np.nan, ss.channels["Y_w2L"][1:]]}),
                      sec), "non-finite"),
    (lambda ss, sec: (SignalSet(ss.fs, ss.time_s, ss.distance_m,
                                {**ss.channels, "Q_w1L": ss.channels["Q_w1L"] * 0}), sec),
     "Q_w1L is exactly 0"),
    (lambda ss, sec: (SignalSet(ss.fs, ss.time_s, ss.distance_m,
                                {**ss.channels, "Y_w1L": ss.channels["Y_w1L"][:-1]}), sec),
     "channel Y_w1L has shape"),
])
def test_invalid_inputs_raise(mutate, match):
    ss, sec = mutate(_random_set(5, 4000), SectionInfo("E", 0, 0, 1, 1, 150.0, 300.0))
    with pytest.raises(InvalidSignal, match=match):
        evaluate_section(ss, sec)


def test_quantity_trace_is_the_signal_each_quantity_is_evaluated_on():
    """The plotted trace of a quantity: Y/Q formed from filtered Y and Q, ΣY per wheelset,
    the 2 m sliding means where used; its marked statistic equals the evaluation's value."""
    from railval.core.en14363 import quantity_trace

    ss = _random_set(1, 6000)
    sec = SectionInfo("R1", 500.0, 120.0, 72.0, 3, 200.0, 380.0)
    got = evaluate_section(ss, sec)
    for (quantity, position), value in got.items():
        tr = quantity_trace(ss, sec, quantity, position)
        assert tr.value == pytest.approx(value, rel=1e-9, abs=1e-12), (quantity, position)
        assert (tr.sliding_means is not None) == (quantity in ("YQ_max", "SumY_max"))
    yq = quantity_trace(ss, sec, "YQ_qst", "w1L")
    y = quantity_trace(ss, sec, "Y_qst", "w1L")
    q = quantity_trace(ss, sec, "Q_qst", "w1L")
    np.testing.assert_allclose(yq.values, y.values / q.values, rtol=1e-12)
    assert set(yq.marks) == {"50 % value"}
    sumy = quantity_trace(ss, sec, "SumY_max", "ws1")
    yr = quantity_trace(ss, sec, "Y_qst", "w1R")
    np.testing.assert_allclose(sumy.values, y.values + yr.values, rtol=1e-12)
    assert set(sumy.marks) == {"0.15 % value", "99.85 % value"}
    assert max(abs(v) for v in sumy.marks.values()) == pytest.approx(sumy.value)
    assert sumy.sliding_centres_m[0] == pytest.approx(201.0)  # first 2 m window centre
    assert "ΣY ws1" in sumy.signal_label and "Y/Q w1L" in yq.signal_label
