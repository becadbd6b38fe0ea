"""core/psd.py: Welch PSD with Parseval and white-noise expectations computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.psd import welch_psd


def test_sine_power_integrates_to_half_amplitude_squared():
    # a sine of amplitude A has variance A²/2 (Parseval); 2 Hz lies on the 0.1 Hz grid of
    # 10 s segments, so the Hann leakage stays inside the integrated band
    fs, a = 200.0, 3.0
    t = np.arange(0, 120, 1 / fs)
    p = welch_psd(a * np.sin(2 * np.pi * 2.0 * t), fs, segment_s=10.0)
    df = p.frequency_hz[1] - p.frequency_hz[0]
    assert df == pytest.approx(0.1)
    assert p.density.sum() * df == pytest.approx(a * a / 2, rel=1e-3)
    assert p.frequency_hz[np.argmax(p.density)] == pytest.approx(2.0)


def test_white_noise_level_is_two_sigma_squared_over_fs():
    # one-sided density of white noise of variance σ²: 2σ²/fs (unit²/Hz); mean over bins,
    # 600 s of data: the relative scatter of the mean is well below 2 %
    rng = np.random.default_rng(1)
    fs, sigma = 100.0, 0.5
    p = welch_psd(rng.normal(0, sigma, int(600 * fs)), fs, segment_s=5.0)
    inner = p.density[1:-1]
    assert inner.mean() == pytest.approx(2 * sigma**2 / fs, rel=0.02)
    assert p.segment_s == pytest.approx(5.0)


def test_short_signal_uses_one_segment_and_to_dict():
    p = welch_psd(np.arange(100, dtype=float) % 7, 50.0, segment_s=10.0)
    assert p.segment_s == pytest.approx(2.0)  # 100 samples at 50 Hz
    d = p.to_dict()
    assert set(d) == {"frequency_hz", "density", "segment_s"} and len(d["density"]) == 51


@pytest.mark.parametrize(("values", "fs", "seg", "error", "text"), [
    (np.ones(4), 10.0, 1.0, InvalidSignal, "at least 8 samples"),
    (np.array([1.0] * 9 + [np.nan]), 10.0, 1.0, InvalidSignal, "NaN"),
    (np.ones(20), 0.0, 1.0, InvalidParameter, "fs must be"),
    (np.ones(20), 10.0, -1.0, InvalidParameter, "segment_s must be > 0 s, got -1.0"),
])
def test_bad_inputs_raise_with_the_bound(values, fs, seg, error, text):
    with pytest.raises(error, match=text):
        welch_psd(values, fs, segment_s=seg)
