"""Zero-phase Butterworth filters (core.filters).

Reference values: the digital Butterworth designed by the bilinear transform has the squared
magnitude |H|² = 1 / (1 + (Ω/Ω_c)^(2N)) with Ω = tan(π f/fs) (low-pass) and
1 / (1 + ((Ω² − Ω_0²)/(Ω·B))^(2N)) with Ω_0² = Ω_1·Ω_2, B = Ω_2 − Ω_1 (band-pass); the
forward–backward filter has amplitude gain |H|² and zero phase (Oppenheim & Schafer,
Discrete-Time Signal Processing, §7.1 and §5.1).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.filters import BANDPASS_HZ, LOWPASS_HZ, design, filtfilt_rows, settling_check

FS = 500.0


def _lp_gain(f, order, fs=FS):
    w = np.tan(np.pi * f / fs) / np.tan(np.pi * LOWPASS_HZ / fs)
    return 1.0 / (1.0 + w ** (2 * order))


def _bp_gain(f, order, fs=FS):
    w1, w2 = (np.tan(np.pi * x / fs) for x in BANDPASS_HZ)
    w = np.tan(np.pi * f / fs)
    x = (w * w - w1 * w2) / (w * (w2 - w1))
    return 1.0 / (1.0 + x ** (2 * order))


def _amp_phase(y, t, f):
    """Amplitude and phase of the f-component by least squares on sin/cos (whole periods)."""
    a = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    (s, c), *_ = np.linalg.lstsq(a, y, rcond=None)
    return np.hypot(s, c), np.arctan2(c, s)


@pytest.mark.parametrize("kind", ["lowpass", "bandpass"])
@pytest.mark.parametrize("order", [2, 4, 6])
def test_equals_scipy_sosfiltfilt(kind, order):
    rng = np.random.default_rng(order)
    x = rng.standard_normal((11, 3000))
    d = design(FS, kind, order)
    ref = scipy.signal.sosfiltfilt(d.sos, x, axis=-1)
    np.testing.assert_allclose(filtfilt_rows(x, FS, kind, order), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(filtfilt_rows(x[3], FS, kind, order), ref[3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind,f", [("lowpass", 2.0), ("lowpass", 8.0), ("bandpass", 2.0),
                                    ("bandpass", 4.0)])
def test_in_band_sinusoid_keeps_amplitude_and_phase(kind, f):
    t = np.arange(int(60 * FS)) / FS
    x = 1.7 * np.sin(2 * np.pi * f * t + 0.3)
    y = filtfilt_rows(x, FS, kind, 4)
    mid = slice(int(20 * FS), int(40 * FS))
    amp, phase = _amp_phase(y[mid], t[mid], f)
    gain = _lp_gain(f, 4) if kind == "lowpass" else _bp_gain(f, 4)
    assert gain > 0.99
    assert amp == pytest.approx(1.7 * gain, rel=1e-6)
    # zero phase: same phase as the input (least-squares phase of sin(ωt + 0.3))
    _, phase_in = _amp_phase(x[mid], t[mid], f)
    assert phase == pytest.approx(phase_in, abs=1e-6)


@pytest.mark.parametrize("order", [2, 4])
@pytest.mark.parametrize("kind,f", [("lowpass", 30.0), ("lowpass", 60.0), ("bandpass", 0.2),
                                    ("bandpass", 20.0)])
def test_out_of_band_attenuation_per_order(kind, f, order):
    t = np.arange(int(200 * FS)) / FS
    x = np.sin(2 * np.pi * f * t)
    y = filtfilt_rows(x, FS, kind, order)
    mid = slice(int(60 * FS), int(140 * FS))
    amp, _ = _amp_phase(y[mid], t[mid], f)
    expected = _lp_gain(f, order) if kind == "lowpass" else _bp_gain(f, order)
    assert expected < 0.5
    assert amp == pytest.approx(expected, rel=2e-3, abs=1e-7)


def test_designs_are_cached_per_fs_kind_order():
    assert design(FS, "lowpass", 4) is design(500, "lowpass", 4)
    assert design(FS, "lowpass", 4) is not design(FS, "lowpass", 2)
    assert design(FS, "bandpass", 4).sos.shape == (4, 6)  # order 2N band-pass
    assert design(FS, "lowpass", 4).sos.shape == (2, 6)


@pytest.mark.parametrize("args,match", [
    ((FS, "highpass", 4), "kind"),
    ((FS, "lowpass", 0), "order"),
    ((FS, "lowpass", 2.5), "order"),
    ((30.0, "lowpass", 4), "fs must exceed 40"),
])
def test_invalid_design_parameters(args, match):
    with pytest.raises(InvalidParameter, match=match):
        design(*args)


def test_too_short_signal_raises():
    with pytest.raises(InvalidSignal, match="padding"):
        filtfilt_rows(np.ones(10), FS, "lowpass", 4)


def test_settling_warning_when_run_in_is_short():
    t = np.arange(int(30 * FS)) / FS
    settle = design(FS, "bandpass", 4).settling_s
    assert 0.5 < settle < 10  # 0.4 Hz corner: seconds
    mask = (t >= settle / 2) & (t <= 30 - 2 * settle)
    warnings = settling_check(t, mask, FS, "bandpass", 4, section="S7")
    assert [w.side for w in warnings] == ["run-in"]
    msg = warnings[0].message
    assert "section S7" in msg and "run-in" in msg and f"{settle:.2f} s" in msg
    assert warnings[0].to_dict()["available_s"] == pytest.approx(t[mask][0])
    ok = (t >= 2 * settle) & (t <= 30 - 2 * settle)
    assert settling_check(t, ok, FS, "bandpass", 4) == []
    late = (t >= 2 * settle) & (t <= 30 - settle / 3)
    assert [w.side for w in settling_check(t, late, FS, "bandpass", 4)] == ["run-out"]


def test_settling_time_matches_impulse_response():
    d = design(FS, "lowpass", 4)
    h = np.abs(scipy.signal.sosfilt(d.sos, np.r_[1.0, np.zeros(int(FS) - 1)]))
    k = round(d.settling_s * FS) - 1
    assert h[k] > 0.01 * h.max() >= h[k + 1:].max()
