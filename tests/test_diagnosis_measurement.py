"""Measurement-side candidates sign, swap and shift (docs/diagnosis.md "Sign, position swap and
time shift"): the pieces on their own — the lag fitted from the cross-correlation, which
channels' sign the EN quantities can see, which channels a swap exchanges, the discrete
candidate's fit — without a database."""

from __future__ import annotations

import numpy as np
import pytest

from railval.core.diagnosis.measurement import (
    discrete_family,
    estimate_lag,
    section_lag,
    shifted,
    sign_blind,
    swap_pairs,
    swapped_bands,
)
from railval.core.types import SignalSet


def _smooth_noise(n: int, fs: float, seed: int, cut_hz: float = 3.0) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng(seed)
    return sosfiltfilt(butter(4, cut_hz, fs=fs, output="sos"), rng.standard_normal(n))


def test_the_lag_is_fitted_to_a_fraction_of_a_sample():
    fs = 200.0
    x = _smooth_noise(4000, fs, 1, cut_hz=20.0)  # a sharp correlation peak (a 3 Hz one is good to ~0.15 sample)
    late = shifted(x, -0.0365, fs)  # x'(t) = x(t − 0.0365): recorded 7.3 samples late
    lag, peak = estimate_lag(late, x, fs)
    assert lag == pytest.approx(0.0365, abs=0.1 / fs) and peak > 0.95
    # re-aligned, the record matches the original again (away from the held ends)
    back = shifted(late, lag, fs)
    assert np.max(np.abs(back[100:-100] - x[100:-100])) < 0.05 * np.max(np.abs(x))  # linear interpolation, twice
    # an early record gives a negative lag; the integer-only answer would be off by 0.3 sample
    lag2, _ = estimate_lag(shifted(x, 0.0515, fs), x, fs)
    assert lag2 == pytest.approx(-0.0515, abs=0.1 / fs) and abs(lag2 * fs - round(lag2 * fs)) > 0.2


def _sets(lags: dict[str, float], fs: float = 200.0, n: int = 4000) -> tuple[SignalSet, SignalSet]:
    t = np.arange(n) / fs
    sim = {c: _smooth_noise(n, fs, k, cut_hz=10.0) for k, c in enumerate(lags)}
    meas = {c: shifted(x, -lags[c], fs) for c, x in sim.items()}
    mk = lambda ch: SignalSet(fs, t, 30.0 * t, ch)
    return mk(meas), mk(sim)


def test_a_section_lag_counts_only_when_its_channels_agree():
    meas, sim = _sets({"Y_w1L": 0.1, "Q_w1L": 0.1, "az_cb_b1": 0.1, "ay_cb_b1": 0.1})
    lag = section_lag(meas, sim)
    assert lag["consistent"] and lag["lag"] == pytest.approx(0.1, abs=0.5 / 200) and lag["spread"] < 1 / 200
    # one channel group recorded late is not a shift of the section
    meas, sim = _sets({"Y_w1L": 0.3, "Q_w1L": 0.3, "az_cb_b1": 0.0, "ay_cb_b1": 0.0})
    lag = section_lag(meas, sim)
    assert not lag["consistent"] and "disagree" in lag["reason"]
    # too few channels that correlate with the simulation
    meas, sim = _sets({"Y_w1L": 0.1, "Q_w1L": 0.1})
    assert "only 2 channel(s)" in section_lag(meas, sim)["reason"]


def test_a_reversed_sign_is_seen_only_by_the_quantities_that_keep_the_sign():
    # car body accelerations: r.m.s. and maximum of the magnitude — blind
    why = sign_blind("az_cb_b1", [("az_rms", "b1"), ("az_max", "b1")])
    assert why and "invisible" in why and "az_max, az_rms" in why
    # a guiding force: the signed median Y_qst and Y/Q see it; Y_max alone would not
    assert sign_blind("Y_w1L", [("Y_max", "w1L"), ("Y_qst", "w1L"), ("YQ_max", "w1L")]) is None
    assert "invisible" in sign_blind("Y_w1L", [("Y_max", "w1L")])
    # Q_max is the 99.85 % value, not a magnitude: a reversed Q is seen
    assert sign_blind("Q_w1L", [("Q_max", "w1L")]) is None
    assert "not a channel" in sign_blind("Y_w9L", [])


def test_swap_names_two_channels_or_two_positions():
    chans = ["Y_w1L", "Y_w1R", "Q_w1L", "Q_w1R", "az_cb_b1", "az_cb_b2", "ay_cb_b1", "ay_cb_b2"]
    assert swap_pairs("w1L", "w1R", chans) == [("Q_w1L", "Q_w1R"), ("Y_w1L", "Y_w1R")]
    assert swap_pairs("b1", "b2", chans) == [("ay_cb_b1", "ay_cb_b2"), ("az_cb_b1", "az_cb_b2")]
    assert swap_pairs("az_cb_b1", "az_cb_b2", chans) == [("az_cb_b1", "az_cb_b2")]
    # channels of different kinds, a channel with itself, absent positions: nothing
    assert swap_pairs("az_cb_b1", "ay_cb_b2", chans) == []
    assert swap_pairs("w1L", "w1L", chans) == [] and swap_pairs("w2L", "w2R", chans) == []
    bands = {"S01": {"az_cb_b1": np.array([1.0]), "az_cb_b2": np.array([2.0]), "ay_cb_b1": np.array([3.0])}}
    out = swapped_bands(bands, [("az_cb_b1", "az_cb_b2")])
    assert out["S01"]["az_cb_b1"][0] == 2.0 and out["S01"]["az_cb_b2"][0] == 1.0 and out["S01"]["ay_cb_b1"][0] == 3.0


def _toy(values: np.ndarray, zones=(1, 1, 1, 2, 2, 2)):
    """Evidence of one quantity component per section: ``values[s]`` = D_v/limit of section s."""
    from railval.core.diagnosis import section_evidence

    secs = [(f"S{k}", z) for k, z in enumerate(zones)]
    pairs = [{"section": s, "zone": 1, "quantity": "Y_qst", "position": "w1L", "D_norm": float(v)}
             for (s, _), v in zip(secs, values, strict=True)]
    return section_evidence(pairs, {}, {}, secs, value_key="D_norm"), secs, pairs


def test_a_discrete_candidate_is_judged_at_its_value_on_held_out_sections():
    from railval.core.diagnosis import diagnose_evidence, section_evidence

    rng = np.random.default_rng(3)
    base, secs, pairs = _toy(1.0 + 0.05 * rng.standard_normal(6))
    good = section_evidence([{**p, "D_norm": 0.05 * rng.standard_normal()} for p in pairs], {}, {}, secs,
                            value_key="D_norm", like=base)
    worse = section_evidence([{**p, "D_norm": 2.0} for p in pairs], {}, {}, secs, value_key="D_norm", like=base)
    fams = [discrete_family("sign Y_w1L", "sign", -1.0, good, half_width=0.01, title="reversed"),
            discrete_family("swap w1L w1R", "swap", 1.0, worse, half_width=0.01, title="swapped")]
    res = diagnose_evidence(base, fams, n_boot=50, folds=3)
    by = {c.name: c for c in res.candidates}
    sign = by["sign Y_w1L"]
    # fitted exactly at its value, not at a bound, explaining nearly all, on held-out sections too
    assert sign.fitted == pytest.approx(-1.0, abs=1e-9) and not sign.at_bound and sign.plausible
    assert sign.held_out_explained > 0.95 and sign.significant and res.verdict == "cause"
    assert sign.fitted_ci[0] >= -1.01 - 1e-9 and sign.fitted_ci[1] <= -0.99 + 1e-9
    # a correction that makes things worse explains nothing
    assert by["swap w1L w1R"].explained == 0.0 and by["swap w1L w1R"].held_out_explained == 0.0
    assert res.candidates[0].name == "sign Y_w1L"
